//! One time step `x' = f(x, u)` (paper section III-A, eq. 1; SCENE.md "One time step"): with `M`, `r`, `d`
//! and `J` frozen at the start of the step, solve for the new velocities and the impulses
//!
//! ```text
//! M (v' - v) = h (r + B u) + J^T lambda,   0 <= lambda _|_ d / h + J v' >= 0,   q' = q + h v'
//! ```
//!
//! as a mixed LCP in `z = [v'; lambda]` with the model's NCP function per row (crate `ncp`).

#![allow(non_snake_case)]

use crate::constraint::{Constraints, ContactFrame, ContactImpulse};
use crate::error::DynamicsError;
use crate::kinematics::{Kinematics, Ring};
use crate::scene::ConstraintRow;
use crate::scene::{CoordinateKind, Scene};
use ncp::{
    ErmSettings, ErmSolver, Info, LemkeSettings, LemkeWorkspace, LinearMcp, NcpFunction,
    NewtonSettings, NewtonSolver, lemke_in_place,
};
use serde::{Deserialize, Serialize};

/// How far a converged step may leave a joint past its limit or a contact in penetration, in the scene's
/// units (`d + h J v'` of every row, [`Model::step`]): beyond it the step's status is
/// [`ncp::Status::Violated`], not converged.
pub const STEP_TOLERANCE: f64 = 1e-6;

/// How the complementarity rows are modelled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum Complementarity {
    /// The exact LCP, solved by Lemke's method.
    Hard,
    /// Logistic noise on each row's constraint velocity, paper eq. (17), solved by Newton.
    Logistic {
        /// Noise scale (the paper's default 0.1).
        sigma: f64,
    },
    /// Normal noise, expected-residual minimisation, paper eq. (14) with (15).
    Normal {
        /// Noise standard deviation.
        sigma: f64,
    },
}

/// In user words: `hard contact`, `logistic contact, sigma 0.1`, `normal contact, sigma 0.1` (the noise
/// scale as given, without trailing digits).
impl std::fmt::Display for Complementarity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Complementarity::Hard => write!(f, "hard contact"),
            Complementarity::Logistic { sigma } => {
                write!(f, "logistic contact, sigma {}", Scale(*sigma))
            }
            Complementarity::Normal { sigma } => {
                write!(f, "normal contact, sigma {}", Scale(*sigma))
            }
        }
    }
}

/// A noise scale as a user wrote it (`0.1`), in exponent form when it is too large or too small to read
/// that way (`1e-300`, not three hundred digits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scale(pub f64);

impl std::fmt::Display for Scale {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        if x.is_finite() && x != 0.0 && !(1e-4..1e9).contains(&x.abs()) {
            write!(f, "{x:e}")
        } else {
            write!(f, "{x}")
        }
    }
}

/// How a step integrates the joints' viscous drag `-c_j v_j`.
///
/// Explicit drag (SCENE.md: "drag, like the rest of r, uses the velocity at the start of the step") is
/// stable only while `h lambda_max(M^-1 D) <= 2`, `D = diag(c)`: a light body on a draggy joint (a thin
/// ellipse, whose inertia falls with its minor axis) breaks that at the finger's h, and each step would
/// then multiply its velocity by `|1 - h c / I| > 1`, creating energy from nothing. The step refuses such a
/// state ([`DynamicsError::UnstableDrag`]) instead. Implicit drag uses the velocity at the end of the step
/// (`M` becomes `M + h D` in the step's equations): it only ever removes energy, at any h.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Drag {
    /// At the start of the step (SCENE.md, the default; refused where it would be unstable).
    #[default]
    Explicit,
    /// At the end of the step: unconditionally dissipative.
    Implicit,
}

/// Settings of a step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepSettings {
    /// Complementarity model; the paper's default is logistic with sigma = 0.1 (section V-A).
    pub model: Complementarity,
    /// Time step (SCENE.md: 0.05).
    pub h: f64,
    /// How the joints' drag is integrated (SCENE.md: explicitly).
    #[serde(default)]
    pub drag: Drag,
    /// How much penetration one step pushes out at the velocity level; the rest is removed at the position
    /// level. Each row's constraint velocity is `max(d, -recovery) / h + J v'`, and the positions of the
    /// step are `q + dq + h v'`, with `dq` the smallest move (in the metric of `M`) that takes every
    /// penetration deeper than `recovery` back to that depth ([`Model::position_correction`]).
    ///
    /// `Some(0.0)`, the default: velocities never push out, so contact only ever removes kinetic energy,
    /// and penetration (which a linearised step leaves where a convex body rolls: the rocking ellipse) is
    /// projected out without a velocity, so nothing sinks and nothing is launched. `None`: SCENE.md's
    /// `d / h + J v'`, all of it at the velocity level: a penetration of depth `p` leaves the step with a
    /// separating velocity `p / h`, kinetic energy from nothing (a rocking ellipse rolls for ever).
    #[serde(default = "position_level")]
    pub recovery: Option<f64>,
    /// Newton settings for the logistic model.
    pub newton: NewtonSettings,
    /// ERM settings for the normal model.
    pub erm: ErmSettings,
}

fn position_level() -> Option<f64> {
    Some(0.0)
}

impl Default for StepSettings {
    fn default() -> Self {
        StepSettings {
            model: Complementarity::Logistic { sigma: 0.1 },
            h: 0.05,
            drag: Drag::Explicit,
            recovery: position_level(),
            newton: NewtonSettings::default(),
            erm: ErmSettings::default(),
        }
    }
}

impl StepSettings {
    /// `Err` naming the first setting out of range.
    pub fn validate(&self) -> Result<(), DynamicsError> {
        if !(self.h.is_finite() && self.h > 0.0) {
            return Err(DynamicsError::Setting {
                name: "h",
                value: self.h,
                expected: "finite and positive",
            });
        }
        if let Complementarity::Logistic { sigma } | Complementarity::Normal { sigma } = self.model
            && !(sigma.is_finite() && sigma > 0.0)
        {
            return Err(DynamicsError::Setting {
                name: "sigma",
                value: sigma,
                expected: "finite and positive",
            });
        }
        if let Some(depth) = self.recovery
            && (depth.is_nan() || depth < 0.0)
        {
            return Err(DynamicsError::Setting {
                name: "recovery",
                value: depth,
                expected: "non-negative (infinity or None: all at the velocity level)",
            });
        }
        self.newton.validate()?;
        self.erm.validate()?;
        Ok(())
    }
}

/// The outcome of one step.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// `[q + h v'; v']`.
    pub x_next: Vec<f64>,
    /// Row impulses, in the order of [`Scene::rows`](crate::Scene::rows) (SCENE.md's).
    pub lambda: Vec<f64>,
    /// Constraint values `d(q)` at the start of the step.
    pub d: Vec<f64>,
    /// Contact geometry at the start of the step, one per pair.
    pub contacts: Vec<ContactFrame>,
    /// Each contact pair's impulse over the step (from its two rows of `lambda`).
    pub impulses: Vec<ContactImpulse>,
    /// How the complementarity solve went.
    pub info: Info,
}

impl Step {
    /// The step's total normal contact impulse, over every contact pair (joint limits excluded).
    pub fn normal_impulse(&self) -> f64 {
        self.impulses.iter().map(|i| i.normal).sum()
    }
}

/// The model of a step (as MuJoCo's `mjModel`): the scene, the step's settings and the rows' noise, fixed
/// while it steps. Everything a step writes lives in a [`StepData`] the caller owns ([`Model::create_data`]):
/// one per sequence of steps (a simulation), or one per knot of a trajectory (an optimiser), so no answer
/// depends on a step the caller did not hand in. [`Simulator`](crate::Simulator) pairs a model with one
/// data for the common case of one simulation.
#[derive(Debug)]
pub struct Model {
    scene: Scene,
    settings: StepSettings,
    erm: ErmSolver,
    covariance: Option<StateCovariance>,
}

/// What a step of a [`Model`] reads besides `(x, u)` and what it writes (as MuJoCo's `mjData`): the applied
/// forces (an input, [`StepData::set_forces`]), the solution the next solve starts from, the last step
/// with the `(x, u)` it was computed from (which [`Model::derivatives`] linearises, never solving again),
/// and the solvers' scratch space.
#[derive(Debug)]
pub struct StepData {
    n_dof: usize,
    n_rows: usize,
    /// Where the next solve starts: `[v'; lambda]` of the last step, or set by the caller.
    warm: Option<Vec<f64>>,
    /// Generalised forces added to `r + B u` (one per joint), or empty for none.
    forces: Vec<f64>,
    x: Vec<f64>,
    u: Vec<f64>,
    step: Option<Step>,
    /// The derivatives of `step` once computed ([`Model::calc_diff`], [`Model::calc_diff2_prepare`]:
    /// the first, and what the second keep besides them), refilled in place by the next step's.
    pub(crate) diff: crate::derivative::DerivativeData,
}

/// What a step works in and keeps nothing of from one step to the next: the ingredients it assembles
/// its problem from, the solvers' and the position correction's scratch. One set per thread, refilled by
/// every step (no allocation once it has the scene's sizes), rather than one per data: an optimiser
/// keeps a data per knot, and a trajectory's knots sharing one set keep it in the cache.
#[derive(Default)]
struct StepWork {
    ingredients: StepIngredients,
    solve: SolveScratch,
}

thread_local! {
    static STEP_WORK: std::cell::RefCell<StepWork> = std::cell::RefCell::new(StepWork::default());
}

/// `f` with this thread's solve scratch ([`StepWork`]), for a derivative pass that solves its step.
pub(crate) fn with_solve_scratch<R>(f: impl FnOnce(&mut SolveScratch) -> R) -> R {
    with_step_work(|work| f(&mut work.solve))
}

/// `f` with this thread's [`StepWork`] (a fresh one should `f` step again from inside).
fn with_step_work<R>(f: impl FnOnce(&mut StepWork) -> R) -> R {
    STEP_WORK.with(|work| match work.try_borrow_mut() {
        Ok(mut work) => f(&mut work),
        Err(_) => f(&mut StepWork::default()),
    })
}

/// The ingredients of a step ([`Model::step`]), sized by the first step and refilled by every later one:
/// the kinematics, `M`, `r + B u`, the rows and the buffers of the mixed LCP.
#[derive(Debug, Default)]
struct StepIngredients {
    kin: Option<Kinematics<f64>>,
    M: Vec<f64>,
    r: Vec<f64>,
    forces: crate::kinematics::ForceScratch<f64>,
    cons: Option<Constraints<f64>>,
    /// The last problem's `M` and `q`, given back for the next one.
    lcp: (Vec<f64>, Vec<f64>),
    /// The drag check's Cholesky factor and `W`.
    drag: (Vec<f64>, Vec<f64>),
}

/// The scratch space of a step's solve: the Newton solver (its workspace), Lemke's workspace, the rows'
/// NCP functions, the iterate, the position correction and its matrices.
#[derive(Debug, Default)]
pub(crate) struct SolveScratch {
    newton: Option<NewtonSolver>,
    lemke: LemkeWorkspace,
    functions: Vec<NcpFunction>,
    z: Vec<f64>,
    correction: Vec<f64>,
    correcting: CorrectionScratch<f64>,
}

/// A step a data holds, as its derivatives read it: the point it was computed from, the step and the
/// applied forces.
#[derive(Clone, Copy)]
pub(crate) struct Stored<'a> {
    pub(crate) x: &'a [f64],
    pub(crate) u: &'a [f64],
    pub(crate) step: &'a Step,
    pub(crate) forces: &'a [f64],
}

impl StepData {
    /// The step it holds as its derivatives read it, if any.
    pub(crate) fn stored(&self) -> Option<Stored<'_>> {
        let StepData {
            x, u, step, forces, ..
        } = self;
        step.as_ref().map(|step| Stored { x, u, step, forces })
    }

    /// [`StepData::stored`], and beside it the derivatives it keeps, to be written.
    pub(crate) fn stored_and_derivatives(
        &mut self,
    ) -> (Option<Stored<'_>>, &mut crate::derivative::DerivativeData) {
        let StepData {
            x,
            u,
            step,
            forces,
            diff,
            ..
        } = self;
        (
            step.as_ref().map(|step| Stored { x, u, step, forces }),
            diff,
        )
    }

    /// The last step computed with this data, if any (and it succeeded).
    pub fn step(&self) -> Option<&Step> {
        self.step.as_ref()
    }

    /// The state and controls the last step was computed from (empty before the first).
    pub fn point(&self) -> (&[f64], &[f64]) {
        (&self.x, &self.u)
    }

    /// Hold the generalised forces `forces` (one per joint) over every following step, added to
    /// `r + B u`: a user pulling on a body ([`Kinematics::point_force`]). Their derivatives are zero (they
    /// are an input, like `u`, held fixed).
    pub fn set_forces(&mut self, forces: &[f64]) -> Result<(), DynamicsError> {
        check("forces", forces, self.n_dof)?;
        self.forces.clear();
        self.forces.extend_from_slice(forces);
        Ok(())
    }

    /// Stop applying forces.
    pub fn clear_forces(&mut self) {
        self.forces.clear();
    }

    /// The applied generalised forces (empty: none).
    pub fn forces(&self) -> &[f64] {
        &self.forces
    }

    /// Start the next solve from `z = [v'; lambda]` (for instance the solution of an earlier step at the
    /// same state, which the solve then accepts without iterating).
    pub fn set_warm_start(&mut self, z: &[f64]) -> Result<(), DynamicsError> {
        check("warm start", z, self.n_dof + self.n_rows)?;
        self.warm = Some(z.to_vec());
        Ok(())
    }

    /// Start the next solve from the solution of `other`'s last step (a step of the same model near this
    /// one: the same knot of the trajectory an optimiser improves); nothing if it has none.
    pub fn warm_start_from(&mut self, other: &StepData) {
        if let Some(step) = &other.step
            && other.n_dof == self.n_dof
            && step.lambda.len() == self.n_rows
        {
            let z = self.warm.get_or_insert_with(Vec::new);
            z.clear();
            z.extend_from_slice(&step.x_next[self.n_dof..]);
            z.extend_from_slice(&step.lambda);
        }
    }

    /// Forget the warm start (the next step starts from `[v; 0]`).
    pub fn reset_warm_start(&mut self) {
        self.warm = None;
    }
}

/// A Gaussian state estimate's covariance, from which each row's noise follows (paper eq. 18):
/// `Sigma_b = J (Sigma_q / h^2 + Sigma_v) J^T`, row `i` smoothed with `sigma_i = sqrt((Sigma_b)_ii)`.
#[derive(Debug, Clone, PartialEq)]
pub struct StateCovariance {
    /// `Sigma_q`, row-major `n x n` (positions).
    pub q: Vec<f64>,
    /// `Sigma_v`, row-major `n x n` (velocities).
    pub v: Vec<f64>,
}

/// Per-row noise from eq. (18), floored at `1e-12` of the model's constant sigma (a row the covariance does
/// not reach stays smooth rather than hard). Generic so that the derivatives see `sigma_i(q)` through `J(q)`.
pub(crate) fn row_sigmas<T: Ring>(
    cov: &StateCovariance,
    jacobian: &[T],
    n: usize,
    h: f64,
    sigma: f64,
) -> Vec<T> {
    let m = jacobian.len() / n;
    let floor = 1e-12 * sigma;
    (0..m)
        .map(|k| {
            let row = &jacobian[k * n..(k + 1) * n];
            let mut var = T::from(0.0);
            for i in 0..n {
                for j in 0..n {
                    var += row[i] * row[j] * (cov.q[i * n + j] / (h * h) + cov.v[i * n + j]);
                }
            }
            if var.value() > floor * floor {
                var.square_root()
            } else {
                T::from(floor)
            }
        })
        .collect()
}

impl Model {
    /// The model of `scene` with checked settings. A time step past the scene's rocking limit
    /// ([`Scene::rocking_limit`](crate::Scene::rocking_limit)) is allowed (no body may ever lie flat) but
    /// logged as a warning: a body that does cannot rest.
    pub fn new(scene: Scene, settings: StepSettings) -> Result<Self, DynamicsError> {
        settings.validate()?;
        if let Complementarity::Logistic { sigma } | Complementarity::Normal { sigma } =
            settings.model
        {
            scene.check_noise_scale(sigma)?;
        }
        NewtonSolver::new(settings.newton)?;
        if let Some(limit) = scene.rocking_limit().filter(|&l| settings.h > l) {
            tracing::warn!(
                h = settings.h,
                limit,
                "the time step is past the scene's rocking limit: a free body lying flat on a plane \
                 cannot rest (Scene::rocking_limit)"
            );
        }
        Ok(Model {
            erm: ErmSolver::new(settings.erm)?,
            scene,
            settings,
            covariance: None,
        })
    }

    /// Fresh data for this model's steps: no warm start, no applied forces, no step yet.
    pub fn create_data(&self) -> StepData {
        StepData {
            n_dof: self.scene.n_dof(),
            n_rows: self.scene.n_constraints(),
            warm: None,
            forces: Vec::new(),
            x: Vec::new(),
            u: Vec::new(),
            step: None,
            diff: Default::default(),
        }
    }

    /// `Err` unless `data` was created by a model of this scene's sizes.
    pub(crate) fn check_data(&self, data: &StepData) -> Result<(), DynamicsError> {
        if data.n_dof != self.scene.n_dof() || data.n_rows != self.scene.n_constraints() {
            return Err(DynamicsError::Input {
                what: "step data",
                problem: format!(
                    "was created for {} joints and {} rows; this model has {} and {}",
                    data.n_dof,
                    data.n_rows,
                    self.scene.n_dof(),
                    self.scene.n_constraints()
                ),
            });
        }
        Ok(())
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The settings.
    pub fn settings(&self) -> &StepSettings {
        &self.settings
    }

    /// Smooth each row with the noise a state covariance implies (paper eq. 18) instead of the model's
    /// constant sigma; `None` returns to the constant. Both matrices must be `n x n`, finite, symmetric and
    /// positive semi-definite (checked on the diagonal and by symmetry).
    pub fn set_state_covariance(
        &mut self,
        covariance: Option<StateCovariance>,
    ) -> Result<(), DynamicsError> {
        if let Some(cov) = &covariance {
            let n = self.scene.n_dof();
            for (what, m) in [("covariance q", &cov.q), ("covariance v", &cov.v)] {
                let ok = m.len() == n * n
                    && m.iter().all(|e| e.is_finite())
                    && (0..n).all(|i| m[i * n + i] >= 0.0)
                    && (0..n).all(|i| {
                        (0..n).all(|j| {
                            (m[i * n + j] - m[j * n + i]).abs()
                                <= 1e-12 * (1.0 + m[i * n + j].abs())
                        })
                    });
                if !ok {
                    return Err(DynamicsError::Input {
                        what: "covariance",
                        problem: format!(
                            "{what} must be {n}x{n}, finite, symmetric, with a non-negative diagonal"
                        ),
                    });
                }
            }
        }
        self.covariance = covariance;
        Ok(())
    }

    /// Whether rows take their noise from a state covariance.
    pub fn has_state_covariance(&self) -> bool {
        self.covariance.is_some()
    }

    /// The state covariance rows take their noise from, if any.
    pub fn state_covariance(&self) -> Option<&StateCovariance> {
        self.covariance.as_ref()
    }

    /// The mixed LCP of the step from `x` under `u`, with the start-of-step quantities.
    pub fn problem(&self, x: &[f64], u: &[f64]) -> Result<(LinearMcp, Constraints), DynamicsError> {
        check("x", x, self.scene.n_state())?;
        check("u", u, self.scene.n_controls)?;
        let mut ing = StepIngredients::default();
        let problem = self.ingredients_into(&mut ing, &[], x, u)?;
        let cons = ing.cons.expect("filled by ingredients_into");
        Ok((problem, cons))
    }

    /// A row's distance as the step's constraint velocity sees it: `max(d, -recovery)`
    /// ([`StepSettings::recovery`]).
    pub(crate) fn recovered(&self, d: f64) -> f64 {
        match self.settings.recovery {
            Some(depth) => d.max(-depth),
            None => d,
        }
    }

    /// [`Model::recovered`] on distances in a dual type: a clamped row's distance is the constant
    /// `-recovery`, with no derivatives.
    pub(crate) fn recovered_all<T: Ring>(&self, d: &mut [T]) {
        if let Some(depth) = self.settings.recovery {
            for e in d.iter_mut() {
                if e.value() < -depth {
                    *e = T::from(-depth);
                }
            }
        }
    }

    /// The derivative passes' ingredients as the step sees them, in place: explicit drag checked
    /// ([`Model::check_drag_in`]), implicit drag added to `M` ([`Model::with_drag`]), the rows'
    /// distances limited by the recovery ([`Model::recovered_all`]). Writes the distances as they were,
    /// which the step reports, into `distance` and the position-level correction
    /// ([`Model::position_correction`]) in the same scalar into `correction`, its working vectors in
    /// `scratch` (no allocation once they have the scene's sizes).
    pub(crate) fn prepare_ingredients_into<T: Ring>(
        &self,
        M: &mut [T],
        jacobian: &[T],
        d: &mut [T],
        (distance, correction): (&mut Vec<f64>, &mut Vec<T>),
        scratch: &mut PrepareScratch<T>,
    ) -> Result<(), DynamicsError> {
        self.check_drag_in(M, &mut scratch.drag)?;
        self.with_drag(M);
        distance.clear();
        distance.extend(d.iter().map(Ring::value));
        self.position_correction_into(|e| M[e], jacobian, d, correction, &mut scratch.correcting);
        self.recovered_all(d);
        Ok(())
    }

    /// The position-level part of the recovery ([`StepSettings::recovery`]): the smallest `dq` in the
    /// metric `W` below with `d_c + J_c dq = -recovery` for every constraint `c` deeper than `recovery`
    /// (a contact pair's normal row, the mean of its two friction-cone rows, or a joint limit), to first
    /// order in `dq`; zero when none is. `d` are the rows' true distances. Generic, so that its
    /// derivatives come with the rest of the step's.
    ///
    /// `dq = W^-1 J_P^T mu`, `(J_P W^-1 J_P^T + eps I) mu = -(d_P + recovery)`, with `eps` a `1e-9` part of
    /// the largest diagonal entry: constraints that cannot all be met (a body pressed between two walls
    /// closer than its width) get a bounded least-squares compromise rather than a singular solve.
    ///
    /// `W = M + sum_b (m_b rho_b^2 - I_b) t_b t_b^T` (`M` the step's, implicit drag included; `rho_b` body
    /// `b`'s largest semi-axis; `t_b` the indicator of the angles that turn it,
    /// [`Scene::turning_coordinates`](crate::Scene::turning_coordinates)): the kinetic metric with each
    /// body turning as a ring of radius `rho_b`, so `|dq|_W` weighs how far the bodies' farthest points
    /// move. In `M` itself turning a thin body is cheap (its `I` is small against `m rho^2`), and a
    /// needle's correction turned it by several times its penetration over its length, past flat, so
    /// that its other tip went in as deep: a two-step cycle, the needle partly sunk for ever. In `W` one
    /// correction turns a free body by at most `|d| / (2 rho)`, where the first-order model of `d` still
    /// holds.
    ///
    /// A trust region bounds it: `|dq|_W` is at most [`CORRECTION_TRUST`] times the root of the sum of
    /// `(d_c + recovery)^2 / A_cc` (`A = J_P W^-1 J_P^T`), the squared moves the constraints would ask for
    /// one by one, and a longer `dq` is shortened onto it (the rest is left to the next steps). Nearly
    /// dependent constraints (two thin needles crossing each other on the ground, each through it) make
    /// `A` nearly singular, and the exact first-order answer moved a needle of semi-axis 0.065 by 0.8 and
    /// turned it by 1.8 rad, out of a penetration of 0.035, putting it entirely below the ground.
    pub fn position_correction<T: Ring>(
        &self,
        M: impl Fn(usize) -> T,
        jacobian: &[T],
        d: &[T],
    ) -> Vec<T> {
        let mut dq = Vec::new();
        self.position_correction_into(M, jacobian, d, &mut dq, &mut CorrectionScratch::default());
        dq
    }

    /// [`Model::position_correction`] into `dq`, its working matrices in `scratch` (no allocation once
    /// they have grown to the penetrated constraints' count).
    pub(crate) fn position_correction_into<T: Ring>(
        &self,
        M: impl Fn(usize) -> T,
        jacobian: &[T],
        d: &[T],
        dq: &mut Vec<T>,
        scratch: &mut CorrectionScratch<T>,
    ) {
        let n = self.scene.n_dof();
        let zero = T::from(0.0);
        dq.clear();
        dq.resize(n, zero);
        let depth = match self.settings.recovery {
            Some(r) if r.is_finite() => r,
            _ => return,
        };
        let CorrectionScratch {
            active,
            jp,
            rhs,
            l,
            y,
            a,
        } = scratch;
        // The penetrated constraints: (row, second row of the pair if any).
        active.clear();
        let rows = self.scene.rows();
        let mut k = 0;
        while k < rows.len() {
            let pair = matches!(rows[k], ConstraintRow::FrictionEdge { positive: true, .. });
            if d[k].value() < -depth {
                active.push((k, pair.then_some(k + 1)));
            }
            k += if pair { 2 } else { 1 };
        }
        if active.is_empty() {
            return;
        }
        let p = active.len();
        // J_P (p x n): a pair's normal row is the mean of its two edges.
        jp.clear();
        jp.resize(p * n, zero);
        rhs.clear();
        rhs.resize(p, zero);
        for (a, &(k, other)) in active.iter().enumerate() {
            for j in 0..n {
                jp[a * n + j] = match other {
                    Some(o) => (jacobian[k * n + j] + jacobian[o * n + j]) * 0.5,
                    None => jacobian[k * n + j],
                };
            }
            rhs[a] = -(d[k] + depth);
        }
        // Y = M^-1 J_P^T (n x p, column a at y[a n..]), by Cholesky of M.
        l.clear();
        l.extend((0..n * n).map(M));
        // W = M + sum_b (m_b rho_b^2 - I_b) t_b t_b^T: each body turns as a ring of its largest semi-axis.
        for (b, body) in self.scene.bodies.iter().enumerate() {
            let rho = body.shape.a().max(body.shape.b());
            let extra = T::from(body.mass * rho * rho - body.inertia);
            // The angles that turn body b (Scene::turning_coordinates, read in place).
            let turns = |j: &usize| {
                self.scene.coordinates[*j].kind == CoordinateKind::Angle && self.scene.moves(*j, b)
            };
            for j in (0..n).filter(turns) {
                for k in (0..n).filter(turns) {
                    l[j * n + k] += extra;
                }
            }
        }
        if !cholesky_in_place(l, n) {
            return;
        }
        y.clear();
        y.extend_from_slice(jp);
        for col in y.chunks_exact_mut(n) {
            cholesky_solve(l, n, col);
        }
        // A = J_P Y + eps I, solved by Gaussian elimination without pivoting (A is positive definite).
        a.clear();
        a.resize(p * p, zero);
        for r in 0..p {
            for c in 0..p {
                let mut e = zero;
                for j in 0..n {
                    e += jp[r * n + j] * y[c * n + j];
                }
                a[r * p + c] = e;
            }
        }
        let largest = (0..p).fold(0.0f64, |m, r| m.max(a[r * p + r].value()));
        for r in 0..p {
            a[r * p + r] += T::from(1e-9 * largest + f64::MIN_POSITIVE);
        }
        // The trust region: kappa^2 times the sum of the squared W-norms the constraints would ask for one
        // by one, (d_c + recovery)^2 / A_cc.
        let mut budget = zero;
        for r in 0..p {
            budget += rhs[r] * rhs[r] / a[r * p + r];
        }
        budget = budget * (CORRECTION_TRUST * CORRECTION_TRUST);
        for c in 0..p {
            for r in c + 1..p {
                let f = a[r * p + c] / a[c * p + c];
                for k in c..p {
                    let v = a[c * p + k];
                    a[r * p + k] -= f * v;
                }
                let v = rhs[c];
                rhs[r] -= f * v;
            }
        }
        for r in (0..p).rev() {
            for k in r + 1..p {
                let v = a[r * p + k] * rhs[k];
                rhs[r] -= v;
            }
            rhs[r] = rhs[r] / a[r * p + r];
        }
        for (i, e) in dq.iter_mut().enumerate() {
            for c in 0..p {
                *e += y[c * n + i] * rhs[c];
            }
        }
        // |dq|_W^2 = mu^T J_P dq (W dq = J_P^T mu); past the trust region, dq is shortened onto it.
        let mut norm = zero;
        for (r, &mu) in rhs.iter().enumerate() {
            let mut e = zero;
            for j in 0..n {
                e += jp[r * n + j] * dq[j];
            }
            norm += mu * e;
        }
        if norm.value() > budget.value() {
            let shrink = (budget / norm).square_root();
            for e in dq.iter_mut() {
                *e = *e * shrink;
            }
        }
    }

    /// Implicit drag ([`Drag::Implicit`]): `M + h D` in place of `M` in the step's equations (with `r`
    /// keeping its `-D v`, `(M + h D) v' = M v + h (r + D v) + ...`). Nothing for explicit drag.
    pub(crate) fn with_drag<T: Ring>(&self, M: &mut [T]) {
        if self.settings.drag == Drag::Implicit {
            let n = self.scene.n_dof();
            for (j, c) in self.scene.coordinates.iter().enumerate() {
                M[j * n + j] += T::from(self.settings.h * c.damping);
            }
        }
    }

    /// Explicit drag ([`Drag::Explicit`]) is stable while `h lambda_max(M^-1 D) <= 2`; an error naming the
    /// joint that breaks it otherwise. With `M = L L^T` and `W = L^-1 D^1/2`, `lambda_max(M^-1 D)` is that of
    /// `S = W^T W`, at most its trace `|W|_F^2`: that bound settles the usual case in a few flops, and the
    /// eigenvalue itself is computed only when the bound is above `2 / h`. Its Cholesky factor and `W`
    /// are kept in `scratch` (no allocation once they have the scene's size, unless the bound calls for
    /// the eigenvalue).
    fn check_drag_in<T: Ring>(
        &self,
        M: &[T],
        (l, w): &mut (Vec<f64>, Vec<f64>),
    ) -> Result<(), DynamicsError> {
        let h = self.settings.h;
        let scene = &self.scene;
        if self.settings.drag == Drag::Implicit
            || scene.coordinates.iter().all(|c| c.damping == 0.0)
        {
            return Ok(());
        }
        let n = scene.n_dof();
        // Cholesky in place (lower), then W = L^-1 D^1/2 column by column.
        l.clear();
        l.extend(M.iter().map(Ring::value));
        if !cholesky_in_place(l, n) {
            return Err(DynamicsError::Unsupported(
                "the mass matrix is not positive definite at this state",
            ));
        }
        w.clear();
        w.resize(n * n, 0.0);
        for (c, coordinate) in scene.coordinates.iter().enumerate() {
            let root = coordinate.damping.sqrt();
            if root == 0.0 {
                continue;
            }
            for i in c..n {
                let mut e = if i == c { root } else { 0.0 };
                for k in c..i {
                    e -= l[i * n + k] * w[k * n + c];
                }
                w[i * n + c] = e / l[i * n + i];
            }
        }
        if h * w.iter().map(|e| e * e).sum::<f64>() <= 2.0 {
            return Ok(());
        }
        let w = nalgebra::DMatrix::from_row_slice(n, n, w);
        let s = w.transpose() * w;
        let eigen = s.clone().symmetric_eigen();
        let (k, lambda) = eigen.eigenvalues.iter().copied().enumerate().fold(
            (0, f64::NEG_INFINITY),
            |a, (k, l)| if l > a.1 { (k, l) } else { a },
        );
        if h * lambda <= 2.0 {
            return Ok(());
        }
        let mode = eigen.eigenvectors.column(k);
        let joint = (0..n)
            .max_by(|&a, &b| mode[a].abs().total_cmp(&mode[b].abs()))
            .unwrap_or(0);
        Err(DynamicsError::UnstableDrag {
            joint: scene.bodies[scene.coordinates[joint].body].name.clone(),
            rate: h * lambda,
            h_max: 2.0 / lambda,
        })
    }

    /// The mixed LCP from its ingredients at the start of the step (`r` holding `B u`), in the buffers
    /// `(a, b)` of an earlier problem (no allocation once they have its size).
    pub(crate) fn assemble_into(
        &self,
        v: &[f64],
        M: &[f64],
        r: &[f64],
        cons: &Constraints,
        (mut a, mut b): (Vec<f64>, Vec<f64>),
    ) -> Result<LinearMcp, DynamicsError> {
        let n = self.scene.n_dof();
        let m = cons.d.len();
        let h = self.settings.h;
        let dim = n + m;
        a.clear();
        a.resize(dim * dim, 0.0);
        b.clear();
        b.resize(dim, 0.0);
        for i in 0..n {
            for j in 0..n {
                a[i * dim + j] = M[i * n + j];
            }
            for k in 0..m {
                a[i * dim + n + k] = -cons.jacobian[k * n + i];
            }
            b[i] = -((0..n).map(|j| M[i * n + j] * v[j]).sum::<f64>() + h * r[i]);
        }
        for k in 0..m {
            for j in 0..n {
                a[(n + k) * dim + j] = cons.jacobian[k * n + j];
            }
            b[n + k] = self.recovered(cons.d[k]) / h;
        }
        Ok(LinearMcp::from_row_major(n, a, b)?)
    }

    /// How far the answer `z` of the step's problem leaves a row's constraint broken at the end of the step:
    /// `max_k -h w_k`, the linearised distance (or joint-limit margin) after the step, for the models
    /// whose rows are never negative at an exact answer (hard and logistic; the normal model's expected
    /// residual lets `w` go below zero by about its noise, so it is not judged).
    fn violation(&self, problem: &LinearMcp, z: &[f64]) -> f64 {
        if matches!(self.settings.model, Complementarity::Normal { .. }) {
            return 0.0;
        }
        // Only the complementarity rows of `M z + q`, read in place.
        let (n, dim) = (self.scene.n_dof(), z.len());
        let (a, q) = (problem.m_row_major(), problem.q());
        (n..dim).fold(0.0f64, |v, k| {
            let row = &a[k * dim..(k + 1) * dim];
            let wk = q[k] + row.iter().zip(z).map(|(x, y)| x * y).sum::<f64>();
            v.max(-self.settings.h * wk)
        })
    }

    /// One step from `x` under the controls `u`, with `data`'s applied forces, started from its warm
    /// start; the step is kept in `data` (for [`Model::derivatives`], and its solution as the next warm
    /// start) and returned. Its ingredients and scratch space live in `data` too: after the first steps,
    /// a logistic or hard step allocates nothing (tests/alloc; the normal model's ERM solve does).
    #[tracing::instrument(name = "dynamics.step", level = "debug", skip_all)]
    pub fn step<'d>(
        &self,
        data: &'d mut StepData,
        x: &[f64],
        u: &[f64],
    ) -> Result<&'d Step, DynamicsError> {
        self.check_data(data)?;
        let scene = &self.scene;
        check("x", x, scene.n_state())?;
        check("u", u, scene.n_controls)?;
        with_step_work(|work| {
            let StepWork { ingredients, solve } = work;
            self.ingredients_into(ingredients, &data.forces, x, u)
                .and_then(|problem| {
                    let cons = ingredients
                        .cons
                        .as_ref()
                        .expect("filled by ingredients_into");
                    self.solve_into(data, solve, (x, u), problem, cons)
                })
                .map(|problem| ingredients.lcp = problem.into_row_major())
        })?;
        Ok(data.step.as_ref().expect("stored by solve_into"))
    }

    /// The step's ingredients at `x` under `u` and the applied `forces` (empty: none) refilled in `ing`,
    /// and its mixed LCP assembled in `ing`'s buffers ([`Model::problem`] without allocating). `x` and
    /// `u` were checked.
    fn ingredients_into(
        &self,
        ing: &mut StepIngredients,
        forces: &[f64],
        x: &[f64],
        u: &[f64],
    ) -> Result<LinearMcp, DynamicsError> {
        let scene = &self.scene;
        let (q, v) = x.split_at(scene.n_dof());
        let kin = Kinematics::refresh(&mut ing.kin, scene, q);
        kin.mass_matrix_into(scene, &mut ing.M);
        self.check_drag_in(&ing.M, &mut ing.drag)?;
        self.with_drag(&mut ing.M);
        kin.applied_forces_into(scene, v, u, &mut ing.r, &mut ing.forces);
        for (r, f) in ing.r.iter_mut().zip(forces) {
            *r += f;
        }
        let cons = Constraints::refresh(&mut ing.cons, scene, kin, q)?;
        self.assemble_into(v, &ing.M, &ing.r, cons, std::mem::take(&mut ing.lcp))
    }

    /// Solve the step's mixed LCP from `data`'s warm start and keep the step, its point and its solution
    /// in `data` (refilling the vectors of the step it held); returns the problem (whose matrix the
    /// derivatives reuse). `x` and `u` were checked.
    pub(crate) fn solve_into(
        &self,
        data: &mut StepData,
        scratch: &mut SolveScratch,
        (x, u): (&[f64], &[f64]),
        problem: LinearMcp,
        cons: &Constraints,
    ) -> Result<LinearMcp, DynamicsError> {
        let n = self.scene.n_dof();
        let m = cons.d.len();
        let mut holder = data.step.take();
        data.diff.forget();
        if scratch.correcting.is_unsized() {
            scratch.correcting = CorrectionScratch::for_size(n, self.scene.n_constraints());
        }
        let z = &mut scratch.z;
        z.clear();
        match &data.warm {
            Some(w) if w.len() == n + m => z.extend_from_slice(w),
            _ => {
                z.extend_from_slice(&x[n..]);
                z.resize(n + m, 0.0);
            }
        }
        let sigmas = |sigma: f64| -> Vec<f64> {
            match &self.covariance {
                None => vec![sigma; m],
                Some(cov) => row_sigmas(cov, &cons.jacobian, n, self.settings.h, sigma),
            }
        };
        let info = match self.settings.model {
            Complementarity::Hard => {
                match lemke_in_place(&problem, &LemkeSettings::default(), &mut scratch.lemke, z) {
                    Err(ncp::NcpError::Infeasible { .. } | ncp::NcpError::InfeasibleRow { .. }) => {
                        nearest_compliant(&problem, n, &mut scratch.lemke, z)?
                    }
                    other => other?,
                }
            }
            Complementarity::Logistic { sigma } => {
                let functions = &mut scratch.functions;
                functions.clear();
                match &self.covariance {
                    None => functions.resize(m, NcpFunction::Logistic { sigma }),
                    Some(_) => functions.extend(
                        sigmas(sigma)
                            .into_iter()
                            .map(|sigma| NcpFunction::Logistic { sigma }),
                    ),
                }
                // The model's settings rule, whichever model stepped on this thread before.
                let newton = match &mut scratch.newton {
                    Some(newton) if newton.settings() == &self.settings.newton => newton,
                    slot => slot.insert(NewtonSolver::new(self.settings.newton)?),
                };
                newton.solve_in_place(&problem, functions, z)?
            }
            Complementarity::Normal { sigma } => {
                let s = self.erm.solve(&problem, &sigmas(sigma), z)?;
                z.copy_from_slice(&s.z);
                s.info
            }
        };
        let h = self.settings.h;
        let mut info = info;
        if info.status == ncp::Status::Converged && self.violation(&problem, z) > STEP_TOLERANCE {
            info.status = ncp::Status::Violated;
        }
        // M is the problem's leading block (implicit drag included), read in place.
        let (dim, a) = (n + m, problem.m_row_major());
        let correction = &mut scratch.correction;
        self.position_correction_into(
            |e| a[(e / n) * dim + e % n],
            &cons.jacobian,
            &cons.d,
            correction,
            &mut scratch.correcting,
        );
        let step = holder.get_or_insert_with(|| Step {
            x_next: Vec::new(),
            lambda: Vec::new(),
            d: Vec::new(),
            contacts: Vec::new(),
            impulses: Vec::new(),
            info,
        });
        step.x_next.clear();
        step.x_next
            .extend((0..n).map(|i| x[i] + correction[i] + h * z[i]));
        step.x_next.extend_from_slice(&z[..n]);
        step.lambda.clear();
        step.lambda.extend_from_slice(&z[n..]);
        step.d.clear();
        step.d.extend_from_slice(&cons.d);
        step.contacts.clear();
        step.contacts.extend_from_slice(&cons.contacts);
        ContactImpulse::of_into(
            &self.scene,
            &step.lambda,
            &cons.contacts,
            &mut step.impulses,
        );
        step.info = info;
        match &mut data.warm {
            Some(w) => std::mem::swap(w, z),
            None => data.warm = Some(z.clone()),
        }
        data.x.clear();
        data.x.extend_from_slice(x);
        data.u.clear();
        data.u.extend_from_slice(u);
        data.step = holder;
        Ok(problem)
    }
}

/// The working vectors of [`Model::prepare_ingredients_into`]: the drag check's and the position
/// correction's.
#[derive(Debug)]
pub(crate) struct PrepareScratch<T> {
    drag: (Vec<f64>, Vec<f64>),
    correcting: CorrectionScratch<T>,
}

impl<T> PrepareScratch<T> {
    /// [`CorrectionScratch::for_size`].
    pub(crate) fn for_size(n: usize, m: usize) -> Self {
        PrepareScratch {
            drag: (Vec::new(), Vec::new()),
            correcting: CorrectionScratch::for_size(n, m),
        }
    }
}

impl<T> Default for PrepareScratch<T> {
    fn default() -> Self {
        PrepareScratch {
            drag: (Vec::new(), Vec::new()),
            correcting: CorrectionScratch::default(),
        }
    }
}

/// The working matrices of [`Model::position_correction_into`]: the penetrated constraints, `J_P`, the
/// right-hand side, the Cholesky factor of `W`, `W^-1 J_P^T` and `A`.
#[derive(Debug)]
pub(crate) struct CorrectionScratch<T> {
    active: Vec<(usize, Option<usize>)>,
    jp: Vec<T>,
    rhs: Vec<T>,
    l: Vec<T>,
    y: Vec<T>,
    a: Vec<T>,
}

impl<T> CorrectionScratch<T> {
    /// Whether it has never been sized.
    fn is_unsized(&self) -> bool {
        self.active.capacity() == 0
    }

    /// Room for every constraint of a scene of `n` coordinates and `m` rows at once, so that no step
    /// allocates when its deepest penetration so far comes (a knot of an optimiser first touching).
    pub(crate) fn for_size(n: usize, m: usize) -> Self {
        CorrectionScratch {
            active: Vec::with_capacity(m),
            jp: Vec::with_capacity(m * n),
            rhs: Vec::with_capacity(m),
            l: Vec::with_capacity(n * n),
            y: Vec::with_capacity(m * n),
            a: Vec::with_capacity(m * m),
        }
    }
}

impl<T> Default for CorrectionScratch<T> {
    fn default() -> Self {
        CorrectionScratch {
            active: Vec::new(),
            jp: Vec::new(),
            rhs: Vec::new(),
            l: Vec::new(),
            y: Vec::new(),
            a: Vec::new(),
        }
    }
}

/// How far, in the metric of [`Model::position_correction`], one step's correction may move the bodies:
/// this many times the root of the sum of the squared moves its constraints would ask for one by one. A
/// stack of `k` equal free bodies, each sunk by the same depth into the one below, asks for
/// `sqrt(k (2k + 1) / 3)` times that (the top body moves `k` depths), so stacks up to four deep are
/// corrected in one step.
pub const CORRECTION_TRUST: f64 = 4.0;

/// Solve `L L^T x = b` in place of `b`, with `L` the lower factor [`cholesky_in_place`] left in `l`.
fn cholesky_solve<T: Ring>(l: &[T], n: usize, b: &mut [T]) {
    for i in 0..n {
        let mut e = b[i];
        for k in 0..i {
            e -= l[i * n + k] * b[k];
        }
        b[i] = e / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut e = b[i];
        for k in i + 1..n {
            e -= l[k * n + i] * b[k];
        }
        b[i] = e / l[i * n + i];
    }
}

/// The lower Cholesky factor of the row-major `n x n` matrix `l`, in place (the upper triangle is left as
/// it was); `false` if a pivot is not positive (or NaN).
fn cholesky_in_place<T: Ring>(l: &mut [T], n: usize) -> bool {
    for j in 0..n {
        let mut diag = l[j * n + j];
        for k in 0..j {
            diag -= l[j * n + k] * l[j * n + k];
        }
        let pivot = diag.value();
        if pivot.is_nan() || pivot <= 0.0 {
            return false;
        }
        let diag = diag.square_root();
        l[j * n + j] = diag;
        for i in j + 1..n {
            let mut e = l[i * n + j];
            for k in 0..j {
                e -= l[i * n + k] * l[j * n + k];
            }
            l[i * n + j] = e / diag;
        }
    }
    true
}

pub(crate) fn check(what: &'static str, v: &[f64], len: usize) -> Result<(), DynamicsError> {
    if v.len() != len {
        return Err(DynamicsError::Input {
            what,
            problem: format!("has {} entries, expected {len}", v.len()),
        });
    }
    if let Some(i) = v.iter().position(|e| !e.is_finite()) {
        return Err(DynamicsError::Input {
            what,
            problem: format!("entry {i} is {}", v[i]),
        });
    }
    Ok(())
}

/// The hard step's LCP when it has no solution (the two-row friction model's matrix is not copositive in
/// some jammed configurations, Painlevé's paradox: a finger pressing a block into the ground it slides
/// on): the solution of the nearest compliant problem instead, `eps` added to every contact row's
/// diagonal (a spring of compliance `eps` in each row), `eps` rising tenfold from `1e-10` of the
/// problem's scale until Lemke's method solves it; a diagonal that large makes the matrix diagonally
/// dominant, which always has a solution. Reported as [`ncp::Status::Inaccurate`]: it is not a
/// solution of the hard problem, which has none.
fn nearest_compliant(
    problem: &LinearMcp,
    n: usize,
    lemke: &mut LemkeWorkspace,
    z: &mut [f64],
) -> Result<ncp::Info, DynamicsError> {
    let dim = problem.q().len();
    let scale = problem.scale();
    let mut last = ncp::NcpError::Infeasible { pivots: 0 };
    // One copy of the problem, its contact diagonal set in place to the hard one's plus each `eps`.
    let m = problem.m_row_major();
    let (mut a, mut q) = (m.to_vec(), problem.q().to_vec());
    for k in -10..=3 {
        let eps = scale * 10f64.powi(k);
        for i in n..dim {
            a[i * dim + i] = m[i * dim + i] + eps;
        }
        let compliant = LinearMcp::from_row_major(n, a, q)?;
        z.iter_mut().skip(n).for_each(|v| *v = 0.0);
        match lemke_in_place(&compliant, &LemkeSettings::default(), lemke, z) {
            Ok(mut info) => {
                info.status = ncp::Status::Inaccurate;
                return Ok(info);
            }
            Err(e) => last = e,
        }
        (a, q) = compliant.into_row_major();
    }
    Err(last.into())
}
