//! The engine room of topomech's rule system: matching checked rules on a G-map, rewriting
//! it, interpreting their expressions, and compiled plans (a rule's matches and expressions
//! as flat arrays and a register program) with their evaluator.
//!
//! Doors go one way: the engine depends on the language (`topomech-lang`) and never on a code
//! generator. Native code comes through the interface defined in [`native`]
//! ([`native::NativeBackend`], [`native::NativeFn`], [`native::JitArgs`]), implemented by
//! `topomech-codegen` (Cranelift) and handed to a rule set ([`RuleSet::set_backend`], or the
//! process-wide [`native::set_default_backend`]) by the facade `topomech-rules`. Without a
//! backend, compiled plans run the evaluator, which stays the reference and the fallback.
#![warn(missing_docs)]

// The register program and its evaluator; public for the code generator only.
#[doc(hidden)]
pub mod compiled;
pub mod engine;
pub mod native;

// The language modules the engine's code names as `crate::...`.
use topomech_lang::{ast, builtins, check, model, value};

pub use engine::{ApplyError, ApplyReport, Params, Region, RuleSet};
