//! The integration tests of topomech-rules, one module a file, built as one test binary (one
//! compile of what the files share and one link, instead of one a file). Run one file's
//! tests with `cargo test -p topomech-rules --test it <file>::`.

mod aggregate_order;
mod build;
mod builtins;
mod checker;
mod dimension_independent;
mod eager;
mod embedding_consistency;
mod find_all_reference;
mod fuzz;
mod guard_plans;
mod hardening;
mod interrupt;
mod interrupt_rewire;
mod invariant_guards;
mod jit;
mod model_decl;
mod modeling;
mod nonfinite;
mod numbering;
mod orbit_writes;
mod overflow_elements;
mod plans;
mod readme;
mod rule_files;
mod shared_matches;
mod sub_orbit_aggregates;

/// Every value of the real embedding `name` of `g`, bit for bit (a column compared before
/// and after, or between two maps).
pub(crate) fn column_bits(g: &topomech_gmap::GMap, name: &str) -> Vec<u64> {
    let id = g.require(name).unwrap();
    g.embedding(id)
        .real_column()
        .unwrap()
        .iter()
        .map(|x| x.to_bits())
        .collect()
}
