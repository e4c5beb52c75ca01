//! Meshes for tests and demos.

use crate::mesh::{reversed, signed_volume, CellKind, Mesh};

/// Elements of a rectangle grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridElement {
    /// Each square split into two triangles.
    Triangle,
    /// Quads.
    Quad,
    /// Quads on the left half, triangles on the right half.
    Mixed,
}

/// Elements of a box.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoxElement {
    /// Each cube split into 6 tetrahedra around its main diagonal (conforming).
    Tetra,
    /// Hexahedra.
    Hexa,
    /// Each cube split into 2 wedges.
    Wedge,
    /// Each cube split into 6 pyramids around its centre.
    Pyramid,
    /// Hexahedra on the left half; on the right half each cube split into pyramids around its
    /// centre, those not facing a hexahedron split again into 2 tetrahedra.
    Mixed,
}

/// A rectangle `size[0] x size[1]` in the plane z = 0 with `n[0] x n[1]` squares, faces
/// counter-clockwise seen from +z. Point `(i, j)` has index `i + j * (n[0] + 1)`.
pub fn grid(n: [usize; 2], size: [f64; 2], element: GridElement) -> Mesh {
    let [nx, ny] = n;
    let mut mesh = Mesh::default();
    for j in 0..=ny {
        for i in 0..=nx {
            mesh.points.push([
                size[0] * i as f64 / nx.max(1) as f64,
                size[1] * j as f64 / ny.max(1) as f64,
                0.0,
            ]);
        }
    }
    let p = |i: usize, j: usize| i + j * (nx + 1);
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
            let quad = match element {
                GridElement::Quad => true,
                GridElement::Triangle => false,
                GridElement::Mixed => i < nx / 2,
            };
            if quad {
                mesh.kinds.push(CellKind::Polygon);
                mesh.cells.push(vec![a, b, c, d]);
            } else {
                mesh.kinds.extend([CellKind::Polygon; 2]);
                mesh.cells.push(vec![a, b, c]);
                mesh.cells.push(vec![a, c, d]);
            }
        }
    }
    mesh
}

/// A box `size` with `n[0] x n[1] x n[2]` cubes, corner at the origin; every cell positively
/// oriented (VTK order). Point `(i, j, k)` has index `i + (n[0]+1) * (j + (n[1]+1) * k)`;
/// cube centres (pyramid and mixed boxes) come after the grid points.
pub fn cuboid(n: [usize; 3], size: [f64; 3], element: BoxElement) -> Mesh {
    let [nx, ny, nz] = n;
    let mut mesh = Mesh::default();
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                mesh.points.push([
                    size[0] * i as f64 / nx.max(1) as f64,
                    size[1] * j as f64 / ny.max(1) as f64,
                    size[2] * k as f64 / nz.max(1) as f64,
                ]);
            }
        }
    }
    let p = |i: usize, j: usize, k: usize| i + (nx + 1) * (j + (ny + 1) * k);
    let is_hex = |i: usize| match element {
        BoxElement::Hexa => true,
        BoxElement::Mixed => i < nx / 2,
        _ => false,
    };
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                // corner with offsets (x, y, z) in {0,1}: bit 0 = x, bit 1 = y, bit 2 = z
                let c = |b: usize| p(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1));
                let push = |mesh: &mut Mesh, kind: CellKind, verts: Vec<usize>| {
                    let verts = if signed_volume(kind, &verts, &mesh.points) < 0.0 {
                        reversed(kind, &verts)
                    } else {
                        verts
                    };
                    mesh.kinds.push(kind);
                    mesh.cells.push(verts);
                };
                match element {
                    _ if is_hex(i) => {
                        push(
                            &mut mesh,
                            CellKind::Hexa,
                            vec![c(0), c(1), c(3), c(2), c(4), c(5), c(7), c(6)],
                        );
                    }
                    BoxElement::Tetra => {
                        for (a, b) in [(1, 2), (2, 1), (1, 4), (4, 1), (2, 4), (4, 2)] {
                            push(&mut mesh, CellKind::Tetra, vec![c(0), c(a), c(a | b), c(7)]);
                        }
                    }
                    BoxElement::Wedge => {
                        push(
                            &mut mesh,
                            CellKind::Wedge,
                            vec![c(4), c(5), c(7), c(0), c(1), c(3)],
                        );
                        push(
                            &mut mesh,
                            CellKind::Wedge,
                            vec![c(4), c(7), c(6), c(0), c(3), c(2)],
                        );
                    }
                    _ => {
                        // pyramids on each face of the cube, apex at its centre
                        let centre = mesh.points.len();
                        let (a, b) = (mesh.points[c(0)], mesh.points[c(7)]);
                        mesh.points.push([
                            f64::midpoint(a[0], b[0]),
                            f64::midpoint(a[1], b[1]),
                            f64::midpoint(a[2], b[2]),
                        ]);
                        let faces: [([usize; 4], bool); 6] = [
                            ([0, 2, 6, 4], i > 0 && is_hex(i - 1)),
                            ([1, 3, 7, 5], i + 1 < nx && is_hex(i + 1)),
                            ([0, 1, 5, 4], false),
                            ([2, 3, 7, 6], false),
                            ([0, 1, 3, 2], false),
                            ([4, 5, 7, 6], false),
                        ];
                        for (f, faces_hex) in faces {
                            let base = f.map(c);
                            if element == BoxElement::Pyramid || faces_hex {
                                push(
                                    &mut mesh,
                                    CellKind::Pyramid,
                                    vec![base[0], base[1], base[2], base[3], centre],
                                );
                            } else {
                                // two tetrahedra, split along the diagonal through the base
                                // vertex of smallest index, the same on both sides of the face
                                let m = (0..4).min_by_key(|&q| base[q]).expect("4 corners");
                                let r = |q: usize| base[(m + q) % 4];
                                push(&mut mesh, CellKind::Tetra, vec![r(0), r(1), r(2), centre]);
                                push(&mut mesh, CellKind::Tetra, vec![r(0), r(2), r(3), centre]);
                            }
                        }
                    }
                }
            }
        }
    }
    mesh
}
