//! Built-in element math for the physical models: what a rule cannot express concisely
//! (an element stiffness matrix), never where data lives — the topology and the data
//! placement stay in the rules.
//!
//! - Linear tetrahedron, small displacements: constant-strain element, K = V B^T D B with
//!   isotropic Hooke's law (Zienkiewicz & Taylor, *The Finite Element Method*, vol. 1; the
//!   model of O'Brien & Hodgins, SIGGRAPH 1999, doi:10.1145/311535.311550).
//! - Co-rotational helpers (Müller & Gross, GI 2004): 12-vectors and the block-diagonal
//!   rotation of a tetrahedron's four nodes.

// Index loops mirror the textbook formulas (B, D, K entries) and read more clearly here.
#![allow(clippy::needless_range_loop)]

use crate::value::{EvalError, Mat, Ty, Val};

/// The element built-ins, as (name, signature, description).
pub const CATALOGUE: &[(&str, &str, &str)] = &[
    (
        "tet_volume",
        "tet_volume(x0: vec3, x1: vec3, x2: vec3, x3: vec3) -> f64",
        "Signed volume det(x1-x0, x2-x0, x3-x0) / 6 of a tetrahedron.",
    ),
    (
        "tet_stiffness",
        "tet_stiffness(x0: vec3, x1: vec3, x2: vec3, x3: vec3, young: num, poisson: num) -> mat12",
        "Stiffness matrix V B^T D B of a linear tetrahedron with rest vertices x0..x3, isotropic \
         linear elasticity (Young's modulus, Poisson ratio); node-major (x0, y0, z0, x1, ...); \
         error if the tetrahedron is degenerate or the Poisson ratio is not in (-1, 0.5).",
    ),
    (
        "tri_stiffness",
        "tri_stiffness(p0: vec2, p1: vec2, p2: vec2, young: num, poisson: num, thickness: num) -> mat6",
        "Plane-stress stiffness matrix t A B^T D B of a linear triangle with rest vertices p0..p2 \
         (in its plane), node-major (x0, y0, x1, ...); error if degenerate or the Poisson ratio \
         is not in (-1, 0.5).",
    ),
    (
        "vec6",
        "vec6(a: vec2, b: vec2, c: vec2) -> mat6x1",
        "The 6-column (a, b, c): the nodal vector of a triangle in its plane.",
    ),
    (
        "blockdiag3",
        "blockdiag3(r: mat2) -> mat6",
        "The 6x6 block-diagonal matrix with r on its three diagonal blocks.",
    ),
    (
        "hex_stiffness_block",
        "hex_stiffness_block(x0: vec3, x1: vec3, x2: vec3, x3: vec3, x4: vec3, x5: vec3, x6: vec3, x7: vec3, young: num, poisson: num, bi: i64, bj: i64) -> mat12",
        "Block (bi, bj) (each 0 or 1: nodes 0-3 or 4-7) of the 24x24 stiffness of a trilinear \
         hexahedron with rest vertices x0..x7 (bottom cycle, then the top vertex above each; \
         either orientation), isotropic linear elasticity, 2x2x2 Gauss quadrature; error if \
         the element is degenerate or twisted.",
    ),
    (
        "hex_center_gradients",
        "hex_center_gradients(x0: vec3, x1: vec3, x2: vec3, x3: vec3, x4: vec3, x5: vec3, x6: vec3, x7: vec3, half: i64) -> mat3x4",
        "Gradients (columns) of the shape functions of nodes 4 half .. 4 half + 3 at the centre \
         of a hexahedron with rest vertices x0..x7: F = sum_i x_i g_i^T is its deformation \
         gradient there.",
    ),
    (
        "mat_from_cols4",
        "mat_from_cols4(a: vec3, b: vec3, c: vec3, d: vec3) -> mat3x4",
        "The 3x4 matrix with columns a, b, c, d.",
    ),
    (
        "spring_force",
        "spring_force(xa: vec3, xb: vec3, va: vec3, vb: vec3, k: num, c: num, l0: num) -> vec3",
        "The force on a of a spring a-b with stiffness k, rest length l0 and damping c (Provot \
         1995): (k (l - l0) + c (vb - va) . u) u, u the unit vector from a to b.",
    ),
    (
        "spring_jvp",
        "spring_jvp(xa: vec3, xb: vec3, va: vec3, vb: vec3, dxa: vec3, dxb: vec3, dva: vec3, dvb: vec3, k: num, c: num, l0: num) -> vec3",
        "The derivative of spring_force in the direction (dxa, dxb, dva, dvb): exact, damping \
         included.",
    ),
    (
        "vec12",
        "vec12(a: vec3, b: vec3, c: vec3, d: vec3) -> mat12x1",
        "The 12-column (a, b, c, d): the nodal vector of a tetrahedron.",
    ),
    (
        "blockdiag4",
        "blockdiag4(r: mat3) -> mat12",
        "The 12x12 block-diagonal matrix with r on its four diagonal blocks (one rotation for \
         the four nodes of a tetrahedron).",
    ),
];

/// The result type of an element built-in, `None` if unknown or the arguments do not fit.
pub fn result_type(name: &str, args: &[Ty]) -> Option<Ty> {
    let num = |t: &Ty| matches!(t, Ty::F64 | Ty::I64);
    match (name, args) {
        ("tet_volume", [Ty::Vec3, Ty::Vec3, Ty::Vec3, Ty::Vec3]) => Some(Ty::F64),
        ("tet_stiffness", [Ty::Vec3, Ty::Vec3, Ty::Vec3, Ty::Vec3, e, nu]) if num(e) && num(nu) => {
            Some(Ty::Mat(12, 12))
        }
        ("vec12", [Ty::Vec3, Ty::Vec3, Ty::Vec3, Ty::Vec3]) => Some(Ty::Mat(12, 1)),
        ("spring_force", a)
            if a.len() == 7 && a[..4].iter().all(|t| *t == Ty::Vec3) && a[4..].iter().all(num) =>
        {
            Some(Ty::Vec3)
        }
        ("spring_jvp", a)
            if a.len() == 11 && a[..8].iter().all(|t| *t == Ty::Vec3) && a[8..].iter().all(num) =>
        {
            Some(Ty::Vec3)
        }
        ("tri_stiffness", [Ty::Vec2, Ty::Vec2, Ty::Vec2, e, nu, t])
            if num(e) && num(nu) && num(t) =>
        {
            Some(Ty::Mat(6, 6))
        }
        ("vec6", [Ty::Vec2, Ty::Vec2, Ty::Vec2]) => Some(Ty::Mat(6, 1)),
        ("hex_stiffness_block", a)
            if a.len() == 12
                && a[..8].iter().all(|t| *t == Ty::Vec3)
                && num(&a[8])
                && num(&a[9])
                && a[10] == Ty::I64
                && a[11] == Ty::I64 =>
        {
            Some(Ty::Mat(12, 12))
        }
        ("hex_center_gradients", a)
            if a.len() == 9 && a[..8].iter().all(|t| *t == Ty::Vec3) && a[8] == Ty::I64 =>
        {
            Some(Ty::Mat(3, 4))
        }
        ("mat_from_cols4", [Ty::Vec3, Ty::Vec3, Ty::Vec3, Ty::Vec3]) => Some(Ty::Mat(3, 4)),
        ("blockdiag3", [Ty::Mat(2, 2)]) => Some(Ty::Mat(6, 6)),
        ("blockdiag4", [Ty::Mat(3, 3)]) => Some(Ty::Mat(12, 12)),
        _ => None,
    }
}

fn v3(v: &Val) -> Option<[f64; 3]> {
    match v {
        Val::V3(x) => Some(*x),
        _ => None,
    }
}

fn num(v: &Val) -> Option<f64> {
    match v {
        Val::F(x) => Some(*x),
        Val::I(i) => Some(*i as f64),
        _ => None,
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn det3(c: [[f64; 3]; 3]) -> f64 {
    // columns c[0], c[1], c[2]
    c[0][0] * (c[1][1] * c[2][2] - c[2][1] * c[1][2])
        - c[1][0] * (c[0][1] * c[2][2] - c[2][1] * c[0][2])
        + c[2][0] * (c[0][1] * c[1][2] - c[1][1] * c[0][2])
}

/// Evaluates an element built-in: `Ok(None)` if `name` is not one or the arguments do not fit.
pub fn eval(name: &str, args: &[Val]) -> Result<Option<Val>, EvalError> {
    Ok(match (name, args) {
        ("tet_volume", [a, b, c, d]) => {
            let (Some(a), Some(b), Some(c), Some(d)) = (v3(a), v3(b), v3(c), v3(d)) else {
                return Ok(None);
            };
            Some(Val::F(det3([sub(b, a), sub(c, a), sub(d, a)]) / 6.0))
        }
        ("tet_stiffness", [a, b, c, d, e, nu]) => {
            let (Some(a), Some(b), Some(c), Some(d), Some(e), Some(nu)) =
                (v3(a), v3(b), v3(c), v3(d), num(e), num(nu))
            else {
                return Ok(None);
            };
            Some(Val::M(tet_stiffness([a, b, c, d], e, nu)?))
        }
        ("tri_stiffness", [a, b, c, e, nu, t]) => {
            let (Val::V2(a), Val::V2(b), Val::V2(c), Some(e), Some(nu), Some(t)) =
                (a, b, c, num(e), num(nu), num(t))
            else {
                return Ok(None);
            };
            Some(Val::M(tri_stiffness([*a, *b, *c], e, nu, t)?))
        }
        ("spring_force", a) if a.len() == 7 => {
            let (Some(xa), Some(xb), Some(va), Some(vb), Some(k), Some(c), Some(l0)) = (
                v3(&a[0]),
                v3(&a[1]),
                v3(&a[2]),
                v3(&a[3]),
                num(&a[4]),
                num(&a[5]),
                num(&a[6]),
            ) else {
                return Ok(None);
            };
            // (the dot products are `builtins::dot`'s, as the compiled plans' are: see
            // `Compiler::spring` in compiled.rs)
            let d = sub(xb, xa);
            let l = crate::builtins::dot(&d, &d).sqrt();
            let u = [d[0] / l, d[1] / l, d[2] / l];
            let dv = sub(vb, va);
            let s = k * (l - l0) + c * crate::builtins::dot(&dv, &u);
            Some(Val::V3([s * u[0], s * u[1], s * u[2]]))
        }
        ("spring_jvp", a) if a.len() == 11 => {
            let mut v = [[0.0; 3]; 8];
            for (k, x) in a[..8].iter().enumerate() {
                let Some(x) = v3(x) else { return Ok(None) };
                v[k] = x;
            }
            let (Some(k), Some(c), Some(l0)) = (num(&a[8]), num(&a[9]), num(&a[10])) else {
                return Ok(None);
            };
            Some(Val::V3(spring_jvp(&v, k, c, l0)))
        }
        ("hex_stiffness_block", a) if a.len() == 12 => {
            let Some(x) = hex_points(&a[..8]) else {
                return Ok(None);
            };
            let (Some(e), Some(nu), Val::I(bi), Val::I(bj)) =
                (num(&a[8]), num(&a[9]), &a[10], &a[11])
            else {
                return Ok(None);
            };
            if !(0..2).contains(bi) || !(0..2).contains(bj) {
                return Err(EvalError(format!(
                    "hex_stiffness_block: block ({bi}, {bj}) is not in 0..2"
                )));
            }
            let k = hex_stiffness(&x, e, nu)?;
            let mut m = Mat::zeros(12, 12);
            for i in 0..12 {
                for j in 0..12 {
                    m.set(i, j, k[12 * *bi as usize + i][12 * *bj as usize + j]);
                }
            }
            Some(Val::M(m))
        }
        ("hex_center_gradients", a) if a.len() == 9 => {
            let Some(x) = hex_points(&a[..8]) else {
                return Ok(None);
            };
            let Val::I(half) = a[8] else { return Ok(None) };
            if !(0..2).contains(&half) {
                return Err(EvalError(format!(
                    "hex_center_gradients: half {half} is not 0 or 1"
                )));
            }
            let (g, _) = hex_gradients(&x, [0.0; 3])?;
            let mut m = Mat::zeros(3, 4);
            for c in 0..4 {
                for r in 0..3 {
                    m.set(r, c, g[4 * half as usize + c][r]);
                }
            }
            Some(Val::M(m))
        }
        ("mat_from_cols4", [a, b, c, d]) => {
            let (Some(a), Some(b), Some(c), Some(d)) = (v3(a), v3(b), v3(c), v3(d)) else {
                return Ok(None);
            };
            let mut m = Mat::zeros(3, 4);
            for (j, col) in [a, b, c, d].iter().enumerate() {
                for r in 0..3 {
                    m.set(r, j, col[r]);
                }
            }
            Some(Val::M(m))
        }
        ("vec6", [Val::V2(a), Val::V2(b), Val::V2(c)]) => Some(Val::M(Mat {
            rows: 6,
            cols: 1,
            data: vec![a[0], a[1], b[0], b[1], c[0], c[1]],
        })),
        ("blockdiag3", [Val::M(r)]) if r.rows == 2 && r.cols == 2 => {
            let mut m = Mat::zeros(6, 6);
            for k in 0..3 {
                for i in 0..2 {
                    for j in 0..2 {
                        m.set(2 * k + i, 2 * k + j, r.get(i, j));
                    }
                }
            }
            Some(Val::M(m))
        }
        ("vec12", [a, b, c, d]) => {
            let (Some(a), Some(b), Some(c), Some(d)) = (v3(a), v3(b), v3(c), v3(d)) else {
                return Ok(None);
            };
            let data = [a, b, c, d].concat();
            Some(Val::M(Mat {
                rows: 12,
                cols: 1,
                data,
            }))
        }
        ("blockdiag4", [Val::M(r)]) if r.rows == 3 && r.cols == 3 => {
            let mut m = Mat::zeros(12, 12);
            for k in 0..4 {
                for i in 0..3 {
                    for j in 0..3 {
                        m.set(3 * k + i, 3 * k + j, r.get(i, j));
                    }
                }
            }
            Some(Val::M(m))
        }
        _ => None,
    })
}

/// The error for an element whose size measure (`det`) is not finite: a non-finite node
/// coordinate when there is one, else an overflow of f64 (finite coordinates so far apart
/// that their products exceed `f64::MAX`), never "degenerate".
fn beyond_f64<'a>(what: &str, coords: impl Iterator<Item = &'a f64>, det: f64) -> EvalError {
    let mut magnitude: f64 = 0.0;
    for &c in coords {
        if !c.is_finite() {
            return EvalError(format!("{what}: a node coordinate is {c}"));
        }
        magnitude = magnitude.max(c.abs());
    }
    EvalError(format!(
        "{what}: its size overflows f64 (determinant {det:e}, coordinates up to {magnitude:.3e})"
    ))
}

/// The linear-elastic stiffness of a tetrahedron (see the module docs).
pub fn tet_stiffness(x: [[f64; 3]; 4], young: f64, poisson: f64) -> Result<Mat, EvalError> {
    if !(poisson > -1.0 && poisson < 0.5 && young.is_finite()) {
        return Err(EvalError(format!(
            "tet_stiffness: Poisson ratio {poisson} must be in (-1, 0.5) and Young's modulus finite ({young})"
        )));
    }
    let cols = [sub(x[1], x[0]), sub(x[2], x[0]), sub(x[3], x[0])];
    let det = det3(cols);
    let scale = cols
        .iter()
        .map(|c| c.iter().map(|v| v * v).sum::<f64>())
        .sum::<f64>()
        .powf(1.5);
    if !det.is_finite() || !scale.is_finite() {
        return Err(beyond_f64(
            "tet_stiffness: tetrahedron",
            x.iter().flatten(),
            det,
        ));
    }
    if det.abs() <= 1e-14 * scale {
        return Err(EvalError(format!(
            "tet_stiffness: degenerate tetrahedron (6 V = {det:e})"
        )));
    }
    // inverse of the edge matrix Dm (columns x1-x0, x2-x0, x3-x0): its rows are the
    // gradients of the barycentric coordinates N1, N2, N3
    let m = |i: usize, j: usize| cols[j][i];
    let cof = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        m(r0, c0) * m(r1, c1) - m(r0, c1) * m(r1, c0)
    };
    let mut grad = [[0.0; 3]; 4];
    for a in 0..3 {
        for k in 0..3 {
            // (Dm^-1)[a][k] = cofactor(k, a) / det
            grad[a + 1][k] = cof(k, a) / det;
        }
    }
    for k in 0..3 {
        grad[0][k] = -(grad[1][k] + grad[2][k] + grad[3][k]);
    }
    let vol = det.abs() / 6.0;
    // B: 6 x 12 strain-displacement matrix (engineering shear strains)
    let mut bm = [[0.0; 12]; 6];
    for (a, g) in grad.iter().enumerate() {
        let c = 3 * a;
        bm[0][c] = g[0];
        bm[1][c + 1] = g[1];
        bm[2][c + 2] = g[2];
        bm[3][c] = g[1];
        bm[3][c + 1] = g[0];
        bm[4][c + 1] = g[2];
        bm[4][c + 2] = g[1];
        bm[5][c] = g[2];
        bm[5][c + 2] = g[0];
    }
    let f = young / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
    let (d0, d1, d2) = (
        f * (1.0 - poisson),
        f * poisson,
        f * (1.0 - 2.0 * poisson) / 2.0,
    );
    let d = [
        [d0, d1, d1, 0.0, 0.0, 0.0],
        [d1, d0, d1, 0.0, 0.0, 0.0],
        [d1, d1, d0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, d2, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, d2, 0.0],
        [0.0, 0.0, 0.0, 0.0, 0.0, d2],
    ];
    let mut db = [[0.0; 12]; 6];
    for i in 0..6 {
        for j in 0..12 {
            db[i][j] = (0..6).map(|k| d[i][k] * bm[k][j]).sum();
        }
    }
    let mut k = Mat::zeros(12, 12);
    for i in 0..12 {
        for j in 0..12 {
            k.set(i, j, vol * (0..6).map(|s| bm[s][i] * db[s][j]).sum::<f64>());
        }
    }
    Ok(k)
}

/// d/ds of the spring force at (xa + s dxa, xb + s dxb, va + s dva, vb + s dvb): with
/// d = xb - xa, u = d / l, P w = w - (u.w) u, w = dxb - dxa, z = dvb - dva, dv = vb - va:
/// k [(1 - l0/l) P w + (u.w) u] + (c / l) [(dv.P w) u + (dv.u) P w] + c (u.z) u.
fn spring_jvp(v: &[[f64; 3]; 8], k: f64, c: f64, l0: f64) -> [f64; 3] {
    // `builtins::dot`, as the compiled plans' (see `Compiler::spring` in compiled.rs)
    let dot = |a: [f64; 3], b: [f64; 3]| crate::builtins::dot(&a, &b);
    let d = sub(v[1], v[0]);
    let l = dot(d, d).sqrt();
    let u = d.map(|x| x / l);
    let w = sub(v[5], v[4]);
    let z = sub(v[7], v[6]);
    let dv = sub(v[3], v[2]);
    let uw = dot(u, w);
    let pw: [f64; 3] = std::array::from_fn(|i| w[i] - uw * u[i]);
    let (dvpw, dvu, uz) = (dot(dv, pw), dot(dv, u), dot(u, z));
    std::array::from_fn(|i| {
        k * ((1.0 - l0 / l) * pw[i] + uw * u[i])
            + (c / l) * (dvpw * u[i] + dvu * pw[i])
            + c * uz * u[i]
    })
}

fn hex_points(a: &[Val]) -> Option<[[f64; 3]; 8]> {
    let mut x = [[0.0; 3]; 8];
    for (k, v) in a.iter().enumerate() {
        x[k] = v3(v)?;
    }
    Some(x)
}

/// Natural coordinates of the nodes of a hexahedron, VTK order.
const HEX_NODES: [[f64; 3]; 8] = [
    [-1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0],
    [1.0, 1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
    [1.0, -1.0, 1.0],
    [1.0, 1.0, 1.0],
    [-1.0, 1.0, 1.0],
];

/// Gradients of the 8 trilinear shape functions at natural point `xi`, and det J.
fn hex_gradients(x: &[[f64; 3]; 8], xi: [f64; 3]) -> Result<([[f64; 3]; 8], f64), EvalError> {
    let mut dn = [[0.0; 3]; 8]; // dN/dxi
    for (i, n) in HEX_NODES.iter().enumerate() {
        let f = |k: usize| 1.0 + xi[k] * n[k];
        dn[i] = [
            n[0] * f(1) * f(2) / 8.0,
            n[1] * f(0) * f(2) / 8.0,
            n[2] * f(0) * f(1) / 8.0,
        ];
    }
    // J[r][c] = d x_r / d xi_c
    let mut j = [[0.0; 3]; 3];
    for i in 0..8 {
        for r in 0..3 {
            for c in 0..3 {
                j[r][c] += x[i][r] * dn[i][c];
            }
        }
    }
    let det = j[0][0] * (j[1][1] * j[2][2] - j[1][2] * j[2][1])
        - j[0][1] * (j[1][0] * j[2][2] - j[1][2] * j[2][0])
        + j[0][2] * (j[1][0] * j[2][1] - j[1][1] * j[2][0]);
    if !det.is_finite() {
        return Err(beyond_f64("hexahedron", x.iter().flatten(), det));
    }
    if det == 0.0 {
        return Err(EvalError(format!(
            "hexahedron: the Jacobian determinant is {det:e} (degenerate element)"
        )));
    }
    // inverse of J
    let mut ji = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            let (r0, r1, c0, c1) = ((c + 1) % 3, (c + 2) % 3, (r + 1) % 3, (r + 2) % 3);
            ji[r][c] = (j[r0][c0] * j[r1][c1] - j[r0][c1] * j[r1][c0]) / det;
        }
    }
    // dN/dx = J^-T dN/dxi
    let mut g = [[0.0; 3]; 8];
    for i in 0..8 {
        for a in 0..3 {
            g[i][a] = (0..3).map(|c| ji[c][a] * dn[i][c]).sum();
        }
    }
    Ok((g, det))
}

/// The 24x24 linear-elastic stiffness of a trilinear hexahedron (2x2x2 Gauss).
pub fn hex_stiffness(
    x: &[[f64; 3]; 8],
    young: f64,
    poisson: f64,
) -> Result<Vec<Vec<f64>>, EvalError> {
    if !(poisson > -1.0 && poisson < 0.5 && young.is_finite()) {
        return Err(EvalError(format!(
            "hex stiffness: Poisson ratio {poisson} must be in (-1, 0.5)"
        )));
    }
    let lambda = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
    let mu = young / (2.0 * (1.0 + poisson));
    let q = 1.0 / 3.0f64.sqrt();
    let mut k = vec![vec![0.0; 24]; 24];
    // either orientation of the node numbering: integrate |det J|, but one sign throughout
    let (_, sign) = hex_gradients(x, [0.0; 3])?;
    for gp in HEX_NODES {
        let (g, det) = hex_gradients(x, [q * gp[0], q * gp[1], q * gp[2]])?;
        // the signs compared, not multiplied: for an element of size 1e-55 both are about
        // 1e-165 and their product underflowed to 0, calling it twisted (QA)
        if det == 0.0 || (det > 0.0) != (sign > 0.0) {
            return Err(EvalError(
                "hexahedron: the Jacobian changes sign inside the element (a twisted element)"
                    .into(),
            ));
        }
        let det = det.abs();
        for a in 0..8 {
            for b in 0..8 {
                let gab: f64 = (0..3).map(|t| g[a][t] * g[b][t]).sum();
                for i in 0..3 {
                    for j in 0..3 {
                        let delta = if i == j { 1.0 } else { 0.0 };
                        k[3 * a + i][3 * b + j] += det
                            * (lambda * g[a][i] * g[b][j]
                                + mu * g[a][j] * g[b][i]
                                + mu * gab * delta);
                    }
                }
            }
        }
    }
    Ok(k)
}

/// The plane-stress stiffness of a linear triangle (constant strain), thickness `t`.
pub fn tri_stiffness(p: [[f64; 2]; 3], young: f64, poisson: f64, t: f64) -> Result<Mat, EvalError> {
    if !(poisson > -1.0 && poisson < 0.5 && young.is_finite() && t.is_finite()) {
        return Err(EvalError(format!(
            "tri_stiffness: Poisson ratio {poisson} must be in (-1, 0.5), Young's modulus and thickness finite"
        )));
    }
    let (a, b) = (
        [p[1][0] - p[0][0], p[1][1] - p[0][1]],
        [p[2][0] - p[0][0], p[2][1] - p[0][1]],
    );
    let det = a[0] * b[1] - a[1] * b[0];
    let scale = a[0] * a[0] + a[1] * a[1] + b[0] * b[0] + b[1] * b[1];
    if !det.is_finite() || !scale.is_finite() {
        return Err(beyond_f64(
            "tri_stiffness: triangle",
            p.iter().flatten(),
            det,
        ));
    }
    if det.abs() <= 1e-14 * scale {
        return Err(EvalError(format!(
            "tri_stiffness: degenerate triangle (2 A = {det:e})"
        )));
    }
    // gradients of the barycentric coordinates: rows of the inverse edge matrix
    let inv = [[b[1] / det, -b[0] / det], [-a[1] / det, a[0] / det]];
    let g = [
        [-(inv[0][0] + inv[1][0]), -(inv[0][1] + inv[1][1])],
        inv[0],
        inv[1],
    ];
    let area = det.abs() / 2.0;
    let mut bm = [[0.0; 6]; 3];
    for (k, gk) in g.iter().enumerate() {
        bm[0][2 * k] = gk[0];
        bm[1][2 * k + 1] = gk[1];
        bm[2][2 * k] = gk[1];
        bm[2][2 * k + 1] = gk[0];
    }
    let f = young / (1.0 - poisson * poisson);
    let d = [
        [f, f * poisson, 0.0],
        [f * poisson, f, 0.0],
        [0.0, 0.0, f * (1.0 - poisson) / 2.0],
    ];
    let mut k = Mat::zeros(6, 6);
    for i in 0..6 {
        for j in 0..6 {
            let mut x = 0.0;
            for r in 0..3 {
                for c in 0..3 {
                    x += bm[r][i] * d[r][c] * bm[c][j];
                }
            }
            k.set(i, j, t * area * x);
        }
    }
    Ok(k)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit() -> [[f64; 3]; 4] {
        [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ]
    }

    fn mul(k: &Mat, u: &[f64]) -> Vec<f64> {
        (0..12)
            .map(|i| (0..12).map(|j| k.get(i, j) * u[j]).sum())
            .collect()
    }

    /// K is symmetric and its null space holds the six rigid motions: translations and
    /// infinitesimal rotations give zero force (to rounding: entries are O(E), so 1e-9 E).
    /// A hexahedron's stiffness scales with its size (K ~ E L): a unit cube and the same cube
    /// scaled by 1e-55 and 1e-90 give K / L equal to 1e-12 relative (a few hundred rounded
    /// products each). At 1e-55 it was refused as twisted: the product of two Jacobian
    /// determinants of about 1e-165 underflowed to 0 (QA).
    #[test]
    fn hex_stiffness_of_tiny_cubes_scales_with_their_size() {
        let cube: [[f64; 3]; 8] = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        let k1 = hex_stiffness(&cube, 1e6, 0.3).expect("a unit cube");
        let big = k1.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs()));
        for s in [1e-55, 1e-90] {
            let x = cube.map(|p| p.map(|v| v * s));
            let ks = hex_stiffness(&x, 1e6, 0.3).unwrap_or_else(|e| panic!("scale {s}: {e:?}"));
            for (r1, rs) in k1.iter().zip(&ks) {
                for (a, b) in r1.iter().zip(rs) {
                    assert!(
                        (b / s - a).abs() <= 1e-12 * big,
                        "scale {s}: {a} against {}",
                        b / s
                    );
                }
            }
        }
    }

    #[test]
    fn stiffness_is_symmetric_with_rigid_null_space() {
        let x = [
            [0.1, 0.2, 0.0],
            [1.3, 0.1, 0.2],
            [0.2, 1.1, -0.1],
            [0.3, 0.2, 0.9],
        ];
        let k = tet_stiffness(x, 1e6, 0.3).unwrap();
        for i in 0..12 {
            for j in 0..12 {
                assert!((k.get(i, j) - k.get(j, i)).abs() < 1e-9 * 1e6);
            }
        }
        for t in 0..3 {
            let u: Vec<f64> = (0..12)
                .map(|i| if i % 3 == t { 1.0 } else { 0.0 })
                .collect();
            assert!(mul(&k, &u).iter().all(|f| f.abs() < 1e-9 * 1e6));
        }
        for axis in 0..3 {
            let w = [
                f64::from(u8::from(axis == 0)),
                f64::from(u8::from(axis == 1)),
                f64::from(u8::from(axis == 2)),
            ];
            let u: Vec<f64> = x
                .iter()
                .flat_map(|p| {
                    [
                        w[1] * p[2] - w[2] * p[1],
                        w[2] * p[0] - w[0] * p[2],
                        w[0] * p[1] - w[1] * p[0],
                    ]
                })
                .collect();
            assert!(
                mul(&k, &u).iter().all(|f| f.abs() < 1e-9 * 1e6),
                "rotation about axis {axis}"
            );
        }
    }

    /// A uniaxial stretch `u_x = e x` of the unit tetrahedron: the strain energy `u^T K u / 2` is
    /// V (lambda + 2 mu) e^2 / 2, the energy density of a laterally constrained stretch.
    #[test]
    fn energy_of_a_uniform_stretch() {
        let (young, nu, e) = (1000.0, 0.25, 0.01);
        let k = tet_stiffness(unit(), young, nu).unwrap();
        let u: Vec<f64> = unit().iter().flat_map(|p| [e * p[0], 0.0, 0.0]).collect();
        let ku = mul(&k, &u);
        let energy: f64 = 0.5 * u.iter().zip(&ku).map(|(a, b)| a * b).sum::<f64>();
        let lambda = young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
        let mu = young / (2.0 * (1.0 + nu));
        let expected = (1.0 / 6.0) * 0.5 * (lambda + 2.0 * mu) * e * e;
        assert!(
            (energy - expected).abs() < 1e-12 * expected.max(1.0),
            "{energy} vs {expected}"
        );
    }

    /// The triangle's stiffness has the three plane rigid motions in its null space, and a
    /// uniaxial stretch stores the plane-stress energy t A E e^2 / (2 (1 - nu^2)).
    #[test]
    fn triangle_stiffness_rigid_modes_and_energy() {
        let p = [[0.1, 0.0], [1.2, 0.3], [0.4, 0.9]];
        let k = tri_stiffness(p, 1e3, 0.3, 0.01).unwrap();
        let mul = |u: &[f64]| -> Vec<f64> {
            (0..6)
                .map(|i| (0..6).map(|j| k.get(i, j) * u[j]).sum())
                .collect()
        };
        for u in [
            [1.0, 0.0, 1.0, 0.0, 1.0, 0.0],
            [0.0, 1.0, 0.0, 1.0, 0.0, 1.0],
        ] {
            assert!(mul(&u).iter().all(|f| f.abs() < 1e-12 * 1e3));
        }
        let rot: Vec<f64> = p.iter().flat_map(|q| [-q[1], q[0]]).collect();
        assert!(mul(&rot).iter().all(|f| f.abs() < 1e-12 * 1e3));
        let e = 0.01;
        let u: Vec<f64> = p.iter().flat_map(|q| [e * q[0], 0.0]).collect();
        let energy: f64 = 0.5 * u.iter().zip(mul(&u)).map(|(a, b)| a * b).sum::<f64>();
        let area = 0.5 * ((1.1f64) * 0.9 - 0.3 * 0.3);
        let expected = 0.01 * area * 1e3 * e * e / (2.0 * (1.0 - 0.09));
        assert!(
            (energy - expected).abs() < 1e-12 * expected,
            "{energy} vs {expected}"
        );
    }

    #[test]
    fn degenerate_and_bad_material_are_errors() {
        let flat = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        assert!(tet_stiffness(flat, 1.0, 0.3).is_err());
        assert!(tet_stiffness(unit(), 1.0, 0.5).is_err());
        assert!(tet_stiffness(unit(), f64::NAN, 0.3).is_err());
    }
}
