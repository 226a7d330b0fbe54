//! Exact references for linear problems: Lemke's complementary pivoting method with lexicographic
//! (degeneracy-safe) ratio tests, and the enumeration of active sets for small problems.
//!
//! Lemke's method solves `0 <= z _|_ w = M z + q >= 0` for every `q` when `M` is a P-matrix, and for
//! copositive-plus `M` (positive semi-definite included) it either solves the LCP or proves that it has no
//! solution (Cottle, Pang and Stone, "The Linear Complementarity Problem", 4.4). Rows are equilibrated first
//! (a positive row scaling changes neither the solutions nor `z`), and the final basis is refined by one
//! solve of its linear system with the original data, so the answer is exact to rounding.

use crate::dense::{DenseLu, LinearSolver, inf_norm};
use crate::error::NcpError;
use crate::problem::{LinearMcp, Mcp};
use crate::solution::{Info, Solution, Status};
use serde::{Deserialize, Serialize};

/// Settings of [`lemke`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LemkeSettings {
    /// Pivots at most (Murty's family needs `2^n`).
    pub max_pivots: usize,
    /// Complementarity rows at most: the revised form refactors the basis at every pivot (`O(n^3)` each,
    /// some `n` pivots), so a problem past this is refused ([`NcpError::TooLarge`]) rather than left to
    /// run for minutes (400 rows take about a second, 2000 would take many minutes).
    #[serde(default = "default_max_size")]
    pub max_size: usize,
}

fn default_max_size() -> usize {
    LemkeSettings::default().max_size
}

impl LemkeSettings {
    /// Check the settings: at least one pivot.
    pub fn validate(&self) -> Result<(), NcpError> {
        if self.max_pivots == 0 {
            return Err(NcpError::Setting {
                name: "max_pivots",
                value: 0.0,
                expected: "at least 1",
            });
        }
        Ok(())
    }
}

impl Default for LemkeSettings {
    fn default() -> Self {
        LemkeSettings {
            max_pivots: 1 << 20,
            max_size: 500,
        }
    }
}

/// Solve the (mixed) LCP `F(z) = M z + q` exactly: equality rows are eliminated through their block (which
/// must be non-singular) and Lemke's method solves the rest. `Err(Infeasible)` on ray termination.
#[tracing::instrument(name = "ncp.lemke", level = "debug", skip_all)]
pub fn lemke(problem: &LinearMcp, settings: &LemkeSettings) -> Result<Solution, NcpError> {
    settings.validate()?;
    let rows = problem.dim() - problem.n_free();
    if rows > settings.max_size {
        return Err(NcpError::TooLarge {
            method: "Lemke's method",
            rows,
            max: settings.max_size,
        });
    }
    let reduced = problem.reduce()?;
    let lcp = reduced.lcp();
    // Ray termination proves infeasibility in exact arithmetic; in floating point a nearly singular M can
    // end on a ray that does not exist. Before saying "infeasible", retry with other covering vectors (the
    // row scales, then ones, then seeded random multiples of them).
    let c = lcp.q().len();
    if let Some(row) = infeasible_row(lcp.m_row_major(), lcp.q()) {
        return Err(NcpError::InfeasibleRow {
            row,
            q: lcp.q()[row],
        });
    }
    // Judged row by row in the equilibrated problem (each row divided by its largest entry), so that a
    // row scaled by 1e-8 is held to the same standard as one scaled by 1e8.
    let accuracy = 1e-10;
    let mut total = 0;
    let mut rays = 0;
    // The best answer so far: (residual, lambda, finished).
    let mut best: Option<(f64, Vec<f64>, bool)> = None;
    for attempt in 0..4u64 {
        let covering: Vec<f64> = match attempt {
            0 => vec![1.0; c],
            1 => {
                // d = 1: undo the row scale.
                let m = lcp.m_row_major();
                (0..c)
                    .map(|i| {
                        let r = m[i * c..(i + 1) * c]
                            .iter()
                            .fold(lcp.q()[i].abs(), |s, v| s.max(v.abs()));
                        row_scale(r)
                    })
                    .collect()
            }
            _ => {
                let mut rng = crate::rng::SplitMix64::new(attempt);
                (0..c).map(|_| rng.uniform(0.5, 2.0)).collect()
            }
        };
        match lemke_lcp(lcp.m_row_major(), lcp.q(), settings.max_pivots, &covering) {
            Attempt::Solved(lambda, pivots, finished) => {
                total += pivots;
                let residual = equilibrated_residual(lcp.m_row_major(), lcp.q(), &lambda);
                let good = residual <= accuracy;
                if best.as_ref().is_none_or(|b| residual < b.0) {
                    best = Some((residual, lambda, finished));
                }
                if good || !finished {
                    break;
                }
            }
            Attempt::Ray(pivots) => {
                total += pivots;
                rays += 1;
            }
            Attempt::Breakdown(pivots) => total += pivots,
        }
    }
    let Some((residual, lambda, finished)) = best else {
        // Every attempt ended on a ray (or broke down): report infeasibility only if one saw a ray.
        return Err(if rays > 0 {
            NcpError::Infeasible { pivots: total }
        } else {
            NcpError::Unsupported("Lemke's method broke down numerically on every covering vector")
        });
    };
    let pivots = total;
    let z = reduced.expand(&lambda);
    let mut w = vec![0.0; z.len()];
    problem.evaluate(&z, &mut w, None);
    let status = if !finished {
        Status::MaxIterations
    } else if residual <= accuracy {
        Status::Converged
    } else {
        Status::Inaccurate
    };
    let residual = complementarity_residual(problem.n_free(), &z, &w);
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

/// `1 / r` for a row's largest magnitude `r`; outside `[1e-300, 1e300]` a power of two held within
/// `[2^-600, 2^600]`: a row whose entries are all subnormal would otherwise scale to infinity, and
/// `0 * inf` is NaN.
fn row_scale(r: f64) -> f64 {
    if !(r > 0.0) {
        return 1.0;
    }
    if (1e-300..=1e300).contains(&r) {
        return 1.0 / r;
    }
    let exponent = r.log2().round().clamp(-600.0, 600.0);
    (-exponent).exp2()
}

/// A row that certifies infeasibility on its own: `q_i < 0` with no positive entry in row `i` of `M`, so
/// `w_i = q_i + (M z)_i <= q_i < 0` for every `z >= 0`.
fn infeasible_row(m: &[f64], q: &[f64]) -> Option<usize> {
    let n = q.len();
    (0..n).find(|&i| q[i] < 0.0 && m[i * n..(i + 1) * n].iter().all(|&v| v <= 0.0))
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
///
/// The revised form: the tableau is never updated in place. Each pivot factors the current basis matrix
/// from the original data and solves for the basic solution and the entering column, so rounding errors do
/// not accumulate over the thousands of pivots of Murty's family or through nearly singular `M`.
fn lemke_lcp(m: &[f64], q: &[f64], max_pivots: usize, covering: &[f64]) -> Attempt {
    let n = q.len();
    if q.iter().all(|&v| v >= 0.0) {
        return Attempt::Solved(vec![0.0; n], 0, true);
    }
    // Row i of the system: w~_i - s_i (M z)_i - z0 = s_i q_i with w~_i = s_i w_i, i.e. covering vector d_i = 1 / s_i, the
    // row's largest entry times `covering[i]`. Variables: w (0..n), z (n..2n), z0 (2n).
    let s: Vec<f64> = (0..n)
        .map(|i| {
            let r = m[i * n..(i + 1) * n]
                .iter()
                .fold(q[i].abs(), |a, v| a.max(v.abs()));
            row_scale(r) / covering[i]
        })
        .collect();
    let z0 = 2 * n;
    let column = |var: usize, out: &mut [f64]| {
        for i in 0..n {
            // The slack of row i is the scaled w~_i = s_i w_i, so that every basic value is in the same units.
            out[i] = if var < n {
                if i == var { 1.0 } else { 0.0 }
            } else if var < 2 * n {
                -s[i] * m[i * n + (var - n)]
            } else {
                -1.0
            };
        }
    };
    let rhs: Vec<f64> = (0..n).map(|i| s[i] * q[i]).collect();
    let mut basis: Vec<usize> = (0..n).collect();
    let mut lu = DenseLu::new(n, LinearSolver::Hand);
    let mut b = vec![0.0; n * n];
    let mut col = vec![0.0; n];
    let mut x = vec![0.0; n];
    let mut a = vec![0.0; n];
    // The basis is factored from the original data every `REFACTOR` pivots (or after a small pivot); the
    // pivots in between are kept in product form, one eta column each
    // (O(n) to apply), so that some n pivots cost O(n^3) in all rather than a factorisation each, O(n^4).
    let mut etas: Vec<(usize, Vec<f64>)> = Vec::new();
    let mut since_refactor = usize::MAX;
    let mut entering = z0;
    let mut pivots = 0;
    let mut seen = std::collections::HashSet::new();
    loop {
        if since_refactor >= REFACTOR {
            for (r, &var) in basis.iter().enumerate() {
                column(var, &mut col);
                for i in 0..n {
                    b[i * n + r] = col[i];
                }
            }
            if lu.factor(&b).is_err() {
                // A singular basis only arises from rounding; let the caller retry with another covering
                // vector.
                return Attempt::Breakdown(pivots);
            }
            etas.clear();
            since_refactor = 0;
        }
        x.copy_from_slice(&rhs);
        solve_basis(&mut lu, &etas, &mut x);
        if !x.iter().all(|v| v.is_finite()) {
            return Attempt::Breakdown(pivots);
        }
        // Basic values at rounding level are degenerate zeros: make them exact, so that the ratio ties they
        // create go to the lexicographic rule instead of to noise (which can cycle).
        let x_max = x.iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
        for v in x.iter_mut() {
            if v.abs() <= 1e-13 * x_max.max(1.0) {
                *v = 0.0;
            }
        }
        column(entering, &mut a);
        solve_basis(&mut lu, &etas, &mut a);
        if !a.iter().all(|v| v.is_finite()) {
            return Attempt::Breakdown(pivots);
        }
        // The first pivot (z0 entering) blocks where the scaled q is most negative; later pivots by the
        // minimum ratio x_i / a_i over a_i > 0. Ties go to the lexicographic rule on rows of B^-1.
        let first = entering == z0 && pivots == 0;
        let sign = if first { -1.0 } else { 1.0 };
        let a_max = a.iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
        let tol = 1e-12 * a_max.max(1.0);
        let eligible: Vec<usize> = (0..n)
            .filter(|&i| if first { a[i] < 0.0 } else { a[i] > tol })
            .collect();
        if eligible.is_empty() {
            return Attempt::Ray(pivots);
        }
        let ratio = |i: usize| x[i] / (sign * a[i]);
        let best = eligible
            .iter()
            .map(|&i| ratio(i))
            .fold(f64::INFINITY, f64::min);
        let near = |v: f64| (v - best).abs() <= 1e-13 * best.abs().max(1e-300);
        let mut ties: Vec<usize> = eligible
            .iter()
            .copied()
            .filter(|&i| near(ratio(i)))
            .collect();
        if ties.len() > 1 {
            // The lexicographic rule reads the tied rows of B^-1: each by one transposed solve through
            // the pivots kept in product form and the factors (O(n^2) a row), never all of B^-1. (Column
            // by column would cost a solve per column, and degenerate slacks tie for some n columns.)
            let rows: Vec<Vec<f64>> = ties
                .iter()
                .map(|&i| {
                    let mut y = vec![0.0; n];
                    y[i] = 1.0;
                    basis_row(&mut lu, &etas, &mut y);
                    y
                })
                .collect();
            let mut alive: Vec<usize> = (0..ties.len()).collect();
            for k in 0..n {
                let key = |t: usize| rows[t][k] / (sign * a[ties[t]]);
                let least = alive.iter().map(|&t| key(t)).fold(f64::INFINITY, f64::min);
                let scale = alive.iter().map(|&t| key(t).abs()).fold(0.0f64, f64::max);
                alive.retain(|&t| key(t) - least <= 1e-11 * scale.max(1e-300));
                if alive.len() <= 1 {
                    break;
                }
            }
            ties = alive.iter().map(|&t| ties[t]).collect();
        }
        // Rounding can leave no row within the tolerance of the minimum (a NaN ratio, a tie rule that
        // drops every row): a breakdown of this attempt, never a panic.
        let Some(&row) = ties.first() else {
            return Attempt::Breakdown(pivots);
        };
        let left = basis[row];
        basis[row] = entering;
        pivots += 1;
        // The pivot in product form: a small one (against its column) asks for a fresh factorisation.
        since_refactor += 1;
        if a[row].abs() < 1e-8 * a_max {
            since_refactor = REFACTOR;
        }
        etas.push((row, a.clone()));
        // The lexicographic rule cannot cycle in exact arithmetic; rounding can make it. A basis seen before
        // (with the same entering variable) means a cycle.
        let mut key = basis.clone();
        key.sort_unstable();
        key.push(left);
        // Only a hash of each basis is kept (8 bytes a pivot, whatever n).
        let key = {
            use std::hash::{Hash, Hasher};
            let mut hasher = std::collections::hash_map::DefaultHasher::new();
            key.hash(&mut hasher);
            hasher.finish()
        };
        if !seen.insert(key) {
            return Attempt::Breakdown(pivots);
        }
        if left == z0 {
            break;
        }
        if pivots >= max_pivots {
            let z = basic_z(&basis, &mut lu, &mut b, &column, &rhs, n);
            return Attempt::Solved(z, pivots, false);
        }
        entering = if left < n { left + n } else { left - n };
    }
    let z = basic_z(&basis, &mut lu, &mut b, &column, &rhs, n);
    Attempt::Solved(refine(m, q, &basis, z), pivots, true)
}

/// Pivots between two factorisations of the basis from the original data.
const REFACTOR: usize = 32;

/// `B^-1 v` in place, with `B` the factored basis followed by the pivots `etas` (each the pivot row and
/// the entering column in the basis before it).
fn solve_basis(lu: &mut DenseLu, etas: &[(usize, Vec<f64>)], v: &mut [f64]) {
    lu.solve(v);
    for (row, a) in etas {
        let pivot = v[*row] / a[*row];
        for (i, (e, ai)) in v.iter_mut().zip(a).enumerate() {
            if i == *row {
                *e = pivot;
            } else {
                *e -= ai * pivot;
            }
        }
    }
}

/// Row `i` of `B^-1` in place of `y = e_i`, with `B` the factored basis followed by the pivots `etas`:
/// `e_i^T E_k ... E_1 B_0^-1`, the etas' transposes applied last to first, then `B_0^-T`.
fn basis_row(lu: &mut DenseLu, etas: &[(usize, Vec<f64>)], y: &mut [f64]) {
    for (row, a) in etas.iter().rev() {
        let others: f64 = y
            .iter()
            .zip(a)
            .enumerate()
            .filter(|(j, _)| j != row)
            .map(|(_, (yj, aj))| yj * aj)
            .sum();
        y[*row] = (y[*row] - others) / a[*row];
    }
    lu.solve_transposed(y);
}

/// How one run of Lemke's method ended.
enum Attempt {
    /// `z`, pivots, and whether `z0` left the basis (false: the pivot limit came first).
    Solved(Vec<f64>, usize, bool),
    /// No blocking row: a secondary ray.
    Ray(usize),
    /// A singular basis or a cycle, both from rounding.
    Breakdown(usize),
}

/// The `z` part of the basic solution of `basis` (zero where the basis matrix is singular).
fn basic_z(
    basis: &[usize],
    lu: &mut DenseLu,
    b: &mut [f64],
    column: &impl Fn(usize, &mut [f64]),
    rhs: &[f64],
    n: usize,
) -> Vec<f64> {
    let mut col = vec![0.0; n];
    for (r, &var) in basis.iter().enumerate() {
        column(var, &mut col);
        for i in 0..n {
            b[i * n + r] = col[i];
        }
    }
    let mut z = vec![0.0; n];
    if lu.factor(b).is_err() {
        return z;
    }
    let mut x = rhs.to_vec();
    lu.solve(&mut x);
    for (r, &var) in basis.iter().enumerate() {
        if (n..2 * n).contains(&var) {
            z[var - n] = x[r].max(0.0);
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
    if lu.factor(&a).is_err() {
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

/// `max_i |min(z_i, w_i / r_i)|` with `r_i` the largest entry of row `i` of `[M q]` (at least the
/// smallest normal number), or infinity if `w` is not finite.
fn equilibrated_residual(m: &[f64], q: &[f64], z: &[f64]) -> f64 {
    let n = q.len();
    (0..n).fold(0.0f64, |r, i| {
        let row = &m[i * n..(i + 1) * n];
        let scale = row
            .iter()
            .fold(q[i].abs(), |a, v| a.max(v.abs()))
            .max(f64::MIN_POSITIVE);
        let w = q[i] + (0..n).map(|j| row[j] * z[j]).sum::<f64>();
        if w.is_finite() {
            r.max((w / scale).min(z[i]).abs())
        } else {
            f64::INFINITY
        }
    })
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
            if lu.factor(&mat).is_err() {
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
