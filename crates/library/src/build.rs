//! The trajectory library of paper section IV-C: receding-horizon optimisation from an initial state,
//! keeping each trajectory's first local controller `u(x) = u_1 + K_1 (x - x_1)`, shifting by `d` steps
//! with the warm start of eq. (19), and perturbing the initial state's velocities every few steps.

use crate::error::LibraryError;
use crate::task::{FingerDynamics, finger_cost};
use ddp::{Ddp, DdpError, DdpSettings};
use dynamics::{Complementarity, Scene, Simulator, StepSettings};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// The contact model a library is built on (a plain enum so that library files stay compact and
/// self-contained).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Model {
    /// Hard contact (the active set's derivatives).
    Hard,
    /// Logistic smoothing (eq. 17) with this sigma.
    Logistic(f64),
    /// Normal smoothing (eq. 14 with 15) with this sigma.
    Normal(f64),
}

impl Model {
    /// The simulator's model.
    pub fn complementarity(self) -> Complementarity {
        match self {
            Model::Hard => Complementarity::Hard,
            Model::Logistic(sigma) => Complementarity::Logistic { sigma },
            Model::Normal(sigma) => Complementarity::Normal { sigma },
        }
    }
}

/// How a library is built (SCENE.md, paper V-B).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LibrarySettings {
    /// Contact model of the optimiser's dynamics.
    pub model: Model,
    /// Time step.
    pub h: f64,
    /// Optimisation horizon `N`.
    pub horizon: usize,
    /// Shift `d` between consecutive trajectories.
    pub shift: usize,
    /// Number of trajectories (= stored controllers).
    pub trajectories: usize,
    /// Independent receding-horizon chains the trajectories are split into, built in parallel (one
    /// thread each); chain `c` starts from `x0` with kick seed `seed + c`. The paper's library is one
    /// chain.
    pub chains: usize,
    /// Perturb the initial state's velocities every this many time steps.
    pub kick_every: usize,
    /// Variance of each velocity's normal perturbation.
    pub kick_variance: f64,
    /// Seed of the perturbations.
    pub seed: u64,
    /// The first trajectory's initial state.
    pub x0: Vec<f64>,
    /// Passes at most for the first solve (from zero controls).
    pub first_passes: usize,
    /// Passes at most for each warm-started re-solve.
    pub warm_passes: usize,
    /// The optimiser's stopping tolerance on the relative cost change (`DdpSettings::tol_cost`). The
    /// default 1e-5 builds the library about 1.6 times faster than 1e-9 with the same closed-loop
    /// quality within the spread between seeds (docs/benchmarks.md, "library tolerance"); 1e-4 spins
    /// clearly slower.
    pub tolerance: f64,
    /// Local controllers kept per trajectory: the paper keeps the first (1); up to `shift` keeps
    /// `u_t + K_t (x - x_t)` for `t < keep` as well, the controllers the trajectory runs before the next one
    /// takes over.
    pub keep: usize,
}

impl Default for LibrarySettings {
    fn default() -> Self {
        LibrarySettings {
            model: Model::Logistic(0.1),
            h: 0.05,
            horizon: 75,
            shift: 4,
            trajectories: 400,
            chains: 1,
            kick_every: 15,
            kick_variance: 4.0,
            seed: 1,
            x0: dynamics::FLICKING_FINGER_X0.to_vec(),
            first_passes: 300,
            warm_passes: 100,
            tolerance: 1e-5,
            keep: 1,
        }
    }
}

impl LibrarySettings {
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
        if let Model::Logistic(s) | Model::Normal(s) = self.model
            && !(s.is_finite() && s > 0.0)
        {
            return bad("sigma", s, "finite and positive");
        }
        if self.horizon == 0 {
            return bad("horizon", 0.0, "at least 1");
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

/// One stored local controller: `u(x) = u + K (x - x)` around the state `x`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    /// The trajectory's initial state `x_1`.
    pub x: Vec<f64>,
    /// Its first control `u_1`.
    pub u: Vec<f64>,
    /// Its first feedback gain `K_1`, row-major `m x n`.
    pub gain: Vec<f64>,
    /// Optimiser passes this trajectory took.
    pub passes: u32,
    /// Whether the optimiser converged (else it stopped at its pass limit or regularisation limit).
    pub converged: bool,
    /// The trajectory's cost.
    pub cost: f64,
}

/// The free joint whose angle the task spins: the last unactuated one.
pub fn free_joint(scene: &Scene) -> Result<usize, LibraryError> {
    (0..scene.n_dof())
        .rev()
        .find(|&j| scene.bodies[j].actuator.is_none())
        .ok_or_else(|| LibraryError::Invalid("the scene has no unactuated joint to spin".into()))
}

/// Build the entries of a library (see the module documentation): the chains' entries one chain after the
/// other, whatever order their threads finish in. `progress` sees each trajectory's first entry as it is
/// made, with the number of trajectories done so far.
pub fn build_entries(
    scene: &Scene,
    settings: &LibrarySettings,
    progress: impl FnMut(usize, &Entry) + Send,
) -> Result<Vec<Entry>, LibraryError> {
    settings.validate(scene)?;
    let (chains, trajectories) = (settings.chains, settings.trajectories);
    if chains == 1 {
        let mut progress = progress;
        return build_chain(scene, settings, settings.seed, trajectories, &mut progress);
    }
    let done = std::sync::Mutex::new((0usize, progress));
    let report = |entry: &Entry| {
        let mut guard = done.lock().unwrap_or_else(|e| e.into_inner());
        let (count, progress) = &mut *guard;
        progress(*count, entry);
        *count += 1;
    };
    let results: Vec<Result<Vec<Entry>, LibraryError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..chains)
            .map(|c| {
                let length = trajectories / chains + usize::from(c < trajectories % chains);
                let seed = settings.seed.wrapping_add(c as u64);
                let report = &report;
                scope.spawn(move || {
                    build_chain(scene, settings, seed, length, &mut |_, e: &Entry| report(e))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    Err(LibraryError::Invalid("a chain's thread panicked".into()))
                })
            })
            .collect()
    });
    let mut entries = Vec::with_capacity(trajectories * settings.keep);
    for chain in results {
        entries.extend(chain?);
    }
    Ok(entries)
}

/// One receding-horizon chain of `trajectories` trajectories with kick seed `seed`.
fn build_chain(
    scene: &Scene,
    settings: &LibrarySettings,
    seed: u64,
    trajectories: usize,
    progress: &mut dyn FnMut(usize, &Entry),
) -> Result<Vec<Entry>, LibraryError> {
    let (n, m) = (scene.n_dof(), scene.n_controls);
    let cost = finger_cost(n, free_joint(scene)?, m);
    let mut dynamics = FingerDynamics::new(settings.simulator(scene)?);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let kick = Normal::new(0.0, settings.kick_variance.sqrt())
        .map_err(|e| LibraryError::Invalid(e.to_string()))?;
    let mut x1 = settings.x0.clone();
    let mut controls = vec![vec![0.0; m]; settings.horizon];
    let mut since_kick = 0usize;
    let mut entries = Vec::with_capacity(trajectories * settings.keep);
    for k in 0..trajectories {
        let span = tracing::info_span!("library.trajectory", k);
        let _guard = span.enter();
        let ddp = Ddp::new(DdpSettings {
            max_iterations: if k == 0 {
                settings.first_passes
            } else {
                settings.warm_passes
            },
            tol_cost: settings.tolerance,
            ..DdpSettings::default()
        })
        .map_err(|source| LibraryError::Optimiser {
            trajectory: k,
            source,
        })?;
        let sol = match ddp.solve(&mut dynamics, &cost, &x1, &controls) {
            Ok(sol) => sol,
            // A perturbed state the warm start cannot even roll out from: start that trajectory from
            // zero controls instead.
            Err(DdpError::InitialRollout { .. }) if k > 0 => ddp
                .solve(
                    &mut dynamics,
                    &cost,
                    &x1,
                    &vec![vec![0.0; m]; settings.horizon],
                )
                .map_err(|source| LibraryError::Optimiser {
                    trajectory: k,
                    source,
                })?,
            Err(source) => {
                return Err(LibraryError::Optimiser {
                    trajectory: k,
                    source,
                });
            }
        };
        for t in 0..settings.keep {
            let entry = Entry {
                x: sol.states[t].clone(),
                u: sol.controls[t].clone(),
                gain: sol.gains[t].clone(),
                passes: sol.iterations.len() as u32,
                converged: sol.status.converged(),
                cost: sol.cost,
            };
            if t == 0 {
                progress(k, &entry);
            }
            entries.push(entry);
        }
        // Receding horizon (eq. 19): the next trajectory starts d steps on, warm-started by the shifted
        // controls; every `kick_every` steps its velocities are perturbed.
        x1 = sol.states[settings.shift].clone();
        controls = ddp::shift_controls(&sol.controls, settings.shift);
        since_kick += settings.shift;
        if since_kick >= settings.kick_every {
            since_kick -= settings.kick_every;
            for v in &mut x1[n..] {
                *v += kick.sample(&mut rng);
            }
        }
    }
    Ok(entries)
}
