//! What the finger's documented results share (`reproduce`, `seeds`, `diagnose`): the run length, the
//! four worlds a library's policy runs on, and the stamp of the settings the numbers were computed with.

use library::{Evaluation, EvaluationSettings, Library, LibrarySettings, evaluate};
use std::path::PathBuf;

/// Simulated seconds per closed-loop run of the documented results.
pub(crate) const SECONDS: f64 = 200.0;

/// Library seeds of the documented sweep (`cargo xtask seeds`).
pub(crate) const SEEDS: u64 = 8;

/// A short fingerprint of everything the documented results depend on that a code change can alter
/// without anyone rerunning `reproduce`: the default and the paper's library settings, the evaluation's
/// defaults, the step. docs/results.md carries the stamp of the run that wrote it, and a test
/// fails when it no longer matches.
pub(crate) fn stamp() -> String {
    // The settings as the finger's results use them: on the built-in file's spin task. A setting only a
    // target task reads (the growth's sharpening) leaves the finger's numbers as they are.
    let task = task::ProblemFile::builtin_task().1;
    let finger = |s: LibrarySettings| {
        let mut v = serde_json::to_value(s.for_task(&task)).expect("settings serialise");
        if let Some(o) = v.as_object_mut() {
            o.remove("growth_sharpening");
        }
        v
    };
    let inputs = serde_json::json!({
        "default": finger(LibrarySettings::default()),
        "paper": finger(LibrarySettings::paper()),
        "evaluation": EvaluationSettings {
            x0: task.x0.clone(),
            ..EvaluationSettings::default()
        },
        // Not the library file's format version: it changes how a library is written, not what it
        // holds or how its policy runs.
        "growth": growth_stamp(),
        "policy": POLICY_STAMP,
        "seeds": SEEDS,
        "seconds": SECONDS,
        // The step itself (how penetration is recovered, issue 27): new physics, new numbers.
        "step": dynamics::StepSettings::default(),
    });
    format!("{:08x}", crc32fast::hash(inputs.to_string().as_bytes()))
}

/// Growth's closed loops as the stamps see them (issue 28: a first kick at 40 s, a final check of every
/// world, reach shrunk where a controller outbid a branch).
pub(crate) fn growth_stamp() -> serde_json::Value {
    serde_json::json!([
        library::GROWTH_SECONDS,
        library::GROWTH_FIRST_KICK,
        library::REACH_SHRINK,
        library::VERIFY_PASSES as f64,
        library::VERIFY_PASSES_MOST as f64,
        library::VERIFY_BRANCHES as f64,
        library::STALL_WINDOW,
        library::DWELL_MARGIN,
        "branches span the failure's window; settled ones kept, empty ones dropped; the best-checked library kept",
    ])
}

/// How the policy chooses, as the stamps see it (laws charged beyond the stored controls, issue 28).
pub(crate) const POLICY_STAMP: &str = "value, reach, extrapolation charge";

/// The line a generated section of docs/results.md starts with.
pub(crate) fn stamp_line() -> String {
    format!(
        "(recipe stamp {}: the settings these numbers were computed with; a test checks it against the code)",
        stamp()
    )
}

/// Rewrite docs/results.md's section `name` with `body` (headings demoted below the page's) and copy the
/// PNGs of `figures` into docs/figures.
pub(crate) fn write_docs(
    docs: &std::path::Path,
    name: &str,
    command: &str,
    body: &str,
    figures: &[PathBuf],
) -> anyhow::Result<()> {
    crate::docs::write_section(docs, name, command, &stamp_line(), "##", body, figures)
}

/// The library's policy on the worlds of `cargo xtask evaluate` (its own model and the hard one, at its
/// time step and at 0.03), without and with kicks: `(world, h, kicks, evaluation)`.
pub(crate) fn on_four_worlds(
    lib: &Library,
    seconds: f64,
) -> anyhow::Result<Vec<(String, f64, bool, Evaluation)>> {
    let policy = lib.policy()?;
    let mut runs = Vec::new();
    for (world, model, h) in crate::tools::evaluate::worlds(lib) {
        for kicks in [false, true] {
            let settings = EvaluationSettings {
                model,
                h,
                seconds,
                kick_every: if kicks { 10.0 } else { 0.0 },
                ..EvaluationSettings::default()
            };
            runs.push((world.clone(), h, kicks, evaluate(lib, &policy, &settings)?));
        }
    }
    Ok(runs)
}
