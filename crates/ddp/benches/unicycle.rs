//! The unicycle benchmark of the ddp issue, solved from zero controls with full DDP and with iLQR, free and
//! boxed to |u| <= 2: the same problem other DDP libraries publish numbers for. `cargo bench -p ddp`.

use criterion::{Criterion, criterion_group, criterion_main};
use ddp::problems::Unicycle;
use ddp::{ControlLimits, Ddp, DdpSettings, Method};
use std::hint::black_box;

fn unicycle(c: &mut Criterion) {
    let mut group = c.benchmark_group("unicycle_solve");
    for (name, method, limit) in [
        ("full", Method::Full, None),
        ("ilqr", Method::GaussNewton, None),
        ("full_boxed", Method::Full, Some(2.0)),
    ] {
        let ddp = Ddp::new(DdpSettings {
            method,
            control_limits: limit.map(|l: f64| ControlLimits {
                lower: vec![-l; 2],
                upper: vec![l; 2],
            }),
            ..DdpSettings::default()
        })
        .unwrap();
        group.bench_function(name, |b| {
            b.iter(|| {
                let sol = ddp
                    .solve(
                        &Unicycle { dt: 0.1 },
                        &Unicycle::benchmark_cost(),
                        &Unicycle::X0,
                        &vec![vec![0.0; 2]; Unicycle::HORIZON],
                    )
                    .unwrap();
                assert!(sol.status.converged());
                black_box(sol.cost)
            })
        });
    }
}

criterion_group!(benches, unicycle);
criterion_main!(benches);
