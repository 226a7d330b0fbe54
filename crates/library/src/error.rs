//! The crate's one error type. Building, loading and using a library fail with a reason a user can act on;
//! a file that is truncated, corrupt, foreign or built for another scene is refused whole.

use thiserror::Error;

/// Errors of a library: building it, its files, its policy and their use.
#[derive(Debug, Error)]
pub enum LibraryError {
    /// A setting out of its range.
    #[error("setting {name} = {} is out of range: {expected}", dynamics::Scale(*value))]
    Setting {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// A state or control of the wrong size or with a non-finite entry.
    #[error("{what}: {problem}")]
    Input {
        /// Which input.
        what: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// The simulator refused the scene or the settings.
    #[error(transparent)]
    Dynamics(#[from] dynamics::DynamicsError),
    /// Every solve of a build stopped before its first pass (a cost whose curvature no regularisation
    /// makes definite, a scale that overflows): the library would hold its starting controls.
    #[error(
        "none of the {trajectories} trajectories' solves took a single pass (the optimiser stopped at \
         once, e.g. on a Q_uu no regularisation makes positive definite: look at the task's weights \
         with `cargo xtask optimize`); no library of unoptimised controls is built"
    )]
    NothingOptimised {
        /// Trajectories solved.
        trajectories: usize,
    },
    /// The optimiser failed where nothing can be retried.
    #[error("trajectory {trajectory}: {source}")]
    Optimiser {
        /// The trajectory of the library being built.
        trajectory: usize,
        /// The optimiser's error.
        #[source]
        source: ddp::DdpError,
    },
    /// Reading or writing a file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The error.
        #[source]
        source: std::io::Error,
    },
    /// The file does not start with the library's magic bytes.
    #[error("not a controller library (no SLCPLIB header)")]
    NotALibrary,
    /// A library file of another format version.
    #[error("library format version {found}, this build reads version {expected}")]
    Version {
        /// The file's version.
        found: u32,
        /// The version this build reads.
        expected: u32,
    },
    /// The file ends before its payload does.
    #[error("truncated library file: {found} bytes of payload, the header announces {expected}")]
    Truncated {
        /// Announced payload length.
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// The payload's checksum does not match the header's.
    #[error("corrupt library file: checksum {found:08x}, the header says {expected:08x}")]
    Corrupt {
        /// Checksum in the header.
        expected: u32,
        /// Checksum of the payload.
        found: u32,
    },
    /// The payload does not decode, or decodes to something inconsistent.
    #[error("invalid library: {0}")]
    Invalid(String),
    /// A closed loop of the library's policy left the finite states.
    #[error("invalid library: the closed loop produced a non-finite state at step {step}")]
    Diverged {
        /// The step that produced it.
        step: usize,
    },
    /// The task refused (a malformed task, one that cannot have a library) or its optimisation failed.
    #[error(transparent)]
    Task(#[from] task::TaskError),
    /// The library was built for another scene than the one it is used with.
    #[error("the library was built for another scene ({0})")]
    SceneMismatch(String),
}
