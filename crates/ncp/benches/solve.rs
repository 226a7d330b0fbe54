//! One contact step's complementarity problem (3 free rows, 6 complementarity rows) per model, warm-started
//! from the solution of the previous step, and the dense LU at that size. `cargo bench -p ncp`.

use criterion::{Criterion, criterion_group, criterion_main};
use ncp::instances::{contact_step, perturbed};
use ncp::{
    DenseLu, ErmSettings, ErmSolver, LemkeSettings, LinearMcp, LinearSolver, Mcp, NcpFunction,
    NewtonSettings, NewtonSolver, lemke,
};
use std::hint::black_box;

/// Problems and the warm starts (each model's solution of the previous step, q moved by 1e-3).
fn problems(f: NcpFunction) -> Vec<(LinearMcp, Vec<f64>)> {
    let mut solver = NewtonSolver::new(NewtonSettings::default()).unwrap();
    (0..64)
        .map(|seed| {
            let p = contact_step(seed);
            let previous = perturbed(&p, 1e-3, seed);
            let warm = solver.solve(&previous, &[f; 6], &[0.0; 9]).unwrap().z;
            (p, warm)
        })
        .collect()
}

fn newton(c: &mut Criterion) {
    let mut group = c.benchmark_group("ncp_step_warm");
    let models = [
        ("logistic_0.1", NcpFunction::Logistic { sigma: 0.1 }),
        ("logistic_0.01", NcpFunction::Logistic { sigma: 0.01 }),
        ("normal_0.1", NcpFunction::Normal { sigma: 0.1 }),
        ("fischer_burmeister", NcpFunction::FischerBurmeister),
    ];
    for (name, f) in models {
        let set = problems(f);
        for solver_kind in [LinearSolver::Hand, LinearSolver::Faer] {
            let settings = NewtonSettings {
                linear_solver: solver_kind,
                ..NewtonSettings::default()
            };
            let mut solver = NewtonSolver::new(settings).unwrap();
            let mut z = vec![0.0; 9];
            let mut k = 0;
            let label = format!(
                "{name}_{}",
                if solver_kind == LinearSolver::Hand {
                    "hand"
                } else {
                    "faer"
                }
            );
            group.bench_function(label, |b| {
                b.iter(|| {
                    let (p, warm) = &set[k % set.len()];
                    k += 1;
                    z.copy_from_slice(warm);
                    black_box(solver.solve_in_place(p, &[f; 6], &mut z).unwrap())
                })
            });
        }
    }
    let set = problems(NcpFunction::Normal { sigma: 0.1 });
    let erm = ErmSolver::new(ErmSettings::default()).unwrap();
    let mut k = 0;
    group.bench_function("normal_erm_0.1", |b| {
        b.iter(|| {
            let (p, warm) = &set[k % set.len()];
            k += 1;
            black_box(erm.solve(p, &[0.1; 6], warm).unwrap())
        })
    });
    let mut k = 0;
    group.bench_function("lemke", |b| {
        b.iter(|| {
            let (p, _) = &set[k % set.len()];
            k += 1;
            black_box(lemke(p, &LemkeSettings::default()).unwrap())
        })
    });
    group.finish();
}

fn dense_lu(c: &mut Criterion) {
    let p = contact_step(1);
    let n = p.dim();
    let mut jac = vec![0.0; n * n];
    let mut f = vec![0.0; n];
    p.evaluate(&[0.5; 9], &mut f, Some(&mut jac));
    for i in 3..9 {
        jac[i * n + i] += 1.0;
    }
    let mut group = c.benchmark_group("dense_lu_9x9");
    for (name, kind) in [("hand", LinearSolver::Hand), ("faer", LinearSolver::Faer)] {
        let mut lu = DenseLu::new(n, kind);
        let mut rhs = f.clone();
        group.bench_function(name, |b| {
            b.iter(|| {
                lu.factor(black_box(&jac)).unwrap();
                rhs.copy_from_slice(&f);
                lu.solve(&mut rhs);
                black_box(rhs[0])
            })
        });
    }
    group.finish();
}

criterion_group!(benches, newton, dense_lu);
criterion_main!(benches);
