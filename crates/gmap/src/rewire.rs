//! Batch rewiring: the primitive under rule application.
//!
//! A rule rewrites many links at once, creates darts and deletes others. [`GMap::rewire`]
//! applies such a batch atomically: it checks that the result keeps every alpha an
//! involution, applies it, removes the deleted darts, then gives every embedding one slot per
//! new orbit around the changed darts, combining old values by each embedding's
//! [`Policy`](crate::Policy). Values on orbits made only of new darts start at zero: the
//! caller writes them.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::Arc;

use crate::embedding::{Column, ColumnRef, EmbeddingType, Policy, Value};
use crate::marks::{with_marks, Marks};
use crate::{Dart, GMap, LinkError, OrbitType};

/// Why a batch was refused; the map is left unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RewireError {
    /// A dart or dimension out of range.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The batch would leave `alpha_dim` not an involution.
    #[error("the rewrite would break alpha{dim}: {a} -> {b} but {b} -> {back}")]
    NotInvolution {
        /// Dimension.
        dim: usize,
        /// The dart.
        a: Dart,
        /// Its new partner.
        b: Dart,
        /// The partner's partner.
        back: Dart,
    },
    /// A dart to remove would still be linked.
    #[error("dart {dart} is removed but stays linked by alpha{dim}")]
    RemovedLinked {
        /// The dart.
        dart: Dart,
        /// Dimension.
        dim: usize,
    },
    /// The caller's interrupt check asked to stop ([`GMap::rewire_interruptible`]).
    #[error("interrupted while rewriting the topology")]
    Interrupted,
    /// An embedding with the `error` policy would merge different values or split.
    #[error("embedding '{embedding}' has policy 'error' and the rewrite would {what} its orbit at {dart}")]
    Policy {
        /// The embedding.
        embedding: String,
        /// A dart of the orbit.
        dart: Dart,
        /// `merge` or `split`.
        what: &'static str,
    },
}

/// [`GMap::rewire_interruptible`] calls its interrupt check once per this many links checked
/// or orbits planned.
pub const REWIRE_CHECK_EVERY: usize = 1024;

/// The caller's interrupt check, called once per [`REWIRE_CHECK_EVERY`] units of work.
struct Poll<'a> {
    interrupt: &'a dyn Fn() -> bool,
    work: usize,
}

impl Poll<'_> {
    /// Counts `n` units of work; true when the check was due and asks to stop.
    fn tick(&mut self, n: usize) -> bool {
        self.work += n;
        if self.work < REWIRE_CHECK_EVERY {
            return false;
        }
        self.work = 0;
        (self.interrupt)()
    }
}

impl GMap {
    /// Applies `changes` (`alpha_dim(a) := b`, both directions must be listed or already hold),
    /// then removes `remove` (each must end up free in every dimension), then re-slots the
    /// embeddings around the changed darts. `fresh` lists darts created by the caller just
    /// before: their (default) values do not take part in merges.
    ///
    /// Cost: proportional to the batch and to the orbits it touches (times the number of
    /// embeddings), not to the map.
    ///
    /// # Errors
    /// [`RewireError`] when the batch is refused; the map is then left unchanged.
    pub fn rewire(
        &mut self,
        changes: &[(usize, Dart, Dart)],
        fresh: &[Dart],
        remove: &[Dart],
    ) -> Result<(), RewireError> {
        self.rewire_interruptible(changes, fresh, remove, &|| false)
    }

    /// [`GMap::rewire`], calling `interrupt` once per [`REWIRE_CHECK_EVERY`] links checked or
    /// orbits planned, up to the point where the map starts to change for good (every check
    /// passed, every embedding planned; what follows costs about as much as one planning
    /// pass). When it returns true the call stops with [`RewireError::Interrupted`] and the
    /// map is left as it was (links, slots, values and version).
    ///
    /// # Errors
    /// [`RewireError::Interrupted`], or any error of [`GMap::rewire`].
    pub fn rewire_interruptible(
        &mut self,
        changes: &[(usize, Dart, Dart)],
        fresh: &[Dart],
        remove: &[Dart],
        interrupt: &dyn Fn() -> bool,
    ) -> Result<(), RewireError> {
        let mut poll = Poll { interrupt, work: 0 };
        if changes.is_empty() && fresh.is_empty() && remove.is_empty() {
            return Ok(()); // nothing changes: the version stays, caches stay valid
        }
        for &(i, a, b) in changes {
            if poll.tick(1) {
                return Err(RewireError::Interrupted);
            }
            self.check_dim(i)?;
            self.check_dart(a)?;
            self.check_dart(b)?;
        }
        for &d in remove {
            self.check_dart(d)?;
        }
        // apply the links in order (a later change of the same link wins), remembering each
        // overwritten value: undone in reverse order, they give back the map as it was
        // (a change that sets a link to what it is already is no change: left out, so that it
        // neither re-slots the embeddings of its dimension nor counts as changed)
        let mut old: Vec<(usize, u32, u32)> = Vec::with_capacity(changes.len());
        for &(i, a, b) in changes {
            let slot = &mut self.alpha[i][a.index()];
            if *slot != b.0 {
                old.push((i, a.0, *slot));
                *slot = b.0;
            }
        }
        if old.is_empty() && fresh.is_empty() && remove.is_empty() {
            return Ok(()); // no link changes: the version stays
        }
        // every dart whose link changed, and each of its earlier partners, must be in an
        // involution now: that covers every dart whose link or whose partner's link changed
        let mut broken = None;
        'check: for &(i, a, prev) in &old {
            if poll.tick(1) {
                broken = Some(RewireError::Interrupted);
                break 'check;
            }
            for x in [a, prev] {
                let y = self.alpha[i][x as usize];
                let back = self.alpha[i][y as usize];
                if back != x {
                    broken = Some(RewireError::NotInvolution {
                        dim: i,
                        a: Dart(x),
                        b: Dart(y),
                        back: Dart(back),
                    });
                    break 'check;
                }
            }
        }
        if broken.is_none() {
            'removed: for &d in remove {
                for i in 0..=3 {
                    if self.alpha[i][d.index()] != d.0 {
                        broken = Some(RewireError::RemovedLinked { dart: d, dim: i });
                        break 'removed;
                    }
                }
            }
        }
        if let Some(err) = broken {
            self.undo_links(&old);
            return Err(err);
        }
        let cap = self.capacity();
        with_marks(cap, |removed| {
            with_marks(cap, |is_fresh| {
                self.reslot_all(&old, fresh, remove, removed, is_fresh, &mut poll)
            })
        })
    }

    /// The second half of [`GMap::rewire`], on the new links (`old` holds the previous ones):
    /// re-slots every embedding around the changed darts, numbers the fresh vertices, removes `remove`.
    fn reslot_all(
        &mut self,
        old: &[(usize, u32, u32)],
        fresh: &[Dart],
        remove: &[Dart],
        removed: &mut Marks,
        is_fresh: &mut Marks,
        poll: &mut Poll<'_>,
    ) -> Result<(), RewireError> {
        for &d in remove {
            removed.mark(d);
        }
        // the orbits to re-slot: around every dart whose link changed, its earlier partners,
        // and the fresh darts
        let mut seeds: Vec<Dart> = Vec::with_capacity(2 * old.len() + fresh.len());
        for &(_, a, prev) in old {
            seeds.push(Dart(a));
            seeds.push(Dart(prev));
        }
        seeds.extend_from_slice(fresh);
        seeds.retain(|d| !removed.is_marked(*d));
        for &d in fresh {
            is_fresh.mark(d);
        }
        let mut dims = [false; 4];
        for &(i, _, _) in old {
            dims[i] = true;
        }
        // plan every embedding first, so a refusal leaves everything as it was; the new
        // orbits around the seeds are walked once per orbit type, for all its embeddings
        let mut plans: Vec<Option<std::rc::Rc<Reslot>>> = Vec::new();
        let mut walks: Vec<(OrbitType, Walk)> = Vec::new();
        // Per embedding, the earlier one it re-slots with (its *leader*): embeddings that
        // share one dart-to-slot table and have the same slot bookkeeping (use counts, free
        // list) get the same plan and the same new table, so the plan is made once and the
        // table stays shared (see `apply_group`)
        let mut leader: Vec<Option<usize>> = vec![None; self.embeddings.len()];
        for k in 0..self.embeddings.len() {
            let e = &self.embeddings[k];
            if e.is_direct()
                || (!(0..4).any(|i| dims[i] && e.orbit.contains(i)) && fresh.is_empty())
            {
                plans.push(None);
                continue;
            }
            let same = (0..k).find(|&j| {
                leader[j].is_none()
                    && plans[j].is_some()
                    && self.embeddings[j].shares_slot_table(e)
                    && self.embeddings[j].slot_use == e.slot_use
                    && self.embeddings[j].free_slots == e.free_slots
            });
            if let Some(j) = same {
                let p = std::rc::Rc::clone(plans[j].as_ref().expect("a leader has a plan"));
                if let Err(err) = self.check_policy(k, &p) {
                    self.undo_links(old);
                    return Err(err);
                }
                leader[k] = Some(j);
                plans.push(Some(p));
                continue;
            }
            let o = e.orbit;
            let w = match walks.iter().position(|(t, _)| *t == o) {
                Some(w) => w,
                None => match self.walk(o, &seeds, poll) {
                    Ok(w) => {
                        walks.push((o, w));
                        walks.len() - 1
                    }
                    Err(err) => {
                        self.undo_links(old);
                        return Err(err);
                    }
                },
            };
            match self.plan_reslot(k, &walks[w].1, removed, is_fresh) {
                Ok(p) => plans.push(Some(std::rc::Rc::new(p))),
                Err(err) => {
                    self.undo_links(old);
                    return Err(err);
                }
            }
        }
        // from here on the map changes for good
        let cap = self.capacity();
        for &(_, a, prev) in old {
            crate::gmap::note(&mut self.log, self.version, a, cap);
            crate::gmap::note(&mut self.log, self.version, prev, cap);
        }
        for d in fresh.iter().chain(remove) {
            crate::gmap::note(&mut self.log, self.version, d.0, cap);
        }
        self.version += 1;
        for k in 0..plans.len() {
            let Some(p) = &plans[k] else { continue };
            if leader[k].is_some() {
                continue; // re-slotted with its leader
            }
            let group: Vec<usize> = (k + 1..plans.len())
                .filter(|&f| leader[f] == Some(k))
                .collect();
            self.apply_group(k, &group, p);
        }
        self.number_fresh_vertices(fresh, removed, is_fresh);
        for &d in remove {
            let iu = d.index();
            self.alive[iu] = false;
            self.free_darts.push(d.0);
            self.n_alive -= 1;
            for e in &mut self.embeddings {
                if !e.is_direct() {
                    let s = e.slot_of[iu];
                    e.release(s);
                }
            }
        }
        Ok(())
    }

    /// Gives the vertex orbits made only of `fresh` darts (vertices a rule created) their own
    /// row in the map's vertex numbering, when the map has one (the `particle` and `point_id`
    /// embeddings of [`crate::mesh::build`]): `particle` the next row after every row in use,
    /// `point_id` -1 (no input point). Without this they would hold the default 0 and read as
    /// a copy of row 0. Orbits that also hold older darts keep their value (copy policy).
    fn number_fresh_vertices(&mut self, fresh: &[Dart], removed: &Marks, is_fresh: &Marks) {
        if fresh.is_empty() {
            return;
        }
        let o = OrbitType::vertex(self.dim);
        let numbering = |name: &str| {
            self.embedding_id(name).filter(|&id| {
                let e = self.embedding(id);
                e.ty() == EmbeddingType::I64 && e.orbit() == o
            })
        };
        let (particle, point_id) = (numbering("particle"), numbering("point_id"));
        if particle.is_none() && point_id.is_none() {
            return;
        }
        let mut created = Vec::new();
        with_marks(self.capacity(), |seen| {
            for &d in fresh {
                if seen.is_marked(d) || removed.is_marked(d) || !self.is_alive(d) {
                    continue;
                }
                let mut all_fresh = true;
                self.visit_orbit(d, o, seen, |x| all_fresh &= is_fresh.is_marked(x));
                if all_fresh {
                    created.push(d);
                }
            }
        });
        if created.is_empty() {
            return;
        }
        let mut next = 0i64;
        if let Some(id) = particle {
            let e = self.embedding(id);
            if let ColumnRef::Int(col) = e.column() {
                for d in self.darts() {
                    if !is_fresh.is_marked(d) {
                        next = next.max(col[e.slot(d)] + 1);
                    }
                }
            }
        }
        for d in created {
            if let Some(id) = particle {
                self.set_value(id, d, &Value::Int(next))
                    .expect("an i64 embedding takes an integer");
                next += 1;
            }
            if let Some(id) = point_id {
                self.set_value(id, d, &Value::Int(-1))
                    .expect("an i64 embedding takes an integer");
            }
        }
    }

    /// Puts back the links `old` recorded (`(dim, dart, previous partner)`), last first.
    fn undo_links(&mut self, old: &[(usize, u32, u32)]) {
        for &(i, a, b) in old.iter().rev() {
            self.alpha[i][a as usize] = b;
        }
    }

    /// The orbits of type `o` (on the new links) around `seeds`, each once. Costs their size,
    /// not the map's.
    fn walk(&self, o: OrbitType, seeds: &[Dart], poll: &mut Poll<'_>) -> Result<Walk, RewireError> {
        with_marks(self.capacity(), |m| {
            let mut w = Walk::default();
            for &sd in seeds {
                if m.is_marked(sd) {
                    continue;
                }
                if poll.tick(1) {
                    return Err(RewireError::Interrupted);
                }
                let first = w.darts.len();
                self.visit_orbit(sd, o, m, |d| w.darts.push(d));
                w.orbits.push(first..w.darts.len());
            }
            Ok(w)
        })
    }

    /// The new orbits of embedding `k` (those of `walk`, of its orbit type), with the old
    /// slots each one covers: one hash lookup per old dart.
    fn plan_reslot(
        &self,
        k: usize,
        walk: &Walk,
        removed: &Marks,
        fresh: &Marks,
    ) -> Result<Reslot, RewireError> {
        let e = &self.embeddings[k];
        let mut plan = Reslot::default();
        // old slot -> its index in `plan.olds`
        let mut index: SlotMap = SlotMap::default();
        plan.darts.extend_from_slice(&walk.darts);
        for range in &walk.orbits {
            let first_slot = plan.slots.len();
            for &d in &walk.darts[range.clone()] {
                if removed.is_marked(d) || fresh.is_marked(d) {
                    continue;
                }
                let s = e.slot(d);
                let q = *index.entry(s).or_insert_with(|| {
                    plan.olds.push(s);
                    plan.parts.push(0);
                    plan.olds.len() - 1
                });
                if !plan.slots[first_slot..].contains(&q) {
                    plan.slots.push(q);
                    plan.parts[q] += 1;
                }
            }
            plan.orbits.push(Orbit {
                darts: range.clone(),
                slots: first_slot..plan.slots.len(),
            });
        }
        self.check_policy(k, &plan)?;
        Ok(plan)
    }

    /// Refuses a plan that would merge different values or split an orbit of embedding
    /// `k` when its policy is [`Policy::Error`] (a stored embedding).
    fn check_policy(&self, k: usize, plan: &Reslot) -> Result<(), RewireError> {
        let e = &self.embeddings[k];
        if e.policy == Policy::Error && e.derived.is_none() {
            let w = e.ty.width();
            for o in &plan.orbits {
                let slots = &plan.slots[o.slots.clone()];
                let dart = plan.darts[o.darts.start];
                let s0 = slots.first().map(|&q| plan.olds[q]);
                if slots
                    .iter()
                    .any(|&q| !e.values.slots_equal(w, s0.unwrap_or(0), plan.olds[q]))
                {
                    return Err(RewireError::Policy {
                        embedding: e.name.clone(),
                        dart,
                        what: "merge",
                    });
                }
                if slots.iter().any(|&q| plan.parts[q] > 1) {
                    return Err(RewireError::Policy {
                        embedding: e.name.clone(),
                        dart,
                        what: "split",
                    });
                }
            }
        }
        Ok(())
    }

    /// Applies `plan` to embedding `k` and to the embeddings of `followers`, which share
    /// its dart-to-slot table and its slot bookkeeping (see `reslot_all`): `k` first, which
    /// writes the table (copying it only when something outside these embeddings holds it,
    /// a clone of the map), then each follower's values at the slots `k` chose, after which
    /// it takes `k`'s table and a copy of its bookkeeping. Each one ends as
    /// [`GMap::apply_reslot`] alone would leave it: the same state before and the same plan
    /// give the same slots (tested against unshared tables in `tests/change_log.rs`).
    fn apply_group(&mut self, k: usize, followers: &[usize], plan: &Reslot) {
        // the followers let go of the table, so that the leader's writes need no copy
        for &f in followers {
            self.embeddings[f].slot_of = Arc::default();
        }
        let mut targets = Vec::with_capacity(plan.orbits.len());
        let mut touched = Vec::new();
        self.apply_reslot(k, plan, None, &mut targets, &mut touched);
        for &f in followers {
            // the follower's use counts were the leader's (see `reslot_all`): only those of
            // the slots the leader's re-slotting touched, and those it appended, change
            let (table, free, n) = {
                let e = &self.embeddings[k];
                (
                    Arc::clone(&e.slot_of),
                    e.free_slots.clone(),
                    e.slot_use.len(),
                )
            };
            let (lead, e) = pick2(&mut self.embeddings, k, f);
            e.slot_of = table;
            e.slot_use.resize(n, 0);
            for &t in &touched {
                e.slot_use[t] = lead.slot_use[t];
            }
            debug_assert_eq!(e.slot_use, lead.slot_use, "a follower's use counts");
            e.free_slots = free;
            let w = e.ty.width();
            while e.n_slots() < e.slot_use.len() {
                e.values.push_default(w);
            }
            self.apply_reslot(f, plan, Some(&targets), &mut Vec::new(), &mut Vec::new());
        }
    }

    /// `given`: the slot of each new orbit, chosen already (for a follower of
    /// [`GMap::apply_group`], whose table and bookkeeping its leader updated): then only the
    /// values are written. Otherwise the slot chosen for each new orbit is appended to
    /// `targets`, and every slot whose use count changed to `touched` (some more than once).
    fn apply_reslot(
        &mut self,
        k: usize,
        plan: &Reslot,
        given: Option<&[usize]>,
        targets: &mut Vec<usize>,
        touched: &mut Vec<usize>,
    ) {
        let cap = self.capacity();
        let e = &mut self.embeddings[k];
        let w = e.ty.width();
        let policy = if e.derived.is_some() {
            Policy::Copy
        } else {
            e.policy
        };
        // values are combined from a snapshot of the old slots: old slot `plan.olds[q]` is
        // row `q` of the snapshot
        let snapshot = e.values.clone_slots(w, &plan.olds);
        let mut reused = vec![false; plan.olds.len()];
        let mut emptied: Vec<usize> = Vec::new();
        let mut acc: Vec<f64> = Vec::new();
        for (oi, o) in plan.orbits.iter().enumerate() {
            let slots = &plan.slots[o.slots.clone()];
            let target = if let Some(t) = given {
                t[oi]
            } else if let Some(&q) = slots.iter().find(|&&q| !reused[q]) {
                reused[q] = true;
                plan.olds[q]
            } else {
                let s = e.alloc_slot(0) as usize;
                touched.push(s);
                s
            };
            targets.push(target);
            e.values
                .combine(w, policy, &snapshot, slots, &plan.parts, target, &mut acc);
            if given.is_some() {
                continue;
            }
            for &d in &plan.darts[o.darts.clone()] {
                let s = e.slot_of[d.index()] as usize;
                if s != target {
                    crate::gmap::note_slot(&mut self.log, self.version, d.0, cap);
                    e.slot_use[s] -= 1;
                    if e.slot_use[s] == 0 {
                        emptied.push(s);
                    }
                    e.slot_use[target] += 1;
                    touched.push(s);
                    touched.push(target);
                    Arc::make_mut(&mut e.slot_of)[d.index()] = target as u32;
                }
            }
        }
        for s in emptied {
            if e.slot_use[s] == 0 {
                e.free_slots.push(s as u32);
            }
        }
    }
}

/// Mutable borrows of two distinct entries of `v`.
fn pick2<T>(v: &mut [T], a: usize, b: usize) -> (&mut T, &mut T) {
    assert_ne!(a, b, "two distinct entries");
    if a < b {
        let (x, y) = v.split_at_mut(b);
        (&mut x[a], &mut y[0])
    } else {
        let (x, y) = v.split_at_mut(a);
        (&mut y[0], &mut x[b])
    }
}

/// One new orbit of a [`Reslot`]: ranges into its `darts` and `slots`.
struct Orbit {
    darts: std::ops::Range<usize>,
    slots: std::ops::Range<usize>,
}

/// The orbits of one type around the changed darts (see [`GMap::walk`]): their darts one
/// after the other, and each orbit's range.
#[derive(Default)]
struct Walk {
    darts: Vec<Dart>,
    orbits: Vec<std::ops::Range<usize>>,
}

/// The plan of one embedding's re-slotting, in flat arrays (no allocation per orbit).
#[derive(Default)]
struct Reslot {
    /// Each new orbit.
    orbits: Vec<Orbit>,
    /// The darts of every new orbit, one after the other.
    darts: Vec<Dart>,
    /// The distinct old slots among each new orbit's old darts, as indices into `olds`.
    slots: Vec<usize>,
    /// The old slots taking part, each once.
    olds: Vec<usize>,
    /// For each entry of `olds`: the number of new orbits covering it.
    parts: Vec<usize>,
}

/// A multiplicative hash for slot numbers (the default `SipHash` costs more than the rest of
/// a re-slotting); keys are slot indices, not adversarial input.
#[derive(Default, Clone, Copy)]
struct SlotHasher(u64);

impl Hasher for SlotHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u64(&mut self, n: u64) {
        self.0 = (self.0.rotate_left(5) ^ n).wrapping_mul(0x517c_c1b7_2722_0a95);
    }

    fn write_usize(&mut self, n: usize) {
        self.write_u64(n as u64);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

type SlotMap = HashMap<usize, usize, BuildHasherDefault<SlotHasher>>;

impl Column {
    /// Writes into slot `to` the value of a new orbit covering the rows `rows` of `snapshot`
    /// (the old slots' values) under `policy`: zero without rows; the first row's value for
    /// [`Policy::Copy`] and [`Policy::Error`]; else their sum or mean, added in order from
    /// zero, a row covered by `parts[q] > 1` new orbits taking its share under
    /// [`Policy::Sum`] (its value divided by `parts[q]`). What scaling copies of the rows and merging
    /// them ([`Column::merge`]) gives, bit for bit, without the copies; `acc` is scratch.
    #[allow(clippy::too_many_arguments)]
    fn combine(
        &mut self,
        width: usize,
        policy: Policy,
        snapshot: &Column,
        rows: &[usize],
        parts: &[usize],
        to: usize,
        acc: &mut Vec<f64>,
    ) {
        let copy = matches!(policy, Policy::Copy | Policy::Error);
        let share = |q: usize| if policy == Policy::Sum { parts[q] } else { 1 };
        match (self, snapshot) {
            (Column::Real(o), Column::Real(v)) => {
                acc.clear();
                acc.resize(width, 0.0);
                if let (true, Some(&q)) = (copy, rows.first()) {
                    acc.copy_from_slice(&v[q * width..(q + 1) * width]);
                } else if !copy {
                    for &q in rows {
                        let n = share(q);
                        for (a, &x) in acc.iter_mut().zip(&v[q * width..(q + 1) * width]) {
                            *a += if n > 1 { x / n as f64 } else { x };
                        }
                    }
                    if policy == Policy::Mean && !rows.is_empty() {
                        for a in acc.iter_mut() {
                            *a /= rows.len() as f64;
                        }
                    }
                }
                o[to * width..(to + 1) * width].copy_from_slice(acc);
            }
            (Column::Int(o), Column::Int(v)) => {
                o[to] = match (copy, rows.first()) {
                    (_, None) => 0,
                    (true, Some(&q)) => v[q],
                    (false, _) => rows
                        .iter()
                        .map(|&q| {
                            let n = share(q);
                            if n > 1 {
                                v[q] / n as i64
                            } else {
                                v[q]
                            }
                        })
                        .fold(0i64, i64::wrapping_add),
                };
            }
            (Column::Bool(o), Column::Bool(v)) => {
                o[to] = match (copy, rows.first()) {
                    (_, None) => false,
                    (true, Some(&q)) => v[q],
                    (false, _) => rows.iter().any(|&q| v[q]),
                };
            }
            _ => unreachable!("a snapshot of the column itself"),
        }
    }
}
