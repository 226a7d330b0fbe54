//! The interactive viewer (after the paper's real-time front-end): the flicking finger simulated in a
//! local web server at real time, drawn in the browser, under the library's policy or an online iLQG
//! controller that re-plans every control step; the user drags bodies with the mouse (a spring from the
//! grabbed point to the cursor), kicks, pauses, changes the world's contact model and sigma.
//!
//! - [`World`]: the simulation behind the page, no networking (the tests drive it directly).
//! - [`OnlineMpc`]: the online optimiser.
//! - [`Viewer`]: the axum server, the page and a WebSocket per client ([`protocol`] documents the
//!   messages). Everything it serves is compiled in: it works offline and over an SSH port forward.

mod error;
mod mpc;
pub mod protocol;
mod server;
mod world;

pub use error::ViewerError;
pub use mpc::{MAX_MPC_HORIZON, MAX_MPC_PASSES, MpcSettings, OnlineMpc, WARMUP_PER_STEP};
pub use server::{
    CLIENT_INPUT_CAPACITY, DEFAULT_IDLE_TIMEOUT, INPUT_CAPACITY, MAX_CLIENT_MESSAGE,
    MAX_READ_MESSAGE, REPLY_CAPACITY, Viewer, ViewerConfig,
};
pub use world::{SPRING_DAMPING, SPRING_MAX_FORCE, SPRING_STIFFNESS, World, WorldSettings};
