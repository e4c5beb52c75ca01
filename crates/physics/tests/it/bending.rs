//! Angular bending against a flat-array reference whose angle gradient comes from forward
//! automatic differentiation (dual numbers over the 12 coordinates of an edge's two vertices
//! and two wings): independent of the rule's closed-form gradients, and exact to rounding, so
//! the two agree to 1e-10 over 100 steps.

// Numeric reference code: index loops mirror the math; dual-number arithmetic is the product
// and quotient rules, so the `+` and `-` inside Mul and Div are meant.
#![allow(
    clippy::needless_range_loop,
    clippy::doc_markdown,
    clippy::suboptimal_flops,
    clippy::suspicious_arithmetic_impl,
    clippy::large_types_passed_by_value
)]

use crate::common;

use common::{add, cross, dot, norm, scale, sub, Flat};
use std::collections::HashMap;
use std::ops::{Add, Div, Mul, Sub};

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_physics::{Config, Integrator, ModelSpec, Simulation};

#[derive(Clone, Copy)]
struct D {
    v: f64,
    d: [f64; 12],
}

impl D {
    fn var(v: f64, i: usize) -> D {
        let mut d = [0.0; 12];
        d[i] = 1.0;
        D { v, d }
    }
    fn sqrt(self) -> D {
        let r = self.v.sqrt();
        D {
            v: r,
            d: self.d.map(|x| x / (2.0 * r)),
        }
    }
}
impl Add for D {
    type Output = D;
    fn add(self, o: D) -> D {
        D {
            v: self.v + o.v,
            d: std::array::from_fn(|i| self.d[i] + o.d[i]),
        }
    }
}
impl Sub for D {
    type Output = D;
    fn sub(self, o: D) -> D {
        D {
            v: self.v - o.v,
            d: std::array::from_fn(|i| self.d[i] - o.d[i]),
        }
    }
}
impl Mul for D {
    type Output = D;
    fn mul(self, o: D) -> D {
        D {
            v: self.v * o.v,
            d: std::array::from_fn(|i| self.d[i] * o.v + self.v * o.d[i]),
        }
    }
}
impl Div for D {
    type Output = D;
    fn div(self, o: D) -> D {
        D {
            v: self.v / o.v,
            d: std::array::from_fn(|i| (self.d[i] * o.v - self.v * o.d[i]) / (o.v * o.v)),
        }
    }
}

type V = [D; 3];

fn vsub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn vdot(a: V, b: V) -> D {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn vcross(a: V, b: V) -> V {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The dihedral angle at edge (x1, x2) between the faces of wings wa, wb, and its gradient
/// with respect to (x1, x2, wa, wb).
fn theta(p: [[f64; 3]; 4]) -> (f64, [[f64; 3]; 4]) {
    let v: [V; 4] = std::array::from_fn(|k| std::array::from_fn(|a| D::var(p[k][a], 3 * k + a)));
    let e = vsub(v[1], v[0]);
    let na = vcross(e, vsub(v[2], v[0]));
    let nb = vcross(vsub(v[3], v[0]), e);
    let s = vdot(vcross(na, nb), e) / vdot(e, e).sqrt();
    let c = vdot(na, nb);
    // atan2 and its derivative (c ds - s dc) / (s^2 + c^2)
    let t = s.v.atan2(c.v);
    let den = s.v * s.v + c.v * c.v;
    let g: [f64; 12] = std::array::from_fn(|i| (c.v * s.d[i] - s.v * c.d[i]) / den);
    (
        t,
        std::array::from_fn(|k| [g[3 * k], g[3 * k + 1], g[3 * k + 2]]),
    )
}

/// The interior edges of a surface mesh: (x1, x2, face a, face b).
fn interior_edges(mesh: &Mesh) -> Vec<(usize, usize, usize, usize)> {
    let mut by_edge: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for (f, c) in mesh.cells.iter().enumerate() {
        for j in 0..c.len() {
            let (a, b) = (c[j], c[(j + 1) % c.len()]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    let mut out: Vec<_> = by_edge
        .into_iter()
        .filter(|(_, fs)| fs.len() == 2)
        .map(|((a, b), fs)| (a, b, fs[0], fs[1]))
        .collect();
    out.sort_unstable();
    out
}

fn wing(mesh: &Mesh, x: &[[f64; 3]], f: usize, a: usize, b: usize) -> ([f64; 3], Vec<usize>) {
    let far: Vec<usize> = mesh.cells[f]
        .iter()
        .copied()
        .filter(|&i| i != a && i != b)
        .collect();
    let mut w = [0.0; 3];
    for &i in &far {
        for k in 0..3 {
            w[k] += x[i][k] / far.len() as f64;
        }
    }
    (w, far)
}

/// Forces of the dihedral springs: -(k (theta - theta0) + c dtheta/dt) grad theta; a wing's
/// force is shared equally by its face's vertices off the edge.
fn bending_forces(
    mesh: &Mesh,
    x: &[[f64; 3]],
    v: &[[f64; 3]],
    rest: &[[f64; 3]],
    k: f64,
    c: f64,
) -> Vec<[f64; 3]> {
    let mut f = vec![[0.0; 3]; x.len()];
    for (a, b, fa, fb) in interior_edges(mesh) {
        let (wa, fara) = wing(mesh, x, fa, a, b);
        let (wb, farb) = wing(mesh, x, fb, a, b);
        let (ra, _) = wing(mesh, rest, fa, a, b);
        let (rb, _) = wing(mesh, rest, fb, a, b);
        let (va, _) = wing(mesh, v, fa, a, b);
        let (vb, _) = wing(mesh, v, fb, a, b);
        let (t, g) = theta([x[a], x[b], wa, wb]);
        let (t0, _) = theta([rest[a], rest[b], ra, rb]);
        let vel = [v[a], v[b], va, vb];
        let rate: f64 = (0..4)
            .map(|i| (0..3).map(|k| g[i][k] * vel[i][k]).sum::<f64>())
            .sum();
        let s = -(k * (t - t0) + c * rate);
        for kk in 0..3 {
            f[a][kk] += s * g[0][kk];
            f[b][kk] += s * g[1][kk];
            for &i in &fara {
                f[i][kk] += s * g[2][kk] / fara.len() as f64;
            }
            for &i in &farb {
                f[i][kk] += s * g[3][kk] / farb.len() as f64;
            }
        }
    }
    f
}

/// A hanging sheet (triangles, quads, mixed) with stretch and angular bending, fixed along
/// x = 0, falling under gravity along -z: 100 steps agree with the reference to 1e-10.
#[test]
fn angular_bending_matches_the_reference() {
    for element in [GridElement::Triangle, GridElement::Quad, GridElement::Mixed] {
        let mesh = grid([4, 3], [2.0, 1.5], element);
        let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let (ks, kb, cb, dt) = (2e3, 0.5, 0.01, 1e-3);
        let gravity = [0.0, 0.0, -9.81];
        let cfg = Config {
            models: vec![
                ModelSpec {
                    kind: "stretch_elementary".into(),
                    params: [("stiffness".to_string(), topomech_rules::Val::F(ks))].into(),
                },
                ModelSpec {
                    kind: "bending_angular".into(),
                    params: [
                        ("stiffness".to_string(), topomech_rules::Val::F(kb)),
                        ("damping".to_string(), topomech_rules::Val::F(cb)),
                    ]
                    .into(),
                },
            ],
            density: 1.0,
            gravity,
            fixed: vec!["x < 1e-9".into()],
            integrator: Integrator::SymplecticEuler,
            dt,
            ..Config::default()
        };
        let mut sim = Simulation::new(g, cfg).unwrap();
        // the reference: lumped masses (a polygon's area shared by its vertices), springs
        let rest = mesh.points.clone();
        let mut m = vec![0.0; rest.len()];
        for c in &mesh.cells {
            let p = |i: usize| mesh.points[c[i]];
            let area: f64 = (1..c.len() - 1)
                .map(|k| 0.5 * norm(cross(sub(p(k), p(0)), sub(p(k + 1), p(0)))))
                .sum();
            for &i in c {
                m[i] += area / c.len() as f64;
            }
        }
        let mut r = Flat::new(rest.clone(), m, 1e-9, gravity, dt);
        let springs: Vec<(usize, usize, f64)> = mesh
            .cells
            .iter()
            .flat_map(|c| (0..c.len()).map(move |j| (c[j], c[(j + 1) % c.len()])))
            .map(|(a, b)| (a, b, norm(sub(rest[b], rest[a]))))
            .collect();
        for _ in 0..100 {
            sim.step().unwrap();
            let mut f = bending_forces(&mesh, &r.x, &r.v, &rest, kb, cb);
            for &(a, b, l0) in &springs {
                let d = sub(r.x[b], r.x[a]);
                let fa = scale(ks * (norm(d) - l0) / norm(d), d);
                f[a] = add(f[a], fa);
                f[b] = sub(f[b], fa);
            }
            r.step(&f);
        }
        let worst = r.worst_relative(&sim, 1e-3);
        assert!(worst < 1e-10, "{element:?}: relative difference {worst:e}");
    }
}

/// Linear bending springs of a quad sheet, found from the cells: for each edge-end (e, v)
/// and each face F of e, the edge e' after e around v in F, the face F' across e', and the
/// edge e'' after e' around v in F'; a spring joins the far ends of e and e''. An edge-end
/// with a face where this leaves the surface has no spring at all. The edge-ends (e, v) and
/// (e'', v) cover the same darts — one interaction — so the second adds nothing.
fn linear_bending_springs(mesh: &Mesh) -> Vec<(usize, usize)> {
    let mut faces_of: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
    for (f, c) in mesh.cells.iter().enumerate() {
        for j in 0..c.len() {
            let (a, b) = (c[j], c[(j + 1) % c.len()]);
            faces_of.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    let key = |a: usize, b: usize| (a.min(b), a.max(b));
    // the neighbour of v in face f other than w
    let other = |f: usize, v: usize, w: usize| -> usize {
        let c = &mesh.cells[f];
        let i = c.iter().position(|&x| x == v).unwrap();
        let (p, n) = (c[(i + c.len() - 1) % c.len()], c[(i + 1) % c.len()]);
        if p == w {
            n
        } else {
            p
        }
    };
    let mut springs = Vec::new();
    let mut seen = std::collections::HashSet::new();
    let mut ends: Vec<(usize, usize)> = faces_of
        .keys()
        .flat_map(|&(a, b)| [(a, b), (b, a)])
        .collect();
    ends.sort_unstable();
    for (v, w) in ends {
        let mut found = Vec::new();
        let mut ok = true;
        for &f in &faces_of[&key(v, w)] {
            let w1 = other(f, v, w);
            let across: Vec<usize> = faces_of[&key(v, w1)]
                .iter()
                .copied()
                .filter(|&g| g != f)
                .collect();
            if across.is_empty() {
                ok = false;
                break;
            }
            let w2 = other(across[0], v, w1);
            found.push((w, w2));
        }
        if ok {
            let partner = (v, found[0].0.min(found[0].1), found[0].0.max(found[0].1));
            if seen.insert(partner) {
                springs.extend(found);
            }
        }
    }
    springs
}

/// A quad sheet with stretch and linear bending, fixed along x = 0, falling along -z:
/// 100 steps agree with the reference to 1e-10.
#[test]
fn linear_bending_matches_the_reference() {
    let mesh = grid([4, 3], [2.0, 1.5], GridElement::Quad);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let (ks, kb, cb, dt) = (2e3, 50.0, 0.5, 1e-3);
    let gravity = [0.0, 0.0, -9.81];
    let cfg = Config {
        models: vec![
            ModelSpec {
                kind: "stretch_elementary".into(),
                params: [("stiffness".to_string(), topomech_rules::Val::F(ks))].into(),
            },
            ModelSpec {
                kind: "bending_linear".into(),
                params: [
                    ("stiffness".to_string(), topomech_rules::Val::F(kb)),
                    ("damping".to_string(), topomech_rules::Val::F(cb)),
                ]
                .into(),
            },
        ],
        density: 1.0,
        gravity,
        fixed: vec!["x < 1e-9".into()],
        integrator: Integrator::SymplecticEuler,
        dt,
        ..Config::default()
    };
    let mut sim = Simulation::new(g, cfg).unwrap();
    let rest = mesh.points.clone();
    let mut m = vec![0.0; rest.len()];
    for c in &mesh.cells {
        for &i in c {
            m[i] += 0.5 * 0.5 / 4.0;
        }
    }
    let mut r = Flat::new(rest.clone(), m, 1e-9, gravity, dt);
    let mut springs: Vec<(usize, usize, f64, f64)> = mesh
        .cells
        .iter()
        .flat_map(|c| (0..c.len()).map(move |j| (c[j], c[(j + 1) % c.len()])))
        .map(|(a, b)| (a, b, ks, 0.0))
        .collect();
    let bend = linear_bending_springs(&mesh);
    assert!(bend.len() > 20, "{}", bend.len());
    springs.extend(bend.into_iter().map(|(a, b)| (a, b, kb, cb)));
    for _ in 0..100 {
        sim.step().unwrap();
        let mut f = vec![[0.0; 3]; rest.len()];
        for &(a, b, k, c) in &springs {
            let d = sub(r.x[b], r.x[a]);
            let u = scale(1.0 / norm(d), d);
            let fa = scale(
                k * (norm(d) - norm(sub(rest[b], rest[a]))) + c * dot(sub(r.v[b], r.v[a]), u),
                u,
            );
            f[a] = add(f[a], fa);
            f[b] = sub(f[b], fa);
        }
        r.step(&f);
    }
    let worst = r.worst_relative(&sim, 1e-3);
    assert!(worst < 1e-10, "relative difference {worst:e}");
}
