//! The paper's experiment in closed loop (section V-C): under velocity kicks the library's global policy
//! spins the ellipse on the smoothed system it was built on and on the hard, non-smooth one, at the
//! library's time step and at another. The paper's library of single first controllers is compared.

use crate::support::finger_library as library;
use library::{Evaluation, EvaluationSettings, Library, Model, evaluate};

fn run(lib: &Library, model: Model, h: f64, kick_every: f64) -> Evaluation {
    let policy = lib.policy().unwrap();
    let e = evaluate(
        lib,
        &policy,
        &EvaluationSettings {
            model,
            h,
            seconds: 100.0,
            kick_every,
            ..EvaluationSettings::default()
        },
    )
    .unwrap();
    println!(
        "{model:?} h = {h}, kicks every {kick_every} s: spin {:.3} rad/s (last quarter {:.3}), {:.1} contacts/s, recovered {}/{}, resumed {}/{} in {:.1} s",
        e.spin_rate,
        e.final_spin_rate,
        e.contacts_per_second,
        e.recovered,
        e.kicks,
        e.resumed,
        e.kicks,
        e.resume_time
    );
    e
}

#[test]
fn under_kicks_the_global_policy_spins_the_ellipse_on_smoothed_and_hard_worlds() {
    // Velocity kicks every 10 s (the paper's experiment). Without kicks the policy may settle: with this
    // seed it spins on, with seeds 2 and 3 the finger comes to rest beside the ellipse (docs/results.md),
    // so only the kicked runs are asserted.
    let lib = library();
    assert_eq!(lib.entries.len(), 1600);
    for (model, h) in [
        (Model::Logistic(0.1), 0.05),
        (Model::Hard, 0.05),
        (Model::Logistic(0.1), 0.03),
    ] {
        let e = run(lib, model, h, 10.0);
        assert!(e.spin_rate > 0.1, "{model:?} at h = {h}: {e:?}");
        assert!(e.contacts_per_second > 0.2, "{e:?}");
        assert!(e.kicks >= 9);
        assert!(e.recovered * 10 >= e.kicks * 7, "{e:?}");
        // The stricter measure: a further quarter turn forward before the next kick.
        assert!(e.resumed * 2 >= e.kicks, "{e:?}");
        assert!(e.resume_time > 0.0 && e.resume_time < 10.0, "{e:?}");
        assert_eq!(e.unconverged_steps, 0);
    }
}

#[test]
fn the_papers_library_of_first_controllers_spins_slower_than_four_per_trajectory() {
    // The same optimisation keeping only each trajectory's first controller (the paper's library): its
    // laws are used up to four steps from their states, where gains of order 100 extrapolate badly.
    let lib = library();
    let mut paper = lib.clone();
    paper.entries = paper.entries.iter().step_by(4).cloned().collect();
    paper.settings.keep = 1;
    for model in [Model::Logistic(0.1), Model::Hard] {
        let first = run(&paper, model, 0.05, 10.0);
        let four = run(lib, model, 0.05, 10.0);
        assert!(
            first.spin_rate < 0.75 * four.spin_rate,
            "{first:?} vs {four:?}"
        );
    }
    // Without kicks it comes to a standstill from rest (by the last quarter of the run).
    let e = run(&paper, Model::Logistic(0.1), 0.05, 0.0);
    assert!(e.final_spin_rate.abs() < 0.05, "{e:?}");
}

#[test]
fn bad_evaluation_settings_are_typed_errors() {
    let lib = library();
    let policy = lib.policy().unwrap();
    // Another world: the same scene gives the same run; a world of other dimensions is refused.
    let short = EvaluationSettings {
        seconds: 5.0,
        ..EvaluationSettings::default()
    };
    // (Compared as text: the unused measures are NaN.)
    assert_eq!(
        format!(
            "{:?}",
            library::evaluate_in(lib.scene(), lib, &policy, &short).unwrap()
        ),
        format!("{:?}", evaluate(lib, &policy, &short).unwrap())
    );
    let mut spec = lib.scene().spec().clone();
    spec.bodies.truncate(2);
    spec.contacts.clear();
    spec.bodies[1].joint.actuated = false;
    let smaller = dynamics::Scene::new(spec).unwrap();
    assert!(matches!(
        library::evaluate_in(&smaller, lib, &policy, &short),
        Err(library::LibraryError::SceneMismatch(_))
    ));
    for s in [
        EvaluationSettings {
            h: 0.0,
            ..EvaluationSettings::default()
        },
        EvaluationSettings {
            seconds: f64::NAN,
            ..EvaluationSettings::default()
        },
        EvaluationSettings {
            kick_std: -1.0,
            ..EvaluationSettings::default()
        },
        EvaluationSettings {
            x0: vec![0.0; 3],
            ..EvaluationSettings::default()
        },
    ] {
        assert!(evaluate(lib, &policy, &s).is_err());
    }
}
