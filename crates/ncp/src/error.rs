//! The one error type of the crate: an ill-posed question, never a solver that ran and fell short (that is a
//! [`Status`](crate::Status)).

/// Why a complementarity problem could not be posed or solved at all.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NcpError {
    /// A vector or matrix had the wrong size.
    #[error("{what} has {got} entries, expected {expected}")]
    Dimension {
        /// What was mis-sized (`"q"`, `"z0"`, `"functions"`, ...).
        what: &'static str,
        /// Its size.
        got: usize,
        /// The size the problem needs.
        expected: usize,
    },
    /// An input held NaN or an infinity (given so, or overflowed where a caller assembled it from finite
    /// but extreme values).
    #[error(
        "{what}[{index}] is {value:?}: the problem's data must be finite (given so, or overflowed while it was assembled from extreme values)"
    )]
    NonFinite {
        /// Which input (`"M"`, `"q"`, `"z0"`, `"F(z0)"`).
        what: &'static str,
        /// Flat index of the first offending entry (row-major for matrices).
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// A smoothing scale was not finite and positive.
    #[error(
        "smoothing sigma = {0}; it must be finite and positive (use a hard function for sigma = 0)"
    )]
    Sigma(f64),
    /// A setting was out of its range.
    #[error("setting `{name}` = {value:?} is out of range: {expected}")]
    Setting {
        /// The field name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The admissible range, in words.
        expected: &'static str,
    },
    /// The block of equality rows cannot be eliminated (it is singular), so the free variables are not
    /// determined by the complementarity variables.
    #[error("the {n_free}x{n_free} block of equality rows cannot be factored: {cause}")]
    SingularFreeBlock {
        /// Number of equality rows.
        n_free: usize,
        /// Why (the failing pivot).
        cause: crate::dense::FactorError,
    },
    /// Lemke's method ended on a secondary ray: the LCP has no solution (certain for copositive-plus M,
    /// which includes every positive semi-definite M).
    #[error("Lemke's method ended on a ray after {pivots} pivots: the LCP has no solution")]
    Infeasible {
        /// Pivots performed.
        pivots: usize,
    },
    /// A row proves the LCP infeasible on its own, before any pivot: `q_i < 0` and no positive entry in
    /// row `i` of `M`, so `w_i = q_i + (M z)_i < 0` for every `z >= 0`.
    #[error(
        "row {row} of the LCP has q = {q:?} < 0 and no positive entry in M: w_{row} < 0 for every z >= 0, so the LCP has no solution"
    )]
    InfeasibleRow {
        /// The row (of the complementarity rows, after the equality rows are eliminated).
        row: usize,
        /// Its `q`.
        q: f64,
    },
    /// Expected residual minimisation on an LCP without a solution: Lemke's method ended on a ray, and the
    /// smallest expected residual found is above what any solution of the LCP would give (each row's
    /// `sigma^2`), so the minimiser is no smoothed solution of anything.
    #[error(
        "the LCP has no solution: Lemke's method ended on a ray and the expected residual's minimum {objective:e} is above {bound:e}, the most any solution would leave"
    )]
    NoSolution {
        /// The expected residual at the minimiser found.
        objective: f64,
        /// `sum_i sigma_i^2`, an upper bound of the expected residual at any solution of the LCP.
        bound: f64,
    },
    /// A problem too large for a method's bounded work (its settings' `max_size`).
    #[error(
        "{method} is limited to {max} complementarity rows (its max_size setting) and this problem has {rows}: its work grows as rows^3 per pivot"
    )]
    TooLarge {
        /// Which method.
        method: &'static str,
        /// The problem's complementarity rows.
        rows: usize,
        /// The limit.
        max: usize,
    },
    /// The matrix and the vector of a problem do not fit together (the message says how).
    #[error("{0}")]
    Shape(String),
    /// A method that only handles one kind of problem was given another.
    #[error("{0}")]
    Unsupported(&'static str),
    /// A solve did not converge and the caller asked for an error in that case.
    #[error(
        "the solver stopped without converging: {status:?} after {iterations} iterations, residual {residual:e}"
    )]
    NotConverged {
        /// Why it stopped.
        status: crate::Status,
        /// Iterations run.
        iterations: usize,
        /// Final residual.
        residual: f64,
    },
}

/// `Err(NonFinite)` naming the first non-finite entry of `values`.
pub(crate) fn check_finite(what: &'static str, values: &[f64]) -> Result<(), NcpError> {
    // All finite in one branch-free pass (NaN and infinities fail `<= MAX`), the first that is not
    // looked for only then: the check runs on every solve's data.
    if values.iter().fold(true, |ok, v| ok & (v.abs() <= f64::MAX)) {
        return Ok(());
    }
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(index) => Err(NcpError::NonFinite {
            what,
            index,
            value: values[index],
        }),
    }
}

/// `Err(Dimension)` unless `got == expected`.
pub(crate) fn check_len(what: &'static str, got: usize, expected: usize) -> Result<(), NcpError> {
    if got == expected {
        Ok(())
    } else {
        Err(NcpError::Dimension {
            what,
            got,
            expected,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_finite_names_the_first_entry_that_is_not_finite() {
        assert!(check_finite("q", &[]).is_ok());
        assert!(check_finite("q", &[0.0, -f64::MAX, f64::MIN_POSITIVE]).is_ok());
        for (values, first) in [
            (vec![1.0, f64::INFINITY, f64::NAN], 1),
            (vec![f64::NAN, 2.0], 0),
            (vec![1.0, 2.0, 3.0, f64::NEG_INFINITY], 3),
        ] {
            match check_finite("q", &values) {
                Err(NcpError::NonFinite { what, index, value }) => {
                    assert_eq!((what, index), ("q", first));
                    assert_eq!(value.to_bits(), values[first].to_bits());
                }
                other => panic!("{other:?}"),
            }
        }
    }
}
