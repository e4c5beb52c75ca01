//! `GMap::set_orbit_values`: one value per orbit, orbits by smallest dart; checked against the
//! per-dart reader `GMap::value` (every dart of an orbit sees its orbit's value), refusals
//! that leave the map unchanged, and derived embeddings refreshed by the write.

// Exact float equality is the point: a write stores the given bits.
#![allow(clippy::float_cmp)]

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{
    Aggregate, ColumnRef, EmbeddingError, EmbeddingType, GMap, OrbitType, Policy, Value,
};

fn o(s: &str) -> OrbitType {
    OrbitType::parse(s).unwrap()
}

fn quads() -> GMap {
    let m = grid([4, 3], [4.0, 3.0], GridElement::Quad);
    build(&m, &BuildOptions::default()).unwrap().0
}

#[test]
fn every_dart_of_row_k_sees_value_k() {
    let mut g = quads();
    for (name, ty, orbit) in [
        ("w", EmbeddingType::Vec2, "<0,1>"),
        ("n", EmbeddingType::I64, "<0>"),
        ("b", EmbeddingType::Bool, "<>"),
        ("m", EmbeddingType::Mat { rows: 2, cols: 3 }, "<1,2>"),
    ] {
        let id = g.add_embedding(name, ty, o(orbit), Policy::Copy).unwrap();
        let reps = g.orbit_representatives(o(orbit));
        let n = reps.len();
        let w = ty.width();
        let reals: Vec<f64> = (0..n * w).map(|k| k as f64 + 0.25).collect();
        let ints: Vec<i64> = (0..n as i64).map(|k| 3 * k - 7).collect();
        let bools: Vec<bool> = (0..n).map(|k| k % 3 == 1).collect();
        let col = match ty {
            EmbeddingType::I64 => ColumnRef::Int(&ints),
            EmbeddingType::Bool => ColumnRef::Bool(&bools),
            _ => ColumnRef::Real(&reals),
        };
        g.set_orbit_values(id, col).unwrap();
        for (k, &r) in reps.iter().enumerate() {
            let want = match ty {
                EmbeddingType::I64 => Value::Int(ints[k]),
                EmbeddingType::Bool => Value::Bool(bools[k]),
                _ => Value::Real(reals[k * w..(k + 1) * w].to_vec()),
            };
            for d in g.orbit(r, o(orbit)) {
                assert_eq!(
                    g.value(id, d).unwrap(),
                    want,
                    "{name}: dart {} of row {k}",
                    d.0
                );
            }
        }
    }
    assert!(g.is_valid());
}

#[test]
fn refusals_write_nothing() {
    let mut g = quads();
    let id = g.require("position").unwrap();
    let n = g.count_orbits(o("<1,2>"));
    let before = g.clone();
    let short = vec![1.0; 3 * n - 3];
    let e = g.set_orbit_values(id, ColumnRef::Real(&short)).unwrap_err();
    assert!(
        matches!(&e, EmbeddingError::Type { name, got, .. } if name == "position" && got == &format!("{} reals", 3 * n - 3)),
        "{e}"
    );
    let ints = vec![0i64; n];
    assert!(g.set_orbit_values(id, ColumnRef::Int(&ints)).is_err());
    for d in g.darts() {
        assert_eq!(g.value(id, d), before.value(id, d));
    }
}

#[test]
fn derived_is_refused_and_refreshed() {
    let mut g = quads();
    let src = g
        .add_embedding("corner", EmbeddingType::F64, o("<1>"), Policy::Copy)
        .unwrap();
    let der = g
        .add_derived("total", "corner", o("<1,2>"), Aggregate::Sum)
        .unwrap();
    let n = g.count_orbits(o("<1>"));
    let ones = vec![1.0; n];
    g.set_orbit_values(src, ColumnRef::Real(&ones)).unwrap();
    assert!(!g.is_stale(der), "the write refreshed the derived sum");
    // each vertex of a quad grid gets one corner per adjacent quad
    for r in g.orbit_representatives(o("<1,2>")) {
        let corners = g.orbit(r, o("<1,2>")).len() / 2;
        assert_eq!(g.value(der, r).unwrap(), Value::Real(vec![corners as f64]));
    }
    let m = g.count_orbits(o("<1,2>"));
    let e = g
        .set_orbit_values(der, ColumnRef::Real(&vec![0.0; m]))
        .unwrap_err();
    assert_eq!(e, EmbeddingError::Derived("total".into()));
}
