//! Native code for compiled plans (`TOPOMECH_JIT`, [`Simulation::set_jit`]) against the plan
//! evaluator: for every shipped model and every integrator, steps with native code give the
//! same positions, velocities and forces as steps through the evaluator, bit for bit, on 1 and
//! 3 threads; and the native code does run (no silent fallback) for the rules named below.
// exact comparisons are the point here
#![allow(clippy::float_cmp, clippy::needless_range_loop)]
use crate::common;

use common::cases::{config, mesh_for};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_physics::{Integrator, Simulation};

/// Model and mesh: 2 (quads, or triangles for the membranes), 3 (tetrahedra), 4 (hexahedra).
const CASES: &[(&str, usize)] = &[
    ("stretch_elementary", 2),
    ("stretch_cumulated", 2),
    ("stretch_cumulated", 3),
    ("shear_isotropic", 2),
    ("shear_anisotropic", 2),
    ("shear_volumic", 4),
    ("stretch_cumulated", 4),
    ("corotational", 4),
    ("bending_linear", 2),
    ("bending_angular", 2),
    ("linear_fem", 3),
    ("corotational", 3),
    ("corotational", 2),
    ("mass_tensor", 3),
    ("neohookean", 3),
    ("stvk", 3),
];

const INTEGRATORS: &[Integrator] = &[
    Integrator::ExplicitEuler,
    Integrator::SymplecticEuler,
    Integrator::ImplicitEuler,
    Integrator::Static,
];

type State = (
    Vec<[f64; 3]>,
    Vec<[f64; 3]>,
    Vec<[f64; 3]>,
    Vec<(String, bool)>,
);

/// Steps (warm-up steps with the evaluator, then one more in the mode asked, from the same
/// state): positions, velocities, forces, and which rules ran native code.
fn run(kind: &str, dim: usize, integ: Integrator, jit: bool, threads: usize) -> Option<State> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let (g, _) = build(&mesh_for(kind, dim), &BuildOptions::default()).unwrap();
        // a model without Jacobian rules is refused by the implicit integrators
        let mut s = Simulation::new(g, config(kind, integ)).ok()?;
        s.set_jit(false);
        let warm = if integ == Integrator::Static { 0 } else { 5 };
        for _ in 0..warm {
            s.step().unwrap();
        }
        s.set_jit(jit);
        // a static solve that does not converge on this small mesh fails in both modes
        s.step().ok()?;
        if integ != Integrator::Static {
            s.step().unwrap();
        }
        s.forces().unwrap();
        let native = s.rules().plan_native();
        Some((
            s.vertex_vec3("position").unwrap(),
            s.vertex_vec3("velocity").unwrap(),
            s.vertex_vec3("force").unwrap(),
            native,
        ))
    })
}

fn bits(v: &[[f64; 3]]) -> Vec<[u64; 3]> {
    v.iter().map(|x| x.map(f64::to_bits)).collect()
}

#[test]
fn every_model_and_integrator_matches_the_evaluator_bit_for_bit() {
    let mut report = Vec::new();
    for &(kind, dim) in CASES {
        for &integ in INTEGRATORS {
            let Some(slow) = run(kind, dim, integ, false, 1) else {
                assert!(run(kind, dim, integ, true, 1).is_none());
                report.push(format!(
                    "{kind} ({dim}D, {integ:?}): refused or fails in both modes"
                ));
                continue;
            };
            assert!(
                slow.3.iter().all(|k| !k.1),
                "{kind} ({dim}D, {integ:?}): native code with the switch off: {:?}",
                slow.3
            );
            for threads in [1, 3] {
                let fast = run(kind, dim, integ, true, threads).expect("runs as the evaluator");
                let what = format!("{kind} ({dim}D, {integ:?}, {threads} threads)");
                assert_eq!(bits(&fast.0), bits(&slow.0), "{what}: positions differ");
                assert_eq!(bits(&fast.1), bits(&slow.1), "{what}: velocities differ");
                assert_eq!(bits(&fast.2), bits(&slow.2), "{what}: forces differ");
                if threads == 1 {
                    let n = fast.3.iter().filter(|k| k.1).count();
                    report.push(format!("{what}: {n}/{} plans native", fast.3.len()));
                }
            }
        }
    }
    println!("{}", report.join("\n"));
}

#[test]
fn native_code_runs_for_the_cloth_springs_and_the_mass_tensor() {
    let before = topomech_rules::jit::compiled_count();
    let chunked = topomech_rules::jit::chunked_runs();
    for (kind, dim, rules) in [
        ("stretch_cumulated", 2, &["stretch_cumulated"][..]),
        ("mass_tensor", 3, &["mass_tensor"][..]),
    ] {
        let (_, _, _, native) = run(kind, dim, Integrator::SymplecticEuler, true, 1).unwrap();
        for r in rules {
            let hit: Vec<_> = native.iter().filter(|k| k.0.contains(r)).collect();
            assert!(
                !hit.is_empty(),
                "{kind}: no plan named like {r}: {native:?}"
            );
            assert!(hit.iter().all(|k| k.1), "{kind}: not native: {native:?}");
        }
        assert!(native.iter().all(|k| k.1), "{kind}: {native:?}");
    }
    assert!(topomech_rules::jit::compiled_count() > before);
    // the step's plans check and scatter their values chunk by chunk (`Plan::run_chunked`),
    // the path the bit-for-bit test above compares with the evaluator
    assert!(topomech_rules::jit::chunked_runs() > chunked);
}
