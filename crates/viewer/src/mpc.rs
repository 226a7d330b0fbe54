//! Online model-predictive control: every control step re-solves the task's iLQG problem from the current
//! state, warm-started from the previous plan shifted by one step (eq. 19 with `d = 1`), with a fixed
//! budget of passes, and applies the first control. The plan improves over successive steps (a
//! real-time iteration scheme), so one pass per step is enough once it has caught on.

use crate::error::ViewerError;
use ddp::{ControlLimits, Ddp, DdpError, DdpSettings, Solution};
use dynamics::{Complementarity, Scene, Simulator, StepSettings};
use library::Policy;
use task::{Progress, SceneDynamics, Task, TaskCost};

/// The largest regularisation carried from one control step to the next (a solve that gave up at a
/// huge `mu` should not freeze the next ones).
const MU_CARRIED_MAX: f64 = 1e3;
/// Passes of a warm-up ([`OnlineMpc::warm_up`]) spent per control step at most, on top of the usual ones:
/// a fresh plan converges over a few dozen steps instead of stalling the world for one long solve.
pub const WARMUP_PER_STEP: usize = 10;

/// How the online optimiser runs.
#[derive(Debug, Clone, PartialEq)]
pub struct MpcSettings {
    /// Noise scale of its smoothed model.
    pub sigma: f64,
    /// Time step.
    pub h: f64,
    /// Horizon in steps.
    pub horizon: usize,
    /// Optimiser passes per control step.
    pub passes: usize,
}

impl Default for MpcSettings {
    fn default() -> Self {
        MpcSettings {
            sigma: 0.1,
            h: 0.05,
            horizon: 60,
            passes: 1,
        }
    }
}

/// The online optimiser (see the module documentation).
#[derive(Debug)]
pub struct OnlineMpc {
    settings: MpcSettings,
    dynamics: SceneDynamics,
    cost: TaskCost,
    control_limits: Option<ControlLimits>,
    plan: Vec<Vec<f64>>,
    /// The regularisation the last solve ended with: the next starts there, so that a few passes per
    /// step add up to one optimisation rather than restarting its trust region every step.
    mu: f64,
    /// How far the last plan moves the task's progress coordinate forward over the horizon.
    planned_turn: f64,
    /// The task's progress coordinate and its rewarded direction (`None`: no progress to stall on).
    progress: Progress,
    /// Extra passes still owed to a fresh plan.
    warmup: usize,
    /// Optimiser passes run so far.
    passes_run: u64,
}

impl OnlineMpc {
    /// An optimiser for `task` on `scene` (its cost and control limits; its contact model, time step
    /// and horizon are the settings'), with an empty (all zero) plan; the horizon at most
    /// [`MAX_MPC_HORIZON`] steps and the passes at most [`MAX_MPC_PASSES`].
    pub fn new(scene: &Scene, task: &Task, settings: MpcSettings) -> Result<Self, ViewerError> {
        if !(settings.sigma.is_finite() && settings.sigma > 0.0) {
            return Err(ViewerError::Setting {
                name: "sigma",
                value: settings.sigma,
                expected: "finite and positive",
            });
        }
        check_count("horizon", settings.horizon, HORIZON_LIMIT)?;
        check_count("passes", settings.passes, PASSES_LIMIT)?;
        let sim = Simulator::new(
            scene.clone(),
            StepSettings {
                model: Complementarity::Logistic {
                    sigma: settings.sigma,
                },
                h: settings.h,
                ..StepSettings::default()
            },
        )?;
        let progress = Progress::of_task(task)?;
        Ok(OnlineMpc {
            cost: task.cost.clone(),
            control_limits: task.control_limits.clone(),
            plan: vec![vec![0.0; scene.n_controls]; settings.horizon],
            dynamics: SceneDynamics::new(sim),
            settings,
            mu: DdpSettings::default().mu_init,
            planned_turn: 0.0,
            progress,
            warmup: 0,
            passes_run: 0,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &MpcSettings {
        &self.settings
    }

    /// How far the last plan moves the task's progress coordinate forward over its horizon (the finger:
    /// turns the free body, rad; near zero: the optimiser sees no way to spin it from here, a local
    /// minimum). `None` for a task that rewards no progress (a target to reach and hold).
    pub fn planned_turn(&self) -> Option<f64> {
        self.progress.forward.map(|_| self.planned_turn)
    }

    /// The current plan (controls over the horizon).
    pub fn plan(&self) -> &[Vec<f64>] {
        &self.plan
    }

    /// Forget the plan (all zero controls).
    pub fn clear(&mut self) {
        for u in &mut self.plan {
            u.iter_mut().for_each(|e| *e = 0.0);
        }
    }

    /// Seed the plan with `policy` rolled out from `x` on the optimiser's own model (a library gives the
    /// online optimiser a flick to start from).
    pub fn seed_from_policy(&mut self, policy: &Policy, x: &[f64]) -> Result<(), ViewerError> {
        let mut x = x.to_vec();
        let mut next = vec![0.0; x.len()];
        let mut data = ddp::Dynamics::create_data(&self.dynamics);
        for u in &mut self.plan {
            policy.control(&x, u)?;
            ddp::Dynamics::calc(&self.dynamics, &mut data, None, &x, u, &mut next)
                .map_err(|e| ViewerError::Message(format!("seeding the plan: {e}")))?;
            std::mem::swap(&mut x, &mut next);
        }
        Ok(())
    }

    /// Owe the plan up to `passes` extra passes, spent [`WARMUP_PER_STEP`] per control step on top of the
    /// usual ones until a solve converges: what [`OnlineMpc::converge`] does in one long solve, spread over
    /// the next control steps so that no step waits for it (the world's clock keeps running).
    pub fn warm_up(&mut self, passes: usize) {
        self.warmup = passes;
    }

    /// Extra passes still owed to a warm-up.
    pub fn warmup_left(&self) -> usize {
        self.warmup
    }

    /// Optimiser passes run so far by [`OnlineMpc::control`] and [`OnlineMpc::converge`].
    pub fn passes_run(&self) -> u64 {
        self.passes_run
    }

    /// Optimise the plan from `x` to convergence (at most `max_passes`; the first solve from rest takes
    /// about 100 passes, some 150 ms), so that the per-step re-solves start from a flick rather than from
    /// rest. Returns the passes taken. Blocks for the whole solve; a running world uses
    /// [`OnlineMpc::warm_up`].
    pub fn converge(&mut self, x: &[f64], max_passes: usize) -> Result<usize, ViewerError> {
        let sol = self.solve(
            DdpSettings {
                max_iterations: max_passes.max(1),
                control_limits: self.control_limits.clone(),
                ..DdpSettings::default()
            },
            x,
        )?;
        self.passes_run += sol.iterations.len() as u64;
        self.plan = sol.controls;
        Ok(sol.iterations.len())
    }

    /// Optimise the plan from `x`; a plan that cannot even be rolled out from here (after a violent drag,
    /// say) is dropped for one at rest.
    fn solve(&mut self, settings: DdpSettings, x: &[f64]) -> Result<Solution, ViewerError> {
        let ddp = Ddp::new(settings)?;
        match ddp.solve(&self.dynamics, &self.cost, x, &self.plan) {
            Ok(sol) => Ok(sol),
            Err(DdpError::InitialRollout { .. }) => {
                self.clear();
                Ok(ddp.solve(&self.dynamics, &self.cost, x, &self.plan)?)
            }
            Err(e) => Err(e.into()),
        }
    }

    /// Re-solve from `x` and return the first control; the plan moves on by one step.
    pub fn control(&mut self, x: &[f64]) -> Result<Vec<f64>, ViewerError> {
        let extra = self.warmup.min(WARMUP_PER_STEP);
        let sol = self.solve(
            DdpSettings {
                max_iterations: self.settings.passes + extra,
                mu_init: self.mu,
                // Step sizes 1, 0.1, 0.01, 0.001: a control step's worst case stays a few rollouts.
                line_search_steps: 4,
                control_limits: self.control_limits.clone(),
                ..DdpSettings::default()
            },
            x,
        )?;
        self.passes_run += sol.iterations.len() as u64;
        // A warm-up ends early once a solve stops short of its budget (converged).
        self.warmup = if sol.iterations.len() < self.settings.passes + extra {
            0
        } else {
            self.warmup - extra
        };
        self.mu = sol
            .iterations
            .last()
            .map_or(self.mu, |it| it.mu)
            .clamp(0.0, MU_CARRIED_MAX);
        let u = sol.controls[0].clone();
        let c = self.progress.coordinate;
        self.planned_turn =
            self.progress.forward.unwrap_or(0.0) * (sol.states[sol.states.len() - 1][c] - x[c]);
        self.plan = ddp::shift_controls(&sol.controls, 1);
        Ok(u)
    }
}

/// The online optimiser's horizon at most, steps (real time: the control step grows with it, about 40 us
/// per step of horizon and pass on the finger).
pub const MAX_MPC_HORIZON: usize = 2000;
/// The online optimiser's passes per control step at most.
pub const MAX_MPC_PASSES: usize = 100;

/// `Err` unless `1 <= value <= max`, saying `expected` (a limit and its wording, [`HORIZON_LIMIT`]).
pub(crate) fn check_count(
    name: &'static str,
    value: usize,
    (max, expected): (usize, &'static str),
) -> Result<(), ViewerError> {
    if value == 0 || value > max {
        return Err(ViewerError::Setting {
            name,
            value: value as f64,
            expected,
        });
    }
    Ok(())
}

/// [`MAX_MPC_HORIZON`] and how an error states it.
pub(crate) const HORIZON_LIMIT: (usize, &str) = (MAX_MPC_HORIZON, "between 1 and 2000 steps");
/// [`MAX_MPC_PASSES`] and how an error states it.
pub(crate) const PASSES_LIMIT: (usize, &str) = (MAX_MPC_PASSES, "between 1 and 100");
