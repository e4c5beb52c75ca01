//! Cost of topology changes against the cost of a step, on a box of ~100k tetrahedra:
//! one plane cut through the middle, a fracture burst opening the faces of a slab, a blade
//! crossing the box during 100 steps, a single-face cut, a step with fracture enabled. A step
//! is timed in the steady state (its rules' plans built); the first step after a change
//! patches them around the changed darts, and that is counted as part of the change. The
//! compiled guards through which cuts find their faces are built once beforehand (as a
//! simulation does at set-up for the cuts its configuration declares), and timed apart.
//! Prints the median of repeated runs (`cargo bench -p topomech-physics`), on one thread
//! (`TOPOMECH_TOPOLOGY_THREADS` sets another count; see `main`).

use std::hint::black_box;
use std::time::Instant;

use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_physics::{
    Blade, Config, Criterion, Cut, Fracture, ModelSpec, Simulation, TimedEvent,
};

fn simulation(n: [usize; 3]) -> Simulation {
    simulation_with(n, None, vec![])
}

/// The box, with a fracture criterion tested after every step when `fracture` is given, and
/// `blades` moving through it.
fn simulation_with(n: [usize; 3], fracture: Option<Fracture>, blades: Vec<Blade>) -> Simulation {
    simulation_events(n, fracture, blades, vec![])
}

/// [`simulation_with`], with timed events.
fn simulation_events(
    n: [usize; 3],
    fracture: Option<Fracture>,
    blades: Vec<Blade>,
    events: Vec<TimedEvent>,
) -> Simulation {
    simulation_dt(n, fracture, blades, events, Config::default().dt)
}

/// [`simulation_events`], with the time step `dt`.
fn simulation_dt(
    n: [usize; 3],
    fracture: Option<Fracture>,
    blades: Vec<Blade>,
    events: Vec<TimedEvent>,
    dt: f64,
) -> Simulation {
    let (g, _) = build(
        &cuboid(n, [2.0, 1.0, 1.0], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .expect("valid");
    let cfg = Config {
        models: vec![ModelSpec {
            kind: "stretch_cumulated".into(),
            params: [("stiffness".to_string(), topomech_rules::Val::F(1e4))].into(),
        }],
        fixed: vec!["x < 1e-9".into()],
        fracture,
        blades,
        events,
        dt,
        ..Config::default()
    };
    Simulation::new(g, cfg).expect("builds")
}

/// `count` predicate cuts of a face or two each (at x = 1, z near 0, y moving up by 0.045
/// from one to the next), timed at the end of steps `first`, `first + 10`, ... of `dt`.
fn single_face_cuts(count: u32, first: u32, dt: f64) -> Vec<TimedEvent> {
    (0..count)
        .map(|k| TimedEvent {
            time: f64::from(10 * k + first) * dt,
            cut: Cut::Where(format!(
                "x > 0.99 && x < 1.01 && y > {} && y < {} && z < 0.03",
                0.045 * f64::from(k),
                0.045 * f64::from(k) + 0.04
            )),
        })
        .collect()
}

fn seconds(f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    t.elapsed().as_secs_f64()
}

/// `TOPOMECH_TOPOLOGY_PROFILE=fracture|single|plane|blade|plain` (or `idle`, see
/// [`fracture_idle`]): runs only that case, repeatedly, and
/// prints the time of its steps after the first (`TOPOMECH_TOPOLOGY_STEPS` of them, 100 by
/// default; for a profiler, see `TOPOMECH_PERF_CTL` below; `TOPOMECH_STEPTIMES=1` also
/// prints each step's time, in ms).
fn profile(case: &str, n: [usize; 3]) {
    // a time step the undamped box stays stable with for hundreds of steps
    let dt = 1e-4;
    if case == "idle" {
        fracture_idle(n, dt);
        return;
    }
    if case == "planecut" {
        plane_cuts(n);
        return;
    }
    let steps: u32 = std::env::var("TOPOMECH_TOPOLOGY_STEPS")
        .ok()
        .and_then(|x| x.parse().ok())
        .unwrap_or(100);
    let (fracture, blades, events) = match case {
        "fracture" => (
            Some(Fracture {
                criterion: Criterion::Strain,
                threshold: 0.5,
            }),
            vec![],
            vec![],
        ),
        // a cut of a face or two every 10 steps (20 at most)
        "single" => (None, vec![], single_face_cuts((steps / 10).min(20), 5, dt)),
        // a plane cut (about 1,300 faces) every 10 steps, at x = 0.3, 0.4, ... (15 at most)
        "plane" => (
            None,
            vec![],
            (0..(steps / 10).min(15))
                .map(|k| TimedEvent {
                    time: f64::from(10 * k + 5) * dt,
                    cut: Cut::Plane {
                        normal: [1.0, 0.0, 0.0],
                        offset: 0.3 + 0.1 * f64::from(k),
                    },
                })
                .collect(),
        ),
        "blade" | "plain" => (
            None,
            if case == "blade" {
                vec![Blade {
                    start: dt,
                    end: f64::from(steps) * dt,
                    from: [[1.0, 1.2, -0.1], [1.0, 1.2, 1.1]],
                    to: [[1.0, -0.2, -0.1], [1.0, -0.2, 1.1]],
                }]
            } else {
                vec![]
            },
            vec![],
        ),
        other => {
            panic!(
                "TOPOMECH_TOPOLOGY_PROFILE: fracture, single, plane, blade, plain or idle, not {other:?}"
            )
        }
    };
    let set_up = Instant::now();
    let mut s = simulation_dt(n, fracture, blades, events, dt);
    s.step().expect("steps");
    eprintln!(
        "set-up and first step: {:.1} s",
        set_up.elapsed().as_secs_f64()
    );
    // `perf record -D -1 --control fifo:FIFO` with TOPOMECH_PERF_CTL=FIFO: the profile starts
    // here, after the set-up
    if let Ok(fifo) = std::env::var("TOPOMECH_PERF_CTL") {
        std::fs::write(fifo, "enable\n").expect("writes to perf's control fifo");
    }
    let mut times = Vec::new();
    let t = seconds(|| {
        for _ in 1..steps {
            let t0 = Instant::now();
            black_box(s.step()).expect("steps");
            times.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    });
    if std::env::var_os("TOPOMECH_STEPTIMES").is_some() {
        eprintln!(
            "{}",
            times
                .iter()
                .map(|t| format!("{t:.1}"))
                .collect::<Vec<_>>()
                .join(" ")
        );
    }
    let faces: usize = s.topology_changes().iter().map(|c| c.unsewn).sum();
    println!(
        "{case}: {} steps in {:.1} ms ({:.2} ms per step), {faces} faces opened",
        steps - 1,
        t * 1e3,
        t * 1e3 / f64::from(steps - 1)
    );
}

/// `TOPOMECH_TOPOLOGY_PROFILE=planecut`: the bench's plane cut (x = 1, after the cuts'
/// guards are built) and the step after it, on `TOPOMECH_TOPOLOGY_STEPS` fresh simulations (3
/// by default); with `TOPOMECH_PERF_CTL`, the profile holds only those. Prints each cut's
/// and next step's time in steady steps.
fn plane_cuts(n: [usize; 3]) {
    let runs: usize = std::env::var("TOPOMECH_TOPOLOGY_STEPS")
        .ok()
        .and_then(|x| x.parse().ok())
        .unwrap_or(3);
    let fifo = std::env::var("TOPOMECH_PERF_CTL").ok();
    let perf = |what: &str| {
        if let Some(f) = &fifo {
            std::fs::write(f, format!("{what}\n")).expect("writes to perf's control fifo");
        }
    };
    for _ in 0..runs {
        let mut s = simulation(n);
        s.step().expect("steps");
        let mut steps: Vec<f64> = (0..5)
            .map(|_| seconds(|| black_box(s.step()).expect("steps")))
            .collect();
        let st = median(&mut steps);
        s.prepare_cuts().expect("prepares");
        perf("enable");
        let ct = seconds(|| {
            s.cut(&Cut::Plane {
                normal: [1.0, 0.0, 0.0],
                offset: 1.0,
            })
            .expect("cuts");
        });
        let at = seconds(|| black_box(s.step()).expect("steps"));
        perf("disable");
        println!(
            "planecut: step {:.2} ms, cut {:.1} ms = {:.2} steps, next {:.1} ms = {:.2} steps",
            st * 1e3,
            ct * 1e3,
            ct / st,
            at * 1e3,
            at / st
        );
    }
}

/// `TOPOMECH_TOPOLOGY_PROFILE=idle`: the step with fracture enabled and nothing breaking
/// against a plain one, as the bench measures it (alternated steps of two simulations), over
/// `TOPOMECH_TOPOLOGY_STEPS` pairs (100 by default): the medians and their ratio.
fn fracture_idle(n: [usize; 3], dt: f64) {
    let pairs: usize = std::env::var("TOPOMECH_TOPOLOGY_STEPS")
        .ok()
        .and_then(|x| x.parse().ok())
        .unwrap_or(100);
    let (pm, bm) = idle_step_medians(n, dt, pairs);
    println!(
        "idle: fracture enabled {:.3} ms, without {:.3} ms: {:.3} steps (medians of {pairs})",
        bm * 1e3,
        pm * 1e3,
        bm / pm
    );
}

/// A step with fracture enabled where nothing breaks (strains stay far below 50%), against a
/// step without: `pairs` alternated samples of two simulations at the time step `dt`, after
/// both have built their plans; the medians (without, with), in seconds.
fn idle_step_medians(n: [usize; 3], dt: f64, pairs: usize) -> (f64, f64) {
    let fracture = Fracture {
        criterion: Criterion::Strain,
        threshold: 0.5,
    };
    let mut plain = simulation_dt(n, None, vec![], vec![], dt);
    let mut brittle = simulation_dt(n, Some(fracture), vec![], vec![], dt);
    plain.step().expect("steps");
    brittle.step().expect("steps");
    let (mut p, mut b) = (Vec::new(), Vec::new());
    for _ in 0..pairs {
        p.push(seconds(|| black_box(plain.step()).expect("steps")));
        b.push(seconds(|| black_box(brittle.step()).expect("steps")));
    }
    assert!(
        brittle.topology_changes().is_empty(),
        "nothing breaks in the fracture-enabled run"
    );
    (median(&mut p), median(&mut b))
}

/// The median (the upper one of an even count).
fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    // as the Python extension does when it is imported: what is timed is what a user runs
    topomech_physics::tune_malloc();
    // one thread unless TOPOMECH_TOPOLOGY_THREADS says otherwise: on a 2-vCPU machine the
    // 2 ms step of this box on two threads swings between 1.7 and 5.6 ms from step to step
    // (one thread: 2.0-2.3 ms), which no ratio to a step survives
    let threads: usize = std::env::var("TOPOMECH_TOPOLOGY_THREADS")
        .ok()
        .and_then(|x| x.parse().ok())
        .unwrap_or(1);
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global()
        .expect("the global thread pool");
    let n = [26, 26, 25];
    if let Ok(case) = std::env::var("TOPOMECH_TOPOLOGY_PROFILE") {
        profile(&case, n);
        return;
    }
    let tets = 6 * n[0] * n[1] * n[2];
    let mut steps = Vec::new();
    let mut cuts = Vec::new();
    let mut after = Vec::new();
    let mut bursts = Vec::new();
    let mut prepares = Vec::new();
    let mut cut_faces = 0;
    let mut burst_faces = 0;
    for _ in 0..2 {
        let mut s = simulation(n);
        s.step().expect("steps");
        for _ in 0..3 {
            steps.push(seconds(|| black_box(s.step()).expect("steps")));
        }
        // the compiled guards the cuts search the faces with, built once (as a simulation
        // does at set-up for the cuts its configuration declares)
        prepares.push(seconds(|| s.prepare_cuts().expect("prepares")));
        cuts.push(seconds(|| {
            cut_faces = s
                .cut(&Cut::Plane {
                    normal: [1.0, 0.0, 0.0],
                    offset: 1.0,
                })
                .expect("cuts")
                .unsewn;
        }));
        after.push(seconds(|| black_box(s.step()).expect("steps")));
        // a burst: stretch a slab x in [0.5, 0.6] by 50% along y, then open what passes 20%
        let x: Vec<[f64; 3]> = s
            .vertex_vec3("rest")
            .expect("rest")
            .iter()
            .map(|p| {
                if p[0] > 0.5 && p[0] < 0.6 {
                    [p[0], 1.5 * p[1], p[2]]
                } else {
                    *p
                }
            })
            .collect();
        s.set_vertex_vec3("position", &x).expect("set");
        bursts.push(seconds(|| {
            burst_faces = s
                .fracture(Fracture {
                    criterion: Criterion::Strain,
                    threshold: 0.2,
                })
                .expect("fractures")
                .unsewn;
        }));
    }
    // a step with fracture enabled where nothing breaks, against a step without (at 0.1 ms,
    // a time step the undamped box stays stable with for hundreds of steps: at the default
    // 1 ms it goes unstable after about 8)
    let stable_dt = 1e-4;
    let (ps, bs) = idle_step_medians(n, stable_dt, 9);
    // a blade crossing the box (down through its middle, x = 1) during 100 steps, against
    // the same 100 steps without it (issue 16's measure): each of its steps tests the faces
    // near the quad it sweeps and, when it cut, patches the plans. At 0.1 ms, a time step the
    // undamped box stays stable with for hundreds of steps (at the default 1 ms it goes
    // unstable after about 8).
    let blade_steps = 100;
    let bdt = 1e-4;
    let mut blade_run = simulation_dt(n, None, vec![], vec![], bdt);
    blade_run.step().expect("steps");
    let mut bladed = simulation_dt(
        n,
        None,
        vec![Blade {
            start: bdt,
            end: f64::from(1 + blade_steps) * bdt,
            from: [[1.0, 1.2, -0.1], [1.0, 1.2, 1.1]],
            to: [[1.0, -0.2, -0.1], [1.0, -0.2, 1.1]],
        }],
        vec![],
        bdt,
    );
    bladed.step().expect("steps");
    let without = seconds(|| {
        for _ in 0..blade_steps {
            black_box(blade_run.step()).expect("steps");
        }
    });
    let with = seconds(|| {
        for _ in 0..blade_steps {
            black_box(bladed.step()).expect("steps");
        }
    });
    let blade_faces: usize = bladed.topology_changes().iter().map(|c| c.unsewn).sum();
    let blade_cutting = bladed.topology_changes().len();
    let dt = stable_dt;
    // single-face cuts (predicate cuts, timed events at the end of steps 3, 13, 23, ...: a
    // face or two each, at other places), each step with a cut and the next against the
    // plain steps of the same run between them
    let single_cuts = 5;
    let mut single = simulation_dt(n, None, vec![], single_face_cuts(single_cuts, 3, dt), dt);
    single.step().expect("steps");
    let (mut single_cut_steps, mut single_next_steps) = (Vec::new(), Vec::new());
    // step 2, plain
    let mut single_plains = vec![seconds(|| black_box(single.step()).expect("steps"))];
    for _ in 0..single_cuts {
        // step 3 (13, 23, ...) ends with the cut, step 4 patches the plans, steps 5-12 are plain
        let before = single.topology_changes().len();
        single_cut_steps.push(seconds(|| black_box(single.step()).expect("steps")));
        assert_eq!(single.topology_changes().len(), before + 1, "the step cut");
        single_next_steps.push(seconds(|| black_box(single.step()).expect("steps")));
        for _ in 0..8 {
            single_plains.push(seconds(|| black_box(single.step()).expect("steps")));
        }
    }
    let single_faces: usize = single.topology_changes().iter().map(|c| c.unsewn).sum();
    let pt = median(&mut prepares);
    let (st, ct, at, bt) = (
        median(&mut steps),
        median(&mut cuts),
        median(&mut after),
        median(&mut bursts),
    );
    println!(
        "topology changes on a box of {tets} tetrahedra, stretch_cumulated, {threads} thread(s) (median of 2 runs; a steady step: of 6):"
    );
    println!(
        "  one step, steady state (forces, accumulation, symplectic Euler)  {:8.1} ms",
        st * 1e3
    );
    println!("  building the cuts' compiled guards (once: plane cut, blade)      {:8.1} ms  = {:.2} steps", pt * 1e3, pt / st);
    println!("  one plane cut ({cut_faces} faces unsewn)                               {:8.1} ms  = {:.2} steps", ct * 1e3, ct / st);
    println!("  the first step after it (plans patched)                          {:8.1} ms  = {:.2} steps", at * 1e3, at / st);
    println!("  one fracture burst ({burst_faces} faces opened)                        {:8.1} ms  = {:.2} steps", bt * 1e3, bt / st);
    println!("  {blade_steps} steps with a blade crossing the middle ({blade_faces} faces, {blade_cutting} steps cutting) {:8.1} ms  = {:.2}x the same steps without it ({:.1} ms)", with * 1e3, with / without, without * 1e3);
    let single_plain = median(&mut single_plains);
    // a cut's own cost is its step less a plain step of that run (the event is part of a
    // step), to which the next step (plans patched) adds: issue 16's measure, in plain steps
    // of that run, per cut; the median of the cuts
    let mut single_costs: Vec<f64> = single_cut_steps
        .iter()
        .zip(&single_next_steps)
        .map(|(c, n)| (c - single_plain).max(0.0) + n)
        .collect();
    let single_cost = median(&mut single_costs);
    let (sc, sn) = (
        median(&mut single_cut_steps),
        median(&mut single_next_steps),
    );
    println!("  a step cutting a face (predicate event), then the next (median of {single_cuts}) {:8.1} ms + {:.1} ms  = {:.2} + {:.2} plain steps of that run ({:.1} ms, median of {}; {single_faces} faces in all)", sc * 1e3, sn * 1e3, sc / single_plain, sn / single_plain, single_plain * 1e3, single_plains.len());
    println!("  the single-face cut (its step less a plain step) plus the next step  {:8.1} ms  = {:.2} plain steps of that run (median of {single_cuts} cuts)", single_cost * 1e3, single_cost / single_plain);
    println!("  a step with fracture enabled, nothing breaking (median of 9)    {:8.1} ms  = {:.2} steps without ({:.1} ms)", bs * 1e3, bs / ps, ps * 1e3);
}
