//! Geometric conventions and element validity the import enforces beyond topology: the
//! positive wedge is Gmsh's and VTK's (its base counter-clockwise seen from its top, like a
//! hexahedron's) and polygons are star-shaped around their vertex centroid (the rules compute
//! areas and masses as the fan of triangles from it). Exact predicates: the cells are
//! far from the tolerances.

use topomech_gmap::mesh::{build, signed_volume, BuildOptions, CellKind, Mesh, MeshError};

fn mesh(kind: CellKind, points: Vec<[f64; 3]>, cells: Vec<Vec<usize>>) -> Mesh {
    Mesh {
        kinds: vec![kind; cells.len()],
        cells,
        points,
    }
}

#[test]
fn a_gmsh_prism_is_positive_and_kept_as_written() {
    let points = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [0.0, 1.0, 1.0],
    ];
    let cell: Vec<usize> = (0..6).collect();
    assert!((signed_volume(CellKind::Wedge, &cell, &points) - 0.5).abs() < 1e-15);
    let m = mesh(CellKind::Wedge, points, vec![cell]);
    let opts = BuildOptions {
        reorient: false,
        ..BuildOptions::default()
    };
    let (g, report) = build(&m, &opts).unwrap();
    assert!(report.reoriented.is_empty());
    assert!(g.is_valid());
}

fn twisted(m: &Mesh) -> Vec<(usize, &'static str, String)> {
    match build(m, &BuildOptions::default()) {
        Err(MeshError::Twisted { cells }) => cells,
        other => panic!("expected a twisted cell, got {other:?}"),
    }
}

#[test]
fn a_concave_quad_hiding_a_side_is_refused_and_a_flat_corner_is_kept() {
    let p = vec![
        [0.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [0.5, 0.5, 0.0],
        [0.0, 2.0, 0.0],
        [1.0, 0.0, 0.0],
    ];
    // concave at point 2: its vertex centroid (0.625, 0.625) sees side (1, 2) from behind
    let m = mesh(CellKind::Polygon, p.clone(), vec![vec![0, 1, 2, 3]]);
    let cells = twisted(&m);
    assert!(cells[0].2.contains("side (1, 2)"), "{cells:?}");
    // named as the file names it: a quad, not a polygon (QA)
    assert_eq!(cells[0].1, "quad");
    // a 180-degree corner at point 4 (a vertex on the side from 0 to 1): area 2, accepted
    let m = mesh(CellKind::Polygon, p, vec![vec![0, 4, 1, 3]]);
    assert!(build(&m, &BuildOptions::default()).is_ok());
}

#[test]
fn polygons_must_be_star_shaped_around_their_vertex_centroid() {
    // a notched pentagon: concave at (2, 3) but every side seen from its vertex centroid
    // (2, 2.2): accepted
    let notched = vec![
        [0.0, 0.0, 0.0],
        [4.0, 0.0, 0.0],
        [4.0, 4.0, 0.0],
        [2.0, 3.0, 0.0],
        [0.0, 4.0, 0.0],
    ];
    let m = mesh(CellKind::Polygon, notched, vec![(0..5).collect()]);
    assert!(build(&m, &BuildOptions::default()).is_ok());
    // a thin C: its vertex centroid lies in the gap, so the inner side is seen from behind
    let c_shape = vec![
        [0.0, 0.0, 0.0],
        [3.0, 0.0, 0.0],
        [3.0, 0.2, 0.0],
        [0.2, 0.2, 0.0],
        [0.2, 2.8, 0.0],
        [3.0, 2.8, 0.0],
        [3.0, 3.0, 0.0],
        [0.0, 3.0, 0.0],
    ];
    let m = mesh(CellKind::Polygon, c_shape, vec![(0..8).collect()]);
    let cells = twisted(&m);
    assert!(cells[0].2.contains("not star-shaped"), "{cells:?}");
    assert_eq!(cells[0].1, "polygon");
}
