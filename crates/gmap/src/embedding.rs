//! Embeddings: named, typed data attached to the orbits of one orbit type.
//!
//! Storage is a dart -> slot index array plus one dense value column indexed by slot; the
//! darts of one orbit share one slot, and two orbits never share a slot (checked by
//! [`GMap::validate`](crate::GMap::validate)). An embedding on `<>` needs no indirection: its
//! slot is the dart index.
//!
//! Each embedding carries a [`Policy`] saying what happens to its values when `sew` merges
//! two of its orbits or `unsew` splits one. A *derived* embedding is an aggregate
//! ([`Aggregate`]) of another one over its sub-orbits; it is recomputed by
//! [`GMap::refresh_derived`](crate::GMap::refresh_derived), never written.

use std::fmt;
use std::sync::Arc;

use crate::{Dart, OrbitType};

/// The type of an embedding's values.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum EmbeddingType {
    /// A real number.
    F64,
    /// A 64-bit integer.
    I64,
    /// A boolean.
    Bool,
    /// A 2-vector of reals.
    Vec2,
    /// A 3-vector of reals.
    Vec3,
    /// A dense real matrix, row-major, at most 12x12.
    Mat {
        /// Rows, 1..=12.
        rows: u8,
        /// Columns, 1..=12.
        cols: u8,
    },
}

/// Largest matrix side.
pub const MAX_MAT: u8 = 12;

impl EmbeddingType {
    /// Number of scalars in one value.
    pub const fn width(self) -> usize {
        match self {
            EmbeddingType::F64 | EmbeddingType::I64 | EmbeddingType::Bool => 1,
            EmbeddingType::Vec2 => 2,
            EmbeddingType::Vec3 => 3,
            EmbeddingType::Mat { rows, cols } => rows as usize * cols as usize,
        }
    }

    /// Whether values are stored as reals (f64, vectors, matrices).
    pub const fn is_real(self) -> bool {
        !matches!(self, EmbeddingType::I64 | EmbeddingType::Bool)
    }

    /// Parses `f64`, `i64`, `bool`, `vec2`, `vec3`, `matN` (square) or `matRxC`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "f64" => Some(EmbeddingType::F64),
            "i64" => Some(EmbeddingType::I64),
            "bool" => Some(EmbeddingType::Bool),
            "vec2" => Some(EmbeddingType::Vec2),
            "vec3" => Some(EmbeddingType::Vec3),
            _ => {
                let dims = s.strip_prefix("mat")?;
                let (r, c) = if let Some((r, c)) = dims.split_once('x') {
                    (r.parse::<u8>().ok()?, c.parse::<u8>().ok()?)
                } else {
                    let k = dims.parse::<u8>().ok()?;
                    (k, k)
                };
                Self::matrix(r, c)
            }
        }
    }

    /// A matrix type, if both sides are in `1..=12`.
    pub fn matrix(rows: u8, cols: u8) -> Option<Self> {
        ((1..=MAX_MAT).contains(&rows) && (1..=MAX_MAT).contains(&cols))
            .then_some(EmbeddingType::Mat { rows, cols })
    }
}

impl fmt::Display for EmbeddingType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EmbeddingType::F64 => write!(f, "f64"),
            EmbeddingType::I64 => write!(f, "i64"),
            EmbeddingType::Bool => write!(f, "bool"),
            EmbeddingType::Vec2 => write!(f, "vec2"),
            EmbeddingType::Vec3 => write!(f, "vec3"),
            EmbeddingType::Mat { rows, cols } if rows == cols => write!(f, "mat{rows}"),
            EmbeddingType::Mat { rows, cols } => write!(f, "mat{rows}x{cols}"),
        }
    }
}

/// What `sew` does when it merges orbits with different values, and `unsew` when it splits one.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub enum Policy {
    /// Merge keeps the value of the first dart's orbit; split copies the value to each part.
    #[default]
    Copy,
    /// Merge sums the values; split divides the value equally between the parts
    /// (integers: the remainder goes to the first part), so the total is kept.
    Sum,
    /// Merge takes the mean of the values; split copies the value (the mean is kept).
    Mean,
    /// Refuse a merge of different values and any split.
    Error,
}

impl Policy {
    /// Parses `copy`, `sum`, `mean`, `error`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "copy" => Some(Policy::Copy),
            "sum" => Some(Policy::Sum),
            "mean" => Some(Policy::Mean),
            "error" => Some(Policy::Error),
            _ => None,
        }
    }

    /// The policy's name.
    pub const fn name(self) -> &'static str {
        match self {
            Policy::Copy => "copy",
            Policy::Sum => "sum",
            Policy::Mean => "mean",
            Policy::Error => "error",
        }
    }
}

/// How a derived embedding aggregates its source over the distinct source orbits inside it.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Aggregate {
    /// Sum of the source values (same type as the source).
    Sum,
    /// Mean of the source values (same type as the source, real types only).
    Mean,
    /// Number of distinct source orbits (an `i64`).
    Count,
}

impl Aggregate {
    /// Parses `sum`, `mean`, `count`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "sum" => Some(Aggregate::Sum),
            "mean" => Some(Aggregate::Mean),
            "count" => Some(Aggregate::Count),
            _ => None,
        }
    }

    /// The aggregate's name.
    pub const fn name(self) -> &'static str {
        match self {
            Aggregate::Sum => "sum",
            Aggregate::Mean => "mean",
            Aggregate::Count => "count",
        }
    }
}

/// The index of an embedding in its map.
#[repr(transparent)]
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, PartialOrd, Ord)]
pub struct EmbeddingId(pub u32);

/// One value of an embedding, for convenience APIs (hot paths use the slices).
#[derive(Clone, PartialEq, Debug)]
pub enum Value {
    /// Real, vector and matrix values: `width` scalars, row-major.
    Real(Vec<f64>),
    /// An integer.
    Int(i64),
    /// A boolean.
    Bool(bool),
}

/// The source of a derived embedding.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Derived {
    /// The aggregated embedding.
    pub source: EmbeddingId,
    /// How.
    pub aggregate: Aggregate,
}

/// A read-only view of an embedding's value column ([`Embedding::column`]): slot `s` of a
/// real embedding of width `w` is `v[s * w..(s + 1) * w]`.
#[derive(Clone, Copy, Debug)]
pub enum ColumnRef<'a> {
    /// Reals.
    Real(&'a [f64]),
    /// Integers.
    Int(&'a [i64]),
    /// Booleans.
    Bool(&'a [bool]),
}

/// A mutable view of a stored embedding's value column ([`crate::GMap::column_mut`]).
#[derive(Debug)]
pub enum ColumnMut<'a> {
    /// Reals.
    Real(&'a mut [f64]),
    /// Integers.
    Int(&'a mut [i64]),
    /// Booleans.
    Bool(&'a mut [bool]),
}

/// The value column of an embedding.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Column {
    Real(Vec<f64>),
    Int(Vec<i64>),
    Bool(Vec<bool>),
}

impl Column {
    pub(crate) fn new(ty: EmbeddingType) -> Self {
        match ty {
            EmbeddingType::I64 => Column::Int(Vec::new()),
            EmbeddingType::Bool => Column::Bool(Vec::new()),
            _ => Column::Real(Vec::new()),
        }
    }

    /// Grows (or shrinks) the column to `slots` slots of `width` values, new ones default.
    pub(crate) fn resize_default(&mut self, width: usize, slots: usize) {
        match self {
            Column::Real(v) => v.resize(slots * width, 0.0),
            Column::Int(v) => v.resize(slots, 0),
            Column::Bool(v) => v.resize(slots, false),
        }
    }

    /// Appends one default (zero / false) value.
    pub(crate) fn push_default(&mut self, width: usize) {
        match self {
            Column::Real(v) => v.extend(std::iter::repeat_n(0.0, width)),
            Column::Int(v) => v.push(0),
            Column::Bool(v) => v.push(false),
        }
    }

    pub(crate) fn copy_slot(&mut self, width: usize, from: usize, to: usize) {
        match self {
            Column::Real(v) => v.copy_within(from * width..(from + 1) * width, to * width),
            Column::Int(v) => v[to] = v[from],
            Column::Bool(v) => v[to] = v[from],
        }
    }

    pub(crate) fn get(&self, width: usize, slot: usize) -> Value {
        match self {
            Column::Real(v) => Value::Real(v[slot * width..(slot + 1) * width].to_vec()),
            Column::Int(v) => Value::Int(v[slot]),
            Column::Bool(v) => Value::Bool(v[slot]),
        }
    }

    pub(crate) fn set(&mut self, width: usize, slot: usize, value: &Value) {
        match (self, value) {
            (Column::Real(v), Value::Real(x)) => {
                v[slot * width..(slot + 1) * width].copy_from_slice(x);
            }
            (Column::Int(v), Value::Int(x)) => v[slot] = *x,
            (Column::Bool(v), Value::Bool(x)) => v[slot] = *x,
            _ => unreachable!("type checked by the caller"),
        }
    }

    pub(crate) fn slots_equal(&self, width: usize, a: usize, b: usize) -> bool {
        match self {
            Column::Real(v) => v[a * width..(a + 1) * width]
                .iter()
                .zip(&v[b * width..(b + 1) * width])
                .all(|(x, y)| x.to_bits() == y.to_bits()),
            Column::Int(v) => v[a] == v[b],
            Column::Bool(v) => v[a] == v[b],
        }
    }

    /// Writes into slot `to` the merge of `slots` under `policy`.
    pub(crate) fn merge(&mut self, width: usize, policy: Policy, slots: &[usize], to: usize) {
        match policy {
            Policy::Copy | Policy::Error => self.copy_slot(width, slots[0], to),
            Policy::Sum | Policy::Mean => {
                let k = slots.len();
                match self {
                    Column::Real(v) => {
                        let mut acc = vec![0.0; width];
                        for &s in slots {
                            for (a, x) in acc.iter_mut().zip(&v[s * width..(s + 1) * width]) {
                                *a += x;
                            }
                        }
                        if policy == Policy::Mean {
                            for a in &mut acc {
                                *a /= k as f64;
                            }
                        }
                        v[to * width..(to + 1) * width].copy_from_slice(&acc);
                    }
                    Column::Int(v) => {
                        let s: i64 = slots.iter().map(|&s| v[s]).fold(0i64, i64::wrapping_add);
                        v[to] = s;
                    }
                    Column::Bool(v) => v[to] = slots.iter().any(|&s| v[s]),
                }
            }
        }
    }

    /// Divides the value of `slot` among `parts` (Sum split): `slot` keeps its share plus
    /// the remainder for integers, and each slot of `others` gets one share.
    pub(crate) fn split_sum(&mut self, width: usize, slot: usize, others: &[usize]) {
        let parts = others.len() + 1;
        match self {
            Column::Real(v) => {
                for x in &mut v[slot * width..(slot + 1) * width] {
                    *x /= parts as f64;
                }
                for &o in others {
                    v.copy_within(slot * width..(slot + 1) * width, o * width);
                }
            }
            Column::Int(v) => {
                let total = v[slot];
                let share = total / parts as i64;
                v[slot] = total - share * others.len() as i64;
                for &o in others {
                    v[o] = share;
                }
            }
            Column::Bool(v) => {
                for &o in others {
                    v[o] = v[slot];
                }
            }
        }
    }
}

/// One embedding of a map: its declaration and storage.
#[derive(Clone, Debug)]
pub struct Embedding {
    pub(crate) name: String,
    pub(crate) ty: EmbeddingType,
    pub(crate) orbit: OrbitType,
    pub(crate) policy: Policy,
    pub(crate) derived: Option<Derived>,
    /// dart -> slot, for orbits other than `<>` (empty for `<>`). Shared, copy on write,
    /// between the embeddings of one orbit type that hold the same table (an embedding
    /// declared on an orbit type another one has starts with that one's table:
    /// `GMap::build_embedding`); the first change to one of them gives it its own.
    pub(crate) slot_of: Arc<Vec<u32>>,
    /// slot -> number of darts using it (empty for `<>`).
    pub(crate) slot_use: Vec<u32>,
    pub(crate) free_slots: Vec<u32>,
    pub(crate) values: Column,
    /// Counts writes, so that derived embeddings know when their source changed.
    pub(crate) writes: u64,
    /// For derived embeddings: (topology version, source writes) at the last refresh.
    pub(crate) refreshed_at: Option<(u64, u64)>,
}

impl Embedding {
    pub(crate) fn new(
        name: &str,
        ty: EmbeddingType,
        orbit: OrbitType,
        policy: Policy,
        derived: Option<Derived>,
    ) -> Self {
        Embedding {
            name: name.to_string(),
            ty,
            orbit,
            policy,
            derived,
            slot_of: Arc::default(),
            slot_use: Vec::new(),
            free_slots: Vec::new(),
            values: Column::new(ty),
            writes: 0,
            refreshed_at: None,
        }
    }

    /// The name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The value type.
    pub fn ty(&self) -> EmbeddingType {
        self.ty
    }

    /// The orbit type the values live on.
    pub fn orbit(&self) -> OrbitType {
        self.orbit
    }

    /// The merge/split policy.
    pub fn policy(&self) -> Policy {
        self.policy
    }

    /// How many times its values were written (or, for a derived embedding, recomputed): a
    /// cache of anything computed from its values is valid while this count stays.
    pub fn writes(&self) -> u64 {
        self.writes
    }

    /// The source and aggregate, if derived.
    pub fn derived(&self) -> Option<Derived> {
        self.derived
    }

    /// Whether slots are darts (orbit `<>`).
    #[inline]
    pub(crate) fn is_direct(&self) -> bool {
        self.orbit.is_empty()
    }

    /// The slot holding the value of `d`'s orbit.
    #[inline]
    pub fn slot(&self, d: Dart) -> usize {
        if self.is_direct() {
            d.index()
        } else {
            self.slot_of[d.index()] as usize
        }
    }

    /// Number of slots in the column (used or free).
    pub fn n_slots(&self) -> usize {
        match &self.values {
            Column::Real(v) => v.len() / self.ty.width(),
            Column::Int(v) => v.len(),
            Column::Bool(v) => v.len(),
        }
    }

    /// The whole real column (width scalars per slot), if the type is real.
    pub fn real_column(&self) -> Option<&[f64]> {
        match &self.values {
            Column::Real(v) => Some(v),
            _ => None,
        }
    }

    /// The whole value column, one entry per slot (`width` scalars per slot when real).
    pub fn column(&self) -> ColumnRef<'_> {
        match &self.values {
            Column::Real(v) => ColumnRef::Real(v),
            Column::Int(v) => ColumnRef::Int(v),
            Column::Bool(v) => ColumnRef::Bool(v),
        }
    }

    /// Bytes of storage this embedding uses, its dart-to-slot table included whole, even
    /// where it shares that table with other embeddings of its orbit type
    /// ([`Embedding::slot_table_bytes`]; [`crate::GMap::memory_bytes`] counts a shared table
    /// once).
    pub fn memory_bytes(&self) -> usize {
        let col = match &self.values {
            Column::Real(v) => v.capacity() * 8,
            Column::Int(v) => v.capacity() * 8,
            Column::Bool(v) => v.capacity(),
        };
        col + self.slot_table_bytes() + (self.slot_use.capacity() + self.free_slots.capacity()) * 4
    }

    /// Bytes of the dart-to-slot table (4 per dart; none for `<>`), which embeddings of one
    /// orbit type share while their slots stay the same.
    pub fn slot_table_bytes(&self) -> usize {
        self.slot_of.capacity() * 4
    }

    /// Whether this embedding and `other` share one dart-to-slot table (then both hold the
    /// same slot for every dart).
    pub fn shares_slot_table(&self, other: &Embedding) -> bool {
        !self.is_direct() && Arc::ptr_eq(&self.slot_of, &other.slot_of)
    }

    /// A new slot with a default value and the given use count.
    pub(crate) fn alloc_slot(&mut self, uses: u32) -> u32 {
        if let Some(s) = self.free_slots.pop() {
            self.slot_use[s as usize] = uses;
            let w = self.ty.width();
            let zero = match self.values {
                Column::Real(_) => Value::Real(vec![0.0; w]),
                Column::Int(_) => Value::Int(0),
                Column::Bool(_) => Value::Bool(false),
            };
            self.values.set(w, s as usize, &zero);
            s
        } else {
            let s = self.slot_use.len() as u32;
            self.slot_use.push(uses);
            self.values.push_default(self.ty.width());
            s
        }
    }

    /// Drops one use of a slot, freeing it at zero.
    pub(crate) fn release(&mut self, s: u32) {
        let u = &mut self.slot_use[s as usize];
        *u -= 1;
        if *u == 0 {
            self.free_slots.push(s);
        }
    }

    /// Checks that `v` fits this embedding's type.
    pub(crate) fn check_value(&self, v: &Value) -> Result<(), crate::EmbeddingError> {
        let ok = match (v, self.ty) {
            (Value::Real(x), t) if t.is_real() => x.len() == t.width(),
            (Value::Int(_), EmbeddingType::I64) | (Value::Bool(_), EmbeddingType::Bool) => true,
            _ => false,
        };
        if ok {
            Ok(())
        } else {
            let got = match v {
                Value::Real(x) => format!("{} real(s)", x.len()),
                Value::Int(_) => "an integer".into(),
                Value::Bool(_) => "a boolean".into(),
            };
            Err(crate::EmbeddingError::Type {
                name: self.name.clone(),
                expected: self.ty.to_string(),
                got,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_parse_and_width() {
        assert_eq!(EmbeddingType::parse("vec3").unwrap().width(), 3);
        assert_eq!(EmbeddingType::parse("mat3").unwrap().width(), 9);
        assert_eq!(EmbeddingType::parse("mat12").unwrap().width(), 144);
        assert_eq!(
            EmbeddingType::parse("mat3x4").unwrap().to_string(),
            "mat3x4"
        );
        assert!(EmbeddingType::parse("mat13").is_none());
        assert!(EmbeddingType::parse("mat0").is_none());
        assert!(EmbeddingType::parse("vec4").is_none());
    }

    #[test]
    fn column_merge_and_split_keep_totals() {
        let mut c = Column::Real(vec![1.0, 2.0, 3.0, 4.0, 0.0, 0.0]);
        c.merge(2, Policy::Sum, &[0, 1], 2);
        assert_eq!(c.get(2, 2), Value::Real(vec![4.0, 6.0]));
        c.merge(2, Policy::Mean, &[0, 1], 2);
        assert_eq!(c.get(2, 2), Value::Real(vec![2.0, 3.0]));
        c.split_sum(2, 2, &[0]);
        assert_eq!(c.get(2, 2), Value::Real(vec![1.0, 1.5]));
        assert_eq!(c.get(2, 0), Value::Real(vec![1.0, 1.5]));
        let mut i = Column::Int(vec![7, 0, 0]);
        i.split_sum(1, 0, &[1, 2]);
        assert_eq!(
            (i.get(1, 0), i.get(1, 1), i.get(1, 2)),
            (Value::Int(3), Value::Int(2), Value::Int(2))
        );
    }
}
