//! Native code for compiled plans ([`RuleSet::set_jit`]) against the plan evaluator, on random
//! rules: every operation the code generator emits (gathers of real and boolean columns, sums,
//! means and counts over orbits, arithmetic, products, comparisons, selections, the flat
//! built-ins and the helper calls for the others) gives the same bits, or the same failure,
//! with the native code as with the evaluator, on many chunks of rows and several threads.
// exact comparisons are the point here
#![allow(clippy::float_cmp)]

use proptest::prelude::*;
use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{ColumnMut, GMap};
use topomech_rules::{load_sources, Params, RuleSet, Val};

const HEADER: &str = "dimension 2
embedding position : vec3 on <1,2>
embedding velocity : vec3 on <1,2>
embedding fmass : f64 on <0,1>
embedding fvel : vec3 on <0,1>
embedding fflag : bool on <0,1>
embedding out_s : f64 on <0,1>
embedding out_v : vec3 on <0,1>
embedding out_m : mat3 on <0,1>

rule init_v {
  left { v : <1,2> hook }
  compute {
    let p = v.position
    v.velocity = vec3(sin(7.0 * x(p) + 1.0), cos(5.0 * y(p)), x(p) * y(p) - 0.25)
  }
}

rule init_f {
  left { f : <0,1> hook }
  compute {
    let c = mean<0,1>(f.position)
    f.fvel = vec3(cos(3.0 * x(c)), sin(2.0 * y(c) + 0.5), x(c) - y(c))
    f.fmass = 1.0 + 0.5 * sin(3.0 * x(c) + 2.0 * y(c))
    f.fflag = x(c) > y(c)
  }
}
";

/// A small deterministic generator of random typed expressions.
struct Gen(u64);

impl Gen {
    fn next(&mut self) -> u64 {
        // xorshift64*
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn pick(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn konst(&mut self) -> String {
        let c = [0.0, -0.0, 0.5, 1.0, -2.0, 3.25, 1e-3, 7.0];
        format!("{:?}", c[self.pick(c.len() as u64) as usize])
    }

    fn s(&mut self, d: u32) -> String {
        let leaf = d == 0 || self.pick(4) == 0;
        if leaf {
            return match self.pick(7) {
                0 => "f.fmass".into(),
                1 => "p".into(),
                2 => "to_f64(count<0,1>(f.position))".into(),
                3 => format!("x({})", self.v(0)),
                4 => "z(q)".into(),
                _ => self.konst(),
            };
        }
        let d = d - 1;
        match self.pick(22) {
            0 => format!("({} + {})", self.s(d), self.s(d)),
            1 => format!("({} - {})", self.s(d), self.s(d)),
            2 => format!("({} * {})", self.s(d), self.s(d)),
            3 => format!("({} / {})", self.s(d), self.s(d)),
            4 => format!("({} % {})", self.s(d), self.s(d)),
            5 => format!("(-{})", self.s(d)),
            6 => format!("dot({}, {})", self.v(d), self.v(d)),
            7 => format!("norm({})", self.v(d)),
            8 => format!("norm2({})", self.v(d)),
            9 => format!("y({})", self.v(d)),
            10 => format!(
                "if {} {{ {} }} else {{ {} }}",
                self.b(d),
                self.s(d),
                self.s(d)
            ),
            11 => {
                let f = ["sqrt", "abs", "sign", "floor", "ceil", "exp", "sin", "atan"];
                format!("{}({})", f[self.pick(f.len() as u64) as usize], self.s(d))
            }
            12 => {
                let f = ["min", "max", "atan2", "pow"];
                format!("{}({}, {})", f[self.pick(4) as usize], self.s(d), self.s(d))
            }
            13 => format!("clamp({}, {}, {})", self.s(d), self.s(d), self.s(d)),
            14 => format!("trace({})", self.m(d)),
            15 => format!("x({} * {})", self.m(d), self.v(d)),
            16 => format!("angle({}, {})", self.v(d), self.v(d)),
            17 => {
                let (i, j) = (self.pick(3), self.pick(3));
                format!("get({}, {i}, {j})", self.m(d))
            }
            _ => format!("({} * {} + {})", self.s(d), self.s(d), self.s(d)),
        }
    }

    fn v(&mut self, d: u32) -> String {
        let leaf = d == 0 || self.pick(4) == 0;
        if leaf {
            return match self.pick(7) {
                0 => "f.fvel".into(),
                1 => "sum<0,1>(f.position)".into(),
                2 => "mean<0,1>(f.position)".into(),
                3 => "sum<0,1>(f.velocity)".into(),
                4 => "q".into(),
                5 => "mean<0,1>(f.velocity)".into(),
                _ => format!("vec3({}, {}, {})", self.konst(), self.konst(), self.konst()),
            };
        }
        let d = d - 1;
        match self.pick(14) {
            0 => format!("({} + {})", self.v(d), self.v(d)),
            1 => format!("({} - {})", self.v(d), self.v(d)),
            2 => format!("({} * {})", self.s(d), self.v(d)),
            3 => format!("({} * {})", self.v(d), self.s(d)),
            4 => format!("({} / {})", self.v(d), self.s(d)),
            5 => format!("(-{})", self.v(d)),
            6 => format!("cross({}, {})", self.v(d), self.v(d)),
            7 => format!("normalize({})", self.v(d)),
            8 => format!("vec3({}, {}, {})", self.s(d), self.s(d), self.s(d)),
            9 => format!("({} * {})", self.m(d), self.v(d)),
            11 => {
                let (f, k) = (["col3", "row3"][self.pick(2) as usize], self.pick(3));
                format!("{f}({}, {k})", self.m(d))
            }
            10 => format!(
                "if {} {{ {} }} else {{ {} }}",
                self.b(d),
                self.v(d),
                self.v(d)
            ),
            _ => format!("({} + {} * {})", self.v(d), self.s(d), self.v(d)),
        }
    }

    fn m(&mut self, d: u32) -> String {
        if d == 0 {
            return format!("outer({}, {})", self.v(0), self.v(0));
        }
        let d = d - 1;
        match self.pick(6) {
            0 => format!("outer({}, {})", self.v(d), self.v(d)),
            1 => format!("transpose({})", self.m(d)),
            2 => format!("({} * {})", self.m(d), self.m(d)),
            3 => format!("sym({})", self.m(d)),
            4 => format!("({} + {})", self.m(d), self.m(d)),
            _ => format!(
                "mat_from_cols3({}, {}, {})",
                self.v(d),
                self.v(d),
                self.v(d)
            ),
        }
    }

    fn b(&mut self, d: u32) -> String {
        if d == 0 {
            return if self.pick(2) == 0 {
                "f.fflag".into()
            } else {
                format!("({} < {})", self.s(0), self.s(0))
            };
        }
        let d = d - 1;
        match self.pick(9) {
            0 => format!("({} < {})", self.s(d), self.s(d)),
            1 => format!("({} >= {})", self.s(d), self.s(d)),
            2 => format!("({} == {})", self.v(d), self.v(d)),
            3 => format!("({} != {})", self.s(d), self.s(d)),
            4 => format!("({} && {})", self.b(d), self.b(d)),
            5 => format!("({} || {})", self.b(d), self.b(d)),
            6 => format!("!{}", self.b(d)),
            7 => "f.fflag".into(),
            _ => format!("is_finite({})", self.s(d)),
        }
    }
}

fn source(seed: u64) -> String {
    let mut g = Gen(seed | 1);
    let (s, v, m) = (g.s(4), g.v(4), g.m(1));
    format!(
        "{HEADER}
rule r(p: f64, q: vec3) {{
  left {{ f : <0,1> hook }}
  compute {{
    f.out_s = {s}
    f.out_v = {v}
    f.out_m = {m}
  }}
}}
"
    )
}

type Outcome = Result<Vec<u64>, String>;

fn bits(g: &GMap) -> Vec<u64> {
    column_bits(g, &["out_s", "out_v", "out_m"])
}

/// The bits of every value of the real embeddings `names` of `g`, column after column (for
/// comparisons bit for bit; `sub_orbit_aggregates` uses it too).
pub(crate) fn column_bits(g: &GMap, names: &[&str]) -> Vec<u64> {
    names
        .iter()
        .flat_map(|n| {
            let id = g.require(n).unwrap();
            g.embedding(id)
                .real_column()
                .unwrap()
                .iter()
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Applies the rule (twice, the second run reusing the plan and its code) with native code or
/// the evaluator: the values written, or the failure; and whether the plan ran native code.
fn run(
    rules: &mut RuleSet,
    g0: &GMap,
    jit: bool,
    threads: usize,
) -> (Outcome, Vec<(String, bool)>) {
    rules.set_jit(jit);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut g = g0.clone();
        let mut out: Result<(), String> = Ok(());
        for (k, p) in [0.75, -1.5].into_iter().enumerate() {
            let params: Params = [
                ("p".to_string(), Val::F(p)),
                ("q".to_string(), Val::V3([0.25, -1.0 + k as f64, 2.0])),
            ]
            .into();
            if let Err(e) = rules.apply_everywhere(&mut g, "r", &params) {
                out = Err(e.to_string());
                break;
            }
        }
        (out.map(|()| bits(&g)), rules.plan_native())
    })
}

fn mesh() -> GMap {
    build(
        &grid([24, 18], [1.0, 0.8], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap()
    .0
}

/// The source of the rule `r(p: f64, q: vec3)` on faces with the compute body `body`, after
/// the header's embeddings and init rules.
fn rule_r_source(body: &str) -> String {
    format!(
        "{HEADER}
rule r(p: f64, q: vec3) {{
  left {{ f : <0,1> hook }}
  compute {{
    {body}
  }}
}}
"
    )
}

/// The rule of [`rule_r_source`], loaded, and a copy of `g0` prepared and initialised for it.
fn rule_r(body: &str, g0: &GMap) -> (RuleSet, GMap) {
    let (rules, _) = load_sources(&[("r.tmr".to_string(), rule_r_source(body))]).unwrap();
    let g = initialised(&rules, g0);
    (rules, g)
}

/// A copy of `g0` prepared for `rules` and initialised by the header's init rules.
fn initialised(rules: &RuleSet, g0: &GMap) -> GMap {
    let mut g = g0.clone();
    rules.prepare(&mut g).unwrap();
    for init in ["init_v", "init_f"] {
        rules
            .apply_everywhere(&mut g, init, &Params::new())
            .unwrap();
    }
    g
}

fn check(seed: u64, g0: &GMap) -> Result<(), TestCaseError> {
    let src = source(seed);
    let (mut rules, _) = load_sources(&[("jit.tmr".to_string(), src.clone())])
        .map_err(|e| TestCaseError::fail(format!("{e:?}\n{src}")))?;
    let g = initialised(&rules, g0);
    let (slow, _) = run(&mut rules, &g, false, 1);
    for threads in [1, 3] {
        let (fast, native) = run(&mut rules, &g, true, threads);
        // every rule of this grammar compiles to a plan, and its plan to native code
        let compiled = rules.plan_kinds().iter().any(|k| k.0 == "r" && k.1);
        prop_assert!(
            compiled,
            "r is not compiled: {:?}\n{}",
            rules.plan_kinds(),
            src
        );
        prop_assert!(
            native.iter().any(|k| k.0 == "r" && k.1),
            "the plan of r did not run native code: {native:?}\n{src}"
        );
        match (&slow, &fast) {
            (Ok(a), Ok(b)) => prop_assert!(a == b, "values differ ({threads} threads)\n{src}"),
            (Err(a), Err(b)) => prop_assert_eq!(a, b, "\n{}", src),
            _ => prop_assert!(false, "{slow:?} vs {fast:?} ({threads} threads)\n{src}"),
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    #[test]
    fn random_rules_run_natively_give_the_evaluators_bits(seed in any::<u64>()) {
        thread_local!(static G: GMap = mesh());
        G.with(|g| check(seed, g))?;
    }
}

/// A fixed selection of the operations, so that each one is exercised whatever the random
/// draw, including a helper call that fails (`clamp` with its bounds reversed: the native
/// code returns a nonzero code and the interpreter reports the error) and a non-finite value
/// (caught by the plan's output scan).
#[test]
fn each_operation_runs_natively_with_the_same_bits() {
    let g0 = mesh();
    let cases = [
        "f.out_s = dot(f.fvel, sum<0,1>(f.velocity)) + norm(f.fvel) * norm2(mean<0,1>(f.position))
    f.out_v = cross(f.fvel, sum<0,1>(f.velocity)) + normalize(mean<0,1>(f.velocity)) / f.fmass
    f.out_m = outer(f.fvel, q) * transpose(mat_from_cols3(q, f.fvel, mean<0,1>(f.position)))",
        "f.out_s = if f.fflag && !(p < f.fmass) || f.fmass == 1.0 { sqrt(abs(p)) % 0.3 } else { sign(p) * floor(f.fmass) + ceil(-f.fmass) + exp(p) + min(p, f.fmass) + atan2(p, f.fmass) }
    f.out_v = if f.fvel == q { -q } else { vec3(to_f64(count<0,1>(f.position)), trace(outer(q, q)), x(mean<0,1>(f.velocity))) }
    f.out_m = sym(outer(f.fvel, q) * outer(q, sum<0,1>(f.position)))",
        // `norm` on both of its paths: direct, and scaled (a branch of its own in the native
        // code) for squares that overflow, underflow, or a zero vector; the values are finite,
        // so the plan must not fall back to the interpreter (checked below)
        "f.out_s = norm(f.fvel) + norm(1e200 * f.fvel) * 1e-200 + norm(1e-170 * f.fvel) * 1e170 + norm(0.0 * f.fvel)
    f.out_v = vec3(norm(1e300 * f.fvel) * 1e-300, norm(vec2(x(f.fvel), 1e-320)), norm(mean<0,1>(f.position)))
    f.out_m = outer(q, q)",
        "f.out_s = clamp(f.fmass, 2.0, 1.0)
    f.out_v = q
    f.out_m = outer(q, q)",
        "f.out_s = 1.0 / (f.fmass - f.fmass)
    f.out_v = q
    f.out_m = outer(q, q)",
    ];
    for (k, body) in cases.iter().enumerate() {
        let (mut rules, g) = rule_r(body, &g0);
        let before = topomech_rules::jit::compiled_count();
        let (slow, _) = run(&mut rules, &g, false, 1);
        let fell_back = rules.plan_fallbacks();
        let (fast, native) = run(&mut rules, &g, true, 3);
        if slow.is_ok() {
            // the native code computed these values itself
            assert_eq!(rules.plan_fallbacks(), fell_back, "case {k}");
        }
        assert!(topomech_rules::jit::compiled_count() > before, "case {k}");
        assert_eq!(native, vec![("r".to_string(), true)], "case {k}");
        assert_eq!(slow, fast, "case {k}");
        assert_eq!(slow.is_err(), k >= 3, "case {k}: {slow:?}");
    }
}

/// Read-only gathers packed in row order (`Plan::pack_read_only`): a column the rule reads
/// but does not write, at scattered slots (a rule on darts reading a vertex embedding), is
/// copied at the plan's second run (its write count held still since the first) and read
/// from the copy after, which the plan's memory shows; a write to it from outside (here
/// every vertex's velocity scaled through `column_mut`) is seen at the next run; and every
/// run gives the evaluator's bits. Fails if the copy is kept after the write, or taken for a
/// column that changes between runs.
#[test]
fn a_read_only_column_packed_in_row_order_sees_later_writes() {
    let src = format!(
        "{HEADER}
embedding out_d : vec3 on <>

rule r {{
  left {{ d : <> hook }}
  compute {{ d.out_d = 2.0 * d.velocity + vec3(1.0, 0.0, 0.0) }}
}}
"
    );
    let outcome = |jit: bool| {
        let (mut rules, _) = load_sources(&[("pack.tmr".to_string(), src.clone())]).unwrap();
        rules.set_jit(jit);
        let mut g = mesh();
        rules.prepare(&mut g).unwrap();
        for init in ["init_v", "init_f"] {
            rules
                .apply_everywhere(&mut g, init, &Params::new())
                .unwrap();
        }
        let velocity = g.require("velocity").unwrap();
        let mut runs = Vec::new();
        let mut bytes = Vec::new();
        for k in 0..5 {
            if k == 3 {
                let ColumnMut::Real(v) = g.column_mut(velocity).unwrap() else {
                    panic!("a column of reals")
                };
                for x in v.iter_mut() {
                    *x = 3.0 * *x - 0.5;
                }
            }
            rules.apply_everywhere(&mut g, "r", &Params::new()).unwrap();
            bytes.push(rules.plan_bytes());
            let out = g.require("out_d").unwrap();
            let values = g.embedding(out).real_column().unwrap();
            runs.push(values.iter().map(|x| x.to_bits()).collect::<Vec<u64>>());
        }
        (runs, bytes)
    };
    let (slow, _) = outcome(false);
    let (fast, bytes) = outcome(true);
    assert_ne!(slow[2], slow[3], "the write changed the values");
    assert_eq!(slow, fast, "the evaluator's bits at every run");
    let darts = mesh().darts().count();
    assert!(
        bytes[1] >= bytes[0] + 24 * darts,
        "packed at the second run: {bytes:?} ({darts} darts)"
    );
}

/// `get`, `row2`/`row3` and `col2`/`col3` at constant indices compile to moves of the
/// matrix's entries (no call to the built-in): the interpreter's bits with the evaluator and
/// with native code. At an index outside the matrix known only when the rule runs (a count),
/// the built-in's own error from all three; at a constant one, the checker's refusal, at the
/// call, with the built-in's message.
#[test]
fn selections_at_constant_indices_give_the_interpreters_bits_and_errors() {
    let g0 = mesh();
    let ok = "let m = outer(f.fvel, q) + mat_from_cols3(q, mean<0,1>(f.position), f.fvel)
    let m2 = mat2(get(m, 0, 0), get(m, 2, 1), p, get(f.fvel, 1, 0))
    f.out_s = get(m, 1, 2) + get(f.fvel, 2, 0) + x(row2(m2, 1)) + y(col2(m2, 0))
    f.out_v = col3(m, 0) + 2.0 * row3(m, 2) - col3(transpose(m), 1)
    f.out_m = mat_from_cols3(col3(m, 2), row3(m, 1), col3(m, 1))";
    // a quad face has 4 vertices: index 4 lies outside a mat3
    let at_run_time = [
        "f.out_s = get(outer(f.fvel, q), count<0,1>(f.position), 0)\n    f.out_v = q\n    f.out_m = outer(q, q)",
        "f.out_s = p\n    f.out_v = col3(outer(f.fvel, q), count<0,1>(f.position))\n    f.out_m = outer(q, q)",
    ];
    for (k, body) in std::iter::once(ok).chain(at_run_time).enumerate() {
        let (mut rules, g) = rule_r(body, &g0);
        rules.set_compiled(false);
        let (interpreted, _) = run(&mut rules, &g, false, 1);
        rules.set_compiled(true);
        let (evaluated, _) = run(&mut rules, &g, false, 1);
        let (native, plans) = run(&mut rules, &g, true, 3);
        assert_eq!(interpreted.is_ok(), k == 0, "case {k}: {interpreted:?}");
        assert_eq!(evaluated, interpreted, "case {k}: evaluator");
        assert_eq!(native, interpreted, "case {k}: native code");
        if k == 0 {
            assert_eq!(plans, vec![("r".to_string(), true)], "case {k}");
        }
    }
    for (call, col, says) in [
        (
            "get(outer(f.fvel, q), 3, 0)",
            15,
            "get: entry (3, 0) outside a mat3",
        ),
        ("get(f.fvel, 0, 1)", 15, "get: entry (0, 1) outside a vec3"),
        (
            "col3(outer(f.fvel, q), -1)",
            15,
            "col3: column -1 out of range 0..3",
        ),
        (
            "row3(outer(f.fvel, q), 3)",
            15,
            "row3: row 3 out of range 0..3",
        ),
    ] {
        let body = format!("f.out_s = x(vec3(1.0, 1.0, 1.0) * 0.0) + z(vec3(0.0, 0.0, 0.0))\n    f.out_v = q\n    f.out_m = outer(q, q)\n    let bad = {call}");
        let Err(diags) = load_sources(&[("bad.tmr".to_string(), rule_r_source(&body))]) else {
            panic!("{call}: the checker accepts it");
        };
        let line = HEADER.lines().count() as u32 + 8;
        assert!(
            diags.iter().any(|d| d.condition == "type"
                && d.message.contains(says)
                && (d.pos.line, d.pos.col) == (line, col)),
            "{call}: {diags:?}"
        );
    }
}

/// The facade wires the Cranelift backend into every rule set a user builds through it: one
/// loaded with `load_sources`, and one built with `RuleSet::new` on rules checked through
/// `topomech_rules::check` (as the physics tests and benches build theirs); both run native
/// code at a plan's first run, and give the same bits as the evaluator.
#[test]
fn rule_sets_built_through_the_facade_get_the_native_backend() {
    let src = "dimension 2
embedding position : vec3 on <1,2>
embedding out : vec3 on <1,2>
rule r {
  left { v : <1,2> hook }
  compute { v.out = cross(v.position, vec3(0.5, -1.0, 2.0)) + v.position }
}
";
    let sources = [("t.tmr".to_string(), src.to_string())];
    let (checked, diags) = topomech_rules::check::check_sources(&sources);
    let by_new = RuleSet::new(checked.unwrap_or_else(|| panic!("{diags:?}")));
    let (loaded, _) = load_sources(&sources).unwrap();
    let (g0, _) = build(
        &grid([5, 4], [1.0, 1.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    let run = |mut rules: RuleSet, jit: bool| {
        assert!(rules.has_backend());
        rules.set_jit(jit);
        let mut g = g0.clone();
        rules.prepare(&mut g).unwrap();
        rules.apply_everywhere(&mut g, "r", &Params::new()).unwrap();
        let id = g.require("out").unwrap();
        let bits: Vec<u64> = g
            .embedding(id)
            .real_column()
            .unwrap()
            .iter()
            .map(|x| x.to_bits())
            .collect();
        (bits, rules.plan_native())
    };
    let (slow, _) = run(by_new.clone(), false);
    for rules in [by_new, loaded] {
        let (fast, native) = run(rules, true);
        assert_eq!(native, vec![("r".to_string(), true)]);
        assert_eq!(fast, slow);
    }
}
