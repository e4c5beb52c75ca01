//! Physical invariants and analytic solutions: mass totals, momentum, the patch test, rigid
//! rotations, a single oscillator's period and the energy behaviour of the integrators.

// Numeric reference code: index loops and formula-like doc comments mirror the math.
#![allow(
    clippy::needless_range_loop,
    clippy::doc_markdown,
    clippy::suboptimal_flops
)]

use crate::common;

use common::model;
use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions, CellKind, Mesh};
use topomech_physics::{Config, Integrator, ModelSpec, PhysicsError, Simulation};

fn sim(
    mesh: &Mesh,
    models: Vec<ModelSpec>,
    f: impl FnOnce(&mut Config),
) -> Result<Simulation, PhysicsError> {
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let mut cfg = Config {
        models,
        ..Config::default()
    };
    f(&mut cfg);
    Simulation::new(g, cfg)
}

/// Total mass is density x volume for every element type (exact up to rounding: 1e-12).
#[test]
fn total_mass_is_density_times_volume() {
    for e in [
        BoxElement::Tetra,
        BoxElement::Hexa,
        BoxElement::Wedge,
        BoxElement::Pyramid,
        BoxElement::Mixed,
    ] {
        let s = sim(
            &cuboid([3, 2, 2], [1.5, 1.0, 0.5], e),
            vec![model("stretch_elementary", &[])],
            |c| c.density = 800.0,
        )
        .unwrap();
        let m = s.total_mass().unwrap();
        assert!((m - 800.0 * 0.75).abs() < 1e-12 * m, "{e:?}: {m}");
    }
}

/// Without gravity and fixed vertices, internal forces sum to zero: linear momentum stays
/// what the initial velocities gave, to rounding (1e-9 of the momentum scale).
#[test]
fn momentum_is_conserved_without_external_forces() {
    for kind in [
        "stretch_elementary",
        "stretch_cumulated",
        "linear_fem",
        "corotational",
        "mass_tensor",
    ] {
        let mesh = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra);
        let mut s = sim(&mesh, vec![model(kind, &[])], |c| {
            c.gravity = [0.0; 3];
            c.young = 1e5;
        })
        .unwrap();
        // a non-uniform initial velocity field
        let v: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| [p[1] - 0.3, 0.2 * p[0] * p[0], -p[2]])
            .collect();
        s.set_vertex_vec3("velocity", &v).unwrap();
        let p0 = s.momentum().unwrap();
        let scale = s.total_mass().unwrap();
        for _ in 0..50 {
            s.step().unwrap();
        }
        let p1 = s.momentum().unwrap();
        for a in 0..3 {
            assert!(
                (p1[a] - p0[a]).abs() < 1e-9 * scale,
                "{kind}: momentum {p0:?} -> {p1:?}"
            );
        }
    }
}

fn rotate(p: [f64; 3], angle: f64) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]
}

fn forces_at(s: &mut Simulation, x: &[[f64; 3]]) -> Vec<[f64; 3]> {
    s.set_vertex_vec3("position", x).unwrap();
    s.forces().unwrap();
    s.vertex_vec3("force").unwrap()
}

/// A rigid rotation gives zero force with co-rotational FEM (to rounding: 1e-9 E h^2) and a
/// non-zero one with linear FEM, whose small-strain measure sees a rotation as a strain.
#[test]
fn rigid_rotation_gives_no_corotational_force() {
    let mesh = cuboid([2, 2, 2], [1.0, 1.0, 1.0], BoxElement::Tetra);
    for (kind, zero) in [("corotational", true), ("linear_fem", false)] {
        let mut s = sim(&mesh, vec![model(kind, &[])], |c| c.young = 1e6).unwrap();
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .unwrap()
            .iter()
            .map(|p| rotate(*p, 0.7))
            .collect();
        let f = forces_at(&mut s, &x);
        let worst = f
            .iter()
            .map(|v| v.iter().map(|x| x.abs()).fold(0.0, f64::max))
            .fold(0.0, f64::max);
        if zero {
            assert!(worst < 1e-9 * 1e6 * 0.25, "{kind}: max force {worst}");
        } else {
            assert!(
                worst > 1e3,
                "{kind}: a rotation is not force-free in linear FEM ({worst})"
            );
        }
    }
}

/// Patch test: an affine displacement u = A X + b gives a constant strain, so the internal
/// forces on interior vertices vanish and the forces on the boundary sum to zero; linear FEM
/// reproduces the affine field exactly (to rounding, 1e-9 of the force scale E |A| h^2).
#[test]
fn affine_field_is_an_equilibrium_of_linear_fem() {
    let mesh = cuboid([3, 3, 3], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let mut s = sim(&mesh, vec![model("linear_fem", &[])], |c| c.young = 1e6).unwrap();
    let a = [
        [0.01, 0.002, -0.003],
        [0.004, -0.02, 0.001],
        [0.0, 0.003, 0.015],
    ];
    let rest = s.vertex_vec3("rest").unwrap();
    let x: Vec<[f64; 3]> = rest
        .iter()
        .map(|p| {
            let mut q = *p;
            for i in 0..3 {
                q[i] += a[i][0] * p[0] + a[i][1] * p[1] + a[i][2] * p[2] + 0.1;
            }
            q
        })
        .collect();
    let f = forces_at(&mut s, &x);
    let scale = 1e6 * 0.02 * (1.0f64 / 3.0).powi(2);
    let mut total = [0.0; 3];
    let mut boundary_max: f64 = 0.0;
    for (p, v) in rest.iter().zip(&f) {
        let interior = p.iter().all(|c| *c > 1e-9 && *c < 1.0 - 1e-9);
        let m = v.iter().map(|x| x.abs()).fold(0.0, f64::max);
        if interior {
            assert!(m < 1e-9 * scale, "interior vertex {p:?}: force {v:?}");
        } else {
            boundary_max = boundary_max.max(m);
        }
        for k in 0..3 {
            total[k] += v[k];
        }
    }
    assert!(
        boundary_max > 1e-3 * scale,
        "the boundary carries the stress ({boundary_max})"
    );
    assert!(total.iter().all(|t| t.abs() < 1e-9 * scale), "{total:?}");
}

/// A single oscillator: a triangle whose base is fixed; its apex hangs on two springs. For a
/// small vertical displacement the stiffness is k_eff = 2 k sin^2(theta), the mass that of
/// the apex (a third of the triangle's), so the period is 2 pi sqrt(m / k_eff): within 1%.
/// The energy grows with explicit Euler and stays bounded with symplectic Euler.
#[test]
fn single_oscillator_period_and_integrator_energy() {
    let h = 0.5;
    let mesh = Mesh {
        points: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, h, 0.0]],
        kinds: vec![CellKind::Polygon],
        cells: vec![vec![0, 1, 2]],
    };
    let k = 1e3;
    let run = |integ: Integrator, steps: usize| -> (Vec<f64>, Vec<f64>, f64) {
        let mut s = sim(
            &mesh,
            vec![model("stretch_elementary", &[("stiffness", k)])],
            |c| {
                c.gravity = [0.0; 3];
                c.fixed = vec!["y < 1e-9".into()];
                c.integrator = integ;
                c.dt = 1e-4;
                c.density = 3.0;
            },
        )
        .unwrap();
        let mut x = s.vertex_vec3("rest").unwrap();
        let apex = x.iter().position(|p| p[1] > 0.1).unwrap();
        x[apex][1] += 1e-4 * h;
        s.set_vertex_vec3("position", &x).unwrap();
        let m = s.vertex_scalar("mass").unwrap()[apex];
        let mut ys = Vec::new();
        let mut energy = Vec::new();
        for _ in 0..steps {
            s.step().unwrap();
            let p = s.vertex_vec3("position").unwrap()[apex];
            ys.push(p[1] - h);
            // spring energy of the two springs + kinetic energy
            let l0 = (0.25f64 + h * h).sqrt();
            let e1 = ((p[0]).hypot(p[1]) - l0).powi(2);
            let e2 = ((p[0] - 1.0).hypot(p[1]) - l0).powi(2);
            energy.push(s.kinetic_energy().unwrap() + 0.5 * k * (e1 + e2));
        }
        (ys, energy, m)
    };
    let (ys, energy, m) = run(Integrator::SymplecticEuler, 20000);
    let theta = (h / (0.25f64 + h * h).sqrt()).asin();
    let k_eff = 2.0 * k * theta.sin().powi(2);
    let expected = 2.0 * std::f64::consts::PI * (m / k_eff).sqrt();
    // period from the downward zero crossings
    let crossings: Vec<f64> = (1..ys.len())
        .filter(|&i| ys[i - 1] > 0.0 && ys[i] <= 0.0)
        .map(|i| i as f64 * 1e-4)
        .collect();
    assert!(crossings.len() >= 3, "{crossings:?}");
    let period = (crossings[crossings.len() - 1] - crossings[0]) / (crossings.len() - 1) as f64;
    assert!(
        (period - expected).abs() < 0.01 * expected,
        "period {period} vs {expected}"
    );
    let (e0, emax) = (energy[0], energy.iter().copied().fold(0.0, f64::max));
    assert!(
        emax < 1.05 * e0,
        "symplectic Euler keeps the energy bounded: {e0} -> {emax}"
    );
    let (_, energy, _) = run(Integrator::ExplicitEuler, 20000);
    assert!(
        energy[energy.len() - 1] > 1.5 * energy[0],
        "explicit Euler gains energy: {} -> {}",
        energy[0],
        energy[energy.len() - 1]
    );
}

#[test]
fn bad_configurations_are_refused_with_a_reason() {
    let mesh = cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Hexa);
    let e = sim(&mesh, vec![model("linear_fem", &[])], |_| {}).unwrap_err();
    assert!(
        e.to_string().contains("matches nothing") && e.to_string().contains("tetrahedra"),
        "{e}"
    );
    let e = sim(&mesh, vec![model("springs", &[])], |_| {}).unwrap_err();
    assert!(e.to_string().contains("unknown model 'springs'"), "{e}");
    let e = sim(
        &mesh,
        vec![model("stretch_elementary", &[("stiffnes", 1.0)])],
        |_| {},
    )
    .unwrap_err();
    assert!(e.to_string().contains("no parameter 'stiffnes'"), "{e}");
    let e = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.dt = -1.0;
    })
    .unwrap_err();
    assert!(e.to_string().contains("dt must be positive"), "{e}");
    let e = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.fixed = vec!["x <".into()];
    })
    .unwrap_err();
    assert!(e.to_string().contains("predicate"), "{e}");
    let e = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.fixed = vec!["w < 1".into()];
    })
    .unwrap_err();
    assert!(
        e.to_string().contains("predicate") && e.to_string().contains('w'),
        "{e}"
    );
}

/// A diverging explicit run stops with an error naming the step, and keeps the last good
/// state (finite positions).
#[test]
fn divergence_is_reported_and_the_last_good_state_kept() {
    let mesh = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let mut s = sim(
        &mesh,
        vec![model("stretch_elementary", &[("stiffness", 1e9)])],
        |c| {
            c.dt = 0.05;
            c.integrator = Integrator::ExplicitEuler;
            c.fixed = vec!["x < 1e-9".into()];
        },
    )
    .unwrap();
    let mut failed = None;
    for _ in 0..2000 {
        if let Err(e) = s.step() {
            failed = Some(e);
            break;
        }
    }
    let e = failed.expect("this run diverges");
    assert!(matches!(e, PhysicsError::Diverged { .. }), "{e}");
    assert!(s
        .vertex_vec3("position")
        .unwrap()
        .iter()
        .all(|p| p.iter().all(|x| x.is_finite())));
}

/// Material regions change the element data where their predicate holds (mass doubles where
/// the density does); prescribed displacements move and fix their vertices; the ground plane
/// stops a falling box; predicates that select nothing are errors.
#[test]
fn regions_prescribed_displacements_and_ground() {
    let mesh = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Hexa);
    let region = topomech_physics::MaterialRegion {
        predicate: "x > 1".into(),
        density: Some(2000.0),
        ..Default::default()
    };
    let s = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.regions = vec![region.clone()];
    })
    .unwrap();
    assert!((s.total_mass().unwrap() - 3000.0).abs() < 1e-9);
    let s = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.prescribed = vec![("x > 1.9".into(), [0.1, 0.0, 0.0])];
    })
    .unwrap();
    let (x, r, fixed) = (
        s.vertex_vec3("position").unwrap(),
        s.vertex_vec3("rest").unwrap(),
        s.vertex_bool("fixed").unwrap(),
    );
    for i in 0..x.len() {
        let moved = r[i][0] > 1.9;
        assert_eq!(fixed[i], moved);
        assert!(((x[i][0] - r[i][0]) - if moved { 0.1 } else { 0.0 }).abs() < 1e-15);
    }
    let mut s = sim(
        &mesh,
        vec![model("stretch_elementary", &[("stiffness", 1e5)])],
        |c| c.ground = Some(topomech_physics::Ground::Height(-0.05)),
    )
    .unwrap();
    for _ in 0..300 {
        s.step().unwrap();
    }
    let lowest = s
        .vertex_vec3("position")
        .unwrap()
        .iter()
        .map(|p| p[1])
        .fold(f64::INFINITY, f64::min);
    assert!(lowest >= -0.05 - 1e-12, "{lowest}");
    let e = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.fixed = vec!["x > 100".into()];
    })
    .unwrap_err();
    assert!(e.to_string().contains("selects no vertex"), "{e}");
    let bad = topomech_physics::MaterialRegion {
        predicate: "x > 100".into(),
        young: Some(1.0),
        ..Default::default()
    };
    let e = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.regions = vec![bad];
    })
    .unwrap_err();
    assert!(e.to_string().contains("contains no element"), "{e}");
}

/// An explicit step tests the integrator's velocities before writing them (no copy of the
/// state is taken): a vertex sent faster than the object's size per step is refused there,
/// and the step then goes the way that saves the state, finds the vertex and restores it.
/// Checks: the error names that vertex and says runaway, positions and velocities are the
/// ones before the step bit for bit (no tolerance: nothing may have been written), and a
/// sane velocity afterwards steps again, to the same positions as a simulation run through
/// the interpreter (which always takes the saving way): the two ways give the same bits.
#[test]
fn a_runaway_refused_before_the_integrator_writes_leaves_the_state_as_it_was() {
    for integrator in [Integrator::SymplecticEuler, Integrator::ExplicitEuler] {
        let mesh = cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra);
        let make = || {
            sim(&mesh, vec![model("corotational", &[])], |c| {
                c.integrator = integrator;
                c.dt = 1e-4;
            })
            .unwrap()
        };
        let (mut fast, mut slow) = (make(), make());
        slow.set_compiled(false);
        for _ in 0..3 {
            fast.step().unwrap();
            slow.step().unwrap();
        }
        assert_eq!(
            fast.vertex_vec3("position").unwrap(),
            slow.vertex_vec3("position").unwrap(),
            "{integrator:?}: the checked step gives the saving step's bits"
        );
        let mut vel = fast.vertex_vec3("velocity").unwrap();
        let n = vel.len();
        // the object is about 2.45 across: 1e5 m/s moves a vertex 10 m in a step of 1e-4 s
        vel[n / 2] = [1e5, 0.0, 0.0];
        fast.set_vertex_vec3("velocity", &vel).unwrap();
        let (p0, v0) = (
            fast.vertex_vec3("position").unwrap(),
            fast.vertex_vec3("velocity").unwrap(),
        );
        match fast.step() {
            Err(PhysicsError::Diverged { vertex, why, .. }) => {
                assert_eq!(vertex, Some(n / 2), "{integrator:?}: {why}");
                assert!(why.contains("runaway"), "{integrator:?}: {why}");
            }
            other => panic!("{integrator:?}: expected a runaway, got {other:?}"),
        }
        let same = |a: &[[f64; 3]], b: &[[f64; 3]]| {
            a.iter()
                .flatten()
                .zip(b.iter().flatten())
                .all(|(x, y)| x.to_bits() == y.to_bits())
        };
        assert!(same(&fast.vertex_vec3("position").unwrap(), &p0));
        assert!(same(&fast.vertex_vec3("velocity").unwrap(), &v0));
        // back to a sane velocity: both step on, equal bit for bit
        vel[n / 2] = slow.vertex_vec3("velocity").unwrap()[n / 2];
        fast.set_vertex_vec3("velocity", &vel).unwrap();
        for _ in 0..2 {
            fast.step().unwrap();
            slow.step().unwrap();
        }
        assert!(same(
            &fast.vertex_vec3("position").unwrap(),
            &slow.vertex_vec3("position").unwrap()
        ));
    }
}

/// An implicit Euler step couples the vertices: one sent far too fast drags its neighbours
/// across the object in the same step. The error names the fastest vertex, the one sent
/// (the middle row of the box), not the first row that ran away in row order (a neighbour
/// with a smaller row, which the scan in order named before).
#[test]
fn an_implicit_runaway_names_the_fastest_vertex() {
    let mesh = cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let mut s = sim(&mesh, vec![model("corotational", &[])], |c| {
        c.integrator = Integrator::ImplicitEuler;
        c.dt = 1e-3;
    })
    .unwrap();
    let mut vel = s.vertex_vec3("velocity").unwrap();
    let n = vel.len();
    vel[n - 1] = [1e9, 0.0, 0.0];
    s.set_vertex_vec3("velocity", &vel).unwrap();
    match s.step() {
        Err(PhysicsError::Diverged { vertex, why, .. }) => {
            assert_eq!(vertex, Some(n - 1), "{why}");
            assert!(why.contains("runaway"), "{why}");
        }
        other => panic!("expected a runaway, got {other:?}"),
    }
}

/// A body in uniform motion fast enough to cross its own size in one step is not a runaway:
/// the runaway test measures velocities relative to the body's mean velocity. Each
/// integrator takes the step, and every vertex moves by v dt (the forces of a rigid
/// translation are zero up to rounding: 1e-9 of the step, far above rounding and far
/// below any deformation a force could give in one step of 1e-3 s).
#[test]
fn a_fast_uniform_motion_is_not_a_runaway() {
    let mesh = cuboid([2, 1, 1], [1.0, 0.5, 0.5], BoxElement::Tetra);
    for integrator in [
        Integrator::SymplecticEuler,
        Integrator::ExplicitEuler,
        Integrator::ImplicitEuler,
    ] {
        let mut s = sim(&mesh, vec![model("corotational", &[])], |c| {
            c.integrator = integrator;
            c.gravity = [0.0; 3];
            c.dt = 1e-3;
        })
        .unwrap();
        let x0 = s.vertex_vec3("position").unwrap();
        let v = vec![[2000.0, 0.0, 0.0]; x0.len()];
        s.set_vertex_vec3("velocity", &v).unwrap();
        s.step()
            .unwrap_or_else(|e| panic!("{integrator:?}: a uniform motion refused: {e}"));
        let x1 = s.vertex_vec3("position").unwrap();
        for (a, b) in x0.iter().zip(&x1) {
            assert!(
                (b[0] - a[0] - 2.0).abs() < 1e-9,
                "{integrator:?}: {a:?} -> {b:?}"
            );
            assert!((b[1] - a[1]).abs() < 1e-9 && (b[2] - a[2]).abs() < 1e-9);
        }
    }
}

/// A cut box's two pieces flying apart, each in uniform motion faster than the box's size
/// per step, are not runaways: speeds are measured from the mean velocity of each part of
/// the body (its connected components). One vertex of a piece sent far faster than the
/// rest is still one, named, and the state restored; after a uniform motion the fast test
/// measures from that motion (the frame), and still refuses that vertex.
#[test]
fn pieces_in_uniform_motion_are_not_runaways_but_a_vertex_of_them_is() {
    let mesh = cuboid([4, 1, 1], [2.0, 0.5, 0.5], BoxElement::Tetra);
    let mut s = sim(&mesh, vec![model("corotational", &[])], |c| {
        c.gravity = [0.0; 3];
        c.dt = 1e-3;
    })
    .unwrap();
    // between the cells at x = 1: the two pieces come apart
    let opened = s
        .cut(&topomech_physics::Cut::Plane {
            normal: [1.0, 0.0, 0.0],
            offset: 1.0,
        })
        .unwrap();
    assert!(opened.unsewn > 0);
    assert_eq!(s.gmap().cell_counts().components, 2);
    let x = s.vertex_vec3("position").unwrap();
    // each row's piece by its elements' centroids (the rows at x = 1 were split, one per
    // piece); the box is 2.1 across: 3000 m/s moves 3 m in a step of 1e-3 s
    let mut v = vec![[0.0; 3]; x.len()];
    for e in s.elements().unwrap() {
        let cx = e.rows.iter().map(|&r| x[r][0]).sum::<f64>() / e.rows.len() as f64;
        for &r in &e.rows {
            v[r] = [if cx > 1.0 { 3000.0 } else { -3000.0 }, 0.0, 0.0];
        }
    }
    s.set_vertex_vec3("velocity", &v).unwrap();
    for _ in 0..3 {
        s.step().expect("two pieces in uniform motion");
    }
    let mut v = s.vertex_vec3("velocity").unwrap();
    let fast = x.iter().position(|p| p[0] > 1.9).unwrap();
    v[fast][1] += 1e5;
    s.set_vertex_vec3("velocity", &v).unwrap();
    let before = s.vertex_vec3("position").unwrap();
    match s.step() {
        Err(PhysicsError::Diverged { vertex, why, .. }) => {
            assert_eq!(vertex, Some(fast), "{why}");
            assert!(
                why.contains("relative to the mean velocity of its part"),
                "{why}"
            );
        }
        other => panic!("expected a runaway, got {other:?}"),
    }
    assert_eq!(s.vertex_vec3("position").unwrap(), before);
    // one body in uniform motion: its frame is set; a runaway vertex is refused from it
    let mut s = sim(&mesh, vec![model("corotational", &[])], |c| {
        c.gravity = [0.0; 3];
        c.dt = 1e-3;
    })
    .unwrap();
    let n = s.vertex_vec3("position").unwrap().len();
    s.set_vertex_vec3("velocity", &vec![[0.0, 2000.0, 0.0]; n])
        .unwrap();
    for _ in 0..3 {
        s.step().expect("a uniform motion");
    }
    let mut v = s.vertex_vec3("velocity").unwrap();
    v[n - 1][2] += 3000.0;
    s.set_vertex_vec3("velocity", &v).unwrap();
    match s.step() {
        Err(PhysicsError::Diverged { vertex, .. }) => assert_eq!(vertex, Some(n - 1)),
        other => panic!("expected a runaway, got {other:?}"),
    }
}

/// In a body moving at 1e14 m/s, a vertex sent 1e4 m/s faster (10 m in a step of 1e-3 s,
/// against a size of 1.2 m) is a runaway still: the rounding allowed for the mean is a few
/// eps per row of the vertex's own motion (about 1e-2 m here), not a fixed fraction of it.
#[test]
fn a_runaway_inside_a_very_fast_body_is_found() {
    let mesh = cuboid([2, 1, 1], [1.0, 0.5, 0.5], BoxElement::Tetra);
    let mut s = sim(&mesh, vec![model("corotational", &[])], |c| {
        c.gravity = [0.0; 3];
        c.dt = 1e-3;
    })
    .unwrap();
    let n = s.vertex_vec3("position").unwrap().len();
    let mut v = vec![[1e14, 0.0, 0.0]; n];
    v[n - 1][1] = 1e4;
    s.set_vertex_vec3("velocity", &v).unwrap();
    match s.step() {
        Err(PhysicsError::Diverged { vertex, why, .. }) => {
            assert_eq!(vertex, Some(n - 1), "{why}");
        }
        other => panic!("expected a runaway, got {other:?}"),
    }
}
