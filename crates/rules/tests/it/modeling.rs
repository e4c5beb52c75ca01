//! The shipped modeling rules, applied globally to every generated mesh: the map stays valid,
//! the cell counts equal those computed independently from the input counts, and positions are
//! where the geometry says.

use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_gmap::{CellCounts, GMap, OrbitType};
use topomech_rules::{library, load_sources, Params, RuleSet};

fn rules(dim: usize) -> RuleSet {
    let (r, warnings) = load_sources(&[library(dim).unwrap()]).unwrap_or_else(|e| {
        panic!(
            "{}",
            e.iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join("\n")
        )
    });
    assert!(warnings.is_empty(), "{warnings:?}");
    r
}

fn meshes2() -> Vec<Mesh> {
    [GridElement::Triangle, GridElement::Quad, GridElement::Mixed]
        .into_iter()
        .map(|e| grid([3, 2], [3.0, 2.0], e))
        .collect()
}

fn meshes3() -> Vec<Mesh> {
    [
        BoxElement::Tetra,
        BoxElement::Hexa,
        BoxElement::Wedge,
        BoxElement::Pyramid,
        BoxElement::Mixed,
    ]
    .into_iter()
    .map(|e| cuboid([2, 2, 1], [2.0, 2.0, 1.0], e))
    .collect()
}

fn map(m: &Mesh) -> GMap {
    build(m, &BuildOptions::default()).unwrap().0
}

/// Sum over faces of their number of sides, counted independently from the cells.
fn sum_face_degrees(m: &Mesh) -> usize {
    if m.kinds[0].dimension() == 2 {
        return m.cells.iter().map(Vec::len).sum();
    }
    let mut faces = std::collections::HashSet::new();
    let mut total = 0;
    for (k, c) in m.kinds.iter().zip(&m.cells) {
        let local: &[&[usize]] = match k {
            topomech_gmap::mesh::CellKind::Tetra => {
                &[&[0, 1, 2], &[0, 1, 3], &[1, 2, 3], &[0, 2, 3]]
            }
            topomech_gmap::mesh::CellKind::Hexa => &[
                &[0, 1, 2, 3],
                &[4, 5, 6, 7],
                &[0, 1, 5, 4],
                &[1, 2, 6, 5],
                &[2, 3, 7, 6],
                &[3, 0, 4, 7],
            ],
            topomech_gmap::mesh::CellKind::Wedge => &[
                &[0, 1, 2],
                &[3, 4, 5],
                &[0, 1, 4, 3],
                &[1, 2, 5, 4],
                &[2, 0, 3, 5],
            ],
            topomech_gmap::mesh::CellKind::Pyramid => &[
                &[0, 1, 2, 3],
                &[0, 1, 4],
                &[1, 2, 4],
                &[2, 3, 4],
                &[3, 0, 4],
            ],
            topomech_gmap::mesh::CellKind::Polygon => unreachable!(),
        };
        for f in local {
            let mut key: Vec<usize> = f.iter().map(|&i| c[i]).collect();
            key.sort_unstable();
            if faces.insert(key) {
                total += f.len();
            }
        }
    }
    total
}

fn apply(r: &RuleSet, g: &mut GMap, name: &str) -> usize {
    let rep = r.apply_everywhere(g, name, &Params::new()).unwrap();
    let v = g.validate();
    assert!(v.is_empty(), "{name}: {:?}", &v[..v.len().min(5)]);
    rep.matches
}

#[test]
fn split_every_edge() {
    for (dim, meshes) in [(2, meshes2()), (3, meshes3())] {
        let r = rules(dim);
        for m in meshes {
            let mut g = map(&m);
            let c0 = g.cell_counts();
            let n = apply(&r, &mut g, "split_edge");
            assert_eq!(n, c0.edges);
            let c = g.cell_counts();
            assert_eq!(
                (c.vertices, c.edges, c.faces, c.volumes, c.components),
                (
                    c0.vertices + c0.edges,
                    2 * c0.edges,
                    c0.faces,
                    c0.volumes,
                    1
                )
            );
            // the new vertices are the edge midpoints: the sum of all positions grows by the
            // sum of the midpoints, computed from the input points and the unique edges
            let pos = g.require("position").unwrap();
            let total: [f64; 3] =
                g.orbit_representatives(OrbitType::vertex(dim))
                    .iter()
                    .fold([0.0; 3], |a, &d| {
                        let p = g.real(pos, d);
                        [a[0] + p[0], a[1] + p[1], a[2] + p[2]]
                    });
            let g0 = map(&m);
            let mut expect = [0.0; 3];
            for p in &m.points {
                for a in 0..3 {
                    expect[a] += p[a];
                }
            }
            let mut seen = std::collections::HashSet::new();
            for d in g0.orbit_representatives(OrbitType::edge(dim)) {
                let p0 = g0.real(g0.require("position").unwrap(), d).to_vec();
                let p1 = g0
                    .real(g0.require("position").unwrap(), g0.alpha(0, d))
                    .to_vec();
                assert!(seen.insert(d));
                for a in 0..3 {
                    expect[a] += f64::midpoint(p0[a], p1[a]);
                }
            }
            for a in 0..3 {
                assert!(
                    (total[a] - expect[a]).abs() < 1e-9 * expect[a].abs().max(1.0),
                    "{total:?} vs {expect:?}"
                );
            }
        }
    }
}

#[test]
fn triangulate_every_face() {
    for (dim, meshes) in [(2, meshes2()), (3, meshes3())] {
        let r = rules(dim);
        for m in meshes {
            let mut g = map(&m);
            let c0 = g.cell_counts();
            let deg = sum_face_degrees(&m);
            let n = apply(&r, &mut g, "triangulate_face");
            assert_eq!(n, c0.faces);
            let c = g.cell_counts();
            assert_eq!(
                (c.vertices, c.edges, c.faces, c.volumes, c.components),
                (c0.vertices + c0.faces, c0.edges + deg, deg, c0.volumes, 1)
            );
        }
    }
}

#[test]
fn quad_subdivide_every_face() {
    for (dim, meshes) in [(2, meshes2()), (3, meshes3())] {
        let r = rules(dim);
        for m in meshes {
            let mut g = map(&m);
            let c0 = g.cell_counts();
            let deg = sum_face_degrees(&m);
            let n = apply(&r, &mut g, "quad_subdivide");
            assert_eq!(n, 1, "one connected component");
            let c = g.cell_counts();
            assert_eq!(
                (c.vertices, c.edges, c.faces, c.volumes),
                (
                    c0.vertices + c0.edges + c0.faces,
                    2 * c0.edges + deg,
                    deg,
                    c0.volumes
                )
            );
            // every face is now a quad
            for d in g.orbit_representatives(OrbitType::parse("<0,1>").unwrap()) {
                assert_eq!(g.orbit(d, OrbitType::parse("<0,1>").unwrap()).len(), 8);
            }
        }
    }
}

#[test]
fn cut_everything_apart_then_remove_cells() {
    for (dim, meshes) in [(2, meshes2()), (3, meshes3())] {
        let r = rules(dim);
        let (unsew, remove) = if dim == 2 {
            ("unsew_edge", "remove_face")
        } else {
            ("unsew_face", "remove_volume")
        };
        for m in meshes {
            let mut g = map(&m);
            let c0: CellCounts = g.cell_counts();
            let cells = m.cells.len();
            let interior = if dim == 2 {
                c0.edges - c0.boundary
            } else {
                c0.faces - c0.boundary
            };
            let n = apply(&r, &mut g, unsew);
            assert_eq!(n, interior);
            let c = g.cell_counts();
            assert_eq!(c.components, cells);
            let corners: usize = m.cells.iter().map(Vec::len).sum();
            assert_eq!(c.vertices, corners, "every cell has its own vertices now");
            let n = apply(&r, &mut g, remove);
            assert_eq!(n, cells);
            assert_eq!(g.n_darts(), 0);
        }
    }
}

#[test]
fn sew_undoes_unsew() {
    let r = rules(2);
    let mut g = map(&grid([2, 1], [2.0, 1.0], GridElement::Quad));
    let before = g.cell_counts();
    let d = g.darts().find(|&d| !g.is_free(2, d)).unwrap();
    let p = g.alpha(2, d);
    r.apply_at(&mut g, "unsew_edge", &[d], &Params::new())
        .unwrap();
    assert_eq!(g.cell_counts().components, 2);
    let e = r
        .apply_at(&mut g, "unsew_edge", &[d], &Params::new())
        .unwrap_err();
    assert!(e.to_string().contains("arc a -2- b"), "{e}");
    r.apply_at(&mut g, "sew_edge", &[d, p], &Params::new())
        .unwrap();
    assert!(g.is_valid());
    assert_eq!(g.cell_counts(), before);
}

/// The example file of the language's specification is accepted as written, and its rules do
/// what they say: `count<0,1>(n0)` counts the darts of the face, a triangulated face gets its
/// centroid, and the centroid is evaluated once per face, not once per dart.
#[test]
fn the_specification_example_runs() {
    let src = include_str!("spec_example.tmr");
    let (r, warnings) = load_sources(&[("spec.tmr".into(), src.into())]).unwrap();
    assert!(warnings.is_empty());
    let m = grid([2, 1], [2.0, 1.0], GridElement::Mixed); // one quad, two triangles
    let mut g = map(&m);
    let rep = r
        .apply_everywhere(&mut g, "face_weight", &Params::new())
        .unwrap();
    assert_eq!((rep.matches, rep.evaluations), (3, 3));
    let w = g.require("weight").unwrap();
    let mut weights: Vec<f64> = g
        .orbit_representatives(OrbitType::face(2))
        .iter()
        .map(|&d| g.real(w, d)[0])
        .collect();
    weights.sort_by(f64::total_cmp);
    assert_eq!(weights, vec![6.0, 6.0, 8.0]);
    let rep = r
        .apply_everywhere(&mut g, "triangulate_face", &Params::new())
        .unwrap();
    assert_eq!(
        (rep.matches, rep.evaluations, rep.created),
        (3, 3, 2 * (6 + 6 + 8)),
        "two new nodes of one dart per row"
    );
    assert!(g.is_valid());
    // the quad [0,1]x[0,1] got its centre (0.5, 0.5)
    let pos = g.require("position").unwrap();
    let has = |p: [f64; 3]| g.darts().any(|d| g.real(pos, d) == p);
    assert!(has([0.5, 0.5, 0.0]));
    assert!(
        has([(1.0 + 2.0 + 2.0) / 3.0, 1.0 / 3.0, 0.0]),
        "the centroid of triangle (1,0),(2,0),(2,1)"
    );
    let inner = g.darts().find(|&d| !g.is_free(2, d)).unwrap();
    r.apply_at(&mut g, "unsew_edge", &[inner], &Params::new())
        .unwrap();
    assert!(g.is_valid());
}

#[test]
fn sew_face_undoes_unsew_face() {
    let r = rules(3);
    let mut g = map(&cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Hexa));
    let before = g.cell_counts();
    let d = g.darts().find(|&d| !g.is_free(3, d)).unwrap();
    let p = g.alpha(3, d);
    r.apply_at(&mut g, "unsew_face", &[d], &Params::new())
        .unwrap();
    assert_eq!(g.cell_counts().components, 2);
    assert!(g.is_valid());
    r.apply_at(&mut g, "sew_face", &[d, p], &Params::new())
        .unwrap();
    assert!(g.is_valid());
    assert_eq!(g.cell_counts(), before);
}

/// `count<o>(n.e)` counts the distinct orbits of `e` inside the `<o>` orbit of `n` (here the
/// vertices of each face), where `count<o>(n)` counts darts.
#[test]
fn count_of_an_embedding_counts_its_orbits() {
    let src = "dimension 2
embedding position : vec3 on <1,2>
embedding corners : i64 on <0,1>
rule corners { left { f : <0,1> hook } compute { f.corners = count<0,1>(f.position) } }";
    let (r, _) = load_sources(&[("c.tmr".into(), src.into())]).unwrap();
    let mut g = map(&grid([2, 1], [2.0, 1.0], GridElement::Mixed));
    r.apply_everywhere(&mut g, "corners", &Params::new())
        .unwrap();
    let c = g.require("corners").unwrap();
    let mut n: Vec<topomech_gmap::Value> = g
        .orbit_representatives(OrbitType::face(2))
        .iter()
        .map(|&d| g.value(c, d).unwrap())
        .collect();
    n.sort_by_key(|v| format!("{v:?}"));
    assert_eq!(
        n,
        vec![
            topomech_gmap::Value::Int(3),
            topomech_gmap::Value::Int(3),
            topomech_gmap::Value::Int(4)
        ]
    );
}

/// A rule set keeps the matches of its computation rules between applications (a plan). It is
/// keyed by the map's identity and topology version: two maps whose topologies differ after
/// the same number of changes, used in turns, each get their own matches; a change of the
/// topology rebuilds them.
#[test]
fn plans_never_cross_maps_or_topologies() {
    let src = "dimension 2
embedding position : vec3 on <1,2>
embedding darts : i64 on <0,2>
rule edge_darts { left { e : <0,2> hook } compute { e.darts = count<0,2>(e) } }
rule unsew_edge { left { a : <0> hook   b : <0>   a -2- b } right { a : <0>   b : <0> } }";
    let (r, _) = load_sources(&[("p.tmr".into(), src.into())]).unwrap();
    let mesh = grid([3, 1], [3.0, 1.0], GridElement::Quad);
    let (mut g1, mut g2) = (map(&mesh), map(&mesh));
    let inner: Vec<topomech_gmap::Dart> = g1.darts().filter(|&d| !g1.is_free(2, d)).collect();
    let a = inner[0];
    let b = *inner
        .iter()
        .find(|&&d| !g1.orbit(a, OrbitType::edge(2)).contains(&d))
        .unwrap();
    r.apply_at(&mut g1, "unsew_edge", &[a], &Params::new())
        .unwrap();
    r.apply_at(&mut g2, "unsew_edge", &[b], &Params::new())
        .unwrap();
    assert_eq!(g1.version(), g2.version());
    let values = |g: &GMap| -> Vec<topomech_gmap::Value> {
        let id = g.require("darts").unwrap();
        g.darts().map(|d| g.value(id, d).unwrap()).collect()
    };
    for _ in 0..2 {
        r.apply_everywhere(&mut g1, "edge_darts", &Params::new())
            .unwrap();
        r.apply_everywhere(&mut g2, "edge_darts", &Params::new())
            .unwrap();
    }
    let (fresh, _) = load_sources(&[("p.tmr".into(), src.into())]).unwrap();
    let (mut h1, mut h2) = (g1.clone(), g2.clone());
    fresh
        .apply_everywhere(&mut h1, "edge_darts", &Params::new())
        .unwrap();
    fresh
        .apply_everywhere(&mut h2, "edge_darts", &Params::new())
        .unwrap();
    assert_eq!(values(&g1), values(&h1));
    assert_eq!(values(&g2), values(&h2));
    assert_ne!(values(&g1), values(&g2), "the two maps differ");
    // a topology change on g1: the plan is rebuilt
    r.apply_at(&mut g1, "unsew_edge", &[b], &Params::new())
        .unwrap();
    r.apply_everywhere(&mut g1, "edge_darts", &Params::new())
        .unwrap();
    let mut h = g1.clone();
    fresh
        .apply_everywhere(&mut h, "edge_darts", &Params::new())
        .unwrap();
    assert_eq!(values(&g1), values(&h));
}

/// Twice the signed area of a polygon of the plane z = 0 (positive counter-clockwise).
fn signed_area2(cell: &[usize], points: &[[f64; 3]]) -> f64 {
    (0..cell.len())
        .map(|k| {
            let (p, q) = (points[cell[k]], points[cell[(k + 1) % cell.len()]]);
            p[0] * q[1] - q[0] * p[1]
        })
        .sum()
}

/// Regression: after `quad_subdivide` (and the other 2D rules) the faces extracted from the map
/// came out with mixed orientations, each starting at its smallest dart whichever orientation
/// class it was in, so that a written surface had flipped normals. Every face of a planar grid
/// listed counter-clockwise (or every face clockwise) must come back with the input's sign.
#[test]
fn extracted_faces_keep_the_input_orientation_after_2d_rules() {
    use topomech_gmap::mesh::extract;
    let r = rules(2);
    for m in meshes2() {
        for turned in [false, true] {
            let mut m = m.clone();
            if turned {
                m.cells.iter_mut().for_each(|c| c.reverse());
            }
            let sign = if turned { -1.0 } else { 1.0 };
            // an unchanged map gives back its input cells, each from its first vertex
            assert_eq!(extract(&map(&m)).unwrap().cells, m.cells);
            for rule in ["quad_subdivide", "split_edge", "triangulate_face"] {
                let mut g = map(&m);
                apply(&r, &mut g, rule);
                let out = extract(&g).unwrap();
                assert!(out.cells.len() >= m.cells.len());
                for (k, c) in out.cells.iter().enumerate() {
                    let a = signed_area2(c, &out.points);
                    assert!(
                        a * sign > 0.0,
                        "{rule}, input turned: {turned}: face {k} {c:?} has signed area {}",
                        a / 2.0
                    );
                }
            }
        }
    }
}
