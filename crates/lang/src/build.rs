//! Rules built as syntax trees, not as text: parse one expression given by a user (a scene's
//! predicate), build rule declarations around it, and check them with the ordinary checker
//! beside rule files given as text ([`check_built`]; `topomech_rules::build::load` also
//! wraps the checked rules in a rule set).
//!
//! A program that makes rules from user input builds them here, so the input can only ever be
//! the one expression it is meant to be: a predicate containing `}` or `rule` is refused by
//! [`parse_expression`], never read as more rules.
//!
//! ```
//! use topomech_lang::build::{self, parse_expression};
//!
//! // where { let x = x(v.rest)  <the user's predicate> }
//! let pred = parse_expression("fix[0].where", "x < 0.5").unwrap();
//! let guard = build::let_block(
//!     vec![("x", build::call("x", vec![build::read("v", "rest")]))],
//!     pred,
//! );
//! let mut r = build::rule("fix_0", build::graph(vec![build::node("v", &[1, 2], true)]));
//! r.guard = Some(guard);
//! r.compute = vec![build::write("v", "fixed", build::boolean(true))];
//! let text = "dimension 2
//!   embedding rest : vec3 on <1,2>
//!   embedding fixed : bool on <1,2>";
//! let glue = build::file(&topomech_lang::parser::parse(text).unwrap(), vec![r]);
//! let (checked, _) =
//!     build::check_built(&[("decl.tmr".into(), text.into())], vec![("glue".into(), glue)])
//!         .unwrap();
//! assert!(checked.rules.iter().any(|r| r.name == "fix_0"));
//!
//! // rule syntax in a predicate is refused, naming where
//! let e = parse_expression("fix[0].where", "x < 0 } rule evil {").unwrap_err();
//! assert_eq!((e.file.as_str(), e.pos.col), ("fix[0].where", 7));
//! ```

use crate::ast::{
    AggKind, ArcDecl, Expr, ExprKind, File, Graph, NodeDecl, Param, Pos, RuleDecl, Stmt,
};
use crate::check::{self, Checked, Diagnostic, Severity};
use crate::value::BinOp;

/// Parses `text` as one expression of the rule language, optionally preceded by `let`
/// bindings (`let a = x * 2  a < 1`), as a rule's `where` guard or a block body reads it.
/// The whole text must be that expression: anything after it (`}`, `rule`, a second
/// expression) is refused.
///
/// Errors: a [`Diagnostic`] of condition `syntax`, with `file` = `file_label` (the name of
/// what gave the text, e.g. a scene key) and the line and column in `text` (from 1) of the
/// first wrong token; an expression deeper than [`crate::parser::MAX_DEPTH`] is refused the
/// same way ("expression nested too deeply"), never a stack overflow.
pub fn parse_expression(file_label: &str, text: &str) -> Result<Expr, Diagnostic> {
    crate::parser::parse_block_body(text).map_err(|e| Diagnostic {
        file: file_label.to_string(),
        pos: e.pos,
        severity: Severity::Error,
        condition: "syntax",
        message: e.message,
    })
}

/// Whether `s` is an identifier of the rule language (`[A-Za-z_][A-Za-z0-9_]*`, not `_`
/// alone), so that it can name a rule, node, embedding or variable of a built rule.
pub fn is_identifier(s: &str) -> bool {
    let mut c = s.chars();
    matches!(c.next(), Some(f) if f.is_ascii_alphabetic() || f == '_')
        && c.all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
        && s != "_"
}

/// An expression of kind `kind`, at no source position (line 0, column 0: built, not written).
pub fn expr(kind: ExprKind) -> Expr {
    Expr {
        kind,
        pos: Pos::default(),
    }
}

/// A real literal.
pub fn real(x: f64) -> Expr {
    expr(ExprKind::Real(x))
}

/// `true` or `false`.
pub fn boolean(b: bool) -> Expr {
    expr(ExprKind::Bool(b))
}

/// A variable or parameter.
pub fn name(n: &str) -> Expr {
    expr(ExprKind::Name(n.to_string()))
}

/// `node.emb`.
pub fn read(node: &str, emb: &str) -> Expr {
    expr(ExprKind::Read {
        node: node.to_string(),
        emb: emb.to_string(),
    })
}

/// `f(args)`.
pub fn call(f: &str, args: Vec<Expr>) -> Expr {
    expr(ExprKind::Call {
        name: f.to_string(),
        args,
    })
}

/// `sum<orbit>(node.emb)`.
pub fn sum(orbit: &[u64], node: &str, emb: &str) -> Expr {
    aggregate(AggKind::Sum, orbit, node, emb)
}

/// `mean<orbit>(node.emb)`.
pub fn mean(orbit: &[u64], node: &str, emb: &str) -> Expr {
    aggregate(AggKind::Mean, orbit, node, emb)
}

fn aggregate(kind: AggKind, orbit: &[u64], node: &str, emb: &str) -> Expr {
    expr(ExprKind::Aggregate {
        kind,
        orbit: orbit.to_vec(),
        node: node.to_string(),
        emb: Some(emb.to_string()),
    })
}

/// `a op b`.
pub fn binary(op: BinOp, a: Expr, b: Expr) -> Expr {
    expr(ExprKind::Binary(op, Box::new(a), Box::new(b)))
}

/// `{ let n0 = e0  let n1 = e1 ...  body }`; `body` itself when there is no binding.
pub fn let_block(lets: Vec<(&str, Expr)>, body: Expr) -> Expr {
    if lets.is_empty() {
        return body;
    }
    let stmts = lets
        .into_iter()
        .map(|(n, value)| Stmt::Let {
            name: n.to_string(),
            value,
            pos: Pos::default(),
        })
        .collect();
    expr(ExprKind::Block(stmts, Box::new(body)))
}

/// The statement `node.emb = value` of a `compute` block.
pub fn write(node: &str, emb: &str, value: Expr) -> Stmt {
    Stmt::Write {
        node: node.to_string(),
        emb: emb.to_string(),
        value,
        pos: Pos::default(),
    }
}

/// The rule parameter `name: ty` (`ty` as written: `f64`, `vec3`, ...).
pub fn param(name: &str, ty: &str) -> Param {
    Param {
        name: name.to_string(),
        ty: ty.to_string(),
        pos: Pos::default(),
    }
}

/// The node `name : <orbit> [hook]`.
pub fn node(name: &str, orbit: &[u64], hook: bool) -> NodeDecl {
    NodeDecl {
        name: name.to_string(),
        orbit: orbit.iter().map(|&i| Some(i)).collect(),
        hook,
        pos: Pos::default(),
        orbit_pos: Pos::default(),
    }
}

/// The arc `a -dim- b`.
pub fn arc(a: &str, dim: u64, b: &str) -> ArcDecl {
    ArcDecl {
        a: a.to_string(),
        dim,
        b: b.to_string(),
        pos: Pos::default(),
    }
}

/// A left or right graph of these nodes, with no explicit arc (push to `arcs` for some).
pub fn graph(nodes: Vec<NodeDecl>) -> Graph {
    Graph {
        nodes,
        arcs: Vec::new(),
        pos: Pos::default(),
    }
}

/// The rule `name` with left graph `left` and nothing else: no parameter, no right graph
/// (the rule only computes), no guard, an empty `compute`. Set the fields to add them.
pub fn rule(name: &str, left: Graph) -> RuleDecl {
    RuleDecl {
        name: name.to_string(),
        params: Vec::new(),
        left: Some(left),
        right: None,
        compute: Vec::new(),
        guard: None,
        pos: Pos::default(),
    }
}

/// A file of the same dimension as `like` (e.g. a parsed declaration file) holding `rules`,
/// and nothing else.
pub fn file(like: &File, rules: Vec<RuleDecl>) -> File {
    File {
        dimension: like.dimension,
        rules,
        ..File::default()
    }
}

/// Parses the text sources `(file name, text)` and checks them together with the files
/// `parsed` (already syntax trees, e.g. built with this module), sharing their embeddings,
/// with every check [`check::check_sources`] makes (what `topomech_rules::load_sources`
/// checks). Diagnostics of a built file name it by its label and, for a parsed expression
/// inside it, the line and column in that expression's text.
///
/// On success: the checked rules (what the engine's rule set wraps, see
/// `topomech_rules::build::load`) and their warnings; otherwise every diagnostic.
pub fn check_built(
    sources: &[(String, String)],
    parsed: Vec<(String, File)>,
) -> Result<(Checked, Vec<Diagnostic>), Vec<Diagnostic>> {
    let mut files = Vec::with_capacity(sources.len() + parsed.len());
    let mut errs = Vec::new();
    for (name, src) in sources {
        match crate::parser::parse(src) {
            Ok(f) => files.push((name.clone(), f)),
            Err(e) => errs.push(Diagnostic {
                file: name.clone(),
                pos: e.pos,
                severity: Severity::Error,
                condition: "syntax",
                message: e.message,
            }),
        }
    }
    if !errs.is_empty() {
        return Err(errs);
    }
    files.extend(parsed);
    let (checked, diags) = check::check_files(&files);
    match checked {
        Some(c) => Ok((c, diags)),
        None => Err(diags),
    }
}
