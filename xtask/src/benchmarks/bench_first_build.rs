//! The first build a newcomer waits for (issue 30): a fresh clone of the repository's committed state,
//! built cold with the README's two commands and its Python install, each timed on the wall clock.

use anyhow::Context;
use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

/// One step of the first build: what it runs, in the clone.
struct Stage {
    name: &'static str,
    program: &'static str,
    args: &'static [&'static str],
}

const STAGES: [Stage; 3] = [
    Stage {
        name: "`cargo xtask reproduce`'s build (`cargo build --release -p xtask`)",
        program: "cargo",
        args: &["build", "--release", "-p", "xtask"],
    },
    Stage {
        name: "`cargo test --workspace`'s build (`--no-run`)",
        program: "cargo",
        args: &["test", "--workspace", "--no-run"],
    },
    Stage {
        name: "`pip install ./python`'s build (`pip wheel --no-deps ./python`)",
        program: "python3",
        args: &[
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "./python",
            "-w",
            "wheel",
        ],
    },
];

/// The section: the three stages, one after another in a fresh clone of HEAD under the system's
/// temporary folder (removed after), the crates' downloads shared with this machine's Cargo home.
pub(crate) fn section() -> anyhow::Result<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let scratch = std::env::temp_dir().join(format!("slcp-first-build-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&scratch);
    let status = Command::new("git")
        .args(["clone", "-q"])
        .arg(&root)
        .arg(&scratch)
        .status()
        .context("running git clone")?;
    anyhow::ensure!(status.success(), "git clone of {} failed", root.display());
    let head = Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .current_dir(&scratch)
        .output()
        .context("running git rev-parse")?;
    let head = String::from_utf8_lossy(&head.stdout).trim().to_string();
    let mut rows = Vec::new();
    for stage in &STAGES {
        let start = Instant::now();
        let out = Command::new(stage.program)
            .args(stage.args)
            .current_dir(&scratch)
            // The clone's own target folder, whatever the caller's environment says.
            .env_remove("CARGO_TARGET_DIR")
            .output()
            .with_context(|| format!("running {}", stage.program))?;
        let seconds = start.elapsed().as_secs_f64();
        anyhow::ensure!(
            out.status.success(),
            "{} failed in the clone: {}",
            stage.name,
            String::from_utf8_lossy(&out.stderr)
        );
        println!("{}: {seconds:.0} s", stage.name);
        rows.push((stage.name, seconds));
    }
    let _ = std::fs::remove_dir_all(&scratch);
    let total: f64 = rows.iter().map(|r| r.1).sum();
    let mut t = String::new();
    let _ = writeln!(
        t,
        "\nA fresh clone of commit {head}, built cold one stage after another with the crates already downloaded (`cargo xtask benchmarks --only first-build`, about ten minutes; wall time on this machine, whatever else it was doing):\n\n| stage | wall time (s) |\n|---|---:|"
    );
    for (name, seconds) in &rows {
        let _ = writeln!(t, "| {name} | {seconds:.0} |");
    }
    let _ = writeln!(t, "| all three | {total:.0} |");
    Ok(t)
}
