//! Meshes for tests and demos.

use crate::mesh::Mesh;

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

/// A rectangle `size[0] x size[1]` in the plane z = 0 with `n[0] x n[1]` squares.
pub fn grid(n: [usize; 2], size: [f64; 2], element: GridElement) -> Mesh {
    let _ = (n, size, element);
    todo!()
}

/// A box `size` with `n[0] x n[1] x n[2]` cubes, corner at the origin.
pub fn cuboid(n: [usize; 3], size: [f64; 3], element: BoxElement) -> Mesh {
    let _ = (n, size, element);
    todo!()
}
