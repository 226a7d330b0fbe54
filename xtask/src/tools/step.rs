//! `cargo xtask step` and `cargo xtask simulate`: the simulator from the command line.

use anyhow::Context;
use dynamics::{Scene, Simulator, StepSettings};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::PathBuf;

/// The complementarity model on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModelArg {
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
    /// Complementarity model [default: logistic; with `optimize --task`, the task's].
    #[arg(long, value_enum)]
    model: Option<ModelArg>,
    /// Noise scale of the smoothed models [default: with `optimize --task`, the task's when its model has one; otherwise 0.1].
    #[arg(long, allow_negative_numbers = true)]
    sigma: Option<f64>,
    /// Time step [default: 0.05; with `optimize --task`, the task's].
    #[arg(long, allow_negative_numbers = true)]
    h: Option<f64>,
    /// Scene file (TOML); default: the flicking finger of SCENE.md (scenes/finger.toml).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// How the joints' drag is integrated: explicit (SCENE.md; a step where it would be unstable, a light
    /// body on a draggy joint, is an error) or implicit (dissipative at any h).
    #[arg(long, value_enum, default_value = "explicit")]
    drag: DragArg,
    /// How deep a penetration the velocities push out; deeper is projected out at the position level
    /// (default 0: velocities never push out, positions recover everything, so contact never creates
    /// energy and nothing sinks). `inf`: SCENE.md's d / h, all of it at the velocity level (the reference
    /// answers' step; a rocking body gains energy from it).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    recovery: f64,
}

/// `--drag`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum DragArg {
    /// At the start of the step (SCENE.md).
    Explicit,
    /// At the end of the step.
    Implicit,
}

impl From<DragArg> for dynamics::Drag {
    fn from(d: DragArg) -> Self {
        match d {
            DragArg::Explicit => dynamics::Drag::Explicit,
            DragArg::Implicit => dynamics::Drag::Implicit,
        }
    }
}

impl SimArgs {
    pub fn simulator(&self) -> anyhow::Result<Simulator> {
        let scene = match &self.scene {
            None => task::ProblemFile::builtin().scene,
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("reading {}", path.display()))?;
                Scene::from_toml_str(&text).with_context(|| format!("scene {}", path.display()))?
            }
        };
        self.simulator_of(scene, None)
    }

    /// The scene file of `--scene` with its tasks (the built-in scenes/finger.toml without it).
    pub fn problem_file(&self) -> anyhow::Result<task::ProblemFile> {
        Ok(problem_file(self.scene.as_deref())?.0)
    }

    /// A simulator of `scene` with the model and time step of `task` (when given) unless the command line
    /// names its own.
    pub fn simulator_of(
        &self,
        scene: Scene,
        task: Option<&task::Task>,
    ) -> anyhow::Result<Simulator> {
        let model = contact_model(self.model, self.sigma, task)?.complementarity();
        Ok(Simulator::new(
            scene,
            StepSettings {
                model,
                h: self.h.or(task.map(|t| t.h)).unwrap_or(0.05),
                drag: self.drag.into(),
                recovery: Some(self.recovery),
                ..StepSettings::default()
            },
        )?)
    }
}

/// The contact model a command runs: `--model` (with `--sigma`, else the task's noise scale when its
/// model has one, else 0.1) if given, else the task's (with `--sigma` in place of its noise scale; refused
/// for a hard task), else logistic.
pub fn contact_model(
    model: Option<ModelArg>,
    sigma: Option<f64>,
    task: Option<&task::Task>,
) -> anyhow::Result<task::ContactModel> {
    use task::ContactModel as M;
    // A noise scale the command line does not give is the task's, when its model has one.
    let task_sigma = task.and_then(|t| match t.model {
        M::Logistic(s) | M::Normal(s) => Some(s),
        M::Hard => None,
    });
    let s = sigma.or(task_sigma).unwrap_or(0.1);
    Ok(match (model, task) {
        (Some(ModelArg::Hard), _) => M::Hard,
        (Some(ModelArg::Logistic), _) => M::Logistic(s),
        (Some(ModelArg::Normal), _) => M::Normal(s),
        (None, Some(task)) => match (task.model, sigma) {
            (M::Logistic(_), Some(s)) => M::Logistic(s),
            (M::Normal(_), Some(s)) => M::Normal(s),
            (M::Hard, Some(_)) => anyhow::bail!(
                "--sigma: task {}'s model is hard, which has no noise scale (give --model too)",
                task.name
            ),
            (model, None) => model,
        },
        (None, None) => M::Logistic(s),
    })
}

/// The scene file at `path` with its tasks, or without one the built-in file
/// ([`task::ProblemFile::builtin`], scenes/finger.toml: SCENE.md's finger and the paper's `spin`), and
/// the name to report it by.
pub fn problem_file(path: Option<&std::path::Path>) -> anyhow::Result<(task::ProblemFile, String)> {
    Ok(match path {
        None => (
            task::ProblemFile::builtin(),
            "scenes/finger.toml (built in)".into(),
        ),
        Some(path) => (
            task::ProblemFile::load(path).with_context(|| format!("scene {}", path.display()))?,
            path.display().to_string(),
        ),
    })
}

#[derive(Debug, clap::Args)]
pub struct StepArgs {
    #[command(flatten)]
    sim: SimArgs,
    /// Also write fx = dx'/dx and fu = dx'/du.
    #[arg(long)]
    derivatives: bool,
    /// Also write fx, fu and "hessian": the Hessian of c^T f(x, u) over (x, u), (n_x + n_u) square,
    /// row-major as nested arrays, for the "c" (length n_x) each line then carries. Any scene.
    #[arg(long)]
    hessian: bool,
}

/// What a `step` line is answered with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answers {
    /// The step.
    Step,
    /// The step, `fx` and `fu`.
    Derivatives,
    /// The step, `fx`, `fu` and the Hessian of `c^T f`.
    Hessian,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Query {
    x: Vec<f64>,
    u: Vec<f64>,
    /// The vector the Hessian is contracted with (`--hessian` only).
    c: Option<Vec<f64>>,
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
    #[serde(skip_serializing_if = "Option::is_none")]
    hessian: Option<Vec<Vec<f64>>>,
}

fn rows(flat: &[f64], cols: usize) -> Vec<Vec<f64>> {
    flat.chunks(cols).map(<[f64]>::to_vec).collect()
}

/// Answers one line; each line is a fresh step (no warm start carried between lines).
pub fn answer_line(sim: &mut Simulator, line: &str, answers: Answers) -> Result<String, String> {
    let q: Query = serde_json::from_str(line).map_err(|e| format!("bad input line: {e}"))?;
    sim.reset_warm_start();
    let (step, der, hessian) = match (answers, &q.c) {
        (Answers::Hessian, None) => {
            return Err(format!(
                "--hessian needs \"c\" on each line: the {} entries the Hessian of c^T f is taken for",
                2 * sim.scene().n_dof()
            ));
        }
        (Answers::Hessian, Some(c)) => {
            let (s, d, h) = sim
                .step_with_hessian(&q.x, &q.u, c)
                .map_err(|e| e.to_string())?;
            (s, Some(d), Some(h))
        }
        (_, Some(_)) => return Err("\"c\" is read only with --hessian".into()),
        (Answers::Derivatives, None) => {
            let (s, d) = sim
                .step_with_derivatives(&q.x, &q.u)
                .map_err(|e| e.to_string())?;
            (s, Some(d), None)
        }
        (Answers::Step, None) => (sim.step(&q.x, &q.u).map_err(|e| e.to_string())?, None, None),
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
        hessian: hessian.as_ref().map(|h| rows(h, nx + nu)),
    };
    crate::tools::jsonl::finite_line(&answer)
}

pub fn run_step(args: &StepArgs) -> anyhow::Result<()> {
    let mut sim = args.sim.simulator()?;
    let answers = match (args.hessian, args.derivatives) {
        (true, _) => Answers::Hessian,
        (false, true) => Answers::Derivatives,
        (false, false) => Answers::Step,
    };
    crate::tools::jsonl::filter(|line| answer_line(&mut sim, line, answers))
}

/// Steps at most in one `simulate` run (about 3 minutes of the finger at 20 us a step).
pub const MAX_STEPS: u64 = 10_000_000;
/// Steps at most the `json` format holds in memory (the others stream).
pub const MAX_HELD_STEPS: usize = 1_000_000;

#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    #[command(flatten)]
    sim: SimArgs,
    /// Initial state (comma-separated). Without it: the x0 of --task, or of the scene file's only task
    /// (SCENE.md's for the built-in finger), with that task's model and time step unless given; with no
    /// single task, rest at q = 0, refused if bodies overlap there.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    x0: Option<Vec<f64>>,
    /// The task whose initial state (and model and time step, unless given) to start from.
    #[arg(long)]
    task: Option<String>,
    /// Controls: a JSON file holding an array of control vectors, one per step, or the file `optimize
    /// --out` writes (its solution's controls).
    #[arg(long)]
    controls: Option<PathBuf>,
    /// Without --controls: this many steps with zero controls (at most 10^7).
    #[arg(long, default_value_t = 75,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(0..=MAX_STEPS))]
    steps: usize,
    /// Output format.
    #[arg(long, value_enum, default_value = "json")]
    format: Format,
    /// Exit with status 1 if a step's complementarity solve did not converge.
    #[arg(long)]
    strict: bool,
}

/// Trajectory output formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// One object {"h","t":[T+1],"x":[T+1][n],"u":[T][m],"lambda":[T][rows],"status":[T]} (held in
    /// memory: at most 10^6 steps).
    Json,
    /// One line per step {"k","t","x","u","lambda","status"}, then {"k","t","x"} for the final state;
    /// streamed.
    Jsonl,
    /// A header, one row per step (t, x..., u..., lambda..., status), then the final state's row with
    /// the other columns empty; streamed.
    Csv,
}

/// The controls of `simulate --controls FILE`: a bare array, or `optimize --out`'s report.
fn read_controls(path: &std::path::Path) -> anyhow::Result<Vec<Vec<f64>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let value: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))?;
    let array = match &value {
        serde_json::Value::Array(_) => value,
        serde_json::Value::Object(o) => o
            .get("solution")
            .and_then(|s| s.get("controls"))
            .or_else(|| o.get("controls"))
            .cloned()
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: an object without \"controls\" or \"solution\".\"controls\"",
                    path.display()
                )
            })?,
        _ => anyhow::bail!("{}: expected an array of control vectors", path.display()),
    };
    serde_json::from_value(array)
        .with_context(|| format!("{}: expected an array of control vectors", path.display()))
}

/// Warn (on stderr) where a `--x0` the user gave starts with bodies inside each other or a joint past
/// its limit, the deepest named: the first steps undo it, which is what `simulate` may be for and
/// not what `optimize` is asked to do. A state of the wrong length is left to the caller's own check.
pub(crate) fn warn_of_overlap(scene: &dynamics::Scene, x: &[f64]) {
    let overlap = (x.len() == scene.n_state())
        .then(|| {
            scene
                .overlaps(&x[..scene.n_dof()], task::START_TOLERANCE)
                .ok()
        })
        .flatten()
        .and_then(|overlaps| overlaps.into_iter().next());
    if let Some(o) = overlap {
        eprintln!(
            "warning: --x0 starts with {} by {:.3e}; the first steps undo it",
            o.what, o.depth
        );
    }
}

pub fn run_simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let file = args.sim.problem_file()?;
    let scene = file.scene.clone();
    // The task to start from: the one named, or without --x0 the file's only one.
    let task = match (&args.task, &args.x0) {
        (Some(name), _) => Some(file.task(Some(name))?),
        (None, None) if file.tasks.len() == 1 => Some(file.task(None)?),
        (None, _) => None,
    };
    let mut sim = args.sim.simulator_of(scene.clone(), task.as_ref())?;
    let x0 = match (&args.x0, &task) {
        (Some(x), _) => {
            warn_of_overlap(&scene, x);
            x.clone()
        }
        (None, Some(task)) => {
            eprintln!("starting from task {}'s x0", task.name);
            task.x0.clone()
        }
        (None, None) => {
            let rest = vec![0.0; scene.n_state()];
            if let Some(o) = scene
                .overlaps(&rest[..scene.n_dof()], task::START_TOLERANCE)?
                .first()
            {
                anyhow::bail!(
                    "no --x0 and no single task to start from, and rest at q = 0 starts with {} by {:.3e}: \
                     give --x0 or --task",
                    o.what,
                    o.depth
                );
            }
            eprintln!("starting from rest at q = 0 (no --x0, and the file has no single task)");
            rest
        }
    };
    let controls = match &args.controls {
        Some(path) => Some(read_controls(path)?),
        None => None,
    };
    let steps = controls.as_ref().map_or(args.steps, Vec::len);
    if steps as u64 > MAX_STEPS {
        anyhow::bail!("{steps} controls: at most {MAX_STEPS} steps per run");
    }
    if args.format == Format::Json && steps > MAX_HELD_STEPS {
        anyhow::bail!(
            "{steps} steps: --format json holds the trajectory in memory, at most {MAX_HELD_STEPS} \
             steps; --format jsonl or csv stream any number"
        );
    }
    let zero = vec![0.0; scene.n_controls];
    let control = |k: usize| controls.as_ref().map_or(&zero, |c| &c[k]);
    let h = sim.settings().h;
    if let Some(limit) = scene.rocking_limit().filter(|&l| h > l) {
        eprintln!(
            "warning: h = {h} is past the scene's rocking limit, {limit:.4} s (Scene::rocking_limit): a \
             free body lying flat on a plane cannot rest there; a smaller --h can"
        );
    }
    let (n, rows) = (scene.n_state(), scene.n_constraints());
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    // Held for --format json only.
    let (mut xs, mut us, mut lambdas, mut statuses) = (vec![x0.clone()], vec![], vec![], vec![]);
    if args.format == Format::Csv {
        let mut header: Vec<String> = vec!["t".into()];
        header.extend((0..n).map(|i| format!("x{i}")));
        header.extend((0..scene.n_controls).map(|i| format!("u{i}")));
        header.extend((0..rows).map(|i| format!("lambda{i}")));
        header.push("status".into());
        writeln!(out, "{}", header.join(","))?;
    }
    let mut x = x0;
    let mut unconverged = 0usize;
    let mut failure = None;
    let mut done = 0usize;
    for k in 0..steps {
        let u = control(k);
        let s = match sim.step(&x, u) {
            Ok(s) if s.x_next.iter().all(|v| v.is_finite()) => s,
            Ok(_) => {
                failure = Some(format!("step {k}: the next state is not finite"));
                break;
            }
            Err(e) => {
                failure = Some(format!("step {k}: {e}"));
                break;
            }
        };
        if s.info.status != ncp::Status::Converged {
            unconverged += 1;
        }
        let status = s.info.status.name();
        let t = k as f64 * h;
        let written = match args.format {
            Format::Json => {
                us.push(u.clone());
                lambdas.push(s.lambda.clone());
                statuses.push(status);
                Ok(())
            }
            Format::Jsonl => writeln!(
                out,
                "{}",
                serde_json::json!({"k": k, "t": t, "x": x, "u": u, "lambda": s.lambda, "status": status})
            ),
            Format::Csv => {
                let mut row = vec![format!("{t}")];
                row.extend(x.iter().map(|v| format!("{v:e}")));
                row.extend(u.iter().map(|v| format!("{v:e}")));
                row.extend(s.lambda.iter().map(|v| format!("{v:e}")));
                row.push(status.to_string());
                writeln!(out, "{}", row.join(","))
            }
        };
        if let Err(e) = written {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                return Ok(());
            }
            return Err(e.into());
        }
        x = s.x_next;
        if args.format == Format::Json {
            xs.push(x.clone());
        }
        done = k + 1;
    }
    let t_end = done as f64 * h;
    let last = match args.format {
        Format::Json => {
            let t: Vec<f64> = (0..xs.len()).map(|k| k as f64 * h).collect();
            let mut json = serde_json::json!({ "h": h, "t": t, "x": xs, "u": us, "lambda": lambdas,
                "status": statuses });
            if let Some(f) = &failure {
                json["error"] = serde_json::json!(f);
            }
            writeln!(out, "{json}")
        }
        Format::Jsonl => writeln!(
            out,
            "{}",
            serde_json::json!({"k": done, "t": t_end, "x": x})
        )
        .and_then(|()| match &failure {
            Some(f) => writeln!(out, "{}", serde_json::json!({ "error": f })),
            None => Ok(()),
        }),
        Format::Csv => {
            let mut row = vec![format!("{t_end}")];
            row.extend(x.iter().map(|v| format!("{v:e}")));
            row.extend(std::iter::repeat_n(
                String::new(),
                scene.n_controls + rows + 1,
            ));
            writeln!(out, "{}", row.join(","))
        }
    };
    match last.and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(()),
        r => r?,
    }
    if let Some(f) = failure {
        anyhow::bail!("{f} (the {done} steps before it were written)");
    }
    if unconverged > 0 {
        eprintln!(
            "{unconverged} of {done} steps' complementarity solves did not converge (their state \
             still advances; see \"status\")"
        );
        if args.strict {
            anyhow::bail!("--strict: {unconverged} steps did not converge");
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use dynamics::Complementarity;

    /// A task supplies the model, sigma and time step; a flag given on the command line overrides it, and
    /// a noise scale given for a hard task is refused.
    #[test]
    fn a_tasks_settings_yield_to_the_command_lines() {
        let file = task::ProblemFile::builtin();
        let task = file.task(Some("spin")).unwrap();
        let args = |model, sigma, h| SimArgs {
            model,
            sigma,
            h,
            scene: None,
            drag: DragArg::Explicit,
            recovery: 0.0,
        };
        let settings = |a: SimArgs, task: &task::Task| {
            let sim = a.simulator_of(file.scene.clone(), Some(task)).unwrap();
            (sim.settings().model, sim.settings().h)
        };
        assert_eq!(
            settings(args(None, None, None), &task),
            (Complementarity::Logistic { sigma: 0.1 }, 0.05)
        );
        assert_eq!(
            settings(args(None, Some(0.2), Some(0.03)), &task),
            (Complementarity::Logistic { sigma: 0.2 }, 0.03)
        );
        assert_eq!(
            settings(args(Some(ModelArg::Hard), None, None), &task),
            (Complementarity::Hard, 0.05)
        );
        let hard = task::Task {
            model: task::ContactModel::Hard,
            ..task.clone()
        };
        assert_eq!(
            settings(args(None, None, None), &hard),
            (Complementarity::Hard, 0.05)
        );
        // A model named without its noise scale takes the task's, not the default 0.1.
        let sharp = task::Task {
            model: task::ContactModel::Logistic(0.03),
            ..task.clone()
        };
        assert_eq!(
            settings(args(Some(ModelArg::Normal), None, None), &sharp),
            (Complementarity::Normal { sigma: 0.03 }, 0.05)
        );
        assert_eq!(
            settings(args(Some(ModelArg::Logistic), None, None), &hard),
            (Complementarity::Logistic { sigma: 0.1 }, 0.05)
        );
        let err = args(None, Some(0.2), None)
            .simulator_of(file.scene.clone(), Some(&hard))
            .unwrap_err()
            .to_string();
        assert!(err.contains("has no noise scale"), "{err}");
    }

    fn sim(model: ModelArg) -> Simulator {
        SimArgs {
            model: Some(model),
            sigma: Some(0.1),
            h: Some(0.05),
            scene: None,
            drag: DragArg::Explicit,
            recovery: 0.0,
        }
        .simulator()
        .unwrap()
    }

    #[test]
    fn a_step_line_gives_the_next_state_and_derivatives() {
        let mut s = sim(ModelArg::Logistic);
        let out: serde_json::Value = serde_json::from_str(
            &answer_line(
                &mut s,
                r#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,0]}"#,
                Answers::Derivatives,
            )
            .unwrap(),
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
        let mut s = sim(ModelArg::Hard);
        for bad in [
            "nope",
            r#"{"x":[1,2],"u":[0,0]}"#,
            r#"{"x":[0,0,0,0,0,0],"u":[0]}"#,
            r#"{"x":[0,0,0,0,0,0],"u":[0,0],"y":1}"#,
        ] {
            assert!(answer_line(&mut s, bad, Answers::Step).is_err(), "{bad}");
        }
        let mut n = sim(ModelArg::Normal);
        let nan = r#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,"NaN"]}"#;
        assert!(answer_line(&mut n, nan, Answers::Derivatives).is_err());
        // The normal model has derivatives too.
        let out = answer_line(
            &mut n,
            r#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,0]}"#,
            Answers::Derivatives,
        )
        .unwrap();
        assert!(out.contains("\"fx\""), "{out}");
        // "c" without --hessian, --hessian without "c" or with the wrong length: errors that say so.
        let with_c = r#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,0],"c":[0,0,1,0,0,0]}"#;
        let e = answer_line(&mut s, with_c, Answers::Derivatives).unwrap_err();
        assert!(e.contains("--hessian"), "{e}");
        let no_c = r#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,0]}"#;
        let e = answer_line(&mut s, no_c, Answers::Hessian).unwrap_err();
        assert!(e.contains("\"c\"") && e.contains('6'), "{e}");
        let short = r#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,0],"c":[1,2]}"#;
        let e = answer_line(&mut s, short, Answers::Hessian).unwrap_err();
        assert!(e.contains("needs 6"), "{e}");
    }

    /// `--hessian` on a scene of four joints and three controls: the (8 + 3) square Hessian of the
    /// simulator, and first derivatives with it.
    #[test]
    fn a_hessian_line_answers_any_scene() {
        let mut spec = task::ProblemFile::builtin().scene.spec().clone();
        let mut link = spec.bodies[1].clone();
        link.name = "link3".into();
        link.parent = "link2".into();
        link.joint.limits = None;
        spec.bodies.insert(2, link);
        let scene = Scene::new(spec).unwrap();
        let mut sim = Simulator::new(scene, StepSettings::default()).unwrap();
        let (x, u, c) = (
            [-1.0, -0.9, -0.6, 0.5, 0.3, -0.2, 0.1, 1.0],
            [0.2, -0.1, 0.3],
            [0.1, 0.2, -0.3, 0.4, 1.0, -0.5, 0.2, 0.3],
        );
        let line = serde_json::json!({"x": x, "u": u, "c": c}).to_string();
        let out: serde_json::Value =
            serde_json::from_str(&answer_line(&mut sim, &line, Answers::Hessian).unwrap()).unwrap();
        let hess = out["hessian"].as_array().unwrap();
        assert_eq!(hess.len(), 11);
        assert!(hess.iter().all(|r| r.as_array().unwrap().len() == 11));
        assert_eq!(out["fx"].as_array().unwrap().len(), 8);
        let (_, _, exact) = sim.step_with_hessian(&x, &u, &c).unwrap();
        for (i, row) in hess.iter().enumerate() {
            for (j, v) in row.as_array().unwrap().iter().enumerate() {
                assert_eq!(v.as_f64().unwrap(), exact[i * 11 + j]);
            }
        }
        assert!(
            exact.iter().any(|v| v.abs() > 1e-6),
            "a Hessian of zeros tests nothing"
        );
    }
}
