//! The crate's one error type: `Err` means the question was ill-posed or the dynamics failed where no
//! fallback exists (the initial rollout); an optimisation that ran reports how it ended in
//! [`crate::Status`].

use thiserror::Error;

/// Errors of the optimiser.
#[derive(Debug, Error)]
pub enum DdpError {
    /// A setting out of its range.
    #[error("setting {name} = {value:?} is out of range: {expected}")]
    Setting {
        /// The setting's name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// An input with the wrong size or a non-finite entry.
    #[error("{what}: {problem}")]
    Input {
        /// Which input.
        what: &'static str,
        /// What is wrong with it.
        problem: String,
    },
    /// The dynamics or the cost failed on the initial control sequence (there is nothing to fall back to).
    #[error("the initial rollout failed at step {step}: {reason}")]
    InitialRollout {
        /// The step at which it failed.
        step: usize,
        /// Why.
        reason: String,
    },
    /// The dynamics' derivatives failed along an accepted trajectory.
    #[error("the dynamics' derivatives failed at step {step}: {source}")]
    Derivatives {
        /// The step.
        step: usize,
        /// The dynamics' error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Full DDP would keep more second-order data than [`crate::FULL_DDP_MAX_BYTES`] allows: refused
    /// before anything is allocated.
    #[error(
        "full second-order DDP would keep about {:.1} GB of second derivatives ({knots} knots), over the limit of {:.1} GB (ddp::FULL_DDP_MAX_BYTES); use Method::GaussNewton (iLQR, --method ilqr), which needs first derivatives only",
        *bytes as f64 / 1e9,
        *limit as f64 / 1e9
    )]
    TooLarge {
        /// The estimate, in bytes.
        bytes: usize,
        /// The knots it is for.
        knots: usize,
        /// The limit, in bytes.
        limit: usize,
    },
    /// Second-order DDP asked of dynamics that provide no second derivatives.
    #[error(
        "full second-order DDP needs the dynamics' second derivatives; use Method::GaussNewton"
    )]
    NoSecondDerivatives,
}
