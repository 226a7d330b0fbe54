//! The trajectory library: receding-horizon building is reproducible, the nearest-neighbour policy of
//! eq. (20) respects the ellipse's symmetry and returns each stored controller's own law, and library files
//! survive a round trip while truncated, corrupt, foreign, future or mismatched files are refused whole.

use dynamics::Scene;
use library::{Library, LibraryError, LibrarySettings, MAGIC};

/// A small library (a few short trajectories) so that the tests stay fast.
fn small(seed: u64) -> Library {
    let settings = LibrarySettings {
        trajectories: 8,
        horizon: 40,
        first_passes: 60,
        warm_passes: 20,
        kick_every: 8,
        seed,
        ..LibrarySettings::paper()
    };
    Library::build(&task::ProblemFile::builtin(), None, &settings, |_, _| {}).unwrap()
}

#[test]
fn building_is_reproducible_and_the_seed_matters() {
    let (a, b, c) = (small(3), small(3), small(4));
    assert_eq!(a, b);
    assert_eq!(a.entries.len(), 8);
    assert_ne!(a.entries, c.entries);
    // The kicks changed the velocities of the later starts.
    assert!(a.entries[7].x[3..].iter().any(|v| v.abs() > 0.1));
    // Each stored controller has feedback.
    assert!(
        a.entries
            .iter()
            .all(|e| e.gain.iter().any(|k| k.abs() > 1e-3))
    );
}

#[test]
fn chains_built_in_parallel_are_the_chains_built_one_by_one() {
    let chained = |trajectories, chains, seed| {
        let settings = LibrarySettings {
            trajectories,
            chains,
            horizon: 30,
            first_passes: 40,
            warm_passes: 10,
            kick_every: 8,
            seed,
            ..LibrarySettings::paper()
        };
        let mut seen = Vec::new();
        let lib = Library::build(&task::ProblemFile::builtin(), None, &settings, |k, _| {
            seen.push(k)
        })
        .unwrap();
        (lib, seen)
    };
    let (both, seen) = chained(7, 2, 5);
    // Progress counts every trajectory once, whichever thread made it.
    assert_eq!(seen, (0..7).collect::<Vec<_>>());
    let (first, _) = chained(4, 1, 5);
    let (second, _) = chained(3, 1, 6);
    let expected: Vec<_> = first
        .entries
        .iter()
        .chain(&second.entries)
        .cloned()
        .collect();
    assert_eq!(both.entries, expected);
    assert_eq!(chained(7, 2, 5).0, both, "reproducible");
}

#[test]
fn the_policy_returns_each_controllers_own_law_and_respects_the_ellipses_symmetry() {
    let lib = small(3);
    let policy = lib.policy().unwrap();
    let mut u = [0.0; 2];
    for (i, e) in lib.entries.iter().enumerate() {
        // At a stored state: that controller, its own control.
        let j = policy.control(&e.x, &mut u).unwrap();
        assert_eq!(lib.entries[j].x, e.x, "entry {i}");
        assert!((u[0] - e.u[0]).abs() < 1e-12 && (u[1] - e.u[1]).abs() < 1e-12);
        // Nearby: the linear law u + K dx, saturated near the range the stored controls span.
        let dx = [1e-4, -2e-4, 3e-4, 1e-3, -1e-3, 2e-3];
        let x: Vec<f64> = e.x.iter().zip(&dx).map(|(a, b)| a + b).collect();
        assert_eq!(policy.control(&x, &mut u).unwrap(), j);
        for (a, ua) in u.iter().enumerate() {
            let (lo, hi) = policy.envelope()[a];
            let margin = library::SATURATION_MARGIN * (hi - lo);
            let expected = (e.u[a] + (0..6).map(|b| e.gain[a * 6 + b] * dx[b]).sum::<f64>())
                .clamp(lo - margin, hi + margin);
            assert!((ua - expected).abs() < 1e-12);
        }
        // The ellipse turned by pi is the same ellipse: same controller, same control.
        let mut turned = x.clone();
        turned[2] += std::f64::consts::PI;
        let mut v = [0.0; 2];
        assert_eq!(policy.control(&turned, &mut v).unwrap(), j);
        assert!((u[0] - v[0]).abs() < 1e-9 && (u[1] - v[1]).abs() < 1e-9);
        turned[2] -= 3.0 * std::f64::consts::PI;
        assert_eq!(policy.control(&turned, &mut v).unwrap(), j);
    }
    assert!(matches!(
        policy.control(&[0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0], &mut u),
        Err(LibraryError::Input { .. })
    ));
    assert!(policy.control(&[0.0; 5], &mut u).is_err());
}

/// A library whose payload sits just below a power of two loads back: bincode claims each number at its
/// size in memory, more than the varint it wrote, and a byte limit of the payload's own size refused such
/// files (a 6080-controller library of 4.006 MB against a limit of 4.194 MB, seen in use).
#[test]
fn a_library_whose_payload_is_just_below_a_power_of_two_loads_back() {
    let payload = |lib: &Library| {
        let bytes = lib.to_bytes().unwrap();
        u64::from_le_bytes(bytes[12..20].try_into().unwrap()) as usize
    };
    let base = small(5);
    for bits in [16u32, 18, 20] {
        let mut lib = base.clone();
        let mut k = 0;
        // Grow one controller at a time (each far smaller than 1% of the target) up to 98-100% of 2^bits.
        while (payload(&lib) as f64) < 0.98 * (1u64 << bits) as f64 {
            lib.entries
                .push(base.entries[k % base.entries.len()].clone());
            k += 1;
        }
        let size = payload(&lib);
        assert!(size < 1 << bits, "{size} for 2^{bits}");
        let back = Library::from_bytes(&lib.to_bytes().unwrap())
            .unwrap_or_else(|e| panic!("payload {size} bytes (2^{bits} = {}): {e}", 1u64 << bits));
        assert_eq!(back, lib);
    }
}

#[test]
fn a_library_file_round_trips_and_bad_files_are_refused_whole() {
    let lib = small(3);
    let dir = std::env::temp_dir().join(format!("slcp-library-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("finger.lib");
    lib.save(&path).unwrap();
    let back = Library::load(&path).unwrap();
    assert_eq!(back, lib);
    back.check_scene(&task::ProblemFile::builtin().scene)
        .unwrap();
    let bytes = std::fs::read(&path).unwrap();

    // Truncated anywhere: in the header or in the payload.
    for cut in [3, 10, 23, bytes.len() / 2, bytes.len() - 1] {
        let err = Library::from_bytes(&bytes[..cut]).unwrap_err();
        assert!(
            matches!(
                err,
                LibraryError::Truncated { .. } | LibraryError::NotALibrary
            ),
            "cut at {cut}: {err}"
        );
    }
    // One flipped bit in the payload.
    let mut corrupt = bytes.clone();
    let at = bytes.len() - 10;
    corrupt[at] ^= 0x10;
    assert!(matches!(
        Library::from_bytes(&corrupt),
        Err(LibraryError::Corrupt { .. })
    ));
    // Someone else's file, a future version, and trailing bytes.
    assert!(matches!(
        Library::from_bytes(b"PK\x03\x04 not a library at all"),
        Err(LibraryError::NotALibrary)
    ));
    let mut future = bytes.clone();
    let next = library::VERSION + 1;
    future[8..12].copy_from_slice(&next.to_le_bytes());
    assert!(matches!(
        Library::from_bytes(&future),
        Err(LibraryError::Version { found, .. }) if found == next
    ));
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(
        Library::from_bytes(&longer),
        Err(LibraryError::Invalid(_))
    ));
    assert_eq!(&bytes[..8], MAGIC);
    // A consistent checksum over a payload that decodes to nonsense (a NaN gain) is still refused.
    let mut broken = lib.clone();
    broken.entries[2].gain[5] = f64::NAN;
    assert!(matches!(
        Library::from_bytes(&broken.to_bytes().unwrap()),
        Err(LibraryError::Invalid(_))
    ));
    // A scene the library was not built for.
    let mut spec = task::ProblemFile::builtin().scene.spec().clone();
    spec.contacts[0].friction = 0.3;
    let other = Scene::new(spec).unwrap();
    assert!(matches!(
        lib.check_scene(&other),
        Err(LibraryError::SceneMismatch(_))
    ));
    // A missing file names itself.
    let err = Library::load(&dir.join("missing.lib")).unwrap_err();
    assert!(err.to_string().contains("missing.lib"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn impossible_library_settings_are_typed_errors() {
    let problem = task::ProblemFile::builtin();
    for s in [
        LibrarySettings {
            shift: 0,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            shift: 100,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            kick_variance: -1.0,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            x0: vec![0.0; 5],
            ..LibrarySettings::default()
        },
        LibrarySettings {
            h: f64::NAN,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            chains: 0,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            trajectories: 3,
            chains: 4,
            ..LibrarySettings::paper()
        },
        LibrarySettings {
            neighbours: 0,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            neighbours: 65,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            trajectories: 50,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            trajectories: usize::MAX,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            growth: 1000,
            ..LibrarySettings::default()
        },
        LibrarySettings {
            exploration: library::Exploration::Branches {
                trunk: 10,
                settle: 10,
                length: 5,
            },
            ..LibrarySettings::default()
        },
        LibrarySettings {
            exploration: library::Exploration::Branches {
                trunk: 10,
                settle: 2,
                length: 0,
            },
            ..LibrarySettings::default()
        },
    ] {
        assert!(
            matches!(
                Library::build(&problem, None, &s, |_, _| {}),
                Err(LibraryError::Setting { .. } | LibraryError::Input { .. })
            ),
            "{s:?}"
        );
    }
}

/// A small cycle-first library: a trunk, branches off it and growth rounds.
fn branched(chains: usize) -> Library {
    let settings = LibrarySettings {
        trajectories: 10,
        horizon: 30,
        first_passes: 60,
        warm_passes: 20,
        exploration: library::Exploration::Branches {
            trunk: 4,
            settle: 1,
            length: 2,
        },
        growth: 1,
        chains,
        ..LibrarySettings::default()
    };
    Library::build(&task::ProblemFile::builtin(), None, &settings, |_, _| {}).unwrap()
}

#[test]
fn branched_libraries_start_on_the_trunk_and_do_not_depend_on_the_threads() {
    let (one, two) = (branched(1), branched(2));
    assert_eq!(one.entries, two.entries);
    // Trunk and branches spend the budget (4 controllers each); growth may add more in branches of 2.
    assert!(one.entries.len() >= 40, "{}", one.entries.len());
    assert_eq!((one.entries.len() - 40) % 8, 0);
    // The trunk is unperturbed: each trajectory starts where the previous one was 4 steps on.
    let trunk_start = &one.entries[4].x;
    assert!(
        one.entries[..16]
            .iter()
            .all(|e| e.x.iter().all(|v| v.is_finite()))
    );
    assert_ne!(trunk_start, &one.entries[0].x);
    // A branch starts from a trunk state past the transient with perturbed velocities: its angles are a
    // trunk state's, its velocities are not.
    let branch = &one.entries[16].x;
    let trunk: Vec<&Vec<f64>> = one.entries[..16].iter().step_by(4).map(|e| &e.x).collect();
    assert!(
        trunk
            .iter()
            .any(|x| x[..3] == branch[..3] && x[3..] != branch[3..])
    );
    // Every controller carries a finite value model; a controller kept t steps into its trajectory
    // idles at its final state for the t steps it lacks, so all compare on one horizon.
    for e in &one.entries {
        assert!(e.value.cost_to_go.is_finite());
        assert!(
            (e.value.per_period + 31.0 * std::f64::consts::PI).abs() < 1e-9,
            "{:?}",
            e.value
        );
    }
}

fn entry(x: Vec<f64>) -> library::Entry {
    library::Entry {
        u: vec![x[0], -x[1]],
        gain: (0..12).map(|i| 0.1 * i as f64).collect(),
        value: library::LocalValue {
            cost_to_go: -x[2],
            gradient: vec![0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
            hessian: vec![0.0; 36],
            per_period: -std::f64::consts::PI,
        },
        ..sized_entry(x)
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    #[test]
    fn the_kd_tree_finds_what_a_scan_of_every_state_finds(
        states in proptest::collection::vec(proptest::collection::vec(-3.0f64..3.0, 6), 1..60),
        turns in proptest::collection::vec(-40i32..40, 60),
        duplicates in 0usize..5,
        queries in proptest::collection::vec(
            (proptest::collection::vec(-4.0f64..4.0, 6), -100.0f64..100.0),
            20,
        ),
    ) {
        // States anywhere, the free angle many turns away, some stored twice; queries anywhere.
        let mut entries: Vec<library::Entry> = states
            .iter()
            .zip(&turns)
            .map(|(x, k)| {
                let mut x = x.clone();
                x[2] += *k as f64 * std::f64::consts::PI;
                entry(x)
            })
            .collect();
        for i in 0..duplicates.min(entries.len()) {
            entries.push(entries[i].clone());
        }
        let tree = library::Policy::new(&entries, 6, 2, 2).unwrap();
        let scan = tree.clone().scanning();
        for (x, theta) in queries {
            let mut x = x;
            x[2] = theta;
            let (a, b) = (tree.nearest(&x).unwrap(), scan.nearest(&x).unwrap());
            // The same controller, or a stored duplicate of it, at the same number of periods.
            proptest::prop_assert!(
                a == b || (entries[a.0].x == entries[b.0].x && a.1 == b.1),
                "{a:?} vs {b:?}"
            );
            let (mut ua, mut ub) = ([0.0; 2], [0.0; 2]);
            tree.control(&x, &mut ua).unwrap();
            scan.control(&x, &mut ub).unwrap();
            proptest::prop_assert!((ua[0] - ub[0]).abs() < 1e-9 && (ua[1] - ub[1]).abs() < 1e-9);
        }
    }
}

/// A stored controller of a state of `x.len()` entries with one control, no cost and small gains (the
/// tests' other controllers change what they need).
fn sized_entry(x: Vec<f64>) -> library::Entry {
    let n = x.len();
    library::Entry {
        u: vec![x[0]],
        gain: vec![0.1; n],
        x,
        passes: 1,
        converged: true,
        cost: 0.0,
        value: library::LocalValue {
            cost_to_go: 0.0,
            gradient: vec![0.0; n],
            hessian: vec![0.0; n * n],
            per_period: 0.0,
        },
        reach: None,
        time_step: 0.05,
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]
    #[test]
    fn the_index_ranks_the_nearest_states_as_a_scan_does_at_every_state_size(
        half in 1usize..8,
        states in proptest::collection::vec(proptest::collection::vec(-3.0f64..3.0, 14), 1..80),
        queries in proptest::collection::vec(proptest::collection::vec(-4.0f64..4.0, 14), 8),
        count in 1usize..12,
    ) {
        // States of 2 to 14 entries: a kd-tree up to 12, a scan beyond (pushing and two fingers have
        // 10); the free angle at entry 1, periodic.
        let n = 2 * half;
        let entries: Vec<library::Entry> =
            states.iter().map(|x| sized_entry(x[..n].to_vec())).collect();
        let index = library::Policy::new(&entries, n, 1, 1).unwrap();
        let scan = index.clone().scanning();
        for q in &queries {
            let x = &q[..n];
            let (a, b) = (index.nearest_n(x, count).unwrap(), scan.nearest_n(x, count).unwrap());
            proptest::prop_assert_eq!(a.len(), count.min(3 * entries.len()));
            proptest::prop_assert_eq!(a.len(), b.len());
            // The same distances in the same order (equal distances may list their states either way).
            let mut last = 0.0;
            for (&(i, ti), &(j, tj)) in a.iter().zip(&b) {
                let (da, db) = (
                    index.distance(x, i, ti).unwrap(),
                    scan.distance(x, j, tj).unwrap(),
                );
                proptest::prop_assert!((da - db).abs() <= 1e-9 * (1.0 + db), "{da} vs {db}");
                proptest::prop_assert!(db >= last - 1e-9 * (1.0 + db), "not nearest first");
                last = db;
            }
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    #[test]
    fn the_policy_uses_the_lowest_predicted_value_among_its_nearest_controllers(
        states in proptest::collection::vec(proptest::collection::vec(-3.0f64..3.0, 6), 2..40),
        levels in proptest::collection::vec((-50.0f64..50.0, -5.0f64..5.0), 40),
        neighbours in 1usize..10,
        queries in proptest::collection::vec(proptest::collection::vec(-4.0f64..4.0, 6), 10),
    ) {
        let entries: Vec<library::Entry> = states
            .iter()
            .zip(&levels)
            .map(|(x, &(level, slope))| {
                let mut e = entry(x.clone());
                e.value.cost_to_go = level;
                e.value.gradient[0] = slope;
                // Curvature of either sign: the policy ranks the convexified models.
                e.value.hessian[7] = slope;
                e
            })
            .collect();
        let policy = library::Policy::new(&entries, 6, 2, 2)
            .unwrap()
            .with_neighbours(neighbours)
            .unwrap();
        for x in queries {
            let candidates = policy.nearest_n(&x, neighbours).unwrap();
            proptest::prop_assert_eq!(candidates.len(), neighbours.min(3 * entries.len()));
            let predict = |(i, turns): (usize, f64)| {
                let mut d: Vec<f64> = x.iter().zip(&entries[i].x).map(|(a, b)| a - b).collect();
                d[2] -= turns * std::f64::consts::PI;
                entries[i].value.convexified().predict(&d, turns)
            };
            let chosen = policy.select(&x).unwrap();
            proptest::prop_assert!(candidates.contains(&chosen));
            for &c in &candidates {
                proptest::prop_assert!(predict(chosen) <= predict(c) + 1e-9);
            }
            if neighbours == 1 {
                proptest::prop_assert_eq!(chosen, policy.nearest(&x).unwrap());
            }
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(128))]
    #[test]
    fn a_convexified_value_model_is_convex_never_predicts_less_and_keeps_a_convex_model(
        factors in proptest::collection::vec(-3.0f64..3.0, 36),
        signs in proptest::collection::vec(proptest::bool::ANY, 6),
        d in proptest::collection::vec(-2.0f64..2.0, 6),
    ) {
        // H = A diag(+-1) A^T: indefinite when the signs differ, convex when they are all positive.
        let mut e = entry(vec![0.0; 6]);
        e.value.gradient = vec![0.0; 6];
        let h = &mut e.value.hessian;
        for i in 0..6 {
            for j in 0..6 {
                h[i * 6 + j] = (0..6)
                    .map(|k| factors[i * 6 + k] * factors[j * 6 + k] * if signs[k] { 1.0 } else { -1.0 })
                    .sum();
            }
        }
        let raw = e.value.clone();
        let convex = raw.convexified();
        let scale = 200.0 * raw.hessian.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        // Convex along every direction tried, and never below the raw model.
        proptest::prop_assert!(convex.predict(&d, 0.0) - convex.cost_to_go >= -1e-9 * scale);
        proptest::prop_assert!(convex.predict(&d, 0.0) >= raw.predict(&d, 0.0) - 1e-9 * scale);
        if signs.iter().all(|s| *s) {
            for (a, b) in convex.hessian.iter().zip(&raw.hessian) {
                proptest::prop_assert!((a - b).abs() <= 1e-9 * scale);
            }
        }
    }
}

#[test]
fn a_concave_value_model_does_not_win_the_ranking_by_extrapolating() {
    // Two controllers a unit apart, the query a unit beyond the second: the far one's model is concave
    // (raw prediction 1 - 500 there), the near one's flat at 0. Ranked raw, the far one would win.
    let mut near = entry(vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    near.value.cost_to_go = 0.0;
    let mut far = entry(vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    far.value.cost_to_go = 1.0;
    far.value.hessian[0] = -250.0;
    let x = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert!(far.value.predict(&[2.0, 0.0, 0.0, 0.0, 0.0, 0.0], 0.0) < -400.0);
    let entries = vec![far, near];
    let policy = library::Policy::new(&entries, 6, 2, 2)
        .unwrap()
        .with_neighbours(2)
        .unwrap();
    assert_eq!(policy.nearest_n(&x, 2).unwrap().len(), 2);
    assert_eq!(policy.select(&x).unwrap().0, 1);
}

#[test]
fn a_controller_is_passed_over_beyond_its_reach_while_another_reaches() {
    // The far controller predicts the lower cost at the query and wins; with its reach ended short of
    // the query the near one is used; with the near one's reach ended short as well, both compete again.
    let mut near = entry(vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    near.value.cost_to_go = 0.0;
    let mut far = entry(vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    far.value.cost_to_go = -10.0;
    let x = [1.2, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut entries = vec![far, near];
    let policy = |entries: &[library::Entry]| {
        library::Policy::new(entries, 6, 2, 2)
            .unwrap()
            .with_neighbours(2)
            .unwrap()
    };
    let mut p = policy(&entries);
    assert_eq!(p.select(&x).unwrap().0, 0);
    let to_far = p.distance(&x, 0, 0.0).unwrap();
    let to_near = p.distance(&x, 1, 0.0).unwrap();
    assert!(to_far > to_near && to_near > 0.0);
    p.set_reach(0, 0.9 * to_far).unwrap();
    assert_eq!(p.select(&x).unwrap().0, 1);
    // The same from the entries' own reach, as a loaded library has it.
    entries[0].reach = Some(0.9 * to_far);
    assert_eq!(policy(&entries).select(&x).unwrap().0, 1);
    entries[1].reach = Some(0.5 * to_near);
    assert_eq!(policy(&entries).select(&x).unwrap().0, 0);
    // Within its reach the far one wins again.
    entries[0].reach = Some(1.1 * to_far);
    entries[1].reach = None;
    assert_eq!(policy(&entries).select(&x).unwrap().0, 0);
    assert!(p.set_reach(2, 1.0).is_err());
    assert!(p.set_reach(0, f64::NAN).is_err());
    assert!(p.set_reach(0, -1.0).is_err());
    assert!(p.distance(&[0.0; 5], 0, 0.0).is_err());
}

#[test]
fn a_policy_at_a_time_step_prefers_the_controllers_optimised_at_it() {
    // Two controllers near the query: the one optimised at the library's 0.05 s predicts the lower cost
    // and wins at 0.05 s and without a time step; at 0.03 s the one optimised there wins where it is a
    // candidate, and at a step neither was optimised at both compete again.
    let mut own = entry(vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    own.value.cost_to_go = -10.0;
    let mut finer = entry(vec![0.5, 0.0, 0.0, 0.0, 0.0, 0.0]);
    finer.value.cost_to_go = 0.0;
    finer.time_step = 0.03;
    let entries = vec![own, finer];
    let policy = || {
        library::Policy::new(&entries, 6, 2, 2)
            .unwrap()
            .with_neighbours(2)
            .unwrap()
    };
    let x = [0.2, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(policy().select(&x).unwrap().0, 0);
    let at = |h: f64| policy().with_time_step(h).unwrap().select(&x).unwrap().0;
    assert_eq!(at(0.05), 0);
    assert_eq!(at(0.03), 1);
    assert_eq!(at(0.01), 0);
    // With one neighbour the nearest alone is used, whatever its step.
    let nearest = library::Policy::new(&entries, 6, 2, 2)
        .unwrap()
        .with_time_step(0.03)
        .unwrap();
    assert_eq!(nearest.select(&x).unwrap().0, 0);
    for bad in [0.0, -0.03, f64::NAN, f64::INFINITY] {
        assert!(policy().with_time_step(bad).is_err(), "{bad}");
    }
    // A stored controller's time step must be positive and finite.
    let mut broken = entries.clone();
    broken[1].time_step = f64::NAN;
    let err = library::Policy::new(&broken, 6, 2, 2).unwrap_err();
    assert!(err.to_string().contains("controller 1"), "{err}");
}

#[test]
fn a_law_asking_beyond_the_stored_controls_pays_for_the_excess_and_is_saturated() {
    // Two controllers predicting nearly the same cost at the query; the better-predicted one's gain
    // asks there for a control of 1e4, a thousand times the stored range. Charged at the control
    // weight for the excess it loses; uncharged (weight 0) it wins, and within the range nothing moves.
    // Whichever wins, the control applied is saturated near the stored range: no trajectory asked more.
    let mut steep = entry(vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    steep.value.cost_to_go = -1.0;
    steep.gain = vec![0.0; 12];
    steep.gain[0] = 1e4;
    let mut calm = entry(vec![0.5, 0.0, 0.0, 0.0, 0.0, 0.0]);
    calm.value.cost_to_go = 0.0;
    calm.gain = vec![0.0; 12];
    let entries = vec![steep, calm];
    let policy = library::Policy::new(&entries, 6, 2, 2)
        .unwrap()
        .with_neighbours(2)
        .unwrap();
    let range = policy.envelope().to_vec();
    assert_eq!(range, vec![(0.0, 0.5), (-0.0, 0.0)]);
    let x = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let mut u = [0.0; 2];
    assert_eq!(policy.control(&x, &mut u).unwrap(), 0);
    // Saturated at the range widened by its width on either side (`SATURATION_MARGIN`): 0.5 + 0.5.
    assert_eq!(library::SATURATION_MARGIN, 1.0);
    assert_eq!(u, [1.0, 0.0]);
    // Within the range the law is applied as it is.
    assert_eq!(
        policy
            .control(&[2e-5, 0.0, 0.0, 0.0, 0.0, 0.0], &mut u)
            .unwrap(),
        0
    );
    assert_eq!(u[0], 1e4 * 2e-5);
    let charged = policy.clone().with_control_weight(0.05).unwrap();
    assert_eq!(charged.control(&x, &mut u).unwrap(), 1);
    // At the steep one's own state its law asks for its stored control: no charge, it wins.
    assert_eq!(charged.select(&[0.0; 6]).unwrap().0, 0);
    assert!(policy.clone().with_control_weight(-1.0).is_err());
    assert!(policy.with_control_weight(f64::NAN).is_err());
}

#[test]
fn saving_never_touches_another_file_and_a_bad_destination_is_found_before_a_build() {
    let dir = std::env::temp_dir().join(format!("slcp-save-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let lib = small(3);
    // A file that the old fixed temporary name (`X.partial`) would have overwritten and deleted.
    let target = dir.join("x.lib");
    let bystander = dir.join("x.partial");
    std::fs::write(&bystander, b"someone else's").unwrap();
    Library::check_destination(&target).unwrap();
    lib.save(&target).unwrap();
    assert_eq!(std::fs::read(&bystander).unwrap(), b"someone else's");
    assert_eq!(
        Library::load(&target).unwrap().entries.len(),
        lib.entries.len()
    );
    // A directory as the destination: refused up front, and a save there fails without leftovers.
    let sub = dir.join("sub.lib");
    std::fs::create_dir_all(&sub).unwrap();
    assert!(Library::check_destination(&sub).is_err());
    assert!(lib.save(&sub).is_err());
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".partial") && n != "x.partial")
        .collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
    // A folder that does not exist cannot take the file either.
    assert!(Library::check_destination(&dir.join("missing/x.lib")).is_err());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A controller of slider_push's state (pusher.position, block.x, block.y, block.angle and their
/// velocities) whose law and value model weigh every entry.
fn pusher_entry(x: Vec<f64>) -> library::Entry {
    library::Entry {
        u: vec![x[0] - 2.0 * x[1]],
        gain: (0..8).map(|i| 0.3 * i as f64 - 1.0).collect(),
        value: library::LocalValue {
            cost_to_go: x[1] * x[1],
            gradient: (0..8).map(|i| 0.1 * i as f64).collect(),
            hessian: (0..64)
                .map(|k| if k % 9 == 0 { 1.0 } else { 0.0 })
                .collect(),
            per_period: 0.0,
        },
        ..sized_entry(x)
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    /// A policy that compares an entry modulo a turn (a task's `Task::turn_symmetries`) answers a state
    /// and the same state with that angle turned by it alike (any whole number of half turns; any angle
    /// for a disc's), and a library whose stored angles were turned so is the same policy.
    #[test]
    fn a_policy_modulo_a_turn_answers_a_turned_state_alike(
        states in proptest::collection::vec(proptest::collection::vec(-1.0f64..1.0, 8), 12..48),
        stored_turns in proptest::collection::vec(-3i32..4, 48),
        query in proptest::collection::vec(-1.5f64..1.5, 8),
        turns in -3i32..4,
        neighbours in 1usize..4,
        round in proptest::bool::ANY,
        fraction in 0.0f64..1.0,
    ) {
        use std::f64::consts::PI;
        let progress = task::Progress { coordinate: 1, period: None, forward: None };
        // A disc's angle turns by any amount, an ellipse's by whole half turns.
        let (symmetry, step) = if round { (0.0, PI * fraction) } else { (PI, PI) };
        let build = |entries: &[library::Entry]| {
            library::Policy::for_task(entries, 8, 1, &progress, &[(3, symmetry)])
                .unwrap()
                .with_neighbours(neighbours)
                .unwrap()
        };
        let entries: Vec<_> = states.iter().cloned().map(pusher_entry).collect();
        let turned_entries: Vec<_> = states
            .iter()
            .zip(&stored_turns)
            .map(|(x, &k)| {
                let mut e = pusher_entry(x.clone());
                e.x[3] += f64::from(k) * step;
                e
            })
            .collect();
        let (policy, turned_policy) = (build(&entries), build(&turned_entries));
        let mut turned_query = query.clone();
        turned_query[3] += f64::from(turns) * step;
        let (mut u, mut v, mut w) = ([0.0], [0.0], [0.0]);
        let i = policy.control(&query, &mut u).unwrap();
        proptest::prop_assert_eq!(policy.control(&turned_query, &mut v).unwrap(), i);
        proptest::prop_assert_eq!(turned_policy.control(&query, &mut w).unwrap(), i);
        for other in [v[0], w[0]] {
            proptest::prop_assert!((u[0] - other).abs() <= 1e-9 * (1.0 + u[0].abs()), "{} against {}", u[0], other);
        }
        // Built without half-turn entries, a policy compares every entry as it is.
        let plain = library::Policy::for_task(&turned_entries, 8, 1, &progress, &[]).unwrap();
        proptest::prop_assert_eq!(plain.turn_symmetries(), Vec::<(usize, f64)>::new());
        proptest::prop_assert_eq!(policy.turn_symmetries(), vec![(3, symmetry)]);
    }
}

#[test]
fn a_turn_symmetry_out_of_range_periodic_or_of_another_turn_is_refused() {
    let entries: Vec<_> = (0..4)
        .map(|i| pusher_entry(vec![0.1 * i as f64; 8]))
        .collect();
    let plain = task::Progress {
        coordinate: 1,
        period: None,
        forward: None,
    };
    let periodic = task::Progress {
        coordinate: 3,
        period: Some(std::f64::consts::PI),
        forward: None,
    };
    let pi = std::f64::consts::PI;
    for (progress, turns) in [
        (plain, vec![(8, pi)]),
        (periodic, vec![(3, pi)]),
        (plain, vec![(3, 1.0)]),
        (plain, vec![(3, f64::NAN)]),
    ] {
        let err = library::Policy::for_task(&entries, 8, 1, &progress, &turns).unwrap_err();
        assert!(err.to_string().contains("turn symmetry"), "{err}");
    }
}
