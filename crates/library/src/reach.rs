//! A contact out of reach (issue 28): the smoothed contact's action at a distance fades within a few
//! sigma, so a solve whose start is farther from the contact the task needs has a zero gradient and
//! "converges" with nothing moved. [`contact_felt`] tells that case apart; [`continue_in_noise`] solves
//! it by continuation in the noise scale (the paper's section VI scaffolding): sigma doubled, each solve
//! warm-started from the last, until a solve feels the contact and uses it, then halved back.

use crate::error::LibraryError;
use crate::problem::TaskCost;
use crate::task::SceneDynamics;
use ddp::{Ddp, Solution};
use dynamics::{Complementarity, Scene, Side, Simulator, StepSettings};

/// Doublings of the noise scale [`continue_in_noise`] tries at most (up to 64 times the task's).
pub const CONTINUATION_DOUBLINGS: usize = 6;

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
) -> Result<bool, LibraryError> {
    let scene = sim.scene().clone();
    let n = scene.n_dof();
    let weighed: Vec<usize> = cost
        .running
        .iter()
        .chain(&cost.final_terms)
        .map(|t| t.index % n)
        .collect();
    let is_driven =
        |i: usize| (0..n).any(|j| scene.coordinates[j].actuator.is_some() && scene.moves(j, i));
    let is_weighed = |i: usize| !is_driven(i) && weighed.iter().any(|&j| scene.moves(j, i));
    if !(0..scene.bodies.len()).any(is_weighed) {
        return Ok(true);
    }
    let body = |side: Side| match side {
        Side::Body(i) => Some(i),
        _ => None,
    };
    let pairs: Vec<bool> = scene
        .contacts
        .iter()
        .map(|c| match (body(c.a), body(c.b)) {
            (Some(a), Some(b)) => {
                (is_driven(a) && is_weighed(b)) || (is_driven(b) && is_weighed(a))
            }
            _ => false,
        })
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

/// The noise scale of a smoothed model, `None` for the hard one.
pub fn noise_scale(model: Complementarity) -> Option<f64> {
    match model {
        Complementarity::Logistic { sigma } | Complementarity::Normal { sigma } => Some(sigma),
        Complementarity::Hard => None,
    }
}

/// What [`continue_in_noise`] found.
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

/// Continuation in the noise scale from `start`, a solve under `settings` (a smoothed model) whose
/// trajectory felt no contact: sigma doubled, each solve warm-started from the last, until a solve feels
/// the contact and lowers the cost by a percent of its size, then halved back to the task's, each stage
/// reported to `stage` as it ends. `Err` for the hard model, which has no noise scale.
#[allow(clippy::too_many_arguments)]
pub fn continue_in_noise(
    ddp: &Ddp,
    scene: &Scene,
    settings: &StepSettings,
    cost: &TaskCost,
    x0: &[f64],
    start: Solution,
    mut stage: impl FnMut(f64, &Solution, Option<bool>),
) -> Result<Continuation, LibraryError> {
    let sigma = noise_scale(settings.model).ok_or_else(|| {
        LibraryError::Invalid("the hard model has no noise scale to continue in".into())
    })?;
    let simulator = |s: f64| -> Result<Simulator, LibraryError> {
        let model = match settings.model {
            Complementarity::Normal { .. } => Complementarity::Normal { sigma: s },
            _ => Complementarity::Logistic { sigma: s },
        };
        Ok(Simulator::new(
            scene.clone(),
            StepSettings { model, ..*settings },
        )?)
    };
    let solve = |s: f64, controls: &[Vec<f64>]| -> Result<Solution, LibraryError> {
        ddp.solve(&mut SceneDynamics::new(simulator(s)?), cost, x0, controls)
            .map_err(|source| LibraryError::Optimiser {
                trajectory: 0,
                source,
            })
    };
    let untouched = start.cost;
    let mut stages = Vec::new();
    let mut sol = start.clone();
    let mut felt_at = None;
    let mut s = sigma;
    for _ in 0..CONTINUATION_DOUBLINGS {
        s *= 2.0;
        sol = solve(s, &sol.controls)?;
        let felt = contact_felt(&mut simulator(s)?, cost, x0, &sol.controls)?
            && untouched - sol.cost > 0.01 * (1.0 + untouched.abs());
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
    let kept = felt_at.is_some()
        && sol.cost < untouched
        && contact_felt(&mut simulator(sigma)?, cost, x0, &sol.controls)?;
    Ok(Continuation {
        solution: if kept { sol } else { start },
        felt_at,
        kept,
        stages,
    })
}
