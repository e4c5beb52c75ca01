//! Computation rules with the same left graph share their matches: the second one planned on
//! a map state reuses the matches the first one found (a model's init and step rules, the
//! spring strains and the cumulated springs). The results must be those of rules planned
//! alone; a rule with a guard, or with another hook, has its own; a topology change, or
//! `clear_shared_matches`, drops what was kept.

// b = 2 a is exact in floating point (a doubling): compared bit for bit on purpose
#![allow(clippy::float_cmp)]

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::GMap;
use topomech_rules::{load_sources, Params, RuleSet};

const RULES: &str = "dimension 2
embedding position : vec3 on <1,2> policy mean
embedding len_a    : f64 on <0,2>
embedding len_b    : f64 on <0,2>
embedding len_g    : f64 on <0,2>
embedding len_h    : f64 on <0,2>

# the same left graph twice (other node names): one set of matches
rule edge_len_a {
  left { a : <2> hook   b : <2>   a -0- b }
  compute { a.len_a = norm(b.position - a.position) }
}
rule edge_len_b {
  left { p : <2> hook   q : <2>   p -0- q }
  compute { p.len_b = 2.0 * norm(q.position - p.position) }
}
# a guard: its own matches
rule edge_len_g {
  left { a : <2> hook   b : <2>   a -0- b }
  where x(a.position) < 1.0
  compute { a.len_g = norm(b.position - a.position) }
}
# the hook on a half-edge: another pattern
rule edge_len_h {
  left { a : <> hook   b : <>   a -0- b }
  compute { a.len_h = norm(b.position - a.position) }
}
rule unsew_edge {
  left  { a : <0> hook   b : <0>   a -2- b }
  right { a : <0>        b : <0> }
  where x(mean<0,1>(a.position)) < 1.0 && x(mean<0,1>(b.position)) > 1.0
}
";

fn setup() -> (GMap, RuleSet) {
    let (g, _) = build(
        &grid([3, 2], [3.0, 2.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    let (rules, _) = load_sources(&[("shared.tmr".to_string(), RULES.to_string())]).unwrap();
    (g, rules)
}

/// `emb` on every edge (by its representative dart's value), in dart order.
fn values(g: &GMap, emb: &str) -> Vec<f64> {
    let id = g.embedding_id(emb).unwrap();
    g.darts().map(|d| g.real(id, d)[0]).collect()
}

/// The rules applied one at a time on fresh maps, each planned alone.
fn alone(rule: &str, emb: &str) -> Vec<f64> {
    let (mut g, rules) = setup();
    rules
        .apply_everywhere(&mut g, rule, &Params::new())
        .unwrap();
    values(&g, emb)
}

#[test]
fn rules_of_one_pattern_share_their_matches_and_their_results_hold() {
    let (mut g, rules) = setup();
    let none = Params::new();
    let a = rules.apply_everywhere(&mut g, "edge_len_a", &none).unwrap();
    assert_eq!(rules.shared_patterns(), 1);
    let b = rules.apply_everywhere(&mut g, "edge_len_b", &none).unwrap();
    assert_eq!(
        rules.shared_patterns(),
        1,
        "the second rule reused the first one's matches"
    );
    assert_eq!(a.matches, b.matches);
    rules.apply_everywhere(&mut g, "edge_len_g", &none).unwrap();
    assert_eq!(
        rules.shared_patterns(),
        1,
        "a guarded rule keeps its own matches"
    );
    rules.apply_everywhere(&mut g, "edge_len_h", &none).unwrap();
    assert_eq!(
        rules.shared_patterns(),
        2,
        "another hook is another pattern"
    );
    for (rule, emb) in [
        ("edge_len_a", "len_a"),
        ("edge_len_b", "len_b"),
        ("edge_len_g", "len_g"),
        ("edge_len_h", "len_h"),
    ] {
        assert_eq!(values(&g, emb), alone(rule, emb), "{rule}");
    }
    // b is twice a, edge by edge (the same matches, another program)
    for (x, y) in values(&g, "len_a").iter().zip(values(&g, "len_b")) {
        assert_eq!(2.0 * x, y);
    }
    rules.clear_shared_matches();
    assert_eq!(rules.shared_patterns(), 0);
}

#[test]
fn a_topology_change_drops_the_shared_matches() {
    let (mut g, rules) = setup();
    let none = Params::new();
    rules.apply_everywhere(&mut g, "edge_len_a", &none).unwrap();
    let before = rules
        .apply_everywhere(&mut g, "edge_len_b", &none)
        .unwrap()
        .matches;
    let cut = rules
        .apply_everywhere(&mut g, "unsew_edge", &none)
        .unwrap()
        .matches;
    assert!(cut > 0);
    // the edges along the cut are now two each: more matches, found again on the new map
    let after_a = rules
        .apply_everywhere(&mut g, "edge_len_a", &none)
        .unwrap()
        .matches;
    let after_b = rules
        .apply_everywhere(&mut g, "edge_len_b", &none)
        .unwrap()
        .matches;
    assert_eq!(after_a, after_b);
    assert_eq!(after_a, before + cut);
    assert_eq!(rules.shared_patterns(), 1);
    for (x, y) in values(&g, "len_a").iter().zip(values(&g, "len_b")) {
        assert_eq!(2.0 * x, y);
    }
}
