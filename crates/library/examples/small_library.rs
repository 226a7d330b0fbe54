//! Build a small controller library for the flicking finger, save it, load it back and run its global
//! policy in closed loop on the hard world for 60 s, with and without velocity kicks.
//!
//! ```sh
//! cargo run --release -p library --example small_library [-- OUT.lib]
//! ```
//!
//! Sixty receding-horizon trajectories and no growth build in a few seconds; the default
//! library (`LibrarySettings::default().for_task(&task)`, what `cargo xtask train` builds) takes longer and spins more
//! robustly (docs/results.md).

use library::{EvaluationSettings, Exploration, Library, LibrarySettings, evaluate};
use task::{ContactModel, ProblemFile};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| std::env::temp_dir().join("small.lib").display().to_string());
    // The built-in scene file, scenes/finger.toml, and its spin task.
    let file = ProblemFile::builtin();
    let task = file.task(Some("spin"))?;
    // The default recipe scaled down: a trunk of 40 unperturbed trajectories (the cycle), 2 kicked
    // branches of 10 around it, no growth rounds.
    let settings = LibrarySettings {
        trajectories: 60,
        exploration: Exploration::Branches {
            trunk: 40,
            settle: 10,
            length: 10,
        },
        growth: 0,
        ..LibrarySettings::default().for_task(&task)
    };
    settings.validate(&file.scene)?;
    let start = std::time::Instant::now();
    // The callback sees each trajectory's controllers as they are stored (a progress bar's hook).
    let library = Library::build(&file, Some("spin"), &settings, |_, _| {})?;
    println!(
        "built {} controllers in {:.1} s",
        library.entries.len(),
        start.elapsed().as_secs_f64()
    );
    library.save(std::path::Path::new(&out))?;
    let library = Library::load(std::path::Path::new(&out))?;
    let policy = library.policy()?;
    for kick_every in [0.0, 10.0] {
        let e = evaluate(
            &library,
            &policy,
            &EvaluationSettings {
                model: ContactModel::Hard,
                seconds: 60.0,
                kick_every,
                ..EvaluationSettings::default()
            },
        )?;
        print!(
            "hard world, {}: spin {:.3} rad/s (last quarter {:.3})",
            if kick_every > 0.0 {
                "kicks every 10 s"
            } else {
                "no kicks"
            },
            e.spin_rate,
            e.final_spin_rate,
        );
        if e.kicks > 0 {
            print!(
                ", {} of {} kicks followed by a quarter turn",
                e.resumed, e.kicks
            );
        }
        println!();
    }
    println!("saved {out}");
    Ok(())
}
