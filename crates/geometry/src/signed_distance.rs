//! Signed distance between two posed ellipses, witness points, normal, and their exact derivatives.
//!
//! Conventions are SCENE.md's (Constraints): `d` is the Euclidean gap when apart and minus the penetration
//! depth when overlapping, `normal` points from A to B, `point_a` and `point_b` are the support points of
//! A along `normal` and of B along `-normal`, and `point_b = point_a + d * normal`.
//!
//! Derivatives are taken with respect to the pose coordinates `p = (x_A, y_A, theta_A, x_B, y_B, theta_B)`.
//! The distance is `d(p) = -F(phi*(p), p)` where `phi*` minimises the support gap (see `gap.rs`), so by the
//! envelope theorem `grad d = -F_p`, and by the implicit function theorem on `F_phi = 0`,
//! `phi*_p = -F_phi_p / F_phi_phi` and `hess d = -(F_pp - F_phi_p F_phi_p^T / F_phi_phi)`.

use crate::gap::{Gap, GapBody, GapJet, GapMinimum};
use crate::scalar::Forward;
use crate::{Ellipse, GeometryError};
use parry2d_f64::math::{Pose, Vector};

/// Pose coordinates `[x, y, theta]` of a planar body.
pub type PoseCoords = [f64; 3];

/// The six pose coordinates `(x_A, y_A, theta_A, x_B, y_B, theta_B)` that derivatives are taken against.
pub const POSE_COORDINATES: usize = 6;

/// Reads `[x, y, theta]` off a parry pose (theta in `(-pi, pi]`).
pub fn pose_coords(pose: &Pose) -> PoseCoords {
    [
        pose.translation.x,
        pose.translation.y,
        pose.rotation.angle(),
    ]
}

/// A parry pose from `[x, y, theta]`.
pub fn pose_from_coords(p: PoseCoords) -> Pose {
    Pose::new(Vector::new(p[0], p[1]), p[2])
}

/// Closest (or deepest) points of two ellipses: the answer to [`signed_distance`].
#[derive(Debug, Clone, Copy)]
pub struct Contact {
    /// Signed distance: positive apart, minus the penetration depth when overlapping.
    pub distance: f64,
    /// Witness point on the boundary of A (the support point of A along `normal`).
    pub point_a: Vector,
    /// Witness point on the boundary of B (the support point of B along `-normal`).
    pub point_b: Vector,
    /// Unit normal from A to B.
    pub normal: Vector,
    /// False where the witnesses are not unique (concentric shapes, or two equally deep escape
    /// directions); the distance is still exact, the witnesses and normal are one valid choice, and the
    /// distance is not differentiable there.
    pub witness_unique: bool,
    /// False only if the global search ran out of its evaluation budget (never seen in testing); the answer
    /// is then the best local minimum found.
    pub certified: bool,
    /// Evaluations of the support gap that the search took (a cost measure).
    pub evaluations: usize,
    jet: GapJet,
    centers: [[f64; 2]; 2],
}

/// First and second derivatives of a [`Contact`] with respect to both poses
/// `p = (x_A, y_A, theta_A, x_B, y_B, theta_B)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactDerivatives {
    /// `d d / d p`.
    pub gradient: [f64; 6],
    /// `d^2 d / d p^2` (symmetric).
    pub hessian: [[f64; 6]; 6],
    /// `d normal / d p`, rows x and y.
    pub normal: [[f64; 6]; 2],
    /// `d point_a / d p`, rows x and y.
    pub point_a: [[f64; 6]; 2],
    /// `d point_b / d p`, rows x and y.
    pub point_b: [[f64; 6]; 2],
}

pub(crate) fn check_pose(shape: &'static str, p: PoseCoords) -> Result<(), GeometryError> {
    for (coordinate, value) in ["x", "y", "theta"].into_iter().zip(p) {
        if !value.is_finite() {
            return Err(GeometryError::Pose {
                shape,
                coordinate,
                value,
            });
        }
    }
    Ok(())
}

/// Signed distance between ellipse `a` at `pose_a` and ellipse `b` at `pose_b`, exact to rounding.
///
/// The search starts from the line of centres: if that direction separates the shapes, a Newton descent on
/// the support gap is globally convergent; otherwise a branch and bound certifies the global minimum.
/// (parry's GJK/EPA start was measured slower than the whole certified search; see docs/benchmarks.md.)
pub fn signed_distance(
    a: &Ellipse,
    pose_a: &Pose,
    b: &Ellipse,
    pose_b: &Pose,
) -> Result<Contact, GeometryError> {
    signed_distance_coords(a, pose_coords(pose_a), b, pose_coords(pose_b))
}

/// [`signed_distance`] with poses given as `[x, y, theta]`.
pub fn signed_distance_coords(
    a: &Ellipse,
    pose_a: PoseCoords,
    b: &Ellipse,
    pose_b: PoseCoords,
) -> Result<Contact, GeometryError> {
    check_pose("A", pose_a)?;
    check_pose("B", pose_b)?;
    let center_a = [pose_a[0], pose_a[1]];
    let center_b = [pose_b[0], pose_b[1]];
    let gap = Gap::new(
        center_a,
        GapBody::ellipse(a, pose_a[2]),
        center_b,
        GapBody::ellipse(b, pose_b[2]),
    );
    // The line of centres separates most apart pairs at once; otherwise the search is global anyway.
    let line = (center_b[1] - center_a[1]).atan2(center_b[0] - center_a[0]);
    let min = gap.minimise(line);
    Ok(Contact::from_minimum(&gap, [center_a, center_b], &min))
}

impl Contact {
    pub(crate) fn from_minimum(gap: &Gap, centers: [[f64; 2]; 2], min: &GapMinimum) -> Self {
        let jet = min.jet;
        let (c, s) = (jet.cos, jet.sin);
        let oa = gap.a.support_offset(c, s);
        let ob = gap.b.support_offset(-c, -s);
        Contact {
            distance: -jet.f,
            point_a: Vector::new(centers[0][0] + oa[0], centers[0][1] + oa[1]),
            point_b: Vector::new(centers[1][0] + ob[0], centers[1][1] + ob[1]),
            normal: Vector::new(c, s),
            witness_unique: !min.tie,
            certified: min.certified,
            evaluations: min.evaluations,
            jet,
            centers,
        }
    }

    /// Angle of the normal, `normal = (cos, sin)` of it.
    pub fn normal_angle(&self) -> f64 {
        self.jet.phi
    }

    /// `d F' / d phi` at the solution: `rho_A + rho_B + d`, the curvature of the support gap. Small values
    /// mean ill-conditioned witnesses (nearly parallel flat sides, near-concentric shapes).
    pub fn gap_curvature(&self) -> f64 {
        self.jet.ddf
    }

    /// Gradient of the distance with respect to `(x_A, y_A, theta_A, x_B, y_B, theta_B)`:
    /// `-F_p = (-n, h_A'(psi_A), n, h_B'(psi_B))`, which equals `n^T (J_B(p_B) - J_A(p_A))` of SCENE.md.
    pub fn gradient(&self) -> [f64; 6] {
        let (c, s) = (self.jet.cos, self.jet.sin);
        [-c, -s, self.jet.a.dh, c, s, self.jet.b.dh]
    }

    /// Gradient, Hessian, and the first derivatives of the normal and both witness points.
    ///
    /// Where the gap curvature vanishes (concentric circles) the witnesses do not move with the poses to first
    /// order in any well-defined way; the angle's derivative is then taken as zero rather than infinite.
    pub fn derivatives(&self) -> ContactDerivatives {
        let j = &self.jet;
        let (c, s) = (j.cos, j.sin);
        let t = [-s, c];
        // F_phi_p and F_pp.
        let f_phi_p = [-s, c, -j.a.ddh(), s, -c, -j.b.ddh()];
        let ddf = j.ddf;
        let inv_ddf = if ddf > f64::EPSILON * (j.a.rho + j.b.rho + j.f.abs()) {
            1.0 / ddf
        } else {
            0.0
        };
        let phi_p = f_phi_p.map(|v| -v * inv_ddf);
        // hess d = F_phi_p F_phi_p^T / F_phi_phi - F_pp; the products commute exactly, so it is symmetric.
        let mut hessian = [[0.0; 6]; 6];
        for (row, fr) in hessian.iter_mut().zip(f_phi_p) {
            for (h, fk) in row.iter_mut().zip(f_phi_p) {
                *h = fr * fk * inv_ddf;
            }
        }
        // F_pp is non-zero only in the two rotation diagonals.
        hessian[2][2] -= j.a.ddh();
        hessian[5][5] -= j.b.ddh();
        let mut normal = [[0.0; 6]; 2];
        for k in 0..6 {
            normal[0][k] = t[0] * phi_p[k];
            normal[1][k] = t[1] * phi_p[k];
        }
        // p_A moves with c_A, rotates with theta_A at fixed phi (J (p_A - c_A) - rho_A t), slides with phi (rho_A t).
        let ra = [
            self.point_a.x - self.centers[0][0],
            self.point_a.y - self.centers[0][1],
        ];
        let rb = [
            self.point_b.x - self.centers[1][0],
            self.point_b.y - self.centers[1][1],
        ];
        let mut point_a = [[0.0; 6]; 2];
        let mut point_b = [[0.0; 6]; 2];
        for i in 0..2 {
            let jr_a = if i == 0 { -ra[1] } else { ra[0] };
            let jr_b = if i == 0 { -rb[1] } else { rb[0] };
            for k in 0..6 {
                point_a[i][k] = j.a.rho * t[i] * phi_p[k];
                point_b[i][k] = -j.b.rho * t[i] * phi_p[k];
            }
            point_a[i][i] += 1.0;
            point_a[i][2] += jr_a - j.a.rho * t[i];
            point_b[i][3 + i] += 1.0;
            point_b[i][5] += jr_b + j.b.rho * t[i];
        }
        ContactDerivatives {
            gradient: self.gradient(),
            hessian,
            normal,
            point_a,
            point_b,
        }
    }
}

/// The contact of [`signed_distance_dual`]: every field carries the derivatives of its scalar type.
#[derive(Debug, Clone, Copy)]
pub struct DualContact<T> {
    /// Signed distance.
    pub distance: T,
    /// Witness point on A.
    pub point_a: [T; 2],
    /// Witness point on B.
    pub point_b: [T; 2],
    /// Unit normal from A to B.
    pub normal: [T; 2],
    /// As [`Contact::witness_unique`]; where false, the derivative parts are those of one witness choice.
    pub witness_unique: bool,
    /// What the search found, for another scalar type's pass at the same poses
    /// ([`signed_distance_dual_seeded`]); `None` for a half-plane, whose contact is closed form.
    pub seed: Option<ContactSeed>,
}

/// Signed distance with poses in any forward-mode dual number type of `num-dual` (first, second or third
/// order, scalar or vector directions): the result carries exact derivatives of the distance, the normal
/// and both witness points to that order.
///
/// The minimising angle is found in `f64`, then refined by Newton steps on `F'(phi, p) = 0` in the dual type:
/// each step doubles the number of exact derivative orders (one step is exact to first order, two to third),
/// because the real part is already converged.
pub fn signed_distance_dual<T: Forward>(
    a: &Ellipse,
    pose_a: [T; 3],
    b: &Ellipse,
    pose_b: [T; 3],
) -> Result<DualContact<T>, GeometryError> {
    signed_distance_dual_posed(a, &DualPose::new(pose_a), b, &DualPose::new(pose_b))
}

/// A pose `[x, y, angle]` in a forward-mode scalar with the sine and cosine of its angle, computed once
/// by whoever has them (a kinematics pass turns every body's frame by them already).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DualPose<T> {
    /// `[x, y, angle]`.
    pub pose: [T; 3],
    /// `(sin, cos)` of the angle: exactly `pose[2].sin_and_cos()`.
    pub turn: (T, T),
}

impl<T: Forward> DualPose<T> {
    /// The pose, its angle's sine and cosine computed here.
    pub fn new(pose: [T; 3]) -> Self {
        DualPose {
            pose,
            turn: pose[2].sin_and_cos(),
        }
    }

    /// The pose with its angle's sine and cosine as the caller computed them (`pose[2].sin_and_cos()`,
    /// checked in debug builds).
    pub fn turned(pose: [T; 3], turn: (T, T)) -> Self {
        debug_assert!({
            let (s, c) = pose[2].sin_and_cos();
            s.value() == turn.0.value() && c.value() == turn.1.value()
        });
        DualPose { pose, turn }
    }
}

/// [`signed_distance_dual`] of poses whose angles' sines and cosines are known ([`DualPose`]): the
/// same arithmetic, without evaluating them again.
pub fn signed_distance_dual_posed<T: Forward>(
    a: &Ellipse,
    posed_a: &DualPose<T>,
    b: &Ellipse,
    posed_b: &DualPose<T>,
) -> Result<DualContact<T>, GeometryError> {
    let re = |p: [T; 3]| [p[0].value(), p[1].value(), p[2].value()];
    let seed = ContactSeed::find(a, re(posed_a.pose), b, re(posed_b.pose))?;
    Ok(signed_distance_dual_seeded(a, posed_a, b, posed_b, &seed))
}

/// What the search in `f64` found for a pair at the poses' values: the minimising angle of the support
/// gap, whether Newton steps on it may refine the dual parts (a strictly convex minimum), and whether the
/// witnesses are unique. [`signed_distance_dual_seeded`] finishes from it in any scalar type without
/// searching again: a caller that computed the contact in `f64` at the same poses (a simulator's step)
/// hands its seed to the derivative passes at those poses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactSeed {
    angle: f64,
    refine: bool,
    witness_unique: bool,
}

impl ContactSeed {
    /// The certified search of [`signed_distance_coords`] at these poses.
    pub fn find(
        a: &Ellipse,
        pose_a: PoseCoords,
        b: &Ellipse,
        pose_b: PoseCoords,
    ) -> Result<Self, GeometryError> {
        let base = signed_distance_coords(a, pose_a, b, pose_b)?;
        let jet = base.jet;
        Ok(ContactSeed {
            angle: jet.phi,
            refine: jet.ddf > f64::EPSILON * (jet.a.rho + jet.b.rho + jet.f.abs()),
            witness_unique: base.witness_unique,
        })
    }
}

/// [`signed_distance_dual_posed`] from the seed the search found at the poses' values
/// ([`ContactSeed::find`] at exactly `posed_a.pose` and `posed_b.pose`'s values: the same result to the
/// bit as searching again; a seed found elsewhere gives the contact of another angle).
pub fn signed_distance_dual_seeded<T: Forward>(
    a: &Ellipse,
    posed_a: &DualPose<T>,
    b: &Ellipse,
    posed_b: &DualPose<T>,
    seed: &ContactSeed,
) -> DualContact<T> {
    let (pose_a, pose_b) = (posed_a.pose, posed_b.pose);
    let steps = match T::ORDER {
        0 => 0,
        1 => 1,
        2 | 3 => 2,
        _ => 3,
    };
    let delta = [pose_a[0] - pose_b[0], pose_a[1] - pose_b[1]];
    // Each body's orientation as (sin, cos), shared by every support evaluation below.
    let (turn_a, turn_b) = (posed_a.turn, posed_b.turn);
    let mut phi = T::from(seed.angle);
    if seed.refine {
        for _ in 0..steps {
            let (s, c) = phi.sin_and_cos();
            let (ha, dha, ddha) = dual_support(a, turn_a, c, s);
            let (hb, dhb, ddhb) = dual_support(b, turn_b, c, s);
            let f = c * delta[0] + s * delta[1] + ha + hb;
            let df = -s * delta[0] + c * delta[1] + dha + dhb;
            // F'' = rho_A + rho_B - F, with rho = h'' + h.
            let ddf = (ddha + ha) + (ddhb + hb) - f;
            phi -= df / ddf;
        }
    }
    let (s, c) = phi.sin_and_cos();
    let (la, ha) = dual_support_point(a, turn_a, c, s);
    let (lb, hb) = dual_support_point(b, turn_b, -c, -s);
    let f = c * delta[0] + s * delta[1] + ha + hb;
    DualContact {
        distance: -f,
        point_a: [pose_a[0] + la[0], pose_a[1] + la[1]],
        point_b: [pose_b[0] + lb[0], pose_b[1] + lb[1]],
        normal: [c, s],
        witness_unique: seed.witness_unique,
        seed: Some(*seed),
    }
}

/// A half-plane `{x : n . (x - point) <= 0}`: everything on the far side of a line (ground, a wall), with
/// `n` the unit normal out of it (towards the free side).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HalfPlane {
    point: [f64; 2],
    normal: [f64; 2],
}

impl HalfPlane {
    /// The half-plane whose boundary passes through `point`, with outward normal along `normal` (any
    /// length above zero; it is normalised). An error for a non-finite entry or a zero normal.
    pub fn new(point: [f64; 2], normal: [f64; 2]) -> Result<Self, GeometryError> {
        let len = normal[0].hypot(normal[1]);
        if !(point.iter().all(|v| v.is_finite()) && len.is_finite() && len > 0.0) {
            return Err(GeometryError::InvalidHalfPlane { point, normal });
        }
        Ok(HalfPlane {
            point,
            normal: [normal[0] / len, normal[1] / len],
        })
    }

    /// A point of the boundary line.
    pub fn point(&self) -> [f64; 2] {
        self.point
    }

    /// The unit outward normal.
    pub fn normal(&self) -> [f64; 2] {
        self.normal
    }
}

/// Signed distance from a half-plane (A) to an ellipse at `pose_b` (B), in any forward-mode scalar:
/// `d = n . (c_B - p) - h_B(-n)`, the height above the boundary of the ellipse's lowest point, in closed
/// form (no search: the pair is smooth everywhere, and the witness is always unique). The normal is the
/// plane's, from A to B; the witness on B is the ellipse's support point along `-n`, the one on A its
/// projection onto the boundary.
pub fn half_plane_distance_dual<T: Forward>(
    plane: &HalfPlane,
    b: &Ellipse,
    pose_b: [T; 3],
) -> Result<DualContact<T>, GeometryError> {
    half_plane_distance_dual_posed(plane, b, &DualPose::new(pose_b))
}

/// [`half_plane_distance_dual`] of a pose whose angle's sine and cosine are known ([`DualPose`]).
pub fn half_plane_distance_dual_posed<T: Forward>(
    plane: &HalfPlane,
    b: &Ellipse,
    posed_b: &DualPose<T>,
) -> Result<DualContact<T>, GeometryError> {
    let pose_b = posed_b.pose;
    check_pose(
        "B",
        [pose_b[0].value(), pose_b[1].value(), pose_b[2].value()],
    )?;
    let [nx, ny] = plane.normal;
    let (c, s) = (T::from(-nx), T::from(-ny));
    let (offset, h) = dual_support_point(b, posed_b.turn, c, s);
    let lowest = [pose_b[0] + offset[0], pose_b[1] + offset[1]];
    let distance = (pose_b[0] + (-plane.point[0])) * nx + (pose_b[1] + (-plane.point[1])) * ny - h;
    Ok(DualContact {
        distance,
        point_a: [lowest[0] - distance * nx, lowest[1] - distance * ny],
        point_b: lowest,
        normal: [T::from(nx), T::from(ny)],
        witness_unique: true,
        seed: None,
    })
}

/// The support function's value and first two angle derivatives, `(h, h', h'')`, of an ellipse whose
/// orientation has sine and cosine `(st, ct)`, along the world direction `(c, s)`: what a Newton step on
/// the angle needs. [`dual_support_point`] gives the offset of the supporting point with the same `h`.
fn dual_support<T: Forward>(e: &Ellipse, (st, ct): (T, T), c: T, s: T) -> (T, T, T) {
    let (bc, bs, h) = support_norm(e, (st, ct), c, s);
    let (a2, b2) = (e.a() * e.a(), e.b() * e.b());
    let dh = bc * bs * (b2 - a2) / h;
    let rho = T::from(a2 * b2) / (h * h * h);
    (h, dh, rho - h)
}

/// The world-frame offset of the supporting point and the support function's value along `(c, s)` (see
/// [`dual_support`]; each evaluates only what its caller reads, the same arithmetic as together).
fn dual_support_point<T: Forward>(e: &Ellipse, (st, ct): (T, T), c: T, s: T) -> ([T; 2], T) {
    let (bc, bs, h) = support_norm(e, (st, ct), c, s);
    let (a2, b2) = (e.a() * e.a(), e.b() * e.b());
    let (lx, ly) = (bc * a2 / h, bs * b2 / h);
    ([ct * lx - st * ly, st * lx + ct * ly], h)
}

/// The direction `(c, s)` in the ellipse's frame, `(bc, bs)`, and the support value there.
#[inline(always)]
fn support_norm<T: Forward>(e: &Ellipse, (st, ct): (T, T), c: T, s: T) -> (T, T, T) {
    let bc = c * ct + s * st;
    let bs = s * ct - c * st;
    let (a2, b2) = (e.a() * e.a(), e.b() * e.b());
    let h = (bc * bc * a2 + bs * bs * b2).square_root();
    (bc, bs, h)
}
