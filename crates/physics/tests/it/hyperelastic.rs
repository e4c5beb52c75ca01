//! Stable Neo-Hookean and St. Venant-Kirchhoff tetrahedra (models/hyperelastic3d.tmr): zero
//! force at rest and under rigid motions, forces equal to minus the gradient of the energy
//! (computed here from the energy alone), exact Jacobian-vector products against central
//! differences, small-strain static and dynamic runs equal to linear FEM (an independent dense
//! solve and the engine's `linear_fem`), and large-deformation static and implicit runs.

// Numeric reference code: index loops and formula-like doc comments mirror the math.
#![allow(
    clippy::needless_range_loop,
    clippy::doc_markdown,
    clippy::suboptimal_flops,
    clippy::many_single_char_names
)]

use crate::common;

use common::{model, norm, sub};
use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_physics::{Config, Integrator, PhysicsError, Simulation};

const KINDS: [&str; 2] = ["neohookean", "stvk"];

type M3 = [[f64; 3]; 3];

fn sim(mesh: &Mesh, kind: &str, f: impl FnOnce(&mut Config)) -> Result<Simulation, PhysicsError> {
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let mut cfg = Config {
        models: vec![model(kind, &[])],
        ..Config::default()
    };
    f(&mut cfg);
    Simulation::new(g, cfg)
}

fn max_abs(v: &[[f64; 3]]) -> f64 {
    v.iter()
        .flat_map(|x| x.iter())
        .fold(0.0f64, |m, x| m.max(x.abs()))
}

fn forces_at(s: &mut Simulation, x: &[[f64; 3]]) -> Vec<[f64; 3]> {
    s.set_vertex_vec3("position", x).unwrap();
    s.forces().unwrap();
    s.vertex_vec3_sum("force").unwrap()
}

/// The rotation by `angle` about the unit axis `w` (Rodrigues).
fn rotation(w: [f64; 3], angle: f64) -> M3 {
    let n = norm(w);
    let k = w.map(|x| x / n);
    let (s, c) = angle.sin_cos();
    let mut r = [[0.0; 3]; 3];
    let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = if i == j { c } else { 0.0 } + s * kx[i][j] + (1.0 - c) * k[i] * k[j];
        }
    }
    r
}

fn apply(r: &M3, p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (0..3).map(|j| r[i][j] * p[j]).sum())
}

/// A large, non-affine deformation of the unit box (stretches, shears, a twist): every element
/// strained by tens of percent, none inverted.
fn large(p: [f64; 3]) -> [f64; 3] {
    let r = rotation([0.3, -1.0, 0.5], 0.9 * p[0]);
    let q = [
        1.3 * p[0] + 0.2 * p[1] * p[1],
        0.8 * p[1] + 0.25 * p[0] * p[2],
        p[2] + 0.3 * p[0] * p[1] - 0.1 * p[2] * p[2],
    ];
    apply(&r, q)
}

/// At rest the forces vanish (P(I) = 0: alpha = 1 + 3 mu / (4 lambda) for Neo-Hookean), and
/// under a rigid motion x = R X + t with a large rotation too (P(R) = R P(I) for both
/// energies, which are rotation invariant): to rounding, 1e-9 of the force scale E h^2
/// (h = 0.5, E = 1e6). A stretch gives forces of order E h^2 (the check can fail).
#[test]
fn zero_force_at_rest_and_under_rigid_motion() {
    let mesh = cuboid([2, 2, 2], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let scale = 1e6 * 0.25;
    for kind in KINDS {
        let mut s = sim(&mesh, kind, |c| c.young = 1e6).unwrap();
        let rest = s.vertex_vec3("rest").unwrap();
        let f = forces_at(&mut s, &rest);
        assert!(
            max_abs(&f) < 1e-9 * scale,
            "{kind} at rest: {}",
            max_abs(&f)
        );
        let r = rotation([1.0, 2.0, -0.5], 2.3);
        let moved: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| {
                let q = apply(&r, *p);
                [q[0] + 3.0, q[1] - 1.0, q[2] + 0.5]
            })
            .collect();
        let f = forces_at(&mut s, &moved);
        assert!(
            max_abs(&f) < 1e-9 * scale,
            "{kind} rotated: {}",
            max_abs(&f)
        );
        let stretched: Vec<[f64; 3]> = rest.iter().map(|p| [1.1 * p[0], p[1], p[2]]).collect();
        let f = forces_at(&mut s, &stretched);
        assert!(
            max_abs(&f) > 1e-3 * scale,
            "{kind} stretched: {}",
            max_abs(&f)
        );
    }
}

fn det(m: &M3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// The edge matrix [p1-p0, p2-p0, p3-p0] (columns).
fn edges(p: [[f64; 3]; 4]) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| p[j + 1][i] - p[0][i]))
}

/// Elastic energy density of each model as a function of F, written from the energies alone
/// (Smith, de Goes & Kim 2018 with their small-strain Lame parameters; Saint Venant-Kirchhoff).
fn energy_density(kind: &str, f: &M3, young: f64, nu: f64) -> f64 {
    let mu = young / (2.0 * (1.0 + nu));
    let lambda = young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let c: M3 =
        std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| f[k][i] * f[k][j]).sum()));
    if kind == "neohookean" {
        let (mu, lambda) = (4.0 / 3.0 * mu, lambda + 5.0 / 6.0 * mu);
        let alpha = 1.0 + 3.0 * mu / (4.0 * lambda);
        let ic = c[0][0] + c[1][1] + c[2][2];
        0.5 * mu * (ic - 3.0) + 0.5 * lambda * (det(f) - alpha).powi(2) - 0.5 * mu * (ic + 1.0).ln()
    } else {
        let e: M3 = std::array::from_fn(|i| {
            std::array::from_fn(|j| 0.5 * (c[i][j] - if i == j { 1.0 } else { 0.0 }))
        });
        let ee: f64 = (0..3)
            .flat_map(|i| (0..3).map(move |j| (i, j)))
            .map(|(i, j)| e[i][j] * e[i][j])
            .sum();
        let tr = e[0][0] + e[1][1] + e[2][2];
        mu * ee + 0.5 * lambda * tr * tr
    }
}

/// The total elastic energy sum_e V_e Psi(F_e), F_e = Ds Dm^-1 (Cramer's rule here).
fn total_energy(
    kind: &str,
    tets: &[Vec<usize>],
    rest: &[[f64; 3]],
    x: &[[f64; 3]],
    young: f64,
    nu: f64,
) -> f64 {
    tets.iter()
        .map(|t| {
            let dm = edges([rest[t[0]], rest[t[1]], rest[t[2]], rest[t[3]]]);
            let ds = edges([x[t[0]], x[t[1]], x[t[2]], x[t[3]]]);
            let d = det(&dm);
            let inv: M3 = std::array::from_fn(|i| {
                std::array::from_fn(|j| {
                    let (r0, r1, c0, c1) = ((j + 1) % 3, (j + 2) % 3, (i + 1) % 3, (i + 2) % 3);
                    (dm[r0][c0] * dm[r1][c1] - dm[r0][c1] * dm[r1][c0]) / d
                })
            });
            let f: M3 = std::array::from_fn(|i| {
                std::array::from_fn(|j| (0..3).map(|k| ds[i][k] * inv[k][j]).sum())
            });
            d.abs() / 6.0 * energy_density(kind, &f, young, nu)
        })
        .sum()
}

/// The forces of the rules are minus the gradient of the energy, computed here from the
/// energy alone by central differences (step 1e-6 on a unit box: truncation ~1e-12, rounding
/// of energies ~1e5 at 1e-16 / 1e-6 ~ 1e-5 absolute against forces ~1e5): to 1e-7 of the
/// largest force, at a large non-affine deformation (strains of tens of percent, twisted).
#[test]
fn forces_are_minus_the_energy_gradient_at_large_deformation() {
    let mesh = cuboid([2, 2, 2], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let (young, nu) = (1e6, 0.3);
    for kind in KINDS {
        let mut s = sim(&mesh, kind, |c| {
            c.young = young;
            c.poisson = nu;
        })
        .unwrap();
        let rest = s.vertex_vec3("rest").unwrap();
        let tets: Vec<Vec<usize>> = s.elements().unwrap().into_iter().map(|e| e.rows).collect();
        assert_eq!(tets.len(), 48);
        let x: Vec<[f64; 3]> = rest.iter().map(|p| large(*p)).collect();
        let f = forces_at(&mut s, &x);
        let scale = max_abs(&f);
        assert!(scale > 1e4, "{kind}: the deformation is large ({scale})");
        let h = 1e-6;
        for v in 0..x.len() {
            for a in 0..3 {
                let mut xp = x.clone();
                let mut xm = x.clone();
                xp[v][a] += h;
                xm[v][a] -= h;
                let g = (total_energy(kind, &tets, &rest, &xp, young, nu)
                    - total_energy(kind, &tets, &rest, &xm, young, nu))
                    / (2.0 * h);
                assert!(
                    (f[v][a] + g).abs() < 1e-7 * scale,
                    "{kind}: vertex {v} axis {a}: rule {} vs -dE/dx {}",
                    f[v][a],
                    -g
                );
            }
        }
    }
}

/// The Jacobian-vector products equal central differences of the forces (step 1e-6 of the
/// unit size: truncation ~1e-12 relative, rounding ~1e-10): to 1e-6 of the largest product,
/// at rest, at a large deformation and at a state with inverted elements (J < 0).
#[test]
fn jvp_matches_central_differences() {
    let mesh = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra);
    for kind in KINDS {
        let mut s = sim(&mesh, kind, |c| c.young = 1e4).unwrap();
        let rest = s.vertex_vec3("rest").unwrap();
        let states: [Vec<[f64; 3]>; 3] = [
            rest.clone(),
            rest.iter().map(|p| large(*p)).collect(),
            // z mirrored on the far half: the elements there are inverted
            rest.iter()
                .map(|p| {
                    if p[0] > 1.5 {
                        [p[0], p[1], 1.0 - 1.4 * p[2]]
                    } else {
                        *p
                    }
                })
                .collect(),
        ];
        let dx: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| [(p[0] * 3.1).sin(), (p[1] + p[2]).cos(), 0.3 * p[0]])
            .collect();
        let dv: Vec<[f64; 3]> = rest.iter().map(|p| [p[1], -p[2], 0.5 * p[0]]).collect();
        let eps = 1e-6;
        for (k, x) in states.iter().enumerate() {
            let shift = |t: f64| -> Vec<[f64; 3]> {
                x.iter()
                    .zip(&dx)
                    .map(|(a, d)| std::array::from_fn(|i| a[i] + t * d[i]))
                    .collect()
            };
            let fp = forces_at(&mut s, &shift(eps));
            let fm = forces_at(&mut s, &shift(-eps));
            s.set_vertex_vec3("position", x).unwrap();
            let j = s.jvp(&dx, &dv).unwrap();
            let scale = max_abs(&j);
            assert!(scale > 1e2, "{kind} state {k}: {scale}");
            for (v, (a, (p, m))) in j.iter().zip(fp.iter().zip(&fm)).enumerate() {
                for i in 0..3 {
                    let fd = (p[i] - m[i]) / (2.0 * eps);
                    assert!(
                        (a[i] - fd).abs() < 1e-6 * scale,
                        "{kind} state {k} vertex {v}: jvp {} vs differences {fd}",
                        a[i]
                    );
                }
            }
        }
    }
}

/// Global stiffness of linear tetrahedra, assembled independently (Lame form), dense.
fn assemble(mesh: &Mesh, young: f64, nu: f64) -> Vec<Vec<f64>> {
    let n = 3 * mesh.points.len();
    let mut k = vec![vec![0.0; n]; n];
    let lambda = young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let mu = young / (2.0 * (1.0 + nu));
    for c in &mesh.cells {
        let m = edges([
            mesh.points[c[0]],
            mesh.points[c[1]],
            mesh.points[c[2]],
            mesh.points[c[3]],
        ]);
        let d = det(&m);
        // rows of Dm^-1: the gradients of the barycentric coordinates 1..3
        let mut g = [[0.0; 3]; 4];
        for i in 0..3 {
            for j in 0..3 {
                let (r0, r1, c0, c1) = ((j + 1) % 3, (j + 2) % 3, (i + 1) % 3, (i + 2) % 3);
                g[i + 1][j] = (m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]) / d;
            }
        }
        for t in 0..3 {
            g[0][t] = -(g[1][t] + g[2][t] + g[3][t]);
        }
        let vol = d.abs() / 6.0;
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

/// The largest distance between two displacement fields, relative to the largest displacement
/// of the second (which must be non-zero).
fn relative_gap(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let scale = b.iter().map(|u| norm(*u)).fold(0.0, f64::max);
    assert!(scale > 0.0);
    a.iter()
        .zip(b)
        .map(|(p, q)| norm(sub(*p, *q)))
        .fold(0.0, f64::max)
        / scale
}

/// A cantilever (6 x 1 x 1, nu = 0.3) under a small load (tip deflection ~1e-6 of the
/// length): the static solves of both models equal linear FEM, solved here by a dense Cholesky
/// on an independently assembled stiffness, to 1e-5 relative. The models differ from linear
/// elasticity by O(strain) ~ 1e-6 (geometric and material nonlinearity); the solver's residual
/// tolerance is 1e-10; measured: 5e-7. A wrong small-strain parametrisation (e.g. Neo-Hookean
/// without the 4/3 and 5/6 of Smith et al.) is off by tens of percent.
#[test]
fn small_strain_static_cantilever_equals_linear_fem() {
    let (length, young, nu, rho, gy) = (6.0, 1e6, 0.3, 100.0, -1e-4);
    let mesh = cuboid([6, 1, 1], [length, 1.0, 1.0], BoxElement::Tetra);
    let kg = assemble(&mesh, young, nu);
    let n = mesh.points.len();
    let mut mass = vec![0.0; n];
    for c in &mesh.cells {
        let e = edges([
            mesh.points[c[0]],
            mesh.points[c[1]],
            mesh.points[c[2]],
            mesh.points[c[3]],
        ]);
        for &i in c {
            mass[i] += rho * det(&e).abs() / 6.0 / 4.0;
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
    let mut reference = vec![[0.0; 3]; n];
    for (k, &d) in free.iter().enumerate() {
        reference[d / 3][d % 3] = u[k];
    }
    let tip = reference.iter().map(|u| norm(*u)).fold(0.0, f64::max);
    assert!(
        tip > 1e-7 * length && tip < 1e-5 * length,
        "small strain: tip {tip}"
    );
    for kind in KINDS {
        let mut s = sim(&mesh, kind, |c| {
            c.young = young;
            c.poisson = nu;
            c.density = rho;
            c.gravity = [0.0, gy, 0.0];
            c.fixed = vec!["x < 1e-9".into()];
            c.integrator = Integrator::Static;
        })
        .unwrap();
        s.step().unwrap();
        assert!(s.solver_report().unwrap().converged);
        let rest = s.vertex_vec3("rest").unwrap();
        let x = s.vertex_vec3("position").unwrap();
        // rows to mesh points through the exact rest positions
        let index: std::collections::HashMap<[u64; 3], usize> = mesh
            .points
            .iter()
            .enumerate()
            .map(|(i, p)| (p.map(f64::to_bits), i))
            .collect();
        let ours: Vec<[f64; 3]> = x.iter().zip(&rest).map(|(p, r)| sub(*p, *r)).collect();
        let theirs: Vec<[f64; 3]> = rest
            .iter()
            .map(|r| reference[index[&r.map(f64::to_bits)]])
            .collect();
        let gap = relative_gap(&ours, &theirs);
        eprintln!("{kind}: relative gap to the linear FEM solve {gap:e}");
        assert!(gap < 1e-5, "{kind}: relative gap to linear FEM {gap:e}");
    }
}

fn cantilever(kind: &str, integrator: Integrator, gy: f64, dt: f64, damping: f64) -> Simulation {
    sim(
        &cuboid([4, 1, 1], [4.0, 1.0, 1.0], BoxElement::Tetra),
        kind,
        |c| {
            c.young = 1e6;
            c.poisson = 0.3;
            c.density = 100.0;
            c.gravity = [0.0, gy, 0.0];
            c.damping = damping;
            c.fixed = vec!["x < 1e-9".into()];
            c.integrator = integrator;
            c.dt = dt;
        },
    )
    .unwrap()
}

fn displacement(s: &Simulation) -> Vec<[f64; 3]> {
    let rest = s.vertex_vec3("rest").unwrap();
    let x = s.vertex_vec3("position").unwrap();
    x.iter().zip(&rest).map(|(p, r)| sub(*p, *r)).collect()
}

/// Every integrator runs both models: at small strain (displacements ~1e-6 of the length) each
/// run equals the same run with the engine's `linear_fem` to 1e-5 relative (the models are
/// linear elasticity to O(strain)); explicit runs 200 steps of dt = 1e-4 (below the stability
/// limit h / c ~ 2e-3), implicit 20 steps of dt = 1e-2, static one solve.
#[test]
fn every_integrator_runs_and_matches_linear_fem_at_small_strain() {
    for (integrator, steps, dt) in [
        (Integrator::ExplicitEuler, 200, 1e-4),
        (Integrator::SymplecticEuler, 200, 1e-4),
        (Integrator::ImplicitEuler, 20, 1e-2),
        (Integrator::Static, 1, 1.0),
    ] {
        let mut lin = cantilever("linear_fem", integrator, -1e-4, dt, 0.5);
        for _ in 0..steps {
            lin.step().unwrap();
        }
        let reference = displacement(&lin);
        for kind in KINDS {
            let mut s = cantilever(kind, integrator, -1e-4, dt, 0.5);
            for _ in 0..steps {
                s.step().unwrap();
            }
            let gap = relative_gap(&displacement(&s), &reference);
            assert!(
                gap < 1e-5,
                "{kind} {integrator:?}: relative gap to linear FEM {gap:e}"
            );
        }
    }
}

/// Large deformation (a tip deflection of ~20% of the length under g = -50): the static solve
/// converges to an equilibrium (the forces, recomputed, balance the weight on every free vertex
/// to 1e-8 of the largest weight), differs visibly from linear FEM (the test is non-linear),
/// and a damped implicit Euler run settles on the same state (to 1e-3 of the deflection).
#[test]
fn large_deformation_static_and_implicit_runs() {
    let gy = -50.0;
    let mut lin = cantilever("linear_fem", Integrator::Static, gy, 1.0, 0.0);
    lin.step().unwrap();
    let linear = displacement(&lin);
    for kind in KINDS {
        let mut s = cantilever(kind, Integrator::Static, gy, 1.0, 0.0);
        s.step().unwrap();
        let u = displacement(&s);
        let tip = u.iter().map(|u| norm(*u)).fold(0.0, f64::max);
        assert!(tip > 0.1 * 4.0, "{kind}: a large deflection ({tip})");
        assert!(
            relative_gap(&u, &linear) > 1e-2,
            "{kind}: non-linear ({:e})",
            relative_gap(&u, &linear)
        );
        let x = s.vertex_vec3("position").unwrap();
        let f = forces_at(&mut s, &x);
        let m = s.vertex_scalar_sum("mass").unwrap();
        let fixed = s.vertex_bool("fixed").unwrap();
        let weight = m.iter().fold(0.0f64, |a, m| a.max(m * gy.abs()));
        for v in 0..f.len() {
            if !fixed[v] {
                let r = [f[v][0], f[v][1] + m[v] * gy, f[v][2]];
                assert!(norm(r) < 1e-8 * weight, "{kind}: vertex {v} residual {r:?}");
            }
        }
        let mut d = cantilever(kind, Integrator::ImplicitEuler, gy, 0.05, 4.0);
        for _ in 0..300 {
            d.step().unwrap();
        }
        let gap = relative_gap(&displacement(&d), &u);
        assert!(gap < 1e-3, "{kind}: implicit run vs static solve {gap:e}");
    }
}

/// A mesh of hexahedra is refused naming the model and what it needs; so is a 2D mesh.
#[test]
fn meshes_without_tetrahedra_are_refused() {
    for kind in KINDS {
        let e = sim(
            &cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Hexa),
            kind,
            |_| {},
        )
        .unwrap_err();
        assert!(
            e.to_string().contains(&format!(
                "model '{kind}' matches nothing on this mesh: it needs tetrahedra"
            )),
            "{e}"
        );
        let e = sim(
            &cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Mixed),
            kind,
            |_| {},
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("the others would get no force"),
            "{e}"
        );
        let e = sim(
            &cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Tetra),
            kind,
            |c| {
                c.models[0]
                    .params
                    .insert("stiffness".into(), topomech_rules::Val::F(1.0));
            },
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .contains(&format!("model '{kind}' has no parameter 'stiffness'")),
            "{e}"
        );
    }
}

/// The rules of both models run through compiled plans (none left to the interpreter), and
/// an implicit Euler run (forces and Jacobian-vector products) through them equals the
/// interpreter's bit for bit.
#[test]
fn compiled_plans_match_the_interpreter_bit_for_bit() {
    for kind in KINDS {
        let run = |compiled: bool| {
            let mut s = cantilever(kind, Integrator::ImplicitEuler, -50.0, 0.05, 1.0);
            s.set_compiled(compiled);
            for _ in 0..3 {
                s.step().unwrap();
            }
            s
        };
        let fast = run(true);
        let interpreted: Vec<(String, bool)> = fast
            .rules()
            .plan_kinds()
            .into_iter()
            .filter(|(_, c)| !c)
            .collect();
        assert!(
            interpreted.is_empty(),
            "{kind}: rules left to the interpreter: {interpreted:?}"
        );
        let used: Vec<String> = fast
            .rules()
            .plan_kinds()
            .into_iter()
            .map(|(n, _)| n)
            .collect();
        assert!(
            used.iter().any(|n| n == &format!("{kind}_jvp")),
            "{kind}: {used:?}"
        );
        let slow = run(false);
        let (a, b) = (displacement(&fast), displacement(&slow));
        assert!(max_abs(&a) > 1e-3, "{kind}: it moves");
        for (i, (p, q)) in a.iter().zip(&b).enumerate() {
            assert_eq!(
                p.map(f64::to_bits),
                q.map(f64::to_bits),
                "{kind}: vertex {i} differs"
            );
        }
    }
}
