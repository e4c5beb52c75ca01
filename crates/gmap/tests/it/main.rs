//! The integration tests of topomech-gmap, one module a file, built as one test binary (one
//! compile of what the files share and one link, instead of one a file). Run one file's
//! tests with `cargo test -p topomech-gmap --test it <file>::`.

mod change_log;
mod common;
mod hardening_mesh;
mod hardening_tmg;
mod import_geometry;
mod import_kinds;
mod kernel;
mod mesh_build;
mod orbit_values;
mod overlap;
mod rewire_scaling;
