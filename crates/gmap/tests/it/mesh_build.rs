//! Building maps from meshes: counts against independent counts, Euler characteristic,
//! positions, round trips through `extract`, and every refusal of bad input.

// Positions are copied, never computed: exact equality is expected.
#![allow(clippy::float_cmp)]

use crate::common;

use proptest::prelude::*;
use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, extract, BuildOptions, CellKind, Mesh, MeshError};
use topomech_gmap::OrbitType;

fn built(mesh: &Mesh) -> topomech_gmap::GMap {
    let (g, report) = build(mesh, &BuildOptions::default()).expect("valid mesh");
    assert!(report.reoriented.is_empty());
    let v = g.validate();
    assert!(v.is_empty(), "{v:?}");
    g
}

fn check_counts(mesh: &Mesh) {
    let g = built(mesh);
    assert_eq!(common::actual(&g), common::expected(mesh));
}

const GRID: [GridElement; 3] = [GridElement::Triangle, GridElement::Quad, GridElement::Mixed];
const BOX: [BoxElement; 5] = [
    BoxElement::Tetra,
    BoxElement::Hexa,
    BoxElement::Wedge,
    BoxElement::Pyramid,
    BoxElement::Mixed,
];

#[test]
fn every_generator_and_element_has_the_independent_counts() {
    for e in GRID {
        check_counts(&grid([4, 3], [2.0, 1.5], e));
    }
    for e in BOX {
        check_counts(&cuboid([3, 2, 2], [3.0, 2.0, 2.0], e));
    }
}

#[test]
fn mixed_meshes_really_mix() {
    let m = grid([4, 2], [1.0, 1.0], GridElement::Mixed);
    let sizes: std::collections::BTreeSet<usize> = m.cells.iter().map(Vec::len).collect();
    assert_eq!(sizes.into_iter().collect::<Vec<_>>(), vec![3, 4]);
    let m = cuboid([4, 2, 2], [1.0, 1.0, 1.0], BoxElement::Mixed);
    for k in [CellKind::Hexa, CellKind::Pyramid, CellKind::Tetra] {
        assert!(m.kinds.contains(&k), "{k:?} missing");
    }
}

#[test]
fn positions_land_on_vertex_orbits() {
    let m = cuboid([2, 2, 2], [1.0, 2.0, 3.0], BoxElement::Tetra);
    let g = built(&m);
    let pos = g.require("position").unwrap();
    assert_eq!(g.embedding(pos).orbit(), OrbitType::vertex(3));
    // every dart's position is one of its cell's points, and the vertex orbit agrees
    let back = extract(&g).unwrap();
    assert_eq!(back.points.len(), m.points.len());
    let mut a = m.points.clone();
    let mut b = back.points.clone();
    a.sort_by(|x, y| x.partial_cmp(y).unwrap());
    b.sort_by(|x, y| x.partial_cmp(y).unwrap());
    assert_eq!(a, b);
}

/// Extracting gives a mesh whose map has the same counts and the same total volume.
#[test]
fn extract_round_trips_every_element() {
    for e in BOX {
        let m = cuboid([2, 2, 1], [2.0, 2.0, 1.0], e);
        let g = built(&m);
        let back = extract(&g).unwrap();
        assert_eq!(back.cells.len(), m.cells.len());
        let vol = |m: &Mesh| -> f64 {
            m.kinds
                .iter()
                .zip(&m.cells)
                .map(|(&k, c)| topomech_gmap::mesh::signed_volume(k, c, &m.points))
                .sum()
        };
        assert!((vol(&back) - 4.0).abs() < 1e-12, "{e:?}: {}", vol(&back));
        assert!(back
            .kinds
            .iter()
            .zip(&back.cells)
            .all(|(&k, c)| topomech_gmap::mesh::signed_volume(k, c, &back.points) > 0.0));
        let g2 = built(&back);
        assert_eq!(common::actual(&g2), common::actual(&g));
    }
    for e in GRID {
        let m = grid([3, 2], [1.0, 1.0], e);
        let back = extract(&built(&m)).unwrap();
        assert_eq!(common::actual(&built(&back)), common::expected(&m));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// V - E + F = 1 for a grid (a disk) and V - E + F - C = 1 for a box (a ball).
    #[test]
    fn euler_characteristic_of_generated_meshes(nx in 1usize..6, ny in 1usize..6, nz in 1usize..4, e in 0usize..5) {
        let g = built(&grid([nx, ny], [1.0, 1.0], GRID[e % 3]));
        let c = g.cell_counts();
        prop_assert_eq!(c.vertices as i64 - c.edges as i64 + c.faces as i64, 1);
        prop_assert_eq!(c.vertices, (nx + 1) * (ny + 1));
        prop_assert_eq!(c.boundary, 2 * (nx + ny));
        let m = cuboid([nx, ny, nz], [1.0, 1.0, 1.0], BOX[e]);
        let g = built(&m);
        let c = g.cell_counts();
        prop_assert_eq!(c.vertices as i64 - c.edges as i64 + c.faces as i64 - c.volumes as i64, 1);
        prop_assert_eq!(c.components, 1);
        prop_assert_eq!(common::actual(&g), common::expected(&m));
    }
}

fn tet_mesh(cells: Vec<Vec<usize>>, points: Vec<[f64; 3]>) -> Mesh {
    Mesh {
        kinds: vec![CellKind::Tetra; cells.len()],
        cells,
        points,
    }
}

fn unit_tet_points() -> Vec<[f64; 3]> {
    vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 1.0, 1.0],
    ]
}

#[test]
fn out_of_range_vertex_names_the_cell() {
    // every index past the points is named, in one error
    let m = tet_mesh(
        vec![vec![0, 1, 2, 3], vec![1, 2, 3, 9], vec![7, 2, 3, 8]],
        unit_tet_points(),
    );
    let e = build(&m, &BuildOptions::default()).unwrap_err();
    assert_eq!(
        e,
        MeshError::VertexOutOfRange {
            cells: vec![(1, 9), (2, 7), (2, 8)],
            n_points: 5
        }
    );
    assert!(e.to_string().contains("cell 1 refers to vertex 9"), "{e}");
}

#[test]
fn wrong_vertex_count_is_refused() {
    let m = Mesh {
        kinds: vec![CellKind::Hexa],
        cells: vec![vec![0, 1, 2, 3]],
        points: unit_tet_points(),
    };
    assert_eq!(
        build(&m, &BuildOptions::default()).unwrap_err(),
        MeshError::VertexCount {
            cells: vec![(0, "hexahedron", 4, 8)]
        }
    );
    let m = Mesh {
        kinds: vec![CellKind::Polygon],
        cells: vec![vec![0, 1]],
        points: unit_tet_points(),
    };
    assert!(matches!(
        build(&m, &BuildOptions::default()),
        Err(MeshError::VertexCount { cells }) if cells == vec![(0, "polygon", 2, 3)]
    ));
    // every offending cell at once
    let m = Mesh {
        kinds: vec![CellKind::Tetra, CellKind::Tetra, CellKind::Hexa],
        cells: vec![vec![0, 1, 2], vec![0, 1, 2, 3], vec![0, 1, 2, 3]],
        points: unit_tet_points(),
    };
    let e = build(&m, &BuildOptions::default()).unwrap_err();
    assert_eq!(
        e,
        MeshError::VertexCount {
            cells: vec![(0, "tetra", 3, 4), (2, "hexahedron", 4, 8)]
        }
    );
    assert!(e.to_string().starts_with("2 cell(s) with a wrong number of vertices: cell 0 is a tetra with 3 vertices, expected 4; cell 2"), "{e}");
}

#[test]
fn degenerate_elements_are_refused() {
    let m = tet_mesh(vec![vec![0, 1, 1, 3]], unit_tet_points());
    assert!(matches!(
        build(&m, &BuildOptions::default()),
        Err(MeshError::Degenerate { ref cells }) if cells[0].0 == 0
    ));
    let flat = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ];
    let m = tet_mesh(vec![vec![0, 1, 2, 3]], flat.clone());
    let e = build(&m, &BuildOptions::default()).unwrap_err();
    assert!(
        matches!(e, MeshError::Degenerate { ref cells } if cells[0].0 == 0),
        "{e}"
    );
    let m = Mesh {
        kinds: vec![CellKind::Polygon],
        cells: vec![vec![0, 1, 1]],
        points: flat.clone(),
    };
    assert!(matches!(
        build(&m, &BuildOptions::default()),
        Err(MeshError::Degenerate { ref cells }) if cells[0].0 == 0
    ));
    let line = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
    let m = Mesh {
        kinds: vec![CellKind::Polygon],
        cells: vec![vec![0, 1, 2]],
        points: line,
    };
    assert!(matches!(
        build(&m, &BuildOptions::default()),
        Err(MeshError::Degenerate { ref cells }) if cells[0].0 == 0
    ));
}

#[test]
fn inverted_tet_is_refused_or_repaired_with_a_report() {
    let m = tet_mesh(vec![vec![0, 1, 2, 3], vec![1, 3, 2, 4]], unit_tet_points());
    // cell 1 = (1,3,2,4): is it inverted? compute independently
    let p = unit_tet_points();
    let s = |c: &[usize]| {
        let d = |k: usize| {
            [
                p[c[k]][0] - p[c[0]][0],
                p[c[k]][1] - p[c[0]][1],
                p[c[k]][2] - p[c[0]][2],
            ]
        };
        let (a, b, e) = (d(1), d(2), d(3));
        a[0] * (b[1] * e[2] - b[2] * e[1]) - a[1] * (b[0] * e[2] - b[2] * e[0])
            + a[2] * (b[0] * e[1] - b[1] * e[0])
    };
    assert!(s(&m.cells[0]) > 0.0 && s(&m.cells[1]) < 0.0);
    let no = BuildOptions {
        reorient: false,
        ..BuildOptions::default()
    };
    let e = build(&m, &no).unwrap_err();
    match &e {
        MeshError::Inverted { cells } => assert_eq!(cells.len(), 1, "{e}"),
        other => panic!("{other}"),
    }
    assert!(
        matches!(&e, MeshError::Inverted { cells } if cells[0].0 == 1),
        "{e}"
    );
    // the message names the cell, not an option (callers add the option in their syntax)
    assert!(e.to_string().contains("cell 1"), "{e}");
    assert!(!e.to_string().contains("reorient"), "{e}");
    assert_eq!(e.option(), Some(("reorient", "true")));
    let (g, report) = build(&m, &BuildOptions::default()).unwrap();
    assert_eq!(report.reoriented, vec![1]);
    assert!(g.is_valid());
    assert_eq!(g.cell_counts().faces, 7);
    assert_eq!(
        g.cell_counts().components,
        1,
        "the repaired tets are sewn by alpha3"
    );
}

#[test]
fn non_manifold_face_names_the_cells() {
    let mut p = unit_tet_points();
    p.push([-0.5, -0.5, -0.5]);
    p.push([0.9, 0.9, 0.9]);
    // three tets on face (1,2,3)
    let mut m = tet_mesh(
        vec![vec![0, 1, 2, 3], vec![1, 3, 2, 4], vec![1, 3, 2, 6]],
        p,
    );
    let e = build(&m, &BuildOptions::default()).unwrap_err();
    match e {
        MeshError::NonManifold {
            what: "face",
            items,
            ..
        } => {
            assert_eq!(items, vec![(vec![1, 2, 3], vec![0, 1, 2])]);
        }
        other => panic!("{other}"),
    }
    // two tets touching at one vertex only: a pinched point, accepted by default (one
    // particle), refused with Pinched::Refuse (tests/import_kinds.rs checks the rest)
    m.points
        .extend([[2.0, 0.0, 1.0], [0.0, 2.0, 1.0], [0.0, 0.0, 3.0]]);
    m.cells = vec![vec![0, 1, 2, 3], vec![3, 7, 8, 9]];
    m.kinds.truncate(2);
    let (_, report) = build(&m, &BuildOptions::default()).unwrap();
    assert_eq!(report.pinched, vec![3]);
    let refuse = BuildOptions {
        pinched: topomech_gmap::mesh::Pinched::Refuse,
        ..BuildOptions::default()
    };
    let e = build(&m, &refuse).unwrap_err();
    assert!(
        matches!(&e, MeshError::Pinched { points } if points == &vec![(3, vec![0, 1])]),
        "{e}"
    );
}

#[test]
fn non_manifold_edge_in_2d() {
    let p = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.5, 1.0, 0.0],
        [0.5, -1.0, 0.0],
        [0.5, 0.0, 1.0],
    ];
    let m = Mesh {
        kinds: vec![CellKind::Polygon; 3],
        cells: vec![vec![0, 1, 2], vec![1, 0, 3], vec![0, 1, 4]],
        points: p,
    };
    let e = build(&m, &BuildOptions::default()).unwrap_err();
    match e {
        MeshError::NonManifold {
            what: "edge",
            items,
            ..
        } => {
            assert_eq!(items, vec![(vec![0, 1], vec![0, 1, 2])]);
        }
        other => panic!("{other}"),
    }
}

#[test]
fn surface_orientation_is_checked_and_repaired() {
    let mut m = grid([2, 2], [1.0, 1.0], GridElement::Quad);
    m.cells[3].reverse();
    let no = BuildOptions {
        reorient: false,
        ..BuildOptions::default()
    };
    let e = build(&m, &no).unwrap_err();
    assert!(matches!(e, MeshError::Orientation { .. }), "{e}");
    let (g, report) = build(&m, &BuildOptions::default()).unwrap();
    assert_eq!(report.reoriented, vec![3]);
    assert_eq!(
        common::actual(&g),
        common::expected(&grid([2, 2], [1.0, 1.0], GridElement::Quad))
    );
}

#[test]
fn non_finite_points_and_empty_meshes_are_refused() {
    let mut p = unit_tet_points();
    p[2][1] = f64::NAN;
    let m = tet_mesh(vec![vec![0, 1, 2, 3]], p);
    assert!(matches!(
        build(&m, &BuildOptions::default()),
        Err(MeshError::NonFinite { ref points }) if points.len() == 1 && points[0].0 == 2
    ));
    assert_eq!(
        build(&Mesh::default(), &BuildOptions::default()).unwrap_err(),
        MeshError::Empty
    );
    // a polygon of another dimension is named as a mesh file names it: a triangle, a quad
    let m = Mesh {
        kinds: vec![CellKind::Tetra, CellKind::Polygon, CellKind::Polygon],
        cells: vec![vec![0, 1, 2, 3], vec![0, 1, 2], vec![0, 1, 2, 3]],
        points: unit_tet_points(),
    };
    let e = build(&m, &BuildOptions::default()).unwrap_err();
    assert_eq!(
        e,
        MeshError::MixedDimension {
            cells: vec![(1, "triangle"), (2, "quad")],
            dim: 3
        }
    );
    assert!(e.to_string().contains("cell 1 is a triangle"), "{e}");
}

#[test]
fn non_conforming_faces_are_refused() {
    // two hexes sharing 4 vertices whose quad faces list them in different cyclic orders
    let mut m = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Hexa);
    // move the shared face's vertices of cell 1 into a twisted order by swapping two
    // points' roles in a copy of the shared face: x = 1 face is (1, 4, 10, 7) in cell 0
    let c1 = m.cells[1].clone();
    // VTK hex: bottom 0..3, top 4..7; swap vertices 0 and 3 on the x=1 side (a twist)
    m.cells[1] = vec![c1[3], c1[1], c1[2], c1[0], c1[4], c1[5], c1[6], c1[7]];
    let e = build(&m, &BuildOptions::default()).unwrap_err();
    assert!(
        matches!(
            e,
            MeshError::NonConforming { .. }
                | MeshError::Twisted { .. }
                | MeshError::Degenerate { .. }
                | MeshError::NonManifold { .. }
        ),
        "{e}"
    );
}

#[test]
fn unused_points_are_reported() {
    let mut p = unit_tet_points();
    p.push([5.0, 5.0, 5.0]);
    let m = tet_mesh(vec![vec![0, 1, 2, 3]], p);
    let (g, report) = build(&m, &BuildOptions::default()).unwrap();
    assert_eq!(report.unused_points, vec![4, 5]);
    assert_eq!(g.cell_counts().vertices, 4);
}

/// Six times the volume the face cycles enclose, each face fanned from its first point to the
/// polyhedron's first point (divergence theorem; positive for outward normals).
fn volume6(points: &[[f64; 3]], faces: &[Vec<usize>]) -> f64 {
    let o = points[faces[0][0]];
    let d = |i: usize| {
        let p = points[i];
        [p[0] - o[0], p[1] - o[1], p[2] - o[2]]
    };
    let mut v6 = 0.0;
    for f in faces {
        for k in 1..f.len() - 1 {
            let (a, b, c) = (d(f[0]), d(f[k]), d(f[k + 1]));
            v6 += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]);
        }
    }
    v6
}

/// `cycle` started at its smallest point, in the same direction.
fn canonical(cycle: &[usize]) -> Vec<usize> {
    let k = (0..cycle.len()).min_by_key(|&k| cycle[k]).expect("a face");
    cycle[k..].iter().chain(&cycle[..k]).copied().collect()
}

/// `extract_polyhedra` on every kind of volume cell (and a mixed box), on a box sheared by a
/// linear map of determinant 1 (faces stay planar, the volume stays 3), checked against the cells `extract` gives and against
/// geometry computed here: each polyhedron has its cell's points and its kind's number of
/// faces; the volumes its faces enclose (fanned to a point of the cell, normals by the
/// right-hand rule) are positive and add up to the box's volume (to rounding: 1e-12 of it,
/// for sums of a few hundred products of order-one coordinates); every interior face is
/// listed twice, in opposite directions, and every boundary face once.
#[test]
fn polyhedra_are_the_cells_with_outward_faces() {
    use std::collections::HashMap;
    use topomech_gmap::mesh::extract_polyhedra;
    for e in BOX {
        let mut mesh = cuboid([3, 2, 2], [2.0, 1.0, 1.5], e);
        for p in &mut mesh.points {
            p[0] += 0.1 * p[1] + 0.05 * p[2];
        }
        let g = built(&mesh);
        let cells = extract(&g).expect("extracts");
        let (points, polys) = extract_polyhedra(&g).expect("polyhedra");
        assert_eq!(points, cells.points);
        assert_eq!(polys.len(), cells.cells.len(), "{e:?}");
        let mut total = 0.0;
        // every face's cycle (started at its smallest point) by its point set: an interior
        // face is listed by both its cells, running opposite ways
        // the cell beside it
        let mut face_keys: HashMap<Vec<usize>, Vec<Vec<usize>>> = HashMap::new();
        for ((faces, verts), kind) in polys.iter().zip(&cells.cells).zip(&cells.kinds) {
            let want = match kind {
                CellKind::Tetra => 4,
                CellKind::Hexa => 6,
                CellKind::Wedge | CellKind::Pyramid => 5,
                CellKind::Polygon => unreachable!("a 3D map"),
            };
            assert_eq!(faces.len(), want, "{kind:?}");
            let mut seen: Vec<usize> = faces.iter().flatten().copied().collect();
            seen.sort_unstable();
            seen.dedup();
            let mut cell: Vec<usize> = verts.clone();
            cell.sort_unstable();
            assert_eq!(seen, cell, "{kind:?}");
            let v6 = volume6(&points, faces);
            for f in faces {
                let mut key = f.clone();
                key.sort_unstable();
                face_keys.entry(key).or_default().push(canonical(f));
            }
            assert!(v6 > 0.0, "{kind:?}: {v6}");
            total += v6 / 6.0;
        }
        assert!((total - 3.0).abs() < 1e-12 * 3.0, "{e:?}: {total}");
        // mirrored (x -> -x) in the map itself, the walk's faces point in: all reversed
        let mut m = g.clone();
        let pos = m.embedding_id("position").expect("position");
        for d in m.orbit_representatives(OrbitType::vertex(3)) {
            let p = m.real(pos, d).to_vec();
            m.set_real(pos, d, &[-p[0], p[1], p[2]]).expect("writes");
        }
        let (mirrored, mpolys) = extract_polyhedra(&m).expect("polyhedra");
        // mirrored and tiny, the same cycles (the products of three differences of 1e-110
        // underflow to 0, and the reversal was missed; the orientation test works in units
        // of the cell's extent)
        let mut t = m.clone();
        for d in t.orbit_representatives(OrbitType::vertex(3)) {
            let p = t.real(pos, d).to_vec();
            t.set_real(pos, d, &p.iter().map(|v| v * 1e-110).collect::<Vec<_>>())
                .expect("writes");
        }
        assert_eq!(
            extract_polyhedra(&t).expect("polyhedra").1,
            mpolys,
            "{e:?} tiny"
        );
        let mut mtotal = 0.0;
        for (faces, same) in mpolys.iter().zip(&polys) {
            let v6 = volume6(&mirrored, faces);
            assert!(v6 > 0.0, "{e:?} mirrored: {v6}");
            mtotal += v6 / 6.0;
            // the same faces, each run the other way from the same first point
            for (f, h) in faces.iter().zip(same) {
                let mut r = h.clone();
                r[1..].reverse();
                assert_eq!(f, &r, "{e:?}");
            }
        }
        assert!((mtotal - 3.0).abs() < 1e-12 * 3.0, "{e:?}: {mtotal}");
        let boundary = face_keys.values().filter(|c| c.len() == 1).count();
        for (key, cycles) in &face_keys {
            assert!(
                cycles.len() <= 2,
                "{e:?}: face {key:?} listed {} times",
                cycles.len()
            );
            if let [a, b] = &cycles[..] {
                let mut r = a.clone();
                r[1..].reverse();
                assert_eq!(
                    &r, b,
                    "{e:?}: face {key:?} runs the same way from both cells"
                );
            }
        }
        assert!(boundary > 0, "{e:?}");
    }
}
