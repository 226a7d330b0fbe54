//! The library section of `cargo xtask benchmarks`: building the finger's library (paper IV-C) and the
//! global policy's look-up (eq. 20) at the library's sizes.

use dynamics::Scene;
use library::{Library, LibrarySettings};
use std::hint::black_box;
use std::time::Instant;

pub fn section() -> anyhow::Result<String> {
    let mut out = String::new();
    let settings = LibrarySettings {
        keep: 4,
        ..LibrarySettings::default()
    };
    let start = Instant::now();
    let lib = Library::build(&Scene::flicking_finger(), &settings, |_, _| {})?;
    let seconds = start.elapsed().as_secs_f64();
    let firsts: Vec<_> = lib.entries.iter().step_by(4).collect();
    let mut passes: Vec<u32> = firsts.iter().map(|e| e.passes).collect();
    let total: u32 = passes.iter().sum();
    let first = passes[0];
    passes.remove(0);
    passes.sort();
    out.push_str(&format!(
        "Building the default library (`cargo xtask train`: 400 receding-horizon trajectories, d = 4, kicks of variance 4 every 15 steps, full DDP at sigma = 0.1), single thread: {seconds:.1} s, {total} optimiser passes: {first} for the first solve from zero controls, then per warm-started re-solve median {}, 90th percentile {}, largest {} (the re-solves right after a kick take the most). {} of 400 converged.\n\n",
        passes[passes.len() / 2],
        passes[passes.len() * 9 / 10],
        passes[passes.len() - 1],
        firsts.iter().filter(|e| e.converged).count()
    ));
    out.push_str("Policy look-up (nearest stored state under the covariance-scaled norm, theta3 modulo pi, then its linear law), brute-force scan, median over the library's own states:\n\n| controllers | look-up (ns) | rate (kHz) |\n|---:|---:|---:|\n");
    for keep in [1usize, 4] {
        let mut l = lib.clone();
        l.entries = l.entries.iter().step_by(5 - keep).cloned().collect();
        let policy = l.policy()?;
        let mut u = [0.0; 2];
        let mut times: Vec<f64> = (0..11)
            .map(|_| {
                let t = Instant::now();
                for e in &l.entries {
                    black_box(policy.control(&e.x, &mut u).expect("a stored state"));
                }
                t.elapsed().as_nanos() as f64 / l.entries.len() as f64
            })
            .collect();
        times.sort_by(f64::total_cmp);
        out.push_str(&format!(
            "| {} | {:.0} | {:.0} |\n",
            l.entries.len(),
            times[5],
            1e6 / times[5]
        ));
    }
    Ok(out)
}
