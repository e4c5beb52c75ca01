//! The syntax tree of a rule file, with source positions.

use crate::value::{BinOp, UnOp};

/// A position in a source file (1-based line and column).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, PartialOrd, Ord, Hash)]
pub struct Pos {
    /// Line, from 1.
    pub line: u32,
    /// Column, from 1 (in characters).
    pub col: u32,
}

/// An orbit label of a checked rule: a dimension, or `_` (a deleted implicit arc).
pub type Label = Option<u8>;

/// An orbit label as written: a dimension (the number the user wrote, however large), or `_`.
pub type WrittenLabel = Option<u64>;

/// A node declaration in a left or right graph.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeDecl {
    /// Its name.
    pub name: String,
    /// Its orbit type, position by position, as written.
    pub orbit: Vec<WrittenLabel>,
    /// Whether it is marked `hook`.
    pub hook: bool,
    /// Where it is declared.
    pub pos: Pos,
    /// Where its orbit type starts.
    pub orbit_pos: Pos,
}

/// An explicit arc `a -i- b`.
#[derive(Clone, Debug, PartialEq)]
pub struct ArcDecl {
    /// One end.
    pub a: String,
    /// The dimension, as written (checked against the map's dimension later).
    pub dim: u64,
    /// The other end.
    pub b: String,
    /// Where it is written.
    pub pos: Pos,
}

/// A left or right graph.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Graph {
    /// Its nodes.
    pub nodes: Vec<NodeDecl>,
    /// Its explicit arcs.
    pub arcs: Vec<ArcDecl>,
    /// Where the graph starts.
    pub pos: Pos,
}

/// An expression.
#[derive(Clone, Debug, PartialEq)]
pub struct Expr {
    /// What it is.
    pub kind: ExprKind,
    /// Where it starts.
    pub pos: Pos,
}

/// The kinds of expressions.
#[derive(Clone, Debug, PartialEq)]
pub enum ExprKind {
    /// A real literal.
    Real(f64),
    /// An integer literal.
    Int(i64),
    /// `true` / `false`.
    Bool(bool),
    /// A variable, parameter or (as an aggregate argument) node name.
    Name(String),
    /// `node.embedding`.
    Read {
        /// The node.
        node: String,
        /// The embedding.
        emb: String,
    },
    /// `f(args)`.
    Call {
        /// The function.
        name: String,
        /// Its arguments.
        args: Vec<Expr>,
    },
    /// `sum<o>(n.e)`, `mean<o>(n.e)`, `count<o>(n)` (darts), `count<o>(n.e)` (distinct orbits of e).
    Aggregate {
        /// `sum`, `mean` or `count`.
        kind: AggKind,
        /// The orbit, as written.
        orbit: Vec<u64>,
        /// The node.
        node: String,
        /// The embedding (absent for `count`).
        emb: Option<String>,
    },
    /// `a op b`.
    Binary(BinOp, Box<Expr>, Box<Expr>),
    /// `op a`.
    Unary(UnOp, Box<Expr>),
    /// `if c { a } else { b }`.
    If(Box<Expr>, Box<Expr>, Box<Expr>),
    /// `{ let x = e; ... ; result }`.
    Block(Vec<Stmt>, Box<Expr>),
}

/// The aggregates over orbits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AggKind {
    /// Sum over the distinct embedding orbits.
    Sum,
    /// Mean over the distinct embedding orbits.
    Mean,
    /// Number of distinct orbits.
    Count,
}

/// A statement of a `compute` block.
#[derive(Clone, Debug, PartialEq)]
pub enum Stmt {
    /// `let x = e`.
    Let {
        /// The variable.
        name: String,
        /// Its value.
        value: Expr,
        /// Where.
        pos: Pos,
    },
    /// `n.e = value`.
    Write {
        /// The node.
        node: String,
        /// The embedding.
        emb: String,
        /// The value.
        value: Expr,
        /// Where.
        pos: Pos,
    },
}

/// A rule parameter `name: type`.
#[derive(Clone, Debug, PartialEq)]
pub struct Param {
    /// Its name.
    pub name: String,
    /// Its type, as written.
    pub ty: String,
    /// Where.
    pub pos: Pos,
}

/// A rule.
#[derive(Clone, Debug, PartialEq)]
pub struct RuleDecl {
    /// Its name.
    pub name: String,
    /// Its parameters.
    pub params: Vec<Param>,
    /// The left graph.
    pub left: Option<Graph>,
    /// The right graph (absent: same as the left; the rule only computes).
    pub right: Option<Graph>,
    /// The statements of its `compute` block.
    pub compute: Vec<Stmt>,
    /// Its `where` guard.
    pub guard: Option<Expr>,
    /// Where it is declared.
    pub pos: Pos,
}

/// An embedding declaration.
#[derive(Clone, Debug, PartialEq)]
pub struct EmbeddingDecl {
    /// Its name.
    pub name: String,
    /// Its type, as written.
    pub ty: String,
    /// Its orbit, as written.
    pub orbit: Vec<u64>,
    /// Its merge/split policy, as written (`copy` by default).
    pub policy: Option<String>,
    /// For a derived embedding: the aggregate and the source embedding.
    pub derived: Option<(String, String)>,
    /// Where.
    pub pos: Pos,
}

/// A constant or parameter given to a rule by a model declaration.
#[derive(Clone, Debug, PartialEq)]
pub enum ModelArgKind {
    /// A model parameter, by name.
    Param(String),
    /// A number (`1`, `-2.5e3`).
    Number(f64),
    /// A vector `vec3(x, y, z)` of numbers.
    Vec3([f64; 3]),
}

/// An argument of a rule call in a model declaration, with its position.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelArg {
    /// What it is.
    pub kind: ModelArgKind,
    /// Where.
    pub pos: Pos,
}

/// A model parameter `name: type [= default]`.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelParam {
    /// Its name.
    pub name: String,
    /// Its type, as written (`f64` or `vec3`).
    pub ty: String,
    /// Its default (absent: the parameter is required).
    pub default: Option<ModelArg>,
    /// Where.
    pub pos: Pos,
}

/// A rule call `rule(arg, ...)` (or a bare `rule` for a rule without parameters).
#[derive(Clone, Debug, PartialEq)]
pub struct RuleCall {
    /// The rule's name.
    pub rule: String,
    /// Its arguments, in the rule's parameter order.
    pub args: Vec<ModelArg>,
    /// Where.
    pub pos: Pos,
}

/// A `model name(params) { init ... step ... forces ... jvp ... -> ... needs "..." per_element }`
/// declaration.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelDecl {
    /// Its name.
    pub name: String,
    /// Its parameters.
    pub params: Vec<ModelParam>,
    /// Rules applied once at set-up, everywhere, in order.
    pub init: Vec<RuleCall>,
    /// Rules applied every step, everywhere, in order.
    pub step: Vec<RuleCall>,
    /// The force embeddings summed into each vertex's `force`.
    pub forces: Vec<(String, Pos)>,
    /// Rules computing the Jacobian-vector product, in order.
    pub jvp: Vec<RuleCall>,
    /// The embeddings the Jacobian-vector product rules write.
    pub jvp_outputs: Vec<(String, Pos)>,
    /// What the model needs of the mesh, said when it matches nothing.
    pub needs: Option<(String, Pos)>,
    /// Where `per_element` is written: every element must be matched by the init rules.
    pub per_element: Option<Pos>,
    /// Where it is declared.
    pub pos: Pos,
}

/// A whole rule file.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct File {
    /// `dimension n`, with its position (the first dimension when several are written).
    pub dimension: Option<(u64, Pos)>,
    /// Every dimension written on the `dimension` line (`dimension 2 3`: the file serves
    /// 2-maps and 3-maps), with their positions.
    pub dimensions: Vec<(u64, Pos)>,
    /// Its embeddings.
    pub embeddings: Vec<EmbeddingDecl>,
    /// Its rules.
    pub rules: Vec<RuleDecl>,
    /// Its model declarations.
    pub models: Vec<ModelDecl>,
}
