//! Compiled plans: computation rules evaluated over flat arrays.
//!
//! A rule that changes no topology has matches that depend only on the topology (and on the
//! embeddings its guard reads). The engine finds them once, then *compiles* the rule and its
//! matches into a plan:
//!
//! - the **domain**: one row per value to compute (a match's row that represents a class of
//!   rows sharing a value, as in the interpreter);
//! - **gather index arrays**: for every `node.emb` the rule reads, the slot of that
//!   embedding for each domain row; for every aggregate, the distinct slots of its orbit
//!   (compressed rows); counts are computed once;
//! - a **program**: the rule's expressions as a list of operations over registers, each
//!   register a fixed number of `f64` per row (its type's width);
//! - **scatter targets**: for every write, the slot each domain row writes.
//!
//! Evaluation runs the program over chunks of rows (each operation a tight loop over the
//! chunk), in parallel on rayon's pool when there are enough rows, with one scratch buffer per
//! thread: no orbit walk, no hash map and no allocation per row (a run allocates only a few
//! short lists: its parameters and columns). The plan is a cache derived
//! from the map: it is rebuilt when the topology version changes (see [`crate::RuleSet`]).
//!
//! The program can also be compiled to native code by a backend (see [`crate::native`];
//! `topomech-codegen` generates it with Cranelift), which the plan then runs per chunk
//! instead of the evaluator here: the same results, bit for bit; the evaluator stays the
//! reference and the fallback.
//!
//! Nothing here knows any model: any rule compiles the same way. A rule using what the plan
//! machinery does not cover (integer arithmetic, reads of integer embeddings) is run by the
//! interpreter instead, and so is an application whose evaluation fails (a built-in refusing
//! its argument, two matches writing different values to one orbit): the interpreter then
//! reports the error precisely, with the dart.

use std::cell::RefCell;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use rayon::prelude::*;
use topomech_gmap::{ColumnMut, ColumnRef, Dart, EmbeddingId, GMap, Marks, OrbitType};

use crate::ast::AggKind;
use crate::builtins;
use crate::check::{EmbDecl, Rule, TExpr, TStmt};
use crate::engine::Match;
use crate::native::{self, ColKind, JitArgs, NativeBackend, NativeFn, OutLayout};
use crate::value::{binop_type, unop_type, BinOp, Ty, UnOp, Val};

/// Why a rule or an application is left to the interpreter.
#[derive(Debug)]
pub(crate) struct Unsupported(#[allow(dead_code)] pub String);

// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub type R = usize;
type F1Fn = fn(f64) -> f64;

/// Binary element-wise operations.
#[derive(Clone, Copy, Debug)]
// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub enum Ew {
    Add,
    Sub,
    Mul,
    Div,
    Rem,
}

impl Ew {
    #[inline]
    pub fn apply(self, x: f64, y: f64) -> f64 {
        match self {
            Ew::Add => x + y,
            Ew::Sub => x - y,
            Ew::Mul => x * y,
            Ew::Div => x / y,
            Ew::Rem => x % y,
        }
    }
}

#[derive(Clone, Copy, Debug)]
// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub enum Cmp {
    Lt,
    Le,
    Gt,
    Ge,
}

/// Built-ins with a flat implementation (the same arithmetic as [`builtins::call`]).
#[derive(Clone, Copy, Debug)]
// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub enum Fast {
    Dot,
    Norm,
    Norm2,
    Cross3,
    Cross2,
    Normalize,
    Polar2,
    Polar3,
    Trace,
    Sym,
}

#[derive(Clone, Debug)]
// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub enum Op {
    /// [`Op::MatMul`] whose left matrix has zeros by construction (a block-diagonal matrix, its
    /// transpose): row `i` sums only over the columns `terms[offs[i]..offs[i + 1]]`, in
    /// increasing order. The same bits as the dense product for finite values: the skipped
    /// terms are `0 * y`, a signed zero, and adding a zero to a sum that started at +0 changes
    /// nothing. (A non-finite `y` facing a structural zero would make the dense product NaN;
    /// here that entry's row stays finite. A step with non-finite positions fails either way.)
    MatMulSparse {
        dst: R,
        a: R,
        b: R,
        k: usize,
        c: usize,
        offs: Vec<u32>,
        terms: Vec<u16>,
    },
    /// A constant or parameter, from the run's fill values at `at`.
    Fill {
        dst: R,
        at: usize,
    },
    /// `dst[row] = column[idx[row]]`.
    Gather {
        dst: R,
        col: usize,
        idx: usize,
    },
    /// Sum (or mean) over the compressed slot lists `csr`.
    Agg {
        dst: R,
        col: usize,
        csr: usize,
        mean: bool,
    },
    /// A value computed per row when the plan was built (counts).
    RowData {
        dst: R,
        data: usize,
    },
    /// Same-width element-wise `a op b`.
    Ew {
        op: Ew,
        dst: R,
        a: R,
        b: R,
    },
    /// `s * v` (`s` scalar).
    ScaleL {
        dst: R,
        s: R,
        v: R,
    },
    /// `v / s` (`s` scalar).
    DivS {
        dst: R,
        v: R,
        s: R,
    },
    /// `(r x k) * (k x c)`.
    MatMul {
        dst: R,
        a: R,
        b: R,
        r: usize,
        k: usize,
        c: usize,
    },
    Neg {
        dst: R,
        a: R,
    },
    Not {
        dst: R,
        a: R,
    },
    Cmp {
        op: Cmp,
        dst: R,
        a: R,
        b: R,
    },
    /// Equality of two values of one type (`ne`: its negation).
    Eq {
        ne: bool,
        dst: R,
        a: R,
        b: R,
    },
    And {
        dst: R,
        a: R,
        b: R,
    },
    Or {
        dst: R,
        a: R,
        b: R,
    },
    Select {
        dst: R,
        c: R,
        a: R,
        b: R,
    },
    /// `dst[k] = srcs[map[k].0][map[k].1]`, or 0 where `map[k].0` is `u16::MAX`.
    Pick {
        dst: R,
        srcs: Vec<R>,
        map: Vec<(u16, u16)>,
    },
    F1 {
        f: fn(f64) -> f64,
        /// The built-in's name (the code generator computes some natively).
        name: &'static str,
        dst: R,
        a: R,
    },
    F2 {
        f: fn(f64, f64) -> f64,
        dst: R,
        a: R,
        b: R,
    },
    Fast {
        f: Fast,
        dst: R,
        args: Vec<R>,
    },
    /// Any other built-in, through [`builtins::call`] (allocates; fails back to the
    /// interpreter on error).
    Generic {
        name: String,
        dst: R,
        args: Vec<(R, Ty)>,
        ty: Ty,
    },
}

#[derive(Clone, Copy, Debug)]
// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub struct Reg {
    /// Offset, in floats per row, of the register in a row's scratch.
    pub off: usize,
    pub width: usize,
}

/// A gather: the node and embedding read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct ReadKey {
    node: usize,
    emb: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct AggKey {
    orbit: OrbitType,
    node: usize,
    emb: Option<usize>,
    distinct: bool,
}

/// What a fill register holds.
#[derive(Clone, Debug)]
// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub enum FillSrc {
    Const(Vec<f64>),
    Param(usize),
}

/// The compiled program of a rule: independent of any map.
#[derive(Clone, Debug)]
// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub struct Program {
    pub ops: Vec<Op>,
    pub regs: Vec<Reg>,
    /// Floats per row of scratch.
    stride: usize,
    pub fills: Vec<FillSrc>,
    /// Reads: (node, rule embedding).
    reads: Vec<ReadKey>,
    /// Aggregates (sum, mean, count).
    aggs: Vec<AggKey>,
    /// Embeddings whose columns the program reads (rule embedding indices).
    cols: Vec<usize>,
    /// Writes, in program order: (node, rule embedding, register, uniform positions). A
    /// guard program ([`compile_guard`]) has one, whose embedding is [`GUARD_OUT`]: its
    /// value stays in the plan's output, one per match (see [`Plan::run_guard`]).
    pub writes: Vec<(usize, usize, R, Vec<usize>)>,
    /// Whether this is a guard program: one domain row per match (its row 0, where the
    /// interpreter evaluates a guard), nothing scattered into the map.
    guard: bool,
}

/// The embedding of a guard program's one write: no embedding (see [`Program::writes`]).
pub(crate) const GUARD_OUT: usize = usize::MAX;

impl Program {
    /// The orbit types the program aggregates over (the orbits its rows walk, besides the
    /// darts of the match).
    pub(crate) fn agg_orbits(&self) -> Vec<OrbitType> {
        let mut v: Vec<OrbitType> = Vec::new();
        for a in &self.aggs {
            if !v.contains(&a.orbit) {
                v.push(a.orbit);
            }
        }
        v
    }
}

struct Compiler<'a> {
    rule: &'a Rule,
    embs: &'a [EmbDecl],
    p: Program,
    locals: Vec<Option<(R, Ty)>>,
    /// The register of each read (index of `p.reads`) already gathered: a rule reads the
    /// values before its writes, so a second read of a node's embedding is the same value.
    read_regs: Vec<Option<R>>,
    /// The register of each parameter already filled.
    param_regs: Vec<Option<R>>,
    /// Per register, which of its floats are zero by construction (the zeros of
    /// `blockdiag`, and where they are selected again, as by `transpose`), if any.
    zeros: Vec<Option<Vec<bool>>>,
}

const INT_EXACT: f64 = 9_007_199_254_740_992.0; // 2^53

fn unsupported<T>(why: impl Into<String>) -> Result<T, Unsupported> {
    Err(Unsupported(why.into()))
}

impl<'a> Compiler<'a> {
    /// A compiler of `rule`'s program (`guard`: of its guard alone) with nothing emitted.
    fn new(rule: &'a Rule, embs: &'a [EmbDecl], guard: bool) -> Self {
        Compiler {
            rule,
            embs,
            p: Program {
                ops: Vec::new(),
                regs: Vec::new(),
                stride: 0,
                fills: Vec::new(),
                reads: Vec::new(),
                aggs: Vec::new(),
                cols: Vec::new(),
                writes: Vec::new(),
                guard,
            },
            locals: vec![None; rule.n_locals],
            read_regs: Vec::new(),
            param_regs: vec![None; rule.params.len()],
            zeros: Vec::new(),
        }
    }

    fn reg(&mut self, width: usize) -> R {
        let off = self.p.stride;
        self.p.stride += width;
        self.p.regs.push(Reg { off, width });
        self.zeros.push(None);
        self.p.regs.len() - 1
    }

    fn col(&mut self, emb: usize) -> usize {
        if let Some(k) = self.p.cols.iter().position(|&e| e == emb) {
            k
        } else {
            self.p.cols.push(emb);
            self.p.cols.len() - 1
        }
    }

    fn fill(&mut self, src: FillSrc, ty: Ty) -> R {
        let dst = self.reg(ty.width());
        self.p.fills.push(src);
        let at = self.p.fills.len() - 1;
        self.p.ops.push(Op::Fill { dst, at });
        dst
    }

    fn constant(&mut self, v: &Val) -> Result<(R, Ty), Unsupported> {
        if let Val::I(i) = v {
            if (*i as f64).abs() >= INT_EXACT {
                return unsupported("an integer constant beyond 2^53");
            }
        }
        let mut x = Vec::new();
        v.to_reals(&mut x);
        Ok((self.fill(FillSrc::Const(x), v.ty()), v.ty()))
    }

    fn expr(&mut self, e: &TExpr) -> Result<(R, Ty), Unsupported> {
        Ok(match e {
            TExpr::Const(v) => self.constant(v)?,
            TExpr::Param(k) => {
                let ty = self.rule.params[*k].1;
                if let Some(r) = self.param_regs[*k] {
                    return Ok((r, ty));
                }
                let r = self.fill(FillSrc::Param(*k), ty);
                self.param_regs[*k] = Some(r);
                (r, ty)
            }
            TExpr::Local(k) => match self.locals.get(*k).copied().flatten() {
                Some(x) => x,
                None => return unsupported("a variable used before it is set"),
            },
            TExpr::Read { node, emb } => {
                let ty = self.embs[*emb].ty;
                if ty == Ty::I64 {
                    return unsupported("a read of an integer embedding");
                }
                let key = ReadKey {
                    node: *node,
                    emb: *emb,
                };
                let idx = if let Some(k) = self.p.reads.iter().position(|r| *r == key) {
                    k
                } else {
                    self.p.reads.push(key);
                    self.read_regs.push(None);
                    self.p.reads.len() - 1
                };
                if let Some(r) = self.read_regs[idx] {
                    return Ok((r, ty));
                }
                let col = self.col(*emb);
                let dst = self.reg(ty.width());
                self.p.ops.push(Op::Gather { dst, col, idx });
                self.read_regs[idx] = Some(dst);
                (dst, ty)
            }
            TExpr::Agg {
                kind,
                orbit,
                node,
                emb,
                ty,
            } => {
                if *kind == AggKind::Count {
                    let key = AggKey {
                        orbit: *orbit,
                        node: *node,
                        emb: *emb,
                        distinct: emb.is_some(),
                    };
                    let data = self.agg_index(key);
                    let dst = self.reg(1);
                    self.p.ops.push(Op::RowData { dst, data });
                    (dst, Ty::I64)
                } else {
                    let Some(e) = emb else {
                        return unsupported("an aggregate without embedding");
                    };
                    let ety = self.embs[*e].ty;
                    if !ety.is_real() {
                        return unsupported("an aggregate of integers or booleans");
                    }
                    let key = AggKey {
                        orbit: *orbit,
                        node: *node,
                        emb: Some(*e),
                        distinct: true,
                    };
                    let csr = self.agg_index(key);
                    let col = self.col(*e);
                    let dst = self.reg(ety.width());
                    self.p.ops.push(Op::Agg {
                        dst,
                        col,
                        csr,
                        mean: *kind == AggKind::Mean,
                    });
                    (dst, if *kind == AggKind::Mean { ety } else { *ty })
                }
            }
            TExpr::Bin(op, a, b) => {
                let (ra, ta) = self.expr(a)?;
                let (rb, tb) = self.expr(b)?;
                self.binary(*op, (ra, ta), (rb, tb))?
            }
            TExpr::Un(op, a) => {
                let (ra, ta) = self.expr(a)?;
                let ty = unop_type(*op, ta).map_err(Unsupported)?;
                if ta == Ty::I64 {
                    return unsupported("integer negation");
                }
                let dst = self.reg(ty.width());
                self.p.ops.push(match op {
                    UnOp::Neg => Op::Neg { dst, a: ra },
                    UnOp::Not => Op::Not { dst, a: ra },
                });
                (dst, ty)
            }
            TExpr::Call(name, args) => self.call(name, args)?,
            TExpr::If(c, a, b) => {
                let (rc, _) = self.expr(c)?;
                let (ra, ta) = self.expr(a)?;
                let (rb, tb) = self.expr(b)?;
                if ta != tb {
                    return unsupported("branches of different types");
                }
                let dst = self.reg(ta.width());
                self.p.ops.push(Op::Select {
                    dst,
                    c: rc,
                    a: ra,
                    b: rb,
                });
                (dst, ta)
            }
            TExpr::Block(lets, res) => {
                for (k, v) in lets {
                    let x = self.expr(v)?;
                    self.locals[*k] = Some(x);
                }
                self.expr(res)?
            }
            TExpr::ToReal(a) => {
                let (ra, ta) = self.expr(a)?;
                (ra, if ta == Ty::I64 { Ty::F64 } else { ta })
            }
        })
    }

    fn agg_index(&mut self, key: AggKey) -> usize {
        if let Some(k) = self.p.aggs.iter().position(|a| *a == key) {
            k
        } else {
            self.p.aggs.push(key);
            self.p.aggs.len() - 1
        }
    }

    fn binary(&mut self, op: BinOp, a: (R, Ty), b: (R, Ty)) -> Result<(R, Ty), Unsupported> {
        let ty = binop_type(op, a.1, b.1).map_err(Unsupported)?;
        let (ra, ta) = a;
        let (rb, tb) = b;
        let int = |t: Ty| t == Ty::I64;
        let scalar = |t: Ty| matches!(t, Ty::F64 | Ty::I64);
        let dst = self.reg(ty.width());
        let o = match op {
            BinOp::Add | BinOp::Sub | BinOp::Rem | BinOp::Div | BinOp::Mul
                if int(ta) && int(tb) =>
            {
                return unsupported("integer arithmetic");
            }
            BinOp::Add | BinOp::Sub | BinOp::Rem => Op::Ew {
                op: match op {
                    BinOp::Add => Ew::Add,
                    BinOp::Sub => Ew::Sub,
                    _ => Ew::Rem,
                },
                dst,
                a: ra,
                b: rb,
            },
            BinOp::Div => {
                if ta.width() == 1 {
                    Op::Ew {
                        op: Ew::Div,
                        dst,
                        a: ra,
                        b: rb,
                    }
                } else {
                    Op::DivS { dst, v: ra, s: rb }
                }
            }
            BinOp::Mul => {
                if scalar(ta) && scalar(tb) {
                    Op::Ew {
                        op: Ew::Mul,
                        dst,
                        a: ra,
                        b: rb,
                    }
                } else if scalar(ta) {
                    Op::ScaleL { dst, s: ra, v: rb }
                } else if scalar(tb) {
                    Op::ScaleL { dst, s: rb, v: ra }
                } else {
                    let (r, k) = match ta {
                        Ty::Mat(r, k) => (usize::from(r), usize::from(k)),
                        _ => return unsupported("a product of these types"),
                    };
                    let c = tb.width() / k;
                    match &self.zeros[ra] {
                        // a matrix with zeros by construction: the products with them skipped
                        Some(z) if z.iter().filter(|&&x| x).count() * 2 >= z.len() => {
                            let mut offs = vec![0u32];
                            let mut terms = Vec::new();
                            for i in 0..r {
                                terms.extend((0..k).filter(|t| !z[i * k + t]).map(|t| t as u16));
                                offs.push(terms.len() as u32);
                            }
                            Op::MatMulSparse {
                                dst,
                                a: ra,
                                b: rb,
                                k,
                                c,
                                offs,
                                terms,
                            }
                        }
                        _ => Op::MatMul {
                            dst,
                            a: ra,
                            b: rb,
                            r,
                            k,
                            c,
                        },
                    }
                }
            }
            BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => Op::Cmp {
                op: match op {
                    BinOp::Lt => Cmp::Lt,
                    BinOp::Le => Cmp::Le,
                    BinOp::Gt => Cmp::Gt,
                    _ => Cmp::Ge,
                },
                dst,
                a: ra,
                b: rb,
            },
            BinOp::Eq | BinOp::Ne => Op::Eq {
                ne: op == BinOp::Ne,
                dst,
                a: ra,
                b: rb,
            },
            BinOp::And => Op::And { dst, a: ra, b: rb },
            BinOp::Or => Op::Or { dst, a: ra, b: rb },
        };
        self.p.ops.push(o);
        Ok((dst, ty))
    }

    fn call(&mut self, name: &str, args: &[TExpr]) -> Result<(R, Ty), Unsupported> {
        // constant folding: a call on constants only is evaluated now
        if args.iter().all(|a| matches!(a, TExpr::Const(_))) {
            let vals: Vec<Val> = args
                .iter()
                .map(|a| match a {
                    TExpr::Const(v) => v.clone(),
                    _ => unreachable!("checked above"),
                })
                .collect();
            if let Ok(v) = builtins::call(name, &vals) {
                return self.constant(&v);
            }
        }
        let mut rs = Vec::with_capacity(args.len());
        let mut ts = Vec::with_capacity(args.len());
        for a in args {
            let (r, t) = self.expr(a)?;
            rs.push(r);
            ts.push(t);
        }
        let ty = builtins::call_type(name, &ts).map_err(Unsupported)?;
        // integer results (min/max/clamp of integers...) are left to the interpreter, for its
        // overflow checks
        if ty == Ty::I64 {
            return unsupported("a built-in with an integer result");
        }
        let width = |t: Ty| t.width();
        // selections with constant indices
        let pick: Option<Vec<u32>> = match (name, ts.as_slice()) {
            ("to_f64", [Ty::F64 | Ty::I64 | Ty::Bool]) => return Ok((rs[0], Ty::F64)),
            ("x", [_]) => Some(vec![0]),
            ("y", [_]) => Some(vec![1]),
            ("z", [_]) => Some(vec![2]),
            ("vec2" | "vec3" | "mat2" | "mat3", _) if ts.iter().all(|t| *t == Ty::F64) => {
                Some((0..ts.len() as u32).collect())
            }
            ("vec12" | "vec6" | "mat_from_rows2" | "mat_from_rows3", _) => {
                Some((0..ty.width() as u32).collect())
            }
            ("mat_from_cols2" | "mat_from_cols3" | "mat_from_cols4", _) => {
                // columns a, b, ... of length n: entry (i, j) is concat[j * n + i]
                let n = width(ts[0]);
                let m = ts.len();
                Some(
                    (0..n)
                        .flat_map(|i| (0..m).map(move |j| (j * n + i) as u32))
                        .collect(),
                )
            }
            ("transpose", [Ty::Mat(r, c)]) => {
                let (r, c) = (usize::from(*r), usize::from(*c));
                // result (c x r): entry (i, j) = m[j][i]
                Some(
                    (0..c)
                        .flat_map(|i| (0..r).map(move |j| (j * c + i) as u32))
                        .collect(),
                )
            }
            ("blockdiag3" | "blockdiag4", [Ty::Mat(k, _)]) => {
                let k = usize::from(*k);
                let nb = if name == "blockdiag3" { 3 } else { 4 };
                let n = k * nb;
                Some(
                    (0..n * n)
                        .map(|e| {
                            let (i, j) = (e / n, e % n);
                            if i / k == j / k {
                                ((i % k) * k + j % k) as u32
                            } else {
                                u32::MAX
                            }
                        })
                        .collect(),
                )
            }
            ("vecn_get2" | "vecn_get3", [Ty::Mat(r, 1), Ty::I64]) => {
                let k = if name == "vecn_get2" { 2 } else { 3 };
                match args[1].const_int() {
                    Some(i) if i >= 0 && (i as usize + 1) * k <= usize::from(*r) => {
                        let i = i as usize;
                        Some((i * k..(i + 1) * k).map(|x| x as u32).collect())
                    }
                    _ => None,
                }
            }
            // an entry, a row or a column at constant indices inside the matrix (a vector is
            // a column); out of range, the built-in's own error at run time (`Generic`)
            ("get", [m @ (Ty::Mat(..) | Ty::Vec2 | Ty::Vec3), Ty::I64, Ty::I64]) => {
                let (r, c) = match m {
                    Ty::Mat(r, c) => (usize::from(*r), usize::from(*c)),
                    _ => (m.width(), 1),
                };
                match (args[1].const_int(), args[2].const_int()) {
                    (Some(i), Some(j))
                        if (0..r as i64).contains(&i) && (0..c as i64).contains(&j) =>
                    {
                        Some(vec![(i as usize * c + j as usize) as u32])
                    }
                    _ => None,
                }
            }
            ("row2" | "row3", [Ty::Mat(r, c), Ty::I64]) if usize::from(*c) == ty.width() => {
                let (r, c) = (usize::from(*r), usize::from(*c));
                match args[1].const_int() {
                    Some(i) if (0..r as i64).contains(&i) => {
                        let i = i as usize;
                        Some((i * c..(i + 1) * c).map(|x| x as u32).collect())
                    }
                    _ => None,
                }
            }
            ("col2" | "col3", [Ty::Mat(r, c), Ty::I64]) if usize::from(*r) == ty.width() => {
                let (r, c) = (usize::from(*r), usize::from(*c));
                match args[1].const_int() {
                    Some(j) if (0..c as i64).contains(&j) => {
                        let j = j as usize;
                        Some((0..r).map(|i| (i * c + j) as u32).collect())
                    }
                    _ => None,
                }
            }
            ("block2" | "block3", [Ty::Mat(r, c), Ty::I64, Ty::I64]) => {
                let k = if name == "block2" { 2 } else { 3 };
                let (r, c) = (usize::from(*r), usize::from(*c));
                match (args[1].const_int(), args[2].const_int()) {
                    (Some(bi), Some(bj))
                        if bi >= 0
                            && bj >= 0
                            && (bi as usize + 1) * k <= r
                            && (bj as usize + 1) * k <= c =>
                    {
                        let (bi, bj) = (bi as usize * k, bj as usize * k);
                        Some(
                            (0..k)
                                .flat_map(|i| (0..k).map(move |j| ((bi + i) * c + bj + j) as u32))
                                .collect(),
                        )
                    }
                    _ => None,
                }
            }
            _ => None,
        };
        let dst;
        if let Some(map) = pick {
            // the arguments that are data (not constant indices)
            let srcs: Vec<R> = match name {
                "vecn_get2" | "vecn_get3" | "block2" | "block3" | "get" | "row2" | "row3"
                | "col2" | "col3" => vec![rs[0]],
                _ => rs.clone(),
            };
            debug_assert_eq!(map.len(), ty.width());
            // resolve each entry of the concatenation to (source, offset)
            let widths: Vec<usize> = srcs.iter().map(|&r| self.p.regs[r].width).collect();
            let map: Vec<(u16, u16)> = map
                .into_iter()
                .map(|m| {
                    if m == u32::MAX {
                        return (u16::MAX, 0);
                    }
                    let mut m = m as usize;
                    for (k, &w) in widths.iter().enumerate() {
                        if m < w {
                            return (k as u16, m as u16);
                        }
                        m -= w;
                    }
                    unreachable!("a selection inside its sources")
                })
                .collect();
            let zeros: Vec<bool> = map
                .iter()
                .map(|&(src, off): &(u16, u16)| {
                    src == u16::MAX
                        || self.zeros[srcs[src as usize]]
                            .as_ref()
                            .is_some_and(|z| z[off as usize])
                })
                .collect();
            dst = self.reg(ty.width());
            if zeros.iter().any(|&z| z) {
                self.zeros[dst] = Some(zeros);
            }
            self.p.ops.push(Op::Pick { dst, srcs, map });
            return Ok((dst, ty));
        }
        if let Some(r) = self.spring(name, &rs, &ts)? {
            return Ok((r, Ty::Vec3));
        }
        let fast = match (name, ts.as_slice()) {
            ("dot", [a, b]) if a == b => Some(Fast::Dot),
            ("norm", [_]) => Some(Fast::Norm),
            ("norm2", [_]) => Some(Fast::Norm2),
            ("cross", [Ty::Vec3, Ty::Vec3]) => Some(Fast::Cross3),
            ("cross", [Ty::Vec2, Ty::Vec2]) => Some(Fast::Cross2),
            ("normalize", [_]) => Some(Fast::Normalize),
            ("polar", [Ty::Mat(2, 2)]) => Some(Fast::Polar2),
            ("polar", [Ty::Mat(3, 3)]) => Some(Fast::Polar3),
            ("trace", [Ty::Mat(..)]) => Some(Fast::Trace),
            ("sym", [Ty::Mat(..)]) => Some(Fast::Sym),
            _ => None,
        };
        dst = self.reg(ty.width());
        if let Some(f) = fast {
            self.p.ops.push(Op::Fast { f, dst, args: rs });
            return Ok((dst, ty));
        }
        let all_f64 = ts.iter().all(|t| *t == Ty::F64);
        let f1: Option<(F1Fn, &'static str)> = match name {
            _ if !(all_f64 && ts.len() == 1) => None,
            "abs" => Some((|x| builtins::scalar1("abs", x), "abs")),
            "sign" => Some((|x| builtins::scalar1("sign", x), "sign")),
            "sqrt" => Some((|x| builtins::scalar1("sqrt", x), "sqrt")),
            "exp" => Some((|x| builtins::scalar1("exp", x), "exp")),
            "log" => Some((|x| builtins::scalar1("log", x), "log")),
            "sin" => Some((|x| builtins::scalar1("sin", x), "sin")),
            "cos" => Some((|x| builtins::scalar1("cos", x), "cos")),
            "tan" => Some((|x| builtins::scalar1("tan", x), "tan")),
            "asin" => Some((|x| builtins::scalar1("asin", x), "asin")),
            "acos" => Some((|x| builtins::scalar1("acos", x), "acos")),
            "atan" => Some((|x| builtins::scalar1("atan", x), "atan")),
            "floor" => Some((|x| builtins::scalar1("floor", x), "floor")),
            "ceil" => Some((|x| builtins::scalar1("ceil", x), "ceil")),
            _ => None,
        };
        if let Some((f, name)) = f1 {
            self.p.ops.push(Op::F1 {
                f,
                name,
                dst,
                a: rs[0],
            });
            return Ok((dst, ty));
        }
        let f2: Option<fn(f64, f64) -> f64> = match name {
            _ if !(all_f64 && ts.len() == 2) => None,
            "atan2" => Some(|a, b| builtins::scalar2("atan2", a, b)),
            "pow" => Some(|a, b| builtins::scalar2("pow", a, b)),
            "min" => Some(|a, b| builtins::scalar2("min", a, b)),
            "max" => Some(|a, b| builtins::scalar2("max", a, b)),
            _ => None,
        };
        if let Some(f) = f2 {
            self.p.ops.push(Op::F2 {
                f,
                dst,
                a: rs[0],
                b: rs[1],
            });
            return Ok((dst, ty));
        }
        // integer arguments are exact in f64 below 2^53 (constants are checked, counts are
        // small): the generic call gets them back as integers
        self.p.ops.push(Op::Generic {
            name: name.to_string(),
            dst,
            args: rs.into_iter().zip(ts).collect(),
            ty,
        });
        Ok((dst, ty))
    }
}

impl Compiler<'_> {
    /// `dot(a, b)` of two registers of one width.
    fn dot(&mut self, a: (R, Ty), b: (R, Ty)) -> (R, Ty) {
        let dst = self.reg(1);
        self.p.ops.push(Op::Fast {
            f: Fast::Dot,
            dst,
            args: vec![a.0, b.0],
        });
        (dst, Ty::F64)
    }

    /// `spring_force(xa, xb, va, vb, k, c, l0)` and `spring_jvp(xa, xb, va, vb, dxa, dxb, dva,
    /// dvb, k, c, l0)` (the damped spring of `mechanics`, Provot 1995) written as the plan's
    /// own operations, in the built-in's order of operations (the same bits as the
    /// interpreter), so that a rule calling them needs no call to the built-in per row.
    /// `None` for another call, or with scalars that are not reals (the generic call then).
    fn spring(&mut self, name: &str, rs: &[R], ts: &[Ty]) -> Result<Option<R>, Unsupported> {
        let nv = match name {
            "spring_force" if ts.len() == 7 => 4,
            "spring_jvp" if ts.len() == 11 => 8,
            _ => return Ok(None),
        };
        if !ts[..nv].iter().all(|t| *t == Ty::Vec3) || !ts[nv..].iter().all(|t| *t == Ty::F64) {
            return Ok(None);
        }
        let v = |i: usize| (rs[i], Ty::Vec3);
        let (k, c, l0) = (
            (rs[nv], Ty::F64),
            (rs[nv + 1], Ty::F64),
            (rs[nv + 2], Ty::F64),
        );
        // d = xb - xa, l = sqrt(d . d), u = d / l, dv = vb - va
        let d = self.binary(BinOp::Sub, v(1), v(0))?;
        let dd = self.dot(d, d);
        let l = self.reg(1);
        self.p.ops.push(Op::F1 {
            f: |x| builtins::scalar1("sqrt", x),
            name: "sqrt",
            dst: l,
            a: dd.0,
        });
        let l = (l, Ty::F64);
        let u = self.binary(BinOp::Div, d, l)?;
        let dv = self.binary(BinOp::Sub, v(3), v(2))?;
        if nv == 4 {
            // (k (l - l0) + c (dv . u)) u
            let p = self.dot(dv, u);
            let t1 = self.binary(BinOp::Sub, l, l0)?;
            let t2 = self.binary(BinOp::Mul, k, t1)?;
            let t3 = self.binary(BinOp::Mul, c, p)?;
            let s = self.binary(BinOp::Add, t2, t3)?;
            return Ok(Some(self.binary(BinOp::Mul, s, u)?.0));
        }
        // w = dxb - dxa, z = dvb - dva, pw = w - (u . w) u;
        // k ((1 - l0 / l) pw + (u . w) u) + (c / l) ((dv . pw) u + (dv . u) pw) + c (u . z) u
        let w = self.binary(BinOp::Sub, v(5), v(4))?;
        let z = self.binary(BinOp::Sub, v(7), v(6))?;
        let uw = self.dot(u, w);
        let uwu = self.binary(BinOp::Mul, uw, u)?;
        let pw = self.binary(BinOp::Sub, w, uwu)?;
        let (dvpw, dvu, uz) = (self.dot(dv, pw), self.dot(dv, u), self.dot(u, z));
        let one = self.constant(&Val::F(1.0))?;
        let q = self.binary(BinOp::Div, l0, l)?;
        let q = self.binary(BinOp::Sub, one, q)?;
        let a = self.binary(BinOp::Mul, q, pw)?;
        let a = self.binary(BinOp::Add, a, uwu)?;
        let a = self.binary(BinOp::Mul, k, a)?;
        let cl = self.binary(BinOp::Div, c, l)?;
        let e = self.binary(BinOp::Mul, dvpw, u)?;
        let f = self.binary(BinOp::Mul, dvu, pw)?;
        let e = self.binary(BinOp::Add, e, f)?;
        let e = self.binary(BinOp::Mul, cl, e)?;
        let a = self.binary(BinOp::Add, a, e)?;
        let cuz = self.binary(BinOp::Mul, c, uz)?;
        let j = self.binary(BinOp::Mul, cuz, u)?;
        Ok(Some(self.binary(BinOp::Add, a, j)?.0))
    }
}

/// Compiles a computation rule's program; `Err` says what the plan machinery does not cover.
pub(crate) fn compile(rule: &Rule, embs: &[EmbDecl]) -> Result<Program, Unsupported> {
    if rule.changes_topology {
        return unsupported("a rule that changes the topology");
    }
    let mut c = Compiler::new(rule, embs, false);
    for s in &rule.program {
        match s {
            TStmt::Let(k, e) => {
                let x = c.expr(e)?;
                c.locals[*k] = Some(x);
            }
            TStmt::Write {
                node,
                emb,
                value,
                uniform,
            } => {
                let (r, t) = c.expr(value)?;
                if t != embs[*emb].ty || embs[*emb].derived.is_some() {
                    return unsupported("a write of another type, or of a derived embedding");
                }
                c.p.writes.push((*node, *emb, r, uniform.clone()));
            }
        }
    }
    Ok(c.p)
}

/// The guard of `rule` (a rule that changes the topology or not) compiled alone: a program
/// computing its value (1 or 0) at row 0 of each match, for [`Plan::run_guard`]. The same
/// operations as a computation rule's, so the same values as the interpreter's, bit for bit;
/// what the plan machinery does not cover is `Err`, and the interpreter evaluates the guard.
/// (Where the interpreter's `&&` and `||` skip their right operand, the program evaluates it
/// too: a failure there makes the run `Err`, and the interpreter decides.)
pub(crate) fn compile_guard(rule: &Rule, embs: &[EmbDecl]) -> Result<Program, Unsupported> {
    let Some(guard) = &rule.guard else {
        return unsupported("a rule without a guard");
    };
    let hook = match rule.hooks.as_slice() {
        [h] => *h,
        _ => return unsupported("a rule without exactly one hook"),
    };
    let mut c = Compiler::new(rule, embs, true);
    let (r, t) = c.expr(guard)?;
    if t != Ty::Bool {
        return unsupported("a guard that is not a boolean");
    }
    c.p.writes.push((hook, GUARD_OUT, r, Vec::new()));
    Ok(c.p)
}

/// Parameters in the units the program reads them: `None` if one cannot be represented
/// exactly (an integer beyond 2^53).
fn param_values(params: &[Val]) -> Option<Vec<Vec<f64>>> {
    params
        .iter()
        .map(|v| {
            if let Val::I(i) = v {
                if (*i as f64).abs() >= INT_EXACT {
                    return None;
                }
            }
            let mut x = Vec::new();
            v.to_reals(&mut x);
            Some(x)
        })
        .collect()
}

/// The largest power of two at most `x` (1 for 0).
fn prev_power_of_two(x: usize) -> usize {
    if x <= 1 {
        1
    } else {
        1 << (usize::BITS - 1 - x.leading_zeros())
    }
}

/// A compiled plan: a program and the index arrays of one map's matches.
#[derive(Debug)]
pub(crate) struct Plan {
    prog: Program,
    matches: usize,
    rows: usize,
    chunk: usize,
    gathers: Vec<Vec<u32>>,
    /// Per aggregate: offsets (rows + 1) and slots, or per-row counts.
    csr: Vec<(Vec<u32>, Vec<u32>)>,
    counts: Vec<Vec<f64>>,
    /// Per write: (domain row, slot) pairs it scatters, offset of its value in an output row.
    targets: Vec<(Vec<(u32, u32)>, usize)>,
    /// Writes to an orbit another write of the rule also writes: (write, row, write, row);
    /// the values must be equal.
    dups: Vec<(usize, u32, usize, u32)>,
    /// Floats per output row.
    out_width: usize,
    /// The values written, chunk by chunk: a chunk's block holds `chunk * out_width` floats,
    /// each write's rows contiguous from `offset * chunk` (see [`Plan::out_index`]).
    out: Vec<f64>,
    evaluations: usize,
    /// Native code for the program (see [`crate::native`]), compiled at the first run when
    /// the plan was built with the switch on and a backend.
    native: NativeState,
    /// Per domain row, the number of its match (see [`Plan::patch`]).
    row_match: Vec<u32>,
    /// Per write, every (domain row, slot) it writes, owners and duplicates alike (what
    /// `targets` and `dups` are computed from again after a patch).
    writes: Vec<Vec<(u32, u32)>>,
    /// Where the plan may scatter its values chunk by chunk in parallel (see
    /// [`Plan::run_chunked`]): per write, where the targets of chunk `c` start in its
    /// targets (sorted by row), `c = 0..=chunks`, and the slots its column must hold (one
    /// past its largest target). `None` where it may not.
    chunk_starts: Option<(Vec<Vec<u32>>, Vec<usize>)>,
    /// Rows of dropped matches left in place by [`Plan::patch_in_place`] (evaluated, never
    /// written), since the plan was last assembled.
    dead: usize,
    /// Per embedding the plan writes (in the order of the writes), the target writing each
    /// slot, `(write, row)`, or `(u32::MAX, 0)`: built at the first in-place patch, kept
    /// up to date by the next ones.
    owner: Option<Owners>,
    /// The values of read-only gathers copied in row order (see [`Plan::pack_read_only`]),
    /// which the native code reads through `identity` instead of the gathers' slots.
    packed: Vec<Packed>,
    /// Per program column, its write count at the last chunked run (`u64::MAX`: none yet).
    last_writes: Vec<u64>,
    /// `0, 1, 2, ...`: the index array of every packed gather (at least `rows` long while
    /// one is packed).
    identity: Vec<u32>,
}

/// A test of the values a plan is about to write, by embedding, before any is written:
/// `check(embedding, values)` gets a write's values for the rows of one chunk (`width`
/// floats each, in row order); a `false` from any call and the plan writes nothing (see
/// [`crate::engine::RuleSet::apply_everywhere_checked`]).
pub(crate) type ValueCheck<'a> = dyn Fn(EmbeddingId, &[f64]) -> bool + Sync + 'a;

/// A gather's values in row order: what the plan's only gather of program column `col`
/// (gather `idx`) reads on each row, copied when the column's write count was `writes`;
/// empty for a gather that reads the column in order already (not worth a copy).
#[derive(Debug)]
struct Packed {
    col: usize,
    idx: usize,
    writes: u64,
    values: Vec<f64>,
}

/// Per written embedding (in the order of the writes), which target writes each slot (see
/// `Plan::owner`).
type Owners = Vec<Vec<(u32, u32)>>;

/// A plan being built from batches of matches (see [`Plan::builder`]).
pub(crate) struct PlanBuilder {
    prog: Program,
    rows: Rows,
    matches: usize,
}

impl PlanBuilder {
    /// Adds the rows of `ms`, numbered after the matches added before.
    pub(crate) fn add(&mut self, rule: &Rule, g: &GMap, ids: &[EmbeddingId], ms: &[Match]) {
        let numbers: Vec<u32> = (self.matches as u32..(self.matches + ms.len()) as u32).collect();
        let base = self.rows.row_match.len();
        self.rows
            .append(Rows::of(&self.prog, rule, g, ids, ms, &numbers, base));
        self.matches += ms.len();
    }

    /// The plan, with native code compiled by `backend` at its first run when there is one
    /// (the rule set's switch on and a backend installed).
    pub(crate) fn finish(
        self,
        g: &GMap,
        ids: &[EmbeddingId],
        backend: Option<Arc<dyn NativeBackend>>,
    ) -> Plan {
        Plan::assemble(
            self.prog,
            g,
            ids,
            self.rows,
            self.matches,
            backend.map_or(NativeState::Off, NativeState::Untried),
            None,
        )
    }
}

/// Whether and how a plan runs native code.
#[derive(Debug)]
enum NativeState {
    /// The switch was off when the plan was built: the evaluator runs.
    Off,
    /// To compile at the first run (the column kinds are known then), with this backend.
    Untried(Arc<dyn NativeBackend>),
    /// Not covered (the reason): the evaluator runs.
    Failed(#[allow(dead_code)] String),
    /// Compiled, with per program column the length it must have at least (in elements):
    /// one more than the largest slot the index arrays hold, times the width read.
    Ready(Arc<dyn NativeFn>, Vec<usize>),
}

/// Partition of the rows: rows joined through the orbit positions `uniform` share a class.
/// Returns, per row, its class's first row.
fn class_reps(
    m: &Match,
    arity: usize,
    uniform: &[usize],
    rep: &mut Vec<u32>,
    stack: &mut Vec<usize>,
) {
    rep.clear();
    rep.resize(m.rows, u32::MAX);
    stack.clear();
    for r0 in 0..m.rows {
        if rep[r0] != u32::MAX {
            continue;
        }
        rep[r0] = r0 as u32;
        stack.push(r0);
        while let Some(r) = stack.pop() {
            for &t in uniform {
                let s = m.next[r * arity + t] as usize;
                if rep[s] == u32::MAX {
                    rep[s] = r0 as u32;
                    stack.push(s);
                }
            }
        }
    }
}

/// Appends to `slots` the distinct slots of embedding `e` at `darts`, in increasing order
/// (what the interpreter sums an aggregate in, see `Eval::aggregate`); returns how many.
fn push_orbit_slots(slots: &mut Vec<u32>, e: &topomech_gmap::Embedding, darts: &[Dart]) -> usize {
    let start = slots.len();
    slots.extend(darts.iter().map(|&x| e.slot(x) as u32));
    slots[start..].sort_unstable();
    let mut k = start;
    for j in start..slots.len() {
        if j == start || slots[j] != slots[k - 1] {
            slots[k] = slots[j];
            k += 1;
        }
    }
    slots.truncate(k);
    k - start
}

/// The per-row arrays of some matches (a plan's, or those a patch appends).
#[derive(Debug, Default)]
struct Rows {
    /// Per domain row, the number of its match (as the caller numbers matches).
    row_match: Vec<u32>,
    gathers: Vec<Vec<u32>>,
    /// Per aggregate: offsets (rows + 1, from 0) and slots; offsets `[0]` for a count.
    csr: Vec<(Vec<u32>, Vec<u32>)>,
    counts: Vec<Vec<f64>>,
    /// Per write: every (domain row, slot) it writes, owners and duplicates alike.
    writes: Vec<Vec<(u32, u32)>>,
}

thread_local! {
    /// Per dart, the row plus one whose aggregate walked its orbit in [`Rows::of`] (0: none
    /// yet): a table the size of the map, per thread, reset for the darts set.
    static ORBIT_ROW: RefCell<Vec<u32>> = const { RefCell::new(Vec::new()) };
}

/// [`ORBIT_ROW`] borrowed, with the darts set in it: reset when dropped, also on a panic, so
/// that no later plan on the thread takes a stale entry for a walked orbit.
struct OrbitRows<'a> {
    row_of: std::cell::RefMut<'a, Vec<u32>>,
    walked: Vec<Dart>,
}

/// Runs `f` with this thread's [`ORBIT_ROW`] table, sized for `g` (reset when `f` ends).
fn with_orbit_rows<R>(g: &GMap, f: impl FnOnce(&mut OrbitRows<'_>) -> R) -> R {
    ORBIT_ROW.with(|t| {
        let mut table = OrbitRows {
            row_of: t.borrow_mut(),
            walked: Vec::new(),
        };
        if table.row_of.len() < g.capacity() {
            table.row_of.resize(g.capacity(), 0);
        }
        f(&mut table)
    })
}

impl OrbitRows<'_> {
    /// Walks the `orbit` of `d` into `darts` (cleared first), and enters `entry` for each of
    /// its darts (`marks`: scratch, left empty).
    fn walk(
        &mut self,
        g: &GMap,
        d: Dart,
        orbit: OrbitType,
        marks: &mut Marks,
        darts: &mut Vec<Dart>,
        entry: u32,
    ) {
        darts.clear();
        g.visit_orbit(d, orbit, marks, |x| darts.push(x));
        marks.clear();
        for &x in darts.iter() {
            self.row_of[x.index()] = entry;
        }
        self.walked.extend_from_slice(darts);
    }

    /// Clears the entries of the darts set.
    fn reset(&mut self) {
        for x in self.walked.drain(..) {
            self.row_of[x.index()] = 0;
        }
    }
}

impl Drop for OrbitRows<'_> {
    fn drop(&mut self) {
        self.reset();
    }
}

impl Rows {
    /// The rows of `matches` (numbered `ids[k]` for `matches[k]`), the first one numbered
    /// `base`.
    fn of(
        prog: &Program,
        rule: &Rule,
        g: &GMap,
        emb_ids: &[EmbeddingId],
        matches: &[Match],
        ids: &[u32],
        base: usize,
    ) -> Rows {
        let nw = prog.writes.len();
        // domain rows: the class representatives of every write
        let mut domain: Vec<(u32, u32)> = Vec::new();
        let mut write_rows: Vec<Vec<(u32, Dart)>> = vec![Vec::new(); nw];
        let mut rep = Vec::new();
        let mut reps: Vec<Vec<u32>> = vec![Vec::new(); nw];
        let mut stack = Vec::new();
        let mut row_match = Vec::new();
        for (mi, m) in matches.iter().enumerate() {
            if prog.guard {
                // one row per match: its row 0, where the guard is evaluated
                let row = (base + domain.len()) as u32;
                domain.push((mi as u32, 0));
                row_match.push(ids[mi]);
                write_rows[0].push((row, m.darts[prog.writes[0].0][0]));
                continue;
            }
            for (w, (_, _, _, uniform)) in prog.writes.iter().enumerate() {
                reps[w].clear();
                // a write uniform along every orbit position has one class (the rows of a
                // match are one orbit, connected through its positions): row 0; a write
                // uniform along the positions of an earlier one has its classes
                if (0..rule.arity).all(|t| uniform.contains(&t)) {
                    reps[w].push(0);
                    continue;
                }
                if let Some(v) = (0..w).find(|&v| prog.writes[v].3 == *uniform) {
                    let (done, rest) = reps.split_at_mut(w);
                    rest[0].extend_from_slice(&done[v]);
                    continue;
                }
                class_reps(m, rule.arity, uniform, &mut rep, &mut stack);
                reps[w].extend(
                    rep.iter()
                        .enumerate()
                        .filter(|(r, x)| **x as usize == *r)
                        .map(|(_, x)| *x),
                );
            }
            let mut rows: Vec<u32> = reps.iter().flatten().copied().collect();
            rows.sort_unstable();
            rows.dedup();
            let first = domain.len();
            domain.extend(rows.iter().map(|&r| (mi as u32, r)));
            row_match.extend(std::iter::repeat_n(ids[mi], rows.len()));
            for (w, (node, _, _, _)) in prog.writes.iter().enumerate() {
                for &r in &reps[w] {
                    let k = rows.binary_search(&r).expect("a representative is a row");
                    write_rows[w].push(((base + first + k) as u32, m.darts[*node][r as usize]));
                }
            }
        }
        let n = domain.len();
        let dart = |node: usize, row: usize| {
            let (mi, r) = domain[row];
            matches[mi as usize].darts[node][r as usize]
        };
        let gathers: Vec<Vec<u32>> = prog
            .reads
            .iter()
            .map(|rk| {
                let e = g.embedding(emb_ids[rk.emb]);
                (0..n)
                    .map(|row| e.slot(dart(rk.node, row)) as u32)
                    .collect()
            })
            .collect();
        let mut csr = Vec::new();
        let mut counts = Vec::new();
        // One orbit walk per orbit, not per row: the rows of one orbit (the twelve half-edges
        // of a tetrahedron aggregating over its volume) get the same slot list, in increasing
        // slot order (what the interpreter sums in, see `Eval::aggregate`), copied from the
        // first row that walked it. `row_of[d] - 1` is that row for each dart `d` of a walked
        // orbit (a table the size of the map, per thread, reset for the darts set).
        let mut marks = Marks::with_capacity(g.capacity());
        let mut darts: Vec<Dart> = Vec::new();
        with_orbit_rows(g, |table| {
            for ak in &prog.aggs {
                let mut offs = Vec::with_capacity(n + 1);
                let mut slots: Vec<u32> = Vec::new();
                let mut cnt = Vec::with_capacity(n);
                offs.push(0);
                // an aggregate over a sub-orbit of its embedding's orbit (the accumulation's
                // `sum<1,2,3>(v.f_tensor)` of a force on the vertex) meets one orbit of the
                // embedding: its row's dart's slot, no walk (the walk finds that one slot)
                if let Some(e) = ak
                    .emb
                    .map(|emb| g.embedding(emb_ids[emb]))
                    .filter(|e| ak.orbit.is_subset_of(e.orbit()))
                {
                    slots.reserve(n);
                    for row in 0..n {
                        slots.push(e.slot(dart(ak.node, row)) as u32);
                        offs.push(slots.len() as u32);
                        cnt.push(1.0);
                    }
                    csr.push((offs, slots));
                    counts.push(cnt);
                    continue;
                }
                for row in 0..n {
                    let d = dart(ak.node, row);
                    let first = table.row_of[d.index()];
                    if first != 0 {
                        let r0 = (first - 1) as usize;
                        cnt.push(cnt[r0]);
                        if ak.emb.is_some() {
                            slots.extend_from_within(offs[r0] as usize..offs[r0 + 1] as usize);
                            offs.push(slots.len() as u32);
                        }
                        continue;
                    }
                    table.walk(g, d, ak.orbit, &mut marks, &mut darts, row as u32 + 1);
                    match ak.emb {
                        None => cnt.push(darts.len() as f64),
                        Some(emb) => {
                            let n = push_orbit_slots(&mut slots, g.embedding(emb_ids[emb]), &darts);
                            cnt.push(n as f64);
                            offs.push(slots.len() as u32);
                        }
                    }
                }
                table.reset();
                csr.push((offs, slots));
                counts.push(cnt);
            }
        });
        let writes = prog
            .writes
            .iter()
            .zip(write_rows)
            .map(|((_, emb, _, _), rows)| {
                if *emb == GUARD_OUT {
                    // no slot: the row itself
                    return rows.into_iter().map(|(row, _)| (row, row)).collect();
                }
                let e = g.embedding(emb_ids[*emb]);
                rows.into_iter()
                    .map(|(row, d)| (row, e.slot(d) as u32))
                    .collect()
            })
            .collect();
        Rows {
            row_match,
            gathers,
            csr,
            counts,
            writes,
        }
    }

    /// The rows whose match `keep` accepts, renumbered from 0 in order.
    ///
    /// In place, and by runs: the rows between two dropped rows move down together (one
    /// `copy_within` per run and array), so that a patch dropping a few rows of a large plan
    /// costs a memory move, not a test per element of every array.
    fn filter(mut self, keep: &dyn Fn(u32) -> bool) -> Rows {
        let n = self.row_match.len();
        let dropped: Vec<usize> = (0..n).filter(|&r| !keep(self.row_match[r])).collect();
        if dropped.is_empty() {
            return self;
        }
        // the runs of kept rows: `lo..hi` (old numbers), the last one up to `n`
        let runs = || {
            std::iter::once(0)
                .chain(dropped.iter().map(|&d| d + 1))
                .zip(dropped.iter().copied().chain(std::iter::once(n)))
                .filter(|(lo, hi)| lo < hi)
        };
        compact(&mut self.row_match, runs());
        for x in &mut self.gathers {
            compact(x, runs());
        }
        for c in &mut self.counts {
            compact(c, runs());
        }
        for (offs, slots) in &mut self.csr {
            if offs.len() != n + 1 {
                *offs = vec![0]; // a count: no slots
                slots.clear();
                continue;
            }
            // a run's slots move down to `at`, its offsets down by as much; `k` new rows so
            // far (never past the old ones: k <= lo, at <= offs[lo], so nothing is
            // overwritten before it is read)
            let (mut at, mut k) = (0usize, 0usize);
            for (lo, hi) in runs() {
                let (a, b) = (offs[lo] as usize, offs[hi] as usize);
                slots.copy_within(a..b, at);
                let shift = (a - at) as u32;
                for i in 0..hi - lo {
                    offs[k + i + 1] = offs[lo + i + 1] - shift;
                }
                at += b - a;
                k += hi - lo;
            }
            offs.truncate(k + 1);
            offs[0] = 0;
            slots.truncate(at);
        }
        // each write's (row, slot) pairs are in increasing row order: those of a dropped
        // row go, the others' rows go down by the dropped rows before them
        for w in &mut self.writes {
            debug_assert!(w.is_sorted_by_key(|x| x.0));
            let mut before = 0usize; // dropped rows below the current pair's row
            let mut at = 0usize;
            for i in 0..w.len() {
                let (r, slot) = w[i];
                while before < dropped.len() && dropped[before] < r as usize {
                    before += 1;
                }
                if before < dropped.len() && dropped[before] == r as usize {
                    continue;
                }
                w[at] = (r - before as u32, slot);
                at += 1;
            }
            w.truncate(at);
        }
        self
    }

    /// Appends `other` (whose rows are numbered after these already).
    fn append(&mut self, other: Rows) {
        let n = self.row_match.len() as u32;
        self.row_match.extend(other.row_match);
        for (a, b) in self.gathers.iter_mut().zip(other.gathers) {
            a.extend(b);
        }
        for ((ao, asl), (bo, bsl)) in self.csr.iter_mut().zip(other.csr) {
            if bo.len() <= 1 && ao.len() <= 1 {
                continue; // a count
            }
            let base = asl.len() as u32;
            ao.extend(bo[1..].iter().map(|&o| o + base));
            asl.extend(bsl);
        }
        for (a, b) in self.counts.iter_mut().zip(other.counts) {
            a.extend(b);
        }
        for (a, b) in self.writes.iter_mut().zip(other.writes) {
            debug_assert!(b.iter().all(|&(r, _)| r >= n));
            a.extend(b);
        }
    }
}

thread_local! {
    /// The owner tables of [`Plan::assemble`], kept between calls (all `(u32::MAX, 0)`).
    static OWNERS: std::cell::RefCell<Vec<Vec<(u32, u32)>>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// The first index from `from` on where `before` is false, `before` being true then false
/// along `v` (a partition point): steps doubling from `from`, then a bisection, so that it
/// costs the logarithm of the distance, not of the length (ordered lookups one after the
/// other, as a patch makes).
fn gallop<T>(v: &[T], from: usize, before: impl Fn(&T) -> bool) -> usize {
    let n = v.len();
    if from >= n || !before(&v[from]) {
        return from.min(n);
    }
    // v[lo] is before; find hi with v[hi] not before (or the end)
    let (mut lo, mut step) = (from, 1);
    let hi = loop {
        let probe = lo + step;
        if probe >= n {
            break n;
        }
        if !before(&v[probe]) {
            break probe;
        }
        lo = probe;
        step *= 2;
    };
    lo + 1 + v[lo + 1..hi].partition_point(before)
}

/// Moves the runs `lo..hi` of `v` down, in order, over what lies before them, and
/// truncates `v` after the last (see [`Rows::filter`]).
fn compact<T: Copy>(v: &mut Vec<T>, runs: impl Iterator<Item = (usize, usize)>) {
    let mut at = 0;
    for (lo, hi) in runs {
        v.copy_within(lo..hi, at);
        at += hi - lo;
    }
    v.truncate(at);
}

/// A plan's output buffer sized to `len` values, in blocks of `block` values (one per chunk
/// of rows). A patched plan keeps its buffer (see [`Plan::patch`]): it is resized in place,
/// with some room to grow so that the next patches appending a few rows allocate nothing.
/// Every run evaluates every row, so it rewrites every block but the last one's entries past
/// the last row, which no run writes: after a resize the last block is zeroed (and a patch
/// zeroes it where the length stays), so that no value left there by the plan's former rows
/// (a non-finite one from a run that failed, found by QA) stays in it and fails the
/// finiteness test of every later run, sending them all to the slow path. Every other kept
/// value is one a later run overwrites before reading.
fn size_out(out: &mut Vec<f64>, len: usize, block: usize) {
    if out.len() == len {
        return;
    }
    if len > out.capacity() && !out.is_empty() {
        out.reserve_exact(len + len / 64 - out.len());
    }
    out.resize(len, 0.0);
    let last = len.saturating_sub(block);
    out[last..].fill(0.0);
}

impl Plan {
    /// Index arrays of `matches` on `g`, whose embeddings for the rule are `ids`. Match
    /// `k` is numbered `k` (see [`Plan::patch`]).
    pub(crate) fn build(
        prog: Program,
        rule: &Rule,
        g: &GMap,
        ids: &[EmbeddingId],
        matches: &[Match],
        backend: Option<Arc<dyn NativeBackend>>,
    ) -> Plan {
        let numbers: Vec<u32> = (0..matches.len() as u32).collect();
        let rows = Rows::of(&prog, rule, g, ids, matches, &numbers, 0);
        Plan::assemble(
            prog,
            g,
            ids,
            rows,
            matches.len(),
            backend.map_or(NativeState::Off, NativeState::Untried),
            None,
        )
    }

    /// A plan to build from matches given in batches ([`PlanBuilder::add`]), so that they
    /// need not all be held at once: the plan [`Plan::build`] gives for all of them, in
    /// order.
    pub(crate) fn builder(
        prog: Program,
        rule: &Rule,
        g: &GMap,
        ids: &[EmbeddingId],
    ) -> PlanBuilder {
        let rows = Rows::of(&prog, rule, g, ids, &[], &[], 0);
        PlanBuilder {
            prog,
            rows,
            matches: 0,
        }
    }

    /// The plan of `rows`: scatter targets (each slot written once, later writes of a slot
    /// compared), output layout.
    fn assemble(
        prog: Program,
        g: &GMap,
        ids: &[EmbeddingId],
        rows: Rows,
        matches: usize,
        native: NativeState,
        appended_from: Option<usize>,
    ) -> Plan {
        let mut targets = Vec::with_capacity(prog.writes.len());
        let mut dups = Vec::new();
        // per written embedding, the first (write, row) writing each slot: tables the size
        // of the embedding, kept per thread between plans (a patch assembles often) and
        // given back as they were, `(u32::MAX, 0)` everywhere: only the entries this call
        // set are reset, so a small patch of a large plan allocates and clears nothing
        let mut owner: Vec<Vec<(u32, u32)>> = OWNERS.with(|o| std::mem::take(&mut *o.borrow_mut()));
        let mut owner_emb: Vec<usize> = Vec::new();
        let mut woff = 0;
        let mut evaluations = 0;
        for (w, (_, emb, reg, _)) in prog.writes.iter().enumerate() {
            if *emb == GUARD_OUT {
                // one value per row, read from the output (`Plan::run_guard`)
                evaluations += rows.writes[w].len();
                targets.push((rows.writes[w].iter().map(|&(r, _)| (r, r)).collect(), woff));
                woff += prog.regs[*reg].width;
                continue;
            }
            let e = g.embedding(ids[*emb]);
            let k = if let Some(k) = owner_emb.iter().position(|x| x == emb) {
                k
            } else {
                owner_emb.push(*emb);
                if owner.len() < owner_emb.len() {
                    owner.push(Vec::new());
                }
                let t = &mut owner[owner_emb.len() - 1];
                if t.len() < e.n_slots() {
                    t.resize(e.n_slots(), (u32::MAX, 0));
                }
                owner_emb.len() - 1
            };
            let mut t = Vec::with_capacity(rows.writes[w].len());
            evaluations += rows.writes[w].len();
            for &(row, s) in &rows.writes[w] {
                let o = &mut owner[k][s as usize];
                if o.0 == u32::MAX {
                    *o = (w as u32, row);
                    t.push((row, s));
                } else if !(o.0 as usize == w && o.1 == row) {
                    dups.push((o.0 as usize, o.1, w, row));
                }
            }
            targets.push((t, woff));
            woff += prog.regs[*reg].width;
        }
        // the tables back, clean: every entry set above is a target's slot
        for (w, (_, emb, _, _)) in prog.writes.iter().enumerate() {
            if let Some(k) = owner_emb.iter().position(|x| x == emb) {
                for &(_, s) in &targets[w].0 {
                    owner[k][s as usize] = (u32::MAX, 0);
                }
            }
        }
        debug_assert!(owner.iter().all(|t| t.iter().all(|&o| o == (u32::MAX, 0))));
        OWNERS.with(|o| *o.borrow_mut() = owner);
        let out_width = woff;
        // rows per chunk: the chunk's scratch stays within a few hundred KiB; a power of two,
        // so that a row's chunk and place in it are a shift and a mask
        let chunk = prev_power_of_two(16_384 / prog.stride.max(1)).clamp(4, 256);
        let mut plan = Plan {
            prog,
            matches,
            rows: rows.row_match.len(),
            chunk,
            gathers: rows.gathers,
            csr: rows.csr,
            counts: rows.counts,
            targets,
            dups,
            out_width,
            out: Vec::new(),
            evaluations,
            native: NativeState::Off,
            row_match: rows.row_match,
            writes: rows.writes,
            chunk_starts: None,
            dead: 0,
            owner: None,
            packed: Vec::new(),
            last_writes: Vec::new(),
            identity: Vec::new(),
        };
        plan.chunk_starts = plan.chunk_starts();
        // native code already generated stays (it depends on the program, the column kinds
        // and the output layout, not on the rows), with `need` computed again from the new
        // index arrays
        plan.native = match native {
            NativeState::Ready(nat, old) => {
                let need = match appended_from {
                    Some(from) => plan.need_grown(nat.kinds(), &old, from),
                    None => plan.need(nat.kinds()),
                };
                match need {
                    Ok(need) => NativeState::Ready(nat, need),
                    Err(why) => NativeState::Failed(why),
                }
            }
            other => other,
        };
        plan
    }

    /// The plan with the rows of the matches `keep` rejects dropped, and the rows of `new`
    /// (numbered `numbers`) appended: what [`Plan::build`] gives for the kept and the new
    /// matches, up to the order of the rows. `g` must be the map the new matches were found
    /// on, and every kept row's index arrays must still hold on it (the caller's proof).
    ///
    /// `dropped`: the matches dropped since the plan was last patched or built (those `keep`
    /// rejects and did not reject then). Where it can, the plan is patched in place
    /// ([`Plan::patch_in_place`]), at a cost that grows with the rows dropped and added;
    /// otherwise, and now and then to compact it, its arrays are filtered and assembled again.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn patch(
        mut self,
        rule: &Rule,
        g: &GMap,
        ids: &[EmbeddingId],
        keep: &dyn Fn(u32) -> bool,
        dropped: &[u32],
        kept_matches: usize,
        new: &[Match],
        numbers: &[u32],
    ) -> (Plan, bool) {
        if self.patch_in_place(rule, g, ids, keep, dropped, kept_matches, new, numbers) {
            return (self, true);
        }
        let Plan {
            prog,
            gathers,
            csr,
            counts,
            native,
            row_match,
            writes,
            out,
            ..
        } = self;
        let mut rows = Rows {
            row_match,
            gathers,
            csr,
            counts,
            writes,
        }
        .filter(keep);
        let base = rows.row_match.len();
        rows.append(Rows::of(&prog, rule, g, ids, new, numbers, base));
        let mut plan = Plan::assemble(
            prog,
            g,
            ids,
            rows,
            kept_matches + new.len(),
            native,
            Some(base),
        );
        // the output buffer stays (resized by the next run, without a new allocation when
        // the rows change little)
        plan.out = out;
        plan.clear_last_block();
        (plan, false)
    }

    /// [`Plan::patch`] without moving or renumbering the kept rows, for a plan without
    /// duplicate writes: the rows of the dropped matches stay where they are, *dead*: their
    /// index arrays become those of a live row (so that they still evaluate to finite
    /// values, which nothing writes; an aggregate's slot list keeps its length, every entry
    /// the live row's first slot, and the new rows' lists are appended after the last one's),
    /// their write targets go (an ordered
    /// pass over the targets), and the new matches' rows are appended, each target checked
    /// against the table of which row writes each slot (`owner`, kept in the plan). What it
    /// costs grows with the rows dropped and added, and one pass over the targets; it gives
    /// the same values on the map as [`Plan::patch`]'s other path (every live row is the
    /// same row, with the same index arrays; only the order of the rows differs).
    ///
    /// `false`, with the plan unchanged, where it does not apply: duplicate writes, no
    /// chunked scatter, a new target on a slot a live row writes (a duplicate:
    /// the full path decides), or more dead rows than an eighth of the plan (at least 1024),
    /// when the full path compacts it.
    #[allow(clippy::too_many_arguments)]
    fn patch_in_place(
        &mut self,
        rule: &Rule,
        g: &GMap,
        ids: &[EmbeddingId],
        keep: &dyn Fn(u32) -> bool,
        dropped: &[u32],
        kept_matches: usize,
        new: &[Match],
        numbers: &[u32],
    ) -> bool {
        if self.prog.guard || !self.dups.is_empty() || self.chunk_starts.is_none() || self.rows == 0
        {
            return false;
        }
        debug_assert!(self.row_match.is_sorted(), "rows are in match order");
        // the rows of the dropped matches: row_match is sorted (rows are built and
        // appended in match order, and their numbers grow)
        let mut dropped = dropped.to_vec();
        dropped.sort_unstable();
        dropped.dedup();
        let mut dead_now: Vec<u32> = Vec::new();
        let mut from = 0;
        for &k in &dropped {
            let lo = gallop(&self.row_match, from, |&m| m < k);
            let hi = gallop(&self.row_match, lo, |&m| m <= k);
            dead_now.extend(lo as u32..hi as u32);
            from = hi;
        }
        if self.dead + dead_now.len() > (self.rows / 8).max(1024) {
            return false;
        }
        // a live row, whose index arrays the dead rows take
        let Some(live) = (0..self.rows).find(|&r| keep(self.row_match[r])) else {
            return false;
        };
        let base = self.rows;
        let added = Rows::of(&self.prog, rule, g, ids, new, numbers, base);
        // the written embeddings, in the order of the writes
        let mut embs: Vec<usize> = Vec::new();
        for (_, emb, _, _) in &self.prog.writes {
            if !embs.contains(emb) {
                embs.push(*emb);
            }
        }
        let emb_of = |w: usize| {
            embs.iter()
                .position(|e| *e == self.prog.writes[w].1)
                .expect("a written embedding")
        };
        if self.owner.is_none() {
            let mut owner: Owners = embs
                .iter()
                .map(|&e| vec![(u32::MAX, 0); g.embedding(ids[e]).n_slots()])
                .collect();
            for (w, (t, _)) in self.targets.iter().enumerate() {
                let table = &mut owner[emb_of(w)];
                for &(row, s) in t {
                    table[s as usize] = (w as u32, row);
                }
            }
            self.owner = Some(owner);
        }
        let owner = self.owner.as_mut().expect("built above");
        for (k, &e) in embs.iter().enumerate() {
            let n = g.embedding(ids[e]).n_slots();
            if owner[k].len() < n {
                owner[k].resize(n, (u32::MAX, 0));
            }
        }
        let is_dead_now = |r: u32| dead_now.binary_search(&r).is_ok();
        // every new target on a slot that no live row writes, none twice (a row's own
        // second write of a slot through the same write is no target, as in `assemble`)
        let mut taken: std::collections::HashMap<(usize, u32), (u32, u32)> =
            std::collections::HashMap::new();
        for (w, pairs) in added.writes.iter().enumerate() {
            let k = emb_of(w);
            for &(row, s) in pairs {
                let Some(&o) = owner[k].get(s as usize) else {
                    return false;
                };
                if o.0 != u32::MAX && !is_dead_now(o.1) {
                    return false;
                }
                match taken.insert((k, s), (w as u32, row)) {
                    Some(prev) if prev != (w as u32, row) => return false,
                    _ => {}
                }
            }
        }
        // from here on the plan changes: the dead rows compute the live row's values, but
        // for their aggregates' slot lists, which stay where they are (the offsets grow row
        // by row): each entry becomes the live row's first slot, so a dead row aggregates as
        // many copies of a value the live row reads as it had slots (its count stays)
        // (the packed gathers hold the rows before)
        self.packed.clear();
        for &r in &dead_now {
            let r = r as usize;
            for x in &mut self.gathers {
                x[r] = x[live];
            }
            for ((offs, slots), c) in self.csr.iter_mut().zip(&mut self.counts) {
                if offs.len() > 1 {
                    let (lo, hi) = (offs[r] as usize, offs[r + 1] as usize);
                    if let Some(&s) = slots
                        .get(offs[live] as usize..offs[live + 1] as usize)
                        .and_then(<[u32]>::first)
                    {
                        slots[lo..hi].fill(s);
                    }
                } else if c.len() == self.rows {
                    c[r] = c[live];
                }
            }
        }
        // their targets and writes go (the pairs are in row order, as `dead_now`): each dead
        // row's pairs found by bisection, the runs between them moved down
        // (returns the pairs dropped per dead row: `(row, count)`, in row order)
        let drop_rows = |v: &mut Vec<(u32, u32)>, mut gone: Option<&mut Vec<(u32, u32)>>| {
            let mut cut: Vec<(usize, usize)> = Vec::with_capacity(dead_now.len());
            let mut per_row: Vec<(u32, u32)> = Vec::new();
            let mut from = 0;
            for &r in &dead_now {
                let lo = gallop(v, from, |p| p.0 < r);
                let hi = gallop(v, lo, |p| p.0 <= r);
                if hi > lo {
                    if let Some(g) = gone.as_mut() {
                        g.extend_from_slice(&v[lo..hi]);
                    }
                    cut.push((lo, hi));
                    per_row.push((r, (hi - lo) as u32));
                }
                from = hi;
            }
            let n = v.len();
            let runs = std::iter::once(0)
                .chain(cut.iter().map(|c| c.1))
                .zip(cut.iter().map(|c| c.0).chain(std::iter::once(n)))
                .filter(|(lo, hi)| lo < hi);
            compact(v, runs);
            per_row
        };
        let mut gone = Vec::new();
        let mut removed: Vec<Vec<(u32, u32)>> = Vec::with_capacity(self.targets.len());
        for (w, (t, _)) in self.targets.iter_mut().enumerate() {
            gone.clear();
            removed.push(drop_rows(t, Some(&mut gone)));
            let table = &mut owner[emb_of(w)];
            for &(_, s) in &gone {
                table[s as usize] = (u32::MAX, 0);
            }
        }
        for wl in &mut self.writes {
            drop_rows(wl, None);
        }
        // the new rows, appended
        let new_from: Vec<usize> = self.targets.iter().map(|(t, _)| t.len()).collect();
        for (w, pairs) in added.writes.iter().enumerate() {
            let table = &mut owner[emb_of(w)];
            for &(row, s) in pairs {
                let o = &mut table[s as usize];
                if o.0 == u32::MAX {
                    *o = (w as u32, row);
                    self.targets[w].0.push((row, s));
                }
            }
        }
        let n_new = added.row_match.len();
        self.append_rows(added);
        self.rows = base + n_new;
        self.matches = kept_matches + new.len();
        self.dead += dead_now.len();
        self.evaluations = self.writes.iter().map(Vec::len).sum();
        // where each chunk's targets start (the targets stay in row order: kept ones in
        // place, new ones after): a boundary over the old rows moves down by the targets
        // dropped before it, one over the new rows is found by bisection; and the slots
        // each column must hold: at least as many as before (columns never shrink), and
        // past the new targets
        let before = self.chunk_starts.take();
        self.chunk_starts = match before {
            Some((starts, slots)) => {
                let shifted = self.shifted_chunk_starts(&starts, &removed, base);
                debug_assert_eq!(
                    shifted,
                    self.bisected_chunk_starts(),
                    "chunk starts moved as bisection finds them"
                );
                Some((shifted, self.target_slots(Some(&slots), &new_from)))
            }
            None => None,
        };
        self.regrow_need(base);
        self.clear_last_block();
        true
    }

    /// Reads again the slots of rows of a guard plan ([`compile_guard`]) whose matches have
    /// the same darts as when the rows were built but some of whose slots changed (a
    /// topology change split a vertex the row reads): `rows[i] = (row, darts)`, `darts[n]`
    /// node `n`'s dart at the match's row 0, where a guard row reads. Each gather reads its
    /// node's slot now, each aggregate the slots of its orbit now (as [`Rows::of`] does, the
    /// same sorted lists; one walk per orbit, shared by the rows that read it). Returns, per
    /// entry of `rows`, whether its row was read again: not where an aggregate's slot list
    /// or count would change length (the caller appends a new row instead), that row left
    /// as it was; none for a plan that is not a guard's.
    pub(crate) fn reslot_guard_rows(
        &mut self,
        g: &GMap,
        emb_ids: &[EmbeddingId],
        rows: &[(usize, Vec<Dart>)],
    ) -> Vec<bool> {
        if !self.prog.guard {
            return vec![false; rows.len()];
        }
        let mut ok: Vec<bool> = rows.iter().map(|(r, _)| *r < self.rows).collect();
        let mut marks = Marks::with_capacity(g.capacity());
        let mut darts: Vec<Dart> = Vec::new();
        // per aggregate, the new slot lists of the rows (flat, `starts`), then written where
        // every aggregate of the row fits
        let mut lists: Vec<(Vec<u32>, Vec<u32>)> = Vec::with_capacity(self.prog.aggs.len());
        with_orbit_rows(g, |table| {
            for (a, ak) in self.prog.aggs.iter().enumerate() {
                let (offs, _) = &self.csr[a];
                let mut starts: Vec<u32> = vec![0];
                let mut slots: Vec<u32> = Vec::new();
                // the entry (plus one) whose list a walked orbit's darts gave
                for (i, (row, nd)) in rows.iter().enumerate() {
                    let d = nd[ak.node];
                    let first = table.row_of[d.index()];
                    let n = if first != 0 {
                        let e = (first - 1) as usize;
                        let (lo, hi) = (starts[e] as usize, starts[e + 1] as usize);
                        slots.extend_from_within(lo..hi);
                        hi - lo
                    } else {
                        table.walk(g, d, ak.orbit, &mut marks, &mut darts, i as u32 + 1);
                        match ak.emb {
                            None => {
                                // a count: the number of darts (kept as the list's length)
                                slots.extend(std::iter::repeat_n(0, darts.len()));
                                darts.len()
                            }
                            Some(emb) => {
                                push_orbit_slots(&mut slots, g.embedding(emb_ids[emb]), &darts)
                            }
                        }
                    };
                    starts.push(slots.len() as u32);
                    if !ok[i] {
                        continue;
                    }
                    ok[i] = match ak.emb {
                        None => self.counts[a].get(*row).copied() == Some(n as f64),
                        Some(_) => {
                            offs.len() == self.rows + 1
                                && n == (offs[*row + 1] - offs[*row]) as usize
                        }
                    };
                }
                table.reset();
                lists.push((starts, slots));
            }
        });
        for (i, (row, nd)) in rows.iter().enumerate() {
            if !ok[i] {
                continue;
            }
            for (a, (starts, sl)) in lists.iter().enumerate() {
                if self.prog.aggs[a].emb.is_some() {
                    let (offs, slots) = &mut self.csr[a];
                    let (lo, hi) = (offs[*row] as usize, offs[*row + 1] as usize);
                    slots[lo..hi].copy_from_slice(&sl[starts[i] as usize..starts[i + 1] as usize]);
                }
            }
            for (k, rk) in self.prog.reads.iter().enumerate() {
                let e = g.embedding(emb_ids[rk.emb]);
                if let Some(x) = self.gathers.get_mut(k).and_then(|v| v.get_mut(*row)) {
                    *x = e.slot(nd[rk.node]) as u32;
                }
            }
        }
        // (a packed copy would hold the old slots' values)
        self.packed.clear();
        ok
    }

    /// A guard plan ([`compile_guard`]) with the rows of `new` (numbered `numbers`)
    /// appended in place, its other rows kept as they are, the dropped ones included: a
    /// guard writes nothing to the map, so a dropped row costs an evaluation whose value the
    /// caller ignores (its slots stay inside their columns, which never shrink). What the
    /// arrays' update costs grows with the new rows only, not with the plan. `None` for a
    /// plan that is not a guard's.
    pub(crate) fn append_guard_rows(
        &mut self,
        rule: &Rule,
        g: &GMap,
        ids: &[EmbeddingId],
        new: &[Match],
        numbers: &[u32],
    ) -> Option<()> {
        if !self.prog.guard || self.targets.len() != 1 {
            return None;
        }
        let base = self.rows;
        let added = Rows::of(&self.prog, rule, g, ids, new, numbers, base);
        let n_new = added.row_match.len();
        self.targets[0]
            .0
            .extend(added.writes[0].iter().map(|&(r, _)| (r, r)));
        self.evaluations += added.writes[0].len();
        self.append_rows(added);
        self.rows = base + n_new;
        self.matches += new.len();
        // `need` only grows: the kept rows' entries are unchanged
        self.regrow_need(base);
        Some(())
    }

    /// Room for `extra` more rows in every per-row array (the aggregates' slot lists grown
    /// by as many slots per row as they hold on average), so that the rows the next patches
    /// append ([`Plan::append_guard_rows`]) do not move arrays the size of the plan.
    pub(crate) fn reserve_rows(&mut self, extra: usize) {
        let rows = self.rows.max(1);
        self.row_match.reserve(extra);
        for x in &mut self.gathers {
            x.reserve(extra);
        }
        for c in &mut self.counts {
            c.reserve(extra);
        }
        for (offs, slots) in &mut self.csr {
            if offs.len() > 1 {
                offs.reserve(extra);
                slots.reserve(slots.len() / rows * extra + extra);
            }
        }
        for w in &mut self.writes {
            w.reserve(w.len() / rows * extra + extra);
        }
        for (t, _) in &mut self.targets {
            t.reserve(t.len() / rows * extra + extra);
        }
    }

    /// After rows were appended from `base` on to rows whose index arrays held before: what
    /// the native code may index, computed again over the appended rows only.
    fn regrow_need(&mut self, base: usize) {
        if let NativeState::Ready(nat, old) = &self.native {
            self.native = match self.need_grown(nat.kinds(), old, base) {
                Ok(need) => NativeState::Ready(Arc::clone(nat), need),
                Err(why) => NativeState::Failed(why),
            };
        }
    }

    /// Zeroes the last block of the kept output buffer after the rows changed: entries past
    /// the new last row may hold values of former rows that no run rewrites (see
    /// `size_out`), even where the buffer keeps its length.
    fn clear_last_block(&mut self) {
        let last = self
            .out
            .len()
            .saturating_sub(self.chunk * self.out_width.max(1));
        self.out[last..].fill(0.0);
    }

    /// Appends `added` (rows numbered after this plan's) to the plan's per-row arrays; the
    /// caller updates the counts and targets.
    fn append_rows(&mut self, added: Rows) {
        // the packed gathers hold the rows before
        self.packed.clear();
        let mut rows = Rows {
            row_match: std::mem::take(&mut self.row_match),
            gathers: std::mem::take(&mut self.gathers),
            csr: std::mem::take(&mut self.csr),
            counts: std::mem::take(&mut self.counts),
            writes: std::mem::take(&mut self.writes),
        };
        rows.append(added);
        self.row_match = rows.row_match;
        self.gathers = rows.gathers;
        self.csr = rows.csr;
        self.counts = rows.counts;
        self.writes = rows.writes;
    }

    /// The program columns that read embedding `target` (`ids` are the rule's embeddings).
    pub(crate) fn cols_reading(&self, ids: &[EmbeddingId], target: EmbeddingId) -> Vec<usize> {
        (0..self.prog.cols.len())
            .filter(|&c| ids[self.prog.cols[c]] == target)
            .collect()
    }

    /// Number of rows.
    pub(crate) fn rows(&self) -> usize {
        self.rows
    }

    /// Appends to `out` the slots row `row` reads from the program columns `cols` (its
    /// gathers and aggregates of them).
    /// Where the program reads the program columns `cols`, in program order: per read, its
    /// gather (`Ok(index)`) or its aggregate (`Err(CSR index)`), for [`Plan::row_slots_from`].
    pub(crate) fn slot_sources(&self, cols: &[usize]) -> Vec<Result<usize, usize>> {
        self.prog
            .ops
            .iter()
            .filter_map(|op| match op {
                Op::Gather { col, idx, .. } if cols.contains(col) => Some(Ok(*idx)),
                Op::Agg { col, csr, .. } if cols.contains(col) => Some(Err(*csr)),
                _ => None,
            })
            .collect()
    }

    /// Calls `f` with every slot row `row` reads through `sources` ([`Plan::slot_sources`]),
    /// in program order.
    pub(crate) fn row_slots_from(
        &self,
        sources: &[Result<usize, usize>],
        row: usize,
        mut f: impl FnMut(u32),
    ) {
        for source in sources {
            match *source {
                Ok(k) => f(self.gathers[k][row]),
                Err(k) => {
                    let (offs, slots) = &self.csr[k];
                    if offs.len() > row + 1 {
                        for &sl in &slots[offs[row] as usize..offs[row + 1] as usize] {
                            f(sl);
                        }
                    }
                }
            }
        }
    }

    /// Generates the plan's native code now, for the column kinds of `g` (`ids` are the
    /// rule's embeddings), when it was to be generated at the first run.
    pub(crate) fn compile_now(&mut self, g: &GMap, ids: &[EmbeddingId]) {
        if matches!(self.native, NativeState::Untried(_)) {
            self.native = self.compile_native(&self.col_kinds(g, ids));
        }
    }

    /// The kinds of the program's columns on `g` (`ids` are the rule's embeddings).
    fn col_kinds(&self, g: &GMap, ids: &[EmbeddingId]) -> Vec<ColKind> {
        self.prog
            .cols
            .iter()
            .map(|&e| col_kind(&g.embedding(ids[e]).column()))
            .collect()
    }

    /// A guard plan ([`compile_guard`]) of the rows `rows` of this one only, in that order,
    /// each keeping its match's number (so [`Plan::run_guard`] on it gives the numbers of
    /// the matches among `rows` that pass, as on this plan), sharing this plan's native code
    /// (compiled now if it was to be; `g` and `ids` give the column kinds). `None` for a plan
    /// that is not a guard's, or a row out of range.
    pub(crate) fn guard_rows(
        &mut self,
        g: &GMap,
        ids: &[EmbeddingId],
        rows: &[u32],
    ) -> Option<Plan> {
        if !self.prog.guard
            || self.targets.len() != 1
            || rows.iter().any(|&r| r as usize >= self.rows)
        {
            return None;
        }
        self.compile_now(g, ids);
        let pick = |v: &[u32]| -> Vec<u32> { rows.iter().map(|&r| v[r as usize]).collect() };
        let n = self.rows;
        let csr = self
            .csr
            .iter()
            .map(|(offs, slots)| {
                if offs.len() != n + 1 {
                    return (vec![0], Vec::new()); // a count: no slots
                }
                let mut o = Vec::with_capacity(rows.len() + 1);
                let mut sl = Vec::new();
                o.push(0);
                for &r in rows {
                    let r = r as usize;
                    sl.extend_from_slice(&slots[offs[r] as usize..offs[r + 1] as usize]);
                    o.push(sl.len() as u32);
                }
                (o, sl)
            })
            .collect();
        let counts = self
            .counts
            .iter()
            .map(|c| rows.iter().map(|&r| c[r as usize]).collect())
            .collect();
        let k = rows.len() as u32;
        let native = match &self.native {
            // the sub-plan's index entries are some of this plan's: what this plan's columns
            // must hold (`need`) bounds what the sub-plan's need
            NativeState::Ready(nat, need) => NativeState::Ready(Arc::clone(nat), need.clone()),
            NativeState::Off => NativeState::Off,
            _ => NativeState::Failed("not compiled".into()),
        };
        Some(Plan {
            prog: self.prog.clone(),
            matches: rows.len(),
            rows: rows.len(),
            chunk: self.chunk,
            gathers: self.gathers.iter().map(|x| pick(x)).collect(),
            csr,
            counts,
            targets: vec![((0..k).map(|r| (r, r)).collect(), self.targets[0].1)],
            dups: Vec::new(),
            out_width: self.out_width,
            out: Vec::new(),
            evaluations: rows.len(),
            native,
            row_match: pick(&self.row_match),
            writes: vec![(0..k).map(|r| (r, r)).collect()],
            chunk_starts: None,
            dead: 0,
            owner: None,
            packed: Vec::new(),
            last_writes: Vec::new(),
            identity: Vec::new(),
        })
    }

    /// The program's aggregated orbit types (see [`Program::agg_orbits`]).
    pub(crate) fn agg_orbits(&self) -> Vec<OrbitType> {
        self.prog.agg_orbits()
    }

    /// Whether the plan runs native code (after its first run).
    pub(crate) fn is_native(&self) -> bool {
        matches!(self.native, NativeState::Ready(..))
    }

    /// Per program column, the length it must have at least (in elements) for the index
    /// arrays to stay in it: one more than the largest slot they hold, times the width read;
    /// `Err` when the arrays are out of shape (rows, CSR offsets). Computed whenever the
    /// arrays change (built or patched), so that a native run only compares lengths.
    fn need(&self, kinds: &[ColKind]) -> Result<Vec<usize>, String> {
        self.need_grown(kinds, &vec![0; kinds.len()], 0)
    }

    /// [`Plan::need`] for a plan whose rows from `from` on were appended to rows kept from
    /// a plan whose need was `old` (a patch: the kept rows' entries are some of that plan's,
    /// copied unchanged by [`Rows::filter`], so `old` bounds them): the shapes checked as
    /// there, the largest slots taken over the appended rows only.
    fn need_grown(
        &self,
        kinds: &[ColKind],
        old: &[usize],
        from: usize,
    ) -> Result<Vec<usize>, String> {
        let rows = self.rows;
        let (mut need, from) = if old.len() == kinds.len() && from <= rows {
            (old.to_vec(), from)
        } else {
            (vec![0; kinds.len()], 0)
        };
        for op in &self.prog.ops {
            match op {
                Op::Gather { dst, col, idx } => {
                    let g = &self.gathers[*idx];
                    if g.len() != rows {
                        return Err("a gather of another length".into());
                    }
                    let w = if kinds[*col] == ColKind::Real {
                        self.prog.regs[*dst].width
                    } else {
                        1
                    };
                    if let Some(&m) = g[from..].iter().max() {
                        need[*col] = need[*col].max((m as usize + 1) * w);
                    }
                }
                Op::Agg { dst, col, csr, .. } => {
                    let (offs, slots) = &self.csr[*csr];
                    // the kept rows' offsets were checked when `old` was computed, and a
                    // patch keeps them increasing (`Rows::filter` shifts each run of them
                    // by one amount; appending adds after the last): only the appended
                    // rows' are checked again (all of them in debug builds)
                    debug_assert!(offs.windows(2).all(|o| o[0] <= o[1]));
                    let monotone = offs
                        .get(from.saturating_sub(1)..)
                        .is_some_and(|o| o.windows(2).all(|o| o[0] <= o[1]));
                    if offs.len() != rows + 1 || !monotone || offs[rows] as usize > slots.len() {
                        return Err("an aggregate's offsets out of shape".into());
                    }
                    let w = self.prog.regs[*dst].width;
                    let start = offs[from] as usize;
                    if let Some(&m) = slots[start..offs[rows] as usize].iter().max() {
                        need[*col] = need[*col].max((m as usize + 1) * w);
                    }
                }
                Op::RowData { data, .. } if self.counts[*data].len() != rows => {
                    return Err("counts of another length".into());
                }
                _ => {}
            }
        }
        Ok(need)
    }

    /// Compiles the program to native code for columns of `kinds`.
    fn compile_native(&self, kinds: &[ColKind]) -> NativeState {
        // what the code will index: checked here and whenever the arrays change (`need`),
        // so that a run only compares column lengths with `need`
        let need = match self.need(kinds) {
            Ok(need) => need,
            Err(why) => return NativeState::Failed(why),
        };
        let offsets: Vec<usize> = self.targets.iter().map(|t| t.1).collect();
        let NativeState::Untried(backend) = &self.native else {
            return NativeState::Failed("no backend".into());
        };
        let layout = OutLayout {
            chunk: self.chunk,
            out_width: self.out_width,
            offsets: &offsets,
        };
        match backend.compile(&self.prog, kinds, self.csr.len(), &layout) {
            Ok(n) => NativeState::Ready(n, need),
            Err(e) => NativeState::Failed(e),
        }
    }

    /// Copies in row order the values of each gather that reads, alone (no other gather
    /// or aggregate reads its column, no other gather goes through its index array), a
    /// column of reals this plan does not write and that held still since the plan's last chunked run (its
    /// write count is the same): what a model reads but does not change from step to step
    /// (rest shapes, stiffness tensors, masses), which the native code then reads
    /// sequentially (through `identity`) instead of at scattered slots. A copy whose column
    /// was written since is dropped (the gather reads the column again until it holds still
    /// for a run), and so is every copy when the plan's rows change. The values are the
    /// column's at the gathered slots: the same bits. Issue 15's "read-only per-element data
    /// packed in row order at plan time".
    fn pack_read_only(&mut self, g: &GMap, ids: &[EmbeddingId]) {
        let n = self.prog.cols.len();
        if self.last_writes.len() != n {
            self.last_writes = vec![u64::MAX; n];
        }
        let written = |e: usize| self.prog.writes.iter().any(|w| ids[w.1] == ids[e]);
        let mut fresh: Vec<Packed> = Vec::new();
        for op in &self.prog.ops {
            let Op::Gather { dst, col, idx } = *op else {
                continue;
            };
            // the column's only gather, and the only one through its index array (several
            // columns on one orbit share an index array: packed, it would become the
            // identity for them too)
            let alone = self.prog.ops.iter().all(|o| match o {
                Op::Gather { col: c, idx: i, .. } => (*c == col) == (*i == idx),
                Op::Agg { col: c, .. } => *c != col,
                _ => true,
            });
            let e = self.prog.cols[col];
            if !alone || written(e) {
                continue;
            }
            let emb = g.embedding(ids[e]);
            let ColumnRef::Real(x) = emb.column() else {
                continue;
            };
            let count = emb.writes();
            let w = self.prog.regs[dst].width;
            match self.packed.iter().position(|p| p.col == col) {
                Some(k) if self.packed[k].writes == count => {}
                Some(k) => {
                    self.packed.swap_remove(k);
                }
                None if self.last_writes[col] == count => {
                    let slots = &self.gathers[idx][..self.rows];
                    // a gather that reads its slots in increasing order over a range at
                    // most 1.5 times the rows already streams the column: a copy would
                    // cost memory for nothing (a co-rotational plan's 144 floats per tet);
                    // such a gather is recorded as not worth a copy (`values` empty). So
                    // does one in increasing order but for a few breaks (at most one per 16
                    // rows): a patched plan's, whose dead rows read the slot of one live row
                    // (one cache line for all) and whose new rows, appended, read the slots
                    // a topology change appended, in order too (copying it after every cut
                    // cost most of a step, for steps no faster)
                    let (lo, hi) = slots
                        .iter()
                        .fold((u32::MAX, 0), |(lo, hi), &s| (lo.min(s), hi.max(s)));
                    let span = (hi as usize + 1).saturating_sub(lo as usize);
                    let breaks = slots.windows(2).filter(|w| w[1] < w[0]).count();
                    let streams = 16 * breaks <= self.rows && 2 * span <= 3 * self.rows;
                    let mut values = Vec::new();
                    let inside = streams
                        || slots.iter().all(|&s| {
                            x.get(s as usize * w..(s as usize + 1) * w)
                                .map(|v| values.extend_from_slice(v))
                                .is_some()
                        });
                    if inside {
                        fresh.push(Packed {
                            col,
                            idx,
                            writes: count,
                            values,
                        });
                    }
                }
                None => {}
            }
            self.last_writes[col] = count;
        }
        self.packed.append(&mut fresh);
        if self.packed.iter().any(|p| !p.values.is_empty()) && self.identity.len() < self.rows {
            self.identity = (0..self.rows as u32).collect();
        }
    }

    /// Bytes held by the plan's arrays.
    pub(crate) fn memory_bytes(&self) -> usize {
        let g: usize = self.gathers.iter().map(|x| x.capacity() * 4).sum();
        let c: usize = self
            .csr
            .iter()
            .map(|(o, s)| (o.capacity() + s.capacity()) * 4)
            .sum::<usize>()
            + self.counts.iter().map(|x| x.capacity() * 8).sum::<usize>();
        let t: usize = self.targets.iter().map(|(t, _)| t.capacity() * 8).sum();
        let w: usize = self.writes.iter().map(|x| x.capacity() * 8).sum();
        let o: usize = self.owner.iter().flatten().map(|t| t.capacity() * 8).sum();
        let p: usize = self
            .packed
            .iter()
            .map(|p| p.values.capacity() * 8)
            .sum::<usize>()
            + self.identity.capacity() * 4
            + self.last_writes.capacity() * 8;
        g + c + t + w + o + p + self.row_match.capacity() * 4 + self.out.capacity() * 8
    }

    /// Where the value of the write whose output offset is `off` and width `width` lies in
    /// `out` for domain row `row`.
    #[inline]
    fn out_index(&self, row: u32, off: usize, width: usize) -> usize {
        let row = row as usize;
        let i = row & (self.chunk - 1);
        (row - i) * self.out_width + off * self.chunk + i * width
    }

    /// Number of matches.
    pub(crate) fn matches(&self) -> usize {
        self.matches
    }

    /// Number of write evaluations an application makes (as the interpreter counts them).
    pub(crate) fn evaluations(&self) -> usize {
        self.evaluations
    }

    /// Evaluates every match and writes the results into `g`. `Err` leaves `g` unchanged
    /// and means: let the interpreter apply the rule (it reports the error precisely).
    /// `eager` (without `check`): where the program reads no embedding it writes, a chunked
    /// run writes each chunk's values as soon as they are evaluated (see
    /// [`Plan::run_chunked`]); an `Err` may then leave the values of the chunks before the
    /// failure written, and the inputs unchanged.
    pub(crate) fn run(
        &mut self,
        g: &mut GMap,
        ids: &[EmbeddingId],
        params: &[Val],
        check: Option<&ValueCheck<'_>>,
        eager: bool,
    ) -> Result<(), Unsupported> {
        if let Some(done) = self.run_chunked(g, ids, params, check, eager) {
            return done;
        }
        self.evaluate(g, ids, params)?;
        if let Some(check) = check {
            if !self.values_pass(ids, check, 0, self.rows.div_ceil(self.chunk), &self.out) {
                return unsupported("the values failed the caller's check");
            }
        }
        self.scatter(g, ids)
    }

    /// Whether the values of every write of chunks `from..to` in `out` (the output buffer,
    /// or from chunk `from` on a part of it starting at that chunk's block) pass `check`.
    fn values_pass(
        &self,
        ids: &[EmbeddingId],
        check: &ValueCheck<'_>,
        from: usize,
        to: usize,
        out: &[f64],
    ) -> bool {
        let (ch, block) = (self.chunk, self.chunk * self.out_width.max(1));
        (from..to).all(|c| {
            let n = (self.rows - c * ch).min(ch);
            let blk = &out[(c - from) * block..][..block];
            self.prog
                .writes
                .iter()
                .zip(&self.targets)
                .all(|((_, emb, reg, _), (_, off))| {
                    *emb == GUARD_OUT || {
                        let width = self.prog.regs[*reg].width;
                        check(ids[*emb], &blk[off * ch..][..n * width])
                    }
                })
        })
    }

    /// Whether the chunks' values may be scattered chunk by chunk in parallel, and where each
    /// write's targets of each chunk start (see [`Plan::chunk_starts`]): where every slot is
    /// written once (no duplicate writes to compare), so that no two chunks write one value.
    fn chunk_starts(&mut self) -> Option<(Vec<Vec<u32>>, Vec<usize>)> {
        if self.prog.guard || !self.dups.is_empty() || self.rows == 0 {
            return None;
        }
        for (t, _) in &mut self.targets {
            if !t.is_sorted_by_key(|x| x.0) {
                t.sort_unstable_by_key(|x| x.0);
            }
        }
        self.chunk_starts_sorted()
    }

    /// The chunk starts of targets from which the pairs `removed[w]` (per write, `(row,
    /// count)` in row order) were dropped and to which the pairs of rows `base..` were
    /// appended, from `old`, the starts before (over `base` rows): a boundary at or below
    /// `base` moves down by the pairs dropped before it; one past it is found by bisection.
    fn shifted_chunk_starts(
        &self,
        old: &[Vec<u32>],
        removed: &[Vec<(u32, u32)>],
        base: usize,
    ) -> Vec<Vec<u32>> {
        let chunks = self.rows.div_ceil(self.chunk);
        self.targets
            .iter()
            .zip(old.iter().zip(removed))
            .map(|((t, _), (old, removed))| {
                let (mut k, mut gone, mut at) = (0, 0u32, 0);
                (0..=chunks)
                    .map(|c| {
                        let b = c * self.chunk;
                        if b <= base && c < old.len() {
                            while k < removed.len() && (removed[k].0 as usize) < b {
                                gone += removed[k].1;
                                k += 1;
                            }
                            at = (old[c] - gone) as usize;
                        } else {
                            at = gallop(t, at, |&(r, _)| (r as usize) < b);
                        }
                        at as u32
                    })
                    .collect()
            })
            .collect()
    }

    /// [`Plan::chunk_starts`] for targets known to be in row order.
    fn chunk_starts_sorted(&self) -> Option<(Vec<Vec<u32>>, Vec<usize>)> {
        if self.prog.guard || !self.dups.is_empty() || self.rows == 0 {
            return None;
        }
        Some((self.bisected_chunk_starts(), self.target_slots(None, &[])))
    }

    /// Per write, where the targets of each chunk start, found by a bisection per chunk
    /// (the targets must be in row order).
    fn bisected_chunk_starts(&self) -> Vec<Vec<u32>> {
        debug_assert!(self
            .targets
            .iter()
            .all(|(t, _)| t.is_sorted_by_key(|x| x.0)));
        let chunks = self.rows.div_ceil(self.chunk);
        self.targets
            .iter()
            .map(|(t, _)| {
                (0..=chunks)
                    .map(|c| t.partition_point(|&(r, _)| (r as usize) < c * self.chunk) as u32)
                    .collect()
            })
            .collect()
    }

    /// Per write, the slots its column must hold: one past its largest target, with
    /// `known` a bound already known for the targets of each write before `from[w]` (those
    /// after are looked at; without it, all are).
    fn target_slots(&self, known: Option<&[usize]>, from: &[usize]) -> Vec<usize> {
        self.targets
            .iter()
            .enumerate()
            .map(|(w, (t, _))| {
                let (known, from) = match known {
                    Some(s) if s.len() == self.targets.len() => (s[w], from[w].min(t.len())),
                    _ => (0, 0),
                };
                t[from..]
                    .iter()
                    .map(|&(_, s)| s as usize + 1)
                    .fold(known, usize::max)
            })
            .collect()
    }

    /// A run of the native code that checks each chunk's values finite as soon as the chunk
    /// is evaluated, while they are in cache, on the chunk's own thread (no second pass over
    /// the output buffer), then, once every chunk passed, scatters them chunk by chunk, in
    /// parallel where [`Plan::evaluate`] runs in parallel (its scatter runs on one thread).
    /// The values are those of [`Plan::run`]'s other path, bit for bit: every row is
    /// evaluated before anything is written. `Err` (nothing written): a chunk failed, as in
    /// [`Plan::run`]. `None` where this run cannot go this way (no native code, no
    /// [`Plan::chunk_starts`], columns of other kinds or lengths): [`Plan::run`] then
    /// takes the other path.
    // the `unsafe` blocks call the plan's native code and write the map's columns through
    // pointers, each with its SAFETY comment
    #[allow(unsafe_code)]
    fn run_chunked(
        &mut self,
        g: &mut GMap,
        ids: &[EmbeddingId],
        params: &[Val],
        check: Option<&ValueCheck<'_>>,
        eager: bool,
    ) -> Option<Result<(), Unsupported>> {
        self.chunk_starts.as_ref()?;
        let pvals = param_values(params)?;
        let kinds = self.col_kinds(g, ids);
        if matches!(self.native, NativeState::Untried(_)) {
            self.native = self.compile_native(&kinds);
        }
        let NativeState::Ready(nat, need) = &self.native else {
            return None;
        };
        // owned, so that the read-only gathers can be packed now (`&mut self`; each copy
        // checks its slots inside its column)
        let (nat, need) = (Arc::clone(nat), need.clone());
        self.pack_read_only(g, ids);
        let fills = self.prog.fill_values(&pvals);
        if nat.kinds() != kinds || !self.prog.fills_fit(&fills) {
            return None;
        }
        // the written embeddings: distinct columns of reals or booleans
        let mut written: Vec<usize> = Vec::new();
        for (_, emb, _, _) in &self.prog.writes {
            if !written.contains(emb) {
                written.push(*emb);
            }
        }
        for (k, &e) in written.iter().enumerate() {
            let kind = col_kind(&g.embedding(ids[e]).column());
            if kind == ColKind::Int
                || written[..k].iter().any(|&f| ids[f] == ids[e])
                || g.embedding(ids[e]).derived().is_some()
            {
                return None;
            }
        }
        let (ch, ow) = (self.chunk, self.out_width);
        let (rows, n_chunks) = (self.rows, self.rows.div_ceil(ch));
        let block = ch * ow.max(1);
        size_out(&mut self.out, n_chunks * block, block);
        // the written columns' addresses, each taken once per write as `scatter` does (one
        // write counted per write); the program reads a written column through the same one
        let mut wcols: Vec<(usize, Col)> = Vec::new();
        for (_, emb, _, _) in &self.prog.writes {
            let col = match g.column_mut(ids[*emb]) {
                Ok(ColumnMut::Real(v)) => Col::Real(v.as_mut_ptr(), v.len()),
                Ok(ColumnMut::Bool(v)) => Col::Bool(v.as_mut_ptr(), v.len()),
                _ => return None,
            };
            if !wcols.iter().any(|(e, _)| e == emb) {
                wcols.push((*emb, col));
            }
        }
        let mut col_p: Vec<*const u8> = Vec::with_capacity(self.prog.cols.len());
        for (k, &e) in self.prog.cols.iter().enumerate() {
            let (p, len) = match wcols.iter().find(|(w, _)| *w == e) {
                Some((_, Col::Real(p, n))) => (p.cast_const().cast::<u8>(), *n),
                Some((_, Col::Bool(p, n))) => (p.cast_const().cast::<u8>(), *n),
                None => col_ptr(&g.embedding(ids[e]).column()),
            };
            if len < need[k] {
                return None;
            }
            col_p.push(p);
        }
        // the read-only gathers read their values in row order (packed above), through the
        // identity
        for p in self.packed.iter().filter(|p| !p.values.is_empty()) {
            col_p[p.col] = p.values.as_ptr().cast::<u8>();
        }
        let write_col: Vec<Col> = self
            .prog
            .writes
            .iter()
            .map(|(_, emb, _, _)| {
                wcols
                    .iter()
                    .find(|(e, _)| e == emb)
                    .map(|(_, c)| *c)
                    .expect("taken above")
            })
            .collect();
        // every target slot lies inside its column (the map may have changed since the
        // plan was built without the plan noticing: then the slow path reports it)
        let (starts, slots) = self.chunk_starts.as_ref().expect("checked above");
        for (w, &n) in slots.iter().enumerate() {
            let width = self.prog.regs[self.prog.writes[w].2].width;
            if n * width > write_col[w].len() {
                return None;
            }
        }
        let out = SyncPtr(self.out.as_mut_ptr());
        let mut tables =
            ArgTables::new(&self.gathers, &self.csr, &self.counts, &*nat, col_p, &fills);
        for p in self.packed.iter().filter(|p| !p.values.is_empty()) {
            tables.gathers[p.idx] = self.identity.as_ptr();
        }
        let args = tables.args(out.0);
        let store_chunk = |c: usize| {
            // SAFETY: block `c` of the output buffer (inside it: `n_chunks` blocks) is
            // touched by the one call handling chunk `c` only.
            let blk = unsafe { std::slice::from_raw_parts(out.at(c * block), block) };
            for (w, (t, off)) in self.targets.iter().enumerate() {
                let width = self.prog.regs[self.prog.writes[w].2].width;
                let mine = &t[starts[w][c] as usize..starts[w][c + 1] as usize];
                let vals = &blk[off * ch..][..ch * width];
                // SAFETY: every slot lies inside its column (checked above); every slot of a
                // column is a target of one row only (`assemble`: no duplicate writes, and
                // the written embeddings are distinct columns), and these rows are chunk
                // `c`'s, so no other thread touches these values; every row was evaluated
                // before (nothing reads the columns meanwhile), or, eagerly, the rows still
                // being evaluated read no written column (`reads_written` false), and nothing
                // else holds a reference into the columns during the run.
                unsafe {
                    match (write_col[w], width) {
                        (Col::Real(p, _), 1) => store_slots::<1>(p, vals, mine, ch),
                        (Col::Real(p, _), 3) => store_slots::<3>(p, vals, mine, ch),
                        (Col::Real(p, _), 9) => store_slots::<9>(p, vals, mine, ch),
                        (Col::Real(p, _), _) => {
                            for &(row, slot) in mine {
                                let i = row as usize & (ch - 1);
                                let v = std::slice::from_raw_parts_mut(
                                    p.add(slot as usize * width),
                                    width,
                                );
                                v.copy_from_slice(&vals[i * width..][..width]);
                            }
                        }
                        (Col::Bool(p, _), _) => {
                            for &(row, slot) in mine {
                                *p.add(slot as usize) = vals[row as usize & (ch - 1)] != 0.0;
                            }
                        }
                    }
                }
            }
        };
        let one = |c: usize| -> bool {
            let (first, n) = (c * ch, (rows - c * ch).min(ch));
            // SAFETY: as in `Plan::evaluate`: `args` describes this plan's arrays, for which
            // `nat` was compiled (kinds, lengths against `need`, fills checked above), but
            // for each packed gather, whose column is its `rows * width` values in row order
            // and whose index array is `identity`, row `r` at `r` (`pack_read_only`: at
            // least `rows` long), so the code reads inside it; rows `first..first + n` are
            // chunk `c`, run by this call only, writing block `c`.
            if unsafe { nat.call(&args, first, n) } != 0 {
                return false;
            }
            // SAFETY: block `c`, now written, is this call's alone (see `store_chunk`).
            let blk = unsafe { std::slice::from_raw_parts(out.at(c * block), block) };
            // no early exit, so that it vectorizes
            !blk.iter().fold(false, |bad, x| bad | !x.is_finite())
                && check.is_none_or(|check| self.values_pass(ids, check, c, c + 1, blk))
        };
        native::CHUNKED.fetch_add(1, Ordering::Relaxed);
        let parallel = n_chunks >= 4 && rayon::current_num_threads() > 1;
        // eager: each chunk written as soon as it passes, while its values are in cache
        // (a cloth step at 10^5 quads, one thread: 5.2 -> 4.8 ms, against writing every
        // chunk after all are evaluated). No row reads a written embedding, so every
        // evaluation reads what it would have read before any write, and so does the
        // interpreter that takes over after a failure.
        let reads_written = self.prog.cols.iter().any(|&c| {
            self.prog
                .writes
                .iter()
                .any(|w| w.1 != GUARD_OUT && ids[w.1] == ids[c])
        });
        if eager && check.is_none() && !reads_written {
            let pass = |c: usize| {
                let ok = one(c);
                if ok {
                    store_chunk(c);
                }
                ok
            };
            let ok = if parallel {
                (0..n_chunks).into_par_iter().all(pass)
            } else {
                (0..n_chunks).all(pass)
            };
            return Some(if ok {
                Ok(())
            } else {
                unsupported("an evaluation failed or a value is not finite")
            });
        }
        let ok = if parallel {
            (0..n_chunks).into_par_iter().all(one)
        } else {
            (0..n_chunks).all(one)
        };
        if !ok {
            return Some(unsupported("an evaluation failed or a value is not finite"));
        }
        if parallel {
            (0..n_chunks).into_par_iter().for_each(store_chunk);
        } else {
            (0..n_chunks).for_each(store_chunk);
        }
        Some(Ok(()))
    }

    /// A guard plan's ([`compile_guard`]) run: the numbers of the matches (as
    /// [`Plan::build`] and [`Plan::patch`] numbered them) whose guard holds, in row order.
    /// `Err` means: let the interpreter evaluate the guard.
    pub(crate) fn run_guard(
        &mut self,
        g: &GMap,
        ids: &[EmbeddingId],
        params: &[Val],
    ) -> Result<Vec<u32>, Unsupported> {
        if !self.prog.guard {
            return unsupported("not a guard program");
        }
        self.evaluate(g, ids, params)?;
        let off = self.targets[0].1;
        Ok((0..self.rows as u32)
            .filter(|&r| self.out[self.out_index(r, off, 1)] != 0.0)
            .map(|r| self.row_match[r as usize])
            .collect())
    }

    /// Evaluates every row into the output buffer: nothing is written to the map. `Err`: an
    /// evaluation failed, a value is not finite, two writes of one orbit differ.
    // the one `unsafe` block calls the plan's native code (see its SAFETY comment)
    #[allow(unsafe_code)]
    fn evaluate(
        &mut self,
        g: &GMap,
        ids: &[EmbeddingId],
        params: &[Val],
    ) -> Result<(), Unsupported> {
        let Some(pvals) = param_values(params) else {
            return unsupported("an integer parameter beyond 2^53");
        };
        let fills = self.prog.fill_values(&pvals);
        let ow = self.out_width;
        let ch = self.chunk;
        let n_chunks = self.rows.div_ceil(ch);
        let block = ch * ow.max(1);
        let need_out = n_chunks * block;
        size_out(&mut self.out, need_out, block);
        let mut native_done = false;
        {
            let cols: Vec<ColumnRef> = self
                .prog
                .cols
                .iter()
                .map(|&e| g.embedding(ids[e]).column())
                .collect();
            let ctx = Ctx {
                prog: &self.prog,
                run: RUNS.fetch_add(1, Ordering::Relaxed),
                fills: &fills,
                cols: &cols,
                gathers: &self.gathers,
                csr: &self.csr,
                counts: &self.counts,
                chunk: self.chunk,
                out_offsets: &self.targets,
            };
            let rows = self.rows;
            let kinds: Vec<ColKind> = cols.iter().map(col_kind).collect();
            if matches!(self.native, NativeState::Untried(_)) {
                self.native = self.compile_native(&kinds);
            }
            if let NativeState::Ready(nat, need) = &self.native {
                let fits = nat.kinds() == kinds
                    && self.prog.fills_fit(&fills)
                    && cols.iter().zip(need).all(|(c, &m)| col_ptr(c).1 >= m)
                    && self.out.len() == need_out;
                if fits {
                    let col_p: Vec<*const u8> = cols.iter().map(|c| col_ptr(c).0).collect();
                    let tables = ArgTables::new(
                        &self.gathers,
                        &self.csr,
                        &self.counts,
                        &**nat,
                        col_p,
                        &fills,
                    );
                    let args = tables.args(self.out.as_mut_ptr());
                    let one = |c: usize| {
                        let (first, n) = (c * ch, (rows - c * ch).min(ch));
                        // SAFETY: `args` describes this plan's arrays, for which `nat` was
                        // compiled (checked above: the column kinds, each column at least as
                        // long as the largest slot its index arrays hold requires (`need`,
                        // computed from these arrays by `Plan::need` whenever they were set:
                        // in `compile_native`, and in `assemble` after a patch; it also
                        // checked their row lengths and CSR shape), fills at least as
                        // wide as their registers, the output buffer of `n_chunks` blocks,
                        // `calls` and `helpers` `nat`'s own tables (`ArgTables::new`), which
                        // `nat`, held by `self.native`, keeps valid for the run);
                        // rows `first..first + n` are one chunk inside `0..rows`, and each
                        // chunk is run by one call only, so concurrent calls write disjoint
                        // blocks of `out`, which nothing else touches meanwhile (`&mut self`).
                        if unsafe { nat.call(&args, first, n) } == 0 {
                            Ok(())
                        } else {
                            Err(())
                        }
                    };
                    let ok = if n_chunks >= 4 && rayon::current_num_threads() > 1 {
                        (0..n_chunks).into_par_iter().try_for_each(one)
                    } else {
                        (0..n_chunks).try_for_each(one)
                    };
                    if ok.is_err() {
                        return unsupported("an evaluation failed");
                    }
                    native_done = true;
                }
            }
            let ok = if native_done {
                Ok(())
            } else if n_chunks >= 4 && rayon::current_num_threads() > 1 {
                self.out
                    .par_chunks_mut(block)
                    .enumerate()
                    .try_for_each(|(c, out)| ctx.chunk(c * ch, (rows - c * ch).min(ch), out))
            } else {
                self.out
                    .chunks_mut(block)
                    .enumerate()
                    .try_for_each(|(c, out)| ctx.chunk(c * ch, (rows - c * ch).min(ch), out))
            };
            if ok.is_err() {
                return unsupported("an evaluation failed");
            }
        }
        // a non-finite value is never written: one pass over the outputs (no early exit, so
        // that it vectorizes), the interpreter then names the rule, embedding and dart
        if self.out.iter().fold(false, |bad, x| bad | !x.is_finite()) {
            return unsupported("a non-finite value");
        }
        // writes of one orbit by two writes must agree
        for &(w1, r1, w2, r2) in &self.dups {
            let (o1, o2) = (self.targets[w1].1, self.targets[w2].1);
            let width = self.prog.regs[self.prog.writes[w1].2].width;
            let a = &self.out[self.out_index(r1, o1, width)..][..width];
            let b = &self.out[self.out_index(r2, o2, width)..][..width];
            if a.iter().zip(b).any(|(x, y)| x.to_bits() != y.to_bits()) {
                return unsupported("two writes of one orbit differ");
            }
        }
        Ok(())
    }

    /// Writes the evaluated values ([`Plan::evaluate`]) into `g`.
    fn scatter(&self, g: &mut GMap, ids: &[EmbeddingId]) -> Result<(), Unsupported> {
        for (w, (_, emb, reg, _)) in self.prog.writes.iter().enumerate() {
            if *emb == GUARD_OUT {
                continue;
            }
            let width = self.prog.regs[*reg].width;
            let (t, off) = &self.targets[w];
            let (out, off) = (&self.out, *off);
            let at = |row: u32| self.out_index(row, off, width);
            let col = g
                .column_mut(ids[*emb])
                .map_err(|e| Unsupported(e.to_string()))?;
            match col {
                ColumnMut::Real(v) => match width {
                    1 => scatter_n::<1>(v, out, t, at),
                    3 => scatter_n::<3>(v, out, t, at),
                    9 => scatter_n::<9>(v, out, t, at),
                    _ => {
                        for &(row, slot) in t {
                            v[slot as usize * width..][..width]
                                .copy_from_slice(&out[at(row)..][..width]);
                        }
                    }
                },
                ColumnMut::Bool(v) => {
                    for &(row, slot) in t {
                        v[slot as usize] = out[at(row)] != 0.0;
                    }
                }
                ColumnMut::Int(v) => {
                    for &(row, slot) in t {
                        v[slot as usize] = out[at(row)] as i64;
                    }
                }
            }
        }
        Ok(())
    }
}

impl Program {
    /// The fill values of a run: constants, and parameters from `pvals`.
    fn fill_values<'a>(&'a self, pvals: &'a [Vec<f64>]) -> Vec<&'a [f64]> {
        self.fills
            .iter()
            .map(|f| match f {
                FillSrc::Const(x) => x.as_slice(),
                FillSrc::Param(k) => pvals[*k].as_slice(),
            })
            .collect()
    }

    /// Whether every fill is as wide as the registers it fills (what native code reads).
    fn fills_fit(&self, fills: &[&[f64]]) -> bool {
        self.ops.iter().all(|op| match op {
            Op::Fill { dst, at } => fills[*at].len() >= self.regs[*dst].width,
            _ => true,
        })
    }
}

/// The element type of a column.
fn col_kind(c: &ColumnRef) -> ColKind {
    match c {
        ColumnRef::Real(_) => ColKind::Real,
        ColumnRef::Bool(_) => ColKind::Bool,
        ColumnRef::Int(_) => ColKind::Int,
    }
}

/// The address of a column's first element and its length in elements.
fn col_ptr(c: &ColumnRef) -> (*const u8, usize) {
    match c {
        ColumnRef::Real(x) => (x.as_ptr().cast::<u8>(), x.len()),
        ColumnRef::Bool(x) => (x.as_ptr().cast::<u8>(), x.len()),
        ColumnRef::Int(x) => (x.as_ptr().cast::<u8>(), x.len()),
    }
}

/// Copies the `N` floats of each target's row in `vals` (a write's values of one chunk, rows
/// of `N` floats, row `r` at `r mod chunk`) to its slot of the column at `col`.
///
/// # Safety
/// Every slot's `N` floats lie inside the column, and no other thread reads or writes them
/// meanwhile.
#[allow(unsafe_code)]
#[inline]
unsafe fn store_slots<const N: usize>(
    col: *mut f64,
    vals: &[f64],
    targets: &[(u32, u32)],
    chunk: usize,
) {
    for &(row, slot) in targets {
        let o: &[f64; N] = vals[(row as usize & (chunk - 1)) * N..][..N]
            .try_into()
            .expect("N floats");
        // SAFETY: the caller's contract: the slot's floats are inside the column and ours.
        unsafe { col.add(slot as usize * N).cast::<[f64; N]>().write(*o) };
    }
}

/// A written column, by address and length in elements (see [`Plan::run_chunked`]).
#[derive(Clone, Copy)]
enum Col {
    Real(*mut f64, usize),
    Bool(*mut bool, usize),
}

impl Col {
    fn len(&self) -> usize {
        match self {
            Col::Real(_, n) | Col::Bool(_, n) => *n,
        }
    }
}

// SAFETY: a `Col` is only an address; `Plan::run_chunked` shares it between the threads of
// one run, each writing the slots of its own chunk's rows only (see its SAFETY comments).
#[allow(unsafe_code)]
unsafe impl Send for Col {}
// SAFETY: as above.
#[allow(unsafe_code)]
unsafe impl Sync for Col {}

/// The output buffer's address, shared between the threads of one run, each touching its
/// own chunk's block only (see [`Plan::run_chunked`]).
#[derive(Clone, Copy)]
struct SyncPtr(*mut f64);

impl SyncPtr {
    /// The address of element `k`, without reading anything.
    fn at(self, k: usize) -> *mut f64 {
        self.0.wrapping_add(k)
    }
}

// SAFETY: an address only; see above.
#[allow(unsafe_code)]
unsafe impl Send for SyncPtr {}
// SAFETY: as above.
#[allow(unsafe_code)]
unsafe impl Sync for SyncPtr {}

/// The arrays of addresses a native call's table ([`JitArgs`]) points into, kept alive
/// for the calls of one run.
struct ArgTables {
    cols: Vec<*const u8>,
    gathers: Vec<*const u32>,
    offs: Vec<*const u32>,
    slots: Vec<*const u32>,
    counts: Vec<*const f64>,
    fills: Vec<*const f64>,
    calls: Vec<*const u8>,
    helpers: Vec<*const u8>,
}

impl ArgTables {
    fn new(
        gathers: &[Vec<u32>],
        csr: &[(Vec<u32>, Vec<u32>)],
        counts: &[Vec<f64>],
        nat: &dyn NativeFn,
        cols: Vec<*const u8>,
        fills: &[&[f64]],
    ) -> Self {
        ArgTables {
            cols,
            gathers: gathers.iter().map(Vec::as_ptr).collect(),
            offs: csr.iter().map(|x| x.0.as_ptr()).collect(),
            slots: csr.iter().map(|x| x.1.as_ptr()).collect(),
            counts: counts.iter().map(Vec::as_ptr).collect(),
            fills: fills.iter().map(|x| x.as_ptr()).collect(),
            calls: nat.call_table(),
            helpers: nat.helper_table(),
        }
    }

    /// The table of a run writing its outputs at `out`.
    fn args(&self, out: *mut f64) -> JitArgs {
        JitArgs {
            cols: self.cols.as_ptr(),
            gathers: self.gathers.as_ptr(),
            offs: self.offs.as_ptr(),
            slots: self.slots.as_ptr(),
            counts: self.counts.as_ptr(),
            fills: self.fills.as_ptr(),
            out,
            calls: self.calls.as_ptr(),
            helpers: self.helpers.as_ptr(),
        }
    }
}

struct Ctx<'a> {
    prog: &'a Program,
    /// This run's number (see [`RUNS`]).
    run: u64,
    fills: &'a [&'a [f64]],
    cols: &'a [ColumnRef<'a>],
    gathers: &'a [Vec<u32>],
    csr: &'a [(Vec<u32>, Vec<u32>)],
    counts: &'a [Vec<f64>],
    chunk: usize,
    out_offsets: &'a [(Vec<(u32, u32)>, usize)],
}

thread_local! {
    /// Per-thread scratch of the evaluator, grown to the largest chunk it has seen.
    /// With the run whose fill registers it holds (0: none).
    static SCRATCH: RefCell<(Vec<f64>, u64)> = const { RefCell::new((Vec::new(), 0)) };
}

/// Numbers the runs of plans, so that a thread's scratch knows whether its fill registers
/// (constants and parameters, the same for every row) are already those of the current run.
static RUNS: AtomicU64 = AtomicU64::new(1);

/// The scratch below register `dst` (all its operands: registers are numbered in creation
/// order, an operation's operands before its result) and `dst`'s own rows.
#[inline]
fn split(s: &mut [f64], base: usize, len: usize) -> (&[f64], &mut [f64]) {
    let (lo, hi) = s.split_at_mut(base);
    (lo, &mut hi[..len])
}

impl Ctx<'_> {
    /// Evaluates rows `first..first + n` into their chunk's block `out`.
    fn chunk(&self, first: usize, n: usize, out: &mut [f64]) -> Result<(), ()> {
        let need = self.prog.stride * self.chunk;
        SCRATCH.with(|s| {
            let (s, filled) = &mut *s.borrow_mut();
            if s.len() < need {
                s.resize(need, 0.0);
            }
            // registers are written by one operation each: a fill stays for the whole run
            self.eval(&mut s[..need], first, n, *filled != self.run)?;
            *filled = self.run;
            for (w, (_, _, reg, _)) in self.prog.writes.iter().enumerate() {
                let r = self.prog.regs[*reg];
                let base = r.off * self.chunk;
                let off = self.out_offsets[w].1 * self.chunk;
                out[off..off + n * r.width].copy_from_slice(&s[base..base + n * r.width]);
            }
            Ok(())
        })
    }

    #[allow(clippy::too_many_lines)]
    fn eval(&self, s: &mut [f64], first: usize, n: usize, fill: bool) -> Result<(), ()> {
        let ch = self.chunk;
        let regs = &self.prog.regs;
        let at = |r: R| (regs[r].off * ch, regs[r].width);
        for op in &self.prog.ops {
            match op {
                Op::Fill { dst, at: k } => {
                    // every row of the chunk, for the next chunks of the run on this thread
                    if fill {
                        let (b, w) = at(*dst);
                        let v = self.fills[*k];
                        for d in s[b..b + ch * w].chunks_exact_mut(w.max(1)) {
                            copy_w(d, v, w);
                        }
                    }
                }
                Op::Gather { dst, col, idx } => {
                    let (b, w) = at(*dst);
                    let idx = &self.gathers[*idx][first..first + n];
                    let d = &mut s[b..b + n * w];
                    match self.cols[*col] {
                        ColumnRef::Real(c) => gather(d, c, idx, w),
                        ColumnRef::Bool(c) => {
                            for (i, &x) in idx.iter().enumerate() {
                                d[i] = if c[x as usize] { 1.0 } else { 0.0 };
                            }
                        }
                        ColumnRef::Int(c) => {
                            for (i, &x) in idx.iter().enumerate() {
                                d[i] = c[x as usize] as f64;
                            }
                        }
                    }
                }
                Op::Agg {
                    dst,
                    col,
                    csr,
                    mean,
                } => {
                    let (b, w) = at(*dst);
                    let (offs, slots) = &self.csr[*csr];
                    let ColumnRef::Real(c) = self.cols[*col] else {
                        return Err(());
                    };
                    let d = &mut s[b..b + n * w];
                    let offs = &offs[first..=first + n];
                    match w {
                        1 => aggregate::<1>(d, c, offs, slots, *mean),
                        3 => aggregate::<3>(d, c, offs, slots, *mean),
                        9 => aggregate::<9>(d, c, offs, slots, *mean),
                        _ => aggregate_w(d, c, offs, slots, *mean, w),
                    }
                }
                Op::RowData { dst, data } => {
                    let (b, _) = at(*dst);
                    s[b..b + n].copy_from_slice(&self.counts[*data][first..first + n]);
                }
                Op::Ew { op, dst, a, b } => {
                    let (bd, w) = at(*dst);
                    let (ba, _) = at(*a);
                    let (bb, _) = at(*b);
                    let (lo, d) = split(s, bd, n * w);
                    let (x, y) = (&lo[ba..ba + n * w], &lo[bb..bb + n * w]);
                    match op {
                        Ew::Add => {
                            for k in 0..n * w {
                                d[k] = x[k] + y[k];
                            }
                        }
                        Ew::Sub => {
                            for k in 0..n * w {
                                d[k] = x[k] - y[k];
                            }
                        }
                        Ew::Mul => {
                            for k in 0..n * w {
                                d[k] = x[k] * y[k];
                            }
                        }
                        op => {
                            for k in 0..n * w {
                                d[k] = op.apply(x[k], y[k]);
                            }
                        }
                    }
                }
                Op::ScaleL { dst, s: sr, v } => {
                    let (bd, w) = at(*dst);
                    let (bs, _) = at(*sr);
                    let (bv, _) = at(*v);
                    let (lo, d) = split(s, bd, n * w);
                    let (sc, x) = (&lo[bs..bs + n], &lo[bv..bv + n * w]);
                    if w == 3 {
                        for ((z, x), f) in d.chunks_exact_mut(3).zip(x.chunks_exact(3)).zip(sc) {
                            z[0] = f * x[0];
                            z[1] = f * x[1];
                            z[2] = f * x[2];
                        }
                    } else {
                        for i in 0..n {
                            let f = sc[i];
                            for k in 0..w {
                                d[i * w + k] = f * x[i * w + k];
                            }
                        }
                    }
                }
                Op::DivS { dst, v, s: sr } => {
                    let (bd, w) = at(*dst);
                    let (bs, _) = at(*sr);
                    let (bv, _) = at(*v);
                    let (lo, d) = split(s, bd, n * w);
                    let (sc, x) = (&lo[bs..bs + n], &lo[bv..bv + n * w]);
                    if w == 3 {
                        for ((z, x), f) in d.chunks_exact_mut(3).zip(x.chunks_exact(3)).zip(sc) {
                            z[0] = x[0] / f;
                            z[1] = x[1] / f;
                            z[2] = x[2] / f;
                        }
                    } else {
                        for i in 0..n {
                            let f = sc[i];
                            for k in 0..w {
                                d[i * w + k] = x[i * w + k] / f;
                            }
                        }
                    }
                }
                Op::MatMul { dst, a, b, r, k, c } => {
                    let (bd, w) = at(*dst);
                    let (ba, wa) = at(*a);
                    let (bb, wb) = at(*b);
                    let (r, k, c) = (*r, *k, *c);
                    let (lo, d) = split(s, bd, n * w);
                    let (x, y) = (&lo[ba..ba + n * wa], &lo[bb..bb + n * wb]);
                    match (r, k, c) {
                        (2, 2, 1) => matmul_rows::<2, 2, 1>(x, y, d),
                        (2, 2, 2) => matmul_rows::<2, 2, 2>(x, y, d),
                        (3, 3, 1) => matmul_rows::<3, 3, 1>(x, y, d),
                        (3, 3, 3) => matmul_rows::<3, 3, 3>(x, y, d),
                        (6, 6, 1) => matmul_rows::<6, 6, 1>(x, y, d),
                        (8, 8, 1) => matmul_rows::<8, 8, 1>(x, y, d),
                        (12, 12, 1) => matmul_rows::<12, 12, 1>(x, y, d),
                        (24, 24, 1) => matmul_rows::<24, 24, 1>(x, y, d),
                        _ => {
                            for i in 0..n {
                                let x = &x[i * wa..][..wa];
                                let y = &y[i * wb..][..wb];
                                let z = &mut d[i * w..][..w];
                                matmul(x, y, z, r, k, c);
                            }
                        }
                    }
                }
                Op::Neg { dst, a } => {
                    let (bd, w) = at(*dst);
                    let (ba, _) = at(*a);
                    let (lo, d) = split(s, bd, n * w);
                    for k in 0..n * w {
                        d[k] = -lo[ba + k];
                    }
                }
                Op::Not { dst, a } => {
                    let (bd, _) = at(*dst);
                    let (ba, _) = at(*a);
                    let (lo, d) = split(s, bd, n);
                    for k in 0..n {
                        d[k] = if lo[ba + k] == 0.0 { 1.0 } else { 0.0 };
                    }
                }
                Op::Cmp { op, dst, a, b } => {
                    let (bd, _) = at(*dst);
                    let (ba, _) = at(*a);
                    let (bb, _) = at(*b);
                    let (lo, d) = split(s, bd, n);
                    for k in 0..n {
                        let (x, y) = (lo[ba + k], lo[bb + k]);
                        let t = match op {
                            Cmp::Lt => x < y,
                            Cmp::Le => x <= y,
                            Cmp::Gt => x > y,
                            Cmp::Ge => x >= y,
                        };
                        d[k] = if t { 1.0 } else { 0.0 };
                    }
                }
                Op::Eq { ne, dst, a, b } => {
                    let (bd, _) = at(*dst);
                    let (ba, w) = at(*a);
                    let (bb, _) = at(*b);
                    let (lo, d) = split(s, bd, n);
                    for i in 0..n {
                        let x = &lo[ba + i * w..][..w];
                        let y = &lo[bb + i * w..][..w];
                        // IEEE equality, as the interpreter's (NaN differs from itself)
                        #[allow(clippy::float_cmp)]
                        let eq = x.iter().zip(y).all(|(p, q)| p == q);
                        d[i] = if eq == *ne { 0.0 } else { 1.0 };
                    }
                }
                Op::And { dst, a, b } | Op::Or { dst, a, b } => {
                    let or = matches!(op, Op::Or { .. });
                    let (bd, _) = at(*dst);
                    let (ba, _) = at(*a);
                    let (bb, _) = at(*b);
                    let (lo, d) = split(s, bd, n);
                    for k in 0..n {
                        let (x, y) = (lo[ba + k] != 0.0, lo[bb + k] != 0.0);
                        d[k] = if if or { x || y } else { x && y } {
                            1.0
                        } else {
                            0.0
                        };
                    }
                }
                Op::Select { dst, c, a, b } => {
                    let (bd, w) = at(*dst);
                    let (bc, _) = at(*c);
                    let (ba, _) = at(*a);
                    let (bb, _) = at(*b);
                    let (lo, d) = split(s, bd, n * w);
                    for i in 0..n {
                        let src = if lo[bc + i] == 0.0 { bb } else { ba };
                        copy_w(&mut d[i * w..], &lo[src + i * w..], w);
                    }
                }
                Op::Pick { dst, srcs, map } => {
                    let (bd, w) = at(*dst);
                    let (lo, d) = split(s, bd, n * w);
                    // entry by entry, its source resolved once for all rows
                    for (k, &(src, off)) in map.iter().enumerate() {
                        if src == u16::MAX {
                            for i in 0..n {
                                d[i * w + k] = 0.0;
                            }
                        } else {
                            let (bs, ws) = at(srcs[src as usize]);
                            let x = &lo[bs + off as usize..];
                            for i in 0..n {
                                d[i * w + k] = x[i * ws];
                            }
                        }
                    }
                }
                Op::MatMulSparse {
                    dst,
                    a,
                    b,
                    k,
                    c,
                    offs,
                    terms,
                } => {
                    let (bd, w) = at(*dst);
                    let (ba, wa) = at(*a);
                    let (bb, wb) = at(*b);
                    let (k, c) = (*k, *c);
                    let (lo, d) = split(s, bd, n * w);
                    for i in 0..n {
                        let x = &lo[ba + i * wa..][..wa];
                        let y = &lo[bb + i * wb..][..wb];
                        let z = &mut d[i * w..][..w];
                        for (ri, o) in offs.windows(2).enumerate() {
                            let ts = &terms[o[0] as usize..o[1] as usize];
                            let xi = &x[ri * k..][..k];
                            for j in 0..c {
                                let mut acc = 0.0;
                                for &t in ts {
                                    acc += xi[t as usize] * y[t as usize * c + j];
                                }
                                z[ri * c + j] = acc;
                            }
                        }
                    }
                }
                Op::F1 { f, dst, a, .. } => {
                    let (bd, _) = at(*dst);
                    let (ba, _) = at(*a);
                    let (lo, d) = split(s, bd, n);
                    for k in 0..n {
                        d[k] = f(lo[ba + k]);
                    }
                }
                Op::F2 { f, dst, a, b } => {
                    let (bd, _) = at(*dst);
                    let (ba, _) = at(*a);
                    let (bb, _) = at(*b);
                    let (lo, d) = split(s, bd, n);
                    for k in 0..n {
                        d[k] = f(lo[ba + k], lo[bb + k]);
                    }
                }
                Op::Fast { f, dst, args } => {
                    let (bd, w) = at(*dst);
                    let (ba, wa) = at(args[0]);
                    let bb = args.get(1).map(|&r| at(r).0);
                    let (lo, d) = split(s, bd, n * w);
                    for i in 0..n {
                        let x = &lo[ba + i * wa..][..wa];
                        let z = &mut d[i * w..][..w];
                        fast(*f, x, bb.map(|bb| &lo[bb + i * wa..][..wa]), z)?;
                    }
                }
                Op::Generic {
                    name,
                    dst,
                    args,
                    ty,
                } => {
                    let (bd, w) = at(*dst);
                    let (lo, d) = split(s, bd, n * w);
                    // each row's arguments laid flat, for a built-in with a flat form
                    let mut xs: Vec<f64> = Vec::new();
                    let mut vals = Vec::with_capacity(args.len());
                    let mut buf = Vec::with_capacity(w);
                    for i in 0..n {
                        xs.clear();
                        for &(r, _) in args {
                            let (b, wr) = at(r);
                            xs.extend_from_slice(&lo[b + i * wr..][..wr]);
                        }
                        if generic_flat(name, &xs, &mut d[i * w..][..w]) {
                            continue;
                        }
                        vals.clear();
                        let mut from = 0;
                        for &(r, t) in args {
                            let wr = at(r).1;
                            vals.push(register_val(t, &xs[from..from + wr]));
                            from += wr;
                        }
                        let v = builtins::call(name, &vals).map_err(|_| ())?;
                        if v.ty() != *ty {
                            return Err(());
                        }
                        buf.clear();
                        v.to_reals(&mut buf);
                        d[i * w..][..w].copy_from_slice(&buf);
                    }
                }
            }
        }
        Ok(())
    }
}

/// A built-in evaluated on its arguments laid flat in `x` (as registers hold them), its
/// value written to `z` as a register holds it; false when `name` has no flat form here (the
/// caller then goes through [`builtins::call`]). `segment_hits_triangle` (five vec3, a
/// boolean: 1 or 0) has one, the built-in's own function without values built per call: a
/// blade's guard calls it twice per face side, every step. Used by the evaluator and by the
/// native code's helper alike.
// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub fn generic_flat(name: &str, x: &[f64], z: &mut [f64]) -> bool {
    if name != "segment_hits_triangle" || x.len() != 15 || z.len() != 1 {
        return false;
    }
    let v = |j: usize| [x[3 * j], x[3 * j + 1], x[3 * j + 2]];
    let hit = builtins::segment_hits_triangle(&v(0), &v(1), &v(2), &v(3), &v(4));
    z[0] = if hit { 1.0 } else { 0.0 };
    true
}

/// Copies `w` floats from the start of `s` to the start of `d`. The widths of the common
/// types get fixed-size copies: a copy of a length known only at run time is a call to
/// `memcpy`, which costs more than the copy itself for a few floats.
#[inline]
fn copy_w(d: &mut [f64], s: &[f64], w: usize) {
    match w {
        1 => d[0] = s[0],
        2 => copy_n::<2>(d, s),
        3 => copy_n::<3>(d, s),
        4 => copy_n::<4>(d, s),
        9 => copy_n::<9>(d, s),
        _ => d[..w].copy_from_slice(&s[..w]),
    }
}

#[inline]
fn copy_n<const N: usize>(d: &mut [f64], s: &[f64]) {
    let s: &[f64; N] = s[..N].try_into().expect("N floats");
    let d: &mut [f64; N] = (&mut d[..N]).try_into().expect("N floats");
    *d = *s;
}

/// `d[i] = c[idx[i]]` for values of `w` floats.
fn gather(d: &mut [f64], c: &[f64], idx: &[u32], w: usize) {
    fn fixed<const W: usize>(d: &mut [f64], c: &[f64], idx: &[u32]) {
        for (z, &x) in d.chunks_exact_mut(W).zip(idx) {
            copy_n::<W>(z, &c[x as usize * W..]);
        }
    }
    match w {
        1 => {
            for (z, &x) in d.iter_mut().zip(idx) {
                *z = c[x as usize];
            }
        }
        3 => fixed::<3>(d, c, idx),
        9 => fixed::<9>(d, c, idx),
        _ => {
            for (i, &x) in idx.iter().enumerate() {
                let x = x as usize;
                d[i * w..][..w].copy_from_slice(&c[x * w..][..w]);
            }
        }
    }
}

/// `v[slot] = out[at(row)]` for every target, values of `N` floats.
fn scatter_n<const N: usize>(
    v: &mut [f64],
    out: &[f64],
    targets: &[(u32, u32)],
    at: impl Fn(u32) -> usize,
) {
    for &(row, slot) in targets {
        copy_n::<N>(&mut v[slot as usize * N..], &out[at(row)..]);
    }
}

/// Row `i` of `d`: the sum (or mean) of the values of `c` at the slots
/// `slots[offs[i]..offs[i + 1]]`, in the interpreter's order: the first value, then each next
/// one added; zero for no slot.
fn aggregate<const W: usize>(d: &mut [f64], c: &[f64], offs: &[u32], slots: &[u32], mean: bool) {
    for (acc, o) in d.chunks_exact_mut(W).zip(offs.windows(2)) {
        let list = &slots[o[0] as usize..o[1] as usize];
        let mut a = [0.0; W];
        if let Some((&s0, rest)) = list.split_first() {
            copy_n::<W>(&mut a, &c[s0 as usize * W..]);
            for &x in rest {
                let v: &[f64; W] = c[x as usize * W..][..W].try_into().expect("W floats");
                for k in 0..W {
                    a[k] += v[k];
                }
            }
        }
        if mean {
            let k = list.len().max(1) as f64;
            for x in &mut a {
                *x /= k;
            }
        }
        copy_n::<W>(acc, &a);
    }
}

/// [`aggregate`] for any width.
fn aggregate_w(d: &mut [f64], c: &[f64], offs: &[u32], slots: &[u32], mean: bool, w: usize) {
    for (acc, o) in d.chunks_exact_mut(w).zip(offs.windows(2)) {
        let list = &slots[o[0] as usize..o[1] as usize];
        if let Some((&s0, rest)) = list.split_first() {
            acc.copy_from_slice(&c[s0 as usize * w..][..w]);
            for &x in rest {
                for (a, v) in acc.iter_mut().zip(&c[x as usize * w..][..w]) {
                    *a += *v;
                }
            }
        } else {
            acc.fill(0.0);
        }
        if mean {
            let k = list.len().max(1) as f64;
            for a in acc.iter_mut() {
                *a /= k;
            }
        }
    }
}

/// [`matmul`] of each row's `R x K` and `K x C` matrices, sizes known at compile time (the
/// same sums in the same order: the same bits).
fn matmul_rows<const R: usize, const K: usize, const C: usize>(
    x: &[f64],
    y: &[f64],
    z: &mut [f64],
) {
    for ((x, y), z) in x
        .chunks_exact(R * K)
        .zip(y.chunks_exact(K * C))
        .zip(z.chunks_exact_mut(R * C))
    {
        for i in 0..R {
            for j in 0..C {
                let mut acc = 0.0;
                for t in 0..K {
                    acc += x[i * K + t] * y[t * C + j];
                }
                z[i * C + j] = acc;
            }
        }
    }
}

/// `z = x * y` for row-major `x` (r x k) and `y` (k x c), summing over k in order from 0 as
/// [`crate::value::Mat::mul`] does.
#[inline]
fn matmul(x: &[f64], y: &[f64], z: &mut [f64], r: usize, k: usize, c: usize) {
    for i in 0..r {
        let xi = &x[i * k..][..k];
        for j in 0..c {
            let mut acc = 0.0;
            for (t, &a) in xi.iter().enumerate() {
                acc += a * y[t * c + j];
            }
            z[i * c + j] = acc;
        }
    }
}

/// The flat built-ins; `Err` when the built-in would refuse its argument.
#[inline]
// For the sibling crate (topomech-codegen) only; `()` is the whole error (the caller falls
// back to the evaluator, which reports it precisely).
#[doc(hidden)]
#[allow(clippy::result_unit_err)]
pub fn fast(f: Fast, x: &[f64], y: Option<&[f64]>, z: &mut [f64]) -> Result<(), ()> {
    match f {
        Fast::Dot => z[0] = builtins::dot(x, y.ok_or(())?),
        Fast::Norm => z[0] = builtins::norm(x),
        Fast::Norm2 => z[0] = builtins::dot(x, x),
        Fast::Cross3 => {
            let y = y.ok_or(())?;
            let c = builtins::cross(&[x[0], x[1], x[2]], &[y[0], y[1], y[2]]);
            z.copy_from_slice(&c);
        }
        Fast::Cross2 => {
            let y = y.ok_or(())?;
            z[0] = builtins::diff_of_products(x[0], y[1], x[1], y[0]);
        }
        Fast::Normalize => builtins::normalize_into(x, z),
        Fast::Polar2 => z.copy_from_slice(&builtins::polar2_data(x).map_err(|_| ())?),
        Fast::Polar3 => z.copy_from_slice(&builtins::polar3_data(x).map_err(|_| ())?),
        Fast::Trace => {
            let n = (x.len() as f64).sqrt() as usize;
            z[0] = (0..n).map(|i| x[i * n + i]).sum();
        }
        Fast::Sym => {
            let n = (x.len() as f64).sqrt() as usize;
            for i in 0..n {
                for j in 0..n {
                    z[i * n + j] = 0.5 * x[i * n + j] + 0.5 * x[j * n + i];
                }
            }
        }
    }
    Ok(())
}

/// A register's floats as the value of type `t` they hold (an integer or a boolean is one
/// float: `0.0` is false), for a built-in called through [`builtins::call`].
// For the sibling crate (topomech-codegen) only.
#[doc(hidden)]
pub fn register_val(t: Ty, x: &[f64]) -> Val {
    match t {
        Ty::I64 => Val::I(x[0] as i64),
        Ty::Bool => Val::B(x[0] != 0.0),
        t => Val::from_reals(t, x),
    }
}

#[cfg(test)]
mod tests {
    use super::{size_out, Rows};

    /// After a resize no stale value stays where no run writes (the last block's tail): a
    /// buffer full of NaN (a failed run's), shrunk or grown, holds zeros in its last block.
    #[test]
    fn a_resized_output_buffer_has_a_clean_last_block() {
        for (from, to) in [(40, 24), (24, 40), (40, 8), (8, 8)] {
            let mut out = vec![f64::NAN; from];
            size_out(&mut out, to, 8);
            assert_eq!(out.len(), to);
            if from != to {
                assert!(out[to - 8..].iter().all(|&x| x == 0.0), "{from} -> {to}");
            }
        }
    }

    /// The rows `filter` keeps, built the plain way: each array rebuilt from the kept rows.
    fn reference(r: &Rows, keep: &dyn Fn(u32) -> bool) -> Rows {
        let n = r.row_match.len();
        let kept: Vec<usize> = (0..n).filter(|&i| keep(r.row_match[i])).collect();
        let mut new_row = vec![u32::MAX; n];
        for (k, &i) in kept.iter().enumerate() {
            new_row[i] = k as u32;
        }
        let pick = |v: &[u32]| kept.iter().map(|&i| v[i]).collect::<Vec<_>>();
        Rows {
            row_match: pick(&r.row_match),
            gathers: r.gathers.iter().map(|g| pick(g)).collect(),
            csr: r
                .csr
                .iter()
                .map(|(offs, slots)| {
                    if offs.len() != n + 1 {
                        return (vec![0], Vec::new());
                    }
                    let mut o = vec![0];
                    let mut s = Vec::new();
                    for &i in &kept {
                        s.extend_from_slice(&slots[offs[i] as usize..offs[i + 1] as usize]);
                        o.push(s.len() as u32);
                    }
                    (o, s)
                })
                .collect(),
            counts: r
                .counts
                .iter()
                .map(|c| kept.iter().map(|&i| c[i]).collect())
                .collect(),
            writes: r
                .writes
                .iter()
                .map(|w| {
                    w.iter()
                        .filter(|&&(row, _)| new_row[row as usize] != u32::MAX)
                        .map(|&(row, s)| (new_row[row as usize], s))
                        .collect()
                })
                .collect(),
        }
    }

    /// `gallop` against `partition_point` on a sorted array with runs of equal values, from
    /// starts inside, at and past its end.
    #[test]
    fn galloping_finds_the_partition_point() {
        let v: Vec<u32> = (0..1000).map(|i| i / 3).collect();
        for from in [0usize, 1, 5, 300, 999, 1000, 1200] {
            for k in [0u32, 1, 2, 50, 200, 332, 333, 400] {
                let want = if from >= v.len() {
                    v.len()
                } else {
                    from + v[from..].partition_point(|&x| x < k)
                };
                assert_eq!(
                    super::gallop(&v, from, |&x| x < k),
                    want,
                    "from {from}, {k}"
                );
            }
        }
    }

    /// `Rows::filter` moves runs of kept rows in place; this checks it against rebuilding
    /// every array from the kept rows, over random plans (several matches per row, CSR rows
    /// of 0 to 4 slots, writes of some rows only, a count aggregate) and random drops
    /// (none, all, the first, the last, runs). Exact: both only copy integers and reals.
    #[test]
    fn filtering_by_runs_gives_the_rows_kept() {
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move |m: u64| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed % m
        };
        for case in 0..300 {
            let n = next(40) as usize;
            let mut row_match = Vec::new();
            let mut m = 0u32;
            while row_match.len() < n {
                for _ in 0..=next(3) {
                    row_match.push(m);
                }
                m += 1;
            }
            row_match.truncate(n);
            let mut offs = vec![0u32];
            let mut slots = Vec::new();
            for _ in 0..n {
                for _ in 0..next(5) {
                    slots.push(next(1000) as u32);
                }
                offs.push(slots.len() as u32);
            }
            let mut writes = vec![Vec::new(), Vec::new()];
            for row in 0..n as u32 {
                for w in &mut writes {
                    if next(3) != 0 {
                        w.push((row, next(1000) as u32));
                    }
                }
            }
            let rows = Rows {
                gathers: vec![
                    (0..n).map(|_| next(1000) as u32).collect(),
                    (0..n).map(|_| next(1000) as u32).collect(),
                ],
                csr: vec![(offs, slots), (vec![0], Vec::new())],
                counts: vec![(0..n).map(|_| next(100) as f64 * 0.5).collect()],
                writes,
                row_match,
            };
            let drop_mod = 1 + (case % 5) as u32;
            let keep: Box<dyn Fn(u32) -> bool> = match case % 4 {
                0 => Box::new(|_| true),
                1 => Box::new(|_| false),
                2 => Box::new(move |k| k % drop_mod != 0),
                _ => Box::new(move |k| (k / drop_mod) % 2 == 1),
            };
            let want = reference(&rows, &*keep);
            let got = rows.filter(&*keep);
            assert_eq!(got.row_match, want.row_match, "case {case}");
            assert_eq!(got.gathers, want.gathers, "case {case}");
            assert_eq!(got.csr, want.csr, "case {case}");
            assert_eq!(got.counts, want.counts, "case {case}");
            assert_eq!(got.writes, want.writes, "case {case}");
        }
    }
}
