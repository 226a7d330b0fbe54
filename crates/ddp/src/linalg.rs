//! Small dense kernels (row-major) for the backward pass: the matrices are a few entries wide (the finger:
//! 6 states, 2 controls), where straight loops beat a general library's dispatch.

/// Cholesky factor `L` (lower, row-major) of the symmetric `n x n` matrix `a`, or `None` when `a` is not
/// positive definite (a pivot that is not positive and finite).
pub fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    cholesky_into(&mut l, a, n).then_some(l)
}

/// Solve `L L^T x = b` in place for the `k` columns of the row-major `n x k` block `b`.
///
/// Row by row over all columns at once (contiguous rows, no bounds checks): each column sees the same
/// operations in the same order as a column-by-column substitution, so the result is the same to the bit.
pub fn cholesky_solve(l: &[f64], n: usize, b: &mut [f64], k: usize) {
    if n == 0 || k == 0 {
        return;
    }
    let (l, b) = (&l[..n * n], &mut b[..n * k]);
    // A few controls (the scenes' 1 to 4): each column through registers, fully unrolled.
    match n {
        1 => return cholesky_solve_fixed::<1>(l, b, k),
        2 => return cholesky_solve_fixed::<2>(l, b, k),
        3 => return cholesky_solve_fixed::<3>(l, b, k),
        4 => return cholesky_solve_fixed::<4>(l, b, k),
        _ => {}
    }
    // Forward: row i of b minus L[i][j] times row j, j ascending, then over L[i][i].
    for i in 0..n {
        let (done, rest) = b.split_at_mut(i * k);
        let row = &mut rest[..k];
        let li = &l[i * n..(i + 1) * n];
        for (&lij, bj) in li[..i].iter().zip(done.chunks_exact(k)) {
            for (e, &bjc) in row.iter_mut().zip(bj) {
                *e -= lij * bjc;
            }
        }
        let d = li[i];
        row.iter_mut().for_each(|e| *e /= d);
    }
    // Backward: row i minus L[j][i] times row j, j ascending from i + 1, then over L[i][i].
    for i in (0..n).rev() {
        let (head, later) = b.split_at_mut((i + 1) * k);
        let row = &mut head[i * k..];
        for (j, bj) in (i + 1..n).zip(later.chunks_exact(k)) {
            let lji = l[j * n + i];
            for (e, &bjc) in row.iter_mut().zip(bj) {
                *e -= lji * bjc;
            }
        }
        let d = l[i * n + i];
        row.iter_mut().for_each(|e| *e /= d);
    }
}

/// [`cholesky_solve`] for `N x N`, column by column: the same operations in the same order.
fn cholesky_solve_fixed<const N: usize>(l: &[f64], b: &mut [f64], k: usize) {
    let (rows, _) = l.as_chunks::<N>();
    let l: &[[f64; N]; N] = rows.try_into().expect("an N x N factor");
    for c in 0..k {
        let mut x = [0.0; N];
        for (i, e) in x.iter_mut().enumerate() {
            *e = b[i * k + c];
        }
        for i in 0..N {
            let mut s = x[i];
            for j in 0..i {
                s -= l[i][j] * x[j];
            }
            x[i] = s / l[i][i];
        }
        for i in (0..N).rev() {
            let mut s = x[i];
            for j in i + 1..N {
                s -= l[j][i] * x[j];
            }
            x[i] = s / l[i][i];
        }
        for (i, e) in x.iter().enumerate() {
            b[i * k + c] = *e;
        }
    }
}

/// `out = A^T B` for row-major `A` (`r x a`) and `B` (`r x b`).
pub fn mul_tn_into(out: &mut [f64], a: &[f64], b: &[f64], r: usize, ca: usize, cb: usize) {
    let out = &mut out[..ca * cb];
    out.fill(0.0);
    if ca == 0 || cb == 0 {
        return;
    }
    let (a, b) = (&a[..r * ca], &b[..r * cb]);
    // The example scenes' widths compiled in (rows of constant length: unrolled, no bounds checks), any
    // other at run time: the same arithmetic in the same order.
    match cb {
        1 => mul_tn_rows::<1>(out, a, b, ca, cb),
        2 => mul_tn_rows::<2>(out, a, b, ca, cb),
        3 => mul_tn_rows::<3>(out, a, b, ca, cb),
        4 => mul_tn_rows::<4>(out, a, b, ca, cb),
        6 => mul_tn_rows::<6>(out, a, b, ca, cb),
        8 => mul_tn_rows::<8>(out, a, b, ca, cb),
        10 => mul_tn_rows::<10>(out, a, b, ca, cb),
        _ => mul_tn_rows::<0>(out, a, b, ca, cb),
    }
}

/// [`mul_tn_into`]'s loop, for `B` of `C` columns when `C` is not 0 (else `cb`).
fn mul_tn_rows<const C: usize>(out: &mut [f64], a: &[f64], b: &[f64], ca: usize, cb: usize) {
    let cb = if C > 0 { C } else { cb };
    for (arow, brow) in a.chunks_exact(ca).zip(b.chunks_exact(cb)) {
        let brow = &brow[..cb];
        for (&aki, orow) in arow.iter().zip(out.chunks_exact_mut(cb)) {
            if aki == 0.0 {
                continue;
            }
            for (o, bv) in orow[..cb].iter_mut().zip(brow) {
                *o += aki * bv;
            }
        }
    }
}

/// `out = A B` for row-major `A` (`r x k`) and `B` (`k x c`).
pub fn mul_into(out: &mut [f64], a: &[f64], b: &[f64], r: usize, k: usize, c: usize) {
    let out = &mut out[..r * c];
    out.fill(0.0);
    if k == 0 || c == 0 {
        return;
    }
    let (a, b) = (&a[..r * k], &b[..k * c]);
    match c {
        1 => mul_rows::<1>(out, a, b, k, c),
        2 => mul_rows::<2>(out, a, b, k, c),
        3 => mul_rows::<3>(out, a, b, k, c),
        4 => mul_rows::<4>(out, a, b, k, c),
        6 => mul_rows::<6>(out, a, b, k, c),
        8 => mul_rows::<8>(out, a, b, k, c),
        10 => mul_rows::<10>(out, a, b, k, c),
        _ => mul_rows::<0>(out, a, b, k, c),
    }
}

/// [`mul_into`]'s loop, for `B` of `C` columns when `C` is not 0 (else `c`).
fn mul_rows<const C: usize>(out: &mut [f64], a: &[f64], b: &[f64], k: usize, c: usize) {
    let c = if C > 0 { C } else { c };
    for (arow, orow) in a.chunks_exact(k).zip(out.chunks_exact_mut(c)) {
        let orow = &mut orow[..c];
        for (&ail, brow) in arow.iter().zip(b.chunks_exact(c)) {
            if ail == 0.0 {
                continue;
            }
            for (o, bv) in orow.iter_mut().zip(&brow[..c]) {
                *o += ail * bv;
            }
        }
    }
}

/// `out = A^T v` for row-major `A` (`r x c`).
pub fn mul_tv_into(out: &mut [f64], a: &[f64], v: &[f64], r: usize, c: usize) {
    let out = &mut out[..c];
    out.fill(0.0);
    if c == 0 {
        return;
    }
    for (row, &vk) in a[..r * c].chunks_exact(c).zip(&v[..r]) {
        for (o, &aki) in out.iter_mut().zip(row) {
            *o += aki * vk;
        }
    }
}

/// Cholesky factor of `a` into `l` (see [`cholesky`]); false when `a` is not positive definite.
pub fn cholesky_into(l: &mut [f64], a: &[f64], n: usize) -> bool {
    l[..n * n].iter_mut().for_each(|e| *e = 0.0);
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return false;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    true
}

/// Replace the square `n x n` matrix by its symmetric part.
pub fn symmetrize(a: &mut [f64], n: usize) {
    for i in 0..n {
        for j in 0..i {
            let s = 0.5 * (a[i * n + j] + a[j * n + i]);
            a[i * n + j] = s;
            a[j * n + i] = s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_a_positive_definite_system_and_refuses_an_indefinite_one() {
        let a = [4.0, 2.0, 0.4, 2.0, 5.0, 1.0, 0.4, 1.0, 3.0];
        let l = cholesky(&a, 3).unwrap();
        let mut b = [1.0, 2.0, 3.0];
        cholesky_solve(&l, 3, &mut b, 1);
        for i in 0..3 {
            let r: f64 = (0..3).map(|j| a[i * 3 + j] * b[j]).sum();
            assert!((r - [1.0, 2.0, 3.0][i]).abs() < 1e-14);
        }
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
        assert!(cholesky(&[f64::NAN], 1).is_none());
    }

    /// The plain column-by-column substitution the compiled sizes and the row-wise loop must match.
    fn cholesky_solve_by_columns(l: &[f64], n: usize, b: &mut [f64], k: usize) {
        for c in 0..k {
            for i in 0..n {
                let mut s = b[i * k + c];
                for j in 0..i {
                    s -= l[i * n + j] * b[j * k + c];
                }
                b[i * k + c] = s / l[i * n + i];
            }
            for i in (0..n).rev() {
                let mut s = b[i * k + c];
                for j in i + 1..n {
                    s -= l[j * n + i] * b[j * k + c];
                }
                b[i * k + c] = s / l[i * n + i];
            }
        }
    }

    #[test]
    fn cholesky_solves_to_the_bit_as_column_by_column_at_every_size() {
        for n in 1usize..=7 {
            // A diagonally dominant symmetric matrix: positive definite.
            let a: Vec<f64> = (0..n * n)
                .map(|e| {
                    let (i, j) = (e / n, e % n);
                    if i == j {
                        n as f64 + 1.0
                    } else {
                        ((i * j + i + j) % 5) as f64 / 7.0 - 0.3
                    }
                })
                .collect();
            let l = cholesky(&a, n).unwrap();
            for k in 1usize..=7 {
                let b: Vec<f64> = (0..n * k).map(|e| (e as f64 * 0.37).sin()).collect();
                let (mut fast, mut plain) = (b.clone(), b.clone());
                cholesky_solve(&l, n, &mut fast, k);
                cholesky_solve_by_columns(&l, n, &mut plain, k);
                let bits = |v: &[f64]| v.iter().map(|e| e.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&fast), bits(&plain), "n = {n}, k = {k}");
            }
        }
    }

    proptest::proptest! {
        /// The products at every width (those compiled in and the others) are the plain sums over the
        /// shared index in order, to the last bit, zero entries of `A` included.
        #[test]
        fn products_are_the_sums_in_order_at_every_width(
            r in 1usize..12,
            k in 1usize..12,
            c in 1usize..13,
            seed in 0u64..1000,
        ) {
            let entry = |i: usize| {
                let v = ((i as u64 * 2654435761 + seed * 40503) % 1009) as f64 / 97.0 - 5.0;
                if i.is_multiple_of(5) { 0.0 } else { v }
            };
            let a: Vec<f64> = (0..r * k).map(entry).collect();
            let b: Vec<f64> = (0..k * c).map(|i| entry(i + 7)).collect();
            let mut out = vec![f64::NAN; r * c];
            mul_into(&mut out, &a, &b, r, k, c);
            for i in 0..r {
                for j in 0..c {
                    let want = (0..k)
                        .filter(|&l| a[i * k + l] != 0.0)
                        .fold(0.0, |s, l| s + a[i * k + l] * b[l * c + j]);
                    proptest::prop_assert_eq!(out[i * c + j].to_bits(), want.to_bits());
                }
            }
            // A^T B with A (k x r), B (k x c).
            let mut out = vec![f64::NAN; r * c];
            mul_tn_into(&mut out, &a, &b, k, r, c);
            for i in 0..r {
                for j in 0..c {
                    let want = (0..k)
                        .filter(|&l| a[l * r + i] != 0.0)
                        .fold(0.0, |s, l| s + a[l * r + i] * b[l * c + j]);
                    proptest::prop_assert_eq!(out[i * c + j].to_bits(), want.to_bits());
                }
            }
        }
    }
}
