//! The complementarity section of `cargo xtask benchmarks`: one contact step's mixed LCP (3 free rows, 6
//! complementarity rows, `ncp::instances::contact_step`) solved by each model, warm and cold, against the
//! exact hard solution.

use ncp::instances::{contact_step, perturbed};
use ncp::{
    DenseLu, ErmSettings, ErmSolver, LemkeSettings, LinearMcp, LinearSolver, NcpFunction,
    NewtonSettings, NewtonSolver, Solution, Status, lemke,
};
use std::hint::black_box;
use std::time::Instant;

/// Problems per measurement.
const PROBLEMS: u64 = 256;

/// How a model is solved.
#[derive(Debug, Clone, Copy)]
enum Method {
    Newton(NcpFunction, LinearSolver),
    Erm(f64),
    Lemke,
}

impl Method {
    fn name(&self) -> String {
        match *self {
            Method::Newton(f, solver) => {
                let back = if solver == LinearSolver::Faer {
                    ", faer LU"
                } else {
                    ""
                };
                match f {
                    NcpFunction::Min => format!("hard, Newton on min{back}"),
                    NcpFunction::FischerBurmeister => {
                        format!("hard, Newton on Fischer-Burmeister{back}")
                    }
                    NcpFunction::Logistic { sigma } => {
                        format!("logistic (eq. 17), sigma = {sigma}{back}")
                    }
                    NcpFunction::Normal { sigma } => {
                        format!("normal mean (fn. 3), sigma = {sigma}{back}")
                    }
                }
            }
            Method::Erm(sigma) => format!("normal ERM (eq. 14+15), sigma = {sigma}"),
            Method::Lemke => "hard, Lemke (exact reference)".into(),
        }
    }
}

/// A reusable solver for one method.
struct Runner {
    method: Method,
    newton: NewtonSolver,
    erm: ErmSolver,
}

impl Runner {
    fn new(method: Method) -> anyhow::Result<Self> {
        let solver = match method {
            Method::Newton(_, s) => s,
            _ => LinearSolver::Hand,
        };
        Ok(Runner {
            method,
            newton: NewtonSolver::new(NewtonSettings {
                linear_solver: solver,
                ..NewtonSettings::default()
            })?,
            erm: ErmSolver::new(ErmSettings::default())?,
        })
    }

    /// Solve from `z` in place; returns (status, iterations, residual).
    fn solve(&mut self, p: &LinearMcp, z: &mut [f64]) -> (Status, usize, f64) {
        match self.method {
            Method::Newton(f, _) => {
                let info = self
                    .newton
                    .solve_in_place(p, &[f; 6], z)
                    .expect("well-posed problem");
                (info.status, info.iterations, info.residual)
            }
            Method::Erm(sigma) => {
                let s = self
                    .erm
                    .solve(p, &[sigma; 6], z)
                    .expect("well-posed problem");
                z.copy_from_slice(&s.z);
                (s.info.status, s.info.iterations, s.info.residual)
            }
            Method::Lemke => {
                let s: Solution = lemke(p, &LemkeSettings::default()).expect("solvable problem");
                z.copy_from_slice(&s.z);
                (s.info.status, s.info.iterations, s.info.residual)
            }
        }
    }
}

/// Median of a sample.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Nanoseconds per solve of `p` from `start`, median of 7 batches of `reps`.
fn time_solve(runner: &mut Runner, p: &LinearMcp, start: &[f64], reps: usize) -> f64 {
    let mut z = start.to_vec();
    let batches: Vec<f64> = (0..7)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..reps {
                z.copy_from_slice(start);
                black_box(runner.solve(black_box(p), &mut z));
            }
            t.elapsed().as_nanos() as f64 / reps as f64
        })
        .collect();
    median(batches)
}

struct RowResult {
    name: String,
    warm_ns: f64,
    cold_ns: f64,
    warm_iter: f64,
    cold_iter: f64,
    residual: f64,
    velocity_gap: f64,
    failures: usize,
}

fn measure(method: Method, hard: &[Vec<f64>]) -> anyhow::Result<RowResult> {
    let mut runner = Runner::new(method)?;
    let reps = if matches!(method, Method::Erm(_) | Method::Lemke) {
        20
    } else {
        100
    };
    let (mut warm_ns, mut cold_ns, mut warm_it, mut cold_it) = (vec![], vec![], 0usize, 0usize);
    let (mut residual, mut gap, mut failures) = (0.0f64, 0.0f64, 0);
    for seed in 0..PROBLEMS {
        let p = contact_step(seed);
        // The warm start: this model's solution of the previous step, q moved by 1e-3 relative.
        let previous = perturbed(&p, 1e-3, seed);
        let mut warm = vec![0.0; 9];
        runner.solve(&previous, &mut warm);
        let cold = vec![0.0; 9];
        let mut z = warm.clone();
        let (status, it, res) = runner.solve(&p, &mut z);
        if status != Status::Converged {
            failures += 1;
        }
        warm_it += it;
        residual = residual.max(res / (1.0 + z.iter().fold(0.0f64, |m, v| m.max(v.abs()))));
        gap = gap.max(
            z[..3]
                .iter()
                .zip(&hard[seed as usize][..3])
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs())),
        );
        let mut zc = cold.clone();
        cold_it += runner.solve(&p, &mut zc).1;
        warm_ns.push(time_solve(&mut runner, &p, &warm, reps));
        cold_ns.push(time_solve(&mut runner, &p, &cold, reps));
    }
    let n = PROBLEMS as f64;
    Ok(RowResult {
        name: method.name(),
        warm_ns: median(warm_ns),
        cold_ns: median(cold_ns),
        warm_iter: warm_it as f64 / n,
        cold_iter: cold_it as f64 / n,
        residual,
        velocity_gap: gap,
        failures,
    })
}

/// Median nanoseconds of one factor-and-solve of an `n x n` Newton-like matrix (diagonally dominant random).
fn lu_ns(solver: LinearSolver, n: usize) -> f64 {
    let mut rng = ncp::instances::SplitMix64::new(n as u64);
    let mut jac: Vec<f64> = (0..n * n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    for i in 0..n {
        jac[i * n + i] += n as f64;
    }
    let f: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let mut lu = DenseLu::new(n, solver);
    let reps = 20_000;
    let mut rhs = f.clone();
    let batches: Vec<f64> = (0..21)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..reps {
                lu.factor(black_box(&jac)).unwrap();
                rhs.copy_from_slice(&f);
                lu.solve(&mut rhs);
                black_box(&rhs);
            }
            t.elapsed().as_nanos() as f64 / reps as f64
        })
        .collect();
    median(batches)
}

pub fn section() -> anyhow::Result<String> {
    let hard: Vec<Vec<f64>> = (0..PROBLEMS)
        .map(|seed| lemke(&contact_step(seed), &LemkeSettings::default()).map(|s| s.z))
        .collect::<Result<_, _>>()?;
    let mut methods = vec![
        Method::Lemke,
        Method::Newton(NcpFunction::FischerBurmeister, LinearSolver::Hand),
        Method::Newton(NcpFunction::Min, LinearSolver::Hand),
    ];
    for sigma in [1.0, 0.1, 1e-2, 1e-3] {
        methods.push(Method::Newton(
            NcpFunction::Logistic { sigma },
            LinearSolver::Hand,
        ));
    }
    methods.push(Method::Newton(
        NcpFunction::Logistic { sigma: 0.1 },
        LinearSolver::Faer,
    ));
    for sigma in [1.0, 0.1, 1e-2, 1e-3] {
        methods.push(Method::Newton(
            NcpFunction::Normal { sigma },
            LinearSolver::Hand,
        ));
    }
    for sigma in [1.0, 0.1, 1e-2, 1e-3] {
        methods.push(Method::Erm(sigma));
    }
    let mut out = String::new();
    out.push_str(&format!(
        "{PROBLEMS} random contact steps (`ncp::instances::contact_step`, seeds 0..{PROBLEMS}: 3 velocities, 4 joint-limit rows, 2 friction-cone rows, some in penetration). Warm: started from the same model's solution of the previous step (q moved by 1e-3 relative, `instances::perturbed`); cold: from zero. Times are medians over the problems of the median of 7 batches. Residual: worst final residual relative to 1 + max|z| (NCP residual for Newton, projected gradient for ERM, max|min(z, w)| for Lemke). Velocity gap: worst max|v' - v'_hard| against Lemke's exact solution (velocities are unique; impulses need not be when four rows are active).\n\n"
    ));
    out.push_str("| model and method | warm (ns) | cold (ns) | warm iterations | cold iterations | residual | velocity gap to hard | not converged |\n|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for m in methods {
        let r = measure(m, &hard)?;
        out.push_str(&format!(
            "| {} | {:.0} | {:.0} | {:.2} | {:.2} | {:.1e} | {:.1e} | {} |\n",
            r.name,
            r.warm_ns,
            r.cold_ns,
            r.warm_iter,
            r.cold_iter,
            r.residual,
            r.velocity_gap,
            r.failures
        ));
    }
    out.push_str("\nDense LU, factor + solve of one right-hand side, at the sizes of a step (6 to 12 unknowns) and beyond; faer is `lu_in_place` + `solve_in_place` with a preallocated workspace and `Par::Seq`:\n\n| n | hand-written (ns) | faer (ns) |\n|---:|---:|---:|\n");
    for n in [6, 9, 12, 24, 48] {
        out.push_str(&format!(
            "| {n} | {:.0} | {:.0} |\n",
            lu_ns(LinearSolver::Hand, n),
            lu_ns(LinearSolver::Faer, n)
        ));
    }
    out.push_str("\nAt a step's sizes faer's per-call overhead dominates the arithmetic, so the hand-written kernel is the default (`LinearSolver::Hand`); the faer row of the table above shows what the choice is worth in a whole solve.\n");
    out.push_str("\nLemke's method at sizes up to its limit (`LemkeSettings::max_size`, 500 rows), on planted positive definite LCPs (`instances::planted_lcp`, seed 7), one solve each: the basis is factored from the original data every 32 pivots and the pivots in between kept in product form (O(n^2) each), and a degenerate pivot's tie is broken on the tied rows of the inverse alone (one transposed solve each); before issue 27 it refactored at every pivot, O(n^4), and 400 rows took about a minute. Error: max |z - z_planted| relative to the data's scale.\n\n| rows | pivots | time (ms) | error |\n|---:|---:|---:|---:|\n");
    for n in [50, 100, 200, 400, 500] {
        let (p, planted) =
            ncp::instances::planted_lcp(ncp::instances::MatrixKind::PositiveDefinite, n, 7);
        let t = Instant::now();
        let s = lemke(&p, &LemkeSettings::default())?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let error =
            s.z.iter()
                .zip(&planted)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
                / p.scale();
        out.push_str(&format!(
            "| {n} | {} | {ms:.1} | {error:.1e} |\n",
            s.info.iterations
        ));
    }
    Ok(out)
}
