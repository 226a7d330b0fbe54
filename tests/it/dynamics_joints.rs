//! Slider, free and weld joints: the mass matrix and the bias forces against the Lagrangian computed
//! independently (differences of positions and of `M`), energy, a free body on the ground, derivatives
//! through contacts of free and sliding bodies.

use dynamics::{Complementarity, DynamicsError, Kinematics, Scene, Simulator, StepSettings};
use ncp::Status;

/// Every joint kind in one chain and beside it, no drag, no contact: a hinged arm carrying a slider
/// carrying a free puck with a tip welded to it, and a free block at the root.
const MIXED: &str = r#"
gravity = [0.0, -9.81]

[[body]]
name = "arm"
semi_axes = [0.5, 0.1]
parent = "world"
anchor = [0.0, 0.0]
centre = [0.5, 0.0]
joint = {}

[[body]]
name = "carriage"
semi_axes = [0.2, 0.15]
parent = "arm"
anchor = [0.3, 0.0]
centre = [0.0, 0.05]
joint = { type = "slider", axis = [1.0, 0.2] }

[[body]]
name = "puck"
semi_axes = [0.3, 0.2]
density = 2.0
parent = "carriage"
anchor = [0.2, 0.1]
centre = [0.1, 0.05]
joint = { type = "free" }

[[body]]
name = "tip"
semi_axes = [0.1, 0.05]
density = 3.0
parent = "puck"
anchor = [0.4, -0.2]
centre = [0.05, 0.1]
joint = { type = "weld" }

[[body]]
name = "block"
semi_axes = [0.4, 0.25]
parent = "world"
anchor = [2.0, -1.0]
centre = [0.0, 0.0]
joint = { type = "free" }
"#;

fn mixed() -> Scene {
    Scene::from_toml_str(MIXED).unwrap()
}

fn states() -> Vec<Vec<f64>> {
    (0..5)
        .map(|i| {
            let t = i as f64;
            vec![
                0.3 * t - 0.7,
                0.4 - 0.1 * t,
                0.2,
                -0.1 * t,
                t,
                0.5,
                -0.3,
                0.7 * t,
                1.0 - 0.3 * t,
                0.5 * t,
                -0.7,
                0.8,
                1.5 - t,
                0.3,
                -0.2 * t,
                0.9,
            ]
        })
        .collect()
}

#[test]
fn coordinates_are_named_and_bad_joints_are_refused() {
    let scene = mixed();
    assert_eq!(scene.n_dof(), 8);
    assert_eq!(
        scene.coordinate_names(),
        [
            "arm.angle",
            "carriage.position",
            "puck.x",
            "puck.y",
            "puck.angle",
            "block.x",
            "block.y",
            "block.angle"
        ]
    );
    let text = toml::to_string(scene.spec()).unwrap();
    assert_eq!(Scene::from_toml_str(&text).unwrap(), scene);
    for (from, to, field) in [
        (
            "type = \"slider\", axis = [1.0, 0.2]",
            "type = \"slider\"",
            "body[1].joint.axis",
        ),
        (
            "type = \"slider\", axis = [1.0, 0.2]",
            "type = \"slider\", axis = [0.0, 0.0]",
            "body[1].joint.axis",
        ),
        (
            "joint = {}",
            "joint = { axis = [1.0, 0.0] }",
            "body[0].joint.axis",
        ),
        (
            "joint = { type = \"free\" }\n\n[[body]]",
            "joint = { type = \"free\", limits = [-1.0, 1.0] }\n\n[[body]]",
            "body[2].joint.limits",
        ),
    ] {
        let text = MIXED.replacen(from, to, 1);
        assert_ne!(text, MIXED);
        let Err(DynamicsError::Scene(problems)) = Scene::from_toml_str(&text) else {
            panic!("accepted {to}")
        };
        assert!(
            problems.iter().any(|p| p.field == field),
            "{field}: {problems:?}"
        );
    }
    let unknown = MIXED.replacen("type = \"free\"", "type = \"ball\"", 1);
    assert!(matches!(
        Scene::from_toml_str(&unknown),
        Err(DynamicsError::Parse(_))
    ));
    // An actuated free joint takes three controls: force along x, along y, torque.
    let actuated = MIXED.replacen(
        "type = \"free\" }\n\n[[body]]",
        "type = \"free\", actuated = true }\n\n[[body]]",
        1,
    );
    assert_eq!(Scene::from_toml_str(&actuated).unwrap().n_controls, 3);
    // A weld adds no coordinate; the tip is carried by the puck's joint.
    assert_eq!(scene.carrier(3), 2);
    assert_eq!(scene.carrier(2), 2);
    assert!(scene.bodies[3].coordinates.is_empty());
}

#[test]
fn bad_welds_are_refused_with_the_field_named() {
    let weld = "parent = \"puck\"\nanchor = [0.4, -0.2]\ncentre = [0.05, 0.1]\njoint = { type = \"weld\" }";
    assert!(MIXED.contains(weld));
    for (to, field) in [
        (
            weld.replace("parent = \"puck\"", "parent = \"world\""),
            "body[3].joint.type",
        ),
        (
            weld.replace("\"weld\"", "\"weld\", limits = [-1.0, 1.0]"),
            "body[3].joint",
        ),
        (
            weld.replace("\"weld\"", "\"weld\", actuated = true"),
            "body[3].joint",
        ),
        (
            weld.replace("\"weld\"", "\"weld\", damping = 0.5"),
            "body[3].joint",
        ),
        (
            weld.replace("\"weld\"", "\"weld\", axis = [1.0, 0.0]"),
            "body[3].joint.axis",
        ),
    ] {
        let text = MIXED.replacen(weld, &to, 1);
        let Err(DynamicsError::Scene(problems)) = Scene::from_toml_str(&text) else {
            panic!("accepted {to}")
        };
        assert!(
            problems.iter().any(|p| p.field == field),
            "{field}: {problems:?}"
        );
    }
    // A pair inside one rigid body (the puck and its tip) never changes: refused, naming the pair.
    let paired = format!("{MIXED}\n[[contact]]\na = \"tip\"\nb = \"puck\"\nfriction = 0.5\n");
    let Err(DynamicsError::Scene(problems)) = Scene::from_toml_str(&paired) else {
        panic!(
            "accepted a pair inside one rigid body: {:?}",
            Scene::from_toml_str(&paired)
        )
    };
    assert!(
        problems
            .iter()
            .any(|p| p.field == "contact[0].b" && p.problem.contains("welded")),
        "{problems:?}"
    );
    // The tip against the carriage (a joint apart) is a pair like any other.
    let apart = format!("{MIXED}\n[[contact]]\na = \"tip\"\nb = \"carriage\"\nfriction = 0.5\n");
    assert!(Scene::from_toml_str(&apart).is_ok());
}

/// `v^T M v / 2` against the kinetic energy from differences of the centres and angles along `v`.
#[test]
fn the_mass_matrix_is_the_kinetic_energy_of_the_moving_centres() {
    let scene = mixed();
    let n = scene.n_dof();
    for x in states() {
        let (q, v) = x.split_at(n);
        let m = Kinematics::new(&scene, q).mass_matrix(&scene);
        let quadratic: f64 = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .map(|(i, j)| 0.5 * v[i] * m[i * n + j] * v[j])
            .sum();
        let eps = 1e-6;
        let shifted = |s: f64| {
            let q: Vec<f64> = q.iter().zip(v).map(|(q, v)| q + s * eps * v).collect();
            Kinematics::new(&scene, &q)
        };
        let (p, mm) = (shifted(1.0), shifted(-1.0));
        let kinetic: f64 = scene
            .bodies
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let cdot = [
                    (p.centre[i][0] - mm.centre[i][0]) / (2.0 * eps),
                    (p.centre[i][1] - mm.centre[i][1]) / (2.0 * eps),
                ];
                let w = (p.phi[i] - mm.phi[i]) / (2.0 * eps);
                0.5 * b.mass * (cdot[0] * cdot[0] + cdot[1] * cdot[1]) + 0.5 * b.inertia * w * w
            })
            .sum();
        assert!(
            (quadratic - kinetic).abs() < 1e-7 * (1.0 + kinetic),
            "{quadratic} vs {kinetic}"
        );
        for i in 0..n {
            for j in 0..n {
                assert_eq!(m[i * n + j], m[j * n + i]);
            }
        }
    }
}

/// The bias forces without gravity and drag are `-(dM/dt) v + grad_q (v^T M v) / 2` (Lagrange), here from
/// differences of `M` alone.
#[test]
fn the_bias_forces_are_lagranges_velocity_terms() {
    let mut spec = mixed().spec().clone();
    spec.gravity = [0.0, 0.0];
    let scene = Scene::new(spec).unwrap();
    let n = scene.n_dof();
    let mass = |q: &[f64]| Kinematics::new(&scene, q).mass_matrix(&scene);
    for x in states() {
        let (q, v) = x.split_at(n);
        let r = Kinematics::new(&scene, q).bias_forces(&scene, v);
        let eps = 1e-6;
        let along = |s: f64| {
            let q: Vec<f64> = q.iter().zip(v).map(|(q, v)| q + s * eps * v).collect();
            mass(&q)
        };
        let (mp, mm) = (along(1.0), along(-1.0));
        let scale = r.iter().fold(1.0f64, |m, e| m.max(e.abs()));
        for k in 0..n {
            let mdot_v: f64 = (0..n)
                .map(|j| (mp[k * n + j] - mm[k * n + j]) / (2.0 * eps) * v[j])
                .sum();
            let (mut qp, mut qm) = (q.to_vec(), q.to_vec());
            qp[k] += eps;
            qm[k] -= eps;
            let energy = |m: &[f64]| -> f64 {
                (0..n)
                    .flat_map(|i| (0..n).map(move |j| (i, j)))
                    .map(|(i, j)| 0.5 * v[i] * m[i * n + j] * v[j])
                    .sum()
            };
            let grad = (energy(&mass(&qp)) - energy(&mass(&qm))) / (2.0 * eps);
            let lagrange = -mdot_v + grad;
            assert!(
                (r[k] - lagrange).abs() < 1e-6 * scale,
                "coordinate {k} at {x:?}: {} vs {lagrange}",
                r[k]
            );
        }
    }
}

#[test]
fn energy_is_conserved_to_first_order_in_h_with_every_joint_kind() {
    let scene = mixed();
    let x0 = states()[1].clone();
    let e0 = crate::support::energy(&scene, &x0);
    let mut drift = Vec::new();
    for h in [0.004, 0.002, 0.001] {
        let mut sim = Simulator::new(
            scene.clone(),
            StepSettings {
                model: Complementarity::Hard,
                h,
                ..StepSettings::default()
            },
        )
        .unwrap();
        let mut x = x0.clone();
        let mut worst = 0.0f64;
        for _ in 0..(0.5 / h) as usize {
            x = sim.step(&x, &[]).unwrap().x_next;
            worst = worst.max((crate::support::energy(&scene, &x) - e0).abs());
        }
        drift.push(worst);
    }
    assert!(
        drift[1] < 0.7 * drift[0] && drift[2] < 0.7 * drift[1],
        "{drift:?}"
    );
    assert!(drift[2] < 0.05 * e0.abs().max(1.0), "{drift:?}");
    // The free block alone falls as a point mass would: v' = v + h g, the spin unchanged.
    let mut sim = Simulator::new(scene.clone(), StepSettings::default()).unwrap();
    let s = sim.step(&x0, &[]).unwrap();
    let h = StepSettings::default().h;
    assert!((s.x_next[8 + 5] - x0[8 + 5]).abs() < 1e-12);
    assert!((s.x_next[8 + 6] - (x0[8 + 6] - h * 9.81)).abs() < 1e-12);
    assert!((s.x_next[8 + 7] - x0[8 + 7]).abs() < 1e-12);
}

/// A free block on the ground and a pusher on a slider along the ground: the planar pushing of issue 15.
const PUSHING: &str = r#"
gravity = [0.0, -9.81]

[[body]]
name = "pusher"
semi_axes = [0.15, 0.15]
parent = "world"
anchor = [-1.0, 0.25]
centre = [0.0, 0.0]
joint = { type = "slider", axis = [1.0, 0.0], damping = 0.5, actuated = true }

[[body]]
name = "block"
semi_axes = [0.4, 0.25]
parent = "world"
anchor = [0.0, 0.0]
centre = [0.0, 0.0]
joint = { type = "free", damping = 0.05 }

[[plane]]
name = "ground"
point = [0.0, 0.0]
normal = [0.0, 1.0]

[[contact]]
a = "ground"
b = "block"
friction = 0.5

[[contact]]
a = "pusher"
b = "block"
friction = 0.3
"#;

#[test]
fn a_free_block_settles_on_the_ground_and_is_pushed_along_it() {
    let scene = Scene::from_toml_str(PUSHING).unwrap();
    assert_eq!(
        scene.coordinate_names(),
        ["pusher.position", "block.x", "block.y", "block.angle"]
    );
    let mut sim = Simulator::new(
        scene.clone(),
        StepSettings {
            model: Complementarity::Hard,
            h: 0.01,
            ..StepSettings::default()
        },
    )
    .unwrap();
    // Dropped from 0.1 above the ground, tilted: it lands, rocks (its drag decays that in about 15 s)
    // and rests on its long side.
    let mut x = vec![0.0, 0.0, 0.35, 0.2, 0.0, 0.0, 0.0, 0.0];
    for _ in 0..1500 {
        let s = sim.step(&x, &[0.0]).unwrap();
        assert_eq!(s.info.status, Status::Converged);
        assert!(
            s.contacts[0].distance > -2e-3,
            "sinks: {}",
            s.contacts[0].distance
        );
        x = s.x_next;
    }
    assert!(x[4..].iter().all(|v| v.abs() < 1e-4), "still moving: {x:?}");
    assert!((x[2] - 0.25).abs() < 1e-6, "rests at height {}", x[2]);
    let angle = x[3].rem_euclid(std::f64::consts::PI);
    assert!(
        angle.min(std::f64::consts::PI - angle) < 1e-2,
        "rests at angle {}",
        x[3]
    );
    // The pusher, driven right, reaches the block and pushes it along the ground.
    let start = x[1];
    for _ in 0..200 {
        x = sim.step(&x, &[3.0]).unwrap().x_next;
    }
    assert!(
        x[1] > start + 0.2,
        "the block moved from {start} to {}",
        x[1]
    );
    assert!((x[2] - 0.25).abs() < 0.05, "lifted or sank: {}", x[2]);
}

#[test]
fn derivatives_of_pushing_match_differences() {
    let scene = Scene::from_toml_str(PUSHING).unwrap();
    // The block on the ground, the pusher touching its left end, both moving.
    let states: Vec<Vec<f64>> = (0..3)
        .map(|i| {
            let t = i as f64 * 0.1;
            vec![0.44 + t, 0.0 + t, 0.25, 0.02, 0.5, 0.3, -0.1, 0.2]
        })
        .collect();
    let u = [0.7];
    let touching = crate::dynamics_hard_cases::hessians_match_differences(
        &scene,
        Complementarity::Logistic { sigma: 0.2 },
        &states,
        &u,
    );
    assert_eq!(touching, 3);
    let touching = crate::dynamics_hard_cases::hessians_match_differences(
        &scene,
        Complementarity::Normal { sigma: 0.2 },
        &states,
        &u,
    );
    assert!(touching >= 2);
    let settings = StepSettings {
        model: Complementarity::Logistic { sigma: 0.2 },
        ..StepSettings::default()
    };
    for x in states {
        crate::dynamics_hard_cases::first_derivatives_match_differences(&scene, settings, &x, &u);
    }
}

/// A fork: the pusher of [`PUSHING`] with a second prong welded 2 to its right, which pushes the block
/// back (to the left) where the first prong pushes it on.
fn fork() -> Scene {
    let prong = r#"
[[body]]
name = "prong"
semi_axes = [0.15, 0.15]
parent = "pusher"
anchor = [2.0, 0.0]
centre = [0.0, 0.0]
joint = { type = "weld" }

[[contact]]
a = "prong"
b = "block"
friction = 0.3
"#;
    let text = PUSHING.replacen(
        "\n[[body]]\nname = \"block\"",
        &format!("{prong}\n[[body]]\nname = \"block\""),
        1,
    );
    Scene::from_toml_str(&text).unwrap()
}

#[test]
fn a_welded_prong_moves_with_its_carrier_and_pushes_back() {
    let scene = fork();
    // The prong adds mass to the pusher's coordinate and no coordinate of its own.
    assert_eq!(
        scene.coordinate_names(),
        ["pusher.position", "block.x", "block.y", "block.angle"]
    );
    let q = [0.3_f64, 0.0, 0.25, 0.0];
    let kin = Kinematics::new(&scene, &q);
    assert!((kin.centre[1][0] - (1.0 + 0.3)).abs() < 1e-15);
    let m = kin.mass_matrix(&scene);
    let disc = std::f64::consts::PI * 0.15 * 0.15;
    assert!((m[0] - 2.0 * disc).abs() < 1e-12, "{}", m[0]);
    // The fork is mirror symmetric about x = 0 when the pusher is at 0: the prong driven left into the
    // block's right end from 0.05 away moves it as the first prong driven right into its left end moves the
    // mirrored block (the block tips against the ground's friction and wedges).
    let mut sim = Simulator::new(
        scene,
        StepSettings {
            model: Complementarity::Hard,
            h: 0.01,
            ..StepSettings::default()
        },
    )
    .unwrap();
    let (mut left, mut right) = (
        vec![-0.4_f64, 0.0, 0.25, 0.0, 0.0, 0.0, 0.0, 0.0],
        vec![0.4_f64, 0.0, 0.25, 0.0, 0.0, 0.0, 0.0, 0.0],
    );
    for _ in 0..200 {
        left = sim.step(&left, &[-1.0]).unwrap().x_next;
        right = sim.step(&right, &[1.0]).unwrap().x_next;
        let mirrored = [-1.0, -1.0, 1.0, -1.0];
        for k in 0..8 {
            assert!(
                (left[k] - mirrored[k % 4] * right[k]).abs() < 1e-9,
                "{left:?} against {right:?}"
            );
        }
    }
    assert!(left[1] < -0.05, "the block moved to {}", left[1]);
}

#[test]
fn derivatives_through_a_welded_prong_match_differences() {
    let scene = fork();
    // The prong touching the block's right end (the first prong far behind its left), both moving.
    let states: Vec<Vec<f64>> = (0..3)
        .map(|i| {
            let t = i as f64 * 0.1;
            vec![t, 0.44 + t, 0.25, -0.02, -0.5, -0.3, -0.1, 0.2]
        })
        .collect();
    let u = [-0.7];
    for model in [
        Complementarity::Logistic { sigma: 0.2 },
        Complementarity::Normal { sigma: 0.2 },
    ] {
        let touching =
            crate::dynamics_hard_cases::hessians_match_differences(&scene, model, &states, &u);
        assert!(touching >= 2, "{model:?}: {touching}");
        let settings = StepSettings {
            model,
            ..StepSettings::default()
        };
        for x in &states {
            crate::dynamics_hard_cases::first_derivatives_match_differences(
                &scene, settings, x, &u,
            );
        }
    }
}
