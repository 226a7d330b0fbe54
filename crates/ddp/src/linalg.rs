//! Small dense kernels (row-major) for the backward pass: the matrices are a few entries wide (the finger:
//! 6 states, 2 controls), where straight loops beat a general library's dispatch.

/// Cholesky factor `L` (lower, row-major) of the symmetric `n x n` matrix `a`, or `None` when `a` is not
/// positive definite (a pivot that is not positive and finite).
pub fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    cholesky_into(&mut l, a, n).then_some(l)
}

/// Solve `L L^T x = b` in place for the `k` columns of the row-major `n x k` block `b`.
pub fn cholesky_solve(l: &[f64], n: usize, b: &mut [f64], k: usize) {
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
    out[..c].iter_mut().for_each(|e| *e = 0.0);
    for k in 0..r {
        for i in 0..c {
            out[i] += a[k * c + i] * v[k];
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
