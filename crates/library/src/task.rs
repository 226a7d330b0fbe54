//! The simulator as [`ddp::Dynamics`] for any scene (the task's cost is [`crate::TaskCost`]).

use ddp::{Dynamics, SecondOrder};
use dynamics::{DynamicsError, Model, SecondOrderStep, Simulator, Step};
use thiserror::Error;

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

/// A step [`Model`] as the optimiser's dynamics: [`Dynamics::calc`] is [`Model::step`] in the knot's data,
/// [`Dynamics::calc_diff`] [`Model::derivatives`] of the step stored there, and the second-order
/// capability [`Model::second_order`] of it (any scene).
///
/// Each knot's [`StepData`] holds the model's step data: its step, which the knot's linearisation
/// differentiates as it is (no second solve), and the warm start of the knot's next solve, which `calc`
/// takes from the same knot of the trajectory being improved (`near`) when there is one and otherwise from
/// the knot's own last solution (a fresh knot starts from `[v; 0]`). It also keeps the step's second-order
/// expansion once computed: a backward pass retried with more regularisation at the same trajectory
/// changes only the vector the Hessian is contracted with, and costs the contraction alone.
#[derive(Debug)]
pub struct SceneDynamics {
    model: Model,
}

/// One knot's step, kept by [`SceneDynamics`] (see there).
#[derive(Debug)]
pub struct StepData {
    /// The model's data: the step last computed at the knot, and where the knot's next solve starts.
    data: dynamics::StepData,
    /// That step's second-order expansion, once asked for.
    prepared: Option<SecondOrderStep>,
}

impl StepData {
    /// The step last computed at the knot, if any.
    pub fn step(&self) -> Option<&Step> {
        self.data.step()
    }
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
    type Error = TaskError;
    type Data = StepData;

    fn state_dim(&self) -> usize {
        self.model.scene().n_state()
    }

    fn control_dim(&self) -> usize {
        self.model.scene().n_controls
    }

    fn create_data(&self) -> StepData {
        StepData {
            data: self.model.create_data(),
            prepared: None,
        }
    }

    fn calc(
        &self,
        data: &mut StepData,
        near: Option<&StepData>,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), TaskError> {
        if let Some(near) = near {
            data.data.warm_start_from(&near.data);
        }
        data.prepared = None;
        let s = self.model.step(&mut data.data, x, u)?;
        if s.info.status != ncp::Status::Converged {
            return Err(TaskError::NotConverged(s.info.status));
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
    ) -> Result<(), TaskError> {
        if let Some(so) = &data.prepared {
            fx.copy_from_slice(&so.derivatives.fx);
            fu.copy_from_slice(&so.derivatives.fu);
            return Ok(());
        }
        let d = self.model.derivatives(&data.data)?;
        fx.copy_from_slice(&d.fx);
        fu.copy_from_slice(&d.fu);
        Ok(())
    }

    fn second_order(&self) -> Option<&dyn SecondOrder<StepData, Error = TaskError>> {
        Some(self)
    }
}

impl SecondOrder<StepData> for SceneDynamics {
    type Error = TaskError;

    fn bytes_per_knot(&self) -> usize {
        self.model.second_order_bytes()
    }

    fn calc_diff2_prepare(
        &self,
        data: &mut StepData,
        _x: &[f64],
        _u: &[f64],
    ) -> Result<(), TaskError> {
        if data.prepared.is_none() {
            let so = self.model.second_order(&data.data)?;
            if so.step.info.status != ncp::Status::Converged {
                return Err(TaskError::NotConverged(so.step.info.status));
            }
            data.prepared = Some(so);
        }
        Ok(())
    }

    fn calc_diff2(
        &self,
        data: &mut StepData,
        x: &[f64],
        u: &[f64],
        c: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), TaskError> {
        self.calc_diff2_prepare(data, x, u)?;
        let so = data.prepared.as_ref().expect("prepared above");
        fx.copy_from_slice(&so.derivatives.fx);
        fu.copy_from_slice(&so.derivatives.fu);
        so.hessian_into(c, hess)?;
        Ok(())
    }
}
