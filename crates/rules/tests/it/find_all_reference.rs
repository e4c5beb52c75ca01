//! The matches a computation rule's global application finds, against a reference search
//! written here from the definition: the darts tried in increasing order, a dart skipped when
//! a kept match's hook orbit holds it, a match kept unless its footprint (the set of its
//! darts) is one kept before. The engine skips more darts than that (every dart of a hook
//! orbit whose footprint is a duplicate: a spring's second end, a pattern's mirror image);
//! this checks that it keeps exactly the same matches, in the same order, with the same
//! darts per node, on patterns whose mirror images repeat footprints.

use std::collections::HashSet;

use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_gmap::{Dart, GMap};
use topomech_rules::engine::match_at;
use topomech_rules::{load_sources, Params};

const RULES_3D: &str = "dimension 3
embedding position : vec3 on <1,2,3> policy mean
embedding s : f64 on <2,3>
embedding h : f64 on <>
# a spring per edge end: the other end's hook orbit gives the same footprint
rule edge_ends {
  left { a : <2,3> hook   b : <2,3>   a -0- b }
  compute { a.s = norm(b.position - a.position) }
}
# a half-edge pair: each half-edge's partner gives the same footprint
rule half_edges {
  left { a : <> hook   b : <>   a -0- b }
  compute { a.h = norm(b.position - a.position) }
}
# a face's two sides through alpha3: mirror images of one another
rule face_sides {
  left { a : <0,1> hook   b : <0,1>   a -3- b }
  compute { a.h = norm(b.position - a.position) }
}
";

const RULES_2D: &str = "dimension 2
embedding position : vec3 on <1,2> policy mean
embedding s : f64 on <2>
rule edge_ends {
  left { a : <2> hook   b : <2>   a -0- b }
  compute { a.s = norm(b.position - a.position) }
}
";

/// The reference search (see the module comment): per match kept, its darts per node.
fn reference(g: &GMap, rule: &topomech_rules::check::Rule, hook: usize) -> Vec<Vec<Vec<Dart>>> {
    reference_flagged(g, rule, hook, &[])
}

fn check(mesh: &Mesh, source: &str, names: &[&str]) {
    let (mut g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let (rules, _) = load_sources(&[("reference.tmr".to_string(), source.to_string())]).unwrap();
    for name in names {
        let rule = rules.rule(name).unwrap();
        let hook = rule.hooks[0];
        let want = reference(&g, rule, hook);
        assert_engine_finds(&mut g, &rules, name, &want);
    }
}

/// The engine's global matches of rule `name` are `want` (not empty), in order, node for node.
fn assert_engine_finds(
    g: &mut GMap,
    rules: &topomech_rules::RuleSet,
    name: &str,
    want: &[Vec<Vec<Dart>>],
) {
    let got: Vec<Vec<Vec<Dart>>> = rules
        .find_matches(g, name, &Params::new())
        .unwrap()
        .into_iter()
        .map(|m| m.darts.to_vecs())
        .collect();
    assert!(!want.is_empty(), "{name}: the pattern matches somewhere");
    assert_eq!(got.len(), want.len(), "{name}: as many matches");
    assert!(
        got == want,
        "{name}: the same matches, in order, node for node"
    );
}

#[test]
fn global_matches_are_those_of_the_reference_search_on_a_tet_box() {
    check(
        &cuboid([3, 2, 2], [3.0, 2.0, 2.0], BoxElement::Tetra),
        RULES_3D,
        &["edge_ends", "half_edges", "face_sides"],
    );
}

#[test]
fn global_matches_are_those_of_the_reference_search_on_a_mixed_box() {
    check(
        &cuboid([2, 2, 1], [2.0, 2.0, 1.0], BoxElement::Mixed),
        RULES_3D,
        &["edge_ends", "half_edges", "face_sides"],
    );
}

#[test]
fn global_matches_are_those_of_the_reference_search_on_a_mixed_grid() {
    check(
        &grid([4, 3], [1.0, 0.75], GridElement::Mixed),
        RULES_2D,
        &["edge_ends"],
    );
}

const RULES_FLAGS: &str = "dimension 3
embedding position : vec3 on <1,2,3> policy mean
embedding mark     : bool on <>
embedding held     : bool on <1,2,3>
embedding s : f64 on <2,3>
embedding h : f64 on <>
embedding v : f64 on <1,2,3>
# a dart flag on the hook: tried dart by dart (not row-invariant)
rule marked_ends {
  left { a : <2,3> hook   b : <2,3>   a -0- b }
  where a.mark
  compute { a.s = norm(b.position - a.position) }
}
# a negated flag and a second flag
rule unmarked_half_edges {
  left { a : <> hook   b : <>   a -0- b }
  where !a.mark && !a.held
  compute { a.h = norm(b.position - a.position) }
}
# a vertex flag on a one-node pattern (the integrators' `where !v.fixed`)
rule free_vertices {
  left { v : <1,2,3> hook }
  where !v.held
  compute { v.v = norm(v.position) }
}
";

/// The reference search of a rule whose guard is `flags` on the hook dart (each an
/// embedding and the value it must have, read with `GMap::value`): a dart whose flags fail
/// is skipped without marking anything, as the definition says (the guard is evaluated at
/// each match's hook dart, row 0).
fn reference_flagged(
    g: &GMap,
    rule: &topomech_rules::check::Rule,
    hook: usize,
    flags: &[(&str, bool)],
) -> Vec<Vec<Vec<Dart>>> {
    let mut used: HashSet<Dart> = HashSet::new();
    let mut prints: HashSet<Vec<Dart>> = HashSet::new();
    let mut out = Vec::new();
    for d in g.darts() {
        if used.contains(&d) {
            continue;
        }
        let pass = flags.iter().all(|(name, want)| {
            let id = g.embedding_id(name).unwrap();
            g.value(id, d).unwrap() == topomech_gmap::Value::Bool(*want)
        });
        if !pass {
            continue;
        }
        let Ok(m) = match_at(g, rule, &[d]) else {
            continue;
        };
        let mut key: Vec<Dart> = m.darts.iter().flatten().copied().collect();
        key.sort_unstable();
        if !prints.insert(key) {
            continue;
        }
        used.extend(m.darts[hook].iter().copied());
        out.push(m.darts.to_vecs());
    }
    out
}

#[test]
fn guards_testing_flags_find_the_matches_of_the_reference_search() {
    // Checks the engine's fast test of flag conjuncts (read from their column, not through
    // the interpreter) against the definition, with the flags set on scattered darts and
    // vertices so that some hook orbits pass at some darts only.
    let (mut g, _) = build(
        &cuboid([3, 2, 2], [3.0, 2.0, 2.0], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .unwrap();
    let (rules, _) = load_sources(&[("flags.tmr".to_string(), RULES_FLAGS.to_string())]).unwrap();
    rules.prepare_named(&mut g, &["mark", "held"]).unwrap();
    let (mark, held) = (
        g.embedding_id("mark").unwrap(),
        g.embedding_id("held").unwrap(),
    );
    let darts: Vec<Dart> = g.darts().collect();
    for (k, &d) in darts.iter().enumerate() {
        if k % 7 == 0 || k % 11 == 3 {
            g.set_value(mark, d, &topomech_gmap::Value::Bool(true))
                .unwrap();
        }
        if k % 97 == 5 {
            g.set_value(held, d, &topomech_gmap::Value::Bool(true))
                .unwrap();
        }
    }
    for (name, flags) in [
        ("marked_ends", &[("mark", true)][..]),
        (
            "unmarked_half_edges",
            &[("mark", false), ("held", false)][..],
        ),
        ("free_vertices", &[("held", false)][..]),
    ] {
        let rule = rules.rule(name).unwrap();
        let want = reference_flagged(&g, rule, rule.hooks[0], flags);
        assert_engine_finds(&mut g, &rules, name, &want);
    }
}
