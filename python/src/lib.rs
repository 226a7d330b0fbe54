//! `slcp`: the Python package over the crates. NumPy arrays in and out (float64; outputs are NumPy
//! arrays that own the vectors the crates computed, no copy), the scene and task files of the command
//! line, every error of the crates raised as `slcp.SlcpError` with the crate's message, and the GIL
//! released for the whole of any long computation (rollouts, optimisation, library builds, evaluations).

use ::library::{
    Evaluation, EvaluationSettings, Exploration, Library as RsLibrary, LibrarySettings,
    Policy as RsPolicy,
};
use ::task::{ContactModel, ProblemFile, SceneDynamics, Task};
use ddp::{Ddp, DdpSettings, Method};
use dynamics::{Scene, Simulator as RsSimulator, StepSettings};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArrayLike1, PyArrayLike2};
use pyo3::create_exception;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

create_exception!(
    slcp,
    SlcpError,
    pyo3::exceptions::PyValueError,
    "An error of the slcp crates (a bad scene, task or library file, a bad input such as a NaN state or an array of the wrong length, an impossible setting), with the crate's message."
);

fn error(e: impl std::fmt::Display) -> PyErr {
    SlcpError::new_err(e.to_string())
}

/// Run `f`, turning a panic below (a bug of the crates) into `SlcpError` naming it, so that Python sees
/// the package's one error type and the interpreter goes on.
fn shielded<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|payload| {
        let what = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".into());
        Err(error(format!(
            "internal error of the slcp crates (a bug; please report it with its input): {what}"
        )))
    })
}

/// A 1-D input as a vector, its length checked.
fn vector(
    a: &PyArrayLike1<'_, f64, AllowTypeChange>,
    what: &str,
    len: usize,
) -> PyResult<Vec<f64>> {
    let v: Vec<f64> = a.as_array().iter().copied().collect();
    if v.len() != len {
        return Err(error(format!(
            "{what} has {} entries, expected {len}",
            v.len()
        )));
    }
    Ok(v)
}

/// A 2-D input as rows, its column count checked.
fn rows(
    a: &PyArrayLike2<'_, f64, AllowTypeChange>,
    what: &str,
    cols: usize,
) -> PyResult<Vec<Vec<f64>>> {
    let view = a.as_array();
    if view.ncols() != cols {
        return Err(error(format!(
            "{what} has {} columns, expected {cols}",
            view.ncols()
        )));
    }
    Ok(view.rows().into_iter().map(|r| r.to_vec()).collect())
}

fn matrix<'py>(
    py: Python<'py>,
    v: Vec<f64>,
    r: usize,
    c: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    Ok(Array2::from_shape_vec((r, c), v)
        .map_err(error)?
        .into_pyarray(py))
}

fn stacked<'py>(
    py: Python<'py>,
    rows: Vec<Vec<f64>>,
    cols: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let n = rows.len();
    matrix(py, rows.into_iter().flatten().collect(), n, cols)
}

/// The contact model named `model` (`"logistic"`, `"normal"`, `"hard"`) at `sigma`.
fn model(model: &str, sigma: f64) -> PyResult<ContactModel> {
    match model {
        "logistic" => Ok(ContactModel::Logistic(sigma)),
        "normal" => Ok(ContactModel::Normal(sigma)),
        "hard" => Ok(ContactModel::Hard),
        other => Err(error(format!(
            "model \"{other}\" is not one of \"logistic\", \"normal\", \"hard\""
        ))),
    }
}

/// The contact model asked for: `model` at `sigma` (the task's own sigma when not given), or the task's
/// own model `own` with `sigma` replacing its noise scale. A sigma for the hard model is refused rather
/// than ignored.
fn contact_model(
    own: ContactModel,
    model: Option<&str>,
    sigma: Option<f64>,
) -> PyResult<ContactModel> {
    let own_sigma = match own {
        ContactModel::Logistic(s) | ContactModel::Normal(s) => s,
        ContactModel::Hard => 0.1,
    };
    match (model, own, sigma) {
        (Some("hard"), _, Some(s)) | (None, ContactModel::Hard, Some(s)) => Err(error(format!(
            "sigma {s} given for the hard model, which has no noise scale (pass model=\"logistic\" or \"normal\")"
        ))),
        (Some(name), _, s) => self::model(name, s.unwrap_or(own_sigma)),
        (None, ContactModel::Logistic(_), Some(s)) => Ok(ContactModel::Logistic(s)),
        (None, ContactModel::Normal(_), Some(s)) => Ok(ContactModel::Normal(s)),
        (None, own, _) => Ok(own),
    }
}

/// The scene file at `path`, or with `None` the built-in one (`scenes/finger.toml`, whose only task is
/// `spin`).
fn problem_file(path: Option<PathBuf>) -> PyResult<ProblemFile> {
    match path {
        None => Ok(ProblemFile::builtin()),
        Some(p) => ProblemFile::load(&p).map_err(|e| error(format!("scene {}: {e}", p.display()))),
    }
}

/// Python's `json.loads` of a serde value: nested dicts, lists and floats.
fn to_python<'py>(py: Python<'py>, value: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value).map_err(error)?;
    py.import("json")?.call_method1("loads", (text,))
}

/// `(x_next, fx, fu)` as NumPy arrays.
type Linearised<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
);

/// The simulator: one time step of a scene under a contact model, its exact first derivatives and the
/// Hessian of `c^T f`. Warm starts carry from one step to the next, as in the crates.
///
/// Arguments:
///     scene: path of a scene file (TOML, docs/scenes.md), or None for the built-in flicking finger
///         of SCENE.md (scenes/finger.toml).
///     model: the contact model: "logistic" (the paper's eq. 17, solved by Newton), "normal" (eq. 14
///         with 15) or "hard" (the exact LCP, Lemke's method).
///     sigma: the noise scale of "logistic" and "normal", positive (the paper's 0.1); not used by
///         "hard".
///     h: the time step, s.
#[pyclass(module = "slcp", frozen)]
struct Simulator {
    /// The simulator, one caller at a time: a second thread using the same object gets a clear error
    /// (never a half-done step), and the sizes below are read without it.
    sim: std::sync::Mutex<RsSimulator>,
    scene: Scene,
    h: f64,
    /// What `__repr__` shows: the scene file as given (None: the built-in finger) and the model.
    source: Option<PathBuf>,
    model: ContactModel,
}

#[pymethods]
impl Simulator {
    /// `Simulator(scene=None, model="logistic", sigma=0.1, h=0.05)`: the scene file at `scene` (TOML,
    /// docs/scenes.md), or the built-in one (`scenes/finger.toml`, SCENE.md's flicking finger).
    #[new]
    #[pyo3(signature = (scene=None, model="logistic", sigma=0.1, h=0.05))]
    fn new(scene: Option<PathBuf>, model: &str, sigma: f64, h: f64) -> PyResult<Self> {
        let source = scene.clone();
        let scene = match scene {
            None => ProblemFile::builtin().scene,
            Some(p) => {
                let text = std::fs::read_to_string(&p)
                    .map_err(|e| error(format!("reading {}: {e}", p.display())))?;
                Scene::from_toml_str(&text)
                    .map_err(|e| error(format!("scene {}: {e}", p.display())))?
            }
        };
        let model = self::model(model, sigma)?;
        if let ContactModel::Logistic(s) | ContactModel::Normal(s) = model
            && !(s.is_finite() && s > 0.0)
        {
            return Err(error(format!("sigma {s} must be positive and finite")));
        }
        let sim = RsSimulator::new(
            scene,
            StepSettings {
                model: model.complementarity(),
                h,
                ..StepSettings::default()
            },
        )
        .map_err(error)?;
        Ok(Simulator {
            scene: sim.scene().clone(),
            h: sim.settings().h,
            sim: std::sync::Mutex::new(sim),
            source,
            model,
        })
    }

    /// `Simulator(scene='scenes/pushing.toml', model='hard', h=0.05)`: how to make it again, with its
    /// sizes.
    fn __repr__(&self) -> String {
        let scene = match &self.source {
            Some(p) => format!("'{}'", p.display().to_string().replace('\'', "\\'")),
            None => "None".into(),
        };
        let model = match self.model {
            ContactModel::Hard => "model='hard'".to_string(),
            // Debug's float form is Python's own: 0.1, and 1e-300 rather than three hundred digits.
            ContactModel::Logistic(s) => format!("model='logistic', sigma={s:?}"),
            ContactModel::Normal(s) => format!("model='normal', sigma={s:?}"),
        };
        format!(
            "Simulator(scene={scene}, {model}, h={:?}) ({} states, {} controls)",
            self.h,
            self.scene.n_state(),
            self.scene.n_controls
        )
    }

    /// Length of the state `x = [q; v]`.
    #[getter]
    fn n_state(&self) -> usize {
        self.scene.n_state()
    }

    /// Number of controls.
    #[getter]
    fn n_controls(&self) -> usize {
        self.scene.n_controls
    }

    /// Names of the state's entries (`link1.angle`, ..., `link1.angle velocity`, ...).
    #[getter]
    fn state_names(&self) -> Vec<String> {
        self.scene.state_names()
    }

    /// The time step.
    #[getter]
    fn h(&self) -> f64 {
        self.h
    }

    /// `step(x, u) -> x_next`.
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: PyArrayLike1<'py, f64, AllowTypeChange>,
        u: PyArrayLike1<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (x, u) = self.inputs(&x, &u)?;
        let step = shielded(|| self.sim()?.step(&x, &u).map_err(error))?;
        Ok(step.x_next.into_pyarray(py))
    }

    /// `step_info(x, u) -> dict`: the next state, the row impulses `lambda` (in the order of the
    /// scene's complementarity rows), each contact pair's distance, normal and tangential impulse, and
    /// the complementarity solve's status, iterations and residual.
    fn step_info<'py>(
        &self,
        py: Python<'py>,
        x: PyArrayLike1<'py, f64, AllowTypeChange>,
        u: PyArrayLike1<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (x, u) = self.inputs(&x, &u)?;
        let step = shielded(|| self.sim()?.step(&x, &u).map_err(error))?;
        let out = PyDict::new(py);
        let pairs = |f: fn(&dynamics::ContactImpulse) -> f64| {
            Array1::from_iter(step.impulses.iter().map(f)).into_pyarray(py)
        };
        out.set_item("normal_impulse", pairs(|i| i.normal))?;
        out.set_item("tangent_impulse", pairs(|i| i.tangent))?;
        out.set_item(
            "contact_distance",
            Array1::from_iter(step.contacts.iter().map(|c| c.distance)).into_pyarray(py),
        )?;
        out.set_item("status", step.info.status.name())?;
        out.set_item("iterations", step.info.iterations)?;
        out.set_item("residual", step.info.residual)?;
        // The vectors move into their arrays, no copy.
        out.set_item("x_next", step.x_next.into_pyarray(py))?;
        out.set_item("lambda", step.lambda.into_pyarray(py))?;
        out.set_item("d", step.d.into_pyarray(py))?;
        Ok(out)
    }

    /// `derivatives(x, u) -> (x_next, fx, fu)`: one step and its exact first derivatives,
    /// `fx[i, j] = d x_next[i] / d x[j]`, `fu[i, j] = d x_next[i] / d u[j]`.
    fn derivatives<'py>(
        &self,
        py: Python<'py>,
        x: PyArrayLike1<'py, f64, AllowTypeChange>,
        u: PyArrayLike1<'py, f64, AllowTypeChange>,
    ) -> PyResult<Linearised<'py>> {
        let (x, u) = self.inputs(&x, &u)?;
        let (n, m) = (x.len(), u.len());
        let (step, d) = shielded(|| self.sim()?.step_with_derivatives(&x, &u).map_err(error))?;
        Ok((
            step.x_next.into_pyarray(py),
            matrix(py, d.fx, n, n)?,
            matrix(py, d.fu, n, m)?,
        ))
    }

    /// `hessian(x, u, c) -> H`: the Hessian of `c . f(x, u)` over `y = (x, u)`, square of side
    /// `n_state + n_controls` (the second-order term of full DDP, with `c` the value gradient).
    fn hessian<'py>(
        &self,
        py: Python<'py>,
        x: PyArrayLike1<'py, f64, AllowTypeChange>,
        u: PyArrayLike1<'py, f64, AllowTypeChange>,
        c: PyArrayLike1<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let (x, u) = self.inputs(&x, &u)?;
        let c = vector(&c, "c", x.len())?;
        let side = x.len() + u.len();
        let (_, _, h) = shielded(|| self.sim()?.step_with_hessian(&x, &u, &c).map_err(error))?;
        matrix(py, h, side, side)
    }

    /// `rollout(x0, us) -> xs`: the states from `x0` under the controls `us` (shape `(N, n_controls)`),
    /// shape `(N + 1, n_state)`. The GIL is released while it runs.
    fn rollout<'py>(
        &self,
        py: Python<'py>,
        x0: PyArrayLike1<'py, f64, AllowTypeChange>,
        us: PyArrayLike2<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = self.n_state();
        let x0 = vector(&x0, "x0", n)?;
        let us = rows(&us, "us", self.n_controls())?;
        let mut guard = self.sim()?;
        let sim = &mut *guard;
        let states = py.allow_threads(move || {
            shielded(|| {
                let mut xs = Vec::with_capacity(us.len() + 1);
                xs.push(x0);
                for (k, u) in us.iter().enumerate() {
                    let x = xs.last().expect("x0 pushed");
                    let next = sim
                        .step(x, u)
                        .map_err(|e| error(format!("step {k}: {e}")))?
                        .x_next;
                    xs.push(next);
                }
                Ok(xs)
            })
        });
        stacked(py, states?, n)
    }

    /// Forget the warm start: the next step's solve starts from `[v; 0]`.
    fn reset_warm_start(&self) -> PyResult<()> {
        self.sim()?.reset_warm_start();
        Ok(())
    }
}

impl Simulator {
    /// The simulator for this call, or a clear error while another thread is using it.
    fn sim(&self) -> PyResult<std::sync::MutexGuard<'_, RsSimulator>> {
        match self.sim.try_lock() {
            Ok(guard) => Ok(guard),
            // A step that panicked (a bug, reported as SlcpError) left nothing half-written that the
            // next step reads: each step starts from its inputs and the warm start it sets whole.
            Err(std::sync::TryLockError::Poisoned(p)) => Ok(p.into_inner()),
            Err(std::sync::TryLockError::WouldBlock) => Err(error(
                "this Simulator is in use by another thread: give each thread its own \
                 slcp.Simulator (they are cheap), or hold a lock around the shared one",
            )),
        }
    }

    fn inputs(
        &self,
        x: &PyArrayLike1<'_, f64, AllowTypeChange>,
        u: &PyArrayLike1<'_, f64, AllowTypeChange>,
    ) -> PyResult<(Vec<f64>, Vec<f64>)> {
        Ok((
            vector(x, "x", self.n_state())?,
            vector(u, "u", self.n_controls())?,
        ))
    }
}

/// `optimize(scene=None, task=None, horizon=None, x0=None, us=None, iterations=None, method="full",
/// model=None, sigma=None, h=None, threads=1) -> dict`: iLQG / DDP on a task of a scene file, as
/// `cargo xtask optimize` (the same names as its flags).
///
/// Arguments:
///     scene: path of a scene file, or None for the built-in finger (scenes/finger.toml).
///     task: the name of one of its `[task.NAME]` tables; None: its only one.
///     horizon: steps N (1 to 100000); None: the task's.
///     x0: the initial state; None: the task's.
///     us: the controls to start from, shape (N, m); None: zeros.
///     iterations: passes at most (1 to 100000); None: 300. `max_iterations` is accepted as its alias
///         (refused when both are given and disagree).
///     method: "full" (second-order DDP: the dynamics' Hessians contracted with the value gradient)
///         or "ilqr" (Gauss-Newton: first derivatives only).
///     model, sigma, h: the contact model ("logistic", "normal", "hard"), its noise scale and the time
///         step; None: the task's.
///     threads: threads each pass's knots are differentiated on (1 to 256; the same result on any
///         number).
///
/// Returns a dict: `states` (N+1, n) and `controls` (N, m); `gains` (N, m, n), the feedback of
/// `u = controls[i] + gains[i] @ (x - states[i])`; the local value model `cost_to_go` (N+1,),
/// `value_gradient` (N+1, n), `value_hessian` (N+1, n, n); `cost`; `passes`; `status` (why it stopped:
/// "cost converged", "step converged", "pass limit reached", "no descent", "regularisation
/// exceeded", or "no contact felt" where the solve never touches the contact its task needs);
/// `optimiser_status` (why the optimiser stopped, whatever the contact); `converged` (the first two,
/// with the contact felt); `contact` (how the contact was felt: "felt" by the first solve, "pulled
/// A-B together", "continued in the noise scale", or "not felt" with the reason); `regularisation` (the
/// returned solve's: "state", `Q_uu + mu f_u^T f_u`, or "control", `Q_uu + mu I` where, with
/// `continuation` and the full method, a solve that stopped without converging was continued under it
/// and came out cheaper, as `cargo xtask optimize` does); `task` (its name). The GIL is released while it
/// runs.
///
/// `continuation` (default True): where the first solve never touches the contact the task's cost needs
/// (its gradient is zero out of reach), reach for it as `cargo xtask optimize` does: pull each needed pair
/// together, then continue in the noise scale (docs/tasks.md); the result replaces the first solve only
/// where it feels the contact and costs less. False only reports it.
#[pyfunction]
#[pyo3(signature = (scene=None, task=None, horizon=None, x0=None, us=None, iterations=None, method="full", model=None, sigma=None, h=None, threads=1, max_iterations=None, continuation=true))]
#[allow(clippy::too_many_arguments)]
fn optimize<'py>(
    py: Python<'py>,
    scene: Option<PathBuf>,
    task: Option<&str>,
    horizon: Option<usize>,
    x0: Option<PyArrayLike1<'py, f64, AllowTypeChange>>,
    us: Option<PyArrayLike2<'py, f64, AllowTypeChange>>,
    iterations: Option<usize>,
    method: &str,
    model: Option<&str>,
    sigma: Option<f64>,
    h: Option<f64>,
    threads: usize,
    max_iterations: Option<usize>,
    continuation: bool,
) -> PyResult<Bound<'py, PyDict>> {
    // `max_iterations` (the crates' name) is an alias of `iterations` (the command line's): either may
    // be given, both only when they agree (an explicit 300 included); neither means 300.
    let max_iterations = match (iterations, max_iterations) {
        (Some(i), Some(m)) if i != m => {
            return Err(error(format!(
                "iterations {i} and its alias max_iterations {m} disagree: give one"
            )));
        }
        (Some(i), _) | (None, Some(i)) => i,
        (None, None) => 300,
    };
    let file = problem_file(scene)?;
    let task = file.task(task).map_err(error)?;
    let (n, m) = (file.scene.n_state(), file.scene.n_controls);
    let horizon = horizon.unwrap_or(task.horizon);
    if !(1..=100_000).contains(&horizon) {
        return Err(error(format!(
            "horizon {horizon} must be 1 to 100000 steps"
        )));
    }
    if !(1..=100_000).contains(&max_iterations) {
        return Err(error(format!(
            "iterations {max_iterations} must be 1 to 100000"
        )));
    }
    let x0 = match &x0 {
        Some(a) => vector(a, "x0", n)?,
        None => task.x0.clone(),
    };
    let us = match &us {
        Some(a) => {
            let r = rows(a, "us", m)?;
            if r.len() != horizon {
                return Err(error(format!(
                    "us has {} rows, expected the horizon {horizon}",
                    r.len()
                )));
            }
            r
        }
        None => vec![vec![0.0; m]; horizon],
    };
    let method = match method {
        "full" => Method::Full,
        "ilqr" => Method::GaussNewton,
        other => {
            return Err(error(format!(
                "method \"{other}\" is not one of \"full\", \"ilqr\""
            )));
        }
    };
    let contact = contact_model(task.model, model, sigma)?;
    let sim = RsSimulator::new(
        file.scene.clone(),
        StepSettings {
            model: contact.complementarity(),
            h: h.unwrap_or(task.h),
            ..StepSettings::default()
        },
    )
    .map_err(error)?;
    let ddp = Ddp::new(DdpSettings {
        method,
        max_iterations,
        control_limits: task.control_limits.clone(),
        threads,
        ..DdpSettings::default()
    })
    .map_err(error)?;
    let cost = task.cost.clone();
    let scene = file.scene.clone();
    let progress = ::task::Progress::of_task(&task).map_err(error)?;
    let (sol, felt, contact, regularisation) = py.allow_threads(move || {
        shielded(|| {
            let settings = *sim.settings();
            let sol = ddp
                .solve(&SceneDynamics::new(sim), &cost, &x0, &us)
                .map_err(error)?;
            let problem = ::task::ContactProblem {
                ddp: &ddp,
                scene: &scene,
                settings: &settings,
                cost: &cost,
                x0: &x0,
            };
            // The contact searched for, a progress task's stalled plan explored, a full-DDP solve
            // that stopped without converging continued under the other regularisation: as
            // `cargo xtask optimize` and a library's first solve finish theirs.
            let stages = ::task::Stages {
                search: continuation,
                explore: continuation,
                other_regularisation: continuation && ddp.settings().method == Method::Full,
            };
            let finished = problem
                .finish(sol, &progress, stages, |_, _, _| {})
                .map_err(error)?;
            let name = |pair: usize| {
                scene
                    .pair_name(pair)
                    .unwrap_or_else(|| format!("contact pair {pair}"))
            };
            let contact = match finished.search.as_ref().map(|s| s.outcome()) {
                None if finished.felt => "felt".to_string(),
                None => "not felt (continuation=False)".to_string(),
                Some(::task::ContactOutcome::Felt) => "felt".to_string(),
                Some(::task::ContactOutcome::Pulled(p)) => format!("pulled {} together", name(p)),
                Some(::task::ContactOutcome::Continued(_)) => {
                    "continued in the noise scale".to_string()
                }
                Some(::task::ContactOutcome::OutOfReach(o)) => format!(
                    "not felt: {} stays apart by more than twice the driven body's reach",
                    name(o.pair)
                ),
                Some(::task::ContactOutcome::TouchedNotKept(_)) => {
                    "not felt: a pull touched, but no solve through the contact costs less"
                        .to_string()
                }
                Some(
                    ::task::ContactOutcome::Lost(_)
                    | ::task::ContactOutcome::NeverFelt
                    | ::task::ContactOutcome::NoContinuation,
                ) => "not felt: no pull or continuation found it".to_string(),
            };
            let contact = match &finished.explored {
                Some(e) if e.kept => format!("{contact}; explored from random starts"),
                _ => contact,
            };
            let regularisation = match finished.other.as_ref().filter(|o| o.kept) {
                Some(o) if o.regularisation == ::ddp::Regularisation::Control => "control",
                _ => "state",
            };
            Ok((finished.solution, finished.felt, contact, regularisation))
        })
    })?;
    let out = PyDict::new(py);
    let steps = sol.controls.len();
    out.set_item("states", stacked(py, sol.states, n)?)?;
    out.set_item("controls", stacked(py, sol.controls, m)?)?;
    out.set_item(
        "gains",
        Array3::from_shape_vec((steps, m, n), sol.gains.into_iter().flatten().collect())
            .map_err(error)?
            .into_pyarray(py),
    )?;
    let knots = sol.values.len();
    out.set_item(
        "cost_to_go",
        Array1::from_iter(sol.values.iter().map(|v| v.cost_to_go)).into_pyarray(py),
    )?;
    out.set_item(
        "value_gradient",
        stacked(
            py,
            sol.values.iter().map(|v| v.gradient.clone()).collect(),
            n,
        )?,
    )?;
    out.set_item(
        "value_hessian",
        Array3::from_shape_vec(
            (knots, n, n),
            sol.values.into_iter().flat_map(|v| v.hessian).collect(),
        )
        .map_err(error)?
        .into_pyarray(py),
    )?;
    out.set_item("cost", sol.cost)?;
    out.set_item("passes", sol.iterations.len())?;
    let status = match felt {
        true => sol.status.to_string(),
        false => "no contact felt".to_string(),
    };
    out.set_item("status", status)?;
    out.set_item("optimiser_status", sol.status.to_string())?;
    out.set_item("converged", felt && sol.status.converged())?;
    out.set_item("contact", contact)?;
    out.set_item("regularisation", regularisation)?;
    out.set_item("task", task.name)?;
    Ok(out)
}

/// A controller library (paper section IV-C): local feedback controllers along receding-horizon
/// trajectories, and the global nearest-neighbour policy over them. Made by `Library.train(...)` (as
/// `cargo xtask train`) or `Library.load(path)`; `len(lib)` is its number of controllers.
#[pyclass(module = "slcp")]
struct Library {
    lib: RsLibrary,
    policy: RsPolicy,
}

impl Library {
    fn wrap(lib: RsLibrary) -> PyResult<Self> {
        let policy = lib.policy().map_err(error)?;
        Ok(Library { lib, policy })
    }
}

#[pymethods]
impl Library {
    /// `Library.train(scene=None, task=None, trajectories=400, seed=1, paper=False, horizon=None,
    /// growth=None, trunk=None, settle=None, length=None, chains=1, model=None, sigma=None, threads=1)`:
    /// build a library as `cargo xtask train` does (`threads`: each solve's knots on that many threads,
    /// `train --threads`; the same library on any number) (the contact model and sigma the task's unless given) for the
    /// task `task` of the scene file `scene` (its only task when `task` is None; without a scene the
    /// built-in `scenes/finger.toml`, whose only task is the paper's `spin`), with the default recipe
    /// (`paper=True`: the paper's).
    /// The GIL is released while it builds.
    #[staticmethod]
    #[pyo3(signature = (scene=None, task=None, trajectories=400, seed=1, paper=false, horizon=None, growth=None, trunk=None, settle=None, length=None, chains=1, model=None, sigma=None, threads=1))]
    #[allow(clippy::too_many_arguments)]
    fn train(
        py: Python<'_>,
        scene: Option<PathBuf>,
        task: Option<&str>,
        trajectories: usize,
        seed: u64,
        paper: bool,
        horizon: Option<usize>,
        growth: Option<usize>,
        trunk: Option<usize>,
        settle: Option<usize>,
        length: Option<usize>,
        chains: usize,
        model: Option<&str>,
        sigma: Option<f64>,
        threads: usize,
    ) -> PyResult<Self> {
        let file = problem_file(scene)?;
        let chosen: Task = file.task(task).map_err(error)?;
        let base = if paper {
            LibrarySettings::paper()
        } else {
            LibrarySettings::default()
        }
        .for_task(&chosen);
        let fitted = base.clone().fitted(trajectories);
        let exploration = match fitted.exploration {
            Exploration::Branches {
                trunk: t,
                settle: s,
                length: l,
            } => Exploration::Branches {
                trunk: trunk.unwrap_or(t),
                settle: settle.unwrap_or(s),
                length: length.unwrap_or(l),
            },
            kicks => {
                if trunk.is_some() || settle.is_some() || length.is_some() {
                    return Err(error(
                        "trunk, settle and length shape the default recipe, not the paper's",
                    ));
                }
                kicks
            }
        };
        let contact = contact_model(base.model, model, sigma)?;
        let settings = LibrarySettings {
            model: contact,
            trajectories,
            seed,
            chains,
            knot_threads: threads,
            horizon: horizon.unwrap_or(base.horizon),
            growth: growth.unwrap_or(fitted.growth),
            exploration,
            ..base
        };
        let lib = py.allow_threads(move || {
            shielded(|| {
                RsLibrary::build(&file, Some(&chosen.name), &settings, |_, _| {}).map_err(error)
            })
        })?;
        Library::wrap(lib)
    }

    /// `Library.load(path)`: a library file written by `save` or `cargo xtask train`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let lib = py.allow_threads(|| {
            shielded(|| {
                RsLibrary::load(&path).map_err(|e| error(format!("{}: {e}", path.display())))
            })
        })?;
        Library::wrap(lib)
    }

    /// `save(path)`: write the library file (the format `cargo xtask` reads).
    fn save(&self, path: PathBuf) -> PyResult<()> {
        self.lib
            .save(&path)
            .map_err(|e| error(format!("{}: {e}", path.display())))
    }

    /// `<slcp.Library: 3600 controllers for task 'push', logistic contact, sigma 0.05, h = 0.05>`.
    fn __repr__(&self) -> String {
        format!(
            "<slcp.Library: {} controllers for task '{}', {}, h = {}>",
            self.lib.entries.len(),
            self.lib.task().name,
            self.lib.settings.model,
            self.lib.settings.h
        )
    }

    /// Number of local controllers.
    fn __len__(&self) -> usize {
        self.lib.entries.len()
    }

    /// The controllers' states, shape `(len, n_state)`.
    #[getter]
    fn states<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = self.lib.scene().n_state();
        stacked(
            py,
            self.lib.entries.iter().map(|e| e.x.clone()).collect(),
            n,
        )
    }

    /// The name of the task it was built for.
    #[getter]
    fn task(&self) -> String {
        self.lib.task().name.clone()
    }

    /// The angles its policy compares modulo a turn, `{name: turn}` (pi for a half turn, 0.0 for a disc's
    /// angle, which does not count at all): those of bodies a turn maps onto themselves that its task
    /// does not see (docs/tasks.md, "Half turns"); empty where there are none.
    #[getter]
    fn turns(&self) -> std::collections::BTreeMap<String, f64> {
        let names = self.lib.scene().coordinate_names();
        self.lib
            .turn_symmetries()
            .into_iter()
            .map(|(c, turn)| (names[c].clone(), turn))
            .collect()
    }

    /// The settings it was built with, as a dict.
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.lib.settings)
    }

    /// The initial state of its first trajectory (its task's).
    #[getter]
    fn x0<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.lib.x0().to_vec().into_pyarray(py)
    }

    /// `policy(x) -> u`: the global policy's control at `x` (eq. 20, or the value-ranked choice among
    /// the nearest controllers when the library was built to rank them).
    fn policy<'py>(
        &self,
        py: Python<'py>,
        x: PyArrayLike1<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let x = vector(&x, "x", self.lib.scene().n_state())?;
        let mut u = vec![0.0; self.lib.scene().n_controls];
        self.policy.control(&x, &mut u).map_err(error)?;
        Ok(u.into_pyarray(py))
    }

    /// `evaluate(seconds=200.0, model=None, sigma=None, h=None, kick_every=10.0, kick_std=2.0, seed=7,
    /// x0=None) -> dict`: the policy in closed loop (`cargo xtask evaluate`'s measures) on the library's
    /// own model (or `model`: "logistic", "normal", "hard") at its time step (or `h`), from its initial
    /// state (or `x0`). The GIL is released while it runs.
    #[pyo3(signature = (seconds=200.0, model=None, sigma=None, h=None, kick_every=10.0, kick_std=2.0, seed=7, x0=None))]
    #[allow(clippy::too_many_arguments)]
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        seconds: f64,
        model: Option<&str>,
        sigma: Option<f64>,
        h: Option<f64>,
        kick_every: f64,
        kick_std: f64,
        seed: u64,
        x0: Option<PyArrayLike1<'py, f64, AllowTypeChange>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let world = contact_model(self.lib.settings.model, model, sigma)?;
        let x0 = match &x0 {
            Some(a) => vector(a, "x0", self.lib.scene().n_state())?,
            None => self.lib.x0().to_vec(),
        };
        if !(seconds.is_finite() && seconds <= 1e6) {
            return Err(error(format!(
                "seconds {seconds} must be finite and at most 1e6"
            )));
        }
        let settings = EvaluationSettings {
            model: world,
            h: h.unwrap_or(self.lib.settings.h),
            seconds,
            kick_every,
            kick_std,
            seed,
            x0,
        };
        let (lib, policy) = (&self.lib, &self.policy);
        let e: Evaluation = py.allow_threads(|| {
            shielded(|| ::library::evaluate(lib, policy, &settings).map_err(error))
        })?;
        to_python(py, &e)
    }
}

/// Stochastic complementarity for contact: the Rust crates from Python.
#[pymodule]
fn slcp(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Simulator>()?;
    m.add_class::<Library>()?;
    m.add_function(wrap_pyfunction!(optimize, m)?)?;
    m.add("SlcpError", m.py().get_type::<SlcpError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
