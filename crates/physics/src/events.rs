//! Topology changes during a run: timed cuts and fracture.

use topomech_rules::{Params, Val};

use crate::*;

/// Where a cut goes: along element boundaries, the faces (3D) or edges (2D) between two elements
/// that the geometry separates.
#[derive(Clone, Debug, PartialEq)]
pub enum Cut {
    /// The plane `normal . x = offset`: elements whose centroids (at the time of the cut) lie
    /// on opposite sides are separated (a centroid whose distance to the plane is within
    /// 1e-12 of the other's is on the plane, as for a blade).
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

/// A blade cutting progressively (what surgery simulators need): the segment from `from[0]`
/// to `from[1]` at time `start` moves linearly to the segment `to[0]`..`to[1]` at `end` (s).
/// Each step that overlaps `[start, end]`, the blade's segment at the step's start and at its
/// end bound the quad it swept during the step (two triangles, `a0 b0 b1` and `a0 b1 a1`),
/// and every face (3D) or edge (2D) between two elements whose centroids it separates — the
/// segment between the centroids, at the end of the step, crosses the quad — is unsewn.
/// Elements are separated along their existing faces: none is split. On a surface the blade
/// is a segment through the sheet (a knife held across it), not a segment lying in it.
#[derive(Clone, Debug, PartialEq)]
pub struct Blade {
    /// When the blade starts moving (s).
    pub start: f64,
    /// When it stops (s), after `start`.
    pub end: f64,
    /// Its two end points at `start`.
    pub from: [[f64; 3]; 2],
    /// Its two end points at `end`.
    pub to: [[f64; 3]; 2],
}

impl Blade {
    /// The blade's end points at time `t`, linearly between `from` (at `start`) and `to` (at
    /// `end`), held at the nearer pose outside `[start, end]`.
    pub fn at(&self, t: f64) -> [[f64; 3]; 2] {
        let s = ((t - self.start) / (self.end - self.start)).clamp(0.0, 1.0);
        segment_at(&self.from, &self.to, s)
    }

    /// Why this blade cannot run, if it cannot: a start before 0, an end not after the start,
    /// a non-finite time or point, a segment of zero length, or one that sweeps nothing (it
    /// does not move, or slides along its own line).
    pub fn problem(&self) -> Option<String> {
        if !(self.start >= 0.0 && self.start.is_finite()) {
            return Some(format!(
                "its start must be a finite time >= 0, got {}",
                self.start
            ));
        }
        if !(self.end > self.start && self.end.is_finite()) {
            return Some(format!(
                "its end must be a finite time after its start ({}), got {}",
                self.start, self.end
            ));
        }
        segments_problem(&self.from, &self.to).or_else(|| sweep_problem(&self.from, &self.to))
    }
}

/// Why the segment `from` moving to the segment `to` (both of two distinct finite points,
/// see [`segments_problem`]) sweeps nothing, if it does: it does not move, or its four points
/// lie on one line (it slides along its own line: every triangle of its quad is flat, and the
/// crossing test, which gives false for a triangle flat within 1e-12 of its edges, finds
/// nothing). The same words for a blade event and for `Simulation::cut_swept`; a scene's
/// check of its blades calls it too (through the Python bindings), so the test is this one.
pub fn sweep_problem(from: &[[f64; 3]; 2], to: &[[f64; 3]; 2]) -> Option<String> {
    if from == to {
        return Some(
            "its segment must move: it is the same segment at its start and at its end, so it \
             would sweep nothing"
                .into(),
        );
    }
    // scaled to coordinates of at most 1 in magnitude: the products below cannot overflow
    let m = largest_coordinate(from, to);
    let p = [from[0], from[1], to[0], to[1]].map(|q| q.map(|x| x / m));
    let flat = |a: usize, b: usize, c: usize| {
        let e1 = [0, 1, 2].map(|i| p[b][i] - p[a][i]);
        let e2 = [0, 1, 2].map(|i| p[c][i] - p[a][i]);
        let n = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        let len = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        len(n) <= 1e-12 * len(e1) * len(e2)
    };
    let on_one_line = flat(0, 1, 2) && flat(0, 1, 3) && flat(0, 2, 3) && flat(1, 2, 3);
    on_one_line.then(|| {
        "its segment must move off its own line: its end points at its start and at its end \
         lie on one line, so it would sweep nothing"
            .into()
    })
}

/// The largest vertex coordinate (in magnitude) a plane or predicate cut takes: a guard sums
/// the positions of a volume's darts (a few dozen) for its centroid, and beyond this the sum
/// could overflow to infinity and open the wrong faces without a word (found by QA at 1e308).
const CENTROID_LIMIT: f64 = 1e300;

/// The largest coordinate (in magnitude) a blade takes, of its points and of the vertex
/// positions: its crossing test multiplies three differences of them.
const CROSSING_LIMIT: f64 = 1e100;

/// `Err` naming the largest vertex coordinate when the box of the positions (`bounds`, see
/// `Simulation::positions_box`) reaches past `limit` in magnitude: `what` could not be
/// computed right.
fn positions_problem(
    bounds: Option<([f64; 3], [f64; 3])>,
    limit: f64,
    what: &str,
) -> Result<(), PhysicsError> {
    let Some((lo, hi)) = bounds else {
        return Ok(());
    };
    let largest = lo.iter().chain(&hi).fold(0.0_f64, |m, v| m.max(v.abs()));
    if largest > limit {
        return Err(PhysicsError::Config(format!(
            "{what} needs vertex coordinates of at most {limit:e} in magnitude (its test would overflow); the largest is {largest:e}"
        )));
    }
    Ok(())
}

/// Why a blade's segments at its two poses cannot cut: a non-finite point, or two end points
/// that coincide.
fn segments_problem(from: &[[f64; 3]; 2], to: &[[f64; 3]; 2]) -> Option<String> {
    if !from.iter().chain(to).flatten().all(|x| x.is_finite()) {
        return Some("its points must be finite".to_string());
    }
    // the crossing test takes differences and products of three of them: beyond this the
    // products overflow, and a crossing would be missed silently
    if from
        .iter()
        .chain(to)
        .flatten()
        .any(|x| x.abs() > CROSSING_LIMIT)
    {
        return Some(
            "its coordinates must be at most 1e100 in magnitude (the crossing test would overflow)"
                .to_string(),
        );
    }
    // the points themselves compared (a squared length underflowed to 0 for points 1e-170
    // apart, and two distinct points were said to coincide: QA)
    #[allow(clippy::float_cmp)] // exactly the same point, on purpose
    let zero_length = |s: &[[f64; 3]; 2]| s[0] == s[1];
    match (zero_length(from), zero_length(to)) {
        (false, false) => None,
        (true, true) => Some(
            "its two end points must differ (they coincide at its start and at its end)".into(),
        ),
        (true, false) => Some("its two end points must differ (they coincide at its start)".into()),
        (false, true) => Some("its two end points must differ (they coincide at its end)".into()),
    }
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

/// The plane `normal . x = offset` with both scaled by one power of two, so that the largest
/// component of the normal lies in [1, 2): the same plane, and, the scaling being exact, the
/// same side for every centroid as the plane given, except that a normal of tiny (or huge)
/// components no longer underflows (overflows) in the cut's guard, which multiplies two
/// signed distances. A zero or non-finite normal is returned as it is (refused before).
fn scaled_plane(normal: [f64; 3], offset: f64) -> ([f64; 3], f64) {
    let m = normal.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if !(m > 0.0 && m.is_finite()) {
        return (normal, offset);
    }
    // 2^-e with e the exponent of m, applied in steps that stay normal numbers
    let mut e = m.log2().floor() as i32;
    let (mut n, mut o) = (normal, offset);
    while e != 0 {
        let step = e.clamp(-1000, 1000);
        let f = 2f64.powi(-step);
        n = n.map(|x| x * f);
        o *= f;
        e -= step;
    }
    (n, o)
}

/// How a timed cut is named in messages: `the timed cut (the plane [a, b, c] . x = o) at t =
/// ...` or `the timed cut (where "...") at t = ...` (the caller's tools read the `at t = `).
fn describe(e: &TimedEvent) -> String {
    match &e.cut {
        Cut::Plane { normal, offset } => format!(
            "the timed cut (the plane [{}, {}, {}] . x = {offset}) at t = {}",
            normal[0], normal[1], normal[2], e.time
        ),
        Cut::Where(p) => format!("the timed cut (where \"{p}\") at t = {}", e.time),
    }
}

/// The rule computing a fracture criterion's measure, the embedding it writes, and the rule
/// opening the faces where the measure passes the threshold.
fn criterion_rules(c: Criterion) -> (&'static str, &'static str, &'static str) {
    match c {
        Criterion::Stress => ("element_stress", "max_stress", "fracture_stress"),
        Criterion::Strain => ("spring_strains", "spring_strain", "fracture_strain"),
    }
}

/// What the strain criterion knew at its last evaluation, to skip the next ones while no
/// spring can have reached the threshold: the position column then (slot by slot), the
/// largest strain computed then (`max_strain`, over every slot of the strain column, dead
/// ones included), the largest inverse rest length (`max_inv`, likewise), and the topology
/// version and the write count of the inverse rest lengths then.
///
/// Why a skip is exact: an edge's strain is `|x_b - x_a| / l0 - 1`; if no vertex moved more
/// than `delta` since, its length changed by at most `2 delta` (the triangle inequality),
/// so its strain by at most `2 delta / l0 <= 2 delta max_inv`, and no strain exceeds
/// `max_strain + 2 delta max_inv`. The mean over a face's edges that the fracture rule
/// compares is at most the largest strain: while that bound, with a margin of 1e-9 of it
/// (far above the few roundings of a strain, a distance and the sums), is at most the
/// threshold's bound, no face can open, and the strains are not computed. `delta` is twice
/// the largest coordinate difference, which bounds every move without squaring it (a square
/// underflows below about 1e-162 and would call a move of 1e-170 none). The strain column
/// then holds the strains of the last step that computed them.
#[derive(Clone, Debug)]
pub(crate) struct StrainBound {
    positions: Vec<f64>,
    max_strain: f64,
    max_inv: f64,
    version: u64,
    inv_writes: u64,
}

/// The rule a criterion's measure needs run once beforehand (the strain's inverse rest
/// lengths, from the rest positions).
fn criterion_init(c: Criterion) -> Option<&'static str> {
    match c {
        Criterion::Stress => None,
        Criterion::Strain => Some("spring_strains_init"),
    }
}

/// The box that the conjunction `text` (a predicate cut's, on the side's centroid `x`, `y`,
/// `z`) confines the centroid to, from its conjuncts that compare a coordinate with a number
/// (`x > 0.99`, `0.2 >= y`, `z == 0`; others, and a predicate that is not a conjunction of
/// such, leave coordinates unbounded: infinite sides). A necessary condition only: a
/// centroid outside the box fails the predicate, one inside may pass or fail. `None` when the
/// text does not parse or binds names of its own (a `let` could rename `x`).
pub(crate) fn predicate_box(text: &str) -> Option<([f64; 3], [f64; 3])> {
    use topomech_rules::ast::{Expr, ExprKind};
    use topomech_rules::value::{BinOp, UnOp};
    fn number(e: &Expr) -> Option<f64> {
        match &e.kind {
            ExprKind::Real(x) => Some(*x),
            ExprKind::Int(i) => Some(*i as f64),
            ExprKind::Unary(UnOp::Neg, a) => number(a).map(|x| -x),
            _ => None,
        }
    }
    fn axis(e: &Expr) -> Option<usize> {
        match &e.kind {
            ExprKind::Name(n) => ["x", "y", "z"].iter().position(|c| c == n),
            _ => None,
        }
    }
    fn walk(e: &Expr, lo: &mut [f64; 3], hi: &mut [f64; 3]) {
        let ExprKind::Binary(op, a, b) = &e.kind else {
            return;
        };
        if *op == BinOp::And {
            walk(a, lo, hi);
            walk(b, lo, hi);
            return;
        }
        // `coordinate op number`, or `number op coordinate` with the comparison turned
        let (k, c, op) = match (axis(a), number(b), axis(b), number(a)) {
            (Some(k), Some(c), _, _) => (k, c, *op),
            (_, _, Some(k), Some(c)) => {
                let turned = match op {
                    BinOp::Lt => BinOp::Gt,
                    BinOp::Le => BinOp::Ge,
                    BinOp::Gt => BinOp::Lt,
                    BinOp::Ge => BinOp::Le,
                    other => *other,
                };
                (k, c, turned)
            }
            _ => return,
        };
        if !c.is_finite() {
            return;
        }
        match op {
            BinOp::Lt | BinOp::Le => hi[k] = hi[k].min(c),
            BinOp::Gt | BinOp::Ge => lo[k] = lo[k].max(c),
            BinOp::Eq => {
                lo[k] = lo[k].max(c);
                hi[k] = hi[k].min(c);
            }
            _ => {}
        }
    }
    let e = topomech_rules::build::parse_expression("predicate", text).ok()?;
    if matches!(e.kind, ExprKind::Block(..)) {
        return None;
    }
    let (mut lo, mut hi) = ([f64::NEG_INFINITY; 3], [f64::INFINITY; 3]);
    walk(&e, &mut lo, &mut hi);
    Some((lo, hi))
}

/// The box bounding the points of the plane `normal . p = offset` inside the box `lo..hi`
/// (interval arithmetic per coordinate, so a little larger than the section for a tilted
/// plane); `None` when the plane misses the box or the normal is zero.
pub(crate) fn plane_box(
    normal: [f64; 3],
    offset: f64,
    lo: [f64; 3],
    hi: [f64; 3],
) -> Option<([f64; 3], [f64; 3])> {
    let (mut a, mut b) = (lo, hi);
    for k in 0..3 {
        if normal[k] == 0.0 {
            continue;
        }
        // p_k = (offset - sum_{j != k} n_j p_j) / n_k over the box
        let (mut s_lo, mut s_hi) = (offset, offset);
        for j in (0..3).filter(|&j| j != k) {
            let (u, v) = (normal[j] * lo[j], normal[j] * hi[j]);
            s_lo -= u.max(v);
            s_hi -= u.min(v);
        }
        let (u, v) = (s_lo / normal[k], s_hi / normal[k]);
        a[k] = a[k].max(u.min(v));
        b[k] = b[k].min(u.max(v));
    }
    (normal.iter().any(|&n| n != 0.0) && (0..3).all(|k| a[k] <= b[k])).then_some((a, b))
}

/// The parameters of the plane cut's rule `cut_plane`.
fn plane_params(normal: [f64; 3], offset: f64) -> Params {
    [
        ("normal".to_string(), Val::V3(normal)),
        ("offset".to_string(), Val::F(offset)),
    ]
    .into()
}

/// The largest angle (radians, 1 degree) a blade's segment turns by within one strip of its
/// sweep (see [`sweep_strips`]).
const MAX_TURN: f64 = std::f64::consts::PI / 180.0;

/// How many strips the sweep of the segment `from` to `to` is cut into, so that the segment
/// turns by at most [`MAX_TURN`] within each: `ceil(angle / MAX_TURN)` for the angle between
/// its directions at both ends (at most 180 strips), 1 for a blade that does not turn. The
/// quad of a strip is nearly flat and nearly a parallelogram, so its two triangles cover
/// what the segment sweeps in it, to within a sliver of that angle's width along the blade.
pub(crate) fn sweep_strips(from: &[[f64; 3]; 2], to: &[[f64; 3]; 2]) -> usize {
    // scaled to coordinates of at most 1 in magnitude: the products cannot overflow
    let m = largest_coordinate(from, to);
    if m == 0.0 || !m.is_finite() {
        return 1;
    }
    let d = |s: &[[f64; 3]; 2]| -> [f64; 3] { std::array::from_fn(|k| (s[1][k] - s[0][k]) / m) };
    let (u, v) = (d(from), d(to));
    let cross = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    let sin = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
    let cos = u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    let angle = sin.atan2(cos);
    if angle.is_nan() || angle <= MAX_TURN {
        return 1;
    }
    // (angle <= pi, so at most 180 strips)
    (angle / MAX_TURN).ceil().min(180.0) as usize
}

/// The largest coordinate, in magnitude, of the segments `from` and `to`.
fn largest_coordinate(from: &[[f64; 3]; 2], to: &[[f64; 3]; 2]) -> f64 {
    from.iter()
        .chain(to)
        .flatten()
        .fold(0.0_f64, |m, x| m.max(x.abs()))
}

/// The segment a fraction `s` of the way from `from` to `to`, each end point moving linearly.
fn segment_at(from: &[[f64; 3]; 2], to: &[[f64; 3]; 2], s: f64) -> [[f64; 3]; 2] {
    [0, 1].map(|e| std::array::from_fn(|c| from[e][c] + s * (to[e][c] - from[e][c])))
}

/// The box bounding the quad the segment `from` sweeps moving to `to`: its corners `lo` and
/// `hi`.
fn quad_box(from: &[[f64; 3]; 2], to: &[[f64; 3]; 2]) -> ([f64; 3], [f64; 3]) {
    let (mut lo, mut hi) = (from[0], from[0]);
    for p in [from[1], to[0], to[1]] {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// The parameters of the blade's rule `cut_swept`: the segment `from` moving to `to`.
fn swept_params(from: [[f64; 3]; 2], to: [[f64; 3]; 2]) -> Params {
    [
        ("a0".to_string(), Val::V3(from[0])),
        ("b0".to_string(), Val::V3(from[1])),
        ("a1".to_string(), Val::V3(to[0])),
        ("b1".to_string(), Val::V3(to[1])),
    ]
    .into()
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
                        "{} separates nothing: it misses the object, or every face it meets is open already, or the element centroids it meets lie on it (a centroid on it is on neither side)",
                        describe(&self.cfg.events[k])
                    )));
                }
            }
        }
        // the blades that moved during this step, over the part of it they moved in
        let (t0, t1) = (self.time - self.cfg.dt, self.time);
        for k in 0..self.cfg.blades.len() {
            let b = &self.cfg.blades[k];
            let (lo, hi) = (t0.max(b.start), t1.min(b.end));
            if hi > lo {
                let (from, to) = (b.at(lo), b.at(hi));
                let end = b.end;
                self.blades_opened[k] += self.sweep(from, to)?.unsewn;
                // like a timed cut that separates nothing: a blade that has swept its whole
                // path without crossing anything misses the object
                if t1 >= end - 1e-9 * self.cfg.dt && self.blades_opened[k] == 0 {
                    return Err(PhysicsError::Config(format!(
                        "blade {k} moved from t = {} to t = {end} and crossed nothing: it misses the object, or every face it meets is open already, or the element centroids it meets lie on it (a centroid on it is on neither side)",
                        self.cfg.blades[k].start
                    )));
                }
            }
        }
        if let Some(f) = self.cfg.fracture {
            self.fracture(f)?;
        }
        Ok(())
    }

    /// Cuts now along the quad a blade sweeps moving from the segment `from` to the segment
    /// `to` (each a pair of end points): unsews every face (3D) or edge (2D) between two
    /// elements whose current centroids the quad separates (see [`Blade`]); returns how many,
    /// and the rows appended for the vertices that split. Nothing crossed is not an error; a
    /// sweep of nothing (the same segment at both ends, or four points on one line) is
    /// refused with the words of [`Blade::problem`], as a blade event's is.
    pub fn cut_swept(
        &mut self,
        from: [[f64; 3]; 2],
        to: [[f64; 3]; 2],
    ) -> Result<TopologyResult, PhysicsError> {
        if let Some(why) = segments_problem(&from, &to).or_else(|| sweep_problem(&from, &to)) {
            return Err(PhysicsError::Config(format!("the blade: {why}")));
        }
        self.sweep(from, to)
    }

    fn sweep(
        &mut self,
        from: [[f64; 3]; 2],
        to: [[f64; 3]; 2],
    ) -> Result<TopologyResult, PhysicsError> {
        let bounds = self.positions_box();
        positions_problem(bounds, CROSSING_LIMIT, "a blade")?;
        // the guard of `cut_swept` is false where the segment between the two centroids
        // misses the swept quad, so where the box of the positions it reads (whose hull
        // holds both centroids, and so the segment) misses the quad's box: only the faces
        // near the quad are tested
        let (lo, hi) = quad_box(&from, &to);
        // and where the quad's box misses the positions' box, grown by far more than the
        // crossing test's tolerance (1e-12 of the quad's edges) and its rounding, no face can
        // open: nothing is searched (a blade before or after it crosses the body costs a
        // pass over the positions, not the guard's)
        if let Some((plo, phi)) = bounds {
            let scale = plo
                .iter()
                .chain(&phi)
                .chain(&lo)
                .chain(&hi)
                .fold(0.0_f64, |m, v| m.max(v.abs()));
            let m = 1e-9 * (1.0 + scale);
            if (0..3).any(|k| lo[k] > phi[k] + m || hi[k] < plo[k] - m) {
                return self.record_change("blade", 0);
            }
        }
        // A segment that turns while it moves sweeps a ruled surface, which the two
        // triangles of its quad approximate only where it turns little: a segment turning by
        // 90 degrees about its middle sweeps two opposite wedges, and the quad's triangles
        // cover parts of the other two, opening faces the blade never crossed (found by QA: a
        // sweep in one step opened 24 faces, the same motion in 50 steps 16). So the sweep is
        // cut into strips along its motion, the segment turning by at most `MAX_TURN` in each
        // (one strip for a blade that does not turn), as that many steps would cut it.
        let strips = sweep_strips(&from, &to);
        let mut n = 0;
        for i in 0..strips {
            let at = |k: usize| segment_at(&from, &to, k as f64 / strips as f64);
            let (f, t) = if strips == 1 {
                (from, to)
            } else {
                (at(i), if i + 1 == strips { to } else { at(i + 1) })
            };
            let (lo, hi) = quad_box(&f, &t);
            let region = topomech_rules::Region {
                embedding: "position".into(),
                lo,
                hi,
            };
            n += self
                .rules
                .apply_everywhere_within(&mut self.g, "cut_swept", &swept_params(f, t), &region)?
                .matches;
        }
        self.record_change("blade", n)
    }

    /// Opens now every face (3D) or edge (2D) where the criterion passes the threshold; returns
    /// how many, and the rows appended for the vertices that split (existing rows keep their
    /// meaning).
    pub fn fracture(&mut self, f: Fracture) -> Result<TopologyResult, PhysicsError> {
        if let Some(why) = crate::schedule::threshold_problem(f.threshold) {
            return Err(PhysicsError::Config(why));
        }
        let none = Params::new();
        let (measure, column, rule) = criterion_rules(f.criterion);
        if self.rules.rule(measure).is_err() {
            // a mesh with volumes that are not tetrahedra (24 darts: four triangles; a
            // wedge has 36, a pyramid 32, a hexahedron 48) is refused for that, first:
            // loading the FEM rules would not help it
            if self.g.dimension() == 3 && f.criterion == Criterion::Stress {
                let volume = topomech_gmap::OrbitType::volume();
                let volumes = self.g.orbit_representatives(volume);
                let tetrahedra = volumes
                    .iter()
                    .filter(|&&d| self.g.orbit(d, volume).len() == 24)
                    .count();
                stress_needs_tetrahedra(&self.g, tetrahedra)?;
            }
            return Err(PhysicsError::Config(if self.g.dimension() == 3 {
                "the stress criterion needs the FEM rules (fem3d.tmr), which this simulation's models do not load (neohookean and stvk do not either): declare the stress fracture in its configuration when it is built, which loads them (or use an FEM model such as corotational)"
                    .into()
            } else {
                "the stress criterion of fracture needs tetrahedra (3D); surfaces tear by strain"
                    .into()
            }));
        }
        self.init_measure(f.criterion)?;
        // the bound the threshold is compared with (see below)
        let bound = f.threshold - 64.0 * f64::EPSILON * f.threshold.abs();
        if f.criterion == Criterion::Strain && self.strain_cannot_reach(bound) {
            return Ok(TopologyResult::default());
        }
        let previous = self.strain_bound.take();
        let rep = self.rules.apply_everywhere(&mut self.g, measure, &none)?;
        if f.criterion == Criterion::Stress {
            // (the strain's bound, taken above, is then unknown: the next strain
            // evaluation computes it)
            stress_needs_tetrahedra(&self.g, rep.matches)?;
        }
        // The guards of the shipped criteria compare a mean of the measure with the threshold
        // (the mean spring strain of a face's edges; the mean of the two elements' largest
        // principal stresses): no mean exceeds the largest value of the measure's column, so
        // when no value exceeds the threshold nothing can open and the search over the faces
        // is skipped. A mean of k values at most T rounds to at most T (1 + k eps): the bound
        // keeps a margin of 64 eps |T| (k is at most a face's 8 half-edges, or 2). Dead slots
        // hold old values and NaN compares as "may exceed": either only sends the step to the
        // search, which decides.
        if let Some(id) = self.g.embedding_id(column) {
            if let Some(values) = self.g.embedding(id).real_column() {
                // the largest value (NaN: infinite, "may exceed")
                let max = values.iter().fold(f64::NEG_INFINITY, |m, &x| {
                    if x.is_nan() {
                        f64::INFINITY
                    } else {
                        m.max(x)
                    }
                });
                if max <= bound {
                    if f.criterion == Criterion::Strain {
                        self.strain_bound = self.strain_state(max, previous);
                    }
                    return Ok(TopologyResult::default());
                }
            }
        }
        let p: Params = [("threshold".to_string(), Val::F(f.threshold))].into();
        let n = self.rules.apply_everywhere(&mut self.g, rule, &p)?.matches;
        self.record_change("fracture", n)
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
        // Only the faces near the region the cut can open are tested (the same faces open,
        // see `RuleSet::apply_everywhere_within`): the plane's section of the box of the
        // positions now, or the box a predicate's comparisons confine the centroid to. The
        // guard reads the positions of the side (a predicate) or of both volumes (the
        // plane): their box holds the centroids, so where it misses the region the guard is
        // false (a centroid outside the predicate's box fails it; two centroids on opposite
        // sides of the plane have a box meeting the plane inside the positions' box).
        // Where the region misses the positions' box, grown by far more than the rounding of
        // a centroid or of its distance to the plane, no face can open: nothing is searched.
        let bounds = self.positions_box();
        positions_problem(bounds, CENTROID_LIMIT, "a cut")?;
        let bounds = bounds.map(|(lo, hi)| {
            let scale = lo.iter().chain(&hi).fold(0.0_f64, |m, v| m.max(v.abs()));
            let m = 1e-9 * (1.0 + scale);
            (lo.map(|v| v - m), hi.map(|v| v + m))
        });
        let (name, params, region) = match cut {
            Cut::Plane { normal, offset } => {
                let (normal, offset) = scaled_plane(*normal, *offset);
                let region = bounds.and_then(|(lo, hi)| plane_box(normal, offset, lo, hi));
                if region.is_none() && bounds.is_some() && normal.iter().any(|&v| v != 0.0) {
                    return self.record_change("cut", 0);
                }
                (
                    "cut_plane".to_string(),
                    plane_params(normal, offset),
                    region,
                )
            }
            Cut::Where(text) => {
                let k = event.expect("predicate cuts are events");
                let region = bounds.zip(predicate_box(text)).map(|((lo, hi), (a, b))| {
                    let a: [f64; 3] = std::array::from_fn(|i| a[i].max(lo[i]));
                    let b: [f64; 3] = std::array::from_fn(|i| b[i].min(hi[i]));
                    (a, b)
                });
                (format!("cut_where_{k}"), Params::new(), region)
            }
        };
        let applied = match region {
            Some((lo, hi)) if (0..3).any(|i| lo[i] > hi[i]) => Ok(0),
            Some((lo, hi)) => {
                let region = topomech_rules::Region {
                    embedding: "position".into(),
                    lo,
                    hi,
                };
                self.rules
                    .apply_everywhere_within(&mut self.g, &name, &params, &region)
                    .map(|r| r.matches)
            }
            None => self
                .rules
                .apply_everywhere(&mut self.g, &name, &params)
                .map(|r| r.matches),
        };
        // a predicate that fails at a face names the predicate and the face, not the rule
        let n = applied.map_err(|e| match &cut {
            Cut::Where(text) => crate::schedule::predicate_failed(
                &self.g,
                "cut predicate",
                text,
                crate::schedule::PredicateAt::Side,
                e,
            ),
            Cut::Plane { .. } => e.into(),
        })?;
        self.record_change("cut", n)
    }

    /// The box of the vertex positions now (every slot of the embedding, so a little
    /// larger where slots are free); `None` for a map without them or with a value that is
    /// not finite.
    fn positions_box(&self) -> Option<([f64; 3], [f64; 3])> {
        let id = self.g.embedding_id("position")?;
        let x = self.g.embedding(id).real_column()?;
        if x.is_empty() || x.len() % 3 != 0 {
            return None;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in x.chunks_exact(3) {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo.iter().chain(&hi).all(|v| v.is_finite())).then_some((lo, hi))
    }

    /// Records a change that opened `n` faces (3D) or edges (2D), when it opened some, and
    /// brings the simulation after it (see [`Simulation::after_topology_change`]).
    fn record_change(
        &mut self,
        kind: &'static str,
        n: usize,
    ) -> Result<TopologyResult, PhysicsError> {
        let mut added_rows = Vec::new();
        if n > 0 {
            self.changes.push(TopologyChange {
                step: self.steps,
                time: self.time,
                kind,
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

    /// Refuses events (and blades) that a run ending at `end_time` would never reach (a blade
    /// that ends after it is allowed: it cuts what it crossed by then); a run ending at
    /// `t = 0` takes no step and reaches no event.
    pub fn check_events(&self, end_time: f64) -> Result<(), PhysicsError> {
        for (k, b) in self.cfg.blades.iter().enumerate() {
            if b.start >= end_time {
                return Err(PhysicsError::Config(format!(
                    "blade {k} starts at t = {} but the run ends at t = {end_time}: it would never move",
                    b.start
                )));
            }
        }
        for e in &self.cfg.events {
            // (an event happens at the end of the step that reaches its time: a run ending
            // at t = 0 takes none)
            if end_time <= 0.0 {
                return Err(PhysicsError::Config(format!(
                    "the event at t = {} is never reached: the run ends at t = {end_time}, before its first step",
                    e.time
                )));
            }
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

    /// Builds now what a cut searches the faces (3D) or edges (2D) with: the compiled guards
    /// of the plane cut ([`Simulation::cut`]) and the blade ([`Simulation::cut_swept`]),
    /// which cuts then only patch and run (and those of the events, blades and fracture the
    /// configuration declares, which a simulation builds when it is set up). Call this before
    /// the first interactive cut to move that cost (about one set-up of a step rule per
    /// guard) out of it. Cuts give the same results either way, bit for bit. (A fracture the
    /// configuration does not declare is not prepared: its measure's embedding, created
    /// then, would change which plans a later change patches, and so the rounding.)
    pub fn prepare_cuts(&mut self) -> Result<(), PhysicsError> {
        // any parameter values: a guard's plan does not depend on them
        let zero = [[0.0; 3]; 2];
        self.rules.prepare_guard_within(
            &mut self.g,
            "cut_plane",
            &plane_params(zero[0], 0.0),
            "position",
        )?;
        self.rules.prepare_guard_within(
            &mut self.g,
            "cut_swept",
            &swept_params(zero, zero),
            "position",
        )?;
        self.prepare_declared_cuts()
    }

    /// For the fracture the configuration declares: the compiled guard of its rule, and the
    /// plan of the rule computing its measure (run once, so that the measure exists first).
    /// Refuses a stress criterion on a mesh with volumes that are not tetrahedra: the stress
    /// is computed per tetrahedron, and another element would never break.
    fn prepare_fracture(&mut self, criterion: Criterion) -> Result<(), PhysicsError> {
        let (measure, _, rule) = criterion_rules(criterion);
        if self.rules.rule(rule).is_err() || self.rules.rule(measure).is_err() {
            return Ok(());
        }
        self.init_measure(criterion)?;
        let rep = self
            .rules
            .apply_everywhere(&mut self.g, measure, &Params::new())?;
        if criterion == Criterion::Stress {
            stress_needs_tetrahedra(&self.g, rep.matches)?;
        }
        let p: Params = [("threshold".to_string(), Val::F(1.0))].into();
        self.rules.prepare_guard(&mut self.g, rule, &p)?;
        Ok(())
    }

    /// Whether no spring's strain can exceed `bound` now, by what the last evaluation knew
    /// (see [`StrainBound`]): `false` when it does not know (none yet, the topology or the
    /// inverse rest lengths changed since, a column of another length, a non-finite value).
    fn strain_cannot_reach(&self, bound: f64) -> bool {
        let Some(b) = &self.strain_bound else {
            return false;
        };
        let (Some(pos), Some(inv)) = (
            self.g.embedding_id("position"),
            self.g.embedding_id("spring_inv_l0"),
        ) else {
            return false;
        };
        let Some(x) = self.g.embedding(pos).real_column() else {
            return false;
        };
        if b.version != self.g.version()
            || b.inv_writes != self.g.embedding(inv).writes()
            || x.len() != b.positions.len()
        {
            return false;
        }
        // a bound on the distance any vertex moved since: twice its largest coordinate
        // difference (the distance is at most sqrt(3) times it; no square, which would
        // underflow for tiny moves; the doubling is exact; NaN where a position is not finite)
        let mut most = 0.0_f64;
        for (p, q) in x.iter().zip(&b.positions) {
            let d = (p - q).abs();
            most = if d.is_nan() { f64::NAN } else { most.max(d) };
        }
        let delta = 2.0 * most;
        let reach = b.max_strain + 2.0 * delta * b.max_inv;
        reach + 1e-9 * (1.0 + reach.abs()) <= bound
    }

    /// The state [`Simulation::strain_cannot_reach`] starts from, after an evaluation whose
    /// largest strain was `max_strain`; `None` where a column is missing or a value is not
    /// finite. `previous`, the state before that evaluation, lends its buffer, and its
    /// largest inverse rest length where they were not written since (a topology change
    /// only copies them to new slots, or gives a new dart 0: the largest stays a bound).
    fn strain_state(&self, max_strain: f64, previous: Option<StrainBound>) -> Option<StrainBound> {
        let pos = self.g.embedding_id("position")?;
        let inv = self.g.embedding_id("spring_inv_l0")?;
        let inv_writes = self.g.embedding(inv).writes();
        let max_inv = match &previous {
            Some(p) if p.inv_writes == inv_writes => p.max_inv,
            _ => {
                let invs = self.g.embedding(inv).real_column()?;
                if !invs.iter().all(|x| x.is_finite()) {
                    return None;
                }
                invs.iter().fold(0.0_f64, |m, &x| m.max(x.abs()))
            }
        };
        if !max_strain.is_finite() {
            return None;
        }
        let mut positions = previous.map(|p| p.positions).unwrap_or_default();
        positions.clear();
        positions.extend_from_slice(self.g.embedding(pos).real_column()?);
        Some(StrainBound {
            positions,
            max_strain,
            max_inv,
            version: self.g.version(),
            inv_writes,
        })
    }

    /// Runs the rule the criterion's measure needs once beforehand, the first time only:
    /// from the rest positions then, as the springs' rest lengths are computed at set-up
    /// (edges that later changes split keep their values).
    fn init_measure(&mut self, criterion: Criterion) -> Result<(), PhysicsError> {
        if let Some(init) = criterion_init(criterion) {
            if !self.measure_ready {
                self.rules
                    .apply_everywhere(&mut self.g, init, &Params::new())?;
                self.measure_ready = true;
            }
        }
        Ok(())
    }

    /// [`Simulation::prepare_cuts`] for what the configuration declares only.
    pub(crate) fn prepare_declared_cuts(&mut self) -> Result<(), PhysicsError> {
        for k in 0..self.cfg.events.len() {
            match &self.cfg.events[k].cut {
                Cut::Where(_) => {
                    self.rules.prepare_guard_within(
                        &mut self.g,
                        &format!("cut_where_{k}"),
                        &Params::new(),
                        "position",
                    )?;
                }
                Cut::Plane { normal, offset } => {
                    let p = plane_params(*normal, *offset);
                    self.rules
                        .prepare_guard_within(&mut self.g, "cut_plane", &p, "position")?;
                }
            }
        }
        if let Some(b) = self.cfg.blades.first() {
            self.rules.prepare_guard_within(
                &mut self.g,
                "cut_swept",
                &swept_params(b.from, b.to),
                "position",
            )?;
        }
        if let Some(f) = self.cfg.fracture {
            self.prepare_fracture(f.criterion)?;
        }
        Ok(())
    }
}

/// Refuses the stress criterion of fracture where the rule computing the stress per
/// tetrahedron matched `tetrahedra` of the map's volumes and some volumes are not
/// tetrahedra: they would never break.
fn stress_needs_tetrahedra(g: &GMap, tetrahedra: usize) -> Result<(), PhysicsError> {
    let volumes = g.count_orbits(topomech_gmap::OrbitType::volume());
    if tetrahedra < volumes {
        return Err(PhysicsError::Config(format!(
            "the stress criterion of fracture needs tetrahedra: {} of the mesh's {volumes} volumes {} not, and would never break (the strain criterion works with springs on any element)",
            volumes - tetrahedra,
            if volumes - tetrahedra == 1 { "is" } else { "are" }
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{plane_box, predicate_box};

    const INF: f64 = f64::INFINITY;

    #[test]
    fn a_predicates_comparisons_bound_its_box_and_nothing_else_does() {
        let b = |t: &str| predicate_box(t);
        assert_eq!(
            b("x > 0.99 && x < 1.01 && y < 0.02 && z < 0.03"),
            Some(([0.99, -INF, -INF], [1.01, 0.02, 0.03]))
        );
        // turned comparisons, integers, negative numbers, equality, nesting
        assert_eq!(
            b("0.5 <= x && (-2 < y && z == 3)"),
            Some(([0.5, -2.0, 3.0], [INF, INF, 3.0]))
        );
        // what is not a comparison of a coordinate with a number bounds nothing
        for t in [
            "x > 0.5 || y > 0.5",
            "x * 2.0 > 1.0",
            "x > y",
            "x != 1.0",
            "!(x < 1.0)",
        ] {
            assert_eq!(b(t), Some(([-INF; 3], [INF; 3])), "{t}");
        }
        // a conjunct not understood leaves the others' bounds (a necessary condition)
        assert_eq!(
            b("x > 1.0 && y * y < 4.0"),
            Some(([1.0, -INF, -INF], [INF; 3]))
        );
        // names of its own: no box (a `let` may rename a coordinate); no parse: no box
        assert_eq!(b("{ let x = y  x > 1.0 }"), None);
        assert_eq!(b("x >"), None);
    }

    #[test]
    fn a_planes_box_holds_its_section_of_the_box() {
        let (lo, hi) = ([0.0; 3], [2.0, 1.0, 1.0]);
        // axis-aligned: a flat box
        assert_eq!(
            plane_box([1.0, 0.0, 0.0], 0.5, lo, hi),
            Some(([0.5, 0.0, 0.0], [0.5, 1.0, 1.0]))
        );
        // tilted: every point of the section inside, checked on a grid of the plane
        let n = [0.6, 0.8, 0.0];
        let (a, b) = plane_box(n, 1.0, lo, hi).expect("meets the box");
        for i in 0..=20 {
            for j in 0..=20 {
                let x = 2.0 * f64::from(i) / 20.0;
                let z = f64::from(j) / 20.0;
                let y = (1.0 - 0.6 * x) / 0.8;
                if (0.0..=1.0).contains(&y) {
                    let p = [x, y, z];
                    assert!((0..3).all(|k| p[k] >= a[k] - 1e-12 && p[k] <= b[k] + 1e-12));
                }
            }
        }
        // and no larger than the section's extent along x (1/3 to 5/3)
        assert!((a[0] - 1.0 / 3.0).abs() < 1e-12 && (b[0] - 5.0 / 3.0).abs() < 1e-12);
        // beside the box, or no normal: none
        assert_eq!(plane_box([1.0, 0.0, 0.0], 3.0, lo, hi), None);
        assert_eq!(plane_box([0.0; 3], 0.0, lo, hi), None);
    }
}
