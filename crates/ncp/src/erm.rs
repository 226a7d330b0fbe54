//! Expected residual minimisation (paper eq. 14 with 15, after Chen and Fukushima): for a linear mixed
//! problem, minimise `f(lambda) = sum_i E[min(lambda_i, w_i + sigma_i xi_i)^2]` over `lambda >= 0`, with
//! `xi_i` standard normal and the equality rows held exactly.
//!
//! The equality rows are eliminated once ([`LinearMcp::reduce`]): `x = X lambda + x0` satisfies them to
//! rounding at every iterate, and `w = A lambda + b` with the Schur complement `A`. What remains is a smooth,
//! generally non-convex, bound-constrained minimisation in `c` variables, solved by a projected Newton method
//! (Bertsekas, "Projected Newton methods for optimization problems with simple constraints", 1982) on the
//! exact Hessian of eq. (15), with a Levenberg–Marquardt shift that makes the reduced Hessian positive
//! definite and adapts to the step's success, and an Armijo search along the projection arc. Where that
//! does not converge (rows whose scales differ by decades, as a light needle's beside a disc's), a primal
//! active-set Newton method takes over from where it stopped, changing the active set one variable at a
//! time.

use crate::dense::{DenseLu, LinearSolver, inf_norm};
use crate::error::{NcpError, check_finite, check_len};
use crate::function::normal_expected_squared;
use crate::problem::{LinearMcp, Mcp, Reduced};
use crate::solution::{Info, Solution, Status};
use serde::{Deserialize, Serialize};

/// Settings of [`ErmSolver`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErmSettings {
    /// Also descend from the exact hard solution and keep the lower objective (the objective is not
    /// convex; see [`ErmSolver::solve`]).
    pub hard_start: bool,
    /// Stop when the projected gradient's infinity norm is below `tol * (1 + max(|lambda|, |w|))^2`
    /// (the objective is quadratic in the data's scale).
    pub tol: f64,
    /// Iterations at most.
    pub max_iter: usize,
    /// Armijo constant of the search along the projection arc.
    pub armijo: f64,
    /// Complementarity rows at most: each iteration factors a dense Hessian (`O(n^3)`, up to `max_iter`
    /// of them and a Lemke start), so a problem past this is refused ([`NcpError::TooLarge`]) rather than
    /// left to run for minutes (1000 rows took three).
    #[serde(default = "default_max_size")]
    pub max_size: usize,
}

fn default_max_size() -> usize {
    ErmSettings::default().max_size
}

impl Default for ErmSettings {
    fn default() -> Self {
        ErmSettings {
            hard_start: true,
            tol: 1e-13,
            max_iter: 200,
            armijo: 1e-4,
            max_size: 300,
        }
    }
}

impl ErmSettings {
    /// `Err` naming the first setting out of range.
    pub fn validate(&self) -> Result<(), NcpError> {
        if !(self.tol.is_finite() && self.tol > 0.0) {
            return Err(NcpError::Setting {
                name: "tol",
                value: self.tol,
                expected: "finite and positive",
            });
        }
        if self.max_iter == 0 {
            return Err(NcpError::Setting {
                name: "max_iter",
                value: 0.0,
                expected: "at least 1",
            });
        }
        if !(self.armijo > 0.0 && self.armijo < 0.5) {
            return Err(NcpError::Setting {
                name: "armijo",
                value: self.armijo,
                expected: "in (0, 0.5)",
            });
        }
        Ok(())
    }
}

/// The ERM solver for linear mixed problems.
#[derive(Debug)]
pub struct ErmSolver {
    settings: ErmSettings,
}

struct Eval {
    f: f64,
    g: Vec<f64>,
    h: Vec<f64>,
    w: Vec<f64>,
}

impl ErmSolver {
    /// A solver with checked settings.
    pub fn new(settings: ErmSettings) -> Result<Self, NcpError> {
        settings.validate()?;
        Ok(ErmSolver { settings })
    }

    /// Minimise the expected squared residual with noise `sigma[i]` on row `i`'s `w`, starting from the
    /// complementarity part of `z0` (projected onto `lambda >= 0`; the free part is recomputed).
    #[tracing::instrument(name = "ncp.erm", level = "debug", skip_all)]
    pub fn solve(
        &self,
        problem: &LinearMcp,
        sigma: &[f64],
        z0: &[f64],
    ) -> Result<Solution, NcpError> {
        let n = problem.dim();
        let nf = problem.n_free();
        check_len("z0", z0.len(), n)?;
        check_len("sigma", sigma.len(), n - nf)?;
        check_finite("z0", z0)?;
        if let Some(&s) = sigma.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
            return Err(NcpError::Sigma(s));
        }
        if n - nf > self.settings.max_size {
            return Err(NcpError::TooLarge {
                method: "expected residual minimisation",
                rows: n - nf,
                max: self.settings.max_size,
            });
        }
        let reduced = problem.reduce()?;
        let start: Vec<f64> = z0[nf..].to_vec();
        let (mut lambda, f, mut info) = self.descend(&reduced, sigma, &start);
        // The objective is not convex, so a warm start can sit in a local minimum. The global minimiser
        // tends to the hard solution as sigma -> 0, so a second descent from Lemke's exact solution finds
        // its basin; the lower objective wins.
        if self.settings.hard_start {
            match crate::lemke::lemke(&reduced.lcp(), &crate::lemke::LemkeSettings::default()) {
                Ok(hard) => {
                    let (l2, f2, i2) = self.descend(&reduced, sigma, &hard.z);
                    let better = (i2.status == Status::Converged, -f2)
                        > (info.status == Status::Converged, -f);
                    info.iterations += i2.iterations;
                    info.evaluations += i2.evaluations;
                    if better {
                        (lambda, info.status, info.residual) = (l2, i2.status, i2.residual);
                    }
                }
                // No solution (certain for the positive semi-definite matrices of a step): at any solution
                // each row's expected residual is at most sigma^2 (E[min(0, w + sigma xi)^2] <= sigma^2 / 2
                // where lambda = 0, E[min(lambda, sigma xi)^2] <= sigma^2 where w = 0), so a minimum above
                // their sum confirms it, and the minimiser is no answer to report as converged.
                Err(NcpError::Infeasible { .. } | NcpError::InfeasibleRow { .. }) => {
                    let bound: f64 = sigma.iter().map(|s| s * s).sum();
                    if f > bound {
                        return Err(NcpError::NoSolution {
                            objective: f,
                            bound,
                        });
                    }
                }
                Err(_) => {}
            }
        }
        let z = reduced.expand(&lambda);
        let mut w = vec![0.0; n];
        problem.evaluate(&z, &mut w, None);
        Ok(Solution { z, w, info })
    }

    /// [`ErmSolver::minimise`] from `start`, and where it does not converge [`ErmSolver::minimise_faces`]
    /// from where it stopped; the counts are summed.
    fn descend(&self, reduced: &Reduced, sigma: &[f64], start: &[f64]) -> (Vec<f64>, f64, Info) {
        let (lambda, f, info) = self.minimise(reduced, sigma, start);
        if info.status == Status::Converged {
            return (lambda, f, info);
        }
        let (l2, f2, mut i2) = self.minimise_faces(reduced, sigma, &lambda);
        i2.iterations += info.iterations;
        i2.evaluations += info.evaluations;
        if i2.status == Status::Converged || f2 <= f {
            (l2, f2, i2)
        } else {
            (
                lambda,
                f,
                Info {
                    iterations: i2.iterations,
                    evaluations: i2.evaluations,
                    ..info
                },
            )
        }
    }

    /// Projected Newton from `start`; returns the minimiser, its objective and how it went.
    fn minimise(&self, reduced: &Reduced, sigma: &[f64], start: &[f64]) -> (Vec<f64>, f64, Info) {
        let s = self.settings;
        let mut lambda: Vec<f64> = start.iter().map(|v| v.max(0.0)).collect();
        let c = lambda.len();
        let mut cur = evaluate(reduced, sigma, &lambda, true);
        let mut mu = 0.0f64;
        let mut lu = DenseLu::new(c, LinearSolver::Hand);
        let mut evaluations = 1;
        let mut iterations = 0;
        let mut trial = vec![0.0; c];
        // Stall detection: the best objective so far and the accepted steps since it last fell measurably.
        let (mut best_f, mut stalled, mut blind) = (cur.f, 0, 0);
        let status = loop {
            let residual = projected_gradient_norm(&lambda, &cur.g);
            let scale = 1.0 + inf_norm(&lambda).max(inf_norm(&cur.w));
            tracing::trace!(iter = iterations, residual, mu, "ncp.erm");
            if residual <= s.tol * scale {
                break Status::Converged;
            }
            if iterations == s.max_iter {
                break Status::MaxIterations;
            }
            iterations += 1;
            // Bertsekas' active set: variables at (or within eps of) the bound that the gradient pushes out.
            // eps is measured in lambda's own units (the data can put lambda at 1e-3 and the gradient at
            // 1e-2): the longest move of the projected diagonal-Newton step, which vanishes at a minimiser
            // and, away from one, stays in proportion to lambda rather than to the gradient.
            let diagonal_step = (0..c).fold(0.0f64, |m, i| {
                let curvature = cur.h[i * c + i];
                let step = if curvature > 0.0 {
                    cur.g[i] / curvature
                } else {
                    cur.g[i].signum() * f64::INFINITY
                };
                m.max((lambda[i] - (lambda[i] - step).max(0.0)).abs())
            });
            let eps = diagonal_step.min(1e-3 * scale);
            let free: Vec<bool> = (0..c)
                .map(|i| !(lambda[i] <= eps && cur.g[i] > 0.0))
                .collect();
            let diag_max = (0..c)
                .fold(0.0f64, |m, i| m.max(cur.h[i * c + i].abs()))
                .max(f64::MIN_POSITIVE);
            // Newton direction on the free set with a Levenberg–Marquardt shift until it is a descent
            // direction of a positive definite model.
            let Some(d) = newton_direction(&cur, &free, &mut mu, &mut lu) else {
                break Status::SingularJacobian;
            };
            // Search along the projection arc lambda(t) = max(lambda + t d, 0); the active variables (within
            // eps of the bound, pushed outwards) go to the bound at full step, so that they land on it
            // instead of creeping towards it.
            // When the full step's predicted decrease is below the rounding of f, f cannot be lowered
            // measurably: the iterate is a minimiser to working precision (flat valleys of redundant rows
            // otherwise make the iteration shuttle between points of equal f).
            let predicted: f64 = (0..c)
                .map(|i| {
                    let step = if free[i] {
                        (lambda[i] + d[i]).max(0.0)
                    } else {
                        0.0
                    } - lambda[i];
                    cur.g[i] * step
                })
                .sum();
            // The step itself measures the distance to the minimiser: at rounding level, stop; when f can no
            // longer tell points apart, stop once the step is small (flat valleys of redundant rows).
            let step_size = (0..c)
                .map(|i| {
                    if free[i] {
                        ((lambda[i] + d[i]).max(0.0) - lambda[i]).abs()
                    } else {
                        lambda[i]
                    }
                })
                .fold(0.0f64, f64::max);
            let lambda_scale = 1.0 + inf_norm(&lambda);
            if step_size <= 4.0 * f64::EPSILON * lambda_scale {
                break Status::Converged;
            }
            // Below f's rounding the line search cannot judge a step: near the minimiser take the Newton
            // step as it is (it converges quadratically there); in a flat valley, where such steps shuttle
            // between points f cannot tell apart, stop after a few.
            if predicted.abs() <= 8.0 * f64::EPSILON * cur.f.abs()
                && step_size <= 1e-8 * lambda_scale
            {
                blind += 1;
                if blind > 4 {
                    break Status::Converged;
                }
                for i in 0..c {
                    lambda[i] = if free[i] {
                        (lambda[i] + d[i]).max(0.0)
                    } else {
                        0.0
                    };
                }
                cur = evaluate(reduced, sigma, &lambda, true);
                evaluations += 1;
                continue;
            }
            let accepted = armijo_search(
                reduced,
                sigma,
                &cur,
                &lambda,
                s.armijo,
                1.0,
                &mut trial,
                &mut evaluations,
                |t, i| {
                    if free[i] {
                        (lambda[i] + t * d[i]).max(0.0)
                    } else {
                        lambda[i] * (1.0 - t)
                    }
                },
            );
            let Some(t) = accepted else {
                // The step was too long for the model: trust it less, or stop at the rounding floor.
                if mu > 1e12 * diag_max {
                    break Status::LineSearchFailed;
                }
                mu = (mu * 10.0).max(1e-6 * diag_max);
                continue;
            };
            let moved = (0..c).fold(0.0f64, |m, i| m.max((trial[i] - lambda[i]).abs()));
            lambda.copy_from_slice(&trial);
            cur = evaluate(reduced, sigma, &lambda, true);
            evaluations += 1;
            if cur.f < best_f - 16.0 * f64::EPSILON * best_f.abs() {
                best_f = cur.f;
                stalled = 0;
            } else {
                stalled += 1;
                // Five steps without a decrease above rounding: a minimiser to working precision.
                if stalled >= 5 && moved <= 1e-8 * (1.0 + inf_norm(&lambda)) {
                    break Status::Converged;
                }
            }
            mu = if t == 1.0 { mu / 10.0 } else { mu * 4.0 };
            if moved <= 4.0 * f64::EPSILON * (1.0 + inf_norm(&lambda)) {
                break Status::Converged;
            }
        };
        let pg_norm = projected_gradient_norm(&lambda, &cur.g);
        (
            lambda,
            cur.f,
            Info {
                status,
                iterations,
                residual: pg_norm,
                evaluations,
            },
        )
    }
}

impl ErmSolver {
    /// The fallback of [`ErmSolver::minimise`]: a primal active-set Newton method. The variables held at
    /// the bound stay there while Newton (with the same Levenberg–Marquardt shift) minimises over the
    /// others, its steps cut where a free variable reaches the bound (which then joins the held ones); a
    /// held variable whose gradient points inwards is released once the free ones are nearly optimal. The
    /// projected method moves the whole active set every iteration, and on badly scaled rows (a light
    /// needle's, whose `A` entries reach 1e4 against 1 for a disc's) it can alternate between two active
    /// sets with steps of 1e-3 for hundreds of iterations; here the set changes one variable at a time.
    fn minimise_faces(
        &self,
        reduced: &Reduced,
        sigma: &[f64],
        start: &[f64],
    ) -> (Vec<f64>, f64, Info) {
        let s = self.settings;
        let mut lambda: Vec<f64> = start.iter().map(|v| v.max(0.0)).collect();
        let c = lambda.len();
        let mut cur = evaluate(reduced, sigma, &lambda, true);
        let mut held: Vec<bool> = (0..c).map(|i| lambda[i] == 0.0 && cur.g[i] > 0.0).collect();
        let mut lu = DenseLu::new(c, LinearSolver::Hand);
        let (mut mu, mut evaluations, mut iterations) = (0.0f64, 1, 0);
        let (mut best_f, mut stalled) = (cur.f, 0);
        let status = loop {
            let residual = projected_gradient_norm(&lambda, &cur.g);
            let scale = 1.0 + inf_norm(&lambda).max(inf_norm(&cur.w));
            if residual <= s.tol * scale {
                break Status::Converged;
            }
            if iterations == s.max_iter {
                break Status::MaxIterations;
            }
            iterations += 1;
            // Release the held variable pushed inwards hardest once the free ones are nearly optimal.
            let face = (0..c)
                .filter(|&i| !held[i])
                .fold(0.0f64, |m, i| m.max(cur.g[i].abs()));
            let inwards = (0..c)
                .filter(|&i| held[i] && cur.g[i] < 0.0)
                .min_by(|&i, &j| cur.g[i].total_cmp(&cur.g[j]));
            if let Some(i) = inwards.filter(|&i| face <= -0.5 * cur.g[i]) {
                held[i] = false;
            }
            let free: Vec<bool> = held.iter().map(|h| !h).collect();
            let Some(d) = newton_direction(&cur, &free, &mut mu, &mut lu) else {
                break Status::SingularJacobian;
            };
            // The longest step that keeps every free variable feasible, and the first it stops.
            let (mut reach, mut blocking) = (1.0f64, None);
            for i in (0..c).filter(|&i| free[i] && d[i] < 0.0) {
                let t = lambda[i] / -d[i];
                if t < reach {
                    (reach, blocking) = (t, Some(i));
                }
            }
            let mut trial = vec![0.0; c];
            let accepted = armijo_search(
                reduced,
                sigma,
                &cur,
                &lambda,
                s.armijo,
                reach,
                &mut trial,
                &mut evaluations,
                |t, i| {
                    if blocking == Some(i) && t == reach {
                        0.0
                    } else {
                        (lambda[i] + t * d[i]).max(0.0)
                    }
                },
            );
            let diag_max = (0..c)
                .fold(0.0f64, |m, i| m.max(cur.h[i * c + i].abs()))
                .max(f64::MIN_POSITIVE);
            let Some(t) = accepted else {
                if mu > 1e12 * diag_max {
                    break Status::LineSearchFailed;
                }
                mu = (mu * 10.0).max(1e-6 * diag_max);
                continue;
            };
            if let Some(b) = blocking.filter(|_| t == reach) {
                held[b] = true;
            }
            let moved = (0..c).fold(0.0f64, |m, i| m.max((trial[i] - lambda[i]).abs()));
            lambda.copy_from_slice(&trial);
            cur = evaluate(reduced, sigma, &lambda, true);
            evaluations += 1;
            mu = if t >= reach.min(1.0) {
                mu / 10.0
            } else {
                mu * 4.0
            };
            if cur.f < best_f - 16.0 * f64::EPSILON * best_f.abs() {
                best_f = cur.f;
                stalled = 0;
            } else {
                stalled += 1;
                if stalled >= 5 && moved <= 1e-8 * (1.0 + inf_norm(&lambda)) {
                    break Status::Converged;
                }
            }
            if moved <= 4.0 * f64::EPSILON * (1.0 + inf_norm(&lambda)) && reach >= 1.0 {
                break Status::Converged;
            }
        };
        let residual = projected_gradient_norm(&lambda, &cur.g);
        (
            lambda,
            cur.f,
            Info {
                status,
                iterations,
                residual,
                evaluations,
            },
        )
    }
}

/// Backtracking from step `t0`, halving down to 1e-12: the first `t` whose trial point (entry `i` is
/// `point(t, i)`, left in `trial`) meets Armijo's condition against `cur` at `lambda`; `None` if none does.
#[allow(clippy::too_many_arguments)]
fn armijo_search(
    reduced: &Reduced,
    sigma: &[f64],
    cur: &Eval,
    lambda: &[f64],
    armijo: f64,
    t0: f64,
    trial: &mut [f64],
    evaluations: &mut usize,
    point: impl Fn(f64, usize) -> f64,
) -> Option<f64> {
    let mut t = t0;
    loop {
        for (i, v) in trial.iter_mut().enumerate() {
            *v = point(t, i);
        }
        let e = evaluate(reduced, sigma, trial, false);
        *evaluations += 1;
        let decrease: f64 = (0..trial.len())
            .map(|i| cur.g[i] * (trial[i] - lambda[i]))
            .sum();
        if e.f.is_finite() && e.f <= cur.f + armijo * decrease {
            return Some(t);
        }
        t *= 0.5;
        if t < 1e-12 {
            return None;
        }
    }
}

/// `max_i |g_i|` over the variables off the bound, `max_i max(-g_i, 0)` over those on it.
fn projected_gradient_norm(lambda: &[f64], g: &[f64]) -> f64 {
    lambda.iter().zip(g).fold(0.0f64, |m, (&l, &g)| {
        m.max(if l > 0.0 { g.abs() } else { (-g).max(0.0) })
    })
}

/// The Newton direction over the `free` variables (zero on the others) with the Levenberg–Marquardt
/// shift `mu` raised until the free block is positive definite; `None` when no shift makes it so.
fn newton_direction(cur: &Eval, free: &[bool], mu: &mut f64, lu: &mut DenseLu) -> Option<Vec<f64>> {
    let c = free.len();
    let diag_max = (0..c)
        .fold(0.0f64, |m, i| m.max(cur.h[i * c + i].abs()))
        .max(f64::MIN_POSITIVE);
    let mut d = vec![0.0; c];
    for _ in 0..60 {
        let mut m = vec![0.0; c * c];
        for i in 0..c {
            for j in 0..c {
                m[i * c + j] = if free[i] && free[j] {
                    cur.h[i * c + j]
                } else if i == j {
                    1.0
                } else {
                    0.0
                };
            }
            if free[i] {
                m[i * c + i] += *mu;
            }
        }
        if is_positive_definite(&m, c) && lu.factor(&m).is_ok() {
            for i in 0..c {
                d[i] = if free[i] { -cur.g[i] } else { 0.0 };
            }
            lu.solve(&mut d);
            if d.iter().all(|v| v.is_finite()) {
                return Some(d);
            }
        }
        *mu = (*mu * 10.0).max(1e-10 * diag_max);
    }
    None
}

/// Objective, gradient and (when asked) Hessian of the reduced ERM objective at `lambda`.
fn evaluate(r: &Reduced, sigma: &[f64], lambda: &[f64], hessian: bool) -> Eval {
    let c = lambda.len();
    let w: Vec<f64> = (0..c)
        .map(|i| r.b[i] + (0..c).map(|j| r.a[i * c + j] * lambda[j]).sum::<f64>())
        .collect();
    let jets: Vec<_> = (0..c)
        .map(|i| normal_expected_squared(lambda[i], w[i], sigma[i]))
        .collect();
    let f = jets.iter().map(|j| j.value).sum();
    // g = e_a + A^T e_b
    let g: Vec<f64> = (0..c)
        .map(|j| jets[j].da + (0..c).map(|i| r.a[i * c + j] * jets[i].db).sum::<f64>())
        .collect();
    let mut h = Vec::new();
    if hessian {
        h = vec![0.0; c * c];
        for j in 0..c {
            for k in 0..c {
                let mut s = 0.0;
                for i in 0..c {
                    s += r.a[i * c + j] * jets[i].dbb * r.a[i * c + k];
                }
                s += jets[j].dab * r.a[j * c + k] + r.a[k * c + j] * jets[k].dab;
                if j == k {
                    s += jets[j].daa;
                }
                h[j * c + k] = s;
            }
        }
    }
    Eval { f, g, h, w }
}

/// Cholesky test of a symmetric row-major matrix.
fn is_positive_definite(m: &[f64], n: usize) -> bool {
    let mut l = vec![0.0; n * n];
    for j in 0..n {
        let mut d = m[j * n + j];
        for k in 0..j {
            d -= l[j * n + k] * l[j * n + k];
        }
        if !(d > 0.0) {
            return false;
        }
        let d = d.sqrt();
        l[j * n + j] = d;
        for i in j + 1..n {
            let mut s = 0.5 * (m[i * n + j] + m[j * n + i]);
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            l[i * n + j] = s / d;
        }
    }
    true
}
