//! `GMap::rewire` costs what its batch changes (issues 13 and 16): time per changed link is
//! flat in the size of the batch, and the batch's result is the one an independent count gives.
//!
//! The batch used is "unsew every face of an n x n quad grid" (every alpha2 link made a fixed
//! point): it splits every vertex orbit, so every vertex embedding is re-slotted, with the
//! `mean` policy (`position`) and the `sum` policy (`mass`, added here).

use std::cell::Cell;
use std::time::Instant;

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::io::to_bytes;
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{Dart, EmbeddingType, GMap, OrbitType, Policy, RewireError};

/// An n x n quad grid of unit squares with a `sum` vertex embedding `mass` of 1 per vertex.
fn quad_map(n: usize) -> GMap {
    let mut g = build(
        &grid([n, n], [n as f64, n as f64], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap()
    .0;
    let v = OrbitType::vertex(2);
    let m = g
        .add_embedding("mass", EmbeddingType::F64, v, Policy::Sum)
        .unwrap();
    for d in g.orbit_representatives(v) {
        g.set_real(m, d, &[1.0]).unwrap();
    }
    g
}

/// The links of "unsew every face": `alpha2(d) := d` for every sewn dart.
fn unsew_all(g: &GMap) -> Vec<(usize, Dart, Dart)> {
    g.darts()
        .filter(|&d| !g.is_free(2, d))
        .map(|d| (2, d, d))
        .collect()
}

/// Seconds per changed link of the unsew-all batch on an n x n grid (best of `runs`: the
/// machine is shared, the minimum is the least disturbed measurement).
fn seconds_per_link(n: usize, runs: usize) -> (f64, usize) {
    let g = quad_map(n);
    let changes = unsew_all(&g);
    let mut best = f64::INFINITY;
    for _ in 0..runs {
        let mut h = g.clone();
        let t = Instant::now();
        h.rewire(&changes, &[], &[]).unwrap();
        best = best.min(t.elapsed().as_secs_f64());
        assert!(h.is_valid());
    }
    (best / changes.len() as f64, changes.len())
}

/// Regression (issue 16, "the rewrite's slot lookup is quadratic"): the old re-slotting found
/// each old slot by a linear search among all old slots of the batch, so a 16 x bigger batch
/// cost more per link the bigger the batch (6.7 s of `triangulate_face` on a 150 x 150 grid,
/// release build). Now the cost per link must stay within 3 x between batches of 6 960 and
/// 114 240 links (the bound leaves room for cache effects and a shared machine; the quadratic
/// code measured 5.2 x here in a debug build, the fixed one under 1.5 x). A timing, so not in
/// `make test` (speed lives in benchmarks: `make bench` times unsewing one face and every face
/// of the 100k-tet box); run it with `cargo test -p topomech-gmap --test it rewire_scaling:: --
/// --ignored`.
#[test]
#[ignore = "a timing: run with --ignored; make bench measures the rewrite"]
fn time_per_changed_link_is_flat_in_the_batch_size() {
    let (small, ns) = seconds_per_link(30, 5);
    let (big, nb) = seconds_per_link(120, 3);
    // 4 sewn darts on each side of each of the 2 n (n - 1) inner edges
    assert_eq!((ns, nb), (8 * 30 * 29, 8 * 120 * 119));
    let ratio = big / small;
    assert!(
        ratio < 3.0,
        "per link: {:.3} us at {ns} links, {:.3} us at {nb} links ({ratio:.1} x)",
        small * 1e6,
        big * 1e6
    );
}

/// The unsew-all batch gives what counting the grid says: every face its own 4 vertices, the
/// `mean` position of each corner the old vertex position (bit for bit), and the `sum` mass of
/// 1 of each old vertex shared among the faces around it (1/4 inside, 1/2 on a side, 1 at a
/// grid corner: exact in binary floating point, so compared exactly).
#[test]
fn unsew_all_splits_values_as_the_policies_say() {
    let n = 12;
    let g0 = quad_map(n);
    let mut g = g0.clone();
    g.rewire(&unsew_all(&g0), &[], &[]).unwrap();
    assert!(g.validate().is_empty(), "{:?}", g.validate());
    let c = g.cell_counts();
    assert_eq!(c.vertices, 4 * n * n);
    assert_eq!(c.faces, n * n);
    assert_eq!(c.darts, 8 * n * n);
    let pos = g.require("position").unwrap();
    let mass = g.require("mass").unwrap();
    for d in g.darts() {
        assert_eq!(g.real(pos, d), g0.real(pos, d), "position at dart {d}");
        let p = g.real(pos, d);
        // grid coordinates are whole numbers 0..=n
        let on_side = |x: f64| x < 0.5 || x > n as f64 - 0.5;
        let faces_around = match (on_side(p[0]), on_side(p[1])) {
            (true, true) => 1.0,
            (true, false) | (false, true) => 2.0,
            (false, false) => 4.0,
        };
        assert_eq!(g.real(mass, d), &[1.0 / faces_around], "mass at dart {d}");
    }
}

/// Issue 13 (Ctrl-C within a second): `rewire_interruptible` calls its check while it
/// prepares; a check that says stop at its k-th call, for every k up to the last call,
/// ends the call with `Interrupted`, the check not called again, and the map exactly as it was
/// (same bytes, same version, valid). A check that never says stop gives the result of
/// `rewire`, byte for byte.
#[test]
fn interrupted_rewire_leaves_the_map_as_it_was() {
    let g0 = quad_map(40);
    let changes = unsew_all(&g0);
    let mut expected = g0.clone();
    expected.rewire(&changes, &[], &[]).unwrap();
    let calls = Cell::new(0usize);
    let mut g = g0.clone();
    g.rewire_interruptible(&changes, &[], &[], &|| {
        calls.set(calls.get() + 1);
        false
    })
    .unwrap();
    assert!(
        to_bytes(&g) == to_bytes(&expected),
        "a check that never stops changes nothing"
    );
    let total = calls.get();
    // 12 480 links checked twice, then the vertex orbits planned for each vertex embedding
    assert!(total >= 2 * changes.len() / 1024, "only {total} checks");
    let before = to_bytes(&g0);
    for k in [1, 2, total / 2, total - 1, total] {
        let mut g = g0.clone();
        let calls = Cell::new(0usize);
        let r = g.rewire_interruptible(&changes, &[], &[], &|| {
            calls.set(calls.get() + 1);
            calls.get() >= k
        });
        assert_eq!(r, Err(RewireError::Interrupted), "k = {k}");
        assert_eq!(
            calls.get(),
            k,
            "the rewire went on after the check said stop"
        );
        assert!(g.is_valid(), "k = {k}");
        assert_eq!(g.version(), g0.version(), "k = {k}");
        assert!(to_bytes(&g) == before, "k = {k}: the map changed");
    }
}

/// Not a check: prints the unsew-all batch time for growing grids (release build:
/// `cargo test --release -p topomech-gmap --test it rewire_scaling:: -- --ignored --nocapture`).
#[test]
#[ignore = "a timing report, run by hand in a release build"]
fn report_unsew_all_times() {
    for n in [50, 100, 150, 250] {
        let (t, links) = seconds_per_link(n, 1);
        eprintln!(
            "n = {n}: {} darts, {links} links, {:.3} s, {:.3} us per link",
            8 * n * n,
            t * links as f64,
            t * 1e6
        );
    }
}
