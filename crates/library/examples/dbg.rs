use ddp::*;
use dynamics::*;
use library::*;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reg = if args[1] == "s" {
        Regularisation::State
    } else {
        Regularisation::Control
    };
    let mu_init: f64 = args[2].parse().unwrap();
    let sigma: f64 = args[3].parse().unwrap();
    let mu_factor: f64 = args.get(4).map(|a| a.parse().unwrap()).unwrap_or(1.6);
    let verbose = args.len() > 5;
    let sim = Simulator::new(
        Scene::flicking_finger(),
        StepSettings {
            model: Complementarity::Logistic { sigma },
            ..StepSettings::default()
        },
    )
    .unwrap();
    let mut dynm = FingerDynamics::new(sim);
    let cost = finger_cost(3, 2, 2);
    let s = DdpSettings {
        method: Method::Full,
        regularisation: reg,
        mu_init,
        mu_factor,
        max_iterations: 300,
        ..DdpSettings::default()
    };
    let t = std::time::Instant::now();
    let sol = Ddp::new(s)
        .unwrap()
        .solve(
            &mut dynm,
            &cost,
            &FLICKING_FINGER_X0,
            &vec![vec![0.0; 2]; 75],
        )
        .unwrap();
    if verbose {
        for it in &sol.iterations {
            println!(
                "{:.6} red {:.3e} exp {:.3e} mu {:.2e} a {:.3} step {:.2e}",
                it.cost, it.reduction, it.expected, it.mu, it.alpha, it.step
            );
        }
    }
    let kmax = sol
        .gains
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    println!(
        "{reg:?} mu0 {mu_init} {:?} passes {} cost {:.9} theta3 {:.4} |K|max {:.3e} {:?}",
        sol.status,
        sol.iterations.len(),
        sol.cost,
        sol.states[75][2],
        kmax,
        t.elapsed()
    );
}
