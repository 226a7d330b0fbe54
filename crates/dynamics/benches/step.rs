//! One step of the flicking finger per model, in contact, warm-started from the previous step, and the step
//! with its exact derivatives. `cargo bench -p dynamics`.

use criterion::{Criterion, criterion_group, criterion_main};
use dynamics::{Complementarity, Scene, Simulator, StepSettings};
use std::hint::black_box;

/// SCENE.md's flicking finger, from its scene file.
fn finger() -> Scene {
    Scene::from_toml_str(include_str!("../../../scenes/finger.toml")).unwrap()
}

/// States along the reference rollout's contact phase (link 2 on the free ellipse), by simulation.
fn contact_states() -> Vec<Vec<f64>> {
    let mut sim = Simulator::new(finger(), StepSettings::default()).unwrap();
    // The finger apart, at rest (scenes/finger.toml's task start).
    let mut x = vec![
        -std::f64::consts::FRAC_PI_4,
        -std::f64::consts::FRAC_PI_6,
        0.0,
        0.0,
        0.0,
        0.0,
    ];
    let mut out = Vec::new();
    for _ in 0..75 {
        let s = sim.step(&x, &[0.3, -0.2]).unwrap();
        if s.contacts[0].distance < 0.05 {
            out.push(x.clone());
        }
        x = s.x_next;
    }
    assert!(!out.is_empty());
    out
}

fn step(c: &mut Criterion) {
    let states = contact_states();
    let mut group = c.benchmark_group("finger_step_in_contact");
    let models = [
        ("hard", Complementarity::Hard),
        ("logistic_0.1", Complementarity::Logistic { sigma: 0.1 }),
        ("normal_0.1", Complementarity::Normal { sigma: 0.1 }),
    ];
    for (name, model) in models {
        let mut sim = Simulator::new(
            finger(),
            StepSettings {
                model,
                ..StepSettings::default()
            },
        )
        .unwrap();
        let mut k = 0;
        group.bench_function(name, |b| {
            b.iter(|| {
                let x = &states[k % states.len()];
                k += 1;
                black_box(sim.step(x, &[0.3, -0.2]).unwrap())
            })
        });
    }
    let mut sim = Simulator::new(finger(), StepSettings::default()).unwrap();
    let mut k = 0;
    group.bench_function("logistic_0.1_with_derivatives", |b| {
        b.iter(|| {
            let x = &states[k % states.len()];
            k += 1;
            black_box(sim.step_with_derivatives(x, &[0.3, -0.2]).unwrap())
        })
    });
    let mut sim = Simulator::new(finger(), StepSettings::default()).unwrap();
    let mut k = 0;
    let c = [0.3, -0.7, 1.0, 0.2, -0.1, 0.5];
    group.bench_function("logistic_0.1_with_hessian_of_c_f", |b| {
        b.iter(|| {
            let x = &states[k % states.len()];
            k += 1;
            black_box(sim.step_with_hessian(x, &[0.3, -0.2], &c).unwrap())
        })
    });
    // For comparison: forward differences of the same step, one extra step per state and control entry.
    let mut sim = Simulator::new(finger(), StepSettings::default()).unwrap();
    let mut k = 0;
    group.bench_function("logistic_0.1_forward_differences", |b| {
        b.iter(|| {
            let x = &states[k % states.len()];
            k += 1;
            let u = [0.3, -0.2];
            let base = sim.step(x, &u).unwrap().x_next;
            let mut acc = 0.0;
            for j in 0..8 {
                let (mut xp, mut up) = (x.clone(), u);
                if j < 6 {
                    xp[j] += 1e-7
                } else {
                    up[j - 6] += 1e-7
                }
                acc += sim.step(&xp, &up).unwrap().x_next[0] - base[0];
            }
            black_box(acc)
        })
    });
    group.finish();
}

criterion_group!(benches, step);
criterion_main!(benches);
