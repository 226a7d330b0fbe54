//! NCP functions: `phi(a, b) = 0` exactly when `a >= 0`, `b >= 0`, `a b = 0` (paper section III-B), their
//! smoothed stochastic versions (section IV-A), and the expected squared residual of eq. (15).
//!
//! Every function is written as `min(a, b)` minus a non-negative correction, so that the value keeps full
//! relative accuracy where it is small (the root, which is where a solver looks) and never overflows:
//!
//! - logistic (eq. 17): `a - s ln(1 + exp((a - b)/s)) = min(a, b) - s softplus(-|a - b| / s)`,
//! - normal mean (footnote 3): `a - s^2 p(a) - (a - b) P(a) = min(a, b) - s I1(|a - b| / s)`,
//!
//! with `I1(x) = E[(Z - x)^+]` (see `special.rs`). The two smoothed functions are the expectation of
//! `min(a, b + noise)` for logistic and normal noise of scale `s` on `b`.

use crate::error::NcpError;
use crate::special::{
    Tails, logistic_k2, normal_pdf, scaled_difference, sigmoid, sigmoid_slope, softplus,
    upper_tails_at,
};
use serde::{Deserialize, Serialize};

/// Which NCP function a complementarity row uses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum NcpFunction {
    /// `min(a, b)`, paper eq. (4): the hard complementarity, semismooth.
    Min,
    /// Fischer–Burmeister `a + b - sqrt(a^2 + b^2)`: hard, semismooth, and its square is smooth.
    FischerBurmeister,
    /// Logistic smoothing, paper eq. (17): `E[min(a, b_L)]` for `b_L` logistic with mean `b` and scale `sigma`.
    Logistic {
        /// Noise scale `sigma > 0` (the paper's default is 0.1).
        sigma: f64,
    },
    /// Normal smoothing, paper footnote 3: `E[min(a, b_N)]` for `b_N ~ N(b, sigma^2)`.
    Normal {
        /// Noise standard deviation `sigma > 0`.
        sigma: f64,
    },
}

/// Value and first and second partial derivatives of a function of `(a, b)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NcpJet {
    /// `phi(a, b)`.
    pub value: f64,
    /// `d phi / d a`.
    pub da: f64,
    /// `d phi / d b`.
    pub db: f64,
    /// `d^2 phi / d a^2`.
    pub daa: f64,
    /// `d^2 phi / d a d b`.
    pub dab: f64,
    /// `d^2 phi / d b^2`.
    pub dbb: f64,
}

impl NcpFunction {
    /// Logistic smoothing with noise scale `sigma`, checked.
    pub fn logistic(sigma: f64) -> Result<Self, NcpError> {
        let f = NcpFunction::Logistic { sigma };
        f.validate()?;
        Ok(f)
    }

    /// Normal smoothing with standard deviation `sigma`, checked.
    pub fn normal(sigma: f64) -> Result<Self, NcpError> {
        let f = NcpFunction::Normal { sigma };
        f.validate()?;
        Ok(f)
    }

    /// `Err` unless a smoothing `sigma` is finite and positive.
    pub fn validate(&self) -> Result<(), NcpError> {
        match *self {
            NcpFunction::Logistic { sigma } | NcpFunction::Normal { sigma } => {
                if sigma.is_finite() && sigma > 0.0 {
                    Ok(())
                } else {
                    Err(NcpError::Sigma(sigma))
                }
            }
            _ => Ok(()),
        }
    }

    /// The smoothing scale, zero for the hard functions.
    pub fn sigma(&self) -> f64 {
        match *self {
            NcpFunction::Logistic { sigma } | NcpFunction::Normal { sigma } => sigma,
            _ => 0.0,
        }
    }

    /// The same function with its smoothing raised to at least `floor` (hard functions are unchanged).
    pub fn with_sigma_at_least(&self, floor: f64) -> Self {
        match *self {
            NcpFunction::Logistic { sigma } => NcpFunction::Logistic {
                sigma: sigma.max(floor),
            },
            NcpFunction::Normal { sigma } => NcpFunction::Normal {
                sigma: sigma.max(floor),
            },
            other => other,
        }
    }

    /// True for the functions whose roots are exactly the complementarity conditions.
    pub fn is_hard(&self) -> bool {
        matches!(self, NcpFunction::Min | NcpFunction::FischerBurmeister)
    }

    /// The value `phi(a, b)` alone.
    pub fn value(&self, a: f64, b: f64) -> f64 {
        match *self {
            NcpFunction::Min => a.min(b),
            NcpFunction::FischerBurmeister => fischer_burmeister(a, b),
            NcpFunction::Logistic { sigma } => {
                let (c, c_lo) = scaled_difference(a, b, sigma);
                a.min(b) - sigma * softplus_at(-c.abs(), -signed(c_lo, c))
            }
            NcpFunction::Normal { sigma } => a.min(b) - sigma * tails(a, b, sigma).0.i1,
        }
    }

    /// Value and first derivatives `(phi, d phi/d a, d phi/d b)`, sharing one exponential (logistic) or one
    /// evaluation of the normal tails: the Newton solver's inner loop. Equal to the corresponding fields of
    /// [`jet`](Self::jet).
    pub fn first_order(&self, a: f64, b: f64) -> (f64, f64, f64) {
        match *self {
            NcpFunction::Logistic { sigma } => {
                let (c, c_lo) = scaled_difference(a, b, sigma);
                let e = (-c.abs()).exp();
                let inv = 1.0 / (1.0 + e);
                // sigmoid(|c|) = inv, sigmoid(-|c|) = e inv; corrections of first order in c_lo.
                let slope = e * inv * inv;
                let y_lo = -signed(c_lo, c);
                let value = a.min(b) - sigma * (e.ln_1p() + e * inv * y_lo);
                let (hi, lo) = (inv, e * inv);
                let (db, da) = if c >= 0.0 { (hi, lo) } else { (lo, hi) };
                (value, da - slope * c_lo, db + slope * c_lo)
            }
            NcpFunction::Normal { sigma } => {
                let (t, below, above) = tails(a, b, sigma);
                (a.min(b) - sigma * t.i1, above, below)
            }
            _ => {
                let j = self.jet(a, b);
                (j.value, j.da, j.db)
            }
        }
    }

    /// Value and first and second derivatives. At the kinks of the hard functions the first derivative is
    /// one element of the generalised (Clarke) Jacobian: `min` takes `(1, 0)` when `a <= b`, and
    /// Fischer–Burmeister takes `(1 - 1/sqrt 2, 1 - 1/sqrt 2)` at the origin; their second derivatives are
    /// zero at the kinks.
    pub fn jet(&self, a: f64, b: f64) -> NcpJet {
        match *self {
            NcpFunction::Min => {
                if a <= b {
                    NcpJet {
                        value: a,
                        da: 1.0,
                        ..NcpJet::default()
                    }
                } else {
                    NcpJet {
                        value: b,
                        db: 1.0,
                        ..NcpJet::default()
                    }
                }
            }
            NcpFunction::FischerBurmeister => fischer_burmeister_jet(a, b),
            NcpFunction::Logistic { sigma } => {
                let (c, c_lo) = scaled_difference(a, b, sigma);
                let value = a.min(b) - sigma * softplus_at(-c.abs(), -signed(c_lo, c));
                let curvature = sigmoid_slope(c) / sigma;
                // sigmoid(c + c_lo) to first order in c_lo.
                let slope = sigmoid_slope(c) * c_lo;
                NcpJet {
                    value,
                    da: sigmoid(-c) - slope,
                    db: sigmoid(c) + slope,
                    daa: -curvature,
                    dab: curvature,
                    dbb: -curvature,
                }
            }
            NcpFunction::Normal { sigma } => {
                let (t, below, above) = tails(a, b, sigma);
                // d/db = P(b_N < a), the weight of the branch where the noisy b is the minimum.
                let (da, db) = (above, below);
                let curvature = t.pdf / sigma;
                NcpJet {
                    value: a.min(b) - sigma * t.i1,
                    da,
                    db,
                    daa: -curvature,
                    dab: curvature,
                    dbb: -curvature,
                }
            }
        }
    }
}

/// `g(t) = ln(1 + t) - t / (1 + t)` for `0 <= t <= 1`, by its series `sum_k (-1)^k (k - 1) / k t^k` below
/// `t = 1/2` (where the two terms cancel) and directly above.
fn log1p_minus_ratio(t: f64) -> f64 {
    if t > 0.5 {
        return t.ln_1p() - t / (1.0 + t);
    }
    let (mut power, mut sum) = (t * t, 0.0);
    for k in 2..=80 {
        let term = power * (k - 1) as f64 / k as f64;
        sum += if k % 2 == 0 { term } else { -term };
        if term <= 1e-17 * sum.abs() {
            break;
        }
        power *= t;
    }
    sum
}

/// `lo` times the sign of `hi`: the correction to `|hi + lo|` beyond `|hi|`.
fn signed(lo: f64, hi: f64) -> f64 {
    if hi < 0.0 { -lo } else { lo }
}

/// `softplus(y + y_lo)` to first order in the rounding-level correction `y_lo`.
fn softplus_at(y: f64, y_lo: f64) -> f64 {
    softplus(y) + sigmoid(y) * y_lo
}

/// The normal tails at `|a - b| / sigma` (compensated), and `P(b_N < a)`, `P(b_N > a)` for
/// `b_N ~ N(b, sigma^2)`, each from a tail so that neither is formed as `1 - p`.
fn tails(a: f64, b: f64, sigma: f64) -> (Tails, f64, f64) {
    let (alpha, alpha_lo) = scaled_difference(a, b, sigma);
    let t = upper_tails_at(alpha.abs(), signed(alpha_lo, alpha));
    if alpha > 0.0 {
        (t, 1.0 - t.i0, t.i0)
    } else {
        (t, t.i0, 1.0 - t.i0)
    }
}

fn fischer_burmeister(a: f64, b: f64) -> f64 {
    let r = a.hypot(b);
    let s = a + b;
    if s > 0.0 {
        2.0 * a * b / (s + r)
    } else {
        s - r
    }
}

fn fischer_burmeister_jet(a: f64, b: f64) -> NcpJet {
    let r = a.hypot(b);
    if r == 0.0 {
        let g = 1.0 - std::f64::consts::FRAC_1_SQRT_2;
        return NcpJet {
            value: 0.0,
            da: g,
            db: g,
            ..NcpJet::default()
        };
    }
    // 1 - a/r = (r - a)/r, with r - a = b^2 / (r + a) when a > 0 (no cancellation).
    let r_minus = |x: f64, y: f64| if x > 0.0 { y * y / (r + x) } else { r - x };
    NcpJet {
        value: fischer_burmeister(a, b),
        da: r_minus(a, b) / r,
        db: r_minus(b, a) / r,
        daa: -(b / r) * (b / r) / r,
        dab: (a / r) * (b / r) / r,
        dbb: -(a / r) * (a / r) / r,
    }
}

/// The expected squared residual of the normal model, paper eq. (15): `E[min(a, b_N)^2]` for
/// `b_N ~ N(b, sigma^2)`, with its first and second derivatives. `sigma` must be positive and finite.
///
/// The paper's form `a^2 - sigma^2 (a + b) p(a) + (sigma^2 + b^2 - a^2) P(a)` is correct (checked against
/// quadrature in the tests) but cancels badly on both sides; with `alpha = (a - b) / sigma` this uses
///
/// - `alpha <= 0`: `a^2 - 2 a sigma I1(-alpha) + sigma^2 I2(-alpha)`,
/// - `alpha > 0`: `b^2 + sigma^2 - 2 a sigma I1(alpha) - sigma^2 I2(alpha)`,
///
/// (from `min(a, b_N) = a - (a - b_N)^+` and `= b_N - (b_N - a)^+`), whose small terms are tail integrals.
pub fn normal_expected_squared(a: f64, b: f64, sigma: f64) -> NcpJet {
    let alpha = (a - b) / sigma;
    let (t, cdf, upper) = tails(a, b, sigma);
    let s2 = sigma * sigma;
    let value = if alpha <= 0.0 {
        a * a - 2.0 * a * sigma * t.i1 + s2 * t.i2
    } else {
        b * b + s2 - 2.0 * a * sigma * t.i1 - s2 * t.i2
    };
    // cdf = P(b_N < a) = Phi(alpha), upper = 1 - cdf, each computed without cancellation.
    // d/da = 2 a P(b_N > a); d/db = 2 E[b_N 1{b_N < a}] = 2 (a Phi(alpha) - sigma G(alpha)), with
    // G(alpha) = E[(alpha - Z)^+] = I1(-alpha) for alpha <= 0 and alpha + I1(alpha) otherwise, so that
    // a Phi - sigma G = b Phi(alpha) - sigma pdf(alpha) on the right.
    let db = if alpha <= 0.0 {
        2.0 * (a * t.i0 - sigma * t.i1)
    } else {
        2.0 * (b * cdf - sigma * t.pdf)
    };
    expected_square_jet(value, db, a, upper, cdf, t.pdf / sigma)
}

/// The third partial derivatives `(d^3/da^3, d^3/da^2 db, d^3/da db^2, d^3/db^3)` of
/// [`normal_expected_squared`], which the second derivatives of the normal model's step need (its
/// stationarity conditions hold first derivatives of eq. 15). With `t = (a - b) / sigma` and
/// `p = pdf(t) / sigma`, from `e_aa = 2 P(b_N > a) - 2 a p`, `e_ab = 2 a p`, `e_bb = 2 P(b_N < a) - 2 a p` and
/// `dp/da = -t p / sigma = -dp/db`:
/// `(-4 p + k, 2 p - k, k, -2 p - k)` with `k = 2 a t p / sigma`. `sigma` must be positive and finite.
pub fn normal_expected_squared_third(a: f64, b: f64, sigma: f64) -> [f64; 4] {
    let t = (a - b) / sigma;
    let p = normal_pdf(t) / sigma;
    let k = 2.0 * a * t * p / sigma;
    [-4.0 * p + k, 2.0 * p - k, k, -2.0 * p - k]
}

/// The expected squared residual under logistic noise, the second formula of the paper's footnote 3 with
/// its sign corrected: `E[min(a, b_L)^2] = a^2 - 2 a s ln(1 + e^c) - 2 s^2 Li2(-e^c)`, `c = (a - b) / s`,
/// for `b_L` logistic of mean `b` and scale `s` (the footnote prints `+ 2 s^2 Li2`, which is negative at
/// `a = 0.3, b = 0.1, s = 0.2`; docs/complementarity.md). With `K2(x) = -2 Li2(-e^x)` it is evaluated as
///
/// - `c <= 0`: `a^2 - 2 a s softplus(c) + s^2 K2(c)`,
/// - `c > 0`: `b^2 + s^2 pi^2 / 3 - 2 a s softplus(-c) - s^2 K2(-c)`,
///
/// whose small terms are tail integrals, as for [`normal_expected_squared`].
pub fn logistic_expected_squared(a: f64, b: f64, sigma: f64) -> NcpJet {
    let (c, c_lo) = scaled_difference(a, b, sigma);
    let x = -c.abs();
    let x_lo = -signed(c_lo, c);
    let e = x.exp();
    let inv = 1.0 / (1.0 + e);
    // softplus(x) and K2(x) at x + x_lo, to first order: softplus' = sigmoid, K2' = 2 softplus.
    let softplus = e.ln_1p() + e * inv * x_lo;
    let k2 = logistic_k2(x) + 2.0 * e.ln_1p() * x_lo;
    let s2 = sigma * sigma;
    // P(b_L > a) = sigmoid(-c), P(b_L < a) = sigmoid(c): e inv is the smaller, inv the larger; both
    // corrected to first order in c_lo.
    let shift = e * inv * inv * c_lo;
    let (upper, lower) = if c > 0.0 {
        (e * inv, inv)
    } else {
        (inv, e * inv)
    };
    let (upper, lower) = (upper - shift, lower + shift);
    let value = if c <= 0.0 {
        a * a - 2.0 * a * sigma * softplus + s2 * k2
    } else {
        let var = std::f64::consts::PI * std::f64::consts::PI / 3.0;
        b * b + s2 * var - 2.0 * a * sigma * softplus - s2 * k2
    };
    // d/db = 2 E[b_L 1{b_L < a}] = 2 (a sigmoid(c) - s softplus(c)) = 2 (b - a sigmoid(-c) - s softplus(-c)).
    // For c <= 0 both terms are about a e^c: written as 2 (sigmoid(c) (a - s) - s g(e^c)) with
    // g(t) = ln(1 + t) - t / (1 + t) = t^2/2 - 2t^3/3 + ..., whose leading terms no longer cancel.
    let db = if c <= 0.0 {
        2.0 * (lower * (a - sigma) - sigma * log1p_minus_ratio(e))
    } else {
        2.0 * (b - a * upper - sigma * softplus)
    };
    expected_square_jet(value, db, a, upper, lower, e * inv * inv / sigma)
}

/// The jet of `E[min(a, b + noise)^2]` from its value, `d/db`, the probabilities `P(b + noise > a)`
/// (`upper`) and `P(b + noise < a)` (`lower`), and the noise density at `a` (`density`): `d/da = 2 a upper`,
/// `d2/da2 = 2 upper - 2 a density`, `d2/da db = 2 a density`, `d2/db2 = 2 lower - 2 a density`.
fn expected_square_jet(
    value: f64,
    db: f64,
    a: f64,
    upper: f64,
    lower: f64,
    density: f64,
) -> NcpJet {
    let k = 2.0 * a * density;
    NcpJet {
        value,
        da: 2.0 * a * upper,
        db,
        daa: 2.0 * upper - k,
        dab: k,
        dbb: 2.0 * lower - k,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn third_partials_of_eq_15_match_differences_of_its_second_partials() {
        for &(a, b, s) in &[
            (0.3, 0.1, 0.2),
            (-0.5, 0.4, 0.1),
            (1.0, 1.0, 1.0),
            (0.0, -2.0, 0.7),
            (2.0, 0.5, 3.0),
        ] {
            let [aaa, aab, abb, bbb] = normal_expected_squared_third(a, b, s);
            let e = 1e-5;
            let da = |f: fn(&NcpJet) -> f64| {
                (f(&normal_expected_squared(a + e, b, s))
                    - f(&normal_expected_squared(a - e, b, s)))
                    / (2.0 * e)
            };
            let db = |f: fn(&NcpJet) -> f64| {
                (f(&normal_expected_squared(a, b + e, s))
                    - f(&normal_expected_squared(a, b - e, s)))
                    / (2.0 * e)
            };
            let close = |x: f64, y: f64| (x - y).abs() <= 1e-7 * (1.0 + y.abs());
            assert!(close(aaa, da(|j| j.daa)), "aaa at {a} {b} {s}");
            assert!(close(aab, db(|j| j.daa)), "aab at {a} {b} {s}");
            assert!(close(aab, da(|j| j.dab)), "aab' at {a} {b} {s}");
            assert!(close(abb, db(|j| j.dab)), "abb at {a} {b} {s}");
            assert!(close(abb, da(|j| j.dbb)), "abb' at {a} {b} {s}");
            assert!(close(bbb, db(|j| j.dbb)), "bbb at {a} {b} {s}");
        }
    }

    #[test]
    fn hard_functions_vanish_exactly_on_complementary_pairs() {
        for f in [NcpFunction::Min, NcpFunction::FischerBurmeister] {
            for &(a, b) in &[
                (0.0, 0.0),
                (0.0, 3.0),
                (2.5, 0.0),
                (0.0, 1e8),
                (1e-300, 0.0),
            ] {
                assert_eq!(f.value(a, b), 0.0, "{f:?} at ({a}, {b})");
            }
            for &(a, b) in &[(1.0, 1.0), (-1.0, 2.0), (2.0, -1e-9), (-1.0, -1.0)] {
                assert!(f.value(a, b) != 0.0, "{f:?} at ({a}, {b})");
            }
        }
    }

    #[test]
    fn smoothed_functions_tend_to_min_as_sigma_shrinks() {
        for &(a, b) in &[(0.3f64, 1.2f64), (2.0, -1.0), (0.5, 0.5), (-1.0, 4.0)] {
            let hard = a.min(b);
            let mut previous = f64::INFINITY;
            for k in 0..12 {
                let s = 10f64.powi(-k);
                for f in [
                    NcpFunction::Logistic { sigma: s },
                    NcpFunction::Normal { sigma: s },
                ] {
                    let gap = hard - f.value(a, b);
                    assert!(gap >= 0.0, "smoothing lowers the min: {f:?} ({a}, {b})");
                    assert!(gap <= s, "{f:?} ({a}, {b}) gap {gap}");
                }
                let gap = hard - NcpFunction::Logistic { sigma: s }.value(a, b);
                assert!(gap <= previous);
                previous = gap;
            }
        }
    }

    #[test]
    fn fischer_burmeister_keeps_relative_accuracy_near_its_zero_set() {
        // a + b - sqrt(a^2 + b^2) for a = 1, b = 1e-12 is 1e-12 - 5e-25 to full precision.
        let v = NcpFunction::FischerBurmeister.value(1.0, 1e-12);
        assert!((v - (1e-12 - 5e-25)).abs() <= 1e-27);
        let j = NcpFunction::FischerBurmeister.jet(1.0, -1e-12);
        assert!((j.da - 0.5e-24).abs() < 1e-38 && (j.db - 1.0 - 1e-12).abs() < 1e-15);
    }

    #[test]
    fn first_order_agrees_with_the_jet() {
        let functions = [
            NcpFunction::Min,
            NcpFunction::FischerBurmeister,
            NcpFunction::Logistic { sigma: 0.1 },
            NcpFunction::Logistic { sigma: 1e-9 },
            NcpFunction::Normal { sigma: 0.3 },
        ];
        for f in functions {
            for &(a, b) in &[
                (0.3, 1.2),
                (2.0, -1.0),
                (0.5, 0.5),
                (-1.0, 4.0),
                (1e-3, 2e-3),
                (7.0, 7.05),
            ] {
                let (v, da, db) = f.first_order(a, b);
                let j = f.jet(a, b);
                let close =
                    |x: f64, y: f64| (x - y).abs() <= 2.0 * f64::EPSILON * x.abs().max(y.abs());
                assert!(
                    close(v, j.value) && close(da, j.da) && close(db, j.db),
                    "{f:?} ({a}, {b})"
                );
            }
        }
    }

    #[test]
    fn expected_squared_residual_dominates_the_squared_mean() {
        // Jensen: E[min^2] >= E[min]^2 (eq. 16 versus eq. 14).
        for &(a, b, s) in &[
            (0.3, 0.1, 0.2),
            (1.0, 1.0, 0.5),
            (-2.0, 3.0, 1.0),
            (5.0, -5.0, 0.01),
        ] {
            let mean = NcpFunction::Normal { sigma: s }.value(a, b);
            let sq = normal_expected_squared(a, b, s).value;
            assert!(sq >= mean * mean * (1.0 - 1e-14), "({a}, {b}, {s})");
        }
    }
}
