//! Issue 27: inputs a hostile user can send get a typed error that names the problem, never a panic, a
//! hang or a silent NaN.

use crate::dynamics_world::PENDULUM;
use dynamics::{DynamicsError, Scene};

fn problems(text: &str) -> Vec<(String, String)> {
    match Scene::from_toml_str(text) {
        Err(DynamicsError::Scene(problems)) => {
            problems.into_iter().map(|p| (p.field, p.problem)).collect()
        }
        other => panic!("expected a refused scene, got {other:?}"),
    }
}

/// A scene of `count` free ellipses in a row, under gravity, actuated or not, and no contact.
fn free_bodies(count: usize, semi_axes: [f64; 2], actuated: bool) -> String {
    let mut text = String::from("gravity = [0.0, -1.0]\n");
    for i in 0..count {
        text.push_str(&format!(
            "[[body]]\nname = \"b{i}\"\nsemi_axes = [{}, {}]\nparent = \"world\"\nanchor = [{i}.0, 0.0]\ncentre = [0.0, 0.0]\njoint = {{ type = \"free\", actuated = {actuated} }}\n",
            semi_axes[0], semi_axes[1]
        ));
    }
    text
}

#[test]
fn magnitudes_past_the_scene_limits_are_refused_by_field() {
    // friction = 1e200 was accepted as finite and made Lemke's method panic in every command.
    let cases = [
        ("friction = 0.6", "friction = 1e200", "contact[0].friction"),
        (
            "anchor = [1.2, 0.0]",
            "anchor = [1e200, 0.0]",
            "body[1].anchor",
        ),
        (
            "centre = [-1.3, -0.4]",
            "centre = [1e9, -0.4]",
            "fixed[0].centre",
        ),
        (
            "point = [0.0, -1.8]",
            "point = [0.0, -1e300]",
            "plane[0].point",
        ),
        (
            "gravity = [0.0, -9.81]",
            "gravity = [0.0, -1e30]",
            "gravity",
        ),
    ];
    for (from, to, field) in cases {
        assert!(PENDULUM.contains(from), "{from}");
        let found = problems(&PENDULUM.replacen(from, to, 1));
        assert!(
            found.iter().any(|(f, _)| f == field),
            "{to}: {field} not in {found:?}"
        );
    }
}

#[test]
fn a_contact_pair_listed_twice_is_refused_either_way_round() {
    let twice = format!("{PENDULUM}\n[[contact]]\na = \"lower\"\nb = \"ground\"\nfriction = 0.2\n");
    let found = problems(&twice);
    assert!(
        found
            .iter()
            .any(|(f, p)| f == "contact[3].b" && p.contains("already contact[0]")),
        "{found:?}"
    );
}

#[test]
fn a_malformed_item_is_named_by_its_index() {
    let text = PENDULUM.replacen("name = \"lower\"\n", "", 1);
    let Err(DynamicsError::Parse(message)) = Scene::from_toml_str(&text) else {
        panic!("accepted")
    };
    assert!(
        message.starts_with("body[1]:") && message.contains("name"),
        "{message}"
    );
}

#[test]
fn a_scene_past_the_body_limit_is_refused_with_the_limit() {
    let text = free_bodies(dynamics::MAX_BODIES + 1, [0.1, 0.1], false);
    let found = problems(&text);
    assert!(
        found
            .iter()
            .any(|(f, p)| f == "body" && p.contains("MAX_BODIES")),
        "{found:?}"
    );
}

/// A library header around `body` with its true length and checksum.
fn library_file(body: &[u8]) -> Vec<u8> {
    let mut out = library::MAGIC.to_vec();
    out.extend_from_slice(&library::VERSION.to_le_bytes());
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(&crc32fast_hash(body).to_le_bytes());
    out.extend_from_slice(body);
    out
}

/// CRC-32 (IEEE), as the library header carries it.
fn crc32fast_hash(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// Issue 27: a payload whose first length prefix claimed 2^62 bytes, with a recomputed checksum, aborted
/// the process (and Python's interpreter) on the allocation. Every prefix is now claimed against a limit
/// of at most twice the file's size before anything is allocated.
#[test]
fn a_crafted_length_prefix_is_refused_without_allocating_it() {
    for claim in [1u64 << 62, 1 << 40, 1 << 31, u64::MAX] {
        // bincode's varint: 253 then the u64 little-endian; then a few bytes of "string".
        let mut body = vec![253u8];
        body.extend_from_slice(&claim.to_le_bytes());
        body.extend_from_slice(b"gravity = ");
        let err = library::Library::from_bytes(&library_file(&body)).unwrap_err();
        assert!(
            matches!(err, library::LibraryError::Invalid(_)),
            "{claim}: {err}"
        );
    }
}

#[test]
fn a_library_used_with_another_scene_says_what_differs() {
    let lib = crate::support::paper_library();
    let mut spec = task::ProblemFile::builtin().scene.spec().clone();
    spec.bodies[1].joint.damping = 0.7;
    let other = dynamics::Scene::new(spec).unwrap();
    let err = lib.check_scene(&other).unwrap_err().to_string();
    assert!(
        err.contains("body[1].joint.damping") && err.contains("0.7"),
        "{err}"
    );
}

/// Every file a command writes is written whole or not at all: a reader never sees part of it, while a
/// writer replaces a large file again and again (with `std::fs::write`, which truncates first, the reader
/// sees short files).
#[test]
fn a_file_being_replaced_is_never_seen_in_part() {
    let dir = std::env::temp_dir().join(format!("slcp-atomic-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("out.json");
    let sizes = [1usize << 20, 3 << 20];
    library::write_atomically(&path, &vec![b'a'; sizes[0]]).unwrap();
    let done = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| {
            for k in 0..30 {
                let byte = if k % 2 == 0 { b'b' } else { b'a' };
                library::write_atomically(&path, &vec![byte; sizes[(k + 1) % 2]]).unwrap();
            }
            done.store(true, std::sync::atomic::Ordering::SeqCst);
        });
        let mut reads = 0;
        while !done.load(std::sync::atomic::Ordering::SeqCst) || reads < 10 {
            let bytes = std::fs::read(&path).unwrap();
            assert!(sizes.contains(&bytes.len()), "read {} bytes", bytes.len());
            reads += 1;
        }
    });
    let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert_eq!(left.len(), 1, "temporary files left behind");
    // A destination that is a directory is refused and left alone.
    assert!(library::write_atomically(&dir, b"x").is_err());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 27: a finger step under `u = [1e20, 0]` returned link 1 at -5.94 rad (limits [-pi, 0]) with the
/// status "converged". An answer that leaves a joint past its limit or a contact in penetration by more
/// than `STEP_TOLERANCE` is now `Violated`; every answer still called converged keeps the limits, for
/// states and controls up to 1e9 and beyond.
#[test]
fn a_converged_step_keeps_its_joint_limits_at_any_input_scale() {
    use dynamics::{Complementarity, Simulator, StepSettings};
    use rand::{Rng, SeedableRng};
    let scene = task::ProblemFile::builtin().scene;
    let n = scene.n_dof();
    let limits: Vec<Option<[f64; 2]>> = scene.coordinates.iter().map(|c| c.limits).collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(27);
    for model in [
        Complementarity::Hard,
        Complementarity::Logistic { sigma: 0.1 },
    ] {
        let mut sim = Simulator::new(
            scene.clone(),
            StepSettings {
                model,
                ..StepSettings::default()
            },
        )
        .unwrap();
        let x0 = task::ProblemFile::builtin_task().1.x0;
        let s = sim.step(&x0, &[1e20, 0.0]).unwrap();
        let [lo, hi] = limits[0].unwrap();
        assert!(
            s.info.status != ncp::Status::Converged
                || (s.x_next[0] >= lo - 1e-6 && s.x_next[0] <= hi + 1e-6),
            "{model:?}: link1 at {} reported converged",
            s.x_next[0]
        );
        let (mut converged, mut tried) = (0, 0);
        for _ in 0..150 {
            let scale = 10f64.powi(rng.random_range(0..=9));
            let mut x = x0.clone();
            for v in &mut x[n..] {
                *v = rng.random_range(-1.0..1.0) * scale;
            }
            let u = [
                rng.random_range(-1.0..1.0) * scale,
                rng.random_range(-1.0..1.0) * scale,
            ];
            sim.reset_warm_start();
            let Ok(s) = sim.step(&x, &u) else { continue };
            tried += 1;
            if s.info.status != ncp::Status::Converged {
                continue;
            }
            converged += 1;
            for (j, l) in limits.iter().enumerate() {
                if let Some([lo, hi]) = l {
                    let q = s.x_next[j];
                    assert!(
                        q >= lo - 2e-6 && q <= hi + 2e-6,
                        "{model:?}: joint {j} at {q} past [{lo}, {hi}] (scale {scale})"
                    );
                }
            }
        }
        assert!(
            tried > 100 && converged > 30,
            "{tried} tried, {converged} converged"
        );
    }
}

/// Issue 27: full DDP on a scene of many bodies asked for 195 GB and was killed. The solver now estimates
/// the second-order data it would keep before allocating and refuses with the estimate and the
/// alternative; Gauss-Newton (iLQR) runs the same problem.
#[test]
fn full_ddp_past_its_memory_limit_is_refused_with_the_estimate_and_ilqr_runs() {
    let scene = Scene::from_toml_str(&free_bodies(30, [0.1, 0.05], true)).unwrap();
    let (n, nu) = (scene.n_state(), scene.n_controls);
    let model = dynamics::Model::new(scene, dynamics::StepSettings::default()).unwrap();
    let per_knot = model.second_order_bytes();
    assert!(per_knot > 100 << 20, "{per_knot}");
    let dynamics = task::SceneDynamics::from_model(model);
    let cost = ddp::QuadraticCost::diagonal(&vec![1.0; n], &vec![0.1; nu], &vec![1.0; n]);
    let x0 = vec![0.0; n];
    let controls = vec![vec![0.0; nu]; 60];
    let full = ddp::Ddp::new(ddp::DdpSettings::default()).unwrap();
    let err = full.solve(&dynamics, &cost, &x0, &controls).unwrap_err();
    assert!(matches!(err, ddp::DdpError::TooLarge { .. }), "{err}");
    let message = err.to_string();
    assert!(
        message.contains("GB") && message.contains("--method ilqr"),
        "{message}"
    );
    let ilqr = ddp::Ddp::new(ddp::DdpSettings {
        method: ddp::Method::GaussNewton,
        max_iterations: 2,
        ..ddp::DdpSettings::default()
    })
    .unwrap();
    ilqr.solve(&dynamics, &cost, &x0, &controls).unwrap();
}

/// Issue 27: a task's `control_limits` with three entries said `invalid length 3` without the field.
#[test]
fn a_malformed_task_field_is_named() {
    let text = include_str!("../../scenes/pushing.toml").replacen(
        "control_weight = 0.05",
        "control_weight = 0.05\ncontrol_limits = [-1.0, 0.0, 1.0]",
        1,
    );
    let err = task::ProblemFile::from_toml_str(&text)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("control_limits") && err.contains("push"),
        "{err}"
    );
}

/// Issue 27: a scene with a 47 MB TOML array took 2.6 GB to parse. A scene text past
/// `MAX_SCENE_TEXT` is refused by its size, before parsing.
#[test]
fn an_oversized_scene_text_is_refused_before_parsing() {
    let numbers = vec!["0.0"; 400_000].join(", ");
    let text = format!("{PENDULUM}\nextra = [{numbers}]\n");
    assert!(text.len() > dynamics::MAX_SCENE_TEXT);
    let Err(DynamicsError::Parse(message)) = Scene::from_toml_str(&text) else {
        panic!("accepted")
    };
    assert!(message.contains("MAX_SCENE_TEXT"), "{message}");
}

/// The repository's scene files, for mutation.
const SCENE_FILES: [&str; 7] = [
    include_str!("../../scenes/finger.toml"),
    include_str!("../../scenes/mirrored_finger.toml"),
    include_str!("../../scenes/pushing.toml"),
    include_str!("../../scenes/roll_block.toml"),
    include_str!("../../scenes/slider_push.toml"),
    include_str!("../../scenes/two_fingers.toml"),
    include_str!("../data/paddle.toml"),
];

/// What a user may write where a file has a number: zero, signs, the extremes, the non-finite, another
/// type.
const REPLACEMENTS: [&str; 18] = [
    "0.0",
    "-0.0",
    "-1.0",
    "1e-12",
    "1e12",
    "1e300",
    "-1e300",
    "nan",
    "inf",
    "-inf",
    "3.5",
    "1000000000",
    "0",
    "-5",
    "\"x\"",
    "[]",
    "[1.0]",
    "true",
];

/// `text` with its `picks`-th numbers (counted over the lines that are not comments) replaced by the
/// chosen replacements.
fn mutated(text: &str, picks: &[(usize, usize)]) -> String {
    let number = |c: char| c.is_ascii_digit();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for &(pick, replacement) in picks {
        // Every maximal run of digits, dots, exponents and signs on a line that is not a comment.
        let mut spans = Vec::new();
        for (l, line) in lines.iter().enumerate() {
            if line.trim_start().starts_with('#') {
                continue;
            }
            let bytes = line.as_bytes();
            let mut i = 0;
            while i < bytes.len() {
                let starts = number(bytes[i] as char)
                    && (i == 0 || !(bytes[i - 1] as char).is_ascii_alphanumeric());
                if starts {
                    let mut j = i;
                    while j < bytes.len()
                        && (number(bytes[j] as char) || b".eE-+".contains(&bytes[j]))
                    {
                        j += 1;
                    }
                    let i0 = if i > 0 && bytes[i - 1] == b'-' {
                        i - 1
                    } else {
                        i
                    };
                    spans.push((l, i0, j));
                    i = j;
                } else {
                    i += 1;
                }
            }
        }
        if spans.is_empty() {
            break;
        }
        let (l, a, b) = spans[pick % spans.len()];
        let line = &lines[l];
        lines[l] = format!(
            "{}{}{}",
            &line[..a],
            REPLACEMENTS[replacement % REPLACEMENTS.len()],
            &line[b..]
        );
    }
    lines.join("\n")
}

/// Everything a scene file reaches without a library: its tasks, their start's check, twenty steps of
/// the simulator on the task's model from its start, and a three-pass solve. Errors are the file's
/// answer; only a panic or a non-finite success fails.
fn run_file(text: &str) -> Result<(), String> {
    let Ok(file) = task::ProblemFile::from_toml_str(text) else {
        return Ok(());
    };
    for name in file.tasks.keys() {
        let Ok(t) = file.task(Some(name)) else {
            continue;
        };
        let settings = dynamics::StepSettings {
            model: t.model.complementarity(),
            h: t.h,
            ..dynamics::StepSettings::default()
        };
        let Ok(mut sim) = dynamics::Simulator::new(file.scene.clone(), settings) else {
            continue;
        };
        let mut x = t.x0.clone();
        let u = vec![0.1; file.scene.n_controls];
        for _ in 0..20 {
            match sim.step(&x, &u) {
                Ok(step) if step.x_next.iter().all(|v| v.is_finite()) => x = step.x_next,
                Ok(step) => {
                    return Err(format!("task {name}: a non-finite step {:?}", step.x_next));
                }
                Err(_) => break,
            }
        }
        let Ok(sim) = dynamics::Simulator::new(file.scene.clone(), settings) else {
            continue;
        };
        let ddp = ddp::Ddp::new(ddp::DdpSettings {
            max_iterations: 3,
            control_limits: t.control_limits.clone(),
            ..ddp::DdpSettings::default()
        });
        let Ok(ddp) = ddp else { continue };
        let horizon = t.horizon.min(30);
        let zero = vec![vec![0.0; file.scene.n_controls]; horizon];
        if let Ok(sol) = ddp.solve(&task::SceneDynamics::new(sim), &t.cost, &t.x0, &zero)
            && !sol.cost.is_finite()
        {
            return Err(format!("task {name}: a solve returned cost {}", sol.cost));
        }
    }
    Ok(())
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
    /// Issue 28: nothing a user can write in a scene or task file panics. Any one or two numbers of the
    /// repository's scene files replaced by zero, a sign, an extreme, a non-finite value or another type
    /// give a typed error, or a scene whose steps and solve are finite.
    #[test]
    fn no_number_written_in_a_scene_file_panics(
        which in 0usize..SCENE_FILES.len(),
        picks in proptest::collection::vec((0usize..10_000, 0usize..REPLACEMENTS.len()), 1..3),
    ) {
        let text = mutated(SCENE_FILES[which], &picks);
        let outcome = std::panic::catch_unwind(|| run_file(&text));
        match outcome {
            Ok(Ok(())) => {}
            Ok(Err(problem)) => proptest::prop_assert!(false, "{problem}\n{text}"),
            Err(_) => proptest::prop_assert!(false, "a panic on\n{text}"),
        }
    }
}

#[test]
fn the_mutation_replaces_numbers_and_leaves_comments() {
    let text = "# 1.0 in a comment\nh = 0.05\nx0 = { \"a.angle\" = -0.5 }";
    assert_eq!(
        mutated(text, &[(0, 7)]),
        "# 1.0 in a comment\nh = nan\nx0 = { \"a.angle\" = -0.5 }"
    );
    assert_eq!(
        mutated(text, &[(1, 2)]),
        "# 1.0 in a comment\nh = 0.05\nx0 = { \"a.angle\" = -1.0 }"
    );
}
