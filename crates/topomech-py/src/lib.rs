//! `topomech._core`: the Python bindings of the topomech kernel.
//!
//! - [`gmap`]: the `GMap` class (numpy arrays in and out, every index checked).
//! - [`rules`]: the `RuleSet` class, rule files loaded, checked and applied to maps.
//! - [`sim`]: the `Simulation` class, the physical models of a configuration stepped on a copy
//!   of a map, and `models`, the catalogue of model kinds.
//! - [`generators`]: `grid` and `box`, generated meshes in the flat layout of [`convert`].
//! - [`errors`]: the exception hierarchy, and the guard that keeps Rust panics out of Python.
//!
//! Python users import `topomech`, whose `GMap` wraps this module's with mesh conversions.
#![warn(missing_docs)]

mod convert;
mod errors;
mod generators;
mod gmap;
mod rules;
mod sim;

use pyo3::prelude::*;

/// The topomech kernel: generalized maps, the meshes they are built from, rules and
/// simulations.
#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // glibc's fast bins off for the process (see `topomech_physics::tune_malloc`: a topology
    // change stalled in malloc's consolidation of them); whether it was done
    m.add("_malloc_tuned", topomech_physics::tune_malloc())?;
    errors::register(m)?;
    m.add_class::<gmap::PyGMap>()?;
    m.add_class::<rules::PyRuleSet>()?;
    m.add_class::<sim::PySimulation>()?;
    m.add_function(wrap_pyfunction!(sim::models, m)?)?;
    m.add_function(wrap_pyfunction!(rules::check_predicate, m)?)?;
    m.add_function(wrap_pyfunction!(rules::blade_sweep_problem, m)?)?;
    m.add_function(wrap_pyfunction!(rules::eval_predicate, m)?)?;
    m.add_function(wrap_pyfunction!(rules::eval_expression, m)?)?;
    m.add_function(wrap_pyfunction!(generators::grid, m)?)?;
    m.add_function(wrap_pyfunction!(generators::cuboid, m)?)?;
    m.add_function(wrap_pyfunction!(panic_for_tests, m)?)?;
    Ok(())
}

/// Panics with `message` inside the boundary guard: the tests check that a Rust panic reaches
/// Python as `InternalError`, never as a crash or a `PanicException`.
#[pyfunction(name = "_panic_for_tests")]
fn panic_for_tests(message: &str) -> PyResult<()> {
    errors::guard(|| panic!("{message}"))
}
