//! Issue 27: contact that never creates energy and never lets a body sink, for every model and any
//! `recovery`, as laws over random scenes; and the position-level recovery's exact derivatives.
//!
//! The energy law. With `M(q) (v' - v) = h r(q, v) + J^T lambda`, `q' = q + dq + h v'` (`dq` the
//! position-level correction) and `E = 1/2 v^T M(q) v + PE(q)`, one step changes the energy by exactly
//!
//! ```text
//! E' - E = lambda^T J v' - 1/2 dv^T M dv + D + C,
//! D = 1/2 v'^T (M(q') - M(q)) v' + h v'^T (r(q, v) - r(q, 0)) + PE(q + h v') - PE(q) + h r(q, 0)^T v',
//! C = PE(q') - PE(q + h v'),
//! ```
//!
//! (no drag, no input: `r(q, 0)` is gravity's generalised force). `D` is the integrator's own drift
//! (semi-implicit Euler with `M` and the Coriolis forces frozen at the start of the step): zero for free
//! bodies, whose `M` is constant and whose potential is linear, O(h^2) a step for chains. `C` is the
//! potential energy the position-level correction gives back: it lifts a body out of the penetration a
//! linearised step left (a rolling ellipse dips by half its curvature times the squared angle turned), by at
//! most that depth. And the contact's work `lambda^T J v' = sum_i lambda_i (w_i - d~_i / h)` with
//! `w = d~ / h + J v'` and `d~ = max(d, -recovery)`: with the default recovery (0) `d~ >= 0`, so the work is
//! at most `sum_i lambda_i w_i`, zero for the hard model (complementarity) and the smoothing's own work
//! for the others. Hence the law each step must keep, to rounding:
//!
//! ```text
//! E' <= E + sum_i lambda_i max(w_i, 0) + D + C.
//! ```
//!
//! SCENE.md's velocity-level recovery (`recovery = None`) breaks it by `lambda |d| / h` in every step
//! that pushes a penetration out: that was the rocking ellipse that rolled for ever.

use dynamics::{Complementarity, Kinematics, Scene, Simulator, StepSettings};
use proptest::prelude::*;

fn potential(scene: &Scene, q: &[f64]) -> f64 {
    let kin = Kinematics::new(scene, q);
    scene
        .bodies
        .iter()
        .zip(&kin.centre)
        .map(|(b, c)| -b.mass * (scene.gravity[0] * c[0] + scene.gravity[1] * c[1]))
        .sum()
}

fn kinetic(scene: &Scene, q: &[f64], v: &[f64]) -> f64 {
    let n = scene.n_dof();
    let m = Kinematics::new(scene, q).mass_matrix(scene);
    (0..n * n).map(|e| 0.5 * v[e / n] * m[e] * v[e % n]).sum()
}

fn energy(scene: &Scene, x: &[f64]) -> f64 {
    let n = scene.n_dof();
    kinetic(scene, &x[..n], &x[n..]) + potential(scene, &x[..n])
}

/// What one step from `x` may add to the energy (module documentation): the smoothing's work, the
/// integrator's drift and the correction's potential energy, each returned.
fn allowance(sim: &Simulator, x: &[f64], step: &dynamics::Step) -> [f64; 3] {
    let scene = sim.scene();
    let (n, h) = (scene.n_dof(), sim.settings().h);
    let (q, v) = x.split_at(n);
    let vn = &step.x_next[n..];
    let (problem, _) = sim.problem(x, &vec![0.0; scene.n_controls]).unwrap();
    let mut z = vn.to_vec();
    z.extend_from_slice(&step.lambda);
    let mut f = vec![0.0; z.len()];
    ncp::Mcp::evaluate(&problem, &z, &mut f, None);
    let work: f64 = step
        .lambda
        .iter()
        .zip(&f[n..])
        .map(|(l, w)| l * w.max(0.0))
        .sum();
    let linear: Vec<f64> = (0..n).map(|i| q[i] + h * vn[i]).collect();
    let kin = Kinematics::new(scene, q);
    let gravity = kin.bias_forces(scene, &vec![0.0; n]);
    let bias = kin.bias_forces(scene, v);
    let m0 = kin.mass_matrix(scene);
    let m1 = Kinematics::new(scene, &step.x_next[..n]).mass_matrix(scene);
    let mut drift = potential(scene, &linear) - potential(scene, q);
    for i in 0..n {
        drift += h * vn[i] * (bias[i] - gravity[i]) + h * gravity[i] * vn[i];
        for j in 0..n {
            drift += 0.5 * vn[i] * (m1[i * n + j] - m0[i * n + j]) * vn[j];
        }
    }
    let correction = potential(scene, &step.x_next[..n]) - potential(scene, &linear);
    [work, drift, correction]
}

/// A random drop scene: free ellipses above a ground (tilted by up to 0.3 rad), some pairs between them,
/// and optionally a drag-free two-link chain hinged above the ground, its lower link in contact with it.
#[derive(Debug, Clone)]
struct Drop {
    bodies: Vec<([f64; 2], f64, [f64; 3], f64)>,
    chain: Option<(f64, f64)>,
    tilt: f64,
    gravity: f64,
    friction: f64,
    pairs: bool,
    h: f64,
}

impl Drop {
    fn toml(&self) -> String {
        let (s, c) = self.tilt.sin_cos();
        let mut t = format!(
            "gravity = [0.0, {}]\n[[plane]]\nname = \"ground\"\npoint = [0.0, 0.0]\nnormal = [{}, {}]\n",
            -self.gravity, -s, c
        );
        for (i, (axes, density, _, _)) in self.bodies.iter().enumerate() {
            t += &format!(
                "[[body]]\nname = \"e{i}\"\nsemi_axes = [{}, {}]\ndensity = {density}\nparent = \"world\"\nanchor = [0.0, 0.0]\ncentre = [0.0, 0.0]\njoint = {{ type = \"free\" }}\n[[contact]]\na = \"ground\"\nb = \"e{i}\"\nfriction = {}\n",
                axes[0], axes[1], self.friction
            );
        }
        if self.pairs {
            for i in 0..self.bodies.len() {
                for j in i + 1..self.bodies.len() {
                    t += &format!(
                        "[[contact]]\na = \"e{i}\"\nb = \"e{j}\"\nfriction = {}\n",
                        self.friction * 0.5
                    );
                }
            }
        }
        if let Some((len, density)) = self.chain {
            t += &format!(
                "[[body]]\nname = \"upper\"\nsemi_axes = [{len}, 0.05]\ndensity = {density}\nparent = \"world\"\nanchor = [-2.0, {}]\ncentre = [{len}, 0.0]\njoint = {{}}\n[[body]]\nname = \"lower\"\nsemi_axes = [{len}, 0.05]\ndensity = {density}\nparent = \"upper\"\nanchor = [{}, 0.0]\ncentre = [{len}, 0.0]\njoint = {{}}\n[[contact]]\na = \"ground\"\nb = \"lower\"\nfriction = {}\n",
                1.5 * len,
                2.0 * len,
                self.friction
            );
        }
        t
    }

    /// Free bodies at their drop poses at rest, the chain horizontal.
    fn x0(&self, scene: &Scene) -> Vec<f64> {
        let mut x = vec![0.0; scene.n_state()];
        for (i, (_, _, pose, spin)) in self.bodies.iter().enumerate() {
            x[3 * i..3 * i + 3].copy_from_slice(pose);
            x[scene.n_dof() + 3 * i + 2] = *spin;
        }
        x
    }
}

fn drops() -> impl Strategy<Value = Drop> {
    let body = (
        0.05f64..0.5,
        1.0f64..12.0,
        0.2f64..5.0,
        -1.5f64..1.5,
        -3.0f64..3.0,
        -2.0f64..2.0,
    );
    (
        proptest::collection::vec(body, 1..=3),
        proptest::option::of((0.2f64..0.5, 0.3f64..3.0)),
        -0.3f64..0.3,
        1.0f64..10.0,
        0.0f64..1.5,
        any::<bool>(),
        0.005f64..0.05,
    )
        .prop_map(|(bodies, chain, tilt, gravity, friction, pairs, h)| {
            let bodies: Vec<_> = bodies
                .into_iter()
                .enumerate()
                .map(|(i, (a, ratio, density, x, angle, spin))| {
                    let b = a / ratio.max(1.0);
                    // Stacked above each other, clear of the ground and of one another.
                    let y = 0.6 + 1.2 * i as f64 + x.abs() * 0.3;
                    ([a, b], density, [x, y, angle], spin)
                })
                .collect();
            // The time step resolves the fall: the fastest impact moves a body less than its shortest
            // semi-major axis in one step. Past that a body can pass through the ground within a step
            // (tunnelling: a step sees a contact only where it starts), which no recovery undoes; the
            // cure is a smaller h, as docs/complementarity.md says.
            let speed = bodies
                .iter()
                .map(|b| (2.0 * gravity * b.2[1]).sqrt() + b.3.abs() * b.0[0])
                .chain(chain.map(|c| (2.0 * gravity * 4.0 * c.0).sqrt()))
                .fold(0.0f64, f64::max);
            let shortest = bodies
                .iter()
                .map(|b| b.0[0])
                .chain(chain.map(|c| c.0))
                .fold(f64::INFINITY, f64::min);
            let h = h.min(0.9 * shortest / speed);
            let mut drop = Drop {
                bodies,
                chain,
                tilt,
                gravity,
                friction,
                pairs,
                h,
            };
            // And it resolves the rocking of a body lying flat, even under the weight of all the others
            // (`loaded_rocking_limit`): past it semi-implicit Euler cannot keep a needle at rest, as
            // `a_needle_rests_below_its_rocking_limit_and_not_above` shows.
            let scene = Scene::from_toml_str(&drop.toml()).unwrap();
            if let Some(limit) = loaded_rocking_limit(&scene) {
                drop.h = drop.h.min(0.9 * limit);
            }
            drop
        })
}

/// [`Scene::rocking_limit`] with each free body on the ground carrying every free body of the scene: a
/// thin needle a heavy ellipse lies on rocks faster by the root of the mass ratio (a needle of 0.008 under
/// an ellipse of 0.6 rocked at 400 rad/s, and semi-implicit Euler at h = 0.012 turned it through flat
/// every step). The rocking frequency `omega^2 = g_n (a^2/b - b) m / I` grows with the load carried;
/// scaling the scene's limit by the root of the lightest free body's share of them all bounds it below.
fn loaded_rocking_limit(scene: &Scene) -> Option<f64> {
    let free: f64 = scene
        .bodies
        .iter()
        .filter(|b| b.parent.is_none())
        .map(|b| b.mass)
        .sum();
    let lightest = scene
        .bodies
        .iter()
        .filter(|b| b.parent.is_none())
        .map(|b| b.mass)
        .fold(f64::INFINITY, f64::min);
    scene
        .rocking_limit()
        .map(|limit| limit * (lightest / free).sqrt())
}

/// Run `drop` for `seconds` under `model`; check the energy law every step from the first impact on, that
/// no body is ever entirely below the ground, and with `ends_above` that every centre ends above it; return
/// the energy after the first impact and the largest later.
fn check_drop(
    drop: &Drop,
    model: Complementarity,
    seconds: f64,
    ends_above: bool,
) -> Result<(f64, f64), TestCaseError> {
    let scene = Scene::from_toml_str(&drop.toml()).unwrap();
    let settings = StepSettings {
        model,
        h: drop.h,
        ..StepSettings::default()
    };
    let mut sim = Simulator::new(scene.clone(), settings).unwrap();
    let mut x = drop.x0(&scene);
    let steps = (seconds / drop.h) as usize;

    let (mut after, mut highest) = (None, f64::NEG_INFINITY);
    let u = vec![0.0; scene.n_controls];
    for k in 0..steps {
        let step = match sim.step(&x, &u) {
            Ok(s) => s,
            Err(e) => return Err(TestCaseError::fail(format!("step {k}: {e}"))),
        };
        prop_assert!(
            step.info.status == ncp::Status::Converged,
            "step {k}: {:?}",
            step.info.status
        );
        let e0 = energy(&scene, &x);
        let e1 = energy(&scene, &step.x_next);
        let [work, drift, correction] = allowance(&sim, &x, &step);
        let tolerance = 1e-9 * (1.0 + e0.abs()) + 1e-9 * step.lambda.iter().sum::<f64>();
        prop_assert!(
            e1 <= e0 + work + drift + correction + tolerance,
            "step {k}: energy {e1} from {e0}: +{} over work {work}, drift {drift}, correction {correction}",
            e1 - e0
        );
        // Nothing sinks through the ground: no free body whose motion the step resolved (no point of it
        // moved by more than its minor semi-axis, `h (|v'| + a |omega'|) <= b`) is left entirely below it
        // (its highest point, the centre's height plus the support radius along the normal, stays above).
        // A step cannot resolve more: a thin needle that a heavy body lands on near its tip spins at
        // hundreds of rad/s, and a linearised step turns it by radians; the correction then lifts it
        // back, which the end of the run checks.
        let n = scene.n_dof();
        for (i, height) in heights(&scene, drop.tilt, &step.x_next)
            .into_iter()
            .enumerate()
            .take(drop.bodies.len())
        {
            let v = &step.x_next[n + 3 * i..n + 3 * i + 3];
            let [a, b] = drop.bodies[i].0;
            let resolved = drop.h * (v[0].hypot(v[1]) + a * v[2].abs()) <= b;
            prop_assert!(
                !resolved || height[0] + height[1] > 0.0,
                "step {k}: body {i} entirely below the ground (centre at {}, reach {})",
                height[0],
                height[1]
            );
        }
        if after.is_none() && step.lambda.iter().any(|&l| l > 1e-9) {
            after = Some(e1);
        } else if after.is_some() {
            highest = highest.max(e1);
        }
        x = step.x_next.clone();
    }
    if ends_above {
        // And nothing stays sunk: at the end every free body's centre is above the ground (the chain's
        // hinge may be below a tilted ground, only its lower link touching it).
        for (i, height) in heights(&scene, drop.tilt, &x)
            .into_iter()
            .enumerate()
            .take(drop.bodies.len())
        {
            prop_assert!(
                height[0] > 0.0,
                "body {i}'s centre ends {} below the ground",
                -height[0]
            );
        }
    }
    Ok((after.unwrap_or(f64::NAN), highest))
}

/// Each body's centre height above the ground (tilted by `tilt`) and its reach along the ground's normal
/// (the support radius `sqrt(a^2 (n . e1)^2 + b^2 (n . e2)^2)`).
fn heights(scene: &Scene, tilt: f64, x: &[f64]) -> Vec<[f64; 2]> {
    let kin = Kinematics::new(scene, &x[..scene.n_dof()]);
    let (s, c) = tilt.sin_cos();
    let normal = [-s, c];
    scene
        .bodies
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let (sp, cp) = kin.phi[i].sin_cos();
            let along = normal[0] * cp + normal[1] * sp;
            let across = -normal[0] * sp + normal[1] * cp;
            let reach =
                (b.shape.a().powi(2) * along.powi(2) + b.shape.b().powi(2) * across.powi(2)).sqrt();
            [
                normal[0] * kin.centre[i][0] + normal[1] * kin.centre[i][1],
                reach,
            ]
        })
        .collect()
}

proptest! {
    // 24 drops by default; `DROPS=4000` widens the draw (a few seconds in release).
    #![proptest_config(ProptestConfig {
        cases: std::env::var("DROPS").ok().and_then(|s| s.parse().ok()).unwrap_or(24),
        ..ProptestConfig::default()
    })]
    #[test]
    fn contact_never_creates_energy_and_nothing_sinks_in_random_drops(
        drop in drops(),
        model in 0usize..4,
    ) {
        let model = [
            Complementarity::Hard,
            Complementarity::Logistic { sigma: 0.1 },
            Complementarity::Logistic { sigma: 0.02 },
            Complementarity::Normal { sigma: 0.05 },
        ][model];
        check_drop(&drop, model, 3.0, true)?;
    }
}

/// The issue's reproducer: a free ellipse (semi-axes 0.4, 0.25, gravity 4) dropped from height 1 at angle
/// 0.6 onto the ground. After the impact its energy is below the 0.503 that standing on end needs; with
/// SCENE.md's velocity-level recovery the hard model climbed above 0.52 and rolled for ever (39.5 rad after
/// 50 s). Now it rocks and never turns over, at h = 0.05 and 0.01; and it never sinks, with any recovery.
#[test]
fn the_rocking_ellipse_never_rolls_over_nor_sinks() {
    let text = "gravity = [0.0, -4.0]\n[[plane]]\nname = \"ground\"\npoint = [0.0, 0.0]\nnormal = [0.0, 1.0]\n\
        [[body]]\nname = \"block\"\nsemi_axes = [0.4, 0.25]\nparent = \"world\"\nanchor = [0.0, 0.0]\n\
        centre = [0.0, 0.0]\njoint = { type = \"free\" }\n[[contact]]\na = \"ground\"\nb = \"block\"\nfriction = 0.5\n";
    let scene = Scene::from_toml_str(text).unwrap();
    let standing = scene.bodies[0].mass * 4.0 * 0.4;
    for h in [0.05, 0.01] {
        for (model, recovery) in [
            (Complementarity::Hard, Some(0.0)),
            (Complementarity::Logistic { sigma: 0.1 }, Some(0.0)),
            (Complementarity::Hard, Some(0.01)),
            (Complementarity::Logistic { sigma: 0.1 }, Some(0.01)),
            (Complementarity::Hard, None),
        ] {
            let mut sim = Simulator::new(
                scene.clone(),
                StepSettings {
                    model,
                    h,
                    recovery,
                    ..StepSettings::default()
                },
            )
            .unwrap();
            let mut x = vec![0.0, 1.0, 0.6, 0.0, 0.0, 0.0];
            let mut lowest = f64::INFINITY;
            let mut highest_after = f64::NEG_INFINITY;
            // The impact takes the first two steps in contact; the energy is judged after them.
            let mut touching = 0;
            for _ in 0..(20.0 / h) as usize {
                let s = sim.step(&x, &[]).unwrap();
                touching += usize::from(touching > 0 || s.lambda.iter().any(|&l| l > 1e-9));
                x = s.x_next;
                lowest = lowest.min(x[1]);
                if touching > 2 {
                    highest_after = highest_after.max(energy(&scene, &x));
                }
            }
            // Never sinks: the centre stays above the minor semi-axis less a small part of it.
            assert!(
                lowest > 0.2,
                "{model:?} h {h} recovery {recovery:?}: centre at {lowest}"
            );
            if recovery == Some(0.0) && model == Complementarity::Hard {
                assert!(
                    highest_after < standing,
                    "{model:?} h {h}: energy {highest_after} reached the {standing} of standing on end"
                );
            }
            if recovery == Some(0.0) {
                assert!(x[2].abs() < 1.6, "{model:?} h {h}: turned over to {}", x[2]);
            }
        }
    }
}

/// The position-level correction is part of the step, and its derivatives are exact: first derivatives
/// and Hessians against differences at a deep penetration (d = -0.1) with the default recovery.
#[test]
fn derivatives_through_the_position_level_recovery_match_differences() {
    let x = crate::dynamics_hard_cases::deep_penetration();
    let scene = task::ProblemFile::builtin().scene;
    for model in [
        Complementarity::Hard,
        Complementarity::Logistic { sigma: 0.1 },
    ] {
        let settings = StepSettings {
            model,
            ..StepSettings::default()
        };
        let step = crate::dynamics_hard_cases::first_derivatives_match_differences(
            &scene,
            settings,
            &x,
            &[0.5, -0.5],
        );
        // The correction acted: the positions moved by more than h v'.
        let moved =
            (0..3).any(|i| (step.x_next[i] - x[i] - 0.05 * step.x_next[3 + i]).abs() > 1e-3);
        assert!(moved, "{model:?}: no correction at d = {:?}", step.d);
        crate::dynamics_hard_cases::hessians_match_differences(
            &scene,
            model,
            std::slice::from_ref(&x),
            &[0.5, -0.5],
        );
    }
}

/// Found by the random drops: a light needle (0.19 x 0.019) dropped flat-ish onto the ground under
/// logistic contact at sigma = 0.02 ended in a two-step cycle with its centre 0.016 below the ground: its
/// angle flipped by +-0.17 and its spin by +-2.9 rad/s every step while it kept falling at 0.42, the
/// position correction lifting it back each step. The correction's metric was M, in which turning a needle
/// is cheap, so each projection turned it past flat rather than lifting it. In the metric that turns each
/// body as a ring of its largest semi-axis (`Model::position_correction`) it ends above the
/// ground (its rocking limit, 0.041 s, is above this h).
#[test]
fn a_light_needle_on_smoothed_contact_ends_above_the_ground() {
    let drop = Drop {
        bodies: vec![(
            [0.18767547213154737, 0.019422214526800433],
            2.6105194316876643,
            [0.46165178685946145, 0.7384955360578385, 0.0],
            1.6695284913059307,
        )],
        chain: None,
        tilt: 0.0,
        gravity: 9.535017079941031,
        friction: 0.0,
        pairs: false,
        h: 0.033848708919350746,
    };
    check_drop(&drop, Complementarity::Logistic { sigma: 0.02 }, 3.0, true).unwrap();
}

/// `Scene::rocking_limit` is the integrator's own limit: a needle (0.18 x 0.017, gravity 9.6) lying flat
/// and tipped by 1e-3 rad keeps rocking by a few 1e-3 rad at 0.9 of the limit, for every model, and turns
/// through flat by a tenth of a radian or more at 1.1 of it, where it cannot rest.
#[test]
fn a_needle_rests_below_its_rocking_limit_and_not_above() {
    let (a, b) = (0.18, 0.017);
    let text = format!(
        "gravity = [0.0, -9.6]\n[[plane]]\nname = \"ground\"\npoint = [0.0, 0.0]\nnormal = [0.0, 1.0]\n\
         [[body]]\nname = \"needle\"\nsemi_axes = [{a}, {b}]\ndensity = 2.6\nparent = \"world\"\n\
         anchor = [0.0, 0.0]\ncentre = [0.0, 0.0]\njoint = {{ type = \"free\" }}\n\
         [[contact]]\na = \"ground\"\nb = \"needle\"\nfriction = 0.5\n"
    );
    let scene = Scene::from_toml_str(&text).unwrap();
    let limit = scene.rocking_limit().unwrap();
    assert!((limit - 0.04246).abs() < 1e-4, "limit {limit}");
    for model in [
        Complementarity::Hard,
        Complementarity::Logistic { sigma: 0.1 },
        Complementarity::Logistic { sigma: 0.02 },
        Complementarity::Normal { sigma: 0.05 },
    ] {
        for (factor, stable) in [(0.9, true), (1.1, false)] {
            let settings = StepSettings {
                model,
                h: factor * limit,
                ..StepSettings::default()
            };
            let mut sim = Simulator::new(scene.clone(), settings).unwrap();
            let mut x = vec![0.0, b, 1e-3, 0.0, 0.0, 0.0];
            let mut late = 0.0f64;
            for k in 0..200 {
                x = sim.step(&x, &[]).unwrap().x_next;
                if k >= 100 {
                    late = late.max(x[2].abs());
                }
            }
            if stable {
                assert!(
                    late < 5e-3,
                    "{model:?} at {factor} of the limit: rocks by {late}"
                );
            } else {
                assert!(
                    late > 0.03,
                    "{model:?} at {factor} of the limit: rocks by only {late}"
                );
            }
        }
    }
}
