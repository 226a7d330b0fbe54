//! `cargo xtask seeds`: the claim of docs/results.md over library seeds. For seeds 1-8 (the kick seeds of
//! the build) it builds the paper's recipe, the default and the default with eight growth rounds, derives
//! two ablations from the default (its entries before growth; its nearest controller alone), and runs each
//! policy from rest for 200 s on the four worlds of `cargo xtask evaluate` with and without kicks. Its
//! table says how many seeds keep a steady cycle, the spread of the spin, and how many kicks each recovers
//! from. About twenty-four library builds: minutes, where `cargo xtask reproduce` (one seed) takes about
//! one.

use crate::experiments::recipe::SEEDS;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use library::{Evaluation, Library, LibrarySettings};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Options of `cargo xtask seeds`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Library seeds (kick seeds of the build): 1 to this.
    #[arg(long, default_value_t = SEEDS, value_parser = clap::value_parser!(u64).range(1..=64))]
    seeds: u64,
    /// Simulated seconds per closed-loop run.
    #[arg(long, default_value_t = crate::experiments::recipe::SECONDS)]
    seconds: f64,
    /// Output folder (seeds.md, seeds.json).
    #[arg(long, default_value = "results")]
    out: PathBuf,
    /// The documentation folder whose results.md a run with the default settings rewrites (its section
    /// "seeds").
    #[arg(long, default_value = "docs")]
    docs: PathBuf,
    /// Leave the documentation alone.
    #[arg(long)]
    no_docs: bool,
}

#[derive(Serialize)]
struct Summary {
    runs: Vec<SeedRun>,
    /// Simulated seconds per closed-loop run.
    run_seconds: f64,
    /// Wall time of the sweep.
    seconds: f64,
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 1e5,
        "--seconds must be in (0, 1e5], not {}",
        dynamics::Scale(args.seconds)
    );
    let start = Instant::now();
    std::fs::create_dir_all(&args.out)?;
    let bars = MultiProgress::new();
    let runs = seed_sweep(args, &bars)?;
    let summary = Summary {
        runs,
        run_seconds: args.seconds,
        seconds: start.elapsed().as_secs_f64(),
    };
    let mut text = String::new();
    seed_table(&mut text, &summary);
    println!("{text}");
    crate::write_file(args.out.join("seeds.md"), &text)?;
    crate::write_file(
        args.out.join("seeds.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    println!(
        "wrote {}/seeds.md and seeds.json in {:.1} s",
        args.out.display(),
        summary.seconds
    );
    if args.no_docs {
        return Ok(());
    }
    if args.seeds != SEEDS || args.seconds != crate::experiments::recipe::SECONDS {
        println!(
            "{}/results.md left alone: it documents the default sweep ({SEEDS} seeds, {} s per run)",
            args.docs.display(),
            crate::experiments::recipe::SECONDS
        );
        return Ok(());
    }
    crate::experiments::recipe::write_docs(&args.docs, "seeds", "cargo xtask seeds", &text, &[])?;
    println!(
        "rewrote the section \"seeds\" of {}/results.md",
        args.docs.display()
    );
    Ok(())
}

/// One closed-loop run of a seed sweep.
#[derive(Serialize)]
pub(crate) struct SeedRun {
    pub(crate) seed: u64,
    /// Which recipe built the library (see the report's table).
    pub(crate) recipe: String,
    pub(crate) world: String,
    pub(crate) h: f64,
    pub(crate) kicks: bool,
    pub(crate) evaluation: Evaluation,
}

/// The recipe `cargo xtask train` builds by default, as the sweeps' tables name it.
pub(crate) const DEFAULT_RECIPE: &str = RECIPES[4];

/// The runs of `lib` (built with `seed` by the recipe `recipe`) on the four worlds of `cargo xtask
/// evaluate`, with and without kicks.
pub(crate) fn runs_of(
    seed: u64,
    recipe: &str,
    lib: &Library,
    seconds: f64,
) -> anyhow::Result<Vec<SeedRun>> {
    Ok(crate::experiments::recipe::on_four_worlds(lib, seconds)?
        .into_iter()
        .map(|(world, h, kicks, evaluation)| SeedRun {
            seed,
            recipe: recipe.into(),
            world,
            h,
            kicks,
            evaluation,
        })
        .collect())
}

/// The recipes of the seed sweep, each a library built with that seed, or one derived from it.
const RECIPES: [&str; 5] = [
    "paper (N = 75, kicked chain, first controllers, nearest)",
    "default without growth",
    "default, nearest controller only",
    "default with 8 growth rounds",
    "default (N = 90, cycle first, 4 per trajectory, 8 ranked by value, 12 growth rounds)",
];

/// A library the seed sweep builds (the other rows of its table derive from the default's).
#[derive(Debug, Clone, Copy)]
enum Build {
    /// The default recipe; its entries before growth and its nearest controller alone derive from it.
    Default,
    /// The default recipe stopped after eight growth rounds.
    EightRounds,
    /// The paper's recipe.
    Paper,
}

impl Build {
    /// The settings it builds with for `seed`.
    fn settings(self, seed: u64) -> LibrarySettings {
        let base = match self {
            Build::Default => LibrarySettings::default(),
            Build::EightRounds => LibrarySettings {
                growth: 8,
                ..LibrarySettings::default()
            },
            Build::Paper => LibrarySettings::paper(),
        };
        LibrarySettings { seed, ..base }
    }

    /// The rows of the table that `lib` (built as `self`) gives: its recipe's label and the library.
    fn variants(self, lib: Library) -> Vec<(&'static str, Library)> {
        match self {
            Build::Paper => vec![(RECIPES[0], lib)],
            Build::EightRounds => vec![(RECIPES[3], lib)],
            Build::Default => {
                let mut ungrown = lib.clone();
                ungrown
                    .entries
                    .truncate(lib.settings.trajectories * lib.settings.keep);
                let mut nearest = lib.clone();
                nearest.settings.neighbours = 1;
                vec![
                    (RECIPES[1], ungrown),
                    (RECIPES[2], nearest),
                    (RECIPES[4], lib),
                ]
            }
        }
    }
}

/// The seed sweep: for each seed the paper's recipe and the default, and two libraries derived from the
/// default (its entries before growth; its nearest controller alone), each on the four worlds with and
/// without kicks. Builds run on two threads, the longest (the default recipe's) first.
fn seed_sweep(args: &Args, bars: &MultiProgress) -> anyhow::Result<Vec<SeedRun>> {
    let jobs: Vec<(u64, Build)> = [Build::Default, Build::EightRounds, Build::Paper]
        .into_iter()
        .flat_map(|build| (1..=args.seeds).map(move |seed| (seed, build)))
        .collect();
    let bar = bars.add(ProgressBar::new(jobs.len() as u64));
    bar.set_style(
        ProgressStyle::with_template(
            "seed sweep: {bar:40} {pos}/{len} libraries {elapsed_precise} (eta {eta})",
        )
        .expect("a valid template"),
    );
    let run_job = |&(seed, build): &(u64, Build)| -> anyhow::Result<Vec<SeedRun>> {
        let lib = Library::build(
            &task::ProblemFile::builtin(),
            None,
            &build.settings(seed),
            |_, _| {},
        )?;
        let mut runs = Vec::new();
        for (recipe, lib) in build.variants(lib) {
            runs.extend(runs_of(seed, recipe, &lib, args.seconds)?);
        }
        bar.inc(1);
        Ok(runs)
    };
    let results = crate::on_two_threads(&jobs, run_job);
    bar.finish_and_clear();
    let mut runs = Vec::new();
    for r in results {
        runs.extend(r?);
    }
    Ok(runs)
}

/// The seed sweep, one row per recipe, world and time step, with and without kicks.
fn seed_table(t: &mut String, s: &Summary) {
    let seeds: std::collections::BTreeSet<u64> = s.runs.iter().map(|r| r.seed).collect();
    let _ = writeln!(
        t,
        "# The seed sweep (`cargo xtask seeds`, {:.0} s): libraries of seeds {}-{} from rest, {:.0} s per run\n",
        s.seconds,
        seeds.first().copied().unwrap_or(0),
        seeds.last().copied().unwrap_or(0),
        s.run_seconds
    );
    seed_rows(t, &s.runs, &RECIPES);
}

/// The table of a seed sweep's `runs`, one row per recipe (in the order of `recipes`), world and time
/// step, with and without kicks, after a paragraph saying what its columns mean.
pub(crate) fn seed_rows(t: &mut String, runs: &[SeedRun], recipes: &[&str]) {
    let _ = writeln!(
        t,
        "Last quarter: the mean spin over the last quarter of the run (the paper's Fig. 5: about 0.67 rad/s, our reading); steady: seeds whose last quarter spins at 0.5 rad/s or more. With kicks (std 2 every 10 s): resumed = kicks after which the ellipse turned a further quarter turn before the next.\n\n| recipe | world | h | last quarter, no kicks: mean (min-max) rad/s | steady | with kicks: last quarter | resumed (mean) | seeds resuming after all but one kick |\n|---|---|---:|---:|---:|---:|---:|---:|"
    );
    for &recipe in recipes {
        let mut keys: Vec<(String, f64)> = Vec::new();
        for r in runs.iter().filter(|r| r.recipe == recipe) {
            if !keys.iter().any(|(w, h)| *w == r.world && *h == r.h) {
                keys.push((r.world.clone(), r.h));
            }
        }
        for (world, h) in keys {
            let runs = |kicks: bool| -> Vec<&Evaluation> {
                runs.iter()
                    .filter(|r| {
                        r.recipe == recipe && r.world == world && r.h == h && r.kicks == kicks
                    })
                    .map(|r| &r.evaluation)
                    .collect()
            };
            let (calm, kicked) = (runs(false), runs(true));
            let stats = |v: &[&Evaluation]| {
                let rates: Vec<f64> = v.iter().map(|e| e.final_spin_rate).collect();
                let mean = rates.iter().sum::<f64>() / rates.len().max(1) as f64;
                let lo = rates.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = rates.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                (mean, lo, hi, rates.iter().filter(|&&r| r >= 0.5).count())
            };
            let (mean, lo, hi, steady) = stats(&calm);
            let (kmean, _, _, _) = stats(&kicked);
            let resumed =
                kicked.iter().map(|e| e.resumed as f64).sum::<f64>() / kicked.len().max(1) as f64;
            let kicks = kicked.first().map_or(0, |e| e.kicks);
            let all_but_one = kicked.iter().filter(|e| e.resumed + 1 >= e.kicks).count();
            let _ = writeln!(
                t,
                "| {recipe} | {world} | {h} | {mean:.3} ({lo:.3}-{hi:.3}) | {steady}/{} | {kmean:.3} | {resumed:.1}/{kicks} | {all_but_one}/{} |",
                calm.len(),
                kicked.len()
            );
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_default_recipes_label_names_the_default_growth_rounds() {
        let growth = library::LibrarySettings::default().growth;
        assert!(
            super::DEFAULT_RECIPE.contains(&format!(" {growth} growth rounds")),
            "{} does not say {growth} growth rounds",
            super::DEFAULT_RECIPE
        );
    }
}
