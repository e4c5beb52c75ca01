//! Building a G-map from points and cells, and back.
//!
//! Surfaces (n = 2) come from polygons of any degree; volumes (n = 3) from tetrahedra,
//! hexahedra, wedges (prisms) and pyramids, in VTK vertex order. Besides the vertex positions
//! (`position`, `vec3` on the vertex orbit), [`build`] writes the input numbering onto the map:
//! `point_id` (i64, vertex orbit: the input point), `particle` (i64, vertex orbit: the row of
//! the vertex in per-vertex arrays) and `cell_id` (i64, element orbit: the input cell).
//!
//! What [`build`] accepts and refuses:
//! - cells listed with the opposite orientation are turned (by default, [`BuildOptions::reorient`])
//!   and listed in [`BuildReport::reoriented`]; a non-orientable surface is accepted;
//! - pinched points (cells touching only at a point) become one particle by default
//!   ([`Pinched`]);
//! - duplicate cells are refused, or dropped with [`Duplicates::Merge`];
//! - cells whose area or volume overflows f64 (or underflows: see [`TINY_SIZE`]) are refused
//!   as such, not as degenerate;
//! - degenerate, twisted (Jacobian changing sign between corners, self-intersecting polygon),
//!   folded (two cells on the same side of their shared face) cells and non-conforming
//!   interfaces (mismatched diagonals, hanging nodes) are refused, naming every offender;
//! - cells whose interiors overlap without sharing a face (3D; in a planar 2D mesh, an edge)
//!   are refused ([`MeshError::Overlapping`]); non-planar surfaces are not checked for it.

mod conform;
mod overlap;

use crate::embedding::Column;
use crate::{Dart, EmbeddingType, GMap, OrbitType, Policy};

/// A fast hasher for small integer keys (the multiply-rotate hash of rustc's `FxHasher`):
/// the maps keyed by point indices here are built from the user's own mesh, so the
/// denial-of-service resistance of the default hasher buys nothing.
#[derive(Default, Clone, Copy)]
pub(crate) struct FxHasher(u64);

impl std::hash::Hasher for FxHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.add(u64::from(b));
        }
    }
    fn write_u32(&mut self, i: u32) {
        self.add(u64::from(i));
    }
    fn write_u64(&mut self, i: u64) {
        self.add(i);
    }
    fn write_usize(&mut self, i: usize) {
        self.add(i as u64);
    }
}

impl FxHasher {
    #[inline]
    fn add(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// A hash map with [`FxHasher`].
pub(crate) type FxMap<K, V> =
    std::collections::HashMap<K, V, std::hash::BuildHasherDefault<FxHasher>>;

fn fx_map<K, V>(capacity: usize) -> FxMap<K, V> {
    FxMap::with_capacity_and_hasher(capacity, std::hash::BuildHasherDefault::default())
}

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

    /// The name of a cell of this kind with `n` vertices, as a message names it: a polygon
    /// by its usual name where it has one (`triangle`, `quad`), else [`CellKind::name`].
    pub const fn name_of(self, n: usize) -> &'static str {
        match (self, n) {
            (CellKind::Polygon, 3) => "triangle",
            (CellKind::Polygon, 4) => "quad",
            _ => self.name(),
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

/// What to do with a pinched point: one whose cells touch only at it (2D: not joined through
/// edges; 3D: not joined through faces), so that it becomes two or more vertex orbits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Pinched {
    /// One particle: every orbit of the point shares its `particle` row (the default, as in
    /// peer simulators).
    #[default]
    Merge,
    /// One particle per orbit: the orbit with the smallest dart keeps the point's row, the
    /// others get new rows appended after the used points.
    Split,
    /// Refuse the mesh, listing every pinched point.
    Refuse,
}

impl Pinched {
    /// `merge`, `split`, `refuse`.
    pub const fn name(self) -> &'static str {
        match self {
            Pinched::Merge => "merge",
            Pinched::Split => "split",
            Pinched::Refuse => "refuse",
        }
    }

    /// Parses the names of [`Pinched::name`].
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "merge" => Pinched::Merge,
            "split" => Pinched::Split,
            "refuse" => Pinched::Refuse,
            _ => return None,
        })
    }
}

/// What to do with duplicate cells (the same vertex set as an earlier cell, in any order).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Duplicates {
    /// Refuse the mesh, listing every duplicate pair (the default: a duplicate silently
    /// doubles the mass).
    #[default]
    Refuse,
    /// Keep the first cell of each vertex set and drop the others (listed in
    /// [`BuildReport::merged_duplicates`]).
    Merge,
}

impl Duplicates {
    /// `refuse`, `merge`.
    pub const fn name(self) -> &'static str {
        match self {
            Duplicates::Refuse => "refuse",
            Duplicates::Merge => "merge",
        }
    }

    /// Parses the names of [`Duplicates::name`].
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "refuse" => Duplicates::Refuse,
            "merge" => Duplicates::Merge,
            _ => return None,
        })
    }
}

/// Options for [`build`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BuildOptions {
    /// Turn cells listed with the opposite orientation (3D: negative signed volume; 2D: faces
    /// whose orientation disagrees with their neighbours) instead of refusing them; what
    /// changed is in the report. Default `true`.
    pub reorient: bool,
    /// Pinched points: see [`Pinched`]. Default [`Pinched::Merge`].
    pub pinched: Pinched,
    /// Duplicate cells: see [`Duplicates`]. Default [`Duplicates::Refuse`].
    pub duplicates: Duplicates,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            reorient: true,
            pinched: Pinched::Merge,
            duplicates: Duplicates::Refuse,
        }
    }
}

/// What [`build`] changed or noticed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildReport {
    /// Cells whose vertex order was reversed (input cell indices, increasing).
    pub reoriented: Vec<usize>,
    /// Points used by no cell: they are not in the map.
    pub unused_points: Vec<usize>,
    /// Pinched points (input point indices, increasing): cells touch only at them.
    pub pinched: Vec<usize>,
    /// Duplicate cells dropped with [`Duplicates::Merge`]: (dropped cell, the earlier cell it
    /// duplicated), by increasing dropped cell.
    pub merged_duplicates: Vec<(usize, usize)>,
    /// A surface with a component that cannot be oriented (a Moebius strip): accepted as a
    /// G-map, with its faces' orientations left as found by a breadth-first walk.
    pub non_orientable: bool,
}

/// The end of the messages refusing non-conforming interfaces and overlapping cells: a run's
/// own output can hold them, its pieces having moved after a cut (no contact between bodies is
/// modelled), and a mesh file cannot say they are separate bodies (QA: `final.vtu` refused).
const SEPARATE_BODIES: &str = "; if these cells belong to separate bodies that touch or \
    interpenetrate (such as the pieces of a cut after they moved: topomech models no contact \
    between bodies), a mesh file cannot say so: read the map saved as .tmg instead, which \
    keeps the bodies apart (`topomech run --save-map` writes final.tmg beside final.vtu \
    after a cut; in Python, GMap.save)";

/// A pair of faces of a non-conforming interface (see [`MeshError::NonConforming`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FacePair {
    /// The first cell (input index).
    pub a: usize,
    /// Its face (2D: edge), as input point indices.
    pub face_a: Vec<usize>,
    /// The second cell (input index).
    pub b: usize,
    /// Its face (2D: edge), as input point indices.
    pub face_b: Vec<usize>,
    /// What is wrong: `faces do not match`, `overlapping faces`, `hanging node N`.
    pub why: String,
}

/// How many offenders a message shows before "and N more".
pub const SHOWN: usize = 20;

/// The first [`SHOWN`] items formatted by `f`, joined by "; ", then "; and N more".
fn listed<T>(items: &[T], f: impl Fn(&T) -> String) -> String {
    let mut out = items
        .iter()
        .take(SHOWN)
        .map(f)
        .collect::<Vec<_>>()
        .join("; ");
    if items.len() > SHOWN {
        out.push_str("; and ");
        out.push_str(&(items.len() - SHOWN).to_string());
        out.push_str(" more");
    }
    out
}

/// Why a mesh cannot become a G-map; every variant names the cells or points (input
/// indices), all of them (messages show the first [`SHOWN`]). Messages name no option: the
/// option that would accept the mesh is [`MeshError::option`], and callers spell it in their
/// user's syntax.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// No cells.
    #[error("the mesh has no cells")]
    Empty,
    /// Not one kind per cell.
    #[error("{kinds} cell kinds given for {cells} cells")]
    KindCount {
        /// Kinds given.
        kinds: usize,
        /// Cells given.
        cells: usize,
    },
    /// Cells of both dimensions.
    #[error("{} cell(s) of another dimension than cell 0 (dimension {dim}): {}; a mesh is all surface or all volume", cells.len(), listed(cells, |(c, k)| format!("cell {c} is a {k}")))]
    MixedDimension {
        /// (cell, its kind's name) for each cell whose dimension differs from cell 0's.
        cells: Vec<(usize, &'static str)>,
        /// The dimension of cell 0.
        dim: usize,
    },
    /// Vertex indices past the points.
    #[error("{} vertex index(es) out of range: {}; there are only {n_points} points", cells.len(), listed(cells, |(c, v)| format!("cell {c} refers to vertex {v}")))]
    VertexOutOfRange {
        /// (cell, vertex index) for each index past the points.
        cells: Vec<(usize, usize)>,
        /// Number of points.
        n_points: usize,
    },
    /// Wrong numbers of vertices for the kinds.
    #[error("{} cell(s) with a wrong number of vertices: {}", cells.len(), listed(cells, |(c, k, got, want)| format!("cell {c} is a {k} with {got} vertices, expected {}{want}", if *k == "polygon" { "at least " } else { "" })))]
    VertexCount {
        /// (cell, its kind's name, vertices given, vertices expected) for each such cell.
        cells: Vec<(usize, &'static str, usize, usize)>,
    },
    /// Points with a NaN or infinite coordinate.
    #[error("{} point(s) with a non-finite coordinate: {}", points.len(), listed(points, |(p, c)| format!("point {p} has a non-finite coordinate {c:?}")))]
    NonFinite {
        /// Each point and its coordinates.
        points: Vec<(usize, [f64; 3])>,
    },
    /// Cells with a vertex twice, or zero area / volume.
    #[error("{} degenerate cell(s): {}", cells.len(), listed(cells, |(c, why)| format!("cell {c} is degenerate ({why})")))]
    Degenerate {
        /// Each cell and what is wrong.
        cells: Vec<(usize, String)>,
    },
    /// Cells whose area (2D) or volume (3D) is beyond what f64 holds: finite coordinates so
    /// far apart that `extent^n` overflows, or so close that it underflows below
    /// [`TINY_SIZE`] (where the relative degeneracy test loses its precision). Not
    /// degenerate: the remedy is to scale the coordinates.
    #[error("{} cell(s) too large or too small for f64 (scale the coordinates): {}", cells.len(), listed(cells, |(c, k, why)| format!("cell {c} ({k}): {why}")))]
    Overflow {
        /// Each cell, its kind's name and what overflows or underflows.
        cells: Vec<(usize, &'static str, String)>,
    },
    /// Cells with negative volume (3D), refused when `reorient` is off.
    #[error("{} inverted cell(s) (negative signed volume): {}", cells.len(), listed(cells, |(c, k, v)| format!("cell {c} ({k}) is inverted (signed volume {v:.3e})")))]
    Inverted {
        /// Each cell, its kind's name and its signed volume.
        cells: Vec<(usize, &'static str, f64)>,
    },
    /// Neighbouring faces of a surface with opposite orientations, refused when `reorient`
    /// is off.
    #[error("{} pair(s) of neighbouring faces with opposite orientations: {}", pairs.len(), listed(pairs, |(a, b, u, v)| format!("faces {a} and {b} across edge ({u}, {v})")))]
    Orientation {
        /// (face, face, edge end, edge end).
        pairs: Vec<(usize, usize, usize, usize)>,
    },
    /// Cells whose Jacobian changes sign between corners (hexahedra, wedges, pyramids) or
    /// polygons whose sides cross (a bow-tie quad).
    #[error("{} twisted or self-intersecting cell(s): {}", cells.len(), listed(cells, |(c, k, why)| format!("cell {c} ({k}): {why}")))]
    Twisted {
        /// Each cell, its kind's name and what is wrong.
        cells: Vec<(usize, &'static str, String)>,
    },
    /// Two cells on the same side of their shared face (3D) or edge (2D planar meshes).
    #[error("{} folded pair(s) of cells (on the same side of their shared {what}): {}", pairs.len(), listed(pairs, |(a, b, f)| format!("cells {a} and {b} at {what} {f:?}")))]
    Folded {
        /// `face` or `edge`.
        what: &'static str,
        /// (cell, cell, shared face's or edge's points).
        pairs: Vec<(usize, usize, Vec<usize>)>,
    },
    /// Cells with the same vertex set as an earlier cell.
    #[error("{} duplicate cell(s) (the same vertices as an earlier cell): {}", pairs.len(), listed(pairs, |(d, f)| format!("cell {d} duplicates cell {f}")))]
    Duplicate {
        /// (duplicate cell, the earlier cell).
        pairs: Vec<(usize, usize)>,
    },
    /// Pinched points, refused with [`Pinched::Refuse`].
    #[error("{} pinched point(s) (their cells touch only at the point): {}", points.len(), listed(points, |(p, c)| format!("point {p} (cells {c:?})")))]
    Pinched {
        /// Each point and the cells around it.
        points: Vec<(usize, Vec<usize>)>,
    },
    /// Edges (2D) or faces (3D) shared by three or more cells.
    #[error("{} non-manifold {what}(s) ({why}): {}", items.len(), listed(items, |(v, c)| format!("non-manifold {what} {v:?} in cells {c:?}")))]
    NonManifold {
        /// What the rule is.
        why: &'static str,
        /// `edge` or `face`.
        what: &'static str,
        /// Each edge or face (its points, increasing) and the cells sharing it, by points.
        items: Vec<(Vec<usize>, Vec<usize>)>,
    },
    /// Non-conforming interfaces: faces (2D: edges) of two cells that share points but do not
    /// match, or that overlap (mismatched diagonals, hanging nodes).
    #[error("{} non-conforming interface(s): {}{SEPARATE_BODIES}", pairs.len(), listed(pairs, |p| format!("face {:?} of cell {} against face {:?} of cell {} ({})", p.face_a, p.a, p.face_b, p.b, p.why)))]
    NonConforming {
        /// Each pair of faces.
        pairs: Vec<FacePair>,
    },
    /// Cells whose interiors intersect without sharing a face (3D) or an edge (planar 2D
    /// meshes): two interpenetrating tetrahedra, a cell inside another, a triangle lying
    /// across others. Found by the separating axis theorem on simplices; see
    /// `mesh/overlap.rs`.
    #[error("{} overlapping pair(s) of cells (their interiors intersect): {}{SEPARATE_BODIES}", pairs.len(), listed(pairs, |(a, b)| format!("cells {a} and {b}")))]
    Overlapping {
        /// (cell, cell), the smaller index first, sorted.
        pairs: Vec<(usize, usize)>,
    },
    /// A map that cannot be turned back into cells.
    #[error("cannot extract cells: {0}")]
    Extract(String),
}

impl MeshError {
    /// The option and value that would make [`build`] accept the mesh, when there is one:
    /// `("reorient", "true")`, `("pinched", "split")`, `("duplicates", "merge")`.
    pub fn option(&self) -> Option<(&'static str, &'static str)> {
        match self {
            MeshError::Inverted { .. } | MeshError::Orientation { .. } => {
                Some(("reorient", "true"))
            }
            MeshError::Pinched { .. } => Some(("pinched", "split")),
            MeshError::Duplicate { .. } => Some(("duplicates", "merge")),
            _ => None,
        }
    }
}

/// The outward-oriented faces of each 3D kind, as local vertex lists (positive cells).
fn local_faces(kind: CellKind) -> &'static [&'static [usize]] {
    match kind {
        CellKind::Tetra => &[&[0, 2, 1], &[0, 1, 3], &[1, 2, 3], &[0, 3, 2]],
        CellKind::Hexa => &[
            &[0, 3, 2, 1],
            &[4, 5, 6, 7],
            &[0, 1, 5, 4],
            &[1, 2, 6, 5],
            &[2, 3, 7, 6],
            &[3, 0, 4, 7],
        ],
        // Gmsh's and VTK's positive prism: the base (0, 1, 2) turns counter-clockwise seen from
        // the top (3, 4, 5), like the base of a hexahedron or a pyramid
        CellKind::Wedge => &[
            &[0, 2, 1],
            &[3, 4, 5],
            &[0, 1, 4, 3],
            &[1, 2, 5, 4],
            &[2, 0, 3, 5],
        ],
        CellKind::Pyramid => &[
            &[0, 3, 2, 1],
            &[0, 1, 4],
            &[1, 2, 4],
            &[2, 3, 4],
            &[3, 0, 4],
        ],
        CellKind::Polygon => &[],
    }
}

/// The corners of each 3D kind: (corner, a, b, c) with the triple product
/// `(p_a - p_corner) . ((p_b - p_corner) x (p_c - p_corner))` positive at every corner of a
/// positive, untwisted cell (the corner Jacobians). For a pyramid, the four base tetrahedra.
fn corners(kind: CellKind) -> &'static [[usize; 4]] {
    match kind {
        CellKind::Hexa => &[
            [0, 1, 3, 4],
            [1, 2, 0, 5],
            [2, 3, 1, 6],
            [3, 0, 2, 7],
            [4, 7, 5, 0],
            [5, 4, 6, 1],
            [6, 5, 7, 2],
            [7, 6, 4, 3],
        ],
        CellKind::Wedge => &[
            [0, 1, 2, 3],
            [1, 2, 0, 4],
            [2, 0, 1, 5],
            [3, 5, 4, 0],
            [4, 3, 5, 1],
            [5, 4, 3, 2],
        ],
        CellKind::Pyramid => &[[0, 1, 3, 4], [1, 2, 0, 4], [2, 3, 1, 4], [3, 0, 2, 4]],
        CellKind::Tetra => &[[0, 1, 2, 3]],
        CellKind::Polygon => &[],
    }
}

/// The vertex order of a cell of the same kind with the opposite orientation.
fn reversal(kind: CellKind) -> &'static [usize] {
    match kind {
        CellKind::Tetra => &[0, 2, 1, 3],
        CellKind::Hexa => &[4, 5, 6, 7, 0, 1, 2, 3],
        CellKind::Wedge => &[3, 4, 5, 0, 1, 2],
        CellKind::Pyramid => &[0, 3, 2, 1, 4],
        CellKind::Polygon => &[],
    }
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The Euclidean norm, scaled by the largest component so that its square neither
/// overflows nor underflows (finite and non-zero for every finite non-zero vector).
pub(crate) fn norm(a: [f64; 3]) -> f64 {
    let m = a[0].abs().max(a[1].abs()).max(a[2].abs());
    if m == 0.0 || !m.is_finite() {
        return m;
    }
    let b = [a[0] / m, a[1] / m, a[2] / m];
    m * dot(b, b).sqrt()
}

/// The signed volume of a 3D cell (positive when its vertices are in VTK order), computed by
/// fanning each face to the cell's centroid.
pub fn signed_volume(kind: CellKind, verts: &[usize], points: &[[f64; 3]]) -> f64 {
    let p = |k: usize| points[verts[k]];
    let mut c = [0.0; 3];
    for &v in verts {
        for a in 0..3 {
            c[a] += points[v][a] / verts.len() as f64;
        }
    }
    let mut vol = 0.0;
    for face in local_faces(kind) {
        for t in 1..face.len() - 1 {
            let (a, b, d) = (
                sub(p(face[0]), c),
                sub(p(face[t]), c),
                sub(p(face[t + 1]), c),
            );
            vol += dot(a, cross(b, d)) / 6.0;
        }
    }
    vol
}

/// The corner Jacobians (triple products, see [`corners`]) of a 3D cell, in corner order.
pub fn corner_jacobians(kind: CellKind, verts: &[usize], points: &[[f64; 3]]) -> Vec<f64> {
    corners(kind)
        .iter()
        .map(|&[c, a, b, d]| {
            let o = points[verts[c]];
            dot(
                sub(points[verts[a]], o),
                cross(sub(points[verts[b]], o), sub(points[verts[d]], o)),
            )
        })
        .collect()
}

/// The Newell normal of a polygon (twice its vector area), computed on the coordinates
/// relative to its first vertex: translation changes nothing, and the products are of the
/// order of the polygon's extent squared, whatever the magnitude of its coordinates.
pub(crate) fn polygon_normal(verts: &[usize], points: &[[f64; 3]]) -> [f64; 3] {
    let mut n = [0.0; 3];
    let o = points[verts[0]];
    for k in 0..verts.len() {
        let a = sub(points[verts[k]], o);
        let b = sub(points[verts[(k + 1) % verts.len()]], o);
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    n
}

pub(crate) fn max_edge(verts: &[usize], points: &[[f64; 3]]) -> f64 {
    let mut m: f64 = 0.0;
    for (k, &a) in verts.iter().enumerate() {
        for &b in &verts[k + 1..] {
            m = m.max(norm(sub(points[a], points[b])));
        }
    }
    m
}

/// Relative size under which an area or volume counts as zero.
const DEGENERATE: f64 = 1e-12;

/// The smallest `extent^n` of a cell (n its dimension) the geometric checks handle: below it,
/// `DEGENERATE * extent^n` is subnormal and a well-shaped cell could not be told from a flat
/// one (`f64::MIN_POSITIVE / DEGENERATE`, about 2.2e-296).
pub const TINY_SIZE: f64 = f64::MIN_POSITIVE / DEGENERATE;

/// The largest difference of one coordinate between two points of a cell: the cell's
/// extent, computed without squares, so that it is finite for any finite coordinates whose
/// differences are, and zero only when every point of the cell is at one position.
pub(crate) fn extent(verts: &[usize], points: &[[f64; 3]]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for &v in verts {
        for ((l, h), &x) in lo.iter_mut().zip(&mut hi).zip(&points[v]) {
            *l = l.min(x);
            *h = h.max(x);
        }
    }
    (0..3).fold(0.0, |e: f64, a| e.max(hi[a] - lo[a]))
}

/// Why the area (`dim` 2) or volume (`dim` 3) of a cell of extent `ext` is out of f64's
/// range, if it is: the squares and triple products of its edge vectors (up to about
/// `6 extent^n`, with the factor 8 of margin) overflow, or `extent^n` is below [`TINY_SIZE`].
fn out_of_range(ext: f64, dim: usize, verts: &[usize], points: &[[f64; 3]]) -> Option<String> {
    let what = if dim == 2 { "area" } else { "volume" };
    let n = if dim == 2 { 2 } else { 3 };
    let size = ext.powi(n);
    let magnitude = verts
        .iter()
        .flat_map(|&v| points[v])
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    if !(8.0 * size).is_finite() {
        Some(format!(
            "its {what} overflows f64 (extent {ext:.3e}, coordinates up to {magnitude:.3e})"
        ))
    } else if ext > 0.0 && size < TINY_SIZE {
        Some(format!(
            "its {what} underflows f64 (extent {ext:.3e}: extent^{n} = {size:.3e} is below {TINY_SIZE:.1e})"
        ))
    } else {
        None
    }
}

/// Relative size (of `l^3`) above which corner Jacobians of both signs make a twisted cell.
const TWIST: f64 = 1e-10;

/// `verts` reordered to the opposite orientation.
pub fn reversed(kind: CellKind, verts: &[usize]) -> Vec<usize> {
    if kind == CellKind::Polygon {
        verts.iter().rev().copied().collect()
    } else {
        reversal(kind).iter().map(|&k| verts[k]).collect()
    }
}

/// Checks indices, vertex counts and finiteness; returns the dimension.
fn check_cells(mesh: &Mesh) -> Result<usize, MeshError> {
    if mesh.kinds.is_empty() {
        return Err(MeshError::Empty);
    }
    if mesh.kinds.len() != mesh.cells.len() {
        return Err(MeshError::KindCount {
            kinds: mesh.kinds.len(),
            cells: mesh.cells.len(),
        });
    }
    let dim = mesh.kinds[0].dimension();
    let mut out_of_range = Vec::new();
    let mut other_dim = Vec::new();
    let mut bad_counts = Vec::new();
    for (c, (&kind, verts)) in mesh.kinds.iter().zip(&mesh.cells).enumerate() {
        if kind.dimension() != dim {
            // a polygon by its usual name where it has one (a triangle, not "a polygon")
            other_dim.push((c, kind.name_of(verts.len())));
        }
        let expected = kind.n_vertices();
        let bad_count = match expected {
            Some(k) => verts.len() != k,
            None => verts.len() < 3,
        };
        if bad_count {
            bad_counts.push((c, kind.name(), verts.len(), expected.unwrap_or(3)));
        }
        for &v in verts {
            if v >= mesh.points.len() {
                out_of_range.push((c, v));
            }
        }
    }
    if !other_dim.is_empty() {
        return Err(MeshError::MixedDimension {
            cells: other_dim,
            dim,
        });
    }
    if !bad_counts.is_empty() {
        return Err(MeshError::VertexCount { cells: bad_counts });
    }
    if !out_of_range.is_empty() {
        return Err(MeshError::VertexOutOfRange {
            cells: out_of_range,
            n_points: mesh.points.len(),
        });
    }
    let bad: Vec<(usize, [f64; 3])> = mesh
        .points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.iter().any(|x| !x.is_finite()))
        .map(|(i, p)| (i, *p))
        .collect();
    if !bad.is_empty() {
        return Err(MeshError::NonFinite { points: bad });
    }
    Ok(dim)
}

/// The kept cells (input indices), dropping or refusing duplicate vertex sets.
fn dedupe(
    mesh: &Mesh,
    opts: &BuildOptions,
    report: &mut BuildReport,
) -> Result<Vec<usize>, MeshError> {
    // cells of up to 8 points (every volume kind, triangles, quads) keyed without allocation
    let mut small: FxMap<[u32; 8], usize> = fx_map(mesh.cells.len());
    let mut large: FxMap<Vec<u32>, usize> = fx_map(0);
    let mut pairs = Vec::new();
    let mut kept = Vec::with_capacity(mesh.cells.len());
    for (c, verts) in mesh.cells.iter().enumerate() {
        let first = if verts.len() <= 8 {
            let mut key = [u32::MAX; 8];
            for (k, &v) in verts.iter().enumerate() {
                key[k] = v as u32;
            }
            key.sort_unstable();
            *small.entry(key).or_insert(c)
        } else {
            let mut key: Vec<u32> = verts.iter().map(|&v| v as u32).collect();
            key.sort_unstable();
            *large.entry(key).or_insert(c)
        };
        if first == c {
            kept.push(c);
        } else {
            pairs.push((c, first));
        }
    }
    if pairs.is_empty() {
        return Ok(kept);
    }
    match opts.duplicates {
        Duplicates::Refuse => Err(MeshError::Duplicate { pairs }),
        Duplicates::Merge => {
            report.merged_duplicates = pairs;
            Ok(kept)
        }
    }
}

/// Whether a polygon's sides cross, in its best-fit plane: the first crossing pair of
/// non-adjacent sides, as `(i, j)` side indices (side `i` runs from vertex `i` to `i + 1`).
fn polygon_crossing(verts: &[usize], points: &[[f64; 3]]) -> Option<(usize, usize)> {
    let k = verts.len();
    if k < 4 {
        return None;
    }
    // the plane: the Newell normal, or for a polygon whose signed area cancels (a bow-tie)
    // the largest fan triangle's normal
    let l = max_edge(verts, points);
    let mut n = polygon_normal(verts, points);
    if norm(n) <= 1e-6 * l * l {
        let o = points[verts[0]];
        for j in 1..k - 1 {
            let t = cross(sub(points[verts[j]], o), sub(points[verts[j + 1]], o));
            if norm(t) > norm(n) {
                n = t;
            }
        }
    }
    if norm(n) <= DEGENERATE * l * l {
        return None;
    }
    let drop = (0..3)
        .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
        .unwrap_or(2);
    let (x, y) = ((drop + 1) % 3, (drop + 2) % 3);
    let q: Vec<[f64; 2]> = verts
        .iter()
        .map(|&v| [points[v][x], points[v][y]])
        .collect();
    let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let eps = 1e-12 * l * l;
    for i in 0..k {
        for j in i + 2..k {
            if i == 0 && j == k - 1 {
                continue;
            }
            let (a, b) = (q[i], q[(i + 1) % k]);
            let (c, d) = (q[j], q[(j + 1) % k]);
            let (o1, o2) = (orient(a, b, c), orient(a, b, d));
            let (o3, o4) = (orient(c, d, a), orient(c, d, b));
            let strict = |s: f64, t: f64| (s > eps && t < -eps) || (s < -eps && t > eps);
            if strict(o1, o2) && strict(o3, o4) {
                return Some((i, j));
            }
        }
    }
    None
}

/// Why a simple polygon cannot be an element, or None: it must be star-shaped around its
/// vertex centroid, every side seen from the front (the fan of triangles from that centroid,
/// which the rules use for areas, masses and face forces, covers the polygon exactly once only
/// then; a concave quad whose reflex corner hides a side would get a wrong area and mass). In
/// the polygon's plane (its Newell normal), with the tolerance of a twist. A corner of exactly
/// 180 degrees (a vertex on a side, as where a polygon meets two smaller neighbours) is fine.
fn polygon_fold(verts: &[usize], points: &[[f64; 3]]) -> Option<String> {
    let k = verts.len();
    // the unit normal: products stay of the order of extent^2, so that any cell whose area
    // is finite is checked without overflow (`n_len > 0`: flat polygons are refused before)
    let n = polygon_normal(verts, points);
    let n_len = norm(n);
    let n = [n[0] / n_len, n[1] / n_len, n[2] / n_len];
    let l = max_edge(verts, points);
    let eps = TWIST * l * l;
    let p = |j: usize| points[verts[j % k]];
    let mut cf = [0.0; 3];
    for &v in verts {
        for (c, x) in cf.iter_mut().zip(points[v]) {
            *c += x / k as f64;
        }
    }
    for j in 0..k {
        if dot(cross(sub(p(j), cf), sub(p(j + 1), cf)), n) <= eps {
            return Some(format!(
                "not star-shaped around its vertex centroid: side ({}, {}) is seen from behind, so its area and mass would be wrong (split it into triangles)",
                verts[j],
                verts[(j + 1) % k]
            ));
        }
    }
    None
}

/// Per-cell geometry: degenerate and twisted cells are refused (all listed); 3D cells with a
/// negative volume are turned (or refused without `reorient`). Returns the oriented cells.
fn check_geometry(
    mesh: &Mesh,
    ids: &[usize],
    dim: usize,
    opts: &BuildOptions,
    report: &mut BuildReport,
) -> Result<Vec<Vec<usize>>, MeshError> {
    let points = &mesh.points;
    let mut degenerate = Vec::new();
    let mut overflow = Vec::new();
    let mut twisted = Vec::new();
    let mut inverted = Vec::new();
    let mut cells = Vec::with_capacity(ids.len());
    for &c in ids {
        let (kind, verts) = (mesh.kinds[c], &mesh.cells[c]);
        if let Some(v) = verts
            .iter()
            .enumerate()
            .find(|&(k, v)| verts[k + 1..].contains(v))
            .map(|(_, v)| *v)
        {
            degenerate.push((c, format!("point {v} appears twice")));
            cells.push(verts.clone());
            continue;
        }
        if let Some(why) = out_of_range(extent(verts, points), dim, verts, points) {
            overflow.push((c, kind.name(), why));
            cells.push(verts.clone());
            continue;
        }
        let l = max_edge(verts, points);
        if dim == 2 {
            if let Some((i, j)) = polygon_crossing(verts, points) {
                let k = verts.len();
                twisted.push((
                    c,
                    kind.name_of(k),
                    format!(
                        "sides ({}, {}) and ({}, {}) cross",
                        verts[i],
                        verts[(i + 1) % k],
                        verts[j],
                        verts[(j + 1) % k]
                    ),
                ));
            } else if norm(polygon_normal(verts, points)) <= DEGENERATE * l * l {
                degenerate.push((c, "zero area".into()));
            } else if let Some(why) = polygon_fold(verts, points) {
                twisted.push((c, kind.name_of(verts.len()), why));
            }
            cells.push(verts.clone());
            continue;
        }
        if kind != CellKind::Tetra {
            let jac = corner_jacobians(kind, verts, points);
            let eps = TWIST * l * l * l;
            let hi = (0..jac.len()).max_by(|&a, &b| jac[a].total_cmp(&jac[b]));
            let lo = (0..jac.len()).min_by(|&a, &b| jac[a].total_cmp(&jac[b]));
            if let (Some(hi), Some(lo)) = (hi, lo) {
                if jac[hi] > eps && jac[lo] < -eps {
                    let corner = |k: usize| verts[corners(kind)[k][0]];
                    twisted.push((
                        c,
                        kind.name(),
                        format!(
                            "the corner Jacobian changes sign: {:.3e} at point {} and {:.3e} at point {}",
                            jac[hi],
                            corner(hi),
                            jac[lo],
                            corner(lo)
                        ),
                    ));
                    cells.push(verts.clone());
                    continue;
                }
            }
        }
        let vol = signed_volume(kind, verts, points);
        if vol.abs() <= DEGENERATE * l * l * l {
            degenerate.push((c, "zero volume".into()));
            cells.push(verts.clone());
            continue;
        }
        if vol < 0.0 {
            inverted.push((c, kind.name(), vol));
            report.reoriented.push(c);
            cells.push(reversed(kind, verts));
        } else {
            cells.push(verts.clone());
        }
    }
    if !overflow.is_empty() {
        return Err(MeshError::Overflow { cells: overflow });
    }
    if !degenerate.is_empty() {
        return Err(MeshError::Degenerate { cells: degenerate });
    }
    if !twisted.is_empty() {
        return Err(MeshError::Twisted { cells: twisted });
    }
    if !inverted.is_empty() && !opts.reorient {
        return Err(MeshError::Inverted { cells: inverted });
    }
    Ok(cells)
}

/// A face of a cell being built: its global vertices in cyclic order and its first dart.
#[derive(Clone, Copy)]
pub(crate) struct BuiltFace {
    pub(crate) verts: [u32; 4],
    pub(crate) len: u8,
    first: u32,
}

impl BuiltFace {
    /// The dart at vertex `u` on the edge towards `w`, if the face has that edge.
    fn dart(&self, u: u32, w: u32) -> Option<u32> {
        let k = self.len as usize;
        for j in 0..k {
            let (a, b) = (self.verts[j], self.verts[(j + 1) % k]);
            if a == u && b == w {
                return Some(self.first + 2 * j as u32);
            }
            if b == u && a == w {
                return Some(self.first + 2 * j as u32 + 1);
            }
        }
        None
    }

    fn points(&self) -> Vec<usize> {
        self.verts[..self.len as usize]
            .iter()
            .map(|&v| v as usize)
            .collect()
    }
}

/// Adds the darts of a polygon with `k` sides: dart `2j` at vertex `j` and `2j+1` at vertex
/// `j+1` on side `j`; alpha0 inside each side, alpha1 between consecutive sides.
///
/// ```text
///        v2
///       /  \            2j --0-- 2j+1 : one side, from v_j to v_j+1
///     5/    \2          2j+1 --1-- 2j+2 : the corner at v_j+1
///     4\    /3
///   v0  0--1  v1
/// ```
fn add_polygon(g: &mut GMap, k: usize) -> u32 {
    let first = g.add_darts(2 * k).0;
    for j in 0..k as u32 {
        let a = first + 2 * j;
        g.alpha[0][a as usize] = a + 1;
        g.alpha[0][a as usize + 1] = a;
        let b = first + (2 * j + 2) % (2 * k as u32);
        g.alpha[1][a as usize + 1] = b;
        g.alpha[1][b as usize] = a + 1;
    }
    first
}

fn link_raw(g: &mut GMap, i: usize, a: u32, b: u32) {
    g.alpha[i][a as usize] = b;
    g.alpha[i][b as usize] = a;
}

/// The darts of the map, the point of each dart and the first dart of each kept cell (one
/// more entry: the number of darts).
struct Built {
    g: GMap,
    vert_of_dart: Vec<u32>,
    cell_first: Vec<u32>,
}

/// Builds the G-map of a mesh: a 2-map for polygons, a 3-map for volume cells.
///
/// Every cell becomes its own darts (2 per side of each face); faces of one cell are sewn by
/// alpha2, neighbouring cells by alpha2 (surfaces) or alpha3 (volumes) across their shared
/// edges or faces. Points used by no cell are left out and listed in the report. Besides
/// `position` (vec3, mean), the map gets `point_id`, `particle` (i64 on the vertex orbit,
/// copy) and `cell_id` (i64 on the element orbit, copy); see the module documentation.
///
/// The darts of each kept cell are consecutive, cells in input order; a cell's darts follow
/// its input vertex order, or [`reversed`] order when it was turned.
///
/// # Errors
/// A [`MeshError`] naming every offending cell or point.
pub fn build(mesh: &Mesh, opts: &BuildOptions) -> Result<(GMap, BuildReport), MeshError> {
    let dim = check_cells(mesh)?;
    let mut report = BuildReport::default();
    let ids = dedupe(mesh, opts, &mut report)?;
    let mut used = vec![false; mesh.points.len()];
    for verts in &mesh.cells {
        for &v in verts {
            used[v] = true;
        }
    }
    report.unused_points = (0..used.len()).filter(|&i| !used[i]).collect();
    let cells = check_geometry(mesh, &ids, dim, opts, &mut report)?;
    let Built {
        mut g,
        vert_of_dart,
        cell_first,
    } = if dim == 2 {
        build_surface(mesh, &ids, cells, opts, &mut report)?
    } else {
        build_volume(mesh, &ids, &cells, &mut report)?
    };
    g.version += 1;
    let vertex = OrbitType::vertex(dim);
    let pos = g
        .add_embedding("position", EmbeddingType::Vec3, vertex, Policy::Mean)
        .expect("fresh map");
    let e = &mut g.embeddings[pos.0 as usize];
    let Column::Real(col) = &mut e.values else {
        unreachable!("vec3 is real")
    };
    for (d, &v) in vert_of_dart.iter().enumerate() {
        let s = e.slot_of[d] as usize;
        col[3 * s..3 * s + 3].copy_from_slice(&mesh.points[v as usize]);
    }
    // the vertex orbits are the slots of `position` (numbered by smallest dart): the other
    // vertex embeddings share that table instead of walking the orbits again
    let labels = std::sync::Arc::clone(&e.slot_of);
    let n_orbits = e.slot_use.len();
    let particle_of_slot = particles(
        &labels,
        n_orbits,
        &vert_of_dart,
        &used,
        mesh,
        &ids,
        opts,
        &mut report,
    )?;
    let mut point_of_slot = vec![0i64; n_orbits];
    for (d, &v) in vert_of_dart.iter().enumerate() {
        point_of_slot[labels[d] as usize] = i64::from(v);
    }
    push_int(&mut g, "point_id", vertex, labels.clone(), point_of_slot);
    push_int(&mut g, "particle", vertex, labels, particle_of_slot);
    // each kept cell's darts are one element orbit
    let element = if dim == 2 {
        OrbitType::face(2)
    } else {
        OrbitType::volume()
    };
    let mut cell_slot = vec![0u32; vert_of_dart.len()];
    for k in 0..ids.len() {
        let (a, b) = (cell_first[k] as usize, cell_first[k + 1] as usize);
        cell_slot[a..b].fill(k as u32);
    }
    let cell_of_slot = ids.iter().map(|&c| c as i64).collect();
    push_int(
        &mut g,
        "cell_id",
        element,
        std::sync::Arc::new(cell_slot),
        cell_of_slot,
    );
    Ok((g, report))
}

/// Declares an i64 embedding (policy copy) on `orbit` whose orbits are already numbered:
/// dart `d` is on orbit `slot_of[d]`, whose value is `values[slot_of[d]]`.
fn push_int(
    g: &mut GMap,
    name: &str,
    orbit: OrbitType,
    slot_of: std::sync::Arc<Vec<u32>>,
    values: Vec<i64>,
) {
    debug_assert!(g.embedding_id(name).is_none());
    let mut e =
        crate::embedding::Embedding::new(name, EmbeddingType::I64, orbit, Policy::Copy, None);
    let mut slot_use = vec![0u32; values.len()];
    for &s in slot_of.iter() {
        slot_use[s as usize] += 1;
    }
    e.slot_of = slot_of;
    e.slot_use = slot_use;
    e.values = Column::Int(values);
    g.embeddings.push(e);
}

/// The `particle` row of every vertex orbit (see [`Pinched`]); refuses pinched points with
/// [`Pinched::Refuse`] and lists them in the report otherwise. `labels[d]` is the vertex
/// orbit of dart `d`, orbits numbered by their smallest dart.
#[allow(clippy::too_many_arguments)]
fn particles(
    labels: &[u32],
    n: usize,
    vert_of_dart: &[u32],
    used: &[bool],
    mesh: &Mesh,
    ids: &[usize],
    opts: &BuildOptions,
    report: &mut BuildReport,
) -> Result<Vec<i64>, MeshError> {
    // row of each used point: its rank among used points
    let mut row = vec![-1i64; used.len()];
    let mut n_used = 0i64;
    for (p, &u) in used.iter().enumerate() {
        if u {
            row[p] = n_used;
            n_used += 1;
        }
    }
    let mut out = vec![-1i64; n];
    for (d, &v) in vert_of_dart.iter().enumerate() {
        out[labels[d] as usize] = row[v as usize];
    }
    if n as i64 == n_used {
        return Ok(out);
    }
    // the first orbit met for a point (smallest dart) keeps its row
    let mut first_label = vec![u32::MAX; used.len()];
    let mut label_point = vec![u32::MAX; n];
    let mut extra: Vec<(u32, u32)> = Vec::new(); // (point, label) of the other orbits
    for (d, &v) in vert_of_dart.iter().enumerate() {
        let l = labels[d];
        if label_point[l as usize] != u32::MAX {
            continue;
        }
        label_point[l as usize] = v;
        if first_label[v as usize] == u32::MAX {
            first_label[v as usize] = l;
        } else {
            extra.push((v, l));
        }
    }
    let mut pinched: Vec<usize> = extra.iter().map(|&(p, _)| p as usize).collect();
    pinched.sort_unstable();
    pinched.dedup();
    if opts.pinched == Pinched::Refuse {
        let mut around: std::collections::HashMap<usize, Vec<usize>> =
            pinched.iter().map(|&p| (p, Vec::new())).collect();
        for &c in ids {
            for v in &mesh.cells[c] {
                if let Some(list) = around.get_mut(v) {
                    list.push(c);
                }
            }
        }
        let points = pinched
            .iter()
            .map(|p| (*p, around.remove(p).unwrap_or_default()))
            .collect();
        return Err(MeshError::Pinched { points });
    }
    if opts.pinched == Pinched::Split {
        // extra orbits in increasing (point, smallest dart); labels increase with the
        // smallest dart
        extra.sort_unstable();
        for (k, &(_, l)) in extra.iter().enumerate() {
            out[l as usize] = n_used + k as i64;
        }
    }
    report.pinched = pinched;
    Ok(out)
}

fn build_surface(
    mesh: &Mesh,
    ids: &[usize],
    mut cells: Vec<Vec<usize>>,
    opts: &BuildOptions,
    report: &mut BuildReport,
) -> Result<Built, MeshError> {
    let points = &mesh.points;
    let mut shared = shared_edges(&cells, ids)?;
    // orientation: neighbours must run along their shared edge in opposite directions
    let n_faces = cells.len();
    let mut flip = vec![false; n_faces];
    let inconsistent: Vec<(usize, usize, usize, usize)> = shared
        .iter()
        .filter(|(_, [a, b])| a.2 == b.2)
        .map(|((u, v), [a, b])| {
            let (a, b) = (ids[a.0 as usize], ids[b.0 as usize]);
            (a.min(b), a.max(b), *u as usize, *v as usize)
        })
        .collect();
    if !inconsistent.is_empty() {
        if !opts.reorient {
            return Err(MeshError::Orientation {
                pairs: inconsistent,
            });
        }
        let mut adj: Vec<Vec<(u32, bool)>> = vec![Vec::new(); n_faces];
        for (_, [a, b]) in &shared {
            let same = a.2 == b.2; // same direction: one of them must flip
            adj[a.0 as usize].push((b.0, same));
            adj[b.0 as usize].push((a.0, same));
        }
        let mut seen = vec![false; n_faces];
        let mut component = Vec::new();
        for s in 0..n_faces {
            if seen[s] {
                continue;
            }
            seen[s] = true;
            component.clear();
            component.push(s);
            let mut orientable = true;
            let mut head = 0;
            while head < component.len() {
                let f = component[head];
                head += 1;
                for &(h, same) in &adj[f] {
                    let want = flip[f] ^ same;
                    if !seen[h as usize] {
                        seen[h as usize] = true;
                        flip[h as usize] = want;
                        component.push(h as usize);
                    } else if flip[h as usize] != want {
                        orientable = false;
                    }
                }
            }
            if !orientable {
                report.non_orientable = true;
            } else if 2 * component.iter().filter(|&&f| flip[f]).count() > component.len() {
                // turn the fewer faces
                for &f in &component {
                    flip[f] = !flip[f];
                }
            }
        }
        for f in 0..n_faces {
            if flip[f] {
                cells[f].reverse();
            }
        }
        report.reoriented = (0..n_faces).filter(|&f| flip[f]).map(|f| ids[f]).collect();
        if !report.reoriented.is_empty() {
            shared = shared_edges(&cells, ids)?; // sides are numbered anew in the flipped faces
        }
    }
    if !report.non_orientable {
        check_planar_folds(points, &cells, ids, &shared)?;
    }
    // boundary sides (the sides not shared): overlapping ones are non-conforming (hanging
    // nodes)
    let mut side_first = Vec::with_capacity(cells.len() + 1);
    side_first.push(0usize);
    for verts in &cells {
        side_first.push(side_first[side_first.len() - 1] + verts.len());
    }
    let mut is_shared = vec![false; side_first[cells.len()]];
    for (_, [a, b]) in &shared {
        is_shared[side_first[a.0 as usize] + a.1 as usize] = true;
        is_shared[side_first[b.0 as usize] + b.1 as usize] = true;
    }
    let mut boundary = Vec::new();
    for (f, verts) in cells.iter().enumerate() {
        let k = verts.len();
        for j in 0..k {
            if !is_shared[side_first[f] + j] {
                boundary.push(conform::Facet {
                    cell: ids[f],
                    verts: vec![verts[j], verts[(j + 1) % k]],
                });
            }
        }
    }
    let pairs = conform::overlapping(points, &boundary);
    if !pairs.is_empty() {
        return Err(MeshError::NonConforming { pairs });
    }
    let kinds = vec![CellKind::Polygon; cells.len()];
    let pairs = overlap::overlapping_cells(points, &cells, &kinds, ids, 2);
    if !pairs.is_empty() {
        return Err(MeshError::Overlapping { pairs });
    }
    let mut g = GMap::new(2).expect("2 is supported");
    let mut faces = Vec::with_capacity(cells.len());
    let mut vert_of_dart = Vec::new();
    let mut cell_first = Vec::with_capacity(cells.len() + 1);
    for verts in &cells {
        let k = verts.len();
        let first = add_polygon(&mut g, k);
        cell_first.push(first);
        for j in 0..k {
            vert_of_dart.push(verts[j] as u32);
            vert_of_dart.push(verts[(j + 1) % k] as u32);
        }
        faces.push(first);
    }
    cell_first.push(vert_of_dart.len() as u32);
    for ((u, v), [a, b]) in &shared {
        // darts at vertex u on the shared side of each face
        for x in [*u, *v] {
            let da = side_dart(&cells[a.0 as usize], faces[a.0 as usize], a.1, x);
            let db = side_dart(&cells[b.0 as usize], faces[b.0 as usize], b.1, x);
            link_raw(&mut g, 2, da, db);
        }
    }
    Ok(Built {
        g,
        vert_of_dart,
        cell_first,
    })
}

/// In a planar surface mesh (every point within a tiny distance of one plane), two
/// consistently oriented neighbours whose normals point to opposite sides of the plane lie on
/// the same side of their shared edge: a fold. Refuses every such pair.
fn check_planar_folds(
    points: &[[f64; 3]],
    cells: &[Vec<usize>],
    ids: &[usize],
    shared: &[SharedEdge],
) -> Result<(), MeshError> {
    let normals: Vec<[f64; 3]> = cells.iter().map(|c| polygon_normal(c, points)).collect();
    let Some(big) =
        (0..normals.len()).max_by(|&a, &b| norm(normals[a]).total_cmp(&norm(normals[b])))
    else {
        return Ok(());
    };
    let nb = norm(normals[big]);
    if nb == 0.0 {
        return Ok(());
    }
    let n = [
        normals[big][0] / nb,
        normals[big][1] / nb,
        normals[big][2] / nb,
    ];
    let o = points[cells[big][0]];
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for c in cells {
        for &v in c {
            for a in 0..3 {
                lo[a] = lo[a].min(points[v][a]);
                hi[a] = hi[a].max(points[v][a]);
            }
        }
    }
    let tol = 1e-9 * norm(sub(hi, lo));
    let planar = cells
        .iter()
        .all(|c| c.iter().all(|&v| dot(sub(points[v], o), n).abs() <= tol));
    if !planar {
        return Ok(());
    }
    let mut pairs = Vec::new();
    for ((u, v), [a, b]) in shared {
        let (sa, sb) = (dot(normals[a.0 as usize], n), dot(normals[b.0 as usize], n));
        if sa * sb < 0.0 {
            let (ca, cb) = (ids[a.0 as usize], ids[b.0 as usize]);
            pairs.push((ca.min(cb), ca.max(cb), vec![*u as usize, *v as usize]));
        }
    }
    pairs.sort_unstable();
    if pairs.is_empty() {
        Ok(())
    } else {
        Err(MeshError::Folded {
            what: "edge",
            pairs,
        })
    }
}

/// A side of a face: (face, side index, whether it runs from the smaller vertex index).
type Side = (u32, u32, bool);

/// An edge (its two vertices, smaller first) and the two sides on it.
type SharedEdge = ((u32, u32), [Side; 2]);

/// The edges shared by two faces, sorted, with the side of each face; refuses an edge on 3+.
fn shared_edges(cells: &[Vec<usize>], ids: &[usize]) -> Result<Vec<SharedEdge>, MeshError> {
    // the first two sides of each edge inline (no allocation per edge); the edges with more
    // go to `extra`
    let none: Side = (u32::MAX, 0, false);
    let mut edges: FxMap<(u32, u32), [Side; 2]> = fx_map(2 * cells.len());
    let mut extra: FxMap<(u32, u32), Vec<u32>> = fx_map(0);
    for (f, verts) in cells.iter().enumerate() {
        let k = verts.len();
        for j in 0..k {
            let (a, b) = (verts[j] as u32, verts[(j + 1) % k] as u32);
            let key = (a.min(b), a.max(b));
            let side = (f as u32, j as u32, a < b);
            let e = edges.entry(key).or_insert([none, none]);
            if e[0].0 == u32::MAX {
                e[0] = side;
            } else if e[1].0 == u32::MAX {
                e[1] = side;
            } else {
                extra.entry(key).or_default().push(f as u32);
            }
        }
    }
    if !extra.is_empty() {
        let mut bad: Vec<(Vec<usize>, Vec<usize>)> = extra
            .iter()
            .map(|(key, more)| {
                let two = edges[key];
                let mut faces: Vec<usize> = [two[0].0, two[1].0]
                    .iter()
                    .chain(more)
                    .map(|&f| ids[f as usize])
                    .collect();
                faces.sort_unstable();
                (vec![key.0 as usize, key.1 as usize], faces)
            })
            .collect();
        bad.sort_unstable();
        return Err(MeshError::NonManifold {
            what: "edge",
            why: "an edge joins at most 2 faces",
            items: bad,
        });
    }
    let mut shared: Vec<SharedEdge> = edges
        .into_iter()
        .filter(|(_, s)| s[1].0 != u32::MAX)
        .collect();
    shared.sort_unstable_by_key(|s| s.0);
    Ok(shared)
}

/// The dart of side `j` of a polygon (first dart `first`) at vertex `x`.
fn side_dart(verts: &[usize], first: u32, j: u32, x: u32) -> u32 {
    if verts[j as usize] as u32 == x {
        first + 2 * j
    } else {
        first + 2 * j + 1
    }
}

fn build_volume(
    mesh: &Mesh,
    ids: &[usize],
    cells: &[Vec<usize>],
    _report: &mut BuildReport,
) -> Result<Built, MeshError> {
    let points = &mesh.points;
    let kinds: Vec<CellKind> = ids.iter().map(|&c| mesh.kinds[c]).collect();
    let mut g = GMap::new(3).expect("3 is supported");
    let n_darts: usize = kinds
        .iter()
        .map(|&k| local_faces(k).iter().map(|f| 2 * f.len()).sum::<usize>())
        .sum();
    for a in &mut g.alpha {
        a.reserve(n_darts);
    }
    let mut vert_of_dart: Vec<u32> = Vec::with_capacity(n_darts);
    let mut cell_first: Vec<u32> = Vec::with_capacity(cells.len() + 1);
    // sorted face vertices -> (cell, face); cell u32::MAX once the face is matched
    let mut face_map: FxMap<[u32; 4], (u32, BuiltFace)> = fx_map(cells.len() * 3);
    let mut local: Vec<BuiltFace> = Vec::with_capacity(6);
    let mut mismatched: Vec<FacePair> = Vec::new();
    let mut folded: Vec<(usize, usize, Vec<usize>)> = Vec::new();
    let mut non_manifold: std::collections::BTreeSet<[u32; 4]> = std::collections::BTreeSet::new();
    for (c, (&kind, verts)) in kinds.iter().zip(cells).enumerate() {
        local.clear();
        cell_first.push(vert_of_dart.len() as u32);
        for lf in local_faces(kind) {
            let k = lf.len();
            let first = add_polygon(&mut g, k);
            let mut fv = [u32::MAX; 4];
            for (j, &lv) in lf.iter().enumerate() {
                fv[j] = verts[lv] as u32;
            }
            for j in 0..k {
                vert_of_dart.push(fv[j]);
                vert_of_dart.push(fv[(j + 1) % k]);
            }
            local.push(BuiltFace {
                verts: fv,
                len: k as u8,
                first,
            });
        }
        // alpha2 inside the cell: the two faces of each edge
        for (fi, f) in local.iter().enumerate() {
            let k = f.len as usize;
            for j in 0..k {
                let (u, w) = (f.verts[j], f.verts[(j + 1) % k]);
                for h in &local[fi + 1..] {
                    if let Some(du) = h.dart(u, w) {
                        let dw = h.dart(w, u).expect("same edge");
                        link_raw(&mut g, 2, f.first + 2 * j as u32, du);
                        link_raw(&mut g, 2, f.first + 2 * j as u32 + 1, dw);
                    }
                }
            }
        }
        // alpha3 across cells
        for f in local.drain(..) {
            let mut key = f.verts;
            key[..f.len as usize].sort_unstable();
            match face_map.remove(&key) {
                None => {
                    face_map.insert(key, (c as u32, f));
                }
                Some((other, h)) if other == u32::MAX => {
                    face_map.insert(key, (other, h));
                    non_manifold.insert(key);
                }
                Some((other, h)) => {
                    let k = f.len as usize;
                    let mut ok = true;
                    let mut same_direction = false;
                    for j in 0..k {
                        let (u, w) = (f.verts[j], f.verts[(j + 1) % k]);
                        let (Some(hu), Some(hw)) = (h.dart(u, w), h.dart(w, u)) else {
                            ok = false;
                            break;
                        };
                        same_direction = (hu - h.first) % 2 == 0;
                        link_raw(&mut g, 3, f.first + 2 * j as u32, hu);
                        link_raw(&mut g, 3, f.first + 2 * j as u32 + 1, hw);
                    }
                    if !ok {
                        mismatched.push(FacePair {
                            a: ids[other as usize],
                            face_a: h.points(),
                            b: ids[c],
                            face_b: f.points(),
                            why: "same points, different edges".into(),
                        });
                    } else if same_direction {
                        // both cells positive and listing the face the same way round: both
                        // lie on the same side of it
                        folded.push((ids[other as usize], ids[c], f.points()));
                    }
                    // a third cell on this face is non-manifold: remember the face as used
                    face_map.insert(key, (u32::MAX, h));
                }
            }
        }
    }
    cell_first.push(vert_of_dart.len() as u32);
    if !non_manifold.is_empty() {
        return Err(non_manifold_faces(&non_manifold, cells, &kinds, ids));
    }
    if !mismatched.is_empty() {
        return Err(MeshError::NonConforming { pairs: mismatched });
    }
    if !folded.is_empty() {
        folded.sort_unstable();
        return Err(MeshError::Folded {
            what: "face",
            pairs: folded,
        });
    }
    let mut boundary: Vec<conform::Facet> = face_map
        .values()
        .filter(|(c, _)| *c != u32::MAX)
        .map(|(c, f)| conform::Facet {
            cell: ids[*c as usize],
            verts: f.points(),
        })
        .collect();
    boundary.sort_unstable_by(|a, b| (a.cell, &a.verts).cmp(&(b.cell, &b.verts)));
    let pairs = conform::overlapping(points, &boundary);
    if !pairs.is_empty() {
        return Err(MeshError::NonConforming { pairs });
    }
    let pairs = overlap::overlapping_cells(points, cells, &kinds, ids, 3);
    if !pairs.is_empty() {
        return Err(MeshError::Overlapping { pairs });
    }
    Ok(Built {
        g,
        vert_of_dart,
        cell_first,
    })
}

/// The error listing every face (sorted padded key) of `keys` with the cells on it.
fn non_manifold_faces(
    keys: &std::collections::BTreeSet<[u32; 4]>,
    cells: &[Vec<usize>],
    kinds: &[CellKind],
    ids: &[usize],
) -> MeshError {
    let mut on_face: std::collections::BTreeMap<[u32; 4], Vec<usize>> =
        keys.iter().map(|k| (*k, Vec::new())).collect();
    for (c, (cv, &kind)) in cells.iter().zip(kinds).enumerate() {
        for lf in local_faces(kind) {
            let mut key = [u32::MAX; 4];
            for (j, &l) in lf.iter().enumerate() {
                key[j] = cv[l] as u32;
            }
            key[..lf.len()].sort_unstable();
            if let Some(list) = on_face.get_mut(&key) {
                list.push(ids[c]);
            }
        }
    }
    let items = on_face
        .into_iter()
        .map(|(key, mut c)| {
            c.sort_unstable();
            let verts = key
                .iter()
                .filter(|&&v| v != u32::MAX)
                .map(|&v| v as usize)
                .collect();
            (verts, c)
        })
        .collect();
    MeshError::NonManifold {
        what: "face",
        why: "a face joins at most 2 cells",
        items,
    }
}

/// Turns a map back into points and cells: one point per vertex orbit (numbered by
/// [`GMap::orbit_labels`]), one cell per face `<0,1>` (2D) or volume `<0,1,2>` (3D), in the
/// order of their smallest dart. Needs the `position` embedding.
///
/// A face's vertices start at the vertex of its smallest dart. On an orientable connected
/// surface every face has the orientation of the component's smallest dart (its darts are
/// split into two classes, alternating along every alpha link; each face is walked from its
/// darts of that class), so that a built map gives back its cells as listed, and a map
/// changed by rules that keep the darts they match (the shipped modeling rules) keeps the
/// input's orientation. On a non-orientable component each face follows its smallest dart.
/// Volumes are listed in VTK order with a positive volume.
pub fn extract(g: &GMap) -> Result<Mesh, MeshError> {
    let n = g.dimension();
    let (points, labels) = extract_points(g)?;
    let mut mesh = Mesh {
        points,
        kinds: Vec::new(),
        cells: Vec::new(),
    };
    if n == 2 {
        let class = orientation_classes(g);
        for d in g.orbit_representatives(OrbitType::face(2)) {
            // a face of the other class than its component's smallest dart is walked from
            // the other dart at the same corner: the same first vertex, the other direction
            let start = if class[d.index()] == 1 {
                g.alpha(1, d)
            } else {
                d
            };
            let verts = face_cycle(g, start, &labels)?;
            mesh.kinds.push(CellKind::Polygon);
            mesh.cells.push(verts.into_iter().map(|(_, v)| v).collect());
        }
    } else {
        let face = OrbitType::parse("<0,1>").expect("static");
        for d in g.orbit_representatives(OrbitType::volume()) {
            let (kind, verts) = volume_cell(g, d, &labels, face)?;
            let verts = if signed_volume(kind, &verts, &mesh.points) < 0.0 {
                reversed(kind, &verts)
            } else {
                verts
            };
            mesh.kinds.push(kind);
            mesh.cells.push(verts);
        }
    }
    Ok(mesh)
}

/// The points of a map, one per vertex row in the map's row order (the input point order
/// for an imported map), and each dart's vertex row (indexed by dart).
fn extract_points(g: &GMap) -> Result<(Vec<[f64; 3]>, Vec<u32>), MeshError> {
    let pos = g
        .embedding_id("position")
        .ok_or_else(|| MeshError::Extract("the map has no 'position' embedding".into()))?;
    let (labels, nv) = g.vertex_rows();
    let mut points = vec![[0.0; 3]; nv];
    let mut done = vec![false; nv];
    for d in g.darts() {
        let l = labels[d.index()] as usize;
        if !done[l] {
            done[l] = true;
            let p = g.real(pos, d);
            if p.len() != 3 {
                return Err(MeshError::Extract("'position' is not a vec3".into()));
            }
            points[l] = [p[0], p[1], p[2]];
        }
    }
    Ok((points, labels))
}

/// Every volume of a 3-map as a general polyhedron, for mesh files that hold polyhedra (VTK's
/// `VTK_POLYHEDRON`, cell type 42): the points as [`extract`] gives them, and per volume (in
/// [`extract`]'s order) its faces, each a cycle of point indices. The faces of a volume are
/// oriented alike, so that their normals by the right-hand rule point out of it (VTK's
/// convention): the face cycles are walked from the darts of one orientation class of the
/// volume, and all reversed when the volume they enclose comes out negative. Refuses a map
/// that is not 3D, an open volume (a free alpha2) or face, and a volume that is not
/// orientable, naming the volume by a dart.
pub fn extract_polyhedra(g: &GMap) -> Result<(Vec<[f64; 3]>, PolyhedronCells), MeshError> {
    if g.dimension() != 3 {
        return Err(MeshError::Extract(format!(
            "a {}-map has no volumes to write as polyhedra",
            g.dimension()
        )));
    }
    let (points, labels) = extract_points(g)?;
    let face = OrbitType::parse("<0,1>").expect("static");
    let mut cells = Vec::new();
    let mut class: Vec<u8> = vec![u8::MAX; g.capacity()];
    let mut faces_seen = crate::Marks::with_capacity(g.capacity());
    let mut stack = Vec::new();
    for d in g.orbit_representatives(OrbitType::volume()) {
        // the volume's two orientation classes, from `d` (class 0) through alpha0,1,2
        let mut darts = vec![d];
        class[d.index()] = 0;
        stack.push(d);
        while let Some(x) = stack.pop() {
            if g.is_free(2, x) {
                return Err(MeshError::Extract(format!(
                    "the volume of dart {d} is open at {x}"
                )));
            }
            for i in 0..3 {
                let y = g.alpha(i, x);
                if y == x {
                    continue; // an open face (free alpha0 or alpha1): face_cycle names it
                }
                if class[y.index()] == u8::MAX {
                    class[y.index()] = 1 - class[x.index()];
                    darts.push(y);
                    stack.push(y);
                } else if class[y.index()] == class[x.index()] {
                    return Err(MeshError::Extract(format!(
                        "the volume of dart {d} is not orientable (alpha{i} links {x} and {y} of one orientation class)"
                    )));
                }
            }
        }
        let mut faces: Vec<Vec<usize>> = Vec::new();
        for &x in &darts {
            if class[x.index()] == 0 && !faces_seen.is_marked(x) {
                g.visit_orbit(x, face, &mut faces_seen, |_| {});
                faces.push(
                    face_cycle(g, x, &labels)?
                        .into_iter()
                        .map(|(_, v)| v)
                        .collect(),
                );
            }
        }
        if polyhedron_volume(&faces, &points) < 0.0 {
            // each cycle run the other way from the same first point
            for f in &mut faces {
                f[1..].reverse();
            }
        }
        cells.push(faces);
    }
    Ok((points, cells))
}

/// The faces of each polyhedron (see [`extract_polyhedra`]): cell, face, point index.
pub type PolyhedronCells = Vec<Vec<Vec<usize>>>;

/// Six times the signed volume a closed polyhedron's face cycles enclose (positive when their
/// normals point out), each face fanned from its first point to the polyhedron's first point,
/// in units of the polyhedron's largest extent from that point (so that the sign survives
/// for tiny or huge coordinates, whose products of three differences would under- or
/// overflow).
fn polyhedron_volume(faces: &[Vec<usize>], points: &[[f64; 3]]) -> f64 {
    let Some(&o) = faces.first().and_then(|f| f.first()) else {
        return 0.0;
    };
    let o = points[o];
    let m = faces
        .iter()
        .flatten()
        .flat_map(|&i| sub(points[i], o))
        .fold(0.0_f64, |m, v| m.max(v.abs()));
    if m == 0.0 || !m.is_finite() {
        return 0.0;
    }
    let d = |i: usize| sub(points[i], o).map(|v| v / m);
    let mut v = 0.0;
    for f in faces {
        let a = d(f[0]);
        for k in 1..f.len().saturating_sub(1) {
            v += dot(a, cross(d(f[k]), d(f[k + 1])));
        }
    }
    v
}

/// The orientation class of each dart of a 2-map (indexed by dart): 0 for the smallest dart
/// of its connected component and every dart an even number of alpha links from it, 1 for the
/// others; 0 for every dart of a non-orientable component (where a dart is linked to one of
/// its own class); removed darts are left unclassed.
fn orientation_classes(g: &GMap) -> Vec<u8> {
    const UNSET: u8 = u8::MAX;
    let mut class = vec![UNSET; g.capacity()];
    let mut component = Vec::new();
    let mut stack = Vec::new();
    for d0 in g.darts() {
        if class[d0.index()] != UNSET {
            continue;
        }
        class[d0.index()] = 0;
        component.clear();
        stack.push(d0);
        let mut orientable = true;
        while let Some(d) = stack.pop() {
            component.push(d);
            let c = class[d.index()];
            for i in 0..=g.dimension() {
                let e = g.alpha(i, d);
                if e == d {
                    continue;
                }
                if class[e.index()] == UNSET {
                    class[e.index()] = 1 - c;
                    stack.push(e);
                } else if class[e.index()] == c {
                    orientable = false;
                }
            }
        }
        if !orientable {
            for d in &component {
                class[d.index()] = 0;
            }
        }
    }
    class
}

/// The (dart, vertex) pairs around the face of `d`, one per corner, following alpha0 then
/// alpha1.
fn face_cycle(g: &GMap, d0: Dart, labels: &[u32]) -> Result<Vec<(Dart, usize)>, MeshError> {
    let mut out = Vec::new();
    let mut d = d0;
    loop {
        let e = g.alpha(0, d);
        if e == d || g.is_free(1, e) {
            return Err(MeshError::Extract(format!("the face of dart {d0} is open")));
        }
        out.push((d, labels[d.index()] as usize));
        d = g.alpha(1, e);
        if d == d0 {
            return Ok(out);
        }
        if out.len() > g.capacity() {
            return Err(MeshError::Extract(format!(
                "the face of dart {d0} does not close"
            )));
        }
    }
}

/// The kind and VTK vertex order (up to orientation) of the volume of `d`.
fn volume_cell(
    g: &GMap,
    d: Dart,
    labels: &[u32],
    face: OrbitType,
) -> Result<(CellKind, Vec<usize>), MeshError> {
    let darts = g.orbit(d, OrbitType::volume());
    let mut faces: Vec<Vec<(Dart, usize)>> = Vec::new();
    let mut m = crate::Marks::with_capacity(g.capacity());
    let mut verts: Vec<usize> = Vec::new();
    for &x in &darts {
        if g.is_free(2, x) {
            return Err(MeshError::Extract(format!(
                "the volume of dart {d} is open at {x}"
            )));
        }
        let v = labels[x.index()] as usize;
        if !verts.contains(&v) {
            verts.push(v);
        }
        if !m.is_marked(x) {
            g.visit_orbit(x, face, &mut m, |_| {});
            faces.push(face_cycle(g, x, labels)?);
        }
    }
    let sizes = |k: usize| faces.iter().filter(|f| f.len() == k).count();
    let (tris, quads) = (sizes(3), sizes(4));
    let kind = match (verts.len(), faces.len(), tris, quads) {
        (4, 4, 4, 0) => CellKind::Tetra,
        (8, 6, 0, 6) => CellKind::Hexa,
        (6, 5, 2, 3) => CellKind::Wedge,
        (5, 5, 4, 1) => CellKind::Pyramid,
        _ => {
            // every face counted by its number of sides: "2 triangles, 1 quad, 1 pentagon"
            let mut sides: Vec<usize> = faces.iter().map(Vec::len).collect();
            sides.sort_unstable();
            sides.dedup();
            let name = |k: usize, n: usize| {
                let one = match k {
                    3 => "triangle".to_string(),
                    4 => "quad".to_string(),
                    5 => "pentagon".to_string(),
                    6 => "hexagon".to_string(),
                    k => format!("{k}-sided face"),
                };
                format!("{n} {one}{}", if n == 1 { "" } else { "s" })
            };
            let kinds: Vec<String> = sides.iter().map(|&k| name(k, sizes(k))).collect();
            return Err(MeshError::Extract(format!(
                "the volume of dart {d} has {} vertices and {} faces ({}): not a tetra, hexahedron, wedge or pyramid",
                verts.len(),
                faces.len(),
                kinds.join(", ")
            )));
        }
    };
    let base_len = if matches!(kind, CellKind::Tetra | CellKind::Wedge) {
        3
    } else {
        4
    };
    let base = faces.iter().find(|f| f.len() == base_len).expect("counted");
    let mut order: Vec<usize> = base.iter().map(|&(_, v)| v).collect();
    // the vertex across the edge leaving each base corner: alpha2 to the side face, alpha1
    // to its other edge at that corner, alpha0 to its far end
    let up = |x: Dart| labels[g.alpha(0, g.alpha(1, g.alpha(2, x))).index()] as usize;
    match kind {
        CellKind::Hexa | CellKind::Wedge => order.extend(base.iter().map(|&(x, _)| up(x))),
        _ => order.push(up(base[0].0)),
    }
    Ok((kind, order))
}
