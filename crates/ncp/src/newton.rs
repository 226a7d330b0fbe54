//! Damped Newton for mixed complementarity problems (paper section III-B): each complementarity row is
//! replaced by its NCP function, `Phi(z) = [g(z); phi_i(lambda_i, w_i(z))]`, and `Phi(z) = 0` is solved by
//! Newton's method (semismooth Newton for the hard functions) with an Armijo line search on the merit
//! `psi = |Phi|^2 / 2`. Where the Newton matrix is singular, or the Newton step is so poor that the search
//! would cut it below `newton_min_step`, the iteration takes a Levenberg–Marquardt step instead: redundant
//! active constraints (four impulses for three velocities, say) make the smoothed problem's Jacobian nearly
//! singular, and there the Newton steps are huge and useless while the Levenberg–Marquardt ones converge.

use crate::dense::{DenseLu, LinearSolver, inf_norm};
use crate::error::{NcpError, check_finite, check_len};
use crate::function::NcpFunction;
use crate::problem::Mcp;
use crate::solution::{Info, Solution, Status};
use serde::{Deserialize, Serialize};

/// Settings of [`NewtonSolver`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NewtonSettings {
    /// Stop when `max |Phi| <= tol * (1 + max(|z|, |F(z)|))` (infinity norms).
    pub tol: f64,
    /// Newton iterations at most, per stage.
    pub max_iter: usize,
    /// Iterations of the direct attempt for smoothed rows before switching to continuation in sigma.
    pub direct_iter: usize,
    /// Armijo constant: accept a step `t` when `psi(z + t dz) <= (1 - 2 armijo t) psi(z)`.
    pub armijo: f64,
    /// Step shrink factor of the backtracking line search.
    pub backtrack: f64,
    /// Smallest step length tried along a Newton direction before falling back to a Levenberg–Marquardt
    /// direction for that iteration.
    pub newton_min_step: f64,
    /// Smallest step length tried along a Levenberg–Marquardt direction.
    pub min_step: f64,
    /// Dense LU back end for the Newton systems.
    pub linear_solver: LinearSolver,
}

impl Default for NewtonSettings {
    fn default() -> Self {
        NewtonSettings {
            // Well above the rounding floor of a scene step (about 1e-15 relative), well below the 1e-10 the
            // reference values ask of a step.
            tol: 1e-13,
            max_iter: 100,
            // A Newton solve that converges at all does so within about 15 iterations on the scene.
            direct_iter: 30,
            // The usual Armijo constant and halving (Nocedal and Wright, ch. 3).
            armijo: 1e-4,
            backtrack: 0.5,
            newton_min_step: 1e-4,
            min_step: 1e-12,
            linear_solver: LinearSolver::Hand,
        }
    }
}

impl NewtonSettings {
    /// `Err` naming the first setting out of range.
    pub fn validate(&self) -> Result<(), NcpError> {
        let bad = |name, value: f64, expected| {
            Err(NcpError::Setting {
                name,
                value,
                expected,
            })
        };
        if !(self.tol.is_finite() && self.tol > 0.0) {
            return bad("tol", self.tol, "finite and positive");
        }
        if self.max_iter == 0 {
            return bad("max_iter", 0.0, "at least 1");
        }
        if self.direct_iter == 0 {
            return bad("direct_iter", 0.0, "at least 1");
        }
        if !(self.armijo > 0.0 && self.armijo < 0.5) {
            return bad("armijo", self.armijo, "in (0, 0.5)");
        }
        if !(self.backtrack > 0.0 && self.backtrack < 1.0) {
            return bad("backtrack", self.backtrack, "in (0, 1)");
        }
        if !(self.min_step > 0.0 && self.min_step < 1.0) {
            return bad("min_step", self.min_step, "in (0, 1)");
        }
        if !(self.newton_min_step > 0.0 && self.newton_min_step <= 1.0) {
            return bad("newton_min_step", self.newton_min_step, "in (0, 1]");
        }
        Ok(())
    }
}

/// A Newton solver with its workspace, sized on first use and reused across solves of the same size.
#[derive(Debug)]
pub struct NewtonSolver {
    settings: NewtonSettings,
    work: Option<Work>,
    scaled: Vec<NcpFunction>,
}

#[derive(Debug)]
struct Work {
    n: usize,
    f: Vec<f64>,
    jac: Vec<f64>,
    phi: Vec<f64>,
    h: Vec<f64>,
    dz: Vec<f64>,
    z_trial: Vec<f64>,
    f_trial: Vec<f64>,
    jac_trial: Vec<f64>,
    phi_trial: Vec<f64>,
    /// `(d phi/d a, d phi/d b)` per complementarity row, at the iterate and at the trial point.
    dphi: Vec<f64>,
    dphi_trial: Vec<f64>,
    normal: Vec<f64>,
    lm: Vec<f64>,
    grad: Vec<f64>,
    z_start: Vec<f64>,
    lu: DenseLu,
}

impl Work {
    fn new(n: usize, solver: LinearSolver) -> Self {
        Work {
            n,
            f: vec![0.0; n],
            jac: vec![0.0; n * n],
            phi: vec![0.0; n],
            h: vec![0.0; n * n],
            dz: vec![0.0; n],
            z_trial: vec![0.0; n],
            f_trial: vec![0.0; n],
            jac_trial: vec![0.0; n * n],
            phi_trial: vec![0.0; n],
            dphi: vec![0.0; 2 * n],
            dphi_trial: vec![0.0; 2 * n],
            normal: vec![0.0; n * n],
            lm: vec![0.0; n * n],
            grad: vec![0.0; n],
            z_start: vec![0.0; n],
            lu: DenseLu::new(n, solver),
        }
    }
}

impl NewtonSolver {
    /// A solver with checked settings.
    pub fn new(settings: NewtonSettings) -> Result<Self, NcpError> {
        settings.validate()?;
        Ok(NewtonSolver {
            settings,
            work: None,
            scaled: Vec::new(),
        })
    }

    /// The settings in use.
    pub fn settings(&self) -> &NewtonSettings {
        &self.settings
    }

    /// Solve from the warm start `z0`; `functions` gives each complementarity row's NCP function.
    pub fn solve(
        &mut self,
        problem: &impl Mcp,
        functions: &[NcpFunction],
        z0: &[f64],
    ) -> Result<Solution, NcpError> {
        let mut z = z0.to_vec();
        let info = self.solve_in_place(problem, functions, &mut z)?;
        let mut w = vec![0.0; z.len()];
        problem.evaluate(&z, &mut w, None);
        Ok(Solution { z, w, info })
    }

    /// As [`solve`](Self::solve), without allocating once the workspace exists: `z` holds the warm start on
    /// entry and the last accepted iterate (always finite) on return.
    #[tracing::instrument(name = "ncp.solve", level = "debug", skip_all)]
    pub fn solve_in_place(
        &mut self,
        problem: &impl Mcp,
        functions: &[NcpFunction],
        z: &mut [f64],
    ) -> Result<Info, NcpError> {
        let n = problem.dim();
        let nf = problem.n_free();
        check_len("z0", z.len(), n)?;
        check_len("functions", functions.len(), n - nf)?;
        check_finite("z0", z)?;
        for f in functions {
            f.validate()?;
        }
        let s = self.settings;
        if self.work.as_ref().is_none_or(|w| w.n != n) {
            self.work = Some(Work::new(n, s.linear_solver));
        }
        let w = self.work.as_mut().expect("workspace was just created");
        w.z_start.copy_from_slice(z);
        let all_hard = functions.iter().all(|f| f.is_hard());
        let direct = if all_hard {
            s.max_iter
        } else {
            s.direct_iter.min(s.max_iter)
        };
        let first = run(w, problem, functions, z, s, direct)?;
        if first.status == Status::Converged || all_hard {
            return Ok(first);
        }
        // Then continuation in sigma (the smoothing Newton methods of Chen, Qi and Sun): restart from z0 with every
        // smoothing raised to the problem's scale, where the system is benign, and follow the solution down
        // a decade at a time to the requested sigma, each stage warm-starting the next. This is what rescues
        // a cold start at small sigma with more active constraints than unknowns.
        let target = functions.iter().map(|f| f.sigma()).fold(0.0f64, f64::max);
        let scale = 1.0 + inf_norm(&w.z_start).max(inf_norm(&w.f));
        let mut total = first;
        // A problem that can solve its hard version exactly (a linear one, by Lemke's method) offers that
        // as a start: the smoothed solution lies within O(sigma) of it, and the redundant rows there already
        // carry the impulse split that the smoothing converges to.
        let hard = problem.as_linear().and_then(|p| {
            crate::lemke::lemke(p, &crate::lemke::LemkeSettings::default())
                .ok()
                .filter(|s| s.converged())
                .map(|s| s.z)
        });
        if let Some(hard) = hard
            && hard.len() == n
            && hard.iter().all(|v| v.is_finite())
        {
            {
                z.copy_from_slice(&hard);
                let info = run(w, problem, functions, z, s, s.max_iter)?;
                total.iterations += info.iterations;
                total.evaluations += info.evaluations;
                total.status = info.status;
                total.residual = info.residual;
                tracing::trace!(status = ?info.status, "ncp.newton.from_hard_solution");
                if info.status == Status::Converged {
                    return Ok(total);
                }
            }
        }
        z.copy_from_slice(&w.z_start);
        let mut sigma = scale.max(target);
        let mut stages = 0;
        loop {
            let last = sigma <= target;
            self.scaled.clear();
            self.scaled
                .extend(functions.iter().map(|f| f.with_sigma_at_least(sigma)));
            let stage = if last { functions } else { &self.scaled[..] };
            let info = run(w, problem, stage, z, s, s.max_iter)?;
            total.iterations += info.iterations;
            total.evaluations += info.evaluations;
            total.status = info.status;
            total.residual = info.residual;
            stages += 1;
            tracing::trace!(stage = stages, sigma, status = ?info.status, "ncp.newton.continuation");
            if last {
                return Ok(total);
            }
            sigma = (sigma * 0.1).max(target);
        }
    }
}

/// The damped Newton iteration from `z` for at most `max_iter` iterations.
fn run(
    w: &mut Work,
    problem: &impl Mcp,
    functions: &[NcpFunction],
    z: &mut [f64],
    s: NewtonSettings,
    max_iter: usize,
) -> Result<Info, NcpError> {
    let n = w.n;
    let nf = problem.n_free();
    problem.evaluate(z, &mut w.f, Some(&mut w.jac));
    check_finite("F(z0)", &w.f)?;
    check_finite("dF/dz(z0)", &w.jac)?;
    let mut evaluations = 1;
    let mut psi = ncp_residual(nf, functions, z, &w.f, &mut w.phi, &mut w.dphi);
    let mut iterations = 0;
    loop {
        let residual = inf_norm(&w.phi);
        let scale = 1.0 + inf_norm(z).max(inf_norm(&w.f));
        tracing::trace!(iter = iterations, residual, "ncp.newton");
        macro_rules! info {
            ($status:expr) => {
                Info {
                    status: $status,
                    iterations,
                    residual,
                    evaluations,
                }
            };
        }
        if residual <= s.tol * scale {
            return Ok(info!(Status::Converged));
        }
        if iterations == max_iter {
            return Ok(info!(Status::MaxIterations));
        }
        iterations += 1;
        newton_matrix(n, nf, &w.dphi, &w.jac, &mut w.h);
        // Newton direction first: H dz = -Phi, along which psi falls at rate -2 psi.
        let mut newton_ok = w.lu.factor(&w.h).is_ok();
        if newton_ok {
            for i in 0..n {
                w.dz[i] = -w.phi[i];
            }
            w.lu.solve(&mut w.dz);
            newton_ok = w.dz.iter().all(|v| v.is_finite());
        }
        if newton_ok {
            // A step at rounding level cannot improve z: the residual is at its floor.
            if inf_norm(&w.dz) <= 4.0 * f64::EPSILON * (1.0 + inf_norm(z)) {
                return Ok(info!(Status::Converged));
            }
            // Fraction to the boundary: the root of a smoothed row has lambda_i > 0, so a step may shrink a
            // positive lambda_i at most a hundredfold. This is what moves impulses along the directions that
            // redundant active rows leave flat (Newton asks for enormous steps there).
            let mut t0 = 1.0f64;
            for (k, f) in functions.iter().enumerate() {
                let i = nf + k;
                if !f.is_hard() && z[i] > 0.0 && w.dz[i] < 0.0 {
                    t0 = t0.min(0.99 * z[i] / -w.dz[i]);
                }
            }
            // The plain Armijo search from the full step first; the boundary-limited step only when that
            // fails and is shorter than anything the search tried.
            let mut outcome = line_search(
                w,
                problem,
                functions,
                z,
                psi,
                -2.0 * psi,
                s,
                1.0,
                s.newton_min_step,
            );
            if let (Search::Rejected(e, _), true) = (&outcome, t0 > 0.0 && t0 < s.newton_min_step) {
                evaluations += e;
                outcome = line_search(w, problem, functions, z, psi, -2.0 * psi, s, t0, 0.5);
            }
            match outcome {
                Search::Accepted(t, p) => {
                    evaluations += t.1;
                    psi = p;
                    tracing::trace!(iter = iterations, alpha = t.0, "ncp.newton.step");
                    continue;
                }
                Search::Rejected(e, _) => evaluations += e,
            }
        }
        // The Newton step was singular or needed a step length below `newton_min_step`: the
        // Levenberg–Marquardt direction (H^T H + mu I) dz = -H^T Phi is always a descent direction of
        // psi, and mu = |Phi| keeps it Newton-like near a solution (Fan and Yuan, 2005) while damping the
        // near-null directions of H that redundant active constraints create.
        let hth_max = gram(n, &w.h, &w.phi, &mut w.normal, &mut w.grad);
        let mut mu = psi.sqrt().max(1e-12 * hth_max);
        let mut accepted = false;
        for _ in 0..8 {
            for i in 0..n {
                w.lm[i * n..(i + 1) * n].copy_from_slice(&w.normal[i * n..(i + 1) * n]);
                w.lm[i * n + i] += mu;
                w.dz[i] = -w.grad[i];
            }
            if w.lu.factor(&w.lm).is_ok() {
                w.lu.solve(&mut w.dz);
                if w.dz.iter().all(|v| v.is_finite()) {
                    let slope: f64 = w.grad.iter().zip(&w.dz).map(|(g, d)| g * d).sum();
                    match line_search(w, problem, functions, z, psi, slope, s, 1.0, s.min_step) {
                        Search::Accepted(t, p) => {
                            evaluations += t.1;
                            psi = p;
                            tracing::trace!(iter = iterations, alpha = t.0, mu, "ncp.lm.step");
                            accepted = true;
                            break;
                        }
                        Search::Rejected(e, finite) => {
                            evaluations += e;
                            if !finite {
                                return Ok(info!(Status::NonFinite));
                            }
                        }
                    }
                }
            }
            mu *= 100.0;
        }
        if !accepted {
            return Ok(info!(if newton_ok {
                Status::LineSearchFailed
            } else {
                Status::SingularJacobian
            }));
        }
    }
}

enum Search {
    /// Step length and evaluations used; the new merit.
    Accepted((f64, usize), f64),
    /// Evaluations used; whether every trial point was finite.
    Rejected(usize, bool),
}

/// Armijo backtracking on `psi` along `w.dz` from `z`, whose directional derivative is `slope < 0`, from
/// the step `t0` down to `min_step * t0`; on success `z` and the workspace's `f`, `jac`, `phi` hold the new
/// point. A step cut short by the boundary (`t0 < 1`) may leave `psi` unchanged to rounding, which is
/// accepted: along flat directions that is all a step can do.
#[allow(clippy::too_many_arguments)]
fn line_search(
    w: &mut Work,
    problem: &impl Mcp,
    functions: &[NcpFunction],
    z: &mut [f64],
    psi: f64,
    slope: f64,
    s: NewtonSettings,
    t0: f64,
    min_step: f64,
) -> Search {
    let n = w.n;
    let nf = problem.n_free();
    let mut t = t0;
    let slack = if t0 < 1.0 {
        4.0 * f64::EPSILON * psi
    } else {
        0.0
    };
    let mut evaluations = 0;
    let mut all_finite = true;
    // A constant Jacobian stays where the solve's first evaluation put it.
    let constant = problem.constant_jacobian();
    loop {
        for i in 0..n {
            w.z_trial[i] = z[i] + t * w.dz[i];
        }
        let finite = if constant {
            problem.evaluate(&w.z_trial, &mut w.f_trial, None);
            w.f_trial.iter().all(|v| v.is_finite())
        } else {
            problem.evaluate(&w.z_trial, &mut w.f_trial, Some(&mut w.jac_trial));
            w.f_trial.iter().chain(&w.jac_trial).all(|v| v.is_finite())
        };
        evaluations += 1;
        all_finite &= finite;
        let psi_trial = if finite {
            ncp_residual(
                nf,
                functions,
                &w.z_trial,
                &w.f_trial,
                &mut w.phi_trial,
                &mut w.dphi_trial,
            )
        } else {
            f64::INFINITY
        };
        if psi_trial <= psi + s.armijo * t * slope + slack {
            z.copy_from_slice(&w.z_trial);
            std::mem::swap(&mut w.f, &mut w.f_trial);
            if !constant {
                std::mem::swap(&mut w.jac, &mut w.jac_trial);
            }
            std::mem::swap(&mut w.phi, &mut w.phi_trial);
            std::mem::swap(&mut w.dphi, &mut w.dphi_trial);
            return Search::Accepted((t, evaluations), psi_trial);
        }
        t *= s.backtrack;
        if t < min_step * t0 {
            return Search::Rejected(evaluations, all_finite);
        }
    }
}

/// `H^T H` into `normal` and `H^T Phi` into `grad` (row-major `H`); returns the largest diagonal entry.
fn gram(n: usize, h: &[f64], phi: &[f64], normal: &mut [f64], grad: &mut [f64]) -> f64 {
    normal.fill(0.0);
    grad.fill(0.0);
    for k in 0..n {
        let row = &h[k * n..(k + 1) * n];
        for i in 0..n {
            let hi = row[i];
            if hi != 0.0 {
                grad[i] += hi * phi[k];
                for j in 0..n {
                    normal[i * n + j] += hi * row[j];
                }
            }
        }
    }
    (0..n).fold(0.0f64, |m, i| m.max(normal[i * n + i]))
}

/// `Phi(z)` into `phi`; returns `psi = |Phi|^2 / 2`.
fn ncp_residual(
    nf: usize,
    functions: &[NcpFunction],
    z: &[f64],
    f: &[f64],
    phi: &mut [f64],
    dphi: &mut [f64],
) -> f64 {
    let mut psi = 0.0;
    for i in 0..nf {
        phi[i] = f[i];
        psi += f[i] * f[i];
    }
    for (k, func) in functions.iter().enumerate() {
        let i = nf + k;
        let (v, da, db) = func.first_order(z[i], f[i]);
        phi[i] = v;
        dphi[2 * k] = da;
        dphi[2 * k + 1] = db;
        psi += v * v;
    }
    0.5 * psi
}

/// The (generalised) Jacobian of `Phi`: equality rows copy `dF/dz`; complementarity row `i` is
/// `phi_a e_i + phi_b dF_i/dz`.
fn newton_matrix(n: usize, nf: usize, dphi: &[f64], jac: &[f64], h: &mut [f64]) {
    h[..nf * n].copy_from_slice(&jac[..nf * n]);
    for k in 0..(n - nf) {
        let i = nf + k;
        let (da, db) = (dphi[2 * k], dphi[2 * k + 1]);
        let row = &mut h[i * n..(i + 1) * n];
        for (hj, jj) in row.iter_mut().zip(&jac[i * n..(i + 1) * n]) {
            *hj = db * jj;
        }
        row[i] += da;
    }
}
