//! The parser: tokens to a [`File`](crate::ast::File). Recursive descent; the first error
//! stops it and names its line and column.

use crate::ast::{
    AggKind, ArcDecl, EmbeddingDecl, Expr, ExprKind, File, Graph, ModelArg, ModelArgKind,
    ModelDecl, ModelParam, NodeDecl, Param, Pos, RuleCall, RuleDecl, Stmt,
};
use crate::lexer::{lex, Tok};
use crate::value::{BinOp, UnOp};

/// A syntax error.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntaxError {
    /// Where.
    pub pos: Pos,
    /// What.
    pub message: String,
}

/// Parses a whole rule file.
pub fn parse(src: &str) -> Result<File, SyntaxError> {
    let toks = lex(src).map_err(|e| SyntaxError {
        pos: e.pos,
        message: e.message,
    })?;
    let mut p = Parser {
        toks,
        at: 0,
        depth: 0,
    };
    p.file()
}

/// Parses `src` as the body of a block with no braces: leading `let` bindings, then one
/// expression, then the end of the text. Anything after the expression (a `}`, a `rule`, a
/// second expression) is refused at its position. Used by
/// [`build::parse_expression`](crate::build::parse_expression).
pub(crate) fn parse_block_body(src: &str) -> Result<Expr, SyntaxError> {
    let toks = lex(src).map_err(|e| SyntaxError {
        pos: e.pos,
        message: e.message,
    })?;
    let mut p = Parser {
        toks,
        at: 0,
        depth: 0,
    };
    p.block_body_to_end()
}

/// A number as written (the lexer reads no sign, so it is never negative).
fn written(i: i64) -> u64 {
    i.unsigned_abs()
}

/// Deepest expression accepted, counted two ways, both refused above it with a syntax error
/// (never a stack overflow): the height of the tree built (a leaf is 1; a chain `a + b + ...`
/// of n terms is n, as every later pass walks it recursively), and the parser's own nesting
/// (parentheses, blocks, unary operators, `else if`).
pub const MAX_DEPTH: u32 = 256;

struct Parser {
    toks: Vec<(Tok, Pos)>,
    at: usize,
    depth: u32,
}

type R<T> = Result<T, SyntaxError>;

/// The refusal of the literal 9223372036854775808 (2^63) where it is not the magnitude of
/// the smallest i64 after its minus sign.
const INT_TOO_LARGE: &str = "integer '9223372036854775808' is too large (integers are i64: from -9223372036854775808 to 9223372036854775807; only the smallest may be written, with its minus sign)";

impl Parser {
    fn peek(&self) -> &Tok {
        &self.toks[self.at].0
    }

    fn peek_at(&self, k: usize) -> &Tok {
        &self.toks[(self.at + k).min(self.toks.len() - 1)].0
    }

    fn pos(&self) -> Pos {
        self.toks[self.at].1
    }

    fn bump(&mut self) -> (Tok, Pos) {
        let t = self.toks[self.at].clone();
        if self.at + 1 < self.toks.len() {
            self.at += 1;
        }
        t
    }

    fn err<T>(&self, message: impl Into<String>) -> R<T> {
        Err(SyntaxError {
            pos: self.pos(),
            message: message.into(),
        })
    }

    fn is_punct(&self, p: &str) -> bool {
        matches!(self.peek(), Tok::Punct(q) if *q == p)
    }

    fn is_kw(&self, k: &str) -> bool {
        matches!(self.peek(), Tok::Ident(s) if s == k)
    }

    fn eat_punct(&mut self, p: &str) -> bool {
        if self.is_punct(p) {
            self.bump();
            true
        } else {
            false
        }
    }

    fn expect_punct(&mut self, p: &str, what: &str) -> R<Pos> {
        if self.is_punct(p) {
            Ok(self.bump().1)
        } else {
            self.err(format!(
                "expected '{p}' {what}, found {}",
                self.peek().describe()
            ))
        }
    }

    fn ident(&mut self, what: &str) -> R<(String, Pos)> {
        match self.peek().clone() {
            Tok::Ident(s) => {
                let p = self.bump().1;
                Ok((s, p))
            }
            t => self.err(format!("expected {what}, found {}", t.describe())),
        }
    }

    fn int(&mut self, what: &str) -> R<(i64, Pos)> {
        match self.peek().clone() {
            Tok::Int(i) => {
                let p = self.bump().1;
                Ok((i, p))
            }
            Tok::IntMinMagnitude => self.err(INT_TOO_LARGE),
            t => self.err(format!("expected {what}, found {}", t.describe())),
        }
    }

    fn file(&mut self) -> R<File> {
        let mut f = File::default();
        loop {
            match self.peek().clone() {
                Tok::Eof => return Ok(f),
                Tok::Ident(k) if k == "dimension" => {
                    let p = self.bump().1;
                    let (n, npos) = self.int("a dimension (2 or 3)")?;
                    if f.dimension.is_some() {
                        return Err(SyntaxError {
                            pos: p,
                            message: "'dimension' given twice".into(),
                        });
                    }
                    f.dimension = Some((written(n), p));
                    f.dimensions.push((written(n), npos));
                    while let Tok::Int(m) = self.peek().clone() {
                        let mpos = self.bump().1;
                        if f.dimensions.iter().any(|d| d.0 == written(m)) {
                            return Err(SyntaxError {
                                pos: mpos,
                                message: format!("dimension {m} is written twice"),
                            });
                        }
                        f.dimensions.push((written(m), mpos));
                    }
                    self.eat_punct(";");
                }
                Tok::Ident(k) if k == "embedding" => {
                    let e = self.embedding()?;
                    f.embeddings.push(e);
                }
                Tok::Ident(k) if k == "rule" => {
                    let r = self.rule()?;
                    f.rules.push(r);
                }
                Tok::Ident(k) if k == "model" => {
                    let m = self.model()?;
                    f.models.push(m);
                }
                t => {
                    return self.err(format!(
                        "expected 'dimension', 'embedding', 'rule' or 'model', found {}",
                        t.describe()
                    ))
                }
            }
        }
    }

    /// A number with an optional sign, as a real.
    fn signed_number(&mut self, what: &str) -> R<f64> {
        let neg = self.eat_punct("-");
        let x = match self.peek().clone() {
            #[allow(clippy::cast_precision_loss)]
            Tok::Int(i) => i as f64,
            // -2^63, the smallest i64, exactly: negated below
            Tok::IntMinMagnitude if neg => 2f64.powi(63),
            Tok::IntMinMagnitude => return self.err(INT_TOO_LARGE),
            Tok::Real(x) => x,
            t => return self.err(format!("expected {what}, found {}", t.describe())),
        };
        self.bump();
        Ok(if neg { -x } else { x })
    }

    /// A model argument or default: a parameter name, a number or `vec3(x, y, z)`.
    fn model_arg(&mut self) -> R<ModelArg> {
        let pos = self.pos();
        if self.is_kw("vec3") && matches!(self.peek_at(1), Tok::Punct("(")) {
            self.bump();
            self.bump();
            let mut v = [0.0; 3];
            for (k, x) in v.iter_mut().enumerate() {
                *x = self.signed_number("a number in vec3(x, y, z)")?;
                if k < 2 {
                    self.expect_punct(",", "between the components of vec3(x, y, z)")?;
                }
            }
            self.expect_punct(")", "to close vec3(x, y, z)")?;
            return Ok(ModelArg {
                kind: ModelArgKind::Vec3(v),
                pos,
            });
        }
        if let Tok::Ident(name) = self.peek().clone() {
            self.bump();
            return Ok(ModelArg {
                kind: ModelArgKind::Param(name),
                pos,
            });
        }
        let x = self.signed_number("a model parameter, a number or vec3(x, y, z)")?;
        Ok(ModelArg {
            kind: ModelArgKind::Number(x),
            pos,
        })
    }

    /// `rule(arg, ...), rule, ...`: one or more rule calls separated by commas.
    fn rule_calls(&mut self) -> R<Vec<RuleCall>> {
        let mut calls = Vec::new();
        loop {
            let (rule, pos) = self.ident("a rule name")?;
            let mut args = Vec::new();
            if self.eat_punct("(") && !self.eat_punct(")") {
                loop {
                    args.push(self.model_arg()?);
                    if self.eat_punct(")") {
                        break;
                    }
                    self.expect_punct(",", "between arguments")?;
                }
            }
            calls.push(RuleCall { rule, args, pos });
            if !self.eat_punct(",") {
                return Ok(calls);
            }
        }
    }

    /// `name, name, ...`: one or more embedding names separated by commas.
    fn names(&mut self, what: &str) -> R<Vec<(String, Pos)>> {
        let mut v = vec![self.ident(what)?];
        while self.eat_punct(",") {
            v.push(self.ident(what)?);
        }
        Ok(v)
    }

    /// `model name(p: f64 = 1.0, ...) { init ... step ... forces ... [jvp ... -> ...]
    /// [needs "..."] [per_element] }`
    fn model(&mut self) -> R<ModelDecl> {
        let pos = self.bump().1;
        let (name, _) = self.ident("a model name")?;
        let mut params = Vec::new();
        if self.eat_punct("(") && !self.eat_punct(")") {
            loop {
                let (pname, ppos) = self.ident("a parameter name")?;
                self.expect_punct(":", "after the parameter name")?;
                let ty = self.ident("a parameter type (f64 or vec3)")?.0;
                let default = if self.eat_punct("=") {
                    Some(self.model_arg()?)
                } else {
                    None
                };
                params.push(ModelParam {
                    name: pname,
                    ty,
                    default,
                    pos: ppos,
                });
                if self.eat_punct(")") {
                    break;
                }
                self.expect_punct(",", "between parameters")?;
            }
        }
        self.expect_punct("{", "to open the model")?;
        let mut m = ModelDecl {
            name,
            params,
            init: Vec::new(),
            step: Vec::new(),
            forces: Vec::new(),
            jvp: Vec::new(),
            jvp_outputs: Vec::new(),
            needs: None,
            per_element: None,
            pos,
        };
        let mut seen: Vec<String> = Vec::new();
        loop {
            if self.eat_punct("}") {
                return Ok(m);
            }
            let expected = "'init', 'step', 'forces', 'jvp', 'needs', 'per_element' or '}'";
            let (kw, kpos) = self.ident(expected)?;
            if seen.contains(&kw) {
                let hint = match kw.as_str() {
                    "init" | "step" | "jvp" => format!(
                        ": list its rules on one line, separated by commas, as in '{kw} a(k), b'"
                    ),
                    "forces" => ": list the embeddings on one line, separated by commas".into(),
                    _ => String::new(),
                };
                return Err(SyntaxError {
                    pos: kpos,
                    message: format!("'{kw}' given twice in model '{}'{hint}", m.name),
                });
            }
            match kw.as_str() {
                "init" => m.init = self.rule_calls()?,
                "step" => m.step = self.rule_calls()?,
                "forces" => m.forces = self.names("a force embedding name")?,
                "jvp" => {
                    m.jvp = self.rule_calls()?;
                    self.expect_punct("-", "then '>' after the jvp rules, as in 'jvp r -> df_r'")?;
                    self.expect_punct(">", "after '-', as in 'jvp r -> df_r'")?;
                    m.jvp_outputs = self.names("a jvp output embedding name")?;
                }
                "needs" => match self.peek().clone() {
                    Tok::Str(s) => {
                        let p = self.bump().1;
                        m.needs = Some((s, p));
                    }
                    t => {
                        return self.err(format!(
                            "expected a string after 'needs', as in needs \"tetrahedra\", found {}",
                            t.describe()
                        ))
                    }
                },
                "per_element" => m.per_element = Some(kpos),
                other => {
                    return Err(SyntaxError {
                        pos: kpos,
                        message: format!("expected {expected}, found '{other}'"),
                    })
                }
            }
            seen.push(kw);
            self.eat_punct(";");
        }
    }

    fn orbit_dims(&mut self) -> R<Vec<u64>> {
        self.expect_punct("<", "to open an orbit")?;
        let mut v = Vec::new();
        if self.eat_punct(">") {
            return Ok(v);
        }
        loop {
            let (i, _) = self.int("a dimension in the orbit")?;
            v.push(written(i));
            if self.eat_punct(">") {
                return Ok(v);
            }
            self.expect_punct(",", "between orbit dimensions")?;
        }
    }

    fn type_name(&mut self) -> R<String> {
        Ok(self
            .ident("a type (f64, i64, bool, vec2, vec3, matN, matRxC)")?
            .0)
    }

    /// `embedding name : type on <o> [policy p] [derived agg(source)]`
    fn embedding(&mut self) -> R<EmbeddingDecl> {
        let pos = self.bump().1;
        let (name, _) = self.ident("an embedding name")?;
        self.expect_punct(":", "after the embedding name")?;
        let ty = self.type_name()?;
        if !self.is_kw("on") {
            return self.err(format!(
                "expected 'on' and an orbit after the type, found {}",
                self.peek().describe()
            ));
        }
        self.bump();
        let orbit = self.orbit_dims()?;
        let mut decl = EmbeddingDecl {
            name,
            ty,
            orbit,
            policy: None,
            derived: None,
            pos,
        };
        loop {
            if self.is_kw("policy") {
                self.bump();
                decl.policy = Some(self.ident("a policy (copy, sum, mean, error)")?.0);
            } else if self.is_kw("derived") {
                self.bump();
                let (agg, _) = self.ident("an aggregate (sum, mean, count)")?;
                self.expect_punct("(", "around the source embedding")?;
                let (src, _) = self.ident("the source embedding")?;
                self.expect_punct(")", "after the source embedding")?;
                decl.derived = Some((agg, src));
            } else {
                break;
            }
        }
        self.eat_punct(";");
        Ok(decl)
    }

    fn rule(&mut self) -> R<RuleDecl> {
        let pos = self.bump().1;
        let (name, _) = self.ident("a rule name")?;
        let mut params = Vec::new();
        if self.eat_punct("(") && !self.eat_punct(")") {
            {
                loop {
                    let (pname, ppos) = self.ident("a parameter name")?;
                    self.expect_punct(":", "after the parameter name")?;
                    let ty = self.type_name()?;
                    params.push(Param {
                        name: pname,
                        ty,
                        pos: ppos,
                    });
                    if self.eat_punct(")") {
                        break;
                    }
                    self.expect_punct(",", "between parameters")?;
                }
            }
        }
        self.expect_punct("{", "to open the rule")?;
        let mut r = RuleDecl {
            name,
            params,
            left: None,
            right: None,
            compute: Vec::new(),
            guard: None,
            pos,
        };
        loop {
            if self.eat_punct("}") {
                return Ok(r);
            }
            let (kw, kpos) = self.ident("'left', 'right', 'compute', 'where' or '}'")?;
            let dup = |what: &str| SyntaxError {
                pos: kpos,
                message: format!("'{what}' given twice in one rule"),
            };
            match kw.as_str() {
                "left" => {
                    if r.left.is_some() {
                        return Err(dup("left"));
                    }
                    r.left = Some(self.graph(kpos)?);
                }
                "right" => {
                    if r.right.is_some() {
                        return Err(dup("right"));
                    }
                    r.right = Some(self.graph(kpos)?);
                }
                "compute" => {
                    self.expect_punct("{", "to open the compute block")?;
                    while !self.eat_punct("}") {
                        let s = self.stmt()?;
                        r.compute.push(s);
                    }
                }
                "where" => {
                    if r.guard.is_some() {
                        return Err(dup("where"));
                    }
                    r.guard = Some(self.expr()?);
                    self.eat_punct(";");
                }
                other => {
                    return Err(SyntaxError {
                        pos: kpos,
                        message: format!(
                            "expected 'left', 'right', 'compute', 'where' or '}}', found '{other}'"
                        ),
                    })
                }
            }
        }
    }

    fn graph(&mut self, pos: Pos) -> R<Graph> {
        self.expect_punct("{", "to open the graph")?;
        let mut g = Graph {
            pos,
            ..Graph::default()
        };
        loop {
            if self.eat_punct("}") {
                return Ok(g);
            }
            let (a, apos) = self.ident("a node name or '}'")?;
            if self.eat_punct(":") {
                let orbit_pos = self.pos();
                self.expect_punct("<", "to open the node's orbit type")?;
                let mut orbit = Vec::new();
                if !self.eat_punct(">") {
                    loop {
                        if self.eat_punct("_") {
                            orbit.push(None);
                        } else {
                            let (i, _) = self.int("a dimension or '_'")?;
                            orbit.push(Some(written(i)));
                        }
                        if self.eat_punct(">") {
                            break;
                        }
                        self.expect_punct(",", "between orbit labels")?;
                    }
                }
                let hook = if self.is_kw("hook") {
                    self.bump();
                    true
                } else {
                    false
                };
                g.nodes.push(NodeDecl {
                    name: a,
                    orbit,
                    hook,
                    pos: apos,
                    orbit_pos,
                });
            } else if self.eat_punct("-") {
                let (d, _) = self.int("the arc's dimension, as in a -2- b")?;
                self.expect_punct("-", "after the arc's dimension, as in a -2- b")?;
                let (b, _) = self.ident("the arc's second node")?;
                g.arcs.push(ArcDecl {
                    a,
                    dim: written(d),
                    b,
                    pos: apos,
                });
            } else {
                return self.err(format!(
                    "expected ':' (a node) or '-' (an arc) after '{a}', found {}",
                    self.peek().describe()
                ));
            }
            self.eat_punct(";");
            self.eat_punct(",");
        }
    }

    fn stmt(&mut self) -> R<Stmt> {
        let pos = self.pos();
        if self.is_kw("let") {
            self.bump();
            let (name, _) = self.ident("a variable name")?;
            self.expect_punct("=", "after the variable name")?;
            let value = self.expr()?;
            self.eat_punct(";");
            return Ok(Stmt::Let { name, value, pos });
        }
        let (node, _) = self.ident("'let' or a write 'node.embedding = ...'")?;
        self.expect_punct(".", "in a write 'node.embedding = ...'")?;
        let (emb, _) = self.ident("an embedding name")?;
        self.expect_punct("=", "in a write 'node.embedding = ...'")?;
        let value = self.expr()?;
        self.eat_punct(";");
        Ok(Stmt::Write {
            node,
            emb,
            value,
            pos,
        })
    }

    /// An expression: its tree, checked against [`MAX_DEPTH`].
    fn expr(&mut self) -> R<Expr> {
        Ok(self.expr_h()?.0)
    }

    /// Enters one level of the parser's own recursion (parentheses, blocks, unary operators,
    /// `else if`), refusing more than [`MAX_DEPTH`] levels.
    fn enter(&mut self) -> R<()> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return self.err(format!(
                "expression nested too deeply: depth {}, the limit is {MAX_DEPTH}",
                self.depth
            ));
        }
        Ok(())
    }

    fn leave(&mut self) {
        self.depth -= 1;
    }

    /// A node of height `h` (1 for a leaf, 1 + the tallest child otherwise) at `pos`,
    /// refused above [`MAX_DEPTH`]: every later pass walks expressions recursively, so no tree
    /// taller than the limit is ever built (a chain `a + b + ...` of n terms has height n).
    fn node(pos: Pos, kind: ExprKind, h: u32) -> R<(Expr, u32)> {
        if h > MAX_DEPTH {
            return Err(SyntaxError {
                pos,
                message: format!(
                    "expression nested too deeply: depth {h}, the limit is {MAX_DEPTH}"
                ),
            });
        }
        Ok((Expr { kind, pos }, h))
    }

    /// An expression and its height.
    fn expr_h(&mut self) -> R<(Expr, u32)> {
        self.binary(0)
    }

    fn binary(&mut self, min_prec: u8) -> R<(Expr, u32)> {
        let (mut lhs, mut lh) = self.unary()?;
        loop {
            let Some((op, prec)) = self.binop() else {
                return Ok((lhs, lh));
            };
            if prec < min_prec {
                return Ok((lhs, lh));
            }
            let pos = self.bump().1;
            let (rhs, rh) = self.binary(prec + 1)?;
            (lhs, lh) = Self::node(
                pos,
                ExprKind::Binary(op, Box::new(lhs), Box::new(rhs)),
                1 + lh.max(rh),
            )?;
        }
    }

    fn binop(&self) -> Option<(BinOp, u8)> {
        let Tok::Punct(p) = self.peek() else {
            return None;
        };
        Some(match *p {
            "||" => (BinOp::Or, 1),
            "&&" => (BinOp::And, 2),
            "==" => (BinOp::Eq, 3),
            "!=" => (BinOp::Ne, 3),
            "<" => (BinOp::Lt, 4),
            "<=" => (BinOp::Le, 4),
            ">" => (BinOp::Gt, 4),
            ">=" => (BinOp::Ge, 4),
            "+" => (BinOp::Add, 5),
            "-" => (BinOp::Sub, 5),
            "*" => (BinOp::Mul, 6),
            "/" => (BinOp::Div, 6),
            "%" => (BinOp::Rem, 6),
            _ => return None,
        })
    }

    fn unary(&mut self) -> R<(Expr, u32)> {
        self.enter()?;
        let r = self.unary_inner();
        self.leave();
        r
    }

    fn unary_inner(&mut self) -> R<(Expr, u32)> {
        let pos = self.pos();
        let op = if self.eat_punct("-") {
            // `-9223372036854775808`: the smallest i64, whose magnitude no i64 holds
            if *self.peek() == Tok::IntMinMagnitude {
                self.bump();
                return Self::node(pos, ExprKind::Int(i64::MIN), 1);
            }
            UnOp::Neg
        } else if self.eat_punct("!") {
            UnOp::Not
        } else {
            return self.primary();
        };
        let (e, h) = self.unary()?;
        Self::node(pos, ExprKind::Unary(op, Box::new(e)), 1 + h)
    }

    fn primary(&mut self) -> R<(Expr, u32)> {
        let pos = self.pos();
        let (tok, _) = self.bump();
        let (kind, h) = match tok {
            Tok::Int(i) => (ExprKind::Int(i), 1),
            Tok::IntMinMagnitude => {
                return Err(SyntaxError {
                    pos,
                    message: INT_TOO_LARGE.into(),
                })
            }
            Tok::Real(x) => (ExprKind::Real(x), 1),
            Tok::Punct("(") => {
                let e = self.expr_h()?;
                self.expect_punct(")", "to close the parenthesis")?;
                return Ok(e);
            }
            Tok::Punct("{") => return self.block(pos),
            Tok::Ident(s) => match s.as_str() {
                "true" => (ExprKind::Bool(true), 1),
                "false" => (ExprKind::Bool(false), 1),
                "if" => {
                    let (c, hc) = self.expr_h()?;
                    let open = self.pos();
                    self.expect_punct("{", "to open the 'if' branch")?;
                    let (a, ha) = self.block(open)?;
                    if !self.is_kw("else") {
                        return self.err("an 'if' expression needs an 'else' branch");
                    }
                    self.bump();
                    let (b, hb) = if self.is_kw("if") {
                        self.enter()?;
                        let r = self.primary();
                        self.leave();
                        r?
                    } else {
                        let open = self.pos();
                        self.expect_punct("{", "to open the 'else' branch")?;
                        self.block(open)?
                    };
                    (
                        ExprKind::If(Box::new(c), Box::new(a), Box::new(b)),
                        1 + hc.max(ha).max(hb),
                    )
                }
                "sum" | "mean" | "count" if self.is_punct("<") => {
                    let kind = match s.as_str() {
                        "sum" => AggKind::Sum,
                        "mean" => AggKind::Mean,
                        _ => AggKind::Count,
                    };
                    let orbit = self.orbit_dims()?;
                    self.expect_punct("(", "around the aggregate's argument")?;
                    let (node, _) = self.ident("a node name")?;
                    let emb = if kind == AggKind::Count && !self.is_punct(".") {
                        None
                    } else {
                        self.expect_punct(".", "in 'node.embedding'")?;
                        Some(self.ident("an embedding name")?.0)
                    };
                    self.expect_punct(")", "to close the aggregate")?;
                    (
                        ExprKind::Aggregate {
                            kind,
                            orbit,
                            node,
                            emb,
                        },
                        1,
                    )
                }
                _ if self.is_punct("(") => {
                    self.bump();
                    let mut args = Vec::new();
                    let mut h = 0;
                    if !self.eat_punct(")") {
                        loop {
                            let (a, ha) = self.expr_h()?;
                            args.push(a);
                            h = h.max(ha);
                            if self.eat_punct(")") {
                                break;
                            }
                            self.expect_punct(",", "between arguments")?;
                        }
                    }
                    (ExprKind::Call { name: s, args }, 1 + h)
                }
                _ if self.is_punct(".") && matches!(self.peek_at(1), Tok::Ident(_)) => {
                    self.bump();
                    let (emb, _) = self.ident("an embedding name")?;
                    (ExprKind::Read { node: s, emb }, 1)
                }
                _ => (ExprKind::Name(s), 1),
            },
            t => {
                return Err(SyntaxError {
                    pos,
                    message: format!("expected an expression, found {}", t.describe()),
                })
            }
        };
        Self::node(pos, kind, h)
    }

    /// `let x = e;` bindings (the `;` optional), with the height of their values.
    fn let_bindings(&mut self) -> R<(Vec<Stmt>, u32)> {
        let mut stmts = Vec::new();
        let mut h = 0;
        while self.is_kw("let") {
            let spos = self.pos();
            self.bump();
            let (name, _) = self.ident("a variable name")?;
            self.expect_punct("=", "after the variable name")?;
            let (value, hv) = self.expr_h()?;
            h = h.max(hv);
            self.eat_punct(";");
            stmts.push(Stmt::Let {
                name,
                value,
                pos: spos,
            });
        }
        Ok((stmts, h))
    }

    /// Leading `let` bindings and one expression, then the end of the text.
    fn block_body_to_end(&mut self) -> R<Expr> {
        let start = self.pos();
        let (stmts, h) = self.let_bindings()?;
        let (e, he) = self.expr_h()?;
        if !matches!(self.peek(), Tok::Eof) {
            return self.err(format!(
                "expected the end of the expression, found {} (one expression is expected here, after optional 'let' bindings; rule syntax is not allowed)",
                self.peek().describe()
            ));
        }
        if stmts.is_empty() {
            Ok(e)
        } else {
            Ok(Self::node(start, ExprKind::Block(stmts, Box::new(e)), 1 + h.max(he))?.0)
        }
    }

    /// `{ let x = e; ...; result }` (the `{` is consumed).
    fn block(&mut self, pos: Pos) -> R<(Expr, u32)> {
        let (stmts, h) = self.let_bindings()?;
        let (e, he) = self.expr_h()?;
        self.expect_punct("}", "to close the block")?;
        if stmts.is_empty() {
            Ok((e, he))
        } else {
            Self::node(pos, ExprKind::Block(stmts, Box::new(e)), 1 + h.max(he))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The example of the language's specification, as written there.
    const EXAMPLE: &str = include_str!("../../rules/tests/it/spec_example.tmr");

    /// The smallest i64 is written with its minus sign wherever a number goes: in an
    /// expression (the integer) and as a model default or argument (the real -2^63,
    /// exactly). 2^63 anywhere else (unsigned, after a binary minus, as an orbit label, an
    /// arc or a dimension) is refused saying it is too large and what the range is.
    #[test]
    fn the_smallest_integer_and_its_magnitude() {
        let f = parse(
            "model m(k: f64 = -9223372036854775808, d: vec3 = vec3(0, -9223372036854775808, 0)) { init r(-9223372036854775808) }",
        )
        .unwrap();
        let m = &f.models[0];
        let minus = -(2f64.powi(63));
        assert_eq!(
            m.params[0].default.as_ref().map(|a| a.kind.clone()),
            Some(ModelArgKind::Number(minus))
        );
        assert_eq!(
            m.params[1].default.as_ref().map(|a| a.kind.clone()),
            Some(ModelArgKind::Vec3([0.0, minus, 0.0]))
        );
        assert_eq!(m.init[0].args[0].kind, ModelArgKind::Number(minus));
        let r = parse("rule r { left { a : <> hook } compute { a.k = -9223372036854775808 } }")
            .unwrap();
        let body = format!("{:?}", r.rules[0].compute);
        assert!(body.contains("Int(-9223372036854775808)"), "{body}");
        for src in [
            "model m(k: f64 = 9223372036854775808) { }",
            "rule r { left { a : <9223372036854775808> hook } compute { } }",
            "rule r { left { a : <> hook  b : <>  a -9223372036854775808- b } compute { } }",
            "dimension 9223372036854775808",
            "rule r { left { a : <> hook } compute { a.k = 1 - 9223372036854775808 } }",
        ] {
            let e = parse(src).unwrap_err();
            assert!(
                e.message.contains("'9223372036854775808' is too large")
                    && e.message
                        .contains("from -9223372036854775808 to 9223372036854775807"),
                "{src}: {}",
                e.message
            );
        }
    }

    #[test]
    fn the_issue_example_parses() {
        let f = parse(EXAMPLE).unwrap();
        assert_eq!(f.dimension.map(|d| d.0), Some(2));
        assert_eq!(f.embeddings.len(), 2);
        assert_eq!(f.rules.len(), 3);
        let t = &f.rules[1];
        let right = t.right.as_ref().unwrap();
        assert_eq!(right.nodes[0].orbit, vec![Some(0), None]);
        assert_eq!(right.arcs.len(), 2);
        assert_eq!(right.arcs[1].dim, 0);
        assert!(f.rules[2].left.as_ref().unwrap().nodes[0].hook);
    }

    #[test]
    fn params_guards_and_expressions() {
        let f = parse(
            "rule integrate(dt: f64, gravity: vec3) {
               left { v : <1,2> hook }
               where v.mass > 0.0 && !(dt <= 0)
               compute {
                 let a = gravity + v.force / v.mass
                 v.velocity = v.velocity + dt * a;
                 v.position = if dt > 1 { v.position } else { v.position + dt * v.velocity }
               }
             }",
        )
        .unwrap();
        let r = &f.rules[0];
        assert_eq!(r.params.len(), 2);
        assert!(r.guard.is_some());
        assert_eq!(r.compute.len(), 3);
    }

    #[test]
    fn errors_name_line_and_column() {
        let e = parse("dimension 2\nrule r {\n  left { a <0> }\n}").unwrap_err();
        assert_eq!(e.pos, Pos { line: 3, col: 12 });
        assert!(e.message.contains("expected ':'"), "{}", e.message);
        let e = parse("rule r { left { a : <0> hook } compute { a.w = (1 + } }").unwrap_err();
        assert!(
            e.message.contains("expected an expression"),
            "{}",
            e.message
        );
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_crash() {
        let src = format!(
            "rule r {{ left {{ a : <0> hook }} compute {{ a.w = {}1{} }} }}",
            "(".repeat(5000),
            ")".repeat(5000)
        );
        assert!(parse(&src).unwrap_err().message.contains("too deeply"));
        let src = format!(
            "rule r {{ left {{ a : <0> hook }} compute {{ a.w = {}1 }} }}",
            "-".repeat(5000)
        );
        assert!(parse(&src).unwrap_err().message.contains("too deeply"));
    }
}
