//! Building a G-map from points and cells, and back.
//!
//! Surfaces (n = 2) come from polygons of any degree; volumes (n = 3) from tetrahedra,
//! hexahedra, wedges (prisms) and pyramids, in VTK vertex order. Vertex positions go to the
//! `position` embedding (`vec3` on the vertex orbit).

use crate::embedding::Column;
use crate::{Dart, EmbeddingType, GMap, OrbitType, Policy};

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
    /// Not one kind per cell.
    #[error("{kinds} cell kinds given for {cells} cells")]
    KindCount {
        /// Kinds given.
        kinds: usize,
        /// Cells given.
        cells: usize,
    },
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
    #[error("cell {cell} is a {kind} with {got} vertices, expected {}{expected}", if *kind == "polygon" { "at least " } else { "" })]
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
    /// An edge (2D) or face (3D) shared by three or more cells, or a vertex whose cells are
    /// not connected through edges (2D) or faces (3D).
    #[error("non-manifold {what} {vertices:?} in cells {cells:?}: {why}")]
    NonManifold {
        /// What the rule is.
        why: &'static str,
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
        CellKind::Wedge => &[
            &[0, 1, 2],
            &[3, 5, 4],
            &[0, 3, 4, 1],
            &[1, 4, 5, 2],
            &[2, 5, 3, 0],
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

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
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

/// The Newell normal of a polygon (twice its vector area).
fn polygon_normal(verts: &[usize], points: &[[f64; 3]]) -> [f64; 3] {
    let mut n = [0.0; 3];
    for k in 0..verts.len() {
        let a = points[verts[k]];
        let b = points[verts[(k + 1) % verts.len()]];
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    n
}

fn max_edge(verts: &[usize], points: &[[f64; 3]]) -> f64 {
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

/// `verts` reordered to the opposite orientation.
pub fn reversed(kind: CellKind, verts: &[usize]) -> Vec<usize> {
    if kind == CellKind::Polygon {
        verts.iter().rev().copied().collect()
    } else {
        reversal(kind).iter().map(|&k| verts[k]).collect()
    }
}

/// Checks indices, vertex counts, repeated vertices, finiteness; returns the dimension.
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
    for (c, (&kind, verts)) in mesh.kinds.iter().zip(&mesh.cells).enumerate() {
        if kind.dimension() != dim {
            return Err(MeshError::MixedDimension {
                cell: c,
                kind: kind.name(),
                dim,
            });
        }
        let expected = kind.n_vertices();
        let bad_count = match expected {
            Some(k) => verts.len() != k,
            None => verts.len() < 3,
        };
        if bad_count {
            return Err(MeshError::VertexCount {
                cell: c,
                kind: kind.name(),
                got: verts.len(),
                expected: expected.unwrap_or(3),
            });
        }
        for &v in verts {
            if v >= mesh.points.len() {
                return Err(MeshError::VertexOutOfRange {
                    cell: c,
                    vertex: v,
                    n_points: mesh.points.len(),
                });
            }
        }
        for (k, &v) in verts.iter().enumerate() {
            if verts[k + 1..].contains(&v) {
                return Err(MeshError::Degenerate {
                    cell: c,
                    why: format!("vertex {v} appears twice"),
                });
            }
        }
    }
    for (i, p) in mesh.points.iter().enumerate() {
        if p.iter().any(|x| !x.is_finite()) {
            return Err(MeshError::NonFinite {
                point: i,
                coords: *p,
            });
        }
    }
    Ok(dim)
}

/// A face of a cell being built: its global vertices in cyclic order and its first dart.
struct BuiltFace {
    verts: [u32; 4],
    len: u8,
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

/// Builds the G-map of a mesh: a 2-map for polygons, a 3-map for volume cells.
///
/// Every cell becomes its own darts (2 per side of each face); faces of one cell are sewn by
/// alpha2, neighbouring cells by alpha2 (surfaces) or alpha3 (volumes) across their shared
/// edges or faces. Points used by no cell are left out and listed in the report.
pub fn build(mesh: &Mesh, opts: &BuildOptions) -> Result<(GMap, BuildReport), MeshError> {
    let dim = check_cells(mesh)?;
    let mut report = BuildReport::default();
    let mut used = vec![false; mesh.points.len()];
    for verts in &mesh.cells {
        for &v in verts {
            used[v] = true;
        }
    }
    report.unused_points = (0..used.len()).filter(|&i| !used[i]).collect();
    let (mut g, vert_of_dart) = if dim == 2 {
        build_surface(mesh, opts, &mut report)?
    } else {
        build_volume(mesh, opts, &mut report)?
    };
    g.version += 1;
    check_manifold_vertices(&g, &vert_of_dart, used.iter().filter(|&&u| u).count(), mesh)?;
    let pos = g
        .add_embedding(
            "position",
            EmbeddingType::Vec3,
            OrbitType::vertex(dim),
            Policy::Mean,
        )
        .expect("fresh map");
    let e = &mut g.embeddings[pos.0 as usize];
    let Column::Real(col) = &mut e.values else {
        unreachable!("vec3 is real")
    };
    for (d, &v) in vert_of_dart.iter().enumerate() {
        let s = e.slot_of[d] as usize;
        col[3 * s..3 * s + 3].copy_from_slice(&mesh.points[v as usize]);
    }
    Ok((g, report))
}

/// A point that became two vertex orbits (two fans touching at one vertex) would be two
/// particles at one place: refuse it.
fn check_manifold_vertices(
    g: &GMap,
    vert_of_dart: &[u32],
    n_used: usize,
    mesh: &Mesh,
) -> Result<(), MeshError> {
    let (labels, n) = g.orbit_labels(OrbitType::vertex(g.dim));
    if n == n_used {
        return Ok(());
    }
    let mut first_label = std::collections::HashMap::new();
    let mut split = u32::MAX;
    for (d, &v) in vert_of_dart.iter().enumerate() {
        let l = *first_label.entry(v).or_insert(labels[d]);
        if l != labels[d] {
            split = split.min(v);
        }
    }
    let v = split as usize;
    Err(MeshError::NonManifold {
        what: "vertex",
        why: "the cells around a vertex must be joined through edges (2D) or faces (3D)",
        vertices: vec![v],
        cells: (0..mesh.cells.len())
            .filter(|&c| mesh.cells[c].contains(&v))
            .collect(),
    })
}

fn build_surface(
    mesh: &Mesh,
    opts: &BuildOptions,
    report: &mut BuildReport,
) -> Result<(GMap, Vec<u32>), MeshError> {
    let points = &mesh.points;
    for (c, verts) in mesh.cells.iter().enumerate() {
        let n = norm(polygon_normal(verts, points));
        let l = max_edge(verts, points);
        if n <= DEGENERATE * l * l {
            return Err(MeshError::Degenerate {
                cell: c,
                why: "zero area".into(),
            });
        }
    }
    let mut shared = shared_edges(&mesh.cells)?;
    // orientation: neighbours must run along their shared edge in opposite directions
    let n_faces = mesh.cells.len();
    let mut flip = vec![false; n_faces];
    let inconsistent = shared.iter().find(|(_, [a, b])| a.2 == b.2);
    if let Some(((u, v), [a, b])) = inconsistent {
        if !opts.reorient {
            return Err(MeshError::Orientation {
                a: a.0.min(b.0) as usize,
                b: a.0.max(b.0) as usize,
                u: *u as usize,
                v: *v as usize,
            });
        }
        let mut adj: Vec<Vec<(u32, bool)>> = vec![Vec::new(); n_faces];
        for (_, [a, b]) in &shared {
            let same = a.2 == b.2; // same direction: one of them must flip
            adj[a.0 as usize].push((b.0, same));
            adj[b.0 as usize].push((a.0, same));
        }
        let mut seen = vec![false; n_faces];
        for s in 0..n_faces {
            if seen[s] {
                continue;
            }
            seen[s] = true;
            let mut stack = vec![s];
            while let Some(f) = stack.pop() {
                for &(h, same) in &adj[f] {
                    if !seen[h as usize] {
                        seen[h as usize] = true;
                        flip[h as usize] = flip[f] ^ same;
                        stack.push(h as usize);
                    }
                }
            }
        }
        report.reoriented = (0..n_faces).filter(|&f| flip[f]).collect();
    }
    let cells: Vec<Vec<usize>> = mesh
        .cells
        .iter()
        .zip(&flip)
        .map(|(v, &fl)| {
            if fl {
                reversed(CellKind::Polygon, v)
            } else {
                v.clone()
            }
        })
        .collect();
    if !report.reoriented.is_empty() {
        shared = shared_edges(&cells)?; // sides are numbered anew in the flipped faces
    }
    let mut g = GMap::new(2).expect("2 is supported");
    let mut faces = Vec::with_capacity(cells.len());
    let mut vert_of_dart = Vec::new();
    for verts in &cells {
        let k = verts.len();
        let first = add_polygon(&mut g, k);
        for j in 0..k {
            vert_of_dart.push(verts[j] as u32);
            vert_of_dart.push(verts[(j + 1) % k] as u32);
        }
        faces.push(first);
    }
    for ((u, v), [a, b]) in &shared {
        // darts at vertex u on the shared side of each face
        for x in [*u, *v] {
            let da = side_dart(&cells[a.0 as usize], faces[a.0 as usize], a.1, x);
            let db = side_dart(&cells[b.0 as usize], faces[b.0 as usize], b.1, x);
            link_raw(&mut g, 2, da, db);
        }
    }
    Ok((g, vert_of_dart))
}

/// A side of a face: (face, side index, whether it runs from the smaller vertex index).
type Side = (u32, u32, bool);

/// An edge (its two vertices, smaller first) and the two sides on it.
type SharedEdge = ((u32, u32), [Side; 2]);

/// The edges shared by two faces, sorted, with the side of each face; refuses an edge on 3+.
fn shared_edges(cells: &[Vec<usize>]) -> Result<Vec<SharedEdge>, MeshError> {
    let mut edges: std::collections::HashMap<(u32, u32), Vec<Side>> =
        std::collections::HashMap::new();
    for (f, verts) in cells.iter().enumerate() {
        let k = verts.len();
        for j in 0..k {
            let (a, b) = (verts[j] as u32, verts[(j + 1) % k] as u32);
            edges
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push((f as u32, j as u32, a < b));
        }
    }
    let mut shared = Vec::new();
    for (&key, uses) in &edges {
        match uses.len() {
            1 => {}
            2 => shared.push((key, [uses[0], uses[1]])),
            _ => {
                let mut faces: Vec<usize> = uses.iter().map(|u| u.0 as usize).collect();
                faces.sort_unstable();
                return Err(MeshError::NonManifold {
                    what: "edge",
                    why: "an edge joins at most 2 faces",
                    vertices: vec![key.0 as usize, key.1 as usize],
                    cells: faces,
                });
            }
        }
    }
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
    opts: &BuildOptions,
    report: &mut BuildReport,
) -> Result<(GMap, Vec<u32>), MeshError> {
    let points = &mesh.points;
    let mut cells: Vec<Vec<usize>> = Vec::with_capacity(mesh.cells.len());
    for (c, (&kind, verts)) in mesh.kinds.iter().zip(&mesh.cells).enumerate() {
        let vol = signed_volume(kind, verts, points);
        let l = max_edge(verts, points);
        if vol.abs() <= DEGENERATE * l * l * l {
            return Err(MeshError::Degenerate {
                cell: c,
                why: "zero volume".into(),
            });
        }
        if vol < 0.0 {
            if !opts.reorient {
                return Err(MeshError::Inverted {
                    cell: c,
                    kind: kind.name(),
                    volume: vol,
                });
            }
            report.reoriented.push(c);
            cells.push(reversed(kind, verts));
        } else {
            cells.push(verts.clone());
        }
    }
    let mut g = GMap::new(3).expect("3 is supported");
    let n_darts: usize = mesh
        .kinds
        .iter()
        .map(|&k| local_faces(k).iter().map(|f| 2 * f.len()).sum::<usize>())
        .sum();
    for a in &mut g.alpha {
        a.reserve(n_darts);
    }
    let mut vert_of_dart: Vec<u32> = Vec::with_capacity(n_darts);
    // sorted face vertices -> (cell, face)
    let mut face_map: std::collections::HashMap<[u32; 4], (u32, BuiltFace)> =
        std::collections::HashMap::with_capacity(mesh.cells.len() * 3);
    let mut local: Vec<BuiltFace> = Vec::with_capacity(6);
    for (c, (&kind, verts)) in mesh.kinds.iter().zip(&cells).enumerate() {
        local.clear();
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
                    return Err(non_manifold_face(&key, &cells, &mesh.kinds));
                }
                Some((other, h)) => {
                    let k = f.len as usize;
                    for j in 0..k {
                        let (u, w) = (f.verts[j], f.verts[(j + 1) % k]);
                        let (Some(hu), Some(hw)) = (h.dart(u, w), h.dart(w, u)) else {
                            return Err(MeshError::NonConforming {
                                a: other as usize,
                                b: c,
                                vertices: key[..k].iter().map(|&v| v as usize).collect(),
                            });
                        };
                        link_raw(&mut g, 3, f.first + 2 * j as u32, hu);
                        link_raw(&mut g, 3, f.first + 2 * j as u32 + 1, hw);
                    }
                    // a third cell on this face is non-manifold: remember the face as used
                    face_map.insert(key, (u32::MAX, h));
                }
            }
        }
    }
    Ok((g, vert_of_dart))
}

fn non_manifold_face(key: &[u32; 4], cells: &[Vec<usize>], kinds: &[CellKind]) -> MeshError {
    let verts: Vec<usize> = key
        .iter()
        .filter(|&&v| v != u32::MAX)
        .map(|&v| v as usize)
        .collect();
    let mut on_face = Vec::new();
    for (c, (cv, &kind)) in cells.iter().zip(kinds).enumerate() {
        for lf in local_faces(kind) {
            let mut fv: Vec<usize> = lf.iter().map(|&l| cv[l]).collect();
            fv.sort_unstable();
            if fv == verts {
                on_face.push(c);
            }
        }
    }
    MeshError::NonManifold {
        what: "face",
        why: "a face joins at most 2 cells",
        vertices: verts,
        cells: on_face,
    }
}

/// Turns a map back into points and cells: one point per vertex orbit (numbered by
/// [`GMap::orbit_labels`]), one cell per face `<0,1>` (2D) or volume `<0,1,2>` (3D), in the
/// order of their smallest dart. Needs the `position` embedding.
pub fn extract(g: &GMap) -> Result<Mesh, MeshError> {
    let n = g.dimension();
    let pos = g
        .embedding_id("position")
        .ok_or_else(|| MeshError::Extract("the map has no 'position' embedding".into()))?;
    let (labels, nv) = g.orbit_labels(OrbitType::vertex(n));
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
    let mut mesh = Mesh {
        points,
        kinds: Vec::new(),
        cells: Vec::new(),
    };
    if n == 2 {
        for d in g.orbit_representatives(OrbitType::face(2)) {
            let verts = face_cycle(g, d, &labels)?;
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
            return Err(MeshError::Extract(format!(
                "the volume of dart {d} has {} vertices and {} faces ({tris} triangles, {quads} quads): not a tetra, hexahedron, wedge or pyramid",
                verts.len(),
                faces.len()
            )))
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
