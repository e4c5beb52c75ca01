//! Values and types of the expression language, and its operators.
//!
//! The language has six kinds of values ([`Val`]) with one type each ([`Ty`]): reals, integers,
//! booleans, 2- and 3-vectors and dense row-major matrices of at most 12x12 (a 3D tetrahedron's
//! element stiffness is 12x12). Vectors are columns: `m * v` multiplies a matrix by a vector.
//!
//! Types are checked before evaluation with [`binop_type`] and [`unop_type`]; [`binop`] and
//! [`unop`] then fail only for numerical reasons ([`EvalError`]): integer division by zero and
//! integer overflow. Real arithmetic follows IEEE 754 (`1.0 / 0.0` is infinite, `0.0 / 0.0` is
//! NaN), so a rule can test a result with `is_finite`.
//!
//! Integer promotion: an `i64` operand mixed with a real operand (`f64`, vector, matrix) is
//! converted to `f64`, so `2 * v`, `x + 1` and `m / 2` work; `i64` with `i64` stays integer.
//!
//! ```
//! use topomech_lang::value::{binop, binop_type, BinOp, Ty, Val};
//!
//! assert_eq!(binop_type(BinOp::Mul, Ty::I64, Ty::Vec3), Ok(Ty::Vec3));
//! assert_eq!(binop_type(BinOp::Mul, Ty::Mat(12, 3), Ty::Vec3), Ok(Ty::Mat(12, 1)));
//! assert!(binop_type(BinOp::Mul, Ty::Vec3, Ty::Vec3).unwrap_err().contains("dot(a, b)"));
//! let v = binop(BinOp::Mul, &Val::I(2), &Val::V3([1.0, 2.0, 3.0])).unwrap();
//! assert_eq!(v, Val::V3([2.0, 4.0, 6.0]));
//! assert!(binop(BinOp::Div, &Val::I(1), &Val::I(0)).is_err());
//! ```

use std::fmt;

/// The largest number of rows or columns of a matrix type.
pub const MAX_MAT: u8 = 12;

/// Types of the expression language.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Ty {
    /// A real number.
    F64,
    /// A 64-bit signed integer.
    I64,
    /// A boolean.
    Bool,
    /// A 2-vector of reals (a column).
    Vec2,
    /// A 3-vector of reals (a column).
    Vec3,
    /// A dense real matrix `Mat(rows, cols)`, each in `1..=12`.
    Mat(u8, u8),
}

impl Ty {
    /// Number of `f64` scalars in a value: 1 for `f64`, `i64` and `bool`, 2 and 3 for the
    /// vectors, `rows * cols` for a matrix.
    pub fn width(self) -> usize {
        match self {
            Ty::F64 | Ty::I64 | Ty::Bool => 1,
            Ty::Vec2 => 2,
            Ty::Vec3 => 3,
            Ty::Mat(r, c) => usize::from(r) * usize::from(c),
        }
    }

    /// Whether the type is made of reals: `f64`, the vectors and the matrices.
    pub fn is_real(self) -> bool {
        matches!(self, Ty::F64 | Ty::Vec2 | Ty::Vec3 | Ty::Mat(..))
    }

    /// The name in the rule language: `f64`, `i64`, `bool`, `vec2`, `vec3`, `mat3` (square)
    /// or `mat3x4` (3 rows, 4 columns).
    pub fn name(self) -> String {
        match self {
            Ty::F64 => "f64".into(),
            Ty::I64 => "i64".into(),
            Ty::Bool => "bool".into(),
            Ty::Vec2 => "vec2".into(),
            Ty::Vec3 => "vec3".into(),
            Ty::Mat(r, c) if r == c => format!("mat{r}"),
            Ty::Mat(r, c) => format!("mat{r}x{c}"),
        }
    }

    /// Parses a name written by [`Ty::name`]; `matRxC` is also accepted for a square matrix.
    /// Dimensions must be in `1..=12`, written in decimal without sign or leading zero.
    pub fn parse(s: &str) -> Option<Ty> {
        match s {
            "f64" => return Some(Ty::F64),
            "i64" => return Some(Ty::I64),
            "bool" => return Some(Ty::Bool),
            "vec2" => return Some(Ty::Vec2),
            "vec3" => return Some(Ty::Vec3),
            _ => {}
        }
        let dims = s.strip_prefix("mat")?;
        let (r, c) = if let Some((r, c)) = dims.split_once('x') {
            (parse_dim(r)?, parse_dim(c)?)
        } else {
            let n = parse_dim(dims)?;
            (n, n)
        };
        Some(Ty::Mat(r, c))
    }

    /// The type of a matrix of `rows x cols`, if both are in `1..=12`.
    pub fn mat(rows: usize, cols: usize) -> Option<Ty> {
        let ok = |n: usize| (1..=usize::from(MAX_MAT)).contains(&n);
        (ok(rows) && ok(cols)).then_some(Ty::Mat(rows as u8, cols as u8))
    }
}

/// A matrix dimension: decimal digits without leading zero, in `1..=12`.
fn parse_dim(s: &str) -> Option<u8> {
    if s.is_empty() || s.len() > 2 || s.starts_with('0') || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let n: u8 = s.parse().ok()?;
    (1..=MAX_MAT).contains(&n).then_some(n)
}

impl fmt::Display for Ty {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name())
    }
}

/// A dense row-major matrix: entry `(i, j)` is `data[i * cols + j]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Mat {
    /// Number of rows.
    pub rows: usize,
    /// Number of columns.
    pub cols: usize,
    /// The `rows * cols` entries, row after row.
    pub data: Vec<f64>,
}

impl Mat {
    /// The `r x c` zero matrix.
    pub fn zeros(r: usize, c: usize) -> Mat {
        Mat {
            rows: r,
            cols: c,
            data: vec![0.0; r * c],
        }
    }

    /// The `n x n` identity matrix.
    pub fn identity(n: usize) -> Mat {
        let mut m = Mat::zeros(n, n);
        for i in 0..n {
            m.set(i, i, 1.0);
        }
        m
    }

    /// Entry `(i, j)`.
    ///
    /// # Panics
    /// If `i >= rows` or `j >= cols`.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        assert!(
            i < self.rows && j < self.cols,
            "entry ({i}, {j}) outside a {}x{} matrix",
            self.rows,
            self.cols
        );
        self.data[i * self.cols + j]
    }

    /// Sets entry `(i, j)` to `x`.
    ///
    /// # Panics
    /// If `i >= rows` or `j >= cols`.
    pub fn set(&mut self, i: usize, j: usize, x: f64) {
        assert!(
            i < self.rows && j < self.cols,
            "entry ({i}, {j}) outside a {}x{} matrix",
            self.rows,
            self.cols
        );
        self.data[i * self.cols + j] = x;
    }

    /// The product `self * o`.
    ///
    /// # Panics
    /// If `self.cols != o.rows`.
    #[must_use]
    pub fn mul(&self, o: &Mat) -> Mat {
        assert_eq!(
            self.cols, o.rows,
            "cannot multiply a {}x{} matrix by a {}x{} matrix",
            self.rows, self.cols, o.rows, o.cols
        );
        let mut p = Mat::zeros(self.rows, o.cols);
        for i in 0..self.rows {
            for k in 0..self.cols {
                let a = self.data[i * self.cols + k];
                for j in 0..o.cols {
                    p.data[i * o.cols + j] += a * o.data[k * o.cols + j];
                }
            }
        }
        p
    }

    /// The transpose.
    #[must_use]
    pub fn transpose(&self) -> Mat {
        let mut t = Mat::zeros(self.cols, self.rows);
        for i in 0..self.rows {
            for j in 0..self.cols {
                t.data[j * self.rows + i] = self.data[i * self.cols + j];
            }
        }
        t
    }

    /// The entrywise map `f(x)`.
    fn map(&self, f: impl Fn(f64) -> f64) -> Mat {
        Mat {
            rows: self.rows,
            cols: self.cols,
            data: self.data.iter().map(|&x| f(x)).collect(),
        }
    }

    /// The entrywise combination `f(x, y)` of two matrices of the same shape.
    fn zip(&self, o: &Mat, f: impl Fn(f64, f64) -> f64) -> Mat {
        Mat {
            rows: self.rows,
            cols: self.cols,
            data: self
                .data
                .iter()
                .zip(&o.data)
                .map(|(&x, &y)| f(x, y))
                .collect(),
        }
    }
}

/// A value.
#[derive(Clone, Debug, PartialEq)]
pub enum Val {
    /// A real number.
    F(f64),
    /// An integer.
    I(i64),
    /// A boolean.
    B(bool),
    /// A 2-vector.
    V2([f64; 2]),
    /// A 3-vector.
    V3([f64; 3]),
    /// A matrix.
    M(Mat),
}

impl Val {
    /// The type of the value.
    pub fn ty(&self) -> Ty {
        match self {
            Val::F(_) => Ty::F64,
            Val::I(_) => Ty::I64,
            Val::B(_) => Ty::Bool,
            Val::V2(_) => Ty::Vec2,
            Val::V3(_) => Ty::Vec3,
            Val::M(m) => Ty::Mat(m.rows as u8, m.cols as u8),
        }
    }

    /// Builds a value of type `ty` from its `ty.width()` scalars (row-major for a matrix).
    /// Meant for real types; for `i64` the scalar is truncated (saturating), for `bool` any
    /// non-zero scalar is `true`, the inverse of [`Val::to_reals`].
    ///
    /// # Panics
    /// If `x.len() != ty.width()`.
    pub fn from_reals(ty: Ty, x: &[f64]) -> Val {
        assert_eq!(
            x.len(),
            ty.width(),
            "a {ty} is made of {} scalars, got {}",
            ty.width(),
            x.len()
        );
        match ty {
            Ty::F64 => Val::F(x[0]),
            Ty::I64 => Val::I(x[0] as i64),
            Ty::Bool => Val::B(x[0] != 0.0),
            Ty::Vec2 => Val::V2([x[0], x[1]]),
            Ty::Vec3 => Val::V3([x[0], x[1], x[2]]),
            Ty::Mat(r, c) => Val::M(Mat {
                rows: usize::from(r),
                cols: usize::from(c),
                data: x.to_vec(),
            }),
        }
    }

    /// Appends the value's scalars to `out` (row-major for a matrix); an integer appends its
    /// value as `f64`, a boolean `1.0` or `0.0`.
    pub fn to_reals(&self, out: &mut Vec<f64>) {
        match self {
            Val::F(x) => out.push(*x),
            Val::I(i) => out.push(*i as f64),
            Val::B(b) => out.push(if *b { 1.0 } else { 0.0 }),
            Val::V2(v) => out.extend_from_slice(v),
            Val::V3(v) => out.extend_from_slice(v),
            Val::M(m) => out.extend_from_slice(&m.data),
        }
    }

    /// The zero of a type: `0.0`, `0`, `false`, the zero vector or matrix.
    pub fn zero(ty: Ty) -> Val {
        match ty {
            Ty::F64 => Val::F(0.0),
            Ty::I64 => Val::I(0),
            Ty::Bool => Val::B(false),
            Ty::Vec2 => Val::V2([0.0; 2]),
            Ty::Vec3 => Val::V3([0.0; 3]),
            Ty::Mat(r, c) => Val::M(Mat::zeros(usize::from(r), usize::from(c))),
        }
    }

    /// The value as a real: an `f64`, or an `i64` promoted to `f64`.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Val::F(x) => Some(*x),
            Val::I(i) => Some(*i as f64),
            _ => None,
        }
    }

    /// The value of a `bool`.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Val::B(b) => Some(*b),
            _ => None,
        }
    }

    /// The value of an `i64`.
    pub fn as_i64(&self) -> Option<i64> {
        match self {
            Val::I(i) => Some(*i),
            _ => None,
        }
    }
}

/// Why an operation failed at evaluation time (types are checked before evaluation, so this is
/// for numerical problems only, e.g. inverse of a singular matrix, integer division by zero,
/// index out of range).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct EvalError(pub String);

/// Binary operators.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BinOp {
    /// `a + b`.
    Add,
    /// `a - b`.
    Sub,
    /// `a * b`: products of scalars, scaling, matrix products.
    Mul,
    /// `a / b`: by a scalar; integer division (toward zero) for two integers.
    Div,
    /// `a % b`: remainder with the sign of `a` (as in Rust and C).
    Rem,
    /// `a < b`.
    Lt,
    /// `a <= b`.
    Le,
    /// `a > b`.
    Gt,
    /// `a >= b`.
    Ge,
    /// `a == b` (IEEE: NaN is not equal to itself).
    Eq,
    /// `a != b`.
    Ne,
    /// Logical and.
    And,
    /// Logical or.
    Or,
}

impl BinOp {
    /// The operator as usually written: `+`, `-`, `*`, `/`, `%`, `<`, ..., `and`, `or`.
    pub fn symbol(self) -> &'static str {
        match self {
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Rem => "%",
            BinOp::Lt => "<",
            BinOp::Le => "<=",
            BinOp::Gt => ">",
            BinOp::Ge => ">=",
            BinOp::Eq => "==",
            BinOp::Ne => "!=",
            BinOp::And => "and",
            BinOp::Or => "or",
        }
    }
}

/// Unary operators.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum UnOp {
    /// `-a` on numbers, vectors and matrices.
    Neg,
    /// Logical not.
    Not,
}

/// `I64` becomes `F64` when the other operand is real.
fn promote(a: Ty, b: Ty) -> (Ty, Ty) {
    match (a, b) {
        (Ty::I64, b) if b.is_real() => (Ty::F64, b),
        (a, Ty::I64) if a.is_real() => (a, Ty::F64),
        _ => (a, b),
    }
}

fn is_scalar(t: Ty) -> bool {
    matches!(t, Ty::F64 | Ty::I64)
}

/// Result type of `a op b`, or a message saying why the operand types do not fit (e.g.
/// "cannot add vec3 and f64").
pub fn binop_type(op: BinOp, a: Ty, b: Ty) -> Result<Ty, String> {
    let (pa, pb) = promote(a, b);
    match op {
        BinOp::Add | BinOp::Sub => {
            let verb = if op == BinOp::Add { "add" } else { "subtract" };
            if pa == pb && pa != Ty::Bool {
                Ok(pa)
            } else if let (Ty::Mat(..), Ty::Mat(..)) = (a, b) {
                Err(format!("cannot {verb} {a} and {b}: the shapes differ"))
            } else {
                Err(format!("cannot {verb} {a} and {b}"))
            }
        }
        BinOp::Mul => mul_type(a, b),
        BinOp::Div => match (pa, pb) {
            (Ty::I64, Ty::I64) => Ok(Ty::I64),
            (t, Ty::F64) if t.is_real() => Ok(t),
            _ if b.is_real() && !is_scalar(b) => Err(format!(
                "cannot divide {a} by {b}: the divisor must be f64 or i64"
            )),
            _ => Err(format!("cannot divide {a} by {b}")),
        },
        BinOp::Rem => match (pa, pb) {
            (Ty::I64, Ty::I64) => Ok(Ty::I64),
            (Ty::F64, Ty::F64) => Ok(Ty::F64),
            _ => Err(format!(
                "cannot take the remainder of {a} by {b}: % applies to f64 and i64"
            )),
        },
        BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => {
            if is_scalar(a) && is_scalar(b) {
                Ok(Ty::Bool)
            } else {
                Err(format!(
                    "cannot compare {a} and {b} with {}: only f64 and i64 are ordered",
                    op.symbol()
                ))
            }
        }
        BinOp::Eq | BinOp::Ne => {
            if pa == pb {
                Ok(Ty::Bool)
            } else {
                Err(format!(
                    "cannot compare {a} and {b} with {}: the types differ",
                    op.symbol()
                ))
            }
        }
        BinOp::And | BinOp::Or => {
            if a == Ty::Bool && b == Ty::Bool {
                Ok(Ty::Bool)
            } else {
                Err(format!(
                    "cannot apply `{}` to {a} and {b}: both operands must be bool",
                    op.symbol()
                ))
            }
        }
    }
}

/// The typing of `a * b`; vectors are columns.
fn mul_type(a: Ty, b: Ty) -> Result<Ty, String> {
    match (a, b) {
        (Ty::I64, Ty::I64) => Ok(Ty::I64),
        (s, t) | (t, s) if is_scalar(s) && t.is_real() => Ok(t),
        (Ty::Mat(r, k), Ty::Mat(k2, c)) => {
            if k == k2 {
                Ok(Ty::Mat(r, c))
            } else {
                Err(format!(
                    "cannot multiply {a} and {b}: {a} has {k} columns but {b} has {k2} rows"
                ))
            }
        }
        (Ty::Mat(r, k), v @ (Ty::Vec2 | Ty::Vec3)) => {
            let n = v.width() as u8;
            if k != n {
                Err(format!(
                    "cannot multiply {a} and {v}: {a} has {k} columns but {v} has {n} rows"
                ))
            } else if r == n {
                Ok(v)
            } else {
                Ok(Ty::Mat(r, 1))
            }
        }
        (Ty::Vec2 | Ty::Vec3, Ty::Vec2 | Ty::Vec3) => Err(format!(
            "cannot multiply {a} and {b}: use dot(a, b), cross(a, b) or outer(a, b)"
        )),
        (Ty::Vec2 | Ty::Vec3, Ty::Mat(..)) => Err(format!(
            "cannot multiply {a} and {b}: vectors are columns, use transpose(m) * v"
        )),
        _ => Err(format!("cannot multiply {a} and {b}")),
    }
}

/// Result type of `op a`, or why it does not apply.
pub fn unop_type(op: UnOp, a: Ty) -> Result<Ty, String> {
    match op {
        UnOp::Neg if a != Ty::Bool => Ok(a),
        UnOp::Neg => Err("cannot negate bool: use `not`".into()),
        UnOp::Not if a == Ty::Bool => Ok(a),
        UnOp::Not => Err(format!("cannot apply `not` to {a}: it needs a bool")),
    }
}

/// An error for operand values whose types [`binop_type`] would have refused.
fn unchecked(op: &str, a: &Val, b: &Val) -> EvalError {
    EvalError(format!(
        "internal error: operator {op} evaluated on {} and {} (types not checked)",
        a.ty(),
        b.ty()
    ))
}

fn overflow(a: i64, op: BinOp, b: i64) -> EvalError {
    EvalError(format!("integer overflow in {a} {} {b}", op.symbol()))
}

/// Applies `f` to every real scalar of a real value.
fn map_real(v: &Val, f: impl Fn(f64) -> f64) -> Option<Val> {
    Some(match v {
        Val::F(x) => Val::F(f(*x)),
        Val::V2(u) => Val::V2(u.map(f)),
        Val::V3(u) => Val::V3(u.map(f)),
        Val::M(m) => Val::M(m.map(f)),
        _ => return None,
    })
}

/// Combines two real values of the same type entrywise.
fn zip_real(a: &Val, b: &Val, f: impl Fn(f64, f64) -> f64) -> Option<Val> {
    Some(match (a, b) {
        (Val::F(x), Val::F(y)) => Val::F(f(*x, *y)),
        (Val::V2(u), Val::V2(v)) => Val::V2([f(u[0], v[0]), f(u[1], v[1])]),
        (Val::V3(u), Val::V3(v)) => Val::V3([f(u[0], v[0]), f(u[1], v[1]), f(u[2], v[2])]),
        (Val::M(m), Val::M(n)) if (m.rows, m.cols) == (n.rows, n.cols) => Val::M(m.zip(n, f)),
        _ => return None,
    })
}

/// An integer operand becomes real when the other operand is real.
fn promote_val(a: &Val, b: &Val) -> (Val, Val) {
    let p = |v: &Val, other: &Val| match v {
        Val::I(i) if other.ty().is_real() => Val::F(*i as f64),
        _ => v.clone(),
    };
    (p(a, b), p(b, a))
}

/// Evaluates `a op b` (operand types already checked with [`binop_type`]).
pub fn binop(op: BinOp, a: &Val, b: &Val) -> Result<Val, EvalError> {
    let sym = op.symbol();
    // Integer arithmetic: exact, checked.
    if let (Val::I(x), Val::I(y)) = (a, b) {
        let (x, y) = (*x, *y);
        let r = match op {
            BinOp::Add => x.checked_add(y),
            BinOp::Sub => x.checked_sub(y),
            BinOp::Mul => x.checked_mul(y),
            BinOp::Div | BinOp::Rem if y == 0 => {
                return Err(EvalError(format!(
                    "integer division by zero in {x} {sym} 0"
                )))
            }
            BinOp::Div => x.checked_div(y),
            BinOp::Rem => x.checked_rem(y),
            BinOp::Lt => return Ok(Val::B(x < y)),
            BinOp::Le => return Ok(Val::B(x <= y)),
            BinOp::Gt => return Ok(Val::B(x > y)),
            BinOp::Ge => return Ok(Val::B(x >= y)),
            BinOp::Eq => return Ok(Val::B(x == y)),
            BinOp::Ne => return Ok(Val::B(x != y)),
            BinOp::And | BinOp::Or => return Err(unchecked(sym, a, b)),
        };
        return r.map(Val::I).ok_or_else(|| overflow(x, op, y));
    }
    if let (Val::B(x), Val::B(y)) = (a, b) {
        return match op {
            BinOp::And => Ok(Val::B(*x && *y)),
            BinOp::Or => Ok(Val::B(*x || *y)),
            BinOp::Eq => Ok(Val::B(x == y)),
            BinOp::Ne => Ok(Val::B(x != y)),
            _ => Err(unchecked(sym, a, b)),
        };
    }
    let (pa, pb) = promote_val(a, b);
    let r = match op {
        BinOp::Add => zip_real(&pa, &pb, |x, y| x + y),
        BinOp::Sub => zip_real(&pa, &pb, |x, y| x - y),
        BinOp::Mul => mul_val(&pa, &pb),
        BinOp::Div => match pb {
            Val::F(y) => map_real(&pa, |x| x / y),
            _ => None,
        },
        BinOp::Rem => match (&pa, &pb) {
            (Val::F(x), Val::F(y)) => Some(Val::F(x % y)),
            _ => None,
        },
        BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => match (&pa, &pb) {
            (Val::F(x), Val::F(y)) => Some(Val::B(match op {
                BinOp::Lt => x < y,
                BinOp::Le => x <= y,
                BinOp::Gt => x > y,
                _ => x >= y,
            })),
            _ => None,
        },
        BinOp::Eq | BinOp::Ne => {
            (pa.ty() == pb.ty()).then(|| Val::B((pa == pb) == (op == BinOp::Eq)))
        }
        BinOp::And | BinOp::Or => None,
    };
    r.ok_or_else(|| unchecked(sym, a, b))
}

/// `a * b` on real operands (integers already promoted).
fn mul_val(a: &Val, b: &Val) -> Option<Val> {
    match (a, b) {
        (Val::F(s), v) | (v, Val::F(s)) => map_real(v, |x| s * x),
        (Val::M(m), Val::M(n)) if m.cols == n.rows => Some(Val::M(m.mul(n))),
        (Val::M(m), Val::V2(_) | Val::V3(_)) => {
            let mut v = Vec::with_capacity(3);
            b.to_reals(&mut v);
            if m.cols != v.len() {
                return None;
            }
            let p = m.mul(&Mat {
                rows: v.len(),
                cols: 1,
                data: v,
            });
            Some(match (p.rows, b) {
                (2, Val::V2(_)) => Val::V2([p.data[0], p.data[1]]),
                (3, Val::V3(_)) => Val::V3([p.data[0], p.data[1], p.data[2]]),
                _ => Val::M(p),
            })
        }
        _ => None,
    }
}

/// Evaluates `op a` (operand type already checked with [`unop_type`]).
pub fn unop(op: UnOp, a: &Val) -> Result<Val, EvalError> {
    match (op, a) {
        (UnOp::Neg, Val::I(i)) => i
            .checked_neg()
            .map(Val::I)
            .ok_or_else(|| EvalError(format!("integer overflow in -({i})"))),
        (UnOp::Not, Val::B(b)) => Ok(Val::B(!b)),
        (UnOp::Neg, v) => map_real(v, |x| -x).ok_or_else(|| {
            EvalError(format!(
                "internal error: negation evaluated on {} (type not checked)",
                v.ty()
            ))
        }),
        (UnOp::Not, v) => Err(EvalError(format!(
            "internal error: `not` evaluated on {} (type not checked)",
            v.ty()
        ))),
    }
}

#[cfg(test)]
// Exact comparisons are intended: the expected values are exactly representable results.
#[allow(clippy::float_cmp)]
mod tests {
    use super::*;

    const ALL_OPS: [BinOp; 13] = [
        BinOp::Add,
        BinOp::Sub,
        BinOp::Mul,
        BinOp::Div,
        BinOp::Rem,
        BinOp::Lt,
        BinOp::Le,
        BinOp::Gt,
        BinOp::Ge,
        BinOp::Eq,
        BinOp::Ne,
        BinOp::And,
        BinOp::Or,
    ];

    /// A type of every kind, with square, tall, wide and column matrices.
    fn sample_types() -> Vec<Ty> {
        vec![
            Ty::F64,
            Ty::I64,
            Ty::Bool,
            Ty::Vec2,
            Ty::Vec3,
            Ty::Mat(2, 2),
            Ty::Mat(3, 3),
            Ty::Mat(2, 3),
            Ty::Mat(3, 2),
            Ty::Mat(4, 3),
            Ty::Mat(4, 2),
            Ty::Mat(3, 1),
            Ty::Mat(12, 12),
            Ty::Mat(12, 1),
        ]
    }

    /// A value of the type whose scalars are 1, 2, 3, ... (so products are exact).
    fn counting(ty: Ty) -> Val {
        match ty {
            Ty::I64 => Val::I(3),
            Ty::Bool => Val::B(true),
            _ => {
                let x: Vec<f64> = (1..=ty.width()).map(|k| k as f64).collect();
                Val::from_reals(ty, &x)
            }
        }
    }

    /// Names are the ones of the gmap embeddings; parse inverts name on every type, and refuses
    /// dimensions outside 1..=12, signs, leading zeros and junk.
    #[test]
    fn names_round_trip() {
        assert_eq!(Ty::Mat(3, 3).name(), "mat3");
        assert_eq!(Ty::Mat(3, 4).to_string(), "mat3x4");
        assert_eq!(Ty::Mat(12, 1).name(), "mat12x1");
        for r in 1..=12 {
            for c in 1..=12 {
                let t = Ty::Mat(r, c);
                assert_eq!(Ty::parse(&t.name()), Some(t));
                assert_eq!(Ty::parse(&format!("mat{r}x{c}")), Some(t));
            }
        }
        for t in [Ty::F64, Ty::I64, Ty::Bool, Ty::Vec2, Ty::Vec3] {
            assert_eq!(Ty::parse(&t.name()), Some(t));
        }
        for bad in [
            "mat0", "mat13", "mat3x0", "mat3x13", "mat03", "mat+3", "mat", "matx", "mat3x",
            "mat3x3x3", "vec4", "F64", "mat 3", "mat256", "",
        ] {
            assert_eq!(Ty::parse(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn widths_and_reality() {
        assert_eq!(Ty::F64.width(), 1);
        assert_eq!(Ty::I64.width(), 1);
        assert_eq!(Ty::Bool.width(), 1);
        assert_eq!(Ty::Vec3.width(), 3);
        assert_eq!(Ty::Mat(12, 12).width(), 144);
        assert!(Ty::Mat(2, 3).is_real() && Ty::Vec2.is_real() && Ty::F64.is_real());
        assert!(!Ty::I64.is_real() && !Ty::Bool.is_real());
        assert_eq!(Ty::mat(3, 4), Some(Ty::Mat(3, 4)));
        assert_eq!(Ty::mat(13, 1), None);
        assert_eq!(Ty::mat(0, 1), None);
    }

    /// `from_reals` and `to_reals` are inverse, `zero` has its type, and the accessors only
    /// answer for their kind (`as_f64` also promotes an integer).
    #[test]
    fn reals_round_trip_and_accessors() {
        for t in sample_types() {
            let v = counting(t);
            assert_eq!(v.ty(), t);
            let mut x = Vec::new();
            v.to_reals(&mut x);
            assert_eq!(x.len(), t.width());
            assert_eq!(Val::from_reals(t, &x), v);
            assert_eq!(Val::zero(t).ty(), t);
        }
        let mut x = vec![7.0];
        Val::B(true).to_reals(&mut x);
        Val::I(-4).to_reals(&mut x);
        assert_eq!(x, [7.0, 1.0, -4.0]);
        assert_eq!(Val::I(2).as_f64(), Some(2.0));
        assert_eq!(Val::F(2.5).as_f64(), Some(2.5));
        assert_eq!(Val::B(true).as_f64(), None);
        assert_eq!(Val::B(true).as_bool(), Some(true));
        assert_eq!(Val::I(1).as_bool(), None);
        assert_eq!(Val::I(5).as_i64(), Some(5));
        assert_eq!(Val::F(5.0).as_i64(), None);
        let m = Mat::identity(3);
        assert_eq!(m.get(1, 1), 1.0);
        assert_eq!(m.get(0, 1), 0.0);
    }

    #[test]
    fn mat_product_and_transpose() {
        let a = Mat {
            rows: 2,
            cols: 3,
            data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        };
        let b = a.transpose();
        assert_eq!(b.rows, 3);
        assert_eq!(b.data, [1.0, 4.0, 2.0, 5.0, 3.0, 6.0]);
        let p = a.mul(&b);
        assert_eq!(p.data, [14.0, 32.0, 32.0, 77.0]);
        assert_eq!(Mat::identity(2).mul(&a), a);
        let mut z = Mat::zeros(2, 2);
        z.set(1, 0, 9.0);
        assert_eq!(z.data, [0.0, 0.0, 9.0, 0.0]);
    }

    /// The accepted cases of the typing rules, one per rule.
    #[test]
    fn typing_accepts() {
        use BinOp::*;
        let m = |r, c| Ty::Mat(r, c);
        let ok = [
            (Add, Ty::F64, Ty::F64, Ty::F64),
            (Add, Ty::I64, Ty::I64, Ty::I64),
            (Add, Ty::F64, Ty::I64, Ty::F64),
            (Sub, Ty::I64, Ty::F64, Ty::F64),
            (Add, Ty::Vec3, Ty::Vec3, Ty::Vec3),
            (Sub, m(3, 4), m(3, 4), m(3, 4)),
            (Mul, Ty::I64, Ty::I64, Ty::I64),
            (Mul, Ty::I64, Ty::F64, Ty::F64),
            (Mul, Ty::I64, Ty::Vec3, Ty::Vec3),
            (Mul, Ty::Vec2, Ty::F64, Ty::Vec2),
            (Mul, Ty::F64, m(3, 4), m(3, 4)),
            (Mul, m(4, 3), Ty::I64, m(4, 3)),
            (Mul, m(2, 3), m(3, 4), m(2, 4)),
            (Mul, m(3, 3), Ty::Vec3, Ty::Vec3),
            (Mul, m(2, 2), Ty::Vec2, Ty::Vec2),
            (Mul, m(4, 3), Ty::Vec3, m(4, 1)),
            (Mul, m(12, 3), Ty::Vec3, m(12, 1)),
            (Mul, m(3, 2), Ty::Vec2, m(3, 1)),
            (Mul, m(1, 2), Ty::Vec2, m(1, 1)),
            (Mul, m(12, 12), m(12, 1), m(12, 1)),
            (Div, Ty::Vec3, Ty::F64, Ty::Vec3),
            (Div, Ty::Vec3, Ty::I64, Ty::Vec3),
            (Div, m(3, 3), Ty::I64, m(3, 3)),
            (Div, Ty::I64, Ty::I64, Ty::I64),
            (Div, Ty::I64, Ty::F64, Ty::F64),
            (Div, Ty::F64, Ty::I64, Ty::F64),
            (Rem, Ty::I64, Ty::I64, Ty::I64),
            (Rem, Ty::F64, Ty::F64, Ty::F64),
            (Rem, Ty::F64, Ty::I64, Ty::F64),
            (Lt, Ty::I64, Ty::F64, Ty::Bool),
            (Ge, Ty::I64, Ty::I64, Ty::Bool),
            (Eq, Ty::Vec3, Ty::Vec3, Ty::Bool),
            (Ne, m(2, 3), m(2, 3), Ty::Bool),
            (Eq, Ty::F64, Ty::I64, Ty::Bool),
            (Eq, Ty::Bool, Ty::Bool, Ty::Bool),
            (And, Ty::Bool, Ty::Bool, Ty::Bool),
            (Or, Ty::Bool, Ty::Bool, Ty::Bool),
        ];
        for (op, a, b, r) in ok {
            assert_eq!(binop_type(op, a, b), Ok(r), "{a} {} {b}", op.symbol());
        }
        assert_eq!(unop_type(UnOp::Neg, Ty::I64), Ok(Ty::I64));
        assert_eq!(unop_type(UnOp::Neg, Ty::Mat(3, 4)), Ok(Ty::Mat(3, 4)));
        assert_eq!(unop_type(UnOp::Not, Ty::Bool), Ok(Ty::Bool));
    }

    /// The refused cases, with the messages a rule author sees.
    #[test]
    fn typing_refuses_with_messages() {
        use BinOp::*;
        let m = |r, c| Ty::Mat(r, c);
        let err = |op, a, b| binop_type(op, a, b).unwrap_err();
        assert_eq!(err(Add, Ty::Vec3, Ty::F64), "cannot add vec3 and f64");
        assert_eq!(
            err(Sub, Ty::Bool, Ty::Bool),
            "cannot subtract bool and bool"
        );
        assert_eq!(
            err(Add, m(3, 3), m(3, 4)),
            "cannot add mat3 and mat3x4: the shapes differ"
        );
        assert_eq!(
            err(Mul, Ty::Vec3, Ty::Vec3),
            "cannot multiply vec3 and vec3: use dot(a, b), cross(a, b) or outer(a, b)"
        );
        assert!(err(Mul, Ty::Vec2, Ty::Vec3).contains("dot(a, b)"));
        assert_eq!(
            err(Mul, m(2, 3), m(2, 3)),
            "cannot multiply mat2x3 and mat2x3: mat2x3 has 3 columns but mat2x3 has 2 rows"
        );
        assert_eq!(
            err(Mul, m(3, 3), Ty::Vec2),
            "cannot multiply mat3 and vec2: mat3 has 3 columns but vec2 has 2 rows"
        );
        assert!(err(Mul, Ty::Vec3, m(3, 3)).contains("transpose(m) * v"));
        assert_eq!(err(Mul, Ty::Bool, Ty::F64), "cannot multiply bool and f64");
        assert_eq!(
            err(Div, Ty::F64, Ty::Vec3),
            "cannot divide f64 by vec3: the divisor must be f64 or i64"
        );
        assert!(err(Div, m(3, 3), m(3, 3)).starts_with("cannot divide mat3 by mat3"));
        assert!(err(Div, Ty::Bool, Ty::I64).starts_with("cannot divide"));
        assert!(err(Rem, Ty::Vec3, Ty::F64).contains("% applies to f64 and i64"));
        assert_eq!(
            err(Lt, Ty::Vec3, Ty::F64),
            "cannot compare vec3 and f64 with <: only f64 and i64 are ordered"
        );
        assert!(err(Le, Ty::Bool, Ty::Bool).contains("only f64 and i64 are ordered"));
        assert_eq!(
            err(Eq, Ty::Vec3, Ty::Vec2),
            "cannot compare vec3 and vec2 with ==: the types differ"
        );
        assert!(err(Ne, m(3, 3), m(2, 2)).contains("the types differ"));
        assert!(err(Eq, Ty::Bool, Ty::I64).contains("the types differ"));
        assert_eq!(
            err(And, Ty::Bool, Ty::I64),
            "cannot apply `and` to bool and i64: both operands must be bool"
        );
        assert_eq!(
            unop_type(UnOp::Not, Ty::F64).unwrap_err(),
            "cannot apply `not` to f64: it needs a bool"
        );
        assert!(unop_type(UnOp::Neg, Ty::Bool).is_err());
    }

    /// Integer promotion: `2 * v`, `x + 1`, `m / 2` are real; `7 / 2` stays an integer
    /// division; mixed comparisons compare the values.
    #[test]
    fn integer_promotion() {
        let v = Val::V3([1.0, -2.0, 0.5]);
        assert_eq!(
            binop(BinOp::Mul, &Val::I(2), &v),
            Ok(Val::V3([2.0, -4.0, 1.0]))
        );
        assert_eq!(binop(BinOp::Add, &Val::F(0.5), &Val::I(1)), Ok(Val::F(1.5)));
        assert_eq!(binop(BinOp::Sub, &Val::I(1), &Val::F(0.5)), Ok(Val::F(0.5)));
        assert_eq!(binop(BinOp::Div, &Val::I(7), &Val::I(2)), Ok(Val::I(3)));
        assert_eq!(binop(BinOp::Div, &Val::I(-7), &Val::I(2)), Ok(Val::I(-3)));
        assert_eq!(binop(BinOp::Rem, &Val::I(-7), &Val::I(2)), Ok(Val::I(-1)));
        assert_eq!(binop(BinOp::Div, &Val::I(7), &Val::F(2.0)), Ok(Val::F(3.5)));
        assert_eq!(binop(BinOp::Rem, &Val::F(7.5), &Val::I(2)), Ok(Val::F(1.5)));
        assert_eq!(
            binop(BinOp::Div, &Val::M(Mat::identity(2)), &Val::I(2)),
            Ok(Val::M(Mat {
                rows: 2,
                cols: 2,
                data: vec![0.5, 0.0, 0.0, 0.5]
            }))
        );
        assert_eq!(binop(BinOp::Lt, &Val::I(1), &Val::F(1.5)), Ok(Val::B(true)));
        assert_eq!(binop(BinOp::Eq, &Val::F(2.0), &Val::I(2)), Ok(Val::B(true)));
        assert_eq!(binop(BinOp::Ne, &Val::I(2), &Val::I(2)), Ok(Val::B(false)));
    }

    /// Matrix times vector: a square matrix keeps the vector type, a tall one gives a column.
    #[test]
    fn mat_vec_shapes() {
        let r = Val::M(Mat {
            rows: 3,
            cols: 3,
            data: vec![0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        });
        assert_eq!(
            binop(BinOp::Mul, &r, &Val::V3([1.0, 2.0, 3.0])),
            Ok(Val::V3([-2.0, 1.0, 3.0]))
        );
        let tall = counting(Ty::Mat(4, 3));
        let p = binop(BinOp::Mul, &tall, &Val::V3([1.0, 0.0, -1.0])).unwrap();
        assert_eq!(p.ty(), Ty::Mat(4, 1));
        assert_eq!(p, Val::from_reals(Ty::Mat(4, 1), &[-2.0, -2.0, -2.0, -2.0]));
        let wide = counting(Ty::Mat(3, 2));
        let q = binop(BinOp::Mul, &wide, &Val::V2([1.0, 1.0])).unwrap();
        assert_eq!(q, Val::from_reals(Ty::Mat(3, 1), &[3.0, 7.0, 11.0]));
        let two = counting(Ty::Mat(2, 2));
        assert_eq!(
            binop(BinOp::Mul, &two, &Val::V2([1.0, -1.0])),
            Ok(Val::V2([-1.0, -1.0]))
        );
    }

    /// Integer division by zero and overflow are errors, never panics; real division by zero
    /// follows IEEE.
    #[test]
    fn integer_errors() {
        let e = binop(BinOp::Div, &Val::I(1), &Val::I(0)).unwrap_err();
        assert_eq!(e.0, "integer division by zero in 1 / 0");
        assert!(binop(BinOp::Rem, &Val::I(1), &Val::I(0)).is_err());
        assert!(binop(BinOp::Div, &Val::I(i64::MIN), &Val::I(-1)).is_err());
        assert!(binop(BinOp::Rem, &Val::I(i64::MIN), &Val::I(-1)).is_err());
        assert!(binop(BinOp::Add, &Val::I(i64::MAX), &Val::I(1)).is_err());
        assert!(binop(BinOp::Mul, &Val::I(i64::MAX), &Val::I(2)).is_err());
        assert!(unop(UnOp::Neg, &Val::I(i64::MIN)).is_err());
        assert_eq!(
            binop(BinOp::Div, &Val::F(1.0), &Val::I(0)),
            Ok(Val::F(f64::INFINITY))
        );
    }

    /// Every operator on every pair of sample types: a refused pair has a message, an accepted
    /// pair evaluates to a value of the announced type; an unchecked pair is an error, not a
    /// panic.
    #[test]
    fn evaluation_matches_typing() {
        for op in ALL_OPS {
            for &a in &sample_types() {
                for &b in &sample_types() {
                    let r = binop(op, &counting(a), &counting(b));
                    match binop_type(op, a, b) {
                        Ok(t) => assert_eq!(r.map(|v| v.ty()), Ok(t), "{a} {} {b}", op.symbol()),
                        Err(msg) => {
                            assert!(!msg.is_empty());
                            assert!(r.is_err(), "{a} {} {b} evaluated", op.symbol());
                        }
                    }
                }
            }
        }
        for a in sample_types() {
            for op in [UnOp::Neg, UnOp::Not] {
                let r = unop(op, &counting(a));
                match unop_type(op, a) {
                    Ok(t) => assert_eq!(r.map(|v| v.ty()), Ok(t)),
                    Err(_) => assert!(r.is_err()),
                }
            }
        }
    }

    #[test]
    fn logic_and_negation() {
        let (t, f) = (Val::B(true), Val::B(false));
        assert_eq!(binop(BinOp::And, &t, &f), Ok(f.clone()));
        assert_eq!(binop(BinOp::Or, &t, &f), Ok(t.clone()));
        assert_eq!(unop(UnOp::Not, &t), Ok(f));
        assert_eq!(
            unop(UnOp::Neg, &Val::V2([1.0, -2.0])),
            Ok(Val::V2([-1.0, 2.0]))
        );
        assert_eq!(
            binop(BinOp::Eq, &Val::F(f64::NAN), &Val::F(f64::NAN)),
            Ok(Val::B(false))
        );
    }
}
