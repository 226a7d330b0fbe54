//! The viewer's world without the network: the online MPC controller spins the ellipse from rest at its
//! control-step budget, and bad settings are typed errors.

use viewer::protocol::{ClientMessage, PolicyKind, WorldKind};
use viewer::{ViewerError, World, WorldSettings};

#[test]
fn online_mpc_spins_the_ellipse_from_rest_and_recovers_from_a_drag() {
    // Seeded by the library's policy at the start and whenever its plan stalls.
    let mut world = World::new(
        dynamics::Scene::flicking_finger(),
        Some(crate::support::finger_library().clone()),
        WorldSettings {
            policy: PolicyKind::Mpc,
            ..WorldSettings::default()
        },
    )
    .unwrap();
    let mut times = Vec::new();
    let mut run = |world: &mut World, steps: usize| {
        let start = world.state()[2];
        for _ in 0..steps {
            world.advance().unwrap();
            assert!(world.warning().is_none(), "{:?}", world.warning());
            times.push(world.frame().control_ms);
        }
        world.state()[2] - start
    };
    let turned = run(&mut world, 600);
    println!("online MPC from rest: theta3 turned {turned:.2} rad in 30 s");
    assert!(turned > 6.0, "{turned}");
    // Pull the ellipse against its spin for 2 s, then let go: the spin resumes.
    world
        .apply(ClientMessage::Grab {
            body: 2,
            point: [0.7, -3.0],
        })
        .unwrap();
    world
        .apply(ClientMessage::Drag {
            target: [0.7, -4.5],
        })
        .unwrap();
    let dragged = run(&mut world, 40);
    world.apply(ClientMessage::Release).unwrap();
    let after = run(&mut world, 400);
    println!("dragged: {dragged:.2} rad in 2 s; after release {after:.2} rad in 20 s");
    assert!(
        dragged < 0.5 * turned / 15.0,
        "the drag should hold the spin back: {dragged}"
    );
    assert!(after > 4.0, "{after}");
    times.sort_by(f64::total_cmp);
    println!(
        "control step: median {:.2} ms, 95th percentile {:.2} ms (test profile)",
        times[times.len() / 2],
        times[times.len() * 95 / 100]
    );
}

#[test]
fn bad_world_settings_and_messages_are_typed_errors_that_change_nothing() {
    let scene = dynamics::Scene::flicking_finger();
    for settings in [
        WorldSettings {
            h: 0.0,
            ..WorldSettings::default()
        },
        WorldSettings {
            sigma: f64::NAN,
            ..WorldSettings::default()
        },
        WorldSettings {
            speed: 100.0,
            ..WorldSettings::default()
        },
        WorldSettings {
            x0: vec![0.0; 5],
            ..WorldSettings::default()
        },
        WorldSettings {
            mpc_passes: 0,
            ..WorldSettings::default()
        },
        // The library policy without a library.
        WorldSettings::default(),
    ] {
        assert!(World::new(scene.clone(), None, settings).is_err());
    }
    let mut world = World::new(
        scene,
        None,
        WorldSettings {
            policy: PolicyKind::Off,
            ..WorldSettings::default()
        },
    )
    .unwrap();
    let before = world.frame();
    for bad in [
        ClientMessage::Sigma { sigma: 0.0 },
        ClientMessage::Sigma { sigma: 1e6 },
        ClientMessage::Speed { speed: 0.0 },
        ClientMessage::Kick { std: f64::NAN },
        ClientMessage::Grab {
            body: 3,
            point: [0.0, 0.0],
        },
        ClientMessage::Grab {
            body: 0,
            point: [f64::INFINITY, 0.0],
        },
        ClientMessage::Policy {
            policy: PolicyKind::Library,
        },
    ] {
        let err = world.apply(bad.clone()).unwrap_err();
        assert!(
            matches!(err, ViewerError::Setting { .. } | ViewerError::Message(_)),
            "{bad:?}: {err}"
        );
    }
    assert_eq!(world.frame(), before);
    world
        .apply(ClientMessage::World {
            world: WorldKind::Hard,
        })
        .unwrap();
    world.advance().unwrap();
    assert_eq!(world.frame().world, WorldKind::Hard);
}
