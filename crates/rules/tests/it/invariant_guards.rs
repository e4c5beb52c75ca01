//! Topology rules whose guard fails: the hook orbit is tried once when the guard provably has
//! one value on every row of a match (it reads each node only through embeddings on orbits
//! that contain the node's orbit), and dart by dart otherwise. These tests check that the
//! shortcut finds exactly the matches the dart-by-dart search finds: a plane cut unsews the
//! faces a brute-force count over the volumes says it must; a guard that holds from one side
//! of a face only (asymmetric) still unsews every such face, although the failed side's darts
//! belong to the other side's match; a guard that differs between the darts of one hook
//! orbit (not invariant) still finds the match from the one dart where it holds.

use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{Dart, GMap, OrbitType};
use topomech_rules::{load_sources, Params, RuleSet, Val};

const RULES: &str = "dimension 3
embedding position : vec3 on <1,2,3> policy mean
embedding tag      : bool on <>

rule cut_plane(normal: vec3, offset: f64) {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where (dot(mean<0,1,2>(a.position), normal) - offset) * (dot(mean<0,1,2>(b.position), normal) - offset) < 0.0
}

# holds from the side whose volume lies further along x only
rule cut_from_the_far_side {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where x(mean<0,1,2>(a.position)) > x(mean<0,1,2>(b.position)) + 1e-9
}

# reads a dart embedding: its value differs between the darts of the hook orbit
rule cut_tagged {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where a.tag
}
";

fn setup() -> (GMap, RuleSet) {
    let (g, _) = build(
        &cuboid([3, 2, 2], [3.0, 2.0, 2.0], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .unwrap();
    let (rules, _) = load_sources(&[("guards.tmr".to_string(), RULES.to_string())]).unwrap();
    (g, rules)
}

/// The interior faces (alpha3-sewn), one dart each, with the centroids of the two volumes.
fn interior_faces(g: &GMap) -> Vec<(Dart, [f64; 3], [f64; 3])> {
    let pos = g.embedding_id("position").unwrap();
    let centroid = |d: Dart| {
        let darts = g.orbit(d, OrbitType::volume());
        let mut c = [0.0; 3];
        let mut n = 0.0;
        let mut seen = Vec::new();
        for x in darts {
            let s = g.embedding(pos).slot(x);
            if !seen.contains(&s) {
                seen.push(s);
                let p = g.real(pos, x);
                for k in 0..3 {
                    c[k] += p[k];
                }
                n += 1.0;
            }
        }
        c.map(|v| v / n)
    };
    let mut seen = topomech_gmap::Marks::with_capacity(g.capacity());
    let mut out = Vec::new();
    for d in g.darts() {
        if seen.is_marked(d) || g.alpha(3, d) == d {
            continue;
        }
        for x in g.orbit(d, OrbitType::parse("<0,1>").unwrap()) {
            seen.mark(x);
            seen.mark(g.alpha(3, x));
        }
        out.push((d, centroid(d), centroid(g.alpha(3, d))));
    }
    out
}

fn sewn_faces(g: &GMap) -> usize {
    interior_faces(g).len()
}

#[test]
fn a_plane_cut_unsews_the_faces_a_brute_force_count_gives() {
    for (normal, offset) in [
        ([1.0, 0.0, 0.0], 1.4),
        ([0.3, 0.9, 0.1], 1.2),
        ([0.0, 0.0, 1.0], 0.9),
    ] {
        let (mut g, rules) = setup();
        let faces = interior_faces(&g);
        let side = |c: [f64; 3]| c[0] * normal[0] + c[1] * normal[1] + c[2] * normal[2] - offset;
        let want = faces
            .iter()
            .filter(|(_, a, b)| side(*a) * side(*b) < 0.0)
            .count();
        assert!(
            want > 0,
            "the plane {normal:?} . x = {offset} crosses the box"
        );
        let params: Params = [
            ("normal".to_string(), Val::V3(normal)),
            ("offset".to_string(), Val::F(offset)),
        ]
        .into();
        let rep = rules
            .apply_everywhere(&mut g, "cut_plane", &params)
            .unwrap();
        assert_eq!(rep.matches, want, "normal {normal:?}");
        assert_eq!(sewn_faces(&g), faces.len() - want);
        assert!(g.validate().is_empty());
    }
}

#[test]
fn an_asymmetric_guard_unsews_every_face_from_the_side_where_it_holds() {
    let (mut g, rules) = setup();
    let faces = interior_faces(&g);
    // every interior face whose two volumes differ along x holds from exactly one side
    let want = faces
        .iter()
        .filter(|(_, a, b)| (a[0] - b[0]).abs() > 1e-9)
        .count();
    assert!(want > 0 && want < faces.len());
    let rep = rules
        .apply_everywhere(&mut g, "cut_from_the_far_side", &Params::new())
        .unwrap();
    assert_eq!(rep.matches, want);
    assert_eq!(sewn_faces(&g), faces.len() - want);
    assert!(g.validate().is_empty());
}

#[test]
fn a_guard_that_differs_on_the_hook_orbit_is_tried_from_every_dart() {
    let (mut g, rules) = setup();
    rules.prepare_named(&mut g, &["tag"]).unwrap();
    let tag = g.embedding_id("tag").unwrap();
    let faces = interior_faces(&g);
    // one dart of each of two interior faces, the last dart of its face orbit in dart order
    // (the search meets the others first, and they fail)
    let mut tagged = Vec::new();
    for (d, _, _) in [faces[0], faces[faces.len() / 2]] {
        let last = g
            .orbit(d, OrbitType::parse("<0,1>").unwrap())
            .into_iter()
            .max()
            .unwrap();
        g.set_value(tag, last, &topomech_gmap::Value::Bool(true))
            .unwrap();
        tagged.push(last);
    }
    let rep = rules
        .apply_everywhere(&mut g, "cut_tagged", &Params::new())
        .unwrap();
    assert_eq!(rep.matches, 2);
    for d in tagged {
        assert_eq!(g.alpha(3, d), d, "the tagged face {d:?} is unsewn");
    }
    assert_eq!(sewn_faces(&g), faces.len() - 2);
}
