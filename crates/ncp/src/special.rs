//! Special functions behind the smoothed NCP functions: the softplus and logistic sigmoid (eq. 17) and the
//! partial expectations of a standard normal variable (eq. 15 and footnote 3), in forms free of overflow,
//! underflow and cancellation.
//!
//! For the normal model everything reduces to three upper-tail integrals of the standard normal density
//! `pdf(t) = exp(-t^2 / 2) / sqrt(2 pi)`, for `x >= 0`:
//!
//! - `I0(x) = P(Z > x)`,
//! - `I1(x) = E[(Z - x)^+] = pdf(x) - x I0(x)`,
//! - `I2(x) = E[((Z - x)^+)^2] = (1 + x^2) I0(x) - x pdf(x)`.
//!
//! The closed forms on the right cancel badly once `x` exceeds about 2. They are the first members of the
//! family `J_n(x) = int_x^inf (t - x)^n / n! pdf(t) dt`, which obeys `n J_n = J_(n-2) - x J_(n-1)` with
//! `J_(-1) = pdf`. That recurrence is unstable upward and stable downward, so for `x >= 2` the tails come from
//! Miller's backward recurrence (the continued fraction of the Mills ratio) normalised by `pdf(x)`, which has
//! no subtraction at all. Below 2 the closed forms lose at most a factor of about 6 (`I1`) and 20 (`I2`)
//! to cancellation. The arguments `(a - b) / sigma` are carried with their rounding error
//! ([`scaled_difference`]) and the tails corrected to first order ([`upper_tails_at`]). The test against
//! 80-digit values (tests/it/ncp_functions.rs) measures at most 4.2 ulps over all functions.

/// `1 / sqrt(2)` rounded to double, and the rounding error: `FRAC_1_SQRT_2 + FRAC_1_SQRT_2_LO` is exact to
/// about 1e-33.
const FRAC_1_SQRT_2_LO: f64 = -4.833_646_656_726_457e-17;
/// `1 / sqrt(2 pi)`.
const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;
/// Below this, the tails use the closed forms; above it, the backward recurrence (at most 176 steps).
const RECURRENCE_FROM: f64 = 2.0;
/// Beyond this the density underflows to zero (exp(-745) is the smallest subnormal).
const TAIL_ZERO_FROM: f64 = 38.6;

/// `ln(1 + exp(x))` without overflow for large `x` or loss of relative accuracy for very negative `x`.
pub fn softplus(x: f64) -> f64 {
    if x > 0.0 {
        x + (-x).exp().ln_1p()
    } else {
        x.exp().ln_1p()
    }
}

/// The logistic sigmoid `1 / (1 + exp(-x))`, the derivative of [`softplus`].
pub fn sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

/// `sigmoid(x) * sigmoid(-x)`, the derivative of the sigmoid, without cancellation or overflow.
pub fn sigmoid_slope(x: f64) -> f64 {
    let e = (-x.abs()).exp();
    let d = 1.0 + e;
    e / (d * d)
}

/// `(a - b) / s` as an unevaluated sum `hi + lo`, correct to about `2^-104` relative: the smoothed
/// functions are evaluated at arguments like `(a - b) / s = -700`, where the rounding of a plain division
/// (half an ulp of 700) would cost hundreds of ulps of `exp(-700)`.
pub fn scaled_difference(a: f64, b: f64, s: f64) -> (f64, f64) {
    // Knuth's TwoSum: d + err = a - b exactly.
    let d = a - b;
    let v = d - a;
    let err = (a - (d - v)) + (-b - v);
    let hi = d / s;
    // d - hi s exactly, by a fused multiply-add.
    let r = (-hi).mul_add(s, d);
    let lo = (r + err) / s;
    if lo.is_finite() { (hi, lo) } else { (hi, 0.0) }
}

/// The standard normal density `exp(-x^2 / 2) / sqrt(2 pi)`, with the rounding error of `x^2` corrected
/// (a plain evaluation loses `x^2 / 2` ulps, 450 of them at `x = 30`).
pub fn normal_pdf(x: f64) -> f64 {
    let x = x.abs();
    if x >= TAIL_ZERO_FROM {
        return 0.0;
    }
    let hi = x * x;
    let lo = x.mul_add(x, -hi);
    FRAC_1_SQRT_2PI * (-0.5 * hi).exp() * (1.0 - 0.5 * lo)
}

/// The standard normal distribution function `P(Z <= x)`.
pub fn normal_cdf(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 - upper_tails(x).i0
    } else {
        upper_tails(-x).i0
    }
}

/// Upper-tail integrals of the standard normal at `x >= 0`; see the module documentation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tails {
    /// The density at `x`.
    pub pdf: f64,
    /// `I0(x) = P(Z > x)`.
    pub i0: f64,
    /// `I1(x) = E[(Z - x)^+]`.
    pub i1: f64,
    /// `I2(x) = E[((Z - x)^+)^2]`.
    pub i2: f64,
}

/// The tails of [`Tails`] at `x`; `x` must be non-negative (NaN propagates).
pub fn upper_tails(x: f64) -> Tails {
    debug_assert!(!(x < 0.0), "upper_tails takes x >= 0, got {x}");
    let pdf = normal_pdf(x);
    if x < RECURRENCE_FROM {
        let i0 = 0.5 * erfc_of_x_over_sqrt2(x);
        let i1 = pdf - x * i0;
        let i2 = i0 - x * i1;
        return Tails { pdf, i0, i1, i2 };
    }
    if x >= TAIL_ZERO_FROM {
        return Tails {
            pdf: 0.0,
            i0: 0.0,
            i1: 0.0,
            i2: 0.0,
        };
    }
    // Miller's algorithm: run p_(n-2) = n p_n + x p_(n-1) down from p_(N+1) = 0, p_N = 1; then
    // J_n = pdf * p_n / p_(-1). The depth keeps the truncation below 1e-17 relative (checked in the tests);
    // the values grow at most like sqrt(N!) x^N, far from overflow for x < 38.6 and N <= 80.
    let depth = 16 + (640.0 / (x * x)) as usize;
    let mut next = 0.0; // p_(n+1)
    let mut current = 1.0; // p_n
    let (mut p2, mut p1, mut p0) = (0.0, 0.0, 0.0);
    let mut n = depth;
    while n >= 1 {
        // p_(n-1) = (n + 1) p_(n+1) + x p_n
        let previous = ((n + 1) as f64).mul_add(next, x * current);
        next = current;
        current = previous;
        n -= 1;
        match n {
            2 => p2 = current,
            1 => p1 = current,
            0 => p0 = current,
            _ => {}
        }
    }
    // current = p_0 here; one more step gives p_(-1) = 1 * p_1 + x p_0.
    let p_minus1 = next.mul_add(1.0, x * current);
    let scale = pdf / p_minus1;
    Tails {
        pdf,
        i0: scale * p0,
        i1: scale * p1,
        i2: 2.0 * scale * p2,
    }
}

/// The tails at `x + x_lo`, `x >= 0`, for a correction `|x_lo|` at rounding level: first-order Taylor
/// terms from `d pdf/dx = -x pdf`, `d I0/dx = -pdf`, `d I1/dx = -I0`, `d I2/dx = -2 I1`.
pub fn upper_tails_at(x: f64, x_lo: f64) -> Tails {
    let t = upper_tails(x);
    if x_lo == 0.0 {
        return t;
    }
    Tails {
        pdf: t.pdf * (1.0 - x * x_lo),
        i0: t.i0 - t.pdf * x_lo,
        i1: t.i1 - t.i0 * x_lo,
        i2: t.i2 - 2.0 * t.i1 * x_lo,
    }
}

/// `B_n / (n + 1)!` for even `n` from 2 to 20 (Bernoulli numbers), the coefficients of
/// `Li2(z) = u - u^2 / 4 + sum_n B_n u^(n+1) / (n+1)!` with `u = -ln(1 - z)`.
const DILOG_BERNOULLI: [f64; 10] = [
    0.027777777777777776,
    -0.0002777777777777778,
    4.72411186696901e-06,
    -9.185773074661964e-08,
    1.8978869988971e-09,
    -4.0647616451442256e-11,
    8.921691020456452e-13,
    -1.9939295860721074e-14,
    4.518980029619918e-16,
    -1.0356517612181247e-17,
];

/// The dilogarithm `Li2(-t) = -int_0^t ln(1 + s) / s ds` for `0 <= t <= 1`: its power series below
/// `t = 1/2`, the Bernoulli series in `u = -ln(1 + t)` (`|u| <= ln 2`) above.
pub fn dilog_of_negative(t: f64) -> f64 {
    debug_assert!(
        (0.0..=1.0).contains(&t),
        "dilog_of_negative takes 0 <= t <= 1, got {t}"
    );
    if t <= 0.5 {
        let (mut power, mut sum) = (-t, 0.0);
        for k in 1..=60 {
            let term = power / (k * k) as f64;
            sum += term;
            if term.abs() <= 1e-17 * sum.abs() {
                break;
            }
            power *= -t;
        }
        sum
    } else {
        let u = -t.ln_1p();
        let u2 = u * u;
        // u - u^2/4 + sum c_n u^(n+1), n = 2, 4, ..., 20, by Horner in u^2.
        let tail = DILOG_BERNOULLI
            .iter()
            .rev()
            .fold(0.0, |acc, c| acc * u2 + c);
        u - 0.25 * u2 + tail * u2 * u
    }
}

/// `K2(x) = E[((x - Y)^+)^2]` for a standard logistic `Y` (density `e^-y / (1 + e^-y)^2`) and `x <= 0`:
/// `-2 Li2(-e^x)`, no cancellation.
pub fn logistic_k2(x: f64) -> f64 {
    debug_assert!(!(x > 0.0), "logistic_k2 takes x <= 0, got {x}");
    -2.0 * dilog_of_negative(x.exp())
}

/// `erfc(x / sqrt(2))` with the rounding of `x / sqrt(2)` corrected to first order (it would otherwise
/// cost `x^2` ulps).
fn erfc_of_x_over_sqrt2(x: f64) -> f64 {
    let z = x * std::f64::consts::FRAC_1_SQRT_2;
    let dz = x.mul_add(std::f64::consts::FRAC_1_SQRT_2, -z) + x * FRAC_1_SQRT_2_LO;
    let slope = std::f64::consts::FRAC_2_SQRT_PI * (-z * z).exp();
    libm::erfc(z) - slope * dz
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn softplus_matches_the_naive_form_where_that_is_exact() {
        for &x in &[0.0, 0.5, 3.0, 30.0] {
            let naive = (1.0f64 + f64::exp(x)).ln();
            assert!((softplus(x) - naive).abs() <= 8.0 * f64::EPSILON * naive.abs());
        }
        // Far left, ln(1 + e^x) = e^x - e^(2x)/2 + ...: the naive form would return 0 or lose all digits.
        for &x in &[-30.0f64, -100.0, -700.0] {
            let series = x.exp() * (1.0 - 0.5 * x.exp());
            assert!((softplus(x) - series).abs() <= 2.0 * f64::EPSILON * series);
        }
        assert_eq!(softplus(1e8), 1e8);
        assert!(softplus(-800.0) == 0.0 && softplus(-700.0) > 0.0);
    }

    #[test]
    fn sigmoid_is_the_derivative_of_softplus_and_sums_to_one() {
        for &x in &[-40.0, -2.0, -1e-3, 0.0, 0.7, 5.0, 40.0] {
            let h = 1e-6;
            let fd = (softplus(x + h) - softplus(x - h)) / (2.0 * h);
            assert!((fd - sigmoid(x)).abs() < 1e-8);
            assert!((sigmoid(x) + sigmoid(-x) - 1.0).abs() < 2.0 * f64::EPSILON);
            assert!(
                (sigmoid_slope(x) - sigmoid(x) * sigmoid(-x)).abs() <= 1e-15 * sigmoid_slope(x)
            );
        }
    }

    #[test]
    fn dilogarithm_matches_known_values_and_is_continuous_at_one_half() {
        // Li2(-1) = -pi^2 / 12; Li2(-1/2) = -0.448414206923646...
        let pi2 = std::f64::consts::PI * std::f64::consts::PI;
        assert!((dilog_of_negative(1.0) + pi2 / 12.0).abs() < 2e-16);
        assert!((dilog_of_negative(0.5) + 0.448_414_206_923_646_2).abs() < 2e-16);
        let (below, above) = (dilog_of_negative(0.5), dilog_of_negative(0.5 + 1e-16));
        assert!((below - above).abs() < 1e-15);
        assert_eq!(dilog_of_negative(0.0), 0.0);
        assert!((dilog_of_negative(1e-20) + 1e-20).abs() < 1e-35);
    }

    #[test]
    fn tails_are_continuous_where_the_method_changes() {
        // A relative step of 1e-15 in x moves I0, I1 and I2 by about 1e-14 relative by itself.
        let below = upper_tails(RECURRENCE_FROM * (1.0 - 1e-15));
        let above = upper_tails(RECURRENCE_FROM);
        assert!((below.i0 / above.i0 - 1.0).abs() < 5e-14);
        assert!((below.i1 / above.i1 - 1.0).abs() < 5e-14);
        assert!((below.i2 / above.i2 - 1.0).abs() < 5e-14);
    }

    #[test]
    fn tails_obey_their_identities() {
        for k in 0..400 {
            let x = 0.1 * k as f64;
            let t = upper_tails(x);
            // d/dx I1 = -I0 and d/dx I2 = -2 I1 (central differences), and the ordering of the integrals.
            if x > 1e-3 && t.i2 > 1e-290 {
                let h = 1e-5 * x.min(1.0);
                let (tp, tm) = (upper_tails(x + h), upper_tails(x - h));
                assert!(
                    ((tp.i1 - tm.i1) / (2.0 * h) + t.i0).abs() < 1e-7 * t.i0,
                    "x = {x}"
                );
                assert!(
                    ((tp.i2 - tm.i2) / (2.0 * h) + 2.0 * t.i1).abs() < 1e-7 * t.i1,
                    "x = {x}"
                );
            }
            assert!(t.i0 >= t.i1 * x && t.i1 >= 0.0 && t.i2 >= 0.0);
        }
    }
}
