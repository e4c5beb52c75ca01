//! Interrupting a long application (issue 13: "a long rule application answers Ctrl-C within a
//! second"). The engine calls the caller's check once per `INTERRUPT_EVERY` units of work; a
//! check that says "stop" at its k-th call must end the application with
//! `ApplyError::Interrupted`, no match applied, and the map valid and unchanged (same darts,
//! same positions, bit for bit). A check that never says stop changes nothing: the result is
//! the one of `apply_everywhere`.

use std::cell::Cell;

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::GMap;
use topomech_rules::engine::INTERRUPT_EVERY;
use topomech_rules::{library, load_sources, ApplyError, Params, RuleSet, Val};

fn quad_map(n: usize) -> GMap {
    build(
        &grid([n, n], [1.0, 1.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap()
    .0
}

fn positions(g: &GMap) -> Vec<u64> {
    crate::column_bits(g, "position")
}

fn library2() -> RuleSet {
    load_sources(&[library(2).unwrap()]).unwrap().0
}

/// Interrupts at the `k`-th call of the check; returns the error and the number of calls.
fn interrupted_at(
    rules: &RuleSet,
    g: &mut GMap,
    rule: &str,
    params: &Params,
    k: usize,
) -> (Result<topomech_rules::ApplyReport, ApplyError>, usize) {
    let calls = Cell::new(0usize);
    let check = || {
        calls.set(calls.get() + 1);
        calls.get() >= k
    };
    let r = rules.apply_everywhere_interruptible(g, rule, params, &check);
    (r, calls.get())
}

#[test]
fn interrupted_topology_rule_stops_before_any_change_and_leaves_the_map_valid() {
    let rules = library2();
    for k in [1, 2, 5] {
        let mut g = quad_map(40); // 6400 darts: several checks while matching
        let darts = g.cell_counts().darts;
        let before = positions(&g);
        let (r, calls) = interrupted_at(&rules, &mut g, "triangulate_face", &Params::new(), k);
        match r {
            Err(ApplyError::Interrupted {
                ref rule,
                found,
                applied,
                ..
            }) => {
                assert_eq!(rule, "triangulate_face");
                assert_eq!(applied, 0);
                // 1600 faces; at the k-th check fewer than k * INTERRUPT_EVERY darts were tried
                assert!(found < 1600, "found {found}");
            }
            other => panic!("k = {k}: expected Interrupted, got {other:?}"),
        }
        assert_eq!(
            calls, k,
            "the application went on after the check said stop"
        );
        let msg = r.unwrap_err().to_string();
        assert!(
            msg.contains("interrupted") && msg.contains("0 match(es) applied"),
            "{msg}"
        );
        assert!(g.is_valid());
        assert_eq!(g.cell_counts().darts, darts);
        assert!(positions(&g) == before, "a position changed");
    }
}

#[test]
fn check_is_called_regularly_and_a_never_check_gives_the_plain_result() {
    let rules = library2();
    let mut a = quad_map(40);
    let mut b = quad_map(40);
    let calls = Cell::new(0usize);
    let check = || {
        calls.set(calls.get() + 1);
        false
    };
    let ra = rules
        .apply_everywhere_interruptible(&mut a, "triangulate_face", &Params::new(), &check)
        .unwrap();
    let rb = rules
        .apply_everywhere(&mut b, "triangulate_face", &Params::new())
        .unwrap();
    assert_eq!(ra, rb);
    assert_eq!(ra.matches, 1600);
    // 6400 darts tried, then 1600 matches of 4 rows evaluated: at least one check per
    // INTERRUPT_EVERY units of work, so never more than INTERRUPT_EVERY units unchecked
    let work = 6400 + 1600 * 4;
    assert!(
        calls.get() >= work / INTERRUPT_EVERY - 1,
        "{} calls",
        calls.get()
    );
    // the same positions (slots may be numbered differently: compare them as sorted lists)
    let sorted = |g: &GMap| {
        let mut p = positions(g);
        p.sort_unstable();
        p
    };
    assert!(sorted(&a) == sorted(&b), "the positions differ");
    assert!(a.is_valid());
}

const DRIFT: &str = "dimension 2
embedding position : vec3 on <1,2>

rule drift(dt: f64) {
  left { v : <1,2> hook }
  compute {
    v.position = v.position + vec3(dt, 0.0, 0.0)
  }
}
";

#[test]
fn interrupted_computation_rule_writes_no_value() {
    let (rules, _) = load_sources(&[("drift.tmr".to_string(), DRIFT.to_string())]).unwrap();
    let p: Params = [("dt".to_string(), Val::F(0.5))].into();
    let mut g = quad_map(60);
    let before = positions(&g);
    // while finding the matches (first application: the plan is built)
    let (r, _) = interrupted_at(&rules, &mut g, "drift", &p, 1);
    assert!(
        matches!(r, Err(ApplyError::Interrupted { applied: 0, .. })),
        "{r:?}"
    );
    assert!(positions(&g) == before, "a position changed");
    // build the plan, then interrupt its run: every check after the matches says stop
    rules.apply_everywhere(&mut g, "drift", &p).unwrap();
    let after_one = positions(&g);
    assert!(after_one != before);
    let (r, _) = interrupted_at(&rules, &mut g, "drift", &p, 1);
    match r {
        Err(ApplyError::Interrupted { stage, found, .. }) => {
            assert_eq!(stage, "running its compiled plan");
            assert_eq!(found, 61 * 61);
        }
        other => panic!("expected Interrupted, got {other:?}"),
    }
    assert!(positions(&g) == after_one, "a position changed");
    assert!(g.is_valid());
}

#[test]
fn interrupted_after_darts_were_created_removes_them() {
    // count the checks of a whole application, then stop at each of the last ones: those
    // come after the new darts are created (planning the new topology, checking the values,
    // preparing the rewrite)
    let rules = library2();
    let mut probe = quad_map(30);
    let calls = Cell::new(0usize);
    let count = || {
        calls.set(calls.get() + 1);
        false
    };
    rules
        .apply_everywhere_interruptible(&mut probe, "triangulate_face", &Params::new(), &count)
        .unwrap();
    let total = calls.get();
    let mut stages = Vec::new();
    for k in [total, total - 1, total / 2 + 1] {
        let mut g = quad_map(30);
        let counts = g.cell_counts();
        let (r, _) = interrupted_at(&rules, &mut g, "triangulate_face", &Params::new(), k);
        match r {
            Err(ApplyError::Interrupted { stage, applied, .. }) => {
                assert_eq!(applied, 0);
                stages.push(stage);
            }
            other => panic!("k = {k} of {total}: expected Interrupted, got {other:?}"),
        }
        assert!(g.is_valid());
        assert_eq!(g.cell_counts(), counts, "created darts left behind");
    }
    assert!(
        stages.iter().all(|s| [
            "planning the new topology",
            "checking the values written",
            "rewriting the topology"
        ]
        .contains(s)),
        "{stages:?}"
    );
}
