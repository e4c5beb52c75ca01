//! Topology changes during a run: cuts and fracture as rules. After every change: the map is
//! valid, the total mass and the linear momentum are unchanged, duplicated vertices sit where
//! the original was, every cumulated embedding equals the sum of its elementary ones, and the
//! run goes on without NaN. A cut mesh behaves like a mesh built cut; a notched bar breaks at
//! its notch and nothing breaks below the threshold.

// Numeric test code: index loops mirror the math.
#![allow(
    clippy::needless_range_loop,
    clippy::doc_markdown,
    clippy::suboptimal_flops
)]

use crate::common;

use common::model;
use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_gmap::{GMap, OrbitType, Value};
use topomech_physics::{
    Config, Criterion, Cut, Fracture, Integrator, ModelSpec, Simulation, TimedEvent,
};

fn sim(mesh: &Mesh, models: Vec<ModelSpec>, f: impl FnOnce(&mut Config)) -> Simulation {
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let mut cfg = Config {
        models,
        ..Config::default()
    };
    f(&mut cfg);
    Simulation::new(g, cfg).unwrap()
}

fn real(g: &GMap, name: &str, d: topomech_gmap::Dart) -> f64 {
    match g.value(g.require(name).unwrap(), d).unwrap() {
        Value::Real(x) => x[0],
        v => panic!("{v:?}"),
    }
}

/// Every cumulated spring (edge) equals the sum of its elementary springs (half-edges),
/// checked by walking the map here.
fn check_cumulated(g: &GMap) {
    let dim = g.dimension();
    let k = g.require("spring_k").unwrap();
    for d in g.orbit_representatives(OrbitType::edge(dim)) {
        let mut slots = Vec::new();
        let mut sum = 0.0;
        for x in g.orbit(d, OrbitType::edge(dim)) {
            let s = g.embedding(k).slot(x);
            if !slots.contains(&s) {
                slots.push(s);
                sum += g.real(k, x)[0];
            }
        }
        let cum = real(g, "spring_k_edge", d);
        assert!(
            (cum - sum).abs() <= 1e-12 * sum.abs(),
            "edge at {d}: cumulated {cum} vs {sum}"
        );
    }
}

fn state(s: &Simulation) -> (f64, [f64; 3], Vec<[f64; 3]>) {
    (
        s.total_mass().unwrap(),
        s.momentum().unwrap(),
        s.vertex_vec3("position").unwrap(),
    )
}

fn check_change(before: &(f64, [f64; 3], Vec<[f64; 3]>), s: &Simulation) {
    let (m0, p0, x0) = before;
    let (m1, p1, x1) = state(s);
    assert!(s.gmap().is_valid());
    assert!((m1 - m0).abs() <= 1e-12 * m0, "mass {m0} -> {m1}");
    let scale = m0 * 1.0;
    for a in 0..3 {
        assert!(
            (p1[a] - p0[a]).abs() <= 1e-12 * scale.max(1.0),
            "momentum {p0:?} -> {p1:?}"
        );
    }
    assert!(x1.len() > x0.len(), "vertices were duplicated");
    // existing rows keep their meaning: the positions of rows 0..n-1 are those before, bit
    // for bit (new vertices are appended)
    assert!(x1[..x0.len()] == x0[..], "existing rows were renumbered");
    // every vertex, old or new, sits exactly where a vertex was at the instant of the cut
    let old: std::collections::HashSet<[u64; 3]> = x0.iter().map(|p| p.map(f64::to_bits)).collect();
    assert!(x1.iter().all(|p| old.contains(&p.map(f64::to_bits))));
    check_cumulated(s.gmap());
}

#[test]
fn a_cut_keeps_mass_momentum_positions_and_cumulated_springs() {
    for (mesh, normal, three) in [
        (
            cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra),
            [1.0, 0.0, 0.0],
            true,
        ),
        (
            cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Hexa),
            [1.0, 0.0, 0.0],
            true,
        ),
        (
            grid([4, 3], [2.0, 1.5], GridElement::Mixed),
            [1.0, 0.0, 0.0],
            false,
        ),
    ] {
        let models = if three {
            vec![
                model("stretch_cumulated", &[("stiffness", 1e4)]),
                model("corotational", &[]),
            ]
        } else {
            // (one stiffness: the two spring models share it, `stretch_init`)
            vec![
                model("stretch_cumulated", &[("stiffness", 1e4)]),
                model("stretch_elementary", &[("stiffness", 1e4)]),
            ]
        };
        let mut s = sim(&mesh, models, |c| {
            c.gravity = [0.0, -9.81, if three { 0.0 } else { -3.0 }];
            c.young = 1e5;
        });
        let v: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| [0.1 * p[1], -0.2 * p[0], 0.3])
            .collect();
        s.set_vertex_vec3("velocity", &v).unwrap();
        for _ in 0..10 {
            s.step().unwrap();
        }
        let before = state(&s);
        let n = s
            .cut(&Cut::Plane {
                normal,
                offset: 1.0,
            })
            .unwrap()
            .unsewn;
        assert!(n > 0);
        check_change(&before, &s);
        assert_eq!(s.gmap().cell_counts().components, 2);
        for _ in 0..50 {
            s.step().unwrap();
        }
        assert!(s
            .vertex_vec3("position")
            .unwrap()
            .iter()
            .all(|p| p.iter().all(|x| x.is_finite())));
        assert!(s.topology_changes().len() == 1 && s.topology_changes()[0].kind == "cut");
    }
}

/// Cutting a box in two gives what building the two halves directly gives: the same cell
/// counts and the same force on every vertex at the next step (compared as sorted lists of
/// (rest position, force), duplicated vertices included; the forces agree to 1e-12 of their
/// scale, rounding only).
#[test]
fn a_cut_mesh_matches_a_mesh_built_cut() {
    let whole = cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let half = cuboid([2, 2, 2], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let mut two = half.clone();
    let offset = two.points.len();
    two.points
        .extend(half.points.iter().map(|p| [p[0] + 1.0, p[1], p[2]]));
    two.kinds.extend(half.kinds.iter().copied());
    two.cells.extend(
        half.cells
            .iter()
            .map(|c| c.iter().map(|i| i + offset).collect::<Vec<_>>()),
    );
    let models = || {
        vec![
            model("stretch_cumulated", &[("stiffness", 1e4)]),
            model("corotational", &[]),
        ]
    };
    let mut a = sim(&whole, models(), |c| c.young = 1e5);
    let mut b = sim(&two, models(), |c| c.young = 1e5);
    a.cut(&Cut::Plane {
        normal: [1.0, 0.0, 0.0],
        offset: 1.0,
    })
    .unwrap();
    assert_eq!(a.gmap().cell_counts(), b.gmap().cell_counts());
    let deform = |s: &mut Simulation| {
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| {
                [
                    p[0] + 0.02 * (3.0 * p[1]).sin(),
                    p[1] + 0.03 * p[0] * p[2],
                    p[2] - 0.01 * p[0] * p[0],
                ]
            })
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
        s.forces().unwrap();
        let mut out: Vec<([f64; 3], [f64; 3])> = s
            .vertex_vec3("rest")
            .unwrap()
            .into_iter()
            .zip(s.vertex_vec3("force").unwrap())
            .collect();
        out.sort_by(|p, q| {
            p.0.partial_cmp(&q.0)
                .unwrap()
                .then(p.1.partial_cmp(&q.1).unwrap())
        });
        out
    };
    let (fa, fb) = (deform(&mut a), deform(&mut b));
    let scale = fb
        .iter()
        .flat_map(|v| v.1)
        .fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(scale > 1.0);
    for (p, q) in fa.iter().zip(&fb) {
        assert!(
            p.0.map(f64::to_bits) == q.0.map(f64::to_bits),
            "rest positions are copied exactly"
        );
        for k in 0..3 {
            assert!(
                (p.1[k] - q.1[k]).abs() <= 1e-12 * scale,
                "at {:?}: {:?} vs {:?}",
                p.0,
                p.1,
                q.1
            );
        }
    }
}

/// A bar with a notch on top at x = 3, pulled by a prescribed displacement of its end and
/// solved statically: below the threshold nothing opens; above it, the faces that open are all
/// at the notch, where the stress concentrates.
#[test]
fn a_notched_bar_breaks_at_the_notch() {
    let bar = cuboid([12, 2, 2], [6.0, 1.0, 1.0], BoxElement::Tetra);
    // the notch: the two top cubes around x = 3 (each cube is 6 consecutive tetrahedra)
    let mut notched = bar.clone();
    let keep: Vec<bool> = bar
        .cells
        .chunks(6)
        .flat_map(|cube| {
            let n = cube.len() as f64 * 4.0;
            let cx: f64 = cube
                .iter()
                .flatten()
                .map(|&i| bar.points[i][0])
                .sum::<f64>()
                / n;
            let cy: f64 = cube
                .iter()
                .flatten()
                .map(|&i| bar.points[i][1])
                .sum::<f64>()
                / n;
            let inside = (cx - 3.0).abs() < 0.5 && cy > 0.5;
            std::iter::repeat_n(!inside, cube.len())
        })
        .collect();
    notched.cells = bar
        .cells
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(c, _)| c.clone())
        .collect();
    notched.kinds = bar
        .kinds
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(c, _)| *c)
        .collect();
    assert_eq!(
        notched.cells.len(),
        bar.cells.len() - 24,
        "two cubes in x by two in z"
    );
    let run = |pull: f64, threshold: f64| -> Simulation {
        let (g, _) = build(&notched, &BuildOptions::default()).unwrap();
        let cfg = Config {
            models: vec![model("linear_fem", &[])],
            young: 1e6,
            poisson: 0.3,
            gravity: [0.0; 3],
            fixed: vec!["x < 1e-9".into()],
            prescribed: vec![("x > 6.0 - 1e-9".into(), [pull, 0.0, 0.0])],
            fracture: Some(Fracture {
                criterion: Criterion::Stress,
                threshold,
            }),
            integrator: Integrator::Static,
            ..Config::default()
        };
        let mut s = Simulation::new(g, cfg).unwrap();
        s.step().unwrap();
        s
    };
    let threshold = 2e4;
    // below: the load is small, nothing opens
    let s = run(0.02, threshold);
    assert!(
        s.topology_changes().is_empty(),
        "{:?}",
        s.topology_changes()
    );
    // increasing the load until something breaks
    let mut broke = None;
    for k in 1..=10 {
        let s = run(0.02 * f64::from(k + 1), threshold);
        if !s.topology_changes().is_empty() {
            broke = Some(s);
            break;
        }
    }
    let s = broke.expect("the bar breaks under a large enough pull");
    assert!(s.gmap().is_valid());
    // the faces that opened: 3-free faces inside the bar (not on its outer or notch surfaces)
    let g = s.gmap();
    let rest = g.require("rest").unwrap();
    let on_surface = |c: [f64; 3]| {
        let eps = 1e-9;
        c[0] < eps
            || c[0] > 6.0 - eps
            || c[1] < eps
            || c[1] > 1.0 - eps
            || c[2] < eps
            || c[2] > 1.0 - eps
            || ((c[0] - 2.5).abs() < eps || (c[0] - 3.5).abs() < eps) && c[1] > 0.5 - eps
            || (c[1] - 0.5).abs() < eps && (c[0] - 3.0).abs() < 0.5 + eps
    };
    let mut opened = 0;
    for d in g.orbit_representatives(OrbitType::parse("<0,1>").unwrap()) {
        if !g.is_free(3, d) {
            continue;
        }
        let face = g.orbit(d, OrbitType::parse("<0,1>").unwrap());
        let mut c = [0.0; 3];
        for &x in &face {
            for a in 0..3 {
                c[a] += g.real(rest, x)[a] / face.len() as f64;
            }
        }
        if !on_surface(c) {
            opened += 1;
            assert!(
                (c[0] - 3.0).abs() < 1.0,
                "a face opened away from the notch, at {c:?}"
            );
        }
    }
    assert!(opened > 0);
}

#[test]
fn bad_events_are_reported() {
    let mesh = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let mut s = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.events = vec![TimedEvent {
            time: 0.002,
            cut: Cut::Plane {
                normal: [1.0, 0.0, 0.0],
                offset: 100.0,
            },
        }];
    });
    s.step().unwrap();
    let e = s.step().unwrap_err().to_string();
    assert!(e.contains("misses the object"), "{e}");
    // the cut is named as given, readably
    assert!(
        e.contains("the timed cut (the plane [1, 0, 0] . x = 100) at t = 0.002"),
        "{e}"
    );
    let s = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.events = vec![TimedEvent {
            time: 5.0,
            cut: Cut::Plane {
                normal: [1.0, 0.0, 0.0],
                offset: 1.0,
            },
        }];
    });
    let e = s.check_events(1.0).unwrap_err().to_string();
    assert!(e.contains("after the end of the run"), "{e}");
    // a run of no step reaches no event, not even one at t = 0 (QA: it was skipped silently)
    let s = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.events = vec![TimedEvent {
            time: 0.0,
            cut: Cut::Plane {
                normal: [1.0, 0.0, 0.0],
                offset: 1.0,
            },
        }];
    });
    assert!(s.check_events(0.001).is_ok());
    let e = s.check_events(0.0).unwrap_err().to_string();
    assert!(e.contains("the event at t = 0 is never reached"), "{e}");
    // a predicate cut at a time happens in the run and separates the halves
    let mut s = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.events = vec![TimedEvent {
            time: 0.001,
            cut: Cut::Where("x > 0.99 && x < 1.01".into()),
        }];
        c.gravity = [0.0; 3];
    });
    s.step().unwrap();
    assert_eq!(s.gmap().cell_counts().components, 2);
}

/// Tearing: a cloth pulled apart at two corners tears where the springs stretch past the limit.
#[test]
fn cloth_tears_under_stretch() {
    let mesh = grid([6, 4], [3.0, 2.0], GridElement::Triangle);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("stretch_elementary", &[("stiffness", 1e3)])],
        density: 1.0,
        gravity: [0.0; 3],
        prescribed: vec![
            ("x < 1e-9 && y < 1e-9".into(), [-0.6, 0.0, 0.0]),
            ("x > 3.0 - 1e-9 && y < 1e-9".into(), [0.6, 0.0, 0.0]),
        ],
        fracture: Some(Fracture {
            criterion: Criterion::Strain,
            threshold: 0.2,
        }),
        damping: 2.0,
        ..Config::default()
    };
    let mut s = Simulation::new(g, cfg).unwrap();
    let m0 = s.total_mass().unwrap();
    for _ in 0..400 {
        s.step().unwrap();
    }
    assert!(!s.topology_changes().is_empty(), "the cloth tore");
    assert!(s.gmap().is_valid());
    assert!((s.total_mass().unwrap() - m0).abs() <= 1e-12 * m0);
}

/// Fracture and tearing, called at an instant: the same invariants as a cut (valid map, mass,
/// momentum, positions copied, cumulated springs), then the run goes on without NaN.
#[test]
fn fracture_and_tearing_keep_the_invariants() {
    for (mesh, three) in [
        (cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra), true),
        (grid([6, 4], [3.0, 2.0], GridElement::Triangle), false),
    ] {
        let models = vec![model("stretch_cumulated", &[("stiffness", 1e4)])];
        let mut s = sim(&mesh, models, |c| c.gravity = [0.0; 3]);
        // stretch a slab along y and give everything a velocity
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| {
                if p[0] > 0.9 && p[0] < 1.6 {
                    [p[0], 1.5 * p[1], p[2]]
                } else {
                    *p
                }
            })
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
        let v: Vec<[f64; 3]> = x.iter().map(|p| [0.2, -0.1 * p[0], 0.05 * p[1]]).collect();
        s.set_vertex_vec3("velocity", &v).unwrap();
        let before = state(&s);
        let n = s
            .fracture(Fracture {
                criterion: Criterion::Strain,
                threshold: 0.2,
            })
            .unwrap()
            .unsewn;
        assert!(n > 0, "something opens");
        check_change(&before, &s);
        assert!(s.gmap().cell_counts().components >= 2 || !three);
        for _ in 0..20 {
            s.step().unwrap();
        }
        assert!(s
            .vertex_vec3("position")
            .unwrap()
            .iter()
            .all(|p| p.iter().all(|x| x.is_finite())));
    }
}

/// Fracture skips the search over the faces when no value of the criterion's measure exceeds
/// the threshold (no mean of them can). The skip must never change the result: for
/// thresholds on both sides of the largest strain (and at it), in 2D and 3D, the number of
/// faces `Simulation::fracture` opens equals what the fracture rule itself finds when applied
/// to a copy of the same map after the same measure.
#[test]
fn fracture_skips_the_search_only_when_nothing_can_open() {
    use topomech_rules::{Params, Val};
    for (mesh, three) in [
        (cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra), true),
        (grid([6, 4], [3.0, 2.0], GridElement::Triangle), false),
    ] {
        let new = || {
            sim(
                &mesh,
                vec![model("stretch_cumulated", &[("stiffness", 1e4)])],
                |c| c.gravity = [0.0; 3],
            )
        };
        let stretched: Vec<[f64; 3]> = new()
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| [p[0] * (1.0 + 0.1 * p[1]), 1.3 * p[1], p[2]])
            .collect();
        // the strains of this state, from the rule that computes them, on a copy of the map
        let mut s = new();
        s.set_vertex_vec3("position", &stretched).unwrap();
        let mut g = s.gmap().clone();
        for rule in ["spring_strains_init", "spring_strains"] {
            s.rules()
                .apply_everywhere(&mut g, rule, &Params::new())
                .unwrap();
        }
        let id = g.embedding_id("spring_strain").unwrap();
        let max = g
            .orbit_representatives(OrbitType::parse("<0>").unwrap())
            .into_iter()
            .map(|d| g.real(id, d)[0])
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(max > 0.05, "the state is stretched ({max})");
        for threshold in [
            // (a threshold must be positive: the smallest that opens every stretched face)
            1e-12 * max,
            0.5 * max,
            max * (1.0 - 1e-9),
            max,
            max * (1.0 + 1e-9),
            2.0 * max,
        ] {
            let p: Params = [("threshold".to_string(), Val::F(threshold))].into();
            let mut full = g.clone();
            let want = s
                .rules()
                .apply_everywhere(&mut full, "fracture_strain", &p)
                .unwrap()
                .matches;
            let mut t = new();
            t.set_vertex_vec3("position", &stretched).unwrap();
            let got = t
                .fracture(Fracture {
                    criterion: Criterion::Strain,
                    threshold,
                })
                .unwrap()
                .unsewn;
            assert_eq!(
                got, want,
                "3D: {three}, threshold {threshold} (max strain {max})"
            );
            if threshold >= max {
                assert_eq!(got, 0);
            }
        }
    }
}

/// A fracture threshold at or below zero (or not finite) is refused, from the configuration
/// and from `Simulation::fracture` alike (scenes refused it, Python broke every element apart).
#[test]
fn a_fracture_threshold_that_is_not_positive_is_refused() {
    use topomech_physics::{Criterion, Fracture};
    let mesh = topomech_gmap::generators::cuboid(
        [2, 1, 1],
        [2.0, 1.0, 1.0],
        topomech_gmap::generators::BoxElement::Tetra,
    );
    let build = || {
        topomech_gmap::mesh::build(&mesh, &topomech_gmap::mesh::BuildOptions::default())
            .unwrap()
            .0
    };
    let springs = || {
        vec![topomech_physics::ModelSpec::with_reals(
            "stretch_cumulated",
            &[],
        )]
    };
    for t in [0.0, -1.0, f64::NAN] {
        let cfg = topomech_physics::Config {
            models: springs(),
            fracture: Some(Fracture {
                criterion: Criterion::Strain,
                threshold: t,
            }),
            ..topomech_physics::Config::default()
        };
        let e = topomech_physics::Simulation::new(build(), cfg)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("fracture threshold must be"), "{t}: {e}");
        let cfg = topomech_physics::Config {
            models: springs(),
            ..topomech_physics::Config::default()
        };
        let mut s = topomech_physics::Simulation::new(build(), cfg).unwrap();
        let e = s
            .fracture(Fracture {
                criterion: Criterion::Strain,
                threshold: t,
            })
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("fracture threshold must be"), "{t}: {e}");
        assert!(s.topology_changes().is_empty());
    }
}

/// A plane given by a tiny (or huge) normal and offset is the same plane: it opens the same
/// faces as the unit normal (the guard multiplies two signed distances, which a normal of
/// 1e-200 would underflow to zero: the plane is scaled by a power of two first, exactly).
#[test]
fn a_plane_cut_does_not_depend_on_the_scale_of_its_normal() {
    let mesh = cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let opened = |k: f64| {
        let mut s = sim(&mesh, vec![model("stretch_elementary", &[])], |_| {});
        s.cut(&Cut::Plane {
            normal: [k, k, 0.0],
            offset: 0.93 * k,
        })
        .unwrap()
        .unsewn
    };
    let want = opened(1.0);
    assert!(want > 0);
    for k in [1e-300, 1e-200, 1e-160, 3.0, 1e200, 1e300] {
        assert_eq!(opened(k), want, "normal scaled by {k:e}");
    }
}

/// Vertex coordinates whose sums could overflow are refused by the cuts that sum them, with
/// the largest coordinate named (QA: a body scaled to 1e308 had its plane cut open 5 faces of
/// the 30 it opens at 1e307, without a word): a plane cut takes them up to 1e300 (it opens
/// there what it opens at scale 1 scaled), a blade up to 1e100, as it does its own points.
#[test]
fn cuts_refuse_coordinates_their_tests_would_overflow() {
    let mesh = cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let scaled = |k: f64| {
        let mut s = sim(&mesh, vec![model("stretch_elementary", &[])], |_| {});
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("position")
            .unwrap()
            .iter()
            .map(|p| p.map(|v| v * k))
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
        s
    };
    let plane = |s: &mut Simulation| {
        s.cut(&Cut::Plane {
            normal: [1.0, -1.0, 0.0],
            offset: 0.0,
        })
    };
    let want = plane(&mut scaled(1.0)).unwrap().unsewn;
    assert!(want > 0);
    assert_eq!(plane(&mut scaled(1e299)).unwrap().unsewn, want);
    let err = plane(&mut scaled(5e307)).unwrap_err().to_string();
    assert!(
        err.contains("at most 1e300") && err.contains("the largest is 1e308"),
        "{err}"
    );
    let blade = |s: &mut Simulation| {
        s.cut_swept(
            [[1.0, -1.0, -1.0], [1.0, -1.0, 2.0]],
            [[1.0, 2.0, -1.0], [1.0, 2.0, 2.0]],
        )
    };
    assert!(blade(&mut scaled(1.0)).unwrap().unsewn > 0);
    let err = blade(&mut scaled(1e101)).unwrap_err().to_string();
    assert!(
        err.contains("a blade needs vertex coordinates of at most 1e100"),
        "{err}"
    );
}

/// A stress fracture on a mesh whose volumes are not all tetrahedra is refused when the
/// simulation is built (the stress is computed per tetrahedron: a hexahedron would never
/// break, silently).
#[test]
fn a_stress_fracture_on_hexahedra_is_refused() {
    let mesh = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Hexa);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("corotational", &[])],
        fixed: vec!["x < 1e-9".into()],
        fracture: Some(Fracture {
            criterion: Criterion::Stress,
            threshold: 1e3,
        }),
        ..Config::default()
    };
    let e = Simulation::new(g, cfg).unwrap_err().to_string();
    assert!(
        e.contains("needs tetrahedra: 2 of the mesh's 2 volumes"),
        "{e}"
    );
}

/// Plane and predicate cuts test only the faces near the region they can open (the plane's
/// section of the positions' box, the box a predicate's comparisons bound): on a deformed box,
/// for axis-aligned and tilted planes and for predicates with and without such bounds, the
/// map after the cut is the one the interpreter's cut (every face tried) gives, link for link.
#[test]
fn cuts_tested_near_their_region_open_what_every_face_tried_opens() {
    let mesh = cuboid([6, 3, 3], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let wavy = |s: &mut Simulation| {
        let rest = s.vertex_vec3("rest").unwrap();
        let x: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| [p[0] + 0.03 * (5.0 * p[1]).sin(), p[1], p[2] + 0.02 * p[0]])
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
    };
    let preds = [
        "x > 0.99 && x < 1.01 && y < 0.4",
        "0.75 < x && x < 0.8 && 0.5 >= z",
        "x * x + y * y < 0.5",
        "y > 0.3 || z > 0.9",
    ];
    let mut opened = 0;
    for (k, pred) in preds.iter().enumerate() {
        let events = vec![TimedEvent {
            time: Config::default().dt,
            cut: Cut::Where((*pred).into()),
        }];
        let model = || vec![model("stretch_cumulated", &[("stiffness", 1e3)])];
        let mut a = sim(&mesh, model(), |c| c.events = events.clone());
        let mut b = sim(&mesh, model(), |c| c.events = events.clone());
        b.set_compiled(false);
        for s in [&mut a, &mut b] {
            wavy(s);
            s.step().unwrap();
        }
        let n = |s: &Simulation| -> usize { s.topology_changes().iter().map(|c| c.unsewn).sum() };
        assert_eq!(n(&a), n(&b), "predicate {k}: {pred}");
        assert!(
            a.rules().culled_guard_runs() > 0,
            "{pred}: the guard ran near its box"
        );
        opened += n(&a);
        assert_same_links(a.gmap(), b.gmap(), pred);
        // and a plane, axis-aligned then tilted, on the maps as cut
        for (normal, offset) in [([1.0, 0.0, 0.0], 1.33), ([0.6, 0.8, 0.0], 0.9)] {
            let (ra, rb) = (
                a.cut(&Cut::Plane { normal, offset }).unwrap(),
                b.cut(&Cut::Plane { normal, offset }).unwrap(),
            );
            assert_eq!(ra.unsewn, rb.unsewn, "plane {normal:?} after {pred}");
            assert!(ra.unsewn > 0, "plane {normal:?} after {pred}");
            assert_same_links(a.gmap(), b.gmap(), pred);
        }
    }
    assert!(opened > 4, "{opened}");
}

fn assert_same_links(a: &GMap, b: &GMap, what: &str) {
    assert!(a.is_valid() && b.is_valid(), "{what}");
    assert_eq!(a.capacity(), b.capacity(), "{what}");
    for d in a.darts() {
        for i in 0..=a.dimension() {
            assert_eq!(a.alpha(i, d), b.alpha(i, d), "{what}: alpha{i}({d})");
        }
    }
}

/// A plane cut of a body far smaller than usual (coordinates about 1e-170 m, whose signed
/// distances to the plane multiply to a number below the smallest float) opens the faces it
/// opens on the body at its usual size: the guard compares the two centroids' signs instead
/// of testing their product, which underflowed to 0 and opened nothing.
#[test]
fn a_plane_cut_of_a_tiny_body_opens_the_faces_of_the_usual_one() {
    let mesh = cuboid([4, 4, 4], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let model = || vec![model("stretch_cumulated", &[("stiffness", 1e3)])];
    let mut counts = Vec::new();
    for scale in [1.0, 1e-170] {
        let mut s = sim(&mesh, model(), |_| {});
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("position")
            .unwrap()
            .iter()
            .map(|p| p.map(|v| v * scale))
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
        let straight = s
            .cut(&Cut::Plane {
                normal: [1.0, 0.0, 0.0],
                offset: 0.5 * scale,
            })
            .unwrap();
        let tilted = s
            .cut(&Cut::Plane {
                normal: [1.0, 1.0, 0.0],
                offset: 0.8 * scale,
            })
            .unwrap();
        assert!(s.gmap().is_valid());
        counts.push((straight.unsewn, tilted.unsewn));
    }
    assert!(counts[0].0 > 0 && counts[0].1 > 0, "{counts:?}");
    assert_eq!(counts[0], counts[1], "the usual body against the tiny one");
}

/// The strain criterion multiplies each edge's length by its inverse rest length, computed
/// once (`spring_strains_init`) before the first fracture test; edges that later cuts and
/// fractures split must keep it (their orbits' values are copied to both parts). After a
/// plane cut, a fracture burst and steps, on a box (3D) and a sheet (2D): every edge's
/// stored value equals 1 / |rest_b - rest_a| of its two vertices now, and every edge's strain
/// is |x_b - x_a| / |rest_b - rest_a| - 1 computed here; 4 ulps (one product and the
/// rounding of the reciprocal against a quotient).
#[test]
fn the_strains_inverse_rest_lengths_survive_cuts_and_fractures() {
    for (mesh, dim) in [
        (cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra), 3),
        (grid([8, 4], [4.0, 2.0], GridElement::Triangle), 2),
    ] {
        let mut s = sim(
            &mesh,
            vec![model("stretch_cumulated", &[("stiffness", 1e4)])],
            |c| {
                c.gravity = [0.0; 3];
                c.fracture = Some(Fracture {
                    criterion: Criterion::Strain,
                    threshold: 0.2,
                });
            },
        );
        s.cut(&Cut::Plane {
            normal: [1.0, 0.0, 0.0],
            offset: 1.3,
        })
        .unwrap();
        // stretch a slab so that the fracture opens faces there
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| {
                if p[0] > 0.4 && p[0] < 0.9 {
                    [p[0], 1.5 * p[1], p[2]]
                } else {
                    *p
                }
            })
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
        let opened = s
            .fracture(Fracture {
                criterion: Criterion::Strain,
                threshold: 0.2,
            })
            .unwrap()
            .unsewn;
        assert!(opened > 0, "{dim}D: the fracture opened nothing");
        for _ in 0..3 {
            s.step().unwrap();
        }
        // the strains of the state now, as the criterion computes them
        let mut g = s.gmap().clone();
        s.rules()
            .apply_everywhere(&mut g, "spring_strains", &topomech_rules::Params::new())
            .unwrap();
        let (rest, pos) = (g.require("rest").unwrap(), g.require("position").unwrap());
        let (inv, strain) = (
            g.require("spring_inv_l0").unwrap(),
            g.require("spring_strain").unwrap(),
        );
        let dist = |a: &[f64], b: &[f64]| {
            ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt()
        };
        let close = |a: f64, b: f64| (a - b).abs() <= 4.0 * f64::EPSILON * a.abs().max(b.abs());
        let mut edges = 0;
        for d in g.orbit_representatives(OrbitType::edge(dim)) {
            let e = g.alpha(0, d);
            let l0 = dist(g.real(rest, d), g.real(rest, e));
            let l = dist(g.real(pos, d), g.real(pos, e));
            let stored = g.real(inv, d)[0];
            assert!(
                close(stored, 1.0 / l0),
                "{dim}D edge at {d}: {stored} vs 1/{l0}"
            );
            let want = l / l0 - 1.0;
            let got = g.real(strain, d)[0];
            assert!(
                (got - want).abs() <= 4.0 * f64::EPSILON * (1.0 + want.abs()),
                "{dim}D edge at {d}: strain {got} vs {want}"
            );
            edges += 1;
        }
        assert!(edges > 0);
    }
}

/// The strain criterion skips its evaluation while no spring can have reached the threshold
/// since the last one (no vertex moved far enough: `events::StrainBound`). On a box, a slab
/// stretched a little more at each call: the calls where the slab moved little skip (the
/// strain column is left as it was), the others compute; and every call opens exactly what
/// the same call opens on a new simulation set to the same positions (which has no last
/// evaluation to skip from), up to and including the first call that opens faces.
#[test]
fn the_strain_criterion_skips_only_calls_where_nothing_can_open() {
    let mesh = cuboid([6, 2, 2], [3.0, 1.0, 1.0], BoxElement::Tetra);
    let threshold = 0.2;
    let fracture = Fracture {
        criterion: Criterion::Strain,
        threshold,
    };
    let new = || {
        sim(
            &mesh,
            vec![model("stretch_cumulated", &[("stiffness", 1e4)])],
            |c| {
                c.gravity = [0.0; 3];
                c.fracture = Some(fracture);
            },
        )
    };
    let mut s = new();
    let rest = s.vertex_vec3("rest").unwrap();
    let strains = |s: &Simulation| {
        let g = s.gmap();
        g.embedding(g.require("spring_strain").unwrap())
            .real_column()
            .unwrap()
            .to_vec()
    };
    let (mut skipped, mut computed) = (0, 0);
    let mut opened = 0;
    for k in 0..200 {
        // the slab 1 < x < 2 stretched along y by up to 30% (0.15% a call), and the rest
        // of the box by a millionth a call: the ends move very little, the slab more and more
        let e = 0.0015 * f64::from(k);
        let x: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| {
                let t =
                    ((p[0] - 1.0).clamp(0.0, 1.0) * (2.0 - p[0]).clamp(0.0, 1.0) * 4.0).min(1.0);
                [p[0], p[1] * (1.0 + e * t + 1e-6 * f64::from(k)), p[2]]
            })
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
        let before = strains(&s);
        let n = s.fracture(fracture).unwrap().unsewn;
        if strains(&s) == before {
            skipped += 1;
        } else {
            computed += 1;
        }
        let mut fresh = new();
        fresh.set_vertex_vec3("position", &x).unwrap();
        let want = fresh.fracture(fracture).unwrap().unsewn;
        assert_eq!(
            n, want,
            "call {k}: {n} faces opened, a new simulation opens {want}"
        );
        if n > 0 {
            opened = n;
            break;
        }
    }
    assert!(opened > 0, "the slab never broke");
    assert!(
        skipped > 0 && computed > 1,
        "{skipped} calls skipped, {computed} computed"
    );
}

/// The skip's bound on how far vertices moved must not underflow: on a sheet scaled down to
/// 1e-170 (its squared moves would be 0), stretched by half after a first test that opened
/// nothing, the next test opens what a new simulation at the same state opens (found by
/// QA, 2026-12-05: it skipped and opened none).
#[test]
fn the_strain_skip_sees_moves_too_small_to_square() {
    let mesh = grid([4, 4], [1.0, 1.0], GridElement::Triangle);
    let fracture = Fracture {
        criterion: Criterion::Strain,
        threshold: 0.1,
    };
    let scale = 1e-170;
    let new = |stretch: f64| {
        let mut s = sim(
            &mesh,
            vec![model("stretch_cumulated", &[("stiffness", 1e4)])],
            |c| c.gravity = [0.0; 3],
        );
        let rest: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| p.map(|x| x * scale))
            .collect();
        s.set_vertex_vec3("rest", &rest).unwrap();
        let x: Vec<[f64; 3]> = rest.iter().map(|p| [p[0] * stretch, p[1], p[2]]).collect();
        s.set_vertex_vec3("position", &x).unwrap();
        (s, rest)
    };
    let (mut a, rest) = new(1.0);
    assert_eq!(a.fracture(fracture).unwrap().unsewn, 0);
    let x: Vec<[f64; 3]> = rest.iter().map(|p| [p[0] * 1.5, p[1], p[2]]).collect();
    a.set_vertex_vec3("position", &x).unwrap();
    let opened = a.fracture(fracture).unwrap().unsewn;
    let (mut b, _) = new(1.5);
    let want = b.fracture(fracture).unwrap().unsewn;
    assert!(want > 0, "the stretched sheet tears");
    assert_eq!(opened, want);
}

/// The stress criterion is computed per tetrahedron: asked of a simulation of hexahedra
/// (which loads the FEM rules), an interactive fracture is refused saying how many volumes
/// are not tetrahedra, as a configured one is when the simulation is built, instead of
/// opening nothing; the map is left as it was.
#[test]
fn a_stress_fracture_of_hexahedra_is_refused() {
    // hexahedra with co-rotational FEM; then wedges with springs (no FEM rules loaded):
    // refused for the wedges, not sent to declare the fracture at set-up (which refuses
    // them too)
    for (element, kind) in [
        (BoxElement::Hexa, "corotational"),
        (BoxElement::Wedge, "stretch_elementary"),
    ] {
        let n = if element == BoxElement::Hexa {
            [2, 1, 1]
        } else {
            [1, 1, 1]
        };
        let mesh = cuboid(n, [1.0, 0.5, 0.5], element);
        let mut s = sim(&mesh, vec![model(kind, &[])], |_| {});
        let darts = s.gmap().n_darts();
        let e = s
            .fracture(Fracture {
                criterion: Criterion::Stress,
                threshold: 1e3,
            })
            .unwrap_err();
        assert!(
            e.to_string()
                .contains("needs tetrahedra: 2 of the mesh's 2 volumes are not"),
            "{kind}: {e}"
        );
        assert_eq!(s.gmap().n_darts(), darts);
        assert!(s.topology_changes().is_empty());
    }
}
