//! What a simulation is built from beside the map: integrator, models, material, loads.

use std::collections::HashMap;

use topomech_rules::Val;

use crate::*;

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
    /// The model's name: one of [`shipped_models`](crate::shipped_models), or a model declared
    /// in one of [`Config::model_files`].
    pub kind: String,
    /// Parameters (missing ones take the model's defaults): a [`Val::F`] for an `f64`
    /// parameter, a [`Val::V3`] for a `vec3` one; another type, or a type that is not the
    /// declared one, is refused when the simulation is built, naming the model and parameter.
    pub params: HashMap<String, Val>,
}

impl ModelSpec {
    /// The model `kind` with the real parameters `params` (the common case: every shipped
    /// model's parameters are `f64`).
    pub fn with_reals(kind: &str, params: &[(&str, f64)]) -> Self {
        ModelSpec {
            kind: kind.to_string(),
            params: params
                .iter()
                .map(|(k, v)| ((*k).to_string(), Val::F(*v)))
                .collect(),
        }
    }
}

/// Everything a simulation needs beside the map.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// The models, summed.
    pub models: Vec<ModelSpec>,
    /// Rule files of the user's own, `(file name, text)`, declaring models (`model`
    /// declarations): loaded with the shipped common rules of the map's dimension, after
    /// the shipped model files. A model they declare replaces the shipped one of the same
    /// name (a simulation that needs both files, for another shipped model of the same file,
    /// is refused: the name is declared twice).
    pub model_files: Vec<(String, String)>,
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
    /// Blades moving through the object during the run (progressive cuts).
    pub blades: Vec<Blade>,
    /// Fracture (or tearing), tested after every step.
    pub fracture: Option<Fracture>,
    /// The integrator.
    pub integrator: Integrator,
    /// Time step.
    pub dt: f64,
    /// The linear solver of the implicit Euler and static steps (scene key
    /// `integrator.linear_solver`).
    pub linear_solver: LinearSolver,
    /// The preconditioner of [`LinearSolver::Pcg`] (scene key `integrator.preconditioner`).
    pub preconditioner: Preconditioner,
    /// The relative residual a solve must reach (scene key `integrator.tolerance`, in
    /// (0, 1)): of the linear solve for implicit Euler (None: [`IMPLICIT_TOLERANCE`],
    /// 1e-6), of Newton's residual force for static (None: [`STATIC_TOLERANCE`], 1e-10).
    pub tolerance: Option<f64>,
    /// The most iterations of the iterative linear solver (cg, pcg) in one linear solve
    /// (scene key `integrator.max_iterations`, at least 1; None: 10 times the degrees of
    /// freedom, at least 50).
    pub max_iterations: Option<usize>,
}

/// The linear solver of the implicit Euler and static steps.
///
/// `Auto` picks [`LinearSolver::Direct`] for a static solve of at most
/// [`AUTO_DIRECT_MAX_DOFS`] free degrees of freedom (3 per free vertex) and
/// [`LinearSolver::Pcg`] otherwise; implicit Euler always gets `Pcg` (its matrix, mass plus
/// h^2 stiffness, is well conditioned at the usual time steps, so a few preconditioned
/// iterations cost less than one assembly).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LinearSolver {
    /// Chosen by the problem (see the type's docs).
    #[default]
    Auto,
    /// Matrix-free conjugate gradients on the models' Jacobian-vector product rules, no
    /// preconditioner.
    Cg,
    /// Matrix-free conjugate gradients with [`Config::preconditioner`].
    Pcg,
    /// The Jacobian assembled from the same rules (compressed probing, Curtis, Powell & Reid
    /// 1974) and factored by a sparse Cholesky (LDL^T when it is not positive definite) of
    /// the `faer` crate, on the free degrees of freedom.
    Direct,
}

impl LinearSolver {
    /// Parses `auto`, `cg`, `pcg`, `direct`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "auto" => Some(LinearSolver::Auto),
            "cg" => Some(LinearSolver::Cg),
            "pcg" => Some(LinearSolver::Pcg),
            "direct" => Some(LinearSolver::Direct),
            _ => None,
        }
    }

    /// The name [`LinearSolver::parse`] reads.
    pub fn name(self) -> &'static str {
        match self {
            LinearSolver::Auto => "auto",
            LinearSolver::Cg => "cg",
            LinearSolver::Pcg => "pcg",
            LinearSolver::Direct => "direct",
        }
    }
}

/// The preconditioner of [`LinearSolver::Pcg`]: built from the diagonal 3x3 blocks of the
/// system matrix, which the models' Jacobian-vector product rules give by probing (a
/// distance-1 coloring of the vertex coupling graph, 3 products per color).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Preconditioner {
    /// The diagonal of the system matrix.
    Jacobi,
    /// The inverse of each free vertex's 3x3 diagonal block (the diagonal for a block that
    /// is not symmetric positive definite).
    #[default]
    BlockJacobi,
}

impl Preconditioner {
    /// Parses `jacobi`, `block_jacobi`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "jacobi" => Some(Preconditioner::Jacobi),
            "block_jacobi" => Some(Preconditioner::BlockJacobi),
            _ => None,
        }
    }

    /// The name [`Preconditioner::parse`] reads.
    pub fn name(self) -> &'static str {
        match self {
            Preconditioner::Jacobi => "jacobi",
            Preconditioner::BlockJacobi => "block_jacobi",
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Config {
            models: Vec::new(),
            model_files: Vec::new(),
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
            blades: Vec::new(),
            fracture: None,
            integrator: Integrator::SymplecticEuler,
            dt: 1e-3,
            linear_solver: LinearSolver::Auto,
            preconditioner: Preconditioner::BlockJacobi,
            tolerance: None,
            max_iterations: None,
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
