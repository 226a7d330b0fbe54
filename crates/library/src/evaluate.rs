//! Running the global policy (paper section V-C): closed loop on a world simulator that may use another
//! contact model or time step than the library was built with, with random velocity kicks, measuring how
//! fast the ellipse spins, how often the finger touches it, and how the spin recovers after each kick;
//! and, for any task, what its own cost says ([`TaskMeasures`]).

use crate::error::LibraryError;
use crate::file::Library;
use crate::policy::Policy;
use dynamics::{Simulator, StepSettings};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use task::Progress;

/// How a policy is evaluated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvaluationSettings {
    /// The world's contact model.
    pub model: task::ContactModel,
    /// The world's time step.
    pub h: f64,
    /// Simulated time.
    pub seconds: f64,
    /// A velocity kick every this many seconds (0: none; finite and non-negative).
    pub kick_every: f64,
    /// Standard deviation of each velocity's kick.
    pub kick_std: f64,
    /// Seed of the kicks.
    pub seed: u64,
    /// Initial state; empty (the default): the library's task's.
    pub x0: Vec<f64>,
}

impl Default for EvaluationSettings {
    fn default() -> Self {
        EvaluationSettings {
            model: task::ContactModel::Logistic(0.1),
            h: 0.05,
            seconds: 200.0,
            kick_every: 10.0,
            kick_std: 2.0,
            seed: 7,
            x0: Vec::new(),
        }
    }
}

/// What a closed-loop run measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Mean spin rate of the free angle over the run, rad/s.
    pub spin_rate: f64,
    /// Mean spin rate over the last quarter of the run, rad/s.
    pub final_spin_rate: f64,
    /// Contact events (the contact impulse rising above [`CONTACT_IMPULSE`] after having fallen below a
    /// tenth of it, so that a smoothed impulse flickering around the threshold counts once) per half-turn
    /// of the ellipse; `None` when the ellipse turned less than half a turn in all (no ratio to speak of).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contacts_per_half_turn: Option<f64>,
    /// Contact events per second.
    pub contacts_per_second: f64,
    /// Fraction of steps with a contact impulse.
    pub contact_fraction: f64,
    /// Kicks applied.
    pub kicks: usize,
    /// Kicks after which the progress coordinate moved the way the task rewards (forward for the finger)
    /// over the second half of the next interval; for a target task, after which every judged target was
    /// back within tolerance at the end of the interval.
    pub recovered: usize,
    /// Kicks after which the progress coordinate turned a further quarter turn the way the task rewards
    /// before the next kick (the stricter measure); for a target task, after which every judged target was
    /// back within tolerance within the task's settle time ([`task::Success::settle`]).
    pub resumed: usize,
    /// Mean time from a kick to that quarter turn (or back within tolerance), over the kicks that
    /// resumed, s; `None` when none did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resume_time: Option<f64>,
    /// Mean spin rate over the second half of each interval between kicks, rad/s; `None` without kicks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spin_after_kicks: Option<f64>,
    /// Steps whose complementarity solve did not converge (they still advance the state).
    pub unconverged_steps: usize,
    /// The free angle at the end.
    pub final_angle: f64,
    /// The task-neutral measures, read off the library's task cost.
    #[serde(default)]
    pub task: TaskMeasures,
    /// Whether the run met the task's success criterion.
    pub success: Verdict,
}

/// A run judged by its task's success criterion ([`task::Success`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// Whether it succeeded.
    pub passed: bool,
    /// The least last-quarter rate, the rewarded way, of the rewarded coordinates (`None`: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate: Option<f64>,
    /// The largest distance of a judged target from its target: the worst over the last quarter without
    /// kicks, at the end with them (`None`: no judged target).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance: Option<f64>,
    /// The criterion in words.
    pub criterion: String,
}

impl Verdict {
    /// A run's verdict from its least last-quarter rate and its largest target distance (each `None`
    /// where the task judges none): passed when the rate is at least the least rate and the distance
    /// within the tolerance, and the task judges at least one of them. `names` are the scene's
    /// coordinates, for the criterion in words.
    pub(crate) fn of(
        success: &task::Success,
        rate: Option<f64>,
        distance: Option<f64>,
        names: &[String],
    ) -> Self {
        Verdict {
            passed: rate.is_none_or(|r| r >= success.min_rate)
                && distance.is_none_or(|d| d <= success.tolerance)
                && (rate.is_some() || distance.is_some()),
            rate,
            distance,
            criterion: success.describe(names),
        }
    }
}

/// What a closed-loop run achieved by the measure of the library's own task cost (any scene and task;
/// the finger's built-in task is `-theta3 + 0.05 |u|^2`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TaskMeasures {
    /// The task's running cost (its running terms and the control cost) as the optimiser accrues it, once
    /// per library time step, over the run and per second: each world step's cost counts `h / h_library`
    /// times, so worlds of different time steps compare. A linear term on a position
    /// keeps falling as its coordinate advances, so for a progress task [`TaskMeasures::rates`] is the
    /// measure to compare.
    pub running_cost_per_second: f64,
    /// The same over the last quarter of the run.
    pub final_running_cost_per_second: f64,
    /// Each coordinate a linear term (running or final, on it or on its velocity) weighs: how fast it
    /// moved.
    pub rates: Vec<CoordinateRate>,
    /// Each entry a quadratic term pulls to a target: its distance (wrapped for a periodic entry), once
    /// per entry and target however many terms name them.
    pub targets: Vec<TargetDistance>,
}

/// How fast a linearly weighted coordinate moved in a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoordinateRate {
    /// Its name (`<body>.angle`).
    pub coordinate: String,
    /// The sum of the linear weights on it and on its velocity (negative: the task rewards increase).
    pub weight: f64,
    /// Mean rate of change over the run, per second.
    pub rate: f64,
    /// Mean rate of change over the last quarter of the run.
    pub final_rate: f64,
}

/// How far a quadratic term's entry stayed from its target in a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TargetDistance {
    /// The entry's name (`<body>.angle`, or `<body>.angle velocity`).
    pub entry: String,
    /// Its target.
    pub target: f64,
    /// Whether only final terms name it (the optimiser weighs it at the horizon only).
    pub final_only: bool,
    /// Mean absolute distance over the run.
    pub mean: f64,
    /// Mean absolute distance over the last quarter.
    pub final_mean: f64,
    /// Largest absolute distance over the last quarter, its final state included.
    pub final_worst: f64,
    /// Absolute distance at the end.
    pub last: f64,
}

/// Accumulates [`TaskMeasures`] along a run.
struct TaskMeter {
    cost: task::TaskCost,
    n: usize,
    h: f64,
    quarter: usize,
    /// The share of one optimiser step a world step is (`h / h_library`).
    share: f64,
    running: [f64; 2],
    /// Per quadratic term: sums of the distance over the run and the last quarter, the worst in it.
    targets: Vec<(task::Term, bool, [f64; 2], f64)>,
}

impl TaskMeter {
    fn new(cost: task::TaskCost, n: usize, h: f64, h_library: f64, quarter: usize) -> Self {
        let mut targets: Vec<(task::Term, bool, [f64; 2], f64)> = Vec::new();
        let terms = cost.running.iter().map(|t| (t, false));
        for (t, fin) in terms.chain(cost.final_terms.iter().map(|t| (t, true))) {
            let same = |(o, ..): &&(task::Term, bool, [f64; 2], f64)| {
                o.index == t.index && o.target == t.target && o.period == t.period
            };
            if t.quadratic != 0.0 && !targets.iter().any(|e| same(&e)) {
                targets.push((*t, fin, [0.0; 2], 0.0));
            }
        }
        TaskMeter {
            cost,
            n,
            h,
            quarter,
            share: h / h_library,
            running: [0.0; 2],
            targets,
        }
    }

    /// Step `k`'s state and control.
    fn observe(&mut self, k: usize, x: &[f64], u: &[f64]) {
        use ddp::Cost;
        let late = k >= self.quarter;
        let l = self.cost.running(k, x, u) * self.share;
        self.running[0] += l;
        for (t, _, sums, worst) in &mut self.targets {
            let d = t.offset(x[t.index]).abs();
            sums[0] += d;
            if late {
                sums[1] += d;
                *worst = worst.max(d);
            }
        }
        if late {
            self.running[1] += l;
        }
    }

    fn finish(
        self,
        scene: &dynamics::Scene,
        steps: usize,
        x0: &[f64],
        at_quarter: &[f64],
        x: &[f64],
    ) -> TaskMeasures {
        let names = scene.state_names();
        let time = steps as f64 * self.h;
        let late_steps = steps - self.quarter;
        let late_time = late_steps as f64 * self.h;
        let mut weights: Vec<(usize, f64)> = Vec::new();
        for t in self.cost.running.iter().chain(&self.cost.final_terms) {
            if t.linear == 0.0 {
                continue;
            }
            let j = t.index % self.n;
            match weights.iter_mut().find(|(i, _)| *i == j) {
                Some((_, w)) => *w += t.linear,
                None => weights.push((j, t.linear)),
            }
        }
        TaskMeasures {
            running_cost_per_second: self.running[0] / time,
            final_running_cost_per_second: self.running[1] / late_time,
            rates: weights
                .into_iter()
                .map(|(j, weight)| CoordinateRate {
                    coordinate: names[j].clone(),
                    weight,
                    rate: (x[j] - x0[j]) / time,
                    final_rate: (x[j] - at_quarter[j]) / late_time,
                })
                .collect(),
            targets: self
                .targets
                .into_iter()
                .map(|(t, final_only, sums, worst)| {
                    let last = t.offset(x[t.index]).abs();
                    TargetDistance {
                        entry: names[t.index].clone(),
                        target: t.target,
                        final_only,
                        mean: sums[0] / steps as f64,
                        final_mean: sums[1] / late_steps as f64,
                        // The last quarter's states and the final one.
                        final_worst: worst.max(last),
                        last,
                    }
                })
                .collect(),
        }
    }
}

/// The longest closed loop [`evaluate`] runs, in time steps (a few minutes of computing on the finger).
pub const MAX_EVALUATION_STEPS: usize = 10_000_000;

/// A contact impulse this large (in the normal direction, per step) counts as touching.
pub const CONTACT_IMPULSE: f64 = 1e-3;

/// Counts contact events along a run: the impulse rising above [`CONTACT_IMPULSE`] after having fallen
/// below a tenth of it, so that a smoothed impulse flickering around the threshold counts once.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ContactEvents {
    touching: bool,
    /// Events so far.
    pub events: usize,
    /// Steps with an impulse above the threshold so far.
    pub touching_steps: usize,
}

impl ContactEvents {
    /// Count one step's contact impulse.
    pub fn observe(&mut self, impulse: f64) {
        if impulse > CONTACT_IMPULSE {
            self.touching_steps += 1;
            if !self.touching {
                self.events += 1;
            }
            self.touching = true;
        } else if impulse < 0.1 * CONTACT_IMPULSE {
            self.touching = false;
        }
    }
}

/// Run the library's policy on a world described by `settings`.
pub fn evaluate(
    library: &Library,
    policy: &Policy,
    settings: &EvaluationSettings,
) -> Result<Evaluation, LibraryError> {
    evaluate_in(library.scene(), library, policy, settings)
}

/// [`evaluate`] in a world whose scene differs from the library's (other friction, masses, drag: a
/// model the library never saw); it must have the library's state, controls and free joint. The policy
/// runs at the world's time step ([`Policy::with_time_step`]).
pub fn evaluate_in(
    scene: &dynamics::Scene,
    library: &Library,
    policy: &Policy,
    settings: &EvaluationSettings,
) -> Result<Evaluation, LibraryError> {
    let judge = Judge {
        own: library.scene(),
        progress: library.progress()?,
        success: library.success(),
        cost: library.cost(),
        x0: &library.task().x0,
        h: library.settings.h,
    };
    closed_loop(scene, &judge, policy, settings)
}

/// The library's side of a closed loop: its scene, its task's progress coordinate, success criterion,
/// cost and start, and the time step its controllers were optimised at. A [`Library`] has them, and so
/// has a library still being built (whose final check judges its worlds as [`evaluate`] does).
pub(crate) struct Judge<'a> {
    pub(crate) own: &'a dynamics::Scene,
    pub(crate) progress: Progress,
    pub(crate) success: &'a task::Success,
    pub(crate) cost: &'a task::TaskCost,
    /// The start when the settings give none.
    pub(crate) x0: &'a [f64],
    pub(crate) h: f64,
}

/// [`evaluate_in`] with the library's side given by `judge`.
pub(crate) fn closed_loop(
    scene: &dynamics::Scene,
    judge: &Judge,
    policy: &Policy,
    settings: &EvaluationSettings,
) -> Result<Evaluation, LibraryError> {
    let own = judge.own;
    // The policy at the world's time step (the controllers growth optimised for it preferred).
    let policy = &policy.clone().with_time_step(settings.h)?;
    let n = scene.n_dof();
    // The coordinate the library's task measures progress along.
    let progress = judge.progress;
    let free = progress.coordinate;
    // The direction the task rewards (the finger's forward spin is +1; a task with a negative linear
    // weight rewards the other way): the kick measures count progress that way.
    let forward = progress.forward.unwrap_or(1.0);
    // A task that rewards no progress has its kicks judged by the way back to its targets.
    let success = judge.success;
    let holds = progress.forward.is_none();
    if scene.n_state() != own.n_state() || scene.n_controls != own.n_controls {
        return Err(LibraryError::SceneMismatch(format!(
            "the world has {} states and {} controls; the library {} and {}",
            scene.n_state(),
            scene.n_controls,
            own.n_state(),
            own.n_controls,
        )));
    }
    if !(settings.h.is_finite() && settings.h > 0.0) {
        return Err(LibraryError::Setting {
            name: "h",
            value: settings.h,
            expected: "finite and positive",
        });
    }
    if !(settings.seconds.is_finite() && settings.seconds >= settings.h) {
        return Err(LibraryError::Setting {
            name: "seconds",
            value: settings.seconds,
            expected: "at least one time step",
        });
    }
    if settings.seconds / settings.h > MAX_EVALUATION_STEPS as f64 {
        return Err(LibraryError::Setting {
            name: "seconds",
            value: settings.seconds,
            expected: "at most 1e7 time steps",
        });
    }
    if !(settings.kick_every.is_finite() && settings.kick_every >= 0.0) {
        return Err(LibraryError::Setting {
            name: "kick_every",
            value: settings.kick_every,
            expected: "finite and non-negative (0: no kicks)",
        });
    }
    // A kick of 1e300 overflows the step (a NaN in its complementarity problem); a million units of
    // velocity is already far past any scene's own scale.
    if !(settings.kick_std.is_finite() && (0.0..=1e6).contains(&settings.kick_std)) {
        return Err(LibraryError::Setting {
            name: "kick_std",
            value: settings.kick_std,
            expected: "between 0 and 1e6",
        });
    }
    let x0 = crate::start(&settings.x0, judge.x0);
    crate::check("x0", x0, scene.n_state())?;
    let mut world = Simulator::new(
        scene.clone(),
        StepSettings {
            model: settings.model.complementarity(),
            h: settings.h,
            ..StepSettings::default()
        },
    )?;
    let steps = (settings.seconds / settings.h).round() as usize;
    let kick_steps = if settings.kick_every > 0.0 {
        ((settings.kick_every / settings.h).round() as usize).max(1)
    } else {
        usize::MAX
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(settings.seed);
    let kick =
        Normal::new(0.0, settings.kick_std).map_err(|e| LibraryError::Invalid(e.to_string()))?;
    let mut x = x0.to_vec();
    let mut u = vec![0.0; scene.n_controls];
    let mut contacts = ContactEvents::default();
    let mut unconverged = 0usize;
    let (mut kicks, mut recovered) = (0usize, 0usize);
    // The free angle at the last kick, until the ellipse has turned a quarter turn past it.
    let mut since_kick: Option<(usize, f64)> = None;
    let (mut resumed, mut resume_steps) = (0usize, 0usize);
    let (mut after_sum, mut after_time) = (0.0, 0.0);
    let mut interval_start = x[free];
    let quarter = steps - steps / 4;
    let mut angle_at_quarter = x[free];
    let mut meter = TaskMeter::new(judge.cost.clone(), n, settings.h, judge.h, quarter);
    let mut at_quarter = x.clone();
    let settle_steps = ((success.settle / settings.h).round() as usize).max(1);
    let mut late_distance: f64 = 0.0;
    for k in 0..steps {
        if k == quarter {
            angle_at_quarter = x[free];
            at_quarter.copy_from_slice(&x);
        }
        // A kick with less than a whole interval left could not be judged: none is given.
        if k > 0 && k % kick_steps == 0 && k + kick_steps <= steps {
            // The interval that ends here: did it spin forward over its second half?
            kicks += 1;
            since_kick = Some((k, x[free]));
            for v in &mut x[n..] {
                *v += kick.sample(&mut rng);
            }
        }
        if k % kick_steps == kick_steps / 2 && k > kick_steps {
            interval_start = x[free];
        }
        if k % kick_steps == kick_steps - 1 && k > kick_steps {
            let rate = (x[free] - interval_start) / (settings.h * (kick_steps / 2) as f64);
            after_sum += rate * (kick_steps / 2) as f64 * settings.h;
            after_time += (kick_steps / 2) as f64 * settings.h;
            let back = if holds {
                success.within(&x)
            } else {
                forward * rate > 0.0
            };
            if back {
                recovered += 1;
            }
        }
        if k >= quarter {
            late_distance = late_distance.max(success.distance(&x));
        }
        policy.control(&x, &mut u)?;
        meter.observe(k, &x, &u);
        let s = world.step(&x, &u)?;
        if s.info.status != ncp::Status::Converged {
            unconverged += 1;
        }
        contacts.observe(s.normal_impulse());
        x = s.x_next;
        if let Some((at, angle)) = since_kick {
            let after = k + 1 - at;
            let back = if holds {
                success.within(&x)
            } else {
                forward * (x[free] - angle) >= std::f64::consts::FRAC_PI_2
            };
            if back && (!holds || after <= settle_steps) {
                resumed += 1;
                resume_steps += after;
                since_kick = None;
            } else if holds && after > settle_steps {
                since_kick = None;
            }
        }
        if !x.iter().all(|v| v.is_finite()) {
            return Err(LibraryError::Diverged { step: k });
        }
    }
    let (events, touching_steps) = (contacts.events, contacts.touching_steps);
    let task = meter.finish(scene, steps, x0, &at_quarter, &x);
    let turned = x[free] - x0[free];
    let time = steps as f64 * settings.h;
    let late_time = (steps - quarter) as f64 * settings.h;
    let rate = success
        .rates
        .iter()
        .map(|&(i, direction)| direction * (x[i] - at_quarter[i]) / late_time)
        .reduce(f64::min);
    let distance = (!success.targets.is_empty()).then(|| {
        let last = success.distance(&x);
        if kicks > 0 {
            last
        } else {
            late_distance.max(last)
        }
    });
    let verdict = Verdict::of(success, rate, distance, &scene.coordinate_names());
    Ok(Evaluation {
        spin_rate: turned / time,
        final_spin_rate: (x[free] - angle_at_quarter) / ((steps - quarter) as f64 * settings.h),
        contacts_per_half_turn: (turned.abs() >= std::f64::consts::PI)
            .then(|| events as f64 / (turned.abs() / std::f64::consts::PI)),
        contacts_per_second: events as f64 / time,
        contact_fraction: touching_steps as f64 / steps as f64,
        kicks,
        recovered: recovered.min(kicks),
        resumed,
        resume_time: (resumed > 0).then(|| resume_steps as f64 * settings.h / resumed as f64),
        spin_after_kicks: (after_time > 0.0).then(|| after_sum / after_time),
        unconverged_steps: unconverged,
        final_angle: x[free],
        task,
        success: verdict,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use task::{TaskCost, Term};

    #[test]
    fn the_task_meter_sums_costs_rates_and_wrapped_distances() {
        // One joint: x = [q, v]. Running: -q (linear) and (q - 3)^2 / 2 wrapped by 2 pi; final: v^2.
        let term = |index, linear, quadratic, target, period| Term {
            index,
            linear,
            quadratic,
            target,
            period,
        };
        let cost = TaskCost {
            running: vec![
                term(0, -1.0, 0.0, 0.0, None),
                term(0, 0.0, 1.0, 3.0, Some(std::f64::consts::TAU)),
            ],
            final_terms: vec![term(1, 0.0, 2.0, 0.0, None)],
            control_weight: 0.5,
        };
        let finger = task::ProblemFile::builtin().scene;
        let scene = dynamics::Scene::new(dynamics::SceneSpec {
            bodies: vec![finger.spec().bodies[2].clone()],
            contacts: vec![],
            ..finger.spec().clone()
        })
        .unwrap();
        let name = scene.coordinate_names()[0].clone();
        // Four world steps of h = 0.1 against a library step of 0.05: each step's cost counts twice.
        let states = [[0.0, 1.0], [0.1, 1.0], [6.0, 1.0], [7.0, 2.0]];
        let mut meter = TaskMeter::new(cost, 1, 0.1, 0.05, 3);
        for (k, x) in states.iter().enumerate() {
            meter.observe(k, x, &[1.0]);
        }
        let end = [7.5, 3.0];
        let m = meter.finish(&scene, 4, &states[0], &states[3], &end);
        // Distances to 3, the offsets wrapped into [-pi, pi): 3, 2.9, 3 (still inside), |7 - 3 - 2 pi|.
        let d = [3.0, 2.9, 3.0, (7.0 - 3.0 - std::f64::consts::TAU).abs()];
        let l: Vec<f64> = states
            .iter()
            .zip(d)
            .map(|(x, d)| 2.0 * (-x[0] + 0.5 * d * d + 0.5))
            .collect();
        assert!((m.running_cost_per_second - l.iter().sum::<f64>() / 0.4).abs() < 1e-12);
        assert!((m.final_running_cost_per_second - l[3] / 0.1).abs() < 1e-12);
        let [rate] = m.rates.as_slice() else {
            panic!("{:?}", m.rates)
        };
        assert_eq!(
            (rate.coordinate.as_str(), rate.weight),
            (name.as_str(), -1.0)
        );
        assert!((rate.rate - 7.5 / 0.4).abs() < 1e-12);
        assert!((rate.final_rate - 0.5 / 0.1).abs() < 1e-12);
        let [angle, speed] = m.targets.as_slice() else {
            panic!("{:?}", m.targets)
        };
        assert!(!angle.final_only && speed.final_only);
        assert_eq!(speed.entry, format!("{name} velocity"));
        assert!((angle.mean - d.iter().sum::<f64>() / 4.0).abs() < 1e-12);
        assert!((angle.final_mean - d[3]).abs() < 1e-12);
        assert!((angle.final_worst - d[3].max(angle.last)).abs() < 1e-12);
        assert!((angle.last - (7.5 - 3.0 - std::f64::consts::TAU).abs()).abs() < 1e-12);
        assert!((speed.mean - 1.25).abs() < 1e-12 && speed.last == 3.0 && speed.final_worst == 3.0);
    }
}
