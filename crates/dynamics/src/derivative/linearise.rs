//! Stage 2 of the derivatives: the step's equations `K(p; y) = 0` in their unknowns `p` at the step's
//! solution, each complementarity row typed by what it is at that solution ([`RowKind`]), `K_p` factored,
//! and `dp/dy` by the implicit function theorem, eight directions of `y = (x, u)` per pass.

#![allow(non_snake_case)]

use super::expansion::{D1, DIRECTIONS, Expansion, Ingredients};
use crate::constraint::Constraints;
use crate::error::DynamicsError;
use crate::kinematics::Scalar;
use crate::step::{Complementarity, Model, StepData};
use ncp::{
    DenseLu, LinearSolver, Mcp, NcpFunction, normal_expected_squared, normal_expected_squared_third,
};

/// The unknowns at the solution, the Jacobian of the equations in them (and its factors), each row's kind
/// and each complementarity row's slope in `w` (logistic and hard models; empty for the normal model).
pub(super) type Equations = (Vec<f64>, Vec<f64>, DenseLu, Vec<RowKind>, Vec<f64>);

/// What a complementarity row of the linearised step is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum RowKind {
    /// `lambda_i` held at its value: an inactive hard row, a normal row on its bound, or a redundant row.
    Fixed,
    /// An active hard row, `w_i = 0`.
    Contact,
    /// The logistic function of eq. (17), `phi(lambda_i, w_i; sigma_i) = 0`.
    Logistic,
    /// A normal (ERM) row off its bound: the stationarity `d E_i / d lambda_i - (J nu)_i = 0`.
    Stationary,
}

/// The equations whose root the step is, in the unknowns `p`:
///
/// - logistic and hard: `p = [v'; lambda]`, `[M (v' - v) - h r - J^T lambda; row_i(lambda_i, w_i)]`;
/// - normal (eq. 14 with 15 as an optimisation over `lambda >= 0` with `v'` from the equations of motion):
///   `p = [v'; lambda; nu]` and the first-order conditions
///   `[M (v' - v) - h r - J^T lambda; J^T e_b + M nu; e_a,i - (J nu)_i or lambda_i]`, `e = E[min(lambda, w +
///   sigma xi)^2]` per row, its derivatives in `(lambda, w)` carried to second order by their Taylor
///   polynomials around the solution (exact for first and second derivatives of the step).
pub(super) fn system<T: Scalar>(
    n: usize,
    h: f64,
    ing: &Ingredients<T>,
    v: &[T],
    p: &[T],
    kinds: &[RowKind],
    normal: bool,
) -> Vec<T> {
    let m = ing.d.len();
    let (vn, rest) = p.split_at(n);
    let lambda = &rest[..m];
    let mut out = Vec::with_capacity(p.len());
    for i in 0..n {
        let mut s = -ing.r[i] * h;
        for j in 0..n {
            s += ing.M[i * n + j] * (vn[j] - v[j]);
        }
        for k in 0..m {
            s -= ing.jac[k * n + i] * lambda[k];
        }
        out.push(s);
    }
    let w: Vec<T> = (0..m)
        .map(|k| {
            let mut s = ing.d[k] / h;
            for j in 0..n {
                s += ing.jac[k * n + j] * vn[j];
            }
            s
        })
        .collect();
    if !normal {
        for k in 0..m {
            out.push(match kinds[k] {
                RowKind::Fixed => lambda[k],
                RowKind::Contact => w[k],
                RowKind::Logistic => logistic(lambda[k], w[k], ing.sigma[k]),
                RowKind::Stationary => unreachable!("stationary rows belong to the normal model"),
            });
        }
        return out;
    }
    let nu = &rest[m..m + n];
    let mut ea = Vec::with_capacity(m);
    let mut eb = Vec::with_capacity(m);
    for k in 0..m {
        let (l0, w0, sigma) = (lambda[k].re(), w[k].re(), ing.sigma[k].re());
        let j = normal_expected_squared(l0, w0, sigma);
        let [aaa, aab, abb, bbb] = normal_expected_squared_third(l0, w0, sigma);
        let (dl, dw) = (lambda[k] - l0, w[k] - w0);
        let (ll, lw, ww) = (dl * dl * 0.5, dl * dw, dw * dw * 0.5);
        ea.push(dl * j.daa + dw * j.dab + ll * aaa + lw * aab + ww * abb + j.da);
        eb.push(dl * j.dab + dw * j.dbb + ll * aab + lw * abb + ww * bbb + j.db);
    }
    for i in 0..n {
        let mut s = T::from(0.0);
        for k in 0..m {
            s += ing.jac[k * n + i] * eb[k];
        }
        for j in 0..n {
            s += ing.M[i * n + j] * nu[j];
        }
        out.push(s);
    }
    for k in 0..m {
        out.push(match kinds[k] {
            RowKind::Fixed => lambda[k],
            RowKind::Stationary => {
                let mut s = ea[k];
                for j in 0..n {
                    s -= ing.jac[k * n + j] * nu[j];
                }
                s
            }
            _ => unreachable!("normal rows are fixed or stationary"),
        });
    }
    out
}

/// Where the step to linearise comes from. The public entry points check the data (and, to solve, `x` and
/// `u`) once; the stages below trust them.
pub(super) enum Source<'a> {
    /// Solve it now in this data (the ingredients' values make its problem: the geometry runs once).
    Solve(&'a mut StepData),
    /// The step this data holds, linearised as it is (no second solve).
    Stored(&'a StepData),
}

impl Source<'_> {
    /// The data, with the step once it is solved.
    pub(super) fn data(&self) -> &StepData {
        match self {
            Source::Solve(data) => data,
            Source::Stored(data) => data,
        }
    }
}

impl Model {
    /// The step, the Jacobian of its equations in their unknowns and `dp/d(x, u)`.
    /// With `second` (the Hessian pass computes them anyway) the first-order ingredients are read off it.
    pub(super) fn linearise(
        &self,
        x: &[f64],
        u: &[f64],
        second: Option<&Expansion>,
        source: &mut Source<'_>,
    ) -> Result<Linearised, DynamicsError> {
        let model = self.settings().model;
        if self.has_state_covariance() && matches!(model, Complementarity::Normal { .. }) {
            return Err(DynamicsError::Unsupported(
                "derivatives of the normal model with per-row noise from a state covariance",
            ));
        }
        let (n, nu) = (self.scene().n_dof(), self.scene().n_controls);
        let cols = 2 * n + nu;
        // With the second-order expansion of a logistic or hard step with a constant noise, the
        // equations' derivatives in y are read off the ingredients' gradients directly; otherwise the
        // ingredients run in first-order duals, eight directions of y per pass.
        let direct = second.filter(|_| {
            !self.has_state_covariance() && !matches!(model, Complementarity::Normal { .. })
        });
        let mut passes = Vec::new();
        if direct.is_none() {
            for first in (0..cols).step_by(DIRECTIONS) {
                passes.push(match second {
                    Some(so) => so.first_order(first, cols),
                    _ => self.first_order_ingredients(x, u, first)?,
                });
            }
        }
        // The ingredients' values make the step's problem (the geometry runs once).
        let (M, mut r, cons) = match direct {
            Some(ex) => ex.values(),
            None => {
                let values = |v: &[D1]| v.iter().map(|e| e.re).collect::<Vec<f64>>();
                let ing = &passes[0];
                let cons = Constraints {
                    d: ing.distance.clone(),
                    jacobian: values(&ing.jac),
                    contacts: ing.contacts.clone(),
                };
                (values(&ing.M), values(&ing.r), cons)
            }
        };
        for (r, f) in r.iter_mut().zip(source.data().forces()) {
            *r += f;
        }
        let problem = self.assemble_problem(&x[n..], &M, &r, cons)?;
        let problem = match source {
            Source::Stored(_) => problem.0,
            Source::Solve(data) => self.solve_into(data, x, u, problem)?,
        };
        let step = source
            .data()
            .step()
            .expect("a stored step (checked by the entry point) or one just solved");
        if step.info.status != ncp::Status::Converged {
            return Err(DynamicsError::Unsupported(
                "derivatives of a step whose complementarity solve did not converge",
            ));
        }
        let m = step.lambda.len();
        let h = self.settings().h;
        let mut z = step.x_next[n..].to_vec();
        z.extend_from_slice(&step.lambda);
        let dim = n + m;
        let mut f = vec![0.0; dim];
        let mut jac = vec![0.0; dim * dim];
        problem.evaluate(&z, &mut f, Some(&mut jac));
        let normal = matches!(model, Complementarity::Normal { .. });
        let (p, _, mut lu, kinds, slope) = if normal {
            self.normal_system(&z, &f, &jac, n)?
        } else {
            self.complementarity_system(&z, &f, &jac, n)?
        };
        let np = p.len();
        let mut dp = vec![0.0; np * cols];
        if let Some(ex) = direct {
            ex.equations_y(h, &x[n..], &p, &slope, &mut dp);
        }
        // Otherwise the equations' derivatives in y = (x, u) in duals, eight directions per pass (one
        // pass for the finger).
        let pc: Vec<D1> = p.iter().map(|&e| D1::from_re(e)).collect();
        for (ing, first) in passes.iter().zip((0..cols).step_by(DIRECTIONS)) {
            let v: Vec<D1> = (0..n)
                .map(|j| {
                    let d = D1::from_re(x[n + j]);
                    if (first..first + DIRECTIONS).contains(&(n + j)) {
                        d.derivative(n + j - first)
                    } else {
                        d
                    }
                })
                .collect();
            let res = system(n, h, ing, &v, &pc, &kinds, normal);
            for k in 0..DIRECTIONS.min(cols - first) {
                for (i, e) in res.iter().enumerate() {
                    dp[i * cols + first + k] = -e.eps.0.as_ref().map_or(0.0, |g| g[k]);
                }
            }
        }
        lu.solve_many(&mut dp, cols);
        // The position-level correction's derivatives: a function of q alone, read off its duals.
        let mut dcorrection = vec![0.0; n * cols];
        if let Some(ex) = direct {
            let geo = &ex.geometry;
            for i in 0..n {
                dcorrection[i * cols..i * cols + n].copy_from_slice(geo.g(ex.correction(i)));
            }
        }
        for (ing, first) in passes.iter().zip((0..cols).step_by(DIRECTIONS)) {
            for (i, e) in ing.correction.iter().enumerate() {
                if let Some(g) = e.eps.0.as_ref() {
                    for k in 0..DIRECTIONS.min(cols - first) {
                        dcorrection[i * cols + first + k] = g[k];
                    }
                }
            }
        }
        Ok(Linearised {
            p,
            lu,
            dp,
            kinds,
            dcorrection,
        })
    }

    /// Logistic and hard models: `p = z`, the Newton matrix with each row's `(d phi/d lambda, d phi/d w)`;
    /// redundant active rows held fixed.
    fn complementarity_system(
        &self,
        z: &[f64],
        f: &[f64],
        jac: &[f64],
        n: usize,
    ) -> Result<Equations, DynamicsError> {
        let dim = z.len();
        let m = dim - n;
        let model = self.settings().model;
        let sigmas: Vec<f64> = match self.state_covariance() {
            Some(_) => {
                let rows: Vec<f64> = (0..m)
                    .flat_map(|k| jac[(n + k) * dim..(n + k) * dim + n].to_vec())
                    .collect();
                self.noise(&rows, m)
            }
            None => self.noise(&vec![0.0; m * n], m),
        };
        let mut kinds = Vec::with_capacity(m);
        let mut dphi = vec![(0.0, 0.0); m];
        for k in 0..m {
            let (lambda, w) = (z[n + k], f[n + k]);
            let (kind, d) = match model {
                Complementarity::Logistic { .. } => {
                    let sigma = sigmas[k];
                    let (_, da, db) = NcpFunction::Logistic { sigma }.first_order(lambda, w);
                    (RowKind::Logistic, (da, db))
                }
                _ if lambda > 0.0 => (RowKind::Contact, (0.0, 1.0)),
                _ => (RowKind::Fixed, (1.0, 0.0)),
            };
            kinds.push(kind);
            dphi[k] = d;
        }
        let build = |dphi: &[(f64, f64)]| {
            let mut H = jac.to_vec();
            for k in 0..m {
                let row = &mut H[(n + k) * dim..(n + k + 1) * dim];
                for e in row.iter_mut() {
                    *e *= dphi[k].1;
                }
                row[n + k] += dphi[k].0;
            }
            H
        };
        let mut H = build(&dphi);
        let mut lu = DenseLu::new(dim, LinearSolver::Hand);
        // Redundant active rows (more than the velocities can satisfy independently) make the matrix
        // singular: exactly for the hard model's active set, to working precision for a smoothed row whose
        // d phi / d lambda has underflowed (lambda >> sigma). The velocities are still unique. Hold the
        // smallest impulses of such rows fixed, one at a time, until the remaining active rows are
        // independent: the derivative of that branch of impulses, and the derivative of v'.
        while let Err(cause) = lu.factor(&H) {
            let weakest = (0..m)
                .filter(|&k| dphi[k].1 > 0.5 && dphi[k].0 < 1e-12)
                .min_by(|&a, &b| z[n + a].total_cmp(&z[n + b]));
            match weakest {
                Some(k) => {
                    dphi[k] = (1.0, 0.0);
                    kinds[k] = RowKind::Fixed;
                    H = build(&dphi);
                }
                None => {
                    return Err(DynamicsError::Singular {
                        what: "the step's Jacobian",
                        cause,
                    });
                }
            }
        }
        let slope = dphi.iter().map(|d| d.1).collect();
        Ok((z.to_vec(), H, lu, kinds, slope))
    }

    /// Normal model: `p = [v'; lambda; nu]` with `nu = -M^-1 J^T e_b` and the first-order conditions'
    /// Jacobian; rows with `lambda_i = 0` are on their bound and held there.
    fn normal_system(
        &self,
        z: &[f64],
        f: &[f64],
        jac: &[f64],
        n: usize,
    ) -> Result<Equations, DynamicsError> {
        let dim = z.len();
        let m = dim - n;
        let sigmas = self.noise(&vec![0.0; m * n], m);
        let M = |i: usize, j: usize| jac[i * dim + j];
        let J = |k: usize, j: usize| jac[(n + k) * dim + j];
        let jets: Vec<_> = (0..m)
            .map(|k| normal_expected_squared(z[n + k], f[n + k], sigmas[k]))
            .collect();
        let kinds: Vec<RowKind> = (0..m)
            .map(|k| {
                if z[n + k] > 0.0 {
                    RowKind::Stationary
                } else {
                    RowKind::Fixed
                }
            })
            .collect();
        // nu from M nu = -J^T e_b.
        let mut lu = DenseLu::new(n, LinearSolver::Hand);
        let mass: Vec<f64> = (0..n * n).map(|e| M(e / n, e % n)).collect();
        lu.factor(&mass).map_err(|cause| DynamicsError::Singular {
            what: "the mass matrix",
            cause,
        })?;
        let mut nu: Vec<f64> = (0..n)
            .map(|i| -(0..m).map(|k| J(k, i) * jets[k].db).sum::<f64>())
            .collect();
        lu.solve(&mut nu);
        let np = 2 * n + m;
        let mut H = vec![0.0; np * np];
        for i in 0..n {
            for j in 0..n {
                H[i * np + j] = M(i, j);
                // K2 = J^T e_b + M nu: d/dv' = J^T diag(e_bb) J, d/dlambda = J^T diag(e_ab), d/dnu = M.
                H[(n + i) * np + n + m + j] = M(i, j);
                H[(n + i) * np + j] = (0..m).map(|k| J(k, i) * jets[k].dbb * J(k, j)).sum();
            }
            for k in 0..m {
                H[i * np + n + k] = -J(k, i);
                H[(n + i) * np + n + k] = J(k, i) * jets[k].dab;
            }
        }
        for k in 0..m {
            let row = n + n + k;
            match kinds[k] {
                RowKind::Stationary => {
                    for j in 0..n {
                        H[row * np + j] = jets[k].dab * J(k, j);
                        H[row * np + n + m + j] = -J(k, j);
                    }
                    H[row * np + n + k] = jets[k].daa;
                }
                _ => H[row * np + n + k] = 1.0,
            }
        }
        let mut p = z.to_vec();
        p.extend_from_slice(&nu);
        let mut lu = DenseLu::new(np, LinearSolver::Hand);
        lu.factor(&H).map_err(|cause| DynamicsError::Singular {
            what: "the step's Jacobian",
            cause,
        })?;
        Ok((p, H, lu, kinds, Vec::new()))
    }
}

/// What the linearisation of a step keeps.
pub(super) struct Linearised {
    /// The unknowns of the step's equations at the solution ([`system`]).
    pub(super) p: Vec<f64>,
    /// The factors of `K_p`.
    pub(super) lu: DenseLu,
    /// `dp/d(x, u)`, row-major `len(p) x (2n + n_u)`.
    pub(super) dp: Vec<f64>,
    /// Each complementarity row's kind.
    pub(super) kinds: Vec<RowKind>,
    /// `d dq / d(x, u)` of the position-level correction, row-major `n x (2n + n_u)`.
    pub(super) dcorrection: Vec<f64>,
}

/// The logistic NCP function of paper eq. (17) in any dual type: `min(a, b) - s softplus(-|a - b| / s)`.
fn logistic<T: Scalar>(a: T, b: T, sigma: T) -> T {
    let c = (a - b) / sigma;
    if c.re() > 0.0 {
        b - (-c).exp().ln_1p() * sigma
    } else {
        a - c.exp().ln_1p() * sigma
    }
}
