//! Controller libraries of a task (paper sections IV-C and V; the task, its cost and the optimiser's
//! dynamics are the [`task`] crate's): receding-horizon library building ([`Library::build`]); the global
//! nearest-neighbour policy of eq. (20) ([`Policy`]); closed-loop evaluation ([`evaluate`]); library files
//! with a versioned, checksummed header ([`Library::save`], [`Library::load`]).

mod build;
mod entry;
mod error;
mod evaluate;
mod file;
mod policy;

pub use build::{
    DWELL_MARGIN, Entries, Exploration, GROWTH_BRANCHES, GROWTH_FIRST_KICK, GROWTH_SECONDS,
    GROWTH_SHARPENING, HORIZON_DOUBLINGS, LONGEST_HORIZON, LibrarySettings, MAX_NEIGHBOURS,
    REACH_SHRINK, STALL_ADVANCE, STALL_WINDOW, VERIFY_BRANCHES, VERIFY_PASSES, VERIFY_PASSES_MOST,
    WORLD_TIME_STEP, build_entries,
};
pub use entry::{Entry, LocalValue};
pub use error::LibraryError;
pub use evaluate::{
    CONTACT_IMPULSE, ContactEvents, CoordinateRate, Evaluation, EvaluationSettings, TargetDistance,
    TaskMeasures, Verdict, evaluate, evaluate_in,
};
pub use file::{Library, MAGIC, VERSION, write_atomically};
pub use policy::{Policy, SATURATION_MARGIN};
/// The control problem the library is built for (tasks, their cost, the optimiser's dynamics): the
/// `task` crate, re-exported so that a library user reaches it through this one.
pub use task;

/// The start a setting's `x0` names: itself, or `task_x0` (the task's) when it is empty (the default of
/// [`LibrarySettings`] and [`EvaluationSettings`]).
pub(crate) fn start<'a>(x0: &'a [f64], task_x0: &'a [f64]) -> &'a [f64] {
    if x0.is_empty() { task_x0 } else { x0 }
}

/// `Err` unless `v` has `len` finite entries ([`task::check`], as the library's own input error).
pub(crate) fn check(what: &'static str, v: &[f64], len: usize) -> Result<(), LibraryError> {
    task::check(what, v, len).map_err(|e| match e {
        task::TaskError::Input { what, problem } => LibraryError::Input { what, problem },
        other => LibraryError::Task(other),
    })
}

/// The README's examples, compiled and run as doctests so that they cannot go stale.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
