//! `cargo xtask distance`: the geometry as a JSON-lines filter, so any tool can check it.

use geometry::{Ellipse, signed_distance_coords};
use serde::{Deserialize, Serialize};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Also write the gradient (6) and Hessian (6x6) of the distance with respect to
    /// (x_A, y_A, theta_A, x_B, y_B, theta_B).
    #[arg(long)]
    derivatives: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Query {
    a: Vec<f64>,
    pose_a: Vec<f64>,
    b: Vec<f64>,
    pose_b: Vec<f64>,
}

/// A field of a fixed length, or a message naming it and what it holds.
fn exactly<const N: usize>(name: &str, holds: &str, v: &[f64]) -> Result<[f64; N], String> {
    v.try_into()
        .map_err(|_| format!("{name} needs {N} numbers ({holds}), got {}", v.len()))
}

#[derive(Debug, Serialize)]
struct Answer {
    distance: f64,
    point_a: [f64; 2],
    point_b: [f64; 2],
    normal: [f64; 2],
    witness_unique: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    gradient: Option<[f64; 6]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    hessian: Option<[[f64; 6]; 6]>,
}

/// Answers one input line: the JSON answer or the error message.
pub fn answer_line(line: &str, derivatives: bool) -> Result<String, String> {
    let q: Query = serde_json::from_str(line).map_err(|e| format!("bad input line: {e}"))?;
    let [a1, b1] = exactly("a", "semi-axes", &q.a)?;
    let [a2, b2] = exactly("b", "semi-axes", &q.b)?;
    let pose_a = exactly("pose_a", "x, y, theta", &q.pose_a)?;
    let pose_b = exactly("pose_b", "x, y, theta", &q.pose_b)?;
    let a = Ellipse::new(a1, b1).map_err(|e| format!("shape a: {e}"))?;
    let b = Ellipse::new(a2, b2).map_err(|e| format!("shape b: {e}"))?;
    let c = signed_distance_coords(&a, pose_a, &b, pose_b).map_err(|e| e.to_string())?;
    let d = derivatives.then(|| c.derivatives());
    let answer = Answer {
        distance: c.distance,
        point_a: [c.point_a.x, c.point_a.y],
        point_b: [c.point_b.x, c.point_b.y],
        normal: [c.normal.x, c.normal.y],
        witness_unique: c.witness_unique,
        gradient: d.map(|d| d.gradient),
        hessian: d.map(|d| d.hessian),
    };
    crate::tools::jsonl::finite_line(&answer)
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    crate::tools::jsonl::filter(|line| answer_line(line, args.derivatives))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answers_a_good_line_and_reports_bad_ones() {
        let ok = answer_line(
            r#"{"a":[1,0.5],"pose_a":[0,0,0],"b":[0.7,0.5],"pose_b":[3,0,0]}"#,
            true,
        )
        .unwrap();
        let v: serde_json::Value = serde_json::from_str(&ok).unwrap();
        assert!((v["distance"].as_f64().unwrap() - 1.3).abs() < 1e-14);
        assert_eq!(v["gradient"].as_array().unwrap().len(), 6);
        for bad in [
            "not json",
            r#"{"a":[1,-0.5],"pose_a":[0,0,0],"b":[0.7,0.5],"pose_b":[3,0,0]}"#,
            r#"{"a":[1,0.5],"pose_a":[0,0],"b":[0.7,0.5],"pose_b":[3,0,0]}"#,
            r#"{"a":[1,0.5],"pose_a":[0,0,1e999],"b":[0.7,0.5],"pose_b":[3,0,0]}"#,
        ] {
            assert!(answer_line(bad, false).is_err(), "accepted {bad}");
        }
        // The message names the field and what it holds, and refuses semi-axes out of the safe range.
        let three = r#"{"a":[1,0.5,2],"pose_a":[0,0,0],"b":[0.7,0.5],"pose_b":[3,0,0]}"#;
        assert_eq!(
            answer_line(three, false).unwrap_err(),
            "a needs 2 numbers (semi-axes), got 3"
        );
        let huge = r#"{"a":[1e200,0.5],"pose_a":[0,0,0],"b":[0.7,0.5],"pose_b":[3,0,0]}"#;
        let e = answer_line(huge, false).unwrap_err();
        assert!(e.contains("between 1e-6 and 1e6"), "{e}");
    }
}
