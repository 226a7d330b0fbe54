//! The paper's experiment in closed loop (section V-C): under velocity kicks the library's global policy
//! spins the ellipse on the smoothed system it was built on and on the hard, non-smooth one, at the
//! library's time step and at another. The paper's library of single first controllers is compared.

use crate::support::finger_library as library;
use library::{Evaluation, EvaluationSettings, Library, evaluate};
use task::ContactModel;

fn run(lib: &Library, model: ContactModel, h: f64, kick_every: f64) -> Evaluation {
    run_for(lib, model, h, kick_every, 100.0)
}

fn run_for(
    lib: &Library,
    model: ContactModel,
    h: f64,
    kick_every: f64,
    seconds: f64,
) -> Evaluation {
    let policy = lib.policy().unwrap();
    let e = evaluate(
        lib,
        &policy,
        &EvaluationSettings {
            model,
            h,
            seconds,
            kick_every,
            ..EvaluationSettings::default()
        },
    )
    .unwrap();
    println!(
        "{model:?} h = {h}, kicks every {kick_every} s: spin {:.3} rad/s (last quarter {:.3}), {:.1} contacts/s, recovered {}/{}, resumed {}/{} in {:?} s",
        e.spin_rate,
        e.final_spin_rate,
        e.contacts_per_second,
        e.recovered,
        e.kicks,
        e.resumed,
        e.kicks,
        e.resume_time
    );
    // The task-neutral measures of the finger's spin task: the rate of its one rewarded coordinate is the
    // spin (weighed -1 per step and -1 at the end: -2 in all), no targets, and the running cost per
    // second is what -theta3 + 0.05 |u|^2 sums to.
    let [rate] = e.task.rates.as_slice() else {
        panic!("{:?}", e.task.rates)
    };
    assert_eq!(rate.coordinate, "ellipse.angle");
    assert_eq!(rate.weight, -2.0);
    assert_eq!(rate.rate, e.spin_rate);
    assert_eq!(rate.final_rate, e.final_spin_rate);
    assert!(e.task.targets.is_empty());
    assert!(e.task.running_cost_per_second.is_finite());
    e
}

#[test]
fn from_rest_without_kicks_the_global_policy_spins_the_ellipse_in_a_steady_cycle_on_four_worlds() {
    // The paper's central result (IV-C, V-C): the time-independent policy settles on a limit cycle that
    // keeps spinning the ellipse, on the smoothed world it was built on and on the hard one, at the
    // library's time step and at another (`cargo xtask reproduce` sweeps eight seeds).
    let lib = library();
    assert!(lib.entries.len() >= 1600);
    for (model, h) in [
        (ContactModel::Logistic(0.1), 0.05),
        (ContactModel::Hard, 0.05),
        (ContactModel::Logistic(0.1), 0.03),
        (ContactModel::Hard, 0.03),
    ] {
        let e = run_for(lib, model, h, 0.0, 200.0);
        assert!(e.final_spin_rate > 0.5, "{model:?} at h = {h}: {e:?}");
        // A flick cycle, not a push: one or a few contacts per half turn of the ellipse (a flick, often
        // after a tap that repositions it; at h = 0.03 the two often merge into one contact, and slower
        // cycles take a few taps: 1.0 to 5.3 over the sweep's seeds), and out of contact most of the time.
        assert!(
            e.contacts_per_half_turn
                .is_some_and(|c| (0.9..6.0).contains(&c)),
            "{model:?} at h = {h}: {e:?}"
        );
        assert!(e.contact_fraction < 0.5, "{model:?} at h = {h}: {e:?}");
        assert_eq!(e.unconverged_steps, 0);
    }
}

#[test]
fn under_kicks_the_global_policy_resumes_its_cycle_on_smoothed_and_hard_worlds() {
    let lib = library();
    for (model, h) in [
        (ContactModel::Logistic(0.1), 0.05),
        (ContactModel::Hard, 0.05),
        (ContactModel::Logistic(0.1), 0.03),
    ] {
        let e = run(lib, model, h, 10.0);
        assert!(e.spin_rate > 0.5, "{model:?} at h = {h}: {e:?}");
        assert!(e.kicks >= 9);
        // A further quarter turn forward before the next kick after most kicks (this seed: 6-8 of 9-10
        // in 100 s; `cargo xtask reproduce` sweeps eight seeds over 200 s).
        assert!(e.resumed * 10 >= e.kicks * 6, "{e:?}");
        assert!(e.resume_time.is_some_and(|t| t > 0.0 && t < 10.0), "{e:?}");
    }
}

#[test]
fn the_default_recipe_spins_faster_than_the_papers_with_and_without_kicks() {
    let (paper, default) = (crate::support::paper_library(), library());
    assert_eq!(paper.entries.len(), 400);
    // Without kicks the paper's library is slower by the last quarter of the run (most seeds' stop; this
    // one's keeps a slower cycle: `cargo xtask seeds`).
    let (p, d) = (
        run(paper, ContactModel::Logistic(0.1), 0.05, 0.0),
        run(default, ContactModel::Logistic(0.1), 0.05, 0.0),
    );
    assert!(p.final_spin_rate < d.final_spin_rate, "{p:?} vs {d:?}");
    for model in [ContactModel::Logistic(0.1), ContactModel::Hard] {
        let (p, d) = (
            run(paper, model, 0.05, 10.0),
            run(default, model, 0.05, 10.0),
        );
        assert!(p.spin_rate < 0.8 * d.spin_rate, "{p:?} vs {d:?}");
    }
    // Ranking by value is what turns the same controllers into a cycle: the nearest alone stalls more,
    // above all at the time step no trajectory was optimised at, and recovers from kicks more slowly
    // (`cargo xtask seeds`: on the smoothed world at h = 0.03, 3 of 8 seeds steady with the nearest
    // controller against 8 of 8 ranked, and under kicks a last quarter about half as fast). Without
    // kicks a single seed may keep its cycle either way; under kicks it shows.
    let mut nearest = default.clone();
    nearest.settings.neighbours = 1;
    let ranked = run(default, ContactModel::Logistic(0.1), 0.03, 10.0);
    let alone = run(&nearest, ContactModel::Logistic(0.1), 0.03, 10.0);
    assert!(
        ranked.spin_rate > alone.spin_rate,
        "{ranked:?} vs {alone:?}"
    );
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
        // A kick that would overflow the step into a NaN.
        EvaluationSettings {
            kick_std: 1e300,
            ..EvaluationSettings::default()
        },
        EvaluationSettings {
            x0: vec![0.0; 3],
            ..EvaluationSettings::default()
        },
        // A count that would run for days, and a kick interval that would silently mean none.
        EvaluationSettings {
            seconds: 1e12,
            ..EvaluationSettings::default()
        },
        EvaluationSettings {
            kick_every: f64::NAN,
            ..EvaluationSettings::default()
        },
        EvaluationSettings {
            kick_every: -1.0,
            ..EvaluationSettings::default()
        },
    ] {
        assert!(evaluate(lib, &policy, &s).is_err(), "{s:?}");
    }
}
