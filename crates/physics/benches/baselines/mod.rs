//! Hand-written flat-array baselines of three models, for the engine benchmark (and the test
//! that keeps them honest, `tests/baselines.rs`). Never used by the engine.
//!
//! Each baseline is what an engineer would write for one model on one CPU core: positions,
//! velocities and forces in flat arrays (`Vec<[f64; 3]>`, contiguous), element and edge data
//! in flat arrays indexed by precomputed vertex indices, no allocation per step, `f64`
//! throughout. A step is the engine's: every force accumulated per vertex, then symplectic
//! Euler exactly as the `symplectic_euler` rule of `models/common{2,3}d.tmr`
//! (`a = f / m + g - damping v; v += dt a; x += dt v`, fixed vertices skipped).
//!
//! The models (the same algorithms as the rules, term by term):
//! - [`Cloth`]: cumulated stretch springs (`stretch_cumulated`), one spring per edge with the
//!   summed stiffness and damping of its faces' sides and their mean rest length (Provot
//!   damping along the spring);
//! - [`Corotational`]: co-rotational linear tetrahedra (Müller & Gross 2004),
//!   `f = -R K (R^T x - X)`, R the polar rotation of `F = Ds Dm^-1` computed by the same
//!   algorithm as the engine's `polar` built-in (scaled Newton iteration, one-sided Jacobi SVD
//!   where it does not apply);
//! - [`MassTensor`]: mass-tensor tetrahedra (Cotin et al. 2000), `f_i = -K_ii u_i - sum_j K_ij u_j`
//!   with the tensors cumulated on vertices and edges, `u = x - X`;
//! - [`NeoHookean`]: stable Neo-Hookean tetrahedra (Smith, de Goes & Kim 2018,
//!   doi:10.1145/3180491), `P = mu (1 - 1/(I_C + 1)) F + lambda (J - alpha) cof F`, forces
//!   `H = -V P Dm^-T` (`neohookean` in `models/hyperelastic3d.tmr`).
//!
//! Initialisation (rest lengths, stiffness matrices, masses, cumulated tensors) is read from
//! the engine's map after `Simulation::new`, so that both start from identical numbers; the
//! per-step kernels are this file's own code. Vertices are numbered as the engine numbers them
//! (its rows: the `particle` embedding), so positions compare index by index.

// Numeric kernels: index loops over fixed-size blocks mirror the math, and the sums are written
// in the engine's order (no fused multiply-add), so results agree to rounding.
#![allow(
    clippy::needless_range_loop,
    clippy::suboptimal_flops,
    clippy::doc_markdown,
    dead_code
)]

use topomech_gmap::{Dart, GMap, OrbitType};
use topomech_physics::Simulation;

/// The time step of every benchmarked simulation (stable at every size).
pub const DT: f64 = 1e-4;

/// A point or vector.
pub type V3 = [f64; 3];
/// A 3x3 matrix, row-major.
pub type M3 = [[f64; 3]; 3];

/// A baseline: one step, and what to compare.
pub trait Baseline {
    /// The vertex state (positions, velocities, forces, masses).
    fn state(&self) -> &State;
    /// Every force of the step, accumulated per vertex into the state's forces.
    fn forces(&mut self);
    /// The state, to integrate.
    fn state_mut(&mut self) -> &mut State;
    /// One full step: forces, accumulation, symplectic Euler.
    fn step(&mut self) {
        self.forces();
        self.state_mut().integrate();
    }
    /// Positions in the engine's vertex order.
    fn positions(&self) -> &[V3] {
        &self.state().x
    }
    /// Bytes of every array the baseline keeps.
    fn memory_bytes(&self) -> usize;
    /// What one step must do at least (see [`Work`]).
    fn work(&self) -> Work;
}

/// The least work of one step, counted from the kernel's formulas: the compulsory memory
/// traffic (every array streamed once: read, or read and written; gathers of vertex data
/// through the element lists counted once per vertex, as if the vertex arrays stayed in
/// cache) and the arithmetic. Used by the bench for the hardware limit of a step, `max(bytes /
/// bandwidth, flops / flop rate + sqrt_div / sqrt-and-division rate)`, all three rates
/// measured by probes in the same run.
#[derive(Clone, Copy, Debug, Default)]
pub struct Work {
    /// Bytes moved between memory and the core.
    pub bytes: f64,
    /// Additions, subtractions and multiplications.
    pub flops: f64,
    /// Square roots and divisions (each far slower than a multiplication).
    pub sqrt_div: f64,
}

impl Work {
    fn add(self, o: Work) -> Work {
        Work {
            bytes: self.bytes + o.bytes,
            flops: self.flops + o.flops,
            sqrt_div: self.sqrt_div + o.sqrt_div,
        }
    }
}

/// The vertex state and the integrator, shared by the three baselines.
pub struct State {
    /// Positions.
    pub x: Vec<V3>,
    /// Velocities.
    pub v: Vec<V3>,
    /// Forces, accumulated per vertex each step.
    pub f: Vec<V3>,
    /// Rest positions.
    pub rest: Vec<V3>,
    /// 1 / mass (0 for a fixed vertex without mass, never read).
    pub inv_m: Vec<f64>,
    /// Fixed vertices (not integrated).
    pub fixed: Vec<bool>,
    dt: f64,
    gravity: V3,
    damping: f64,
}

impl State {
    /// The simulation's current vertex state and its integrator settings.
    pub fn from_sim(sim: &Simulation) -> Self {
        let cfg = sim.config();
        let m = sim.vertex_scalar("mass").expect("mass");
        let x = sim.vertex_vec3("position").expect("position");
        let n = x.len();
        State {
            x,
            v: sim.vertex_vec3("velocity").expect("velocity"),
            f: vec![[0.0; 3]; n],
            rest: sim.vertex_vec3("rest").expect("rest"),
            inv_m: m
                .iter()
                .map(|&m| if m > 0.0 { 1.0 / m } else { 0.0 })
                .collect(),
            fixed: sim.vertex_bool("fixed").expect("fixed"),
            dt: cfg.dt,
            gravity: cfg.gravity,
            damping: cfg.damping,
        }
    }

    fn clear_forces(&mut self) {
        self.f.fill([0.0; 3]);
    }

    /// Symplectic Euler: `a = f / m + g - damping v; v += dt a; x += dt v`.
    fn integrate(&mut self) {
        let (dt, g, c) = (self.dt, self.gravity, self.damping);
        for ((((x, v), f), &im), &fixed) in self
            .x
            .iter_mut()
            .zip(&mut self.v)
            .zip(&self.f)
            .zip(&self.inv_m)
            .zip(&self.fixed)
        {
            if fixed {
                continue;
            }
            for k in 0..3 {
                let a = f[k] * im + g[k] - c * v[k];
                v[k] += dt * a;
                x[k] += dt * v[k];
            }
        }
    }

    fn memory_bytes(&self) -> usize {
        let n = self.x.len();
        n * (4 * 24 + 8 + 1)
    }

    /// Symplectic Euler and the force column: per vertex, x and v read and written (96 B),
    /// f written by the force pass and read here (48 B), 1/m and the fixed flag (9 B); per
    /// component 4 operations for the acceleration and 2 each for v and x.
    fn work(&self) -> Work {
        let n = self.x.len() as f64;
        Work {
            bytes: n * (96.0 + 48.0 + 9.0),
            flops: n * 3.0 * 8.0,
            sqrt_div: 0.0,
        }
    }
}

/// The engine's vertex number (row) of every dart: its `particle` (the simulation creates it
/// from the vertex orbit order when the map has none).
fn vertex_labels(g: &GMap) -> Vec<u32> {
    let Some(id) = g.embedding_id("particle") else {
        return g.orbit_labels(OrbitType::vertex(g.dimension())).0;
    };
    let mut label = vec![u32::MAX; g.capacity()];
    for d in g.darts() {
        if let Ok(topomech_gmap::Value::Int(x)) = g.value(id, d) {
            label[d.index()] = u32::try_from(x).unwrap_or(u32::MAX);
        }
    }
    label
}

fn read<const N: usize>(g: &GMap, name: &str, d: Dart) -> [f64; N] {
    let id = g
        .embedding_id(name)
        .unwrap_or_else(|| panic!("no embedding '{name}'"));
    g.real(id, d).try_into().expect("width")
}

fn m3(a: [f64; 9]) -> M3 {
    [[a[0], a[1], a[2]], [a[3], a[4], a[5]], [a[6], a[7], a[8]]]
}

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `m v`.
fn mv(m: &M3, v: V3) -> V3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

/// `m^T v`.
fn mtv(m: &M3, v: V3) -> V3 {
    let col = |c: usize| [m[0][c], m[1][c], m[2][c]];
    [dot(col(0), v), dot(col(1), v), dot(col(2), v)]
}

// ------------------------------------------------------------------------------------ cloth

/// Cumulated stretch springs: one spring per edge.
pub struct Cloth {
    /// Vertex state.
    pub s: State,
    /// Edge end vertices.
    edges: Vec<[u32; 2]>,
    /// Per edge: stiffness, damping, rest length.
    params: Vec<[f64; 3]>,
}

impl Cloth {
    /// From a simulation of `stretch_cumulated` (2D or 3D).
    pub fn from_sim(sim: &Simulation) -> Self {
        let g = sim.gmap();
        let label = vertex_labels(g);
        let reps = g.orbit_representatives(OrbitType::edge(g.dimension()));
        let mut edges = Vec::with_capacity(reps.len());
        let mut params = Vec::with_capacity(reps.len());
        for d in reps {
            let b = g.alpha(0, d);
            edges.push([label[d.index()], label[b.index()]]);
            params.push([
                read::<1>(g, "spring_k_edge", d)[0],
                read::<1>(g, "spring_c_edge", d)[0],
                read::<1>(g, "spring_l0_edge", d)[0],
            ]);
        }
        Cloth {
            s: State::from_sim(sim),
            edges,
            params,
        }
    }
}

impl Baseline for Cloth {
    fn state(&self) -> &State {
        &self.s
    }
    fn state_mut(&mut self) -> &mut State {
        &mut self.s
    }
    fn forces(&mut self) {
        self.s.clear_forces();
        let (x, v, f) = (&self.s.x, &self.s.v, &mut self.s.f);
        for (&[a, b], &[k, c, l0]) in self.edges.iter().zip(&self.params) {
            let (a, b) = (a as usize, b as usize);
            let d = sub(x[b], x[a]);
            let l = dot(d, d).sqrt();
            let il = 1.0 / l;
            let u = [d[0] * il, d[1] * il, d[2] * il];
            let s = k * (l - l0) + c * dot(sub(v[b], v[a]), u);
            for i in 0..3 {
                f[a][i] += s * u[i];
                f[b][i] -= s * u[i];
            }
        }
    }
    fn memory_bytes(&self) -> usize {
        self.s.memory_bytes() + self.edges.len() * (8 + 24)
    }
    /// Per edge: its two vertex numbers and three parameters (32 B); d (3), l^2 (5), u (3),
    /// the spring and damper force (12), the two updates (9): 32 operations, one sqrt and
    /// one division.
    fn work(&self) -> Work {
        let e = self.edges.len() as f64;
        self.s.work().add(Work {
            bytes: e * 32.0,
            flops: e * 32.0,
            sqrt_div: e * 2.0,
        })
    }
}

// ------------------------------------------------------------------------------ tetrahedra

/// The vertices of each tetrahedron in the engine's numbering (from its `vertex0` dart, the
/// smallest of the volume): `n0`, `a0(n0)`, `a0(a1(n0))`, `a0(a1(a2(n0)))`.
fn tet_vertices(g: &GMap, label: &[u32]) -> Vec<(Dart, [u32; 4])> {
    g.orbit_representatives(OrbitType::volume())
        .into_iter()
        .map(|n0| {
            let n1 = g.alpha(0, n0);
            let n2 = g.alpha(0, g.alpha(1, n0));
            let n3 = g.alpha(0, g.alpha(1, g.alpha(2, n0)));
            let l = |d: Dart| label[d.index()];
            (n0, [l(n0), l(n1), l(n2), l(n3)])
        })
        .collect()
}

/// Co-rotational linear tetrahedra.
pub struct Corotational {
    /// Vertex state.
    pub s: State,
    tets: Vec<[u32; 4]>,
    /// Inverse rest edge matrix `Dm^-1`.
    dm_inv: Vec<M3>,
    /// Rest positions of the four vertices.
    x_rest: Vec<[f64; 12]>,
    /// Element stiffness, 12x12 row-major, node-major (x0, y0, z0, x1, ...).
    k: Vec<[f64; 144]>,
}

impl Corotational {
    /// From a simulation of `corotational` on tetrahedra.
    pub fn from_sim(sim: &Simulation) -> Self {
        let g = sim.gmap();
        let label = vertex_labels(g);
        let tv = tet_vertices(g, &label);
        let mut b = Corotational {
            s: State::from_sim(sim),
            tets: Vec::with_capacity(tv.len()),
            dm_inv: Vec::with_capacity(tv.len()),
            x_rest: Vec::with_capacity(tv.len()),
            k: Vec::with_capacity(tv.len()),
        };
        for (n0, verts) in tv {
            b.tets.push(verts);
            b.dm_inv.push(m3(read(g, "dm_inv", n0)));
            b.x_rest.push(read(g, "x_rest", n0));
            b.k.push(read(g, "k_elem", n0));
        }
        b
    }
}

impl Baseline for Corotational {
    fn state(&self) -> &State {
        &self.s
    }
    fn state_mut(&mut self) -> &mut State {
        &mut self.s
    }
    fn forces(&mut self) {
        self.s.clear_forces();
        let (x, f) = (&self.s.x, &mut self.s.f);
        for (((t, dm), xr), k) in self
            .tets
            .iter()
            .zip(&self.dm_inv)
            .zip(&self.x_rest)
            .zip(&self.k)
        {
            let p = t.map(|i| x[i as usize]);
            // F = Ds Dm^-1, Ds the edge matrix (columns x1 - x0, x2 - x0, x3 - x0)
            let e = [sub(p[1], p[0]), sub(p[2], p[0]), sub(p[3], p[0])];
            let mut fm = [[0.0; 3]; 3];
            for r in 0..3 {
                for c in 0..3 {
                    fm[r][c] = e[0][r] * dm[0][c] + e[1][r] * dm[1][c] + e[2][r] * dm[2][c];
                }
            }
            let rot = polar3(&fm);
            // y = R^T x - X, node by node
            let mut y = [0.0; 12];
            for n in 0..4 {
                for r in 0..3 {
                    y[3 * n + r] = rot[0][r] * p[n][0] + rot[1][r] * p[n][1] + rot[2][r] * p[n][2]
                        - xr[3 * n + r];
                }
            }
            // g = K y, then f = -R g node by node
            let mut gk = [0.0; 12];
            for r in 0..12 {
                let row = &k[12 * r..12 * r + 12];
                let mut acc = 0.0;
                for c in 0..12 {
                    acc += row[c] * y[c];
                }
                gk[r] = acc;
            }
            for n in 0..4 {
                let gn = [gk[3 * n], gk[3 * n + 1], gk[3 * n + 2]];
                let fi = &mut f[t[n] as usize];
                for r in 0..3 {
                    fi[r] -= dot(rot[r], gn);
                }
            }
        }
    }
    fn memory_bytes(&self) -> usize {
        self.s.memory_bytes() + self.tets.len() * (16 + 72 + 96 + 1152)
    }
    /// Per tet: vertex numbers, Dm^-1, rest positions and the 12x12 stiffness (1,336 B);
    /// edges (9), F (45), y = R^T x - X (72), K y (276), f = -R g (72): 474 operations; the
    /// polar decomposition counted as one scaled Newton iteration (cofactors, determinant,
    /// the two norms and the update: about 102 operations, 2 square roots and 2 divisions).
    /// The baseline takes several iterations: the count is a lower bound.
    fn work(&self) -> Work {
        let t = self.tets.len() as f64;
        self.s.work().add(Work {
            bytes: t * 1336.0,
            flops: t * (474.0 + 102.0),
            sqrt_div: t * 4.0,
        })
    }
}

/// Mass-tensor tetrahedra, tensors cumulated on vertices and edges.
pub struct MassTensor {
    /// Vertex state.
    pub s: State,
    /// Displacements `x - X`, recomputed each step.
    u: Vec<V3>,
    /// Cumulated vertex tensors `K_ii`.
    t_vertex: Vec<M3>,
    /// Edges `(i, j)`.
    edges: Vec<[u32; 2]>,
    /// Cumulated edge tensors `K_ij` (`K_ji = K_ij^T`: the element stiffness is symmetric).
    t_edge: Vec<M3>,
}

impl MassTensor {
    /// From a simulation of `mass_tensor`.
    pub fn from_sim(sim: &Simulation) -> Self {
        let g = sim.gmap();
        let label = vertex_labels(g);
        let t_vertex = sim
            .vertex_darts()
            .into_iter()
            .map(|d| m3(read(g, "t_vertex_cum", d)))
            .collect();
        let reps = g.orbit_representatives(OrbitType::edge(3));
        let mut edges = Vec::with_capacity(reps.len());
        let mut t_edge = Vec::with_capacity(reps.len());
        for d in reps {
            // the edge-end at i stores K_ij: the force on i from the displacement of j
            let e = g.alpha(0, d);
            edges.push([label[d.index()], label[e.index()]]);
            t_edge.push(m3(read(g, "t_edge_cum", d)));
        }
        let s = State::from_sim(sim);
        MassTensor {
            u: vec![[0.0; 3]; s.x.len()],
            s,
            t_vertex,
            edges,
            t_edge,
        }
    }
}

impl Baseline for MassTensor {
    fn state(&self) -> &State {
        &self.s
    }
    fn state_mut(&mut self) -> &mut State {
        &mut self.s
    }
    fn forces(&mut self) {
        let s = &mut self.s;
        for (((u, x), r), (f, t)) in self
            .u
            .iter_mut()
            .zip(&s.x)
            .zip(&s.rest)
            .zip(s.f.iter_mut().zip(&self.t_vertex))
        {
            *u = sub(*x, *r);
            let k = mv(t, *u);
            *f = [-k[0], -k[1], -k[2]];
        }
        let (u, f) = (&self.u, &mut s.f);
        for (&[i, j], kij) in self.edges.iter().zip(&self.t_edge) {
            let (i, j) = (i as usize, j as usize);
            let fi = mv(kij, u[j]);
            let fj = mtv(kij, u[i]);
            for r in 0..3 {
                f[i][r] -= fi[r];
                f[j][r] -= fj[r];
            }
        }
    }
    fn memory_bytes(&self) -> usize {
        self.s.memory_bytes() + self.u.len() * (24 + 72) + self.edges.len() * (8 + 72)
    }
    /// Per vertex: the rest position and the vertex tensor read, u written and read (144 B);
    /// u (3), K_ii u (15), its negation (3). Per edge: its vertex numbers and one tensor
    /// (80 B); two products (30) and the two updates (6).
    fn work(&self) -> Work {
        let (n, e) = (self.u.len() as f64, self.edges.len() as f64);
        self.s.work().add(Work {
            bytes: n * 144.0 + e * 80.0,
            flops: n * 21.0 + e * 36.0,
            sqrt_div: 0.0,
        })
    }
}

/// Stable Neo-Hookean tetrahedra (`neohookean`): per element `F = Ds Dm^-1`, the first
/// Piola-Kirchhoff stress `P = mu (1 - 1 / (I_C + 1)) F + lambda (J - alpha) cof F` with
/// `I_C = tr(F^T F)`, `J = det F`, `alpha = 1 + 3 mu / (4 lambda)`, `cof F` the columns
/// `f1 x f2, f2 x f0, f0 x f1`, and the forces `H = -V P Dm^-T` on vertices 1-3, their
/// negated sum on vertex 0 (Smith, de Goes & Kim 2018, doi:10.1145/3180491; Sifakis & Barbic
/// 2012 for `H`). The rest data (`Dm^-1`, `V`, the reparametrised Lame parameters) are read
/// from the engine's map, as the rule's init computes them.
pub struct NeoHookean {
    /// Vertex state.
    pub s: State,
    tets: Vec<[u32; 4]>,
    /// Inverse rest edge matrix `Dm^-1`.
    dm_inv: Vec<M3>,
    /// Per tet: rest volume, mu and lambda.
    material: Vec<[f64; 3]>,
}

impl NeoHookean {
    /// From a simulation of `neohookean` on tetrahedra.
    pub fn from_sim(sim: &Simulation) -> Self {
        let g = sim.gmap();
        let tv = tet_vertices(g, &vertex_labels(g));
        let scalar = |name: &str, d: Dart| read::<1>(g, name, d)[0];
        NeoHookean {
            s: State::from_sim(sim),
            tets: tv.iter().map(|t| t.1).collect(),
            dm_inv: tv
                .iter()
                .map(|&(n0, _)| m3(read(g, "hyper_dm_inv", n0)))
                .collect(),
            material: tv
                .iter()
                .map(|&(n0, _)| ["hyper_volume", "nh_mu", "nh_lambda"].map(|e| scalar(e, n0)))
                .collect(),
        }
    }
}

impl Baseline for NeoHookean {
    fn state(&self) -> &State {
        &self.s
    }
    fn state_mut(&mut self) -> &mut State {
        &mut self.s
    }
    fn forces(&mut self) {
        self.s.clear_forces();
        let (x, f) = (&self.s.x, &mut self.s.f);
        for ((t, dm), &[vol, mu, lambda]) in self.tets.iter().zip(&self.dm_inv).zip(&self.material)
        {
            let p = t.map(|i| x[i as usize]);
            let e = [sub(p[1], p[0]), sub(p[2], p[0]), sub(p[3], p[0])];
            // F = Ds Dm^-1, row-major; its columns c0, c1, c2
            let mut fm = [[0.0; 3]; 3];
            for r in 0..3 {
                for c in 0..3 {
                    fm[r][c] = e[0][r] * dm[0][c] + e[1][r] * dm[1][c] + e[2][r] * dm[2][c];
                }
            }
            let col = |c: usize| [fm[0][c], fm[1][c], fm[2][c]];
            let (c0, c1, c2) = (col(0), col(1), col(2));
            let cof = [cross(c1, c2), cross(c2, c0), cross(c0, c1)];
            let ic = dot(c0, c0) + dot(c1, c1) + dot(c2, c2);
            let j = dot(c0, cof[0]);
            let alpha = 1.0 + 0.75 * mu / lambda;
            let a = mu * (1.0 - 1.0 / (ic + 1.0));
            let b = lambda * (j - alpha);
            // P = a F + b cof F (cof F's column k is cof[k])
            let mut pm = [[0.0; 3]; 3];
            for r in 0..3 {
                for c in 0..3 {
                    pm[r][c] = a * fm[r][c] + b * cof[c][r];
                }
            }
            // H = -V P Dm^-T: column k of H is the force on vertex k + 1
            let mut f0 = [0.0; 3];
            for k in 0..3 {
                let mut h = [0.0; 3];
                for r in 0..3 {
                    h[r] = -vol * (pm[r][0] * dm[k][0] + pm[r][1] * dm[k][1] + pm[r][2] * dm[k][2]);
                }
                let fk = &mut f[t[k + 1] as usize];
                for r in 0..3 {
                    fk[r] += h[r];
                    f0[r] -= h[r];
                }
            }
            let fv = &mut f[t[0] as usize];
            for r in 0..3 {
                fv[r] += f0[r];
            }
        }
    }
    fn memory_bytes(&self) -> usize {
        self.s.memory_bytes() + self.tets.len() * (16 + 72 + 24)
    }
    /// Per tet: vertex numbers, Dm^-1, volume, mu and lambda (112 B); edges (9), F (45), the
    /// three cofactor columns (27), I_C (17), J (5), the scalars (7), P (27), H (45 and its
    /// 9 scalings), the forces (18): 209 operations, 2 divisions.
    fn work(&self) -> Work {
        let t = self.tets.len() as f64;
        self.s.work().add(Work {
            bytes: t * 112.0,
            flops: t * 209.0,
            sqrt_div: t * 2.0,
        })
    }
}

// ---------------------------------------------------------------------------- polar rotation

fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn unit_or(x: V3, fallback: V3) -> V3 {
    let n = norm(x);
    if n > 0.0 && n.is_finite() {
        [x[0] / n, x[1] / n, x[2] / n]
    } else {
        fallback
    }
}

fn perpendicular(u: V3) -> V3 {
    let mut k = 0;
    for i in 1..3 {
        if u[i].abs() < u[k].abs() {
            k = i;
        }
    }
    let mut w = u.map(|x| -u[k] * x);
    w[k] += 1.0;
    unit_or(w, [0.0, 0.0, 1.0])
}

/// The rotation of the polar decomposition of `m`, by the algorithm of the engine's `polar`
/// built-in (crates/lang/src/builtins.rs, `polar3_data`), written again for this file's
/// arrays with the same operations in the same order, so that both agree bit for bit where
/// Newton applies: Newton's iteration with Frobenius-norm scaling (Higham 1986,
/// doi:10.1137/0907079) from `m` normalized by a power of two, used when `det m > 0` and the
/// condition number is below about 100 ([`polar3_newton`]), else the one-sided Jacobi SVD
/// ([`polar3_jacobi`]). Fixed-size arrays, no allocation.
pub fn polar3(m: &M3) -> M3 {
    let mut s = 0.0_f64;
    for row in m {
        for &x in row {
            s = s.max(x.abs());
        }
    }
    if s == 0.0 {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    polar3_newton(m, s).unwrap_or_else(|| polar3_jacobi(m))
}

/// Newton's iteration for the polar rotation of `m` (largest entry magnitude `s > 0`), as
/// the engine's `polar3_newton`: `X <- (g X + (g X)^{-T}) / 2` with `X^{-T} = C / det X` (C the
/// cofactors), Frobenius scaling `g = (|X^-1|_F / |X|_F)^{1/2}` on the first step and while
/// `|X|_F^2 > 4`, stopping after an unscaled step with `|X_{k+1} - X_k|_F^2 <= eps`. `None`
/// when `det X <= 0`, `27 K^4 det^2 < |X|_F^6` or `|X|_F |C|_F > K det` (K = 100), when `s`
/// is below 2^-1022 or at least 2^1023, or after 20 steps.
pub fn polar3_newton(m: &M3, s: f64) -> Option<M3> {
    const K2: f64 = 100.0 * 100.0;
    let biased = s.to_bits() >> 52;
    if !(1..2046).contains(&biased) {
        return None;
    }
    let scale = f64::from_bits((2046 - biased) << 52);
    let mut x = [[0.0; 3]; 3];
    let mut nr = [0.0; 3];
    for i in 0..3 {
        for j in 0..3 {
            x[i][j] = m[i][j] * scale;
            nr[j] += x[i][j] * x[i][j];
        }
    }
    let mut nx = nr[0] + nr[1] + nr[2];
    let mut scaled = true;
    for k in 0..20 {
        let c = [
            [
                x[1][1] * x[2][2] - x[1][2] * x[2][1],
                x[1][2] * x[2][0] - x[1][0] * x[2][2],
                x[1][0] * x[2][1] - x[1][1] * x[2][0],
            ],
            [
                x[0][2] * x[2][1] - x[0][1] * x[2][2],
                x[0][0] * x[2][2] - x[0][2] * x[2][0],
                x[0][1] * x[2][0] - x[0][0] * x[2][1],
            ],
            [
                x[0][1] * x[1][2] - x[0][2] * x[1][1],
                x[0][2] * x[1][0] - x[0][0] * x[1][2],
                x[0][0] * x[1][1] - x[0][1] * x[1][0],
            ],
        ];
        let d = x[0][0] * c[0][0] + x[0][1] * c[0][1] + x[0][2] * c[0][2];
        let (a, b) = if scaled {
            let mut ncr = [0.0; 3];
            for i in 0..3 {
                for j in 0..3 {
                    ncr[j] += c[i][j] * c[i][j];
                }
            }
            let nc = ncr[0] + ncr[1] + ncr[2];
            let w = 1.0 / (nx * nc * (d * d));
            if k == 0 {
                let d2 = d * d;
                if !(d > 0.0 && nx * nx * nx <= 27.0 * K2 * K2 * d2 && nx * nc <= K2 * d2) {
                    return None;
                }
            }
            let sw = w.sqrt();
            let g = (nc * sw).sqrt();
            (0.5 * g, 0.5 * g * (nx * d * sw))
        } else {
            (0.5, 0.5 / d)
        };
        let mut step = [0.0; 3];
        let mut norm = [0.0; 3];
        for i in 0..3 {
            for j in 0..3 {
                let y = a * x[i][j] + b * c[i][j];
                let e = y - x[i][j];
                step[j] += e * e;
                norm[j] += y * y;
                x[i][j] = y;
            }
        }
        let step = step[0] + step[1] + step[2];
        nx = norm[0] + norm[1] + norm[2];
        if !scaled && step <= f64::EPSILON {
            return Some(x);
        }
        scaled = nx > 4.0;
    }
    None
}

/// The polar rotation by the algorithm of the engine's `polar3_jacobi`: a one-sided Jacobi
/// SVD `m = U S V^T` of the scaled matrix (Hestenes rotations until every pair of columns is
/// orthogonal to machine precision), singular values ordered, `det V = +1`, `U` completed
/// with `det U = +1` so that the smallest singular value carries the sign of `det m` (Irving
/// et al. 2004); `R = U V^T`.
fn polar3_jacobi(m: &M3) -> M3 {
    let mut s = 0.0_f64;
    for row in m {
        for &x in row {
            s = s.max(x.abs());
        }
    }
    if s == 0.0 {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let inv_s = 1.0 / s;
    // columns of A = (m / s) V, and of V
    let mut a = [[0.0; 3]; 3];
    for j in 0..3 {
        for i in 0..3 {
            a[j][i] = m[i][j] * inv_s;
        }
    }
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..64 {
        let mut rotated = false;
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let alpha = dot(a[p], a[p]);
            let beta = dot(a[q], a[q]);
            let gamma = dot(a[p], a[q]);
            if gamma == 0.0 || gamma.abs() <= f64::EPSILON * (alpha * beta).sqrt() {
                continue;
            }
            rotated = true;
            let zeta = (beta - alpha) / (2.0 * gamma);
            let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
            let c = 1.0 / (1.0 + t * t).sqrt();
            let sn = c * t;
            for w in [&mut a, &mut v] {
                let (x, y) = (w[p], w[q]);
                w[p] = [
                    c * x[0] - sn * y[0],
                    c * x[1] - sn * y[1],
                    c * x[2] - sn * y[2],
                ];
                w[q] = [
                    sn * x[0] + c * y[0],
                    sn * x[1] + c * y[1],
                    sn * x[2] + c * y[2],
                ];
            }
        }
        if !rotated {
            break;
        }
    }
    // order by decreasing singular value (stable, as the engine's sort)
    let n = [norm(a[0]), norm(a[1]), norm(a[2])];
    let mut order = [0, 1, 2];
    for i in 1..3 {
        let mut j = i;
        while j > 0 && n[order[j]] > n[order[j - 1]] {
            order.swap(j, j - 1);
            j -= 1;
        }
    }
    let a = order.map(|k| a[k]);
    let mut v = order.map(|k| v[k]);
    if dot(v[0], cross(v[1], v[2])) < 0.0 {
        v[2] = v[2].map(|x| -x);
    }
    let u1 = unit_or(a[0], [1.0, 0.0, 0.0]);
    let mut w = a[1];
    for _ in 0..2 {
        let d = dot(u1, w);
        w = [w[0] - d * u1[0], w[1] - d * u1[1], w[2] - d * u1[2]];
    }
    let u2 = if norm(w) > 1e-290 {
        unit_or(w, perpendicular(u1))
    } else {
        perpendicular(u1)
    };
    let u3 = unit_or(cross(u1, u2), [0.0, 0.0, 1.0]);
    let u = [u1, u2, u3];
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = u[0][i] * v[0][j] + u[1][i] * v[1][j] + u[2][i] * v[2][j];
        }
    }
    r
}

// ------------------------------------------------------------------------------ the cases

/// The three benchmarked models.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    /// `stretch_cumulated` on a quad grid (elements: quads).
    Cloth,
    /// `corotational` on a box of tetrahedra (elements: tetrahedra).
    Corotational,
    /// `mass_tensor` on a box of tetrahedra (elements: tetrahedra).
    MassTensor,
    /// `neohookean` on a box of tetrahedra (elements: tetrahedra).
    NeoHookean,
}

impl Model {
    /// Every model, in report order.
    pub const ALL: [Model; 4] = [
        Model::Cloth,
        Model::Corotational,
        Model::MassTensor,
        Model::NeoHookean,
    ];

    /// The engine's name of the model.
    pub fn kind(self) -> &'static str {
        match self {
            Model::Cloth => "stretch_cumulated",
            Model::Corotational => "corotational",
            Model::MassTensor => "mass_tensor",
            Model::NeoHookean => "neohookean",
        }
    }

    /// What an element is.
    pub fn element(self) -> &'static str {
        match self {
            Model::Cloth => "quad",
            Model::Corotational | Model::MassTensor | Model::NeoHookean => "tet",
        }
    }

    /// The mesh of about `target` elements: its cell counts and the number of elements.
    /// Cloth: a square grid of n x n quads on the unit square. Volumes: a box of cubes,
    /// `nx x n x n` (about twice as long as wide), each cube split into 6 tetrahedra.
    pub fn cells(self, target: usize) -> (Vec<usize>, usize) {
        let t = target as f64;
        match self {
            Model::Cloth => {
                let n = (t.sqrt().round() as usize).max(2);
                (vec![n, n], n * n)
            }
            Model::Corotational | Model::MassTensor | Model::NeoHookean => {
                let n = ((t / 12.0).cbrt().round() as usize).max(2);
                let nx = ((t / (6.0 * (n * n) as f64)).round() as usize).max(2);
                (vec![nx, n, n], 6 * nx * n * n)
            }
        }
    }

    /// The simulation of this model on the mesh of `cells` (from [`Model::cells`]), built at
    /// rest and then deformed (the same deformation for every size): a cloth fixed along
    /// `x = 0` with a bump out of its plane, a box fixed at `x = 0`, stretched by 1% and twisted
    /// about its axis. Gravity, viscous damping, and spring damping for the cloth. Stable with
    /// [`DT`] up to 10^6 elements: the largest frequency is about 2,800 rad/s for the cloth
    /// (`sqrt(4 k / m)`, k = 2,000 N/m per interior edge, m = 1 g per vertex) and, by power
    /// iteration on the mass-tensor stiffness at 10^4 tetrahedra scaled by the element size,
    /// about 4,800 rad/s for the box: `dt omega` below 0.5, symplectic Euler needs below 2.
    pub fn simulation(self, cells: &[usize]) -> Simulation {
        use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
        use topomech_gmap::mesh::{build, BuildOptions};
        use topomech_physics::{Config, ModelSpec};
        let (mesh, params): (_, Vec<(String, f64)>) = match self {
            Model::Cloth => (
                grid([cells[0], cells[1]], [1.0, 1.0], GridElement::Quad),
                vec![("stiffness".into(), 1e3), ("damping".into(), 0.1)],
            ),
            Model::Corotational | Model::MassTensor | Model::NeoHookean => {
                let len = cells[0] as f64 / cells[1] as f64;
                (
                    cuboid(
                        [cells[0], cells[1], cells[2]],
                        [len, 1.0, 1.0],
                        BoxElement::Tetra,
                    ),
                    vec![],
                )
            }
        };
        let (g, _) = build(&mesh, &BuildOptions::default()).expect("a valid mesh");
        let cfg = Config {
            models: vec![ModelSpec {
                kind: self.kind().into(),
                params: params
                    .into_iter()
                    .map(|(k, v)| (k, topomech_rules::Val::F(v)))
                    .collect(),
            }],
            density: 1000.0,
            young: 1e6,
            poisson: 0.3,
            damping: 0.5,
            gravity: [0.0, -9.81, 0.0],
            fixed: vec!["x < 1e-9".into()],
            dt: DT,
            ..Config::default()
        };
        let mut sim = Simulation::new(g, cfg).expect("the simulation builds");
        let x: Vec<V3> = sim
            .vertex_vec3("rest")
            .expect("rest")
            .into_iter()
            .map(|p| self.deformed(p))
            .collect();
        sim.set_vertex_vec3("position", &x).expect("set positions");
        sim
    }

    /// The initial deformation (none at `x = 0`, where vertices are fixed).
    pub fn deformed(self, p: V3) -> V3 {
        let pi = std::f64::consts::PI;
        match self {
            Model::Cloth => [p[0], p[1], 0.05 * (pi * p[0]).sin() * (pi * p[1]).sin()],
            Model::Corotational | Model::MassTensor | Model::NeoHookean => {
                let th = 0.2 * p[0];
                let (s, c) = th.sin_cos();
                let (y, z) = (p[1] - 0.5, p[2] - 0.5);
                [1.01 * p[0], 0.5 + c * y - s * z, 0.5 + s * y + c * z]
            }
        }
    }

    /// The baseline of this model, from the simulation's current state.
    pub fn baseline(self, sim: &Simulation) -> Box<dyn Baseline> {
        match self {
            Model::Cloth => Box::new(Cloth::from_sim(sim)),
            Model::Corotational => Box::new(Corotational::from_sim(sim)),
            Model::MassTensor => Box::new(MassTensor::from_sim(sim)),
            Model::NeoHookean => Box::new(NeoHookean::from_sim(sim)),
        }
    }
}

/// How far the engine's positions are from the baseline's: the largest distance between
/// corresponding vertices, relative to the largest distance a vertex moved from `start` (the
/// positions both began the compared steps from). Returns (relative difference, motion).
pub fn disagreement(sim: &Simulation, base: &dyn Baseline, start: &[V3]) -> (f64, f64) {
    let x = sim.vertex_vec3("position").expect("positions");
    let y = base.positions();
    assert_eq!(x.len(), y.len(), "vertex counts differ");
    let motion = y
        .iter()
        .zip(start)
        .map(|(a, b)| norm(sub(*a, *b)))
        .fold(0.0, f64::max);
    let diff = x
        .iter()
        .zip(y)
        .map(|(a, b)| norm(sub(*a, *b)))
        .fold(0.0, f64::max);
    (diff / motion, motion)
}
