//! The optimiser section of `cargo xtask benchmarks`: the unicycle benchmark (free and boxed), the finger
//! at several noise levels with full DDP and Gauss-Newton iLQR, and where a finger solve spends its time.

use ddp::problems::Unicycle;
use ddp::{
    ControlLimits, Ddp, DdpSettings, Dynamics, Method, Regularisation, SecondOrder, Solution,
};
use dynamics::{Complementarity, Scene, Simulator, StepSettings};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;
use task::{ProblemFile, SceneDynamics};

/// Dynamics that time every call of the wrapped ones (nanoseconds, summed over threads).
struct Timed<D> {
    inner: D,
    step: AtomicU64,
    first: AtomicU64,
    second: AtomicU64,
    /// Of `second`, the time in the knots' preparation.
    prepare: AtomicU64,
    second_calls: AtomicU64,
}

impl<D> Timed<D> {
    fn new(inner: D) -> Self {
        Timed {
            inner,
            step: AtomicU64::new(0),
            first: AtomicU64::new(0),
            second: AtomicU64::new(0),
            prepare: AtomicU64::new(0),
            second_calls: AtomicU64::new(0),
        }
    }

    /// `f`, its time added to `clock`.
    fn timed<R>(clock: &AtomicU64, f: impl FnOnce() -> R) -> R {
        let t = Instant::now();
        let r = f();
        clock.fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
        r
    }

    /// The time `clock` summed, in milliseconds.
    fn ms(clock: &AtomicU64) -> f64 {
        clock.load(Ordering::Relaxed) as f64 * 1e-6
    }
}

impl<D: Dynamics> Dynamics for Timed<D> {
    type Error = D::Error;
    type Data = D::Data;
    fn state_dim(&self) -> usize {
        self.inner.state_dim()
    }
    fn control_dim(&self) -> usize {
        self.inner.control_dim()
    }
    fn create_data(&self) -> D::Data {
        self.inner.create_data()
    }
    fn calc(
        &self,
        data: &mut D::Data,
        near: Option<&D::Data>,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), D::Error> {
        Self::timed(&self.step, || self.inner.calc(data, near, x, u, next))
    }
    fn calc_diff(
        &self,
        data: &mut D::Data,
        x: &[f64],
        u: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), D::Error> {
        Self::timed(&self.first, || self.inner.calc_diff(data, x, u, fx, fu))
    }
    fn second_order(&self) -> Option<&dyn SecondOrder<D::Data, Error = D::Error>> {
        self.inner.second_order()?;
        Some(self)
    }
}

impl<D: Dynamics> Timed<D> {
    fn inner_second(&self) -> &dyn SecondOrder<D::Data, Error = D::Error> {
        self.inner
            .second_order()
            .expect("asked only through Timed::second_order, which checked it")
    }
}

impl<D: Dynamics> SecondOrder<D::Data> for Timed<D> {
    type Error = D::Error;
    fn calc_diff2_prepare(&self, data: &mut D::Data, x: &[f64], u: &[f64]) -> Result<(), D::Error> {
        let t = Instant::now();
        let r = self.inner_second().calc_diff2_prepare(data, x, u);
        let ns = t.elapsed().as_nanos() as u64;
        self.second.fetch_add(ns, Ordering::Relaxed);
        self.prepare.fetch_add(ns, Ordering::Relaxed);
        r
    }
    fn calc_diff2(
        &self,
        data: &mut D::Data,
        x: &[f64],
        u: &[f64],
        c: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), D::Error> {
        self.second_calls.fetch_add(1, Ordering::Relaxed);
        Self::timed(&self.second, || {
            self.inner_second().calc_diff2(data, x, u, c, fx, fu, hess)
        })
    }
}

fn finger(sigma: f64) -> SceneDynamics {
    SceneDynamics::new(
        Simulator::new(
            ProblemFile::builtin().scene,
            StepSettings {
                model: Complementarity::Logistic { sigma },
                ..StepSettings::default()
            },
        )
        .expect("valid settings"),
    )
}

fn settings(method: Method, regularisation: Regularisation) -> DdpSettings {
    DdpSettings {
        method,
        regularisation,
        max_iterations: 300,
        ..DdpSettings::default()
    }
}

/// Solve the finger from SCENE.md's x0 with zero controls; the solution and the wall time.
fn solve_finger(
    sigma: f64,
    s: DdpSettings,
) -> anyhow::Result<(Solution, f64, Timed<SceneDynamics>)> {
    let d = Timed::new(finger(sigma));
    let task = ProblemFile::builtin_task().1;
    let t = Instant::now();
    let sol = Ddp::new(s)?.solve(&d, &task.cost, &task.x0, &vec![vec![0.0; 2]; 75])?;
    Ok((sol, t.elapsed().as_secs_f64(), d))
}

fn max_gain(sol: &Solution) -> f64 {
    sol.gains
        .iter()
        .flatten()
        .fold(0.0f64, |m, k| m.max(k.abs()))
}

/// crocoddyl's solvers on the same unicycle in the same run (`xtask/scripts/crocoddyl_unicycle.py`, with
/// the Python of `SLCP_PYTHON`, default `python3`), as rows of the unicycle table; a line saying why not
/// when crocoddyl is not importable.
fn crocoddyl_rows() -> String {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/crocoddyl_unicycle.py");
    let lines = match super::run_python(script, &["21"]) {
        Ok(lines) => lines,
        Err((python, why)) => {
            return format!(
                "\ncrocoddyl not run ({python}: {why}; `pip install crocoddyl` and set SLCP_PYTHON to compare in the same run).\n"
            );
        }
    };
    let mut rows = String::new();
    for line in lines.lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let (Some(name), Some(iterations), Some(cost), Some(ms), Some(version)) = (
            v["solver"].as_str(),
            v["iterations"].as_u64(),
            v["cost"].as_f64(),
            v["ms"].as_f64(),
            v["version"].as_str(),
        ) else {
            continue;
        };
        rows.push_str(&format!(
            "| crocoddyl {version} {name} (Gauss-Newton: no second derivatives of the dynamics), from Python, median of 21 | free | {iterations} | - | {cost:.12e} | {ms:.2} | {:.0} |\n",
            ms * 1e3 / iterations.max(1) as f64
        ));
    }
    rows
}

pub fn section() -> anyhow::Result<String> {
    let mut out = String::new();
    out.push_str("The unicycle benchmark of the ddp issue: x0 = [-1, -1, 1], dt = 0.1, T = 75, running cost 50 |x|^2 + 0.5 |u|^2 (not scaled by dt), final 50 |x_T|^2, zero initial controls (`cargo xtask optimize --problem unicycle [--method ilqr] [--regularisation control] [--limit 2]`). Time: median of 21 solves, as for crocoddyl below. The regularisation is the state one (`Q_uu + mu f_u^T f_u`) unless the row says control (`Q_uu + mu I`, as crocoddyl regularises). With the state one, full DDP's `V_x f_xx` terms keep `V_xx` indefinite early on, so `mu` climbs to about 1e4 and the first twenty passes are small steps; with the control one the same optimum takes 15 passes.\n\n| method | controls | passes | status | final cost | solve (ms) | per pass (us) |\n|---|---|---:|---|---:|---:|---:|\n");
    for (method, regularisation, name) in [
        (Method::Full, Regularisation::State, "full DDP"),
        (
            Method::Full,
            Regularisation::Control,
            "full DDP, control reg.",
        ),
        (Method::GaussNewton, Regularisation::State, "iLQR"),
    ] {
        for limit in [None, Some(2.0)] {
            let s = DdpSettings {
                method,
                regularisation,
                control_limits: limit.map(|l| ControlLimits {
                    lower: vec![-l; 2],
                    upper: vec![l; 2],
                }),
                ..DdpSettings::default()
            };
            let ddp = Ddp::new(s)?;
            let mut times = Vec::new();
            let mut last = None;
            for _ in 0..21 {
                let t = Instant::now();
                let sol = ddp.solve(
                    &Unicycle { dt: 0.1 },
                    &Unicycle::benchmark_cost(),
                    &Unicycle::X0,
                    &vec![vec![0.0; 2]; Unicycle::HORIZON],
                )?;
                times.push(t.elapsed().as_secs_f64());
                last = Some(sol);
            }
            times.sort_by(f64::total_cmp);
            let sol = last.expect("five solves");
            let ms = times[2] * 1e3;
            out.push_str(&format!(
                "| {name} | {} | {} | {:?} | {:.12e} | {ms:.2} | {:.0} |\n",
                limit.map_or("free".to_string(), |l| format!("|u| <= {l}")),
                sol.iterations.len(),
                sol.status,
                sol.cost,
                ms * 1e3 / sol.iterations.len() as f64
            ));
        }
    }
    out.push_str(&crocoddyl_rows());

    out.push_str("\nThe flicking finger (SCENE.md: logistic model, h = 0.05, N = 75, cost -theta3 + 0.05 |u|^2, x0 at rest, zero initial controls; `cargo xtask optimize [--sigma S] [--method ilqr] [--regularisation control]`), at most 300 passes. theta3 is the ellipse's turn over the horizon; |K| the largest feedback gain of the returned policy (zero for iLQR: with no state Hessian in the cost, V_xx stays zero).\n\n| method | sigma | passes | status | cost | theta3 turned | max abs K | solve (ms) | per pass (ms) |\n|---|---:|---:|---|---:|---:|---:|---:|---:|\n");
    let runs = [
        (Method::Full, Regularisation::State, "full DDP", 0.2),
        (Method::Full, Regularisation::State, "full DDP", 0.1),
        (Method::Full, Regularisation::State, "full DDP", 0.05),
        (Method::Full, Regularisation::State, "full DDP", 0.02),
        (
            Method::Full,
            Regularisation::Control,
            "full DDP, control reg.",
            0.1,
        ),
        (Method::GaussNewton, Regularisation::State, "iLQR", 0.1),
        (
            Method::GaussNewton,
            Regularisation::Control,
            "iLQR, control reg.",
            0.1,
        ),
    ];
    let mut profile = None;
    for (method, reg, name, sigma) in runs {
        let (sol, secs, timed) = solve_finger(sigma, settings(method, reg))?;
        let turned = sol.states[75][2] - sol.states[0][2];
        out.push_str(&format!(
            "| {name} | {sigma} | {} | {:?} | {:.6} | {turned:.3} | {:.1e} | {:.0} | {:.2} |\n",
            sol.iterations.len(),
            sol.status,
            sol.cost,
            max_gain(&sol),
            secs * 1e3,
            secs * 1e3 / sol.iterations.len() as f64
        ));
        if method == Method::Full && sigma == 0.1 && reg == Regularisation::State {
            profile = Some((sol.iterations.len(), secs, timed));
        }
    }
    // The pass count is sensitive to the path (a non-convex problem: rounding-level changes pick another
    // sequence of regularisations and sometimes another local minimum), so also over perturbed starts.
    let mut passes = Vec::new();
    let mut times = Vec::new();
    let mut costs = Vec::new();
    let task = ProblemFile::builtin_task().1;
    for k in 0..8 {
        let mut x0 = task.x0.clone();
        x0[0] += 0.01 * (k as f64 - 3.5);
        x0[5] += 0.02 * (k % 3) as f64;
        let t = Instant::now();
        let sol = Ddp::new(settings(Method::Full, Regularisation::State))?.solve(
            &finger(0.1),
            &task.cost,
            &x0,
            &vec![vec![0.0; 2]; 75],
        )?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        passes.push(sol.iterations.len());
        costs.push(sol.cost);
    }
    let mut sorted_passes = passes.clone();
    sorted_passes.sort();
    times.sort_by(f64::total_cmp);
    costs.sort_by(f64::total_cmp);
    out.push_str(&format!(
        "\nFull DDP at sigma = 0.1 from 8 starts around x0 (theta1 shifted by -0.035..0.035, dtheta3 by 0, 0.02, 0.04): passes {passes:?} (median {}), solve time median {:.0} ms (min {:.0}, max {:.0}), cost from {:.3} to {:.3}.\n",
        sorted_passes[4],
        times[4],
        times[0],
        times[7],
        costs[0],
        costs[7]
    ));

    // One pass from a trajectory midway through a solve: a one-pass solve minus its initial rollout.
    let (cost, x0) = (task.cost.clone(), task.x0.clone());
    let midway = Ddp::new(DdpSettings {
        max_iterations: 30,
        ..DdpSettings::default()
    })?
    .solve(&finger(0.1), &cost, &x0, &vec![vec![0.0; 2]; 75])?
    .controls;
    let median_ms = |f: &mut dyn FnMut()| {
        let mut t: Vec<f64> = (0..21)
            .map(|_| {
                let s = Instant::now();
                f();
                s.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        t.sort_by(f64::total_cmp);
        t[10]
    };
    let rollout = median_ms(&mut || {
        ddp::rollout(&finger(0.1), &cost, &x0, &midway).expect("the midway controls run");
    });
    out.push_str(&format!(
        "
One pass (backward pass with the steps' derivatives, then the forward pass with its line search) from the trajectory 30 full-DDP passes into the solve at sigma = 0.1, median of 21: a one-pass solve minus its initial rollout ({rollout:.2} ms for 75 steps).

| method | pass (ms) | step size accepted | line-search trials |
|---|---:|---:|---:|
"
    ));
    for (name, method) in [("full DDP", Method::Full), ("iLQR", Method::GaussNewton)] {
        let ddp = Ddp::new(DdpSettings {
            method,
            max_iterations: 1,
            ..DdpSettings::default()
        })?;
        let mut alpha = 0.0;
        let pass = median_ms(&mut || {
            let sol = ddp
                .solve(&finger(0.1), &cost, &x0, &midway)
                .expect("one pass");
            alpha = sol.iterations[0].alpha;
        }) - rollout;
        // Step sizes are 10^(-3 k / 10): the accepted one tells how many were tried.
        let trials = if alpha > 0.0 {
            format!("{}", (-alpha.log10() * 10.0 / 3.0).round() as i64 + 1)
        } else {
            "11 (none accepted)".into()
        };
        out.push_str(&format!(
            "| {name} | {pass:.2} | {alpha:.3} | {trials} |
"
        ));
    }
    out.push_str(&scenes_pass_table()?);
    if let Some((passes, secs, t)) = profile {
        let total = secs * 1e3;
        let second = Timed::<SceneDynamics>::ms(&t.second);
        let step = Timed::<SceneDynamics>::ms(&t.step);
        let rest = total - second - step - Timed::<SceneDynamics>::ms(&t.first);
        out.push_str(&format!(
            "\nWhere the time of the full-DDP solve at sigma = 0.1 goes ({passes} passes, {total:.0} ms): second derivatives of the steps (`SceneDynamics`'s `calc_diff2_prepare` and `calc_diff2`: one `Model::second_order` per step and trajectory (of the step the forward pass stored in the knot's data, not solved again), kept in the knot's data, then a cheap contraction per backward attempt; {} calls) {second:.0} ms ({:.0}%), steps of the forward passes and line searches {step:.0} ms ({:.0}%), the optimiser's own backward-pass algebra, box QP and bookkeeping {rest:.0} ms ({:.0}%).\n",
            t.second_calls.load(Ordering::Relaxed),
            100.0 * second / total,
            100.0 * step / total,
            100.0 * rest / total
        ));
    }
    Ok(out)
}

/// One full-DDP pass (as in the table above: a one-pass solve from the trajectory 30 passes into a solve,
/// minus its rollout) on the finger and on the three-link finger (`scenes/three_link_finger.toml`: 4
/// joints, 3 controls, 8 states) with the cost `-angle of the free body + 0.05 |u|^2`, and on the two
/// fingers and the pushing scene with their tasks' costs; N = 75, logistic sigma = 0.1; median of 21.
fn scenes_pass_table() -> anyhow::Result<String> {
    let mut out = String::from(
        "\nOne full-DDP pass (as above) on scenes of other sizes, N = 75, logistic sigma = 0.1, cost -(angle of the free body) + 0.05 |u|^2 from rest (two fingers and pushing: their tasks' costs and initial states), median of 21, with the knots on one thread and on two (`--threads 2`: the same pass to the last bit). Only the knots' second-order preparation is shared out, the first half of the knots on the calling thread and the second on a pool thread (its share of the one-thread pass in the column before last, the most two threads can halve); the rollouts of the line search and the backward recursion stay sequential, so the speed-up is at most 1 / (1 - share / 2), and the second thread reads the knots the forward pass wrote on the first, from the other core's cache. On this shared 2-core machine the speed-up moves with the other core's load from run to run (the finger's 0.93 to 1.08 over five runs of this build; over the four scenes 0.93 to 1.35 with this build, 0.70 to 1.02 with the build before the calling thread took part):\n\n| scene | states / controls | pass (ms) | per knot (us) | pass on 2 threads (ms) | speed-up | preparation's share | passes to get there |\n|---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    // The two spin tasks' costs (-(the ellipse's angle) + 0.05 |u|^2); the three-link finger from a
    // start of its own, bent further than its task's.
    let (finger, spin) = ProblemFile::builtin_task();
    let three = ProblemFile::from_toml_str(include_str!("../../../scenes/three_link_finger.toml"))?;
    let three_spin = three.task(Some("spin"))?;
    let cases = [
        ("finger (SCENE.md)", finger, spin.x0.clone(), spin.cost),
        (
            "three-link finger (three_link_finger.toml)",
            three.scene,
            vec![-1.2, -0.6, -0.8, 0.0, 0.0, 0.0, 0.0, 0.0],
            three_spin.cost,
        ),
    ];
    for (name, scene, x0, cost) in cases {
        out.push_str(&pass_row(name, &scene, &x0, &cost)?);
    }
    // The two target tasks on their own costs and initial states.
    for (name, text, task) in [
        (
            "two fingers (two_fingers.toml, its task turn)",
            include_str!("../../../scenes/two_fingers.toml"),
            "turn",
        ),
        (
            "pushing (pushing.toml, its task push)",
            include_str!("../../../scenes/pushing.toml"),
            "push",
        ),
    ] {
        let file = task::ProblemFile::from_toml_str(text)?;
        let task = file.task(Some(task))?;
        out.push_str(&pass_row(name, &file.scene, &task.x0, &task.cost)?);
    }
    Ok(out)
}

/// One row of [`scenes_pass_table`]: a one-pass solve from the trajectory 30 passes into a solve of `cost`
/// from `x0` (zero controls), minus its rollout, median of 21.
fn pass_row<C: ddp::Cost>(
    name: &str,
    scene: &Scene,
    x0: &[f64],
    cost: &C,
) -> anyhow::Result<String> {
    let (n, m) = (scene.n_dof(), scene.n_controls);
    let settings = StepSettings {
        model: Complementarity::Logistic { sigma: 0.1 },
        ..StepSettings::default()
    };
    let make = || -> anyhow::Result<SceneDynamics> {
        Ok(SceneDynamics::new(Simulator::new(scene.clone(), settings)?))
    };
    let before = Ddp::new(DdpSettings {
        max_iterations: 30,
        ..DdpSettings::default()
    })?
    .solve(&make()?, cost, x0, &vec![vec![0.0; m]; 75])?;
    let midway = before.controls;
    // A solve of at most `max_iterations` passes (0: the rollout alone) with the knots on `threads`
    // threads: its time and the time in the knots' second-order preparation (the stage shared out).
    let run = |max_iterations: usize, threads: usize| -> anyhow::Result<(f64, f64)> {
        let d = Timed::new(make()?);
        let s = Instant::now();
        if max_iterations == 0 {
            ddp::rollout(&d, cost, x0, &midway)
                .map_err(|(i, e)| anyhow::anyhow!("step {i}: {e}"))?;
        } else {
            Ddp::new(DdpSettings {
                max_iterations,
                threads,
                ..DdpSettings::default()
            })?
            .solve(&d, cost, x0, &midway)?;
        }
        let ms = s.elapsed().as_secs_f64() * 1e3;
        Ok((ms, Timed::<SceneDynamics>::ms(&d.prepare)))
    };
    // Median of 21 of each, the three taken in turn so that the machine's drift (it varies up to 2x
    // between hours) falls on all of them alike.
    let (mut rollouts, mut ones, mut twos, mut prepares) = (vec![], vec![], vec![], vec![]);
    for _ in 0..21 {
        rollouts.push(run(0, 1)?.0);
        let (one, prepare) = run(1, 1)?;
        ones.push(one);
        prepares.push(prepare);
        twos.push(run(1, 2)?.0);
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let rollout = median(rollouts);
    let pass = median(ones) - rollout;
    let two = median(twos) - rollout;
    let prepare = median(prepares);
    Ok(format!(
        "| {name} | {} / {m} | {pass:.2} | {:.1} | {two:.2} | {:.2} | {:.0}% | {} |\n",
        2 * n,
        pass * 1e3 / 75.0,
        pass / two,
        100.0 * prepare / pass,
        before.iterations.len()
    ))
}
