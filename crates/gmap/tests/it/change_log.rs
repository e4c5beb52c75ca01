//! The change log ([`GMap::changed_since`]): after unsewing faces, every dart
//! whose links or embedding slots changed is listed, and every dart not listed kept its links
//! and its slot in every embedding (what a plan patched after a topology change relies on).

use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{Dart, GMap, OrbitType};

fn snapshot(g: &GMap) -> Vec<(Dart, [Dart; 4], Vec<usize>)> {
    g.darts()
        .map(|d| {
            let links = [0, 1, 2, 3].map(|i| g.alpha(i, d));
            let slots = g.embeddings().iter().map(|e| e.slot(d)).collect();
            (d, links, slots)
        })
        .collect()
}

fn check(g: &GMap, before: &[(Dart, [Dart; 4], Vec<usize>)], changed: &[Dart]) {
    let mut listed = vec![false; g.capacity()];
    for d in changed {
        listed[d.index()] = true;
    }
    for (d, links, slots) in before {
        if listed[d.index()] {
            continue;
        }
        assert!(g.is_alive(*d), "{d} removed but not listed");
        assert_eq!(&[0, 1, 2, 3].map(|i| g.alpha(i, *d)), links, "{d}: links");
        let now: Vec<usize> = g.embeddings().iter().map(|e| e.slot(*d)).collect();
        assert_eq!(&now, slots, "{d}: slots");
    }
    for d in g.darts() {
        assert!(
            d.index() < before.len() && before.iter().any(|b| b.0 == d) || listed[d.index()],
            "{d} created but not listed"
        );
    }
}

/// A box of 3 x 2 x 2 cells of tetrahedra.
fn small_box() -> GMap {
    build(
        &cuboid([3, 2, 2], [3.0, 2.0, 2.0], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .unwrap()
    .0
}

/// One dart of each of the first `n` faces between two volumes.
fn interior_faces(g: &GMap, n: usize) -> Vec<Dart> {
    g.orbit_representatives(OrbitType::parse("<0,1>").unwrap())
        .into_iter()
        .filter(|&d| !g.is_free(3, d))
        .take(n)
        .collect()
}

#[test]
fn unsewn_faces_and_their_orbits_are_listed_and_nothing_else_changed() {
    let mut g = small_box();
    assert!(g.changed_since(g.version()).is_none(), "not tracked yet");
    g.track_changes();
    let v0 = g.version();
    assert_eq!(g.changed_since(v0), Some(vec![]));
    assert!(g.changed_since(v0 + 1).is_none(), "a future version");
    let before = snapshot(&g);
    // unsew a few interior faces
    let faces = interior_faces(&g, 3);
    assert_eq!(faces.len(), 3);
    for d in faces {
        if !g.is_free(3, d) {
            g.unsew(3, d).unwrap();
        }
    }
    assert!(g.is_valid());
    let changed = g.changed_since(v0).unwrap();
    assert!(!changed.is_empty());
    check(&g, &before, &changed);
    // later changes only: since the version after the first ones, one more face
    let v1 = g.version();
    let before1 = snapshot(&g);
    let d = g.darts().find(|&d| !g.is_free(3, d)).unwrap();
    let e = g.alpha(3, d);
    g.unsew(3, d).unwrap();
    let since1 = g.changed_since(v1).unwrap();
    assert!(since1.contains(&d) && since1.contains(&e));
    assert!(
        !changed.iter().all(|x| since1.contains(x)),
        "earlier changes left out"
    );
    check(&g, &before1, &since1);
    // and since the start, both
    let all = g.changed_since(v0).unwrap();
    assert!(changed.iter().chain(&since1).all(|x| all.contains(x)));
    check(&g, &before, &all);
    // `changes_since` is both lists from one pass over the record, at every version
    for v in [v0, v1, g.version()] {
        let (c, r) = g.changes_since(v).unwrap();
        assert_eq!(Some(&c), g.changed_since(v).as_ref(), "changed since {v}");
        assert_eq!(Some(&r), g.relinked_since(v).as_ref(), "relinked since {v}");
        assert!(r.iter().all(|x| c.contains(x)));
    }
    assert!(
        g.changes_since(g.version() + 1).is_none(),
        "a future version"
    );
    // a clone has its own identity but keeps the record
    let c = g.clone();
    assert_eq!(c.changed_since(v0).unwrap(), all);
}

/// A derived embedding refreshed after a change recomputes only the orbits around the
/// changed darts: it then equals one computed from scratch on the new map, for sums, means
/// and counts, after every change of a sequence.
#[test]
fn a_local_refresh_of_derived_embeddings_equals_a_full_one() {
    use topomech_gmap::{Aggregate, EmbeddingType, Policy, Value};
    let mut g = small_box();
    let dim = g.dimension();
    // a value per <2>-orbit (a pair of darts in a volume), aggregated per vertex and edge
    let src_orbit = OrbitType::parse("<2>").unwrap();
    let src = g
        .add_embedding("w", EmbeddingType::F64, src_orbit, Policy::Sum)
        .unwrap();
    for (k, d) in g.orbit_representatives(src_orbit).into_iter().enumerate() {
        g.set_value(src, d, &Value::Real(vec![1.0 + k as f64 * 0.37]))
            .unwrap();
    }
    let aggs = [Aggregate::Sum, Aggregate::Mean, Aggregate::Count];
    let orbits = [OrbitType::vertex(dim), OrbitType::edge(dim)];
    let mut names = Vec::new();
    for (i, agg) in aggs.into_iter().enumerate() {
        for (j, o) in orbits.into_iter().enumerate() {
            let name = format!("d{i}{j}");
            g.add_derived(&name, "w", o, agg).unwrap();
            names.push((name, o, agg));
        }
    }
    g.track_changes();
    // unsewing volumes (alpha3: vertices and edges split), unsewing inside a volume (alpha2:
    // the source's <2>-orbits split too, and its sum policy halves the value of the slot a
    // part keeps, though that part's darts keep their slot), and unsewing volumes by a batch
    // rewrite (`GMap::rewire`, as rules do)
    for round in 0..6 {
        let dim_cut = if round == 3 || round == 4 { 2 } else { 3 };
        let d = g
            .darts()
            .filter(|&d| !g.is_free(dim_cut, d))
            .nth(7 * round)
            .unwrap();
        if round == 5 {
            let face = g.orbit(d, g.sew_orbit(3));
            let changes: Vec<(usize, Dart, Dart)> = face
                .iter()
                .flat_map(|&x| [(3, x, x), (3, g.alpha(3, x), g.alpha(3, x))])
                .collect();
            g.rewire(&changes, &[], &[]).unwrap();
        } else {
            g.unsew(dim_cut, d).unwrap();
        }
        g.refresh_derived(); // local
        let mut fresh = g.clone();
        for (name, o, agg) in &names {
            let full = format!("{name}_full");
            let f = fresh.add_derived(&full, "w", *o, *agg).unwrap(); // from scratch
            let l = fresh.require(name).unwrap();
            for x in fresh.darts() {
                assert_eq!(
                    fresh.value(l, x).unwrap(),
                    fresh.value(f, x).unwrap(),
                    "round {round}: {name} at {x}"
                );
            }
        }
    }
}

/// A new embedding on an orbit type that another embedding already has shares its
/// dart-to-slot table (copy on write, `GMap::build_embedding`) and counts it once in
/// `memory_bytes`; after faces were unsewn (vertices split, slots allocated) and a volume's
/// darts were removed (slots freed), the map is valid, every live dart holds the same slot in
/// every embedding of the orbit type, a new one declared then is zero everywhere, and writing
/// it leaves the others alone; a map written and read back shares its equal tables again.
#[test]
fn an_embedding_added_on_an_existing_orbit_type_shares_its_slots_and_stays_valid() {
    use topomech_gmap::io::{from_bytes, to_bytes};
    use topomech_gmap::{EmbeddingType, Policy, Value};
    let mut g = small_box();
    let vertex = OrbitType::vertex(g.dimension());
    let pos = g.require("position").unwrap();
    let first = g
        .add_embedding("first", EmbeddingType::Vec3, vertex, Policy::Mean)
        .unwrap();
    assert!(g.embedding(first).shares_slot_table(g.embedding(pos)));
    // a third vertex embedding costs its values and use counts, not another table
    let before = g.memory_bytes();
    let third = g
        .add_embedding("third", EmbeddingType::F64, vertex, Policy::Sum)
        .unwrap();
    let grew = g.memory_bytes() - before;
    assert!(
        grew < g.embedding(third).memory_bytes() - g.embedding(third).slot_table_bytes() + 64,
        "grew by {grew}: the shared table was counted again"
    );
    for (k, d) in g.orbit_representatives(vertex).into_iter().enumerate() {
        g.set_value(first, d, &Value::Real(vec![k as f64, 1.0, 2.0]))
            .unwrap();
    }
    // split vertices: unsew a few interior faces
    for _ in 0..4 {
        let d = g.darts().find(|&d| !g.is_free(3, d)).unwrap();
        g.unsew(3, d).unwrap();
    }
    assert!(g.is_valid(), "{:?}", g.validate());
    let same = |g: &GMap, a, b| {
        g.darts()
            .all(|d| g.embedding(a).slot(d) == g.embedding(b).slot(d))
    };
    assert!(same(&g, first, pos) && same(&g, third, pos));
    // free slots: detach one tetrahedron (each of its darts then is a vertex orbit of its
    // own, with its own slot) and remove its darts, which frees those slots
    let vol = OrbitType::parse("<0,1,2>").unwrap();
    let d0 = g.orbit_representatives(vol)[0];
    let darts = g.orbit(d0, vol);
    for &d in &darts {
        for i in 0..4 {
            if !g.is_free(i, d) {
                g.unsew(i, d).unwrap();
            }
        }
    }
    for &d in &darts {
        g.remove_dart(d).unwrap();
    }
    assert!(g.is_valid(), "{:?}", g.validate());
    let second = g
        .add_embedding("second", EmbeddingType::F64, vertex, Policy::Copy)
        .unwrap();
    assert!(g.is_valid(), "{:?}", g.validate());
    assert!(same(&g, second, first) && same(&g, first, pos));
    assert_eq!(g.embedding(second).n_slots(), g.embedding(first).n_slots());
    for d in g.darts() {
        assert_eq!(g.real(second, d), &[0.0]);
    }
    let snapshot: Vec<f64> = g.embedding(first).real_column().unwrap().to_vec();
    for d in g.orbit_representatives(vertex) {
        g.set_value(second, d, &Value::Real(vec![5.0])).unwrap();
    }
    assert_eq!(g.embedding(first).real_column().unwrap(), &snapshot[..]);
    assert!(g.is_valid());
    // written and read back: the equal tables are one again
    let h = from_bytes(&to_bytes(&g)).unwrap();
    let (p2, f2, s2) = (
        h.require("position").unwrap(),
        h.require("first").unwrap(),
        h.require("second").unwrap(),
    );
    assert!(h.embedding(f2).shares_slot_table(h.embedding(p2)));
    assert!(h.embedding(s2).shares_slot_table(h.embedding(p2)));
    assert!(h.is_valid());
    assert!(h.memory_bytes() < g.memory_bytes());
}

/// Re-slotting after a batch rewrite (`GMap::rewire`, what every rule that changes the
/// topology goes through) keeps a table shared: embeddings of one orbit type that shared their
/// dart-to-slot table before the rewrite still share one after it (made once, not copied per
/// embedding), and every embedding ends exactly as on a copy of the map whose embeddings each
/// hold their own table (unshared by adding and removing a dart): the same slot per dart, the
/// same values, the same slot bookkeeping (checked through a second rewrite and new slots).
#[test]
fn a_rewrite_keeps_shared_slot_tables_shared_and_gives_the_unshared_result() {
    use topomech_gmap::{EmbeddingType, Policy, Value};
    let (mut g, _) = build(
        &cuboid([4, 3, 3], [4.0, 3.0, 3.0], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .unwrap();
    let vertex = OrbitType::vertex(g.dimension());
    let pos = g.require("position").unwrap();
    let sum = g
        .add_embedding("sum", EmbeddingType::F64, vertex, Policy::Sum)
        .unwrap();
    let mean = g
        .add_embedding("mean", EmbeddingType::Vec3, vertex, Policy::Mean)
        .unwrap();
    for (k, d) in g.orbit_representatives(vertex).into_iter().enumerate() {
        g.set_value(sum, d, &Value::Real(vec![1.0 + k as f64]))
            .unwrap();
        g.set_value(mean, d, &Value::Real(vec![k as f64, 0.5, -1.0]))
            .unwrap();
    }
    assert!(g.embedding(sum).shares_slot_table(g.embedding(pos)));
    // the reference: the same map with one table per embedding
    let mut h = g.clone();
    let extra = h.add_darts(1);
    h.remove_dart(extra).unwrap();
    assert!(!h.embedding(sum).shares_slot_table(h.embedding(pos)));
    // unsew alpha3 along the faces of a few interior darts: vertices split
    let unsew = |g: &GMap, count: usize| {
        let mut changes = Vec::new();
        let mut seen = std::collections::HashSet::new();
        for d in g.darts().filter(|&d| !g.is_free(3, d)).step_by(37) {
            if seen.len() >= count * 6 {
                break;
            }
            for x in g.orbit(d, OrbitType::parse("<0,1>").unwrap()) {
                for y in [x, g.alpha(3, x)] {
                    if seen.insert(y) {
                        changes.push((3, y, y));
                    }
                }
            }
        }
        changes
    };
    // a batch that sets links to what they are already changes nothing, not even the version
    let v = g.identity();
    let same: Vec<_> = g.darts().take(50).map(|d| (0, d, g.alpha(0, d))).collect();
    g.rewire(&same, &[], &[]).unwrap();
    assert_eq!(g.identity(), v, "no link changed");
    for round in 0..2 {
        let changes = unsew(&g, 5 + 10 * round);
        assert_eq!(
            changes,
            unsew(&h, 5 + 10 * round),
            "the same map, the same batch"
        );
        g.rewire(&changes, &[], &[]).unwrap();
        h.rewire(&changes, &[], &[]).unwrap();
        assert!(g.is_valid(), "{:?}", g.validate());
        assert!(h.is_valid(), "{:?}", h.validate());
        for id in [sum, mean] {
            assert!(
                g.embedding(id).shares_slot_table(g.embedding(pos)),
                "round {round}: the table stays shared"
            );
            assert_eq!(g.embedding(id).n_slots(), h.embedding(id).n_slots());
        }
        for d in g.darts() {
            for id in [pos, sum, mean] {
                assert_eq!(g.embedding(id).slot(d), h.embedding(id).slot(d), "dart {d}");
                assert_eq!(g.real(id, d), h.real(id, d), "dart {d}");
            }
        }
    }
    // one table for the three, not three
    assert!(g.memory_bytes() + 2 * 4 * g.capacity() <= h.memory_bytes() + 64);
    // the bookkeeping agrees too: writing one embedding leaves the others alone
    let d = g.darts().next().unwrap();
    g.set_value(sum, d, &Value::Real(vec![42.0])).unwrap();
    assert_eq!(g.real(sum, d), &[42.0]);
    assert_eq!(g.real(mean, d), h.real(mean, d));
    assert!(g.is_valid());
}

/// A map's identity, change record and changed darts at one state.
type State = ((u64, u64), (u64, u64), Vec<Dart>);

/// `change_record` (what a cache of `changes_since` keys on, with the map's identity) moves
/// with every change recorded and only then: reads leave it, and at every state it takes
/// again, `changes_since` gives again what it gave.
#[test]
fn the_change_record_moves_with_every_recorded_change() {
    let mut g = small_box();
    assert_eq!(g.change_record(), None, "not tracked yet");
    g.track_changes();
    let v0 = g.version();
    assert_eq!(g.change_record(), Some((v0, 0)));
    let faces = interior_faces(&g, 3);
    let mut seen: Vec<State> = Vec::new();
    for &f in &faces {
        let before = g.change_record().unwrap();
        let changes = g.changes_since(v0).unwrap();
        assert_eq!(g.change_record(), Some(before), "a read records nothing");
        assert_eq!(
            g.changes_since(v0).unwrap(),
            changes,
            "same state, same answer"
        );
        seen.push((g.identity(), before, changes.0));
        g.unsew(3, f).unwrap();
        let after = g.change_record().unwrap();
        assert_eq!(after.0, before.0, "the record covers the same versions");
        assert!(
            after.1 > before.1,
            "an unsewing adds entries: {before:?} -> {after:?}"
        );
    }
    // every state seen had its own key and its own answer
    for (k, a) in seen.iter().enumerate() {
        for b in &seen[k + 1..] {
            assert_ne!((a.0, a.1), (b.0, b.1));
            assert_ne!(a.2, b.2);
        }
    }
}
