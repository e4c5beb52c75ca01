//! A static solve that does not converge never reports success: a heavy load that one Newton
//! solve cannot balance converges by line search and automatic load stepping, to the state a
//! hundred converged load increments reach; a body with no equilibrium fails with
//! `Diverged`, its state kept as before the step, and the solver report says why.

// The load fraction reached is set to exactly 1.0 on success.
#![allow(clippy::needless_range_loop, clippy::float_cmp)]

use crate::common;

use common::model;
use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_physics::{Config, Integrator, PhysicsError, Simulation, STALL_TOLERANCE};

/// A cantilever of tetrahedra held at x = 0, stretch springs (an exact Jacobian, nonlinear
/// under large rotations), no gravity, `tip` on each vertex of the end x = 2.
fn cantilever(tip: [f64; 3]) -> Simulation {
    let mesh = cuboid([6, 1, 1], [2.0, 0.25, 0.25], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("stretch_elementary", &[("stiffness", 1e3)])],
        gravity: [0.0; 3],
        fixed: vec!["x < 1e-9".into()],
        integrator: Integrator::Static,
        dt: 1.0,
        ..Config::default()
    };
    let mut s = Simulation::new(g, cfg).unwrap();
    let load = tip_load(&s, tip, 1.0);
    s.set_external_forces(&load).unwrap();
    s
}

fn tip_load(s: &Simulation, tip: [f64; 3], fraction: f64) -> Vec<[f64; 3]> {
    s.vertex_vec3("rest")
        .unwrap()
        .iter()
        .map(|x| {
            if x[0] > 2.0 - 1e-9 {
                tip.map(|f| f * fraction)
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

/// A static configuration of one model with default parameters, no gravity, the vertices
/// where `fixed` holds held.
fn static_config(kind: &str, fixed: &str) -> Config {
    Config {
        models: vec![model(kind, &[])],
        gravity: [0.0; 3],
        fixed: vec![fixed.into()],
        integrator: Integrator::Static,
        dt: 1.0,
        ..Config::default()
    }
}

/// The largest difference of two position sets, relative to the largest displacement.
fn relative_difference(a: &[[f64; 3]], b: &[[f64; 3]], rest: &[[f64; 3]]) -> f64 {
    let mut diff = 0.0f64;
    let mut disp = 0.0f64;
    for i in 0..a.len() {
        for k in 0..3 {
            diff = diff.max((a[i][k] - b[i][k]).abs());
            disp = disp.max((a[i][k] - rest[i][k]).abs());
        }
    }
    diff / disp
}

const HEAVY: [f64; 3] = [0.0, -10.0, 0.0];

/// Today's regression: the whole heavy load at once made Newton stop after its iteration
/// limit and report success with a residual far above the load. Now the step converges (by
/// load stepping), its residual is within the tolerance, and the result is the state that
/// 100 converged static steps at fractions k/100 of the load reach, to 1e-8 relative.
#[test]
fn heavy_load_converges_by_load_stepping_to_the_incremental_solution() {
    let mut s = cantilever(HEAVY);
    let rest = s.vertex_vec3("rest").unwrap();
    s.step().unwrap();
    let report = s.solver_report().unwrap().clone();
    assert!(report.converged, "{report:?}");
    assert!(report.relative_residual <= STALL_TOLERANCE, "{report:?}");
    assert!(
        report.load_steps > 1,
        "the load needed stepping: {report:?}"
    );
    assert_eq!(report.load_fraction, 1.0);
    let once = s.vertex_vec3("position").unwrap();

    let mut inc = cantilever(HEAVY);
    for k in 1..=100 {
        let load = tip_load(&inc, HEAVY, f64::from(k) / 100.0);
        inc.set_external_forces(&load).unwrap();
        inc.step().unwrap();
        let r = inc.solver_report().unwrap();
        assert!(r.converged && r.load_steps == 1, "increment {k}: {r:?}");
    }
    let stepped = inc.vertex_vec3("position").unwrap();
    let d = relative_difference(&once, &stepped, &rest);
    assert!(d < 1e-8, "relative difference {d:e}");
    // and a large deflection (the nonlinear regime, where one Newton solve fails)
    let tip = once
        .iter()
        .zip(&rest)
        .map(|(x, r)| r[1] - x[1])
        .fold(0.0f64, f64::max);
    assert!(tip > 0.4, "tip deflection {tip}");
}

/// A light load (tip deflection 2e-3 of the length) converges in one increment, and the report says so.
#[test]
fn light_load_converges_in_one_increment() {
    let mut s = cantilever([0.0, -0.01, 0.0]);
    assert!(s.solver_report().is_none());
    s.step().unwrap();
    let r = s.solver_report().unwrap();
    assert!(
        r.converged && r.load_steps == 1 && r.iterations >= 1,
        "{r:?}"
    );
    assert_eq!(r.integrator, "static");
    assert!(r.relative_residual <= STALL_TOLERANCE);
}

/// A body held at one point, or along one line, with a load that has a moment about it,
/// fails with advice saying so (where the held vertices lie, that the body can rotate about
/// them, how to hold it) instead of the general advice; held along a line the load has no
/// moment about (gravity along it), the same body balances. Gravity -z on a 1 x 0.2 x 0.2
/// box: the weight acts at (0.5, 0.1, 0.1), off the x = y = z = 0 corner and the y = z = 0
/// edge, and on the x = y = 0 edge's line.
#[test]
fn a_body_held_at_a_point_or_on_a_line_is_told_so() {
    let mesh = cuboid([4, 1, 1], [1.0, 0.2, 0.2], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let with = |fixed: &str| Config {
        gravity: [0.0, 0.0, -9.81],
        ..static_config("corotational", fixed)
    };
    for (fixed, lies) in [
        ("x < 1e-9 && y < 1e-9 && z < 1e-9", "all lie at one point"),
        ("y < 1e-9 && z < 1e-9", "all lie on one line"),
    ] {
        let mut s = Simulation::new(g.clone(), with(fixed)).unwrap();
        let e = s.step().unwrap_err();
        let msg = e.to_string();
        // the vertex named is the largest residual's: a free one
        let PhysicsError::Diverged { vertex, .. } = &e else {
            panic!("{e:?}");
        };
        assert!(
            !s.vertex_bool("fixed").unwrap()[vertex.expect("a vertex")],
            "{msg}"
        );
        for part in [lies, "rotate rigidly", "not all on one line"] {
            assert!(msg.contains(part), "{fixed}: {part:?} missing from {msg}");
        }
        assert!(!msg.contains("try a smaller load"), "{msg}");
    }
    let mut s = Simulation::new(g, with("x < 1e-9 && y < 1e-9")).unwrap();
    s.step().unwrap();
    assert!(s.solver_report().unwrap().converged);
}

/// A body of two parts (two boxes apart) under gravity -z, one held at x = 0 and the other
/// nowhere: the failure says the body is two parts, one of which can still move rigidly,
/// held nowhere, and names a vertex of it (its smallest row, the second box's first point),
/// not the largest residual in the held part. Held instead on the first box's edge
/// y = z = 0 (a line its weight turns it about) and at the second box's corner: both parts
/// are listed, the one held at a point first (the residual cannot tell which one stops the
/// solve). A part held on a line the load does not turn it about (the edge x = y = 0,
/// parallel to gravity) is not listed.
#[test]
fn the_parts_of_a_body_left_a_rigid_motion_are_named() {
    let one = cuboid([2, 1, 1], [1.0, 0.2, 0.2], BoxElement::Tetra);
    let mut two = one.clone();
    let shift = one.points.len();
    two.points
        .extend(one.points.iter().map(|p| [p[0] + 2.0, p[1], p[2]]));
    two.kinds.extend(one.kinds.iter().copied());
    two.cells.extend(
        one.cells
            .iter()
            .map(|c| c.iter().map(|&v| v + shift).collect::<Vec<_>>()),
    );
    let (g, _) = build(&two, &BuildOptions::default()).unwrap();
    let with = |fixed: &str| Config {
        gravity: [0.0, 0.0, -9.81],
        ..static_config("corotational", fixed)
    };
    let mut s = Simulation::new(g.clone(), with("x < 1e-9")).unwrap();
    let e = s.step().unwrap_err();
    let PhysicsError::Diverged { vertex, point, .. } = &e else {
        panic!("{e:?}");
    };
    let msg = e.to_string();
    assert!(
        msg.contains("the body is 2 parts") && msg.contains("1 of them can still move rigidly"),
        "{msg}"
    );
    assert_eq!(*point, Some(shift as i64), "{msg}");
    let v = vertex.expect("a vertex of the part");
    assert!(
        msg.contains(&format!(
            "the one at vertex row {v} (input point {shift}), held nowhere"
        )),
        "{msg}"
    );
    assert!(msg.contains("; it is the one at vertex row"), "{msg}");
    // held on a line its weight turns it about, and at a point
    let corner = "(x > 1.99 && y < 1e-9 && z < 1e-9 && x < 2.01)";
    let mut s = Simulation::new(
        g.clone(),
        with(&format!("(x < 1e-9 && z < 1e-9) || {corner}")),
    )
    .unwrap();
    let e = s.step().unwrap_err();
    let msg = e.to_string();
    let at_point = msg
        .find(&format!("(input point {shift}), held at one point"))
        .unwrap_or_else(|| panic!("{msg}"));
    let on_line = msg
        .find("(input point 0), held on one line")
        .unwrap_or_else(|| panic!("{msg}"));
    assert!(at_point < on_line && msg.contains("2 of them"), "{msg}");
    // the first box held on a line parallel to gravity: only the second is listed
    let mut s = Simulation::new(g, with(&format!("(x < 1e-9 && y < 1e-9) || {corner}"))).unwrap();
    let msg = s.step().unwrap_err().to_string();
    assert!(
        msg.contains("1 of them") && msg.contains("held at one point"),
        "{msg}"
    );
    assert!(!msg.contains("held on one line"), "{msg}");
}

/// A sheet in the plane z = 0 clamped along its edge y = 0 under a load in its plane too
/// large to balance: the edge is a line, but the load does not turn the sheet about it, so
/// the failure gives the general advice, not the support's, and names a free vertex.
#[test]
fn an_in_plane_load_on_a_sheet_held_on_a_line_gets_no_support_advice() {
    let mesh = topomech_gmap::generators::grid(
        [4, 4],
        [1.0, 1.0],
        topomech_gmap::generators::GridElement::Triangle,
    );
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        gravity: [0.0, -1e5, 0.0],
        young: 1e5,
        density: 1.0,
        ..static_config("corotational", "y < 1e-9")
    };
    let mut s = Simulation::new(g, cfg).unwrap();
    let e = s.step().unwrap_err();
    let PhysicsError::Diverged { vertex, .. } = &e else {
        panic!("{e:?}");
    };
    let msg = e.to_string();
    assert!(
        !msg.contains("on one line") && !msg.contains("rigid"),
        "{msg}"
    );
    let fixed = s.vertex_bool("fixed").unwrap();
    assert!(!fixed[vertex.expect("a vertex")], "{msg}");
}

/// A body held nowhere under gravity has no equilibrium: every load increment fails, the
/// step raises `Diverged` naming the relative residual, the tolerance, that no vertex is
/// held and what to try (no vertex named), and the positions are those before the step.
#[test]
fn unbalanced_load_fails_with_the_residual() {
    let mesh = cuboid([2, 1, 1], [1.0, 0.5, 0.5], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("stretch_elementary", &[("stiffness", 1e3)])],
        integrator: Integrator::Static,
        dt: 1.0,
        ..Config::default()
    };
    let mut s = Simulation::new(g, cfg).unwrap();
    let before = s.vertex_vec3("position").unwrap();
    let e = s.step().unwrap_err();
    let PhysicsError::Diverged { step, why, .. } = &e else {
        panic!("{e:?}");
    };
    assert_eq!(*step, 1);
    let msg = e.to_string();
    for part in [
        "relative residual",
        "tolerance 1e-10",
        "no vertex is held",
        "implicit_euler",
    ] {
        assert!(msg.contains(part), "{part:?} missing from {msg}");
    }
    // no vertex is to blame: none is named
    assert!(
        matches!(e, PhysicsError::Diverged { vertex: None, .. }),
        "{e:?}"
    );
    assert!(why.contains("did not converge"), "{why}");
    assert_eq!(s.vertex_vec3("position").unwrap(), before);
    assert_eq!(s.steps(), 0);
    let r = s.solver_report().unwrap();
    assert!(!r.converged, "{r:?}");
    assert!(r.relative_residual > 0.1, "{r:?}");
}

/// An implicit Euler step reports its linear solve: converged, within its tolerance, no load
/// stepping; the explicit integrators report nothing.
#[test]
fn implicit_euler_step_reports_its_linear_solve() {
    let mesh = cuboid([2, 1, 1], [1.0, 0.5, 0.5], BoxElement::Tetra);
    for (integrator, reported) in [
        (Integrator::ImplicitEuler, true),
        (Integrator::SymplecticEuler, false),
    ] {
        let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let cfg = Config {
            models: vec![model("stretch_elementary", &[("stiffness", 1e3)])],
            fixed: vec!["x < 1e-9".into()],
            integrator,
            ..Config::default()
        };
        let mut s = Simulation::new(g, cfg).unwrap();
        s.step().unwrap();
        s.step().unwrap();
        let Some(r) = s.solver_report() else {
            assert!(!reported);
            continue;
        };
        assert!(reported);
        assert_eq!(r.integrator, "implicit_euler");
        assert!(r.converged && r.iterations >= 1, "{r:?}");
        assert!(r.relative_residual <= r.tolerance, "{r:?}");
        assert_eq!((r.load_steps, r.load_stepped_steps), (0, 0));
    }
}

/// A start with every element inverted (the box mirrored through x = 0, one vertex held at
/// the origin, no load): Newton balances the Neo-Hookean forces by collapsing the body to a
/// point (F = 0 is a stationary point of the energy, where the forces vanish), which the
/// static solve reported as converged. Now it fails with `Diverged` naming the degenerate
/// element and how far it shrank, the positions are those before the solve (exactly), and
/// the report says not converged. The same solve from the rest positions (nothing to
/// balance) still succeeds: the check refuses only elements shrunk to 1e-3 of their rest size
/// (`tests/test_hardening_static.py`: linear FEM far beyond small strains, elements inverted
/// and flattened but of a size, is still the scaled answer).
#[test]
fn a_collapsed_balance_from_an_inverted_start_is_refused() {
    let mesh = cuboid([2, 1, 1], [1.0, 0.5, 0.5], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = static_config("neohookean", "x * x + y * y + z * z < 1e-12");
    let mut s = Simulation::new(g.clone(), cfg.clone()).unwrap();
    let mirrored: Vec<[f64; 3]> = s
        .vertex_vec3("rest")
        .unwrap()
        .iter()
        .map(|p| [-p[0], p[1], p[2]])
        .collect();
    s.set_vertex_vec3("position", &mirrored).unwrap();
    let err = s.step().unwrap_err();
    let PhysicsError::Diverged { why, vertex, .. } = &err else {
        panic!("expected Diverged, got {err}");
    };
    assert!(
        why.contains("of its rest size")
            && why.contains("collapsed to a point")
            && why.contains("a start with inverted elements"),
        "{err}"
    );
    assert!(vertex.is_some(), "{err}");
    assert_eq!(s.vertex_vec3("position").unwrap(), mirrored);
    assert!(!s.solver_report().unwrap().converged);
    let mut at_rest = Simulation::new(g, cfg).unwrap();
    at_rest.step().unwrap();
    assert!(at_rest.solver_report().unwrap().converged);
}

/// A Neo-Hookean static solve from a start that is the rest shape mirrored through x = 0,
/// held on the edge x = y = 0 (which the mirror keeps, so the rest shape balances the forces),
/// no load: Newton stopped on a stationary point folded onto the held line, 20 of the 48
/// elements inverted and none shrunk to a point, and reported it converged (a saddle: QA
/// found 11 negative stiffness eigenvalues there). Elements inverted at the balance of a start
/// with inverted elements are refused now, naming how many. A start compressed to half size
/// (no element inverted) that collapses to a point is refused without blaming an inverted
/// start; and linear FEM from the rest shape keeps an inverted answer (see the test above).
#[test]
fn a_folded_balance_from_a_mirrored_start_and_a_collapse_from_a_compressed_one_are_refused() {
    let mesh = cuboid([2, 2, 2], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let run = |fixed: &str, map: &dyn Fn([f64; 3]) -> [f64; 3]| {
        let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let cfg = Config {
            young: 1e5,
            ..static_config("neohookean", fixed)
        };
        let mut s = Simulation::new(g, cfg).unwrap();
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .into_iter()
            .map(map)
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
        let out = s.step();
        assert_eq!(s.vertex_vec3("position").unwrap(), x, "positions kept");
        out
    };
    let folded = run("x * x + y * y < 1e-12", &|p| [-p[0], p[1], p[2]]).unwrap_err();
    let PhysicsError::Diverged { why, .. } = &folded else {
        panic!("expected Diverged, got {folded}");
    };
    assert!(
        why.contains("elements inverted") && why.contains("from a start where"),
        "{folded}"
    );
    let collapsed = run("x * x + y * y + z * z < 1e-12", &|p| p.map(|v| 0.5 * v)).unwrap_err();
    let PhysicsError::Diverged { why, .. } = &collapsed else {
        panic!("expected Diverged, got {collapsed}");
    };
    assert!(
        why.contains("collapsed to a point") && !why.contains("inverted elements"),
        "{collapsed}"
    );
}

/// A static run of two steps under a load large enough to invert elements (linear FEM, far
/// beyond small strains): the first step's answer has inverted elements and is kept, and the
/// second step, which starts from it (the last state a solve held), ends at the same answer
/// instead of being refused for starting inverted (QA: "diverged at step 2").
#[test]
fn a_static_run_continues_from_an_accepted_inverted_answer() {
    let mesh = cuboid([6, 1, 1], [2.0, 0.25, 0.25], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let mut s = Simulation::new(g, static_config("linear_fem", "x < 1e-9")).unwrap();
    let load = tip_load(&s, [0.0, -1e9, 0.0], 1.0);
    s.set_external_forces(&load).unwrap();
    s.step().unwrap();
    let first = s.vertex_vec3("position").unwrap();
    let rest = s.vertex_vec3("rest").unwrap();
    let inverted = s
        .elements()
        .unwrap()
        .iter()
        .filter(|el| topomech_gmap::mesh::signed_volume(el.kind, &el.rows, &first) < 0.0)
        .count();
    assert!(inverted > 0, "the load inverts elements");
    s.step().unwrap();
    let second = s.vertex_vec3("position").unwrap();
    assert!(relative_difference(&first, &second, &rest) < 1e-8);
}

/// A co-rotational cantilever of tetrahedra (1 x 0.2 x 0.2 m, E = 7e5 Pa, density 1000, under
/// gravity) bends about 27% of its length: Newton on the model's `jvp` rules (the warped
/// stiffness, without dR/dx) stalled at 75% of the load down to increments of 1/1024. The
/// solve is taken again on finite-difference products and balances. Checked independently
/// of any Jacobian: the forces recomputed at the answer plus the weights leave a residual on
/// the free vertices below 1e-9 of the total weight (the solve's tolerance is 1e-10 of the
/// load; the margin covers the norm's definition), and the tip has moved down by more than
/// a fifth of the length (the large-rotation regime that made the rules stall).
#[test]
fn a_cantilever_the_jacobian_rules_cannot_balance_balances_on_finite_differences() {
    let mesh = cuboid([10, 2, 2], [1.0, 0.2, 0.2], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("corotational", &[])],
        young: 7e5,
        poisson: 0.3,
        density: 1000.0,
        gravity: [0.0, 0.0, -9.81],
        fixed: vec!["x < 1e-9".into()],
        integrator: Integrator::Static,
        dt: 1.0,
        ..Config::default()
    };
    let mut s = Simulation::new(g, cfg).unwrap();
    s.step().unwrap();
    let r = s.solver_report().unwrap().clone();
    assert!(r.converged, "{r:?}");
    assert_eq!(r.jacobian, "finite_differences");
    let fixed = s.vertex_bool("fixed").unwrap();
    let m = s.vertex_scalar_sum("mass").unwrap();
    s.forces().unwrap();
    let f = s.vertex_vec3_sum("force").unwrap();
    let gz = -9.81;
    let mut worst: f64 = 0.0;
    for i in 0..f.len() {
        if !fixed[i] {
            let r = [f[i][0], f[i][1], f[i][2] + m[i] * gz];
            worst = worst.max((r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt());
        }
    }
    let weight: f64 = m.iter().sum::<f64>() * 9.81;
    assert!(
        worst < 1e-9 * weight,
        "residual {worst:e} of weight {weight:e}"
    );
    let x = s.vertex_vec3("position").unwrap();
    let x0 = s.vertex_vec3("rest").unwrap();
    let drop = (0..x.len())
        .map(|i| x0[i][2] - x[i][2])
        .fold(0.0f64, f64::max);
    assert!(drop > 0.2, "tip drop {drop}");
}

/// `Simulation::jvp_finite_differences` against the models' `jvp` rules at a bent state:
/// equal to 1e-6 relative for the models whose rules are exact derivatives (linear FEM,
/// Neo-Hookean, St. Venant-Kirchhoff, springs; the central differences' truncation and
/// rounding are below 1e-8 at the step used, the margin covers the forces' rounding over the
/// step), and different by more than 1e-4 for co-rotational tetrahedra, whose rules omit
/// dR/dx (what the README says): the finite differences see the rotation's derivative.
#[test]
fn finite_difference_products_are_the_exact_rules_and_see_what_the_corotational_rules_omit() {
    for (kind, exact) in [
        ("linear_fem", true),
        ("neohookean", true),
        ("stvk", true),
        ("stretch_elementary", true),
        ("corotational", false),
    ] {
        let mesh = cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra);
        let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let mut s = Simulation::new(g, static_config(kind, "x < 1e-9")).unwrap();
        // bent: a rotation about y growing along x, and a stretch
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| {
                let a = 0.3 * p[0];
                let (c, sn) = (a.cos(), a.sin());
                [1.05 * (c * p[0] + sn * p[2]), p[1], -sn * p[0] + c * p[2]]
            })
            .collect();
        s.set_vertex_vec3("position", &x).unwrap();
        let dx: Vec<[f64; 3]> = (0..x.len())
            .map(|i| {
                let t = i as f64;
                [(0.7 * t).sin(), (1.3 * t).cos(), (2.1 * t).sin()]
            })
            .collect();
        let zero = vec![[0.0; 3]; x.len()];
        let rules = s.jvp(&dx, &zero).unwrap();
        let fd = s.jvp_finite_differences(&dx, &zero).unwrap();
        assert_eq!(
            s.vertex_vec3("position").unwrap(),
            x,
            "{kind}: positions restored"
        );
        let norm = |v: &[[f64; 3]]| v.iter().flatten().map(|a| a * a).sum::<f64>().sqrt();
        let diff: Vec<[f64; 3]> = rules
            .iter()
            .zip(&fd)
            .map(|(a, b)| std::array::from_fn(|k| a[k] - b[k]))
            .collect();
        let rel = norm(&diff) / norm(&rules);
        if exact {
            assert!(rel < 1e-6, "{kind}: {rel:e}");
        } else {
            assert!(rel > 1e-4, "{kind}: {rel:e}");
        }
    }
}

/// Two boxes touching at one corner only (a pinched vertex, kept as one particle: the
/// default): the first held at x = 0, the second hanging on the corner under gravity -z.
/// The body is one part, held on a plane, yet the second box can turn about the corner:
/// the static solve fails, and its message names the second box (its smallest row and
/// input point) and the pinched vertex, not a rigid motion of the whole body or a linear
/// solver. Held on its own far face too, it balances.
#[test]
fn a_piece_hanging_on_a_pinched_vertex_is_named() {
    let one = cuboid([2, 1, 1], [1.0, 0.2, 0.2], BoxElement::Tetra);
    let shift = [1.0, 0.2, 0.2];
    let n = one.points.len();
    let corner = one
        .points
        .iter()
        .position(|p| *p == [1.0, 0.2, 0.2])
        .expect("the first box's far corner");
    let origin = one
        .points
        .iter()
        .position(|p| *p == [0.0, 0.0, 0.0])
        .expect("the first box's origin corner");
    let mut two = one.clone();
    // the second box's points, but its origin corner, which is the first box's far corner
    let mut index = vec![0; n];
    for (k, p) in one.points.iter().enumerate() {
        if k == origin {
            index[k] = corner;
        } else {
            index[k] = two.points.len();
            two.points
                .push([p[0] + shift[0], p[1] + shift[1], p[2] + shift[2]]);
        }
    }
    two.kinds.extend(one.kinds.iter().copied());
    two.cells.extend(
        one.cells
            .iter()
            .map(|c| c.iter().map(|&v| index[v]).collect::<Vec<_>>()),
    );
    let (g, _) = build(&two, &BuildOptions::default()).unwrap();
    let with = |fixed: &str| Config {
        gravity: [0.0, 0.0, -9.81],
        ..static_config("corotational", fixed)
    };
    let mut s = Simulation::new(g.clone(), with("x < 1e-9")).unwrap();
    assert_eq!(s.welded_rows().len(), 1, "one pinched vertex, one particle");
    let e = s.step().unwrap_err();
    let PhysicsError::Diverged { point, .. } = &e else {
        panic!("{e:?}");
    };
    let msg = e.to_string();
    assert!(
        msg.contains("1 piece(s) of the body touch the rest only at pinched vertices"),
        "{msg}"
    );
    assert!(
        msg.contains(&format!(
            "joined to the rest at one pinched vertex only (at vertex row {corner} (input point {corner}))"
        )),
        "{msg}"
    );
    // the second box's smallest row is its first point (input point n: the first after
    // the first box's)
    assert_eq!(*point, Some(n as i64), "{msg}");
    assert!(!msg.contains("can still move rigidly"), "{msg}");
    assert!(!msg.contains("linear solve"), "{msg}");
    // held on its own far face too: it balances
    let mut s = Simulation::new(g, with("x < 1e-9 || x > 1.999")).unwrap();
    s.step().unwrap();
    assert!(s.solver_report().unwrap().converged);
}
