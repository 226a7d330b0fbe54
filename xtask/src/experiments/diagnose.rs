//! `cargo xtask diagnose`: where the paper's limit cycle is won or lost. From rest, without kicks, the
//! same task is run under (a) the receding-horizon optimiser itself as MPC with converged re-solves (the
//! upper bound a library approximates; at the paper's horizon N = 75 and at the default 90, applying one
//! step or the library's shift of four steps per re-solve), (b) the viewer's online MPC (one pass per
//! control step, N = 60), (c) the global policies of the paper's library and of the default one. Each
//! run's spin over its last quarter, its contacts per half turn, and a picture of its last 20 s in
//! configuration space.

use crate::experiments::draw::{both, register_font};
use crate::experiments::figures::{Run, draw_cycle_2d};
use anyhow::Context;
use ddp::{Ddp, DdpSettings};
use dynamics::{Complementarity, Simulator, StepSettings};
use library::{ContactEvents, Library, LibrarySettings};
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;
use task::SceneDynamics;
use viewer::protocol::{ClientMessage, PolicyKind, WorldKind};
use viewer::{World, WorldSettings};

/// Options of `cargo xtask diagnose`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder (diagnose.md, diagnose.json, diagnose.png and .svg).
    #[arg(long, default_value = "results/diagnose")]
    out: PathBuf,
    /// Simulated seconds per run.
    #[arg(long, default_value_t = SECONDS, value_parser = seconds)]
    seconds: f64,
    /// The documentation folder whose results.md and figures/ a run of the default length rewrites.
    #[arg(long, default_value = "docs")]
    docs: PathBuf,
    /// Leave the documentation alone.
    #[arg(long)]
    no_docs: bool,
}

const SECONDS: f64 = 200.0;

fn seconds(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(s) if (1.0..=10_000.0).contains(&s) => Ok(s),
        _ => Err(format!("{text}: expected seconds between 1 and 10000")),
    }
}

/// One run's measures.
#[derive(serde::Serialize)]
struct Measured {
    controller: String,
    world: String,
    /// Mean spin over the last quarter, rad/s.
    last_quarter: f64,
    /// Contact events per half turn of the ellipse over the last quarter (null when it did not turn).
    contacts_per_half_turn: Option<f64>,
    /// Wall time per control step, ms.
    ms_per_step: f64,
}

/// What to run.
#[derive(Clone, Copy)]
enum Controller {
    /// Converged receding-horizon re-solves every `shift` steps with horizon `horizon`.
    Receding { horizon: usize, shift: usize },
    /// The viewer's online MPC.
    Online,
    /// A library's policy (`true`: the paper's recipe).
    Policy { paper: bool },
}

impl Controller {
    fn name(self) -> String {
        match self {
            Controller::Receding { horizon, shift } => format!(
                "optimiser as MPC, N = {horizon}, re-solved every {shift} step{}",
                if shift > 1 { "s" } else { "" }
            ),
            Controller::Online => "online MPC (N = 60, 1 pass per step)".into(),
            Controller::Policy { paper: true } => "policy of the paper's library".into(),
            Controller::Policy { paper: false } => "policy of the default library".into(),
        }
    }
}

fn model(hard: bool) -> Complementarity {
    if hard {
        Complementarity::Hard
    } else {
        Complementarity::Logistic { sigma: 0.1 }
    }
}

/// The world's simulator at h = 0.05.
fn world(hard: bool) -> anyhow::Result<Simulator> {
    Ok(Simulator::new(
        task::ProblemFile::builtin().scene,
        StepSettings {
            model: model(hard),
            h: 0.05,
            ..StepSettings::default()
        },
    )?)
}

fn receding(horizon: usize, shift: usize, hard: bool, seconds: f64) -> anyhow::Result<Run> {
    let (scene, task) = task::ProblemFile::builtin_task();
    let settings = LibrarySettings {
        horizon,
        ..LibrarySettings::default().for_task(&task)
    };
    let dynamics = SceneDynamics::new(settings.simulator(&scene)?);
    let cost = task.cost;
    let mut sim = world(hard)?;
    let mut x = settings.x0.clone();
    let mut plan = vec![vec![0.0; scene.n_controls]; horizon];
    let mut run = Run {
        states: vec![x.clone()],
        impulses: vec![0.0],
        h: 0.05,
    };
    let steps = (seconds / 0.05).round() as usize;
    let mut first = true;
    while run.states.len() <= steps {
        let ddp = Ddp::new(DdpSettings {
            max_iterations: if first {
                settings.first_passes
            } else {
                settings.warm_passes
            },
            tol_cost: settings.tolerance,
            ..DdpSettings::default()
        })?;
        first = false;
        let sol = ddp.solve(&dynamics, &cost, &x, &plan)?;
        for t in 0..shift {
            // The plan's time-varying law (its feedback acts after the first step).
            let mut u = sol.controls[t].clone();
            for (a, ua) in u.iter_mut().enumerate() {
                for (b, xb) in x.iter().enumerate() {
                    *ua += sol.gains[t][a * x.len() + b] * (xb - sol.states[t][b]);
                }
            }
            let s = sim.step(&x, &u)?;
            run.impulses.push(s.normal_impulse());
            x = s.x_next;
            run.states.push(x.clone());
        }
        plan = ddp::shift_controls(&sol.controls, shift);
    }
    Ok(run)
}

fn online(lib: &Library, hard: bool, seconds: f64) -> anyhow::Result<Run> {
    let mut w = World::new(
        task::ProblemFile::builtin().scene,
        Some(lib.clone()),
        WorldSettings {
            policy: PolicyKind::Mpc,
            ..WorldSettings::default()
        },
    )?;
    if hard {
        w.apply(ClientMessage::World {
            world: WorldKind::Hard,
        })?;
    }
    let mut run = Run {
        states: vec![w.state().to_vec()],
        impulses: vec![0.0],
        h: w.h(),
    };
    for _ in 0..(seconds / w.h()).round() as usize {
        w.advance()?;
        let frame = w.frame();
        let impulse = frame
            .contacts
            .iter()
            .map(|c| c.impulse[0] * c.normal[0] + c.impulse[1] * c.normal[1])
            .sum();
        run.impulses.push(impulse);
        run.states.push(frame.x);
    }
    Ok(run)
}

fn policy(lib: &Library, hard: bool, seconds: f64) -> anyhow::Result<Run> {
    let policy = lib.policy()?;
    let mut sim = world(hard)?;
    let mut x = lib.x0().to_vec();
    let mut u = vec![0.0; lib.scene().n_controls];
    let mut run = Run {
        states: vec![x.clone()],
        impulses: vec![0.0],
        h: 0.05,
    };
    for _ in 0..(seconds / 0.05).round() as usize {
        policy.control(&x, &mut u)?;
        let s = sim.step(&x, &u)?;
        run.impulses.push(s.normal_impulse());
        x = s.x_next;
        run.states.push(x.clone());
    }
    Ok(run)
}

/// Spin over the last quarter and contact events per half turn there.
fn measure(run: &Run) -> (f64, f64) {
    let n = run.states.len() - 1;
    let from = n - n / 4;
    let turned = run.states[n][2] - run.states[from][2];
    let mut contacts = ContactEvents::default();
    for &impulse in &run.impulses[from + 1..] {
        contacts.observe(impulse);
    }
    // A ratio per half turn only where the ellipse turned at least half a turn.
    let per_half_turn = if turned.abs() >= std::f64::consts::PI {
        contacts.events as f64 / (turned.abs() / std::f64::consts::PI)
    } else {
        f64::INFINITY
    };
    (turned / ((n - from) as f64 * run.h), per_half_turn)
}

/// Every run's picture, two to a row.
fn draw_panels<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    runs: &[(String, Run)],
) -> anyhow::Result<()> {
    let panels = root.split_evenly((runs.len().div_ceil(2), 2));
    for ((name, run), panel) in runs.iter().zip(&panels) {
        draw_cycle_2d(panel, run, name)?;
    }
    Ok(())
}

/// Run `cargo xtask diagnose`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let start = Instant::now();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    println!("building the paper's and the default library ...");
    let libraries: Vec<Library> = std::thread::scope(|scope| {
        let jobs: Vec<_> = [LibrarySettings::paper(), LibrarySettings::default()]
            .map(|s| {
                scope.spawn(move || {
                    Library::build(&task::ProblemFile::builtin(), None, &s, |_, _| {})
                })
            })
            .into_iter()
            .collect();
        jobs.into_iter()
            .map(|j| j.join().expect("a library build does not panic"))
            .collect::<Result<_, _>>()
    })?;
    let (paper, default) = (&libraries[0], &libraries[1]);
    let mut jobs = Vec::new();
    for (horizon, shift) in [(75, 4), (90, 4), (75, 1), (90, 1)] {
        jobs.push((Controller::Receding { horizon, shift }, false));
    }
    jobs.push((
        Controller::Receding {
            horizon: 90,
            shift: 4,
        },
        true,
    ));
    for c in [
        Controller::Online,
        Controller::Policy { paper: true },
        Controller::Policy { paper: false },
    ] {
        jobs.push((c, false));
        jobs.push((c, true));
    }
    println!(
        "{} closed loops of {} s from rest ...",
        jobs.len(),
        args.seconds
    );
    let work = |&(c, hard): &(Controller, bool)| -> anyhow::Result<(Run, f64)> {
        let t = Instant::now();
        let run = match c {
            Controller::Receding { horizon, shift } => {
                receding(horizon, shift, hard, args.seconds)?
            }
            Controller::Online => online(default, hard, args.seconds)?,
            Controller::Policy { paper: true } => policy(paper, hard, args.seconds)?,
            Controller::Policy { paper: false } => policy(default, hard, args.seconds)?,
        };
        let ms = t.elapsed().as_secs_f64() * 1e3 / (run.states.len() - 1) as f64;
        Ok((run, ms))
    };
    let done = crate::on_two_threads(&jobs, work);
    let mut rows = Vec::new();
    let mut runs = Vec::new();
    for ((c, hard), result) in jobs.iter().zip(done) {
        let (run, ms) = result?;
        let (last_quarter, contacts_per_half_turn) = measure(&run);
        let world = if *hard { "hard" } else { "logistic 0.1" };
        rows.push(Measured {
            controller: c.name(),
            world: world.into(),
            last_quarter,
            contacts_per_half_turn: contacts_per_half_turn
                .is_finite()
                .then_some(contacts_per_half_turn),
            ms_per_step: ms,
        });
        runs.push((format!("{}, {world}", c.name()), run));
    }
    let mut md = format!(
        "# Where the cycle is lost (`cargo xtask diagnose`, {:.0} s per run from rest, no kicks, h = 0.05)\n\n| controller | world | last quarter (rad/s) | contacts per half turn | ms per control step |\n|---|---|---:|---:|---:|\n",
        args.seconds
    );
    for r in &rows {
        let per_half_turn = r
            .contacts_per_half_turn
            .map_or("- (under half a turn)".into(), |c| format!("{c:.2}"));
        let _ = writeln!(
            md,
            "| {} | {} | {:.3} | {per_half_turn} | {:.2} |",
            r.controller, r.world, r.last_quarter, r.ms_per_step
        );
    }
    let _ = writeln!(
        md,
        "\n![each run's last 20 s in (theta1, theta2), coloured by contact impulse](figures/diagnose.png)\n\n{:.0} s in all.",
        start.elapsed().as_secs_f64()
    );
    crate::write_file(args.out.join("diagnose.md"), &md)?;
    crate::write_file(
        args.out.join("diagnose.json"),
        serde_json::to_string_pretty(&rows)?,
    )?;
    register_font()?;
    let panels = runs.len().div_ceil(2);
    both(
        &args.out,
        "diagnose",
        (1200, 380 * panels as u32),
        |r| draw_panels(r, &runs),
        |r| draw_panels(r, &runs),
    )?;
    println!("{md}");
    println!(
        "wrote {}/diagnose.md, diagnose.json, diagnose.png and .svg",
        args.out.display()
    );
    if !args.no_docs && args.seconds == SECONDS {
        crate::experiments::recipe::write_docs(
            &args.docs,
            "diagnose",
            "cargo xtask diagnose",
            &md,
            &[args.out.join("diagnose.png")],
        )?;
        println!(
            "rewrote the diagnosis in {}/results.md and {}/figures/diagnose.png",
            args.docs.display(),
            args.docs.display()
        );
    }
    Ok(())
}
