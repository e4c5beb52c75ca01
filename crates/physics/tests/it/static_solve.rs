//! Jacobian-vector products against central differences, the implicit integrator's energy,
//! and the cantilever: a static solve against an independent dense linear solve assembled here,
//! converging toward Timoshenko's beam deflection as the mesh is refined.

// Numeric reference code: index loops mirror the math.
#![allow(
    clippy::needless_range_loop,
    clippy::doc_markdown,
    clippy::suboptimal_flops
)]

use crate::common;

use common::model;
use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions, CellKind, Mesh};
use topomech_physics::{Config, Integrator, Simulation};

fn sim(mesh: &Mesh, kind: &str, params: &[(&str, f64)], f: impl FnOnce(&mut Config)) -> Simulation {
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let mut cfg = Config {
        models: vec![model(kind, params)],
        ..Config::default()
    };
    f(&mut cfg);
    Simulation::new(g, cfg).unwrap()
}

/// The Jacobian-vector products of every model agree with central differences of the forces
/// (step 1e-6 of the size: truncation error ~1e-12 relative, rounding ~1e-10): to 1e-6
/// relative. Co-rotational's product is the usual warped stiffness -R K R^T, which omits
/// dR/dx: it is checked at a rigidly rotated state, where it is exact. Shear and linear
/// bending springs share the stretch spring's exact product.
#[test]
fn jvp_matches_central_differences() {
    let tets = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let hexes = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Hexa);
    let quads = topomech_gmap::generators::grid(
        [3, 2],
        [1.5, 1.0],
        topomech_gmap::generators::GridElement::Quad,
    );
    let springs = vec![("stiffness", 1e3), ("damping", 3.0)];
    for (mesh, kind, params) in [
        (&tets, "stretch_elementary", springs.clone()),
        (&tets, "stretch_cumulated", springs.clone()),
        (&tets, "linear_fem", vec![]),
        (&tets, "mass_tensor", vec![]),
        (&tets, "corotational", vec![]),
        (&hexes, "corotational", vec![]),
        (&hexes, "shear_isotropic", springs.clone()),
        (&hexes, "shear_anisotropic", springs.clone()),
        (&hexes, "shear_volumic", springs.clone()),
        (&quads, "bending_linear", springs.clone()),
        (&quads, "shear_isotropic", springs.clone()),
    ] {
        let mut s = sim(mesh, kind, &params, |c| c.young = 1e4);
        let rest = s.vertex_vec3("rest").unwrap();
        let rigid = kind == "corotational";
        let x: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| {
                if rigid {
                    let (sn, cs) = 0.4f64.sin_cos();
                    [cs * p[0] - sn * p[1], sn * p[0] + cs * p[1], p[2]]
                } else {
                    [
                        p[0] + 0.05 * p[1] * p[1],
                        p[1] - 0.03 * p[0],
                        p[2] + 0.02 * p[0] * p[2],
                    ]
                }
            })
            .collect();
        let v: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| [0.1 * p[2], -0.2 * p[0], 0.05])
            .collect();
        let dx: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| [(p[0] * 3.1).sin(), (p[1] + p[2]).cos(), 0.3 * p[0]])
            .collect();
        let dv: Vec<[f64; 3]> = rest.iter().map(|p| [p[1], -p[2], 0.5 * p[0]]).collect();
        let force_at = |s: &mut Simulation, x: &[[f64; 3]], v: &[[f64; 3]]| {
            s.set_vertex_vec3("position", x).unwrap();
            s.set_vertex_vec3("velocity", v).unwrap();
            s.forces().unwrap();
            s.vertex_vec3("force").unwrap()
        };
        let eps = 1e-6;
        let shift = |a: &[[f64; 3]], d: &[[f64; 3]], t: f64| -> Vec<[f64; 3]> {
            a.iter()
                .zip(d)
                .map(|(a, d)| std::array::from_fn(|k| a[k] + t * d[k]))
                .collect()
        };
        let fp = force_at(&mut s, &shift(&x, &dx, eps), &shift(&v, &dv, eps));
        let fm = force_at(&mut s, &shift(&x, &dx, -eps), &shift(&v, &dv, -eps));
        s.set_vertex_vec3("position", &x).unwrap();
        s.set_vertex_vec3("velocity", &v).unwrap();
        let j = s.jvp(&dx, &dv).unwrap();
        let scale = j
            .iter()
            .flat_map(|v| v.iter())
            .fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.0);
        for (a, (p, m)) in j.iter().zip(fp.iter().zip(&fm)) {
            for k in 0..3 {
                let fd = (p[k] - m[k]) / (2.0 * eps);
                assert!(
                    (a[k] - fd).abs() < 1e-6 * scale,
                    "{kind}: jvp {} vs differences {fd}",
                    a[k]
                );
            }
        }
    }
}

/// Implicit Euler on the oscillator of the triangle loses energy (numerical dissipation),
/// where symplectic Euler keeps it (see invariants.rs).
#[test]
fn implicit_euler_dissipates_energy() {
    let mesh = Mesh {
        points: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.5, 0.0]],
        kinds: vec![CellKind::Polygon],
        cells: vec![vec![0, 1, 2]],
    };
    let mut s = sim(&mesh, "stretch_elementary", &[("stiffness", 1e3)], |c| {
        c.gravity = [0.0; 3];
        c.fixed = vec!["y < 1e-9".into()];
        c.integrator = Integrator::ImplicitEuler;
        c.dt = 1e-3;
        c.density = 3.0;
    });
    let mut x = s.vertex_vec3("rest").unwrap();
    let apex = x.iter().position(|p| p[1] > 0.1).unwrap();
    x[apex][1] += 0.01;
    s.set_vertex_vec3("position", &x).unwrap();
    let energy = |s: &mut Simulation| {
        let p = s.vertex_vec3("position").unwrap()[apex];
        let l0 = 0.5f64.hypot(0.5);
        s.kinetic_energy().unwrap()
            + 0.5
                * 1e3
                * ((p[0].hypot(p[1]) - l0).powi(2) + ((p[0] - 1.0).hypot(p[1]) - l0).powi(2))
    };
    let e0 = energy(&mut s);
    for _ in 0..400 {
        s.step().unwrap();
    }
    let e1 = energy(&mut s);
    assert!(e1 < 0.9 * e0, "implicit Euler damps: {e0} -> {e1}");
    assert!(e1 > 0.0);
}

/// Global stiffness of linear tetrahedra, assembled independently (Lame form), dense.
fn assemble(mesh: &Mesh, young: f64, nu: f64) -> Vec<Vec<f64>> {
    let n = 3 * mesh.points.len();
    let mut k = vec![vec![0.0; n]; n];
    let lambda = young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let mu = young / (2.0 * (1.0 + nu));
    for c in &mesh.cells {
        let p = |i: usize| mesh.points[c[i]];
        let e = |i: usize| [p(i)[0] - p(0)[0], p(i)[1] - p(0)[1], p(i)[2] - p(0)[2]];
        let m = [
            [e(1)[0], e(2)[0], e(3)[0]],
            [e(1)[1], e(2)[1], e(3)[1]],
            [e(1)[2], e(2)[2], e(3)[2]],
        ];
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        let mut inv = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                let (r0, r1, c0, c1) = ((j + 1) % 3, (j + 2) % 3, (i + 1) % 3, (i + 2) % 3);
                inv[i][j] = (m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]) / det;
            }
        }
        let mut g = [[0.0; 3]; 4];
        g[1..4].copy_from_slice(&inv);
        for k in 0..3 {
            g[0][k] = -(g[1][k] + g[2][k] + g[3][k]);
        }
        let vol = det.abs() / 6.0;
        for a in 0..4 {
            for b in 0..4 {
                let gab: f64 = (0..3).map(|t| g[a][t] * g[b][t]).sum();
                for i in 0..3 {
                    for j in 0..3 {
                        let delta = if i == j { 1.0 } else { 0.0 };
                        k[3 * c[a] + i][3 * c[b] + j] += vol
                            * (lambda * g[a][i] * g[b][j]
                                + mu * g[b][i] * g[a][j]
                                + mu * gab * delta);
                    }
                }
            }
        }
    }
    k
}

/// Solves the SPD system by Cholesky.
fn cholesky_solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for j in 0..n {
        let d = (a[j][j] - (0..j).map(|k| a[j][k] * a[j][k]).sum::<f64>()).sqrt();
        a[j][j] = d;
        for i in j + 1..n {
            a[i][j] = (a[i][j] - (0..j).map(|k| a[i][k] * a[j][k]).sum::<f64>()) / d;
        }
    }
    for i in 0..n {
        b[i] = (b[i] - (0..i).map(|k| a[i][k] * b[k]).sum::<f64>()) / a[i][i];
    }
    for i in (0..n).rev() {
        b[i] = (b[i] - (i + 1..n).map(|k| a[k][i] * b[k]).sum::<f64>()) / a[i][i];
    }
    b
}

/// The tip deflection (mean vertical displacement of the free end's vertices).
fn tip(points: &[[f64; 3]], disp: impl Fn(usize) -> f64, length: f64) -> f64 {
    let ids: Vec<usize> = (0..points.len())
        .filter(|&i| (points[i][0] - length).abs() < 1e-9)
        .collect();
    ids.iter().map(|&i| disp(i)).sum::<f64>() / ids.len() as f64
}

/// A cantilever under its own weight: the static solve through the rules equals the
/// independent assembled solve to 1e-6 relative (the conjugate-gradient tolerance is 1e-12
/// on the residual; the beam's condition number, below 1e6, bounds the error), and the tip
/// deflection approaches Timoshenko's q L^4 / (8 E I) + q L^2 / (2 k G A) from below (linear
/// tetrahedra are too stiff in bending) as the mesh is refined.
#[test]
fn cantilever_static_deflection() {
    let (length, young, nu, rho, gy): (f64, f64, f64, f64, f64) = (6.0, 1e6, 0.0, 100.0, -9.81);
    let q = rho * gy.abs(); // load per length for a unit square section
    let (inertia, area, kappa, shear) = (1.0 / 12.0, 1.0, 5.0 / 6.0, young / 2.0);
    let timoshenko = q * length.powi(4) / (8.0 * young * inertia)
        + q * length.powi(2) / (2.0 * kappa * shear * area);
    let mut errors = Vec::new();
    for (k, cells) in [[6, 1, 1], [12, 2, 2], [18, 3, 3]].into_iter().enumerate() {
        let mesh = cuboid(cells, [length, 1.0, 1.0], BoxElement::Tetra);
        let mut s = sim(&mesh, "linear_fem", &[], |c| {
            c.young = young;
            c.poisson = nu;
            c.density = rho;
            c.gravity = [0.0, gy, 0.0];
            c.fixed = vec!["x < 1e-9".into()];
            c.integrator = Integrator::Static;
        });
        s.step().unwrap();
        let rest = s.vertex_vec3("rest").unwrap();
        let x = s.vertex_vec3("position").unwrap();
        let ours = -tip(&rest, |i| x[i][1] - rest[i][1], length);
        if k < 2 {
            // the independent solve: K u = f on the free dofs, lumped gravity loads
            let kg = assemble(&mesh, young, nu);
            let n = mesh.points.len();
            let mut mass = vec![0.0; n];
            for c in &mesh.cells {
                let p = |i: usize| mesh.points[c[i]];
                let e = |i: usize| [p(i)[0] - p(0)[0], p(i)[1] - p(0)[1], p(i)[2] - p(0)[2]];
                let (a, b, d) = (e(1), e(2), e(3));
                let vol = (a[0] * (b[1] * d[2] - b[2] * d[1]) - a[1] * (b[0] * d[2] - b[2] * d[0])
                    + a[2] * (b[0] * d[1] - b[1] * d[0]))
                    .abs()
                    / 6.0;
                for &i in c {
                    mass[i] += rho * vol / 4.0;
                }
            }
            let free: Vec<usize> = (0..3 * n)
                .filter(|&d| mesh.points[d / 3][0] > 1e-9)
                .collect();
            let kr: Vec<Vec<f64>> = free
                .iter()
                .map(|&i| free.iter().map(|&j| kg[i][j]).collect())
                .collect();
            let fr: Vec<f64> = free
                .iter()
                .map(|&d| if d % 3 == 1 { mass[d / 3] * gy } else { 0.0 })
                .collect();
            let u = cholesky_solve(kr, fr);
            let mut full = vec![0.0; 3 * n];
            for (k, &d) in free.iter().enumerate() {
                full[d] = u[k];
            }
            let theirs = -tip(&mesh.points, |i| full[3 * i + 1], length);
            assert!(
                (ours - theirs).abs() < 1e-6 * theirs,
                "{cells:?}: rules {ours} vs assembled {theirs}"
            );
        }
        errors.push((timoshenko - ours) / timoshenko);
    }
    eprintln!("Timoshenko tip deflection {timoshenko}, relative errors {errors:?}");
    assert!(
        errors.iter().all(|&e| e > 0.0),
        "linear tets are stiff: {errors:?}"
    );
    assert!(
        errors.windows(2).all(|w| w[1] < w[0]),
        "the error shrinks with refinement: {errors:?}"
    );
}

/// The mean tip deflection (z) of a 1 x 0.2 x 0.2 steel cantilever of tetrahedra moved by
/// `offset` along every axis, clamped at its low-x end, under a tip load of `tip_load` N
/// down z (none: its own weight), solved statically with linear FEM; and whether the solve
/// said it converged.
fn steel_tip(offset: f64, tip_load: Option<f64>) -> (f64, bool) {
    let mut mesh = cuboid([10, 2, 2], [1.0, 0.2, 0.2], BoxElement::Tetra);
    for p in &mut mesh.points {
        for x in p.iter_mut() {
            *x += offset;
        }
    }
    let mut s = sim(&mesh, "linear_fem", &[], |c| {
        c.young = 2e11;
        c.poisson = 0.3;
        c.density = 7800.0;
        c.gravity = if tip_load.is_some() {
            [0.0; 3]
        } else {
            [0.0, 0.0, -9.81]
        };
        c.fixed = vec![format!("x < {offset} + 1e-9")];
        c.integrator = Integrator::Static;
        c.dt = 1.0;
    });
    let rest = s.vertex_vec3("rest").unwrap();
    let at_tip = |p: &[f64; 3]| (p[0] - offset - 1.0).abs() < 1e-9;
    if let Some(load) = tip_load {
        let n = rest.iter().filter(|p| at_tip(p)).count() as f64;
        let f: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| {
                if at_tip(p) {
                    [0.0, 0.0, -load / n]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        s.set_vertex_vec3("f_ext", &f).unwrap();
    }
    s.step().unwrap();
    let x = s.vertex_vec3("position").unwrap();
    let tips: Vec<f64> = (0..rest.len())
        .filter(|&i| at_tip(&rest[i]))
        .map(|i| x[i][2] - rest[i][2])
        .collect();
    let converged = s.solver_report().is_some_and(|r| r.converged);
    (tips.iter().sum::<f64>() / tips.len() as f64, converged)
}

/// The static solve's answer does not depend on where the body is, nor on the load being
/// small (QA). A body far from the origin rounds its forces at the size of its coordinates:
/// moved 100 m (or 10 km) away, the steel cantilever under its own weight stalled at a
/// relative residual of 1e-4 and was refused, where at the origin it converged. And a tip
/// load below the forces' rounding level (1e-5 N on this beam, whose forces round near 1e-5
/// N) was "balanced" at the rest positions, 0 displacement, said converged. Now the
/// deflection at 100 m equals the origin's to 1e-6 relative (positions there resolve it to
/// about ulp(100) / 2e-6 m = 7e-9), at 10 km to 1e-4 (ulp(1e4) / 2e-6 m = 1e-6); and the
/// deflection is linear in the load down to 1e-5 N, to 1e-4 relative (the first Newton step
/// is the linear solve's answer; the next ones correct it by residuals at the forces'
/// rounding level, which moved it by 4e-6 at 1e-3 N and 2e-5 at 1e-5 N in the runs that
/// set this tolerance).
#[test]
fn a_static_solve_does_not_depend_on_where_the_body_is_or_a_small_load() {
    let (home, ok) = steel_tip(0.0, None);
    assert!(ok && home < 0.0, "{home}");
    for (offset, tol) in [(100.0, 1e-6), (1e4, 1e-4)] {
        let (away, ok) = steel_tip(offset, None);
        assert!(ok, "{offset} m: converged");
        assert!(
            ((away - home) / home).abs() < tol,
            "{offset} m: {away} against {home} at the origin"
        );
    }
    let (big, ok) = steel_tip(0.0, Some(1e-3));
    assert!(ok && big < 0.0);
    for load in [1e-4, 1e-5] {
        let (small, ok) = steel_tip(0.0, Some(load));
        assert!(ok, "{load} N: converged");
        let want = big * load / 1e-3;
        assert!(
            ((small - want) / want).abs() < 1e-4,
            "{load} N: {small} against {want} (linear in the load)"
        );
    }
}
