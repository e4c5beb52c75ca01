//! Helpers shared by the physics tests: model specs and small vector arithmetic, written here
//! (independent of the crates under test).
#![allow(dead_code, missing_docs, clippy::needless_range_loop)]

pub mod cases;
pub mod renamed;

use topomech_physics::ModelSpec;

pub type V3 = [f64; 3];

pub fn model(kind: &str, params: &[(&str, f64)]) -> ModelSpec {
    ModelSpec::with_reals(kind, params)
}

pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn scale(s: f64, a: V3) -> V3 {
    [s * a[0], s * a[1], s * a[2]]
}

pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// Points stepped by symplectic Euler with forces computed elsewhere: the integrator of the
/// flat-array references, written here.
pub struct Flat {
    pub x: Vec<V3>,
    pub v: Vec<V3>,
    pub rest: Vec<V3>,
    pub m: Vec<f64>,
    pub fixed: Vec<bool>,
    pub gravity: V3,
    pub dt: f64,
}

impl Flat {
    /// At rest, vertices with x below `fixed_x_below` fixed.
    pub fn new(rest: Vec<V3>, m: Vec<f64>, fixed_x_below: f64, gravity: V3, dt: f64) -> Self {
        let n = rest.len();
        Flat {
            x: rest.clone(),
            v: vec![[0.0; 3]; n],
            fixed: rest.iter().map(|p| p[0] < fixed_x_below).collect(),
            rest,
            m,
            gravity,
            dt,
        }
    }

    /// One step: v += dt (f / m + g), x += dt v, fixed vertices kept.
    pub fn step(&mut self, f: &[V3]) {
        for i in 0..self.x.len() {
            if self.fixed[i] {
                continue;
            }
            for a in 0..3 {
                self.v[i][a] += self.dt * (f[i][a] / self.m[i] + self.gravity[a]);
                self.x[i][a] += self.dt * self.v[i][a];
            }
        }
    }

    /// The largest distance between the simulation's vertices and these (matched through their
    /// exact rest positions), relative to the largest displacement here, which must exceed
    /// `min_disp` (the object must move for the comparison to mean anything).
    pub fn worst_relative(&self, sim: &topomech_physics::Simulation, min_disp: f64) -> f64 {
        let index: std::collections::HashMap<[u64; 3], usize> = self
            .rest
            .iter()
            .enumerate()
            .map(|(i, p)| (p.map(f64::to_bits), i))
            .collect();
        let disp = self
            .x
            .iter()
            .zip(&self.rest)
            .map(|(a, b)| norm(sub(*a, *b)))
            .fold(0.0, f64::max);
        assert!(disp > min_disp, "the object moves: {disp}");
        let rest = sim.vertex_vec3("rest").unwrap();
        let x = sim.vertex_vec3("position").unwrap();
        rest.iter()
            .zip(&x)
            .map(|(r, p)| norm(sub(*p, self.x[index[&r.map(f64::to_bits)]])) / disp)
            .fold(0.0, f64::max)
    }
}
