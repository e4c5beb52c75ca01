//! External loads (`f_ext`) and the ground plane: a static solve balances the loads by the
//! reactions of the held vertices; the loads stay as set; a body falling along -z stops on a
//! ground whose normal is the opposite of gravity.

// Numeric reference code: index loops mirror the math; the default normal is compared exactly
// (-g / |g| of an axis-aligned g is exact).
#![allow(clippy::needless_range_loop, clippy::float_cmp)]

use crate::common;

use common::model;
use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_physics::{Config, Ground, Integrator, ModelSpec, PhysicsError, Simulation};

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

/// A bar of tetrahedra held at x = 0, loaded by forces on its end x = 1 (no gravity): the
/// static solve reaches equilibrium, so the forces on the free vertices (models plus loads)
/// vanish and the reactions on the held ones add up to the total load (the models' internal
/// forces sum to zero). The solve stops at a residual of 1e-10 of the load: 1e-8 here.
#[test]
fn static_solve_balances_external_loads() {
    let mesh = cuboid([4, 1, 1], [1.0, 0.2, 0.2], BoxElement::Tetra);
    let mut s = sim(&mesh, vec![model("linear_fem", &[])], |c| {
        c.young = 1e6;
        c.gravity = [0.0; 3];
        c.fixed = vec!["x < 1e-9".into()];
        c.integrator = Integrator::Static;
        c.dt = 1.0;
    })
    .unwrap();
    let rest = s.vertex_vec3("rest").unwrap();
    let load: Vec<[f64; 3]> = rest
        .iter()
        .map(|x| {
            if x[0] > 1.0 - 1e-9 {
                [0.5, -1.0, 0.25]
            } else {
                [0.0; 3]
            }
        })
        .collect();
    let n_end = load.iter().filter(|f| f[1] != 0.0).count();
    assert_eq!(n_end, 4);
    s.set_external_forces(&load).unwrap();
    s.step().unwrap();
    assert_eq!(s.external_forces().unwrap(), load, "the loads stay as set");
    s.forces().unwrap();
    let force = s.vertex_vec3("force").unwrap();
    let fixed = s.vertex_bool("fixed").unwrap();
    let total = [0.5 * 4.0, -4.0, 0.25 * 4.0];
    let mut reaction = [0.0; 3];
    for (f, held) in force.iter().zip(&fixed) {
        if *held {
            for a in 0..3 {
                reaction[a] += f[a];
            }
        } else {
            assert!(f.iter().all(|x| x.abs() < 1e-8), "{f:?}");
        }
    }
    for a in 0..3 {
        assert!((reaction[a] - total[a]).abs() < 1e-8, "{reaction:?}");
    }
    let u = s.vertex_vec3("position").unwrap();
    assert!(u.iter().zip(&rest).any(|(x, r)| (x[1] - r[1]) < -1e-4));
}

/// Loads of the wrong length or non-finite are refused, naming the row.
#[test]
fn bad_external_loads_are_refused() {
    let mesh = cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Hexa);
    let mut s = sim(&mesh, vec![model("stretch_elementary", &[])], |_| {}).unwrap();
    let n = s.vertex_darts().len();
    let e = s.set_external_forces(&vec![[0.0; 3]; n - 1]).unwrap_err();
    assert!(
        e.to_string().contains("7 values given for 8 vertices"),
        "{e}"
    );
    let mut bad = vec![[0.0; 3]; n];
    bad[3][2] = f64::INFINITY;
    let e = s.set_external_forces(&bad).unwrap_err();
    assert!(
        e.to_string()
            .contains("must be finite: not so at vertices 3"),
        "{e}"
    );
}

/// Gravity along -z: the ground's default normal is +z, so a box stops on the plane z = h
/// (given as a height, or as a point without normal): no vertex is ever below it (1e-12),
/// and the box did reach it (a vertex on it, 1e-9). A zero normal is refused, naming the ground.
#[test]
fn ground_normal_defaults_to_the_opposite_of_gravity() {
    let mesh = cuboid([1, 1, 1], [0.2, 0.2, 0.2], BoxElement::Hexa);
    for ground in [
        Ground::Height(-0.1),
        Ground::Plane {
            point: [3.0, -7.0, -0.1],
            normal: None,
        },
        Ground::Plane {
            point: [0.0, 0.0, -0.1],
            normal: Some([0.0, 0.0, 5.0]),
        },
    ] {
        let mut s = sim(
            &mesh,
            vec![model("stretch_elementary", &[("stiffness", 1e4)])],
            |c| {
                c.gravity = [0.0, 0.0, -9.81];
                c.ground = Some(ground);
            },
        )
        .unwrap();
        // the lowest z over the run (the springs may bounce the box back up)
        let mut lowest = f64::INFINITY;
        for _ in 0..400 {
            s.step().unwrap();
            let z = s
                .vertex_vec3("position")
                .unwrap()
                .iter()
                .map(|p| p[2])
                .fold(f64::INFINITY, f64::min);
            assert!(z >= -0.1 - 1e-12, "{ground:?}: {z}");
            lowest = lowest.min(z);
        }
        assert!(lowest < -0.1 + 1e-9, "{ground:?}: {lowest}");
    }
    let e = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.ground = Some(Ground::Plane {
            point: [0.0; 3],
            normal: Some([0.0; 3]),
        });
    })
    .unwrap_err();
    assert!(e.to_string().contains("ground: the normal"), "{e}");
    // a static solve would balance the box as if the plane were not there: refused
    let e = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.integrator = Integrator::Static;
        c.ground = Some(Ground::Height(-1.0));
    })
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("ground: the static integrator does not model contact"),
        "{e}"
    );
    assert_eq!(Ground::up([0.0, 0.0, -9.81]), [0.0, 0.0, 1.0]);
    assert_eq!(Ground::up([0.0; 3]), [0.0, 1.0, 0.0]);
}

/// A body that starts through the ground is refused at set-up, naming the deepest vertex
/// (QA: the first step put every vertex below onto the plane at once, crushing the elements
/// to volumes of 1e-19, with no error); one resting on the plane, its lowest vertices on it
/// to rounding, is not. Checked with a tilted plane, whose test is not exact.
#[test]
fn a_body_through_the_ground_is_refused_at_set_up() {
    let mesh = cuboid([2, 2, 2], [0.4, 0.4, 0.4], BoxElement::Tetra);
    let springs = || vec![model("stretch_elementary", &[])];
    // the box spans z in [0, 0.4]: a plane at z = 0.2 cuts it
    let e = sim(&mesh, springs(), |c| {
        c.gravity = [0.0, 0.0, -9.81];
        c.ground = Some(Ground::Height(0.2));
    })
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("ground: the free vertex at [") && msg.contains("is 0.2 below the plane"),
        "{msg}"
    );
    // held vertices are never projected: those below may start there
    sim(&mesh, springs(), |c| {
        c.gravity = [0.0, 0.0, -9.81];
        c.ground = Some(Ground::Height(0.2));
        c.fixed = vec!["z < 0.3".into()];
    })
    .unwrap();
    // moved below after the set-up (a scene's initial displacement, set_positions): the
    // first step refuses, writing nothing
    let mut s = sim(&mesh, springs(), |c| {
        c.gravity = [0.0, 0.0, -9.81];
        c.ground = Some(Ground::Height(0.0));
    })
    .unwrap();
    let moved: Vec<[f64; 3]> = s
        .vertex_vec3("position")
        .unwrap()
        .iter()
        .map(|p| [p[0], p[1], p[2] - 0.1])
        .collect();
    s.set_vertex_vec3("position", &moved).unwrap();
    let e = s.step().unwrap_err().to_string();
    assert!(e.contains("below the plane"), "{e}");
    assert_eq!(s.vertex_vec3("position").unwrap(), moved);
    // resting on it: accepted, also on a plane through a bottom edge with a tilted normal
    sim(&mesh, springs(), |c| {
        c.gravity = [0.0, 0.0, -9.81];
        c.ground = Some(Ground::Height(0.0));
    })
    .unwrap();
    let n = [0.0, 1.0 / 3.0, 1.0];
    sim(&mesh, springs(), |c| {
        c.ground = Some(Ground::Plane {
            point: [0.1, 0.0, 0.0],
            normal: Some(n),
        });
    })
    .unwrap();
    // the same plane moved up by 1e-6 along its normal: the corner (0, 0, 0) is below it
    let len = (1.0f64 + 1.0 / 9.0).sqrt();
    let e = sim(&mesh, springs(), |c| {
        c.ground = Some(Ground::Plane {
            point: [0.0, 1e-6 / 3.0 / len, 1e-6 / len],
            normal: Some(n),
        });
    })
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("ground: the free vertex at [0.0, 0.0, 0.0]"),
        "{e}"
    );
    // far from the origin, a tilted plane's equation rounds at the coordinates' scale, not
    // the body's (QA: a 1 mm body resting on a plane through (1e6, -1e6, 5e5) was refused)
    let small = cuboid([1, 1, 1], [1e-3, 1e-3, 1e-3], BoxElement::Tetra);
    let mut seed = 12345u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for _ in 0..30 {
        let (mut g, _) = build(&small, &BuildOptions::default()).unwrap();
        let nn = [rnd(), rnd(), 1.0];
        let l = (nn[0] * nn[0] + nn[1] * nn[1] + 1.0).sqrt();
        let u = nn.map(|v| v / l);
        let p0 = [2e6 * rnd(), 2e6 * rnd(), 1e6 * rnd()];
        // each vertex x put at p0 + x moved along u so that its height over the plane is
        // its z (the bottom face on the plane, to rounding); every dart read first (the
        // darts of a vertex share its value)
        let id = g.embedding_id("position").unwrap();
        let moved: Vec<_> = g
            .darts()
            .map(|d| {
                let x = g.real(id, d).to_vec();
                let on = [p0[0] + x[0], p0[1] + x[1], p0[2] + x[2]];
                let h = (on[0] - p0[0]) * u[0] + (on[1] - p0[1]) * u[1] + (on[2] - p0[2]) * u[2];
                (d, [0, 1, 2].map(|k| on[k] - (h - x[2]) * u[k]))
            })
            .collect();
        for (d, y) in moved {
            g.set_real(id, d, &y).unwrap();
        }
        let cfg = Config {
            models: springs(),
            ground: Some(Ground::Plane {
                point: p0,
                normal: Some(nn),
            }),
            ..Config::default()
        };
        Simulation::new(g, cfg).unwrap();
    }
}

/// A map with an open element, valid as a G-map, is refused at set-up naming the free dart
/// and its element (QA: a quad grid with one corner unsewn, `alpha_1` free, got a total mass
/// of 898 for 1000 and a NaN velocity at the first step; a volume opened at `alpha_2`, in 3D,
/// the same).
#[test]
fn an_open_element_is_refused_at_set_up() {
    use topomech_gmap::generators::{grid, GridElement};
    use topomech_gmap::Dart;
    let quads = grid([3, 3], [1.0, 1.0], GridElement::Quad);
    let tets = cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Tetra);
    for (mesh, i) in [(&quads, 1), (&quads, 0), (&tets, 2), (&tets, 1)] {
        let (mut g, _) = build(mesh, &BuildOptions::default()).unwrap();
        g.unsew(i, Dart(9)).unwrap();
        assert!(g.first_link_violation().is_none(), "still a valid G-map");
        let cfg = Config {
            models: vec![model("stretch_elementary", &[])],
            ..Config::default()
        };
        let e = Simulation::new(g, cfg).unwrap_err().to_string();
        let what = if i == 2 {
            "volume whose boundary surface is open"
        } else {
            "face whose boundary is open"
        };
        assert!(e.contains(what) && e.contains("is free at alpha_"), "{e}");
        assert!(e.contains("the element whose centroid is ["), "{e}");
        if mesh.points.len() == 16 {
            // a quad of the 3 x 3 grid of the unit square: its centre, each point counted
            // once (an open corner splits a vertex into two orbits at one point)
            let c = e.split("centroid is [").nth(1).unwrap();
            let xy: Vec<f64> = c
                .split([',', ']'])
                .take(2)
                .map(|v| v.trim().parse().unwrap())
                .collect();
            for v in xy {
                assert!(
                    [1.0 / 6.0, 0.5, 5.0 / 6.0]
                        .iter()
                        .any(|m| (v - m).abs() < 1e-12),
                    "{e}"
                );
            }
        }
    }
}

/// A step with a ground plane keeps its plans: the ground rule's test below the plane is in
/// its body, not in a guard reading the positions (which every step writes, so the rule
/// was searched and planned again every step: 20 times slower on a 6,000-tet box). No plan
/// is built after the first steps, and a vertex that reaches the plane stays on it.
#[test]
fn the_ground_keeps_its_plan_from_step_to_step() {
    let mesh = cuboid([3, 2, 2], [1.0, 0.5, 0.5], BoxElement::Tetra);
    let mut s = sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
        c.gravity = [0.0, 0.0, -9.81];
        c.ground = Some(Ground::Height(-0.01));
        c.dt = 1e-3;
    })
    .unwrap();
    for _ in 0..3 {
        s.step().unwrap();
    }
    let built = s.rules().plans_built();
    for _ in 0..200 {
        s.step().unwrap();
    }
    assert_eq!(s.rules().plans_built(), built, "no plan built again");
    let lowest = s
        .vertex_vec3("position")
        .unwrap()
        .iter()
        .fold(f64::INFINITY, |m, p| m.min(p[2]));
    // the box fell 0.01 m in about 0.045 s and rests on the plane
    assert!((lowest + 0.01).abs() < 1e-12, "{lowest}");
}

/// An explicit step with a ground plane runs the integrator and the ground in one rule
/// (`symplectic_euler_ground`, `explicit_euler_ground`), whose values are tested before
/// they are written, as a step without ground is: no copy of the state is taken. Checks,
/// with each explicit integrator: the steps give the bits of the interpreter's, which runs
/// the integrator and then the ground rule and copies the state every step (exact: the
/// same operations in the same order); some vertices did reach the plane; no compiled step
/// copied the state; and a vertex sent running away, also into the plane, is refused, the
/// state after the failed step the one before it, bit for bit, in both runs.
#[test]
fn a_step_with_ground_is_tested_before_it_writes() {
    for integrator in [Integrator::SymplecticEuler, Integrator::ExplicitEuler] {
        let mesh = cuboid([3, 2, 2], [1.0, 0.5, 0.5], BoxElement::Tetra);
        let make = || {
            sim(&mesh, vec![model("stretch_elementary", &[])], |c| {
                c.gravity = [0.0, 0.0, -9.81];
                c.ground = Some(Ground::Height(-0.01));
                c.dt = 1e-3;
                c.integrator = integrator;
            })
            .unwrap()
        };
        let (mut fast, mut slow) = (make(), make());
        slow.set_compiled(false);
        for _ in 0..80 {
            fast.step().unwrap();
            slow.step().unwrap();
        }
        for name in ["position", "velocity"] {
            assert_eq!(
                fast.vertex_vec3(name).unwrap(),
                slow.vertex_vec3(name).unwrap(),
                "{integrator:?}: {name}"
            );
        }
        let on_plane = fast
            .vertex_vec3("position")
            .unwrap()
            .iter()
            .filter(|p| p[2] == -0.01)
            .count();
        assert!(on_plane > 0, "{integrator:?}: the box reached the plane");
        assert_eq!(fast.steps_saving_state(), 0, "{integrator:?}");
        assert_eq!(slow.steps_saving_state(), 80, "{integrator:?}");
        // a runaway vertex, up, or down into the plane (the projection would drop its
        // velocity into it and put it back onto the plane, or, from 1e100 m/s, beside it: a
        // runaway is one before the projection), compiled and through the interpreter:
        // refused, nothing written
        for v in [1e6, -1e6, -1e100] {
            for s in [&mut fast, &mut slow] {
                let mut vel = s.vertex_vec3("velocity").unwrap();
                let keep = vel[0];
                vel[0] = [0.0, 0.0, v];
                s.set_vertex_vec3("velocity", &vel).unwrap();
                let (p0, v0) = (
                    s.vertex_vec3("position").unwrap(),
                    s.vertex_vec3("velocity").unwrap(),
                );
                match s.step() {
                    Err(PhysicsError::Diverged { vertex, why, .. }) => {
                        assert_eq!(vertex, Some(0), "{integrator:?} {v}: {why}");
                        assert!(why.contains("runaway"), "{integrator:?} {v}: {why}");
                    }
                    other => panic!("{integrator:?} {v}: expected a runaway, got {other:?}"),
                }
                assert_eq!(s.vertex_vec3("position").unwrap(), p0, "{integrator:?} {v}");
                assert_eq!(s.vertex_vec3("velocity").unwrap(), v0, "{integrator:?} {v}");
                vel[0] = keep;
                s.set_vertex_vec3("velocity", &vel).unwrap();
            }
        }
        // and both step on alike
        fast.step().unwrap();
        slow.step().unwrap();
        assert_eq!(
            fast.vertex_vec3("position").unwrap(),
            slow.vertex_vec3("position").unwrap(),
            "{integrator:?}"
        );
    }
}

/// A held vertex keeps its position and zero velocity under every integrator: holding a
/// falling body's end mid-run stops it (QA: implicit Euler went on moving the held vertices
/// by the velocity they had, 0.049 m in 100 steps, and the explicit ones kept reporting it in
/// the kinetic energy), and giving a held vertex a velocity is refused, naming it.
#[test]
fn holding_a_moving_vertex_stops_it() {
    for integrator in [
        Integrator::SymplecticEuler,
        Integrator::ExplicitEuler,
        Integrator::ImplicitEuler,
    ] {
        let mesh = cuboid([3, 1, 1], [1.0, 0.2, 0.2], BoxElement::Tetra);
        let mut s = sim(&mesh, vec![model("corotational", &[])], |c| {
            c.integrator = integrator;
            c.dt = 1e-3;
            c.gravity = [0.0, 0.0, -9.81];
        })
        .unwrap();
        for _ in 0..20 {
            s.step().unwrap();
        }
        let rest = s.vertex_vec3("rest").unwrap();
        let mask: Vec<bool> = rest.iter().map(|p| p[0] < 1e-9).collect();
        assert!(s
            .vertex_vec3("velocity")
            .unwrap()
            .iter()
            .any(|v| v[2] < -1e-3));
        s.set_fixed(&mask).unwrap();
        let held_at = s.vertex_vec3("position").unwrap();
        for _ in 0..20 {
            s.step().unwrap();
        }
        let (x, v) = (
            s.vertex_vec3("position").unwrap(),
            s.vertex_vec3("velocity").unwrap(),
        );
        for r in (0..mask.len()).filter(|&r| mask[r]) {
            assert_eq!(x[r], held_at[r], "{integrator:?}: held row {r} moved");
            assert_eq!(
                v[r], [0.0; 3],
                "{integrator:?}: held row {r} has a velocity"
            );
        }
        let mut w = v.clone();
        let first = mask.iter().position(|&m| m).unwrap();
        w[first] = [0.0, 0.0, 1.0];
        let e = s.set_velocities(&w).unwrap_err().to_string();
        assert!(
            e.contains(&format!("vertex {first} is held (fixed)")),
            "{e}"
        );
        assert_eq!(
            s.vertex_vec3("velocity").unwrap(),
            v,
            "a refusal changes nothing"
        );
    }
}
