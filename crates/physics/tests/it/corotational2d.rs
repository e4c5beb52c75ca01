//! The co-rotational triangle's Jacobian rules (`corotational_tri_jvp`): the exact differential
//! of its forces (central differences at random large-rotation states, through the interpreter
//! and the compiled plans), a static solve of a plate against an independent linear
//! plane-stress solve assembled here, and implicit Euler with a step far beyond the explicit
//! limit, staying bounded and settling on the static solution.

// Numeric reference code: index loops mirror the math.
#![allow(
    clippy::needless_range_loop,
    clippy::doc_markdown,
    clippy::suboptimal_flops
)]

use crate::common;

use common::model;
use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_physics::{Config, Integrator, Simulation};

fn sim(mesh: &Mesh, thickness: f64, f: impl FnOnce(&mut Config)) -> Simulation {
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let mut cfg = Config {
        models: vec![model("corotational", &[("thickness", thickness)])],
        ..Config::default()
    };
    f(&mut cfg);
    Simulation::new(g, cfg).unwrap()
}

/// A small deterministic generator (xorshift64*), uniform in [-1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let r = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (r >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// The rotation of angle |w| about w (Rodrigues).
fn rotation(w: [f64; 3]) -> [[f64; 3]; 3] {
    let t = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
    let k = [w[0] / t, w[1] / t, w[2] / t];
    let (s, c) = t.sin_cos();
    let mut r = [[0.0; 3]; 3];
    let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
    for i in 0..3 {
        for j in 0..3 {
            let kk: f64 = (0..3).map(|l| kx[i][l] * kx[l][j]).sum();
            r[i][j] = f64::from(u8::from(i == j)) + s * kx[i][j] + (1.0 - c) * kk;
        }
    }
    r
}

fn apply(r: &[[f64; 3]; 3], p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2])
}

fn shift(a: &[[f64; 3]], d: &[[f64; 3]], t: f64) -> Vec<[f64; 3]> {
    a.iter()
        .zip(d)
        .map(|(a, d)| std::array::from_fn(|k| a[k] + t * d[k]))
        .collect()
}

/// The Jacobian-vector product equals central differences of the forces at random deformed
/// states of a 3 x 2 plate: a rigid rotation of up to pi about a random 3D axis (the plane of
/// the triangles turns out of the xy plane, so the in-plane frame moves), random in-plane and
/// out-of-plane vertex displacements of up to 15% of the cell size (strains of tens of
/// percent, the elements not inverted), random directions dx. Step 1e-6 of the size: the
/// truncation error is ~1e-12 and rounding ~1e-10 of the product's scale, so 1e-6 relative
/// to the largest entry is a strict bound that an approximate product (the warped stiffness
/// -R K R^T, which omits dR/dx and the frame's motion: errors of the order of the stress,
/// here ~1e-1 relative) fails. Both through the compiled plans and the interpreter.
#[test]
fn jvp_matches_central_differences_at_large_rotations() {
    let mesh = grid([3, 2], [1.5, 1.0], GridElement::Triangle);
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for compiled in [true, false] {
        let mut s = sim(&mesh, 0.1, |c| {
            c.young = 1e3;
            c.poisson = 0.3;
        });
        s.set_compiled(compiled);
        let rest = s.vertex_vec3("rest").unwrap();
        for trial in 0..6 {
            let w = [rng.next(), rng.next(), rng.next()];
            let n = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            let angle = std::f64::consts::PI * (0.2 + 0.8 * (f64::from(trial) / 5.0));
            let r = rotation([angle * w[0] / n, angle * w[1] / n, angle * w[2] / n]);
            let x: Vec<[f64; 3]> = rest
                .iter()
                .map(|p| {
                    let q = [
                        p[0] + 0.075 * rng.next(),
                        p[1] + 0.075 * rng.next(),
                        0.075 * rng.next(),
                    ];
                    let y = apply(&r, q);
                    [y[0] + 0.3, y[1] - 0.2, y[2] + 0.1]
                })
                .collect();
            let dx: Vec<[f64; 3]> = rest
                .iter()
                .map(|_| [rng.next(), rng.next(), rng.next()])
                .collect();
            let dv = vec![[0.0; 3]; rest.len()];
            let eps = 1e-6;
            let mut force_at = |x: &[[f64; 3]]| {
                s.set_vertex_vec3("position", x).unwrap();
                s.forces().unwrap();
                s.vertex_vec3("force").unwrap()
            };
            let fp = force_at(&shift(&x, &dx, eps));
            let fm = force_at(&shift(&x, &dx, -eps));
            let f0 = force_at(&x);
            let j = s.jvp(&dx, &dv).unwrap();
            let scale = j
                .iter()
                .flat_map(|v| v.iter())
                .fold(0.0f64, |m, x| m.max(x.abs()));
            let fscale = f0
                .iter()
                .flat_map(|v| v.iter())
                .fold(0.0f64, |m, x| m.max(x.abs()));
            assert!(scale > 0.0 && fscale > 0.0, "a deformed state has forces");
            let mut worst = 0.0f64;
            for (a, (p, m)) in j.iter().zip(fp.iter().zip(&fm)) {
                for k in 0..3 {
                    let fd = (p[k] - m[k]) / (2.0 * eps);
                    worst = worst.max((a[k] - fd).abs() / scale);
                }
            }
            assert!(
                worst < 1e-6,
                "compiled {compiled}, trial {trial}: jvp differs from central differences by {worst:e} of its scale"
            );
        }
    }
}

/// Plane-stress stiffness of linear triangles, assembled independently (constant strain,
/// B^T D B A t), dense, on 2 dofs per vertex.
fn assemble_plane_stress(
    pts: &[[f64; 3]],
    tris: &[[usize; 3]],
    young: f64,
    nu: f64,
    t: f64,
) -> Vec<Vec<f64>> {
    let n = 2 * pts.len();
    let mut k = vec![vec![0.0; n]; n];
    let c = young / (1.0 - nu * nu);
    let d = [
        [c, c * nu, 0.0],
        [c * nu, c, 0.0],
        [0.0, 0.0, c * (1.0 - nu) / 2.0],
    ];
    for tri in tris {
        let p = |i: usize| pts[tri[i]];
        let (x, y) = ([p(0)[0], p(1)[0], p(2)[0]], [p(0)[1], p(1)[1], p(2)[1]]);
        let det = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
        let area = det.abs() / 2.0;
        let b = [y[1] - y[2], y[2] - y[0], y[0] - y[1]];
        let cc = [x[2] - x[1], x[0] - x[2], x[1] - x[0]];
        // B (3 x 6): strains (exx, eyy, gxy) from (u0, v0, u1, v1, u2, v2)
        let mut bm = [[0.0; 6]; 3];
        for i in 0..3 {
            bm[0][2 * i] = b[i] / det;
            bm[1][2 * i + 1] = cc[i] / det;
            bm[2][2 * i] = cc[i] / det;
            bm[2][2 * i + 1] = b[i] / det;
        }
        for a in 0..6 {
            for bb in 0..6 {
                let mut s = 0.0;
                for i in 0..3 {
                    for j in 0..3 {
                        s += bm[i][a] * d[i][j] * bm[j][bb];
                    }
                }
                let (ga, gb) = (2 * tri[a / 2] + a % 2, 2 * tri[bb / 2] + bb % 2);
                k[ga][gb] += s * area * t;
            }
        }
    }
    k
}

/// Solves a dense system by Gaussian elimination with partial pivoting.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for col in 0..n {
        let piv = (col..n)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap();
        a.swap(col, piv);
        b.swap(col, piv);
        for i in col + 1..n {
            let f = a[i][col] / a[col][col];
            for j in col..n {
                a[i][j] -= f * a[col][j];
            }
            b[i] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        x[i] = (b[i] - (i + 1..n).map(|j| a[i][j] * x[j]).sum::<f64>()) / a[i][i];
    }
    x
}

/// The row of the simulation holding each input point (matched by rest position).
fn rows_of(mesh: &Mesh, rest: &[[f64; 3]]) -> Vec<usize> {
    mesh.points
        .iter()
        .map(|p| {
            rest.iter()
                .position(|q| (0..3).all(|k| (p[k] - q[k]).abs() < 1e-12))
                .expect("every point is a vertex")
        })
        .collect()
}

/// The linear reference of a plate fixed on x = 0 under the body load m_i g (the masses the
/// simulation lumped): displacements per simulation row.
fn linear_reference(
    mesh: &Mesh,
    s: &Simulation,
    young: f64,
    nu: f64,
    t: f64,
    g: [f64; 3],
) -> Vec<[f64; 3]> {
    let rest = s.vertex_vec3("rest").unwrap();
    let mass = s.vertex_scalar("mass").unwrap();
    let rows = rows_of(mesh, &rest);
    let tris: Vec<[usize; 3]> = mesh
        .cells
        .iter()
        .map(|c| [rows[c[0]], rows[c[1]], rows[c[2]]])
        .collect();
    let k = assemble_plane_stress(&rest, &tris, young, nu, t);
    let free: Vec<usize> = (0..2 * rest.len())
        .filter(|&d| rest[d / 2][0] > 1e-9)
        .collect();
    let kr: Vec<Vec<f64>> = free
        .iter()
        .map(|&i| free.iter().map(|&j| k[i][j]).collect())
        .collect();
    let fr: Vec<f64> = free.iter().map(|&d| mass[d / 2] * g[d % 2]).collect();
    let u = solve(kr, fr);
    let mut full = vec![[0.0; 3]; rest.len()];
    for (i, &d) in free.iter().enumerate() {
        full[d / 2][d % 2] = u[i];
    }
    full
}

/// A static solve of a 4 x 2 plate (thickness 0.1, E = 1e3, nu = 0.3) under a small in-plane
/// body load (displacements ~1e-7 of the plate's size) equals the linear plane-stress solve
/// assembled here, to 1e-6 relative: the co-rotational model differs from the linear one by
/// O(u / L) ~ 1e-7, the Newton stop (1e-10 of the load) and the conjugate-gradient tolerance
/// (1e-12) are far below, and the displacement's rounding is 1e-16 / 1e-7 ~ 1e-9. Static solves
/// of the 2D co-rotational model were refused before it had Jacobian rules.
#[test]
fn static_plate_matches_linear_plane_stress() {
    let (young, nu, t) = (1e3, 0.3, 0.1);
    let gravity = [0.3e-6, -1e-6, 0.0];
    let mesh = grid([4, 2], [2.0, 1.0], GridElement::Triangle);
    for compiled in [true, false] {
        let mut s = sim(&mesh, t, |c| {
            c.young = young;
            c.poisson = nu;
            c.density = 2.0;
            c.gravity = gravity;
            c.fixed = vec!["x < 1e-9".into()];
            c.integrator = Integrator::Static;
        });
        s.set_compiled(compiled);
        s.step().unwrap();
        let rest = s.vertex_vec3("rest").unwrap();
        let x = s.vertex_vec3("position").unwrap();
        let reference = linear_reference(&mesh, &s, young, nu, t, gravity);
        let scale = reference
            .iter()
            .flat_map(|v| v.iter())
            .fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 1e-8 && scale < 1e-5, "the load is small: {scale:e}");
        for i in 0..rest.len() {
            for k in 0..3 {
                let u = x[i][k] - rest[i][k];
                assert!(
                    (u - reference[i][k]).abs() < 1e-6 * scale,
                    "compiled {compiled}, vertex {i} axis {k}: static {u:e} vs linear {:e}",
                    reference[i][k]
                );
            }
        }
    }
}

/// Implicit Euler on the same plate under a large in-plane load (tip displacement ~10% of the
/// plate, so the rotations matter), with a step 100 times the explicit stability limit
/// (~ h sqrt(rho / E) ~ 1e-2 here) and some viscous damping: it runs without a divergence
/// error, every position stays finite and within the plate's reach at every step, and it
/// settles on the static solution of the same load (the co-rotational equilibrium found by
/// Newton) to 1e-6 of the displacement: implicit Euler's fixed point is the static
/// equilibrium.
#[test]
fn implicit_euler_is_stable_and_settles_on_the_static_solution() {
    let (young, nu, t) = (1e3, 0.3, 0.1);
    let gravity = [0.0, -0.4, 0.0];
    let mesh = grid([4, 2], [2.0, 1.0], GridElement::Triangle);
    let setup = |c: &mut Config, integrator: Integrator| {
        c.young = young;
        c.poisson = nu;
        c.density = 2.0;
        c.gravity = gravity;
        c.damping = 2.0;
        c.fixed = vec!["x < 1e-9".into()];
        c.integrator = integrator;
        c.dt = 1.0;
    };
    let mut st = sim(&mesh, t, |c| setup(c, Integrator::Static));
    st.step().unwrap();
    let rest = st.vertex_vec3("rest").unwrap();
    let target = st.vertex_vec3("position").unwrap();
    let umax = target
        .iter()
        .zip(&rest)
        .map(|(x, r)| (x[1] - r[1]).abs())
        .fold(0.0f64, f64::max);
    assert!(umax > 0.05 && umax < 0.5, "a large deflection: {umax}");
    let mut s = sim(&mesh, t, |c| setup(c, Integrator::ImplicitEuler));
    for step in 0..300 {
        s.step().unwrap();
        let x = s.vertex_vec3("position").unwrap();
        assert!(
            x.iter()
                .zip(&rest)
                .all(|(x, r)| (0..3).all(|k| x[k].is_finite() && (x[k] - r[k]).abs() < 3.0)),
            "step {step}: a position left the plate's reach"
        );
    }
    let x = s.vertex_vec3("position").unwrap();
    let err = x
        .iter()
        .zip(&target)
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
        .fold(0.0f64, f64::max);
    assert!(
        err < 1e-6 * umax,
        "implicit Euler settles on the static solution: off by {err:e} (deflection {umax})"
    );
}

/// The Jacobian rule runs through a compiled plan (not the interpreter), like the force rule:
/// static and implicit solves apply it once per conjugate-gradient iteration.
#[test]
fn jvp_rule_runs_through_a_compiled_plan() {
    let mesh = grid([3, 2], [1.5, 1.0], GridElement::Triangle);
    let mut s = sim(&mesh, 0.1, |_| {});
    let n = s.vertex_darts().len();
    s.jvp(&vec![[0.1, 0.2, 0.3]; n], &vec![[0.0; 3]; n])
        .unwrap();
    s.forces().unwrap();
    let kinds = s.rules().plan_kinds();
    for rule in ["corotational_tri", "corotational_tri_jvp"] {
        assert!(
            kinds
                .iter()
                .any(|(name, compiled)| name == rule && *compiled),
            "{rule} is not compiled: {kinds:?}"
        );
    }
}
