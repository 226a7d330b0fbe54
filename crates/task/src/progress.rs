//! The coordinate a task makes progress along (what a library's growth and its measures call progress).

use crate::error::TaskError;
use crate::problem::{Success, Task};

/// The state entry a library's progress is measured along, its period when the policy compares states
/// modulo it, and the direction its task rewards along it (what growth rounds call progress).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// The state entry: the task's periodic coordinate if it has one, else the coordinate its running
    /// cost rewards, else the first judged target's (or 0).
    pub coordinate: usize,
    /// Its period, when it is periodic (the policy then compares states modulo it); `None`: the task has
    /// no periodic coordinate and states compare as they are.
    pub period: Option<f64>,
    /// `1` or `-1`: the direction the running cost rewards motion along it (growth branches where the
    /// policy stops moving that way); `None` when it rewards none (a target task: growth branches where
    /// the policy does not get back to its targets).
    pub forward: Option<f64>,
}

impl Progress {
    /// A task's: its periodic coordinate if it has one (the policy compares states modulo at most one),
    /// forward where the running terms' linear weights on it (or on its velocity) sum to a reward; without
    /// one, the first rewarded coordinate, or none.
    pub fn of_task(task: &Task) -> Result<Progress, TaskError> {
        let periodic: Vec<(usize, f64)> = task
            .periods
            .iter()
            .enumerate()
            .filter_map(|(i, p)| p.map(|p| (i, p)))
            .collect();
        let n = task.x0.len() / 2;
        let rewarded = Success::rewarded(&task.cost, n);
        match periodic.as_slice() {
            [] => Ok(match rewarded.first() {
                Some(&(coordinate, direction)) => Progress {
                    coordinate,
                    period: None,
                    forward: Some(direction),
                },
                None => Progress {
                    coordinate: task.success.targets.first().map_or(0, |t| t.0),
                    period: None,
                    forward: None,
                },
            }),
            &[(coordinate, period)] => Ok(Progress {
                coordinate,
                period: Some(period),
                forward: rewarded.iter().find(|r| r.0 == coordinate).map(|r| r.1),
            }),
            _ => Err(TaskError::Spec {
                task: task.name.clone(),
                field: "periods".into(),
                problem: format!(
                    "a library's policy compares states modulo at most one periodic coordinate; the task declares {}",
                    periodic.len()
                ),
            }),
        }
    }
}
