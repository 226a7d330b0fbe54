//! Stage 3 of the derivatives: the second-order terms. With `K(p; y) = 0` the step's equations (stage 2)
//! and `K_p^T mu = -g` for `g = (dx'/dp)^T c`, `d^2 (c^T f) / dy^2 = T^T (d^2 (mu^T K) / d(p, y)^2) T` with
//! `T = [dp/dy; I]` (second-order adjoint). For the logistic and hard models with a constant noise the
//! weighted sum over the equations is contracted directly from the ingredients' expansions (stage 1) in
//! plain arrays, never assembling one equation's Hessian ([`Structured`]); otherwise each equation's
//! Hessian along `T` is assembled in second-order vector duals (one pass per pair of blocks of
//! directions beyond eight) and the sum taken after.

#![allow(non_snake_case)]

use super::expansion::{D2, DIRECTIONS, Expansion, block_pairs, packed_len};
use super::linearise::{Linearised, RowKind, system};
use crate::error::DynamicsError;
use nalgebra::SMatrix;
use ncp::NcpFunction;
use num_dual::Derivative;

/// What the logistic or hard model with a constant sigma keeps, besides the step's expansion and
/// linearisation, to contract its equations' Hessians along `T` with any `mu` ([`Structured::contract`])
/// without assembling them: every product in the equations ([`system`]) is of a function of `q` alone
/// (gradient and Hessian over the first `n` directions, from its expansion) and a function affine in `s`,
/// and each complementarity row is a function of two such quantities (`lambda_k`, `w_k`).
#[derive(Default)]
pub(super) struct Structured {
    /// The velocities `v` of `x`.
    v: Vec<f64>,
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
    /// linearisation (`p`, `dp` and the rows' kinds), refilled in place.
    pub(super) fn fill(
        &mut self,
        expansion: &Expansion,
        (h, sigma): (f64, f64),
        x: &[f64],
        lin: &Linearised,
    ) {
        let (n, m) = (expansion.n, expansion.m);
        let (p, dp, kinds) = (&lin.p, &lin.dp, &lin.kinds);
        let cols = dp.len() / p.len();
        let geo = &expansion.geometry;
        let Structured {
            v,
            slope,
            curvature,
            bend,
        } = self;
        for buffer in [&mut *slope, &mut *curvature] {
            buffer.clear();
            buffer.resize(m, 0.0);
        }
        bend.clear();
        bend.resize(m * cols, 0.0);
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
        v.clear();
        v.extend_from_slice(&x[n..2 * n]);
    }

    /// `sum_k mu_k H_k` into `out` (row-major `cols x cols`), `H_k` the Hessian in `s` of equation `k`
    /// at `(p0 + dp s, y0 + s)`. The equations are weighted as they are accumulated, and the products
    /// that share a row of `dp` are summed before they are multiplied out, so the contraction costs about
    /// as much as one equation's Hessian.
    fn contract(&self, on: On<'_>, mu: &[f64], out: &mut [f64], scratch: &mut Vec<f64>) {
        // The example scenes' sizes compiled in (the same arithmetic, the loops unrolled): the finger, the
        // three-link finger, the slider, two fingers and pushing; any other at run time.
        match (on.expansion.n, on.cols) {
            (3, 8) => self.contract_sized::<3, 8>(on, mu, out, scratch),
            (4, 11) => self.contract_sized::<4, 11>(on, mu, out, scratch),
            (4, 9) => self.contract_sized::<4, 9>(on, mu, out, scratch),
            (5, 14) => self.contract_sized::<5, 14>(on, mu, out, scratch),
            (5, 12) => self.contract_sized::<5, 12>(on, mu, out, scratch),
            _ => self.contract_sized::<0, 0>(on, mu, out, scratch),
        }
    }

    /// [`Structured::contract`] with `N` joints and `C` columns when they are not 0.
    fn contract_sized<const N: usize, const C: usize>(
        &self,
        on: On<'_>,
        mu: &[f64],
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        let ex = on.expansion;
        let n = if N > 0 { N } else { ex.n };
        let cols = if C > 0 { C } else { on.cols };
        let (m, h, p, v) = (ex.m, on.h, &on.lin.p, &self.v);
        let geo = &ex.geometry;
        let dp = &on.lin.dp;
        let row = |t: usize| &dp[t * cols..(t + 1) * cols];
        // The sum has three parts, each accumulated in its own place:
        // - second derivatives in q of functions of q, weighted: `hq`, the leading n x n block (its upper
        //   triangle, packed as the expansion keeps the Hessians);
        // - products of a gradient in q with a row t of dp (or a unit vector): the gradients that meet
        //   row t are summed over all equations first, in `a[t n..(t + 1) n]`, and the products
        //   `P = sum_t a_t row(t)^T` (n x cols) enter as `P + P^T`;
        // - the forces' curvature in (q, v) and the logistic rows' in (lambda_k, w_k), directly in the
        //   upper triangle of `out`.
        // Every slice below is cut to its length first, so that with the sizes compiled in the loops
        // have constant trip counts and no bounds checks.
        let (nn, nc) = (packed_len(n), n * cols);
        scratch.clear();
        scratch.resize(nn + nc + (n + m) * n, 0.0);
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
            let hm = &ex.forces.h(i)[..packed_len(dim)];
            let wh = w * h;
            let mut e = 0;
            for r in 0..dim {
                for c in r..dim {
                    out[r * cols + c] -= wh * hm[e];
                    e += 1;
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
        let mut packed = 0;
        for i in 0..n {
            for j in i..cols {
                let mut e = pm[i * cols + j];
                if j < n {
                    e += hq[packed] + pm[j * cols + i];
                    packed += 1;
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

/// The Hessians over `q` of the position-level correction's entries (`n` row-major `n x n` blocks) into
/// `out`, or nothing (`out` empty) where the correction is zero (no constraint deeper than the recovery).
pub(super) fn correction_hessians(ing: &Expansion, out: &mut Vec<f64>) {
    let n = ing.n;
    let geo = &ing.geometry;
    let dim = geo.dim();
    out.clear();
    let any = (0..n).any(|i| {
        let k = ing.correction(i);
        geo.re(k) != 0.0 || geo.g(k).iter().any(|&g| g != 0.0)
    });
    if any {
        out.resize(n * n * n, 0.0);
        for i in 0..n {
            for a in 0..n.min(dim) {
                for b in 0..n.min(dim) {
                    out[i * n * n + a * n + b] = geo.hessian(ing.correction(i), a, b);
                }
            }
        }
    }
}

/// What a contraction reads of the step besides its own vectors: the expansion, the linearisation, the
/// time step and `y`'s length.
#[derive(Clone, Copy)]
struct On<'a> {
    expansion: &'a Expansion,
    lin: &'a Linearised,
    h: f64,
    cols: usize,
}

/// How the second-order adjoint contracts the Hessians of the step's equations along `T` with `mu`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(super) enum Equations {
    /// From the ingredients they are made of, directly ([`Structured::contract`]).
    #[default]
    Structured,
    /// Each equation's Hessian, assembled ([`SecondOrderParts::assembled`]).
    Assembled,
}

/// The Hessians along `T` of the step's equations ([`system`]) in second-order vector duals: one pass
/// when `y` has at most eight entries, otherwise one pass per pair of blocks of four directions.
pub(super) fn general_hessians(
    ing: &Expansion,
    (h, x): (f64, &[f64]),
    lin: &Linearised,
    cols: usize,
    normal: bool,
    e: &mut Vec<f64>,
) {
    let n = ing.n;
    let np = lin.p.len();
    let passes = block_pairs(cols, DIRECTIONS);
    let cc = cols * cols;
    e.clear();
    e.resize(np * cc, 0.0);
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
}

/// What a step's second derivatives keep besides the step and its first derivatives: the ingredients'
/// expansion, the step's linearisation (with the factors of `K_p`, for the adjoint `mu`) and the
/// Hessians of the step's equations along `T`, or what they are made of (module documentation of stage
/// 3). Kept in the step's data ([`Model::calc_diff2_prepare`]), where every vector is refilled in place
/// by the next step's, or in a [`SecondOrderStep`].
#[derive(Default)]
pub(crate) struct SecondOrderParts {
    pub(super) n: usize,
    pub(super) cols: usize,
    pub(super) h: f64,
    /// The second-order expansion of the step's ingredients.
    pub(super) expansion: Expansion,
    /// The step's linearisation; its factors of `K_p` are the adjoint's.
    pub(super) lin: Linearised,
    /// How the equations' Hessians are contracted, and what each way keeps.
    pub(super) equations: Equations,
    pub(super) structured: Structured,
    /// Each equation's Hessian, row-major `cols x cols`, one after the other (the general path).
    pub(super) assembled: Vec<f64>,
    /// The Hessians over `q` of the position-level correction `dq(q)` (`q' = q + dq + h v'`), `n` blocks of
    /// `n x n`; empty when it is zero.
    pub(super) correction: Vec<f64>,
    /// The contraction's adjoint `mu` and its scratch (refilled by each).
    pub(super) mu: Vec<f64>,
    pub(super) scratch: Vec<f64>,
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
        let np = self.lin.p.len();
        // g = (dx'/dp)^T c with x' = [q + h v'; v'], and mu from K_p^T mu = -g.
        let mu = &mut self.mu;
        mu.clear();
        mu.resize(np, 0.0);
        for i in 0..n {
            mu[i] = -(h * c[i] + c[n + i]);
        }
        self.lin.lu.solve_transposed(mu);
        match self.equations {
            Equations::Structured => {
                let on = On {
                    expansion: &self.expansion,
                    lin: &self.lin,
                    h,
                    cols,
                };
                self.structured.contract(on, mu, hess, &mut self.scratch)
            }
            Equations::Assembled => {
                hess.fill(0.0);
                for (e, w) in self.assembled.chunks_exact(cols * cols).zip(mu.iter()) {
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
        if !self.correction.is_empty() {
            for (i, block) in self.correction.chunks_exact(n * n).enumerate() {
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
