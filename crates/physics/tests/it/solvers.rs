//! The linear solvers of the implicit Euler and static steps (cg, pcg with Jacobi and
//! block-Jacobi preconditioners, the assembled sparse direct solve) against references
//! written here: the Jacobian built column by column from the models' Jacobian-vector
//! products and a dense Gaussian elimination, on small tetrahedral meshes (a few dozen
//! tetrahedra) for springs, linear FEM and co-rotational FEM.

// Numeric reference code: index loops mirror the math; the mass matrix holds the masses
// themselves (exact comparison).
#![allow(clippy::needless_range_loop, clippy::doc_markdown, clippy::float_cmp)]

use crate::common;

use common::model;
use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_physics::{
    Config, Csr, Integrator, LinearSolver, PhysicsError, Preconditioner, Simulation,
};

/// The models checked, with parameters that give a well-posed problem on the beam.
fn models() -> Vec<(&'static str, Vec<(&'static str, f64)>)> {
    vec![
        (
            "stretch_elementary",
            vec![("stiffness", 1e3), ("damping", 3.0)],
        ),
        ("linear_fem", vec![]),
        ("corotational", vec![]),
    ]
}

/// A 4 x 2 x 1 box of 1 m cubes split into tetrahedra (a few dozen), its vertices at x = 0
/// fixed.
fn sim(kind: &str, params: &[(&str, f64)], f: impl FnOnce(&mut Config)) -> Simulation {
    let mesh = cuboid([4, 2, 1], [4.0, 2.0, 1.0], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let mut cfg = Config {
        models: vec![model(kind, params)],
        young: 1e4,
        density: 10.0,
        fixed: vec!["x < 1e-9".into()],
        ..Config::default()
    };
    f(&mut cfg);
    Simulation::new(g, cfg).unwrap()
}

/// Moves the free vertices off their rest positions by a smooth field (a bend and a twist,
/// so that springs are stretched and co-rotational elements rotated) and gives them a
/// velocity (for the damping terms).
fn perturb(s: &mut Simulation) {
    let rest = s.vertex_vec3("rest").unwrap();
    let fixed = s.vertex_bool("fixed").unwrap();
    let x: Vec<[f64; 3]> = rest
        .iter()
        .zip(&fixed)
        .map(|(p, &f)| {
            if f {
                *p
            } else {
                [
                    p[0] + 0.02 * p[1],
                    p[1] - 0.03 * p[0] * p[0] + 0.01 * p[2],
                    p[2] + 0.02 * p[0] * p[1],
                ]
            }
        })
        .collect();
    let v: Vec<[f64; 3]> = rest
        .iter()
        .zip(&fixed)
        .map(|(p, &f)| {
            if f {
                [0.0; 3]
            } else {
                [0.1 * p[1], -0.2 * p[0], 0.05]
            }
        })
        .collect();
    s.set_vertex_vec3("position", &x).unwrap();
    s.set_vertex_vec3("velocity", &v).unwrap();
}

/// The dense `3V x 3V` matrix of `(dx, dv) -> jvp(hx dx, hv dx)`, column by column.
fn dense_jacobian(s: &mut Simulation, hx: f64, hv: f64) -> Vec<Vec<f64>> {
    let n = s.n_vertices();
    let mut cols = vec![vec![0.0; 3 * n]; 3 * n];
    for j in 0..n {
        for b in 0..3 {
            let mut dx = vec![[0.0; 3]; n];
            let mut dv = vec![[0.0; 3]; n];
            dx[j][b] = hx;
            dv[j][b] = hv;
            let r = s.jvp(&dx, &dv).unwrap();
            for i in 0..n {
                for a in 0..3 {
                    cols[3 * j + b][3 * i + a] = r[i][a];
                }
            }
        }
    }
    // row-major
    (0..3 * n)
        .map(|i| (0..3 * n).map(|j| cols[j][i]).collect())
        .collect()
}

fn csr_dense(m: &Csr) -> Vec<Vec<f64>> {
    let mut d = vec![vec![0.0; m.n]; m.n];
    for i in 0..m.n {
        for p in m.indptr[i]..m.indptr[i + 1] {
            d[i][m.indices[p]] = m.data[p];
        }
        assert!(
            m.indices[m.indptr[i]..m.indptr[i + 1]]
                .windows(2)
                .all(|w| w[0] < w[1]),
            "row {i}'s columns are sorted"
        );
    }
    d
}

/// Gaussian elimination with partial pivoting.
fn dense_solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = b.len();
    for k in 0..n {
        let p = (k..n)
            .max_by(|&i, &j| a[i][k].abs().total_cmp(&a[j][k].abs()))
            .unwrap();
        a.swap(k, p);
        b.swap(k, p);
        for i in k + 1..n {
            let f = a[i][k] / a[k][k];
            for j in k..n {
                a[i][j] -= f * a[k][j];
            }
            b[i] -= f * b[k];
        }
    }
    let mut x = vec![0.0; n];
    for k in (0..n).rev() {
        let s: f64 = (k + 1..n).map(|j| a[k][j] * x[j]).sum();
        x[k] = (b[k] - s) / a[k][k];
    }
    x
}

fn max_abs(v: impl IntoIterator<Item = f64>) -> f64 {
    v.into_iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// The stiffness matrix assembled by compressed probing (a distance-2 coloring, 3 products
/// per color) equals the dense matrix built one column per degree of freedom from the same
/// rules, and so does the damping matrix: both are sums of the same products, so they agree
/// to rounding (1e-12 of the largest entry). The mass matrix is the lumped masses, 3 times
/// each.
#[test]
fn assembled_matrices_equal_dense_jvp_columns() {
    for (kind, params) in models() {
        let mut s = sim(kind, &params, |_| {});
        perturb(&mut s);
        let k = csr_dense(&s.stiffness_matrix().unwrap());
        let want = dense_jacobian(&mut s, 1.0, 0.0);
        let scale = max_abs(want.iter().flatten().copied());
        assert!(scale > 0.0);
        let err = max_abs(
            k.iter()
                .flatten()
                .zip(want.iter().flatten())
                .map(|(k, w)| k + w),
        );
        assert!(
            err <= 1e-12 * scale,
            "{kind}: K differs by {err:e} (scale {scale:e})"
        );
        let d = csr_dense(&s.damping_matrix().unwrap());
        let want = dense_jacobian(&mut s, 0.0, 1.0);
        let dscale = max_abs(want.iter().flatten().copied()).max(f64::MIN_POSITIVE);
        let err = max_abs(
            d.iter()
                .flatten()
                .zip(want.iter().flatten())
                .map(|(d, w)| d + w),
        );
        assert!(err <= 1e-12 * dscale, "{kind}: D differs by {err:e}");
        let m = s.mass_matrix().unwrap();
        let masses = s.vertex_scalar_sum("mass").unwrap();
        assert_eq!(m.n, 3 * masses.len());
        for i in 0..m.n {
            assert_eq!(m.indices[m.indptr[i]..m.indptr[i + 1]], [i]);
            assert_eq!(m.data[m.indptr[i]], masses[i / 3]);
        }
    }
}

/// The solver settings compared.
fn solvers() -> Vec<(LinearSolver, Preconditioner)> {
    vec![
        (LinearSolver::Cg, Preconditioner::BlockJacobi),
        (LinearSolver::Pcg, Preconditioner::Jacobi),
        (LinearSolver::Pcg, Preconditioner::BlockJacobi),
        (LinearSolver::Direct, Preconditioner::BlockJacobi),
    ]
}

/// One implicit Euler step with each linear solver equals the step computed here with a
/// dense Gaussian elimination of `((1 + h c) M - h^2 df/dx - h df/dv) dv = h (f + h df/dx v)`
/// on the free degrees of freedom. The iterative solvers run to a relative residual of
/// 1e-13; the matrix (mass plus a small stiffness) has a condition number below 1e3 here,
/// so the error is below 1e-10 of the velocity change: checked to 1e-8 (of the largest
/// position change), as the direct solve is.
#[test]
fn implicit_step_of_each_solver_equals_a_dense_solve() {
    for (kind, params) in models() {
        let dt = 0.05;
        let mut reference = sim(kind, &params, |c| {
            c.integrator = Integrator::ImplicitEuler;
            c.dt = dt;
        });
        perturb(&mut reference);
        let s = &mut reference;
        let n = s.n_vertices();
        let x = s.vertex_vec3("position").unwrap();
        let v = s.vertex_vec3("velocity").unwrap();
        let m = s.vertex_scalar_sum("mass").unwrap();
        let fixed = s.vertex_bool("fixed").unwrap();
        s.forces().unwrap();
        let f = s.vertex_vec3_sum("force").unwrap();
        let g = s.config().gravity;
        let jx = dense_jacobian(s, 1.0, 0.0);
        let jv = dense_jacobian(s, 0.0, 1.0);
        let free: Vec<usize> = (0..3 * n).filter(|&d| !fixed[d / 3]).collect();
        let a: Vec<Vec<f64>> = free
            .iter()
            .map(|&i| {
                free.iter()
                    .map(|&j| {
                        let mass = if i == j { m[i / 3] } else { 0.0 };
                        mass - dt * dt * jx[i][j] - dt * jv[i][j]
                    })
                    .collect()
            })
            .collect();
        let b: Vec<f64> = free
            .iter()
            .map(|&i| {
                let kv: f64 = (0..3 * n).map(|j| jx[i][j] * v[j / 3][j % 3]).sum();
                dt * (f[i / 3][i % 3] + m[i / 3] * g[i % 3] + dt * kv)
            })
            .collect();
        let dv = dense_solve(a, b);
        let mut want = x.clone();
        for (q, &i) in free.iter().enumerate() {
            want[i / 3][i % 3] = x[i / 3][i % 3] + dt * (v[i / 3][i % 3] + dv[q]);
        }
        let moved = max_abs(
            want.iter()
                .flatten()
                .zip(x.iter().flatten())
                .map(|(w, x)| w - x),
        );
        for (solver, pre) in solvers() {
            let mut s = sim(kind, &params, |c| {
                c.integrator = Integrator::ImplicitEuler;
                c.dt = dt;
                c.linear_solver = solver;
                c.preconditioner = pre;
                c.tolerance = Some(1e-13);
            });
            perturb(&mut s);
            s.step().unwrap();
            let got = s.vertex_vec3("position").unwrap();
            let err = max_abs(
                got.iter()
                    .flatten()
                    .zip(want.iter().flatten())
                    .map(|(g, w)| g - w),
            );
            let r = s.solver_report().unwrap().clone();
            assert!(
                err <= 1e-8 * moved,
                "{kind} {solver:?} {pre:?}: the step differs by {err:e} (moved {moved:e}); {r:?}"
            );
            assert!(r.converged, "{kind} {solver:?}: {r:?}");
            let name = match solver {
                LinearSolver::Cg => "cg",
                LinearSolver::Pcg => "pcg",
                _ => "direct",
            };
            assert_eq!(r.linear_solver, name);
            assert_eq!(
                r.preconditioner,
                if solver == LinearSolver::Pcg {
                    pre.name()
                } else {
                    "none"
                }
            );
            if solver == LinearSolver::Direct {
                assert_eq!(r.linear_iterations, 0);
            } else {
                assert!(r.linear_iterations > 0);
                assert_eq!(r.linear_iterations, r.iterations);
            }
        }
    }
}

/// A static solve under gravity with each linear solver reaches the same equilibrium: the
/// Newton tolerance is 1e-13 of the load, and the stiffness' condition number on this mesh is
/// below 1e4, so the positions agree to 1e-8 of the deflection.
#[test]
fn static_solves_of_each_solver_agree() {
    for (kind, params) in models() {
        let mut results = Vec::new();
        for (solver, pre) in solvers() {
            let mut s = sim(kind, &params, |c| {
                c.integrator = Integrator::Static;
                c.linear_solver = solver;
                c.preconditioner = pre;
                c.tolerance = Some(1e-13);
            });
            s.step()
                .unwrap_or_else(|e| panic!("{kind} {solver:?}: {e}"));
            let r = s.solver_report().unwrap().clone();
            assert!(r.converged, "{kind} {solver:?}: {r:?}");
            let rest = s.vertex_vec3("rest").unwrap();
            let u: Vec<[f64; 3]> = s
                .vertex_vec3("position")
                .unwrap()
                .iter()
                .zip(&rest)
                .map(|(x, p)| std::array::from_fn(|a| x[a] - p[a]))
                .collect();
            results.push((solver, pre, u));
        }
        let direct = &results[3].2;
        let deflection = max_abs(direct.iter().flatten().copied());
        assert!(deflection > 1e-6, "{kind}: it deflects ({deflection:e})");
        for (solver, pre, u) in &results {
            let err = max_abs(
                u.iter()
                    .flatten()
                    .zip(direct.iter().flatten())
                    .map(|(a, b)| a - b),
            );
            assert!(
                err <= 1e-8 * deflection,
                "{kind} {solver:?} {pre:?}: differs from direct by {err:e} (deflection {deflection:e})"
            );
        }
    }
}

/// An iterative solve stopped by `max_iterations` before the tolerance still takes the step
/// (with the solution found) and reports `converged: false` with its residual.
#[test]
fn implicit_step_short_of_iterations_reports_not_converged() {
    let mut s = sim("corotational", &[], |c| {
        c.integrator = Integrator::ImplicitEuler;
        c.dt = 0.05;
        c.linear_solver = LinearSolver::Cg;
        c.tolerance = Some(1e-12);
        c.max_iterations = Some(1);
    });
    perturb(&mut s);
    let before = s.vertex_vec3("position").unwrap();
    s.step().unwrap();
    assert_eq!(s.steps(), 1);
    assert_ne!(s.vertex_vec3("position").unwrap(), before);
    let r = s.solver_report().unwrap();
    assert!(!r.converged, "{r:?}");
    assert_eq!(r.iterations, 1);
    assert!(r.relative_residual > 1e-12 && r.relative_residual.is_finite());
}

/// A static solve with no fixed vertex under gravity has no equilibrium (its stiffness is
/// singular: rigid motions): with each solver it fails with `Diverged`, the state kept,
/// naming the relative residual and saying that no vertex is held (no vertex is to blame:
/// none is named), and the report says converged false with the residual.
#[test]
fn static_solve_that_cannot_converge_is_diverged_with_the_residual() {
    for (solver, pre) in solvers() {
        let mut s = sim("linear_fem", &[], |c| {
            c.integrator = Integrator::Static;
            c.fixed.clear();
            c.linear_solver = solver;
            c.preconditioner = pre;
        });
        let before = s.vertex_vec3("position").unwrap();
        let e = s.step().unwrap_err();
        let PhysicsError::Diverged { vertex, why, .. } = &e else {
            panic!("{solver:?}: {e}");
        };
        assert!(vertex.is_none(), "{e}");
        assert!(why.contains("relative residual"), "{e}");
        assert!(why.contains("no vertex is held"), "{e}");
        // the direct solver was tried (direct, or auto's first try): not suggested again
        if matches!(solver, LinearSolver::Direct | LinearSolver::Auto) {
            assert!(!why.contains("the linear solver direct"), "{solver:?}: {e}");
        }
        assert_eq!(s.vertex_vec3("position").unwrap(), before);
        let r = s.solver_report().unwrap();
        assert!(!r.converged && r.residual > 0.0, "{r:?}");
        // held nowhere: no finite-difference retry, and the report says so
        assert_eq!(r.jacobian, "rules", "{r:?}");
    }
}

/// `tolerance` outside (0, 1) and `max_iterations` 0 are refused when the simulation is
/// built, naming the scene key.
#[test]
fn out_of_range_settings_are_refused_naming_the_key() {
    for t in [0.0, 1.0, -1e-6, f64::NAN, f64::INFINITY] {
        let mesh = cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Tetra);
        let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let cfg = Config {
            models: vec![model("linear_fem", &[])],
            tolerance: Some(t),
            ..Config::default()
        };
        let e = Simulation::new(g, cfg).unwrap_err();
        assert!(
            matches!(&e, PhysicsError::Config(m) if m.contains("integrator.tolerance")),
            "{t}: {e}"
        );
    }
    let mesh = cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("linear_fem", &[])],
        max_iterations: Some(0),
        ..Config::default()
    };
    let e = Simulation::new(g, cfg).unwrap_err();
    assert!(
        matches!(&e, PhysicsError::Config(m) if m.contains("integrator.max_iterations")),
        "{e}"
    );
    for (s, want) in [
        ("auto", Some(LinearSolver::Auto)),
        ("cg", Some(LinearSolver::Cg)),
        ("pcg", Some(LinearSolver::Pcg)),
        ("direct", Some(LinearSolver::Direct)),
        ("lu", None),
    ] {
        assert_eq!(LinearSolver::parse(s), want);
    }
    assert_eq!(
        Preconditioner::parse("jacobi"),
        Some(Preconditioner::Jacobi)
    );
    assert_eq!(
        Preconditioner::parse("block_jacobi"),
        Some(Preconditioner::BlockJacobi)
    );
    assert_eq!(Preconditioner::parse("ilu"), None);
}

/// A static solve of a mechanism (hexahedra held at x = 0 with stretch springs only: every
/// cube can shear) under gravity: the stiffness is singular although the body is held on a
/// plane. With `auto`, the direct solver finds it singular and conjugate gradients are
/// tried next; when the solve fails, its advice must not suggest the direct solver, which
/// was tried (it did before: the conjugate gradients' message suggested it).
#[test]
fn a_failed_auto_solve_does_not_suggest_the_direct_solver_it_tried() {
    let mesh = cuboid([3, 1, 1], [3.0, 1.0, 1.0], BoxElement::Hexa);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("stretch_elementary", &[("stiffness", 1e3)])],
        density: 10.0,
        fixed: vec!["x < 1e-9".into()],
        integrator: Integrator::Static,
        linear_solver: LinearSolver::Auto,
        ..Config::default()
    };
    let mut s = Simulation::new(g, cfg).unwrap();
    let e = s
        .step()
        .expect_err("a mechanism has no static equilibrium under gravity");
    let PhysicsError::Diverged { why, .. } = &e else {
        panic!("{e}");
    };
    assert!(!why.contains("the linear solver direct"), "{e}");
    assert!(
        why.contains("the direct solver found the stiffness singular"),
        "{e}"
    );
}
