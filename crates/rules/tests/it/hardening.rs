//! Issue 13 (hardening): any rule text gives a rule set or diagnostics, never a crash.
//!
//! A long chain of one binary operator (`1.0 + 1.0 + ...`) used to build a tree as deep as the
//! chain is long, and every later pass (checker, compiler, interpreter, drop) walked it
//! recursively: a few thousand terms overflowed the stack. The parser now refuses any
//! expression deeper than [`MAX_DEPTH`] (a chain of n terms is depth n) with a `syntax`
//! diagnostic at the operator that goes too deep, and everything at the limit works.
//! Numbers in messages are the ones written (an orbit label 256 is not reported as 255).
//! The fuzz test mutates the shipped rule files (with long chains among the mutations) and
//! asserts no panic and a rule set or an error diagnostic, within a few seconds.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::{Duration, Instant};

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{GMap, Value};
use topomech_rules::parser::MAX_DEPTH;
use topomech_rules::{load_sources, load_sources_for, Diagnostic, Params, RuleSet, Severity};

const LIMIT: usize = MAX_DEPTH as usize;

const HEAD: &str = "dimension 2
embedding position : vec3 on <1,2>
embedding weight   : f64  on <0,1>
embedding tally    : i64  on <0,1>
";

fn load(src: &str) -> Result<RuleSet, Vec<Diagnostic>> {
    load_sources(&[("chain.tmr".into(), src.into())]).map(|(r, _)| r)
}

/// `term op term op ...` with `n` terms.
fn chain(term: &str, op: &str, n: usize) -> String {
    vec![term; n].join(&format!(" {op} "))
}

fn errors(d: &[Diagnostic]) -> Vec<&Diagnostic> {
    d.iter().filter(|d| d.severity == Severity::Error).collect()
}

fn quad_grid() -> GMap {
    build(
        &grid([2, 2], [1.0, 1.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap()
    .0
}

/// The `syntax` error of a too-deep expression, at line `line`.
fn assert_too_deep(src: &str, line: u32) -> Diagnostic {
    let Err(d) = load(src) else {
        panic!("accepted");
    };
    let e = errors(&d);
    assert_eq!(e.len(), 1, "{d:?}");
    let e = e[0].clone();
    assert_eq!(e.condition, "syntax", "{e:?}");
    assert_eq!(e.pos.line, line, "{e:?}");
    assert!(
        e.message.contains(&format!(
            "expression nested too deeply: depth {}, the limit is {LIMIT}",
            LIMIT + 1
        )),
        "{}",
        e.message
    );
    e
}

#[test]
fn long_operator_chain_in_compute_is_a_syntax_error_not_a_stack_overflow() {
    for op in ["+", "-", "*", "/", "%", "&&", "||", "==", "<"] {
        for n in [LIMIT + 1, 3000, 200_000] {
            let src = format!(
                "{HEAD}rule r {{\n  left {{ n0 : <0,1> hook }}\n  compute {{ n0.weight = {} }}\n}}\n",
                chain("1.0", op, n)
            );
            let e = assert_too_deep(&src, 7);
            // the operator that makes the chain LIMIT + 1 deep: after LIMIT terms
            let prefix = format!("  compute {{ n0.weight = {} ", chain("1.0", op, LIMIT));
            assert_eq!(e.pos.col as usize, prefix.chars().count() + 1, "{op} {n}");
        }
    }
}

#[test]
fn long_operator_chain_in_a_guard_or_let_is_a_syntax_error() {
    let n = 5000;
    for body in [
        format!("where {} > 0.0", chain("n0.weight", "+", n)),
        format!("where {{ let x = 1.0  {} }}", chain("x", "+", n)),
        format!(
            "compute {{ let t = {}  n0.weight = t }}",
            chain("2.5", "*", n)
        ),
        format!(
            "compute {{ n0.weight = max(0.0, {}) }}",
            chain("n0.weight", "-", n)
        ),
        format!(
            "compute {{ n0.weight = if true {{ {} }} else {{ 0.0 }} }}",
            chain("1.0", "+", n)
        ),
    ] {
        let src = format!("{HEAD}rule r {{\n  left {{ n0 : <0,1> hook }}\n  {body}\n}}\n");
        assert_too_deep(&src, 7);
    }
}

#[test]
fn every_kind_of_nesting_counts_toward_the_limit() {
    let deep = LIMIT + 1;
    for e in [
        // parentheses, unary operators, else-if chains, blocks, calls: each level counts
        format!("{}1.0{}", "(".repeat(deep), ")".repeat(deep)),
        format!("{}1.0", "-".repeat(deep)),
        format!("{}0.0{}", "if false { 1.0 } else ".repeat(deep), "").replacen(
            "else 0.0",
            "else { 0.0 }",
            1,
        ),
        format!("{}1.0{}", "{ let a = 1.0  ".repeat(deep), " }".repeat(deep)),
        format!("{}1.0{}", "abs(".repeat(deep), ")".repeat(deep)),
        // a right-leaning tree: (1 - (1 - (1 - ...)))
        format!("{}1.0{}", "(1.0 - ".repeat(deep), ")".repeat(deep)),
        // thousands of them
        format!("{}1.0", "- ".repeat(100_000)),
        format!("{}1.0{}", "(".repeat(100_000), ")".repeat(100_000)),
    ] {
        let src = format!(
            "{HEAD}rule r {{\n  left {{ n0 : <0,1> hook }}\n  compute {{ n0.weight = {e} }}\n}}\n"
        );
        let Err(d) = load(&src) else {
            panic!("accepted");
        };
        let es = errors(&d);
        assert_eq!(es.len(), 1, "{d:?}");
        assert_eq!(es[0].condition, "syntax");
        assert!(
            es[0]
                .message
                .contains("expression nested too deeply: depth ")
                && es[0].message.contains(&format!("the limit is {LIMIT}")),
            "{}",
            es[0].message
        );
    }
}

/// At the limit, every pass (checker, compiled plan, interpreter) handles the deepest tree the
/// parser accepts, in a thread with a small stack (half of Rust's default).
#[test]
fn chains_at_the_limit_check_compile_and_run() {
    std::thread::Builder::new()
        .stack_size(1 << 20)
        .spawn(|| {
            let src = format!(
                "{HEAD}
rule weigh {{
  left {{ n0 : <0,1> hook }}
  where {} > 0.0
  compute {{ n0.weight = {} }}
}}
rule count_up {{
  left {{ n0 : <0,1> hook }}
  compute {{ n0.tally = {} }}
}}
rule nested {{
  left {{ n0 : <0,1> hook }}
  compute {{ n0.weight = {}0.5{} }}
}}
rule choose {{
  left {{ n0 : <0,1> hook }}
  compute {{ n0.weight = {}{{ 2 }} }}
}}
",
                chain("1.0", "+", LIMIT - 1), // the comparison adds one level
                chain("1.0", "+", LIMIT),
                // an integer embedding read: the interpreter (no compiled plan)
                chain("n0.tally", "+", LIMIT - 1) + " + 1",
                "(1.0 - ".repeat(LIMIT - 1),
                ")".repeat(LIMIT - 1),
                // an else-if chain with an integer last branch (promoted to a real)
                "if false { 1.0 } else ".repeat(LIMIT - 2),
            );
            let rules = load(&src).unwrap_or_else(|d| panic!("{d:?}"));
            let mut g = quad_grid();
            rules.prepare_named(&mut g, &["weight", "tally"]).unwrap();
            let report = rules
                .apply_everywhere(&mut g, "weigh", &Params::new())
                .unwrap();
            assert_eq!(report.matches, 4);
            let w = g.embedding_id("weight").unwrap();
            let d0 = g.darts().next().unwrap();
            assert_eq!(g.value(w, d0).unwrap(), Value::Real(vec![LIMIT as f64]));
            rules
                .apply_everywhere(&mut g, "count_up", &Params::new())
                .unwrap();
            let t = g.embedding_id("tally").unwrap();
            assert_eq!(g.value(t, d0).unwrap(), Value::Int(1));
            rules
                .apply_everywhere(&mut g, "nested", &Params::new())
                .unwrap();
            // 1 - (1 - (... - 0.5)) with LIMIT - 1 subtractions: 0.5 either way
            assert_eq!(g.value(w, d0).unwrap(), Value::Real(vec![0.5]));
            rules
                .apply_everywhere(&mut g, "choose", &Params::new())
                .unwrap();
            assert_eq!(g.value(w, d0).unwrap(), Value::Real(vec![2.0]));
            assert!(g.is_valid());
        })
        .unwrap()
        .join()
        .unwrap();
}

#[test]
fn orbit_labels_and_dimensions_are_reported_as_written() {
    let cases = [
        ("left { a : <0,256> hook }", "label 256 outside 0..=2"),
        (
            "left { a : <0,4294967296> hook }",
            "label 4294967296 outside 0..=2",
        ),
        (
            "left { a : <0,1> hook  b : <0,1>  a -256- b }",
            "arc a -256- b has label 256 outside 0..=2",
        ),
        (
            "left { a : <0,1> hook  b : <0,1>  a -4294967296- b }",
            "has label 4294967296 outside",
        ),
        (
            "left { a : <0,1> hook } compute { a.weight = sum<0,300>(a.weight) }",
            "dimension 300 outside 0..=2",
        ),
        (
            "left { a : <0,1> hook } compute { a.weight = sum<0,4294967296>(a.weight) }",
            "dimension 4294967296 outside 0..=2",
        ),
    ];
    for (body, want) in cases {
        let src = format!("{HEAD}rule r {{ {body} }}\n");
        let Err(d) = load(&src) else {
            panic!("accepted");
        };
        assert!(
            errors(&d).iter().any(|e| e.message.contains(want)
                && !e.message.contains("255")
                && !e.message.contains("4294967295")),
            "{want}: {d:?}"
        );
    }
    let d = load("dimension 2\nembedding w : f64 on <0,256>\n")
        .err()
        .unwrap();
    assert!(
        d.iter()
            .any(|e| e.message.contains("dimension 256 is outside")),
        "{d:?}"
    );
    let d = load("dimension 4294967298\n").err().unwrap();
    assert!(
        d.iter()
            .any(|e| e.message.contains("dimension 4294967298 is not supported")),
        "{d:?}"
    );
}

// ------------------------------------------------------------------------------------ fuzz

/// The shipped rule files: physics models and the modeling library.
const SHIPPED: &[(&str, &str)] = &[
    (
        "bending2d.tmr",
        include_str!("../../../physics/models/bending2d.tmr"),
    ),
    (
        "common2d.tmr",
        include_str!("../../../physics/models/common2d.tmr"),
    ),
    (
        "common3d.tmr",
        include_str!("../../../physics/models/common3d.tmr"),
    ),
    (
        "fem2d.tmr",
        include_str!("../../../physics/models/fem2d.tmr"),
    ),
    (
        "prelude.tmr",
        include_str!("../../../physics/models/prelude.tmr"),
    ),
    (
        "fem3d.tmr",
        include_str!("../../../physics/models/fem3d.tmr"),
    ),
    (
        "shear.tmr",
        include_str!("../../../physics/models/shear.tmr"),
    ),
    (
        "shear3d.tmr",
        include_str!("../../../physics/models/shear3d.tmr"),
    ),
    (
        "stretch.tmr",
        include_str!("../../../physics/models/stretch.tmr"),
    ),
    (
        "topology.tmr",
        include_str!("../../../physics/models/topology.tmr"),
    ),
    ("glue.tmr", include_str!("../../../physics/models/glue.tmr")),
    (
        "hyperelastic3d.tmr",
        include_str!("../../../physics/models/hyperelastic3d.tmr"),
    ),
    (
        "topology2d.tmr",
        include_str!("../../../physics/models/topology2d.tmr"),
    ),
    (
        "topology3d.tmr",
        include_str!("../../../physics/models/topology3d.tmr"),
    ),
    (
        "modeling2d.tmr",
        include_str!("../../library/modeling2d.tmr"),
    ),
    (
        "modeling3d.tmr",
        include_str!("../../library/modeling3d.tmr"),
    ),
];

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const PIECES: &[&str] = &[
    "+",
    "-",
    "*",
    "/",
    "%",
    "&&",
    "||",
    "==",
    "<",
    "<=",
    "!",
    "(",
    ")",
    "{",
    "}",
    "<",
    ">",
    ",",
    ";",
    ":",
    ".",
    "_",
    "=",
    "if",
    "else",
    "let",
    "rule",
    "left",
    "right",
    "compute",
    "where",
    "hook",
    "sum",
    "mean",
    "count",
    "0",
    "1",
    "3",
    "256",
    "4294967296",
    "1e308",
    "1.5",
    "99999999999999999999",
    "n0",
    "a",
    "position",
    "norm(",
    "true",
    "\u{e9}",
    "\t",
    "\n",
    "\u{0}",
];

/// One mutation of `s`, on character boundaries.
fn mutate(rng: &mut Rng, s: &str) -> String {
    let chars: Vec<char> = s.chars().collect();
    let at = rng.below(chars.len() + 1);
    let len = rng.below(40).min(chars.len() - at.min(chars.len()));
    let (head, tail): (String, String) =
        (chars[..at].iter().collect(), chars[at..].iter().collect());
    let rest: String = chars[at + len..].iter().collect();
    match rng.below(8) {
        0 => format!("{head}{rest}"),
        1 => format!("{head}{}{tail}", PIECES[rng.below(PIECES.len())]),
        2 => {
            let dup: String = chars[at..at + len].iter().collect();
            format!("{head}{dup}{dup}{tail}")
        }
        3 => {
            // a long operator chain, sometimes at, sometimes far beyond the limit
            let n = [LIMIT - 1, LIMIT, LIMIT + 1, 3000, 20_000][rng.below(5)];
            let op = ["+", "*", "-", "&&", "||", "<"][rng.below(6)];
            let c = chain("1.0", op, n);
            // mostly where an expression starts, so the chain gets past the parser
            let starts: Vec<usize> = s
                .match_indices("= ")
                .chain(s.match_indices("where "))
                .map(|(i, m)| s[..i + m.len()].chars().count())
                .collect();
            if starts.is_empty() || rng.below(4) == 0 {
                format!("{head} {c} {tail}")
            } else {
                let k = starts[rng.below(starts.len())];
                let h: String = chars[..k].iter().collect();
                let t: String = chars[k..].iter().collect();
                format!("{h}{c} {op} {t}")
            }
        }
        4 => {
            let n = [LIMIT, LIMIT + 1, 5000][rng.below(3)];
            let (o, c) = [("(", ")"), ("-", ""), ("!", ""), ("abs(", ")")][rng.below(4)];
            format!("{head}{}1.0{}{tail}", o.repeat(n), c.repeat(n))
        }
        5 => format!("{head}{}{rest}", rng.next() % 1000),
        6 => {
            // splice a piece of another shipped file
            let other = SHIPPED[rng.below(SHIPPED.len())].1;
            let oc: Vec<char> = other.chars().collect();
            let a = rng.below(oc.len());
            let b = (a + rng.below(200)).min(oc.len());
            format!("{head}{}{tail}", oc[a..b].iter().collect::<String>())
        }
        _ => {
            let c = char::from_u32(rng.below(0x250) as u32).unwrap_or('?');
            format!("{head}{c}{rest}")
        }
    }
}

fn check_no_panic(sources: &[(String, String)]) {
    let r = catch_unwind(AssertUnwindSafe(|| load_sources(sources)));
    let r = r.unwrap_or_else(|_| panic!("panic on {sources:?}"));
    if let Err(d) = r {
        let e = errors(&d);
        assert!(!e.is_empty(), "refused without an error: {d:?}");
        for d in e {
            assert!(
                !d.message.is_empty() && d.pos.line >= 1 && d.pos.col >= 1,
                "{d:?}"
            );
        }
    }
}

/// Mutated shipped rule files (with long operator chains and deep nesting among the
/// mutations) and random texts: no panic, no stack overflow, a rule set or an error
/// diagnostic. A fixed seed and case count, with a time cap so it stays a few seconds.
#[test]
fn random_and_mutated_rule_texts_never_crash() {
    let start = Instant::now();
    let cap = Duration::from_secs(4);
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for case in 0..500 {
        if start.elapsed() > cap {
            assert!(case >= 50, "only {case} cases in {cap:?}");
            break;
        }
        let (name, text) = SHIPPED[rng.below(SHIPPED.len())];
        let mut s = text.to_string();
        for _ in 0..=rng.below(4) {
            s = mutate(&mut rng, &s);
        }
        let dim = if name.contains("3d") { 3 } else { 2 };
        let common = SHIPPED
            .iter()
            .find(|(n, _)| *n == format!("common{dim}d.tmr"))
            .unwrap();
        check_no_panic(&[(name.into(), s.clone())]);
        check_no_panic(&[(common.0.into(), common.1.into()), (format!("x-{name}"), s)]);
        // pure noise over the pieces
        let noise: Vec<&str> = (0..rng.below(300))
            .map(|_| PIECES[rng.below(PIECES.len())])
            .collect();
        check_no_panic(&[("noise.tmr".into(), noise.join(" "))]);
    }
}

/// The shipped files themselves still load (the limit leaves them well inside).
#[test]
fn shipped_rule_files_still_load() {
    for dim in [2, 3] {
        let mut sources: Vec<(String, String)> = SHIPPED
            .iter()
            .filter(|(n, _)| {
                // the files of this dimension, and those serving both (no 2d/3d in the name)
                let both = !n.contains("2d") && !n.contains("3d");
                (n.contains(&format!("{dim}d")) || both) && !n.starts_with("modeling")
            })
            .map(|(n, t)| ((*n).to_string(), (*t).to_string()))
            .collect();
        sources.sort();
        let (_, warnings) = load_sources_for(dim, &sources).unwrap_or_else(|d| panic!("{d:?}"));
        let (n, t) = SHIPPED
            .iter()
            .find(|(n, _)| *n == format!("modeling{dim}d.tmr"))
            .unwrap();
        let (_, more) = load_sources(&[((*n).to_string(), (*t).to_string())])
            .unwrap_or_else(|d| panic!("{d:?}"));
        // no shipped rule writes one side of a symmetric pattern only
        let mirror: Vec<String> = warnings
            .iter()
            .chain(&more)
            .filter(|d| d.condition == "mirror-write")
            .map(ToString::to_string)
            .collect();
        assert!(mirror.is_empty(), "{mirror:#?}");
    }
}
