//! Model declarations: parsed into checked models with their calls, parameters and
//! defaults; each mistake refused at its `file:line:col` with the checker's condition name.

use topomech_rules::model::Arg;
use topomech_rules::{load_sources, Diagnostic, Severity, Val};

const HEAD: &str = "dimension 3
embedding position : vec3 on <1,2,3>
embedding rest     : vec3 on <1,2,3>
embedding f_anchor : vec3 on <1,2,3>
embedding df_anchor : vec3 on <1,2,3>
embedding dx       : vec3 on <1,2,3>
embedding k_anchor : f64  on <1,2,3>
embedding dir      : vec3 on <1,2,3>
embedding wrong    : vec3 on <0,1>
embedding scalar   : f64  on <1,2,3>
rule anchor_init(k: f64, d: vec3) {
  left { v : <1,2,3> hook }
  compute { v.k_anchor = k  v.dir = d }
}
rule anchor_force {
  left { v : <1,2,3> hook }
  compute { v.f_anchor = -v.k_anchor * (v.position - v.rest) }
}
rule anchor_jvp {
  left { v : <1,2,3> hook }
  compute { v.df_anchor = -v.k_anchor * v.dx }
}
";

fn errors(model: &str) -> Vec<Diagnostic> {
    let src = format!("{HEAD}{model}");
    match load_sources(&[("m.tmr".into(), src)]) {
        Ok(_) => panic!("accepted:\n{model}"),
        Err(d) => d
            .into_iter()
            .filter(|d| d.severity == Severity::Error)
            .collect(),
    }
}

/// The line of `HEAD` + model text on which `needle` first appears (1-based).
fn line_of(model: &str, needle: &str) -> u32 {
    let src = format!("{HEAD}{model}");
    let k = src.find(needle).expect("needle in source");
    (src[..k].matches('\n').count() + 1) as u32
}

#[test]
fn a_declaration_is_parsed_into_a_checked_model() {
    // (per_element wants an init rule on elements: `element_init`, a hook on <0,1,2>)
    let model = "rule element_init(k: f64) {
  left { e : <0,1,2> hook }
  compute { e.k_anchor = k }
}
model anchor(k: f64 = 10.0, d: vec3 = vec3(0, 0, -1.5), c: f64) {
  init   anchor_init(k, vec3(1, 2, 3)), anchor_init(2.5, d), anchor_init(c, d), element_init(k)
  step   anchor_force
  forces f_anchor
  jvp    anchor_jvp -> df_anchor
  needs  \"vertices\"
  per_element
}
";
    let (rules, _) = load_sources(&[("m.tmr".into(), format!("{HEAD}{model}"))]).unwrap();
    let ms = rules.models();
    assert_eq!(ms.len(), 1);
    let m = &ms[0];
    assert_eq!(m.name, "anchor");
    assert_eq!(m.file, "m.tmr");
    assert_eq!(m.pos.line, line_of(model, "model anchor"));
    assert_eq!(m.params.len(), 3);
    assert_eq!(m.params[0].default, Some(Val::F(10.0)));
    assert_eq!(m.params[1].default, Some(Val::V3([0.0, 0.0, -1.5])));
    assert_eq!(m.params[2].default, None);
    assert_eq!(m.init.len(), 4);
    assert_eq!(m.init[0].rule, "anchor_init");
    assert_eq!(
        m.init[0].args,
        vec![
            ("k".to_string(), Arg::Param("k".into())),
            ("d".to_string(), Arg::Const(Val::V3([1.0, 2.0, 3.0])))
        ]
    );
    assert_eq!(m.init[1].args[0].1, Arg::Const(Val::F(2.5)));
    assert_eq!(m.step[0].rule, "anchor_force");
    assert!(m.step[0].args.is_empty());
    assert_eq!(m.forces, vec!["f_anchor"]);
    assert_eq!(m.jvp[0].rule, "anchor_jvp");
    assert_eq!(m.jvp_outputs, vec!["df_anchor"]);
    assert_eq!(m.needs.as_deref(), Some("vertices"));
    assert!(m.per_element);
    assert_eq!(m.dimensions, vec![3]);
    // parameter values: defaults, overrides, required, unknown, wrong type
    let given = [("c".to_string(), Val::F(1.0))].into();
    let v = m.values(&given).unwrap();
    assert_eq!(v["k"], Val::F(10.0));
    assert_eq!(v["c"], Val::F(1.0));
    let p = m.init[0].params(&v);
    assert_eq!(p["k"], Val::F(10.0));
    assert_eq!(p["d"], Val::V3([1.0, 2.0, 3.0]));
    let e = m.values(&std::collections::HashMap::default()).unwrap_err();
    assert!(e.contains("parameter 'c' is required"), "{e}");
    let e = m
        .values(&[("kk".to_string(), Val::F(1.0))].into())
        .unwrap_err();
    assert!(e.contains("has no parameter 'kk' (it has: k, d, c)"), "{e}");
    let e = m
        .values(&[("d".to_string(), Val::F(1.0))].into())
        .unwrap_err();
    assert!(e.contains("parameter 'd' is a vec3"), "{e}");
}

/// Each mistake: the model text, the condition, a piece of the message, the text at whose
/// line the error is reported.
#[test]
fn mistakes_are_refused_where_they_are() {
    let cases: &[(&str, &str, &str, &str)] = &[
        (
            "model a(k: f64 = 1.0) { init nope(k) step anchor_force forces f_anchor }",
            "name",
            "calls rule 'nope', which is not defined",
            "model a",
        ),
        (
            "model a(k: f64 = 1.0) {\n init anchor_init(k)\n step anchor_force forces f_anchor }",
            "arity",
            "rule 'anchor_init' takes 2 argument(s) (k: f64, d: vec3), the call gives 1",
            "init anchor_init",
        ),
        (
            "model a(k: f64 = 1.0) {\n init anchor_init(k, k)\n step anchor_force forces f_anchor }",
            "type",
            "parameter 'd' of rule 'anchor_init' is a vec3, the argument a f64",
            "init anchor_init",
        ),
        (
            "model a(k: f64 = 1.0) {\n init anchor_init(stiff, vec3(0,0,0))\n step anchor_force forces f_anchor }",
            "name",
            "argument 'stiff' of rule 'anchor_init' names no parameter of the model (it has: k)",
            "init anchor_init",
        ),
        (
            "model a(k: f64 = 1.0,\n stiff: f64) {\n init anchor_init(k, vec3(0,0,0))\n step anchor_force forces f_anchor }",
            "unused-parameter",
            "parameter 'stiff' is required but no rule call of the model passes it on",
            "stiff: f64",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0)) step anchor_force\n forces f_nope }",
            "name",
            "force 'f_nope' is not a declared embedding",
            "forces f_nope",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0)) step anchor_force\n forces wrong }",
            "type",
            "force 'wrong' is a vec3 on <0,1>; it must be a vec3 on a sub-orbit of the vertex",
            "forces wrong",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0)) step anchor_force\n forces scalar }",
            "type",
            "force 'scalar' is a f64",
            "forces scalar",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0)) step anchor_force forces f_anchor\n jvp anchor_jvp -> scalar }",
            "type",
            "jvp output 'scalar' is a f64",
            "jvp anchor_jvp",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0)) step anchor_force forces f_anchor\n jvp anchor_jvp -> df_anchor, dx }",
            "arity",
            "has 1 force(s) and 2 jvp output(s)",
            "jvp anchor_jvp",
        ),
        (
            "model a(k: f64 = vec3(1, 2, 3)) { init anchor_init(k, vec3(0,0,0)) step anchor_force forces f_anchor }",
            "type",
            "the default of parameter 'k' is a vec3, the parameter a f64",
            "model a",
        ),
        (
            "model a(k: i64) { init anchor_init(1, vec3(0,0,0)) step anchor_force forces f_anchor }",
            "type",
            "parameter 'k' has type 'i64'; a model parameter is f64 or vec3",
            "model a",
        ),
        (
            "model a(k: f64, k: f64) { init anchor_init(k, vec3(0,0,0)) step anchor_force forces f_anchor }",
            "name",
            "parameter 'k' is declared twice",
            "model a",
        ),
        (
            "model a { step anchor_force forces f_anchor }",
            "syntax",
            "model 'a' has no 'init' line",
            "model a",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0)) step anchor_force forces f_anchor }\nmodel a { init anchor_init(1, vec3(0,0,0)) step anchor_force forces f_anchor }",
            "name",
            "model 'a' is already declared at m.tmr:",
            "model a {",
        ),
    ];
    for (model, cond, msg, at) in cases {
        let errs = errors(model);
        let hit = errs
            .iter()
            .find(|d| d.condition == *cond && d.message.contains(msg))
            .unwrap_or_else(|| panic!("{model}: no {cond} error with {msg:?} in {errs:?}"));
        let mut line = line_of(model, at);
        if model.matches("model a {").count() == 2 {
            line += 1; // the second declaration
        }
        assert_eq!(hit.pos.line, line, "{model}: {hit}");
        assert_eq!(hit.file, "m.tmr");
        assert!(hit.pos.col >= 1);
    }
}

/// A parameter refused for its type is still the model's: an argument naming it gives no
/// second, false error (`argument 'k' of rule 'anchor_init' names no parameter of the model
/// (it has: none)` followed the type error before the fix).
#[test]
fn a_parameter_of_a_refused_type_is_one_error_not_two() {
    let model = "model anchor(k: i64 = 10) { init anchor_init(k, vec3(0,0,0)) step anchor_force forces f_anchor }";
    let errs = errors(model);
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert_eq!(errs[0].condition, "type");
    assert!(
        errs[0]
            .message
            .contains("parameter 'k' has type 'i64'; a model parameter is f64 or vec3"),
        "{}",
        errs[0]
    );
    // a name that is no parameter at all is still reported
    let model = "model anchor(k: i64) { init anchor_init(j, vec3(0,0,0)) step anchor_force forces f_anchor }";
    let errs = errors(model);
    assert!(
        errs.iter().any(|d| d
            .message
            .contains("argument 'j' of rule 'anchor_init' names no parameter of the model")),
        "{errs:?}"
    );
}

#[test]
fn duplicate_models_across_files_are_refused() {
    let other = "dimension 3\nmodel anchor { init anchor_init(1, vec3(0,0,0)) step anchor_force forces f_anchor }\n";
    let first = format!(
        "{HEAD}model anchor {{ init anchor_init(1, vec3(0,0,0)) step anchor_force forces f_anchor }}\n"
    );
    let d = load_sources(&[("a.tmr".into(), first), ("b.tmr".into(), other.into())])
        .expect_err("refused");
    let e = d
        .iter()
        .find(|d| d.condition == "name")
        .expect("a name error");
    assert_eq!(e.file, "b.tmr");
    assert_eq!((e.pos.line, e.pos.col), (2, 1));
    assert!(
        e.message
            .contains("model 'anchor' is already declared at a.tmr:"),
        "{e}"
    );
}

#[test]
fn syntax_errors_name_line_and_column() {
    for (model, msg) in [
        ("model a { init }", "expected a rule name, found '}'"),
        (
            "model a { needs vertices }",
            "expected a string after 'needs'",
        ),
        ("model a { needs \"vertices }", "string not closed"),
        (
            "model a { init r init r }",
            "'init' given twice in model 'a': list its rules on one line, separated by commas",
        ),
        ("model a { jvp r df }", "expected '-'"),
        ("model a { bogus }", "expected 'init', 'step', 'forces'"),
        ("model a(k: f64 = vec3(1, 2)) { }", "expected ','"),
    ] {
        let d = load_sources(&[("m.tmr".into(), format!("dimension 3\n{model}"))])
            .expect_err("refused");
        assert_eq!(d[0].condition, "syntax", "{model}");
        assert_eq!(d[0].pos.line, 2, "{model}: {}", d[0]);
        assert!(d[0].message.contains(msg), "{model}: {}", d[0]);
    }
}

/// A force that no step rule writes, or a jvp output that no jvp rule writes, would be summed
/// as whatever the map holds (zero; or a state such as `position`, summed as a force), and a
/// non-finite default would only fail when a simulation is built: each is refused where it
/// is written.
#[test]
fn outputs_nobody_writes_and_non_finite_defaults_are_refused() {
    for (model, needle, says) in [
        (
            "model m(k: f64 = 1.0, d: vec3 = vec3(0, 0, 0)) {\n  init anchor_init(k, d)\n  step anchor_force\n  forces f_anchor\n  jvp anchor_force -> df_anchor\n}\n",
            "df_anchor\n}",
            "jvp output 'df_anchor' is written by none of its jvp rules (anchor_force)",
        ),
        (
            "model m(k: f64 = 1.0, d: vec3 = vec3(0, 0, 0)) {\n  init anchor_init(k, d)\n  step anchor_force\n  forces position\n}\n",
            "position\n}",
            "force 'position' is written by none of its init or step rules (anchor_init, anchor_force)",
        ),
        (
            // a rule both init and step is named once
            "model m(k: f64 = 1.0, d: vec3 = vec3(0, 0, 0)) {\n  init anchor_init(k, d)\n  step anchor_init(k, d)\n  forces position\n}\n",
            "position\n}",
            "force 'position' is written by none of its init or step rules (anchor_init)",
        ),
        (
            // a default past the largest float: refused where it is written (the lexer reads
            // no infinity), before the model's own check of finite defaults
            "model m(k: f64 = 1e400, d: vec3 = vec3(0, 0, 0)) {\n  init anchor_init(k, d)\n  step anchor_force\n  forces f_anchor\n}\n",
            "1e400",
            "number '1e400' is too large",
        ),
        (
            "model m(k: f64 = 1.0, d: vec3 = vec3(0, -1e999, 0)) {\n  init anchor_init(k, d)\n  step anchor_force\n  forces f_anchor\n}\n",
            "vec3(0, -1e999",
            "number '1e999' is too large",
        ),
    ] {
        let errs = errors(model);
        let e = errs
            .iter()
            .find(|d| d.message.contains(says))
            .unwrap_or_else(|| panic!("no '{says}' in {errs:?}"));
        assert_eq!(e.pos.line, line_of(model, needle), "{says}");
    }
}

/// A parameter with a default that no rule call passes on loads, with a warning at the
/// parameter (a value given for it would change nothing); one that is passed on gives none.
#[test]
fn an_unused_parameter_with_a_default_is_a_warning() {
    let model = "model a(k: f64 = 1.0,\n unused: f64 = 2.0) {\n init anchor_init(k, vec3(0,0,0))\n step anchor_force forces f_anchor }\n";
    let (rules, warnings) = load_sources(&[("m.tmr".into(), format!("{HEAD}{model}"))])
        .expect("a warning does not refuse the file");
    // nor drop the model
    let names: Vec<&str> = rules.models().iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["a"], "{warnings:?}");
    let w: Vec<&Diagnostic> = warnings
        .iter()
        .filter(|d| d.condition == "unused-parameter")
        .collect();
    assert_eq!(w.len(), 1, "{warnings:?}");
    assert_eq!(w[0].severity, Severity::Warning);
    assert!(
        w[0].message
            .contains("model 'a': parameter 'unused' is passed to no rule call"),
        "{}",
        w[0]
    );
    assert_eq!(w[0].pos.line, line_of(model, "unused: f64"));
}

/// A model's rules compute its own embeddings: a call to a rule that changes the topology
/// (it lost the map's masses and crashed a run: QA), or to one that writes the simulation's
/// state (`fixed`, `position`: it undid the supports), is refused at the call (`model-rule`);
/// so is a force that is the simulation's own (`f_ext`) or one listed twice (summed twice).
/// The numbering the simulation sets up is its own too: a model's `point_id = 0` passed the
/// checker and renumbered every output to point 0, one writing `vertex0` passed and made a
/// shipped model's init fail with a write conflict that blamed that model, one writing
/// `corner_mass` in a step made the total mass negative and ran on (QA).
#[test]
fn model_rules_that_would_change_what_the_simulation_owns_are_refused() {
    let extra = "embedding fixed : bool on <1,2,3>
embedding f_ext : vec3 on <1,2,3>
rule tear {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
}
rule unfix { left { v : <1,2,3> hook } compute { v.fixed = false  v.f_anchor = vec3(0, 0, 0) } }
rule push { left { v : <1,2,3> hook } compute { v.position = v.position + vec3(0, 0, 1) } }
embedding point_id : i64 on <1,2,3>
embedding vertex0 : bool on <>
rule renumber { left { v : <1,2,3> hook } compute { v.point_id = 0  v.f_anchor = vec3(0, 0, 0) } }
rule mark { left { v : <1,2,3> hook } compute { v.vertex0 = true  v.f_anchor = vec3(0, 0, 0) } }
embedding corner_mass : f64 on <1,2>
rule lose_mass { left { c : <1,2> hook } compute { c.corner_mass = -1.0 } }
";
    let cases: &[(&str, &str, &str)] = &[
        (
            "model a { init anchor_init(1, vec3(0,0,0))\n step anchor_force, tear forces f_anchor }",
            "step calls rule 'tear', which changes the topology",
            "step anchor_force, tear",
        ),
        (
            "model a {\n init unfix\n step anchor_force forces f_anchor }",
            "init calls rule 'unfix', which writes 'fixed', the simulation's own",
            "init unfix",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0))\n step push forces f_anchor }",
            "step calls rule 'push', which writes 'position'",
            "step push",
        ),
        (
            "model a {\n init renumber\n step anchor_force forces f_anchor }",
            "init calls rule 'renumber', which writes 'point_id', the simulation's own",
            "init renumber",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0))\n step mark forces f_anchor }",
            "step calls rule 'mark', which writes 'vertex0'",
            "step mark",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0))\n step anchor_force, lose_mass forces f_anchor }",
            "step calls rule 'lose_mass', which writes 'corner_mass'",
            "step anchor_force, lose_mass",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0)) step anchor_force\n forces f_ext }",
            "force 'f_ext' is the simulation's own",
            "forces f_ext",
        ),
        (
            "model a { init anchor_init(1, vec3(0,0,0)) step anchor_force\n forces f_anchor, f_anchor }",
            "force 'f_anchor' is listed twice",
            "forces f_anchor",
        ),
    ];
    for (model, msg, at) in cases {
        let text = format!("{extra}{model}");
        let errs = errors(&text);
        let hit = errs
            .iter()
            .find(|d| d.message.contains(msg))
            .unwrap_or_else(|| panic!("{model}: no error with {msg:?} in {errs:?}"));
        assert_eq!(hit.pos.line, line_of(&text, at), "{model}: {hit}");
    }
}

/// A model calling a rule the checker refused says so, instead of calling the rule
/// undefined (QA: the rule is right there, with its own errors above).
#[test]
fn a_call_to_a_refused_rule_says_it_was_refused() {
    let model = "rule broken { left { v : <1,2,3> hook } compute { v.nope = 1.0 } }
model a { init broken step anchor_force forces f_anchor }
";
    let errs = errors(model);
    assert!(
        errs.iter().any(|d| d
            .message
            .contains("init calls rule 'broken', which the checker refused")),
        "{errs:?}"
    );
    assert!(
        !errs
            .iter()
            .any(|d| d.message.contains("which is not defined")),
        "{errs:?}"
    );
}

/// A model calling a rule of its own file that was refused because another file defines the
/// name (a user's `lump_mass` beside the shipped one) gets only that error: before, the model
/// was checked against the other file's rule, and a second error blamed it for what that
/// rule writes or takes (QA).
#[test]
fn a_model_calling_its_files_refused_duplicate_rule_gets_one_error() {
    let first = "dimension 3
embedding k_a : f64 on <1,2,3>
rule setup { left { v : <1,2,3> hook } compute { v.k_a = 1.0 } }
";
    let other = "dimension 3
embedding k_b : f64 on <1,2,3>
embedding f_b : vec3 on <1,2,3>
rule setup(k: f64) { left { v : <1,2,3> hook } compute { v.k_b = k } }
rule push { left { v : <1,2,3> hook } compute { v.f_b = v.k_b * vec3(1, 0, 0) } }
model pushed(k: f64 = 1.0) { init setup(k) step push forces f_b }
";
    let d = load_sources(&[
        ("a.tmr".into(), first.into()),
        ("b.tmr".into(), other.into()),
    ])
    .expect_err("refused");
    let errs: Vec<&Diagnostic> = d.iter().filter(|d| d.severity == Severity::Error).collect();
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert!(
        errs[0]
            .message
            .contains("rule 'setup' is already defined at a.tmr:3:1"),
        "{}",
        errs[0]
    );
}

/// `per_element` without an init rule on elements (a hook on the element's orbit or a dart)
/// is refused by the checker, at `per_element`: every simulation would refuse the model
/// (QA: `topomech check` said ok).
#[test]
fn per_element_without_an_element_rule_is_refused_where_it_is_written() {
    let model = "model m(k: f64 = 1.0, d: vec3 = vec3(0, 0, 0)) {
  init   anchor_init(k, d)
  step   anchor_force
  forces f_anchor
  per_element
}
";
    let errs = errors(model);
    let e = errs
        .iter()
        .find(|d| d.message.contains("is declared per_element"))
        .unwrap_or_else(|| panic!("{errs:?}"));
    assert_eq!(e.condition, "model-rule");
    assert_eq!(e.pos.line, line_of(model, "per_element"));
    assert!(
        e.message
            .contains("none of its init rules (anchor_init) is on elements"),
        "{e}"
    );
}
