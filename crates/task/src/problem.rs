//! Tasks as data: a scene file's `[task.NAME]` tables (one or several), each an optimal control problem on
//! the scene: where it starts, the time step and horizon, the contact model the optimiser sees, and a cost
//! made of terms on named coordinates (docs/tasks.md).
//!
//! ```toml
//! [task.spin]
//! h = 0.05
//! horizon = 75
//! model = "logistic"
//! sigma = 0.1
//! x0 = { "link1.angle" = -0.785, "link2.angle" = -0.524 }
//! control_weight = 0.05
//! periods = { "ellipse.angle" = 3.141592653589793 }
//! running = [{ coordinate = "ellipse.angle", linear = -1.0 }]
//! final = [{ coordinate = "ellipse.angle", linear = -1.0 }]
//! ```
//!
//! A coordinate is named `<body>.<coordinate of its joint>` ([`dynamics::Scene::coordinate_names`]); a
//! term acts on its value, or on its velocity with `velocity = true`. Coordinates the task does not name
//! start at rest at their reference (zero). Every field is checked, and a bad one is refused with an error
//! that names the task and the field.

use crate::error::TaskError;
use crate::model::ContactModel;
use ddp::{ControlLimits, Cost, CostDerivatives};
use dynamics::{Scale, Scene};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// One cost term as a task table writes it: `linear * y + quadratic / 2 * (y - target)^2` on the
/// coordinate (or its velocity) `y`, the difference wrapped into `[-period / 2, period / 2)` when the
/// coordinate has a period.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TermSpec {
    /// The coordinate's name, `<body>.<coordinate>`.
    pub coordinate: String,
    /// Whether the term acts on the coordinate's velocity instead of its value.
    #[serde(default)]
    pub velocity: bool,
    /// Linear weight.
    #[serde(default)]
    pub linear: f64,
    /// Quadratic weight (at least zero).
    #[serde(default)]
    pub quadratic: f64,
    /// Target of the quadratic term.
    #[serde(default)]
    pub target: f64,
}

/// A task as a scene file's `[task.NAME]` table describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskSpec {
    /// Time step (s).
    pub h: f64,
    /// Optimisation horizon (steps).
    pub horizon: usize,
    /// The optimiser's contact model: `"hard"`, `"logistic"` or `"normal"`.
    pub model: String,
    /// Noise scale of the smoothed models (required for them, refused for the hard one).
    #[serde(default)]
    pub sigma: Option<f64>,
    /// Initial coordinates by name; the others start at zero.
    #[serde(default)]
    pub x0: BTreeMap<String, f64>,
    /// Initial velocities by coordinate name; the others start at rest.
    #[serde(default)]
    pub v0: BTreeMap<String, f64>,
    /// Weight `c_u` of `c_u |u|^2` per step.
    pub control_weight: f64,
    /// Bounds `[lower, upper]` on every control, if any.
    #[serde(default)]
    pub control_limits: Option<[f64; 2]>,
    /// Periodic coordinates and their periods (an angle whose body is symmetric under a half turn has
    /// period pi): quadratic terms wrap their differences, and the library's policy and metrics measure
    /// distances along them modulo the period.
    #[serde(default)]
    pub periods: BTreeMap<String, f64>,
    /// Terms of the running cost, charged at every step.
    #[serde(default)]
    pub running: Vec<TermSpec>,
    /// Terms of the final cost, charged at the end of the horizon.
    #[serde(default, rename = "final")]
    pub final_terms: Vec<TermSpec>,
    /// What counts as success in closed loop (`[task.NAME.success]`); every field has a default derived
    /// from the terms ([`Success`]).
    #[serde(default)]
    pub success: SuccessSpec,
}

/// A task's `[task.NAME.success]` table: what `evaluate` and the library's growth call success. Every
/// field is optional.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SuccessSpec {
    /// The least rate (the coordinate's unit per second, in the direction the task rewards) at which
    /// every linearly rewarded coordinate must advance over a run's last quarter.
    #[serde(default)]
    pub min_rate: Option<f64>,
    /// The coordinates whose targets must be reached (names of coordinates with a quadratic term);
    /// default: every position target of a task that rewards no progress, none of one that does.
    #[serde(default)]
    pub targets: Option<Vec<String>>,
    /// How far from its target each judged coordinate may be.
    #[serde(default)]
    pub tolerance: Option<f64>,
    /// Seconds after a perturbation by which a target task must be back within tolerance, or a progress
    /// task moving forward again.
    #[serde(default)]
    pub settle: Option<f64>,
}

/// A task's success criterion, checked ([`SuccessSpec`] with its defaults filled in).
///
/// A run succeeds when every rewarded coordinate in [`Success::rates`] advanced at least
/// [`Success::min_rate`] per second the rewarded way over its last quarter, and every judged target in
/// [`Success::targets`] stayed within [`Success::tolerance`] of its target throughout the last quarter
/// (after kicks: is within it at the end, a whole kick interval after the last kick).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Success {
    /// `(state entry, direction)` of each coordinate the running cost rewards linearly (`direction` is
    /// 1 where the task rewards increase, -1 decrease).
    pub rates: Vec<(usize, f64)>,
    /// The least last-quarter rate. Default: a tenth of the coordinate's period per second for a periodic
    /// one (the finger: pi / 10 = 0.31 rad/s), 0.1 per second otherwise.
    pub min_rate: f64,
    /// `(state entry, target, period)` of each judged position target.
    pub targets: Vec<(usize, f64, Option<f64>)>,
    /// How far from its target each may be. Default: 0.05, or a tenth of the farthest judged target's
    /// distance from the start if that is more.
    pub tolerance: f64,
    /// Seconds after a kick to be back (within tolerance, or moving forward). Default 5.
    pub settle: f64,
}

/// [`Success::settle`]'s default, seconds.
pub const DEFAULT_SETTLE: f64 = 5.0;

/// A checked term: the state entry it reads and its weights.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Term {
    /// Index into the state `x = [q; v]`.
    pub index: usize,
    /// Linear weight.
    pub linear: f64,
    /// Quadratic weight.
    pub quadratic: f64,
    /// Target of the quadratic term.
    pub target: f64,
    /// Period of the difference to the target, if the entry is periodic.
    pub period: Option<f64>,
}

impl Term {
    /// `y - target`, wrapped into `[-period / 2, period / 2)` for a periodic entry.
    pub fn offset(&self, y: f64) -> f64 {
        wrapped_offset(y, self.target, self.period)
    }

    fn value(&self, x: &[f64]) -> f64 {
        let y = x[self.index];
        let d = self.offset(y);
        self.linear * y + 0.5 * self.quadratic * d * d
    }
}

/// `y - target`, wrapped into `[-period / 2, period / 2)` when there is a period.
fn wrapped_offset(y: f64, target: f64, period: Option<f64>) -> f64 {
    let d = y - target;
    match period {
        Some(p) => d - p * (d / p + 0.5).floor(),
        None => d,
    }
}

/// A task's cost: `sum of running terms + c_u |u|^2` per step, the final terms at the end. Its
/// derivatives are exact (a wrapped difference has slope one away from its jump, half a period from the
/// target).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskCost {
    /// Running terms.
    pub running: Vec<Term>,
    /// Final terms.
    pub final_terms: Vec<Term>,
    /// `c_u`.
    pub control_weight: f64,
}

impl TaskCost {
    fn terms_value(terms: &[Term], x: &[f64]) -> f64 {
        terms.iter().map(|t| t.value(x)).sum()
    }

    fn terms_derivatives(terms: &[Term], x: &[f64], lx: &mut [f64], lxx: &mut [f64]) {
        let n = x.len();
        lx.iter_mut().for_each(|e| *e = 0.0);
        lxx.iter_mut().for_each(|e| *e = 0.0);
        for t in terms {
            lx[t.index] += t.linear + t.quadratic * t.offset(x[t.index]);
            lxx[t.index * n + t.index] += t.quadratic;
        }
    }
}

impl Cost for TaskCost {
    fn running(&self, _i: usize, x: &[f64], u: &[f64]) -> f64 {
        Self::terms_value(&self.running, x)
            + self.control_weight * u.iter().map(|e| e * e).sum::<f64>()
    }

    fn terminal(&self, x: &[f64]) -> f64 {
        Self::terms_value(&self.final_terms, x)
    }

    fn running_derivatives(&self, _i: usize, x: &[f64], u: &[f64], out: &mut CostDerivatives) {
        Self::terms_derivatives(&self.running, x, &mut out.lx, &mut out.lxx);
        let m = u.len();
        for (a, &e) in u.iter().enumerate() {
            out.lu[a] = 2.0 * self.control_weight * e;
            for b in 0..m {
                out.luu[a * m + b] = if a == b {
                    2.0 * self.control_weight
                } else {
                    0.0
                };
            }
        }
        out.lux.iter_mut().for_each(|e| *e = 0.0);
    }

    fn terminal_derivatives(&self, x: &[f64], lx: &mut [f64], lxx: &mut [f64]) {
        Self::terms_derivatives(&self.final_terms, x, lx, lxx);
    }
}

/// The shortest period a coordinate may have: far below any body's size in a scene's units, far above
/// the rounding of a coordinate wrapped into it.
pub const SHORTEST_PERIOD: f64 = 1e-6;

/// How far a task's initial state may break a constraint (bodies overlapping, a joint past its limit):
/// rounding in a hand-written start, no more.
pub const START_TOLERANCE: f64 = 1e-6;

/// A checked task on a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Task {
    /// Its name in the scene file.
    pub name: String,
    /// Time step.
    pub h: f64,
    /// Optimisation horizon.
    pub horizon: usize,
    /// The optimiser's contact model.
    pub model: ContactModel,
    /// Initial state `[q; v]`.
    pub x0: Vec<f64>,
    /// The cost.
    pub cost: TaskCost,
    /// Bounds on the controls, if any.
    pub control_limits: Option<ControlLimits>,
    /// The period of each state entry (`None`: not periodic); velocities are never periodic.
    pub periods: Vec<Option<f64>>,
    /// What counts as success in closed loop.
    pub success: Success,
}

impl Task {
    /// Check `spec` (the task called `name`) against `scene`.
    pub fn new(scene: &Scene, name: &str, spec: &TaskSpec) -> Result<Self, TaskError> {
        let bad = |field: &str, problem: String| TaskError::Spec {
            task: name.to_string(),
            field: field.to_string(),
            problem,
        };
        let n = scene.n_dof();
        let names = scene.coordinate_names();
        let index = |field: &str, coordinate: &str| -> Result<usize, TaskError> {
            names.iter().position(|c| c == coordinate).ok_or_else(|| {
                bad(
                    field,
                    format!(
                        "the scene has no coordinate \"{coordinate}\" (it has {})",
                        names.join(", ")
                    ),
                )
            })
        };
        let finite = |field: &str, v: f64| -> Result<f64, TaskError> {
            if v.is_finite() {
                Ok(v)
            } else {
                Err(bad(field, format!("{v} is not a finite number")))
            }
        };
        if !(spec.h.is_finite() && spec.h > 0.0 && spec.h <= 1.0) {
            return Err(bad("h", format!("{} must be in (0, 1] s", spec.h)));
        }
        if !(1..=100_000).contains(&spec.horizon) {
            return Err(bad(
                "horizon",
                format!("{} must be 1 to 100000 steps", spec.horizon),
            ));
        }
        let sigma = |model: &str| -> Result<f64, TaskError> {
            match spec.sigma {
                Some(s) if s.is_finite() && s > 0.0 => match scene.check_noise_scale(s) {
                    Ok(()) => Ok(s),
                    Err(_) => Err(bad(
                        "sigma",
                        format!(
                            "{} is beyond this scene's noise scales: {}",
                            Scale(s),
                            dynamics::NoiseScaleBound(scene.largest_noise_scale())
                        ),
                    )),
                },
                Some(s) => Err(bad(
                    "sigma",
                    format!("{} must be positive and finite", Scale(s)),
                )),
                None => Err(bad(
                    "sigma",
                    format!("the {model} model needs a noise scale sigma"),
                )),
            }
        };
        let model = match spec.model.as_str() {
            "hard" => match spec.sigma {
                None => ContactModel::Hard,
                Some(_) => {
                    return Err(bad(
                        "sigma",
                        "the hard model has no noise scale; remove sigma".into(),
                    ));
                }
            },
            "logistic" => ContactModel::Logistic(sigma("logistic")?),
            "normal" => ContactModel::Normal(sigma("normal")?),
            other => {
                return Err(bad(
                    "model",
                    format!("\"{other}\" is not one of \"hard\", \"logistic\", \"normal\""),
                ));
            }
        };
        let mut periods = vec![None; 2 * n];
        for (c, &p) in &spec.periods {
            let i = index("periods", c)?;
            if !(p.is_finite() && p >= SHORTEST_PERIOD) {
                return Err(bad(
                    "periods",
                    format!(
                        "the period of {c} is {}, it must be finite and at least {SHORTEST_PERIOD:e}",
                        Scale(p)
                    ),
                ));
            }
            // A joint stopped by its limits does not come back to the same state a period on: states
            // a period apart are different states, which the wrapped costs and the policy's distances
            // would take for one.
            if let Some(coordinate) = scene.coordinates.get(i)
                && let Some([lower, upper]) = coordinate.limits
                && upper - lower > p
            {
                return Err(bad(
                    "periods",
                    format!(
                        "{c} has joint limits [{lower}, {upper}], wider than its period {p}: a coordinate its limits stop is not periodic"
                    ),
                ));
            }
            periods[i] = Some(p);
        }
        let mut x0 = vec![0.0; 2 * n];
        for (c, &v) in &spec.x0 {
            x0[index("x0", c)?] = finite("x0", v)?;
        }
        for (c, &v) in &spec.v0 {
            x0[n + index("v0", c)?] = finite("v0", v)?;
        }
        // A start with bodies inside each other (or a joint past its limit) would begin by pushing them
        // apart, which the task does not ask for: refused, the deepest named.
        let overlaps = scene.overlaps(&x0[..n], START_TOLERANCE)?;
        if let Some(o) = overlaps.first() {
            return Err(bad(
                "x0",
                format!(
                    "the initial state starts with {} by {:.3e} (more than START_TOLERANCE = {START_TOLERANCE:e}{}); \
                     start without it",
                    o.what,
                    o.depth,
                    match overlaps.len() {
                        1 => String::new(),
                        k => format!(", and {} more", k - 1),
                    }
                ),
            ));
        }
        let terms = |field: &str, specs: &[TermSpec]| -> Result<Vec<Term>, TaskError> {
            specs
                .iter()
                .map(|t| {
                    let i = index(field, &t.coordinate)?;
                    let linear = finite(field, t.linear)?;
                    let quadratic = finite(field, t.quadratic)?;
                    if quadratic < 0.0 {
                        return Err(bad(
                            field,
                            format!(
                                "the quadratic weight on {} is {quadratic}; a negative one has no minimum",
                                t.coordinate
                            ),
                        ));
                    }
                    Ok(Term {
                        index: if t.velocity { n + i } else { i },
                        linear,
                        quadratic,
                        target: finite(field, t.target)?,
                        period: if t.velocity { None } else { periods[i] },
                    })
                })
                .collect()
        };
        let control_weight = finite("control_weight", spec.control_weight)?;
        if control_weight < 0.0 {
            return Err(bad(
                "control_weight",
                format!("{control_weight} must be at least zero"),
            ));
        }
        let control_limits = match spec.control_limits {
            None => None,
            Some([lo, hi]) => {
                if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                    return Err(bad(
                        "control_limits",
                        format!("[{lo}, {hi}] must be finite with lower < upper"),
                    ));
                }
                let m = scene.n_controls;
                Some(ControlLimits {
                    lower: vec![lo; m],
                    upper: vec![hi; m],
                })
            }
        };
        let cost = TaskCost {
            running: terms("running", &spec.running)?,
            final_terms: terms("final", &spec.final_terms)?,
            control_weight,
        };
        let success = Success::new(&spec.success, &cost, &x0, &periods, &names, &bad)?;
        Ok(Task {
            name: name.to_string(),
            h: spec.h,
            horizon: spec.horizon,
            model,
            x0,
            cost,
            control_limits,
            periods,
            success,
        })
    }
}

impl Task {
    /// The coordinates of `scene` a turn of which changes nothing this task sees, each with the turn:
    /// `(coordinate, PI)` for the scene's [`Scene::half_turn_coordinates`] (an ellipse turned by pi), `(coordinate,
    /// 0.0)` for its [`Scene::round_coordinates`] (a disc turned by any angle), where the task neither
    /// declares the angle periodic (its policy's own periodic coordinate) nor weighs, rewards or judges
    /// it, unless, for a half turn, only modulo a period a half turn is a whole number of (a term on the
    /// angle's velocity is no obstacle: a turn leaves it). A state and the same state so turned have the
    /// same future and the same cost, so a library's policy compares states modulo the turn
    /// (`library::Policy::for_task`).
    pub fn turn_symmetries(&self, scene: &Scene) -> Vec<(usize, f64)> {
        use std::f64::consts::PI;
        let round = scene.round_coordinates();
        let invariant = |c: usize, period: Option<f64>| {
            !round.contains(&c)
                && period.is_some_and(|p| {
                    let k = PI / p;
                    p > 0.0 && (k - k.round()).abs() <= 1e-9 * k.max(1.0)
                })
        };
        let seen = |c: usize| {
            let terms = self.cost.running.iter().chain(&self.cost.final_terms);
            let weighed = terms
                .filter(|t| t.index == c)
                .any(|t| t.linear != 0.0 || !invariant(c, t.period));
            let judged = self.success.rates.iter().any(|r| r.0 == c)
                || (self.success.targets.iter()).any(|t| t.0 == c && !invariant(c, t.2));
            weighed || judged || self.periods.get(c).is_some_and(|p| p.is_some())
        };
        scene
            .half_turn_coordinates()
            .into_iter()
            .filter(|&c| !seen(c))
            .map(|c| (c, if round.contains(&c) { 0.0 } else { PI }))
            .collect()
    }

    /// `Err` unless the task's sizes (its state and, when it has them, its control limits) are `scene`'s:
    /// a task is checked against its own scene file, and this is for a task used with another scene.
    pub fn check_scene(&self, scene: &Scene) -> Result<(), TaskError> {
        let limits = self
            .control_limits
            .as_ref()
            .map_or(scene.n_controls, |l| l.lower.len());
        if self.x0.len() != scene.n_state() || limits != scene.n_controls {
            return Err(TaskError::SceneMismatch(format!(
                "task {} has {} state entries and {limits} controls, the scene {} and {}",
                self.name,
                self.x0.len(),
                scene.n_state(),
                scene.n_controls
            )));
        }
        Ok(())
    }
}

impl Success {
    /// `spec` checked against a task's cost, initial state and periods (`names`: the scene's coordinate
    /// names; `bad` makes the error for a field).
    fn new(
        spec: &SuccessSpec,
        cost: &TaskCost,
        x0: &[f64],
        periods: &[Option<f64>],
        names: &[String],
        bad: &dyn Fn(&str, String) -> TaskError,
    ) -> Result<Self, TaskError> {
        let n = names.len();
        let rates = Success::rewarded(cost, n);
        let min_rate = match spec.min_rate {
            Some(r) if r.is_finite() && r >= 0.0 => r,
            Some(r) => {
                return Err(bad(
                    "success.min_rate",
                    format!("{r} must be finite and at least zero"),
                ));
            }
            None => rates
                .iter()
                .map(|&(i, _)| periods[i].map_or(0.1, |p| p / 10.0))
                .fold(f64::INFINITY, f64::min),
        };
        let min_rate = if min_rate.is_finite() { min_rate } else { 0.1 };
        // Every position target a quadratic term pulls to, once per entry and target.
        let mut all: Vec<(usize, f64, Option<f64>)> = Vec::new();
        for t in cost.running.iter().chain(&cost.final_terms) {
            if t.quadratic != 0.0
                && t.index < n
                && !all
                    .iter()
                    .any(|&(i, target, _)| i == t.index && target == t.target)
            {
                all.push((t.index, t.target, t.period));
            }
        }
        let targets = match &spec.targets {
            None if rates.is_empty() => all,
            None => Vec::new(),
            Some(list) => {
                let mut out = Vec::new();
                for c in list {
                    let chosen: Vec<_> = all
                        .iter()
                        .filter(|&&(i, ..)| names[i] == *c)
                        .copied()
                        .collect();
                    if chosen.is_empty() {
                        return Err(bad(
                            "success.targets",
                            format!(
                                "\"{c}\" has no position target (no quadratic term on it); the targets are {}",
                                if all.is_empty() {
                                    "none".to_string()
                                } else {
                                    all.iter()
                                        .map(|&(i, ..)| names[i].clone())
                                        .collect::<Vec<_>>()
                                        .join(", ")
                                }
                            ),
                        ));
                    }
                    out.extend(chosen);
                }
                out
            }
        };
        let tolerance = match spec.tolerance {
            Some(t) if t.is_finite() && t > 0.0 => t,
            Some(t) => {
                return Err(bad(
                    "success.tolerance",
                    format!("{t} must be finite and positive"),
                ));
            }
            None => targets
                .iter()
                .map(|&(i, target, period)| wrapped_offset(x0[i], target, period).abs() / 10.0)
                .fold(0.05, f64::max),
        };
        let settle = match spec.settle {
            Some(s) if s.is_finite() && s > 0.0 => s,
            Some(s) => {
                return Err(bad(
                    "success.settle",
                    format!("{s} must be finite and positive (seconds)"),
                ));
            }
            None => DEFAULT_SETTLE,
        };
        Ok(Success {
            rates,
            min_rate,
            targets,
            tolerance,
            settle,
        })
    }

    /// `(position entry, direction)` of every coordinate whose linear running weights (on it and on its
    /// velocity) sum to a reward, the direction the cost falls.
    pub fn rewarded(cost: &TaskCost, n: usize) -> Vec<(usize, f64)> {
        let mut weights: Vec<(usize, f64)> = Vec::new();
        for t in &cost.running {
            if t.linear == 0.0 {
                continue;
            }
            let j = t.index % n;
            match weights.iter_mut().find(|(i, _)| *i == j) {
                Some((_, w)) => *w += t.linear,
                None => weights.push((j, t.linear)),
            }
        }
        weights
            .into_iter()
            .filter(|&(_, w)| w != 0.0)
            .map(|(j, w)| (j, -w.signum()))
            .collect()
    }

    /// The criterion of a task that rewards turning the entry `free` (period `period`) forward: the
    /// finger's built-in task's.
    pub fn spin(free: usize, period: f64) -> Self {
        Success {
            rates: vec![(free, 1.0)],
            min_rate: period / 10.0,
            targets: Vec::new(),
            tolerance: 0.05,
            settle: DEFAULT_SETTLE,
        }
    }

    /// The largest distance of a judged target from its target at `x` (0 without targets).
    pub fn distance(&self, x: &[f64]) -> f64 {
        self.targets
            .iter()
            .map(|&(i, target, period)| wrapped_offset(x[i], target, period).abs())
            .fold(0.0, f64::max)
    }

    /// Whether every judged target is within the tolerance of its target at `x`.
    pub fn within(&self, x: &[f64]) -> bool {
        self.distance(x) <= self.tolerance
    }

    /// Whether the task holds targets (and rewards no progress): perturbations are judged by the way
    /// back to them.
    pub fn holds(&self) -> bool {
        self.rates.is_empty()
    }

    /// In words.
    pub fn describe(&self, names: &[String]) -> String {
        let mut parts = Vec::new();
        if !self.rates.is_empty() {
            parts.push(format!(
                "{} at least {:.3} per second the rewarded way over the last quarter",
                self.rates
                    .iter()
                    .map(|&(i, _)| names[i].clone())
                    .collect::<Vec<_>>()
                    .join(", "),
                self.min_rate
            ));
        }
        if !self.targets.is_empty() {
            parts.push(format!(
                "{} within {} of the target throughout the last quarter",
                self.targets
                    .iter()
                    .map(|&(i, t, _)| format!("{} -> {t}", names[i]))
                    .collect::<Vec<_>>()
                    .join(", "),
                self.tolerance
            ));
        }
        if parts.is_empty() {
            "nothing (the task rewards no progress and holds no target)".into()
        } else {
            parts.join("; ")
        }
    }
}

/// The scene file the commands, the viewer and the Python package use when given none: `scenes/finger.toml`,
/// SCENE.md's flicking finger with the paper's `spin` task (its only task). It is read like any other
/// scene file ([`ProblemFile::builtin`]); nothing about the finger is written anywhere else.
pub const BUILTIN_SCENE_FILE: &str = include_str!("../../../scenes/finger.toml");

/// A scene file with its tasks: the scene checked by [`dynamics::Scene`], the `[task.NAME]` tables kept
/// as written until one is asked for.
#[derive(Debug, Clone)]
pub struct ProblemFile {
    /// The scene.
    pub scene: Scene,
    /// The tasks by name.
    pub tasks: BTreeMap<String, TaskSpec>,
}

impl ProblemFile {
    /// Parse a scene file and its tasks (every task table strictly: unknown keys are refused).
    pub fn from_toml_str(text: &str) -> Result<Self, TaskError> {
        let mut table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
            TaskError::Dynamics(dynamics::DynamicsError::Parse(e.to_string()))
        })?;
        let tasks = match table.remove("task") {
            None => BTreeMap::new(),
            Some(value) => {
                let tasks: toml::Table =
                    value
                        .try_into()
                        .map_err(|e: toml::de::Error| TaskError::Spec {
                            task: String::new(),
                            field: "task".into(),
                            problem: format!("must be tables [task.NAME]: {e}"),
                        })?;
                let mut out = BTreeMap::new();
                for (name, value) in tasks {
                    // Deserialised through the path tracker, so that an error names its field
                    // (`control_limits: invalid length 3, expected an array of length 2`).
                    let spec: TaskSpec = serde_path_to_error::deserialize(value).map_err(
                        |e: serde_path_to_error::Error<toml::de::Error>| {
                            let path = e.path().to_string();
                            TaskError::Spec {
                                task: name.clone(),
                                field: if path == "." { String::new() } else { path },
                                problem: e.into_inner().message().to_string(),
                            }
                        },
                    )?;
                    out.insert(name, spec);
                }
                out
            }
        };
        // The scene as the dynamics crate reads it (it skips the task tables).
        let scene = Scene::from_toml_str(text)?;
        // Check every task now, so that a bad one is reported whichever is asked for.
        for (name, spec) in &tasks {
            Task::new(&scene, name, spec)?;
        }
        Ok(ProblemFile { scene, tasks })
    }

    /// [`BUILTIN_SCENE_FILE`], parsed (a test checks that it parses, so this cannot fail).
    pub fn builtin() -> Self {
        Self::from_toml_str(BUILTIN_SCENE_FILE).expect("scenes/finger.toml is a valid scene file")
    }

    /// The built-in file's scene and its only task (`spin`).
    pub fn builtin_task() -> (Scene, Task) {
        let file = Self::builtin();
        let task = file
            .task(None)
            .expect("scenes/finger.toml has one valid task");
        (file.scene, task)
    }

    /// Read and parse a scene file.
    pub fn load(path: &std::path::Path) -> Result<Self, TaskError> {
        let io = |source| TaskError::Io {
            path: path.display().to_string(),
            source,
        };
        // Refused by size before it is read: a scene file is small (dynamics::MAX_SCENE_TEXT).
        let size = std::fs::metadata(path).map_err(io)?.len();
        if size > dynamics::MAX_SCENE_TEXT as u64 {
            return Err(TaskError::Dynamics(dynamics::DynamicsError::Parse(
                format!(
                    "{}: {size} bytes, over the {} of a scene file (dynamics::MAX_SCENE_TEXT)",
                    path.display(),
                    dynamics::MAX_SCENE_TEXT
                ),
            )));
        }
        let text = std::fs::read_to_string(path).map_err(io)?;
        Self::from_toml_str(&text)
    }

    /// The task called `name`, or with `None` the file's only task.
    pub fn task(&self, name: Option<&str>) -> Result<Task, TaskError> {
        let listed = || {
            if self.tasks.is_empty() {
                "the file has no [task.NAME] table".to_string()
            } else {
                format!(
                    "it has {}",
                    self.tasks.keys().cloned().collect::<Vec<_>>().join(", ")
                )
            }
        };
        let (name, spec) = match name {
            Some(name) => self
                .tasks
                .get_key_value(name)
                .ok_or_else(|| TaskError::Spec {
                    task: name.to_string(),
                    field: String::new(),
                    problem: format!("no such task ({})", listed()),
                })?,
            None => {
                let mut it = self.tasks.iter();
                match (it.next(), it.next()) {
                    (Some(only), None) => only,
                    _ => {
                        return Err(TaskError::Spec {
                            task: String::new(),
                            field: String::new(),
                            problem: format!("name the task to use ({})", listed()),
                        });
                    }
                }
            }
        };
        Task::new(&self.scene, name, spec)
    }
}
