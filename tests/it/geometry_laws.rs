//! Laws of the signed distance that hold for all inputs (proptest), and hard configurations on purpose.

use geometry::{Ellipse, parry_estimate, signed_distance_coords, signed_distance_dual};
use num_dual::{Dual64, DualStruct, HyperDual64};
use proptest::prelude::*;

fn ellipse() -> impl Strategy<Value = Ellipse> {
    (0.05_f64..2.0, 0.05_f64..2.0).prop_map(|(a, b)| Ellipse::new(a, b).unwrap())
}

fn pose() -> impl Strategy<Value = [f64; 3]> {
    (-2.0_f64..2.0, -2.0_f64..2.0, -4.0_f64..4.0).prop_map(|(x, y, t)| [x, y, t])
}

/// Oracle: `d = -min_phi [h_A(n) + h_B(-n)]` by a dense scan refined by golden sections (independent of the
/// crate's search).
fn oracle(a: &Ellipse, pa: [f64; 3], b: &Ellipse, pb: [f64; 3]) -> f64 {
    let h = |e: &Ellipse, t: f64, c: f64, s: f64| {
        let (bc, bs) = (c * t.cos() + s * t.sin(), s * t.cos() - c * t.sin());
        ((e.a() * bc).powi(2) + (e.b() * bs).powi(2)).sqrt()
    };
    let f = |phi: f64| {
        let (c, s) = (phi.cos(), phi.sin());
        c * (pa[0] - pb[0]) + s * (pa[1] - pb[1]) + h(a, pa[2], c, s) + h(b, pb[2], c, s)
    };
    let n = 20_000;
    let step = std::f64::consts::TAU / n as f64;
    let mut best = (f64::INFINITY, 0.0);
    for k in 0..n {
        let phi = k as f64 * step;
        let v = f(phi);
        if v < best.0 {
            best = (v, phi);
        }
    }
    let (mut lo, mut hi) = (best.1 - step, best.1 + step);
    for _ in 0..100 {
        let m1 = lo + (hi - lo) * 0.382;
        let m2 = lo + (hi - lo) * 0.618;
        if f(m1) < f(m2) { hi = m2 } else { lo = m1 }
    }
    -f(0.5 * (lo + hi)).min(best.0)
}

fn rigid(p: [f64; 3], angle: f64, shift: [f64; 2]) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    [
        c * p[0] - s * p[1] + shift[0],
        s * p[0] + c * p[1] + shift[1],
        p[2] + angle,
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(
        std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(64)))]

    #[test]
    fn swapping_the_shapes_keeps_distance_and_swaps_witnesses(a in ellipse(), pa in pose(), b in ellipse(), pb in pose()) {
        let ab = signed_distance_coords(&a, pa, &b, pb).unwrap();
        let ba = signed_distance_coords(&b, pb, &a, pa).unwrap();
        let size = a.max_axis().max(b.max_axis());
        prop_assert!((ab.distance - ba.distance).abs() <= 1e-12 * size);
        if ab.witness_unique && ab.gap_curvature() > 1e-3 {
            prop_assert!((ab.point_a - ba.point_b).length() <= 1e-9 * size);
            prop_assert!((ab.normal + ba.normal).length() <= 1e-9);
        }
    }

    #[test]
    fn a_common_rigid_motion_changes_nothing_but_the_frame(
        a in ellipse(), pa in pose(), b in ellipse(), pb in pose(),
        angle in -3.0_f64..3.0, sx in -5.0_f64..5.0, sy in -5.0_f64..5.0,
    ) {
        let before = signed_distance_coords(&a, pa, &b, pb).unwrap();
        let after = signed_distance_coords(&a, rigid(pa, angle, [sx, sy]), &b, rigid(pb, angle, [sx, sy])).unwrap();
        let size = a.max_axis().max(b.max_axis());
        prop_assert!((before.distance - after.distance).abs() <= 1e-11 * (size + 5.0));
    }

    #[test]
    fn distance_equals_the_support_function_oracle(a in ellipse(), pa in pose(), b in ellipse(), pb in pose()) {
        let got = signed_distance_coords(&a, pa, &b, pb).unwrap().distance;
        let want = oracle(&a, pa, &b, pb);
        // The oracle is a dense scan: it can only be higher (a worse minimum), never meaningfully lower.
        prop_assert!(got >= want - 1e-12, "ours {got} below oracle {want}");
        prop_assert!(got <= want + 1e-9, "ours {got} above oracle {want}");
    }

    #[test]
    fn sign_agrees_with_parry_and_witnesses_lie_on_the_boundaries(a in ellipse(), pa in pose(), b in ellipse(), pb in pose()) {
        let c = signed_distance_coords(&a, pa, &b, pb).unwrap();
        let size = a.max_axis().max(b.max_axis());
        if c.distance.abs() > 1e-6 * size {
            let parry = parry_estimate(&a, pa, &b, pb).unwrap().unwrap();
            prop_assert_eq!(parry.intersecting, c.distance < 0.0);
        }
        let on = |e: &Ellipse, p: [f64; 3], q: geometry::Vector| {
            let (s, co) = p[2].sin_cos();
            let (dx, dy) = (q.x - p[0], q.y - p[1]);
            let (lx, ly) = (co * dx + s * dy, -s * dx + co * dy);
            (lx / e.a()).powi(2) + (ly / e.b()).powi(2) - 1.0
        };
        prop_assert!(on(&a, pa, c.point_a).abs() < 1e-12 * (1.0 + a.max_axis() / a.a().min(a.b())));
        prop_assert!(on(&b, pb, c.point_b).abs() < 1e-12 * (1.0 + b.max_axis() / b.a().min(b.b())));
        prop_assert!((c.point_a + c.distance * c.normal - c.point_b).length() < 1e-11 * size);
    }

    #[test]
    fn normal_is_orthogonal_to_both_tangents_when_apart(a in ellipse(), pa in pose(), b in ellipse(), pb in pose()) {
        let c = signed_distance_coords(&a, pa, &b, pb).unwrap();
        prop_assume!(c.distance > 1e-3);
        // Outward normals of the implicit forms at the witnesses are parallel to +n (A) and -n (B).
        let grad = |e: &Ellipse, p: [f64; 3], q: geometry::Vector| {
            let (s, co) = p[2].sin_cos();
            let (dx, dy) = (q.x - p[0], q.y - p[1]);
            let (lx, ly) = (co * dx + s * dy, -s * dx + co * dy);
            let (gx, gy) = (lx / (e.a() * e.a()), ly / (e.b() * e.b()));
            let v = geometry::Vector::new(co * gx - s * gy, s * gx + co * gy);
            v / v.length()
        };
        prop_assert!(grad(&a, pa, c.point_a).perp_dot(c.normal).abs() < 1e-9);
        prop_assert!(grad(&b, pb, c.point_b).perp_dot(c.normal).abs() < 1e-9);
    }

    #[test]
    fn derivatives_match_central_differences_and_dual_numbers(a in ellipse(), pa in pose(), b in ellipse(), pb in pose()) {
        let c = signed_distance_coords(&a, pa, &b, pb).unwrap();
        prop_assume!(c.witness_unique && c.gap_curvature() > 0.05);
        let d = c.derivatives();
        let coords = |p: &[f64; 6]| ([p[0], p[1], p[2]], [p[3], p[4], p[5]]);
        let p0 = [pa[0], pa[1], pa[2], pb[0], pb[1], pb[2]];
        let eps = 1e-6;
        for k in 0..6 {
            let (mut pp, mut pm) = (p0, p0);
            pp[k] += eps;
            pm[k] -= eps;
            let (ppa, ppb) = coords(&pp);
            let (pma, pmb) = coords(&pm);
            let cp = signed_distance_coords(&a, ppa, &b, ppb).unwrap();
            let cm = signed_distance_coords(&a, pma, &b, pmb).unwrap();
            prop_assume!(cp.witness_unique && cm.witness_unique);
            let fd = (cp.distance - cm.distance) / (2.0 * eps);
            prop_assert!((fd - d.gradient[k]).abs() < 1e-6, "gradient {k}: {fd} vs {}", d.gradient[k]);
            let gp = cp.gradient();
            let gm = cm.gradient();
            for r in 0..6 {
                let fd2 = (gp[r] - gm[r]) / (2.0 * eps);
                prop_assert!((fd2 - d.hessian[r][k]).abs() < 1e-4 * (1.0 + d.hessian[r][k].abs()),
                    "hessian {r},{k}: {fd2} vs {}", d.hessian[r][k]);
            }
            let fdn = (cp.normal - cm.normal) / (2.0 * eps);
            let fdp = (cp.point_a - cm.point_a) / (2.0 * eps);
            let fdq = (cp.point_b - cm.point_b) / (2.0 * eps);
            for (name, fd, an) in [("normal", fdn, d.normal), ("point_a", fdp, d.point_a), ("point_b", fdq, d.point_b)] {
                let err = (fd.x - an[0][k]).abs().max((fd.y - an[1][k]).abs());
                prop_assert!(err < 1e-4 * (1.0 + an[0][k].abs() + an[1][k].abs()), "{name} {k}: {fd:?} vs {:?}", [an[0][k], an[1][k]]);
            }
            // The same derivatives through forward-mode dual numbers.
            let mut da = pa.map(Dual64::from);
            let mut db = pb.map(Dual64::from);
            if k < 3 { da[k].eps = 1.0 } else { db[k - 3].eps = 1.0 }
            let dual = signed_distance_dual(&a, da, &b, db).unwrap();
            prop_assert!((dual.distance.eps - d.gradient[k]).abs() < 1e-10 * (1.0 + d.gradient[k].abs()));
            prop_assert!((dual.normal[0].eps - d.normal[0][k]).abs() < 1e-8 * (1.0 + d.normal[0][k].abs()));
            prop_assert!((dual.point_b[1].eps - d.point_b[1][k]).abs() < 1e-8 * (1.0 + d.point_b[1][k].abs()));
        }
        // Second order through hyper-dual numbers: one mixed entry.
        let mut ha = pa.map(HyperDual64::from);
        let mut hb = pb.map(HyperDual64::from);
        ha[2] = HyperDual64::new(pa[2], 1.0, 0.0, 0.0);
        hb[0] = HyperDual64::new(pb[0], 0.0, 1.0, 0.0);
        let hd = signed_distance_dual(&a, ha, &b, hb).unwrap();
        prop_assert!((hd.distance.eps1eps2 - d.hessian[2][3]).abs() < 1e-8 * (1.0 + d.hessian[2][3].abs()));
        prop_assert!((hd.distance.re() - c.distance).abs() < 1e-14 * (1.0 + c.distance.abs()));
    }
}

fn d(a: (f64, f64), pa: [f64; 3], b: (f64, f64), pb: [f64; 3]) -> geometry::Contact {
    signed_distance_coords(
        &Ellipse::new(a.0, a.1).unwrap(),
        pa,
        &Ellipse::new(b.0, b.1).unwrap(),
        pb,
    )
    .unwrap()
}

#[test]
fn hard_configurations_are_exact_and_never_nan() {
    // Concentric circles: depth is the sum of radii, witnesses flagged as not unique.
    let c = d((1.0, 1.0), [0.3, 0.3, 0.0], (0.5, 0.5), [0.3, 0.3, 1.0]);
    assert!((c.distance + 1.5).abs() < 1e-15 && !c.witness_unique);
    // Concentric ellipses: escape along the minor axis, two ways.
    let c = d((2.0, 1.0), [0.0, 0.0, 0.0], (1.5, 0.2), [0.0, 0.0, 0.0]);
    assert!((c.distance + 1.2).abs() < 1e-14 && !c.witness_unique);
    // Eccentricity 1000, flat sides parallel at gap 1e-3.
    let c = d((1.0, 1e-3), [0.0, 0.0, 0.0], (1.0, 1e-3), [0.0, 3e-3, 0.0]);
    assert!((c.distance - 1e-3).abs() < 1e-15, "{}", c.distance);
    // Touching circles.
    let c = d((1.0, 1.0), [0.0, 0.0, 0.0], (1.0, 1.0), [2.0, 0.0, 0.0]);
    assert!(c.distance.abs() < 1e-15 && (c.normal.x - 1.0).abs() < 1e-15);
    // A thin needle across a circle, off-centre: the shallower escape is the right one.
    let c = d((3.0, 0.2), [0.0, 0.1, 0.0], (1.0, 1.0), [0.0, 0.0, 0.0]);
    assert!((c.distance + 1.1).abs() < 1e-14, "{}", c.distance);
    // Huge and tiny scales.
    let c = d((1e6, 1e5), [0.0, 0.0, 0.0], (1e-6, 1e-6), [2e6, 0.0, 0.0]);
    assert!((c.distance - (1e6 - 1e-6)).abs() < 1e-9, "{}", c.distance);
    assert!(c.distance.is_finite() && c.normal.is_finite() && c.point_a.is_finite());
}

#[test]
fn bad_input_is_a_typed_error() {
    let e = Ellipse::new(1.0, 1.0).unwrap();
    for bad in [
        [f64::NAN, 0.0, 0.0],
        [0.0, f64::INFINITY, 0.0],
        [0.0, 0.0, f64::NEG_INFINITY],
    ] {
        assert!(signed_distance_coords(&e, bad, &e, [3.0, 0.0, 0.0]).is_err());
        assert!(signed_distance_coords(&e, [3.0, 0.0, 0.0], &e, bad).is_err());
    }
    assert!(Ellipse::new(-1.0, 1.0).is_err());
}

fn half_plane() -> impl Strategy<Value = geometry::HalfPlane> {
    (-2.0_f64..2.0, -2.0_f64..2.0, -4.0_f64..4.0, 0.1_f64..5.0).prop_map(|(x, y, angle, len)| {
        geometry::HalfPlane::new([x, y], [len * angle.cos(), len * angle.sin()]).unwrap()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Against an oracle independent of the support formula: the ellipse's boundary scanned by its
    /// parameter (then golden sections), the lowest point's height above the boundary line.
    #[test]
    fn a_half_plane_distance_is_the_height_of_the_lowest_boundary_point(
        plane in half_plane(), e in ellipse(), p in pose()
    ) {
        let c = geometry::half_plane_distance_dual(&plane, &e, p).unwrap();
        let [nx, ny] = plane.normal();
        let q = plane.point();
        let height = |t: f64| {
            let (lx, ly) = (e.a() * t.cos(), e.b() * t.sin());
            let (x, y) = (p[0] + p[2].cos() * lx - p[2].sin() * ly, p[1] + p[2].sin() * lx + p[2].cos() * ly);
            nx * (x - q[0]) + ny * (y - q[1])
        };
        let n = 20_000;
        let step = std::f64::consts::TAU / n as f64;
        let k = (0..n).min_by(|&i, &j| height(i as f64 * step).total_cmp(&height(j as f64 * step))).unwrap();
        let (mut lo, mut hi) = ((k as f64 - 1.0) * step, (k as f64 + 1.0) * step);
        for _ in 0..100 {
            let (m1, m2) = (lo + (hi - lo) * 0.382, lo + (hi - lo) * 0.618);
            if height(m1) < height(m2) { hi = m2 } else { lo = m1 }
        }
        let oracle = height(0.5 * (lo + hi));
        prop_assert!((c.distance - oracle).abs() < 1e-10 * (1.0 + oracle.abs()), "{} vs {oracle}", c.distance);
        // Witnesses: A on the boundary line, B on the ellipse, B - A = d n, the normal the plane's.
        prop_assert!((nx * (c.point_a[0] - q[0]) + ny * (c.point_a[1] - q[1])).abs() < 1e-12 * (1.0 + q[0].abs() + q[1].abs() + c.point_a[0].abs() + c.point_a[1].abs()));
        let (rx, ry) = (c.point_b[0] - p[0], c.point_b[1] - p[1]);
        let (lx, ly) = (p[2].cos() * rx + p[2].sin() * ry, -p[2].sin() * rx + p[2].cos() * ry);
        prop_assert!(((lx / e.a()).powi(2) + (ly / e.b()).powi(2) - 1.0).abs() < 1e-12);
        prop_assert!((c.point_b[0] - c.point_a[0] - c.distance * nx).abs() < 1e-12 * (1.0 + c.distance.abs()));
        prop_assert!((c.point_b[1] - c.point_a[1] - c.distance * ny).abs() < 1e-12 * (1.0 + c.distance.abs()));
        prop_assert_eq!(c.normal, [nx, ny]);
        prop_assert!(c.witness_unique);
    }

    /// First and second derivatives through dual numbers against central differences of the values.
    #[test]
    fn half_plane_distance_derivatives_match_differences(
        plane in half_plane(), e in ellipse(), p in pose()
    ) {
        let value = |p: [f64; 3]| geometry::half_plane_distance_dual(&plane, &e, p).unwrap();
        let eps = 1e-5;
        for k in 0..3 {
            let mut dp = p.map(Dual64::from);
            dp[k].eps = 1.0;
            let dual = geometry::half_plane_distance_dual(&plane, &e, dp).unwrap();
            let (mut pp, mut pm) = (p, p);
            pp[k] += eps;
            pm[k] -= eps;
            let (cp, cm) = (value(pp), value(pm));
            let fd = (cp.distance - cm.distance) / (2.0 * eps);
            prop_assert!((fd - dual.distance.eps).abs() < 1e-7 * (1.0 + fd.abs()), "d/dp{k}: {fd} vs {}", dual.distance.eps);
            for i in 0..2 {
                let fd = (cp.point_b[i] - cm.point_b[i]) / (2.0 * eps);
                prop_assert!((fd - dual.point_b[i].eps).abs() < 1e-6 * (1.0 + fd.abs()), "point_b {i} d/dp{k}");
            }
            // Second order: the (theta, k) entry through hyper-duals against differences of the first.
            let mut hp = p.map(HyperDual64::from);
            hp[2].eps1 = 1.0;
            hp[k].eps2 = 1.0;
            let hd = geometry::half_plane_distance_dual(&plane, &e, hp).unwrap();
            let first = |p: [f64; 3]| {
                let mut d = p.map(Dual64::from);
                d[2].eps = 1.0;
                geometry::half_plane_distance_dual(&plane, &e, d).unwrap().distance.eps
            };
            let fd2 = (first(pp) - first(pm)) / (2.0 * eps);
            prop_assert!((fd2 - hd.distance.eps1eps2).abs() < 1e-6 * (1.0 + fd2.abs()), "d2/dtheta dp{k}: {fd2} vs {}", hd.distance.eps1eps2);
        }
    }
}

#[test]
fn a_half_plane_needs_a_finite_point_and_a_non_zero_normal() {
    for (point, normal) in [
        ([0.0, 0.0], [0.0, 0.0]),
        ([f64::NAN, 0.0], [0.0, 1.0]),
        ([0.0, 0.0], [f64::INFINITY, 1.0]),
    ] {
        let e = geometry::HalfPlane::new(point, normal).unwrap_err();
        assert!(e.to_string().contains("half-plane"), "{e}");
    }
    let plane = geometry::HalfPlane::new([0.0, -1.0], [0.0, 2.0]).unwrap();
    assert_eq!(plane.normal(), [0.0, 1.0]);
    let e = Ellipse::new(0.5, 0.2).unwrap();
    assert!(geometry::half_plane_distance_dual(&plane, &e, [0.0f64, f64::NAN, 0.0]).is_err());
    // An upright ellipse touching the ground, and one sunk into it by 0.1.
    let c =
        geometry::half_plane_distance_dual(&plane, &e, [3.0f64, -0.8, std::f64::consts::FRAC_PI_2])
            .unwrap();
    assert!((c.distance - (-0.3)).abs() < 1e-15, "{}", c.distance);
    let c = geometry::half_plane_distance_dual(&plane, &e, [3.0f64, -0.8, 0.0]).unwrap();
    assert!(c.distance.abs() < 1e-15 && (c.point_b[0] - 3.0).abs() < 1e-15);
}
