//! Co-rotational triangles (a membrane) against a flat-array reference written here: a sheet
//! of triangles fixed along x = 0 falls under gravity along -z; 100 steps agree to 1e-10.

// Numeric reference code: index loops mirror the math.
#![allow(
    clippy::needless_range_loop,
    clippy::doc_markdown,
    clippy::suboptimal_flops
)]

use crate::common;

use common::{cross, dot, norm, sub, Flat};

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_physics::{Config, Integrator, ModelSpec, Simulation};

type V = common::V3;
fn unit(a: V) -> V {
    let n = dot(a, a).sqrt();
    [a[0] / n, a[1] / n, a[2] / n]
}

/// The triangle's in-plane frame (e1 along edge 0-1) and its vertices' 2D coordinates.
fn frame(x: [V; 3]) -> (V, V, [[f64; 2]; 3]) {
    let (d1, d2) = (sub(x[1], x[0]), sub(x[2], x[0]));
    let e1 = unit(d1);
    let e2 = cross(unit(cross(d1, d2)), e1);
    (
        e1,
        e2,
        [
            [0.0, 0.0],
            [dot(d1, e1), dot(d1, e2)],
            [dot(d2, e1), dot(d2, e2)],
        ],
    )
}

/// Forces of one co-rotated plane-stress triangle.
fn triangle_forces(x: [V; 3], rest: [V; 3], young: f64, nu: f64, t: f64) -> [V; 3] {
    let (_, _, p0) = frame(rest);
    let (e1, e2, p) = frame(x);
    // F = [p1 p2] [P1 P2]^-1, its rotation in closed form
    let (a, b) = (p0[1], p0[2]);
    let det = a[0] * b[1] - a[1] * b[0];
    let inv = [[b[1] / det, -b[0] / det], [-a[1] / det, a[0] / det]];
    let ds = [[p[1][0], p[2][0]], [p[1][1], p[2][1]]];
    let f = [
        [
            ds[0][0] * inv[0][0] + ds[0][1] * inv[1][0],
            ds[0][0] * inv[0][1] + ds[0][1] * inv[1][1],
        ],
        [
            ds[1][0] * inv[0][0] + ds[1][1] * inv[1][0],
            ds[1][0] * inv[0][1] + ds[1][1] * inv[1][1],
        ],
    ];
    let ang = (f[1][0] - f[0][1]).atan2(f[0][0] + f[1][1]);
    let (s, c) = ang.sin_cos();
    // displacement in the rotated frame: u_i = R^T p_i - P_i
    let u: Vec<[f64; 2]> = (0..3)
        .map(|i| {
            [
                c * p[i][0] + s * p[i][1] - p0[i][0],
                -s * p[i][0] + c * p[i][1] - p0[i][1],
            ]
        })
        .collect();
    // constant strain from the barycentric gradients, plane-stress stress
    let g = [
        [-(inv[0][0] + inv[1][0]), -(inv[0][1] + inv[1][1])],
        inv[0],
        inv[1],
    ];
    let (exx, eyy, gxy) = (0..3).fold((0.0, 0.0, 0.0), |acc, i| {
        (
            acc.0 + g[i][0] * u[i][0],
            acc.1 + g[i][1] * u[i][1],
            acc.2 + g[i][1] * u[i][0] + g[i][0] * u[i][1],
        )
    });
    let k = young / (1.0 - nu * nu);
    let (sxx, syy, sxy) = (
        k * (exx + nu * eyy),
        k * (eyy + nu * exx),
        k * (1.0 - nu) / 2.0 * gxy,
    );
    let area = det.abs() / 2.0;
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        // local force -t A B_i^T sigma, rotated back by R, then to 3D
        let fl = [
            -t * area * (g[i][0] * sxx + g[i][1] * sxy),
            -t * area * (g[i][1] * syy + g[i][0] * sxy),
        ];
        let fr = [c * fl[0] - s * fl[1], s * fl[0] + c * fl[1]];
        for k in 0..3 {
            out[i][k] = fr[0] * e1[k] + fr[1] * e2[k];
        }
    }
    out
}

#[test]
fn corotational_triangles_match_the_reference() {
    let mesh = grid([4, 3], [2.0, 1.5], GridElement::Triangle);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let (young, nu, t, rho, dt) = (1e4, 0.3, 0.01, 0.1, 1e-3);
    let gravity = [0.0, 0.0, -9.81];
    let cfg = Config {
        models: vec![ModelSpec {
            kind: "corotational".into(),
            params: [("thickness".to_string(), topomech_rules::Val::F(t))].into(),
        }],
        density: rho,
        young,
        poisson: nu,
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
        let area = 0.5
            * norm(cross(
                sub(rest[c[1]], rest[c[0]]),
                sub(rest[c[2]], rest[c[0]]),
            ));
        for &i in c {
            m[i] += rho * area / 3.0;
        }
    }
    let mut r = Flat::new(rest.clone(), m, 1e-9, gravity, dt);
    for _ in 0..100 {
        sim.step().unwrap();
        let mut f = vec![[0.0; 3]; rest.len()];
        for c in &mesh.cells {
            let fe = triangle_forces(
                [r.x[c[0]], r.x[c[1]], r.x[c[2]]],
                [rest[c[0]], rest[c[1]], rest[c[2]]],
                young,
                nu,
                t,
            );
            for k in 0..3 {
                f[c[k]] = common::add(f[c[k]], fe[k]);
            }
        }
        r.step(&f);
    }
    let worst = r.worst_relative(&sim, 1e-3);
    assert!(worst < 1e-10, "relative difference {worst:e}");
}
