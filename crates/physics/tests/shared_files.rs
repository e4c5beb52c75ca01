//! The shipped prelude (`prelude.tmr`, `dimension 2 3`) and the per-dimension common files
//! after it check to the same embeddings and rules as the common file of each dimension did
//! before the prelude was split out (kept as fixtures): the split moves text, it changes no
//! datum, orbit, policy or program. Bit-identical simulations follow from this; the other
//! tests of this crate and the pytest suite check them unchanged.

use topomech_rules::check::Rule;
use topomech_rules::{load_sources, load_sources_for, RuleSet};

const PRELUDE: &str = include_str!("../models/prelude.tmr");
const COMMON2D: &str = include_str!("../models/common2d.tmr");
const COMMON3D: &str = include_str!("../models/common3d.tmr");
const BEFORE2D: &str = include_str!("fixtures/common2d_before_prelude.tmr");
const BEFORE3D: &str = include_str!("fixtures/common3d_before_prelude.tmr");

/// The rules by name, without their file names and source positions (the text moved).
fn unplaced(r: &RuleSet) -> Vec<Rule> {
    let mut rules: Vec<Rule> = r
        .rules()
        .iter()
        .cloned()
        .map(|mut rule| {
            rule.file = String::new();
            for n in &mut rule.nodes {
                n.pos = topomech_rules::ast::Pos::default();
            }
            rule
        })
        .collect();
    rules.sort_by(|a, b| a.name.cmp(&b.name));
    rules
}

#[test]
fn prelude_and_common_file_are_the_common_file_as_before() {
    for (dim, common, before) in [(2, COMMON2D, BEFORE2D), (3, COMMON3D, BEFORE3D)] {
        let (now, _) = load_sources_for(
            dim,
            &[
                ("prelude.tmr".to_string(), PRELUDE.to_string()),
                (format!("common{dim}d.tmr"), common.to_string()),
            ],
        )
        .unwrap_or_else(|d| panic!("{dim}D: {d:?}"));
        let (was, _) = load_sources(&[(format!("common{dim}d.tmr"), before.to_string())])
            .unwrap_or_else(|d| panic!("{dim}D before: {d:?}"));
        assert_eq!(now.dimension(), dim);
        // same embeddings in the same order (storage is declared in this order)
        assert_eq!(now.embeddings(), was.embeddings(), "{dim}D embeddings");
        let (n, w) = (unplaced(&now), unplaced(&was));
        assert_eq!(n.len(), w.len(), "{dim}D rule count");
        assert_eq!(n, w, "{dim}D rules");
    }
}

#[test]
fn the_common_files_keep_only_what_differs() {
    // what both dimensions share is declared once, in the prelude
    for name in [
        "position", "rest", "velocity", "force", "fixed", "f_ext", "dx", "dv", "df",
    ] {
        let decl = format!("embedding {name} ");
        assert!(PRELUDE.contains(&decl), "prelude declares {name}");
        assert!(!COMMON2D.contains(&decl), "common2d.tmr redeclares {name}");
        assert!(!COMMON3D.contains(&decl), "common3d.tmr redeclares {name}");
    }
    for rule in ["init_rest", "symplectic_euler", "explicit_euler"] {
        let decl = format!("rule {rule}");
        assert!(PRELUDE.contains(&decl), "prelude has {rule}");
        assert!(!COMMON2D.contains(&decl) && !COMMON3D.contains(&decl));
    }
    // a common file alone no longer loads: it needs the prelude's `rest`
    let err = load_sources(&[("common2d.tmr".to_string(), COMMON2D.to_string())]).unwrap_err();
    assert!(err.iter().any(|d| d.message.contains("rest")), "{err:?}");
}
