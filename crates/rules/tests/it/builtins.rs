//! Properties of the built-in functions and operators, through the public API: no built-in
//! panics on any input of the right types, values have the types `call_type` announced, and
//! the numerical kernels (inverse, det, polar, symmetric eigenvalues) meet their accuracy
//! bounds on random matrices.

use proptest::prelude::*;
use topomech_rules::builtins::{call, call_type, catalogue};
use topomech_rules::value::{binop, binop_type, unop, unop_type, BinOp, Mat, Ty, UnOp, Val};

const EPS: f64 = f64::EPSILON;

/// Argument types for every built-in, at least one overload each, with the 12x12 shapes of
/// finite elements where they apply.
const SAMPLES: &[(&str, &[Ty])] = &[
    ("vec2", &[Ty::F64, Ty::I64]),
    ("vec3", &[Ty::I64, Ty::F64, Ty::F64]),
    ("mat2", &[Ty::F64, Ty::F64, Ty::I64, Ty::F64]),
    ("mat3", &[Ty::F64; 9]),
    ("mat_from_cols2", &[Ty::Vec2, Ty::Vec2]),
    ("mat_from_rows2", &[Ty::Vec2, Ty::Vec2]),
    ("mat_from_cols3", &[Ty::Vec3, Ty::Vec3, Ty::Vec3]),
    ("mat_from_rows3", &[Ty::Vec3, Ty::Vec3, Ty::Vec3]),
    ("identity2", &[]),
    ("identity3", &[]),
    ("zeros2", &[]),
    ("zeros3", &[]),
    ("zeros6", &[]),
    ("zeros6x1", &[]),
    ("zeros12", &[]),
    ("zeros12x1", &[]),
    ("x", &[Ty::Vec2]),
    ("y", &[Ty::Vec3]),
    ("z", &[Ty::Vec3]),
    ("elem", &[Ty::Vec3, Ty::I64]),
    ("elem", &[Ty::Mat(12, 1), Ty::I64]),
    ("get", &[Ty::Mat(3, 4), Ty::I64, Ty::I64]),
    ("get", &[Ty::Vec2, Ty::I64, Ty::I64]),
    ("set", &[Ty::Mat(12, 12), Ty::I64, Ty::I64, Ty::F64]),
    ("set", &[Ty::Vec3, Ty::I64, Ty::I64, Ty::I64]),
    ("row2", &[Ty::Mat(5, 2), Ty::I64]),
    ("col2", &[Ty::Mat(2, 2), Ty::I64]),
    ("row3", &[Ty::Mat(3, 3), Ty::I64]),
    ("col3", &[Ty::Mat(3, 12), Ty::I64]),
    ("block2", &[Ty::Mat(6, 6), Ty::I64, Ty::I64]),
    (
        "set_block2",
        &[Ty::Mat(6, 4), Ty::I64, Ty::I64, Ty::Mat(2, 2)],
    ),
    ("vecn_get2", &[Ty::Mat(6, 1), Ty::I64]),
    ("vecn_set2", &[Ty::Mat(6, 1), Ty::I64, Ty::Vec2]),
    ("block3", &[Ty::Mat(12, 12), Ty::I64, Ty::I64]),
    (
        "set_block3",
        &[Ty::Mat(12, 12), Ty::I64, Ty::I64, Ty::Mat(3, 3)],
    ),
    ("vecn_get3", &[Ty::Mat(12, 1), Ty::I64]),
    ("vecn_set3", &[Ty::Mat(12, 1), Ty::I64, Ty::Vec3]),
    ("to_f64", &[Ty::I64]),
    ("to_f64", &[Ty::Bool]),
    ("to_i64", &[Ty::F64]),
    ("abs", &[Ty::I64]),
    ("abs", &[Ty::F64]),
    ("sign", &[Ty::I64]),
    ("sign", &[Ty::F64]),
    ("sqrt", &[Ty::F64]),
    ("exp", &[Ty::F64]),
    ("log", &[Ty::I64]),
    ("sin", &[Ty::F64]),
    ("cos", &[Ty::F64]),
    ("tan", &[Ty::F64]),
    ("asin", &[Ty::F64]),
    ("acos", &[Ty::F64]),
    ("atan", &[Ty::F64]),
    ("atan2", &[Ty::F64, Ty::I64]),
    ("pow", &[Ty::F64, Ty::F64]),
    ("floor", &[Ty::F64]),
    ("ceil", &[Ty::F64]),
    ("min", &[Ty::I64, Ty::I64]),
    ("min", &[Ty::F64, Ty::I64]),
    ("max", &[Ty::F64, Ty::F64]),
    ("clamp", &[Ty::I64, Ty::I64, Ty::I64]),
    ("clamp", &[Ty::F64, Ty::F64, Ty::F64]),
    ("select", &[Ty::Bool, Ty::Mat(3, 3), Ty::Mat(3, 3)]),
    ("select", &[Ty::Bool, Ty::I64, Ty::F64]),
    ("is_finite", &[Ty::Mat(12, 12)]),
    ("is_finite", &[Ty::F64]),
    ("dot", &[Ty::Vec3, Ty::Vec3]),
    ("dot", &[Ty::Mat(12, 1), Ty::Mat(12, 1)]),
    ("cross", &[Ty::Vec3, Ty::Vec3]),
    ("cross", &[Ty::Vec2, Ty::Vec2]),
    ("norm", &[Ty::Vec3]),
    ("norm2", &[Ty::Mat(12, 1)]),
    ("normalize", &[Ty::Vec2]),
    ("normalize", &[Ty::Vec3]),
    ("outer", &[Ty::Vec3, Ty::Vec2]),
    ("angle", &[Ty::Vec3, Ty::Vec3]),
    ("angle", &[Ty::Vec2, Ty::Vec2]),
    ("transpose", &[Ty::Mat(3, 12)]),
    ("trace", &[Ty::Mat(12, 12)]),
    ("det", &[Ty::Mat(2, 2)]),
    ("det", &[Ty::Mat(3, 3)]),
    ("det", &[Ty::Mat(12, 12)]),
    ("inverse", &[Ty::Mat(3, 3)]),
    ("inverse", &[Ty::Mat(12, 12)]),
    ("frobenius", &[Ty::Mat(12, 12)]),
    ("sym", &[Ty::Mat(3, 3)]),
    ("segment_hits_triangle", &[Ty::Vec3; 5]),
    ("polar", &[Ty::Mat(2, 2)]),
    ("polar", &[Ty::Mat(3, 3)]),
    ("eigvals_sym2", &[Ty::Mat(2, 2)]),
    ("eigvals_sym3", &[Ty::Mat(3, 3)]),
];

/// Every built-in in the catalogue has samples, and every sample names a built-in.
#[test]
fn samples_cover_the_catalogue() {
    for (name, _, _) in catalogue() {
        assert!(
            SAMPLES.iter().any(|(n, _)| n == name),
            "no sample arguments for `{name}`"
        );
    }
    for (name, args) in SAMPLES {
        assert!(call_type(name, args).is_ok(), "{name}{args:?}");
    }
}

/// Reals of every kind: ordinary, zero of both signs, subnormal, huge, infinite, NaN.
fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -10.0..10.0f64,
        1 => Just(0.0),
        1 => Just(-0.0),
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(f64::MAX),
        1 => Just(f64::MIN_POSITIVE / 8.0),
        1 => any::<f64>(),
    ]
}

/// Integers: mostly in-range indices, sometimes anything.
fn any_i64() -> impl Strategy<Value = i64> {
    prop_oneof![4 => -2..14i64, 1 => any::<i64>(), 1 => Just(i64::MIN), 1 => Just(i64::MAX)]
}

fn any_val(ty: Ty) -> BoxedStrategy<Val> {
    match ty {
        Ty::I64 => any_i64().prop_map(Val::I).boxed(),
        Ty::Bool => any::<bool>().prop_map(Val::B).boxed(),
        _ => prop::collection::vec(any_f64(), ty.width())
            .prop_map(move |x| Val::from_reals(ty, &x))
            .boxed(),
    }
}

fn any_args(tys: &'static [Ty]) -> BoxedStrategy<Vec<Val>> {
    tys.iter().map(|&t| any_val(t)).collect::<Vec<_>>().boxed()
}

/// Calls a built-in whose argument types are accepted: it returns a value of the announced
/// type or an error, and never panics.
fn check_call(name: &str, args: &[Val]) {
    let tys: Vec<Ty> = args.iter().map(Val::ty).collect();
    let want = call_type(name, &tys).expect("sample types are accepted");
    match call(name, args) {
        Ok(v) => assert_eq!(v.ty(), want, "{name}({args:?})"),
        Err(e) => assert!(!e.0.is_empty() && !e.0.contains("internal error"), "{e}"),
    }
}

/// Every built-in on constant inputs that break naive code: all zero, all NaN, all infinite,
/// all huge (indices 0).
#[test]
fn no_builtin_panics_on_extreme_constants() {
    for x in [
        0.0,
        -0.0,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::MAX,
        1e-310,
    ] {
        for (name, tys) in SAMPLES {
            let args: Vec<Val> = tys
                .iter()
                .map(|&t| match t {
                    Ty::I64 => Val::I(0),
                    Ty::Bool => Val::B(x.is_nan()),
                    _ => Val::from_reals(t, &vec![x; t.width()]),
                })
                .collect();
            check_call(name, &args);
        }
    }
}

const OPS: [BinOp; 13] = [
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

const OPERAND_TYPES: [Ty; 10] = [
    Ty::F64,
    Ty::I64,
    Ty::Bool,
    Ty::Vec2,
    Ty::Vec3,
    Ty::Mat(2, 2),
    Ty::Mat(3, 3),
    Ty::Mat(12, 3),
    Ty::Mat(3, 1),
    Ty::Mat(12, 12),
];

/// A random matrix with entries in `[-1, 1]`.
fn any_mat(r: usize, c: usize) -> impl Strategy<Value = Mat> {
    prop::collection::vec(-1.0..1.0f64, r * c).prop_map(move |data| Mat {
        rows: r,
        cols: c,
        data,
    })
}

/// A random rotation: Rodrigues' formula on a random axis and angle.
fn any_rotation3() -> impl Strategy<Value = Mat> {
    (
        prop::array::uniform3(-1.0..1.0f64),
        -std::f64::consts::PI..std::f64::consts::PI,
    )
        .prop_filter("axis not too short", |(a, _)| norm(a) > 1e-3)
        .prop_map(|(a, t)| rot3(a, t))
}

fn norm(x: &[f64]) -> f64 {
    x.iter().map(|v| v * v).sum::<f64>().sqrt()
}

fn rot3(axis: [f64; 3], t: f64) -> Mat {
    let n = norm(&axis);
    let [x, y, z] = axis.map(|c| c / n);
    let (s, c) = t.sin_cos();
    let k = 1.0 - c;
    Mat {
        rows: 3,
        cols: 3,
        data: vec![
            c + x * x * k,
            x * y * k - z * s,
            x * z * k + y * s,
            y * x * k + z * s,
            c + y * y * k,
            y * z * k - x * s,
            z * x * k - y * s,
            z * y * k + x * s,
            c + z * z * k,
        ],
    }
}

fn rot2(t: f64) -> Mat {
    let (s, c) = t.sin_cos();
    Mat {
        rows: 2,
        cols: 2,
        data: vec![c, -s, s, c],
    }
}

fn diag(d: &[f64]) -> Mat {
    let mut m = Mat::zeros(d.len(), d.len());
    for (i, &x) in d.iter().enumerate() {
        m.set(i, i, x);
    }
    m
}

fn max_diff(a: &Mat, b: &Mat) -> f64 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn frob(m: &Mat) -> f64 {
    norm(&m.data)
}

fn mat_call(name: &str, m: &Mat) -> Mat {
    match call(name, &[Val::M(m.clone())]) {
        Ok(Val::M(r)) => r,
        other => panic!("{name}: {other:?}"),
    }
}

fn f64_call(name: &str, m: &Mat) -> f64 {
    call(name, &[Val::M(m.clone())]).unwrap().as_f64().unwrap()
}

fn polar(m: &Mat) -> Mat {
    mat_call("polar", m)
}

/// `R` is a rotation: `R^T R = I` and `det R = +1`, to a few ulps (the rotation is assembled
/// from orthonormal vectors, each product adding a rounding error).
fn assert_rotation(r: &Mat, what: &str) {
    let n = r.rows;
    let orth = max_diff(&r.transpose().mul(r), &Mat::identity(n));
    assert!(orth < 20.0 * EPS, "{what}: R^T R - I = {orth:e}");
    let d = f64_call("det", r);
    assert!((d - 1.0).abs() < 20.0 * EPS, "{what}: det R = {d}");
}

/// `R` is the rotation closest to `m`: no small rotation of it increases `tr(R^T m)`
/// (the first-order condition of the closest-rotation problem, and the second order since
/// the perturbations are finite). Tolerance: rounding of the traces, scaled by `|m|`.
fn assert_closest(r: &Mat, m: &Mat, what: &str) {
    let tr = |q: &Mat| {
        let p = q.transpose().mul(m);
        (0..m.rows).map(|i| p.get(i, i)).sum::<f64>()
    };
    let best = tr(r);
    let perturbations: Vec<Mat> = if m.rows == 2 {
        [1e-3, -1e-3, 0.1, -0.1, 2.0]
            .iter()
            .map(|&t| rot2(t))
            .collect()
    } else {
        let mut v = Vec::new();
        for axis in [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
        ] {
            for t in [1e-3, -1e-3, 0.1, -0.1, 2.0] {
                v.push(rot3(axis, t));
            }
        }
        v
    };
    for e in perturbations {
        let other = tr(&r.mul(&e));
        assert!(
            other <= best + 100.0 * EPS * frob(m),
            "{what}: tr(R^T m) = {best}, a perturbed rotation gives {other}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// No built-in panics on arbitrary finite or non-finite inputs of the right types, and a
    /// value has the type `call_type` announced.
    #[test]
    fn no_builtin_panics(
        (k, args) in (0..SAMPLES.len()).prop_flat_map(|k| any_args(SAMPLES[k].1).prop_map(move |a| (k, a)))
    ) {
        check_call(SAMPLES[k].0, &args);
    }

    /// No operator panics on values of accepted types, and the result has the announced type.
    #[test]
    fn no_operator_panics(
        op in prop::sample::select(OPS.to_vec()),
        (a, b) in (prop::sample::select(OPERAND_TYPES.to_vec()), prop::sample::select(OPERAND_TYPES.to_vec()))
            .prop_flat_map(|(a, b)| (any_val(a), any_val(b))),
    ) {
        if let Ok(t) = binop_type(op, a.ty(), b.ty()) {
            if let Ok(v) = binop(op, &a, &b) {
                prop_assert_eq!(v.ty(), t);
            }
        }
        for u in [UnOp::Neg, UnOp::Not] {
            if let Ok(t) = unop_type(u, a.ty()) {
                if let Ok(v) = unop(u, &a) {
                    prop_assert_eq!(v.ty(), t);
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// `inverse(m) * m = I` for random 12x12 matrices made well conditioned by a dominant
    /// diagonal, and for every size 1..=12 with plain random entries. Tolerance: Gauss-Jordan
    /// with partial pivoting has a left residual `|X A - I| <= c n u |X| |A|` (Higham, Accuracy
    /// and Stability, §14.4), so the bound is `n eps |X|_F |A|_F` times a margin of 4; it grows
    /// with the condition number `|X| |A|`.
    #[test]
    fn inverse_times_matrix_is_identity(
        a in any_mat(12, 12),
        signs in prop::collection::vec(any::<bool>(), 12),
        n in 1usize..=12,
        b in any_mat(12, 12),
    ) {
        let mut a = a;
        for (i, s) in signs.into_iter().enumerate() {
            a.set(i, i, a.get(i, i) + if s { 12.0 } else { -12.0 });
        }
        let x = mat_call("inverse", &a);
        let tol = 4.0 * 12.0 * EPS * frob(&x) * frob(&a);
        prop_assert!(frob(&x) * frob(&a) < 100.0, "well conditioned");
        prop_assert!(max_diff(&x.mul(&a), &Mat::identity(12)) < tol);

        let b = Mat { rows: n, cols: n, data: b.data[..n * n].to_vec() };
        if let Ok(Val::M(x)) = call("inverse", &[Val::M(b.clone())]) {
            let tol = 4.0 * n as f64 * EPS * frob(&x) * frob(&b);
            prop_assert!(max_diff(&x.mul(&b), &Mat::identity(n)) <= tol,
                "n = {}, cond = {:e}", n, frob(&x) * frob(&b));
        }
    }

    /// `det(a b) = det(a) det(b)` and `det(a^T) = det(a)` for every size. Tolerance: by
    /// multilinearity, perturbing row `i` by `d_i` moves a determinant by at most
    /// `|d_i| prod_{j != i} |row_j|`; LU and the product `a b` perturb each row by `O(n eps)`
    /// relative to its length, so the bound is `n eps` times Hadamard's bound
    /// (the product of row lengths) of `a` and `b` and of `|a| |b|` (of `a` and `a^T` for the
    /// transpose), times a margin of 8.
    #[test]
    fn det_is_multiplicative(n in 1usize..=12, a in any_mat(12, 12), b in any_mat(12, 12)) {
        let cut = |m: &Mat| Mat { rows: n, cols: n, data: m.data[..n * n].to_vec() };
        let (a, b) = (cut(&a), cut(&b));
        let abs = |m: &Mat| Mat { rows: n, cols: n, data: m.data.iter().map(|x| x.abs()).collect() };
        let (da, db, dab) = (f64_call("det", &a), f64_call("det", &b), f64_call("det", &a.mul(&b)));
        let hadamard = |m: &Mat| (0..n).map(|i| norm(&m.data[i * n..(i + 1) * n])).product::<f64>();
        let scale = hadamard(&a) * hadamard(&b) + hadamard(&abs(&a).mul(&abs(&b)));
        prop_assert!((dab - da * db).abs() <= 8.0 * n as f64 * EPS * scale,
            "{} vs {}", dab, da * db);
        let both = hadamard(&a) + hadamard(&a.transpose());
        prop_assert!((f64_call("det", &a.transpose()) - da).abs() <= 8.0 * n as f64 * EPS * both);
    }

    /// polar: the R of a rotation times an SPD stretch is that rotation (tolerance: the
    /// polar factor's condition number is about `2 / (s_min + s_next)`, at most 10 for
    /// stretches in [0.1, 10], times rounding errors of a few ulps).
    #[test]
    fn polar_recovers_the_rotation(
        r in any_rotation3(),
        q in any_rotation3(),
        d in prop::array::uniform3(0.1..10.0f64),
        t in -3.1..3.1f64,
        q2 in -3.1..3.1f64,
        d2 in prop::array::uniform2(0.1..10.0f64),
    ) {
        let s = q.mul(&diag(&d)).mul(&q.transpose());
        let got = polar(&r.mul(&s));
        prop_assert!(max_diff(&got, &r) < 1e-13, "{:?}", got);
        prop_assert!(max_diff(&polar(&r), &r) < 1e-14);

        let r2 = rot2(t);
        let s2 = rot2(q2).mul(&diag(&d2)).mul(&rot2(q2).transpose());
        prop_assert!(max_diff(&polar(&r2.mul(&s2)), &r2) < 1e-13);
        prop_assert!(max_diff(&polar(&r2), &r2) < 1e-15);
    }

    /// polar of random matrices, of either determinant sign, is a rotation closest to them.
    #[test]
    fn polar_of_random_matrices(m3 in any_mat(3, 3), m2 in any_mat(2, 2)) {
        for m in [m3, m2] {
            let r = polar(&m);
            assert_rotation(&r, "random");
            assert_closest(&r, &m, "random");
        }
    }

    /// polar of rank-deficient and nearly singular matrices (flat and needle elements, and
    /// inverted ones): still a rotation, still the closest one.
    #[test]
    fn polar_of_singular_matrices(
        u in any_rotation3(),
        v in any_rotation3(),
        s in prop::array::uniform3(0.0..2.0f64),
        rank in 0usize..3,
        tiny in prop::sample::select(vec![0.0, 1e-300, 1e-12, -1e-12, 1e-8, -1e-3]),
        t in -3.1..3.1f64,
    ) {
        let mut d = s;
        for x in d.iter_mut().skip(rank) {
            *x = tiny;
        }
        let m = u.mul(&diag(&d)).mul(&v.transpose());
        let r = polar(&m);
        assert_rotation(&r, "singular");
        assert_closest(&r, &m, "singular");
        // A pure rotation in the 2x2 case and a rank-one 2x2.
        let m2 = rot2(t).mul(&diag(&[s[0], tiny]));
        let r2 = polar(&m2);
        assert_rotation(&r2, "singular 2x2");
        assert_closest(&r2, &m2, "singular 2x2");
    }

    /// The symmetric eigenvalues of `Q diag(d) Q^T` are `d` sorted (tolerance: Jacobi is
    /// backward stable, a few ulps of the largest eigenvalue; the test matrix itself carries
    /// rounding errors of the same size).
    #[test]
    fn symmetric_eigenvalues(q in any_rotation3(), d in prop::array::uniform3(-5.0..5.0f64)) {
        let s = q.mul(&diag(&d)).mul(&q.transpose());
        let got = call("eigvals_sym3", &[Val::M(s)]).unwrap();
        let mut want = d;
        want.sort_by(|a, b| b.total_cmp(a));
        let mut x = Vec::new();
        got.to_reals(&mut x);
        for (g, w) in x.iter().zip(want) {
            prop_assert!((g - w).abs() < 64.0 * EPS * 5.0, "{:?} vs {:?}", x, want);
        }
    }
}
