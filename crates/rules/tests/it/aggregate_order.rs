//! An aggregate (`sum<o>(n.emb)`, `mean<o>(n.emb)`) adds the distinct orbits' values in one
//! fixed order (by storage slot), so its value is a function of the `<o>` orbit: the same bits
//! from each of its darts, in the interpreter and in compiled plans (which walk each orbit
//! once and copy its slot list to the orbit's other rows). Before, each dart summed in the
//! order of an orbit walk from itself, and the twelve half-edges of a tetrahedron could
//! disagree on its centroid in the last bit.

// compared bit for bit on purpose: the property is exact equality
#![allow(clippy::float_cmp)]

use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{GMap, Value};
use topomech_rules::{load_sources, Params};

const RULES: &str = "dimension 3
embedding position : vec3 on <1,2,3> policy mean
embedding centroid : vec3 on <>
embedding face_sum : vec3 on <>
embedding n_corner : f64 on <>

rule per_half_edge {
  left { a : <> hook   b : <>   a -0- b }
  compute {
    a.centroid = mean<0,1,2>(a.position)
    a.face_sum = sum<0,1>(a.position) + sum<0,1>(b.position)
    a.n_corner = to_f64(count<0,1,2>(a.position))
  }
}
";

/// A 2 x 2 x 2 box of tetrahedra whose vertices are moved by irrational amounts, so that the
/// order of a sum shows in its last bits.
fn mesh() -> GMap {
    let (mut g, _) = build(
        &cuboid([2, 2, 2], [1.0, 1.0, 1.0], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .unwrap();
    let pos = g.embedding_id("position").unwrap();
    // once per vertex (the position is one value per vertex orbit)
    for d in g.orbit_representatives(topomech_gmap::OrbitType::vertex(3)) {
        let p = g.real(pos, d).to_vec();
        let q: Vec<f64> = p
            .iter()
            .enumerate()
            .map(|(k, x)| x * (1.0 + 0.1 * (k as f64 + 1.0).sqrt()) + 1e-3 * (7.0 * x).sin() + 1e8)
            .collect();
        g.set_value(pos, d, &Value::Real(q)).unwrap();
    }
    g
}

#[test]
fn an_aggregate_has_the_same_bits_from_every_dart_of_its_orbit() {
    for compiled in [true, false] {
        let mut g = mesh();
        let (mut rules, _) = load_sources(&[("agg.tmr".to_string(), RULES.to_string())]).unwrap();
        rules.set_compiled(compiled);
        let rep = rules
            .apply_everywhere(&mut g, "per_half_edge", &Params::new())
            .unwrap();
        assert!(rep.matches > 0);
        let c = g.embedding_id("centroid").unwrap();
        let s = g.embedding_id("face_sum").unwrap();
        let n = g.embedding_id("n_corner").unwrap();
        let volume = topomech_gmap::OrbitType::volume();
        let mut checked = 0;
        for d in g.darts() {
            // every written dart (the hook of a match) against the first written dart of its
            // volume: one centroid, bit for bit
            if g.real(n, d)[0] == 0.0 {
                continue;
            }
            assert_eq!(g.real(n, d)[0], 4.0, "a tetrahedron has 4 vertices");
            let first = g
                .orbit(d, volume)
                .into_iter()
                .filter(|&x| g.real(n, x)[0] != 0.0)
                .min()
                .unwrap();
            assert_eq!(
                g.real(c, d),
                g.real(c, first),
                "compiled {compiled}, dart {d}"
            );
            checked += 1;
        }
        assert!(
            checked >= 12 * 48,
            "every half-edge of the 48 tets: {checked}"
        );
        // a face's sum seen from its two ends of an edge: the same face, the same bits
        for d in g.darts() {
            let e = g.alpha(0, d);
            if g.real(n, d)[0] != 0.0 && g.real(n, e)[0] != 0.0 {
                assert_eq!(g.real(s, d), g.real(s, e), "compiled {compiled}, dart {d}");
            }
        }
    }
}
