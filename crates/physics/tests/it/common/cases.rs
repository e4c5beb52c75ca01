//! The model-and-mesh cases shared by the tests that compare two ways of running a step
//! (the interpreter, compiled plans, native code): one configuration and one small mesh per
//! shipped model.

use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::Mesh;
use topomech_physics::{Config, Integrator};

use super::model;

/// Model `kind` with its defaults, under gravity, damped, held at x = 0.
pub fn config(kind: &str, integrator: Integrator) -> Config {
    Config {
        models: vec![model(kind, &[])],
        gravity: [0.0, -9.81, 0.0],
        damping: 0.3,
        fixed: vec!["x < 1e-9".into()],
        integrator,
        dt: 1e-3,
        ..Config::default()
    }
}

/// The mesh of a case: `dim` 2 (quads, or triangles for the co-rotational membrane), 3
/// (tetrahedra), 4 (hexahedra).
pub fn mesh_for(kind: &str, dim: usize) -> Mesh {
    if dim == 4 {
        cuboid([3, 2, 2], [1.5, 1.0, 1.0], BoxElement::Hexa)
    } else if dim == 3 {
        cuboid([3, 2, 2], [1.5, 1.0, 1.0], BoxElement::Tetra)
    } else if kind == "corotational" {
        grid([4, 3], [1.0, 0.75], GridElement::Triangle)
    } else {
        grid([4, 3], [1.0, 0.75], GridElement::Quad)
    }
}
