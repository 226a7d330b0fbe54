//! Stage 2 of the derivatives: the step's equations `K(p; y) = 0` in their unknowns `p` at the step's
//! solution, each complementarity row typed by what it is at that solution ([`RowKind`]), `K_p` factored,
//! and `dp/dy` by the implicit function theorem, eight directions of `y = (x, u)` per pass.

#![allow(non_snake_case)]

use super::expansion::Ingredients;
use crate::kinematics::Scalar;
use ncp::{DenseLu, normal_expected_squared, normal_expected_squared_third};

/// The unknowns at the solution, the Jacobian of the equations in them (and its factors), each row's kind
/// and each complementarity row's slope in `w` (logistic and hard models; empty for the normal model).
pub(super) type System = (Vec<f64>, Vec<f64>, DenseLu, Vec<RowKind>, Vec<f64>);

/// What a complementarity row of the linearised step is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum RowKind {
    /// `lambda_i` held at its value: an inactive hard row, a normal row on its bound, or a redundant row.
    Fixed,
    /// An active hard row, `w_i = 0`.
    Contact,
    /// The logistic function of eq. (17), `phi(lambda_i, w_i; sigma_i) = 0`.
    Logistic,
    /// A normal (ERM) row off its bound: the stationarity `d E_i / d lambda_i - (J nu)_i = 0`.
    Stationary,
}

/// The equations whose root the step is, in the unknowns `p`:
///
/// - logistic and hard: `p = [v'; lambda]`, `[M (v' - v) - h r - J^T lambda; row_i(lambda_i, w_i)]`;
/// - normal (eq. 14 with 15 as an optimisation over `lambda >= 0` with `v'` from the equations of motion):
///   `p = [v'; lambda; nu]` and the first-order conditions
///   `[M (v' - v) - h r - J^T lambda; J^T e_b + M nu; e_a,i - (J nu)_i or lambda_i]`, `e = E[min(lambda, w +
///   sigma xi)^2]` per row, its derivatives in `(lambda, w)` carried to second order by their Taylor
///   polynomials around the solution (exact for first and second derivatives of the step).
pub(super) fn system<T: Scalar>(
    n: usize,
    h: f64,
    ing: &Ingredients<T>,
    v: &[T],
    p: &[T],
    kinds: &[RowKind],
    normal: bool,
) -> Vec<T> {
    let (mut out, mut w) = (Vec::with_capacity(p.len()), Vec::new());
    system_into(n, h, ing, (v, p), kinds, normal, (&mut out, &mut w));
    out
}

/// [`system`] into `out`, the rows' `w` in `w` (both refilled; the logistic and hard models' allocate
/// nothing once they have the step's sizes).
pub(super) fn system_into<T: Scalar>(
    n: usize,
    h: f64,
    ing: &Ingredients<T>,
    (v, p): (&[T], &[T]),
    kinds: &[RowKind],
    normal: bool,
    (out, w): (&mut Vec<T>, &mut Vec<T>),
) {
    let m = ing.d.len();
    let (vn, rest) = p.split_at(n);
    let lambda = &rest[..m];
    out.clear();
    for i in 0..n {
        let mut s = -ing.r[i] * h;
        for j in 0..n {
            s += ing.M[i * n + j] * (vn[j] - v[j]);
        }
        for k in 0..m {
            s -= ing.jac[k * n + i] * lambda[k];
        }
        out.push(s);
    }
    w.clear();
    w.extend((0..m).map(|k| {
        let mut s = ing.d[k] / h;
        for j in 0..n {
            s += ing.jac[k * n + j] * vn[j];
        }
        s
    }));
    if !normal {
        for k in 0..m {
            out.push(match kinds[k] {
                RowKind::Fixed => lambda[k],
                RowKind::Contact => w[k],
                RowKind::Logistic => logistic(lambda[k], w[k], ing.sigma[k]),
                RowKind::Stationary => unreachable!("stationary rows belong to the normal model"),
            });
        }
        return;
    }
    let nu = &rest[m..m + n];
    let mut ea = Vec::with_capacity(m);
    let mut eb = Vec::with_capacity(m);
    for k in 0..m {
        let (l0, w0, sigma) = (lambda[k].re(), w[k].re(), ing.sigma[k].re());
        let j = normal_expected_squared(l0, w0, sigma);
        let [aaa, aab, abb, bbb] = normal_expected_squared_third(l0, w0, sigma);
        let (dl, dw) = (lambda[k] - l0, w[k] - w0);
        let (ll, lw, ww) = (dl * dl * 0.5, dl * dw, dw * dw * 0.5);
        ea.push(dl * j.daa + dw * j.dab + ll * aaa + lw * aab + ww * abb + j.da);
        eb.push(dl * j.dab + dw * j.dbb + ll * aab + lw * abb + ww * bbb + j.db);
    }
    for i in 0..n {
        let mut s = T::from(0.0);
        for k in 0..m {
            s += ing.jac[k * n + i] * eb[k];
        }
        for j in 0..n {
            s += ing.M[i * n + j] * nu[j];
        }
        out.push(s);
    }
    for k in 0..m {
        out.push(match kinds[k] {
            RowKind::Fixed => lambda[k],
            RowKind::Stationary => {
                let mut s = ea[k];
                for j in 0..n {
                    s -= ing.jac[k * n + j] * nu[j];
                }
                s
            }
            _ => unreachable!("normal rows are fixed or stationary"),
        });
    }
}

/// What the linearisation of a step keeps (refilled in place by the next step's).
pub(super) struct Linearised {
    /// The unknowns of the step's equations at the solution ([`system`]).
    pub(super) p: Vec<f64>,
    /// The factors of `K_p`.
    pub(super) lu: DenseLu,
    /// `dp/d(x, u)`, row-major `len(p) x (2n + n_u)`.
    pub(super) dp: Vec<f64>,
    /// Each complementarity row's kind.
    pub(super) kinds: Vec<RowKind>,
    /// `d dq / d(x, u)` of the position-level correction, row-major `n x (2n + n_u)`.
    pub(super) dcorrection: Vec<f64>,
}

impl Default for Linearised {
    fn default() -> Self {
        Linearised {
            p: Vec::new(),
            lu: DenseLu::new(0, ncp::LinearSolver::Hand),
            dp: Vec::new(),
            kinds: Vec::new(),
            dcorrection: Vec::new(),
        }
    }
}

/// The logistic NCP function of paper eq. (17) in any dual type: `min(a, b) - s softplus(-|a - b| / s)`.
fn logistic<T: Scalar>(a: T, b: T, sigma: T) -> T {
    let c = (a - b) / sigma;
    if c.re() > 0.0 {
        b - (-c).exp().ln_1p() * sigma
    } else {
        a - c.exp().ln_1p() * sigma
    }
}
