//! A contact out of reach (issue 28): the smoothed contact's action at a distance fades within a few
//! sigma (and the hard contact has none), so a solve whose start is farther from the contact the task
//! needs has a zero gradient and "converges" with nothing moved. [`contact_felt`] tells that case apart;
//! [`ContactProblem::feel_contact`] mends it, first by pulling each needed pair together ([`ContactProblem::reach_for_contact`],
//! [`ReachCost`]: the task's cost plus a penalty on the pair's distance, then the task's own cost from
//! there), then by continuation in the noise scale ([`ContactProblem::continue_in_noise`], the paper's section VI
//! scaffolding: sigma doubled, each solve warm-started from the last, until a solve feels the contact
//! and uses it, then halved back).

use crate::error::TaskError;
use crate::problem::TaskCost;
use crate::progress::Progress;
use crate::scene_dynamics::SceneDynamics;
use ddp::{Ddp, DdpSettings, Solution};
use dynamics::{
    Complementarity, ConstraintRow, Constraints, Kinematics, Scene, Side, Simulator, StepSettings,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// A progress task's plan stalls when it advances its rewarded coordinate less than this the rewarded way
/// over its horizon ([`plan_stalls`]); growth's closed loops use the same amount over their window.
pub const STALL_ADVANCE: f64 = 0.3;
/// Smooth random warm starts a stalled progress solve is tried from ([`ContactProblem::explore`]).
pub const EXPLORE_STARTS: usize = 12;
/// Their amplitudes (the controls' units), as many starts at each.
pub const EXPLORE_AMPLITUDES: [f64; 3] = [1.0, 3.0, 10.0];
/// The seed the starts are drawn from: one for every caller, so that an explored solve is a function of
/// its task and start (a library's chains, each seeded apart, are the chains built one by one).
const EXPLORE_SEED: u64 = 28;

/// Whether a progress task's plan `sol` advances its rewarded coordinate less than [`STALL_ADVANCE`] the
/// rewarded way over its whole horizon (never for a target task).
pub fn plan_stalls(progress: &Progress, sol: &Solution) -> bool {
    let (Some(forward), Some(first), Some(last)) =
        (progress.forward, sol.states.first(), sol.states.last())
    else {
        return false;
    };
    let c = progress.coordinate;
    forward * (last[c] - first[c]) < STALL_ADVANCE
}

/// Doublings of the noise scale [`ContactProblem::continue_in_noise`] tries at most (up to 64 times the task's).
pub const CONTINUATION_DOUBLINGS: usize = 6;

/// The contact pairs a task needs: each between a body the controls move and a body they do not move
/// but `cost` weighs (the finger and the ellipse, the pusher and the block; not the block on the ground,
/// nor the finger on the ground). `None` when the cost weighs no undriven body: no contact is needed.
pub fn needed_pairs(scene: &Scene, cost: &TaskCost) -> Option<Vec<usize>> {
    let n = scene.n_dof();
    let weighed: Vec<usize> = cost
        .running
        .iter()
        .chain(&cost.final_terms)
        .map(|t| t.index % n)
        .collect();
    let is_weighed = |i: usize| !driven(scene, i) && weighed.iter().any(|&j| scene.moves(j, i));
    if !(0..scene.bodies.len()).any(is_weighed) {
        return None;
    }
    let body = |side: Side| match side {
        Side::Body(i) => Some(i),
        _ => None,
    };
    Some(
        scene
            .contacts
            .iter()
            .enumerate()
            .filter(|(_, c)| match (body(c.a), body(c.b)) {
                (Some(a), Some(b)) => {
                    (driven(scene, a) && is_weighed(b)) || (driven(scene, b) && is_weighed(a))
                }
                _ => false,
            })
            .map(|(p, _)| p)
            .collect(),
    )
}

/// Whether the controls move body `i`: an actuated coordinate of its own joint or of an ancestor's.
fn driven(scene: &Scene, i: usize) -> bool {
    (0..scene.n_dof()).any(|j| scene.coordinates[j].actuator.is_some() && scene.moves(j, i))
}

/// Whether the rollout of `controls` from `x0` in `sim` feels the contact `cost` needs: the total normal
/// impulse of the pairs between a body the controls move and a body they do not move but the cost weighs
/// (the finger and the ellipse, the pusher and the block; not the block resting on the ground, nor the
/// finger on it), against 1e-6 times the impulse the scene's weight delivers over the horizon. A cost
/// that weighs only driven bodies needs no contact: always felt.
pub fn contact_felt(
    sim: &mut Simulator,
    cost: &TaskCost,
    x0: &[f64],
    controls: &[Vec<f64>],
) -> Result<bool, TaskError> {
    let scene = sim.scene().clone();
    let Some(needed) = needed_pairs(&scene, cost) else {
        return Ok(true);
    };
    let pairs: Vec<bool> = (0..scene.contacts.len())
        .map(|p| needed.contains(&p))
        .collect();
    let g = scene.gravity[0].hypot(scene.gravity[1]);
    let weight: f64 = scene.bodies.iter().map(|b| b.mass).sum::<f64>() * g;
    let scale = (weight * sim.settings().h * controls.len() as f64).max(1.0);
    let mut x = x0.to_vec();
    let mut total = 0.0;
    for u in controls {
        let s = sim.step(&x, u)?;
        total += s
            .impulses
            .iter()
            .zip(&pairs)
            .filter(|(_, d)| **d)
            .map(|(i, _)| i.normal.abs())
            .sum::<f64>();
        x = s.x_next;
    }
    Ok(total > 1e-6 * scale)
}

/// Whether a solve of cost `cost` improves on one of cost `untouched` by a percent of its size: what a
/// solve that reached the contact must do to replace one that felt none.
fn lowers(untouched: f64, cost: f64) -> bool {
    untouched - cost > 0.01 * (1.0 + untouched.abs())
}

/// The noise scale of a smoothed model, `None` for the hard one.
pub fn noise_scale(model: Complementarity) -> Option<f64> {
    match model {
        Complementarity::Logistic { sigma } | Complementarity::Normal { sigma } => Some(sigma),
        Complementarity::Hard => None,
    }
}

/// What [`ContactProblem::continue_in_noise`] found.
#[derive(Debug, Clone)]
pub struct Continuation {
    /// The solution at the task's noise scale: the continued one if it is kept, else the start.
    pub solution: Solution,
    /// The noise scale at which a solve first felt the contact and lowered the cost, if one did.
    pub felt_at: Option<f64>,
    /// Whether the continued solution replaced the start: it felt the contact, still feels it at the
    /// task's noise scale, and costs less there than the start.
    pub kept: bool,
    /// Each stage: `(sigma, passes, converged, cost)`.
    pub stages: Vec<(f64, usize, bool, f64)>,
}

/// A task's cost plus a pull of one needed contact pair together: `weight / 2 max(d, 0)^2` on the pair's
/// signed distance `d(q)` at every step and at the end (Gauss-Newton curvature `weight J^T J`, `J` its
/// normal Jacobian). The scaffold of [`ContactProblem::reach_for_contact`]: it gives a solve from a state where the
/// contact is out of reach the gradient the task's cost lacks there.
#[derive(Debug, Clone)]
pub struct ReachCost<'a> {
    task: &'a TaskCost,
    scene: &'a Scene,
    /// The pair's two friction-cone rows (their Jacobians average to the normal one).
    edges: [usize; 2],
    weight: f64,
}

impl<'a> ReachCost<'a> {
    /// The pull of contact pair `pair` of `scene` with `weight`, added to `task`.
    pub fn new(
        task: &'a TaskCost,
        scene: &'a Scene,
        pair: usize,
        weight: f64,
    ) -> Result<Self, TaskError> {
        let row = |positive: bool| {
            scene
                .rows()
                .iter()
                .position(|r| *r == ConstraintRow::FrictionEdge { pair, positive })
                .ok_or_else(|| TaskError::Invalid(format!("the scene has no contact pair {pair}")))
        };
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(TaskError::Invalid(format!(
                "a reaching weight must be finite and non-negative, not {weight}"
            )));
        }
        Ok(ReachCost {
            task,
            scene,
            edges: [row(true)?, row(false)?],
            weight,
        })
    }

    /// The pair's distance at `x` and its gradient with respect to `q`, while apart (`None` in touch, or
    /// where the geometry has no answer).
    pub fn gap(&self, x: &[f64]) -> Option<(f64, Vec<f64>)> {
        let n = self.scene.n_dof();
        let q = &x[..n];
        let c = Constraints::new(self.scene, &Kinematics::new(self.scene, q), q).ok()?;
        let d = c.d[self.edges[0]];
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        let [a, b] = self.edges;
        let grad = (0..n)
            .map(|j| 0.5 * (c.jacobian[a * n + j] + c.jacobian[b * n + j]))
            .collect();
        Some((d, grad))
    }

    fn pull(&self, x: &[f64]) -> f64 {
        self.gap(x).map_or(0.0, |(d, _)| 0.5 * self.weight * d * d)
    }

    fn pull_derivatives(&self, x: &[f64], lx: &mut [f64], lxx: &mut [f64]) {
        let Some((d, g)) = self.gap(x) else {
            return;
        };
        let ns = x.len();
        for (a, &ga) in g.iter().enumerate() {
            lx[a] += self.weight * d * ga;
            for (b, &gb) in g.iter().enumerate() {
                lxx[a * ns + b] += self.weight * ga * gb;
            }
        }
    }
}

impl ddp::Cost for ReachCost<'_> {
    fn running(&self, i: usize, x: &[f64], u: &[f64]) -> f64 {
        self.task.running(i, x, u) + self.pull(x)
    }

    fn terminal(&self, x: &[f64]) -> f64 {
        self.task.terminal(x) + self.pull(x)
    }

    fn running_derivatives(&self, i: usize, x: &[f64], u: &[f64], out: &mut ddp::CostDerivatives) {
        self.task.running_derivatives(i, x, u, out);
        self.pull_derivatives(x, &mut out.lx, &mut out.lxx);
    }

    fn terminal_derivatives(&self, x: &[f64], lx: &mut [f64], lxx: &mut [f64]) {
        self.task.terminal_derivatives(x, lx, lxx);
        self.pull_derivatives(x, lx, lxx);
    }
}

/// What [`ContactProblem::reach_for_contact`] found.
#[derive(Debug, Clone)]
pub struct Reach {
    /// The task's solution: the reached one if one is kept, else the start.
    pub solution: Solution,
    /// The pair whose pull led to the kept solution, if one did.
    pub pair: Option<usize>,
    /// Each pair tried, in order.
    pub tries: Vec<Pull>,
}

/// One pair's pull in [`ContactProblem::reach_for_contact`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pull {
    /// The contact pair pulled together.
    pub pair: usize,
    /// The pulled solve's cost (the task's plus the pull).
    pub cost: f64,
    /// The pulled solve's passes (at most [`REACH_PULL_PASSES`]).
    pub passes: usize,
    /// The cost of the task's own solve from the pulled one; none where the pulled solve felt no contact.
    pub task_cost: Option<f64>,
    /// Whether that task solve feels the contact and costs a percent less than the start.
    pub felt: bool,
}

/// A contact too far to reach from a start ([`ContactProblem::out_of_reach`]): over the start's rollout,
/// which touches nothing the controls move, the bodies they do not move keep farther from every driven
/// body than twice that body's [workspace](dynamics::Scene::workspace) radius ([`OUT_OF_REACH_SLACK`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutOfReach {
    /// The contact pair that came nearest.
    pub pair: usize,
    /// By how much it stayed beyond the margin at its nearest.
    pub clearance: f64,
}

/// The margin of [`ContactProblem::out_of_reach`] beyond the driven body's workspace, as a fraction of
/// its radius. No placement of the joints reaches past the workspace, but a step's contact rows are
/// linear in the velocities, so a link turning fast can meet a body beyond it within one step:
/// `sqrt(1 + (omega h)^2)` times its reach away, twice at `omega h = 1.7` (35 rad/s at h = 0.05). With a
/// quarter of the radius (1.25 times the reach), one search in 72 the margin skipped in a build of
/// roll_block.toml would have felt the contact (issue 28); with the whole radius none in that build or
/// in a build of pushing.toml did (one of the zoo's 32 libraries changed, roll_block's seed 4, with the
/// same verdicts). The smoothed contact's action at a distance adds `40 h sigma` (its
/// force has fallen by `e^-40` there). A heuristic, not a proof: controls that spin a link faster still
/// could make such a contact.
pub const OUT_OF_REACH_SLACK: f64 = 1.0;

/// Passes at most of [`ContactProblem::reach_for_contact`]'s pulled solve: it only has to bring the pair together.
pub const REACH_PULL_PASSES: usize = 40;

/// The pulled solve's stopping tolerance on the relative cost change (`DdpSettings::tol_cost`, or the
/// optimiser's own where that is looser). The pull is a scaffold for the task's solve, a sum of squared
/// distances, and is solved by Gauss-Newton: full DDP's second-order terms, weighted by the pull's large
/// value gradient, are indefinite, and in pushing.toml's seed-4 build 70 of its 136 pulls ran out their
/// 40 passes under regularisation 1e4 to 1e7, crawling (2 felt contact; 14.6 s of a 55.6 s build).
/// Gauss-Newton's regularisation falls to zero in two passes, and its pulls bring the pair together
/// where full DDP's did not (the door of `optimize_tells_a_contact_that_does_not_pay_from_one_out_of_reach`:
/// a pulled cost of 48 against 270), but take the whole budget at the library's tolerance 1e-5 (36 s of
/// pulls in that build); at 1e-3 they take 17 passes on average (13.7 s), 6 of 145 feeling contact
/// (issue 28). Full DDP at 1e-3 stops after one crawling pass (a spurious convergence), so both go
/// together.
pub const REACH_PULL_TOLERANCE: f64 = 1e-3;

/// How strongly [`ContactProblem::reach_for_contact`] pulls, relative to the task: the pull at the start, summed over
/// the horizon, is this many times the start's cost (plus one).
pub const REACH_PULL: f64 = 10.0;

/// What [`ContactProblem::explore`] did for a solve.
#[derive(Debug, Clone)]
pub struct Explored {
    /// The solve kept: the best explored, or the start.
    pub solution: Solution,
    /// How many starts were solved (0: the start did not stall).
    pub tried: usize,
    /// Whether an explored solve replaced the start.
    pub kept: bool,
}

/// How much cheaper, relative to the start's cost (at least 1 in magnitude), a solve continued under the
/// other regularisation must be to replace it ([`ContactProblem::other_regularisation`]): a continuation
/// that only moves the cost at rounding level keeps the start.
pub const REGULARISATION_MARGIN: f64 = 1e-6;

/// What [`ContactProblem::other_regularisation`] did for a solve.
#[derive(Debug, Clone)]
pub struct OtherRegularisation {
    /// The solve kept: the other regularisation's, or the start.
    pub solution: Solution,
    /// The regularisation the other solve ran under (`State` when it was not tried).
    pub regularisation: ddp::Regularisation,
    /// The other solve's cost (the start's when it was not tried).
    pub cost: f64,
    /// Whether the other solve replaced the start.
    pub kept: bool,
    /// Whether it was tried (the start had not converged).
    pub tried: bool,
    /// The other solve's passes (0 when it was not tried).
    pub passes: usize,
}

/// The stages [`ContactProblem::finish`] runs on a solve from the start, in this order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stages {
    /// Search for the contact the task needs where the solve feels none ([`ContactProblem::feel_contact`]).
    pub search: bool,
    /// Solve a progress task's stalled plan again from smooth random starts ([`ContactProblem::explore`]).
    pub explore: bool,
    /// Continue a solve that stopped without converging under the other regularisation
    /// ([`ContactProblem::other_regularisation`]).
    pub other_regularisation: bool,
}

impl Stages {
    /// Every stage: what `optimize`, `train`'s first solve, Python's `optimize` and the examples' solve
    /// from rest run unless told otherwise.
    pub const ALL: Stages = Stages {
        search: true,
        explore: true,
        other_regularisation: true,
    };
    /// None: the solve is only checked for its contact.
    pub const NONE: Stages = Stages {
        search: false,
        explore: false,
        other_regularisation: false,
    };
}

/// What [`ContactProblem::finish`] did to a solve from the start: each stage's record (`None` where the
/// stage was not asked for; each keeps the solution it handed on), and the solution at the end.
#[derive(Debug, Clone)]
pub struct Finished {
    /// The solution after every stage asked for.
    pub solution: Solution,
    /// Whether `solution` feels the contact the task needs ([`contact_felt`]).
    pub felt: bool,
    /// The contact search.
    pub search: Option<ContactSearch>,
    /// The exploration from random starts.
    pub explored: Option<Explored>,
    /// The continuation under the other regularisation.
    pub other: Option<OtherRegularisation>,
}

/// What [`ContactProblem::feel_contact`] did for a solve.
#[derive(Debug, Clone)]
pub struct ContactSearch {
    /// The solution: the start unless a pull or the continuation found one that feels the contact and
    /// costs less.
    pub solution: Solution,
    /// Whether the start felt the contact already (then nothing else was tried).
    pub felt: bool,
    /// The pulls, if the start felt none ([`ContactProblem::reach_for_contact`]).
    pub reach: Option<Reach>,
    /// The continuation in the noise scale, if no pull found the contact and the model is smoothed
    /// ([`ContactProblem::continue_in_noise`]).
    pub continuation: Option<Continuation>,
    /// Where no pull or continuation was tried because the contact is plainly too far
    /// ([`ContactProblem::out_of_reach`]).
    pub out_of_reach: Option<OutOfReach>,
}

impl OtherRegularisation {
    /// `start` as it is, not continued.
    pub fn untried(start: Solution) -> Self {
        OtherRegularisation {
            cost: start.cost,
            solution: start,
            regularisation: ddp::Regularisation::State,
            kept: false,
            tried: false,
            passes: 0,
        }
    }
}

impl ContactSearch {
    /// Whether the solution feels the contact: the start did, or a pull or the continuation replaced it.
    pub fn found(&self) -> bool {
        self.felt
            || self.reach.as_ref().is_some_and(|r| r.pair.is_some())
            || self.continuation.as_ref().is_some_and(|c| c.kept)
    }

    /// How the search ended, the first that applies in this order: the one classification `optimize`'s
    /// message and Python's `contact` are written from.
    pub fn outcome(&self) -> ContactOutcome {
        if self.felt {
            return ContactOutcome::Felt;
        }
        if let Some(o) = self.out_of_reach {
            return ContactOutcome::OutOfReach(o);
        }
        let tries = self.reach.as_ref().map_or(&[][..], |r| &r.tries[..]);
        if let Some(p) = self.reach.as_ref().and_then(|r| r.pair) {
            return ContactOutcome::Pulled(p);
        }
        let touched: Vec<usize> = tries
            .iter()
            .filter(|t| t.task_cost.is_some())
            .map(|t| t.pair)
            .collect();
        if !touched.is_empty() {
            return ContactOutcome::TouchedNotKept(touched);
        }
        match &self.continuation {
            Some(Continuation {
                felt_at: Some(top),
                kept: true,
                ..
            }) => ContactOutcome::Continued(*top),
            Some(Continuation {
                felt_at: Some(top), ..
            }) => ContactOutcome::Lost(*top),
            Some(_) => ContactOutcome::NeverFelt,
            None => ContactOutcome::NoContinuation,
        }
    }
}

/// How a [`ContactSearch`] ended ([`ContactSearch::outcome`]).
#[derive(Debug, Clone, PartialEq)]
pub enum ContactOutcome {
    /// The start felt the contact: nothing else was tried.
    Felt,
    /// Too far to search ([`ContactProblem::out_of_reach`]): no pull or continuation was tried.
    OutOfReach(OutOfReach),
    /// The pull of this pair led to the solve kept.
    Pulled(usize),
    /// The pulls of these pairs touched, but the task's own solve from there let go again or cost more
    /// than the start, which is kept: from this start the contact does not pay by the task's cost.
    TouchedNotKept(Vec<usize>),
    /// Continuation in the noise scale felt the contact at this sigma and kept it down to the task's.
    Continued(f64),
    /// Continuation felt the contact at this sigma and lost it (or found no cheaper solve) on the way
    /// back down; the start is kept.
    Lost(f64),
    /// Continuation never felt the contact, up to [`CONTINUATION_DOUBLINGS`] doublings of sigma.
    NeverFelt,
    /// No pull found it, and the model has no noise scale to continue in (the hard model).
    NoContinuation,
}

/// A solve's problem for the contact searches: the optimiser, the scene under a step setting (its
/// model and time step), the task's cost and the start. [`ContactProblem::feel_contact`] checks a solve
/// for the contact the task needs and mends it by [`ContactProblem::reach_for_contact`] and
/// [`ContactProblem::continue_in_noise`].
#[derive(Debug, Clone, Copy)]
pub struct ContactProblem<'a> {
    /// The optimiser of every solve (its pass budget, tolerance and control limits).
    pub ddp: &'a Ddp,
    /// The scene.
    pub scene: &'a Scene,
    /// The step setting the solves run under (the task's model, noise scale and time step).
    pub settings: &'a StepSettings,
    /// The task's cost.
    pub cost: &'a TaskCost,
    /// The start.
    pub x0: &'a [f64],
}

impl ContactProblem<'_> {
    /// `ddp`'s solve of `cost` from the start on a fresh simulator of the scene under `settings`,
    /// warm-started from `controls`: every solve of the searches.
    fn solve<C: ddp::Cost>(
        &self,
        ddp: &Ddp,
        settings: StepSettings,
        cost: &C,
        controls: &[Vec<f64>],
    ) -> Result<Solution, TaskError> {
        let dynamics = SceneDynamics::new(Simulator::new(self.scene.clone(), settings)?);
        ddp.solve(&dynamics, cost, self.x0, controls)
            .map_err(|source| TaskError::Optimiser { solve: 0, source })
    }

    /// Whether the rollout of `controls` from the start, under `settings`, feels the contact the task
    /// needs ([`contact_felt`] on a fresh simulator of the scene).
    fn felt(&self, settings: StepSettings, controls: &[Vec<f64>]) -> Result<bool, TaskError> {
        let mut probe = Simulator::new(self.scene.clone(), settings)?;
        contact_felt(&mut probe, self.cost, self.x0, controls)
    }

    /// A progress task's solve `start` that stalls ([`plan_stalls`]), solved again from [`EXPLORE_STARTS`]
    /// smooth random control sequences (each control a sum of three sines over the horizon at amplitudes
    /// [`EXPLORE_AMPLITUDES`], clamped to `ddp`'s control limits; drawn from one fixed seed): the cheapest
    /// solve that no longer stalls replaces it, if it costs less. A local optimiser only improves the motion
    /// it starts from, and from rest the nearest contact may turn the object the wrong way: a finger
    /// spinning an ellipse of semi-axes 0.9 by 0.35 falls onto its near end and turns it back (-0.52 rad
    /// from zero controls), where striking its far half turns it forward. A start that ends in the same
    /// optimum to rounding, or in another stall, is not taken. `start` itself when it does not stall.
    pub fn explore(&self, start: Solution, progress: &Progress) -> Result<Explored, TaskError> {
        if !plan_stalls(progress, &start) {
            return Ok(Explored {
                solution: start,
                tried: 0,
                kept: false,
            });
        }
        let (n, m) = (start.controls.len(), self.scene.n_controls);
        let limits = self.ddp.settings().control_limits.clone();
        let mut rng = ChaCha8Rng::seed_from_u64(EXPLORE_SEED);
        let (mut best, mut kept, mut tried) = (start, false, 0);
        for &amplitude in &EXPLORE_AMPLITUDES {
            for _ in 0..EXPLORE_STARTS / EXPLORE_AMPLITUDES.len() {
                let mut controls = vec![vec![0.0; m]; n];
                for a in 0..m {
                    for f in 1..=3 {
                        let z: f64 = rng.sample(StandardNormal);
                        let weight = amplitude * z / f as f64;
                        let phase = rng.random_range(0.0..std::f64::consts::TAU);
                        for (i, u) in controls.iter_mut().enumerate() {
                            let angle =
                                std::f64::consts::TAU * f as f64 * i as f64 / n as f64 + phase;
                            u[a] += weight * angle.sin();
                        }
                    }
                    if let Some(l) = &limits {
                        for u in &mut controls {
                            u[a] = u[a].clamp(l.lower[a], l.upper[a]);
                        }
                    }
                }
                let sol = self.solve(self.ddp, *self.settings, self.cost, &controls)?;
                tried += 1;
                if sol.cost < best.cost && !plan_stalls(progress, &sol) {
                    best = sol;
                    kept = true;
                }
            }
        }
        Ok(Explored {
            solution: best,
            tried,
            kept,
        })
    }

    /// A solve `start` that stopped without converging (the pass limit, no descent) continued under the
    /// other place for the regularisation ([`ddp::Regularisation`]: `Q_uu + mu f_u^T f_u` or
    /// `Q_uu + mu I`), warm-started from its own controls, and kept where it costs less (by more than
    /// [`REGULARISATION_MARGIN`]); a converged `start` as it is. Under the state regularisation the
    /// contact's second derivatives can make the first knots' `Q_uu` indefinite pass after pass, so that
    /// `mu` hovers between 1e4 and 1e6 and the passes crawl: a three-link finger turning an ellipse to a
    /// target ends 300 passes at cost 340.7 (all accepted, `mu` raised at knots 0 to 9), where the
    /// control regularisation's `mu I` makes the same knots definite at a small `mu`.
    pub fn other_regularisation(&self, start: Solution) -> Result<OtherRegularisation, TaskError> {
        let regularisation = match self.ddp.settings().regularisation {
            ddp::Regularisation::State => ddp::Regularisation::Control,
            ddp::Regularisation::Control => ddp::Regularisation::State,
        };
        if start.status.converged() {
            return Ok(OtherRegularisation::untried(start));
        }
        let other = Ddp::new(DdpSettings {
            regularisation,
            ..self.ddp.settings().clone()
        })
        .map_err(|source| TaskError::Optimiser { solve: 0, source })?;
        let sol = self.solve(&other, *self.settings, self.cost, &start.controls)?;
        let (cost, passes) = (sol.cost, sol.iterations.len());
        let margin = REGULARISATION_MARGIN * start.cost.abs().max(1.0);
        let kept = cost.is_finite() && cost < start.cost - margin;
        Ok(OtherRegularisation {
            solution: if kept { sol } else { start },
            regularisation,
            cost,
            kept,
            tried: true,
            passes,
        })
    }

    /// A solve from the start `start` finished as every caller finishes one, the `stages` asked for in
    /// order: the contact search ([`ContactProblem::feel_contact`], each continuation stage reported to
    /// `stage`), the exploration of a progress task's stalled plan ([`ContactProblem::explore`], whether or
    /// not the search found its contact: a random swing may touch where the search did not), and the
    /// continuation of an unconverged solve under the other regularisation
    /// ([`ContactProblem::other_regularisation`]). `optimize`, Python's `optimize`, the examples' solve
    /// from rest and a library's first solve all go through it, so that they cannot drift apart.
    pub fn finish(
        &self,
        start: Solution,
        progress: &Progress,
        stages: Stages,
        stage: impl FnMut(f64, &Solution, Option<bool>),
    ) -> Result<Finished, TaskError> {
        let (mut solution, mut felt, mut search) = (start, false, None);
        if stages.search {
            let found = self.feel_contact(solution, stage)?;
            (solution, felt) = (found.solution.clone(), found.found());
            search = Some(found);
        }
        let mut explored = None;
        if stages.explore {
            let e = self.explore(solution, progress)?;
            solution = e.solution.clone();
            explored = Some(e);
        }
        let mut other = None;
        if stages.other_regularisation {
            let o = self.other_regularisation(solution)?;
            solution = o.solution.clone();
            other = Some(o);
        }
        // A kept exploration or continuation is a new solve: check it again (so is a search's, but the
        // search checked its own).
        let replaced =
            explored.as_ref().is_some_and(|e| e.kept) || other.as_ref().is_some_and(|o| o.kept);
        if !stages.search || replaced {
            felt = self.felt(*self.settings, &solution.controls)?;
        }
        Ok(Finished {
            solution,
            felt,
            search,
            explored,
            other,
        })
    }

    /// A solve `start` from `x0` checked for the contact its task needs ([`contact_felt`], under
    /// `settings`), and where none is felt, mended: first by pulling each needed pair together
    /// ([`ContactProblem::reach_for_contact`]), then, if no pull found a cheaper solve that feels it and the model is
    /// smoothed, by continuation in the noise scale ([`ContactProblem::continue_in_noise`], each stage reported to
    /// `stage`). `optimize`, `train`'s first solve and every first solve of a target
    /// task's chain go through it.
    pub fn feel_contact(
        &self,
        start: Solution,
        stage: impl FnMut(f64, &Solution, Option<bool>),
    ) -> Result<ContactSearch, TaskError> {
        if self.felt(*self.settings, &start.controls)? {
            return Ok(ContactSearch {
                solution: start,
                felt: true,
                reach: None,
                continuation: None,
                out_of_reach: None,
            });
        }
        if let Some(apart) = self.out_of_reach(&start) {
            return Ok(ContactSearch {
                solution: start,
                felt: false,
                reach: None,
                continuation: None,
                out_of_reach: Some(apart),
            });
        }
        let reach = self.reach_for_contact(start)?;
        if reach.pair.is_some() || noise_scale(self.settings.model).is_none() {
            return Ok(ContactSearch {
                solution: reach.solution.clone(),
                felt: false,
                reach: Some(reach),
                continuation: None,
                out_of_reach: None,
            });
        }
        let c = self.continue_in_noise(reach.solution.clone(), stage)?;
        Ok(ContactSearch {
            solution: c.solution.clone(),
            felt: false,
            reach: Some(reach),
            continuation: Some(c),
            out_of_reach: None,
        })
    }

    /// Whether the contact the task needs is too far for a search from `start` (which felt none) to be
    /// worth its solves, judged on `start`'s rollout: until a driven body touches an undriven one, the
    /// undriven bodies move as they do there whatever the controls do. Too far when, for every contact
    /// pair between a driven body and an undriven one, the undriven body stays farther from the driven
    /// body's [workspace](dynamics::Scene::workspace) centre than its radius, the undriven body's longest
    /// semi-axis and the margin ([`OUT_OF_REACH_SLACK`]) at every state of the rollout: then the pair that
    /// came nearest and its clearance. `None` (no claim) when a pair's driven body can go anywhere (a
    /// free joint, an unlimited slider), or when the scene has no such pair. In one pushing.toml build
    /// (issue 28) 79 of 206 searches were skipped so, every one of which had found nothing.
    pub fn out_of_reach(&self, start: &Solution) -> Option<OutOfReach> {
        let scene = self.scene;
        let n = scene.n_dof();
        let sigma = noise_scale(self.settings.model).unwrap_or(0.0);
        let kinematics: Vec<Kinematics> = start
            .states
            .iter()
            .map(|x| Kinematics::new(scene, &x[..n]))
            .collect();
        let mut nearest: Option<OutOfReach> = None;
        for (pair, c) in scene.contacts.iter().enumerate() {
            let (Side::Body(a), Side::Body(b)) = (c.a, c.b) else {
                continue;
            };
            let (mover, other) = match (driven(scene, a), driven(scene, b)) {
                (true, false) => (a, b),
                (false, true) => (b, a),
                _ => continue,
            };
            let (centre, radius) = scene.workspace(mover)?;
            let shape = &scene.bodies[other].shape;
            let margin = OUT_OF_REACH_SLACK * radius + 40.0 * self.settings.h * sigma;
            let reach = radius + shape.a().max(shape.b()) + margin;
            let clearance = kinematics
                .iter()
                .map(|k| {
                    let c = k.centre[other];
                    (c[0] - centre[0]).hypot(c[1] - centre[1]) - reach
                })
                .fold(f64::INFINITY, f64::min);
            // Not finite, or within reach at some state: no claim.
            if !(clearance > 0.0 && clearance.is_finite()) {
                return None;
            }
            if nearest.is_none_or(|o| clearance < o.clearance) {
                nearest = Some(OutOfReach { pair, clearance });
            }
        }
        nearest
    }

    /// A solve from `x0` (the start `start`, which felt no contact) that reaches the contact its task needs:
    /// for each needed pair apart at `x0` ([`needed_pairs`]), nearest first, a solve of the task's cost plus
    /// a pull of the pair together ([`ReachCost`], by Gauss-Newton, at most [`REACH_PULL_PASSES`] passes,
    /// stopping at [`REACH_PULL_TOLERANCE`]), warm-started from
    /// `start`, then, if the pulled solve feels the contact, a solve of the task's own cost warm-started
    /// from it. The first task solve that feels the contact under `settings` and costs a percent less than
    /// `start` replaces it; otherwise `start` is kept. A pull that did not bring the pair into contact
    /// hands the task's solve a start no better than `start` (its cost has no gradient towards a contact
    /// the rollout does not feel), so that solve is skipped: in a pushing.toml build (issue 28) 118 of
    /// 121 pulls felt nothing, and their task solves took 7.4 s of 66 s and found nothing. Works for the
    /// hard model as well as the smoothed ones (the pull needs no action at a distance).
    pub fn reach_for_contact(&self, start: Solution) -> Result<Reach, TaskError> {
        let untouched = start.cost;
        let mut tries = Vec::new();
        let steps = start.controls.len() as f64 + 1.0;
        // The needed pairs apart at the start, nearest first.
        let mut apart = Vec::new();
        for pair in needed_pairs(self.scene, self.cost).unwrap_or_default() {
            if let Some((d0, _)) = ReachCost::new(self.cost, self.scene, pair, 1.0)?.gap(self.x0) {
                apart.push((d0, pair));
            }
        }
        apart.sort_by(|a, b| a.0.total_cmp(&b.0));
        let pulling = Ddp::new(DdpSettings {
            max_iterations: self.ddp.settings().max_iterations.min(REACH_PULL_PASSES),
            tol_cost: self.ddp.settings().tol_cost.max(REACH_PULL_TOLERANCE),
            method: ddp::Method::GaussNewton,
            ..self.ddp.settings().clone()
        })
        .map_err(|source| TaskError::Optimiser { solve: 0, source })?;
        for (d0, pair) in apart {
            let weight = REACH_PULL * (1.0 + untouched.abs()) / (0.5 * d0 * d0 * steps);
            let pull = ReachCost::new(self.cost, self.scene, pair, weight)?;
            let pulled = self.solve(&pulling, *self.settings, &pull, &start.controls)?;
            if !self.felt(*self.settings, &pulled.controls)? {
                tries.push(Pull {
                    pair,
                    cost: pulled.cost,
                    passes: pulled.iterations.len(),
                    task_cost: None,
                    felt: false,
                });
                continue;
            }
            let sol = self.solve(self.ddp, *self.settings, self.cost, &pulled.controls)?;
            let felt = self.felt(*self.settings, &sol.controls)? && lowers(untouched, sol.cost);
            tries.push(Pull {
                pair,
                cost: pulled.cost,
                passes: pulled.iterations.len(),
                task_cost: Some(sol.cost),
                felt,
            });
            if felt {
                return Ok(Reach {
                    solution: sol,
                    pair: Some(pair),
                    tries,
                });
            }
        }
        Ok(Reach {
            solution: start,
            pair: None,
            tries,
        })
    }

    /// Continuation in the noise scale from `start`, a solve under `settings` (a smoothed model) whose
    /// trajectory felt no contact: sigma doubled (at most to [`Scene::largest_noise_scale`]), each solve
    /// warm-started from the last, until a solve feels the contact and lowers the cost by a percent of its
    /// size, then halved back to the task's, each stage reported to `stage` as it ends. `Err` for the hard
    /// model, which has no noise scale.
    pub fn continue_in_noise(
        &self,
        start: Solution,
        mut stage: impl FnMut(f64, &Solution, Option<bool>),
    ) -> Result<Continuation, TaskError> {
        let sigma = noise_scale(self.settings.model).ok_or_else(|| {
            TaskError::Invalid("the hard model has no noise scale to continue in".into())
        })?;
        let at = |s: f64| StepSettings {
            model: match self.settings.model {
                Complementarity::Normal { .. } => Complementarity::Normal { sigma: s },
                _ => Complementarity::Logistic { sigma: s },
            },
            ..*self.settings
        };
        let solve =
            |s: f64, controls: &[Vec<f64>]| self.solve(self.ddp, at(s), self.cost, controls);
        let untouched = start.cost;
        let mut stages = Vec::new();
        let mut sol = start.clone();
        let mut felt_at = None;
        let mut s = sigma;
        // Never past the scene's largest noise scale, where the smoothed step stops dissipating.
        let most = self.scene.largest_noise_scale();
        for _ in 0..CONTINUATION_DOUBLINGS {
            if s * 2.0 > most {
                break;
            }
            s *= 2.0;
            sol = solve(s, &sol.controls)?;
            let felt = self.felt(at(s), &sol.controls)? && lowers(untouched, sol.cost);
            stages.push((s, sol.iterations.len(), sol.status.converged(), sol.cost));
            stage(s, &sol, Some(felt));
            if felt {
                felt_at = Some(s);
                break;
            }
        }
        if felt_at.is_some() {
            while s > sigma * 1.000_001 {
                s = (s / 2.0).max(sigma);
                sol = solve(s, &sol.controls)?;
                stages.push((s, sol.iterations.len(), sol.status.converged(), sol.cost));
                stage(s, &sol, None);
            }
        }
        // The continued solve replaces the start only where it ends at the task's noise scale, feeling the
        // contact, at a lower cost: a continuation that never felt it ended at a larger noise scale, and one
        // that lost it on the way down may have ended in a worse local minimum than the start's.
        let kept =
            felt_at.is_some() && sol.cost < untouched && self.felt(at(sigma), &sol.controls)?;
        Ok(Continuation {
            solution: if kept { sol } else { start },
            felt_at,
            kept,
            stages,
        })
    }
}
