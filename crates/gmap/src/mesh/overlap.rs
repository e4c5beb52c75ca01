//! Overlapping cells: two cells whose interiors intersect without sharing a face (two
//! interpenetrating tetrahedra, a tetrahedron inside a hexahedron, a triangle lying across
//! others in a planar 2D mesh). A conforming mesh never has them; the fold check
//! (`check_planar_folds`, and the face matching of `build_volume`) handles cells that share a
//! face, so pairs sharing a face (2D: an edge) are skipped here; pairs sharing only a vertex
//! or an edge are tested.
//!
//! Candidate pairs come from a hierarchy of uniform grids over the cells' bounding boxes
//! (level `L` has buckets of `h 2^L`, `h` the median cell extent, and holds the cells of
//! extent within a factor `sqrt 2` of it), so each cell lies in at most 27 buckets of its level and
//! the cost stays linear for well-spread meshes, graded ones included. Each candidate pair is
//! decided exactly enough with the separating axis theorem on a decomposition of each cell
//! into simplices (Ericson, *Real-Time Collision Detection*, 2005, sections 4.4 and 5.2.1;
//! Gottschalk, Lin, Manocha, *`OBBTree`*, SIGGRAPH 1996):
//! - a tetrahedron is itself; a hexahedron, wedge or pyramid is the fan of tetrahedra from
//!   its vertex centroid to the triangles of its faces, a quadrilateral face being the four
//!   triangles from its vertex centroid (two cells sharing a face decompose it the same way,
//!   so a conforming mesh decomposes into tetrahedra that only touch);
//! - a polygon of a planar 2D mesh is the fan of triangles from its vertex centroid (the
//!   import requires polygons star-shaped around it); a triangle is itself.
//!
//! Two tetrahedra overlap unless one of 4 + 4 face normals or 6 x 6 edge cross products
//! separates them; two triangles unless one of their 3 + 3 side normals does. Projections
//! overlapping by at most `TOL` times the smaller cell's extent count as separated, so cells
//! that merely touch (at a vertex, an edge, a face or along a plane) are never refused.
//!
//! Surfaces that are not planar (shells in 3D) are not checked: two faces of a shell can
//! only overlap where they are coplanar, which the boundary-side check of `conform` covers
//! for faces that touch.

use super::{cross, dot, fx_map, local_faces, polygon_normal, sub, CellKind, FxMap};

/// Relative tolerance (of the smaller cell's extent) for a penetration that still counts as
/// touching: the same as `conform`'s "on the same plane / overlapping".
const TOL: f64 = 1e-6;

/// A cell's axis-aligned bounding box.
#[derive(Clone, Copy)]
struct Aabb {
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Aabb {
    fn of(pts: impl Iterator<Item = [f64; 3]>) -> Self {
        let mut b = Aabb {
            lo: [f64::INFINITY; 3],
            hi: [f64::NEG_INFINITY; 3],
        };
        for p in pts {
            for ((l, h), x) in b.lo.iter_mut().zip(&mut b.hi).zip(p) {
                *l = l.min(x);
                *h = h.max(x);
            }
        }
        b
    }

    fn extent(&self) -> f64 {
        (0..3).fold(0.0, |e: f64, a| e.max(self.hi[a] - self.lo[a]))
    }

    /// Whether the boxes overlap by more than `tol` on every axis of `axes` (the plane's two
    /// for a planar 2D mesh, whose boxes are flat).
    fn overlaps(&self, o: &Aabb, tol: f64, axes: &[usize]) -> bool {
        axes.iter()
            .all(|&a| self.hi[a].min(o.hi[a]) - self.lo[a].max(o.lo[a]) > tol)
    }
}

/// Every pair of cells (input indices `ids`, smaller first, sorted) whose interiors
/// intersect by more than the tolerance and that share no face (2D: edge). `cells` are the
/// kept cells' vertex lists, `kinds` their kinds. A 2D mesh is checked only when planar.
pub(crate) fn overlapping_cells(
    points: &[[f64; 3]],
    cells: &[Vec<usize>],
    kinds: &[CellKind],
    ids: &[usize],
    dim: usize,
) -> Vec<(usize, usize)> {
    let n = cells.len();
    if n < 2 {
        return Vec::new();
    }
    // 2D: the plane's two coordinates (drop the normal's largest component), or no check
    let plane = if dim == 2 {
        match planar_axes(points, cells) {
            Some(p) => Some(p),
            None => return Vec::new(),
        }
    } else {
        None
    };
    let box_axes: &[usize] = match plane {
        Some((x, y)) => &[x, y],
        None => &[0, 1, 2],
    };
    let boxes: Vec<Aabb> = cells
        .iter()
        .map(|c| Aabb::of(c.iter().map(|&v| points[v])))
        .collect();
    let exts: Vec<f64> = boxes.iter().map(Aabb::extent).collect();
    let median = |mut v: Vec<f64>| *v.select_nth_unstable_by(n / 2, f64::total_cmp).1;
    let h = median(exts.clone());
    if !(h.is_finite() && h > 0.0) {
        return Vec::new();
    }
    let log_h = h.log2();
    // the buckets' side along each axis: the median width of the boxes along it (a box
    // grid's cells then fit their buckets exactly), at least h / 4 so that a cell spans at
    // most 7 buckets per axis of its level
    let mut log_side = [log_h; 3];
    for &a in box_axes {
        let w = median(boxes.iter().map(|b| b.hi[a] - b.lo[a]).collect());
        log_side[a] = w.max(h / 4.0).log2();
    }
    let mut origin = [f64::INFINITY; 3];
    for b in &boxes {
        for (o, x) in origin.iter_mut().zip(b.lo) {
            *o = o.min(x);
        }
    }
    // level of each cell: the L with extent within a factor sqrt 2 of h 2^L
    let levels: Vec<i32> = exts
        .iter()
        .map(|&e| {
            let l = (e.log2() - log_h).round();
            if l.is_finite() {
                l.clamp(-4000.0, 4000.0) as i32
            } else {
                0
            }
        })
        .collect();
    let mut level_list: Vec<i32> = levels.clone();
    level_list.sort_unstable();
    level_list.dedup();
    // the buckets a box shrunk by half its tolerance reaches into with a positive width:
    // two boxes overlapping by more than the sum of their shrinkings on every axis share the
    // bucket of a point inside both (so a box that fits a bucket exactly stays in it); a
    // planar 2D mesh is bucketed in its plane only
    let range = |c: usize, level: i32| -> ([i64; 3], [i64; 3]) {
        let (b, shrink) = (&boxes[c], 0.5 * TOL * exts[c]);
        let (mut lo, mut hi) = ([0i64; 3], [0i64; 3]);
        for &a in box_axes {
            let s = (log_side[a] + f64::from(level)).exp2();
            let x0 = b.lo[a] + shrink - origin[a];
            let x1 = (b.hi[a] - shrink - origin[a]).max(x0);
            lo[a] = (x0 / s).floor() as i64;
            hi[a] = ((x1 / s).ceil() as i64 - 1).max(lo[a]);
            // a cell spans at most 7 buckets of its level per axis (fewer above): a saturated
            // division (coordinates far beyond the bucket size) must not make it more
            hi[a] = hi[a].min(lo[a].saturating_add(8));
        }
        (lo, hi)
    };
    let ranges: Vec<([i64; 3], [i64; 3])> = (0..n).map(|c| range(c, levels[c])).collect();
    // one grid per level: bucket -> cells of that level
    let mut grids: FxMap<i32, FxMap<[i64; 3], Vec<u32>>> = fx_map(level_list.len());
    for c in 0..n {
        let (lo, hi) = ranges[c];
        let grid = grids.entry(levels[c]).or_insert_with(|| fx_map(0));
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    grid.entry([x, y, z]).or_default().push(c as u32);
                }
            }
        }
    }
    let mut pairs = Vec::new();
    let mut test = |a: usize, b: usize| {
        // boxes overlapping by at most the sum of their shrinkings are not in one bucket
        if !boxes[a].overlaps(&boxes[b], 0.5 * TOL * (exts[a] + exts[b]), box_axes)
            || share_face(&cells[a], kinds[a], &cells[b], kinds[b], dim)
        {
            return;
        }
        // the rounding of projections grows with the coordinates' differences
        let tol = TOL * exts[a].min(exts[b]) + 1e3 * f64::EPSILON * exts[a].max(exts[b]);
        let hit = match plane {
            Some(axes) => overlap_2d(
                points, &cells[a], &cells[b], &boxes[a], &boxes[b], axes, tol,
            ),
            None => overlap_3d(
                points, &cells[a], kinds[a], &cells[b], kinds[b], &boxes[a], &boxes[b], tol,
            ),
        };
        if hit {
            let (x, y) = (ids[a], ids[b]);
            pairs.push((x.min(y), x.max(y)));
        }
    };
    // pairs of one level: within each bucket, each pair once (in the first bucket the two
    // ranges share)
    for grid in grids.values() {
        for (key, bucket) in grid {
            for (k, &i) in bucket.iter().enumerate() {
                for &j in &bucket[k + 1..] {
                    let (ra, rb) = (&ranges[i as usize], &ranges[j as usize]);
                    let first = [0, 1, 2].map(|a| ra.0[a].max(rb.0[a]));
                    if first == *key {
                        test(i as usize, j as usize);
                    }
                }
            }
        }
    }
    // pairs of two levels: the smaller cell looks into the larger cells' grids
    let mut candidates: Vec<u32> = Vec::new();
    for (a, &level_a) in levels.iter().enumerate() {
        candidates.clear();
        for &level in level_list.iter().filter(|&&l| l > level_a) {
            let grid = &grids[&level];
            let (lo, hi) = range(a, level);
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        if let Some(bucket) = grid.get(&[x, y, z]) {
                            candidates.extend_from_slice(bucket);
                        }
                    }
                }
            }
        }
        candidates.sort_unstable();
        candidates.dedup();
        for &b in &candidates {
            test(a, b as usize);
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// For a planar surface (every point within `1e-9` of the mesh's size from the plane of its
/// largest polygon), the two coordinates spanning the plane; `None` otherwise.
fn planar_axes(points: &[[f64; 3]], cells: &[Vec<usize>]) -> Option<(usize, usize)> {
    // hypot: the normals of cells with coordinates near 1e100 are finite, their squares not
    let len = |n: &[f64; 3]| n[0].hypot(n[1]).hypot(n[2]);
    let normals = cells.iter().map(|c| polygon_normal(c, points));
    let n = normals.max_by(|a, b| len(a).total_cmp(&len(b)))?;
    let l = len(&n);
    if !(l > 0.0 && l.is_finite()) {
        return None;
    }
    let n = [n[0] / l, n[1] / l, n[2] / l];
    let all = Aabb::of(cells.iter().flatten().map(|&v| points[v]));
    let tol = 1e-9 * len(&sub(all.hi, all.lo));
    let o = points[cells[0][0]];
    let mut off = 0.0_f64;
    for c in cells {
        for &v in c {
            off = off.max(dot(sub(points[v], o), n).abs());
        }
    }
    if off > 2.0 * tol {
        return None;
    }
    let drop = (0..3)
        .max_by(|&i, &j| n[i].abs().total_cmp(&n[j].abs()))
        .unwrap_or(2);
    Some(((drop + 1) % 3, (drop + 2) % 3))
}

/// Whether two cells share a face (3D: one of their faces has the same point set; 2D: a
/// side with the same two points).
fn share_face(a: &[usize], ka: CellKind, b: &[usize], kb: CellKind, dim: usize) -> bool {
    let common = a.iter().filter(|v| b.contains(v)).count();
    if dim == 2 {
        if common < 2 {
            return false;
        }
        let k = a.len();
        return (0..k).any(|j| {
            let (u, w) = (a[j], a[(j + 1) % k]);
            let m = b.len();
            (0..m).any(|i| {
                let (x, y) = (b[i], b[(i + 1) % m]);
                (x == u && y == w) || (x == w && y == u)
            })
        });
    }
    if common < 3 {
        return false;
    }
    if ka == CellKind::Tetra && kb == CellKind::Tetra {
        // any 3 points of a tetrahedron are a face
        return true;
    }
    let key = |verts: &[usize], lf: &[usize]| {
        let mut k = [usize::MAX; 4];
        for (j, &l) in lf.iter().enumerate() {
            k[j] = verts[l];
        }
        k.sort_unstable();
        k
    };
    local_faces(ka).iter().any(|la| {
        let k = key(a, la);
        local_faces(kb).iter().any(|lb| key(b, lb) == k)
    })
}

fn mean(pts: impl Iterator<Item = [f64; 3]>) -> [f64; 3] {
    let mut s = [0.0; 3];
    let mut k = 0.0;
    for p in pts {
        for a in 0..3 {
            s[a] += p[a];
        }
        k += 1.0;
    }
    [s[0] / k, s[1] / k, s[2] / k]
}

/// The tetrahedra of a 3D cell (see the module documentation).
fn tetrahedra(points: &[[f64; 3]], verts: &[usize], kind: CellKind, out: &mut Vec<[[f64; 3]; 4]>) {
    out.clear();
    let p = |v: usize| points[v];
    if kind == CellKind::Tetra {
        out.push([p(verts[0]), p(verts[1]), p(verts[2]), p(verts[3])]);
        return;
    }
    let centre = mean(verts.iter().map(|&v| p(v)));
    for lf in local_faces(kind) {
        let f: Vec<[f64; 3]> = lf.iter().map(|&l| p(verts[l])).collect();
        if f.len() == 3 {
            out.push([f[0], f[1], f[2], centre]);
        } else {
            let fc = mean(f.iter().copied());
            for j in 0..f.len() {
                out.push([f[j], f[(j + 1) % f.len()], fc, centre]);
            }
        }
    }
}

/// Whether two 3D cells' interiors intersect (penetration beyond `tol`).
#[allow(clippy::too_many_arguments)]
fn overlap_3d(
    points: &[[f64; 3]],
    a: &[usize],
    ka: CellKind,
    b: &[usize],
    kb: CellKind,
    ba: &Aabb,
    bb: &Aabb,
    tol: f64,
) -> bool {
    let p = |v: usize| points[v];
    if ka == CellKind::Tetra && kb == CellKind::Tetra {
        let s = [p(a[0]), p(a[1]), p(a[2]), p(a[3])];
        return !separated_tets(&s, &[p(b[0]), p(b[1]), p(b[2]), p(b[3])], tol);
    }
    let (mut ta, mut tb) = (Vec::new(), Vec::new());
    tetrahedra(points, a, ka, &mut ta);
    tetrahedra(points, b, kb, &mut tb);
    // only the pieces reaching into the other cell's box can overlap it
    let ta: Vec<_> = ta
        .into_iter()
        .filter(|t| Aabb::of(t.iter().copied()).overlaps(bb, tol, &[0, 1, 2]))
        .collect();
    let tb: Vec<_> = tb
        .into_iter()
        .filter(|t| Aabb::of(t.iter().copied()).overlaps(ba, tol, &[0, 1, 2]))
        .collect();
    ta.iter()
        .any(|s| tb.iter().any(|t| !separated_tets(s, t, tol)))
}

/// Separating axis test for two tetrahedra: whether one of the face normals of either or
/// one cross product of an edge of each separates them (projections overlapping by at most
/// `tol`).
fn separated_tets(s: &[[f64; 3]; 4], t: &[[f64; 3]; 4], tol: f64) -> bool {
    const EDGES: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];
    const FACES: [(usize, usize, usize); 4] = [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)];
    // coordinates relative to a common origin, scaled to about 1: the projections' rounding
    // stays small and the squares of the axes neither overflow (1e100) nor underflow (1e-100)
    let o = s[0];
    let m = s
        .iter()
        .chain(t)
        .flat_map(|p| sub(*p, o))
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    if !(m > 0.0 && m.is_finite()) {
        return false;
    }
    let inv = 1.0 / m;
    let s = s.map(|p| sub(p, o).map(|x| x * inv));
    let t = t.map(|p| sub(p, o).map(|x| x * inv));
    let tol2 = (tol * inv) * (tol * inv);
    // whether the projections on `axis` (not normalised: lengths compared squared, no square
    // root) overlap by at most `tol`; a zero axis separates nothing
    let separates = |axis: [f64; 3]| {
        let l2 = dot(axis, axis);
        if !(l2 > 0.0 && l2.is_finite()) {
            return false;
        }
        let (mut s0, mut s1) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in &s {
            let x = dot(*p, axis);
            s0 = s0.min(x);
            s1 = s1.max(x);
        }
        let (mut t0, mut t1) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in &t {
            let x = dot(*p, axis);
            t0 = t0.min(x);
            t1 = t1.max(x);
        }
        let overlap = s1.min(t1) - s0.max(t0);
        overlap <= 0.0 || overlap * overlap <= tol2 * l2
    };
    // a face plane separates when the other tetrahedron lies beyond it (outward): only that
    // side needs testing (the facets of the Minkowski difference from faces have these
    // outward normals; Ericson 2005, 5.2.1), 4 projections instead of 8
    for (q, r) in [(&s, &t), (&t, &s)] {
        for (f, (i, j, k)) in FACES.into_iter().enumerate() {
            let mut n = cross(sub(q[j], q[i]), sub(q[k], q[i]));
            let l2 = dot(n, n);
            if !(l2 > 0.0 && l2.is_finite()) {
                continue;
            }
            // the vertex off this face is FACES' complement: 3, 2, 1, 0
            if dot(n, sub(q[3 - f], q[i])) > 0.0 {
                n = n.map(|x| -x);
            }
            let d = r
                .iter()
                .map(|p| dot(sub(*p, q[i]), n))
                .fold(f64::INFINITY, f64::min);
            if d >= 0.0 || d * d <= tol2 * l2 {
                return true;
            }
        }
    }
    let es = EDGES.map(|(i, j)| sub(s[j], s[i]));
    let et = EDGES.map(|(i, j)| sub(t[j], t[i]));
    let lt = et.map(|f| dot(f, f));
    for e in es {
        let le = dot(e, e);
        for (f, &lf) in et.iter().zip(&lt) {
            let c = cross(e, *f);
            // parallel edges give no axis of their own
            if dot(c, c) <= 1e-24 * le * lf {
                continue;
            }
            if separates(c) {
                return true;
            }
        }
    }
    false
}

/// The triangles of a polygon, in the plane's coordinates (see the module documentation).
fn triangles(points: &[[f64; 3]], verts: &[usize], axes: (usize, usize)) -> Vec<[[f64; 2]; 3]> {
    let q = |v: usize| [points[v][axes.0], points[v][axes.1]];
    if verts.len() == 3 {
        return vec![[q(verts[0]), q(verts[1]), q(verts[2])]];
    }
    let c = mean(verts.iter().map(|&v| points[v]));
    let c = [c[axes.0], c[axes.1]];
    let k = verts.len();
    (0..k)
        .map(|j| [q(verts[j]), q(verts[(j + 1) % k]), c])
        .collect()
}

/// Whether two polygons of a planar mesh overlap (penetration beyond `tol`).
fn overlap_2d(
    points: &[[f64; 3]],
    a: &[usize],
    b: &[usize],
    ba: &Aabb,
    bb: &Aabb,
    axes: (usize, usize),
    tol: f64,
) -> bool {
    let in_box = |t: &[[f64; 2]; 3], bx: &Aabb| {
        let (x, y) = axes;
        let lo0 = t.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
        let hi0 = t.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max);
        let lo1 = t.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min);
        let hi1 = t.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
        hi0.min(bx.hi[x]) - lo0.max(bx.lo[x]) > tol && hi1.min(bx.hi[y]) - lo1.max(bx.lo[y]) > tol
    };
    let ta: Vec<_> = triangles(points, a, axes)
        .into_iter()
        .filter(|t| in_box(t, bb))
        .collect();
    let tb: Vec<_> = triangles(points, b, axes)
        .into_iter()
        .filter(|t| in_box(t, ba))
        .collect();
    ta.iter()
        .any(|s| tb.iter().any(|t| !separated_triangles(s, t, tol)))
}

/// Separating axis test for two triangles in a plane: whether a side normal of either
/// separates them (projections overlapping by at most `tol`).
fn separated_triangles(s: &[[f64; 2]; 3], t: &[[f64; 2]; 3], tol: f64) -> bool {
    // relative to a common origin and scaled to about 1, as in `separated_tets`
    let o = s[0];
    let m = s
        .iter()
        .chain(t)
        .flat_map(|p| [p[0] - o[0], p[1] - o[1]])
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    if !(m > 0.0 && m.is_finite()) {
        return false;
    }
    let s = s.map(|p| [(p[0] - o[0]) / m, (p[1] - o[1]) / m]);
    let t = t.map(|p| [(p[0] - o[0]) / m, (p[1] - o[1]) / m]);
    let tol = tol / m;
    for q in [&s, &t] {
        for i in 0..3 {
            let (a, b) = (q[i], q[(i + 1) % 3]);
            let (nx, ny) = (-(b[1] - a[1]), b[0] - a[0]);
            let l = (nx * nx + ny * ny).sqrt();
            if !(l > 0.0 && l.is_finite()) {
                continue;
            }
            let proj = |p: &[f64; 2]| (p[0] * nx + p[1] * ny) / l;
            let (mut s0, mut s1) = (f64::INFINITY, f64::NEG_INFINITY);
            for p in &s {
                s0 = s0.min(proj(p));
                s1 = s1.max(proj(p));
            }
            let (mut t0, mut t1) = (f64::INFINITY, f64::NEG_INFINITY);
            for p in &t {
                t0 = t0.min(proj(p));
                t1 = t1.max(proj(p));
            }
            if s1.min(t1) - s0.max(t0) <= tol {
                return true;
            }
        }
    }
    false
}
