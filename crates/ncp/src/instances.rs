//! Reproducible problem families for tests, benchmarks and `cargo xtask lcp`: classic hard LCPs and
//! random problems with the structure of one contact step. Each takes an explicit seed.

#![allow(non_snake_case)]

use crate::problem::LinearMcp;

pub use crate::rng::SplitMix64;

/// Murty's family (K. G. Murty, "Computational complexity of complementary pivot methods", 1978; "Linear
/// Complementarity, Linear and Nonlinear Programming", 1988, ch. 6): `M` lower triangular with ones on the
/// diagonal and twos below, `q_i = -(2^n + 2^(n-1) + ... + 2^(n-i))`. `M` is a P-matrix, so the solution is
/// unique (`z = 2^n e_1`), yet Lemke's method with covering vector `e` takes `2^n` pivots to find it.
pub fn murty(n: usize) -> LinearMcp {
    let mut m = vec![0.0; n * n];
    for i in 0..n {
        m[i * n + i] = 1.0;
        for j in 0..i {
            m[i * n + j] = 2.0;
        }
    }
    let q = (0..n)
        .map(|i| -(0..=i).map(|k| 2f64.powi((n - k) as i32)).sum::<f64>())
        .collect();
    LinearMcp::from_row_major(0, m, q).expect("finite data")
}

/// Kinds of random LCP matrices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MatrixKind {
    /// Symmetric positive definite `B^T B + I / 10`.
    PositiveDefinite,
    /// A P-matrix that is not positive definite: upper triangular, positive diagonal, large entries above.
    PMatrix,
    /// Non-symmetric positive definite: `B^T B / 10 + D + S` with `S` skew-symmetric.
    Monotone,
    /// Positive semi-definite and singular: `B^T B` with `B` of rank about `n / 2`.
    SingularPsd,
}

/// A random `n`-row LCP of the given kind with a planted solution `z*`: a random support, complementary
/// `w*`, and `q = w* - M z*`; about a fifth of the rows are degenerate (`z*_i = w*_i = 0`). Returns the
/// problem and `z*` (the unique solution for P-matrices).
pub fn planted_lcp(kind: MatrixKind, n: usize, seed: u64) -> (LinearMcp, Vec<f64>) {
    let mut rng = SplitMix64::new(seed);
    let mut b = vec![0.0; n * n];
    for v in b.iter_mut() {
        *v = rng.uniform(-1.0, 1.0);
    }
    let gram = |b: &[f64], rank: usize| {
        let mut m = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                m[i * n + j] = (0..rank).map(|k| b[k * n + i] * b[k * n + j]).sum();
            }
        }
        m
    };
    let m = match kind {
        MatrixKind::PositiveDefinite => {
            let mut m = gram(&b, n);
            for i in 0..n {
                m[i * n + i] += 0.1;
            }
            m
        }
        MatrixKind::PMatrix => {
            let mut m = vec![0.0; n * n];
            for i in 0..n {
                m[i * n + i] = rng.uniform(0.5, 2.0);
                for j in i + 1..n {
                    m[i * n + j] = rng.uniform(-4.0, 4.0);
                }
            }
            m
        }
        MatrixKind::Monotone => {
            let mut m = gram(&b, n);
            for v in m.iter_mut() {
                *v *= 0.1;
            }
            for i in 0..n {
                m[i * n + i] += rng.uniform(0.2, 1.0);
                for j in i + 1..n {
                    let s = rng.uniform(-2.0, 2.0);
                    m[i * n + j] += s;
                    m[j * n + i] -= s;
                }
            }
            m
        }
        MatrixKind::SingularPsd => gram(&b, n.div_ceil(2)),
    };
    let mut z = vec![0.0; n];
    let mut w = vec![0.0; n];
    for i in 0..n {
        let u = rng.uniform(0.0, 1.0);
        if u < 0.4 {
            z[i] = rng.uniform(0.1, 2.0);
        } else if u < 0.8 {
            w[i] = rng.uniform(0.1, 2.0);
        }
    }
    let q: Vec<f64> = (0..n)
        .map(|i| w[i] - (0..n).map(|j| m[i * n + j] * z[j]).sum::<f64>())
        .collect();
    (LinearMcp::from_row_major(0, m, q).expect("finite data"), z)
}

/// A random mixed LCP with the structure and scale of one step of the flicking finger (SCENE.md "One
/// time step"): unknowns `z = [v'; lambda]` with 3 velocities and 6 impulses,
/// `F = [M v' - J^T lambda - (M v + h f); J v' + d / h]`, four joint-limit rows `+-e_1, +-e_2` and two
/// friction-cone rows `J_n +- mu J_t` with `mu = 0.5`. Distances range from penetration (-0.05) to far
/// apart, so some rows are active and some are not. `h = 0.05`.
pub fn contact_step(seed: u64) -> LinearMcp {
    let mut rng = SplitMix64::new(seed);
    let h = 0.05;
    // M = L L^T + diag, like a 3-body mass matrix.
    let mut l = [0.0; 9];
    for v in l.iter_mut() {
        *v = rng.uniform(-0.6, 0.6);
    }
    let mut M = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            M[i * 3 + j] = (0..3).map(|k| l[i * 3 + k] * l[j * 3 + k]).sum();
        }
        M[i * 3 + i] += rng.uniform(0.2, 1.5);
    }
    let mu = 0.5;
    // The hard problem has a solution whenever its reduced matrix J M^-1 J^T (PSD) admits no y >= 0 with
    // J^T y = 0 and b^T y < 0 (Farkas). With |J_n3| > mu |J_t3| (the free body turns more by the push than
    // by the friction) no combination of the contact rows cancels, so every instance is solvable.
    let jt = [
        rng.uniform(-1.5, 1.5),
        rng.uniform(-1.5, 1.5),
        rng.uniform(-0.8, 0.8),
    ];
    let lever = mu * jt[2].abs() + rng.uniform(0.1, 0.8);
    let jn = [
        rng.uniform(-1.5, 1.5),
        rng.uniform(-1.5, 1.5),
        if rng.uniform(0.0, 1.0) < 0.5 {
            lever
        } else {
            -lever
        },
    ];
    let J = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [jn[0] + mu * jt[0], jn[1] + mu * jt[1], jn[2] + mu * jt[2]],
        [jn[0] - mu * jt[0], jn[1] - mu * jt[1], jn[2] - mu * jt[2]],
    ];
    let v = [
        rng.uniform(-3.0, 3.0),
        rng.uniform(-3.0, 3.0),
        rng.uniform(-3.0, 3.0),
    ];
    let f = [
        rng.uniform(-5.0, 5.0),
        rng.uniform(-5.0, 5.0),
        rng.uniform(-1.0, 1.0),
    ];
    // A joint's two limit distances add up to its range (as theta + pi and -theta do), so at most one is
    // near zero or slightly violated.
    let limits = |rng: &mut SplitMix64| {
        let span = rng.uniform(1.5, 3.5);
        let lower = if rng.uniform(0.0, 1.0) < 0.3 {
            rng.uniform(-0.01, 0.02)
        } else {
            rng.uniform(0.2, 1.4)
        };
        if rng.uniform(0.0, 1.0) < 0.5 {
            (lower, span - lower)
        } else {
            (span - lower, lower)
        }
    };
    let (d0, d1) = limits(&mut rng);
    let (d2, d3) = limits(&mut rng);
    let contact = rng.uniform(-0.05, 0.15);
    let d = [d0, d1, d2, d3, contact, contact];
    let n = 9;
    let mut m = vec![0.0; n * n];
    let mut q = vec![0.0; n];
    for i in 0..3 {
        for j in 0..3 {
            m[i * n + j] = M[i * 3 + j];
        }
        for k in 0..6 {
            m[i * n + 3 + k] = -J[k][i];
        }
        q[i] = -((0..3).map(|j| M[i * 3 + j] * v[j]).sum::<f64>() + h * f[i]);
    }
    for k in 0..6 {
        for j in 0..3 {
            m[(3 + k) * n + j] = J[k][j];
        }
        q[3 + k] = d[k] / h;
    }
    LinearMcp::from_row_major(3, m, q).expect("finite data")
}

/// The same problem with `q` moved by a relative `epsilon` (deterministically, by `seed`): the next time
/// step of a smooth trajectory, for warm-start measurements.
pub fn perturbed(problem: &LinearMcp, epsilon: f64, seed: u64) -> LinearMcp {
    let mut rng = SplitMix64::new(seed ^ 0x5eed);
    let q: Vec<f64> = problem
        .q()
        .iter()
        .map(|v| v + epsilon * (v.abs() + 1.0) * rng.uniform(-1.0, 1.0))
        .collect();
    LinearMcp::from_row_major(problem.n_free_rows(), problem.m_row_major().to_vec(), q)
        .expect("finite data")
}
