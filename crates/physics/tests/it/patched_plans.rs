//! Plans patched after a topology change, not rebuilt: after every incremental change (a plane
//! cut, a single-face cut, successive cuts, a blade sweeping over several steps, a fracture),
//! on 2D and 3D meshes with springs and co-rotational FEM, the map is valid, the rules'
//! plans were patched (not rebuilt), the forces they give equal those of plans built from
//! scratch to 1e-12 of their scale, the mass and the momentum are kept, and a run in
//! lockstep with one whose plans are rebuilt every step stays the same.

// Numeric test code (and the shared helpers): index loops mirror the math.
#![allow(clippy::doc_markdown, clippy::needless_range_loop)]

use crate::common;

use common::model;
use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_physics::{
    Blade, Config, Criterion, Cut, Fracture, ModelSpec, Simulation, TimedEvent,
};

fn models() -> Vec<ModelSpec> {
    vec![
        // (one stiffness: the two spring models share it, `stretch_init`)
        model("stretch_cumulated", &[("stiffness", 1e4)]),
        model("stretch_elementary", &[("stiffness", 1e4)]),
        model("corotational", &[]),
    ]
}

fn sim(mesh: &Mesh, blades: Vec<Blade>) -> Simulation {
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: models(),
        young: 1e5,
        gravity: [0.0, -9.81, 0.0],
        fixed: vec!["x < 1e-9".into()],
        blades,
        ..Config::default()
    };
    Simulation::new(g, cfg).unwrap()
}

fn box3() -> Mesh {
    cuboid([6, 3, 3], [2.0, 1.0, 1.0], BoxElement::Tetra)
}

fn grid2() -> Mesh {
    grid([8, 4], [2.0, 1.0], GridElement::Triangle)
}

/// A deformation and a velocity, so that every force term is non-zero.
fn shake(s: &mut Simulation) {
    let rest = s.vertex_vec3("rest").unwrap();
    let x: Vec<[f64; 3]> = rest
        .iter()
        .map(|p| {
            [
                p[0] + 0.02 * (3.0 * p[1]).sin(),
                p[1] + 0.03 * (2.0 * p[0]).cos(),
                p[2] + 0.01 * p[0] * p[1],
            ]
        })
        .collect();
    s.set_vertex_vec3("position", &x).unwrap();
    // (held vertices keep zero velocity)
    let held = s.vertex_bool("fixed").unwrap();
    let v: Vec<[f64; 3]> = rest
        .iter()
        .zip(&held)
        .map(|(p, h)| {
            if *h {
                [0.0; 3]
            } else {
                [0.1 * p[1], -0.2 * p[0], 0.05]
            }
        })
        .collect();
    s.set_velocities(&v).unwrap();
}

fn close(a: &[[f64; 3]], b: &[[f64; 3]], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let scale = a
        .iter()
        .chain(b)
        .flat_map(|p| p.iter())
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(1e-300);
    for (i, (p, q)) in a.iter().zip(b).enumerate() {
        for k in 0..3 {
            assert!(
                (p[k] - q[k]).abs() <= 1e-12 * scale,
                "{what}: vertex {i}: {p:?} vs {q:?} (scale {scale})"
            );
        }
    }
}

/// The forces of `s` with its plans as they are (patched when the topology changed since
/// they were built), against those of plans built from scratch.
fn check_forces(s: &mut Simulation, what: &str) {
    s.forces().unwrap();
    let patched = s.vertex_vec3("force").unwrap();
    s.set_compiled(true); // drops every plan
    s.forces().unwrap();
    let fresh = s.vertex_vec3("force").unwrap();
    close(&patched, &fresh, what);
    assert!(
        patched.iter().flatten().any(|x| *x != 0.0),
        "{what}: forces"
    );
}

/// After a change: the map valid, mass and momentum kept, forces as from scratch, and plans
/// patched since `patches_before`.
fn check_change(
    s: &mut Simulation,
    mass: f64,
    momentum: [f64; 3],
    patches_before: usize,
    what: &str,
) {
    assert!(s.gmap().is_valid(), "{what}: {:?}", s.gmap().validate());
    let m = s.total_mass().unwrap();
    assert!(
        (m - mass).abs() <= 1e-12 * mass,
        "{what}: mass {m} vs {mass}"
    );
    let p = s.momentum().unwrap();
    let scale = momentum.iter().fold(1e-300f64, |a, x| a.max(x.abs()));
    for k in 0..3 {
        assert!(
            (p[k] - momentum[k]).abs() <= 1e-12 * scale,
            "{what}: momentum {p:?} vs {momentum:?}"
        );
    }
    check_forces(s, what);
    assert!(
        s.rules().plan_patches() > patches_before,
        "{what}: no plan was patched"
    );
}

/// After [`check_change`]: matches were rebuilt without a search since `rebuilt_before` (a
/// change that opens faces re-slots the vertices around them, whose springs and elements
/// keep their links: `RuleSet::matches_rebuilt`).
fn check_rebuilt(s: &Simulation, rebuilt_before: usize, what: &str) {
    assert!(
        s.rules().matches_rebuilt() > rebuilt_before,
        "{what}: no match was rebuilt"
    );
}

/// Applies `change` to `s`, checks it (see [`check_change`]), and returns the faces opened.
fn change(s: &mut Simulation, what: &str, f: impl FnOnce(&mut Simulation) -> usize) -> usize {
    // plans built on the current topology, so that the change patches them
    s.forces().unwrap();
    let mass = s.total_mass().unwrap();
    let momentum = s.momentum().unwrap();
    let patches = s.rules().plan_patches();
    let rebuilt = s.rules().matches_rebuilt();
    let n = f(s);
    assert!(n > 0, "{what}: nothing opened");
    check_change(s, mass, momentum, patches, what);
    check_rebuilt(s, rebuilt, what);
    n
}

fn plane(s: &mut Simulation, normal: [f64; 3], offset: f64) -> usize {
    s.cut(&Cut::Plane { normal, offset }).unwrap().unsewn
}

#[test]
fn a_plane_cut_patches_the_plans_3d_and_2d() {
    for mesh in [box3(), grid2()] {
        let mut s = sim(&mesh, vec![]);
        shake(&mut s);
        change(&mut s, "plane cut", |s| plane(s, [1.0, 0.0, 0.0], 1.0));
        for _ in 0..3 {
            s.step().unwrap();
        }
    }
}

#[test]
fn a_single_face_cut_patches_the_plans() {
    // one interior face (3D) or edge (2D): only its centroid passes the predicate; a
    // predicate cut is a timed event, done during the step
    for (mesh, pred, three) in [
        (box3(), "x > 0.99 && x < 1.01 && y < 0.2 && z < 0.34", true),
        (grid2(), "x > 0.99 && x < 1.01 && y < 0.2", false),
    ] {
        let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let cfg = Config {
            models: models(),
            young: 1e5,
            gravity: [0.0; 3],
            events: vec![TimedEvent {
                time: Config::default().dt,
                cut: Cut::Where(pred.into()),
            }],
            ..Config::default()
        };
        let mut s = Simulation::new(g, cfg).unwrap();
        shake(&mut s);
        s.forces().unwrap();
        let mass = s.total_mass().unwrap();
        let patches = s.rules().plan_patches();
        s.step().unwrap();
        let n: usize = s.topology_changes().iter().map(|c| c.unsewn).sum();
        assert!(n >= 1, "nothing cut");
        assert!(n <= if three { 2 } else { 1 }, "{n} faces cut");
        assert!(s.gmap().is_valid());
        assert!((s.total_mass().unwrap() - mass).abs() <= 1e-12 * mass);
        check_forces(&mut s, "single-face cut");
        assert!(s.rules().plan_patches() > patches, "no plan was patched");
    }
}

#[test]
fn successive_cuts_patch_the_plans_and_a_run_stays_with_rebuilt_plans() {
    for mesh in [box3(), grid2()] {
        let mut a = sim(&mesh, vec![]);
        let mut b = sim(&mesh, vec![]);
        shake(&mut a);
        shake(&mut b);
        for (k, off) in [0.5, 1.0, 1.5].into_iter().enumerate() {
            let what = format!("cut {k}");
            change(&mut a, &what, |s| plane(s, [1.0, 0.0, 0.0], off));
            assert!(plane(&mut b, [1.0, 0.0, 0.0], off) > 0);
            for _ in 0..2 {
                a.step().unwrap();
                b.set_compiled(true); // b rebuilds every plan every step
                b.step().unwrap();
                close(
                    &a.vertex_vec3("position").unwrap(),
                    &b.vertex_vec3("position").unwrap(),
                    &format!("{what}: positions"),
                );
                close(
                    &a.vertex_vec3("velocity").unwrap(),
                    &b.vertex_vec3("velocity").unwrap(),
                    &format!("{what}: velocities"),
                );
            }
        }
        // a cut across the earlier ones
        change(&mut a, "cross cut", |s| plane(s, [0.0, 1.0, 0.0], 0.5));
    }
}

#[test]
fn a_blade_sweeping_over_several_steps_patches_the_plans() {
    for mesh in [box3(), grid2()] {
        let dt = Config::default().dt;
        let blade = Blade {
            start: 0.0,
            end: 4.0 * dt,
            from: [[1.0, 1.2, -0.1], [1.0, 1.2, 1.1]],
            to: [[1.0, -0.2, -0.1], [1.0, -0.2, 1.1]],
        };
        let mut s = sim(&mesh, vec![blade.clone()]);
        let mut r = sim(&mesh, vec![blade]);
        shake(&mut s);
        shake(&mut r);
        s.forces().unwrap();
        let mut cuts = 0;
        let patches = s.rules().plan_patches();
        for step in 0..5 {
            let mass = s.total_mass().unwrap();
            s.step().unwrap();
            r.set_compiled(true);
            r.step().unwrap();
            let what = format!("blade step {step}");
            assert!(s.gmap().is_valid(), "{what}");
            assert!(
                (s.total_mass().unwrap() - mass).abs() <= 1e-12 * mass,
                "{what}"
            );
            close(
                &s.vertex_vec3("position").unwrap(),
                &r.vertex_vec3("position").unwrap(),
                &what,
            );
            close(
                &s.vertex_vec3("velocity").unwrap(),
                &r.vertex_vec3("velocity").unwrap(),
                &what,
            );
            if s.topology_changes().len() > cuts {
                cuts = s.topology_changes().len();
                // the blade cut during this step: the next forces patch the plans
                check_forces(&mut s, &what);
            }
        }
        assert!(cuts >= 2, "the blade cut in {cuts} steps only");
        assert!(
            s.rules().plan_patches() > patches,
            "no plan was patched during the sweep"
        );
    }
}

#[test]
fn a_fracture_patches_the_plans() {
    for mesh in [box3(), grid2()] {
        let mut s = sim(&mesh, vec![]);
        // stretch a slab x in [0.6, 0.9] along y, then open what passes 20% strain
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| {
                if p[0] > 0.6 && p[0] < 0.9 {
                    [p[0], 1.5 * p[1], p[2]]
                } else {
                    *p
                }
            })
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
        change(&mut s, "fracture", |s| {
            s.fracture(Fracture {
                criterion: Criterion::Strain,
                threshold: 0.2,
            })
            .unwrap()
            .unsewn
        });
    }
}

/// A rule without matches adds nothing to the map, before and after a change: the
/// co-rotational hexahedron rules (the shipped file declares them beside the tetrahedron
/// rules) match no tetrahedron, so their embeddings (`k_hex00`, ...) are never created, not
/// even by a plan patched after a cut. This test failed when a plan without matches bound
/// (and so created) every embedding of its rule: 8 embeddings, 6 KB per tetrahedron.
#[test]
fn a_rule_without_matches_creates_no_embedding_when_its_plan_is_patched() {
    let mut s = sim(&box3(), vec![]);
    s.step().unwrap();
    s.step().unwrap();
    for name in ["k_hex00", "k_hex11", "g_hex0", "x_rest1"] {
        assert!(s.gmap().embedding_id(name).is_none(), "{name} after set-up");
    }
    assert!(plane(&mut s, [1.0, 0.0, 0.0], 1.0) > 0);
    let patches = s.rules().plan_patches();
    s.step().unwrap();
    s.step().unwrap();
    assert!(
        s.rules().plan_patches() > patches,
        "the step after the cut patched plans"
    );
    for name in ["k_hex00", "k_hex11", "g_hex0", "x_rest1"] {
        assert!(s.gmap().embedding_id(name).is_none(), "{name} after a cut");
    }
}

/// `Simulation::prepare_cuts` builds what cuts search the faces with before the first cut:
/// the same steps and cuts, with and without it, give the same map and the same forces and
/// positions bit for bit (it must not change which plans are patched or how), on tetrahedra
/// with co-rotational FEM and springs, a step before it as after.
#[test]
fn prepare_cuts_changes_no_result() {
    let run = |prepare: bool, models: Vec<ModelSpec>| {
        let (g, _) = build(&box3(), &BuildOptions::default()).unwrap();
        let cfg = Config {
            models,
            young: 1e5,
            fixed: vec!["x < 1e-9".into()],
            ..Config::default()
        };
        let mut s = Simulation::new(g, cfg).unwrap();
        shake(&mut s);
        s.step().unwrap();
        if prepare {
            s.prepare_cuts().unwrap();
        }
        let r = s
            .cut(&Cut::Plane {
                normal: [1.0, 1.0, 0.0],
                offset: 1.1,
            })
            .unwrap();
        s.forces().unwrap();
        let f = s.vertex_vec3("force").unwrap();
        s.step().unwrap();
        (
            r,
            f,
            s.vertex_vec3("position").unwrap(),
            s.vertex_vec3("velocity").unwrap(),
        )
    };
    for models in [models(), vec![model("corotational", &[])]] {
        let (a, b) = (run(false, models.clone()), run(true, models));
        assert!(a.0.unsewn > 0);
        assert_eq!(a.0, b.0, "faces unsewn, rows added");
        let bits = |v: &[[f64; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.1), bits(&b.1), "forces after the cut");
        assert_eq!(bits(&a.2), bits(&b.2), "positions after a step");
        assert_eq!(bits(&a.3), bits(&b.3), "velocities after a step");
    }
}

/// Plans patched in place (the rows of dropped matches left dead where they are, the new
/// ones appended: the springs', the accumulation's with its aggregates, the integrator's) give
/// the forces of plans built from scratch after each of a series of cuts (a simulation
/// never rebuilding its plans, against one rebuilding them before each comparison), and keep
/// doing so once the dead rows are many and a patch compacts the plan instead (the other
/// path), with the map valid and mass and momentum kept after each cut.
#[test]
fn plans_patched_in_place_and_then_compacted_give_fresh_forces() {
    let mesh = cuboid([10, 4, 4], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let (mut a, mut b) = (sim(&mesh, vec![]), sim(&mesh, vec![]));
    shake(&mut a);
    shake(&mut b);
    a.forces().unwrap();
    let mass = a.total_mass().unwrap();
    let (mut in_place, mut other) = (0, 0);
    for k in 1..10 {
        let what = format!("cut {k}");
        let before = (
            a.rules().plan_patches_in_place(),
            a.rules().plan_patches() - a.rules().plan_patches_in_place(),
        );
        let x = 0.2 * f64::from(k);
        assert!(
            plane(&mut a, [1.0, 0.0, 0.0], x) > 0,
            "{what}: nothing opened"
        );
        assert!(
            plane(&mut b, [1.0, 0.0, 0.0], x) > 0,
            "{what}: nothing opened"
        );
        assert!(a.gmap().is_valid(), "{what}: {:?}", a.gmap().validate());
        let m = a.total_mass().unwrap();
        assert!(
            (m - mass).abs() <= 1e-12 * mass,
            "{what}: mass {m} vs {mass}"
        );
        a.forces().unwrap();
        b.set_compiled(true); // drops every plan
        b.forces().unwrap();
        close(
            &a.vertex_vec3("force").unwrap(),
            &b.vertex_vec3("force").unwrap(),
            &what,
        );
        in_place += a.rules().plan_patches_in_place() - before.0;
        other += a.rules().plan_patches() - a.rules().plan_patches_in_place() - before.1;
        a.step().unwrap();
        b.step().unwrap();
        close(
            &a.vertex_vec3("position").unwrap(),
            &b.vertex_vec3("position").unwrap(),
            &format!("{what}, a step later"),
        );
    }
    // three plans patched per cut (springs, accumulation, integrator): more than two per
    // cut in place means the accumulation's, which has aggregates, is among them (16 of 27
    // before aggregates were patched in place, 24 after)
    assert!(in_place > 18, "{in_place} patches in place");
    // the compactions take the other path
    assert!(other >= 9, "{other} patches by filtering");
}
