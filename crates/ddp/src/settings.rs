//! The optimiser's settings ([`DdpSettings`], checked by [`DdpSettings::validate`]) and the choices they
//! name: the method, where the regularisation goes, the controls' box limits, the knots' threads.

use crate::error::DdpError;
use serde::{Deserialize, Serialize};

/// Which second-order terms the backward pass keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// Full second-order DDP: `Q` includes `V_x . f_xx`, `V_x . f_ux`, `V_x . f_uu` (the dynamics'
    /// [`crate::SecondOrder`] capability).
    Full,
    /// Gauss-Newton iLQR: those terms dropped.
    GaussNewton,
}

/// Where the Levenberg-Marquardt term `mu` goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Regularisation {
    /// On the value Hessian: `Q_uu + mu f_u^T f_u`, `Q_ux + mu f_u^T f_x` (invariant to the controls'
    /// scaling, and keeps the feedback gains of a state-space trust region).
    State,
    /// On the controls: `Q_uu + mu I`.
    Control,
}

/// Box limits on the controls, the same at every step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControlLimits {
    /// Lower bounds (`m`).
    pub lower: Vec<f64>,
    /// Upper bounds (`m`).
    pub upper: Vec<f64>,
}

/// The most second-order data full DDP keeps over a horizon (each knot's
/// [`SecondOrder::bytes_per_knot`](crate::SecondOrder::bytes_per_knot)), 8 GiB: past it a solve is refused
/// before anything is allocated, with the estimate and the alternative (Gauss-Newton).
pub const FULL_DDP_MAX_BYTES: usize = 8 << 30;

/// Settings of [`Ddp`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DdpSettings {
    /// Full DDP or Gauss-Newton.
    pub method: Method,
    /// Passes at most.
    pub max_iterations: usize,
    /// Stop when an accepted pass lowers the cost by less than `tol_cost * (1 + |J|)`.
    pub tol_cost: f64,
    /// Stop when the feedforward step's mean relative size `mean_i max_j |k_ij| / (|u_ij| + 1)` is below
    /// this (with the regularisation below `1e-5`).
    pub tol_step: f64,
    /// Where the regularisation goes.
    pub regularisation: Regularisation,
    /// Initial regularisation `mu`.
    pub mu_init: f64,
    /// Below this `mu` is set to zero.
    pub mu_min: f64,
    /// Above this the optimiser gives up.
    pub mu_max: f64,
    /// Growth factor of the regularisation schedule.
    pub mu_factor: f64,
    /// Accept a step when actual / expected reduction exceeds this.
    pub accept_ratio: f64,
    /// Step sizes tried, `10^(-3 k / (steps - 1))` for `k = 0..steps`.
    pub line_search_steps: usize,
    /// Start each line search two sizes above the last accepted one instead of at 1 (fewer rejected
    /// trials when the model keeps overshooting, as Gauss-Newton does on the finger); a search that finds
    /// nothing falls back to the full range next time.
    pub adaptive_line_search: bool,
    /// Optional box limits on the controls.
    pub control_limits: Option<ControlLimits>,
    /// Threads the knots of a trajectory are differentiated on (1: on the caller's thread; at most
    /// [`MAX_THREADS`]). Each knot's derivatives depend on its own data alone, so every result is the
    /// same to the last bit on any number of threads; only the backward pass's linearisation (the
    /// dynamics' [`Dynamics::calc_diff`](crate::Dynamics::calc_diff) or [`SecondOrder::calc_diff2_prepare`](crate::SecondOrder)) is
    /// shared out, the rollouts and the backward recursion stay sequential.
    #[serde(default = "one_thread")]
    pub threads: usize,
}

/// The most threads [`DdpSettings::threads`] accepts.
pub const MAX_THREADS: usize = 256;

fn one_thread() -> usize {
    1
}

impl Default for DdpSettings {
    fn default() -> Self {
        DdpSettings {
            method: Method::Full,
            max_iterations: 200,
            tol_cost: 1e-12,
            tol_step: 1e-7,
            regularisation: Regularisation::State,
            mu_init: 1.0,
            mu_min: 1e-6,
            mu_max: 1e10,
            mu_factor: 1.6,
            accept_ratio: 0.0,
            line_search_steps: 11,
            adaptive_line_search: false,
            control_limits: None,
            threads: 1,
        }
    }
}

impl DdpSettings {
    /// `Err` naming the first setting out of range.
    pub fn validate(&self) -> Result<(), DdpError> {
        let positive = |name: &'static str, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(DdpError::Setting {
                    name,
                    value,
                    expected: "finite and positive",
                })
            }
        };
        positive("tol_cost", self.tol_cost)?;
        positive("tol_step", self.tol_step)?;
        positive("mu_min", self.mu_min)?;
        positive("mu_max", self.mu_max)?;
        if !(self.mu_init.is_finite() && self.mu_init >= 0.0) {
            return Err(DdpError::Setting {
                name: "mu_init",
                value: self.mu_init,
                expected: "finite and non-negative",
            });
        }
        if !(self.mu_factor.is_finite() && self.mu_factor > 1.0) {
            return Err(DdpError::Setting {
                name: "mu_factor",
                value: self.mu_factor,
                expected: "finite and above 1",
            });
        }
        if !(self.accept_ratio.is_finite() && (0.0..1.0).contains(&self.accept_ratio)) {
            return Err(DdpError::Setting {
                name: "accept_ratio",
                value: self.accept_ratio,
                expected: "in [0, 1)",
            });
        }
        if !(1..=MAX_THREADS).contains(&self.threads) {
            return Err(DdpError::Setting {
                name: "threads",
                value: self.threads as f64,
                expected: "from 1 to 256",
            });
        }
        for (name, count) in [
            ("max_iterations", self.max_iterations),
            ("line_search_steps", self.line_search_steps),
        ] {
            if count == 0 {
                return Err(DdpError::Setting {
                    name,
                    value: 0.0,
                    expected: "at least 1",
                });
            }
        }
        if let Some(l) = &self.control_limits
            && (l.lower.len() != l.upper.len()
                || l.lower
                    .iter()
                    .zip(&l.upper)
                    .any(|(a, b)| !(a <= b) || a.is_nan()))
        {
            return Err(DdpError::Input {
                what: "control_limits",
                problem: "lower and upper must have one entry per control, lower <= upper".into(),
            });
        }
        Ok(())
    }
}
