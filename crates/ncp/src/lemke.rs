//! Exact references for linear problems: Lemke's complementary pivoting method with lexicographic
//! (degeneracy-safe) ratio tests, and the enumeration of active sets for small problems.
//!
//! Lemke's method solves `0 <= z _|_ w = M z + q >= 0` for every `q` when `M` is a P-matrix, and for
//! copositive-plus `M` (positive semi-definite included) it either solves the LCP or proves that it has no
//! solution (Cottle, Pang and Stone, "The Linear Complementarity Problem", 4.4). Rows are equilibrated first
//! (a positive row scaling changes neither the solutions nor `z`), and the final basis is refined by one
//! solve of its linear system with the original data, so the answer is exact to rounding.

use crate::dense::{DenseLu, LinearSolver};
use crate::error::NcpError;
use crate::newton::inf_norm;
use crate::problem::{LinearMcp, Mcp};
use crate::solution::{Info, Solution, Status};
use serde::{Deserialize, Serialize};

/// Settings of [`lemke`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LemkeSettings {
    /// Pivots at most (Murty's family needs `2^n`).
    pub max_pivots: usize,
}

impl Default for LemkeSettings {
    fn default() -> Self {
        LemkeSettings {
            max_pivots: 1 << 20,
        }
    }
}

/// Solve the (mixed) LCP `F(z) = M z + q` exactly: equality rows are eliminated through their block (which
/// must be non-singular) and Lemke's method solves the rest. `Err(Infeasible)` on ray termination.
#[tracing::instrument(name = "ncp.lemke", level = "debug", skip_all)]
pub fn lemke(problem: &LinearMcp, settings: &LemkeSettings) -> Result<Solution, NcpError> {
    if settings.max_pivots == 0 {
        return Err(NcpError::Setting {
            name: "max_pivots",
            value: 0.0,
            expected: "at least 1",
        });
    }
    let reduced = problem.reduce()?;
    let lcp = reduced.lcp();
    let (lambda, pivots, finished) = lemke_lcp(lcp.m_row_major(), lcp.q(), settings.max_pivots)?;
    let z = reduced.expand(&lambda);
    let mut w = vec![0.0; z.len()];
    problem.evaluate(&z, &mut w, None);
    let residual = complementarity_residual(problem.n_free(), &z, &w);
    let status = if finished {
        Status::Converged
    } else {
        Status::MaxIterations
    };
    Ok(Solution {
        z,
        w,
        info: Info {
            status,
            iterations: pivots,
            residual,
            evaluations: 1,
        },
    })
}

/// `max(|F_i|)` over equality rows and `max |min(z_i, w_i)|` over complementarity rows.
pub fn complementarity_residual(n_free: usize, z: &[f64], w: &[f64]) -> f64 {
    let eq = inf_norm(&w[..n_free]);
    z[n_free..]
        .iter()
        .zip(&w[n_free..])
        .fold(eq, |m, (a, b)| m.max(a.min(*b).abs()))
}

/// Lemke on a plain LCP (row-major `m`); returns `z`, the pivot count, and whether it finished.
fn lemke_lcp(m: &[f64], q: &[f64], max_pivots: usize) -> Result<(Vec<f64>, usize, bool), NcpError> {
    let n = q.len();
    if q.iter().all(|&v| v >= 0.0) {
        return Ok((vec![0.0; n], 0, true));
    }
    // Tableau rows: w_i - sum_j M_ij z_j - z0 = q_i, each row divided by its largest entry.
    // Columns: w (0..n), z (n..2n), z0 (2n), right-hand side (2n + 1).
    let width = 2 * n + 2;
    let (z0, rhs) = (2 * n, 2 * n + 1);
    let mut t = vec![0.0; n * width];
    for i in 0..n {
        let row_scale = m[i * n..(i + 1) * n]
            .iter()
            .fold(q[i].abs(), |s, v| s.max(v.abs()));
        let s = if row_scale > 0.0 {
            1.0 / row_scale
        } else {
            1.0
        };
        let r = &mut t[i * width..(i + 1) * width];
        r[i] = s;
        for j in 0..n {
            r[n + j] = -m[i * n + j] * s;
        }
        r[z0] = -1.0;
        r[rhs] = q[i] * s;
    }
    let mut basis: Vec<usize> = (0..n).collect();

    // First pivot: z0 enters where q_i (scaled) is most negative, lexicographically.
    let leave = lex_min_row(&t, n, width, z0, |_, v| v < 0.0, -1.0);
    let mut pivots = 0;
    let mut row = leave.expect("some q_i is negative");
    let mut entering = z0;
    loop {
        pivot(&mut t, n, width, row, entering);
        pivots += 1;
        let left = basis[row];
        basis[row] = entering;
        if left == z0 {
            break;
        }
        if pivots >= max_pivots {
            return Ok((read_z(&t, &basis, n, width), pivots, false));
        }
        entering = if left < n { left + n } else { left - n };
        let col_max = (0..n).fold(0.0f64, |s, i| s.max(t[i * width + entering].abs()));
        let tol = 1e-12 * col_max.max(1e-300);
        match lex_min_row(&t, n, width, entering, |_, v| v > tol, 1.0) {
            Some(r) => row = r,
            None => return Err(NcpError::Infeasible { pivots }),
        }
    }
    let z = read_z(&t, &basis, n, width);
    Ok((refine(m, q, &basis, z), pivots, true))
}

/// Among rows whose entry in `col` passes `eligible`, the one minimising `(rhs, B^-1 row) / (sign * entry)`
/// lexicographically.
fn lex_min_row(
    t: &[f64],
    n: usize,
    width: usize,
    col: usize,
    eligible: impl Fn(usize, f64) -> bool,
    sign: f64,
) -> Option<usize> {
    let rhs = width - 1;
    let key = |i: usize, k: usize| {
        let d = sign * t[i * width + col];
        let v = if k == 0 {
            t[i * width + rhs]
        } else {
            t[i * width + (k - 1)]
        };
        // For the first pivot (sign = -1) the ratio is rhs / -d, minimised by the most negative rhs.
        v / d
    };
    let mut best: Option<usize> = None;
    for i in 0..n {
        if !eligible(i, t[i * width + col]) {
            continue;
        }
        best = match best {
            None => Some(i),
            Some(b) => {
                let mut choose = b;
                for k in 0..=n {
                    let (ki, kb) = (key(i, k), key(b, k));
                    let tie = 1e-11 * ki.abs().max(kb.abs()).max(1e-300);
                    if (ki - kb).abs() <= tie {
                        continue;
                    }
                    choose = if ki < kb { i } else { b };
                    break;
                }
                Some(choose)
            }
        };
    }
    best
}

fn pivot(t: &mut [f64], n: usize, width: usize, row: usize, col: usize) {
    let p = t[row * width + col];
    for j in 0..width {
        t[row * width + j] /= p;
    }
    t[row * width + col] = 1.0;
    for i in 0..n {
        if i == row {
            continue;
        }
        let f = t[i * width + col];
        if f != 0.0 {
            for j in 0..width {
                t[i * width + j] -= f * t[row * width + j];
            }
            t[i * width + col] = 0.0;
        }
    }
}

fn read_z(t: &[f64], basis: &[usize], n: usize, width: usize) -> Vec<f64> {
    let mut z = vec![0.0; n];
    for (i, &b) in basis.iter().enumerate() {
        if (n..2 * n).contains(&b) {
            z[b - n] = t[i * width + width - 1].max(0.0);
        }
    }
    z
}

/// Re-solve `M_SS z_S = -q_S` on the final support `S` with the original data; keep the result if it is at
/// least as complementary as the tableau's.
fn refine(m: &[f64], q: &[f64], basis: &[usize], z: Vec<f64>) -> Vec<f64> {
    let n = q.len();
    let support: Vec<usize> = basis
        .iter()
        .filter(|&&b| (n..2 * n).contains(&b))
        .map(|b| b - n)
        .collect();
    let k = support.len();
    if k == 0 {
        return z;
    }
    let mut a = vec![0.0; k * k];
    let mut x = vec![0.0; k];
    for (r, &i) in support.iter().enumerate() {
        for (c, &j) in support.iter().enumerate() {
            a[r * k + c] = m[i * n + j];
        }
        x[r] = -q[i];
    }
    let mut lu = DenseLu::new(k, LinearSolver::Hand);
    if !lu.factor(&a) {
        return z;
    }
    lu.solve(&mut x);
    let mut refined = vec![0.0; n];
    for (r, &i) in support.iter().enumerate() {
        refined[i] = x[r].max(0.0);
    }
    if lcp_residual(m, q, &refined) <= lcp_residual(m, q, &z) {
        refined
    } else {
        z
    }
}

fn lcp_residual(m: &[f64], q: &[f64], z: &[f64]) -> f64 {
    let n = q.len();
    (0..n).fold(0.0f64, |r, i| {
        let w = q[i] + (0..n).map(|j| m[i * n + j] * z[j]).sum::<f64>();
        if w.is_finite() {
            r.max(w.min(z[i]).abs())
        } else {
            f64::INFINITY
        }
    })
}

/// Every solution of a small (mixed) LCP, by enumerating the `2^c` active sets of its complementarity rows
/// (after eliminating the equality rows): the oracle the tests hold the solvers to. Sets whose system is
/// singular are skipped, so degenerate problems with a continuum of solutions report the vertices found.
/// `tol` is the complementarity tolerance relative to the data's scale; `c <= 20`.
pub fn enumerate_solutions(problem: &LinearMcp, tol: f64) -> Result<Vec<Vec<f64>>, NcpError> {
    let reduced = problem.reduce()?;
    let c = reduced.n_compl();
    if c > 20 {
        return Err(NcpError::Unsupported(
            "active-set enumeration takes at most 20 complementarity rows",
        ));
    }
    let (a, b) = (&reduced.a, &reduced.b);
    let scale = a.iter().chain(b).fold(1.0f64, |s, v| s.max(v.abs()));
    let mut found: Vec<Vec<f64>> = Vec::new();
    for mask in 0u32..(1u32 << c) {
        let support: Vec<usize> = (0..c).filter(|i| mask & (1 << i) != 0).collect();
        let k = support.len();
        let mut lambda = vec![0.0; c];
        if k > 0 {
            let mut mat = vec![0.0; k * k];
            let mut x = vec![0.0; k];
            for (r, &i) in support.iter().enumerate() {
                for (s, &j) in support.iter().enumerate() {
                    mat[r * k + s] = a[i * c + j];
                }
                x[r] = -b[i];
            }
            let mut lu = DenseLu::new(k, LinearSolver::Hand);
            if !lu.factor(&mat) {
                continue;
            }
            lu.solve(&mut x);
            for (r, &i) in support.iter().enumerate() {
                lambda[i] = x[r];
            }
        }
        let ok = (0..c).all(|i| {
            let w = b[i] + (0..c).map(|j| a[i * c + j] * lambda[j]).sum::<f64>();
            lambda[i] >= -tol * scale && w >= -tol * scale
        });
        if ok {
            let z = reduced.expand(&lambda);
            let duplicate = found.iter().any(|g| {
                g.iter()
                    .zip(&z)
                    .all(|(p, q)| (p - q).abs() <= 1e3 * tol * scale.max(1.0))
            });
            if !duplicate {
                found.push(z);
            }
        }
    }
    Ok(found)
}
