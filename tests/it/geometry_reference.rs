//! The geometry against the independent 45-digit reference of `tests/data/ellipse_cases.json`,
//! to the tolerances its README gives.

use crate::support::reference_json;
use geometry::{Ellipse, signed_distance_coords};

#[test]
fn every_reference_case_within_its_tolerance() {
    let data = reference_json("ellipse_cases.json");
    let cases = data["cases"].as_array().expect("cases");
    assert_eq!(cases.len(), 40);
    let mut worst = (0.0_f64, String::new());
    for (i, case) in cases.iter().enumerate() {
        let g = |k: &str| {
            case[k]
                .as_f64()
                .unwrap_or_else(|| panic!("case {i} lacks {k}"))
        };
        let a = Ellipse::new(g("a1"), g("b1")).unwrap();
        let b = Ellipse::new(g("a2"), g("b2")).unwrap();
        let c = signed_distance_coords(
            &a,
            [g("x1"), g("y1"), g("th1")],
            &b,
            [g("x2"), g("y2"), g("th2")],
        )
        .unwrap();
        let size = a.max_axis().max(b.max_axis());
        let cond = case["witness_condition"].as_f64().unwrap_or(1.0).max(1.0);
        let category = case["category"].as_str().unwrap();
        let err_d = (c.distance - g("distance")).abs() / size;
        assert!(
            err_d <= 1e-12,
            "case {i} ({category}): distance {} vs {} (rel {err_d:e})",
            c.distance,
            g("distance")
        );
        if err_d > worst.0 {
            worst = (err_d, format!("case {i} distance"));
        }
        let unique = case["witness_unique"].as_bool().unwrap();
        assert_eq!(
            c.witness_unique, unique,
            "case {i} ({category}): witness uniqueness"
        );
        if !unique {
            continue;
        }
        let vec = |k: &str| {
            let v = case[k].as_array().unwrap();
            [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()]
        };
        for (name, got, want, scale) in [
            ("pA", [c.point_a.x, c.point_a.y], vec("pA"), size * cond),
            ("pB", [c.point_b.x, c.point_b.y], vec("pB"), size * cond),
            ("normal", [c.normal.x, c.normal.y], vec("normal"), cond),
        ] {
            let err = (got[0] - want[0]).hypot(got[1] - want[1]) / scale;
            assert!(
                err <= 1e-12,
                "case {i} ({category}): {name} {got:?} vs {want:?} (rel {err:e})"
            );
            if err > worst.0 {
                worst = (err, format!("case {i} {name}"));
            }
        }
    }
    eprintln!("worst relative error {:e} at {}", worst.0, worst.1);
}
