//! [`RuleSet::apply_everywhere_eager`]: a compiled plan writing each chunk of rows as soon as
//! it is evaluated (a simulation's forces) writes the same values, bit for bit, as
//! [`RuleSet::apply_everywhere`], which evaluates every row first; a rule that reads an
//! embedding it writes is applied the buffered way (an eager write would change what a later
//! row reads); a failure reports the same error and leaves what the rule reads unchanged.
//! On a grid of 7,381 vertices (about 30 chunks of native code), on 1 and 3 threads.

use topomech_gmap::generators::{grid, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::GMap;
use topomech_rules::{load_sources, ApplyError, Params, RuleSet, Val};

use crate::column_bits as column;
use crate::nonfinite::on_threads;

const SOURCE: &str = "dimension 2
embedding position : vec3 on <1,2>
embedding velocity : vec3 on <1,2>
embedding corner   : f64 on <1>

# Reads positions only: infinite at the vertex (ax, ay).
rule pull(ax: f64, ay: f64) {
  left { v : <1,2> hook }
  compute {
    let dx = x(v.position) - ax
    let dy = y(v.position) - ay
    v.velocity = vec3(1.0, 0.0, 0.0) / (dx * dx + dy * dy)
  }
}

rule init_corner {
  left { a : <1> hook }
  compute { a.corner = x(a.position) + 10.0 * y(a.position) }
}

# Reads the values it writes on other rows: the sum over the vertex's corners, each
# another row's.
rule gather {
  left { a : <1> hook }
  compute { a.corner = sum<1,2>(a.corner) * 0.25 + 1.0 }
}
";

fn setup() -> (GMap, RuleSet) {
    let (mut g, _) = build(
        &grid([120, 60], [12.0, 6.0], GridElement::Quad),
        &BuildOptions::default(),
    )
    .unwrap();
    let (mut rules, _) = load_sources(&[("eager.tmr".to_string(), SOURCE.to_string())]).unwrap();
    rules.set_compiled(true);
    rules.set_jit(true);
    rules
        .prepare_named(&mut g, &["velocity", "corner"])
        .unwrap();
    rules
        .apply_everywhere(&mut g, "init_corner", &Params::new())
        .unwrap();
    (g, rules)
}

fn pull_at(ax: f64, ay: f64) -> Params {
    [
        ("ax".to_string(), Val::F(ax)),
        ("ay".to_string(), Val::F(ay)),
    ]
    .into()
}

/// The same values as the buffered application, through the chunked native path; for
/// `gather`, which reads what it writes on other rows, too (written eagerly, a row of a
/// later chunk would sum the new values of its vertex's corners in earlier chunks).
#[test]
fn eager_writes_give_the_buffered_values() {
    for threads in [1, 3] {
        on_threads(threads, || {
            for (rule, params, written) in [
                ("pull", pull_at(-1.0, -1.0), "velocity"),
                ("gather", Params::new(), "corner"),
            ] {
                let (mut a, rules_a) = setup();
                let (mut b, rules_b) = setup();
                let runs = topomech_rules::jit::chunked_runs();
                for _ in 0..3 {
                    rules_a.apply_everywhere(&mut a, rule, &params).unwrap();
                    rules_b
                        .apply_everywhere_eager(&mut b, rule, &params)
                        .unwrap();
                }
                assert!(
                    topomech_rules::jit::chunked_runs() >= runs + 6,
                    "the chunked path did not run"
                );
                let (x, y) = (column(&a, written), column(&b, written));
                let differ = x.iter().zip(&y).filter(|(p, q)| p != q).count();
                assert!(
                    x.len() == y.len() && differ == 0,
                    "{rule} on {threads} threads: {differ} of {} values differ",
                    x.len()
                );
                assert!(a.embedding(a.require(written).unwrap()).writes() > 0);
            }
        });
    }
}

/// A failure (an infinite velocity at the first or the last vertex) is the error
/// `apply_everywhere` reports, naming that vertex's dart; what the rule reads (the
/// positions) is unchanged and the map valid; then a finite application writes every
/// vertex's value, as the buffered one does.
#[test]
fn an_eager_failure_reports_the_error_and_keeps_the_inputs() {
    for threads in [1, 3] {
        on_threads(threads, || {
            let (mut g, rules) = setup();
            let (mut h, rules_h) = setup();
            for (ax, ay) in [(0.0, 0.0), (12.0, 6.0)] {
                let positions = column(&g, "position");
                let e = rules
                    .apply_everywhere_eager(&mut g, "pull", &pull_at(ax, ay))
                    .unwrap_err();
                let f = rules_h
                    .apply_everywhere(&mut h, "pull", &pull_at(ax, ay))
                    .unwrap_err();
                assert_eq!(e.to_string(), f.to_string(), "{threads} threads");
                let ApplyError::NonFinite { dart, .. } = &e else {
                    panic!("not a non-finite error: {e}");
                };
                let p = g.real(g.require("position").unwrap(), *dart);
                assert!((p[0] - ax).abs() < 1e-9 && (p[1] - ay).abs() < 1e-9);
                assert_eq!(column(&g, "position"), positions);
                assert!(g.is_valid());
            }
            rules
                .apply_everywhere_eager(&mut g, "pull", &pull_at(-1.0, -1.0))
                .unwrap();
            rules_h
                .apply_everywhere(&mut h, "pull", &pull_at(-1.0, -1.0))
                .unwrap();
            assert_eq!(column(&g, "velocity"), column(&h, "velocity"));
        });
    }
}
