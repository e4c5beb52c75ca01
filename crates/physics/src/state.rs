//! The simulation state read and written per vertex: rows (particles), embeddings per row.

use topomech_gmap::{Dart, EmbeddingId, EmbeddingType, GMap, Marks, OrbitType, Policy, Value};
use topomech_rules::RuleSet;

use crate::*;

/// An element (volume in 3D, face in 2D) as [`Simulation::elements`] lists it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Element {
    /// The index of the input cell it was built from (-1 when unknown).
    pub cell_id: i64,
    /// Its kind.
    pub kind: topomech_gmap::mesh::CellKind,
    /// Its vertices' rows.
    pub rows: Vec<usize>,
}

/// The simulation's vertex numbering: rows (particles) from the map's `particle` embedding.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Rows {
    /// One dart per row: the smallest dart of the row's first vertex orbit.
    pub(crate) darts: Vec<Dart>,
    /// One dart per vertex orbit (its smallest), in increasing order.
    pub(crate) orbits: Vec<Dart>,
    /// The row of each orbit of `orbits`.
    pub(crate) row_of: Vec<usize>,
    /// Rows of several orbits, with each orbit's smallest dart.
    pub(crate) welded: Vec<(usize, Vec<Dart>)>,
}

impl Rows {
    /// The numbering of a new simulation's map: from its `particle` embedding, created (with
    /// `point_id`) from the vertex orbit order when the map has none.
    pub(crate) fn init(g: &mut GMap) -> Result<Self, PhysicsError> {
        let vertex = OrbitType::vertex(g.dimension());
        let err = |e: topomech_gmap::EmbeddingError| PhysicsError::Config(e.to_string());
        let orbits = g.orbit_representatives(vertex);
        for name in ["particle", "point_id"] {
            if let Some(id) = g.embedding_id(name) {
                let e = g.embedding(id);
                if e.orbit() != vertex || e.ty() != EmbeddingType::I64 {
                    return Err(PhysicsError::Config(format!(
                        "the map's '{name}' must be an i64 on the vertex orbit {vertex}, it is a {} on {}",
                        e.ty(),
                        e.orbit()
                    )));
                }
            }
        }
        let particle = if let Some(id) = g.embedding_id("particle") {
            id
        } else {
            let id = g
                .add_embedding("particle", EmbeddingType::I64, vertex, Policy::Copy)
                .map_err(err)?;
            for (k, &d) in orbits.iter().enumerate() {
                g.set_value(id, d, &Value::Int(k as i64)).map_err(err)?;
            }
            id
        };
        let mut row_of = Vec::with_capacity(orbits.len());
        let mut negative = Vec::new();
        for &d in &orbits {
            match g.value(particle, d).map_err(err)? {
                Value::Int(x) if x >= 0 => row_of.push(x as usize),
                _ => {
                    negative.push(d.index());
                    row_of.push(0);
                }
            }
        }
        if !negative.is_empty() {
            return Err(PhysicsError::Config(format!(
                "the map's 'particle' is negative on the vertices of darts {}",
                list_some(&negative, 20)
            )));
        }
        let n = row_of.iter().max().map_or(0, |m| m + 1);
        let mut used = vec![false; n];
        for &r in &row_of {
            used[r] = true;
        }
        let missing: Vec<usize> = (0..n).filter(|&r| !used[r]).collect();
        if !missing.is_empty() {
            return Err(PhysicsError::Config(format!(
                "the map's 'particle' numbering has gaps: no vertex has rows {} (the rows must be \
                 every number from 0 to {}; a rule that removed vertices leaves gaps: write \
                 'particle' again, e.g. with GMap.set_embedding)",
                list_some(&missing, 20),
                n - 1
            )));
        }
        if g.embedding_id("point_id").is_none() {
            let id = g
                .add_embedding("point_id", EmbeddingType::I64, vertex, Policy::Copy)
                .map_err(err)?;
            for (&d, &r) in orbits.iter().zip(&row_of) {
                g.set_value(id, d, &Value::Int(r as i64)).map_err(err)?;
            }
        }
        let mut rows = Rows {
            orbits,
            row_of,
            ..Rows::default()
        };
        rows.index(n);
        // the orbits of one particle must start at one place: they share its position
        let pos = g.require("position").map_err(err)?;
        let apart: Vec<usize> = rows
            .welded
            .iter()
            .filter(|(_, darts)| {
                darts
                    .iter()
                    .any(|&d| g.real(pos, d) != g.real(pos, darts[0]))
            })
            .map(|(r, _)| *r)
            .collect();
        if !apart.is_empty() {
            return Err(PhysicsError::Config(format!(
                "vertex orbits that share a 'particle' are one particle and must be at the same position: those of rows {} are not",
                list_some(&apart, 20)
            )));
        }
        Ok(rows)
    }

    /// Rebuilds `darts` and `welded` from `orbits` and `row_of` (`n` rows).
    pub(crate) fn index(&mut self, n: usize) {
        let mut count = vec![0usize; n];
        self.darts = vec![Dart(0); n];
        for (&d, &r) in self.orbits.iter().zip(&self.row_of).rev() {
            // reversed: the smallest orbit dart of the row is written last
            self.darts[r] = d;
            count[r] += 1;
        }
        self.welded.clear();
        if count.iter().any(|&c| c > 1) {
            let mut welded: Vec<(usize, Vec<Dart>)> = Vec::new();
            let mut slot = vec![usize::MAX; n];
            for (&d, &r) in self.orbits.iter().zip(&self.row_of) {
                if count[r] > 1 {
                    if slot[r] == usize::MAX {
                        slot[r] = welded.len();
                        welded.push((r, Vec::new()));
                    }
                    welded[slot[r]].1.push(d);
                }
            }
            welded.sort_by_key(|w| w.0);
            self.welded = welded;
        }
    }

    /// [`Rows::renumber`] from the darts `changed` since the numbering was made (their links
    /// changed, or they were created or removed: [`GMap::relinked_since`]), walking only the
    /// vertex orbits that hold one. The same numbering: a vertex orbit (on the new map) without
    /// a changed dart is closed under the old links, so it is an old orbit, with the same smallest dart
    /// and row; every other orbit holds a changed dart, and is numbered here as `renumber`
    /// numbers it (the row of the old representatives it holds, or a new row, appended in
    /// increasing order of its smallest dart: the new orbits are all among these). The old
    /// representatives these orbits hold, and the changed ones that died, are replaced.
    pub(crate) fn renumber_changed(
        &mut self,
        g: &mut GMap,
        changed: &[Dart],
    ) -> Result<Vec<usize>, PhysicsError> {
        let vertex = OrbitType::vertex(g.dimension());
        let n_rows = self.darts.len();
        // the old representatives, marked: most darts walked are none, and a bit says so
        // faster than a search
        let mut reps = Marks::with_capacity(g.capacity());
        for &d in &self.orbits {
            reps.mark(d);
        }
        let rep = |x: Dart| {
            if reps.is_marked(x) {
                self.orbits.binary_search(&x).ok()
            } else {
                None
            }
        };
        // the old representatives replaced, and the orbits holding a changed dart: (smallest
        // dart, row of the old representatives it holds or usize::MAX)
        let mut replaced: Vec<usize> = Vec::new();
        let mut walked: Vec<(Dart, usize)> = Vec::new();
        let mut seen = Marks::with_capacity(g.capacity());
        for &c in changed {
            if !g.is_alive(c) {
                replaced.extend(rep(c));
                continue;
            }
            if seen.is_marked(c) {
                continue;
            }
            let (mut min, mut row, mut merged) = (c, usize::MAX, None);
            g.visit_orbit(c, vertex, &mut seen, |x| {
                min = min.min(x);
                if let Some(k) = rep(x) {
                    replaced.push(k);
                    let r = self.row_of[k];
                    if row == usize::MAX {
                        row = r;
                    } else if row != r {
                        merged = Some((row, r));
                    }
                }
            });
            if let Some((a, b)) = merged {
                return Err(PhysicsError::Config(format!(
                    "a topology change merged the vertices of rows {} and {}: only splits are supported",
                    a.min(b),
                    a.max(b)
                )));
            }
            walked.push((min, row));
        }
        replaced.sort_unstable();
        replaced.dedup();
        // a row whose every representative was replaced, and that no walked orbit has, is lost
        let mut has = vec![false; n_rows];
        let mut is_replaced = vec![false; self.orbits.len()];
        for &k in &replaced {
            is_replaced[k] = true;
        }
        for (k, &r) in self.row_of.iter().enumerate() {
            if !is_replaced[k] {
                has[r] = true;
            }
        }
        for &(_, r) in &walked {
            if r != usize::MAX {
                has[r] = true;
            }
        }
        let particle = kept_rows_particle(g, &has)?;
        walked.sort_unstable_by_key(|w| w.0);
        let mut added = Vec::new();
        for w in &mut walked {
            if w.1 == usize::MAX {
                w.1 = n_rows + added.len();
                added.push(w.1);
                g.set_value(particle, w.0, &Value::Int(w.1 as i64))
                    .map_err(|e| PhysicsError::Config(e.to_string()))?;
            }
        }
        // the kept orbits (in increasing order of their darts, as `orbits` is) and the walked
        // ones (sorted above) merged: one pass, where a sort of the whole numbering cost
        // most of a single-face cut's renumbering
        let total = self.orbits.len() - replaced.len() + walked.len();
        let (mut orbits, mut row_of) = (Vec::with_capacity(total), Vec::with_capacity(total));
        let mut kept = self
            .orbits
            .iter()
            .zip(&self.row_of)
            .enumerate()
            .filter(|(k, _)| !is_replaced[*k])
            .map(|(_, (&d, &r))| (d, r))
            .peekable();
        let mut walked = walked.into_iter().peekable();
        loop {
            let next = match (kept.peek(), walked.peek()) {
                (Some(a), Some(b)) if a.0 < b.0 => kept.next(),
                (Some(_) | None, Some(_)) => walked.next(),
                (Some(_), None) => kept.next(),
                (None, None) => break,
            };
            let (d, r) = next.expect("peeked");
            orbits.push(d);
            row_of.push(r);
        }
        self.orbits = orbits;
        self.row_of = row_of;
        self.index(n_rows + added.len());
        Ok(added)
    }

    /// The numbering after a topology change of `g` (see [`Simulation::sync_rows`]); returns
    /// the rows added.
    pub(crate) fn renumber(&mut self, g: &mut GMap) -> Result<Vec<usize>, PhysicsError> {
        let vertex = OrbitType::vertex(g.dimension());
        let (labels, n_orbits) = g.orbit_labels(vertex);
        let orbits = g.orbit_representatives(vertex);
        let mut row_of = vec![usize::MAX; n_orbits];
        let n_rows = self.darts.len();
        let mut kept = vec![false; n_rows];
        for (&d, &r) in self.orbits.iter().zip(&self.row_of) {
            if !g.is_alive(d) {
                continue;
            }
            let l = labels[d.index()] as usize;
            if row_of[l] != usize::MAX && row_of[l] != r {
                return Err(PhysicsError::Config(format!(
                    "a topology change merged the vertices of rows {} and {r}: only splits are supported",
                    row_of[l]
                )));
            }
            row_of[l] = r;
            kept[r] = true;
        }
        let particle = kept_rows_particle(g, &kept)?;
        let mut added = Vec::new();
        for (l, &d) in orbits.iter().enumerate() {
            if row_of[l] == usize::MAX {
                let r = n_rows + added.len();
                row_of[l] = r;
                added.push(r);
                g.set_value(particle, d, &Value::Int(r as i64))
                    .map_err(|e| PhysicsError::Config(e.to_string()))?;
            }
        }
        self.orbits = orbits;
        self.row_of = row_of;
        self.index(n_rows + added.len());
        Ok(added)
    }
}

/// After a renumbering found which old rows still have a vertex orbit (`kept`): an error
/// naming the rows a topology change removed (only splits are supported), else the map's
/// `particle` embedding, which the new rows are written to.
fn kept_rows_particle(g: &GMap, kept: &[bool]) -> Result<EmbeddingId, PhysicsError> {
    let lost: Vec<usize> = (0..kept.len()).filter(|&r| !kept[r]).collect();
    if !lost.is_empty() {
        return Err(PhysicsError::Config(format!(
            "a topology change removed the vertices of rows {}: only splits are supported",
            list_some(&lost, 20)
        )));
    }
    g.require("particle")
        .map_err(|e| PhysicsError::Config(e.to_string()))
}

impl Simulation {
    /// The map with all its embeddings.
    pub fn gmap(&self) -> &GMap {
        &self.g
    }

    /// The rules in use.
    pub fn rules(&self) -> &RuleSet {
        &self.rules
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Simulated time.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Steps done.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Brings the numbering in step with the map after a topology change: an orbit that holds
    /// a dart that represented an orbit before keeps that orbit's row; every other (new)
    /// vertex orbit gets a new row, appended in increasing order of its smallest dart, with
    /// its `particle` set to it (its `point_id`, copied by the split, stays the point it was
    /// split from). Returns the rows added.
    pub(crate) fn sync_rows(&mut self) -> Result<Vec<usize>, PhysicsError> {
        if self.vertex_darts_version == self.g.version() {
            return Ok(Vec::new());
        }
        // from the change record when it covers the numbering's version (it does once
        // recording started: plans start it, and so does this), else over the whole map
        let added = match self.g.relinked_since(self.vertex_darts_version) {
            Some(changed) => {
                // tests (debug builds, small maps) check it against the whole-map numbering
                let check = (cfg!(debug_assertions) && self.g.capacity() < 200_000)
                    .then(|| (self.rows.clone(), self.g.clone()));
                let added = self.rows.renumber_changed(&mut self.g, &changed)?;
                if let Some((mut rows, mut g)) = check {
                    let want = rows.renumber(&mut g)?;
                    assert_eq!(added, want, "rows added");
                    assert_eq!(self.rows, rows, "the numbering from the changed darts");
                }
                added
            }
            None => self.rows.renumber(&mut self.g)?,
        };
        self.g.track_changes();
        self.vertex_darts_version = self.g.version();
        Ok(added)
    }

    /// One dart per row (vertex), in row order: the smallest dart of the row's first vertex
    /// orbit. Rows follow the map's `particle` embedding (the input point order for a map
    /// built from a mesh); a welded row (several vertex orbits sharing one `particle`: a
    /// pinched input vertex kept as one particle) is represented by its first orbit.
    pub fn vertex_darts(&self) -> Vec<Dart> {
        self.rows.darts.clone()
    }

    /// The number of rows (particles, V).
    pub fn n_vertices(&self) -> usize {
        self.rows.darts.len()
    }

    /// Every vertex orbit (its smallest dart, in increasing order) with its row.
    pub fn vertex_orbits(&self) -> (&[Dart], &[usize]) {
        (&self.rows.orbits, &self.rows.row_of)
    }

    /// The rows made of several vertex orbits, each with the smallest dart of every orbit.
    pub fn welded_rows(&self) -> &[(usize, Vec<Dart>)] {
        &self.rows.welded
    }

    /// The input point index (`point_id`) of each row, in row order.
    pub fn point_ids(&self) -> Result<Vec<i64>, PhysicsError> {
        let id = self.id("point_id")?;
        self.rows
            .darts
            .iter()
            .map(|&d| match self.g.value(id, d) {
                Ok(Value::Int(x)) => Ok(x),
                Ok(v) => Err(PhysicsError::Config(format!(
                    "'point_id' is not an i64: {v:?}"
                ))),
                Err(e) => Err(PhysicsError::Config(e.to_string())),
            })
            .collect()
    }

    /// Every element (volume in 3D, face in 2D), in increasing order of its smallest dart:
    /// its `cell_id` (the index of the input cell, -1 when the map has no `cell_id`), its
    /// kind and its vertex rows in the order of [`topomech_gmap::mesh::extract`] (VTK order
    /// for volumes, oriented so that the rest volume is positive; the face's cycle in 2D).
    pub fn elements(&self) -> Result<Vec<Element>, PhysicsError> {
        let err = |e: topomech_gmap::mesh::MeshError| PhysicsError::Config(e.to_string());
        let mesh = topomech_gmap::mesh::extract(&self.g).map_err(err)?;
        let dim = self.g.dimension();
        let elem = if dim == 3 {
            OrbitType::volume()
        } else {
            OrbitType::face(2)
        };
        let reps = self.g.orbit_representatives(elem);
        let cell_id = self.g.embedding_id("cell_id").filter(|&id| {
            let e = self.g.embedding(id);
            e.orbit() == elem && e.ty() == EmbeddingType::I64
        });
        let rest = self.rest_points()?;
        let mut out = Vec::with_capacity(reps.len());
        for ((d, kind), verts) in reps.iter().zip(&mesh.kinds).zip(&mesh.cells) {
            // extract numbers points by the map's `particle` rows, which the simulation keeps
            // equal to its rows (it writes `particle` when it numbers new vertex orbits)
            let mut verts = verts.clone();
            if dim == 3 && topomech_gmap::mesh::signed_volume(*kind, &verts, &rest) < 0.0 {
                verts = topomech_gmap::mesh::reversed(*kind, &verts);
            }
            let cell = match cell_id {
                Some(id) => match self.g.value(id, *d) {
                    Ok(Value::Int(x)) => x,
                    _ => -1,
                },
                None => -1,
            };
            out.push(Element {
                cell_id: cell,
                kind: *kind,
                rows: verts,
            });
        }
        Ok(out)
    }

    /// The rest position of each row.
    pub(crate) fn rest_points(&self) -> Result<Vec<[f64; 3]>, PhysicsError> {
        self.vertex_vec3("rest")
    }

    pub(crate) fn id(&self, name: &str) -> Result<EmbeddingId, PhysicsError> {
        self.g
            .require(name)
            .map_err(|e| PhysicsError::Config(e.to_string()))
    }

    /// A vec3 vertex embedding (`position`, `velocity`, `rest`) in row order: the value of the
    /// row's first orbit (the orbits of a welded row share positions and velocities).
    pub fn vertex_vec3(&self, name: &str) -> Result<Vec<[f64; 3]>, PhysicsError> {
        let id = self.id(name)?;
        Ok(self
            .rows
            .darts
            .iter()
            .map(|&d| {
                let x = self.g.real(id, d);
                [x[0], x[1], x[2]]
            })
            .collect())
    }

    /// A vec3 vertex embedding summed over the orbits of each row (`force`, `df`), in row
    /// order; the same as [`Simulation::vertex_vec3`] for rows of one orbit.
    pub fn vertex_vec3_sum(&self, name: &str) -> Result<Vec<[f64; 3]>, PhysicsError> {
        let mut out = self.vertex_vec3(name)?;
        if !self.rows.welded.is_empty() {
            let id = self.id(name)?;
            for (row, darts) in &self.rows.welded {
                let mut f = [0.0; 3];
                for &d in darts {
                    let x = self.g.real(id, d);
                    for a in 0..3 {
                        f[a] += x[a];
                    }
                }
                out[*row] = f;
            }
        }
        Ok(out)
    }

    /// A f64 vertex embedding in row order (the value of the row's first orbit).
    pub fn vertex_scalar(&self, name: &str) -> Result<Vec<f64>, PhysicsError> {
        let id = self.id(name)?;
        self.rows
            .darts
            .iter()
            .map(|&d| match self.g.value(id, d) {
                Ok(Value::Real(x)) => Ok(x[0]),
                Ok(v) => Err(PhysicsError::Config(format!(
                    "'{name}' is not a real: {v:?}"
                ))),
                Err(e) => Err(PhysicsError::Config(e.to_string())),
            })
            .collect()
    }

    /// A f64 vertex embedding summed over the orbits of each row (`mass`), in row order.
    pub fn vertex_scalar_sum(&self, name: &str) -> Result<Vec<f64>, PhysicsError> {
        let mut out = self.vertex_scalar(name)?;
        if !self.rows.welded.is_empty() {
            let id = self.id(name)?;
            for (row, darts) in &self.rows.welded {
                out[*row] = darts.iter().map(|&d| self.g.real(id, d)[0]).sum();
            }
        }
        Ok(out)
    }

    /// A bool vertex embedding (`fixed`) in row order (the value of the row's first orbit).
    pub fn vertex_bool(&self, name: &str) -> Result<Vec<bool>, PhysicsError> {
        let id = self.id(name)?;
        self.rows
            .darts
            .iter()
            .map(|&d| match self.g.value(id, d) {
                Ok(Value::Bool(b)) => Ok(b),
                Ok(v) => Err(PhysicsError::Config(format!(
                    "'{name}' is not a bool: {v:?}"
                ))),
                Err(e) => Err(PhysicsError::Config(e.to_string())),
            })
            .collect()
    }

    /// A bool vertex embedding, true for a row when it is true on any of its orbits.
    pub(crate) fn row_any(&self, name: &str) -> Result<Vec<bool>, PhysicsError> {
        let id = self.id(name)?;
        let mut out = vec![false; self.rows.darts.len()];
        for (&d, &r) in self.rows.orbits.iter().zip(&self.rows.row_of) {
            if let Ok(Value::Bool(true)) = self.g.value(id, d) {
                out[r] = true;
            }
        }
        Ok(out)
    }

    pub(crate) fn check_rows<T>(&self, values: &[T]) -> Result<(), PhysicsError> {
        let n = self.rows.darts.len();
        if values.len() != n {
            return Err(PhysicsError::Config(format!(
                "{} values given for {n} vertices",
                values.len()
            )));
        }
        Ok(())
    }

    /// Sets a vec3 vertex embedding from values in row order (every orbit of a row), as
    /// given: no rule of the supports is applied (the solvers write trial velocities with
    /// it); [`Simulation::set_velocities`] is the user's.
    pub fn set_vertex_vec3(&mut self, name: &str, values: &[[f64; 3]]) -> Result<(), PhysicsError> {
        self.sync_rows()?;
        let id = self.id(name)?;
        self.check_rows(values)?;
        for (&d, &r) in self.rows.orbits.iter().zip(&self.rows.row_of) {
            self.g
                .set_real(id, d, &values[r])
                .map_err(|e| PhysicsError::Config(e.to_string()))?;
        }
        Ok(())
    }

    /// Sets a bool vertex embedding from values in row order (every orbit of a row).
    pub fn set_vertex_bool(&mut self, name: &str, values: &[bool]) -> Result<(), PhysicsError> {
        self.sync_rows()?;
        let id = self.id(name)?;
        self.check_rows(values)?;
        for (&d, &r) in self.rows.orbits.iter().zip(&self.rows.row_of) {
            self.g
                .set_value(id, d, &Value::Bool(values[r]))
                .map_err(|e| PhysicsError::Config(e.to_string()))?;
        }
        Ok(())
    }

    /// Sets the velocities (m/s, row order). Errors: a wrong row count, a held row (`fixed`)
    /// given a non-zero velocity (see [`Simulation::check_held_velocities`]).
    pub fn set_velocities(&mut self, velocities: &[[f64; 3]]) -> Result<(), PhysicsError> {
        self.sync_rows()?;
        self.check_rows(velocities)?;
        self.check_held_velocities(|r| velocities[r])?;
        self.set_vertex_vec3("velocity", velocities)
    }

    /// A held vertex keeps its position and zero velocity: velocities that give one of the
    /// held rows (`fixed`) a non-zero velocity are refused, naming the rows (QA: implicit
    /// Euler moved a held vertex by the velocity it was given, and the kinetic energy and
    /// momentum counted it). `velocity(r)` is row `r`'s.
    pub(crate) fn check_held_velocities(
        &self,
        velocity: impl Fn(usize) -> [f64; 3],
    ) -> Result<(), PhysicsError> {
        let held = self.vertex_bool("fixed")?;
        let moving: Vec<usize> = (0..held.len())
            .filter(|&r| held[r] && velocity(r).iter().any(|&x| x != 0.0))
            .collect();
        if moving.is_empty() {
            return Ok(());
        }
        let (which, are, them) = if moving.len() == 1 {
            ("vertex", "is", "it")
        } else {
            ("vertices", "are", "them")
        };
        Err(PhysicsError::Config(format!(
            "velocities: {which} {} {are} held (fixed), and a held vertex keeps zero velocity: give {them} 0, or free {them} first (set_fixed)",
            list_some(&moving, 20)
        )))
    }

    /// Holds the rows where `mask` is true in place, with zero velocity (and frees the
    /// others, keeping their velocity). Refuses, naming them, to free rows without mass
    /// (they could not move).
    pub fn set_fixed(&mut self, mask: &[bool]) -> Result<(), PhysicsError> {
        self.check_rows(mask)?;
        let m = self.vertex_scalar_sum("mass")?;
        let bad: Vec<usize> = (0..mask.len())
            .filter(|&v| !mask[v] && m[v].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater))
            .collect();
        if !bad.is_empty() {
            return Err(PhysicsError::Config(format!(
                "cannot free vertices without mass (they must stay fixed): {}",
                list_some(&bad, 20)
            )));
        }
        // a row held from now on stops: its velocity is zero (the integrators leave held
        // rows as they are, and implicit Euler would move one by its velocity)
        let vel = self.id("velocity")?;
        for (&d, &r) in self.rows.orbits.iter().zip(&self.rows.row_of) {
            if mask[r] {
                self.g
                    .set_real(vel, d, &[0.0; 3])
                    .map_err(|e| PhysicsError::Config(e.to_string()))?;
            }
        }
        self.set_vertex_bool("fixed", mask)
    }

    /// Writes a stored vertex embedding of type `f64`, `vec3` or `bool` from one value per row
    /// (every orbit of a row gets its row's value; but a force, see [`is_additive`], is the
    /// row's total: its first orbit gets it and the others zero). An embedding that the rules declare but
    /// the map does not hold yet is added first. Refuses another orbit or type, a derived
    /// embedding, a wrong count, and non-finite values (naming every offending row, up to 20).
    pub fn set_vertex_field(&mut self, name: &str, values: &[Value]) -> Result<(), PhysicsError> {
        self.sync_rows()?;
        if self.g.embedding_id(name).is_none()
            && self.rules.embeddings().iter().any(|e| e.name == name)
        {
            self.rules.prepare_named(&mut self.g, &[name])?;
        }
        let vertex = OrbitType::vertex(self.g.dimension());
        let Some(id) = self.g.embedding_id(name) else {
            let names: Vec<&str> = self
                .g
                .embeddings()
                .iter()
                .filter(|e| e.orbit() == vertex && e.derived().is_none())
                .map(topomech_gmap::Embedding::name)
                .collect();
            return Err(PhysicsError::Config(format!(
                "no vertex embedding '{name}' (the map's stored vertex embeddings: {})",
                names.join(", ")
            )));
        };
        let e = self.g.embedding(id);
        if e.orbit() != vertex {
            return Err(PhysicsError::Config(format!(
                "embedding '{name}' is on the orbit {}, not on the vertex orbit {vertex}",
                e.orbit()
            )));
        }
        if e.derived().is_some() {
            return Err(PhysicsError::Config(format!(
                "embedding '{name}' is derived (computed from another one): it cannot be written"
            )));
        }
        let ty = e.ty();
        if !matches!(
            ty,
            EmbeddingType::F64 | EmbeddingType::Vec3 | EmbeddingType::Bool
        ) {
            return Err(PhysicsError::Config(format!(
                "embedding '{name}' has type {ty}: only f64, vec3 and bool vertex embeddings can be set per vertex"
            )));
        }
        self.check_rows(values)?;
        let mut bad_type = Vec::new();
        let mut non_finite = Vec::new();
        for (k, v) in values.iter().enumerate() {
            match (ty, v) {
                (EmbeddingType::Bool, Value::Bool(_)) => {}
                (EmbeddingType::F64, Value::Real(x)) if x.len() == 1 => {}
                (EmbeddingType::Vec3, Value::Real(x)) if x.len() == 3 => {}
                _ => bad_type.push(k),
            }
            if let Value::Real(x) = v {
                if x.iter().any(|x| !x.is_finite()) {
                    non_finite.push(k);
                }
            }
        }
        if !bad_type.is_empty() {
            return Err(PhysicsError::Config(format!(
                "'{name}' is a {ty}: not so at vertices {}",
                list_some(&bad_type, 20)
            )));
        }
        if !non_finite.is_empty() {
            return Err(PhysicsError::Config(format!(
                "'{name}' must be finite: not so at vertices {}",
                list_some(&non_finite, 20)
            )));
        }
        // the support's rules: holding stops a vertex (and refuses to free one without
        // mass); a held vertex has no velocity
        if name == "fixed" {
            let mask: Vec<bool> = values
                .iter()
                .map(|v| matches!(v, Value::Bool(true)))
                .collect();
            return self.set_fixed(&mask);
        }
        if name == "velocity" {
            self.check_held_velocities(|r| match &values[r] {
                Value::Real(x) => [x[0], x[1], x[2]],
                _ => [0.0; 3],
            })?;
        }
        // a force is a row's total: on the row's first orbit, zero on the others (the
        // accumulation sums them, the step shares the sum by mass)
        let share = is_additive(name);
        let zero = Value::Real(vec![0.0; ty.width()]);
        for (&d, &r) in self.rows.orbits.iter().zip(&self.rows.row_of) {
            let v = if share && self.rows.darts[r] != d {
                &zero
            } else {
                &values[r]
            };
            self.g
                .set_value(id, d, v)
                .map_err(|e| PhysicsError::Config(e.to_string()))?;
        }
        Ok(())
    }

    /// Sets the external loads `f_ext` (N, one row per vertex, in row order): constant
    /// forces the accumulation adds into `force` every step and the static solve balances.
    /// Each row's load is written on one vertex orbit of the row (a welded row's other orbits
    /// get zero), so that the row's total is the value given.
    /// Errors: a wrong row count, a non-finite value (naming the rows).
    pub fn set_external_forces(&mut self, forces: &[[f64; 3]]) -> Result<(), PhysicsError> {
        let values: Vec<Value> = forces.iter().map(|f| Value::Real(f.to_vec())).collect();
        self.set_vertex_field("f_ext", &values)
    }

    /// The external loads `f_ext` (N) in row order (a welded row's total).
    pub fn external_forces(&self) -> Result<Vec<[f64; 3]>, PhysicsError> {
        self.vertex_vec3_sum("f_ext")
    }

    /// Writes every value of the stored embedding `name`, one per orbit of its orbit type by
    /// smallest dart ([`GMap::set_orbit_values`], which also recomputes derived embeddings).
    /// Refuses the embeddings the simulation numbers its rows and elements with (`particle`,
    /// `point_id`, `cell_id`, `vertex0`, `face0`), naming them, and values of the material
    /// and mass embeddings the shipped prelude declares that no material has
    /// ([`material_value_problem`]: a `density`, `young` or `corner_mass` not positive, a `poisson`
    /// outside (-1, 0.5)), naming the embedding, the value and its orbit's index, as the
    /// scene and the constructor refuse them (QA: a negative `corner_mass` made the total
    /// mass -192 and the steps ran).
    pub fn set_orbit_values(
        &mut self,
        name: &str,
        values: topomech_gmap::ColumnRef<'_>,
    ) -> Result<(), PhysicsError> {
        const NUMBERING: [&str; 5] = ["particle", "point_id", "cell_id", "vertex0", "face0"];
        if NUMBERING.contains(&name) {
            return Err(PhysicsError::Config(format!(
                "embedding '{name}' numbers the simulation's rows or elements and cannot be written ({} are set when the simulation is built)",
                NUMBERING.join(", ")
            )));
        }
        if let topomech_gmap::ColumnRef::Real(v) = values {
            if let Some(why) = material_value_problem(name, v) {
                return Err(PhysicsError::Config(why));
            }
        }
        self.sync_rows()?;
        let id = self.id(name)?;
        // the values before, slot by slot (a write changes values only, never the slots)
        let before: Option<(Vec<f64>, Vec<bool>)> = match name {
            "velocity" | "fixed" => match self.g.embedding(id).column() {
                topomech_gmap::ColumnRef::Real(v) => Some((v.to_vec(), Vec::new())),
                topomech_gmap::ColumnRef::Bool(v) => Some((Vec::new(), v.to_vec())),
                topomech_gmap::ColumnRef::Int(_) => None,
            },
            _ => None,
        };
        self.g
            .set_orbit_values(id, values)
            .map_err(|e| PhysicsError::Config(e.to_string()))?;
        let Some(before) = before else {
            return Ok(());
        };
        let restore = |g: &mut GMap| match g.column_mut(id) {
            Ok(topomech_gmap::ColumnMut::Real(v)) if v.len() == before.0.len() => {
                v.copy_from_slice(&before.0);
            }
            Ok(topomech_gmap::ColumnMut::Bool(v)) if v.len() == before.1.len() => {
                v.copy_from_slice(&before.1);
            }
            _ => {}
        };
        // the supports' rules, as `set_fixed` and `set_velocities` keep them (QA: this way
        // round them, a held vertex kept a velocity, and implicit Euler moved it): holding
        // goes through `set_fixed`; a velocity for a held row is refused; either way the
        // embedding is as it was before a refusal
        let outcome = if name == "fixed" {
            let mask = self.vertex_bool("fixed");
            restore(&mut self.g);
            mask.and_then(|m| self.set_fixed(&m))
        } else {
            self.vertex_vec3("velocity")
                .and_then(|v| self.check_held_velocities(|r| v[r]))
        };
        if outcome.is_err() {
            restore(&mut self.g);
        }
        outcome
    }

    /// Total mass (sum of the vertex masses).
    pub fn total_mass(&self) -> Result<f64, PhysicsError> {
        Ok(self.vertex_scalar_sum("mass")?.iter().sum())
    }

    /// Kinetic energy, sum over rows of m |v|^2 / 2 (a welded row counts once, with its
    /// whole mass).
    pub fn kinetic_energy(&self) -> Result<f64, PhysicsError> {
        let m = self.vertex_scalar_sum("mass")?;
        let v = self.vertex_vec3("velocity")?;
        Ok(m.iter()
            .zip(&v)
            .map(|(m, v)| 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]))
            .sum())
    }

    /// Linear momentum, sum over rows of m v.
    pub fn momentum(&self) -> Result<[f64; 3], PhysicsError> {
        let m = self.vertex_scalar_sum("mass")?;
        let v = self.vertex_vec3("velocity")?;
        let mut p = [0.0; 3];
        for (m, v) in m.iter().zip(&v) {
            for a in 0..3 {
                p[a] += m * v[a];
            }
        }
        Ok(p)
    }
}

/// A test on one value, and what the value must be (for messages).
type ValueRange = (fn(f64) -> bool, &'static str);

/// The values a material or mass embedding of the shipped prelude takes (a test on one value,
/// and what it must be), `None` for other names: `density` (kg/m^3, per area in 2D), `young`
/// (Pa) and the `corner_mass` that vertex masses sum (kg) are positive and finite, `poisson`
/// lies in (-1, 0.5) (the range in which the isotropic elasticity tensor is positive
/// definite; Lamé's first parameter diverges at 0.5).
fn material_range(name: &str) -> Option<ValueRange> {
    fn positive(x: f64) -> bool {
        x > 0.0 && x.is_finite()
    }
    fn poisson(x: f64) -> bool {
        -1.0 < x && x < 0.5
    }
    match name {
        "density" | "young" | "corner_mass" => Some((positive, "must be positive and finite")),
        "poisson" => Some((poisson, "must be in (-1, 0.5)")),
        _ => None,
    }
}

/// Why `values` (one per orbit, in the order of the embedding's orbits) cannot be written to
/// the material or mass embedding `name` of the shipped prelude (see `material_range`): the
/// first value out of range, with its row; `None` when they can, or for another name.
pub fn material_value_problem(name: &str, values: &[f64]) -> Option<String> {
    let (ok, must) = material_range(name)?;
    let k = values.iter().position(|&x| !ok(x))?;
    Some(format!(
        "'{name}' {must}: got {:?} at row {k} of the values (one per orbit, in the order of the embedding's orbits)",
        values[k]
    ))
}
