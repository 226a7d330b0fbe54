//! `cargo xtask examples`: other scenes and tasks through the whole pipeline (issue 15): for each, the
//! task solved from rest by full second-order DDP, libraries over several seeds, their policies in closed
//! loop on the smoothed and the hard world, a success measure per run, a table and two pictures, and
//! the generated section of docs/results.md. By default the three example scenes under scenes/; with
//! `--scene FILE --task NAME`, any scene file's task.

use crate::experiments::draw::register_font;
use crate::experiments::task_pictures::task_pictures;
use crate::tools::evaluate::in_world;
use anyhow::Context;
use ddp::{Ddp, DdpSettings};
use library::{Evaluation, Library, LibrarySettings};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use task::{ProblemFile, SceneDynamics, Task};

/// Options of `cargo xtask examples`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A scene file to run instead of the zoo (with --task when it has several tasks). The documentation
    /// is then left alone.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// The task of --scene.
    #[arg(long, requires = "scene")]
    task: Option<String>,
    /// Run only the zoo's examples whose name contains this.
    #[arg(long, conflicts_with = "scene")]
    only: Option<String>,
    /// Library seeds per example (1 to this).
    #[arg(long, default_value_t = SEEDS, value_parser = clap::value_parser!(u64).range(1..=32))]
    seeds: u64,
    /// Simulated seconds per closed-loop run.
    #[arg(long, default_value_t = SECONDS)]
    seconds: f64,
    /// Output folder (tables as JSON, pictures, libraries).
    #[arg(long, default_value = "results/examples")]
    out: PathBuf,
    /// The documentation folder whose results.md section "examples" and figures a run of the whole zoo
    /// with the default seeds and seconds rewrites.
    #[arg(long, default_value = "docs")]
    docs: PathBuf,
    /// Leave the documentation alone.
    #[arg(long)]
    no_docs: bool,
}

/// Library seeds per example of the documented results.
const SEEDS: u64 = 4;
/// Simulated seconds per closed-loop run of the documented results.
const SECONDS: f64 = 40.0;
/// Standard deviation of each velocity's kick in the kicked runs.
const KICK_STD: f64 = 1.0;
/// Seconds between kicks in the kicked runs.
const KICK_EVERY: f64 = 10.0;
/// The kicked runs of library seed S draw their kicks from seed `KICK_SEED_BASE + S`: one kick sequence
/// per library seed and world rather than one for all, none of them a sequence the library grew on.
const KICK_SEED_BASE: u64 = 100;

/// One example: a scene file of this repository and its task. Its library is `train`'s defaults for the
/// task, and its success the task's own criterion ([`task::Success`]).
#[derive(Debug, Clone, Serialize)]
struct Example {
    name: String,
    file: String,
    #[serde(skip)]
    text: String,
    task: String,
    what: String,
}

/// The zoo: every scene file's task under scenes/.
fn examples() -> Vec<Example> {
    let ex = |name: &str, file: &str, text: &str, task: &str, what: &str| Example {
        name: name.into(),
        file: file.into(),
        text: text.into(),
        task: task.into(),
        what: what.into(),
    };
    vec![
        ex(
            "finger",
            "scenes/finger.toml",
            include_str!("../../../scenes/finger.toml"),
            "spin",
            "the paper's task: a two-link finger spins an anchored ellipse by flicking it",
        ),
        ex(
            "mirrored_finger",
            "scenes/mirrored_finger.toml",
            include_str!("../../../scenes/mirrored_finger.toml"),
            "spin_back",
            "a task with a negative direction: the finger mirrored left to right spins the ellipse clockwise (its cost +theta3)",
        ),
        ex(
            "mirrored_turn",
            "scenes/mirrored_finger.toml",
            include_str!("../../../scenes/mirrored_finger.toml"),
            "turn",
            "a target task for one finger, which can only push: the mirrored finger turns the ellipse to -1.0 rad and holds it there",
        ),
        ex(
            "three_link",
            "scenes/three_link_finger.toml",
            include_str!("../../../scenes/three_link_finger.toml"),
            "spin",
            "a three-link finger spins the ellipse (the paper's task; 4 joints, 3 controls, 2 contact pairs)",
        ),
        ex(
            "two_fingers",
            "scenes/two_fingers.toml",
            include_str!("../../../scenes/two_fingers.toml"),
            "turn",
            "two two-link fingers mounted either side of the ellipse turn it to 0.5 rad and hold it there (the Control Suite's finger-turn task with two fingers; 5 joints, 4 controls, 2 contact pairs)",
        ),
        ex(
            "pushing",
            "scenes/pushing.toml",
            include_str!("../../../scenes/pushing.toml"),
            "push",
            "a two-link finger pushes a free block resting on the ground 0.6 to the right, in the vertical plane (free body, ground contact with friction)",
        ),
        ex(
            "slider_push",
            "scenes/slider_push.toml",
            include_str!("../../../scenes/slider_push.toml"),
            "push",
            "a contact out of reach: a fork on a slider, both prongs starting 0.45 from a block, pushes it 0.5 along the ground and can push it back (one actuator, no periodic coordinate)",
        ),
        ex(
            "roll_block",
            "scenes/roll_block.toml",
            include_str!("../../../scenes/roll_block.toml"),
            "roll",
            "a block reoriented on the ground: a two-link finger turns a block lying on the ground a half turn over",
        ),
    ]
}

/// A fingerprint of what the documented examples depend on: the zoo, its scene files, the library
/// defaults (`train`'s), the seeds, seconds and kicks, the step.
pub(crate) fn stamp() -> String {
    let inputs = serde_json::json!({
        "examples": examples(),
        "texts": examples().iter().map(|e| e.text.clone()).collect::<Vec<_>>(),
        "default": LibrarySettings::default(),
        // Not the library file's format version: it changes how a library is written, not its numbers.
        "growth": crate::experiments::recipe::growth_stamp(),
        "policy": crate::experiments::recipe::POLICY_STAMP,
        // Target tasks' contact searches skip a contact plainly too far (the finger's never search in
        // growth, so the finger's own stamps leave it out).
        "search": task::OUT_OF_REACH_SLACK,
        // A pull is a Gauss-Newton scaffold that stops when its passes stop paying.
        "pull": ["gauss-newton", task::REACH_PULL_PASSES, task::REACH_PULL_TOLERANCE],
        // A target task's final-check branches for a world of another time step are optimised at that
        // step, and the policy prefers the controllers of the step it runs at (the finger's growth,
        // a progress task's, has none: its stamps leave it out).
        "world_step": "final check at the world's step; policy prefers its step",
        "seeds": SEEDS,
        "seconds": SECONDS,
        "kicks": [KICK_STD, KICK_EVERY, KICK_SEED_BASE],
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
        &SceneDynamics::new(sim),
        &task.cost,
        &task.x0,
        &vec![vec![0.0; m]; task.horizon],
    )?;
    let probe = LibrarySettings::default()
        .for_task(task)
        .simulator(&problem.scene)?;
    let contact = task::ContactProblem {
        ddp: &ddp,
        scene: &problem.scene,
        settings: probe.settings(),
        cost: &task.cost,
        x0: &task.x0,
    };
    // A solve that feels no contact reaches for it, one that stalls is explored from random starts, one
    // that stopped without converging is continued under the other regularisation: as `optimize` and
    // `train` finish theirs.
    let sol = contact
        .finish(
            sol,
            &task::Progress::of_task(task)?,
            task::Stages::ALL,
            |_, _, _| {},
        )?
        .solution;
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
            format!("not converged: {}", sol.status)
        },
        cost: sol.cost,
        seconds,
        entries,
    })
}

/// One world's two closed loops from x0: without kicks and with them.
#[derive(Debug, Serialize)]
struct WorldRun {
    world: String,
    h: f64,
    calm: Evaluation,
    kicked: Evaluation,
}

/// One library's closed loops.
#[derive(Debug, Serialize)]
struct SeedRun {
    seed: u64,
    controllers: usize,
    trajectories: usize,
    build_seconds: f64,
    worlds: Vec<WorldRun>,
    /// The entries over time on the first two worlds (the task's time step; for the pictures), not in
    /// the JSON.
    #[serde(skip)]
    traces: Vec<Vec<Vec<f64>>>,
}

#[derive(Debug, Serialize)]
struct ExampleResult {
    example: Example,
    sizes: (usize, usize, usize, usize),
    criterion: String,
    from_rest: FromRest,
    seeds: Vec<SeedRun>,
}

impl ExampleResult {
    /// `(succeeded, runs)` without kicks and with them.
    fn tally(&self) -> ((usize, usize), (usize, usize)) {
        let runs = self.seeds.iter().flat_map(|s| &s.worlds);
        let count = |kicked: bool| {
            let all: Vec<bool> = runs
                .clone()
                .map(|w| {
                    if kicked {
                        w.kicked.success.passed
                    } else {
                        w.calm.success.passed
                    }
                })
                .collect();
            (all.iter().filter(|p| **p).count(), all.len())
        };
        (count(false), count(true))
    }
}

/// A run's measure in words: its rate, its distance, and whether it passed.
fn measure(e: &Evaluation) -> String {
    let mut parts = Vec::new();
    if let Some(r) = e.success.rate {
        parts.push(format!("rate {r:.3}"));
    }
    if let Some(d) = e.success.distance {
        parts.push(format!("off {d:.3}"));
    }
    format!(
        "{} {}",
        parts.join(", "),
        if e.success.passed { "yes" } else { "**no**" }
    )
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
    let seed_list: Vec<u64> = (1..=seeds).collect();
    let runs = crate::on_two_threads(&seed_list, |&seed| -> anyhow::Result<(SeedRun, Library)> {
        let settings = crate::tools::train::defaults_for(&task, seed);
        // The build runs on this thread alone (one chain, the knots on one thread): its CPU time is
        // the single-thread build time, whatever else the machine runs beside it.
        anyhow::ensure!(
            settings.chains == 1 && settings.knot_threads == 1,
            "the examples' builds are single-thread"
        );
        let start = cpu_time::ThreadTime::now();
        let lib = Library::build(&problem, Some(&e.task), &settings, |_, _| {})?;
        let build_seconds = start.elapsed().as_secs_f64();
        let mut run = SeedRun {
            seed,
            controllers: lib.entries.len(),
            trajectories: lib.entries.len() / settings.keep,
            build_seconds,
            worlds: Vec::new(),
            traces: Vec::new(),
        };
        let policy = lib.policy()?;
        for (w, (name, model, h)) in crate::tools::evaluate::worlds(&lib).into_iter().enumerate() {
            let world = (model, h);
            let calm = in_world(&lib, &policy, world, seconds, (0.0, KICK_STD, 0))?;
            let kicks = (KICK_EVERY, KICK_STD, KICK_SEED_BASE + seed);
            let kicked = in_world(&lib, &policy, world, seconds, kicks)?;
            if w < 2 {
                let steps = (seconds / h).round() as usize;
                let trace = crate::experiments::figures::closed_loop(
                    &lib,
                    &policy,
                    (model, h),
                    &task.x0,
                    steps,
                )?;
                run.traces.push(trace.states);
            }
            run.worlds.push(WorldRun {
                world: name,
                h,
                calm,
                kicked,
            });
        }
        println!(
            "  seed {seed}: {} controllers in {build_seconds:.1} s; {}",
            run.controllers,
            run.worlds
                .iter()
                .map(|w| format!(
                    "{} h {}: {} / kicked {}",
                    w.world,
                    w.h,
                    measure(&w.calm),
                    measure(&w.kicked)
                ))
                .collect::<Vec<_>>()
                .join("; ")
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
            criterion: task.success.describe(&scene.coordinate_names()),
            from_rest: rest,
            seeds: seed_runs,
        },
        figures,
    ))
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
        task.success.holds(),
        scene,
        task,
        &traces,
        out,
    )
}

fn report(results: &[ExampleResult], seconds: f64) -> String {
    let mut t = String::new();
    let seeds = results.first().map_or(0, |r| r.seeds.len());
    let _ = writeln!(
        t,
        "# Other scenes and tasks (`cargo xtask examples`)\n\nThe zoo: every task in scenes/, each solved by full second-order DDP from rest (zero controls, the task's x0 and horizon, 300 passes at most), then a library per seed with `train`'s defaults for the task (`cargo xtask train --scene FILE --task NAME --seed S`: the default recipe on the task's model, time step, horizon and start, growth on the policy's own failures), and its policy run in closed loop from x0 for {seconds} s on four worlds (the task's smoothed model and hard contact, at the task's time step and at 0.03 s), once without kicks and once with velocity kicks (normal, standard deviation {KICK_STD}, every {KICK_EVERY} s, none in the last {KICK_EVERY} s; library seed S's runs kicked by the draws of kick seed {KICK_SEED_BASE} + S, so that the kicked runs sample {seeds} kick sequences per world, none of them the library's own). A run succeeds by the task's own criterion (`[task.NAME.success]`, docs/tasks.md): a progress task's rewarded coordinate advancing at least its minimum rate over the last quarter; a target task's judged targets within tolerance throughout the last quarter (with kicks: at the end). Seeds are 1 to {seeds}; every seed run is reported. Build times are single-thread: the CPU time of the thread that builds the library alone (two libraries are built at a time, one per core of the 2-core machine).\n",
    );
    let _ = writeln!(
        t,
        "| task | controllers (mean) | build (mean, max) | succeed without kicks | with kicks |\n|---|---:|---:|---:|---:|"
    );
    let (mut all_ok, mut all_runs) = (0, 0);
    for r in results {
        let seeds = r.seeds.len().max(1) as f64;
        let controllers = r.seeds.iter().map(|s| s.controllers).sum::<usize>() as f64 / seeds;
        let build = r.seeds.iter().map(|s| s.build_seconds).sum::<f64>() / seeds;
        let worst = r.seeds.iter().map(|s| s.build_seconds).fold(0.0, f64::max);
        let ((calm, n), (kicked, k)) = r.tally();
        all_ok += calm + kicked;
        all_runs += n + k;
        let _ = writeln!(
            t,
            "| [{}](#{}) (`{}`, `{}`) | {controllers:.0} | {build:.1} s, {worst:.1} s | {calm}/{n} | {kicked}/{k} |",
            r.example.name,
            r.example.name.replace('_', "-"),
            r.example.file,
            r.example.task
        );
    }
    let _ = writeln!(
        t,
        "\nIn all, {all_ok} of {all_runs} runs succeed ({:.0}%).",
        100.0 * all_ok as f64 / all_runs.max(1) as f64
    );
    for r in results {
        let e = &r.example;
        let (n, m, pairs, rows) = r.sizes;
        let _ = writeln!(
            t,
            "\n## {}\n\n`{}`, task `{}`: {}: {n} coordinates, {m} controls, {pairs} contact pairs, {rows} complementarity rows.\n\nSuccess: {}.\n",
            e.name, e.file, e.task, e.what, r.criterion
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
            "| seed | controllers | build | world | h | without kicks | with kicks | kicks back |\n|---:|---:|---:|---|---:|---|---|---:|"
        );
        for s in &r.seeds {
            for w in &s.worlds {
                let _ = writeln!(
                    t,
                    "| {} | {} | {:.1} s | {} | {} | {} | {} | {}/{} |",
                    s.seed,
                    s.controllers,
                    s.build_seconds,
                    w.world,
                    w.h,
                    measure(&w.calm),
                    measure(&w.kicked),
                    w.kicked.recovered,
                    w.kicked.kicks
                );
            }
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
        anyhow::bail!(
            "--seconds {} must be between 1 and 10000",
            dynamics::Scale(args.seconds)
        );
    }
    let list = match &args.scene {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            let problem = ProblemFile::from_toml_str(&text)
                .with_context(|| format!("scene {}", path.display()))?;
            let task = problem.task(args.task.as_deref())?;
            let name = path
                .file_stem()
                .map_or("scene".into(), |s| s.to_string_lossy().to_string());
            vec![Example {
                name,
                file: path.display().to_string(),
                text,
                what: format!("task {}", task.name),
                task: task.name.clone(),
            }]
        }
        None => examples()
            .into_iter()
            .filter(|e| {
                args.only
                    .as_ref()
                    .is_none_or(|o| e.name.contains(o.as_str()))
            })
            .collect(),
    };
    if list.is_empty() {
        anyhow::bail!(
            "--only {} matches no example (they are {})",
            args.only.as_deref().unwrap_or(""),
            examples()
                .iter()
                .map(|e| e.name.clone())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
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
    let documented = args.scene.is_none()
        && args.only.is_none()
        && args.seeds == SEEDS
        && args.seconds == SECONDS;
    if documented && !args.no_docs {
        crate::docs::write_section(
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
    fn the_zoo_is_every_task_in_scenes() {
        // Every scene file's every task is in the zoo, and every example's file and task exist.
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes");
        let mut found = Vec::new();
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let file = ProblemFile::load(&path).unwrap();
                for task in file.tasks.keys() {
                    found.push(format!(
                        "scenes/{}:{task}",
                        path.file_name().unwrap().to_string_lossy()
                    ));
                }
            }
        }
        found.sort();
        let mut zoo: Vec<String> = examples()
            .iter()
            .map(|e| format!("{}:{}", e.file, e.task))
            .collect();
        zoo.sort();
        assert_eq!(zoo, found);
        assert!(zoo.len() >= 8);
    }
}
