//! The one error type of the crate: an ill-posed question (a malformed scene, a non-finite state, a setting
//! out of range), never a step that ran (that reports a status).

/// One problem found in a scene description, naming the field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SceneProblem {
    /// Where: `body[1].joint.limits`, `contact[0].b`, `gravity`, ...
    pub field: String,
    /// What is wrong with it.
    pub problem: String,
}

impl std::fmt::Display for SceneProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.field, self.problem)
    }
}

/// Why a dynamics question could not be posed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DynamicsError {
    /// The scene is invalid; every problem found is listed.
    #[error("invalid scene: {}", .0.iter().map(|p| p.to_string()).collect::<Vec<_>>().join("; "))]
    Scene(Vec<SceneProblem>),
    /// The scene text is not valid TOML for a scene.
    #[error("scene file: {0}")]
    Parse(String),
    /// A state or control had the wrong size or a non-finite entry.
    #[error("{what}: {problem}")]
    Input {
        /// `"x"`, `"u"`.
        what: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// A setting is out of range.
    #[error("setting `{name}` = {value:?} is out of range: {expected}")]
    Setting {
        /// The field.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The admissible range.
        expected: &'static str,
    },
    /// A smoothed model's noise scale beyond the scene's ([`crate::Scene::largest_noise_scale`]).
    #[error(
        "setting `sigma` = {} is out of range for this scene: {}",
        crate::Scale(*sigma), NoiseScaleBound(*largest)
    )]
    NoiseScale {
        /// The noise scale asked for.
        sigma: f64,
        /// The scene's largest.
        largest: f64,
    },
    /// Explicit drag would create energy at this state ([`crate::Drag`]): `h lambda_max(M^-1 D) > 2`.
    #[error(
        "explicit drag is unstable here: h lambda_max(M^-1 D) = {rate:.3e} > 2, mostly joint `{joint}` (its drag is too strong for its inertia at this h): take a time step below {h_max:.3e}, or step with implicit drag (`Drag::Implicit`)"
    )]
    UnstableDrag {
        /// The body whose joint dominates the unstable mode.
        joint: String,
        /// `h lambda_max(M^-1 D)`.
        rate: f64,
        /// The largest stable time step at this state.
        h_max: f64,
    },
    /// A computation would need more memory than its limit: refused before allocating, with the estimate
    /// and what to use instead.
    #[error(
        "{what} would need about {:.1} GB, over its limit of {:.1} GB; use {alternative}",
        *bytes as f64 / 1e9,
        *limit as f64 / 1e9
    )]
    TooLarge {
        /// What would be computed.
        what: &'static str,
        /// The estimate, in bytes.
        bytes: usize,
        /// The limit, in bytes.
        limit: usize,
        /// What to do instead.
        alternative: &'static str,
    },
    /// A capability this model does not have (yet), or a degenerate state it cannot differentiate at.
    #[error("unsupported: {0}")]
    Unsupported(&'static str),
    /// A matrix of the step's linearisation could not be factored.
    #[error("{what} cannot be factored: {cause}")]
    Singular {
        /// Which matrix.
        what: &'static str,
        /// Why (the failing pivot).
        cause: ncp::FactorError,
    },
    /// The contact geometry could not be evaluated.
    #[error(transparent)]
    Geometry(#[from] geometry::GeometryError),
    /// The complementarity problem could not be posed.
    #[error(transparent)]
    Ncp(#[from] ncp::NcpError),
}

/// A scene's noise-scale bound `largest` ([`crate::Scene::largest_noise_scale`]) and why, as every refusal
/// of a noise scale beyond it words it: "at most 8 (10 per second times its largest semi-axis); beyond it
/// ...".
#[derive(Debug, Clone, Copy)]
pub struct NoiseScaleBound(pub f64);

impl std::fmt::Display for NoiseScaleBound {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "at most {} ({} per second times its largest semi-axis); beyond it every constraint pushes \
             at any distance and the smoothed step can create energy",
            crate::Scale(self.0),
            crate::NOISE_SCALE_PER_SIZE
        )
    }
}
