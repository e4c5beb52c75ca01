//! A time step: forces, accumulation and the explicit integrators.

use topomech_gmap::{ColumnMut, Dart, EmbeddingId, GMap};
use topomech_rules::{ApplyError, Params, Val};

use crate::{norm3, Integrator, PhysicsError, Simulation};

impl Simulation {
    /// One time step: forces, accumulation, integration. On divergence (a non-finite
    /// position or velocity) the state before the step is restored and an error names the
    /// step and the vertex.
    pub fn step(&mut self) -> Result<(), PhysicsError> {
        if self.steps == 0 {
            // the body may have moved since the set-up checked it (a scene's initial
            // displacement, `set_positions`)
            self.check_ground()?;
        }
        let pos = self.id("position")?;
        let vel = self.id("velocity")?;
        // An explicit step without ground contact writes positions and velocities in one
        // rule, the integrator, whose values are tested before they are written
        // (`explicit_checked`): nothing to save, nothing to scan after. Where that cannot
        // be done, the state before the step is saved and tested after.
        let checked = match self.cfg.integrator {
            Integrator::ExplicitEuler => self.explicit_checked("explicit_euler", vel),
            Integrator::SymplecticEuler => self.explicit_checked("symplectic_euler", vel),
            Integrator::ImplicitEuler | Integrator::Static => Checked::NotTested,
        };
        let (result, saved) = if let Checked::Done(result) = checked {
            (result, false)
        } else {
            let ready = matches!(checked, Checked::ForcesReady);
            self.saving_steps += 1;
            // the state before the step: the whole position and velocity columns (kept to
            // restore them on divergence; a step changes values only, never the slots)
            for (id, saved) in [pos, vel].into_iter().zip(&mut self.saved) {
                let column = self.g.embedding(id).real_column().ok_or_else(|| {
                    PhysicsError::Config("position and velocity must be vec3".into())
                })?;
                saved.clear();
                saved.extend_from_slice(column);
            }
            let result = match self.cfg.integrator {
                Integrator::ExplicitEuler => self.explicit("explicit_euler", ready),
                Integrator::SymplecticEuler => self.explicit("symplectic_euler", ready),
                Integrator::ImplicitEuler => self.implicit_euler(),
                Integrator::Static => self.solve_static(),
            };
            (result, true)
        };
        let bad = match &result {
            // a rule computed a non-finite value (and wrote nothing): name its vertex
            Err(PhysicsError::Apply(ApplyError::NonFinite {
                rule,
                embedding,
                dart,
                value,
            })) => Some((
                Some(self.vertex_of(*dart, pos)),
                format!("rule '{rule}' computed a non-finite value {value} for '{embedding}' (dart {dart})"),
            )),
            // a built-in refusing its argument (a non-finite matrix for `polar`, ...): its
            // dart names the vertex too
            Err(PhysicsError::Apply(e @ ApplyError::Eval { dart, .. })) => {
                Some((Some(self.vertex_of(*dart, pos)), e.to_string()))
            }
            Err(e) => Some((None, e.to_string())),
            // tested before they were written (`explicit_checked`)
            Ok(()) if !saved => None,
            // every slot scanned in order first (dead slots included: they hold old, finite
            // values), the vertices searched one by one only to name the one that fails
            Ok(()) if self.columns_sane(pos, vel) => None,
            // the first vertex with a non-finite value, else the fastest one where it runs
            // away: crossing more than the whole object in one step relative to its part's
            // mean motion (a piece in uniform motion or falling freely, however fast, is not
            // running away). An implicit step moves the vertices coupled to a runaway one
            // too, and the first of those in row order is not the one to blame
            Ok(()) => self.runaway(pos, vel),
        };
        if let Some((vertex, why)) = bad {
            // (without the copy, the step failed before writing any position or velocity)
            if saved {
                for (id, copy) in [pos, vel].into_iter().zip(&self.saved) {
                    if let Ok(ColumnMut::Real(v)) = self.g.column_mut(id) {
                        if v.len() == copy.len() {
                            v.copy_from_slice(copy);
                        }
                    }
                }
            }
            let e = match result {
                // the step's own finding, or a rule's non-finite value (its why says which)
                Ok(()) | Err(PhysicsError::Apply(ApplyError::NonFinite { .. })) => {
                    PhysicsError::diverged(self.steps + 1, vertex, why)
                }
                Err(PhysicsError::Apply(e)) => {
                    PhysicsError::diverged(self.steps + 1, vertex, e.to_string())
                }
                Err(e) => e,
            };
            return Err(self.with_input_point(e));
        }
        self.steps += 1;
        self.time += self.cfg.dt;
        let events = self.topology_events();
        // the matches shared by rules of one pattern while this step planned them: its plans
        // hold what they need
        self.rules.clear_shared_matches();
        events
    }

    /// How many steps so far (taken or refused) copied the positions and velocities before
    /// integrating, to restore them on divergence: implicit Euler and static steps, an
    /// explicit step whose integrator's values were refused before being written (a
    /// runaway vertex, say), and every step through the interpreter
    /// ([`Simulation::set_compiled`] off). An explicit step of compiled plans, with or
    /// without a ground plane, tests its values before writing them and copies nothing.
    pub fn steps_saving_state(&self) -> usize {
        self.saving_steps
    }

    /// `e` with the input point of its vertex row filled in (a [`PhysicsError::Diverged`]
    /// naming a row, on a map with `point_id`); other errors as they are.
    pub(crate) fn with_input_point(&self, e: PhysicsError) -> PhysicsError {
        match e {
            PhysicsError::Diverged {
                step,
                vertex: Some(v),
                point: None,
                why,
            } => {
                let point = self.input_point(v);
                PhysicsError::Diverged {
                    step,
                    vertex: Some(v),
                    point,
                    why,
                }
            }
            e => e,
        }
    }

    /// The slow runaway test of a step that saved the state (what the fast test, one pass
    /// over the velocities less [`Simulation::frame`](crate::Simulation) at half the
    /// object's size per step, could not pass): the first row with a non-finite position or
    /// velocity, else the row moving fastest relative to the mean velocity of its part (the
    /// map's connected components, joined where a welded row holds orbits of several),
    /// where that carries it more than the object's size in one step, with why; `None`
    /// when nothing runs away. A relative motion below 8 (n + 1) eps of the vertex's own
    /// (n rows) is within the rounding of the mean, not a runaway. When nothing runs away and the body is one
    /// part, its mean becomes the frame of the next fast tests: passing them (every
    /// velocity within half the limit of the frame) implies passing this one (the mean of
    /// velocities all within a distance of the frame lies within it too).
    fn runaway(&mut self, pos: EmbeddingId, vel: EmbeddingId) -> Option<(Option<usize>, String)> {
        let (part, means) = self.part_mean_velocities(vel);
        let dt = self.cfg.dt;
        // the rounding of a running mean of n values (a few eps per update) and of the
        // difference, relative to the vertex's own motion
        #[allow(clippy::cast_precision_loss)]
        let rounding = 8.0 * (self.rows.darts.len() as f64 + 1.0) * f64::EPSILON;
        let mut fastest: Option<(usize, f64)> = None;
        let non_finite = self.rows.darts.iter().enumerate().find_map(|(v, d)| {
            let (p, u) = (self.g.real(pos, *d), self.g.real(vel, *d));
            if p.iter().chain(u).any(|x| !x.is_finite()) {
                return Some(v);
            }
            let m = means[part[v]];
            let step = norm3([u[0] - m[0], u[1] - m[1], u[2] - m[2]]) * dt;
            let own = norm3([u[0], u[1], u[2]]) * dt;
            if step > rounding * own && fastest.is_none_or(|(_, s)| step > s) {
                fastest = Some((v, step));
            }
            None
        });
        match (non_finite, fastest) {
            (Some(v), _) => Some((Some(v), "non-finite position or velocity".to_string())),
            (None, Some((v, step))) if step > self.size => Some((
                Some(v),
                format!("runaway motion: the vertex's new velocity, relative to the mean velocity of its part of the body, would carry it {step:.3e} in one step, more than the object's size ({:.3e})", self.size),
            )),
            (None, _) => {
                self.frame = if means.len() == 1 { means[0] } else { [0.0; 3] };
                None
            }
        }
    }

    /// Each row's part of the body (the map's connected components, joined where a welded
    /// row holds vertex orbits of several; numbered from 0 in row order) and the number of
    /// parts: found once per topology version (a walk of every dart), kept until the map
    /// changes.
    pub(crate) fn parts(&mut self) -> (Vec<usize>, usize) {
        let identity = self.g.identity();
        if let Some((at, part, count)) = &self.parts {
            if *at == identity && part.len() == self.rows.darts.len() {
                return (part.clone(), *count);
            }
        }
        // the component of each dart, then of each row (joined through welded rows)
        let mut comps = Components::new(&self.g);
        let mut parent: Vec<usize> = Vec::new();
        let g = &self.g;
        let mut component = |d: Dart, parent: &mut Vec<usize>| -> usize {
            let c = comps.of(g, d);
            if c == parent.len() {
                parent.push(c); // a new component, numbered next
            }
            c
        };
        let mut row_comp: Vec<usize> = self
            .rows
            .darts
            .iter()
            .map(|&d| component(d, &mut parent))
            .collect();
        for (row, darts) in &self.rows.welded {
            for &d in darts {
                let c = component(d, &mut parent);
                let (a, b) = (root(&mut parent, row_comp[*row]), root(&mut parent, c));
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
        // parts numbered in row order
        let mut number: Vec<usize> = vec![usize::MAX; parent.len()];
        let mut parts = 0;
        for c in &mut row_comp {
            let r = root(&mut parent, *c);
            if number[r] == usize::MAX {
                number[r] = parts;
                parts += 1;
            }
            *c = number[r];
        }
        self.parts = Some((identity, row_comp.clone(), parts));
        (row_comp, parts)
    }

    /// Each row's part of the body ([`Simulation::parts`]) and each part's mean velocity:
    /// its rows' velocities weighted by their masses (the row's total, over its orbits), as
    /// a running mean (no sum that overflows), or the plain mean where the masses are not
    /// finite and positive; zero where the mean is not finite.
    fn part_mean_velocities(&mut self, vel: EmbeddingId) -> (Vec<usize>, Vec<[f64; 3]>) {
        let n = self.rows.darts.len();
        let (row_comp, parts) = self.parts();
        let masses = self.vertex_scalar_sum("mass").ok().filter(|m| m.len() == n);
        let top = masses
            .as_ref()
            .map_or(0.0, |m| m.iter().fold(0.0_f64, |a, &x| a.max(x)));
        let weighted = top > 0.0
            && top.is_finite()
            && masses
                .as_ref()
                .is_some_and(|m| m.iter().all(|x| x.is_finite() && *x >= 0.0));
        let mut mean = vec![[0.0; 3]; parts];
        let mut weight = vec![0.0; parts];
        for (v, d) in self.rows.darts.iter().enumerate() {
            let u = self.g.real(vel, *d);
            let w = match (&masses, weighted) {
                (Some(m), true) => m[v] / top,
                _ => 1.0,
            };
            if w <= 0.0 || u.len() < 3 {
                continue;
            }
            let p = row_comp[v];
            weight[p] += w;
            let f = w / weight[p];
            for a in 0..3 {
                mean[p][a] += f * (u[a] - mean[p][a]);
            }
        }
        for m in &mut mean {
            if !m.iter().all(|x| x.is_finite()) {
                *m = [0.0; 3];
            }
        }
        (row_comp, mean)
    }

    /// The row of the vertex whose orbit holds `dart`, by the slot of the vertex
    /// embedding `pos`; 0 if none does.
    pub(crate) fn vertex_of(&self, dart: Dart, pos: EmbeddingId) -> usize {
        let e = self.g.embedding(pos);
        if !self.g.is_alive(dart) {
            return 0;
        }
        let slot = e.slot(dart);
        self.rows
            .orbits
            .iter()
            .zip(&self.rows.row_of)
            .find(|(d, _)| e.slot(**d) == slot)
            .map_or(0, |(_, &r)| r)
    }

    /// Whether every value of the position and velocity columns is finite and no velocity
    /// moves a vertex further than the object's size in one step: the test of
    /// [`Simulation::step`] over whole columns, in order. One pass per column without early
    /// exit or square root, so that it vectorizes; it errs on the safe side: it passes only
    /// where the vertex test of `step` (`|v| dt <= size`, with the square root) passes for
    /// every vertex, and where it fails, that test looks for the vertex (and may find none
    /// within the margin of 1e-9 relative of [`speed_limit`]).
    pub(crate) fn columns_sane(&self, pos: EmbeddingId, vel: EmbeddingId) -> bool {
        let (Some(p), Some(v)) = (
            self.g.embedding(pos).real_column(),
            self.g.embedding(vel).real_column(),
        ) else {
            return false;
        };
        let finite = !p.iter().fold(false, |bad, x| bad | !x.is_finite());
        finite && velocities_slow(v, speed_limit(0.5 * self.size, self.cfg.dt), self.frame)
    }

    /// The explicit step of [`Simulation::explicit`] with the integrator's values tested
    /// before they are written ([`RuleSet::apply_everywhere_checked`]): every velocity
    /// written must move its vertex at most the object's size in one step (the test of
    /// [`Simulation::columns_sane`], with its margin), every value finite. [`Checked`] says
    /// where the step must go the other way, with nothing written to positions or
    /// velocities: ground contact configured (a second rule writes them), plans off, or the
    /// integrator's values refused or not testable (then the other way takes the step again,
    /// from the forces computed here, and names the vertex).
    ///
    /// [`RuleSet::apply_everywhere_checked`]: topomech_rules::RuleSet::apply_everywhere_checked
    fn explicit_checked(&mut self, rule: &str, vel: EmbeddingId) -> Checked {
        if !self.rules.compiled() {
            return Checked::NotTested;
        }
        // (half the distance, from the frame: see `runaway`)
        let limit = speed_limit(0.5 * self.size, self.cfg.dt);
        let frame = self.frame;
        // with a ground plane, the integrator and the ground rule in one rule (glue.tmr:
        // the same operations, so the same bits as the two in turn)
        let ground = match &self.cfg.ground {
            None => None,
            Some(g) => match g.plane(self.cfg.gravity) {
                Ok((p, n)) => {
                    let mut params = self.step_params.clone();
                    params.insert("p".to_string(), Val::V3(p));
                    params.insert("n".to_string(), Val::V3(n));
                    // the fast runaway test's bound, a little looser (see glue.tmr): a
                    // velocity the rule leaves unprojected as a runaway is one the test
                    // below refuses
                    params.insert("limit".to_string(), Val::F(limit * (1.0 + 1e-9)));
                    params.insert("frame".to_string(), Val::V3(frame));
                    Some((format!("{rule}_ground"), params))
                }
                // the saving way reports it
                Err(_) => return Checked::NotTested,
            },
        };
        if let Err(e) = self.forces().and_then(|()| self.share_welded_forces()) {
            return Checked::Done(Err(e));
        }
        let check = |id: EmbeddingId, v: &[f64]| id != vel || velocities_slow(v, limit, frame);
        let (rule, params) = match &ground {
            Some((r, p)) => (r.as_str(), p),
            None => (rule, &self.step_params),
        };
        match self
            .rules
            .apply_everywhere_checked(&mut self.g, rule, params, &check)
        {
            Ok(Some(_)) => Checked::Done(Ok(())),
            Ok(None) => Checked::ForcesReady,
            Err(e) => Checked::Done(Err(e.into())),
        }
    }

    /// An explicit step: forces (unless `forces_ready`: computed at these positions
    /// already), the integrator `rule`, ground contact.
    fn explicit(&mut self, rule: &str, forces_ready: bool) -> Result<(), PhysicsError> {
        if !forces_ready {
            self.forces()?;
            self.share_welded_forces()?;
        }
        self.rules
            .apply_everywhere(&mut self.g, rule, &self.step_params)?;
        if self.cfg.ground.is_some() {
            // a runaway is one before the ground's projection, which would hide a vertex
            // sent into the plane (its velocity into it dropped, the vertex put back onto
            // it, or, from far enough, beside it: the projection cancels); the caller
            // restores the state (it saved it: this way always does)
            let (pos, vel) = (self.id("position")?, self.id("velocity")?);
            if !self.columns_sane(pos, vel) {
                if let Some((vertex, why)) = self.runaway(pos, vel) {
                    return Err(PhysicsError::diverged(self.steps + 1, vertex, why));
                }
            }
        }
        self.contact()
    }

    /// The ground plane, if any.
    pub(crate) fn contact(&mut self) -> Result<(), PhysicsError> {
        if let Some(ground) = &self.cfg.ground {
            let (point, normal) = ground.plane(self.cfg.gravity)?;
            let p: Params = [
                ("p".to_string(), Val::V3(point)),
                ("n".to_string(), Val::V3(normal)),
            ]
            .into();
            self.rules.apply_everywhere(&mut self.g, "ground", &p)?;
        }
        Ok(())
    }

    /// Gives every orbit of a welded row the share of the row's total force in proportion to
    /// its mass, so that each orbit's acceleration `force / mass` (and with it gravity and
    /// viscous damping, which act per unit mass on the shared velocity) is the row's
    /// `F_total / M_total`: the orbits move as one particle. Nothing to do (no allocation, no
    /// orbit walk) for maps without welded rows.
    pub(crate) fn share_welded_forces(&mut self) -> Result<(), PhysicsError> {
        if self.rows.welded.is_empty() {
            return Ok(());
        }
        let force = self.id("force")?;
        let mass = self.id("mass")?;
        let err = |e: topomech_gmap::EmbeddingError| PhysicsError::Config(e.to_string());
        for (_, darts) in &self.rows.welded {
            let mut f = [0.0; 3];
            let mut m = 0.0;
            for &d in darts {
                let x = self.g.real(force, d);
                for a in 0..3 {
                    f[a] += x[a];
                }
                m += self.g.real(mass, d)[0];
            }
            if m.is_nan() || m <= 0.0 {
                continue;
            }
            for &d in darts {
                let share = self.g.real(mass, d)[0] / m;
                self.g
                    .set_real(force, d, &[f[0] * share, f[1] * share, f[2] * share])
                    .map_err(err)?;
            }
        }
        Ok(())
    }

    /// Computes every model's forces and their sum `force` on each vertex.
    pub fn forces(&mut self) -> Result<(), PhysicsError> {
        // force embeddings (named f_*) are rewritten every step; a pattern that no longer
        // matches after a topology change must not leave a stale force behind (but not the
        // external loads, which the user sets once)
        let forces: Vec<topomech_gmap::EmbeddingId> = (0..self.g.embeddings().len())
            .map(|k| topomech_gmap::EmbeddingId(k as u32))
            .filter(|&id| {
                let e = self.g.embedding(id);
                e.name().starts_with("f_") && e.name() != "f_ext" && e.derived().is_none()
            })
            .collect();
        // The reset is needed only when the step rules may write other slots than they did
        // last time: after a topology change, after a write by anyone else (a user, a solver),
        // or where a guard decides per step which matches write. Otherwise every slot they
        // write is overwritten and every other slot still holds the reset's zero.
        let writes =
            |g: &GMap| -> Vec<u64> { forces.iter().map(|&id| g.embedding(id).writes()).collect() };
        let unguarded = self.defs.iter().all(|def| {
            def.step
                .iter()
                .all(|(r, _)| self.rules.rule(r).is_ok_and(|r| r.guard.is_none()))
        });
        let clean = unguarded
            && self
                .forces_written
                .as_ref()
                .is_some_and(|(id, w)| *id == self.g.identity() && *w == writes(&self.g));
        self.forces_written = None;
        if !clean {
            for &id in &forces {
                self.g
                    .reset_values(id)
                    .map_err(|e| PhysicsError::Config(e.to_string()))?;
            }
        }
        // the forces are rewritten at every step: each chunk of a plan's rows is written as
        // soon as it is evaluated (on an error, some may be written; the step fails)
        let none = Params::new();
        for def in &self.defs {
            for (r, p) in &def.step {
                self.rules.apply_everywhere_eager(&mut self.g, r, p)?;
            }
        }
        self.forces_written = Some((self.g.identity(), writes(&self.g)));
        self.rules
            .apply_everywhere_eager(&mut self.g, "accumulate", &none)?;
        Ok(())
    }

    /// Whether the computation rules run through compiled plans (the default) or through the
    /// interpreter only: both give the same results; the switch exists to compare them.
    pub fn set_compiled(&mut self, on: bool) {
        self.rules.set_compiled(on);
    }

    /// Whether compiled plans run native code (see [`topomech_rules::RuleSet::set_jit`]):
    /// the same results bit for bit; the default is on, unless the environment variable
    /// `TOPOMECH_JIT` is `0`.
    pub fn set_jit(&mut self, on: bool) {
        self.rules.set_jit(on);
    }
}

/// What [`Simulation::explicit_checked`] did.
enum Checked {
    /// The step is taken (`Ok`), or failed before writing any position or velocity.
    Done(Result<(), PhysicsError>),
    /// Nothing done: the step goes the way that saves the state.
    NotTested,
    /// The forces are computed at the positions of the step's start, nothing else is
    /// written: the step goes the way that saves the state, from these forces.
    ForcesReady,
}

/// The bound on a velocity's squared length for a step of `dt` on an object of `size`:
/// `(size / dt)^2 (1 - 1e-9)`, so that `|v|^2` below it implies `|v| dt <= size` despite
/// rounding; at most `f64::MAX`, so that passing it also says `|v|^2` is finite.
fn speed_limit(size: f64, dt: f64) -> f64 {
    let limit = size / dt;
    (limit * limit * (1.0 - 1e-9)).min(f64::MAX)
}

/// Whether every velocity of `v` (vec3s, flat) less `frame` has a squared length at most
/// `limit` ([`speed_limit`]): one pass without early exit or square root, so that it
/// vectorizes.
fn velocities_slow(v: &[f64], limit: f64, frame: [f64; 3]) -> bool {
    // `&`, not `&&`: no early exit, so that the loop vectorizes
    #[allow(clippy::needless_bitwise_bool)]
    let slow = v.chunks_exact(3).fold(true, |ok, u| {
        let d = [u[0] - frame[0], u[1] - frame[1], u[2] - frame[2]];
        ok & (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= limit)
    });
    v.len() % 3 == 0 && slow
}

/// The connected components of a map's darts (each the orbit of all its labels), found as
/// they are asked for: numbered 0, 1, ... in the order their first dart was asked for.
pub(crate) struct Components {
    comp: Vec<u32>,
    seen: topomech_gmap::Marks,
    count: u32,
}

impl Components {
    pub(crate) fn new(g: &GMap) -> Self {
        Components {
            comp: vec![u32::MAX; g.capacity()],
            seen: topomech_gmap::Marks::with_capacity(g.capacity()),
            count: 0,
        }
    }

    /// The component of dart `d` of `g` (the map `new` was given), walked on first sight.
    pub(crate) fn of(&mut self, g: &GMap, d: Dart) -> usize {
        if self.comp[d.index()] == u32::MAX {
            let c = self.count;
            self.count += 1;
            let comp = &mut self.comp;
            g.visit_orbit(
                d,
                topomech_gmap::OrbitType::all(g.dimension()),
                &mut self.seen,
                |x| comp[x.index()] = c,
            );
        }
        self.comp[d.index()] as usize
    }

    /// How many components were found so far.
    pub(crate) fn count(&self) -> usize {
        self.count as usize
    }
}

/// The root of `a` in the union-find forest `parent` (paths halved on the way).
fn root(parent: &mut [usize], mut a: usize) -> usize {
    while parent[a] != a {
        parent[a] = parent[parent[a]];
        a = parent[a];
    }
    a
}
