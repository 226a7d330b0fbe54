//! The ellipse shape: semi-axes, support function and curvature.

use crate::GeometryError;
use num_dual::DualNum;

/// A solid ellipse centred at its body origin, semi-axis `a` along the body x axis and `b` along the body y axis.
///
/// The fields are private so that every `Ellipse` in a program has finite, positive semi-axes
/// (construct it with [`Ellipse::new`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipse {
    a: f64,
    b: f64,
}

/// The semi-axes an [`Ellipse`] may have: the range in which every query of this crate stays finite and
/// keeps its accuracy (squares, products and support functions of lengths from 1e-6 to 1e6, and aspect
/// ratios up to 1e12, are far from overflow and underflow). Outside it [`Ellipse::new`] refuses the value.
pub const SEMI_AXIS_RANGE: [f64; 2] = [1e-6, 1e6];

impl Ellipse {
    /// An ellipse with semi-axes `a` (body x) and `b` (body y); both must be finite and positive.
    pub fn new(a: f64, b: f64) -> Result<Self, GeometryError> {
        for (axis, value) in [("a", a), ("b", b)] {
            if !(SEMI_AXIS_RANGE[0]..=SEMI_AXIS_RANGE[1]).contains(&value) {
                return Err(GeometryError::SemiAxis {
                    shape: "ellipse",
                    axis,
                    value,
                });
            }
        }
        Ok(Self { a, b })
    }

    /// A circle of radius `r`.
    pub fn circle(r: f64) -> Result<Self, GeometryError> {
        Self::new(r, r)
    }

    /// Semi-axis along the body x axis.
    pub fn a(&self) -> f64 {
        self.a
    }

    /// Semi-axis along the body y axis.
    pub fn b(&self) -> f64 {
        self.b
    }

    /// The larger semi-axis: the radius of the bounding circle, and the length scale of tolerances.
    pub fn max_axis(&self) -> f64 {
        self.a.max(self.b)
    }

    /// Area `pi a b`.
    pub fn area(&self) -> f64 {
        std::f64::consts::PI * self.a * self.b
    }

    /// Moment of inertia about the centre per unit density: `area (a^2 + b^2) / 4`.
    pub fn unit_inertia(&self) -> f64 {
        self.area() * (self.a * self.a + self.b * self.b) / 4.0
    }

    /// Support function in the body frame for the unit direction `(c, s)`:
    /// `h = sqrt(a^2 c^2 + b^2 s^2)`, the largest `m . p` over the ellipse.
    pub fn support_value<T: DualNum<Primitive = f64> + Copy>(&self, c: T, s: T) -> T {
        (c * c * (self.a * self.a) + s * s * (self.b * self.b)).sqrt()
    }

    /// Support point in the body frame for the unit direction `(c, s)`:
    /// `(a^2 c, b^2 s) / h`, the point of the boundary whose outward normal is `(c, s)`.
    pub fn support_point_local<T: DualNum<Primitive = f64> + Copy>(&self, c: T, s: T) -> [T; 2] {
        let h = self.support_value(c, s);
        [c * (self.a * self.a) / h, s * (self.b * self.b) / h]
    }

    /// Whether the body-frame point lies inside or on the boundary (`(x/a)^2 + (y/b)^2 <= 1`).
    pub fn contains_local(&self, x: f64, y: f64) -> bool {
        (x / self.a).powi(2) + (y / self.b).powi(2) <= 1.0
    }
}

/// The support function of an ellipse along the body-frame angle psi and its first two derivatives
/// in psi, with the radius of curvature of the boundary at the support point.
///
/// With `h(psi) = sqrt(a^2 cos^2 psi + b^2 sin^2 psi)`: `h' = (b^2 - a^2) cos psi sin psi / h`,
/// `rho = a^2 b^2 / h^3` and `h'' = rho - h` (support functions satisfy `h + h'' = rho`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct SupportJet {
    pub h: f64,
    pub dh: f64,
    pub rho: f64,
}

impl SupportJet {
    /// Evaluates at the body-frame direction `(c, s) = (cos psi, sin psi)`.
    #[inline]
    pub fn at(e: &Ellipse, c: f64, s: f64) -> Self {
        let a2 = e.a * e.a;
        let b2 = e.b * e.b;
        let h = (a2 * c * c + b2 * s * s).sqrt();
        let dh = (b2 - a2) * c * s / h;
        let rho = a2 * b2 / (h * h * h);
        Self { h, dh, rho }
    }

    /// `h''`.
    #[inline]
    pub fn ddh(&self) -> f64 {
        self.rho - self.h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_axes_outside_the_safe_range() {
        for (a, b) in [
            (0.0, 1.0),
            (1.0, -1.0),
            (f64::NAN, 1.0),
            (1.0, f64::INFINITY),
            (1e-300, 1e300),
            (1.0, 0.99e-6),
            (1.01e6, 1.0),
        ] {
            assert!(Ellipse::new(a, b).is_err(), "accepted ({a}, {b})");
        }
        // The range's ends are in it, and every distance between such shapes is finite.
        let (lo, hi) = (SEMI_AXIS_RANGE[0], SEMI_AXIS_RANGE[1]);
        let shapes = [(lo, lo), (lo, hi), (hi, lo), (hi, hi), (1.0, lo)];
        for &(a1, b1) in &shapes {
            for &(a2, b2) in &shapes {
                let (a, b) = (Ellipse::new(a1, b1).unwrap(), Ellipse::new(a2, b2).unwrap());
                for pose_b in [[0.0, 0.0, 0.7], [3.0 * hi, -hi, 2.0], [3.0 * lo, lo, -1.0]] {
                    let c = crate::signed_distance_coords(&a, [0.0, 0.0, 0.3], &b, pose_b).unwrap();
                    assert!(
                        c.distance.is_finite() && c.point_a.x.is_finite() && c.normal.y.is_finite(),
                        "({a1}, {b1}) vs ({a2}, {b2}) at {pose_b:?}: {c:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn support_jet_obeys_h_plus_hpp_equals_radius_of_curvature() {
        let e = Ellipse::new(0.7, 0.5).unwrap();
        let psi = 0.37_f64;
        let eps = 1e-5;
        let jet = SupportJet::at(&e, psi.cos(), psi.sin());
        let hp = SupportJet::at(&e, (psi + eps).cos(), (psi + eps).sin()).h;
        let hm = SupportJet::at(&e, (psi - eps).cos(), (psi - eps).sin()).h;
        assert!(((hp - hm) / (2.0 * eps) - jet.dh).abs() < 1e-9);
        assert!(((hp - 2.0 * jet.h + hm) / (eps * eps) - jet.ddh()).abs() < 1e-5);
    }

    #[test]
    fn support_point_lies_on_boundary_with_given_normal() {
        let e = Ellipse::new(2.0, 0.1).unwrap();
        let psi = 1.2_f64;
        let [x, y] = e.support_point_local(psi.cos(), psi.sin());
        assert!(((x / 2.0).powi(2) + (y / 0.1).powi(2) - 1.0).abs() < 1e-14);
        // Outward normal of the implicit form is proportional to (x / a^2, y / b^2).
        let (nx, ny) = (x / 4.0, y / 0.01);
        assert!((nx * psi.sin() - ny * psi.cos()).abs() < 1e-12 * nx.hypot(ny));
    }
}
