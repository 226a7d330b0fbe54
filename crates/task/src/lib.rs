//! The control problem, below the library that stores its controllers: tasks as data ([`ProblemFile`],
//! [`Task`], [`TaskCost`]; the paper's flicking finger is the built-in `scenes/finger.toml`'s `spin`,
//! [`ProblemFile::builtin`]), the step model as the optimiser's dynamics ([`SceneDynamics`]), the
//! coordinate a task progresses along ([`Progress`]), a solve that reaches for a contact out of reach
//! ([`ContactProblem`]) and the paper's noise annealing ([`anneal`]). It knows nothing of libraries or
//! policies.

mod anneal;
mod error;
mod model;
mod problem;
mod progress;
mod reach;
mod scene_dynamics;

pub use anneal::{AnnealStep, anneal};
pub use error::TaskError;
pub use model::ContactModel;
pub use problem::{
    BUILTIN_SCENE_FILE, DEFAULT_SETTLE, ProblemFile, SHORTEST_PERIOD, START_TOLERANCE, Success,
    SuccessSpec, Task, TaskCost, TaskSpec, Term, TermSpec,
};
pub use progress::Progress;
pub use reach::{
    CONTINUATION_DOUBLINGS, ContactOutcome, ContactProblem, ContactSearch, Continuation,
    EXPLORE_AMPLITUDES, EXPLORE_STARTS, Explored, Finished, OUT_OF_REACH_SLACK,
    OtherRegularisation, OutOfReach, Pull, REACH_PULL, REACH_PULL_PASSES, REACH_PULL_TOLERANCE,
    REGULARISATION_MARGIN, Reach, ReachCost, STALL_ADVANCE, Stages, contact_felt, needed_pairs,
    noise_scale, plan_stalls,
};
pub use scene_dynamics::{SceneDynamics, StepError};

/// `Err` unless `v` has `len` finite entries.
pub fn check(what: &'static str, v: &[f64], len: usize) -> Result<(), TaskError> {
    if v.len() != len {
        return Err(TaskError::Input {
            what,
            problem: format!("has {} entries, expected {len}", v.len()),
        });
    }
    if let Some(i) = v.iter().position(|e| !e.is_finite()) {
        return Err(TaskError::Input {
            what,
            problem: format!("entry {i} is {}", v[i]),
        });
    }
    Ok(())
}

/// The README's examples, compiled and run as doctests so that they cannot go stale.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
