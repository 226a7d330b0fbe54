//! The commands that put the crates on the command line: JSON-line streams (`distance`, `lcp`, `step`,
//! over `jsonl`), a rollout (`simulate`, in `step`), a solve (`optimize`), a library (`train`,
//! `evaluate`) and the viewer (`view`). The experiments are built on them; they import no experiment.

pub mod distance;
pub mod evaluate;
pub mod jsonl;
pub mod lcp;
pub mod optimize;
pub mod step;
pub mod train;
pub mod view;
