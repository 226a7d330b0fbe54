//! The contact model a task is optimised on, and a library built on (a plain enum so that task and
//! library files stay compact and self-contained).

use dynamics::Complementarity;
use serde::{Deserialize, Serialize};

/// The contact model a task's optimiser sees (and a library of it is built on).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum ContactModel {
    /// Hard contact (the active set's derivatives).
    Hard,
    /// Logistic smoothing (eq. 17) with this sigma.
    Logistic(f64),
    /// Normal smoothing (eq. 14 with 15) with this sigma.
    Normal(f64),
}

impl ContactModel {
    /// The simulator's model.
    pub fn complementarity(self) -> Complementarity {
        match self {
            ContactModel::Hard => Complementarity::Hard,
            ContactModel::Logistic(sigma) => Complementarity::Logistic { sigma },
            ContactModel::Normal(sigma) => Complementarity::Normal { sigma },
        }
    }
}

/// In user words, as the simulator's model reads (`logistic contact, sigma 0.1`, `hard contact`).
impl std::fmt::Display for ContactModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.complementarity().fmt(f)
    }
}
