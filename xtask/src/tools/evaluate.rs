//! `cargo xtask evaluate`: the library's global policy in closed loop (paper section V-C) on the smoothed
//! and on the hard system, at the library's time step and at another, with random velocity kicks.

use anyhow::Context;
use library::{Evaluation, EvaluationSettings, Library, evaluate};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;
use task::ContactModel;

/// Options of `cargo xtask evaluate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The library to run.
    #[arg(long, default_value = "results/finger.lib")]
    library: PathBuf,
    /// Simulated seconds per run.
    #[arg(long, default_value_t = 200.0)]
    seconds: f64,
    /// Seconds between velocity kicks (0: none).
    #[arg(long, default_value_t = 10.0)]
    kick_every: f64,
    /// Standard deviation of each velocity's kick.
    #[arg(long, default_value_t = 2.0)]
    kick_std: f64,
    /// Seed of the kicks.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Write the table as JSON here.
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Serialize)]
struct Row {
    world: String,
    h: f64,
    evaluation: Evaluation,
}

/// The worlds of the paper's experiment: the library's own smoothed model and the hard one, at the
/// library's time step and at 0.03.
pub fn worlds(library: &Library) -> Vec<(String, ContactModel, f64)> {
    let own = library.settings.model;
    let h = library.settings.h;
    let name = |m: ContactModel| match m {
        ContactModel::Hard => "hard".to_string(),
        ContactModel::Logistic(s) => format!("logistic {}", dynamics::Scale(s)),
        ContactModel::Normal(s) => format!("normal {}", dynamics::Scale(s)),
    };
    let mut out = Vec::new();
    for step in [h, library::WORLD_TIME_STEP] {
        for m in [own, ContactModel::Hard] {
            if !out.iter().any(|(_, mm, hh)| *mm == m && *hh == step) {
                out.push((name(m), m, step));
            }
        }
    }
    out
}

/// `library`'s policy in closed loop from its task's start in the world `(model, h)` for `seconds`, with
/// velocity kicks `(every, std, seed)` (every 0: none): its evaluation.
pub fn in_world(
    library: &Library,
    policy: &library::Policy,
    (model, h): (ContactModel, f64),
    seconds: f64,
    (kick_every, kick_std, seed): (f64, f64, u64),
) -> anyhow::Result<Evaluation> {
    let settings = EvaluationSettings {
        model,
        h,
        seconds,
        kick_every,
        kick_std,
        seed,
        x0: library.x0().to_vec(),
    };
    Ok(evaluate(library, policy, &settings)?)
}

/// A mean time in seconds, or "-" when there was nothing to average.
pub fn seconds(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.1} s"))
}

/// Write `text` to stdout and clear it; false when the reader has gone away (a closed pipe), which
/// ends the command quietly rather than in a panic.
fn emit(text: &mut String) -> bool {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    let ok = stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
        .is_ok();
    text.clear();
    ok
}

/// Run `cargo xtask evaluate`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let library = Library::load(&args.library)
        .with_context(|| format!("loading {}", args.library.display()))?;
    let policy = library.policy()?;
    let progress = library.progress()?;
    let watched = &library.scene().coordinate_names()[progress.coordinate];
    // The spin measures (rate, contacts per half-turn, kicks recovered as forward spin) mean something
    // for a task that rewards progress along its periodic coordinate (the finger's); a task that holds a
    // target gets the task's own measures alone.
    let spin = progress.forward.is_some();
    let mut out = String::new();
    let _ = writeln!(
        out,
        "library {}: {} controllers for task {}, built on {} at h = {}; {}, from the library's initial state",
        args.library.display(),
        library.entries.len(),
        library.task().name,
        library.settings.model,
        library.settings.h,
        if spin {
            format!("rates are of {watched}")
        } else {
            "the task holds targets: its own measures alone".into()
        }
    );
    if spin {
        let _ = writeln!(
            out,
            "| world | h | rate (rad/s) | last quarter | after kicks | contacts per half-turn | contacts/s | in contact | kicks recovered | quarter turn resumed (mean time) |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        );
    }
    if !emit(&mut out) {
        return Ok(());
    }
    let mut rows = Vec::new();
    for (world, model, h) in worlds(&library) {
        let kicks = (args.kick_every, args.kick_std, args.seed);
        let e = in_world(&library, &policy, (model, h), args.seconds, kicks)?;
        let kicked = e.kicks > 0;
        if spin {
            let _ = writeln!(
                out,
                "| {world} | {h} | {:.3} | {:.3} | {} | {} | {:.2} | {:.0}% | {} | {} |",
                e.spin_rate,
                e.final_spin_rate,
                e.spin_after_kicks.map_or("-".into(), |v| format!("{v:.3}")),
                e.contacts_per_half_turn
                    .map_or("- (under half a turn)".into(), |v| format!("{v:.2}")),
                e.contacts_per_second,
                100.0 * e.contact_fraction,
                if kicked {
                    format!("{}/{}", e.recovered, e.kicks)
                } else {
                    "- (no kicks)".into()
                },
                if kicked {
                    format!("{}/{} ({})", e.resumed, e.kicks, seconds(e.resume_time))
                } else {
                    "-".into()
                },
            );
        }
        if !emit(&mut out) {
            return Ok(());
        }
        rows.push(Row {
            world,
            h,
            evaluation: e,
        });
    }
    // What the task's own cost says (any task; for the finger's, the rate repeats the spin above).
    let _ = writeln!(
        out,
        "{}by the task's cost: running cost per second (whole run / last quarter); each linearly weighted coordinate's rate (whole run / last quarter, weight); each quadratic target's distance (mean / last-quarter mean / last-quarter worst / at the end)\n| world | h | running cost per second | rates | distance to targets |\n|---|---:|---:|---|---|",
        if spin { "\n" } else { "" }
    );
    for row in &rows {
        let t = &row.evaluation.task;
        let rates: Vec<String> = t
            .rates
            .iter()
            .map(|r| {
                format!(
                    "{}: {:.3} / {:.3} (weight {})",
                    r.coordinate, r.rate, r.final_rate, r.weight
                )
            })
            .collect();
        let targets: Vec<String> = t
            .targets
            .iter()
            .map(|d| {
                format!(
                    "{}{} -> {}: {:.3} / {:.3} / {:.3} / {:.3}",
                    if d.final_only { "final " } else { "" },
                    d.entry,
                    d.target,
                    d.mean,
                    d.final_mean,
                    d.final_worst,
                    d.last
                )
            })
            .collect();
        let or_none = |v: Vec<String>| {
            if v.is_empty() {
                "-".to_string()
            } else {
                v.join("; ")
            }
        };
        let _ = writeln!(
            out,
            "| {} | {} | {:.3} / {:.3} | {} | {} |",
            row.world,
            row.h,
            t.running_cost_per_second,
            t.final_running_cost_per_second,
            or_none(rates),
            or_none(targets)
        );
    }
    // The task's own success criterion, per world and in sum.
    let criterion = rows
        .first()
        .map_or(String::new(), |r| r.evaluation.success.criterion.clone());
    let _ = writeln!(
        out,
        "\nsuccess: {criterion}{}\n| world | h | succeeded | last-quarter rate | distance to targets |\n|---|---:|---|---:|---:|",
        if args.kick_every > 0.0 {
            " (with kicks: the targets' distance at the end)"
        } else {
            ""
        }
    );
    for row in &rows {
        let v = &row.evaluation.success;
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {} |",
            row.world,
            row.h,
            if v.passed { "yes" } else { "no" },
            v.rate.map_or("-".into(), |r| format!("{r:.3}")),
            v.distance.map_or("-".into(), |d| format!("{d:.3}")),
        );
    }
    let passed = rows.iter().filter(|r| r.evaluation.success.passed).count();
    let _ = writeln!(
        out,
        "{passed} of {} worlds succeed by the task's criterion",
        rows.len()
    );
    if !emit(&mut out) {
        return Ok(());
    }
    if let Some(path) = &args.out {
        crate::write_file(path, serde_json::to_string_pretty(&rows)?)
            .with_context(|| format!("writing {}", path.display()))?;
        let _ = writeln!(out, "wrote {}", path.display());
        emit(&mut out);
    }
    Ok(())
}
