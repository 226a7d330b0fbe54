//! The simulator as [`ddp::Dynamics`] and the task's cost: `l(x, u) = -theta3 + c_u |u|^2` per step and
//! `-theta3` at the end (SCENE.md, paper section V-A).

use ddp::{Dynamics, QuadraticCost, SecondOrder};
use dynamics::{DynamicsError, SecondOrderStep, Simulator, Step};
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

/// A [`Simulator`] as the optimiser's dynamics: [`Dynamics::calc`] is [`Simulator::step`],
/// [`Dynamics::calc_diff`] [`Simulator::derivatives_of`] that step and the second-order capability
/// [`Simulator::second_order_of`] it (any scene).
///
/// Each knot's [`StepData`] keeps its step, which the knot's linearisation differentiates as it is (no
/// second solve), and whose solution `[v'; lambda]` starts the next step computed near it; and the step's
/// second-order expansion once computed: a backward pass retried with more regularisation at the same
/// trajectory changes only the vector the Hessian is contracted with, and costs the contraction alone.
#[derive(Debug)]
pub struct FingerDynamics {
    sim: Simulator,
}

/// One knot's step, kept by [`FingerDynamics`] (see there).
#[derive(Debug, Default)]
pub struct StepData {
    /// The step last computed at the knot; its derivatives linearise it as it is, and its solution
    /// `[v'; lambda]` starts the next solve near it.
    step: Option<Step>,
    /// That step's second-order expansion, once asked for.
    prepared: Option<SecondOrderStep>,
}

impl StepData {
    /// The step last computed at the knot, if any.
    pub fn step(&self) -> Option<&Step> {
        self.step.as_ref()
    }
}

impl FingerDynamics {
    /// Wrap a simulator.
    pub fn new(sim: Simulator) -> Self {
        FingerDynamics { sim }
    }

    /// The simulator.
    pub fn simulator(&self) -> &Simulator {
        &self.sim
    }

    /// The simulator, mutably (to change its covariance or reset its warm start).
    pub fn simulator_mut(&mut self) -> &mut Simulator {
        &mut self.sim
    }

    /// Start the simulator's next solve from the solution `[v'; lambda]` of `step`, if given.
    fn resume(&mut self, step: Option<&Step>) {
        if let Some(step) = step {
            let n = self.sim.scene().n_dof();
            let mut z = step.x_next[n..].to_vec();
            z.extend_from_slice(&step.lambda);
            self.sim
                .set_warm_start(&z)
                .expect("a stored solution has the scene's size");
        }
    }
}

impl Dynamics for FingerDynamics {
    type Error = TaskError;
    type Data = StepData;

    fn state_dim(&self) -> usize {
        self.sim.scene().n_state()
    }

    fn control_dim(&self) -> usize {
        self.sim.scene().n_controls
    }

    fn create_data(&self) -> StepData {
        StepData::default()
    }

    fn calc(
        &mut self,
        data: &mut StepData,
        near: Option<&StepData>,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), TaskError> {
        self.resume(near.and_then(StepData::step));
        data.prepared = None;
        data.step = None;
        let s = self.sim.step(x, u)?;
        if s.info.status != ncp::Status::Converged {
            return Err(TaskError::NotConverged(s.info.status));
        }
        next.copy_from_slice(&s.x_next);
        data.step = Some(s);
        Ok(())
    }

    fn calc_diff(
        &mut self,
        data: &mut StepData,
        x: &[f64],
        u: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), TaskError> {
        if let Some(so) = &data.prepared {
            fx.copy_from_slice(&so.derivatives.fx);
            fu.copy_from_slice(&so.derivatives.fu);
            return Ok(());
        }
        let d = match &data.step {
            Some(step) => self.sim.derivatives_of(x, u, step)?,
            None => self.sim.step_with_derivatives(x, u)?.1,
        };
        fx.copy_from_slice(&d.fx);
        fu.copy_from_slice(&d.fu);
        Ok(())
    }

    fn second_order(&mut self) -> Option<&mut dyn SecondOrder<StepData, Error = TaskError>> {
        Some(self)
    }
}

impl SecondOrder<StepData> for FingerDynamics {
    type Error = TaskError;

    fn calc_diff_second(
        &mut self,
        data: &mut StepData,
        x: &[f64],
        u: &[f64],
        c: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), TaskError> {
        if data.prepared.is_none() {
            let so = match &data.step {
                Some(step) => self.sim.second_order_of(x, u, step)?,
                None => self.sim.second_order_step(x, u)?,
            };
            if so.step.info.status != ncp::Status::Converged {
                return Err(TaskError::NotConverged(so.step.info.status));
            }
            data.prepared = Some(so);
        }
        let so = data.prepared.as_ref().expect("prepared above");
        fx.copy_from_slice(&so.derivatives.fx);
        fu.copy_from_slice(&so.derivatives.fu);
        hess.copy_from_slice(&so.hessian(c)?);
        Ok(())
    }
}
