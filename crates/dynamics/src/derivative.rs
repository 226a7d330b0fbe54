//! Exact first derivatives of the step, `fx = dx'/dx` and `fu = dx'/du`, by the implicit function theorem
//! on the step's equations (paper section IV: the smoothed impulses are differentiable functions of the
//! state).
//!
//! At the solution `z = [v'; lambda]` of `Phi(z; x, u) = 0`, with
//! `Phi = [M (v' - v) - h (r + B u) - J^T lambda; phi_i(lambda_i, w_i)]` and `w = d / h + J v'`,
//! `dz = -Phi_z^-1 Phi_x dx`. `Phi_z` is the Newton matrix of the solve; `Phi_x` comes from the same
//! kinematics code run in forward-mode dual numbers, through `geometry::signed_distance_dual` for the
//! contact rows, eight directions per pass: all of the finger's state and control entries at
//! once), then `q' = q + h v'` gives `fx = [[I + h dv'/dq, h dv'/dv]; [dv'/dq, dv'/dv]]` and `fu = [h dv'/du; dv'/du]`.
//!
//! For the hard model the derivative is that of the active set: rows with `lambda_i > 0` are held as
//! equalities `w_i = 0`, the others dropped (`lambda_i = 0`); it is the derivative of the step wherever the
//! active set does not change, and one-sided where it does.

#![allow(non_snake_case)]

use crate::constraint::Constraints;
use crate::error::DynamicsError;
use crate::kinematics::{Kinematics, Scalar};
use crate::scene::Scene;
use crate::step::{Complementarity, Simulator, Step};
use ncp::{DenseLu, LinearSolver, Mcp, NcpFunction};
use num_dual::{Dual2SVec64, DualSVec64};

/// Directions per vector-dual pass: the finger's three joint angles in one.
const DIRECTIONS: usize = 3;

/// Component `k` of a vector dual's derivative (zero when it carries none).
fn eps(d: &DualSVec64<DIRECTIONS>, k: usize) -> f64 {
    d.eps.0.as_ref().map_or(0.0, |e| e[k])
}

/// `fx` (row-major `2n x 2n`, `fx[i][j] = dx'_i / dx_j`) and `fu` (row-major `2n x n_u`).
#[derive(Debug, Clone, PartialEq)]
pub struct StepDerivatives {
    /// `dx'/dx`, row-major.
    pub fx: Vec<f64>,
    /// `dx'/du`, row-major.
    pub fu: Vec<f64>,
}

/// The step's equations at `(x, u)` for a given `z = [v'; lambda]`: the equation-of-motion residual
/// `M (v' - v) - h (r + B u) - J^T lambda` and the constraint velocities `w = d / h + J v'`.
pub fn step_residual<T: Scalar>(
    scene: &Scene,
    h: f64,
    x: &[T],
    u: &[T],
    z: &[f64],
) -> Result<(Vec<T>, Vec<T>), DynamicsError> {
    let z: Vec<T> = z.iter().map(|&e| T::from(e)).collect();
    step_residual_at(scene, h, x, u, &z)
}

/// As [`step_residual`], with `z` in the dual type too.
pub fn step_residual_at<T: Scalar>(
    scene: &Scene,
    h: f64,
    x: &[T],
    u: &[T],
    z: &[T],
) -> Result<(Vec<T>, Vec<T>), DynamicsError> {
    let n = scene.n_dof();
    let (q, v) = x.split_at(n);
    let kin = Kinematics::new(scene, q);
    let M = kin.mass_matrix(scene);
    let r = kin.applied_forces(scene, v, u);
    let cons = Constraints::new(scene, &kin, q)?;
    Ok(assemble(n, h, &M, &r, &cons.jacobian, &cons.d, v, z))
}

/// The step's equations from their ingredients: `M (v' - v) - h r - J^T lambda` and `d / h + J v'`
/// (`r` already holds `B u`).
#[allow(clippy::too_many_arguments)]
fn assemble<T: Scalar>(
    n: usize,
    h: f64,
    M: &[T],
    r: &[T],
    jac: &[T],
    d: &[T],
    v: &[T],
    z: &[T],
) -> (Vec<T>, Vec<T>) {
    let m = d.len();
    let (v_next, lambda) = z.split_at(n);
    let mut free = Vec::with_capacity(n);
    for i in 0..n {
        let mut s = -r[i] * h;
        for j in 0..n {
            s += M[i * n + j] * (-v[j] + v_next[j]);
        }
        for k in 0..m {
            s -= jac[k * n + i] * lambda[k];
        }
        free.push(s);
    }
    let w = (0..m)
        .map(|k| {
            let mut s = d[k] / h;
            for j in 0..n {
                s += jac[k * n + j] * v_next[j];
            }
            s
        })
        .collect();
    (free, w)
}

/// The Hessian pass's residual for a three-joint scene: the geometry and kinematics run in second-order
/// duals over the three joint angles only, then their values are lifted into the eight-direction duals by
/// their second-order Taylor polynomials (exact to second order), where they meet v, u, v' and lambda.
fn residual_lifted(
    scene: &Scene,
    h: f64,
    x: &[f64],
    xs: &[Dual2SVec64<HESSIAN_DIRECTIONS>],
    us: &[Dual2SVec64<HESSIAN_DIRECTIONS>],
    zs: &[Dual2SVec64<HESSIAN_DIRECTIONS>],
) -> Result<
    (
        Vec<Dual2SVec64<HESSIAN_DIRECTIONS>>,
        Vec<Dual2SVec64<HESSIAN_DIRECTIONS>>,
    ),
    DynamicsError,
> {
    type D3 = Dual2SVec64<3>;
    type D8 = Dual2SVec64<HESSIAN_DIRECTIONS>;
    let n = 3;
    let q3: Vec<D3> = (0..n).map(|i| D3::from_re(x[i]).derivative(i)).collect();
    let kin3 = Kinematics::new(scene, &q3);
    let m3 = kin3.mass_matrix(scene);
    let cons3 = Constraints::new(scene, &kin3, &q3)?;
    let s: Vec<D8> = (0..n).map(|k| D8::from_re(0.0).derivative(k)).collect();
    let mut ss = Vec::with_capacity(n * n);
    for i in 0..n {
        for j in 0..n {
            ss.push(s[i] * s[j]);
        }
    }
    let lift = |d: &D3| -> D8 {
        let mut out = D8::from_re(d.re);
        if let Some(g) = &d.v1.0 {
            for i in 0..n {
                out += s[i] * g[(0, i)];
            }
        }
        if let Some(hm) = &d.v2.0 {
            for i in 0..n {
                for j in 0..n {
                    out += ss[i * n + j] * (0.5 * hm[(i, j)]);
                }
            }
        }
        out
    };
    let lift2 = |p: &[D3; 2]| [lift(&p[0]), lift(&p[1])];
    let kin8 = Kinematics {
        phi: kin3.phi.iter().map(lift).collect(),
        hinge: kin3.hinge.iter().map(lift2).collect(),
        centre: kin3.centre.iter().map(lift2).collect(),
    };
    let v = &xs[n..];
    let r = kin8.applied_forces(scene, v, us);
    let M: Vec<D8> = m3.iter().map(lift).collect();
    let jac: Vec<D8> = cons3.jacobian.iter().map(lift).collect();
    let d: Vec<D8> = cons3.d.iter().map(lift).collect();
    Ok(assemble(n, h, &M, &r, &jac, &d, v, zs))
}

impl Simulator {
    /// The step, its Newton matrix and `dz/d(x, u)`.
    fn linearise(&mut self, x: &[f64], u: &[f64]) -> Result<Linearised, DynamicsError> {
        if self.has_state_covariance() {
            return Err(DynamicsError::Unsupported(
                "derivatives with per-row noise from a state covariance (sigma then depends on q)",
            ));
        }
        let (step, problem) = self.step_and_problem(x, u)?;
        if step.info.status != ncp::Status::Converged {
            return Err(DynamicsError::Unsupported(
                "derivatives of a step whose complementarity solve did not converge",
            ));
        }
        let scene = self.scene();
        let n = scene.n_dof();
        let nu = scene.n_controls;
        let m = step.lambda.len();
        let h = self.settings().h;
        let model = self.settings().model;
        let mut z = step.x_next[n..].to_vec();
        z.extend_from_slice(&step.lambda);
        let dim = n + m;
        let mut f = vec![0.0; dim];
        let mut jac = vec![0.0; dim * dim];
        problem.evaluate(&z, &mut f, Some(&mut jac));
        // Phi_z: the equation rows as they are, complementarity rows phi_a e_i + phi_b (row of w).
        let mut dphi = vec![(0.0, 0.0); m];
        for k in 0..m {
            let (lambda, w) = (z[n + k], f[n + k]);
            dphi[k] = match model {
                Complementarity::Logistic { sigma } => {
                    let (_, da, db) = NcpFunction::Logistic { sigma }.first_order(lambda, w);
                    (da, db)
                }
                Complementarity::Hard => {
                    if lambda > 0.0 {
                        (0.0, 1.0)
                    } else {
                        (1.0, 0.0)
                    }
                }
                Complementarity::Normal { .. } => {
                    return Err(DynamicsError::Unsupported(
                        "derivatives of the normal (ERM) model",
                    ));
                }
            };
        }
        let build = |dphi: &[(f64, f64)]| {
            let mut H = jac.clone();
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
        while !lu.factor(&H) {
            let weakest = (0..m)
                .filter(|&k| dphi[k].1 > 0.5 && dphi[k].0 < 1e-12)
                .min_by(|&a, &b| z[n + a].total_cmp(&z[n + b]));
            match weakest {
                Some(k) => {
                    dphi[k] = (1.0, 0.0);
                    H = build(&dphi);
                }
                None => {
                    return Err(DynamicsError::Unsupported(
                        "the step's Jacobian is singular at this state",
                    ));
                }
            }
        }
        // Phi_x column by column. Only the q directions pass through the geometry (vector duals, DIRECTIONS
        // at a time: one pass for the finger); v enters through M (v' - v) and r(q, v) alone, u through B.
        let cols = 2 * n + nu;
        let mut phi_x = vec![0.0; dim * cols];
        for first in (0..n).step_by(DIRECTIONS) {
            let seed = |idx: usize, v: f64| {
                let d = DualSVec64::<DIRECTIONS>::from_re(v);
                if idx < n && (first..first + DIRECTIONS).contains(&idx) {
                    d.derivative(idx - first)
                } else {
                    d
                }
            };
            let xd: Vec<_> = x.iter().enumerate().map(|(j, &v)| seed(j, v)).collect();
            let ud: Vec<_> = u
                .iter()
                .map(|&v| DualSVec64::<DIRECTIONS>::from_re(v))
                .collect();
            let (free, w) = step_residual(scene, h, &xd, &ud, &z)?;
            for k in 0..DIRECTIONS.min(n - first) {
                for i in 0..n {
                    phi_x[i * cols + first + k] = eps(&free[i], k);
                }
                for r in 0..m {
                    phi_x[(n + r) * cols + first + k] = dphi[r].1 * eps(&w[r], k);
                }
            }
        }
        let (q, v) = x.split_at(n);
        let M = &jac; // rows 0..n, columns 0..n of the step's matrix are M
        for first in (0..n).step_by(DIRECTIONS) {
            let qd: Vec<_> = q
                .iter()
                .map(|&e| DualSVec64::<DIRECTIONS>::from_re(e))
                .collect();
            let vd: Vec<_> = v
                .iter()
                .enumerate()
                .map(|(j, &e)| {
                    let d = DualSVec64::<DIRECTIONS>::from_re(e);
                    if (first..first + DIRECTIONS).contains(&j) {
                        d.derivative(j - first)
                    } else {
                        d
                    }
                })
                .collect();
            let r = Kinematics::new(scene, &qd).bias_forces(scene, &vd);
            for k in 0..DIRECTIONS.min(n - first) {
                let j = first + k;
                for i in 0..n {
                    // d/dv_j [M (v' - v) - h r] = -M_ij - h dr_i/dv_j.
                    phi_x[i * cols + n + j] = -M[i * dim + j] - h * eps(&r[i], k);
                }
            }
        }
        for (j, b) in scene.bodies.iter().enumerate() {
            if let Some(k) = b.actuator {
                phi_x[j * cols + 2 * n + k] = -h;
            }
        }
        let mut dz = vec![0.0; dim * cols];
        let mut rhs = vec![0.0; dim];
        for c in 0..cols {
            for i in 0..dim {
                rhs[i] = -phi_x[i * cols + c];
            }
            lu.solve(&mut rhs);
            for i in 0..dim {
                dz[i * cols + c] = rhs[i];
            }
        }
        Ok(Linearised {
            step,
            z,
            newton: H,
            dz,
            dphi,
        })
    }

    /// One step and its exact derivatives (logistic and hard models; the normal model's ERM derivatives
    /// are not implemented yet and return an error).
    #[tracing::instrument(name = "dynamics.step_derivatives", level = "debug", skip_all)]
    pub fn step_with_derivatives(
        &mut self,
        x: &[f64],
        u: &[f64],
    ) -> Result<(Step, StepDerivatives), DynamicsError> {
        let lin = self.linearise(x, u)?;
        let der = self.first_derivatives(&lin);
        Ok((lin.step, der))
    }

    fn first_derivatives(&self, lin: &Linearised) -> StepDerivatives {
        let scene = self.scene();
        let (n, nu, h) = (scene.n_dof(), scene.n_controls, self.settings().h);
        let cols = 2 * n + nu;
        let dv = &lin.dz;
        let nx = 2 * n;
        let mut fx = vec![0.0; nx * nx];
        let mut fu = vec![0.0; nx * nu];
        for i in 0..n {
            for j in 0..nx {
                let d = dv[i * cols + j];
                fx[i * nx + j] = h * d + if i == j { 1.0 } else { 0.0 };
                fx[(n + i) * nx + j] = d;
            }
            for k in 0..nu {
                let d = dv[i * cols + nx + k];
                fu[i * nu + k] = h * d;
                fu[(n + i) * nu + k] = d;
            }
        }
        StepDerivatives { fx, fu }
    }

    /// One step, its first derivatives, and for a given `c` (length `2n`, the value gradient of DDP) the
    /// Hessian of `c^T f(x, u)` with respect to `y = (x, u)`, row-major `(2n + n_u)^2`: the `f_xx`, `f_xu`,
    /// `f_uu` terms contracted with `c`. Second-order adjoint: with `Phi_z^T mu = -g`, `g = dz' c`,
    /// `d^2 (c^T f) / dy^2 = T^T (d^2 (mu^T Phi) / d(z, y)^2) T`, `T = [dz/dy; I]`, the inner Hessian along
    /// the columns of `T` in one pass of second-order vector duals (`num_dual::Dual2SVec64`).
    #[tracing::instrument(name = "dynamics.step_hessian", level = "debug", skip_all)]
    pub fn step_with_hessian(
        &mut self,
        x: &[f64],
        u: &[f64],
        c: &[f64],
    ) -> Result<(Step, StepDerivatives, Vec<f64>), DynamicsError> {
        let scene = self.scene().clone();
        let (n, nu, h) = (scene.n_dof(), scene.n_controls, self.settings().h);
        if c.len() != 2 * n || !c.iter().all(|e| e.is_finite()) {
            return Err(DynamicsError::Input {
                what: "c",
                problem: format!("needs {} finite entries", 2 * n),
            });
        }
        let cols = 2 * n + nu;
        if cols > HESSIAN_DIRECTIONS {
            return Err(DynamicsError::Unsupported(
                "Hessians of scenes with more than 8 state and control entries",
            ));
        }
        let model = self.settings().model;
        let lin = self.linearise(x, u)?;
        let der = self.first_derivatives(&lin);
        let dim = lin.z.len();
        let m = dim - n;
        // g = (dx'/dz)^T c: x' = [q + h v'; v'].
        let mut g = vec![0.0; dim];
        for i in 0..n {
            g[i] = h * c[i] + c[n + i];
        }
        // mu from Phi_z^T mu = -g.
        let mut transposed = vec![0.0; dim * dim];
        for i in 0..dim {
            for j in 0..dim {
                transposed[j * dim + i] = lin.newton[i * dim + j];
            }
        }
        let mut lu = DenseLu::new(dim, LinearSolver::Hand);
        if !lu.factor(&transposed) {
            return Err(DynamicsError::Unsupported(
                "the step's Jacobian is singular at this state",
            ));
        }
        let mut mu: Vec<f64> = g.iter().map(|e| -e).collect();
        lu.solve(&mut mu);
        // (z, y) = (z0 + dz s, y0 + s) with s the vector-dual variables.
        type D2 = Dual2SVec64<HESSIAN_DIRECTIONS>;
        let s: Vec<D2> = (0..cols).map(|k| D2::from_re(0.0).derivative(k)).collect();
        let affine = |base: f64, coeffs: &[f64]| {
            coeffs
                .iter()
                .zip(&s)
                .fold(D2::from_re(base), |acc, (a, sk)| acc + *sk * *a)
        };
        let zs: Vec<D2> = (0..dim)
            .map(|i| affine(lin.z[i], &lin.dz[i * cols..(i + 1) * cols]))
            .collect();
        let unit = |k: usize| {
            (0..cols)
                .map(|j| if j == k { 1.0 } else { 0.0 })
                .collect::<Vec<f64>>()
        };
        let xs: Vec<D2> = (0..2 * n).map(|k| affine(x[k], &unit(k))).collect();
        let us: Vec<D2> = (0..nu).map(|k| affine(u[k], &unit(2 * n + k))).collect();
        let (free, w) = if n == 3 {
            residual_lifted(&scene, h, x, &xs, &us, &zs)?
        } else {
            step_residual_at(&scene, h, &xs, &us, &zs)?
        };
        let mut psi = D2::from_re(0.0);
        for i in 0..n {
            psi += free[i] * mu[i];
        }
        for k in 0..m {
            let (lambda, wk) = (zs[n + k], w[k]);
            // Rows the linearisation held fixed (redundant active rows) stay fixed here, so that mu and dz/dy
            // describe the same system.
            let phi = match (model, lin.dphi[k]) {
                (_, (a, b)) if a == 1.0 && b == 0.0 => lambda,
                (Complementarity::Hard, _) => wk,
                (Complementarity::Logistic { sigma }, _) => logistic(lambda, wk, sigma),
                (Complementarity::Normal { .. }, _) => {
                    unreachable!("linearise rejects the normal model")
                }
            };
            psi += phi * mu[n + k];
        }
        let hess = psi.v2.0.map_or_else(
            || vec![0.0; cols * cols],
            |hm| {
                let mut out = vec![0.0; cols * cols];
                for i in 0..cols {
                    for j in 0..cols {
                        out[i * cols + j] = hm[(i, j)];
                    }
                }
                out
            },
        );
        Ok((lin.step, der, hess))
    }
}

/// Directions of the second-order pass: the finger's 6 state and 2 control entries.
const HESSIAN_DIRECTIONS: usize = 8;

/// What the first-order linearisation of a step keeps.
struct Linearised {
    step: Step,
    z: Vec<f64>,
    newton: Vec<f64>,
    /// `dz/d(x, u)`, row-major `(n + m) x (2n + n_u)`.
    dz: Vec<f64>,
    /// `(d phi/d lambda, d phi/d w)` per row at the solution.
    dphi: Vec<(f64, f64)>,
}

/// The logistic NCP function of paper eq. (17) in any dual type: `min(a, b) - s softplus(-|a - b| / s)`.
fn logistic<T: Scalar>(a: T, b: T, sigma: f64) -> T {
    let c = (a - b) / sigma;
    if c.re() > 0.0 {
        b - (-c).exp().ln_1p() * sigma
    } else {
        a - c.exp().ln_1p() * sigma
    }
}
