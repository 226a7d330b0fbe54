//! Exact references for linear problems: Lemke's complementary pivoting method with lexicographic
//! (degeneracy-safe) ratio tests, and the enumeration of active sets for small problems.
//!
//! Lemke's method solves `0 <= z _|_ w = M z + q >= 0` for every `q` when `M` is a P-matrix, and for
//! copositive-plus `M` (positive semi-definite included) it either solves the LCP or proves that it has no
//! solution (Cottle, Pang and Stone, "The Linear Complementarity Problem", 4.4). Rows are equilibrated first
//! (a positive row scaling changes neither the solutions nor `z`), and the final basis is refined by one
//! solve of its linear system with the original data, so the answer is exact to rounding.

use crate::dense::{DenseLu, LinearSolver, inf_norm, sized};
use crate::error::NcpError;
use crate::problem::{FreeBlock, LinearMcp, Mcp, Reduced};
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
    let mut z = vec![0.0; problem.dim()];
    let mut work = LemkeWorkspace::default();
    let info = lemke_in_place(problem, settings, &mut work, &mut z)?;
    Ok(Solution { w: work.w, z, info })
}

/// Lemke's working storage: the reduced problem, the basis and its factors, the pivots kept in product
/// form, the ratio test's ties, the final refinement. Kept between solves ([`lemke_in_place`]), it makes a
/// solve allocate nothing once it has seen the problem's size (a hard step's data keeps one).
#[derive(Debug, Default)]
pub struct LemkeWorkspace {
    reduced: Reduced,
    /// The free block's factors.
    free: FreeBlock,
    covering: Vec<f64>,
    /// The best answer so far and one attempt's.
    best: Vec<f64>,
    lambda: Vec<f64>,
    attempt: AttemptScratch,
    /// `w = M z + q` of the answer.
    w: Vec<f64>,
}

/// [`lemke`] in `work`, the answer written into `z` (the problem's size; its entries are not read): the
/// same answer, to the last bit, without allocating once `work` has seen a problem of this size.
pub fn lemke_in_place(
    problem: &LinearMcp,
    settings: &LemkeSettings,
    work: &mut LemkeWorkspace,
    z: &mut [f64],
) -> Result<Info, NcpError> {
    settings.validate()?;
    let rows = problem.dim() - problem.n_free();
    if rows > settings.max_size {
        return Err(NcpError::TooLarge {
            method: "Lemke's method",
            rows,
            max: settings.max_size,
        });
    }
    if z.len() != problem.dim() {
        return Err(NcpError::Dimension {
            what: "z",
            got: z.len(),
            expected: problem.dim(),
        });
    }
    let LemkeWorkspace {
        reduced,
        free,
        covering,
        best,
        lambda,
        attempt: scratch,
        w,
    } = work;
    problem.reduce_into(reduced, free)?;
    let (m, q) = (&reduced.a[..], &reduced.b[..]);
    // Ray termination proves infeasibility in exact arithmetic; in floating point a nearly singular M can
    // end on a ray that does not exist. Before saying "infeasible", retry with other covering vectors (the
    // row scales, then ones, then seeded random multiples of them).
    let c = q.len();
    if let Some(row) = infeasible_row(m, q) {
        return Err(NcpError::InfeasibleRow { row, q: q[row] });
    }
    // Judged row by row in the equilibrated problem (each row divided by its largest entry), so that a
    // row scaled by 1e-8 is held to the same standard as one scaled by 1e8.
    let accuracy = 1e-10;
    let mut total = 0;
    let mut rays = 0;
    // The best answer so far (in `best`): (residual, finished).
    let mut found: Option<(f64, bool)> = None;
    for attempt in 0..4u64 {
        covering.clear();
        match attempt {
            0 => covering.resize(c, 1.0),
            1 => {
                // d = 1: undo the row scale.
                covering.extend((0..c).map(|i| {
                    let r = m[i * c..(i + 1) * c]
                        .iter()
                        .fold(q[i].abs(), |s, v| s.max(v.abs()));
                    row_scale(r)
                }));
            }
            _ => {
                let mut rng = crate::rng::SplitMix64::new(attempt);
                covering.extend((0..c).map(|_| rng.uniform(0.5, 2.0)));
            }
        }
        match lemke_lcp(m, q, settings.max_pivots, covering, scratch, lambda) {
            Attempt::Solved(pivots, finished) => {
                total += pivots;
                let residual = equilibrated_residual(m, q, lambda);
                let good = residual <= accuracy;
                if found.is_none_or(|b| residual < b.0) {
                    found = Some((residual, finished));
                    std::mem::swap(best, lambda);
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
    let Some((residual, finished)) = found else {
        // Every attempt ended on a ray (or broke down): report infeasibility only if one saw a ray.
        return Err(if rays > 0 {
            NcpError::Infeasible { pivots: total }
        } else {
            NcpError::Unsupported("Lemke's method broke down numerically on every covering vector")
        });
    };
    reduced.expand_into(best, z);
    w.clear();
    w.resize(z.len(), 0.0);
    problem.evaluate(z, w, None);
    let status = if !finished {
        Status::MaxIterations
    } else if residual <= accuracy {
        Status::Converged
    } else {
        Status::Inaccurate
    };
    Ok(Info {
        status,
        iterations: total,
        residual: complementarity_residual(problem.n_free(), z, w),
        evaluations: 1,
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

/// One attempt's working storage ([`lemke_lcp`]).
#[derive(Debug, Default)]
struct AttemptScratch {
    /// Row scales, the scaled right-hand side, the basis.
    s: Vec<f64>,
    rhs: Vec<f64>,
    basis: Vec<usize>,
    /// The basis matrix, its factors, a column, the basic solution and the entering column.
    lu: Option<DenseLu>,
    b: Vec<f64>,
    col: Vec<f64>,
    x: Vec<f64>,
    a: Vec<f64>,
    /// The pivots since the last factorisation in product form: each one's row and entering column.
    eta_rows: Vec<usize>,
    eta_columns: Vec<f64>,
    /// Hashes of the bases seen (with their leaving variable), and the sorted basis being hashed.
    seen: std::collections::HashSet<u64>,
    key: Vec<usize>,
    /// The ratio test's eligible rows, its ties, the tied rows of `B^-1` and the ties still alive.
    eligible: Vec<usize>,
    ties: Vec<usize>,
    tie_rows: Vec<f64>,
    alive: Vec<usize>,
    /// The refinement's support, system and answer, and its factors by support size.
    support: Vec<usize>,
    system: Vec<f64>,
    solution: Vec<f64>,
    refined: Vec<f64>,
    refine_lu: Vec<Option<DenseLu>>,
}

/// Lemke on a plain LCP (row-major `m`), its `z` written into `z` (resized to `q`'s length); returns the
/// pivot count and whether it finished.
///
/// The revised form: the tableau is never updated in place. Each pivot factors the current basis matrix
/// from the original data and solves for the basic solution and the entering column, so rounding errors do
/// not accumulate over the thousands of pivots of Murty's family or through nearly singular `M`.
fn lemke_lcp(
    m: &[f64],
    q: &[f64],
    max_pivots: usize,
    covering: &[f64],
    scratch: &mut AttemptScratch,
    z: &mut Vec<f64>,
) -> Attempt {
    let n = q.len();
    z.clear();
    z.resize(n, 0.0);
    if q.iter().all(|&v| v >= 0.0) {
        return Attempt::Solved(0, true);
    }
    let AttemptScratch {
        s,
        rhs,
        basis,
        lu,
        b,
        col,
        x,
        a,
        eta_rows,
        eta_columns,
        seen,
        key,
        eligible,
        ties,
        tie_rows,
        alive,
        support,
        system,
        solution,
        refined,
        refine_lu,
    } = scratch;
    // Row i of the system: w~_i - s_i (M z)_i - z0 = s_i q_i with w~_i = s_i w_i, i.e. covering vector d_i = 1 / s_i, the
    // row's largest entry times `covering[i]`. Variables: w (0..n), z (n..2n), z0 (2n).
    s.clear();
    s.extend((0..n).map(|i| {
        let r = m[i * n..(i + 1) * n]
            .iter()
            .fold(q[i].abs(), |a, v| a.max(v.abs()));
        row_scale(r) / covering[i]
    }));
    let s = &s[..];
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
    rhs.clear();
    rhs.extend((0..n).map(|i| s[i] * q[i]));
    basis.clear();
    basis.extend(0..n);
    let lu = sized(lu, n);
    b.clear();
    b.resize(n * n, 0.0);
    for v in [&mut *col, &mut *x, &mut *a] {
        v.clear();
        v.resize(n, 0.0);
    }
    // The basis is factored from the original data every `REFACTOR` pivots (or after a small pivot); the
    // pivots in between are kept in product form, one eta column each
    // (O(n) to apply), so that some n pivots cost O(n^3) in all rather than a factorisation each, O(n^4).
    eta_rows.clear();
    eta_columns.clear();
    let mut since_refactor = usize::MAX;
    let mut entering = z0;
    let mut pivots = 0;
    seen.clear();
    loop {
        if since_refactor >= REFACTOR {
            for (r, &var) in basis.iter().enumerate() {
                column(var, col);
                for i in 0..n {
                    b[i * n + r] = col[i];
                }
            }
            if lu.factor(b).is_err() {
                // A singular basis only arises from rounding; let the caller retry with another covering
                // vector.
                return Attempt::Breakdown(pivots);
            }
            eta_rows.clear();
            eta_columns.clear();
            since_refactor = 0;
        }
        x.copy_from_slice(rhs);
        solve_basis(lu, eta_rows, eta_columns, x);
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
        column(entering, a);
        solve_basis(lu, eta_rows, eta_columns, a);
        if !a.iter().all(|v| v.is_finite()) {
            return Attempt::Breakdown(pivots);
        }
        // The first pivot (z0 entering) blocks where the scaled q is most negative; later pivots by the
        // minimum ratio x_i / a_i over a_i > 0. Ties go to the lexicographic rule on rows of B^-1.
        let first = entering == z0 && pivots == 0;
        let sign = if first { -1.0 } else { 1.0 };
        let a_max = a.iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
        let tol = 1e-12 * a_max.max(1.0);
        eligible.clear();
        eligible.extend((0..n).filter(|&i| if first { a[i] < 0.0 } else { a[i] > tol }));
        if eligible.is_empty() {
            return Attempt::Ray(pivots);
        }
        let ratio = |i: usize| x[i] / (sign * a[i]);
        let best = eligible
            .iter()
            .map(|&i| ratio(i))
            .fold(f64::INFINITY, f64::min);
        let near = |v: f64| (v - best).abs() <= 1e-13 * best.abs().max(1e-300);
        ties.clear();
        ties.extend(eligible.iter().copied().filter(|&i| near(ratio(i))));
        if ties.len() > 1 {
            // The lexicographic rule reads the tied rows of B^-1: each by one transposed solve through
            // the pivots kept in product form and the factors (O(n^2) a row), never all of B^-1. (Column
            // by column would cost a solve per column, and degenerate slacks tie for some n columns.)
            tie_rows.clear();
            tie_rows.resize(ties.len() * n, 0.0);
            for (t, y) in tie_rows.chunks_exact_mut(n).enumerate() {
                y[ties[t]] = 1.0;
                basis_row(lu, eta_rows, eta_columns, y);
            }
            alive.clear();
            alive.extend(0..ties.len());
            for k in 0..n {
                let key = |t: usize| tie_rows[t * n + k] / (sign * a[ties[t]]);
                let least = alive.iter().map(|&t| key(t)).fold(f64::INFINITY, f64::min);
                let scale = alive.iter().map(|&t| key(t).abs()).fold(0.0f64, f64::max);
                alive.retain(|&t| key(t) - least <= 1e-11 * scale.max(1e-300));
                if alive.len() <= 1 {
                    break;
                }
            }
            // The survivors, in order (each at or after its own place).
            for (k, &t) in alive.iter().enumerate() {
                ties[k] = ties[t];
            }
            ties.truncate(alive.len());
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
        eta_rows.push(row);
        eta_columns.extend_from_slice(a);
        // The lexicographic rule cannot cycle in exact arithmetic; rounding can make it. A basis seen before
        // (with the same entering variable) means a cycle.
        key.clear();
        key.extend_from_slice(basis);
        key.sort_unstable();
        key.push(left);
        // Only a hash of each basis is kept (8 bytes a pivot, whatever n).
        let hash = {
            use std::hash::{Hash, Hasher};
            let mut hasher = std::collections::hash_map::DefaultHasher::new();
            key.hash(&mut hasher);
            hasher.finish()
        };
        if !seen.insert(hash) {
            return Attempt::Breakdown(pivots);
        }
        if left == z0 {
            break;
        }
        if pivots >= max_pivots {
            basic_z(basis, lu, b, &column, rhs, col, x, z);
            return Attempt::Solved(pivots, false);
        }
        entering = if left < n { left + n } else { left - n };
    }
    basic_z(basis, lu, b, &column, rhs, col, x, z);
    let refine = Refinement {
        support,
        system,
        solution,
        refined,
        lus: refine_lu,
    };
    refine.run(m, q, basis, z);
    Attempt::Solved(pivots, true)
}

/// Pivots between two factorisations of the basis from the original data.
const REFACTOR: usize = 32;

/// `B^-1 v` in place, with `B` the factored basis followed by the pivots in product form (row `rows[k]`
/// and the entering column `columns[k n..(k + 1) n]` in the basis before it).
fn solve_basis(lu: &mut DenseLu, rows: &[usize], columns: &[f64], v: &mut [f64]) {
    lu.solve(v);
    let n = v.len();
    for (&row, a) in rows.iter().zip(columns.chunks_exact(n.max(1))) {
        let pivot = v[row] / a[row];
        for (i, (e, ai)) in v.iter_mut().zip(a).enumerate() {
            if i == row {
                *e = pivot;
            } else {
                *e -= ai * pivot;
            }
        }
    }
}

/// Row `i` of `B^-1` in place of `y = e_i`, with `B` the factored basis followed by the pivots in product
/// form: `e_i^T E_k ... E_1 B_0^-1`, the pivots' transposes applied last to first, then `B_0^-T`.
fn basis_row(lu: &mut DenseLu, rows: &[usize], columns: &[f64], y: &mut [f64]) {
    let n = y.len();
    for (&row, a) in rows.iter().zip(columns.chunks_exact(n.max(1))).rev() {
        let others: f64 = y
            .iter()
            .zip(a)
            .enumerate()
            .filter(|(j, _)| *j != row)
            .map(|(_, (yj, aj))| yj * aj)
            .sum();
        y[row] = (y[row] - others) / a[row];
    }
    lu.solve_transposed(y);
}

/// How one run of Lemke's method ended.
enum Attempt {
    /// Pivots, and whether `z0` left the basis (false: the pivot limit came first); `z` is written.
    Solved(usize, bool),
    /// No blocking row: a secondary ray.
    Ray(usize),
    /// A singular basis or a cycle, both from rounding.
    Breakdown(usize),
}

/// The `z` part of the basic solution of `basis` into `z` (zero where the basis matrix is singular), with
/// `b`, `col` and `x` as scratch.
#[allow(clippy::too_many_arguments)]
fn basic_z(
    basis: &[usize],
    lu: &mut DenseLu,
    b: &mut [f64],
    column: &impl Fn(usize, &mut [f64]),
    rhs: &[f64],
    col: &mut [f64],
    x: &mut [f64],
    z: &mut [f64],
) {
    let n = rhs.len();
    for (r, &var) in basis.iter().enumerate() {
        column(var, col);
        for i in 0..n {
            b[i * n + r] = col[i];
        }
    }
    z.fill(0.0);
    if lu.factor(b).is_err() {
        return;
    }
    x.copy_from_slice(rhs);
    lu.solve(x);
    for (r, &var) in basis.iter().enumerate() {
        if (n..2 * n).contains(&var) {
            z[var - n] = x[r].max(0.0);
        }
    }
}

/// The final refinement's scratch: re-solve `M_SS z_S = -q_S` on the final support `S` with the original
/// data, and keep the result if it is at least as complementary as the tableau's.
struct Refinement<'a> {
    support: &'a mut Vec<usize>,
    system: &'a mut Vec<f64>,
    solution: &'a mut Vec<f64>,
    refined: &'a mut Vec<f64>,
    /// Factors by support size (a step's support changes as contacts open and close).
    lus: &'a mut Vec<Option<DenseLu>>,
}

impl Refinement<'_> {
    fn run(self, m: &[f64], q: &[f64], basis: &[usize], z: &mut [f64]) {
        let n = q.len();
        self.support.clear();
        self.support.extend(
            basis
                .iter()
                .filter(|&&b| (n..2 * n).contains(&b))
                .map(|b| b - n),
        );
        let support = &self.support[..];
        let k = support.len();
        if k == 0 {
            return;
        }
        let (a, x) = (&mut *self.system, &mut *self.solution);
        a.clear();
        a.resize(k * k, 0.0);
        x.clear();
        x.resize(k, 0.0);
        for (r, &i) in support.iter().enumerate() {
            for (c, &j) in support.iter().enumerate() {
                a[r * k + c] = m[i * n + j];
            }
            x[r] = -q[i];
        }
        if self.lus.len() <= k {
            self.lus.resize_with(k + 1, || None);
        }
        let lu = sized(&mut self.lus[k], k);
        if lu.factor(a).is_err() {
            return;
        }
        lu.solve(x);
        let refined = &mut *self.refined;
        refined.clear();
        refined.resize(n, 0.0);
        for (r, &i) in support.iter().enumerate() {
            refined[i] = x[r].max(0.0);
        }
        if lcp_residual(m, q, refined) <= lcp_residual(m, q, z) {
            z.copy_from_slice(refined);
        }
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
