//! Darts: the atoms of a generalized map.

use std::fmt;

/// A dart of a [`GMap`](crate::GMap), an index into its struct-of-arrays tables.
///
/// A dart is only meaningful for the map that created it. A free link `alpha_i(d)` is
/// represented by `d` itself.
#[repr(transparent)]
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Dart(pub u32);

impl Dart {
    /// The dart with index `i`.
    #[inline]
    pub const fn new(i: u32) -> Self {
        Dart(i)
    }

    /// The index of this dart in the map's tables.
    #[inline]
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

impl fmt::Debug for Dart {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "d{}", self.0)
    }
}

impl fmt::Display for Dart {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "d{}", self.0)
    }
}

impl From<Dart> for usize {
    fn from(d: Dart) -> usize {
        d.index()
    }
}
