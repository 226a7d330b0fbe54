//! Damped Newton for mixed complementarity problems (paper section III-B): each complementarity row is
//! replaced by its NCP function, `Phi(z) = [g(z); phi_i(lambda_i, w_i(z))]`, and `Phi(z) = 0` is solved by
//! Newton's method (semismooth Newton for the hard functions) with an Armijo line search on the merit
//! `psi = |Phi|^2 / 2`.

use crate::dense::{DenseLu, LinearSolver};
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
    /// Newton iterations at most.
    pub max_iter: usize,
    /// Armijo constant: accept a step `t` when `psi(z + t dz) <= (1 - 2 armijo t) psi(z)`.
    pub armijo: f64,
    /// Step shrink factor of the backtracking line search.
    pub backtrack: f64,
    /// Smallest step length tried before the line search fails.
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
            // The usual Armijo constant and halving (Nocedal and Wright, ch. 3).
            armijo: 1e-4,
            backtrack: 0.5,
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
        if !(self.armijo > 0.0 && self.armijo < 0.5) {
            return bad("armijo", self.armijo, "in (0, 0.5)");
        }
        if !(self.backtrack > 0.0 && self.backtrack < 1.0) {
            return bad("backtrack", self.backtrack, "in (0, 1)");
        }
        if !(self.min_step > 0.0 && self.min_step < 1.0) {
            return bad("min_step", self.min_step, "in (0, 1)");
        }
        Ok(())
    }
}

/// A Newton solver with its workspace, sized on first use and reused across solves of the same size.
#[derive(Debug)]
pub struct NewtonSolver {
    settings: NewtonSettings,
    work: Option<Work>,
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

        problem.evaluate(z, &mut w.f, Some(&mut w.jac));
        check_finite("F(z0)", &w.f)?;
        check_finite("dF/dz(z0)", &w.jac)?;
        let mut evaluations = 1;
        let mut psi = ncp_residual(nf, functions, z, &w.f, &mut w.phi);
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
            if iterations == s.max_iter {
                return Ok(info!(Status::MaxIterations));
            }
            newton_matrix(n, nf, functions, z, &w.f, &w.jac, &mut w.h);
            if !w.lu.factor(&w.h) {
                return Ok(info!(Status::SingularJacobian));
            }
            for i in 0..n {
                w.dz[i] = -w.phi[i];
            }
            w.lu.solve(&mut w.dz);
            if w.dz.iter().any(|v| !v.is_finite()) {
                return Ok(info!(Status::SingularJacobian));
            }
            iterations += 1;
            // A step at rounding level cannot improve z: the residual is at its floor.
            if inf_norm(&w.dz) <= 4.0 * f64::EPSILON * (1.0 + inf_norm(z)) {
                return Ok(info!(Status::Converged));
            }
            // Backtracking on psi; the directional derivative of psi along a Newton step is -2 psi.
            let mut t = 1.0;
            loop {
                for i in 0..n {
                    w.z_trial[i] = z[i] + t * w.dz[i];
                }
                problem.evaluate(&w.z_trial, &mut w.f_trial, Some(&mut w.jac_trial));
                evaluations += 1;
                let finite = w.f_trial.iter().chain(&w.jac_trial).all(|v| v.is_finite());
                let psi_trial = if finite {
                    ncp_residual(nf, functions, &w.z_trial, &w.f_trial, &mut w.phi_trial)
                } else {
                    f64::INFINITY
                };
                if psi_trial <= (1.0 - 2.0 * s.armijo * t) * psi {
                    z.copy_from_slice(&w.z_trial);
                    std::mem::swap(&mut w.f, &mut w.f_trial);
                    std::mem::swap(&mut w.jac, &mut w.jac_trial);
                    std::mem::swap(&mut w.phi, &mut w.phi_trial);
                    psi = psi_trial;
                    tracing::trace!(iter = iterations, alpha = t, "ncp.newton.step");
                    break;
                }
                t *= s.backtrack;
                if t < s.min_step {
                    let status = if finite {
                        Status::LineSearchFailed
                    } else {
                        Status::NonFinite
                    };
                    return Ok(info!(status));
                }
            }
        }
    }
}

/// `Phi(z)` into `phi`; returns `psi = |Phi|^2 / 2`.
fn ncp_residual(
    nf: usize,
    functions: &[NcpFunction],
    z: &[f64],
    f: &[f64],
    phi: &mut [f64],
) -> f64 {
    let mut psi = 0.0;
    for i in 0..nf {
        phi[i] = f[i];
        psi += f[i] * f[i];
    }
    for (k, func) in functions.iter().enumerate() {
        let i = nf + k;
        let v = func.value(z[i], f[i]);
        phi[i] = v;
        psi += v * v;
    }
    0.5 * psi
}

/// The (generalised) Jacobian of `Phi`: equality rows copy `dF/dz`; complementarity row `i` is
/// `phi_a e_i + phi_b dF_i/dz`.
fn newton_matrix(
    n: usize,
    nf: usize,
    functions: &[NcpFunction],
    z: &[f64],
    f: &[f64],
    jac: &[f64],
    h: &mut [f64],
) {
    h[..nf * n].copy_from_slice(&jac[..nf * n]);
    for (k, func) in functions.iter().enumerate() {
        let i = nf + k;
        let jet = func.jet(z[i], f[i]);
        let row = &mut h[i * n..(i + 1) * n];
        for (hj, jj) in row.iter_mut().zip(&jac[i * n..(i + 1) * n]) {
            *hj = jet.db * jj;
        }
        row[i] += jet.da;
    }
}

pub(crate) fn inf_norm(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}
