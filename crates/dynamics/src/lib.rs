//! The time-stepping simulator of the paper (section III-A and IV): planar scenes of rigid ellipses on
//! hinge, slider and free joints with ground, walls and fixed ellipses (docs/scenes.md), hard and
//! stochastically smoothed contact with relaxed Coulomb friction (SCENE.md).
//!
//! - [`Scene`]: checked, immutable scene data, from a TOML file ([`Scene::from_toml_str`],
//!   such as `scenes/finger.toml`, SCENE.md's flicking finger).
//! - [`Kinematics`]: positions, point Jacobians, `M(q)`, `r(q, v)`.
//! - [`Constraints`]: `d(q)` and `J(q)` in the order of [`Scene::rows`] (SCENE.md's), each row typed by [`ConstraintRow`]; a [`Step`] gives each pair's [`ContactImpulse`].
//! - [`Model`] (the scene, its settings, the rows' noise; fixed while it steps) and [`StepData`] (what a
//!   step reads and writes: applied forces, warm start, the step and its point, solver scratch), as
//!   MuJoCo's model and data: [`Model::step`] fills a data, [`Model::derivatives`] and
//!   [`Model::second_order`] linearise the step it holds (exact `fx`, `fu` by the implicit function
//!   theorem, and the Hessians of `c^T f`), never solving it again.
//! - [`Simulator`]: a model with one data, for one simulation; [`Simulator::step`] for the models
//!   [`Complementarity::Hard`], `Logistic` (eq. 17) and `Normal` (eq. 14 with 15).
//!
//! ```
//! use dynamics::{Scene, Simulator, StepSettings};
//! let finger = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/finger.toml"));
//! let mut sim = Simulator::new(Scene::from_toml_str(finger)?, StepSettings::default())?;
//! // The finger apart, at rest: [theta1, theta2, theta3, their velocities].
//! let x0 = [-std::f64::consts::FRAC_PI_4, -std::f64::consts::FRAC_PI_6, 0.0, 0.0, 0.0, 0.0];
//! let step = sim.step(&x0, &[0.0, 0.0])?;
//! // Apart and at rest, the free ellipse feels (next to) nothing; gravity turns the finger clockwise.
//! assert!(step.x_next[5].abs() < 1e-12);
//! assert!(step.x_next[3] < 0.0);
//! # Ok::<(), dynamics::DynamicsError>(())
//! ```

// Dense kernels index several arrays with one counter.
#![allow(clippy::needless_range_loop)]

mod constraint;
mod derivative;
mod error;
mod jet;
mod kinematics;
mod scene;
mod simulator;
mod step;

pub use constraint::{Constraints, ContactFrame, ContactImpulse};
pub use derivative::{
    SECOND_ORDER_MAX_BYTES, SecondOrderStep, StepDerivatives, step_residual, step_residual_at,
};
pub use error::{DynamicsError, NoiseScaleBound, SceneProblem};
pub use jet::{Jet, Jet1};
pub use kinematics::{ForceScratch, Kinematics, Ring, Scalar};
pub use scene::{
    Body, BodySpec, ConstraintRow, ContactPair, ContactSpec, Coordinate, CoordinateKind,
    DENSITY_RANGE, Fixed, FixedSpec, JointKind, JointSpec, MAX_BODIES, MAX_CONTACTS, MAX_DAMPING,
    MAX_FRICTION, MAX_GRAVITY, MAX_LENGTH, MAX_SCENE_TEXT, NOISE_SCALE_PER_SIZE, Overlap, Plane,
    PlaneSpec, Scene, SceneSpec, Side, Tree,
};
pub use simulator::Simulator;
pub use step::{
    CORRECTION_TRUST, Complementarity, Drag, Model, STEP_TOLERANCE, Scale, StateCovariance, Step,
    StepData, StepSettings,
};

/// The README's examples, compiled and run as doctests so that they cannot go stale.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
