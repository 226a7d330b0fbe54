//! Exact first and second derivatives of the step, `fx = dx'/dx`, `fu = dx'/du` and the Hessian of
//! `c^T f(x, u)`, by the implicit function theorem on the step's equations (paper section IV: the smoothed
//! impulses are differentiable functions of the state), for scenes of any size.
//!
//! At the solution `z = [v'; lambda]` of `Phi(z; x, u) = 0`, with
//! `Phi = [M (v' - v) - h (r + B u) - J^T lambda; phi_i(lambda_i, w_i)]` and `w = d / h + J v'`,
//! `dz = -Phi_z^-1 Phi_x dx`. `Phi_z` is the Newton matrix of the solve; `Phi_x` comes from the same
//! kinematics code run in forward-mode dual numbers, through `geometry::signed_distance_dual` for the
//! contact rows; then `q' = q + h v'` gives `fx = [[I + h dv'/dq, h dv'/dv]; [dv'/dq, dv'/dv]]` and
//! `fu = [h dv'/du; dv'/du]`.
//!
//! For the hard model the derivative is that of the active set: rows with `lambda_i > 0` are held as
//! equalities `w_i = 0`, the others dropped (`lambda_i = 0`); it is the derivative of the step wherever the
//! active set does not change, and one-sided where it does.
//!
//! One file per stage: `expansion` (the ingredients and their derivatives in `y = (x, u)`), `linearise`
//! (the equations at the step's solution, their Jacobian and `dp/dy`), `hessian` (the second-order adjoint);
//! `residual` evaluates the equations themselves.

mod expansion;
mod hessian;
mod linearise;
mod residual;

pub use hessian::SecondOrderStep;
pub use residual::{step_residual, step_residual_at};

use crate::error::DynamicsError;
use crate::step::{Simulator, Step};
use linearise::Linearised;

/// `fx` (row-major `2n x 2n`, `fx[i][j] = dx'_i / dx_j`) and `fu` (row-major `2n x n_u`).
#[derive(Debug, Clone, PartialEq)]
pub struct StepDerivatives {
    /// `dx'/dx`, row-major.
    pub fx: Vec<f64>,
    /// `dx'/du`, row-major.
    pub fu: Vec<f64>,
}

impl Simulator {
    /// One step and its exact derivatives, for every model: the hard model's are its active set's (module
    /// documentation), the normal model's those of the first-order conditions of its minimisation.
    #[tracing::instrument(name = "dynamics.step_derivatives", level = "debug", skip_all)]
    pub fn step_with_derivatives(
        &mut self,
        x: &[f64],
        u: &[f64],
    ) -> Result<(Step, StepDerivatives), DynamicsError> {
        let lin = self.linearise(x, u, None, None)?;
        let der = self.first_derivatives(&lin);
        Ok((lin.step, der))
    }

    /// The exact derivatives of `step`, a step this simulator computed from `x` under `u` (by
    /// [`Simulator::step`] or a derivative call): its solution is linearised as it is, without solving the
    /// step again, so the derivatives belong to exactly the step the caller holds (and the warm start is
    /// left alone). A step computed from another `(x, u)` gives the derivatives of a wrong point; one with
    /// another number of rows is an error.
    #[tracing::instrument(name = "dynamics.derivatives_of", level = "debug", skip_all)]
    pub fn derivatives_of(
        &mut self,
        x: &[f64],
        u: &[f64],
        step: &Step,
    ) -> Result<StepDerivatives, DynamicsError> {
        let lin = self.linearise(x, u, None, Some(step))?;
        Ok(self.first_derivatives(&lin))
    }

    fn first_derivatives(&self, lin: &Linearised) -> StepDerivatives {
        let scene = self.scene();
        let (n, nu, h) = (scene.n_dof(), scene.n_controls, self.settings().h);
        let cols = 2 * n + nu;
        let dv = &lin.dp;
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
    /// `f_uu` terms contracted with `c`. [`Simulator::second_order_step`] then
    /// [`SecondOrderStep::hessian`]; use those directly to contract one step with several `c`.
    #[tracing::instrument(name = "dynamics.step_hessian", level = "debug", skip_all)]
    pub fn step_with_hessian(
        &mut self,
        x: &[f64],
        u: &[f64],
        c: &[f64],
    ) -> Result<(Step, StepDerivatives, Vec<f64>), DynamicsError> {
        let so = self.second_order_step(x, u)?;
        let hess = so.hessian(c)?;
        Ok((so.step, so.derivatives, hess))
    }

    /// One step, its first derivatives, and everything its second derivatives need except the vector
    /// they are contracted with (any scene): the step's linearisation, the factors of `K_p^T`, and the
    /// Hessians of the step's equations along `T`. About three
    /// quarters of the work of [`Simulator::step_with_hessian`]; each [`SecondOrderStep::hessian`] is the
    /// rest.
    #[tracing::instrument(name = "dynamics.second_order_step", level = "debug", skip_all)]
    pub fn second_order_step(
        &mut self,
        x: &[f64],
        u: &[f64],
    ) -> Result<SecondOrderStep, DynamicsError> {
        self.second_order(x, u, None)
    }

    /// [`Simulator::second_order_step`] of `step`, a step this simulator computed from `x` under `u`: its
    /// solution is linearised as it is, without a second solve (see [`Simulator::derivatives_of`]).
    #[tracing::instrument(name = "dynamics.second_order_of", level = "debug", skip_all)]
    pub fn second_order_of(
        &mut self,
        x: &[f64],
        u: &[f64],
        step: &Step,
    ) -> Result<SecondOrderStep, DynamicsError> {
        self.second_order(x, u, Some(step))
    }
}
