//! The optimiser on the flicking finger (SCENE.md, logistic sigma = 0.1, N = 75): one pass (backward pass
//! with the steps' derivatives, then the forward pass with its line search) from a trajectory midway
//! through a solve, for full DDP and for iLQR; and a full-DDP solve from zero controls.
//! `cargo bench -p library`.

use criterion::{Criterion, criterion_group, criterion_main};
use ddp::{Ddp, DdpSettings, Method};
use dynamics::{Simulator, StepSettings};
use std::hint::black_box;
use task::{ProblemFile, SceneDynamics};

fn finger() -> SceneDynamics {
    SceneDynamics::new(
        Simulator::new(ProblemFile::builtin().scene, StepSettings::default()).unwrap(),
    )
}

fn optimise(c: &mut Criterion) {
    // scenes/finger.toml's spin task: -theta3 + 0.05 |u|^2 per step, from the finger apart at rest.
    let task = ProblemFile::builtin_task().1;
    let (cost, x0) = (task.cost, task.x0);
    // A trajectory midway: 30 passes of full DDP from zero controls.
    let midway = Ddp::new(DdpSettings {
        max_iterations: 30,
        ..DdpSettings::default()
    })
    .unwrap()
    .solve(&finger(), &cost, &x0, &vec![vec![0.0; 2]; 75])
    .unwrap()
    .controls;
    let mut group = c.benchmark_group("finger");
    for (name, method) in [
        ("full_ddp_pass", Method::Full),
        ("ilqr_pass", Method::GaussNewton),
    ] {
        // One pass; Ddp::solve also rolls the start out once (75 steps, about 0.25 ms of the time).
        let ddp = Ddp::new(DdpSettings {
            method,
            max_iterations: 1,
            ..DdpSettings::default()
        })
        .unwrap();
        group.bench_function(name, |b| {
            b.iter(|| {
                let d = finger();
                black_box(ddp.solve(&d, &cost, &x0, &midway).unwrap().cost)
            })
        });
    }
    group.sample_size(10);
    let ddp = Ddp::new(DdpSettings::default()).unwrap();
    group.bench_function("full_ddp_solve_from_zero", |b| {
        b.iter(|| {
            let d = finger();
            let sol = ddp.solve(&d, &cost, &x0, &vec![vec![0.0; 2]; 75]).unwrap();
            black_box(sol.cost)
        })
    });
}

criterion_group!(benches, optimise);
criterion_main!(benches);
