//! One call shape for the crate's solvers: [`Solver::solve`] takes a linear mixed complementarity
//! problem, what each of its complementarity rows needs from the caller ([`Solver::Rows`]: nothing for
//! Lemke's exact method, the NCP function for Newton, the noise for expected-residual minimisation) and a
//! start, and returns a [`Solution`]; each solver is built once from checked settings and reused.

use crate::erm::ErmSolver;
use crate::error::NcpError;
use crate::function::NcpFunction;
use crate::lemke::{LemkeSettings, lemke};
use crate::newton::NewtonSolver;
use crate::problem::{LinearMcp, Mcp};
use crate::solution::Solution;

/// A complementarity solver (see the module documentation).
pub trait Solver {
    /// Per complementarity row, what the method needs.
    type Rows: ?Sized;

    /// Solve `problem` from `z0` (length `problem.dim()`; Lemke's method, which needs no start, checks
    /// its length only), with `rows` giving each complementarity row's data.
    fn solve(
        &mut self,
        problem: &LinearMcp,
        rows: &Self::Rows,
        z0: &[f64],
    ) -> Result<Solution, NcpError>;
}

/// Lemke's method ([`lemke`]) as a [`Solver`]: the exact answer of the hard problem.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lemke {
    settings: LemkeSettings,
}

impl Lemke {
    /// The method with checked settings.
    pub fn new(settings: LemkeSettings) -> Result<Self, NcpError> {
        settings.validate()?;
        Ok(Lemke { settings })
    }
}

impl Solver for Lemke {
    type Rows = ();

    fn solve(&mut self, problem: &LinearMcp, _: &(), z0: &[f64]) -> Result<Solution, NcpError> {
        crate::error::check_len("z0", z0.len(), problem.dim())?;
        lemke(problem, &self.settings)
    }
}

impl Solver for NewtonSolver {
    type Rows = [NcpFunction];

    fn solve(
        &mut self,
        problem: &LinearMcp,
        rows: &[NcpFunction],
        z0: &[f64],
    ) -> Result<Solution, NcpError> {
        NewtonSolver::solve(self, problem, rows, z0)
    }
}

impl Solver for ErmSolver {
    type Rows = [f64];

    fn solve(
        &mut self,
        problem: &LinearMcp,
        rows: &[f64],
        z0: &[f64],
    ) -> Result<Solution, NcpError> {
        ErmSolver::solve(self, problem, rows, z0)
    }
}
