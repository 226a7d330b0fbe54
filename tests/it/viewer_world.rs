//! The viewer's world without the network: the online MPC controller spins the ellipse from rest at its
//! control-step budget, and bad settings are typed errors.

use viewer::protocol::{ClientMessage, PolicyKind, WorldKind};
use viewer::{ViewerError, World, WorldSettings};

#[test]
fn online_mpc_spins_the_ellipse_from_rest_and_recovers_from_a_drag() {
    // Seeded by the library's policy at the start and whenever its plan stalls.
    let mut world = World::new(
        task::ProblemFile::builtin().scene,
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
    let scene = task::ProblemFile::builtin().scene;
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
        // Within the field's range, beyond the finger's own bound (8: Scene::largest_noise_scale).
        ClientMessage::Sigma { sigma: 9.0 },
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
        if bad == (ClientMessage::Sigma { sigma: 9.0 }) {
            assert!(err.to_string().contains("at most 8"), "{err}");
        }
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
            task::ProblemFile::builtin().scene,
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
        task::ProblemFile::builtin().scene,
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

/// A world on a scene file's task: the task's initial state, time step and noise scale, as
/// `cargo xtask view --scene FILE --task NAME` sets them.
fn task_world(text: &str, task: &str, policy: PolicyKind) -> World {
    let problem = task::ProblemFile::from_toml_str(text).unwrap();
    let task = problem.task(Some(task)).unwrap();
    let sigma = match task.model {
        task::ContactModel::Logistic(s) | task::ContactModel::Normal(s) => s,
        task::ContactModel::Hard => 0.1,
    };
    World::new(
        problem.scene.clone(),
        None,
        WorldSettings {
            policy,
            x0: task.x0.clone(),
            h: task.h,
            sigma,
            task,
            ..WorldSettings::default()
        },
    )
    .unwrap()
}

#[test]
fn the_pushing_scene_is_shown_whole_its_free_block_can_be_dragged_and_online_mpc_pushes_it() {
    let text = include_str!("../../scenes/pushing.toml");
    let mut world = task_world(text, "push", PolicyKind::Off);
    let hello = serde_json::to_value(world.hello()).unwrap();
    // The ground is sent, the window holds it and every body, and the page follows block.x to 0.6.
    assert_eq!(hello["planes"].as_array().unwrap().len(), 1, "{hello}");
    assert_eq!(hello["planes"][0]["normal"], serde_json::json!([0.0, 1.0]));
    assert_eq!(hello["bodies"].as_array().unwrap().len(), 3);
    assert_eq!(hello["watched"]["name"], "block.x");
    assert_eq!(hello["watched"]["target"], 0.6);
    assert_eq!(hello["watched"]["unit"], "units", "block.x slides");
    // The block drawn where the task wants it: at x = 0.6, on the ground as it starts (y 0.2, level);
    // the finger's links have no target and are not sent.
    let targets = hello["targets"].as_array().unwrap();
    assert_eq!(targets.len(), 1, "{hello}");
    assert_eq!(targets[0]["body"], 2);
    let centre: [f64; 2] = serde_json::from_value(targets[0]["centre"].clone()).unwrap();
    assert!(
        (centre[0] - 0.6).abs() < 1e-12 && (centre[1] - 0.2).abs() < 1e-12,
        "{centre:?}"
    );
    assert_eq!(targets[0]["angle"], 0.0);
    let w: Vec<f64> = serde_json::from_value(hello["window"].clone()).unwrap();
    assert!(
        w[2] < 0.0 && w[3] > 1.3 && w[0] < -1.4 - 0.5 && w[1] > 1.2,
        "{w:?}"
    );
    let frame = world.frame();
    assert_eq!(
        frame.bodies.len(),
        3,
        "one pose per body, not per coordinate"
    );
    // Grab the block (body 2, a free body: 3 coordinates, so body indices are not coordinates) at its
    // centre and pull it right along the ground.
    let start = world.state()[2];
    world
        .apply(ClientMessage::Grab {
            body: 2,
            point: [0.0, 0.2],
        })
        .unwrap();
    world
        .apply(ClientMessage::Drag { target: [1.0, 0.2] })
        .unwrap();
    for _ in 0..40 {
        world.advance().unwrap();
    }
    world.apply(ClientMessage::Release).unwrap();
    let dragged = world.state()[2] - start;
    assert!(dragged > 0.2, "the drag moved the block {dragged}");
    assert!(world.frame().watched == world.state()[2]);
    // A body index past the scene's bodies is refused (the scene has 5 coordinates but 3 bodies).
    assert!(
        world
            .apply(ClientMessage::Grab {
                body: 3,
                point: [0.0, 0.2],
            })
            .is_err()
    );
    // Online MPC on the task's cost, from the task's start, pushes the block most of the way.
    let mut world = task_world(text, "push", PolicyKind::Mpc);
    for _ in 0..120 {
        world.advance().unwrap();
        assert!(world.warning().is_none(), "{:?}", world.warning());
    }
    let x = world.state()[2];
    println!("online MPC: block.x {x:.3} after 6 s (target 0.6)");
    assert!((x - 0.6).abs() < 0.15, "block.x {x}");
}

#[test]
fn the_two_finger_scene_turns_to_its_target_under_online_mpc_and_never_counts_a_stall() {
    let mut world = task_world(
        include_str!("../../scenes/two_fingers.toml"),
        "turn",
        PolicyKind::Mpc,
    );
    let hello = serde_json::to_value(world.hello()).unwrap();
    assert_eq!(hello["watched"]["name"], "ellipse.angle");
    assert_eq!(hello["watched"]["unit"], "rad");
    assert!(hello["planes"].as_array().unwrap().is_empty());
    // The ellipse outlined at its target angle, in place on its hinge.
    let targets = hello["targets"].as_array().unwrap();
    assert_eq!(targets.len(), 1, "{hello}");
    assert_eq!(targets[0]["angle"], 0.5);
    for _ in 0..160 {
        world.advance().unwrap();
        assert!(world.warning().is_none(), "{:?}", world.warning());
    }
    let frame = world.frame();
    println!(
        "online MPC: ellipse.angle {:.3} after 8 s (target 0.5)",
        frame.watched
    );
    assert!((frame.watched - 0.5).abs() < 0.15, "{}", frame.watched);
    // A target task has no progress to stall on: the plan is never re-seeded (there is no library
    // either).
    assert_eq!(frame.mpc_reseeds, 0);
}

#[test]
fn a_scene_with_a_fixed_peg_and_a_ground_sends_both_and_keeps_them_in_the_window() {
    // The pendulum of dynamics_world: two hinged links over a ground, a fixed peg beside them.
    // A task for it: hold the upper link level (the world follows the task's target).
    let text = format!(
        "{}\n[task.level]\nh = 0.05\nhorizon = 10\nmodel = \"hard\"\ncontrol_weight = 0.1\nrunning = [{{ coordinate = \"upper.angle\", quadratic = 1.0 }}]\n",
        crate::dynamics_world::PENDULUM
    );
    let problem = task::ProblemFile::from_toml_str(&text).unwrap();
    let scene = problem.scene.clone();
    // The default world's task (the built-in finger's spin) does not fit this scene: refused by its sizes.
    let err = World::new(
        scene.clone(),
        None,
        WorldSettings {
            policy: PolicyKind::Off,
            x0: vec![-1.2, 0.3, 0.0, 0.0],
            ..WorldSettings::default()
        },
    )
    .unwrap_err();
    assert!(
        err.to_string().contains("task spin has 6 state entries"),
        "{err}"
    );
    let mut world = World::new(
        scene.clone(),
        None,
        WorldSettings {
            policy: PolicyKind::Off,
            x0: vec![-1.2, 0.3, 0.0, 0.0],
            task: problem.task(None).unwrap(),
            ..WorldSettings::default()
        },
    )
    .unwrap();
    let hello = serde_json::to_value(world.hello()).unwrap();
    assert_eq!(hello["fixed"][0]["name"], "peg");
    assert_eq!(
        hello["fixed"][0]["semi_axes"],
        serde_json::json!([0.25, 0.2])
    );
    assert_eq!(hello["fixed"][0]["centre"], serde_json::json!([-1.3, -0.4]));
    assert_eq!(hello["fixed"][0]["angle"], 0.3);
    // The ground's normal arrives normalised.
    assert_eq!(hello["planes"][0]["normal"], serde_json::json!([0.0, 1.0]));
    let w: Vec<f64> = serde_json::from_value(hello["window"].clone()).unwrap();
    // The chain swings round its pivot at the origin (reach 1.8 + 0.6), the peg and the ground inside.
    assert!(
        w[0] < -2.4 && w[1] > 2.4 && w[2] < -2.1 && w[3] > 2.4,
        "{w:?}"
    );
    // The pendulum falls onto the peg and the ground under gravity; the world keeps stepping, its
    // contacts reported.
    for _ in 0..60 {
        world.advance().unwrap();
    }
    assert!(world.state().iter().all(|v| v.is_finite()));
    assert_eq!(world.frame().contacts.len(), 3);
}

#[test]
fn the_finger_page_follows_the_spin_in_radians_and_draws_no_target() {
    // The spin task rewards progress and pulls no position to a target: nothing to outline.
    let world = World::new(
        task::ProblemFile::builtin().scene,
        None,
        WorldSettings {
            policy: PolicyKind::Off,
            ..WorldSettings::default()
        },
    )
    .unwrap();
    let hello = serde_json::to_value(world.hello()).unwrap();
    assert_eq!(hello["watched"]["name"], "ellipse.angle");
    assert_eq!(hello["watched"]["target"], serde_json::Value::Null);
    assert_eq!(hello["watched"]["unit"], "rad");
    assert_eq!(hello["targets"], serde_json::json!([]));
}
