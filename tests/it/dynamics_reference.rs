//! The step against the independent high-precision values of tests/data/finger_steps.json, to the
//! tolerances of its README.

use crate::support::reference_json;
use dynamics::{Complementarity, Scene, Simulator, StepSettings};

fn vector(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_f64().unwrap())
        .collect()
}

fn settings(case: &serde_json::Value) -> StepSettings {
    let sigma = case["sigma"].as_f64();
    let model = match case["model"].as_str().unwrap() {
        "hard" => Complementarity::Hard,
        "logistic" => Complementarity::Logistic {
            sigma: sigma.unwrap(),
        },
        "normal" => Complementarity::Normal {
            sigma: sigma.unwrap(),
        },
        other => panic!("unknown model {other}"),
    };
    StepSettings {
        model,
        h: case["h"].as_f64().unwrap(),
        // The reference answers are SCENE.md's step: all penetration recovered at the velocity level.
        recovery: None,
        ..StepSettings::default()
    }
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

#[test]
fn single_steps_match_the_reference_in_all_three_models() {
    let data = reference_json("finger_steps.json");
    let steps = data["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 30);
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for case in steps {
        let mut sim = Simulator::new(task::ProblemFile::builtin().scene, settings(case)).unwrap();
        let (x, u) = (vector(&case["x"]), vector(&case["u"]));
        let step = sim.step(&x, &u).unwrap();
        let tag = format!(
            "{} {} {:?} h={}",
            case["id"],
            case["tag"],
            sim.settings().model,
            case["h"]
        );
        let d_err = max_diff(&step.d, &vector(&case["d"]));
        let x_err = max_diff(&step.x_next, &vector(&case["x_next"]));
        let lambda = vector(&case["lambda"]);
        let scale = lambda.iter().fold(1.0f64, |m, l| m.max(l.abs()));
        let l_err = max_diff(&step.lambda, &lambda) / scale;
        println!(
            "{tag}: d {d_err:.1e} x_next {x_err:.1e} lambda {l_err:.1e} ({:?})",
            step.info
        );
        assert!(d_err <= 1e-12, "{tag}: d off by {d_err}");
        assert!(x_err <= 1e-10, "{tag}: x_next off by {x_err}");
        assert!(
            l_err <= 1e-10,
            "{tag}: lambda off by {l_err}: {:?} vs {lambda:?}",
            step.lambda
        );
        worst = (worst.0.max(d_err), worst.1.max(x_err), worst.2.max(l_err));
    }
    println!(
        "worst: d {:.1e}, x_next {:.1e}, lambda {:.1e}",
        worst.0, worst.1, worst.2
    );
}

#[test]
fn the_rollout_matches_the_reference() {
    let data = reference_json("finger_steps.json");
    let r = &data["rollout"];
    let settings = StepSettings {
        model: Complementarity::Logistic {
            sigma: r["sigma"].as_f64().unwrap(),
        },
        h: r["h"].as_f64().unwrap(),
        recovery: None,
        ..StepSettings::default()
    };
    let mut sim = Simulator::new(task::ProblemFile::builtin().scene, settings).unwrap();
    let u = vector(&r["u"]);
    let states: Vec<Vec<f64>> = r["states"].as_array().unwrap().iter().map(vector).collect();
    let lambdas: Vec<Vec<f64>> = r["lambdas"]
        .as_array()
        .unwrap()
        .iter()
        .map(vector)
        .collect();
    let mut x = vector(&r["x0"]);
    assert!(max_diff(&x, &states[0]) == 0.0);
    let mut worst = 0.0f64;
    for k in 0..lambdas.len() {
        let step = sim.step(&x, &u).unwrap();
        x = step.x_next;
        let err = max_diff(&x, &states[k + 1]);
        worst = worst.max(err);
        assert!(err <= 1e-9, "step {k}: state off by {err}");
        let scale = lambdas[k].iter().fold(1.0f64, |m, l| m.max(l.abs()));
        assert!(
            max_diff(&step.lambda, &lambdas[k]) <= 1e-9 * scale,
            "step {k}: impulses"
        );
    }
    println!(
        "rollout: worst state error {worst:.1e} over {} steps",
        lambdas.len()
    );
}

#[test]
fn the_shipped_scene_file_is_scene_md() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenes/finger.toml"
    ))
    .unwrap();
    assert_eq!(
        Scene::from_toml_str(&text).unwrap(),
        task::ProblemFile::builtin().scene
    );
}

fn matrix(v: &serde_json::Value) -> Vec<f64> {
    v.as_array().unwrap().iter().flat_map(vector).collect()
}

#[test]
fn logistic_step_derivatives_match_the_reference() {
    let data = reference_json("finger_steps.json");
    let mut worst = 0.0f64;
    let mut checked = 0;
    for case in data["steps"].as_array().unwrap() {
        if case["model"] != "logistic" {
            continue;
        }
        let mut sim = Simulator::new(task::ProblemFile::builtin().scene, settings(case)).unwrap();
        let (x, u) = (vector(&case["x"]), vector(&case["u"]));
        let (_, der) = sim.step_with_derivatives(&x, &u).unwrap();
        for (name, ours, exact) in [
            ("fx", &der.fx, matrix(&case["fx"])),
            ("fu", &der.fu, matrix(&case["fu"])),
        ] {
            let scale = exact.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let err = max_diff(ours, &exact) / scale;
            println!("{} {} {name}: {err:.1e}", case["id"], case["tag"]);
            assert!(
                err <= 1e-7,
                "{} {}: {name} off by {err} of its largest entry",
                case["id"],
                case["tag"]
            );
            worst = worst.max(err);
        }
        checked += 1;
    }
    assert_eq!(checked, 10);
    println!("worst derivative error {worst:.1e} relative to the largest entry");
}

#[test]
fn hessians_of_c_f_match_differences_at_the_reference_contact_states() {
    let data = reference_json("finger_steps.json");
    let c = [0.3, -0.7, 1.0, 0.2, -0.1, 0.5];
    let mut checked = 0;
    for case in data["steps"].as_array().unwrap() {
        if case["model"] != "logistic" {
            continue;
        }
        let mut sim = Simulator::new(task::ProblemFile::builtin().scene, settings(case)).unwrap();
        let (x, u) = (vector(&case["x"]), vector(&case["u"]));
        let (step, _, hess) = sim.step_with_hessian(&x, &u, &c).unwrap();
        let in_contact = step.lambda[4] + step.lambda[5] > 1e-3;
        let y: Vec<f64> = x.iter().chain(&u).copied().collect();
        let mut grad = |y: &[f64]| crate::support::c_gradient(&mut sim, &c, y);
        let scale = hess.iter().fold(1e-300f64, |m, v| m.max(v.abs()));
        let mut worst = 0.0f64;
        for k in 0..8 {
            // Step scaled to sigma h, the width of the smoothing in distance.
            let eps = 1e-4 * case["sigma"].as_f64().unwrap() * case["h"].as_f64().unwrap();
            let (mut yp, mut ym) = (y.clone(), y.clone());
            yp[k] += eps;
            ym[k] -= eps;
            let (gp, gm) = (grad(&yp), grad(&ym));
            for i in 0..8 {
                worst = worst.max(((gp[i] - gm[i]) / (2.0 * eps) - hess[i * 8 + k]).abs() / scale);
            }
        }
        println!(
            "{} {} (contact {in_contact}): Hessian vs differences {worst:.1e} of {scale:.1e}",
            case["id"], case["tag"]
        );
        assert!(worst < 1e-5, "{}: {worst}", case["tag"]);
        checked += usize::from(in_contact);
    }
    assert!(checked >= 3, "the reference has contact cases: {checked}");
}
