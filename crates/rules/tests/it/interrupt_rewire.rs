//! Interrupting the last phase of a topology rule, the rewrite itself (issue 13: "a long rule
//! application answers Ctrl-C within a second"). `GMap::rewire` used to run as one batch
//! without checks (8 s for `triangulate_face` on a 150 x 150 grid); the engine now passes the
//! caller's check to `GMap::rewire_interruptible`. The last check of an application falls in
//! that rewrite: a stop there must end it with `Interrupted` in the stage "rewriting the
//! topology", nothing applied, and the map valid and unchanged: the same darts with the same
//! links, the same cell counts, the same position slots and values bit for bit. (The darts
//! the application created and removed again stay as free capacity, so the `.tmg` bytes and
//! the column length may differ; `crates/gmap/tests/it/rewire_scaling.rs` compares the bytes of
//! an interrupted `rewire_interruptible` alone.)

use std::cell::Cell;

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::GMap;
use topomech_rules::{library, load_sources, ApplyError, Params};

/// Every live dart's links, its position slot and its position bit for bit.
fn state(g: &GMap) -> Vec<([u32; 3], usize, Vec<u64>)> {
    let id = g.require("position").unwrap();
    g.darts()
        .map(|d| {
            (
                [g.alpha(0, d).0, g.alpha(1, d).0, g.alpha(2, d).0],
                g.embedding(id).slot(d),
                g.real(id, d).iter().map(|x| x.to_bits()).collect(),
            )
        })
        .collect()
}

fn quad_map(n: usize) -> GMap {
    build(
        &grid([n, n], [1.0, 1.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap()
    .0
}

#[test]
fn a_stop_during_the_rewrite_leaves_the_map_unchanged() {
    let rules = load_sources(&[library(2).unwrap()]).unwrap().0;
    let g0 = quad_map(40);
    // how many checks a full application makes
    let calls = Cell::new(0usize);
    let mut g = g0.clone();
    rules
        .apply_everywhere_interruptible(&mut g, "triangulate_face", &Params::new(), &|| {
            calls.set(calls.get() + 1);
            false
        })
        .unwrap();
    let total = calls.get();
    let before = state(&g0);
    for k in [total, total - 1] {
        let mut g = g0.clone();
        let calls = Cell::new(0usize);
        let r = rules.apply_everywhere_interruptible(
            &mut g,
            "triangulate_face",
            &Params::new(),
            &|| {
                calls.set(calls.get() + 1);
                calls.get() >= k
            },
        );
        match r {
            Err(ApplyError::Interrupted {
                stage,
                found,
                applied,
                ..
            }) => {
                assert_eq!(stage, "rewriting the topology", "k = {k} of {total}");
                assert_eq!((found, applied), (1600, 0));
            }
            other => panic!("k = {k}: expected Interrupted, got {other:?}"),
        }
        assert_eq!(
            calls.get(),
            k,
            "the application went on after the check said stop"
        );
        assert!(g.is_valid());
        assert_eq!(g.cell_counts(), g0.cell_counts());
        assert!(state(&g) == before, "k = {k}: the map changed");
    }
}
