//! Laws of the simulator that hold for all states: a symmetric positive definite mass matrix, constraint
//! Jacobians that are the gradients of the distances, derivatives that agree with differences, energy that
//! the step conserves to O(h) without drag and contact; and scene files that are checked field by field.

use dynamics::{
    Complementarity, Constraints, DynamicsError, Kinematics, Model, Scene, Simulator,
    StateCovariance, StepSettings,
};
use proptest::prelude::*;

fn finger() -> Scene {
    task::ProblemFile::builtin().scene
}

fn state() -> impl Strategy<Value = Vec<f64>> {
    (
        -3.0f64..0.0,
        -2.0f64..0.0,
        -3.2f64..3.2,
        -3.0f64..3.0,
        -3.0f64..3.0,
        -3.0f64..3.0,
    )
        .prop_map(|(a, b, c, d, e, f)| vec![a, b, c, d, e, f])
}

/// The step, or `None` where the hard LCP has no solution (deep inside the free ellipse, where the normal
/// model's expected-residual minimisation refuses the step): not a physical state.
fn physical_step(sim: &mut Simulator, x: &[f64], u: &[f64]) -> Option<dynamics::Step> {
    match sim.step(x, u) {
        Ok(step) => Some(step),
        Err(DynamicsError::Ncp(
            ncp::NcpError::NoSolution { .. }
            | ncp::NcpError::Infeasible { .. }
            | ncp::NcpError::InfeasibleRow { .. },
        )) => None,
        Err(e) => panic!("step at {x:?}: {e}"),
    }
}

/// The smoothed models whose derivatives are exact: logistic, normal (ERM), and logistic with each row's
/// noise from a state covariance (eq. 18); `Hard` too when `hard` is set.
fn smoothed_simulator(which: usize) -> Simulator {
    let model = match which {
        0 | 2 => Complementarity::Logistic { sigma: 0.3 },
        1 => Complementarity::Normal { sigma: 0.3 },
        _ => Complementarity::Hard,
    };
    let mut sim = Simulator::new(
        finger(),
        StepSettings {
            model,
            ..StepSettings::default()
        },
    )
    .unwrap();
    if which == 2 {
        // Position std 0.01 (0.2 in velocity at h = 0.05) and velocity std 0.1, correlated.
        let q = vec![1e-4, 2e-5, 0.0, 2e-5, 1e-4, 0.0, 0.0, 0.0, 1e-4];
        let v = vec![1e-2, 0.0, 1e-3, 0.0, 1e-2, 0.0, 1e-3, 0.0, 1e-2];
        sim.set_state_covariance(Some(StateCovariance { q, v }))
            .unwrap();
    }
    sim
}

proptest! {
    #[test]
    fn mass_matrix_is_symmetric_positive_definite(x in state()) {
        let scene = finger();
        let m = Kinematics::new(&scene, &x[..3]).mass_matrix(&scene);
        for i in 0..3 {
            for j in 0..3 {
                prop_assert!((m[i * 3 + j] - m[j * 3 + i]).abs() < 1e-14);
            }
        }
        // Leading minors (Sylvester).
        let d1 = m[0];
        let d2 = m[0] * m[4] - m[1] * m[3];
        let d3 = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6]);
        prop_assert!(d1 > 0.0 && d2 > 0.0 && d3 > 0.0);
    }

    #[test]
    fn a_point_force_does_the_virtual_work_of_its_point_and_acts_as_a_joint_torque(
        x in state(),
        body in 0usize..3,
        offset in (-0.5f64..0.5, -0.2f64..0.2),
        force in (-5.0f64..5.0, -5.0f64..5.0),
    ) {
        let scene = finger();
        let q = &x[..3];
        let kin = Kinematics::new(&scene, q);
        let c = kin.centre[body];
        let p = [c[0] + offset.0, c[1] + offset.1];
        let tau = kin.point_force(&scene, body, p, [force.0, force.1]);
        // Virtual work: tau . dq = F . dp for the material point carried along by dq.
        let dq = [0.3, -0.7, 0.5];
        let eps = 1e-6;
        let moved: Vec<f64> = q.iter().zip(dq).map(|(a, b)| a + eps * b).collect();
        let k2 = Kinematics::new(&scene, &moved);
        // The material point in body coordinates, then where it is after the move.
        let phi = kin.phi[body];
        let rel = [p[0] - kin.hinge[body][0], p[1] - kin.hinge[body][1]];
        let local = [phi.cos() * rel[0] + phi.sin() * rel[1], -phi.sin() * rel[0] + phi.cos() * rel[1]];
        let phi2 = k2.phi[body];
        let p2 = [
            k2.hinge[body][0] + phi2.cos() * local[0] - phi2.sin() * local[1],
            k2.hinge[body][1] + phi2.sin() * local[0] + phi2.cos() * local[1],
        ];
        let work = force.0 * (p2[0] - p[0]) / eps + force.1 * (p2[1] - p[1]) / eps;
        let virtual_work: f64 = tau.iter().zip(dq).map(|(t, d)| t * d).sum();
        prop_assert!((work - virtual_work).abs() < 1e-5 * (1.0 + work.abs()), "{work} vs {virtual_work}");
        // A generalised force on the actuated joints is the same step as that control torque; none is the
        // plain step.
        let mut sim = Simulator::new(scene.clone(), StepSettings::default()).unwrap();
        let by_control = sim.step(&x, &[tau[0], tau[1]]).unwrap();
        sim.reset_warm_start();
        let by_control_d = sim.derivatives().ok();
        sim.reset_warm_start();
        sim.data_mut().set_forces(&[tau[0], tau[1], 0.0]).unwrap();
        let by_force = sim.step(&x, &[0.0, 0.0]).unwrap();
        let by_force_d = sim.derivatives().ok();
        sim.reset_warm_start();
        sim.data_mut().clear_forces();
        let plain = sim.step(&x, &[0.0, 0.0]).unwrap();
        sim.reset_warm_start();
        sim.data_mut().set_forces(&[0.0; 3]).unwrap();
        let no_force = sim.step(&x, &[0.0, 0.0]).unwrap();
        for i in 0..6 {
            prop_assert!((by_control.x_next[i] - by_force.x_next[i]).abs() < 1e-10);
            prop_assert!((plain.x_next[i] - no_force.x_next[i]).abs() < 1e-12);
        }
        // The forces are an input held fixed: the step's derivatives in x are those of the same torque
        // given as controls.
        if let (Some(a), Some(b)) = (by_control_d, by_force_d) {
            let scale = a.fx.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for (p, q) in a.fx.iter().zip(&b.fx) {
                prop_assert!((p - q).abs() <= 1e-6 * scale, "{p} vs {q}");
            }
        }
    }

    #[test]
    fn constraint_jacobian_rows_are_gradients_of_the_distances(x in state()) {
        let scene = finger();
        let q = &x[..3];
        let c = Constraints::new(&scene, &Kinematics::new(&scene, q), q).unwrap();
        prop_assume!(c.contacts[0].witness_unique);
        let hstep = 1e-6;
        for j in 0..3 {
            let mut qp = q.to_vec();
            let mut qm = q.to_vec();
            qp[j] += hstep;
            qm[j] -= hstep;
            let dp = Constraints::new(&scene, &Kinematics::new(&scene, &qp), &qp).unwrap().d;
            let dm = Constraints::new(&scene, &Kinematics::new(&scene, &qm), &qm).unwrap().d;
            // Rows 0-3 (limits) exactly; rows 4 and 5 share d, whose gradient is their mean (J_n).
            for k in 0..4 {
                prop_assert!(((dp[k] - dm[k]) / (2.0 * hstep) - c.jacobian[k * 3 + j]).abs() < 1e-8);
            }
            let jn = 0.5 * (c.jacobian[4 * 3 + j] + c.jacobian[5 * 3 + j]);
            let fd = (dp[4] - dm[4]) / (2.0 * hstep);
            prop_assert!((fd - jn).abs() < 1e-6 * (1.0 + jn.abs()), "J_n[{}]: {} vs {}", j, fd, jn);
        }
    }

    #[test]
    fn smoothed_step_derivatives_match_central_differences(
        x in state(),
        u in (-2.0f64..2.0, -2.0f64..2.0),
        which in 0usize..3,
    ) {
        let mut sim = smoothed_simulator(which);
        let u = [u.0, u.1];
        let first = physical_step(&mut sim, &x, &u);
        prop_assume!(first.is_some());
        let first = first.unwrap();
        prop_assume!(first.d[4] > -0.2 && first.info.status == ncp::Status::Converged);
        let (_, der) = sim.step_with_derivatives(&x, &u).unwrap();
        prop_assume!(sim.step(&x, &u).unwrap().contacts[0].witness_unique);
        // The normal model's ERM solve stops at its objective's rounding floor (solutions good to ~1e-10),
        // which differences at 1e-6 amplify past the tolerance: for it, Richardson's extrapolation of central
        // differences at 1e-4 and 5e-5, and entries where those two disagree are not a test of the
        // derivative. The logistic model's sharp curvatures need plain central differences at 1e-6.
        let mut fresh = smoothed_simulator(which);
        let mut f = |x: &[f64], u: &[f64]| { fresh.reset_warm_start(); fresh.step(x, u).unwrap().x_next };
        let scale = der.fx.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        // Column j of [fx fu] by differences, or None where they are unreliable.
        let mut column = |j: usize| -> Vec<Option<f64>> {
            let mut central = |eps: f64| {
                let (mut xp, mut xm, mut up, mut um) = (x.clone(), x.clone(), u, u);
                if j < 6 {
                    xp[j] += eps;
                    xm[j] -= eps;
                } else {
                    up[j - 6] += eps;
                    um[j - 6] -= eps;
                }
                let (p, m) = (f(&xp, &up), f(&xm, &um));
                (0..6).map(|i| (p[i] - m[i]) / (2.0 * eps)).collect::<Vec<f64>>()
            };
            if which != 1 {
                return central(1e-6).into_iter().map(Some).collect();
            }
            let (coarse, fine) = (central(1e-4), central(5e-5));
            coarse
                .iter()
                .zip(&fine)
                .map(|(c, f)| ((c - f).abs() <= 1e-5 * scale).then_some((4.0 * f - c) / 3.0))
                .collect()
        };
        for j in 0..8 {
            for (i, fd) in column(j).into_iter().enumerate() {
                let Some(fd) = fd else { continue };
                let exact = if j < 6 { der.fx[i * 6 + j] } else { der.fu[i * 2 + j - 6] };
                prop_assert!((fd - exact).abs() < 1e-5 * scale, "model {}: d x'_{} / d y_{}: {} vs {}", which, i, j, fd, exact);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(32),
        ..ProptestConfig::default()
    })]

    #[test]
    fn the_hessian_of_c_f_matches_differences_of_exact_first_derivatives(
        x in state(),
        u in (-2.0f64..2.0, -2.0f64..2.0),
        c in proptest::collection::vec(-1.0f64..1.0, 6),
        which in 0usize..4,
    ) {
        let mut sim = smoothed_simulator(which);
        let u = [u.0, u.1];
        // Physical states: not deep inside the free ellipse (where the hard LCP can be infeasible and the
        // smoothed solve does not converge; derivatives are then refused).
        let first = physical_step(&mut sim, &x, &u);
        prop_assume!(first.is_some());
        let first = first.unwrap();
        prop_assume!(first.d[4] > -0.2 && first.info.status == ncp::Status::Converged);
        let (step, _, hess) = sim.step_with_hessian(&x, &u, &c).unwrap();
        prop_assume!(step.contacts[0].witness_unique);
        // c^T [fx fu] at y = (x, u), by the exact first derivatives.
        let mut grad = |y: &[f64]| crate::support::c_gradient(&mut sim, &c, y);
        let y: Vec<f64> = x.iter().chain(&u).copied().collect();
        let scale = hess.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        let mut difference = |k: usize, eps: f64| {
            let (mut yp, mut ym) = (y.clone(), y.clone());
            yp[k] += eps;
            ym[k] -= eps;
            let (gp, gm) = (grad(&yp), grad(&ym));
            (0..8).map(|i| (gp[i] - gm[i]) / (2.0 * eps)).collect::<Vec<f64>>()
        };
        for k in 0..8 {
            // Differences at two steps: where they disagree the gradient is too sharp for differences to
            // resolve (lambda >> sigma makes curvatures of 1e7), and the entry is not a test of the Hessian.
            let (coarse, fine) = (difference(k, 1e-6), difference(k, 5e-7));
            for i in 0..8 {
                if (coarse[i] - fine[i]).abs() > 1e-6 * scale {
                    continue;
                }
                let fd = (4.0 * fine[i] - coarse[i]) / 3.0;
                prop_assert!((fd - hess[i * 8 + k]).abs() < 1e-5 * scale, "model {}: H[{}][{}]: {} vs {}", which, i, k, fd, hess[i * 8 + k]);
            }
        }
        // Symmetric, as a Hessian must be.
        for i in 0..8 {
            for k in 0..8 {
                prop_assert!((hess[i * 8 + k] - hess[k * 8 + i]).abs() < 1e-9 * scale);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(32),
        ..ProptestConfig::default()
    })]

    /// `Model::derivatives` and `Model::second_order` linearise the step the data holds, with no second
    /// solve: they agree with the calls that solve the step (to the solver's tolerance) in a fresh data,
    /// and leave the data alone; a data holding no step, or made by a model of another size, is refused.
    #[test]
    fn derivatives_of_a_stored_step_match_a_fresh_solve(
        x in state(),
        u in (-2.0f64..2.0, -2.0f64..2.0),
        c in proptest::collection::vec(-1.0f64..1.0, 6),
        which in 0usize..4,
    ) {
        let mut sim = smoothed_simulator(which);
        let u = [u.0, u.1];
        let step = physical_step(&mut sim, &x, &u);
        prop_assume!(step.is_some());
        let step = step.unwrap();
        prop_assume!(step.d[4] > -0.2 && step.info.status == ncp::Status::Converged);
        let model = sim.model();
        let mut fresh_data = model.create_data();
        prop_assert!(model.derivatives(&fresh_data).is_err());
        let Ok(fresh) = model.step_with_derivatives(&mut fresh_data, &x, &u) else {
            // Refused (a singular Jacobian at an active-set change): the stored step must be refused too.
            prop_assert!(sim.derivatives().is_err());
            return Ok(());
        };
        let stored = sim.derivatives().unwrap();
        let scale = fresh.fx.iter().chain(&fresh.fu).fold(1.0f64, |m, v| m.max(v.abs()));
        for (a, b) in stored.fx.iter().chain(&stored.fu).zip(fresh.fx.iter().chain(&fresh.fu)) {
            prop_assert!((a - b).abs() <= 1e-6 * scale, "model {}: {} vs {}", which, a, b);
        }
        if which != 1 || !sim.has_state_covariance() {
            let model = sim.model();
            let (so, again) = (model.second_order(sim.data()), model.second_order_step(&mut fresh_data, &x, &u));
            if let (Ok(so), Ok(again)) = (so, again) {
                prop_assert_eq!(&so.step.x_next, &step.x_next);
                let (h1, h2) = (so.hessian(&c).unwrap(), again.hessian(&c).unwrap());
                let hs = h2.iter().fold(1.0f64, |m, v| m.max(v.abs()));
                for (a, b) in h1.iter().zip(&h2) {
                    prop_assert!((a - b).abs() <= 1e-6 * hs, "model {}: {} vs {}", which, a, b);
                }
                // Written in place over whatever was there, the same bits; a buffer of the wrong size refused.
                let mut into = vec![f64::NAN; h1.len()];
                so.hessian_into(&c, &mut into).unwrap();
                prop_assert_eq!(&into, &h1);
                let mut short = vec![0.0; h1.len() - 1];
                let refused = matches!(so.hessian_into(&c, &mut short), Err(DynamicsError::Input { what: "hess", .. }));
                prop_assert!(refused, "a short buffer was accepted");
            }
        }
        // Linearising left the data as it was: its step is the one it computed.
        prop_assert_eq!(sim.data().step(), Some(&step));
        // Data of a model of another size is refused, not linearised or stepped.
        let other = Model::new(Scene::from_toml_str(include_str!("../../scenes/three_link_finger.toml")).unwrap(), StepSettings::default()).unwrap();
        let mut alien = other.create_data();
        let refused = |e: Result<(), DynamicsError>| matches!(e, Err(DynamicsError::Input { what: "step data", .. }));
        prop_assert!(refused(sim.model().derivatives(&alien).map(|_| ())));
        prop_assert!(refused(sim.model().step(&mut alien, &x, &u).map(|_| ())));
    }

    /// A model's answer depends only on the data handed in: a step in one data is bit for bit the same
    /// whatever steps other data of the same model took in between (no state hidden in the model).
    #[test]
    fn a_models_step_depends_only_on_its_data(
        x in state(),
        others in proptest::collection::vec((state(), (-2.0f64..2.0, -2.0f64..2.0)), 1..4),
        u in (-2.0f64..2.0, -2.0f64..2.0),
    ) {
        let model = Model::new(task::ProblemFile::builtin().scene, StepSettings::default()).unwrap();
        let u = [u.0, u.1];
        let mut quiet = model.create_data();
        let alone = model.step(&mut quiet, &x, &u).map(|s| s.x_next.clone()).ok();
        let mut data = model.create_data();
        let mut busy = model.create_data();
        for (y, v) in &others {
            let _ = model.step(&mut busy, y, &[v.0, v.1]);
        }
        let after = model.step(&mut data, &x, &u).map(|s| s.x_next.clone()).ok();
        prop_assert_eq!(alone, after);
    }
}

/// The finger without drag, limits or contact: a double pendulum and a free spinner.
fn conservative_scene() -> Scene {
    let mut spec = task::ProblemFile::builtin().scene.spec().clone();
    for b in &mut spec.bodies {
        b.joint.damping = 0.0;
        b.joint.limits = None;
    }
    spec.contacts.clear();
    Scene::new(spec).unwrap()
}

#[test]
fn energy_is_conserved_to_first_order_in_h_without_drag_or_contact() {
    let scene = conservative_scene();
    let x0 = [-0.7, -0.4, 0.3, 1.0, -0.5, 2.0];
    let e0 = crate::support::energy(&scene, &x0);
    let mut drift = Vec::new();
    for h in [0.004, 0.002, 0.001] {
        let settings = StepSettings {
            model: Complementarity::Hard,
            h,
            ..StepSettings::default()
        };
        let mut sim = Simulator::new(scene.clone(), settings).unwrap();
        let mut x = x0.to_vec();
        let steps = (0.5 / h) as usize;
        let mut worst = 0.0f64;
        for _ in 0..steps {
            x = sim.step(&x, &[0.0, 0.0]).unwrap().x_next;
            worst = worst.max((crate::support::energy(&scene, &x) - e0).abs());
        }
        drift.push(worst);
    }
    println!("energy drift over 0.5 s for h = 0.004, 0.002, 0.001: {drift:?}");
    // First order: halving h about halves the drift.
    assert!(
        drift[1] < 0.7 * drift[0] && drift[2] < 0.7 * drift[1],
        "{drift:?}"
    );
    assert!(drift[2] < 0.05 * e0.abs().max(1.0));
}

#[test]
fn contact_never_creates_energy_in_a_drag_free_scene() {
    let mut spec = task::ProblemFile::builtin().scene.spec().clone();
    for b in &mut spec.bodies {
        b.joint.damping = 0.0;
    }
    let scene = Scene::new(spec).unwrap();
    let settings = StepSettings {
        model: Complementarity::Hard,
        h: 0.01,
        ..StepSettings::default()
    };
    let mut sim = Simulator::new(scene.clone(), settings).unwrap();
    // Start apart, falling onto the ellipse and the joint limits.
    let mut x = vec![-0.9, -0.3, 0.2, -1.0, -1.0, 0.0];
    let e0 = crate::support::energy(&scene, &x);
    let mut contacts = 0;
    for _ in 0..300 {
        let s = sim.step(&x, &[0.0, 0.0]).unwrap();
        if s.lambda.iter().any(|l| *l > 0.0) {
            contacts += 1;
        }
        x = s.x_next;
        // Symplectic-Euler-like drift is bounded; contact and limits only remove energy.
        assert!(
            crate::support::energy(&scene, &x) <= e0 + 0.05,
            "energy {} rose above {e0}",
            crate::support::energy(&scene, &x)
        );
    }
    assert!(contacts > 0, "the scenario must touch something");
}

#[test]
fn a_malformed_scene_names_every_bad_field() {
    let text = r#"
gravity = [0.0, nan]
[[body]]
name = "a"
semi_axes = [0.0, 1.0]
parent = "nobody"
anchor = [0.0, 0.0]
centre = [1.0, 0.0]
joint = { limits = [1.0, -1.0], damping = -0.1 }
[[body]]
name = "a"
semi_axes = [1.0, 1.0]
density = -2.0
parent = "world"
anchor = [0.0, 0.0]
centre = [1.0, 0.0]
joint = {}
[[contact]]
a = "a"
b = "ghost"
friction = -1.0
"#;
    let Err(DynamicsError::Scene(problems)) = Scene::from_toml_str(text) else {
        panic!("must be rejected")
    };
    let fields: Vec<&str> = problems.iter().map(|p| p.field.as_str()).collect();
    for expected in [
        "gravity",
        "body[0].semi_axes",
        "body[0].parent",
        "body[0].joint.limits",
        "body[0].joint.damping",
        "body[1].name",
        "body[1].density",
        "contact[0].b",
        "contact[0].friction",
    ] {
        assert!(
            fields.contains(&expected),
            "{expected} missing from {fields:?}"
        );
    }
    assert!(matches!(
        Scene::from_toml_str("gravity = 3"),
        Err(DynamicsError::Parse(_))
    ));
    assert!(matches!(
        Scene::from_toml_str("gravity = [0.0, -4.0]\nbody = []"),
        Err(DynamicsError::Scene(_))
    ));
}

#[test]
fn bad_states_and_settings_are_typed_errors() {
    let mut sim = Simulator::new(finger(), StepSettings::default()).unwrap();
    assert!(matches!(
        sim.step(&[0.0; 5], &[0.0; 2]),
        Err(DynamicsError::Input { what: "x", .. })
    ));
    assert!(matches!(
        sim.step(&[0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0], &[0.0; 2]),
        Err(DynamicsError::Input { what: "x", .. })
    ));
    assert!(matches!(
        sim.step(&[-0.5; 6], &[f64::INFINITY, 0.0]),
        Err(DynamicsError::Input { what: "u", .. })
    ));
    for forces in [&[f64::NAN, 0.0, 0.0][..], &[0.0, 0.0]] {
        assert!(matches!(
            sim.data_mut().set_forces(forces),
            Err(DynamicsError::Input { what: "forces", .. })
        ));
        assert!(
            sim.data().forces().is_empty(),
            "a refused input leaves the forces as they were"
        );
    }
    for bad in [
        StepSettings {
            h: 0.0,
            ..StepSettings::default()
        },
        StepSettings {
            h: f64::NAN,
            ..StepSettings::default()
        },
        StepSettings {
            model: Complementarity::Logistic { sigma: 0.0 },
            ..StepSettings::default()
        },
        StepSettings {
            model: Complementarity::Normal { sigma: -1.0 },
            ..StepSettings::default()
        },
    ] {
        assert!(matches!(
            Simulator::new(finger(), bad),
            Err(DynamicsError::Setting { .. })
        ));
    }
}

#[test]
fn noise_from_a_state_covariance_follows_eq_18() {
    // In contact, pushed: the step's distance from the hard step grows with the state's uncertainty.
    let x = [-1.3, -0.4, 0.2, -1.0, -0.5, 0.3];
    let u = [0.5, -0.5];
    let hard = Simulator::new(
        finger(),
        StepSettings {
            model: Complementarity::Hard,
            ..StepSettings::default()
        },
    )
    .unwrap()
    .step(&x, &u)
    .unwrap();
    let mut gaps = Vec::new();
    for s in [1e-4, 1e-3, 1e-2] {
        let mut sim = Simulator::new(finger(), StepSettings::default()).unwrap();
        let eye = |v: f64| {
            (0..9)
                .map(|k| if k % 4 == 0 { v } else { 0.0 })
                .collect::<Vec<f64>>()
        };
        sim.set_state_covariance(Some(StateCovariance {
            q: eye(s * s),
            v: eye(0.0),
        }))
        .unwrap();
        let step = sim.step(&x, &u).unwrap();
        assert_eq!(step.info.status, ncp::Status::Converged);
        gaps.push(
            step.x_next
                .iter()
                .zip(&hard.x_next)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs())),
        );
    }
    println!("gap to the hard step for position std 1e-4, 1e-3, 1e-2: {gaps:?}");
    assert!(gaps[0] < gaps[1] && gaps[1] < gaps[2], "{gaps:?}");
    let mut sim = Simulator::new(finger(), StepSettings::default()).unwrap();
    let bad = StateCovariance {
        q: vec![1.0, 2.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        v: vec![0.0; 9],
    };
    assert!(matches!(
        sim.set_state_covariance(Some(bad)),
        Err(DynamicsError::Input {
            what: "covariance",
            ..
        })
    ));
    let short = StateCovariance {
        q: vec![0.0; 4],
        v: vec![0.0; 9],
    };
    assert!(sim.set_state_covariance(Some(short)).is_err());
}

#[test]
fn a_scene_file_with_extra_or_missing_array_entries_is_refused() {
    let finger = include_str!("../../scenes/finger.toml");
    for (from, to) in [
        ("gravity = [0.0, -4.0]", "gravity = [0.0, -4.0, 99.0]"),
        ("semi_axes = [0.7, 0.5]", "semi_axes = [0.7]"),
    ] {
        assert!(finger.contains(from), "scenes/finger.toml has {from}");
        let text = finger.replacen(from, to, 1);
        let e = Scene::from_toml_str(&text).unwrap_err().to_string();
        assert!(e.contains("needs exactly 2 numbers"), "{to}: {e}");
    }
    assert!(Scene::from_toml_str(finger).is_ok());
}

/// A data carries no settings of its own: stepped by another model of the same sizes, it solves with that
/// model's Newton settings, bit for bit as that model's own fresh data.
#[test]
fn a_data_steps_with_the_settings_of_the_model_that_steps_it() {
    let loose = StepSettings {
        newton: ncp::NewtonSettings {
            tol: 1e-3,
            max_iter: 3,
            ..ncp::NewtonSettings::default()
        },
        ..StepSettings::default()
    };
    let tight = Model::new(task::ProblemFile::builtin().scene, StepSettings::default()).unwrap();
    let loose = Model::new(task::ProblemFile::builtin().scene, loose).unwrap();
    let x = [-0.9, -1.5, 0.3, 0.5, -0.4, 0.2];
    let u = [0.3, -0.2];
    let mut borrowed = loose.create_data();
    let mut own = tight.create_data();
    let a = tight.step(&mut borrowed, &x, &u).unwrap().clone();
    let b = tight.step(&mut own, &x, &u).unwrap().clone();
    assert_eq!(a, b);
    let c = loose
        .step(&mut loose.create_data(), &x, &u)
        .unwrap()
        .clone();
    assert!(c.info.iterations <= 3, "{c:?}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// The knots' path (the derivatives kept in the step's data: `calc_diff`, `calc_diff2_prepare`, then
    /// `calc_diff2` with several `c`) gives what the owned path gives (`derivatives`, `second_order`, then
    /// `hessian`), to the last bit, for every contact model; a new step drops what the data kept.
    #[test]
    fn derivatives_kept_in_the_data_are_the_owned_ones(x in state(), model in 0usize..3) {
        let model = [
            Complementarity::Logistic { sigma: 0.1 },
            Complementarity::Hard,
            Complementarity::Normal { sigma: 0.2 },
        ][model];
        let m = Model::new(finger(), StepSettings { model, ..StepSettings::default() }).unwrap();
        let mut data = m.create_data();
        let u = [0.4, -0.3];
        let Ok(step) = m.step(&mut data, &x, &u) else {
            return Ok(());
        };
        if step.info.status != ncp::Status::Converged {
            return Ok(());
        }
        let Ok(owned) = m.second_order(&data) else { return Ok(()) };
        let first = m.derivatives(&data).unwrap();
        prop_assert_eq!(m.calc_diff(&mut data).unwrap(), &first);
        m.calc_diff2_prepare(&mut data).unwrap();
        for k in 0..3 {
            let c: Vec<f64> = (0..6).map(|i| ((i + k) % 4) as f64 - 1.5).collect();
            let mut hess = vec![0.0; 64];
            let d = m.calc_diff2(&mut data, &c, &mut hess).unwrap().clone();
            prop_assert_eq!(&d, &owned.derivatives);
            prop_assert_eq!(hess, owned.hessian(&c).unwrap());
        }
        // The next step's derivatives are its own: the kept ones are dropped.
        let mut x2 = x.clone();
        x2[3] += 0.5;
        if m.step(&mut data, &x2, &u).is_ok_and(|s| s.info.status == ncp::Status::Converged)
            && let Ok(fresh) = m.derivatives(&data)
        {
            prop_assert_eq!(m.calc_diff(&mut data).unwrap(), &fresh);
        }
    }
}

/// Every scene of the repository with the coordinates a half turn maps onto themselves
/// ([`Scene::half_turn_coordinates`]).
fn scenes_with_half_turns() -> Vec<(&'static str, Scene)> {
    [
        ("finger", include_str!("../../scenes/finger.toml")),
        ("slider_push", include_str!("../../scenes/slider_push.toml")),
        ("roll_block", include_str!("../../scenes/roll_block.toml")),
        ("two_fingers", include_str!("../../scenes/two_fingers.toml")),
        ("paddle", include_str!("../data/paddle.toml")),
    ]
    .into_iter()
    .map(|(name, text)| (name, task::ProblemFile::from_toml_str(text).unwrap().scene))
    .chain([("puck", puck())])
    .collect()
}

/// The slider with a round block ([`crate::support::puck_text`]).
fn puck() -> Scene {
    task::ProblemFile::from_toml_str(&crate::support::puck_text())
        .unwrap()
        .scene
}

#[test]
fn a_half_turn_is_a_symmetry_only_of_a_centred_unlimited_childless_angle() {
    let names = |scene: &Scene| -> Vec<String> {
        let all = scene.coordinate_names();
        scene
            .half_turn_coordinates()
            .into_iter()
            .map(|c| all[c].clone())
            .collect()
    };
    let expected = [
        ("finger", "ellipse.angle"),
        ("slider_push", "block.angle"),
        ("roll_block", "block.angle"),
        ("two_fingers", "ellipse.angle"),
        ("paddle", "wheel.angle"),
        ("puck", "block.angle"),
    ];
    for ((name, scene), (same, coordinate)) in scenes_with_half_turns().iter().zip(expected) {
        assert_eq!(*name, same);
        // The links turn about a hinge at one end, the slider slides, the limited joints are limited.
        assert_eq!(names(scene), vec![coordinate.to_string()], "{name}");
        // Only the puck is round: any turn maps it onto itself.
        let round = scene.round_coordinates();
        assert_eq!(
            round.len(),
            usize::from(*name == "puck"),
            "{name}: {round:?}"
        );
    }
    // The same ellipse off its hinge, limited, or carrying a body, is no longer a symmetry.
    let base = include_str!("../../scenes/finger.toml");
    let ellipse = "anchor = [0.0, -3.0]\ncentre = [0.0, 0.0]\njoint = { damping = 0.7 }";
    assert!(base.contains(ellipse));
    for (change, why) in [
        (
            "anchor = [0.0, -3.0]\ncentre = [0.1, 0.0]\njoint = { damping = 0.7 }",
            "off centre",
        ),
        (
            "anchor = [0.0, -3.0]\ncentre = [0.0, 0.0]\njoint = { damping = 0.7, limits = [-10.0, 10.0] }",
            "limited",
        ),
        (
            "anchor = [0.0, -3.0]\ncentre = [0.0, 0.0]\njoint = { damping = 0.7 }\n\n[[body]]\nname = \"tab\"\nsemi_axes = [0.2, 0.1]\nparent = \"ellipse\"\nanchor = [0.7, 0.0]\ncentre = [0.0, 0.0]\njoint = { type = \"weld\" }",
            "carrying a body",
        ),
    ] {
        // The scene alone: the task declares the ellipse's angle periodic, which limits contradict.
        let text = base.replace(ellipse, change);
        let text = &text[..text.find("\n[task.").unwrap()];
        let scene = task::ProblemFile::from_toml_str(text).unwrap().scene;
        assert!(
            names(&scene).is_empty(),
            "an ellipse {why}: {:?}",
            names(&scene)
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// What makes a half turn a symmetry: the step from a state and from the same state with the angle
    /// moved by pi land on the same state, moved by pi, on the smoothed and on the hard model; for a
    /// round body (the puck), moved by any angle.
    #[test]
    fn a_half_turn_of_a_symmetric_angle_commutes_with_the_step(
        seed in proptest::collection::vec(-1.0f64..1.0, 16),
        which in 0usize..6,
        hard in proptest::bool::ANY,
        turns in -2i32..3,
        fraction in 0.0f64..1.0,
    ) {
        let (name, scene) = scenes_with_half_turns().swap_remove(which);
        let (n, m) = (scene.n_dof(), scene.n_controls);
        let model = if hard { Complementarity::Hard } else { Complementarity::Logistic { sigma: 0.05 } };
        let mut sim = Simulator::new(scene.clone(), StepSettings { model, ..StepSettings::default() }).unwrap();
        // A state near the task's start: small angles and offsets, any velocities; a block resting on
        // the ground is lifted to its half height.
        let mut x: Vec<f64> = seed.iter().cycle().take(2 * n).map(|s| 0.3 * s).collect();
        for (i, v) in x[n..].iter_mut().enumerate() {
            *v = 2.0 * seed[(i + 5) % seed.len()];
        }
        let names = scene.coordinate_names();
        if let Some(y) = names.iter().position(|c| c == "block.y") {
            x[y] = 0.25 + 0.1 * seed[3].abs();
        }
        let u: Vec<f64> = (0..m).map(|a| seed[(a + 11) % seed.len()]).collect();
        let round = scene.round_coordinates();
        for c in scene.half_turn_coordinates() {
            let Some(a) = physical_step(&mut sim, &x, &u) else { continue };
            let mut turned = x.clone();
            let step = if round.contains(&c) { fraction } else { 1.0 } * std::f64::consts::PI;
            turned[c] += f64::from(turns) * step;
            let Some(b) = physical_step(&mut sim, &turned, &u) else { continue };
            for (i, (p, q)) in a.x_next.iter().zip(&b.x_next).enumerate() {
                let q = if i == c { q - f64::from(turns) * step } else { *q };
                prop_assert!((p - q).abs() <= 1e-12 * (1.0 + p.abs()), "{name}: entry {i}: {p} against {q}");
            }
        }
    }
}
