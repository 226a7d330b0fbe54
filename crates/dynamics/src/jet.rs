//! A second-order forward-mode number over `N` directions with plain arrays: value, gradient and the
//! Hessian's upper triangle, packed, each product fused into one pass (no temporaries). The Hessians of the
//! forces `r(q, v)` run on it (`Jet<6, 21>` over `(q, v)` for three joints, the narrowest width that holds
//! a scene's arguments up to twelve; larger scenes take several passes): a few times cheaper than the
//! general-purpose dual types for the one place where second derivatives of many operations are needed.

use crate::kinematics::Ring;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

/// `re + g . s + 1/2 s^T h s`, to second order in `s`. The Hessian is symmetric: only its upper triangle
/// is computed and stored, packed row by row in `H = N (N + 1) / 2` entries (read it with
/// [`Jet::hessian`]), which saves close to half the arithmetic of every operation and of every copy.
/// `H` is spelled out because stable Rust cannot compute an array's length from `N`; a jet whose `H` is
/// not `N (N + 1) / 2` does not compile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jet<const N: usize, const H: usize> {
    /// Value.
    pub re: f64,
    /// Gradient.
    pub g: [f64; N],
    /// Hessian, upper triangle packed row by row: `(0, 0), (0, 1), .., (0, N - 1), (1, 1), ..`.
    h: [f64; H],
}

impl<const N: usize, const H: usize> Jet<N, H> {
    /// Compile-time check of the packed triangle's length.
    const PACKED: () = assert!(H == N * (N + 1) / 2, "a jet's H must be N (N + 1) / 2");

    /// The Hessian's entry `(i, j)`.
    pub fn hessian(&self, i: usize, j: usize) -> f64 {
        let (i, j) = if i <= j { (i, j) } else { (j, i) };
        // Rows 0..i hold N + (N - 1) + .. + (N - i + 1) = i N - i (i - 1) / 2 entries.
        self.h[i * N - i * i.saturating_sub(1) / 2 + (j - i)]
    }

    /// The Hessian's upper triangle, packed row by row.
    pub fn packed(&self) -> &[f64; H] {
        &self.h
    }

    /// The variable `s_i` at value `re`.
    pub fn variable(re: f64, i: usize) -> Self {
        let mut j = Jet::from(re);
        j.g[i] = 1.0;
        j
    }

    /// `f(self)` from `f`, `f'` and `f''` at `self.re` (chain rule).
    fn chain(&self, f0: f64, f1: f64, f2: f64) -> Self {
        let mut out = Jet::from(f0);
        let mut k = 0;
        for i in 0..N {
            out.g[i] = f1 * self.g[i];
            for j in i..N {
                out.h[k] = f1 * self.h[k] + f2 * self.g[i] * self.g[j];
                k += 1;
            }
        }
        out
    }
}

impl<const N: usize, const H: usize> From<f64> for Jet<N, H> {
    fn from(re: f64) -> Self {
        let () = Self::PACKED;
        Jet {
            re,
            g: [0.0; N],
            h: [0.0; H],
        }
    }
}

impl<const N: usize, const H: usize> Add for Jet<N, H> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: Self) -> Self {
        self += o;
        self
    }
}

impl<const N: usize, const H: usize> AddAssign for Jet<N, H> {
    #[inline]
    fn add_assign(&mut self, o: Self) {
        self.re += o.re;
        for i in 0..N {
            self.g[i] += o.g[i];
        }
        for k in 0..H {
            self.h[k] += o.h[k];
        }
    }
}

impl<const N: usize, const H: usize> Sub for Jet<N, H> {
    type Output = Self;
    #[inline]
    fn sub(mut self, o: Self) -> Self {
        self -= o;
        self
    }
}

impl<const N: usize, const H: usize> Neg for Jet<N, H> {
    type Output = Self;
    #[inline]
    fn neg(mut self) -> Self {
        self.re = -self.re;
        for i in 0..N {
            self.g[i] = -self.g[i];
        }
        for k in 0..H {
            self.h[k] = -self.h[k];
        }
        self
    }
}

impl<const N: usize, const H: usize> Mul for Jet<N, H> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        let mut out = Jet::from(self.re * o.re);
        let mut k = 0;
        for i in 0..N {
            out.g[i] = self.re * o.g[i] + o.re * self.g[i];
            for j in i..N {
                out.h[k] =
                    self.re * o.h[k] + o.re * self.h[k] + self.g[i] * o.g[j] + o.g[i] * self.g[j];
                k += 1;
            }
        }
        out
    }
}

impl<const N: usize, const H: usize> Add<f64> for Jet<N, H> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: f64) -> Self {
        self.re += o;
        self
    }
}

impl<const N: usize, const H: usize> Mul<f64> for Jet<N, H> {
    type Output = Self;
    #[inline]
    fn mul(mut self, o: f64) -> Self {
        self.re *= o;
        for i in 0..N {
            self.g[i] *= o;
        }
        for k in 0..H {
            self.h[k] *= o;
        }
        self
    }
}

impl<const N: usize, const H: usize> SubAssign for Jet<N, H> {
    #[inline]
    fn sub_assign(&mut self, o: Self) {
        self.re -= o.re;
        for i in 0..N {
            self.g[i] -= o.g[i];
        }
        for k in 0..H {
            self.h[k] -= o.h[k];
        }
    }
}

impl<const N: usize, const H: usize> Div for Jet<N, H> {
    type Output = Self;
    #[inline]
    fn div(self, o: Self) -> Self {
        let r = 1.0 / o.re;
        self * o.chain(r, -r * r, 2.0 * r * r * r)
    }
}

impl<const N: usize, const H: usize> Div<f64> for Jet<N, H> {
    type Output = Self;
    #[inline]
    fn div(self, o: f64) -> Self {
        self * (1.0 / o)
    }
}

impl<const N: usize, const H: usize> Ring for Jet<N, H> {
    const ORDER: usize = 2;

    fn value(&self) -> f64 {
        self.re
    }

    fn sin_and_cos(self) -> (Self, Self) {
        let (s, c) = self.re.sin_cos();
        (self.chain(s, c, -s), self.chain(c, -s, -c))
    }

    fn square_root(self) -> Self {
        let r = self.re.sqrt();
        self.chain(r, 0.5 / r, -0.25 / (r * self.re))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_dual::Dual2SVec64;

    /// A polynomial-and-trigonometric expression in any ring.
    fn expr<T: Ring>(x: T, y: T) -> T {
        let (s, c) = (x * y + 0.3).sin_and_cos();
        let mut out = s * x * 2.0 + c * c * y - (x + y * x) * (-y) + T::from(1.5);
        out -= (x * x + 2.0).square_root() / (y + 3.0) + x / 4.0;
        out
    }

    #[test]
    fn jet_arithmetic_matches_num_duals_second_order_numbers() {
        for &(a, b) in &[(0.3, -1.2), (2.0, 0.7), (-0.4, 0.0)] {
            let j = expr(Jet::<2, 3>::variable(a, 0), Jet::<2, 3>::variable(b, 1));
            let d = expr(
                Dual2SVec64::<2>::from_re(a).derivative(0),
                Dual2SVec64::<2>::from_re(b).derivative(1),
            );
            assert!((j.re - d.re).abs() < 1e-14);
            let g = d.v1.0.unwrap();
            let h = d.v2.0.unwrap();
            for i in 0..2 {
                assert!((j.g[i] - g[(0, i)]).abs() < 1e-13);
                for k in 0..2 {
                    assert!((j.hessian(i, k) - h[(i, k)]).abs() < 1e-13, "h[{i}][{k}]");
                }
            }
        }
    }
}

/// `re + g . s`, to first order in `s`: the first-order counterpart of [`Jet`] (the step's first
/// derivatives run the geometry and the forces on it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jet1<const N: usize> {
    /// Value.
    pub re: f64,
    /// Gradient.
    pub g: [f64; N],
}

impl<const N: usize> Jet1<N> {
    /// The variable `s_i` at value `re`.
    pub fn variable(re: f64, i: usize) -> Self {
        let mut j = Jet1::from(re);
        j.g[i] = 1.0;
        j
    }

    fn chain(&self, f0: f64, f1: f64) -> Self {
        let mut out = Jet1::from(f0);
        for i in 0..N {
            out.g[i] = f1 * self.g[i];
        }
        out
    }
}

impl<const N: usize> From<f64> for Jet1<N> {
    fn from(re: f64) -> Self {
        Jet1 { re, g: [0.0; N] }
    }
}

impl<const N: usize> AddAssign for Jet1<N> {
    fn add_assign(&mut self, o: Self) {
        self.re += o.re;
        for i in 0..N {
            self.g[i] += o.g[i];
        }
    }
}

impl<const N: usize> SubAssign for Jet1<N> {
    fn sub_assign(&mut self, o: Self) {
        self.re -= o.re;
        for i in 0..N {
            self.g[i] -= o.g[i];
        }
    }
}

impl<const N: usize> Add for Jet1<N> {
    type Output = Self;
    fn add(mut self, o: Self) -> Self {
        self += o;
        self
    }
}

impl<const N: usize> Sub for Jet1<N> {
    type Output = Self;
    fn sub(mut self, o: Self) -> Self {
        self -= o;
        self
    }
}

impl<const N: usize> Neg for Jet1<N> {
    type Output = Self;
    fn neg(mut self) -> Self {
        self.re = -self.re;
        for i in 0..N {
            self.g[i] = -self.g[i];
        }
        self
    }
}

impl<const N: usize> Mul for Jet1<N> {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        let mut out = Jet1::from(self.re * o.re);
        for i in 0..N {
            out.g[i] = self.re * o.g[i] + o.re * self.g[i];
        }
        out
    }
}

impl<const N: usize> Div for Jet1<N> {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        let r = 1.0 / o.re;
        self * o.chain(r, -r * r)
    }
}

impl<const N: usize> Add<f64> for Jet1<N> {
    type Output = Self;
    fn add(mut self, o: f64) -> Self {
        self.re += o;
        self
    }
}

impl<const N: usize> Mul<f64> for Jet1<N> {
    type Output = Self;
    fn mul(mut self, o: f64) -> Self {
        self.re *= o;
        for i in 0..N {
            self.g[i] *= o;
        }
        self
    }
}

impl<const N: usize> Div<f64> for Jet1<N> {
    type Output = Self;
    fn div(self, o: f64) -> Self {
        self * (1.0 / o)
    }
}

impl<const N: usize> Ring for Jet1<N> {
    const ORDER: usize = 1;

    fn value(&self) -> f64 {
        self.re
    }

    fn sin_and_cos(self) -> (Self, Self) {
        let (s, c) = self.re.sin_cos();
        (self.chain(s, c), self.chain(c, -s))
    }

    fn square_root(self) -> Self {
        let r = self.re.sqrt();
        self.chain(r, 0.5 / r)
    }
}

#[cfg(test)]
mod first_order_tests {
    use super::*;

    #[test]
    fn a_first_order_jet_is_the_gradient_part_of_a_second_order_one() {
        let f = |x: f64, y: f64| {
            let (a, b) = (Jet1::<2>::variable(x, 0), Jet1::<2>::variable(y, 1));
            let (c, d) = (Jet::<2, 3>::variable(x, 0), Jet::<2, 3>::variable(y, 1));
            let e1 = (a * b + 0.3).sin_and_cos().0 / (a * a + 1.0).square_root() - b * 2.0;
            let e2 = (c * d + 0.3).sin_and_cos().0 / (c * c + 1.0).square_root() - d * 2.0;
            (e1, e2)
        };
        for &(x, y) in &[(0.3, -1.2), (2.0, 0.7)] {
            let (a, b) = f(x, y);
            assert_eq!(a.re, b.re);
            for i in 0..2 {
                assert!((a.g[i] - b.g[i]).abs() < 1e-15);
            }
        }
    }
}
