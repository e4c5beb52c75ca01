//! Errors of the kernel, one small enum per family.

use crate::{Dart, OrbitType};

/// A refused operation on links or darts.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinkError {
    /// The dimension is not in `0..=n`.
    #[error("link dimension {dim} is out of range for a {n}-map")]
    Dimension {
        /// The dimension asked for.
        dim: usize,
        /// The map's dimension.
        n: usize,
    },
    /// The dart does not exist (never created, or removed).
    #[error("dart {0} does not exist in this map")]
    NoSuchDart(Dart),
    /// `link` needs both darts free at that dimension.
    #[error("cannot link {a} and {b} by alpha{dim}: {busy} is already linked to {to}")]
    NotFree {
        /// The dimension.
        dim: usize,
        /// First dart.
        a: Dart,
        /// Second dart.
        b: Dart,
        /// The dart that is not free.
        busy: Dart,
        /// Its current partner.
        to: Dart,
    },
    /// `unlink` or `unsew` on a dart that is free.
    #[error("dart {dart} is free at alpha{dim}: nothing to unlink")]
    AlreadyFree {
        /// The dimension.
        dim: usize,
        /// The dart.
        dart: Dart,
    },
    /// `remove_dart` on a dart that is still linked.
    #[error("cannot remove dart {dart}: it is still linked by alpha{dim} to {to}")]
    StillLinked {
        /// The dart.
        dart: Dart,
        /// A dimension where it is linked.
        dim: usize,
        /// Its partner.
        to: Dart,
    },
    /// The map cannot hold more than `u32::MAX - 1` darts.
    #[error("too many darts: the map holds at most {max}")]
    Capacity {
        /// The limit.
        max: usize,
    },
}

/// Why `sew` or `unsew` refused: the map is left as it was.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SewError {
    /// A low-level problem (bad dart or dimension).
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The two orbits to sew do not have the same structure.
    #[error("cannot {dim}-sew {a} and {b}: their orbits {orbit} differ in shape at {x} / {y}")]
    NotIsomorphic {
        /// The dimension.
        dim: usize,
        /// First dart given.
        a: Dart,
        /// Second dart given.
        b: Dart,
        /// The orbit traversed in parallel.
        orbit: OrbitType,
        /// Where the shapes differ, on the `a` side.
        x: Dart,
        /// Where the shapes differ, on the `b` side.
        y: Dart,
    },
    /// A dart of the orbit to sew is already linked at that dimension.
    #[error("cannot {dim}-sew {a} and {b}: dart {busy} is not {dim}-free")]
    NotFree {
        /// The dimension.
        dim: usize,
        /// First dart given.
        a: Dart,
        /// Second dart given.
        b: Dart,
        /// The dart that is linked already.
        busy: Dart,
    },
    /// An embedding with the `error` policy would merge or split two different values.
    #[error("cannot {op} at {dart}: embedding '{embedding}' has policy 'error' and its orbits would {what}")]
    Embedding {
        /// `sew` or `unsew`.
        op: &'static str,
        /// The dart given.
        dart: Dart,
        /// The embedding's name.
        embedding: String,
        /// `merge with different values` or `split`.
        what: &'static str,
    },
}

/// A refused operation on embeddings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EmbeddingError {
    /// No embedding of that name.
    #[error("no embedding named '{0}'")]
    Unknown(String),
    /// An embedding of that name exists already.
    #[error("an embedding named '{0}' exists already")]
    Duplicate(String),
    /// The name is empty or has characters other than letters, digits, `_` and `-`.
    #[error("invalid embedding name {0:?}: use letters, digits, '_' and '-'")]
    BadName(String),
    /// The orbit uses a dimension above the map's.
    #[error("embedding '{name}' on {orbit} uses a dimension above the map's ({n})")]
    Dimension {
        /// The embedding.
        name: String,
        /// Its orbit.
        orbit: OrbitType,
        /// The map's dimension.
        n: usize,
    },
    /// A value of the wrong type or size.
    #[error("embedding '{name}' holds {expected}, got {got}")]
    Type {
        /// The embedding.
        name: String,
        /// Its type.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A policy that makes no sense for the type (e.g. `mean` of booleans).
    #[error("policy '{policy}' is not defined for type {ty} (embedding '{name}')")]
    Policy {
        /// The embedding.
        name: String,
        /// The policy.
        policy: String,
        /// The type.
        ty: String,
    },
    /// A derived embedding whose source orbit is not inside its own orbit.
    #[error("derived embedding '{name}' on {orbit} cannot aggregate '{source_name}' on {source_orbit}: the source orbit must be a sub-orbit")]
    NotSubOrbit {
        /// The derived embedding.
        name: String,
        /// Its orbit.
        orbit: OrbitType,
        /// The source.
        source_name: String,
        /// The source's orbit.
        source_orbit: OrbitType,
    },
    /// Writing a derived embedding directly.
    #[error("embedding '{0}' is derived: it is recomputed from its source, never written")]
    Derived(String),
    /// Reading a derived embedding whose source or topology changed since it was recomputed.
    #[error("derived embedding '{0}' is stale: call refresh_derived() first")]
    Stale(String),
    /// A dart that does not exist.
    #[error("dart {0} does not exist in this map")]
    NoSuchDart(Dart),
}

/// A refused map construction.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GMapError {
    /// Only 2- and 3-maps are supported.
    #[error("unsupported dimension {0}: topomech handles 2 (surfaces) and 3 (volumes)")]
    Dimension(usize),
}
