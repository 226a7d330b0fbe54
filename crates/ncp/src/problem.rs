//! Mixed complementarity problems: `n` unknowns `z = [x; lambda]`, the leading `n_free` rows equalities
//! `g(z) = 0` in free variables `x` (the paper's "phi = b" rows, the equations of motion), the remaining
//! rows complementarity pairs `0 <= lambda_i  _|_  w_i(z) >= 0` (paper eq. 1c, 3; SCENE.md "One time step").

#![allow(non_snake_case)]

use crate::dense::DenseLu;
use crate::error::{NcpError, check_finite, check_len};
use faer::{Mat, MatRef};

/// A mixed complementarity problem `F(z) = [g(z); w(z)]` with its Jacobian, supplied by the caller.
pub trait Mcp {
    /// Number of unknowns (and of rows).
    fn dim(&self) -> usize;
    /// Number of leading equality rows (free variables).
    fn n_free(&self) -> usize;
    /// Number of trailing complementarity rows.
    fn n_compl(&self) -> usize {
        self.dim() - self.n_free()
    }
    /// Write `F(z)` into `value` and, when asked, the row-major `n x n` Jacobian `dF/dz` into `jacobian`.
    fn evaluate(&self, z: &[f64], value: &mut [f64], jacobian: Option<&mut [f64]>);
    /// The problem as a linear one, if it is: a smoothed solve that fails from its warm start restarts
    /// from the hard problem's exact solution (Lemke's method). `None` by default.
    fn as_linear(&self) -> Option<&LinearMcp> {
        None
    }

    /// Whether `dF/dz` is the same at every `z` (a linear problem's `M`): Newton's method then takes it
    /// once per solve and its line search evaluates `F` alone. False by default.
    fn constant_jacobian(&self) -> bool {
        false
    }
}

/// The linear case `F(z) = M z + q`: a mixed LCP, or a plain LCP when `n_free = 0`. This is the form of one
/// time step, whose `M` and `q` are frozen at the start of the step.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearMcp {
    n: usize,
    n_free: usize,
    /// Row-major `n x n`.
    m: Vec<f64>,
    q: Vec<f64>,
}

impl LinearMcp {
    /// `F(z) = M z + q` with the first `n_free` rows equalities; `M` square and everything finite.
    pub fn new(n_free: usize, M: MatRef<'_, f64>, q: &[f64]) -> Result<Self, NcpError> {
        let n = M.nrows();
        check_len("M's columns", M.ncols(), n)?;
        let mut m = Vec::with_capacity(n * n);
        for i in 0..n {
            for j in 0..n {
                m.push(M[(i, j)]);
            }
        }
        Self::from_row_major(n_free, m, q.to_vec())
    }

    /// The plain LCP `0 <= z _|_ M z + q >= 0`.
    pub fn lcp(M: MatRef<'_, f64>, q: &[f64]) -> Result<Self, NcpError> {
        Self::new(0, M, q)
    }

    /// From rows of `M` (as read from JSON, say); every row must have `q.len()` entries.
    pub fn from_rows(n_free: usize, rows: &[Vec<f64>], q: &[f64]) -> Result<Self, NcpError> {
        let n = q.len();
        if rows.len() != n {
            return Err(NcpError::Shape(format!(
                "M has {} rows but q has {n} entries: M must be {n}x{n}",
                rows.len()
            )));
        }
        let mut m = Vec::with_capacity(n * n);
        for (i, row) in rows.iter().enumerate() {
            if row.len() != n {
                return Err(NcpError::Shape(format!(
                    "row {i} of M has {} entries but q has {n}: M must be {n}x{n}",
                    row.len()
                )));
            }
            m.extend_from_slice(row);
        }
        Self::from_row_major(n_free, m, q.to_vec())
    }

    /// From a row-major `n x n` buffer and `q` of length `n`.
    pub fn from_row_major(n_free: usize, m: Vec<f64>, q: Vec<f64>) -> Result<Self, NcpError> {
        let n = q.len();
        check_len("M (row-major)", m.len(), n * n)?;
        if n_free > n {
            return Err(NcpError::Dimension {
                what: "n_free",
                got: n_free,
                expected: n,
            });
        }
        check_finite("M", &m)?;
        check_finite("q", &q)?;
        Ok(LinearMcp { n, n_free, m, q })
    }

    /// `M` row-major and `q`, given back (to be refilled for the next problem of the same size without
    /// allocating, [`LinearMcp::from_row_major`]).
    pub fn into_row_major(self) -> (Vec<f64>, Vec<f64>) {
        (self.m, self.q)
    }

    /// `M` as a faer matrix.
    pub fn matrix(&self) -> Mat<f64> {
        Mat::from_fn(self.n, self.n, |i, j| self.m[i * self.n + j])
    }

    /// Number of leading equality rows.
    pub fn n_free_rows(&self) -> usize {
        self.n_free
    }

    /// `M` row-major.
    pub fn m_row_major(&self) -> &[f64] {
        &self.m
    }

    /// `q`.
    pub fn q(&self) -> &[f64] {
        &self.q
    }

    /// Largest magnitude in `M` and `q`, at least 1: the scale against which residuals are judged.
    pub fn scale(&self) -> f64 {
        self.m
            .iter()
            .chain(&self.q)
            .fold(1.0f64, |s, v| s.max(v.abs()))
    }

    /// Eliminate the free variables through the equality rows: `x = -M_ff^-1 (M_fc lambda + q_f)`, leaving
    /// the LCP `0 <= lambda _|_ A lambda + b >= 0` with the Schur complement
    /// `A = M_cc - M_cf M_ff^-1 M_fc` and `b = q_c - M_cf M_ff^-1 q_f`.
    pub fn reduce(&self) -> Result<Reduced, NcpError> {
        let mut out = Reduced::default();
        self.reduce_into(&mut out, &mut FreeBlock::default())?;
        Ok(out)
    }

    /// [`LinearMcp::reduce`] into `out`, the free block factored in `free` (no allocation once both have
    /// this problem's sizes).
    pub(crate) fn reduce_into(
        &self,
        out: &mut Reduced,
        free: &mut FreeBlock,
    ) -> Result<(), NcpError> {
        let (n, f) = (self.n, self.n_free);
        let c = n - f;
        let FreeBlock { lu, mff, col } = free;
        let lu = crate::dense::sized(lu, f);
        mff.clear();
        mff.resize(f * f, 0.0);
        for i in 0..f {
            mff[i * f..(i + 1) * f].copy_from_slice(&self.m[i * n..i * n + f]);
        }
        if f > 0
            && let Err(cause) = lu.factor(mff)
        {
            return Err(NcpError::SingularFreeBlock { n_free: f, cause });
        }
        let Reduced {
            n_free,
            a,
            b,
            x_of_lambda,
            x0,
        } = out;
        *n_free = f;
        // Columns of M_ff^-1 [M_fc, q_f]: x = X lambda + x0.
        x_of_lambda.clear();
        x_of_lambda.resize(f * c, 0.0);
        col.clear();
        col.resize(f, 0.0);
        for j in 0..c {
            for i in 0..f {
                col[i] = -self.m[i * n + f + j];
            }
            lu.solve(col);
            for i in 0..f {
                x_of_lambda[i * c + j] = col[i];
            }
        }
        for i in 0..f {
            col[i] = -self.q[i];
        }
        lu.solve(col);
        x0.clear();
        x0.extend_from_slice(col);
        a.clear();
        a.resize(c * c, 0.0);
        b.clear();
        b.resize(c, 0.0);
        for i in 0..c {
            let row = &self.m[(f + i) * n..(f + i + 1) * n];
            for j in 0..c {
                let mut s = row[f + j];
                for k in 0..f {
                    s += row[k] * x_of_lambda[k * c + j];
                }
                a[i * c + j] = s;
            }
            let mut s = self.q[f + i];
            for k in 0..f {
                s += row[k] * x0[k];
            }
            b[i] = s;
        }
        Ok(())
    }
}

/// The free block's factors and scratch for [`LinearMcp::reduce_into`].
#[derive(Debug, Default)]
pub(crate) struct FreeBlock {
    lu: Option<DenseLu>,
    mff: Vec<f64>,
    col: Vec<f64>,
}

impl Mcp for LinearMcp {
    fn dim(&self) -> usize {
        self.n
    }

    fn n_free(&self) -> usize {
        self.n_free
    }

    fn evaluate(&self, z: &[f64], value: &mut [f64], jacobian: Option<&mut [f64]>) {
        let n = self.n;
        for i in 0..n {
            let row = &self.m[i * n..(i + 1) * n];
            let mut s = self.q[i];
            for j in 0..n {
                s += row[j] * z[j];
            }
            value[i] = s;
        }
        if let Some(jac) = jacobian {
            jac.copy_from_slice(&self.m);
        }
    }

    fn as_linear(&self) -> Option<&LinearMcp> {
        Some(self)
    }

    fn constant_jacobian(&self) -> bool {
        true
    }
}

/// A mixed LCP with its free variables eliminated (see [`LinearMcp::reduce`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Reduced {
    n_free: usize,
    /// Row-major Schur complement `A` (`c x c`).
    pub a: Vec<f64>,
    /// `b`, so that `w = A lambda + b`.
    pub b: Vec<f64>,
    /// Row-major `f x c`: `x = x_of_lambda lambda + x0`.
    pub x_of_lambda: Vec<f64>,
    /// The free variables at `lambda = 0`.
    pub x0: Vec<f64>,
}

impl Reduced {
    /// Number of complementarity rows.
    pub fn n_compl(&self) -> usize {
        self.b.len()
    }

    /// The full unknown vector `z = [x(lambda); lambda]`.
    pub fn expand(&self, lambda: &[f64]) -> Vec<f64> {
        let mut z = vec![0.0; self.n_free + self.b.len()];
        self.expand_into(lambda, &mut z);
        z
    }

    /// [`Reduced::expand`] into `z` (of the full problem's size).
    pub fn expand_into(&self, lambda: &[f64], z: &mut [f64]) {
        let (f, c) = (self.n_free, self.b.len());
        for i in 0..f {
            let mut s = self.x0[i];
            for j in 0..c {
                s += self.x_of_lambda[i * c + j] * lambda[j];
            }
            z[i] = s;
        }
        z[f..f + c].copy_from_slice(lambda);
    }

    /// The reduced problem as a plain LCP.
    pub fn lcp(&self) -> LinearMcp {
        LinearMcp {
            n: self.b.len(),
            n_free: 0,
            m: self.a.clone(),
            q: self.b.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_problems_are_rejected_with_the_offending_input_named() {
        let rows = vec![vec![1.0, 0.0], vec![0.0]];
        assert_eq!(
            LinearMcp::from_rows(0, &rows, &[1.0, 2.0])
                .unwrap_err()
                .to_string(),
            "row 1 of M has 1 entries but q has 2: M must be 2x2"
        );
        assert_eq!(
            LinearMcp::from_rows(0, &rows, &[1.0, 2.0, 3.0])
                .unwrap_err()
                .to_string(),
            "M has 2 rows but q has 3 entries: M must be 3x3"
        );
        let rows = vec![vec![1.0, f64::NAN], vec![0.0, 1.0]];
        assert!(matches!(
            LinearMcp::from_rows(0, &rows, &[1.0, 2.0]),
            Err(NcpError::NonFinite {
                what: "M",
                index: 1,
                ..
            })
        ));
        let rows = vec![vec![1.0, 0.0], vec![0.0, 1.0]];
        assert!(matches!(
            LinearMcp::from_rows(3, &rows, &[1.0, 2.0]),
            Err(NcpError::Dimension { .. })
        ));
        assert!(matches!(
            LinearMcp::from_rows(0, &rows, &[1.0, f64::INFINITY]),
            Err(NcpError::NonFinite {
                what: "q",
                index: 1,
                ..
            })
        ));
    }

    #[test]
    fn reduction_reproduces_the_equality_rows_exactly() {
        // [M_ff M_fc; M_cf M_cc] with a 2x2 free block.
        let rows = vec![
            vec![4.0, 1.0, -1.0, 0.5],
            vec![1.0, 3.0, 0.0, -1.0],
            vec![1.0, 0.0, 0.0, 0.0],
            vec![0.5, -1.0, 0.0, 0.0],
        ];
        let p = LinearMcp::from_rows(2, &rows, &[-1.0, 2.0, 0.3, 0.1]).unwrap();
        let r = p.reduce().unwrap();
        let lambda = [0.7, 1.3];
        let z = r.expand(&lambda);
        let mut f = [0.0; 4];
        p.evaluate(&z, &mut f, None);
        assert!(f[0].abs() < 1e-14 && f[1].abs() < 1e-14);
        for i in 0..2 {
            let w = r.b[i] + r.a[i * 2] * lambda[0] + r.a[i * 2 + 1] * lambda[1];
            assert!((w - f[2 + i]).abs() < 1e-14);
        }
        let singular = vec![
            vec![1.0, 1.0, 0.0],
            vec![1.0, 1.0, 0.0],
            vec![0.0, 1.0, 1.0],
        ];
        let p = LinearMcp::from_rows(2, &singular, &[0.0; 3]).unwrap();
        assert!(matches!(
            p.reduce(),
            Err(NcpError::SingularFreeBlock {
                n_free: 2,
                cause: crate::FactorError::Singular { column: 1, .. }
            })
        ));
    }
}
