//! A [`Model`] with one [`StepData`]: one simulation, each step warm-started from the one before.

use crate::constraint::Constraints;
use crate::derivative::{SecondOrderStep, StepDerivatives};
use crate::error::DynamicsError;
use crate::scene::Scene;
use crate::step::{Model, StateCovariance, Step, StepData, StepSettings};
use ncp::LinearMcp;

/// One simulation: a [`Model`] and the one [`StepData`] its steps share, so that each step starts from the
/// solution of the one before (the sequence of a rollout). For steps that must not share a warm start (the
/// knots of a trajectory an optimiser improves), use the model with one data per knot instead.
#[derive(Debug)]
pub struct Simulator {
    model: Model,
    data: StepData,
}

impl Simulator {
    /// A simulator of `scene` with checked settings.
    pub fn new(scene: Scene, settings: StepSettings) -> Result<Self, DynamicsError> {
        Ok(Simulator::from_model(Model::new(scene, settings)?))
    }

    /// A simulator of `model`, with fresh data.
    pub fn from_model(model: Model) -> Self {
        let data = model.create_data();
        Simulator { model, data }
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The model, leaving the data behind.
    pub fn into_model(self) -> Model {
        self.model
    }

    /// The data the steps share: the last step, the warm start, the applied forces.
    pub fn data(&self) -> &StepData {
        &self.data
    }

    /// The data, mutably (to apply forces, [`StepData::set_forces`], or set the warm start).
    pub fn data_mut(&mut self) -> &mut StepData {
        &mut self.data
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        self.model.scene()
    }

    /// The settings.
    pub fn settings(&self) -> &StepSettings {
        self.model.settings()
    }

    /// See [`Model::set_state_covariance`].
    pub fn set_state_covariance(
        &mut self,
        covariance: Option<StateCovariance>,
    ) -> Result<(), DynamicsError> {
        self.model.set_state_covariance(covariance)
    }

    /// Whether rows take their noise from a state covariance.
    pub fn has_state_covariance(&self) -> bool {
        self.model.has_state_covariance()
    }

    /// The state covariance rows take their noise from, if any.
    pub fn state_covariance(&self) -> Option<&StateCovariance> {
        self.model.state_covariance()
    }

    /// See [`StepData::set_warm_start`].
    pub fn set_warm_start(&mut self, z: &[f64]) -> Result<(), DynamicsError> {
        self.data.set_warm_start(z)
    }

    /// See [`StepData::reset_warm_start`].
    pub fn reset_warm_start(&mut self) {
        self.data.reset_warm_start();
    }

    /// See [`Model::problem`].
    pub fn problem(&self, x: &[f64], u: &[f64]) -> Result<(LinearMcp, Constraints), DynamicsError> {
        self.model.problem(x, u)
    }

    /// One step from `x` under the controls `u` ([`Model::step`]), started from the last one's solution.
    pub fn step(&mut self, x: &[f64], u: &[f64]) -> Result<Step, DynamicsError> {
        self.model.step(&mut self.data, x, u).cloned()
    }

    /// One step and its exact derivatives ([`Model::step_with_derivatives`]).
    pub fn step_with_derivatives(
        &mut self,
        x: &[f64],
        u: &[f64],
    ) -> Result<(Step, StepDerivatives), DynamicsError> {
        let d = self.model.step_with_derivatives(&mut self.data, x, u)?;
        Ok((self.last_step()?.clone(), d))
    }

    /// The exact derivatives of the last step ([`Model::derivatives`]), without solving it again.
    pub fn derivatives(&self) -> Result<StepDerivatives, DynamicsError> {
        self.model.derivatives(&self.data)
    }

    /// The last step's [`Model::second_order`], without solving it again.
    pub fn second_order(&self) -> Result<SecondOrderStep, DynamicsError> {
        self.model.second_order(&self.data)
    }

    /// One step and its [`Model::second_order`] ([`Model::second_order_step`]).
    pub fn second_order_step(
        &mut self,
        x: &[f64],
        u: &[f64],
    ) -> Result<SecondOrderStep, DynamicsError> {
        self.model.second_order_step(&mut self.data, x, u)
    }

    /// One step, its first derivatives, and for a given `c` (length `2n`, the value gradient of DDP) the
    /// Hessian of `c^T f(x, u)` with respect to `y = (x, u)`, row-major `(2n + n_u)^2`: the `f_xx`, `f_xu`,
    /// `f_uu` terms contracted with `c`. [`Simulator::second_order_step`] then
    /// [`SecondOrderStep::hessian`]; use those directly to contract one step with several `c`.
    pub fn step_with_hessian(
        &mut self,
        x: &[f64],
        u: &[f64],
        c: &[f64],
    ) -> Result<(Step, StepDerivatives, Vec<f64>), DynamicsError> {
        let so = self.second_order_step(x, u)?;
        let hess = so.hessian(c)?;
        Ok((so.step, so.derivatives, hess))
    }

    fn last_step(&self) -> Result<&Step, DynamicsError> {
        self.data.step().ok_or(DynamicsError::Input {
            what: "simulator",
            problem: "has taken no step".into(),
        })
    }
}
