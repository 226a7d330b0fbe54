//! Issue 27: inputs a hostile user can send get a typed error that names the problem, never a panic, a
//! hang or a silent NaN.

use crate::dynamics_world::PENDULUM;
use dynamics::{DynamicsError, Scene};

fn problems(text: &str) -> Vec<(String, String)> {
    match Scene::from_toml_str(text) {
        Err(DynamicsError::Scene(problems)) => {
            problems.into_iter().map(|p| (p.field, p.problem)).collect()
        }
        other => panic!("expected a refused scene, got {other:?}"),
    }
}

#[test]
fn magnitudes_past_the_scene_limits_are_refused_by_field() {
    // friction = 1e200 was accepted as finite and made Lemke's method panic in every command.
    let cases = [
        ("friction = 0.6", "friction = 1e200", "contact[0].friction"),
        (
            "anchor = [1.2, 0.0]",
            "anchor = [1e200, 0.0]",
            "body[1].anchor",
        ),
        (
            "centre = [-1.3, -0.4]",
            "centre = [1e9, -0.4]",
            "fixed[0].centre",
        ),
        (
            "point = [0.0, -1.8]",
            "point = [0.0, -1e300]",
            "plane[0].point",
        ),
        (
            "gravity = [0.0, -9.81]",
            "gravity = [0.0, -1e30]",
            "gravity",
        ),
    ];
    for (from, to, field) in cases {
        assert!(PENDULUM.contains(from), "{from}");
        let found = problems(&PENDULUM.replacen(from, to, 1));
        assert!(
            found.iter().any(|(f, _)| f == field),
            "{to}: {field} not in {found:?}"
        );
    }
}

#[test]
fn a_contact_pair_listed_twice_is_refused_either_way_round() {
    let twice = format!("{PENDULUM}\n[[contact]]\na = \"lower\"\nb = \"ground\"\nfriction = 0.2\n");
    let found = problems(&twice);
    assert!(
        found
            .iter()
            .any(|(f, p)| f == "contact[3].b" && p.contains("already contact[0]")),
        "{found:?}"
    );
}

#[test]
fn a_malformed_item_is_named_by_its_index() {
    let text = PENDULUM.replacen("name = \"lower\"\n", "", 1);
    let Err(DynamicsError::Parse(message)) = Scene::from_toml_str(&text) else {
        panic!("accepted")
    };
    assert!(
        message.starts_with("body[1]:") && message.contains("name"),
        "{message}"
    );
}

#[test]
fn a_scene_past_the_body_limit_is_refused_with_the_limit() {
    let mut text = String::from("gravity = [0.0, -1.0]\n");
    for i in 0..=dynamics::MAX_BODIES {
        text.push_str(&format!(
            "[[body]]\nname = \"b{i}\"\nsemi_axes = [0.1, 0.1]\nparent = \"world\"\nanchor = [{i}.0, 0.0]\ncentre = [0.0, 0.0]\njoint = {{ type = \"free\" }}\n"
        ));
    }
    let found = problems(&text);
    assert!(
        found
            .iter()
            .any(|(f, p)| f == "body" && p.contains("MAX_BODIES")),
        "{found:?}"
    );
}
