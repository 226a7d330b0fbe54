//! Drawing for every picture of the experiments: the bundled font, the PNG-and-SVG writer ([`both`]),
//! and any scene (its bodies at a state, its half-planes and fixed ellipses) in a plotters chart.

use anyhow::anyhow;
use dynamics::{Kinematics, Scene};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::f64::consts::PI;
use std::path::Path;

static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

pub(crate) fn register_font() -> anyhow::Result<()> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| anyhow!("the bundled font does not load"))
}

pub(crate) fn err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("drawing: {e:?}")
}

/// Draw with `f` into `name.png` and `name.svg` under `dir`.
pub(crate) fn both(
    dir: &Path,
    name: &str,
    size: (u32, u32),
    f: impl Fn(&DrawingArea<BitMapBackend, Shift>) -> anyhow::Result<()>,
    g: impl Fn(&DrawingArea<SVGBackend, Shift>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    // Each picture whole or not at all: the PNG drawn into memory (RGB) and encoded, the SVG drawn into
    // memory, each written atomically (a failed draw never leaves half a figure).
    let mut pixels = vec![0u8; 3 * size.0 as usize * size.1 as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        f(&root)?;
        root.present().map_err(err)?;
    }
    let mut encoded = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut encoded, size.0, size.1);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        // Figures are committed: the smallest file (an adaptive filter per row, the strongest deflate)
        // over the fastest encoding, which doubled their size.
        encoder.set_compression(png::Compression::Best);
        encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
        let mut writer = encoder.write_header().map_err(err)?;
        writer.write_image_data(&pixels).map_err(err)?;
        writer.finish().map_err(err)?;
    }
    crate::write_file(dir.join(format!("{name}.png")), encoded)?;
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        g(&root)?;
        root.present().map_err(err)?;
    }
    crate::write_file(dir.join(format!("{name}.svg")), text)?;
    Ok(())
}

/// A 2-D chart in world coordinates.
pub(crate) type WorldChart<'a, DB> =
    ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// An ellipse's outline, 48 segments.
pub(crate) fn ellipse_outline(c: [f64; 2], phi: f64, a: f64, b: f64) -> Vec<(f64, f64)> {
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

/// A square-ish window `(x range, y range)` holding every body over `states`, the fixed ellipses and a
/// strip of each half-plane, with a margin, stretched to the aspect `width / height`.
pub(crate) fn bounds(
    scene: &Scene,
    states: &[Vec<f64>],
    aspect: f64,
) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let n = scene.n_dof();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    fn cover(lo: &mut [f64; 2], hi: &mut [f64; 2], c: [f64; 2], r: f64) {
        for k in 0..2 {
            lo[k] = lo[k].min(c[k] - r);
            hi[k] = hi[k].max(c[k] + r);
        }
    }
    for x in states {
        let kin = Kinematics::new(scene, &x[..n]);
        for (i, b) in scene.bodies.iter().enumerate() {
            cover(
                &mut lo,
                &mut hi,
                kin.centre[i],
                b.shape.a().max(b.shape.b()),
            );
        }
    }
    for f in &scene.fixed {
        cover(
            &mut lo,
            &mut hi,
            [f.pose[0], f.pose[1]],
            f.shape.a().max(f.shape.b()),
        );
    }
    if !lo[0].is_finite() {
        (lo, hi) = ([-1.0; 2], [1.0; 2]);
    }
    for p in &scene.planes {
        // The boundary's point nearest the window's centre, and a little of the solid side below it.
        let (o, nrm) = (p.shape.point(), p.shape.normal());
        let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        let s = (mid[0] - o[0]) * nrm[0] + (mid[1] - o[1]) * nrm[1];
        let foot = [mid[0] - s * nrm[0], mid[1] - s * nrm[1]];
        if foot.iter().all(|v| v.abs() < 1e3) {
            cover(&mut lo, &mut hi, foot, 0.0);
            cover(
                &mut lo,
                &mut hi,
                [foot[0] - 0.2 * nrm[0], foot[1] - 0.2 * nrm[1]],
                0.0,
            );
        }
    }
    let margin = 0.15;
    let (mut w, mut h) = (hi[0] - lo[0] + 2.0 * margin, hi[1] - lo[1] + 2.0 * margin);
    if w / h < aspect {
        w = h * aspect;
    } else {
        h = w / aspect;
    }
    let c = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    (
        c[0] - w / 2.0..c[0] + w / 2.0,
        c[1] - h / 2.0..c[1] + h / 2.0,
    )
}

/// The part of the window `[x0, x1] x [y0, y1]` on the solid side of the line through `o` with outward
/// normal `nrm` (one clip of the window's rectangle).
fn solid_part(o: [f64; 2], nrm: [f64; 2], x: (f64, f64), y: (f64, f64)) -> Vec<(f64, f64)> {
    let corners = [(x.0, y.0), (x.1, y.0), (x.1, y.1), (x.0, y.1)];
    let side = |p: (f64, f64)| (p.0 - o[0]) * nrm[0] + (p.1 - o[1]) * nrm[1];
    let mut out = Vec::new();
    for k in 0..4 {
        let (p, q) = (corners[k], corners[(k + 1) % 4]);
        let (sp, sq) = (side(p), side(q));
        if sp <= 0.0 {
            out.push(p);
        }
        if (sp < 0.0) != (sq < 0.0) && sp != sq {
            let t = sp / (sp - sq);
            out.push((p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1)));
        }
    }
    out
}

/// Draw the scene's static world (half-planes hatched grey, fixed ellipses grey) into `chart`.
pub(crate) fn draw_static<DB: DrawingBackend>(
    chart: &mut WorldChart<'_, DB>,
    scene: &Scene,
) -> anyhow::Result<()> {
    let (xr, yr) = (chart.x_range(), chart.y_range());
    for p in &scene.planes {
        let part = solid_part(
            p.shape.point(),
            p.shape.normal(),
            (xr.start, xr.end),
            (yr.start, yr.end),
        );
        if part.len() >= 3 {
            chart
                .draw_series(std::iter::once(Polygon::new(
                    part,
                    RGBColor(150, 150, 150).mix(0.5).filled(),
                )))
                .map_err(err)?;
        }
    }
    for f in &scene.fixed {
        draw_ellipse(
            chart,
            ([f.pose[0], f.pose[1]], f.pose[2]),
            (f.shape.a(), f.shape.b()),
            RGBColor(120, 120, 120).mix(0.6),
        )?;
    }
    Ok(())
}

/// An ellipse filled with `fill` and outlined in black.
fn draw_ellipse<DB: DrawingBackend>(
    chart: &mut WorldChart<'_, DB>,
    (c, phi): ([f64; 2], f64),
    (a, b): (f64, f64),
    fill: RGBAColor,
) -> anyhow::Result<()> {
    let outline = ellipse_outline(c, phi, a, b);
    chart
        .draw_series(std::iter::once(Polygon::new(
            outline.clone(),
            fill.filled(),
        )))
        .map_err(err)?;
    chart
        .draw_series(LineSeries::new(outline, BLACK.stroke_width(1)))
        .map_err(err)?;
    Ok(())
}

/// Draw body `i` of `scene` posed by `kin`, filled with `fill`; a passive body also gets its major axis
/// with one end marked, so that its turning shows.
pub(crate) fn draw_body<DB: DrawingBackend>(
    chart: &mut WorldChart<'_, DB>,
    scene: &Scene,
    kin: &Kinematics,
    i: usize,
    fill: RGBAColor,
) -> anyhow::Result<()> {
    let shape = &scene.bodies[i].shape;
    let (a, b) = (shape.a(), shape.b());
    let (c, phi) = (kin.centre[i], kin.phi[i]);
    draw_ellipse(chart, (c, phi), (a, b), fill)?;
    if !scene.actuated(i) {
        let tip = (c[0] + a * phi.cos(), c[1] + a * phi.sin());
        chart
            .draw_series(LineSeries::new(
                [(c[0] - a * phi.cos(), c[1] - a * phi.sin()), tip],
                BLACK.stroke_width(1),
            ))
            .map_err(err)?;
        chart
            .draw_series(std::iter::once(Circle::new(tip, 3, BLACK.filled())))
            .map_err(err)?;
    }
    Ok(())
}

/// Draw the scene's bodies at state `x`: actuated bodies blue, passive ones orange with their major
/// axis and one end marked.
pub(crate) fn draw_bodies<DB: DrawingBackend>(
    chart: &mut WorldChart<'_, DB>,
    scene: &Scene,
    x: &[f64],
) -> anyhow::Result<()> {
    let kin = Kinematics::new(scene, &x[..scene.n_dof()]);
    for i in 0..scene.bodies.len() {
        let fill = if !scene.actuated(i) {
            RGBColor(240, 150, 40).mix(0.35)
        } else {
            BLUE.mix(0.25)
        };
        draw_body(chart, scene, &kin, i, fill)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_solid_side_of_a_ground_is_the_window_below_it() {
        let part = solid_part([0.0, 0.0], [0.0, 1.0], (-1.0, 1.0), (-1.0, 2.0));
        let area: f64 = (0..part.len())
            .map(|k| {
                let (p, q) = (part[k], part[(k + 1) % part.len()]);
                p.0 * q.1 - q.0 * p.1
            })
            .sum::<f64>()
            / 2.0;
        assert!((area.abs() - 2.0).abs() < 1e-12, "{part:?}");
        // A wall wholly outside the window leaves nothing solid in it.
        assert!(solid_part([-5.0, 0.0], [1.0, 0.0], (-1.0, 1.0), (-1.0, 1.0)).is_empty());
    }

    #[test]
    fn the_window_holds_the_ground_and_the_block_of_the_pushing_scene() {
        let problem =
            task::ProblemFile::from_toml_str(include_str!("../../../scenes/pushing.toml")).unwrap();
        let task = problem.task(Some("push")).unwrap();
        let (xr, yr) = bounds(&problem.scene, std::slice::from_ref(&task.x0), 1.5);
        assert!(yr.start < -0.05 && yr.end > 0.4, "{yr:?}");
        assert!(xr.start < -0.3 && xr.end > 0.3, "{xr:?}");
        assert!(((xr.end - xr.start) / (yr.end - yr.start) - 1.5).abs() < 1e-9);
    }
}
