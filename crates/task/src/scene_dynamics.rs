//! The simulator as [`ddp::Dynamics`] for any scene (the task's cost is [`crate::TaskCost`]).

use ddp::{Dynamics, SecondOrder};
use dynamics::{DynamicsError, Model, Simulator, StepData};
use thiserror::Error;

/// Why a step of the task failed.
#[derive(Debug, Error)]
pub enum StepError {
    /// The simulator refused the input or the derivatives.
    #[error(transparent)]
    Dynamics(#[from] DynamicsError),
    /// The step's complementarity solve did not converge (an optimiser rejects the trial).
    #[error("the step's complementarity solve did not converge: {0:?}")]
    NotConverged(ncp::Status),
}

/// A step [`Model`] as the optimiser's dynamics: each knot's data is the model's [`StepData`],
/// [`Dynamics::calc`] is [`Model::step`] in it, [`Dynamics::calc_diff`] [`Model::calc_diff`] of the step
/// stored there, and the second-order capability [`Model::calc_diff2_prepare`] and [`Model::calc_diff2`]
/// (any scene).
///
/// A knot's data holds its step, which the knot's linearisation differentiates as it is (no second solve),
/// and the warm start of the knot's next solve, which `calc` takes from the same knot of the trajectory
/// being improved (`near`) when there is one and otherwise from the knot's own last solution (a fresh knot
/// starts from `[v; 0]`). It also keeps the step's derivatives once computed: a backward pass retried with
/// more regularisation at the same trajectory changes only the vector the Hessian is contracted with, and
/// costs the contraction alone.
#[derive(Debug)]
pub struct SceneDynamics {
    model: Model,
}

impl SceneDynamics {
    /// The dynamics of a simulator's model (its data is left behind).
    pub fn new(sim: Simulator) -> Self {
        SceneDynamics::from_model(sim.into_model())
    }

    /// The dynamics of `model`.
    pub fn from_model(model: Model) -> Self {
        SceneDynamics { model }
    }

    /// The step model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The step model, mutably (to change its covariance).
    pub fn model_mut(&mut self) -> &mut Model {
        &mut self.model
    }
}

impl Dynamics for SceneDynamics {
    type Error = StepError;
    type Data = StepData;

    fn state_dim(&self) -> usize {
        self.model.scene().n_state()
    }

    fn control_dim(&self) -> usize {
        self.model.scene().n_controls
    }

    fn create_data(&self) -> StepData {
        self.model.create_data()
    }

    fn calc(
        &self,
        data: &mut StepData,
        near: Option<&StepData>,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), StepError> {
        if let Some(near) = near {
            data.warm_start_from(near);
        }
        let s = self.model.step(data, x, u)?;
        if s.info.status != ncp::Status::Converged {
            return Err(StepError::NotConverged(s.info.status));
        }
        next.copy_from_slice(&s.x_next);
        Ok(())
    }

    fn calc_diff(
        &self,
        data: &mut StepData,
        _x: &[f64],
        _u: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), StepError> {
        let d = self.model.calc_diff(data)?;
        fx.copy_from_slice(&d.fx);
        fu.copy_from_slice(&d.fu);
        Ok(())
    }

    fn second_order(&self) -> Option<&dyn SecondOrder<StepData, Error = StepError>> {
        Some(self)
    }
}

impl SecondOrder<StepData> for SceneDynamics {
    type Error = StepError;

    fn bytes_per_knot(&self) -> usize {
        self.model.second_order_bytes()
    }

    fn calc_diff2_prepare(
        &self,
        data: &mut StepData,
        _x: &[f64],
        _u: &[f64],
    ) -> Result<(), StepError> {
        Ok(self.model.calc_diff2_prepare(data)?)
    }

    fn calc_diff2(
        &self,
        data: &mut StepData,
        _x: &[f64],
        _u: &[f64],
        c: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), StepError> {
        let d = self.model.calc_diff2(data, c, hess)?;
        fx.copy_from_slice(&d.fx);
        fu.copy_from_slice(&d.fu);
        Ok(())
    }
}
