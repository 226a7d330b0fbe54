//! `cargo xtask step` and `cargo xtask simulate`: the simulator from the command line.

use anyhow::Context;
use dynamics::{Complementarity, Scene, Simulator, StepSettings};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::PathBuf;

/// The complementarity model on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Model {
    /// The exact LCP (Lemke).
    Hard,
    /// Logistic smoothing, paper eq. (17).
    Logistic,
    /// Normal noise, expected-residual minimisation, paper eq. (14) with (15).
    Normal,
}

/// Options shared by `step` and `simulate`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// Complementarity model.
    #[arg(long, value_enum, default_value = "logistic")]
    model: Model,
    /// Noise scale of the smoothed models.
    #[arg(long, default_value_t = 0.1)]
    sigma: f64,
    /// Time step.
    #[arg(long, default_value_t = 0.05)]
    h: f64,
    /// Scene file (TOML); default: the flicking finger of SCENE.md (scenes/finger.toml).
    #[arg(long)]
    scene: Option<PathBuf>,
}

impl SimArgs {
    pub fn simulator(&self) -> anyhow::Result<Simulator> {
        let scene = match &self.scene {
            None => Scene::flicking_finger(),
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("reading {}", path.display()))?;
                Scene::from_toml_str(&text).with_context(|| format!("scene {}", path.display()))?
            }
        };
        let model = match self.model {
            Model::Hard => Complementarity::Hard,
            Model::Logistic => Complementarity::Logistic { sigma: self.sigma },
            Model::Normal => Complementarity::Normal { sigma: self.sigma },
        };
        Ok(Simulator::new(
            scene,
            StepSettings {
                model,
                h: self.h,
                ..StepSettings::default()
            },
        )?)
    }
}

#[derive(Debug, clap::Args)]
pub struct StepArgs {
    #[command(flatten)]
    sim: SimArgs,
    /// Also write fx = dx'/dx and fu = dx'/du (logistic and hard models).
    #[arg(long)]
    derivatives: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Query {
    x: Vec<f64>,
    u: Vec<f64>,
}

#[derive(Debug, Serialize)]
struct Answer {
    x_next: Vec<f64>,
    lambda: Vec<f64>,
    d: Vec<f64>,
    status: ncp::Status,
    #[serde(skip_serializing_if = "Option::is_none")]
    fx: Option<Vec<Vec<f64>>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fu: Option<Vec<Vec<f64>>>,
}

fn rows(flat: &[f64], cols: usize) -> Vec<Vec<f64>> {
    flat.chunks(cols).map(<[f64]>::to_vec).collect()
}

/// Answers one line; each line is a fresh step (no warm start carried between lines).
pub fn answer_line(sim: &mut Simulator, line: &str, derivatives: bool) -> Result<String, String> {
    let q: Query = serde_json::from_str(line).map_err(|e| format!("bad input line: {e}"))?;
    sim.reset_warm_start();
    let (step, der) = if derivatives {
        let (s, d) = sim
            .step_with_derivatives(&q.x, &q.u)
            .map_err(|e| e.to_string())?;
        (s, Some(d))
    } else {
        (sim.step(&q.x, &q.u).map_err(|e| e.to_string())?, None)
    };
    let nx = step.x_next.len();
    let nu = q.u.len();
    let answer = Answer {
        x_next: step.x_next,
        lambda: step.lambda,
        d: step.d,
        status: step.info.status,
        fx: der.as_ref().map(|d| rows(&d.fx, nx)),
        fu: der.as_ref().map(|d| rows(&d.fu, nu.max(1))),
    };
    crate::jsonl::finite_line(&answer)
}

pub fn run_step(args: &StepArgs) -> anyhow::Result<()> {
    let mut sim = args.sim.simulator()?;
    crate::jsonl::filter(|line| answer_line(&mut sim, line, args.derivatives))
}

#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    #[command(flatten)]
    sim: SimArgs,
    /// Initial state (comma-separated); default SCENE.md's x0 for the finger.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    x0: Option<Vec<f64>>,
    /// Controls: a JSON file holding an array of control vectors, one per step.
    #[arg(long)]
    controls: Option<PathBuf>,
    /// Without --controls: this many steps with zero controls.
    #[arg(long, default_value_t = 75)]
    steps: usize,
    /// Output format.
    #[arg(long, value_enum, default_value = "json")]
    format: Format,
}

/// Trajectory output formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// {"t":[...],"x":[[...]],"u":[[...]],"lambda":[[...]]}
    Json,
    /// One row per step: t, x..., u..., lambda...
    Csv,
}

pub fn run_simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let mut sim = args.sim.simulator()?;
    let scene = sim.scene().clone();
    let x0 = match &args.x0 {
        Some(x) => x.clone(),
        None if scene.n_state() == 6 => dynamics::FLICKING_FINGER_X0.to_vec(),
        None => vec![0.0; scene.n_state()],
    };
    let controls: Vec<Vec<f64>> = match &args.controls {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            serde_json::from_str(&text).with_context(|| {
                format!("{}: expected an array of control vectors", path.display())
            })?
        }
        None => vec![vec![0.0; scene.n_controls]; args.steps],
    };
    let h = sim.settings().h;
    let (mut xs, mut lambdas) = (vec![x0.clone()], Vec::new());
    let mut x = x0;
    for (k, u) in controls.iter().enumerate() {
        let s = sim.step(&x, u).with_context(|| format!("step {k}"))?;
        x = s.x_next;
        xs.push(x.clone());
        lambdas.push(s.lambda);
    }
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    match args.format {
        Format::Json => {
            let t: Vec<f64> = (0..xs.len()).map(|k| k as f64 * h).collect();
            let json =
                serde_json::json!({ "h": h, "t": t, "x": xs, "u": controls, "lambda": lambdas });
            writeln!(out, "{json}")?;
        }
        Format::Csv => {
            let n = scene.n_state();
            let m = scene.n_constraints();
            let mut header: Vec<String> = vec!["t".into()];
            header.extend((0..n).map(|i| format!("x{i}")));
            header.extend((0..scene.n_controls).map(|i| format!("u{i}")));
            header.extend((0..m).map(|i| format!("lambda{i}")));
            writeln!(out, "{}", header.join(","))?;
            for k in 0..controls.len() {
                let mut row = vec![format!("{}", k as f64 * h)];
                row.extend(xs[k].iter().map(|v| format!("{v:e}")));
                row.extend(controls[k].iter().map(|v| format!("{v:e}")));
                row.extend(lambdas[k].iter().map(|v| format!("{v:e}")));
                writeln!(out, "{}", row.join(","))?;
            }
        }
    }
    out.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sim(model: Model) -> Simulator {
        SimArgs {
            model,
            sigma: 0.1,
            h: 0.05,
            scene: None,
        }
        .simulator()
        .unwrap()
    }

    #[test]
    fn a_step_line_gives_the_next_state_and_derivatives() {
        let mut s = sim(Model::Logistic);
        let out: serde_json::Value = serde_json::from_str(
            &answer_line(&mut s, r#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,0]}"#, true).unwrap(),
        )
        .unwrap();
        assert_eq!(out["x_next"].as_array().unwrap().len(), 6);
        assert_eq!(out["lambda"].as_array().unwrap().len(), 6);
        assert_eq!(out["fx"].as_array().unwrap().len(), 6);
        assert_eq!(out["fu"][0].as_array().unwrap().len(), 2);
        assert_eq!(out["status"], "converged");
    }

    #[test]
    fn bad_step_lines_get_an_error() {
        let mut s = sim(Model::Hard);
        for bad in [
            "nope",
            r#"{"x":[1,2],"u":[0,0]}"#,
            r#"{"x":[0,0,0,0,0,0],"u":[0]}"#,
            r#"{"x":[0,0,0,0,0,0],"u":[0,0],"y":1}"#,
        ] {
            assert!(answer_line(&mut s, bad, false).is_err(), "{bad}");
        }
        let mut n = sim(Model::Normal);
        let nan = r#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,"NaN"]}"#;
        assert!(answer_line(&mut n, nan, true).is_err());
        // The normal model has derivatives too.
        let out = answer_line(&mut n, r#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,0]}"#, true).unwrap();
        assert!(out.contains("\"fx\""), "{out}");
    }
}
