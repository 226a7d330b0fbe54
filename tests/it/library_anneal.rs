//! Noise annealing (paper section VI's proposal): lowering sigma step by step with warm starts reaches
//! sigmas at which a solve from zero controls never touches the ellipse.

use task::anneal;

#[test]
fn annealing_reaches_small_sigma_where_a_direct_solve_never_touches_the_ellipse() {
    let (scene, task) = task::ProblemFile::builtin_task();
    let schedule = [0.3, 0.2, 0.1, 0.05, 0.03, 0.02, 0.01, 0.005];
    let annealed = anneal(&scene, &task, &schedule, 300).unwrap();
    for s in &annealed {
        println!(
            "annealed sigma {}: {} passes, converged {}, cost {:.3}, theta3 turned {:.3}",
            s.sigma, s.passes, s.converged, s.cost, s.turned
        );
        assert!(s.converged, "sigma {}", s.sigma);
        assert!(s.turned > 0.8, "sigma {}: {}", s.sigma, s.turned);
    }
    for &sigma in &[0.02, 0.005] {
        let direct = &anneal(&scene, &task, &[sigma], 300).unwrap()[0];
        let warm = annealed.iter().find(|s| s.sigma == sigma).unwrap();
        println!(
            "direct sigma {sigma}: {} passes, cost {:.3}, theta3 turned {:.3}",
            direct.passes, direct.cost, direct.turned
        );
        assert!(direct.turned.abs() < 0.1, "{direct:?}");
        assert!(warm.cost < direct.cost - 10.0);
    }
}
