//! Second-order differential dynamic programming (DDP) and Gauss-Newton iLQR for finite-horizon optimal
//! control, generic over discrete dynamics and cost (paper section III-C.2, eq. 8-12): the optimiser of the
//! flicking finger, with no dependency on any scene.
//!
//! ```
//! use ddp::{Ddp, DdpSettings, Dynamics, Method, QuadraticCost};
//!
//! /// A double integrator, x = [position, velocity], u = [force], h = 0.1.
//! struct Integrator;
//! impl Dynamics for Integrator {
//!     type Error = std::convert::Infallible;
//!     type Data = ();
//!     fn state_dim(&self) -> usize { 2 }
//!     fn control_dim(&self) -> usize { 1 }
//!     fn create_data(&self) {}
//!     fn calc(&self, _: &mut (), _: Option<&()>, x: &[f64], u: &[f64], next: &mut [f64]) -> Result<(), Self::Error> {
//!         next[0] = x[0] + 0.1 * x[1];
//!         next[1] = x[1] + 0.1 * u[0];
//!         Ok(())
//!     }
//!     fn calc_diff(&self, _: &mut (), _x: &[f64], _u: &[f64], fx: &mut [f64], fu: &mut [f64]) -> Result<(), Self::Error> {
//!         fx.copy_from_slice(&[1.0, 0.1, 0.0, 1.0]);
//!         fu.copy_from_slice(&[0.0, 0.1]);
//!         Ok(())
//!     }
//! }
//!
//! let cost = QuadraticCost::diagonal(&[1.0, 0.1], &[0.01], &[100.0, 10.0]);
//! let settings = DdpSettings { method: Method::GaussNewton, ..DdpSettings::default() };
//! let solution = Ddp::new(settings)?.solve(&Integrator, &cost, &[1.0, 0.0], &vec![vec![0.0]; 50])?;
//! assert!(solution.status.converged());
//! assert!(solution.states[50][0].abs() < 0.05);
//! # Ok::<(), ddp::DdpError>(())
//! ```

#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

mod boxqp;
mod error;
mod linalg;
mod model;
pub mod problems;
mod settings;
mod solver;
mod work;

pub use error::DdpError;
pub use model::{Cost, CostDerivatives, Dynamics, QuadraticCost, SecondOrder};
pub use settings::{
    ControlLimits, DdpSettings, FULL_DDP_MAX_BYTES, MAX_THREADS, Method, Regularisation,
};
pub use solver::{
    Ddp, Iteration, RESOLUTION, Solution, Status, ValueModel, rollout, shift_controls,
};

/// `Err` unless `v` has `len` finite entries.
pub(crate) fn check(what: &'static str, v: &[f64], len: usize) -> Result<(), DdpError> {
    if v.len() != len {
        return Err(DdpError::Input {
            what,
            problem: format!("has {} entries, expected {len}", v.len()),
        });
    }
    if let Some(i) = v.iter().position(|e| !e.is_finite()) {
        return Err(DdpError::Input {
            what,
            problem: format!("entry {i} is {}", v[i]),
        });
    }
    Ok(())
}
