//! Exact first and second derivatives of the step, `fx = dx'/dx`, `fu = dx'/du` and the Hessian of
//! `c^T f(x, u)`, by the implicit function theorem on the step's equations (paper section IV: the smoothed
//! impulses are differentiable functions of the state), for scenes of any size.
//!
//! At the solution `z = [v'; lambda]` of `Phi(z; x, u) = 0`, with
//! `Phi = [M (v' - v) - h (r + B u) - J^T lambda; phi_i(lambda_i, w_i)]` and `w = d / h + J v'`,
//! `dz = -Phi_z^-1 Phi_x dx`. `Phi_z` is the Newton matrix of the solve; `Phi_x` comes from the same
//! kinematics code run in forward-mode dual numbers, through `geometry::signed_distance_dual` for the
//! contact rows; then `q' = q + dq(q) + h v'` (`dq` the position-level correction,
//! [`Model::position_correction`], differentiated with the ingredients) gives
//! `fx = [[I + d dq/dq + h dv'/dq, h dv'/dv]; [dv'/dq, dv'/dv]]` and `fu = [h dv'/du; dv'/du]`.
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

pub(crate) use hessian::SecondOrderParts;
pub use hessian::SecondOrderStep;
pub use residual::{step_residual, step_residual_at};

use crate::error::DynamicsError;
use crate::step::{Model, StepData, check};
use linearise::{Linearised, Source};

/// `fx` (row-major `2n x 2n`, `fx[i][j] = dx'_i / dx_j`) and `fu` (row-major `2n x n_u`).
#[derive(Debug, Clone, PartialEq)]
pub struct StepDerivatives {
    /// `dx'/dx`, row-major.
    pub fx: Vec<f64>,
    /// `dx'/du`, row-major.
    pub fu: Vec<f64>,
}

/// The most memory one step's second-order expansion may take ([`Model::second_order_bytes`]): 1 GiB.
/// Its Taylor expansion of `M(q)` grows like the fourth power of the joints, so a scene of a few hundred
/// joints would ask for tens of gigabytes a knot; it is refused with the estimate instead.
pub const SECOND_ORDER_MAX_BYTES: usize = 1 << 30;

impl Model {
    /// An estimate, before anything is allocated, of the bytes one step's second-order expansion
    /// ([`Model::second_order`]) holds: the second-order Taylor expansions of `M`, `J`, `d` and the
    /// noise over `q` and of the forces over `(q, v)`, and the Hessians of the step's equations over
    /// `(x, u)`. An optimiser that keeps one per knot needs this times its knots.
    pub fn second_order_bytes(&self) -> usize {
        let scene = self.scene();
        let (n, m, nu) = (scene.n_dof(), scene.n_constraints(), scene.n_controls);
        let taylor = |len: usize, dim: usize| len.saturating_mul(1 + dim + dim.saturating_mul(dim));
        let cols = 2 * n + nu;
        let doubles = taylor(n * n + m * n + 2 * m, n)
            .saturating_add(taylor(n, 2 * n))
            .saturating_add(
                (n + m)
                    .saturating_mul(cols)
                    .saturating_mul(cols)
                    .saturating_mul(2),
            );
        doubles.saturating_mul(std::mem::size_of::<f64>())
    }

    /// The first derivatives of the step `data` holds ([`Model::derivatives`]), kept in `data` (and read
    /// from it when [`Model::calc_diff2_prepare`] computed them already) until its next step: the
    /// first-order stage of the optimiser's knots, without copying.
    pub fn calc_diff<'d>(
        &self,
        data: &'d mut StepData,
    ) -> Result<&'d StepDerivatives, DynamicsError> {
        if data.derivatives.is_none() {
            let d = self.derivatives(data)?;
            data.derivatives = Some(d);
        }
        Ok(data.derivatives.as_ref().expect("kept above"))
    }

    /// Keep in `data` the first derivatives of the step it holds and everything its second derivatives
    /// need except the vector they are contracted with ([`Model::second_order`], without copying the
    /// step); nothing when they are kept already. Each [`Model::calc_diff2`] is then the contraction.
    pub fn calc_diff2_prepare(&self, data: &mut StepData) -> Result<(), DynamicsError> {
        if data.second.is_none() {
            let (x, u) = self.stored_point(data)?;
            let (derivatives, parts) = self.second_order_parts(x, u, Source::Stored(data))?;
            data.derivatives = Some(derivatives);
            data.second = Some(parts);
        }
        Ok(())
    }

    /// The Hessian of `c^T f(x, u)` with respect to `y = (x, u)` for the step `data` holds, into `hess`
    /// (row-major `(2n + n_u)^2`), and its first derivatives: [`Model::calc_diff2_prepare`] (if it has
    /// not run since the step) and the contraction with `c` ([`SecondOrderStep::hessian`]).
    pub fn calc_diff2<'d>(
        &self,
        data: &'d mut StepData,
        c: &[f64],
        hess: &mut [f64],
    ) -> Result<&'d StepDerivatives, DynamicsError> {
        self.calc_diff2_prepare(data)?;
        data.second
            .as_mut()
            .expect("prepared above")
            .hessian_into(c, hess)?;
        Ok(data.derivatives.as_ref().expect("prepared above"))
    }

    /// The exact derivatives of the step `data` holds (the last [`Model::step`] computed with it), at the
    /// `(x, u)` it was computed from: its solution is linearised as it is, never solved again, so the
    /// derivatives belong to exactly that step. For every model: the hard model's are its active set's
    /// (module documentation), the normal model's those of the first-order conditions of its minimisation.
    /// `Err` when `data` holds no step.
    #[tracing::instrument(name = "dynamics.derivatives", level = "debug", skip_all)]
    pub fn derivatives(&self, data: &StepData) -> Result<StepDerivatives, DynamicsError> {
        let (x, u) = self.stored_point(data)?;
        let lin = self.linearise(x, u, None, &mut Source::Stored(data))?;
        Ok(self.first_derivatives(&lin))
    }

    /// One step from `x` under `u` in `data` (as [`Model::step`]) and its exact derivatives, the geometry
    /// evaluated once for both.
    #[tracing::instrument(name = "dynamics.step_derivatives", level = "debug", skip_all)]
    pub fn step_with_derivatives(
        &self,
        data: &mut StepData,
        x: &[f64],
        u: &[f64],
    ) -> Result<StepDerivatives, DynamicsError> {
        self.check_point(data, x, u)?;
        let lin = self.linearise(x, u, None, &mut Source::Solve(data))?;
        Ok(self.first_derivatives(&lin))
    }

    /// The point of the step `data` holds; `Err` for data of another model or holding no step.
    fn stored_point<'d>(
        &self,
        data: &'d StepData,
    ) -> Result<(&'d [f64], &'d [f64]), DynamicsError> {
        self.check_data(data)?;
        if data.step().is_none() {
            return Err(DynamicsError::Input {
                what: "step data",
                problem: "holds no step to linearise (compute one with Model::step first)".into(),
            });
        }
        Ok(data.point())
    }

    /// `Err` for data of another model, or an `x` or `u` of the wrong length or not finite.
    fn check_point(&self, data: &StepData, x: &[f64], u: &[f64]) -> Result<(), DynamicsError> {
        self.check_data(data)?;
        check("x", x, self.scene().n_state())?;
        check("u", u, self.scene().n_controls)
    }

    fn first_derivatives(&self, lin: &Linearised) -> StepDerivatives {
        let scene = self.scene();
        let (n, nu, h) = (scene.n_dof(), scene.n_controls, self.settings().h);
        let cols = 2 * n + nu;
        let dv = &lin.dp;
        let nx = 2 * n;
        let mut fx = vec![0.0; nx * nx];
        let mut fu = vec![0.0; nx * nu];
        let dc = &lin.dcorrection;
        for i in 0..n {
            for j in 0..nx {
                let d = dv[i * cols + j];
                fx[i * nx + j] = h * d + dc[i * cols + j] + if i == j { 1.0 } else { 0.0 };
                fx[(n + i) * nx + j] = d;
            }
            for k in 0..nu {
                let d = dv[i * cols + nx + k];
                fu[i * nu + k] = h * d + dc[i * cols + nx + k];
                fu[(n + i) * nu + k] = d;
            }
        }
        StepDerivatives { fx, fu }
    }

    /// The first derivatives of the step `data` holds and everything its second derivatives need except
    /// the vector they are contracted with (any scene): the step's linearisation, the factors of `K_p^T`,
    /// and the Hessians of the step's equations (for the logistic and hard models with a constant noise,
    /// what they are made of). Each [`SecondOrderStep::hessian`] is the rest. Linearises the stored step
    /// as [`Model::derivatives`] does; `Err` when `data` holds no step.
    #[tracing::instrument(name = "dynamics.second_order", level = "debug", skip_all)]
    pub fn second_order(&self, data: &StepData) -> Result<SecondOrderStep, DynamicsError> {
        let (x, u) = self.stored_point(data)?;
        self.second_order_from(x, u, Source::Stored(data))
    }

    /// One step from `x` under `u` in `data` (as [`Model::step`]) and its [`Model::second_order`], the
    /// geometry evaluated once for both.
    #[tracing::instrument(name = "dynamics.second_order_step", level = "debug", skip_all)]
    pub fn second_order_step(
        &self,
        data: &mut StepData,
        x: &[f64],
        u: &[f64],
    ) -> Result<SecondOrderStep, DynamicsError> {
        self.check_point(data, x, u)?;
        self.second_order_from(x, u, Source::Solve(data))
    }
}
