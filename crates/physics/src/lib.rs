//! Physics through rules: the models of the paper as rule files, and the simulation loop.
//!
//! Every model is a `.tmr` file shipped in `models/` (see [`shipped_models`]) declaring it as
//! a `model` (see [`model`](crate::model)): an init rule that
//! stores its parameters on the orbits the paper's Tables 1 and 2 give, and interaction rules
//! that store forces on sub-orbits of the vertices. A step applies, in order, every model's
//! interaction rules everywhere, one accumulation rule that sums every force embedding over
//! each vertex's sub-orbits into `force`, and an integration rule. Nothing is stored beside
//! the G-map: the simulation state is its embeddings.
//!
//! Where things are:
//! - `model`: finding a model's declaration (shipped or the user's file) and binding its
//!   parameters;
//! - `schedule`: building a simulation, the glue rules of a step (accumulation, fixed and
//!   prescribed vertices, material regions, ground) and the set-up they run;
//! - `integrate`: a time step and the explicit integrators;
//! - `solve`: Jacobian-vector products, implicit Euler and the static solve;
//! - `events`: timed cuts and fracture;
//! - `state`: rows (particles) and reading and writing embeddings per vertex;
//! - `config`: what a simulation is built from beside the map.
#![warn(missing_docs)]

mod config;
mod events;
mod integrate;
mod linear;
mod malloc;
mod model;
mod schedule;
mod solve;
mod state;

use std::fmt::Write as _;

use topomech_gmap::GMap;
use topomech_rules::{ApplyError, Diagnostic, Params, RuleSet};

pub use config::*;
pub use events::*;
pub use linear::Csr;
pub use malloc::tune_malloc;
pub use model::*;
pub use schedule::{check_predicate, eval_expression, eval_predicate, PointsError};
pub use solve::*;
pub use state::*;

/// Why a simulation could not be built or stepped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhysicsError {
    /// Unknown model kind, or one that does not exist in this dimension.
    #[error("{0}")]
    Model(String),
    /// A bad parameter, predicate or setting.
    #[error("{0}")]
    Config(String),
    /// A rule file (shipped, or generated from the scene) was refused.
    #[error("rules refused:\n{}", .0.iter().map(ToString::to_string).collect::<Vec<_>>().join("\n"))]
    Rules(Vec<Diagnostic>),
    /// A rule failed to apply.
    #[error(transparent)]
    Apply(#[from] ApplyError),
    /// The simulation diverged; the last good state was kept.
    #[error("diverged at step {step}: {why}{} (the last good state is kept)", vertex_at(*.vertex, *.point))]
    Diverged {
        /// The step that failed.
        step: u64,
        /// The vertex (its row: index in the per-vertex arrays) where it means something
        /// (the largest residual force, the first non-finite value); None for a failure of
        /// a global linear solve.
        vertex: Option<usize>,
        /// That row's input point (its `point_id`: the index of the point in the mesh the
        /// map was imported from, which differs from the row where the mesh has unused
        /// points), where the map has one; filled in by [`Simulation::step`] and
        /// [`Simulation::solve_static`] (None elsewhere, and for a vertex a rule created).
        point: Option<i64>,
        /// What happened.
        why: String,
    },
}

impl PhysicsError {
    /// A [`PhysicsError::Diverged`] without its input point, which the public entry points
    /// fill in from the vertex row ([`Simulation::step`], [`Simulation::solve_static`]).
    pub(crate) fn diverged(step: u64, vertex: Option<usize>, why: String) -> Self {
        PhysicsError::Diverged {
            step,
            vertex,
            point: None,
            why,
        }
    }
}

/// How a divergence message names its vertex: its row, and its input point where known.
fn vertex_at(vertex: Option<usize>, point: Option<i64>) -> String {
    match (vertex, point) {
        (None, _) => String::new(),
        (Some(v), Some(p)) if p >= 0 => format!(" at vertex row {v} (input point {p})"),
        (Some(v), _) => format!(" at vertex row {v}"),
    }
}

/// A running simulation: a G-map with its embeddings, and the rules that move it.
#[derive(Debug)]
pub struct Simulation {
    g: GMap,
    rules: RuleSet,
    cfg: Config,
    defs: Vec<model::RunModel>,
    step_params: Params,
    time: f64,
    steps: u64,
    /// The vertex numbering (rows), kept in step with the map's topology version.
    rows: Rows,
    vertex_darts_version: u64,
    /// The diagonal of the rest bounding box: no vertex moves that far in one step.
    size: f64,
    /// Which events have happened.
    events_done: Vec<bool>,
    /// The faces (3D) or edges (2D) each blade has opened so far.
    blades_opened: Vec<usize>,
    /// Whether the rule a fracture criterion's measure needs run once beforehand has run
    /// (the strain's inverse rest lengths; see `events::criterion_init`).
    measure_ready: bool,
    /// The strain criterion's state at its last evaluation, which lets a step whose vertices
    /// moved too little since skip it (see `events::StrainBound`).
    strain_bound: Option<events::StrainBound>,
    /// The topology changes so far.
    changes: Vec<TopologyChange>,
    /// The position and velocity columns before the step being taken (kept between steps so
    /// that a step allocates nothing).
    saved: [Vec<f64>; 2],
    /// The steps that copied the state into `saved` (see
    /// [`Simulation::steps_saving_state`]).
    saving_steps: usize,
    /// The velocity the fast runaway test measures speeds from: the mean velocity of a body
    /// of one part at the last step whose runaway test was taken the slow way (zero at
    /// first); see `integrate::Simulation::runaway`.
    frame: [f64; 3],
    /// Each row's part of the body (see `integrate::Simulation::parts`) and the number of
    /// parts, for the map identity (id, topology version) it was found for.
    parts: Option<((u64, u64), Vec<usize>, usize)>,
    /// What the last static or implicit Euler step's solve did.
    report: Option<SolverReport>,
    /// The positions of the last converged static solve: where a load ramp of prescribed
    /// displacements starts from (the rest positions before the first one).
    static_base: Vec<[f64; 3]>,
    /// What the linear solvers keep between solves (coupling graph, colorings, symbolic
    /// factorization, the implicit Euler preconditioner and warm start).
    solver: linear::SolverCache,
    /// The map's identity and the write counts of the force embeddings (`f_*`) when the last
    /// [`Simulation::forces`] ended: while both are unchanged and no step rule has a guard,
    /// the step rules write the same slots as last time, so the force columns need no reset.
    forces_written: Option<((u64, u64), Vec<u64>)>,
    /// Whether [`Simulation::jvp`] takes finite differences of the forces instead of the
    /// models' `jvp` rules (a static solve's fallback, see [`Simulation::solve_static`]).
    fd_jacobian: bool,
    /// Why the last Newton direction of the static solve in progress is approximate (its
    /// conjugate-gradient solve stopped at `max_iterations`), to say so if the solve fails.
    capped_solve: Option<String>,
}

/// Whether a vertex embedding holds a share of a row's quantity (masses and forces: `mass`,
/// `force`, `df`, `f_*`, `df_*`): read per row it is summed over the row's orbits, and written
/// per row it goes to the row's first orbit alone.
pub fn is_additive(name: &str) -> bool {
    matches!(name, "mass" | "force" | "df") || name.starts_with("f_") || name.starts_with("df_")
}

/// "1, 2, 3" for the first `limit` items, then "and N more".
fn list_some(items: &[usize], limit: usize) -> String {
    let mut s = items
        .iter()
        .take(limit)
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ");
    if items.len() > limit {
        let _ = write!(s, " and {} more", items.len() - limit);
    }
    s
}

/// The Euclidean norm of a `(V, 3)` array, scaled by its largest entry so that forces up to
/// the largest f64 do not overflow when squared (an unscaled sum of squares of 1e160 N is
/// infinite, and a solve would take an infinite tolerance for convergence).
fn rows_norm(r: &[[f64; 3]]) -> f64 {
    let m = r.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    if m == 0.0 || !m.is_finite() {
        return m;
    }
    m * r
        .iter()
        .flatten()
        .map(|x| (x / m) * (x / m))
        .sum::<f64>()
        .sqrt()
}

/// The length of a 3-vector, without overflow for entries up to the largest f64.
fn norm3(a: [f64; 3]) -> f64 {
    a[0].hypot(a[1]).hypot(a[2])
}

/// Zeroes the components of fixed vertices.
fn project(v: &mut [[f64; 3]], fixed: &[bool]) {
    for (x, &f) in v.iter_mut().zip(fixed) {
        if f {
            *x = [0.0; 3];
        }
    }
}

/// The shipped common rules a model file is loaded with on a map of dimension `dim` (2 or
/// 3): `(file name, text)`, declaring the material and the masses (`density`, `young`,
/// `poisson`, `mass`, ...) on that dimension's element orbit; it is loaded after
/// [`prelude_rules`]. None for
/// another dimension. Tools that check a user's model file (`topomech check`,
/// `topomech models`) load it after this, as a simulation does.
pub fn common_rules(dim: usize) -> Option<(String, &'static str)> {
    model::model_source("common", dim).map(|text| (format!("common{dim}d.tmr"), text))
}

/// The shipped prelude, `("prelude.tmr", text)`: the embeddings every simulation has that are
/// the same in both dimensions (`position`, `rest`, `velocity`, `force`, `fixed`, `f_ext`,
/// `dx`, `dv`, `df`, `vertex0`), `init_rest` and the integrators; a `dimension 2 3` file.
/// Every simulation and every model file is loaded with it first, then with
/// [`common_rules`] of its dimension (the material and the masses, on the element orbit).
pub fn prelude_rules() -> (String, &'static str) {
    (
        "prelude.tmr".to_string(),
        model::model_source("prelude", 3).expect("shipped"),
    )
}
