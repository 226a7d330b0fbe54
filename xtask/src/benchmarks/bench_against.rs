//! This build against another one, run alternately in the same run (issue 29: the machine's speed drifts
//! by up to 2x between hours, so only timings taken side by side compare). The other build is any
//! `xtask` binary (`--baseline`, for example one built from an older commit in a worktree beside this
//! one); each round runs the same commands with it and with this binary, one after the other, and the
//! table gives both, their ratio and whether the two builds computed the same thing.

use anyhow::Context;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// What a row runs: `xtask` arguments, and how to read the time and the result from its output.
struct Job {
    what: &'static str,
    args: &'static [&'static str],
    kind: Kind,
}

#[derive(Clone, Copy)]
enum Kind {
    /// `optimize`: the solve's time (`..., T ms` on its summary line) and its passes and cost.
    Solve,
    /// `train`: the build time (`in T s:`) and the library file written.
    Build,
}

const JOBS: [Job; 5] = [
    Job {
        what: "finger, full-DDP solve from rest at sigma 0.1",
        args: &["optimize", "--sigma", "0.1"],
        kind: Kind::Solve,
    },
    Job {
        what: "three-link finger, solve from rest",
        args: &[
            "optimize",
            "--scene",
            "scenes/three_link_finger.toml",
            "--task",
            "spin",
        ],
        kind: Kind::Solve,
    },
    Job {
        what: "two fingers, solve from rest",
        args: &[
            "optimize",
            "--scene",
            "scenes/two_fingers.toml",
            "--task",
            "turn",
        ],
        kind: Kind::Solve,
    },
    Job {
        what: "pushing, solve from rest",
        args: &[
            "optimize",
            "--scene",
            "scenes/pushing.toml",
            "--task",
            "push",
        ],
        kind: Kind::Solve,
    },
    Job {
        what: "the default finger library, single thread",
        args: &["train"],
        kind: Kind::Build,
    },
];

/// One run's time (ms for a solve, s for a build) and what it computed (a solve's passes and cost, a
/// build's library file's bytes).
fn run(binary: &Path, job: &Job, scratch: &Path, tag: &str) -> anyhow::Result<(f64, Vec<u8>)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut command = Command::new(binary);
    command.args(job.args).current_dir(&root);
    let library = scratch.join(format!("{tag}.lib"));
    if let Kind::Build = job.kind {
        command.arg("--out").arg(&library);
    }
    let output = command
        .output()
        .with_context(|| format!("running {}", binary.display()))?;
    let text = String::from_utf8_lossy(&output.stdout).into_owned()
        + &String::from_utf8_lossy(&output.stderr);
    anyhow::ensure!(
        output.status.success(),
        "{} {} failed:\n{text}",
        binary.display(),
        job.args.join(" ")
    );
    let number_before = |line: &str, unit: &str| -> Option<f64> {
        let head = &line[..line.rfind(unit)?];
        head.rsplit([' ', ',']).next()?.parse().ok()
    };
    match job.kind {
        Kind::Solve => {
            // `task NAME (full): ... after N passes, cost C, T ms`
            let line = text
                .lines()
                .rfind(|l| l.contains(" passes, cost ") && l.ends_with(" ms"))
                .with_context(|| format!("no solve summary in:\n{text}"))?;
            let ms = number_before(line, " ms").context("no time on the summary line")?;
            let (from, to) = (
                line.find("after").unwrap_or(0),
                line.rfind(',').unwrap_or(0),
            );
            let result = line.as_bytes()[from..to.max(from)].to_vec();
            Ok((ms, result))
        }
        Kind::Build => {
            // `built K controllers from J trajectories (...) in T s: ...`
            let line = text
                .lines()
                .find(|l| l.starts_with("built "))
                .with_context(|| format!("no build summary in:\n{text}"))?;
            let head = &line[..line.find(" s:").context("no build time")?];
            let s: f64 = head
                .rsplit(' ')
                .next()
                .and_then(|t| t.parse().ok())
                .context("no build time")?;
            let bytes = std::fs::read(&library)
                .with_context(|| format!("reading {}", library.display()))?;
            Ok((s, bytes))
        }
    }
}

/// Minimum and median.
fn spread(v: &mut [f64]) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    (v[0], median)
}

/// The section: `rounds` rounds, each running every job with `baseline` and then with this binary.
pub(crate) fn section(baseline: &Path, label: &str, rounds: usize) -> anyhow::Result<String> {
    anyhow::ensure!(
        (1..=50).contains(&rounds),
        "--rounds must be 1 to 50, got {rounds}"
    );
    anyhow::ensure!(
        baseline.is_file(),
        "--baseline {} is not a file: give the path of another build's xtask binary",
        baseline.display()
    );
    let this: PathBuf = std::env::current_exe().context("finding this binary")?;
    let scratch = std::env::temp_dir().join(format!("slcp-against-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let head = Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")))
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default();
    let mut out = String::new();
    writeln!(
        out,
        "\nThis build (commit {head}) against {label} (`cargo xtask benchmarks --only against --baseline PATH --baseline-label TEXT`): {rounds} rounds, each running every row's command with {label}'s xtask and then with this one, one after the other on one core, so that both see the same machine. Solves: the time `optimize` prints for its solve (ms); builds: the build time `train` prints (s). Same result: the same passes and cost to the printed digit (solves), the same library file byte for byte (builds); where the two builds' solves take different numbers of passes, the last column compares the time per pass.\n"
    )?;
    writeln!(
        out,
        "| what | {label}: min / median | this build: min / median | ratio of medians (of minima) | same result | passes, {label} / this | ratio of medians per pass |"
    )?;
    writeln!(out, "|---|---:|---:|---:|---|---:|---:|")?;
    let mut times = vec![(Vec::new(), Vec::new()); JOBS.len()];
    let mut same = vec![true; JOBS.len()];
    // A solve's passes (`after N passes`), each build's last: the builds may take different numbers.
    let mut passes = vec![(None, None); JOBS.len()];
    let passes_of = |result: &[u8]| -> Option<f64> {
        let text = String::from_utf8_lossy(result);
        text.strip_prefix("after ")?.split(' ').next()?.parse().ok()
    };
    for round in 0..rounds {
        for (j, job) in JOBS.iter().enumerate() {
            let (tb, rb) = run(baseline, job, &scratch, "baseline")?;
            let (tt, rt) = run(&this, job, &scratch, "this")?;
            times[j].0.push(tb);
            times[j].1.push(tt);
            same[j] &= rb == rt;
            if let Kind::Solve = job.kind {
                passes[j] = (passes_of(&rb), passes_of(&rt));
            }
            eprintln!("round {}: {}: {tb} vs {tt}", round + 1, job.what);
        }
    }
    let _ = std::fs::remove_dir_all(&scratch);
    for (j, job) in JOBS.iter().enumerate() {
        let unit = match job.kind {
            Kind::Solve => "ms",
            Kind::Build => "s",
        };
        let (bmin, bmed) = spread(&mut times[j].0);
        let (tmin, tmed) = spread(&mut times[j].1);
        let (per_pass_passes, per_pass) = match passes[j] {
            (Some(pb), Some(pt)) => (
                format!("{pb} / {pt}"),
                format!("{:.2}", (tmed / pt) / (bmed / pb)),
            ),
            _ => ("-".to_string(), "-".to_string()),
        };
        writeln!(
            out,
            "| {} (`cargo xtask {}`) | {bmin:.1} / {bmed:.1} {unit} | {tmin:.1} / {tmed:.1} {unit} | {:.2} ({:.2}) | {} | {per_pass_passes} | {per_pass} |",
            job.what,
            job.args.join(" "),
            tmed / bmed,
            tmin / bmin,
            if same[j] { "yes" } else { "no" }
        )?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_spread_is_the_minimum_and_the_median() {
        assert_eq!(spread(&mut [3.0, 1.0, 2.0]), (1.0, 2.0));
        assert_eq!(spread(&mut [4.0, 1.0, 2.0, 3.0]), (1.0, 2.5));
    }
}
