//! Compiled plans under parameters that change from one run to the next, on many chunks of
//! rows and several threads: each run must see its own parameters (a thread's scratch keeps
//! the constant registers of the run it last served, never of an earlier one). Compared bit for
//! bit with the interpreter, which evaluates the same operations in the same order.

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::GMap;
use topomech_rules::{load_sources, Params, Val};

const SOURCE: &str = "dimension 2
embedding position : vec3 on <1,2>
embedding velocity : vec3 on <1,2>

rule drift(dt: f64, g: vec3) {
  left { v : <1,2> hook }
  compute {
    let vel = v.velocity + dt * (g - 0.5 * v.velocity)
    v.velocity = vel
    v.position = v.position + dt * vel + vec3(0.0, 0.0, 1e-3)
  }
}
";

fn positions(g: &GMap) -> Vec<u64> {
    crate::column_bits(g, "position")
}

fn run(compiled: bool, threads: usize) -> Vec<u64> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let (mut g, _) = build(
            &grid([60, 50], [1.0, 0.8], GridElement::Quad),
            &BuildOptions::default(),
        )
        .unwrap();
        let (mut rules, _) =
            load_sources(&[("plans.tmr".to_string(), SOURCE.to_string())]).unwrap();
        rules.set_compiled(compiled);
        rules.prepare_named(&mut g, &["velocity"]).unwrap();
        for k in 0..8 {
            let dt = if k % 2 == 0 { 1e-2 } else { 3e-3 };
            let gravity = [0.0, -9.81 + f64::from(k), 0.1 * f64::from(k)];
            let p: Params = [
                ("dt".to_string(), Val::F(dt)),
                ("g".to_string(), Val::V3(gravity)),
            ]
            .into();
            rules.apply_everywhere(&mut g, "drift", &p).unwrap();
        }
        let kinds = rules.plan_kinds();
        assert_eq!(kinds.len(), 1);
        assert_eq!(kinds[0].1, compiled, "{kinds:?}");
        positions(&g)
    })
}

#[test]
fn parameters_changing_between_runs_reach_every_chunk_on_every_thread() {
    let slow = run(false, 1);
    for threads in [1, 3] {
        assert_eq!(run(true, threads), slow, "{threads} threads");
    }
    // the parameters did act: the positions moved from the grid's
    let (g, _) = build(
        &grid([60, 50], [1.0, 0.8], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    assert_ne!(positions(&g), slow);
}
