//! `cargo xtask lcp`: the complementarity solvers as a JSON-lines filter, so external problem collections
//! can be run through them.

use ncp::{
    ErmSettings, ErmSolver, LemkeSettings, LinearMcp, NcpFunction, NewtonSettings, NewtonSolver,
    Solution, enumerate_solutions, lemke,
};
use serde::{Deserialize, Serialize};

/// A solver for `cargo xtask lcp`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Method {
    /// Lemke's method, exact (the hard reference).
    Lemke,
    /// Enumeration of active sets (exact; at most 20 complementarity rows); prints the first solution.
    Enumerate,
    /// Semismooth Newton on Fischer-Burmeister (hard).
    Fb,
    /// Semismooth Newton on min (hard; not globally convergent).
    Min,
    /// Newton on the logistic smoothing, paper eq. (17), noise scale --sigma.
    Logistic,
    /// Newton on the normal smoothing (mean form, paper footnote 3), noise --sigma.
    Normal,
    /// Expected residual minimisation with normal noise, paper eq. (14) with (15), noise --sigma.
    Erm,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Which solver.
    #[arg(long, value_enum, default_value = "lemke")]
    method: Method,
    /// Noise scale of the smoothed methods.
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    sigma: f64,
}

/// The most rows a line may pose, for every method (Lemke's own limit: each solve is `O(n^3)`, about a
/// second at this size); ERM takes at most 300 complementarity rows, enumeration 20.
pub const MAX_ROWS: usize = 500;

/// One problem: `0 <= z _|_ M z + q >= 0`, the first `n_free` rows equalities with free variables.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Query {
    #[serde(rename = "M")]
    m: Vec<Vec<f64>>,
    q: Vec<f64>,
    /// Leading equality rows (default 0: a plain LCP).
    #[serde(default)]
    n_free: usize,
    /// Warm start for the iterative methods (default zero).
    #[serde(default)]
    z0: Option<Vec<f64>>,
}

#[derive(Debug, Serialize)]
struct Answer {
    z: Vec<f64>,
    w: Vec<f64>,
    iterations: usize,
    status: ncp::Status,
    residual: f64,
}

/// Answers one input line: the JSON answer or the error message.
pub fn answer_line(line: &str, args: &Args) -> Result<String, String> {
    let q: Query = serde_json::from_str(line).map_err(|e| format!("bad input line: {e}"))?;
    if q.q.len() > MAX_ROWS {
        return Err(format!(
            "the problem has {} rows: this command takes at most {MAX_ROWS} (MAX_ROWS)",
            q.q.len()
        ));
    }
    let p = LinearMcp::from_rows(q.n_free, &q.m, &q.q).map_err(|e| e.to_string())?;
    let n = q.q.len();
    if let Some(z0) = &q.z0
        && z0.len() != n
    {
        return Err(format!(
            "z0 has {} entries but q has {n}: a warm start has one entry per row",
            z0.len()
        ));
    }
    let z0 = q.z0.unwrap_or_else(|| vec![0.0; n]);
    let smooth =
        |f: fn(f64) -> Result<NcpFunction, ncp::NcpError>| f(args.sigma).map_err(|e| e.to_string());
    let newton = |f: NcpFunction| -> Result<Solution, String> {
        let mut solver = NewtonSolver::new(NewtonSettings::default()).map_err(|e| e.to_string())?;
        solver
            .solve(&p, &vec![f; n - q.n_free.min(n)], &z0)
            .map_err(|e| e.to_string())
    };
    let s = match args.method {
        Method::Lemke => lemke(&p, &LemkeSettings::default()).map_err(|e| e.to_string())?,
        Method::Enumerate => {
            let all = enumerate_solutions(&p, 1e-12).map_err(|e| e.to_string())?;
            let z = all
                .into_iter()
                .next()
                .ok_or("no solution found by enumeration")?;
            let mut w = vec![0.0; n];
            ncp::Mcp::evaluate(&p, &z, &mut w, None);
            let residual = ncp::complementarity_residual(q.n_free, &z, &w);
            Solution {
                z,
                w,
                info: ncp::Info {
                    status: ncp::Status::Converged,
                    iterations: 0,
                    residual,
                    evaluations: 1,
                },
            }
        }
        Method::Fb => newton(NcpFunction::FischerBurmeister)?,
        Method::Min => newton(NcpFunction::Min)?,
        Method::Logistic => newton(smooth(NcpFunction::logistic)?)?,
        Method::Normal => newton(smooth(NcpFunction::normal)?)?,
        Method::Erm => {
            let erm = ErmSolver::new(ErmSettings::default()).map_err(|e| e.to_string())?;
            let c = n.saturating_sub(q.n_free);
            erm.solve(&p, &vec![args.sigma; c], &z0)
                .map_err(|e| e.to_string())?
        }
    };
    let answer = Answer {
        z: s.z,
        w: s.w,
        iterations: s.info.iterations,
        status: s.info.status,
        residual: s.info.residual,
    };
    crate::tools::jsonl::finite_line(&answer)
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    crate::tools::jsonl::filter(|line| answer_line(line, args))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(method: Method) -> Args {
        Args { method, sigma: 0.1 }
    }

    #[test]
    fn every_method_answers_a_good_line() {
        let line = r#"{"M":[[2,1],[1,2]],"q":[-1,1]}"#;
        for m in [
            Method::Lemke,
            Method::Enumerate,
            Method::Fb,
            Method::Min,
            Method::Logistic,
            Method::Normal,
            Method::Erm,
        ] {
            let out: serde_json::Value =
                serde_json::from_str(&answer_line(line, &args(m)).unwrap()).unwrap();
            assert_eq!(out["status"], "converged", "{m:?}: {out}");
            let z0 = out["z"][0].as_f64().unwrap();
            assert!((z0 - 0.5).abs() < 0.1, "{m:?}: {out}");
        }
        let exact: serde_json::Value =
            serde_json::from_str(&answer_line(line, &args(Method::Lemke)).unwrap()).unwrap();
        assert_eq!(exact["z"], serde_json::json!([0.5, 0.0]));
        assert_eq!(exact["w"], serde_json::json!([0.0, 1.5]));
    }

    #[test]
    fn mixed_problems_and_warm_starts_are_read() {
        // x free with 2x - lambda = 1, and 0 <= lambda _|_ x + lambda >= 0: x = 0.5, lambda = 0.
        let line = r#"{"M":[[2,-1],[1,1]],"q":[-1,0],"n_free":1,"z0":[0.4,0.1]}"#;
        let out: serde_json::Value =
            serde_json::from_str(&answer_line(line, &args(Method::Fb)).unwrap()).unwrap();
        assert_eq!(out["status"], "converged");
        assert!((out["z"][0].as_f64().unwrap() - 0.5).abs() < 1e-12);
    }

    #[test]
    fn bad_lines_get_an_error_not_a_crash() {
        for bad in [
            "not json",
            r#"{"M":[[1,2]],"q":[1,2]}"#,
            r#"{"M":[[1,"x"],[0,1]],"q":[1,2]}"#,
            r#"{"M":[[1,0],[0,1]],"q":[1,2],"extra":3}"#,
            r#"{"M":[[1,0],[0,1]],"q":[1,2],"n_free":5}"#,
            r#"{"M":[[0,1],[-1,0]],"q":[-1,-1]}"#,
            // Issue 27: a subnormal row panicked Lemke's method; a warm start of the wrong length was
            // ignored by the exact methods.
            r#"{"M":[[0,0],[0,1]],"q":[-5e-324,-0.5]}"#,
            r#"{"M":[[1,0],[0,1]],"q":[1,2],"z0":[0,0,0]}"#,
        ] {
            assert!(answer_line(bad, &args(Method::Lemke)).is_err(), "{bad}");
        }
        for m in [Method::Enumerate, Method::Lemke] {
            let e = answer_line(r#"{"M":[[1,0],[0,1]],"q":[1,2],"z0":[0]}"#, &args(m)).unwrap_err();
            assert!(e.contains("z0 has 1 entries"), "{m:?}: {e}");
        }
        let neg = Args {
            method: Method::Logistic,
            sigma: -1.0,
        };
        assert!(
            answer_line(r#"{"M":[[1]],"q":[1]}"#, &neg)
                .unwrap_err()
                .contains("sigma")
        );
    }
}
