//! `grid` and `box`: generated meshes for tests and demos, in the flat layout.

use pyo3::prelude::*;
use topomech_gmap::generators::{self, BoxElement, GridElement};
use topomech_gmap::MAX_DARTS;

use crate::convert::{count_arg, mesh_to_flat, size_arg, FlatMesh};
use crate::errors::{guard, value_error, Result};

/// The most darts one cell of any kind has (a hexahedron: 6 quads of 8 darts).
const MAX_DARTS_PER_CELL: usize = 48;
/// The most cells a generator makes per square or cube (pyramids and tetrahedra of `mixed`).
const MAX_CELLS_PER_CUBE: usize = 12;

/// Refuses a generated mesh whose G-map could not hold its darts.
fn check_size(counts: &[usize]) -> Result<()> {
    let limit = MAX_DARTS / MAX_DARTS_PER_CELL / MAX_CELLS_PER_CUBE;
    let total = counts
        .iter()
        .try_fold(1usize, |acc, &n| acc.checked_mul(n))
        .filter(|&t| t <= limit);
    match total {
        Some(_) => Ok(()),
        None => Err(value_error(format!(
            "{counts:?} squares or cubes is too many: a G-map holds at most {MAX_DARTS} darts"
        ))),
    }
}

/// A rectangle `sx x sy` in the plane z = 0 with `nx x ny` squares, as a flat mesh
/// `(points, kinds, offsets, connectivity)`. `element`: `triangle` (two per square), `quad`,
/// or `mixed` (quads on the left half, triangles on the right half).
#[pyfunction]
#[pyo3(signature = (nx, ny, sx = 1.0, sy = 1.0, element = "quad"))]
pub(crate) fn grid<'py>(
    py: Python<'py>,
    nx: i64,
    ny: i64,
    sx: f64,
    sy: f64,
    element: &str,
) -> PyResult<FlatMesh<'py>> {
    let mesh = guard(|| {
        let n = [count_arg(nx, "nx")?, count_arg(ny, "ny")?];
        let size = [size_arg(sx, "sx")?, size_arg(sy, "sy")?];
        let element = match element {
            "triangle" | "tri" => GridElement::Triangle,
            "quad" => GridElement::Quad,
            "mixed" => GridElement::Mixed,
            other => {
                let expected = "'triangle' (or 'tri'), 'quad' or 'mixed'";
                return Err(value_error(format!(
                    "unknown grid element {other:?}: expected {expected}"
                )));
            }
        };
        check_size(&n)?;
        Ok((n, size, element))
    })
    .and_then(|(n, size, element)| {
        py.detach(|| guard(|| Ok(generators::grid(n, size, element))))
    })?;
    guard(|| mesh_to_flat(py, &mesh))
}

/// A box `sx x sy x sz` with `nx x ny x nz` cubes, corner at the origin, as a flat mesh.
/// `element`: `tetra` (6 per cube), `hexahedron`, `wedge` (2 per cube), `pyramid` (6 per cube)
/// or `mixed` (hexahedra, pyramids and tetrahedra); `tet` and `hex` too, as scenes spell them.
#[pyfunction(name = "box")]
#[pyo3(signature = (nx, ny, nz, sx = 1.0, sy = 1.0, sz = 1.0, element = "hexahedron"))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn cuboid<'py>(
    py: Python<'py>,
    nx: i64,
    ny: i64,
    nz: i64,
    sx: f64,
    sy: f64,
    sz: f64,
    element: &str,
) -> PyResult<FlatMesh<'py>> {
    let mesh = guard(|| {
        let n = [count_arg(nx, "nx")?, count_arg(ny, "ny")?, count_arg(nz, "nz")?];
        let size = [size_arg(sx, "sx")?, size_arg(sy, "sy")?, size_arg(sz, "sz")?];
        let element = match element {
            "tetra" | "tet" => BoxElement::Tetra,
            "hexahedron" | "hex" => BoxElement::Hexa,
            "wedge" => BoxElement::Wedge,
            "pyramid" => BoxElement::Pyramid,
            "mixed" => BoxElement::Mixed,
            other => {
                return Err(value_error(format!(
                    "unknown box element {other:?}: expected 'tetra' (or 'tet'), 'hexahedron' (or 'hex'), 'wedge', 'pyramid' or 'mixed'"
                )))
            }
        };
        check_size(&n)?;
        Ok((n, size, element))
    })
    .and_then(|(n, size, element)| py.detach(|| guard(|| Ok(generators::cuboid(n, size, element)))))?;
    guard(|| mesh_to_flat(py, &mesh))
}
