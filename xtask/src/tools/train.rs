//! `cargo xtask train`: build a controller library (paper section IV-C), the flicking finger's or one
//! for a task of a scene file, behind a progress bar and save it.

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use library::{Library, LibrarySettings};
use std::path::PathBuf;
use std::time::Instant;

/// Options of `cargo xtask train`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Where to save the library.
    #[arg(long, default_value = "results/finger.lib")]
    out: PathBuf,
    /// Contact model of the optimiser's dynamics [default: the task's with --task, else logistic].
    #[arg(long, value_enum)]
    model: Option<crate::tools::step::ModelArg>,
    /// Noise scale of the smoothed models [default: the task's with --task when its model has one, else
    /// 0.1].
    #[arg(long)]
    sigma: Option<f64>,
    /// Time step [default: the task's with --task, else 0.05].
    #[arg(long)]
    h: Option<f64>,
    /// Number of trajectories (stored controllers).
    #[arg(long, default_value_t = 400)]
    trajectories: usize,
    /// Seed of the velocity kicks.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Independent receding-horizon chains, built in parallel (one thread each; chain c uses seed +
    /// c). The paper's library is one chain.
    #[arg(long, default_value_t = 1)]
    chains: usize,
    /// Threads each solve differentiates its knots on (1 to 256; the same library on any number). They
    /// multiply with --chains' threads: on two cores, use one or the other.
    #[arg(long, default_value_t = 1,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=256))]
    threads: usize,
    /// Optimiser passes at most per warm-started re-solve.
    #[arg(long, default_value_t = 100)]
    warm_passes: usize,
    /// The paper's recipe (horizon 75, one chain kicked every 15 steps, the first controller of each
    /// trajectory, the nearest controller's law) instead of the default (horizon 90, the cycle first and
    /// branches off it, four controllers per trajectory, the best of eight by value, twelve growth rounds).
    #[arg(long)]
    paper: bool,
    /// Optimisation horizon in steps, 1 to 1000 (default: the task's with --task, else 90, the paper's
    /// recipe 75); one shorter than the recipe's shift of 4 steps shifts by the whole horizon.
    #[arg(long)]
    horizon: Option<usize>,
    /// Nearest controllers the policy ranks by their value models (1: the nearest alone, eq. 20).
    #[arg(long)]
    neighbours: Option<usize>,
    /// Rounds of growth on the policy's own failures (a stall for a task that rewards progress; not back
    /// at its targets in time after a kick for a target task) [default: 12, one per 32 trajectories below
    /// 384].
    #[arg(long)]
    growth: Option<usize>,
    /// The optimiser's stopping tolerance on the relative cost change.
    #[arg(long, default_value_t = LibrarySettings::default().tolerance)]
    tolerance: f64,
    /// Local controllers kept per trajectory (1: the paper's first controller; up to the shift of 4;
    /// default 4, the paper's recipe 1).
    #[arg(long)]
    keep: Option<usize>,
    /// With the default recipe: trajectories of the unperturbed receding-horizon chain from x0 (the
    /// trunk) [default: 100].
    #[arg(long)]
    trunk: Option<usize>,
    /// With the default recipe: trunk trajectories branches do not start from [default: 25].
    #[arg(long)]
    settle: Option<usize>,
    /// With the default recipe: trajectories per branch [default: 20].
    #[arg(long)]
    length: Option<usize>,
    /// Scene file (TOML); default: the built-in scenes/finger.toml (SCENE.md's flicking finger).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// A task of the scene file (`[task.NAME]`, docs/tasks.md): the library minimises its cost from its
    /// initial state under its control limits, with its contact model, time step and horizon unless
    /// given here, and its policy compares states modulo its one periodic coordinate. Without it, the
    /// file's only task (the built-in finger's: `spin`).
    #[arg(long)]
    task: Option<String>,
}

/// Run `cargo xtask train`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    // The destination first: a build of minutes must not end on a directory or an unwritable folder.
    if let Some(dir) = args.out.parent()
        && !dir.as_os_str().is_empty()
    {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    Library::check_destination(&args.out)
        .with_context(|| format!("--out {} cannot be written", args.out.display()))?;
    let (problem, source) = crate::tools::step::problem_file(args.scene.as_deref())?;
    let task = problem
        .task(args.task.as_deref())
        .with_context(|| format!("scene {source}"))?;
    let base = if args.paper {
        LibrarySettings::paper()
    } else {
        LibrarySettings::default()
    }
    .for_task(&task);
    let model = crate::tools::step::contact_model(args.model, args.sigma, Some(&task))?;
    // The default recipe's shape fitted to the budget; flags given override it.
    let fitted = base.clone().fitted(args.trajectories);
    let exploration = match fitted.exploration {
        library::Exploration::Branches {
            trunk,
            settle,
            length,
        } => library::Exploration::Branches {
            trunk: args.trunk.unwrap_or(trunk),
            settle: args.settle.unwrap_or(settle),
            length: args.length.unwrap_or(length),
        },
        kicks => {
            if args.trunk.is_some() || args.settle.is_some() || args.length.is_some() {
                anyhow::bail!(
                    "--trunk, --settle and --length shape the default recipe, not --paper's"
                );
            }
            kicks
        }
    };
    let mut settings = LibrarySettings {
        model,
        h: args.h.unwrap_or(base.h),
        trajectories: args.trajectories,
        seed: args.seed,
        chains: args.chains,
        knot_threads: args.threads,
        keep: args.keep.unwrap_or(base.keep),
        horizon: args.horizon.unwrap_or(base.horizon),
        neighbours: args.neighbours.unwrap_or(base.neighbours),
        growth: args.growth.unwrap_or(fitted.growth),
        warm_passes: args.warm_passes,
        tolerance: args.tolerance,
        exploration,
        ..base
    };
    // A horizon shorter than the recipe's shift (the steps between consecutive trajectories of a
    // chain) shifts by the whole horizon, keeping no more controllers than that per trajectory.
    if args.horizon.is_some() && settings.horizon < settings.shift {
        settings.shift = settings.horizon.max(1);
        if args.keep.is_none() {
            settings.keep = settings.keep.min(settings.shift);
        }
    }
    let progress = task::Progress::of_task(&task)?;
    let watched = problem.scene.coordinate_names()[progress.coordinate].clone();
    // One tick per optimised trajectory (each keeps `keep` controllers); growth adds trajectories beyond
    // the budget, and the bar grows with them.
    let bar = ProgressBar::new(settings.trajectories as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:40} {pos}/{len} trajectories  {elapsed_precise} (eta {eta})  {msg}",
        )
        .expect("a valid template"),
    );
    let start = Instant::now();
    let tick = |_, e: &library::Entry| {
        if bar.position() >= bar.length().unwrap_or(0) {
            bar.set_length(bar.position() + 1);
        }
        bar.inc(1);
        bar.set_message(format!(
            "{} passes, {watched} {:.2}",
            e.passes, e.x[progress.coordinate]
        ));
    };
    let library = Library::build(&problem, Some(&task.name), &settings, tick)?;
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    let firsts: Vec<_> = library.entries.iter().step_by(settings.keep).collect();
    let passes: u64 = firsts.iter().map(|e| e.passes as u64).sum();
    let converged = firsts.iter().filter(|e| e.converged).count();
    println!(
        "built {} controllers from {} trajectories ({} beyond the budget of {} grown on the policy's stalls) in {seconds:.1} s: {passes} optimiser passes ({} for the first solve, {:.1} per trajectory), {converged} converged",
        library.entries.len(),
        firsts.len(),
        firsts.len() - settings.trajectories,
        settings.trajectories,
        library.entries[0].passes,
        passes as f64 / firsts.len() as f64
    );
    if library.settings.horizon != settings.horizon {
        println!(
            "the receding horizon of {} steps let the task stall (the unperturbed chain from the start stopped advancing {watched}): every trajectory was solved over {} steps instead",
            settings.horizon, library.settings.horizon
        );
    }
    if let Some(line) = turns_line(&library) {
        println!("{line}");
    }
    library.save(&args.out)?;
    println!("wrote {}", args.out.display());
    println!("{}", unkicked_verdict(&library)?);
    Ok(())
}

/// The angles the library's policy compares modulo a turn, in a line, where there are any
/// ([`task::Task::turn_symmetries`]).
fn turns_line(library: &Library) -> Option<String> {
    let names = library.scene().coordinate_names();
    let turns: Vec<String> = library
        .turn_symmetries()
        .into_iter()
        .map(|(c, turn)| {
            let how = if turn > 0.0 {
                "modulo a half turn"
            } else {
                "not at all (a disc)"
            };
            format!("{} {how}", names[c])
        })
        .collect();
    (!turns.is_empty()).then(|| {
        format!(
            "its policy compares {}: the task does not see that angle and the body is the same so turned (docs/tasks.md, \"Half turns\")",
            turns.join(", ")
        )
    })
}

/// Simulated seconds of the check `train` reports: `evaluate`'s unkicked run of `examples` (and the
/// build's final check).
const CHECK_SECONDS: f64 = 40.0;

/// How the library's policy does from the task's start without kicks, on the worlds `evaluate` runs,
/// by the task's own success criterion: one line, with a hint where no world succeeds.
fn unkicked_verdict(library: &Library) -> anyhow::Result<String> {
    let policy = library.policy()?;
    let worlds = crate::tools::evaluate::worlds(library);
    let mut checked = Vec::new();
    for (world, model, h) in &worlds {
        let outcome = crate::tools::evaluate::in_world(
            library,
            &policy,
            (*model, *h),
            CHECK_SECONDS,
            (0.0, 0.0, 0),
        )
        .map(|e| e.success.passed)
        .map_err(|e| format!("{e:#}"));
        checked.push((world.to_string(), *h, outcome));
    }
    let criterion = library.success().describe(&library.scene().state_names());
    Ok(verdict_line(&checked, library.settings.h, &criterion))
}

/// [`unkicked_verdict`]'s line from each world's name, time step and outcome (whether it succeeded, or
/// why it could not run), for a library built at time step `own` with success `criterion`.
fn verdict_line(
    checked: &[(String, f64, Result<bool, String>)],
    own: f64,
    criterion: &str,
) -> String {
    let mut failed = Vec::new();
    // Whether a world failed at the library's own time step.
    let mut failed_at_own_step = false;
    // A world the closed loop cannot run (a time step too short for the check's seconds, a step that
    // fails) has no verdict: said with its reason, after the library is written, not as train's failure.
    let mut unrun = Vec::new();
    for (world, h, outcome) in checked {
        match outcome {
            Ok(true) => {}
            Ok(false) => {
                failed_at_own_step |= *h == own;
                failed.push(format!("{world} at h = {}", dynamics::Scale(*h)));
            }
            Err(e) => unrun.push(format!("{world} at h = {} ({e})", dynamics::Scale(*h))),
        }
    }
    let succeeding = checked.len() - failed.len() - unrun.len();
    let mut line = format!(
        "without kicks for {CHECK_SECONDS} s from the task's start, its policy succeeds on {succeeding} of {} worlds ({criterion})",
        checked.len()
    );
    if !failed.is_empty() {
        line.push_str(&format!("; not on {}", failed.join(", ")));
    }
    if !unrun.is_empty() {
        line.push_str(&format!("; no verdict on {}", unrun.join(", ")));
    }
    if succeeding > 0 && !failed.is_empty() && !failed_at_own_step {
        line.push_str(&format!(
            ". It fails only at another time step than its own (h = {}): at another step the same controls move the bodies differently through a contact (docs/tasks.md, \"The paddles fail at 0.03 s\"), and a task written at that step is built for it",
            dynamics::Scale(own)
        ));
    }
    if succeeding == 0 && !failed.is_empty() {
        line.push_str(
            ". On none: `cargo xtask optimize` on the task says whether a solve from its start feels the contact the task needs and whether that contact pays (docs/tasks.md), and `cargo xtask evaluate` gives the measures",
        );
    }
    line
}

/// `train`'s settings for `task` with no flag but `--seed`: the default recipe on the task's model, time
/// step, horizon and start, shaped for the default budget (what `cargo xtask examples` builds).
pub(crate) fn defaults_for(task: &task::Task, seed: u64) -> LibrarySettings {
    let base = LibrarySettings::default().for_task(task);
    let trajectories = base.trajectories;
    LibrarySettings {
        seed,
        ..base.fitted(trajectories)
    }
}

#[cfg(test)]
mod tests {
    use super::verdict_line;

    fn world(
        name: &str,
        h: f64,
        outcome: Result<bool, String>,
    ) -> (String, f64, Result<bool, String>) {
        (name.to_string(), h, outcome)
    }

    #[test]
    fn a_policy_failing_only_at_another_time_step_is_told_so() {
        let only_finer = [
            world("logistic 0.1", 0.05, Ok(true)),
            world("hard", 0.05, Ok(true)),
            world("logistic 0.1", 0.03, Ok(false)),
            world("hard", 0.03, Ok(false)),
        ];
        let line = verdict_line(&only_finer, 0.05, "c");
        assert!(line.contains("succeeds on 2 of 4 worlds (c)"), "{line}");
        assert!(
            line.contains("not on logistic 0.1 at h = 0.03, hard at h = 0.03"),
            "{line}"
        );
        assert!(
            line.contains("fails only at another time step than its own (h = 0.05)"),
            "{line}"
        );
        // A failure at its own step as well: no such hint.
        let own_too = [
            world("logistic 0.1", 0.05, Ok(false)),
            world("hard", 0.05, Ok(true)),
            world("logistic 0.1", 0.03, Ok(false)),
        ];
        let line = verdict_line(&own_too, 0.05, "c");
        assert!(!line.contains("another time step"), "{line}");
        // Every world fails: the contact hint instead.
        let none = [world("logistic 0.1", 0.03, Ok(false))];
        let line = verdict_line(&none, 0.05, "c");
        assert!(
            !line.contains("another time step") && line.contains("On none"),
            "{line}"
        );
        // A world that could not run is said with its reason and is no failure.
        let unrun = [
            world("logistic 0.1", 0.05, Ok(true)),
            world("hard", 0.03, Err("too short".into())),
        ];
        let line = verdict_line(&unrun, 0.05, "c");
        assert!(line.contains("succeeds on 1 of 2"), "{line}");
        assert!(
            line.contains("no verdict on hard at h = 0.03 (too short)"),
            "{line}"
        );
        assert!(!line.contains("another time step"), "{line}");
    }
}
