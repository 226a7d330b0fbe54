//! The optimiser on problems with known answers: a linear-quadratic problem against an independent
//! Riccati recursion, the unicycle benchmark (free and boxed), and hard cases (indefinite `Q_uu`, dynamics
//! that fail for some controls, long horizons, bad input).

use ddp::problems::{Linear, Unicycle};
use ddp::{
    ControlLimits, Ddp, DdpError, DdpSettings, Dynamics, Method, QuadraticCost, SecondOrder,
};

fn lq_problem() -> (Linear, QuadraticCost) {
    // A lightly unstable 4-state, 2-control system.
    let a = vec![
        1.0, 0.1, 0.0, 0.0, //
        0.05, 1.02, 0.1, 0.0, //
        0.0, 0.0, 1.0, 0.1, //
        0.0, -0.03, 0.02, 0.99,
    ];
    let b = vec![0.0, 0.0, 0.1, 0.0, 0.0, 0.05, 0.02, 0.1];
    let cost = QuadraticCost {
        target: vec![0.0; 4],
        q: vec![
            2.0, 0.3, 0.0, 0.0, 0.3, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.1, 0.0, 0.0, 0.1, 0.2,
        ],
        q_lin: vec![0.1, 0.0, -0.2, 0.0],
        r: vec![0.3, 0.05, 0.05, 0.2],
        r_lin: vec![0.0, 0.01],
        qf: vec![
            10.0, 0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ],
        qf_lin: vec![0.0; 4],
    };
    (Linear { a, b, n: 4, m: 2 }, cost)
}

/// Independent discrete Riccati recursion with linear terms: value `1/2 x^T P x + p^T x`, control
/// `u = K x + k`. Returns the optimal cost from `x0` and the gains.
fn riccati(sys: &Linear, c: &QuadraticCost, x0: &[f64], horizon: usize) -> (f64, Vec<Vec<f64>>) {
    let (n, m) = (sys.n, sys.m);
    let at =
        |mat: &[f64], r: usize, cc: usize, i: usize, j: usize| mat[i * cc + j] + 0.0 * r as f64;
    let mut p = c.qf.clone();
    let mut pv = c.qf_lin.clone();
    let mut ks = vec![Vec::new(); horizon];
    let mut kff = vec![Vec::new(); horizon];
    for i in (0..horizon).rev() {
        // H = R + B^T P B, G = B^T P A, g = r + B^T p.
        let mut pb = vec![0.0; n * m];
        let mut pa = vec![0.0; n * n];
        for r in 0..n {
            for col in 0..m {
                pb[r * m + col] = (0..n)
                    .map(|l| p[r * n + l] * at(&sys.b, n, m, l, col))
                    .sum();
            }
            for col in 0..n {
                pa[r * n + col] = (0..n).map(|l| p[r * n + l] * sys.a[l * n + col]).sum();
            }
        }
        let mut h = c.r.clone();
        let mut g = vec![0.0; m * n];
        let mut gl = c.r_lin.clone();
        for r in 0..m {
            for col in 0..m {
                h[r * m + col] += (0..n)
                    .map(|l| sys.b[l * m + r] * pb[l * m + col])
                    .sum::<f64>();
            }
            for col in 0..n {
                g[r * n + col] = (0..n).map(|l| sys.b[l * m + r] * pa[l * n + col]).sum();
            }
            gl[r] += (0..n).map(|l| sys.b[l * m + r] * pv[l]).sum::<f64>();
        }
        // 2x2 inverse.
        let det = h[0] * h[3] - h[1] * h[2];
        let inv = [h[3] / det, -h[1] / det, -h[2] / det, h[0] / det];
        let mut kk = vec![0.0; m * n];
        let mut kf = vec![0.0; m];
        for r in 0..m {
            for col in 0..n {
                kk[r * n + col] = -(0..m).map(|l| inv[r * m + l] * g[l * n + col]).sum::<f64>();
            }
            kf[r] = -(0..m).map(|l| inv[r * m + l] * gl[l]).sum::<f64>();
        }
        // P = Q + A^T P A + G^T K (with K = -H^-1 G), p = q + A^T p + G^T k.
        let mut pn = c.q.clone();
        let mut pvn = c.q_lin.clone();
        for r in 0..n {
            for col in 0..n {
                pn[r * n + col] += (0..n)
                    .map(|l| sys.a[l * n + r] * pa[l * n + col])
                    .sum::<f64>()
                    + (0..m).map(|l| g[l * n + r] * kk[l * n + col]).sum::<f64>();
            }
            pvn[r] += (0..n).map(|l| sys.a[l * n + r] * pv[l]).sum::<f64>()
                + (0..m).map(|l| g[l * n + r] * kf[l]).sum::<f64>();
        }
        p = pn;
        pv = pvn;
        ks[i] = kk;
        kff[i] = kf;
    }
    // Roll out the optimal policy for its cost.
    let mut x = x0.to_vec();
    let mut total = 0.0;
    let sys = sys.clone();
    for i in 0..horizon {
        let u: Vec<f64> = (0..m)
            .map(|r| kff[i][r] + (0..n).map(|l| ks[i][r * n + l] * x[l]).sum::<f64>())
            .collect();
        total += ddp::Cost::running(c, i, &x, &u);
        let mut next = vec![0.0; n];
        sys.calc(&mut (), None, &x, &u, &mut next).unwrap();
        x = next;
    }
    total += ddp::Cost::terminal(c, &x);
    (total, ks)
}

#[test]
fn a_linear_quadratic_problem_converges_in_one_pass_to_the_riccati_solution() {
    let (sys, cost) = lq_problem();
    let x0 = [1.0, -0.5, 0.3, 0.8];
    let horizon = 40;
    let (optimum, gains) = riccati(&sys, &cost, &x0, horizon);
    for method in [Method::Full, Method::GaussNewton] {
        let settings = DdpSettings {
            method,
            mu_init: 0.0,
            ..DdpSettings::default()
        };
        let sol = Ddp::new(settings)
            .unwrap()
            .solve(&sys, &cost, &x0, &vec![vec![0.0; 2]; horizon])
            .unwrap();
        assert!(sol.status.converged(), "{:?}", sol.status);
        let first = sol.iterations[0];
        assert_eq!(first.alpha, 1.0);
        assert!(
            (first.cost - optimum).abs() <= 1e-12 * optimum.abs().max(1.0),
            "{} vs Riccati {}",
            first.cost,
            optimum
        );
        for (k, r) in sol.gains.iter().zip(&gains) {
            for (a, b) in k.iter().zip(r) {
                assert!((a - b).abs() < 1e-10, "{a} vs {b}");
            }
        }
        // The expected reduction of the one pass is exact for a quadratic problem.
        assert!((first.reduction - first.expected).abs() < 1e-10 * first.expected.abs());
    }
}

fn unicycle(method: Method, limits: Option<f64>) -> ddp::Solution {
    let settings = DdpSettings {
        method,
        control_limits: limits.map(|l| ControlLimits {
            lower: vec![-l; 2],
            upper: vec![l; 2],
        }),
        ..DdpSettings::default()
    };
    Ddp::new(settings)
        .unwrap()
        .solve(
            &Unicycle { dt: 0.1 },
            &Unicycle::benchmark_cost(),
            &Unicycle::X0,
            &vec![vec![0.0; 2]; Unicycle::HORIZON],
        )
        .unwrap()
}

#[test]
fn the_unicycle_converges_to_the_same_cost_with_full_ddp_and_ilqr_and_respects_its_box() {
    let full = unicycle(Method::Full, None);
    let gn = unicycle(Method::GaussNewton, None);
    println!(
        "unicycle: full {} passes cost {:.12}, iLQR {} passes cost {:.12}",
        full.iterations.len(),
        full.cost,
        gn.iterations.len(),
        gn.cost
    );
    assert!(full.status.converged() && gn.status.converged());
    assert!((full.cost - gn.cost).abs() < 1e-6 * full.cost);
    // Starts at distance sqrt(3) with cost 50 * 3 * 76 = 11400 if it never moved.
    assert!(full.cost < 11400.0 * 0.5);
    let boxed = unicycle(Method::Full, Some(2.0));
    println!(
        "boxed |u| <= 2: {} passes cost {:.12}",
        boxed.iterations.len(),
        boxed.cost
    );
    assert!(boxed.status.converged(), "{:?}", boxed.status);
    assert!(boxed.controls.iter().flatten().all(|u| u.abs() <= 2.0));
    assert!(
        boxed
            .controls
            .iter()
            .flatten()
            .any(|u| u.abs() > 2.0 - 1e-9)
    );
    assert!(boxed.cost >= full.cost - 1e-9);
}

/// The unicycle with its second derivatives of `c^T f` checked against differences of its first.
#[test]
fn unicycle_second_derivatives_match_differences_of_its_first() {
    let mut u = Unicycle { dt: 0.1 };
    let c = [0.3, -1.2, 0.7];
    let y0 = [0.2, -0.4, 0.9, 1.3, -0.6];
    let grad = |u: &mut Unicycle, y: &[f64]| {
        let (mut fx, mut fu) = (vec![0.0; 9], vec![0.0; 6]);
        u.calc_diff(&mut (), &y[..3], &y[3..], &mut fx, &mut fu)
            .unwrap();
        let mut g = vec![0.0; 5];
        for j in 0..3 {
            g[j] = (0..3).map(|i| c[i] * fx[i * 3 + j]).sum();
        }
        for k in 0..2 {
            g[3 + k] = (0..3).map(|i| c[i] * fu[i * 2 + k]).sum();
        }
        g
    };
    let (mut fx, mut fu, mut hess) = (vec![0.0; 9], vec![0.0; 6], vec![0.0; 25]);
    u.calc_diff2(&mut (), &y0[..3], &y0[3..], &c, &mut fx, &mut fu, &mut hess)
        .unwrap();
    for k in 0..5 {
        let (mut yp, mut ym) = (y0.to_vec(), y0.to_vec());
        yp[k] += 1e-6;
        ym[k] -= 1e-6;
        let (gp, gm) = (grad(&mut u, &yp), grad(&mut u, &ym));
        for i in 0..5 {
            let fd = (gp[i] - gm[i]) / 2e-6;
            assert!((fd - hess[i * 5 + k]).abs() < 1e-8, "H[{i}][{k}]");
        }
    }
}

/// Dynamics that fail for large controls: the line search must reject such trials, never propagate them.
struct Fragile(Unicycle);

#[derive(Debug)]
struct TooFast;
impl std::fmt::Display for TooFast {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "speed above 1.5")
    }
}
impl std::error::Error for TooFast {}

impl Dynamics for Fragile {
    type Error = TooFast;
    type Data = ();
    fn state_dim(&self) -> usize {
        3
    }
    fn control_dim(&self) -> usize {
        2
    }
    fn create_data(&self) {}
    fn calc(
        &self,
        _: &mut (),
        _: Option<&()>,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), TooFast> {
        if u[0].abs() > 1.5 {
            return Err(TooFast);
        }
        self.0.calc(&mut (), None, x, u, next).unwrap();
        if u[1].abs() > 1.5 {
            next[2] = f64::NAN;
        }
        Ok(())
    }
    fn calc_diff(
        &self,
        _: &mut (),
        x: &[f64],
        u: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), TooFast> {
        self.0.calc_diff(&mut (), x, u, fx, fu).unwrap();
        Ok(())
    }
}

#[test]
fn failing_and_nan_dynamics_are_rejected_trials_never_results() {
    let settings = DdpSettings {
        method: Method::GaussNewton,
        ..DdpSettings::default()
    };
    let sol = Ddp::new(settings)
        .unwrap()
        .solve(
            &Fragile(Unicycle { dt: 0.1 }),
            &Unicycle::benchmark_cost(),
            &Unicycle::X0,
            &vec![vec![0.0; 2]; Unicycle::HORIZON],
        )
        .unwrap();
    assert!(sol.cost.is_finite());
    assert!(sol.states.iter().flatten().all(|e| e.is_finite()));
    assert!(sol.controls.iter().flatten().all(|u| u.abs() <= 1.5));
    // Progress despite the failures (never moving costs 11400), and never uphill.
    assert!(sol.cost < 11400.0 * 0.7, "{}", sol.cost);
    let costs: Vec<f64> = sol.iterations.iter().map(|it| it.cost).collect();
    assert!(costs.windows(2).all(|w| w[1] <= w[0]), "{costs:?}");
    // Full DDP on dynamics without second derivatives is refused up front.
    let err = Ddp::new(DdpSettings::default()).unwrap().solve(
        &Fragile(Unicycle { dt: 0.1 }),
        &Unicycle::benchmark_cost(),
        &Unicycle::X0,
        &vec![vec![0.0; 2]; 10],
    );
    assert!(matches!(err, Err(DdpError::NoSecondDerivatives)));
    // An initial control sequence the dynamics cannot run is an error naming the step.
    let mut bad = vec![vec![0.0; 2]; 10];
    bad[3][0] = 2.0;
    let err = Ddp::new(DdpSettings {
        method: Method::GaussNewton,
        ..DdpSettings::default()
    })
    .unwrap()
    .solve(
        &Fragile(Unicycle { dt: 0.1 }),
        &Unicycle::benchmark_cost(),
        &Unicycle::X0,
        &bad,
    );
    assert!(
        matches!(err, Err(DdpError::InitialRollout { step: 3, .. })),
        "{err:?}"
    );
}

#[test]
fn an_indefinite_problem_is_regularised_not_followed_uphill() {
    // Negative control weight: Q_uu is indefinite for small mu; the schedule must raise mu and still
    // reduce the cost (the state cost dominates).
    let mut cost = Unicycle::benchmark_cost();
    cost.r = vec![-0.05, 0.0, 0.0, -0.05];
    let sol = Ddp::new(DdpSettings {
        mu_init: 0.0,
        max_iterations: 50,
        ..DdpSettings::default()
    })
    .unwrap()
    .solve(
        &Unicycle { dt: 0.1 },
        &cost,
        &Unicycle::X0,
        &vec![vec![0.0; 2]; Unicycle::HORIZON],
    )
    .unwrap();
    assert!(sol.iterations.iter().any(|it| it.mu > 0.0));
    let costs: Vec<f64> = sol.iterations.iter().map(|it| it.cost).collect();
    assert!(costs.windows(2).all(|w| w[1] <= w[0]), "{costs:?}");
    assert!(sol.cost < 11400.0 * 0.5);
}

#[test]
fn a_thousand_step_horizon_converges() {
    let sol = Ddp::new(DdpSettings::default())
        .unwrap()
        .solve(
            &Unicycle { dt: 0.01 },
            &QuadraticCost::diagonal(&[1.0; 3], &[0.1; 2], &[1000.0; 3]),
            &Unicycle::X0,
            &vec![vec![0.0; 2]; 1000],
        )
        .unwrap();
    assert!(sol.status.converged(), "{:?}", sol.status);
    assert!(
        sol.states[1000].iter().all(|e| e.abs() < 0.05),
        "{:?}",
        sol.states[1000]
    );
}

#[test]
fn bad_settings_and_inputs_are_typed_errors() {
    for s in [
        DdpSettings {
            tol_cost: -1.0,
            ..DdpSettings::default()
        },
        DdpSettings {
            mu_factor: 1.0,
            ..DdpSettings::default()
        },
        DdpSettings {
            control_limits: Some(ControlLimits {
                lower: vec![1.0],
                upper: vec![0.0],
            }),
            ..DdpSettings::default()
        },
    ] {
        assert!(Ddp::new(s).is_err());
    }
    for threads in [0, ddp::MAX_THREADS + 1, usize::MAX] {
        assert!(matches!(
            Ddp::new(DdpSettings {
                threads,
                ..DdpSettings::default()
            }),
            Err(DdpError::Setting {
                name: "threads",
                ..
            })
        ));
    }
    let ddp = Ddp::new(DdpSettings::default()).unwrap();
    let cost = Unicycle::benchmark_cost();
    let u = Unicycle { dt: 0.1 };
    assert!(matches!(
        ddp.solve(&u, &cost, &[0.0, f64::NAN, 0.0], &vec![vec![0.0; 2]; 5]),
        Err(DdpError::Input { what: "x0", .. })
    ));
    assert!(matches!(
        ddp.solve(&u, &cost, &Unicycle::X0, &[vec![0.0; 3]]),
        Err(DdpError::Input {
            what: "controls",
            ..
        })
    ));
    assert!(ddp.solve(&u, &cost, &Unicycle::X0, &[]).is_err());
}

#[test]
fn the_receding_horizon_shift_drops_d_controls_and_repeats_the_last() {
    let u: Vec<Vec<f64>> = (0..6).map(|i| vec![i as f64]).collect();
    let s = ddp::shift_controls(&u, 4);
    assert_eq!(
        s,
        vec![
            vec![4.0],
            vec![5.0],
            vec![5.0],
            vec![5.0],
            vec![5.0],
            vec![5.0]
        ]
    );
    assert_eq!(ddp::shift_controls(&u, 0), u);
    assert_eq!(ddp::shift_controls(&u, 10), vec![vec![5.0]; 6]);
}

/// The unicycle with a step that, like an iterative solve, is exact only to about 1e-13 relative: each
/// result is perturbed by a deterministic pseudo-random amount of that size.
struct Rounded(Unicycle);

impl Dynamics for Rounded {
    type Error = std::convert::Infallible;
    type Data = ();
    fn state_dim(&self) -> usize {
        3
    }
    fn control_dim(&self) -> usize {
        2
    }
    fn create_data(&self) {}
    fn calc(
        &self,
        _: &mut (),
        _: Option<&()>,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), Self::Error> {
        self.0.calc(&mut (), None, x, u, next)?;
        let mut bits = x.iter().chain(u).fold(0x9e37_79b9_7f4a_7c15u64, |h, e| {
            (h ^ e.to_bits()).wrapping_mul(0x0100_0000_01b3)
        });
        for e in next.iter_mut() {
            bits = bits.wrapping_mul(6364136223846793005).wrapping_add(1);
            let unit = (bits >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            *e *= 1.0 + 2e-13 * unit;
        }
        Ok(())
    }
    fn calc_diff(
        &self,
        _: &mut (),
        x: &[f64],
        u: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), Self::Error> {
        self.0.calc_diff(&mut (), x, u, fx, fu)
    }
    fn second_order(&self) -> Option<&dyn SecondOrder<(), Error = Self::Error>> {
        Some(self)
    }
}

impl SecondOrder<()> for Rounded {
    type Error = std::convert::Infallible;
    fn calc_diff2(
        &self,
        _: &mut (),
        x: &[f64],
        u: &[f64],
        c: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), Self::Error> {
        self.0.calc_diff2(&mut (), x, u, c, fx, fu, hess)
    }
}

#[test]
fn rounding_noise_in_the_steps_ends_in_convergence_not_in_a_failed_search() {
    // With a cost tolerance far below what noisy rollouts resolve, the line search eventually compares
    // rounding errors; the optimiser must recognise convergence there instead of raising the
    // regularisation to its limit and reporting no descent.
    let settings = DdpSettings {
        tol_cost: 1e-16,
        tol_step: 1e-16,
        ..DdpSettings::default()
    };
    let sol = Ddp::new(settings)
        .unwrap()
        .solve(
            &Rounded(Unicycle { dt: 0.1 }),
            &Unicycle::benchmark_cost(),
            &Unicycle::X0,
            &vec![vec![0.0; 2]; Unicycle::HORIZON],
        )
        .unwrap();
    let exact = unicycle(Method::Full, None);
    println!(
        "{:?} after {} passes, cost {:.12e} (exact dynamics {:.12e})",
        sol.status,
        sol.iterations.len(),
        sol.cost,
        exact.cost
    );
    assert_eq!(sol.status, ddp::Status::CostConverged);
    assert!((sol.cost - exact.cost).abs() < 1e-9 * exact.cost.abs());
}

#[test]
fn the_value_model_of_a_linear_quadratic_problem_predicts_the_optimal_cost_from_other_states() {
    // For LQ problems the backward pass's value is exact: the optimum from any other start is the
    // quadratic model's prediction, at every knot.
    let (sys, cost) = lq_problem();
    let x0 = [1.0, -0.5, 0.3, 0.8];
    let horizon = 40;
    for method in [Method::Full, Method::GaussNewton] {
        let settings = DdpSettings {
            method,
            mu_init: 0.0,
            ..DdpSettings::default()
        };
        let ddp = Ddp::new(settings).unwrap();
        let sol = ddp
            .solve(&sys, &cost, &x0, &vec![vec![0.0; 2]; horizon])
            .unwrap();
        assert_eq!(sol.values.len(), horizon + 1);
        assert!((sol.values[0].cost_to_go - sol.cost).abs() < 1e-12 * sol.cost.abs());
        for knot in [0, 17, horizon - 1] {
            let v = &sol.values[knot];
            let delta = [0.3, -0.2, 0.5, 0.1];
            let start: Vec<f64> = sol.states[knot]
                .iter()
                .zip(delta)
                .map(|(a, b)| a + b)
                .collect();
            let (optimum, _) = riccati(&sys, &cost, &start, horizon - knot);
            let mut predicted = v.cost_to_go;
            for a in 0..4 {
                predicted += v.gradient[a] * delta[a];
                for b in 0..4 {
                    predicted += 0.5 * delta[a] * v.hessian[a * 4 + b] * delta[b];
                }
            }
            assert!(
                (predicted - optimum).abs() < 1e-9 * optimum.abs().max(1.0),
                "knot {knot}: predicted {predicted}, optimum {optimum}"
            );
        }
        // The final knot's model is the final cost's.
        let last = &sol.values[horizon];
        assert!((last.cost_to_go - ddp::Cost::terminal(&cost, &sol.states[horizon])).abs() < 1e-12);
    }
}

/// A clock whose derivatives fail at some of its ticks: the state counts the steps (`x' = x + 1`, the
/// control unused), and `calc_diff` (and full DDP's `calc_diff2_prepare`) fail where `x` is one of `bad`.
struct FailingClock {
    bad: Vec<f64>,
}

#[derive(Debug)]
struct Tick(f64);

impl std::fmt::Display for Tick {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "no derivatives at tick {}", self.0)
    }
}

impl std::error::Error for Tick {}

impl FailingClock {
    fn check(&self, x: &[f64]) -> Result<(), Tick> {
        match self.bad.contains(&x[0]) {
            true => Err(Tick(x[0])),
            false => Ok(()),
        }
    }
}

impl Dynamics for FailingClock {
    type Error = Tick;
    type Data = ();

    fn state_dim(&self) -> usize {
        1
    }

    fn control_dim(&self) -> usize {
        1
    }

    fn create_data(&self) {}

    fn calc(
        &self,
        _: &mut (),
        _: Option<&()>,
        x: &[f64],
        _: &[f64],
        next: &mut [f64],
    ) -> Result<(), Tick> {
        next[0] = x[0] + 1.0;
        Ok(())
    }

    fn calc_diff(
        &self,
        _: &mut (),
        x: &[f64],
        _: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), Tick> {
        self.check(x)?;
        fx[0] = 1.0;
        fu[0] = 0.0;
        Ok(())
    }

    fn second_order(&self) -> Option<&dyn SecondOrder<(), Error = Tick>> {
        Some(self)
    }
}

impl SecondOrder<()> for FailingClock {
    type Error = Tick;

    fn calc_diff2_prepare(&self, _: &mut (), x: &[f64], _: &[f64]) -> Result<(), Tick> {
        self.check(x)
    }

    fn calc_diff2(
        &self,
        data: &mut (),
        x: &[f64],
        u: &[f64],
        _: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), Tick> {
        hess.fill(0.0);
        self.calc_diff(data, x, u, fx, fu)
    }
}

/// Knots differentiated on several threads (the calling thread takes the first run of knots, the pool
/// the others) report the first knot that fails, as one thread does: where ticks 10 and 60 of 75 fail
/// (in the calling thread's run and in a pool thread's), on 1, 2 and 3 threads, for full DDP and iLQR,
/// the error names step 10 and its cause; where only tick 60 fails (a pool thread's run alone), step 60.
#[test]
fn knots_on_several_threads_report_the_first_that_fails() {
    let cost = QuadraticCost::diagonal(&[1.0], &[1.0], &[1.0]);
    for (bad, first) in [(vec![60.0, 10.0], 10), (vec![60.0], 60)] {
        let clock = FailingClock { bad };
        for method in [Method::Full, Method::GaussNewton] {
            for threads in [1, 2, 3] {
                let ddp = Ddp::new(DdpSettings {
                    method,
                    threads,
                    ..DdpSettings::default()
                })
                .unwrap();
                match ddp.solve(&clock, &cost, &[0.0], &vec![vec![0.0]; 75]) {
                    Err(DdpError::Derivatives { step, source }) => {
                        assert_eq!(step, first, "{method:?} on {threads} threads");
                        assert_eq!(
                            source.to_string(),
                            format!("no derivatives at tick {first}")
                        );
                    }
                    other => panic!("{method:?} on {threads} threads: {other:?}"),
                }
            }
        }
    }
}
