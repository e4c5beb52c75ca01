//! Every model against a hand-written flat-array reference of the same model (written here,
//! independent of the rules and of the element built-ins): storing everything in the G-map
//! changes nothing. Same mesh, same parameters, same integrator (symplectic Euler), 100 steps;
//! positions agree to 1e-10 relative to the displacement scale. Both sides do the same
//! arithmetic up to the order of floating-point sums, so the only difference is rounding,
//! amplified over 100 steps of a stable system: far below 1e-10.

// Numeric reference code: index loops and formula-like doc comments mirror the math.
#![allow(
    clippy::needless_range_loop,
    clippy::doc_markdown,
    clippy::suboptimal_flops
)]

use crate::common;

use common::{add, cross, dot, norm, scale, sub, V3};
use std::collections::HashMap;

use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, CellKind, Mesh};
use topomech_physics::{Config, Integrator, ModelSpec, Simulation};

type M3 = [[f64; 3]; 3];

fn m_mul(a: &M3, b: &M3) -> M3 {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}
fn m_t(a: &M3) -> M3 {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[j][i];
        }
    }
    c
}
fn m_det(a: &M3) -> f64 {
    dot(
        [a[0][0], a[1][0], a[2][0]],
        cross([a[0][1], a[1][1], a[2][1]], [a[0][2], a[1][2], a[2][2]]),
    )
}
fn m_inv(a: &M3) -> M3 {
    let d = m_det(a);
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let (r0, r1, c0, c1) = ((j + 1) % 3, (j + 2) % 3, (i + 1) % 3, (i + 2) % 3);
            c[i][j] = (a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]) / d;
        }
    }
    c
}
fn m_v(a: &M3, v: V3) -> V3 {
    [dot(a[0], v), dot(a[1], v), dot(a[2], v)]
}
fn cols(a: V3, b: V3, c: V3) -> M3 {
    [[a[0], b[0], c[0]], [a[1], b[1], c[1]], [a[2], b[2], c[2]]]
}

/// Polar rotation by Higham's iteration X <- (X + X^-T) / 2 (det > 0 here).
fn polar(f: &M3) -> M3 {
    let mut x = *f;
    for _ in 0..100 {
        let it = m_t(&m_inv(&x));
        let mut n = [[0.0; 3]; 3];
        let mut delta: f64 = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                n[i][j] = 0.5 * (x[i][j] + it[i][j]);
                delta = delta.max((n[i][j] - x[i][j]).abs());
            }
        }
        x = n;
        if delta < 1e-15 {
            break;
        }
    }
    x
}

/// The faces of each cell kind as local vertex cycles (orientation irrelevant for springs).
fn local_faces(kind: CellKind, n: usize) -> Vec<Vec<usize>> {
    match kind {
        CellKind::Tetra => vec![vec![0, 1, 2], vec![0, 1, 3], vec![1, 2, 3], vec![0, 2, 3]],
        CellKind::Hexa => vec![
            vec![0, 1, 2, 3],
            vec![4, 5, 6, 7],
            vec![0, 1, 5, 4],
            vec![1, 2, 6, 5],
            vec![2, 3, 7, 6],
            vec![3, 0, 4, 7],
        ],
        CellKind::Polygon => vec![(0..n).collect()],
        _ => unimplemented!("not used in these tests"),
    }
}

/// A hexahedron of the reference: vertices (VTK order), 24x24 stiffness, centre gradients.
type Hex = ([usize; 8], Vec<Vec<f64>>, [V3; 8]);

/// The flat-array simulation: arrays of points, per-vertex masses, springs, tetrahedra.
struct Reference {
    x: Vec<V3>,
    rest: Vec<V3>,
    v: Vec<V3>,
    m: Vec<f64>,
    fixed: Vec<bool>,
    springs: Vec<(usize, usize, f64, f64, f64)>,
    /// tets: vertices, rest edge-matrix inverse, element stiffness in Lame form per block
    tets: Vec<([usize; 4], M3, [[M3; 4]; 4])>,
    corot: bool,
    /// hexahedra: vertices (VTK order), 24x24 stiffness, shape gradients at the centre
    hexes: Vec<Hex>,
    gravity: V3,
    dt: f64,
}

impl Reference {
    fn new(mesh: &Mesh, density: f64, fixed_x_below: f64, gravity: V3, dt: f64) -> Self {
        let n = mesh.points.len();
        let mut m = vec![0.0; n];
        for (kind, c) in mesh.kinds.iter().zip(&mesh.cells) {
            let measure = match kind {
                CellKind::Tetra => {
                    let p = |i: usize| mesh.points[c[i]];
                    m_det(&cols(sub(p(1), p(0)), sub(p(2), p(0)), sub(p(3), p(0)))).abs() / 6.0
                }
                CellKind::Polygon => {
                    // fan from the first vertex (convex polygons)
                    (1..c.len() - 1)
                        .map(|k| {
                            0.5 * norm(cross(
                                sub(mesh.points[c[k]], mesh.points[c[0]]),
                                sub(mesh.points[c[k + 1]], mesh.points[c[0]]),
                            ))
                        })
                        .sum()
                }
                CellKind::Hexa => {
                    // an axis-aligned box cell in these tests
                    let (a, b) = (mesh.points[c[0]], mesh.points[c[6]]);
                    ((b[0] - a[0]) * (b[1] - a[1]) * (b[2] - a[2])).abs()
                }
                _ => unimplemented!(),
            };
            for &i in c {
                m[i] += density * measure / c.len() as f64;
            }
        }
        Reference {
            x: mesh.points.clone(),
            rest: mesh.points.clone(),
            v: vec![[0.0; 3]; n],
            m,
            fixed: mesh.points.iter().map(|p| p[0] < fixed_x_below).collect(),
            springs: Vec::new(),
            tets: Vec::new(),
            corot: false,
            hexes: Vec::new(),
            gravity,
            dt,
        }
    }

    /// One elementary spring per side of every face of every cell.
    fn add_springs(&mut self, mesh: &Mesh, k: f64, c: f64) {
        for (kind, cell) in mesh.kinds.iter().zip(&mesh.cells) {
            for f in local_faces(*kind, cell.len()) {
                for j in 0..f.len() {
                    let (a, b) = (cell[f[j]], cell[f[(j + 1) % f.len()]]);
                    self.springs
                        .push((a, b, k, c, norm(sub(self.rest[b], self.rest[a]))));
                }
            }
        }
    }

    /// The two diagonals of every quad face of every cell.
    fn add_quad_diagonals(&mut self, mesh: &Mesh, k: f64, c: f64) {
        for (kind, cell) in mesh.kinds.iter().zip(&mesh.cells) {
            for f in local_faces(*kind, cell.len()) {
                if f.len() == 4 {
                    for (i, j) in [(0, 2), (1, 3)] {
                        let (a, b) = (cell[f[i]], cell[f[j]]);
                        self.springs
                            .push((a, b, k, c, norm(sub(self.rest[b], self.rest[a]))));
                    }
                }
            }
        }
    }

    /// One spring per corner of every face of every cell, between its neighbours.
    fn add_corner_springs(&mut self, mesh: &Mesh, k: f64, c: f64) {
        for (kind, cell) in mesh.kinds.iter().zip(&mesh.cells) {
            for f in local_faces(*kind, cell.len()) {
                let n = f.len();
                for i in 0..n {
                    let (a, b) = (cell[f[(i + n - 1) % n]], cell[f[(i + 1) % n]]);
                    self.springs
                        .push((a, b, k, c, norm(sub(self.rest[b], self.rest[a]))));
                }
            }
        }
    }

    /// The four space diagonals of every hexahedron.
    fn add_space_diagonals(&mut self, mesh: &Mesh, k: f64, c: f64) {
        for cell in &mesh.cells {
            for (i, j) in [(0, 6), (1, 7), (2, 4), (3, 5)] {
                let (a, b) = (cell[i], cell[j]);
                self.springs
                    .push((a, b, k, c, norm(sub(self.rest[b], self.rest[a]))));
            }
        }
    }

    /// Linear tetrahedra: K_ab = V (lambda g_a g_b^T + mu g_b g_a^T + mu (g_a . g_b) I).
    fn add_tets(&mut self, mesh: &Mesh, young: f64, nu: f64, corot: bool) {
        let lambda = young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
        let mu = young / (2.0 * (1.0 + nu));
        for c in &mesh.cells {
            let x = |i: usize| self.rest[c[i]];
            let dm = cols(sub(x(1), x(0)), sub(x(2), x(0)), sub(x(3), x(0)));
            let dmi = m_inv(&dm);
            let vol = m_det(&dm).abs() / 6.0;
            let mut g = [[0.0; 3]; 4];
            g[1..4].copy_from_slice(&dmi);
            g[0] = scale(-1.0, add(add(g[1], g[2]), g[3]));
            let mut k = [[[[0.0; 3]; 3]; 4]; 4];
            for a in 0..4 {
                for b in 0..4 {
                    for i in 0..3 {
                        for j in 0..3 {
                            let delta = if i == j { 1.0 } else { 0.0 };
                            k[a][b][i][j] = vol
                                * (lambda * g[a][i] * g[b][j]
                                    + mu * g[b][i] * g[a][j]
                                    + mu * dot(g[a], g[b]) * delta);
                        }
                    }
                }
            }
            self.tets.push(([c[0], c[1], c[2], c[3]], dmi, k));
        }
        self.corot = corot;
    }

    /// Trilinear hexahedra, K = sum over 2x2x2 Gauss points of B^T D B det J (B 6x24), and
    /// the shape gradients at the centre for the co-rotational frame.
    fn add_hexes(&mut self, mesh: &Mesh, young: f64, nu: f64) {
        let nat: [[f64; 3]; 8] = [
            [-1., -1., -1.],
            [1., -1., -1.],
            [1., 1., -1.],
            [-1., 1., -1.],
            [-1., -1., 1.],
            [1., -1., 1.],
            [1., 1., 1.],
            [-1., 1., 1.],
        ];
        let grads = |x: &[V3; 8], xi: V3| -> ([V3; 8], f64) {
            let mut dn = [[0.0; 3]; 8];
            for i in 0..8 {
                let f = |k: usize| 1.0 + xi[k] * nat[i][k];
                dn[i] = [
                    nat[i][0] * f(1) * f(2) / 8.0,
                    nat[i][1] * f(0) * f(2) / 8.0,
                    nat[i][2] * f(0) * f(1) / 8.0,
                ];
            }
            let mut j = [[0.0; 3]; 3];
            for i in 0..8 {
                for r in 0..3 {
                    for c in 0..3 {
                        j[r][c] += x[i][r] * dn[i][c];
                    }
                }
            }
            let ji = m_inv(&j);
            let mut g = [[0.0; 3]; 8];
            for i in 0..8 {
                for a in 0..3 {
                    g[i][a] = (0..3).map(|c| ji[c][a] * dn[i][c]).sum();
                }
            }
            (g, m_det(&j).abs())
        };
        let f = young / ((1.0 + nu) * (1.0 - 2.0 * nu));
        let d = [
            [f * (1.0 - nu), f * nu, f * nu, 0.0, 0.0, 0.0],
            [f * nu, f * (1.0 - nu), f * nu, 0.0, 0.0, 0.0],
            [f * nu, f * nu, f * (1.0 - nu), 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, f * (1.0 - 2.0 * nu) / 2.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, f * (1.0 - 2.0 * nu) / 2.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, f * (1.0 - 2.0 * nu) / 2.0],
        ];
        let q = 1.0 / 3.0f64.sqrt();
        for c in &mesh.cells {
            let vs: [usize; 8] = std::array::from_fn(|i| c[i]);
            let x: [V3; 8] = vs.map(|i| self.rest[i]);
            let mut k = vec![vec![0.0; 24]; 24];
            for gp in nat {
                let (g, det) = grads(&x, [q * gp[0], q * gp[1], q * gp[2]]);
                let mut b = vec![[0.0; 24]; 6];
                for i in 0..8 {
                    let (gx, gy, gz) = (g[i][0], g[i][1], g[i][2]);
                    b[0][3 * i] = gx;
                    b[1][3 * i + 1] = gy;
                    b[2][3 * i + 2] = gz;
                    b[3][3 * i] = gy;
                    b[3][3 * i + 1] = gx;
                    b[4][3 * i + 1] = gz;
                    b[4][3 * i + 2] = gy;
                    b[5][3 * i] = gz;
                    b[5][3 * i + 2] = gx;
                }
                for r in 0..24 {
                    for s2 in 0..24 {
                        let mut acc = 0.0;
                        for a in 0..6 {
                            for bb in 0..6 {
                                acc += b[a][r] * d[a][bb] * b[bb][s2];
                            }
                        }
                        k[r][s2] += det * acc;
                    }
                }
            }
            let (g0, _) = grads(&x, [0.0; 3]);
            self.hexes.push((vs, k, g0));
        }
    }

    fn step(&mut self) {
        let n = self.x.len();
        let mut f = vec![[0.0; 3]; n];
        for &(a, b, k, c, l0) in &self.springs {
            let d = sub(self.x[b], self.x[a]);
            let l = norm(d);
            let u = scale(1.0 / l, d);
            let fa = scale(k * (l - l0) + c * dot(sub(self.v[b], self.v[a]), u), u);
            f[a] = add(f[a], fa);
            f[b] = sub(f[b], fa);
        }
        for (vs, dmi, k) in &self.tets {
            let r = if self.corot {
                let ds = cols(
                    sub(self.x[vs[1]], self.x[vs[0]]),
                    sub(self.x[vs[2]], self.x[vs[0]]),
                    sub(self.x[vs[3]], self.x[vs[0]]),
                );
                polar(&m_mul(&ds, dmi))
            } else {
                [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
            };
            let rt = m_t(&r);
            // u_b = R^T x_b - X_b (R = I: the linear displacement)
            let u: Vec<V3> = vs
                .iter()
                .map(|&i| sub(m_v(&rt, self.x[i]), self.rest[i]))
                .collect();
            for a in 0..4 {
                let mut fa = [0.0; 3];
                for b in 0..4 {
                    fa = add(fa, m_v(&k[a][b], u[b]));
                }
                f[vs[a]] = sub(f[vs[a]], m_v(&r, fa));
            }
        }
        for (vs, k, g0) in &self.hexes {
            // deformation gradient at the centre, its rotation, then -R K (R^T x - X)
            let mut fg = [[0.0; 3]; 3];
            for i in 0..8 {
                for r in 0..3 {
                    for c in 0..3 {
                        fg[r][c] += self.x[vs[i]][r] * g0[i][c];
                    }
                }
            }
            let r = polar(&fg);
            let rt = m_t(&r);
            let u: Vec<f64> = vs
                .iter()
                .flat_map(|&i| sub(m_v(&rt, self.x[i]), self.rest[i]))
                .collect();
            for a in 0..8 {
                let fa: V3 = std::array::from_fn(|c| (0..24).map(|j| k[3 * a + c][j] * u[j]).sum());
                f[vs[a]] = sub(f[vs[a]], m_v(&r, fa));
            }
        }
        for i in 0..n {
            if self.fixed[i] {
                continue;
            }
            let a = add(scale(1.0 / self.m[i], f[i]), self.gravity);
            self.v[i] = add(self.v[i], scale(self.dt, a));
            self.x[i] = add(self.x[i], scale(self.dt, self.v[i]));
        }
    }
}

fn key(p: V3) -> [u64; 3] {
    p.map(f64::to_bits)
}

fn compare(
    kind: &str,
    params: &[(&str, f64)],
    mesh: &Mesh,
    reference: Reference,
    young: f64,
    nu: f64,
) {
    compare_models(&[(kind, params)], mesh, reference, young, nu);
}

/// Runs the models through the rules and the reference side by side (see the module docs).
fn compare_models(
    models: &[(&str, &[(&str, f64)])],
    mesh: &Mesh,
    mut reference: Reference,
    young: f64,
    nu: f64,
) {
    let kind = models.iter().map(|m| m.0).collect::<Vec<_>>().join("+");
    let kind = kind.as_str();
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: models
            .iter()
            .map(|(kind, params)| ModelSpec {
                kind: (*kind).into(),
                params: params
                    .iter()
                    .map(|(k, v)| ((*k).to_string(), topomech_rules::Val::F(*v)))
                    .collect(),
            })
            .collect(),
        density: 1000.0,
        young,
        poisson: nu,
        damping: 0.0,
        gravity: reference.gravity,
        fixed: vec!["x < 1e-9".into()],
        integrator: Integrator::SymplecticEuler,
        dt: reference.dt,
        ..Config::default()
    };
    let mut sim = Simulation::new(g, cfg).unwrap();
    // vertex correspondence through the exact rest positions
    let index: HashMap<[u64; 3], usize> = mesh
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| (key(*p), i))
        .collect();
    let rest = sim.vertex_vec3("rest").unwrap();
    let map: Vec<usize> = rest.iter().map(|p| index[&key(*p)]).collect();
    let masses = sim.vertex_scalar("mass").unwrap();
    for (v, &i) in map.iter().enumerate() {
        assert!(
            (masses[v] - reference.m[i]).abs() <= 1e-12 * reference.m[i],
            "{kind}: mass of vertex {i}"
        );
    }
    for _ in 0..100 {
        sim.step().unwrap();
        reference.step();
    }
    let x = sim.vertex_vec3("position").unwrap();
    let disp: f64 = reference
        .x
        .iter()
        .zip(&reference.rest)
        .map(|(a, b)| norm(sub(*a, *b)))
        .fold(0.0, f64::max);
    assert!(
        disp > 1e-4,
        "{kind}: the object must actually move (max displacement {disp})"
    );
    let mut worst: f64 = 0.0;
    for (v, &i) in map.iter().enumerate() {
        worst = worst.max(norm(sub(x[v], reference.x[i])) / disp);
    }
    assert!(
        worst < 1e-10,
        "{kind}: relative difference {worst:e} after 100 steps"
    );
}

fn beam() -> Mesh {
    cuboid([3, 1, 1], [3.0, 1.0, 1.0], BoxElement::Tetra)
}

#[test]
fn stretch_elementary_matches_the_flat_reference() {
    for (mesh, three) in [
        (beam(), true),
        (grid([4, 3], [2.0, 1.5], GridElement::Mixed), false),
    ] {
        let mut r = Reference::new(
            &mesh,
            1000.0,
            1e-9,
            [0.0, -9.81, if three { 0.0 } else { -3.0 }],
            1e-3,
        );
        r.add_springs(&mesh, 2e4, 5.0);
        let mut r2 = Reference::new(&mesh, 1000.0, 1e-9, r.gravity, 1e-3);
        r2.add_springs(&mesh, 2e4, 5.0);
        compare(
            "stretch_elementary",
            &[("stiffness", 2e4), ("damping", 5.0)],
            &mesh,
            r,
            1e6,
            0.3,
        );
        compare(
            "stretch_cumulated",
            &[("stiffness", 2e4), ("damping", 5.0)],
            &mesh,
            r2,
            1e6,
            0.3,
        );
    }
}

#[test]
fn linear_fem_and_mass_tensor_match_the_flat_reference() {
    let mesh = beam();
    for kind in ["linear_fem", "mass_tensor"] {
        let mut r = Reference::new(&mesh, 1000.0, 1e-9, [0.0, -9.81, 0.0], 1e-3);
        r.add_tets(&mesh, 1e6, 0.3, false);
        compare(kind, &[], &mesh, r, 1e6, 0.3);
    }
}

/// The mass-tensor step reads one tensor per edge, the hook end's, and takes the other end's as
/// its transpose (`mass_tensor_edges` in fem3d.tmr): that holds because the element stiffness
/// is symmetric, so the cumulated tensor at the end j of an edge is K_ji = K_ij^T. Checked on
/// every edge of the beam, relative to the largest entry: the two ends are summed over the
/// same tetrahedra, maybe in another order, so they agree to rounding (a few ulps), far below
/// the 1e-12 asked (the flat reference above then checks the forces themselves). On a box of
/// 4 x 3 x 2 cells (144 tetrahedra, interior edges shared by up to 6 of them).
#[test]
fn mass_tensor_edge_tensors_are_transposes_of_each_other() {
    use topomech_gmap::OrbitType;
    let mesh = cuboid([4, 3, 2], [2.0, 1.5, 1.0], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![ModelSpec {
            kind: "mass_tensor".into(),
            params: HashMap::default(),
        }],
        young: 1e6,
        poisson: 0.3,
        ..Config::default()
    };
    let sim = Simulation::new(g, cfg).unwrap();
    let g = sim.gmap();
    let id = g.require("t_edge_cum").unwrap();
    let m = |d| -> M3 {
        let v = g.real(id, d);
        [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]]
    };
    let reps = g.orbit_representatives(OrbitType::edge(3));
    assert!(reps.len() > 50);
    let scale = reps
        .iter()
        .flat_map(|&d| g.real(id, d).to_vec())
        .fold(0.0f64, |a, x| a.max(x.abs()));
    assert!(scale > 0.0);
    for d in reps {
        let (kij, kji) = (m(d), m(g.alpha(0, d)));
        let t = m_t(&kij);
        for r in 0..3 {
            for c in 0..3 {
                let e = (kji[r][c] - t[r][c]).abs() / scale;
                assert!(e < 1e-12, "edge at {d}: K_ji - K_ij^T = {e:e} relative");
            }
        }
    }
}

#[test]
fn corotational_matches_the_flat_reference() {
    let mesh = beam();
    let mut r = Reference::new(&mesh, 1000.0, 1e-9, [0.0, -9.81, 0.0], 1e-3);
    r.add_tets(&mesh, 1e5, 0.3, true);
    compare("corotational", &[], &mesh, r, 1e5, 0.3);
}

#[test]
fn shear_springs_match_the_flat_reference() {
    let p: &[(&str, f64)] = &[("stiffness", 5e3), ("damping", 2.0)];
    let s: &[(&str, f64)] = &[("stiffness", 2e4), ("damping", 1.0)];
    let quads = grid([3, 2], [1.5, 1.0], GridElement::Quad);
    let hexes = cuboid([3, 1, 1], [3.0, 1.0, 1.0], BoxElement::Hexa);
    let tris = grid([3, 2], [1.5, 1.0], GridElement::Mixed);
    let tets = beam();
    let g2 = [0.0, -9.81, -2.0];
    let g3 = [0.0, -9.81, 0.0];
    // isotropic shear with stretch (quads alone have a shear mechanism), 2D and 3D
    for (mesh, g) in [(&quads, g2), (&hexes, g3)] {
        let mut r = Reference::new(mesh, 1000.0, 1e-9, g, 1e-3);
        r.add_springs(mesh, 2e4, 1.0);
        r.add_quad_diagonals(mesh, 5e3, 2.0);
        compare_models(
            &[("stretch_elementary", s), ("shear_isotropic", p)],
            mesh,
            r,
            1e6,
            0.3,
        );
    }
    // anisotropic shear on any faces
    for (mesh, g) in [(&tris, g2), (&tets, g3), (&hexes, g3)] {
        let mut r = Reference::new(mesh, 1000.0, 1e-9, g, 1e-3);
        r.add_springs(mesh, 2e4, 1.0);
        r.add_corner_springs(mesh, 5e3, 2.0);
        compare_models(
            &[("stretch_elementary", s), ("shear_anisotropic", p)],
            mesh,
            r,
            1e6,
            0.3,
        );
    }
    // volumic shear on hexahedra
    let mut r = Reference::new(&hexes, 1000.0, 1e-9, g3, 1e-3);
    r.add_springs(&hexes, 2e4, 1.0);
    r.add_space_diagonals(&hexes, 5e3, 2.0);
    compare_models(
        &[("stretch_elementary", s), ("shear_volumic", p)],
        &hexes,
        r,
        1e6,
        0.3,
    );
}

#[test]
fn corotational_hexahedra_match_the_flat_reference() {
    let mesh = cuboid([3, 1, 1], [3.0, 1.0, 1.0], BoxElement::Hexa);
    let mut r = Reference::new(&mesh, 1000.0, 1e-9, [0.0, -9.81, 0.0], 1e-3);
    r.add_hexes(&mesh, 1e5, 0.3);
    compare("corotational", &[], &mesh, r, 1e5, 0.3);
}

#[test]
fn element_models_refuse_elements_they_cannot_handle() {
    let mesh = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Mixed);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![ModelSpec {
            kind: "linear_fem".into(),
            params: HashMap::new(),
        }],
        ..Config::default()
    };
    let e = Simulation::new(g, cfg).unwrap_err().to_string();
    assert!(e.contains("would get no force"), "{e}");
}
