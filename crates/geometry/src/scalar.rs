//! The arithmetic [`signed_distance_dual`](crate::signed_distance_dual) (and the simulator's kinematics)
//! run on: a ring over `f64` with division, sine and cosine and square root, and a known derivative
//! order. Every forward-mode type of `num-dual` is one (blanket implementation); a crate may add its own
//! (the simulator's fused second-order `Jet`).

use num_dual::DualNum;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

/// A forward-mode number over `f64` (or `f64` itself).
pub trait Forward:
    Copy
    + From<f64>
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
    + AddAssign
    + SubAssign
{
    /// Highest derivative order carried (0 for `f64`).
    const ORDER: usize;

    /// The value (real part).
    fn value(&self) -> f64;

    /// `(sin x, cos x)`.
    fn sin_and_cos(self) -> (Self, Self);

    /// `sqrt(x)`.
    fn square_root(self) -> Self;
}

impl<T: DualNum<Primitive = f64> + Copy> Forward for T {
    const ORDER: usize = T::NDERIV;

    fn value(&self) -> f64 {
        self.re()
    }

    fn sin_and_cos(self) -> (Self, Self) {
        self.sin_cos()
    }

    fn square_root(self) -> Self {
        self.sqrt()
    }
}
