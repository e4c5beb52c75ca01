//! An aggregate over a sub-orbit of its embedding's orbit (`sum<1>(v.velocity)` with
//! `velocity` on `<1,2>`, the accumulation's `sum<1,2,3>(v.f_tensor)` of a force on the
//! vertex) meets one orbit of the embedding: compiled plans take the row's slot without
//! walking the orbit. The values must be the interpreter's, bit for bit (a sum of one value,
//! a mean divided by one, a count of one), with the plan evaluator and with native code, on
//! 1 and 3 threads; and after a topology change, through a patched plan. The checker knows
//! such an aggregate is constant on its embedding's whole orbit: `v.out_v = mean<1>(...)`
//! on `<1,2>` is one value per vertex (it was refused as a write that may differ along
//! label 2).

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::GMap;
use topomech_rules::{load_sources, Params, RuleSet};

const SOURCE: &str = "dimension 2
embedding position : vec3 on <1,2>
embedding velocity : vec3 on <1,2>
embedding out_v    : vec3 on <1,2>
embedding out_w    : vec3 on <>
embedding out_s    : f64  on <>
embedding out_e    : f64  on <>

rule init_v {
  left { v : <1,2> hook }
  compute {
    let p = v.position
    v.velocity = vec3(sin(7.0 * x(p) + 1.0), cos(5.0 * y(p)), x(p) * y(p) - 0.25)
  }
}
rule agg {
  left { v : <1,2> hook }
  compute {
    v.out_v = sum<1,2>(v.velocity) + 2.0 * mean<1>(v.velocity) - sum<2>(v.velocity)
    v.out_w = sum<1,2>(v.velocity) - 0.5 * mean<>(v.velocity)
    v.out_s = to_f64(count<1,2>(v.velocity)) + to_f64(count<2>(v.velocity)) + x(mean<>(v.velocity))
  }
}
rule agg_dart {
  left { a : <> hook }
  compute { a.out_e = x(sum<>(a.velocity)) + to_f64(count<>(a.velocity)) }
}
rule unsew_middle {
  left  { a : <0> hook   b : <0>   a -2- b }
  right { a : <0>        b : <0> }
  where x(mean<0,1>(a.position)) < 0.45 && x(mean<0,1>(b.position)) > 0.45
}
";

fn sheet(rules: &RuleSet) -> GMap {
    let (mut g, _) = build(
        &grid([9, 7], [1.0, 0.8], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    rules.prepare(&mut g).unwrap();
    rules
        .apply_everywhere(&mut g, "init_v", &Params::new())
        .unwrap();
    g
}

fn bits(g: &GMap) -> Vec<u64> {
    crate::jit::column_bits(g, &["out_v", "out_w", "out_s", "out_e"])
}

/// The two rules applied, a cut, and the two rules applied again (the second time through
/// patched plans where compiled).
fn run(rules: &mut RuleSet, compiled: bool, jit: bool, threads: usize) -> Vec<u64> {
    rules.set_compiled(compiled);
    rules.set_jit(jit);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let none = Params::new();
        let mut g = sheet(rules);
        let mut out = Vec::new();
        for pass in 0..2 {
            rules.apply_everywhere(&mut g, "agg", &none).unwrap();
            rules.apply_everywhere(&mut g, "agg_dart", &none).unwrap();
            out.extend(bits(&g));
            if pass == 0 {
                let cut = rules
                    .apply_everywhere(&mut g, "unsew_middle", &none)
                    .unwrap();
                assert!(cut.matches > 0);
            }
        }
        out
    })
}

#[test]
fn sub_orbit_aggregates_give_the_interpreters_bits() {
    let (mut rules, _) = load_sources(&[("sub.tmr".to_string(), SOURCE.to_string())]).unwrap();
    let want = run(&mut rules, false, false, 1);
    for (compiled, jit, threads) in [(true, false, 1), (true, true, 1), (true, true, 3)] {
        let got = run(&mut rules, compiled, jit, threads);
        assert!(
            got == want,
            "compiled {compiled}, native code {jit}, {threads} threads"
        );
        assert!(rules.plan_kinds().iter().any(|(r, c)| r == "agg" && *c));
    }
}
