//! The complementarity solvers against exact answers: planted solutions, active-set enumeration, Lemke's
//! method, and each other; classic hard LCPs; smoothing limits; bad input.

use ncp::instances::{MatrixKind, contact_step, murty, perturbed, planted_lcp};
use ncp::{
    ErmSettings, ErmSolver, LemkeSettings, LinearMcp, Mcp, NcpError, NcpFunction, NewtonSettings,
    NewtonSolver, Status, complementarity_residual, enumerate_solutions, lemke,
};
use proptest::prelude::*;

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

fn newton(settings: NewtonSettings) -> NewtonSolver {
    NewtonSolver::new(settings).expect("valid settings")
}

const KINDS: [MatrixKind; 4] = [
    MatrixKind::PositiveDefinite,
    MatrixKind::PMatrix,
    MatrixKind::Monotone,
    MatrixKind::SingularPsd,
];

proptest! {
    #[test]
    fn lemke_solves_random_families_to_1e_10_of_the_data_scale(kind in 0usize..4, n in 1usize..13, seed in 0u64..u64::MAX) {
        let (p, planted) = planted_lcp(KINDS[kind], n, seed);
        let s = lemke(&p, &LemkeSettings::default()).expect("a planted LCP has a solution");
        prop_assert_eq!(s.info.status, Status::Converged);
        prop_assert!(s.info.residual <= 1e-10 * p.scale(), "residual {}", s.info.residual);
        prop_assert!(s.z.iter().all(|v| *v >= 0.0));
        if matches!(KINDS[kind], MatrixKind::PositiveDefinite | MatrixKind::Monotone) {
            // Unique solution (positive definite M).
            prop_assert!(max_diff(&s.z, &planted) <= 1e-8 * p.scale());
        }
    }

    #[test]
    fn hard_newton_matches_enumeration_on_positive_definite_lcps(n in 1usize..7, seed in 0u64..u64::MAX, fb in any::<bool>()) {
        let (p, _) = planted_lcp(MatrixKind::PositiveDefinite, n, seed);
        let exact = enumerate_solutions(&p, 1e-12).unwrap();
        prop_assert_eq!(exact.len(), 1, "positive definite: one solution");
        let f = if fb { NcpFunction::FischerBurmeister } else { NcpFunction::Min };
        let s = newton(NewtonSettings::default()).solve(&p, &vec![f; n], &vec![0.0; n]).unwrap();
        prop_assert_eq!(s.info.status, Status::Converged);
        prop_assert!(max_diff(&s.z, &exact[0]) <= 1e-9 * p.scale(), "{:?} vs {:?}", s.z, exact[0]);
    }

    #[test]
    fn smoothed_newton_approaches_the_hard_solution_linearly_in_sigma(seed in 0u64..u64::MAX, normal in any::<bool>()) {
        let p = contact_step(seed);
        let exact = lemke(&p, &LemkeSettings::default()).unwrap();
        let mut solver = newton(NewtonSettings::default());
        let mut z = vec![0.0; 9];
        for k in 1..=6 {
            let sigma = 10f64.powi(-k);
            let f = if normal { NcpFunction::Normal { sigma } } else { NcpFunction::Logistic { sigma } };
            // Continuation: each sigma warm-starts from the previous one.
            let info = solver.solve_in_place(&p, &[f; 6], &mut z).unwrap();
            prop_assert_eq!(info.status, Status::Converged, "sigma {}", sigma);
            // The velocities (unique, unlike the impulses when more rows are active than there are
            // velocities) move by O(sigma).
            let err = max_diff(&z[..3], &exact.z[..3]);
            prop_assert!(err <= 20.0 * sigma * p.scale(), "sigma {}: {}", sigma, err);
        }
    }

    #[test]
    fn erm_holds_the_equality_rows_and_tends_to_the_hard_solution(seed in 0u64..u64::MAX) {
        let p = contact_step(seed);
        let exact = lemke(&p, &LemkeSettings::default()).unwrap();
        let erm = ErmSolver::new(ErmSettings::default()).unwrap();
        let mut z = exact.z.clone();
        for k in 1..=5 {
            let sigma = 10f64.powi(-k);
            let s = erm.solve(&p, &[sigma; 6], &z).unwrap();
            prop_assert_eq!(s.info.status, Status::Converged, "sigma {}: {:?}", sigma, s.info);
            prop_assert!(s.w[..3].iter().all(|r| r.abs() <= 1e-13 * p.scale()), "equality rows {:?}", &s.w[..3]);
            prop_assert!(s.z[3..].iter().all(|l| *l >= 0.0));
            let err = max_diff(&s.z[..3], &exact.z[..3]);
            prop_assert!(err <= 20.0 * sigma * p.scale(), "sigma {}: {}", sigma, err);
            z = s.z;
        }
    }
}

proptest! {
    /// The step of a light body: its mass matrix scaled by `10^k` (its forces with it, so the velocities
    /// stay and the impulses scale) puts the impulses at `10^k` and the reduced matrix at `10^-k`, while
    /// the noise stays in velocity units. The projected method alone measured its active set's margin in
    /// the gradient's units and, on a light needle beside a disc, alternated between two active sets for
    /// hundreds of iterations (issue 27's random drops); every scale must converge.
    #[test]
    fn erm_converges_however_light_the_bodies(seed in 0u64..u64::MAX, k in -5i32..=1) {
        let p = contact_step(seed);
        let (dim, s) = (p.dim(), 10f64.powi(k));
        let mut m = p.m_row_major().to_vec();
        let mut q = p.q().to_vec();
        for i in 0..3 {
            for j in 0..3 {
                m[i * dim + j] *= s;
            }
            q[i] *= s;
        }
        let light = LinearMcp::from_row_major(3, m, q).unwrap();
        let erm = ErmSolver::new(ErmSettings::default()).unwrap();
        for sigma in [0.5, 0.05, 0.005] {
            let sol = erm.solve(&light, &[sigma; 6], &[0.0; 9]).unwrap();
            prop_assert_eq!(sol.info.status, Status::Converged, "k {} sigma {}: {:?}", k, sigma, sol.info);
            prop_assert!(sol.z[3..].iter().all(|l| *l >= 0.0));
        }
    }
}

#[test]
fn lemke_walks_murtys_exponential_family_and_still_lands_on_the_unique_solution() {
    for n in 2..=14 {
        let p = murty(n);
        let s = lemke(&p, &LemkeSettings::default()).unwrap();
        assert_eq!(s.info.status, Status::Converged);
        assert_eq!(
            s.info.iterations,
            1 << n,
            "Murty's family costs Lemke 2^n pivots"
        );
        assert!(
            s.info.residual <= 1e-12 * p.scale(),
            "n = {n}: {}",
            s.info.residual
        );
        let mut expected = vec![0.0; n];
        expected[0] = 2f64.powi(n as i32);
        assert_eq!(s.z, expected);
        if n <= 8 {
            assert_eq!(enumerate_solutions(&p, 1e-12).unwrap(), vec![expected]);
        }
    }
    // With a pivot limit, the method reports that it stopped early rather than a wrong answer.
    let s = lemke(
        &murty(12),
        &LemkeSettings {
            max_pivots: 100,
            ..LemkeSettings::default()
        },
    )
    .unwrap();
    assert_eq!(s.info.status, Status::MaxIterations);
}

#[test]
fn lemke_handles_degenerate_singular_and_badly_scaled_problems() {
    // q = 0: z = w = 0 on every row, the most degenerate start.
    let p = LinearMcp::from_rows(0, &[vec![1.0, -1.0], vec![-1.0, 1.0]], &[0.0, 0.0]).unwrap();
    let s = lemke(&p, &LemkeSettings::default()).unwrap();
    assert_eq!(s.z, vec![0.0, 0.0]);
    // Ties in every ratio test (identical rows, degenerate solution with z_2 = w_2 = 0).
    let rows = vec![
        vec![1.0, 1.0, 1.0],
        vec![1.0, 1.0, 1.0],
        vec![1.0, 1.0, 2.0],
    ];
    let p = LinearMcp::from_rows(0, &rows, &[-1.0, -1.0, -1.0]).unwrap();
    let s = lemke(&p, &LemkeSettings::default()).unwrap();
    assert!(s.info.residual <= 1e-14, "{:?}", s);
    // Singular PSD with a solution set that is a segment: any point of it will do.
    let p = LinearMcp::from_rows(0, &[vec![1.0, 1.0], vec![1.0, 1.0]], &[-1.0, -1.0]).unwrap();
    let s = lemke(&p, &LemkeSettings::default()).unwrap();
    assert!(s.info.residual <= 1e-14 && (s.z[0] + s.z[1] - 1.0).abs() < 1e-14);
    // Rows scaled from 1e-8 to 1e8 have the same solutions.
    for seed in 0..20 {
        let (p, planted) = planted_lcp(MatrixKind::PositiveDefinite, 8, seed);
        let n = 8;
        let mut m = p.m_row_major().to_vec();
        let mut q = p.q().to_vec();
        for i in 0..n {
            let s = 10f64.powi(2 * i as i32 - 8);
            for j in 0..n {
                m[i * n + j] *= s;
            }
            q[i] *= s;
        }
        let scaled = LinearMcp::from_row_major(0, m, q).unwrap();
        let s = lemke(&scaled, &LemkeSettings::default()).unwrap();
        assert!(
            max_diff(&s.z, &planted) < 1e-9,
            "seed {seed}: {:?} vs {planted:?} {:?} w {:?}",
            s.z,
            s.info,
            s.w
        );
        assert!(complementarity_residual(0, &s.z, &s.w) <= 1e-10 * scaled.scale());
    }
}

#[test]
fn lemke_reports_an_infeasible_lcp_as_an_error() {
    // w_1 = z_2 - 1 >= 0 and w_2 = -z_1 - 1 >= 0 cannot both hold for z >= 0; M is PSD (skew).
    // Row 2 has no positive entry and q_2 < 0: it proves infeasibility before any pivot.
    let p = LinearMcp::from_rows(0, &[vec![0.0, 1.0], vec![-1.0, 0.0]], &[-1.0, -1.0]).unwrap();
    assert!(matches!(
        lemke(&p, &LemkeSettings::default()),
        Err(NcpError::InfeasibleRow { row: 1, .. })
    ));
    // Infeasible with every row holding a positive entry: the ray of Lemke's method proves it.
    let p = LinearMcp::from_rows(0, &[vec![1.0, -1.0], vec![-1.0, 1.0]], &[-1.0, -1.0]).unwrap();
    assert!(matches!(
        lemke(&p, &LemkeSettings::default()),
        Err(NcpError::Infeasible { .. })
    ));
}

#[test]
fn erm_refuses_an_lcp_without_a_solution_and_still_solves_feasible_ones() {
    // No z >= 0 with w >= 0 (see lemke_reports_an_infeasible_lcp_as_an_error), and a one-row one.
    let erm = ErmSolver::new(ErmSettings::default()).unwrap();
    let skew = LinearMcp::from_rows(0, &[vec![0.0, 1.0], vec![-1.0, 0.0]], &[-1.0, -1.0]).unwrap();
    let negative = LinearMcp::from_rows(0, &[vec![-1.0]], &[-1.0]).unwrap();
    for (p, n) in [(&skew, 2), (&negative, 1)] {
        for sigma in [1e-3, 0.1] {
            match erm.solve(p, &vec![sigma; n], &vec![0.0; n]) {
                Err(NcpError::NoSolution { objective, bound }) => assert!(objective > bound),
                other => panic!("sigma {sigma}: expected NoSolution, got {other:?}"),
            }
        }
    }
    // A feasible problem next to it still converges.
    let fine = LinearMcp::from_rows(0, &[vec![2.0, 1.0], vec![1.0, 2.0]], &[-1.0, 1.0]).unwrap();
    let s = erm.solve(&fine, &[0.01, 0.01], &[0.0, 0.0]).unwrap();
    assert_eq!(s.info.status, Status::Converged);
}

#[test]
fn scene_sized_problems_agree_across_lemke_enumeration_and_hard_newton() {
    let mut solver = newton(NewtonSettings::default());
    for seed in 0..200 {
        let p = contact_step(seed);
        let exact = lemke(&p, &LemkeSettings::default()).unwrap();
        assert!(exact.info.residual <= 1e-12 * p.scale(), "seed {seed}");
        let all = enumerate_solutions(&p, 1e-11).unwrap();
        // Impulses need not be unique (A = J M^-1 J^T has rank 3), but the velocities are.
        assert!(
            all.iter().all(|z| max_diff(&z[..3], &exact.z[..3]) < 1e-9),
            "seed {seed}"
        );
        let s = solver
            .solve(&p, &[NcpFunction::FischerBurmeister; 6], &[0.0; 9])
            .unwrap();
        assert_eq!(
            s.info.status,
            Status::Converged,
            "seed {seed}: {:?}",
            s.info
        );
        assert!(max_diff(&s.z[..3], &exact.z[..3]) < 1e-9, "seed {seed}");
    }
}

#[test]
fn warm_start_from_the_previous_step_saves_iterations() {
    let mut solver = newton(NewtonSettings::default());
    let f = [NcpFunction::Logistic { sigma: 0.1 }; 6];
    let (mut cold, mut warm) = (0, 0);
    for seed in 0..100 {
        let p = contact_step(seed);
        let s = solver.solve(&p, &f, &[0.0; 9]).unwrap();
        let next = perturbed(&p, 1e-2, seed);
        let c = solver.solve(&next, &f, &[0.0; 9]).unwrap();
        let w = solver.solve(&next, &f, &s.z).unwrap();
        assert!(c.converged() && w.converged());
        assert!(max_diff(&c.z, &w.z) < 1e-10);
        cold += c.info.iterations;
        warm += w.info.iterations;
    }
    println!("iterations over 100 problems: cold {cold}, warm {warm}");
    assert!(10 * warm < 7 * cold, "cold {cold}, warm {warm}");
}

#[test]
fn faer_and_hand_back_ends_give_the_same_solutions() {
    let mut hand = newton(NewtonSettings::default());
    let mut faer = newton(NewtonSettings {
        linear_solver: ncp::LinearSolver::Faer,
        ..NewtonSettings::default()
    });
    for seed in 0..50 {
        let p = contact_step(seed);
        let f = [NcpFunction::Logistic { sigma: 0.01 }; 6];
        let a = hand.solve(&p, &f, &[0.0; 9]).unwrap();
        let b = faer.solve(&p, &f, &[0.0; 9]).unwrap();
        assert!(a.converged() && b.converged());
        assert!(max_diff(&a.z, &b.z) < 1e-12);
    }
}

/// A nonlinear complementarity problem supplied through the trait: one free row `x^3 + x - lambda = 1` and
/// one pair `0 <= lambda _|_ w = x + lambda^2 - 0.5 >= 0`.
#[derive(Debug)]
struct Cubic;

impl Mcp for Cubic {
    fn dim(&self) -> usize {
        2
    }
    fn n_free(&self) -> usize {
        1
    }
    fn evaluate(&self, z: &[f64], value: &mut [f64], jacobian: Option<&mut [f64]>) {
        let (x, l) = (z[0], z[1]);
        value[0] = x * x * x + x - l - 1.0;
        value[1] = x + l * l - 0.5;
        if let Some(j) = jacobian {
            j.copy_from_slice(&[3.0 * x * x + 1.0, -1.0, 1.0, 2.0 * l]);
        }
    }
}

#[test]
fn newton_solves_a_nonlinear_mcp_given_through_the_trait() {
    // x^3 + x = 1 has x = 0.6823 > 0.5, so w > 0 at lambda = 0: the solution is (0.6823..., 0).
    for f in [NcpFunction::FischerBurmeister, NcpFunction::Min] {
        let s = newton(NewtonSettings::default())
            .solve(&Cubic, &[f], &[3.0, 2.0])
            .unwrap();
        assert_eq!(s.info.status, Status::Converged, "{f:?}");
        assert!((s.z[0].powi(3) + s.z[0] - 1.0).abs() < 1e-13 && s.z[1].abs() < 1e-13);
    }
}

/// A problem that returns NaN away from the origin, as a broken model might.
#[derive(Debug)]
struct Poisoned;

impl Mcp for Poisoned {
    fn dim(&self) -> usize {
        1
    }
    fn n_free(&self) -> usize {
        1
    }
    fn evaluate(&self, z: &[f64], value: &mut [f64], jacobian: Option<&mut [f64]>) {
        value[0] = if z[0].abs() > 0.5 {
            f64::NAN
        } else {
            z[0] - 10.0
        };
        if let Some(j) = jacobian {
            j[0] = 1.0;
        }
    }
}

#[test]
fn bad_input_is_a_typed_error_and_bad_trial_points_never_leak_nan() {
    let p = contact_step(1);
    let f = [NcpFunction::Logistic { sigma: 0.1 }; 6];
    let mut s = newton(NewtonSettings::default());
    assert!(matches!(
        s.solve(&p, &f, &[f64::NAN; 9]),
        Err(NcpError::NonFinite { what: "z0", .. })
    ));
    assert!(matches!(
        s.solve(&p, &f, &[0.0; 8]),
        Err(NcpError::Dimension { what: "z0", .. })
    ));
    assert!(matches!(
        s.solve(&p, &f[..5], &[0.0; 9]),
        Err(NcpError::Dimension {
            what: "functions",
            ..
        })
    ));
    let bad_sigma = [NcpFunction::Logistic { sigma: -1.0 }; 6];
    assert!(matches!(
        s.solve(&p, &bad_sigma, &[0.0; 9]),
        Err(NcpError::Sigma(_))
    ));
    for bad in [
        NewtonSettings {
            tol: 0.0,
            ..NewtonSettings::default()
        },
        NewtonSettings {
            tol: f64::NAN,
            ..NewtonSettings::default()
        },
        NewtonSettings {
            max_iter: 0,
            ..NewtonSettings::default()
        },
        NewtonSettings {
            armijo: 0.7,
            ..NewtonSettings::default()
        },
        NewtonSettings {
            backtrack: 1.0,
            ..NewtonSettings::default()
        },
    ] {
        assert!(matches!(
            NewtonSolver::new(bad),
            Err(NcpError::Setting { .. })
        ));
    }
    let erm = ErmSolver::new(ErmSettings::default()).unwrap();
    assert!(matches!(
        erm.solve(&p, &[0.0; 6], &[0.0; 9]),
        Err(NcpError::Sigma(_))
    ));
    assert!(matches!(
        erm.solve(&p, &[0.1; 5], &[0.0; 9]),
        Err(NcpError::Dimension { .. })
    ));
    assert!(
        ErmSolver::new(ErmSettings {
            max_iter: 0,
            ..ErmSettings::default()
        })
        .is_err()
    );
    // The Newton step from 0 lands on x = 10 where the problem is NaN; every trial is rejected and the
    // last finite iterate comes back with its status.
    let r = s.solve(&Poisoned, &[], &[0.0]).unwrap();
    assert_eq!(r.info.status, Status::NonFinite);
    assert!(r.z[0].is_finite() && r.z[0].abs() <= 0.5);
    assert!(r.clone().into_converged().is_err());
    // A singular free block cannot be eliminated for the exact methods.
    let singular = LinearMcp::from_rows(1, &[vec![0.0, 1.0], vec![1.0, 0.0]], &[1.0, 1.0]).unwrap();
    assert!(matches!(
        lemke(&singular, &LemkeSettings::default()),
        Err(NcpError::SingularFreeBlock { .. })
    ));
}

#[test]
fn smoothed_solves_survive_tiny_and_huge_sigma() {
    let mut solver = newton(NewtonSettings::default());
    for seed in 0..30 {
        let p = contact_step(seed);
        let exact = lemke(&p, &LemkeSettings::default()).unwrap();
        for sigma in [1e-12, 1e-9, 1e-6, 1e2, 1e3] {
            // From the hard solution for tiny sigma (the continuation's end), from zero for huge sigma.
            let start = if sigma < 1.0 {
                exact.z.clone()
            } else {
                vec![0.0; 9]
            };
            let s = solver
                .solve(&p, &[NcpFunction::Logistic { sigma }; 6], &start)
                .unwrap();
            assert_eq!(
                s.info.status,
                Status::Converged,
                "seed {seed} sigma {sigma}: {:?}",
                s.info
            );
            assert!(s.z.iter().all(|v| v.is_finite()));
            if sigma < 1.0 {
                assert!(
                    max_diff(&s.z, &exact.z) <= 1e-5 * p.scale().max(1.0),
                    "sigma {sigma}"
                );
            }
        }
    }
}

#[test]
fn lemke_and_erm_refuse_problems_past_their_size_at_once() {
    // An identity LCP of 2000 rows: trivial data, but the methods' work grows as rows^3 per pivot or
    // iteration; they answer at once with the limit instead of running for minutes.
    let n = 2000;
    let mut m = vec![0.0; n * n];
    for i in 0..n {
        m[i * n + i] = 1.0;
    }
    let p = LinearMcp::from_row_major(0, m, vec![-1.0; n]).unwrap();
    let start = std::time::Instant::now();
    match lemke(&p, &LemkeSettings::default()) {
        Err(NcpError::TooLarge { rows, max, .. }) => assert_eq!((rows, max), (n, 500)),
        other => panic!("expected TooLarge, got {:?}", other.map(|s| s.info)),
    }
    let erm = ErmSolver::new(ErmSettings::default()).unwrap();
    assert!(matches!(
        erm.solve(&p, &vec![0.1; n], &vec![0.0; n]),
        Err(NcpError::TooLarge {
            rows: 2000,
            max: 300,
            ..
        })
    ));
    // Not a timing test: refusing must not even factor the problem (seconds for 2000 rows).
    assert!(start.elapsed().as_secs_f64() < 30.0);
    // Below the limit they still solve: 200 rows.
    let n = 200;
    let mut m = vec![0.0; n * n];
    for i in 0..n {
        m[i * n + i] = 2.0;
    }
    let p = LinearMcp::from_row_major(0, m, vec![-1.0; n]).unwrap();
    let s = lemke(&p, &LemkeSettings::default()).unwrap();
    assert!(s.z.iter().all(|z| (z - 0.5).abs() < 1e-12));
}

#[test]
fn lemke_finds_tiny_entries_on_rows_of_tiny_scale() {
    // Row 2's own scale is 1e-11 and its solution entry 1e-12: a ratio test that took ratios 1e-12 apart
    // (relative) for a tie once ended on w_2 = -1e-23 with z_2 = 0, a 100% error on that row, reported
    // "converged". Each row is judged in its own units.
    for (m22, q2) in [(1e-11, -1e-23), (1e-6, -1e-13), (1.0, -1e-12)] {
        let p = LinearMcp::from_rows(0, &[vec![1.0, 0.0], vec![0.0, m22]], &[-1.0, q2]).unwrap();
        let s = lemke(&p, &LemkeSettings::default()).unwrap();
        let exact = -q2 / m22;
        assert_eq!(s.info.status, Status::Converged);
        assert!(
            (s.z[1] - exact).abs() <= 1e-12 * exact,
            "M22 = {m22}: z2 = {} vs {exact}",
            s.z[1]
        );
        assert!((s.z[0] - 1.0).abs() < 1e-15);
    }
}

/// The three solvers through one call shape ([`ncp::Solver`]): a generic caller gets the exact answer
/// from Lemke's method and answers within O(sigma) of it from the smoothed Newton and ERM solvers.
#[test]
fn every_solver_answers_through_one_call_shape() {
    use ncp::{ErmSettings, ErmSolver, Lemke, NewtonSettings, NewtonSolver, Solver};
    fn solve<S: Solver + ?Sized>(s: &mut S, p: &LinearMcp, rows: &S::Rows) -> Vec<f64> {
        let z0 = vec![0.0; p.dim()];
        let out = s.solve(p, rows, &z0).unwrap();
        assert!(out.converged(), "{:?}", out.info);
        out.z
    }
    // One equality row (a velocity) and two complementarity rows (impulses), a P-matrix LCP.
    let p = LinearMcp::from_rows(
        1,
        &[
            vec![2.0, -1.0, -0.5],
            vec![1.0, 1.0, 0.2],
            vec![0.5, 0.2, 1.0],
        ],
        &[0.3, -0.4, 0.1],
    )
    .unwrap();
    let exact = solve(&mut Lemke::new(LemkeSettings::default()).unwrap(), &p, &());
    let sigma = 1e-4;
    let mut newton = NewtonSolver::new(NewtonSettings::default()).unwrap();
    let smooth = solve(&mut newton, &p, &[NcpFunction::Logistic { sigma }; 2]);
    let mut erm = ErmSolver::new(ErmSettings::default()).unwrap();
    let expected = solve(&mut erm, &p, &[sigma; 2]);
    for (name, z) in [("newton", &smooth), ("erm", &expected)] {
        let gap = z
            .iter()
            .zip(&exact)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(gap < 10.0 * sigma, "{name}: {z:?} vs exact {exact:?}");
    }
    assert!(
        exact.iter().any(|v| v.abs() > 1e-3),
        "a trivial solution tests nothing"
    );
    // The shape's checks: Lemke's settings and the start's length.
    assert!(
        Lemke::new(LemkeSettings {
            max_pivots: 0,
            ..LemkeSettings::default()
        })
        .is_err()
    );
    let mut lemke = Lemke::new(LemkeSettings::default()).unwrap();
    assert!(lemke.solve(&p, &(), &[0.0]).is_err());
}

/// Issue 27: Lemke's method panicked (an empty tie list) on a row whose entries were all subnormal, where
/// `1 / scale` overflowed and every ratio was NaN. Such a row with `q_i < 0` and no positive entry proves
/// the problem infeasible on its own.
#[test]
fn lemke_never_panics_on_subnormal_rows_and_names_a_row_that_proves_infeasibility() {
    let p = LinearMcp::from_rows(0, &[vec![0.0, 0.0], vec![0.0, 1.0]], &[-5e-324, -0.5]).unwrap();
    assert!(matches!(
        lemke(&p, &LemkeSettings::default()),
        Err(NcpError::InfeasibleRow { row: 0, .. })
    ));
    // Subnormal but feasible: the row scale stays finite and the answer is exact.
    let p =
        LinearMcp::from_rows(0, &[vec![1e-310, 0.0], vec![0.0, 1.0]], &[-5e-324, -0.5]).unwrap();
    let s = lemke(&p, &LemkeSettings::default()).unwrap();
    assert_eq!(s.info.status, Status::Converged);
    assert!((s.z[1] - 0.5).abs() < 1e-15, "{:?}", s.z);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]
    /// For any finite data, from 1e-320 to 1e300 in size, Lemke's method answers (a solution with a
    /// status, or a typed error) and never panics; a converged answer is complementary to the data's scale.
    #[test]
    fn lemke_answers_every_finite_problem_without_panicking(
        n in 1usize..7,
        entries in proptest::collection::vec((-1.0f64..1.0, -320i32..300), 56),
    ) {
        let value = |k: usize| entries[k].0 * 10f64.powi(entries[k].1);
        let m: Vec<f64> = (0..n * n).map(value).collect();
        let q: Vec<f64> = (0..n).map(|i| value(49 + i)).collect();
        let p = LinearMcp::from_row_major(0, m, q).unwrap();
        if let Ok(s) = lemke(&p, &LemkeSettings::default()) {
            prop_assert!(s.z.iter().all(|v| v.is_finite() && *v >= 0.0));
            if s.info.status == Status::Converged {
                prop_assert!(s.info.residual.is_finite());
            }
        }
    }
}

/// Lemke's revised form updates its basis inverse per pivot (O(n^2)) and refactors only now and then, so
/// a problem at the size limit answers in well under a second (was O(n^4): 400 rows took a minute); the
/// time is measured in the ncp benchmarks, this checks the answer at that size.
#[test]
fn lemke_solves_a_problem_at_its_size_limit_exactly() {
    let n = 300;
    let (p, planted) = planted_lcp(MatrixKind::PositiveDefinite, n, 7);
    let s = lemke(&p, &LemkeSettings::default()).unwrap();
    assert_eq!(s.info.status, Status::Converged);
    assert!(
        max_diff(&s.z, &planted) <= 1e-8 * p.scale(),
        "{}",
        max_diff(&s.z, &planted)
    );
}
