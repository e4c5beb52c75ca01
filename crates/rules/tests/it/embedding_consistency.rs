//! Embedding consistency at application time (issue 14): a topology-changing rule applied to
//! a map that carries embeddings the rule's file does not declare (a declared one that a
//! created node does not get is refused by the checker, `embedding-missing`) gives every orbit made only of new darts a value by the
//! embedding's policy, from the old orbits of the new darts' origins (the hook dart of their
//! row): `copy` the first origin's value, `mean` the mean of the origins, `sum` zero (its
//! neutral value, so totals are kept), and `error` refuses the application naming the
//! embedding, with the map unchanged. Before this, those orbits were left at zero.
//!
//! Every expected value here is computed independently from the map before the application
//! (plain arithmetic on the values read), and compared exactly or to 1e-12 (a mean of a few
//! numbers of order 1 rounds at 1e-16).

// values copied from the map are compared bit for bit on purpose (a copy is exact)
#![allow(clippy::float_cmp)]

use std::collections::HashMap;

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{Dart, EmbeddingId, EmbeddingType, GMap, OrbitType, Policy, Value};
use topomech_rules::{load_sources, ApplyError, Params, RuleSet};

const SOURCE: &str = "dimension 2
embedding position : vec3 on <1,2> policy mean

rule split_edge {
  left  { n0 : <0,2> hook }
  right {
    n0 : <_,2>
    n1 : <1,2>
    n0 -0- n1
  }
  compute { n1.position = mean<0,2>(n0.position) }
}

rule triangulate_face {
  left  { n0 : <0,1> hook }
  right {
    n0 : <0,_>
    n1 : <_,2>
    n2 : <1,2>
    n0 -1- n1
    n1 -0- n2
  }
  compute { n2.position = mean<0,1>(n0.position) }
}
";

fn vertex() -> OrbitType {
    OrbitType::parse("<1,2>").unwrap()
}

/// A 2x1 grid of quads with `position` (the rules' only embedding) and extra embeddings the rule file does not declare, each holding nonzero values.
fn setup(with_error: bool) -> (GMap, RuleSet) {
    let (mut g, _) = build(
        &grid([2, 1], [2.0, 1.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    let (rules, _) = load_sources(&[("consistency.tmr".to_string(), SOURCE.to_string())]).unwrap();
    rules.prepare(&mut g).unwrap();
    let pos = g.require("position").unwrap();
    let add = |g: &mut GMap, name: &str, ty: EmbeddingType, o: &str, p: Policy| {
        g.add_embedding(name, ty, OrbitType::parse(o).unwrap(), p)
            .unwrap()
    };
    let heat = add(&mut g, "heat", EmbeddingType::F64, "<1,2>", Policy::Mean);
    let m_copy = add(&mut g, "m_copy", EmbeddingType::F64, "<1,2>", Policy::Copy);
    let m_mean = add(&mut g, "m_mean", EmbeddingType::Vec3, "<1,2>", Policy::Mean);
    let m_sum = add(&mut g, "m_sum", EmbeddingType::F64, "<1,2>", Policy::Sum);
    let corner = add(&mut g, "corner", EmbeddingType::F64, "<1>", Policy::Copy);
    let count = add(&mut g, "count", EmbeddingType::I64, "<1,2>", Policy::Copy);
    let tag = add(&mut g, "tag", EmbeddingType::Bool, "<>", Policy::Copy);
    let err = with_error.then(|| add(&mut g, "m_err", EmbeddingType::F64, "<1,2>", Policy::Error));
    let darts: Vec<Dart> = g.darts().collect();
    for d in darts {
        let p = g.real(pos, d).to_vec();
        let (x, y) = (p[0], p[1]);
        g.set_value(heat, d, &Value::Real(vec![1.0 + x + 3.0 * y]))
            .unwrap();
        g.set_value(m_copy, d, &Value::Real(vec![1.0 + 2.0 * x + 5.0 * y]))
            .unwrap();
        g.set_value(m_mean, d, &Value::Real(vec![1.0 + x, 2.0 + y, 3.0 + x * y]))
            .unwrap();
        g.set_value(m_sum, d, &Value::Real(vec![0.25 + x])).unwrap();
        g.set_value(count, d, &Value::Int(7 + (2.0 * x) as i64 + 10 * y as i64))
            .unwrap();
        g.set_value(tag, d, &Value::Bool(true)).unwrap();
        if let Some(e) = err {
            g.set_value(e, d, &Value::Real(vec![4.0])).unwrap();
        }
    }
    // a distinct value per corner (orbit <1>): 1 + the dart index of one of its darts
    let darts: Vec<Dart> = g.darts().collect();
    for d in darts {
        let other = g.alpha(1, d);
        g.set_value(
            corner,
            d,
            &Value::Real(vec![1.0 + f64::from(d.0.min(other.0))]),
        )
        .unwrap();
    }
    (g, rules)
}

fn real(g: &GMap, name: &str, d: Dart) -> Vec<f64> {
    match g.value(g.require(name).unwrap(), d).unwrap() {
        Value::Real(v) => v,
        other => panic!("{name} is not real: {other:?}"),
    }
}

/// The darts at position (x, y).
fn darts_at(g: &GMap, x: f64, y: f64) -> Vec<Dart> {
    g.darts()
        .filter(|&d| {
            let p = real(g, "position", d);
            (p[0] - x).abs() < 1e-12 && (p[1] - y).abs() < 1e-12
        })
        .collect()
}

/// Sum of a real scalar embedding over its orbits (one value per orbit).
fn total(g: &GMap, id: EmbeddingId) -> f64 {
    let e = g.embedding(id);
    let mut seen = HashMap::new();
    for d in g.darts() {
        seen.entry(e.slot(d)).or_insert(d);
    }
    seen.values().map(|&d| g.real(id, d)[0]).sum()
}

/// The hook: a dart at (0,0) whose alpha0 is at (1,0) (the bottom edge of the first quad).
fn bottom_edge(g: &GMap) -> Dart {
    darts_at(g, 0.0, 0.0)
        .into_iter()
        .find(|&d| {
            let q = real(g, "position", g.alpha(0, d));
            (q[0] - 1.0).abs() < 1e-12 && q[1].abs() < 1e-12
        })
        .unwrap()
}

/// Splitting the bottom edge of the first quad (a boundary edge: two darts, endpoints A at
/// (0,0) and B at (1,0)) makes a new vertex M of new darts only. `heat` and `m_mean` get the mean of A and B; `m_copy` the value of A (the hook's vertex,
/// the first origin); `count` (i64, copy) A's value; `m_sum` zero with the total over
/// the vertices kept; the new corner the hook's corner value; the direct `tag` its origin
/// dart's `true`. On the code before the change every one of these (but the written
/// position) was 0 on M.
#[test]
fn split_edge_fills_undeclared_embeddings_by_policy() {
    let (mut g, rules) = setup(false);
    let h = bottom_edge(&g);
    let a = h;
    let b = g.alpha(0, h);
    let before: Vec<Vec<f64>> = ["heat", "m_mean"]
        .iter()
        .map(|n| {
            let (va, vb) = (real(&g, n, a), real(&g, n, b));
            va.iter().zip(&vb).map(|(x, y)| (x + y) / 2.0).collect()
        })
        .collect();
    let copy_a = real(&g, "m_copy", a)[0];
    let corner_a = real(&g, "corner", a)[0];
    let corner_b = real(&g, "corner", b)[0];
    let count_a = g.value(g.require("count").unwrap(), a).unwrap();
    let count_b = g.value(g.require("count").unwrap(), b).unwrap();
    let sum_id = g.require("m_sum").unwrap();
    let sum_before = total(&g, sum_id);
    rules
        .apply_at(&mut g, "split_edge", &[h], &Params::new())
        .unwrap();
    let m = darts_at(&g, 0.5, 0.0);
    assert_eq!(
        m.len(),
        2,
        "the new vertex M has the 2 new darts of a boundary edge"
    );
    let d = m[0];
    for (k, n) in ["heat", "m_mean"].iter().enumerate() {
        let got = real(&g, n, d);
        let want = &before[k];
        for (x, y) in got.iter().zip(want) {
            assert!(
                (x - y).abs() < 1e-12,
                "{n} at M: {got:?}, want mean {want:?}"
            );
        }
    }
    assert_eq!(
        real(&g, "m_copy", d)[0],
        copy_a,
        "copy takes the hook's vertex value"
    );
    assert_ne!(count_a, count_b, "the endpoints' counts differ");
    assert_eq!(
        g.value(g.require("count").unwrap(), d).unwrap(),
        count_a,
        "copy of an integer: the hook's vertex"
    );
    assert_eq!(real(&g, "m_sum", d)[0], 0.0);
    assert!(
        (total(&g, sum_id) - sum_before).abs() < 1e-12,
        "sum total kept"
    );
    // M (on the boundary) has one corner, of both new darts; their origins are the hook's
    // corner at A and its alpha0's at B: copy keeps the first, the hook's
    assert_ne!(corner_a, corner_b);
    for &x in &m {
        assert_eq!(
            real(&g, "corner", x)[0],
            corner_a,
            "the new corner copies the hook's"
        );
    }
    for &x in &m {
        assert_eq!(
            g.value(g.require("tag").unwrap(), x).unwrap(),
            Value::Bool(true)
        );
    }
}

/// Triangulating the first quad creates its centre vertex C from new darts only: `m_mean` and
/// `heat` at C are the mean of the 4 corners' values, `m_sum` at C is zero and the total is
/// kept, and every copy/mean embedding on every vertex of the result is nonzero (the setup
/// writes only nonzero values, so a zero would be a value left unset).
#[test]
fn triangulate_face_fills_the_centre_by_policy() {
    let (mut g, rules) = setup(false);
    let h = bottom_edge(&g);
    let corners = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
    let mut want = [0.0; 3];
    for &(x, y) in &corners {
        let d = darts_at(&g, x, y)[0];
        for (w, v) in want.iter_mut().zip(real(&g, "m_mean", d)) {
            *w += v / 4.0;
        }
    }
    let heat_want: f64 = corners
        .iter()
        .map(|&(x, y)| real(&g, "heat", darts_at(&g, x, y)[0])[0] / 4.0)
        .sum();
    let sum_id = g.require("m_sum").unwrap();
    let sum_before = total(&g, sum_id);
    rules
        .apply_at(&mut g, "triangulate_face", &[h], &Params::new())
        .unwrap();
    let c = darts_at(&g, 0.5, 0.5);
    assert_eq!(c.len(), 8, "the centre of a quad has 8 darts");
    let got = real(&g, "m_mean", c[0]);
    for (x, y) in got.iter().zip(&want) {
        assert!(
            (x - y).abs() < 1e-12,
            "m_mean at the centre {got:?}, want {want:?}"
        );
    }
    assert!((real(&g, "heat", c[0])[0] - heat_want).abs() < 1e-12);
    assert_eq!(real(&g, "m_sum", c[0])[0], 0.0);
    assert!((total(&g, sum_id) - sum_before).abs() < 1e-12);
    for name in ["heat", "m_copy", "m_mean", "corner"] {
        for d in g.darts() {
            assert!(
                real(&g, name, d).iter().any(|&x| x != 0.0),
                "{name} left at zero on dart {d}"
            );
        }
    }
}

/// An embedding with policy `error` on the vertex: the new vertex would split its origin, so
/// the application is refused with `NoValue` naming the rule, the embedding, its orbit and
/// policy, and the map is unchanged (same darts, same values). On the code before the change
/// the rule applied and left `m_err` at 0 on the new vertex.
#[test]
fn error_policy_refuses_naming_the_embedding() {
    let (mut g, rules) = setup(true);
    let h = bottom_edge(&g);
    let n = g.darts().count();
    let snap: Vec<Vec<f64>> = ["position", "m_err", "m_mean"]
        .iter()
        .map(|name| g.darts().flat_map(|d| real(&g, name, d)).collect())
        .collect();
    let e = rules
        .apply_at(&mut g, "split_edge", &[h], &Params::new())
        .unwrap_err();
    match &e {
        ApplyError::NoValue {
            rule,
            embedding,
            policy,
            orbit,
            ..
        } => {
            assert_eq!(rule, "split_edge");
            assert_eq!(embedding, "m_err");
            assert_eq!(*policy, "error");
            assert_eq!(*orbit, vertex());
        }
        other => panic!("expected NoValue, got {other:?}"),
    }
    let msg = e.to_string();
    assert!(
        msg.contains("'m_err'") && msg.contains("policy error") && msg.contains("split_edge"),
        "{msg}"
    );
    assert_eq!(g.darts().count(), n, "no dart added or removed");
    let after: Vec<Vec<f64>> = ["position", "m_err", "m_mean"]
        .iter()
        .map(|name| g.darts().flat_map(|d| real(&g, name, d)).collect())
        .collect();
    assert_eq!(after, snap, "no value changed");
    assert!(g.validate().is_empty());
}

/// Applied everywhere (every edge split at once), no copy/mean embedding of the result is
/// left at zero and the sum total is kept.
#[test]
fn split_everywhere_leaves_nothing_at_zero() {
    let (mut g, rules) = setup(false);
    let sum_id = g.require("m_sum").unwrap();
    let sum_before = total(&g, sum_id);
    let r = rules
        .apply_everywhere(&mut g, "split_edge", &Params::new())
        .unwrap();
    assert_eq!(r.matches, 7, "a 2x1 quad grid has 7 edges");
    for name in ["heat", "m_copy", "m_mean", "corner"] {
        for d in g.darts() {
            assert!(
                real(&g, name, d).iter().any(|&x| x != 0.0),
                "{name} left at zero on dart {d}"
            );
        }
    }
    assert!((total(&g, sum_id) - sum_before).abs() < 1e-12);
}
