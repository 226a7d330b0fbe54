//! The simulator as [`ddp::Dynamics`] and the task's cost: `l(x, u) = -theta3 + c_u |u|^2` per step and
//! `-theta3` at the end (SCENE.md, paper section V-A).

use ddp::{Dynamics, QuadraticCost};
use dynamics::{DynamicsError, SecondOrderStep, Simulator};
use std::collections::HashMap;
use thiserror::Error;

/// SCENE.md's control weight `c_u`.
pub const CONTROL_WEIGHT: f64 = 0.05;

/// The task's cost for a scene whose free body is joint `free` (the finger: 2, theta3), state weight
/// `c_x = 1`.
pub fn finger_cost(n_dof: usize, free: usize, n_controls: usize) -> QuadraticCost {
    let mut c = vec![0.0; 2 * n_dof];
    c[free] = -1.0;
    QuadraticCost::linear_state(&c, CONTROL_WEIGHT, n_controls)
}

/// Why a step of the task failed.
#[derive(Debug, Error)]
pub enum TaskError {
    /// The simulator refused the input or the derivatives.
    #[error(transparent)]
    Dynamics(#[from] DynamicsError),
    /// The step's complementarity solve did not converge (an optimiser rejects the trial).
    #[error("the step's complementarity solve did not converge: {0:?}")]
    NotConverged(ncp::Status),
}

/// A [`Simulator`] as the optimiser's dynamics: `step` is [`Simulator::step`], `derivatives`
/// [`Simulator::step_with_derivatives`], `second_derivatives` [`Simulator::step_with_hessian`].
///
/// The optimiser retries a backward pass with more regularisation at the same trajectory, which changes
/// only the vector the step's Hessian is contracted with: prepared steps ([`SecondOrderStep`]) are kept by
/// the exact bits of `(x, u)`, so a retry costs the contraction alone.
#[derive(Debug)]
pub struct FingerDynamics {
    sim: Simulator,
    prepared: HashMap<Vec<u64>, SecondOrderStep>,
    /// Solutions `[v'; lambda]` of recent steps: the derivatives at a state the forward pass has stepped
    /// from start their solve there and need no iteration.
    solutions: HashMap<Vec<u64>, Vec<f64>>,
}

fn key(x: &[f64], u: &[f64]) -> Vec<u64> {
    x.iter().chain(u).map(|e| e.to_bits()).collect()
}

/// Prepared steps (and step solutions) kept at most: a few trajectories' worth.
const PREPARED_CAPACITY: usize = 512;

impl FingerDynamics {
    /// Wrap a simulator.
    pub fn new(sim: Simulator) -> Self {
        FingerDynamics {
            sim,
            prepared: HashMap::new(),
            solutions: HashMap::new(),
        }
    }

    /// The simulator.
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    /// The simulator, mutably (to change its covariance or reset its warm start); forgets prepared steps.
    pub fn simulator_mut(&mut self) -> &mut Simulator {
        self.prepared.clear();
        self.solutions.clear();
        &mut self.sim
    }

    /// Warm-start the simulator from the stored solution of a step from `(x, u)`, if any.
    fn resume(&mut self, x: &[f64], u: &[f64]) {
        if let Some(z) = self.solutions.get(&key(x, u)) {
            self.sim
                .set_warm_start(z)
                .expect("a stored solution has the scene's size");
        }
    }
}

impl Dynamics for FingerDynamics {
    type Error = TaskError;

    fn state_dim(&self) -> usize {
        self.sim.scene().n_state()
    }

    fn control_dim(&self) -> usize {
        self.sim.scene().n_controls
    }

    fn step(&mut self, x: &[f64], u: &[f64], next: &mut [f64]) -> Result<(), TaskError> {
        let s = self.sim.step(x, u)?;
        if s.info.status != ncp::Status::Converged {
            return Err(TaskError::NotConverged(s.info.status));
        }
        next.copy_from_slice(&s.x_next);
        if self.solutions.len() >= PREPARED_CAPACITY {
            self.solutions.clear();
        }
        let n = self.sim.scene().n_dof();
        let mut z = s.x_next[n..].to_vec();
        z.extend_from_slice(&s.lambda);
        self.solutions.insert(key(x, u), z);
        Ok(())
    }

    fn step_near(
        &mut self,
        x: &[f64],
        u: &[f64],
        near_x: &[f64],
        near_u: &[f64],
        next: &mut [f64],
    ) -> Result<(), TaskError> {
        self.resume(near_x, near_u);
        self.step(x, u, next)
    }

    fn derivatives(
        &mut self,
        x: &[f64],
        u: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), TaskError> {
        self.resume(x, u);
        let (_, d) = self.sim.step_with_derivatives(x, u)?;
        fx.copy_from_slice(&d.fx);
        fu.copy_from_slice(&d.fu);
        Ok(())
    }

    fn has_second_derivatives(&self) -> bool {
        let s = self.sim.scene();
        s.n_dof() <= 3 && s.n_state() + s.n_controls <= 8
    }

    fn second_derivatives(
        &mut self,
        x: &[f64],
        u: &[f64],
        c: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), TaskError> {
        let key = key(x, u);
        if !self.prepared.contains_key(&key) {
            if self.prepared.len() >= PREPARED_CAPACITY {
                self.prepared.clear();
            }
            self.resume(x, u);
            let so = self.sim.second_order_step(x, u)?;
            if so.step.info.status != ncp::Status::Converged {
                return Err(TaskError::NotConverged(so.step.info.status));
            }
            self.prepared.insert(key.clone(), so);
        }
        let so = &self.prepared[&key];
        fx.copy_from_slice(&so.derivatives.fx);
        fu.copy_from_slice(&so.derivatives.fu);
        hess.copy_from_slice(&so.hessian(c)?);
        Ok(())
    }
}
