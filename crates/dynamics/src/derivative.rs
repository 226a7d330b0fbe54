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
use num_dual::DualSVec64;

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
    let n = scene.n_dof();
    let (q, v) = x.split_at(n);
    let kin = Kinematics::new(scene, q);
    let M = kin.mass_matrix(scene);
    let mut r = kin.bias_forces(scene, v);
    for (j, b) in scene.bodies.iter().enumerate() {
        if let Some(k) = b.actuator {
            r[j] += u[k];
        }
    }
    let cons = Constraints::new(scene, &kin, q)?;
    let m = cons.d.len();
    let (v_next, lambda) = z.split_at(n);
    let mut free = Vec::with_capacity(n);
    for i in 0..n {
        let mut s = -r[i] * h;
        for j in 0..n {
            s += M[i * n + j] * (-v[j] + v_next[j]);
        }
        for k in 0..m {
            s -= cons.jacobian[k * n + i] * lambda[k];
        }
        free.push(s);
    }
    let w = (0..m)
        .map(|k| {
            let mut s = cons.d[k] / h;
            for j in 0..n {
                s += cons.jacobian[k * n + j] * v_next[j];
            }
            s
        })
        .collect();
    Ok((free, w))
}

impl Simulator {
    /// One step and its exact derivatives (logistic and hard models; the normal model's ERM derivatives
    /// are not implemented yet and return an error).
    #[tracing::instrument(name = "dynamics.step_derivatives", level = "debug", skip_all)]
    pub fn step_with_derivatives(
        &mut self,
        x: &[f64],
        u: &[f64],
    ) -> Result<(Step, StepDerivatives), DynamicsError> {
        let (step, problem) = self.step_and_problem(x, u)?;
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
        let mut H = jac.clone();
        for k in 0..m {
            let row = &mut H[(n + k) * dim..(n + k + 1) * dim];
            for e in row.iter_mut() {
                *e *= dphi[k].1;
            }
            row[n + k] += dphi[k].0;
        }
        let mut lu = DenseLu::new(dim, LinearSolver::Hand);
        if !lu.factor(&H) {
            return Err(DynamicsError::Unsupported(
                "the step's Jacobian is singular at this state",
            ));
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
        let mut dv = vec![0.0; n * cols];
        let mut rhs = vec![0.0; dim];
        for c in 0..cols {
            for i in 0..dim {
                rhs[i] = -phi_x[i * cols + c];
            }
            lu.solve(&mut rhs);
            for i in 0..n {
                dv[i * cols + c] = rhs[i];
            }
        }
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
        Ok((step, StepDerivatives { fx, fu }))
    }
}
