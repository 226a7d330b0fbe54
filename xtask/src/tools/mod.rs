//! The commands that put the crates on the command line: JSON-line streams (`distance`, `lcp`, `step`,
//! over `jsonl`), a rollout (`simulate`, in `step`), a solve (`optimize`), a library (`train`,
//! `evaluate`) and the viewer (`view`). The experiments are built on them; they import no experiment.

pub mod distance;
pub mod evaluate;
pub mod jsonl;
pub mod lcp;
pub mod optimize;
pub mod step;
pub mod train;
pub mod view;

/// A number in a message with `digits` after the point, or in exponent form when it is too large or too
/// small for that to read (a user's scene may hold `sigma = 1e-300` or a weight of `1e300`): never a
/// line of three hundred digits.
#[derive(Debug, Clone, Copy)]
pub struct Num(pub f64, pub usize);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Num(x, digits) = *self;
        let a = x.abs();
        if x.is_finite() && x != 0.0 && !(1e-4..1e9).contains(&a) {
            write!(f, "{x:.digits$e}")
        } else {
            write!(f, "{x:.digits$}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Num;

    #[test]
    fn numbers_in_messages_switch_to_exponents_at_the_extremes() {
        assert_eq!(Num(12.889634, 6).to_string(), "12.889634");
        assert_eq!(Num(0.05, 4).to_string(), "0.0500");
        assert_eq!(Num(0.0, 3).to_string(), "0.000");
        assert_eq!(Num(-2.5e300, 6).to_string(), "-2.500000e300");
        assert_eq!(Num(1e-300, 4).to_string(), "1.0000e-300");
        assert_eq!(Num(f64::INFINITY, 3).to_string(), "inf");
        assert_eq!(Num(f64::NAN, 3).to_string(), "NaN");
    }
}
