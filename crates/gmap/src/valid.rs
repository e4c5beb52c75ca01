//! The map's invariants, checked with a report of each violation and the darts involved.

use std::fmt;

use crate::marks::Marks;
use crate::{Dart, GMap};

/// One violated invariant.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Violation {
    /// `alpha_i(d)` is a removed or out-of-range dart.
    DanglingLink {
        /// Dimension.
        dim: usize,
        /// The live dart.
        dart: Dart,
        /// Where its link points.
        to: Dart,
    },
    /// `alpha_i(alpha_i(d)) != d`.
    NotInvolution {
        /// Dimension.
        dim: usize,
        /// The dart.
        dart: Dart,
        /// `alpha_i(d)`.
        image: Dart,
        /// `alpha_i(alpha_i(d))`.
        back: Dart,
    },
    /// `(alpha_i alpha_j)^2 (d) != d` for `i + 2 <= j`.
    Cycle {
        /// Lower dimension.
        i: usize,
        /// Higher dimension.
        j: usize,
        /// The dart.
        dart: Dart,
    },
    /// `alpha_3` used in a 2-map.
    UnusedDimension {
        /// The dart.
        dart: Dart,
    },
    /// Two darts of one orbit of an embedding hold different slots.
    NotConstant {
        /// The embedding.
        embedding: String,
        /// First dart.
        a: Dart,
        /// Second dart, in the same orbit.
        b: Dart,
    },
    /// Two orbits of an embedding share one slot (a write to one would change the other).
    SharedSlot {
        /// The embedding.
        embedding: String,
        /// A dart of one orbit.
        a: Dart,
        /// A dart of the other orbit.
        b: Dart,
    },
    /// A slot's use count disagrees with the darts that use it.
    SlotCount {
        /// The embedding.
        embedding: String,
        /// The slot.
        slot: usize,
    },
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Violation::DanglingLink { dim, dart, to } => {
                write!(f, "alpha{dim}({dart}) = {to}, which is not a live dart")
            }
            Violation::NotInvolution { dim, dart, image, back } => write!(
                f,
                "alpha{dim} is not an involution: alpha{dim}({dart}) = {image} but alpha{dim}({image}) = {back}"
            ),
            Violation::Cycle { i, j, dart } => write!(
                f,
                "alpha{i} o alpha{j} is not an involution at {dart} (cycle condition for {i}+2 <= {j})"
            ),
            Violation::UnusedDimension { dart } => {
                write!(f, "alpha3({dart}) is linked in a 2-map, where alpha3 must stay free")
            }
            Violation::NotConstant { embedding, a, b } => write!(
                f,
                "embedding '{embedding}' is not constant on an orbit: {a} and {b} hold different slots"
            ),
            Violation::SharedSlot { embedding, a, b } => write!(
                f,
                "embedding '{embedding}': the orbits of {a} and {b} share one slot"
            ),
            Violation::SlotCount { embedding, slot } => {
                write!(f, "embedding '{embedding}': use count of slot {slot} is wrong")
            }
        }
    }
}

impl GMap {
    /// Whether every invariant holds.
    pub fn is_valid(&self) -> bool {
        self.validate_limited(1).is_empty()
    }

    /// Every violated invariant (at most 100 reported).
    pub fn validate(&self) -> Vec<Violation> {
        self.validate_limited(100)
    }

    /// The first violated invariant of the links alone (each alpha an involution on live
    /// darts, `alpha_i alpha_j` one for `i + 2 <= j`), or `None`: the part of [`GMap::validate`]
    /// that orbit walks rely on, in two passes over the darts (embeddings not checked).
    pub fn first_link_violation(&self) -> Option<Violation> {
        self.validate_links(1).into_iter().next()
    }

    fn validate_limited(&self, limit: usize) -> Vec<Violation> {
        let mut out = self.validate_links(limit);
        // the embeddings' checks walk orbits: only safe on involutions (a broken cycle
        // condition leaves them walkable, and they are checked too)
        if out.len() < limit && out.iter().all(|v| matches!(v, Violation::Cycle { .. })) {
            self.validate_embeddings(limit, &mut out);
        }
        out
    }

    fn validate_links(&self, limit: usize) -> Vec<Violation> {
        let mut out = Vec::new();
        let cap = self.capacity() as u32;
        // involutions
        for d in self.darts() {
            for i in 0..=3 {
                let e = self.alpha[i][d.index()];
                if e >= cap || !self.alive[e as usize] {
                    out.push(Violation::DanglingLink {
                        dim: i,
                        dart: d,
                        to: Dart(e),
                    });
                } else if self.alpha[i][e as usize] != d.0 {
                    out.push(Violation::NotInvolution {
                        dim: i,
                        dart: d,
                        image: Dart(e),
                        back: Dart(self.alpha[i][e as usize]),
                    });
                } else if i == 3 && self.dim == 2 && e != d.0 {
                    out.push(Violation::UnusedDimension { dart: d });
                }
                if out.len() >= limit {
                    return out;
                }
            }
        }
        if !out.is_empty() {
            return out; // later checks follow links: only safe on involutions
        }
        for d in self.darts() {
            for i in 0..=self.dim {
                for j in i + 2..=self.dim {
                    let x = self.alpha(j, self.alpha(i, self.alpha(j, self.alpha(i, d))));
                    if x != d {
                        out.push(Violation::Cycle { i, j, dart: d });
                        if out.len() >= limit {
                            return out;
                        }
                    }
                }
            }
        }
        out
    }

    fn validate_embeddings(&self, limit: usize, out: &mut Vec<Violation>) {
        for e in &self.embeddings {
            if e.is_direct() {
                continue;
            }
            let mut owner: Vec<u32> = vec![u32::MAX; e.slot_use.len()];
            let mut counts: Vec<u32> = vec![0; e.slot_use.len()];
            let mut m = Marks::with_capacity(self.capacity());
            for d in self.darts() {
                if m.is_marked(d) {
                    continue;
                }
                let s = e.slot_of[d.index()] as usize;
                if s >= owner.len() {
                    out.push(Violation::SlotCount {
                        embedding: e.name.clone(),
                        slot: s,
                    });
                    return;
                }
                if owner[s] == u32::MAX {
                    owner[s] = d.0;
                } else {
                    out.push(Violation::SharedSlot {
                        embedding: e.name.clone(),
                        a: Dart(owner[s]),
                        b: d,
                    });
                }
                let mut bad = None;
                self.visit_orbit(d, e.orbit, &mut m, |x| {
                    let sx = e.slot_of[x.index()] as usize;
                    if sx < counts.len() {
                        counts[sx] += 1;
                    }
                    if sx != s && bad.is_none() {
                        bad = Some(x);
                    }
                });
                if let Some(b) = bad {
                    out.push(Violation::NotConstant {
                        embedding: e.name.clone(),
                        a: d,
                        b,
                    });
                }
                if out.len() >= limit {
                    return;
                }
            }
            for (s, (&c, &u)) in counts.iter().zip(&e.slot_use).enumerate() {
                if c != u {
                    out.push(Violation::SlotCount {
                        embedding: e.name.clone(),
                        slot: s,
                    });
                    if out.len() >= limit {
                        return;
                    }
                }
            }
        }
    }
}
