//! Stage 3 of the derivatives: the second-order terms. With `K(p; y) = 0` the step's equations (stage 2)
//! and `K_p^T mu = -g` for `g = (dx'/dp)^T c`, `d^2 (c^T f) / dy^2 = T^T (d^2 (mu^T K) / d(p, y)^2) T` with
//! `T = [dp/dy; I]` (second-order adjoint). For the logistic and hard models with a constant noise the
//! weighted sum over the equations is contracted directly from the ingredients' expansions (stage 1) in
//! plain arrays, never assembling one equation's Hessian ([`Structured`]); otherwise each equation's
//! Hessian along `T` is assembled in second-order vector duals (one pass per pair of blocks of
//! directions beyond eight) and the sum taken after.

#![allow(non_snake_case)]

use super::expansion::{D2, DIRECTIONS, Expansion, block_pairs};
use super::linearise::{Linearised, RowKind, system};
use crate::error::DynamicsError;
use nalgebra::SMatrix;
use ncp::{DenseLu, NcpFunction};
use num_dual::Derivative;

/// The linearised step of the logistic or hard model with a constant sigma, kept to contract its
/// equations' Hessians along `T` with any `mu` ([`Structured::contract`]) without assembling them: every
/// product in the equations ([`system`]) is of a function of `q` alone (gradient and Hessian over the first
/// `n` directions, from its expansion) and a function affine in `s`, and each complementarity row is a
/// function of two such quantities (`lambda_k`, `w_k`).
pub(super) struct Structured {
    expansion: Expansion,
    h: f64,
    /// The velocities `v` of `x`.
    v: Vec<f64>,
    p: Vec<f64>,
    /// `dp/dy`, row-major `len(p) x cols`.
    dp: Vec<f64>,
    cols: usize,
    /// Each complementarity row's weight on the curvature of `w_k`: `d phi / d w_k` for a logistic row,
    /// 1 for an active hard row, 0 for a fixed one.
    slope: Vec<f64>,
    /// Each logistic row's curvature `c_k`: the logistic function's Hessian in `(lambda_k, w_k)` is
    /// `-c_k [1, -1] [1, -1]^T`, so the row adds `-mu_k c_k b_k b_k^T` with `b_k` the gradient of
    /// `lambda_k - w_k` along `T` (in `bend`, `cols` per row); 0 for the other rows.
    curvature: Vec<f64>,
    bend: Vec<f64>,
}

impl Structured {
    /// Everything of the contraction that does not depend on `mu`, from the step's expansion and
    /// linearisation (`p`, `dp` and the rows' kinds).
    pub(super) fn new(
        expansion: Expansion,
        h: f64,
        x: &[f64],
        p: Vec<f64>,
        dp: Vec<f64>,
        kinds: &[RowKind],
        sigma: f64,
    ) -> Structured {
        let (n, m) = (expansion.n, expansion.m);
        let cols = dp.len() / p.len();
        let geo = &expansion.geometry;
        let mut slope = vec![0.0; m];
        let mut curvature = vec![0.0; m];
        let mut bend = vec![0.0; m * cols];
        for k in 0..m {
            match kinds[k] {
                RowKind::Fixed => {}
                RowKind::Contact => slope[k] = 1.0,
                RowKind::Logistic => {
                    let w0 = geo.re(expansion.dist(k)) / h
                        + (0..n)
                            .map(|j| geo.re(expansion.jac(k, j)) * p[j])
                            .sum::<f64>();
                    let jet = NcpFunction::Logistic { sigma }.jet(p[n + k], w0);
                    debug_assert!(jet.daa == -jet.dab && jet.dbb == -jet.dab);
                    slope[k] = jet.db;
                    curvature[k] = jet.dab;
                    // b_k = grad lambda_k - grad w_k, w_k = d_k / h + sum_j J_kj v'_j.
                    let b = &mut bend[k * cols..(k + 1) * cols];
                    b.copy_from_slice(&dp[(n + k) * cols..(n + k + 1) * cols]);
                    for (e, g) in b.iter_mut().zip(geo.g(expansion.dist(k))) {
                        *e -= g / h;
                    }
                    for j in 0..n {
                        let f = expansion.jac(k, j);
                        for (e, g) in b.iter_mut().zip(geo.g(f)) {
                            *e -= p[j] * g;
                        }
                        let re = geo.re(f);
                        for (e, d) in b.iter_mut().zip(&dp[j * cols..(j + 1) * cols]) {
                            *e -= re * d;
                        }
                    }
                }
                RowKind::Stationary => {
                    unreachable!("logistic and hard rows are fixed, contact or logistic")
                }
            }
        }
        Structured {
            v: x[n..2 * n].to_vec(),
            expansion,
            h,
            p,
            dp,
            cols,
            slope,
            curvature,
            bend,
        }
    }

    /// `sum_k mu_k H_k` into `out` (row-major `cols x cols`), `H_k` the Hessian in `s` of equation `k`
    /// at `(p0 + dp s, y0 + s)`. The equations are weighted as they are accumulated, and the products
    /// that share a row of `dp` are summed before they are multiplied out, so the contraction costs about
    /// as much as one equation's Hessian.
    fn contract(&self, mu: &[f64], out: &mut [f64]) {
        // The example scenes' sizes compiled in (the same arithmetic, the loops unrolled): the finger, the
        // three-link finger, the slider, two fingers and pushing; any other at run time.
        match (self.expansion.n, self.cols) {
            (3, 8) => self.contract_sized::<3, 8>(mu, out),
            (4, 11) => self.contract_sized::<4, 11>(mu, out),
            (4, 9) => self.contract_sized::<4, 9>(mu, out),
            (5, 14) => self.contract_sized::<5, 14>(mu, out),
            (5, 12) => self.contract_sized::<5, 12>(mu, out),
            _ => self.contract_sized::<0, 0>(mu, out),
        }
    }

    /// [`Structured::contract`] with `N` joints and `C` columns when they are not 0.
    fn contract_sized<const N: usize, const C: usize>(&self, mu: &[f64], out: &mut [f64]) {
        let ex = &self.expansion;
        let n = if N > 0 { N } else { ex.n };
        let cols = if C > 0 { C } else { self.cols };
        let (m, h, p, v) = (ex.m, self.h, &self.p, &self.v);
        let geo = &ex.geometry;
        let row = |t: usize| &self.dp[t * cols..(t + 1) * cols];
        // The sum has three parts, each accumulated in its own place:
        // - second derivatives in q of functions of q, weighted: `hq`, the leading n x n block;
        // - products of a gradient in q with a row t of dp (or a unit vector): the gradients that meet
        //   row t are summed over all equations first, in `a[t n..(t + 1) n]`, and the products
        //   `P = sum_t a_t row(t)^T` (n x cols) enter as `P + P^T`;
        // - the forces' curvature in (q, v) and the logistic rows' in (lambda_k, w_k), directly in the
        //   upper triangle of `out`.
        // Every slice below is cut to its length first, so that with the sizes compiled in the loops
        // have constant trip counts and no bounds checks.
        let (nn, nc) = (n * n, n * cols);
        let mut scratch = vec![0.0; nn + nc + (n + m) * n];
        let (hq, rest) = scratch.split_at_mut(nn);
        let (pm, a) = rest.split_at_mut(nc);
        let pm = &mut pm[..nc];
        let out = &mut out[..cols * cols];
        let add_q = |hq: &mut [f64], f: usize, scale: f64| {
            let (hq, hf) = (&mut hq[..nn], &geo.h(f)[..nn]);
            for e in 0..nn {
                hq[e] += scale * hf[e];
            }
        };
        let add_g = |a: &mut [f64], f: usize, scale: f64| {
            let (a, g) = (&mut a[..n], &geo.g(f)[..n]);
            for e in 0..n {
                a[e] += scale * g[e];
            }
        };
        out.fill(0.0);
        // Equations of motion: sum_j M_ij (v'_j - v_j) - h r_i - sum_k J_ki lambda_k.
        let dim = 2 * n;
        for (i, &w) in mu[..n].iter().enumerate() {
            if w == 0.0 {
                continue;
            }
            for j in 0..n {
                let f = ex.mass(i, j);
                add_q(hq, f, w * (p[j] - v[j]));
                add_g(&mut a[j * n..], f, w);
                // The -v_j of (v'_j - v_j): direction n + j of y.
                let g = &geo.g(f)[..n];
                for t in 0..n {
                    pm[t * cols + n + j] -= w * g[t];
                }
            }
            for k in 0..m {
                let f = ex.jac(k, i);
                add_q(hq, f, -w * p[n + k]);
                add_g(&mut a[(n + k) * n..], f, -w);
            }
            debug_assert_eq!(ex.forces.dim(), dim);
            let hm = &ex.forces.h(i)[..dim * dim];
            let wh = w * h;
            for r in 0..dim {
                for c in r..dim {
                    out[r * cols + c] -= wh * hm[r * dim + c];
                }
            }
        }
        // Rows: w_k = d_k / h + sum_j J_kj v'_j, then lambda_k (no curvature), w_k or phi(lambda_k, w_k).
        for k in 0..m {
            let s = mu[n + k] * self.slope[k];
            if s == 0.0 {
                continue;
            }
            add_q(hq, ex.dist(k), s / h);
            for j in 0..n {
                let f = ex.jac(k, j);
                add_q(hq, f, s * p[j]);
                add_g(&mut a[j * n..], f, s);
            }
            let c = -mu[n + k] * self.curvature[k];
            if c != 0.0 {
                let b = &self.bend[k * cols..(k + 1) * cols];
                for r in 0..cols {
                    let cb = c * b[r];
                    for q in r..cols {
                        out[r * cols + q] += cb * b[q];
                    }
                }
            }
        }
        for t in 0..n + m {
            let (rt, at) = (row(t), &a[t * n..(t + 1) * n]);
            for i in 0..n {
                let ai = at[i];
                if ai != 0.0 {
                    let prow = &mut pm[i * cols..(i + 1) * cols];
                    for q in 0..cols {
                        prow[q] += ai * rt[q];
                    }
                }
            }
        }
        // The upper triangle of hq + P + P^T.
        for i in 0..n {
            for j in i..cols {
                let mut e = pm[i * cols + j];
                if j < n {
                    e += hq[i * n + j] + pm[j * cols + i];
                }
                out[i * cols + j] += e;
            }
        }
        for r in 1..cols {
            for c in 0..r {
                out[r * cols + c] = out[c * cols + r];
            }
        }
    }
}

/// The Hessians over `q` of the position-level correction's entries (`n` row-major `n x n` blocks), or
/// `None` where the correction is zero (no constraint deeper than the recovery).
pub(super) fn correction_hessians(ing: &Expansion) -> Option<Vec<f64>> {
    let n = ing.n;
    let geo = &ing.geometry;
    let dim = geo.dim();
    let any = (0..n).any(|i| {
        let k = ing.correction(i);
        geo.re(k) != 0.0 || geo.g(k).iter().any(|&g| g != 0.0)
    });
    any.then(|| {
        let mut out = vec![0.0; n * n * n];
        for i in 0..n {
            let h = geo.h(ing.correction(i));
            for a in 0..n.min(dim) {
                for b in 0..n.min(dim) {
                    out[i * n * n + a * n + b] = h[a * dim + b];
                }
            }
        }
        out
    })
}

/// What the second-order adjoint contracts with `mu`: the Hessians of the step's equations along `T`.
// One per knot, kept with the knot's data: the variants' sizes do not matter, an allocation would.
#[allow(clippy::large_enum_variant)]
pub(super) enum Equations {
    /// Each equation's Hessian, row-major `cols x cols`, one after the other (the general path).
    Assembled(Vec<f64>),
    /// The ingredients they are assembled from, contracted directly ([`Structured::contract`]).
    Structured(Structured),
}

/// The Hessians along `T` of the step's equations ([`system`]) in second-order vector duals: one pass
/// when `y` has at most eight entries, otherwise one pass per pair of blocks of four directions.
pub(super) fn general_hessians(
    ing: &Expansion,
    h: f64,
    x: &[f64],
    lin: &Linearised,
    cols: usize,
    normal: bool,
) -> Vec<f64> {
    let n = ing.n;
    let np = lin.p.len();
    let passes = block_pairs(cols, DIRECTIONS);
    let cc = cols * cols;
    let mut e = vec![0.0; np * cc];
    for dirs in &passes {
        let ps: Vec<D2> = (0..np)
            .map(|i| {
                let mut grad = SMatrix::<f64, 1, DIRECTIONS>::zeros();
                for (l, &k) in dirs.iter().enumerate() {
                    grad[(0, l)] = lin.dp[i * cols + k];
                }
                D2::new(lin.p[i], Derivative::some(grad), Derivative::none())
            })
            .collect();
        let v: Vec<D2> = (0..n)
            .map(|j| {
                let d = D2::from_re(x[n + j]);
                match dirs.iter().position(|&k| k == n + j) {
                    Some(l) => d.derivative(l),
                    None => d,
                }
            })
            .collect();
        for (k, eq) in system(n, h, &ing.lifted(dirs), &v, &ps, &lin.kinds, normal)
            .iter()
            .zip(e.chunks_exact_mut(cc))
        {
            if let Some(hm) = &k.v2.0 {
                for (l, &i) in dirs.iter().enumerate() {
                    for (l2, &j) in dirs.iter().enumerate() {
                        eq[i * cols + j] = hm[(l, l2)];
                    }
                }
            }
        }
    }
    e
}

/// What a step's second derivatives keep besides the step and its first derivatives: the factors of
/// `K_p` (for the adjoint `mu`) and the Hessians of the step's equations along `T`, or what they are made
/// of (module documentation of stage 3). Kept in the step's data ([`Model::calc_diff2_prepare`]) or in a
/// [`SecondOrderStep`].
pub(crate) struct SecondOrderParts {
    pub(super) n: usize,
    pub(super) cols: usize,
    pub(super) h: f64,
    pub(super) adjoint: DenseLu,
    /// The Hessians of the step's equations along `T`, or what they are made of.
    pub(super) equations: Equations,
    /// The Hessians over `q` of the position-level correction `dq(q)` (`q' = q + dq + h v'`), `n` blocks of
    /// `n x n`; `None` when it is zero.
    pub(super) correction: Option<Vec<f64>>,
}

impl std::fmt::Debug for SecondOrderParts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SecondOrderParts")
            .field("n", &self.n)
            .field("cols", &self.cols)
            .finish_non_exhaustive()
    }
}

impl SecondOrderParts {
    /// [`SecondOrderStep::hessian_into`].
    pub(crate) fn hessian_into(
        &mut self,
        c: &[f64],
        hess: &mut [f64],
    ) -> Result<(), DynamicsError> {
        let (n, cols, h) = (self.n, self.cols, self.h);
        if c.len() != 2 * n || !c.iter().all(|e| e.is_finite()) {
            return Err(DynamicsError::Input {
                what: "c",
                problem: format!("needs {} finite entries", 2 * n),
            });
        }
        if hess.len() != cols * cols {
            return Err(DynamicsError::Input {
                what: "hess",
                problem: format!("needs {} entries, has {}", cols * cols, hess.len()),
            });
        }
        let np = match &self.equations {
            Equations::Assembled(e) => e.len() / (cols * cols),
            Equations::Structured(s) => s.p.len(),
        };
        // g = (dx'/dp)^T c with x' = [q + h v'; v'], and mu from K_p^T mu = -g.
        let mut mu = vec![0.0; np];
        for i in 0..n {
            mu[i] = -(h * c[i] + c[n + i]);
        }
        self.adjoint.solve_transposed(&mut mu);
        match &self.equations {
            Equations::Structured(s) => s.contract(&mu, hess),
            Equations::Assembled(equations) => {
                hess.fill(0.0);
                for (e, w) in equations.chunks_exact(cols * cols).zip(&mu) {
                    for (a, b) in hess.iter_mut().zip(e) {
                        *a += w * b;
                    }
                }
                // Symmetric to rounding; make it exactly so.
                for i in 0..cols {
                    for j in 0..i {
                        let v = 0.5 * (hess[i * cols + j] + hess[j * cols + i]);
                        hess[i * cols + j] = v;
                        hess[j * cols + i] = v;
                    }
                }
            }
        }
        // The correction's own curvature: c_q^T dq(q) adds sum_i c_i d^2 dq_i / dq^2 to the (q, q) block.
        if let Some(blocks) = &self.correction {
            for (i, block) in blocks.chunks_exact(n * n).enumerate() {
                if c[i] == 0.0 {
                    continue;
                }
                for a in 0..n {
                    for b in 0..n {
                        hess[a * cols + b] += c[i] * block[a * n + b];
                    }
                }
            }
        }
        Ok(())
    }
}
