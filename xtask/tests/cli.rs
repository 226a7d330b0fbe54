//! The command-line driver as a user's script drives it: a co-process answering line by line, and the
//! bad arguments and inputs that must end in a clear error, never a panic or a hang.

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

fn xtask() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_xtask"));
    c.env_remove("RUST_BACKTRACE")
        .env_remove("RUST_LIB_BACKTRACE");
    c
}

/// `text` written to `name` in a fresh folder of the temporary directory tagged `tag` (the folder, to
/// remove, and the file).
fn scene_file(tag: &str, name: &str, text: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("xtask-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

/// The standard output of `command`, which must succeed (else both its outputs are shown).
fn succeeds(command: &mut Command) -> String {
    let out = command.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// The standard output of `xtask optimize ARGS --scene SCENE`, which must succeed.
fn optimize_ok(args: &[&str], scene: &std::path::Path) -> String {
    succeeds(xtask().arg("optimize").args(args).arg("--scene").arg(scene))
}

/// Spawn `args` with piped stdin and stdout; its stdout lines arrive on the returned channel.
fn co_process(
    args: &[&str],
) -> (
    std::process::Child,
    std::process::ChildStdin,
    mpsc::Receiver<String>,
) {
    let mut child = xtask()
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("xtask starts");
    let stdin = child.stdin.take().expect("piped stdin");
    let stdout = child.stdout.take().expect("piped stdout");
    let (send, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if send.send(line).is_err() {
                break;
            }
        }
    });
    (child, stdin, lines)
}

/// The answer to one line, waiting at most a minute (a command that held its answers would hang here).
fn ask(
    stdin: &mut std::process::ChildStdin,
    lines: &mpsc::Receiver<String>,
    line: &[u8],
) -> String {
    stdin.write_all(line).unwrap();
    stdin.write_all(b"\n").unwrap();
    stdin.flush().unwrap();
    lines
        .recv_timeout(Duration::from_secs(60))
        .expect("an answer to a line while the input stays open")
}

#[test]
fn step_answers_each_line_before_the_next_is_written() {
    let (mut child, mut stdin, lines) = co_process(&["step"]);
    let mut x = "[-0.7853981633974483,-0.5235987755982989,0,0,0,0]".to_string();
    for _ in 0..5 {
        let answer = ask(
            &mut stdin,
            &lines,
            format!(r#"{{"x":{x},"u":[1,0]}}"#).as_bytes(),
        );
        let v: serde_json::Value = serde_json::from_str(&answer).unwrap();
        assert_eq!(v["status"], "converged", "{answer}");
        x = v["x_next"].to_string();
    }
    // Bytes that are not UTF-8, a blank line (no answer) and a state of the wrong size: each bad line
    // gets its error line and the stream goes on.
    let bad = ask(&mut stdin, &lines, b"\xff\xfe{\"x\":1}");
    assert!(bad.contains("not UTF-8"), "{bad}");
    stdin.write_all(b"\n").unwrap();
    let answer = ask(&mut stdin, &lines, br#"{"x":[1,2],"u":[0,0]}"#);
    assert!(answer.starts_with(r#"{"error""#), "{answer}");
    let answer = ask(
        &mut stdin,
        &lines,
        format!(r#"{{"x":{x},"u":[0,0]}}"#).as_bytes(),
    );
    assert!(answer.contains("x_next"), "{answer}");
    drop(stdin);
    assert!(child.wait().unwrap().success());
}

#[test]
fn distance_and_lcp_answer_line_by_line_too() {
    let (mut child, mut stdin, lines) = co_process(&["distance"]);
    let a = ask(
        &mut stdin,
        &lines,
        br#"{"a":[1,0.5],"pose_a":[0,0,0],"b":[0.7,0.5],"pose_b":[3,0,0]}"#,
    );
    assert!(a.starts_with(r#"{"distance":1.3"#), "{a}");
    let a = ask(
        &mut stdin,
        &lines,
        br#"{"a":[1e250,0.5],"pose_a":[0,0,0],"b":[0.7,0.5],"pose_b":[3,0,0]}"#,
    );
    assert!(a.starts_with(r#"{"error""#) && !a.contains("null"), "{a}");
    drop(stdin);
    assert!(child.wait().unwrap().success());

    let (mut child, mut stdin, lines) = co_process(&["lcp"]);
    let a = ask(&mut stdin, &lines, br#"{"M":[[2,1],[1,2]],"q":[-1,-1]}"#);
    assert!(a.contains(r#""status":"converged""#), "{a}");
    drop(stdin);
    assert!(child.wait().unwrap().success());
}

#[test]
fn simulate_streams_keeps_the_final_state_and_accepts_optimize_output() {
    let out = xtask()
        .args(["simulate", "--steps", "3", "--format", "csv"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    let rows: Vec<&str> = text.lines().collect();
    // Header, three steps, the final state.
    assert_eq!(rows.len(), 5, "{text}");
    assert!(rows[0].ends_with(",status"));
    assert!(rows[4].starts_with("0.15"), "{}", rows[4]);

    let out = xtask()
        .args(["simulate", "--steps", "2", "--format", "jsonl"])
        .output()
        .unwrap();
    let lines: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 3);
    assert_eq!(lines[2]["k"], 2);
    assert_eq!(lines[2]["x"].as_array().unwrap().len(), 6);

    // The report `optimize --out` writes is a valid --controls file.
    let dir = std::env::temp_dir().join(format!("xtask-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let report = dir.join("optimized.json");
    std::fs::write(
        &report,
        r#"{"problem":"finger","solution":{"controls":[[1,0],[0,1],[0,0],[1,1]]}}"#,
    )
    .unwrap();
    let out = xtask()
        .args(["simulate", "--format", "jsonl", "--controls"])
        .arg(&report)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert_eq!(String::from_utf8(out.stdout).unwrap().lines().count(), 5);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn impossible_counts_and_failing_runs_end_in_an_error_not_a_panic() {
    for args in [
        &["simulate", "--steps", "1000000000000"][..],
        &["simulate", "--steps", "18446744073709551615"],
        &["simulate", "--steps", "2000000"],
        &["optimize", "--horizon", "100000000000"],
        &["view", "--mpc-horizon", "100000000000"],
        &[
            "train",
            "--trajectories",
            "10000000000000",
            "--out",
            "/dev/null",
        ],
    ] {
        let out = xtask().args(args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(
            err.contains("range") || err.contains("at most") || err.contains("not in"),
            "{args:?}: {err}"
        );
    }
    // A step that fails mid-run: the steps before it are written, then the error, and the exit code
    // says so.
    let out = xtask()
        .args([
            "simulate", "--steps", "3", "--h", "1e300", "--format", "jsonl",
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.lines().last().unwrap().contains("error"), "{text}");
}

#[test]
fn a_reader_that_goes_away_is_not_a_crash() {
    let mut child = xtask()
        .args(["simulate", "--steps", "200000", "--format", "jsonl"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with('{'));
    let out = child.wait_with_output().unwrap();
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("panicked"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_negative_number_is_read_as_a_value_and_range_checked() {
    let out = xtask()
        .args(["simulate", "--sigma", "-1", "--steps", "1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("sigma") && err.contains("positive"), "{err}");
    assert!(!err.contains("unexpected argument"), "{err}");
}

#[test]
fn optimize_explains_its_status_and_strict_fails_when_it_did_not_converge() {
    let out = xtask()
        .args([
            "optimize",
            "--problem",
            "unicycle",
            "--iterations",
            "2",
            "--quiet",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "without --strict the exit code is 0");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("status: not converged"), "{text}");
    let out = xtask()
        .args([
            "optimize",
            "--problem",
            "unicycle",
            "--iterations",
            "2",
            "--quiet",
            "--strict",
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--strict"));
    let out = xtask()
        .args(["optimize", "--problem", "unicycle", "--quiet", "--strict"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("status: converged"));
}

/// Issue 28: `simulate` without `--x0` starts from the scene file's task (it took the finger's x0 for
/// any scene of six states), and with no task from rest, refused where bodies overlap there.
#[test]
fn simulate_without_x0_starts_from_the_files_task_or_a_checked_rest() {
    let pushing = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/pushing.toml");
    let out = xtask()
        .args([
            "simulate", "--scene", pushing, "--steps", "1", "--format", "jsonl",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("task push's x0"), "{stderr}");
    let first: serde_json::Value = serde_json::from_str(
        String::from_utf8(out.stdout)
            .unwrap()
            .lines()
            .next()
            .unwrap(),
    )
    .unwrap();
    let x: Vec<f64> = serde_json::from_value(first["x"].clone()).unwrap();
    // link1.angle, link2.angle, block.x, block.y, block.angle.
    assert_eq!(&x[..5], &[-0.5, -0.9, 0.0, 0.2, 0.0]);

    // The same scene without its task: at rest at q = 0 the block sits half in the ground.
    let text = std::fs::read_to_string(pushing).unwrap();
    let scene_only = &text[..text.find("[task.").unwrap()];
    let (dir, path) = scene_file("rest", "pushing_scene.toml", scene_only);
    let out = xtask()
        .args(["simulate", "--steps", "1", "--scene"])
        .arg(&path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("ground and block overlap") && stderr.contains("--x0"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Issue 28: `train`'s defaults give a library for a target task (they stopped on `growth = 12 is out of
/// range`) and for a small budget (`--trajectories 20` stopped on `trunk = 100 is out of range`).
#[test]
fn train_defaults_fit_target_tasks_and_small_budgets() {
    let dir = std::env::temp_dir().join(format!("xtask-train-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let two_fingers = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/two_fingers.toml");
    let out = xtask()
        .args([
            "train",
            "--scene",
            two_fingers,
            "--task",
            "turn",
            "--trajectories",
            "6",
        ])
        .arg("--out")
        .arg(dir.join("turn.lib"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let out = xtask()
        .args(["train", "--trajectories", "6", "--growth", "0", "--out"])
        .arg(dir.join("finger.lib"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // A horizon shorter than the recipe's shift of 4 steps is taken (each trajectory shifts by the whole
    // horizon: it stopped on `shift = 4 is out of range`, a setting no flag names); one past the longest
    // a library solves over is refused with the range at once, where 100001 steps ran for minutes.
    succeeds(
        xtask()
            .args([
                "train",
                "--trajectories",
                "6",
                "--growth",
                "0",
                "--horizon",
                "2",
                "--out",
            ])
            .arg(dir.join("short.lib")),
    );
    let out = xtask()
        .args([
            "train",
            "--trajectories",
            "6",
            "--horizon",
            "100001",
            "--out",
        ])
        .arg(dir.join("long.lib"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("horizon = 100001 is out of range: between 1 and 1000 steps"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Issue 28: a contact out of reach at the task's noise scale (a pusher 0.45 behind the block, sigma
/// 0.05) "converged" after one pass with nothing moved. `optimize` now says no contact was felt and
/// reaches for it: the finger and the block pulled together (here the pull never brings them into
/// contact, so no solve of the task's own cost follows it), then continuation in the noise scale, each
/// try and stage logged, and the block moves; `--no-continuation` only says so, and `--strict`
/// fails then.
#[test]
fn optimize_says_when_no_contact_is_felt_and_reaches_for_it() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenes/pushing.toml"
    ))
    .unwrap()
    .replacen(
        "\"block.y\" = 0.2 }",
        "\"block.y\" = 0.2, \"block.x\" = 0.45 }",
        1,
    )
    .replace("target = 0.6 }", "target = 1.05 }");
    let (dir, path) = scene_file("reach", "far.toml", &text);
    let stdout = optimize_ok(&["--task", "push", "--quiet", "--strict"], &path);
    assert!(stdout.contains("no contact felt"), "{stdout}");
    // The pull brings the finger no nearer than the block's reach: no task solve follows it.
    assert!(
        stdout.contains("reach: link2-block pulled (")
            && stdout.contains("but not into contact: no task solve from there"),
        "{stdout}"
    );
    assert!(stdout.contains("continuation: sigma 0.1000"), "{stdout}");
    assert!(stdout.contains("continued in the noise scale"), "{stdout}");
    assert!(!stdout.contains("status: no contact felt"), "{stdout}");
    let moved: f64 = stdout
        .split("block.x 0.4500 -> ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("the summary names block.x");
    assert!(moved > 0.9, "block.x ends at {moved}: {stdout}");

    let out = xtask()
        .args([
            "optimize",
            "--task",
            "push",
            "--quiet",
            "--no-continuation",
            "--strict",
            "--scene",
        ])
        .arg(&path)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stdout.contains("no contact felt (--no-continuation)"),
        "{stdout}"
    );
    // The status line says so too, not a plain "converged".
    assert!(
        stdout.contains("status: no contact felt, nothing moved through a contact"),
        "{stdout}"
    );
    assert!(stderr.contains("--strict: no contact felt"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A paddle below a hanging door whose bob it can only push up, which turns the door away from its
/// target: a contact the controls reach but the task's cost does not pay for.
const DOOR: &str = r#"
gravity = [0.0, -4.0]

[[body]]
name = "paddle"
semi_axes = [0.7, 0.12]
parent = "world"
anchor = [-1.0, 0.0]
centre = [0.7, 0.0]
joint = { limits = [-1.2, 1.2], damping = 0.2, actuated = true }

[[body]]
name = "door"
semi_axes = [0.6, 0.1]
parent = "world"
anchor = [0.0, 0.9]
centre = [0.0, -0.6]
joint = { damping = 0.4 }

[[contact]]
a = "paddle"
b = "door"
friction = 0.4

[task.close]
h = 0.05
horizon = 60
model = "logistic"
sigma = 0.05
x0 = { "paddle.angle" = -0.6 }
control_weight = 0.05
running = [{ coordinate = "door.angle", quadratic = 10.0, target = 0.3 }]
final = [
    { coordinate = "door.angle", quadratic = 20.0, target = 0.3 },
    { coordinate = "door.angle", velocity = true, quadratic = 2.0 },
]
"#;

/// A contact the controls can reach but the task's cost does not pay for: a paddle below a hanging door
/// whose bob it can only push up, which turns the door away from its target. The pull touches, the
/// task's own solve from there lets go again, and `optimize` says that, not that nothing the controls do
/// reaches a contact (which it said before).
#[test]
fn optimize_tells_a_contact_that_does_not_pay_from_one_out_of_reach() {
    let (dir, path) = scene_file("door", "door.toml", DOOR);
    let stdout = optimize_ok(&["--quiet"], &path);
    assert!(
        stdout.contains("reach: paddle-door pulled together (") && stdout.contains("passes, cost"),
        "{stdout}"
    );
    assert!(
        stdout.contains(
            "no contact kept: the controls can reach it (pulling paddle-door together touched)"
        ),
        "{stdout}"
    );
    assert!(
        !stdout.contains("nothing the controls do reaches a contact"),
        "{stdout}"
    );
    assert!(
        stdout.contains("status: no contact felt, nothing moved through a contact"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `train` ends with how the library's policy does without kicks on `evaluate`'s worlds, by the task's
/// criterion, and where it succeeds on none says where to look: the door's task cannot succeed.
#[test]
fn train_reports_its_policys_unkicked_verdict() {
    let (dir, path) = scene_file("door-train", "door.toml", DOOR);
    let stdout = succeeds(
        xtask()
            .args(["train", "--trajectories", "20", "--scene"])
            .arg(&path)
            .arg("--out")
            .arg(dir.join("door.lib")),
    );
    assert!(
        stdout.contains("without kicks for 40 s from the task's start, its policy succeeds on 0 of 4 worlds (door.angle -> 0.3 within 0.05"),
        "{stdout}"
    );
    assert!(
        stdout.contains("not on logistic 0.05 at h = 0.05, hard at h = 0.05"),
        "{stdout}"
    );
    assert!(
        stdout.contains("On none: `cargo xtask optimize`"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A library whose own time step is too short for the check's 40 s (1e-12 s: 4e13 steps) is still
/// written, and the check says which worlds it could not run and why instead of failing `train` after the
/// file is on disk; the worlds at 0.03 s are judged as ever.
#[test]
fn train_without_a_verdict_on_a_world_says_why_and_keeps_the_library() {
    let (dir, path) = scene_file(
        "door-tiny-h",
        "door.toml",
        &DOOR.replacen("h = 0.05", "h = 1e-12", 1),
    );
    let out = dir.join("door.lib");
    let stdout = succeeds(
        xtask()
            .args(["train", "--trajectories", "20", "--scene"])
            .arg(&path)
            .arg("--out")
            .arg(&out),
    );
    assert!(out.exists(), "{stdout}");
    assert!(
        stdout.contains("no verdict on logistic 0.05 at h = 1e-12 (setting seconds = 40 is out of range: at most 1e7 time steps)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("not on logistic 0.05 at h = 0.03, hard at h = 0.03"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A user's extreme numbers (a noise scale of 1e-300, a block 1e300 up) are printed in exponent form in
/// every message, never as a line of three hundred digits.
#[test]
fn extreme_numbers_in_a_task_read_as_exponents() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenes/slider_push.toml"
    ))
    .unwrap()
    .replacen("sigma = 0.05", "sigma = 1e-300", 1)
    .replacen(
        "x0 = { \"block.y\" = 0.25 }",
        "x0 = { \"block.y\" = 1e300 }",
        1,
    );
    let (dir, path) = scene_file("extreme", "extreme.toml", &text);
    let stdout = optimize_ok(&["--task", "push"], &path);
    assert!(
        stdout.contains("logistic contact, sigma 1e-300"),
        "{stdout}"
    );
    assert!(stdout.contains("none in reach"), "{stdout}");
    assert!(stdout.contains("e300 at its nearest"), "{stdout}");
    for line in stdout.lines() {
        assert!(
            line.len() < 400,
            "a line of {} characters: {line}",
            line.len()
        );
    }
    // The same in the refusals of flags and of a period.
    for (args, expected) in [
        (
            &["examples", "--no-docs", "--seconds", "1e300"][..],
            "--seconds 1e300 must be between 1 and 10000",
        ),
        (
            &["seeds", "--no-docs", "--seconds", "1e300"][..],
            "--seconds must be in (0, 1e5], not 1e300",
        ),
    ] {
        let out = xtask().args(args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(expected),
            "{stderr}"
        );
    }
    let tiny = text.replacen(
        "sigma = 1e-300",
        "sigma = 0.05\nperiods = { \"block.angle\" = 1e-300 }",
        1,
    );
    let path = dir.join("tiny_period.toml");
    std::fs::write(&path, tiny).unwrap();
    let out = xtask()
        .args(["optimize", "--task", "push", "--scene"])
        .arg(&path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("the period of block.angle is 1e-300, it must be finite and at least 1e-6"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Issue 28: a receding horizon that lets the task stall is lengthened, and `train` says so. The paddle of
/// tests/data/paddle.toml stops its wheel out of reach over 90 steps; its library is built over more, and
/// the file records the horizon it was built over.
#[test]
fn train_says_when_it_lengthened_a_stalled_horizon() {
    let dir = std::env::temp_dir().join(format!("xtask-horizon-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let paddle = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/data/paddle.toml");
    let stdout = succeeds(
        xtask()
            .args([
                "train",
                "--scene",
                paddle,
                "--trajectories",
                "80",
                "--trunk",
                "80",
                "--settle",
                "5",
                "--growth",
                "0",
                "--out",
            ])
            .arg(dir.join("paddle.lib")),
    );
    assert!(
        stdout.contains("the receding horizon of 90 steps let the task stall")
            && stdout.contains("stopped advancing wheel.angle"),
        "{stdout}"
    );
    let lib = library::Library::load(&dir.join("paddle.lib")).unwrap();
    assert!(lib.settings.horizon > 90, "{}", lib.settings.horizon);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_comparison_against_another_build_names_what_it_lacks() {
    let run = |args: &[&str]| {
        let out = xtask()
            .args(["benchmarks", "--only", "against", "--dry-run"])
            .args(args)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?} should be refused");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let missing = run(&[]);
    assert!(missing.contains("--baseline"), "{missing}");
    let absent = run(&["--baseline", "/no/such/xtask"]);
    assert!(
        absent.contains("/no/such/xtask") && absent.contains("not a file"),
        "{absent}"
    );
    let rounds = run(&["--baseline", env!("CARGO_BIN_EXE_xtask"), "--rounds", "0"]);
    assert!(rounds.contains("--rounds must be 1 to 50"), "{rounds}");
    for text in [missing, absent, rounds] {
        assert!(!text.contains("panicked"), "{text}");
    }
}

/// `optimize --x0` is not checked as a task file's start is (a user may solve from any state), but a
/// start past a joint's limit or with bodies inside each other is said, as `simulate` says it, and the
/// summary of a start 1e300 past the finger's limit reads in exponents, not a hundred digits.
#[test]
fn optimize_from_a_start_that_breaks_a_constraint_says_so() {
    let out = xtask()
        .args([
            "optimize",
            "--quiet",
            "--iterations",
            "3",
            "--x0=1e300,0,0,0,0,0",
        ])
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(
        stderr.contains(
            "warning: --x0 starts with link1.angle above its upper limit by 1.000e300; the first steps undo it"
        ),
        "{stderr}"
    );
    let summary = stdout
        .lines()
        .find(|l| l.starts_with("over the horizon:"))
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(summary.len() < 120, "{summary}");
    // From the task's own start, no warning.
    let out = xtask()
        .args(["optimize", "--quiet", "--iterations", "3"])
        .output()
        .unwrap();
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("warning"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Refusals name what the user can change: a pass limit of 0 is out of `--iterations`' range, and a
/// time step too long for the scene's drag names the longest that is not, without a flag of another command.
#[test]
fn refusals_name_the_flags_range_and_a_time_step_that_works() {
    let out = xtask()
        .args(["optimize", "--iterations", "0"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("0 is not in 1..=100000"),
        "{stderr}"
    );
    let out = xtask().args(["optimize", "--h", "2"]).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("take a time step below 5.812e-1"),
        "{stderr}"
    );
    assert!(!stderr.contains("--drag"), "{stderr}");
}

/// A progress task's solve that turns its object the wrong way is explored from random starts, and
/// `optimize` says so: above an ellipse of 0.9 by 0.35 the finger's solve from zero controls turned it
/// back (-0.52 rad); the finger's own solve advances and is left as it is.
#[test]
fn optimize_explores_a_solve_that_turns_the_wrong_way() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenes/finger.toml"
    ))
    .unwrap();
    let (dir, path) = scene_file(
        "explore",
        "long.toml",
        &text.replacen("semi_axes = [0.7, 0.5]", "semi_axes = [0.9, 0.35]", 1),
    );
    let stdout = optimize_ok(&["--quiet"], &path);
    assert!(
        stdout.contains("explored: the solve (cost 20.311404) advances less than 0.3")
            && stdout.contains("the cheapest that does not stall is kept"),
        "{stdout}"
    );
    let turned: f64 = stdout
        .split("ellipse.angle 0.0000 -> ")
        .nth(1)
        .and_then(|rest| rest.split(';').next())
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(turned > 1.0, "{stdout}");
    let (finger_dir, finger) = scene_file("explore-finger", "finger.toml", &text);
    assert!(!optimize_ok(&["--quiet"], &finger).contains("explored"));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::remove_dir_all(&finger_dir).ok();
}

/// A solve that stops without converging is continued under the other regularisation, and `optimize`
/// says so: the three-link finger turning its ellipse to 1.0 (tests/data/three_link_turn.toml) crawls for
/// 300 passes under the state regularisation (cost 340.7) and the control regularisation continues it to
/// a converged 175.2; the finger's solve converges and is left as it is.
#[test]
fn optimize_continues_a_crawling_solve_under_the_other_regularisation() {
    let path = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/data/three_link_turn.toml"
    ));
    let stdout = optimize_ok(&["--quiet"], path);
    assert!(
        stdout.contains("continued under the control regularisation (Q_uu + mu I)")
            && stdout.contains("cheaper: kept"),
        "{stdout}"
    );
    let cost: f64 = stdout
        .split("(full): ")
        .nth(1)
        .and_then(|rest| rest.split(", cost ").nth(1))
        .and_then(|rest| rest.split(',').next())
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(cost < 250.0, "{stdout}");
    let finger = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenes/finger.toml"
    ))
    .unwrap();
    let (finger_dir, finger) = scene_file("regularisation-finger", "finger.toml", &finger);
    assert!(!optimize_ok(&["--quiet"], &finger).contains("continued under"));
    std::fs::remove_dir_all(&finger_dir).ok();
}

/// Issue 28: `train` says which angles its policy compares modulo a turn (the slider's block, a half
/// turn), and says nothing of the kind where there are none (the finger's ellipse is its task's own
/// periodic coordinate).
#[test]
fn train_names_the_angles_its_policy_compares_modulo_a_turn() {
    let dir = std::env::temp_dir().join(format!("xtask-turns-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let slider = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/slider_push.toml");
    let line = "its policy compares block.angle modulo a half turn";
    for (args, expected) in [
        (vec!["--scene", slider, "--task", "push"], true),
        (vec![], false),
    ] {
        let out = xtask()
            .arg("train")
            .args(&args)
            .args(["--trajectories", "6", "--growth", "0", "--out"])
            .arg(dir.join("turns.lib"))
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(stdout.contains(line), expected, "{stdout}");
        assert_eq!(stdout.contains("its policy compares"), expected, "{stdout}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
