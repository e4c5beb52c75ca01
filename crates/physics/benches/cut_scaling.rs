//! The cost of a cut against the number of faces it unsews, at several mesh sizes (issue 16:
//! it should grow with the faces unsewn, not with the mesh). On boxes of about 10^4, 10^5
//! and 10^6 tetrahedra (`TOPOMECH_CUT_SIZES`, default `1e4,1e5,1e6`), cumulated springs, one
//! thread: a steady step is timed (median of 3), then cuts of growing extent, each the
//! square a blade sweeps across part of a cross-section (`Simulation::cut_swept`), at a
//! different x each so that none reuses another's faces. Each cut is timed with the first
//! step after it (what it costs a run), and reported in steady steps. The compiled guards
//! the cuts find their faces with are built once before them (`Simulation::prepare_cuts`, as a
//! simulation does at set-up for the cuts it declares) and timed apart. Last, at each size,
//! a step with fracture enabled where nothing breaks against a plain step (issue 16: under
//! 1.2 plain steps at 10^5 tets, reported at 10^6): two fresh simulations of the box, one
//! with a strain criterion at 50%, stepped in alternation, medians of 9 (the `topology`
//! bench's measure at 10^5, here at every size).
//!
//! Writes `bench/topology_scaling.json` (or `$TOPOMECH_BENCH_OUT/topology_scaling.json`);
//! `bench/topology_plot.py` draws `bench/topology.png` and the table in
//! `bench/topology_scaling.md` from it. A size whose set-up would not fit in the memory
//! available (about 7 KB per tetrahedron: the simulation, and the two cut guards at about
//! 0.6 KB each, estimated) is skipped and recorded as such.

use std::fmt::Write as _;
use std::hint::black_box;
use std::time::Instant;

use topomech_gmap::generators::{cuboid, BoxElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_physics::{Config, Criterion, Fracture, ModelSpec, Simulation};

/// Bytes per tetrahedron the simulation needs at most (map, plans, the first step's
/// planning), for the memory check.
const BYTES_PER_TET: f64 = 7200.0;

fn simulation(n: [usize; 3]) -> Simulation {
    simulation_with(n, None)
}

/// The box of [`simulation`], with a fracture criterion tested after every step when
/// `fracture` is given.
fn simulation_with(n: [usize; 3], fracture: Option<Fracture>) -> Simulation {
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
        // the undamped box at the default 1 ms goes unstable after about 8 steps; this
        // bench takes 9
        dt: 1e-4,
        fracture,
        ..Config::default()
    };
    Simulation::new(g, cfg).expect("builds")
}

fn seconds(f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    t.elapsed().as_secs_f64()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn mem_available() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = s.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

/// Cells of a 2 x 1 x 1 box with about `target` tetrahedra (6 per cube): n x n/2 x n/2.
fn cells(target: usize) -> [usize; 3] {
    let k = ((target as f64 / 6.0 / 0.25).cbrt()).round().max(4.0) as usize;
    [k, (k / 2).max(2), (k / 2).max(2)]
}

fn main() {
    // as the Python extension does when it is imported: what is timed is what a user runs
    topomech_physics::tune_malloc();
    let sizes: Vec<usize> = std::env::var("TOPOMECH_CUT_SIZES")
        .unwrap_or_else(|_| "1e4,1e5,1e6".into())
        .split(',')
        .filter_map(|s| s.trim().parse::<f64>().ok())
        .map(|x| x as usize)
        .collect();
    let out_dir = std::env::var("TOPOMECH_BENCH_OUT").map_or_else(
        |_| std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bench"),
        std::path::PathBuf::from,
    );
    // the square's side as a fraction of the cross-section's (1 x 1): from a face or two to
    // the whole section
    let fractions = [0.02, 0.1, 0.3, 0.6, 1.0];
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    let mut json =
        String::from("{\n  \"model\": \"stretch_cumulated\",\n  \"threads\": 1,\n  \"sizes\": [");
    println!("cut cost against faces unsewn (stretch_cumulated, one thread; a cut with the first step after it, in steady steps):");
    for (si, &target) in sizes.iter().enumerate() {
        let n = cells(target);
        let tets = 6 * n[0] * n[1] * n[2];
        if si > 0 {
            json.push(',');
        }
        if let Some(avail) = mem_available() {
            if tets as f64 * BYTES_PER_TET > 0.8 * avail {
                println!(
                    "  {tets} tets: skipped (about {:.1} GiB needed, {:.1} GiB available)",
                    tets as f64 * BYTES_PER_TET / 1_073_741_824.0,
                    avail / 1_073_741_824.0
                );
                let _ = write!(
                    json,
                    "\n    {{\"tets\": {tets}, \"status\": \"skipped: memory\"}}"
                );
                continue;
            }
        }
        pool.install(|| {
            let setup = Instant::now();
            let mut s = simulation(n);
            s.step().expect("steps");
            let setup_s = setup.elapsed().as_secs_f64();
            let step_s = median(
                (0..3)
                    .map(|_| seconds(|| black_box(s.step()).expect("steps")))
                    .collect(),
            );
            // the compiled guards the cuts find their faces with, built once before the
            // first (as a simulation does at set-up for the cuts it declares)
            let prepare_s = seconds(|| s.prepare_cuts().expect("prepares"));
            let _ = write!(
                json,
                "\n    {{\"tets\": {tets}, \"status\": \"ok\", \"setup_and_first_step_s\": {setup_s}, \"step_s\": {step_s}, \"prepare_cuts_s\": {prepare_s}, \"cuts\": ["
            );
            println!(
                "  {tets} tets: steady step {:.2} ms, cut guards built in {:.1} ms",
                step_s * 1e3,
                prepare_s * 1e3
            );
            for (k, &w) in fractions.iter().enumerate() {
                // a square of side w in the plane x = x_k, swept by a segment along z moving
                // along y, centred on the cross-section
                let x = 0.25 + 0.3 * k as f64;
                let (lo, hi) = (0.5 - w / 2.0, 0.5 + w / 2.0);
                let from = [[x, hi, lo], [x, hi, hi]];
                let to = [[x, lo, lo], [x, lo, hi]];
                let mut faces = 0;
                let cut_s = seconds(|| faces = s.cut_swept(from, to).expect("cuts").unsewn);
                let next_s = seconds(|| black_box(s.step()).expect("steps"));
                let total = (cut_s + next_s) / step_s;
                println!(
                    "    square {w:4.2} of the section: {faces:6} faces unsewn, cut {:9.1} ms + next step {:9.1} ms = {total:8.1} steps",
                    cut_s * 1e3,
                    next_s * 1e3
                );
                let _ = write!(
                    json,
                    "{}\n      {{\"fraction\": {w}, \"faces\": {faces}, \"cut_s\": {cut_s}, \"next_step_s\": {next_s}, \"steps\": {total}}}",
                    if k > 0 { "," } else { "" }
                );
            }
            json.push_str("\n    ]");
            drop(s);
            // a step with fracture enabled where nothing breaks (strains stay far below
            // 50%), against a plain step: two fresh simulations at once, stepped in turn
            let two = 2.0 * tets as f64 * BYTES_PER_TET;
            if mem_available().is_some_and(|avail| two > 0.8 * avail) {
                println!("    a step with fracture enabled: skipped (two simulations do not fit in memory)");
                json.push_str(", \"fracture_idle\": null}");
                return;
            }
            let mut plain = simulation(n);
            let mut brittle = simulation_with(
                n,
                Some(Fracture {
                    criterion: Criterion::Strain,
                    threshold: 0.5,
                }),
            );
            plain.step().expect("steps");
            brittle.step().expect("steps");
            let (mut p, mut b) = (Vec::new(), Vec::new());
            for _ in 0..9 {
                p.push(seconds(|| black_box(plain.step()).expect("steps")));
                b.push(seconds(|| black_box(brittle.step()).expect("steps")));
            }
            assert!(
                brittle.topology_changes().is_empty(),
                "nothing breaks in the fracture-enabled run"
            );
            let (pm, bm) = (median(p), median(b));
            println!(
                "    a step with fracture enabled, nothing breaking: {:.2} ms = {:.2} plain steps ({:.2} ms; medians of 9 alternated)",
                bm * 1e3,
                bm / pm,
                pm * 1e3
            );
            let _ = write!(
                json,
                ", \"fracture_idle\": {{\"plain_step_s\": {pm}, \"fracture_step_s\": {bm}, \"steps\": {}}}}}",
                bm / pm
            );
        });
    }
    json.push_str("\n  ]\n}\n");
    std::fs::create_dir_all(&out_dir).expect("the output directory");
    let path = out_dir.join("topology_scaling.json");
    std::fs::write(&path, json).expect("write topology_scaling.json");
    println!("wrote {}", path.display());
}
