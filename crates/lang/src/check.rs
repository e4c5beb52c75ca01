//! The checker: from a syntax tree to checked rules, refusing any rule that could break a
//! G-map or leave an embedding inconsistent.
//!
//! Each refusal is a [`Diagnostic`] with a stable condition name (the conditions of Jerboa's
//! rule editor, Belhaouari et al. ICGT 2014; Arnould et al. MSCS 2022):
//!
//! | condition | what is refused |
//! |---|---|
//! | `syntax` | text that does not parse |
//! | `type` | an expression, parameter or embedding whose types do not fit |
//! | `dimension` | a label outside `0..=n`, a missing or unsupported `dimension` |
//! | `name` | duplicate or unknown node, rule, embedding, parameter or variable names |
//! | `hook` | a left component without exactly one hook; a hook with `_`; hooks of different types |
//! | `arity` | orbit types of different lengths in one rule |
//! | `duplicate-label` | a label twice on a node (orbit type and explicit arcs together) |
//! | `incident-arc` | a created or deleted node missing a label; a kept node whose orbit label vanishes |
//! | `cycle` | a node where `alpha_i alpha_j` (i + 2 <= j) would stop being an involution |
//! | `embedding-missing` | a created orbit that gets no value |
//! | `embedding-merge` | orbits that may merge with no expression for the result |
//! | `embedding-write-conflict` | two writes to one orbit, or one write whose value differs on one orbit |
//!
//! Semantics of labels on a kept node (in both graphs): a label that neither graph mentions is
//! left as it is; an explicit arc of the left graph that the right graph drops is unlinked (its
//! darts become free); an explicit arc of the right graph that the left graph does not mention
//! requires free darts at match time. A label of an orbit type that is removed (`_`) or
//! relabelled must reappear as an explicit arc (write a loop `a -i- a` to free the darts on
//! purpose): a silently vanishing orbit link is refused.

use std::collections::{HashMap, HashSet};
use std::fmt;

use topomech_gmap::{Aggregate, OrbitType, Policy};

use crate::ast::{self, AggKind, ExprKind, Label, Pos, Stmt};
use crate::builtins;
use crate::value::{binop_type, unop_type, BinOp, Ty, UnOp, Val};

/// How bad a diagnostic is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Severity {
    /// The rule file is refused.
    Error,
    /// Worth a look; the file is accepted.
    Warning,
}

/// One problem found in a rule file.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    /// The file (as given to the loader).
    pub file: String,
    /// Where.
    pub pos: Pos,
    /// Error or warning.
    pub severity: Severity,
    /// The condition's stable name, e.g. `incident-arc`.
    pub condition: &'static str,
    /// What is wrong, naming the rule, node and label involved.
    pub message: String,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sev = match self.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
        };
        write!(
            f,
            "{}:{}:{}: {sev}[{}]: {}",
            self.file, self.pos.line, self.pos.col, self.condition, self.message
        )
    }
}

/// A checked embedding declaration.
#[derive(Clone, Debug, PartialEq)]
pub struct EmbDecl {
    /// Its name.
    pub name: String,
    /// Its type.
    pub ty: Ty,
    /// Its orbit.
    pub orbit: OrbitType,
    /// Its merge/split policy.
    pub policy: Policy,
    /// For a derived embedding: the aggregate and the source's index.
    pub derived: Option<(Aggregate, usize)>,
}

/// Where a node's label `i` comes from, in one graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// Not mentioned.
    None,
    /// Position `t` of the node's orbit type.
    Orbit(usize),
    /// An explicit arc to another node.
    Arc(usize),
    /// A loop `a -i- a`: the darts are free at `i`.
    Loop,
}

/// A node of a checked rule.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// Its name.
    pub name: String,
    /// Its orbit type in the left graph (absent: created by the rule).
    pub left: Option<Vec<Label>>,
    /// Its orbit type in the right graph (absent: deleted by the rule).
    pub right: Option<Vec<Label>>,
    /// Label sources in the left graph, per dimension 0..=3.
    pub left_src: [Source; 4],
    /// Label sources in the right graph, per dimension 0..=3.
    pub right_src: [Source; 4],
    /// Where it is first declared.
    pub pos: Pos,
}

impl Node {
    /// Kept by the rule (in both graphs).
    pub fn is_kept(&self) -> bool {
        self.left.is_some() && self.right.is_some()
    }
}

/// A typed expression.
#[derive(Clone, Debug, PartialEq)]
pub enum TExpr {
    /// A constant.
    Const(Val),
    /// Rule parameter number k.
    Param(usize),
    /// Local variable number k.
    Local(usize),
    /// `node.emb` before the rule.
    Read {
        /// The node.
        node: usize,
        /// The embedding.
        emb: usize,
    },
    /// An aggregate over the node's orbit, before the rule.
    Agg {
        /// Sum, mean or count.
        kind: AggKind,
        /// The orbit.
        orbit: OrbitType,
        /// The node.
        node: usize,
        /// The embedding (`None` for `count`: the darts' orbits are counted).
        emb: Option<usize>,
        /// Result type.
        ty: Ty,
    },
    /// A binary operation.
    Bin(BinOp, Box<TExpr>, Box<TExpr>),
    /// A unary operation.
    Un(UnOp, Box<TExpr>),
    /// A built-in call.
    Call(String, Vec<TExpr>),
    /// `if c { a } else { b }`.
    If(Box<TExpr>, Box<TExpr>, Box<TExpr>),
    /// `let`s then a result.
    Block(Vec<(usize, TExpr)>, Box<TExpr>),
    /// An integer promoted to a real.
    ToReal(Box<TExpr>),
}

impl TExpr {
    /// The value of an integer constant, negated ones included (`3`, `-1`); `None` for any
    /// other expression.
    pub fn const_int(&self) -> Option<i64> {
        match self {
            TExpr::Const(Val::I(i)) => Some(*i),
            TExpr::Un(UnOp::Neg, a) => a.const_int()?.checked_neg(),
            _ => None,
        }
    }
}

/// A checked statement.
#[derive(Clone, Debug, PartialEq)]
pub enum TStmt {
    /// Local `k = value`.
    Let(usize, TExpr),
    /// `node.emb = value`.
    Write {
        /// The node.
        node: usize,
        /// The embedding.
        emb: usize,
        /// The value.
        value: TExpr,
        /// Orbit positions along which the value is known to be constant and the node's
        /// darts stay in one orbit of the embedding (the node's label there is in the
        /// embedding's orbit type): rows joined through them share one evaluation, and one
        /// write, since they are one orbit of the embedding. (Rows joined along a position
        /// that leaves the embedding's orbit, a face's corners for a corner embedding, are
        /// other orbits: each is written.)
        uniform: Vec<usize>,
    },
}

/// A checked rule.
#[derive(Clone, Debug, PartialEq)]
pub struct Rule {
    /// Its name.
    pub name: String,
    /// The file it comes from.
    pub file: String,
    /// Its parameters.
    pub params: Vec<(String, Ty)>,
    /// The length of every orbit type.
    pub arity: usize,
    /// Its nodes (left and right).
    pub nodes: Vec<Node>,
    /// Explicit arcs of the left graph.
    pub left_arcs: Vec<(usize, u8, usize)>,
    /// Explicit arcs of the right graph.
    pub right_arcs: Vec<(usize, u8, usize)>,
    /// One hook per left component, in declaration order.
    pub hooks: Vec<usize>,
    /// For each node of the left graph, the index of its component's hook in `hooks`.
    pub component: Vec<Option<usize>>,
    /// The orbit labels of the hooks (all hooks have the same).
    pub hook_orbit: Vec<u8>,
    /// Whether the rule changes the topology.
    pub changes_topology: bool,
    /// The `compute` block.
    pub program: Vec<TStmt>,
    /// Number of local variables.
    pub n_locals: usize,
    /// The `where` guard.
    pub guard: Option<TExpr>,
    /// The embeddings the guard reads (directly or in aggregates): the matches a guard
    /// accepts change only when the topology or one of these does.
    pub guard_reads: Vec<usize>,
    /// For a rule with one hook: the other nodes an automorphism of the left graph (a
    /// permutation of its nodes keeping every node's orbit type and every arc) maps the hook
    /// to. A match's darts at such a node are the hook orbit of another match with the same
    /// footprint (the first composed with the automorphism); searches matching each footprint
    /// once need not start there. Empty for larger patterns (more than 7 left nodes: not
    /// searched).
    pub hook_images: Vec<usize>,
}

/// The result of checking files: their shared dimension and embeddings, and their rules.
#[derive(Clone, Debug, PartialEq)]
pub struct Checked {
    /// The dimension.
    pub dim: usize,
    /// The embeddings.
    pub embeddings: Vec<EmbDecl>,
    /// The rules.
    pub rules: Vec<Rule>,
    /// The model declarations.
    pub models: Vec<crate::model::Model>,
}

struct Ctx<'a> {
    file: &'a str,
    out: &'a mut Vec<Diagnostic>,
}

impl Ctx<'_> {
    /// How many errors were reported so far.
    fn errors(&self) -> usize {
        self.out
            .iter()
            .filter(|d| d.severity == Severity::Error)
            .count()
    }

    fn error(&mut self, pos: Pos, condition: &'static str, message: String) {
        self.out.push(Diagnostic {
            file: self.file.to_string(),
            pos,
            severity: Severity::Error,
            condition,
            message,
        });
    }

    fn warning(&mut self, pos: Pos, condition: &'static str, message: String) {
        self.out.push(Diagnostic {
            file: self.file.to_string(),
            pos,
            severity: Severity::Warning,
            condition,
            message,
        });
    }
}

/// Parses and checks rule files given as `(file name, source)`. Returns the checked rules
/// when no error was found, and every diagnostic (warnings too) either way. The dimension is
/// the one of the files that serve a single dimension (a set of files that all serve several
/// is refused: use [`check_sources_for`]).
pub fn check_sources(sources: &[(String, String)]) -> (Option<Checked>, Vec<Diagnostic>) {
    check_sources_for(None, sources)
}

/// Parses and checks rule files for maps of dimension `target` (`None`: inferred as in
/// [`check_sources`]). A file serves the dimensions of its `dimension` line (`dimension 2 3`:
/// both; no line: both); loaded for 2-maps, a file that also serves 3-maps has label 3
/// dropped (`<1,2,3>` means `<1,2>`, a loop `a -3- a` is always true), and an arc `a -3- b`
/// between two nodes is refused (it can never match: alpha3 is free on a 2-map).
#[allow(clippy::single_match_else, clippy::too_many_lines)]
pub fn check_sources_for(
    target: Option<usize>,
    sources: &[(String, String)],
) -> (Option<Checked>, Vec<Diagnostic>) {
    let mut diags = Vec::new();
    let mut files = Vec::new();
    for (name, src) in sources {
        match crate::parser::parse(src) {
            Ok(f) => files.push((name.clone(), f)),
            Err(e) => diags.push(Diagnostic {
                file: name.clone(),
                pos: e.pos,
                severity: Severity::Error,
                condition: "syntax",
                message: e.message,
            }),
        }
    }
    if diags.iter().any(|d| d.severity == Severity::Error) {
        return (None, diags);
    }
    check_files_for(target, &files)
}

/// The advice ending the error on rule files that all serve 2-maps and 3-maps when they are
/// loaded without a dimension (a front end may replace it by how its caller gives one).
pub const LOAD_FOR_A_DIMENSION: &str =
    "load the rules for one dimension, 2 (surfaces) or 3 (volumes)";

/// Checks rule files already parsed (or built as syntax trees, see [`crate::build`]), given as
/// `(file name, syntax tree)`, exactly as [`check_sources`] checks parsed text.
pub fn check_files(files: &[(String, crate::ast::File)]) -> (Option<Checked>, Vec<Diagnostic>) {
    check_files_for(None, files)
}

/// Checks rule files already parsed, for maps of dimension `target` (`None`: inferred), as
/// [`check_sources_for`] checks parsed text.
#[allow(clippy::single_match_else, clippy::too_many_lines)]
pub fn check_files_for(
    target: Option<usize>,
    files: &[(String, crate::ast::File)],
) -> (Option<Checked>, Vec<Diagnostic>) {
    let mut diags = Vec::new();
    // dimension: each file's dimensions (none written: both), and the one they are checked for
    let mut file_dims: Vec<Vec<usize>> = Vec::new();
    for (name, f) in files {
        let mut c = Ctx {
            file: name,
            out: &mut diags,
        };
        let mut v = Vec::new();
        for &(n, p) in &f.dimensions {
            if n == 2 || n == 3 {
                v.push(n as usize);
            } else {
                c.error(
                    p,
                    "dimension",
                    format!("dimension {n} is not supported: use 2 (surfaces) or 3 (volumes)"),
                );
            }
        }
        if f.dimensions.is_empty() {
            v = vec![2, 3];
        }
        v.sort_unstable();
        file_dims.push(v);
    }
    if diags.iter().any(|d| d.severity == Severity::Error) {
        return (None, diags);
    }
    let dim = match target {
        Some(t) => {
            for ((name, f), dims) in files.iter().zip(&file_dims) {
                if !dims.contains(&t) {
                    let p = f.dimension.map_or(Pos { line: 1, col: 1 }, |d| d.1);
                    let mut c = Ctx {
                        file: name,
                        out: &mut diags,
                    };
                    c.error(
                        p,
                        "dimension",
                        format!(
                            "the file serves dimension {}, not dimension {t} (the dimension the rules are loaded for)",
                            dims.iter().map(ToString::to_string).collect::<Vec<_>>().join(" ")
                        ),
                    );
                }
            }
            t
        }
        None => {
            // inferred from the files that serve one dimension
            let mut dim: Option<(usize, String)> = None;
            for ((name, f), dims) in files.iter().zip(&file_dims) {
                let [n] = dims[..] else { continue };
                let p = f.dimension.map_or(Pos { line: 1, col: 1 }, |d| d.1);
                let mut c = Ctx {
                    file: name,
                    out: &mut diags,
                };
                match &dim {
                    Some((d, other)) if *d != n => c.error(
                        p,
                        "dimension",
                        format!("dimension {n} differs from dimension {d} of {other}"),
                    ),
                    Some(_) => {}
                    None => dim = Some((n, name.clone())),
                }
            }
            match dim {
                Some((d, other)) => {
                    for ((name, f), dims) in files.iter().zip(&file_dims) {
                        // (a file of one other dimension is refused above)
                        if dims.len() > 1 && !dims.contains(&d) {
                            let p = f.dimension.map_or(Pos { line: 1, col: 1 }, |x| x.1);
                            let mut c = Ctx {
                                file: name,
                                out: &mut diags,
                            };
                            c.error(
                                p,
                                "dimension",
                                format!("the file does not serve dimension {d} of {other}"),
                            );
                        }
                    }
                    d
                }
                None => {
                    let others = if files.len() > 1 {
                        "no other file fixes the dimension"
                    } else {
                        "nothing fixes the dimension"
                    };
                    for ((name, f), dims) in files.iter().zip(&file_dims) {
                        let mut c = Ctx {
                            file: name,
                            out: &mut diags,
                        };
                        match f.dimension {
                            None => c.error(
                                Pos { line: 1, col: 1 },
                                "dimension",
                                format!("the file has no 'dimension' line, so it serves 2-maps and 3-maps, and {others}: {LOAD_FOR_A_DIMENSION}"),
                            ),
                            Some((_, p)) => c.error(
                                p,
                                "dimension",
                                format!(
                                    "the file says 'dimension {}', so it serves 2-maps and 3-maps, and {others}: {LOAD_FOR_A_DIMENSION}",
                                    dims.iter().map(ToString::to_string).collect::<Vec<_>>().join(" ")
                                ),
                            ),
                        }
                    }
                    return (None, diags);
                }
            }
        }
    };
    if diags.iter().any(|d| d.severity == Severity::Error) {
        return (None, diags);
    }
    // on a 2-map, a file that also serves 3-maps has its label 3 dropped (alpha3 is free)
    let dropped: Vec<(String, crate::ast::File)>;
    let files = if dim == 2 && file_dims.iter().any(|d| d.contains(&3)) {
        let mut owned = files.to_vec();
        for ((name, f), dims) in owned.iter_mut().zip(&file_dims) {
            if dims.contains(&3) {
                crate::dims::drop_label3(name, f, &mut diags);
            }
        }
        if diags.iter().any(|d| d.severity == Severity::Error) {
            return (None, diags);
        }
        dropped = owned;
        &dropped[..]
    } else {
        files
    };
    // embeddings, shared by all files
    let mut embs: Vec<EmbDecl> = Vec::new();
    // where each of `embs` is declared first
    let mut emb_at: Vec<(String, Pos)> = Vec::new();
    for (name, f) in files {
        let mut c = Ctx {
            file: name,
            out: &mut diags,
        };
        for e in &f.embeddings {
            if let Some(d) = check_embedding(&mut c, e, dim, &embs) {
                if let Some(k) = embs.iter().position(|x| x.name == d.name) {
                    if embs[k] != d {
                        let (other, p) = &emb_at[k];
                        c.error(
                            e.pos,
                            "name",
                            format!(
                                "embedding '{}' is declared again differently (its {}): '{}' here, '{}' at {other}:{}:{}",
                                e.name,
                                emb_differences(&embs[k], &d, &embs).join(" and "),
                                describe_embedding(&d, &embs),
                                describe_embedding(&embs[k], &embs),
                                p.line,
                                p.col
                            ),
                        );
                    }
                } else {
                    embs.push(d);
                    emb_at.push((name.clone(), e.pos));
                }
            }
        }
    }
    let mut rules: Vec<Rule> = Vec::new();
    let mut rule_pos: HashMap<String, (String, Pos)> = HashMap::new();
    for (name, f) in files {
        let mut c = Ctx {
            file: name,
            out: &mut diags,
        };
        for r in &f.rules {
            if let Some((other, p)) = rule_pos.get(&r.name) {
                c.error(
                    r.pos,
                    "name",
                    format!(
                        "rule '{}' is already defined at {other}:{}:{}",
                        r.name, p.line, p.col
                    ),
                );
                // its body is checked all the same, so that its own problems are reported
                // now rather than once the name is fixed (the rule is not kept)
                check_rule(&mut c, r, dim, &embs);
                continue;
            }
            rule_pos.insert(r.name.clone(), (name.clone(), r.pos));
            if let Some(checked) = check_rule(&mut c, r, dim, &embs) {
                rules.push(checked);
            }
        }
    }
    let models = crate::model::check_models(files, &file_dims, &embs, &rules, &mut diags);
    let ok = !diags.iter().any(|d| d.severity == Severity::Error);
    (
        ok.then_some(Checked {
            dim,
            embeddings: embs,
            rules,
            models,
        }),
        diags,
    )
}

fn check_orbit(c: &mut Ctx, dims: &[u64], dim: usize, pos: Pos, what: &str) -> Option<OrbitType> {
    let mut v = Vec::new();
    for &i in dims {
        if i > dim as u64 {
            c.error(
                pos,
                "dimension",
                format!("{what}: dimension {i} is outside 0..={dim}"),
            );
            return None;
        }
        v.push(i as usize);
    }
    match OrbitType::new(&v) {
        Ok(o) => Some(o),
        Err(e) => {
            c.error(pos, "duplicate-label", format!("{what}: {e}"));
            None
        }
    }
}

/// A checked embedding declaration as it would be written after its name:
/// `f64 on <0,1> policy sum`, with `derived AGG(SOURCE)` for a derived one (`embs` names its
/// source).
fn describe_embedding(e: &EmbDecl, embs: &[EmbDecl]) -> String {
    let s = format!("{} on {} policy {}", e.ty, e.orbit, e.policy.name());
    match e.derived {
        Some((agg, k)) => {
            let source = embs.get(k).map_or("?", |x| x.name.as_str());
            format!("{s} derived {}({source})", agg.name())
        }
        None => s,
    }
}

/// What differs between two declarations of one embedding: "type", "orbit", "policy",
/// "derivation".
fn emb_differences(a: &EmbDecl, b: &EmbDecl, embs: &[EmbDecl]) -> Vec<&'static str> {
    let source = |e: &EmbDecl| {
        e.derived
            .map(|(agg, k)| (agg, embs.get(k).map(|x| &x.name)))
    };
    [
        (a.ty != b.ty, "type"),
        (a.orbit != b.orbit, "orbit"),
        (a.policy != b.policy, "policy"),
        (source(a) != source(b), "derivation"),
    ]
    .into_iter()
    .filter_map(|(differs, what)| differs.then_some(what))
    .collect()
}

/// The aggregates a derived embedding may take, by the type of its source.
const DERIVED_TYPES: &str = "sum takes f64, i64, vectors and matrices, mean f64, vectors and matrices, both of the source's type; count takes any type and is i64";

fn check_embedding(
    c: &mut Ctx,
    e: &ast::EmbeddingDecl,
    dim: usize,
    embs: &[EmbDecl],
) -> Option<EmbDecl> {
    let Some(ty) = Ty::parse(&e.ty) else {
        c.error(
            e.pos,
            "type",
            format!("embedding '{}': unknown type '{}'", e.name, e.ty),
        );
        return None;
    };
    let orbit = check_orbit(c, &e.orbit, dim, e.pos, &format!("embedding '{}'", e.name))?;
    let policy = match e.policy.as_deref() {
        None => Policy::Copy,
        Some(p) => {
            if let Some(p) = Policy::parse(p) {
                p
            } else {
                c.error(
                    e.pos,
                    "type",
                    format!(
                        "embedding '{}': unknown policy '{p}' (copy, sum, mean, error)",
                        e.name
                    ),
                );
                return None;
            }
        }
    };
    let derived = match &e.derived {
        None => None,
        Some((agg, src)) => {
            let Some(agg) = Aggregate::parse(agg) else {
                c.error(
                    e.pos,
                    "type",
                    format!(
                        "embedding '{}': unknown aggregate '{agg}' (sum, mean, count)",
                        e.name
                    ),
                );
                return None;
            };
            let Some(k) = embs.iter().position(|x| &x.name == src) else {
                c.error(
                    e.pos,
                    "name",
                    format!(
                        "embedding '{}': source '{src}' is not declared before it",
                        e.name
                    ),
                );
                return None;
            };
            if !embs[k].orbit.is_subset_of(orbit) {
                c.error(
                    e.pos,
                    "type",
                    format!("derived embedding '{}' on {orbit} aggregates '{src}' on {}, which is not a sub-orbit", e.name, embs[k].orbit),
                );
                return None;
            }
            // what the map can aggregate (GMap::add_derived_embedding): a sum of reals or
            // integers, a mean of reals, a count of anything
            let src_ty = embs[k].ty;
            let defined = match agg {
                Aggregate::Sum => src_ty.is_real() || src_ty == Ty::I64,
                Aggregate::Mean => src_ty.is_real(),
                Aggregate::Count => true,
            };
            if !defined {
                c.error(
                    e.pos,
                    "type",
                    format!(
                        "derived embedding '{}': {} of '{src}' is not defined, '{src}' being {src_ty} ({DERIVED_TYPES})",
                        e.name,
                        agg.name()
                    ),
                );
                return None;
            }
            let expected = if agg == Aggregate::Count {
                Ty::I64
            } else {
                src_ty
            };
            if expected != ty {
                let why = if agg == Aggregate::Count {
                    "a count is i64".to_string()
                } else {
                    format!(
                        "a {} has its source's type: '{src}' is {src_ty}",
                        agg.name()
                    )
                };
                c.error(
                    e.pos,
                    "type",
                    format!(
                        "derived embedding '{}' must have type {expected} ({why})",
                        e.name
                    ),
                );
                return None;
            }
            Some((agg, k))
        }
    };
    Some(EmbDecl {
        name: e.name.clone(),
        ty,
        orbit,
        policy,
        derived,
    })
}

/// A label as written, as an index (labels beyond `usize` are out of range anyway).
fn small(i: u64) -> usize {
    usize::try_from(i).unwrap_or(usize::MAX)
}

/// The labels of a node as written, for the checked rule: a label above 255 (refused with the
/// number as written, before the rule is used) saturates.
fn checked_labels(orbit: &[ast::WrittenLabel]) -> Vec<Label> {
    orbit
        .iter()
        .map(|l| l.map(|i| u8::try_from(i).unwrap_or(u8::MAX)))
        .collect()
}

/// Label sources of each node of one graph; reports duplicate labels.
fn sources(
    c: &mut Ctx,
    rule: &str,
    graph: &ast::Graph,
    index: &HashMap<&str, usize>,
    n_nodes: usize,
    side: &str,
) -> Vec<[Source; 4]> {
    let mut src = vec![[Source::None; 4]; n_nodes];
    let mut set = |c: &mut Ctx, k: usize, i: usize, s: Source, pos: Pos, name: &str| {
        if i > 3 {
            return;
        }
        if src[k][i] == Source::None {
            src[k][i] = s;
        } else {
            c.error(
                pos,
                "duplicate-label",
                format!("rule '{rule}': node '{name}' has label {i} twice in the {side} graph (orbit type and explicit arcs together)"),
            );
        }
    };
    for nd in &graph.nodes {
        let k = index[nd.name.as_str()];
        for (t, l) in nd.orbit.iter().enumerate() {
            if let Some(i) = l {
                set(c, k, small(*i), Source::Orbit(t), nd.orbit_pos, &nd.name);
            }
        }
    }
    for a in &graph.arcs {
        let (Some(&ka), Some(&kb)) = (index.get(a.a.as_str()), index.get(a.b.as_str())) else {
            continue;
        };
        let i = small(a.dim);
        if ka == kb {
            set(c, ka, i, Source::Loop, a.pos, &a.a);
        } else {
            set(c, ka, i, Source::Arc(kb), a.pos, &a.a);
            set(c, kb, i, Source::Arc(ka), a.pos, &a.b);
        }
    }
    src
}

#[allow(clippy::too_many_lines)]
fn check_rule(c: &mut Ctx, r: &ast::RuleDecl, dim: usize, embs: &[EmbDecl]) -> Option<Rule> {
    let errors_before = c.errors();
    let rn = r.name.as_str();
    let Some(left) = &r.left else {
        c.error(r.pos, "syntax", format!("rule '{rn}' has no left graph"));
        return None;
    };
    let right = r.right.as_ref().unwrap_or(left);
    // node names, unique per graph
    let mut nodes: Vec<Node> = Vec::new();
    let mut index: HashMap<&str, usize> = HashMap::new();
    // a rule without a right graph keeps its left one: its problems are reported once, for
    // the left graph
    let explicit_right = r.right.is_some();
    for (side, g) in [("left", left), ("right", right)] {
        let report = side == "left" || explicit_right;
        let mut seen = HashSet::new();
        for nd in &g.nodes {
            if !seen.insert(nd.name.as_str()) {
                if report {
                    c.error(
                        nd.pos,
                        "name",
                        format!(
                            "rule '{rn}': node '{}' is declared twice in the {side} graph",
                            nd.name
                        ),
                    );
                }
                continue;
            }
            let k = *index.entry(nd.name.as_str()).or_insert_with(|| {
                nodes.push(Node {
                    name: nd.name.clone(),
                    left: None,
                    right: None,
                    left_src: [Source::None; 4],
                    right_src: [Source::None; 4],
                    pos: nd.pos,
                });
                nodes.len() - 1
            });
            if side == "left" {
                nodes[k].left = Some(checked_labels(&nd.orbit));
            } else {
                nodes[k].right = Some(checked_labels(&nd.orbit));
                if nd.hook && r.right.is_some() {
                    c.error(nd.pos, "hook", format!("rule '{rn}': node '{}' is marked hook in the right graph; hooks belong to the left graph", nd.name));
                }
            }
        }
        for a in &g.arcs {
            for end in [&a.a, &a.b] {
                if report && !g.nodes.iter().any(|n| &n.name == end) {
                    c.error(a.pos, "name", format!("rule '{rn}': arc {} -{}- {} names node '{end}', which is not in the {side} graph", a.a, a.dim, a.b));
                }
            }
            if report && a.dim > dim as u64 {
                c.error(
                    a.pos,
                    "dimension",
                    format!(
                        "rule '{rn}': arc {} -{}- {} has label {} outside 0..={dim}",
                        a.a, a.dim, a.b, a.dim
                    ),
                );
            }
        }
        for nd in &g.nodes {
            for l in nd.orbit.iter().flatten() {
                if report && *l > dim as u64 {
                    c.error(nd.orbit_pos, "dimension", format!("rule '{rn}': node '{}' has label {l} outside 0..={dim} in the {side} graph", nd.name));
                }
            }
        }
    }
    // arity
    let reference = left.nodes.iter().find(|n| n.hook).or(left.nodes.first());
    let arity = reference.map_or(0, |n| n.orbit.len());
    for (side, g) in [("left", left), ("right", right)] {
        if side == "right" && !explicit_right {
            continue;
        }
        for nd in &g.nodes {
            if nd.orbit.len() != arity {
                c.error(
                    nd.orbit_pos,
                    "arity",
                    format!(
                        "rule '{rn}': node '{}' has {} orbit labels in the {side} graph, but '{}' has {arity}: every orbit type of a rule has the same length",
                        nd.name,
                        nd.orbit.len(),
                        reference.map_or("", |n| n.name.as_str())
                    ),
                );
            }
        }
    }
    if left.nodes.is_empty() {
        c.error(
            left.pos,
            "hook",
            format!("rule '{rn}': the left graph is empty; it needs a hook"),
        );
    }
    let errors_now = c.errors();
    if errors_now > errors_before {
        return None; // later conditions rely on names, arity and dimensions
    }
    let n = nodes.len();
    let ls = sources(c, rn, left, &index, n, "left");
    let rs = sources(c, rn, right, &index, n, "right");
    for k in 0..n {
        nodes[k].left_src = ls[k];
        nodes[k].right_src = rs[k];
    }
    // hooks: one per left component
    let left_arcs: Vec<(usize, u8, usize)> = left
        .arcs
        .iter()
        .map(|a| (index[a.a.as_str()], a.dim as u8, index[a.b.as_str()]))
        .collect();
    let right_arcs: Vec<(usize, u8, usize)> = right
        .arcs
        .iter()
        .map(|a| (index[a.a.as_str()], a.dim as u8, index[a.b.as_str()]))
        .collect();
    let mut comp_of: Vec<Option<usize>> = vec![None; n];
    let mut hooks: Vec<usize> = Vec::new();
    for nd in &left.nodes {
        let k = index[nd.name.as_str()];
        if comp_of[k].is_some() {
            continue;
        }
        // the component of k
        let mut members = vec![k];
        let mut stack = vec![k];
        let mut seen = HashSet::from([k]);
        while let Some(x) = stack.pop() {
            for &(a, _, b) in &left_arcs {
                for (p, q) in [(a, b), (b, a)] {
                    if p == x && seen.insert(q) {
                        members.push(q);
                        stack.push(q);
                    }
                }
            }
        }
        let comp_hooks: Vec<usize> = left
            .nodes
            .iter()
            .filter(|m| m.hook && members.contains(&index[m.name.as_str()]))
            .map(|m| index[m.name.as_str()])
            .collect();
        match comp_hooks.len() {
            1 => {}
            0 => {
                c.error(nd.pos, "hook", format!("rule '{rn}': the left component of node '{}' has no hook (mark one node 'hook')", nd.name));
                continue;
            }
            _ => {
                let names: Vec<&str> = comp_hooks.iter().map(|&h| nodes[h].name.as_str()).collect();
                c.error(nd.pos, "hook", format!("rule '{rn}': the left component of node '{}' has {} hooks ({}); a component has exactly one", nd.name, names.len(), names.join(", ")));
                continue;
            }
        }
        let h = comp_hooks[0];
        for &m in &members {
            comp_of[m] = Some(hooks.len());
        }
        hooks.push(h);
    }
    let mut hook_orbit: Vec<u8> = Vec::new();
    for (j, &h) in hooks.iter().enumerate() {
        let orbit = nodes[h].left.clone().unwrap_or_default();
        let nd = left
            .nodes
            .iter()
            .find(|x| x.name == nodes[h].name)
            .expect("hook declared");
        if orbit.iter().any(Option::is_none) {
            c.error(nd.orbit_pos, "hook", format!("rule '{rn}': hook '{}' has '_' in its orbit type; a hook matches a whole orbit", nodes[h].name));
            continue;
        }
        let labels: Vec<u8> = orbit.iter().map(|l| l.expect("checked")).collect();
        if j == 0 {
            hook_orbit = labels;
        } else if labels != hook_orbit {
            c.error(nd.orbit_pos, "hook", format!("rule '{rn}': hook '{}' has a different orbit type from hook '{}': hooks of one rule are matched in parallel", nodes[h].name, nodes[hooks[0]].name));
        }
    }
    let errors_now = c.errors();
    if errors_now > errors_before {
        return None;
    }
    check_incident(c, rn, &nodes, dim);
    let changes_topology = r.right.is_some()
        && (nodes.iter().any(|x| !x.is_kept())
            || nodes
                .iter()
                .any(|x| x.left != x.right || x.left_src != x.right_src));
    check_cycles(c, rn, &nodes, &hook_orbit, dim);
    // expressions
    let mut env = Env {
        params: Vec::new(),
        locals: Vec::new(),
        n_locals: 0,
        used_params: HashSet::new(),
    };
    for p in &r.params {
        match Ty::parse(&p.ty) {
            Some(t) => {
                if env.params.iter().any(|(q, _)| q == &p.name) {
                    c.error(
                        p.pos,
                        "name",
                        format!("rule '{rn}': parameter '{}' is declared twice", p.name),
                    );
                }
                env.params.push((p.name.clone(), t));
            }
            None => c.error(
                p.pos,
                "type",
                format!(
                    "rule '{rn}': parameter '{}' has unknown type '{}'",
                    p.name, p.ty
                ),
            ),
        }
    }
    let mut x = ExprCheck {
        c,
        rn,
        nodes: &nodes,
        embs,
        dim,
        index: &index,
        integer_quotient_meant: false,
    };
    let guard = r.guard.as_ref().and_then(|g| {
        let (e, t) = x.expr(g, &mut env)?;
        if t == Ty::Bool {
            Some(e)
        } else {
            x.c.error(
                g.pos,
                "type",
                format!("rule '{rn}': the 'where' guard has type {t}, expected bool"),
            );
            None
        }
    });
    let mut program = Vec::new();
    let mut writes: Vec<(usize, usize, Pos, HashSet<usize>)> = Vec::new();
    let mut local_uniform: Vec<HashSet<usize>> = Vec::new();
    for s in &r.compute {
        match s {
            Stmt::Let { name, value, pos } => {
                if let Some((e, t)) = x.expr(value, &mut env) {
                    let u = x.uniform(&e, &local_uniform, arity);
                    let k = env.n_locals;
                    env.n_locals += 1;
                    env.locals.push((name.clone(), t, k, *pos, false));
                    if local_uniform.len() <= k {
                        local_uniform.resize(k + 1, HashSet::new());
                    }
                    local_uniform[k] = u;
                    program.push(TStmt::Let(k, e));
                }
            }
            Stmt::Write {
                node,
                emb,
                value,
                pos,
            } => {
                let Some(&k) = index.get(node.as_str()) else {
                    x.c.error(
                        *pos,
                        "name",
                        format!("rule '{rn}': write to unknown node '{node}'"),
                    );
                    continue;
                };
                if nodes[k].right.is_none() {
                    x.c.error(*pos, "name", format!("rule '{rn}': node '{node}' is deleted by the rule; it cannot be written"));
                    continue;
                }
                let Some(ei) = embs.iter().position(|e| &e.name == emb) else {
                    x.c.error(*pos, "name", format!("rule '{rn}': unknown embedding '{emb}' (declare it with 'embedding {emb} : TYPE on <...>')"));
                    continue;
                };
                if embs[ei].derived.is_some() {
                    x.c.error(*pos, "type", format!("rule '{rn}': embedding '{emb}' is derived: it is recomputed from its source, never written"));
                    continue;
                }
                let Some((mut e, t)) = x.expr(value, &mut env) else {
                    continue;
                };
                let want = embs[ei].ty;
                if t == Ty::I64 && want == Ty::F64 {
                    e = TExpr::ToReal(Box::new(e));
                } else if t != want {
                    x.c.error(
                        *pos,
                        "type",
                        format!(
                            "rule '{rn}': {node}.{emb} has type {want}, but the value has type {t}"
                        ),
                    );
                    continue;
                }
                let u = x.uniform(&e, &local_uniform, arity);
                // the node's labels: its left graph's, or the right graph's for a created node
                let labels = nodes[k].left.as_ref().or(nodes[k].right.as_ref());
                let mut uniform: Vec<usize> = u
                    .iter()
                    .copied()
                    .filter(|&t| {
                        labels.is_some_and(|l| {
                            l[t].is_some_and(|i| embs[ei].orbit.contains(i as usize))
                        })
                    })
                    .collect();
                uniform.sort_unstable();
                writes.push((k, ei, *pos, u));
                program.push(TStmt::Write {
                    node: k,
                    emb: ei,
                    value: e,
                    uniform,
                });
            }
        }
    }
    for (name, _, _, pos, used) in &env.locals {
        if !used {
            x.c.warning(
                *pos,
                "unused",
                format!("rule '{rn}': variable '{name}' is never used"),
            );
        }
    }
    for p in &r.params {
        if !env.used_params.contains(&p.name) {
            x.c.warning(
                p.pos,
                "unused",
                format!("rule '{rn}': parameter '{}' is never used", p.name),
            );
        }
    }
    check_embeddings(c, rn, &nodes, &right_arcs, &left_arcs, embs, &writes, arity);
    // a guard may tell the hook positions apart (a per-dart flag on the hook): then the
    // footprint may pass from one only, and nothing can be said
    if !changes_topology && hooks.len() == 1 && guard.is_none() {
        check_mirror(c, rn, &nodes, &left_arcs, hooks[0], embs, &writes);
    }
    let errors_now = c.errors();
    if errors_now > errors_before {
        return None;
    }
    let hook_images = if hooks.len() == 1 {
        hook_images(&nodes, &left_arcs, hooks[0])
    } else {
        Vec::new()
    };
    Some(Rule {
        hook_images,
        name: r.name.clone(),
        file: c.file.to_string(),
        params: env.params,
        arity,
        nodes,
        left_arcs,
        right_arcs,
        hooks,
        component: comp_of,
        hook_orbit,
        changes_topology,
        program,
        n_locals: env.n_locals,
        guard_reads: guard.as_ref().map(reads_of).unwrap_or_default(),
        guard,
    })
}

/// Warns where a computation rule's left graph maps onto itself with the hook moved (an
/// automorphism: a permutation `s` of its nodes keeping every node's orbit type and every
/// arc) and the `compute` block writes a node's embedding but not its image's. The global
/// application matches each footprint (set of darts) once, from whichever of its hook
/// positions it meets first; the footprint found from the other is the same one and is
/// skipped. So a spring `a -0- b` written only at `a` leaves the other end of every edge
/// unwritten (which one depends on the dart numbering, and may change after a cut). A write
/// of `n.e` is covered when `s(n).e` is written too, or when a path of arcs whose labels are
/// all in the orbit of `e` joins `n` and `s(n)` (then their darts share `e`'s cells: an edge
/// embedding on `<0,2,3>` written at `a` is written at `b`). Rules with a guard are not
/// checked: a guard may tell the hook positions apart (the shear springs' `n0.face0`).
fn check_mirror(
    c: &mut Ctx,
    rn: &str,
    nodes: &[Node],
    arcs: &[(usize, u8, usize)],
    hook: usize,
    embs: &[EmbDecl],
    writes: &[(usize, usize, Pos, HashSet<usize>)],
) {
    if writes.is_empty() {
        return;
    }
    for p in &automorphisms_moving(nodes, arcs, hook) {
        for (k, e, pos, _) in writes {
            let image = p[*k];
            let covered =
                image == *k || writes.iter().any(|(k2, e2, _, _)| *k2 == image && e2 == e) || {
                    // joined by arcs whose labels are all in the embedding's orbit
                    let comp = components(nodes.len(), arcs, embs[*e].orbit, |n| {
                        nodes[n].left.is_some()
                    });
                    comp[*k] == comp[image]
                };
            if !covered {
                c.warning(
                    *pos,
                    "mirror-write",
                    format!(
                        "rule '{rn}': its left graph maps onto itself with '{}' in the place of '{}', so each footprint is matched once, from either; '{}.{}' is written but '{}.{}' is not, so the orbits matched as '{}' are left unwritten (write both, as a spring writes a.f = f and b.f = -f)",
                        nodes[image].name,
                        nodes[*k].name,
                        nodes[*k].name,
                        embs[*e].name,
                        nodes[image].name,
                        embs[*e].name,
                        nodes[image].name,
                    ),
                );
                // one warning per rule
                return;
            }
        }
    }
}

/// Every automorphism of the left graph (`nodes` with a left side, `arcs`) that moves
/// `hook`, as a permutation of the nodes (`usize::MAX` for nodes without a left side);
/// none for a pattern of fewer than 2 or more than 7 left nodes (the search tries
/// permutations).
fn automorphisms_moving(
    nodes: &[Node],
    arcs: &[(usize, u8, usize)],
    hook: usize,
) -> Vec<Vec<usize>> {
    let left: Vec<usize> = (0..nodes.len())
        .filter(|&k| nodes[k].left.is_some())
        .collect();
    if left.len() < 2 || left.len() > 7 {
        return Vec::new();
    }
    let norm = |(a, i, b): (usize, u8, usize)| (a.min(b), i, a.max(b));
    let mut want: Vec<(usize, u8, usize)> = arcs.iter().map(|&x| norm(x)).collect();
    want.sort_unstable();
    // by backtracking over the left nodes
    let mut found: Vec<Vec<usize>> = Vec::new();
    let mut perm = vec![usize::MAX; nodes.len()];
    let mut taken = vec![false; nodes.len()];
    let ok = |p: &[usize]| {
        if p[hook] == hook {
            return false;
        }
        let mut got: Vec<(usize, u8, usize)> = arcs
            .iter()
            .map(|&(a, i, b)| norm((p[a], i, p[b])))
            .collect();
        got.sort_unstable();
        got == want
    };
    extend_automorphism(0, &left, nodes, &mut perm, &mut taken, &mut found, &ok);
    found
}

/// The nodes the automorphisms of the left graph map `hook` to (see [`Rule::hook_images`]).
fn hook_images(nodes: &[Node], arcs: &[(usize, u8, usize)], hook: usize) -> Vec<usize> {
    let mut out: Vec<usize> = automorphisms_moving(nodes, arcs, hook)
        .iter()
        .map(|p| p[hook])
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// The permutations of the left nodes `left` extending `perm` (fixed up to `left[at]`) that
/// keep every node's orbit type and that `ok` accepts, into `out` (see [`check_mirror`]).
fn extend_automorphism(
    at: usize,
    left: &[usize],
    nodes: &[Node],
    perm: &mut [usize],
    taken: &mut [bool],
    out: &mut Vec<Vec<usize>>,
    ok: &dyn Fn(&[usize]) -> bool,
) {
    if at == left.len() {
        if ok(perm) {
            out.push(perm.to_vec());
        }
        return;
    }
    let k = left[at];
    for &t in left {
        if !taken[t] && nodes[t].left == nodes[k].left {
            taken[t] = true;
            perm[k] = t;
            extend_automorphism(at + 1, left, nodes, perm, taken, out, ok);
            taken[t] = false;
        }
    }
    perm[k] = usize::MAX;
}

fn check_incident(c: &mut Ctx, rn: &str, nodes: &[Node], dim: usize) {
    for nd in nodes {
        match (&nd.left, &nd.right) {
            (None, Some(_)) => {
                for i in 0..=dim {
                    if nd.right_src[i] == Source::None {
                        c.error(nd.pos, "incident-arc", format!("rule '{rn}': node '{}' is created but has no label {i}: give it in its orbit type, an arc, or a loop {} -{i}- {}", nd.name, nd.name, nd.name));
                    }
                }
            }
            (Some(_), None) => {
                for i in 0..=dim {
                    if nd.left_src[i] == Source::None {
                        c.error(nd.pos, "incident-arc", format!("rule '{rn}': node '{}' is deleted but its label {i} is not matched: links to darts outside the rule would dangle (give it in its orbit type, an arc, or a loop)", nd.name));
                    }
                }
            }
            (Some(l), Some(r)) => {
                for t in 0..l.len().min(r.len()) {
                    if l[t] == r[t] {
                        continue;
                    }
                    if let Some(i) = l[t] {
                        if !matches!(nd.right_src[i as usize], Source::Arc(_) | Source::Loop) {
                            c.error(nd.pos, "incident-arc", format!("rule '{rn}': node '{}' loses label {i} at orbit position {t} and the right graph does not give it back as an explicit arc (write a loop {} -{i}- {} to free the darts)", nd.name, nd.name, nd.name));
                        }
                    }
                    if let Some(j) = r[t] {
                        if !matches!(nd.left_src[j as usize], Source::Arc(_) | Source::Loop) {
                            c.error(nd.pos, "incident-arc", format!("rule '{rn}': node '{}' gains label {j} at orbit position {t}, but the left graph has no label {j} for it at that position or as an explicit arc", nd.name));
                        }
                    }
                }
            }
            (None, None) => {}
        }
    }
}

/// The right-graph source of label `i`, where an explicit arc of the left graph that the
/// right graph drops counts as a loop (its darts become free).
pub fn effective_right(nd: &Node, i: usize) -> Source {
    match nd.right_src[i] {
        Source::None if nd.is_kept() && nd.left_src[i] != Source::None => Source::Loop,
        s => s,
    }
}

/// Whether label `i` of node `nd` changes.
fn changed(nd: &Node, i: usize) -> bool {
    !nd.is_kept() || nd.left_src[i] != effective_right(nd, i)
}

fn check_cycles(c: &mut Ctx, rn: &str, nodes: &[Node], hook_orbit: &[u8], dim: usize) {
    for (k, nd) in nodes.iter().enumerate() {
        if nd.right.is_none() {
            continue;
        }
        let mut reported = HashSet::new();
        for i in 0..=dim {
            if !changed(nd, i) {
                continue;
            }
            for j in 0..=dim {
                if i.abs_diff(j) < 2 || !reported.insert((i.min(j), i.max(j))) {
                    continue;
                }
                // walk i, j, i, j from (k, identity row)
                let (mut at, mut word): (usize, Vec<usize>) = (k, Vec::new());
                let mut missing = None;
                for step in [i, j, i, j] {
                    match effective_right(&nodes[at], step) {
                        Source::Orbit(t) => {
                            if word.last() == Some(&t) {
                                word.pop();
                            } else {
                                word.push(t);
                            }
                        }
                        Source::Arc(m) => at = m,
                        Source::Loop => {}
                        Source::None => {
                            missing = Some((at, step));
                            break;
                        }
                    }
                }
                if let Some((m, s)) = missing {
                    c.error(nd.pos, "cycle", format!("rule '{rn}': label {i} of node '{}' changes, but the alpha{}-alpha{} cycle cannot be checked: node '{}' has no label {s} in the right graph (mention it in its orbit type or an arc)", nd.name, i.min(j), i.max(j), nodes[m].name));
                    continue;
                }
                let commuting = word.len() == 4
                    && word[0] == word[2]
                    && word[1] == word[3]
                    && hook_orbit
                        .get(word[0])
                        .zip(hook_orbit.get(word[1]))
                        .is_some_and(|(a, b)| a.abs_diff(*b) >= 2);
                if at != k || !(word.is_empty() || commuting) {
                    c.error(nd.pos, "cycle", format!("rule '{rn}': at node '{}', alpha{} o alpha{} would not be an involution in the result (following labels {i},{j},{i},{j} does not come back to '{}')", nd.name, i.min(j), i.max(j), nd.name));
                }
            }
        }
    }
}

/// Connected components of nodes through arcs whose label is in `orbit`.
fn components(
    n: usize,
    arcs: &[(usize, u8, usize)],
    orbit: OrbitType,
    present: impl Fn(usize) -> bool,
) -> Vec<usize> {
    fn find(c: &mut [usize], x: usize) -> usize {
        let mut r = x;
        while c[r] != r {
            r = c[r];
        }
        c[x] = r;
        r
    }
    let mut comp: Vec<usize> = (0..n).collect();
    for &(a, i, b) in arcs {
        if orbit.contains(i as usize) && present(a) && present(b) {
            let (ra, rb) = (find(&mut comp, a), find(&mut comp, b));
            comp[ra] = rb;
        }
    }
    (0..n).map(|x| find(&mut comp, x)).collect()
}

#[allow(clippy::too_many_arguments)]
fn check_embeddings(
    c: &mut Ctx,
    rn: &str,
    nodes: &[Node],
    right_arcs: &[(usize, u8, usize)],
    left_arcs: &[(usize, u8, usize)],
    embs: &[EmbDecl],
    writes: &[(usize, usize, Pos, HashSet<usize>)],
    arity: usize,
) {
    let n = nodes.len();
    for (ei, e) in embs.iter().enumerate() {
        if e.derived.is_some() {
            continue;
        }
        let rc = components(n, right_arcs, e.orbit, |k| nodes[k].right.is_some());
        let lc = components(n, left_arcs, e.orbit, |k| nodes[k].left.is_some());
        let written: Vec<&(usize, usize, Pos, HashSet<usize>)> =
            writes.iter().filter(|w| w.1 == ei).collect();
        let comp_written = |comp: usize| written.iter().any(|w| rc[w.0] == comp);
        // missing values on created orbits
        for (k, nd) in nodes.iter().enumerate() {
            if nd.left.is_some() || nd.right.is_none() {
                continue;
            }
            let has_kept = (0..n).any(|m| rc[m] == rc[k] && nodes[m].is_kept());
            if !has_kept && !comp_written(rc[k]) {
                c.error(nd.pos, "embedding-missing", format!("rule '{rn}': node '{}' is created and gets no value of '{}' ({} on {}): write {}.{} = ..., or link it by a label of {} to a kept node", nd.name, e.name, e.ty, e.orbit, nd.name, e.name, e.orbit));
            }
        }
        // merges
        let mut seen_comp = HashSet::new();
        for (k, nd) in nodes.iter().enumerate() {
            if !nd.is_kept() || !seen_comp.insert(rc[k]) {
                continue;
            }
            let kept: Vec<usize> = (0..n)
                .filter(|&m| rc[m] == rc[k] && nodes[m].is_kept())
                .collect();
            let mut merge: Option<String> = None;
            for &m in &kept {
                if lc[m] != lc[kept[0]] {
                    merge = Some(format!(
                        "the right graph joins '{}' and '{}' by a label of {}",
                        nodes[kept[0]].name, nodes[m].name, e.orbit
                    ));
                }
                let (l, r) = (
                    nodes[m].left.as_ref().expect("kept"),
                    nodes[m].right.as_ref().expect("kept"),
                );
                for t in 0..arity {
                    let in_r = r[t].is_some_and(|i| e.orbit.contains(i as usize));
                    let in_l = l[t].is_some_and(|i| e.orbit.contains(i as usize));
                    if in_r && !in_l {
                        merge = Some(format!(
                            "node '{}' gains label {} of {} at orbit position {t}",
                            nodes[m].name,
                            r[t].expect("some"),
                            e.orbit
                        ));
                    }
                }
            }
            if let Some(why) = merge {
                if !comp_written(rc[k]) {
                    c.error(nd.pos, "embedding-merge", format!("rule '{rn}': orbits of '{}' may merge ({why}): write the merged value with {}.{} = ...", e.name, nd.name, e.name));
                }
            }
        }
        // write conflicts
        for (a, wa) in written.iter().enumerate() {
            for wb in &written[a + 1..] {
                if rc[wa.0] == rc[wb.0] {
                    c.error(wb.2, "embedding-write-conflict", format!("rule '{rn}': '{}' is written twice on one orbit ({}.{} and {}.{} are joined by labels of {})", e.name, nodes[wa.0].name, e.name, nodes[wb.0].name, e.name, e.orbit));
                }
            }
            // rows joined in the result orbit must get one value
            let joined: HashSet<usize> = (0..arity)
                .filter(|&t| {
                    (0..n).any(|m| {
                        rc[m] == rc[wa.0]
                            && nodes[m]
                                .right
                                .as_ref()
                                .is_some_and(|r| r[t].is_some_and(|i| e.orbit.contains(i as usize)))
                    })
                })
                .collect();
            if let Some(t) = joined.iter().find(|t| !wa.3.contains(t)) {
                c.error(wa.2, "embedding-write-conflict", format!("rule '{rn}': {}.{} is one value per {} orbit, which joins the rows along orbit position {t}, but the expression may differ along it: read values that are constant on that orbit (e.g. an aggregate over it)", nodes[wa.0].name, e.name, e.orbit));
            }
        }
    }
}

struct Env {
    params: Vec<(String, Ty)>,
    /// name, type, slot, position, used
    locals: Vec<(String, Ty, usize, Pos, bool)>,
    n_locals: usize,
    used_params: HashSet<String>,
}

struct ExprCheck<'a, 'c> {
    c: &'a mut Ctx<'c>,
    rn: &'a str,
    nodes: &'a [Node],
    embs: &'a [EmbDecl],
    dim: usize,
    index: &'a HashMap<&'a str, usize>,
    /// Set while checking the argument of `to_i64(a / b)`, read (and cleared) by that
    /// division: its integer quotient is meant, no `integer-division` warning.
    integer_quotient_meant: bool,
}

impl ExprCheck<'_, '_> {
    #[allow(clippy::needless_pass_by_value)] // callers build the message with format!
    fn err(&mut self, pos: Pos, cond: &'static str, msg: String) {
        self.c
            .error(pos, cond, format!("rule '{}': {msg}", self.rn));
    }

    fn left_node(&mut self, name: &str, pos: Pos) -> Option<usize> {
        let Some(&k) = self.index.get(name) else {
            self.err(pos, "name", format!("unknown node '{name}'"));
            return None;
        };
        if self.nodes[k].left.is_none() {
            self.err(
                pos,
                "name",
                format!("node '{name}' is created by the rule: it has no value before it to read"),
            );
            return None;
        }
        Some(k)
    }

    fn emb(&mut self, name: &str, pos: Pos) -> Option<usize> {
        let k = self.embs.iter().position(|e| e.name == name);
        if k.is_none() {
            self.err(pos, "name", format!("unknown embedding '{name}'"));
        }
        k
    }

    fn expr(&mut self, e: &ast::Expr, env: &mut Env) -> Option<(TExpr, Ty)> {
        let pos = e.pos;
        Some(match &e.kind {
            ExprKind::Real(x) => (TExpr::Const(Val::F(*x)), Ty::F64),
            ExprKind::Int(i) => (TExpr::Const(Val::I(*i)), Ty::I64),
            ExprKind::Bool(b) => (TExpr::Const(Val::B(*b)), Ty::Bool),
            ExprKind::Name(n) => {
                if let Some(l) = env.locals.iter_mut().rev().find(|l| &l.0 == n) {
                    l.4 = true;
                    (TExpr::Local(l.2), l.1)
                } else if let Some(k) = env.params.iter().position(|p| &p.0 == n) {
                    env.used_params.insert(n.clone());
                    (TExpr::Param(k), env.params[k].1)
                } else {
                    let hint = if self.index.contains_key(n.as_str()) {
                        format!(" ('{n}' is a node: read an embedding with {n}.NAME)")
                    } else {
                        String::new()
                    };
                    self.err(
                        pos,
                        "name",
                        format!("unknown variable or parameter '{n}'{hint}"),
                    );
                    return None;
                }
            }
            ExprKind::Read { node, emb } => {
                let k = self.left_node(node, pos)?;
                let ei = self.emb(emb, pos)?;
                (TExpr::Read { node: k, emb: ei }, self.embs[ei].ty)
            }
            ExprKind::Aggregate {
                kind,
                orbit,
                node,
                emb,
            } => {
                let mut dims = Vec::new();
                for &i in orbit {
                    if i > self.dim as u64 {
                        self.err(
                            pos,
                            "dimension",
                            format!("aggregate orbit has dimension {i} outside 0..={}", self.dim),
                        );
                        return None;
                    }
                    dims.push(i as usize);
                }
                let Ok(o) = OrbitType::new(&dims) else {
                    self.err(
                        pos,
                        "duplicate-label",
                        "aggregate orbit repeats a dimension".into(),
                    );
                    return None;
                };
                let k = self.left_node(node, pos)?;
                let (ei, ty) = match (kind, emb) {
                    (AggKind::Count, None) => (None, Ty::I64),
                    (AggKind::Count, Some(em)) => (Some(self.emb(em, pos)?), Ty::I64),
                    (_, Some(em)) => {
                        let ei = self.emb(em, pos)?;
                        let t = self.embs[ei].ty;
                        if !(t.is_real() || t == Ty::I64 && *kind == AggKind::Sum) {
                            self.err(
                                pos,
                                "type",
                                format!(
                                    "cannot {} values of type {t}",
                                    if *kind == AggKind::Sum {
                                        "sum"
                                    } else {
                                        "average"
                                    }
                                ),
                            );
                            return None;
                        }
                        (
                            Some(ei),
                            if *kind == AggKind::Mean && t == Ty::I64 {
                                Ty::F64
                            } else {
                                t
                            },
                        )
                    }
                    (_, None) => unreachable!("parser requires an embedding"),
                };
                (
                    TExpr::Agg {
                        kind: *kind,
                        orbit: o,
                        node: k,
                        emb: ei,
                        ty,
                    },
                    ty,
                )
            }
            ExprKind::Binary(op, a, b) => {
                let meant = std::mem::take(&mut self.integer_quotient_meant);
                let (ea, ta) = self.expr(a, env)?;
                let (eb, tb) = self.expr(b, env)?;
                if *op == BinOp::Div && ta == Ty::I64 && tb == Ty::I64 && !meant {
                    // as a cut predicate refuses it (there it is always a mistake); here an
                    // integer quotient may be meant: a warning, silenced by to_i64(a / b)
                    self.c.warning(
                        pos,
                        "integer-division",
                        format!(
                            "rule '{}': a quotient of two integers is an integer, rounded toward zero (1 / 2 is 0, 7 / 2 is 3): write a real operand, e.g. 1.0 / 2, for the real quotient, or to_i64(a / b) where the integer quotient is meant",
                            self.rn
                        ),
                    );
                }
                match binop_type(*op, ta, tb) {
                    Ok(t) => (TExpr::Bin(*op, Box::new(ea), Box::new(eb)), t),
                    Err(m) => {
                        self.err(pos, "type", m);
                        return None;
                    }
                }
            }
            ExprKind::Unary(op, a) => {
                let (ea, ta) = self.expr(a, env)?;
                match unop_type(*op, ta) {
                    Ok(t) => (TExpr::Un(*op, Box::new(ea)), t),
                    Err(m) => {
                        self.err(pos, "type", m);
                        return None;
                    }
                }
            }
            ExprKind::Call { name, args } => {
                let mut es = Vec::new();
                let mut ts = Vec::new();
                for a in args {
                    // to_i64(a / b): the integer quotient written on purpose
                    self.integer_quotient_meant = name == "to_i64"
                        && args.len() == 1
                        && matches!(a.kind, ExprKind::Binary(BinOp::Div, ..));
                    let (ea, ta) = self.expr(a, env)?;
                    es.push(ea);
                    ts.push(ta);
                }
                match builtins::call_type(name, &ts) {
                    Ok(t) => {
                        if let Some(m) = constant_index_problem(name, &es, &ts) {
                            self.err(pos, "type", m);
                            return None;
                        }
                        (TExpr::Call(name.clone(), es), t)
                    }
                    Err(m) => {
                        self.err(
                            pos,
                            if m.contains("unknown") {
                                "name"
                            } else {
                                "type"
                            },
                            m,
                        );
                        return None;
                    }
                }
            }
            ExprKind::If(cnd, a, b) => {
                let (ec, tc) = self.expr(cnd, env)?;
                if tc != Ty::Bool {
                    self.err(
                        cnd.pos,
                        "type",
                        format!("an 'if' condition has type {tc}, expected bool"),
                    );
                    return None;
                }
                let (ea, ta) = self.expr(a, env)?;
                let (eb, tb) = self.expr(b, env)?;
                let (ea, eb, t) = unify(ea, ta, eb, tb).or_else(|| {
                    self.err(
                        pos,
                        "type",
                        format!("the branches of an 'if' have types {ta} and {tb}"),
                    );
                    None
                })?;
                (TExpr::If(Box::new(ec), Box::new(ea), Box::new(eb)), t)
            }
            ExprKind::Block(stmts, result) => {
                let mark = env.locals.len();
                let mut lets = Vec::new();
                for s in stmts {
                    if let Stmt::Let { name, value, pos } = s {
                        let (ev, tv) = self.expr(value, env)?;
                        let k = env.n_locals;
                        env.n_locals += 1;
                        env.locals.push((name.clone(), tv, k, *pos, false));
                        lets.push((k, ev));
                    }
                }
                let r = self.expr(result, env);
                for l in env.locals.drain(mark..) {
                    if !l.4 {
                        self.c.warning(
                            l.3,
                            "unused",
                            format!("rule '{}': variable '{}' is never used", self.rn, l.0),
                        );
                    }
                }
                let (er, tr) = r?;
                (TExpr::Block(lets, Box::new(er)), tr)
            }
        })
    }

    /// The orbit positions along which the value of `e` is known to be constant.
    fn uniform(&self, e: &TExpr, locals: &[HashSet<usize>], arity: usize) -> HashSet<usize> {
        let all: HashSet<usize> = (0..arity).collect();
        let along = |node: usize, o: OrbitType| -> HashSet<usize> {
            let l = self.nodes[node]
                .left
                .as_ref()
                .expect("read nodes are on the left");
            (0..arity)
                .filter(|&t| l[t].is_some_and(|i| o.contains(i as usize)))
                .collect()
        };
        match e {
            TExpr::Const(_) | TExpr::Param(_) => all,
            TExpr::Local(k) => locals.get(*k).cloned().unwrap_or(all),
            TExpr::Read { node, emb } => along(*node, self.embs[*emb].orbit),
            // over a sub-orbit of its embedding's orbit, an aggregate meets one orbit of the
            // embedding: its value is the embedding's there, constant on that whole orbit
            TExpr::Agg {
                orbit,
                node,
                emb: Some(e),
                ..
            } if orbit.is_subset_of(self.embs[*e].orbit) => along(*node, self.embs[*e].orbit),
            TExpr::Agg { orbit, node, .. } => along(*node, *orbit),
            TExpr::Bin(_, a, b) => {
                &self.uniform(a, locals, arity) & &self.uniform(b, locals, arity)
            }
            TExpr::Un(_, a) | TExpr::ToReal(a) => self.uniform(a, locals, arity),
            TExpr::Call(_, args) => args
                .iter()
                .fold(all, |acc, a| &acc & &self.uniform(a, locals, arity)),
            TExpr::If(c, a, b) => {
                &(&self.uniform(c, locals, arity) & &self.uniform(a, locals, arity))
                    & &self.uniform(b, locals, arity)
            }
            TExpr::Block(lets, r) => {
                let mut ls = locals.to_vec();
                for (k, v) in lets {
                    let u = self.uniform(v, &ls, arity);
                    if ls.len() <= *k {
                        ls.resize(*k + 1, all.clone());
                    }
                    ls[*k] = u;
                }
                self.uniform(r, &ls, arity)
            }
        }
    }
}

/// Calls `f` on `e` and on every expression inside it, parents before their operands.
// For the sibling crate (topomech-engine) only.
#[doc(hidden)]
pub fn visit(e: &TExpr, f: &mut dyn FnMut(&TExpr)) {
    f(e);
    match e {
        TExpr::Const(_)
        | TExpr::Param(_)
        | TExpr::Local(_)
        | TExpr::Read { .. }
        | TExpr::Agg { .. } => {}
        TExpr::Bin(_, a, b) => {
            visit(a, f);
            visit(b, f);
        }
        TExpr::Un(_, a) | TExpr::ToReal(a) => visit(a, f),
        TExpr::Call(_, args) => {
            for a in args {
                visit(a, f);
            }
        }
        TExpr::If(c, a, b) => {
            visit(c, f);
            visit(a, f);
            visit(b, f);
        }
        TExpr::Block(lets, r) => {
            for (_, v) in lets {
                visit(v, f);
            }
            visit(r, f);
        }
    }
}

/// The embeddings an expression reads, sorted, without repeats.
// For the sibling crate (topomech-engine) only.
#[doc(hidden)]
pub fn reads_of(e: &TExpr) -> Vec<usize> {
    let mut out = Vec::new();
    visit(e, &mut |x| match x {
        TExpr::Read { emb, .. } => out.push(*emb),
        TExpr::Agg { emb, .. } => out.extend(emb.iter().copied()),
        _ => {}
    });
    out.sort_unstable();
    out.dedup();
    out
}

/// Makes two branch types agree (promoting an integer to a real).
fn unify(a: TExpr, ta: Ty, b: TExpr, tb: Ty) -> Option<(TExpr, TExpr, Ty)> {
    match (ta, tb) {
        _ if ta == tb => Some((a, b, ta)),
        (Ty::I64, Ty::F64) => Some((TExpr::ToReal(Box::new(a)), b, Ty::F64)),
        (Ty::F64, Ty::I64) => Some((a, TExpr::ToReal(Box::new(b)), Ty::F64)),
        _ => None,
    }
}

/// The built-ins that take an entry, row, column or block of a matrix (or vector) at integer
/// indices.
const INDEXED: &[&str] = &[
    "get",
    "set",
    "elem",
    "row2",
    "row3",
    "col2",
    "col3",
    "block2",
    "block3",
    "set_block2",
    "set_block3",
    "vecn_get2",
    "vecn_get3",
];

/// Where every index of a call of [`INDEXED`] is a constant: the built-in's own error when
/// one lies outside the matrix (found by calling it on a zero matrix of the argument's type),
/// so that the checker refuses what every application would.
fn constant_index_problem(name: &str, args: &[TExpr], ts: &[Ty]) -> Option<String> {
    if !INDEXED.contains(&name) {
        return None;
    }
    let mut vals = Vec::with_capacity(args.len());
    for (e, &t) in args.iter().zip(ts) {
        vals.push(if t == Ty::I64 {
            Val::I(e.const_int()?)
        } else {
            Val::zero(t)
        });
    }
    builtins::call(name, &vals).err().map(|e| e.0)
}
