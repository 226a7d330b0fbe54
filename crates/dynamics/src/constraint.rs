//! The unilateral constraints `d(q) >= 0` and their Jacobians, in SCENE.md's row order: for each joint with
//! limits its lower then upper row, then for each contact pair the two friction-cone rows
//! `J_n + mu J_t` and `J_n - mu J_t` with `d` the signed distance. Generic over the scalar like
//! `kinematics.rs`; the contact geometry goes through `geometry::signed_distance_dual`, whose derivatives
//! are exact.

use crate::error::DynamicsError;
use crate::kinematics::{Kinematics, Ring, perp};
use crate::scene::Scene;
use geometry::signed_distance_dual;

/// One contact pair's geometry at the start of a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactFrame {
    /// Signed distance (negative in penetration).
    pub distance: f64,
    /// Unit normal from A to B.
    pub normal: [f64; 2],
    /// Witness point on A.
    pub point_a: [f64; 2],
    /// Witness point on B.
    pub point_b: [f64; 2],
    /// Whether the witness points are unique (else `d` is not differentiable there).
    pub witness_unique: bool,
}

/// Constraint values and Jacobian rows at `q`.
#[derive(Debug, Clone, PartialEq)]
pub struct Constraints<T = f64> {
    /// `d(q)`, one per row.
    pub d: Vec<T>,
    /// Row-major `m x n` Jacobian.
    pub jacobian: Vec<T>,
    /// Per contact pair (values only).
    pub contacts: Vec<ContactFrame>,
}

impl<T: Ring> Constraints<T> {
    /// Evaluate every row at the configuration `kin` (positions `q`).
    pub fn new(scene: &Scene, kin: &Kinematics<T>, q: &[T]) -> Result<Self, DynamicsError> {
        let n = scene.n_dof();
        let (zero, one) = (T::from(0.0), T::from(1.0));
        let mut d = Vec::with_capacity(scene.n_constraints());
        let mut jacobian = Vec::with_capacity(scene.n_constraints() * n);
        for (j, b) in scene.bodies.iter().enumerate() {
            if let Some([lo, hi]) = b.limits {
                d.push(q[j] + (-lo));
                jacobian.extend((0..n).map(|k| if k == j { one } else { zero }));
                d.push(-q[j] + hi);
                jacobian.extend((0..n).map(|k| if k == j { -one } else { zero }));
            }
        }
        let mut contacts = Vec::with_capacity(scene.contacts.len());
        for pair in &scene.contacts {
            let pose = |i: usize| [kin.centre[i][0], kin.centre[i][1], kin.phi[i]];
            let (a, b) = (&scene.bodies[pair.a], &scene.bodies[pair.b]);
            let c = signed_distance_dual(&a.shape, pose(pair.a), &b.shape, pose(pair.b))?;
            let re = |p: [T; 2]| [p[0].value(), p[1].value()];
            contacts.push(ContactFrame {
                distance: c.distance.value(),
                normal: re(c.normal),
                point_a: re(c.point_a),
                point_b: re(c.point_b),
                witness_unique: c.witness_unique,
            });
            let ja = kin.point_jacobian(scene, pair.a, c.point_a);
            let jb = kin.point_jacobian(scene, pair.b, c.point_b);
            let t = perp(c.normal);
            let along = |dir: [T; 2], k: usize| {
                dir[0] * (jb[0][k] - ja[0][k]) + dir[1] * (jb[1][k] - ja[1][k])
            };
            for sign in [1.0, -1.0] {
                d.push(c.distance);
                jacobian.extend(
                    (0..n).map(|k| along(c.normal, k) + along(t, k) * (sign * pair.friction)),
                );
            }
        }
        Ok(Constraints {
            d,
            jacobian,
            contacts,
        })
    }
}
