//! Marks: per-call visited sets for traversals.
//!
//! A [`Marks`] is owned by the traversal that uses it, never stored in the map, so any
//! number of traversals may run at once on a shared `&GMap` from several threads.
//! [`with_marks`] lends one from a per-thread pool so that repeated small traversals do not
//! reallocate; clearing costs the number of darts marked, not the size of the map.

use std::cell::RefCell;

use crate::Dart;

/// A set of marked darts: a bit set plus the list of what was set, for cheap clearing.
#[derive(Debug, Default, Clone)]
pub struct Marks {
    bits: Vec<u64>,
    set: Vec<u32>,
}

impl Marks {
    /// Empty marks able to hold darts `0..capacity`: from this thread's pool when it has
    /// some (marks dropped go back to it, cleared), so that a traversal repeated once per
    /// change of a large map neither allocates nor zeroes a set the size of the map.
    pub fn with_capacity(capacity: usize) -> Self {
        let mut m = POOL
            .try_with(|p| p.try_borrow_mut().ok().and_then(|mut p| p.pop()))
            .ok()
            .flatten()
            .unwrap_or_default();
        m.reserve_darts(capacity);
        m
    }

    /// Grows the set to hold darts `0..capacity` (marks are kept).
    pub fn reserve_darts(&mut self, capacity: usize) {
        let words = capacity.div_ceil(64);
        if self.bits.len() < words {
            self.bits.resize(words, 0);
        }
    }

    /// Whether `d` is marked.
    #[inline]
    pub fn is_marked(&self, d: Dart) -> bool {
        let i = d.index();
        self.bits
            .get(i >> 6)
            .is_some_and(|w| w & (1u64 << (i & 63)) != 0)
    }

    /// Marks `d`; returns `true` if it was not marked before.
    #[inline]
    pub fn mark(&mut self, d: Dart) -> bool {
        let i = d.index();
        if i >> 6 >= self.bits.len() {
            self.reserve_darts(i + 1);
        }
        let w = &mut self.bits[i >> 6];
        let b = 1u64 << (i & 63);
        if *w & b != 0 {
            return false;
        }
        *w |= b;
        self.set.push(d.0);
        true
    }

    /// The number of marked darts.
    pub fn len(&self) -> usize {
        self.set.len()
    }

    /// Whether nothing is marked.
    pub fn is_empty(&self) -> bool {
        self.set.is_empty()
    }

    /// Unmarks everything, in time proportional to what was marked.
    pub fn clear(&mut self) {
        if self.set.len() * 8 > self.bits.len() {
            self.bits.fill(0);
        } else {
            for &i in &self.set {
                self.bits[(i >> 6) as usize] = 0;
            }
        }
        self.set.clear();
    }
}

impl Drop for Marks {
    /// Gives the set back to this thread's pool, cleared, while the pool holds fewer than
    /// [`POOL_MAX`] (else, or while the thread ends, it is freed).
    fn drop(&mut self) {
        if self.bits.is_empty() {
            return;
        }
        let _ = POOL.try_with(|p| {
            if let Ok(mut p) = p.try_borrow_mut() {
                if p.len() < POOL_MAX {
                    self.clear();
                    // what a walk over a whole map listed is not kept
                    self.set.shrink_to(SET_KEPT);
                    p.push(Marks {
                        bits: std::mem::take(&mut self.bits),
                        set: std::mem::take(&mut self.set),
                    });
                }
            }
        });
    }
}

/// Marks kept per thread at most.
const POOL_MAX: usize = 16;

/// Entries of a pooled set's list of marked darts kept allocated at most.
const SET_KEPT: usize = 1 << 16;

thread_local! {
    static POOL: RefCell<Vec<Marks>> = const { RefCell::new(Vec::new()) };
}

/// Runs `f` with cleared marks from this thread's pool, sized for `capacity` darts.
pub fn with_marks<R>(capacity: usize, f: impl FnOnce(&mut Marks) -> R) -> R {
    // drawn from the pool, and given back cleared when dropped (`Marks::drop`)
    f(&mut Marks::with_capacity(capacity))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mark_and_clear() {
        let mut m = Marks::with_capacity(10);
        assert!(m.mark(Dart(3)));
        assert!(!m.mark(Dart(3)));
        assert!(m.mark(Dart(200)), "grows on demand");
        assert!(m.is_marked(Dart(3)) && m.is_marked(Dart(200)));
        assert!(!m.is_marked(Dart(4)));
        m.clear();
        assert!(!m.is_marked(Dart(3)) && !m.is_marked(Dart(200)) && m.is_empty());
    }

    #[test]
    fn dropped_marks_come_back_clear_and_big_enough() {
        let mut big = Marks::with_capacity(1 << 20);
        for i in (0..1 << 20).step_by(3) {
            big.mark(Dart(i));
        }
        drop(big);
        let mut small = Vec::new();
        for _ in 0..2 * POOL_MAX {
            let mut m = Marks::with_capacity(100);
            assert!(m.is_empty());
            assert!((0..1 << 20).step_by(3).all(|i| !m.is_marked(Dart(i))));
            assert!(m.mark(Dart(99)) && m.mark(Dart(5000)), "grows on demand");
            small.push(m);
        }
        drop(small); // POOL_MAX go back, the others are freed
        let pooled = POOL.with(|p| p.borrow().len());
        assert!(pooled <= POOL_MAX, "{pooled}");
        with_marks(10, |m| {
            assert!(!m.is_marked(Dart(99)) && !m.is_marked(Dart(5000)));
        });
    }

    #[test]
    fn pooled_marks_come_back_clear() {
        with_marks(100, |m| {
            m.mark(Dart(5));
        });
        with_marks(100, |m| assert!(!m.is_marked(Dart(5))));
        // nested use takes a second set
        with_marks(10, |a| {
            a.mark(Dart(1));
            with_marks(10, |b| assert!(!b.is_marked(Dart(1))));
        });
    }
}
