//! `cargo xtask figures`: the paper's figures as PNG and SVG (plotters, the bundled DejaVu Sans font, no
//! system fonts needed): the contact surface d(q) = 0 in cylindrical coordinates (Fig. 2), the library's
//! states (Fig. 3), a closed-loop limit cycle coloured by contact impulse (Fig. 4), and frames of the
//! controlled finger (Fig. 5).

use anyhow::{Context, anyhow};
use dynamics::{Constraints, Kinematics, Scene, Simulator, StepSettings};
use library::{Library, Policy};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// Options of `cargo xtask figures`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The library whose states and closed loop are drawn.
    #[arg(long, default_value = "results/finger.lib")]
    library: PathBuf,
    /// Output folder.
    #[arg(long, default_value = "results/figures")]
    out: PathBuf,
}

static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

fn register_font() -> anyhow::Result<()> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| anyhow!("the bundled font does not load"))
}

fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("drawing: {e:?}")
}

/// Draw with `f` into `name.png` and `name.svg` under `dir`.
fn both(
    dir: &Path,
    name: &str,
    size: (u32, u32),
    f: impl Fn(&DrawingArea<BitMapBackend, Shift>) -> anyhow::Result<()>,
    g: impl Fn(&DrawingArea<SVGBackend, Shift>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let png = dir.join(format!("{name}.png"));
    let svg = dir.join(format!("{name}.svg"));
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        f(&root)?;
        root.present().map_err(err)?;
    }
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        g(&root)?;
        root.present().map_err(err)?;
    }
    Ok(())
}

/// Points of the contact surface: for each (theta3, theta1) the smallest theta2 in the joint's range at
/// which link 2 touches the free ellipse (bisection on the signed distance), in cylindrical coordinates
/// (angle theta3 doubled, the ellipse's period being pi; radius theta1 + pi + 0.5; height theta2).
fn contact_surface(scene: &Scene) -> Vec<(f64, f64, f64)> {
    let d = |q: [f64; 3]| -> Option<f64> {
        let kin = Kinematics::new(scene, &q);
        Constraints::new(scene, &kin, &q)
            .ok()
            .and_then(|c| c.contacts.first().map(|f| f.distance))
    };
    let (lo2, hi2) = scene.bodies[1]
        .limits
        .unwrap_or([-2.0 * PI / 3.0, 0.0])
        .into();
    let mut out = Vec::new();
    for i in 0..48 {
        let t3 = PI * i as f64 / 48.0;
        for j in 0..40 {
            let t1 = -PI + PI * (j as f64 + 0.5) / 40.0;
            // Scan theta2 for a sign change, then bisect.
            let steps = 60;
            let mut prev: Option<(f64, f64)> = None;
            for k in 0..=steps {
                let t2 = hi2 + (lo2 - hi2) * k as f64 / steps as f64;
                let Some(v) = d([t1, t2, t3]) else { continue };
                if let Some((pt, pv)) = prev
                    && pv > 0.0
                    && v <= 0.0
                {
                    let (mut a, mut b) = (pt, t2);
                    for _ in 0..40 {
                        let m = 0.5 * (a + b);
                        if d([t1, m, t3]).unwrap_or(1.0) > 0.0 {
                            a = m;
                        } else {
                            b = m;
                        }
                    }
                    let r = t1 + PI + 0.5;
                    out.push((r * (2.0 * t3).cos(), 0.5 * (a + b), r * (2.0 * t3).sin()));
                    break;
                }
                prev = Some((t2, v));
            }
        }
    }
    out
}

fn draw_surface<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    pts: &[(f64, f64, f64)],
) -> anyhow::Result<()> {
    let r = pts
        .iter()
        .fold(1.0f64, |m, p| m.max(p.0.abs()).max(p.2.abs()));
    let (zmin, zmax) = pts
        .iter()
        .fold((0.0f64, -2.2f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let mut chart = ChartBuilder::on(root)
        .caption(
            "Fig. 2: contact surface d(q) = 0 (angle 2 theta3, radius theta1 + pi + 0.5, height theta2)",
            ("sans-serif", 16),
        )
        .margin(10)
        .build_cartesian_3d(-r..r, zmin.min(-2.2)..zmax.max(0.0), -r..r)
        .map_err(err)?;
    chart.with_projection(|mut p| {
        p.pitch = 0.5;
        p.yaw = 0.6;
        p.scale = 0.8;
        p.into_matrix()
    });
    chart.configure_axes().draw().map_err(err)?;
    chart
        .draw_series(pts.iter().map(|&(x, y, z)| {
            let c = HSLColor(0.6 - 0.6 * (y - zmin) / (zmax - zmin + 1e-12), 0.8, 0.45);
            Circle::new((x, y, z), 2, c.filled())
        }))
        .map_err(err)?;
    Ok(())
}

fn draw_states<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    lib: &Library,
) -> anyhow::Result<()> {
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "Fig. 3: the library's {} controller states (theta1, theta2, theta3 mod pi)",
                lib.entries.len()
            ),
            ("sans-serif", 16),
        )
        .margin(10)
        .build_cartesian_3d(-PI..0.0, -2.2..0.2, 0.0..PI)
        .map_err(err)?;
    chart.with_projection(|mut p| {
        p.pitch = 0.4;
        p.yaw = 0.7;
        p.scale = 0.85;
        p.into_matrix()
    });
    chart.configure_axes().draw().map_err(err)?;
    chart
        .draw_series(lib.entries.iter().map(|e| {
            let t3 = e.x[2].rem_euclid(PI);
            Circle::new((e.x[0], e.x[1], t3), 2, BLUE.mix(0.6).filled())
        }))
        .map_err(err)?;
    Ok(())
}

/// The closed loop of the library's policy on its own smoothed model: states, controls, contact impulses.
struct Run {
    states: Vec<Vec<f64>>,
    impulses: Vec<f64>,
}

fn closed_loop(lib: &Library, policy: &Policy, seconds: f64) -> anyhow::Result<Run> {
    let mut sim = Simulator::new(
        lib.scene().clone(),
        StepSettings {
            model: lib.settings.model.complementarity(),
            h: lib.settings.h,
            ..StepSettings::default()
        },
    )?;
    let limit_rows: usize = lib
        .scene()
        .bodies
        .iter()
        .filter(|b| b.limits.is_some())
        .count()
        * 2;
    let mut x = lib.settings.x0.clone();
    let mut u = vec![0.0; lib.scene().n_controls];
    let mut states = vec![x.clone()];
    let mut impulses = vec![0.0];
    for _ in 0..(seconds / lib.settings.h) as usize {
        policy.control(&x, &mut u)?;
        let s = sim.step(&x, &u)?;
        impulses.push(s.lambda[limit_rows..].iter().sum());
        x = s.x_next;
        states.push(x.clone());
    }
    Ok(Run { states, impulses })
}

fn draw_cycle<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, run: &Run) -> anyhow::Result<()> {
    let start = run.states.len().saturating_sub(400);
    let top = run.impulses[start..].iter().fold(1e-9f64, |m, v| m.max(*v));
    let mut chart = ChartBuilder::on(root)
        .caption(
            "Fig. 4: the controlled finger's last 20 s in (theta1, theta2), coloured by contact impulse",
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .build_cartesian_2d(-PI..0.0, -2.2..0.2)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("theta1 (rad)")
        .y_desc("theta2 (rad)")
        .draw()
        .map_err(err)?;
    for k in start + 1..run.states.len() {
        let (a, b) = (&run.states[k - 1], &run.states[k]);
        let w = (run.impulses[k] / top).clamp(0.0, 1.0);
        let colour = RGBColor((40.0 + 215.0 * w) as u8, 60, (200.0 * (1.0 - w)) as u8);
        chart
            .draw_series(LineSeries::new(
                [(a[0], a[1]), (b[0], b[1])],
                colour.stroke_width(2),
            ))
            .map_err(err)?;
    }
    Ok(())
}

fn ellipse_outline(c: [f64; 2], phi: f64, a: f64, b: f64) -> Vec<(f64, f64)> {
    (0..=48)
        .map(|k| {
            let t = 2.0 * PI * k as f64 / 48.0;
            let (x, y) = (a * t.cos(), b * t.sin());
            (
                c[0] + phi.cos() * x - phi.sin() * y,
                c[1] + phi.sin() * x + phi.cos() * y,
            )
        })
        .collect()
}

fn draw_frames<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    scene: &Scene,
    run: &Run,
) -> anyhow::Result<()> {
    root.titled(
        "Fig. 5: frames of the controlled finger, 0.5 s apart (red: contact impulse)",
        ("sans-serif", 16),
    )
    .map_err(err)?;
    let panels = root.margin(30, 5, 5, 5).split_evenly((2, 4));
    let start = run.states.len().saturating_sub(80);
    for (p, panel) in panels.iter().enumerate() {
        let k = start + 10 * p;
        let Some(x) = run.states.get(k) else { break };
        let n = scene.n_dof();
        let kin = Kinematics::new(scene, &x[..n]);
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("t = {:.2} s", k as f64 * 0.05), ("sans-serif", 12))
            .build_cartesian_2d(-2.2..2.2, -3.8..0.6)
            .map_err(err)?;
        for (i, body) in scene.bodies.iter().enumerate() {
            let outline =
                ellipse_outline(kin.centre[i], kin.phi[i], body.shape.a(), body.shape.b());
            chart
                .draw_series(std::iter::once(Polygon::new(
                    outline.clone(),
                    BLUE.mix(0.25).filled(),
                )))
                .map_err(err)?;
            chart
                .draw_series(LineSeries::new(outline, BLACK.stroke_width(1)))
                .map_err(err)?;
        }
        let q = &x[..n];
        if let Ok(c) = Constraints::new(scene, &kin, q)
            && run.impulses[k] > library::CONTACT_IMPULSE
            && let Some(f) = c.contacts.first()
        {
            chart
                .draw_series(std::iter::once(Circle::new(
                    (f.point_a[0], f.point_a[1]),
                    (3.0 + 20.0 * run.impulses[k].min(1.0)) as i32,
                    RED.filled(),
                )))
                .map_err(err)?;
        }
    }
    Ok(())
}

/// Write every figure for `lib` into `dir`.
pub fn write_all(lib: &Library, dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    register_font()?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let scene = lib.scene();
    let surface = contact_surface(scene);
    both(
        dir,
        "fig2_contact_surface",
        (900, 700),
        |r| draw_surface(r, &surface),
        |r| draw_surface(r, &surface),
    )?;
    both(
        dir,
        "fig3_library_states",
        (900, 700),
        |r| draw_states(r, lib),
        |r| draw_states(r, lib),
    )?;
    let policy = lib.policy()?;
    let run = closed_loop(lib, &policy, 60.0)?;
    both(
        dir,
        "fig4_limit_cycle",
        (900, 700),
        |r| draw_cycle(r, &run),
        |r| draw_cycle(r, &run),
    )?;
    both(
        dir,
        "fig5_frames",
        (1200, 700),
        |r| draw_frames(r, scene, &run),
        |r| draw_frames(r, scene, &run),
    )?;
    Ok([
        "fig2_contact_surface",
        "fig3_library_states",
        "fig4_limit_cycle",
        "fig5_frames",
    ]
    .iter()
    .flat_map(|n| ["png", "svg"].map(|e| dir.join(format!("{n}.{e}"))))
    .collect())
}

/// Run `cargo xtask figures`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let lib = Library::load(&args.library).with_context(|| {
        format!(
            "loading {} (cargo xtask train makes one)",
            args.library.display()
        )
    })?;
    for p in write_all(&lib, &args.out)? {
        println!("wrote {}", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use library::LibrarySettings;

    #[test]
    fn every_figure_is_written_as_png_and_svg() {
        let settings = LibrarySettings {
            trajectories: 6,
            horizon: 40,
            first_passes: 60,
            warm_passes: 20,
            exploration: library::Exploration::Branches {
                trunk: 4,
                settle: 1,
                length: 1,
            },
            growth: 0,
            ..LibrarySettings::default()
        };
        let lib = Library::build(&Scene::flicking_finger(), &settings, |_, _| {}).unwrap();
        let dir = std::env::temp_dir().join(format!("slcp-figures-{}", std::process::id()));
        let files = write_all(&lib, &dir).unwrap();
        assert_eq!(files.len(), 8);
        for f in &files {
            let bytes = std::fs::read(f).unwrap();
            if f.extension().is_some_and(|e| e == "png") {
                assert_eq!(&bytes[1..4], b"PNG", "{}", f.display());
                assert!(bytes.len() > 10_000, "{}", f.display());
            } else {
                let text = String::from_utf8(bytes).unwrap();
                assert!(
                    text.starts_with("<svg") && text.contains("Fig."),
                    "{}",
                    f.display()
                );
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
