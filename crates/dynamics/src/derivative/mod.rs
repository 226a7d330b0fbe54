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

mod data;
mod expansion;
mod hessian;
mod linearise;
mod model;
mod residual;

pub(crate) use data::DerivativeData;
pub use model::SecondOrderStep;
pub use residual::{step_residual, step_residual_at};

/// `fx` (row-major `2n x 2n`, `fx[i][j] = dx'_i / dx_j`) and `fu` (row-major `2n x n_u`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StepDerivatives {
    /// `dx'/dx`, row-major.
    pub fx: Vec<f64>,
    /// `dx'/du`, row-major.
    pub fu: Vec<f64>,
}

/// The most memory one step's second-order expansion may take ([`Model::second_order_bytes`](crate::Model::second_order_bytes)): 1 GiB.
/// Its Taylor expansion of `M(q)` grows like the fourth power of the joints, so a scene of a few hundred
/// joints would ask for tens of gigabytes a knot; it is refused with the estimate instead.
pub const SECOND_ORDER_MAX_BYTES: usize = 1 << 30;
