//! Batch rewiring: the primitive under rule application.
//!
//! A rule rewrites many links at once, creates darts and deletes others. [`GMap::rewire`]
//! applies such a batch atomically: it checks that the result keeps every alpha an
//! involution, applies it, removes the deleted darts, then gives every embedding one slot per
//! new orbit around the changed darts, combining old values by each embedding's
//! [`Policy`](crate::Policy). Values on orbits made only of new darts start at zero: the
//! caller writes them.

use std::collections::HashMap;

use crate::embedding::{Column, ColumnRef, EmbeddingType, Policy, Value};
use crate::marks::Marks;
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

impl GMap {
    /// Applies `changes` (`alpha_dim(a) := b`, both directions must be listed or already hold),
    /// then removes `remove` (each must end up free in every dimension), then re-slots the
    /// embeddings around the changed darts. `fresh` lists darts created by the caller just
    /// before: their (default) values do not take part in merges.
    pub fn rewire(
        &mut self,
        changes: &[(usize, Dart, Dart)],
        fresh: &[Dart],
        remove: &[Dart],
    ) -> Result<(), RewireError> {
        if changes.is_empty() && fresh.is_empty() && remove.is_empty() {
            return Ok(()); // nothing changes: the version stays, caches stay valid
        }
        let mut new: HashMap<(usize, u32), u32> = HashMap::with_capacity(changes.len());
        for &(i, a, b) in changes {
            self.check_dim(i)?;
            self.check_dart(a)?;
            self.check_dart(b)?;
            new.insert((i, a.0), b.0);
        }
        let after = |i: usize, x: u32| {
            new.get(&(i, x))
                .copied()
                .unwrap_or(self.alpha[i][x as usize])
        };
        // every dart whose link changes, and its old partner, must be in an involution after
        for &(i, a, _) in changes {
            for x in [a.0, self.alpha[i][a.index()]] {
                let y = after(i, x);
                let back = after(i, y);
                if back != x {
                    return Err(RewireError::NotInvolution {
                        dim: i,
                        a: Dart(x),
                        b: Dart(y),
                        back: Dart(back),
                    });
                }
            }
        }
        for &d in remove {
            self.check_dart(d)?;
            for i in 0..=3 {
                if after(i, d.0) != d.0 {
                    return Err(RewireError::RemovedLinked { dart: d, dim: i });
                }
            }
        }
        let old: Vec<(usize, u32, u32)> = new
            .keys()
            .map(|&(i, a)| (i, a, self.alpha[i][a as usize]))
            .collect();
        for (&(i, a), &b) in &new {
            self.alpha[i][a as usize] = b;
        }
        self.version += 1;
        let mut seeds: Vec<Dart> = new.keys().map(|&(_, a)| Dart(a)).collect();
        seeds.extend(old.iter().map(|&(_, _, b)| Dart(b)));
        seeds.extend_from_slice(fresh);
        let mut removed = Marks::with_capacity(self.capacity());
        for &d in remove {
            removed.mark(d);
        }
        seeds.retain(|d| !removed.is_marked(*d));
        let mut is_fresh = Marks::with_capacity(self.capacity());
        for &d in fresh {
            is_fresh.mark(d);
        }
        let dims: Vec<usize> = {
            let mut v: Vec<usize> = new.keys().map(|&(i, _)| i).collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        // plan every embedding first, so a refusal leaves everything as it was
        let mut plans = Vec::new();
        for k in 0..self.embeddings.len() {
            let e = &self.embeddings[k];
            if e.is_direct() || (!dims.iter().any(|&i| e.orbit.contains(i)) && fresh.is_empty()) {
                plans.push(None);
                continue;
            }
            match self.plan_reslot(k, &seeds, &removed, &is_fresh) {
                Ok(p) => plans.push(Some(p)),
                Err(err) => {
                    for &(i, a, b) in &old {
                        self.alpha[i][a as usize] = b;
                    }
                    self.version += 1;
                    return Err(err);
                }
            }
        }
        for (k, plan) in plans.into_iter().enumerate() {
            if let Some(p) = plan {
                self.apply_reslot(k, p);
            }
        }
        self.number_fresh_vertices(fresh, &removed);
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
    fn number_fresh_vertices(&mut self, fresh: &[Dart], removed: &Marks) {
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
        let mut is_fresh = Marks::with_capacity(self.capacity());
        for &d in fresh {
            is_fresh.mark(d);
        }
        let mut seen = Marks::with_capacity(self.capacity());
        let mut created = Vec::new();
        for &d in fresh {
            if seen.is_marked(d) || removed.is_marked(d) || !self.is_alive(d) {
                continue;
            }
            let mut all_fresh = true;
            self.visit_orbit(d, o, &mut seen, |x| all_fresh &= is_fresh.is_marked(x));
            if all_fresh {
                created.push(d);
            }
        }
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

    /// The new orbits of embedding `k` around `seeds`, with the old slots each one covers.
    fn plan_reslot(
        &self,
        k: usize,
        seeds: &[Dart],
        removed: &Marks,
        fresh: &Marks,
    ) -> Result<Reslot, RewireError> {
        let e = &self.embeddings[k];
        let mut m = Marks::with_capacity(self.capacity());
        let mut orbits: Vec<(Vec<Dart>, Vec<usize>)> = Vec::new();
        let mut parts: HashMap<usize, usize> = HashMap::new();
        for &sd in seeds {
            if m.is_marked(sd) {
                continue;
            }
            let mut darts = Vec::new();
            self.visit_orbit(sd, e.orbit, &mut m, |d| darts.push(d));
            let mut slots: Vec<usize> = Vec::new();
            for &d in &darts {
                if removed.is_marked(d) || fresh.is_marked(d) {
                    continue;
                }
                let s = e.slot(d);
                if !slots.contains(&s) {
                    slots.push(s);
                }
            }
            for &s in &slots {
                *parts.entry(s).or_insert(0) += 1;
            }
            orbits.push((darts, slots));
        }
        if e.policy == Policy::Error && e.derived.is_none() {
            let w = e.ty.width();
            for (darts, slots) in &orbits {
                if slots.iter().any(|&s| !e.values.slots_equal(w, slots[0], s)) {
                    return Err(RewireError::Policy {
                        embedding: e.name.clone(),
                        dart: darts[0],
                        what: "merge",
                    });
                }
                if slots.iter().any(|s| parts[s] > 1) {
                    return Err(RewireError::Policy {
                        embedding: e.name.clone(),
                        dart: darts[0],
                        what: "split",
                    });
                }
            }
        }
        Ok(Reslot { orbits, parts })
    }

    fn apply_reslot(&mut self, k: usize, plan: Reslot) {
        let e = &mut self.embeddings[k];
        let w = e.ty.width();
        let policy = if e.derived.is_some() {
            Policy::Copy
        } else {
            e.policy
        };
        // values are combined from a snapshot of the old slots
        let olds: Vec<usize> = plan.parts.keys().copied().collect();
        let snapshot = e.values.clone_slots(w, &olds);
        let at = |s: usize| olds.iter().position(|&x| x == s).expect("planned");
        let mut reused: HashMap<usize, bool> = HashMap::new();
        let mut emptied: Vec<usize> = Vec::new();
        for (darts, slots) in plan.orbits {
            let target = if let Some(&s) = slots.iter().find(|s| !reused.contains_key(s)) {
                reused.insert(s, true);
                s
            } else {
                e.alloc_slot(0) as usize
            };
            if slots.is_empty() {
                let zero = match &e.values {
                    Column::Real(_) => crate::Value::Real(vec![0.0; w]),
                    Column::Int(_) => crate::Value::Int(0),
                    Column::Bool(_) => crate::Value::Bool(false),
                };
                e.values.set(w, target, &zero);
            } else {
                let mut scratch =
                    snapshot.clone_slots(w, &slots.iter().map(|&s| at(s)).collect::<Vec<_>>());
                if policy == Policy::Sum {
                    for (q, s) in slots.iter().enumerate() {
                        let parts = plan.parts[s];
                        if parts > 1 {
                            scratch.scale(w, q, parts);
                        }
                    }
                }
                let idx: Vec<usize> = (0..slots.len()).collect();
                scratch.merge(w, policy, &idx, 0);
                e.values.set(w, target, &scratch.get(w, 0));
            }
            for &d in &darts {
                let s = e.slot_of[d.index()] as usize;
                if s != target {
                    e.slot_use[s] -= 1;
                    if e.slot_use[s] == 0 {
                        emptied.push(s);
                    }
                    e.slot_use[target] += 1;
                    e.slot_of[d.index()] = target as u32;
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

struct Reslot {
    /// Each new orbit: its darts and the distinct old slots among its old darts.
    orbits: Vec<(Vec<Dart>, Vec<usize>)>,
    /// Old slot -> number of new orbits covering it.
    parts: HashMap<usize, usize>,
}

impl Column {
    /// Divides slot `q` by `parts` (a share of a split sum); integers take the floor share.
    pub(crate) fn scale(&mut self, width: usize, q: usize, parts: usize) {
        match self {
            Column::Real(v) => {
                for x in &mut v[q * width..(q + 1) * width] {
                    *x /= parts as f64;
                }
            }
            Column::Int(v) => v[q] /= parts as i64,
            Column::Bool(_) => {}
        }
    }
}
