//! The crate's one error type: a task file, a task or its optimisation fails with a reason a user can
//! act on, naming the task and the field at fault where there is one.

use thiserror::Error;

/// Errors of a task: reading its file, checking it against its scene, optimising it.
#[derive(Debug, Error)]
pub enum TaskError {
    /// A state or control of the wrong size or with a non-finite entry.
    #[error("{what}: {problem}")]
    Input {
        /// Which input.
        what: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// The simulator refused the scene, the settings or a step.
    #[error(transparent)]
    Dynamics(#[from] dynamics::DynamicsError),
    /// The optimiser failed where nothing can be retried.
    #[error("solve {solve}: {source}")]
    Optimiser {
        /// Which solve of a sequence (an annealing schedule's; 0 for a single one).
        solve: usize,
        /// The optimiser's error.
        #[source]
        source: ddp::DdpError,
    },
    /// Reading a scene file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The error.
        #[source]
        source: std::io::Error,
    },
    /// A request the task cannot meet (a contact pair the scene does not have, a noise scale the hard
    /// model lacks).
    #[error("{0}")]
    Invalid(String),
    /// A task of a scene file is malformed or does not fit its scene.
    #[error("{}", spec_message(task, field, problem))]
    Spec {
        /// The task's name (empty when the file's task tables as a whole are at fault).
        task: String,
        /// The field at fault (empty when the task as a whole is).
        field: String,
        /// What is wrong.
        problem: String,
    },
    /// A task used with another scene than its own.
    #[error("{0}")]
    SceneMismatch(String),
}

fn spec_message(task: &str, field: &str, problem: &str) -> String {
    match (task.is_empty(), field.is_empty()) {
        (true, true) => format!("tasks: {problem}"),
        (true, false) => format!("tasks, {field}: {problem}"),
        (false, true) => format!("task {task}: {problem}"),
        (false, false) => format!("task {task}, {field}: {problem}"),
    }
}
