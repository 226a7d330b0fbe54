//! The flicking finger as an optimal control task (SCENE.md "The task"): the simulator behind
//! [`ddp::Dynamics`], the task's cost, and (to come) the receding-horizon library and its global policy
//! (paper sections IV-C and V).

mod task;

pub use task::{CONTROL_WEIGHT, FingerDynamics, TaskError, finger_cost};
