//! Physics through rules: the models of the paper as rule files, and the simulation loop.
//!
//! Every model is a `.tmr` file shipped in `models/` (see [`MODELS`]): an init rule that
//! stores its parameters on the orbits the paper's Tables 1 and 2 give, and interaction rules
//! that store forces on sub-orbits of the vertices. A step applies, in order, every model's
//! interaction rules everywhere, one accumulation rule that sums every force embedding over
//! each vertex's sub-orbits into `force`, and an integration rule. Nothing is stored beside
//! the G-map: the simulation state is its embeddings.
#![warn(missing_docs)]

use std::collections::HashMap;
use std::fmt::Write as _;

use topomech_gmap::{ColumnMut, Dart, EmbeddingId, EmbeddingType, GMap, OrbitType, Policy, Value};
use topomech_rules::{load_sources, ApplyError, Diagnostic, Params, RuleSet, Val};

/// A physical model: its rule file and rules.
#[derive(Clone, Copy, Debug)]
pub struct ModelDef {
    /// The scene's name for it.
    pub kind: &'static str,
    /// Dimensions it exists in.
    pub dims: &'static [usize],
    /// Base name of its rule file in `models/` (`{file}{dim}d.tmr`).
    pub file: &'static str,
    /// Init rules, applied once, in order; a rule's parameters come from the model's
    /// parameters of the same name.
    pub init: &'static [&'static str],
    /// Interaction rules, applied every step, in order.
    pub rules: &'static [&'static str],
    /// The force embeddings the accumulation sums.
    pub forces: &'static [&'static str],
    /// Rules computing the Jacobian-vector product `df = (df/dx) dx + (df/dv) dv`.
    pub jvp_rules: &'static [&'static str],
    /// The embeddings they write, summed per vertex into `df`.
    pub jvp_forces: &'static [&'static str],
    /// Parameters with their defaults.
    pub params: &'static [(&'static str, f64)],
    /// What the model needs of the mesh, said when it matches nothing.
    pub needs: &'static str,
    /// Whether every element must be matched by one of the init rules (the element models:
    /// an element they cannot handle would silently get no force).
    pub per_element: bool,
}

/// Every model topomech ships.
pub const MODELS: &[ModelDef] = &[
    ModelDef {
        kind: "stretch_elementary",
        dims: &[2, 3],
        file: "stretch",
        init: &["stretch_init"],
        rules: &["stretch_elementary"],
        forces: &["f_stretch"],
        jvp_rules: &["stretch_elementary_jvp"],
        jvp_forces: &["df_stretch"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "edges",
        per_element: false,
    },
    ModelDef {
        kind: "stretch_cumulated",
        dims: &[2, 3],
        file: "stretch",
        init: &["stretch_init"],
        rules: &["stretch_cumulated"],
        forces: &["f_stretch_cum"],
        jvp_rules: &["stretch_cumulated_jvp"],
        jvp_forces: &["df_stretch_cum"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "edges",
        per_element: false,
    },
    ModelDef {
        kind: "shear_isotropic",
        dims: &[2, 3],
        file: "shear",
        init: &["shear_isotropic_init"],
        rules: &["shear_isotropic"],
        forces: &["f_shear_iso"],
        jvp_rules: &["shear_isotropic_jvp"],
        jvp_forces: &["df_shear_iso"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "quadrilateral faces",
        per_element: false,
    },
    ModelDef {
        kind: "shear_anisotropic",
        dims: &[2, 3],
        file: "shear",
        init: &["shear_anisotropic_init"],
        rules: &["shear_anisotropic"],
        forces: &["f_shear_aniso"],
        jvp_rules: &["shear_anisotropic_jvp"],
        jvp_forces: &["df_shear_aniso"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "faces",
        per_element: false,
    },
    ModelDef {
        kind: "shear_volumic",
        dims: &[3],
        file: "shear",
        init: &["shear_volumic_init"],
        rules: &["shear_volumic"],
        forces: &["f_shear_vol"],
        jvp_rules: &["shear_volumic_jvp"],
        jvp_forces: &["df_shear_vol"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "hexahedra",
        per_element: false,
    },
    ModelDef {
        kind: "bending_linear",
        dims: &[2],
        file: "bending",
        init: &["bending_linear_init"],
        rules: &["bending_linear"],
        forces: &["f_bend_lin_a", "f_bend_lin_e"],
        jvp_rules: &["bending_linear_jvp"],
        jvp_forces: &["df_bend_lin_a", "df_bend_lin_e"],
        params: &[("stiffness", 100.0), ("damping", 0.0)],
        needs: "edges continuing each other across faces",
        per_element: false,
    },
    ModelDef {
        kind: "bending_angular",
        dims: &[2],
        file: "bending",
        init: &["bending_angular_init", "face_rest_centroids"],
        rules: &["face_centroids", "bending_angular"],
        forces: &["f_bend", "f_bend_wing"],
        jvp_rules: &[],
        jvp_forces: &[],
        params: &[("stiffness", 1.0), ("damping", 0.0)],
        needs: "interior edges between two triangles or quads",
        per_element: false,
    },
    ModelDef {
        kind: "linear_fem",
        dims: &[3],
        file: "fem",
        init: &["fem_init"],
        rules: &["linear_fem"],
        forces: &["f_linear"],
        jvp_rules: &["linear_fem_jvp"],
        jvp_forces: &["df_linear"],
        params: &[],
        needs: "tetrahedra",
        per_element: true,
    },
    ModelDef {
        kind: "corotational",
        dims: &[3],
        file: "fem",
        init: &["fem_init", "corotational_hex_init"],
        rules: &["corotational", "corotational_hex"],
        forces: &["f_corot", "f_corot_hex"],
        jvp_rules: &["corotational_jvp", "corotational_hex_jvp"],
        jvp_forces: &["df_corot", "df_corot_hex"],
        params: &[],
        needs: "tetrahedra or hexahedra",
        per_element: true,
    },
    ModelDef {
        kind: "corotational",
        dims: &[2],
        file: "fem",
        init: &["corotational_tri_init"],
        rules: &["corotational_tri"],
        forces: &["f_corot_tri"],
        jvp_rules: &["corotational_tri_jvp"],
        jvp_forces: &["df_corot_tri"],
        params: &[("thickness", 1.0)],
        needs: "triangles",
        per_element: true,
    },
    ModelDef {
        kind: "mass_tensor",
        dims: &[3],
        file: "fem",
        init: &["mass_tensor_init"],
        rules: &["mass_tensor_edges", "mass_tensor_vertices"],
        forces: &["f_tensor"],
        jvp_rules: &["mass_tensor_edges_jvp", "mass_tensor_vertices_jvp"],
        jvp_forces: &["df_tensor"],
        params: &[],
        needs: "tetrahedra",
        per_element: true,
    },
    ModelDef {
        kind: "neohookean",
        dims: &[3],
        file: "hyperelastic",
        init: &["neohookean_init"],
        rules: &["neohookean"],
        forces: &["f_neohookean"],
        jvp_rules: &["neohookean_jvp"],
        jvp_forces: &["df_neohookean"],
        params: &[],
        needs: "tetrahedra",
        per_element: true,
    },
    ModelDef {
        kind: "stvk",
        dims: &[3],
        file: "hyperelastic",
        init: &["stvk_init"],
        rules: &["stvk"],
        forces: &["f_stvk"],
        jvp_rules: &["stvk_jvp"],
        jvp_forces: &["df_stvk"],
        params: &[],
        needs: "tetrahedra",
        per_element: true,
    },
];

fn model_source(file: &str, dim: usize) -> Option<&'static str> {
    Some(match (file, dim) {
        ("common", 2) => include_str!("../models/common2d.tmr"),
        ("common", 3) => include_str!("../models/common3d.tmr"),
        ("stretch", 2) => include_str!("../models/stretch2d.tmr"),
        ("stretch", 3) => include_str!("../models/stretch3d.tmr"),
        ("fem", 3) => include_str!("../models/fem3d.tmr"),
        ("shear", 2) => include_str!("../models/shear2d.tmr"),
        ("shear", 3) => include_str!("../models/shear3d.tmr"),
        ("bending", 2) => include_str!("../models/bending2d.tmr"),
        ("fem", 2) => include_str!("../models/fem2d.tmr"),
        ("topology", 2) => include_str!("../models/topology2d.tmr"),
        ("topology", 3) => include_str!("../models/topology3d.tmr"),
        ("hyperelastic", 3) => include_str!("../models/hyperelastic3d.tmr"),
        _ => return None,
    })
}

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
    #[error("diverged at step {step}: {why} at vertex {vertex} (the last good state is kept)")]
    Diverged {
        /// The step that failed.
        step: u64,
        /// The vertex (its row: index in the per-vertex arrays).
        vertex: usize,
        /// What happened.
        why: String,
    },
}

/// The time integrator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Integrator {
    /// x += dt v; v += dt a (both from the old state).
    ExplicitEuler,
    /// v += dt a; x += dt v (the new velocity).
    SymplecticEuler,
    /// Backward Euler, linearized once per step (Baraff & Witkin 1998):
    /// (M - h df/dv - h^2 df/dx) dv = h (f + h (df/dx) v), solved by conjugate gradients on
    /// Jacobian-vector products computed by the models' rules.
    ImplicitEuler,
    /// Newton iterations to the equilibrium f(x) + m g = 0; each step is one solve.
    Static,
}

impl Integrator {
    /// Parses `explicit_euler`, `symplectic_euler`, `implicit_euler`, `static`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "explicit_euler" => Some(Integrator::ExplicitEuler),
            "symplectic_euler" => Some(Integrator::SymplecticEuler),
            "implicit_euler" => Some(Integrator::ImplicitEuler),
            "static" => Some(Integrator::Static),
            _ => None,
        }
    }
}

/// A model in a scene: its kind and parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelSpec {
    /// One of [`MODELS`]' kinds.
    pub kind: String,
    /// Parameters (missing ones take the model's defaults).
    pub params: HashMap<String, f64>,
}

/// Everything a simulation needs beside the map.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// The models, summed.
    pub models: Vec<ModelSpec>,
    /// Mass density (per volume in 3D, per area in 2D).
    pub density: f64,
    /// Young's modulus for the continuous models.
    pub young: f64,
    /// Poisson ratio for the continuous models.
    pub poisson: f64,
    /// Viscous damping (1/s).
    pub damping: f64,
    /// Gravity acceleration.
    pub gravity: [f64; 3],
    /// Predicates on the rest position (`x`, `y`, `z`) selecting fixed vertices, in the rule
    /// language's expression syntax (e.g. `x < 1e-9`).
    pub fixed: Vec<String>,
    /// Vertices held at a prescribed displacement from their rest position (they are fixed
    /// there): (predicate on the rest position, displacement).
    pub prescribed: Vec<(String, [f64; 3])>,
    /// Elements whose material differs: predicates on the element's rest centroid (`x`, `y`,
    /// `z`), applied in order after the defaults.
    pub regions: Vec<MaterialRegion>,
    /// A ground plane: vertices below it (on the side its normal points away from) are
    /// projected back onto it and lose the velocity component into it.
    pub ground: Option<Ground>,
    /// Topology changes at given times.
    pub events: Vec<TimedEvent>,
    /// Fracture (or tearing), tested after every step.
    pub fracture: Option<Fracture>,
    /// The integrator.
    pub integrator: Integrator,
    /// Time step.
    pub dt: f64,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            models: Vec::new(),
            density: 1000.0,
            young: 1e6,
            poisson: 0.3,
            damping: 0.0,
            gravity: [0.0, -9.81, 0.0],
            fixed: Vec::new(),
            prescribed: Vec::new(),
            regions: Vec::new(),
            ground: None,
            events: Vec::new(),
            fracture: None,
            integrator: Integrator::SymplecticEuler,
            dt: 1e-3,
        }
    }
}

/// A ground plane. Its normal (the side the bodies stay on) defaults to the opposite of
/// gravity, or +y without gravity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Ground {
    /// The plane `up . x = h`, `up` the default normal (a height above the origin along it;
    /// with gravity along -y, the plane `y = h`).
    Height(f64),
    /// The plane through `point` with `normal` (None: the default normal).
    Plane {
        /// A point of the plane (m).
        point: [f64; 3],
        /// Its normal, pointing to the side bodies stay on (any length but zero).
        normal: Option<[f64; 3]>,
    },
}

impl Ground {
    /// The default normal: the opposite of `gravity`, normalized; +y when gravity is zero.
    pub fn up(gravity: [f64; 3]) -> [f64; 3] {
        let n = norm3(gravity);
        if n > 0.0 && n.is_finite() {
            gravity.map(|g| -g / n)
        } else {
            [0.0, 1.0, 0.0]
        }
    }

    /// A point of the plane and its unit normal, for a simulation with this `gravity`.
    /// Errors name what is wrong: a non-finite value, a zero normal.
    pub fn plane(&self, gravity: [f64; 3]) -> Result<([f64; 3], [f64; 3]), PhysicsError> {
        let bad = |what: &str| PhysicsError::Config(format!("ground: {what}"));
        let (point, normal) = match *self {
            Ground::Height(h) => {
                if !h.is_finite() {
                    return Err(bad(&format!("the height must be finite, got {h}")));
                }
                let up = Ground::up(gravity);
                (up.map(|u| h * u), up)
            }
            Ground::Plane { point, normal } => {
                if point.iter().any(|x| !x.is_finite()) {
                    return Err(bad(&format!("the point must be finite, got {point:?}")));
                }
                let n = normal.unwrap_or_else(|| Ground::up(gravity));
                let len = norm3(n);
                if !(len > 0.0 && len.is_finite()) {
                    return Err(bad(&format!(
                        "the normal must be finite and not zero, got {n:?}"
                    )));
                }
                (point, n.map(|x| x / len))
            }
        };
        Ok((point, normal))
    }
}

/// Where a cut goes: along element boundaries, the faces (3D) or edges (2D) between two elements
/// that the geometry separates.
#[derive(Clone, Debug, PartialEq)]
pub enum Cut {
    /// The plane `normal . x = offset`: elements whose centroids (at the time of the cut) lie
    /// on opposite sides are separated.
    Plane {
        /// Normal of the plane.
        normal: [f64; 3],
        /// Its offset.
        offset: f64,
    },
    /// A predicate on the centroid `x`, `y`, `z` of the shared face (3D) or edge (2D).
    Where(String),
}

/// A topology change at a time.
#[derive(Clone, Debug, PartialEq)]
pub struct TimedEvent {
    /// When (s).
    pub time: f64,
    /// The cut.
    pub cut: Cut,
}

/// What opens a face (3D) or an edge (2D) during the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Criterion {
    /// The mean of the largest principal stresses of the two elements (tetrahedra).
    Stress,
    /// The strain of springs: the mean over the face's edges (3D), the edge's (2D; tearing).
    Strain,
}

/// Fracture settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fracture {
    /// The criterion.
    pub criterion: Criterion,
    /// Its threshold (a stress in Pa, or a strain).
    pub threshold: f64,
}

/// A topology change that happened.
#[derive(Clone, Debug, PartialEq)]
pub struct TopologyChange {
    /// The step after which it happened.
    pub step: u64,
    /// The time.
    pub time: f64,
    /// `cut` or `fracture`.
    pub kind: &'static str,
    /// Faces (3D) or edges (2D) unsewn.
    pub unsewn: usize,
}

/// A region of elements with their own material (unset values keep the defaults).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct MaterialRegion {
    /// Predicate on the element's rest centroid `x`, `y`, `z`.
    pub predicate: String,
    /// Density.
    pub density: Option<f64>,
    /// Young's modulus.
    pub young: Option<f64>,
    /// Poisson ratio.
    pub poisson: Option<f64>,
}

/// A running simulation: a G-map with its embeddings, and the rules that move it.
#[derive(Debug)]
pub struct Simulation {
    g: GMap,
    rules: RuleSet,
    cfg: Config,
    defs: Vec<(ModelDef, HashMap<String, f64>)>,
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
    /// The topology changes so far.
    changes: Vec<TopologyChange>,
    /// The position and velocity columns before the step being taken (kept between steps so
    /// that a step allocates nothing).
    saved: [Vec<f64>; 2],
    /// What the last static or implicit Euler step's solve did.
    report: Option<SolverReport>,
    /// The positions of the last converged static solve: where a load ramp of prescribed
    /// displacements starts from (the rest positions before the first one).
    static_base: Vec<[f64; 3]>,
}

/// What the solve of the last static or implicit Euler step did
/// ([`Simulation::solver_report`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SolverReport {
    /// `static` or `implicit_euler`.
    pub integrator: &'static str,
    /// Newton iterations over every load step (static), or conjugate-gradient iterations
    /// of the linearized solve (implicit Euler).
    pub iterations: usize,
    /// The norm of the residual force on the free vertices (static: of the whole load), or of
    /// the linear system's residual (implicit Euler).
    pub residual: f64,
    /// `residual` divided by the load (static: gravity plus external loads, or the first
    /// residual when prescribed displacements drive the solve), or by the norm of the linear
    /// system's right-hand side (implicit Euler).
    pub relative_residual: f64,
    /// The relative residual the solve must reach.
    pub tolerance: f64,
    /// Whether `relative_residual <= tolerance`, or (static) within [`STALL_TOLERANCE`] where
    /// rounding in the forces stops Newton from decreasing the residual further.
    pub converged: bool,
    /// The load increments the static solve took (1: the whole load at once; more when
    /// automatic load stepping was needed; 0 for implicit Euler).
    pub load_steps: usize,
    /// The fraction of the load at which the static solve last converged (1 when it
    /// converged).
    pub load_fraction: f64,
    /// The largest relative residual of every static or implicit Euler step so far (the
    /// failed one included).
    pub worst_relative_residual: f64,
    /// How many static steps so far needed more than one load increment.
    pub load_stepped_steps: usize,
}

/// The relative residual a static solve must reach.
pub const STATIC_TOLERANCE: f64 = 1e-10;
/// The relative residual the linear solve of an implicit Euler step must reach.
pub const IMPLICIT_TOLERANCE: f64 = 1e-8;
/// The relative residual at which a static solve whose Newton step no longer decreases the
/// residual (rounding in the forces) counts as converged.
pub const STALL_TOLERANCE: f64 = 1e-8;
/// The rounding level of the forces, in ulps of the size of their terms, at which a static
/// solve whose Newton step no longer decreases the residual counts as converged.
const ROUNDING_ULPS: f64 = 1e3;
/// The smallest load increment automatic load stepping tries, as a fraction of the load.
pub const MIN_LOAD_INCREMENT: f64 = 1.0 / 1024.0;
/// Newton iterations allowed for one load increment.
const NEWTON_ITERATIONS: usize = 30;
/// Halvings of a Newton step the line search tries before giving up on the increment.
const LINE_SEARCH_HALVINGS: usize = 10;

/// The outcome of Newton iterations for one load increment.
struct NewtonOutcome {
    converged: bool,
    iterations: usize,
    /// The final residual norm and its largest vertex.
    residual: f64,
    worst: usize,
}

/// The conjugate-gradient solution, its iterations and its relative residual.
struct CgOutcome {
    x: Vec<[f64; 3]>,
    iterations: usize,
    relative: f64,
    residual: f64,
}

fn find_model(kind: &str, dim: usize) -> Result<ModelDef, PhysicsError> {
    if let Some(def) = MODELS
        .iter()
        .find(|m| m.kind == kind && m.dims.contains(&dim))
    {
        return Ok(*def);
    }
    let Some(def) = MODELS.iter().find(|m| m.kind == kind) else {
        let mut known: Vec<&str> = MODELS.iter().map(|m| m.kind).collect();
        known.dedup();
        return Err(PhysicsError::Model(format!(
            "unknown model '{kind}' (known: {})",
            known.join(", ")
        )));
    };
    if !def.dims.contains(&dim) {
        return Err(PhysicsError::Model(format!(
            "model '{kind}' needs a mesh of dimension {:?}, this one has dimension {dim}",
            def.dims
        )));
    }
    Ok(*def)
}

/// The accumulation rules for the given force and Jacobian-vector-product embeddings, and one
/// rule per fixed predicate.
fn generated_rules(dim: usize, forces: &[&str], jvp: &[&str], cfg: &Config) -> String {
    let fixed = &cfg.fixed;
    let v = if dim == 3 { "<1,2,3>" } else { "<1,2>" };
    let mut s = format!("dimension {dim}\n");
    for (rule, target, parts) in [
        ("accumulate", "force", forces),
        ("accumulate_jvp", "df", jvp),
    ] {
        let _ = write!(
            s,
            "\nrule {rule} {{\n  left {{ v : {v} hook }}\n  compute {{ v.{target} = vec3(0, 0, 0)"
        );
        for f in parts {
            let _ = write!(s, " + sum{v}(v.{f})");
        }
        if rule == "accumulate" {
            // the external loads: constant, so nothing in the Jacobian
            s.push_str(" + v.f_ext");
        }
        s.push_str(" }\n}\n");
    }
    for (k, p) in fixed.iter().enumerate() {
        let _ = write!(
            s,
            "\nrule fix_{k} {{\n  left {{ v : {v} hook }}\n  where {{ let x = x(v.rest)  let y = y(v.rest)  let z = z(v.rest)  {p} }}\n  compute {{ v.fixed = true }}\n}}\n"
        );
    }
    for (k, (p, _)) in cfg.prescribed.iter().enumerate() {
        let _ = write!(
            s,
            "\nrule prescribe_{k}(d: vec3) {{\n  left {{ v : {v} hook }}\n  where {{ let x = x(v.rest)  let y = y(v.rest)  let z = z(v.rest)  {p} }}\n  compute {{ v.fixed = true  v.position = v.rest + d }}\n}}\n"
        );
    }
    let (side, arc, centre) = if dim == 3 {
        ("<0,1>", 3, "mean<0,1>")
    } else {
        ("<0>", 2, "mean<0>")
    };
    for (k, e) in cfg.events.iter().enumerate() {
        if let Cut::Where(p) = &e.cut {
            let _ = write!(
                s,
                "\nrule cut_where_{k} {{\n  left  {{ a : {side} hook   b : {side}   a -{arc}- b }}\n  right {{ a : {side}        b : {side} }}\n  where {{ let c = {centre}(a.position)  let x = x(c)  let y = y(c)  let z = z(c)  {p} }}\n}}\n"
            );
        }
    }
    let e = if dim == 3 { "<0,1,2>" } else { "<0,1>" };
    for (k, r) in cfg.regions.iter().enumerate() {
        let mut body = String::new();
        for (name, val) in [
            ("density", r.density),
            ("young", r.young),
            ("poisson", r.poisson),
        ] {
            if let Some(x) = val {
                let _ = write!(body, " e.{name} = {x:?}");
            }
        }
        let _ = write!(
            s,
            "\nrule region_{k} {{\n  left {{ e : {e} hook }}\n  where {{ let c = mean{e}(e.rest)  let x = x(c)  let y = y(c)  let z = z(c)  {} }}\n  compute {{{body} }}\n}}\n",
            r.predicate
        );
    }
    // the ground plane through p with unit normal n: a free vertex below it is projected onto
    // it and loses its velocity into it (the tangential velocity is kept)
    let _ = write!(
        s,
        "\nrule ground(p: vec3, n: vec3) {{\n  left {{ v : {v} hook }}\n  where !v.fixed && dot(v.position - p, n) < 0.0\n  compute {{\n    v.position = v.position - dot(v.position - p, n) * n\n    v.velocity = v.velocity - min(dot(v.velocity, n), 0.0) * n\n  }}\n}}\n"
    );
    s
}

impl Simulation {
    /// Builds a simulation on `g` (it must have a `position` embedding): loads the rules of
    /// the models, computes rest state, masses and model parameters.
    pub fn new(mut g: GMap, cfg: Config) -> Result<Self, PhysicsError> {
        let dim = g.dimension();
        if !(cfg.dt > 0.0 && cfg.dt.is_finite()) {
            return Err(PhysicsError::Config(format!(
                "dt must be positive, got {}",
                cfg.dt
            )));
        }
        if !(cfg.density > 0.0 && cfg.density.is_finite()) {
            return Err(PhysicsError::Config(format!(
                "density must be positive, got {}",
                cfg.density
            )));
        }
        if cfg.models.is_empty() {
            return Err(PhysicsError::Model("no model given".into()));
        }
        let mut defs = Vec::new();
        for m in &cfg.models {
            let def = find_model(&m.kind, dim)?;
            let mut params: HashMap<String, f64> = def
                .params
                .iter()
                .map(|(k, v)| ((*k).to_string(), *v))
                .collect();
            for (k, v) in &m.params {
                if !params.contains_key(k) {
                    let known: Vec<&str> = def.params.iter().map(|p| p.0).collect();
                    return Err(PhysicsError::Config(format!(
                        "model '{}' has no parameter '{k}' (it has: {})",
                        m.kind,
                        if known.is_empty() {
                            "none; it uses the material's young and poisson".into()
                        } else {
                            known.join(", ")
                        }
                    )));
                }
                params.insert(k.clone(), *v);
            }
            defs.push((def, params));
        }
        if matches!(
            cfg.integrator,
            Integrator::ImplicitEuler | Integrator::Static
        ) {
            if let Some((def, _)) = defs.iter().find(|(d, _)| d.jvp_rules.is_empty()) {
                return Err(PhysicsError::Model(format!(
                    "model '{}' has no Jacobian rules yet: use explicit_euler or symplectic_euler with it",
                    def.kind
                )));
            }
        }
        let mut sources = vec![
            (
                format!("common{dim}d.tmr"),
                model_source("common", dim).expect("shipped").to_string(),
            ),
            (
                format!("topology{dim}d.tmr"),
                model_source("topology", dim).expect("shipped").to_string(),
            ),
        ];
        if let Some(f) = cfg.fracture {
            if !(f.threshold.is_finite()) {
                return Err(PhysicsError::Config(format!(
                    "fracture threshold must be finite, got {}",
                    f.threshold
                )));
            }
            if f.criterion == Criterion::Stress {
                if dim != 3 {
                    return Err(PhysicsError::Config("the stress criterion of fracture needs tetrahedra (3D); surfaces tear by strain".into()));
                }
                sources.push((
                    "fem3d.tmr".into(),
                    model_source("fem", 3).expect("shipped").to_string(),
                ));
            }
        }
        for e in &cfg.events {
            if !(e.time >= 0.0 && e.time.is_finite()) {
                return Err(PhysicsError::Config(format!(
                    "event time must be a finite time >= 0, got {}",
                    e.time
                )));
            }
        }
        for (def, _) in &defs {
            let name = format!("{}{dim}d.tmr", def.file);
            if !sources.iter().any(|s| s.0 == name) {
                sources.push((
                    name,
                    model_source(def.file, dim)
                        .expect("listed in MODELS")
                        .to_string(),
                ));
            }
        }
        let forces: Vec<&str> = defs
            .iter()
            .flat_map(|(d, _)| d.forces.iter().copied())
            .collect();
        let jvp: Vec<&str> = defs
            .iter()
            .flat_map(|(d, _)| d.jvp_forces.iter().copied())
            .collect();
        sources.push((
            "scene-generated.tmr".into(),
            generated_rules(dim, &forces, &jvp, &cfg),
        ));
        let (rules, _warnings) = load_sources(&sources).map_err(|diags| {
            // a refused predicate is the scene's fault: say so
            if diags.iter().any(|d| {
                d.file == "scene-generated.tmr" && d.severity == topomech_rules::Severity::Error
            }) {
                let msgs: Vec<String> = diags
                    .iter()
                    .filter(|d| d.severity == topomech_rules::Severity::Error)
                    .map(|d| d.message.clone())
                    .collect();
                PhysicsError::Config(format!(
                    "bad fixed-vertex predicate in {:?}: {}",
                    cfg.fixed,
                    msgs.join("; ")
                ))
            } else {
                PhysicsError::Rules(diags)
            }
        })?;
        if let Some(ground) = &cfg.ground {
            ground.plane(cfg.gravity)?;
        }
        if g.embedding_id("position").is_none() {
            return Err(PhysicsError::Config(
                "the map has no 'position' embedding".into(),
            ));
        }
        // the data the simulation itself reads; each rule adds what it uses when it first runs
        rules.prepare_named(
            &mut g,
            &[
                "position", "rest", "velocity", "force", "fixed", "mass", "dx", "dv", "df",
                "vertex0", "face0", "f_ext",
            ],
        )?;
        mark_vertex0(&mut g)?;
        let none = Params::new();
        rules.apply_everywhere(&mut g, "init_rest", &none)?;
        let material: Params = [
            ("density".to_string(), Val::F(cfg.density)),
            ("young".to_string(), Val::F(cfg.young)),
            ("poisson".to_string(), Val::F(cfg.poisson)),
        ]
        .into();
        rules.apply_everywhere(&mut g, "set_material", &material)?;
        for k in 0..cfg.regions.len() {
            let rep = rules.apply_everywhere(&mut g, &format!("region_{k}"), &none)?;
            if rep.matches == 0 {
                return Err(PhysicsError::Config(format!(
                    "material region '{}' contains no element",
                    cfg.regions[k].predicate
                )));
            }
        }
        let (he, elem) = if dim == 3 {
            ("half_edge_volume", "element_volume")
        } else {
            ("half_edge_area", "element_area")
        };
        rules.apply_everywhere(&mut g, he, &none)?;
        rules.apply_everywhere(&mut g, elem, &none)?;
        rules.apply_everywhere(&mut g, "lump_mass", &none)?;
        for k in 0..cfg.fixed.len() {
            let rep = rules.apply_everywhere(&mut g, &format!("fix_{k}"), &none)?;
            if rep.matches == 0 {
                return Err(PhysicsError::Config(format!(
                    "fix predicate '{}' selects no vertex",
                    cfg.fixed[k]
                )));
            }
        }
        for (k, (p, d)) in cfg.prescribed.iter().enumerate() {
            let params: Params = [("d".to_string(), Val::V3(*d))].into();
            let rep = rules.apply_everywhere(&mut g, &format!("prescribe_{k}"), &params)?;
            if rep.matches == 0 {
                return Err(PhysicsError::Config(format!(
                    "prescribed-displacement predicate '{p}' selects no vertex"
                )));
            }
        }
        let elements = g.count_orbits(if dim == 3 {
            OrbitType::volume()
        } else {
            OrbitType::face(2)
        });
        for (def, params) in &defs {
            let mut matched = 0;
            for init in def.init {
                let rule = rules.rule(init)?;
                let p: Params = rule
                    .params
                    .iter()
                    .map(|(n, _)| (n.clone(), Val::F(params.get(n).copied().unwrap_or(0.0))))
                    .collect();
                matched += rules.apply_everywhere(&mut g, init, &p)?.matches;
            }
            if matched == 0 {
                return Err(PhysicsError::Model(format!(
                    "model '{}' matches nothing on this mesh: it needs {}",
                    def.kind, def.needs
                )));
            }
            if def.per_element && matched < elements {
                return Err(PhysicsError::Model(format!(
                    "model '{}' handles {} elements of {elements}: it needs {}, and the others would get no force",
                    def.kind, matched, def.needs
                )));
            }
        }
        // the derived data of what the models stored (cumulated springs, tensors) exists from
        // the start, so that it is kept up to date through topology changes
        let embs = rules.embeddings();
        let derived: Vec<&str> = embs
            .iter()
            .filter(|e| {
                e.derived
                    .is_some_and(|(_, src)| g.embedding_id(&embs[src].name).is_some())
            })
            .map(|e| e.name.as_str())
            .collect();
        rules.prepare_named(&mut g, &derived)?;
        rules.clear_plans();
        g.refresh_derived();
        let step_params: Params = [
            ("dt".to_string(), Val::F(cfg.dt)),
            ("gravity".to_string(), Val::V3(cfg.gravity)),
            ("damping".to_string(), Val::F(cfg.damping)),
        ]
        .into();
        let rows = Rows::init(&mut g)?;
        let vertex_darts_version = g.version();
        let size = {
            let pos = g
                .require("rest")
                .map_err(|e| PhysicsError::Config(e.to_string()))?;
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for d in g.darts() {
                let p = g.real(pos, d);
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
            norm3([hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]]).max(f64::MIN_POSITIVE)
        };
        let cfg_events = cfg.events.len();
        let mut sim = Simulation {
            g,
            rules,
            cfg,
            defs,
            step_params,
            time: 0.0,
            steps: 0,
            rows,
            vertex_darts_version,
            size,
            events_done: vec![false; cfg_events],
            changes: Vec::new(),
            saved: [Vec::new(), Vec::new()],
            report: None,
            static_base: Vec::new(),
        };
        // a welded row is one particle: held when any of its orbits is
        if !sim.rows.welded.is_empty() {
            let fixed = sim.row_any("fixed")?;
            sim.set_vertex_bool("fixed", &fixed)?;
        }
        // every free vertex needs a mass
        let masses = sim.vertex_scalar_sum("mass")?;
        let fixed = sim.vertex_bool("fixed")?;
        if let Some(v) = (0..masses.len()).find(|&v| {
            !fixed[v] && masses[v].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        }) {
            return Err(PhysicsError::Config(format!(
                "vertex {v} has mass {} and is not fixed",
                masses[v]
            )));
        }
        Ok(sim)
    }

    /// One time step: forces, accumulation, integration. On divergence (a non-finite
    /// position or velocity) the state before the step is restored and an error names the
    /// step and the vertex.
    pub fn step(&mut self) -> Result<(), PhysicsError> {
        let pos = self.id("position")?;
        let vel = self.id("velocity")?;
        // the state before the step: the whole position and velocity columns (kept to restore
        // them on divergence; a step changes values only, never the slots)
        for (id, saved) in [pos, vel].into_iter().zip(&mut self.saved) {
            let column =
                self.g.embedding(id).real_column().ok_or_else(|| {
                    PhysicsError::Config("position and velocity must be vec3".into())
                })?;
            saved.clear();
            saved.extend_from_slice(column);
        }
        let result = match self.cfg.integrator {
            Integrator::ExplicitEuler => self.explicit("explicit_euler"),
            Integrator::SymplecticEuler => self.explicit("symplectic_euler"),
            Integrator::ImplicitEuler => self.implicit_euler(),
            Integrator::Static => self.solve_static(),
        };
        let bad = match &result {
            // a rule computed a non-finite value (and wrote nothing): name its vertex
            Err(PhysicsError::Apply(ApplyError::NonFinite {
                rule,
                embedding,
                dart,
                value,
            })) => Some((
                self.vertex_of(*dart, pos),
                format!("rule '{rule}' computed a non-finite value {value} for '{embedding}' (dart {dart})"),
            )),
            Err(e) => Some((0, e.to_string())),
            // every slot scanned in order first (dead slots included: they hold old, finite
            // values), the vertices searched one by one only to name the one that fails
            Ok(()) if self.columns_sane(pos, vel) => None,
            Ok(()) => self.rows.darts.iter().enumerate().find_map(|(v, d)| {
                let (p, u) = (self.g.real(pos, *d), self.g.real(vel, *d));
                if p.iter().chain(u).any(|x| !x.is_finite()) {
                    return Some((v, "non-finite position or velocity".to_string()));
                }
                // runaway: a vertex crossing more than the whole object in one step
                let step = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt() * self.cfg.dt;
                (step > self.size).then(|| {
                    (v, format!("runaway motion: the vertex moved {step:.3e} in one step, more than the object's size {:.3e}", self.size))
                })
            }),
        };
        if let Some((vertex, why)) = bad {
            for (id, saved) in [pos, vel].into_iter().zip(&self.saved) {
                if let Ok(ColumnMut::Real(v)) = self.g.column_mut(id) {
                    if v.len() == saved.len() {
                        v.copy_from_slice(saved);
                    }
                }
            }
            return Err(match result {
                // the step's own finding, or a rule's non-finite value (its why says which)
                Ok(()) | Err(PhysicsError::Apply(ApplyError::NonFinite { .. })) => {
                    PhysicsError::Diverged {
                        step: self.steps + 1,
                        vertex,
                        why,
                    }
                }
                Err(PhysicsError::Apply(e)) => PhysicsError::Diverged {
                    step: self.steps + 1,
                    vertex,
                    why: e.to_string(),
                },
                Err(e) => e,
            });
        }
        self.steps += 1;
        self.time += self.cfg.dt;
        self.topology_events()
    }

    /// The row of the vertex whose orbit holds `dart`, by the slot of the vertex
    /// embedding `pos`; 0 if none does.
    fn vertex_of(&self, dart: Dart, pos: EmbeddingId) -> usize {
        let e = self.g.embedding(pos);
        if !self.g.is_alive(dart) {
            return 0;
        }
        let slot = e.slot(dart);
        self.rows
            .orbits
            .iter()
            .zip(&self.rows.row_of)
            .find(|(d, _)| e.slot(**d) == slot)
            .map_or(0, |(_, &r)| r)
    }

    /// Whether every value of the position and velocity columns is finite and no velocity
    /// moves a vertex further than the object's size in one step: the test of
    /// [`Simulation::step`] over whole columns, in order.
    fn columns_sane(&self, pos: EmbeddingId, vel: EmbeddingId) -> bool {
        let (Some(p), Some(v)) = (
            self.g.embedding(pos).real_column(),
            self.g.embedding(vel).real_column(),
        ) else {
            return false;
        };
        p.iter().all(|x| x.is_finite())
            && v.chunks_exact(3).all(|u| {
                // the same expression as the vertex test, so that both agree at the limit
                let step = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt() * self.cfg.dt;
                step.is_finite() && step <= self.size
            })
    }

    /// Applies the events whose time has come and the fracture criterion.
    fn topology_events(&mut self) -> Result<(), PhysicsError> {
        for k in 0..self.cfg.events.len() {
            if !self.events_done[k] && self.cfg.events[k].time <= self.time + 1e-9 * self.cfg.dt {
                self.events_done[k] = true;
                let cut = self.cfg.events[k].cut.clone();
                let n = self.apply_cut(&cut, Some(k))?.unsewn;
                if n == 0 {
                    return Err(PhysicsError::Config(format!(
                        "the cut {cut:?} at t = {} separates nothing: it misses the object",
                        self.cfg.events[k].time
                    )));
                }
            }
        }
        if let Some(f) = self.cfg.fracture {
            self.fracture(f)?;
        }
        Ok(())
    }

    /// Opens now every face (3D) or edge (2D) where the criterion passes the threshold; returns
    /// how many, and the rows appended for the vertices that split (existing rows keep their
    /// meaning).
    pub fn fracture(&mut self, f: Fracture) -> Result<TopologyResult, PhysicsError> {
        let none = Params::new();
        let measure = match f.criterion {
            Criterion::Stress => "element_stress",
            Criterion::Strain => "spring_strains",
        };
        if self.rules.rule(measure).is_err() {
            return Err(PhysicsError::Config(
                "the stress criterion needs the fracture configured when the simulation is built"
                    .into(),
            ));
        }
        self.rules.apply_everywhere(&mut self.g, measure, &none)?;
        let p: Params = [("threshold".to_string(), Val::F(f.threshold))].into();
        let rule = if f.criterion == Criterion::Stress {
            "fracture_stress"
        } else {
            "fracture_strain"
        };
        let n = self.rules.apply_everywhere(&mut self.g, rule, &p)?.matches;
        let mut added_rows = Vec::new();
        if n > 0 {
            self.changes.push(TopologyChange {
                step: self.steps,
                time: self.time,
                kind: "fracture",
                unsewn: n,
            });
            added_rows = self.after_topology_change()?;
        }
        Ok(TopologyResult {
            unsewn: n,
            added_rows,
        })
    }

    /// Cuts now; returns the number of faces (3D) or edges (2D) unsewn and the rows appended
    /// for the vertices that split (existing rows keep their meaning).
    pub fn cut(&mut self, cut: &Cut) -> Result<TopologyResult, PhysicsError> {
        if let Cut::Where(_) = cut {
            return Err(PhysicsError::Config(
                "a predicate cut must be declared in the configuration's events".into(),
            ));
        }
        self.apply_cut(cut, None)
    }

    fn apply_cut(
        &mut self,
        cut: &Cut,
        event: Option<usize>,
    ) -> Result<TopologyResult, PhysicsError> {
        let n = match cut {
            Cut::Plane { normal, offset } => {
                let p: Params = [
                    ("normal".to_string(), Val::V3(*normal)),
                    ("offset".to_string(), Val::F(*offset)),
                ]
                .into();
                self.rules
                    .apply_everywhere(&mut self.g, "cut_plane", &p)?
                    .matches
            }
            Cut::Where(_) => {
                let k = event.expect("predicate cuts are events");
                self.rules
                    .apply_everywhere(&mut self.g, &format!("cut_where_{k}"), &Params::new())?
                    .matches
            }
        };
        let mut added_rows = Vec::new();
        if n > 0 {
            self.changes.push(TopologyChange {
                step: self.steps,
                time: self.time,
                kind: "cut",
                unsewn: n,
            });
            added_rows = self.after_topology_change()?;
        }
        Ok(TopologyResult {
            unsewn: n,
            added_rows,
        })
    }

    /// After a change: derived embeddings refreshed, and the new vertex orbits numbered
    /// (appended rows); returns the rows added.
    fn after_topology_change(&mut self) -> Result<Vec<usize>, PhysicsError> {
        self.g.refresh_derived();
        self.sync_rows()
    }

    /// Refuses events that a run ending at `end_time` would never reach.
    pub fn check_events(&self, end_time: f64) -> Result<(), PhysicsError> {
        for e in &self.cfg.events {
            if e.time > end_time + 1e-9 * self.cfg.dt {
                return Err(PhysicsError::Config(format!(
                    "the event at t = {} comes after the end of the run (t = {end_time}): it would never happen",
                    e.time
                )));
            }
        }
        Ok(())
    }

    /// The topology changes so far.
    pub fn topology_changes(&self) -> &[TopologyChange] {
        &self.changes
    }

    fn explicit(&mut self, rule: &str) -> Result<(), PhysicsError> {
        self.forces()?;
        self.share_welded_forces()?;
        self.rules
            .apply_everywhere(&mut self.g, rule, &self.step_params)?;
        self.contact()
    }

    /// The ground plane, if any.
    fn contact(&mut self) -> Result<(), PhysicsError> {
        if let Some(ground) = &self.cfg.ground {
            let (point, normal) = ground.plane(self.cfg.gravity)?;
            let p: Params = [
                ("p".to_string(), Val::V3(point)),
                ("n".to_string(), Val::V3(normal)),
            ]
            .into();
            self.rules.apply_everywhere(&mut self.g, "ground", &p)?;
        }
        Ok(())
    }

    /// Gives every orbit of a welded row the share of the row's total force in proportion to
    /// its mass, so that each orbit's acceleration `force / mass` (and with it gravity and
    /// viscous damping, which act per unit mass on the shared velocity) is the row's
    /// `F_total / M_total`: the orbits move as one particle. Nothing to do (no allocation, no
    /// orbit walk) for maps without welded rows.
    fn share_welded_forces(&mut self) -> Result<(), PhysicsError> {
        if self.rows.welded.is_empty() {
            return Ok(());
        }
        let force = self.id("force")?;
        let mass = self.id("mass")?;
        let err = |e: topomech_gmap::EmbeddingError| PhysicsError::Config(e.to_string());
        for (_, darts) in &self.rows.welded {
            let mut f = [0.0; 3];
            let mut m = 0.0;
            for &d in darts {
                let x = self.g.real(force, d);
                for a in 0..3 {
                    f[a] += x[a];
                }
                m += self.g.real(mass, d)[0];
            }
            if m.is_nan() || m <= 0.0 {
                continue;
            }
            for &d in darts {
                let share = self.g.real(mass, d)[0] / m;
                self.g
                    .set_real(force, d, &[f[0] * share, f[1] * share, f[2] * share])
                    .map_err(err)?;
            }
        }
        Ok(())
    }

    /// `(df/dx) dx + (df/dv) dv` for vertex vectors in row order (a welded row's result is the
    /// sum over its orbits).
    pub fn jvp(&mut self, dx: &[[f64; 3]], dv: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, PhysicsError> {
        self.set_vertex_vec3("dx", dx)?;
        self.set_vertex_vec3("dv", dv)?;
        let none = Params::new();
        for (def, _) in &self.defs {
            for r in def.jvp_rules {
                self.rules.apply_everywhere(&mut self.g, r, &none)?;
            }
        }
        self.rules
            .apply_everywhere(&mut self.g, "accumulate_jvp", &none)?;
        self.vertex_vec3_sum("df")
    }

    /// The total force on each vertex: the models' forces, gravity and viscous damping.
    fn total_force(&mut self) -> Result<VertexForces, PhysicsError> {
        self.forces()?;
        let f = self.vertex_vec3_sum("force")?;
        let m = self.vertex_scalar_sum("mass")?;
        let v = self.vertex_vec3("velocity")?;
        let fixed = self.vertex_bool("fixed")?;
        let g = self.cfg.gravity;
        let c = self.cfg.damping;
        let total = f
            .iter()
            .zip(&m)
            .zip(&v)
            .map(|((f, m), v)| {
                [
                    f[0] + m * (g[0] - c * v[0]),
                    f[1] + m * (g[1] - c * v[1]),
                    f[2] + m * (g[2] - c * v[2]),
                ]
            })
            .collect();
        Ok((total, m, fixed))
    }

    fn implicit_euler(&mut self) -> Result<(), PhysicsError> {
        let h = self.cfg.dt;
        let c = self.cfg.damping;
        let (f, m, fixed) = self.total_force()?;
        let v = self.vertex_vec3("velocity")?;
        let zero = vec![[0.0; 3]; v.len()];
        let kv = self.jvp(&v, &zero)?;
        let mut rhs: Vec<[f64; 3]> = f
            .iter()
            .zip(&kv)
            .map(|(f, k)| std::array::from_fn(|a| h * (f[a] + h * k[a])))
            .collect();
        project(&mut rhs, &fixed);
        // A z = (1 + h c) M z - h^2 (df/dx) z - h (df/dv) z
        let solve = self.cg(&rhs, &fixed, |sim, z| {
            let dx: Vec<[f64; 3]> = z.iter().map(|z| z.map(|x| h * h * x)).collect();
            let dv: Vec<[f64; 3]> = z.iter().map(|z| z.map(|x| h * x)).collect();
            let df = sim.jvp(&dx, &dv)?;
            Ok(z.iter()
                .zip(&df)
                .zip(&m)
                .map(|((z, d), m)| std::array::from_fn(|a| (1.0 + h * c) * m * z[a] - d[a]))
                .collect())
        })?;
        let converged = solve.relative <= IMPLICIT_TOLERANCE;
        self.record(SolverReport {
            integrator: "implicit_euler",
            iterations: solve.iterations,
            residual: solve.residual,
            relative_residual: solve.relative,
            tolerance: IMPLICIT_TOLERANCE,
            converged,
            load_steps: 0,
            load_fraction: 1.0,
            worst_relative_residual: 0.0,
            load_stepped_steps: 0,
        });
        if !converged {
            return Err(PhysicsError::Diverged {
                step: self.steps + 1,
                vertex: 0,
                why: format!(
                    "the linear solve of the implicit Euler step did not converge: relative residual {:.3e} above the tolerance {IMPLICIT_TOLERANCE:e} after {} conjugate-gradient iterations; try a smaller dt or a finer mesh (the solve is global: the vertex named is the first)",
                    solve.relative, solve.iterations
                ),
            });
        }
        let dvel = solve.x;
        let x = self.vertex_vec3("position")?;
        let newv: Vec<[f64; 3]> = v
            .iter()
            .zip(&dvel)
            .map(|(v, d)| std::array::from_fn(|a| v[a] + d[a]))
            .collect();
        let newx: Vec<[f64; 3]> = x
            .iter()
            .zip(&newv)
            .map(|(x, v)| std::array::from_fn(|a| x[a] + h * v[a]))
            .collect();
        self.set_vertex_vec3("velocity", &newv)?;
        self.set_vertex_vec3("position", &newx)?;
        self.contact()
    }

    /// Newton iterations on f(x) + `f_ext` + m g = 0 with conjugate gradients on -df/dx and a
    /// backtracking line search on the residual norm; the velocity is set to zero. Converged
    /// when the residual on the free vertices is at most [`STATIC_TOLERANCE`] of the load
    /// (gravity and external loads, or the first residual when prescribed displacements drive
    /// it). When the whole load does not converge in 30 iterations, the load (gravity,
    /// `f_ext` and prescribed displacements) is applied in increments from the last converged
    /// fraction, halving the increment on failure down to [`MIN_LOAD_INCREMENT`].
    /// [`Simulation::solver_report`] then says what happened.
    /// Errors: [`PhysicsError::Diverged`] (the positions before the solve restored) when no
    /// increment converges, with the relative residual, the tolerance and what to try; a
    /// rule's failure other than a non-finite value.
    pub fn solve_static(&mut self) -> Result<(), PhysicsError> {
        let n = self.rows.darts.len();
        self.set_vertex_vec3("velocity", &vec![[0.0; 3]; n])?;
        let x0 = self.vertex_vec3("position")?;
        let fixed = self.vertex_bool("fixed")?;
        let load: f64 = {
            let m = self.vertex_scalar_sum("mass")?;
            let external: f64 = self.vertex_vec3_sum("f_ext")?.into_iter().map(norm3).sum();
            m.iter().sum::<f64>() * norm3(self.cfg.gravity) + external
        };
        // the positions of the fixed vertices ramp from where the last solve held them (the
        // rest positions before the first) to where they are now
        let base = if self.static_base.len() == n {
            self.static_base.clone()
        } else {
            self.vertex_vec3("rest")?
        };
        let at = |t: f64, free: &[[f64; 3]]| -> Vec<[f64; 3]> {
            free.iter()
                .zip(&x0)
                .zip(&base)
                .zip(&fixed)
                .map(|(((x, target), b), &held)| {
                    if held {
                        std::array::from_fn(|a| b[a] + t * (target[a] - b[a]))
                    } else {
                        *x
                    }
                })
                .collect()
        };
        // the residual of the start (fixed vertices at their base): the part of the load the
        // current state does not balance yet. At fraction t the residual solved for is
        // R(x) - (1 - t) R0, which is R(x) at t = 1 (from rest: the load scaled by t).
        let start = at(0.0, &x0);
        self.set_vertex_vec3("position", &start)?;
        let r0 = self.static_residual(&fixed, None, 1.0)?;
        self.set_vertex_vec3("position", &x0)?;
        let first = self.static_residual(&fixed, None, 1.0)?;
        let norm = rows_norm;
        let scale = load.max(norm(&first)).max(norm(&r0)).max(f64::MIN_POSITIVE);
        if !scale.is_finite() {
            return Err(PhysicsError::Diverged {
                step: self.steps + 1,
                vertex: 0,
                why: format!(
                    "the static solve's load overflows: its size is {scale:e} (gravity times mass plus the external loads), beyond what f64 arithmetic can balance; scale the problem (units) or the load down"
                ),
            });
        }
        let tol = STATIC_TOLERANCE * scale;
        // the rounding level of the forces: the stiffness applied to the positions is the
        // size of the forces' terms (at unit strain), each computed to a few ulps
        let zero = vec![[0.0; 3]; n];
        let mut kx = self.jvp(&x0, &zero)?;
        project(&mut kx, &fixed);
        let rounding = ROUNDING_ULPS * f64::EPSILON * norm(&kx);
        let stall = (STALL_TOLERANCE * scale).max(rounding);
        let mut iterations = 0;
        let mut load_steps = 0;
        let (mut s, mut ds) = (0.0f64, 1.0f64);
        let mut good = start;
        // the closest the whole load came to balance (the first attempt is the whole load)
        let (mut best, mut worst) = (f64::INFINITY, 0);
        loop {
            let t = (s + ds).min(1.0);
            let trial = at(t, &good);
            self.set_vertex_vec3("position", &trial)?;
            let out = self.newton(&fixed, &r0, t, (tol, stall))?;
            iterations += out.iterations;
            if t >= 1.0 && out.residual < best {
                best = out.residual;
                worst = out.worst;
            }
            if out.converged {
                load_steps += 1;
                s = t;
                good = self.vertex_vec3("position")?;
                if s >= 1.0 {
                    break;
                }
                ds = (2.0 * ds).min(1.0 - s);
            } else {
                ds *= 0.5;
                if ds < MIN_LOAD_INCREMENT {
                    self.set_vertex_vec3("position", &x0)?;
                    let rel = best / scale;
                    self.record(SolverReport {
                        integrator: "static",
                        iterations,
                        residual: best,
                        relative_residual: rel,
                        tolerance: STATIC_TOLERANCE,
                        converged: false,
                        load_steps,
                        load_fraction: s,
                        worst_relative_residual: 0.0,
                        load_stepped_steps: 0,
                    });
                    return Err(PhysicsError::Diverged {
                        step: self.steps + 1,
                        vertex: worst,
                        why: format!(
                            "the static solve did not converge: relative residual {rel:.3e} above the tolerance {STATIC_TOLERANCE:e} after {iterations} Newton iterations with a line search and load stepping down to increments of 1/{} of the load ({:.1}% of the load reached); try a smaller load, a finer mesh, or the integrator implicit_euler to find a dynamic path; the largest residual force is",
                            (1.0 / MIN_LOAD_INCREMENT).round(),
                            100.0 * s
                        ),
                    });
                }
            }
        }
        let res = norm(&self.static_residual(&fixed, None, 1.0)?);
        self.set_vertex_vec3("position", &good)?;
        self.static_base = good;
        self.record(SolverReport {
            integrator: "static",
            iterations,
            residual: res,
            relative_residual: res / scale,
            tolerance: STATIC_TOLERANCE,
            converged: true,
            load_steps,
            load_fraction: 1.0,
            worst_relative_residual: 0.0,
            load_stepped_steps: 0,
        });
        Ok(())
    }

    /// Keeps `r` as the last step's report, with the run's worst relative residual and count
    /// of load-stepped steps carried over from the previous one.
    fn record(&mut self, mut r: SolverReport) {
        let (worst, stepped) = self.report.as_ref().map_or((0.0, 0), |p| {
            (p.worst_relative_residual, p.load_stepped_steps)
        });
        r.worst_relative_residual = worst.max(r.relative_residual);
        r.load_stepped_steps =
            stepped + usize::from(r.integrator == "static" && (r.load_steps > 1 || !r.converged));
        self.report = Some(r);
    }

    /// What the solve of the last static or implicit Euler step did (None before the first
    /// such step, and for the other integrators).
    pub fn solver_report(&self) -> Option<&SolverReport> {
        self.report.as_ref()
    }

    /// The static residual at the current positions, fixed vertices' components zero:
    /// R(x) - (1 - t) R0 (R0 given), or R(x).
    fn static_residual(
        &mut self,
        fixed: &[bool],
        r0: Option<&[[f64; 3]]>,
        t: f64,
    ) -> Result<Vec<[f64; 3]>, PhysicsError> {
        let (mut r, _, _) = self.total_force()?;
        if let Some(r0) = r0 {
            for (r, r0) in r.iter_mut().zip(r0) {
                for a in 0..3 {
                    r[a] -= (1.0 - t) * r0[a];
                }
            }
        }
        project(&mut r, fixed);
        Ok(r)
    }

    /// Newton iterations with a backtracking line search on the residual norm for the load
    /// fraction `t`, from the current positions. A non-finite force, an indefinite stiffness
    /// or a line search that finds no decrease ends them unconverged (positions left as
    /// they are: the caller restores them).
    fn newton(
        &mut self,
        fixed: &[bool],
        r0: &[[f64; 3]],
        t: f64,
        (tol, stall): (f64, f64),
    ) -> Result<NewtonOutcome, PhysicsError> {
        let norm = rows_norm;
        let worst_of = |r: &[[f64; 3]]| {
            r.iter()
                .map(|x| norm3(*x))
                .enumerate()
                .fold(
                    (0, -1.0),
                    |acc, (i, v)| if v > acc.1 { (i, v) } else { acc },
                )
                .0
        };
        let attempt = |e: PhysicsError| match e {
            PhysicsError::Apply(ApplyError::NonFinite { .. }) | PhysicsError::Diverged { .. } => {
                Ok(())
            }
            e => Err(e),
        };
        let mut r = match self.static_residual(fixed, Some(r0), t) {
            Ok(r) => r,
            Err(e) => {
                attempt(e)?;
                return Ok(NewtonOutcome {
                    converged: false,
                    iterations: 0,
                    residual: f64::INFINITY,
                    worst: 0,
                });
            }
        };
        let mut res = norm(&r);
        let zero = vec![[0.0; 3]; r.len()];
        let mut iterations = 0;
        let done = |converged, iterations, res: f64, r: &[[f64; 3]]| NewtonOutcome {
            converged,
            iterations,
            residual: if res.is_finite() { res } else { f64::INFINITY },
            worst: worst_of(r),
        };
        while iterations < NEWTON_ITERATIONS {
            if res <= tol {
                return Ok(done(true, iterations, res, &r));
            }
            if !res.is_finite() {
                break;
            }
            iterations += 1;
            let du = match self.cg(&r, fixed, |sim, z| {
                Ok(sim.jvp(z, &zero)?.iter().map(|d| d.map(|x| -x)).collect())
            }) {
                Ok(c) => c.x,
                Err(e) => {
                    attempt(e)?;
                    return Ok(done(false, iterations, res, &r));
                }
            };
            let x = self.vertex_vec3("position")?;
            let mut alpha = 1.0;
            let mut accepted = None;
            for _ in 0..=LINE_SEARCH_HALVINGS {
                let trial: Vec<[f64; 3]> = x
                    .iter()
                    .zip(&du)
                    .map(|(x, d)| std::array::from_fn(|a| x[a] + alpha * d[a]))
                    .collect();
                self.set_vertex_vec3("position", &trial)?;
                match self.static_residual(fixed, Some(r0), t) {
                    Ok(rt) => {
                        let nt = norm(&rt);
                        // sufficient decrease (Armijo on the residual norm)
                        if nt.is_finite() && nt <= (1.0 - 1e-4 * alpha) * res {
                            accepted = Some((rt, nt));
                            break;
                        }
                    }
                    Err(e) => attempt(e)?,
                }
                alpha *= 0.5;
            }
            let Some((rt, nt)) = accepted else {
                self.set_vertex_vec3("position", &x)?;
                // the residual may stall at the rounding level of the forces just above the
                // tolerance (small loads on stiff models): close enough when within
                // STALL_TOLERANCE
                return Ok(done(res <= stall, iterations, res, &r));
            };
            r = rt;
            res = nt;
        }
        Ok(done(res <= tol, iterations, res, &r))
    }

    /// Conjugate gradients on `apply`, with fixed vertices' components held at zero; relative
    /// residual 1e-12, at most 10 n iterations; returns the solution, the iterations and the
    /// relative residual reached.
    fn cg(
        &mut self,
        b: &[[f64; 3]],
        fixed: &[bool],
        mut apply: impl FnMut(&mut Self, &[[f64; 3]]) -> Result<Vec<[f64; 3]>, PhysicsError>,
    ) -> Result<CgOutcome, PhysicsError> {
        let n = b.len();
        let dot = |a: &[[f64; 3]], b: &[[f64; 3]]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| x[0] * y[0] + x[1] * y[1] + x[2] * y[2])
                .sum::<f64>()
        };
        let mut x = vec![[0.0; 3]; n];
        let mut r = b.to_vec();
        let mut p = r.clone();
        let mut rr = dot(&r, &r);
        let rr0 = rr;
        let tol = 1e-24 * rr;
        let mut iterations = 0;
        for _ in 0..(10 * 3 * n).max(50) {
            if rr <= tol || rr == 0.0 {
                break;
            }
            iterations += 1;
            let mut ap = apply(self, &p)?;
            project(&mut ap, fixed);
            let pap = dot(&p, &ap);
            if pap <= 0.0 || !pap.is_finite() {
                return Err(PhysicsError::Diverged {
                    step: self.steps + 1,
                    vertex: 0,
                    why: format!("the linear system is not positive definite (p^T A p = {pap:e})"),
                });
            }
            let alpha = rr / pap;
            for i in 0..n {
                for a in 0..3 {
                    x[i][a] += alpha * p[i][a];
                    r[i][a] -= alpha * ap[i][a];
                }
            }
            let rr_new = dot(&r, &r);
            let beta = rr_new / rr;
            rr = rr_new;
            for i in 0..n {
                for a in 0..3 {
                    p[i][a] = r[i][a] + beta * p[i][a];
                }
            }
        }
        Ok(CgOutcome {
            x,
            iterations,
            relative: if rr0 > 0.0 { (rr / rr0).sqrt() } else { 0.0 },
            residual: rr.sqrt(),
        })
    }

    /// Computes every model's forces and their sum `force` on each vertex.
    pub fn forces(&mut self) -> Result<(), PhysicsError> {
        // force embeddings (named f_*) are rewritten every step; a pattern that no longer
        // matches after a topology change must not leave a stale force behind
        for k in 0..self.g.embeddings().len() {
            let e = &self.g.embeddings()[k];
            // (but not the external loads, which the user sets once)
            if e.name().starts_with("f_") && e.name() != "f_ext" && e.derived().is_none() {
                let id = topomech_gmap::EmbeddingId(k as u32);
                self.g
                    .reset_values(id)
                    .map_err(|e| PhysicsError::Config(e.to_string()))?;
            }
        }
        let none = Params::new();
        for (def, _) in &self.defs {
            for r in def.rules {
                self.rules.apply_everywhere(&mut self.g, r, &none)?;
            }
        }
        self.rules
            .apply_everywhere(&mut self.g, "accumulate", &none)?;
        Ok(())
    }

    /// Whether the computation rules run through compiled plans (the default) or through the
    /// interpreter only: both give the same results; the switch exists to compare them.
    pub fn set_compiled(&mut self, on: bool) {
        self.rules.set_compiled(on);
    }

    /// The map with all its embeddings.
    pub fn gmap(&self) -> &GMap {
        &self.g
    }

    /// The rules in use.
    pub fn rules(&self) -> &RuleSet {
        &self.rules
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Simulated time.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Steps done.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Brings the numbering in step with the map after a topology change: an orbit that holds
    /// a dart that represented an orbit before keeps that orbit's row; every other (new)
    /// vertex orbit gets a new row, appended in increasing order of its smallest dart, with
    /// its `particle` set to it (its `point_id`, copied by the split, stays the point it was
    /// split from). Returns the rows added.
    fn sync_rows(&mut self) -> Result<Vec<usize>, PhysicsError> {
        if self.vertex_darts_version == self.g.version() {
            return Ok(Vec::new());
        }
        let added = self.rows.renumber(&mut self.g)?;
        self.vertex_darts_version = self.g.version();
        Ok(added)
    }

    /// One dart per row (vertex), in row order: the smallest dart of the row's first vertex
    /// orbit. Rows follow the map's `particle` embedding (the input point order for a map
    /// built from a mesh); a welded row (several vertex orbits sharing one `particle`: a
    /// pinched input vertex kept as one particle) is represented by its first orbit.
    pub fn vertex_darts(&self) -> Vec<Dart> {
        self.rows.darts.clone()
    }

    /// The number of rows (particles, V).
    pub fn n_vertices(&self) -> usize {
        self.rows.darts.len()
    }

    /// Every vertex orbit (its smallest dart, in increasing order) with its row.
    pub fn vertex_orbits(&self) -> (&[Dart], &[usize]) {
        (&self.rows.orbits, &self.rows.row_of)
    }

    /// The rows made of several vertex orbits, each with the smallest dart of every orbit.
    pub fn welded_rows(&self) -> &[(usize, Vec<Dart>)] {
        &self.rows.welded
    }

    /// The input point index (`point_id`) of each row, in row order.
    pub fn point_ids(&self) -> Result<Vec<i64>, PhysicsError> {
        let id = self.id("point_id")?;
        self.rows
            .darts
            .iter()
            .map(|&d| match self.g.value(id, d) {
                Ok(Value::Int(x)) => Ok(x),
                Ok(v) => Err(PhysicsError::Config(format!(
                    "'point_id' is not an i64: {v:?}"
                ))),
                Err(e) => Err(PhysicsError::Config(e.to_string())),
            })
            .collect()
    }

    /// Every element (volume in 3D, face in 2D), in increasing order of its smallest dart:
    /// its `cell_id` (the index of the input cell, -1 when the map has no `cell_id`), its
    /// kind and its vertex rows in the order of [`topomech_gmap::mesh::extract`] (VTK order
    /// for volumes, oriented so that the rest volume is positive; the face's cycle in 2D).
    pub fn elements(&self) -> Result<Vec<Element>, PhysicsError> {
        let err = |e: topomech_gmap::mesh::MeshError| PhysicsError::Config(e.to_string());
        let mesh = topomech_gmap::mesh::extract(&self.g).map_err(err)?;
        let dim = self.g.dimension();
        let elem = if dim == 3 {
            OrbitType::volume()
        } else {
            OrbitType::face(2)
        };
        let reps = self.g.orbit_representatives(elem);
        let cell_id = self.g.embedding_id("cell_id").filter(|&id| {
            let e = self.g.embedding(id);
            e.orbit() == elem && e.ty() == EmbeddingType::I64
        });
        let rest = self.rest_points()?;
        let mut out = Vec::with_capacity(reps.len());
        for ((d, kind), verts) in reps.iter().zip(&mesh.kinds).zip(&mesh.cells) {
            // extract numbers points by the map's `particle` rows, which the simulation keeps
            // equal to its rows (it writes `particle` when it numbers new vertex orbits)
            let mut verts = verts.clone();
            if dim == 3 && topomech_gmap::mesh::signed_volume(*kind, &verts, &rest) < 0.0 {
                verts = topomech_gmap::mesh::reversed(*kind, &verts);
            }
            let cell = match cell_id {
                Some(id) => match self.g.value(id, *d) {
                    Ok(Value::Int(x)) => x,
                    _ => -1,
                },
                None => -1,
            };
            out.push(Element {
                cell_id: cell,
                kind: *kind,
                rows: verts,
            });
        }
        Ok(out)
    }

    /// The rest position of each row.
    fn rest_points(&self) -> Result<Vec<[f64; 3]>, PhysicsError> {
        self.vertex_vec3("rest")
    }

    fn id(&self, name: &str) -> Result<EmbeddingId, PhysicsError> {
        self.g
            .require(name)
            .map_err(|e| PhysicsError::Config(e.to_string()))
    }

    /// A vec3 vertex embedding (`position`, `velocity`, `rest`) in row order: the value of the
    /// row's first orbit (the orbits of a welded row share positions and velocities).
    pub fn vertex_vec3(&self, name: &str) -> Result<Vec<[f64; 3]>, PhysicsError> {
        let id = self.id(name)?;
        Ok(self
            .rows
            .darts
            .iter()
            .map(|&d| {
                let x = self.g.real(id, d);
                [x[0], x[1], x[2]]
            })
            .collect())
    }

    /// A vec3 vertex embedding summed over the orbits of each row (`force`, `df`), in row
    /// order; the same as [`Simulation::vertex_vec3`] for rows of one orbit.
    pub fn vertex_vec3_sum(&self, name: &str) -> Result<Vec<[f64; 3]>, PhysicsError> {
        let mut out = self.vertex_vec3(name)?;
        if !self.rows.welded.is_empty() {
            let id = self.id(name)?;
            for (row, darts) in &self.rows.welded {
                let mut f = [0.0; 3];
                for &d in darts {
                    let x = self.g.real(id, d);
                    for a in 0..3 {
                        f[a] += x[a];
                    }
                }
                out[*row] = f;
            }
        }
        Ok(out)
    }

    /// A f64 vertex embedding in row order (the value of the row's first orbit).
    pub fn vertex_scalar(&self, name: &str) -> Result<Vec<f64>, PhysicsError> {
        let id = self.id(name)?;
        self.rows
            .darts
            .iter()
            .map(|&d| match self.g.value(id, d) {
                Ok(Value::Real(x)) => Ok(x[0]),
                Ok(v) => Err(PhysicsError::Config(format!(
                    "'{name}' is not a real: {v:?}"
                ))),
                Err(e) => Err(PhysicsError::Config(e.to_string())),
            })
            .collect()
    }

    /// A f64 vertex embedding summed over the orbits of each row (`mass`), in row order.
    pub fn vertex_scalar_sum(&self, name: &str) -> Result<Vec<f64>, PhysicsError> {
        let mut out = self.vertex_scalar(name)?;
        if !self.rows.welded.is_empty() {
            let id = self.id(name)?;
            for (row, darts) in &self.rows.welded {
                out[*row] = darts.iter().map(|&d| self.g.real(id, d)[0]).sum();
            }
        }
        Ok(out)
    }

    /// A bool vertex embedding (`fixed`) in row order (the value of the row's first orbit).
    pub fn vertex_bool(&self, name: &str) -> Result<Vec<bool>, PhysicsError> {
        let id = self.id(name)?;
        self.rows
            .darts
            .iter()
            .map(|&d| match self.g.value(id, d) {
                Ok(Value::Bool(b)) => Ok(b),
                Ok(v) => Err(PhysicsError::Config(format!(
                    "'{name}' is not a bool: {v:?}"
                ))),
                Err(e) => Err(PhysicsError::Config(e.to_string())),
            })
            .collect()
    }

    /// A bool vertex embedding, true for a row when it is true on any of its orbits.
    fn row_any(&self, name: &str) -> Result<Vec<bool>, PhysicsError> {
        let id = self.id(name)?;
        let mut out = vec![false; self.rows.darts.len()];
        for (&d, &r) in self.rows.orbits.iter().zip(&self.rows.row_of) {
            if let Ok(Value::Bool(true)) = self.g.value(id, d) {
                out[r] = true;
            }
        }
        Ok(out)
    }

    fn check_rows<T>(&self, values: &[T]) -> Result<(), PhysicsError> {
        let n = self.rows.darts.len();
        if values.len() != n {
            return Err(PhysicsError::Config(format!(
                "{} values given for {n} vertices",
                values.len()
            )));
        }
        Ok(())
    }

    /// Sets a vec3 vertex embedding from values in row order (every orbit of a row).
    pub fn set_vertex_vec3(&mut self, name: &str, values: &[[f64; 3]]) -> Result<(), PhysicsError> {
        self.sync_rows()?;
        let id = self.id(name)?;
        self.check_rows(values)?;
        for (&d, &r) in self.rows.orbits.iter().zip(&self.rows.row_of) {
            self.g
                .set_real(id, d, &values[r])
                .map_err(|e| PhysicsError::Config(e.to_string()))?;
        }
        Ok(())
    }

    /// Sets a bool vertex embedding from values in row order (every orbit of a row).
    pub fn set_vertex_bool(&mut self, name: &str, values: &[bool]) -> Result<(), PhysicsError> {
        self.sync_rows()?;
        let id = self.id(name)?;
        self.check_rows(values)?;
        for (&d, &r) in self.rows.orbits.iter().zip(&self.rows.row_of) {
            self.g
                .set_value(id, d, &Value::Bool(values[r]))
                .map_err(|e| PhysicsError::Config(e.to_string()))?;
        }
        Ok(())
    }

    /// Holds the rows where `mask` is true in place (and frees the others). Refuses, naming
    /// them, to free rows without mass (they could not move).
    pub fn set_fixed(&mut self, mask: &[bool]) -> Result<(), PhysicsError> {
        self.check_rows(mask)?;
        let m = self.vertex_scalar_sum("mass")?;
        let bad: Vec<usize> = (0..mask.len())
            .filter(|&v| !mask[v] && m[v].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater))
            .collect();
        if !bad.is_empty() {
            return Err(PhysicsError::Config(format!(
                "cannot free vertices without mass (they must stay fixed): {}",
                list_some(&bad, 20)
            )));
        }
        self.set_vertex_bool("fixed", mask)
    }

    /// Writes a stored vertex embedding of type `f64`, `vec3` or `bool` from one value per row
    /// (every orbit of a row gets its row's value; but a force, see [`is_additive`], is the
    /// row's total: its first orbit gets it and the others zero). An embedding that the rules declare but
    /// the map does not hold yet is added first. Refuses another orbit or type, a derived
    /// embedding, a wrong count, and non-finite values (naming every offending row, up to 20).
    pub fn set_vertex_field(&mut self, name: &str, values: &[Value]) -> Result<(), PhysicsError> {
        self.sync_rows()?;
        if self.g.embedding_id(name).is_none()
            && self.rules.embeddings().iter().any(|e| e.name == name)
        {
            self.rules.prepare_named(&mut self.g, &[name])?;
        }
        let vertex = OrbitType::vertex(self.g.dimension());
        let Some(id) = self.g.embedding_id(name) else {
            let names: Vec<&str> = self
                .g
                .embeddings()
                .iter()
                .filter(|e| e.orbit() == vertex && e.derived().is_none())
                .map(topomech_gmap::Embedding::name)
                .collect();
            return Err(PhysicsError::Config(format!(
                "no vertex embedding '{name}' (the map's stored vertex embeddings: {})",
                names.join(", ")
            )));
        };
        let e = self.g.embedding(id);
        if e.orbit() != vertex {
            return Err(PhysicsError::Config(format!(
                "embedding '{name}' is on the orbit {}, not on the vertex orbit {vertex}",
                e.orbit()
            )));
        }
        if e.derived().is_some() {
            return Err(PhysicsError::Config(format!(
                "embedding '{name}' is derived (computed from another one): it cannot be written"
            )));
        }
        let ty = e.ty();
        if !matches!(
            ty,
            EmbeddingType::F64 | EmbeddingType::Vec3 | EmbeddingType::Bool
        ) {
            return Err(PhysicsError::Config(format!(
                "embedding '{name}' has type {ty}: only f64, vec3 and bool vertex embeddings can be set per vertex"
            )));
        }
        self.check_rows(values)?;
        let mut bad_type = Vec::new();
        let mut non_finite = Vec::new();
        for (k, v) in values.iter().enumerate() {
            match (ty, v) {
                (EmbeddingType::Bool, Value::Bool(_)) => {}
                (EmbeddingType::F64, Value::Real(x)) if x.len() == 1 => {}
                (EmbeddingType::Vec3, Value::Real(x)) if x.len() == 3 => {}
                _ => bad_type.push(k),
            }
            if let Value::Real(x) = v {
                if x.iter().any(|x| !x.is_finite()) {
                    non_finite.push(k);
                }
            }
        }
        if !bad_type.is_empty() {
            return Err(PhysicsError::Config(format!(
                "'{name}' is a {ty}: the values of vertices {} are not",
                list_some(&bad_type, 20)
            )));
        }
        if !non_finite.is_empty() {
            return Err(PhysicsError::Config(format!(
                "'{name}' must be finite: vertices {} are not",
                list_some(&non_finite, 20)
            )));
        }
        // a force is a row's total: on the row's first orbit, zero on the others (the
        // accumulation sums them, the step shares the sum by mass)
        let share = is_additive(name);
        let zero = Value::Real(vec![0.0; ty.width()]);
        for (&d, &r) in self.rows.orbits.iter().zip(&self.rows.row_of) {
            let v = if share && self.rows.darts[r] != d {
                &zero
            } else {
                &values[r]
            };
            self.g
                .set_value(id, d, v)
                .map_err(|e| PhysicsError::Config(e.to_string()))?;
        }
        Ok(())
    }

    /// Sets the external loads `f_ext` (N, one row per vertex, in row order): constant
    /// forces the accumulation adds into `force` every step and the static solve balances.
    /// Each row's load is written on one vertex orbit of the row (a welded row's other orbits
    /// get zero), so that the row's total is the value given.
    /// Errors: a wrong row count, a non-finite value (naming the rows).
    pub fn set_external_forces(&mut self, forces: &[[f64; 3]]) -> Result<(), PhysicsError> {
        let values: Vec<Value> = forces.iter().map(|f| Value::Real(f.to_vec())).collect();
        self.set_vertex_field("f_ext", &values)
    }

    /// The external loads `f_ext` (N) in row order (a welded row's total).
    pub fn external_forces(&self) -> Result<Vec<[f64; 3]>, PhysicsError> {
        self.vertex_vec3_sum("f_ext")
    }

    /// Total mass (sum of the vertex masses).
    pub fn total_mass(&self) -> Result<f64, PhysicsError> {
        Ok(self.vertex_scalar_sum("mass")?.iter().sum())
    }

    /// Kinetic energy, sum over rows of m |v|^2 / 2 (a welded row counts once, with its
    /// whole mass).
    pub fn kinetic_energy(&self) -> Result<f64, PhysicsError> {
        let m = self.vertex_scalar_sum("mass")?;
        let v = self.vertex_vec3("velocity")?;
        Ok(m.iter()
            .zip(&v)
            .map(|(m, v)| 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]))
            .sum())
    }

    /// Linear momentum, sum over rows of m v.
    pub fn momentum(&self) -> Result<[f64; 3], PhysicsError> {
        let m = self.vertex_scalar_sum("mass")?;
        let v = self.vertex_vec3("velocity")?;
        let mut p = [0.0; 3];
        for (m, v) in m.iter().zip(&v) {
            for a in 0..3 {
                p[a] += m * v[a];
            }
        }
        Ok(p)
    }
}

/// What a topology change did ([`Simulation::cut`], [`Simulation::fracture`]).
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct TopologyResult {
    /// Faces (3D) or edges (2D) unsewn.
    pub unsewn: usize,
    /// The rows appended for the vertex orbits the change split off, in increasing order;
    /// each has the `point_id` of the vertex it was split from. Existing rows keep their
    /// meaning.
    pub added_rows: Vec<usize>,
}

/// An element (volume in 3D, face in 2D) as [`Simulation::elements`] lists it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Element {
    /// The index of the input cell it was built from (-1 when unknown).
    pub cell_id: i64,
    /// Its kind.
    pub kind: topomech_gmap::mesh::CellKind,
    /// Its vertices' rows.
    pub rows: Vec<usize>,
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

/// The simulation's vertex numbering: rows (particles) from the map's `particle` embedding.
#[derive(Debug, Clone, Default)]
struct Rows {
    /// One dart per row: the smallest dart of the row's first vertex orbit.
    darts: Vec<Dart>,
    /// One dart per vertex orbit (its smallest), in increasing order.
    orbits: Vec<Dart>,
    /// The row of each orbit of `orbits`.
    row_of: Vec<usize>,
    /// Rows of several orbits, with each orbit's smallest dart.
    welded: Vec<(usize, Vec<Dart>)>,
}

impl Rows {
    /// The numbering of a new simulation's map: from its `particle` embedding, created (with
    /// `point_id`) from the vertex orbit order when the map has none.
    fn init(g: &mut GMap) -> Result<Self, PhysicsError> {
        let vertex = OrbitType::vertex(g.dimension());
        let err = |e: topomech_gmap::EmbeddingError| PhysicsError::Config(e.to_string());
        let orbits = g.orbit_representatives(vertex);
        for name in ["particle", "point_id"] {
            if let Some(id) = g.embedding_id(name) {
                let e = g.embedding(id);
                if e.orbit() != vertex || e.ty() != EmbeddingType::I64 {
                    return Err(PhysicsError::Config(format!(
                        "the map's '{name}' must be an i64 on the vertex orbit {vertex}, it is a {} on {}",
                        e.ty(),
                        e.orbit()
                    )));
                }
            }
        }
        let particle = if let Some(id) = g.embedding_id("particle") {
            id
        } else {
            let id = g
                .add_embedding("particle", EmbeddingType::I64, vertex, Policy::Copy)
                .map_err(err)?;
            for (k, &d) in orbits.iter().enumerate() {
                g.set_value(id, d, &Value::Int(k as i64)).map_err(err)?;
            }
            id
        };
        let mut row_of = Vec::with_capacity(orbits.len());
        let mut negative = Vec::new();
        for &d in &orbits {
            match g.value(particle, d).map_err(err)? {
                Value::Int(x) if x >= 0 => row_of.push(x as usize),
                _ => {
                    negative.push(d.index());
                    row_of.push(0);
                }
            }
        }
        if !negative.is_empty() {
            return Err(PhysicsError::Config(format!(
                "the map's 'particle' is negative on the vertices of darts {}",
                list_some(&negative, 20)
            )));
        }
        let n = row_of.iter().max().map_or(0, |m| m + 1);
        let mut used = vec![false; n];
        for &r in &row_of {
            used[r] = true;
        }
        let missing: Vec<usize> = (0..n).filter(|&r| !used[r]).collect();
        if !missing.is_empty() {
            return Err(PhysicsError::Config(format!(
                "the map's 'particle' numbering has gaps: no vertex has rows {} (rows must be 0..{})",
                list_some(&missing, 20),
                n
            )));
        }
        if g.embedding_id("point_id").is_none() {
            let id = g
                .add_embedding("point_id", EmbeddingType::I64, vertex, Policy::Copy)
                .map_err(err)?;
            for (&d, &r) in orbits.iter().zip(&row_of) {
                g.set_value(id, d, &Value::Int(r as i64)).map_err(err)?;
            }
        }
        let mut rows = Rows {
            orbits,
            row_of,
            ..Rows::default()
        };
        rows.index(n);
        // the orbits of one particle must start at one place: they share its position
        let pos = g.require("position").map_err(err)?;
        let apart: Vec<usize> = rows
            .welded
            .iter()
            .filter(|(_, darts)| {
                darts
                    .iter()
                    .any(|&d| g.real(pos, d) != g.real(pos, darts[0]))
            })
            .map(|(r, _)| *r)
            .collect();
        if !apart.is_empty() {
            return Err(PhysicsError::Config(format!(
                "vertex orbits that share a 'particle' are one particle and must be at the same position: those of rows {} are not",
                list_some(&apart, 20)
            )));
        }
        Ok(rows)
    }

    /// Rebuilds `darts` and `welded` from `orbits` and `row_of` (`n` rows).
    fn index(&mut self, n: usize) {
        let mut count = vec![0usize; n];
        self.darts = vec![Dart(0); n];
        for (&d, &r) in self.orbits.iter().zip(&self.row_of).rev() {
            // reversed: the smallest orbit dart of the row is written last
            self.darts[r] = d;
            count[r] += 1;
        }
        self.welded.clear();
        if count.iter().any(|&c| c > 1) {
            let mut welded: Vec<(usize, Vec<Dart>)> = Vec::new();
            let mut slot = vec![usize::MAX; n];
            for (&d, &r) in self.orbits.iter().zip(&self.row_of) {
                if count[r] > 1 {
                    if slot[r] == usize::MAX {
                        slot[r] = welded.len();
                        welded.push((r, Vec::new()));
                    }
                    welded[slot[r]].1.push(d);
                }
            }
            welded.sort_by_key(|w| w.0);
            self.welded = welded;
        }
    }

    /// The numbering after a topology change of `g` (see [`Simulation::sync_rows`]); returns
    /// the rows added.
    fn renumber(&mut self, g: &mut GMap) -> Result<Vec<usize>, PhysicsError> {
        let vertex = OrbitType::vertex(g.dimension());
        let (labels, n_orbits) = g.orbit_labels(vertex);
        let orbits = g.orbit_representatives(vertex);
        let mut row_of = vec![usize::MAX; n_orbits];
        let n_rows = self.darts.len();
        let mut kept = vec![false; n_rows];
        for (&d, &r) in self.orbits.iter().zip(&self.row_of) {
            if !g.is_alive(d) {
                continue;
            }
            let l = labels[d.index()] as usize;
            if row_of[l] != usize::MAX && row_of[l] != r {
                return Err(PhysicsError::Config(format!(
                    "a topology change merged the vertices of rows {} and {r}: only splits are supported",
                    row_of[l]
                )));
            }
            row_of[l] = r;
            kept[r] = true;
        }
        let lost: Vec<usize> = (0..n_rows).filter(|&r| !kept[r]).collect();
        if !lost.is_empty() {
            return Err(PhysicsError::Config(format!(
                "a topology change removed the vertices of rows {}: only splits are supported",
                list_some(&lost, 20)
            )));
        }
        let particle = g
            .require("particle")
            .map_err(|e| PhysicsError::Config(e.to_string()))?;
        let mut added = Vec::new();
        for (l, &d) in orbits.iter().enumerate() {
            if row_of[l] == usize::MAX {
                let r = n_rows + added.len();
                row_of[l] = r;
                added.push(r);
                g.set_value(particle, d, &Value::Int(r as i64))
                    .map_err(|e| PhysicsError::Config(e.to_string()))?;
            }
        }
        self.orbits = orbits;
        self.row_of = row_of;
        self.index(n_rows + added.len());
        Ok(added)
    }
}

/// Per vertex: total force, mass, fixed.
type VertexForces = (Vec<[f64; 3]>, Vec<f64>, Vec<bool>);

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

/// Marks one dart per element (volume in 3D, face in 2D) as `vertex0`: the element's smallest
/// dart; and, where a model declares `face0`, one dart per face `<0,1>` of an element. Rules
/// number an element's or a face's vertices from them.
fn mark_vertex0(g: &mut GMap) -> Result<(), PhysicsError> {
    let elem = if g.dimension() == 3 {
        OrbitType::volume()
    } else {
        OrbitType::face(2)
    };
    mark_one_per_orbit(g, "vertex0", elem)?;
    if g.embedding_id("face0").is_some() {
        mark_one_per_orbit(g, "face0", OrbitType::parse("<0,1>").expect("static"))?;
    }
    Ok(())
}

/// Sets the bool embedding `name` (on `<>`) true on the smallest dart of each orbit `o`,
/// false elsewhere.
fn mark_one_per_orbit(g: &mut GMap, name: &str, o: OrbitType) -> Result<(), PhysicsError> {
    let err = |e: topomech_gmap::EmbeddingError| PhysicsError::Config(e.to_string());
    let id = g.require(name).map_err(err)?;
    let all: Vec<Dart> = g.darts().collect();
    for d in all {
        g.set_value(id, d, &Value::Bool(false)).map_err(err)?;
    }
    for d in g.orbit_representatives(o) {
        g.set_value(id, d, &Value::Bool(true)).map_err(err)?;
    }
    Ok(())
}
