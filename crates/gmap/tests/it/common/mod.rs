//! Independent counts from point/cell lists, for checking the maps built from them.
#![allow(dead_code, missing_docs)]

use std::collections::{BTreeSet, HashMap};

use topomech_gmap::mesh::{CellKind, Mesh};

/// The faces of a 3D cell as local vertex lists (orientation irrelevant here): written
/// again from the VTK cell definitions, independently of the kernel's tables.
pub fn faces_of(kind: CellKind, v: &[usize]) -> Vec<Vec<usize>> {
    let f: &[&[usize]] = match kind {
        CellKind::Tetra => &[&[0, 1, 2], &[0, 1, 3], &[1, 2, 3], &[0, 2, 3]],
        CellKind::Hexa => &[
            &[0, 1, 2, 3],
            &[4, 5, 6, 7],
            &[0, 1, 5, 4],
            &[1, 2, 6, 5],
            &[2, 3, 7, 6],
            &[3, 0, 4, 7],
        ],
        CellKind::Wedge => &[
            &[0, 1, 2],
            &[3, 4, 5],
            &[0, 1, 4, 3],
            &[1, 2, 5, 4],
            &[2, 0, 3, 5],
        ],
        CellKind::Pyramid => &[
            &[0, 1, 2, 3],
            &[0, 1, 4],
            &[1, 2, 4],
            &[2, 3, 4],
            &[3, 0, 4],
        ],
        CellKind::Polygon => return vec![v.to_vec()],
    };
    f.iter()
        .map(|f| f.iter().map(|&k| v[k]).collect())
        .collect()
}

/// Counts computed from the lists alone.
#[derive(Debug, PartialEq, Eq)]
pub struct Expected {
    pub darts: usize,
    pub vertices: usize,
    pub edges: usize,
    pub faces: usize,
    pub volumes: usize,
    pub components: usize,
    pub boundary: usize,
}

fn find(p: &mut [usize], x: usize) -> usize {
    let mut r = x;
    while p[r] != r {
        r = p[r];
    }
    let mut y = x;
    while p[y] != r {
        let n = p[y];
        p[y] = r;
        y = n;
    }
    r
}

pub fn expected(mesh: &Mesh) -> Expected {
    let dim = mesh.kinds[0].dimension();
    let mut verts = BTreeSet::new();
    let mut edges = BTreeSet::new();
    let mut faces: HashMap<Vec<usize>, Vec<usize>> = HashMap::new();
    let mut darts = 0;
    for (c, (&k, v)) in mesh.kinds.iter().zip(&mesh.cells).enumerate() {
        verts.extend(v.iter().copied());
        for f in faces_of(k, v) {
            darts += 2 * f.len();
            for j in 0..f.len() {
                let (a, b) = (f[j], f[(j + 1) % f.len()]);
                edges.insert((a.min(b), a.max(b)));
            }
            let mut key = f.clone();
            key.sort_unstable();
            faces.entry(key).or_default().push(c);
        }
    }
    // cells joined through a shared edge (2D) or face (3D)
    let n = mesh.cells.len();
    let mut parent: Vec<usize> = (0..n).collect();
    let mut boundary = 0;
    if dim == 2 {
        let mut by_edge: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
        for (c, v) in mesh.cells.iter().enumerate() {
            for j in 0..v.len() {
                let (a, b) = (v[j], v[(j + 1) % v.len()]);
                by_edge.entry((a.min(b), a.max(b))).or_default().push(c);
            }
        }
        for cs in by_edge.values() {
            if cs.len() == 1 {
                boundary += 1;
            }
            for w in cs.windows(2) {
                let (a, b) = (find(&mut parent, w[0]), find(&mut parent, w[1]));
                parent[a] = b;
            }
        }
    } else {
        for cs in faces.values() {
            if cs.len() == 1 {
                boundary += 1;
            }
            for w in cs.windows(2) {
                let (a, b) = (find(&mut parent, w[0]), find(&mut parent, w[1]));
                parent[a] = b;
            }
        }
    }
    let components = (0..n).filter(|&c| find(&mut parent, c) == c).count();
    Expected {
        darts,
        vertices: verts.len(),
        edges: edges.len(),
        faces: if dim == 2 { n } else { faces.len() },
        volumes: if dim == 3 { n } else { 0 },
        components,
        boundary,
    }
}

pub fn actual(g: &topomech_gmap::GMap) -> Expected {
    let c = g.cell_counts();
    Expected {
        darts: c.darts,
        vertices: c.vertices,
        edges: c.edges,
        faces: c.faces,
        volumes: c.volumes,
        components: c.components,
        boundary: c.boundary,
    }
}
