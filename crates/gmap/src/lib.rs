//! The topological kernel of topomech: generalized maps (G-maps) whose mechanical data live
//! on orbits.
//!
//! A G-map of dimension `n` is a set of darts with `n + 1` involutions `alpha_0..alpha_n`
//! (Lienhardt 1994; the paper of the `seed/`: Ben Salah et al., JFIG 2016, hal-01457731).
//! Cells and the paper's finer places for data (half-edges, corners, edge-ends) are all
//! orbits: the darts reachable through a subset of the alphas.
//!
//! - [`GMap`]: darts, links, [`GMap::sew`]/[`GMap::unsew`], orbits, [`GMap::validate`].
//! - [`Embedding`]: typed values on an orbit type, with merge/split [`Policy`] and derived
//!   aggregates.
//! - [`mesh`]: building a map from points and cells, and back; [`generators`]: test meshes.
//! - [`io`]: the `.tmg` file format.
#![warn(missing_docs)]

mod dart;
mod embedding;
mod error;
pub mod generators;
mod gmap;
pub mod io;
pub mod marks;
pub mod mesh;
mod orbit;
mod rewire;
mod sew;
mod valid;

pub use dart::Dart;
pub use embedding::{
    Aggregate, ColumnMut, ColumnRef, Derived, Embedding, EmbeddingId, EmbeddingType, Policy, Value,
    MAX_MAT,
};
pub use error::{EmbeddingError, GMapError, LinkError, SewError};
pub use gmap::{CellCounts, GMap, MAX_DARTS};
pub use marks::Marks;
pub use orbit::{OrbitType, OrbitTypeError, MAX_DIM};
pub use rewire::{RewireError, REWIRE_CHECK_EVERY};
pub use valid::Violation;
