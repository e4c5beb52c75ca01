//! Mesh import, kind by kind (issue 12): what `build` accepts (turned cells, non-orientable
//! surfaces, pinched points, merged duplicates) and what it refuses (folds, duplicates,
//! non-conforming interfaces, twisted cells), in 2D and 3D, with every offender named by its
//! input index; and the numbering it writes (`point_id`, `particle`, `cell_id`).
//!
//! The meshes are made here, with coordinates chosen so that the expected answer is known by
//! construction (which cells are inverted, which points are hanging, ...). Positions and
//! indices are copied, never computed, so equality is exact.

// Coordinates are copied, never computed: exact equality is expected.
#![allow(clippy::float_cmp)]

use std::collections::{BTreeMap, BTreeSet};

use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{
    build, extract, signed_volume, BuildOptions, BuildReport, CellKind, Duplicates, Mesh,
    MeshError, Pinched,
};
use topomech_gmap::{Dart, GMap, OrbitType, Value};

fn ok(mesh: &Mesh, opts: &BuildOptions) -> (GMap, BuildReport) {
    let (g, report) = build(mesh, opts).unwrap_or_else(|e| panic!("refused: {e}"));
    let v = g.validate();
    assert!(v.is_empty(), "{v:?}");
    (g, report)
}

fn refused(mesh: &Mesh, opts: &BuildOptions) -> MeshError {
    match build(mesh, opts) {
        Ok(_) => panic!("accepted"),
        Err(e) => e,
    }
}

fn no_reorient() -> BuildOptions {
    BuildOptions {
        reorient: false,
        ..BuildOptions::default()
    }
}

fn int(g: &GMap, name: &str, d: Dart) -> i64 {
    let id = g.require(name).unwrap();
    match g.value(id, d).unwrap() {
        Value::Int(x) => x,
        other => panic!("{name} is not an int: {other:?}"),
    }
}

/// For each vertex orbit (by its smallest dart): (`point_id`, `particle`).
fn vertex_rows(g: &GMap) -> Vec<(Dart, i64, i64)> {
    g.orbit_representatives(OrbitType::vertex(g.dimension()))
        .into_iter()
        .map(|d| (d, int(g, "point_id", d), int(g, "particle", d)))
        .collect()
}

// ------------------------------------------------------------------ orientation

/// Each 3D kind listed with its two orientations: the mirrored cells are turned, listed in
/// the report, the map is the one of the unmirrored mesh, and every extracted cell has a
/// positive volume. Without reorient, every mirrored cell is named in one error.
#[test]
fn inverted_cells_of_every_3d_kind_are_turned() {
    // mirror permutations written out here (not the library's `reversed`)
    let mirror = |k: CellKind, v: &[usize]| -> Vec<usize> {
        let p: &[usize] = match k {
            CellKind::Tetra => &[1, 0, 2, 3],
            CellKind::Hexa => &[3, 2, 1, 0, 7, 6, 5, 4],
            CellKind::Wedge => &[0, 2, 1, 3, 5, 4],
            CellKind::Pyramid => &[1, 0, 3, 2, 4],
            CellKind::Polygon => unreachable!(),
        };
        p.iter().map(|&i| v[i]).collect()
    };
    for e in [
        BoxElement::Tetra,
        BoxElement::Hexa,
        BoxElement::Wedge,
        BoxElement::Pyramid,
        BoxElement::Mixed,
    ] {
        let good = cuboid([3, 2, 2], [3.0, 2.0, 2.0], e);
        let mut m = good.clone();
        let turned: Vec<usize> = (0..m.cells.len()).filter(|c| c % 3 == 1).collect();
        for &c in &turned {
            m.cells[c] = mirror(m.kinds[c], &m.cells[c]);
            assert!(signed_volume(m.kinds[c], &m.cells[c], &m.points) < 0.0);
        }
        let (g, report) = ok(&m, &BuildOptions::default());
        assert_eq!(report.reoriented, turned, "{e:?}");
        let (g0, _) = ok(&good, &BuildOptions::default());
        assert_eq!(g.cell_counts(), g0.cell_counts(), "{e:?}");
        let back = extract(&g).unwrap();
        for (k, c) in back.kinds.iter().zip(&back.cells) {
            assert!(signed_volume(*k, c, &back.points) > 0.0);
        }
        let err = refused(&m, &no_reorient());
        match &err {
            MeshError::Inverted { cells } => {
                let named: Vec<usize> = cells.iter().map(|c| c.0).collect();
                assert_eq!(named, turned, "{e:?}: every inverted cell is named");
            }
            other => panic!("{e:?}: {other}"),
        }
        assert_eq!(err.option(), Some(("reorient", "true")));
    }
}

/// A triangle and a quad-triangle surface with some faces listed the other way round (as in
/// scikit-fem's meshes): the fewer faces of each component are turned; without reorient the
/// error lists every disagreeing edge.
#[test]
fn mixed_surface_orientations_are_made_consistent() {
    for e in [GridElement::Triangle, GridElement::Mixed] {
        let good = grid([4, 3], [4.0, 3.0], e);
        let mut m = good.clone();
        let turned = vec![1, 4, 7];
        for &c in &turned {
            m.cells[c].reverse();
        }
        let (g, report) = ok(&m, &BuildOptions::default());
        assert_eq!(report.reoriented, turned);
        assert!(!report.non_orientable);
        let (g0, _) = ok(&good, &BuildOptions::default());
        assert_eq!(g.cell_counts(), g0.cell_counts());
        // every face has the orientation of the unturned ones: normal +z as generated
        let back = extract(&g).unwrap();
        for c in &back.cells {
            let p = |k: usize| back.points[c[k]];
            let (a, b, d) = (p(0), p(1), p(2));
            let z = (b[0] - a[0]) * (d[1] - a[1]) - (b[1] - a[1]) * (d[0] - a[0]);
            assert!(z > 0.0);
        }
        match refused(&m, &no_reorient()) {
            MeshError::Orientation { pairs } => {
                let faces: BTreeSet<usize> = pairs.iter().flat_map(|p| [p.0, p.1]).collect();
                for c in &turned {
                    assert!(faces.contains(c), "face {c} is named");
                }
                // one pair per edge between a turned and an unturned face
                let mut uses: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
                for (f, c) in good.cells.iter().enumerate() {
                    for j in 0..c.len() {
                        let (a, b) = (c[j], c[(j + 1) % c.len()]);
                        uses.entry((a.min(b), a.max(b))).or_default().push(f);
                    }
                }
                let expected = uses
                    .values()
                    .filter(|f| f.len() == 2 && (turned.contains(&f[0]) != turned.contains(&f[1])))
                    .count();
                assert_eq!(pairs.len(), expected);
            }
            other => panic!("{other}"),
        }
    }
    // two components: each is oriented on its own (the second one's majority wins)
    let mut m = grid([2, 1], [2.0, 1.0], GridElement::Triangle);
    let n = m.points.len();
    let shifted: Vec<[f64; 3]> = m.points.iter().map(|p| [p[0] + 10.0, p[1], p[2]]).collect();
    m.points.extend(shifted);
    let mut second: Vec<Vec<usize>> = m
        .cells
        .iter()
        .map(|c| c.iter().rev().map(|v| v + n).collect())
        .collect();
    second[0].reverse(); // one face of the second copy agrees with the first copy
    m.cells.extend(second);
    m.kinds = vec![CellKind::Polygon; m.cells.len()];
    let (_, report) = ok(&m, &BuildOptions::default());
    assert_eq!(report.reoriented, vec![4]);
}

/// A Moebius strip of quads: non-orientable, still a valid G-map (V - E + F = 0, one
/// boundary curve of 2n edges), accepted and reported; refused without reorient.
#[test]
fn moebius_strip_is_a_valid_map() {
    let n = 12;
    let (r, w) = (3.0, 0.5);
    let mut points = Vec::new();
    for i in 0..n {
        let t = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
        let (c, s) = (t.cos(), t.sin());
        let (cp, sp) = ((t / 2.0).cos(), (t / 2.0).sin());
        for sign in [-1.0, 1.0] {
            points.push([
                (r + sign * w * cp) * c,
                (r + sign * w * cp) * s,
                sign * w * sp,
            ]);
        }
    }
    let a = |i: usize| 2 * i;
    let b = |i: usize| 2 * i + 1;
    let mut cells: Vec<Vec<usize>> = (0..n - 1)
        .map(|i| vec![a(i), b(i), b(i + 1), a(i + 1)])
        .collect();
    // after a half turn, a(n) sits at b(0) and b(n) at a(0)
    cells.push(vec![a(n - 1), b(n - 1), a(0), b(0)]);
    let m = Mesh {
        kinds: vec![CellKind::Polygon; n],
        cells,
        points,
    };
    let (g, report) = ok(&m, &BuildOptions::default());
    assert!(report.non_orientable);
    let c = g.cell_counts();
    assert_eq!((c.vertices, c.edges, c.faces), (2 * n, 3 * n, n));
    assert_eq!(c.boundary, 2 * n);
    assert!(matches!(
        refused(&m, &no_reorient()),
        MeshError::Orientation { .. }
    ));
}

// ------------------------------------------------------------------ folds

/// Two tetrahedra on the same side of their shared face overlap: refused, both pairs named
/// at once; on opposite sides they build.
#[test]
fn folded_tetrahedra_are_refused() {
    let points = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.2, 0.2, 1.0],
        [0.3, 0.3, 2.0],  // same side as 3
        [0.2, 0.2, -1.0], // the other side
    ];
    let mut pts = points.clone();
    pts.extend(points.iter().map(|p| [p[0] + 5.0, p[1], p[2]]));
    let m = Mesh {
        kinds: vec![CellKind::Tetra; 4],
        cells: vec![
            vec![0, 1, 2, 3],
            vec![0, 2, 1, 4],
            vec![6, 7, 8, 9],
            vec![6, 7, 8, 10],
        ],
        points: pts,
    };
    match refused(&m, &BuildOptions::default()) {
        MeshError::Folded { what, pairs } => {
            assert_eq!(what, "face");
            let named: Vec<(usize, usize)> = pairs.iter().map(|p| (p.0, p.1)).collect();
            assert_eq!(named, vec![(0, 1), (2, 3)]);
            let mut f = pairs[0].2.clone();
            f.sort_unstable();
            assert_eq!(f, vec![0, 1, 2]);
        }
        other => panic!("{other}"),
    }
    let good = Mesh {
        kinds: vec![CellKind::Tetra; 2],
        cells: vec![vec![0, 1, 2, 3], vec![0, 1, 2, 5]],
        points,
    };
    let (g, report) = ok(&good, &BuildOptions::default());
    assert_eq!(report.reoriented, vec![1]);
    assert_eq!(g.cell_counts().components, 1);
}

/// In a planar 2D mesh, two triangles with their third points on the same side of the
/// shared edge are folded: refused, named.
#[test]
fn folded_planar_faces_are_refused() {
    let points = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.5, 1.0, 0.0],
        [0.6, 0.5, 0.0],  // same side of (0, 1) as 2
        [0.5, -1.0, 0.0], // the other side
    ];
    let m = Mesh {
        kinds: vec![CellKind::Polygon; 2],
        cells: vec![vec![0, 1, 2], vec![1, 0, 3]],
        points: points.clone(),
    };
    match refused(&m, &BuildOptions::default()) {
        MeshError::Folded { what, pairs } => {
            assert_eq!(what, "edge");
            assert_eq!(pairs, vec![(0, 1, vec![0, 1])]);
        }
        other => panic!("{other}"),
    }
    let good = Mesh {
        kinds: vec![CellKind::Polygon; 2],
        cells: vec![vec![0, 1, 2], vec![0, 1, 4]],
        points,
    };
    let (_, report) = ok(&good, &BuildOptions::default());
    assert_eq!(report.reoriented, vec![1]);
}

// ------------------------------------------------------------------ pinched points

/// Two triangles touching at point 2 only (2D), with an unused point 1 in between: merge
/// shares the particle row, split appends one, refuse names the point and its cells.
#[test]
fn pinched_point_in_2d_merge_split_refuse() {
    let m = Mesh {
        kinds: vec![CellKind::Polygon; 2],
        cells: vec![vec![0, 3, 2], vec![2, 4, 5]],
        points: vec![
            [0.0, 0.0, 0.0],
            [9.0, 9.0, 0.0], // unused
            [1.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [2.0, 1.0, 0.0],
            [1.0, 2.0, 0.0],
        ],
    };
    // used points 0, 2, 3, 4, 5 get rows 0..5 in input order
    let row = BTreeMap::from([(0, 0), (2, 1), (3, 2), (4, 3), (5, 4)]);
    let (g, report) = ok(&m, &BuildOptions::default());
    assert_eq!(report.pinched, vec![2]);
    assert_eq!(report.unused_points, vec![1]);
    let rows = vertex_rows(&g);
    assert_eq!(rows.len(), 6, "point 2 is two vertex orbits");
    for &(_, p, r) in &rows {
        assert_eq!(r, row[&(p as usize)], "merge: the row of point {p}");
    }
    let split = BuildOptions {
        pinched: Pinched::Split,
        ..BuildOptions::default()
    };
    let (g, report) = ok(&m, &split);
    assert_eq!(report.pinched, vec![2]);
    let mut twos: Vec<(Dart, i64)> = vertex_rows(&g)
        .into_iter()
        .filter(|r| r.1 == 2)
        .map(|r| (r.0, r.2))
        .collect();
    twos.sort_unstable();
    assert_eq!(twos.iter().map(|t| t.1).collect::<Vec<_>>(), vec![1, 5]);
    let refuse = BuildOptions {
        pinched: Pinched::Refuse,
        ..BuildOptions::default()
    };
    let e = refused(&m, &refuse);
    assert_eq!(
        e,
        MeshError::Pinched {
            points: vec![(2, vec![0, 1])]
        }
    );
    assert_eq!(e.option(), Some(("pinched", "split")));
    assert!(e.to_string().contains("point 2"), "{e}");
}

/// Three tetrahedra chained at points 3 and 7: both points listed; split gives new rows in
/// increasing (point, smallest dart) order after the used points.
#[test]
fn pinched_points_in_3d_are_all_listed() {
    let mut points = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    points.extend([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 2.0]]); // 4, 5, 6 (+3)
    points.extend([[1.0, 0.0, 2.0], [0.0, 1.0, 2.0], [0.0, 0.0, 3.0]]); // 7, 8, 9 (+6)
    let m = Mesh {
        kinds: vec![CellKind::Tetra; 3],
        cells: vec![vec![0, 1, 2, 3], vec![3, 4, 5, 6], vec![6, 7, 8, 9]],
        points,
    };
    let (g, report) = ok(&m, &BuildOptions::default());
    assert_eq!(report.pinched, vec![3, 6]);
    for (_, p, r) in vertex_rows(&g) {
        assert_eq!(p, r, "all points used: row = point");
    }
    let e = refused(
        &m,
        &BuildOptions {
            pinched: Pinched::Refuse,
            ..BuildOptions::default()
        },
    );
    assert_eq!(
        e,
        MeshError::Pinched {
            points: vec![(3, vec![0, 1]), (6, vec![1, 2])]
        }
    );
    let (g, _) = ok(
        &m,
        &BuildOptions {
            pinched: Pinched::Split,
            ..BuildOptions::default()
        },
    );
    let rows = vertex_rows(&g);
    let of = |p: i64| -> Vec<i64> {
        let mut r: Vec<(Dart, i64)> = rows
            .iter()
            .filter(|x| x.1 == p)
            .map(|x| (x.0, x.2))
            .collect();
        r.sort_unstable();
        r.into_iter().map(|x| x.1).collect()
    };
    assert_eq!(of(3), vec![3, 10]);
    assert_eq!(of(6), vec![6, 11]);
}

// ------------------------------------------------------------------ duplicates

/// The same tetrahedron listed twice more (other vertex orders), and a quad twice in 2D:
/// refused naming every pair; merged on request, the duplicates get no element.
#[test]
fn duplicate_cells_are_refused_or_merged() {
    let mut m = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let n = m.cells.len();
    let c0 = m.cells[0].clone();
    let c5 = m.cells[5].clone();
    m.cells.push(vec![c0[3], c0[2], c0[1], c0[0]]);
    m.cells.push(vec![c5[1], c5[0], c5[2], c5[3]]);
    m.kinds.extend([CellKind::Tetra; 2]);
    let e = refused(&m, &BuildOptions::default());
    assert_eq!(
        e,
        MeshError::Duplicate {
            pairs: vec![(n, 0), (n + 1, 5)]
        }
    );
    assert_eq!(e.option(), Some(("duplicates", "merge")));
    let merge = BuildOptions {
        duplicates: Duplicates::Merge,
        ..BuildOptions::default()
    };
    let (g, report) = ok(&m, &merge);
    assert_eq!(report.merged_duplicates, vec![(n, 0), (n + 1, 5)]);
    assert_eq!(g.cell_counts().volumes, n);
    let ids: BTreeSet<i64> = g
        .orbit_representatives(OrbitType::volume())
        .into_iter()
        .map(|d| int(&g, "cell_id", d))
        .collect();
    assert_eq!(ids, (0..n as i64).collect());

    let mut m = grid([2, 1], [2.0, 1.0], GridElement::Quad);
    let c = m.cells[1].clone();
    m.cells.push(vec![c[2], c[3], c[0], c[1]]);
    m.kinds.push(CellKind::Polygon);
    assert_eq!(
        refused(&m, &BuildOptions::default()),
        MeshError::Duplicate {
            pairs: vec![(2, 1)]
        }
    );
    let (g, report) = ok(&m, &merge);
    assert_eq!(report.merged_duplicates, vec![(2, 1)]);
    assert_eq!(g.cell_counts().faces, 2);
}

// ------------------------------------------------------------------ non-conforming

fn hex(points: &mut Vec<[f64; 3]>, lo: [f64; 3], hi: [f64; 3]) -> Vec<usize> {
    let base = points.len();
    for z in [lo[2], hi[2]] {
        for (x, y) in [
            (lo[0], lo[1]),
            (hi[0], lo[1]),
            (hi[0], hi[1]),
            (lo[0], hi[1]),
        ] {
            points.push([x, y, z]);
        }
    }
    (base..base + 8).collect()
}

/// Welds points at the same place (the meshes above are made cell by cell).
fn weld(m: &mut Mesh) {
    let mut first: BTreeMap<[u64; 3], usize> = BTreeMap::new();
    let mut map = Vec::new();
    let mut pts = Vec::new();
    for p in &m.points {
        let key = p.map(f64::to_bits);
        let k = *first.entry(key).or_insert_with(|| {
            pts.push(*p);
            pts.len() - 1
        });
        map.push(k);
    }
    m.points = pts;
    for c in &mut m.cells {
        for v in c.iter_mut() {
            *v = map[*v];
        }
    }
}

/// A hexahedron's face against two tetrahedra splitting it (a quad against two triangles),
/// and two pairs of tetrahedra splitting a square by opposite diagonals: refused naming
/// every overlapping pair of faces.
#[test]
fn mismatched_diagonals_are_refused() {
    let mut points = Vec::new();
    let h = hex(&mut points, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
    let apex = points.len();
    points.push([2.0, 0.5, 0.5]);
    // the hex's x = 1 face is points h[1], h[2], h[6], h[5]
    let m = Mesh {
        kinds: vec![CellKind::Hexa, CellKind::Tetra, CellKind::Tetra],
        cells: vec![
            h.clone(),
            vec![h[1], h[2], h[6], apex],
            vec![h[1], h[6], h[5], apex],
        ],
        points,
    };
    match refused(&m, &BuildOptions::default()) {
        MeshError::NonConforming { pairs } => {
            let named: Vec<(usize, usize)> = pairs.iter().map(|p| (p.a, p.b)).collect();
            assert_eq!(named, vec![(0, 1), (0, 2)]);
            let mut q = pairs[0].face_a.clone();
            q.sort_unstable();
            assert_eq!(q, vec![h[1], h[2], h[5], h[6]]);
        }
        other => panic!("{other}"),
    }
    // square a b c d at z = 0, apexes e above and f below, diagonals a-c above, b-d below
    let points = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.5, 0.5, 1.0],
        [0.5, 0.5, -1.0],
    ];
    let m = Mesh {
        kinds: vec![CellKind::Tetra; 4],
        cells: vec![
            vec![0, 1, 2, 4],
            vec![0, 2, 3, 4],
            vec![0, 1, 3, 5],
            vec![1, 2, 3, 5],
        ],
        points,
    };
    match refused(&m, &BuildOptions::default()) {
        MeshError::NonConforming { pairs } => {
            let named: BTreeSet<(usize, usize)> = pairs.iter().map(|p| (p.a, p.b)).collect();
            // each upper triangle overlaps each lower one (each pair shares an area)
            assert_eq!(named, BTreeSet::from([(0, 2), (0, 3), (1, 2), (1, 3)]));
        }
        other => panic!("{other}"),
    }
}

/// Hanging nodes: a hexahedron beside two half-height ones (3D), a quad beside two half
/// quads (2D): the points at mid-edge are named. The same blocks with matching points build.
#[test]
fn hanging_nodes_are_refused_in_2d_and_3d() {
    let mut points = Vec::new();
    let a = hex(&mut points, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
    let b = hex(&mut points, [1.0, 0.0, 0.0], [2.0, 1.0, 0.5]);
    let c = hex(&mut points, [1.0, 0.0, 0.5], [2.0, 1.0, 1.0]);
    let mut m = Mesh {
        kinds: vec![CellKind::Hexa; 3],
        cells: vec![a, b, c],
        points,
    };
    weld(&mut m);
    let mid: Vec<usize> = (0..m.points.len())
        .filter(|&i| m.points[i][0] == 1.0 && m.points[i][2] == 0.5)
        .collect();
    assert_eq!(mid.len(), 2);
    match refused(&m, &BuildOptions::default()) {
        MeshError::NonConforming { pairs } => {
            let named: Vec<(usize, usize)> = pairs.iter().map(|p| (p.a, p.b)).collect();
            assert_eq!(named, vec![(0, 1), (0, 2)]);
            for p in &pairs {
                assert!(
                    mid.iter().any(|v| p.why == format!("hanging node {v}")),
                    "{}",
                    p.why
                );
            }
        }
        other => panic!("{other}"),
    }
    // 2D: quad [0,1]^2 beside [1,2]x[0,.5] and [1,2]x[.5,1]
    let p = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 0.5, 0.0],
        [2.0, 0.0, 0.0],
        [2.0, 0.5, 0.0],
        [2.0, 1.0, 0.0],
    ];
    let m = Mesh {
        kinds: vec![CellKind::Polygon; 3],
        cells: vec![vec![0, 1, 2, 3], vec![1, 5, 6, 4], vec![4, 6, 7, 2]],
        points: p.clone(),
    };
    match refused(&m, &BuildOptions::default()) {
        MeshError::NonConforming { pairs } => {
            let named: Vec<(usize, usize)> = pairs.iter().map(|p| (p.a, p.b)).collect();
            assert_eq!(named, vec![(0, 1), (0, 2)]);
            assert!(pairs.iter().all(|p| p.why == "hanging node 4"), "{pairs:?}");
        }
        other => panic!("{other}"),
    }
    // conforming: the left quad also uses point 4
    let m = Mesh {
        kinds: vec![CellKind::Polygon; 3],
        cells: vec![vec![0, 1, 4, 2, 3], vec![1, 5, 6, 4], vec![4, 6, 7, 2]],
        points: p,
    };
    ok(&m, &BuildOptions::default());
}

/// Two blocks whose touching faces coincide point for point with distinct points (an
/// interface cut on purpose) are two components, not a non-conforming interface.
#[test]
fn coincident_distinct_points_are_an_accepted_interface() {
    let mut points = Vec::new();
    let a = hex(&mut points, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
    let b = hex(&mut points, [1.0, 0.0, 0.0], [2.0, 1.0, 1.0]);
    let m = Mesh {
        kinds: vec![CellKind::Hexa; 2],
        cells: vec![a, b],
        points,
    };
    let (g, _) = ok(&m, &BuildOptions::default());
    assert_eq!(g.cell_counts().components, 2);
}

// ------------------------------------------------------------------ twisted cells

fn triple(o: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let (a, b, c) = (
        [a[0] - o[0], a[1] - o[1], a[2] - o[2]],
        [b[0] - o[0], b[1] - o[1], b[2] - o[2]],
        [c[0] - o[0], c[1] - o[1], c[2] - o[2]],
    );
    a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
        + a[2] * (b[0] * c[1] - b[1] * c[0])
}

/// A hexahedron with a corner pushed inside (positive volume, negative Jacobian at that
/// corner), a pyramid over a bow-tie base, a wedge with a top point pushed across: all
/// three named in one error.
#[test]
fn twisted_3d_cells_are_refused_all_at_once() {
    let mut points = Vec::new();
    let h = hex(&mut points, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
    points[h[6]] = [0.2, 0.2, 0.2];
    // independent check of the construction: corner 6 (edges to 5, 7, 2) is negative,
    // corner 0 (edges to 1, 3, 4) positive, the volume positive
    let p = |k: usize| points[h[k]];
    assert!(triple(p(6), p(5), p(7), p(2)) < 0.0);
    assert!(triple(p(0), p(1), p(3), p(4)) > 0.0);
    let base = points.len();
    points.extend([
        [3.0, 0.0, 0.0],
        [4.0, 0.0, 0.0],
        [4.0, 1.0, 0.0],
        [3.0, 1.0, 0.0],
        [3.5, 0.5, 1.0],
    ]);
    let pyr = vec![base, base + 1, base + 3, base + 2, base + 4]; // base listed as a bow-tie
    let w0 = points.len();
    // a wedge (bottom 0 1 2 seen clockwise from its top) with top point 3 pushed beyond the
    // far side of the top triangle
    points.extend([
        [6.0, 0.0, 0.0],
        [6.0, 1.0, 0.0],
        [7.0, 0.0, 0.0],
        [6.6, 0.6, 0.2],
        [6.0, 1.0, 1.0],
        [7.0, 0.0, 1.0],
    ]);
    let q = |k: usize| points[w0 + k];
    assert!(triple(q(3), q(4), q(5), q(0)) < 0.0);
    assert!(triple(q(1), q(0), q(2), q(4)) > 0.0);
    let wedge: Vec<usize> = (w0..w0 + 6).collect();
    let m = Mesh {
        kinds: vec![CellKind::Hexa, CellKind::Pyramid, CellKind::Wedge],
        cells: vec![h, pyr, wedge],
        points,
    };
    match refused(&m, &BuildOptions::default()) {
        MeshError::Twisted { cells } => {
            let named: Vec<usize> = cells.iter().map(|c| c.0).collect();
            assert_eq!(named, vec![0, 1, 2], "{cells:?}");
            assert!(cells[0].2.contains("Jacobian"));
        }
        other => panic!("{other}"),
    }
}

/// A bow-tie quad and a self-intersecting pentagon (a star listed out of order) in a
/// surface: both named; their convex listings build.
#[test]
fn self_intersecting_polygons_are_refused() {
    let mut points = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let star0 = points.len();
    for k in 0..5 {
        let t = 2.0 * std::f64::consts::PI * f64::from(k) / 5.0;
        points.push([5.0 + t.cos(), t.sin(), 0.0]);
    }
    let star: Vec<usize> = [0, 2, 4, 1, 3].iter().map(|k| star0 + k).collect();
    let m = Mesh {
        kinds: vec![CellKind::Polygon; 2],
        cells: vec![vec![0, 1, 3, 2], star],
        points: points.clone(),
    };
    match refused(&m, &BuildOptions::default()) {
        MeshError::Twisted { cells } => {
            let named: Vec<usize> = cells.iter().map(|c| c.0).collect();
            assert_eq!(named, vec![0, 1]);
            assert!(cells[0].2.contains("cross"), "{}", cells[0].2);
        }
        other => panic!("{other}"),
    }
    let m = Mesh {
        kinds: vec![CellKind::Polygon; 2],
        cells: vec![vec![0, 1, 2, 3], (star0..star0 + 5).collect()],
        points,
    };
    ok(&m, &BuildOptions::default());
}

// ------------------------------------------------------------------ numbering

/// `point_id` is the input point of every vertex orbit, `cell_id` the input cell of every
/// element; a turned hexahedron's darts start from its top quad (`reversed` order), an
/// unturned one's from its first point.
#[test]
fn point_and_cell_ids_follow_the_input() {
    let mut m = cuboid([2, 2, 1], [2.0, 2.0, 1.0], BoxElement::Hexa);
    let c = m.cells[2].clone();
    m.cells[2] = vec![c[4], c[5], c[6], c[7], c[0], c[1], c[2], c[3]];
    let (g, report) = ok(&m, &BuildOptions::default());
    assert_eq!(report.reoriented, vec![2]);
    let pos = g.require("position").unwrap();
    for d in g.darts() {
        let p = int(&g, "point_id", d) as usize;
        assert_eq!(g.real(pos, d), m.points[p].as_slice());
        assert_eq!(int(&g, "particle", d), p as i64, "every point used");
    }
    let mut seen = Vec::new();
    for d in g.orbit_representatives(OrbitType::volume()) {
        let id = int(&g, "cell_id", d) as usize;
        seen.push(id);
        for x in g.orbit(d, OrbitType::volume()) {
            assert_eq!(int(&g, "cell_id", x), id as i64);
        }
        // the smallest dart of the element is at the first point of its build order
        let first = int(&g, "point_id", d) as usize;
        let want = if id == 2 { c[0] } else { m.cells[id][0] };
        assert_eq!(first, want, "cell {id}");
    }
    assert_eq!(seen, vec![0, 1, 2, 3]);
    // 2D: faces
    let m = grid([3, 2], [3.0, 2.0], GridElement::Mixed);
    let (g, _) = ok(&m, &BuildOptions::default());
    let ids: Vec<i64> = g
        .orbit_representatives(OrbitType::face(2))
        .into_iter()
        .map(|d| int(&g, "cell_id", d))
        .collect();
    assert_eq!(ids, (0..m.cells.len() as i64).collect::<Vec<_>>());
}

/// The new i64 embeddings survive a `.tmg` round trip bit for bit.
#[test]
fn numbering_survives_a_tmg_round_trip() {
    let m = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Mixed);
    let (g, _) = ok(&m, &BuildOptions::default());
    let back = topomech_gmap::io::from_bytes(&topomech_gmap::io::to_bytes(&g)).unwrap();
    for name in ["point_id", "particle", "cell_id"] {
        for d in g.darts() {
            assert_eq!(int(&g, name, d), int(&back, name, d), "{name} at {d}");
        }
    }
}

/// Refusals show the first 20 offenders, then "and N more".
#[test]
fn long_lists_are_cut_with_a_count() {
    let mut m = cuboid([5, 5, 1], [5.0, 5.0, 1.0], BoxElement::Tetra);
    let n = m.cells.len();
    assert!(n > 30);
    for c in 0..n {
        let v = m.cells[c].clone();
        m.cells.push(v);
        m.kinds.push(CellKind::Tetra);
    }
    let e = refused(&m, &BuildOptions::default());
    let text = e.to_string();
    assert!(
        text.starts_with(&format!("{n} duplicate cell(s)")),
        "{text}"
    );
    assert!(text.ends_with(&format!("and {} more", n - 20)), "{text}");
    assert_eq!(text.matches("duplicates cell").count(), 20);
}

/// Two edges each on three triangles: both named in one error, with their faces.
#[test]
fn every_non_manifold_edge_is_named() {
    let mut points = Vec::new();
    let mut cells = Vec::new();
    for k in 0..2 {
        let x = 10.0 * f64::from(k);
        let b = points.len();
        points.extend([
            [x, 0.0, 0.0],
            [x + 1.0, 0.0, 0.0],
            [x + 0.5, 1.0, 0.0],
            [x + 0.5, -1.0, 0.0],
            [x + 0.5, 0.0, 1.0],
        ]);
        cells.extend([
            vec![b, b + 1, b + 2],
            vec![b + 1, b, b + 3],
            vec![b, b + 1, b + 4],
        ]);
    }
    let m = Mesh {
        kinds: vec![CellKind::Polygon; 6],
        cells,
        points,
    };
    match refused(&m, &BuildOptions::default()) {
        MeshError::NonManifold { what, items, .. } => {
            assert_eq!(what, "edge");
            assert_eq!(
                items,
                vec![(vec![0, 1], vec![0, 1, 2]), (vec![5, 6], vec![3, 4, 5])]
            );
        }
        other => panic!("{other}"),
    }
}
