//! `cargo xtask <experiment>`: the experiment driver, the only binary of the workspace.

// The commands' doc comments are their --help text, where JSON shapes like {"x":[n]} must read as they
// are: rustdoc would take the brackets for links.
#![allow(rustdoc::broken_intra_doc_links)]

// The experiments allocate many small vectors per simulated step (the derivatives' ingredients, the
// solver's trial data): mimalloc makes an optimiser pass about 8% faster than the system allocator
// (`xtask optimize`, alternating binaries; docs/benchmarks.md). Its v2 allocator: see the workspace
// Cargo.toml.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

// The command-line plumbing over the crates (`tools`), the experiments that compute the documented
// results (`experiments`), the speed tables (`benchmarks`), and the generated sections of the docs they
// rewrite (`docs`): experiments and benchmarks use tools and docs, never the other way round.
mod benchmarks;
mod docs;
mod experiments;
mod tools;

use experiments::{diagnose, examples, figures, reproduce, seeds};
use tools::{distance, evaluate, jsonl, lcp, optimize, step, train, view};

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(
    name = "xtask",
    about = "Experiments of the stochastic-complementarity contact project"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Signed distance of posed ellipse pairs: JSON lines in on stdin, JSON lines out on stdout.
    ///
    /// Each input line is {"a":[a1,b1],"pose_a":[x,y,theta],"b":[a2,b2],"pose_b":[x,y,theta]};
    /// each output line is {"distance":d,"point_a":[x,y],"point_b":[x,y],"normal":[nx,ny],
    /// "witness_unique":bool} or {"error":"..."}.
    #[command(after_help = jsonl::STREAM_HELP)]
    Distance(distance::Args),
    /// Complementarity problems through the ncp solvers: JSON lines in on stdin, JSON lines out.
    ///
    /// Each input line is {"M":[[...],...],"q":[...]} with optional "n_free" (leading equality rows)
    /// and "z0" (warm start); each output line is {"z":[...],"w":[...],"iterations":k,
    /// "status":"converged"|...,"residual":r} or {"error":"..."}. Limits: at most 500 rows a line (ERM
    /// 300 complementarity rows, enumeration 20).
    #[command(after_help = jsonl::STREAM_HELP)]
    Lcp(lcp::Args),
    /// One step of the simulator per JSON line on stdin: {"x":[6],"u":[2]} ->
    /// {"x_next":[6],"lambda":[6],"d":[6],"status":..,"fx":[[..]],"fu":[[..]]} (fx[i][j] = dx'_i/dx_j,
    /// with --derivatives) or {"error":"..."}.
    #[command(after_help = jsonl::STREAM_HELP)]
    Step(step::StepArgs),
    /// Roll out a control sequence from a state; writes the trajectory and impulses as JSON or CSV.
    Simulate(step::SimulateArgs),
    /// iLQG / DDP on a task of a scene file (the built-in finger's by default) or the unicycle
    /// benchmark: one line per pass behind a progress bar,
    /// then passes, final cost and time; --out writes the trajectory and its linear policy as JSON.
    Optimize(optimize::Args),
    /// Build a task's controller library (receding-horizon iLQG, paper IV-C; the built-in finger's spin by
    /// default) and save it.
    Train(train::Args),
    /// Run a library's global policy in closed loop on the smoothed and the hard system, with kicks.
    Evaluate(evaluate::Args),
    /// The paper's experiments end to end with default settings: summary, libraries and JSON under one
    /// folder (default results/).
    Reproduce(reproduce::Args),
    /// The claim over library seeds: the paper's recipe, the default and three ablations for library
    /// seeds 1-8, each on four worlds with and without kicks (minutes: twenty-four library builds).
    Seeds(seeds::Args),
    /// Where the paper's limit cycle is won or lost: the optimiser as MPC (N = 75 and 90), online MPC
    /// and the libraries' policies from rest without kicks; a table and a picture per run.
    Diagnose(diagnose::Args),
    /// Other scenes and tasks end to end (three example scenes, or --scene FILE): solved from rest,
    /// libraries over seeds, closed loops on the smoothed and hard world, success measures, pictures,
    /// and docs/results.md's examples section.
    Examples(examples::Args),
    /// The paper's figures (contact surface, library states, limit cycle, frames) as PNG and SVG.
    Figures(figures::Args),
    /// Measure speed against error and rewrite the generated tables of docs/benchmarks.md.
    Benchmarks(benchmarks::Args),
    /// The interactive viewer: a local web server with the finger (or any --scene and --task) simulated
    /// at real time under the library's policy or online MPC; drag bodies with the mouse.
    View(view::Args),
}

/// Write a file whole or not at all (a temporary file beside it, renamed into place): a failed write never
/// leaves half a file where a good one was. Every file a command writes goes through here.
pub(crate) fn write_file(
    path: impl AsRef<std::path::Path>,
    bytes: impl AsRef<[u8]>,
) -> std::io::Result<()> {
    library::write_atomically(path.as_ref(), bytes.as_ref()).map_err(|e| match e {
        library::LibraryError::Io { source, path } => {
            std::io::Error::new(source.kind(), format!("{path}: {source}"))
        }
        other => std::io::Error::other(other.to_string()),
    })
}

/// `work` on every job, on two threads taking the next job as they finish one; results in job order.
pub(crate) fn on_two_threads<J: Sync, R: Send>(
    jobs: &[J],
    work: impl Fn(&J) -> R + Sync,
) -> Vec<R> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut done: Vec<(usize, R)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..2)
            .map(|_| {
                scope.spawn(|| {
                    let mut out = Vec::new();
                    loop {
                        let j = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(job) = jobs.get(j) else { break };
                        out.push((j, work(job)));
                    }
                    out
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().expect("a worker does not panic"))
            .collect()
    });
    done.sort_by_key(|(j, _)| *j);
    done.into_iter().map(|(_, r)| r).collect()
}

fn main() -> anyhow::Result<()> {
    let command = Cli::parse().command;
    // The viewer logs its warnings by default; every command logs its stages (a library build's trunk,
    // growth rounds and final check; RUST_LOG=info) to standard error when asked.
    // RUST_LOG holds `LEVEL` and `target=LEVEL` directives (`info`, `warn,library=debug`); a filter by
    // target alone, so that no regex engine is built for it (issue 30: the first build's time).
    if matches!(command, Command::View(_)) || std::env::var_os("RUST_LOG").is_some() {
        use tracing_subscriber::filter::{LevelFilter, Targets};
        use tracing_subscriber::prelude::*;
        let targets = match std::env::var("RUST_LOG") {
            Ok(text) => text.parse::<Targets>().unwrap_or_else(|e| {
                eprintln!("RUST_LOG={text:?} is not a list of LEVEL or target=LEVEL ({e}): logging warnings");
                Targets::new().with_default(LevelFilter::WARN)
            }),
            Err(_) => Targets::new().with_default(LevelFilter::WARN),
        };
        tracing_subscriber::registry()
            .with(tracing_subscriber::fmt::layer().with_writer(std::io::stderr))
            .with(targets)
            .init();
    }
    match command {
        Command::Distance(args) => distance::run(&args),
        Command::Lcp(args) => lcp::run(&args),
        Command::Step(args) => step::run_step(&args),
        Command::Simulate(args) => step::run_simulate(&args),
        Command::Optimize(args) => optimize::run(&args),
        Command::Train(args) => train::run(&args),
        Command::Evaluate(args) => evaluate::run(&args),
        Command::Reproduce(args) => reproduce::run(&args),
        Command::Seeds(args) => seeds::run(&args),
        Command::Figures(args) => figures::run(&args),
        Command::Examples(args) => examples::run(&args),
        Command::Diagnose(args) => diagnose::run(&args),
        Command::Benchmarks(args) => benchmarks::run(&args),
        Command::View(args) => view::run(&args),
    }
}

/// The three stream commands on the same bytes (each command's own tests are in its file).
#[cfg(test)]
mod streams {
    #[derive(clap::Parser)]
    struct LcpCli {
        #[command(flatten)]
        args: crate::lcp::Args,
    }

    type Answer<'a> = dyn FnMut(&str) -> Result<String, String> + 'a;

    /// Lines of `input` that get an answer: all but the blank ones (UTF-8 and only white space).
    fn answered(input: &[u8]) -> usize {
        let mut parts: Vec<&[u8]> = input.split(|&b| b == b'\n').collect();
        if parts.last().is_some_and(|p| p.is_empty()) {
            parts.pop();
        }
        parts
            .iter()
            .filter(|p| !std::str::from_utf8(p).is_ok_and(|s| s.trim().is_empty()))
            .count()
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]
        #[test]
        fn no_byte_string_crashes_a_stream_command(
            chunks in proptest::collection::vec(
                proptest::prop_oneof![
                    proptest::collection::vec(proptest::num::u8::ANY, 0..40),
                    proptest::sample::select(vec![
                        br#"{"x":[-0.7,-0.5,0,0,0,0],"u":[0,0]}"#.to_vec(),
                        br#"{"x":[1e308,-1e308,0,0,0,0],"u":[1e308,0]}"#.to_vec(),
                        br#"{"a":[1,0.5],"pose_a":[0,0,0],"b":[1e-300,0.5],"pose_b":[3,0,0]}"#.to_vec(),
                        br#"{"a":[1e200,1e-200],"pose_a":[0,0,0],"b":[0.7,0.5],"pose_b":[0,0,0]}"#.to_vec(),
                        br#"{"M":[[0,-1],[1,0]],"q":[-1,-1]}"#.to_vec(),
                        br#"{"M":[[1e308]],"q":[-1e308]}"#.to_vec(),
                        b"\xff\xfe\x00".to_vec(),
                        b"   ".to_vec(),
                    ]),
                ],
                0..8,
            ),
        ) {
            let input = chunks.join(&b'\n');
            let expected = answered(&input);
            let lcp = <LcpCli as clap::Parser>::parse_from(["lcp"]).args;
            let mut sim = dynamics::Simulator::new(
                task::ProblemFile::builtin().scene,
                dynamics::StepSettings::default(),
            )
            .unwrap();
            let mut answers: Vec<Box<Answer<'_>>> = vec![
                Box::new(|l| crate::distance::answer_line(l, true)),
                Box::new(|l| crate::lcp::answer_line(l, &lcp)),
                Box::new(|l| {
                    crate::step::answer_line(&mut sim, l, crate::step::Answers::Derivatives)
                }),
            ];
            for answer in &mut answers {
                let mut out = Vec::new();
                crate::jsonl::filter_with(&input[..], &mut out, answer).unwrap();
                let text = String::from_utf8(out).unwrap();
                proptest::prop_assert_eq!(text.lines().count(), expected);
                for line in text.lines() {
                    let v: serde_json::Value = serde_json::from_str(line).unwrap();
                    proptest::prop_assert!(!line.contains("null"), "{}", line);
                    proptest::prop_assert!(v.is_object());
                }
            }
        }
    }
}
