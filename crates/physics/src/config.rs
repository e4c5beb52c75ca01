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
