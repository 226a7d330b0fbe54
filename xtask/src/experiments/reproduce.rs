//! `cargo xtask reproduce`: the paper's experiments end to end with default settings (sections V-B and
//! V-C): the optimiser on the finger, the library at sigma = 0.1 and 0.05, the global policy in closed loop
//! on the smoothed and the hard system at two time steps with and without kicks, and a summary of paper
//! against ours. Everything lands in one output folder.

use crate::experiments::recipe::{SECONDS, on_four_worlds, write_docs};
use anyhow::Context;
use ddp::{Ddp, DdpSettings};
use dynamics::{Complementarity, Scene, Simulator, StepSettings};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use library::{Evaluation, EvaluationSettings, Library, LibrarySettings};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;
use task::{ContactModel, SceneDynamics};

/// Options of `cargo xtask reproduce`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder.
    #[arg(long, default_value = "results")]
    out: PathBuf,
    /// Simulated seconds per closed-loop run.
    #[arg(long, default_value_t = SECONDS)]
    seconds: f64,
    /// The documentation folder whose results.md and figures/ a run with the default settings rewrites
    /// (its generated section and the figures).
    #[arg(long, default_value = "docs")]
    docs: PathBuf,
    /// Leave the documentation alone.
    #[arg(long)]
    no_docs: bool,
    /// Library seeds of the default recipe to run on the four worlds (1 to this; results under `seeds` in
    /// summary.json): 1 is the default library itself, each further seed builds one more (about half a
    /// minute each on two cores). `cargo xtask seeds` adds the paper's recipe and the ablations.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=64))]
    seeds: u64,
}

#[derive(Serialize)]
struct Optimised {
    sigma: f64,
    passes: usize,
    status: String,
    cost: f64,
    theta3_turned: f64,
    max_gain: f64,
    milliseconds: f64,
}

#[derive(Serialize)]
struct ClosedLoop {
    library: String,
    world: String,
    h: f64,
    kicks: bool,
    evaluation: Evaluation,
}

#[derive(Serialize)]
struct Annealed {
    sigma: f64,
    annealed_passes: usize,
    annealed_cost: f64,
    annealed_turned: f64,
    direct_passes: usize,
    direct_cost: f64,
    direct_turned: f64,
}

#[derive(Serialize)]
struct Kicked {
    kick_std: f64,
    world: String,
    evaluation: Evaluation,
}

#[derive(Serialize)]
struct Mismatched {
    change: String,
    world: String,
    evaluation: Evaluation,
}

#[derive(Serialize)]
struct Summary {
    optimised: Vec<Optimised>,
    annealing: Vec<Annealed>,
    larger_kicks: Vec<Kicked>,
    mismatched: Vec<Mismatched>,
    libraries: Vec<(String, f64, usize)>,
    closed_loop: Vec<ClosedLoop>,
    /// The default recipe over library seeds 1 to `--seeds` (seed 1: the default library of
    /// `closed_loop`), on the four worlds with and without kicks.
    seeds: Vec<crate::experiments::seeds::SeedRun>,
    /// Simulated seconds per closed-loop run.
    run_seconds: f64,
    seconds: f64,
}

fn optimise(sigma: f64) -> anyhow::Result<Optimised> {
    let (scene, task) = task::ProblemFile::builtin_task();
    let sim = Simulator::new(
        scene,
        StepSettings {
            model: Complementarity::Logistic { sigma },
            ..StepSettings::default()
        },
    )?;
    let t = Instant::now();
    let sol = Ddp::new(DdpSettings::default())?.solve(
        &SceneDynamics::new(sim),
        &task.cost,
        &task.x0,
        &vec![vec![0.0; 2]; task.horizon],
    )?;
    Ok(Optimised {
        sigma,
        passes: sol.iterations.len(),
        status: sol.status.to_string(),
        cost: sol.cost,
        theta3_turned: sol.states[75][2] - sol.states[0][2],
        max_gain: sol.gains.iter().flatten().fold(0.0, |m, k| m.max(k.abs())),
        milliseconds: t.elapsed().as_secs_f64() * 1e3,
    })
}

/// The growth rounds of the sigma = 0.05 comparison library: its policy stalls far more often than the
/// default's, so eight rounds grow it to some 2500 trajectories (two minutes on the 2-core VM, twice the
/// rest of `reproduce`); four rounds keep it near the default library's cost.
const COMPARISON_GROWTH: usize = 4;

/// The label of the library built at `sigma` (the sigma = 0.1 one is the default).
fn recipe_label(sigma: f64) -> String {
    if sigma == 0.1 {
        format!("sigma {sigma}, default recipe")
    } else {
        format!("sigma {sigma}, default recipe with {COMPARISON_GROWTH} growth rounds")
    }
}

fn build(sigma: f64, bars: &MultiProgress) -> anyhow::Result<(Library, f64)> {
    let base = LibrarySettings::default();
    // The comparison library's branches on two threads (the same library as on one): its build is the
    // longest job, and once the default library's thread is done it has both cores to itself.
    let (growth, chains) = if sigma == 0.1 {
        (base.growth, base.chains)
    } else {
        (COMPARISON_GROWTH, 2)
    };
    let settings = LibrarySettings {
        model: ContactModel::Logistic(sigma),
        growth,
        chains,
        ..base
    };
    let bar = bars.add(ProgressBar::new(settings.trajectories as u64));
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "library sigma = {sigma}: {{bar:40}} {{pos}}/{{len}} {{elapsed_precise}} (eta {{eta}})"
        ))
        .expect("a valid template"),
    );
    let t = Instant::now();
    let lib = Library::build(&task::ProblemFile::builtin(), None, &settings, |_, _| {
        bar.inc(1)
    })?;
    bar.finish_and_clear();
    Ok((lib, t.elapsed().as_secs_f64()))
}

/// The library's policy on the smoothed and the hard world of `scene` (h = 0.05, a velocity kick of
/// standard deviation `kick_std` every 10 s).
fn on_both_worlds(
    scene: &Scene,
    lib: &Library,
    policy: &library::Policy,
    args: &Args,
    kick_std: f64,
) -> anyhow::Result<Vec<(&'static str, Evaluation)>> {
    [
        ("logistic 0.1", ContactModel::Logistic(0.1)),
        ("hard", ContactModel::Hard),
    ]
    .into_iter()
    .map(|(world, model)| {
        let settings = EvaluationSettings {
            model,
            h: 0.05,
            seconds: args.seconds,
            kick_every: 10.0,
            kick_std,
            ..EvaluationSettings::default()
        };
        Ok((world, library::evaluate_in(scene, lib, policy, &settings)?))
    })
    .collect()
}

/// The flicking finger with one property changed (SCENE.md: friction 0.5, density 1, ellipse drag 0.7).
fn mismatched_scenes() -> Vec<(String, dynamics::SceneSpec)> {
    let base = task::ProblemFile::builtin().scene.spec().clone();
    let mut out = Vec::new();
    for friction in [0.1, 0.25, 1.0, 2.0] {
        let mut spec = base.clone();
        spec.contacts[0].friction = friction;
        out.push((format!("friction {friction} (0.5)"), spec));
    }
    for density in [0.25, 4.0] {
        let mut spec = base.clone();
        spec.bodies[2].density = density;
        out.push((format!("ellipse density {density} (1)"), spec));
    }
    for damping in [0.1, 2.8] {
        let mut spec = base.clone();
        spec.bodies[2].joint.damping = damping;
        out.push((format!("ellipse drag {damping} (0.7)"), spec));
    }
    out
}

/// Run `cargo xtask reproduce`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let start = Instant::now();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    // The sigma = 0.05 library (the longest build) is built and run on a thread of its own; this one
    // builds and runs the default library, then the optimiser and annealing experiments, so that each core
    // has one sequence of work.
    let bars = MultiProgress::new();
    std::thread::scope(|scope| {
        let bars = &bars;
        let comparison = scope.spawn(move || {
            let (lib, secs) = build(0.05, bars)?;
            evaluate_built(args, lib, secs)
        });
        let default = build(0.1, bars).and_then(|(lib, secs)| evaluate_built(args, lib, secs));
        let rest = experiments(bars);
        let comparison = comparison.join().expect("a library build does not panic");
        let (mut default, comparison) = (default?, comparison?);
        let mut seeds = std::mem::take(&mut default.seed_runs);
        seeds.extend(further_seeds(args, bars)?);
        finish(args, start, rest?, vec![default, comparison], seeds)
    })
}

/// The default recipe's libraries of seeds 2 to `--seeds`, each on the four worlds, on two threads.
fn further_seeds(
    args: &Args,
    bars: &MultiProgress,
) -> anyhow::Result<Vec<crate::experiments::seeds::SeedRun>> {
    let jobs: Vec<u64> = (2..=args.seeds).collect();
    if jobs.is_empty() {
        return Ok(Vec::new());
    }
    let bar = bars.add(ProgressBar::new(jobs.len() as u64));
    bar.set_style(
        ProgressStyle::with_template(
            "further library seeds: {bar:40} {pos}/{len} {elapsed_precise} (eta {eta})",
        )
        .expect("a valid template"),
    );
    let results = crate::on_two_threads(&jobs, |&seed| {
        let settings = LibrarySettings {
            seed,
            ..LibrarySettings::default()
        };
        let lib = Library::build(&task::ProblemFile::builtin(), None, &settings, |_, _| {})?;
        let runs = crate::experiments::seeds::runs_of(
            seed,
            crate::experiments::seeds::DEFAULT_RECIPE,
            &lib,
            args.seconds,
        );
        bar.inc(1);
        runs
    });
    bar.finish_and_clear();
    let mut runs = Vec::new();
    for r in results {
        runs.extend(r?);
    }
    Ok(runs)
}

/// One built library, saved, with its closed-loop runs (and for the default one the figures and the
/// runs beyond its training).
struct Evaluated {
    label: String,
    secs: f64,
    controllers: usize,
    larger_kicks: Vec<Kicked>,
    mismatched: Vec<Mismatched>,
    closed_loop: Vec<ClosedLoop>,
    /// For the default library, its closed-loop runs as those of the seed sweep's first seed.
    seed_runs: Vec<crate::experiments::seeds::SeedRun>,
}

fn evaluate_built(args: &Args, lib: Library, secs: f64) -> anyhow::Result<Evaluated> {
    let sigma = match lib.settings.model {
        ContactModel::Logistic(sigma) => sigma,
        other => anyhow::bail!("reproduce builds logistic libraries, not {other}"),
    };
    let mut larger_kicks = Vec::new();
    let mut mismatched = Vec::new();
    let mut closed_loop = Vec::new();
    // The sigma = 0.1 library is the default one (`cargo xtask train`), which `view` and `figures`
    // load.
    let file = if sigma == 0.1 {
        "finger.lib".to_string()
    } else {
        format!("finger_sigma{sigma}.lib")
    };
    lib.save(&args.out.join(file))?;
    if sigma == 0.1 {
        println!("drawing the figures ...");
        crate::experiments::figures::write_all(&lib, &args.out.join("figures"))?;
        // Kicks beyond the training's (variance 4, std 2): where does the policy break?
        let policy = lib.policy()?;
        for kick_std in [2.0, 8.0, 32.0, 128.0, 256.0] {
            for (world, evaluation) in on_both_worlds(lib.scene(), &lib, &policy, args, kick_std)? {
                larger_kicks.push(Kicked {
                    kick_std,
                    world: world.into(),
                    evaluation,
                });
            }
        }
        // Worlds the library never saw: other friction, a heavier or lighter ellipse, other drag.
        for (change, spec) in mismatched_scenes() {
            let scene = Scene::new(spec)?;
            for (world, evaluation) in on_both_worlds(&scene, &lib, &policy, args, 2.0)? {
                mismatched.push(Mismatched {
                    change: change.clone(),
                    world: world.into(),
                    evaluation,
                });
            }
        }
    }
    let mut seed_runs = Vec::new();
    for (world, h, kicks, evaluation) in on_four_worlds(&lib, args.seconds)? {
        if sigma == 0.1 {
            seed_runs.push(crate::experiments::seeds::SeedRun {
                seed: lib.settings.seed,
                recipe: crate::experiments::seeds::DEFAULT_RECIPE.into(),
                world: world.clone(),
                h,
                kicks,
                evaluation: evaluation.clone(),
            });
        }
        closed_loop.push(ClosedLoop {
            library: recipe_label(sigma),
            world,
            h,
            kicks,
            evaluation,
        });
    }
    Ok(Evaluated {
        label: recipe_label(sigma),
        secs,
        controllers: lib.entries.len(),
        larger_kicks,
        mismatched,
        closed_loop,
        seed_runs,
    })
}

/// The optimiser from rest and the annealing table.
fn experiments(bars: &MultiProgress) -> anyhow::Result<(Vec<Optimised>, Vec<Annealed>)> {
    let _ = bars.println("optimising the finger from rest (full DDP, N = 75) ...");
    let optimised = vec![optimise(0.1)?, optimise(0.05)?];
    let _ = bars.println("annealing sigma from 0.3 to 0.001 ...");
    let schedule = [
        0.3, 0.2, 0.1, 0.05, 0.03, 0.02, 0.01, 0.005, 0.003, 0.002, 0.001,
    ];
    let (scene, task) = task::ProblemFile::builtin_task();
    let warm = task::anneal(&scene, &task, &schedule, 300)?;
    let mut annealing = Vec::new();
    for w in &warm {
        let direct = &task::anneal(&scene, &task, &[w.sigma], 300)?[0];
        annealing.push(Annealed {
            sigma: w.sigma,
            annealed_passes: w.passes,
            annealed_cost: w.cost,
            annealed_turned: w.turned,
            direct_passes: direct.passes,
            direct_cost: direct.cost,
            direct_turned: direct.turned,
        });
    }
    Ok((optimised, annealing))
}

/// The libraries' closed-loop runs, the figures, and the summary.
fn finish(
    args: &Args,
    start: Instant,
    (optimised, annealing): (Vec<Optimised>, Vec<Annealed>),
    evaluated: Vec<Evaluated>,
    seeds: Vec<crate::experiments::seeds::SeedRun>,
) -> anyhow::Result<()> {
    let mut larger_kicks = Vec::new();
    let mut mismatched = Vec::new();
    let mut libraries = Vec::new();
    let mut closed_loop = Vec::new();
    for e in evaluated {
        libraries.push((e.label, e.secs, e.controllers));
        larger_kicks.extend(e.larger_kicks);
        mismatched.extend(e.mismatched);
        closed_loop.extend(e.closed_loop);
    }
    let seconds = start.elapsed().as_secs_f64();
    let summary = Summary {
        optimised,
        annealing,
        larger_kicks,
        mismatched,
        libraries,
        closed_loop,
        seeds,
        run_seconds: args.seconds,
        seconds,
    };
    let text = report(&summary, true);
    println!("{text}");
    crate::write_file(args.out.join("summary.md"), &text)?;
    crate::write_file(
        args.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    println!(
        "wrote {}/summary.md, summary.json, figures/ and the libraries in {seconds:.1} s",
        args.out.display()
    );
    if args.no_docs {
        return Ok(());
    }
    if args.seconds != SECONDS || args.seeds != 1 {
        println!(
            "{}/results.md left alone: it documents the default run ({SECONDS} s per closed loop, one library seed)",
            args.docs.display()
        );
        return Ok(());
    }
    let figures: Vec<PathBuf> = FIGURES
        .iter()
        .map(|n| args.out.join("figures").join(format!("{n}.png")))
        .collect();
    // Only inside a checkout of this repository: run elsewhere (or with another --docs that is not a
    // documentation folder) the results above are all it writes.
    if !args.docs.join("results.md").is_file() {
        println!(
            "no {}/results.md here (not run from the repository's root): wrote the results only",
            args.docs.display()
        );
        return Ok(());
    }
    // The documentation carries the numbers without the timings, which vary from run to run and machine
    // to machine (they are in summary.md): a rerun on the same code leaves it unchanged.
    write_docs(
        &args.docs,
        "reproduce",
        "cargo xtask reproduce",
        &report(&summary, false),
        &figures,
    )?;
    println!(
        "rewrote the generated section of {}/results.md and the figures in {}/figures",
        args.docs.display(),
        args.docs.display()
    );
    Ok(())
}

/// The figures `reproduce` draws (and copies into the documentation).
const FIGURES: [&str; 4] = [
    "fig2_contact_surface",
    "fig3_library_states",
    "fig4_limit_cycle",
    "fig5_frames",
];

/// The summary as markdown; `timed`: with the run's time, each solve's and each library's (summary.md),
/// else without them (docs/results.md, so that a rerun of the same code rewrites the same text).
fn report(s: &Summary, timed: bool) -> String {
    let mut t = String::new();
    if timed {
        let _ = writeln!(
            t,
            "# Reproduction summary (`cargo xtask reproduce`, {:.0} s)\n",
            s.seconds
        );
    } else {
        let _ = writeln!(
            t,
            "# Reproduction summary (`cargo xtask reproduce`)\n\nTimings vary with the machine and are left out here: `results/summary.md` has them for each run, and docs/benchmarks.md measures them.\n"
        );
    }
    let _ = writeln!(
        t,
        "## Trajectory optimisation from rest (paper V-B: ~60 passes of ~5 s each)\n\n| sigma | passes | status | cost | theta3 turned | max abs K |{}\n|---:|---:|---|---:|---:|---:|{}",
        if timed { " time (ms) |" } else { "" },
        if timed { "---:|" } else { "" }
    );
    for o in &s.optimised {
        let _ = write!(
            t,
            "| {} | {} | {} | {:.4} | {:.3} | {:.1e} |",
            o.sigma, o.passes, o.status, o.cost, o.theta3_turned, o.max_gain
        );
        if timed {
            let _ = write!(t, " {:.0} |", o.milliseconds);
        }
        let _ = writeln!(t);
    }
    let _ = writeln!(
        t,
        "\n## Noise annealing (paper section VI's proposal; the paper could not go below sigma = 0.05)\n\nEach sigma solved warm-started from the previous one's controls, against a solve from zero controls at that sigma.\n\n| sigma | annealed: passes | cost | theta3 turned | direct: passes | cost | theta3 turned |\n|---:|---:|---:|---:|---:|---:|---:|"
    );
    for a in &s.annealing {
        let _ = writeln!(
            t,
            "| {} | {} | {:.3} | {:.3} | {} | {:.3} | {:.3} |",
            a.sigma,
            a.annealed_passes,
            a.annealed_cost,
            a.annealed_turned,
            a.direct_passes,
            a.direct_cost,
            a.direct_turned
        );
    }
    let _ = writeln!(
        t,
        "\n## Kicks beyond training (library sigma = 0.1, 4 per trajectory, h = 0.05, a kick every 10 s; training used std 2)\n\n| kick std | world | spin (rad/s) | kicks recovered | quarter turn resumed | mean time to it (s) |\n|---:|---|---:|---:|---:|---:|"
    );
    for k in &s.larger_kicks {
        let _ = writeln!(
            t,
            "| {} | {} | {:.3} | {}/{} | {}/{} | {} |",
            k.kick_std,
            k.world,
            k.evaluation.spin_rate,
            k.evaluation.recovered,
            k.evaluation.kicks,
            k.evaluation.resumed,
            k.evaluation.kicks,
            k.evaluation
                .resume_time
                .map_or("-".into(), |t| format!("{t:.1}"))
        );
    }
    let _ = writeln!(
        t,
        "\n## Worlds the library never saw (library sigma = 0.1, 4 per trajectory, h = 0.05, kicks of std 2 every 10 s; nominal value in brackets)\n\n| change | world | spin (rad/s) | kicks recovered | quarter turn resumed | in contact |\n|---|---|---:|---:|---:|---:|"
    );
    for m in &s.mismatched {
        let e = &m.evaluation;
        let _ = writeln!(
            t,
            "| {} | {} | {:.3} | {}/{} | {}/{} | {:.0}% |",
            m.change,
            m.world,
            e.spin_rate,
            e.recovered,
            e.kicks,
            e.resumed,
            e.kicks,
            100.0 * e.contact_fraction
        );
    }
    let _ = writeln!(
        t,
        "\n## Libraries (paper: 400 controllers, receding horizon with ~8 passes per shift)\n\n| library |{} controllers |\n|---|{}---:|",
        if timed {
            " build (s, wall time, built side by side on two cores) |"
        } else {
            ""
        },
        if timed { "---:|" } else { "" }
    );
    for (name, secs, n) in &s.libraries {
        let build = if timed {
            format!(" {secs:.1} |")
        } else {
            String::new()
        };
        let _ = writeln!(t, "| {name} |{build} {n} |");
    }
    let _ = writeln!(
        t,
        "\n## The global policy in closed loop ({:.0} s per run; kicks: normal velocity kicks of std 2 every 10 s)\n\nPaper's claims: the controller spins the ellipse on the smoothed and on the hard system, survives the kicks, works at another time step, and sigma = 0.05 is less robust.\n\n| library | world | h | kicks | spin (rad/s) | last quarter (rad/s) | contacts/s | in contact | kicks recovered | quarter turn resumed (mean time) |\n|---|---|---:|---|---:|---:|---:|---:|---:|---:|",
        s.run_seconds
    );
    for c in &s.closed_loop {
        let e = &c.evaluation;
        let _ = writeln!(
            t,
            "| {} | {} | {} | {} | {:.3} | {:.3} | {:.2} | {:.0}% | {} | {} |",
            c.library,
            c.world,
            c.h,
            if c.kicks { "yes" } else { "no" },
            e.spin_rate,
            e.final_spin_rate,
            e.contacts_per_second,
            100.0 * e.contact_fraction,
            if c.kicks {
                format!("{}/{}", e.recovered, e.kicks)
            } else {
                "-".into()
            },
            if c.kicks {
                format!(
                    "{}/{} ({})",
                    e.resumed,
                    e.kicks,
                    crate::tools::evaluate::seconds(e.resume_time)
                )
            } else {
                "-".into()
            }
        );
    }
    let last = s.seeds.iter().map(|r| r.seed).max().unwrap_or(1);
    let _ = writeln!(
        t,
        "\n## Over library seeds (`seeds` in summary.json)\n\nThe default recipe with library seeds 1-{last} (`cargo xtask reproduce --seeds N` for more; each further seed builds one more library). `cargo xtask seeds` runs seeds 1-8 against the paper's recipe and three ablations (its section below).\n"
    );
    crate::experiments::seeds::seed_rows(
        &mut t,
        &s.seeds,
        &[crate::experiments::seeds::DEFAULT_RECIPE],
    );
    let _ = writeln!(
        t,
        "\n## Figures (the default library at sigma = 0.1, seed 1)\n\n![Fig. 2: the contact surface](figures/fig2_contact_surface.png)\n\n![Fig. 3: the library's states](figures/fig3_library_states.png)\n\n![Fig. 4: the limit cycle in configuration space](figures/fig4_limit_cycle.png)\n\n![Fig. 5: one cycle in frames](figures/fig5_frames.png)"
    );
    t
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_documented_results_were_computed_with_the_current_settings() {
        let text =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/results.md"))
                .expect("docs/results.md");
        for section in ["reproduce", "seeds", "diagnose"] {
            let begin = format!("<!-- BEGIN {section} (generated by `cargo xtask {section}`) -->");
            let at = text
                .find(&begin)
                .unwrap_or_else(|| panic!("docs/results.md has no section {section}"));
            let end = text[at..]
                .find(&format!("<!-- END {section} -->"))
                .unwrap_or_else(|| panic!("docs/results.md's section {section} has no end"));
            assert!(
                text[at..at + end].contains(&crate::experiments::recipe::stamp_line()),
                "docs/results.md's {section} section is stale (its recipe stamp is not {}): run `cargo xtask {section}`",
                crate::experiments::recipe::stamp()
            );
        }
    }
}
