//! Noise annealing, the paper's own proposal (section VI): solve with a large sigma first, then lower it
//! step by step, warm-starting each solve from the previous controls, so that the contact's action at a
//! distance guides the early solves and the later ones refine a trajectory that already touches.

use crate::error::TaskError;
use crate::problem::Task;
use crate::scene_dynamics::SceneDynamics;
use ddp::{Ddp, DdpSettings};
use dynamics::{Complementarity, Scene, Simulator, StepSettings};
use serde::{Deserialize, Serialize};

/// One solve of a schedule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AnnealStep {
    /// The noise of this solve.
    pub sigma: f64,
    /// Its passes.
    pub passes: usize,
    /// Whether it converged.
    pub converged: bool,
    /// Its cost.
    pub cost: f64,
    /// How far the task's progress coordinate ([`crate::Progress`]) moved over the horizon.
    pub turned: f64,
    /// The optimised controls (the next solve's warm start).
    #[serde(skip)]
    pub controls: Vec<Vec<f64>>,
}

/// Solve `task` from its initial state at each sigma of `schedule` in turn (the logistic model at the
/// task's time step and horizon, within its control limits), each solve warm-started from the previous
/// one's controls (the first from zero).
pub fn anneal(
    scene: &Scene,
    task: &Task,
    schedule: &[f64],
    max_passes: usize,
) -> Result<Vec<AnnealStep>, TaskError> {
    let x0 = task.x0.as_slice();
    crate::check("x0", x0, scene.n_state())?;
    let (h, horizon, cost) = (task.h, task.horizon, &task.cost);
    let free = crate::Progress::of_task(task)?.coordinate;
    let mut controls = vec![vec![0.0; scene.n_controls]; horizon];
    let mut out = Vec::with_capacity(schedule.len());
    for (k, &sigma) in schedule.iter().enumerate() {
        let sim = Simulator::new(
            scene.clone(),
            StepSettings {
                model: Complementarity::Logistic { sigma },
                h,
                ..StepSettings::default()
            },
        )?;
        let sol = Ddp::new(DdpSettings {
            max_iterations: max_passes,
            control_limits: task.control_limits.clone(),
            ..DdpSettings::default()
        })
        .and_then(|d| d.solve(&SceneDynamics::new(sim), cost, x0, &controls))
        .map_err(|source| TaskError::Optimiser { solve: k, source })?;
        controls = sol.controls.clone();
        out.push(AnnealStep {
            sigma,
            passes: sol.iterations.len(),
            converged: sol.status.converged(),
            cost: sol.cost,
            turned: sol.states[horizon][free] - x0[free],
            controls: sol.controls,
        });
    }
    Ok(out)
}
