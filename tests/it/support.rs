//! Shared fixtures: the independent reference answers in `tests/data/` (copied from the project's
//! reference files; tests/data/README.md says where they came from) and the libraries several tests use.

use std::path::PathBuf;

/// Path of a reference file in `tests/data/`.
pub fn reference_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(name)
}

/// Parsed JSON of a reference file.
pub fn reference_json(name: &str) -> serde_json::Value {
    let text = std::fs::read_to_string(reference_path(name)).expect("readable reference file");
    serde_json::from_str(&text).expect("valid reference JSON")
}

/// `c^T [fx fu]` of the step at `y = (x, u)` (`x` as long as `c`), by the exact first derivatives from a
/// cold start: the gradient whose differences check the Hessian of `c^T f`.
pub fn c_gradient(sim: &mut dynamics::Simulator, c: &[f64], y: &[f64]) -> Vec<f64> {
    let nx = c.len();
    let nu = y.len() - nx;
    sim.reset_warm_start();
    let (_, d) = sim.step_with_derivatives(&y[..nx], &y[nx..]).unwrap();
    let mut g = vec![0.0; nx + nu];
    for (j, gj) in g.iter_mut().enumerate().take(nx) {
        *gj = (0..nx).map(|i| c[i] * d.fx[i * nx + j]).sum();
    }
    for k in 0..nu {
        g[nx + k] = (0..nx).map(|i| c[i] * d.fu[i * nu + k]).sum();
    }
    g
}

/// A finger library built with `settings` once per test run and shared.
fn built_once(
    cell: &'static std::sync::OnceLock<library::Library>,
    settings: fn() -> library::LibrarySettings,
) -> &'static library::Library {
    cell.get_or_init(|| {
        library::Library::build(&task::ProblemFile::builtin(), None, &settings(), |_, _| {})
            .unwrap()
    })
}

/// The default library (`cargo xtask train`'s: 400 trajectories, the cycle first, growth on the policy's
/// stalls); about 30 s.
pub fn finger_library() -> &'static library::Library {
    static LIB: std::sync::OnceLock<library::Library> = std::sync::OnceLock::new();
    built_once(&LIB, library::LibrarySettings::default)
}

/// The paper's recipe (horizon 75, a kicked chain, first controllers, the nearest controller's law),
/// seed 1; about 7 s.
pub fn paper_library() -> &'static library::Library {
    static LIB: std::sync::OnceLock<library::Library> = std::sync::OnceLock::new();
    built_once(&LIB, library::LibrarySettings::paper)
}

/// Kinetic plus potential energy (gravity on every centre).
pub fn energy(scene: &dynamics::Scene, x: &[f64]) -> f64 {
    let n = scene.n_dof();
    let (q, v) = x.split_at(n);
    let kin = dynamics::Kinematics::new(scene, q);
    let m = kin.mass_matrix(scene);
    let kinetic: f64 = (0..n)
        .flat_map(|i| (0..n).map(move |j| (i, j)))
        .map(|(i, j)| 0.5 * v[i] * m[i * n + j] * v[j])
        .sum();
    let potential: f64 = scene
        .bodies
        .iter()
        .zip(&kin.centre)
        .map(|(b, c)| -b.mass * (scene.gravity[0] * c[0] + scene.gravity[1] * c[1]))
        .sum();
    kinetic + potential
}

/// scenes/slider_push.toml with a round block (a puck of radius 0.25): a body any turn maps onto itself.
pub fn puck_text() -> String {
    let slider = include_str!("../../scenes/slider_push.toml");
    let ellipse = "semi_axes = [0.4, 0.25]\nparent = \"world\"";
    assert!(slider.contains(ellipse), "the slider's block");
    slider.replace(ellipse, "semi_axes = [0.25, 0.25]\nparent = \"world\"")
}
