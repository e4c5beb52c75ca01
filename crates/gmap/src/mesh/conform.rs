//! Non-conforming interfaces: boundary faces (3D) or boundary sides (2D) of different cells
//! that overlap, which a conforming mesh never has. Two cells whose shared face is split two
//! ways (mismatched diagonals) or carries a hanging node leave the halves of that face
//! unmatched, on the boundary, lying on top of each other: a hidden crack. Found with a
//! uniform grid of the facets' bounding boxes, so the cost stays linear in the boundary size.

use super::{cross, dot, fx_map, max_edge, norm, polygon_normal, sub, FacePair, FxMap};

/// A boundary face (3 or 4 points) or side (2 points) of a cell.
pub(crate) struct Facet {
    /// The cell (input index).
    pub(crate) cell: usize,
    /// Its points (input indices), in cyclic order.
    pub(crate) verts: Vec<usize>,
}

/// Relative tolerance (of the facets' size) for "on the same line / plane" and "overlapping".
const TOL: f64 = 1e-6;

/// Every pair of facets of different cells that overlap (with a positive length or area),
/// except facets that coincide point for point with distinct points (an interface the user
/// cut on purpose). Sorted by (cell, cell).
pub(crate) fn overlapping(points: &[[f64; 3]], facets: &[Facet]) -> Vec<FacePair> {
    if facets.len() < 2 {
        return Vec::new();
    }
    let sizes: Vec<f64> = facets.iter().map(|f| max_edge(&f.verts, points)).collect();
    let h = sizes.iter().sum::<f64>() / facets.len() as f64;
    if !(h.is_finite() && h > 0.0) {
        return Vec::new();
    }
    let mut origin = [f64::INFINITY; 3];
    for f in facets {
        for &v in &f.verts {
            for a in 0..3 {
                origin[a] = origin[a].min(points[v][a]);
            }
        }
    }
    let ranges: Vec<([i64; 3], [i64; 3])> = facets
        .iter()
        .zip(&sizes)
        .map(|(f, &s)| {
            let pad = TOL * s;
            let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
            for &v in &f.verts {
                for a in 0..3 {
                    let x = points[v][a] - origin[a];
                    lo[a] = lo[a].min(((x - pad) / h).floor() as i64);
                    hi[a] = hi[a].max(((x + pad) / h).floor() as i64);
                }
            }
            (lo, hi)
        })
        .collect();
    let mut grid: FxMap<[i64; 3], Vec<u32>> = fx_map(facets.len());
    for (i, (lo, hi)) in ranges.iter().enumerate() {
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    grid.entry([x, y, z]).or_default().push(i as u32);
                }
            }
        }
    }
    let mut pairs = Vec::new();
    for (key, bucket) in &grid {
        for (k, &i) in bucket.iter().enumerate() {
            for &j in &bucket[k + 1..] {
                let (fa, fb) = (&facets[i as usize], &facets[j as usize]);
                if fa.cell == fb.cell {
                    continue;
                }
                // test each pair once: in the first bucket the two ranges share
                let (ra, rb) = (&ranges[i as usize], &ranges[j as usize]);
                let first = [0, 1, 2].map(|a| ra.0[a].max(rb.0[a]));
                if first != *key {
                    continue;
                }
                let size = sizes[i as usize].max(sizes[j as usize]);
                if let Some(why) = overlap(points, &fa.verts, &fb.verts, size) {
                    let (a, b) = if fa.cell < fb.cell {
                        (fa, fb)
                    } else {
                        (fb, fa)
                    };
                    pairs.push(FacePair {
                        a: a.cell,
                        face_a: a.verts.clone(),
                        b: b.cell,
                        face_b: b.verts.clone(),
                        why,
                    });
                }
            }
        }
    }
    pairs.sort_unstable_by(|x, y| {
        (x.a, x.b, &x.face_a, &x.face_b).cmp(&(y.a, y.b, &y.face_a, &y.face_b))
    });
    pairs
}

/// Whether two facets overlap, and how: `hanging node P` (a point of one inside the other,
/// at none of its points) or `overlapping faces`. `None` when they only touch, lie apart, or
/// coincide point for point with distinct points.
fn overlap(points: &[[f64; 3]], a: &[usize], b: &[usize], size: f64) -> Option<String> {
    let tol = TOL * size;
    let p = |v: usize| points[v];
    let coincident = |x: usize, list: &[usize]| list.iter().any(|&y| norm(sub(p(x), p(y))) <= tol);
    if a.len() == 2 && b.len() == 2 {
        let d = sub(p(a[1]), p(a[0]));
        let la = norm(d);
        if la <= tol {
            return None;
        }
        let u = [d[0] / la, d[1] / la, d[2] / la];
        let off = |x: usize| norm(cross(sub(p(x), p(a[0])), u));
        if off(b[0]) > tol || off(b[1]) > tol {
            return None;
        }
        let t = |x: usize| dot(sub(p(x), p(a[0])), u);
        let (t0, t1) = (t(b[0]), t(b[1]));
        let len = la.min(t0.max(t1)) - 0f64.max(t0.min(t1));
        if len <= tol {
            return None;
        }
    } else if a.len() >= 3 && b.len() >= 3 {
        let na = polygon_normal(a, points);
        let nb = polygon_normal(b, points);
        let (la, lb) = (norm(na), norm(nb));
        if la == 0.0 || lb == 0.0 || dot(na, nb).abs() < (1.0 - 1e-6) * la * lb {
            return None;
        }
        let n = [na[0] / la, na[1] / la, na[2] / la];
        let o = p(a[0]);
        if b.iter().any(|&v| dot(sub(p(v), o), n).abs() > tol) {
            return None;
        }
        let drop = (0..3)
            .max_by(|&i, &j| n[i].abs().total_cmp(&n[j].abs()))
            .unwrap_or(2);
        let (x, y) = ((drop + 1) % 3, (drop + 2) % 3);
        let flat =
            |f: &[usize]| -> Vec<[f64; 2]> { f.iter().map(|&v| [p(v)[x], p(v)[y]]).collect() };
        let (qa, qb) = (flat(a), flat(b));
        if separated(&qa, &qb, tol) || separated(&qb, &qa, tol) {
            return None;
        }
    } else {
        return None;
    }
    if a.len() == b.len() && b.iter().all(|&v| coincident(v, a)) {
        return None;
    }
    let hanging = b
        .iter()
        .find(|&&v| !coincident(v, a))
        .or_else(|| a.iter().find(|&&v| !coincident(v, b)));
    Some(match hanging {
        Some(v) if b.contains(v) && inside(points, *v, a, tol) => format!("hanging node {v}"),
        Some(v) if a.contains(v) && inside(points, *v, b, tol) => format!("hanging node {v}"),
        _ => "overlapping faces".into(),
    })
}

/// Whether an edge of `q` separates the convex polygons `q` and `r` (their projections on
/// its normal overlap by at most `tol`).
fn separated(q: &[[f64; 2]], r: &[[f64; 2]], tol: f64) -> bool {
    let k = q.len();
    for i in 0..k {
        let (s, e) = (q[i], q[(i + 1) % k]);
        let (nx, ny) = (-(e[1] - s[1]), e[0] - s[0]);
        let l = (nx * nx + ny * ny).sqrt();
        if l == 0.0 {
            continue;
        }
        let proj = |v: &[f64; 2]| (v[0] * nx + v[1] * ny) / l;
        let (mut q0, mut q1) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in q {
            q0 = q0.min(proj(v));
            q1 = q1.max(proj(v));
        }
        let (mut r0, mut r1) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in r {
            r0 = r0.min(proj(v));
            r1 = r1.max(proj(v));
        }
        if q1 <= r0 + tol || r1 <= q0 + tol {
            return true;
        }
    }
    false
}

/// Whether point `v` lies on facet `f` (a segment, or a convex polygon), within `tol`.
fn inside(points: &[[f64; 3]], v: usize, f: &[usize], tol: f64) -> bool {
    let p = points[v];
    if f.len() == 2 {
        let (a, b) = (points[f[0]], points[f[1]]);
        let d = sub(b, a);
        let l = norm(d);
        let t = dot(sub(p, a), d) / l;
        return l > 0.0 && t > -tol && t < l + tol && norm(cross(sub(p, a), d)) / l <= tol;
    }
    let n = polygon_normal(f, points);
    let k = f.len();
    (0..k).all(|i| {
        let (a, b) = (points[f[i]], points[f[(i + 1) % k]]);
        dot(cross(sub(b, a), sub(p, a)), n) >= -tol * norm(n)
    })
}
