//! The code generator room of topomech's rule system: compiled plans' register programs to
//! native code with Cranelift ([`jit`]), bit for bit what the engine's evaluator computes.
//!
//! Doors go one way: the code generator depends on the engine (`topomech-engine`, whose
//! interface [`topomech_engine::native::NativeBackend`] it implements as [`Cranelift`]) and on
//! the language (`topomech-lang`, for values and built-ins); neither depends on it. The facade
//! `topomech-rules` installs [`Cranelift`] in the rule sets it builds.
#![warn(missing_docs)]

pub mod jit;

pub use jit::{compiled_count, Cranelift};
