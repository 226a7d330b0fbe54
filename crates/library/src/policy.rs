//! The global policy of paper eq. (20): the stored controller whose state is nearest, under the Euclidean
//! norm scaled by the covariance of the stored states, with the free angle (theta3) compared modulo its
//! period (pi: the ellipse is symmetric), then that controller's linear law.

use crate::build::Entry;
use crate::error::LibraryError;
use std::f64::consts::PI;

/// A nearest-neighbour policy over stored local controllers (a brute-force scan: at the paper's 400
/// controllers and 6 states a query is a few microseconds, below a kd-tree's overheads; see
/// docs/benchmarks.md).
#[derive(Debug, Clone)]
pub struct Policy {
    n: usize,
    m: usize,
    free: usize,
    period: f64,
    /// Stored states, whitened: `L^-1 x_i` (row-major, `count x n`).
    whitened: Vec<f64>,
    /// `L^-1 e_free`: the whitened shift of one period of the free angle.
    period_shift: Vec<f64>,
    /// Cholesky factor `L` of the states' covariance (row-major lower).
    chol: Vec<f64>,
    states: Vec<Vec<f64>>,
    controls: Vec<Vec<f64>>,
    gains: Vec<Vec<f64>>,
}

/// `x` wrapped into `(-p/2, p/2]`.
fn wrap(x: f64, p: f64) -> f64 {
    x - p * (x / p).round()
}

impl Policy {
    /// The policy of `entries` for a scene with `n` joints, `m` controls and the free angle at index
    /// `free` of the state (period `pi`).
    pub fn new(
        entries: &[Entry],
        n_state: usize,
        m: usize,
        free: usize,
    ) -> Result<Self, LibraryError> {
        if entries.is_empty() {
            return Err(LibraryError::Invalid(
                "a library with no controllers".into(),
            ));
        }
        for (i, e) in entries.iter().enumerate() {
            let ok = e.x.len() == n_state
                && e.u.len() == m
                && e.gain.len() == m * n_state
                && e.x.iter().chain(&e.u).chain(&e.gain).all(|v| v.is_finite());
            if !ok {
                return Err(LibraryError::Invalid(format!(
                    "controller {i} has the wrong sizes or a non-finite entry"
                )));
            }
        }
        let n = n_state;
        let period = PI;
        let count = entries.len() as f64;
        // The free angle's circular mean (period pi: angles doubled), then every state's free angle
        // unwrapped next to it.
        let (s, c) = entries.iter().fold((0.0, 0.0), |(s, c), e| {
            let a = 2.0 * PI * e.x[free] / period;
            (s + a.sin(), c + a.cos())
        });
        let centre = s.atan2(c) * period / (2.0 * PI);
        let unwrapped = |x: &[f64]| -> Vec<f64> {
            let mut y = x.to_vec();
            y[free] = centre + wrap(x[free] - centre, period);
            y
        };
        let mut mean = vec![0.0; n];
        for e in entries {
            for (m, v) in mean.iter_mut().zip(unwrapped(&e.x)) {
                *m += v / count;
            }
        }
        let mut cov = vec![0.0; n * n];
        for e in entries {
            let d: Vec<f64> = unwrapped(&e.x)
                .iter()
                .zip(&mean)
                .map(|(a, b)| a - b)
                .collect();
            for i in 0..n {
                for j in 0..n {
                    cov[i * n + j] += d[i] * d[j] / count;
                }
            }
        }
        // A floor on every variance keeps the scaling defined when a coordinate never moved (a library of
        // one controller, a locked joint).
        let trace: f64 = (0..n).map(|i| cov[i * n + i]).sum();
        let floor = 1e-9 * trace.max(1e-12) + 1e-12;
        for i in 0..n {
            cov[i * n + i] += floor;
        }
        let chol = cholesky(&cov, n).ok_or_else(|| {
            LibraryError::Invalid("the states' covariance is not positive".into())
        })?;
        let mut whitened = Vec::with_capacity(entries.len() * n);
        for e in entries {
            whitened.extend(forward(&chol, n, &e.x));
        }
        let mut unit = vec![0.0; n];
        unit[free] = period;
        let period_shift = forward(&chol, n, &unit);
        Ok(Policy {
            n,
            m,
            free,
            period,
            whitened,
            period_shift,
            chol,
            states: entries.iter().map(|e| e.x.clone()).collect(),
            controls: entries.iter().map(|e| e.u.clone()).collect(),
            gains: entries.iter().map(|e| e.gain.clone()).collect(),
        })
    }

    /// Number of stored controllers.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// Whether there are none (never: [`Policy::new`] refuses an empty library).
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// The stored states.
    pub fn states(&self) -> &[Vec<f64>] {
        &self.states
    }

    /// Index of the nearest stored state to `x` and the whole periods of the free angle between them.
    pub fn nearest(&self, x: &[f64]) -> Result<(usize, f64), LibraryError> {
        crate::check("x", x, self.n)?;
        let y = forward(&self.chol, self.n, x);
        let mut best = (0usize, 0.0f64, f64::INFINITY);
        for (i, w) in self.whitened.chunks_exact(self.n).enumerate() {
            let turns = ((x[self.free] - self.states[i][self.free]) / self.period).round();
            let mut d2 = 0.0;
            for j in 0..self.n {
                let d = y[j] - w[j] - turns * self.period_shift[j];
                d2 += d * d;
            }
            if d2 < best.2 {
                best = (i, turns, d2);
            }
        }
        Ok((best.0, best.1))
    }

    /// The policy's control at `x` (eq. 20) written into `u`; returns the controller used.
    pub fn control(&self, x: &[f64], u: &mut [f64]) -> Result<usize, LibraryError> {
        let (i, turns) = self.nearest(x)?;
        if u.len() != self.m {
            return Err(LibraryError::Input {
                what: "u",
                problem: format!("has {} entries, expected {}", u.len(), self.m),
            });
        }
        let xi = &self.states[i];
        let k = &self.gains[i];
        for a in 0..self.m {
            let mut s = self.controls[i][a];
            for b in 0..self.n {
                let mut d = x[b] - xi[b];
                if b == self.free {
                    d -= turns * self.period;
                }
                s += k[a * self.n + b] * d;
            }
            u[a] = s;
        }
        Ok(i)
    }
}

fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// `L^-1 b` for lower-triangular `L`.
fn forward(l: &[f64], n: usize, b: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; n];
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * y[k];
        }
        y[i] = s / l[i * n + i];
    }
    y
}
