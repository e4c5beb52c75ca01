//! Built-in functions of the expression language: constructors, accessors, scalar math,
//! vector and matrix algebra, and the block helpers of finite-element assembly.
//!
//! [`call_type`] checks a call before evaluation; [`call`] evaluates it and fails only for
//! numerical reasons (an index out of range, a singular matrix, a non-finite input to a
//! decomposition); [`catalogue`] lists every built-in with its signature.
//!
//! In the signatures, `num` is `f64` or `i64` (an `i64` argument is promoted to `f64`), `vecN`
//! is `vec2` or `vec3`, `col` is `vec2`, `vec3` or a column `matNx1` (the element vectors of
//! finite elements), `matN` is a square matrix and `same` is the type of the first argument.
//! Indices are `i64`, counted from 0.
//!
//! ```
//! use topomech_lang::builtins::{call, call_type};
//! use topomech_lang::value::{Mat, Ty, Val};
//!
//! assert_eq!(call_type("cross", &[Ty::Vec3, Ty::Vec3]), Ok(Ty::Vec3));
//! assert!(call_type("crss", &[Ty::Vec3, Ty::Vec3]).unwrap_err().contains("`cross`"));
//! // The rotation of an inverted element (a reflection) is still a rotation.
//! let f = Val::M(Mat { rows: 2, cols: 2, data: vec![1.0, 0.0, 0.0, -2.0] });
//! let Val::M(r) = call("polar", &[f]).unwrap() else { unreachable!() };
//! assert_eq!(r.data, [-1.0, 0.0, 0.0, -1.0]);
//! ```
//!
//! Scalar functions follow IEEE 754 (`sqrt(-1)` is NaN, `log(0)` is `-inf`); a rule can test
//! a result with `is_finite`. `min`, `max` and `clamp` propagate NaN instead of hiding it.
//!
//! Methods, with their sources:
//! - `det`: closed forms up to 3x3, with Kahan's fused-multiply-add difference of products for
//!   the 2x2 minors (Jeannerod, Louvet, Muller 2013, "Further analysis of Kahan's algorithm for
//!   the accurate computation of 2x2 determinants", Math. Comp. 82, doi:10.1090/S0025-5718-2013-02679-8);
//!   above, LU with partial pivoting (Golub & Van Loan, *Matrix Computations*, 4th ed., §3.4).
//! - `inverse`: Gauss-Jordan elimination with partial pivoting (Golub & Van Loan §3.4; Higham,
//!   *Accuracy and Stability of Numerical Algorithms*, 2nd ed., §14.4 for its residual bound).
//! - `polar`: the rotation of the polar decomposition, as used by co-rotational FEM
//!   (Müller & Gross 2004, "Interactive virtual materials", Graphics Interface), with the
//!   convention of Irving, Teran & Fedkiw 2004 ("Invertible finite elements for robust
//!   simulation of large deformation", SCA, doi:10.1145/1028523.1028541) for inverted
//!   elements. 3x3: Newton's iteration with Frobenius-norm scaling (Higham 1986, "Computing
//!   the polar decomposition -- with applications", SIAM J. Sci. Stat. Comput. 7,
//!   doi:10.1137/0907079) where `det m > 0` and the condition number is below 100; otherwise
//!   one-sided Jacobi SVD (Hestenes 1958, doi:10.1137/0106005; accurate small singular
//!   values: Demmel & Veselić 1992, doi:10.1137/0613074). 2x2: closed form.
//! - `eigvals_sym3`: cyclic Jacobi (Golub & Van Loan §8.5).
//! - `angle`: `atan2(|a x b|, a . b)` (Kahan 2006, "How futile are mindless assessments of
//!   roundoff in floating-point computation?", §12), accurate near 0 and pi where `acos` is not.

use crate::value::{EvalError, Mat, Ty, Val};

/// Every built-in: name, signature, description.
const CATALOGUE: &[(&str, &str, &str)] = &[
    // Constructors.
    ("vec2", "vec2(x: num, y: num) -> vec2", "The 2-vector (x, y)."),
    ("vec3", "vec3(x: num, y: num, z: num) -> vec3", "The 3-vector (x, y, z)."),
    (
        "mat2",
        "mat2(a: num, b: num, c: num, d: num) -> mat2",
        "The 2x2 matrix with rows (a, b) and (c, d).",
    ),
    (
        "mat3",
        "mat3(a: num, b: num, c: num, d: num, e: num, f: num, g: num, h: num, i: num) -> mat3",
        "The 3x3 matrix with rows (a, b, c), (d, e, f) and (g, h, i).",
    ),
    (
        "mat_from_cols2",
        "mat_from_cols2(a: vec2, b: vec2) -> mat2",
        "The 2x2 matrix with columns a and b.",
    ),
    (
        "mat_from_rows2",
        "mat_from_rows2(a: vec2, b: vec2) -> mat2",
        "The 2x2 matrix with rows a and b.",
    ),
    (
        "mat_from_cols3",
        "mat_from_cols3(a: vec3, b: vec3, c: vec3) -> mat3",
        "The 3x3 matrix with columns a, b and c (e.g. the edge matrix of a tetrahedron).",
    ),
    (
        "mat_from_rows3",
        "mat_from_rows3(a: vec3, b: vec3, c: vec3) -> mat3",
        "The 3x3 matrix with rows a, b and c.",
    ),
    ("identity2", "identity2() -> mat2", "The 2x2 identity matrix."),
    ("identity3", "identity3() -> mat3", "The 3x3 identity matrix."),
    ("zeros2", "zeros2() -> mat2", "The 2x2 zero matrix."),
    ("zeros3", "zeros3() -> mat3", "The 3x3 zero matrix."),
    (
        "zeros6",
        "zeros6() -> mat6",
        "The 6x6 zero matrix (the element matrix of a linear triangle in 2D).",
    ),
    (
        "zeros6x1",
        "zeros6x1() -> mat6x1",
        "The zero 6-column (the element vector of a linear triangle in 2D).",
    ),
    (
        "zeros12",
        "zeros12() -> mat12",
        "The 12x12 zero matrix (the element matrix of a linear tetrahedron).",
    ),
    (
        "zeros12x1",
        "zeros12x1() -> mat12x1",
        "The zero 12-column (the element vector of a linear tetrahedron).",
    ),
    // Accessors.
    ("x", "x(v: vecN) -> f64", "The first component of v."),
    ("y", "y(v: vecN) -> f64", "The second component of v."),
    ("z", "z(v: vec3) -> f64", "The third component of v."),
    (
        "elem",
        "elem(v: col, i: i64) -> f64",
        "Component i of a vector or column; error if out of range.",
    ),
    (
        "get",
        "get(m: matRxC | vecN, i: i64, j: i64) -> f64",
        "Entry (i, j) of m (a vector is a column: j = 0); error if out of range.",
    ),
    (
        "set",
        "set(m: matRxC | vecN, i: i64, j: i64, x: num) -> same",
        "A copy of m with entry (i, j) set to x (a vector is a column: j = 0); error if out of range.",
    ),
    (
        "row2",
        "row2(m: matRx2, i: i64) -> vec2",
        "Row i of a matrix with 2 columns; error if out of range.",
    ),
    (
        "col2",
        "col2(m: mat2xC, j: i64) -> vec2",
        "Column j of a matrix with 2 rows; error if out of range.",
    ),
    (
        "row3",
        "row3(m: matRx3, i: i64) -> vec3",
        "Row i of a matrix with 3 columns; error if out of range.",
    ),
    (
        "col3",
        "col3(m: mat3xC, j: i64) -> vec3",
        "Column j of a matrix with 3 rows; error if out of range.",
    ),
    // Finite-element blocks.
    (
        "block2",
        "block2(m: mat(2p)x(2q), i: i64, j: i64) -> mat2",
        "The 2x2 block (i, j) of m: rows 2i, 2i+1 and columns 2j, 2j+1; error if out of range.",
    ),
    (
        "set_block2",
        "set_block2(m: mat(2p)x(2q), i: i64, j: i64, b: mat2) -> same",
        "A copy of m with its 2x2 block (i, j) replaced by b; error if out of range.",
    ),
    (
        "vecn_get2",
        "vecn_get2(v: mat(2p)x1, i: i64) -> vec2",
        "Entries 2i, 2i+1 of a column (node i's part of an element vector); error if out of range.",
    ),
    (
        "vecn_set2",
        "vecn_set2(v: mat(2p)x1, i: i64, x: vec2) -> same",
        "A copy of v with entries 2i, 2i+1 set to x; error if out of range.",
    ),
    (
        "block3",
        "block3(m: mat(3p)x(3q), i: i64, j: i64) -> mat3",
        "The 3x3 block (i, j) of m: rows 3i..3i+2 and columns 3j..3j+2; error if out of range.",
    ),
    (
        "set_block3",
        "set_block3(m: mat(3p)x(3q), i: i64, j: i64, b: mat3) -> same",
        "A copy of m with its 3x3 block (i, j) replaced by b; error if out of range.",
    ),
    (
        "vecn_get3",
        "vecn_get3(v: mat(3p)x1, i: i64) -> vec3",
        "Entries 3i..3i+2 of a column (node i's part of an element vector); error if out of range.",
    ),
    (
        "vecn_set3",
        "vecn_set3(v: mat(3p)x1, i: i64, x: vec3) -> same",
        "A copy of v with entries 3i..3i+2 set to x; error if out of range.",
    ),
    // Conversions.
    (
        "to_f64",
        "to_f64(x: i64 | f64 | bool) -> f64",
        "x as a real (true is 1, false is 0).",
    ),
    (
        "to_i64",
        "to_i64(x: f64 | i64 | bool) -> i64",
        "x truncated toward zero; error if x is NaN, infinite or outside the i64 range.",
    ),
    // Scalar math.
    (
        "abs",
        "abs(x: f64) -> f64 | abs(x: i64) -> i64",
        "Absolute value; error for the i64 minimum, whose absolute value is not an i64.",
    ),
    (
        "sign",
        "sign(x: f64) -> f64 | sign(x: i64) -> i64",
        "-1, 0 or 1 by the sign of x (0 for -0.0, NaN for NaN).",
    ),
    ("sqrt", "sqrt(x: num) -> f64", "Square root (NaN for x < 0)."),
    ("exp", "exp(x: num) -> f64", "The exponential e^x."),
    (
        "log",
        "log(x: num) -> f64",
        "Natural logarithm (-inf at 0, NaN for x < 0).",
    ),
    ("sin", "sin(x: num) -> f64", "Sine of x in radians."),
    ("cos", "cos(x: num) -> f64", "Cosine of x in radians."),
    ("tan", "tan(x: num) -> f64", "Tangent of x in radians."),
    (
        "asin",
        "asin(x: num) -> f64",
        "Arcsine in [-pi/2, pi/2] (NaN outside [-1, 1]).",
    ),
    (
        "acos",
        "acos(x: num) -> f64",
        "Arccosine in [0, pi] (NaN outside [-1, 1]; angle(a, b) is more accurate for vectors).",
    ),
    ("atan", "atan(x: num) -> f64", "Arctangent in [-pi/2, pi/2]."),
    (
        "atan2",
        "atan2(y: num, x: num) -> f64",
        "The angle of the point (x, y) from the x axis, in [-pi, pi].",
    ),
    ("pow", "pow(x: num, y: num) -> f64", "x raised to the power y."),
    ("floor", "floor(x: num) -> f64", "The largest integer <= x, as f64."),
    ("ceil", "ceil(x: num) -> f64", "The smallest integer >= x, as f64."),
    (
        "min",
        "min(a: num, b: num) -> num",
        "The smaller of a and b (i64 if both are i64; NaN if either is NaN).",
    ),
    (
        "max",
        "max(a: num, b: num) -> num",
        "The larger of a and b (i64 if both are i64; NaN if either is NaN).",
    ),
    (
        "clamp",
        "clamp(x: num, lo: num, hi: num) -> num",
        "x limited to [lo, hi] (i64 if all are i64; NaN if any is NaN); error if lo > hi.",
    ),
    (
        "select",
        "select(c: bool, a: T, b: T) -> T",
        "a if c, else b, for any type T (an i64 and an f64 give f64); both are evaluated.",
    ),
    (
        "is_finite",
        "is_finite(x: num | vecN | matRxC) -> bool",
        "Whether every entry of x is finite, neither NaN nor infinite (always true for i64).",
    ),
    // Vectors.
    (
        "dot",
        "dot(a: col, b: col) -> f64",
        "Dot product of two vectors or columns of the same type.",
    ),
    (
        "cross",
        "cross(a: vec3, b: vec3) -> vec3 | cross(a: vec2, b: vec2) -> f64",
        "Cross product; in 2D its z-component a.x*b.y - a.y*b.x.",
    ),
    (
        "norm",
        "norm(v: col) -> f64",
        "Euclidean length: sqrt of the sum of squares where that sum is finite and at least 2^-960, else computed scaled by the largest entry, so that huge or tiny entries neither overflow nor underflow.",
    ),
    ("norm2", "norm2(v: col) -> f64", "Squared Euclidean length."),
    (
        "normalize",
        "normalize(v: col) -> same",
        "v / norm(v), the unit vector along v; the zero vector for a zero input.",
    ),
    (
        "outer",
        "outer(a: col, b: col) -> matMxN",
        "Outer product a b^T, M and N being the lengths of a and b.",
    ),
    (
        "angle",
        "angle(a: vecN, b: vecN) -> f64",
        "Unsigned angle in [0, pi] between a and b, atan2(|a x b|, a . b) (Kahan): accurate near \
         0 and pi; 0 if either is zero.",
    ),
    // Matrices.
    (
        "transpose",
        "transpose(m: matRxC) -> matCxR",
        "The transpose of m.",
    ),
    ("trace", "trace(m: matN) -> f64", "Sum of the diagonal of m."),
    (
        "det",
        "det(m: matN) -> f64",
        "Determinant: closed forms up to 3x3, LU with partial pivoting above.",
    ),
    (
        "inverse",
        "inverse(m: matN) -> matN",
        "Inverse by Gauss-Jordan elimination with partial pivoting; error if m is singular (a \
         pivot below 1e-300), not finite, or its inverse overflows.",
    ),
    (
        "frobenius",
        "frobenius(m: matRxC) -> f64",
        "Frobenius norm, the square root of the sum of squared entries (scaled: no overflow).",
    ),
    ("sym", "sym(m: matN) -> matN", "Symmetric part (m + m^T) / 2."),
    (
        "segment_hits_triangle",
        "segment_hits_triangle(a: vec3, b: vec3, p: vec3, q: vec3, r: vec3) -> bool",
        "Whether the segment from a to b crosses the triangle p q r: its ends strictly on \
         opposite sides of the triangle's plane (an end on the plane does not count, as for \
         a plane cut's sides), through the closed triangle (its edges and vertices count), by \
         Moeller and Trumbore 1997 (doi:10.1080/10867651.1997.10487468) with tolerances \
         relative to the sizes; false for a flat triangle, a zero-length segment, a segment \
         lying in the triangle's plane, or non-finite input.",
    ),
    (
        "polar",
        "polar(m: mat2 | mat3) -> same",
        "The rotation R (det R = +1) of the polar decomposition m = R S: the rotation closest \
         to m; for det m < 0 the smallest singular value is negated (Irving et al. 2004); error \
         if m is not finite.",
    ),
    (
        "eigvals_sym2",
        "eigvals_sym2(m: mat2) -> vec2",
        "Eigenvalues of sym(m), in descending order (closed form).",
    ),
    (
        "eigvals_sym3",
        "eigvals_sym3(m: mat3) -> vec3",
        "Eigenvalues of sym(m), in descending order (cyclic Jacobi); error if m is not finite.",
    ),
];

/// Every built-in, as (name, signature text, one-line description), for documentation and
/// `topomech` help.
pub fn catalogue() -> &'static [(&'static str, &'static str, &'static str)] {
    CATALOGUE
}

/// The signature of a built-in.
fn signature(name: &str) -> Option<&'static str> {
    CATALOGUE
        .iter()
        .chain(crate::mechanics::CATALOGUE)
        .find(|(n, _, _)| *n == name)
        .map(|(_, sig, _)| *sig)
}

/// Every built-in of the language: [`catalogue`] and the element built-ins of
/// [`crate::mechanics`].
pub fn full_catalogue() -> Vec<(&'static str, &'static str, &'static str)> {
    CATALOGUE
        .iter()
        .chain(crate::mechanics::CATALOGUE)
        .copied()
        .collect()
}

/// The number of arguments in a signature `name(a: t, b: t) -> r` (all overloads of a
/// built-in have the same number).
fn arity(sig: &str) -> usize {
    // Commas at depth 1 of the first parenthesized group; types such as `mat(3p)x(3q)` nest.
    let mut depth = 0;
    let (mut commas, mut empty) = (0, true);
    for ch in sig.chars() {
        match ch {
            '(' => depth += 1,
            ')' if depth == 1 => break,
            ')' => depth -= 1,
            ',' if depth == 1 => commas += 1,
            c if depth >= 1 && !c.is_whitespace() => empty = false,
            _ => {}
        }
    }
    if empty {
        0
    } else {
        commas + 1
    }
}

/// Levenshtein distance, for suggestions.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// The message for an unknown function, with up to three close names.
fn unknown(name: &str) -> String {
    let mut close: Vec<(usize, &str)> = CATALOGUE
        .iter()
        .map(|(n, _, _)| (edit_distance(name, n), *n))
        .filter(|&(d, n)| d <= 2.min(n.len().saturating_sub(1)) && d < name.len().max(1))
        .collect();
    close.sort_unstable();
    let close: Vec<String> = close
        .iter()
        .take(3)
        .map(|(_, n)| format!("`{n}`"))
        .collect();
    match close.len() {
        0 => format!("unknown function `{name}`"),
        1 => format!("unknown function `{name}`; did you mean {}?", close[0]),
        _ => format!(
            "unknown function `{name}`; did you mean one of {}?",
            close.join(", ")
        ),
    }
}

fn is_num(t: Ty) -> bool {
    matches!(t, Ty::F64 | Ty::I64)
}

/// The length of a vector or column type.
fn col_len(t: Ty) -> Option<usize> {
    match t {
        Ty::Vec2 => Some(2),
        Ty::Vec3 => Some(3),
        Ty::Mat(r, 1) => Some(usize::from(r)),
        _ => None,
    }
}

/// A matrix type made of `k x k` blocks.
fn is_blocked(t: Ty, k: u8) -> bool {
    matches!(t, Ty::Mat(r, c) if r % k == 0 && c % k == 0)
}

/// The type of `name(args...)`, or why it does not apply (an unknown function's message names
/// it and lists close names).
pub fn call_type(name: &str, args: &[Ty]) -> Result<Ty, String> {
    let Some(sig) = signature(name) else {
        return Err(unknown(name));
    };
    let n = arity(sig);
    if args.len() != n {
        let s = if n == 1 { "" } else { "s" };
        return Err(format!(
            "`{name}` takes {n} argument{s}, got {}: {sig}",
            args.len()
        ));
    }
    result_type(name, args).ok_or_else(|| {
        let got: Vec<String> = args.iter().map(|t| t.name()).collect();
        format!("`{name}` does not apply to ({}): {sig}", got.join(", "))
    })
}

/// The result type of a known built-in with the right number of arguments, `None` if the
/// argument types do not fit.
// One arm per built-in or overload, in catalogue order: a table of signatures, whose equal
// result types are a coincidence, not something to merge.
#[allow(clippy::match_same_arms)]
fn result_type(name: &str, args: &[Ty]) -> Option<Ty> {
    use Ty::{Bool, Mat, Vec2, Vec3, F64, I64};
    if let Some(t) = crate::mechanics::result_type(name, args) {
        return Some(t);
    }
    let all_num = args.iter().all(|&t| is_num(t));
    let all_int = args.iter().all(|&t| t == I64);
    let r = match (name, args) {
        ("vec2", _) if all_num => Vec2,
        ("vec3", _) if all_num => Vec3,
        ("mat2", _) if all_num => Mat(2, 2),
        ("mat3", _) if all_num => Mat(3, 3),
        ("mat_from_cols2" | "mat_from_rows2", [Vec2, Vec2]) => Mat(2, 2),
        ("mat_from_cols3" | "mat_from_rows3", [Vec3, Vec3, Vec3]) => Mat(3, 3),
        ("identity2" | "zeros2", []) => Mat(2, 2),
        ("identity3" | "zeros3", []) => Mat(3, 3),
        ("zeros6", []) => Mat(6, 6),
        ("zeros6x1", []) => Mat(6, 1),
        ("zeros12", []) => Mat(12, 12),
        ("zeros12x1", []) => Mat(12, 1),
        ("x" | "y", [Vec2 | Vec3]) | ("z", [Vec3]) => F64,
        ("elem", [v, I64]) if col_len(*v).is_some() => F64,
        ("get", [Mat(..) | Vec2 | Vec3, I64, I64]) => F64,
        ("set", [m @ (Mat(..) | Vec2 | Vec3), I64, I64, x]) if is_num(*x) => *m,
        ("row2", [Mat(_, 2), I64]) | ("col2", [Mat(2, _), I64]) => Vec2,
        ("row3", [Mat(_, 3), I64]) | ("col3", [Mat(3, _), I64]) => Vec3,
        ("block2", [m, I64, I64]) if is_blocked(*m, 2) => Mat(2, 2),
        ("block3", [m, I64, I64]) if is_blocked(*m, 3) => Mat(3, 3),
        ("set_block2", [m, I64, I64, Mat(2, 2)]) if is_blocked(*m, 2) => *m,
        ("set_block3", [m, I64, I64, Mat(3, 3)]) if is_blocked(*m, 3) => *m,
        ("vecn_get2", [Mat(r, 1), I64]) if r % 2 == 0 => Vec2,
        ("vecn_get3", [Mat(r, 1), I64]) if r % 3 == 0 => Vec3,
        ("vecn_set2", [v @ Mat(r, 1), I64, Vec2]) if r % 2 == 0 => *v,
        ("vecn_set3", [v @ Mat(r, 1), I64, Vec3]) if r % 3 == 0 => *v,
        ("to_f64", [F64 | I64 | Bool]) => F64,
        ("to_i64", [F64 | I64 | Bool]) => I64,
        ("abs" | "sign" | "min" | "max" | "clamp", _) if all_int => I64,
        ("abs" | "sign" | "min" | "max" | "clamp", _) if all_num => F64,
        (
            "sqrt" | "exp" | "log" | "sin" | "cos" | "tan" | "asin" | "acos" | "atan" | "atan2"
            | "pow" | "floor" | "ceil",
            _,
        ) if all_num => F64,
        ("select", [Bool, a, b]) if a == b => *a,
        ("select", [Bool, a, b]) if is_num(*a) && is_num(*b) => F64,
        ("is_finite", [t]) if *t != Bool => Bool,
        ("dot", [a, b]) if a == b && col_len(*a).is_some() => F64,
        ("cross", [Vec3, Vec3]) => Vec3,
        ("cross", [Vec2, Vec2]) => F64,
        ("norm" | "norm2", [v]) if col_len(*v).is_some() => F64,
        ("normalize", [v]) if col_len(*v).is_some() => *v,
        ("outer", [a, b]) => Ty::mat(col_len(*a)?, col_len(*b)?)?,
        ("angle", [Vec2, Vec2] | [Vec3, Vec3]) => F64,
        ("transpose", [Mat(r, c)]) => Mat(*c, *r),
        ("frobenius", [Mat(..)]) => F64,
        ("trace" | "det", [Mat(r, c)]) if r == c => F64,
        ("inverse" | "sym", [m @ Mat(r, c)]) if r == c => *m,
        ("segment_hits_triangle", [Vec3, Vec3, Vec3, Vec3, Vec3]) => Bool,
        ("polar", [m @ (Mat(2, 2) | Mat(3, 3))]) => *m,
        ("eigvals_sym2", [Mat(2, 2)]) => Vec2,
        ("eigvals_sym3", [Mat(3, 3)]) => Vec3,
        _ => return None,
    };
    Some(r)
}

// ---------------------------------------------------------------------------------------------
// Evaluation.

fn err(msg: impl Into<String>) -> EvalError {
    EvalError(msg.into())
}

/// The error for arguments whose types [`call_type`] would have refused.
fn unchecked(name: &str, args: &[Val]) -> EvalError {
    let tys: Vec<String> = args.iter().map(|v| v.ty().name()).collect();
    err(format!(
        "internal error: `{name}` evaluated on ({}) (types not checked)",
        tys.join(", ")
    ))
}

/// A `num` argument as a real.
fn real(v: &Val) -> Option<f64> {
    v.as_f64()
}

/// The scalars of a vector or column.
fn col(v: &Val) -> Option<&[f64]> {
    match v {
        Val::V2(x) => Some(x),
        Val::V3(x) => Some(x),
        Val::M(m) if m.cols == 1 => Some(&m.data),
        _ => None,
    }
}

/// A value of the same vector or column type as `like`, from its scalars.
fn col_like(like: &Val, x: &[f64]) -> Val {
    Val::from_reals(like.ty(), x)
}

/// An `i64` index checked against `0..len`.
fn index(name: &str, what: &str, i: i64, len: usize) -> Result<usize, EvalError> {
    usize::try_from(i)
        .ok()
        .filter(|&k| k < len)
        .ok_or_else(|| err(format!("{name}: {what} {i} out of range 0..{len}")))
}

fn mat_of(rows: usize, cols: usize, data: Vec<f64>) -> Val {
    Val::M(Mat { rows, cols, data })
}

fn mat_rows<const R: usize, const C: usize>(rows: [[f64; C]; R]) -> Mat {
    Mat {
        rows: R,
        cols: C,
        data: rows.concat(),
    }
}

/// Evaluates a built-in (argument types already checked by [`call_type`]).
pub fn call(name: &str, args: &[Val]) -> Result<Val, EvalError> {
    match eval(name, args)? {
        Some(v) => Ok(v),
        None if signature(name).is_none() => Err(err(unknown(name))),
        None => Err(unchecked(name, args)),
    }
}

/// Evaluation: `Ok(None)` when the arguments do not fit.
fn eval(name: &str, args: &[Val]) -> Result<Option<Val>, EvalError> {
    use Val::{B, F, I, M, V2, V3};
    if let Some(v) = crate::mechanics::eval(name, args)? {
        return Ok(Some(v));
    }
    let nums: Option<Vec<f64>> = args.iter().map(real).collect();
    let v = match (name, args) {
        ("vec2", [_, _]) => nums.map(|x| V2([x[0], x[1]])),
        ("vec3", [_, _, _]) => nums.map(|x| V3([x[0], x[1], x[2]])),
        ("mat2", [_, _, _, _]) => nums.map(|x| mat_of(2, 2, x)),
        ("mat3", [_, _, _, _, _, _, _, _, _]) => nums.map(|x| mat_of(3, 3, x)),
        ("mat_from_rows2", [V2(a), V2(b)]) => Some(M(mat_rows([*a, *b]))),
        ("mat_from_cols2", [V2(a), V2(b)]) => Some(M(mat_rows([*a, *b]).transpose())),
        ("mat_from_rows3", [V3(a), V3(b), V3(c)]) => Some(M(mat_rows([*a, *b, *c]))),
        ("mat_from_cols3", [V3(a), V3(b), V3(c)]) => Some(M(mat_rows([*a, *b, *c]).transpose())),
        ("identity2", []) => Some(M(Mat::identity(2))),
        ("identity3", []) => Some(M(Mat::identity(3))),
        ("zeros2", []) => Some(M(Mat::zeros(2, 2))),
        ("zeros3", []) => Some(M(Mat::zeros(3, 3))),
        ("zeros6", []) => Some(M(Mat::zeros(6, 6))),
        ("zeros6x1", []) => Some(M(Mat::zeros(6, 1))),
        ("zeros12", []) => Some(M(Mat::zeros(12, 12))),
        ("zeros12x1", []) => Some(M(Mat::zeros(12, 1))),
        ("x", [V2([x, _]) | V3([x, _, _])])
        | ("y", [V2([_, x]) | V3([_, x, _])])
        | ("z", [V3([_, _, x])]) => Some(F(*x)),
        ("elem", [v, I(i)]) => match col(v) {
            Some(x) => Some(F(x[index(name, "index", *i, x.len())?])),
            None => None,
        },
        ("get", [m, I(i), I(j)]) => get(m, *i, *j)?,
        ("set", [m, I(i), I(j), x]) => match real(x) {
            Some(x) => set(m, *i, *j, x)?,
            None => None,
        },
        ("row2" | "row3", [M(m), I(i)]) if m.cols == name_k(name) => {
            let i = index(name, "row", *i, m.rows)?;
            Some(col_val(&m.data[i * m.cols..(i + 1) * m.cols]))
        }
        ("col2" | "col3", [M(m), I(j)]) if m.rows == name_k(name) => {
            let j = index(name, "column", *j, m.cols)?;
            let x: Vec<f64> = (0..m.rows).map(|i| m.get(i, j)).collect();
            Some(col_val(&x))
        }
        ("block2" | "block3", [M(m), I(i), I(j)]) => {
            let k = name_k(name);
            let (bi, bj) = block_index(name, m, k, *i, *j)?;
            let mut b = Mat::zeros(k, k);
            for r in 0..k {
                for c in 0..k {
                    b.set(r, c, m.get(bi + r, bj + c));
                }
            }
            Some(M(b))
        }
        ("set_block2" | "set_block3", [M(m), I(i), I(j), M(b)])
            if b.rows == name_k(name) && b.cols == b.rows =>
        {
            let k = name_k(name);
            let (bi, bj) = block_index(name, m, k, *i, *j)?;
            let mut out = m.clone();
            for r in 0..k {
                for c in 0..k {
                    out.set(bi + r, bj + c, b.get(r, c));
                }
            }
            Some(M(out))
        }
        ("vecn_get2" | "vecn_get3", [M(v), I(i)]) if v.cols == 1 => {
            let k = name_k(name);
            let i = index(name, "node", *i, v.rows / k)?;
            Some(col_val(&v.data[k * i..k * i + k]))
        }
        ("vecn_set2" | "vecn_set3", [M(v), I(i), x]) if v.cols == 1 => match col(x) {
            Some(x) if x.len() == name_k(name) => {
                let k = x.len();
                let i = index(name, "node", *i, v.rows / k)?;
                let mut out = v.clone();
                out.data[k * i..k * i + k].copy_from_slice(x);
                Some(M(out))
            }
            _ => None,
        },
        ("to_f64", [x]) => match x {
            B(b) => Some(F(if *b { 1.0 } else { 0.0 })),
            x => real(x).map(F),
        },
        ("to_i64", [x]) => match x {
            I(i) => Some(I(*i)),
            B(b) => Some(I(i64::from(*b))),
            F(x) => Some(I(to_i64(*x)?)),
            _ => None,
        },
        ("abs", [I(i)]) => Some(I(i
            .checked_abs()
            .ok_or_else(|| err(format!("abs: |{i}| is not an i64")))?)),
        ("sign", [I(i)]) => Some(I(i.signum())),
        ("min", [I(a), I(b)]) => Some(I(*a.min(b))),
        ("max", [I(a), I(b)]) => Some(I(*a.max(b))),
        ("clamp", [I(x), I(lo), I(hi)]) => {
            if lo > hi {
                return Err(err(format!(
                    "clamp: lower bound {lo} above upper bound {hi}"
                )));
            }
            Some(I(*x.max(lo).min(hi)))
        }
        ("select", [B(c), a, b]) => Some(select(*c, a, b)),
        ("is_finite", [x]) => Some(B(is_finite(x))),
        ("dot", [a, b]) => match (col(a), col(b)) {
            (Some(x), Some(y)) if x.len() == y.len() => Some(F(dot(x, y))),
            _ => None,
        },
        ("cross", [V3(a), V3(b)]) => Some(V3(cross(a, b))),
        ("cross", [V2(a), V2(b)]) => Some(F(diff_of_products(a[0], b[1], a[1], b[0]))),
        ("norm", [v]) => col(v).map(|x| F(norm(x))),
        ("norm2", [v]) => col(v).map(|x| F(dot(x, x))),
        ("normalize", [v]) => col(v).map(|x| col_like(v, &normalize(x))),
        ("outer", [a, b]) => match (col(a), col(b)) {
            (Some(x), Some(y)) => {
                let data = x.iter().flat_map(|&p| y.iter().map(move |&q| p * q));
                Some(mat_of(x.len(), y.len(), data.collect()))
            }
            _ => None,
        },
        ("angle", [V2(a), V2(b)]) => Some(F(angle(a, b))),
        ("angle", [V3(a), V3(b)]) => Some(F(angle(a, b))),
        ("transpose", [M(m)]) => Some(M(m.transpose())),
        ("frobenius", [M(m)]) => Some(F(norm_scaled(&m.data))),
        ("trace", [M(m)]) if m.rows == m.cols => Some(F((0..m.rows).map(|i| m.get(i, i)).sum())),
        ("det", [M(m)]) if m.rows == m.cols => Some(F(det(m))),
        ("inverse", [M(m)]) if m.rows == m.cols => Some(M(inverse(m)?)),
        ("sym", [M(m)]) if m.rows == m.cols => Some(M(sym(m))),
        ("segment_hits_triangle", [V3(a), V3(b), V3(p), V3(q), V3(r)]) => {
            Some(B(segment_hits_triangle(a, b, p, q, r)))
        }
        ("polar", [M(m)]) if m.rows == 2 && m.cols == 2 => Some(M(polar2(m)?)),
        ("polar", [M(m)]) if m.rows == 3 && m.cols == 3 => Some(M(polar3(m)?)),
        ("eigvals_sym2", [M(m)]) if m.rows == 2 && m.cols == 2 => Some(V2(eigvals_sym2(m))),
        ("eigvals_sym3", [M(m)]) if m.rows == 3 && m.cols == 3 => Some(V3(eigvals_sym3(m)?)),
        (
            "abs" | "sign" | "sqrt" | "exp" | "log" | "sin" | "cos" | "tan" | "asin" | "acos"
            | "atan" | "floor" | "ceil",
            [_],
        ) => nums.map(|x| F(scalar1(name, x[0]))),
        ("atan2" | "pow" | "min" | "max", [_, _]) => nums.map(|x| F(scalar2(name, x[0], x[1]))),
        ("clamp", [_, _, _]) => match nums {
            Some(x) => Some(F(clamp(x[0], x[1], x[2])?)),
            None => None,
        },
        _ => None,
    };
    Ok(v)
}

/// The block size in a name ending in `2` or `3`.
fn name_k(name: &str) -> usize {
    if name.ends_with('2') {
        2
    } else {
        3
    }
}

/// A `vec2` or `vec3` from 2 or 3 scalars.
fn col_val(x: &[f64]) -> Val {
    match *x {
        [a, b] => Val::V2([a, b]),
        [a, b, c] => Val::V3([a, b, c]),
        _ => Val::M(Mat {
            rows: x.len(),
            cols: 1,
            data: x.to_vec(),
        }),
    }
}

/// The first row and column of block `(i, j)` of size `k`.
fn block_index(name: &str, m: &Mat, k: usize, i: i64, j: i64) -> Result<(usize, usize), EvalError> {
    let (p, q) = (m.rows / k, m.cols / k);
    let bad = || {
        err(format!(
            "{name}: block ({i}, {j}) outside the {p}x{q} blocks of a {}x{} matrix",
            m.rows, m.cols
        ))
    };
    let bi = usize::try_from(i).ok().filter(|&b| b < p).ok_or_else(bad)?;
    let bj = usize::try_from(j).ok().filter(|&b| b < q).ok_or_else(bad)?;
    Ok((bi * k, bj * k))
}

/// `get(m, i, j)`; a vector is a column.
fn get(m: &Val, i: i64, j: i64) -> Result<Option<Val>, EvalError> {
    let (rows, cols, data): (usize, usize, &[f64]) = match m {
        Val::M(m) => (m.rows, m.cols, &m.data),
        v => match col(v) {
            Some(x) => (x.len(), 1, x),
            None => return Ok(None),
        },
    };
    let (i, j) = entry_index("get", m, i, j, rows, cols)?;
    Ok(Some(Val::F(data[i * cols + j])))
}

/// `set(m, i, j, x)`; a vector is a column.
fn set(m: &Val, i: i64, j: i64, x: f64) -> Result<Option<Val>, EvalError> {
    let mut out = m.clone();
    let (rows, cols, data): (usize, usize, &mut [f64]) = match &mut out {
        Val::M(m) => (m.rows, m.cols, &mut m.data),
        Val::V2(v) => (2, 1, v),
        Val::V3(v) => (3, 1, v),
        _ => return Ok(None),
    };
    let (i, j) = entry_index("set", m, i, j, rows, cols)?;
    data[i * cols + j] = x;
    Ok(Some(out))
}

fn entry_index(
    name: &str,
    m: &Val,
    i: i64,
    j: i64,
    rows: usize,
    cols: usize,
) -> Result<(usize, usize), EvalError> {
    let bad = || err(format!("{name}: entry ({i}, {j}) outside a {}", m.ty()));
    let i = usize::try_from(i)
        .ok()
        .filter(|&i| i < rows)
        .ok_or_else(bad)?;
    let j = usize::try_from(j)
        .ok()
        .filter(|&j| j < cols)
        .ok_or_else(bad)?;
    Ok((i, j))
}

/// Truncation toward zero, refusing what has no `i64` value.
fn to_i64(x: f64) -> Result<i64, EvalError> {
    // 2^63: the first real above the i64 range; -2^63 is i64::MIN.
    const TWO_63: f64 = 9_223_372_036_854_775_808.0;
    let t = x.trunc();
    if t.is_finite() && (-TWO_63..TWO_63).contains(&t) {
        Ok(t as i64)
    } else {
        // (in scientific notation: 1e300 written out is 301 digits)
        Err(err(format!(
            "to_i64: {x:e} has no i64 value (it is outside -2^63..2^63 or not finite)"
        )))
    }
}

// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn scalar1(name: &str, x: f64) -> f64 {
    match name {
        "abs" => x.abs(),
        "sign" => {
            if x > 0.0 {
                1.0
            } else if x < 0.0 {
                -1.0
            } else {
                // 0 for ±0, NaN for NaN.
                x * 0.0
            }
        }
        "sqrt" => x.sqrt(),
        "exp" => x.exp(),
        "log" => x.ln(),
        "sin" => x.sin(),
        "cos" => x.cos(),
        "tan" => x.tan(),
        "asin" => x.asin(),
        "acos" => x.acos(),
        "atan" => x.atan(),
        "floor" => x.floor(),
        _ => x.ceil(),
    }
}

// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn scalar2(name: &str, a: f64, b: f64) -> f64 {
    match name {
        "atan2" => a.atan2(b),
        "pow" => a.powf(b),
        _ if a.is_nan() || b.is_nan() => f64::NAN,
        "min" => a.min(b),
        _ => a.max(b),
    }
}

/// `x` limited to `[lo, hi]`, propagating NaN.
fn clamp(x: f64, lo: f64, hi: f64) -> Result<f64, EvalError> {
    if x.is_nan() || lo.is_nan() || hi.is_nan() {
        return Ok(f64::NAN);
    }
    if lo > hi {
        return Err(err(format!(
            "clamp: lower bound {lo} above upper bound {hi}"
        )));
    }
    Ok(x.max(lo).min(hi))
}

fn select(c: bool, a: &Val, b: &Val) -> Val {
    let chosen = if c { a } else { b };
    match (chosen, a.ty() == b.ty()) {
        (Val::I(i), false) => Val::F(*i as f64),
        (v, _) => v.clone(),
    }
}

fn is_finite(x: &Val) -> bool {
    match x {
        Val::F(x) => x.is_finite(),
        Val::I(_) | Val::B(_) => true,
        Val::V2(v) => v.iter().all(|x| x.is_finite()),
        Val::V3(v) => v.iter().all(|x| x.is_finite()),
        Val::M(m) => m.data.iter().all(|x| x.is_finite()),
    }
}

// ---------------------------------------------------------------------------------------------
// Vector and matrix algebra.

// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn dot(x: &[f64], y: &[f64]) -> f64 {
    x.iter().zip(y).map(|(a, b)| a * b).sum()
}

/// `a * b - c * d` with one rounding error instead of two (Kahan's algorithm with a fused
/// multiply-add).
// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn diff_of_products(a: f64, b: f64, c: f64, d: f64) -> f64 {
    let w = c * d;
    let e = (-c).mul_add(d, w);
    let f = a.mul_add(b, -w);
    f + e
}

// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        diff_of_products(a[1], b[2], a[2], b[1]),
        diff_of_products(a[2], b[0], a[0], b[2]),
        diff_of_products(a[0], b[1], a[1], b[0]),
    ]
}

/// The largest absolute value, NaN if any entry is NaN.
fn max_abs(x: &[f64]) -> f64 {
    x.iter().fold(0.0_f64, |m, &v| {
        if v.is_nan() || m.is_nan() {
            f64::NAN
        } else {
            m.max(v.abs())
        }
    })
}

/// The smallest sum of squares [`norm`] takes the square root of directly: `2^-960`. Above
/// it, a square that underflowed (below `2^-1022`, so off by at most `2^-1075`) changes the
/// sum by less than `2^-115` of it, far below the sum's own rounding.
// 2^-960: biased exponent 1023 - 960 = 63, mantissa 0
// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub const NORM_DIRECT_MIN: f64 = f64::from_bits(63 << 52);

/// The Euclidean norm of the built-in `norm`: `sqrt(x0^2 + x1^2 + ...)` (the squares summed
/// in order, as `Iterator::sum` does) where that sum is finite and at least
/// [`NORM_DIRECT_MIN`]: no square overflowed (they are not negative, so one infinite square
/// makes the sum infinite) and none that underflowed matters; the result is then within
/// about `(n/2 + 1)` ulps, like the scaled form. Elsewhere (huge, tiny, zero, non-finite
/// entries) it is [`norm_scaled`]. Direct, it costs a square root; scaled, a division per
/// entry more.
// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn norm(x: &[f64]) -> f64 {
    let s = x.iter().map(|v| v * v).sum::<f64>();
    if (NORM_DIRECT_MIN..=f64::MAX).contains(&s) {
        return s.sqrt();
    }
    norm_scaled(x)
}

/// Euclidean norm, scaled by the largest entry so that it neither overflows nor underflows.
// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn norm_scaled(x: &[f64]) -> f64 {
    let m = max_abs(x);
    if m == 0.0 || !m.is_finite() {
        return m;
    }
    m * x.iter().map(|v| (v / m) * (v / m)).sum::<f64>().sqrt()
}

/// `x / |x|`, the zero vector for a zero input.
pub(crate) fn normalize(x: &[f64]) -> Vec<f64> {
    let m = max_abs(x);
    if m == 0.0 {
        return x.iter().map(|_| 0.0).collect();
    }
    // Scale first: the norm of huge or tiny entries stays representable.
    let y: Vec<f64> = x.iter().map(|v| v / m).collect();
    let n = norm_scaled(&y);
    y.iter().map(|v| v / n).collect()
}

/// [`normalize`] into `z` (of `x`'s length), without allocating.
// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn normalize_into(x: &[f64], z: &mut [f64]) {
    let m = max_abs(x);
    if m == 0.0 {
        z.fill(0.0);
        return;
    }
    for (zi, v) in z.iter_mut().zip(x) {
        *zi = v / m;
    }
    let n = norm_scaled(z);
    for zi in z.iter_mut() {
        *zi /= n;
    }
}

/// Unsigned angle `atan2(|a x b|, a . b)`, each vector first scaled by its largest entry.
fn angle<const N: usize>(a: &[f64; N], b: &[f64; N]) -> f64 {
    let scale = |v: &[f64; N]| {
        let m = max_abs(v);
        if m > 0.0 && m.is_finite() {
            v.map(|x| x / m)
        } else {
            *v
        }
    };
    let (a, b) = (scale(a), scale(b));
    let sin = match (a.as_slice(), b.as_slice()) {
        (&[a0, a1, a2], &[b0, b1, b2]) => norm_scaled(&cross(&[a0, a1, a2], &[b0, b1, b2])),
        (&[a0, a1], &[b0, b1]) => diff_of_products(a0, b1, a1, b0).abs(),
        _ => f64::NAN,
    };
    sin.atan2(dot(&a, &b))
}

fn sym(m: &Mat) -> Mat {
    let t = m.transpose();
    Mat {
        rows: m.rows,
        cols: m.cols,
        data: m
            .data
            .iter()
            .zip(&t.data)
            .map(|(a, b)| 0.5 * a + 0.5 * b)
            .collect(),
    }
}

/// Determinant: closed forms up to 3x3, LU with partial pivoting above.
fn det(m: &Mat) -> f64 {
    let a = &m.data;
    match m.rows {
        0 => 1.0,
        1 => a[0],
        2 => diff_of_products(a[0], a[3], a[1], a[2]),
        3 => {
            a[0] * diff_of_products(a[4], a[8], a[5], a[7])
                - a[1] * diff_of_products(a[3], a[8], a[5], a[6])
                + a[2] * diff_of_products(a[3], a[7], a[4], a[6])
        }
        n => {
            let mut a = a.clone();
            let mut d = 1.0;
            for k in 0..n {
                let p = pivot_row(&a, n, k);
                if a[p * n + k] == 0.0 {
                    return 0.0;
                }
                if p != k {
                    swap_rows(&mut a, n, p, k);
                    d = -d;
                }
                let piv = a[k * n + k];
                d *= piv;
                for i in k + 1..n {
                    let f = a[i * n + k] / piv;
                    for j in k..n {
                        a[i * n + j] -= f * a[k * n + j];
                    }
                }
            }
            d
        }
    }
}

/// The row `>= k` with the largest entry in column `k` (NaN entries are never chosen).
fn pivot_row(a: &[f64], n: usize, k: usize) -> usize {
    let mut p = k;
    for i in k + 1..n {
        if a[i * n + k].abs() > a[p * n + k].abs() {
            p = i;
        }
    }
    p
}

fn swap_rows(a: &mut [f64], n: usize, p: usize, k: usize) {
    for j in 0..n {
        a.swap(p * n + j, k * n + j);
    }
}

/// The smallest pivot magnitude accepted by `inverse`.
const MIN_PIVOT: f64 = 1e-300;

/// Inverse by Gauss-Jordan elimination with partial pivoting.
fn inverse(m: &Mat) -> Result<Mat, EvalError> {
    let n = m.rows;
    if !m.data.iter().all(|x| x.is_finite()) {
        return Err(err(format!(
            "inverse: the {n}x{n} matrix has non-finite entries"
        )));
    }
    let mut a = m.data.clone();
    let mut inv = Mat::identity(n).data;
    for k in 0..n {
        let p = pivot_row(&a, n, k);
        let piv = a[p * n + k];
        if piv.abs() < MIN_PIVOT {
            return Err(err(format!(
                "inverse: the {n}x{n} matrix is singular (pivot {piv:e} in column {k})"
            )));
        }
        swap_rows(&mut a, n, p, k);
        swap_rows(&mut inv, n, p, k);
        for j in 0..n {
            a[k * n + j] /= piv;
            inv[k * n + j] /= piv;
        }
        for i in (0..n).filter(|&i| i != k) {
            let f = a[i * n + k];
            if f != 0.0 {
                for j in 0..n {
                    a[i * n + j] -= f * a[k * n + j];
                    inv[i * n + j] -= f * inv[k * n + j];
                }
            }
        }
    }
    if inv.iter().all(|x| x.is_finite()) {
        Ok(Mat {
            rows: n,
            cols: n,
            data: inv,
        })
    } else {
        Err(err(format!(
            "inverse: the {n}x{n} matrix is singular to working precision (its inverse overflows)"
        )))
    }
}

fn require_finite(name: &str, m: &Mat) -> Result<(), EvalError> {
    require_finite_data(name, m.rows, m.cols, &m.data)
}

fn require_finite_data(name: &str, rows: usize, cols: usize, m: &[f64]) -> Result<(), EvalError> {
    if m.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(err(format!(
            "{name}: the {rows}x{cols} matrix has non-finite entries"
        )))
    }
}

/// The closest rotation to a 2x2 matrix: the angle maximizing
/// `tr(R^T m) = cos t (m00 + m11) + sin t (m10 - m01)`, in closed form.
/// When no rotation is closer than another (`m = [[a, b], [b, -a]]`), the identity.
fn polar2(m: &Mat) -> Result<Mat, EvalError> {
    polar2_data(&m.data).map(|r| mat_rows([[r[0], r[1]], [r[2], r[3]]]))
}

/// [`polar2`] on the 4 row-major entries of a 2x2 matrix, without allocating.
// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn polar2_data(a: &[f64]) -> Result<[f64; 4], EvalError> {
    require_finite_data("polar", 2, 2, a)?;
    // Scale first: the sums below must not overflow.
    let s = max_abs(a);
    if s == 0.0 {
        return Ok([1.0, 0.0, 0.0, 1.0]);
    }
    let (c, d) = (
        a[0] / s + a[3] / s, // tr(m) / s
        a[2] / s - a[1] / s, // (m10 - m01) / s
    );
    // The maximizing angle is atan2(d, c); its cosine and sine directly, without the angle.
    let h = c.hypot(d);
    if h == 0.0 {
        return Ok([1.0, 0.0, 0.0, 1.0]);
    }
    let (cos, sin) = (c / h, d / h);
    Ok([cos, -sin, sin, cos])
}

/// The closest rotation to a 3x3 matrix: [`polar3_newton`] where it applies (`det m > 0`,
/// condition number at most about [`NEWTON_MAX_COND`]: almost every element of a
/// co-rotational simulation), else [`polar3_jacobi`] (inverted, flat, nearly singular,
/// extreme scales). Both give the same rotation to rounding: their entries differ by a few
/// `eps s1 / (s2 + s3)` (singular values `s1 >= s2 >= s3`), the conditioning of the rotation
/// itself (see the `polar_newton_*` tests).
fn polar3(m: &Mat) -> Result<Mat, EvalError> {
    polar3_data(&m.data).map(|r| Mat {
        rows: 3,
        cols: 3,
        data: r.to_vec(),
    })
}

/// [`polar3`] on the 9 row-major entries of a 3x3 matrix, without allocating.
// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn polar3_data(m: &[f64]) -> Result<[f64; 9], EvalError> {
    require_finite_data("polar", 3, 3, m)?;
    if max_abs(m) == 0.0 {
        return Ok([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    }
    Ok(polar3_newton(m).map_or_else(|| polar3_jacobi(m), |(r, _)| r))
}

/// The largest condition number `K` for which [`polar3_newton`] is used (see
/// [`newton_applies`]). Newton's first step inverts `X` through its cofactors, which is not
/// backward stable: the result's backward error, measured by the asymmetry of `R^T m`
/// (exactly symmetric for the exact polar factor), grows in proportion to the condition
/// number (measured maxima: 3-5 eps below condition 100, 34 eps in [1e2, 1e3), 3.3e3 eps in
/// [1e4, 1e5), 3.1e4 eps in [1e5, 1e6)), while the Jacobi SVD's stays at 3-5 eps throughout. The entries of R still agree with Jacobi's to a few
/// `eps s1 / (s2 + s3)` up to condition 1e14, but 100 keeps both measures at the level of
/// Jacobi's rounding; co-rotational elements beyond it are degenerate and rare, and Jacobi
/// costs them ~4x more.
const NEWTON_MAX_COND: f64 = 100.0;

/// Newton steps are scaled while `|X_k|_F^2 > 3 + SCALING_OFF` (and always the first).
/// After any step every singular value is at least 1 (`(y + 1/y) / 2 >= 1`), so
/// `|X_k|_F^2 - 3 = sum (s^2 - 1) <= 1` means every `s <= sqrt 2`, from where unscaled steps
/// converge in 4-5 iterations, each a division cheaper than a scaled one (measured fastest
/// on FEM-like matrices against Higham's switch at `|X_{k+1} - X_k|_F <= 1e-2` and against
/// scaling the first step only, which takes many more steps for ill-conditioned input).
const SCALING_OFF: f64 = 1.0;

/// The rotation of the polar decomposition of a finite, non-zero 3x3 matrix with `det m > 0`
/// and condition number at most about [`NEWTON_MAX_COND`], by Newton's iteration with
/// Frobenius-norm scaling (N. J. Higham, "Computing the polar decomposition -- with
/// applications", SIAM J. Sci. Stat. Comput. 7 (1986), 1160-1174, doi:10.1137/0907079):
/// `X_{k+1} = (g X_k + (g X_k)^{-T}) / 2`, `g = (|X_k^{-1}|_F / |X_k|_F)^{1/2}`, from `X_0 = m`
/// multiplied by a power of two (exact: the result does not depend on such a factor) that
/// brings its largest entry into [1, 2). `X^{-T}` is the cofactor matrix `C` over `det X`,
/// on fixed-size arrays; `g` and `1 / (g det X)` come from one division and two square roots.
/// For `det m > 0` the limit is the rotation `U V^T` of `m = U S V^T`: each step maps every
/// singular value `s` to `(g s + 1 / (g s)) / 2` and keeps `U` and `V`, so `det X_k > 0`
/// throughout, and convergence is quadratic.
///
/// Stopping: an unscaled step maps `s` to `s' = (s + 1/s) / 2`, and with `d = |s' - s|`
/// (that singular value's part of `|X_{k+1} - X_k|_F`, the norm being invariant under
/// `U` and `V`), `s' - 1 = d |s - 1| / (s + 1) <= d^2 / 2`. So the iteration stops after an
/// unscaled step with `|X_{k+1} - X_k|_F^2 <= eps`: the singular values of `X_{k+1}` are
/// within `eps / 2` of 1 in exact arithmetic, and what remains is the last step's rounding.
/// This saves the step a stop at `|X_{k+1} - X_k| ~ eps` would take. Measured: 2 iterations
/// for a rotation, at most 4 for small strains (principal stretches within 2% of 1), 5 for
/// principal stretches in [0.7, 1.4], 7 up to the condition threshold (and still 7 at
/// condition 1e14).
///
/// `None` (the caller falls back to Jacobi) when [`newton_applies`] refuses `X_0`
/// (`det m <= 0`, or condition above about [`NEWTON_MAX_COND`]), when the largest entry is
/// below 2^-1022 or at least 2^1023 (no exact power-of-two normalization), or when 20
/// iterations do not converge (never observed). The iteration count comes with the result
/// for the tests.
fn polar3_newton(m: &[f64]) -> Option<([f64; 9], u32)> {
    // 2^-e for the largest entry 2^e * 1.f: the scaled entries are below 2 in magnitude.
    let biased = max_abs(m).to_bits() >> 52;
    if !(1..2046).contains(&biased) {
        return None;
    }
    let scale = f64::from_bits((2046 - biased) << 52);
    let mut x = [0.0; 9];
    for (xi, mi) in x.iter_mut().zip(m) {
        *xi = mi * scale;
    }
    let mut nx = sum_sq9(&x);
    let mut scaled = true;
    for k in 0..20 {
        let c = cofactors3(&x);
        let d = x[0] * c[0] + x[1] * c[1] + x[2] * c[2];
        let (a, b) = if scaled {
            let nc = sum_sq9(&c);
            // With w = 1 / (|X|_F^2 |C|_F^2 d^2) (one division): g^2 = |C|_F / (|X|_F d)
            // = |C|_F^2 sqrt(w) and 1 / (g d) = g |X|_F^2 d sqrt(w).
            let w = 1.0 / (nx * nc * (d * d));
            if k == 0 && !newton_applies(nx, nc, d) {
                return None;
            }
            let sw = w.sqrt();
            let g = (nc * sw).sqrt();
            (0.5 * g, 0.5 * g * (nx * d * sw))
        } else {
            (0.5, 0.5 / d)
        };
        let mut step = [0.0; 3];
        let mut norm = [0.0; 3];
        for (i, (xi, ci)) in x.iter_mut().zip(&c).enumerate() {
            let y = a * *xi + b * ci;
            let e = y - *xi;
            step[i % 3] += e * e;
            norm[i % 3] += y * y;
            *xi = y;
        }
        let step = step[0] + step[1] + step[2];
        nx = norm[0] + norm[1] + norm[2];
        if !scaled && step <= f64::EPSILON {
            return Some((x, k + 1));
        }
        scaled = nx > 3.0 + SCALING_OFF;
    }
    None
}

/// Whether [`polar3_newton`] may start from `X` with `|X|_F^2 = nx`, cofactor matrix `C` with
/// `|C|_F^2 = nc`, and computed determinant `d` (`X` scaled so that its largest entry is in
/// [1, 2)). Two tests, both without division (`d * d` underflowing to 0 fails them):
/// - `det X` relative to `|X|_F^3`: `27 K^4 d^2 >= nx^3`. It holds for every `X` of condition
///   number `s1 / s3 <= K` (then `d = s1 s2 s3 >= s1^3 / K^2` and `nx <= 3 s1^2`), and it
///   certifies that `d` and `C` are not rounding noise: their absolute errors are a few `eps`
///   times `|X|_F^3` and `|X|_F^2`, so `d` is then exact to about `5 eps K^2` relative (its
///   sign is right) and `C` to about `eps K`. (A rank-1 `X` has cofactors and determinant
///   made of rounding errors alone, which can pass the next test by accident.)
/// - the condition estimate `|X|_F |X^-1|_F = |X|_F |C|_F / d <= K`, which lies between the
///   condition number and 3 times it.
fn newton_applies(nx: f64, nc: f64, d: f64) -> bool {
    const K2: f64 = NEWTON_MAX_COND * NEWTON_MAX_COND;
    let d2 = d * d;
    d > 0.0 && nx * nx * nx <= 27.0 * K2 * K2 * d2 && nx * nc <= K2 * d2
}

/// The cofactor matrix of a row-major 3x3 matrix (`det x` times `x^{-T}`), plain products.
fn cofactors3(x: &[f64; 9]) -> [f64; 9] {
    [
        x[4] * x[8] - x[5] * x[7],
        x[5] * x[6] - x[3] * x[8],
        x[3] * x[7] - x[4] * x[6],
        x[2] * x[7] - x[1] * x[8],
        x[0] * x[8] - x[2] * x[6],
        x[1] * x[6] - x[0] * x[7],
        x[1] * x[5] - x[2] * x[4],
        x[2] * x[3] - x[0] * x[5],
        x[0] * x[4] - x[1] * x[3],
    ]
}

/// The sum of squares of 9 entries, in three interleaved partial sums (shorter latency).
fn sum_sq9(x: &[f64; 9]) -> f64 {
    let mut s = [0.0; 3];
    for (i, v) in x.iter().enumerate() {
        s[i % 3] += v * v;
    }
    s[0] + s[1] + s[2]
}

/// The closest rotation to a finite, non-zero 3x3 matrix, by a one-sided Jacobi SVD
/// `m = U S V^T`: `R = U V^T` with `det U = det V = +1`, the sign of the smallest singular
/// value carrying `det m` (Irving et al. 2004). Rank-deficient input still gives a rotation:
/// missing left singular directions are completed orthogonally.
fn polar3_jacobi(m: &[f64]) -> [f64; 9] {
    let s = max_abs(m);
    // Columns of A = (m / s) V, and of V.
    let mut a = [[0.0; 3]; 3];
    for (j, col) in a.iter_mut().enumerate() {
        for (i, x) in col.iter_mut().enumerate() {
            *x = m[3 * i + j] / s;
        }
    }
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..64 {
        let mut rotated = false;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let alpha = dot(&a[p], &a[p]);
            let beta = dot(&a[q], &a[q]);
            let gamma = dot(&a[p], &a[q]);
            if gamma == 0.0 || gamma.abs() <= f64::EPSILON * alpha.sqrt() * beta.sqrt() {
                continue;
            }
            rotated = true;
            // The rotation making columns p and q orthogonal (Hestenes 1958). `sqrt(1 + x^2)`
            // rather than `hypot`, which is several times slower: |t| <= 1 cannot overflow,
            // and where zeta^2 overflows (|zeta| > 1e154) t is 0 instead of below 1e-154:
            // c is 1 either way and sn differs by less than 1e-154.
            let zeta = (beta - alpha) / (2.0 * gamma);
            let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
            let c = 1.0 / (1.0 + t * t).sqrt();
            let sn = c * t;
            for w in [&mut a, &mut v] {
                let (x, y) = (w[p], w[q]);
                w[p] = [0, 1, 2].map(|i| c * x[i] - sn * y[i]);
                w[q] = [0, 1, 2].map(|i| sn * x[i] + c * y[i]);
            }
        }
        if !rotated {
            break;
        }
    }
    // Order by decreasing singular value.
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| norm_scaled(&a[j]).total_cmp(&norm_scaled(&a[i])));
    let a = order.map(|k| a[k]);
    let mut v = order.map(|k| v[k]);
    if det3_cols(&v) < 0.0 {
        v[2] = v[2].map(|x| -x);
    }
    // U with det +1: u3 follows from u1 and u2, so its sign carries det m.
    let u1 = unit_or(&a[0], [1.0, 0.0, 0.0]);
    let mut w = a[1];
    for _ in 0..2 {
        let d = dot(&u1, &w);
        w = [w[0] - d * u1[0], w[1] - d * u1[1], w[2] - d * u1[2]];
    }
    let u2 = if norm_scaled(&w) > 1e-290 {
        unit_or(&w, perpendicular(&u1))
    } else {
        perpendicular(&u1)
    };
    let u3 = unit_or(&cross(&u1, &u2), [0.0, 0.0, 1.0]);
    // R = U V^T = sum over k of u_k v_k^T.
    let mut r = [0.0; 9];
    for (uk, vk) in [u1, u2, u3].iter().zip(&v) {
        for (i, ui) in uk.iter().enumerate() {
            for (j, vj) in vk.iter().enumerate() {
                r[3 * i + j] += ui * vj;
            }
        }
    }
    r
}

/// Whether the segment `a b` crosses the closed triangle `p q r`: Moeller & Trumbore, "Fast,
/// minimum storage ray-triangle intersection", J. Graphics Tools 2 (1997),
/// doi:10.1080/10867651.1997.10487468, restricted to the open range (0, 1) of the segment's
/// parameter. Barycentric coordinates are accepted within `1e-12` of their range (relative:
/// they are ratios), so a segment through an edge or a vertex of the triangle crosses it; the
/// segment parameter must lie `1e-12` inside (0, 1), so an end on the triangle's plane (or
/// within 1e-12 of the segment's length of it) does not: like the plane cut, which separates
/// two centroids only when they lie strictly on opposite sides, a centroid on the blade's
/// plane is on neither side, and the faces on both sides of it stay. A segment parallel to
/// the plane (within `1e-12` of the product of the lengths), a zero-length segment, a flat
/// triangle and any non-finite coordinate give false.
// For the sibling crates (topomech-engine, topomech-codegen) only.
#[doc(hidden)]
pub fn segment_hits_triangle(
    a: &[f64; 3],
    b: &[f64; 3],
    p: &[f64; 3],
    q: &[f64; 3],
    r: &[f64; 3],
) -> bool {
    const TOL: f64 = 1e-12;
    if [a, b, p, q, r]
        .iter()
        .any(|v| v.iter().any(|x| !x.is_finite()))
    {
        return false;
    }
    let sub = |u: &[f64; 3], v: &[f64; 3]| [u[0] - v[0], u[1] - v[1], u[2] - v[2]];
    let (mut d, mut e1, mut e2, mut s) = (sub(b, a), sub(q, p), sub(r, p), sub(a, p));
    // The differences scaled by one power of two, their largest component to about 1: the
    // test is the same for every scale (u, v and t are ratios, the tolerances relative) and
    // a power of two scales exactly, so the answer is unchanged where nothing under- or
    // overflows, and the products of three differences neither underflow (a body of
    // coordinates about 1e-110 crossed nothing: QA) nor overflow.
    let largest = [d, e1, e2, s]
        .iter()
        .flatten()
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    if largest == 0.0 || !largest.is_finite() {
        return false;
    }
    // (two factors, each a normal power of two, for exponents from -1023 to 1074)
    let k = -(largest.log2().floor() as i32);
    let (f1, f2) = (pow2(k / 2), pow2(k - k / 2));
    for v in [&mut d, &mut e1, &mut e2, &mut s] {
        *v = v.map(|x| x * f1 * f2);
    }
    let h = cross(&d, &e2);
    let det = dot(&e1, &h);
    // the scale of det: |d| |e1| |e2|; below it relatively, the segment is parallel to the
    // plane or something is degenerate
    let scale = norm_scaled(&d) * norm_scaled(&e1) * norm_scaled(&e2);
    if scale.is_nan() || scale <= 0.0 || det.abs() <= TOL * scale {
        return false;
    }
    let u = dot(&s, &h) / det;
    if !(-TOL..=1.0 + TOL).contains(&u) {
        return false;
    }
    let qv = cross(&s, &e1);
    let v = dot(&d, &qv) / det;
    if v < -TOL || u + v > 1.0 + TOL {
        return false;
    }
    let t = dot(&e2, &qv) / det;
    t > TOL && t < 1.0 - TOL
}

/// `2^k` for `k` in [-1022, 1023] (a normal number), exactly.
fn pow2(k: i32) -> f64 {
    debug_assert!((-1022..=1023).contains(&k));
    f64::from_bits(((k + 1023) as u64) << 52)
}

/// The determinant of the matrix with columns `c`.
fn det3_cols(c: &[[f64; 3]; 3]) -> f64 {
    dot(&c[0], &cross(&c[1], &c[2]))
}

/// `x / |x|`, or `fallback` for a zero `x`.
fn unit_or(x: &[f64; 3], fallback: [f64; 3]) -> [f64; 3] {
    let n = norm_scaled(x);
    if n > 0.0 && n.is_finite() {
        x.map(|c| c / n)
    } else {
        fallback
    }
}

/// A unit vector orthogonal to the unit vector `u`: the axis least aligned with `u`, minus its
/// component along `u`.
fn perpendicular(u: &[f64; 3]) -> [f64; 3] {
    let k = (0..3)
        .min_by(|&i, &j| u[i].abs().total_cmp(&u[j].abs()))
        .unwrap_or(0);
    let mut w = u.map(|x| -u[k] * x);
    w[k] += 1.0;
    unit_or(&w, [0.0, 0.0, 1.0])
}

/// Eigenvalues of `sym(m)` for 2x2, descending: `mean ± hypot(half difference, off-diagonal)`.
fn eigvals_sym2(m: &Mat) -> [f64; 2] {
    let s = sym(m);
    let (a, b, d) = (s.data[0], s.data[1], s.data[3]);
    let mean = 0.5 * a + 0.5 * d;
    let r = (0.5 * a - 0.5 * d).hypot(b);
    [mean + r, mean - r]
}

/// Eigenvalues of `sym(m)` for 3x3, descending, by cyclic Jacobi on the scaled matrix.
fn eigvals_sym3(m: &Mat) -> Result<[f64; 3], EvalError> {
    require_finite("eigvals_sym3", m)?;
    let s = max_abs(&m.data);
    if s == 0.0 {
        return Ok([0.0; 3]);
    }
    let sm = sym(m);
    let mut a = [[0.0; 3]; 3];
    for (i, row) in a.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = sm.get(i, j) / s;
        }
    }
    // Off-diagonal entries below this change no eigenvalue by more than a rounding error.
    let tiny = f64::EPSILON * 1e-3 * norm_scaled(&a.concat());
    for _sweep in 0..64 {
        let mut rotated = false;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let apq = a[p][q];
            if apq.abs() <= tiny {
                continue;
            }
            rotated = true;
            let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
            let t = theta.signum() / (theta.abs() + theta.hypot(1.0));
            let c = 1.0 / t.hypot(1.0);
            let sn = t * c;
            a[p][p] -= t * apq;
            a[q][q] += t * apq;
            a[p][q] = 0.0;
            a[q][p] = 0.0;
            let r = 3 - p - q;
            let (arp, arq) = (a[r][p], a[r][q]);
            a[r][p] = c * arp - sn * arq;
            a[p][r] = a[r][p];
            a[r][q] = sn * arp + c * arq;
            a[q][r] = a[r][q];
        }
        if !rotated {
            break;
        }
    }
    let mut e = [a[0][0] * s, a[1][1] * s, a[2][2] * s];
    e.sort_by(|x, y| y.total_cmp(x));
    Ok(e)
}

#[cfg(test)]
// Exact comparisons are intended: the expected values are exactly representable results.
#[allow(clippy::float_cmp)]
mod tests {
    use super::*;

    fn m(rows: usize, cols: usize, data: &[f64]) -> Mat {
        Mat {
            rows,
            cols,
            data: data.to_vec(),
        }
    }

    fn c(name: &str, args: &[Val]) -> Val {
        let tys: Vec<Ty> = args.iter().map(Val::ty).collect();
        let t = call_type(name, &tys).unwrap_or_else(|e| panic!("{e}"));
        let v = call(name, args).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(v.ty(), t, "{name}: value type differs from call_type");
        v
    }

    fn f(v: &Val) -> f64 {
        v.as_f64().unwrap()
    }

    /// The direct `norm` against the scaled one it replaced: on random 2-, 3- and 9-vectors
    /// of magnitudes 1e-120 to 1e120 they agree to 4 ulps relative (both are a few roundings
    /// from the true value: one per square, per addition and for the root, and, scaled, one
    /// per division and the final product); outside the direct range the scaled form is taken, bit for bit, so huge
    /// and tiny entries neither overflow nor underflow.
    #[test]
    fn direct_norm_agrees_with_the_scaled_one_and_falls_back_outside_its_range() {
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for k in 0..30_000 {
            let n = [2, 3, 9][k % 3];
            let scale = 10f64.powf(240.0 * next() - 120.0);
            let x: Vec<f64> = (0..n).map(|_| (2.0 * next() - 1.0) * scale).collect();
            let (a, b) = (norm(&x), norm_scaled(&x));
            assert!(
                (a - b).abs() <= 4.0 * f64::EPSILON * b,
                "{x:?}: direct {a:e}, scaled {b:e}"
            );
        }
        // the range's edges: huge entries (squares overflow), tiny ones (squares underflow),
        // zero, infinite and NaN entries go the scaled way, with its exact bits
        for x in [
            vec![1e200, -1e200, 1e200],
            vec![3e-170, 4e-170, 0.0],
            vec![1e-300, 0.0, 0.0],
            vec![0.0, -0.0, 0.0],
            vec![f64::INFINITY, 1.0, 0.0],
            vec![f64::NAN, 1.0, 0.0],
            vec![f64::MAX, f64::MAX],
        ] {
            let s: f64 = x.iter().map(|v| v * v).sum();
            assert!(!(NORM_DIRECT_MIN..=f64::MAX).contains(&s), "{x:?}");
            let (a, b) = (norm(&x), norm_scaled(&x));
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{x:?}"
            );
        }
        assert_eq!(norm(&[1e200, -1e200, 1e200]), 1e200 * 3f64.sqrt());
        assert_eq!(norm(&[3e-170, 4e-170, 0.0]), 5e-170);
        assert_eq!(norm(&[3.0, 4.0]), 5.0);
        assert_eq!(norm(&[f64::MAX, f64::MAX]), f64::INFINITY);
        assert_eq!(NORM_DIRECT_MIN, 2f64.powi(-960));
    }

    fn max_diff(a: &Mat, b: &Mat) -> f64 {
        a.data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    }

    /// Rotation about a unit axis (Rodrigues).
    fn rot3(axis: [f64; 3], t: f64) -> Mat {
        let n = norm_scaled(&axis);
        let [x, y, z] = axis.map(|c| c / n);
        let (s, co) = t.sin_cos();
        let k = 1.0 - co;
        m(
            3,
            3,
            &[
                co + x * x * k,
                x * y * k - z * s,
                x * z * k + y * s,
                y * x * k + z * s,
                co + y * y * k,
                y * z * k - x * s,
                z * x * k - y * s,
                z * y * k + x * s,
                co + z * z * k,
            ],
        )
    }

    /// The catalogue names are unique, each has a documented signature starting with its
    /// name, and `call_type` knows each (no "unknown function").
    #[test]
    fn catalogue_is_consistent() {
        let mut names: Vec<&str> = catalogue().iter().map(|e| e.0).collect();
        names.sort_unstable();
        let n = names.len();
        names.dedup();
        assert_eq!(names.len(), n, "duplicate names");
        for (name, sig, doc) in catalogue() {
            assert!(sig.starts_with(&format!("{name}(")), "{sig}");
            assert!(sig.contains("->"), "{sig}");
            assert!(doc.ends_with('.') && doc.len() > 10, "{doc}");
            let e = call_type(name, &[Ty::Bool; 13]).unwrap_err();
            assert!(e.contains("takes"), "{e}");
        }
    }

    /// Unknown names are refused with close suggestions; wrong arity and wrong types say what
    /// the signature is.
    #[test]
    fn call_type_messages() {
        assert_eq!(
            call_type("nrom", &[Ty::Vec3]).unwrap_err(),
            "unknown function `nrom`; did you mean `norm`?"
        );
        assert_eq!(
            call_type("invers", &[Ty::Mat(3, 3)]).unwrap_err(),
            "unknown function `invers`; did you mean `inverse`?"
        );
        assert_eq!(
            call_type("frobnicate", &[]).unwrap_err(),
            "unknown function `frobnicate`"
        );
        assert_eq!(
            call_type("dot", &[Ty::Vec3]).unwrap_err(),
            "`dot` takes 2 arguments, got 1: dot(a: col, b: col) -> f64"
        );
        assert_eq!(
            call_type("dot", &[Ty::Vec3, Ty::Vec2]).unwrap_err(),
            "`dot` does not apply to (vec3, vec2): dot(a: col, b: col) -> f64"
        );
        assert!(call_type("det", &[Ty::Mat(3, 4)]).is_err());
        assert!(call_type("polar", &[Ty::Mat(4, 4)]).is_err());
        assert!(call_type("block3", &[Ty::Mat(12, 4), Ty::I64, Ty::I64]).is_err());
        assert!(call_type("get", &[Ty::Mat(3, 3), Ty::F64, Ty::I64]).is_err());
        assert!(call_type("sqrt", &[Ty::Vec3]).is_err());
        assert!(call_type("select", &[Ty::Bool, Ty::Vec3, Ty::F64]).is_err());
        assert!(call_type("is_finite", &[Ty::Bool]).is_err());
        assert!(call_type("outer", &[Ty::Mat(12, 1), Ty::Mat(3, 3)]).is_err());
    }

    /// The overloads: integers stay integers where the signature says so, otherwise promote.
    #[test]
    fn call_type_overloads() {
        use Ty::{Bool, Mat, Vec2, Vec3, F64, I64};
        let ok = |name: &str, args: &[Ty], r: Ty| assert_eq!(call_type(name, args), Ok(r));
        ok("vec3", &[I64, F64, I64], Vec3);
        ok("abs", &[I64], I64);
        ok("abs", &[F64], F64);
        ok("min", &[I64, I64], I64);
        ok("min", &[I64, F64], F64);
        ok("clamp", &[I64, I64, I64], I64);
        ok("clamp", &[F64, I64, I64], F64);
        ok("sqrt", &[I64], F64);
        ok("select", &[Bool, Mat(12, 12), Mat(12, 12)], Mat(12, 12));
        ok("select", &[Bool, I64, F64], F64);
        ok("cross", &[Vec2, Vec2], F64);
        ok("cross", &[Vec3, Vec3], Vec3);
        ok("outer", &[Vec3, Vec2], Mat(3, 2));
        ok("outer", &[Mat(12, 1), Vec3], Mat(12, 3));
        ok("dot", &[Mat(12, 1), Mat(12, 1)], F64);
        ok("transpose", &[Mat(3, 12)], Mat(12, 3));
        ok("block3", &[Mat(12, 6), I64, I64], Mat(3, 3));
        ok("set_block2", &[Mat(6, 6), I64, I64, Mat(2, 2)], Mat(6, 6));
        ok("vecn_get3", &[Mat(12, 1), I64], Vec3);
        ok("vecn_set3", &[Mat(9, 1), I64, Vec3], Mat(9, 1));
        ok("get", &[Vec3, I64, I64], F64);
        ok("set", &[Vec2, I64, I64, I64], Vec2);
        ok("is_finite", &[Mat(3, 4)], Bool);
        ok("row3", &[Mat(12, 3), I64], Vec3);
        ok("col2", &[Mat(2, 5), I64], Vec2);
    }

    #[test]
    fn constructors_and_accessors() {
        use Val::{F, I, M, V2, V3};
        assert_eq!(c("vec3", &[I(1), F(2.5), I(-3)]), V3([1.0, 2.5, -3.0]));
        let a = c("mat3", &(1..=9).map(I).collect::<Vec<_>>());
        let Val::M(am) = &a else { panic!() };
        assert_eq!(am.get(0, 1), 2.0);
        assert_eq!(am.get(2, 0), 7.0);
        let cols = c(
            "mat_from_cols3",
            &[
                V3([1.0, 4.0, 7.0]),
                V3([2.0, 5.0, 8.0]),
                V3([3.0, 6.0, 9.0]),
            ],
        );
        assert_eq!(cols, a);
        let rows = c(
            "mat_from_rows3",
            &[
                V3([1.0, 2.0, 3.0]),
                V3([4.0, 5.0, 6.0]),
                V3([7.0, 8.0, 9.0]),
            ],
        );
        assert_eq!(rows, a);
        assert_eq!(
            c("mat_from_cols2", &[V2([1.0, 3.0]), V2([2.0, 4.0])]),
            c("mat2", &[I(1), I(2), I(3), I(4)])
        );
        assert_eq!(c("row3", &[a.clone(), I(1)]), V3([4.0, 5.0, 6.0]));
        assert_eq!(c("col3", &[a.clone(), I(2)]), V3([3.0, 6.0, 9.0]));
        assert_eq!(c("get", &[a.clone(), I(2), I(1)]), F(8.0));
        let b = c("set", &[a.clone(), I(2), I(1), I(0)]);
        assert_eq!(c("get", &[b, I(2), I(1)]), F(0.0));
        assert_eq!(c("get", &[a.clone(), I(1), I(1)]), F(5.0), "set copies");
        let v = V3([1.0, 2.0, 3.0]);
        assert_eq!(c("x", std::slice::from_ref(&v)), F(1.0));
        assert_eq!(c("z", std::slice::from_ref(&v)), F(3.0));
        assert_eq!(c("elem", &[v.clone(), I(1)]), F(2.0));
        assert_eq!(c("get", &[v.clone(), I(2), I(0)]), F(3.0));
        assert_eq!(
            c("set", &[v.clone(), I(0), I(0), F(9.0)]),
            V3([9.0, 2.0, 3.0])
        );
        assert_eq!(c("identity3", &[]), M(Mat::identity(3)));
        assert_eq!(c("zeros12x1", &[]), M(Mat::zeros(12, 1)));
        assert_eq!(c("to_i64", &[F(-2.7)]), I(-2));
        assert_eq!(c("to_i64", &[F(2.7)]), I(2));
        assert_eq!(c("to_f64", &[Val::B(true)]), F(1.0));
    }

    /// Indices out of range, negative or huge, are errors naming the function.
    #[test]
    fn index_errors() {
        use Val::{F, I, M, V3};
        let a = M(Mat::identity(3));
        for (i, j) in [(3, 0), (0, 3), (-1, 0), (i64::MIN, i64::MAX)] {
            let e = call("get", &[a.clone(), I(i), I(j)]).unwrap_err();
            assert!(e.0.starts_with("get: entry"), "{e}");
            assert!(call("set", &[a.clone(), I(i), I(j), F(0.0)]).is_err());
        }
        assert_eq!(
            call("get", &[V3([0.0; 3]), I(0), I(1)]).unwrap_err().0,
            "get: entry (0, 1) outside a vec3"
        );
        assert_eq!(
            call("elem", &[V3([0.0; 3]), I(3)]).unwrap_err().0,
            "elem: index 3 out of range 0..3"
        );
        let k = M(Mat::zeros(12, 12));
        assert_eq!(
            call("block3", &[k.clone(), I(4), I(0)]).unwrap_err().0,
            "block3: block (4, 0) outside the 4x4 blocks of a 12x12 matrix"
        );
        assert!(call("vecn_get3", &[M(Mat::zeros(12, 1)), I(4)]).is_err());
        assert!(call(
            "vecn_set2",
            &[M(Mat::zeros(6, 1)), I(-1), Val::V2([0.0; 2])]
        )
        .is_err());
        assert!(call("row2", &[M(Mat::zeros(2, 2)), I(2)]).is_err());
        assert!(call("to_i64", &[F(f64::NAN)]).is_err());
        assert!(call("to_i64", &[F(9.3e18)]).is_err());
        assert_eq!(call("to_i64", &[F(-(2.0_f64.powi(63)))]), Ok(I(i64::MIN)));
        assert!(call("abs", &[I(i64::MIN)]).is_err());
        assert!(call("clamp", &[I(0), I(2), I(1)]).is_err());
        assert!(call("clamp", &[F(0.0), F(2.0), F(1.0)]).is_err());
        assert!(call("nope", &[])
            .unwrap_err()
            .0
            .contains("unknown function"));
        assert!(call("dot", &[F(1.0)])
            .unwrap_err()
            .0
            .contains("internal error"));
    }

    /// The 12x12 block helpers address the 3x3 block of nodes (i, j) of a tetrahedron's
    /// stiffness, and the 3-entry part of node i of its force column.
    #[test]
    fn fem_blocks() {
        use Val::{I, M, V3};
        let mut k = Mat::zeros(12, 12);
        for (n, x) in k.data.iter_mut().enumerate() {
            *x = n as f64;
        }
        let b = c("block3", &[M(k.clone()), I(2), I(1)]);
        let Val::M(bm) = &b else { panic!() };
        assert_eq!(bm.get(0, 0), k.get(6, 3));
        assert_eq!(bm.get(2, 1), k.get(8, 4));
        let k2 = c(
            "set_block3",
            &[M(k.clone()), I(3), I(3), M(Mat::identity(3))],
        );
        let Val::M(k2) = k2 else { panic!() };
        assert_eq!(k2.get(9, 9), 1.0);
        assert_eq!(k2.get(9, 10), 0.0);
        assert_eq!(k2.get(8, 8), k.get(8, 8));
        let f = c(
            "vecn_set3",
            &[c("zeros12x1", &[]), I(1), V3([1.0, 2.0, 3.0])],
        );
        let Val::M(fm) = &f else { panic!() };
        assert_eq!(fm.data[3..6], [1.0, 2.0, 3.0]);
        assert_eq!(c("vecn_get3", &[f, I(1)]), V3([1.0, 2.0, 3.0]));
        let k6 = c(
            "set_block2",
            &[c("zeros6", &[]), I(2), I(0), c("identity2", &[])],
        );
        assert_eq!(c("block2", &[k6.clone(), I(2), I(0)]), c("identity2", &[]));
        assert_eq!(
            c("vecn_get2", &[c("zeros6x1", &[]), I(2)]),
            Val::V2([0.0; 2])
        );
    }

    #[test]
    fn scalar_math() {
        use Val::{B, F, I};
        assert_eq!(c("abs", &[I(-3)]), I(3));
        assert_eq!(c("abs", &[F(-3.5)]), F(3.5));
        assert_eq!(c("sign", &[F(-0.0)]), F(0.0));
        assert_eq!(c("sign", &[F(2.0)]), F(1.0));
        assert_eq!(c("sign", &[I(-7)]), I(-1));
        assert!(f(&c("sign", &[F(f64::NAN)])).is_nan());
        assert_eq!(c("sqrt", &[I(9)]), F(3.0));
        assert_eq!(c("pow", &[I(2), I(10)]), F(1024.0));
        assert_eq!(
            c("atan2", &[F(1.0), F(0.0)]),
            F(std::f64::consts::FRAC_PI_2)
        );
        assert_eq!(c("floor", &[F(-1.5)]), F(-2.0));
        assert_eq!(c("ceil", &[F(-1.5)]), F(-1.0));
        assert_eq!(c("min", &[I(3), I(-2)]), I(-2));
        assert_eq!(c("max", &[I(3), F(4.5)]), F(4.5));
        assert!(
            f(&c("min", &[F(f64::NAN), F(1.0)])).is_nan(),
            "NaN propagates"
        );
        assert_eq!(c("clamp", &[F(5.0), I(0), I(1)]), F(1.0));
        assert_eq!(c("clamp", &[I(-5), I(0), I(1)]), I(0));
        assert!(f(&c("clamp", &[F(f64::NAN), F(0.0), F(1.0)])).is_nan());
        assert_eq!(c("select", &[B(false), I(1), F(2.5)]), F(2.5));
        assert_eq!(c("select", &[B(true), I(1), F(2.5)]), F(1.0));
        assert_eq!(c("select", &[B(true), I(1), I(2)]), I(1));
        assert_eq!(
            c("is_finite", &[Val::V3([1.0, f64::INFINITY, 0.0])]),
            B(false)
        );
        assert_eq!(c("is_finite", &[I(1)]), B(true));
        assert!(f(&c("log", &[F(-1.0)])).is_nan());
    }

    #[test]
    fn vectors() {
        use std::f64::consts::{FRAC_PI_2, PI};
        use Val::{F, V2, V3};
        let (a, b) = (V3([1.0, 0.0, 0.0]), V3([0.0, 2.0, 0.0]));
        assert_eq!(c("dot", &[a.clone(), b.clone()]), F(0.0));
        assert_eq!(c("cross", &[a.clone(), b.clone()]), V3([0.0, 0.0, 2.0]));
        assert_eq!(c("cross", &[V2([1.0, 0.0]), V2([0.0, 2.0])]), F(2.0));
        assert_eq!(c("norm", &[V3([3.0, 4.0, 12.0])]), F(13.0));
        assert_eq!(c("norm2", &[V2([3.0, 4.0])]), F(25.0));
        // Scaled norm: 3e200 and 4e200 square to infinity, the norm does not.
        assert!((f(&c("norm", &[V2([3e200, 4e200])])) / 5e200 - 1.0).abs() < 1e-15);
        assert_eq!(
            c("normalize", &[V3([0.0, 0.0, -2.0])]),
            V3([0.0, 0.0, -1.0])
        );
        assert_eq!(
            c("normalize", &[V3([0.0; 3])]),
            V3([0.0; 3]),
            "zero stays zero"
        );
        let n = c("normalize", &[V2([1e-310, 1e-310])]);
        assert!((f(&c("norm", &[n])) - 1.0).abs() < 1e-15, "subnormal input");
        let o = c("outer", &[V3([1.0, 2.0, 3.0]), V2([1.0, -1.0])]);
        assert_eq!(o, Val::M(m(3, 2, &[1.0, -1.0, 2.0, -2.0, 3.0, -3.0])));
        assert_eq!(c("angle", &[a.clone(), b.clone()]), F(FRAC_PI_2));
        assert_eq!(c("angle", &[V2([1.0, 0.0]), V2([-1.0, 0.0])]), F(PI));
        assert_eq!(c("angle", &[a.clone(), V3([0.0; 3])]), F(0.0));
        // Nearly parallel: acos(dot) would round the cosine to 1 and give 0 (or 1.5e-8).
        let t = 1e-10_f64;
        let got = f(&c("angle", &[a, V3([t.cos(), t.sin(), 0.0])]));
        assert!((got - t).abs() < 1e-24, "{got}");
    }

    /// Determinants against hand-computed values; the 2x2 uses no cancellation-prone formula.
    #[test]
    fn det_hand_computed() {
        assert_eq!(det(&m(1, 1, &[-4.0])), -4.0);
        assert_eq!(det(&m(2, 2, &[1.0, 2.0, 3.0, 4.0])), -2.0);
        assert_eq!(
            det(&m(3, 3, &[2.0, 0.0, 1.0, 1.0, 3.0, 2.0, 1.0, 1.0, 1.0])),
            // 2(3-2) - 0 + 1(1-3)
            0.0
        );
        assert_eq!(
            det(&m(3, 3, &[6.0, 1.0, 1.0, 4.0, -2.0, 5.0, 2.0, 8.0, 7.0])),
            // 6(-14-40) - 1(28-10) + 1(32+4)
            -306.0
        );
        // 4x4 with a zero leading entry (the pivot search must swap):
        // expanding along the first column, det = -1 * det([[1,1,0],[0,2,1],[1,0,3]]) * ...
        let a = m(
            4,
            4,
            &[
                0.0, 1.0, 2.0, 3.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 2.0, 2.0, 0.0, 0.0, 1.0,
            ],
        );
        // Cofactor expansion by hand along column 0:
        // -1 * det([[1,2,3],[1,0,2],[0,0,1]]) - 2 * det([[1,2,3],[0,1,0],[1,0,2]])
        // = -1 * (1*(0-0) - 2*(1-0) + 3*0) - 2 * (1*2 - 2*0 + 3*(0-1)) = 2 + 2 = 4
        assert!((det(&a) - 4.0).abs() < 1e-14);
        // Triangular 5x5: the product of the diagonal.
        let mut t = Mat::identity(5);
        for i in 0..5 {
            t.set(i, i, (i + 1) as f64);
            for j in i + 1..5 {
                t.set(i, j, 7.0);
            }
        }
        assert!((det(&t) - 120.0).abs() < 1e-12);
        // A row permutation of the identity: its sign.
        let mut p = Mat::zeros(6, 6);
        for (i, j) in [(0, 1), (1, 0), (2, 2), (3, 4), (4, 5), (5, 3)] {
            p.set(i, j, 1.0);
        }
        assert_eq!(det(&p), -1.0);
        assert_eq!(det(&Mat::zeros(12, 12)), 0.0);
        // Kahan's case: ad - bc with cancellation, exact with the fused multiply-add.
        let (a, b) = (1.0 + f64::EPSILON, 1.0 - f64::EPSILON);
        assert_eq!(
            det(&m(2, 2, &[a, b, b, a])),
            4.0 * f64::EPSILON,
            "(1+e)^2 - (1-e)^2 = 4e"
        );
    }

    #[test]
    fn inverse_hand_computed() {
        let a = m(2, 2, &[4.0, 7.0, 2.0, 6.0]);
        let inv = inverse(&a).unwrap();
        // 1/10 * [[6, -7], [-2, 4]]
        assert!(max_diff(&inv, &m(2, 2, &[0.6, -0.7, -0.2, 0.4])) < 1e-15);
        let b = m(3, 3, &[1.0, 2.0, 3.0, 0.0, 1.0, 4.0, 5.0, 6.0, 0.0]);
        let inv = inverse(&b).unwrap();
        // The classic example: det 1, inverse [[-24, 18, 5], [20, -15, -4], [-5, 4, 1]].
        let want = m(3, 3, &[-24.0, 18.0, 5.0, 20.0, -15.0, -4.0, -5.0, 4.0, 1.0]);
        assert!(max_diff(&inv, &want) < 1e-13);
    }

    /// Singular, non-finite and overflowing inverses are errors naming the size.
    #[test]
    fn singular_inverse_is_an_error() {
        let e = inverse(&m(2, 2, &[1.0, 2.0, 2.0, 4.0])).unwrap_err();
        assert!(
            e.0.starts_with("inverse: the 2x2 matrix is singular"),
            "{e}"
        );
        let mut s = Mat::identity(12);
        s.set(7, 7, 0.0);
        assert!(inverse(&s).unwrap_err().0.contains("12x12"));
        assert!(inverse(&Mat::zeros(3, 3)).is_err());
        assert!(inverse(&m(1, 1, &[1e-301])).is_err());
        assert!(inverse(&m(1, 1, &[f64::NAN]))
            .unwrap_err()
            .0
            .contains("non-finite"));
        // Rank 2 in 3D: the last pivot is a rounding residue or zero, never a NaN result.
        let r2 = m(3, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
        match inverse(&r2) {
            Err(_) => {}
            Ok(x) => assert!(x.data.iter().all(|v| v.is_finite())),
        }
        assert!(call("inverse", &[Val::M(Mat::zeros(4, 4))]).is_err());
    }

    /// R of a pure rotation is that rotation; of rotation * SPD stretch, that rotation
    /// (tolerance: a few hundred ulps, the Jacobi sweeps and products of 3x3 matrices).
    /// The segment-triangle test on cases whose answer is known by construction: through
    /// the interior, outside, through an edge and a vertex (the closed triangle counts),
    /// ending or starting on its plane (no crossing: an end on the plane is on neither side)
    /// or just short of it, parallel and in-plane segments, degenerate
    /// input; and the same answers after a translation and a scaling by 1e6, 1e-6, 1e-150
    /// and 1e-300 (the tolerances are relative; products of three differences of 1e-150
    /// underflowed to 0: QA) and by 1e95 (below the blade's 1e100 limit), and with the
    /// triangle's vertices in either order.
    #[test]
    fn segment_hits_triangle_cases() {
        let (p, q, r) = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let cases: [([f64; 3], [f64; 3], bool, &str); 12] = [
            (
                [0.2, 0.2, -1.0],
                [0.2, 0.2, 1.0],
                true,
                "through the interior",
            ),
            (
                [0.8, 0.8, -1.0],
                [0.8, 0.8, 1.0],
                false,
                "beside the hypotenuse",
            ),
            (
                [0.5, 0.5, -1.0],
                [0.5, 0.5, 1.0],
                true,
                "through the hypotenuse",
            ),
            ([0.0, 0.0, -1.0], [0.0, 0.0, 1.0], true, "through a vertex"),
            (
                [0.2, 0.2, -1.0],
                [0.2, 0.2, 0.0],
                false,
                "ending on the triangle's plane",
            ),
            ([0.2, 0.2, 0.0], [0.2, 0.2, 1.0], false, "starting on it"),
            (
                [0.2, 0.2, -1.0],
                [0.2, 0.2, -1e-3],
                false,
                "ending short of it",
            ),
            (
                [0.2, 0.2, 1e-3],
                [0.2, 0.2, 1.0],
                false,
                "starting above it",
            ),
            ([-1.0, 0.2, 0.5], [2.0, 0.2, 0.5], false, "parallel, above"),
            ([-1.0, 0.2, 0.0], [2.0, 0.2, 0.0], false, "in the plane"),
            ([0.2, 0.2, 0.0], [0.2, 0.2, 0.0], false, "zero length"),
            (
                [0.2, 0.2, -1.0],
                [0.3, 0.1, 1.0],
                true,
                "slanted, through the interior",
            ),
        ];
        let tf = |v: [f64; 3], k: f64| [v[0] * k + 3.0 * k, v[1] * k - 7.0 * k, v[2] * k + k];
        for (a, b, want, what) in cases {
            for k in [1.0, 1e6, 1e-6, 1e-150, 1e-300, 1e95] {
                let (a, b, p, q, r) = (tf(a, k), tf(b, k), tf(p, k), tf(q, k), tf(r, k));
                assert_eq!(
                    segment_hits_triangle(&a, &b, &p, &q, &r),
                    want,
                    "{what}, scale {k}"
                );
                assert_eq!(
                    segment_hits_triangle(&a, &b, &p, &r, &q),
                    want,
                    "{what}, reversed"
                );
                assert_eq!(
                    segment_hits_triangle(&b, &a, &q, &r, &p),
                    want,
                    "{what}, from b"
                );
            }
        }
        let flat = segment_hits_triangle(
            &[0.2, 0.2, -1.0],
            &[0.2, 0.2, 1.0],
            &p,
            &q,
            &[2.0, 0.0, 0.0],
        );
        assert!(!flat, "a flat triangle");
        let nan = segment_hits_triangle(&[f64::NAN, 0.2, -1.0], &[0.2, 0.2, 1.0], &p, &q, &r);
        assert!(!nan, "non-finite input");
        assert_eq!(
            call(
                "segment_hits_triangle",
                &[
                    Val::V3([0.2, 0.2, -1.0]),
                    Val::V3([0.2, 0.2, 1.0]),
                    Val::V3(p),
                    Val::V3(q),
                    Val::V3(r)
                ]
            )
            .unwrap(),
            Val::B(true)
        );
        assert_eq!(
            call_type("segment_hits_triangle", &[Ty::Vec3; 5]).unwrap(),
            Ty::Bool
        );
    }

    #[test]
    fn polar_of_rotation_and_stretch() {
        for (axis, t) in [
            ([0.0, 0.0, 1.0], 0.3),
            ([1.0, 2.0, 3.0], 2.9),
            ([1.0, -1.0, 0.5], std::f64::consts::PI),
            ([0.0, 1.0, 0.0], 0.0),
        ] {
            let r = rot3(axis, t);
            assert!(max_diff(&polar3(&r).unwrap(), &r) < 1e-14, "{axis:?} {t}");
            // S = Q diag(3, 0.5, 1e-3) Q^T, SPD and anisotropic.
            let q = rot3([0.3, 0.2, -1.0], 1.1);
            let mut d = Mat::zeros(3, 3);
            for (i, x) in [3.0, 0.5, 1e-3].into_iter().enumerate() {
                d.set(i, i, x);
            }
            let s = q.mul(&d).mul(&q.transpose());
            let f = r.mul(&s);
            assert!(
                max_diff(&polar3(&f).unwrap(), &r) < 1e-12,
                "{axis:?} {t}: {:?}",
                polar3(&f)
            );
            // The same with a repeated singular value.
            let s = q
                .mul(&m(3, 3, &[2.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.5]))
                .mul(&q.transpose());
            assert!(max_diff(&polar3(&r.mul(&s)).unwrap(), &r) < 1e-13);
        }
        for t in [0.0, 0.7, -2.0, 3.1] {
            let (s, co) = f64::sin_cos(t);
            let r = m(2, 2, &[co, -s, s, co]);
            assert!(max_diff(&polar2(&r).unwrap(), &r) < 1e-15);
            let stretch = m(2, 2, &[2.0, 0.3, 0.3, 0.1]);
            assert!(max_diff(&polar2(&r.mul(&stretch)).unwrap(), &r) < 1e-14);
        }
    }

    /// A nearly flat element with distinct tiny singular values: the polar factor's condition
    /// number is about `1 / (s2 + s3)`, so rounding errors of `eps |m|` move it by about
    /// `eps / 3e-9 ~ 1e-7`; a method through `m^T m` would square the condition and lose these
    /// singular values entirely (an O(1) error). Tolerance 1e-6.
    #[test]
    fn polar_of_nearly_flat_element() {
        let u = rot3([1.0, 2.0, 3.0], 0.7);
        let v = rot3([-2.0, 0.5, 1.0], 2.3);
        let d = m(3, 3, &[1.0, 0.0, 0.0, 0.0, 2e-9, 0.0, 0.0, 0.0, 1e-9]);
        let f = u.mul(&d).mul(&v.transpose());
        let want = u.mul(&v.transpose());
        let err = max_diff(&polar3(&f).unwrap(), &want);
        assert!(err < 1e-6, "{err:e}");
    }

    /// Inverted elements: a reflection's closest rotation flips the direction of least
    /// stretch (Irving et al. 2004), and a flat element still gets a rotation.
    #[test]
    fn polar_of_inverted_and_flat() {
        // diag(2, 1, -0.5): the smallest singular value is negated, R = I.
        let f = m(3, 3, &[2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -0.5]);
        assert!(max_diff(&polar3(&f).unwrap(), &Mat::identity(3)) < 1e-15);
        // diag(-3, 1, 2): the smallest singular value (1, axis y) is negated:
        // R = diag(-1, -1, 1), a half-turn about z.
        let f = m(3, 3, &[-3.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 2.0]);
        let want = m(3, 3, &[-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0]);
        assert!(max_diff(&polar3(&f).unwrap(), &want) < 1e-15);
        // A flat tetrahedron (rank 2) and a needle (rank 1) and zero.
        for f in [
            m(3, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]),
            m(3, 3, &[1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 0.0, 0.0]),
            m(3, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]),
            Mat::zeros(3, 3),
        ] {
            let r = polar3(&f).unwrap();
            assert!(max_diff(&r.transpose().mul(&r), &Mat::identity(3)) < 1e-14);
            assert!((det(&r) - 1.0).abs() < 1e-14);
        }
        // The flat diag(1, 1, 0) is already closest to the identity.
        let f = m(3, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
        assert!(max_diff(&polar3(&f).unwrap(), &Mat::identity(3)) < 1e-15);
        // 2D reflection diag(1, -2): the smaller singular value (1) is negated, R = -I.
        let r = polar2(&m(2, 2, &[1.0, 0.0, 0.0, -2.0])).unwrap();
        assert!(max_diff(&r, &m(2, 2, &[-1.0, 0.0, 0.0, -1.0])) < 1e-15);
        assert!(polar3(&m(3, 3, &[f64::NAN; 9])).is_err());
        assert!(polar2(&m(2, 2, &[f64::INFINITY, 0.0, 0.0, 1.0])).is_err());
    }

    /// A deterministic generator for the randomized polar tests (`SplitMix64`).
    struct Rng(u64);

    impl Rng {
        fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }

        /// Uniform in [0, 1).
        #[allow(clippy::cast_precision_loss)]
        fn unit(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }

        /// Uniform in [lo, hi).
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.unit()
        }

        /// A random rotation (from a normalized random quaternion).
        fn rotation(&mut self) -> [f64; 9] {
            let q = loop {
                let q = [0; 4].map(|_| self.range(-1.0, 1.0));
                let n = dot(&q, &q);
                if n > 1e-3 && n <= 1.0 {
                    break q.map(|c| c / n.sqrt());
                }
            };
            let [w, x, y, z] = q;
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ]
        }
    }

    fn mul9(a: &[f64; 9], b: &[f64; 9]) -> [f64; 9] {
        let mut c = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                c[3 * i + j] = (0..3).map(|k| a[3 * i + k] * b[3 * k + j]).sum();
            }
        }
        c
    }

    fn transpose9(a: &[f64; 9]) -> [f64; 9] {
        [a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8]]
    }

    fn mat9(a: &[f64; 9]) -> Mat {
        m(3, 3, a)
    }

    fn max_diff9(a: &[f64; 9], b: &[f64; 9]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    }

    /// `U diag(s) V^T` for random rotations U, V, times `scale`.
    fn with_singular_values(rng: &mut Rng, s: [f64; 3], scale: f64) -> [f64; 9] {
        let (u, v) = (rng.rotation(), rng.rotation());
        let d = [s[0], 0.0, 0.0, 0.0, s[1], 0.0, 0.0, 0.0, s[2]];
        mul9(&mul9(&u, &d), &transpose9(&v)).map(|x| x * scale)
    }

    /// The checks every `polar3_data` result must pass, whichever method produced it, against
    /// the Jacobi SVD `want` of the same matrix `m` with singular values `s` (descending,
    /// before the random overall scale):
    /// - the entries differ by at most `16 eps s1 / (s2 + s3)`. Both methods are backward
    ///   stable (each returns the exact rotation of `m + dm`, `|dm| ~ eps |m|`), and the
    ///   rotation of a real 3x3 matrix moves by at most `2 |dm|_F / (s2 + s3)` (its condition
    ///   number; Higham, *Functions of Matrices*, SIAM 2008, ch. 8): so a few `eps s1 / (s2 + s3)`
    ///   is the best two correct methods can agree to. Measured: at most `4 eps s1 / (s2 + s3)`
    ///   over all the random cases (so 1e-15 for well-shaped elements, 2e-12 for condition 1e5
    ///   with two small singular values); 16 leaves a factor 4;
    /// - `|R^T R - I|` and `|det R - 1|` at most 1e-14 (an orthogonal limit up to the rounding
    ///   of the last step, tens of ulps);
    /// - `R^T m` symmetric to `64 eps |m|` and its eigenvalues at least `-64 eps |m|` (the
    ///   definition of the polar factor: `S = R^T m` symmetric positive semi-definite, up to
    ///   the backward error `R^T dm`; measured below `4 eps |m|`).
    ///
    /// Returns the entry difference in units of `eps s1 / (s2 + s3)`, the entry difference,
    /// and the asymmetry of `R^T m / |m|` in units of `eps`.
    fn check_polar3(m: &[f64; 9], s: [f64; 3], want: &[f64; 9], what: &str) -> [f64; 3] {
        let r = polar3_data(m).unwrap();
        let sep = f64::EPSILON * s[0] / (s[1] + s[2]);
        let diff = max_diff9(&r, want);
        assert!(diff <= 16.0 * sep, "{what}: {diff:e} > 16 * {sep:e}\n{m:?}");
        let mut rtr = mul9(&transpose9(&r), &r);
        for i in 0..3 {
            rtr[4 * i] -= 1.0;
        }
        assert!(max_abs(&rtr) <= 1e-14, "{what}: R^T R - I {rtr:?}");
        let dr = det(&mat9(&r));
        assert!((dr - 1.0).abs() <= 1e-14, "{what}: det R = {dr}");
        let big = max_abs(m);
        let st = mul9(&transpose9(&r), &m.map(|x| x / big));
        let asym = max_diff9(&st, &transpose9(&st));
        assert!(
            asym <= 64.0 * f64::EPSILON,
            "{what}: R^T m asymmetric by {asym:e}"
        );
        let e = eigvals_sym3(&mat9(&st)).unwrap();
        assert!(
            e[2] >= -64.0 * f64::EPSILON,
            "{what}: R^T m has eigenvalue {e:?}"
        );
        [diff / sep, diff, asym / f64::EPSILON]
    }

    /// Rotations times SPD stretches (`m = U diag(s) V^T`) with condition numbers
    /// `s1 / s3` log-uniform from 1 to 1e8, `s2` log-uniform between, and overall scales
    /// log-uniform from 1e-100 to 1e100. Newton must be taken whenever the condition is
    /// below `NEWTON_MAX_COND / 3` (the estimate `|X|_F |X^-1|_F` is at most 3 times the
    /// condition) and refused above `NEWTON_MAX_COND` (it is at least the condition), take
    /// at most 8 iterations (measured: 7), and pass [`check_polar3`] against the Jacobi SVD.
    #[test]
    fn polar_newton_matches_jacobi_on_stretched_rotations() {
        let mut rng = Rng(7);
        let (mut worst, mut newton) = ([0.0_f64; 3], 0);
        for i in 0..20_000 {
            // Half the cases up to the threshold, half up to 1e8.
            let kappa = 10f64.powf(rng.range(0.0, if i % 2 == 0 { 2.0 } else { 8.0 }));
            let s = [1.0, kappa.powf(-rng.unit()), 1.0 / kappa];
            let scale = 10f64.powf(rng.range(-100.0, 100.0));
            let m = with_singular_values(&mut rng, s, scale);
            let by_newton = if let Some((_, it)) = polar3_newton(&m) {
                assert!(kappa <= NEWTON_MAX_COND, "{kappa:e}");
                assert!(it <= 8, "{it} iterations at condition {kappa:e}");
                newton += 1;
                true
            } else {
                assert!(kappa >= NEWTON_MAX_COND / 3.0, "{kappa:e}");
                false
            };
            let what = format!("condition {kappa:e}, scale {scale:e}");
            let e = check_polar3(&m, s, &polar3_jacobi(&m), &what);
            if by_newton {
                worst = [0, 1, 2].map(|k| worst[k].max(e[k]));
            }
        }
        println!(
            "stretched rotations: {newton}/20000 by Newton; there, worst difference {:.2} eps \
             s1/(s2+s3), {:.2e} absolute; worst asymmetry of R^T m {:.1} eps",
            worst[0], worst[1], worst[2]
        );
        assert!(newton > 10_000, "{newton}");
    }

    /// Random general matrices (entries uniform in [-1, 1], negated where det < 0 so that
    /// det > 0), times random scales from 1e-100 to 1e100: the same checks, with the singular
    /// values from the Jacobi SVD's `S = R^T m` (eigenvalues of its symmetric part).
    #[test]
    fn polar_newton_matches_jacobi_on_general_matrices() {
        let mut rng = Rng(8);
        let (mut worst, mut newton) = ([0.0_f64; 3], 0);
        for _ in 0..20_000 {
            let mut m = [0; 9].map(|_| rng.range(-1.0, 1.0));
            if det(&mat9(&m)) < 0.0 {
                m = m.map(|x| -x);
            }
            let want = polar3_jacobi(&m);
            let s = eigvals_sym3(&mat9(&mul9(&transpose9(&want), &m))).unwrap();
            let scale = 10f64.powf(rng.range(-100.0, 100.0));
            let ms = m.map(|x| x * scale);
            if polar3_newton(&ms).is_some() {
                newton += 1;
                let e = check_polar3(&ms, s, &polar3_jacobi(&ms), "general");
                worst = [0, 1, 2].map(|k| worst[k].max(e[k]));
            }
        }
        println!(
            "general matrices: {newton}/20000 by Newton; there, worst difference {:.2} eps \
             s1/(s2+s3), {:.2e} absolute; worst asymmetry of R^T m {:.1} eps",
            worst[0], worst[1], worst[2]
        );
        assert!(newton > 10_000, "{newton}");
    }

    /// Where Newton does not apply, `polar` is the Jacobi SVD bit for bit: inverted elements
    /// (det < 0), flat ones (rank 2 and 1), nearly singular ones (condition 1e7 to 1e15),
    /// and scales beyond an exact power-of-two normalization (largest entry at least 2^1023 or
    /// subnormal). The results still pass [`check_polar3`]'s rotation checks (inverted
    /// elements: `R^T m` then has one negative eigenvalue, so that check is skipped).
    #[test]
    fn polar_newton_falls_back_to_jacobi() {
        let mut rng = Rng(9);
        for _ in 0..2_000 {
            let kappa = 10f64.powf(rng.range(7.0, 15.0));
            let s2 = kappa.powf(-rng.unit());
            for (s, what) in [
                ([1.0, s2, 1.0 / kappa], "nearly singular"),
                ([1.0, s2, 0.0], "flat"),
                ([1.0, 0.0, 0.0], "needle"),
                ([1.0, s2, -1.0 / kappa], "inverted"),
                ([1.0, 0.5, -0.3], "inverted"),
            ] {
                let m = with_singular_values(&mut rng, s, 1.0);
                assert!(polar3_newton(&m).is_none(), "{what} {m:?}");
                let r = polar3_data(&m).unwrap();
                assert_eq!(r, polar3_jacobi(&m), "{what}");
                let mut rtr = mul9(&transpose9(&r), &r);
                for i in 0..3 {
                    rtr[4 * i] -= 1.0;
                }
                assert!(max_abs(&rtr) <= 1e-14, "{what}: R^T R - I {rtr:?}");
                assert!((det(&mat9(&r)) - 1.0).abs() <= 1e-14, "{what}");
            }
        }
        let base = with_singular_values(&mut rng, [1.0, 0.8, 0.6], 1.0);
        let big = max_abs(&base);
        for scale in [1.5 * 2f64.powi(1023), 2f64.powi(1023), 1e-310, 2e-323] {
            let m = base.map(|x| x / big * scale);
            assert!(polar3_newton(&m).is_none(), "{scale:e}");
            assert_eq!(polar3_data(&m).unwrap(), polar3_jacobi(&m), "{scale:e}");
        }
    }

    /// The power-of-two normalization is exact, so Newton's result does not depend on a
    /// power-of-two factor at all (bit for bit from 2^-1000 to 2^1000 times a matrix), and at
    /// the extremes where it still applies (largest entry just below 2^1023 and just above the
    /// smallest normal number) it agrees with the Jacobi SVD as in the other tests.
    #[test]
    fn polar_newton_scale_invariance() {
        let mut rng = Rng(10);
        for _ in 0..200 {
            let m = fem_like(&mut rng);
            let r = polar3_data(&m).unwrap();
            for k in [-1000, -300, -1, 1, 300, 1000] {
                let mk = m.map(|x| x * 2f64.powi(k));
                assert_eq!(polar3_data(&mk).unwrap(), r, "2^{k}");
            }
            let big = max_abs(&m);
            for scale in [8.9e307, 2.3e-308] {
                let ms = m.map(|x| x / big * scale);
                assert!(polar3_newton(&ms).is_some(), "{scale:e}");
                let diff = max_diff9(&polar3_data(&ms).unwrap(), &polar3_jacobi(&ms));
                assert!(diff <= 1e-14, "{scale:e}: {diff:e}");
            }
        }
    }

    /// Deformation gradients as co-rotational FEM sees them: a random rotation times an SPD
    /// stretch with principal stretches in [0.7, 1.4] (condition up to 2).
    fn fem_like(rng: &mut Rng) -> [f64; 9] {
        let s = [0; 3].map(|_| rng.range(0.7, 1.4));
        let scale = rng.range(0.1, 10.0);
        with_singular_values(rng, s, scale)
    }

    /// Not a unit test: ns per call of the Jacobi SVD (the old `polar`) and of `polar3_data`
    /// (Newton, with the Jacobi fallback), measured in the same run on the same FEM-like
    /// matrices (random rotations times SPD stretches, at random scales), alternating, best
    /// of 15 rounds. Run with
    /// `cargo test --release -p topomech-rules --lib -- --ignored polar_speed --nocapture`.
    #[test]
    #[ignore = "timing, not a test: run it in release"]
    #[allow(clippy::cast_precision_loss)]
    fn polar_speed() {
        use std::hint::black_box;
        use std::time::Instant;
        let mut rng = Rng(11);
        for (what, lo, hi) in [
            ("stretches 0.7..1.4", 0.7, 1.4),
            ("stretches 0.98..1.02", 0.98, 1.02),
        ] {
            let ms: Vec<[f64; 9]> = (0..4096)
                .map(|_| {
                    let s = [0; 3].map(|_| rng.range(lo, hi));
                    let scale = rng.range(0.1, 10.0);
                    with_singular_values(&mut rng, s, scale)
                })
                .collect();
            let iters = ms
                .iter()
                .map(|m| polar3_newton(m).map_or(0, |(_, k)| k))
                .max();
            let time = |f: &dyn Fn(&[f64]) -> [f64; 9]| {
                let t = Instant::now();
                let mut acc = 0.0;
                for m in &ms {
                    acc += f(black_box(m))[4];
                }
                black_box(acc);
                t.elapsed().as_nanos() as f64 / ms.len() as f64
            };
            let (mut old, mut new) = (f64::INFINITY, f64::INFINITY);
            for _ in 0..15 {
                old = old.min(time(&|m| polar3_jacobi(m)));
                new = new.min(time(&|m| polar3_data(m).unwrap()));
            }
            println!(
                "polar3, {what}: Jacobi SVD {old:.1} ns/call, Newton {new:.1} ns/call ({:.1}x, \
                 at most {iters:?} iterations)",
                old / new
            );
        }
    }

    /// Eigenvalues of symmetric matrices with known spectra (tolerance: Jacobi is backward
    /// stable, errors of a few ulps of the largest eigenvalue).
    #[test]
    fn symmetric_eigenvalues() {
        let q = rot3([1.0, 2.0, -0.5], 0.9);
        let d = m(3, 3, &[5.0, 0.0, 0.0, 0.0, -2.0, 0.0, 0.0, 0.0, 1e-3]);
        let s = q.mul(&d).mul(&q.transpose());
        let e = eigvals_sym3(&s).unwrap();
        for (x, y) in e.iter().zip([5.0, 1e-3, -2.0]) {
            assert!((x - y).abs() < 1e-14 * 5.0, "{e:?}");
        }
        assert_eq!(eigvals_sym3(&Mat::identity(3)).unwrap(), [1.0; 3]);
        // Only the symmetric part counts.
        let skewed = m(3, 3, &[1.0, 5.0, 0.0, -5.0, 2.0, 0.0, 0.0, 0.0, 3.0]);
        assert_eq!(eigvals_sym3(&skewed).unwrap(), [3.0, 2.0, 1.0]);
        let e2 = eigvals_sym2(&m(2, 2, &[2.0, 1.0, 1.0, 2.0]));
        assert_eq!(e2, [3.0, 1.0]);
        assert!(eigvals_sym3(&m(3, 3, &[f64::NAN; 9])).is_err());
    }

    #[test]
    fn matrix_helpers() {
        use Val::{F, M};
        let a = M(m(2, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]));
        assert_eq!(
            c("transpose", std::slice::from_ref(&a)),
            M(m(3, 2, &[1.0, 4.0, 2.0, 5.0, 3.0, 6.0]))
        );
        assert_eq!(c("frobenius", &[a]), F(91.0_f64.sqrt()));
        assert_eq!(c("trace", &[M(Mat::identity(12))]), F(12.0));
        assert_eq!(
            c("sym", &[M(m(2, 2, &[1.0, 4.0, 2.0, 3.0]))]),
            M(m(2, 2, &[1.0, 3.0, 3.0, 3.0]))
        );
        assert_eq!(c("det", &[c("identity3", &[])]), F(1.0));
    }
}
