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

fn any_message() -> impl proptest::strategy::Strategy<Value = ClientMessage> {
    use proptest::prelude::*;
    let number = prop_oneof![
        -10.0f64..10.0,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(-1e300),
        Just(0.0),
        1e-6f64..1e6,
    ];
    prop_oneof![
        (0usize..5, number.clone(), number.clone()).prop_map(|(body, x, y)| ClientMessage::Grab {
            body,
            point: [x, y]
        }),
        (number.clone(), number.clone()).prop_map(|(x, y)| ClientMessage::Drag { target: [x, y] }),
        Just(ClientMessage::Release),
        number
            .clone()
            .prop_map(|sigma| ClientMessage::Sigma { sigma }),
        number
            .clone()
            .prop_map(|speed| ClientMessage::Speed { speed }),
        number.prop_map(|std| ClientMessage::Kick { std }),
        Just(ClientMessage::Reset),
        any::<bool>().prop_map(|paused| ClientMessage::Pause { paused }),
        prop_oneof![Just(WorldKind::Smoothed), Just(WorldKind::Hard)]
            .prop_map(|world| ClientMessage::World { world }),
        prop_oneof![Just(PolicyKind::Library), Just(PolicyKind::Off)]
            .prop_map(|policy| ClientMessage::Policy { policy }),
    ]
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    #[test]
    fn no_sequence_of_messages_breaks_the_world(
        messages in proptest::collection::vec((any_message(), 0usize..6), 1..12),
        with_library in proptest::bool::ANY,
    ) {
        // Whatever the page sends (valid or not, in any order), the world answers Ok or a typed error,
        // keeps stepping, and its state stays finite, with the library's policy in the loop or none.
        let mut world = World::new(
            dynamics::Scene::flicking_finger(),
            with_library.then(|| crate::support::finger_library().clone()),
            WorldSettings {
                policy: PolicyKind::Off,
                ..WorldSettings::default()
            },
        )
        .unwrap();
        for (message, steps) in messages {
            let _ = world.apply(message);
            for _ in 0..steps {
                world.advance().unwrap();
                let frame = world.frame();
                proptest::prop_assert!(frame.x.iter().all(|e| e.is_finite()), "{frame:?}");
                proptest::prop_assert!(serde_json::to_string(&frame).is_ok());
            }
        }
    }

    #[test]
    fn no_text_crashes_the_message_parser(text in ".{0,200}") {
        let _ = ClientMessage::parse(&text);
    }
}

#[test]
fn switching_to_online_mpc_never_stalls_the_world_and_spreads_its_first_solve_over_steps() {
    let mut world = World::new(
        dynamics::Scene::flicking_finger(),
        Some(crate::support::finger_library().clone()),
        WorldSettings {
            policy: PolicyKind::Off,
            ..WorldSettings::default()
        },
    )
    .unwrap();
    // Two hundred switches (and resets and sigma changes in MPC mode) run no optimiser pass at all.
    for k in 0..200 {
        let policy = if k % 2 == 0 {
            PolicyKind::Mpc
        } else {
            PolicyKind::Off
        };
        world.apply(ClientMessage::Policy { policy }).unwrap();
        if k % 50 == 0 {
            world.apply(ClientMessage::Reset).unwrap();
            world.apply(ClientMessage::Sigma { sigma: 0.1 }).unwrap();
        }
    }
    world
        .apply(ClientMessage::Policy {
            policy: PolicyKind::Mpc,
        })
        .unwrap();
    assert_eq!(world.frame().mpc_passes, 0);
    // Then each control step runs its pass plus at most WARMUP_PER_STEP of the first solve's.
    let bound = (WorldSettings::default().mpc_passes + viewer::WARMUP_PER_STEP) as u64;
    let mut last = 0;
    for _ in 0..40 {
        world.advance().unwrap();
        let passes = world.frame().mpc_passes;
        assert!(
            passes - last <= bound,
            "{} passes in one step",
            passes - last
        );
        last = passes;
    }
    assert!(last > bound, "the warm-up ran: {last} passes in 40 steps");
}
