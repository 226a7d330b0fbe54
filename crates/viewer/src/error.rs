//! The crate's one error type.

use thiserror::Error;

/// Why the viewer could not start, or refused an input.
#[derive(Debug, Error)]
pub enum ViewerError {
    /// The address could not be bound (a port already in use, say).
    #[error("cannot listen on {addr} (another server on that port? choose one with --port)")]
    Bind {
        /// The address asked for.
        addr: std::net::SocketAddr,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The server stopped with an I/O error.
    #[error("the server stopped: {0}")]
    Serve(#[source] std::io::Error),
    /// The world's thread died (a bug below the viewer): the clients were told, and the server stopped
    /// rather than serve a world that no longer moves.
    #[error("the simulated world stopped on an internal error (a bug; please report it): {0}")]
    WorldDied(String),
    /// A setting or a message's value out of range.
    #[error("{name} = {value:?} is out of range: {expected}")]
    Setting {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// A message that is not one of the protocol's.
    #[error("malformed message: {0}")]
    Message(String),
    /// The library does not fit the scene, or its policy failed.
    #[error(transparent)]
    Library(#[from] library::LibraryError),
    /// The task file or task refused, or its optimisation failed.
    #[error(transparent)]
    Task(#[from] task::TaskError),
    /// The simulator refused a scene, a setting or a state.
    #[error(transparent)]
    Dynamics(#[from] dynamics::DynamicsError),
    /// The online optimiser failed where nothing could be retried.
    #[error(transparent)]
    Optimiser(#[from] ddp::DdpError),
}
