//! The viewer end to end in a real headless browser (Debian's Chromium driven by playwright-core from
//! tests/e2e/viewer.mjs): the page loads, the online controller spins the ellipse, a mouse drag against
//! the spin reaches the server and holds the ellipse back, and after the release the spin resumes; and on
//! the pushing scene (tests/e2e/scene.mjs), the ground is drawn where it is and a drag lifts the free
//! block. Screenshots land in target/e2e/.
//!
//! Needs node, /usr/bin/chromium and `npm ci --prefix tests/e2e`, which `.ci/run` installs. So the tests
//! are ignored, with that reason, by a plain `cargo test --workspace` (its summary counts them as ignored,
//! not passed); `.ci/run` runs them with `--include-ignored` after installing what they need, and asked for
//! on a machine without it they fail naming what is missing (issue 30).

use std::net::{Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;
use viewer::protocol::PolicyKind;
use viewer::{Viewer, ViewerConfig, WorldSettings};

fn missing(e2e: &Path) -> Vec<String> {
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    let mut missing = Vec::new();
    if Command::new("node").arg("--version").output().is_err() {
        missing.push("node".to_string());
    }
    if !Path::new(&chromium).exists() {
        missing.push(chromium);
    }
    if !e2e.join("node_modules/playwright-core").exists() {
        missing.push("tests/e2e/node_modules (npm ci --prefix tests/e2e)".into());
    }
    missing
}

/// Serve `config` on a free port of 127.0.0.1, run the e2e script `script` against it (its screenshot
/// to target/e2e/`screenshot`), stop the server, and return the script's JSON result. Panics naming
/// what is missing when the browser or its driver is not installed.
fn in_browser(config: ViewerConfig, script: &str, screenshot: &str) -> serde_json::Value {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let e2e = root.join("e2e");
    let missing = missing(&e2e);
    assert!(
        missing.is_empty(),
        "the browser test needs {missing:?} (bash .ci/run installs them)"
    );
    let out = root.join("../target/e2e");
    std::fs::create_dir_all(&out).unwrap();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let viewer = runtime.block_on(Viewer::bind(config)).unwrap();
    let addr = viewer.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = runtime.spawn(viewer.run(async {
        let _ = stopped.await;
    }));
    let output = Command::new("node")
        .arg(e2e.join(script))
        .arg(format!("http://{addr}/"))
        .arg(out.join(screenshot))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    println!("{stdout}{}", String::from_utf8_lossy(&output.stderr));
    stop.send(()).unwrap();
    runtime
        .block_on(async { tokio::time::timeout(Duration::from_secs(10), server).await })
        .expect("the server stops")
        .unwrap()
        .unwrap();
    assert!(out.join(screenshot).exists() || !output.status.success());
    serde_json::from_str(stdout.lines().last().expect("the script prints its result")).unwrap()
}

#[test]
#[ignore = "needs Chromium and tests/e2e's npm packages: bash .ci/run installs them and runs it"]
fn in_a_browser_a_drag_against_the_spin_holds_the_ellipse_and_the_spin_resumes() {
    let result = in_browser(
        ViewerConfig {
            addr: SocketAddr::from((Ipv4Addr::LOCALHOST, 0)),
            scene: task::ProblemFile::builtin().scene,
            library: Some(crate::support::finger_library().clone()),
            world: WorldSettings {
                policy: PolicyKind::Library,
                ..WorldSettings::default()
            },
        },
        "viewer.mjs",
        "viewer.png",
    );
    assert_eq!(result["ok"], true, "{result}");
    assert!(result["perturbations"].as_u64().unwrap() >= 1);
    assert!(result["turned_while_held"].as_f64().unwrap() < 0.5);
    assert!(result["spin_after"].as_f64().unwrap() > 0.1);
}

#[test]
#[ignore = "needs Chromium and tests/e2e's npm packages: bash .ci/run installs them and runs it"]
fn in_a_browser_the_pushing_scene_shows_its_ground_and_its_free_block_can_be_lifted() {
    let problem =
        task::ProblemFile::from_toml_str(include_str!("../../scenes/pushing.toml")).unwrap();
    let task = problem.task(Some("push")).unwrap();
    let result = in_browser(
        ViewerConfig {
            addr: SocketAddr::from((Ipv4Addr::LOCALHOST, 0)),
            scene: problem.scene.clone(),
            library: None,
            world: WorldSettings {
                policy: PolicyKind::Off,
                x0: task.x0.clone(),
                h: task.h,
                task,
                ..WorldSettings::default()
            },
        },
        "scene.mjs",
        "viewer-pushing.png",
    );
    assert_eq!(result["ok"], true, "{result}");
    assert_eq!(result["watched"], "block.x");
    assert!(result["lifted"].as_f64().unwrap() > 0.3, "{result}");
}
