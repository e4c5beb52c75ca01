//! Building a simulation: the rules of its models and the glue of a step (accumulation,
//! fixed and prescribed vertices, material regions, ground), and the set-up they run.

use topomech_gmap::{ColumnMut, ColumnRef, Dart, GMap, OrbitType, Value};
use topomech_rules::value::BinOp;
use topomech_rules::{ast, build, parser, ApplyError, Params, RuleSet, Ty, Val};

use crate::*;

/// Why a ground plane is refused with the static integrator.
const STATIC_GROUND: &str = "ground: the static integrator does not model contact with the ground (it would balance the body as if the plane were not there); hold the vertices the ground supports (fixed or prescribed), or use implicit_euler, which puts vertices that go below the plane back onto it";

/// The glue of a step that reads no user input: the ground rule, shipped as a rule file that
/// serves both dimensions (`dimension 2 3`).
fn glue_source() -> (String, String) {
    (
        "glue.tmr".to_string(),
        include_str!("../models/glue.tmr").to_string(),
    )
}

/// The embeddings the init rules of a model write (by name, each once).
fn init_writes(rules: &RuleSet, def: &RunModel) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for (rule, _) in &def.init {
        let Ok(r) = rules.rule(rule) else { continue };
        for name in topomech_rules::model::written_by(r, rules.embeddings()) {
            if !out.iter().any(|n| n == name) {
                out.push(name.to_string());
            }
        }
    }
    out
}

/// The bits of the NaN that marks the values of an embedding no init rule has written yet
/// (a quiet NaN with a payload no arithmetic produces).
const MARKER: u64 = 0x7ff8_7a3d_c0de_0001;

/// The embeddings the init rules of a model read (by name, each once): the rules' reads,
/// aggregates and guards.
fn init_reads(rules: &RuleSet, def: &RunModel) -> Vec<String> {
    use topomech_rules::check::{visit, TExpr, TStmt};
    let walk = |e: &TExpr, out: &mut Vec<usize>| {
        visit(e, &mut |x| match x {
            TExpr::Read { emb, .. } => out.push(*emb),
            TExpr::Agg { emb, .. } => out.extend(emb.iter().copied()),
            _ => {}
        });
    };
    let embs = rules.embeddings();
    let mut ids: Vec<usize> = Vec::new();
    for (rule, _) in &def.init {
        let Ok(r) = rules.rule(rule) else { continue };
        for st in &r.program {
            match st {
                TStmt::Let(_, v) | TStmt::Write { value: v, .. } => walk(v, &mut ids),
            }
        }
        if let Some(guard) = &r.guard {
            walk(guard, &mut ids);
        }
    }
    let mut out: Vec<String> = Vec::new();
    for i in ids {
        if let Some(e) = embs.get(i) {
            if !out.contains(&e.name) {
                out.push(e.name.clone());
            }
        }
    }
    out
}

/// How many distinct orbits of type `o` the darts of `darts` lie in (each orbit walked once).
fn distinct_orbits(g: &GMap, darts: &[Dart], o: OrbitType) -> usize {
    let mut marks = topomech_gmap::Marks::with_capacity(g.capacity());
    darts
        .iter()
        .filter(|&&d| {
            // a dart of an orbit walked before is marked already
            let fresh = g.is_alive(d) && !marks.is_marked(d);
            if fresh {
                g.visit_orbit(d, o, &mut marks, |_| {});
            }
            fresh
        })
        .count()
}

/// Every value of an embedding's column, bit for bit (empty for one the map lacks).
fn column_bits(g: &GMap, name: &str) -> Vec<u64> {
    let Some(id) = g.embedding_id(name) else {
        return Vec::new();
    };
    match g.embedding(id).column() {
        ColumnRef::Real(v) => v.iter().map(|x| x.to_bits()).collect(),
        ColumnRef::Int(v) => v.iter().map(|&x| x as u64).collect(),
        ColumnRef::Bool(v) => v.iter().map(|&b| u64::from(b)).collect(),
    }
}

/// The label of the built file holding the accumulation rules.
const ACCUMULATION: &str = "accumulation (built from the models' force embeddings)";

/// What kind of predicate a built glue file holds, for its error messages: the prefix of
/// its label (the configuration's key) and how the message names it.
const PREDICATE_KINDS: [(&str, &str); 4] = [
    ("fixed[", "fixed-vertex"),
    ("prescribed[", "prescribed-displacement"),
    ("regions[", "material-region"),
    ("events[", "cut"),
];

/// The glue of a step that reads the configuration, built as syntax trees (never as text,
/// so a predicate is only ever one expression): the accumulation rules summing the given
/// force and Jacobian-vector-product embeddings into `force` and `df`, and one rule per
/// fixed predicate (`fix_k`), prescribed displacement (`prescribe_k(d: vec3)`), predicate
/// cut (`cut_where_k`) and material region (`region_k`). Each predicate's rule is its own
/// file, labelled by its key (`fixed[0]`, `prescribed[0]`, `events[0]`, `regions[0]`), so
/// that a diagnostic names the key and the line and column in the predicate.
///
/// `glue` is the parsed shipped glue file, whose `dimension` every built file copies.
/// Errors: a predicate that is not one expression ([`build::parse_expression`]), or a
/// force name that is not an identifier, as a [`PhysicsError`] naming it.
pub(crate) fn glue_files(
    dim: usize,
    glue: &ast::File,
    forces: &[&str],
    jvp: &[&str],
    cfg: &Config,
) -> Result<Vec<(String, ast::File)>, PhysicsError> {
    let file = |rules: Vec<ast::RuleDecl>| build::file(glue, rules);
    // the vertex orbit of both dimensions: label 3 is dropped on a 2-map
    let v_orbit: &[u64] = &[1, 2, 3];
    let vertex = || build::graph(vec![build::node("v", v_orbit, true)]);
    let mut out = Vec::new();

    // accumulation: force = sum of the force embeddings + f_ext; df = sum of the jvp outputs
    let mut acc = Vec::new();
    for (rule, target, parts) in [
        ("accumulate", "force", forces),
        ("accumulate_jvp", "df", jvp),
    ] {
        let zero = build::call(
            "vec3",
            vec![build::real(0.0), build::real(0.0), build::real(0.0)],
        );
        let mut sum = zero;
        for f in parts {
            if !build::is_identifier(f) {
                return Err(PhysicsError::Model(format!(
                    "force embedding name '{f}' is not an identifier"
                )));
            }
            sum = build::binary(BinOp::Add, sum, build::sum(v_orbit, "v", f));
        }
        if rule == "accumulate" {
            // the external loads: constant, so nothing in the Jacobian
            sum = build::binary(BinOp::Add, sum, build::read("v", "f_ext"));
        }
        let mut r = build::rule(rule, vertex());
        r.compute = vec![build::write("v", target, sum)];
        acc.push(r);
    }
    out.push((ACCUMULATION.to_string(), file(acc)));

    for (k, p) in cfg.fixed.iter().enumerate() {
        let label = format!("fixed[{k}]");
        let mut r = build::rule(&format!("fix_{k}"), vertex());
        r.guard = Some(glue_guard(&label, p, vec![], &build::read("v", "rest"))?);
        r.compute = vec![build::write("v", "fixed", build::boolean(true))];
        out.push((label, file(vec![r])));
    }
    for (k, (p, _)) in cfg.prescribed.iter().enumerate() {
        let label = format!("prescribed[{k}]");
        let mut r = build::rule(&format!("prescribe_{k}"), vertex());
        r.params = vec![build::param("d", "vec3")];
        r.guard = Some(glue_guard(&label, p, vec![], &build::read("v", "rest"))?);
        r.compute = vec![
            build::write("v", "fixed", build::boolean(true)),
            build::write(
                "v",
                "position",
                build::binary(BinOp::Add, build::read("v", "rest"), build::name("d")),
            ),
        ];
        out.push((label, file(vec![r])));
    }
    // a predicate cut opens the faces (3D) or edges (2D) between two elements whose shared
    // side's current centroid satisfies it
    let (side, arc): (&[u64], u64) = if dim == 3 { (&[0, 1], 3) } else { (&[0], 2) };
    for (k, e) in cfg.events.iter().enumerate() {
        if let Cut::Where(p) = &e.cut {
            let label = format!("events[{k}]");
            let mut left = build::graph(vec![
                build::node("a", side, true),
                build::node("b", side, false),
            ]);
            left.arcs.push(build::arc("a", arc, "b"));
            let right = build::graph(vec![
                build::node("a", side, false),
                build::node("b", side, false),
            ]);
            let mut r = build::rule(&format!("cut_where_{k}"), left);
            r.right = Some(right);
            r.guard = Some(glue_guard(
                &label,
                p,
                vec![("c", build::mean(side, "a", "position"))],
                &build::name("c"),
            )?);
            out.push((label, file(vec![r])));
        }
    }
    // a material region sets the element data where its rest centroid satisfies it
    let e_orbit: &[u64] = if dim == 3 { &[0, 1, 2] } else { &[0, 1] };
    for (k, reg) in cfg.regions.iter().enumerate() {
        let label = format!("regions[{k}]");
        let mut r = build::rule(
            &format!("region_{k}"),
            build::graph(vec![build::node("e", e_orbit, true)]),
        );
        for (name, val) in [
            ("density", reg.density),
            ("young", reg.young),
            ("poisson", reg.poisson),
        ] {
            if let Some(x) = val {
                r.compute.push(build::write("e", name, build::real(x)));
            }
        }
        r.guard = Some(glue_guard(
            &label,
            &reg.predicate,
            vec![("c", build::mean(e_orbit, "e", "rest"))],
            &build::name("c"),
        )?);
        out.push((label, file(vec![r])));
    }
    Ok(out)
}

/// The guard of a glue rule around a scene's predicate, `{ let <lets...>  let x = x(point)
/// let y = y(point)  let z = z(point)  <predicate> }`, at the predicate's position; the
/// predicate is parsed as one expression ([`build::parse_expression`]), `label` naming it in
/// the diagnostic.
fn predicate_guard(
    label: &str,
    text: &str,
    mut lets: Vec<(&'static str, ast::Expr)>,
    point: &ast::Expr,
) -> Result<ast::Expr, topomech_rules::Diagnostic> {
    let pred = build::parse_expression(label, text)?;
    if let Some(d) = embedding_read_refused(label, &pred) {
        return Err(d);
    }
    if let Some(d) = integer_division_refused(label, &pred) {
        return Err(d);
    }
    let pos = pred.pos;
    for c in ["x", "y", "z"] {
        lets.push((c, build::call(c, vec![point.clone()])));
    }
    let mut g = build::let_block(lets, pred);
    g.pos = pos;
    Ok(g)
}

/// What a predicate or a load expression may read, said in the refusal of anything else.
const PREDICATE_READS: &str = "a predicate (or a load's expression) reads only the coordinates x, y, z of the point it is evaluated at (a vertex's rest position, an element's rest centroid, a cut face's or edge's centroid) and its own 'let' names, with the rule language's operators and built-ins, e.g. x < 1e-9 && y > 0.5";

/// The refusal of an expression of `label` that reads an embedding (`v.position`) or
/// aggregates over an orbit (`sum<0>(v.rest)`): rule syntax, which a predicate does not
/// have. Before, `v.position` in a cut's `where` said `unknown embedding 'position'` (the
/// node and embeddings of the rule built around it leaking through) and `x(v.rest) > 0`
/// was accepted in a fixed vertex's.
fn embedding_read_refused(label: &str, e: &ast::Expr) -> Option<topomech_rules::Diagnostic> {
    embedding_read(e).map(|(at, what)| topomech_rules::Diagnostic {
        file: label.to_string(),
        pos: at,
        severity: topomech_rules::Severity::Error,
        condition: "name",
        message: format!("{what} is rule syntax, not allowed here: {PREDICATE_READS}"),
    })
}

/// The first embedding read or aggregate in `e`: where, and what it is (`'v.position'
/// reads an embedding`).
fn embedding_read(e: &ast::Expr) -> Option<(topomech_rules::ast::Pos, String)> {
    use ast::ExprKind as K;
    match &e.kind {
        K::Read { node, emb } => Some((e.pos, format!("'{node}.{emb}' reads an embedding, which"))),
        K::Aggregate {
            kind,
            orbit,
            node,
            emb,
        } => {
            let kind = match kind {
                ast::AggKind::Sum => "sum",
                ast::AggKind::Mean => "mean",
                ast::AggKind::Count => "count",
            };
            let orbit: Vec<String> = orbit.iter().map(u64::to_string).collect();
            let of = emb.as_ref().map_or(node.clone(), |m| format!("{node}.{m}"));
            Some((
                e.pos,
                format!(
                    "'{kind}<{}>({of})' aggregates over an orbit of the map, which",
                    orbit.join(",")
                ),
            ))
        }
        K::Binary(_, a, b) => embedding_read(a).or_else(|| embedding_read(b)),
        K::Unary(_, a) => embedding_read(a),
        K::If(c, a, b) => embedding_read(c)
            .or_else(|| embedding_read(a))
            .or_else(|| embedding_read(b)),
        K::Call { args, .. } => args.iter().find_map(embedding_read),
        K::Block(stmts, r) => stmts
            .iter()
            .find_map(|st| match st {
                ast::Stmt::Let { value, .. } | ast::Stmt::Write { value, .. } => {
                    embedding_read(value)
                }
            })
            .or_else(|| embedding_read(r)),
        _ => None,
    }
}

/// The refusal of an expression of `label` that divides an integer by an integer
/// ([`integer_division`]): the rule language divides integers as integers, so `x < 4/3`
/// would read `x < 1`.
fn integer_division_refused(label: &str, e: &ast::Expr) -> Option<topomech_rules::Diagnostic> {
    integer_division(e).map(|at| topomech_rules::Diagnostic {
        file: label.to_string(),
        pos: at,
        severity: topomech_rules::Severity::Error,
        condition: "integer-division",
        message: "a quotient of two integers is an integer in the rule language (4/3 is 1, 1/3 is 0): write a real literal, e.g. 4.0/3, for the real quotient".into(),
    })
}

/// Where `e` divides an integer by an integer, if it does anywhere: in a predicate on
/// coordinates that is a mistake (`x < 4/3` reads `x < 1`). An operand is an integer when
/// the rule language types it `i64` ([`expr_type`]: literals, `let` names bound to such,
/// arithmetic, and built-ins by their signatures, `clamp(4, 0, 9)`, `to_i64(x)`,
/// `select(c, 4, 5)`; the coordinates `x`, `y`, `z` are reals).
fn integer_division(e: &ast::Expr) -> Option<topomech_rules::ast::Pos> {
    integer_division_in(e, &mut Vec::new())
}

/// [`integer_division`] with the types of the `let` names bound so far (`env`, the last
/// binding of a name winning).
fn integer_division_in(
    e: &ast::Expr,
    env: &mut Vec<(String, Option<Ty>)>,
) -> Option<topomech_rules::ast::Pos> {
    use ast::ExprKind as K;
    match &e.kind {
        K::Binary(BinOp::Div, a, b)
            if expr_type(a, env) == Some(Ty::I64) && expr_type(b, env) == Some(Ty::I64) =>
        {
            Some(e.pos)
        }
        K::Binary(_, a, b) => integer_division_in(a, env).or_else(|| integer_division_in(b, env)),
        K::Unary(_, a) => integer_division_in(a, env),
        K::If(c, a, b) => integer_division_in(c, env)
            .or_else(|| integer_division_in(a, env))
            .or_else(|| integer_division_in(b, env)),
        K::Call { args, .. } => args.iter().find_map(|a| integer_division_in(a, env)),
        K::Block(stmts, r) => {
            let bound = env.len();
            let mut found = None;
            for st in stmts {
                if let ast::Stmt::Let { name, value, .. } = st {
                    found = found.or_else(|| integer_division_in(value, env));
                    let t = expr_type(value, env);
                    env.push((name.clone(), t));
                }
            }
            let out = found.or_else(|| integer_division_in(r, env));
            env.truncate(bound);
            out
        }
        _ => None,
    }
}

/// The type the rule language gives `e` in a predicate on coordinates, where it can tell
/// from the expression alone (`env`: the `let` names bound around it; `x`, `y`, `z` are
/// reals; operators and built-ins by [`binop_type`](topomech_rules::value::binop_type),
/// [`unop_type`](topomech_rules::value::unop_type) and
/// [`call_type`](topomech_rules::builtins::call_type)); `None` where it cannot (a read, an
/// aggregate, a type error, which the checker reports).
fn expr_type(e: &ast::Expr, env: &[(String, Option<Ty>)]) -> Option<Ty> {
    use ast::ExprKind as K;
    use topomech_rules::value::{binop_type, unop_type};
    match &e.kind {
        K::Int(_) => Some(Ty::I64),
        K::Real(_) => Some(Ty::F64),
        K::Bool(_) => Some(Ty::Bool),
        K::Name(n) => match env.iter().rev().find(|(m, _)| m == n) {
            Some((_, t)) => *t,
            None => ["x", "y", "z"].contains(&n.as_str()).then_some(Ty::F64),
        },
        K::Unary(op, a) => unop_type(*op, expr_type(a, env)?).ok(),
        K::Binary(op, a, b) => binop_type(*op, expr_type(a, env)?, expr_type(b, env)?).ok(),
        K::Call { name, args } => {
            let types: Option<Vec<Ty>> = args.iter().map(|a| expr_type(a, env)).collect();
            topomech_rules::builtins::call_type(name, &types?).ok()
        }
        K::If(_, a, b) => {
            let (ta, tb) = (expr_type(a, env)?, expr_type(b, env)?);
            (ta == tb).then_some(ta)
        }
        K::Block(stmts, r) => {
            let mut env = env.to_vec();
            for st in stmts {
                if let ast::Stmt::Let { name, value, .. } = st {
                    let t = expr_type(value, &env);
                    env.push((name.clone(), t));
                }
            }
            expr_type(r, &env)
        }
        _ => None,
    }
}

/// [`predicate_guard`], a refusal being the configuration error naming the key.
fn glue_guard(
    label: &str,
    text: &str,
    lets: Vec<(&'static str, ast::Expr)>,
    point: &ast::Expr,
) -> Result<ast::Expr, PhysicsError> {
    predicate_guard(label, text, lets, point).map_err(|d| bad_predicate(label, text, &[d]))
}

/// Checks a predicate on the rest position `x`, `y`, `z` exactly as a simulation builds and
/// checks a fixed vertex's (a 3D `fix` rule's guard): one expression of the rule language
/// ([`build::parse_expression`]), of type bool, reading only `x`, `y`, `z` and its own `let`
/// bindings. The same predicate is accepted for prescribed displacements, material regions
/// (on the element's centroid) and cuts (on the side's centroid).
///
/// Errors: every error diagnostic, its `file` being `label` and its line and column the place
/// in `text` (e.g. rule syntax after the expression: "expected the end of the expression").
pub fn check_predicate(label: &str, text: &str) -> Result<(), Vec<topomech_rules::Diagnostic>> {
    let r = fix_rule(label, text).map_err(|d| vec![d])?;
    load_points_rule(label, &r, "fixed : bool").map(|_| ())
}

/// The fixed-vertex rule around the predicate `text` (labelled `label`): on each vertex
/// orbit whose rest position satisfies it, `fixed` set. Errors: the text refused as one
/// expression ([`predicate_guard`]).
fn fix_rule(label: &str, text: &str) -> Result<ast::RuleDecl, topomech_rules::Diagnostic> {
    let guard = predicate_guard(label, text, vec![], &build::read("v", "rest"))?;
    let mut r = build::rule(
        "fix",
        build::graph(vec![build::node("v", &[1, 2, 3], true)]),
    );
    r.guard = Some(guard);
    r.compute = vec![build::write("v", "fixed", build::boolean(true))];
    Ok(r)
}

/// `d` without the prefix naming the internal rule (`rule 'fix': `) that [`eval_predicate`]
/// and [`eval_expression`] build around the text: the user wrote no rule.
fn without_rule(mut d: Vec<topomech_rules::Diagnostic>) -> Vec<topomech_rules::Diagnostic> {
    for x in &mut d {
        x.message = without_rule_name(&x.message).to_string();
    }
    d
}

/// A checker message without its leading `rule '<name>': `, the built rule's name, which
/// means nothing to the user.
fn without_rule_name(message: &str) -> &str {
    match message.strip_prefix("rule '") {
        Some(rest) => rest.split_once("': ").map_or(message, |x| x.1),
        None => message,
    }
}

/// What [`eval_predicate`] and [`eval_expression`] may answer instead of values.
#[derive(Debug)]
pub enum PointsError {
    /// The text is refused as [`check_predicate`] refuses it: every error diagnostic.
    Refused(Vec<topomech_rules::Diagnostic>),
    /// It could not be evaluated at a point (a built-in refusing its argument, an integer
    /// overflow): the point's index and the kernel's message.
    At(usize, String),
}

/// Evaluates the predicate `text` on the position `x`, `y`, `z` at each of `points` with the
/// kernel itself: it is checked as [`check_predicate`] checks it (one expression, of type
/// bool, reading `x`, `y`, `z` and its own `let` bindings, no quotient of two integers) and
/// evaluated as the guard of a fixed-vertex rule is (the same parser, checker and
/// evaluator, so `%`, comparisons, `let`, `if` and comments mean what they mean in a
/// `where` of a scene), on a map of one free dart per point holding it as `rest`.
/// `label` names the text in the diagnostics.
///
/// Errors: [`PointsError::Refused`] with the checker's diagnostics; [`PointsError::At`] for
/// a point where the evaluation fails.
pub fn eval_predicate(
    label: &str,
    text: &str,
    points: &[[f64; 3]],
) -> Result<Vec<bool>, PointsError> {
    let rules = compiled(true, label, text, || {
        let r = fix_rule(label, text).map_err(|d| PointsError::Refused(vec![d]))?;
        load_for_points(label, &r, "fixed : bool")
    })?;
    let (g, fixed) = on_points(&rules, "fix", "fixed", points)?;
    Ok((0..points.len())
        .map(|k| matches!(g.value(fixed, Dart(k as u32)), Ok(Value::Bool(true))))
        .collect())
}

/// Evaluates the number-valued expression `text` on `x`, `y`, `z` at each of `points` with
/// the kernel, as [`eval_predicate`] evaluates a predicate: one expression of the rule
/// language of type `f64` or `i64` (converted), reading `x`, `y`, `z` and its own `let`
/// bindings, no quotient of two integers (`1/2` is 0 in the rule language).
///
/// Errors: as [`eval_predicate`]'s.
pub fn eval_expression(
    label: &str,
    text: &str,
    points: &[[f64; 3]],
) -> Result<Vec<f64>, PointsError> {
    let rules = compiled(false, label, text, || expression_rules(label, text))?;
    let (g, id) = on_points(&rules, "value", "value", points)?;
    Ok((0..points.len())
        .map(|k| match g.value(id, Dart(k as u32)) {
            Ok(Value::Real(v)) => v.first().copied().unwrap_or(f64::NAN),
            _ => f64::NAN,
        })
        .collect())
}

/// The rules [`eval_expression`] runs for `text`: its value written to `value`, converted
/// to f64 when it is an integer; refused as that function says.
fn expression_rules(label: &str, text: &str) -> Result<RuleSet, PointsError> {
    let refused = |d| PointsError::Refused(vec![d]);
    let e = build::parse_expression(label, text).map_err(refused)?;
    if let Some(d) = embedding_read_refused(label, &e) {
        return Err(refused(d));
    }
    if let Some(d) = integer_division_refused(label, &e) {
        return Err(refused(d));
    }
    let pos = e.pos;
    let lets = ["x", "y", "z"]
        .into_iter()
        .map(|c| (c, build::call(c, vec![build::read("v", "rest")])))
        .collect();
    // `to_f64` of an integer, the value itself of a real: one rule each, the checker says
    // which type the expression has
    let mut value = build::let_block(lets, e);
    value.pos = pos;
    let attempt = |v: ast::Expr| {
        let mut r = build::rule(
            "value",
            build::graph(vec![build::node("v", &[1, 2, 3], true)]),
        );
        r.compute = vec![build::write("v", "value", v)];
        load_for_points(label, &r, "value : f64")
    };
    // the checker's type error for a value that is no f64: "... but the value has type T"
    let typed = |d: &[topomech_rules::Diagnostic]| {
        d.iter().find_map(|d| {
            (d.condition == "type")
                .then(|| {
                    d.message
                        .rsplit_once("but the value has type ")
                        .map(|x| x.1.to_string())
                })
                .flatten()
        })
    };
    match attempt(value.clone()) {
        Err(PointsError::Refused(first)) => match typed(&first).as_deref() {
            Some("i64") => attempt(build::call("to_f64", vec![value])),
            Some(ty) => Err(PointsError::Refused(vec![topomech_rules::Diagnostic {
                file: label.to_string(),
                pos,
                severity: topomech_rules::Severity::Error,
                condition: "type",
                message: format!(
                    "the expression has type {ty}, expected a number (f64, or i64, converted)"
                ),
            }])),
            None => Err(PointsError::Refused(first)),
        },
        other => other,
    }
}

/// The checked rules of one predicate or expression (`r`, writing the embedding declared
/// by `out`, e.g. `"fixed : bool"`, on `<1,2,3>`, reading `rest`), run by the evaluator
/// (no native code: each run is on a new map, whose plan native code would compile again).
/// Errors: the checker's diagnostics.
fn load_for_points(label: &str, r: &ast::RuleDecl, out: &str) -> Result<RuleSet, PointsError> {
    let mut rules =
        load_points_rule(label, r, out).map_err(|d| PointsError::Refused(without_rule(d)))?;
    rules.set_jit(false);
    Ok(rules)
}

/// Rule `r` (labelled `label`) loaded and checked with the declarations of the points' map:
/// `rest` and `out` (e.g. `"fixed : bool"`), vertex embeddings of a 3D map. Errors: every
/// error diagnostic, as the checker words it.
fn load_points_rule(
    label: &str,
    r: &ast::RuleDecl,
    out: &str,
) -> Result<RuleSet, Vec<topomech_rules::Diagnostic>> {
    let decls_text =
        format!("dimension 3\nembedding rest : vec3 on <1,2,3>\nembedding {out} on <1,2,3>\n");
    let decls = parser::parse(&decls_text).expect("static declarations parse");
    let f = build::file(&decls, vec![r.clone()]);
    build::load(
        &[("decls".into(), decls_text.clone())],
        vec![(label.to_string(), f)],
    )
    .map(|(rules, _)| rules)
    .map_err(|diags| {
        diags
            .into_iter()
            .filter(|d| d.severity == topomech_rules::Severity::Error)
            .collect()
    })
}

/// The checked rules of [`eval_predicate`] (`predicate`) or [`eval_expression`] for `text`
/// (labelled `label`), from a cache of the last few, or `build` and kept: a load's density
/// is evaluated face by face, a handful of points at a time, and checking the text each
/// time cost more than evaluating it. Refusals are not kept (they end the caller's work).
fn compiled(
    predicate: bool,
    label: &str,
    text: &str,
    build: impl FnOnce() -> Result<RuleSet, PointsError>,
) -> Result<std::sync::Arc<RuleSet>, PointsError> {
    type Cache = Vec<((bool, String, String), std::sync::Arc<RuleSet>)>;
    static CACHE: std::sync::Mutex<Cache> = std::sync::Mutex::new(Vec::new());
    const KEPT: usize = 16;
    let key = (predicate, label.to_string(), text.to_string());
    {
        let cache = CACHE
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, r)) = cache.iter().find(|(k, _)| *k == key) {
            return Ok(std::sync::Arc::clone(r));
        }
    }
    let rules = std::sync::Arc::new(build()?);
    let mut cache = CACHE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if cache.len() >= KEPT {
        cache.remove(0);
    }
    cache.push((key, std::sync::Arc::clone(&rules)));
    Ok(rules)
}

/// The map of one free dart per point (`rest` the point) after the rule `rule` of `rules`
/// was applied at every dart, and the id of the embedding `out` it writes. Errors: the rule
/// failing at a point (its index).
fn on_points(
    rules: &RuleSet,
    rule: &str,
    out: &str,
    points: &[[f64; 3]],
) -> Result<(GMap, topomech_gmap::EmbeddingId), PointsError> {
    let at = |e: String| PointsError::At(0, e);
    let mut g = GMap::new(3).map_err(|e| at(e.to_string()))?;
    if !points.is_empty() {
        g.add_darts(points.len());
    }
    rules.prepare(&mut g).map_err(|e| at(e.to_string()))?;
    let rest = g.require("rest").map_err(|e| at(e.to_string()))?;
    for (k, p) in points.iter().enumerate() {
        g.set_real(rest, Dart(k as u32), p)
            .map_err(|e| at(e.to_string()))?;
    }
    if !points.is_empty() {
        let applied = rules.apply_once(&mut g, rule, &Params::new());
        // the plan is of this map only: not kept
        rules.clear_plans();
        if let Err(e) = applied {
            // the dart of the failure is the point's index
            return Err(match e {
                ApplyError::Eval { dart, message, .. } => PointsError::At(dart.0 as usize, message),
                ApplyError::NonFinite { dart, value, .. } => PointsError::At(
                    dart.0 as usize,
                    format!("the value is {value}, not a finite number"),
                ),
                e => PointsError::At(0, e.to_string()),
            });
        }
    }
    let id = g.require(out).map_err(|e| at(e.to_string()))?;
    Ok((g, id))
}

/// The error for a refused predicate: `bad <kind> predicate <key> "<text>": <where>: <what>`,
/// one `<where>: <what>` per error diagnostic.
fn bad_predicate(label: &str, text: &str, diags: &[topomech_rules::Diagnostic]) -> PhysicsError {
    let kind = PREDICATE_KINDS
        .iter()
        .find(|(prefix, _)| label.starts_with(prefix))
        .map_or("glue", |k| k.1);
    let msgs: Vec<String> = diags
        .iter()
        .filter(|d| d.severity == topomech_rules::Severity::Error)
        .map(|d| {
            let at = if d.pos.line > 1 {
                format!("line {}, column {}", d.pos.line, d.pos.col)
            } else {
                format!("column {}", d.pos.col.max(1))
            };
            // the built rule's name means nothing to the user: the key names it
            let msg = without_rule_name(&d.message);
            format!("{at}: {msg}")
        })
        .collect();
    PhysicsError::Config(format!(
        "bad {kind} predicate {label} {text:?}: {}",
        msgs.join("; ")
    ))
}

/// Where a glue predicate is evaluated: at a vertex's rest position, at an element's rest
/// centroid, or at a face's (3D) or edge's (2D) current centroid.
#[derive(Clone, Copy)]
pub(crate) enum PredicateAt {
    Vertex,
    Element,
    Side,
}

/// Why `g` cannot be simulated as a closed mesh, if so: a dart free at a dimension below the
/// map's (a face whose boundary is open, `alpha_0` or `alpha_1` free, or in 3D a volume
/// whose boundary surface is open, `alpha_2` free). Such a map is a valid G-map, but its
/// elements are not: the volume and mass rules read a face's or a volume's orbit as closed,
/// so an open one got a wrong mass and its vertices a NaN velocity (QA). Names the dart and
/// the centroid of its element's positions.
fn open_cell(g: &GMap) -> Option<String> {
    let dim = g.dimension();
    let (d, i) = g
        .darts()
        .find_map(|d| (0..dim).find(|&i| g.is_free(i, d)).map(|i| (d, i)))?;
    let (what, elem) = match (dim, i) {
        (3, 2) => ("volume whose boundary surface is open", OrbitType::volume()),
        (3, _) => ("face whose boundary is open", OrbitType::volume()),
        _ => ("face whose boundary is open", OrbitType::face(2)),
    };
    // the mean of the element's distinct points (an open corner splits its vertex into two
    // orbits at one point: counted once)
    let mut points: Vec<[u64; 3]> = Vec::new();
    if let Some(id) = g.embedding_id("position") {
        let mut marks = topomech_gmap::Marks::with_capacity(g.capacity());
        g.visit_orbit(d, elem, &mut marks, |x| {
            let p = g.real(id, x);
            if let [a, b, c] = p {
                let key = [a.to_bits(), b.to_bits(), c.to_bits()];
                if !points.contains(&key) {
                    points.push(key);
                }
            }
        });
    }
    let at = if points.is_empty() {
        String::new()
    } else {
        let c = [0, 1, 2].map(|k| {
            points.iter().map(|q| f64::from_bits(q[k])).sum::<f64>() / points.len() as f64
        });
        format!(" (the element whose centroid is {c:?})")
    };
    Some(format!(
        "the map has a {what}: dart {} is free at alpha_{i}{at}; a simulation needs closed elements \
         (every alpha_0 and alpha_1{} linked): sew it, or build the map from a mesh",
        d.0,
        if dim == 3 { " and alpha_2" } else { "" }
    ))
}

/// Refuses a ground plane (`p`, unit normal `n`) with a free vertex of `g` (not `fixed`: a
/// held vertex is never projected) on its far side, by more than the larger of 1e-9 of the
/// free vertices' bounding-box diagonal and 64 ulps of the largest coordinate (of the
/// vertices and of `p`: the rounding of the plane's equation far from the origin). The first
/// step would put every such vertex back onto the plane at once, crushing the elements
/// between into it, with no error (QA: a box through the ground was flattened to volumes of
/// 1e-19 in one step). A body resting on the plane to rounding passes.
fn below_ground(g: &GMap, p: [f64; 3], n: [f64; 3]) -> Result<(), PhysicsError> {
    let Some(id) = g.embedding_id("position") else {
        return Ok(());
    };
    let e = g.embedding(id);
    let Some(col) = e.real_column().filter(|c| c.len() == 3 * e.n_slots()) else {
        return Ok(());
    };
    let fixed = g.embedding_id("fixed").map(|f| g.embedding(f));
    // the slots of free vertices in use (a slot a removed orbit released keeps its last
    // value)
    let mut used = vec![false; e.n_slots()];
    for d in g.darts() {
        let held = fixed.is_some_and(
            |f| matches!(f.column(), ColumnRef::Bool(b) if b.get(f.slot(d)) == Some(&true)),
        );
        if !held {
            used[e.slot(d)] = true;
        }
    }
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    let mut big = p.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut deepest: Option<(f64, [f64; 3])> = None;
    for (x, _) in col.chunks_exact(3).zip(&used).filter(|(_, u)| **u) {
        let x = [x[0], x[1], x[2]];
        for k in 0..3 {
            lo[k] = lo[k].min(x[k]);
            hi[k] = hi[k].max(x[k]);
            big = big.max(x[k].abs());
        }
        let d = (x[0] - p[0]) * n[0] + (x[1] - p[1]) * n[1] + (x[2] - p[2]) * n[2];
        if deepest.is_none_or(|(m, _)| d < m) {
            deepest = Some((d, x));
        }
    }
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let tol = (1e-9 * diag).max(64.0 * f64::EPSILON * big);
    // (+ 0.0: no "-0" in the message, from a normal opposite to gravity)
    let z = |v: [f64; 3]| [v[0] + 0.0, v[1] + 0.0, v[2] + 0.0];
    match deepest {
        Some((d, x)) if d < -tol => Err(PhysicsError::Config(format!(
            "ground: the free vertex at {:?} is {:?} below the plane through {:?} with normal \
             {:?}; a body must start on the side the normal points to (its first step would \
             put every free vertex below onto the plane at once, crushing the elements \
             between): move the body or the ground, or hold those vertices",
            z(x),
            -d,
            z(p),
            z(n)
        ))),
        _ => Ok(()),
    }
}

/// The mean of the distinct values of the vec3 embedding `name` over the orbit `orbit` of
/// `d` (what `mean` of the rule language gives); `None` where the map lacks it.
fn orbit_mean(g: &GMap, d: Dart, orbit: OrbitType, name: &str) -> Option<[f64; 3]> {
    let id = g.embedding_id(name)?;
    if !g.is_alive(d) {
        return None;
    }
    let e = g.embedding(id);
    let mut marks = topomech_gmap::Marks::with_capacity(g.capacity());
    let mut slots: Vec<usize> = Vec::new();
    let mut sum = [0.0; 3];
    g.visit_orbit(d, orbit, &mut marks, |x| {
        let s = e.slot(x);
        if !slots.contains(&s) {
            slots.push(s);
            let p = g.real(id, x);
            for k in 0..3 {
                sum[k] += p[k];
            }
        }
    });
    (!slots.is_empty()).then(|| sum.map(|v| v / slots.len() as f64))
}

/// A glue predicate's rule that failed when applied: an evaluation error (a built-in
/// refusing its argument, an integer overflow) becomes `<subject> '<text>' cannot be
/// evaluated at <where>: <why>`, `subject` as the other messages about it quote it (`fix
/// predicate`, `prescribed-displacement predicate`, `material region`, `cut predicate`: a
/// scene finds its key by that quote), `where` the point it was evaluated at, not the rule
/// built around it and a dart; other errors pass as they are.
pub(crate) fn predicate_failed(
    g: &GMap,
    subject: &str,
    text: &str,
    at: PredicateAt,
    e: ApplyError,
) -> PhysicsError {
    match e {
        ApplyError::Eval { dart, message, .. } => {
            let dim = g.dimension();
            let (what, point) = match at {
                PredicateAt::Vertex => (
                    "the vertex at rest position",
                    g.embedding_id("rest")
                        .filter(|_| g.is_alive(dart))
                        .map(|id| std::array::from_fn(|k| g.real(id, dart)[k])),
                ),
                PredicateAt::Element => (
                    "the element whose rest centroid is",
                    orbit_mean(
                        g,
                        dart,
                        if dim == 3 {
                            OrbitType::volume()
                        } else {
                            OrbitType::face(2)
                        },
                        "rest",
                    ),
                ),
                PredicateAt::Side => (
                    if dim == 3 {
                        "the face whose centroid is"
                    } else {
                        "the edge whose midpoint is"
                    },
                    orbit_mean(
                        g,
                        dart,
                        if dim == 3 {
                            OrbitType::face(3)
                        } else {
                            OrbitType::edge(2)
                        },
                        "position",
                    ),
                ),
            };
            let place = point.map_or_else(
                || "one of its points".to_string(),
                |p: [f64; 3]| format!("{what} ({}, {}, {})", p[0], p[1], p[2]),
            );
            PhysicsError::Config(format!(
                "{subject} '{text}' cannot be evaluated at {place}: {message}"
            ))
        }
        e => e.into(),
    }
}

/// An error of model `model`'s init rule `rule` at set-up, with the model, the rule's file
/// and, where the error names a dart, the element it lies in (by its rest centroid): the
/// rule's own message names only the dart.
fn model_init_failed(
    g: &GMap,
    rules: &RuleSet,
    model: &str,
    rule: &str,
    e: ApplyError,
) -> PhysicsError {
    let dart = match &e {
        ApplyError::Eval { dart, .. } | ApplyError::NonFinite { dart, .. } => Some(*dart),
        _ => None,
    };
    let Some(dart) = dart else {
        return e.into();
    };
    let file = rules
        .rule(rule)
        .map(|r| format!(" (in {})", r.file))
        .unwrap_or_default();
    let elem = if g.dimension() == 3 {
        OrbitType::volume()
    } else {
        OrbitType::face(2)
    };
    let place = orbit_mean(g, dart, elem, "rest").map_or_else(String::new, |p| {
        format!(
            " at the element whose rest centroid is ({}, {}, {})",
            p[0], p[1], p[2]
        )
    });
    PhysicsError::Model(format!(
        "model '{model}': its init rule '{rule}'{file} failed{place}: {e}"
    ))
}

/// The text of the predicate a glue label (`fixed[k]`, ...) names.
fn predicate_text(cfg: &Config, label: &str) -> String {
    let Some((key, rest)) = label.split_once('[') else {
        return String::new();
    };
    let k: usize = rest.trim_end_matches(']').parse().unwrap_or(usize::MAX);
    let text = match key {
        "fixed" => cfg.fixed.get(k).cloned(),
        "prescribed" => cfg.prescribed.get(k).map(|p| p.0.clone()),
        "regions" => cfg.regions.get(k).map(|r| r.predicate.clone()),
        "events" => cfg.events.get(k).and_then(|e| match &e.cut {
            Cut::Where(p) => Some(p.clone()),
            Cut::Plane { .. } => None,
        }),
        _ => None,
    };
    text.unwrap_or_default()
}

impl Simulation {
    /// Builds a simulation on `g` (it must have a `position` embedding): loads the rules of
    /// the models, computes rest state, masses and model parameters.
    pub fn new(mut g: GMap, cfg: Config) -> Result<Self, PhysicsError> {
        let dim = g.dimension();
        // the links every orbit walk relies on (two passes over the darts; the embeddings'
        // consistency is left to `GMap::validate`): a broken map would otherwise fail later
        // in some rule, with a message about that rule
        if let Some(v) = g.first_link_violation() {
            return Err(PhysicsError::Config(format!(
                "the map is not a valid G-map: {v} (GMap.violations() in Python, topomech info on its file, list every violation)"
            )));
        }
        if let Some(msg) = open_cell(&g) {
            return Err(PhysicsError::Config(msg));
        }
        if !(cfg.dt > 0.0 && cfg.dt.is_finite()) {
            return Err(PhysicsError::Config(format!(
                "dt must be positive, got {}",
                cfg.dt
            )));
        }
        if let Some(t) = cfg.tolerance {
            if !(MIN_TOLERANCE..1.0).contains(&t) {
                return Err(PhysicsError::Config(format!(
                    "integrator.tolerance must be a relative residual in [{MIN_TOLERANCE:e}, 1), got {t:e} (below {MIN_TOLERANCE:e} rounding in f64 arithmetic hides whether a solve reached it)"
                )));
            }
        }
        if cfg.max_iterations == Some(0) {
            return Err(PhysicsError::Config(
                "integrator.max_iterations must be at least 1, got 0".into(),
            ));
        }
        if !(cfg.density > 0.0 && cfg.density.is_finite()) {
            return Err(PhysicsError::Config(format!(
                "density must be positive, got {}",
                cfg.density
            )));
        }
        if cfg.models.is_empty() {
            return Err(PhysicsError::Model("no model given".into()));
        }
        // a model's rules and embeddings exist once on a map: listed twice, its force would
        // be summed twice with the last parameters for both
        for (k, m) in cfg.models.iter().enumerate() {
            if let Some(j) = cfg.models[..k].iter().position(|o| o.kind == m.kind) {
                return Err(PhysicsError::Model(format!(
                    "model '{}' is listed twice (models {j} and {k}): its rules and embeddings exist once per map, so give it once, with the parameters you want",
                    m.kind
                )));
            }
        }
        let mut sources = vec![
            (
                "prelude.tmr".to_string(),
                model_source("prelude", dim).expect("shipped").to_string(),
            ),
            (
                format!("common{dim}d.tmr"),
                model_source("common", dim).expect("shipped").to_string(),
            ),
            (
                "topology.tmr".to_string(),
                model_source("topology", 0).expect("shipped").to_string(),
            ),
            (
                format!("topology{dim}d.tmr"),
                model_source("topology", dim).expect("shipped").to_string(),
            ),
        ];
        if let Some(f) = cfg.fracture {
            if let Some(why) = threshold_problem(f.threshold) {
                return Err(PhysicsError::Config(why));
            }
            if f.criterion == Criterion::Stress {
                if dim != 3 {
                    return Err(PhysicsError::Config("the stress criterion of fracture needs tetrahedra (3D); surfaces tear by strain".into()));
                }
                sources.push((
                    "fem3d.tmr".into(),
                    model_source("fem", 3).expect("shipped").to_string(),
                ));
            }
        }
        for (k, b) in cfg.blades.iter().enumerate() {
            if let Some(why) = b.problem() {
                return Err(PhysicsError::Config(format!("blade {k}: {why}")));
            }
        }
        for e in &cfg.events {
            if !(e.time >= 0.0 && e.time.is_finite()) {
                return Err(PhysicsError::Config(format!(
                    "event time must be a finite time >= 0, got {}",
                    e.time
                )));
            }
        }
        for (name, text) in model_files(&cfg, dim)? {
            if !sources.iter().any(|s| s.0 == name) {
                sources.push((name, text));
            }
        }
        // the forces the glue sums, from the declarations as written (they are checked with
        // everything else below)
        let outputs: Vec<(Vec<String>, Vec<String>)> = cfg
            .models
            .iter()
            .map(|m| declared_outputs(&sources, &m.kind))
            .collect();
        // two models listing one force (or jvp output): their rules write one value (the
        // last writer's), which the accumulation would sum once per model
        for (k, (f, j)) in outputs.iter().enumerate() {
            for (i, (g, h)) in outputs[..k].iter().enumerate() {
                let shared = f
                    .iter()
                    .find(|x| g.contains(x))
                    .or_else(|| j.iter().find(|x| h.contains(x)));
                if let Some(name) = shared {
                    return Err(PhysicsError::Model(format!(
                        "models '{}' (model[{i}]) and '{}' (model[{k}]) both list the embedding '{name}' as a force or jvp output: their rules write one value (the last one's), which would be summed once per model; give each model its own",
                        cfg.models[i].kind, cfg.models[k].kind
                    )));
                }
            }
        }
        let forces: Vec<&str> = outputs
            .iter()
            .flat_map(|o| o.0.iter().map(String::as_str))
            .collect();
        let jvp: Vec<&str> = outputs
            .iter()
            .flat_map(|o| o.1.iter().map(String::as_str))
            .collect();
        // the glue: shipped where it reads no user input, built as syntax trees where it does
        let (glue_name, glue_text) = glue_source();
        let glue = parser::parse(&glue_text).map_err(|e| {
            PhysicsError::Config(format!(
                "{glue_name}:{}:{}: {}",
                e.pos.line, e.pos.col, e.message
            ))
        })?;
        let built = glue_files(dim, &glue, &forces, &jvp, &cfg)?;
        let labels: Vec<String> = built.iter().map(|(l, _)| l.clone()).collect();
        sources.push((glue_name, glue_text));
        let (rules, _warnings) = build::load(&sources, built).map_err(|diags| {
            // a refused predicate is the scene's fault: say which, and where in it
            let bad = diags.iter().find(|d| {
                d.severity == topomech_rules::Severity::Error
                    && d.file != ACCUMULATION
                    && labels.contains(&d.file)
            });
            match bad {
                Some(d) => {
                    let text = predicate_text(&cfg, &d.file);
                    let mine: Vec<_> = diags.iter().filter(|x| x.file == d.file).cloned().collect();
                    bad_predicate(&d.file, &text, &mine)
                }
                None => PhysicsError::Rules(diags),
            }
        })?;
        let mut defs = Vec::new();
        for m in &cfg.models {
            let decl = rules.model(&m.kind).ok_or_else(|| {
                PhysicsError::Model(format!("model '{}' is not declared in its file", m.kind))
            })?;
            if !decl.dimensions.contains(&dim) {
                return Err(PhysicsError::Model(format!(
                    "model '{}' needs a mesh of dimension {}, this one has dimension {dim}",
                    m.kind,
                    crate::model::dims_text(&decl.dimensions)
                )));
            }
            defs.push(RunModel::bind(decl, &m.params)?);
        }
        if matches!(
            cfg.integrator,
            Integrator::ImplicitEuler | Integrator::Static
        ) {
            if let Some(def) = defs.iter().find(|d| d.jvp.is_empty()) {
                return Err(PhysicsError::Model(format!(
                    "model '{}' has no Jacobian rules yet: use explicit_euler or symplectic_euler with it",
                    def.name
                )));
            }
        }
        if let Some(ground) = &cfg.ground {
            ground.plane(cfg.gravity)?;
            if cfg.integrator == Integrator::Static {
                return Err(PhysicsError::Config(STATIC_GROUND.into()));
            }
        }
        if g.embedding_id("position").is_none() {
            return Err(PhysicsError::Config(
                "the map has no 'position' embedding".into(),
            ));
        }
        // the data the simulation itself reads; each rule adds what it uses when it first runs
        rules.prepare_named(
            &mut g,
            &[
                "position", "rest", "velocity", "force", "fixed", "mass", "dx", "dv", "df",
                "vertex0", "face0", "f_ext",
            ],
        )?;
        mark_vertex0(&mut g)?;
        let none = Params::new();
        rules.apply_once(&mut g, "init_rest", &none)?;
        let material: Params = [
            ("density".to_string(), Val::F(cfg.density)),
            ("young".to_string(), Val::F(cfg.young)),
            ("poisson".to_string(), Val::F(cfg.poisson)),
        ]
        .into();
        rules.apply_once(&mut g, "set_material", &material)?;
        for k in 0..cfg.regions.len() {
            let rep = rules
                .apply_once(&mut g, &format!("region_{k}"), &none)
                .map_err(|e| {
                    let text = &cfg.regions[k].predicate;
                    predicate_failed(&g, "material region", text, PredicateAt::Element, e)
                })?;
            if rep.matches == 0 {
                return Err(PhysicsError::Config(format!(
                    "material region '{}' contains no element",
                    cfg.regions[k].predicate
                )));
            }
        }
        let (he, elem) = if dim == 3 {
            ("half_edge_volume", "element_volume")
        } else {
            ("half_edge_area", "element_area")
        };
        rules.apply_once(&mut g, he, &none)?;
        rules.apply_once(&mut g, elem, &none)?;
        rules.apply_once(&mut g, "lump_mass", &none)?;
        // which support holds each vertex orbit (its representative's index), to refuse a
        // prescribed displacement that moves a vertex another support holds: the last one
        // applied would win silently (nothing to check, and no walk over the map, without
        // prescribed displacements)
        let supports = if cfg.prescribed.is_empty() {
            None
        } else {
            Some(Supports::new(&g)?)
        };
        // per vertex orbit, the index in `labels` of the support holding it
        let mut held_by: Vec<Option<usize>> =
            vec![None; supports.as_ref().map_or(0, |s| s.reps.len())];
        let mut labels: Vec<String> = Vec::new();
        for k in 0..cfg.fixed.len() {
            let rep = rules
                .apply_once(&mut g, &format!("fix_{k}"), &none)
                .map_err(|e| {
                    predicate_failed(&g, "fix predicate", &cfg.fixed[k], PredicateAt::Vertex, e)
                })?;
            if rep.matches == 0 {
                return Err(PhysicsError::Config(format!(
                    "fix predicate '{}' selects no vertex",
                    cfg.fixed[k]
                )));
            }
            if let Some(s) = &supports {
                labels.push(format!("fix predicate '{}'", cfg.fixed[k]));
                s.claim(&g, &mut held_by, labels.len() - 1);
            }
        }
        for (k, (p, d)) in cfg.prescribed.iter().enumerate() {
            let params: Params = [("d".to_string(), Val::V3(*d))].into();
            let before = supports.as_ref().map(|s| s.positions(&g));
            let rep = rules
                .apply_once(&mut g, &format!("prescribe_{k}"), &params)
                .map_err(|e| {
                    let what = "prescribed-displacement predicate";
                    predicate_failed(&g, what, p, PredicateAt::Vertex, e)
                })?;
            if rep.matches == 0 {
                return Err(PhysicsError::Config(format!(
                    "prescribed-displacement predicate '{p}' selects no vertex"
                )));
            }
            if let (Some(supports), Some(before)) = (&supports, before) {
                let this = format!("prescribed-displacement predicate '{p}'");
                if let Some((r, other)) = supports.moved_held(&g, &before, &held_by) {
                    let point = supports.point(&g, r);
                    return Err(PhysicsError::Config(format!(
                        "{this} moves the vertex at rest {point:?}, which {} holds too: a vertex is held one way (narrow one predicate, or give both the same displacement)",
                        labels[other]
                    )));
                }
                labels.push(this);
                supports.claim(&g, &mut held_by, labels.len() - 1);
            }
        }
        let element_orbit = if dim == 3 {
            OrbitType::volume()
        } else {
            OrbitType::face(2)
        };
        let elements = g.count_orbits(element_orbit);
        // Two models whose init rules write one embedding share its values: the last one
        // written, which both models' step rules read. Where the later model writes other
        // values than the earlier one did, it is refused (QA: `stretch_elementary` and
        // `stretch_cumulated` share `spring_k` through `stretch_init`; with 1000 and 10, both
        // ran at the later one's stiffness, and the result depended on the order of the
        // models). Equal values (the same parameters; the rest-shape data two hyperelastic
        // models both compute) pass.
        //
        // To see which values a model's init rules wrote, each such embedding is filled with
        // a marker NaN no rule computes before they run (an embedding its own init rules read
        // is left alone, and checked by its changes); after them, a value that is not the
        // marker was written, and the others get back what they held.
        let writes_of: Vec<Vec<String>> = defs.iter().map(|d| init_writes(&rules, d)).collect();
        let shared: Vec<String> = writes_of
            .iter()
            .flatten()
            .filter(|n| writes_of.iter().filter(|w| w.contains(n)).count() > 1)
            .cloned()
            .collect();
        // per embedding written by two models or more: (model, values written, all values)
        let mut set_by: Vec<(String, usize, Vec<bool>, Vec<u64>)> = Vec::new();
        for (k, def) in defs.iter().enumerate() {
            let reads = init_reads(&rules, def);
            // the shared embeddings this model writes (created now, as the first run of the
            // rules writing them would), marked unless its own init rules read them
            let mine: Vec<&str> = writes_of[k]
                .iter()
                .filter(|n| shared.contains(n))
                .map(String::as_str)
                .collect();
            rules.prepare_named(&mut g, &mine)?;
            let marked: Vec<(String, topomech_gmap::EmbeddingId, Vec<f64>)> = mine
                .iter()
                .filter(|n| !reads.iter().any(|r| r == *n))
                .filter_map(|n| {
                    let id = g.embedding_id(n)?;
                    let ColumnRef::Real(v) = g.embedding(id).column() else {
                        return None;
                    };
                    Some(((*n).to_string(), id, v.to_vec()))
                })
                .collect();
            for (_, id, _) in &marked {
                if let Ok(ColumnMut::Real(v)) = g.column_mut(*id) {
                    v.fill(f64::from_bits(MARKER));
                }
            }
            // the matches of every init rule, and the elements the rules on elements handle
            // (a hook on the element's orbit, or on a dart: the shipped rules take one dart
            // per element, `where n0.vertex0`): the distinct elements of their hook darts,
            // not their matches (24 a tetrahedron for a dart rule without that guard); a
            // rule on vertices, edges or corners handles no element
            let mut matched = 0;
            let mut element_hooks: Option<Vec<Dart>> = Some(Vec::new());
            let mut element_matches = 0;
            for (init, p) in &def.init {
                let (report, hooks) = rules
                    .apply_once_hooks(&mut g, init, p)
                    .map_err(|e| model_init_failed(&g, &rules, &def.name, init, e))?;
                matched += report.matches;
                if rules
                    .rule(init)
                    .is_ok_and(|r| topomech_rules::model::hook_on_elements(r, dim))
                {
                    element_matches += report.matches;
                    match (element_hooks.as_mut(), hooks) {
                        (Some(all), Some(h)) => all.extend(h),
                        _ => element_hooks = None,
                    }
                }
            }
            // what the init rules wrote of each marked embedding; the rest restored
            let mut written_of: Vec<(String, Vec<bool>)> = Vec::new();
            for (name, id, before) in marked {
                let Ok(ColumnMut::Real(v)) = g.column_mut(id) else {
                    continue;
                };
                let written: Vec<bool> = v.iter().map(|x| x.to_bits() != MARKER).collect();
                for ((x, w), b) in v.iter_mut().zip(&written).zip(&before) {
                    if !w {
                        *x = *b;
                    }
                }
                written_of.push((name, written));
            }
            if matched == 0 {
                return Err(PhysicsError::Model(format!(
                    "model '{}' matches nothing on this mesh: it needs {}",
                    def.name, def.needs
                )));
            }
            // (a per_element model without an init rule on elements is refused by the
            // checker, `hook_on_elements`)
            if def.per_element {
                // (the matches where the hooks were not recorded: a rule applied before)
                let on_elements = element_hooks
                    .map_or(element_matches, |h| distinct_orbits(&g, &h, element_orbit));
                if on_elements < elements {
                    return Err(PhysicsError::Model(format!(
                        "model '{}' handles {on_elements} elements of {elements}: it needs {}, and the others would get no force",
                        def.name, def.needs
                    )));
                }
            }
            for name in mine {
                let now = column_bits(&g, name);
                // what this model wrote: its marked values; one that reads the embedding in
                // its own init rules was not marked: every value it changed
                let written: Vec<bool> = match written_of.iter().find(|(n, _)| n == name) {
                    Some((_, w)) => w.clone(),
                    None => match set_by.iter().rev().find(|(n, _, _, _)| n == name) {
                        Some((_, _, _, before)) => {
                            before.iter().zip(&now).map(|(b, n)| b != n).collect()
                        }
                        None => vec![true; now.len()],
                    },
                };
                // a value both models wrote, to other values (on disjoint parts of the mesh,
                // a tetrahedra model and a hexahedra one, each writes its own slots)
                let conflict = set_by
                    .iter()
                    .find(|(n, _, w, before)| {
                        n == name
                            && before.len() == now.len()
                            && (0..now.len()).any(|x| w[x] && written[x] && before[x] != now[x])
                    })
                    .map(|(_, i, _, _)| *i);
                if let Some(i) = conflict {
                    return Err(PhysicsError::Model(format!(
                        "models '{}' (model[{i}]) and '{}' (model[{k}]) both set '{name}' in their init rules, to other values: the embedding holds one value, the last one written, which both models would use; give them the same parameters, or give one its own embeddings (a copy of its rule file with them renamed)",
                        defs[i].name, def.name
                    )));
                }
                set_by.push((name.to_string(), k, written, now));
            }
        }
        // the derived data of what the models stored (cumulated springs, tensors) exists from
        // the start, so that it is kept up to date through topology changes
        let embs = rules.embeddings();
        let derived: Vec<&str> = embs
            .iter()
            .filter(|e| {
                e.derived
                    .is_some_and(|(_, src)| g.embedding_id(&embs[src].name).is_some())
            })
            .map(|e| e.name.as_str())
            .collect();
        rules.prepare_named(&mut g, &derived)?;
        rules.clear_plans();
        g.refresh_derived();
        let step_params: Params = [
            ("dt".to_string(), Val::F(cfg.dt)),
            ("gravity".to_string(), Val::V3(cfg.gravity)),
            ("damping".to_string(), Val::F(cfg.damping)),
        ]
        .into();
        let rows = Rows::init(&mut g)?;
        let vertex_darts_version = g.version();
        let size = {
            let pos = g
                .require("rest")
                .map_err(|e| PhysicsError::Config(e.to_string()))?;
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for d in g.darts() {
                let p = g.real(pos, d);
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
            norm3([hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]]).max(f64::MIN_POSITIVE)
        };
        let cfg_events = cfg.events.len();
        let cfg_blades = cfg.blades.len();
        let mut sim = Simulation {
            g,
            rules,
            cfg,
            defs,
            step_params,
            time: 0.0,
            steps: 0,
            rows,
            vertex_darts_version,
            size,
            events_done: vec![false; cfg_events],
            blades_opened: vec![0; cfg_blades],
            measure_ready: false,
            strain_bound: None,
            changes: Vec::new(),
            saved: [Vec::new(), Vec::new()],
            saving_steps: 0,
            frame: [0.0; 3],
            parts: None,
            forces_written: None,
            fd_jacobian: false,
            capped_solve: None,
            report: None,
            static_base: Vec::new(),
            solver: linear::SolverCache::default(),
        };
        // a welded row is one particle: held when any of its orbits is
        if !sim.rows.welded.is_empty() {
            let fixed = sim.row_any("fixed")?;
            sim.set_vertex_bool("fixed", &fixed)?;
        }
        // the cuts the configuration declares find their faces through compiled guards: built
        // now, with the rest of the set-up, so that a cut only runs and patches them
        sim.prepare_declared_cuts()?;
        // every free vertex needs a mass
        let masses = sim.vertex_scalar_sum("mass")?;
        let fixed = sim.vertex_bool("fixed")?;
        if let Some(v) = (0..masses.len()).find(|&v| {
            !fixed[v] && masses[v].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        }) {
            return Err(PhysicsError::Config(format!(
                "vertex {v} has mass {} and is not fixed",
                masses[v]
            )));
        }
        // after the supports: a held vertex is never projected, so it may start below
        sim.check_ground()?;
        Ok(sim)
    }

    /// Refuses a ground plane with a free vertex on its far side now ([`below_ground`]): run
    /// at set-up and again before the first step, when a scene's initial displacement or a
    /// user's `set_positions` may have moved the body since.
    pub(crate) fn check_ground(&self) -> Result<(), PhysicsError> {
        let Some(ground) = &self.cfg.ground else {
            return Ok(());
        };
        let (p, n) = ground.plane(self.cfg.gravity)?;
        below_ground(&self.g, p, n)
    }
}

/// Marks one dart per element (volume in 3D, face in 2D) as `vertex0`: the element's smallest
/// dart; and, where a model declares `face0`, one dart per face `<0,1>` of an element. Rules
/// number an element's or a face's vertices from them.
fn mark_vertex0(g: &mut GMap) -> Result<(), PhysicsError> {
    let elem = if g.dimension() == 3 {
        OrbitType::volume()
    } else {
        OrbitType::face(2)
    };
    mark_one_per_orbit(g, "vertex0", elem)?;
    if g.embedding_id("face0").is_some() {
        mark_one_per_orbit(g, "face0", OrbitType::parse("<0,1>").expect("static"))?;
    }
    Ok(())
}

/// Sets the bool embedding `name` (on `<>`) true on the smallest dart of each orbit `o`,
/// false elsewhere.
fn mark_one_per_orbit(g: &mut GMap, name: &str, o: OrbitType) -> Result<(), PhysicsError> {
    let err = |e: topomech_gmap::EmbeddingError| PhysicsError::Config(e.to_string());
    let id = g.require(name).map_err(err)?;
    // the column written at once: a value set per dart cost 40 ms at 10^5 tets
    let reps: Vec<usize> = g
        .orbit_representatives(o)
        .into_iter()
        .map(|d| g.embedding(id).slot(d))
        .collect();
    match g.column_mut(id).map_err(err)? {
        ColumnMut::Bool(col) => {
            col.fill(false);
            for s in reps {
                col[s] = true;
            }
        }
        _ => {
            return Err(PhysicsError::Config(format!(
                "the map's embedding '{name}' is not a bool"
            )))
        }
    }
    Ok(())
}

/// Why a fracture threshold is refused (as scenes refuse it): not finite, or not positive (a
/// threshold at or below zero opens every face of an element at rest or stretched).
pub(crate) fn threshold_problem(t: f64) -> Option<String> {
    if !t.is_finite() {
        Some(format!("fracture threshold must be finite, got {t}"))
    } else if t <= 0.0 {
        Some(format!("fracture threshold must be positive, got {t}"))
    } else {
        None
    }
}

/// The vertex orbits of a map being set up, for [`Simulation::new`]'s check that no two
/// supports (fix predicates, prescribed displacements) hold one vertex differently.
struct Supports {
    reps: Vec<Dart>,
    fixed: topomech_gmap::EmbeddingId,
    position: topomech_gmap::EmbeddingId,
    rest: topomech_gmap::EmbeddingId,
}

impl Supports {
    fn new(g: &GMap) -> Result<Self, PhysicsError> {
        let id = |name: &str| {
            g.require(name)
                .map_err(|e| PhysicsError::Config(e.to_string()))
        };
        Ok(Supports {
            reps: g.orbit_representatives(OrbitType::vertex(g.dimension())),
            fixed: id("fixed")?,
            position: id("position")?,
            rest: id("rest")?,
        })
    }

    /// Gives support `k` the held vertex orbits no support holds yet.
    fn claim(&self, g: &GMap, held_by: &mut [Option<usize>], k: usize) {
        for (h, &d) in held_by.iter_mut().zip(&self.reps) {
            if h.is_none() && matches!(g.value(self.fixed, d), Ok(Value::Bool(true))) {
                *h = Some(k);
            }
        }
    }

    /// Every vertex orbit's position, bit for bit.
    fn positions(&self, g: &GMap) -> Vec<[u64; 3]> {
        self.reps
            .iter()
            .map(|&d| {
                let p = g.real(self.position, d);
                [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()]
            })
            .collect()
    }

    /// The first vertex orbit (by index) that a support in `held_by` holds and whose position
    /// differs from `before`, with that support.
    fn moved_held(
        &self,
        g: &GMap,
        before: &[[u64; 3]],
        held_by: &[Option<usize>],
    ) -> Option<(usize, usize)> {
        let now = self.positions(g);
        // compared as numbers, not bits: a zero displacement added to a rest coordinate -0.0
        // gives +0.0, the same position (found by QA); exactly, as the positions a support
        // writes are exact (rest + d, the same sum for the same d)
        #[allow(clippy::float_cmp)]
        let moved =
            |r: usize| (0..3).any(|k| f64::from_bits(now[r][k]) != f64::from_bits(before[r][k]));
        (0..self.reps.len()).find_map(|r| match held_by[r] {
            Some(other) if moved(r) => Some((r, other)),
            _ => None,
        })
    }

    /// The rest position of vertex orbit `r`.
    fn point(&self, g: &GMap, r: usize) -> [f64; 3] {
        let p = g.real(self.rest, self.reps[r]);
        [p[0], p[1], p[2]]
    }
}
