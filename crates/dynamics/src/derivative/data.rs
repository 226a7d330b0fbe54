//! What a step's data keeps of its derivatives: the results for the step it holds (its first
//! derivatives and what its second derivatives keep), each refilled in place by the next step's; and the
//! stages' working vectors, which hold nothing between calls (issue 29: no allocation once they have
//! the scene's sizes, and nothing moved but numbers). The stages' own files take these as arguments and
//! import nothing of this one.

#![allow(non_snake_case)]

use super::StepDerivatives;
use super::expansion::{D1, Ingredients};
use super::hessian::SecondOrderParts;
use crate::constraint::Constraints;
use std::any::Any;

/// The derivatives a [`StepData`](crate::StepData) keeps for its step, and their working vectors.
#[derive(Default)]
pub(crate) struct DerivativeData {
    /// The step's first derivatives, when `has_first`.
    pub(crate) first: StepDerivatives,
    pub(crate) has_first: bool,
    /// What the step's second derivatives keep (and its linearisation, which the first derivatives
    /// read), when `has_second`.
    pub(crate) parts: SecondOrderParts,
    pub(crate) has_second: bool,
}

impl std::fmt::Debug for DerivativeData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DerivativeData")
            .field("has_first", &self.has_first)
            .field("has_second", &self.has_second)
            .finish_non_exhaustive()
    }
}

impl DerivativeData {
    /// A new step: what was kept belongs to the old one (the vectors stay, to be refilled).
    pub(crate) fn forget(&mut self) {
        self.has_first = false;
        self.has_second = false;
    }
}

/// The working vectors of the derivative stages: nothing in them outlives a call (the model keeps one set
/// per thread).
#[derive(Default)]
pub(crate) struct Work {
    /// The step's values as the linearisation reassembles them.
    pub(super) values: Values,
    /// The jets' working vectors, one set per scalar type in use (`JetWork` of the model's stages).
    pub(super) jets: Vec<Box<dyn Any + Send>>,
    /// The first derivatives' ingredients in duals, one per eight directions of `(x, u)`, and the
    /// vectors their equations are evaluated in.
    pub(super) first_order: Vec<Ingredients<D1>>,
    pub(super) duals: Duals,
}

/// The step's ingredients' values and its problem's buffers, as the linearisation rebuilds them.
#[derive(Default)]
pub(super) struct Values {
    pub(super) M: Vec<f64>,
    pub(super) r: Vec<f64>,
    pub(super) cons: Constraints,
    /// The problem's `M` and `q`.
    pub(super) lcp: (Vec<f64>, Vec<f64>),
    pub(super) z: Vec<f64>,
    pub(super) f: Vec<f64>,
    pub(super) jac: Vec<f64>,
    /// The Newton matrix, and each row's `(d phi / d lambda, d phi / d w)` and slope in `w`.
    pub(super) H: Vec<f64>,
    pub(super) dphi: Vec<(f64, f64)>,
    pub(super) slope: Vec<f64>,
}

/// The first-order duals of the equations' evaluation: the unknowns, the velocities, the equations and
/// the rows' `w`.
#[derive(Default)]
pub(super) struct Duals {
    pub(super) pc: Vec<D1>,
    pub(super) v: Vec<D1>,
    pub(super) res: Vec<D1>,
    pub(super) w: Vec<D1>,
}
