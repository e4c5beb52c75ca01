//! A rule application that would write a non-finite value (NaN or an infinity) to an
//! embedding fails naming the rule, the embedding and a dart of the orbit written, and writes
//! nothing: through the interpreter and through compiled plans (which scan their outputs once
//! before scattering them), for every match at once and for one application at given hooks.

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::{Dart, GMap};
use topomech_rules::{load_sources, ApplyError, Params, RuleSet, Val};

const SOURCE: &str = "dimension 2
embedding position : vec3 on <1,2>
embedding velocity : vec3 on <1,2>
embedding heat     : f64 on <1,2>
embedding tensor   : mat2 on <1,2>

# Writes position first, then a velocity that is infinite where x = at (1 / 0).
rule kick(at: f64) {
  left { v : <1,2> hook }
  compute {
    v.position = v.position + vec3(0.0, 0.0, 1.0)
    v.velocity = vec3(1.0, 0.0, 0.0) / (x(v.position) - at)
  }
}

# Moves every vertex, then writes a velocity that is infinite at the one vertex (ax, ay).
rule kick_at(ax: f64, ay: f64) {
  left { v : <1,2> hook }
  compute {
    v.position = v.position + vec3(0.0, 0.0, 1.0)
    let dx = x(v.position) - ax
    let dy = y(v.position) - ay
    v.velocity = vec3(1.0, 0.0, 0.0) / (dx * dx + dy * dy)
  }
}

# 0 / 0: NaN where x = at, in a scalar.
rule warm(at: f64) {
  left { v : <1,2> hook }
  compute { v.heat = (x(v.position) - at) / (x(v.position) - at) }
}

# A matrix with one NaN entry where x = at.
rule strain(at: f64) {
  left { v : <1,2> hook }
  compute { v.tensor = mat2(1.0, 0.0, sqrt(at - x(v.position)) * 0.0, 1.0) }
}
";

/// Every value of every embedding, bit for bit, and the number of darts.
fn snapshot(g: &GMap) -> (usize, Vec<Vec<u64>>) {
    let cols = (0..g.embeddings().len())
        .map(|k| {
            let e = &g.embeddings()[k];
            e.real_column()
                .map(|c| c.iter().map(|x| x.to_bits()).collect())
                .unwrap_or_default()
        })
        .collect();
    (g.darts().count(), cols)
}

fn setup(compiled: bool) -> (GMap, RuleSet) {
    setup_on([4, 2], [1.0, 0.5], compiled)
}

/// Runs `f` on a rayon pool of `threads` threads.
pub(crate) fn on_threads(threads: usize, f: impl FnOnce() + Send) {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f);
}

/// A quad grid of `cells` over `size`, with the rules loaded and their embeddings created.
fn setup_on(cells: [usize; 2], size: [f64; 2], compiled: bool) -> (GMap, RuleSet) {
    let (mut g, _) = build(
        &grid(cells, size, GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    let (mut rules, _) =
        load_sources(&[("nonfinite.tmr".to_string(), SOURCE.to_string())]).unwrap();
    rules.set_compiled(compiled);
    rules
        .prepare_named(&mut g, &["velocity", "heat", "tensor"])
        .unwrap();
    (g, rules)
}

fn at(x: f64) -> Params {
    [("at".to_string(), Val::F(x))].into()
}

fn x_of(g: &GMap, d: Dart) -> f64 {
    g.real(g.require("position").unwrap(), d)[0]
}

/// `apply_everywhere` of a rule that writes +inf at the vertices on x = 0.5 (1.0 after its own
/// first write moved nothing in x): the error is `NonFinite` naming the rule, `velocity` and a
/// dart on x = 0.5; the position the rule writes before the velocity is not written either
/// (every column bit for bit as before). Then the same rule with a harmless parameter applies
/// through a compiled plan (the scan does not make plans fall back for good).
#[test]
fn apply_everywhere_refuses_a_non_finite_write_and_writes_nothing() {
    for compiled in [true, false] {
        let (mut g, rules) = setup(compiled);
        let before = snapshot(&g);
        let e = rules
            .apply_everywhere(&mut g, "kick", &at(0.5))
            .unwrap_err();
        let ApplyError::NonFinite {
            rule,
            embedding,
            dart,
            value,
        } = &e
        else {
            panic!("compiled {compiled}: not a non-finite error: {e}");
        };
        assert_eq!(rule, "kick");
        assert_eq!(embedding, "velocity");
        assert!(
            (x_of(&g, *dart) - 0.5).abs() < 1e-12,
            "dart {dart} is not on x = 0.5"
        );
        assert!(value.contains("inf"), "{value}");
        let msg = e.to_string();
        for part in [
            "rule 'kick'",
            "'velocity'",
            &format!("dart {dart}"),
            "nothing was written",
        ] {
            assert!(msg.contains(part), "{msg} lacks {part}");
        }
        assert_eq!(snapshot(&g), before, "compiled {compiled}: the map changed");
        // a finite application goes through, compiled when asked
        rules.apply_everywhere(&mut g, "kick", &at(7.0)).unwrap();
        assert_ne!(snapshot(&g), before);
        let kinds = rules.plan_kinds();
        assert!(
            kinds
                .iter()
                .any(|(name, c)| name == "kick" && *c == compiled),
            "{kinds:?}"
        );
    }
}

/// Native code checks each chunk of rows as soon as it is evaluated and then scatters the
/// chunks (in parallel on several threads): a failure in any chunk, the first or a late one,
/// must write nothing, not even the chunks that passed. On a grid of 7,381 vertices (about 30
/// chunks), one infinite velocity at either corner (first or last rows), on 1 and 3 threads:
/// the error names that vertex's dart and every column is bit for bit as before; then a
/// finite application goes through the same path and writes every vertex.
#[test]
fn a_failure_in_any_chunk_writes_nothing() {
    let (mut g, mut rules) = setup_on([120, 60], [12.0, 6.0], true);
    rules.set_jit(true);
    for threads in [1, 3] {
        on_threads(threads, || {
            for (ax, ay) in [(0.0, 0.0), (12.0, 6.0)] {
                let before = snapshot(&g);
                let runs = topomech_rules::jit::chunked_runs();
                let p: Params = [
                    ("ax".to_string(), Val::F(ax)),
                    ("ay".to_string(), Val::F(ay)),
                ]
                .into();
                let e = rules.apply_everywhere(&mut g, "kick_at", &p).unwrap_err();
                let ApplyError::NonFinite { dart, .. } = &e else {
                    panic!("not a non-finite error: {e}");
                };
                let pos = g.real(g.require("position").unwrap(), *dart);
                assert!(
                    (pos[0] - ax).abs() < 1e-9 && (pos[1] - ay).abs() < 1e-9,
                    "{threads} threads: dart {dart} at {pos:?}, not ({ax}, {ay})"
                );
                assert_eq!(snapshot(&g), before, "{threads} threads: the map changed");
                assert!(
                    topomech_rules::jit::chunked_runs() > runs,
                    "the chunked path did not run"
                );
            }
            let z = |g: &GMap| {
                let id = g.require("position").unwrap();
                g.embedding(id).real_column().unwrap().to_vec()
            };
            let before = z(&g);
            let p: Params = [
                ("ax".to_string(), Val::F(-1.0)),
                ("ay".to_string(), Val::F(-1.0)),
            ]
            .into();
            rules.apply_everywhere(&mut g, "kick_at", &p).unwrap();
            let after = z(&g);
            // every vertex slot moved up by 1 (unused slots, if any, stay)
            let moved = before
                .chunks(3)
                .zip(after.chunks(3))
                .filter(|(b, a)| a[2].to_bits() == (b[2] + 1.0).to_bits())
                .count();
            assert_eq!(moved, 121 * 61, "{threads} threads");
        });
    }
}

/// NaN in a scalar (0 / 0) and in one entry of a matrix: both refused naming the embedding;
/// the matrix's message says which entry.
#[test]
fn nan_scalars_and_matrix_entries_are_refused() {
    for compiled in [true, false] {
        let (mut g, rules) = setup(compiled);
        let before = snapshot(&g);
        let e = rules
            .apply_everywhere(&mut g, "warm", &at(0.25))
            .unwrap_err();
        assert!(
            matches!(&e, ApplyError::NonFinite { embedding, value, .. } if embedding == "heat" && value == "NaN"),
            "{e}"
        );
        let e = rules
            .apply_everywhere(&mut g, "strain", &at(0.6))
            .unwrap_err();
        match &e {
            ApplyError::NonFinite {
                embedding,
                value,
                dart,
                ..
            } => {
                assert_eq!(embedding, "tensor");
                assert!(
                    value.contains("mat2") && value.contains("(1, 0)") && value.contains("NaN"),
                    "{value}"
                );
                assert!(x_of(&g, *dart) > 0.6, "dart {dart} has a finite tensor");
            }
            _ => panic!("{e}"),
        }
        assert_eq!(snapshot(&g), before, "compiled {compiled}: the map changed");
    }
}

/// `apply_at` (one application at given hooks) refuses too, naming the hook's orbit, and
/// applies where the value is finite.
#[test]
fn apply_at_refuses_a_non_finite_write() {
    let (mut g, rules) = setup(false);
    let pos = g.require("position").unwrap();
    let bad = g
        .darts()
        .find(|&d| (g.real(pos, d)[0] - 0.5).abs() < 1e-12)
        .unwrap();
    let good = g
        .darts()
        .find(|&d| (g.real(pos, d)[0] - 0.5).abs() > 0.1)
        .unwrap();
    let before = snapshot(&g);
    let e = rules
        .apply_at(&mut g, "kick", &[bad], &at(0.5))
        .unwrap_err();
    assert!(
        matches!(&e, ApplyError::NonFinite { rule, embedding, .. } if rule == "kick" && embedding == "velocity"),
        "{e}"
    );
    assert_eq!(snapshot(&g), before);
    rules.apply_at(&mut g, "kick", &[good], &at(0.5)).unwrap();
    assert_ne!(snapshot(&g), before);
}

/// [`RuleSet::apply_everywhere_checked`]: the caller's test sees every value before any is
/// written. Refused, or where the values cannot be tested first (plans off, a non-finite
/// value), the map is unchanged bit for bit and `None` comes back; passed, the map is the one
/// [`RuleSet::apply_everywhere`] gives, bit for bit. On 1 and 3 threads, over a grid large
/// enough for chunks run in parallel, refusing the velocities of the vertices at x = 0.
#[test]
fn a_checked_application_writes_only_values_that_pass() {
    for threads in [1, 3] {
        on_threads(threads, || {
            for compiled in [true, false] {
                let (mut g, rules) = setup_on([64, 64], [1.0, 1.0], compiled);
                let (mut want, _) = setup_on([64, 64], [1.0, 1.0], compiled);
                let vel = g.embedding_id("velocity").unwrap();
                let p: Params = [("at".to_string(), Val::F(-0.5))].into();
                let before = snapshot(&g);
                // 1 / (x + 0.5) is 2 at x = 0 and 2/3 at x = 1: refuse the speeds at x = 0
                let refuse = |id: topomech_gmap::EmbeddingId, v: &[f64]| {
                    id != vel || v.chunks_exact(3).all(|u| u[0] < 1.999)
                };
                let got = rules
                    .apply_everywhere_checked(&mut g, "kick", &p, &refuse)
                    .unwrap();
                assert!(got.is_none(), "{threads} threads, compiled {compiled}");
                assert_eq!(snapshot(&g), before, "refused: nothing written");
                let pass =
                    |_: topomech_gmap::EmbeddingId, v: &[f64]| v.iter().all(|x| x.is_finite());
                let got = rules
                    .apply_everywhere_checked(&mut g, "kick", &p, &pass)
                    .unwrap();
                if compiled {
                    assert!(got.is_some_and(|r| r.matches > 0));
                    rules.apply_everywhere(&mut want, "kick", &p).unwrap();
                    assert_eq!(
                        snapshot(&g),
                        snapshot(&want),
                        "passed: what applying writes"
                    );
                } else {
                    assert!(got.is_none(), "plans off: not testable first");
                    assert_eq!(snapshot(&g), before);
                }
                // a non-finite value (x = 0.5 is a vertex): nothing written, and the plain
                // application reports it
                let inf: Params = [("at".to_string(), Val::F(0.5))].into();
                let now = snapshot(&g);
                assert!(rules
                    .apply_everywhere_checked(&mut g, "kick", &inf, &pass)
                    .unwrap()
                    .is_none());
                assert_eq!(snapshot(&g), now);
                assert!(matches!(
                    rules.apply_everywhere(&mut g, "kick", &inf),
                    Err(ApplyError::NonFinite { .. })
                ));
            }
        });
    }
}
