//! `topomech._core.GMap`: the kernel's map, with numpy arrays in and out.

use std::path::PathBuf;

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyKeyError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use topomech_gmap::mesh::{self, BuildOptions, Duplicates, Pinched};
use topomech_gmap::{io, ColumnRef, EmbeddingId, EmbeddingType, GMap, Marks, OrbitType};

use crate::convert::{
    array_arg, dart_arg, dim_arg, mesh_from_flat, mesh_to_flat, polyhedra_to_flat, rows_to_array,
    shape_str, FlatMesh, FlatPolyhedra,
};
use crate::errors::{exclusive, guard, shared, value_error, Error, InternalError, Result};

/// A generalized map of dimension 2 (surfaces) or 3 (volumes).
///
/// Build one with `GMap.from_flat` (or the friendlier `topomech.GMap.from_mesh`), or load a
/// `.tmg` file with `GMap.load`.
#[pyclass(name = "GMap", module = "topomech._core")]
pub(crate) struct PyGMap {
    inner: GMap,
    /// Set when a panic interrupted a method that changes the map: its state is then unknown,
    /// and every later call refuses with `InternalError` rather than read a broken map.
    poisoned: bool,
}

impl PyGMap {
    pub(crate) fn new(inner: GMap) -> Self {
        PyGMap {
            inner,
            poisoned: false,
        }
    }

    /// The map, unless a panic left it in an unknown state.
    pub(crate) fn map(&self) -> PyResult<&GMap> {
        if self.poisoned {
            Err(InternalError::new_err(
                "this map was left in an unknown state by an earlier internal error and cannot be used",
            ))
        } else {
            Ok(&self.inner)
        }
    }

    /// Runs a changing operation; a panic poisons the map.
    pub(crate) fn mutate<T>(
        &mut self,
        py: Python<'_>,
        f: impl FnOnce(&mut GMap) -> Result<T>,
    ) -> PyResult<T> {
        self.map()?;
        let r = guard(|| f(&mut self.inner));
        if r.as_ref()
            .is_err_and(|e| e.is_instance_of::<InternalError>(py))
        {
            self.poisoned = true;
        }
        r
    }
}

/// What `embedding` returns to Python: the values (one row per orbit), the smallest dart of
/// each orbit (int64), and the orbit type as written (`<1,2,3>`).
pub(crate) type OrbitValuesPy<'py> = (Bound<'py, PyAny>, Bound<'py, PyArray1<i64>>, String);

/// Refuses values for the map's vertex numbering `particle` (i64 on the vertex orbit, see
/// `GMap::vertex_rows`) that number no rows: a negative row, a row past the number of vertex
/// orbits, unused rows below the largest (the numbering is dense, 0..n), or one row given to
/// vertex orbits at different positions (orbits sharing a row are one particle). Without the
/// check such a numbering was written and then ignored, or collapsed the written mesh onto one
/// point. Other embeddings, and a `particle` declared otherwise, pass.
fn check_particle_rows(
    g: &GMap,
    id: EmbeddingId,
    vals: &Gathered,
    reps: &[topomech_gmap::Dart],
) -> Result<()> {
    let e = g.embedding(id);
    let vertex = OrbitType::vertex(g.dimension());
    let Gathered::Int(rows) = vals else {
        return Ok(());
    };
    if e.name() != "particle" || e.ty() != EmbeddingType::I64 || e.orbit() != vertex {
        return Ok(());
    }
    let what = format!(
        "values for 'particle' (the vertex numbering: a row 0..n-1 for each of the {} vertex orbits)",
        reps.len()
    );
    let at = |k: usize| format!("the vertex of dart {} (row {k} of the values)", reps[k].0);
    if let Some(k) = rows.iter().position(|&r| r < 0) {
        return Err(value_error(format!(
            "{what} must not be negative: {} for {}",
            rows[k],
            at(k)
        )));
    }
    if let Some(k) = rows
        .iter()
        .position(|&r| usize::try_from(r).map_or(true, |r| r >= reps.len()))
    {
        return Err(value_error(format!(
            "{what} must be below {}: {} for {}",
            reps.len(),
            rows[k],
            at(k)
        )));
    }
    // every row now indexes `first` (0 <= r < reps.len())
    let n = rows.iter().max().map_or(0, |&m| m as usize + 1);
    let mut first: Vec<Option<usize>> = vec![None; n];
    let pos = g
        .embedding_id("position")
        .filter(|&p| matches!(g.embedding(p).column(), ColumnRef::Real(_)));
    for (k, &r) in rows.iter().enumerate() {
        let r = r as usize;
        match first[r] {
            None => first[r] = Some(k),
            Some(j) => {
                if let Some(p) = pos {
                    let (a, b) = (g.real(p, reps[j]), g.real(p, reps[k]));
                    if a != b {
                        return Err(value_error(format!(
                            "{what} give particle row {r} to vertices at different positions: {} at {a:?} and {} at {b:?} (vertex orbits sharing a row are one particle, at one place)",
                            at(j),
                            at(k)
                        )));
                    }
                }
            }
        }
    }
    let unused: Vec<String> = (0..n)
        .filter(|&r| first[r].is_none())
        .map(|r| r.to_string())
        .collect();
    if !unused.is_empty() {
        let shown = unused.len().min(20);
        let more = if unused.len() > shown {
            format!(" and {} more", unused.len() - shown)
        } else {
            String::new()
        };
        return Err(value_error(format!(
            "{what} must use every row below the largest, {}: no vertex has row {}{more}",
            n - 1,
            unused[..shown].join(", ")
        )));
    }
    Ok(())
}

/// Refuses values for the map's input numbering that no input mesh gives: `point_id` (i64 on
/// the vertex orbit: the index of each vertex's point in the mesh the map was built from) and
/// `cell_id` (i64 on the element orbit, faces of a 2-map and volumes of a 3-map: the index of
/// its input cell), which the written meshes carry as their `point_id` and `cell_id` data and
/// which point groups and the output's cell order are read through.
///
/// The contract, from what the kernel writes: a value is an input index (>= 0) or -1 for
/// none (a vertex a rule created, see `GMap::rewire`); the vertices of one element are
/// distinct input points (an input cell lists distinct points; the output maps an element
/// back to its input cell through them), -1 aside. Values are not unique otherwise: a point
/// split in several vertices (`pinched="split"`, a fracture, a cut) keeps its `point_id` on
/// each, and the pieces of a cell a rule subdivides keep its `cell_id`. Other embeddings, and
/// a `point_id` or `cell_id` declared on another orbit or type, pass.
fn check_input_numbering(
    g: &GMap,
    id: EmbeddingId,
    vals: &Gathered,
    reps: &[topomech_gmap::Dart],
) -> Result<()> {
    let e = g.embedding(id);
    let Gathered::Int(values) = vals else {
        return Ok(());
    };
    let dim = g.dimension();
    let (element, element_word) = if dim == 2 {
        (OrbitType::face(2), "face")
    } else {
        (OrbitType::volume(), "volume")
    };
    let name = e.name();
    let (orbit_word, of) = match name {
        "point_id" if e.orbit() == OrbitType::vertex(dim) => {
            ("vertex", "the input point of each vertex".to_string())
        }
        "cell_id" if e.orbit() == element => (
            element_word,
            format!("the input cell of each {element_word}"),
        ),
        _ => return Ok(()),
    };
    if e.ty() != EmbeddingType::I64 {
        return Ok(());
    }
    let what = format!(
        "values for '{name}' ({of}: its index in the mesh the map was built from, or -1 for none)"
    );
    let at = |k: usize| {
        format!(
            "the {orbit_word} of dart {} (row {k} of the values)",
            reps[k].0
        )
    };
    if let Some(k) = values.iter().position(|&v| v < -1) {
        return Err(value_error(format!(
            "{what} must be -1 or more: {} for {}",
            values[k],
            at(k)
        )));
    }
    if name == "point_id" {
        if let Some((elem, j, k)) = point_twice_in_an_element(g, values, reps, element) {
            return Err(value_error(format!(
                "{what} must differ between the vertices of one {element_word}: point {} for {} and {}, both on the {element_word} of dart {}",
                values[j],
                at(j),
                at(k),
                elem.0
            )));
        }
    }
    Ok(())
}

/// The first element of type `element` (by smallest dart, returned) with two vertex orbits
/// that hold the same point (not -1), and those orbits' indices in `reps` (the vertex orbits,
/// by smallest dart), smaller first; `values[k]` is the point of `reps[k]`.
fn point_twice_in_an_element(
    g: &GMap,
    values: &[i64],
    reps: &[topomech_gmap::Dart],
    element: OrbitType,
) -> Option<(topomech_gmap::Dart, usize, usize)> {
    let vertex = OrbitType::vertex(g.dimension());
    // the vertex orbit of each dart (an index into `reps`: below the dart count, a u32)
    let mut vertex_of = vec![0u32; g.capacity()];
    let mut marks = Marks::with_capacity(g.capacity());
    for (k, &r) in reps.iter().enumerate() {
        g.visit_orbit(r, vertex, &mut marks, |d| vertex_of[d.index()] = k as u32);
    }
    marks.clear();
    // (point, vertex) of the element's corners, one entry per dart
    let mut corners: Vec<(i64, usize)> = Vec::new();
    for d in g.darts() {
        if marks.is_marked(d) {
            continue;
        }
        corners.clear();
        g.visit_orbit(d, element, &mut marks, |x| {
            let k = vertex_of[x.index()] as usize;
            if values[k] >= 0 {
                corners.push((values[k], k));
            }
        });
        corners.sort_unstable();
        corners.dedup();
        if let Some(w) = corners.windows(2).find(|w| w[0].0 == w[1].0) {
            return Some((d, w[0].1, w[1].1));
        }
    }
    None
}

/// An embedding's values gathered one per orbit, owned: `width` reals per orbit (row-major),
/// or one integer or boolean per orbit.
pub(crate) enum Gathered {
    Real(Vec<f64>),
    Int(Vec<i64>),
    Bool(Vec<bool>),
}

impl Gathered {
    /// Whether values `a` and `b` (of `w` scalars each when real) are equal, bit for bit.
    pub(crate) fn rows_equal(&self, w: usize, a: usize, b: usize) -> bool {
        match self {
            Gathered::Real(v) => v[a * w..(a + 1) * w]
                .iter()
                .zip(&v[b * w..(b + 1) * w])
                .all(|(x, y)| x.to_bits() == y.to_bits()),
            Gathered::Int(v) => v[a] == v[b],
            Gathered::Bool(v) => v[a] == v[b],
        }
    }

    pub(crate) fn as_column(&self) -> ColumnRef<'_> {
        match self {
            Gathered::Real(v) => ColumnRef::Real(v),
            Gathered::Int(v) => ColumnRef::Int(v),
            Gathered::Bool(v) => ColumnRef::Bool(v),
        }
    }
}

/// The values of one embedding, one per orbit of its orbit type, orbits by smallest dart.
pub(crate) struct OrbitValues {
    /// The numpy shape: `(n,)`, `(n, 2)`, `(n, 3)` or `(n, R, C)`.
    shape: Vec<usize>,
    /// The smallest dart of each orbit, increasing.
    darts: Vec<i64>,
    /// The orbit type, as written.
    orbit: String,
    values: Gathered,
}

/// The `KeyError` for an embedding `name` that `g` does not have, listing those it has.
pub(crate) fn unknown_embedding(g: &GMap, name: &str) -> PyErr {
    let names: Vec<&str> = g
        .embeddings()
        .iter()
        .map(topomech_gmap::Embedding::name)
        .collect();
    PyKeyError::new_err(format!(
        "no embedding named '{name}'; the map has: {}",
        if names.is_empty() {
            "none".to_string()
        } else {
            names.join(", ")
        }
    ))
}

/// The id of `name`, or the `KeyError` of [`unknown_embedding`].
pub(crate) fn embedding_key(g: &GMap, name: &str) -> PyResult<EmbeddingId> {
    g.embedding_id(name)
        .ok_or_else(|| unknown_embedding(g, name))
}

/// The numpy shape of `n` values of type `ty`.
fn value_shape(ty: EmbeddingType, n: usize) -> Vec<usize> {
    match ty {
        EmbeddingType::F64 | EmbeddingType::I64 | EmbeddingType::Bool => vec![n],
        EmbeddingType::Vec2 => vec![n, 2],
        EmbeddingType::Vec3 => vec![n, 3],
        EmbeddingType::Mat { rows, cols } => vec![n, usize::from(rows), usize::from(cols)],
    }
}

/// `shape` written with `n` for the row count, as a message shows the expected shape.
fn shape_pattern(shape: &[usize]) -> String {
    let mut parts = vec!["n".to_string()];
    parts.extend(shape[1..].iter().map(ToString::to_string));
    if parts.len() == 1 {
        "(n,)".to_string()
    } else {
        format!("({})", parts.join(", "))
    }
}

/// Reads embedding `id` of `g`, one value per orbit. A derived embedding must be fresh (the
/// caller refreshes it first).
pub(crate) fn read_orbit_values(g: &GMap, id: EmbeddingId) -> Result<OrbitValues> {
    let e = g.embedding(id);
    if g.is_stale(id) {
        return Err(Error::EmbeddingInput(format!(
            "derived embedding '{}' is stale",
            e.name()
        )));
    }
    let reps = g.orbit_representatives(e.orbit());
    let w = e.ty().width();
    let values = match e.column() {
        ColumnRef::Real(col) => {
            let mut out = Vec::with_capacity(reps.len() * w);
            for &d in &reps {
                let s = e.slot(d);
                out.extend_from_slice(&col[s * w..(s + 1) * w]);
            }
            Gathered::Real(out)
        }
        ColumnRef::Int(col) => Gathered::Int(reps.iter().map(|&d| col[e.slot(d)]).collect()),
        ColumnRef::Bool(col) => Gathered::Bool(reps.iter().map(|&d| col[e.slot(d)]).collect()),
    };
    Ok(OrbitValues {
        shape: value_shape(e.ty(), reps.len()),
        darts: reps.iter().map(|d| i64::from(d.0)).collect(),
        orbit: e.orbit().to_string(),
        values,
    })
}

/// The Python tuple `(values, darts, orbit)` of `v`.
pub(crate) fn orbit_values_to_py<'py>(
    py: Python<'py>,
    name: &str,
    v: OrbitValues,
) -> PyResult<OrbitValuesPy<'py>> {
    let darts = v.darts.into_pyarray(py);
    let values = match v.values {
        Gathered::Int(x) => x.into_pyarray(py).into_any(),
        Gathered::Bool(x) => x.into_pyarray(py).into_any(),
        Gathered::Real(x) => {
            let a = guard(|| {
                ArrayD::from_shape_vec(IxDyn(&v.shape), x)
                    .map_err(|e| value_error(format!("cannot shape '{name}': {e}")))
            })?;
            let arr: Bound<'py, PyArrayDyn<f64>> = a.into_pyarray(py);
            arr.into_any()
        }
    };
    Ok((values, darts, v.orbit))
}

/// Checks `values` for writing the stored embedding `id` of `g` one value per orbit (the
/// layout of [`read_orbit_values`]): the dtype (`TypeError`), the shape and finiteness
/// (`ValueError`, naming the embedding and the first bad row with its dart), and refuses a
/// derived embedding (`EmbeddingError`). Returns the values and the smallest dart of each
/// orbit.
pub(crate) fn orbit_values_arg(
    g: &GMap,
    id: EmbeddingId,
    values: &Bound<'_, PyAny>,
) -> Result<(Gathered, Vec<topomech_gmap::Dart>)> {
    let e = g.embedding(id);
    let name = e.name();
    if e.derived().is_some() {
        return Err(Error::EmbeddingInput(format!(
            "embedding '{name}' is derived (recomputed from its source, never written): write its source instead"
        )));
    }
    let ty = e.ty();
    let reps = g.orbit_representatives(e.orbit());
    let n = reps.len();
    let want = value_shape(ty, n);
    let what = format!("values for '{name}'");
    let check_shape = |shape: &[usize]| -> Result<()> {
        if shape == want.as_slice() {
            Ok(())
        } else {
            Err(value_error(format!(
                "{what} ({ty} on {}) must have shape {} = {} (one row per orbit), got {}",
                e.orbit(),
                shape_pattern(&want),
                shape_str(&want),
                shape_str(shape)
            )))
        }
    };
    let gathered = match ty {
        EmbeddingType::I64 => {
            let a = array_arg::<i64>(values, &what, "int64")?;
            check_shape(a.shape())?;
            Gathered::Int(a.as_array().iter().copied().collect())
        }
        EmbeddingType::Bool => {
            let a = array_arg::<bool>(values, &what, "bool_")?;
            check_shape(a.shape())?;
            Gathered::Bool(a.as_array().iter().copied().collect())
        }
        _ => {
            let a = array_arg::<f64>(values, &what, "float64")?;
            check_shape(a.shape())?;
            let flat: Vec<f64> = a.as_array().iter().copied().collect();
            let w = ty.width();
            let bad: Vec<usize> = (0..n)
                .filter(|&k| flat[k * w..(k + 1) * w].iter().any(|x| !x.is_finite()))
                .collect();
            if let Some(&k) = bad.first() {
                return Err(value_error(format!(
                    "{what} must be finite: row {k} (the orbit of dart {}) is {:?}{}",
                    reps[k].0,
                    &flat[k * w..(k + 1) * w],
                    if bad.len() > 1 {
                        format!(" ({} rows are not finite)", bad.len())
                    } else {
                        String::new()
                    }
                )));
            }
            Gathered::Real(flat)
        }
    };
    Ok((gathered, reps))
}

/// The `(name, type, orbit, derived)` of every embedding of `g`, in declaration order.
pub(crate) fn embedding_specs(g: &GMap) -> Vec<(String, String, String, bool)> {
    g.embeddings()
        .iter()
        .map(|e| {
            (
                e.name().to_string(),
                e.ty().to_string(),
                e.orbit().to_string(),
                e.derived().is_some(),
            )
        })
        .collect()
}

/// The counts of `GMap::cell_counts` as a dict.
fn counts_dict<'py>(py: Python<'py>, g: &GMap) -> PyResult<Bound<'py, PyDict>> {
    let c = guard(|| Ok(g.cell_counts()))?;
    let d = PyDict::new(py);
    d.set_item("darts", c.darts)?;
    d.set_item("vertices", c.vertices)?;
    d.set_item("edges", c.edges)?;
    d.set_item("faces", c.faces)?;
    d.set_item("volumes", c.volumes)?;
    d.set_item("components", c.components)?;
    d.set_item("boundary", c.boundary)?;
    Ok(d)
}

/// The build options, or a `ValueError` naming the accepted values.
fn build_options(reorient: bool, pinched: &str, duplicates: &str) -> Result<BuildOptions> {
    let pinched = Pinched::parse(pinched).ok_or_else(|| {
        value_error(format!(
            "pinched must be \"merge\", \"split\" or \"refuse\", got {pinched:?}"
        ))
    })?;
    let duplicates = Duplicates::parse(duplicates).ok_or_else(|| {
        value_error(format!(
            "duplicates must be \"refuse\" or \"merge\", got {duplicates:?}"
        ))
    })?;
    Ok(BuildOptions {
        reorient,
        pinched,
        duplicates,
    })
}

#[pymethods]
impl PyGMap {
    /// Builds a map from a flat mesh: `points` float64 (N, 3); `kinds` the meshio name of each
    /// cell (`polygon`, `tetra`, `hexahedron`, `wedge`, `pyramid`); `offsets` int64 (M + 1,);
    /// `connectivity` int64. Options: `reorient` (turn cells listed the other way round),
    /// `pinched` (`merge`, `split` or `refuse`), `duplicates` (`refuse` or `merge`). Returns
    /// the map and a report `{"reoriented": [cells], "unused_points": [points], "pinched":
    /// [points], "merged_duplicates": [(dropped, kept)], "non_orientable": bool}`. A refused
    /// mesh raises `MeshError` whose `option` is the `(name, value)` that would accept it, or
    /// `None`.
    #[staticmethod]
    #[pyo3(signature = (points, kinds, offsets, connectivity, reorient = true, pinched = "merge", duplicates = "refuse"))]
    #[allow(clippy::too_many_arguments)]
    fn from_flat<'py>(
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        kinds: Vec<String>,
        offsets: &Bound<'py, PyAny>,
        connectivity: &Bound<'py, PyAny>,
        reorient: bool,
        pinched: &str,
        duplicates: &str,
    ) -> PyResult<(PyGMap, Bound<'py, PyDict>)> {
        let opts = guard(|| build_options(reorient, pinched, duplicates))?;
        let mesh = guard(move || mesh_from_flat(points, &kinds, offsets, connectivity))?;
        let (g, report) = py.detach(|| guard(|| Ok(mesh::build(&mesh, &opts)?)))?;
        let d = PyDict::new(py);
        d.set_item("reoriented", report.reoriented)?;
        d.set_item("unused_points", report.unused_points)?;
        d.set_item("pinched", report.pinched)?;
        d.set_item("merged_duplicates", report.merged_duplicates)?;
        d.set_item("non_orientable", report.non_orientable)?;
        Ok((PyGMap::new(g), d))
    }

    /// Loads a map saved by `save` (a `.tmg` file). Raises `FileNotFoundError` naming the
    /// path for a file that does not exist, and `FileFormatError` naming it for one that
    /// cannot be opened or is not a regular file (a directory, `/dev/zero`, a FIFO: refused
    /// before reading), or that is truncated or corrupt.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<PyGMap> {
        let g = py.detach(move || guard(|| Ok(io::load(&path)?)))?;
        Ok(PyGMap::new(g))
    }

    /// Reads a map from the bytes of a `.tmg` file. Raises `FileFormatError` for bytes that are
    /// truncated or corrupt; every count is checked against the bytes left before allocating.
    #[staticmethod]
    fn from_bytes(py: Python<'_>, data: Vec<u8>) -> PyResult<PyGMap> {
        let g = py.detach(move || guard(|| Ok(io::from_bytes(&data)?)))?;
        Ok(PyGMap::new(g))
    }

    /// Saves the map, with its embeddings, to a `.tmg` file (round-trip exact). Raises
    /// `FileNotFoundError` for a folder that does not exist, `FileFormatError` when the file
    /// cannot be written.
    fn save(slf: &Bound<'_, Self>, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let this = shared(slf)?;
        let g = this.map()?;
        py.detach(move || guard(|| Ok(io::save(g, &path)?)))
    }

    /// The bytes of the map's `.tmg` file.
    fn to_bytes<'py>(slf: &Bound<'_, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let this = shared(slf)?;
        let g = this.map()?;
        let b = py.detach(|| guard(|| Ok(io::to_bytes(g))))?;
        Ok(PyBytes::new(py, &b))
    }

    /// The dimension n: 2 (surface) or 3 (volume).
    #[getter]
    fn dimension(slf: &Bound<'_, Self>) -> PyResult<usize> {
        let this = shared(slf)?;
        Ok(this.map()?.dimension())
    }

    /// The number of live darts.
    #[getter]
    fn n_darts(slf: &Bound<'_, Self>) -> PyResult<usize> {
        let this = shared(slf)?;
        Ok(this.map()?.n_darts())
    }

    /// The topology version: it changes whenever a link changes or a dart is added or removed.
    #[getter]
    fn version(slf: &Bound<'_, Self>) -> PyResult<u64> {
        let this = shared(slf)?;
        Ok(this.map()?.version())
    }

    /// Counts of darts, vertices, edges, faces, volumes, connected components and boundary
    /// cells (faces in 3D, edges in 2D).
    fn cell_counts<'py>(slf: &Bound<'_, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let this = shared(slf)?;
        counts_dict(py, this.map()?)
    }

    /// Whether every invariant holds (involutions, cycles, embeddings constant on orbits).
    fn is_valid(slf: &Bound<'_, Self>, py: Python<'_>) -> PyResult<bool> {
        let this = shared(slf)?;
        let g = this.map()?;
        py.detach(|| guard(|| Ok(g.is_valid())))
    }

    /// Each violated invariant, described (empty for a valid map).
    fn violations(slf: &Bound<'_, Self>, py: Python<'_>) -> PyResult<Vec<String>> {
        let this = shared(slf)?;
        let g = this.map()?;
        py.detach(|| guard(|| Ok(g.validate().iter().map(ToString::to_string).collect())))
    }

    /// Vertex positions, float64 (V, 3), in row order (`GMap::vertex_rows`: the input point
    /// order of an imported map; row k is the vertex labelled k by `vertex_labels`).
    fn positions<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let this = shared(slf)?;
        let g = this.map()?;
        let rows = guard(|| {
            let id = g.require("position")?;
            let ty = g.embedding(id).ty();
            if ty != EmbeddingType::Vec3 {
                return Err(Error::EmbeddingInput(format!(
                    "embedding 'position' holds {ty}, expected vec3"
                )));
            }
            let (labels, n) = g.vertex_rows();
            let mut rows = vec![[0.0f64; 3]; n];
            let mut seen = vec![false; n];
            for d in g.darts() {
                let k = labels[d.index()] as usize;
                if !seen[k] {
                    seen[k] = true;
                    let p = g.real(id, d);
                    rows[k] = [p[0], p[1], p[2]];
                }
            }
            Ok(rows)
        })?;
        guard(|| rows_to_array(py, &rows))
    }

    /// The vertex row of each dart, int64 (capacity,): -1 for removed darts.
    fn vertex_labels<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let this = shared(slf)?;
        let g = this.map()?;
        let labels = guard(|| {
            let (labels, _) = g.vertex_rows();
            Ok(labels
                .into_iter()
                .map(|l| if l == u32::MAX { -1 } else { i64::from(l) })
                .collect::<Vec<i64>>())
        })?;
        Ok(labels.into_pyarray(py))
    }

    /// The map as a flat mesh `(points, kinds, offsets, connectivity)`: one point per vertex
    /// orbit, one cell per face (2D) or volume (3D).
    fn to_flat<'py>(slf: &Bound<'_, Self>, py: Python<'py>) -> PyResult<FlatMesh<'py>> {
        let this = shared(slf)?;
        let g = this.map()?;
        let mesh = py.detach(|| guard(|| Ok(mesh::extract(g)?)))?;
        guard(|| mesh_to_flat(py, &mesh))
    }

    /// Every volume of a 3-map as a general polyhedron, faces oriented outward (see the
    /// kernel's `mesh::extract_polyhedra`): `(points, cell_offsets, face_offsets,
    /// connectivity)`, the points as `to_flat` gives them. Raises `MeshError` for a map that
    /// is not 3D, an open or non-orientable volume.
    fn to_polyhedra<'py>(slf: &Bound<'_, Self>, py: Python<'py>) -> PyResult<FlatPolyhedra<'py>> {
        let this = shared(slf)?;
        let g = this.map()?;
        let (points, cells) = py.detach(|| guard(|| Ok(mesh::extract_polyhedra(g)?)))?;
        guard(|| polyhedra_to_flat(py, &points, &cells))
    }

    /// `alpha_i(dart)`; a free link returns the dart itself.
    fn alpha(
        slf: &Bound<'_, Self>,
        i: &Bound<'_, PyAny>,
        dart: &Bound<'_, PyAny>,
    ) -> PyResult<u32> {
        let this = shared(slf)?;
        let g = this.map()?;
        guard(|| {
            let i = dim_arg(g, i)?;
            let d = dart_arg(g, dart)?;
            Ok(g.alpha(i, d).0)
        })
    }

    /// The darts of the orbit of `dart` of type `orbit` (e.g. `"<0,1>"`), `dart` first.
    fn orbit<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
        dart: &Bound<'py, PyAny>,
        orbit: &str,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let this = shared(slf)?;
        let g = this.map()?;
        let darts = guard(|| {
            let d = dart_arg(g, dart)?;
            let o = OrbitType::parse(orbit)?;
            Ok(g.orbit(d, o)
                .into_iter()
                .map(|x| i64::from(x.0))
                .collect::<Vec<i64>>())
        })?;
        Ok(darts.into_pyarray(py))
    }

    /// Sews `a` and `b` along dimension `i`, keeping the map valid; on error nothing changes.
    fn sew(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        i: &Bound<'_, PyAny>,
        a: &Bound<'_, PyAny>,
        b: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        this.mutate(py, |g| {
            let i = dim_arg(g, i)?;
            let a = dart_arg(g, a)?;
            let b = dart_arg(g, b)?;
            Ok(g.sew(i, a, b)?)
        })
    }

    /// Unsews the orbit of `a` along dimension `i`; on error nothing changes.
    fn unsew(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        i: &Bound<'_, PyAny>,
        a: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        this.mutate(py, |g| {
            let i = dim_arg(g, i)?;
            let a = dart_arg(g, a)?;
            Ok(g.unsew(i, a)?)
        })
    }

    /// The embedding `name`, one row per orbit of its orbit type: a tuple `(values, darts,
    /// orbit)`. `darts` is int64 `(n,)`: the smallest dart id of each orbit, increasing (the
    /// rows' order); `orbit` the orbit type as written (`"<1,2,3>"`). `values` has shape
    /// `(n,)` float64 / int64 / bool for `f64` / `i64` / `bool`, `(n, 2)` and `(n, 3)` float64
    /// for `vec2` and `vec3`, `(n, R, C)` float64 for a matrix `matRxC` (row-major). Every
    /// orbit has a value: one never written reads 0 (or false). A stale derived embedding is
    /// recomputed first. Raises `KeyError` for an unknown name, listing the map's embeddings.
    fn embedding<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
        name: &str,
    ) -> PyResult<OrbitValuesPy<'py>> {
        let stale = {
            let this = shared(slf)?;
            let g = this.map()?;
            let id = embedding_key(g, name)?;
            g.is_stale(id)
        };
        if stale {
            let mut this = exclusive(slf)?;
            this.mutate(py, |g| {
                g.refresh_derived();
                Ok(())
            })?;
        }
        let this = shared(slf)?;
        let g = this.map()?;
        let id = embedding_key(g, name)?;
        let v = guard(|| read_orbit_values(g, id))?;
        orbit_values_to_py(py, name, v)
    }

    /// Writes every value of the stored embedding `name`, one row per orbit in the order and
    /// layout that `embedding(name)` returns (same shape; float64 for real types, int64 for
    /// `i64`, bool for `bool`), then recomputes the derived embeddings. Nothing is written
    /// when it raises: `KeyError` for an unknown name (listing the map's embeddings),
    /// `TypeError` for another dtype, `ValueError` for another shape, a non-finite value
    /// (naming the embedding, the row and its dart), a `particle` that is not a vertex
    /// numbering, or a `point_id` or `cell_id` that is not an input numbering (below -1, or
    /// one point for two vertices of one element), `EmbeddingError` for a derived embedding.
    fn set_embedding(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        name: &str,
        values: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        let (id, vals) = {
            let g = this.map()?;
            let id = embedding_key(g, name)?;
            let (vals, reps) = guard(|| orbit_values_arg(g, id, values))?;
            guard(|| check_particle_rows(g, id, &vals, &reps))?;
            guard(|| check_input_numbering(g, id, &vals, &reps))?;
            (id, vals)
        };
        this.mutate(py, |g| Ok(g.set_orbit_values(id, vals.as_column())?))
    }

    /// Every embedding, in declaration order: `(name, type, orbit, derived)` tuples, e.g.
    /// `("position", "vec3", "<1,2,3>", False)`.
    fn embeddings(slf: &Bound<'_, Self>) -> PyResult<Vec<(String, String, String, bool)>> {
        let this = shared(slf)?;
        Ok(embedding_specs(this.map()?))
    }

    /// The names of the embeddings, in declaration order.
    fn embedding_names(slf: &Bound<'_, Self>) -> PyResult<Vec<String>> {
        let this = shared(slf)?;
        let g = this.map()?;
        Ok(g.embeddings()
            .iter()
            .map(|e| e.name().to_string())
            .collect())
    }

    /// `{"name", "type", "orbit", "policy", "derived"}` of an embedding; `derived` is `None`
    /// or `{"source": name, "aggregate": "sum" | "mean" | "count"}`.
    fn embedding_info<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
        name: &str,
    ) -> PyResult<Bound<'py, PyDict>> {
        let this = shared(slf)?;
        let g = this.map()?;
        let id = guard(|| Ok(g.require(name)?))?;
        let e = g.embedding(id);
        let d = PyDict::new(py);
        d.set_item("name", e.name())?;
        d.set_item("type", e.ty().to_string())?;
        d.set_item("orbit", e.orbit().to_string())?;
        d.set_item("policy", e.policy().name())?;
        match e.derived() {
            None => d.set_item("derived", py.None())?,
            Some(der) => {
                let s = PyDict::new(py);
                s.set_item("source", g.embedding(der.source).name())?;
                s.set_item("aggregate", der.aggregate.name())?;
                d.set_item("derived", s)?;
            }
        }
        Ok(d)
    }

    /// The value of the i64 embedding `name` on every dart, int64 `(n_darts,)` (0 on removed
    /// darts), e.g. the `point_id`, `particle` and `cell_id` that a mesh build writes.
    /// Raises `EmbeddingError` for an unknown name or an embedding of another type.
    fn int_embedding<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
        name: &str,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let this = shared(slf)?;
        let g = this.map()?;
        let id = guard(|| Ok(g.require(name)?))?;
        if g.embedding(id).ty() != EmbeddingType::I64 {
            return Err(Error::EmbeddingInput(format!(
                "embedding '{name}' is {}, not i64",
                g.embedding(id).ty()
            ))
            .into());
        }
        let out: Vec<i64> = (0..g.capacity())
            .map(|d| {
                let d = topomech_gmap::Dart(d as u32);
                match g.is_alive(d).then(|| g.value(id, d)) {
                    Some(Ok(topomech_gmap::Value::Int(x))) => x,
                    _ => 0,
                }
            })
            .collect();
        Ok(out.into_pyarray(py))
    }

    /// Bytes used by the topology and every embedding.
    fn memory_bytes(slf: &Bound<'_, Self>) -> PyResult<usize> {
        let this = shared(slf)?;
        Ok(this.map()?.memory_bytes())
    }

    fn __repr__(slf: &Bound<'_, Self>) -> String {
        let Ok(this) = slf.try_borrow() else {
            return "<topomech._core.GMap (busy: in use by another thread)>".to_string();
        };
        if this.poisoned {
            return "<topomech._core.GMap (unusable after an internal error)>".to_string();
        }
        format!(
            "<topomech._core.GMap dimension={} darts={}>",
            this.inner.dimension(),
            this.inner.n_darts()
        )
    }
}
