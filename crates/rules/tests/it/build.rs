//! `build`: one expression parsed from user text, rules built as syntax trees and checked and
//! loaded beside text sources. A built rule behaves exactly as the same rule written as text
//! (same matches, same vertices selected).

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build as build_mesh, BuildOptions};
use topomech_gmap::Value;
use topomech_rules::ast::ExprKind;
use topomech_rules::build::{self, parse_expression};
use topomech_rules::value::BinOp;
use topomech_rules::{load_sources, parser, Params, Severity};

const DECLS: &str = "dimension 2
embedding position : vec3 on <1,2>
embedding fixed : bool on <1,2>
";

/// The whole text must be one expression: everything after it is refused at its column,
/// naming the label given.
#[test]
fn trailing_tokens_and_rule_syntax_are_refused_at_their_column() {
    for (text, col) in [
        ("x < 0 }", 7),
        (
            "x < 0 } rule evil { left { v : <1,2> hook } compute { v.fixed = true } } rule x {",
            7,
        ),
        ("x < 0 rule", 7),
        ("x < 0 x", 7),
        ("x < 0;", 6),
        ("(x < 0))", 8),
        ("let a = 1; a < 0 } {", 18),
    ] {
        let d = parse_expression("fix[0].where", text).unwrap_err();
        assert_eq!(d.file, "fix[0].where");
        assert_eq!(d.severity, Severity::Error);
        assert_eq!(d.condition, "syntax");
        assert_eq!((d.pos.line, d.pos.col), (1, col), "{text}: {}", d.message);
        assert!(
            d.message.starts_with("expected the end of the expression"),
            "{}",
            d.message
        );
    }
    // nothing, or only bindings, is not an expression
    for text in ["", "   ", "let a = 1"] {
        let d = parse_expression("p", text).unwrap_err();
        assert!(
            d.message.contains("expected an expression"),
            "{text:?}: {}",
            d.message
        );
    }
    // a lexing error is a diagnostic too
    let d = parse_expression("p", "x < 0 @").unwrap_err();
    assert_eq!(d.pos.col, 7, "{}", d.message);
}

/// Expressions the rule language allows in a guard parse: operators, functions, blocks,
/// `if`, leading `let` bindings (then the result is a block of those bindings).
#[test]
fn expressions_parse() {
    let e = parse_expression("p", "x < 0.5 && !(y > 1) || abs(z) <= 2").unwrap();
    assert!(matches!(e.kind, ExprKind::Binary(BinOp::Or, _, _)));
    let e = parse_expression("p", "let a = x * 2; let b = a + 1  b > 0").unwrap();
    let ExprKind::Block(stmts, _) = &e.kind else {
        panic!("{e:?}")
    };
    assert_eq!(stmts.len(), 2);
    assert!(parse_expression("p", "if x > 0 { y } else { z } < 1").is_ok());
    assert!(parse_expression("p", "{ let s = x + y  s < 1 }").is_ok());
    assert!(parse_expression("p", "x < 1 # a comment").is_ok());
    let e = parse_expression("p", "\n  x < 1").unwrap();
    assert_eq!((e.pos.line, e.pos.col), (2, 5));
}

/// A chain deeper than the parser's limit is its depth error, not a stack overflow.
#[test]
fn a_long_operator_chain_is_the_depth_error() {
    let text = format!("{} < 0", vec!["x"; 20000].join(" + "));
    let d = parse_expression("p", &text).unwrap_err();
    assert!(
        d.message
            .contains("expression nested too deeply: depth 257, the limit is 256"),
        "{}",
        d.message
    );
    let text = format!("{}x{} < 0", "(".repeat(5000), ")".repeat(5000));
    assert!(parse_expression("p", &text)
        .unwrap_err()
        .message
        .contains("too deeply"));
}

/// The rule `fix` written as text and built as a tree around a parsed predicate: both match
/// the same darts and fix the same vertices of a 3 x 3 grid.
#[test]
fn a_built_rule_equals_the_same_rule_written_as_text() {
    let text_rule = "dimension 2
rule fix {
  left { v : <1,2> hook }
  where { let x = x(v.position)  let y = y(v.position)  x < 1.5 && y > 0.5 }
  compute { v.fixed = true }
}";
    let pred = parse_expression("fix.where", "x < 1.5 && y > 0.5").unwrap();
    let mut r = build::rule("fix", build::graph(vec![build::node("v", &[1, 2], true)]));
    r.guard = Some(build::let_block(
        vec![
            ("x", build::call("x", vec![build::read("v", "position")])),
            ("y", build::call("y", vec![build::read("v", "position")])),
        ],
        pred,
    ));
    r.compute = vec![build::write("v", "fixed", build::boolean(true))];
    let built = build::file(&parser::parse(DECLS).unwrap(), vec![r]);

    let (by_text, _) = load_sources(&[
        ("decls.tmr".into(), DECLS.into()),
        ("fix.tmr".into(), text_rule.into()),
    ])
    .unwrap();
    let (by_tree, _) = build::load(
        &[("decls.tmr".into(), DECLS.into())],
        vec![("built".into(), built)],
    )
    .unwrap();

    let mesh = grid([2, 2], [2.0, 2.0], GridElement::Quad);
    let mut fixed = Vec::new();
    for rules in [&by_text, &by_tree] {
        let (mut g, _) = build_mesh(&mesh, &BuildOptions::default()).unwrap();
        let rep = rules
            .apply_everywhere(&mut g, "fix", &Params::new())
            .unwrap();
        let id = g.embedding_id("fixed").unwrap();
        let pos = g.embedding_id("position").unwrap();
        let mut sel: Vec<[u64; 2]> = Vec::new();
        for d in g.darts() {
            if g.value(id, d).unwrap() == Value::Bool(true) {
                let p = g.real(pos, d);
                sel.push([p[0].to_bits(), p[1].to_bits()]);
            }
        }
        sel.sort_unstable();
        sel.dedup();
        fixed.push((rep.matches, sel));
    }
    // vertices with x in {0, 1} and y in {1, 2}: 4 of the 9
    assert_eq!(fixed[0].1.len(), 4, "{:?}", fixed[0]);
    assert_eq!(fixed[0], fixed[1]);
}

/// A built rule goes through every check: writing an undeclared embedding or reading an
/// unknown variable is a diagnostic naming the built file's label and the place in the
/// parsed predicate.
#[test]
fn built_rules_are_checked() {
    let decls = parser::parse(DECLS).unwrap();
    let mut r = build::rule("r", build::graph(vec![build::node("v", &[1, 2], true)]));
    r.guard = Some(parse_expression("fixed[0]", "x < 1 && w > 0").unwrap());
    r.compute = vec![build::write("v", "fixed", build::boolean(true))];
    let f = build::file(&decls, vec![r]);
    let diags = build::load(
        &[("decls.tmr".into(), DECLS.into())],
        vec![("fixed[0]".into(), f)],
    )
    .err()
    .unwrap();
    let d = diags
        .iter()
        .find(|d| d.severity == Severity::Error)
        .unwrap();
    assert_eq!(d.file, "fixed[0]");
    assert_eq!((d.pos.line, d.pos.col), (1, 1), "{d}");
    assert!(
        d.message.contains("unknown variable or parameter 'x'"),
        "{d}"
    );

    let mut r = build::rule("r", build::graph(vec![build::node("v", &[1, 2], true)]));
    r.compute = vec![build::write("v", "nowhere", build::real(1.0))];
    let f = build::file(&decls, vec![r]);
    let diags = build::load(
        &[("decls.tmr".into(), DECLS.into())],
        vec![("built".into(), f)],
    )
    .err()
    .unwrap();
    assert!(
        diags
            .iter()
            .any(|d| d.file == "built" && d.message.contains("nowhere")),
        "{diags:?}"
    );
    // a syntax error in a text source is reported as by load_sources
    let diags = build::load(&[("bad.tmr".into(), "dimension 2 rule {".into())], vec![])
        .err()
        .unwrap();
    assert_eq!(diags[0].file, "bad.tmr");
}

#[test]
fn identifiers() {
    for ok in ["f_stretch", "_a", "df2"] {
        assert!(build::is_identifier(ok), "{ok}");
    }
    for bad in ["", "_", "2f", "f-x", "a b", "v.force", "f}"] {
        assert!(!build::is_identifier(bad), "{bad}");
    }
}
