//! The integration tests of topomech-physics, one module a file, built as one test binary (one
//! compile of what the files share and one link, instead of one a file). Run one file's
//! tests with `cargo test -p topomech-physics --test it <file>::`.

mod baselines;
mod bending;
mod blade;
mod common;
mod compiled;
mod corotational2d;
mod glue;
mod hyperelastic;
mod invariants;
mod jit;
mod loads;
mod membrane;
mod model_files;
mod numbering;
mod patched_plans;
mod reference;
mod shared_files;
mod solvers;
mod static_convergence;
mod static_solve;
mod topology;
