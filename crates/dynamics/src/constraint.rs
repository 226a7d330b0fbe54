//! The unilateral constraints `d(q) >= 0` and their Jacobians, in SCENE.md's row order: for each joint with
//! limits its lower then upper row, then for each contact pair the two friction-cone rows
//! `J_n + mu J_t` and `J_n - mu J_t` with `d` the signed distance. Generic over the scalar like
//! `kinematics.rs`; the contact geometry goes through `geometry::signed_distance_dual`, whose derivatives
//! are exact.

use crate::error::DynamicsError;
use crate::kinematics::{Kinematics, Ring, perp};
use crate::scene::{ConstraintRow, Scene, Side};
use geometry::{
    ContactSeed, DualContact, DualPose, half_plane_distance_dual_posed, signed_distance_dual_posed,
    signed_distance_dual_seeded,
};

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
    /// What the geometry's search found for a pair of ellipses (`None` against a half-plane): the
    /// derivative passes at the same configuration finish from it instead of searching again.
    pub seed: Option<ContactSeed>,
}

/// A contact pair's impulse over one step, from its two friction-cone rows `lambda_+` and `lambda_-`:
/// `normal = lambda_+ + lambda_-` along the pair's normal (from A to B), `tangent = mu (lambda_+ -
/// lambda_-)` along `perp(normal)`; `on_b` is the impulse on body B in world coordinates (A receives
/// its opposite).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ContactImpulse {
    /// Along the normal.
    pub normal: f64,
    /// Along the tangent `perp(normal)`.
    pub tangent: f64,
    /// On body B, world coordinates.
    pub on_b: [f64; 2],
}

impl ContactImpulse {
    /// Each pair's impulse from the step's row impulses `lambda` (the order of [`Scene::rows`]) and the
    /// pairs' frames.
    pub(crate) fn of_into(
        scene: &Scene,
        lambda: &[f64],
        frames: &[ContactFrame],
        out: &mut Vec<ContactImpulse>,
    ) {
        // Each pair's two edge impulses, held in `normal` (plus) and `tangent` (minus) until combined.
        out.clear();
        out.resize(
            scene.contacts.len(),
            ContactImpulse {
                normal: 0.0,
                tangent: 0.0,
                on_b: [0.0; 2],
            },
        );
        for (row, l) in scene.rows().iter().zip(lambda) {
            if let ConstraintRow::FrictionEdge { pair, positive } = *row {
                let edge = &mut out[pair];
                *(if positive {
                    &mut edge.normal
                } else {
                    &mut edge.tangent
                }) = *l;
            }
        }
        for ((impulse, pair), frame) in out.iter_mut().zip(&scene.contacts).zip(frames) {
            let (plus, minus) = (impulse.normal, impulse.tangent);
            let (normal, tangent) = (plus + minus, pair.friction * (plus - minus));
            let [nx, ny] = frame.normal;
            *impulse = ContactImpulse {
                normal,
                tangent,
                on_b: [normal * nx - tangent * ny, normal * ny + tangent * nx],
            };
        }
    }
}

/// Constraint values and Jacobian rows at `q`, in the order of [`Scene::rows`].
#[derive(Debug, Clone, PartialEq, Default)]
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
        let mut cons = Self::sized(scene);
        cons.update(scene, kin, q)?;
        Ok(cons)
    }

    /// Empty rows with room for the scene's.
    fn sized(scene: &Scene) -> Self {
        Constraints {
            d: Vec::with_capacity(scene.n_constraints()),
            jacobian: Vec::with_capacity(scene.n_constraints() * scene.n_dof()),
            contacts: Vec::with_capacity(scene.contacts.len()),
        }
    }

    /// The rows in `slot` updated to `kin` ([`Constraints::update`]), or new ones made there (see
    /// [`Kinematics::refresh`]).
    pub fn refresh<'a>(
        slot: &'a mut Option<Self>,
        scene: &Scene,
        kin: &Kinematics<T>,
        q: &[T],
    ) -> Result<&'a mut Self, DynamicsError> {
        Self::refresh_seeded(slot, scene, kin, q, None)
    }

    /// [`Constraints::refresh`] from the contacts' seeds ([`Constraints::update_seeded`]).
    pub(crate) fn refresh_seeded<'a>(
        slot: &'a mut Option<Self>,
        scene: &Scene,
        kin: &Kinematics<T>,
        q: &[T],
        seeds: Option<&[ContactFrame]>,
    ) -> Result<&'a mut Self, DynamicsError> {
        let cons = slot.get_or_insert_with(|| Self::sized(scene));
        cons.update_seeded(scene, kin, q, seeds)?;
        Ok(cons)
    }

    /// [`Constraints::new`] in place: the same vectors refilled, without allocating once they have the
    /// scene's sizes (a step's data keeps one).
    pub fn update(
        &mut self,
        scene: &Scene,
        kin: &Kinematics<T>,
        q: &[T],
    ) -> Result<(), DynamicsError> {
        self.update_seeded(scene, kin, q, None)
    }

    /// [`Constraints::update`] at a configuration whose contacts were computed already (in `f64`, at
    /// exactly `q`'s values): each pair of ellipses finishes from that contact's
    /// [seed](ContactFrame::seed) instead of searching again, to the same result.
    pub(crate) fn update_seeded(
        &mut self,
        scene: &Scene,
        kin: &Kinematics<T>,
        q: &[T],
        seeds: Option<&[ContactFrame]>,
    ) -> Result<(), DynamicsError> {
        let n = scene.n_dof();
        let (zero, one) = (T::from(0.0), T::from(1.0));
        let Constraints {
            d,
            jacobian,
            contacts,
        } = self;
        d.clear();
        jacobian.clear();
        contacts.clear();
        for (j, c) in scene.coordinates.iter().enumerate() {
            if let Some([lo, hi]) = c.limits {
                d.push(q[j] + (-lo));
                jacobian.extend((0..n).map(|k| if k == j { one } else { zero }));
                d.push(-q[j] + hi);
                jacobian.extend((0..n).map(|k| if k == j { -one } else { zero }));
            }
        }
        for (index, pair) in scene.contacts.iter().enumerate() {
            // An ellipse side's shape and pose: a body's from the kinematics, a fixed one's constant.
            // (A body's angle's sine and cosine are the kinematics'.)
            let ellipse = |side: Side| match side {
                Side::Body(i) => (
                    &scene.bodies[i].shape,
                    DualPose::turned(
                        [kin.centre[i][0], kin.centre[i][1], kin.phi[i]],
                        kin.turn[i],
                    ),
                ),
                Side::Fixed(i) => {
                    let f = &scene.fixed[i];
                    (&f.shape, DualPose::new(f.pose.map(T::from)))
                }
                Side::Plane(_) => unreachable!("a half-plane side is handled before"),
            };
            let c = match (pair.a, pair.b) {
                (Side::Plane(p), b) => {
                    let (shape, pose) = ellipse(b);
                    half_plane_distance_dual_posed(&scene.planes[p].shape, shape, &pose)?
                }
                (a, Side::Plane(p)) => {
                    // The same contact seen from the ellipse: witnesses swapped, the normal reversed.
                    let (shape, pose) = ellipse(a);
                    let c = half_plane_distance_dual_posed(&scene.planes[p].shape, shape, &pose)?;
                    DualContact {
                        distance: c.distance,
                        point_a: c.point_b,
                        point_b: c.point_a,
                        normal: [-c.normal[0], -c.normal[1]],
                        witness_unique: c.witness_unique,
                        seed: c.seed,
                    }
                }
                (a, b) => {
                    let ((sa, pa), (sb, pb)) = (ellipse(a), ellipse(b));
                    match seeds.and_then(|f| f.get(index)).and_then(|f| f.seed) {
                        Some(seed) => signed_distance_dual_seeded(sa, &pa, sb, &pb, &seed),
                        None => signed_distance_dual_posed(sa, &pa, sb, &pb)?,
                    }
                }
            };
            let re = |p: [T; 2]| [p[0].value(), p[1].value()];
            contacts.push(ContactFrame {
                distance: c.distance.value(),
                normal: re(c.normal),
                point_a: re(c.point_a),
                point_b: re(c.point_b),
                witness_unique: c.witness_unique,
                seed: c.seed,
            });
            // Per joint: the normal and tangential relative velocity of the witness points.
            let t = perp(c.normal);
            let start = jacobian.len();
            jacobian.resize(start + 2 * n, zero);
            let (plus, minus) = jacobian[start..].split_at_mut(n);
            for k in 0..n {
                let column = |side: Side, p| match side.body() {
                    Some(i) => kin.point_jacobian_column(scene, i, p, k),
                    None => [zero; 2],
                };
                let (ja, jb) = (column(pair.a, c.point_a), column(pair.b, c.point_b));
                let rel = [jb[0] - ja[0], jb[1] - ja[1]];
                let normal = c.normal[0] * rel[0] + c.normal[1] * rel[1];
                let tangent = (t[0] * rel[0] + t[1] * rel[1]) * pair.friction;
                plus[k] = normal + tangent;
                minus[k] = normal - tangent;
            }
            d.push(c.distance);
            d.push(c.distance);
        }
        Ok(())
    }
}
