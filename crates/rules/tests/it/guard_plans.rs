//! Compiled guards of topology rules: a rule that changes the topology finds its matches
//! through its guard compiled over every hook orbit (kept between applications, patched after
//! each change). These tests check it against the interpreter, which evaluates the guard dart
//! by dart: two copies of one map, one cut through compiled guards and one through the
//! interpreter, cut after cut (plane cuts at several offsets and normals, an asymmetric guard
//! that holds from one side of a face only, a guard with local variables, a blade's sweep
//! through a built-in, the positions moved between cuts), must stay the same map dart for dart, with the same positions bit for bit,
//! and valid; and the compiled path must really have run, patched after the first cut.

use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{Dart, GMap};
use topomech_rules::{load_sources, Params, Region, RuleSet, Val};

const RULES: &str = "dimension 3
embedding position : vec3 on <1,2,3> policy mean

rule cut_plane(normal: vec3, offset: f64) {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where (dot(mean<0,1,2>(a.position), normal) - offset) * (dot(mean<0,1,2>(b.position), normal) - offset) < 0.0
}

# holds from the side whose volume lies further along x only
rule cut_from_the_far_side(at: f64) {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where {
    let ca = mean<0,1,2>(a.position)
    let cb = mean<0,1,2>(b.position)
    x(ca) > x(cb) + 1e-9 && x(ca) > at && x(cb) < at
  }
}

# a blade's sweep (as topology3d.tmr's cut_swept): a built-in the plans call per row
rule cut_swept(a0: vec3, b0: vec3, a1: vec3, b1: vec3) {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where {
    let ca = mean<0,1,2>(a.position)
    let cb = mean<0,1,2>(b.position)
    segment_hits_triangle(ca, cb, a0, b0, b1) || segment_hits_triangle(ca, cb, a0, b1, a1)
  }
}

# a face (its own centroid) in a slab
rule cut_slab(lo: f64, hi: f64) {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where y(mean<0,1>(a.position)) > lo && y(mean<0,1>(a.position)) < hi
}
";

fn setup() -> (GMap, RuleSet, RuleSet) {
    let (g, _) = build(
        &cuboid([6, 4, 3], [3.0, 2.0, 1.5], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .unwrap();
    let (compiled, _) = load_sources(&[("guards.tmr".to_string(), RULES.to_string())]).unwrap();
    let mut interpreted = compiled.clone();
    interpreted.set_compiled(false);
    (g, compiled, interpreted)
}

/// The two maps are the same: the same live darts, links and positions (bit for bit).
fn same(a: &GMap, b: &GMap, what: &str) {
    assert_eq!(a.capacity(), b.capacity(), "{what}: dart capacity");
    let (pa, pb) = (
        a.embedding_id("position").unwrap(),
        b.embedding_id("position").unwrap(),
    );
    for k in 0..a.capacity() {
        let d = Dart(k as u32);
        assert_eq!(a.is_alive(d), b.is_alive(d), "{what}: dart {k} alive");
        if !a.is_alive(d) {
            continue;
        }
        for i in 0..=3 {
            assert_eq!(a.alpha(i, d), b.alpha(i, d), "{what}: alpha{i} of dart {k}");
        }
        let (x, y) = (a.real(pa, d), b.real(pb, d));
        assert!(
            x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits()),
            "{what}: position of dart {k}: {x:?} and {y:?}"
        );
    }
    assert!(a.validate().is_empty(), "{what}: the map is valid");
}

/// Moves every vertex a little (a different amount each call), the same on both maps.
fn shake(g: &mut GMap, t: f64) {
    let pos = g.embedding_id("position").unwrap();
    for d in g.orbit_representatives(topomech_gmap::OrbitType::vertex(3)) {
        let p = g.real(pos, d).to_vec();
        let q = [
            p[0] + 0.03 * (t + 2.0 * p[1]).sin(),
            p[1] + 0.02 * (t + 3.0 * p[2]).cos(),
            p[2] + 0.01 * (t * p[0]).sin(),
        ];
        g.set_real(pos, d, &q).unwrap();
    }
}

fn plane(normal: [f64; 3], offset: f64) -> Params {
    [
        ("normal".to_string(), Val::V3(normal)),
        ("offset".to_string(), Val::F(offset)),
    ]
    .into()
}

fn swept(a0: [f64; 3], b0: [f64; 3], a1: [f64; 3], b1: [f64; 3]) -> Params {
    [
        ("a0".to_string(), Val::V3(a0)),
        ("b0".to_string(), Val::V3(b0)),
        ("a1".to_string(), Val::V3(a1)),
        ("b1".to_string(), Val::V3(b1)),
    ]
    .into()
}

#[test]
fn cuts_through_compiled_guards_give_the_interpreters_map_cut_after_cut() {
    let (mut g, compiled, interpreted) = setup();
    let mut h = g.clone();
    let steps: Vec<(&str, Params)> = vec![
        ("cut_plane", plane([1.0, 0.0, 0.0], 1.4)),
        ("cut_plane", plane([0.3, 0.9, 0.1], 1.2)),
        (
            "cut_from_the_far_side",
            [("at".to_string(), Val::F(2.1))].into(),
        ),
        (
            "cut_slab",
            [
                ("lo".to_string(), Val::F(0.4)),
                ("hi".to_string(), Val::F(0.6)),
            ]
            .into(),
        ),
        (
            "cut_swept",
            swept(
                [2.3, 1.9, -0.1],
                [2.3, 1.9, 1.6],
                [2.3, 0.1, -0.1],
                [2.3, 0.1, 1.6],
            ),
        ),
        ("cut_plane", plane([0.0, 0.0, 1.0], 0.7)),
        (
            "cut_swept",
            swept(
                [0.2, 1.0, -0.1],
                [2.8, 1.0, -0.1],
                [0.2, 1.0, 1.6],
                [2.8, 1.0, 1.6],
            ),
        ),
        // nothing crosses this plane: no change, and the next cut runs the same plan
        ("cut_plane", plane([1.0, 0.0, 0.0], 10.0)),
        ("cut_plane", plane([0.0, 1.0, 0.0], 1.5)),
        ("cut_plane", plane([1.0, 0.0, 0.0], 1.4)),
    ];
    let mut total = 0;
    for (k, (rule, p)) in steps.iter().enumerate() {
        shake(&mut g, k as f64);
        shake(&mut h, k as f64);
        let a = compiled.apply_everywhere(&mut g, rule, p).unwrap();
        let b = interpreted.apply_everywhere(&mut h, rule, p).unwrap();
        let what = format!("application {k} ({rule})");
        if rule.starts_with("cut_swept") {
            assert!(a.matches > 0, "{what}: the blade crosses faces");
        }
        assert_eq!(a.matches, b.matches, "{what}: faces unsewn");
        total += a.matches;
        same(&g, &h, &what);
    }
    assert!(total > 50, "the cuts opened faces ({total})");
    let (runs, patches) = compiled.compiled_guard_runs();
    assert_eq!(
        runs,
        steps.len(),
        "every application ran its compiled guard"
    );
    // one plan per rule, built at its first application, patched at later ones that
    // followed a change (or rebuilt, which compacts it, once its index has grown past
    // twice the map: these cuts change much of a small map)
    assert!(patches >= 1, "plans patched: {patches}");
    assert_eq!(interpreted.compiled_guard_runs(), (0, 0));
}

#[test]
fn a_guard_the_plans_do_not_cover_is_left_to_the_interpreter() {
    // an integer embedding read by the guard: compiled plans do not read integer columns
    let rules = "dimension 3
embedding position : vec3 on <1,2,3> policy mean
embedding label : i64 on <0,1,2>
rule cut_labels {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where a.label != b.label
}
";
    let (mut g, _) = build(
        &cuboid([3, 2, 2], [3.0, 2.0, 2.0], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .unwrap();
    let (rs, _) = load_sources(&[("labels.tmr".to_string(), rules.to_string())]).unwrap();
    rs.prepare(&mut g).unwrap();
    let label = g.embedding_id("label").unwrap();
    // label each volume by the x of its first dart's vertex
    let pos = g.embedding_id("position").unwrap();
    for d in g.orbit_representatives(topomech_gmap::OrbitType::volume()) {
        let v = i64::from(g.real(pos, d)[0] > 1.5);
        g.set_value(label, d, &topomech_gmap::Value::Int(v))
            .unwrap();
    }
    let rep = rs
        .apply_everywhere(&mut g, "cut_labels", &Params::new())
        .unwrap();
    assert!(rep.matches > 0);
    assert_eq!(rs.compiled_guard_runs().0, 0, "the interpreter decided");
    assert!(g.validate().is_empty());
}

/// The box of a blade's sweep from the segment `a0 b0` to `a1 b1`.
fn sweep_box(p: &[[f64; 3]; 4]) -> Region {
    let mut lo = p[0];
    let mut hi = p[0];
    for q in &p[1..] {
        for k in 0..3 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    Region {
        embedding: "position".into(),
        lo,
        hi,
    }
}

/// A progressive cut: a blade moving a little per application, its compiled guard run only
/// near the quad it sweeps (`apply_everywhere_within`), gives the map the interpreter gives
/// trying every face, dart for dart, application after application: with the map moving
/// a little between them, and once a lot (more than a row's extent: the rows are indexed
/// again), with patched plans whose appended rows must be tried too.
#[test]
fn a_blade_tested_near_its_sweep_only_cuts_what_testing_every_face_cuts() {
    let (mut g, compiled, interpreted) = setup();
    let mut h = g.clone();
    // the guard built and its rows indexed beforehand (as a simulation does for the blades
    // it declares); a region of what is not a vec3 embedding is refused, naming it
    let zero = swept([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
    assert!(compiled
        .prepare_guard_within(&mut g, "cut_swept", &zero, "position")
        .unwrap());
    let e = compiled
        .prepare_guard_within(&mut g, "cut_swept", &zero, "nowhere")
        .unwrap_err()
        .to_string();
    assert!(e.contains("nowhere") && e.contains("vec3"), "{e}");
    let mut total = 0;
    let n = 12;
    for k in 0..n {
        let t = k as f64;
        // a large move once: every vertex shifted by 0.5 along y (the blade follows)
        let shift = if k == 6 { 0.5 } else { 0.0 };
        let offset = if k >= 6 { 0.5 } else { 0.0 };
        for m in [&mut g, &mut h] {
            shake(m, t);
            let pos = m.embedding_id("position").unwrap();
            for d in m.orbit_representatives(topomech_gmap::OrbitType::vertex(3)) {
                let mut p = m.real(pos, d).to_vec();
                p[1] += shift;
                m.set_real(pos, d, &p).unwrap();
            }
        }
        // the blade across x = 1.1, moving down in y by 0.2 per application
        let x = 1.1;
        let (y0, y1) = (2.1 - 0.2 * t + offset, 1.9 - 0.2 * t + offset);
        let q = [[x, y0, -0.1], [x, y0, 1.6], [x, y1, -0.1], [x, y1, 1.6]];
        let p = swept(q[0], q[1], q[2], q[3]);
        let a = compiled
            .apply_everywhere_within(&mut g, "cut_swept", &p, &sweep_box(&q))
            .unwrap();
        let b = interpreted
            .apply_everywhere(&mut h, "cut_swept", &p)
            .unwrap();
        let what = format!("sweep {k}");
        assert_eq!(a.matches, b.matches, "{what}: faces unsewn");
        total += a.matches;
        same(&g, &h, &what);
    }
    assert!(total > 10, "the sweeps opened faces ({total})");
    assert_eq!(
        compiled.culled_guard_runs(),
        n,
        "every sweep ran near its quad only"
    );
    // a region naming what is not a vec3 embedding is refused, naming it
    let q = [
        [1.0, 1.0, -0.1],
        [1.0, 1.0, 1.6],
        [1.0, 0.9, -0.1],
        [1.0, 0.9, 1.6],
    ];
    let mut r = sweep_box(&q);
    r.embedding = "no_such".into();
    let e = compiled
        .apply_everywhere_within(&mut g, "cut_swept", &swept(q[0], q[1], q[2], q[3]), &r)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no_such") && e.contains("vec3"), "{e}");
    // corners swapped or not finite: refused, not an empty search
    for (lo, hi) in [
        ([1.0, 1.0, 1.0], [0.0, 2.0, 2.0]),
        ([f64::NAN, 0.0, 0.0], [1.0; 3]),
    ] {
        let r = Region {
            embedding: "position".into(),
            lo,
            hi,
        };
        let e = compiled
            .apply_everywhere_within(&mut g, "cut_swept", &swept(q[0], q[1], q[2], q[3]), &r)
            .unwrap_err()
            .to_string();
        assert!(e.contains("lo <= hi"), "{e}");
    }
}
