//! Static world geometry: half-planes (ground, walls) and fixed ellipses in contact pairs with bodies.

use dynamics::{Complementarity, DynamicsError, Scene, Simulator, StepSettings};
use ncp::Status;

/// A drag-free two-link pendulum over the ground, with a fixed peg beside its upper link: three pairs
/// (ground under the lower link, the peg against either link).
pub(crate) const PENDULUM: &str = r#"
gravity = [0.0, -9.81]

[[body]]
name = "upper"
semi_axes = [0.6, 0.15]
parent = "world"
anchor = [0.0, 0.0]
centre = [0.6, 0.0]
joint = {}

[[body]]
name = "lower"
semi_axes = [0.6, 0.15]
parent = "upper"
anchor = [1.2, 0.0]
centre = [0.6, 0.0]
joint = { actuated = true }

[[plane]]
name = "ground"
point = [0.0, -1.8]
normal = [0.0, 2.0]

[[fixed]]
name = "peg"
semi_axes = [0.25, 0.2]
centre = [-1.3, -0.4]
angle = 0.3

[[contact]]
a = "ground"
b = "lower"
friction = 0.6

[[contact]]
a = "upper"
b = "peg"
friction = 0.3

[[contact]]
a = "lower"
b = "peg"
friction = 0.3
"#;

fn pendulum() -> Scene {
    Scene::from_toml_str(PENDULUM).unwrap()
}

/// States touching the ground (lower link's tip at the boundary) and the peg (upper link pointing at
/// it), moving.
fn touching() -> Vec<Vec<f64>> {
    vec![
        vec![-0.9, 0.1, 0.3, -0.5],
        vec![-0.85, 0.05, -0.4, 0.2],
        vec![-2.78, 0.3, 0.2, 0.6],
        vec![-2.7, -0.2, -0.3, 0.1],
    ]
}

#[test]
fn the_world_geometry_is_read_and_checked() {
    let scene = pendulum();
    assert_eq!(scene.n_dof(), 2);
    assert_eq!(scene.planes[0].shape.normal(), [0.0, 1.0]);
    assert_eq!(scene.fixed[0].pose, [-1.3, -0.4, 0.3]);
    assert_eq!(
        scene
            .contacts
            .iter()
            .map(|c| (c.a, c.b))
            .collect::<Vec<_>>(),
        [
            (dynamics::Side::Plane(0), dynamics::Side::Body(1)),
            (dynamics::Side::Body(0), dynamics::Side::Fixed(0)),
            (dynamics::Side::Body(1), dynamics::Side::Fixed(0)),
        ]
    );
    // Two rows per pair, no limit rows.
    assert_eq!(scene.n_constraints(), 6);
    // The file round-trips through its spec; a scene without world geometry writes none.
    let text = toml::to_string(scene.spec()).unwrap();
    assert_eq!(Scene::from_toml_str(&text).unwrap(), scene);
    let finger = toml::to_string(task::ProblemFile::builtin().scene.spec()).unwrap();
    assert!(
        !finger.contains("plane") && !finger.contains("fixed"),
        "{finger}"
    );
    // Every bad field named.
    let bad = PENDULUM
        .replace("normal = [0.0, 2.0]", "normal = [0.0, 0.0]")
        .replace("semi_axes = [0.25, 0.2]", "semi_axes = [0.0, 0.2]")
        .replace("angle = 0.3", "angle = nan")
        .replace("a = \"upper\"", "a = \"ground\"")
        .replace("b = \"lower\"\nfriction", "b = \"nowhere\"\nfriction");
    let Err(DynamicsError::Scene(problems)) = Scene::from_toml_str(&bad) else {
        panic!("accepted")
    };
    let fields: Vec<&str> = problems.iter().map(|p| p.field.as_str()).collect();
    for f in [
        "plane[0].point/normal",
        "fixed[0].semi_axes",
        "fixed[0].angle",
        "contact[0].b",
    ] {
        assert!(fields.contains(&f), "{f} not in {fields:?}");
    }
    // Static against static ("ground" against the peg) needs a body.
    assert!(
        problems
            .iter()
            .any(|p| p.field == "contact[1].b" && p.problem.contains("moving body")),
        "{problems:?}"
    );
    // Names are unique across bodies, planes and fixed ellipses.
    for clash in ["name = \"ground\"", "name = \"peg\""] {
        let text = PENDULUM.replacen(clash, "name = \"upper\"", 1);
        let Err(DynamicsError::Scene(problems)) = Scene::from_toml_str(&text) else {
            panic!("accepted {clash}")
        };
        assert!(
            problems.iter().any(|p| p.field.ends_with(".name")),
            "{problems:?}"
        );
    }
    let unknown = PENDULUM.replace("angle = 0.3", "angle = 0.3\nmass = 2.0");
    assert!(matches!(
        Scene::from_toml_str(&unknown),
        Err(DynamicsError::Parse(_))
    ));
}

/// Each contact pair is named by its file's names, whatever its sides are (a half-plane, a body, a fixed
/// ellipse), in the file's order; a pair or side the scene does not have has no name.
#[test]
fn contact_pairs_are_named_by_their_sides_names() {
    let scene = pendulum();
    let names: Vec<String> = (0..scene.contacts.len())
        .map(|k| scene.pair_name(k).unwrap())
        .collect();
    assert_eq!(names, ["ground-lower", "upper-peg", "lower-peg"]);
    assert_eq!(scene.pair_name(3), None);
    assert_eq!(scene.side_name(dynamics::Side::Plane(0)), Some("ground"));
    assert_eq!(scene.side_name(dynamics::Side::Fixed(0)), Some("peg"));
    assert_eq!(scene.side_name(dynamics::Side::Body(1)), Some("lower"));
    assert_eq!(scene.side_name(dynamics::Side::Plane(1)), None);
}

#[test]
fn the_hard_world_holds_the_pendulum_on_the_ground_and_never_adds_energy() {
    let scene = pendulum();
    let mut sim = Simulator::new(
        scene.clone(),
        StepSettings {
            model: Complementarity::Hard,
            h: 0.01,
            ..StepSettings::default()
        },
    )
    .unwrap();
    // Released horizontal to the right it swings down onto the ground; to the left, onto the peg.
    let mut touched = [0usize; 3];
    let mut lowest = f64::INFINITY;
    for start in [0.0, -3.1] {
        let mut x = vec![start, 0.0, 0.0, 0.0];
        sim.reset_warm_start();
        let e0 = crate::support::energy(&scene, &x);
        for _ in 0..600 {
            let s = sim.step(&x, &[0.0]).unwrap();
            assert_eq!(s.info.status, Status::Converged);
            for (k, c) in s.contacts.iter().enumerate() {
                lowest = lowest.min(c.distance);
                touched[k] += usize::from(s.lambda[2 * k] + s.lambda[2 * k + 1] > 1e-6);
            }
            x = s.x_next;
            let e = crate::support::energy(&scene, &x);
            assert!(e <= e0 + 0.05, "from {start}: energy {e} rose above {e0}");
        }
        // It comes to rest (the hard contacts and friction take the energy).
        assert!(
            x[2].abs() + x[3].abs() < 0.05,
            "from {start}: still moving at {x:?}"
        );
    }
    assert!(
        touched[0] > 10 && touched[1] + touched[2] > 10,
        "steps in contact per pair: {touched:?}"
    );
    assert!(lowest > -0.05, "penetration {lowest}");
}

#[test]
fn which_side_a_static_shape_is_on_changes_nothing() {
    let swapped = PENDULUM
        .replace(
            "a = \"ground\"\nb = \"lower\"",
            "a = \"lower\"\nb = \"ground\"",
        )
        .replace("a = \"upper\"\nb = \"peg\"", "a = \"peg\"\nb = \"upper\"");
    let (one, other) = (pendulum(), Scene::from_toml_str(&swapped).unwrap());
    assert_ne!(one, other);
    for model in [
        Complementarity::Hard,
        Complementarity::Logistic { sigma: 0.2 },
    ] {
        let settings = StepSettings {
            model,
            ..StepSettings::default()
        };
        let (mut a, mut b) = (
            Simulator::new(one.clone(), settings).unwrap(),
            Simulator::new(other.clone(), settings).unwrap(),
        );
        for x in touching() {
            let (sa, sb) = (a.step(&x, &[0.3]).unwrap(), b.step(&x, &[0.3]).unwrap());
            for (p, q) in sa.x_next.iter().zip(&sb.x_next) {
                assert!(
                    (p - q).abs() < 1e-9 * (1.0 + p.abs()),
                    "{model:?} at {x:?}: {p} vs {q}"
                );
            }
            let (ia, ib) = (&sa.impulses, &sb.impulses);
            assert!((ia[0].normal - ib[0].normal).abs() < 1e-9);
        }
    }
}

#[test]
fn derivatives_through_world_contacts_match_differences() {
    let scene = pendulum();
    let settings = StepSettings {
        model: Complementarity::Logistic { sigma: 0.2 },
        ..StepSettings::default()
    };
    let u = [0.3];
    let mut pairs_touched = [false; 3];
    for x in touching() {
        let step = crate::dynamics_hard_cases::first_derivatives_match_differences(
            &scene, settings, &x, &u,
        );
        assert_eq!(step.info.status, Status::Converged);
        for (k, touched) in pairs_touched.iter_mut().enumerate() {
            *touched |= step.lambda[2 * k] + step.lambda[2 * k + 1] > 1e-3;
        }
    }
    assert_eq!(
        pairs_touched,
        [true, true, true],
        "every pair must be in contact somewhere"
    );
    // Second derivatives: the logistic model at every state; the normal model at the first three (at the
    // fourth, both links near the peg, differences of its ERM-solved first derivatives at steps of 1e-6
    // and 5e-7 disagree by 1e-4 of the scale, so too few entries resolve to compare).
    let touching_states = crate::dynamics_hard_cases::hessians_match_differences(
        &scene,
        Complementarity::Logistic { sigma: 0.2 },
        &touching(),
        &u,
    );
    assert_eq!(touching_states, 4);
    let touching_states = crate::dynamics_hard_cases::hessians_match_differences(
        &scene,
        Complementarity::Normal { sigma: 0.2 },
        &touching()[..3],
        &u,
    );
    assert!(touching_states >= 2, "{touching_states}");
}
