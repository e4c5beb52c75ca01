//! Progressive cutting: a blade (a segment) moving through the object during the run unsews,
//! each step, the faces (3D) or edges (2D) between elements whose centroids the quad it swept
//! during that step separates. Checked against the plane cut: a blade sweeping a whole
//! cross-section of an object at rest, in the plane x = c, opens exactly the faces the plane
//! cut x = c opens (both separate the same centroids: the segment between two centroids
//! crosses the plane, inside the swept quad, exactly when they lie on opposite sides), and it
//! opens them progressively (none before the blade moves, a part half-way, all at the end).
//! After each step the map is valid and the mass and momentum are unchanged.

// the shared test helpers index their arrays in loops, as the math reads
#![allow(clippy::needless_range_loop)]

use crate::common;

use common::model;
use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_physics::{Blade, Config, Cut, Simulation};

fn sim(mesh: &Mesh, blades: Vec<Blade>) -> Simulation {
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("stretch_cumulated", &[("stiffness", 1e3)])],
        gravity: [0.0; 3],
        blades,
        dt: 1e-3,
        ..Config::default()
    };
    Simulation::new(g, cfg).unwrap()
}

fn unsewn_so_far(s: &Simulation) -> usize {
    s.topology_changes().iter().map(|c| c.unsewn).sum()
}

/// A blade through the plane x = 1.3 of a 2 x 1 x 1 box (at rest: no load), its segment
/// along y spanning the box, swept along z from below to above in 10 steps.
#[test]
fn a_blade_opens_progressively_what_the_plane_cut_opens() {
    for (mesh, three) in [
        (cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra), true),
        (grid([6, 4], [2.0, 1.0], GridElement::Quad), false),
    ] {
        let x = 1.3;
        let mut planar = sim(&mesh, vec![]);
        let want = planar
            .cut(&Cut::Plane {
                normal: [1.0, 0.0, 0.0],
                offset: x,
            })
            .unwrap()
            .unsewn;
        assert!(want > 0);
        // the box spans z in [0, 1] (3D); the sheet lies in z = 0 (2D): a knife through it,
        // its segment along z, swept along y
        let blade = if three {
            Blade {
                start: 0.0,
                end: 0.01,
                from: [[x, -0.5, -0.5], [x, 1.5, -0.5]],
                to: [[x, -0.5, 1.5], [x, 1.5, 1.5]],
            }
        } else {
            Blade {
                start: 0.0,
                end: 0.01,
                from: [[x, -0.5, -1.0], [x, -0.5, 1.0]],
                to: [[x, 1.5, -1.0], [x, 1.5, 1.0]],
            }
        };
        let mut s = sim(&mesh, vec![blade]);
        let m0 = s.total_mass().unwrap();
        let mut counts = Vec::new();
        for _ in 0..12 {
            s.step().unwrap();
            assert!(s.gmap().is_valid(), "valid after every step");
            assert!((s.total_mass().unwrap() - m0).abs() <= 1e-12 * m0);
            let p = s.momentum().unwrap();
            assert!(
                p.iter().all(|c| c.abs() <= 1e-9),
                "momentum stays zero: {p:?}"
            );
            counts.push(unsewn_so_far(&s));
        }
        assert!(counts.windows(2).all(|w| w[0] <= w[1]), "{counts:?}");
        assert!(counts[0] < want, "not all at once: {counts:?} of {want}");
        assert!(
            counts[4] > 0 && counts[4] < want,
            "part-way: {counts:?} of {want}"
        );
        assert_eq!(*counts.last().unwrap(), want, "all by the end ({three})");
        // after the blade stops, nothing more opens
        assert_eq!(counts[10], counts[11]);
        assert!(s.topology_changes().iter().all(|c| c.kind == "blade"));
    }
}

/// `Simulation::cut_swept` applies one sweep now: the blade of the test above in one go.
#[test]
fn one_sweep_now_is_the_plane_cut_too() {
    let mesh = cuboid([4, 2, 2], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let mut planar = sim(&mesh, vec![]);
    let want = planar
        .cut(&Cut::Plane {
            normal: [1.0, 0.0, 0.0],
            offset: 0.7,
        })
        .unwrap()
        .unsewn;
    let mut s = sim(&mesh, vec![]);
    let got = s
        .cut_swept(
            [[0.7, -0.5, -0.5], [0.7, 1.5, -0.5]],
            [[0.7, -0.5, 1.5], [0.7, 1.5, 1.5]],
        )
        .unwrap();
    assert_eq!(got.unsewn, want);
    assert!(!got.added_rows.is_empty());
    // a sweep that misses the object opens nothing and is no error
    let none = s
        .cut_swept(
            [[5.0, 0.0, 0.0], [5.0, 1.0, 0.0]],
            [[5.0, 0.0, 1.0], [5.0, 1.0, 1.0]],
        )
        .unwrap();
    assert_eq!(none.unsewn, 0);
    // one whose quad's box misses the positions' box is not searched at all (the guard does
    // not run), and one whose box only meets it is
    let runs = s.rules().compiled_guard_runs().0;
    let far = s
        .cut_swept(
            [[0.7, 2.0, -0.5], [0.7, 2.0, 1.5]],
            [[0.7, 3.0, -0.5], [0.7, 3.0, 1.5]],
        )
        .unwrap();
    assert_eq!(far.unsewn, 0);
    assert_eq!(s.rules().compiled_guard_runs().0, runs, "no search");
    let y_max = s
        .vertex_vec3("position")
        .unwrap()
        .iter()
        .fold(f64::NEG_INFINITY, |m, p| m.max(p[1]));
    let near = s
        .cut_swept(
            [[0.7, y_max, -0.5], [0.7, y_max, 1.5]],
            [[0.7, 3.0, -0.5], [0.7, 3.0, 1.5]],
        )
        .unwrap();
    assert_eq!(near.unsewn, 0, "no centroid is on the body's boundary");
    assert_eq!(s.rules().compiled_guard_runs().0, runs + 1, "searched");
    let err = s
        .cut_swept(
            [[f64::NAN, 0.0, 0.0], [5.0, 1.0, 0.0]],
            [[5.0, 0.0, 1.0], [5.0, 1.0, 1.0]],
        )
        .unwrap_err();
    assert!(err.to_string().contains("finite"), "{err}");
}

#[test]
fn bad_blades_are_refused_naming_them() {
    let mesh = cuboid([2, 1, 1], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let ok = Blade {
        start: 0.0,
        end: 1.0,
        from: [[0.5, 0.0, 0.0], [0.5, 1.0, 0.0]],
        to: [[0.5, 0.0, 1.0], [0.5, 1.0, 1.0]],
    };
    for (blade, says) in [
        (
            Blade {
                end: 0.0,
                ..ok.clone()
            },
            "blade 0: its end must be a finite time after its start",
        ),
        (
            Blade {
                start: -1.0,
                ..ok.clone()
            },
            "blade 0: its start must be a finite time >= 0",
        ),
        (
            Blade {
                to: [[0.5, f64::INFINITY, 1.0], [0.5, 1.0, 1.0]],
                ..ok.clone()
            },
            "blade 0: its points must be finite",
        ),
    ] {
        let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let cfg = Config {
            models: vec![model("stretch_cumulated", &[])],
            blades: vec![blade],
            ..Config::default()
        };
        let err = Simulation::new(g, cfg).err().unwrap().to_string();
        assert!(err.contains(says), "{err}");
    }
    let s = sim(
        &mesh,
        vec![Blade {
            start: 2.0,
            end: 3.0,
            ..ok
        }],
    );
    let err = s.check_events(1.0).unwrap_err().to_string();
    assert!(err.contains("blade 0 starts at t = 2"), "{err}");
}

/// The plane of the sweep through element centroids (x at the middle of a cell row, where
/// tetrahedra have their centroids): a centroid on the blade's plane is on neither side, as
/// for the plane cut, so both open the same faces (none, or those between other centroids)
/// for every offset, on and off the centroids and cell boundaries. The same where the
/// centroids lie on the plane only up to rounding (cells of 0.2 or 1/3, planes at 0.3, 0.35
/// or 0.5, hexahedra too): the plane cut takes a centroid within 1e-12 of the other's
/// distance as on the plane, as the blade does (it opened 70 of the 90 faces around x = 0.3
/// in a 5 x 5 x 5 box, where rounding put their centroids on either side, and the blade none).
#[test]
fn a_blade_through_centroids_opens_what_the_plane_cut_opens() {
    let cases = [
        (
            cuboid([8, 4, 4], [1.0, 0.5, 0.5], BoxElement::Tetra),
            vec![0.0625, 0.1875, 0.3125, 0.4375, 0.5, 0.5625, 0.3, 0.71],
        ),
        (
            cuboid([5, 5, 5], [1.0, 1.0, 1.0], BoxElement::Tetra),
            vec![0.3, 0.35, 0.5, 0.1, 0.300_000_01],
        ),
        (
            cuboid([3, 3, 3], [1.0, 1.0, 1.0], BoxElement::Tetra),
            vec![0.5, 1.0 / 6.0],
        ),
        (
            cuboid([3, 3, 3], [1.0, 1.0, 1.0], BoxElement::Hexa),
            vec![0.5, 1.0 / 6.0],
        ),
    ];
    for (mesh, offsets) in cases {
        for c in offsets {
            blade_and_plane_agree(&mesh, c);
        }
    }
}

/// Asserts that the plane cut at x = `c` and a blade sweeping the whole section there open
/// as many faces of `mesh`.
fn blade_and_plane_agree(mesh: &Mesh, c: f64) {
    let want = sim(mesh, vec![])
        .cut(&Cut::Plane {
            normal: [1.0, 0.0, 0.0],
            offset: c,
        })
        .unwrap()
        .unsewn;
    let got = sim(mesh, vec![])
        .cut_swept(
            [[c, 1.7, -0.1], [c, 1.7, 1.6]],
            [[c, -0.2, -0.1], [c, -0.2, 1.6]],
        )
        .unwrap()
        .unsewn;
    assert_eq!(got, want, "x = {c}");
}

/// A blade that has swept its whole path without crossing anything misses the object: an
/// error at the step it stops, like a timed cut that separates nothing; a zero-length blade
/// is refused.
#[test]
fn a_blade_that_misses_or_cannot_finish_is_an_error() {
    let mesh = cuboid([2, 1, 1], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let far = Blade {
        start: 0.0,
        end: 0.003,
        from: [[5.0, 0.0, 0.0], [5.0, 1.0, 0.0]],
        to: [[5.0, 0.0, 1.0], [5.0, 1.0, 1.0]],
    };
    let mut s = sim(&mesh, vec![far.clone()]);
    s.step().unwrap();
    s.step().unwrap();
    let err = s.step().unwrap_err().to_string();
    assert!(
        err.contains("blade 0 moved from t = 0 to t = 0.003 and crossed nothing"),
        "{err}"
    );
    let s = sim(
        &mesh,
        vec![Blade {
            end: 2.0,
            ..far.clone()
        }],
    );
    // a blade still moving when the run ends is allowed (it cuts what it crossed by then)
    assert!(s.check_events(1.0).is_ok());
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("stretch_cumulated", &[])],
        blades: vec![Blade {
            from: [[0.5, 0.0, 0.0], [0.5, 0.0, 0.0]],
            ..far
        }],
        ..Config::default()
    };
    let err = Simulation::new(g, cfg).err().unwrap().to_string();
    assert!(err.contains("its two end points must differ"), "{err}");
    // a blade that does not move (from == to) sweeps nothing: refused at set-up, not at its
    // end with "crossed nothing"
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let still = [[0.5, 0.0, -0.1], [0.5, 1.0, 1.1]];
    let cfg = Config {
        models: vec![model("stretch_cumulated", &[])],
        blades: vec![Blade {
            start: 0.0,
            end: 0.003,
            from: still,
            to: still,
        }],
        ..Config::default()
    };
    let err = Simulation::new(g, cfg).err().unwrap().to_string();
    assert!(
        err.contains("blade 0") && err.contains("must move"),
        "{err}"
    );
    let err = sim(&mesh, vec![])
        .cut_swept(
            [[0.5, 0.0, 0.0], [0.5, 0.0, 0.0]],
            [[0.5, 0.0, 1.0], [0.5, 1.0, 1.0]],
        )
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("must differ") && err.contains("at its start)"),
        "{err}"
    );
    // a sweep of nothing is refused by `cut_swept` with a blade event's words, where it
    // returned 0 unsewn silently: the same segment at both ends, or a segment sliding along
    // its own line (four points on one line, here at coordinates near 1e100 too: scaled)
    let err = sim(&mesh, vec![])
        .cut_swept(still, still)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("the blade: its segment must move: it is the same segment at its start and at its end, so it would sweep nothing"),
        "{err}"
    );
    for (from, to) in [
        (
            [[0.5, 0.0, -0.1], [0.5, 0.0, 1.1]],
            [[0.5, 0.0, 0.4], [0.5, 0.0, 1.6]],
        ),
        // reversed: the same line, the ends swapped
        (
            [[0.5, 0.0, -0.1], [0.5, 0.0, 1.1]],
            [[0.5, 0.0, 1.1], [0.5, 0.0, -0.1]],
        ),
        (
            [[1e99, 1e99, 0.0], [2e99, 2e99, 0.0]],
            [[3e99, 3e99, 0.0], [4e99, 4e99, 0.0]],
        ),
    ] {
        let err = sim(&mesh, vec![])
            .cut_swept(from, to)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("the blade: its segment must move off its own line: its end points at its start and at its end lie on one line, so it would sweep nothing"),
            "{err}"
        );
        let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let cfg = Config {
            models: vec![model("stretch_cumulated", &[])],
            blades: vec![Blade {
                start: 0.0,
                end: 0.003,
                from,
                to,
            }],
            ..Config::default()
        };
        let err = Simulation::new(g, cfg).err().unwrap().to_string();
        assert!(
            err.contains("blade 0: its segment must move off its own line"),
            "{err}"
        );
    }
    // turning about one end point sweeps a triangle: accepted
    assert!(sim(&mesh, vec![])
        .cut_swept(
            [[0.5, -0.5, 0.5], [0.5, 1.5, 0.5]],
            [[0.5, -0.5, 0.5], [0.5, 1.5, 1.5]],
        )
        .is_ok());
    // coordinates whose differences' products would overflow: refused, not a silent miss
    let err = sim(&mesh, vec![])
        .cut_swept(
            [[0.5, 1.7e308, 0.0], [0.5, 1.7e308, 1.0]],
            [[0.5, -1.7e308, 0.0], [0.5, -1.7e308, 1.0]],
        )
        .unwrap_err()
        .to_string();
    assert!(err.contains("1e100"), "{err}");
}

/// A body of tiny coordinates: the blade opens what the plane cut opens at every scale down
/// to 1e-300 (QA: at 1e-110 the crossing test's products of three differences underflowed to
/// 0 and the blade opened nothing, and at 1e-170 a blade of distinct points was refused as
/// having coinciding end points). The simulation is built at unit scale (the import refuses
/// elements whose volume underflows) and its positions then scaled, as the QA did; the
/// plane cut at the scaled offset on the same scaled positions is the reference.
#[test]
fn a_blade_cuts_bodies_of_tiny_coordinates() {
    let mesh = cuboid([4, 2, 2], [1.0, 0.5, 0.5], BoxElement::Tetra);
    let scaled = |s: f64| {
        let mut sim = sim(&mesh, vec![]);
        let x: Vec<[f64; 3]> = sim
            .vertex_vec3("position")
            .unwrap()
            .iter()
            .map(|p| p.map(|v| v * s))
            .collect();
        sim.set_vertex_vec3("position", &x).unwrap();
        sim
    };
    for s in [1.0, 1e-110, 1e-160, 1e-200, 1e-300] {
        let c = 0.3 * s;
        let want = scaled(s)
            .cut(&Cut::Plane {
                normal: [1.0, 0.0, 0.0],
                offset: c,
            })
            .unwrap()
            .unsewn;
        assert!(want > 0, "scale {s}");
        let got = scaled(s)
            .cut_swept(
                [[c, 1.7 * s, -0.1 * s], [c, 1.7 * s, 1.6 * s]],
                [[c, -0.2 * s, -0.1 * s], [c, -0.2 * s, 1.6 * s]],
            )
            .unwrap()
            .unsewn;
        assert_eq!(got, want, "scale {s}");
    }
}

/// The faces between two tetrahedra of `s`'s map whose centroid segment crosses the plane
/// x = 0.5: per face (one dart of it, in the volume on the smaller-x side), the crossing
/// point's (y, z), and whether the face is still sewn.
fn faces_across_half(s: &Simulation) -> Vec<(topomech_gmap::Dart, [f64; 2], bool)> {
    use topomech_gmap::OrbitType;
    let g = s.gmap();
    let pos = g.embedding_id("position").unwrap();
    let centroid = |d| {
        let darts = g.orbit(d, OrbitType::volume());
        let mut c = [0.0; 3];
        for &x in &darts {
            let p = g.real(pos, x);
            for k in 0..3 {
                c[k] += p[k] / darts.len() as f64;
            }
        }
        c
    };
    let mut out = Vec::new();
    for d in g.orbit_representatives(OrbitType::face(3)) {
        // a face orbit <0,1> of a volume: its other side through alpha_3, sewn or not (an
        // unsewn face's partner is found by its vertices: the other side of the plane)
        let (a, b) = if g.is_free(3, d) {
            continue;
        } else {
            (centroid(d), centroid(g.alpha(3, d)))
        };
        if (a[0] - 0.5) * (b[0] - 0.5) < 0.0 && a[0] < b[0] {
            let t = (0.5 - a[0]) / (b[0] - a[0]);
            out.push((
                d,
                [a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])],
                true,
            ));
        }
    }
    out
}

/// Whether the point `x` (y, z) of the plane x = 0.5 lies on the segment `p0(s) p1(s)` for
/// some s in [0, 1], the end points moving linearly from `from` to `to` (what a blade sweeps),
/// and how far it is from the boundary of that region (by a fine search over s): `None` where
/// it is too near the boundary to say.
fn swept_exactly(x: [f64; 2], from: [[f64; 2]; 2], to: [[f64; 2]; 2]) -> Option<bool> {
    let n: u32 = 20_000;
    let mut best = f64::INFINITY;
    let mut inside = false;
    let mut prev: Option<f64> = None;
    for i in 0..=n {
        let s = f64::from(i) / f64::from(n);
        let p0 = [0, 1].map(|k| from[0][k] + s * (to[0][k] - from[0][k]));
        let p1 = [0, 1].map(|k| from[1][k] + s * (to[1][k] - from[1][k]));
        let d = [p1[0] - p0[0], p1[1] - p0[1]];
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        let r = [x[0] - p0[0], x[1] - p0[1]];
        // signed distance of x from the segment's line, and where along it
        let f = (d[0] * r[1] - d[1] * r[0]) / len;
        let u = (d[0] * r[0] + d[1] * r[1]) / (len * len);
        if let Some(fp) = prev {
            if fp * f <= 0.0 && (0.0..=1.0).contains(&u) {
                inside = true;
            }
        }
        prev = Some(f);
        // the distance to the region's boundary: to the segments at s = 0 and 1, and to the
        // paths of the end points (where u leaves [0, 1])
        if i == 0 || i == n {
            best = best.min(f.abs());
        }
        for e in [p0, p1] {
            best = best.min(((x[0] - e[0]).powi(2) + (x[1] - e[1]).powi(2)).sqrt());
        }
    }
    (best > 0.05).then_some(inside)
}

/// A blade that turns while it moves sweeps a ruled surface: a segment in the plane x = 0.5
/// turning about its middle by 90 degrees sweeps two opposite quadrants, and a bow-tie
/// motion (its ends crossing over) two opposite wedges. The faces opened must be those whose
/// centroid segment crosses what it swept (the reference: a fine search over the motion, for
/// the faces not within 0.05 of the swept region's boundary), whether the sweep is one call
/// or 50. QA: the quad's two triangles covered the other quadrants too, and one call opened
/// 24 of the 32 faces across x = 0.5 (the bow-tie, all 32) where 50 calls opened 16.
#[test]
fn a_turning_blade_opens_what_it_sweeps_whatever_the_step() {
    let mesh = cuboid([4, 4, 4], [1.0, 1.0, 1.0], BoxElement::Tetra);
    for (from, to) in [
        (
            [[0.5, 0.5, -1.0], [0.5, 0.5, 2.0]],
            [[0.5, -1.0, 0.5], [0.5, 2.0, 0.5]],
        ),
        (
            [[0.5, 2.0, -1.0], [0.5, -2.0, 2.0]],
            [[0.5, -2.0, -1.0], [0.5, 2.0, 2.0]],
        ),
    ] {
        let yz = |s: [[f64; 3]; 2]| [[s[0][1], s[0][2]], [s[1][1], s[1][2]]];
        let before = faces_across_half(&sim(&mesh, vec![]));
        assert_eq!(before.len(), 32);
        let want: Vec<Option<bool>> = before
            .iter()
            .map(|(_, x, _)| swept_exactly(*x, yz(from), yz(to)))
            .collect();
        let sure = want.iter().filter(|w| w.is_some()).count();
        assert!(sure >= 24, "{sure} faces clear of the boundary");
        let lerp = |s: f64| -> [[f64; 3]; 2] {
            [0, 1].map(|e| std::array::from_fn(|k| from[e][k] + s * (to[e][k] - from[e][k])))
        };
        for calls in [1_u32, 50] {
            let mut s = sim(&mesh, vec![]);
            let mut opened = 0;
            for i in 0..calls {
                let (f, t) = (
                    lerp(f64::from(i) / f64::from(calls)),
                    lerp(f64::from(i + 1) / f64::from(calls)),
                );
                opened += s.cut_swept(f, t).unwrap().unsewn;
            }
            let g = s.gmap();
            let mut open_here = 0;
            for ((d, x, _), w) in before.iter().zip(&want) {
                let open = g.is_free(3, *d);
                open_here += usize::from(open);
                if let Some(w) = w {
                    assert_eq!(open, *w, "{calls} calls: the face crossed at {x:?}");
                }
            }
            assert_eq!(
                opened, open_here,
                "{calls} calls: only faces across x = 0.5"
            );
            assert!(g.is_valid());
        }
    }
}
