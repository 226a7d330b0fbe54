//! Steady state allocates nothing (issue 29): a counting global allocator (allocation-counter, counting
//! on the calling thread) around the calls that run every step of a rollout, once the data they fill
//! has been sized by a first pass over the same work.

use dynamics::{Complementarity, Model, StepData, StepSettings};
use task::ProblemFile;

/// The task's start and `steps` controls that swing the actuators both ways (so that contacts open and
/// close along the way), on the task's model or on hard contact.
fn rollout_of(
    file: &str,
    task: &str,
    steps: usize,
    hard: bool,
) -> (Model, Vec<f64>, Vec<Vec<f64>>) {
    let problem = ProblemFile::from_toml_str(file).expect("a scene file of the repository");
    let task = problem.task(Some(task)).expect("its task");
    let model = Model::new(
        problem.scene.clone(),
        StepSettings {
            model: if hard {
                Complementarity::Hard
            } else {
                task.model.complementarity()
            },
            h: task.h,
            ..StepSettings::default()
        },
    )
    .expect("the task's model");
    let m = problem.scene.n_controls;
    let controls = (0..steps)
        .map(|k| {
            (0..m)
                .map(|a| 0.8 * ((0.21 * k as f64) + a as f64).sin())
                .collect()
        })
        .collect();
    (model, task.x0.clone(), controls)
}

/// Roll `controls` out from `x0` with `model` in `data`; the final state.
fn roll(model: &Model, data: &mut StepData, x0: &[f64], controls: &[Vec<f64>], x: &mut Vec<f64>) {
    x.clear();
    x.extend_from_slice(x0);
    for u in controls {
        let step = model.step(data, x, u).expect("a step of the rollout");
        x.copy_from_slice(&step.x_next);
    }
}

/// A rollout's steps, after a first rollout sized the data, allocate nothing: the step's ingredients
/// (kinematics, mass matrix, forces, rows, the mixed LCP), the solve's iterate and NCP functions (or
/// Lemke's workspace), the position correction and the step it returns are all refilled in place.
fn steps_allocate_nothing(file: &str, task: &str, hard: bool) {
    let (model, x0, controls) = rollout_of(file, task, 200, hard);
    let mut data = model.create_data();
    let mut x = Vec::with_capacity(x0.len());
    roll(&model, &mut data, &x0, &controls, &mut x);
    let first = x.clone();
    // The same rollout again, from the last one's warm starts: the same buffers suffice.
    let info = allocation_counter::measure(|| roll(&model, &mut data, &x0, &controls, &mut x));
    assert_eq!(
        info.count_total, 0,
        "{task} (hard: {hard}): {} allocations ({} bytes) over 200 steps",
        info.count_total, info.bytes_total
    );
    // It did the work: the state moved, and the same rollout gives the same end to solver tolerance.
    assert!(x.iter().zip(&x0).any(|(a, b)| (a - b).abs() > 1e-3));
    for (a, b) in x.iter().zip(&first) {
        assert!((a - b).abs() < 1e-6, "{a} against {b}");
    }
}

#[test]
fn the_counter_counts_this_thread_s_allocations() {
    let info = allocation_counter::measure(|| {
        std::hint::black_box(vec![0.0f64; 8]);
    });
    assert_eq!(info.count_total, 1);
}

#[test]
fn a_finger_step_allocates_nothing_in_steady_state() {
    for hard in [false, true] {
        steps_allocate_nothing(include_str!("../../scenes/finger.toml"), "spin", hard);
    }
}

#[test]
fn a_pushing_step_allocates_nothing_in_steady_state() {
    for hard in [false, true] {
        steps_allocate_nothing(include_str!("../../scenes/pushing.toml"), "push", hard);
    }
}

/// An optimiser of `passes` passes by `method` with a cost tolerance no pass meets: every solve runs
/// its whole pass budget.
fn exhausting(passes: usize, method: ddp::Method) -> ddp::Ddp {
    ddp::Ddp::new(ddp::DdpSettings {
        max_iterations: passes,
        tol_cost: 1e-300,
        method,
        ..ddp::DdpSettings::default()
    })
    .expect("settings")
}

/// The optimiser's own passes allocate nothing: on the unicycle, whose dynamics and cost allocate
/// nothing, a solve of nine passes allocates exactly what one of three does (the workspace, the
/// solution), for full DDP and for iLQR alike.
#[test]
fn an_optimiser_pass_allocates_nothing_of_its_own() {
    use ddp::Method;
    use ddp::problems::Unicycle;
    for method in [Method::Full, Method::GaussNewton] {
        let solve = |passes: usize| {
            let ddp = exhausting(passes, method);
            let (x0, zero) = (Unicycle::X0.to_vec(), vec![vec![0.0; 2]; 75]);
            let mut ran = 0;
            let info = allocation_counter::measure(|| {
                let cost = Unicycle::benchmark_cost();
                let s = ddp.solve(&Unicycle { dt: 0.1 }, &cost, &x0, &zero);
                ran = s.expect("the unicycle solves").iterations.len();
            });
            (info.count_total, ran)
        };
        let ((three, ran3), (nine, ran9)) = (solve(3), solve(9));
        assert_eq!((ran3, ran9), (3, 9), "{method:?}");
        assert_eq!(
            three, nine,
            "{method:?}: {three} allocations in 3 passes, {nine} in 9"
        );
    }
}

/// A solve of a scene file's task, by full second-order DDP and by iLQR, allocates in all what a solve of
/// the same problem with fewer passes allocates (the workspace, the knots' data sized by the first pass,
/// the solution; the thread's working vectors of the derivatives are sized by an earlier solve): every
/// later pass (the knots' steps, their first and second derivatives and the
/// contractions of the backward passes, the line search's trial steps) allocates nothing.
fn passes_allocate_nothing(file: &str, task: &str) {
    use ddp::Method;
    use task::SceneDynamics;
    let problem = ProblemFile::from_toml_str(file).expect("a scene file of the repository");
    let task = problem.task(Some(task)).expect("its task");
    let model = Model::new(
        problem.scene.clone(),
        StepSettings {
            model: task.model.complementarity(),
            h: task.h,
            ..StepSettings::default()
        },
    )
    .expect("the task's model");
    let dynamics = SceneDynamics::from_model(model);
    let zero = vec![vec![0.0; problem.scene.n_controls]; task.horizon];
    let solve = |passes: usize, method: Method| {
        let ddp = exhausting(passes, method);
        let mut ran = 0;
        let info = allocation_counter::measure(|| {
            let s = ddp.solve(&dynamics, &task.cost, &task.x0, &zero);
            ran = s.expect("the task solves").iterations.len();
        });
        (info.count_total, ran)
    };
    for method in [Method::Full, Method::GaussNewton] {
        // The derivative stages' working vectors are the thread's, sized by its first solve.
        solve(1, method);
        let ((few, ran_few), (many, ran_many)) = (solve(3, method), solve(20, method));
        assert_eq!((ran_few, ran_many), (3, 20), "{} {method:?}", task.name);
        assert!(few > 0, "the first pass sizes the knots' data");
        assert_eq!(
            few, many,
            "{} {method:?}: {few} allocations in 3 passes, {many} in 20",
            task.name
        );
    }
}

#[test]
fn a_finger_optimiser_pass_allocates_nothing_in_steady_state() {
    passes_allocate_nothing(include_str!("../../scenes/finger.toml"), "spin");
}

#[test]
fn a_pushing_optimiser_pass_allocates_nothing_in_steady_state() {
    passes_allocate_nothing(include_str!("../../scenes/pushing.toml"), "push");
}
