//! The rule language of topomech: a small text format for graph-transformation rules on
//! G-maps, a static checker that refuses any rule that could break a map, a matcher and a
//! rewriter.
//!
//! ```
//! use topomech_rules::{load_sources, Params};
//! use topomech_gmap::generators::{grid, GridElement};
//! use topomech_gmap::mesh::{build, BuildOptions};
//!
//! let src = "dimension 2
//! embedding position : vec3 on <1,2>
//! embedding weight   : f64  on <0,1>
//! rule face_weight {
//!   left { n0 : <0,1> hook }
//!   compute { n0.weight = count<0,1>(n0) }
//! }";
//! let rules = load_sources(&[("weights.tmr".into(), src.into())]).unwrap().0;
//! let (mut g, _) = build(&grid([2, 2], [1.0, 1.0], GridElement::Quad), &BuildOptions::default()).unwrap();
//! let report = rules.apply_everywhere(&mut g, "face_weight", &Params::new()).unwrap();
//! assert_eq!(report.matches, 4);
//! assert!(g.is_valid());
//! ```
#![warn(missing_docs)]

pub mod ast;
pub mod build;
pub mod builtins;
pub mod check;
mod compiled;
mod dims;
pub mod engine;
pub mod jit;
pub mod lexer;
pub mod mechanics;
pub mod model;
pub mod parser;
pub mod value;

use std::path::Path;

pub use check::{Diagnostic, Severity};
pub use engine::{ApplyError, ApplyReport, Params, Region, RuleSet};
pub use model::Model;
pub use value::{Ty, Val};

/// Parses and checks rule sources `(file name, text)` that share their embeddings.
/// On success: the rule set and its warnings; otherwise every diagnostic.
pub fn load_sources(
    sources: &[(String, String)],
) -> Result<(RuleSet, Vec<Diagnostic>), Vec<Diagnostic>> {
    let (checked, diags) = check::check_sources(sources);
    match checked {
        Some(c) => Ok((RuleSet::new(c), diags)),
        None => Err(diags),
    }
}

/// Parses and checks rule sources `(file name, text)` for maps of dimension `dim` (2 or 3).
/// A file serves the dimensions of its `dimension` line: `dimension 2 3` (or no line) serves
/// both, and on a 2-map its label 3 is dropped (`<1,2,3>` means `<1,2>`); an arc `a -3- b`
/// between two nodes is refused there (it can never match). A file that does not serve `dim`
/// is refused. On success: the rule set and its warnings; otherwise every diagnostic.
pub fn load_sources_for(
    dim: usize,
    sources: &[(String, String)],
) -> Result<(RuleSet, Vec<Diagnostic>), Vec<Diagnostic>> {
    let (checked, diags) = check::check_sources_for(Some(dim), sources);
    match checked {
        Some(c) => Ok((RuleSet::new(c), diags)),
        None => Err(diags),
    }
}

/// Reads, parses and checks rule files. An unreadable file is a diagnostic at 1:1.
pub fn load_files(paths: &[&Path]) -> Result<(RuleSet, Vec<Diagnostic>), Vec<Diagnostic>> {
    let mut sources = Vec::new();
    let mut errs = Vec::new();
    for p in paths {
        match std::fs::read_to_string(p) {
            Ok(s) => sources.push((p.display().to_string(), s)),
            Err(e) => errs.push(Diagnostic {
                file: p.display().to_string(),
                pos: ast::Pos { line: 1, col: 1 },
                severity: Severity::Error,
                condition: "file",
                message: format!("cannot read the file: {e}"),
            }),
        }
    }
    if !errs.is_empty() {
        return Err(errs);
    }
    load_sources(&sources)
}

/// The modeling rules shipped with topomech, as `(file name, text)`: split an edge, triangulate
/// a face, Catmull-Clark quad subdivision, unsew and sew along alpha2 (2D) or alpha3 (3D),
/// remove a detached face (2D) or volume (3D).
pub fn library(dimension: usize) -> Option<(String, String)> {
    match dimension {
        2 => Some((
            "modeling2d.tmr".into(),
            include_str!("../library/modeling2d.tmr").into(),
        )),
        3 => Some((
            "modeling3d.tmr".into(),
            include_str!("../library/modeling3d.tmr").into(),
        )),
        _ => None,
    }
}
