//! The language room of topomech's rule system: the text format of graph-transformation rules
//! on G-maps (lexer, parser, syntax trees, rules built as trees), the static checker that
//! refuses any rule that could break a map, model declarations, values and their types, and
//! the built-in functions with the mechanics math they serve.
//!
//! Doors go one way: the language depends on no other room. The engine
//! (`topomech-engine`: matching, rewriting, interpreting, compiled plans) depends on it, the
//! code generator (`topomech-codegen`, Cranelift) on both, and `topomech-rules` is the facade
//! that wires them together.
//!
//! ```
//! use topomech_lang::check::check_sources;
//!
//! let src = "dimension 2
//! embedding weight : f64 on <0,1>
//! rule face_weight {
//!   left { n0 : <0,1> hook }
//!   compute { n0.weight = count<0,1>(n0) }
//! }";
//! let (checked, diags) = check_sources(&[("weights.tmr".into(), src.into())]);
//! assert!(diags.is_empty());
//! assert_eq!(checked.unwrap().rules[0].name, "face_weight");
//! ```
#![warn(missing_docs)]

pub mod ast;
pub mod build;
pub mod builtins;
pub mod check;
mod dims;
pub mod lexer;
pub mod mechanics;
pub mod model;
pub mod parser;
pub mod value;

pub use check::{Diagnostic, Severity};
pub use model::Model;
pub use value::{Ty, Val};
