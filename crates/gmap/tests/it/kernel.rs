//! The kernel's invariants under sew/unsew, embedding policies, derived embeddings,
//! validation reports, and the file format.

// Exact float equality is the point here: merges, splits and the file format must not
// change a single bit of these small sums of exactly representable numbers.
#![allow(clippy::float_cmp)]

use proptest::prelude::*;
use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::io::{from_bytes, to_bytes, FormatError};
use topomech_gmap::mesh::{build, BuildOptions, CellKind, Mesh};
use topomech_gmap::{
    Aggregate, Dart, EmbeddingError, EmbeddingType, GMap, OrbitType, Policy, SewError, Value,
    Violation,
};

fn o(s: &str) -> OrbitType {
    OrbitType::parse(s).unwrap()
}

/// Two separate triangles side by side, sharing (in space) the edge (1, 2).
fn two_triangles() -> GMap {
    let points = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ];
    let m = Mesh {
        points,
        kinds: vec![CellKind::Polygon; 2],
        cells: vec![vec![0, 1, 2], vec![1, 3, 2]],
    };
    let (g, _) = build(&m, &BuildOptions::default()).unwrap();
    g
}

#[test]
fn unsew_then_sew_restores_the_map_and_positions() {
    let mut g = two_triangles();
    let before = g.cell_counts();
    let pos = g.require("position").unwrap();
    // the shared edge: the dart of face 0 that is 2-linked
    let d = g.darts().find(|&d| !g.is_free(2, d)).unwrap();
    let partner = g.alpha(2, d);
    let v0 = g.version();
    g.unsew(2, d).unwrap();
    assert!(g.version() > v0, "unsew changes the version");
    assert!(g.is_valid());
    let c = g.cell_counts();
    assert_eq!(
        (c.vertices, c.edges, c.components, c.boundary),
        (6, 6, 2, 6)
    );
    // the split vertex orbits copied the position (policy mean splits by copying)
    assert_eq!(g.real(pos, d), g.real(pos, partner));
    // move one side, sew back: the merged vertex gets the mean
    let moved = [g.real(pos, d)[0] + 0.5, g.real(pos, d)[1], 0.0];
    let before_pos = g.real(pos, d).to_vec();
    g.set_real(pos, d, &moved).unwrap();
    g.sew(2, d, partner).unwrap();
    assert!(g.is_valid());
    assert_eq!(g.cell_counts(), before);
    assert_eq!(g.real(pos, d)[0], f64::midpoint(moved[0], before_pos[0]));
}

#[test]
fn sew_refuses_non_free_and_mismatched_orbits_and_changes_nothing() {
    let mut g = two_triangles();
    let d = g.darts().find(|&d| !g.is_free(2, d)).unwrap();
    let e = g.darts().find(|&x| g.is_free(2, x)).unwrap();
    let snapshot = to_bytes(&g);
    assert!(matches!(g.sew(2, d, e), Err(SewError::NotFree { .. })));
    assert!(matches!(g.sew(5, d, e), Err(SewError::Link(_))));
    assert!(matches!(g.unsew(2, e), Err(SewError::Link(_))));
    assert!(
        to_bytes(&g) == snapshot,
        "a refused operation leaves the map as it was"
    );
    // 1-sew needs 1-free darts: every dart of a closed polygon is 1-linked
    assert!(matches!(
        g.sew(1, e, g.alpha(0, e)),
        Err(SewError::NotFree { .. })
    ));
}

#[test]
fn error_policy_refuses_merges_of_different_values_and_splits() {
    let mut g = two_triangles();
    let id = g
        .add_embedding("tag", EmbeddingType::I64, o("<1,2>"), Policy::Error)
        .unwrap();
    let d = g.darts().find(|&d| !g.is_free(2, d)).unwrap();
    let partner = g.alpha(2, d);
    let snapshot = to_bytes(&g);
    let err = g.unsew(2, d).unwrap_err();
    assert!(
        matches!(&err, SewError::Embedding { embedding, what: "split", .. } if embedding == "tag"),
        "{err}"
    );
    assert!(to_bytes(&g) == snapshot);
    // with a copy policy it splits; then different values refuse to merge back
    let mut g = two_triangles();
    let id2 = g
        .add_embedding("tag", EmbeddingType::I64, o("<0>"), Policy::Error)
        .unwrap();
    let _ = id;
    g.unsew(2, d).unwrap(); // <0> orbits do not contain alpha2: nothing splits
    g.set_value(id2, d, &Value::Int(4)).unwrap();
    let g2 = g.clone();
    assert!(
        g.sew(2, d, partner).is_ok(),
        "<0> orbits do not merge along alpha2"
    );
    let mut g = g2;
    let v = g
        .add_embedding("vtag", EmbeddingType::I64, o("<1,2>"), Policy::Error)
        .unwrap();
    g.set_value(v, d, &Value::Int(1)).unwrap();
    let snap = to_bytes(&g);
    assert!(matches!(
        g.sew(2, d, partner),
        Err(SewError::Embedding {
            what: "merge with different values",
            ..
        })
    ));
    assert!(to_bytes(&g) == snap);
}

#[test]
fn sum_policy_keeps_totals_across_split_and_merge() {
    let mut g = two_triangles();
    let m = g
        .add_embedding("mass", EmbeddingType::F64, o("<1,2>"), Policy::Sum)
        .unwrap();
    for d in g.orbit_representatives(o("<1,2>")) {
        g.set_real(m, d, &[1.0]).unwrap();
    }
    let total = |g: &GMap| -> f64 {
        g.orbit_representatives(o("<1,2>"))
            .iter()
            .map(|&d| g.real(m, d)[0])
            .sum()
    };
    assert_eq!(total(&g), 4.0);
    let d = g.darts().find(|&d| !g.is_free(2, d)).unwrap();
    let p = g.alpha(2, d);
    g.unsew(2, d).unwrap();
    assert_eq!(total(&g), 4.0);
    assert_eq!(g.real(m, d), [0.5]);
    g.sew(2, d, p).unwrap();
    assert_eq!(total(&g), 4.0);
    assert_eq!(g.real(m, d), [1.0]);
}

#[test]
fn derived_embeddings_aggregate_and_go_stale() {
    let (mut g, _) = build(
        &grid([2, 1], [2.0, 1.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    let k = g
        .add_embedding("k", EmbeddingType::F64, o("<0>"), Policy::Copy)
        .unwrap();
    for d in g.orbit_representatives(o("<0>")) {
        g.set_real(k, d, &[2.0]).unwrap();
    }
    let cum = g
        .add_derived("k_edge", "k", o("<0,2>"), Aggregate::Sum)
        .unwrap();
    let cnt = g
        .add_derived("n_faces", "k", o("<0,2>"), Aggregate::Count)
        .unwrap();
    let inner = g.darts().find(|&d| !g.is_free(2, d)).unwrap();
    let outer = g.darts().find(|&d| g.is_free(2, d)).unwrap();
    assert_eq!(g.value(cum, inner).unwrap(), Value::Real(vec![4.0]));
    assert_eq!(g.value(cum, outer).unwrap(), Value::Real(vec![2.0]));
    assert_eq!(g.value(cnt, inner).unwrap(), Value::Int(2));
    g.set_real(k, inner, &[3.0]).unwrap();
    assert!(g.is_stale(cum));
    assert!(matches!(g.value(cum, inner), Err(EmbeddingError::Stale(_))));
    assert!(matches!(
        g.set_real(cum, inner, &[1.0]),
        Err(EmbeddingError::Derived(_))
    ));
    g.refresh_derived();
    assert_eq!(g.value(cum, inner).unwrap(), Value::Real(vec![5.0]));
    // a topology change splits the cumulated spring into the elementary ones
    g.unsew(2, inner).unwrap();
    assert!(g.is_stale(cum));
    g.refresh_derived();
    assert_eq!(g.value(cum, inner).unwrap(), Value::Real(vec![3.0]));
    assert_eq!(g.value(cnt, inner).unwrap(), Value::Int(1));
    assert!(g.is_valid());
    assert!(matches!(
        g.add_derived("bad", "k", o("<1>"), Aggregate::Sum),
        Err(EmbeddingError::NotSubOrbit { .. })
    ));
}

#[test]
fn embedding_declarations_are_checked() {
    let mut g = two_triangles();
    assert!(matches!(
        g.add_embedding("position", EmbeddingType::F64, o("<>"), Policy::Copy),
        Err(EmbeddingError::Duplicate(_))
    ));
    assert!(matches!(
        g.add_embedding("a b", EmbeddingType::F64, o("<>"), Policy::Copy),
        Err(EmbeddingError::BadName(_))
    ));
    assert!(matches!(
        g.add_embedding("x", EmbeddingType::F64, o("<2,3>"), Policy::Copy),
        Err(EmbeddingError::Dimension { .. })
    ));
    assert!(matches!(
        g.add_embedding("x", EmbeddingType::Bool, o("<>"), Policy::Mean),
        Err(EmbeddingError::Policy { .. })
    ));
    let id = g
        .add_embedding(
            "m",
            EmbeddingType::Mat { rows: 12, cols: 12 },
            o("<0,1>"),
            Policy::Copy,
        )
        .unwrap();
    let d = Dart(0);
    assert!(matches!(
        g.set_real(id, d, &[1.0; 3]),
        Err(EmbeddingError::Type { .. })
    ));
    g.set_real(id, d, &[1.5; 144]).unwrap();
    // every dart of the face sees it
    for x in g.orbit(d, o("<0,1>")) {
        assert_eq!(g.real(id, x), [1.5; 144]);
    }
    assert!(matches!(
        g.set_real(id, Dart(999), &[0.0; 144]),
        Err(EmbeddingError::NoSuchDart(_))
    ));
}

#[test]
fn validate_reports_each_violation_with_its_darts() {
    let mut g = GMap::new(2).unwrap();
    let a = g.add_darts(4);
    let (b, c, d) = (Dart(a.0 + 1), Dart(a.0 + 2), Dart(a.0 + 3));
    g.link(0, a, b).unwrap();
    g.link(0, c, d).unwrap();
    g.link(2, a, c).unwrap();
    // alpha0 alpha2 not an involution: b and d are not 2-linked
    let v = g.validate();
    assert!(
        v.iter()
            .any(|x| matches!(x, Violation::Cycle { i: 0, j: 2, .. })),
        "{v:?}"
    );
    assert!(v[0].to_string().contains("alpha0 o alpha2"));
    g.link(2, b, d).unwrap();
    assert!(g.is_valid());
    g.link(3, a, d).unwrap_err(); // dimension 3 is refused in a 2-map
                                  // an embedding made inconsistent by raw links
    let e = g
        .add_embedding("w", EmbeddingType::F64, o("<0>"), Policy::Copy)
        .unwrap();
    let _ = e;
    g.unlink(0, a).unwrap();
    let v = g.validate();
    assert!(
        v.iter().any(|x| matches!(x, Violation::SharedSlot { .. })),
        "{v:?}"
    );
    assert!(matches!(
        g.remove_dart(a),
        Err(topomech_gmap::LinkError::StillLinked { .. })
    ));
}

#[test]
fn removed_darts_are_reused_and_tables_stay_consistent() {
    let mut g = two_triangles();
    let f = g
        .add_embedding("f", EmbeddingType::F64, o("<0,1>"), Policy::Copy)
        .unwrap();
    let x = g.add_dart();
    let y = g.add_dart();
    g.sew(0, x, y).unwrap();
    g.set_real(f, x, &[7.0]).unwrap();
    assert_eq!(g.real(f, y), [7.0]);
    assert!(g.is_valid());
    g.unsew(0, x).unwrap();
    g.remove_dart(x).unwrap();
    g.remove_dart(y).unwrap();
    assert!(g.is_valid());
    let z = g.add_dart();
    assert!(z == x || z == y, "the free list is reused");
    assert_eq!(
        g.real(f, z),
        [0.0],
        "a reused dart starts with a zero value"
    );
    assert!(g.is_valid());
}

#[test]
fn file_round_trip_is_exact() {
    for mesh in [
        cuboid([2, 2, 2], [1.0, 1.0, 1.0], BoxElement::Mixed),
        grid([3, 3], [1.0, 1.0], GridElement::Mixed),
    ] {
        let (mut g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let w = g
            .add_embedding("w", EmbeddingType::F64, o("<0>"), Policy::Sum)
            .unwrap();
        g.add_embedding("flag", EmbeddingType::Bool, o("<>"), Policy::Copy)
            .unwrap();
        g.add_embedding("id", EmbeddingType::I64, o("<0,1>"), Policy::Error)
            .unwrap();
        g.add_derived("w_sum", "w", o("<0,1>"), Aggregate::Sum)
            .unwrap();
        g.set_real(w, Dart(3), &[0.1 + 0.2]).unwrap();
        let d = g.darts().find(|&d| !g.is_free(2, d)).unwrap();
        g.unsew(2, d).unwrap(); // free slots and split orbits survive the round trip too
        g.refresh_derived(); // derived values are recomputed on load
        let b = to_bytes(&g);
        let h = from_bytes(&b).unwrap();
        assert!(
            to_bytes(&h) == b,
            "save(load(save(g))) differs from save(g)"
        );
        // a map read back holds no more than the map written (its columns were read into
        // vectors of their size, not grown by doubling)
        assert!(
            h.memory_bytes() <= g.memory_bytes(),
            "{} bytes read back, {} written",
            h.memory_bytes(),
            g.memory_bytes()
        );
        assert_eq!(h.cell_counts(), g.cell_counts());
        assert!(h.is_valid());
        assert_eq!(h.real(w, Dart(3)), [0.1 + 0.2]);
        assert!(!h.is_stale(h.require("w_sum").unwrap()));
    }
}

#[test]
fn truncated_and_corrupt_files_are_errors_not_panics() {
    let (g, _) = build(
        &grid([2, 1], [1.0, 1.0], GridElement::Triangle),
        &BuildOptions::default(),
    )
    .unwrap();
    let b = to_bytes(&g);
    for n in 0..b.len() {
        assert!(from_bytes(&b[..n]).is_err(), "prefix of {n} bytes accepted");
    }
    assert!(matches!(from_bytes(b"hello"), Err(FormatError::Magic)));
    let mut v = b.clone();
    v[14] = 9;
    assert!(matches!(from_bytes(&v), Err(FormatError::Version(9, 1))));
    let mut extra = b.clone();
    extra.push(0);
    assert!(matches!(
        from_bytes(&extra),
        Err(FormatError::Corrupt { .. })
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Flipping arbitrary bytes of a valid file never panics the reader.
    #[test]
    fn mutated_files_never_panic(flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8)) {
        let (g, _) = build(&grid([2, 2], [1.0, 1.0], GridElement::Mixed), &BuildOptions::default()).unwrap();
        let mut b = to_bytes(&g);
        for (i, x) in flips {
            let k = i.index(b.len());
            b[k] = x;
        }
        if let Ok(h) = from_bytes(&b) {
            // a loaded map may be invalid, but checking it must not panic either
            let _ = h.validate();
            let _ = h.cell_counts();
        }
    }

    /// Random sequences of sew and unsew on a 2D and a 3D map keep every invariant, keep
    /// the total of a `sum` embedding, and round-trip through the file format.
    #[test]
    fn random_sew_unsew_keeps_the_map_valid(
        three in any::<bool>(),
        ops in prop::collection::vec((0usize..4, any::<prop::sample::Index>(), any::<prop::sample::Index>()), 1..40),
    ) {
        let mesh = if three {
            cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Mixed)
        } else {
            grid([2, 2], [1.0, 1.0], GridElement::Mixed)
        };
        let (mut g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let n = g.dimension();
        let mass = g.add_embedding("mass", EmbeddingType::F64, OrbitType::vertex(n), Policy::Sum).unwrap();
        g.add_embedding("face_id", EmbeddingType::I64, o("<0,1>"), Policy::Copy).unwrap();
        g.add_embedding("edge_k", EmbeddingType::Vec2, OrbitType::edge(n), Policy::Mean).unwrap();
        for d in g.orbit_representatives(OrbitType::vertex(n)) {
            g.set_real(mass, d, &[1.0]).unwrap();
        }
        let total = |g: &GMap| -> f64 {
            g.orbit_representatives(OrbitType::vertex(n)).iter().map(|&d| g.real(mass, d)[0]).sum()
        };
        let t0 = total(&g);
        let darts: Vec<Dart> = g.darts().collect();
        for (kind, a, b) in ops {
            let i = if n == 3 { 2 + kind % 2 } else { 2 };
            let (x, y) = (darts[a.index(darts.len())], darts[b.index(darts.len())]);
            let before = to_bytes(&g);
            let r = if kind < 2 { g.unsew(i, x) } else { g.sew(i, x, y) };
            if r.is_err() {
                prop_assert!(to_bytes(&g) == before, "a refused operation changed the map");
            }
            let v = g.validate();
            prop_assert!(v.is_empty(), "{:?}", v);
            prop_assert!((total(&g) - t0).abs() < 1e-9);
        }
        let b = to_bytes(&g);
        prop_assert!(to_bytes(&from_bytes(&b).unwrap()) == b);
    }
}

/// `rewire` with the links of an unsew gives the same map as `unsew`: same counts, same
/// values on every dart, totals of `sum` embeddings kept; a batch that would break an
/// involution is refused and changes nothing.
#[test]
fn rewire_matches_unsew_and_refuses_bad_batches() {
    let (mut a, _) = build(
        &grid([2, 2], [1.0, 1.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    let m = a
        .add_embedding("m", EmbeddingType::F64, o("<1,2>"), Policy::Sum)
        .unwrap();
    for d in a.orbit_representatives(o("<1,2>")) {
        a.set_real(m, d, &[1.0]).unwrap();
    }
    let mut b = a.clone();
    let d = a.darts().find(|&d| !a.is_free(2, d)).unwrap();
    let e = a.alpha(0, d);
    let (pd, pe) = (a.alpha(2, d), a.alpha(2, e));
    a.unsew(2, d).unwrap();
    let snapshot = to_bytes(&b);
    assert!(matches!(
        b.rewire(&[(2, d, d)], &[], &[]),
        Err(topomech_gmap::RewireError::NotInvolution { .. })
    ));
    assert!(to_bytes(&b) == snapshot, "a refused batch changes nothing");
    b.rewire(&[(2, d, d), (2, pd, pd), (2, e, e), (2, pe, pe)], &[], &[])
        .unwrap();
    assert!(b.validate().is_empty(), "{:?}", b.validate());
    assert_eq!(a.cell_counts(), b.cell_counts());
    let pos = a.require("position").unwrap();
    for x in a.darts() {
        assert_eq!(a.real(pos, x), b.real(pos, x));
        assert_eq!(a.real(m, x), b.real(m, x));
    }
    // new darts: two fresh darts linked by alpha0 get one zero <0,1> value, and removing them
    // again restores the counts
    let before = b.cell_counts();
    let f = b.add_darts(2);
    let g2 = Dart(f.0 + 1);
    b.rewire(&[(0, f, g2), (0, g2, f)], &[f, g2], &[]).unwrap();
    assert!(b.is_valid());
    b.rewire(&[(0, f, f), (0, g2, g2)], &[], &[f, g2]).unwrap();
    assert!(b.is_valid());
    assert_eq!(b.cell_counts(), before);
}
