//! The `.tmg` file format: a whole G-map with its embeddings, round-trip exact.
//!
//! Little-endian binary, in this order (version 1):
//!
//! | field | type |
//! |---|---|
//! | magic | the 14 bytes `TOPOMECH-GMAP\n` |
//! | version | u32 (= 1) |
//! | dimension | u32 (2 or 3) |
//! | capacity `C` (dart indices `0..C`) | u32 |
//! | alive flags | `C` x u8 (0 or 1) |
//! | `alpha_0` .. `alpha_3` | 4 x `C` x u32 (a free link is the dart itself) |
//! | number of embeddings | u32 |
//! | each embedding: name | u32 length + UTF-8 bytes |
//! | orbit | u8 bit mask (bit i: dimension i) |
//! | type | u8 tag (0 f64, 1 i64, 2 bool, 3 vec2, 4 vec3, 5 matrix) + u8 rows + u8 cols |
//! | policy | u8 (0 copy, 1 sum, 2 mean, 3 error) |
//! | derived | u8 (0 no, 1 yes) then, if yes, u32 source index + u8 aggregate (0 sum, 1 mean, 2 count) |
//! | slots `S` | u32 |
//! | dart -> slot | `C` x u32, only when the orbit is not `<>` (then `S = C`) |
//! | values | `S x width` f64 bit patterns, or `S` x i64, or `S` x u8 |
//!
//! Reals are stored as their bit patterns, so a load gives back exactly what was saved.
//! Slot use counts and free lists are recomputed on load; derived embeddings are recomputed.
//!
//! Reading never trusts a count: each one (darts, embeddings, name length, slots) is checked
//! against the bytes left in the file before anything is allocated for it, so a short or
//! garbage file costs at most memory in proportion to its own size. [`load`] reads only
//! regular files, and no more than the size the file has when opened.

use std::path::Path;

use crate::embedding::{Column, Derived, Embedding};
use crate::{Aggregate, EmbeddingType, GMap, OrbitType, Policy};

const MAGIC: &[u8; 14] = b"TOPOMECH-GMAP\n";
/// The format version this build writes and reads.
pub const VERSION: u32 = 1;

/// Why a map could not be saved or loaded.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The OS refused.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// Not a `.tmg` file.
    #[error("not a topomech G-map file (bad magic header)")]
    Magic,
    /// A version this build cannot read.
    #[error("unsupported .tmg version {0} (this build reads version {1})")]
    Version(u32, u32),
    /// The file ends early.
    #[error("file truncated at byte {0}")]
    Truncated(usize),
    /// The content is inconsistent.
    #[error("corrupt file at byte {at}: {why}")]
    Corrupt {
        /// Byte offset.
        at: usize,
        /// What is wrong.
        why: String,
    },
}

/// Writes `g` to bytes.
pub fn to_bytes(g: &GMap) -> Vec<u8> {
    let cap = g.capacity();
    let mut w = Vec::with_capacity(64 + cap * 17);
    w.extend_from_slice(MAGIC);
    put_u32(&mut w, VERSION);
    put_u32(&mut w, g.dim as u32);
    put_u32(&mut w, cap as u32);
    w.extend(g.alive.iter().map(|&a| u8::from(a)));
    for a in &g.alpha {
        for &x in a {
            put_u32(&mut w, x);
        }
    }
    put_u32(&mut w, g.embeddings.len() as u32);
    for e in &g.embeddings {
        put_u32(&mut w, e.name.len() as u32);
        w.extend_from_slice(e.name.as_bytes());
        w.push(e.orbit.mask());
        let (tag, r, c) = match e.ty {
            EmbeddingType::F64 => (0, 1, 1),
            EmbeddingType::I64 => (1, 1, 1),
            EmbeddingType::Bool => (2, 1, 1),
            EmbeddingType::Vec2 => (3, 2, 1),
            EmbeddingType::Vec3 => (4, 3, 1),
            EmbeddingType::Mat { rows, cols } => (5, rows, cols),
        };
        w.extend([tag, r, c]);
        w.push(match e.policy {
            Policy::Copy => 0,
            Policy::Sum => 1,
            Policy::Mean => 2,
            Policy::Error => 3,
        });
        match e.derived {
            None => w.push(0),
            Some(d) => {
                w.push(1);
                put_u32(&mut w, d.source.0);
                w.push(match d.aggregate {
                    Aggregate::Sum => 0,
                    Aggregate::Mean => 1,
                    Aggregate::Count => 2,
                });
            }
        }
        put_u32(&mut w, e.n_slots() as u32);
        if !e.is_direct() {
            for &s in e.slot_of.iter() {
                put_u32(&mut w, s);
            }
        }
        match &e.values {
            Column::Real(v) => v
                .iter()
                .for_each(|x| w.extend_from_slice(&x.to_bits().to_le_bytes())),
            Column::Int(v) => v.iter().for_each(|x| w.extend_from_slice(&x.to_le_bytes())),
            Column::Bool(v) => w.extend(v.iter().map(|&b| u8::from(b))),
        }
    }
    w
}

fn put_u32(w: &mut Vec<u8>, x: u32) {
    w.extend_from_slice(&x.to_le_bytes());
}

/// A bounds-checked cursor: every read past the end is a [`FormatError::Truncated`].
struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], FormatError> {
        if self.b.len() - self.at < n {
            return Err(FormatError::Truncated(self.b.len()));
        }
        let s = &self.b[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }

    fn u8(&mut self) -> Result<u8, FormatError> {
        Ok(self.take(1)?[0])
    }

    fn u32(&mut self) -> Result<u32, FormatError> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }

    fn u64(&mut self) -> Result<u64, FormatError> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    /// The bytes not read yet.
    fn left(&self) -> usize {
        self.b.len() - self.at
    }

    /// Refuses a count of `what` whose `need` bytes the rest of the file cannot hold,
    /// naming it; called before anything is allocated for it.
    fn expect_bytes(&self, need: usize, what: impl FnOnce() -> String) -> Result<(), FormatError> {
        let left = self.left();
        if need > left {
            return Err(self.corrupt(format!(
                "{} need {need} bytes but only {left} are left in the file",
                what()
            )));
        }
        Ok(())
    }

    fn corrupt(&self, why: impl Into<String>) -> FormatError {
        FormatError::Corrupt {
            at: self.at,
            why: why.into(),
        }
    }
}

/// Reads a map from bytes. Never panics: garbage gives a [`FormatError`].
pub fn from_bytes(b: &[u8]) -> Result<GMap, FormatError> {
    let mut r = Reader { b, at: 0 };
    if r.take(MAGIC.len()).map_err(|_| FormatError::Magic)? != MAGIC {
        return Err(FormatError::Magic);
    }
    let version = r.u32()?;
    if version != VERSION {
        return Err(FormatError::Version(version, VERSION));
    }
    let dim = r.u32()? as usize;
    let mut g = GMap::new(dim).map_err(|e| r.corrupt(e.to_string()))?;
    let cap = r.u32()? as usize;
    if cap > crate::MAX_DARTS {
        return Err(r.corrupt("dart capacity too large"));
    }
    r.expect_bytes(cap.saturating_mul(17), || {
        format!("{cap} darts (alive flags and 4 links)")
    })?;
    for (i, &a) in r.take(cap)?.iter().enumerate() {
        if a > 1 {
            return Err(r.corrupt(format!("alive flag of dart {i} is {a}")));
        }
        g.alive.push(a == 1);
        if a == 0 {
            g.free_darts.push(i as u32);
        }
    }
    g.free_darts.reverse();
    g.n_alive = cap - g.free_darts.len();
    for i in 0..4 {
        let mut col = Vec::with_capacity(cap);
        for _ in 0..cap {
            let x = r.u32()?;
            if x as usize >= cap {
                return Err(r.corrupt(format!(
                    "alpha{i} points at dart {x}, past the capacity {cap}"
                )));
            }
            col.push(x);
        }
        g.alpha[i] = col;
    }
    let n_emb = r.u32()? as usize;
    // the smallest embedding record: name length, a 1-byte name, orbit, type (3), policy,
    // derived flag, slot count
    r.expect_bytes(n_emb.saturating_mul(15), || format!("{n_emb} embeddings"))?;
    for k in 0..n_emb {
        let len = r.u32()? as usize;
        r.expect_bytes(len, || format!("embedding {k}: a name of {len} bytes"))?;
        let name = std::str::from_utf8(r.take(len)?)
            .map_err(|_| r.corrupt(format!("embedding {k}: name is not UTF-8")))?
            .to_string();
        let valid_name = !name.is_empty()
            && name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !valid_name || g.embedding_id(&name).is_some() {
            return Err(r.corrupt(format!("embedding {k}: bad or duplicate name {name:?}")));
        }
        let orbit = OrbitType::from_mask(r.u8()?).map_err(|e| r.corrupt(e.to_string()))?;
        if orbit.max_dim().is_some_and(|m| m > dim) {
            return Err(r.corrupt(format!(
                "embedding '{name}': orbit {orbit} above dimension {dim}"
            )));
        }
        let (tag, rows, cols) = (r.u8()?, r.u8()?, r.u8()?);
        let ty = match tag {
            0 => EmbeddingType::F64,
            1 => EmbeddingType::I64,
            2 => EmbeddingType::Bool,
            3 => EmbeddingType::Vec2,
            4 => EmbeddingType::Vec3,
            5 => EmbeddingType::matrix(rows, cols)
                .ok_or_else(|| r.corrupt(format!("embedding '{name}': matrix {rows}x{cols}")))?,
            t => return Err(r.corrupt(format!("embedding '{name}': type tag {t}"))),
        };
        let policy = match r.u8()? {
            0 => Policy::Copy,
            1 => Policy::Sum,
            2 => Policy::Mean,
            3 => Policy::Error,
            t => return Err(r.corrupt(format!("embedding '{name}': policy tag {t}"))),
        };
        let derived = match r.u8()? {
            0 => None,
            1 => {
                let source = r.u32()?;
                if source as usize >= k {
                    return Err(r.corrupt(format!(
                        "embedding '{name}': source {source} not declared before it"
                    )));
                }
                let aggregate = match r.u8()? {
                    0 => Aggregate::Sum,
                    1 => Aggregate::Mean,
                    2 => Aggregate::Count,
                    t => return Err(r.corrupt(format!("embedding '{name}': aggregate tag {t}"))),
                };
                Some(Derived {
                    source: crate::EmbeddingId(source),
                    aggregate,
                })
            }
            t => return Err(r.corrupt(format!("embedding '{name}': derived flag {t}"))),
        };
        let mut e = Embedding::new(&name, ty, orbit, policy, derived);
        let n_slots = r.u32()? as usize;
        // every count is checked against the bytes left before anything is allocated
        let value_bytes = match ty {
            EmbeddingType::Bool => 1,
            _ => 8 * ty.width(),
        };
        let map_bytes = if e.is_direct() { 0 } else { cap * 4 };
        r.expect_bytes(
            n_slots
                .saturating_mul(value_bytes)
                .saturating_add(map_bytes),
            || {
                format!(
                    "embedding '{name}': {n_slots} slots of {value_bytes} bytes for {cap} darts"
                )
            },
        )?;
        if e.is_direct() {
            if n_slots != cap {
                return Err(r.corrupt(format!(
                    "embedding '{name}' on <> has {n_slots} slots for {cap} darts"
                )));
            }
        } else {
            let mut table = Vec::with_capacity(cap);
            e.slot_use = vec![0; n_slots];
            for d in 0..cap {
                let s = r.u32()?;
                if s as usize >= n_slots && g.alive[d] {
                    return Err(r.corrupt(format!(
                        "embedding '{name}': dart {d} has slot {s} of {n_slots}"
                    )));
                }
                if g.alive[d] {
                    e.slot_use[s as usize] += 1;
                }
                table.push(s);
            }
            // one table for the embeddings of an orbit type that hold the same slots, as
            // when they were declared (`GMap::build_embedding`)
            e.slot_of = g
                .embeddings
                .iter()
                .find(|t| t.orbit == e.orbit && *t.slot_of == table)
                .map_or_else(
                    || std::sync::Arc::new(table),
                    |t| std::sync::Arc::clone(&t.slot_of),
                );
            e.free_slots = (0..n_slots as u32)
                .rev()
                .filter(|&s| e.slot_use[s as usize] == 0)
                .collect();
        }
        let w = ty.width();
        e.values = match ty {
            EmbeddingType::I64 => {
                // (collected into a vector of the exact size: `collect` over results grows
                // it by doubling, up to twice the memory the map then reports)
                let mut v = Vec::with_capacity(n_slots);
                for _ in 0..n_slots {
                    v.push(r.u64()? as i64);
                }
                Column::Int(v)
            }
            EmbeddingType::Bool => {
                let bytes = r.take(n_slots)?;
                if let Some(x) = bytes.iter().find(|&&x| x > 1) {
                    return Err(r.corrupt(format!("embedding '{name}': boolean byte {x}")));
                }
                Column::Bool(bytes.iter().map(|&x| x == 1).collect())
            }
            _ => {
                let mut v = Vec::with_capacity(n_slots * w);
                for _ in 0..n_slots * w {
                    v.push(f64::from_bits(r.u64()?));
                }
                Column::Real(v)
            }
        };
        if let Some(d) = derived {
            let src = &g.embeddings[d.source.0 as usize];
            let expected = if d.aggregate == Aggregate::Count {
                EmbeddingType::I64
            } else {
                src.ty
            };
            if expected != ty || !src.orbit.is_subset_of(orbit) {
                return Err(r.corrupt(format!(
                    "embedding '{name}': inconsistent with its source '{}'",
                    src.name
                )));
            }
        }
        g.embeddings.push(e);
    }
    if r.at != b.len() {
        return Err(r.corrupt(format!("{} bytes after the last embedding", b.len() - r.at)));
    }
    g.refresh_derived();
    Ok(g)
}

/// Saves `g` to `path`.
pub fn save(g: &GMap, path: &Path) -> Result<(), FormatError> {
    std::fs::write(path, to_bytes(g)).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Loads a map from `path`: a regular file, read up to the size it has when opened. A
/// device, FIFO or socket (`/dev/zero`, a named pipe: an endless stream) is refused with
/// [`FormatError::Io`] before anything is read.
pub fn load(path: &Path) -> Result<GMap, FormatError> {
    use std::io::Read;
    let io_err = |source| FormatError::Io {
        path: path.display().to_string(),
        source,
    };
    let not_a_file = || {
        io_err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file (a directory, device, FIFO or socket); a .tmg map is read \
             only from a regular file",
        ))
    };
    // checked before opening too: opening a FIFO waits for a writer
    if !std::fs::metadata(path).map_err(io_err)?.is_file() {
        return Err(not_a_file());
    }
    let f = std::fs::File::open(path).map_err(io_err)?;
    let meta = f.metadata().map_err(io_err)?;
    if !meta.is_file() {
        return Err(not_a_file());
    }
    let len = meta.len();
    // no capacity reserved from the size: a sparse file may claim terabytes
    let mut b = Vec::new();
    f.take(len).read_to_end(&mut b).map_err(io_err)?;
    from_bytes(&b)
}
