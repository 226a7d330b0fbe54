//! The crate's one error type: `Err` means the question was ill-posed or the dynamics failed where no
//! fallback exists (the initial rollout); an optimisation that ran reports how it ended in
//! [`crate::Status`].

use thiserror::Error;

/// Errors of the optimiser.
#[derive(Debug, Error)]
pub enum DdpError {
    /// A setting out of its range.
    #[error("setting {name} = {value} is out of range: {expected}")]
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
    /// Second-order DDP asked of dynamics that provide no second derivatives.
    #[error(
        "full second-order DDP needs the dynamics' second derivatives; use Method::GaussNewton"
    )]
    NoSecondDerivatives,
}
