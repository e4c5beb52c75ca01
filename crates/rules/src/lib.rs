//! The rule language of topomech: a small text format for graph-transformation rules on
//! G-maps, a static checker that refuses any rule that could break a map, a matcher and a
//! rewriter, compiled plans and their native code.
//!
//! This crate is the facade over three rooms, each its own crate, whose doors go one way
//! (language <- engine <- codegen):
//!
//! - `topomech-lang`: the language ([`ast`], [`lexer`], [`parser`], [`check`], [`model`],
//!   [`value`], [`builtins`] with the [`mechanics`] math they serve, [`build`]); it depends on
//!   neither other room;
//! - `topomech-engine`: matching, rewriting, interpreting ([`engine`]) and compiled plans with
//!   their evaluator; it depends on the language and defines the interface a code generator
//!   implements (`topomech_engine::native::NativeBackend`), never naming one;
//! - `topomech-codegen`: the Cranelift code generator ([`jit`]), implementing that interface.
//!
//! The facade re-exports their public paths and wires the backend in: every rule set it
//! builds ([`load_sources`], [`load_sources_for`], [`load_files`], [`load_files_for`],
//! [`build::load`]), and every rule set built with [`RuleSet::new`] from rules checked through
//! it ([`check`]), gets the Cranelift backend.
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

use std::path::Path;
use std::sync::{Arc, Once};

pub use topomech_codegen::jit;
pub use topomech_engine::engine;
pub use topomech_lang::{ast, builtins, lexer, mechanics, model, parser, value};

pub use check::{Diagnostic, Severity};
pub use engine::{ApplyError, ApplyReport, Params, Region, RuleSet};
pub use model::Model;
pub use value::{Ty, Val};

/// Registers the Cranelift code generator as the engine's process-wide default backend
/// (`topomech_engine::native::set_default_backend`), once; a default registered before (by
/// another caller) is kept. Every entry point of this crate that gives checked rules or a
/// rule set calls it, so a caller needs it only for rules checked with `topomech-lang`
/// directly.
///
/// Why a process-wide default rather than a constructor of this crate's own: callers (the
/// physics crate, its tests and benches) build rule sets with `RuleSet::new` on rules checked
/// through [`check`]; `RuleSet` is the engine's type, which cannot name its code generator
/// (the door goes the other way), so the engine takes its default backend from a `OnceLock`
/// that this crate fills, and those callers keep native code without a change.
pub fn install_backend() {
    static INSTALL: Once = Once::new();
    INSTALL.call_once(|| {
        topomech_engine::native::set_default_backend(Arc::new(topomech_codegen::Cranelift));
    });
}

/// The rule set of checked rules, with the Cranelift backend (unless another default backend
/// was registered before, see [`install_backend`]).
fn rule_set(checked: check::Checked) -> RuleSet {
    install_backend();
    RuleSet::new(checked)
}

/// The static checker (`topomech_lang::check`); its entry points also install the Cranelift
/// backend (see [`install_backend`]), so that a [`RuleSet::new`] of what they check runs
/// native code.
pub mod check {
    pub use topomech_lang::check::*;

    use crate::ast::File;
    use crate::install_backend;

    /// Parses and checks rule sources `(file name, text)` that share their embeddings (see
    /// `topomech_lang::check::check_sources`), after [`install_backend`].
    pub fn check_sources(sources: &[(String, String)]) -> (Option<Checked>, Vec<Diagnostic>) {
        install_backend();
        topomech_lang::check::check_sources(sources)
    }

    /// Parses and checks rule sources for maps of dimension `dim`, or of the files'
    /// dimension when `None` (see `topomech_lang::check::check_sources_for`), after
    /// [`install_backend`].
    pub fn check_sources_for(
        dim: Option<usize>,
        sources: &[(String, String)],
    ) -> (Option<Checked>, Vec<Diagnostic>) {
        install_backend();
        topomech_lang::check::check_sources_for(dim, sources)
    }

    /// Checks rule files already parsed (see `topomech_lang::check::check_files`), after
    /// [`install_backend`].
    pub fn check_files(files: &[(String, File)]) -> (Option<Checked>, Vec<Diagnostic>) {
        install_backend();
        topomech_lang::check::check_files(files)
    }

    /// Checks rule files already parsed for maps of dimension `dim` (see
    /// `topomech_lang::check::check_files_for`), after [`install_backend`].
    pub fn check_files_for(
        dim: Option<usize>,
        files: &[(String, File)],
    ) -> (Option<Checked>, Vec<Diagnostic>) {
        install_backend();
        topomech_lang::check::check_files_for(dim, files)
    }
}

/// Rules built as syntax trees (`topomech_lang::build`), and [`build::load`], which checks
/// and loads them into a rule set.
///
/// ```
/// use topomech_rules::build::{self, parse_expression};
///
/// // where { let x = x(v.rest)  <the user's predicate> }
/// let pred = parse_expression("fix[0].where", "x < 0.5").unwrap();
/// let guard = build::let_block(
///     vec![("x", build::call("x", vec![build::read("v", "rest")]))],
///     pred,
/// );
/// let mut r = build::rule("fix_0", build::graph(vec![build::node("v", &[1, 2], true)]));
/// r.guard = Some(guard);
/// r.compute = vec![build::write("v", "fixed", build::boolean(true))];
/// let text = "dimension 2
///   embedding rest : vec3 on <1,2>
///   embedding fixed : bool on <1,2>";
/// let glue = build::file(&topomech_rules::parser::parse(text).unwrap(), vec![r]);
/// let (rules, _) = build::load(&[("decl.tmr".into(), text.into())], vec![("glue".into(), glue)])
///     .unwrap();
/// assert_eq!(rules.rule("fix_0").unwrap().name, "fix_0");
///
/// // rule syntax in a predicate is refused, naming where
/// let e = parse_expression("fix[0].where", "x < 0 } rule evil {").unwrap_err();
/// assert_eq!((e.file.as_str(), e.pos.col), ("fix[0].where", 7));
/// ```
pub mod build {
    pub use topomech_lang::build::*;

    use crate::ast::File;
    use crate::{Diagnostic, RuleSet};

    /// Parses the text sources `(file name, text)` and checks them together with the files
    /// `parsed` (already syntax trees, e.g. built with this module), sharing their embeddings,
    /// with every check [`crate::load_sources`] makes (see [`check_built`]). Diagnostics of a
    /// built file name it by its label and, for a parsed expression inside it, the line and
    /// column in that expression's text.
    ///
    /// On success: the rule set (with the Cranelift backend, see
    /// [`crate::install_backend`]) and its warnings; otherwise every diagnostic.
    pub fn load(
        sources: &[(String, String)],
        parsed: Vec<(String, File)>,
    ) -> Result<(RuleSet, Vec<Diagnostic>), Vec<Diagnostic>> {
        let (checked, diags) = check_built(sources, parsed)?;
        Ok((crate::rule_set(checked), diags))
    }
}
/// Parses and checks rule sources `(file name, text)` that share their embeddings.
/// On success: the rule set (with the Cranelift backend, see [`install_backend`]) and its
/// warnings; otherwise every diagnostic.
pub fn load_sources(
    sources: &[(String, String)],
) -> Result<(RuleSet, Vec<Diagnostic>), Vec<Diagnostic>> {
    let (checked, diags) = topomech_lang::check::check_sources(sources);
    match checked {
        Some(c) => Ok((rule_set(c), diags)),
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
    let (checked, diags) = topomech_lang::check::check_sources_for(Some(dim), sources);
    match checked {
        Some(c) => Ok((rule_set(c), diags)),
        None => Err(diags),
    }
}

/// Reads, parses and checks rule files. An unreadable file, or one that is not a regular file
/// (a directory, `/dev/zero`, a FIFO: refused before reading), is a diagnostic at 1:1.
pub fn load_files(paths: &[&Path]) -> Result<(RuleSet, Vec<Diagnostic>), Vec<Diagnostic>> {
    load_sources(&read_files(paths)?)
}

/// Reads, parses and checks rule files for maps of dimension `dim` (2 or 3), as
/// [`load_sources_for`] checks their texts. An unreadable file, or one that is not a regular
/// file, is a diagnostic at 1:1.
pub fn load_files_for(
    dim: usize,
    paths: &[&Path],
) -> Result<(RuleSet, Vec<Diagnostic>), Vec<Diagnostic>> {
    load_sources_for(dim, &read_files(paths)?)
}

/// The text of the rule file `path`: a regular file, read up to the size it has when opened.
/// A directory, device, FIFO or socket (`/dev/zero`, a named pipe: an endless or blocking
/// stream) is refused before anything is read, as [`topomech_gmap::io::load`] refuses it.
fn read_rule_file(path: &Path) -> std::io::Result<String> {
    use std::io::Read;
    let not_a_file = || {
        std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file (a directory, device, FIFO or socket); a rule file is read \
             only from a regular file",
        )
    };
    // checked before opening too: opening a FIFO waits for a writer
    if !std::fs::metadata(path)?.is_file() {
        return Err(not_a_file());
    }
    let f = std::fs::File::open(path)?;
    let meta = f.metadata()?;
    if !meta.is_file() {
        return Err(not_a_file());
    }
    let mut text = String::new();
    f.take(meta.len()).read_to_string(&mut text)?;
    Ok(text)
}

/// The `(file name, text)` of each file, or a diagnostic at 1:1 for each unreadable one (or
/// one that is not a regular file).
fn read_files(paths: &[&Path]) -> Result<Vec<(String, String)>, Vec<Diagnostic>> {
    let mut sources = Vec::new();
    let mut errs = Vec::new();
    for p in paths {
        match read_rule_file(p) {
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
    if errs.is_empty() {
        Ok(sources)
    } else {
        Err(errs)
    }
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
