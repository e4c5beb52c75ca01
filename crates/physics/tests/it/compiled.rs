//! Compiled plans against the interpreter: every shipped model's rules compile (no rule of a
//! step is left to the interpreter), and a run through the plans gives the same positions as a
//! run through the interpreter, bit for bit — the plans evaluate the same operations in the
//! same order, so no tolerance is needed. Compiled plans run native code
//! ([`Simulation::set_jit`]) or the plan evaluator: both are compared with the interpreter. A
//! renamed copy of a shipped rule file (what a user would write) compiles to the same plan and
//! gives the same results.
// exact comparisons are the point here; the shared helpers index their arrays
#![allow(clippy::float_cmp, clippy::needless_range_loop)]
use crate::common;

use common::cases::{config, mesh_for};
use common::renamed;
use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::GMap;
use topomech_physics::{Integrator, Simulation};
use topomech_rules::{Params, RuleSet};

fn run(
    kind: &str,
    dim: usize,
    integrator: Integrator,
    compiled: bool,
) -> (Simulation, Vec<[f64; 3]>) {
    run_with(kind, dim, integrator, compiled, true)
}

/// [`run`], the compiled plans running native code (`jit`) or the plan evaluator.
fn run_with(
    kind: &str,
    dim: usize,
    integrator: Integrator,
    compiled: bool,
    jit: bool,
) -> (Simulation, Vec<[f64; 3]>) {
    let (g, _) = build(&mesh_for(kind, dim), &BuildOptions::default()).unwrap();
    let mut s = Simulation::new(g, config(kind, integrator)).unwrap();
    s.set_compiled(compiled);
    s.set_jit(jit);
    for _ in 0..15 {
        s.step().unwrap();
    }
    let x = s.vertex_vec3("position").unwrap();
    (s, x)
}

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
];

#[test]
fn every_model_runs_compiled_and_matches_the_interpreter_bit_for_bit() {
    for &(kind, dim) in CASES {
        let (s, fast) = run(kind, dim, Integrator::SymplecticEuler, true);
        let interpreted: Vec<(String, bool)> = s
            .rules()
            .plan_kinds()
            .into_iter()
            .filter(|(_, c)| !c)
            .collect();
        assert!(
            interpreted.is_empty(),
            "{kind} ({dim}D): rules left to the interpreter: {interpreted:?}"
        );
        let native = s.rules().plan_native();
        assert!(
            native.iter().all(|k| k.1),
            "{kind} ({dim}D): plans without native code: {native:?}"
        );
        let (_, slow) = run(kind, dim, Integrator::SymplecticEuler, false);
        // the third mode: compiled plans through the plan evaluator instead of native code
        let (_, evaluated) = run_with(kind, dim, Integrator::SymplecticEuler, true, false);
        for (i, (a, b)) in evaluated.iter().zip(&slow).enumerate() {
            assert_eq!(
                a.map(f64::to_bits),
                b.map(f64::to_bits),
                "{kind} ({dim}D): vertex {i} differs: evaluator {a:?}, interpreted {b:?}"
            );
        }
        assert_eq!(fast.len(), slow.len());
        let moved = fast
            .iter()
            .zip(s.vertex_vec3("rest").unwrap())
            .any(|(x, r)| x != &r);
        assert!(
            moved,
            "{kind} ({dim}D): nothing moved, the comparison would be empty"
        );
        for (i, (a, b)) in fast.iter().zip(&slow).enumerate() {
            assert_eq!(
                a.map(f64::to_bits),
                b.map(f64::to_bits),
                "{kind} ({dim}D): vertex {i} differs: compiled {a:?}, interpreted {b:?}"
            );
        }
    }
}

#[test]
fn jacobian_vector_products_and_other_integrators_match_too() {
    for &(kind, dim) in &[
        ("stretch_cumulated", 2),
        ("shear_isotropic", 2),
        ("corotational", 3),
        ("mass_tensor", 3),
    ] {
        for integ in [Integrator::ExplicitEuler, Integrator::ImplicitEuler] {
            let (_, fast) = run(kind, dim, integ, true);
            let (_, slow) = run(kind, dim, integ, false);
            for (i, (a, b)) in fast.iter().zip(&slow).enumerate() {
                assert_eq!(
                    a.map(f64::to_bits),
                    b.map(f64::to_bits),
                    "{kind} ({dim}D, {integ:?}): vertex {i} differs"
                );
            }
        }
    }
}

/// The co-rotational rules as a user would copy them into a file of their own: every rule and
/// embedding renamed. The engine knows nothing of the shipped names, so the copy must compile
/// to a plan of the same size and give the same forces.
#[test]
fn a_renamed_copy_of_a_shipped_rule_file_gets_the_same_plan_and_results() {
    let copy = renamed::renamed_fem3d();
    assert!(copy.contains("rule my_warped_tets {"));
    let load = renamed::load_with_common3d;
    let shipped = load(renamed::FEM3D, "fem3d.tmr");
    let user = load(&copy, "mine.tmr");
    let (g0, _) = build(
        &cuboid([3, 2, 2], [1.5, 1.0, 1.0], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .unwrap();
    let prepare = |rules: &RuleSet, init: &str| -> GMap {
        let mut g = g0.clone();
        rules.prepare(&mut g).unwrap();
        let none = Params::new();
        rules.apply_everywhere(&mut g, "init_rest", &none).unwrap();
        let mut mat = Params::new();
        mat.insert("density".into(), topomech_rules::Val::F(1000.0));
        mat.insert("young".into(), topomech_rules::Val::F(1e5));
        mat.insert("poisson".into(), topomech_rules::Val::F(0.3));
        rules
            .apply_everywhere(&mut g, "set_material", &mat)
            .unwrap();
        mark_vertex0(&mut g);
        rules.apply_everywhere(&mut g, init, &none).unwrap();
        // deform: a shear and a stretch, so that the forces are not zero
        let pos = g.embedding_id("position").unwrap();
        for d in g.darts().collect::<Vec<_>>() {
            let p = g.real(pos, d).to_vec();
            g.set_real(pos, d, &[p[0] * 1.1 + 0.2 * p[1], p[1], p[2] - 0.05 * p[0]])
                .unwrap();
        }
        g
    };
    let mut a = prepare(&shipped, "fem_init");
    let mut b = prepare(&user, "my_init");
    let none = Params::new();
    let ra = shipped
        .apply_everywhere(&mut a, "corotational", &none)
        .unwrap();
    let rb = user
        .apply_everywhere(&mut b, "my_warped_tets", &none)
        .unwrap();
    assert_eq!(ra, rb, "same matches and evaluations");
    assert!(ra.matches > 0);
    assert_eq!(
        shipped.plan_kinds().iter().filter(|k| k.1).count(),
        user.plan_kinds().iter().filter(|k| k.1).count()
    );
    assert!(
        shipped.plan_kinds().iter().all(|k| k.1),
        "{:?}",
        shipped.plan_kinds()
    );
    assert!(
        user.plan_kinds().iter().all(|k| k.1),
        "{:?}",
        user.plan_kinds()
    );
    assert_eq!(
        shipped.plan_bytes(),
        user.plan_bytes(),
        "plans of the same size"
    );
    let fa = a.embedding_id("f_corot").unwrap();
    let fb = b.embedding_id("my_force").unwrap();
    let mut nonzero = false;
    for d in a.darts() {
        assert_eq!(a.real(fa, d), b.real(fb, d), "dart {d}");
        nonzero |= a.real(fa, d).iter().any(|x| *x != 0.0);
    }
    assert!(nonzero);
}

/// Marks one dart per volume as its `vertex0`, as the simulation does.
fn mark_vertex0(g: &mut GMap) {
    let id = g.embedding_id("vertex0").unwrap();
    let o = topomech_gmap::OrbitType::new(&[0, 1, 2]).unwrap();
    for d in g.orbit_representatives(o) {
        g.set_value(id, d, &topomech_gmap::Value::Bool(true))
            .unwrap();
    }
}

/// Meshes large enough for many chunks of rows, run in rayon pools of 1 and 3 threads: the
/// chunks are evaluated in any order on any thread, with one scratch per thread whose constant
/// registers are filled once per run (and refilled when a thread moves to another plan). The
/// positions must still be the interpreter's, bit for bit. (Parameters that change between
/// runs: `crates/rules/tests/it/plans.rs`.)
#[test]
fn many_chunks_on_several_threads_match_the_interpreter_bit_for_bit() {
    for &(kind, cells) in &[
        ("stretch_cumulated", [40usize, 30, 0]),
        ("corotational", [6, 4, 4]),
        ("mass_tensor", [6, 4, 4]),
    ] {
        let mesh = if cells[2] == 0 {
            grid([cells[0], cells[1]], [1.0, 0.75], GridElement::Quad)
        } else {
            cuboid(cells, [1.5, 1.0, 1.0], BoxElement::Tetra)
        };
        let simulate = |compiled: bool, threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
                let mut s = Simulation::new(g, config(kind, Integrator::SymplecticEuler)).unwrap();
                s.set_compiled(compiled);
                for _ in 0..6 {
                    s.step().unwrap();
                }
                let plans = s.rules().plan_kinds();
                (s.vertex_vec3("position").unwrap(), plans)
            })
        };
        let (slow, _) = simulate(false, 1);
        for threads in [1, 3] {
            let (fast, plans) = simulate(true, threads);
            assert!(
                plans.iter().all(|(_, c)| *c),
                "{kind}: rules left to the interpreter: {plans:?}"
            );
            for (i, (a, b)) in fast.iter().zip(&slow).enumerate() {
                assert_eq!(
                    a.map(f64::to_bits),
                    b.map(f64::to_bits),
                    "{kind} on {threads} threads: vertex {i} differs"
                );
            }
        }
    }
}
