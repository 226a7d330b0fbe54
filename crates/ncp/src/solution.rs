//! What every solver returns: the solution, the constraint values at it, and how the solve went.

use crate::error::NcpError;
use serde::{Deserialize, Serialize};

/// Why a solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// The residual met the tolerance, or the Newton step fell to rounding level.
    Converged,
    /// The iteration (or pivot) limit was reached first.
    MaxIterations,
    /// No step length in the line search reduced the merit function enough.
    LineSearchFailed,
    /// The Newton matrix was singular to working precision.
    SingularJacobian,
    /// The method finished, but its answer misses the accuracy it promises (a numerical breakdown of an
    /// exact method); `residual` says by how much.
    Inaccurate,
    /// The problem returned a non-finite value at a trial point; the last finite iterate is kept.
    NonFinite,
    /// The solve finished, but its answer breaks a constraint of the problem it belongs to by more than
    /// that problem's tolerance (a time step's answer that leaves a joint past its limit or a body inside
    /// another, as rounding does at inputs of 1e20): not an answer to trust.
    Violated,
}

impl Status {
    /// Its serialised name (`converged`, `max_iterations`, ...): what the command line and the Python
    /// package print.
    pub fn name(self) -> &'static str {
        match self {
            Status::Converged => "converged",
            Status::MaxIterations => "max_iterations",
            Status::LineSearchFailed => "line_search_failed",
            Status::SingularJacobian => "singular_jacobian",
            Status::Inaccurate => "inaccurate",
            Status::NonFinite => "non_finite",
            Status::Violated => "violated",
        }
    }
}

/// How a solve went.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Info {
    /// Why it stopped.
    pub status: Status,
    /// Newton or Gauss–Newton iterations, or pivots for Lemke's method.
    pub iterations: usize,
    /// Final residual: the infinity norm of the NCP residual (Newton), of the projected gradient (ERM),
    /// or `max |min(z, w)|` over complementarity rows and `max |F|` over equality rows (Lemke).
    pub residual: f64,
    /// Residual and Jacobian evaluations of the problem.
    pub evaluations: usize,
}

/// A solution `z` of a (mixed) complementarity problem and `F(z)`: the equality residuals in the leading
/// rows, `w(z)` in the complementarity rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// The unknowns: free variables first, then the complementarity variables.
    pub z: Vec<f64>,
    /// `F(z)`: equality residuals (about zero) first, then `w(z)`.
    pub w: Vec<f64>,
    /// How the solve went.
    pub info: Info,
}

impl Solution {
    /// True when the solver converged.
    pub fn converged(&self) -> bool {
        self.info.status == Status::Converged
    }

    /// The solution if it converged, otherwise [`NcpError::NotConverged`].
    pub fn into_converged(self) -> Result<Self, NcpError> {
        if self.converged() {
            Ok(self)
        } else {
            Err(NcpError::NotConverged {
                status: self.info.status,
                iterations: self.info.iterations,
                residual: self.info.residual,
            })
        }
    }
}

#[cfg(test)]
mod name_tests {
    use super::Status;

    #[test]
    fn every_status_is_named_as_it_is_serialised() {
        for s in [
            Status::Converged,
            Status::MaxIterations,
            Status::LineSearchFailed,
            Status::SingularJacobian,
            Status::Inaccurate,
            Status::NonFinite,
            Status::Violated,
        ] {
            assert_eq!(serde_json::to_value(s).unwrap(), s.name());
        }
    }
}
