//! The unicycle benchmark of the ddp issue, as other DDP libraries publish it: state [px, py, theta],
//! control [v, w], explicit Euler with dt = 0.1, running cost 50 |x|^2 + 0.5 |u|^2 per step (not scaled by
//! dt), final cost 50 |x_T|^2, T = 75, x0 = [-1, -1, 1], zero initial controls; free and with |u_i| <= 2.
//!
//! `cargo run --release -p ddp --example unicycle`

use ddp::problems::Unicycle;
use ddp::{ControlLimits, Ddp, DdpSettings, Method};
use std::time::Instant;

fn main() -> Result<(), ddp::DdpError> {
    for (name, method) in [("full DDP", Method::Full), ("iLQR", Method::GaussNewton)] {
        for limit in [None, Some(2.0)] {
            let settings = DdpSettings {
                method,
                control_limits: limit.map(|l: f64| ControlLimits {
                    lower: vec![-l; 2],
                    upper: vec![l; 2],
                }),
                ..DdpSettings::default()
            };
            let start = Instant::now();
            let solution = Ddp::new(settings)?.solve(
                &Unicycle { dt: 0.1 },
                &Unicycle::benchmark_cost(),
                &Unicycle::X0,
                &vec![vec![0.0; 2]; Unicycle::HORIZON],
            )?;
            let seconds = start.elapsed().as_secs_f64();
            println!(
                "{name:8} {:10} {:?} after {:3} passes: cost {:.12e} in {:.2} ms; |x_T| = {:.3e}",
                limit.map_or("free".to_string(), |l| format!("|u| <= {l}")),
                solution.status,
                solution.iterations.len(),
                solution.cost,
                seconds * 1e3,
                solution.states[Unicycle::HORIZON]
                    .iter()
                    .map(|e| e * e)
                    .sum::<f64>()
                    .sqrt()
            );
        }
    }
    Ok(())
}
