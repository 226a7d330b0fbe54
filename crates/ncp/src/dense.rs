//! Small dense LU factorisation with partial pivoting, in two interchangeable back ends: faer's in-place
//! factorisation (with a workspace allocated once) and a hand-written loop over a row-major slice.
//!
//! At the scene's sizes (6 to 12 unknowns) a whole Newton solve takes a couple of microseconds, so the
//! per-call cost of the factorisation matters; `cargo xtask benchmarks` and `cargo bench -p ncp` measure
//! both back ends and docs/benchmarks.md shows the result that picked the default.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::{Mat, Par};
use serde::{Deserialize, Serialize};

/// Why a matrix could not be factored.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FactorError {
    /// The matrix has the wrong number of entries for this workspace.
    #[error("the matrix has {len} entries; a {n} x {n} factorisation needs {}", n * n)]
    Shape {
        /// Entries given.
        len: usize,
        /// The workspace's size.
        n: usize,
    },
    /// An entry is NaN or infinite.
    #[error("the matrix has a non-finite entry")]
    NonFinite,
    /// Singular to working precision: elimination step `column`'s largest available pivot is below
    /// `threshold` (`n eps max|a|`).
    #[error("singular to working precision: pivot {column} is {pivot:e}, below {threshold:e}")]
    Singular {
        /// The elimination step (column) that failed.
        column: usize,
        /// The largest pivot available there (its magnitude).
        pivot: f64,
        /// The smallest pivot accepted.
        threshold: f64,
    },
}

/// Which dense LU implementation a solver uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LinearSolver {
    /// Hand-written partial-pivoting LU on a row-major buffer (the default: cheaper below ~20 unknowns).
    #[default]
    Hand,
    /// faer's `lu_in_place` and `solve_in_place`, sequential, with a preallocated workspace.
    Faer,
}

/// A reusable LU factorisation of an `n x n` matrix.
pub struct DenseLu {
    n: usize,
    backend: Backend,
}

impl std::fmt::Debug for DenseLu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kind = match self.backend {
            Backend::Hand { .. } => LinearSolver::Hand,
            Backend::Faer { .. } => LinearSolver::Faer,
        };
        f.debug_struct("DenseLu")
            .field("n", &self.n)
            .field("backend", &kind)
            .finish()
    }
}

enum Backend {
    Hand {
        lu: Vec<f64>,
        perm: Vec<usize>,
        /// A copy of the right-hand sides of [`DenseLu::solve_many`] (grown to the largest seen).
        copy: Vec<f64>,
    },
    Faer {
        lu: Mat<f64>,
        perm: Vec<usize>,
        perm_inv: Vec<usize>,
        rhs: Mat<f64>,
        buffer: MemBuffer,
    },
}

/// The hand-written factors workspace in `slot` for `n x n` matrices, made when it holds none of that size
/// (kept by a caller that factors matrices of one size over and over).
pub(crate) fn sized(slot: &mut Option<DenseLu>, n: usize) -> &mut DenseLu {
    if slot.as_ref().is_none_or(|l| l.dim() != n) {
        *slot = Some(DenseLu::new(n, LinearSolver::Hand));
    }
    slot.as_mut().expect("made above")
}

impl DenseLu {
    /// Workspace for `n x n` matrices with the chosen back end.
    pub fn new(n: usize, solver: LinearSolver) -> Self {
        let backend = match solver {
            LinearSolver::Hand => Backend::Hand {
                lu: vec![0.0; n * n],
                perm: (0..n).collect(),
                copy: Vec::new(),
            },
            LinearSolver::Faer => {
                let req =
                    factor::lu_in_place_scratch::<usize, f64>(n, n, Par::Seq, Default::default())
                        .or(solve::solve_in_place_scratch::<usize, f64>(n, 1, Par::Seq))
                        .or(solve::solve_transpose_in_place_scratch::<usize, f64>(
                            n,
                            1,
                            Par::Seq,
                        ));
                Backend::Faer {
                    lu: Mat::zeros(n, n),
                    perm: vec![0; n],
                    perm_inv: vec![0; n],
                    rhs: Mat::zeros(n, 1),
                    buffer: MemBuffer::new(req),
                }
            }
        };
        DenseLu { n, backend }
    }

    /// The size this workspace factors.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Factor the row-major `n x n` matrix `a`. An error when it is singular to working precision (a
    /// pivot below `n eps max|a|`: the failing column and pivot), has a non-finite entry, or has the wrong
    /// size; the factorisation is then unusable.
    pub fn factor(&mut self, a: &[f64]) -> Result<(), FactorError> {
        let n = self.n;
        if a.len() != n * n {
            return Err(FactorError::Shape { len: a.len(), n });
        }
        // The largest magnitude and whether every entry is finite, in one branch-free pass.
        let (scale, finite) = a.iter().fold((0.0f64, true), |(m, ok), v| {
            let e = v.abs();
            (if e > m { e } else { m }, ok & (e <= f64::MAX))
        });
        if !finite {
            return Err(FactorError::NonFinite);
        }
        let tiny = (n as f64) * f64::EPSILON * scale;
        match &mut self.backend {
            Backend::Hand { lu, perm, .. } => {
                lu.copy_from_slice(a);
                for (i, p) in perm.iter_mut().enumerate() {
                    *p = i;
                }
                // The scenes' sizes get a copy of the loop compiled for their size (no bounds checks,
                // unrolled rows); any other size runs the same elimination on run-time lengths.
                match n {
                    4 => eliminate_fixed::<4>(lu, perm, tiny),
                    5 => eliminate_fixed::<5>(lu, perm, tiny),
                    6 => eliminate_fixed::<6>(lu, perm, tiny),
                    7 => eliminate_fixed::<7>(lu, perm, tiny),
                    8 => eliminate_fixed::<8>(lu, perm, tiny),
                    9 => eliminate_fixed::<9>(lu, perm, tiny),
                    10 => eliminate_fixed::<10>(lu, perm, tiny),
                    11 => eliminate_fixed::<11>(lu, perm, tiny),
                    12 => eliminate_fixed::<12>(lu, perm, tiny),
                    13 => eliminate_fixed::<13>(lu, perm, tiny),
                    14 => eliminate_fixed::<14>(lu, perm, tiny),
                    15 => eliminate_fixed::<15>(lu, perm, tiny),
                    16 => eliminate_fixed::<16>(lu, perm, tiny),
                    17 => eliminate_fixed::<17>(lu, perm, tiny),
                    18 => eliminate_fixed::<18>(lu, perm, tiny),
                    _ => eliminate(lu, perm, n, tiny),
                }
            }
            Backend::Faer {
                lu,
                perm,
                perm_inv,
                buffer,
                ..
            } => {
                for i in 0..n {
                    for j in 0..n {
                        lu[(i, j)] = a[i * n + j];
                    }
                }
                let stack = MemStack::new(buffer);
                factor::lu_in_place(
                    lu.as_mut(),
                    perm,
                    perm_inv,
                    Par::Seq,
                    stack,
                    Default::default(),
                );
                match (0..n).find(|&k| {
                    let u = lu[(k, k)];
                    !(u.is_finite() && u.abs() > tiny)
                }) {
                    None => Ok(()),
                    Some(k) => Err(FactorError::Singular {
                        column: k,
                        pivot: lu[(k, k)].abs(),
                        threshold: tiny,
                    }),
                }
            }
        }
    }

    /// The faer back end's solve of `a x = rhs` or `a^T x = rhs` in place.
    fn faer_solve(&mut self, rhs: &mut [f64], transposed: bool) {
        let n = self.n;
        let Backend::Faer {
            lu,
            perm,
            perm_inv,
            rhs: b,
            buffer,
        } = &mut self.backend
        else {
            unreachable!("called for the faer back end only");
        };
        for i in 0..n {
            b[(i, 0)] = rhs[i];
        }
        let stack = MemStack::new(buffer);
        let p = faer::perm::PermRef::new_checked(perm, perm_inv, n);
        if transposed {
            solve::solve_transpose_in_place(
                lu.as_ref(),
                lu.as_ref(),
                p,
                b.as_mut(),
                Par::Seq,
                stack,
            );
        } else {
            solve::solve_in_place(lu.as_ref(), lu.as_ref(), p, b.as_mut(), Par::Seq, stack);
        }
        for i in 0..n {
            rhs[i] = b[(i, 0)];
        }
    }

    /// Overwrite `rhs` with the solution of `a^T y = rhs` for the last matrix factored successfully (the
    /// adjoint systems of the dynamics' second derivatives reuse the factors of the forward one).
    pub fn solve_transposed(&mut self, rhs: &mut [f64]) {
        let n = self.n;
        debug_assert_eq!(rhs.len(), n);
        match &mut self.backend {
            Backend::Hand { lu, perm, .. } => {
                // P a = L U, so a^T y = U^T L^T (P y): solve U^T w = rhs, L^T t = w, then y = P^T t.
                macro_rules! fixed {
                    ($($k:literal)*) => {
                        match n {
                            $($k => return transposed_sized::<$k>(lu, perm, rhs),)*
                            _ => {}
                        }
                    };
                }
                fixed!(4 5 6 7 8 9 10 11 12 13 14 15 16 17 18);
                transposed(lu, perm, rhs);
            }
            Backend::Faer { .. } => self.faer_solve(rhs, true),
        }
    }

    /// Overwrite the row-major `n x k` block `rhs` with the solutions of `a X = rhs` for its `k` columns at
    /// once (for the hand back end the columns' substitutions interleave, which hides the latency of one
    /// column's dependency chain: the derivatives of a step solve for eight right-hand sides).
    pub fn solve_many(&mut self, rhs: &mut [f64], k: usize) {
        let n = self.n;
        debug_assert_eq!(rhs.len(), n * k);
        match &mut self.backend {
            Backend::Hand { lu, perm, copy } => {
                // A copy of the right-hand sides (rows are read in pivot order), kept for the next
                // solve: no allocation once it has the largest size.
                copy.clear();
                copy.extend_from_slice(rhs);
                // The step derivatives' right-hand sides (states and controls) of the example scenes
                // get a copy compiled for their width (the finger's 8, the slider's 9, the three-link
                // finger's 11, two fingers' and pushing's 12, 14): the same arithmetic, each row's
                // update one unrolled block.
                match k {
                    8 => substitute_many::<8>(lu, perm, copy, rhs, n, k),
                    9 => substitute_many::<9>(lu, perm, copy, rhs, n, k),
                    11 => substitute_many::<11>(lu, perm, copy, rhs, n, k),
                    12 => substitute_many::<12>(lu, perm, copy, rhs, n, k),
                    14 => substitute_many::<14>(lu, perm, copy, rhs, n, k),
                    _ => substitute_many::<0>(lu, perm, copy, rhs, n, k),
                }
            }
            Backend::Faer { .. } => {
                let mut col = vec![0.0; n];
                for c in 0..k {
                    for i in 0..n {
                        col[i] = rhs[i * k + c];
                    }
                    self.solve(&mut col);
                    for i in 0..n {
                        rhs[i * k + c] = col[i];
                    }
                }
            }
        }
    }

    /// Overwrite `rhs` with the solution of `a x = rhs` for the last matrix factored successfully.
    pub fn solve(&mut self, rhs: &mut [f64]) {
        let n = self.n;
        debug_assert_eq!(rhs.len(), n);
        match &mut self.backend {
            Backend::Hand { lu, perm, .. } => {
                // Forward substitution on P b (unit lower), then back substitution.
                let mut x = [0.0f64; 32];
                if n <= 32 {
                    let x = &mut x[..n];
                    // The sizes `factor` compiles for, compiled here too.
                    macro_rules! fixed {
                        ($($k:literal)*) => {
                            match n {
                                $($k => substitute_sized::<$k>(lu, perm, rhs, x),)*
                                _ => substitute(lu, perm, rhs, x),
                            }
                        };
                    }
                    fixed!(4 5 6 7 8 9 10 11 12 13 14 15 16 17 18);
                    rhs.copy_from_slice(x);
                } else {
                    let mut x = vec![0.0; n];
                    substitute(lu, perm, rhs, &mut x);
                    rhs.copy_from_slice(&x);
                }
            }
            Backend::Faer { .. } => self.faer_solve(rhs, false),
        }
    }
}

/// Partial pivoting at elimination step `k`: the row (`k` or below) of the largest magnitude in
/// `column` (the magnitudes from row `k` down; the first of equals), or `Singular` when it is not above
/// `tiny`.
#[inline(always)]
fn pivot(k: usize, column: impl Iterator<Item = f64>, tiny: f64) -> Result<usize, FactorError> {
    let (mut p, mut best) = (k, f64::NEG_INFINITY);
    for (i, v) in (k..).zip(column) {
        if v > best || i == k {
            best = v;
            p = i;
        }
    }
    if !(best > tiny) {
        return Err(FactorError::Singular {
            column: k,
            pivot: best,
            threshold: tiny,
        });
    }
    Ok(p)
}

/// Gaussian elimination with partial pivoting of the row-major `n x n` matrix in `lu`, in place (`L`'s
/// multipliers below the diagonal, `U` on and above it), recording the row swaps in `perm`.
fn eliminate(lu: &mut [f64], perm: &mut [usize], n: usize, tiny: f64) -> Result<(), FactorError> {
    for k in 0..n {
        let p = pivot(k, (k..n).map(|i| lu[i * n + k].abs()), tiny)?;
        if p != k {
            let (top, bottom) = lu.split_at_mut(p * n);
            top[k * n..(k + 1) * n].swap_with_slice(&mut bottom[..n]);
            perm.swap(k, p);
        }
        // Eliminate below the pivot, row slices against the pivot row's tail.
        let (top, bottom) = lu.split_at_mut((k + 1) * n);
        let pivot_row = &top[k * n + k..(k + 1) * n];
        let inv = 1.0 / pivot_row[0];
        for row in bottom.chunks_exact_mut(n) {
            let tail = &mut row[k..];
            let l = tail[0] * inv;
            tail[0] = l;
            if l != 0.0 {
                for (r, u) in tail[1..].iter_mut().zip(&pivot_row[1..]) {
                    *r -= l * u;
                }
            }
        }
    }
    Ok(())
}

/// [`eliminate`] for `N x N`, the same arithmetic in the same order.
fn eliminate_fixed<const N: usize>(
    lu: &mut [f64],
    perm: &mut [usize],
    tiny: f64,
) -> Result<(), FactorError> {
    let (rows, _) = lu.as_chunks_mut::<N>();
    let rows: &mut [[f64; N]; N] = rows.try_into().expect("an N x N matrix");
    for k in 0..N {
        let p = pivot(k, rows[k..].iter().map(|row| row[k].abs()), tiny)?;
        if p != k {
            rows.swap(k, p);
            perm.swap(k, p);
        }
        let (top, bottom) = rows.split_at_mut(k + 1);
        let pivot_row = &top[k];
        let inv = 1.0 / pivot_row[k];
        for row in bottom.iter_mut() {
            let l = row[k] * inv;
            row[k] = l;
            if l != 0.0 {
                for j in k + 1..N {
                    row[j] -= l * pivot_row[j];
                }
            }
        }
    }
    Ok(())
}

/// [`DenseLu::solve_many`]'s substitutions for `K` right-hand sides when `K` is not 0 (else `k`): `b`
/// the right-hand sides as given, `rhs` their solutions.
fn substitute_many<const K: usize>(
    lu: &[f64],
    perm: &[usize],
    b: &[f64],
    rhs: &mut [f64],
    n: usize,
    k: usize,
) {
    let k = if K > 0 { K } else { k };
    for i in 0..n {
        let (done, rest) = rhs.split_at_mut(i * k);
        let xi = &mut rest[..k];
        xi.copy_from_slice(&b[perm[i] * k..(perm[i] + 1) * k]);
        for j in 0..i {
            let l = lu[i * n + j];
            for (x, xj) in xi.iter_mut().zip(&done[j * k..(j + 1) * k]) {
                *x -= l * xj;
            }
        }
    }
    for i in (0..n).rev() {
        let (head, rest) = rhs.split_at_mut((i + 1) * k);
        let xi = &mut head[i * k..(i + 1) * k];
        for j in i + 1..n {
            let u = lu[i * n + j];
            for (x, xj) in xi.iter_mut().zip(&rest[(j - i - 1) * k..(j - i) * k]) {
                *x -= u * xj;
            }
        }
        let inv = 1.0 / lu[i * n + i];
        for x in xi.iter_mut() {
            *x *= inv;
        }
    }
}

fn substitute(lu: &[f64], perm: &[usize], b: &[f64], x: &mut [f64]) {
    substitute_sized::<0>(lu, perm, b, x);
}

/// [`substitute`] for `N x N` when `N` is not 0 (else the pivots' length): one loop for both, the sizes
/// compiled in unrolled and without bounds checks, the same arithmetic in the same order.
fn substitute_sized<const N: usize>(lu: &[f64], perm: &[usize], b: &[f64], x: &mut [f64]) {
    let n = if N > 0 { N } else { perm.len() };
    let (lu, perm, b, x) = (&lu[..n * n], &perm[..n], &b[..n], &mut x[..n]);
    for i in 0..n {
        let mut s = b[perm[i]];
        for j in 0..i {
            s -= lu[i * n + j] * x[j];
        }
        x[i] = s;
    }
    for i in (0..n).rev() {
        let mut s = x[i];
        for j in i + 1..n {
            s -= lu[i * n + j] * x[j];
        }
        x[i] = s / lu[i * n + i];
    }
}

/// [`DenseLu::solve_transposed`]'s substitutions at any size.
fn transposed(lu: &[f64], perm: &[usize], rhs: &mut [f64]) {
    transposed_sized::<0>(lu, perm, rhs);
}

/// [`transposed`] for `N x N` when `N` is not 0 (else the pivots' length), as [`substitute_sized`].
fn transposed_sized<const N: usize>(lu: &[f64], perm: &[usize], rhs: &mut [f64]) {
    let n = if N > 0 { N } else { perm.len() };
    let (lu, perm, rhs) = (&lu[..n * n], &perm[..n], &mut rhs[..n]);
    let mut stack = [0.0f64; 32];
    let mut heap = Vec::new();
    let t: &mut [f64] = if n <= 32 {
        &mut stack[..n]
    } else {
        heap.resize(n, 0.0);
        &mut heap
    };
    for i in 0..n {
        let mut s = rhs[i];
        for j in 0..i {
            s -= lu[j * n + i] * t[j];
        }
        t[i] = s / lu[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = t[i];
        for j in i + 1..n {
            s -= lu[j * n + i] * t[j];
        }
        t[i] = s;
    }
    for i in 0..n {
        rhs[perm[i]] = t[i];
    }
}

/// The largest absolute entry of `v` (0 for an empty `v`): the solvers' residual and scale norm.
pub(crate) fn inf_norm(v: &[f64]) -> f64 {
    // A select rather than `f64::max`, whose NaN rule keeps the loop from vectorising; the same value
    // (a NaN entry is passed over by both, as the running maximum is never NaN).
    v.iter().fold(0.0f64, |m, x| {
        let a = x.abs();
        if a > m { a } else { m }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The residual norm's rule, which the solvers' stopping tests read: the largest magnitude, a NaN
    /// passed over (a NaN is caught by the finiteness checks, not by the norm), 0 for nothing.
    #[test]
    fn the_inf_norm_is_the_largest_magnitude_and_passes_over_nan() {
        assert_eq!(inf_norm(&[]), 0.0);
        assert_eq!(inf_norm(&[1.0, -3.0, 2.0]), 3.0);
        assert_eq!(inf_norm(&[f64::NAN, -0.5, f64::NAN]), 0.5);
        assert_eq!(inf_norm(&[2.0, f64::NEG_INFINITY]), f64::INFINITY);
        assert_eq!(inf_norm(&[-0.0]).to_bits(), 0.0f64.to_bits());
        let v: Vec<f64> = (0..37).map(|i| ((i * 7919) % 101) as f64 - 50.0).collect();
        assert_eq!(inf_norm(&v), v.iter().fold(0.0f64, |m, x| m.max(x.abs())));
    }

    /// Several right-hand sides at once (the widths compiled in) solve to the bit as the run-time loop
    /// does, and solve the system.
    #[test]
    fn compiled_widths_of_right_hand_sides_solve_to_the_bit_as_the_run_time_loop() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(8);
        for (n, k) in [
            (1usize, 8usize),
            (3, 8),
            (9, 8),
            (14, 8),
            (4, 11),
            (5, 12),
            (4, 9),
            (5, 14),
        ] {
            let a: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let b: Vec<f64> = (0..n * k).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut lu = DenseLu::new(n, LinearSolver::Hand);
            lu.factor(&a).unwrap();
            let mut x = b.clone();
            lu.solve_many(&mut x, k);
            let Backend::Hand { lu: f, perm, .. } = &lu.backend else {
                unreachable!("the hand back end")
            };
            let mut general = b.clone();
            substitute_many::<0>(f, perm, &b, &mut general, n, k);
            assert_eq!(
                x.iter().map(|e| e.to_bits()).collect::<Vec<_>>(),
                general.iter().map(|e| e.to_bits()).collect::<Vec<_>>(),
                "n = {n}"
            );
            let residual = (0..n)
                .flat_map(|i| (0..k).map(move |c| (i, c)))
                .map(|(i, c)| {
                    let ax: f64 = (0..n).map(|j| a[i * n + j] * x[j * k + c]).sum();
                    (ax - b[i * k + c]).abs()
                })
                .fold(0.0, f64::max);
            assert!(residual < 1e-10, "n = {n}: {residual}");
        }
    }

    #[test]
    fn the_sizes_compiled_in_solve_to_the_bit_as_the_run_time_loops() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(29);
        for n in 1usize..=20 {
            let a: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let b: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut lu = DenseLu::new(n, LinearSolver::Hand);
            lu.factor(&a).unwrap();
            let Backend::Hand { lu: f, perm, .. } = &lu.backend else {
                unreachable!("the hand back end")
            };
            let (f, perm) = (f.clone(), perm.clone());
            let (mut x, mut general) = (b.clone(), vec![0.0; n]);
            lu.solve(&mut x);
            substitute(&f, &perm, &b, &mut general);
            assert_eq!(
                x.iter().map(|e| e.to_bits()).collect::<Vec<_>>(),
                general.iter().map(|e| e.to_bits()).collect::<Vec<_>>(),
                "solve, n = {n}"
            );
            let (mut y, mut general) = (b.clone(), b.clone());
            lu.solve_transposed(&mut y);
            transposed(&f, &perm, &mut general);
            assert_eq!(
                y.iter().map(|e| e.to_bits()).collect::<Vec<_>>(),
                general.iter().map(|e| e.to_bits()).collect::<Vec<_>>(),
                "transposed solve, n = {n}"
            );
        }
    }

    #[test]
    fn the_transposed_solve_solves_the_transposed_system() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(13);
        for n in [1usize, 2, 5, 9, 33] {
            let a: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let c: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            for solver in [LinearSolver::Hand, LinearSolver::Faer] {
                let mut lu = DenseLu::new(n, solver);
                lu.factor(&a).unwrap();
                let mut y = c.clone();
                lu.solve_transposed(&mut y);
                for j in 0..n {
                    let r: f64 = (0..n).map(|i| a[i * n + j] * y[i]).sum();
                    assert!(
                        (r - c[j]).abs() < 1e-10 * (1.0 + c[j].abs()),
                        "n = {n}: {r} vs {}",
                        c[j]
                    );
                }
            }
        }
    }

    #[test]
    fn solving_many_columns_at_once_matches_one_at_a_time() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for n in [1usize, 3, 9, 14] {
            let a: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let k = 5;
            let b: Vec<f64> = (0..n * k).map(|_| rng.random_range(-1.0..1.0)).collect();
            for solver in [LinearSolver::Hand, LinearSolver::Faer] {
                let mut lu = DenseLu::new(n, solver);
                lu.factor(&a).unwrap();
                let mut many = b.clone();
                lu.solve_many(&mut many, k);
                for c in 0..k {
                    let mut col: Vec<f64> = (0..n).map(|i| b[i * k + c]).collect();
                    lu.solve(&mut col);
                    for i in 0..n {
                        assert!((col[i] - many[i * k + c]).abs() <= 1e-12 * (1.0 + col[i].abs()));
                    }
                }
            }
        }
    }

    #[test]
    fn hand_and_faer_back_ends_solve_the_same_systems() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for n in [1usize, 2, 3, 6, 9, 12, 40] {
            let a: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let x: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let b: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| a[i * n + j] * x[j]).sum())
                .collect();
            for solver in [LinearSolver::Hand, LinearSolver::Faer] {
                let mut lu = DenseLu::new(n, solver);
                lu.factor(&a).unwrap();
                let mut y = b.clone();
                lu.solve(&mut y);
                let err = x
                    .iter()
                    .zip(&y)
                    .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()));
                assert!(err < 1e-10, "{solver:?} n = {n}: error {err}");
            }
        }
    }

    #[test]
    fn the_sized_eliminations_equal_the_general_one_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        for n in 1usize..=14 {
            for trial in 0..20 {
                let mut a: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
                if trial % 4 == 1 && n > 1 {
                    // Exact zeros below the diagonal (the multiplier-is-zero branch) ...
                    for i in 1..n {
                        a[i * n] = 0.0;
                    }
                }
                if trial % 4 == 2 && n > 1 {
                    // ... and a repeated row, singular in both.
                    let row = a[..n].to_vec();
                    a[(n - 1) * n..].copy_from_slice(&row);
                }
                let mut lu = DenseLu::new(n, LinearSolver::Hand);
                let sized = lu.factor(&a);
                let (mut general, mut perm) = (a.clone(), (0..n).collect::<Vec<_>>());
                let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let tiny = (n as f64) * f64::EPSILON * scale;
                let reference = eliminate(&mut general, &mut perm, n, tiny);
                assert_eq!(sized, reference, "n = {n}, trial {trial}");
                if reference.is_ok() {
                    let Backend::Hand {
                        lu: factors,
                        perm: p,
                        ..
                    } = &lu.backend
                    else {
                        unreachable!()
                    };
                    assert_eq!(factors, &general, "n = {n}, trial {trial}");
                    assert_eq!(p, &perm, "n = {n}, trial {trial}");
                }
            }
        }
    }

    #[test]
    fn infinite_entries_are_non_finite_and_huge_ones_are_not() {
        for n in [3usize, 10, 13] {
            let mut lu = DenseLu::new(n, LinearSolver::Hand);
            let mut a: Vec<f64> = (0..n * n)
                .map(|k| {
                    if k % (n + 1) == 0 {
                        f64::MAX / 2.0
                    } else {
                        0.0
                    }
                })
                .collect();
            a[n + 1] = f64::MAX;
            lu.factor(&a).unwrap();
            for bad in [f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
                a[n * n - 2] = bad;
                assert_eq!(lu.factor(&a), Err(FactorError::NonFinite), "n = {n}, {bad}");
            }
        }
    }

    #[test]
    fn singular_and_non_finite_matrices_are_reported() {
        for solver in [LinearSolver::Hand, LinearSolver::Faer] {
            let mut lu = DenseLu::new(3, solver);
            // Rows 1 and 2 are parallel: elimination fails in its second column.
            let e = lu
                .factor(&[1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 1.0, 1.0])
                .unwrap_err();
            match e {
                FactorError::Singular {
                    column, threshold, ..
                } => {
                    assert!(column >= 1, "{e}");
                    assert!(threshold > 0.0 && threshold < 1e-14, "{e}");
                }
                other => panic!("{solver:?}: {other}"),
            }
            assert!(e.to_string().contains("pivot"), "{e}");
            assert_eq!(
                lu.factor(&[1.0, 0.0, 0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0, 1.0]),
                Err(FactorError::NonFinite)
            );
            assert_eq!(
                lu.factor(&[1.0, 0.0]),
                Err(FactorError::Shape { len: 2, n: 3 })
            );
            // A pivot far below the matrix's scale is singular; the same matrix scaled uniformly is not.
            assert!(matches!(
                lu.factor(&[0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1e-300]),
                Err(FactorError::Singular { column: 2, .. })
            ));
            lu.factor(&[0.0, 1e-200, 0.0, 1e-200, 0.0, 0.0, 0.0, 0.0, 1e-200])
                .unwrap();
        }
    }
}
