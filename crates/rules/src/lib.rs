//! The rule language of topomech.
#![warn(missing_docs)]

pub mod builtins;
pub mod value;
