//! `cargo xtask figures`: the paper's figures as PNG and SVG (plotters, the bundled DejaVu Sans font, no
//! system fonts needed): the contact surface d(q) = 0 in cylindrical coordinates (Fig. 2), the library's
//! states (Fig. 3), a closed-loop limit cycle coloured by contact impulse (Fig. 4), and frames of the
//! controlled finger (Fig. 5).

use crate::experiments::draw::{both, err, register_font};
use anyhow::Context;
use dynamics::{Constraints, Kinematics, Scene, Simulator, StepSettings};
use library::{Library, Policy};
use plotters::coord::Shift;
use plotters::coord::ranged3d::Cartesian3d;
use plotters::prelude::*;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// Options of `cargo xtask figures`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The library whose states and closed loop are drawn: the paper's four figures for the finger, and
    /// for a task library on another scene its closed loops over time and in frames.
    #[arg(long, default_value = "results/finger.lib")]
    library: PathBuf,
    /// Output folder.
    #[arg(long, default_value = "results/figures")]
    out: PathBuf,
}

/// Points `(theta1, theta2, theta3)` of the contact surface, `theta3` in `[0, pi)`: for each (theta3,
/// theta1) the theta2 nearest 0 in the joint's range at which link 2 touches the free ellipse (bisection
/// on the signed distance).
fn contact_surface(scene: &Scene) -> Vec<[f64; 3]> {
    let d = |q: [f64; 3]| -> Option<f64> {
        let kin = Kinematics::new(scene, &q);
        Constraints::new(scene, &kin, &q)
            .ok()
            .and_then(|c| c.contacts.first().map(|f| f.distance))
    };
    let (lo2, hi2) = scene.coordinates[1]
        .limits
        .unwrap_or([-2.0 * PI / 3.0, 0.0])
        .into();
    let mut out = Vec::new();
    for i in 0..48 {
        let t3 = PI * i as f64 / 48.0;
        for j in 0..120 {
            let t1 = -PI + PI * (j as f64 + 0.5) / 120.0;
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
                    out.push([t1, 0.5 * (a + b), t3]);
                    break;
                }
                prev = Some((t2, v));
            }
        }
    }
    out
}

/// Names on a 3D chart's axes (plotters' 3D axes have none): each text at its point.
fn axis_names<DB: DrawingBackend, X, Y, Z>(
    chart: &mut ChartContext<'_, DB, Cartesian3d<X, Y, Z>>,
    names: [(&str, (f64, f64, f64)); 3],
) -> anyhow::Result<()>
where
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
    Z: Ranged<ValueType = f64>,
{
    chart
        .draw_series(
            names
                .into_iter()
                .map(|(name, at)| Text::new(name.to_string(), at, ("sans-serif", 15).into_font())),
        )
        .map_err(err)?;
    Ok(())
}

fn draw_surface<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    surface: &[[f64; 3]],
) -> anyhow::Result<()> {
    // Cylindrical coordinates: angle 2 theta3 (the ellipse's period is pi), radius theta1 + pi + 0.5,
    // height theta2.
    let pts: Vec<(f64, f64, f64)> = surface
        .iter()
        .map(|&[t1, t2, t3]| {
            let r = t1 + PI + 0.5;
            (r * (2.0 * t3).cos(), t2, r * (2.0 * t3).sin())
        })
        .collect();
    let r = pts
        .iter()
        .fold(1.0f64, |m, p| m.max(p.0.abs()).max(p.2.abs()));
    let (zmin, zmax) = pts
        .iter()
        .fold((0.0f64, -2.2f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
    // Colour by height (theta2), blue low to red high, with its scale on the right.
    let colour = |y: f64| -> RGBColor {
        let c = HSLColor(0.6 - 0.6 * (y - zmin) / (zmax - zmin + 1e-12), 0.8, 0.45);
        let (r, g, b) = c.rgb();
        RGBColor(r, g, b)
    };
    let (root, right) = root.split_horizontally(root.dim_in_pixel().0 as i32 - 130);
    colour_bar(&right, (zmin, zmax), "theta2 (rad)", &colour)?;
    let root = &root;
    let floor = zmin.min(-2.2);
    let mut chart = ChartBuilder::on(root)
        .caption(
            "Fig. 2: contact surface d(q) = 0 (angle 2 theta3, radius theta1 + pi + 0.5, height theta2)",
            ("sans-serif", 16),
        )
        .margin(10)
        .build_cartesian_3d(-r..r, floor..zmax.max(0.0), -r..r)
        .map_err(err)?;
    chart.with_projection(|mut p| {
        p.pitch = 0.5;
        p.yaw = 0.6;
        p.scale = 0.75;
        p.into_matrix()
    });
    chart.configure_axes().draw().map_err(err)?;
    // Each name below the floor beside the edge plotters puts its ticks on (x along z = r, z along
    // x = r), theta2's above the vertical edge with its ticks (x = -r, z = r).
    axis_names(
        &mut chart,
        [
            (
                "(theta1 + pi + 0.5) cos 2 theta3",
                (-0.9 * r, floor - 0.75, r),
            ),
            ("theta2 (rad)", (-r, zmax.max(0.0) + 0.35, r)),
            (
                "(theta1 + pi + 0.5) sin 2 theta3",
                (r, floor - 0.75, -0.5 * r),
            ),
        ],
    )?;
    chart
        .draw_series(
            pts.iter()
                .map(|&(x, y, z)| Circle::new((x, y, z), 2, colour(y).filled())),
        )
        .map_err(err)?;
    Ok(())
}

/// `theta3` modulo pi in `[cut, cut + pi)`: the axis of Figs. 3 and 4 cut where the cycle does not
/// touch ([`contact_cut`]), so that its contact is drawn in one piece.
fn wrapped(theta3: f64, cut: f64) -> f64 {
    cut + (theta3 - cut).rem_euclid(PI)
}

/// Where to cut theta3 modulo pi for the run's last 20 s: the middle of the widest gap, on the circle of
/// circumference pi, between the theta3 (mod pi) of its steps in contact (impulse above a tenth of the
/// largest), rounded to a tenth; 0 when nothing touches.
fn contact_cut(run: &Run) -> f64 {
    let start = run
        .states
        .len()
        .saturating_sub((20.0 / run.h).round() as usize);
    let top = run.impulses[start..].iter().fold(0.0f64, |m, v| m.max(*v));
    let mut touching: Vec<f64> = (start..run.states.len())
        .filter(|&k| top > 0.0 && run.impulses[k] > 0.1 * top)
        .map(|k| run.states[k][2].rem_euclid(PI))
        .collect();
    if touching.is_empty() {
        return 0.0;
    }
    touching.sort_by(f64::total_cmp);
    let (mut widest, mut cut) = (0.0, 0.0);
    for (i, &a) in touching.iter().enumerate() {
        let b = touching.get(i + 1).copied().unwrap_or(touching[0] + PI);
        if b - a > widest {
            widest = b - a;
            cut = 0.5 * (a + b);
        }
    }
    (cut.rem_euclid(PI) * 10.0).round() / 10.0
}

/// The finger's joint space `(theta1, theta2, theta3 mod pi)` (theta3 in `[cut, cut + pi)`) as a 3-D
/// chart under `caption`, seen at `(pitch, yaw)`, with its axes drawn and named (Figs. 3 and 4).
fn joint_space_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    (pitch, yaw): (f64, f64),
    cut: f64,
) -> anyhow::Result<JointChart<'a, DB>> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(10)
        .build_cartesian_3d(-PI..0.0, -2.2..0.2, cut..cut + PI)
        .map_err(err)?;
    chart.with_projection(|mut p| {
        p.pitch = pitch;
        p.yaw = yaw;
        p.scale = 0.85;
        p.into_matrix()
    });
    // theta1's tick at 0 and theta3's last share the front corner: theta1's is left out there.
    let theta1 = |v: &f64| {
        if v.abs() < 1e-9 {
            String::new()
        } else {
            format!("{v:.1}")
        }
    };
    chart
        .configure_axes()
        .x_formatter(&theta1)
        .draw()
        .map_err(err)?;
    let name = if cut == 0.0 {
        "theta3 mod pi (rad)".to_string()
    } else {
        format!("theta3 mod pi (rad, from {cut:.1})")
    };
    axis_names(
        &mut chart,
        // Beside the edges plotters puts each axis's ticks on: theta1 along theta3 = cut + pi, theta3
        // along theta1 = 0, theta2 up the edge at theta1 = -pi, theta3 = cut + pi.
        [
            ("theta1 (rad)", (-2.2, -2.6, cut + PI)),
            ("theta2 (rad)", (-PI, 0.45, cut + PI)),
            (&name, (0.0, -2.6, cut + 1.2)),
        ],
    )?;
    Ok(chart)
}

/// A 3-D chart over the finger's joint space.
type JointChart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian3d<
        plotters::coord::types::RangedCoordf64,
        plotters::coord::types::RangedCoordf64,
        plotters::coord::types::RangedCoordf64,
    >,
>;

fn draw_states<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    lib: &Library,
    cut: f64,
) -> anyhow::Result<()> {
    let caption = format!(
        "Fig. 3: the library's {} controller states (theta1, theta2, theta3 mod pi)",
        lib.entries.len()
    );
    let mut chart = joint_space_chart(root, &caption, (0.4, 0.7), cut)?;
    chart
        .draw_series(lib.entries.iter().map(|e| {
            let t3 = wrapped(e.x[2], cut);
            Circle::new((e.x[0], e.x[1], t3), 2, BLUE.mix(0.6).filled())
        }))
        .map_err(err)?;
    Ok(())
}

/// A closed-loop run: the states and each step's contact impulse (normal, summed over the contact rows;
/// entry `k` belongs to the step into state `k`).
pub(crate) struct Run {
    pub(crate) states: Vec<Vec<f64>>,
    pub(crate) impulses: Vec<f64>,
    /// Time step.
    pub(crate) h: f64,
}

/// `steps` time steps of the library's policy in closed loop from `x0` on the world of `model` at time
/// step `h`.
pub(crate) fn closed_loop(
    lib: &Library,
    policy: &Policy,
    (model, h): (task::ContactModel, f64),
    x0: &[f64],
    steps: usize,
) -> anyhow::Result<Run> {
    let mut sim = Simulator::new(
        lib.scene().clone(),
        StepSettings {
            model: model.complementarity(),
            h,
            ..StepSettings::default()
        },
    )?;
    let policy = &policy.clone().with_time_step(h)?;
    let mut x = x0.to_vec();
    let mut u = vec![0.0; lib.scene().n_controls];
    let mut states = vec![x.clone()];
    let mut impulses = vec![0.0];
    for _ in 0..steps {
        policy.control(&x, &mut u)?;
        let s = sim.step(&x, &u)?;
        impulses.push(s.normal_impulse());
        x = s.x_next;
        states.push(x.clone());
    }
    Ok(Run {
        states,
        impulses,
        h,
    })
}

/// The run's last 20 s in (theta1, theta2), coloured by contact impulse (blue none, red the run's
/// largest).
pub(crate) fn draw_cycle_2d<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    run: &Run,
    caption: &str,
) -> anyhow::Result<()> {
    let start = run
        .states
        .len()
        .saturating_sub((20.0 / run.h).round() as usize);
    let top = run.impulses[start..].iter().fold(1e-9f64, |m, v| m.max(*v));
    let mut chart = ChartBuilder::on(root)
        .caption(caption, ("sans-serif", 14))
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
        chart
            .draw_series(LineSeries::new(
                [(a[0], a[1]), (b[0], b[1])],
                impulse_colour(run.impulses[k], top).stroke_width(2),
            ))
            .map_err(err)?;
    }
    Ok(())
}

/// The impulse colour scale: blue (none) to red (`top`).
fn impulse_colour(impulse: f64, top: f64) -> RGBColor {
    let w = (impulse / top).clamp(0.0, 1.0);
    RGBColor((40.0 + 215.0 * w) as u8, 60, (200.0 * (1.0 - w)) as u8)
}

/// A vertical colour bar of `colour` over `(lo, hi)`, named `name`, with its ends labelled (and a few
/// values between).
fn colour_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    (lo, hi): (f64, f64),
    name: &str,
    colour: &dyn Fn(f64) -> RGBColor,
) -> anyhow::Result<()> {
    let mut bar = ChartBuilder::on(root)
        .margin_top(60)
        .margin_bottom(60)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..1.0, lo..hi)
        .map_err(err)?;
    bar.configure_mesh()
        .disable_x_mesh()
        .disable_x_axis()
        .disable_y_mesh()
        .y_desc(name)
        .y_labels(6)
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .draw()
        .map_err(err)?;
    let steps = 64;
    bar.draw_series((0..steps).map(|k| {
        let (a, b) = (
            lo + (hi - lo) * k as f64 / steps as f64,
            lo + (hi - lo) * (k + 1) as f64 / steps as f64,
        );
        Rectangle::new([(0.0, a), (1.0, b)], colour(0.5 * (a + b)).filled())
    }))
    .map_err(err)?;
    // The ends, whatever ticks the mesh chose: the bar's top and bottom values above and below it.
    // The plotting area's pixels are the backend's; `root`'s drawing coordinates start at its corner.
    let (x, y) = bar.plotting_area().get_pixel_range();
    let (x0, y0) = root.get_base_pixel();
    let (x, top, bottom) = (x.start - x0, y.start - y0, y.end - y0);
    let style = ("sans-serif", 13).into_font();
    root.draw(&Text::new(format!("{hi:.2}"), (x, top - 18), style.clone()))
        .map_err(err)?;
    root.draw(&Text::new(format!("{lo:.2}"), (x, bottom + 6), style))
        .map_err(err)?;
    Ok(())
}

/// Fig. 4 in the paper's configuration space: the run's last 20 s in (theta1, theta2, theta3 mod pi)
/// over the contact surface (grey), coloured by contact impulse, with the colour scale.
fn draw_cycle_3d<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    run: &Run,
    surface: &[[f64; 3]],
    cut: f64,
) -> anyhow::Result<()> {
    let start = run
        .states
        .len()
        .saturating_sub((20.0 / run.h).round() as usize);
    let top = run.impulses[start..].iter().fold(1e-9f64, |m, v| m.max(*v));
    let (left, right) = root.split_horizontally(root.dim_in_pixel().0 as i32 - 130);
    let mut chart = joint_space_chart(
        &left,
        "Fig. 4: the limit cycle's last 20 s in (theta1, theta2, theta3 mod pi) over the contact surface",
        (0.35, 0.8),
        cut,
    )?;
    chart
        .draw_series(surface.iter().map(|&[a, b, c]| {
            Circle::new((a, b, wrapped(c, cut)), 1, RGBColor(170, 170, 170).filled())
        }))
        .map_err(err)?;
    for k in start + 1..run.states.len() {
        let (a, b) = (&run.states[k - 1], &run.states[k]);
        let (ta, tb) = (wrapped(a[2], cut), wrapped(b[2], cut));
        // theta3 wraps at pi: no segment across the cut.
        if (ta - tb).abs() > PI / 2.0 {
            continue;
        }
        chart
            .draw_series(LineSeries::new(
                [(a[0], a[1], ta), (b[0], b[1], tb)],
                impulse_colour(run.impulses[k], top).stroke_width(3),
            ))
            .map_err(err)?;
    }
    colour_bar(&right, (0.0, top), "contact impulse per step", &|v| {
        impulse_colour(v, top)
    })
}

fn draw_frames<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    scene: &Scene,
    run: &Run,
) -> anyhow::Result<()> {
    // The run's last half turn of the free angle (one cycle: the ellipse's period is pi), in 12 frames.
    let n = scene.n_dof();
    let last = run.states.len() - 1;
    let end_angle = run.states[last][n - 1];
    let first = (0..last)
        .rev()
        .find(|&k| run.states[k][n - 1] <= end_angle - PI)
        .unwrap_or(0);
    let frames = 12;
    let stride = ((last - first) as f64 / (frames - 1) as f64).max(1.0);
    root.titled(
        &format!(
            "Fig. 5: one cycle (the last half turn, {:.2} s) in {frames} frames {:.2} s apart; red arrow: contact impulse on the ellipse",
            (last - first) as f64 * run.h,
            stride * run.h
        ),
        ("sans-serif", 16),
    )
    .map_err(err)?;
    let panels = root.margin(30, 5, 5, 5).split_evenly((3, frames / 3));
    let top = run.impulses[first..].iter().fold(1e-9f64, |m, v| m.max(*v));
    for (p, panel) in panels.iter().enumerate() {
        let k = first + (p as f64 * stride).round() as usize;
        let Some(x) = run.states.get(k) else { break };
        let kin = Kinematics::new(scene, &x[..n]);
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!("t = {:.2} s", (k - first) as f64 * run.h),
                ("sans-serif", 12),
            )
            .build_cartesian_2d(-2.9..1.3, -3.8..0.8)
            .map_err(err)?;
        for i in 0..scene.bodies.len() {
            crate::experiments::draw::draw_body(&mut chart, scene, &kin, i, BLUE.mix(0.25))?;
        }
        let q = &x[..n];
        if let Ok(c) = Constraints::new(scene, &kin, q)
            && run.impulses[k] > library::CONTACT_IMPULSE
            && let Some(f) = c.contacts.first()
        {
            // An arrow from the contact point along the normal into the ellipse, its length the
            // impulse (relative to the cycle's largest): the contact itself stays visible.
            let length = 0.3 + 0.9 * run.impulses[k] / top;
            let (p0, nrm) = (f.point_b, f.normal);
            let p1 = (p0[0] + length * nrm[0], p0[1] + length * nrm[1]);
            chart
                .draw_series(LineSeries::new([(p0[0], p0[1]), p1], RED.stroke_width(3)))
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(Circle::new(
                    (p0[0], p0[1]),
                    4,
                    RED.stroke_width(2),
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
    let policy = lib.policy()?;
    let s = &lib.settings;
    let run = closed_loop(
        lib,
        &policy,
        (s.model, s.h),
        lib.x0(),
        (60.0 / s.h) as usize,
    )?;
    // Figs. 3 and 4 cut theta3 (mod pi) where the cycle does not touch.
    let cut = contact_cut(&run);
    both(
        dir,
        "fig3_library_states",
        (900, 700),
        |r| draw_states(r, lib, cut),
        |r| draw_states(r, lib, cut),
    )?;
    both(
        dir,
        "fig4_limit_cycle",
        (900, 700),
        |r| draw_cycle_3d(r, &run, &surface, cut),
        |r| draw_cycle_3d(r, &run, &surface, cut),
    )?;
    both(
        dir,
        "fig5_frames",
        (1200, 1000),
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

/// Whether `scene` has the flicking finger's shape (three hinges, two of them driven), which the paper's
/// figures (the contact surface over three angles, the cycle over the two finger joints) assume.
fn finger_shaped(scene: &Scene) -> bool {
    scene.n_dof() == 3
        && scene.n_controls == 2
        && scene.bodies.len() == 3
        && scene
            .coordinates
            .iter()
            .all(|c| c.kind == dynamics::CoordinateKind::Angle)
}

/// A task library's figures (any scene): its policy from the library's initial state for 40 s on its own
/// model and on hard contact, the watched entry over time and eight frames.
pub fn write_task(lib: &Library, dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let task = lib.task();
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let task = task::Task {
        x0: lib.x0().to_vec(),
        h: lib.settings.h,
        ..task.clone()
    };
    let policy = lib.policy()?;
    let steps = (40.0 / task.h).round() as usize;
    let mut traces = Vec::new();
    for model in [lib.settings.model, task::ContactModel::Hard] {
        traces.push(closed_loop(lib, &policy, (model, task.h), &task.x0, steps)?.states);
    }
    let holds = lib.progress()?.forward.is_none();
    let files = crate::experiments::task_pictures::task_pictures(
        "task",
        &format!("task {}", task.name),
        holds,
        lib.scene(),
        &task,
        &[(lib.settings.seed, traces.as_slice())],
        dir,
    )?;
    Ok(files
        .iter()
        .flat_map(|p| [p.clone(), p.with_extension("svg")])
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
    let written = if !finger_shaped(lib.scene()) {
        write_task(&lib, &args.out)?
    } else {
        write_all(&lib, &args.out)?
    };
    for p in written {
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
        let lib =
            Library::build(&task::ProblemFile::builtin(), None, &settings, |_, _| {}).unwrap();
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
        // Drawn whole or not at all: no temporary file is left beside the figures.
        let left: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
            .collect();
        assert!(left.is_empty(), "{left:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
