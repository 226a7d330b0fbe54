//! Textbook problems with exact derivatives, for comparing the solver with other DDP libraries on
//! identical terms (and for its own tests): linear dynamics, and the unicycle.

use crate::model::{Dynamics, SecondOrder};
use std::convert::Infallible;

/// `x' = A x + B u`.
#[derive(Debug, Clone, PartialEq)]
pub struct Linear {
    /// `A`, row-major `n x n`.
    pub a: Vec<f64>,
    /// `B`, row-major `n x m`.
    pub b: Vec<f64>,
    /// `n`.
    pub n: usize,
    /// `m`.
    pub m: usize,
}

impl Dynamics for Linear {
    type Error = Infallible;
    type Data = ();

    fn state_dim(&self) -> usize {
        self.n
    }

    fn control_dim(&self) -> usize {
        self.m
    }

    fn create_data(&self) {}

    fn calc(
        &self,
        _: &mut (),
        _: Option<&()>,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), Infallible> {
        for i in 0..self.n {
            next[i] = (0..self.n)
                .map(|j| self.a[i * self.n + j] * x[j])
                .sum::<f64>()
                + (0..self.m)
                    .map(|j| self.b[i * self.m + j] * u[j])
                    .sum::<f64>();
        }
        Ok(())
    }

    fn calc_diff(
        &self,
        _: &mut (),
        _x: &[f64],
        _u: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), Infallible> {
        fx.copy_from_slice(&self.a);
        fu.copy_from_slice(&self.b);
        Ok(())
    }

    fn second_order(&self) -> Option<&dyn SecondOrder<(), Error = Infallible>> {
        Some(self)
    }
}

/// Linear dynamics have no second-order terms: the Hessian is zero.
impl SecondOrder<()> for Linear {
    type Error = Infallible;

    fn calc_diff2(
        &self,
        data: &mut (),
        x: &[f64],
        u: &[f64],
        _c: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), Infallible> {
        hess.iter_mut().for_each(|e| *e = 0.0);
        self.calc_diff(data, x, u, fx, fu)
    }
}

/// The unicycle: state `[px, py, theta]`, control `[v, w]`, explicit Euler with step `dt`:
/// `px += v cos(theta) dt`, `py += v sin(theta) dt`, `theta += w dt`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Unicycle {
    /// Time step.
    pub dt: f64,
}

impl Unicycle {
    /// The benchmark problem's cost: `50 |x|^2 + 0.5 |u|^2` per step (not scaled by `dt`) and `50 |x_T|^2`.
    pub fn benchmark_cost() -> crate::QuadraticCost {
        crate::QuadraticCost::diagonal(&[100.0; 3], &[1.0; 2], &[100.0; 3])
    }

    /// The benchmark problem's start, `[-1, -1, 1]`.
    pub const X0: [f64; 3] = [-1.0, -1.0, 1.0];

    /// The benchmark problem's horizon.
    pub const HORIZON: usize = 75;
}

impl Dynamics for Unicycle {
    type Error = Infallible;
    type Data = ();

    fn state_dim(&self) -> usize {
        3
    }

    fn control_dim(&self) -> usize {
        2
    }

    fn create_data(&self) {}

    fn calc(
        &self,
        _: &mut (),
        _: Option<&()>,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), Infallible> {
        let (s, c) = x[2].sin_cos();
        next[0] = x[0] + u[0] * c * self.dt;
        next[1] = x[1] + u[0] * s * self.dt;
        next[2] = x[2] + u[1] * self.dt;
        Ok(())
    }

    fn calc_diff(
        &self,
        _: &mut (),
        x: &[f64],
        u: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), Infallible> {
        let (s, c) = x[2].sin_cos();
        let dt = self.dt;
        fx.copy_from_slice(&[
            1.0,
            0.0,
            -u[0] * s * dt,
            0.0,
            1.0,
            u[0] * c * dt,
            0.0,
            0.0,
            1.0,
        ]);
        fu.copy_from_slice(&[c * dt, 0.0, s * dt, 0.0, 0.0, dt]);
        Ok(())
    }

    fn second_order(&self) -> Option<&dyn SecondOrder<(), Error = Infallible>> {
        Some(self)
    }
}

impl SecondOrder<()> for Unicycle {
    type Error = Infallible;

    fn calc_diff2(
        &self,
        data: &mut (),
        x: &[f64],
        u: &[f64],
        cv: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), Infallible> {
        self.calc_diff(data, x, u, fx, fu)?;
        let (s, c) = x[2].sin_cos();
        let dt = self.dt;
        // y = (px, py, theta, v, w): d2/dtheta2 and d2/dtheta dv of c0 px' + c1 py'.
        hess.iter_mut().for_each(|e| *e = 0.0);
        hess[2 * 5 + 2] = (-cv[0] * c - cv[1] * s) * u[0] * dt;
        let cross = (-cv[0] * s + cv[1] * c) * dt;
        hess[2 * 5 + 3] = cross;
        hess[3 * 5 + 2] = cross;
        Ok(())
    }
}
