//! The vertex numbering of an imported map (`point_id`, `particle`: the input point order)
//! survives modeling rules that create vertices: the kernel gives each created vertex orbit
//! the next row and `point_id` -1, so the rows of the input points keep their meaning and the
//! numbering stays dense (`GMap::vertex_rows` uses it). Exact comparisons: rows and positions
//! of old vertices are copied, never computed.

use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_gmap::{GMap, OrbitType, Value};
use topomech_rules::{library, load_sources, Params};

fn int(g: &GMap, name: &str, d: topomech_gmap::Dart) -> i64 {
    match g.value(g.embedding_id(name).unwrap(), d).unwrap() {
        Value::Int(x) => x,
        v => panic!("{name} is {v:?}"),
    }
}

fn check_split_edge(mesh: &Mesh, dim: usize) {
    let (mut g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let n = mesh.points.len();
    let (rows, nv) = g.vertex_rows();
    assert_eq!(nv, n);
    let pos = g.embedding_id("position").unwrap();
    for d in g.darts() {
        let r = rows[d.index()] as usize;
        assert_eq!(g.real(pos, d), &mesh.points[r][..]);
    }
    let (rules, _) = load_sources(&[library(dim).unwrap()]).unwrap();
    let edges = g.count_orbits(OrbitType::edge(dim));
    rules
        .apply_everywhere(&mut g, "split_edge", &Params::new())
        .unwrap();
    assert!(g.is_valid());
    let (rows, nv) = g.vertex_rows();
    assert_eq!(nv, n + edges, "one new row per edge, appended");
    let mut new_rows = Vec::new();
    for d in g.darts() {
        let r = rows[d.index()] as usize;
        let id = int(&g, "point_id", d);
        if r < n {
            // an input vertex: same row, same point, same position
            assert_eq!(id, r as i64);
            assert_eq!(g.real(pos, d), &mesh.points[r][..]);
        } else {
            assert_eq!(id, -1, "a created vertex has no input point");
            new_rows.push(r);
        }
    }
    new_rows.sort_unstable();
    new_rows.dedup();
    assert_eq!(new_rows, (n..n + edges).collect::<Vec<_>>());
}

#[test]
fn split_edge_appends_rows_and_keeps_the_input_rows() {
    check_split_edge(&grid([3, 2], [3.0, 2.0], GridElement::Quad), 2);
    check_split_edge(&cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra), 3);
}
