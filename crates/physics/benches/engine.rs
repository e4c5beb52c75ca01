//! The engine against hand-written baselines (issue 6): one full simulation step
//! (interactions, accumulation, symplectic Euler) through the rules, against the same
//! algorithm written by hand on flat arrays (`baselines/mod.rs`), for four models — cumulated
//! stretch springs on a quad cloth, co-rotational tetrahedra, mass-tensor tetrahedra, stable
//! Neo-Hookean tetrahedra — at about
//! 10^3 .. 10^6 elements (quads for the cloth, tetrahedra for the volumes).
//!
//! For each model and size: the simulation is built and deformed; its baseline is built from the
//! engine's map (same masses, rest lengths, stiffness matrices, tensors); both take the same
//! steps and must end at the same positions (to 1e-9 relative to how far the vertices moved:
//! the bench aborts otherwise, the baseline would not be the same algorithm); then the time of
//! a step is the median of repeated samples, the engine's inside a rayon pool of 1 and of 2
//! threads, the baseline's single-threaded. Memory: the map's bytes per element, split into
//! topology, embedding slot indices and embedding values, and the baseline's arrays.
//!
//! A case that the previous size predicts to exceed the time budget (or the available memory)
//! is skipped and recorded as such. Writes `bench/results.json`; `bench/report.py` turns it
//! into `bench/results.md`.
//!
//! Environment:
//! - `TOPOMECH_BENCH_SIZES`: target element counts, e.g. `1e3,1e4` (default `1e3,1e4,1e5,1e6`)
//! - `TOPOMECH_BENCH_MODELS`: any of `cloth,corotational,mass_tensor,neohookean` (default all)
//! - `TOPOMECH_BENCH_THREADS`: engine pool sizes (default `1,2`)
//! - `TOPOMECH_BENCH_CASE_BUDGET_S`: seconds one case may take (default 120)
//! - `TOPOMECH_BENCH_TOTAL_BUDGET_S`: seconds for the whole bench (default 360)
//! - `TOPOMECH_BENCH_OUT`: the output directory (default `bench/` at the workspace root)
//! - `TOPOMECH_BENCH_SOLVER_SIZES`: the solver section's beam sizes (default `1.5e3,1e5`;
//!   empty or `0` skips it): implicit against symplectic Euler, iterations of cg, Jacobi-
//!   and block-Jacobi-PCG, static cantilevers (issue 17)
//! - `TOPOMECH_BENCH_SOLVER_STEPS`: timed steps per solver case (default 5)
//! - `TOPOMECH_BENCH_SOLVER_PARTS`: `implicit`, `static` or both (the default)

mod baselines;
#[path = "../tests/it/common/renamed.rs"]
mod renamed;

use std::fmt::Write as _;
use std::hint::black_box;
use std::time::Instant;

use baselines::{disagreement, Baseline, Model};
use topomech_gmap::EmbeddingType;
use topomech_physics::Simulation;
use topomech_rules::{Params, RuleSet, Val};

/// Largest disagreement accepted between engine and baseline, relative to the motion.
const TOLERANCE: f64 = 1e-9;
/// Steps both take before timing (the engine's first builds its rules' plans).
const CHECK_STEPS: usize = 2;
/// Samples per timing, at most (5 when a sample lasts over half a second).
const MAX_SAMPLES: usize = 7;
/// Samples a case must have time for, by the previous size's prediction, to be run at all.
const MIN_SAMPLES: usize = 3;
/// A sample lasts at least this long (several steps per sample for small meshes).
const SAMPLE_S: f64 = 0.02;

// ------------------------------------------------------------------------------ JSON

/// A JSON value, written by hand (the bench has no dependencies beyond the workspace's).
enum J {
    Null,
    Bool(bool),
    Num(f64),
    Str(String),
    Arr(Vec<J>),
    Obj(Vec<(&'static str, J)>),
}

impl J {
    fn num(x: f64) -> J {
        if x.is_finite() {
            J::Num(x)
        } else {
            J::Null
        }
    }
    fn str(s: impl Into<String>) -> J {
        J::Str(s.into())
    }
    fn write(&self, out: &mut String, indent: usize) {
        let pad = |out: &mut String, n: usize| out.extend(std::iter::repeat_n(' ', n));
        match self {
            J::Null => out.push_str("null"),
            J::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
            J::Num(x) => {
                if x.fract() == 0.0 && x.abs() < 1e15 {
                    let _ = write!(out, "{}", *x as i64);
                } else {
                    let _ = write!(out, "{x:e}");
                }
            }
            J::Str(s) => {
                out.push('"');
                for c in s.chars() {
                    match c {
                        '"' => out.push_str("\\\""),
                        '\\' => out.push_str("\\\\"),
                        '\n' => out.push_str("\\n"),
                        c if (c as u32) < 0x20 => {
                            let _ = write!(out, "\\u{:04x}", c as u32);
                        }
                        c => out.push(c),
                    }
                }
                out.push('"');
            }
            J::Arr(v) => {
                if v.iter().all(|x| matches!(x, J::Num(_) | J::Null)) {
                    out.push('[');
                    for (i, x) in v.iter().enumerate() {
                        if i > 0 {
                            out.push_str(", ");
                        }
                        x.write(out, indent);
                    }
                    out.push(']');
                    return;
                }
                out.push_str("[\n");
                for (i, x) in v.iter().enumerate() {
                    pad(out, indent + 2);
                    x.write(out, indent + 2);
                    out.push_str(if i + 1 < v.len() { ",\n" } else { "\n" });
                }
                pad(out, indent);
                out.push(']');
            }
            J::Obj(v) => {
                out.push_str("{\n");
                for (i, (k, x)) in v.iter().enumerate() {
                    pad(out, indent + 2);
                    let _ = write!(out, "\"{k}\": ");
                    x.write(out, indent + 2);
                    out.push_str(if i + 1 < v.len() { ",\n" } else { "\n" });
                }
                pad(out, indent);
                out.push('}');
            }
        }
    }
}

// ------------------------------------------------------------------------------ settings

fn env_list<T>(name: &str, default: &str, parse: impl Fn(&str) -> Option<T>) -> Vec<T> {
    let s = std::env::var(name).unwrap_or_else(|_| default.to_string());
    s.split(',')
        .map(str::trim)
        .filter(|x| !x.is_empty())
        .map(|x| parse(x).unwrap_or_else(|| panic!("{name}: cannot read '{x}'")))
        .collect()
}

fn env_f64(name: &str, default: f64) -> f64 {
    std::env::var(name).ok().map_or(default, |s| {
        s.trim()
            .parse()
            .unwrap_or_else(|_| panic!("{name}: not a number: '{s}'"))
    })
}

fn model_named(s: &str) -> Option<Model> {
    match s {
        "cloth" | "stretch_cumulated" => Some(Model::Cloth),
        "corotational" | "corot" => Some(Model::Corotational),
        "mass_tensor" | "mass-tensor" => Some(Model::MassTensor),
        "neohookean" | "neo-hookean" => Some(Model::NeoHookean),
        _ => None,
    }
}

fn model_label(m: Model) -> &'static str {
    match m {
        Model::Cloth => "cloth",
        Model::Corotational => "corotational",
        Model::MassTensor => "mass_tensor",
        Model::NeoHookean => "neohookean",
    }
}

// ------------------------------------------------------------------------------ machine

fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

fn physical_cores() -> Option<usize> {
    let s = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let mut cores = std::collections::BTreeSet::new();
    let (mut phys, mut core) = (None, None);
    for l in s.lines().chain(std::iter::once("")) {
        if l.trim().is_empty() {
            if let (Some(p), Some(c)) = (phys.take(), core.take()) {
                cores.insert((p, c));
            }
            continue;
        }
        if let Some((k, v)) = l.split_once(':') {
            match k.trim() {
                "physical id" => phys = Some(v.trim().to_string()),
                "core id" => core = Some(v.trim().to_string()),
                _ => {}
            }
        }
    }
    (!cores.is_empty()).then_some(cores.len())
}

fn meminfo_kib(key: &str) -> Option<f64> {
    let s = std::fs::read_to_string("/proc/meminfo").ok()?;
    let l = s.lines().find(|l| l.starts_with(key))?;
    l.split_whitespace().nth(1)?.parse().ok()
}

fn command_output(cmd: &str, args: &[&str]) -> Option<String> {
    let out = std::process::Command::new(cmd).args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// UTC now as `YYYY-MM-DDTHH:MM:SSZ` (civil-from-days, Hinnant).
fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

fn machine() -> J {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    J::Obj(vec![
        ("cpu", J::str(cpu_model())),
        (
            "logical_cpus",
            J::num(std::thread::available_parallelism().map_or(0, std::num::NonZero::get) as f64),
        ),
        (
            "physical_cores",
            physical_cores().map_or(J::Null, |c| J::num(c as f64)),
        ),
        (
            "memory_gib",
            meminfo_kib("MemTotal:")
                .map_or(J::Null, |k| J::num((k / 1_048_576.0 * 10.0).round() / 10.0)),
        ),
        (
            "os",
            J::str(
                std::fs::read_to_string("/proc/sys/kernel/osrelease").map_or_else(
                    |_| std::env::consts::OS.to_string(),
                    |r| format!("{} {}", std::env::consts::OS, r.trim()),
                ),
            ),
        ),
        (
            "rustc",
            J::str(command_output(&rustc, &["--version"]).unwrap_or_else(|| "unknown".into())),
        ),
        (
            "git_commit",
            command_output("git", &["describe", "--always", "--dirty", "--abbrev=7"])
                .map_or(J::Null, J::Str),
        ),
        ("date", J::str(utc_now())),
    ])
}

// ------------------------------------------------------------------------------ timing

fn seconds(f: impl FnOnce()) -> f64 {
    let t = Instant::now();
    f();
    t.elapsed().as_secs_f64()
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// A timing: the median seconds per step over `samples`, each of `batch` steps.
struct Timing {
    step_s: f64,
    samples: Vec<f64>,
    batch: usize,
}

impl Timing {
    fn json(&self) -> J {
        J::Obj(vec![
            ("step_s", J::num(self.step_s)),
            ("batch", J::num(self.batch as f64)),
            (
                "samples_s",
                J::Arr(self.samples.iter().map(|&x| J::num(x)).collect()),
            ),
        ])
    }
}

/// Times `step` in `samples` samples of `batch` steps; returns seconds per step.
fn time_steps(samples: usize, batch: usize, mut step: impl FnMut()) -> Timing {
    let s: Vec<f64> = (0..samples)
        .map(|_| {
            seconds(|| {
                for _ in 0..batch {
                    step();
                }
            }) / batch as f64
        })
        .collect();
    Timing {
        step_s: median(&s),
        samples: s,
        batch,
    }
}

/// Fewer samples when one lasts long (the largest meshes).
fn max_samples(sample_s: f64) -> usize {
    if sample_s > 0.5 {
        5
    } else {
        MAX_SAMPLES
    }
}

fn batch_for(step_s: f64, cap: usize) -> usize {
    ((SAMPLE_S / step_s.max(1e-9)).ceil() as usize).clamp(1, cap)
}

// ------------------------------------------------------------------------------ memory

/// The map's memory per element, split into topology (alpha links, liveness), embedding slot
/// indices (the dart-to-slot tables, 4 bytes per dart, each table shared by the embeddings of
/// one orbit type counted once), embedding values, and the rest (slot use counts, free lists,
/// spare vector capacity); the largest embeddings (their own storage, without the shared
/// tables); the baseline's.
fn memory(sim: &Simulation, base: &dyn Baseline, elements: usize) -> J {
    let g = sim.gmap();
    let topo = g.topology_bytes();
    let total = g.memory_bytes();
    let index = g.slot_table_bytes();
    let (mut values, mut other) = (0usize, 0usize);
    let mut per: Vec<(String, String, usize, usize)> = Vec::new();
    for e in g.embeddings() {
        let bytes = e.memory_bytes() - e.slot_table_bytes();
        let v = match e.ty() {
            EmbeddingType::Bool => e.n_slots(),
            EmbeddingType::I64 => e.n_slots() * 8,
            t => e.n_slots() * t.width() * 8,
        }
        .min(bytes);
        values += v;
        other += bytes - v;
        per.push((e.name().to_string(), e.orbit().to_string(), bytes, v));
    }
    per.sort_by_key(|p| std::cmp::Reverse(p.2));
    let n = elements as f64;
    let per_elem = |b: usize| J::num(b as f64 / n);
    let used: Vec<J> = per
        .iter()
        .map(|(name, orbit, bytes, v)| {
            J::Obj(vec![
                ("name", J::str(name.clone())),
                ("orbit", J::str(orbit.clone())),
                ("bytes_per_element", per_elem(*bytes)),
                ("values_bytes_per_element", per_elem(*v)),
            ])
        })
        .collect();
    J::Obj(vec![
        ("engine_bytes", J::num(total as f64)),
        ("engine_bytes_per_element", per_elem(total)),
        ("topology_bytes_per_element", per_elem(topo)),
        ("embedding_index_bytes_per_element", per_elem(index)),
        ("embedding_values_bytes_per_element", per_elem(values)),
        ("embedding_other_bytes_per_element", per_elem(other)),
        ("embeddings", J::num(g.embeddings().len() as f64)),
        ("darts_per_element", J::num(g.n_darts() as f64 / n)),
        ("baseline_bytes", J::num(base.memory_bytes() as f64)),
        ("baseline_bytes_per_element", per_elem(base.memory_bytes())),
        ("by_embedding", J::Arr(used)),
    ])
}

// ------------------------------------------------------------------------------ a case

/// What a measured case leaves for predicting the next size.
#[derive(Clone, Copy)]
struct Measured {
    elements: usize,
    /// Engine and baseline setup plus the first steps.
    setup_s: f64,
    /// The slowest engine step time over the pool sizes.
    engine_step_s: f64,
    baseline_step_s: f64,
    memory_bytes: f64,
}

struct Budget {
    case_s: f64,
    total_s: f64,
    start: Instant,
}

impl Budget {
    /// Seconds left to the bench.
    fn left(&self) -> f64 {
        self.total_s - self.start.elapsed().as_secs_f64()
    }
    /// Seconds left to a case started at `started`: its own budget or the bench's.
    fn case_left(&self, started: Instant) -> f64 {
        (self.case_s - started.elapsed().as_secs_f64()).min(self.left())
    }
}

/// A case not measured: `status` is `skipped` (over budget) or `failed` (the engine's error).
fn not_measured(
    model: Model,
    target: usize,
    cells: &[usize],
    elements: usize,
    status: &str,
    why: String,
) -> J {
    println!(
        "  {:13} {elements:>9} {}s  {why}",
        model_label(model),
        model.element()
    );
    J::Obj(vec![
        ("model", J::str(model_label(model))),
        ("kind", J::str(model.kind())),
        ("element", J::str(model.element())),
        ("target", J::num(target as f64)),
        (
            "cells",
            J::Arr(cells.iter().map(|&c| J::num(c as f64)).collect()),
        ),
        ("elements", J::num(elements as f64)),
        ("status", J::str(status)),
        ("reason", J::str(why)),
    ])
}

/// Runs one case; `None` for the JSON means the engine and the baseline disagree (fatal).
/// The machine's rates for the hardware limit of a step (see [`baselines::Work`]), measured
/// on one thread in this run: best of 5 repeats of each probe.
#[derive(Clone, Copy, Debug)]
struct Rates {
    /// Memory bandwidth (bytes/s) from DRAM: the triad `a = b + s c` on three arrays of
    /// 64 MiB each (twice the largest L3 of the machines we run on), 24 bytes per element.
    /// Each case's limit uses [`triad_bandwidth`] at its own working set instead (a case
    /// that fits in cache streams at the cache's bandwidth).
    bandwidth: f64,
    /// Additions and multiplications (per s): 16 independent chains `x = x a + b`, which the
    /// compiler may vectorize as it may the baselines (the same flags build both).
    flops: f64,
    /// Square roots and divisions (per s): 8 independent chains of one of each.
    sqrt_div: f64,
}

fn best_of(repeats: usize, mut f: impl FnMut() -> f64) -> f64 {
    (0..repeats).map(|_| f()).fold(f64::INFINITY, f64::min)
}

/// The triad's bandwidth (bytes/s) over three arrays holding `bytes` in all (at least 96 KiB,
/// at most 192 MiB, past which it is DRAM's): best of 5, each of at least ~50 MB moved.
fn triad_bandwidth(bytes: f64) -> f64 {
    let n = ((bytes / 24.0) as usize).clamp(4096, 1 << 23);
    let b = vec![1.0f64; n];
    let c = vec![2.0f64; n];
    let mut a = vec![0.0f64; n];
    let s = black_box(0.5);
    let reps = (2_000_000 / n).max(1);
    let t = best_of(5, || {
        let t = Instant::now();
        for _ in 0..reps {
            for ((a, b), c) in a.iter_mut().zip(&b).zip(&c) {
                *a = b + s * c;
            }
            black_box(&mut a);
        }
        t.elapsed().as_secs_f64()
    });
    24.0 * (n * reps) as f64 / t
}

fn probe_rates() -> Rates {
    let iters = 4_000_000usize;
    let fl = best_of(5, || {
        let (m, k) = (black_box(0.999_999_9), black_box(1e-9));
        let mut x = [1.0f64; 16];
        let t = Instant::now();
        for _ in 0..iters {
            for v in &mut x {
                *v = *v * m + k;
            }
        }
        black_box(x);
        t.elapsed().as_secs_f64()
    });
    let sq_iters = 1_000_000usize;
    let sq = best_of(5, || {
        let c = black_box(1.000_001);
        let mut x = [2.0f64; 8];
        let t = Instant::now();
        for _ in 0..sq_iters {
            for v in &mut x {
                *v = c / (*v).sqrt();
            }
        }
        black_box(x);
        t.elapsed().as_secs_f64()
    });
    Rates {
        bandwidth: triad_bandwidth(f64::INFINITY),
        flops: 2.0 * 16.0 * iters as f64 / fl,
        sqrt_div: 2.0 * 8.0 * sq_iters as f64 / sq,
    }
}

impl Rates {
    fn json(&self) -> J {
        J::Obj(vec![
            ("bandwidth_bytes_per_s", J::num(self.bandwidth)),
            ("flops_per_s", J::num(self.flops)),
            ("sqrt_div_per_s", J::num(self.sqrt_div)),
        ])
    }

    /// The least time of a step doing `w` (s), and which bound sets it; the bandwidth is the
    /// triad's over a working set of `w.bytes`.
    fn limit(&self, w: baselines::Work) -> (f64, &'static str, f64) {
        let bandwidth = triad_bandwidth(w.bytes);
        let memory = w.bytes / bandwidth;
        let compute = w.flops / self.flops + w.sqrt_div / self.sqrt_div;
        if memory >= compute {
            (memory, "memory", bandwidth)
        } else {
            (compute, "arithmetic", bandwidth)
        }
    }
}

fn run_case(
    model: Model,
    target: usize,
    threads: &[usize],
    prev: &[Measured],
    budget: &Budget,
    rates: &Rates,
) -> (J, Option<Measured>) {
    let (cells, elements) = model.cells(target);
    let left = budget.left().min(budget.case_s);
    if let Some(p) = prev.last().copied() {
        let scale = elements as f64 / p.elements as f64;
        // a power law through the last two sizes (setup is not always linear), at least linear
        let grow = |f: fn(&Measured) -> f64| -> f64 {
            let e = match prev {
                [.., a, b] if f(a) > 0.0 && f(b) > 0.0 && b.elements > a.elements => {
                    ((f(b) / f(a)).ln() / (b.elements as f64 / a.elements as f64).ln())
                        .clamp(1.0, 2.0)
                }
                _ => 1.0,
            };
            f(&p) * scale.powf(e)
        };
        let predicted = grow(|m| m.setup_s)
            + (CHECK_STEPS + MIN_SAMPLES * threads.len()) as f64 * grow(|m| m.engine_step_s)
            + (2 * CHECK_STEPS + MIN_SAMPLES * (1 + threads.len())) as f64
                * grow(|m| m.baseline_step_s);
        if predicted > left {
            let why = format!(
                "skipped: over time budget (predicted {predicted:.0} s from {} elements, {left:.0} s left)",
                p.elements
            );
            return (
                not_measured(model, target, &cells, elements, "skipped", why),
                None,
            );
        }
        let mem = scale * p.memory_bytes * 1.5;
        if let Some(avail) = meminfo_kib("MemAvailable:") {
            if mem > 0.8 * avail * 1024.0 {
                let why = format!(
                    "skipped: over memory (predicted {:.1} GiB, {:.1} GiB available)",
                    mem / 1_073_741_824.0,
                    avail / 1_048_576.0
                );
                return (
                    not_measured(model, target, &cells, elements, "skipped", why),
                    None,
                );
            }
        }
    }
    let started = Instant::now();
    let mut sim = None;
    let setup_engine_s = seconds(|| sim = Some(model.simulation(&cells)));
    let mut sim = sim.expect("built");
    let mut check: Option<Box<dyn Baseline>> = None;
    let setup_baseline_s = seconds(|| check = Some(model.baseline(&sim)));
    let mut check = check.expect("built");
    let mut timed = model.baseline(&sim);
    let start = sim.vertex_vec3("position").expect("positions");
    let vertices = start.len();

    // the same steps on both; the engine's first builds its plans
    let mut first_steps = Vec::new();
    let failed = |e: topomech_physics::PhysicsError| {
        let why = format!("failed: the engine's step: {e}");
        (
            not_measured(model, target, &cells, elements, "failed", why),
            None,
        )
    };
    for _ in 0..CHECK_STEPS {
        let t = Instant::now();
        if let Err(e) = sim.step() {
            return failed(e);
        }
        first_steps.push(t.elapsed().as_secs_f64());
        check.step();
    }
    let mut engine_steps = CHECK_STEPS;
    let agree = |sim: &Simulation, check: &dyn Baseline, steps: usize| {
        let (rel, motion) = disagreement(sim, check, &start);
        if rel.is_nan() || rel > TOLERANCE {
            eprintln!(
                "\nABORT: the {} baseline disagrees with the engine on {elements} {}s after {steps} steps: \
                 max position difference {rel:e} relative to the motion ({motion:e}), tolerance {TOLERANCE:e}. \
                 The baseline is not the engine's algorithm; fix benches/baselines/mod.rs \
                 (tests/baselines.rs checks the same on small meshes).",
                model_label(model),
                model.element()
            );
            std::process::exit(2);
        }
        (rel, motion)
    };
    agree(&sim, check.as_ref(), engine_steps);

    // baseline timing (on its own copy, which may run many steps)
    let one = seconds(|| timed.step());
    let bbatch = batch_for(one, 1000);
    let baseline = time_steps(max_samples(one * bbatch as f64), bbatch, || timed.step());

    // engine timing: the pool sizes take turns, sample by sample (drift in the machine's load
    // or in the state touches them alike), as many samples as the budget leaves
    let est = *first_steps.last().expect("steps");
    let batch = batch_for(est, 100);
    let pools: Vec<rayon::ThreadPool> = threads
        .iter()
        .map(|&t| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .expect("a thread pool")
        })
        .collect();
    let round_s = est * (batch * threads.len()) as f64;
    let mut samples: Vec<Vec<f64>> = vec![Vec::new(); threads.len()];
    for round in 0..max_samples(est * batch as f64) {
        if round > 0 && budget.case_left(started) < round_s {
            break;
        }
        for (pool, out) in pools.iter().zip(&mut samples) {
            let t = pool.install(|| {
                let t = Instant::now();
                for _ in 0..batch {
                    black_box(sim.step())?;
                }
                Ok(t.elapsed().as_secs_f64())
            });
            match t {
                Ok(t) => out.push(t / batch as f64),
                Err(e) => return failed(e),
            }
            engine_steps += batch;
        }
    }
    let engine: Vec<(usize, Timing)> = threads
        .iter()
        .zip(samples)
        .map(|(&t, s)| {
            (
                t,
                Timing {
                    step_s: median(&s),
                    samples: s,
                    batch,
                },
            )
        })
        .collect();

    // the checking baseline catches up: same steps, same positions
    for _ in CHECK_STEPS..engine_steps {
        check.step();
    }
    let (rel, motion) = agree(&sim, check.as_ref(), engine_steps);

    let mem = memory(&sim, check.as_ref(), elements);
    let mem_bytes = sim.gmap().memory_bytes() as f64;
    let t1 = engine
        .iter()
        .find(|(t, _)| *t == 1)
        .map_or(engine[0].1.step_s, |(_, x)| x.step_s);
    let ratio = t1 / baseline.step_s;
    let slowest = engine.iter().map(|(_, x)| x.step_s).fold(0.0, f64::max);
    let mut line = format!(
        "  {:13} {elements:>9} {}s  engine {:9.3} ms  baseline {:9.3} ms  ratio {ratio:7.2}",
        model_label(model),
        model.element(),
        t1 * 1e3,
        baseline.step_s * 1e3
    );
    for (t, x) in &engine {
        if *t != 1 {
            let _ = write!(line, "  {t} threads x{:.2}", t1 / x.step_s);
        }
    }
    let _ = write!(
        line,
        "  {:.0} B/{}  (baseline {:.0})  setup {:.1} s  agree {rel:.1e}",
        mem_bytes / elements as f64,
        model.element(),
        check.memory_bytes() as f64 / elements as f64,
        setup_engine_s
    );
    println!("{line}");
    let json = J::Obj(vec![
        ("model", J::str(model_label(model))),
        ("kind", J::str(model.kind())),
        ("element", J::str(model.element())),
        ("target", J::num(target as f64)),
        (
            "cells",
            J::Arr(cells.iter().map(|&c| J::num(c as f64)).collect()),
        ),
        ("elements", J::num(elements as f64)),
        ("vertices", J::num(vertices as f64)),
        ("darts", J::num(sim.gmap().n_darts() as f64)),
        ("status", J::str("ok")),
        ("setup_engine_s", J::num(setup_engine_s)),
        ("setup_baseline_s", J::num(setup_baseline_s)),
        (
            "first_steps_s",
            J::Arr(first_steps.iter().map(|&x| J::num(x)).collect()),
        ),
        (
            "engine",
            J::Arr(
                engine
                    .iter()
                    .map(|(t, x)| {
                        let J::Obj(mut o) = x.json() else {
                            unreachable!()
                        };
                        o.insert(0, ("threads", J::num(*t as f64)));
                        o.push(("speedup_vs_1", J::num(t1 / x.step_s)));
                        J::Obj(o)
                    })
                    .collect(),
            ),
        ),
        ("baseline", baseline.json()),
        ("ratio", J::num(ratio)),
        ("limit", {
            let w = check.work();
            let (limit_s, bound, bandwidth) = rates.limit(w);
            J::Obj(vec![
                ("step_s", J::num(limit_s)),
                ("bound", J::str(bound)),
                ("bandwidth_bytes_per_s", J::num(bandwidth)),
                ("bytes", J::num(w.bytes)),
                ("flops", J::num(w.flops)),
                ("sqrt_div", J::num(w.sqrt_div)),
                ("baseline_over_limit", J::num(baseline.step_s / limit_s)),
            ])
        }),
        ("engine_ns_per_element", J::num(t1 * 1e9 / elements as f64)),
        (
            "baseline_ns_per_element",
            J::num(baseline.step_s * 1e9 / elements as f64),
        ),
        (
            "agreement",
            J::Obj(vec![
                ("steps", J::num(engine_steps as f64)),
                ("max_relative_difference", J::num(rel)),
                ("motion", J::num(motion)),
                ("tolerance", J::num(TOLERANCE)),
            ]),
        ),
        ("memory", mem),
        ("wall_s", J::num(started.elapsed().as_secs_f64())),
    ]);
    let measured = Measured {
        elements,
        setup_s: setup_engine_s + setup_baseline_s + first_steps[0],
        engine_step_s: slowest,
        baseline_step_s: baseline.step_s,
        memory_bytes: mem_bytes,
    };
    (json, Some(measured))
}

/// The co-rotational rule file as a user would copy it into a file of their own, every rule
/// and embedding of the model renamed, against the shipped file: the time of one application
/// of the force rule on the same mesh (median of alternated samples, one thread), whether the
/// forces are the same bits, and the plans' sizes. The engine knows no rule by name: the two
/// must run at the same speed within the machine's noise.
fn renamed_copy(target: usize) -> J {
    use topomech_gmap::generators::{cuboid, BoxElement};
    use topomech_gmap::mesh::{build, BuildOptions};
    let copy = renamed::renamed_fem3d();
    let load = renamed::load_with_common3d;
    let shipped = load(renamed::FEM3D, "fem3d.tmr");
    let user = load(&copy, "mine.tmr");
    let (cells, n) = Model::Corotational.cells(target);
    let (g0, _) = build(
        &cuboid(
            [cells[0], cells[1], cells[2]],
            [cells[0] as f64 / cells[1] as f64, 1.0, 1.0],
            BoxElement::Tetra,
        ),
        &BuildOptions::default(),
    )
    .expect("a valid mesh");
    let prepare = |rules: &RuleSet, init: &str| {
        let mut g = g0.clone();
        rules.prepare(&mut g).expect("prepare");
        let none = Params::new();
        rules
            .apply_everywhere(&mut g, "init_rest", &none)
            .expect("init_rest");
        let mat: Params = [
            ("density".to_string(), Val::F(1000.0)),
            ("young".to_string(), Val::F(1e6)),
            ("poisson".to_string(), Val::F(0.3)),
        ]
        .into();
        rules
            .apply_everywhere(&mut g, "set_material", &mat)
            .expect("set_material");
        let v0 = g.embedding_id("vertex0").expect("vertex0");
        let volume = topomech_gmap::OrbitType::new(&[0, 1, 2]).expect("an orbit");
        for d in g.orbit_representatives(volume) {
            g.set_value(v0, d, &topomech_gmap::Value::Bool(true))
                .expect("vertex0");
        }
        rules.apply_everywhere(&mut g, init, &none).expect(init);
        // the bench's deformation: stretched and twisted
        let pos = g.embedding_id("position").expect("position");
        for d in g.darts().collect::<Vec<_>>() {
            let p = g.real(pos, d).to_vec();
            let x = Model::Corotational.deformed([p[0], p[1], p[2]]);
            g.set_real(pos, d, &x).expect("position");
        }
        g
    };
    let mut a = prepare(&shipped, "fem_init");
    let mut b = prepare(&user, "my_init");
    let none = Params::new();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    let (ta, tb) = pool.install(|| {
        // the first application builds the plan
        shipped
            .apply_everywhere(&mut a, "corotational", &none)
            .expect("corotational");
        user.apply_everywhere(&mut b, "my_warped_tets", &none)
            .expect("my_warped_tets");
        let time = |rules: &RuleSet, g: &mut topomech_gmap::GMap, rule: &str| {
            let t = Instant::now();
            let mut k = 0;
            while k == 0 || t.elapsed().as_secs_f64() < SAMPLE_S {
                black_box(rules.apply_everywhere(g, rule, &none).expect("a rule"));
                k += 1;
            }
            t.elapsed().as_secs_f64() / f64::from(k)
        };
        let (mut ta, mut tb) = (Vec::new(), Vec::new());
        for _ in 0..MAX_SAMPLES {
            ta.push(time(&shipped, &mut a, "corotational"));
            tb.push(time(&user, &mut b, "my_warped_tets"));
        }
        (median(&ta), median(&tb))
    });
    let (fa, fb) = (
        a.embedding_id("f_corot").expect("f_corot"),
        b.embedding_id("my_force").expect("my_force"),
    );
    let identical = a.darts().all(|d| {
        a.real(fa, d)
            .iter()
            .map(|x| x.to_bits())
            .eq(b.real(fb, d).iter().map(|x| x.to_bits()))
    });
    println!(
        "  renamed copy of fem3d.tmr, {n} tets: shipped {:.3} ms, renamed {:.3} ms, ratio {:.3}, forces identical: {identical}",
        ta * 1e3,
        tb * 1e3,
        tb / ta
    );
    J::Obj(vec![
        ("model", J::str("corotational")),
        ("rule", J::str("corotational")),
        ("renamed_rule", J::str("my_warped_tets")),
        ("elements", J::num(n as f64)),
        ("element", J::str("tet")),
        ("shipped_s", J::num(ta)),
        ("renamed_s", J::num(tb)),
        ("ratio", J::num(tb / ta)),
        ("identical_forces", J::Bool(identical)),
        ("shipped_plan_bytes", J::num(shipped.plan_bytes() as f64)),
        ("renamed_plan_bytes", J::num(user.plan_bytes() as f64)),
    ])
}

/// Stable Neo-Hookean and St. Venant-Kirchhoff tetrahedra (`hyperelastic3d.tmr`, written with
/// generic built-ins only) beside co-rotational ones on the same deformed mesh: the time of one
/// full step (forces, accumulation, symplectic Euler) and of one Jacobian-vector product (what
/// each conjugate-gradient iteration of `implicit_euler` and `static` costs), medians of
/// alternated samples, one thread.
fn hyperelastic_beside_corotational(target: usize) -> J {
    use topomech_gmap::generators::{cuboid, BoxElement};
    use topomech_gmap::mesh::{build, BuildOptions};
    use topomech_physics::{Config, ModelSpec};
    let kinds = ["corotational", "neohookean", "stvk"];
    let (cells, n) = Model::Corotational.cells(target);
    let mesh = cuboid(
        [cells[0], cells[1], cells[2]],
        [cells[0] as f64 / cells[1] as f64, 1.0, 1.0],
        BoxElement::Tetra,
    );
    let mut sims: Vec<Simulation> = kinds
        .iter()
        .map(|kind| {
            let (g, _) = build(&mesh, &BuildOptions::default()).expect("a valid mesh");
            let cfg = Config {
                models: vec![ModelSpec {
                    kind: (*kind).to_string(),
                    params: std::collections::HashMap::new(),
                }],
                young: 1e6,
                poisson: 0.3,
                fixed: vec!["x < 1e-9".into()],
                dt: 1e-6,
                ..Config::default()
            };
            let mut s = Simulation::new(g, cfg).expect("a simulation");
            let x: Vec<[f64; 3]> = s
                .vertex_vec3("rest")
                .expect("rest")
                .iter()
                .map(|p| Model::Corotational.deformed(*p))
                .collect();
            s.set_vertex_vec3("position", &x).expect("position");
            s
        })
        .collect();
    let dx: Vec<[f64; 3]> = sims[0]
        .vertex_vec3("rest")
        .expect("rest")
        .iter()
        .map(|p| [p[1], -p[0], 0.5 * p[2]])
        .collect();
    let zero = vec![[0.0; 3]; dx.len()];
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    let (steps, jvps) = pool.install(|| {
        for s in &mut sims {
            // the first application builds the plans
            s.step().expect("a step");
            s.jvp(&dx, &zero).expect("a product");
        }
        let time = |s: &mut Simulation, jvp: bool| {
            let t = Instant::now();
            let mut k = 0;
            while k == 0 || t.elapsed().as_secs_f64() < SAMPLE_S {
                if jvp {
                    black_box(s.jvp(&dx, &zero).expect("a product"));
                } else {
                    s.step().expect("a step");
                }
                k += 1;
            }
            t.elapsed().as_secs_f64() / f64::from(k)
        };
        let mut samples = vec![(Vec::new(), Vec::new()); sims.len()];
        for _ in 0..MAX_SAMPLES {
            for (s, (a, b)) in sims.iter_mut().zip(&mut samples) {
                a.push(time(s, false));
                b.push(time(s, true));
            }
        }
        let steps: Vec<f64> = samples.iter().map(|(a, _)| median(a)).collect();
        let jvps: Vec<f64> = samples.iter().map(|(_, b)| median(b)).collect();
        (steps, jvps)
    });
    let mut rows = Vec::new();
    for (k, kind) in kinds.iter().enumerate() {
        println!(
            "  {kind}, {n} tets: step {:.3} ms ({:.2} x co-rotational), jacobian-vector product {:.3} ms ({:.2} x)",
            steps[k] * 1e3,
            steps[k] / steps[0],
            jvps[k] * 1e3,
            jvps[k] / jvps[0]
        );
        rows.push(J::Obj(vec![
            ("model", J::str(*kind)),
            ("step_s", J::num(steps[k])),
            ("jvp_s", J::num(jvps[k])),
            ("step_ratio", J::num(steps[k] / steps[0])),
            ("jvp_ratio", J::num(jvps[k] / jvps[0])),
        ]));
    }
    J::Obj(vec![
        ("elements", J::num(n as f64)),
        ("element", J::str("tet")),
        ("reference", J::str("corotational")),
        ("models", J::Arr(rows)),
    ])
}

/// `TOPOMECH_BENCH_PROFILE=model:size:steps` (e.g. `cloth:1e5:200`): builds the case and
/// takes only engine steps, single-threaded, so that a profiler (`perf record`) sees the steady
/// step and nothing else; prints the mean time per step.
fn profile(spec: &str) {
    let parts: Vec<&str> = spec.split(':').collect();
    let (Some(model), Some(size), Some(steps)) = (
        parts.first().and_then(|m| model_named(m)),
        parts.get(1).and_then(|s| s.parse::<f64>().ok()),
        parts.get(2).and_then(|s| s.parse::<usize>().ok()),
    ) else {
        panic!(
            "TOPOMECH_BENCH_PROFILE must be model:size:steps, e.g. cloth:1e5:200 (got {spec:?})"
        );
    };
    let (cells, n) = model.cells(size as usize);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    pool.install(|| {
        let t = Instant::now();
        let mut sim = model.simulation(&cells);
        let setup = t.elapsed().as_secs_f64();
        let t = Instant::now();
        sim.step().expect("first step");
        println!(
            "{} {n} elements: set-up {:.3} s, first step {:.3} s",
            model_label(model),
            setup,
            t.elapsed().as_secs_f64()
        );
        let t = Instant::now();
        for _ in 0..steps {
            sim.step().expect("a step");
        }
        let dt = t.elapsed().as_secs_f64() / steps as f64;
        println!(
            "{} {n} elements: {:.3} ms per step",
            model_label(model),
            dt * 1e3
        );
    });
}

// ------------------------------------------------------------------------------ solvers

/// A beam of about `target` tetrahedra (the corotational case's proportions, 1 m thick),
/// its vertices at x = 0 fixed, one model of `kind` with default parameters, E = 1e6 Pa,
/// density 1000, gravity, dt 1e-3 (the defaults), then `f`.
fn solver_beam(
    kind: &str,
    target: usize,
    f: impl FnOnce(&mut topomech_physics::Config),
) -> Simulation {
    use topomech_gmap::generators::{cuboid, BoxElement};
    use topomech_gmap::mesh::{build, BuildOptions};
    use topomech_physics::{Config, ModelSpec};
    let (cells, _) = Model::Corotational.cells(target);
    let mesh = cuboid(
        [cells[0], cells[1], cells[2]],
        [cells[0] as f64 / cells[1] as f64, 1.0, 1.0],
        BoxElement::Tetra,
    );
    let (g, _) = build(&mesh, &BuildOptions::default()).expect("a valid mesh");
    let mut cfg = Config {
        models: vec![ModelSpec {
            kind: kind.to_string(),
            params: std::collections::HashMap::new(),
        }],
        young: 1e6,
        poisson: 0.3,
        fixed: vec!["x < 1e-9".into()],
        ..Config::default()
    };
    f(&mut cfg);
    Simulation::new(g, cfg).expect("a simulation")
}

/// Implicit Euler (default solver settings: block-Jacobi PCG to 1e-6) against symplectic
/// Euler on the same beam and model at dt 1e-3, from rest under gravity: the median of
/// `steps` timed steps each (after one untimed step, which builds the plans, the coupling
/// graph and the preconditioner; that first implicit step is timed apart), and the linear
/// iterations per step of cg, Jacobi-PCG and block-Jacobi-PCG side by side (means over
/// `steps` steps, tolerance 1e-6).
fn implicit_vs_symplectic(kind: &str, target: usize, steps: usize) -> J {
    use topomech_physics::{Integrator, LinearSolver, Preconditioner};
    let time_steps_of = |s: &mut Simulation| -> (f64, Vec<f64>, Vec<usize>) {
        let first = seconds(|| s.step().expect("a step"));
        let mut t = Vec::new();
        let mut its = Vec::new();
        for _ in 0..steps {
            t.push(seconds(|| s.step().expect("a step")));
            its.push(s.solver_report().map_or(0, |r| r.linear_iterations));
        }
        (first, t, its)
    };
    let mut sym = solver_beam(kind, target, |_| {});
    let n = sym.n_vertices();
    let (_, ts, _) = time_steps_of(&mut sym);
    let mut imp = solver_beam(kind, target, |c| c.integrator = Integrator::ImplicitEuler);
    let colors = imp.coupling_colors().expect("the coupling graph");
    let (first, ti, its_default) = time_steps_of(&mut imp);
    let (symplectic, implicit) = (median(&ts), median(&ti));
    let mut iterations = Vec::new();
    for (name, solver, pre) in [
        ("cg", LinearSolver::Cg, Preconditioner::Jacobi),
        ("jacobi_pcg", LinearSolver::Pcg, Preconditioner::Jacobi),
        (
            "block_jacobi_pcg",
            LinearSolver::Pcg,
            Preconditioner::BlockJacobi,
        ),
    ] {
        let mut s = solver_beam(kind, target, |c| {
            c.integrator = Integrator::ImplicitEuler;
            c.linear_solver = solver;
            c.preconditioner = pre;
        });
        let mut its = Vec::new();
        let mut times = Vec::new();
        for _ in 0..=steps {
            times.push(seconds(|| s.step().expect("a step")));
            its.push(s.solver_report().map_or(0, |r| r.linear_iterations) as f64);
        }
        let mean = its.iter().sum::<f64>() / its.len() as f64;
        iterations.push((name, mean, median(&times[1..])));
    }
    println!(
        "  {kind}, {} tets ({n} vertices): implicit Euler step {:.3} ms, symplectic {:.3} ms: {:.1} x (first implicit step {:.1} ms: coupling graph, {} + {} colors, preconditioner); iterations per step: {}",
        Model::Corotational.cells(target).1,
        implicit * 1e3,
        symplectic * 1e3,
        implicit / symplectic,
        first * 1e3,
        colors.0,
        colors.1,
        iterations
            .iter()
            .map(|(n, m, t)| format!("{n} {m:.1} ({:.1} ms)", t * 1e3))
            .collect::<Vec<_>>()
            .join(", ")
    );
    J::Obj(vec![
        ("model", J::str(kind)),
        (
            "elements",
            J::num(Model::Corotational.cells(target).1 as f64),
        ),
        ("vertices", J::num(n as f64)),
        ("dt", J::num(imp.config().dt)),
        ("implicit_step_s", J::num(implicit)),
        ("symplectic_step_s", J::num(symplectic)),
        ("ratio", J::num(implicit / symplectic)),
        ("first_implicit_step_s", J::num(first)),
        (
            "default_iterations",
            J::Arr(its_default.iter().map(|&i| J::num(i as f64)).collect()),
        ),
        ("distance1_colors", J::num(colors.0 as f64)),
        ("distance2_colors", J::num(colors.1 as f64)),
        (
            "iterations",
            J::Arr(
                iterations
                    .iter()
                    .map(|(n, m, t)| {
                        J::Obj(vec![
                            ("solver", J::str(*n)),
                            ("mean_iterations", J::num(*m)),
                            ("step_s", J::num(*t)),
                        ])
                    })
                    .collect(),
            ),
        ),
    ])
}

/// A static co-rotational cantilever of about `target` tetrahedra under gravity solved to
/// 1e-8 relative residual with the default linear solver (auto: direct at this size), timed;
/// its deflection against a solve with `against` (pcg at the small sizes, where it is
/// affordable; direct at 1e-12 otherwise) to 1e-6.
fn static_cantilever(target: usize, against: topomech_physics::LinearSolver) -> J {
    use topomech_physics::{Integrator, LinearSolver};
    let deflection = |s: &Simulation| -> Vec<[f64; 3]> {
        let rest = s.vertex_vec3("rest").expect("rest");
        s.vertex_vec3("position")
            .expect("position")
            .iter()
            .zip(&rest)
            .map(|(x, p)| [x[0] - p[0], x[1] - p[1], x[2] - p[2]])
            .collect()
    };
    let mut s = solver_beam("corotational", target, |c| {
        c.integrator = Integrator::Static;
        c.tolerance = Some(1e-8);
    });
    let n = s.n_vertices();
    // one-off costs apart: the coupling graph and its colorings, one assembly
    let graph = seconds(|| {
        s.coupling_colors().expect("the coupling graph");
    });
    let assembly = seconds(|| {
        black_box(s.stiffness_matrix().expect("an assembly"));
    });
    let t = seconds(|| s.step().expect("a static solve"));
    let r = s.solver_report().expect("a report").clone();
    let u = deflection(&s);
    let tip = u.iter().map(|u| u[1]).fold(0.0f64, f64::min);
    let mut o = solver_beam("corotational", target, |c| {
        c.integrator = Integrator::Static;
        c.linear_solver = against;
        c.tolerance = Some(if against == LinearSolver::Direct {
            1e-12
        } else {
            1e-8
        });
    });
    let t2 = seconds(|| o.step().expect("a static solve"));
    let r2 = o.solver_report().expect("a report").clone();
    let u2 = deflection(&o);
    let diff = u
        .iter()
        .zip(&u2)
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
        .fold(0.0f64, f64::max);
    let scale = u2.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    println!(
        "  static cantilever, {} tets ({n} vertices): {:.2} s with {} ({} Newton iterations, {} load steps, relative residual {:.2e}; plus the coupling graph {graph:.2} s: {:.2} s in all; one assembly {assembly:.2} s), tip deflection {tip:.4e} m; against {} ({:.2} s, {} linear iterations): max difference {:.2e} of the deflection",
        Model::Corotational.cells(target).1,
        t,
        r.linear_solver,
        r.iterations,
        r.load_steps,
        r.relative_residual,
        graph + t,
        r2.linear_solver,
        t2,
        r2.linear_iterations,
        diff / scale
    );
    J::Obj(vec![
        (
            "elements",
            J::num(Model::Corotational.cells(target).1 as f64),
        ),
        ("vertices", J::num(n as f64)),
        ("time_s", J::num(t)),
        ("coupling_graph_s", J::num(graph)),
        ("total_s", J::num(graph + t)),
        ("assembly_s", J::num(assembly)),
        ("linear_solver", J::str(r.linear_solver)),
        ("newton_iterations", J::num(r.iterations as f64)),
        ("load_steps", J::num(r.load_steps as f64)),
        ("relative_residual", J::num(r.relative_residual)),
        ("tip_deflection_m", J::num(tip)),
        ("against", J::str(r2.linear_solver)),
        ("against_time_s", J::num(t2)),
        (
            "against_linear_iterations",
            J::num(r2.linear_iterations as f64),
        ),
        ("relative_difference", J::num(diff / scale)),
    ])
}

/// The solver section (issue 17): `TOPOMECH_BENCH_SOLVER_SIZES` (default `1.5e3,1e5`; empty
/// or `0` skips it) and `TOPOMECH_BENCH_SOLVER_STEPS` (timed steps, default 5).
fn solvers() -> J {
    // `0` reads as no size (it skips the section, as the doc says)
    let sizes: Vec<usize> = env_list("TOPOMECH_BENCH_SOLVER_SIZES", "1.5e3,1e5", |s| {
        s.parse::<f64>()
            .ok()
            .filter(|x| *x == 0.0 || *x >= 1.0)
            .map(|x| x as usize)
    })
    .into_iter()
    .filter(|&n| n > 0)
    .collect();
    if sizes.is_empty() {
        return J::Null;
    }
    let steps = env_f64("TOPOMECH_BENCH_SOLVER_STEPS", 5.0).max(1.0) as usize;
    println!("solvers: implicit Euler against symplectic Euler (dt 1e-3), static cantilevers");
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool");
    pool.install(|| {
        let mut implicit = Vec::new();
        let mut statics = Vec::new();
        let parts = std::env::var("TOPOMECH_BENCH_SOLVER_PARTS")
            .unwrap_or_else(|_| "implicit,static".into());
        for &target in &sizes {
            if parts.contains("implicit") {
                for kind in ["corotational", "stretch_cumulated"] {
                    implicit.push(implicit_vs_symplectic(kind, target, steps));
                }
            }
            if !parts.contains("static") {
                continue;
            }
            let against = if target <= 20_000 {
                topomech_physics::LinearSolver::Pcg
            } else {
                topomech_physics::LinearSolver::Direct
            };
            statics.push(static_cantilever(target, against));
        }
        J::Obj(vec![
            ("threads", J::num(1.0)),
            ("implicit", J::Arr(implicit)),
            ("static", J::Arr(statics)),
        ])
    })
}

fn main() {
    // as the Python extension does when it is imported: what is timed is what a user runs
    topomech_physics::tune_malloc();
    if let Ok(spec) = std::env::var("TOPOMECH_BENCH_PROFILE") {
        profile(&spec);
        return;
    }
    let sizes: Vec<usize> = env_list("TOPOMECH_BENCH_SIZES", "1e3,1e4,1e5,1e6", |s| {
        s.parse::<f64>()
            .ok()
            .filter(|x| *x >= 1.0)
            .map(|x| x as usize)
    });
    let models = env_list(
        "TOPOMECH_BENCH_MODELS",
        "cloth,corotational,mass_tensor,neohookean",
        model_named,
    );
    let threads: Vec<usize> = env_list("TOPOMECH_BENCH_THREADS", "1,2", |s| {
        s.parse().ok().filter(|&t| t >= 1)
    });
    let budget = Budget {
        case_s: env_f64("TOPOMECH_BENCH_CASE_BUDGET_S", 120.0),
        total_s: env_f64("TOPOMECH_BENCH_TOTAL_BUDGET_S", 360.0),
        start: Instant::now(),
    };
    let out_dir = std::env::var("TOPOMECH_BENCH_OUT").map_or_else(
        |_| std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bench"),
        std::path::PathBuf::from,
    );
    println!(
        "engine vs hand-written baselines: one full step (forces, accumulation, symplectic Euler), \
         median of up to {MAX_SAMPLES} samples; engine in rayon pools of {threads:?} threads"
    );
    let rates = probe_rates();
    println!(
        "hardware rates (1 thread): {:.1} GB/s triad, {:.2} Gflop/s, {:.3} G sqrt-or-div/s",
        rates.bandwidth / 1e9,
        rates.flops / 1e9,
        rates.sqrt_div / 1e9
    );
    // size by size, so that a tight budget skips the largest sizes of every model alike
    let mut cases = Vec::new();
    let mut measured: Vec<Vec<Measured>> = vec![Vec::new(); models.len()];
    for &target in &sizes {
        for (k, &model) in models.iter().enumerate() {
            let (json, m) = run_case(model, target, &threads, &measured[k], &budget, &rates);
            cases.push(json);
            measured[k].extend(m);
        }
    }
    let results = J::Obj(vec![
        ("machine", machine()),
        ("rates", rates.json()),
        (
            "settings",
            J::Obj(vec![
                (
                    "sizes",
                    J::Arr(sizes.iter().map(|&s| J::num(s as f64)).collect()),
                ),
                (
                    "models",
                    J::Arr(models.iter().map(|&m| J::str(model_label(m))).collect()),
                ),
                (
                    "threads",
                    J::Arr(threads.iter().map(|&t| J::num(t as f64)).collect()),
                ),
                ("case_budget_s", J::num(budget.case_s)),
                ("total_budget_s", J::num(budget.total_s)),
                ("max_samples", J::num(MAX_SAMPLES as f64)),
                ("check_steps", J::num(CHECK_STEPS as f64)),
                ("tolerance", J::num(TOLERANCE)),
                ("integrator", J::str("symplectic_euler")),
                ("dt", J::num(baselines::DT)),
                (
                    "profile",
                    J::str(if cfg!(debug_assertions) {
                        "debug"
                    } else {
                        "release"
                    }),
                ),
                ("wall_s", J::num(budget.start.elapsed().as_secs_f64())),
            ]),
        ),
        ("cases", J::Arr(cases)),
        ("renamed_copy", renamed_copy(20_000)),
        ("hyperelastic", hyperelastic_beside_corotational(20_000)),
        ("solvers", solvers()),
    ]);
    let mut s = String::new();
    results.write(&mut s, 0);
    s.push('\n');
    std::fs::create_dir_all(&out_dir).expect("the output directory");
    let path = out_dir.join("results.json");
    std::fs::write(&path, s).expect("write results.json");
    println!("wrote {}", path.display());
}
