//! Optimal control tasks from scene files and their controller libraries (paper sections IV-C and V): tasks
//! as data ([`ProblemFile`], [`Task`], [`TaskCost`]; the paper's flicking finger is the built-in
//! `scenes/finger.toml`'s `spin`, [`ProblemFile::builtin`]), the simulator behind [`ddp::Dynamics`]
//! ([`SceneDynamics`]); receding-horizon library building ([`Library::build`]); the global nearest-neighbour policy of eq. (20)
//! ([`Policy`]); library files with a versioned, checksummed header ([`Library::save`],
//! [`Library::load`]). The only library crate that touches the disk.

mod anneal;
mod build;
mod entry;
mod error;
mod evaluate;
mod file;
mod policy;
mod problem;
mod reach;
mod task;

pub use anneal::{AnnealStep, anneal};
pub use build::{
    Entries, Exploration, GROWTH_BRANCHES, GROWTH_SECONDS, GROWTH_SHARPENING, HORIZON_DOUBLINGS,
    LONGEST_HORIZON, LibrarySettings, MAX_NEIGHBOURS, Progress, STALL_ADVANCE, STALL_WINDOW,
    WORLD_TIME_STEP, build_entries,
};
pub use entry::{ContactModel, Entry, LocalValue};
pub use error::LibraryError;
pub use evaluate::{
    CONTACT_IMPULSE, ContactEvents, CoordinateRate, Evaluation, EvaluationSettings, TargetDistance,
    TaskMeasures, Verdict, evaluate, evaluate_in,
};
pub use file::{Library, MAGIC, VERSION, write_atomically};
pub use policy::Policy;
pub use problem::{
    BUILTIN_SCENE_FILE, DEFAULT_SETTLE, ProblemFile, START_TOLERANCE, Success, SuccessSpec, Task,
    TaskCost, TaskSpec, Term, TermSpec,
};
pub use reach::{
    CONTINUATION_DOUBLINGS, ContactProblem, ContactSearch, Continuation, REACH_PULL,
    REACH_PULL_PASSES, Reach, ReachCost, contact_felt, needed_pairs, noise_scale,
};
pub use task::{SceneDynamics, TaskError};

/// `Err` unless `v` has `len` finite entries.
pub(crate) fn check(what: &'static str, v: &[f64], len: usize) -> Result<(), LibraryError> {
    if v.len() != len {
        return Err(LibraryError::Input {
            what,
            problem: format!("has {} entries, expected {len}", v.len()),
        });
    }
    if let Some(i) = v.iter().position(|e| !e.is_finite()) {
        return Err(LibraryError::Input {
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
