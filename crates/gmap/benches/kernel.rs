//! Kernel benchmark: building the G-map of a ~100k-tetrahedron box, its memory per dart, and
//! orbit traversals over it, and batch rewrites (`GMap::rewire`) of one face and of every face.
//! Prints the median of repeated runs (`cargo bench`).

use std::hint::black_box;
use std::time::Instant;

use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{Dart, GMap, OrbitType};

fn median_seconds(runs: usize, mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[runs / 2]
}

/// Median seconds of `g.clone().rewire(changes)`, the clone not timed.
fn rewire_seconds(runs: usize, g: &GMap, changes: &[(usize, Dart, Dart)]) -> f64 {
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let mut h = g.clone();
            let s = Instant::now();
            h.rewire(changes, &[], &[])
                .expect("an unsew is a valid batch");
            let e = s.elapsed().as_secs_f64();
            black_box(h);
            e
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[runs / 2]
}

fn main() {
    // 26 x 26 x 25 cubes, 6 tetrahedra each: 101,400 tetrahedra
    let mesh = cuboid([26, 26, 25], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let n_tets = mesh.cells.len();
    let opts = BuildOptions::default();
    let build_s = median_seconds(5, || {
        black_box(build(&mesh, &opts).expect("valid"));
    });
    let (g, _) = build(&mesh, &opts).expect("valid");
    let n = g.n_darts();
    println!("kernel benchmark: box of {n_tets} tetrahedra, {n} darts (median of 5 runs)");
    println!(
        "  build G-map (with position embedding)  {:8.1} ms   {:6.1} ns/dart",
        build_s * 1e3,
        build_s * 1e9 / n as f64
    );
    println!(
        "  memory: {:.1} bytes/dart in all ({:.1} topology: 4 alpha links of 4 bytes + liveness), {:.0} bytes/tet",
        g.memory_bytes() as f64 / n as f64,
        g.topology_bytes() as f64 / n as f64,
        g.memory_bytes() as f64 / n_tets as f64
    );
    for (name, o) in [
        ("vertices <1,2,3>", OrbitType::vertex(3)),
        ("edges <0,2,3>", OrbitType::edge(3)),
        ("faces <0,1,3>", OrbitType::face(3)),
        ("volumes <0,1,2>", OrbitType::volume()),
        ("half-edges <0>", OrbitType::parse("<0>").expect("static")),
    ] {
        let mut count = 0;
        let s = median_seconds(5, || count = black_box(g.count_orbits(o)));
        println!(
            "  count {name:18} {count:9}  {:8.1} ms   {:6.1} ns/dart",
            s * 1e3,
            s * 1e9 / n as f64
        );
    }
    let s = median_seconds(3, || {
        black_box(g.is_valid());
    });
    println!(
        "  is_valid (all invariants)              {:8.1} ms",
        s * 1e3
    );
    // unsew (alpha3 := identity) one inner face, then every inner face: the cost per link
    // should be about the same (a rewrite costs what it changes, not the map)
    let sewn: Vec<Dart> = g.darts().filter(|&d| !g.is_free(3, d)).collect();
    // a face orbit <0,1,3> holds the darts of both its sides
    let one: Vec<(usize, Dart, Dart)> = g
        .orbit(sewn[0], OrbitType::face(3))
        .into_iter()
        .map(|d| (3, d, d))
        .collect();
    let all: Vec<(usize, Dart, Dart)> = sewn.iter().map(|&d| (3, d, d)).collect();
    for (name, changes, runs) in [("one face", &one, 5), ("every face", &all, 3)] {
        let s = rewire_seconds(runs, &g, changes);
        println!(
            "  rewire: unsew {name:10} {:9} links {:8.3} ms   {:6.1} ns/link",
            changes.len(),
            s * 1e3,
            s * 1e9 / changes.len() as f64
        );
    }
}
