//! `cargo xtask benchmarks`: speed against error, written into the generated sections of docs/benchmarks.md.
//!
//! Timings here are medians over repeated batches on whatever machine runs the command; the criterion
//! benches (`cargo bench -p geometry`) measure the same hot paths with statistics.

mod bench_against;
mod bench_ddp;
mod bench_dynamics;
mod bench_first_build;
mod bench_library;
mod bench_ncp;
mod bench_viewer;

use crate::docs::replace_section;
use anyhow::Context;
use geometry::{Ellipse, parry_estimate, signed_distance_coords, signed_distance_dual};
use num_dual::HyperDual64;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The markdown file whose generated sections are rewritten.
    #[arg(long, default_value = "docs/benchmarks.md")]
    out: PathBuf,
    /// Folder of the reference files (the repository's copies, tests/data/README.md).
    #[arg(long, default_value = "tests/data")]
    reference: PathBuf,
    /// Print the tables only; leave the file alone.
    #[arg(long)]
    dry_run: bool,
    /// Run only these sections (default: all).
    #[arg(long, value_enum)]
    only: Vec<Section>,
    /// For `--only against`: another build's xtask binary, run alternately with this one.
    #[arg(long)]
    baseline: Option<PathBuf>,
    /// For `--only against`: what the other build is, as the table names it (a commit, a branch).
    #[arg(long, default_value = "the baseline")]
    baseline_label: String,
    /// For `--only against`: rounds of alternate runs (1 to 50).
    #[arg(long, default_value_t = 5)]
    rounds: usize,
}

/// The generated sections of docs/benchmarks.md.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Section {
    /// Ellipse signed distance against the reference cases and parry.
    Geometry,
    /// Complementarity solvers on scene-sized problems.
    Ncp,
    /// The simulator's step, derivatives and knobs.
    Dynamics,
    /// The optimiser on the unicycle and the finger.
    Ddp,
    /// Building the library and looking up its policy.
    Library,
    /// The library optimiser's tolerance against build time and closed-loop quality (several minutes).
    LibraryTolerance,
    /// The viewer's online MPC: control-step time against spin.
    Viewer,
    /// The viewer's server under load on 127.0.0.1: floods, policy switches, silent connections.
    ViewerLoad,
    /// The Python package's call overhead (python/benchmarks/overhead.py, in the Python of SLCP_PYTHON,
    /// default python3, with `pip install ./python` done).
    Python,
    /// The first build of a fresh clone: the README's two commands and `pip install ./python`, cold
    /// (about ten minutes; only when asked for by name).
    FirstBuild,
    /// This build against another build's xtask (`--baseline`), run alternately: solves and a library
    /// build, their times side by side and whether they compute the same (only when asked for by name).
    Against,
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let wanted = |s: Section| args.only.is_empty() || args.only.contains(&s);
    let mut sections = Vec::new();
    if wanted(Section::Geometry) {
        sections.push(("geometry", geometry_section(&args.reference)?));
    }
    if wanted(Section::Ncp) {
        sections.push(("ncp", bench_ncp::section()?));
    }
    if wanted(Section::Dynamics) {
        sections.push(("dynamics", bench_dynamics::section(&args.reference)?));
    }
    if wanted(Section::Ddp) {
        sections.push(("ddp", bench_ddp::section()?));
    }
    if wanted(Section::Library) {
        sections.push(("library", bench_library::section()?));
    }
    if wanted(Section::Viewer) {
        sections.push(("viewer", bench_viewer::section()?));
    }
    if wanted(Section::ViewerLoad) {
        sections.push(("viewer-load", bench_viewer::load_section()?));
    }
    if wanted(Section::Python) {
        sections.push(("python", python_section()?));
    }
    // Ten minutes of compiling, and a measure of the machine as much as of the code: by name only.
    if args.only.contains(&Section::FirstBuild) {
        sections.push(("first-build", bench_first_build::section()?));
    }
    // Another build to compare with: by name only, and only with the binary given.
    if args.only.contains(&Section::Against) {
        let baseline = args.baseline.as_ref().context(
            "--only against needs --baseline PATH: another build's xtask binary to run alternately with this one",
        )?;
        sections.push((
            "against",
            bench_against::section(baseline, &args.baseline_label, args.rounds)?,
        ));
    }
    if wanted(Section::LibraryTolerance) {
        sections.push(("library-tolerance", bench_library::tolerance_section()?));
    }
    for (name, body) in sections {
        println!("{body}");
        if !args.dry_run {
            replace_section(&args.out, name, "cargo xtask benchmarks", &body)?;
            println!("wrote section {name} of {}", args.out.display());
        }
    }
    Ok(())
}

/// The Python package's call overhead: python/benchmarks/overhead.py's table, or a line saying why it
/// did not run.
/// The standard output of `script args` run by the Python of `SLCP_PYTHON` (default `python3`), or why
/// not: the interpreter's name and the last line of its standard error (or why it could not start).
pub(crate) fn run_python(script: &str, args: &[&str]) -> Result<String, (String, String)> {
    let python = std::env::var("SLCP_PYTHON").unwrap_or_else(|_| "python3".into());
    match std::process::Command::new(&python)
        .arg(script)
        .args(args)
        .output()
    {
        Ok(o) if o.status.success() => Ok(String::from_utf8_lossy(&o.stdout).into_owned()),
        Ok(o) => {
            let why = String::from_utf8_lossy(&o.stderr);
            let why = why.lines().last().unwrap_or("failed").to_string();
            Err((python, why))
        }
        Err(e) => Err((python, e.to_string())),
    }
}

fn python_section() -> anyhow::Result<String> {
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../python/benchmarks/overhead.py"
    );
    let intro = "\nCalling the crates from Python (`pip install ./python`, docs/python.md): what one call adds to the work it asks for. Target: at most 1 us per `step` call.\n\n";
    Ok(match run_python(script, &[]) {
        Ok(stdout) => format!("{intro}{stdout}"),
        Err((python, why)) => format!(
            "{intro}Not run ({python}: {why}; `pip install ./python` and set SLCP_PYTHON).\n"
        ),
    })
}

/// A table row: name, timed call, worst errors (distance, normal, witness, unanswered).
type Row<'a> = (&'a str, fn(&Case) -> f64, (f64, f64, f64, usize));

/// One pair of posed ellipses.
#[derive(Debug, Clone, Copy)]
struct Case {
    a: Ellipse,
    pose_a: [f64; 3],
    b: Ellipse,
    pose_b: [f64; 3],
}

/// Known answer of a reference case.
#[derive(Debug, Clone, Copy)]
struct Known {
    distance: f64,
    normal: Option<[f64; 2]>,
    point_a: Option<[f64; 2]>,
    scale: f64,
    condition: f64,
}

fn load_reference(dir: &Path) -> anyhow::Result<Vec<(Case, Known)>> {
    let path = dir.join("ellipse_cases.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let data: serde_json::Value = serde_json::from_str(&text)?;
    let cases = data["cases"].as_array().context("no `cases` array")?;
    cases
        .iter()
        .map(|c| {
            let g = |k: &str| c[k].as_f64().with_context(|| format!("case lacks {k}"));
            let v = |k: &str| -> Option<[f64; 2]> {
                let a = c[k].as_array()?;
                Some([a[0].as_f64()?, a[1].as_f64()?])
            };
            let a = Ellipse::new(g("a1")?, g("b1")?)?;
            let b = Ellipse::new(g("a2")?, g("b2")?)?;
            let unique = c["witness_unique"].as_bool().unwrap_or(true);
            Ok((
                Case {
                    a,
                    pose_a: [g("x1")?, g("y1")?, g("th1")?],
                    b,
                    pose_b: [g("x2")?, g("y2")?, g("th2")?],
                },
                Known {
                    distance: g("distance")?,
                    normal: if unique { v("normal") } else { None },
                    point_a: if unique { v("pA") } else { None },
                    scale: a.max_axis().max(b.max_axis()),
                    condition: c["witness_condition"].as_f64().unwrap_or(1.0).max(1.0),
                },
            ))
        })
        .collect()
}

/// Link 2 against the free ellipse over a grid of finger configurations (SCENE.md poses).
fn scene_cases() -> Vec<Case> {
    let finger = Ellipse::new(0.8, 0.25).expect("valid");
    let free = Ellipse::new(0.7, 0.5).expect("valid");
    let mut out = Vec::new();
    for i in 0..24 {
        for j in 0..16 {
            for k in 0..8 {
                let t1 = -std::f64::consts::PI * (i as f64 + 0.5) / 24.0;
                let t2 = -2.0 * std::f64::consts::FRAC_PI_3 * (j as f64 + 0.5) / 16.0;
                let t3 = std::f64::consts::PI * k as f64 / 8.0;
                let phi2 = t1 + t2;
                let hinge = [1.6 * t1.cos(), 1.6 * t1.sin()];
                let pose_a = [
                    hinge[0] + 0.8 * phi2.cos(),
                    hinge[1] + 0.8 * phi2.sin(),
                    phi2,
                ];
                out.push(Case {
                    a: finger,
                    pose_a,
                    b: free,
                    pose_b: [0.0, -3.0, t3],
                });
            }
        }
    }
    out
}

/// Median nanoseconds per call of `f` over the cases (21 batches).
fn time_ns(cases: &[Case], mut f: impl FnMut(&Case) -> f64) -> f64 {
    let reps = (20_000 / cases.len().max(1)).max(1);
    let mut batches: Vec<f64> = (0..21)
        .map(|_| {
            let start = Instant::now();
            let mut acc = 0.0;
            for _ in 0..reps {
                for c in cases {
                    acc += f(black_box(c));
                }
            }
            black_box(acc);
            start.elapsed().as_nanos() as f64 / (reps * cases.len()) as f64
        })
        .collect();
    batches.sort_by(f64::total_cmp);
    batches[batches.len() / 2]
}

fn ours(c: &Case) -> f64 {
    signed_distance_coords(&c.a, c.pose_a, &c.b, c.pose_b).map_or(f64::NAN, |r| r.distance)
}

fn parry(c: &Case) -> f64 {
    parry_estimate(&c.a, c.pose_a, &c.b, c.pose_b)
        .ok()
        .flatten()
        .map_or(f64::NAN, |e| e.distance)
}

/// Worst errors over the reference cases: distance / size, normal / condition, witness / (size condition).
fn errors(
    reference: &[(Case, Known)],
    mut answer: impl FnMut(&Case) -> Option<(f64, [f64; 2], [f64; 2])>,
) -> (f64, f64, f64, usize) {
    let (mut ed, mut en, mut ep, mut missing) = (0.0_f64, 0.0_f64, 0.0_f64, 0);
    for (case, known) in reference {
        let Some((d, n, pa)) = answer(case) else {
            missing += 1;
            continue;
        };
        ed = ed.max((d - known.distance).abs() / known.scale);
        if let (Some(kn), Some(kp)) = (known.normal, known.point_a) {
            en = en.max((n[0] - kn[0]).hypot(n[1] - kn[1]) / known.condition);
            ep = ep.max((pa[0] - kp[0]).hypot(pa[1] - kp[1]) / (known.scale * known.condition));
        }
    }
    (ed, en, ep, missing)
}

fn geometry_section(reference_dir: &Path) -> anyhow::Result<String> {
    let reference = load_reference(reference_dir)?;
    let scene = scene_cases();
    let (apart, overlapping): (Vec<Case>, Vec<Case>) = scene.iter().partition(|c| ours(c) >= 0.0);
    let ref_cases: Vec<Case> = reference.iter().map(|(c, _)| *c).collect();

    let e_ours = errors(&reference, |c| {
        let r = signed_distance_coords(&c.a, c.pose_a, &c.b, c.pose_b).ok()?;
        Some((
            r.distance,
            [r.normal.x, r.normal.y],
            [r.point_a.x, r.point_a.y],
        ))
    });
    let e_parry = errors(&reference, |c| {
        let r = parry_estimate(&c.a, c.pose_a, &c.b, c.pose_b).ok()??;
        Some((
            r.distance,
            [r.normal.x, r.normal.y],
            [r.point_a.x, r.point_a.y],
        ))
    });
    let rows: [Row; 5] = [
        (
            "parry GJK/EPA contact (its default tolerances)",
            parry,
            e_parry,
        ),
        ("ours: distance, witnesses, normal", ours, e_ours),
        (
            "ours + gradient",
            |c| {
                signed_distance_coords(&c.a, c.pose_a, &c.b, c.pose_b)
                    .map_or(f64::NAN, |r| r.gradient()[2])
            },
            e_ours,
        ),
        (
            "ours + all derivatives (Hessian, witness and normal Jacobians)",
            |c| {
                signed_distance_coords(&c.a, c.pose_a, &c.b, c.pose_b)
                    .map_or(f64::NAN, |r| r.derivatives().hessian[2][2])
            },
            e_ours,
        ),
        (
            "ours through num-dual HyperDual64 (one 2nd-order direction)",
            |c| {
                let mut pa = c.pose_a.map(HyperDual64::from);
                pa[2] = HyperDual64::new(c.pose_a[2], 1.0, 1.0, 0.0);
                let pb = c.pose_b.map(HyperDual64::from);
                signed_distance_dual(&c.a, pa, &c.b, pb).map_or(f64::NAN, |r| r.distance.eps1eps2)
            },
            e_ours,
        ),
    ];
    let mut s = String::new();
    s.push_str(&format!(
        "Scene poses: link 2 against the free ellipse over a {}-point grid of (theta1, theta2, theta3) \
         ({} apart, {} overlapping). Errors: worst over the {} reference cases \
         (`tests/data/ellipse_cases.json`), distance relative to the larger semi-axis, normal and \
         witness point relative to the case's witness condition as its README defines.\n\n",
        scene.len(),
        apart.len(),
        overlapping.len(),
        reference.len()
    ));
    s.push_str("| method | scene apart (ns) | scene overlapping (ns) | reference cases (ns) | distance error | normal error | witness error | no answer |\n");
    s.push_str("|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for (name, f, (ed, en, ep, missing)) in rows {
        s.push_str(&format!(
            "| {name} | {:.0} | {:.0} | {:.0} | {ed:.1e} | {en:.1e} | {ep:.1e} | {missing} |\n",
            time_ns(&apart, f),
            time_ns(&overlapping, f),
            time_ns(&ref_cases, f),
        ));
    }
    let evals = |cs: &[Case]| {
        let mut v: Vec<usize> = cs
            .iter()
            .filter_map(|c| signed_distance_coords(&c.a, c.pose_a, &c.b, c.pose_b).ok())
            .map(|r| r.evaluations)
            .collect();
        v.sort_unstable();
        (v[v.len() / 2], v[v.len() - 1])
    };
    let (ma, xa) = evals(&apart);
    let (mo, xo) = evals(&overlapping);
    let (mr, xr) = evals(&ref_cases);
    s.push_str(&format!(
        "\nSupport-gap evaluations per query (median / worst): scene apart {ma} / {xa}, scene overlapping {mo} / {xo}, \
         reference cases {mr} / {xr}.\n"
    ));
    Ok(s)
}
