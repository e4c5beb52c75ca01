//! `sew` and `unsew`: linking and unlinking whole orbits so the map stays valid.
//!
//! An `i`-sew of darts `a` and `b` links, by `alpha_i`, every dart of the orbit
//! `<{0..n} \ {i-1, i, i+1}>` of `a` to the corresponding dart of the same orbit of `b`,
//! found by walking both orbits in parallel. The two orbits must have the same shape and be
//! `i`-free; then `alpha_i o alpha_j` stays an involution for every `|i - j| >= 2`.
//!
//! ```text
//!  2-sew in a 2-map: the orbit <0> (the half-edge) of each side
//!
//!   a ---0--- a'            a ---0--- a'
//!                   ==>     |2        |2
//!   b ---0--- b'            b ---0--- b'
//! ```
//!
//! Embeddings whose orbit type contains `i` see orbits merge (on sew) or split (on unsew);
//! each one's [`Policy`](crate::Policy) decides the values. If an embedding with the `error`
//! policy would merge two different values, or split, the operation is refused and the map
//! is left as it was.

use std::sync::Arc;

use crate::embedding::Policy;
use crate::marks::Marks;
use crate::{Dart, GMap, OrbitType, SewError};

impl GMap {
    /// The orbit walked in parallel by an `i`-sew: every dimension but `i-1, i, i+1`.
    pub fn sew_orbit(&self, i: usize) -> OrbitType {
        let mut o = OrbitType::all(self.dim).without(i);
        if i > 0 {
            o = o.without(i - 1);
        }
        if i < 3 {
            o = o.without(i + 1);
        }
        o
    }

    /// The pairs of darts an `i`-sew of `a` and `b` would link, or why it cannot.
    pub fn sew_pairs(&self, i: usize, a: Dart, b: Dart) -> Result<Vec<(Dart, Dart)>, SewError> {
        self.check_dim(i)?;
        self.check_dart(a)?;
        self.check_dart(b)?;
        let o = self.sew_orbit(i);
        // partner map of the parallel walk: x -> y and y -> x for every pair found
        let mut pmap = std::collections::HashMap::new();
        let not_iso = |x: Dart, y: Dart| SewError::NotIsomorphic {
            dim: i,
            a,
            b,
            orbit: o,
            x,
            y,
        };
        if a == b {
            return Err(not_iso(a, b));
        }
        pmap.insert(a, b);
        pmap.insert(b, a);
        let mut stack = vec![(a, b)];
        let mut pairs: Vec<(Dart, Dart)> = Vec::new();
        while let Some((x, y)) = stack.pop() {
            for z in [x, y] {
                if !self.is_free(i, z) {
                    return Err(SewError::NotFree {
                        dim: i,
                        a,
                        b,
                        busy: z,
                    });
                }
            }
            pairs.push((x, y));
            for j in o.dims() {
                let xj = self.alpha(j, x);
                let yj = self.alpha(j, y);
                if (xj == x) != (yj == y) {
                    return Err(not_iso(x, y));
                }
                match (pmap.get(&xj), pmap.get(&yj)) {
                    (Some(&px), Some(&py)) => {
                        if px != yj || py != xj {
                            return Err(not_iso(xj, yj));
                        }
                    }
                    (None, None) if xj != yj => {
                        pmap.insert(xj, yj);
                        pmap.insert(yj, xj);
                        stack.push((xj, yj));
                    }
                    _ => return Err(not_iso(xj, yj)),
                }
            }
        }
        Ok(pairs)
    }

    /// Sews `a` and `b` along dimension `i` (see the module docs). On error nothing changes.
    pub fn sew(&mut self, i: usize, a: Dart, b: Dart) -> Result<(), SewError> {
        let pairs = self.sew_pairs(i, a, b)?;
        let cap = self.capacity();
        for &(x, y) in &pairs {
            self.alpha[i][x.index()] = y.0;
            self.alpha[i][y.index()] = x.0;
            crate::gmap::note(&mut self.log, self.version, x.0, cap);
            crate::gmap::note(&mut self.log, self.version, y.0, cap);
        }
        self.version += 1;
        if let Err(name) = self.merge_embeddings(i, &pairs, true) {
            for &(x, y) in &pairs {
                self.alpha[i][x.index()] = x.0;
                self.alpha[i][y.index()] = y.0;
            }
            self.version += 1;
            return Err(SewError::Embedding {
                op: "sew",
                dart: a,
                embedding: name,
                what: "merge with different values",
            });
        }
        self.merge_embeddings(i, &pairs, false)
            .expect("checked in the dry run");
        Ok(())
    }

    /// Unsews the dart `a` along dimension `i`: unlinks by `alpha_i` every dart of the orbit
    /// [`GMap::sew_orbit`] of `a`. On error nothing changes.
    pub fn unsew(&mut self, i: usize, a: Dart) -> Result<(), SewError> {
        self.check_dim(i)?;
        self.check_dart(a)?;
        if self.is_free(i, a) {
            return Err(crate::LinkError::AlreadyFree { dim: i, dart: a }.into());
        }
        let o = self.sew_orbit(i);
        let mut pairs = Vec::new();
        let mut m = Marks::with_capacity(self.capacity());
        let darts = self.orbit(a, o);
        for x in darts {
            let y = self.alpha(i, x);
            if x != y && m.mark(x) && m.mark(y) {
                pairs.push((x, y));
            }
        }
        let cap = self.capacity();
        for &(x, y) in &pairs {
            self.alpha[i][x.index()] = x.0;
            self.alpha[i][y.index()] = y.0;
            crate::gmap::note(&mut self.log, self.version, x.0, cap);
            crate::gmap::note(&mut self.log, self.version, y.0, cap);
        }
        self.version += 1;
        if let Err(name) = self.split_embeddings(i, &pairs, true) {
            for &(x, y) in &pairs {
                self.alpha[i][x.index()] = y.0;
                self.alpha[i][y.index()] = x.0;
            }
            self.version += 1;
            return Err(SewError::Embedding {
                op: "unsew",
                dart: a,
                embedding: name,
                what: "split",
            });
        }
        self.split_embeddings(i, &pairs, false)
            .expect("checked in the dry run");
        Ok(())
    }

    /// After linking `pairs` by `alpha_i`: gives each merged orbit one slot. With `dry`, only
    /// checks the `error` policies and returns the first embedding that refuses.
    fn merge_embeddings(
        &mut self,
        i: usize,
        pairs: &[(Dart, Dart)],
        dry: bool,
    ) -> Result<(), String> {
        let cap = self.capacity();
        for k in 0..self.embeddings.len() {
            if !self.embeddings[k].orbit.contains(i) {
                continue;
            }
            if dry && self.embeddings[k].policy != Policy::Error {
                continue;
            }
            let orbit = self.embeddings[k].orbit;
            let mut m = Marks::with_capacity(cap);
            for &(x, _) in pairs {
                if m.is_marked(x) {
                    continue;
                }
                let mut darts = Vec::new();
                self.visit_orbit(x, orbit, &mut m, |d| darts.push(d));
                let e = &mut self.embeddings[k];
                let mut slots: Vec<usize> = Vec::new();
                // the slot of x comes first: it is the one kept
                for d in std::iter::once(x).chain(darts.iter().copied()) {
                    let s = e.slot(d);
                    if !slots.contains(&s) {
                        slots.push(s);
                    }
                }
                if slots.len() < 2 {
                    continue;
                }
                let w = e.ty.width();
                if dry {
                    if slots.iter().any(|&s| !e.values.slots_equal(w, slots[0], s)) {
                        return Err(e.name.clone());
                    }
                    continue;
                }
                let target = slots[0];
                e.values.merge(w, e.policy, &slots, target);
                for &s in &slots[1..] {
                    e.slot_use[s] = 0;
                    e.free_slots.push(s as u32);
                }
                e.slot_use[target] = darts.len() as u32;
                for d in darts {
                    if e.slot_of[d.index()] != target as u32 {
                        crate::gmap::note_slot(&mut self.log, self.version, d.0, cap);
                        Arc::make_mut(&mut e.slot_of)[d.index()] = target as u32;
                    }
                }
            }
        }
        Ok(())
    }

    /// After unlinking `pairs` by `alpha_i`: gives each part of a split orbit its own slot.
    fn split_embeddings(
        &mut self,
        i: usize,
        pairs: &[(Dart, Dart)],
        dry: bool,
    ) -> Result<(), String> {
        let cap = self.capacity();
        for k in 0..self.embeddings.len() {
            if !self.embeddings[k].orbit.contains(i) {
                continue;
            }
            if dry && self.embeddings[k].policy != Policy::Error {
                continue;
            }
            let orbit = self.embeddings[k].orbit;
            let mut m = Marks::with_capacity(cap);
            // old slot -> parts (dart lists) found
            let mut parts: Vec<(usize, Vec<Vec<Dart>>)> = Vec::new();
            for &(x, y) in pairs {
                for z in [x, y] {
                    if m.is_marked(z) {
                        continue;
                    }
                    let mut darts = Vec::new();
                    self.visit_orbit(z, orbit, &mut m, |d| darts.push(d));
                    let s = self.embeddings[k].slot(z);
                    match parts.iter_mut().find(|(t, _)| *t == s) {
                        Some((_, ps)) => ps.push(darts),
                        None => parts.push((s, vec![darts])),
                    }
                }
            }
            let e = &mut self.embeddings[k];
            for (s, ps) in parts {
                if ps.len() < 2 {
                    continue;
                }
                if dry {
                    return Err(e.name.clone());
                }
                let w = e.ty.width();
                let mut new_slots = Vec::with_capacity(ps.len() - 1);
                for part in &ps[1..] {
                    let ns = e.alloc_slot(part.len() as u32) as usize;
                    e.values.copy_slot(w, s, ns);
                    for d in part {
                        Arc::make_mut(&mut e.slot_of)[d.index()] = ns as u32;
                        crate::gmap::note_slot(&mut self.log, self.version, d.0, cap);
                    }
                    new_slots.push(ns);
                }
                e.slot_use[s] = ps[0].len() as u32;
                if e.policy == Policy::Sum {
                    e.values.split_sum(w, s, &new_slots);
                }
            }
        }
        Ok(())
    }
}
