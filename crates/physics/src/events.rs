//! Topology changes during a run: timed cuts and fracture.

use topomech_rules::{Params, Val};

use crate::*;

/// Where a cut goes: along element boundaries, the faces (3D) or edges (2D) between two elements
/// that the geometry separates.
#[derive(Clone, Debug, PartialEq)]
pub enum Cut {
    /// The plane `normal . x = offset`: elements whose centroids (at the time of the cut) lie
    /// on opposite sides are separated.
    Plane {
        /// Normal of the plane.
        normal: [f64; 3],
        /// Its offset.
        offset: f64,
    },
    /// A predicate on the centroid `x`, `y`, `z` of the shared face (3D) or edge (2D).
    Where(String),
}

/// A topology change at a time.
#[derive(Clone, Debug, PartialEq)]
pub struct TimedEvent {
    /// When (s).
    pub time: f64,
    /// The cut.
    pub cut: Cut,
}

/// What opens a face (3D) or an edge (2D) during the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Criterion {
    /// The mean of the largest principal stresses of the two elements (tetrahedra).
    Stress,
    /// The strain of springs: the mean over the face's edges (3D), the edge's (2D; tearing).
    Strain,
}

/// Fracture settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fracture {
    /// The criterion.
    pub criterion: Criterion,
    /// Its threshold (a stress in Pa, or a strain).
    pub threshold: f64,
}

/// A topology change that happened.
#[derive(Clone, Debug, PartialEq)]
pub struct TopologyChange {
    /// The step after which it happened.
    pub step: u64,
    /// The time.
    pub time: f64,
    /// `cut` or `fracture`.
    pub kind: &'static str,
    /// Faces (3D) or edges (2D) unsewn.
    pub unsewn: usize,
}

/// What a topology change did ([`Simulation::cut`], [`Simulation::fracture`]).
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct TopologyResult {
    /// Faces (3D) or edges (2D) unsewn.
    pub unsewn: usize,
    /// The rows appended for the vertex orbits the change split off, in increasing order;
    /// each has the `point_id` of the vertex it was split from. Existing rows keep their
    /// meaning.
    pub added_rows: Vec<usize>,
}

impl Simulation {
    /// Applies the events whose time has come and the fracture criterion.
    pub(crate) fn topology_events(&mut self) -> Result<(), PhysicsError> {
        for k in 0..self.cfg.events.len() {
            if !self.events_done[k] && self.cfg.events[k].time <= self.time + 1e-9 * self.cfg.dt {
                self.events_done[k] = true;
                let cut = self.cfg.events[k].cut.clone();
                let n = self.apply_cut(&cut, Some(k))?.unsewn;
                if n == 0 {
                    return Err(PhysicsError::Config(format!(
                        "the cut {cut:?} at t = {} separates nothing: it misses the object",
                        self.cfg.events[k].time
                    )));
                }
            }
        }
        if let Some(f) = self.cfg.fracture {
            self.fracture(f)?;
        }
        Ok(())
    }

    /// Opens now every face (3D) or edge (2D) where the criterion passes the threshold; returns
    /// how many, and the rows appended for the vertices that split (existing rows keep their
    /// meaning).
    pub fn fracture(&mut self, f: Fracture) -> Result<TopologyResult, PhysicsError> {
        let none = Params::new();
        let measure = match f.criterion {
            Criterion::Stress => "element_stress",
            Criterion::Strain => "spring_strains",
        };
        if self.rules.rule(measure).is_err() {
            return Err(PhysicsError::Config(
                "the stress criterion needs the fracture configured when the simulation is built"
                    .into(),
            ));
        }
        self.rules.apply_everywhere(&mut self.g, measure, &none)?;
        // The guards of the shipped criteria compare a mean of the measure with the threshold
        // (the mean spring strain of a face's edges; the mean of the two elements' largest
        // principal stresses): no mean exceeds the largest value of the measure's column, so
        // when no value exceeds the threshold nothing can open and the search over the faces
        // is skipped. A mean of k values at most T rounds to at most T (1 + k eps): the bound
        // keeps a margin of 64 eps |T| (k is at most a face's 8 half-edges, or 2). Dead slots
        // hold old values and NaN compares as "may exceed": either only sends the step to the
        // search, which decides.
        let column = match f.criterion {
            Criterion::Stress => "max_stress",
            Criterion::Strain => "spring_strain",
        };
        if let Some(id) = self.g.embedding_id(column) {
            if let Some(values) = self.g.embedding(id).real_column() {
                let bound = f.threshold - 64.0 * f64::EPSILON * f.threshold.abs();
                if values.iter().all(|&x| x <= bound) {
                    return Ok(TopologyResult::default());
                }
            }
        }
        let p: Params = [("threshold".to_string(), Val::F(f.threshold))].into();
        let rule = if f.criterion == Criterion::Stress {
            "fracture_stress"
        } else {
            "fracture_strain"
        };
        let n = self.rules.apply_everywhere(&mut self.g, rule, &p)?.matches;
        let mut added_rows = Vec::new();
        if n > 0 {
            self.changes.push(TopologyChange {
                step: self.steps,
                time: self.time,
                kind: "fracture",
                unsewn: n,
            });
            added_rows = self.after_topology_change()?;
        }
        Ok(TopologyResult {
            unsewn: n,
            added_rows,
        })
    }

    /// Cuts now; returns the number of faces (3D) or edges (2D) unsewn and the rows appended
    /// for the vertices that split (existing rows keep their meaning).
    pub fn cut(&mut self, cut: &Cut) -> Result<TopologyResult, PhysicsError> {
        if let Cut::Where(_) = cut {
            return Err(PhysicsError::Config(
                "a predicate cut must be declared in the configuration's events".into(),
            ));
        }
        self.apply_cut(cut, None)
    }

    pub(crate) fn apply_cut(
        &mut self,
        cut: &Cut,
        event: Option<usize>,
    ) -> Result<TopologyResult, PhysicsError> {
        let n = match cut {
            Cut::Plane { normal, offset } => {
                let p: Params = [
                    ("normal".to_string(), Val::V3(*normal)),
                    ("offset".to_string(), Val::F(*offset)),
                ]
                .into();
                self.rules
                    .apply_everywhere(&mut self.g, "cut_plane", &p)?
                    .matches
            }
            Cut::Where(_) => {
                let k = event.expect("predicate cuts are events");
                self.rules
                    .apply_everywhere(&mut self.g, &format!("cut_where_{k}"), &Params::new())?
                    .matches
            }
        };
        let mut added_rows = Vec::new();
        if n > 0 {
            self.changes.push(TopologyChange {
                step: self.steps,
                time: self.time,
                kind: "cut",
                unsewn: n,
            });
            added_rows = self.after_topology_change()?;
        }
        Ok(TopologyResult {
            unsewn: n,
            added_rows,
        })
    }

    /// After a change: derived embeddings refreshed, and the new vertex orbits numbered
    /// (appended rows); returns the rows added.
    pub(crate) fn after_topology_change(&mut self) -> Result<Vec<usize>, PhysicsError> {
        self.g.refresh_derived();
        self.sync_rows()
    }

    /// Refuses events that a run ending at `end_time` would never reach.
    pub fn check_events(&self, end_time: f64) -> Result<(), PhysicsError> {
        for e in &self.cfg.events {
            if e.time > end_time + 1e-9 * self.cfg.dt {
                return Err(PhysicsError::Config(format!(
                    "the event at t = {} comes after the end of the run (t = {end_time}): it would never happen",
                    e.time
                )));
            }
        }
        Ok(())
    }

    /// The topology changes so far.
    pub fn topology_changes(&self) -> &[TopologyChange] {
        &self.changes
    }
}
