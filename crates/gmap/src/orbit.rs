//! Orbit types: subsets of the link dimensions `{0..n}`.
//!
//! An orbit `<i, j, ...>` of a dart is the set of darts reachable from it through the
//! links `alpha_i, alpha_j, ...` in any order. The paper stores mechanical data on orbits
//! that are not cells (half-edges `<0>`, corners `<1>`, edge-ends `<2,3>`), so an orbit
//! type here is any subset, not a fixed list of cells.

use std::fmt;

/// The largest dimension a map may have.
pub const MAX_DIM: usize = 3;

/// A set of link dimensions, e.g. `<0,2,3>`, stored as a bit mask.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct OrbitType(u8);

/// Why an orbit type could not be parsed or built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OrbitTypeError {
    /// A dimension outside `0..=3`.
    #[error("dimension {0} is out of range 0..=3 in orbit type")]
    Dimension(usize),
    /// A dimension listed twice.
    #[error("dimension {0} appears twice in orbit type")]
    Duplicate(usize),
    /// Not of the form `<i,j,...>`.
    #[error("malformed orbit type {0:?}: expected a form like <0,2,3>")]
    Syntax(String),
}

impl OrbitType {
    /// The empty orbit `<>`: a single dart.
    pub const EMPTY: OrbitType = OrbitType(0);

    /// Builds an orbit type from its dimensions; each in `0..=3`, none twice.
    pub fn new(dims: &[usize]) -> Result<Self, OrbitTypeError> {
        let mut m = 0u8;
        for &i in dims {
            if i > MAX_DIM {
                return Err(OrbitTypeError::Dimension(i));
            }
            if m & (1 << i) != 0 {
                return Err(OrbitTypeError::Duplicate(i));
            }
            m |= 1 << i;
        }
        Ok(OrbitType(m))
    }

    /// Builds an orbit type from a bit mask (bit i set when dimension i is in the orbit).
    pub fn from_mask(mask: u8) -> Result<Self, OrbitTypeError> {
        if mask >> (MAX_DIM + 1) != 0 {
            return Err(OrbitTypeError::Dimension(7 - mask.leading_zeros() as usize));
        }
        Ok(OrbitType(mask))
    }

    /// The bit mask of this orbit type.
    #[inline]
    pub const fn mask(self) -> u8 {
        self.0
    }

    /// Whether dimension `i` belongs to this orbit type.
    #[inline]
    pub const fn contains(self, i: usize) -> bool {
        i <= MAX_DIM && self.0 & (1 << i) != 0
    }

    /// Whether every dimension of `self` is in `other`.
    #[inline]
    pub const fn is_subset_of(self, other: OrbitType) -> bool {
        self.0 & !other.0 == 0
    }

    /// The dimensions, in increasing order.
    pub fn dims(self) -> impl Iterator<Item = usize> + Clone {
        (0..=MAX_DIM).filter(move |&i| self.contains(i))
    }

    /// The number of dimensions.
    pub const fn len(self) -> usize {
        self.0.count_ones() as usize
    }

    /// Whether this is `<>`.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The largest dimension in the orbit, if any.
    pub fn max_dim(self) -> Option<usize> {
        self.dims().last()
    }

    /// `self` with dimension `i` added.
    #[must_use]
    pub const fn with(self, i: usize) -> Self {
        OrbitType(self.0 | (1 << i))
    }

    /// `self` with dimension `i` removed.
    #[must_use]
    pub const fn without(self, i: usize) -> Self {
        OrbitType(self.0 & !(1 << i))
    }

    /// All dimensions `0..=n`: the connected component.
    pub const fn all(n: usize) -> Self {
        OrbitType(((1u16 << (n + 1)) - 1) as u8)
    }

    /// The `i`-cell of an `n`-map: every dimension of `0..=n` but `i`.
    pub const fn cell(n: usize, i: usize) -> Self {
        OrbitType::all(n).without(i)
    }

    /// The vertex orbit `<1..n>`.
    pub const fn vertex(n: usize) -> Self {
        Self::cell(n, 0)
    }

    /// The edge orbit `<0,2..n>`.
    pub const fn edge(n: usize) -> Self {
        Self::cell(n, 1)
    }

    /// The face orbit `<0,1,3..n>` (a face shared by two volumes is one face).
    pub const fn face(n: usize) -> Self {
        Self::cell(n, 2)
    }

    /// The volume orbit `<0,1,2>`.
    pub const fn volume() -> Self {
        OrbitType(0b0111)
    }

    /// Parses `<>`, `<0>`, `<0,2,3>` (spaces allowed).
    pub fn parse(s: &str) -> Result<Self, OrbitTypeError> {
        let t = s.trim();
        let inner = t
            .strip_prefix('<')
            .and_then(|r| r.strip_suffix('>'))
            .ok_or_else(|| OrbitTypeError::Syntax(s.to_string()))?;
        let inner = inner.trim();
        if inner.is_empty() {
            return Ok(OrbitType::EMPTY);
        }
        let mut dims = Vec::new();
        for part in inner.split(',') {
            let p = part.trim();
            let i: usize = p
                .parse()
                .map_err(|_| OrbitTypeError::Syntax(s.to_string()))?;
            dims.push(i);
        }
        OrbitType::new(&dims)
    }
}

impl fmt::Display for OrbitType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "<")?;
        for (k, i) in self.dims().enumerate() {
            if k > 0 {
                write!(f, ",")?;
            }
            write!(f, "{i}")?;
        }
        write!(f, ">")
    }
}

impl fmt::Debug for OrbitType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl std::str::FromStr for OrbitType {
    type Err = OrbitTypeError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        OrbitType::parse(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_and_display_round_trip() {
        for s in ["<>", "<0>", "<1,2>", "<0,2,3>", "<0,1,2,3>"] {
            assert_eq!(OrbitType::parse(s).unwrap().to_string(), s);
        }
        assert_eq!(
            OrbitType::parse(" < 2 , 0 > ").unwrap().to_string(),
            "<0,2>"
        );
    }

    #[test]
    fn parse_rejects_bad_input() {
        assert!(matches!(
            OrbitType::parse("<4>"),
            Err(OrbitTypeError::Dimension(4))
        ));
        assert!(matches!(
            OrbitType::parse("<1,1>"),
            Err(OrbitTypeError::Duplicate(1))
        ));
        assert!(matches!(
            OrbitType::parse("0,1"),
            Err(OrbitTypeError::Syntax(_))
        ));
        assert!(matches!(
            OrbitType::parse("<a>"),
            Err(OrbitTypeError::Syntax(_))
        ));
        assert!(OrbitType::from_mask(0b1_0000).is_err());
    }

    #[test]
    fn cells_match_the_paper() {
        assert_eq!(OrbitType::vertex(2).to_string(), "<1,2>");
        assert_eq!(OrbitType::vertex(3).to_string(), "<1,2,3>");
        assert_eq!(OrbitType::edge(2).to_string(), "<0,2>");
        assert_eq!(OrbitType::edge(3).to_string(), "<0,2,3>");
        assert_eq!(OrbitType::face(2).to_string(), "<0,1>");
        assert_eq!(OrbitType::face(3).to_string(), "<0,1,3>");
        assert_eq!(OrbitType::volume().to_string(), "<0,1,2>");
        assert_eq!(OrbitType::all(3).to_string(), "<0,1,2,3>");
    }
}
