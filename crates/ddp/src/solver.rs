//! The optimiser: backward pass (paper eq. 11-12) with Levenberg-Marquardt regularisation of the value
//! Hessian, forward pass with a backtracking line search on the ratio of actual to expected reduction,
//! optional control limits (box QP), after Tassa, Erez and Todorov (IROS 2012) and Tassa, Mansard and
//! Todorov (ICRA 2014).

use crate::error::DdpError;
use crate::model::{Cost, Dynamics};
use crate::settings::{DdpSettings, FULL_DDP_MAX_BYTES, Method};
use crate::work::Workspace;
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex};

/// The relative cost change below which a rollout cannot tell improvement from rounding: dynamics whose
/// step is an iterative solve (a complementarity problem solved to about 1e-13) resolve a horizon's cost
/// to about 1e-12 relative, so a line search that finds no decrease where the model promised less than
/// this has converged rather than failed.
pub const RESOLUTION: f64 = 1e-10;

/// Pass records a solve reserves room for up front (its pass limit, up to this many): within them a pass
/// of the optimiser allocates nothing of its own; the dynamics' and the cost's calls are theirs.
const RESERVED_RECORDS: usize = 4096;

/// Why the optimiser stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Status {
    /// An accepted pass changed the cost by less than `tol_cost * (1 + |J|)`, or right after an accepted
    /// pass no step size reduced the cost where the model expected less than [`RESOLUTION`]
    /// `* (1 + |J|)` from its full step.
    CostConverged,
    /// The feedforward step became smaller than `tol_step`.
    StepConverged,
    /// `max_iterations` passes ran.
    MaxIterations,
    /// No step size reduced the cost and the regularisation reached `mu_max`.
    NoDescent,
    /// `Q_uu` stayed indefinite up to `mu_max`.
    RegularisationExceeded,
}

/// In user words: `cost converged`, `step converged`, `pass limit reached`, `no descent`,
/// `regularisation exceeded` (the serialised form keeps the variant's name).
impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Status::CostConverged => "cost converged",
            Status::StepConverged => "step converged",
            Status::MaxIterations => "pass limit reached",
            Status::NoDescent => "no descent",
            Status::RegularisationExceeded => "regularisation exceeded",
        })
    }
}

impl Status {
    /// Whether the optimiser converged.
    pub fn converged(self) -> bool {
        matches!(self, Status::CostConverged | Status::StepConverged)
    }
}

/// One pass of the optimiser.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Iteration {
    /// Cost after the pass.
    pub cost: f64,
    /// Actual reduction (0 when rejected).
    pub reduction: f64,
    /// Expected reduction at the accepted step size.
    pub expected: f64,
    /// Regularisation used by the backward pass.
    pub mu: f64,
    /// Accepted step size (0 when none was).
    pub alpha: f64,
    /// Mean relative feedforward size.
    pub step: f64,
}

impl Iteration {
    /// A pass that left the trajectory as it was (rejected, or converged before its forward pass).
    fn unchanged(cost: f64, mu: f64, step: f64) -> Self {
        Iteration {
            cost,
            reduction: 0.0,
            expected: 0.0,
            mu,
            alpha: 0.0,
            step,
        }
    }
}

/// The optimised trajectory and its time-varying linear policy `u = u_i + K_i (x - x_i)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Solution {
    /// `x_0 .. x_N`.
    pub states: Vec<Vec<f64>>,
    /// `u_0 .. u_{N-1}`.
    pub controls: Vec<Vec<f64>>,
    /// `K_i`, row-major `m x n`, from the backward pass at this trajectory.
    pub gains: Vec<Vec<f64>>,
    /// The local value model at each knot `i = 0 .. N`: the cost-to-go from `x_i` and the value's
    /// gradient and Hessian from the same backward pass as the gains, so that
    /// `V_i(x) ~ v_i + V_x,i . (x - x_i) + 1/2 (x - x_i)^T V_xx,i (x - x_i)`.
    pub values: Vec<ValueModel>,
    /// Total cost.
    pub cost: f64,
    /// One record per pass.
    pub iterations: Vec<Iteration>,
    /// Why it stopped.
    pub status: Status,
}

/// The second-order model of the cost-to-go around one knot of a trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ValueModel {
    /// The cost-to-go from the knot's state under the trajectory's controls.
    pub cost_to_go: f64,
    /// `V_x` (`n`).
    pub gradient: Vec<f64>,
    /// `V_xx`, row-major `n x n`, symmetric.
    pub hessian: Vec<f64>,
}

/// The process's pool of `threads` threads, started on first use and shared by every optimiser asking for
/// that many (a library builds thousands of optimisers, each solve a few milliseconds long).
fn shared_pool(threads: usize) -> Result<Arc<rayon::ThreadPool>, DdpError> {
    static POOLS: Mutex<Vec<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(Vec::new());
    let mut pools = POOLS
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((_, pool)) = pools.iter().find(|(t, _)| *t == threads) {
        return Ok(pool.clone());
    }
    // The calling thread differentiates a run of knots too: the pool holds the others.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads - 1)
        .thread_name(|i| format!("ddp-knots-{i}"))
        .build()
        .map_err(|e| DdpError::Input {
            what: "threads",
            problem: format!("could not be started: {e}"),
        })?;
    let pool = Arc::new(pool);
    pools.push((threads, pool.clone()));
    Ok(pool)
}

/// The optimiser. See the module documentation.
#[derive(Debug, Clone)]
pub struct Ddp {
    settings: DdpSettings,
    /// The threads the knots are differentiated on, when [`DdpSettings::threads`] is above 1.
    pool: Option<Arc<rayon::ThreadPool>>,
}

impl Ddp {
    /// An optimiser with checked settings (and its threads, when it has more than one).
    pub fn new(settings: DdpSettings) -> Result<Self, DdpError> {
        settings.validate()?;
        let pool = match settings.threads {
            1 => None,
            threads => Some(shared_pool(threads)?),
        };
        Ok(Ddp { settings, pool })
    }

    /// The settings.
    pub fn settings(&self) -> &DdpSettings {
        &self.settings
    }

    /// Minimise the cost from `x0` over `controls.len()` steps, starting from `controls`.
    pub fn solve<D: Dynamics, C: Cost>(
        &self,
        dynamics: &D,
        cost: &C,
        x0: &[f64],
        controls: &[Vec<f64>],
    ) -> Result<Solution, DdpError> {
        self.solve_observed(dynamics, cost, x0, controls, |_| {})
    }

    /// As [`Ddp::solve`], calling `observe` after every pass (for progress reports).
    pub fn solve_observed<D: Dynamics, C: Cost>(
        &self,
        dynamics: &D,
        cost: &C,
        x0: &[f64],
        controls: &[Vec<f64>],
        mut observe: impl FnMut(&Iteration),
    ) -> Result<Solution, DdpError> {
        let (n, m) = (dynamics.state_dim(), dynamics.control_dim());
        let s = &self.settings;
        crate::check("x0", x0, n)?;
        if controls.is_empty() {
            return Err(DdpError::Input {
                what: "controls",
                problem: "the horizon must be at least one step".into(),
            });
        }
        for u in controls {
            crate::check("controls", u, m)?;
        }
        if let Some(l) = &s.control_limits
            && l.lower.len() != m
        {
            return Err(DdpError::Input {
                what: "control_limits",
                problem: format!("needs {m} entries, has {}", l.lower.len()),
            });
        }
        let horizon = controls.len();
        if s.method == Method::Full {
            let Some(second) = dynamics.second_order() else {
                return Err(DdpError::NoSecondDerivatives);
            };
            let bytes = second.bytes_per_knot().saturating_mul(horizon);
            if bytes > FULL_DDP_MAX_BYTES {
                return Err(DdpError::TooLarge {
                    bytes,
                    knots: horizon,
                    limit: FULL_DDP_MAX_BYTES,
                });
            }
        }
        let mut u: Vec<Vec<f64>> = controls.to_vec();
        if let Some(l) = &s.control_limits {
            for ui in &mut u {
                for j in 0..m {
                    ui[j] = ui[j].clamp(l.lower[j], l.upper[j]);
                }
            }
        }
        // Each knot's step data: the accepted trajectory's, and the line search's trial (swapped in on
        // acceptance). Created once per solve.
        let mut data: Vec<D::Data> = (0..horizon).map(|_| dynamics.create_data()).collect();
        let mut trial: Vec<D::Data> = (0..horizon).map(|_| dynamics.create_data()).collect();
        let (mut x, mut total) = match rollout_into(dynamics, cost, x0, &u, &mut data) {
            Ok(r) => r,
            Err((step, reason)) => return Err(DdpError::InitialRollout { step, reason }),
        };
        let alphas: Vec<f64> = (0..s.line_search_steps)
            .map(|k| {
                if s.line_search_steps == 1 {
                    1.0
                } else {
                    10f64.powf(-3.0 * k as f64 / (s.line_search_steps - 1) as f64)
                }
            })
            .collect();
        let mut mu = s.mu_init;
        let mut dmu = 1.0f64;
        let mut first_alpha = 0usize;
        // One record per pass, reserved up front so that a pass allocates nothing of its own.
        let mut iterations = Vec::with_capacity(s.max_iterations.min(RESERVED_RECORDS));
        let mut record = |iterations: &mut Vec<Iteration>, it: Iteration| {
            observe(&it);
            iterations.push(it);
        };
        // Everything the passes write, allocated once: the backward pass's temporaries and results, the
        // line search's trial trajectory, Gauss-Newton's linearisation.
        let mut work = Workspace::new(n, m, horizon);
        let mut gains = vec![vec![0.0; m * n]; horizon];
        // The value model of the last successful backward pass, and the one being computed (swapped on
        // success, so that a pass that fails half way leaves the last one intact; no allocation per pass).
        let mut values = vec![(vec![0.0; n], vec![0.0; n * n]); horizon + 1];
        let mut trial_values = values.clone();
        let mut k_prev = vec![vec![0.0; m]; horizon];
        let mut status = Status::MaxIterations;
        // Whether the last pass was accepted (the first pass counts: its model is the initial one).
        let mut previous_accepted = true;
        let increase = |mu: &mut f64, dmu: &mut f64| {
            *dmu = (*dmu * s.mu_factor).max(s.mu_factor);
            *mu = (*mu * *dmu).max(s.mu_min);
        };
        for iteration in 0..s.max_iterations {
            let span = tracing::info_span!("ddp.iteration", iteration);
            let _guard = span.enter();
            // Backward pass, raising mu until Q_uu is positive definite everywhere.
            loop {
                match self.backward(
                    dynamics,
                    &mut data,
                    cost,
                    (&x, &u),
                    &k_prev,
                    mu,
                    &mut work,
                    &mut trial_values,
                ) {
                    Ok(true) => {
                        std::mem::swap(&mut values, &mut trial_values);
                        break;
                    }
                    Ok(false) => {
                        increase(&mut mu, &mut dmu);
                        if mu > s.mu_max {
                            status = Status::RegularisationExceeded;
                            break;
                        }
                    }
                    Err(e) => return Err(e),
                }
            }
            if status == Status::RegularisationExceeded {
                break;
            }
            std::mem::swap(&mut gains, &mut work.gains);
            for (p, k) in k_prev.iter_mut().zip(&work.k) {
                p.copy_from_slice(k);
            }
            let dv = work.dv;
            let step = k_prev
                .iter()
                .zip(&u)
                .map(|(k, u)| {
                    k.iter()
                        .zip(u)
                        .map(|(a, b)| a.abs() / (b.abs() + 1.0))
                        .fold(0.0, f64::max)
                })
                .sum::<f64>()
                / horizon as f64;
            if step < s.tol_step && mu < 1e-5 {
                status = Status::StepConverged;
                record(&mut iterations, Iteration::unchanged(total, mu, step));
                break;
            }
            // An unregularised model that expects less from its full step than the cost tolerance: the
            // trajectory is converged (a line search there would only compare rounding errors).
            // Forward pass with a line search.
            let mut accepted = None;
            for (index, &alpha) in alphas.iter().enumerate().skip(first_alpha) {
                let expected = -alpha * (dv[0] + alpha * dv[1]);
                if let Ok(cn) = self.forward(
                    dynamics,
                    (&data, &mut trial),
                    cost,
                    (&x, &u),
                    (&k_prev, &gains),
                    alpha,
                    &mut work,
                ) {
                    let reduction = total - cn;
                    let ratio = if expected > 0.0 {
                        reduction / expected
                    } else {
                        reduction.signum()
                    };
                    if ratio > s.accept_ratio && reduction.is_finite() {
                        accepted = Some((cn, alpha, expected, reduction));
                        if s.adaptive_line_search {
                            first_alpha = index.saturating_sub(2);
                        }
                        break;
                    }
                }
            }
            if accepted.is_none() {
                first_alpha = 0;
            }
            let just_accepted = std::mem::replace(&mut previous_accepted, accepted.is_some());
            match accepted {
                Some((cn, alpha, expected, reduction)) => {
                    tracing::debug!(cost = cn, reduction, expected, mu, alpha, step, "accepted");
                    dmu = (dmu / s.mu_factor).min(1.0 / s.mu_factor);
                    mu = if mu * dmu > s.mu_min { mu * dmu } else { 0.0 };
                    std::mem::swap(&mut x, &mut work.x_trial);
                    std::mem::swap(&mut u, &mut work.u_trial);
                    total = cn;
                    std::mem::swap(&mut data, &mut trial);
                    work.lin_current = false;
                    record(
                        &mut iterations,
                        Iteration {
                            cost: cn,
                            reduction,
                            expected,
                            mu,
                            alpha,
                            step,
                        },
                    );
                    if reduction < s.tol_cost * (1.0 + total.abs()) {
                        status = Status::CostConverged;
                        // The gains of the final trajectory.
                        if let Ok(true) = self.backward(
                            dynamics,
                            &mut data,
                            cost,
                            (&x, &u),
                            &k_prev,
                            mu,
                            &mut work,
                            &mut trial_values,
                        ) {
                            std::mem::swap(&mut gains, &mut work.gains);
                            std::mem::swap(&mut values, &mut trial_values);
                        }
                        break;
                    }
                }
                None if just_accepted && -(dv[0] + dv[1]) < RESOLUTION * (1.0 + total.abs()) => {
                    // The model that was just trusted expects less from its full step than a rollout
                    // resolves: converged (the failed line search compared rounding errors).
                    status = Status::CostConverged;
                    record(&mut iterations, Iteration::unchanged(total, mu, step));
                    break;
                }
                None => {
                    tracing::debug!(mu, step, "no step size reduced the cost");
                    increase(&mut mu, &mut dmu);
                    record(&mut iterations, Iteration::unchanged(total, mu, step));
                    if mu > s.mu_max {
                        status = Status::NoDescent;
                        break;
                    }
                }
            }
        }
        // The cost-to-go at each knot, summed from the end.
        let mut to_go = vec![cost.terminal(&x[horizon]); horizon + 1];
        for i in (0..horizon).rev() {
            to_go[i] = to_go[i + 1] + cost.running(i, &x[i], &u[i]);
        }
        let values = values
            .into_iter()
            .zip(to_go)
            .map(|((gradient, hessian), cost_to_go)| ValueModel {
                cost_to_go,
                gradient,
                hessian,
            })
            .collect();
        Ok(Solution {
            states: x,
            controls: u,
            gains,
            values,
            cost: total,
            iterations,
            status,
        })
    }

    /// The backward pass at regularisation `mu` along the trajectory `(x, u)`, by stages over the
    /// workspace (Q's expansion, its regularisation, the gains, the value's update; `work.k`,
    /// `work.gains` and `work.dv` hold the result), writing `(V_x, V_xx)` at every knot into `values`;
    /// `Ok(false)` when `Q_uu` is not positive definite.
    #[allow(clippy::too_many_arguments)]
    fn backward<D: Dynamics, C: Cost>(
        &self,
        dynamics: &D,
        data: &mut [D::Data],
        cost: &C,
        (x, u): (&[Vec<f64>], &[Vec<f64>]),
        k_prev: &[Vec<f64>],
        mu: f64,
        work: &mut Workspace,
        values: &mut [(Vec<f64>, Vec<f64>)],
    ) -> Result<bool, DdpError> {
        let (n, m) = (dynamics.state_dim(), dynamics.control_dim());
        let horizon = u.len();
        let full = self.settings.method == Method::Full;
        if !work.lin_current {
            // The trajectory's linearisation, kept across regularisation retries: everything of full DDP's
            // second derivatives that does not depend on the value gradient, or Gauss-Newton's first
            // derivatives.
            if !full && work.lin_fx.is_empty() {
                work.lin_fx = vec![vec![0.0; n * n]; horizon];
                work.lin_fu = vec![vec![0.0; n * m]; horizon];
            }
            self.linearise(dynamics, data, (x, u), full, work)?;
            work.lin_current = true;
        }
        cost.terminal_derivatives(&x[horizon], &mut work.vx, &mut work.vxx);
        values[horizon].0.copy_from_slice(&work.vx);
        values[horizon].1.copy_from_slice(&work.vxx);
        work.dv = [0.0; 2];
        for i in (0..horizon).rev() {
            cost.running_derivatives(i, &x[i], &u[i], &mut work.cd);
            if full {
                let w = &mut *work;
                dynamics
                    .second_order()
                    .ok_or(DdpError::NoSecondDerivatives)?
                    .calc_diff2(
                        &mut data[i],
                        &x[i],
                        &u[i],
                        &w.vx,
                        &mut w.fx,
                        &mut w.fu,
                        &mut w.hess,
                    )
                    .map_err(|e| DdpError::Derivatives {
                        step: i,
                        source: Box::new(e),
                    })?;
            } else {
                work.fx.copy_from_slice(&work.lin_fx[i]);
                work.fu.copy_from_slice(&work.lin_fu[i]);
            }
            work.q_expansion(full);
            work.regularise(mu, self.settings.regularisation);
            if !work.gains(i, self.settings.control_limits.as_ref(), &u[i], &k_prev[i]) {
                return Ok(false);
            }
            if !work.value_update(i) {
                return Ok(false);
            }
            values[i].0.copy_from_slice(&work.vx);
            values[i].1.copy_from_slice(&work.vxx);
        }
        Ok(true)
    }

    /// Each knot's linearisation along `(x, u)` in its data (full DDP: [`SecondOrder::calc_diff2_prepare`](
    /// crate::SecondOrder); Gauss-Newton: [`Dynamics::calc_diff`] into the workspace), on the pool when
    /// there is one. A failure names the first knot that failed, as a sequential pass would.
    fn linearise<D: Dynamics>(
        &self,
        dynamics: &D,
        data: &mut [D::Data],
        (x, u): (&[Vec<f64>], &[Vec<f64>]),
        full: bool,
        work: &mut Workspace,
    ) -> Result<(), DdpError> {
        let fail = |step: usize, e: D::Error| DdpError::Derivatives {
            step,
            source: Box::new(e),
        };
        let second = match full {
            true => Some(
                dynamics
                    .second_order()
                    .ok_or(DdpError::NoSecondDerivatives)?,
            ),
            false => None,
        };
        let knot = |i: usize, data: &mut D::Data, fx: &mut [f64], fu: &mut [f64]| match second {
            Some(second) => second.calc_diff2_prepare(data, &x[i], &u[i]),
            None => dynamics.calc_diff(data, &x[i], &u[i], fx, fu),
        };
        // Gauss-Newton writes each knot's fx, fu into the workspace; full DDP keeps all in the data.
        let (fx_all, fu_all): (&mut [Vec<f64>], &mut [Vec<f64>]) = match full {
            true => (&mut [], &mut []),
            false => (&mut work.lin_fx[..], &mut work.lin_fu[..]),
        };
        let failures = std::sync::Mutex::new(Vec::<(usize, D::Error)>::new());
        // Knots `start..` of `data` in order, up to the first that fails.
        let run_chunk =
            |start: usize, data: &mut [D::Data], fx: &mut [Vec<f64>], fu: &mut [Vec<f64>]| {
                for (j, d) in data.iter_mut().enumerate() {
                    let (fx, fu) = match full {
                        true => (&mut [][..], &mut [][..]),
                        false => (&mut fx[j][..], &mut fu[j][..]),
                    };
                    if let Err(e) = knot(start + j, d, fx, fu) {
                        failures
                            .lock()
                            .unwrap_or_else(|p| p.into_inner())
                            .push((start + j, e));
                        break;
                    }
                }
            };
        match &self.pool {
            None => run_chunk(0, data, fx_all, fu_all),
            Some(pool) => {
                // One contiguous run of knots per thread, the first on the calling thread (whose caches
                // hold the knots the forward pass just wrote), the others on the pool's `threads - 1`.
                let chunk = data.len().div_ceil(pool.current_num_threads() + 1).max(1);
                pool.in_place_scope(|scope| {
                    let (mut fx_rest, mut fu_rest) = (fx_all, fu_all);
                    // The next `len` knots' fx and fu (none for full DDP).
                    let mut take = |len: usize| {
                        let (fx_len, fu_len) = (len.min(fx_rest.len()), len.min(fu_rest.len()));
                        let (fx, rest) = std::mem::take(&mut fx_rest).split_at_mut(fx_len);
                        fx_rest = rest;
                        let (fu, rest) = std::mem::take(&mut fu_rest).split_at_mut(fu_len);
                        fu_rest = rest;
                        (fx, fu)
                    };
                    let mut runs = data.chunks_mut(chunk);
                    let first = runs.next().map(|d| {
                        let (fx, fu) = take(d.len());
                        (d, fx, fu)
                    });
                    for (c, d) in runs.enumerate() {
                        let (fx, fu) = take(d.len());
                        let run_chunk = &run_chunk;
                        scope.spawn(move |_| run_chunk((c + 1) * chunk, d, fx, fu));
                    }
                    if let Some((d, fx, fu)) = first {
                        run_chunk(0, d, fx, fu);
                    }
                });
            }
        }
        let failures = failures.into_inner().unwrap_or_else(|p| p.into_inner());
        match failures.into_iter().min_by_key(|f| f.0) {
            Some((i, e)) => Err(fail(i, e)),
            None => Ok(()),
        }
    }

    /// The forward pass at step size `alpha` into the workspace's trial trajectory: at each knot, try
    /// the step `u = u_i + alpha k_i + K_i (x - x_i)` (clamped to the limits), then roll it out; the
    /// trial's total cost, or `Err` where a step fails or a cost is not finite.
    #[allow(clippy::too_many_arguments)]
    fn forward<D: Dynamics, C: Cost>(
        &self,
        dynamics: &D,
        (data, trial): (&[D::Data], &mut [D::Data]),
        cost: &C,
        (x, u): (&[Vec<f64>], &[Vec<f64>]),
        (k, gains): (&[Vec<f64>], &[Vec<f64>]),
        alpha: f64,
        work: &mut Workspace,
    ) -> Result<f64, ()> {
        let (n, m) = (dynamics.state_dim(), dynamics.control_dim());
        let horizon = u.len();
        let (xn, un) = (&mut work.x_trial, &mut work.u_trial);
        xn[0].copy_from_slice(&x[0]);
        let mut total = 0.0;
        for i in 0..horizon {
            let ui = &mut un[i];
            for a in 0..m {
                ui[a] = u[i][a]
                    + alpha * k[i][a]
                    + (0..n)
                        .map(|b| gains[i][a * n + b] * (xn[i][b] - x[i][b]))
                        .sum::<f64>();
            }
            if let Some(l) = &self.settings.control_limits {
                for a in 0..m {
                    ui[a] = ui[a].clamp(l.lower[a], l.upper[a]);
                }
            }
            let (done, rest) = xn.split_at_mut(i + 1);
            let next = &mut rest[0];
            dynamics
                .calc(&mut trial[i], Some(&data[i]), &done[i], ui, next)
                .map_err(|_| ())?;
            total += cost.running(i, &done[i], ui);
            if !(total.is_finite() && next.iter().all(|e| e.is_finite())) {
                return Err(());
            }
        }
        total += cost.terminal(&xn[horizon]);
        if !total.is_finite() {
            return Err(());
        }
        Ok(total)
    }
}

/// A rollout's states and total cost.
pub type Rollout = (Vec<Vec<f64>>, f64);

/// Roll out `u` from `x0`: the states and the total cost, or the step and reason of the first failure.
pub fn rollout<D: Dynamics, C: Cost>(
    dynamics: &D,
    cost: &C,
    x0: &[f64],
    u: &[Vec<f64>],
) -> Result<Rollout, (usize, String)> {
    let mut data: Vec<D::Data> = (0..u.len()).map(|_| dynamics.create_data()).collect();
    rollout_into(dynamics, cost, x0, u, &mut data)
}

/// [`rollout`], each knot's step computed in `data[i]`.
fn rollout_into<D: Dynamics, C: Cost>(
    dynamics: &D,
    cost: &C,
    x0: &[f64],
    u: &[Vec<f64>],
    data: &mut [D::Data],
) -> Result<Rollout, (usize, String)> {
    let n = dynamics.state_dim();
    let mut x = Vec::with_capacity(u.len() + 1);
    x.push(x0.to_vec());
    let mut total = 0.0;
    for (i, ui) in u.iter().enumerate() {
        let mut next = vec![0.0; n];
        dynamics
            .calc(&mut data[i], None, &x[i], ui, &mut next)
            .map_err(|e| (i, e.to_string()))?;
        if !next.iter().all(|e| e.is_finite()) {
            return Err((i, "non-finite state".into()));
        }
        total += cost.running(i, &x[i], ui);
        x.push(next);
    }
    total += cost.terminal(&x[u.len()]);
    if !total.is_finite() {
        return Err((u.len(), "non-finite cost".into()));
    }
    Ok((x, total))
}

/// The receding-horizon warm start of paper eq. (19): drop the first `d` controls and repeat the last one
/// `d` times, keeping the horizon.
pub fn shift_controls(u: &[Vec<f64>], d: usize) -> Vec<Vec<f64>> {
    let horizon = u.len();
    if horizon == 0 {
        return Vec::new();
    }
    let d = d.min(horizon);
    let last = u[horizon - 1].clone();
    u[d..]
        .iter()
        .cloned()
        .chain(std::iter::repeat_n(last, d))
        .collect()
}
