//! One test per checker condition: a rule that violates it (the diagnostic names the
//! condition, the line and the node or label) and a close rule that passes.

use topomech_rules::{load_sources, Diagnostic, Severity};

fn check(src: &str) -> Result<Vec<Diagnostic>, Vec<Diagnostic>> {
    load_sources(&[("t.tmr".into(), src.into())]).map(|(_, w)| w)
}

/// Asserts `src` is refused with `condition` at `line`, with `needle` in the message.
fn refused(src: &str, condition: &str, line: u32, needle: &str) {
    let errs = check(src).expect_err("the rule should be refused");
    let hit = errs
        .iter()
        .find(|d| d.condition == condition && d.severity == Severity::Error)
        .unwrap_or_else(|| panic!("no {condition} error in {errs:#?}"));
    assert_eq!(hit.pos.line, line, "{hit}");
    assert!(hit.message.contains(needle), "{hit}");
    let text = hit.to_string();
    assert!(text.starts_with(&format!("t.tmr:{line}:")), "{text}");
    assert!(text.contains(&format!("error[{condition}]")), "{text}");
}

fn accepted(src: &str) {
    if let Err(e) = check(src) {
        panic!(
            "{}",
            e.iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join("\n")
        );
    }
}

const HEAD: &str =
    "dimension 2\nembedding position : vec3 on <1,2>\nembedding weight : f64 on <0,1>\n";

fn with_head(body: &str) -> String {
    format!("{HEAD}{body}")
}

#[test]
fn syntax() {
    refused(
        &with_head("rule r {\n  left { a <0> hook }\n}"),
        "syntax",
        5,
        "expected ':'",
    );
    accepted(&with_head("rule r {\n  left { a : <0> hook }\n}"));
}

#[test]
fn type_() {
    refused(
        &with_head("rule r {\n  left { a : <0,1> hook }\n  compute { a.weight = a.position }\n}"),
        "type",
        6,
        "weight has type f64",
    );
    accepted(&with_head("rule r {\n  left { a : <0,1> hook }\n  compute { a.weight = norm(mean<0,1>(a.position)) }\n}"));
    refused(
        &with_head("rule r(dt: f64) {\n  left { a : <0,1> hook }\n  where dt\n}"),
        "type",
        6,
        "guard has type f64",
    );
    refused(
        &with_head("rule r {\n  left { a : <0,1> hook }\n  compute { a.weight = 1.0 + true }\n}"),
        "type",
        6,
        "",
    );
}

#[test]
fn dimension() {
    refused(
        &with_head("rule r {\n  left { a : <0,3> hook }\n}"),
        "dimension",
        5,
        "label 3",
    );
    refused(
        &with_head("rule r {\n  left { a : <0> hook  b : <0>  a -4- b }\n}"),
        "dimension",
        5,
        "label 4",
    );
    refused("dimension 4\n", "dimension", 1, "dimension 4");
    refused(
        "embedding x : f64 on <0>\n",
        "dimension",
        1,
        "has no 'dimension' line",
    );
    accepted(&with_head("rule r {\n  left { a : <0,2> hook }\n}"));
}

#[test]
fn name() {
    refused(
        &with_head("rule r {\n  left { a : <0> hook  a : <0> }\n}"),
        "name",
        5,
        "'a' is declared twice",
    );
    refused(
        &with_head("rule r {\n  left { a : <0> hook }\n}\nrule r {\n  left { a : <0> hook }\n}"),
        "name",
        7,
        "already defined",
    );
    refused(
        &with_head("rule r {\n  left { a : <0> hook }\n  compute { a.mass = 1.0 }\n}"),
        "name",
        6,
        "unknown embedding 'mass'",
    );
    refused(
        &with_head("rule r {\n  left { a : <0> hook  a -2- z }\n}"),
        "name",
        5,
        "'z'",
    );
    refused(
        "dimension 2\nembedding w : f64 on <0>\nembedding w : f64 on <1>\n",
        "name",
        3,
        "declared again differently",
    );
    accepted(&with_head("rule r {\n  left { a : <0> hook  b : <0>  a -2- b }\n}\nrule s {\n  left { a : <0> hook }\n}"));
}

/// Regression: "embedding 'w' is declared again differently" did not say how, nor where the
/// other declaration is. The error names what differs and both declarations, the first at its
/// `FILE:LINE:COL`.
#[test]
fn an_embedding_declared_again_differently_names_both_declarations() {
    let first = "dimension 2\nembedding m : f64 on <>\nembedding w : f64 on <0> policy sum\n";
    let cases = [
        (
            "embedding w : i64 on <0> policy sum",
            "type",
            "i64 on <0> policy sum",
        ),
        (
            "embedding w : f64 on <1> policy sum",
            "orbit",
            "f64 on <1> policy sum",
        ),
        (
            "embedding w : f64 on <0>",
            "policy",
            "f64 on <0> policy copy",
        ),
        (
            "embedding w : vec3 on <0,1>",
            "type and orbit and policy",
            "vec3 on <0,1> policy copy",
        ),
        (
            "embedding w : f64 on <0> policy sum derived sum(m)",
            "derivation",
            "f64 on <0> policy sum derived sum(m)",
        ),
    ];
    for (again, what, described) in cases {
        let second = format!("dimension 2\n\n{again}\n");
        let errs = load_sources(&[("a.tmr".into(), first.into()), ("b.tmr".into(), second)])
            .map(|_| ())
            .expect_err(again);
        let hit = errs.iter().find(|d| d.condition == "name").expect(again);
        assert_eq!(
            hit.to_string(),
            format!(
                "b.tmr:3:1: error[name]: embedding 'w' is declared again differently (its \
                 {what}): '{described}' here, 'f64 on <0> policy sum' at a.tmr:3:1"
            )
        );
    }
    // the same declaration again is the same embedding
    let same = "dimension 2\nembedding w : f64 on <0> policy sum\n";
    assert!(load_sources(&[
        ("a.tmr".into(), first.into()),
        ("b.tmr".into(), same.into())
    ])
    .is_ok());
}

#[test]
fn hook() {
    refused(
        &with_head("rule r {\n  left { a : <0> }\n}"),
        "hook",
        5,
        "no hook",
    );
    refused(
        &with_head("rule r {\n  left { a : <0> hook  b : <0> hook  a -2- b }\n}"),
        "hook",
        5,
        "2 hooks",
    );
    refused(
        &with_head("rule r {\n  left { a : <0,_> hook }\n}"),
        "hook",
        5,
        "'_'",
    );
    accepted(&with_head(
        "rule r {\n  left { a : <0,1> hook  b : <0,_>  a -2- b }\n}",
    ));
}

#[test]
fn arity() {
    refused(
        &with_head("rule r {\n  left { a : <0> hook\n  b : <0,1>  a -2- b }\n}"),
        "arity",
        6,
        "every orbit type of a rule has the same length",
    );
    accepted(&with_head(
        "rule r {\n  left { a : <0> hook\n  b : <1>  a -2- b }\n}",
    ));
}

#[test]
fn duplicate_label() {
    refused(
        &with_head("rule r {\n  left { a : <0> hook  b : <0>  a -0- b }\n}"),
        "duplicate-label",
        5,
        "label 0 twice",
    );
    refused(
        &with_head("rule r {\n  left { a : <1,1> hook }\n}"),
        "duplicate-label",
        5,
        "label 1 twice",
    );
    accepted(&with_head(
        "rule r {\n  left { a : <0> hook  b : <0>  a -1- b }\n}",
    ));
}

#[test]
fn incident_arc() {
    // a created node without label 1
    refused(
        &with_head("rule r {\n  left { a : <0> hook }\n  right { a : <0>  b : <0>\n  a -2- a }\n}"),
        "incident-arc",
        6,
        "node 'b' is created but has no label 1",
    );
    // a deleted node whose label 2 leads outside the rule
    refused(
        &with_head("rule r {\n  left { a : <0,1> hook }\n  right { }\n}"),
        "incident-arc",
        5,
        "label 2 is not matched",
    );
    accepted(&with_head(
        "rule r {\n  left { a : <0,1> hook  a -2- a }\n  right { }\n}",
    ));
    // a kept node losing its orbit label 1 without giving it back
    refused(
        &with_head("rule r {\n  left { a : <0,1> hook }\n  right { a : <0,_> }\n}"),
        "incident-arc",
        5,
        "loses label 1",
    );
    accepted(&with_head(
        "rule r {\n  left { a : <0,1> hook }\n  right { a : <0,_>  a -1- a }\n}",
    ));
}

#[test]
fn cycle() {
    // a new face glued by alpha2 whose alpha0 does not follow: alpha0 alpha2 breaks
    refused(
        &with_head("rule r {\n  left { a : <0,1> hook }\n  right { a : <0,1>  b : <1,_>  a -2- b  b -0- b }\n  compute { b.weight = 1.0 }\n}"),
        "cycle",
        5,
        "alpha0 o alpha2",
    );
    // a label changed while the other label of the cycle is outside the rule
    refused(
        &with_head("rule r {\n  left { a : <1> hook }\n  right { a : <1>  b : <1>\n  a -0- b  b -2- b }\n  compute { b.position = a.position }\n}"),
        "cycle",
        5,
        "node 'a' has no label 2",
    );
    accepted(&with_head("rule r {\n  left { a : <0> hook  b : <0> hook  a -2- a  b -2- b }\n  right { a : <0>  b : <0>  a -2- b }\n  compute { a.position = (a.position + b.position) / 2.0 }\n}"));
}

#[test]
fn embedding_missing() {
    let tri = "rule r {\n  left  { n0 : <0,1> hook }\n  right { n0 : <0,_>  n1 : <_,2>  n2 : <1,2>  n0 -1- n1  n1 -0- n2 }\n  compute { X }\n}";
    refused(
        &with_head(&tri.replace('X', "n0.weight = 1.0")),
        "embedding-missing",
        6,
        "'n2' is created and gets no value of 'position'",
    );
    accepted(&with_head(
        &tri.replace('X', "n2.position = mean<0,1>(n0.position)"),
    ));
}

#[test]
fn embedding_merge() {
    let sew = "rule r {\n  left { a : <0> hook  b : <0> hook  a -2- a  b -2- b }\n  right { a : <0>  b : <0>  a -2- b }\n  compute { X }\n}";
    refused(
        &with_head(&sew.replace('X', "")),
        "embedding-merge",
        5,
        "may merge",
    );
    accepted(&with_head(
        &sew.replace('X', "a.position = (a.position + b.position) / 2.0"),
    ));
}

#[test]
fn embedding_write_conflict() {
    let tri = "rule r {\n  left  { n0 : <0,1> hook }\n  right { n0 : <0,_>  n1 : <_,2>  n2 : <1,2>  n0 -1- n1  n1 -0- n2 }\n  compute { X }\n}";
    // one value per new vertex, but n0.position differs from corner to corner
    refused(
        &with_head(&tri.replace('X', "n2.position = n0.position")),
        "embedding-write-conflict",
        7,
        "may differ",
    );
    // two writes to the same orbit
    let sew = "rule r {\n  left { a : <0> hook  b : <0> hook  a -2- a  b -2- b }\n  right { a : <0>  b : <0>  a -2- b }\n  compute {\n  a.position = a.position\n  b.position = b.position }\n}";
    refused(
        &with_head(sew),
        "embedding-write-conflict",
        9,
        "written twice",
    );
    accepted(&with_head(
        &tri.replace('X', "n2.position = mean<0,1>(n0.position)"),
    ));
}

/// A derived embedding whose aggregate is not defined for its source's type says so, and
/// which aggregates take which types, at the declaration's line and column: before, a sum of
/// a bool said "derived embedding 'w' must have type bool" (as if `w : bool` would do, which
/// the map then refuses). A wrong type for a defined aggregate says why it is the one.
#[test]
fn derived_aggregates_of_a_type_they_do_not_take_are_refused_saying_which_do() {
    let src = |agg: &str, src_ty: &str, ty: &str| {
        format!("dimension 2\nembedding s : {src_ty} on <0>\nembedding w : {ty} on <0,1> derived {agg}(s)\n")
    };
    let which = "sum takes f64, i64, vectors and matrices, mean f64, vectors and matrices, both of the source's type; count takes any type and is i64";
    for (agg, src_ty, ty) in [
        ("sum", "bool", "f64"),
        ("sum", "bool", "bool"),
        ("mean", "bool", "f64"),
        ("mean", "i64", "i64"),
    ] {
        let text = src(agg, src_ty, ty);
        refused(
            &text,
            "type",
            3,
            &format!(
                "derived embedding 'w': {agg} of 's' is not defined, 's' being {src_ty} ({which})"
            ),
        );
        let errs = check(&text).unwrap_err();
        assert_eq!(errs[0].pos.col, 1, "{}", errs[0]);
        assert!(!errs[0].message.contains("must have type"), "{}", errs[0]);
    }
    refused(
        &src("sum", "vec3", "f64"),
        "type",
        3,
        "derived embedding 'w' must have type vec3 (a sum has its source's type: 's' is vec3)",
    );
    refused(
        &src("count", "bool", "f64"),
        "type",
        3,
        "derived embedding 'w' must have type i64 (a count is i64)",
    );
    accepted(&src("count", "bool", "i64"));
    accepted(&src("sum", "i64", "i64"));
    accepted(&src("mean", "vec3", "vec3"));
}

#[test]
fn warnings_do_not_refuse() {
    let w = check(&with_head(
        "rule r(dt: f64) {\n  left { a : <0,1> hook }\n}",
    ))
    .unwrap();
    assert_eq!(w.len(), 1);
    assert_eq!(w[0].condition, "unused");
    assert!(w[0].to_string().contains("warning[unused]"));
}

/// `a.w = 1 / 2` divides two integers (0, written as 0.0): accepted silently before, while a
/// cut predicate refuses the same quotient. Now a warning `integer-division` at the
/// division's `file:line:col` (its operator), which does not refuse the file; a real operand, `to_i64(a /
/// b)` (the integer quotient meant) or reals give none; integer-typed operands of any kind
/// (a count, an i64 parameter, a let) warn.
#[test]
fn a_quotient_of_two_integers_is_a_warning() {
    let rule = |body: &str| {
        with_head(&format!(
            "rule r(n: i64) {{\n  left {{ a : <0,1> hook }}\n  compute {{ {body} }}\n}}"
        ))
    };
    for body in [
        "a.weight = 1 / 2 + to_f64(n)",
        "a.weight = to_f64(n / 2)",
        "a.weight = to_f64(count<0,1>(a) / 3) + to_f64(n)",
        "let k = n / 4\n    a.weight = to_f64(k)",
    ] {
        // at the operator, on the compute line (its body starts at column 13)
        let col = 13 + body.find('/').unwrap() as u32;
        let src = rule(body);
        let w = check(&src).unwrap_or_else(|e| panic!("refused: {e:?}"));
        let hits: Vec<_> = w
            .iter()
            .filter(|d| d.condition == "integer-division")
            .collect();
        assert_eq!(hits.len(), 1, "{body}: {w:?}");
        let d = hits[0];
        assert_eq!(d.severity, Severity::Warning);
        assert_eq!((d.pos.line, d.pos.col), (6, col), "{body}: {d}");
        assert!(d.to_string().starts_with("t.tmr:6:"), "{d}");
        assert!(d.to_string().contains("warning[integer-division]: rule 'r': a quotient of two integers is an integer, rounded toward zero (1 / 2 is 0, 7 / 2 is 3): write a real operand, e.g. 1.0 / 2, for the real quotient, or to_i64(a / b) where the integer quotient is meant"), "{d}");
    }
    for body in [
        "a.weight = 1.0 / 2 + to_f64(n)",
        "a.weight = to_f64(n) / 2",
        "a.weight = to_f64(to_i64(n / 2))",
        "a.weight = 1.0 / 2.0 + to_f64(n % 2)",
    ] {
        let w = check(&rule(body)).unwrap_or_else(|e| panic!("refused: {e:?}"));
        assert!(
            w.iter().all(|d| d.condition != "integer-division"),
            "{body}: {w:?}"
        );
    }
}

/// No shipped rule file divides two integers (each would print the warning on every load).
#[test]
fn no_shipped_rule_file_divides_two_integers() {
    for dim in [2, 3] {
        let (name, text) = topomech_rules::library(dim).unwrap();
        let (_, w) = load_sources(&[(name.clone(), text)]).unwrap();
        assert!(
            w.iter().all(|d| d.condition != "integer-division"),
            "{name}: {w:?}"
        );
    }
}

/// `Rule::hook_images`, which lets a patch skip the hook orbits whose match is one found
/// already (the same footprint): the other end of a spring (both ends `<2,3>`, or both
/// half-edges `<>`); none where the two ends have other orbit types, or where the hook is
/// the middle of a chain whose two arcs have other labels (nothing maps it elsewhere).
#[test]
fn hook_images_are_the_nodes_an_automorphism_moves_the_hook_to() {
    let head = "dimension 3\nembedding position : vec3 on <1,2,3>\nembedding h : f64 on <>\n";
    let images = |left: &str| -> Vec<usize> {
        let src = format!("{head}rule s {{\n  left {{ {left} }}\n  compute {{ a.h = 1.0 }}\n}}\n");
        let (rs, _) = load_sources(&[("t.tmr".into(), src)]).expect("accepted");
        rs.rule("s").expect("declared").hook_images.clone()
    };
    // node indices in declaration order
    assert_eq!(images("a : <2,3> hook   b : <2,3>   a -0- b"), vec![1]);
    assert_eq!(images("b : <> a : <> hook   b -0- a"), vec![0]);
    assert!(images("a : <2,3> hook   b : <1,3>   a -0- b").is_empty());
    assert!(images("b : <> a : <> hook   c : <>   a -0- b   a -1- c").is_empty());
}

/// A computation rule whose left graph maps onto itself with the hook moved (a spring's two
/// ends) is matched once per footprint: writing one end only leaves the other unwritten, a
/// warning at the write. Writing both ends, or an embedding whose orbit joins the two ends
/// (an edge embedding), or a pattern with no such symmetry, passes without it.
#[test]
fn mirror_write() {
    let head = "dimension 3\nembedding position : vec3 on <1,2,3>\nembedding f : vec3 on <2,3>\nembedding l : f64 on <0,2,3>\nembedding h : f64 on <>\n";
    let spring = |body: &str| {
        format!("{head}rule s {{\n  left {{ a : <2,3> hook   b : <2,3>   a -0- b }}\n  compute {{\n{body}\n  }}\n}}\n")
    };
    let mirror = |src: &str| -> Vec<Diagnostic> {
        check(src)
            .expect("accepted: a warning only")
            .into_iter()
            .filter(|d| d.condition == "mirror-write")
            .collect()
    };
    let w = mirror(&spring("    a.f = b.position - a.position"));
    assert_eq!(w.len(), 1, "{w:#?}");
    assert_eq!(w[0].severity, Severity::Warning);
    assert_eq!((w[0].pos.line, w[0].pos.col), (9, 5), "{}", w[0]);
    assert!(
        w[0].message.contains("'a.f' is written but 'b.f' is not"),
        "{}",
        w[0]
    );
    assert!(w[0]
        .to_string()
        .starts_with("t.tmr:9:5: warning[mirror-write]"));
    // both ends written: no warning
    assert!(mirror(&spring(
        "    a.f = b.position - a.position\n    b.f = a.position - b.position"
    ))
    .is_empty());
    // an edge embedding: the two ends are one edge
    assert!(mirror(&spring("    a.l = norm(b.position - a.position)")).is_empty());
    // half-edges: the same symmetry
    let half = format!(
        "{head}rule s {{\n  left {{ a : <> hook   b : <>   a -0- b }}\n  compute {{ a.h = norm(b.position - a.position) }}\n}}\n"
    );
    assert_eq!(mirror(&half).len(), 1);
    // no symmetry moving the hook: the two nodes have other orbit types
    let asym = format!(
        "{head}rule s {{\n  left {{ a : <2,3> hook   b : <1,3>   a -0- b }}\n  compute {{ a.f = b.position - a.position }}\n}}\n"
    );
    assert!(mirror(&asym).is_empty());
}

/// A rule defined twice: the second one's body is checked all the same, so its own problems
/// (here a type error) are reported with the name's, not only once the name is fixed.
#[test]
fn a_duplicated_rule_body_is_checked_too() {
    let errs = check(&with_head(
        "rule r {\n  left { a : <0> hook }\n}\nrule r {\n  left { a : <0> hook }\n  compute { a.weight = 1.0 + true }\n}",
    ))
    .expect_err("refused");
    assert!(
        errs.iter()
            .any(|d| d.condition == "name" && d.message.contains("already defined")),
        "{errs:#?}"
    );
    assert!(
        errs.iter()
            .any(|d| d.condition == "type" && d.pos.line == 9),
        "{errs:#?}"
    );
}

/// A compute-only rule (no right graph) keeps its left graph: a problem of it is reported
/// once, for the left graph, not again for a right graph the rule does not have.
#[test]
fn a_compute_only_rule_reports_a_label_once() {
    let errs = check(&with_head(
        "rule r {\n  left { a : <0,7> hook }\n  compute { a.weight = 1.0 }\n}",
    ))
    .expect_err("refused");
    let dims: Vec<&Diagnostic> = errs.iter().filter(|d| d.condition == "dimension").collect();
    assert_eq!(dims.len(), 1, "{errs:#?}");
    assert!(dims[0].message.contains("in the left graph"), "{}", dims[0]);
}
