//! Exact geometry of planar ellipses for the contact simulator: signed distance, witness points, normals,
//! and their first and second derivatives with respect to both poses.
//!
//! The contact constraint `d(q) >= 0` of the paper (section III-A, eq. 1c) and of SCENE.md (Constraints)
//! needs `d`, its gradient `J = grad d` and, for exact step derivatives, the derivatives of the witness
//! points and normal that build the friction rows. Everything here is computed from the support gap
//! `F(phi) = h_A(n) + h_B(-n)`, whose global minimum over the normal angle is `-d` (see `gap.rs`); no
//! distance is ever differentiated numerically.
//!
//! [`Ellipse`] is a parry shape (support map, ray cast, point query, mass properties), so parry's GJK/EPA
//! queries run on it; they supply the start of the search when the line of centres does not separate the
//! shapes, and serve as the independent cross-check in the tests.
//!
//! ```
//! use geometry::{signed_distance_coords, Ellipse};
//! let finger = Ellipse::new(0.8, 0.25)?;
//! let free = Ellipse::new(0.7, 0.5)?;
//! let c = signed_distance_coords(&finger, [0.0, -1.0, -1.2], &free, [0.0, -3.0, 0.3])?;
//! assert!(c.distance > 0.0 && c.witness_unique);
//! let p = c.point_a + c.distance * c.normal;
//! assert!((p - c.point_b).length() < 1e-13);
//! # Ok::<(), geometry::GeometryError>(())
//! ```

mod ellipse;
mod error;
mod gap;
mod parry_shape;
mod scalar;
mod signed_distance;

pub use ellipse::{Ellipse, SEMI_AXIS_RANGE};
pub use error::GeometryError;
pub use parry_shape::{ParryEstimate, parry_estimate};
pub use parry2d_f64;
pub use parry2d_f64::math::{Pose, Vector};
pub use scalar::Forward;
pub use signed_distance::{
    Contact, ContactDerivatives, ContactSeed, DualContact, DualPose, HalfPlane, POSE_COORDINATES,
    PoseCoords, half_plane_distance_dual, half_plane_distance_dual_posed, pose_coords,
    pose_from_coords, signed_distance, signed_distance_coords, signed_distance_dual,
    signed_distance_dual_posed, signed_distance_dual_seeded,
};

/// The README's examples, compiled and run as doctests so that they cannot go stale.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
