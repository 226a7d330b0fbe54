//! Scenes: planar rigid ellipses on hinge, slider or free joints (to the world or to a parent body), with
//! joint limits, viscous joint drag, gravity, actuated joints, static world geometry (half-planes and
//! fixed ellipses) and an explicit list of contact pairs (SCENE.md, docs/scenes.md).
//!
//! A scene is data: [`SceneSpec`] is what a TOML file holds (`scenes/finger.toml`), [`Scene::new`] checks it
//! and reports every problem with the field it is in; SCENE.md's flicking finger is `scenes/finger.toml` like
//! any other scene.
//!
//! Frames: every body has a joint frame, rotated by its absolute angle `phi` (the sum of its own and its
//! ancestors' turning coordinates), with its origin at its anchor (a hinge's pivot) moved by its sliding
//! coordinates. A body's `anchor` is given in its parent's joint frame (the world frame for a root body) and
//! its `centre` in its own joint frame; the ellipse's x axis is the joint frame's x axis.

use crate::error::{DynamicsError, SceneProblem};
use geometry::Ellipse;
use serde::{Deserialize, Serialize};

/// How a body moves relative to its parent's joint frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointKind {
    /// Turns about its anchor: one coordinate, `<body>.angle`.
    #[default]
    Hinge,
    /// Slides along `axis` (in the parent's joint frame) from its anchor, without turning: one
    /// coordinate, `<body>.position`.
    Slider,
    /// Moves freely in the plane: `<body>.x` and `<body>.y` (its frame's origin from the anchor, along the
    /// parent frame's axes), then `<body>.angle` (about that origin).
    Free,
    /// Welded to its parent (a body, not the world): no coordinate; the body is one more ellipse of its
    /// parent's rigid body (its frame is the parent's, moved to the anchor), for compound shapes such as a
    /// fork.
    Weld,
}

/// A body's joint to its parent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// The kind (default a hinge).
    #[serde(default, rename = "type", skip_serializing_if = "is_hinge")]
    pub kind: JointKind,
    /// A slider's direction in the parent's joint frame (any non-zero length); only for sliders.
    #[serde(
        default,
        deserialize_with = "strict_pair_option",
        skip_serializing_if = "Option::is_none"
    )]
    pub axis: Option<[f64; 2]>,
    /// `[lower, upper]` on the joint's coordinate (two unilateral constraints), or none; not for a free
    /// joint.
    #[serde(default, deserialize_with = "strict_pair_option")]
    pub limits: Option<[f64; 2]>,
    /// Viscous drag coefficient: each of the joint's coordinates feels `-damping * its velocity`.
    #[serde(default)]
    pub damping: f64,
    /// Whether controls act on this joint: one per coordinate (a free joint's force along x, along y,
    /// then its torque), numbered in body order.
    #[serde(default)]
    pub actuated: bool,
}

fn is_hinge(kind: &JointKind) -> bool {
    *kind == JointKind::Hinge
}

/// What a generalised coordinate does to its body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CoordinateKind {
    /// Turns the body (and its descendants) about its frame's origin.
    Angle,
    /// Moves the body's frame along this unit axis of the parent's joint frame.
    Slide {
        /// The unit axis.
        axis: [f64; 2],
    },
}

/// A checked generalised coordinate: whose it is, what it does, its limits, drag and control.
#[derive(Debug, Clone, PartialEq)]
pub struct Coordinate {
    /// The body whose joint it belongs to.
    pub body: usize,
    /// What it does.
    pub kind: CoordinateKind,
    /// Limits, if any.
    pub limits: Option<[f64; 2]>,
    /// Viscous drag.
    pub damping: f64,
    /// Index of the control acting on it.
    pub actuator: Option<usize>,
}

/// One body as a scene file describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    /// Unique name.
    pub name: String,
    /// Ellipse semi-axes `[a, b]` along the body's x and y axes.
    #[serde(deserialize_with = "strict_pair")]
    pub semi_axes: [f64; 2],
    /// Mass density (per unit area); mass `pi a b density`, inertia `mass (a^2 + b^2) / 4` (SCENE.md).
    #[serde(default = "one")]
    pub density: f64,
    /// `"world"` or the name of an earlier body.
    pub parent: String,
    /// Hinge position in the parent's joint frame.
    #[serde(deserialize_with = "strict_pair")]
    pub anchor: [f64; 2],
    /// Centre of the ellipse in the body's own joint frame.
    #[serde(deserialize_with = "strict_pair")]
    pub centre: [f64; 2],
    /// The hinge joint to the parent.
    pub joint: JointSpec,
}

fn one() -> f64 {
    1.0
}

/// A modelled contact pair (SCENE.md: the scene models only the pairs it lists).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSpec {
    /// Body A (the normal points from A to B).
    pub a: String,
    /// Body B.
    pub b: String,
    /// Friction coefficient of the relaxed polyhedral cone.
    pub friction: f64,
}

/// A half-plane of the world (ground, a wall): everything on the far side of the line through `point`,
/// `normal` pointing out of it into the free side.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaneSpec {
    /// Unique name (among bodies, planes and fixed ellipses), which contact pairs use.
    pub name: String,
    /// A point of the boundary line, in the world frame.
    #[serde(deserialize_with = "strict_pair")]
    pub point: [f64; 2],
    /// The outward normal (any length above zero).
    #[serde(deserialize_with = "strict_pair")]
    pub normal: [f64; 2],
}

/// An ellipse fixed in the world (a peg, an obstacle): no joint, no coordinate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixedSpec {
    /// Unique name (among bodies, planes and fixed ellipses), which contact pairs use.
    pub name: String,
    /// Semi-axes `[a, b]`.
    #[serde(deserialize_with = "strict_pair")]
    pub semi_axes: [f64; 2],
    /// Centre in the world frame.
    #[serde(deserialize_with = "strict_pair")]
    pub centre: [f64; 2],
    /// Angle of the ellipse's x axis from the world's.
    #[serde(default)]
    pub angle: f64,
}

/// A scene file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    /// Gravitational acceleration `[gx, gy]`.
    #[serde(deserialize_with = "strict_pair")]
    pub gravity: [f64; 2],
    /// Bodies, parents before children.
    #[serde(rename = "body")]
    pub bodies: Vec<BodySpec>,
    /// Contact pairs.
    #[serde(rename = "contact", default)]
    pub contacts: Vec<ContactSpec>,
    /// Half-planes of the world.
    #[serde(rename = "plane", default, skip_serializing_if = "Vec::is_empty")]
    pub planes: Vec<PlaneSpec>,
    /// Ellipses fixed in the world.
    #[serde(rename = "fixed", default, skip_serializing_if = "Vec::is_empty")]
    pub fixed: Vec<FixedSpec>,
}

/// The most bodies a scene holds: every derivative pass is dense in the joints (a free body has three), so
/// a bigger scene is refused by name rather than left to run out of memory.
pub const MAX_BODIES: usize = 100;
/// The most contact pairs a scene lists (two complementarity rows each).
pub const MAX_CONTACTS: usize = 200;
/// The largest size of a position, an anchor, a joint limit or a plane's point (the semi-axes' own bound,
/// `geometry::SEMI_AXIS_RANGE`): past it `M` and the contact rows lose every significant digit of the
/// scene's own scale.
pub const MAX_LENGTH: f64 = 1e6;
/// The largest gravity entry.
pub const MAX_GRAVITY: f64 = 1e6;
/// The largest friction coefficient of a contact pair (physical ones are below 2): past it the friction
/// rows dwarf the normal ones and the step's problem loses the normal rows to rounding.
pub const MAX_FRICTION: f64 = 100.0;
/// The longest scene file text (1 MiB): parsing TOML takes some fifty times its size in memory, so a
/// 47 MB array would ask for gigabytes before any field is checked.
pub const MAX_SCENE_TEXT: usize = 1 << 20;
/// The largest joint drag coefficient.
pub const MAX_DAMPING: f64 = 1e6;
/// The admissible densities (mass per unit area).
pub const DENSITY_RANGE: std::ops::RangeInclusive<f64> = 1e-6..=1e6;

/// A checked body.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    /// Name.
    pub name: String,
    /// Shape.
    pub shape: Ellipse,
    /// Mass.
    pub mass: f64,
    /// Moment of inertia about the centre.
    pub inertia: f64,
    /// Parent body index, `None` for the world.
    pub parent: Option<usize>,
    /// Hinge position in the parent's joint frame.
    pub anchor: [f64; 2],
    /// Centre in the body's joint frame.
    pub centre: [f64; 2],
    /// Its joint's kind.
    pub joint: JointKind,
    /// Its joint's coordinates (indices into [`Scene::coordinates`], in `q`'s order).
    pub coordinates: std::ops::Range<usize>,
}

/// A checked half-plane of the world.
#[derive(Debug, Clone, PartialEq)]
pub struct Plane {
    /// Name.
    pub name: String,
    /// Shape.
    pub shape: geometry::HalfPlane,
}

/// A checked ellipse fixed in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct Fixed {
    /// Name.
    pub name: String,
    /// Shape.
    pub shape: Ellipse,
    /// Pose `[x, y, angle]` in the world frame.
    pub pose: [f64; 3],
}

/// One side of a contact pair: a body on its joint, or a fixed part of the world.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The body of this index (it moves with its joint and its ancestors').
    Body(usize),
    /// The fixed ellipse of this index.
    Fixed(usize),
    /// The half-plane of this index.
    Plane(usize),
}

impl Side {
    /// The body, if this side is one.
    pub fn body(self) -> Option<usize> {
        match self {
            Side::Body(i) => Some(i),
            _ => None,
        }
    }
}

/// A checked contact pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactPair {
    /// Side A (the normal points from A to B).
    pub a: Side,
    /// Side B.
    pub b: Side,
    /// Friction coefficient.
    pub friction: f64,
}

/// A constraint a state breaks ([`Scene::overlaps`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Overlap {
    /// Which, by name: `contact[1]: ground and block overlap`, `finger.angle above its upper limit`.
    pub what: String,
    /// By how much (positive): the pair's penetration depth, or how far past the limit.
    pub depth: f64,
}

/// A scene's largest noise scale, per second, in multiples of its largest semi-axis
/// ([`Scene::largest_noise_scale`]).
pub const NOISE_SCALE_PER_SIZE: f64 = 10.0;

/// A checked, immutable scene. One generalised coordinate per body (its joint angle).
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    spec: SceneSpec,
    /// Gravity.
    pub gravity: [f64; 2],
    /// Bodies, parents first.
    pub bodies: Vec<Body>,
    /// The generalised coordinates, body by body (`q`'s order).
    pub coordinates: Vec<Coordinate>,
    /// Contact pairs.
    pub contacts: Vec<ContactPair>,
    /// Half-planes of the world.
    pub planes: Vec<Plane>,
    /// Ellipses fixed in the world.
    pub fixed: Vec<Fixed>,
    /// Number of controls.
    pub n_controls: usize,
    /// What each complementarity row is.
    rows: Vec<ConstraintRow>,
    /// `moves[j * bodies + i]`: whether coordinate `j` moves body `i` ([`Scene::moves`]).
    moves: Vec<bool>,
    /// The kinematic trees ([`Scene::trees`]).
    trees: Vec<Tree>,
}

/// The bodies hanging from one root body (a body whose parent is the world), and their coordinates. No
/// coordinate of one tree moves a body of another, so each tree's forces `r(q, v)` depend on its own
/// coordinates and velocities alone; only contacts couple trees.
#[derive(Debug, Clone, PartialEq)]
pub struct Tree {
    /// The tree's bodies, in the scene's order (parents first).
    pub bodies: Vec<usize>,
    /// The coordinates of its bodies' joints, in `q`'s order.
    pub coordinates: Vec<usize>,
}

impl Scene {
    /// Check a description; `Err(Scene)` lists every problem found.
    pub fn new(spec: SceneSpec) -> Result<Self, DynamicsError> {
        let mut problems = Vec::new();
        let mut bad = |field: String, problem: &str| {
            problems.push(SceneProblem {
                field,
                problem: problem.into(),
            })
        };
        if !spec
            .gravity
            .iter()
            .all(|g| g.is_finite() && g.abs() <= MAX_GRAVITY)
        {
            bad(
                "gravity".into(),
                "must be finite, each entry at most 1e6 in size (MAX_GRAVITY)",
            );
        }
        if spec.bodies.is_empty() {
            bad("body".into(), "a scene needs at least one body");
        }
        if spec.bodies.len() > MAX_BODIES {
            bad(
                "body".into(),
                &format!(
                    "{} bodies: a scene holds at most {MAX_BODIES} (MAX_BODIES)",
                    spec.bodies.len()
                ),
            );
        }
        if spec.contacts.len() > MAX_CONTACTS {
            bad(
                "contact".into(),
                &format!(
                    "{} contact pairs: a scene holds at most {MAX_CONTACTS} (MAX_CONTACTS)",
                    spec.contacts.len()
                ),
            );
        }
        let length = |v: &f64| v.is_finite() && v.abs() <= MAX_LENGTH;
        let mut bodies = Vec::new();
        let mut coordinates = Vec::new();
        let mut n_controls = 0;
        for (i, b) in spec.bodies.iter().enumerate() {
            let f = |name: &str| format!("body[{i}].{name}");
            if spec.bodies[..i].iter().any(|o| o.name == b.name) || b.name == "world" {
                bad(f("name"), "must be unique and not \"world\"");
            }
            let shape = match Ellipse::new(b.semi_axes[0], b.semi_axes[1]) {
                Ok(s) => Some(s),
                Err(_) => {
                    bad(
                        f("semi_axes"),
                        "must be between 1e-6 and 1e6 (geometry::SEMI_AXIS_RANGE)",
                    );
                    None
                }
            };
            if !(DENSITY_RANGE.contains(&b.density)) {
                bad(f("density"), "must be between 1e-6 and 1e6 (DENSITY_RANGE)");
            }
            let parent = if b.parent == "world" {
                Some(None)
            } else {
                match spec.bodies[..i].iter().position(|o| o.name == b.parent) {
                    Some(p) => Some(Some(p)),
                    None => {
                        bad(
                            f("parent"),
                            "must be \"world\" or the name of an earlier body",
                        );
                        None
                    }
                }
            };
            if !b.anchor.iter().all(length) {
                bad(
                    f("anchor"),
                    "must be finite, each entry at most 1e6 in size (MAX_LENGTH)",
                );
            }
            if !b.centre.iter().all(length) {
                bad(
                    f("centre"),
                    "must be finite, each entry at most 1e6 in size (MAX_LENGTH)",
                );
            }
            if let Some([lo, hi]) = b.joint.limits
                && !(length(&lo) && length(&hi) && lo < hi)
            {
                bad(
                    f("joint.limits"),
                    "must be finite, at most 1e6 in size (MAX_LENGTH), with lower < upper",
                );
            }
            if !(b.joint.damping.is_finite()
                && b.joint.damping >= 0.0
                && b.joint.damping <= MAX_DAMPING)
            {
                bad(
                    f("joint.damping"),
                    "must be between 0 and 1e6 (MAX_DAMPING)",
                );
            }
            let axis = match (b.joint.kind, b.joint.axis) {
                (JointKind::Slider, Some([x, y])) => {
                    let len = x.hypot(y);
                    if !(len.is_finite() && len > 0.0) {
                        bad(f("joint.axis"), "must be finite and non-zero");
                    }
                    [x / len, y / len]
                }
                (JointKind::Slider, None) => {
                    bad(f("joint.axis"), "a slider needs an axis");
                    [1.0, 0.0]
                }
                (_, Some(_)) => {
                    bad(f("joint.axis"), "only a slider has an axis");
                    [1.0, 0.0]
                }
                (_, None) => [1.0, 0.0],
            };
            if b.joint.kind == JointKind::Free && b.joint.limits.is_some() {
                bad(
                    f("joint.limits"),
                    "a free joint takes no limits (bound it with planes)",
                );
            }
            if b.joint.kind == JointKind::Weld {
                if b.parent == "world" {
                    bad(
                        f("joint.type"),
                        "a weld joins a body to another body; an ellipse welded to the world is a [[fixed]] ellipse",
                    );
                }
                if b.joint.limits.is_some() || b.joint.actuated || b.joint.damping != 0.0 {
                    bad(
                        f("joint"),
                        "a weld has no coordinate: it takes no limits, damping or actuation",
                    );
                }
            }
            let kinds = match b.joint.kind {
                JointKind::Hinge => vec![CoordinateKind::Angle],
                JointKind::Slider => vec![CoordinateKind::Slide { axis }],
                JointKind::Free => vec![
                    CoordinateKind::Slide { axis: [1.0, 0.0] },
                    CoordinateKind::Slide { axis: [0.0, 1.0] },
                    CoordinateKind::Angle,
                ],
                JointKind::Weld => Vec::new(),
            };
            let first = coordinates.len();
            for kind in kinds {
                let actuator = b.joint.actuated.then(|| {
                    n_controls += 1;
                    n_controls - 1
                });
                coordinates.push(Coordinate {
                    body: bodies.len(),
                    kind,
                    limits: b.joint.limits,
                    damping: b.joint.damping,
                    actuator,
                });
            }
            if let (Some(shape), Some(parent)) = (shape, parent) {
                let mass = std::f64::consts::PI * b.semi_axes[0] * b.semi_axes[1] * b.density;
                bodies.push(Body {
                    name: b.name.clone(),
                    shape,
                    mass,
                    inertia: b.density * shape.unit_inertia(),
                    parent,
                    anchor: b.anchor,
                    centre: b.centre,
                    joint: b.joint.kind,
                    coordinates: first..coordinates.len(),
                });
            } else {
                // The scene is refused; keep the coordinates consistent with the bodies kept.
                coordinates.truncate(first);
            }
        }
        // The static shapes' names: unique among bodies, planes and fixed ellipses, and not "world".
        let statics: Vec<(String, &String)> = (spec.planes.iter().enumerate())
            .map(|(i, p)| (format!("plane[{i}].name"), &p.name))
            .chain(
                (spec.fixed.iter().enumerate()).map(|(i, e)| (format!("fixed[{i}].name"), &e.name)),
            )
            .collect();
        for (field, name) in &statics {
            if *name == "world"
                || spec.bodies.iter().any(|o| &o.name == *name)
                || statics.iter().filter(|(_, o)| o == name).count() > 1
            {
                bad(
                    field.clone(),
                    "must be unique among bodies, planes and fixed ellipses and not \"world\"",
                );
            }
        }
        let mut planes = Vec::new();
        for (i, p) in spec.planes.iter().enumerate() {
            let f = |name: &str| format!("plane[{i}].{name}");
            if !p.point.iter().all(length) {
                bad(
                    f("point"),
                    "must be finite, each entry at most 1e6 in size (MAX_LENGTH)",
                );
            }
            match geometry::HalfPlane::new(p.point, p.normal) {
                Ok(shape) => planes.push(Plane {
                    name: p.name.clone(),
                    shape,
                }),
                Err(_) => bad(
                    f("point/normal"),
                    "the point must be finite and the normal finite and non-zero",
                ),
            }
        }
        let mut fixed = Vec::new();
        for (i, e) in spec.fixed.iter().enumerate() {
            let f = |name: &str| format!("fixed[{i}].{name}");
            if !e.centre.iter().all(length) {
                bad(
                    f("centre"),
                    "must be finite, each entry at most 1e6 in size (MAX_LENGTH)",
                );
            }
            if !length(&e.angle) {
                bad(
                    f("angle"),
                    "must be finite, at most 1e6 in size (MAX_LENGTH)",
                );
            }
            match Ellipse::new(e.semi_axes[0], e.semi_axes[1]) {
                Ok(shape) => fixed.push(Fixed {
                    name: e.name.clone(),
                    shape,
                    pose: [e.centre[0], e.centre[1], e.angle],
                }),
                Err(_) => bad(
                    f("semi_axes"),
                    "must be between 1e-6 and 1e6 (geometry::SEMI_AXIS_RANGE)",
                ),
            }
        }
        let index = |name: &str| {
            if let Some(i) = spec.bodies.iter().position(|b| b.name == name) {
                Some(Side::Body(i))
            } else if let Some(i) = spec.fixed.iter().position(|b| b.name == name) {
                Some(Side::Fixed(i))
            } else {
                spec.planes
                    .iter()
                    .position(|b| b.name == name)
                    .map(Side::Plane)
            }
        };
        // The body whose joint carries body `i`: itself, or for a weld its parent's carrier.
        let welded_to = |mut i: usize| {
            while spec.bodies[i].joint.kind == JointKind::Weld {
                match spec.bodies[..i]
                    .iter()
                    .position(|o| o.name == spec.bodies[i].parent)
                {
                    Some(p) => i = p,
                    None => break,
                }
            }
            i
        };
        let mut contacts = Vec::new();
        for (k, c) in spec.contacts.iter().enumerate() {
            let f = |name: &str| format!("contact[{k}].{name}");
            let (a, b) = (index(&c.a), index(&c.b));
            if a.is_none() {
                bad(f("a"), "names no body, plane or fixed ellipse");
            }
            if b.is_none() {
                bad(f("b"), "names no body, plane or fixed ellipse");
            }
            if a.is_some() && a == b {
                bad(f("b"), "a pair needs two different bodies");
            }
            if let (Some(a), Some(b)) = (a, b)
                && a.body().is_none()
                && b.body().is_none()
            {
                bad(
                    f("b"),
                    "a pair needs a moving body on one side (both are fixed parts of the world)",
                );
            }
            if let (Some(Side::Body(a)), Some(Side::Body(b))) = (a, b)
                && a != b
                && welded_to(a) == welded_to(b)
            {
                bad(
                    f("b"),
                    "the two sides are welded into one rigid body: their distance never changes",
                );
            }
            if !(c.friction.is_finite() && c.friction >= 0.0 && c.friction <= MAX_FRICTION) {
                bad(f("friction"), "must be between 0 and 100 (MAX_FRICTION)");
            }
            if let Some(j) = spec.contacts[..k]
                .iter()
                .position(|o| (o.a == c.a && o.b == c.b) || (o.a == c.b && o.b == c.a))
            {
                bad(
                    f("b"),
                    &format!(
                        "the pair {} / {} is already contact[{j}]: each pair is listed once",
                        c.a, c.b
                    ),
                );
            }
            if let (Some(a), Some(b)) = (a, b) {
                contacts.push(ContactPair {
                    a,
                    b,
                    friction: c.friction,
                });
            }
        }
        if !problems.is_empty() {
            return Err(DynamicsError::Scene(problems));
        }
        let mut scene = Scene {
            gravity: spec.gravity,
            bodies,
            coordinates,
            contacts,
            planes,
            fixed,
            n_controls,
            spec,
            rows: Vec::new(),
            moves: Vec::new(),
            trees: Vec::new(),
        };
        scene.rows = ConstraintRow::of(&scene);
        let nb = scene.bodies.len();
        scene.moves = (0..scene.n_dof() * nb)
            .map(|k| {
                let (j, i) = (scene.coordinates[k / nb].body, k % nb);
                let mut b = Some(i);
                while let Some(a) = b {
                    if a == j {
                        return true;
                    }
                    b = scene.bodies[a].parent;
                }
                false
            })
            .collect();
        // Each body's tree: its root's (parents come first, so a parent's is known).
        let mut tree_of = vec![0; nb];
        for i in 0..nb {
            tree_of[i] = match scene.bodies[i].parent {
                Some(p) => tree_of[p],
                None => {
                    scene.trees.push(Tree {
                        bodies: Vec::new(),
                        coordinates: Vec::new(),
                    });
                    scene.trees.len() - 1
                }
            };
            let tree = &mut scene.trees[tree_of[i]];
            tree.bodies.push(i);
            tree.coordinates.extend(scene.bodies[i].coordinates.clone());
        }
        // Bodies are visited in order and each body's coordinates follow the previous body's, so each
        // tree's coordinates are in q's order already.
        debug_assert!(scene.trees.iter().all(|t| t.coordinates.is_sorted()));
        Ok(scene)
    }

    /// Parse and check a TOML scene.
    ///
    /// A scene file may also hold `[task.NAME]` tables: they belong to the crates above (the `library`
    /// crate's `ProblemFile` reads them) and are left out here, unchecked.
    pub fn from_toml_str(text: &str) -> Result<Self, DynamicsError> {
        if text.len() > MAX_SCENE_TEXT {
            return Err(DynamicsError::Parse(format!(
                "{} bytes: a scene file is at most {MAX_SCENE_TEXT} bytes (MAX_SCENE_TEXT; a scene at every \
                 other limit takes well under a hundredth of it)",
                text.len()
            )));
        }
        let mut table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| DynamicsError::Parse(e.to_string()))?;
        table.remove("task");
        // Each listed item on its own first, so that an error names the item (`body[2]: missing field
        // `name``) rather than only the field.
        fn each<T: serde::de::DeserializeOwned>(
            table: &toml::Table,
            key: &str,
        ) -> Result<(), DynamicsError> {
            if let Some(toml::Value::Array(items)) = table.get(key) {
                for (i, item) in items.iter().enumerate() {
                    if let Err(e) = T::deserialize(item.clone()) {
                        return Err(DynamicsError::Parse(format!(
                            "{key}[{i}]: {}",
                            e.to_string().trim_end()
                        )));
                    }
                }
            }
            Ok(())
        }
        each::<BodySpec>(&table, "body")?;
        each::<ContactSpec>(&table, "contact")?;
        each::<PlaneSpec>(&table, "plane")?;
        each::<FixedSpec>(&table, "fixed")?;
        let spec: SceneSpec = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| DynamicsError::Parse(e.to_string()))?;
        Self::new(spec)
    }

    /// The description this scene was built from (for saving it beside results).
    pub fn spec(&self) -> &SceneSpec {
        &self.spec
    }

    /// The largest noise scale a smoothed model may have on this scene: [`NOISE_SCALE_PER_SIZE`] per second
    /// times its largest semi-axis (of a moving body or a fixed ellipse), for any time step. The noise acts
    /// on a row's velocity `d / h + J v'` (docs/complementarity.md): out of contact a smoothed row's impulse
    /// is about `sigma exp(-b / sigma)`, so far beyond the speeds at which the scene's bodies cross their
    /// own sizes every limit and contact row pushes at any distance, and the step stops being dissipative.
    /// From rest with zero controls for 20 s, the pushing scene (largest semi-axis 0.5) is still moving at
    /// 1.8 to 3.3 at sigma 20 (h 0.01 and 0.05) and the finger of SCENE.md (0.8) spins its ellipse at
    /// sigma 50 (h 0.05 and 0.1), where at this bound every scene of the repository comes to rest
    /// (`noise_scales_up_to_the_scenes_bound_dissipate`).
    pub fn largest_noise_scale(&self) -> f64 {
        let body = self.bodies.iter().map(|b| b.shape.a().max(b.shape.b()));
        let fixed = self.fixed.iter().map(|f| f.shape.a().max(f.shape.b()));
        NOISE_SCALE_PER_SIZE * body.chain(fixed).fold(0.0, f64::max)
    }

    /// `Err(DynamicsError::NoiseScale)` for a noise scale beyond [`Scene::largest_noise_scale`]: the one
    /// check a step's model, a task file and the viewer make.
    pub fn check_noise_scale(&self, sigma: f64) -> Result<(), DynamicsError> {
        let largest = self.largest_noise_scale();
        if sigma > largest {
            return Err(DynamicsError::NoiseScale { sigma, largest });
        }
        Ok(())
    }

    /// The time step below which every free body of the scene rests stably on its flat side on each plane
    /// it touches; `None` when no free body touches a plane that gravity presses it onto, or none could
    /// rock (a disc).
    ///
    /// An ellipse of semi-axes `a > b` lying on its long side on a plane rocks like a pendulum: its
    /// centre's height is `b + (a^2/b - b) theta^2 / 2` after turning by `theta`, so it rocks at
    /// `omega^2 = g_n (a^2/b - b) / k^2` (sliding; `g_n` gravity along the plane's normal, `k^2 = I / m`;
    /// rolling without slip adds `b^2` to `k^2`, which only slows it). The step's semi-implicit Euler
    /// resolves a rocking mode only while `h omega < 2`: past it the rest of a thin needle is unstable,
    /// rounding grows by a constant factor every step, and the needle ends in a two-step cycle, turning
    /// through flat and partly sunk. A needle 0.18 by 0.017 under gravity 9.6 rocks at 48 rad/s: the limit
    /// is 0.042 s. This is `min 2 / omega` over the scene's free bodies (root bodies with a free joint)
    /// and the planes they touch.
    pub fn rocking_limit(&self) -> Option<f64> {
        let mut limit: Option<f64> = None;
        for pair in &self.contacts {
            let (plane, body) = match (pair.a, pair.b) {
                (Side::Plane(p), Side::Body(b)) | (Side::Body(b), Side::Plane(p)) => (p, b),
                _ => continue,
            };
            let b = &self.bodies[body];
            if b.joint != JointKind::Free || b.parent.is_some() {
                continue;
            }
            let normal = self.planes[plane].shape.normal();
            let pressing = -(self.gravity[0] * normal[0] + self.gravity[1] * normal[1]);
            let (long, short) = (b.shape.a().max(b.shape.b()), b.shape.a().min(b.shape.b()));
            let lift = long * long / short - short;
            if pressing <= 0.0 || lift <= 0.0 {
                continue;
            }
            let omega = (pressing * lift * b.mass / b.inertia).sqrt();
            let h = 2.0 / omega;
            limit = Some(limit.map_or(h, |l| l.min(h)));
        }
        limit
    }

    /// The constraints `q` breaks by more than `tolerance`, deepest first: contact pairs whose sides
    /// overlap (named by the scene file's `contact[i]` and its two sides) and coordinates past a limit
    /// (named by [`Scene::coordinate_names`]). A task or a simulation that starts there starts with its
    /// bodies being pushed apart, which no one asked for; `Err` when `q` has the wrong length or is not
    /// finite.
    pub fn overlaps(&self, q: &[f64], tolerance: f64) -> Result<Vec<Overlap>, DynamicsError> {
        if q.len() != self.n_dof() {
            return Err(DynamicsError::Input {
                what: "q",
                problem: format!(
                    "{} entries, the scene has {} coordinates",
                    q.len(),
                    self.n_dof()
                ),
            });
        }
        if let Some(i) = q.iter().position(|v| !v.is_finite()) {
            return Err(DynamicsError::Input {
                what: "q",
                problem: format!("q[{i}] = {} is not finite", q[i]),
            });
        }
        let kin = crate::Kinematics::new(self, q);
        let cons = crate::Constraints::new(self, &kin, q)?;
        let names = self.coordinate_names();
        let mut out: Vec<Overlap> = Vec::new();
        for (row, &d) in self.rows.iter().zip(&cons.d) {
            if d >= -tolerance {
                continue;
            }
            let what = match *row {
                ConstraintRow::LowerLimit { joint } => {
                    format!("{} below its lower limit", names[joint])
                }
                ConstraintRow::UpperLimit { joint } => {
                    format!("{} above its upper limit", names[joint])
                }
                ConstraintRow::FrictionEdge {
                    pair,
                    positive: true,
                } => {
                    let c = &self.spec.contacts[pair];
                    format!("contact[{pair}]: {} and {} overlap", c.a, c.b)
                }
                ConstraintRow::FrictionEdge { .. } => continue,
            };
            out.push(Overlap { what, depth: -d });
        }
        out.sort_by(|a, b| b.depth.total_cmp(&a.depth));
        Ok(out)
    }

    /// The angle coordinates that turn `body`: its own joint's and every ancestor's (a body's absolute
    /// angle is their sum; sliders move frames without turning them).
    pub fn turning_coordinates(&self, body: usize) -> Vec<usize> {
        let mut turns = Vec::new();
        let mut next = Some(body);
        while let Some(i) = next {
            let b = &self.bodies[i];
            turns.extend(
                b.coordinates
                    .clone()
                    .filter(|&c| self.coordinates[c].kind == CoordinateKind::Angle),
            );
            next = b.parent;
        }
        turns
    }

    /// The angle coordinates a half turn of which maps the scene onto itself: the angle of a body (a
    /// hinge's, or a free joint's third coordinate) whose ellipse is centred on the joint's origin, with no
    /// limits and no body attached to it. An ellipse of uniform density is the same shape, mass and
    /// inertia turned by pi about its centre, and its weight acts there, so the state with such an angle
    /// moved by pi (every other entry the same) is the same physical state and steps the same way: a block
    /// a kick turned over is the block it was.
    pub fn half_turn_coordinates(&self) -> Vec<usize> {
        (self.coordinates.iter().enumerate())
            .filter(|(_, c)| c.kind == CoordinateKind::Angle && c.limits.is_none())
            .filter(|(_, c)| {
                let b = &self.bodies[c.body];
                b.centre == [0.0, 0.0] && !self.bodies.iter().any(|o| o.parent == Some(c.body))
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// Those of the [`Scene::half_turn_coordinates`] whose body is round (equal semi-axes): any turn of
    /// them maps the scene onto itself, and the angle itself does not matter (a disc's orientation).
    pub fn round_coordinates(&self) -> Vec<usize> {
        self.half_turn_coordinates()
            .into_iter()
            .filter(|&c| {
                let shape = &self.bodies[self.coordinates[c].body].shape;
                shape.a() == shape.b()
            })
            .collect()
    }

    /// The body whose joint carries `body`: `body` itself, or for a body welded to its parent the parent's
    /// carrier (a weld has no coordinate of its own).
    pub fn carrier(&self, body: usize) -> usize {
        let mut i = body;
        while self.bodies[i].joint == JointKind::Weld {
            match self.bodies[i].parent {
                Some(p) => i = p,
                None => break,
            }
        }
        i
    }

    /// The name the scene file gives a side of a contact pair (its body's, half-plane's or fixed
    /// ellipse's); `None` for an index the scene does not have.
    pub fn side_name(&self, side: Side) -> Option<&str> {
        match side {
            Side::Body(i) => self.bodies.get(i).map(|b| b.name.as_str()),
            Side::Fixed(i) => self.fixed.get(i).map(|f| f.name.as_str()),
            Side::Plane(i) => self.planes.get(i).map(|p| p.name.as_str()),
        }
    }

    /// Contact pair `pair` named by its two sides, `a-b` (`link2-ellipse`, `ground-block`); `None` for a
    /// pair the scene does not have.
    pub fn pair_name(&self, pair: usize) -> Option<String> {
        let c = self.contacts.get(pair)?;
        Some(format!("{}-{}", self.side_name(c.a)?, self.side_name(c.b)?))
    }

    /// Whether a control acts on `body`'s own joint (its carrier's, for a welded body): a driven body, not
    /// a free object of a task.
    pub fn actuated(&self, body: usize) -> bool {
        self.coordinates[self.bodies[self.carrier(body)].coordinates.clone()]
            .iter()
            .any(|c| c.actuator.is_some())
    }

    /// A disc fixed in the world, `(centre, radius)`, that holds every point of body `i` in every
    /// configuration its joints allow: hinges at any angle (their limits are not needed, and soft limits
    /// may be passed), slides within their limits. `None` when a slide on the way from the world has no
    /// limits (a free joint's `x` and `y`): the body can go anywhere; also for a body index the scene does
    /// not have. A bound by the triangle inequality, loose but never short: a point outside the disc (by
    /// more than the limits' slack) is out of the body's reach, whatever the controls do.
    pub fn workspace(&self, i: usize) -> Option<([f64; 2], f64)> {
        let b = self.bodies.get(i)?;
        let (centre, mut radius) = self.origin_workspace(i)?;
        radius += b.centre[0].hypot(b.centre[1]) + b.shape.a().max(b.shape.b());
        Some((centre, radius))
    }

    /// [`Scene::workspace`] of body `i`'s joint frame origin.
    fn origin_workspace(&self, i: usize) -> Option<([f64; 2], f64)> {
        let b = &self.bodies[i];
        let (centre, mut radius) = match b.parent {
            None => (b.anchor, 0.0),
            Some(p) => {
                let (c, r) = self.origin_workspace(p)?;
                (c, r + b.anchor[0].hypot(b.anchor[1]))
            }
        };
        for c in &self.coordinates[b.coordinates.clone()] {
            if let CoordinateKind::Slide { axis } = c.kind {
                let [lo, hi] = c.limits?;
                radius += lo.abs().max(hi.abs()) * axis[0].hypot(axis[1]);
            }
        }
        Some((centre, radius))
    }

    /// Number of generalised coordinates (one per hinge or slider, three per free joint, none for a weld).
    pub fn n_dof(&self) -> usize {
        self.coordinates.len()
    }

    /// Number of state entries `[q; v]`.
    pub fn n_state(&self) -> usize {
        2 * self.n_dof()
    }

    /// The name of each joint coordinate, in the order of `q` (and of `v`): `<body>.<coordinate>`, a
    /// hinge's being `<body>.angle`, a slider's `<body>.position`, a free joint's `<body>.x`, `<body>.y`
    /// and `<body>.angle`. Tasks name the coordinates their costs and initial states act on.
    pub fn coordinate_names(&self) -> Vec<String> {
        self.coordinates
            .iter()
            .map(|c| {
                let b = &self.bodies[c.body];
                let what = match (b.joint, c.kind) {
                    (_, CoordinateKind::Angle) => "angle",
                    (JointKind::Free, CoordinateKind::Slide { axis }) if axis[0] == 1.0 => "x",
                    (JointKind::Free, CoordinateKind::Slide { .. }) => "y",
                    (_, CoordinateKind::Slide { .. }) => "position",
                };
                format!("{}.{what}", b.name)
            })
            .collect()
    }

    /// The name of each state entry of `x = [q; v]`: the coordinates' names, then each with " velocity".
    pub fn state_names(&self) -> Vec<String> {
        let names = self.coordinate_names();
        let velocities: Vec<String> = names.iter().map(|c| format!("{c} velocity")).collect();
        names.into_iter().chain(velocities).collect()
    }

    /// Number of unilateral constraint rows: two per joint with limits, two per contact pair.
    pub fn n_constraints(&self) -> usize {
        self.rows.len()
    }

    /// What each complementarity row is (joint limit of which joint, or friction-cone edge of which
    /// contact pair), in the order of a step's `lambda` and `d`.
    pub fn rows(&self) -> &[ConstraintRow] {
        &self.rows
    }

    /// The kinematic trees: the bodies under each root body, in the order of their roots.
    pub fn trees(&self) -> &[Tree] {
        &self.trees
    }

    /// Whether coordinate `j` belongs to body `i` or one of its ancestors (so it moves body `i`).
    #[inline]
    pub fn moves(&self, j: usize, i: usize) -> bool {
        self.moves[j * self.bodies.len() + i]
    }
}

/// A pair read strictly: exactly two numbers (a plain `[f64; 2]` lets a TOML reader drop extra entries).
fn strict_pair<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    let v = Vec::<f64>::deserialize(d)?;
    <[f64; 2]>::try_from(v.as_slice())
        .map_err(|_| serde::de::Error::custom(format!("needs exactly 2 numbers, got {}", v.len())))
}

/// [`strict_pair`] for an optional field.
fn strict_pair_option<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> Result<Option<[f64; 2]>, D::Error> {
    let v = Option::<Vec<f64>>::deserialize(d)?;
    v.map(|v| {
        <[f64; 2]>::try_from(v.as_slice()).map_err(|_| {
            serde::de::Error::custom(format!("needs exactly 2 numbers, got {}", v.len()))
        })
    })
    .transpose()
}

/// What a complementarity row is and whose it is ([`Scene::rows`]): rows are never decoded by position
/// outside this crate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ConstraintRow {
    /// Coordinate `joint`'s lower limit, `q_j - lo >= 0`.
    LowerLimit {
        /// The coordinate (index into `q`; a hinge's is its body's index when every joint is a hinge).
        joint: usize,
    },
    /// Coordinate `joint`'s upper limit, `hi - q_j >= 0`.
    UpperLimit {
        /// The coordinate (index into `q`).
        joint: usize,
    },
    /// An edge of contact pair `pair`'s linearised friction cone: the row `J_n + mu J_t` (`positive`) or
    /// `J_n - mu J_t`, whose constraint value is the pair's signed distance.
    FrictionEdge {
        /// The contact pair (index into [`Scene::contacts`]).
        pair: usize,
        /// Which edge: `+ mu J_t` or `- mu J_t`.
        positive: bool,
    },
}

impl ConstraintRow {
    /// The rows of `scene` in the order of [`Constraints`](crate::Constraints): each limited joint's lower then upper row,
    /// then each contact pair's two friction-cone edges.
    pub(crate) fn of(scene: &Scene) -> Vec<ConstraintRow> {
        let mut rows = Vec::new();
        for (joint, c) in scene.coordinates.iter().enumerate() {
            if c.limits.is_some() {
                rows.push(ConstraintRow::LowerLimit { joint });
                rows.push(ConstraintRow::UpperLimit { joint });
            }
        }
        for pair in 0..scene.contacts.len() {
            rows.push(ConstraintRow::FrictionEdge {
                pair,
                positive: true,
            });
            rows.push(ConstraintRow::FrictionEdge {
                pair,
                positive: false,
            });
        }
        rows
    }
}
