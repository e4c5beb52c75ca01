//! A write `n.e = value` applied everywhere writes `e` on every orbit of `e` the match's rows
//! reach, also where the value is the same on every row. The rows along which a value is
//! constant share one evaluation, but they are one orbit of `e` only along labels of `e`'s
//! orbit type: a face's corners (`<1>`) are four orbits, each written. Compiled plans (native
//! code and the plan evaluator) wrote only one row of each class, so a constant written from a
//! face reached one corner of four (found by a QA pass: a user model's corner stiffness was
//! set on a quarter of the corners, and its forces were wrong). The reference is the rule
//! applied at each dart in turn, which the interpreter writes row by row. And two hooks whose
//! orbits differ in size are refused for that, not as a pattern folding onto itself.

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{Dart, GMap};
use topomech_rules::{load_sources, Params, RuleSet};

const SOURCE: &str = "dimension 2
embedding position : vec3 on <1,2>
embedding corner_c : f64 on <1>
embedding dart_e   : f64 on <>
embedding dart_l   : f64 on <>
embedding edge_k   : i64 on <0>
embedding face_b   : bool on <0,1>

rule corners { left { f : <0,1> hook } compute { f.corner_c = 1.5 } }
rule half_edges { left { a : <0> hook } compute { a.dart_e = 2.0 } }
rule boundary { left { a : <0> hook } where true compute { a.dart_l = y(mean<0>(a.position)) + 1.0 } }
rule edge_ints { left { f : <0,1> hook } compute { f.edge_k = 7 } }
rule faces { left { f : <0,1> hook } compute { f.face_b = true } }
";

fn sheet(rules: &RuleSet) -> GMap {
    let (mut g, _) = build(
        &grid([5, 4], [1.0, 0.8], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    rules.prepare(&mut g).unwrap();
    g
}

/// Every dart's value of `emb` as bits (reals) or integers.
fn column(g: &GMap, emb: &str) -> Vec<String> {
    let id = g.require(emb).unwrap();
    g.darts()
        .map(|d| format!("{:?}", g.value(id, d).unwrap()))
        .collect()
}

#[test]
fn a_value_constant_on_the_rows_is_written_on_every_orbit_they_reach() {
    let (mut rules, _) = load_sources(&[("w.tmr".to_string(), SOURCE.to_string())]).unwrap();
    let none = Params::new();
    for (rule, emb) in [
        ("corners", "corner_c"),
        ("half_edges", "dart_e"),
        ("boundary", "dart_l"),
        ("edge_ints", "edge_k"),
        ("faces", "face_b"),
    ] {
        // the reference: the interpreter, at each dart in turn
        let mut want = sheet(&rules);
        rules.set_compiled(false);
        let darts: Vec<Dart> = want.darts().collect();
        for d in darts {
            rules.apply_at(&mut want, rule, &[d], &none).unwrap();
        }
        let want = column(&want, emb);
        // nothing is left at its initial zero (false)
        let unset = column(&sheet(&rules), emb);
        assert!(
            want.iter().zip(&unset).all(|(w, u)| w != u),
            "{rule}: the reference writes every dart"
        );
        for (compiled, jit) in [(false, false), (true, false), (true, true)] {
            rules.set_compiled(compiled);
            rules.set_jit(jit);
            let mut g = sheet(&rules);
            rules.apply_everywhere(&mut g, rule, &none).unwrap();
            assert_eq!(
                column(&g, emb),
                want,
                "{rule}: compiled {compiled}, native code {jit}"
            );
        }
    }
}

/// Two hooks whose orbits differ in shape are refused as such, whichever comes first: an
/// interior edge's `<2>` orbit has two darts, a boundary edge's one. With the boundary dart
/// second, its walk filled the rows consistently (its one dart twice) and the refusal said
/// the pattern folds onto itself, which it does not.
#[test]
fn two_hooks_on_orbits_of_different_sizes_are_refused_as_such() {
    const TWO: &str = "dimension 2
embedding position : vec3 on <1,2>
rule pair { left { a : <2> hook   b : <2> hook } }
";
    let (rules, _) = load_sources(&[("two.tmr".to_string(), TWO.to_string())]).unwrap();
    let mut g = sheet(&rules);
    let interior = g.darts().find(|&d| !g.is_free(2, d)).unwrap();
    let boundary = g.darts().find(|&d| g.is_free(2, d)).unwrap();
    for hooks in [[interior, boundary], [boundary, interior]] {
        let e = rules
            .apply_at(&mut g, "pair", &hooks, &Params::new())
            .unwrap_err()
            .to_string();
        assert!(e.contains("its orbit differs in shape"), "{hooks:?}: {e}");
    }
}
