//! The WebSocket protocol, JSON text messages both ways.
//!
//! The server sends `{"type":"hello",...}` once (the scene's bodies, half-planes and fixed ellipses, the
//! world window to show, the state entry the page follows, and the options), then a `frame` after
//! every simulated step (at most one per step; a slow client skips frames rather than falling behind),
//! and `error` in reply to a message it refused. The page sends:
//!
//! | message | effect |
//! |---|---|
//! | `{"type":"grab","body":i,"point":[x,y]}` | start pulling body `i` at the world point `[x, y]` (its material point there) |
//! | `{"type":"drag","target":[x,y]}` | move the cursor end of the spring |
//! | `{"type":"release"}` | let go |
//! | `{"type":"policy","policy":"library"\|"mpc"\|"off"}` | who chooses the torques |
//! | `{"type":"world","world":"smoothed"\|"hard"}` | the contact model the world runs on |
//! | `{"type":"sigma","sigma":s}` | the smoothed world's and the online optimiser's noise scale |
//! | `{"type":"speed","speed":r}` | simulated seconds per real second (0.05 to 10) |
//! | `{"type":"pause","paused":bool}` | stop or resume time |
//! | `{"type":"reset"}` | back to the scene's initial state |
//! | `{"type":"kick","std":s}` | add normal noise of standard deviation `s` to every velocity |

use serde::{Deserialize, Serialize};

/// Who chooses the torques.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PolicyKind {
    /// The library's nearest-neighbour policy (paper eq. 20).
    Library,
    /// iLQG re-solved every control step from the shifted previous plan.
    Mpc,
    /// No torques.
    Off,
}

/// The contact model the world runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WorldKind {
    /// Logistic smoothing (eq. 17) at the current sigma.
    Smoothed,
    /// Hard contact (the exact LCP).
    Hard,
}

/// A message from the page.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    /// Start pulling `body` at the world point `point`.
    Grab {
        /// Body index (scene order).
        body: usize,
        /// World coordinates of the grabbed point.
        point: [f64; 2],
    },
    /// Move the cursor end of the spring.
    Drag {
        /// World coordinates.
        target: [f64; 2],
    },
    /// Let go.
    Release,
    /// Choose the policy.
    Policy {
        /// Which.
        policy: PolicyKind,
    },
    /// Choose the world's contact model.
    World {
        /// Which.
        world: WorldKind,
    },
    /// Set sigma.
    Sigma {
        /// Noise scale, positive.
        sigma: f64,
    },
    /// Set the speed.
    Speed {
        /// Simulated seconds per real second.
        speed: f64,
    },
    /// Pause or resume.
    Pause {
        /// Whether time stands still.
        paused: bool,
    },
    /// Back to the initial state.
    Reset,
    /// Random velocity kick.
    Kick {
        /// Standard deviation of each velocity's kick.
        std: f64,
    },
}

impl ClientMessage {
    /// Parse one text message.
    pub fn parse(text: &str) -> Result<Self, crate::ViewerError> {
        let message: Self =
            serde_json::from_str(text).map_err(|e| crate::ViewerError::Message(e.to_string()))?;
        // serde's internally tagged unit variants ignore other fields; a message that carries any is
        // refused like every other message with a field it does not have.
        if matches!(message, ClientMessage::Release | ClientMessage::Reset)
            && let Ok(serde_json::Value::Object(fields)) = serde_json::from_str(text)
            && let Some(extra) = fields.keys().find(|k| k.as_str() != "type")
        {
            return Err(crate::ViewerError::Message(format!(
                "unknown field `{extra}`: this message takes only `type`"
            )));
        }
        Ok(message)
    }
}

/// One body's pose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BodyPose {
    /// Centre of the ellipse.
    pub centre: [f64; 2],
    /// Angle of the body's x axis (the ellipse's first semi-axis).
    pub angle: f64,
    /// Hinge position.
    pub hinge: [f64; 2],
}

/// One contact pair's state over the last step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ContactView {
    /// Witness point on body B (where the impulse is drawn).
    pub point: [f64; 2],
    /// Unit normal from A to B.
    pub normal: [f64; 2],
    /// Signed distance at the start of the step.
    pub distance: f64,
    /// Impulse on B, world coordinates.
    pub impulse: [f64; 2],
}

/// The spring of a drag, for drawing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpringView {
    /// The grabbed body.
    pub body: usize,
    /// The grabbed material point, world coordinates.
    pub from: [f64; 2],
    /// The cursor.
    pub to: [f64; 2],
}

/// The state after a step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    /// Simulated time, s.
    pub t: f64,
    /// Step count since the last reset.
    pub step: u64,
    /// The state `[q; v]`.
    pub x: Vec<f64>,
    /// The torques applied over the last step.
    pub u: Vec<f64>,
    /// Every body's pose.
    pub bodies: Vec<BodyPose>,
    /// Every contact pair.
    pub contacts: Vec<ContactView>,
    /// The spring, while a body is held.
    pub spring: Option<SpringView>,
    /// Rate of the watched entry ([`WatchedView`]; the finger: its free body's spin) over the last 2 s,
    /// per second.
    pub spin_rate: f64,
    /// The watched entry's value.
    pub watched: f64,
    /// Current policy.
    pub policy: PolicyKind,
    /// Current world.
    pub world: WorldKind,
    /// Current sigma.
    pub sigma: f64,
    /// Current speed.
    pub speed: f64,
    /// Whether paused.
    pub paused: bool,
    /// Time the controller took for the last control step, ms (the online optimiser's whole re-solve).
    pub control_ms: f64,
    /// The largest control-step time over the last 2 s, ms.
    pub control_ms_max: f64,
    /// Velocity kicks and drags applied since the last reset.
    pub perturbations: u64,
    /// Steps whose complementarity solve did not converge since the last reset.
    pub unconverged: u64,
    /// Why the last step ran without its controller, if it did.
    pub warning: Option<String>,
    /// Times the online optimiser's stalled plan was re-seeded from the library's policy.
    pub mpc_reseeds: u64,
    /// Passes the online optimiser has run since it last started (0 while it is off).
    pub mpc_passes: u64,
}

/// One body's shape, sent once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BodyShape {
    /// Name.
    pub name: String,
    /// Semi-axes `[a, b]`.
    pub semi_axes: [f64; 2],
    /// Whether a joint torque drives it.
    pub actuated: bool,
}

/// A half-plane of the world (ground, wall), sent once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlaneShape {
    /// Name.
    pub name: String,
    /// A point of its boundary line.
    pub point: [f64; 2],
    /// Its unit outward normal (the solid lies behind it).
    pub normal: [f64; 2],
}

/// An ellipse fixed in the world, sent once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FixedShape {
    /// Name.
    pub name: String,
    /// Semi-axes `[a, b]`.
    pub semi_axes: [f64; 2],
    /// Centre.
    pub centre: [f64; 2],
    /// Angle of its first semi-axis.
    pub angle: f64,
}

/// A body where the task wants it, sent once and drawn as a faint outline: the task's initial pose with
/// every position its cost pulls to a target (a quadratic term on a joint coordinate, the final term's
/// target where both name one) set to that target. Only the bodies those coordinates move are sent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TargetPose {
    /// The body's index (as in `bodies`).
    pub body: usize,
    /// Centre.
    pub centre: [f64; 2],
    /// Angle of its first semi-axis.
    pub angle: f64,
}

/// The state entry the page follows: the task's progress coordinate, whose rate the frames carry, or
/// the first position a task without progress pulls to a target.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WatchedView {
    /// Its name (`ellipse.angle`, `block.x`).
    pub name: String,
    /// Its index in the state.
    pub index: usize,
    /// Its target, if the task has one.
    pub target: Option<f64>,
    /// Its unit: `rad` for an angle, `units` (the scene's length unit) for a slide.
    pub unit: String,
}

/// A message from the server.
// The hello is sent once per connection, the frames (boxed) at every step: its size costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    /// Sent once on connection.
    Hello {
        /// The bodies' shapes.
        bodies: Vec<BodyShape>,
        /// The time step, s.
        h: f64,
        /// Whether a library is loaded (else the library policy is unavailable).
        library: bool,
        /// Its number of controllers.
        controllers: usize,
        /// What runs (`flicking finger`, `task NAME`).
        title: String,
        /// The world's half-planes.
        planes: Vec<PlaneShape>,
        /// The world's fixed ellipses.
        fixed: Vec<FixedShape>,
        /// The world window to show, `[x_min, x_max, y_min, y_max]`.
        window: [f64; 4],
        /// The state entry the frames follow.
        watched: WatchedView,
        /// The bodies where the task wants them (empty for a task with no position target).
        targets: Vec<TargetPose>,
    },
    /// The state after a step.
    Frame(Box<Frame>),
    /// A refused message.
    Error {
        /// Why.
        message: String,
    },
}
