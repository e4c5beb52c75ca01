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
    let (mut g, _) = build(
        &grid([4, 2], [1.0, 0.5], GridElement::Quad),
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
