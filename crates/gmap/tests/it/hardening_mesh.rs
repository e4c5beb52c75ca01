//! Issue 13, mesh side: an overflow is called an overflow, not a degenerate cell; identical
//! cells and cells folded onto each other (on the same side of a shared face) are refused.
//!
//! The overflow and underflow tests fail on the code before the `Overflow` check: a cell at
//! coordinates 1e200 was reported as "degenerate (zero volume)" (its volume, ~1e600, is inf
//! and `inf <= 1e-12 * inf`), and a well-shaped cell of extent 1e-200 as degenerate too (its
//! edge length squared underflows to 0).

use topomech_gmap::mesh::{build, BuildOptions, CellKind, Mesh, MeshError, TINY_SIZE};

fn unit_tet(scale: f64, offset: f64) -> Mesh {
    Mesh {
        points: vec![
            [offset, offset, offset],
            [offset + scale, offset, offset],
            [offset, offset + scale, offset],
            [offset, offset, offset + scale],
        ],
        kinds: vec![CellKind::Tetra],
        cells: vec![vec![0, 1, 2, 3]],
    }
}

fn unit_triangle(scale: f64) -> Mesh {
    Mesh {
        points: vec![[0.0, 0.0, 0.0], [scale, 0.0, 0.0], [0.0, scale, 0.0]],
        kinds: vec![CellKind::Polygon],
        cells: vec![vec![0, 1, 2]],
    }
}

fn refused(m: &Mesh) -> MeshError {
    match build(m, &BuildOptions::default()) {
        Ok(_) => panic!("the mesh was accepted"),
        Err(e) => e,
    }
}

#[test]
fn overflowing_tetrahedron_is_called_an_overflow_not_degenerate() {
    // 1e200: finite coordinates, but the volume ~ (1e200)^3 / 6 is beyond f64::MAX
    let e = refused(&unit_tet(1e200, 0.0));
    let msg = e.to_string();
    match &e {
        MeshError::Overflow { cells } => {
            assert_eq!(cells.len(), 1);
            assert_eq!(cells[0].0, 0);
            assert_eq!(cells[0].1, "tetra");
        }
        other => panic!("expected Overflow, got {other}"),
    }
    assert!(msg.contains("overflows") && msg.contains("volume"), "{msg}");
    assert!(
        msg.contains("1.000e200"),
        "the message names the magnitude: {msg}"
    );
    assert!(!msg.contains("degenerate"), "{msg}");
}

#[test]
fn overflowing_surface_and_hexahedron_are_called_overflows() {
    let e = refused(&unit_triangle(1e160)); // area ~ 1e320 > f64::MAX
    assert!(matches!(e, MeshError::Overflow { .. }), "{e}");
    assert!(e.to_string().contains("its area overflows"), "{e}");
    // a hexahedron goes through the corner-Jacobian test first: that must not call it twisted
    let s = 1e110;
    let mut points = Vec::new();
    for z in [0.0, s] {
        for (x, y) in [(0.0, 0.0), (s, 0.0), (s, s), (0.0, s)] {
            points.push([x, y, z]);
        }
    }
    let hex = Mesh {
        points,
        kinds: vec![CellKind::Hexa],
        cells: vec![(0..8).collect()],
    };
    let e = refused(&hex);
    assert!(matches!(e, MeshError::Overflow { .. }), "{e}");
}

#[test]
fn large_but_representable_cells_are_accepted() {
    // extent 1e100: volume 1.7e299 is finite, as are the squares and triple products; a small
    // cell far from the origin (coordinates 1e15, extent 1) is fine too
    for m in [
        unit_tet(1e100, 0.0),
        unit_tet(1.0, 1e15),
        unit_triangle(1e150),
    ] {
        let (g, _) = build(&m, &BuildOptions::default()).unwrap();
        assert!(g.is_valid());
    }
}

#[test]
fn underflowing_tetrahedron_is_called_an_underflow_not_degenerate() {
    // a regular-shaped tetrahedron of extent 1e-110: extent^3 = 1e-330 is below f64's
    // normal range; before, its edge length (sqrt of an underflowed square) was 0 and the
    // cell "degenerate (zero volume)"
    let e = refused(&unit_tet(1e-110, 0.0));
    match &e {
        MeshError::Overflow { cells } => assert_eq!(cells[0].0, 0),
        other => panic!("expected Overflow, got {other}"),
    }
    let msg = e.to_string();
    assert!(
        msg.contains("underflows") && !msg.contains("degenerate"),
        "{msg}"
    );
    // the bound: extent^3 just above TINY_SIZE is accepted, and measured right
    let ext = (TINY_SIZE * 4.0).cbrt();
    let (g, _) = build(&unit_tet(ext, 0.0), &BuildOptions::default()).unwrap();
    assert!(g.is_valid());
    // nanometre cells (extent 1e-9 m, volume 1.7e-28 m^3) are ordinary
    build(&unit_tet(1e-9, 0.0), &BuildOptions::default()).unwrap();
}

#[test]
fn a_flat_cell_is_still_degenerate_at_any_scale() {
    // four coplanar points: zero volume at scale 1, 1e-60 and 1e90 alike (the check is
    // relative to extent^3)
    for s in [1.0, 1e-60, 1e90] {
        let m = Mesh {
            points: vec![[0.0, 0.0, 0.0], [s, 0.0, 0.0], [0.0, s, 0.0], [s, s, 0.0]],
            kinds: vec![CellKind::Tetra],
            cells: vec![vec![0, 1, 2, 3]],
        };
        let e = refused(&m);
        assert!(matches!(e, MeshError::Degenerate { .. }), "scale {s}: {e}");
    }
    // all four points at one position: degenerate (extent 0), not an underflow
    let m = Mesh {
        points: vec![[1.0, 1.0, 1.0]; 4],
        kinds: vec![CellKind::Tetra],
        cells: vec![vec![0, 1, 2, 3]],
    };
    assert!(matches!(refused(&m), MeshError::Degenerate { .. }));
}

// ------------------------------------------------------------- identical and folded cells

fn two_tets(second: Vec<usize>, apex2: [f64; 3]) -> Mesh {
    Mesh {
        points: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            apex2,
        ],
        kinds: vec![CellKind::Tetra; 2],
        cells: vec![vec![0, 1, 2, 3], second],
    }
}

#[test]
fn identical_cells_are_refused() {
    // the same vertices in another order (even the opposite orientation) are the same cell
    for second in [vec![0, 1, 2, 3], vec![1, 2, 0, 3], vec![0, 2, 1, 3]] {
        let e = refused(&two_tets(second.clone(), [9.0, 9.0, 9.0]));
        assert_eq!(
            e,
            MeshError::Duplicate {
                pairs: vec![(1, 0)]
            },
            "{second:?}"
        );
    }
}

#[test]
fn two_tets_on_the_same_side_of_a_shared_face_are_refused() {
    // face (0, 1, 2) shared; the second apex (0.2, 0.2, 0.5) is on the same side (z > 0) as
    // the first one's: the two cells overlap. Refused as folded, both named.
    let e = refused(&two_tets(vec![0, 2, 1, 4], [0.2, 0.2, 0.5]));
    match e {
        MeshError::Folded { what, pairs } => {
            assert_eq!(what, "face");
            assert_eq!(pairs.len(), 1);
            assert_eq!((pairs[0].0, pairs[0].1), (0, 1));
        }
        other => panic!("expected Folded, got {other}"),
    }
    // apex below the face: a proper neighbour
    let (g, _) = build(
        &two_tets(vec![0, 2, 1, 4], [0.2, 0.2, -0.5]),
        &BuildOptions::default(),
    )
    .unwrap();
    assert!(g.is_valid());
}
