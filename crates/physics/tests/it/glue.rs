//! The glue of a step built as syntax trees: a scene's predicate is one expression, never
//! rule text. A predicate containing rule syntax is refused as a bad predicate naming its key
//! and column; an ordinary predicate selects exactly the vertices (elements) it says,
//! checked against the same predicate evaluated here in Rust on the rest positions.

// the shared test helpers index arrays in loops, as the formulas they mirror do
#![allow(clippy::needless_range_loop)]

use crate::common;

use common::model;
use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_physics::{
    eval_expression, eval_predicate, Config, Cut, MaterialRegion, PhysicsError, PointsError,
    Simulation, TimedEvent,
};

fn sim(mesh: &Mesh, f: impl FnOnce(&mut Config)) -> Result<Simulation, PhysicsError> {
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let mut cfg = Config {
        models: vec![model("stretch_elementary", &[])],
        ..Config::default()
    };
    f(&mut cfg);
    Simulation::new(g, cfg)
}

fn mesh() -> Mesh {
    cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra)
}

/// Sets one predicate of a configuration.
type SetUp = Box<dyn FnOnce(&mut Config)>;

/// A timed predicate cut of predicate `p` (the configuration's `events[0]`).
fn cut_where(p: &str) -> SetUp {
    let p = p.to_string();
    Box::new(move |c: &mut Config| {
        c.events = vec![TimedEvent {
            time: 0.01,
            cut: Cut::Where(p),
        }];
    })
}

/// The message of the refusal of the simulation `f` sets up on `m`, with `p` at `key`: a
/// configuration error (a panic when it is accepted or refused otherwise).
fn refused(m: &Mesh, f: SetUp, key: &str, p: &str) -> String {
    let Err(e) = sim(m, f) else {
        panic!("{key} = {p:?} was accepted")
    };
    let msg = e.to_string();
    assert!(matches!(e, PhysicsError::Config(_)), "{msg}");
    msg
}

/// Predicates that, spliced into rule text as they used to be, closed the guard and defined
/// rules of their own (the first two made a valid file: the old code built the simulation
/// with the extra rule `evil`). Each is refused at the column of its first token after the
/// expression.
const EVIL: [(&str, u32); 5] = [
    (
        "x < 1e-9 } compute { v.fixed = true } } rule evil { left { v : <1,2,3> hook } where { true",
        10,
    ),
    (
        "true } compute { v.fixed = true } } rule evil(d: vec3) { left { v : <1,2,3> hook } where { true",
        6,
    ),
    (
        "x < 0 } rule evil { left { v : <1,2,3> hook } compute { v.fixed = true } } rule x {",
        7,
    ),
    ("x < 0 rule", 7),
    ("x < 0  x > 1", 8),
];

/// Rule syntax in a fixed, prescribed, region or cut predicate is a bad predicate naming the
/// configuration's key, the predicate and the column; no simulation is built.
#[test]
fn rule_syntax_in_a_predicate_is_refused_as_a_bad_predicate() {
    let m = mesh();
    for (p, col) in EVIL {
        let cases: [(&str, &str, SetUp); 4] = [
            (
                "fixed-vertex",
                "fixed[1]",
                Box::new(|c: &mut Config| c.fixed = vec!["x < 1e-9".into(), p.into()]),
            ),
            (
                "prescribed-displacement",
                "prescribed[0]",
                Box::new(|c: &mut Config| c.prescribed = vec![(p.into(), [0.0, 0.1, 0.0])]),
            ),
            (
                "material-region",
                "regions[0]",
                Box::new(|c: &mut Config| {
                    c.regions = vec![MaterialRegion {
                        predicate: p.into(),
                        young: Some(2e6),
                        ..Default::default()
                    }];
                }),
            ),
            ("cut", "events[0]", cut_where(p)),
        ];
        for (kind, key, f) in cases {
            let msg = refused(&m, f, key, p);
            let head = format!("bad {kind} predicate {key} {p:?}: column {col}: ");
            assert!(msg.contains(&head), "expected {head:?} in: {msg}");
            assert!(msg.contains("expected the end of the expression"), "{msg}");
        }
    }
}

/// A line break in a predicate does not hide rule syntax: the place is line and column.
#[test]
fn a_multi_line_predicate_is_refused_at_its_line_and_column() {
    let p = "x < 1e-9\n}\nrule evil { left { v : <1,2,3> hook } where { true";
    let e = sim(&mesh(), |c| c.fixed = vec![p.into()]).unwrap_err();
    assert!(
        e.to_string()
            .contains("bad fixed-vertex predicate fixed[0] \"x < 1e-9\\n}\\nrule evil"),
        "{e}"
    );
    assert!(
        e.to_string()
            .contains(": line 2, column 1: expected the end"),
        "{e}"
    );
}

/// Checker errors in a predicate (an unknown variable, a guard that is not a bool) keep
/// naming the key, now with the column in the predicate; a bad region predicate names the
/// region (it used to be reported as "bad fixed-vertex predicate in []").
#[test]
fn checker_errors_name_the_key_and_the_column() {
    let m = mesh();
    let e = sim(&m, |c| c.fixed = vec!["x < 1 && w > 2".into()]).unwrap_err();
    assert!(
        e.to_string().contains(
            "bad fixed-vertex predicate fixed[0] \"x < 1 && w > 2\": column 10: unknown variable or parameter 'w'"
        ),
        "{e}"
    );
    let e = sim(&m, |c| c.fixed = vec!["x + 1".into()]).unwrap_err();
    assert!(
        e.to_string()
            .contains("bad fixed-vertex predicate fixed[0] \"x + 1\": column 3: ")
            && e.to_string().contains("expected bool"),
        "{e}"
    );
    let e = sim(&m, |c| {
        c.regions = vec![MaterialRegion {
            predicate: "x >".into(),
            density: Some(1.0),
            ..Default::default()
        }];
    })
    .unwrap_err();
    assert!(
        e.to_string().contains(
            "bad material-region predicate regions[0] \"x >\": column 4: expected an expression"
        ),
        "{e}"
    );
    let e = sim(&m, |c| c.fixed = vec![String::new()]).unwrap_err();
    assert!(
        e.to_string()
            .contains("bad fixed-vertex predicate fixed[0] \"\": column 1: expected an expression"),
        "{e}"
    );
}

/// An embedding read or an aggregate (rule syntax) in a predicate is refused at its column,
/// saying what a predicate reads: before, `v.position` in a cut's predicate said `unknown
/// embedding 'position'` (the rule built around it leaking through) and `x(v.position) >
/// 0.5` was accepted as a fixed vertex's predicate, reading the node of that rule.
#[test]
fn embedding_reads_in_a_predicate_say_what_a_predicate_reads() {
    let m = mesh();
    let reads = [
        ("v.position", 1, "'v.position' reads an embedding"),
        ("x(v.position) > 0.5", 3, "'v.position' reads an embedding"),
        (
            "let r = v.rest\nx(r) > 0.5",
            9,
            "'v.rest' reads an embedding",
        ),
        (
            "sum<0>(v.rest) > 0",
            1,
            "'sum<0>(v.rest)' aggregates over an orbit",
        ),
    ];
    let says = "is rule syntax, not allowed here: a predicate (or a load's expression) reads only the coordinates x, y, z of the point it is evaluated at";
    for (p, col, what) in reads {
        let cases: [(&str, &str, SetUp); 2] = [
            (
                "fixed-vertex",
                "fixed[0]",
                Box::new(|c: &mut Config| c.fixed = vec![p.into()]),
            ),
            ("cut", "events[0]", cut_where(p)),
        ];
        for (kind, key, f) in cases {
            let msg = refused(&m, f, key, p);
            let head = format!("bad {kind} predicate {key} {p:?}: column {col}: {what}");
            assert!(msg.contains(&head), "expected {head:?} in: {msg}");
            assert!(msg.contains(says), "{msg}");
            assert!(!msg.contains("unknown embedding"), "{msg}");
        }
        match eval_predicate("p", p, &[[0.0; 3]]) {
            Err(PointsError::Refused(d)) => assert!(d[0].message.contains(says), "{d:?}"),
            other => panic!("{other:?}"),
        }
    }
    match eval_expression("e", "x + v.rest", &[[0.0; 3]]) {
        Err(PointsError::Refused(d)) => {
            assert!(
                d[0].message.contains("'v.rest' reads an embedding"),
                "{d:?}"
            );
            assert_eq!(d[0].pos.col, 5);
        }
        other => panic!("{other:?}"),
    }
}

/// A chain of 4000 additions is refused with the parser's depth error, not a stack overflow.
#[test]
fn a_long_operator_chain_gets_the_depth_error() {
    let p = format!("{} < 0", vec!["x"; 4000].join(" + "));
    let e = sim(&mesh(), |c| c.fixed = vec![p]).unwrap_err();
    assert!(
        e.to_string()
            .contains("bad fixed-vertex predicate fixed[0]"),
        "{e}"
    );
    assert!(
        e.to_string()
            .contains("expression nested too deeply: depth 257, the limit is 256"),
        "{e}"
    );
}

/// Ordinary predicates (with `&&`, `||`, `!`, functions, leading `let` bindings, blocks and
/// `if`) select exactly the vertices the same predicate selects evaluated here on the rest
/// positions; a prescribed vertex sits at rest + d exactly; a region sets the density of
/// exactly the elements whose rest centroid satisfies it (total mass, to 1e-12 relative).
#[test]
fn ordinary_predicates_select_what_they_say() {
    type Pred = fn([f64; 3]) -> bool;
    let cases: [(&str, Pred); 5] = [
        ("x < 1e-9", |p| p[0] < 1e-9),
        ("x < 0.6 && !(y > 0.4) || z > 0.9", |p| {
            p[0] < 0.6 && p[1] <= 0.4 || p[2] > 0.9
        }),
        ("let r = x - 1.0  abs(r) < 0.3", |p| {
            (p[0] - 1.0).abs() < 0.3
        }),
        ("if y > 0.5 { x < 0.6 } else { x > 1.4 }", |p| {
            if p[1] > 0.5 {
                p[0] < 0.6
            } else {
                p[0] > 1.4
            }
        }),
        ("{ let s = x + y  s <= 1.0 }", |p| p[0] + p[1] <= 1.0),
    ];
    let m = mesh();
    for (text, f) in cases {
        let s = sim(&m, |c| c.fixed = vec![text.into()]).unwrap();
        let rest = s.vertex_vec3("rest").unwrap();
        let fixed = s.vertex_bool("fixed").unwrap();
        let expected: Vec<bool> = rest.iter().map(|&p| f(p)).collect();
        assert!(
            expected.iter().any(|&b| b) && !expected.iter().all(|&b| b),
            "{text}"
        );
        assert_eq!(fixed, expected, "{text}");

        let d = [0.01, -0.02, 0.03];
        let s = sim(&m, |c| c.prescribed = vec![(text.into(), d)]).unwrap();
        let (x, fixed) = (
            s.vertex_vec3("position").unwrap(),
            s.vertex_bool("fixed").unwrap(),
        );
        assert_eq!(fixed, expected, "{text}");
        for i in 0..x.len() {
            let want: Vec<f64> = (0..3)
                .map(|a| rest[i][a] + if expected[i] { d[a] } else { 0.0 })
                .collect();
            assert_eq!(x[i].to_vec(), want, "{text}: vertex {i}");
        }
    }
    // regions: the bar is 2 x 1 x 1 at density 1000 (mass 2000); no tetrahedron straddles
    // x = 1 (a plane of grid nodes), so the predicate on the centroid selects exactly the left
    // half: mass 1000 * 1 (right) + 2000 * 1 (left) = 3000
    let base = sim(&m, |_| {}).unwrap().total_mass().unwrap();
    let half = sim(&m, |c| {
        c.regions = vec![MaterialRegion {
            predicate: "let c = x  c < 1.0".into(),
            density: Some(2000.0),
            ..Default::default()
        }];
    })
    .unwrap()
    .total_mass()
    .unwrap();
    assert!((base - 2000.0).abs() < 1e-9 * base, "{base}");
    assert!((half - 3000.0).abs() < 1e-9 * half, "{half}");
}

/// A predicate cut still runs as before: at its time it opens the faces whose centroid
/// satisfies it, separating the halves of the bar.
#[test]
fn a_predicate_cut_still_cuts() {
    let mut s = sim(&mesh(), |c| {
        c.gravity = [0.0, 0.0, 0.0];
        c.events = vec![TimedEvent {
            time: 0.0,
            cut: Cut::Where("abs(x - 1.0) < 1e-9".into()),
        }];
    })
    .unwrap();
    let before = s.vertex_vec3("rest").unwrap().len();
    s.step().unwrap();
    let after = s.vertex_vec3("rest").unwrap().len();
    // the 3 x 3 vertices of the plane x = 1 are doubled
    assert_eq!(after, before + 9, "{before} -> {after}");
}

/// A predicate cut whose predicate fails when evaluated at its time (`clamp` with crossed
/// bounds) fails the step naming the predicate and the face it failed at (a current
/// centroid), not the rule built around it and a dart.
#[test]
fn a_predicate_cut_failing_at_a_face_names_the_predicate_and_the_face() {
    let mut s = sim(&mesh(), |c| {
        c.gravity = [0.0, 0.0, 0.0];
        c.events = vec![TimedEvent {
            time: 0.0,
            cut: Cut::Where("clamp(x, 1.0, 0.0) > 0.0".into()),
        }];
    })
    .unwrap();
    let e = s.step().unwrap_err().to_string();
    assert!(
        e.contains("cut predicate 'clamp(x, 1.0, 0.0) > 0.0'"),
        "{e}"
    );
    assert!(
        e.contains("cannot be evaluated at the face whose centroid is ("),
        "{e}"
    );
    assert!(!e.contains("rule '") && !e.contains("dart"), "{e}");
}

/// `eval_predicate` selects at a list of points exactly the vertices a fixed-vertex
/// predicate holds (the same kernel), and `eval_expression` gives the rule language's
/// values: `%` keeps the dividend's sign (Rust's `%`: -0.75 % 0.5 is -0.25), an integer value
/// is converted, a comparison with NaN is false, a quotient of two integers is refused, and
/// a built-in refusing its argument names the point. Exact: the values are single
/// operations on coordinates that are multiples of 0.5.
#[test]
fn predicates_and_expressions_at_points_are_the_kernels() {
    let pred = "(x - 0.75) % 0.5 < 0.0 || sqrt(y - 0.75) > 0.0";
    let s = sim(&mesh(), |c| c.fixed = vec![pred.into()]).unwrap();
    let rest = s.vertex_vec3("rest").unwrap();
    let got = eval_predicate("p", pred, &rest).unwrap();
    let fixed = s.vertex_bool("fixed").unwrap();
    assert_eq!(got, fixed);
    assert!(got.iter().any(|b| *b) && !got.iter().all(|b| *b));
    let pts = [[-3.0, 0.0, 0.0], [0.5, 1.0, 0.0]];
    assert_eq!(
        eval_expression("e", "x % 2.0", &pts).unwrap(),
        vec![-1.0, 0.5]
    );
    assert_eq!(eval_expression("e", "3", &pts).unwrap(), vec![3.0, 3.0]);
    assert_eq!(
        eval_predicate("p", "sqrt(x) > -1.0", &pts).unwrap(),
        vec![false, true]
    );
    match eval_expression("e", "1 / 2", &pts) {
        Err(PointsError::Refused(d)) => assert_eq!(d[0].condition, "integer-division"),
        other => panic!("{other:?}"),
    }
    match eval_expression("e", "log(x)", &pts) {
        Err(PointsError::At(0, why)) => assert!(why.contains("not a finite number"), "{why}"),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        eval_predicate("p", "x < 0.0", &[]).unwrap(),
        Vec::<bool>::new()
    );
}

/// The smallest i64 can be written (`-9223372036854775808`: its magnitude is no i64, so the
/// minus and the literal are read together), and is that integer: converted, it is -2^63
/// exactly, and one less overflows (the evaluator's checked arithmetic). The literal alone,
/// or after a binary minus, is refused at its position.
#[test]
fn the_smallest_integer_can_be_written() {
    let pts = [[0.0, 0.0, 0.0]];
    assert_eq!(
        eval_expression("e", "to_f64(-9223372036854775808)", &pts).unwrap(),
        vec![-(2f64.powi(63))]
    );
    assert_eq!(
        eval_predicate("p", "-9223372036854775808 < -9223372036854775807", &pts).unwrap(),
        vec![true]
    );
    match eval_expression("e", "to_f64(-9223372036854775808 - 1)", &pts) {
        Err(PointsError::At(0, why)) => assert!(why.contains("overflow"), "{why}"),
        other => panic!("{other:?}"),
    }
    for (text, col) in [
        ("to_f64(9223372036854775808)", 8),
        ("to_f64(1 - 9223372036854775808)", 12),
    ] {
        match eval_expression("e", text, &pts) {
            Err(PointsError::Refused(d)) => {
                assert!(
                    d[0].message.contains("'9223372036854775808' is too large"),
                    "{}",
                    d[0].message
                );
                assert_eq!(d[0].pos.col, col, "{text}: {d:?}");
            }
            other => panic!("{text}: {other:?}"),
        }
    }
    match eval_expression("e", "to_f64(-9223372036854775809)", &pts) {
        Err(PointsError::Refused(d)) => {
            assert!(
                d[0].message.contains("'9223372036854775809' is too large"),
                "{d:?}"
            );
        }
        other => panic!("{other:?}"),
    }
}

/// A predicate that parses and checks but fails when evaluated (a built-in refusing its
/// argument: `clamp` with its bounds crossed) is quoted as the other messages about it quote
/// it (a scene finds its key by that), with the point it was evaluated at: a vertex's rest
/// position, or an element's rest centroid (a region's `&&` stops before the `clamp` at
/// x <= 0.1, so the centroid named is one beyond, not a corner at x = 0); not the rule built
/// around it and a dart. A value expression of another type than a number (a bool, a
/// vector) is refused saying which type it has.
#[test]
fn a_predicate_failing_at_a_vertex_names_its_key_and_the_vertex() {
    let bad = "clamp(x, 1.0, 0.0) > 0.0";
    for (set, quoted, place) in [
        (0, "fix predicate 'clamp", "the vertex at rest position ("),
        (
            1,
            "prescribed-displacement predicate 'clamp",
            "the vertex at rest position (",
        ),
        (
            2,
            "material region 'x > 0.1 && clamp",
            "the element whose rest centroid is (",
        ),
    ] {
        let e = sim(&mesh(), |c| match set {
            0 => c.fixed = vec![bad.into()],
            1 => c.prescribed = vec![(bad.into(), [0.0; 3])],
            _ => {
                c.regions = vec![MaterialRegion {
                    predicate: format!("x > 0.1 && {bad}"),
                    density: Some(2000.0),
                    young: None,
                    poisson: None,
                }];
            }
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains(quoted), "{e}");
        assert!(
            e.contains(&format!("cannot be evaluated at {place}")),
            "{e}"
        );
        assert!(e.contains("clamp"), "{e}");
        assert!(!e.contains("rule '") && !e.contains("dart"), "{e}");
        if set == 2 {
            // the centroid named has x > 0.1
            let x: f64 = e
                .split(place)
                .nth(1)
                .unwrap()
                .split(',')
                .next()
                .unwrap()
                .parse()
                .unwrap();
            assert!(x > 0.1, "{e}");
        }
    }
    for (text, ty) in [
        ("x < 0.5", "bool"),
        ("vec3(x, y, z)", "vec3"),
        ("true", "bool"),
    ] {
        match eval_expression("e", text, &[[0.0; 3]]) {
            Err(PointsError::Refused(d)) => {
                assert!(
                    d[0].message
                        .contains(&format!("has type {ty}, expected a number")),
                    "{d:?}"
                );
            }
            other => panic!("{text}: {other:?}"),
        }
    }
}

/// Two supports holding one vertex differently (a fix predicate and a prescribed
/// displacement, or two prescribed displacements) are refused naming both and the vertex's
/// rest position: the last one applied won silently (QA). Supports that agree (a zero
/// displacement on a fixed vertex, two equal displacements) are accepted.
#[test]
fn supports_holding_one_vertex_differently_are_refused() {
    let m = mesh();
    let d = [0.0, 0.0, 0.1];
    let e = sim(&m, |c| {
        c.fixed = vec!["x < 1e-9".into()];
        c.prescribed = vec![("x < 1e-9 && y < 1e-9".into(), d)];
    })
    .unwrap_err()
    .to_string();
    assert!(
        e.contains(
            "prescribed-displacement predicate 'x < 1e-9 && y < 1e-9' moves the vertex at rest"
        ) && e.contains("which fix predicate 'x < 1e-9' holds too"),
        "{e}"
    );
    let e = sim(&m, |c| {
        c.prescribed = vec![("x < 1e-9".into(), d), ("y < 1e-9".into(), [0.1, 0.0, 0.0])];
    })
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("prescribed-displacement predicate 'y < 1e-9' moves")
            && e.contains("which prescribed-displacement predicate 'x < 1e-9' holds too"),
        "{e}"
    );
    // agreeing supports
    sim(&m, |c| {
        c.fixed = vec!["x < 1e-9".into()];
        c.prescribed = vec![("x < 1e-9".into(), [0.0; 3])];
    })
    .unwrap();
    sim(&m, |c| {
        c.prescribed = vec![("x < 1e-9".into(), d), ("y < 1e-9".into(), d)];
    })
    .unwrap();
    // a rest coordinate -0.0 held in place and at a zero displacement: rest + 0 is +0.0,
    // another bit pattern but the same position (refused before: bits were compared)
    let mut neg = mesh();
    for p in &mut neg.points {
        for x in p.iter_mut() {
            if *x == 0.0 {
                *x = -0.0;
            }
        }
    }
    sim(&neg, |c| {
        c.fixed = vec!["x < 1e-9".into()];
        c.prescribed = vec![("x < 1e-9".into(), [0.0; 3])];
    })
    .unwrap();
}
