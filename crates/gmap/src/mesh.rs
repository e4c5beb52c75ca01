//! Building a G-map from points and cells, and back.
//!
//! Surfaces (n = 2) come from polygons of any degree; volumes (n = 3) from tetrahedra,
//! hexahedra, wedges (prisms) and pyramids, in VTK vertex order. Vertex positions go to the
//! `position` embedding (`vec3` on the vertex orbit).

use crate::GMap;

/// The kind of a cell, with VTK's vertex order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CellKind {
    /// A polygon of 3 or more vertices (a 2-cell of a surface).
    Polygon,
    /// A tetrahedron: 4 vertices.
    Tetra,
    /// A hexahedron: 8 vertices, bottom quad then top quad.
    Hexa,
    /// A wedge (triangular prism): 6 vertices, bottom triangle then top triangle.
    Wedge,
    /// A pyramid: 5 vertices, the base quad then the apex.
    Pyramid,
}

impl CellKind {
    /// The number of vertices, `None` for polygons.
    pub const fn n_vertices(self) -> Option<usize> {
        match self {
            CellKind::Polygon => None,
            CellKind::Tetra => Some(4),
            CellKind::Hexa => Some(8),
            CellKind::Wedge => Some(6),
            CellKind::Pyramid => Some(5),
        }
    }

    /// A short name: `polygon`, `tetra`, `hexahedron`, `wedge`, `pyramid` (meshio's names).
    pub const fn name(self) -> &'static str {
        match self {
            CellKind::Polygon => "polygon",
            CellKind::Tetra => "tetra",
            CellKind::Hexa => "hexahedron",
            CellKind::Wedge => "wedge",
            CellKind::Pyramid => "pyramid",
        }
    }

    /// Parses the names of [`CellKind::name`].
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "polygon" => CellKind::Polygon,
            "tetra" => CellKind::Tetra,
            "hexahedron" => CellKind::Hexa,
            "wedge" => CellKind::Wedge,
            "pyramid" => CellKind::Pyramid,
            _ => return None,
        })
    }

    /// The cell's dimension: 2 for polygons, 3 otherwise.
    pub const fn dimension(self) -> usize {
        match self {
            CellKind::Polygon => 2,
            _ => 3,
        }
    }
}

/// Points and cells: the usual mesh representation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex coordinates.
    pub points: Vec<[f64; 3]>,
    /// Each cell's kind.
    pub kinds: Vec<CellKind>,
    /// Each cell's vertex indices into `points`.
    pub cells: Vec<Vec<usize>>,
}

/// Options for [`build`].
#[derive(Clone, Debug, Default)]
pub struct BuildOptions {
    /// Re-orient inverted elements (and, in 2D, faces whose orientation disagrees with their
    /// neighbours) instead of refusing them; what changed is in the report.
    pub reorient: bool,
}

/// What [`build`] changed or noticed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildReport {
    /// Cells whose vertex order was reversed (only with `reorient`).
    pub reoriented: Vec<usize>,
    /// Points used by no cell: they are not in the map.
    pub unused_points: Vec<usize>,
}

/// Why a mesh cannot become a G-map; every variant names the element or vertex.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// No cells.
    #[error("the mesh has no cells")]
    Empty,
    /// Cells of both dimensions.
    #[error("cell {cell} is a {kind} but cell 0 is of dimension {dim}: a mesh is all surface or all volume")]
    MixedDimension {
        /// The offending cell.
        cell: usize,
        /// Its kind's name.
        kind: &'static str,
        /// The dimension of cell 0.
        dim: usize,
    },
    /// A vertex index past the points.
    #[error("cell {cell} refers to vertex {vertex}, but there are only {n_points} points")]
    VertexOutOfRange {
        /// The cell.
        cell: usize,
        /// The index.
        vertex: usize,
        /// Number of points.
        n_points: usize,
    },
    /// Wrong number of vertices for the kind.
    #[error("cell {cell} is a {kind} with {got} vertices, expected {expected}")]
    VertexCount {
        /// The cell.
        cell: usize,
        /// Its kind's name.
        kind: &'static str,
        /// Vertices given.
        got: usize,
        /// Vertices expected.
        expected: usize,
    },
    /// A point with a NaN or infinite coordinate.
    #[error("point {point} has a non-finite coordinate {coords:?}")]
    NonFinite {
        /// The point.
        point: usize,
        /// Its coordinates.
        coords: [f64; 3],
    },
    /// A vertex twice in one cell, or zero area / volume.
    #[error("cell {cell} is degenerate: {why}")]
    Degenerate {
        /// The cell.
        cell: usize,
        /// What is wrong.
        why: String,
    },
    /// Negative volume (3D), without `reorient`.
    #[error("cell {cell} ({kind}) is inverted (signed volume {volume:.3e}); pass reorient=True to fix it")]
    Inverted {
        /// The cell.
        cell: usize,
        /// Its kind's name.
        kind: &'static str,
        /// Its signed volume.
        volume: f64,
    },
    /// An edge (2D) or face (3D) shared by three or more cells.
    #[error("non-manifold {what} {vertices:?}: shared by cells {cells:?} (at most 2 allowed)")]
    NonManifold {
        /// `edge` or `face`.
        what: &'static str,
        /// Its vertices.
        vertices: Vec<usize>,
        /// The cells sharing it.
        cells: Vec<usize>,
    },
    /// Two neighbouring faces of a surface with opposite orientations, without `reorient`.
    #[error("faces {a} and {b} have opposite orientations across edge ({u}, {v}); pass reorient=True to fix it")]
    Orientation {
        /// First face.
        a: usize,
        /// Second face.
        b: usize,
        /// Edge end.
        u: usize,
        /// Edge end.
        v: usize,
    },
    /// Two cells share a face's vertices but not its edges (e.g. a quad split two ways).
    #[error("cells {a} and {b} share vertices {vertices:?} but their faces do not match")]
    NonConforming {
        /// First cell.
        a: usize,
        /// Second cell.
        b: usize,
        /// The shared vertices.
        vertices: Vec<usize>,
    },
    /// A map that cannot be turned back into cells.
    #[error("cannot extract cells: {0}")]
    Extract(String),
}

/// Builds the G-map of a mesh. See the module docs.
pub fn build(mesh: &Mesh, opts: &BuildOptions) -> Result<(GMap, BuildReport), MeshError> {
    let _ = (mesh, opts);
    todo!()
}

/// Turns a map built by [`build`] (or changed since) back into points and cells: one point per
/// vertex orbit (numbered by [`GMap::orbit_labels`]), one cell per face (2D) or volume (3D).
pub fn extract(g: &GMap) -> Result<Mesh, MeshError> {
    let _ = g;
    todo!()
}
