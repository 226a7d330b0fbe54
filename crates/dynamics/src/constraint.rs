//! The unilateral constraints `d(q) >= 0` and their Jacobians, in SCENE.md's row order: for each joint with
//! limits its lower then upper row, then for each contact pair the two friction-cone rows
//! `J_n + mu J_t` and `J_n - mu J_t` with `d` the signed distance.

use crate::error::DynamicsError;
use crate::kinematics::{Kinematics, perp};
use crate::scene::Scene;
use geometry::signed_distance_coords;

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
pub struct Constraints {
    /// `d(q)`, one per row.
    pub d: Vec<f64>,
    /// Row-major `m x n` Jacobian.
    pub jacobian: Vec<f64>,
    /// Per contact pair.
    pub contacts: Vec<ContactFrame>,
}

impl Constraints {
    /// Evaluate every row at the configuration `kin` (positions `q`).
    pub fn new(scene: &Scene, kin: &Kinematics, q: &[f64]) -> Result<Self, DynamicsError> {
        let n = scene.n_dof();
        let mut d = Vec::with_capacity(scene.n_constraints());
        let mut jacobian = Vec::with_capacity(scene.n_constraints() * n);
        for (j, b) in scene.bodies.iter().enumerate() {
            if let Some([lo, hi]) = b.limits {
                d.push(q[j] - lo);
                jacobian.extend((0..n).map(|k| if k == j { 1.0 } else { 0.0 }));
                d.push(hi - q[j]);
                jacobian.extend((0..n).map(|k| if k == j { -1.0 } else { 0.0 }));
            }
        }
        let mut contacts = Vec::with_capacity(scene.contacts.len());
        for pair in &scene.contacts {
            let pose = |i: usize| [kin.centre[i][0], kin.centre[i][1], kin.phi[i]];
            let (a, b) = (&scene.bodies[pair.a], &scene.bodies[pair.b]);
            let c = signed_distance_coords(&a.shape, pose(pair.a), &b.shape, pose(pair.b))?;
            let frame = ContactFrame {
                distance: c.distance,
                normal: [c.normal.x, c.normal.y],
                point_a: [c.point_a.x, c.point_a.y],
                point_b: [c.point_b.x, c.point_b.y],
                witness_unique: c.witness_unique,
            };
            let ja = kin.point_jacobian(scene, pair.a, frame.point_a);
            let jb = kin.point_jacobian(scene, pair.b, frame.point_b);
            let t = perp(frame.normal);
            let along = |dir: [f64; 2], k: usize| {
                dir[0] * (jb[0][k] - ja[0][k]) + dir[1] * (jb[1][k] - ja[1][k])
            };
            for sign in [1.0, -1.0] {
                d.push(frame.distance);
                jacobian.extend(
                    (0..n).map(|k| along(frame.normal, k) + sign * pair.friction * along(t, k)),
                );
            }
            contacts.push(frame);
        }
        Ok(Constraints {
            d,
            jacobian,
            contacts,
        })
    }
}
