//! The trajectory library of paper section IV-C: receding-horizon optimisation from an initial state,
//! keeping each trajectory's first local controller `u(x) = u_1 + K_1 (x - x_1)`, shifting by `d` steps
//! with the warm start of eq. (19), and perturbing the initial state's velocities every few steps.

use crate::entry::{Entry, LocalValue};
use crate::error::LibraryError;
use crate::evaluate::{EvaluationSettings, Judge, Verdict, closed_loop};
use crate::policy::Policy;
use ddp::{Ddp, DdpError, DdpSettings};
use dynamics::{Scene, Simulator, StepSettings};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use task::{ContactModel, Progress, SceneDynamics, Task, TaskCost, TaskError};

/// How a library is built (SCENE.md, paper V-B).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LibrarySettings {
    /// Contact model of the optimiser's dynamics.
    pub model: ContactModel,
    /// Time step.
    pub h: f64,
    /// Optimisation horizon `N`.
    pub horizon: usize,
    /// Shift `d` between consecutive trajectories.
    pub shift: usize,
    /// Number of trajectories (each stores `keep` controllers), before growth.
    pub trajectories: usize,
    /// How the trajectories explore the state space.
    pub exploration: Exploration,
    /// With [`Exploration::Kicks`]: independent receding-horizon chains the trajectories are split into,
    /// built in parallel (one thread each); chain `c` starts from `x0` with kick seed `seed + c` (the
    /// paper's library is one chain). With [`Exploration::Branches`]: threads the branches are built on
    /// (the library is the same for any number).
    pub chains: usize,
    /// With [`Exploration::Kicks`]: perturb the chain's initial state's velocities every this many time
    /// steps.
    pub kick_every: usize,
    /// Variance of each velocity's normal perturbation.
    pub kick_variance: f64,
    /// Seed of the perturbations.
    pub seed: u64,
    /// The first trajectory's initial state; empty (the default): the task's.
    pub x0: Vec<f64>,
    /// Passes at most for the first solve (from zero controls).
    pub first_passes: usize,
    /// Passes at most for each warm-started re-solve.
    pub warm_passes: usize,
    /// The optimiser's stopping tolerance on the relative cost change (`DdpSettings::tol_cost`). The
    /// default 1e-5 builds the library 1.3 to 1.7 times faster than 1e-7 (two regenerations of the
    /// table) with the same closed-loop quality within the spread between seeds (docs/benchmarks.md,
    /// "library tolerance"); 1e-4 saves nothing more (its libraries stall more, so growth adds more),
    /// spins slower and resumes after fewer kicks.
    pub tolerance: f64,
    /// Local controllers kept per trajectory: the paper keeps the first (1); up to `shift` keeps
    /// `u_t + K_t (x - x_t)` for `t < keep` as well, the controllers the trajectory runs before the next one
    /// takes over.
    pub keep: usize,
    /// The policy compares this many nearest controllers by their local value models (1: the nearest
    /// alone, the paper's eq. 20); see [`crate::Policy::select`].
    pub neighbours: usize,
    /// Rounds of growth on the policy's own stalls (see [`Exploration::Branches`]; 0: none).
    pub growth: usize,
    /// The time steps of the growth rounds' closed loops, in turn, each for a round on the library's
    /// model and one on hard contact (rounds 0 and 1 at the first, 2 and 3 at the second, ...; empty: the
    /// library's `h`). The trajectories themselves are always optimised at `h`.
    pub growth_time_steps: Vec<f64>,
    /// A target task's growth branches for a world the library is not built on (a round on hard contact,
    /// or at another time step) are optimised at this fraction of the library's noise scale, in (0, 1]
    /// (1: at its own). The smoothed contact acts at a distance, and a policy built on it alone leaves
    /// hard contact short of the target: the finger stops where the smoothed force would still push
    /// (issue 28, `cargo xtask examples`: the mirrored finger's turn, 0.19-0.24 rad short on hard contact
    /// at every seed, ends 0.049-0.094 from it with 0.25). A task that rewards progress grows at its own
    /// noise scale.
    pub growth_sharpening: f64,
    /// Threads each optimiser differentiates its knots on ([`ddp::DdpSettings::threads`]; at most
    /// [`ddp::MAX_THREADS`]): the same library on any number. They multiply with [`Self::chains`]'
    /// threads (each chain's solves share one pool of this many), so on two cores use one or the other.
    /// A property of the build, not of the library: not kept in its file (a loaded library says 1).
    #[serde(skip, default = "one_thread")]
    pub knot_threads: usize,
}

fn one_thread() -> usize {
    1
}

/// How a library's trajectories explore the state space.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Exploration {
    /// The paper's (V-B): one receding-horizon chain from `x0` whose initial state's velocities are
    /// perturbed every [`LibrarySettings::kick_every`] steps.
    Kicks,
    /// The limit cycle first, then the space around it: an unperturbed receding-horizon chain of `trunk`
    /// trajectories from `x0` (the transient from rest and the cycle it settles on), then branches until
    /// the trajectory budget is spent: each starts from a trunk state drawn past its first `settle`
    /// trajectories, its velocities perturbed (variance [`LibrarySettings::kick_variance`]), and runs a
    /// chain of `length` trajectories warm-started from the trunk's plan there. Then
    /// [`LibrarySettings::growth`] rounds: the policy runs in closed loop from `x0` with a velocity kick
    /// every 10 s, on the library's own model in even rounds and on hard contact in odd ones, at the time
    /// steps of [`LibrarySettings::growth_time_steps`] in turn (a pair of rounds each); wherever the free
    /// angle advances less than [`STALL_ADVANCE`] over the stall window ([`STALL_WINDOW`] seconds, or
    /// [`DWELL_MARGIN`] times the trunk's longest pause if longer), a branch of `length` trajectories at
    /// most (spanning the failure's window: `Build::growth_length`) starts from that state, warm-started
    /// from the plan of the controller the policy used there.
    Branches {
        /// Trajectories of the unperturbed chain.
        trunk: usize,
        /// Trunk trajectories branches do not start from (the transient from rest).
        settle: usize,
        /// Trajectories per branch.
        length: usize,
    },
}

impl Exploration {
    /// The branched recipe's defaults shaped for a budget of `trajectories`: at or above the 400 they were
    /// chosen for, unchanged; below it, a trunk of a quarter of the budget (at least 1), settling over a
    /// quarter of the trunk (less than it), and branches no longer than the budget the trunk leaves (at
    /// least 1). `train --trajectories 20` stopped on `trunk = 100 is out of range`; now any budget the
    /// settings accept has a recipe. The paper's kicked chain has no shape to fit.
    pub fn fitted(self, trajectories: usize) -> Self {
        match self {
            Exploration::Branches {
                trunk,
                settle,
                length,
            } if trunk > trajectories / 4 => {
                let trunk = (trajectories / 4).max(1).min(trunk);
                Exploration::Branches {
                    trunk,
                    settle: settle.min(trunk / 4),
                    length: length.min(trajectories.saturating_sub(trunk).max(1)),
                }
            }
            other => other,
        }
    }
}

/// The second time step the policy is evaluated at and grown for, besides its own (the paper's 0.03 s).
pub const WORLD_TIME_STEP: f64 = 0.03;

/// A growth round's closed loop counts as stalled when the free angle advances less than this (rad) ...
pub use task::STALL_ADVANCE;
/// ... over this many seconds.
pub const STALL_WINDOW: f64 = 2.0;
/// A progress task's growth judges stalls over the longer of [`STALL_WINDOW`] and this multiple of the
/// trunk's longest pause (the time its cycle takes to advance [`STALL_ADVANCE`]: `Build::dwell`).
pub const DWELL_MARGIN: f64 = 1.5;
/// Simulated seconds per growth round: [`GROWTH_FIRST_KICK`] unkicked, then nine kicks 10 s apart and
/// 10 s after the last.
pub const GROWTH_SECONDS: f64 = 130.0;
/// When a growth round's closed loop is first kicked: until then it runs the policy from the task's
/// start as it is, so that growth sees where the unkicked run stalls or misses (a first kick at 10 s
/// hid a rest the three-link finger's policy came to at 10-12 s on its own world: issue 28).
pub const GROWTH_FIRST_KICK: f64 = 40.0;
/// Branches at most per growth round.
pub const GROWTH_BRANCHES: usize = 20;
/// The default [`LibrarySettings::growth_sharpening`].
pub const GROWTH_SHARPENING: f64 = 0.25;

impl Default for LibrarySettings {
    fn default() -> Self {
        LibrarySettings {
            model: ContactModel::Logistic(0.1),
            h: 0.05,
            horizon: 90,
            shift: 4,
            trajectories: 400,
            exploration: Exploration::Branches {
                trunk: 100,
                settle: 25,
                length: 20,
            },
            chains: 1,
            kick_every: 15,
            kick_variance: 4.0,
            seed: 1,
            x0: Vec::new(),
            first_passes: 300,
            warm_passes: 100,
            tolerance: 1e-5,
            keep: 4,
            neighbours: 8,
            growth: 12,
            growth_time_steps: vec![0.05, 0.03],
            growth_sharpening: GROWTH_SHARPENING,
            knot_threads: 1,
        }
    }
}

impl LibrarySettings {
    /// The paper's recipe (V-B, IV-C): horizon 75, one chain kicked every 15 steps, the first controller
    /// of each trajectory, the nearest controller's law.
    pub fn paper() -> Self {
        LibrarySettings {
            horizon: 75,
            exploration: Exploration::Kicks,
            keep: 1,
            neighbours: 1,
            growth: 0,
            growth_time_steps: Vec::new(),
            ..LibrarySettings::default()
        }
    }
}

impl LibrarySettings {
    /// This recipe on `task`'s contact model, time step and initial state, with the longer of the task's
    /// horizon and the recipe's. Growth's closed loops,
    /// if any, run at the task's time step and at 0.03 s, the worlds `evaluate` runs the policy on (for a
    /// task that rewards progress, growth branches where the policy stalls; for a target task, where it
    /// is not back at its targets in time after a kick).
    pub fn for_task(self, task: &Task) -> Self {
        let growth_time_steps = if self.growth_time_steps.is_empty() {
            Vec::new()
        } else if task.h == WORLD_TIME_STEP {
            vec![task.h]
        } else {
            vec![task.h, WORLD_TIME_STEP]
        };
        LibrarySettings {
            model: task.model,
            h: task.h,
            // The longer of the task's horizon and the recipe's: a receding-horizon library looks further
            // ahead than a single solve needs (the finger's spin task, horizon 75, built at 75 settled on
            // slow cycles of 0.31-0.35 rad/s on 5 of 16 world-seeds; at the recipe's 90, 0.97-1.25 rad/s,
            // in half the build time).
            horizon: task.horizon.max(self.horizon),
            x0: task.x0.clone(),
            growth_time_steps,
            ..self
        }
    }

    /// This recipe shaped for a budget of `trajectories`: the exploration [`Exploration::fitted`] to it,
    /// and at most one growth round per 32 trajectories of budget (the default 12 rounds from 384 on), so
    /// that growth, which adds up to [`GROWTH_BRANCHES`] branches a round, stays in proportion to the
    /// library asked for.
    pub fn fitted(self, trajectories: usize) -> Self {
        LibrarySettings {
            trajectories,
            exploration: self.exploration.fitted(trajectories),
            growth: self.growth.min(trajectories / 32),
            ..self
        }
    }

    /// `Err` naming the first setting out of range.
    pub fn validate(&self, scene: &Scene) -> Result<(), LibraryError> {
        let bad = |name, value: f64, expected| {
            Err(LibraryError::Setting {
                name,
                value,
                expected,
            })
        };
        if !(self.h.is_finite() && self.h > 0.0) {
            return bad("h", self.h, "finite and positive");
        }
        if let ContactModel::Logistic(s) | ContactModel::Normal(s) = self.model
            && !(s.is_finite() && s > 0.0)
        {
            return bad("sigma", s, "finite and positive");
        }
        // A bound on the work: every trajectory is a solve over the horizon (a stalled trunk is
        // lengthened to no more than this either).
        if !(1..=LONGEST_HORIZON).contains(&self.horizon) {
            return bad(
                "horizon",
                self.horizon as f64,
                "between 1 and 1000 steps (LONGEST_HORIZON)",
            );
        }
        if self.shift == 0 || self.shift > self.horizon {
            return bad("shift", self.shift as f64, "between 1 and the horizon");
        }
        if self.trajectories == 0 {
            return bad("trajectories", 0.0, "at least 1");
        }
        if self.chains == 0 || self.chains > self.trajectories {
            return bad(
                "chains",
                self.chains as f64,
                "between 1 and the number of trajectories",
            );
        }
        if !(1..=ddp::MAX_THREADS).contains(&self.knot_threads) {
            return bad("knot_threads", self.knot_threads as f64, "from 1 to 256");
        }
        if self.kick_every == 0 {
            return bad("kick_every", 0.0, "at least 1");
        }
        if !(self.kick_variance.is_finite() && self.kick_variance >= 0.0) {
            return bad(
                "kick_variance",
                self.kick_variance,
                "finite and non-negative",
            );
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return bad("tolerance", self.tolerance, "finite and positive");
        }
        if self.keep == 0 || self.keep > self.shift {
            return bad("keep", self.keep as f64, "between 1 and the shift");
        }
        if self.first_passes == 0 || self.warm_passes == 0 {
            return bad("first_passes / warm_passes", 0.0, "at least 1");
        }
        if self.neighbours == 0 || self.neighbours > MAX_NEIGHBOURS {
            return bad("neighbours", self.neighbours as f64, "between 1 and 64");
        }
        if self.trajectories > MAX_TRAJECTORIES {
            return bad("trajectories", self.trajectories as f64, "at most 1e6");
        }
        if self.growth > MAX_GROWTH {
            return bad("growth", self.growth as f64, "at most 100 rounds");
        }
        if self.growth_time_steps.len() > MAX_GROWTH {
            return bad(
                "growth_time_steps",
                self.growth_time_steps.len() as f64,
                "at most 100 time steps",
            );
        }
        if let Some(&h) = self
            .growth_time_steps
            .iter()
            .find(|h| !(h.is_finite() && **h > 0.0 && **h <= 1.0))
        {
            return bad(
                "growth_time_steps",
                h,
                "each finite, positive and at most 1 s",
            );
        }
        if !(self.growth_sharpening > 0.0 && self.growth_sharpening <= 1.0) {
            return bad(
                "growth_sharpening",
                self.growth_sharpening,
                "in (0, 1]: a fraction of the library's noise scale",
            );
        }
        if let Exploration::Branches {
            trunk,
            settle,
            length,
        } = self.exploration
        {
            if trunk == 0 || trunk > self.trajectories {
                return bad(
                    "trunk",
                    trunk as f64,
                    "between 1 and the number of trajectories",
                );
            }
            if settle >= trunk {
                return bad("settle", settle as f64, "less than the trunk");
            }
            if length == 0 {
                return bad("length", 0.0, "at least 1");
            }
        }
        if self.x0.is_empty() {
            return Ok(());
        }
        crate::check("x0", &self.x0, scene.n_state())
    }

    /// The simulator these settings build on.
    pub fn simulator(&self, scene: &Scene) -> Result<Simulator, LibraryError> {
        Ok(Simulator::new(
            scene.clone(),
            StepSettings {
                model: self.model.complementarity(),
                h: self.h,
                ..StepSettings::default()
            },
        )?)
    }
}

/// The largest [`LibrarySettings::neighbours`].
pub const MAX_NEIGHBOURS: usize = 64;
const MAX_TRAJECTORIES: usize = 1_000_000;
const MAX_GROWTH: usize = 100;

/// The local value models of the first `keep` knots of `sol` (see [`LocalValue`]), for the free angle at
/// index `free` with period `period`.
pub(crate) fn local_values(
    sol: &ddp::Solution,
    cost: &impl ddp::Cost,
    keep: usize,
    free: usize,
    period: f64,
) -> Vec<LocalValue> {
    let horizon = sol.controls.len();
    let (n, m) = (sol.states[0].len(), sol.controls[0].len());
    let last = &sol.states[horizon];
    let idle = vec![0.0; m];
    let mut cd = ddp::CostDerivatives::zeros(n, m);
    // The value's slope along the free angle from knot t: every remaining cost term's (summed from the
    // end), plus t idling terms'.
    let (mut lfx, mut lfxx) = (vec![0.0; n], vec![0.0; n * n]);
    cost.terminal_derivatives(last, &mut lfx, &mut lfxx);
    let mut remaining = vec![lfx[free]; horizon + 1];
    for i in (0..horizon).rev() {
        cost.running_derivatives(i, &sol.states[i], &sol.controls[i], &mut cd);
        remaining[i] = remaining[i + 1] + cd.lx[free];
    }
    cost.running_derivatives(horizon - 1, last, &idle, &mut cd);
    let idle_slope = cd.lx[free];
    let idle_cost = cost.running(horizon - 1, last, &idle);
    (0..keep)
        .map(|t| {
            let v = &sol.values[t];
            LocalValue {
                cost_to_go: v.cost_to_go + t as f64 * idle_cost,
                gradient: v.gradient.clone(),
                hessian: v.hessian.clone(),
                per_period: (remaining[t] + t as f64 * idle_slope) * period,
            }
        })
        .collect()
}

/// Build the entries of a library for `task` on `scene` (see the module documentation and
/// [`Exploration`]): its cost, control limits, periodic coordinate and success criterion; the settings'
/// `model`, `h`, `horizon` and `x0` rule (an empty `x0` is the task's; [`LibrarySettings::for_task`]
/// takes all four from the task). The entries come in an order that depends on the settings alone,
/// whatever order threads finish in. `progress` sees each trajectory's first entry as it is made, with
/// the number of trajectories done so far.
pub fn build_entries(
    scene: &Scene,
    task: &Task,
    settings: &LibrarySettings,
    progress: impl FnMut(usize, &Entry) + Send,
) -> Result<Entries, LibraryError> {
    settings.validate(scene)?;
    let mut resolved;
    let settings = if settings.x0.is_empty() {
        resolved = settings.clone();
        resolved.x0 = task.x0.clone();
        &resolved
    } else {
        settings
    };
    let task = Build::new(scene, task, settings)?;
    let done = std::sync::Mutex::new((0usize, progress));
    let report = |entry: &Entry| {
        let mut guard = done.lock().unwrap_or_else(|e| e.into_inner());
        let (count, progress) = &mut *guard;
        progress(*count, entry);
        *count += 1;
    };
    let built = match settings.exploration {
        Exploration::Kicks => Entries {
            entries: kicked_chains(&task, &report)?,
            horizon: settings.horizon,
        },
        Exploration::Branches {
            trunk,
            settle,
            length,
        } => branched(&task, trunk, settle, length, &report)?,
    };
    // A library whose every solve stopped before its first pass holds the starting controls, not
    // optimised ones: refused, not saved as if it were a controller.
    if built.entries.iter().all(|e| e.passes == 0 && !e.converged) {
        return Err(LibraryError::NothingOptimised {
            trajectories: built.entries.len().div_ceil(settings.keep.max(1)),
        });
    }
    Ok(built)
}

/// What [`build_entries`] made: the entries, and the horizon their trajectories were solved over (the
/// settings' own, or a longer one where the trunk stalled at it: [`HORIZON_DOUBLINGS`]).
#[derive(Debug, Clone)]
pub struct Entries {
    /// The library's controllers.
    pub entries: Vec<Entry>,
    /// The horizon every trajectory was solved over.
    pub horizon: usize,
}

/// How many times a build doubles its horizon when the trunk of a progress task stalls: a receding
/// horizon too short to see past the next contact can settle where the task cannot go on (a paddle that
/// stops a wheel with its long end out of reach, `stalled_trunk_lengthens_the_horizon`), and the
/// policy then stalls there on every world; growth cannot mend that, because every solve from the
/// stalled state finds nothing to do within the horizon.
pub const HORIZON_DOUBLINGS: usize = 2;
/// The longest horizon a stalled trunk is lengthened to.
pub const LONGEST_HORIZON: usize = 1000;

/// `Err` naming the reason when the task cannot have a library of controllers on `scene`: the scene
/// has no control to feed back, or the cost rewards nothing (no state term, so every trajectory's
/// best is to do nothing).
fn check_for_library(task: &Task, scene: &Scene) -> Result<(), LibraryError> {
    let refuse = |field: &str, problem: &str| {
        Err(LibraryError::Task(TaskError::Spec {
            task: task.name.clone(),
            field: field.to_string(),
            problem: problem.to_string(),
        }))
    };
    if scene.n_controls == 0 {
        return refuse(
            "",
            "the scene has no actuated joint: a library stores feedback controllers and there is nothing to control",
        );
    }
    let weighs = task
        .cost
        .running
        .iter()
        .chain(&task.cost.final_terms)
        .any(|t| t.linear != 0.0 || t.quadratic != 0.0);
    if !weighs {
        return refuse(
            "running",
            "the cost rewards nothing (no running or final term with a non-zero weight): the best control is none, and a library of it is empty of purpose",
        );
    }
    Ok(())
}

/// `cost` with its running terms and control weight scaled by `ratio` (the final terms as they are):
/// the task's per-step cost for a time step `ratio` times the task's, the same integral over time.
fn scaled_running(cost: &TaskCost, ratio: f64) -> TaskCost {
    if ratio == 1.0 {
        return cost.clone();
    }
    let mut scaled = cost.clone();
    for t in &mut scaled.running {
        t.linear *= ratio;
        t.quadratic *= ratio;
    }
    scaled.control_weight *= ratio;
    scaled
}

/// `plan`, a control sequence at time step `from`, held piecewise constant and sampled at time step
/// `to` over `horizon` steps (its last control repeated past its end): the warm start of a branch
/// optimised at another time step than the plan it starts from.
fn resampled(plan: &[Vec<f64>], from: f64, to: f64, horizon: usize) -> Vec<Vec<f64>> {
    if from == to && plan.len() == horizon {
        return plan.to_vec();
    }
    let Some(last) = plan.len().checked_sub(1) else {
        return Vec::new();
    };
    (0..horizon)
        .map(|k| {
            // The plan's step holding time k to (rounding-safe at the shared instants).
            let j = ((k as f64 * to + 1e-9 * to) / from).floor() as usize;
            plan[j.min(last)].clone()
        })
        .collect()
}

/// What every chain of a build shares.
struct Build<'a> {
    scene: &'a Scene,
    settings: &'a LibrarySettings,
    cost: TaskCost,
    progress: Progress,
    /// The state entries its policy compares modulo a turn ([`Task::turn_symmetries`]).
    turns: Vec<(usize, f64)>,
    success: task::Success,
    control_limits: Option<ddp::ControlLimits>,
    kick: Normal<f64>,
}

/// Trajectories built so far: `keep` entries each, and each one's plan (the warm start of branches that
/// start near it).
#[derive(Default, Clone)]
struct Built {
    entries: Vec<Entry>,
    plans: Vec<Vec<Vec<f64>>>,
}

impl Built {
    fn append(&mut self, other: Built) {
        self.entries.extend(other.entries);
        self.plans.extend(other.plans);
    }
}

impl<'a> Build<'a> {
    fn new(
        scene: &'a Scene,
        task: &Task,
        settings: &'a LibrarySettings,
    ) -> Result<Self, LibraryError> {
        task.check_scene(scene)?;
        check_for_library(task, scene)?;
        let progress = Progress::of_task(task)?;
        let cost = task.cost.clone();
        let control_limits = task.control_limits.clone();
        let success = task.success.clone();
        Ok(Build {
            scene,
            settings,
            cost,
            progress,
            turns: task.turn_symmetries(scene),
            success,
            control_limits,
            kick: Normal::new(0.0, settings.kick_variance.sqrt())
                .map_err(|e| LibraryError::Invalid(e.to_string()))?,
        })
    }

    /// The same build under other settings (a longer horizon; another time step, for which the running
    /// cost is scaled by the ratio of the steps, so that a solve over the same time weighs the same
    /// integral and its values compare with the library's own: [`scaled_running`]).
    fn with_settings<'b>(&self, settings: &'b LibrarySettings) -> Build<'b>
    where
        'a: 'b,
    {
        Build {
            scene: self.scene,
            settings,
            cost: scaled_running(&self.cost, settings.h / self.settings.h),
            progress: self.progress,
            turns: self.turns.clone(),
            success: self.success.clone(),
            control_limits: self.control_limits.clone(),
            kick: self.kick,
        }
    }

    /// How far a trunk of `trunk` trajectories advanced the progress coordinate the rewarded way from
    /// trajectory `from` to its last; 0 for a target task.
    fn advance(&self, built: &Built, trunk: usize, from: usize) -> f64 {
        let (Some(forward), Some(last)) = (self.progress.forward, trunk.checked_sub(1)) else {
            return 0.0;
        };
        forward * (self.coordinate_at(built, last) - self.coordinate_at(built, from.min(last)))
    }

    /// The build's first solve `start`, finished as `optimize` finishes its solve
    /// ([`task::ContactProblem::finish`], on one optimiser): its contact searched for unless it already
    /// ends within a target task's tolerance (it then needs none), a progress task's stalled plan explored
    /// from smooth random starts, an unconverged solve continued under the other regularisation.
    fn finish_first_solve(
        &self,
        settings: &StepSettings,
        x1: &[f64],
        start: ddp::Solution,
        passes: usize,
    ) -> Result<ddp::Solution, LibraryError> {
        let ddp = self.optimiser(passes, 0)?;
        let stages = task::Stages {
            search: !self.settles(&start),
            ..task::Stages::ALL
        };
        let finished = self.contact_problem(&ddp, settings, x1).finish(
            start,
            &self.progress,
            stages,
            log_continuation,
        )?;
        if let Some(search) = &finished.search {
            log_reach(search);
        }
        if let Some(e) = finished.explored.as_ref().filter(|e| e.tried > 0) {
            tracing::info!(
                tried = e.tried,
                kept = e.kept,
                cost = e.solution.cost,
                "library first solve explored"
            );
        }
        if let Some(o) = finished.other.as_ref().filter(|o| o.tried) {
            tracing::info!(
                regularisation = ?o.regularisation,
                cost = o.cost,
                kept = o.kept,
                "library first solve under the other regularisation"
            );
        }
        Ok(finished.solution)
    }

    /// The task's contact searches from `x1` under `settings` with the optimiser `ddp`.
    fn contact_problem<'p>(
        &'p self,
        ddp: &'p Ddp,
        settings: &'p StepSettings,
        x1: &'p [f64],
    ) -> task::ContactProblem<'p> {
        task::ContactProblem {
            ddp,
            scene: self.scene,
            settings,
            cost: &self.cost,
            x0: x1,
        }
    }

    /// Whether a progress task's plan `sol` stalls ([`task::plan_stalls`]).
    fn plan_stalls(&self, sol: &ddp::Solution) -> bool {
        task::plan_stalls(&self.progress, sol)
    }

    /// The progress coordinate at the start of trajectory `j`.
    fn coordinate_at(&self, built: &Built, j: usize) -> f64 {
        built.entries[j * self.settings.keep].x[self.progress.coordinate]
    }

    /// Whether a progress task's trunk stalls: over its last [`STALL_WINDOW`] seconds (when it runs that
    /// long past its first `settle` trajectories) the progress coordinate advances less than
    /// [`STALL_ADVANCE`] the rewarded way, the growth rounds' criterion.
    fn stalls(&self, built: &Built, trunk: usize, settle: usize) -> bool {
        let s = self.settings;
        let window = (STALL_WINDOW / (s.shift as f64 * s.h)).ceil() as usize;
        self.progress.forward.is_some()
            && trunk > settle + window
            && self.advance(built, trunk, trunk - 1 - window) < STALL_ADVANCE
    }

    /// The trunk's longest dwell: over the trunk's trajectories past its first `settle`, the longest time
    /// (s) from one's start until the progress coordinate has advanced [`STALL_ADVANCE`] the rewarded way,
    /// over the starts from which it does before the trunk ends; `None` for a target task or a trunk that
    /// never advances that far.
    fn dwell(&self, built: &Built, trunk: usize, settle: usize) -> Option<f64> {
        let forward = self.progress.forward?;
        let s = self.settings;
        let at = |j: usize| self.coordinate_at(built, j);
        (settle..trunk)
            .filter_map(|i| {
                (i + 1..trunk)
                    .find(|&j| forward * (at(j) - at(i)) >= STALL_ADVANCE)
                    .map(|j| (j - i) as f64 * s.shift as f64 * s.h)
            })
            .reduce(f64::max)
    }

    /// Whether a target task's solve ends within the task's success tolerance of its targets (never for
    /// a task that rewards progress).
    fn settles(&self, sol: &ddp::Solution) -> bool {
        self.progress.forward.is_none() && sol.states.last().is_some_and(|x| self.success.within(x))
    }

    /// Trajectories per growth branch: as many as span the window the task's failure is judged over,
    /// at most `length` (the recipe's branches off the trunk). A progress task's stall is judged over
    /// [`STALL_WINDOW`] (10 trajectories of 4 steps at 0.05 s): its branch only has to lead the policy
    /// back onto the cycle the library covers. A target task's miss is judged [`task::Success::settle`]
    /// seconds after a kick (25 such trajectories at the default 5 s): its branch has to carry the task all
    /// the way back. (Issue 28: 10 trajectories for every task cut the three-link finger's builds by a
    /// fifth with 2 more kicked runs recovered, but the slider's kicked runs fell from 14 of 16 to 8.)
    fn growth_length(&self, length: usize) -> usize {
        let s = self.settings;
        let window = match self.progress.forward {
            Some(_) => STALL_WINDOW,
            None => self.success.settle,
        };
        // Rounded, not ceiled: 2 s over 4 steps of 0.05 s must not become 11 at a rounding error.
        let trajectories = (window / (s.shift as f64 * s.h)).round();
        // A window that is not a finite positive time (a settle of 0, say) leaves the recipe's length.
        if trajectories.is_finite() && trajectories >= 1.0 {
            length.min(trajectories as usize)
        } else {
            length
        }
    }

    fn dynamics(&self) -> Result<SceneDynamics, LibraryError> {
        Ok(SceneDynamics::new(self.settings.simulator(self.scene)?))
    }

    /// Add the velocity perturbation to `x`.
    fn perturb(&self, x: &mut [f64], rng: &mut ChaCha8Rng) {
        for v in &mut x[self.scene.n_dof()..] {
            *v += self.kick.sample(rng);
        }
    }

    /// A receding-horizon chain of `count` trajectories from `x1`, the first warm-started from `controls`
    /// (from zero controls if `first`, with the larger pass budget); `perturb(k, x)` may change the next
    /// trajectory's initial state after trajectory `k`.
    #[allow(clippy::too_many_arguments)]
    fn chain(
        &self,
        dynamics: &mut SceneDynamics,
        mut x1: Vec<f64>,
        mut controls: Vec<Vec<f64>>,
        count: usize,
        first: bool,
        mut perturb: impl FnMut(usize, &mut [f64]),
        report: &(dyn Fn(&Entry) + Sync),
    ) -> Result<Built, LibraryError> {
        let s = self.settings;
        let mut out = Built::default();
        for k in 0..count {
            let span = tracing::info_span!("library.trajectory", k);
            let _guard = span.enter();
            let passes = if first && k == 0 {
                s.first_passes
            } else {
                s.warm_passes
            };
            let mut sol = self.solve(dynamics, &x1, &controls, passes, k)?;
            // The build's first solve, and the first of every chain of a target task (a branch from a
            // state the policy left off target, perhaps with the contact out of reach), unless it ends
            // within the task's tolerance: then it needs no contact, and teaches the policy to let be
            // (issue 28: 6 of pushing's 207 fruitless searches in one build).
            if first && k == 0 {
                let settings = *dynamics.model().settings();
                sol = self.finish_first_solve(&settings, &x1, sol, passes)?;
            } else if k == 0 && self.progress.forward.is_none() && !self.settles(&sol) {
                let settings = *dynamics.model().settings();
                let found;
                (sol, found) = self.reach(&settings, &x1, sol, passes)?;
                // A branch that never touches teaches the policy nothing: it already does nothing there.
                if !found {
                    break;
                }
            } else if k > 0 && self.plan_stalls(&sol) {
                // A progress task's receding horizon that has let go of its contact: a finger without
                // gravity swings clear after a flick, and from there no solve feels the contact (its
                // gradient is zero), so the chain would rest for ever. Reached for as on the first solve;
                // kept only where a cheaper solve feels it.
                let settings = *dynamics.model().settings();
                (sol, _) = self.reach(&settings, &x1, sol, passes)?;
            }
            let p = self.progress;
            let values = local_values(
                &sol,
                &self.cost,
                s.keep,
                p.coordinate,
                p.period.unwrap_or(0.0),
            );
            for (t, value) in values.into_iter().enumerate() {
                let entry = Entry {
                    x: sol.states[t].clone(),
                    u: sol.controls[t].clone(),
                    gain: sol.gains[t].clone(),
                    passes: sol.iterations.len() as u32,
                    converged: sol.status.converged(),
                    cost: sol.cost,
                    value,
                    reach: None,
                    time_step: s.h,
                };
                if t == 0 {
                    report(&entry);
                }
                out.entries.push(entry);
            }
            // Receding horizon (eq. 19): the next trajectory starts d steps on, warm-started by the
            // shifted controls.
            x1 = sol.states[s.shift].clone();
            controls = ddp::shift_controls(&sol.controls, s.shift);
            perturb(k, &mut x1);
            out.plans.push(sol.controls);
        }
        Ok(out)
    }

    /// A chain's first solve, checked for the contact its task needs ([`task::contact_felt`]) under
    /// `settings` (the chain's dynamics). Where none is felt, the contact is reached for: first by
    /// pulling each needed pair together ([`task::ContactProblem::reach_for_contact`]), then, for a smoothed model
    /// where no pull found a cheaper solve that feels it, by continuation in the noise scale
    /// ([`task::ContactProblem::continue_in_noise`]). Either replaces the solve only with one that feels the contact
    /// and costs less; a first solve that touches (the finger's, for one) is left as it was. Also
    /// whether the solve returned feels the contact.
    fn reach(
        &self,
        settings: &StepSettings,
        x1: &[f64],
        sol: ddp::Solution,
        passes: usize,
    ) -> Result<(ddp::Solution, bool), LibraryError> {
        let ddp = self.optimiser(passes, 0)?;
        let search = self
            .contact_problem(&ddp, settings, x1)
            .feel_contact(sol, log_continuation)?;
        log_reach(&search);
        let found = search.found();
        Ok((search.solution, found))
    }

    /// The build's optimiser with `passes` at most: its tolerance and its task's control limits
    /// (errors name trajectory `k`).
    fn optimiser(&self, passes: usize, k: usize) -> Result<Ddp, LibraryError> {
        Ddp::new(DdpSettings {
            max_iterations: passes,
            tol_cost: self.settings.tolerance,
            control_limits: self.control_limits.clone(),
            threads: self.settings.knot_threads,
            ..DdpSettings::default()
        })
        .map_err(|source| LibraryError::Optimiser {
            trajectory: k,
            source,
        })
    }

    fn solve(
        &self,
        dynamics: &mut SceneDynamics,
        x1: &[f64],
        controls: &[Vec<f64>],
        passes: usize,
        k: usize,
    ) -> Result<ddp::Solution, LibraryError> {
        let failed = |source| LibraryError::Optimiser {
            trajectory: k,
            source,
        };
        let ddp = self.optimiser(passes, k)?;
        match ddp.solve(dynamics, &self.cost, x1, controls) {
            Ok(sol) => Ok(sol),
            Err(DdpError::InitialRollout { .. })
                if controls.iter().flatten().any(|&u| u != 0.0) =>
            {
                let zero = vec![vec![0.0; self.scene.n_controls]; controls.len()];
                ddp.solve(dynamics, &self.cost, x1, &zero).map_err(failed)
            }
            Err(source) => Err(failed(source)),
        }
    }
}

/// `count` jobs on `threads` threads (job `j` on thread `j % threads`), results in job order.
fn in_parallel<T: Send>(
    count: usize,
    threads: usize,
    job: impl Fn(usize) -> Result<T, LibraryError> + Sync,
) -> Result<Vec<T>, LibraryError> {
    let threads = threads.clamp(1, count.max(1));
    if threads == 1 {
        return (0..count).map(job).collect();
    }
    let job = &job;
    let mut slots: Vec<Option<Result<T, LibraryError>>> = (0..count).map(|_| None).collect();
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|c| {
                scope.spawn(move || {
                    (c..count)
                        .step_by(threads)
                        .map(|j| (j, job(j)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for h in handles {
            match h.join() {
                Ok(done) => {
                    for (j, r) in done {
                        slots[j] = Some(r);
                    }
                }
                Err(_) => {
                    return Err(LibraryError::Invalid("a build thread panicked".into()));
                }
            }
        }
        Ok(())
    })?;
    slots
        .into_iter()
        .map(|r| r.unwrap_or_else(|| Err(LibraryError::Invalid("a build job was lost".into()))))
        .collect()
}

/// The paper's exploration: `chains` kicked chains (chain `c` with kick seed `seed + c`), in chain order.
fn kicked_chains(
    task: &Build,
    report: &(dyn Fn(&Entry) + Sync),
) -> Result<Vec<Entry>, LibraryError> {
    let s = task.settings;
    let (chains, trajectories) = (s.chains, s.trajectories);
    let built = in_parallel(chains, chains, |c| {
        let length = trajectories / chains + usize::from(c < trajectories % chains);
        let mut rng = ChaCha8Rng::seed_from_u64(s.seed.wrapping_add(c as u64));
        let mut since_kick = 0usize;
        let zero = vec![vec![0.0; task.scene.n_controls]; s.horizon];
        task.chain(
            &mut task.dynamics()?,
            s.x0.clone(),
            zero,
            length,
            true,
            |_, x1| {
                since_kick += s.shift;
                if since_kick >= s.kick_every {
                    since_kick -= s.kick_every;
                    task.perturb(x1, &mut rng);
                }
            },
            report,
        )
    })?;
    Ok(built.into_iter().flat_map(|b| b.entries).collect())
}

/// The cycle-first exploration of [`Exploration::Branches`], then growth. For a task that rewards
/// progress, a trunk that stalls ([`Build::stalls`]) is built again over twice the horizon, at most
/// [`HORIZON_DOUBLINGS`] times, and the trunk that advanced furthest is kept with its horizon, which every
/// branch after it uses.
fn branched(
    task: &Build,
    trunk: usize,
    settle: usize,
    length: usize,
    report: &(dyn Fn(&Entry) + Sync),
) -> Result<Entries, LibraryError> {
    let mut best: Option<(f64, LibrarySettings, Built)> = None;
    let mut settings = task.settings.clone();
    let mut dynamics = task.dynamics()?;
    for doubling in 0..=HORIZON_DOUBLINGS {
        let this = task.with_settings(&settings);
        let zero = vec![vec![0.0; this.scene.n_controls]; settings.horizon];
        // Progress counts the trunk once: a lengthened trunk, which replaces the first, is not reported.
        let silent = |_: &Entry| {};
        let built = this.chain(
            &mut dynamics,
            settings.x0.clone(),
            zero,
            trunk,
            true,
            |_, _| {},
            if doubling == 0 { report } else { &silent },
        )?;
        let advance = this.advance(&built, trunk, settle);
        let stalls = this.stalls(&built, trunk, settle);
        tracing::info!(horizon = settings.horizon, advance, stalls, "library trunk");
        if best.as_ref().is_none_or(|(a, ..)| advance > *a) {
            best = Some((advance, settings.clone(), built));
        }
        if !stalls || doubling == HORIZON_DOUBLINGS || settings.horizon * 2 > LONGEST_HORIZON {
            break;
        }
        settings.horizon *= 2;
    }
    let Some((_, settings, mut built)) = best else {
        return Err(LibraryError::Invalid("a build made no trunk".into()));
    };
    let task = task.with_settings(&settings);
    let task = &task;
    let s = &settings;
    // A stall is a pause longer than any the trunk's own cycle makes (the three-link finger's cycle
    // pauses 3.2 s between flicks; judged over 2 s, every cycle of it stalled and growth never tapered).
    let dwell = task.dwell(&built, trunk, settle);
    let stall_window = dwell.map_or(STALL_WINDOW, |d| STALL_WINDOW.max(DWELL_MARGIN * d));
    tracing::info!(?dwell, stall_window, "library trunk dwell");
    // Branches off the trunk, the budget's remainder split into chains of `length` (the last shorter).
    let rest = s.trajectories - trunk;
    let count = rest.div_ceil(length);
    let trunk_built = &built;
    let branches = in_parallel(count, s.chains, |b| {
        let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
        rng.set_stream(b as u64 + 1);
        let j = rng.random_range(settle..trunk);
        let mut x1 = trunk_built.entries[j * s.keep].x.clone();
        task.perturb(&mut x1, &mut rng);
        let this = length.min(rest - b * length);
        let plan = trunk_built.plans[j].clone();
        task.chain(
            &mut task.dynamics()?,
            x1,
            plan,
            this,
            false,
            |_, _| {},
            report,
        )
    })?;
    for b in branches {
        built.append(b);
    }
    let mut run = |built: &mut Built, kind| {
        grow(
            task,
            &mut dynamics,
            built,
            length,
            stall_window,
            kind,
            report,
        )
    };
    for round in 0..s.growth {
        let grown = run(&mut built, Round::Kicked(round))?;
        tracing::info!(round, grown, "library growth");
    }
    if s.growth > 0 {
        // Every world the rounds ran on, from the task's start without kicks, with the policy as it
        // finally is: the rounds after a world's last one changed the policy there too. A pass's
        // branches can mend one world and break another: the library kept is the one, of those before
        // and after each pass, on which the most worlds succeed (the latest of equals), and passes past
        // the first VERIFY_PASSES are made only while a world still fails.
        let worlds = 2 * s.growth_time_steps.len().max(1);
        let succeeding = |built: &Built| -> Result<usize, LibraryError> {
            let mut count = 0;
            for world in 0..worlds {
                count += usize::from(unkicked(task, built, world)?.passed);
            }
            Ok(count)
        };
        let mut best = succeeding(&built)?;
        tracing::info!(succeeding = best, worlds, "library verification");
        // The best library so far where it is not the current one.
        let mut kept: Option<Built> = None;
        for pass in 0..VERIFY_PASSES_MOST {
            if pass >= VERIFY_PASSES && best == worlds {
                break;
            }
            let before = kept.is_none().then(|| built.clone());
            let mut grown = 0;
            for world in 0..worlds {
                grown += run(&mut built, Round::Nominal(world))?;
            }
            if grown == 0 {
                tracing::info!(pass, grown, "library verification");
                break;
            }
            let now = succeeding(&built)?;
            tracing::info!(
                pass,
                grown,
                succeeding = now,
                worlds,
                "library verification"
            );
            if now >= best {
                best = now;
                kept = None;
            } else if kept.is_none() {
                kept = before;
            }
        }
        if let Some(earlier) = kept {
            tracing::info!(
                succeeding = best,
                dropped = built.entries.len() - earlier.entries.len(),
                "library verification kept an earlier library"
            );
            built = earlier;
        }
    }
    Ok(Entries {
        entries: built.entries,
        horizon: s.horizon,
    })
}

/// The reach a controller keeps, as a fraction of its distance to the state whose branch it outbid
/// ([`shrink_shadowing`]): a margin for the policy's whitening, which moves a little as the library grows.
pub const REACH_SHRINK: f64 = 0.8;

/// After a branch grown from `from`, a state the policy is stuck at (a progress task's stall, where a
/// target task's policy left it short of its targets), its controllers from `first_new` on: while the
/// policy still chooses an older controller at `from`, whose value model outbids the branch's solve
/// there, that controller's reach ends short of `from` ([`REACH_SHRINK`] of its distance), as
/// simulation-based LQR-trees shrink a funnel to exclude a state its controller failed from. Not for the
/// state a kick left, from which the policy may have failed anywhere on the way: there the older
/// controllers may well be right (ending their reach at a target task's start once left the mirrored
/// finger's turn with a policy that never turned the ellipse). Without it (issue 28,
/// the three-link finger) two branches in five were never used where they were grown: the policy
/// stalled again on the same state. At most `neighbours` controllers are shrunk: the branch's own
/// first controller, at `from` itself, is among the nearest.
fn shrink_shadowing(
    policy: &mut Policy,
    built: &mut Built,
    from: &[f64],
    first_new: usize,
    neighbours: usize,
) -> Result<(), LibraryError> {
    for _ in 0..neighbours {
        let (j, turns) = policy.select(from)?;
        if j >= first_new {
            break;
        }
        let reach = REACH_SHRINK * policy.distance(from, j, turns)?;
        policy.set_reach(j, reach)?;
        built.entries[j].reach = Some(reach);
    }
    Ok(())
}

/// Passes of the final check of every growth world from the task's start ([`Round::Nominal`]); a pass
/// that grows nothing ends it.
pub const VERIFY_PASSES: usize = 2;
/// Passes at most of that check while a world still fails the task's criterion after
/// [`VERIFY_PASSES`]; the library kept is the one on which the most worlds succeed.
pub const VERIFY_PASSES_MOST: usize = 4;
/// Branches at most per world and pass of that check.
pub const VERIFY_BRANCHES: usize = 4;

/// A closed loop growth runs: world `w` is the library's own model (even `w`) or hard contact (odd) at
/// the `w / 2`-th of [`LibrarySettings::growth_time_steps`], in turn.
#[derive(Debug, Clone, Copy)]
enum Round {
    /// A growth round: [`GROWTH_SECONDS`] from the task's start, kicked from [`GROWTH_FIRST_KICK`] on,
    /// at most [`GROWTH_BRANCHES`] branches.
    Kicked(usize),
    /// The final check of world `w`: [`GROWTH_FIRST_KICK`] seconds from the task's start, no kicks,
    /// at most [`VERIFY_BRANCHES`] branches.
    Nominal(usize),
}

/// The settings and dynamics a growth world's branches are optimised on, where not the library's own.
type BranchWorld = (LibrarySettings, SceneDynamics);

/// Growth world `w` (see [`Round`]): its time step and contact model.
fn world_model(task: &Build, round: usize) -> (f64, ContactModel) {
    let s = task.settings;
    let steps_of = &s.growth_time_steps;
    let h = if steps_of.is_empty() {
        s.h
    } else {
        steps_of[(round / 2) % steps_of.len()]
    };
    // Odd rounds run on hard contact: the policy is meant for the smoothed and the hard world alike.
    let model = if round % 2 == 1 {
        ContactModel::Hard
    } else {
        s.model
    };
    (h, model)
}

/// Growth world `w` (see [`Round`]): its time step and its simulator.
fn world_of(task: &Build, round: usize) -> Result<(f64, Simulator), LibraryError> {
    let (h, model) = world_model(task, round);
    let world = Simulator::new(
        task.scene.clone(),
        StepSettings {
            model: model.complementarity(),
            h,
            ..StepSettings::default()
        },
    )?;
    Ok((h, world))
}

/// The policy of the controllers built so far, run at time step `h`: the library's policy
/// ([`crate::Library::policy`]) as it would be saved now.
fn policy_at(task: &Build, built: &Built, h: f64) -> Result<Policy, LibraryError> {
    let s = task.settings;
    Policy::for_task(
        &built.entries,
        task.scene.n_state(),
        task.scene.n_controls,
        &task.progress,
        &task.turns,
    )?
    .with_neighbours(s.neighbours)?
    .with_limits(task.control_limits.clone())?
    .with_control_weight(task.cost.control_weight)?
    .with_time_step(h)
}

/// The policy of the controllers built so far, run on growth world `w` ([`world_model`]) from the
/// task's start without kicks for [`GROWTH_FIRST_KICK`] seconds by [`crate::evaluate`]'s own closed
/// loop, and its verdict by the task's criterion (every rewarded coordinate's last-quarter rate at
/// least the least rate, every judged target within tolerance over the last quarter).
fn unkicked(task: &Build, built: &Built, w: usize) -> Result<Verdict, LibraryError> {
    let s = task.settings;
    let (h, model) = world_model(task, w);
    let judge = Judge {
        own: task.scene,
        progress: task.progress,
        success: &task.success,
        cost: &task.cost,
        x0: &s.x0,
        h: s.h,
    };
    let run = EvaluationSettings {
        model,
        h,
        seconds: GROWTH_FIRST_KICK,
        kick_every: 0.0,
        ..EvaluationSettings::default()
    };
    match closed_loop(task.scene, &judge, &policy_at(task, built, h)?, &run) {
        Ok(evaluation) => Ok(evaluation.success),
        // A closed loop that blows up fails, whatever its numbers so far.
        Err(LibraryError::Diverged { .. }) => Ok(Verdict {
            criterion: task.success.describe(&task.scene.coordinate_names()),
            ..Verdict::default()
        }),
        Err(e) => Err(e),
    }
}

/// Growth world `w` (see [`Round`]): its time step, its simulator, and for a target task on a world
/// other than the library's own the settings and dynamics its branches are optimised on: the sharpened
/// noise scale ([`LibrarySettings::growth_sharpening`]) and, when `at_world_step` (the final check), the
/// world's time step, the horizon scaled to the same time and the running cost to the same integral
/// ([`Build::with_settings`]); a growth round's branches stay at the task's step.
fn growth_world(
    task: &Build,
    round: usize,
    at_world_step: bool,
) -> Result<(f64, Simulator, Option<BranchWorld>), LibraryError> {
    let s = task.settings;
    let (h, world) = world_of(task, round)?;
    // A target task's branches for a world other than the library's own are optimised at its time step
    // and nearer contact (LibrarySettings::growth_sharpening).
    let other_world = round % 2 == 1 || h != s.h;
    if task.progress.forward.is_some() || !other_world {
        return Ok((h, world, None));
    }
    let model = match s.model {
        ContactModel::Logistic(sigma) => ContactModel::Logistic(sigma * s.growth_sharpening),
        ContactModel::Normal(sigma) => ContactModel::Normal(sigma * s.growth_sharpening),
        ContactModel::Hard => ContactModel::Hard,
    };
    let branch_h = if at_world_step { h } else { s.h };
    if model == s.model && branch_h == s.h {
        return Ok((h, world, None));
    }
    let horizon = ((s.horizon as f64 * s.h / branch_h).round() as usize).clamp(1, LONGEST_HORIZON);
    let settings = LibrarySettings {
        model,
        h: branch_h,
        horizon,
        ..s.clone()
    };
    let dynamics = SceneDynamics::new(settings.simulator(task.scene)?);
    Ok((h, world, Some((settings, dynamics))))
}

/// One growth round (see [`Exploration::Branches`]) or final check: the number of branches added (not
/// counting those that came back empty).
///
/// Failure is the task's: for a task that rewards progress, a stall (the progress coordinate advancing
/// less than [`STALL_ADVANCE`] the rewarded way in `stall_window` seconds), and a branch starts where
/// the policy stalled; for a target task, not being back within its success tolerance
/// ([`task::Success::tolerance`]) [`task::Success::settle`] seconds after a kick (or at the end of the
/// first interval, from the start), and two branches start, one from the state the kick left and one
/// from the state the policy is in then (whose first solve reaches for the contact if the policy let go
/// of it: [`task::ContactProblem::feel_contact`]), optimised at the sharpened noise scale, and in the
/// final check at the world's time step ([`growth_world`]), when the round's world is not the library's
/// own. A branch spans the
/// failure's window ([`Build::growth_length`] of the recipe's `length`) at its time step. A branch
/// whose first solve ends within the tolerance is kept as it is (it teaches the policy to let be); one
/// whose search for the contact finds none that pays comes back empty and is not added (it still counts
/// towards the round's branches at most). The round's policy runs at the world's time step
/// ([`Policy::with_time_step`]).
fn grow(
    task: &Build,
    dynamics: &mut SceneDynamics,
    built: &mut Built,
    length: usize,
    stall_window: f64,
    kind: Round,
    report: &(dyn Fn(&Entry) + Sync),
) -> Result<usize, LibraryError> {
    let (round, seconds, first_kick_seconds, most) = match kind {
        Round::Kicked(r) => (r, GROWTH_SECONDS, GROWTH_FIRST_KICK, GROWTH_BRANCHES),
        Round::Nominal(w) => (w, GROWTH_FIRST_KICK, GROWTH_FIRST_KICK, VERIFY_BRANCHES),
    };
    let s = task.settings;
    let progress = task.progress;
    let free = progress.coordinate;
    let (h, mut world, branch_world) =
        growth_world(task, round, matches!(kind, Round::Nominal(_)))?;
    let policy_of = |built: &Built| policy_at(task, built, h);
    let mut policy = policy_of(built)?;
    let (branch_settings, mut branch_dynamics) = branch_world.unzip();
    let branch_task = branch_settings.as_ref().map(|b| task.with_settings(b));
    let branch_task = branch_task.as_ref().unwrap_or(task);
    // Trajectories per branch: as many as span the failure's window at the branches' time step.
    let length = branch_task.growth_length(length);
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    rng.set_stream(u64::MAX - round as u64);
    let steps = (seconds / h).round() as usize;
    let kick_steps = ((10.0 / h).round() as usize).max(1);
    let first_kick = ((first_kick_seconds / h).round() as usize).max(1);
    let window = ((stall_window / h).round() as usize).max(1);
    // A target task's time bound after a kick (from the start: the first interval).
    let settle = ((task.success.settle / h).round() as usize).clamp(1, kick_steps);
    let mut recent = std::collections::VecDeque::with_capacity(window + 1);
    let mut x = s.x0.clone();
    let mut u = vec![0.0; task.scene.n_controls];
    // Branches grown, and tried (some come back empty): a round tries at most `most`.
    let (mut grown, mut tried) = (0, 0);
    // A target task's last perturbed state, the controller used there, and when to judge the way back.
    let mut kicked: Option<(Vec<f64>, usize)> = None;
    let mut judge_at = first_kick - 1;
    // A final check judges a target task as `evaluate` does without kicks: its worst distance over the
    // last quarter; a growth round, by the distance when judged.
    let quarter = match kind {
        Round::Nominal(_) if progress.forward.is_none() => steps - steps / 4,
        _ => usize::MAX,
    };
    let mut worst = 0.0f64;
    for k in 0..steps {
        if k >= first_kick && (k - first_kick).is_multiple_of(kick_steps) {
            task.perturb(&mut x, &mut rng);
            recent.clear();
            kicked = None;
            judge_at = k + settle;
        }
        let i = policy.control(&x, &mut u)?;
        if k >= quarter {
            worst = worst.max(task.success.distance(&x));
        }
        let judged = |x: &[f64]| task.success.distance(x).max(worst);
        if kicked.is_none() {
            kicked = Some((x.clone(), i));
        }
        // (state, controller in use, whether the policy is stuck there): a branch from each.
        let failed_at: Vec<(Vec<f64>, usize, bool)> = match progress.forward {
            Some(forward) => {
                recent.push_back(x[free]);
                if recent.len() > window {
                    recent.pop_front();
                }
                // Stalled: a branch from here, warm-started from the plan of the controller in use.
                (recent.len() == window && forward * (x[free] - recent[0]) < STALL_ADVANCE)
                    .then(|| (x.clone(), i, true))
                    .into_iter()
                    .collect()
            }
            None if k == judge_at && judged(&x) > task.success.tolerance => {
                // Not back within tolerance in time: a branch from the state the kick left, and one
                // from where the policy left the task (its first solve reaching for the contact if the
                // policy let go of it there). The policy is stuck at the second; from the first it
                // may have gone wrong anywhere on the way.
                (kicked.clone().into_iter().map(|(x, i)| (x, i, false)))
                    .chain([(x.clone(), i, true)])
                    .collect()
            }
            None => Vec::new(),
        };
        let tried_before = tried;
        for (from, i, stuck) in failed_at {
            if tried == most {
                break;
            }
            tried += 1;
            tracing::debug!(
                ?kind,
                seconds = k as f64 * h,
                stuck,
                angle = from[free],
                "growth branch"
            );
            let (trajectory, offset) = (i / s.keep, i % s.keep);
            let plan = resampled(
                &ddp::shift_controls(&built.plans[trajectory], offset),
                built.entries[trajectory * s.keep].time_step,
                branch_task.settings.h,
                branch_task.settings.horizon,
            );
            let branch = branch_task.chain(
                branch_dynamics.as_mut().unwrap_or(&mut *dynamics),
                from.clone(),
                plan,
                length,
                false,
                |_, _| {},
                report,
            )?;
            // A target task's branch whose search found no contact that helps (a block knocked out of
            // the finger's reach, say) has nothing to teach: the policy stays as it is.
            if branch.entries.is_empty() {
                continue;
            }
            let first_new = built.entries.len();
            built.append(branch);
            policy = policy_of(built)?;
            if stuck {
                shrink_shadowing(&mut policy, built, &from, first_new, s.neighbours)?;
            }
            recent.clear();
            grown += 1;
        }
        if tried > tried_before {
            if tried == most {
                break;
            }
            policy.control(&x, &mut u)?;
        }
        let step = world.step(&x, &u)?;
        if !step.x_next.iter().all(|v| v.is_finite()) {
            break;
        }
        x = step.x_next;
    }
    Ok(grown)
}

/// A contact search's pulls, where it made any, logged at info level.
fn log_reach(search: &task::ContactSearch) {
    if let Some(r) = &search.reach {
        tracing::info!(pair = ?r.pair, tries = ?r.tries, "a first solve felt no contact: reaching for it");
    }
}

/// A stage of a continuation in the noise scale, logged at info level.
fn log_continuation(sigma: f64, stage: &ddp::Solution, felt: Option<bool>) {
    tracing::info!(
        sigma,
        passes = stage.iterations.len(),
        cost = stage.cost,
        ?felt,
        "continuation"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A controller at `x` (2 joints' state, 4 entries) with cost-to-go `v` and no gain.
    fn entry(x: [f64; 4], v: f64) -> Entry {
        Entry {
            x: x.to_vec(),
            u: vec![0.0],
            gain: vec![0.0; 4],
            passes: 1,
            converged: true,
            cost: v,
            value: LocalValue {
                cost_to_go: v,
                gradient: vec![0.0; 4],
                hessian: vec![0.0; 16],
                per_period: 0.0,
            },
            reach: None,
            time_step: 0.05,
        }
    }

    #[test]
    fn a_branch_is_chosen_where_it_was_grown_and_only_the_outbidding_controllers_lose_reach() {
        // Three old controllers around `from`: two predict less than the branch's solve there (they
        // outbid it), one more. The branch's controller sits at `from` itself.
        let from = [0.0, 0.0, 0.0, 0.0];
        let mut built = Built {
            entries: vec![
                entry([0.5, 0.0, 0.0, 0.0], -3.0),
                entry([0.0, 0.7, 0.0, 0.0], -2.0),
                entry([0.0, 0.0, 0.4, 0.0], 5.0),
                entry([3.0, 3.0, 3.0, 3.0], -9.0),
            ],
            plans: Vec::new(),
        };
        let first_new = built.entries.len();
        built.entries.push(entry(from, 0.0));
        let fresh = |built: &Built| {
            Policy::new(&built.entries, 4, 1, 3)
                .unwrap()
                .with_neighbours(4)
                .unwrap()
        };
        let mut policy = fresh(&built);
        assert_eq!(policy.select(&from).unwrap().0, 0);
        shrink_shadowing(&mut policy, &mut built, &from, first_new, 4).unwrap();
        assert_eq!(policy.select(&from).unwrap().0, first_new);
        // The same from the entries' reach, as the next policy and the library file have it.
        assert_eq!(fresh(&built).select(&from).unwrap().0, first_new);
        for (i, e) in built.entries.iter().enumerate() {
            match i {
                0 | 1 => {
                    let r = e.reach.unwrap();
                    let d = policy.distance(&from, i, 0.0).unwrap();
                    assert!((r - REACH_SHRINK * d).abs() <= 1e-12 * d, "{i}: {r} {d}");
                }
                _ => assert_eq!(e.reach, None, "{i}"),
            }
        }
    }

    /// A fork on a slider and a block on the ground, whose target is 0.5 along it.
    const SLIDER: &str = include_str!("../../../scenes/slider_push.toml");

    #[test]
    fn the_final_checks_verdict_on_each_world_is_evaluates_unkicked_verdict() {
        // The finger's task and a short trunk from its start: the final check keeps the library on
        // which the most worlds succeed, judged by `unkicked`; that must be what `evaluate` reports
        // without kicks over the same time, to the last bit of the rate.
        let file = task::ProblemFile::builtin();
        let task = file.task(None).unwrap();
        let settings = LibrarySettings {
            warm_passes: 20,
            ..LibrarySettings::default().for_task(&task)
        };
        assert_eq!(settings.growth_time_steps, [0.05, WORLD_TIME_STEP]);
        let build = Build::new(&file.scene, &task, &settings).unwrap();
        let zero = vec![vec![0.0; file.scene.n_controls]; settings.horizon];
        let mut dynamics = build.dynamics().unwrap();
        let built = build
            .chain(
                &mut dynamics,
                task.x0.clone(),
                zero,
                60,
                false,
                |_, _| {},
                &|_| {},
            )
            .unwrap();
        let entries = Entries {
            entries: built.entries.clone(),
            horizon: settings.horizon,
        };
        let library = crate::Library::assemble(&file, task.clone(), &settings, entries);
        let policy = library.policy().unwrap();
        let mut rates = Vec::new();
        for w in 0..4 {
            let (h, _) = world_of(&build, w).unwrap();
            let model = if w % 2 == 1 {
                ContactModel::Hard
            } else {
                settings.model
            };
            let run = crate::EvaluationSettings {
                model,
                h,
                seconds: GROWTH_FIRST_KICK,
                kick_every: 0.0,
                ..crate::EvaluationSettings::default()
            };
            let evaluated = crate::evaluate(&library, &policy, &run).unwrap().success;
            let checked = unkicked(&build, &built, w).unwrap();
            assert_eq!(checked, evaluated, "world {w} (h {h}, {model:?})");
            rates.push(checked.rate.unwrap());
        }
        // Four different runs, the ellipse turned on each: the worlds differ in contact and time step.
        assert!(rates.iter().all(|&r| r != 0.0), "{rates:?}");
        for (a, ra) in rates.iter().enumerate() {
            for rb in &rates[a + 1..] {
                assert_ne!(ra.to_bits(), rb.to_bits(), "{rates:?}");
            }
        }
    }

    #[test]
    fn a_target_tasks_branch_already_at_its_targets_is_kept_without_reaching_for_contact() {
        let file = task::ProblemFile::from_toml_str(SLIDER).unwrap();
        let task = file.task(Some("push")).unwrap();
        let scene = &file.scene;
        let settings = LibrarySettings::default().for_task(&task).fitted(40);
        let build = Build::new(scene, &task, &settings).unwrap();
        // The block at rest on its target, both prongs 0.45 from it: nothing to do, and no contact felt.
        let names = scene.coordinate_names();
        let at = |name: &str| names.iter().position(|n| n == name).unwrap();
        let mut x1 = task.x0.clone();
        x1[at("block.x")] = 0.5;
        x1[at("pusher.position")] = 0.5;
        let zero = vec![vec![0.0; scene.n_controls]; settings.horizon];
        let mut dynamics = build.dynamics().unwrap();
        let branch = build
            .chain(&mut dynamics, x1, zero, 2, false, |_, _| {}, &|_| {})
            .unwrap();
        // Both trajectories kept: the policy learns to leave the block be there (a branch that reached
        // for the contact found none that pays, and came back empty).
        assert_eq!(branch.entries.len(), 2 * settings.keep);
        let first = &branch.entries[0];
        assert!(first.cost < 1e-2, "{}", first.cost);
    }

    #[test]
    fn a_plan_is_resampled_to_another_time_step_held_piecewise_constant() {
        let plan: Vec<Vec<f64>> = (0..6).map(|k| vec![k as f64]).collect();
        let flat = |p: Vec<Vec<f64>>| p.into_iter().flatten().collect::<Vec<f64>>();
        // 0.05 s to 0.03 s over 8 steps: times 0, 0.03, ..., 0.21 fall in steps 0, 0, 1, 1, 2, 3, 3, 4.
        assert_eq!(
            flat(resampled(&plan[..5], 0.05, 0.03, 8)),
            vec![0.0, 0.0, 1.0, 1.0, 2.0, 3.0, 3.0, 4.0]
        );
        // 0.03 s to 0.05 s: times 0, 0.05, 0.1, 0.15 fall in steps 0, 1, 3, 5; past the end, the last.
        assert_eq!(
            flat(resampled(&plan, 0.03, 0.05, 5)),
            vec![0.0, 1.0, 3.0, 5.0, 5.0]
        );
        assert_eq!(resampled(&plan, 0.05, 0.05, 6), plan);
        assert!(resampled(&[], 0.05, 0.03, 4).is_empty());
    }

    #[test]
    fn a_cost_at_another_time_step_weighs_the_same_integral() {
        let file = task::ProblemFile::from_toml_str(SLIDER).unwrap();
        let cost = file.task(Some("push")).unwrap().cost;
        let scaled = scaled_running(&cost, 0.6);
        assert_eq!(scaled.final_terms, cost.final_terms);
        assert_eq!(scaled.control_weight, 0.6 * cost.control_weight);
        for (s, c) in scaled.running.iter().zip(&cost.running) {
            assert_eq!((s.linear, s.quadratic), (0.6 * c.linear, 0.6 * c.quadratic));
            assert_eq!((s.index, s.target), (c.index, c.target));
        }
        assert_eq!(scaled_running(&cost, 1.0), cost);
    }

    #[test]
    fn a_growth_branch_spans_the_window_its_failure_is_judged_over() {
        let length = |text: &str, recipe: usize| {
            let file = task::ProblemFile::from_toml_str(text).unwrap();
            let task = file.task(None).unwrap();
            let settings = LibrarySettings::default().for_task(&task);
            let build = Build::new(&file.scene, &task, &settings).unwrap();
            build.growth_length(recipe)
        };
        // The finger's stall window, 2 s, is 10 trajectories of 4 steps at 0.05 s ...
        assert_eq!(length(task::BUILTIN_SCENE_FILE, 20), 10);
        assert_eq!(length(task::BUILTIN_SCENE_FILE, 6), 6);
        // ... the slider's settle time, 5 s, 25 of them: the recipe's 20 at most.
        assert_eq!(length(SLIDER, 20), 20);
        assert_eq!(length(SLIDER, 40), 25);
    }

    #[test]
    fn the_stall_window_outlasts_the_trunks_longest_pause() {
        // A trunk of 30 trajectories (keep 4, shift 4, h 0.05: 0.2 s each) on the finger's ellipse angle,
        // the state's third entry: 0.12 rad a trajectory, but a pause of 15 trajectories (3 s) from 10 on.
        let build = |text: &str| {
            let file = task::ProblemFile::from_toml_str(text).unwrap();
            let task = file.task(None).unwrap();
            (file, task)
        };
        let (file, finger) = build(task::BUILTIN_SCENE_FILE);
        let settings = LibrarySettings::default().for_task(&finger);
        let spin = Build::new(&file.scene, &finger, &settings).unwrap();
        let angle = |j: usize| match j {
            ..10 => 0.12 * j as f64,
            10..25 => 1.2 + 0.001 * (j - 10) as f64,
            _ => 1.214 + 0.12 * (j - 24) as f64,
        };
        let mut built = Built::default();
        for j in 0..30 {
            for _ in 0..settings.keep {
                built.entries.push(entry([0.0, 0.0, angle(j), 0.0], 0.0));
            }
        }
        let dwell = spin.dwell(&built, 30, 5).unwrap();
        // From trajectory 8, 9 or 10 (0.96 to 1.2 rad): 0.3 rad further 17 trajectories on, over the pause.
        assert!((dwell - 17.0 * 0.2).abs() < 1e-12, "{dwell}");
        // Past the pause the trunk never pauses: 3 trajectories for 0.3 rad at 0.12 each.
        let dwell = spin.dwell(&built, 30, 25).unwrap();
        assert!((dwell - 0.6).abs() < 1e-12, "{dwell}");
        // A target task has no pause to measure.
        let (file, slider) = build(SLIDER);
        let settings = LibrarySettings::default().for_task(&slider);
        let push = Build::new(&file.scene, &slider, &settings).unwrap();
        assert_eq!(push.dwell(&built, 30, 5), None);
    }
}
