//! Running the global policy (paper section V-C): closed loop on a world simulator that may use another
//! contact model or time step than the library was built with, with random velocity kicks, measuring how
//! fast the ellipse spins, how often the finger touches it, and how the spin recovers after each kick.

use crate::error::LibraryError;
use crate::file::Library;
use crate::policy::Policy;
use dynamics::{Simulator, StepSettings};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// How a policy is evaluated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvaluationSettings {
    /// The world's contact model.
    pub model: crate::Model,
    /// The world's time step.
    pub h: f64,
    /// Simulated time.
    pub seconds: f64,
    /// A velocity kick every this many seconds (none if not positive).
    pub kick_every: f64,
    /// Standard deviation of each velocity's kick.
    pub kick_std: f64,
    /// Seed of the kicks.
    pub seed: u64,
    /// Initial state.
    pub x0: Vec<f64>,
}

impl Default for EvaluationSettings {
    fn default() -> Self {
        EvaluationSettings {
            model: crate::Model::Logistic(0.1),
            h: 0.05,
            seconds: 200.0,
            kick_every: 10.0,
            kick_std: 2.0,
            seed: 7,
            x0: dynamics::FLICKING_FINGER_X0.to_vec(),
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
    /// Kicks after which the spin rate over the second half of the next interval was positive.
    pub recovered: usize,
    /// Kicks after which the ellipse turned a further quarter turn forward before the next kick (the
    /// stricter measure).
    pub resumed: usize,
    /// Mean time from a kick to that quarter turn, over the kicks that resumed, s; `None` when none did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resume_time: Option<f64>,
    /// Mean spin rate over the second half of each interval between kicks, rad/s; `None` without kicks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spin_after_kicks: Option<f64>,
    /// Steps whose complementarity solve did not converge (they still advance the state).
    pub unconverged_steps: usize,
    /// The free angle at the end.
    pub final_angle: f64,
}

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
/// model the library never saw); it must have the library's state, controls and free joint.
pub fn evaluate_in(
    scene: &dynamics::Scene,
    library: &Library,
    policy: &Policy,
    settings: &EvaluationSettings,
) -> Result<Evaluation, LibraryError> {
    let own = library.scene();
    let n = scene.n_dof();
    // The library's periodic coordinate (its task's, or the finger's free joint, which the world must
    // share).
    let free = library.progress()?.coordinate;
    let world_free = match library.task() {
        Some(_) => free,
        None => crate::free_joint(scene)?,
    };
    if scene.n_state() != own.n_state() || scene.n_controls != own.n_controls || free != world_free
    {
        return Err(LibraryError::SceneMismatch(format!(
            "the world has {} states, {} controls and free joint {world_free}; the library {}, {} and {free}",
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
    if !(settings.kick_std.is_finite() && settings.kick_std >= 0.0) {
        return Err(LibraryError::Setting {
            name: "kick_std",
            value: settings.kick_std,
            expected: "finite and non-negative",
        });
    }
    crate::check("x0", &settings.x0, scene.n_state())?;
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
    let mut x = settings.x0.clone();
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
    for k in 0..steps {
        if k == quarter {
            angle_at_quarter = x[free];
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
            if rate > 0.0 {
                recovered += 1;
            }
        }
        policy.control(&x, &mut u)?;
        let s = world.step(&x, &u)?;
        if s.info.status != ncp::Status::Converged {
            unconverged += 1;
        }
        contacts.observe(s.normal_impulse());
        x = s.x_next;
        if let Some((at, angle)) = since_kick
            && x[free] - angle >= std::f64::consts::FRAC_PI_2
        {
            resumed += 1;
            resume_steps += k + 1 - at;
            since_kick = None;
        }
        if !x.iter().all(|v| v.is_finite()) {
            return Err(LibraryError::Invalid(format!(
                "the closed loop produced a non-finite state at step {k}"
            )));
        }
    }
    let (events, touching_steps) = (contacts.events, contacts.touching_steps);
    let turned = x[free] - settings.x0[free];
    let time = steps as f64 * settings.h;
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
    })
}
