//! The viewer section of `cargo xtask benchmarks`: the online MPC's control step (one re-solve from the
//! shifted plan) against how well it spins the ellipse, per horizon and passes, beside the library's
//! policy.

use dynamics::Scene;
use library::{Library, LibrarySettings};
use viewer::protocol::{ClientMessage, PolicyKind, WorldKind};
use viewer::{World, WorldSettings};

const SECONDS: f64 = 120.0;

pub fn section() -> anyhow::Result<String> {
    let lib = Library::build(
        &Scene::flicking_finger(),
        &LibrarySettings::default(),
        |_, _| {},
    )?;
    let mut out = format!(
        "Online MPC in the viewer's world (`viewer::World`, `cargo xtask view`): each control step re-solves iLQG from the current state with the given passes, warm-started from the previous plan shifted by one step (regularisation carried over), and re-seeds the plan from the library's policy after 20 steps of plans that expect less than 0.1 rad of turn. {SECONDS:.0} s from SCENE.md's x0 with velocity kicks of std 2 every 10 s, h = 0.05 (real time: 50 ms per step); control-step times over all steps, single thread. Target: one control step at most 2.5 ms.\n\n| controller | world | control step median / 95% / 99% / max (ms) | spin (rad/s) | re-seeds |\n|---|---|---:|---:|---:|\n"
    );
    let mut configs: Vec<(String, PolicyKind, usize, usize)> = vec![(
        format!(
            "library policy (default, {} controllers)",
            lib.entries.len()
        ),
        PolicyKind::Library,
        60,
        1,
    )];
    for (horizon, passes) in [(40, 1), (50, 1), (60, 1), (75, 1), (60, 2)] {
        configs.push((
            format!(
                "MPC, N = {horizon}, {passes} pass{}",
                if passes > 1 { "es" } else { "" }
            ),
            PolicyKind::Mpc,
            horizon,
            passes,
        ));
    }
    for (name, policy, horizon, passes) in configs {
        for world_kind in [WorldKind::Smoothed, WorldKind::Hard] {
            let mut world = World::new(
                Scene::flicking_finger(),
                Some(lib.clone()),
                WorldSettings {
                    policy,
                    mpc_horizon: horizon,
                    mpc_passes: passes,
                    ..WorldSettings::default()
                },
            )?;
            world.apply(ClientMessage::World { world: world_kind })?;
            let steps = (SECONDS / world.h()).round() as usize;
            let kick_every = (10.0 / world.h()).round() as usize;
            let start = world.state()[2];
            let mut times = Vec::with_capacity(steps);
            for k in 1..=steps {
                if k % kick_every == 0 {
                    world.apply(ClientMessage::Kick { std: 2.0 })?;
                }
                world.advance()?;
                times.push(world.frame().control_ms);
            }
            times.sort_by(f64::total_cmp);
            let q = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
            let frame = world.frame();
            out.push_str(&format!(
                "| {name} | {} | {:.2} / {:.2} / {:.2} / {:.2} | {:.3} | {} |\n",
                match world_kind {
                    WorldKind::Smoothed => "smoothed",
                    WorldKind::Hard => "hard",
                },
                q(0.5),
                q(0.95),
                q(0.99),
                q(1.0),
                (world.state()[2] - start) / SECONDS,
                frame.mpc_reseeds
            ));
        }
    }
    Ok(out)
}
