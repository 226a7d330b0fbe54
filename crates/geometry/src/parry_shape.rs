//! The ellipse as a parry shape: support map, ray cast, point query, bounding volumes and mass properties,
//! so that parry's queries (GJK distance, GJK/EPA contact, intersection tests) and the dimforge ecosystem
//! run on it. Ray casts and point projections are exact; the pairwise queries are parry's own.

use crate::gap::{Gap, GapBody};
use crate::signed_distance::{PoseCoords, check_pose, pose_from_coords};
use crate::{Ellipse, GeometryError};
use parry2d_f64::bounding_volume::{Aabb, BoundingSphere};
use parry2d_f64::mass_properties::MassProperties;
use parry2d_f64::math::{Pose, Real, Vector};
use parry2d_f64::query::details::{
    contact_support_map_support_map, intersection_test_support_map_support_map,
};
use parry2d_f64::query::{PointProjection, PointQuery, Ray, RayCast, RayIntersection};
use parry2d_f64::shape::{FeatureId, Shape, ShapeType, SupportMap, TypedShape};

impl SupportMap for Ellipse {
    fn local_support_point(&self, dir: Vector) -> Vector {
        let len = dir.length();
        if !(len > 0.0 && len.is_finite()) {
            return Vector::ZERO;
        }
        let [x, y] = self.support_point_local(dir.x / len, dir.y / len);
        Vector::new(x, y)
    }
}

impl RayCast for Ellipse {
    fn cast_local_ray_and_get_normal(
        &self,
        ray: &Ray,
        max_time_of_impact: Real,
        solid: bool,
    ) -> Option<RayIntersection> {
        // In coordinates scaled by the semi-axes the ellipse is the unit circle.
        let (a, b) = (self.a(), self.b());
        let o = Vector::new(ray.origin.x / a, ray.origin.y / b);
        let d = Vector::new(ray.dir.x / a, ray.dir.y / b);
        let qa = d.length_squared();
        let qb = o.dot(d);
        let qc = o.length_squared() - 1.0;
        let outward = |t: Real| {
            let p = ray.origin + ray.dir * t;
            Vector::new(p.x / (a * a), p.y / (b * b)).normalize_or_zero()
        };
        if qc <= 0.0 {
            // The origin is inside.
            if solid {
                return Some(RayIntersection::new(0.0, Vector::ZERO, FeatureId::Face(0)));
            }
            if qa == 0.0 {
                return None;
            }
            let t = (-qb + (qb * qb - qa * qc).max(0.0).sqrt()) / qa;
            return (t <= max_time_of_impact)
                .then(|| RayIntersection::new(t, -outward(t), FeatureId::Face(0)));
        }
        let disc = qb * qb - qa * qc;
        if qa == 0.0 || qb >= 0.0 || disc < 0.0 {
            return None;
        }
        // Entry root, in the cancellation-free form c / (-b + sqrt(disc)).
        let t = qc / (-qb + disc.sqrt());
        (t <= max_time_of_impact).then(|| RayIntersection::new(t, outward(t), FeatureId::Face(0)))
    }
}

impl PointQuery for Ellipse {
    fn project_local_point(&self, pt: Vector, solid: bool) -> PointProjection {
        let inside = self.contains_local(pt.x, pt.y);
        if inside && solid {
            return PointProjection::new(true, pt);
        }
        // The nearest boundary point is the support point at the minimum of the gap to a point.
        let gap = Gap::new(
            [0.0, 0.0],
            GapBody::ellipse(self, 0.0),
            [pt.x, pt.y],
            GapBody::point(),
        );
        let min = gap.minimise(pt.y.atan2(pt.x));
        let [x, y] = gap.a.support_offset(min.jet.cos, min.jet.sin);
        PointProjection::new(inside, Vector::new(x, y))
    }

    fn project_local_point_and_get_feature(&self, pt: Vector) -> (PointProjection, FeatureId) {
        (self.project_local_point(pt, false), FeatureId::Face(0))
    }

    fn contains_local_point(&self, pt: Vector) -> bool {
        self.contains_local(pt.x, pt.y)
    }
}

impl Shape for Ellipse {
    fn compute_local_aabb(&self) -> Aabb {
        Aabb::new(
            Vector::new(-self.a(), -self.b()),
            Vector::new(self.a(), self.b()),
        )
    }

    fn compute_aabb(&self, position: &Pose) -> Aabb {
        // Exact: the half-widths are the support values along the world axes.
        let (c, s) = (position.rotation.re, position.rotation.im);
        let half = Vector::new(self.support_value(c, -s), self.support_value(s, c));
        Aabb::new(position.translation - half, position.translation + half)
    }

    fn compute_local_bounding_sphere(&self) -> BoundingSphere {
        BoundingSphere::new(Vector::ZERO, self.max_axis())
    }

    fn clone_dyn(&self) -> Box<dyn Shape> {
        Box::new(*self)
    }

    fn scale_dyn(&self, scale: Vector, _num_subdivisions: u32) -> Option<Box<dyn Shape>> {
        Ellipse::new(self.a() * scale.x.abs(), self.b() * scale.y.abs())
            .ok()
            .map(|e| Box::new(e) as Box<dyn Shape>)
    }

    fn mass_properties(&self, density: Real) -> MassProperties {
        MassProperties::new(
            Vector::ZERO,
            density * self.area(),
            density * self.unit_inertia(),
        )
    }

    fn shape_type(&self) -> ShapeType {
        ShapeType::Custom
    }

    fn as_typed_shape(&self) -> TypedShape<'_> {
        TypedShape::Custom(self)
    }

    fn ccd_thickness(&self) -> Real {
        self.a().min(self.b())
    }

    fn ccd_angular_thickness(&self) -> Real {
        std::f64::consts::FRAC_PI_2
    }

    fn is_convex(&self) -> bool {
        true
    }

    fn as_support_map(&self) -> Option<&dyn SupportMap> {
        Some(self)
    }
}

/// What parry's own GJK/EPA says about two posed ellipses, in world coordinates (the cross-check and the
/// baseline of the speed-against-error table).
#[derive(Debug, Clone, Copy)]
pub struct ParryEstimate {
    /// GJK distance when apart, minus the EPA depth when overlapping.
    pub distance: f64,
    /// Point on A.
    pub point_a: Vector,
    /// Point on B.
    pub point_b: Vector,
    /// Normal from A to B.
    pub normal: Vector,
    /// parry's intersection test.
    pub intersecting: bool,
}

/// Runs parry's GJK/EPA contact query and intersection test on two posed ellipses.
/// `Ok(None)` when parry returns no contact.
pub fn parry_estimate(
    a: &Ellipse,
    pose_a: PoseCoords,
    b: &Ellipse,
    pose_b: PoseCoords,
) -> Result<Option<ParryEstimate>, GeometryError> {
    check_pose("A", pose_a)?;
    check_pose("B", pose_b)?;
    let pa = pose_from_coords(pose_a);
    let pb = pose_from_coords(pose_b);
    let pos12 = pa.inv_mul(&pb);
    let reach =
        4.0 * (a.max_axis() + b.max_axis()) + (pose_a[0] - pose_b[0]).hypot(pose_a[1] - pose_b[1]);
    let intersecting = intersection_test_support_map_support_map(&pos12, a, b);
    Ok(
        contact_support_map_support_map(&pos12, a, b, reach).map(|c| ParryEstimate {
            distance: c.dist,
            point_a: pa.transform_point(c.point1),
            point_b: pb.transform_point(c.point2),
            normal: pa.rotation * c.normal1,
            intersecting,
        }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use parry2d_f64::query;

    #[test]
    fn parry_distance_query_runs_on_ellipses() {
        let a = Ellipse::new(1.0, 0.5).unwrap();
        let b = Ellipse::new(0.7, 0.5).unwrap();
        let pa = Pose::new(Vector::new(0.0, 0.0), 0.0);
        let pb = Pose::new(Vector::new(3.0, 0.0), 0.0);
        let d = query::distance(&pa, &a, &pb, &b).unwrap().distance;
        assert!((d - 1.3).abs() < 1e-6, "{d}");
        assert!(
            query::intersection_test(&pa, &a, &pa, &b)
                .unwrap()
                .intersecting
        );
    }

    #[test]
    fn ray_cast_hits_the_boundary_exactly() {
        let e = Ellipse::new(2.0, 0.5).unwrap();
        let ray = Ray::new(Vector::new(-5.0, 0.3), Vector::new(1.0, 0.0));
        let hit = e.cast_local_ray_and_get_normal(&ray, 100.0, true).unwrap();
        let p = ray.point_at(hit.time_of_impact);
        assert!(((p.x / 2.0).powi(2) + (p.y / 0.5).powi(2) - 1.0).abs() < 1e-15);
        assert!(hit.normal.x < 0.0);
        let inside = Ray::new(Vector::ZERO, Vector::new(0.0, 1.0));
        assert_eq!(e.cast_local_ray(&inside, 10.0, true), Some(0.0));
        let exit = e.cast_local_ray(&inside, 10.0, false).unwrap();
        assert!((exit - 0.5).abs() < 1e-15);
        let away = Ray::new(Vector::new(-5.0, 0.0), Vector::new(-1.0, 0.0));
        assert!(e.cast_local_ray(&away, 100.0, true).is_none());
    }

    #[test]
    fn point_projection_is_the_nearest_boundary_point() {
        let e = Ellipse::new(1.5, 0.2).unwrap();
        for &(x, y) in &[
            (2.0, 1.0),
            (0.1, 0.05),
            (-3.0, -0.01),
            (0.0, 0.0),
            (0.3, 0.9),
        ] {
            let proj = e.project_local_point(Vector::new(x, y), false);
            let best = (0..200_000)
                .map(|k| {
                    let t = k as f64 * std::f64::consts::TAU / 200_000.0;
                    (1.5 * t.cos() - x).hypot(0.2 * t.sin() - y)
                })
                .fold(f64::INFINITY, f64::min);
            let got = (proj.point.x - x).hypot(proj.point.y - y);
            assert!(
                got <= best + 1e-12 && got >= best - 1e-6,
                "({x},{y}): {got} vs {best}"
            );
            assert_eq!(proj.is_inside, e.contains_local(x, y));
        }
    }

    #[test]
    fn aabb_is_tight() {
        let e = Ellipse::new(1.0, 0.25).unwrap();
        let pose = Pose::new(Vector::new(1.0, -2.0), 0.7);
        let aabb = e.compute_aabb(&pose);
        let (mut lo, mut hi) = (
            Vector::splat(f64::INFINITY),
            Vector::splat(f64::NEG_INFINITY),
        );
        for k in 0..100_000 {
            let t = k as f64 * std::f64::consts::TAU / 100_000.0;
            let p = pose.transform_point(Vector::new(t.cos(), 0.25 * t.sin()));
            lo = lo.min(p);
            hi = hi.max(p);
        }
        assert!((aabb.mins - lo).length() < 1e-8 && (aabb.maxs - hi).length() < 1e-8);
        assert!(aabb.mins.x <= lo.x && aabb.maxs.y >= hi.y);
    }

    #[test]
    fn mass_properties_follow_density_one() {
        let e = Ellipse::new(0.8, 0.25).unwrap();
        let m = e.mass_properties(1.0);
        assert!((m.mass() - std::f64::consts::PI * 0.2).abs() < 1e-15);
        assert!((m.principal_inertia() - m.mass() * (0.64 + 0.0625) / 4.0).abs() < 1e-15);
    }
}
