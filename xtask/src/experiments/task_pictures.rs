//! Pictures of any task's closed loops (`cargo xtask examples`, and `cargo xtask figures` for a task
//! library): the entries the task watches over time, and frames of the scene.

use crate::experiments::draw::{self, both, err, register_font};
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use task::Task;

/// The entries the pictures follow: the rewarded coordinate of a progress task, else every position
/// target (`(index, name, target)`).
fn watched(scene: &dynamics::Scene, task: &Task) -> Vec<(usize, String, Option<f64>)> {
    let names = scene.state_names();
    let mut out: Vec<(usize, String, Option<f64>)> = Vec::new();
    let n = scene.n_dof();
    for t in task.cost.running.iter().chain(&task.cost.final_terms) {
        if t.index >= n || out.iter().any(|o| o.0 == t.index) {
            continue;
        }
        out.push((
            t.index,
            names[t.index].clone(),
            (t.quadratic != 0.0).then_some(t.target),
        ));
    }
    out
}

/// Two pictures of a task's closed loops under `out`: `{file}_time` (the watched entry over time, per
/// seed, solid on the smoothed world and dashed on the hard one) and `{file}_frames` (eight frames of the
/// first run: the first four seconds when the task `holds` a target, else the last four). Returns the
/// PNGs' paths (SVGs are written beside them).
pub(crate) fn task_pictures(
    file: &str,
    title: &str,
    holds: bool,
    scene: &dynamics::Scene,
    task: &Task,
    runs: &[(u64, &[Vec<Vec<f64>>])],
    out: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    register_font()?;
    let watched = watched(scene, task);
    let time_name = format!("{file}_time");
    both(
        out,
        &time_name,
        (900, 450),
        |root| time_plot(root, title, task, &watched, runs),
        |root| time_plot(root, title, task, &watched, runs),
    )?;
    let frames_name = format!("{file}_frames");
    let states = &runs[0].1[0];
    both(
        out,
        &frames_name,
        (1200, 640),
        |root| frames(root, title, holds, scene, task, states),
        |root| frames(root, title, holds, scene, task, states),
    )?;
    Ok(vec![
        out.join(format!("{time_name}.png")),
        out.join(format!("{frames_name}.png")),
    ])
}

fn time_plot<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    task: &Task,
    watched: &[(usize, String, Option<f64>)],
    runs: &[(u64, &[Vec<Vec<f64>>])],
) -> anyhow::Result<()> {
    let (i, name, target) = watched
        .first()
        .cloned()
        .ok_or_else(|| anyhow::anyhow!("the task weighs no position"))?;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, traces) in runs {
        for trace in traces.iter() {
            for x in trace {
                lo = lo.min(x[i]);
                hi = hi.max(x[i]);
            }
        }
    }
    if let Some(t) = target {
        lo = lo.min(t);
        hi = hi.max(t);
    }
    let pad = 0.05 * (hi - lo).max(1e-3);
    let t_end = runs[0].1[0].len().saturating_sub(1) as f64 * task.h;
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "{title}: {name} in closed loop from x0, {} seeds (solid: smoothed world, dashed: hard)",
                runs.len()
            ),
            ("sans-serif", 14),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..t_end, lo - pad..hi + pad)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_desc(name.as_str())
        .draw()
        .map_err(err)?;
    if let Some(t) = target {
        chart
            .draw_series(LineSeries::new(
                [(0.0, t), (t_end, t)],
                BLACK.mix(0.5).stroke_width(1),
            ))
            .map_err(err)?;
    }
    for (s, (seed, traces)) in runs.iter().enumerate() {
        let colour = Palette99::pick(s).to_rgba();
        for (w, trace) in traces.iter().enumerate() {
            let points: Vec<(f64, f64)> = trace
                .iter()
                .enumerate()
                .map(|(k, x)| (k as f64 * task.h, x[i]))
                .collect();
            if w == 0 {
                chart
                    .draw_series(LineSeries::new(points, colour.stroke_width(2)))
                    .map_err(err)?
                    .label(format!("seed {seed}"))
                    .legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2))
                    });
            } else {
                chart
                    .draw_series(DashedLineSeries::new(points, 6, 4, colour.stroke_width(1)))
                    .map_err(err)?;
            }
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}

/// Eight frames of the first run on the smoothed world: the first four seconds for a task that `holds`
/// targets (the approach), the last four for a progress task (the steady motion).
fn frames<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    holds: bool,
    scene: &dynamics::Scene,
    task: &Task,
    states: &[Vec<f64>],
) -> anyhow::Result<()> {
    let count = 8;
    let span = ((4.0 / task.h).round() as usize).min(states.len() - 1);
    let first = if holds { 0 } else { states.len() - 1 - span };
    let picked: Vec<usize> = (0..count).map(|k| first + k * span / (count - 1)).collect();
    let window: Vec<Vec<f64>> = picked.iter().map(|&k| states[k].clone()).collect();
    root.titled(
        &format!(
            "{title}: the first run on the smoothed world, {} frames {:.2} s apart",
            count,
            span as f64 * task.h / (count - 1) as f64
        ),
        ("sans-serif", 16),
    )
    .map_err(err)?;
    let panels = root.margin(30, 5, 5, 5).split_evenly((2, count / 2));
    let (w, h) = panels[0].dim_in_pixel();
    let (xr, yr) = draw::bounds(scene, &window, w as f64 / h.max(1) as f64);
    for (panel, &k) in panels.iter().zip(&picked) {
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!("t = {:.2} s", k as f64 * task.h),
                ("sans-serif", 12),
            )
            .build_cartesian_2d(xr.clone(), yr.clone())
            .map_err(err)?;
        draw::draw_static(&mut chart, scene)?;
        draw::draw_bodies(&mut chart, scene, &states[k])?;
    }
    Ok(())
}
