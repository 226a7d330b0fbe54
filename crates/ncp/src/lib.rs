//! Complementarity for the contact simulator: NCP functions, a Newton solver for mixed complementarity
//! problems, expected-residual minimisation, and exact LCP references.
//!
//! One time step of the simulator (paper section III-A, eq. 1-3; SCENE.md "One time step") is a mixed
//! linear complementarity problem: equations of motion in the velocities, and complementarity between each
//! impulse and its constraint velocity. This crate knows no bodies; it solves
//!
//! ```text
//! F(z) = [g(z); w(z)],   g(z) = 0,   0 <= lambda_i _|_ w_i(z) >= 0,   z = [x; lambda]
//! ```
//!
//! - [`NcpFunction`]: `min` (eq. 4) and Fischer–Burmeister (the hard functions), the logistic smoothing
//!   (eq. 17) and the normal smoothing (footnote 3); [`normal_expected_squared`] is eq. (15).
//! - [`NewtonSolver`]: damped (semismooth) Newton on `[g; phi(lambda, w)] = 0`, warm-started, per-row
//!   NCP functions (paper section IV-A; sigma per row is eq. 18).
//! - [`ErmSolver`]: the expected residual minimisation of eq. (14) with (15), equality rows held exactly.
//! - [`lemke`] and [`enumerate_solutions`]: exact answers for the hard problem.
//! - [`Solver`]: one call shape for [`Lemke`], [`NewtonSolver`] and [`ErmSolver`] (a problem, each row's
//!   data, a start).
//!
//! ```
//! use ncp::{LinearMcp, NcpFunction, NewtonSettings, NewtonSolver, lemke, LemkeSettings};
//! // 0 <= z _|_ M z + q >= 0 with a P-matrix M.
//! let p = LinearMcp::from_rows(0, &[vec![2.0, 1.0], vec![1.0, 2.0]], &[-1.0, 1.0])?;
//! let exact = lemke(&p, &LemkeSettings::default())?;
//! assert!((exact.z[0] - 0.5).abs() < 1e-15 && exact.z[1] == 0.0);
//! let mut newton = NewtonSolver::new(NewtonSettings::default())?;
//! let smooth = newton.solve(&p, &[NcpFunction::Logistic { sigma: 1e-3 }; 2], &[0.0, 0.0])?;
//! assert!(smooth.converged() && (smooth.z[0] - 0.5).abs() < 1e-3);
//! # Ok::<(), ncp::NcpError>(())
//! ```

// Dense kernels index several arrays with one counter, and `!(x > 0.0)` is how a test rejects NaN too.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

mod dense;
mod erm;
mod error;
mod function;
pub mod instances;
mod lemke;
mod newton;
mod problem;
mod rng;
mod solution;
mod solver;
pub mod special;

pub use dense::{DenseLu, FactorError, LinearSolver};
pub use erm::{ErmSettings, ErmSolver};
pub use error::NcpError;
pub use function::{
    NcpFunction, NcpJet, logistic_expected_squared, normal_expected_squared,
    normal_expected_squared_third,
};
pub use lemke::{
    LemkeSettings, LemkeWorkspace, complementarity_residual, enumerate_solutions, lemke,
    lemke_in_place,
};
pub use newton::{NewtonSettings, NewtonSolver};
pub use problem::{LinearMcp, Mcp, Reduced};
pub use solution::{Info, Solution, Status};
pub use solver::{Lemke, Solver};

/// The README's examples, compiled and run as doctests so that they cannot go stale.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
