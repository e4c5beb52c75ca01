//! Computation rules with the same left graph share their matches: the second one planned on
//! a map state reuses the matches the first one found (a model's init and step rules, the
//! spring strains and the cumulated springs). The results must be those of rules planned
//! alone; a rule with a guard, or with another hook, has its own; a topology change, or
//! `clear_shared_matches`, drops what was kept.

// b = 2 a is exact in floating point (a doubling): compared bit for bit on purpose
#![allow(clippy::float_cmp)]

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{GMap, Value};
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
# the same left graph and guard as edge_len_g: its matches
rule edge_len_g2 {
  left { p : <2> hook   q : <2>   p -0- q }
  where x(p.position) < 1.0
  compute { p.len_h = 3.0 * norm(q.position - p.position) }
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
        2,
        "a guarded rule keeps its own matches (shared with rules of the same guard only)"
    );
    rules.apply_everywhere(&mut g, "edge_len_h", &none).unwrap();
    assert_eq!(
        rules.shared_patterns(),
        3,
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

const VERTEX_RULES: &str = "dimension 2
embedding position : vec3 on <1,2> policy mean
embedding held     : bool on <1,2>
embedding a_plain  : f64 on <1,2>
embedding a_held   : f64 on <1,2>
embedding a_dart   : f64 on <1,2>
embedding mark     : bool on <>
embedding m        : mat3 on <1,2>
embedding a_inv    : f64 on <1,2>

rule hold_left {
  left { v : <1,2> hook }
  compute { v.held = x(v.position) < 0.5 }
}
rule vertex_plain {
  left { v : <1,2> hook }
  compute { v.a_plain = 1.0 + x(v.position) }
}
# a row-invariant guard on a one-node pattern: the plain matches, filtered
rule vertex_free {
  left { v : <1,2> hook }
  where !v.held && y(v.position) > 0.5
  compute { v.a_held = 1.0 + x(v.position) }
}
# a guard whose first conjunct fails to evaluate (m is zero: singular) where the second is
# false: skipped there, as the search does; an error where the second holds
rule vertex_inverse {
  left { v : <1,2> hook }
  where det(inverse(v.m)) > 0.0 && v.held
  compute { v.a_inv = 1.0 }
}
# a guard reading a parameter: the matches depend on its value
rule vertex_beyond(t: f64) {
  left { v : <1,2> hook }
  where x(v.position) > t
  compute { v.a_inv = 2.0 }
}
# a guard that reads a dart embedding: not row-invariant, its own matches
rule vertex_marked {
  left { v : <1,2> hook }
  where v.mark
  compute { v.a_dart = 1.0 + x(v.position) }
}
";

/// The vertex rules' map: a 3 x 2 quad grid with `mark` set on a few darts (not whole
/// vertices), so that the dart-level guard of `vertex_marked` depends on the hook dart.
fn vertex_setup() -> (GMap, RuleSet) {
    let (mut g, _) = build(
        &grid([3, 2], [3.0, 2.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    let (rules, _) = load_sources(&[("vertex.tmr".to_string(), VERTEX_RULES.to_string())]).unwrap();
    rules.prepare_named(&mut g, &["mark"]).unwrap();
    let mark = g.embedding_id("mark").unwrap();
    let darts: Vec<_> = g.darts().collect();
    for d in darts.iter().step_by(3) {
        g.set_value(mark, *d, &Value::Bool(true)).unwrap();
    }
    (g, rules)
}

/// `emb` at every dart, in dart order (0 where a rule wrote nothing).
fn vertex_values(g: &GMap, emb: &str) -> Vec<f64> {
    let id = g.embedding_id(emb).unwrap();
    g.darts().map(|d| g.real(id, d)[0]).collect()
}

#[test]
fn a_one_node_rule_with_a_row_invariant_guard_filters_the_shared_matches() {
    // Checks that the integrators' kind of rule (one node, a guard with one value on its
    // whole orbit) takes the plain matches of its left graph instead of a search of its own,
    // and that this changes nothing: the same matches and values (bit for bit: the same
    // arithmetic on the same rows) as the rule planned alone on a fresh map, compiled or
    // interpreted; a guard that reads a dart embedding keeps its own search.
    let none = Params::new();
    let run = |shared: bool, compiled: bool| {
        let (mut g, mut rules) = vertex_setup();
        rules.set_compiled(compiled);
        rules.apply_everywhere(&mut g, "hold_left", &none).unwrap();
        rules.clear_shared_matches();
        if shared {
            let plain = rules
                .apply_everywhere(&mut g, "vertex_plain", &none)
                .unwrap();
            assert_eq!(plain.matches, 12, "a 3 x 2 grid has 12 vertices");
            assert_eq!(rules.shared_patterns(), 1);
        }
        let free = rules
            .apply_everywhere(&mut g, "vertex_free", &none)
            .unwrap();
        let marked = rules
            .apply_everywhere(&mut g, "vertex_marked", &none)
            .unwrap();
        if compiled {
            assert_eq!(
                rules.shared_patterns(),
                2,
                "vertex_free adds no pattern of its own; vertex_marked keeps its own search"
            );
        }
        (
            free.matches,
            marked.matches,
            vertex_values(&g, "a_held"),
            vertex_values(&g, "a_dart"),
        )
    };
    let reference = run(false, false);
    // x >= 0.5 and y > 0.5: the vertices at x in {1, 2, 3} and y in {1, 2}
    assert_eq!(reference.0, 6);
    assert!(reference.1 > 0);
    for (shared, compiled) in [(true, true), (true, false), (false, true)] {
        assert_eq!(
            run(shared, compiled),
            reference,
            "shared {shared}, compiled {compiled}"
        );
    }
}

#[test]
fn rules_of_one_pattern_and_one_guard_share_their_matches_while_what_the_guard_reads_stays() {
    // Checks that a second rule with the left graph and guard of a first takes its matches
    // (no new pattern kept), and that a write to an embedding the guard reads makes the
    // next one search again: its matches are then those of a rule planned alone on the
    // changed map.
    let none = Params::new();
    let (mut g, rules) = setup();
    let first = rules.apply_everywhere(&mut g, "edge_len_g", &none).unwrap();
    let patterns = rules.shared_patterns();
    let second = rules
        .apply_everywhere(&mut g, "edge_len_g2", &none)
        .unwrap();
    assert_eq!(
        rules.shared_patterns(),
        patterns,
        "the same matches, shared"
    );
    assert_eq!(first.matches, second.matches);
    // move every vertex left by 1: more edge ends pass x < 1
    let pos = g.embedding_id("position").unwrap();
    for d in g.orbit_representatives(topomech_gmap::OrbitType::vertex(2)) {
        let p = g.real(pos, d).to_vec();
        g.set_value(pos, d, &Value::Real(vec![p[0] - 1.0, p[1], p[2]]))
            .unwrap();
    }
    let moved = rules
        .apply_everywhere(&mut g, "edge_len_g2", &none)
        .unwrap();
    assert!(
        moved.matches > second.matches,
        "the guard saw the new positions"
    );
    // the same map, a fresh rule set: the rule planned alone
    let (_, fresh) = setup();
    let alone = fresh
        .apply_everywhere(&mut g, "edge_len_g2", &none)
        .unwrap();
    assert_eq!(moved.matches, alone.matches);
}

#[test]
fn a_guard_that_fails_to_evaluate_is_skipped_or_reported_alike_with_shared_matches() {
    // Checks that the filtered shared matches decide as the search itself (`find_matches`,
    // the global search with the guard) does: a match one of whose leading conjuncts is
    // false is skipped even where another conjunct fails to evaluate (here `inverse` of a
    // singular matrix), and the failure is reported where no conjunct is false.
    let none = Params::new();
    let (mut g, rules) = vertex_setup();
    // no vertex held: `v.held` is false everywhere, nothing is reported
    assert!(rules
        .find_matches(&mut g, "vertex_inverse", &none)
        .unwrap()
        .is_empty());
    rules
        .apply_everywhere(&mut g, "vertex_plain", &none)
        .unwrap();
    let rep = rules
        .apply_everywhere(&mut g, "vertex_inverse", &none)
        .unwrap();
    assert_eq!(rep.matches, 0);
    // some held: the singular matrix is reported by both, naming the rule
    rules.apply_everywhere(&mut g, "hold_left", &none).unwrap();
    rules
        .apply_everywhere(&mut g, "vertex_plain", &none)
        .unwrap();
    let singular = |e: &topomech_rules::ApplyError| {
        matches!(e, topomech_rules::ApplyError::Eval { rule, message, .. }
            if rule == "vertex_inverse" && message.contains("singular"))
    };
    let searched = rules
        .find_matches(&mut g, "vertex_inverse", &none)
        .unwrap_err();
    assert!(singular(&searched), "{searched}");
    let filtered = rules
        .apply_everywhere(&mut g, "vertex_inverse", &none)
        .unwrap_err();
    assert!(singular(&filtered), "{filtered}");
}

#[test]
fn a_rule_applied_again_with_another_parameter_of_its_guard_takes_its_new_matches() {
    // Checks that a plan (and the shared matches under it) is not reused when a parameter
    // the guard reads changed: each application matches what the search with that value
    // finds (found by QA: the plan kept the first value's matches).
    let (mut g, rules) = vertex_setup();
    for t in [0.5, 1.5, -1.0, 2.5, 0.5] {
        let p: Params = [("t".to_string(), topomech_rules::Val::F(t))].into();
        let want = rules
            .find_matches(&mut g, "vertex_beyond", &p)
            .unwrap()
            .len();
        // x in {0, 1, 2, 3} on 3 rows of vertices
        assert_eq!(
            want,
            3 * (0..4).filter(|&x| f64::from(x) > t).count(),
            "t = {t}"
        );
        let got = rules.apply_everywhere(&mut g, "vertex_beyond", &p).unwrap();
        assert_eq!(got.matches, want, "t = {t}");
    }
}

/// `apply_once` (a simulation's set-up rules) writes what `apply_everywhere` writes, bit for
/// bit, and keeps no plan: the next application of the rule builds one again, where
/// `apply_everywhere`'s kept plan is reused. A kept plan would hold its rows, and their
/// index by dart, for a rule that never runs again.
#[test]
fn a_rule_applied_once_writes_the_same_values_and_keeps_no_plan() {
    let none = Params::new();
    for (rule, emb) in [("edge_len_a", "len_a"), ("edge_len_g", "len_g")] {
        let (mut g, rules) = setup();
        let once = rules.apply_once(&mut g, rule, &none).unwrap();
        assert!(once.matches > 0, "{rule}");
        assert_eq!(values(&g, emb), alone(rule, emb), "{rule}");
        assert!(
            rules.plan_kinds().iter().all(|(r, _)| r != rule),
            "{rule}: no plan kept after apply_once: {:?}",
            rules.plan_kinds()
        );
        assert_eq!(rules.plan_bytes(), 0, "{rule}");
        let built = rules.plans_built();
        rules.apply_everywhere(&mut g, rule, &none).unwrap();
        assert_eq!(rules.plans_built(), built + 1, "{rule}: planned again");
        assert!(rules.plan_kinds().iter().any(|(r, _)| r == rule), "{rule}");
        rules.apply_everywhere(&mut g, rule, &none).unwrap();
        assert_eq!(
            rules.plans_built(),
            built + 1,
            "{rule}: the kept plan reused"
        );
        assert_eq!(values(&g, emb), alone(rule, emb), "{rule}");
    }
}
