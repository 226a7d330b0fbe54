//! The simulator section of `cargo xtask benchmarks`: step time per model, exact derivatives against
//! finite differences, and the error that each knob (time step, sigma, solver tolerance) buys.

use dynamics::{Complementarity, Scene, Simulator, StepSettings};
use ncp::NewtonSettings;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

/// The finger apart, at rest: the built-in scene file's task start (SCENE.md's x0).
fn x0() -> Vec<f64> {
    task::ProblemFile::builtin_task().1.x0
}

/// SCENE.md's flicking finger: the built-in scene file's scene.
fn finger() -> Scene {
    task::ProblemFile::builtin().scene
}
const U: [f64; 2] = [0.3, -0.2];

fn sim(model: Complementarity, h: f64) -> Simulator {
    Simulator::new(
        finger(),
        StepSettings {
            model,
            h,
            ..StepSettings::default()
        },
    )
    .expect("valid")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Trajectory from [`x0`] under U for `seconds`; returns the states.
fn trajectory(sim: &mut Simulator, seconds: f64) -> Vec<Vec<f64>> {
    let h = sim.settings().h;
    let steps = (seconds / h).round() as usize;
    let mut x = x0();
    let mut out = vec![x.clone()];
    for _ in 0..steps {
        x = sim.step(&x, &U).expect("step").x_next;
        out.push(x.clone());
    }
    out
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

/// Median nanoseconds per call of `f` over 7 batches of `reps`.
fn time_ns(reps: usize, mut f: impl FnMut()) -> f64 {
    median(
        (0..7)
            .map(|_| {
                let t = Instant::now();
                for _ in 0..reps {
                    f();
                }
                t.elapsed().as_nanos() as f64 / reps as f64
            })
            .collect(),
    )
}

pub fn section(reference_dir: &Path) -> anyhow::Result<String> {
    let mut out = String::new();
    // Contact states along the default trajectory.
    let states: Vec<Vec<f64>> = {
        let mut s = sim(Complementarity::Logistic { sigma: 0.1 }, 0.05);
        let traj = trajectory(&mut s, 3.75);
        traj.into_iter()
            .filter(|x| {
                s.step(x, &U)
                    .map(|st| st.contacts[0].distance < 0.05)
                    .unwrap_or(false)
            })
            .collect()
    };
    out.push_str(&format!(
        "Step time: median over the {} in-contact states of the default trajectory (x0 of SCENE.md, u = [0.3, -0.2], h = 0.05), warm-started from the previous call.\n\n| model | step (ns) | step + exact fx, fu (ns) | + Hessian of c^T f (ns) | + forward differences (ns) | + central differences (ns) |\n|---|---:|---:|---:|---:|---:|\n",
        states.len()
    ));
    // The logistic model's step and step with exact derivatives, for the comparison with MuJoCo.
    let mut logistic = None;
    for (name, model) in [
        ("hard (Lemke)", Complementarity::Hard),
        (
            "logistic, sigma = 0.1",
            Complementarity::Logistic { sigma: 0.1 },
        ),
        (
            "normal (ERM), sigma = 0.1",
            Complementarity::Normal { sigma: 0.1 },
        ),
    ] {
        let mut s = sim(model, 0.05);
        let mut k = 0;
        let c = [0.3, -0.7, 1.0, 0.2, -0.1, 0.5];
        let [step, exact, hessian] = derivative_times(&mut s, &states, &U, &c, &mut k);
        let differences = |central: bool, s: &mut Simulator, k: &mut usize| {
            time_ns(200, || {
                *k += 1;
                let x = &states[*k % states.len()];
                let mut acc = s.step(x, &U).unwrap().x_next[0];
                for j in 0..8 {
                    for sign in if central {
                        &[1.0, -1.0][..]
                    } else {
                        &[1.0][..]
                    } {
                        let (mut xp, mut up) = (x.clone(), U);
                        if j < 6 {
                            xp[j] += sign * 1e-6
                        } else {
                            up[j - 6] += sign * 1e-6
                        }
                        acc += s.step(&xp, &up).unwrap().x_next[0];
                    }
                }
                black_box(acc);
            })
        };
        let forward = differences(false, &mut s, &mut k);
        let central = differences(true, &mut s, &mut k);
        out.push_str(&format!(
            "| {name} | {step:.0} | {exact:.0} | {hessian:.0} | {forward:.0} | {central:.0} |\n"
        ));
        if matches!(model, Complementarity::Logistic { .. }) {
            logistic = Some((step, exact));
        }
    }
    out.push_str(&mujoco_rows(logistic));

    // Scenes beyond the finger: the derivatives of any size.
    out.push_str(&scenes_table(&states)?);

    // Exact derivatives against central differences, both against the reference.
    let text = std::fs::read_to_string(reference_dir.join("finger_steps.json"))?;
    let data: serde_json::Value = serde_json::from_str(&text)?;
    let (mut exact_err, mut fd_err) = (0.0f64, 0.0f64);
    for case in data["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["model"] == "logistic")
    {
        let v = |k: &str| -> Vec<f64> {
            case[k]
                .as_array()
                .unwrap()
                .iter()
                .map(|e| e.as_f64().unwrap())
                .collect()
        };
        let fx: Vec<f64> = case["fx"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|r| r.as_array().unwrap().iter().map(|e| e.as_f64().unwrap()))
            .collect();
        let scale = fx.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        let model = Complementarity::Logistic {
            sigma: case["sigma"].as_f64().unwrap(),
        };
        // The reference answers are SCENE.md's step: penetration recovered at the velocity level.
        let mut s = Simulator::new(
            finger(),
            StepSettings {
                model,
                h: case["h"].as_f64().unwrap(),
                recovery: None,
                ..StepSettings::default()
            },
        )?;
        let (x, u) = (v("x"), v("u"));
        let (_, der) = s.step_with_derivatives(&x, &u)?;
        exact_err = exact_err.max(max_diff(&der.fx, &fx) / scale);
        for j in 0..6 {
            let mut xp = x.clone();
            let mut xm = x.clone();
            xp[j] += 1e-6;
            xm[j] -= 1e-6;
            s.reset_warm_start();
            let p = s.step(&xp, &u)?.x_next;
            s.reset_warm_start();
            let m = s.step(&xm, &u)?.x_next;
            for i in 0..6 {
                fd_err = fd_err.max(((p[i] - m[i]) / 2e-6 - fx[i * 6 + j]).abs() / scale);
            }
        }
    }
    out.push_str(
        "\nThe Hessian column is one step, its first derivatives and the 8 x 8 Hessian of c^T f (second-order adjoint) for c = [0.3, -0.7, 1, 0.2, -0.1, 0.5].\n",
    );
    out.push_str(&format!(
        "\nDerivative error against the reference `fx` of the 10 logistic cases (tests/data/finger_steps.json), relative to the largest entry: exact (implicit function theorem) {exact_err:.1e}; central differences with step 1e-6 {fd_err:.1e} (the README's tolerance is 1e-7).\n"
    ));

    // Time step against trajectory error. The smoothed models have no common limit as h -> 0: the noise acts
    // on b = d/h + J v', so the smoothing's force law depends on h (with sigma fixed it tends to a hard wall
    // of width sigma h). The hard model is the one whose trajectories converge; the logistic column shows the
    // h-dependence of the smoothed model at the paper's sigma.
    out.push_str("\nTime step against trajectory error: 1.5 s from x0 under u = [0.3, -0.2]; error of the state at 1.5 s against h = 1e-4 with the same model. Only the hard model has a limit as h -> 0 (first order here); the smoothed models' noise acts on b = d/h + J v', so their force law itself changes with h (docs/complementarity.md), and the logistic column measures that model change, not a discretisation error.\n\n| h | hard: error at 1.5 s | hard: us per simulated second | logistic, sigma = 0.1: change vs h = 1e-4 | logistic: us per simulated second |\n|---:|---:|---:|---:|---:|\n");
    let logistic = |_h: f64| Complementarity::Logistic { sigma: 0.1 };
    let hard_end = trajectory(&mut sim(Complementarity::Hard, 1e-4), 1.5)
        .pop()
        .unwrap();
    let smooth_end = trajectory(&mut sim(logistic(1e-4), 1e-4), 1.5)
        .pop()
        .unwrap();
    for h in [0.05, 0.02, 0.01, 0.005, 0.002, 0.001] {
        let mut row = format!("| {h} |");
        for (model, reference) in [
            (Complementarity::Hard, &hard_end),
            (logistic(h), &smooth_end),
        ] {
            let mut s = sim(model, h);
            let t = Instant::now();
            let end = trajectory(&mut s, 1.5).pop().unwrap();
            let per_second = t.elapsed().as_secs_f64() / 1.5 * 1e6;
            row.push_str(&format!(
                " {:.1e} | {per_second:.0} |",
                max_diff(&end, reference)
            ));
        }
        out.push_str(&row);
        out.push('\n');
    }

    // Sigma against the distance from the hard trajectory.
    out.push_str("\nSigma against the distance from the hard trajectory: 75 steps at h = 0.05 from x0 under u = [0.3, -0.2] (the reference rollout's inputs); largest state difference along the way.\n\n| sigma | logistic: gap to hard | logistic ns/step | normal (ERM): gap to hard | normal ns/step |\n|---:|---:|---:|---:|---:|\n");
    let hard = trajectory(&mut sim(Complementarity::Hard, 0.05), 3.75);
    for sigma in [1.0, 0.3, 0.1, 0.03, 0.01, 1e-3] {
        let mut row = format!("| {sigma} |");
        for model in [
            Complementarity::Logistic { sigma },
            Complementarity::Normal { sigma },
        ] {
            let mut s = sim(model, 0.05);
            let t = Instant::now();
            let traj = trajectory(&mut s, 3.75);
            let ns = t.elapsed().as_nanos() as f64 / 75.0;
            let gap = traj
                .iter()
                .zip(&hard)
                .fold(0.0f64, |m, (a, b)| m.max(max_diff(a, b)));
            row.push_str(&format!(" {gap:.1e} | {ns:.0} |"));
        }
        out.push_str(&row);
        out.push('\n');
    }

    // Solver tolerance against time and error.
    out.push_str("\nNewton tolerance against time and error: logistic, sigma = 0.1, the same 75 steps; error against the trajectory at tolerance 1e-14.\n\n| tolerance | ns/step | trajectory error |\n|---:|---:|---:|\n");
    let run = |tol: f64| {
        let settings = StepSettings {
            newton: NewtonSettings {
                tol,
                ..NewtonSettings::default()
            },
            ..StepSettings::default()
        };
        let mut s = Simulator::new(finger(), settings).unwrap();
        let t = Instant::now();
        let traj = trajectory(&mut s, 3.75);
        (traj, t.elapsed().as_nanos() as f64 / 75.0)
    };
    let (best, _) = run(1e-14);
    for tol in [1e-4, 1e-6, 1e-9, 1e-12, 1e-13] {
        let (traj, ns) = run(tol);
        let err = traj
            .iter()
            .zip(&best)
            .fold(0.0f64, |m, (a, b)| m.max(max_diff(a, b)));
        out.push_str(&format!("| {tol:.0e} | {ns:.0} | {err:.1e} |\n"));
    }
    Ok(out)
}

/// MuJoCo on the same finger in the same run (`xtask/scripts/mujoco_finger.py`, with the Python of
/// `SLCP_PYTHON`, default `python3`): a row of the step table and the ratios to the logistic model's
/// `(step, step + exact fx, fu)`; a line saying why not when MuJoCo is not importable.
fn mujoco_rows(logistic: Option<(f64, f64)>) -> String {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/mujoco_finger.py");
    let line = match super::run_python(script, &["21"]) {
        Ok(line) => line,
        Err((python, why)) => {
            return format!(
                "\nMuJoCo not run ({python}: {why}; `pip install mujoco` and set SLCP_PYTHON to compare in the same run).\n"
            );
        }
    };
    let Ok(v) = serde_json::from_str::<serde_json::Value>(line.trim()) else {
        return format!("\nMuJoCo's script printed no result ({}).\n", line.trim());
    };
    let (Some(version), Some(states), Some(step), Some(forward), Some(central), Some(call)) = (
        v["version"].as_str(),
        v["states"].as_u64(),
        v["step_ns"].as_f64(),
        v["step_fd_forward_ns"].as_f64(),
        v["step_fd_central_ns"].as_f64(),
        v["python_call_ns"].as_f64(),
    ) else {
        return format!("\nMuJoCo's script printed no result ({}).\n", line.trim());
    };
    let mut out = format!(
        "| MuJoCo {version} (soft contact; derivatives by `mjd_transitionFD`, eps 1e-6; median over the {states} in-contact states of its own rollout) | {step:.0} | - | - | {forward:.0} | {central:.0} |\n"
    );
    out.push_str(&format!(
        "\nThe MuJoCo row is the same finger in MuJoCo, in the same run (`xtask/scripts/mujoco_finger.py`: ellipsoids in the plane, hinges about z with the file's limits and damping, SCENE.md's masses and moments of inertia, friction 0.5, h = 0.05, its default Euler integrator and soft contact): its step timed in C over the batch of states (`mujoco.rollout`), its derivatives of the transition (A = dx'/dx, B = dx'/du, each with the step) by one Python call per state, whose own overhead is about {call:.0} ns (included)."
    ));
    if let Some((our_step, our_exact)) = logistic {
        out.push_str(&format!(
            " Against it, the logistic step takes {:.2} of MuJoCo's step's time ({:.1}x as fast), and the logistic step with its exact fx, fu {:.2} of MuJoCo's step with forward differences ({:.1}x as fast; {:.1}x against its central differences).",
            our_step / step,
            step / our_step,
            our_exact / forward,
            forward / our_exact,
            central / our_exact,
        ));
    }
    out.push('\n');
    out
}

/// Median ns of a step, a step with exact `fx`, `fu`, and a step with those and the Hessian of `c^T f`,
/// cycling through `states` under `u` (`k` counts the calls, so a caller's later timings go on cycling).
fn derivative_times(
    s: &mut Simulator,
    states: &[Vec<f64>],
    u: &[f64],
    c: &[f64],
    k: &mut usize,
) -> [f64; 3] {
    let mut next = || {
        *k += 1;
        &states[*k % states.len()]
    };
    let step = time_ns(2000, || {
        black_box(s.step(next(), u).unwrap());
    });
    let exact = time_ns(1000, || {
        black_box(s.step_with_derivatives(next(), u).unwrap());
    });
    let hessian = time_ns(300, || {
        black_box(s.step_with_hessian(next(), u, c).unwrap());
    });
    [step, exact, hessian]
}

/// A scene, its states and control.
type Case = (&'static str, Scene, Vec<Vec<f64>>, Vec<f64>);

/// Step, first and second derivatives on scenes of 3, 4 and 5 joints (logistic, sigma = 0.1, h = 0.05),
/// median over states in contact.
fn scenes_table(finger_states: &[Vec<f64>]) -> anyhow::Result<String> {
    let mut out = String::from(
        "\nScenes of any size (logistic, sigma = 0.1, h = 0.05; median over 8 states with a link on the ellipse (pushing: on the block), warm-started; the Hessian of c^T f over (x, u) for a fixed c): the scene files under scenes/.\n\n| scene | coordinates / controls / rows | step (ns) | step + exact fx, fu (ns) | + Hessian of c^T f (ns) |\n|---|---:|---:|---:|---:|\n",
    );
    let three = Scene::from_toml_str(include_str!("../../../scenes/three_link_finger.toml"))?;
    let two = Scene::from_toml_str(include_str!("../../../scenes/two_fingers.toml"))?;
    let at = |f: &dyn Fn(f64) -> Vec<f64>| (0..8).map(|i| f(i as f64 * 0.4)).collect::<Vec<_>>();
    let pushing = Scene::from_toml_str(include_str!("../../../scenes/pushing.toml"))?;
    // Pushing: states of its task's optimal trajectory, the finger on the block, the block on the ground.
    let pushed = [
        [
            -0.674, -0.285, 0.293, 0.241, -0.002, -0.521, 0.921, 1.318, -0.062, -0.432,
        ],
        [
            -0.775, -0.039, 0.566, 0.226, -0.304, -0.303, 0.732, 0.599, 0.027, -0.919,
        ],
        [
            -0.876, 0.185, 0.654, 0.229, -0.405, -0.345, 0.735, 0.113, -0.013, 0.054,
        ],
        [
            -0.979, 0.392, 0.646, 0.218, -0.275, -0.341, 0.655, -0.092, -0.043, 0.62,
        ],
    ];
    let cases: [Case; 4] = [
        (
            "finger (finger.toml)",
            finger(),
            finger_states.iter().take(8).cloned().collect(),
            U.to_vec(),
        ),
        (
            "three-link finger (three_link_finger.toml)",
            three,
            at(&|t| vec![-1.2, -0.6, -0.8 + 0.1 * t.sin(), t, 0.5, -1.0, 1.5, 0.2]),
            vec![0.2, -0.3, 0.1],
        ),
        (
            "two fingers (two_fingers.toml)",
            two,
            // Both fingers reaching over the ellipse, within about 0.05 of it.
            at(&|t| vec![0.6, -1.65, 2.54, 1.65, t, 0.3, -0.4, 0.2, 0.1, 1.0]),
            vec![0.2, -0.3, 0.1, 0.4],
        ),
        (
            "pushing (pushing.toml: a free body, ground)",
            pushing,
            pushed.iter().cycle().take(8).map(|x| x.to_vec()).collect(),
            vec![0.2, -0.3],
        ),
    ];
    for (name, scene, states, u) in cases {
        let (n, nu, rows) = (scene.n_dof(), scene.n_controls, scene.n_constraints());
        let mut s = Simulator::new(
            scene,
            StepSettings {
                model: Complementarity::Logistic { sigma: 0.1 },
                ..StepSettings::default()
            },
        )?;
        let c: Vec<f64> = (0..2 * n).map(|i| 0.3 - 0.1 * i as f64).collect();
        let [step, exact, hessian] = derivative_times(&mut s, &states, &u, &c, &mut 0);
        out.push_str(&format!(
            "| {name} | {n} / {nu} / {rows} | {step:.0} | {exact:.0} | {hessian:.0} |\n"
        ));
    }
    Ok(out)
}
