//! The support gap `F(phi)` of two posed ellipses and its global minimisation over the normal angle.
//!
//! For a unit normal `n = (cos phi, sin phi)` let `F(phi) = h_A(n) + h_B(-n)`, where `h_X` is the support
//! function of body X in the world frame. The signed distance of SCENE.md is
//! `d = max_n [min_{p in B} n.p - max_{p in A} n.p] = -min_phi F(phi)`, apart and in penetration alike.
//! With `Delta = c_A - c_B` and body-frame support functions `h_X(psi)`:
//!
//! ```text
//! F   = n.Delta + h_A(phi - theta_A) + h_B(phi - theta_B)
//! F'  = t.Delta + h_A' + h_B'                      (t = n rotated by +90 degrees)
//! F'' = rho_A + rho_B - F                          (h + h'' = rho, the radius of curvature)
//! ```
//!
//! Two facts make the minimisation exact and cheap:
//! - where `F < 0` (a separating direction) `F'' > 0`, and each sublevel set `{F <= -c}` is an arc
//!   (it is the cone where the convex function `h_{A-B}(n) + c |n|` is non-positive); so one separating
//!   direction and a damped Newton descent give the global minimum when the ellipses are apart;
//! - everywhere `F'' + F >= rho_min_A + rho_min_B`; this gives rigorous lower bounds of `F` on an interval
//!   from its end values and slopes (`lower_bound`), so a branch and bound certifies the global minimum in
//!   penetration, where `F` may have several local minima.

use crate::ellipse::{Ellipse, SupportJet};

/// Relative rounding allowance of the certification, in units of `f64::EPSILON` times the problem's scale.
const CERTIFY_ULPS: f64 = 64.0;
/// Intervals of the initial branch-and-bound grid over the full circle.
const INITIAL_CELLS: usize = 4;
/// Budget of gap evaluations for one certification (a safety net; the hardest reference case uses 59).
const MAX_EVALUATIONS: usize = 20_000;
/// Narrowest interval the branch and bound splits, in radians.
const MIN_CELL: f64 = 1e-13;
/// Intervals the branch and bound holds at once, at most: it splits the last one it took, so it holds the
/// initial cells plus one per halving, and `2 pi` halves to [`MIN_CELL`] in 46. Held on the call stack,
/// the certification allocates nothing.
const MAX_OPEN_CELLS: usize = 64;

/// One body as the gap sees it: squared semi-axes and orientation, or a single point (zero axes).
#[derive(Debug, Clone, Copy)]
pub(crate) struct GapBody {
    a2: f64,
    b2: f64,
    cos: f64,
    sin: f64,
    rho_min: f64,
    /// Largest radius of curvature, `max^2 / min`.
    rho_max: f64,
    /// Lipschitz constant of the support value in the angle: `|a^2 - b^2| / (2 min(a, b))`.
    slope_max: f64,
    ellipse: Option<Ellipse>,
}

impl GapBody {
    pub fn ellipse(e: &Ellipse, theta: f64) -> Self {
        let (sin, cos) = theta.sin_cos();
        let (lo, hi) = (e.a().min(e.b()), e.max_axis());
        Self {
            a2: e.a() * e.a(),
            b2: e.b() * e.b(),
            cos,
            sin,
            rho_min: lo * lo / hi,
            rho_max: hi * hi / lo,
            slope_max: (hi * hi - lo * lo) / (2.0 * lo),
            ellipse: Some(*e),
        }
    }

    pub fn point() -> Self {
        Self {
            a2: 0.0,
            b2: 0.0,
            cos: 1.0,
            sin: 0.0,
            rho_min: 0.0,
            rho_max: 0.0,
            slope_max: 0.0,
            ellipse: None,
        }
    }

    /// Support jet along the world direction `(c, s)`.
    #[inline]
    fn jet(&self, c: f64, s: f64) -> SupportJet {
        match &self.ellipse {
            Some(e) => SupportJet::at(e, c * self.cos + s * self.sin, s * self.cos - c * self.sin),
            None => SupportJet {
                h: 0.0,
                dh: 0.0,
                rho: 0.0,
            },
        }
    }

    /// Support point (relative to the body's centre) along the world direction `(c, s)`.
    #[inline]
    pub fn support_offset(&self, c: f64, s: f64) -> [f64; 2] {
        match &self.ellipse {
            Some(_) => {
                let (bc, bs) = (c * self.cos + s * self.sin, s * self.cos - c * self.sin);
                let h = (self.a2 * bc * bc + self.b2 * bs * bs).sqrt();
                let (lx, ly) = (self.a2 * bc / h, self.b2 * bs / h);
                [self.cos * lx - self.sin * ly, self.sin * lx + self.cos * ly]
            }
            None => [0.0, 0.0],
        }
    }

    pub fn max_axis(&self) -> f64 {
        self.a2.max(self.b2).sqrt()
    }
}

/// `F`, `F'`, `F''` at one angle, with the support jets of both bodies.
#[derive(Debug, Clone, Copy)]
pub(crate) struct GapJet {
    pub phi: f64,
    pub cos: f64,
    pub sin: f64,
    pub f: f64,
    pub df: f64,
    pub ddf: f64,
    pub a: SupportJet,
    pub b: SupportJet,
}

/// The support gap of two bodies at fixed poses.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Gap {
    /// `c_A - c_B`.
    pub delta: [f64; 2],
    pub a: GapBody,
    pub b: GapBody,
    /// `|Delta|`, the distance between the centres.
    centre_distance: f64,
    /// Length scale: `|Delta|` plus both largest semi-axes; bounds `|F|` and `|F'|`.
    pub scale: f64,
}

/// The global minimiser of the gap, and what the search learnt about it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct GapMinimum {
    pub jet: GapJet,
    /// Another global minimiser exists (within rounding) away from `jet.phi`.
    pub tie: bool,
    /// The branch and bound finished within its budget (always true for separated bodies).
    pub certified: bool,
    /// Gap evaluations spent.
    pub evaluations: usize,
}

impl Gap {
    pub fn new(center_a: [f64; 2], a: GapBody, center_b: [f64; 2], b: GapBody) -> Self {
        let delta = [center_a[0] - center_b[0], center_a[1] - center_b[1]];
        let centre_distance = delta[0].hypot(delta[1]);
        Self {
            delta,
            a,
            b,
            centre_distance,
            scale: centre_distance + a.max_axis() + b.max_axis(),
        }
    }

    #[inline]
    pub fn eval(&self, phi: f64) -> GapJet {
        let (sin, cos) = phi.sin_cos();
        let a = self.a.jet(cos, sin);
        let b = self.b.jet(cos, sin);
        let f = cos * self.delta[0] + sin * self.delta[1] + a.h + b.h;
        let df = -sin * self.delta[0] + cos * self.delta[1] + a.dh + b.dh;
        let ddf = a.rho + b.rho - f;
        GapJet {
            phi,
            cos,
            sin,
            f,
            df,
            ddf,
            a,
            b,
        }
    }

    fn rounding(&self) -> f64 {
        CERTIFY_ULPS * f64::EPSILON * self.scale
    }

    /// Global minimum of `F`, starting from the angle `start`.
    pub fn minimise(&self, start: f64) -> GapMinimum {
        let (local, evaluations) = self.descend(self.eval(start));
        let evaluations = evaluations + 1;
        if local.f < 0.0 {
            // Separated: F is strictly convex on the arc {F < 0} that holds the global minimum, and the
            // descent never raises F, so the local minimum is the global one.
            return GapMinimum {
                jet: local,
                tie: false,
                certified: true,
                evaluations,
            };
        }
        self.branch_and_bound(local, evaluations)
    }

    /// Damped Newton descent on `F` to a local minimum (safeguarded by an Armijo line search, which
    /// gives way to plain Newton steps once rounding hides the decrease).
    pub fn descend(&self, mut jet: GapJet) -> (GapJet, usize) {
        let floor = self.rounding();
        let mut evaluations = 0;
        for _ in 0..100 {
            if jet.df.abs() <= floor * 1e-3 {
                break;
            }
            let newton = jet.ddf > 0.0;
            let full = if newton {
                (-jet.df / jet.ddf).clamp(-0.5, 0.5)
            } else {
                -jet.df.signum() * 0.5
            };
            let mut step = full;
            let mut accepted = None;
            for _ in 0..60 {
                let cand = self.eval(jet.phi + step);
                evaluations += 1;
                let armijo = cand.f <= jet.f + 1e-4 * step * jet.df;
                let rounding_regime =
                    newton && cand.f <= jet.f + floor && cand.df.abs() < jet.df.abs();
                if armijo || rounding_regime {
                    accepted = Some(cand);
                    break;
                }
                step *= 0.5;
            }
            let Some(cand) = accepted else { break };
            let moved = (cand.phi - jet.phi).abs();
            jet = cand;
            if moved <= 4.0 * f64::EPSILON * jet.phi.abs().max(1.0) {
                break;
            }
        }
        (jet, evaluations)
    }

    /// Certifies (or improves) a local minimum as the global one over the whole circle.
    fn branch_and_bound(&self, mut best: GapJet, mut evaluations: usize) -> GapMinimum {
        let tol = self.rounding();
        let curvature_min = self.a.rho_min + self.b.rho_min;
        let curvature_max = self.a.rho_max + self.b.rho_max + self.centre_distance;
        let mut runner_up: Option<GapJet> = None;
        let mut stack = [(best, best); MAX_OPEN_CELLS];
        let mut open = 0;
        let origin = best.phi;
        let mut left = best;
        for k in 1..=INITIAL_CELLS {
            let phi = origin + std::f64::consts::TAU * k as f64 / INITIAL_CELLS as f64;
            let mut right = self.eval(phi);
            evaluations += 1;
            if k == INITIAL_CELLS {
                // The same angle as the start, one turn on: reuse its values exactly.
                right = GapJet { phi, ..best };
            }
            stack[open] = (left, right);
            open += 1;
            left = right;
        }
        let mut certified = true;
        while open > 0 {
            open -= 1;
            let (l, r) = stack[open];
            if lower_bound(&l, &r, curvature_min) >= best.f - tol
                || self.convex_lower_bound(&l, &r, curvature_max) >= best.f - tol
            {
                continue;
            }
            let width = r.phi - l.phi;
            if width <= MIN_CELL {
                continue;
            }
            if evaluations >= MAX_EVALUATIONS {
                certified = false;
                break;
            }
            let mid = self.eval(l.phi + 0.5 * width);
            evaluations += 1;
            if mid.f < best.f {
                let (local, n) = self.descend(mid);
                evaluations += n;
                if local.f < best.f {
                    if angular_gap(local.phi, best.phi) > 1e-6 {
                        runner_up = Some(best);
                    }
                    best = local;
                }
            }
            if open + 2 > MAX_OPEN_CELLS {
                // Past the halving bound: cannot happen above MIN_CELL, never a panic if it did.
                certified = false;
                break;
            }
            stack[open] = (l, mid);
            stack[open + 1] = (mid, r);
            open += 2;
        }
        // A second minimiser within rounding of the best one, away from it, makes the witnesses ambiguous.
        let tie = runner_up.is_some_and(|r| r.f - best.f <= tol * 16.0)
            || self.centre_distance <= 4.0 * f64::EPSILON * self.scale;
        GapMinimum {
            jet: best,
            tie,
            certified,
            evaluations,
        }
    }

    /// A lower bound of `F` on `[l.phi, r.phi]` that holds where `F` is convex there (else `-inf`).
    ///
    /// On the interval `F <= U := max(F_l, F_r) + F''_max w^2 / 8` with `F''_max = rho_max_A + rho_max_B + |Delta|`,
    /// and each radius of curvature `rho = a^2 b^2 / h^3` is at least its value at the largest support value
    /// `h` can reach (`h` is Lipschitz with `slope_max`). If `rho_A + rho_B - U > 0` the gap is convex on the
    /// interval and lies above both end tangents. This settles the intervals next to a minimum deeper than
    /// `rho_min_A + rho_min_B`, where the sinusoid bound of `lower_bound` would need many bisections.
    fn convex_lower_bound(&self, l: &GapJet, r: &GapJet, curvature_max: f64) -> f64 {
        let w = r.phi - l.phi;
        let upper = l.f.max(r.f) + curvature_max * w * w / 8.0;
        let rho_low = |body: &GapBody, hl: f64, hr: f64| {
            if body.ellipse.is_none() {
                return 0.0;
            }
            let h = 0.5 * (hl + hr) + 0.5 * body.slope_max * w;
            body.a2 * body.b2 / (h * h * h)
        };
        let m = rho_low(&self.a, l.a.h, r.a.h) + rho_low(&self.b, l.b.h, r.b.h) - upper;
        if m.is_nan() || m <= 0.0 {
            return f64::NEG_INFINITY;
        }
        let ends = l.f.min(r.f);
        let denom = l.df - r.df;
        if denom >= 0.0 {
            return ends;
        }
        // Tangents F_l + F'_l x and F_r + F'_r (x - w) cross at x.
        let x = (r.f - r.df * w - l.f) / denom;
        if x > 0.0 && x < w {
            ends.min(l.f + l.df * x)
        } else {
            ends
        }
    }
}

/// Smallest angle between two angles on the circle.
fn angular_gap(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

/// A rigorous lower bound of `F` on `[l.phi, r.phi]` (an interval no wider than pi).
///
/// `G = F - P` with `P = rho_min_A + rho_min_B` obeys `G'' + G = rho_A + rho_B - P >= 0`, so by Sturm
/// comparison `G` lies above the sinusoid that matches its value and slope at either end of the interval
/// (the property of support functions behind Blaschke's rolling theorem). The bound is the minimum over the
/// interval of the larger of the two sinusoids: at an end, where they cross, or at a trough of either.
fn lower_bound(l: &GapJet, r: &GapJet, curvature_min: f64) -> f64 {
    let w = r.phi - l.phi;
    let (sw, cw) = w.sin_cos();
    // Both sinusoids as P + u cos x + v sin x, with x measured from the left end.
    let (ul, vl) = (l.f - curvature_min, l.df);
    let (ur, vr) = (
        (r.f - curvature_min) * cw - r.df * sw,
        (r.f - curvature_min) * sw + r.df * cw,
    );
    // Candidate points are handled by their (cos, sin): a point with sin > 0 lies inside (0, w) iff its
    // cosine exceeds cos w (w <= pi), so no angle is ever formed.
    let upper = |c: f64, s: f64| (ul * c + vl * s).max(ur * c + vr * s);
    let mut lowest = ul.max(ur).min(upper(cw, sw));
    let mut consider = |c: f64, s: f64| {
        if s > 0.0 && c > cw {
            lowest = lowest.min(upper(c, s));
        }
    };
    // Crossing: (ul - ur) cos x + (vl - vr) sin x = 0, i.e. (cos x, sin x) parallel to (vl - vr, ur - ul).
    let (cx, sx) = (vl - vr, ur - ul);
    let norm = (cx * cx + sx * sx).sqrt();
    if norm > 0.0 {
        let sign = if sx < 0.0 { -1.0 } else { 1.0 };
        consider(sign * cx / norm, sign * sx / norm);
    }
    // Troughs of u cos x + v sin x lie at (cos, sin) = -(u, v) / |(u, v)|.
    for (u, v) in [(ul, vl), (ur, vr)] {
        let norm = (u * u + v * v).sqrt();
        if norm > 0.0 {
            consider(-u / norm, -v / norm);
        }
    }
    curvature_min + lowest
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body(a: f64, b: f64, theta: f64) -> GapBody {
        GapBody::ellipse(&Ellipse::new(a, b).unwrap(), theta)
    }

    #[test]
    fn gap_derivatives_match_central_differences() {
        let gap = Gap::new(
            [0.3, -0.2],
            body(1.0, 0.3, 0.4),
            [1.1, 0.9],
            body(0.7, 0.5, -1.0),
        );
        for phi in [0.0, 0.7, 2.0, -2.5] {
            let j = gap.eval(phi);
            let e = 1e-5;
            let (p, m) = (gap.eval(phi + e), gap.eval(phi - e));
            assert!(((p.f - m.f) / (2.0 * e) - j.df).abs() < 1e-8);
            assert!(((p.df - m.df) / (2.0 * e) - j.ddf).abs() < 1e-8);
        }
    }

    #[test]
    fn lower_bound_never_exceeds_sampled_values() {
        let gap = Gap::new(
            [0.1, 0.0],
            body(2.0, 0.02, 0.3),
            [0.0, 0.05],
            body(0.7, 0.5, 1.0),
        );
        let kmin = gap.a.rho_min + gap.b.rho_min;
        let kmax = gap.a.rho_max + gap.b.rho_max + gap.centre_distance;
        for i in 0..200 {
            let lo = i as f64 * 0.03;
            for w in [1e-3, 0.05, 0.4, 1.5, 3.0] {
                let (l, r) = (gap.eval(lo), gap.eval(lo + w));
                let lb = lower_bound(&l, &r, kmin).max(gap.convex_lower_bound(&l, &r, kmax));
                let sampled = (0..=50)
                    .map(|k| gap.eval(lo + w * k as f64 / 50.0).f)
                    .fold(f64::INFINITY, f64::min);
                assert!(lb <= sampled + 1e-12, "bound {lb} above sample {sampled}");
            }
        }
    }

    #[test]
    fn branch_and_bound_finds_the_deeper_of_two_escape_directions() {
        // A long thin ellipse across a circle, off-centre: escaping up or down are both local minima.
        let gap = Gap::new(
            [0.0, 0.1],
            body(3.0, 0.2, 0.0),
            [0.0, 0.0],
            body(1.0, 1.0, 0.0),
        );
        let from_wrong_side = gap.minimise(std::f64::consts::FRAC_PI_2);
        let dense = (0..100_000)
            .map(|k| gap.eval(k as f64 * std::f64::consts::TAU / 100_000.0).f)
            .fold(f64::INFINITY, f64::min);
        assert!(from_wrong_side.certified);
        assert!((from_wrong_side.jet.f - dense).abs() < 1e-9);
        assert!(from_wrong_side.jet.f <= dense + 1e-15);
    }
}
