//! `cargo xtask examples`: other scenes and tasks through the whole pipeline (issue 15): for each, the
//! task solved from rest by full second-order DDP, libraries over several seeds, their policies in closed
//! loop on the smoothed and the hard world, a success measure per run, a table and two pictures, and
//! the generated section of docs/results.md. By default the three example scenes under scenes/; with
//! `--scene FILE --task NAME`, any scene file's task.

use crate::draw;
use crate::figures::{both, err, register_font};
use anyhow::Context;
use ddp::{Ddp, DdpSettings};
use library::{
    Evaluation, EvaluationSettings, Exploration, FingerDynamics, Library, LibrarySettings, Model,
    ProblemFile, Task, evaluate,
};
use plotters::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `cargo xtask examples`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A scene file to run instead of the three examples (with --task when it has several tasks); its
    /// library recipe is the flags below. The documentation is then left alone.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// The task of --scene.
    #[arg(long, requires = "scene")]
    task: Option<String>,
    /// Library seeds per example (1 to this).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=32))]
    seeds: u64,
    /// Simulated seconds per closed-loop run.
    #[arg(long, default_value_t = SECONDS)]
    seconds: f64,
    /// Output folder (tables as JSON, pictures, libraries).
    #[arg(long, default_value = "results/examples")]
    out: PathBuf,
    /// The documentation folder whose results.md section "examples" and figures a run of the three
    /// examples with the default seeds and seconds rewrites.
    #[arg(long, default_value = "docs")]
    docs: PathBuf,
    /// Leave the documentation alone.
    #[arg(long)]
    no_docs: bool,
    /// With --scene: trajectories of the library (before growth).
    #[arg(long, default_value_t = 120)]
    trajectories: usize,
    /// With --scene: the unperturbed chain's trajectories.
    #[arg(long, default_value_t = 40)]
    trunk: usize,
    /// With --scene: trunk trajectories branches do not start from.
    #[arg(long, default_value_t = 5)]
    settle: usize,
    /// With --scene: trajectories per branch.
    #[arg(long, default_value_t = 10)]
    length: usize,
    /// With --scene: growth rounds (only for a task that rewards progress along its periodic
    /// coordinate).
    #[arg(long, default_value_t = 0)]
    growth: usize,
}

/// Simulated seconds per closed-loop run of the documented results.
const SECONDS: f64 = 40.0;
/// Standard deviation of each velocity's kick in the kicked runs.
const KICK_STD: f64 = 1.0;
/// Seconds between kicks in the kicked runs.
const KICK_EVERY: f64 = 10.0;

/// What counts as success for an example.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
enum Success {
    /// The rewarded coordinate advances at least this fast (its unit per second) over the run's last
    /// quarter.
    Rate(f64),
    /// Every position target is within this distance over the run's last quarter (the worst of it).
    Hold(f64),
}

impl Success {
    fn describe(self) -> String {
        match self {
            Success::Rate(r) => format!(
                "still spinning at the end: at least {r} rad/s forward over the run's last quarter"
            ),
            Success::Hold(d) => format!(
                "at the target and held there: within {d} of every position target throughout the run's last quarter"
            ),
        }
    }

    /// The same measure after kicks: a progress task's last-quarter rate, a target task's distance at
    /// the end of the run (ten seconds after the last kick), and whether it meets the same threshold.
    fn judge_kicked(self, e: &Evaluation) -> (f64, bool) {
        match self {
            Success::Rate(_) => self.judge(e),
            Success::Hold(max) => {
                let worst = e
                    .task
                    .targets
                    .iter()
                    .filter(|t| !t.entry.ends_with("velocity"))
                    .map(|t| t.last)
                    .fold(f64::NAN, f64::max);
                (worst, worst <= max)
            }
        }
    }

    /// The measure and whether it passes.
    fn judge(self, e: &Evaluation) -> (f64, bool) {
        match self {
            Success::Rate(min) => {
                let rate = e
                    .task
                    .rates
                    .iter()
                    .map(|r| -r.weight.signum() * r.final_rate)
                    .fold(f64::NAN, f64::min);
                (rate, rate >= min)
            }
            Success::Hold(max) => {
                let worst = e
                    .task
                    .targets
                    .iter()
                    .filter(|t| !t.entry.ends_with("velocity"))
                    .map(|t| t.final_worst)
                    .fold(f64::NAN, f64::max);
                (worst, worst <= max)
            }
        }
    }
}

/// One example: a scene file of this repository, its task, its library recipe and its success measure.
#[derive(Debug, Clone, Serialize)]
struct Example {
    name: String,
    file: String,
    #[serde(skip)]
    text: String,
    task: String,
    what: String,
    trajectories: usize,
    trunk: usize,
    settle: usize,
    length: usize,
    growth: usize,
    success: Success,
}

/// The three examples of issue 15.
fn examples() -> Vec<Example> {
    let ex = |name: &str,
              file: &str,
              text: &str,
              task: &str,
              what: &str,
              recipe: [usize; 5],
              success| Example {
        name: name.into(),
        file: file.into(),
        text: text.into(),
        task: task.into(),
        what: what.into(),
        trajectories: recipe[0],
        trunk: recipe[1],
        settle: recipe[2],
        length: recipe[3],
        growth: recipe[4],
        success,
    };
    vec![
        ex(
            "three_link",
            "scenes/three_link_finger.toml",
            include_str!("../../scenes/three_link_finger.toml"),
            "spin",
            "a three-link finger spins the ellipse (the paper's task; 4 joints, 3 controls, 2 contact pairs)",
            [200, 60, 15, 10, 12],
            Success::Rate(0.5),
        ),
        ex(
            "two_fingers",
            "scenes/two_fingers.toml",
            include_str!("../../scenes/two_fingers.toml"),
            "turn",
            "two two-link fingers mounted either side of the ellipse turn it to 0.5 rad and hold it there (the Control Suite's finger-turn task with two fingers; 5 joints, 4 controls, 2 contact pairs)",
            [300, 60, 10, 20, 0],
            Success::Hold(0.05),
        ),
        ex(
            "pushing",
            "scenes/pushing.toml",
            include_str!("../../scenes/pushing.toml"),
            "push",
            "a two-link finger pushes a free block resting on the ground 0.6 to the right, in the vertical plane (free body, ground contact with friction)",
            [80, 30, 5, 10, 0],
            Success::Hold(0.05),
        ),
    ]
}

/// A fingerprint of what the documented examples depend on: the recipes, the success measures, the
/// scene files, the seeds and seconds, the library defaults they start from.
pub(crate) fn stamp() -> String {
    let inputs = serde_json::json!({
        "examples": examples(),
        "texts": examples().iter().map(|e| e.text.clone()).collect::<Vec<_>>(),
        "default": LibrarySettings::default(),
        "format": library::VERSION,
        "seeds": 3,
        "seconds": SECONDS,
        "kicks": [KICK_STD, KICK_EVERY],
        // The step itself (how penetration is recovered, issue 27): new physics, new numbers.
        "step": dynamics::StepSettings::default(),
    });
    format!("{:08x}", crc32fast::hash(inputs.to_string().as_bytes()))
}

fn stamp_line() -> String {
    format!(
        "(examples stamp {}: the scenes, recipes and measures these numbers were computed with; a test checks it against the code)",
        stamp()
    )
}

/// The optimiser from the task's initial state and zero controls.
#[derive(Debug, Serialize)]
struct FromRest {
    passes: usize,
    status: String,
    cost: f64,
    seconds: f64,
    /// `(entry, at the start, at the horizon's end, target)` of each entry the task weighs.
    entries: Vec<(String, f64, f64, Option<f64>)>,
}

fn from_rest(problem: &ProblemFile, task: &Task) -> anyhow::Result<FromRest> {
    let sim = LibrarySettings::default()
        .for_task(task)
        .simulator(&problem.scene)?;
    let m = problem.scene.n_controls;
    let ddp = Ddp::new(DdpSettings {
        control_limits: task.control_limits.clone(),
        max_iterations: 300,
        ..DdpSettings::default()
    })?;
    let start = Instant::now();
    let sol = ddp.solve(
        &mut FingerDynamics::new(sim),
        &task.cost,
        &task.x0,
        &vec![vec![0.0; m]; task.horizon],
    )?;
    let seconds = start.elapsed().as_secs_f64();
    let names = problem.scene.state_names();
    let last = sol.states.last().expect("N + 1 states");
    let mut entries: Vec<(String, f64, f64, Option<f64>)> = Vec::new();
    for t in task.cost.running.iter().chain(&task.cost.final_terms) {
        let target = (t.quadratic != 0.0).then_some(t.target);
        if !entries
            .iter()
            .any(|e| e.0 == names[t.index] && e.3 == target)
        {
            entries.push((
                names[t.index].clone(),
                task.x0[t.index],
                last[t.index],
                target,
            ));
        }
    }
    Ok(FromRest {
        passes: sol.iterations.len(),
        status: if sol.status.converged() {
            "converged".into()
        } else {
            format!("not converged: {:?}", sol.status)
        },
        cost: sol.cost,
        seconds,
        entries,
    })
}

/// One library's closed loops.
#[derive(Debug, Serialize)]
struct SeedRun {
    seed: u64,
    controllers: usize,
    trajectories: usize,
    build_seconds: f64,
    /// `(world, evaluation, success measure, passed)`.
    worlds: Vec<(String, Evaluation, f64, bool)>,
    /// Per world, the run with velocity kicks ([`KICK_STD`] every [`KICK_EVERY`] s): its measure
    /// ([`Success::judge_kicked`]) and whether it meets the threshold.
    kicked: Vec<(f64, bool)>,
    /// The watched entries over time per world (for the pictures), not in the JSON.
    #[serde(skip)]
    traces: Vec<Vec<Vec<f64>>>,
}

#[derive(Debug, Serialize)]
struct ExampleResult {
    example: Example,
    sizes: (usize, usize, usize, usize),
    from_rest: FromRest,
    seeds: Vec<SeedRun>,
}

fn recipe(task: &Task, e: &Example, seed: u64) -> LibrarySettings {
    LibrarySettings {
        trajectories: e.trajectories,
        exploration: Exploration::Branches {
            trunk: e.trunk,
            settle: e.settle,
            length: e.length,
        },
        growth: e.growth,
        seed,
        ..LibrarySettings::default().for_task(task)
    }
}

/// The closed loop of `lib`'s policy from the task's x0 in one world, with kicks every `kick_every` s
/// (0: none): its evaluation.
fn evaluated(
    lib: &Library,
    policy: &library::Policy,
    task: &Task,
    model: Model,
    seconds: f64,
    kick_every: f64,
) -> anyhow::Result<Evaluation> {
    Ok(evaluate(
        lib,
        policy,
        &EvaluationSettings {
            model,
            h: task.h,
            seconds,
            kick_every,
            kick_std: KICK_STD,
            x0: task.x0.clone(),
            ..EvaluationSettings::default()
        },
    )?)
}

fn run_example(
    e: &Example,
    seeds: u64,
    seconds: f64,
    out: &Path,
) -> anyhow::Result<(ExampleResult, Vec<PathBuf>)> {
    let problem =
        ProblemFile::from_toml_str(&e.text).with_context(|| format!("scene {}", e.file))?;
    let task = problem.task(Some(&e.task))?;
    let scene = &problem.scene;
    println!("{}: {}", e.name, e.what);
    let rest = from_rest(&problem, &task)?;
    println!(
        "  from rest: {} passes ({}), cost {:.3}, {:.2} s",
        rest.passes, rest.status, rest.cost, rest.seconds
    );
    let worlds = [
        (
            match task.model {
                Model::Logistic(s) => format!("logistic {s}"),
                Model::Normal(s) => format!("normal {s}"),
                Model::Hard => "hard (its own)".into(),
            },
            task.model,
        ),
        ("hard".to_string(), Model::Hard),
    ];
    let seed_list: Vec<u64> = (1..=seeds).collect();
    let runs = crate::on_two_threads(&seed_list, |&seed| -> anyhow::Result<(SeedRun, Library)> {
        let settings = recipe(&task, e, seed);
        let start = Instant::now();
        let lib = Library::build_task(&problem, Some(&e.task), &settings, |_, _| {})?;
        let build_seconds = start.elapsed().as_secs_f64();
        let mut run = SeedRun {
            seed,
            controllers: lib.entries.len(),
            trajectories: lib.entries.len() / settings.keep,
            build_seconds,
            worlds: Vec::new(),
            kicked: Vec::new(),
            traces: Vec::new(),
        };
        let policy = lib.policy()?;
        let steps = (seconds / task.h).round() as usize;
        for &(ref name, model) in &worlds {
            let evaluation = evaluated(&lib, &policy, &task, model, seconds, 0.0)?;
            let (measure, passed) = e.success.judge(&evaluation);
            run.worlds.push((name.clone(), evaluation, measure, passed));
            let trace =
                crate::figures::closed_loop(&lib, &policy, (model, task.h), &task.x0, steps)?;
            run.traces.push(trace.states);
            let kicked = evaluated(&lib, &policy, &task, model, seconds, KICK_EVERY)?;
            run.kicked.push(e.success.judge_kicked(&kicked));
        }
        println!(
            "  seed {seed}: {} controllers in {build_seconds:.1} s; {}",
            run.controllers,
            run.worlds
                .iter()
                .map(|(w, _, m, p)| format!("{w} {m:.3} {}", if *p { "pass" } else { "FAIL" }))
                .collect::<Vec<_>>()
                .join(", ")
        );
        Ok((run, lib))
    });
    let mut seed_runs = Vec::new();
    let mut first_lib = None;
    for r in runs {
        let (run, lib) = r?;
        if first_lib.is_none() {
            first_lib = Some(lib.clone());
            lib.save(&out.join(format!("{}.lib", e.name)))?;
        }
        seed_runs.push(run);
    }
    let figures = pictures(e, scene, &task, &seed_runs, out)?;
    Ok((
        ExampleResult {
            example: e.clone(),
            sizes: (
                scene.n_dof(),
                scene.n_controls,
                scene.contacts.len(),
                scene.rows().len(),
            ),
            from_rest: rest,
            seeds: seed_runs,
        },
        figures,
    ))
}

/// The entries the pictures follow: the rewarded coordinate of a progress task, else every position
/// target (`(index, name, target)`).
fn watched(scene: &dynamics::Scene, task: &Task) -> Vec<(usize, String, Option<f64>)> {
    let names = scene.state_names();
    let mut out: Vec<(usize, String, Option<f64>)> = Vec::new();
    let n = scene.n_dof();
    for t in task.cost.running.iter().chain(&task.cost.final_terms) {
        if t.index >= n || out.iter().any(|o| o.0 == t.index) {
            continue;
        }
        out.push((
            t.index,
            names[t.index].clone(),
            (t.quadratic != 0.0).then_some(t.target),
        ));
    }
    out
}

fn pictures(
    e: &Example,
    scene: &dynamics::Scene,
    task: &Task,
    runs: &[SeedRun],
    out: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    register_font()?;
    let traces: Vec<(u64, &[Vec<Vec<f64>>])> =
        runs.iter().map(|r| (r.seed, r.traces.as_slice())).collect();
    task_pictures(
        &format!("examples_{}", e.name),
        &e.name,
        matches!(e.success, Success::Hold(_)),
        scene,
        task,
        &traces,
        out,
    )
}

/// Two pictures of a task's closed loops under `out`: `{file}_time` (the watched entry over time, per
/// seed, solid on the smoothed world and dashed on the hard one) and `{file}_frames` (eight frames of the
/// first run: the first four seconds when the task `holds` a target, else the last four). Returns the
/// PNGs' paths (SVGs are written beside them).
pub(crate) fn task_pictures(
    file: &str,
    title: &str,
    holds: bool,
    scene: &dynamics::Scene,
    task: &Task,
    runs: &[(u64, &[Vec<Vec<f64>>])],
    out: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    register_font()?;
    let watched = watched(scene, task);
    let time_name = format!("{file}_time");
    both(
        out,
        &time_name,
        (900, 450),
        |root| time_plot(root, title, task, &watched, runs),
        |root| time_plot(root, title, task, &watched, runs),
    )?;
    let frames_name = format!("{file}_frames");
    let states = &runs[0].1[0];
    both(
        out,
        &frames_name,
        (1200, 640),
        |root| frames(root, title, holds, scene, task, states),
        |root| frames(root, title, holds, scene, task, states),
    )?;
    Ok(vec![
        out.join(format!("{time_name}.png")),
        out.join(format!("{frames_name}.png")),
    ])
}

fn time_plot<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    task: &Task,
    watched: &[(usize, String, Option<f64>)],
    runs: &[(u64, &[Vec<Vec<f64>>])],
) -> anyhow::Result<()> {
    let (i, name, target) = watched
        .first()
        .cloned()
        .ok_or_else(|| anyhow::anyhow!("the task weighs no position"))?;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, traces) in runs {
        for trace in traces.iter() {
            for x in trace {
                lo = lo.min(x[i]);
                hi = hi.max(x[i]);
            }
        }
    }
    if let Some(t) = target {
        lo = lo.min(t);
        hi = hi.max(t);
    }
    let pad = 0.05 * (hi - lo).max(1e-3);
    let t_end = runs[0].1[0].len().saturating_sub(1) as f64 * task.h;
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "{title}: {name} in closed loop from x0, {} seeds (solid: smoothed world, dashed: hard)",
                runs.len()
            ),
            ("sans-serif", 14),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..t_end, lo - pad..hi + pad)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_desc(name.as_str())
        .draw()
        .map_err(err)?;
    if let Some(t) = target {
        chart
            .draw_series(LineSeries::new(
                [(0.0, t), (t_end, t)],
                BLACK.mix(0.5).stroke_width(1),
            ))
            .map_err(err)?;
    }
    for (s, (seed, traces)) in runs.iter().enumerate() {
        let colour = Palette99::pick(s).to_rgba();
        for (w, trace) in traces.iter().enumerate() {
            let points: Vec<(f64, f64)> = trace
                .iter()
                .enumerate()
                .map(|(k, x)| (k as f64 * task.h, x[i]))
                .collect();
            if w == 0 {
                chart
                    .draw_series(LineSeries::new(points, colour.stroke_width(2)))
                    .map_err(err)?
                    .label(format!("seed {seed}"))
                    .legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2))
                    });
            } else {
                chart
                    .draw_series(DashedLineSeries::new(points, 6, 4, colour.stroke_width(1)))
                    .map_err(err)?;
            }
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}

/// Eight frames of the first run on the smoothed world: the first four seconds for a task that `holds`
/// targets (the approach), the last four for a progress task (the steady motion).
fn frames<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    holds: bool,
    scene: &dynamics::Scene,
    task: &Task,
    states: &[Vec<f64>],
) -> anyhow::Result<()> {
    let count = 8;
    let span = ((4.0 / task.h).round() as usize).min(states.len() - 1);
    let first = if holds { 0 } else { states.len() - 1 - span };
    let picked: Vec<usize> = (0..count).map(|k| first + k * span / (count - 1)).collect();
    let window: Vec<Vec<f64>> = picked.iter().map(|&k| states[k].clone()).collect();
    root.titled(
        &format!(
            "{title}: the first run on the smoothed world, {} frames {:.2} s apart",
            count,
            span as f64 * task.h / (count - 1) as f64
        ),
        ("sans-serif", 16),
    )
    .map_err(err)?;
    let panels = root.margin(30, 5, 5, 5).split_evenly((2, count / 2));
    let (w, h) = panels[0].dim_in_pixel();
    let (xr, yr) = draw::bounds(scene, &window, w as f64 / h.max(1) as f64);
    for (panel, &k) in panels.iter().zip(&picked) {
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!("t = {:.2} s", k as f64 * task.h),
                ("sans-serif", 12),
            )
            .build_cartesian_2d(xr.clone(), yr.clone())
            .map_err(err)?;
        draw::draw_static(&mut chart, scene)?;
        draw::draw_bodies(&mut chart, scene, &states[k])?;
    }
    Ok(())
}

fn report(results: &[ExampleResult], seconds: f64) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "# Other scenes and tasks (`cargo xtask examples`)\n\nEach example's scene file and task, solved by full second-order DDP from rest (zero controls, the task's x0 and horizon, 300 passes at most), then a library per seed (the default recipe's branches, sized per example: trunk, settle, branch length, budget, growth rounds), and its policy run in closed loop from x0 for {seconds} s on the task's smoothed world and on hard contact, at the task's time step, without kicks. A run passes when it meets the example's success measure. Each library's policy also runs the same way with velocity kicks (normal, standard deviation {KICK_STD}, every {KICK_EVERY} s, the last {KICK_EVERY} s before the end), judged by the same threshold on its last-quarter rate or on its distance at the end."
    );
    for r in results {
        let e = &r.example;
        let (n, m, pairs, rows) = r.sizes;
        let _ = writeln!(
            t,
            "\n## {} (`{}`, task `{}`)\n\n{}: {n} coordinates, {m} controls, {pairs} contact pairs, {rows} complementarity rows.\n\nSuccess: {}.\n",
            e.name,
            e.file,
            e.task,
            e.what,
            e.success.describe()
        );
        let entries: Vec<String> = r
            .from_rest
            .entries
            .iter()
            .map(|(name, a, b, target)| {
                let target = target.map_or(String::new(), |v| format!(" (target {v})"));
                format!("{name} {a:.3} -> {b:.3}{target}")
            })
            .collect();
        let _ = writeln!(
            t,
            "From rest: {} passes ({}), cost {:.3}, {:.2} s; over the horizon {}.\n",
            r.from_rest.passes,
            r.from_rest.status,
            r.from_rest.cost,
            r.from_rest.seconds,
            entries.join(", ")
        );
        let _ = writeln!(
            t,
            "Library recipe: {} trajectories (trunk {}, settle {}, branches of {}), {} growth rounds.\n",
            e.trajectories, e.trunk, e.settle, e.length, e.growth
        );
        let measure = match e.success {
            Success::Rate(_) => "last-quarter rate (rad/s)",
            Success::Hold(_) => "last-quarter worst distance",
        };
        let kicked_measure = match e.success {
            Success::Rate(_) => "last-quarter rate",
            Success::Hold(_) => "distance at the end",
        };
        let _ = writeln!(
            t,
            "| seed | controllers | build | world | {measure} | pass | with kicks: {kicked_measure} (meets it) | running cost per second (whole / last quarter) | distance to targets at the end | unconverged steps |\n|---:|---:|---:|---|---:|---|---:|---:|---|---:|"
        );
        for s in &r.seeds {
            for ((world, ev, value, passed), (kicked, kicked_passed)) in
                s.worlds.iter().zip(&s.kicked)
            {
                let targets: Vec<String> = ev
                    .task
                    .targets
                    .iter()
                    .map(|d| format!("{} {:.3}", d.entry, d.last))
                    .collect();
                let _ = writeln!(
                    t,
                    "| {} | {} | {:.1} s | {world} | {value:.3} | {} | {kicked:.3} ({}) | {:.3} / {:.3} | {} | {} |",
                    s.seed,
                    s.controllers,
                    s.build_seconds,
                    if *passed { "yes" } else { "no" },
                    if *kicked_passed { "yes" } else { "no" },
                    ev.task.running_cost_per_second,
                    ev.task.final_running_cost_per_second,
                    if targets.is_empty() {
                        "-".into()
                    } else {
                        targets.join("; ")
                    },
                    ev.unconverged_steps
                );
            }
        }
        for (w, world) in ["smoothed", "hard"].iter().enumerate() {
            let values: Vec<f64> = r.seeds.iter().map(|s| s.worlds[w].2).collect();
            let passed = r.seeds.iter().filter(|s| s.worlds[w].3).count();
            let (lo, hi) = values
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    (a.min(*v), b.max(*v))
                });
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            let kicked_passed = r.seeds.iter().filter(|s| s.kicked[w].1).count();
            let _ = writeln!(
                t,
                "\n{world}: {passed} of {} seeds pass; {measure} mean {mean:.3}, range {lo:.3} to {hi:.3}. With kicks, {kicked_passed} of {} meet the same threshold.",
                r.seeds.len(),
                r.seeds.len()
            );
        }
        let _ = writeln!(
            t,
            "\n![{0}: the watched coordinate over time](figures/examples_{0}_time.png)\n\n![{0}: frames](figures/examples_{0}_frames.png)",
            e.name
        );
    }
    t
}

/// Run `cargo xtask examples`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    if !(args.seconds.is_finite() && (1.0..=10_000.0).contains(&args.seconds)) {
        anyhow::bail!("--seconds {} must be between 1 and 10000", args.seconds);
    }
    let list = match &args.scene {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            let problem = ProblemFile::from_toml_str(&text)
                .with_context(|| format!("scene {}", path.display()))?;
            let task = problem.task(args.task.as_deref())?;
            let progress = library::Progress::of_task(&task)?;
            let name = path
                .file_stem()
                .map_or("scene".into(), |s| s.to_string_lossy().to_string());
            vec![Example {
                name,
                file: path.display().to_string(),
                text,
                what: format!("task {}", task.name),
                task: task.name.clone(),
                trajectories: args.trajectories,
                trunk: args.trunk,
                settle: args.settle,
                length: args.length,
                growth: args.growth,
                success: match progress.forward {
                    Some(_) => Success::Rate(0.5),
                    None => Success::Hold(0.1),
                },
            }]
        }
        None => examples(),
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let start = Instant::now();
    let mut results = Vec::new();
    let mut figures = Vec::new();
    for e in &list {
        let (r, f) = run_example(e, args.seeds, args.seconds, &args.out)?;
        results.push(r);
        figures.extend(f);
    }
    let body = report(&results, args.seconds);
    crate::write_file(args.out.join("examples.md"), &body)?;
    crate::write_file(
        args.out.join("examples.json"),
        serde_json::to_string_pretty(&results)?,
    )?;
    println!("{body}");
    println!(
        "wrote {} and examples.json in {:.0} s",
        args.out.join("examples.md").display(),
        start.elapsed().as_secs_f64()
    );
    let documented = args.scene.is_none() && args.seeds == 3 && args.seconds == SECONDS;
    if documented && !args.no_docs {
        crate::reproduce::write_section(
            &args.docs,
            "examples",
            "cargo xtask examples",
            &stamp_line(),
            "#",
            &body,
            &figures,
        )?;
        println!("rewrote {}", args.docs.join("results.md").display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_documented_examples_were_computed_with_the_current_settings() {
        let text =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/results.md"))
                .expect("docs/results.md");
        let begin = "<!-- BEGIN examples (generated by `cargo xtask examples`) -->";
        let at = text
            .find(begin)
            .expect("docs/results.md has an examples section");
        assert!(
            text[at..].contains(&stamp_line()),
            "docs/results.md's examples section is stale (its stamp is not {}): run `cargo xtask examples`",
            stamp()
        );
    }

    #[test]
    fn the_success_measures_judge_what_they_say() {
        let mut e = Evaluation {
            spin_rate: 0.0,
            final_spin_rate: 0.0,
            contacts_per_half_turn: None,
            contacts_per_second: 0.0,
            contact_fraction: 0.0,
            kicks: 0,
            recovered: 0,
            resumed: 0,
            resume_time: None,
            spin_after_kicks: None,
            unconverged_steps: 0,
            final_angle: 0.0,
            task: Default::default(),
        };
        e.task.rates.push(library::CoordinateRate {
            coordinate: "ellipse.angle".into(),
            weight: -1.0,
            rate: 1.0,
            final_rate: 0.7,
        });
        assert_eq!(Success::Rate(0.5).judge(&e), (0.7, true));
        assert!(!Success::Rate(1.0).judge(&e).1);
        e.task.targets.push(library::TargetDistance {
            entry: "block.x".into(),
            target: 0.6,
            final_only: false,
            mean: 0.2,
            final_mean: 0.02,
            final_worst: 0.04,
            last: 0.01,
        });
        e.task.targets.push(library::TargetDistance {
            entry: "block.x velocity".into(),
            target: 0.0,
            final_only: true,
            mean: 0.2,
            final_mean: 0.2,
            final_worst: 0.9,
            last: 0.3,
        });
        // The velocity's distance is not a position target.
        assert_eq!(Success::Hold(0.05).judge(&e), (0.04, true));
        // After kicks, the distance at the end counts (the last kick's disturbance lies in the last
        // quarter).
        assert_eq!(Success::Hold(0.05).judge_kicked(&e), (0.01, true));
        assert!(!Success::Hold(0.005).judge_kicked(&e).1);
        assert!(!Success::Hold(0.03).judge(&e).1);
        // No position target at all: NaN, which fails.
        e.task.targets.clear();
        assert!(!Success::Hold(0.05).judge(&e).1);
    }
}
