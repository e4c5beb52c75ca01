//! Arguments in, arrays out: shape, type and range checks at the boundary, and the flat mesh
//! layout shared by `GMap.from_flat`, `GMap.to_flat`, `grid` and `box`.
//!
//! A flat mesh is four values (meshio's and VTK's layout without the cell types' codes):
//! `points` float64 `(N, 3)`, `kinds` a list of `M` names, `offsets` int64 `(M + 1,)` starting
//! at 0 and non-decreasing, `connectivity` int64 `(offsets[M],)`; cell `c` has the vertices
//! `connectivity[offsets[c]:offsets[c + 1]]`.

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyInt;
use topomech_gmap::mesh::{CellKind, Mesh};
use topomech_gmap::{Dart, GMap};

use crate::errors::{index_error, type_error, value_error, Error, Result};

/// The flat layout returned to Python: `(points, kinds, offsets, connectivity)`.
pub(crate) type FlatMesh<'py> = (
    Bound<'py, PyArray2<f64>>,
    Vec<&'static str>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
);

/// A shape written as Python writes a tuple: `(5,)`, `(5, 4)`.
pub(crate) fn shape_str(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The Python type name of `obj`, for messages.
pub(crate) fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map_or_else(|_| "?".to_string(), |n| n.to_string())
}

/// A numpy array of element type `T`, or a `TypeError` naming the argument.
pub(crate) fn array_arg<'py, T: numpy::Element>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    dtype: &str,
) -> Result<PyReadonlyArrayDyn<'py, T>> {
    obj.extract::<PyReadonlyArrayDyn<'py, T>>().map_err(|_| {
        let got = obj
            .getattr("dtype")
            .map_or_else(|_| type_name(obj), |d| format!("a {d} array"));
        type_error(format!(
            "{name} must be a numpy array of dtype {dtype}, got {got} (convert it with numpy.asarray(..., dtype=numpy.{dtype}))"
        ))
    })
}

/// `points`: float64 `(N, 3)`, as rows.
pub(crate) fn points_arg(obj: &Bound<'_, PyAny>) -> Result<Vec<[f64; 3]>> {
    rows3_arg(obj, "points", "N")
}

/// A float64 `(rows, 3)` array named `name` (`rows` is how messages name the row count), as
/// rows.
pub(crate) fn rows3_arg(obj: &Bound<'_, PyAny>, name: &str, rows: &str) -> Result<Vec<[f64; 3]>> {
    let a = array_arg::<f64>(obj, name, "float64")?;
    let shape = a.shape();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(value_error(format!(
            "{name} must have shape ({rows}, 3), got {}",
            shape_str(shape)
        )));
    }
    let v = a.as_array();
    Ok(v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// A 1-D int64 array, as a vector.
fn int_vector_arg(obj: &Bound<'_, PyAny>, name: &str, expected: &str) -> Result<Vec<i64>> {
    let a = array_arg::<i64>(obj, name, "int64")?;
    let shape = a.shape();
    if shape.len() != 1 {
        return Err(value_error(format!(
            "{name} must have shape {expected}, got {}",
            shape_str(shape)
        )));
    }
    Ok(a.as_array().iter().copied().collect())
}

/// Builds a [`Mesh`] from the flat layout, checking every length, offset and index; a negative
/// vertex index is refused here (it would wrap as an unsigned index), naming its cell.
pub(crate) fn mesh_from_flat(
    points: &Bound<'_, PyAny>,
    kinds: &[String],
    offsets: &Bound<'_, PyAny>,
    connectivity: &Bound<'_, PyAny>,
) -> Result<Mesh> {
    let points = points_arg(points)?;
    let m = kinds.len();
    let offsets = int_vector_arg(
        offsets,
        "offsets",
        &format!("(M + 1,) = ({},) for {m} kinds", m + 1),
    )?;
    let connectivity = int_vector_arg(connectivity, "connectivity", "(K,)")?;
    if offsets.len() != m + 1 {
        return Err(value_error(format!(
            "offsets must have shape (M + 1,) = ({},) for {m} kinds, got ({},)",
            m + 1,
            offsets.len()
        )));
    }
    if offsets[0] != 0 {
        return Err(value_error(format!(
            "offsets[0] must be 0, got {}",
            offsets[0]
        )));
    }
    for c in 0..m {
        if offsets[c + 1] < offsets[c] {
            return Err(value_error(format!(
                "offsets must be non-decreasing: offsets[{}] = {} < offsets[{c}] = {}",
                c + 1,
                offsets[c + 1],
                offsets[c]
            )));
        }
    }
    if offsets[m] != connectivity.len() as i64 {
        return Err(value_error(format!(
            "offsets[-1] = {} must equal the length of connectivity ({})",
            offsets[m],
            connectivity.len()
        )));
    }
    let mut cell_kinds = Vec::with_capacity(m);
    let mut cells = Vec::with_capacity(m);
    for (c, name) in kinds.iter().enumerate() {
        let kind = CellKind::parse(name).ok_or_else(|| {
            Error::MeshInput(format!(
                "cell {c} has unknown kind {name:?}: expected one of polygon, tetra, hexahedron, wedge, pyramid"
            ))
        })?;
        let verts = &connectivity[offsets[c] as usize..offsets[c + 1] as usize];
        let mut cell = Vec::with_capacity(verts.len());
        for &v in verts {
            let v = usize::try_from(v).map_err(|_| {
                Error::MeshInput(format!(
                    "cell {c} ({name}) refers to vertex {v}: vertex indices must be non-negative"
                ))
            })?;
            cell.push(v);
        }
        cell_kinds.push(kind);
        cells.push(cell);
    }
    Ok(Mesh {
        points,
        kinds: cell_kinds,
        cells,
    })
}

/// `(N, 3)` float64 array from rows.
pub(crate) fn rows_to_array<'py>(
    py: Python<'py>,
    rows: &[[f64; 3]],
) -> Result<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    let a = Array2::from_shape_vec((rows.len(), 3), flat)
        .map_err(|e| value_error(format!("cannot shape points: {e}")))?;
    Ok(a.into_pyarray(py))
}

/// The flat layout of a mesh.
pub(crate) fn mesh_to_flat<'py>(py: Python<'py>, mesh: &Mesh) -> Result<FlatMesh<'py>> {
    let points = rows_to_array(py, &mesh.points)?;
    let kinds: Vec<&'static str> = mesh.kinds.iter().map(|k| k.name()).collect();
    let mut offsets = Vec::with_capacity(mesh.cells.len() + 1);
    offsets.push(0i64);
    let mut connectivity = Vec::new();
    for cell in &mesh.cells {
        connectivity.extend(cell.iter().map(|&v| v as i64));
        offsets.push(connectivity.len() as i64);
    }
    Ok((
        points,
        kinds,
        offsets.into_pyarray(py),
        connectivity.into_pyarray(py),
    ))
}

/// Polyhedra as flat arrays `(points, cell_offsets, face_offsets, connectivity)`: the faces
/// of cell `c` are `cell_offsets[c]..cell_offsets[c + 1]`, the points of face `f`
/// `connectivity[face_offsets[f]..face_offsets[f + 1]]`.
pub(crate) type FlatPolyhedra<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
);

/// [`FlatPolyhedra`] of `mesh::extract_polyhedra`'s output.
pub(crate) fn polyhedra_to_flat<'py>(
    py: Python<'py>,
    points: &[[f64; 3]],
    cells: &[Vec<Vec<usize>>],
) -> Result<FlatPolyhedra<'py>> {
    let points = rows_to_array(py, points)?;
    let mut cell_offsets = vec![0i64];
    let mut face_offsets = vec![0i64];
    let mut connectivity = Vec::new();
    for faces in cells {
        for f in faces {
            connectivity.extend(f.iter().map(|&v| v as i64));
            face_offsets.push(connectivity.len() as i64);
        }
        cell_offsets.push(face_offsets.len() as i64 - 1);
    }
    Ok((
        points,
        cell_offsets.into_pyarray(py),
        face_offsets.into_pyarray(py),
        connectivity.into_pyarray(py),
    ))
}

/// A Python integer as `i64`; an integer too large for it is an `IndexError` (an index out of
/// range), anything else not an integer a `TypeError`.
fn int_arg(obj: &Bound<'_, PyAny>, what: &str) -> Result<i64> {
    match obj.extract::<i64>() {
        Ok(v) => Ok(v),
        Err(_) if obj.is_instance_of::<PyInt>() => {
            Err(index_error(format!("{what} {obj} is out of range")))
        }
        Err(_) => Err(type_error(format!(
            "{what} must be an int, got {}",
            type_name(obj)
        ))),
    }
}

/// A live dart of `g`, or an `IndexError` saying why not. Never wraps a negative value.
pub(crate) fn dart_arg(g: &GMap, obj: &Bound<'_, PyAny>) -> Result<Dart> {
    let d = int_arg(obj, "dart")?;
    let cap = g.capacity();
    match u32::try_from(d) {
        Ok(u) if (u as usize) < cap => {
            let dart = Dart(u);
            if g.is_alive(dart) {
                Ok(dart)
            } else {
                Err(index_error(format!("dart {d} was removed from this map")))
            }
        }
        _ if cap == 0 => Err(index_error(format!(
            "dart {d} is out of range: the map has no darts"
        ))),
        _ => Err(index_error(format!(
            "dart {d} is out of range: darts are numbered 0..{}",
            cap - 1
        ))),
    }
}

/// A link dimension `0..=n` of `g`, or an `IndexError`.
pub(crate) fn dim_arg(g: &GMap, obj: &Bound<'_, PyAny>) -> Result<usize> {
    let i = int_arg(obj, "dimension")?;
    let n = g.dimension();
    match usize::try_from(i) {
        Ok(u) if u <= n => Ok(u),
        _ => Err(index_error(format!(
            "dimension {i} is out of range: a {n}-map has links alpha0..alpha{n}"
        ))),
    }
}

/// A count argument (`nx`, ...) that must be at least 1.
pub(crate) fn count_arg(v: i64, name: &str) -> Result<usize> {
    match usize::try_from(v) {
        Ok(u) if u >= 1 => Ok(u),
        _ => Err(value_error(format!("{name} must be at least 1, got {v}"))),
    }
}

/// A size argument (`sx`, ...) that must be finite and positive.
pub(crate) fn size_arg(v: f64, name: &str) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(value_error(format!(
            "{name} must be finite and positive, got {v}"
        )))
    }
}
