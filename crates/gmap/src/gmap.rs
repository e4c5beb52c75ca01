//! The generalized map: darts, alpha links, orbits and embeddings.

use crate::embedding::{
    Column, ColumnMut, ColumnRef, Derived, Embedding, EmbeddingId, EmbeddingType, Policy, Value,
};
use crate::marks::{with_marks, Marks};
use crate::{Aggregate, Dart, EmbeddingError, GMapError, LinkError, OrbitType};
use std::sync::Arc;

thread_local! {
    /// The stack of [`GMap::visit_orbit`], kept per thread between walks.
    static WALK_STACK: std::cell::Cell<Vec<Dart>> = const { std::cell::Cell::new(Vec::new()) };
}

/// Largest number of darts a map holds (indices are `u32`).
pub const MAX_DARTS: usize = u32::MAX as usize - 1;

/// A generalized map of dimension 2 (surfaces) or 3 (volumes).
///
/// Darts are indices into struct-of-arrays tables: `alpha[i][d]` for `i` in `0..=3` (alpha3 is
/// kept and stays free in a 2-map). A free link points to the dart itself. Removed darts go
/// to a free list and are reused by [`GMap::add_dart`].
///
/// Invariants (checked by [`GMap::validate`]): each `alpha_i` is an involution; `alpha_i o
/// alpha_j` is an involution for `i + 2 <= j`; every embedding is constant on its orbits
/// (the darts of an orbit share one slot, and no slot is shared by two orbits).
///
/// ```
/// use topomech_gmap::{GMap, OrbitType};
/// let mut g = GMap::new(2).unwrap();
/// let a = g.add_darts(2);
/// let b = topomech_gmap::Dart(a.0 + 1);
/// g.link(0, a, b).unwrap();
/// assert_eq!(g.alpha(0, a), b);
/// assert_eq!(g.orbit(a, OrbitType::parse("<0>").unwrap()).len(), 2);
/// assert!(g.is_valid());
/// ```
#[derive(Clone, Debug)]
pub struct GMap {
    pub(crate) dim: usize,
    pub(crate) alpha: [Vec<u32>; 4],
    pub(crate) alive: Vec<bool>,
    pub(crate) free_darts: Vec<u32>,
    pub(crate) n_alive: usize,
    pub(crate) version: u64,
    pub(crate) embeddings: Vec<Embedding>,
    pub(crate) id: MapId,
    /// The darts changed since some version, when tracking is on (see
    /// [`GMap::track_changes`]).
    pub(crate) log: Option<ChangeLog>,
}

/// The darts whose links or embedding slots changed, or that were created or removed, each
/// tagged with the topology version the map had when it changed (the version before the
/// operation's increment, or a later one: a tag is never earlier than the change).
#[derive(Clone, Debug)]
pub(crate) struct ChangeLog {
    /// The log covers every change made at versions `>= from`.
    from: u64,
    /// (tag, dart, whether its links changed or it was created or removed: else only its
    /// slot in some embedding changed)
    entries: Vec<(u64, u32, bool)>,
    /// The tag of the last entry, and the darts listed at that tag as link changes and as
    /// slot changes, so that a dart is listed once per tag and kind (a re-slotting touches
    /// it once per embedding). Bit sets, cleared in time proportional to what they hold
    /// when the tag changes: a change touches a few pages of them, not a table of a word
    /// per dart that its first use would fault in.
    tag: u64,
    links_at_tag: Marks,
    slots_at_tag: Marks,
    /// Entries recorded since recording started (those dropped included).
    recorded: u64,
}

/// At most this many entries (or one per dart of the map, if more) are kept: past it the
/// older half is dropped (the versions it covered are then no longer answered).
const LOG_MIN_LIMIT: usize = 1 << 16;

/// Records that the links of dart `d` changed (or that it was created or removed) while the
/// map was at `version` (a free function, so that it can be called while an embedding of the
/// map is borrowed).
#[inline]
pub(crate) fn note(log: &mut Option<ChangeLog>, version: u64, d: u32, capacity: usize) {
    note_kind(log, version, d, capacity, true);
}

/// Records that the slot of dart `d` in some embedding changed while the map was at
/// `version`, its links staying (see [`note`]).
#[inline]
pub(crate) fn note_slot(log: &mut Option<ChangeLog>, version: u64, d: u32, capacity: usize) {
    note_kind(log, version, d, capacity, false);
}

#[inline]
fn note_kind(log: &mut Option<ChangeLog>, version: u64, d: u32, capacity: usize, links: bool) {
    let Some(l) = log else { return };
    if l.tag != version {
        l.tag = version;
        l.links_at_tag.clear();
        l.slots_at_tag.clear();
    }
    // listed at this tag already as a link change, or as a slot change and this is one
    let x = Dart(d);
    if l.links_at_tag.is_marked(x) || (!links && l.slots_at_tag.is_marked(x)) {
        return;
    }
    if links {
        l.links_at_tag.mark(x);
    } else {
        l.slots_at_tag.mark(x);
    }
    l.entries.push((version, d, links));
    l.recorded += 1;
    if l.entries.len() > LOG_MIN_LIMIT.max(capacity) {
        // drop every entry tagged up to the middle one's tag: the log then answers from the
        // next version on
        let t = l.entries[l.entries.len() / 2].0;
        let keep = l.entries.partition_point(|e| e.0 <= t);
        l.entries.drain(..keep);
        l.from = l.from.max(t + 1);
    }
}

/// A number naming one map object: every map, and every clone of one, gets its own, so a cache
/// keyed by (`id`, `version`) can never be applied to another map.
#[derive(Debug)]
pub(crate) struct MapId(pub(crate) u64);

impl MapId {
    pub(crate) fn fresh() -> Self {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        MapId(NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed))
    }
}

impl Clone for MapId {
    fn clone(&self) -> Self {
        MapId::fresh()
    }
}

/// Counts of the cells of a map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct CellCounts {
    /// Number of darts.
    pub darts: usize,
    /// Vertex orbits `<1..n>`.
    pub vertices: usize,
    /// Edge orbits `<0,2..n>`.
    pub edges: usize,
    /// Face orbits `<0,1,3..n>` (a face between two volumes counts once).
    pub faces: usize,
    /// Volume orbits `<0,1,2>` (0 for a 2-map).
    pub volumes: usize,
    /// Connected components `<0..n>`.
    pub components: usize,
    /// Boundary cells: in 3D the faces `<0,1>` whose darts are 3-free; in 2D the edges `<0>`
    /// whose darts are 2-free.
    pub boundary: usize,
}

impl GMap {
    /// An empty map of dimension 2 or 3.
    pub fn new(dim: usize) -> Result<Self, GMapError> {
        if dim != 2 && dim != 3 {
            return Err(GMapError::Dimension(dim));
        }
        Ok(GMap {
            dim,
            alpha: Default::default(),
            alive: Vec::new(),
            free_darts: Vec::new(),
            n_alive: 0,
            version: 0,
            embeddings: Vec::new(),
            id: MapId::fresh(),
            log: None,
        })
    }

    /// The dimension `n` (2 or 3).
    #[inline]
    pub fn dimension(&self) -> usize {
        self.dim
    }

    /// The number of live darts.
    #[inline]
    pub fn n_darts(&self) -> usize {
        self.n_alive
    }

    /// One more than the largest dart index ever used: tables have this length.
    #[inline]
    pub fn capacity(&self) -> usize {
        self.alive.len()
    }

    /// The topology version: it changes whenever a link changes or a dart is added or removed.
    /// Caches derived from the topology (plans) key on it.
    #[inline]
    pub fn version(&self) -> u64 {
        self.version
    }

    /// The identity of this map object (unique per map and per clone) and its topology
    /// version: a cache keyed by both is never applied to another map or topology.
    #[inline]
    pub fn identity(&self) -> (u64, u64) {
        (self.id.0, self.version)
    }

    /// Starts recording which darts change (links, embedding slots, creation, removal), so
    /// that [`GMap::changed_since`] can answer for the versions from now on. Does nothing
    /// when it records already. A clone records too (from its own creation on).
    pub fn track_changes(&mut self) {
        if self.log.is_none() {
            self.log = Some(ChangeLog {
                from: self.version,
                entries: Vec::new(),
                tag: self.version,
                links_at_tag: Marks::default(),
                slots_at_tag: Marks::default(),
                recorded: 0,
            });
        }
    }

    /// Every dart whose links or embedding slots changed, or that was created or removed,
    /// since the map had topology version `version` (each once, in no particular order;
    /// removed darts included). `None` when the record does not cover that version (not
    /// tracked then, or dropped since: the record is bounded), or `version` is in the
    /// future. What a cache keyed by [`GMap::identity`] can patch itself from.
    pub fn changed_since(&self, version: u64) -> Option<Vec<Dart>> {
        let l = self.log.as_ref()?;
        if version < l.from || version > self.version {
            return None;
        }
        let start = l.entries.partition_point(|e| e.0 < version);
        let mut out: Vec<Dart> = l.entries[start..].iter().map(|e| Dart(e.1)).collect();
        out.sort_unstable();
        out.dedup();
        Some(out)
    }

    /// The darts of [`GMap::changed_since`] whose links changed, or that were created or
    /// removed, since version `version`: those whose slots only changed are left out. Every
    /// orbit that was split, merged or re-slotted holds one (a re-slotting walks the orbits
    /// around the darts whose links changed), so an orbit holding none is an orbit of the map
    /// at `version`, on the same slots of every embedding. `None` as for
    /// [`GMap::changed_since`].
    pub fn relinked_since(&self, version: u64) -> Option<Vec<Dart>> {
        let l = self.log.as_ref()?;
        if version < l.from || version > self.version {
            return None;
        }
        let start = l.entries.partition_point(|e| e.0 < version);
        let mut out: Vec<Dart> = l.entries[start..]
            .iter()
            .filter(|e| e.2)
            .map(|e| Dart(e.1))
            .collect();
        out.sort_unstable();
        out.dedup();
        Some(out)
    }

    /// The state of the change record: the first version it covers and how many entries it
    /// has recorded (those dropped since included); `None` when changes are not recorded.
    /// Every change recorded adds one, so with [`GMap::identity`] it fixes what
    /// [`GMap::changes_since`] answers: a cache of that answer keys on both.
    pub fn change_record(&self) -> Option<(u64, u64)> {
        self.log.as_ref().map(|l| (l.from, l.recorded))
    }

    /// [`GMap::changed_since`] and [`GMap::relinked_since`] from one pass over the record:
    /// `(changed, relinked)`, each sorted, each dart once; `relinked` is a subset of
    /// `changed`. `None` as for [`GMap::changed_since`].
    pub fn changes_since(&self, version: u64) -> Option<(Vec<Dart>, Vec<Dart>)> {
        let l = self.log.as_ref()?;
        if version < l.from || version > self.version {
            return None;
        }
        let start = l.entries.partition_point(|e| e.0 < version);
        // (dart, relinked), sorted so that a dart's relinked entry, if any, comes last
        let mut all: Vec<(u32, bool)> = l.entries[start..].iter().map(|e| (e.1, e.2)).collect();
        all.sort_unstable();
        let mut changed: Vec<Dart> = Vec::with_capacity(all.len());
        let mut relinked: Vec<Dart> = Vec::new();
        for (k, &(d, r)) in all.iter().enumerate() {
            if all.get(k + 1).is_some_and(|n| n.0 == d) {
                continue;
            }
            changed.push(Dart(d));
            if r {
                relinked.push(Dart(d));
            }
        }
        Some((changed, relinked))
    }

    /// Whether `d` is a live dart of this map.
    #[inline]
    pub fn is_alive(&self, d: Dart) -> bool {
        self.alive.get(d.index()).copied().unwrap_or(false)
    }

    /// The live darts, in index order.
    pub fn darts(&self) -> impl Iterator<Item = Dart> + '_ {
        self.alive
            .iter()
            .enumerate()
            .filter(|(_, &a)| a)
            .map(|(i, _)| Dart(i as u32))
    }

    /// `alpha_i(d)`. `d` must be live and `i <= 3`.
    #[inline]
    pub fn alpha(&self, i: usize, d: Dart) -> Dart {
        Dart(self.alpha[i][d.index()])
    }

    /// `alpha_I(d)` with the dimension known at compile time.
    #[inline]
    pub fn alpha_c<const I: usize>(&self, d: Dart) -> Dart {
        Dart(self.alpha[I][d.index()])
    }

    /// Whether `d` is free at dimension `i`.
    #[inline]
    pub fn is_free(&self, i: usize, d: Dart) -> bool {
        self.alpha[i][d.index()] == d.0
    }

    pub(crate) fn check_dart(&self, d: Dart) -> Result<(), LinkError> {
        if self.is_alive(d) {
            Ok(())
        } else {
            Err(LinkError::NoSuchDart(d))
        }
    }

    pub(crate) fn check_dim(&self, i: usize) -> Result<(), LinkError> {
        if i <= self.dim {
            Ok(())
        } else {
            Err(LinkError::Dimension {
                dim: i,
                n: self.dim,
            })
        }
    }

    /// Adds one free dart, reusing a removed index when there is one.
    pub fn add_dart(&mut self) -> Dart {
        if let Some(i) = self.free_darts.pop() {
            let iu = i as usize;
            self.alive[iu] = true;
            for a in &mut self.alpha {
                a[iu] = i;
            }
            self.n_alive += 1;
            let cap = self.capacity();
            note(&mut self.log, self.version, i, cap);
            self.version += 1;
            for e in &mut self.embeddings {
                if e.is_direct() {
                    let w = e.ty.width();
                    match &e.values {
                        Column::Real(_) => e.values.set(w, iu, &Value::Real(vec![0.0; w])),
                        Column::Int(_) => e.values.set(w, iu, &Value::Int(0)),
                        Column::Bool(_) => e.values.set(w, iu, &Value::Bool(false)),
                    }
                } else {
                    let s = e.alloc_slot(1);
                    Arc::make_mut(&mut e.slot_of)[iu] = s;
                }
            }
            Dart(i)
        } else {
            self.add_darts(1)
        }
    }

    /// Appends `k` free darts with consecutive indices (never from the free list) and returns
    /// the first. Panics past [`MAX_DARTS`].
    pub fn add_darts(&mut self, k: usize) -> Dart {
        let first = self.alive.len();
        assert!(first + k <= MAX_DARTS, "too many darts");
        let end = first + k;
        for a in &mut self.alpha {
            a.extend(first as u32..end as u32);
        }
        self.alive.resize(end, true);
        self.n_alive += k;
        for d in first..end {
            note(&mut self.log, self.version, d as u32, end);
        }
        self.version += 1;
        for e in &mut self.embeddings {
            let w = e.ty.width();
            if e.is_direct() {
                for _ in 0..k {
                    e.values.push_default(w);
                }
            } else {
                let mut table = std::mem::take(&mut e.slot_of);
                let t = Arc::make_mut(&mut table);
                t.reserve(k);
                for _ in 0..k {
                    t.push(e.alloc_slot(1));
                }
                e.slot_of = table;
            }
        }
        Dart(first as u32)
    }

    /// Removes a dart that is free in every dimension.
    pub fn remove_dart(&mut self, d: Dart) -> Result<(), LinkError> {
        self.check_dart(d)?;
        for i in 0..=3 {
            if !self.is_free(i, d) {
                return Err(LinkError::StillLinked {
                    dart: d,
                    dim: i,
                    to: self.alpha(i, d),
                });
            }
        }
        self.alive[d.index()] = false;
        self.free_darts.push(d.0);
        self.n_alive -= 1;
        let cap = self.capacity();
        note(&mut self.log, self.version, d.0, cap);
        self.version += 1;
        for e in &mut self.embeddings {
            if !e.is_direct() {
                let s = e.slot_of[d.index()];
                e.release(s);
            }
        }
        Ok(())
    }

    /// Links `a` and `b` by `alpha_i` (both must be `i`-free; `a == b` is refused).
    ///
    /// This is the raw operation: it does not keep embeddings constant on orbits, and may
    /// break the cycle invariant. Use [`GMap::sew`] to keep the map valid.
    pub fn link(&mut self, i: usize, a: Dart, b: Dart) -> Result<(), LinkError> {
        self.check_dim(i)?;
        self.check_dart(a)?;
        self.check_dart(b)?;
        for x in [a, b] {
            if !self.is_free(i, x) || a == b {
                return Err(LinkError::NotFree {
                    dim: i,
                    a,
                    b,
                    busy: x,
                    to: self.alpha(i, x),
                });
            }
        }
        self.alpha[i][a.index()] = b.0;
        self.alpha[i][b.index()] = a.0;
        let cap = self.capacity();
        note(&mut self.log, self.version, a.0, cap);
        note(&mut self.log, self.version, b.0, cap);
        self.version += 1;
        Ok(())
    }

    /// Unlinks `a` from its `alpha_i` partner and returns the partner (raw, like [`GMap::link`]).
    pub fn unlink(&mut self, i: usize, a: Dart) -> Result<Dart, LinkError> {
        self.check_dim(i)?;
        self.check_dart(a)?;
        let b = self.alpha(i, a);
        if b == a {
            return Err(LinkError::AlreadyFree { dim: i, dart: a });
        }
        self.alpha[i][a.index()] = a.0;
        self.alpha[i][b.index()] = b.0;
        let cap = self.capacity();
        note(&mut self.log, self.version, a.0, cap);
        note(&mut self.log, self.version, b.0, cap);
        self.version += 1;
        Ok(b)
    }

    /// Visits the orbit `o` of `d` depth-first, marking with `marks`; calls `f` on each dart
    /// newly marked. Dimensions above the map's are ignored.
    pub fn visit_orbit(&self, d: Dart, o: OrbitType, marks: &mut Marks, mut f: impl FnMut(Dart)) {
        if !marks.mark(d) {
            return;
        }
        let dims: [usize; 4] = [0, 1, 2, 3];
        // the stack is this thread's, kept between walks (a walk per half-edge of a large
        // map allocated one each); a walk started from `f` takes an empty one of its own
        let mut stack = WALK_STACK
            .try_with(std::cell::Cell::take)
            .unwrap_or_default();
        stack.clear();
        stack.push(d);
        while let Some(x) = stack.pop() {
            f(x);
            for &i in &dims[..=self.dim] {
                if o.contains(i) {
                    let y = Dart(self.alpha[i][x.index()]);
                    if marks.mark(y) {
                        stack.push(y);
                    }
                }
            }
        }
        let _ = WALK_STACK.try_with(|s| s.set(stack));
    }

    /// The darts of the orbit `o` of `d`, `d` first.
    pub fn orbit(&self, d: Dart, o: OrbitType) -> Vec<Dart> {
        let mut out = Vec::new();
        with_marks(self.capacity(), |m| {
            self.visit_orbit(d, o, m, |x| out.push(x));
        });
        out
    }

    /// One dart per orbit of type `o` (the smallest index of each), in increasing order.
    pub fn orbit_representatives(&self, o: OrbitType) -> Vec<Dart> {
        let mut out = Vec::new();
        let mut m = Marks::with_capacity(self.capacity());
        for d in self.darts() {
            if !m.is_marked(d) {
                out.push(d);
                self.visit_orbit(d, o, &mut m, |_| {});
            }
        }
        out
    }

    /// The number of orbits of type `o`.
    pub fn count_orbits(&self, o: OrbitType) -> usize {
        let mut n = 0;
        let mut m = Marks::with_capacity(self.capacity());
        for d in self.darts() {
            if !m.is_marked(d) {
                n += 1;
                self.visit_orbit(d, o, &mut m, |_| {});
            }
        }
        n
    }

    /// Labels every live dart with the index of its orbit of type `o` (numbered in order of
    /// their smallest dart); removed darts get `u32::MAX`. Returns the labels and the count.
    pub fn orbit_labels(&self, o: OrbitType) -> (Vec<u32>, usize) {
        let mut label = vec![u32::MAX; self.capacity()];
        let mut n = 0u32;
        let mut m = Marks::with_capacity(self.capacity());
        for d in self.darts() {
            if !m.is_marked(d) {
                self.visit_orbit(d, o, &mut m, |x| label[x.index()] = n);
                n += 1;
            }
        }
        (label, n as usize)
    }

    /// The row of every live dart's vertex in per-vertex arrays (removed darts get
    /// `u32::MAX`), and the number of rows. Rows follow the map's `particle` embedding (i64 on
    /// the vertex orbit, written by the mesh import: the input point order, see
    /// [`crate::mesh::build`]) when it is a dense numbering (every value in `0..n` used, none
    /// negative); otherwise they are the vertex orbits numbered by their smallest dart
    /// ([`GMap::orbit_labels`]). Several orbits share a row where the import kept a pinched
    /// point as one particle.
    pub fn vertex_rows(&self) -> (Vec<u32>, usize) {
        let o = OrbitType::vertex(self.dim);
        self.particle_rows(o)
            .unwrap_or_else(|| self.orbit_labels(o))
    }

    fn particle_rows(&self, o: OrbitType) -> Option<(Vec<u32>, usize)> {
        let e = self.embedding(self.embedding_id("particle")?);
        if e.ty() != EmbeddingType::I64 || e.orbit() != o {
            return None;
        }
        let ColumnRef::Int(col) = e.column() else {
            return None;
        };
        let mut label = vec![u32::MAX; self.capacity()];
        let mut n = 0usize;
        for d in self.darts() {
            let v = u32::try_from(*col.get(e.slot(d))?)
                .ok()
                .filter(|&v| v != u32::MAX)?;
            label[d.index()] = v;
            n = n.max(v as usize + 1);
        }
        let mut used = vec![false; n];
        for d in self.darts() {
            used[label[d.index()] as usize] = true;
        }
        used.iter().all(|&u| u).then_some((label, n))
    }

    /// Counts of vertices, edges, faces, volumes, components and boundary cells.
    pub fn cell_counts(&self) -> CellCounts {
        let n = self.dim;
        let boundary = if n == 3 {
            self.orbit_representatives(OrbitType::parse("<0,1>").expect("static"))
                .into_iter()
                .filter(|&d| self.is_free(3, d))
                .count()
        } else {
            self.orbit_representatives(OrbitType::parse("<0>").expect("static"))
                .into_iter()
                .filter(|&d| self.is_free(2, d))
                .count()
        };
        CellCounts {
            darts: self.n_darts(),
            vertices: self.count_orbits(OrbitType::vertex(n)),
            edges: self.count_orbits(OrbitType::edge(n)),
            faces: self.count_orbits(OrbitType::face(n)),
            volumes: if n == 3 {
                self.count_orbits(OrbitType::volume())
            } else {
                0
            },
            components: self.count_orbits(OrbitType::all(n)),
            boundary,
        }
    }

    /// Bytes used by the topology tables (alpha links and liveness).
    pub fn topology_bytes(&self) -> usize {
        self.alpha.iter().map(|a| a.capacity() * 4).sum::<usize>()
            + self.alive.capacity()
            + self.free_darts.capacity() * 4
    }

    /// Bytes used by the topology and every embedding, a dart-to-slot table shared by
    /// several embeddings counted once.
    pub fn memory_bytes(&self) -> usize {
        self.topology_bytes()
            + self
                .embeddings
                .iter()
                .map(|e| e.memory_bytes() - e.slot_table_bytes())
                .sum::<usize>()
            + self.slot_table_bytes()
    }

    /// Bytes of the embeddings' dart-to-slot tables (4 per dart and table), each table
    /// shared by several embeddings of one orbit type counted once.
    pub fn slot_table_bytes(&self) -> usize {
        let mut seen: Vec<*const Vec<u32>> = Vec::new();
        let mut bytes = 0;
        for e in &self.embeddings {
            let p = Arc::as_ptr(&e.slot_of);
            if !seen.contains(&p) {
                seen.push(p);
                bytes += e.slot_table_bytes();
            }
        }
        bytes
    }

    // ---------------------------------------------------------------- embeddings

    fn check_name(&self, name: &str) -> Result<(), EmbeddingError> {
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(EmbeddingError::BadName(name.to_string()));
        }
        if self.embedding_id(name).is_some() {
            return Err(EmbeddingError::Duplicate(name.to_string()));
        }
        Ok(())
    }

    /// Declares an embedding on orbit type `orbit`, with a zero value on every orbit.
    pub fn add_embedding(
        &mut self,
        name: &str,
        ty: EmbeddingType,
        orbit: OrbitType,
        policy: Policy,
    ) -> Result<EmbeddingId, EmbeddingError> {
        self.check_name(name)?;
        if orbit.max_dim().is_some_and(|m| m > self.dim) {
            return Err(EmbeddingError::Dimension {
                name: name.into(),
                orbit,
                n: self.dim,
            });
        }
        if matches!(ty, EmbeddingType::Bool) && matches!(policy, Policy::Sum | Policy::Mean)
            || matches!(ty, EmbeddingType::I64) && policy == Policy::Mean
        {
            return Err(EmbeddingError::Policy {
                name: name.into(),
                policy: policy.name().into(),
                ty: ty.to_string(),
            });
        }
        let e = self.build_embedding(Embedding::new(name, ty, orbit, policy, None));
        self.embeddings.push(e);
        Ok(EmbeddingId(self.embeddings.len() as u32 - 1))
    }

    /// Declares a derived embedding on `orbit`: the aggregate of `source` over the distinct
    /// source orbits inside each orbit. The source's orbit must be a sub-orbit of `orbit`.
    /// It is computed now and by every [`GMap::refresh_derived`].
    pub fn add_derived(
        &mut self,
        name: &str,
        source: &str,
        orbit: OrbitType,
        aggregate: Aggregate,
    ) -> Result<EmbeddingId, EmbeddingError> {
        self.check_name(name)?;
        let sid = self
            .embedding_id(source)
            .ok_or_else(|| EmbeddingError::Unknown(source.into()))?;
        let src = &self.embeddings[sid.0 as usize];
        if orbit.max_dim().is_some_and(|m| m > self.dim) {
            return Err(EmbeddingError::Dimension {
                name: name.into(),
                orbit,
                n: self.dim,
            });
        }
        if !src.orbit.is_subset_of(orbit) {
            return Err(EmbeddingError::NotSubOrbit {
                name: name.into(),
                orbit,
                source_name: source.into(),
                source_orbit: src.orbit,
            });
        }
        let ty = match aggregate {
            Aggregate::Count => EmbeddingType::I64,
            Aggregate::Mean if !src.ty.is_real() => {
                return Err(EmbeddingError::Policy {
                    name: name.into(),
                    policy: "mean".into(),
                    ty: src.ty.to_string(),
                })
            }
            Aggregate::Sum if src.ty == EmbeddingType::Bool => {
                return Err(EmbeddingError::Policy {
                    name: name.into(),
                    policy: "sum".into(),
                    ty: src.ty.to_string(),
                })
            }
            _ => src.ty,
        };
        let derived = Derived {
            source: sid,
            aggregate,
        };
        let e = self.build_embedding(Embedding::new(name, ty, orbit, Policy::Copy, Some(derived)));
        self.embeddings.push(e);
        let id = EmbeddingId(self.embeddings.len() as u32 - 1);
        self.recompute(&[id]);
        Ok(id)
    }

    /// Fills the slot tables of a new embedding: one slot per orbit. Where an embedding on
    /// the same orbit type exists, the new one shares its dart-to-slot table (copy on write)
    /// and copies its use counts and free list (every embedding holds one slot per orbit of
    /// its type, so they are the new one's too) instead of walking every orbit: the
    /// embeddings of one orbit type then hold one table until a change gives one its own.
    fn build_embedding(&self, mut e: Embedding) -> Embedding {
        let w = e.ty.width();
        if e.is_direct() {
            e.values.resize_default(w, self.capacity());
            return e;
        }
        if let Some(t) = self
            .embeddings
            .iter()
            .find(|t| t.orbit == e.orbit && t.slot_of.len() == self.capacity())
        {
            e.slot_of = Arc::clone(&t.slot_of);
            e.slot_use.clone_from(&t.slot_use);
            e.free_slots.clone_from(&t.free_slots);
            e.values.resize_default(w, e.slot_use.len());
            return e;
        }
        let mut slot_of = vec![u32::MAX; self.capacity()];
        let mut m = Marks::with_capacity(self.capacity());
        // a new embedding has no slot: one per orbit, numbered in order, and the value
        // column sized once at the end (not grown slot by slot)
        debug_assert!(e.slot_use.is_empty() && e.free_slots.is_empty());
        for d in self.darts() {
            if !m.is_marked(d) {
                let s = e.slot_use.len() as u32;
                let mut k = 0;
                self.visit_orbit(d, e.orbit, &mut m, |x| {
                    slot_of[x.index()] = s;
                    k += 1;
                });
                e.slot_use.push(k);
            }
        }
        e.values.resize_default(w, e.slot_use.len());
        // Removed darts point at slot 0 (never read); keep the table dense.
        for s in &mut slot_of {
            if *s == u32::MAX {
                *s = 0;
            }
        }
        e.slot_of = Arc::new(slot_of);
        e
    }

    /// The id of the embedding named `name`.
    pub fn embedding_id(&self, name: &str) -> Option<EmbeddingId> {
        self.embeddings
            .iter()
            .position(|e| e.name == name)
            .map(|i| EmbeddingId(i as u32))
    }

    /// The id of `name`, or an error naming it.
    pub fn require(&self, name: &str) -> Result<EmbeddingId, EmbeddingError> {
        self.embedding_id(name)
            .ok_or_else(|| EmbeddingError::Unknown(name.to_string()))
    }

    /// The embedding `id`.
    pub fn embedding(&self, id: EmbeddingId) -> &Embedding {
        &self.embeddings[id.0 as usize]
    }

    /// All embeddings, in declaration order.
    pub fn embeddings(&self) -> &[Embedding] {
        &self.embeddings
    }

    fn check_live(&self, d: Dart) -> Result<(), EmbeddingError> {
        if self.is_alive(d) {
            Ok(())
        } else {
            Err(EmbeddingError::NoSuchDart(d))
        }
    }

    /// The value of embedding `id` on the orbit of `d`. A derived embedding must be fresh.
    pub fn value(&self, id: EmbeddingId, d: Dart) -> Result<Value, EmbeddingError> {
        self.check_live(d)?;
        let e = self.embedding(id);
        if e.derived.is_some() && self.is_stale(id) {
            return Err(EmbeddingError::Stale(e.name.clone()));
        }
        Ok(e.values.get(e.ty.width(), e.slot(d)))
    }

    /// The real value (scalar, vector or matrix) of `id` on `d`'s orbit, without checks of
    /// freshness: for hot paths. Panics if the type is not real.
    #[inline]
    pub fn real(&self, id: EmbeddingId, d: Dart) -> &[f64] {
        let e = &self.embeddings[id.0 as usize];
        let w = e.ty.width();
        let s = e.slot(d);
        match &e.values {
            Column::Real(v) => &v[s * w..(s + 1) * w],
            _ => panic!("embedding '{}' is not real", e.name),
        }
    }

    /// Writes `v` on the orbit of `d` (every dart of the orbit sees it).
    pub fn set_value(&mut self, id: EmbeddingId, d: Dart, v: &Value) -> Result<(), EmbeddingError> {
        self.check_live(d)?;
        let e = &mut self.embeddings[id.0 as usize];
        if e.derived.is_some() {
            return Err(EmbeddingError::Derived(e.name.clone()));
        }
        e.check_value(v)?;
        let s = e.slot(d);
        e.values.set(e.ty.width(), s, v);
        e.writes += 1;
        Ok(())
    }

    /// Writes `v` into slot `slot` of embedding `id`: the value of the orbit that owns the slot
    /// (see [`Embedding::slot`]). For engines that group their writes by slot.
    pub fn set_slot_value(
        &mut self,
        id: EmbeddingId,
        slot: usize,
        v: &Value,
    ) -> Result<(), EmbeddingError> {
        let e = &mut self.embeddings[id.0 as usize];
        if e.derived.is_some() {
            return Err(EmbeddingError::Derived(e.name.clone()));
        }
        e.check_value(v)?;
        if slot >= e.n_slots() {
            return Err(EmbeddingError::Type {
                name: e.name.clone(),
                expected: format!("a slot below {}", e.n_slots()),
                got: format!("slot {slot}"),
            });
        }
        e.values.set(e.ty.width(), slot, v);
        e.writes += 1;
        Ok(())
    }

    /// The whole value column of the stored embedding `id`, for engines that write many slots
    /// at once; counts as one write (see [`Embedding::writes`]). Refused for a derived
    /// embedding, which is recomputed, never written.
    pub fn column_mut(&mut self, id: EmbeddingId) -> Result<ColumnMut<'_>, EmbeddingError> {
        let e = &mut self.embeddings[id.0 as usize];
        if e.derived.is_some() {
            return Err(EmbeddingError::Derived(e.name.clone()));
        }
        e.writes += 1;
        Ok(match &mut e.values {
            Column::Real(v) => ColumnMut::Real(v),
            Column::Int(v) => ColumnMut::Int(v),
            Column::Bool(v) => ColumnMut::Bool(v),
        })
    }

    /// Writes every value of the stored embedding `id` at once, one value per orbit of its
    /// orbit type, orbits in the order of [`GMap::orbit_representatives`] (by smallest dart):
    /// `values` holds `width` reals per orbit (row-major) for a real type, one integer or one
    /// boolean per orbit otherwise. Counts as one write, then recomputes the stale derived
    /// embeddings ([`GMap::refresh_derived`]), so that an aggregate of `id` is up to date.
    ///
    /// Errors (nothing is written): [`EmbeddingError::Derived`] for a derived embedding,
    /// [`EmbeddingError::Type`] for values of another type or another count.
    pub fn set_orbit_values(
        &mut self,
        id: EmbeddingId,
        values: ColumnRef<'_>,
    ) -> Result<(), EmbeddingError> {
        let e = self.embedding(id);
        if e.derived.is_some() {
            return Err(EmbeddingError::Derived(e.name.clone()));
        }
        let w = e.ty.width();
        let slots: Vec<usize> = self
            .orbit_representatives(e.orbit)
            .into_iter()
            .map(|d| e.slot(d))
            .collect();
        let n = slots.len();
        let (kind, len) = match values {
            ColumnRef::Real(v) => ("reals", v.len()),
            ColumnRef::Int(v) => ("integers", v.len()),
            ColumnRef::Bool(v) => ("booleans", v.len()),
        };
        let type_ok = matches!(
            (&e.values, values),
            (Column::Real(_), ColumnRef::Real(_))
                | (Column::Int(_), ColumnRef::Int(_))
                | (Column::Bool(_), ColumnRef::Bool(_))
        );
        let want = if e.ty.is_real() { n * w } else { n };
        if !type_ok || len != want {
            return Err(EmbeddingError::Type {
                name: e.name.clone(),
                expected: format!(
                    "{} on {}: {want} {} for its {n} orbits",
                    e.ty,
                    e.orbit,
                    if e.ty.is_real() {
                        "reals"
                    } else if e.ty == EmbeddingType::I64 {
                        "integers"
                    } else {
                        "booleans"
                    }
                ),
                got: format!("{len} {kind}"),
            });
        }
        let e = &mut self.embeddings[id.0 as usize];
        match (&mut e.values, values) {
            (Column::Real(col), ColumnRef::Real(v)) => {
                for (k, &s) in slots.iter().enumerate() {
                    col[s * w..(s + 1) * w].copy_from_slice(&v[k * w..(k + 1) * w]);
                }
            }
            (Column::Int(col), ColumnRef::Int(v)) => {
                for (k, &s) in slots.iter().enumerate() {
                    col[s] = v[k];
                }
            }
            (Column::Bool(col), ColumnRef::Bool(v)) => {
                for (k, &s) in slots.iter().enumerate() {
                    col[s] = v[k];
                }
            }
            _ => unreachable!("types checked above"),
        }
        e.writes += 1;
        self.refresh_derived();
        Ok(())
    }

    /// Sets every value of the stored embedding `id` to zero (or false).
    pub fn reset_values(&mut self, id: EmbeddingId) -> Result<(), EmbeddingError> {
        let e = &mut self.embeddings[id.0 as usize];
        if e.derived.is_some() {
            return Err(EmbeddingError::Derived(e.name.clone()));
        }
        match &mut e.values {
            Column::Real(v) => v.fill(0.0),
            Column::Int(v) => v.fill(0),
            Column::Bool(v) => v.fill(false),
        }
        e.writes += 1;
        Ok(())
    }

    /// Writes a real value (scalar, vector, matrix: `width` numbers) on the orbit of `d`.
    pub fn set_real(&mut self, id: EmbeddingId, d: Dart, v: &[f64]) -> Result<(), EmbeddingError> {
        self.set_value(id, d, &Value::Real(v.to_vec()))
    }

    /// Whether the derived embedding `id` was computed before the last change of its source or
    /// of the topology (always `false` for a stored embedding).
    pub fn is_stale(&self, id: EmbeddingId) -> bool {
        let e = self.embedding(id);
        match e.derived {
            None => false,
            Some(der) => e.refreshed_at != Some((self.version, self.embedding(der.source).writes)),
        }
    }

    /// Recomputes every stale derived embedding from its source. Stale embeddings on one
    /// orbit type whose sources share an orbit type and which were refreshed last at one
    /// version are recomputed together: their orbits are found and walked once for all of
    /// them (the three edge sums of a spring model), each then aggregating its own source
    /// over the same darts in the same order, so each gets the values it would get alone.
    pub fn refresh_derived(&mut self) {
        let mut done = vec![false; self.embeddings.len()];
        for k in 0..self.embeddings.len() {
            let id = EmbeddingId(k as u32);
            if done[k] || !self.is_stale(id) {
                continue;
            }
            let key = self.refresh_key(id);
            // (one whose source is derived too stays alone, refreshed in its turn as before)
            let stored_source = |j: EmbeddingId| {
                self.embedding(j)
                    .derived
                    .is_some_and(|der| self.embedding(der.source).derived.is_none())
            };
            let group: Vec<EmbeddingId> = if stored_source(id) {
                (k..self.embeddings.len())
                    .map(|j| EmbeddingId(j as u32))
                    .filter(|&j| {
                        !done[j.0 as usize]
                            && self.is_stale(j)
                            && stored_source(j)
                            && self.refresh_key(j) == key
                    })
                    .collect()
            } else {
                vec![id]
            };
            for j in &group {
                done[j.0 as usize] = true;
            }
            self.recompute(&group);
        }
    }

    /// What decides how derived embedding `id` is refreshed (see [`GMap::refresh_derived`]):
    /// its orbit type, its source's, and the version it was refreshed at when its source was
    /// not written since (else `None`: a refresh over the whole map).
    fn refresh_key(&self, id: EmbeddingId) -> Option<(OrbitType, OrbitType, Option<u64>)> {
        let e = self.embedding(id);
        let der = e.derived?;
        let src = self.embedding(der.source);
        let at = match e.refreshed_at {
            Some((v, writes)) if writes == src.writes => Some(v),
            _ => None,
        };
        Some((e.orbit, src.orbit, at))
    }

    /// Recomputes the derived embeddings `ids`, which share a [`GMap::refresh_key`].
    fn recompute(&mut self, ids: &[EmbeddingId]) {
        let Some(Some((orbit, _, at))) = ids.first().map(|&id| self.refresh_key(id)) else {
            return;
        };
        let mut es: Vec<Embedding> = ids
            .iter()
            .map(|id| {
                std::mem::replace(
                    &mut self.embeddings[id.0 as usize],
                    Embedding::new("", EmbeddingType::F64, OrbitType::EMPTY, Policy::Copy, None),
                )
            })
            .collect();
        let mut m = Marks::with_capacity(self.capacity());
        // Only the orbits around what changed since the last refresh, when the sources were
        // not written since and the change log covers that version: an orbit of `e` holding no
        // dart whose links changed is the same orbit, on the same slot, over the same source
        // slots holding the same values, so its value stands. (A topology change re-slots and
        // recombines, and so changes the values of, only the orbits holding such a dart
        // ([`GMap::relinked_since`]); the source's orbit type is a sub-orbit of `e`'s, so a
        // source orbit holding one lies in an orbit of `e` holding it.)
        let local: Option<Vec<Dart>> = at
            .and_then(|v| self.relinked_since(v))
            .map(|changed| changed.into_iter().filter(|&c| self.is_alive(c)).collect());
        let all: Vec<Dart>;
        let starts: &[Dart] = if let Some(l) = &local {
            l
        } else {
            all = self.darts().collect();
            &all
        };
        // a local refresh walks each orbit from its smallest dart, as the full one (which
        // meets it there first): the same order of the source slots, the same sums bit for
        // bit. The orbits are walked once for all of `ids`: each one's darts in `darts`,
        // from its first dart on
        let mut walk = Marks::with_capacity(if local.is_some() { self.capacity() } else { 0 });
        let mut darts: Vec<Dart> = Vec::new();
        let mut seen: Vec<usize> = Vec::new();
        // the source slots already listed for a large orbit (a bit per slot number; small
        // orbits search `seen` instead)
        let mut listed = Marks::default();
        let mut acc: Vec<f64> = Vec::new();
        for &d in starts {
            if m.is_marked(d) {
                continue;
            }
            darts.clear();
            let d = if local.is_some() {
                // the orbit's smallest dart: the walk from it is the one the full refresh
                // makes; when `d` is that dart, this walk is it already (no dart of the
                // orbit was marked before it)
                let mut lo = d;
                self.visit_orbit(d, orbit, &mut m, |x| {
                    lo = lo.min(x);
                    darts.push(x);
                });
                if lo != d {
                    darts.clear();
                    self.visit_orbit(lo, orbit, &mut walk, |x| darts.push(x));
                }
                lo
            } else {
                self.visit_orbit(d, orbit, &mut m, |x| darts.push(x));
                d
            };
            for (e, id) in es.iter_mut().zip(ids) {
                let der = e.derived.expect("a derived embedding");
                debug_assert!(
                    der.source != *id,
                    "a derived embedding is not its own source"
                );
                let src = self.embedding(der.source);
                // the distinct source slots, in the order of the walk
                seen.clear();
                if darts.len() <= 32 {
                    for &x in &darts {
                        let s = src.slot(x);
                        if !seen.contains(&s) {
                            seen.push(s);
                        }
                    }
                } else {
                    for &x in &darts {
                        let s = src.slot(x);
                        if listed.mark(Dart(s as u32)) {
                            seen.push(s);
                        }
                    }
                    listed.clear();
                }
                let target = e.slot(d);
                match der.aggregate {
                    Aggregate::Count => {
                        e.values.set(1, target, &Value::Int(seen.len() as i64));
                    }
                    agg => {
                        let policy = if agg == Aggregate::Sum {
                            Policy::Sum
                        } else {
                            Policy::Mean
                        };
                        src.values.aggregate_to(
                            src.ty.width(),
                            policy,
                            &seen,
                            &mut e.values,
                            target,
                            &mut acc,
                        );
                    }
                }
            }
        }
        for (mut e, id) in es.into_iter().zip(ids) {
            let src = self.embedding(e.derived.expect("a derived embedding").source);
            e.refreshed_at = Some((self.version, src.writes));
            e.writes += 1;
            self.embeddings[id.0 as usize] = e;
        }
    }
}

impl Column {
    /// Writes into slot `to` of `out` the sum (`policy` [`Policy::Sum`]) or the mean
    /// ([`Policy::Mean`]) of this column's `slots`, added in their order from zero: what
    /// [`Column::merge`] of copies of them gives, bit for bit, without the copies. `out` has
    /// this column's kind and `width`; `acc` is scratch.
    pub(crate) fn aggregate_to(
        &self,
        width: usize,
        policy: Policy,
        slots: &[usize],
        out: &mut Column,
        to: usize,
        acc: &mut Vec<f64>,
    ) {
        debug_assert!(matches!(policy, Policy::Sum | Policy::Mean));
        match (self, out) {
            (Column::Real(v), Column::Real(o)) => {
                acc.clear();
                acc.resize(width, 0.0);
                for &s in slots {
                    for (a, x) in acc.iter_mut().zip(&v[s * width..(s + 1) * width]) {
                        *a += x;
                    }
                }
                if policy == Policy::Mean {
                    for a in acc.iter_mut() {
                        *a /= slots.len() as f64;
                    }
                }
                o[to * width..(to + 1) * width].copy_from_slice(acc);
            }
            (Column::Int(v), Column::Int(o)) => {
                o[to] = slots.iter().map(|&s| v[s]).fold(0i64, i64::wrapping_add);
            }
            (Column::Bool(v), Column::Bool(o)) => o[to] = slots.iter().any(|&s| v[s]),
            _ => unreachable!("a derived embedding has its source's type"),
        }
    }

    /// A new column holding copies of `slots`, in order.
    pub(crate) fn clone_slots(&self, width: usize, slots: &[usize]) -> Column {
        match self {
            Column::Real(v) => Column::Real(
                slots
                    .iter()
                    .flat_map(|&s| v[s * width..(s + 1) * width].iter().copied())
                    .collect(),
            ),
            Column::Int(v) => Column::Int(slots.iter().map(|&s| v[s]).collect()),
            Column::Bool(v) => Column::Bool(slots.iter().map(|&s| v[s]).collect()),
        }
    }
}
