//! The viewer section of `cargo xtask benchmarks`: the online MPC's control step (one re-solve from the
//! shifted plan) against how well it spins the ellipse, per horizon and passes, beside the library's
//! policy.

use library::{Library, LibrarySettings};
use viewer::protocol::{ClientMessage, PolicyKind, WorldKind};
use viewer::{World, WorldSettings};

const SECONDS: f64 = 120.0;

/// The default library, built once for both sections.
fn default_library() -> anyhow::Result<Library> {
    static BUILT: std::sync::OnceLock<Library> = std::sync::OnceLock::new();
    if let Some(lib) = BUILT.get() {
        return Ok(lib.clone());
    }
    let lib = Library::build(
        &task::ProblemFile::builtin(),
        None,
        &LibrarySettings::default(),
        |_, _| {},
    )?;
    Ok(BUILT.get_or_init(|| lib).clone())
}

pub fn section() -> anyhow::Result<String> {
    let lib = default_library()?;
    let mut out = format!(
        "Online MPC in the viewer's world (`viewer::World`, `cargo xtask view`): each control step re-solves iLQG from the current state with the given passes, warm-started from the previous plan shifted by one step (regularisation carried over), and re-seeds the plan from the library's policy after 20 steps of plans that expect less than 0.1 rad of turn. A start spreads its first solve over the next steps, up to 10 passes more per step until it converges (`OnlineMpc::warm_up`): the max column. {SECONDS:.0} s from SCENE.md's x0 with velocity kicks of std 2 every 10 s, h = 0.05 (real time: 50 ms per step); control-step times over all steps, single thread. Target: one control step at most 2.5 ms.\n\n| controller | world | control step median / 95% / 99% / max (ms) | spin (rad/s) | re-seeds |\n|---|---|---:|---:|---:|\n"
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
                task::ProblemFile::builtin().scene,
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

/// The server under load, all on 127.0.0.1 and bounded in time: a client that reads every frame measures
/// the largest real-time gap between frames and how fast simulated time advances while others misbehave.
pub fn load_section() -> anyhow::Result<String> {
    use futures_util::{SinkExt, StreamExt};
    use std::time::{Duration, Instant};
    use tokio_tungstenite::tungstenite::Message;

    let lib = default_library()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let idle = Duration::from_secs(2);
    runtime.block_on(async move {
        let viewer = viewer::Viewer::bind(viewer::ViewerConfig {
            addr: std::net::SocketAddr::from((std::net::Ipv4Addr::LOCALHOST, 0)),
            scene: task::ProblemFile::builtin().scene,
            library: Some(lib),
            world: WorldSettings {
                policy: PolicyKind::Library,
                ..WorldSettings::default()
            },
        })
        .await?
        .with_idle_timeout(idle);
        let addr = viewer.local_addr()?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let server = tokio::spawn(viewer.run(async {
            let _ = stopped.await;
        }));
        let url = format!("ws://{addr}/ws");
        // A reader of every frame for `seconds`: (largest gap between frames in ms, simulated seconds per
        // real second).
        let watch = |seconds: f64| {
            let url = url.clone();
            tokio::spawn(async move {
                let (mut ws, _) = tokio_tungstenite::connect_async(&url).await?;
                let start = Instant::now();
                let (mut last, mut gap) = (Instant::now(), 0.0f64);
                let (mut t0, mut t1) = (None, 0.0);
                while start.elapsed().as_secs_f64() < seconds {
                    let Ok(Some(Ok(message))) =
                        tokio::time::timeout(Duration::from_secs(30), ws.next()).await
                    else {
                        anyhow::bail!("the watcher lost its connection");
                    };
                    if let Message::Text(text) = message {
                        let v: serde_json::Value = serde_json::from_str(text.as_str())?;
                        if v["type"] == "frame" {
                            let t = v["t"].as_f64().unwrap_or(0.0);
                            if t0.is_none() {
                                t0 = Some(t);
                            } else {
                                gap = gap.max(last.elapsed().as_secs_f64() * 1e3);
                            }
                            t1 = t;
                            last = Instant::now();
                        }
                    }
                }
                anyhow::Ok((gap, (t1 - t0.unwrap_or(t1)) / seconds))
            })
        };
        let mut rows = Vec::new();
        let rss0 = rss_mb();
        let (gap, rate) = watch(5.0).await??;
        rows.push(format!(
            "| nothing else (5 s) | - | {gap:.0} | {rate:.2} | {rss0:.0} -> {:.0} |",
            rss_mb()
        ));
        // Ten clients flooding refused messages for 10 s, never reading their replies.
        let before = rss_mb();
        let watcher = watch(10.0);
        let mut flooders = Vec::new();
        for _ in 0..10 {
            let url = url.clone();
            flooders.push(tokio::spawn(async move {
                let (mut ws, _) = tokio_tungstenite::connect_async(&url).await?;
                let bad = serde_json::json!({"type": "kick", "std": 1e9}).to_string();
                let until = tokio::time::Instant::now() + Duration::from_secs(10);
                let mut sent = 0u64;
                while let Ok(Ok(())) =
                    tokio::time::timeout_at(until, ws.send(Message::Text(bad.clone().into()))).await
                {
                    sent += 1;
                }
                anyhow::Ok(sent)
            }));
        }
        let (gap, rate) = watcher.await??;
        let mut sent = 0;
        for f in flooders {
            sent += f.await??;
        }
        rows.push(format!(
            "| ten clients flooding refused kicks (10 s) | {sent} | {gap:.0} | {rate:.2} | {before:.0} -> {:.0} |",
            rss_mb()
        ));
        // One client switching the policy between online MPC and off, 200 times as fast as it can, then
        // 100 switches 50 ms apart (each switch restarts the online optimiser).
        let before = rss_mb();
        let watcher = watch(10.0);
        let switcher = {
            let url = url.clone();
            tokio::spawn(async move {
                let (mut ws, _) = tokio_tungstenite::connect_async(&url).await?;
                for k in 0..300 {
                    let policy = if k % 2 == 0 { "mpc" } else { "off" };
                    let m = serde_json::json!({"type": "policy", "policy": policy}).to_string();
                    ws.send(Message::Text(m.into())).await?;
                    if k >= 200 {
                        tokio::time::sleep(Duration::from_millis(50)).await;
                    }
                }
                anyhow::Ok(300u64)
            })
        };
        let (gap, rate) = watcher.await??;
        let switches = switcher.await??;
        rows.push(format!(
            "| policy switched mpc / off (200 at once, 100 at 20 Hz) | {switches} | {gap:.0} | {rate:.2} | {before:.0} -> {:.0} |",
            rss_mb()
        ));
        // A hundred silent TCP connections: how long until the server has closed them all.
        let start = Instant::now();
        let mut silent = Vec::new();
        for _ in 0..100 {
            silent.push(tokio::net::TcpStream::connect(addr).await?);
        }
        let mut closed = 0;
        for mut s in silent {
            let mut buf = [0u8; 8];
            if let Ok(Ok(0) | Err(_)) =
                tokio::time::timeout(idle * 5, tokio::io::AsyncReadExt::read(&mut s, &mut buf)).await
            {
                closed += 1;
            }
        }
        let close_s = start.elapsed().as_secs_f64();
        let _ = stop.send(());
        server.await??;
        anyhow::Ok(format!(
            "The viewer's server under load, on 127.0.0.1 with the default library's policy at real time (h = 0.05: a frame every 50 ms), its idle timeout set to {:.0} s (default {:.0} s). A client reading every frame measures the largest real-time gap between two frames and the simulated seconds per real second (1.00 is real time) while the others misbehave; memory is this process's resident set (server and clients), before and after. Inputs wait at most {} in all and {} per client; a client's excess is refused with a reply; warnings are logged at most once a second with a count.\n\n| load | messages | largest frame gap (ms) | simulated s per s | resident memory (MB) |\n|---|---:|---:|---:|---|\n{}\n\nA hundred half-open connections (TCP only, never a request): {closed} of 100 closed by the server after {close_s:.1} s.\n",
            idle.as_secs_f64(),
            viewer::DEFAULT_IDLE_TIMEOUT.as_secs_f64(),
            viewer::INPUT_CAPACITY,
            viewer::CLIENT_INPUT_CAPACITY,
            rows.join("\n")
        ))
    })
}

/// This process's resident memory, MB (0 where /proc is not there).
fn rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}
