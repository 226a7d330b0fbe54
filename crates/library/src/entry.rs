//! What a library stores: its controllers ([`Entry`]), each with the local model of its cost-to-go
//! ([`LocalValue`]) that the policy ranks them by. Plain data, below the build and the policy that both
//! use it.

use serde::{Deserialize, Serialize};

/// One stored local controller: `u(x) = u + K (x - x)` around the state `x`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    /// The trajectory's initial state `x_1`.
    pub x: Vec<f64>,
    /// Its first control `u_1`.
    pub u: Vec<f64>,
    /// Its first feedback gain `K_1`, row-major `m x n`.
    pub gain: Vec<f64>,
    /// Optimiser passes this trajectory took.
    pub passes: u32,
    /// Whether the optimiser converged (else it stopped at its pass limit or regularisation limit).
    pub converged: bool,
    /// The trajectory's cost.
    pub cost: f64,
    /// The trajectory's local model of the cost-to-go around `x` (what [`crate::Policy`] ranks nearby
    /// controllers by).
    pub value: LocalValue,
    /// How far from `x` the policy may use this controller, in the policy's whitened distance
    /// ([`crate::Policy::distance`]); `None`: anywhere. Growth sets it where this controller's value
    /// model outbid, at a state the policy failed from, the branch grown there: that state is then
    /// outside its reach (the funnel shrinking of simulation-based LQR-trees).
    pub reach: Option<f64>,
    /// The time step its trajectory was optimised at: the library's own, or for a target task's growth
    /// branch on a world of another time step, that world's ([`crate::Policy::with_time_step`] prefers
    /// the controllers of the step it runs at).
    pub time_step: f64,
}

/// The second-order model of the cost-to-go around a stored state `x_s`, extended to the library's full
/// horizon: `V(x) ~ cost_to_go + gradient . d + 1/2 d^T hessian d + per_period k` with `d = x - x_s - k P
/// e_free` for `x` whose free angle lies `k` whole periods `P` from the stored one.
///
/// A controller kept `t` steps into its trajectory has `t` steps less to go than the trajectory's first;
/// its cost-to-go adds `t` running costs at the trajectory's final state with zero control (the cost of
/// idling there), so that controllers from different offsets compare on the same horizon.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocalValue {
    /// The cost-to-go from `x_s`.
    pub cost_to_go: f64,
    /// `V_x` (`n`).
    pub gradient: Vec<f64>,
    /// `V_xx`, row-major `n x n`.
    pub hessian: Vec<f64>,
    /// How much the cost-to-go changes when the free angle advances one whole period (with the
    /// finger's cost `-theta3` per step over `N` steps and the final cost: `-(N + 1) pi`).
    pub per_period: f64,
}

impl LocalValue {
    /// The model's prediction at `d = x - x_s - k P e_free`, `k` whole periods on.
    pub fn predict(&self, d: &[f64], periods: f64) -> f64 {
        let n = d.len();
        let mut v = self.cost_to_go + periods * self.per_period;
        for a in 0..n {
            let hd: f64 = (0..n).map(|b| self.hessian[a * n + b] * d[b]).sum();
            v += d[a] * (self.gradient[a] + 0.5 * hd);
        }
        v
    }

    /// The same model with the Hessian's negative curvature removed (its eigenvalues below zero set to
    /// zero): what [`crate::Policy`] ranks controllers by. A concave model predicts ever lower costs the
    /// farther it extrapolates, so among nearby controllers the one with the most negative curvature would
    /// win wherever it is wrong; the convex part only penalises distance. (Measured on the finger: the
    /// raw models chose controllers with gains in the thousands far from their states, and closed loops
    /// stalled.)
    pub fn convexified(&self) -> LocalValue {
        LocalValue {
            hessian: positive_part(&self.hessian, self.gradient.len()),
            ..self.clone()
        }
    }
}

/// The positive semi-definite part of the symmetrised `n x n` matrix `a` (row-major): its eigenvalues below
/// zero set to zero (zero if the eigendecomposition fails, which it does only for non-finite entries).
fn positive_part(a: &[f64], n: usize) -> Vec<f64> {
    let sym = faer::Mat::<f64>::from_fn(n, n, |i, j| 0.5 * (a[i * n + j] + a[j * n + i]));
    let mut out = vec![0.0; n * n];
    let Ok(evd) = sym.self_adjoint_eigen(faer::Side::Lower) else {
        return out;
    };
    let (u, s) = (evd.U(), evd.S());
    for k in 0..n {
        let l = s[k];
        if l > 0.0 {
            for i in 0..n {
                for j in 0..n {
                    out[i * n + j] += l * u[(i, k)] * u[(j, k)];
                }
            }
        }
    }
    out
}
