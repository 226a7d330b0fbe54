//! The simulated world behind the page: the scene's state stepped in real time under a policy, the user's
//! drag spring and kicks, and the frames the page draws. No networking here: the server drives a
//! [`World`] and the tests can too.

use crate::error::ViewerError;
use crate::mpc::{MpcSettings, OnlineMpc};
use crate::protocol::{
    BodyPose, BodyShape, ClientMessage, ContactView, FixedShape, Frame, PlaneShape, PolicyKind,
    ServerMessage, SpringView, TargetPose, WatchedView, WorldKind,
};
use dynamics::{Complementarity, CoordinateKind, Kinematics, Scene, Simulator, StepSettings};
use library::{Library, Policy};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::collections::VecDeque;
use task::{Progress, Task};

/// Spring stiffness of a drag, force per unit length.
pub const SPRING_STIFFNESS: f64 = 10.0;
/// Damping of a drag, force per unit velocity of the grabbed point.
pub const SPRING_DAMPING: f64 = 1.0;
/// The largest force a drag applies.
pub const SPRING_MAX_FORCE: f64 = 30.0;
/// Passes at most of the online optimiser's first solve.
const MPC_FIRST_PASSES: usize = 300;
/// A plan turning the free body less than this over its horizon counts as stalled, rad.
const STALL_TURN: f64 = 0.1;
/// Control steps of stalled plans before the online optimiser is re-seeded from the library's policy.
const STALL_STEPS: u64 = 20;
/// Window of the spin rate and of the largest control time, s.
const WINDOW: f64 = 2.0;

/// How the world starts.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldSettings {
    /// Time step.
    pub h: f64,
    /// The smoothed world's and the online optimiser's sigma.
    pub sigma: f64,
    /// Initial policy.
    pub policy: PolicyKind,
    /// Initial world.
    pub world: WorldKind,
    /// Simulated seconds per real second.
    pub speed: f64,
    /// Initial state (and the state of a reset).
    pub x0: Vec<f64>,
    /// The online optimiser's horizon, steps (60: a control step well inside 2.5 ms; the task's 75 spins
    /// about as well at 1.3 times the time, docs/benchmarks.md).
    pub mpc_horizon: usize,
    /// Optimiser passes per control step.
    pub mpc_passes: usize,
    /// Seed of the kicks.
    pub seed: u64,
    /// The task of a scene file the online optimiser minimises, whose progress or target the page
    /// follows (by default the built-in file's, `scenes/finger.toml`'s `spin`). Its `x0`, `h` and
    /// contact model are not taken from it here: set them above.
    pub task: Task,
}

impl Default for WorldSettings {
    /// The built-in scene file's task ([`task::ProblemFile::builtin_task`]) from its start.
    fn default() -> Self {
        let task = task::ProblemFile::builtin_task().1;
        WorldSettings {
            h: 0.05,
            sigma: 0.1,
            policy: PolicyKind::Library,
            world: WorldKind::Smoothed,
            speed: 1.0,
            x0: task.x0.clone(),
            mpc_horizon: MpcSettings::default().horizon,
            mpc_passes: MpcSettings::default().passes,
            seed: 1,
            task,
        }
    }
}

/// The state entry the page follows: the task's progress coordinate (its rate is the frame's
/// `spin_rate`) or, for a task without one, its first position target.
#[derive(Debug, Clone, PartialEq)]
struct Watched {
    index: usize,
    name: String,
    target: Option<f64>,
}

impl Watched {
    fn of(scene: &Scene, task: &Task) -> Result<Self, ViewerError> {
        let names = scene.state_names();
        let progress = Progress::of_task(task)?;
        if progress.forward.is_none()
            && let Some(term) = task
                .cost
                .running
                .iter()
                .chain(&task.cost.final_terms)
                .find(|t| t.index < scene.n_dof() && t.quadratic != 0.0)
        {
            return Ok(Watched {
                index: term.index,
                name: names[term.index].clone(),
                target: Some(term.target),
            });
        }
        Ok(Watched {
            index: progress.coordinate,
            name: names[progress.coordinate].clone(),
            target: None,
        })
    }
}

/// The bodies where `task` wants them ([`TargetPose`]): its initial pose with each position its cost
/// pulls to a target set to that target (a final term's over a running term's), and only the bodies
/// those coordinates move; none for a task without position targets.
pub fn target_poses(scene: &Scene, task: &Task) -> Vec<TargetPose> {
    let n = scene.n_dof();
    let mut q = task.x0[..n].to_vec();
    let mut targeted = vec![false; n];
    for term in task.cost.running.iter().chain(&task.cost.final_terms) {
        if term.index < n && term.quadratic != 0.0 && term.target.is_finite() {
            q[term.index] = term.target;
            targeted[term.index] = true;
        }
    }
    let kin = Kinematics::new(scene, &q);
    (0..scene.bodies.len())
        .filter(|&b| (0..n).any(|c| targeted[c] && scene.moves(c, b)))
        .map(|b| TargetPose {
            body: b,
            centre: kin.centre[b],
            angle: kin.phi[b],
        })
        .collect()
}

/// A world window `[x_min, x_max, y_min, y_max]` for the page: every body at `x0` and within the reach
/// of its chain's root (a hinged chain can swing all the way round its anchor), the fixed ellipses, and
/// a strip of each half-plane, with a margin.
pub fn window(scene: &Scene, x0: &[f64]) -> [f64; 4] {
    let kin = Kinematics::new(scene, &x0[..scene.n_dof()]);
    let mut bounds = [[f64::INFINITY; 2], [f64::NEG_INFINITY; 2]];
    let cover = |bounds: &mut [[f64; 2]; 2], c: [f64; 2], r: f64| {
        for k in 0..2 {
            bounds[0][k] = bounds[0][k].min(c[k] - r);
            bounds[1][k] = bounds[1][k].max(c[k] + r);
        }
    };
    for (i, b) in scene.bodies.iter().enumerate() {
        let size = b.shape.a().max(b.shape.b());
        cover(&mut bounds, kin.centre[i], size);
        let mut root = i;
        while let Some(p) = scene.bodies[root].parent {
            root = p;
        }
        // A hinged root swings its chain round its pivot; a free or sliding root carries it along (a unit
        // of room around it).
        if scene.bodies[root].joint == dynamics::JointKind::Hinge {
            let pivot = kin.hinge[root];
            let reach = (kin.centre[i][0] - pivot[0]).hypot(kin.centre[i][1] - pivot[1]) + size;
            cover(&mut bounds, pivot, reach);
        } else {
            cover(&mut bounds, kin.centre[i], size + 1.0);
        }
    }
    for f in &scene.fixed {
        cover(
            &mut bounds,
            [f.pose[0], f.pose[1]],
            f.shape.a().max(f.shape.b()),
        );
    }
    let [lo, hi] = bounds;
    let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    for p in &scene.planes {
        let (o, n) = (p.shape.point(), p.shape.normal());
        let s = (mid[0] - o[0]) * n[0] + (mid[1] - o[1]) * n[1];
        let foot = [mid[0] - s * n[0], mid[1] - s * n[1]];
        if foot.iter().all(|v| v.abs() < 1e3) {
            cover(&mut bounds, foot, 0.3);
        }
    }
    let [lo, hi] = bounds;
    let margin = 0.3;
    [
        lo[0] - margin,
        hi[0] + margin,
        lo[1] - margin,
        hi[1] + margin,
    ]
}

#[derive(Debug, Clone, Copy)]
struct Drag {
    body: usize,
    /// The grabbed material point in the body's frame (relative to its hinge).
    local: [f64; 2],
    target: [f64; 2],
}

/// The world (see the module documentation).
#[derive(Debug)]
pub struct World {
    scene: Scene,
    settings: WorldSettings,
    library: Option<(Library, Policy)>,
    mpc: Option<OnlineMpc>,
    sim: Simulator,
    x: Vec<f64>,
    u: Vec<f64>,
    t: f64,
    steps: u64,
    policy: PolicyKind,
    world: WorldKind,
    sigma: f64,
    speed: f64,
    paused: bool,
    drag: Option<Drag>,
    contacts: Vec<ContactView>,
    /// `(t, watched entry, control ms)` over the last [`WINDOW`] seconds.
    history: VecDeque<(f64, f64, f64)>,
    control_ms: f64,
    perturbations: u64,
    unconverged: u64,
    watched: Watched,
    rng: rand_chacha::ChaCha8Rng,
    warning: Option<String>,
    stalled: u64,
    reseeds: u64,
}

fn check_positive(name: &'static str, value: f64) -> Result<(), ViewerError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ViewerError::Setting {
            name,
            value,
            expected: "finite and positive",
        })
    }
}

fn check_speed(speed: f64) -> Result<(), ViewerError> {
    if (0.05..=10.0).contains(&speed) {
        Ok(())
    } else {
        Err(ViewerError::Setting {
            name: "speed",
            value: speed,
            expected: "between 0.05 and 10",
        })
    }
}

fn check_point(p: [f64; 2]) -> Result<(), ViewerError> {
    if p.iter().all(|e| e.is_finite() && e.abs() < 1e3) {
        Ok(())
    } else {
        Err(ViewerError::Message(format!(
            "point {p:?} is not finite or is far outside the scene"
        )))
    }
}

impl World {
    /// A world on `scene`, with an optional library (checked against the scene).
    pub fn new(
        scene: Scene,
        library: Option<Library>,
        settings: WorldSettings,
    ) -> Result<Self, ViewerError> {
        check_positive("h", settings.h)?;
        check_positive("sigma", settings.sigma)?;
        check_speed(settings.speed)?;
        crate::mpc::check_count(
            "mpc_horizon",
            settings.mpc_horizon,
            crate::mpc::HORIZON_LIMIT,
        )?;
        crate::mpc::check_count("mpc_passes", settings.mpc_passes, crate::mpc::PASSES_LIMIT)?;
        if settings.x0.len() != scene.n_state() || !settings.x0.iter().all(|e| e.is_finite()) {
            return Err(ViewerError::Message(format!(
                "x0 must have {} finite entries",
                scene.n_state()
            )));
        }
        let library = match library {
            Some(lib) => {
                lib.check_scene(&scene)?;
                let policy = lib.policy()?.with_time_step(settings.h)?;
                Some((lib, policy))
            }
            None => None,
        };
        if settings.policy == PolicyKind::Library && library.is_none() {
            return Err(ViewerError::Message(
                "the library policy needs a library".into(),
            ));
        }
        let task = &settings.task;
        task.check_scene(&scene)?;
        let watched = Watched::of(&scene, task)?;
        let sim = Self::simulator(&scene, settings.world, settings.sigma, settings.h)?;
        let m = scene.n_controls;
        let mut world = World {
            x: settings.x0.clone(),
            u: vec![0.0; m],
            t: 0.0,
            steps: 0,
            policy: settings.policy,
            world: settings.world,
            sigma: settings.sigma,
            speed: settings.speed,
            paused: false,
            drag: None,
            contacts: Vec::new(),
            history: VecDeque::new(),
            control_ms: 0.0,
            perturbations: 0,
            unconverged: 0,
            watched,
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(settings.seed),
            warning: None,
            stalled: 0,
            reseeds: 0,
            mpc: None,
            library,
            sim,
            scene,
            settings,
        };
        if world.policy == PolicyKind::Mpc {
            world.start_mpc()?;
        }
        Ok(world)
    }

    fn simulator(
        scene: &Scene,
        world: WorldKind,
        sigma: f64,
        h: f64,
    ) -> Result<Simulator, ViewerError> {
        Ok(Simulator::new(
            scene.clone(),
            StepSettings {
                model: match world {
                    WorldKind::Smoothed => Complementarity::Logistic { sigma },
                    WorldKind::Hard => Complementarity::Hard,
                },
                h,
                ..StepSettings::default()
            },
        )?)
    }

    /// (Re)start the online optimiser at the current sigma, seeded by the library's policy if any.
    fn start_mpc(&mut self) -> Result<(), ViewerError> {
        let mut mpc = OnlineMpc::new(
            &self.scene,
            &self.settings.task,
            MpcSettings {
                sigma: self.sigma,
                h: self.settings.h,
                horizon: self.settings.mpc_horizon,
                passes: self.settings.mpc_passes,
            },
        )?;
        if let Some((_, policy)) = &self.library {
            // A policy that cannot be rolled out from here leaves the plan at rest.
            if mpc.seed_from_policy(policy, &self.x).is_err() {
                mpc.clear();
            }
        }
        // The first solve's passes spread over the next control steps (a few more passes per step until it
        // converges), then the usual passes per step: starting never stalls the world's clock, however
        // often the page switches the policy, sigma or resets.
        mpc.warm_up(MPC_FIRST_PASSES);
        self.mpc = Some(mpc);
        Ok(())
    }

    /// The first message a client gets.
    pub fn hello(&self) -> ServerMessage {
        ServerMessage::Hello {
            bodies: self
                .scene
                .bodies
                .iter()
                .enumerate()
                .map(|(i, b)| BodyShape {
                    name: b.name.clone(),
                    semi_axes: [b.shape.a(), b.shape.b()],
                    actuated: self.scene.actuated(i),
                })
                .collect(),
            h: self.settings.h,
            library: self.library.is_some(),
            controllers: self.library.as_ref().map_or(0, |(l, _)| l.entries.len()),
            title: format!("task {}", self.settings.task.name),
            planes: self
                .scene
                .planes
                .iter()
                .map(|p| PlaneShape {
                    name: p.name.clone(),
                    point: p.shape.point(),
                    normal: p.shape.normal(),
                })
                .collect(),
            fixed: self
                .scene
                .fixed
                .iter()
                .map(|f| FixedShape {
                    name: f.name.clone(),
                    semi_axes: [f.shape.a(), f.shape.b()],
                    centre: [f.pose[0], f.pose[1]],
                    angle: f.pose[2],
                })
                .collect(),
            window: window(&self.scene, &self.settings.x0),
            watched: WatchedView {
                name: self.watched.name.clone(),
                index: self.watched.index,
                target: self.watched.target,
                unit: match self.scene.coordinates[self.watched.index % self.scene.n_dof()].kind {
                    CoordinateKind::Angle => "rad",
                    CoordinateKind::Slide { .. } => "units",
                }
                .into(),
            },
            targets: target_poses(&self.scene, &self.settings.task),
        }
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The state.
    pub fn state(&self) -> &[f64] {
        &self.x
    }

    /// Whether time stands still.
    pub fn paused(&self) -> bool {
        self.paused
    }

    /// Simulated seconds per real second.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The time step.
    pub fn h(&self) -> f64 {
        self.settings.h
    }

    /// Apply a message from the page; `Err` (and nothing changed) for a value out of range.
    pub fn apply(&mut self, message: ClientMessage) -> Result<(), ViewerError> {
        match message {
            ClientMessage::Grab { body, point } => {
                check_point(point)?;
                if body >= self.scene.bodies.len() {
                    return Err(ViewerError::Message(format!(
                        "there is no body {body} (the scene has {})",
                        self.scene.bodies.len()
                    )));
                }
                let kin = Kinematics::new(&self.scene, &self.x[..self.scene.n_dof()]);
                let (phi, hinge) = (kin.phi[body], kin.hinge[body]);
                let rel = [point[0] - hinge[0], point[1] - hinge[1]];
                let (s, c) = phi.sin_cos();
                self.drag = Some(Drag {
                    body,
                    local: [c * rel[0] + s * rel[1], -s * rel[0] + c * rel[1]],
                    target: point,
                });
                self.perturbations += 1;
            }
            ClientMessage::Drag { target } => {
                check_point(target)?;
                if let Some(d) = &mut self.drag {
                    d.target = target;
                }
            }
            ClientMessage::Release => self.drag = None,
            ClientMessage::Policy { policy } => {
                if policy == PolicyKind::Library && self.library.is_none() {
                    return Err(ViewerError::Message(
                        "no library is loaded (start the viewer with --library FILE)".into(),
                    ));
                }
                if policy == PolicyKind::Mpc && self.policy != PolicyKind::Mpc {
                    self.start_mpc()?;
                }
                self.policy = policy;
            }
            ClientMessage::World { world } => {
                self.sim = Self::simulator(&self.scene, world, self.sigma, self.settings.h)?;
                self.world = world;
            }
            ClientMessage::Sigma { sigma } => {
                if !(1e-3..=10.0).contains(&sigma) {
                    return Err(ViewerError::Setting {
                        name: "sigma",
                        value: sigma,
                        expected: "between 0.001 and 10",
                    });
                }
                // The scene's own bound (Scene::largest_noise_scale) may be lower than the field's.
                self.scene
                    .check_noise_scale(sigma)
                    .map_err(|e| ViewerError::Message(e.to_string()))?;
                self.sim = Self::simulator(&self.scene, self.world, sigma, self.settings.h)?;
                self.sigma = sigma;
                if self.policy == PolicyKind::Mpc {
                    self.start_mpc()?;
                } else {
                    self.mpc = None;
                }
            }
            ClientMessage::Speed { speed } => {
                check_speed(speed)?;
                self.speed = speed;
            }
            ClientMessage::Pause { paused } => self.paused = paused,
            ClientMessage::Reset => {
                self.x = self.settings.x0.clone();
                self.u.iter_mut().for_each(|e| *e = 0.0);
                self.t = 0.0;
                self.steps = 0;
                self.drag = None;
                self.history.clear();
                self.contacts.clear();
                self.perturbations = 0;
                self.reseeds = 0;
                self.stalled = 0;
                self.unconverged = 0;
                self.sim.reset_warm_start();
                if self.policy == PolicyKind::Mpc {
                    self.start_mpc()?;
                }
            }
            ClientMessage::Kick { std } => {
                if !(std.is_finite() && (0.0..=50.0).contains(&std)) {
                    return Err(ViewerError::Setting {
                        name: "std",
                        value: std,
                        expected: "between 0 and 50",
                    });
                }
                let normal =
                    Normal::new(0.0, std).map_err(|e| ViewerError::Message(e.to_string()))?;
                let n = self.scene.n_dof();
                for v in &mut self.x[n..] {
                    *v += normal.sample(&mut self.rng);
                }
                self.perturbations += 1;
            }
        }
        Ok(())
    }

    /// The drag spring's generalised forces at the current state, and its end points.
    fn spring(&self) -> Option<(Vec<f64>, SpringView)> {
        let d = self.drag?;
        let n = self.scene.n_dof();
        let kin = Kinematics::new(&self.scene, &self.x[..n]);
        let (phi, hinge) = (kin.phi[d.body], kin.hinge[d.body]);
        let (s, c) = phi.sin_cos();
        let p = [
            hinge[0] + c * d.local[0] - s * d.local[1],
            hinge[1] + s * d.local[0] + c * d.local[1],
        ];
        let velocity = kin.point_velocity(&self.scene, d.body, p, &self.x[n..]);
        let mut force = [
            SPRING_STIFFNESS * (d.target[0] - p[0]) - SPRING_DAMPING * velocity[0],
            SPRING_STIFFNESS * (d.target[1] - p[1]) - SPRING_DAMPING * velocity[1],
        ];
        let size = force[0].hypot(force[1]);
        if size > SPRING_MAX_FORCE {
            force = [
                force[0] * SPRING_MAX_FORCE / size,
                force[1] * SPRING_MAX_FORCE / size,
            ];
        }
        Some((
            kin.point_force(&self.scene, d.body, p, force),
            SpringView {
                body: d.body,
                from: p,
                to: d.target,
            },
        ))
    }

    /// The policy's control at the current state (zero where it has nothing to say).
    fn control(&mut self) -> Result<Vec<f64>, ViewerError> {
        let m = self.scene.n_controls;
        let start = std::time::Instant::now();
        let u = match self.policy {
            PolicyKind::Off => vec![0.0; m],
            PolicyKind::Library => {
                let mut u = vec![0.0; m];
                if let Some((_, policy)) = &self.library {
                    policy.control(&self.x, &mut u)?;
                }
                u
            }
            PolicyKind::Mpc => {
                if self.mpc.is_none() {
                    self.start_mpc()?;
                }
                let mpc = self.mpc.as_mut().expect("started above");
                let u = mpc.control(&self.x)?;
                // A plan that has not expected to turn the ellipse for a while is stuck in a local
                // minimum (the finger pressing on it, or resting beside it): start the next plan from the
                // library's policy, which knows a flick from here (a cheap rollout, within the step's
                // budget). A task without progress to make (a target to hold) never stalls.
                match mpc.planned_turn() {
                    Some(turn) if turn < STALL_TURN => self.stalled += 1,
                    _ => self.stalled = 0,
                }
                if self.stalled >= STALL_STEPS
                    && let Some((_, policy)) = &self.library
                {
                    if mpc.seed_from_policy(policy, &self.x).is_err() {
                        mpc.clear();
                    }
                    self.stalled = 0;
                    self.reseeds += 1;
                }
                u
            }
        };
        self.control_ms = start.elapsed().as_secs_f64() * 1e3;
        Ok(u)
    }

    /// Advance one time step. A controller that fails (its optimiser finds nothing from a violent state,
    /// say) applies no torque this step and says why in the frame's warning; the world goes on. A step
    /// the simulator cannot take, or a state that becomes non-finite, resets the world, with a warning.
    /// `Err` only if even the reset fails.
    pub fn advance(&mut self) -> Result<(), ViewerError> {
        let m = self.scene.n_controls;
        let control = self.control();
        let (u, failure) = match control {
            Ok(u) if u.iter().all(|e| e.is_finite()) => (u, None),
            Ok(_) => (
                vec![0.0; m],
                Some(ViewerError::Message(
                    "the policy gave a non-finite torque".into(),
                )),
            ),
            Err(e) => (vec![0.0; m], Some(e)),
        };
        // The spring the user pulls with is an input of the step's data, held over the step.
        let applied = match self.spring() {
            Some((forces, _)) => self.sim.data_mut().set_forces(&forces),
            None => {
                self.sim.data_mut().clear_forces();
                Ok(())
            }
        };
        let step = match applied.and_then(|()| self.sim.step(&self.x, &u)) {
            Ok(step) => step,
            // The contact solve itself failed (a violent state the hard model has no answer for):
            // start over rather than stop the world.
            Err(e) => {
                tracing::warn!(error = %e, "the step failed; the world was reset");
                self.apply(ClientMessage::Reset)?;
                self.warning = Some(format!("the step failed ({e}); the world was reset"));
                return Ok(());
            }
        };
        if step.info.status != ncp::Status::Converged {
            self.unconverged += 1;
        }
        if !step.x_next.iter().all(|e| e.is_finite()) {
            self.apply(ClientMessage::Reset)?;
            self.warning = Some("the world's state became non-finite; it was reset".into());
            return Ok(());
        }
        self.contacts = step
            .contacts
            .iter()
            .zip(&step.impulses)
            .map(|(c, i)| ContactView {
                point: c.point_b,
                normal: c.normal,
                distance: c.distance,
                impulse: i.on_b,
            })
            .collect();
        self.x = step.x_next;
        self.u = u;
        self.t += self.settings.h;
        self.steps += 1;
        self.history
            .push_back((self.t, self.x[self.watched.index], self.control_ms));
        while self
            .history
            .front()
            .is_some_and(|(t, _, _)| *t < self.t - WINDOW - 1e-9)
        {
            self.history.pop_front();
        }
        self.warning = failure.map(|e| {
            tracing::warn!(error = %e, "the controller failed; no torque this step");
            format!("controller: {e}")
        });
        Ok(())
    }

    /// Why the last step ran without its controller, if it did.
    pub fn warning(&self) -> Option<&str> {
        self.warning.as_deref()
    }

    /// The current frame.
    pub fn frame(&self) -> Frame {
        let n = self.scene.n_dof();
        let kin = Kinematics::new(&self.scene, &self.x[..n]);
        let spin_rate = match (self.history.front(), self.history.back()) {
            (Some(a), Some(b)) if b.0 > a.0 => (b.1 - a.1) / (b.0 - a.0),
            _ => 0.0,
        };
        Frame {
            t: self.t,
            step: self.steps,
            x: self.x.clone(),
            u: self.u.clone(),
            bodies: (0..self.scene.bodies.len())
                .map(|i| BodyPose {
                    centre: kin.centre[i],
                    angle: kin.phi[i],
                    hinge: kin.hinge[i],
                })
                .collect(),
            contacts: self.contacts.clone(),
            spring: self.spring().map(|(_, s)| s),
            spin_rate,
            watched: self.x[self.watched.index],
            policy: self.policy,
            world: self.world,
            sigma: self.sigma,
            speed: self.speed,
            paused: self.paused,
            control_ms: self.control_ms,
            control_ms_max: self.history.iter().fold(0.0, |m, e| m.max(e.2)),
            perturbations: self.perturbations,
            unconverged: self.unconverged,
            warning: self.warning.clone(),
            mpc_reseeds: self.reseeds,
            mpc_passes: self.mpc.as_ref().map_or(0, OnlineMpc::passes_run),
        }
    }
}
