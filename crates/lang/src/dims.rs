//! Dimension-independent rule files: a file that serves 2-maps and 3-maps (`dimension 2 3`,
//! or no `dimension` line), read for a 2-map.
//!
//! On a 2-map alpha3 is free (every dart is its own alpha3 image), so an orbit `<..., 3>` is
//! the orbit without 3: label 3 is dropped from embedding orbits, node orbit types (the
//! position where the rule's reference node, its first hook, has 3, on every node) and
//! aggregates, and a loop `a -3- a` (free darts at 3) is always true and dropped. What cannot
//! be read on a 2-map is refused with the `dimension` condition: an arc `a -3- b` between two
//! nodes (it never matches), or a label 3 at a position where the reference node has another
//! label (a relabelling through alpha3).

use crate::ast::{self, Expr, ExprKind, Pos, Stmt};
use crate::check::{Diagnostic, Severity};

fn error(out: &mut Vec<Diagnostic>, file: &str, pos: Pos, message: String) {
    out.push(Diagnostic {
        file: file.to_string(),
        pos,
        severity: Severity::Error,
        condition: "dimension",
        message,
    });
}

/// Drops label 3 from file `f` (named `file`) for a 2-map; refusals go to `out`.
pub(crate) fn drop_label3(file: &str, f: &mut ast::File, out: &mut Vec<Diagnostic>) {
    for e in &mut f.embeddings {
        e.orbit.retain(|&l| l != 3);
    }
    for r in &mut f.rules {
        let rn = r.name.clone();
        // positions where the reference node (first hook, else first node) has label 3
        let drop: Vec<usize> = r
            .left
            .as_ref()
            .and_then(|g| g.nodes.iter().find(|n| n.hook).or(g.nodes.first()))
            .map(|n| {
                n.orbit
                    .iter()
                    .enumerate()
                    .filter(|(_, l)| **l == Some(3))
                    .map(|(t, _)| t)
                    .collect()
            })
            .unwrap_or_default();
        for (side, g) in [("left", r.left.as_mut()), ("right", r.right.as_mut())] {
            let Some(g) = g else { continue };
            for n in &mut g.nodes {
                let mut kept = Vec::new();
                for (t, l) in n.orbit.iter().enumerate() {
                    if drop.contains(&t) {
                        if !matches!(l, Some(3) | None) {
                            error(
                                out,
                                file,
                                n.orbit_pos,
                                format!(
                                    "rule '{rn}': node '{}' has label {} where the hook has 3 in the {side} graph; on a 2-map (alpha3 free) this cannot be read: put the rule in a 'dimension 3' file",
                                    n.name,
                                    l.map_or("_".to_string(), |x| x.to_string())
                                ),
                            );
                        }
                        continue;
                    }
                    if *l == Some(3) {
                        error(
                            out,
                            file,
                            n.orbit_pos,
                            format!(
                                "rule '{rn}': node '{}' has label 3 where the hook has another label in the {side} graph; on a 2-map (alpha3 free) this cannot be read: put the rule in a 'dimension 3' file",
                                n.name
                            ),
                        );
                    }
                    kept.push(*l);
                }
                n.orbit = kept;
            }
            let mut arcs = Vec::new();
            for a in std::mem::take(&mut g.arcs) {
                if a.dim != 3 {
                    arcs.push(a);
                } else if a.a != a.b {
                    error(
                        out,
                        file,
                        a.pos,
                        format!(
                            "rule '{rn}': arc {} -3- {} in the {side} graph can never hold on a 2-map (alpha3 is free there): put the rule in a 'dimension 3' file",
                            a.a, a.b
                        ),
                    );
                }
            }
            g.arcs = arcs;
        }
        if let Some(e) = &mut r.guard {
            drop_in_expr(e);
        }
        for s in &mut r.compute {
            drop_in_stmt(s);
        }
    }
}

fn drop_in_stmt(s: &mut Stmt) {
    match s {
        Stmt::Let { value, .. } | Stmt::Write { value, .. } => drop_in_expr(value),
    }
}

fn drop_in_expr(e: &mut Expr) {
    match &mut e.kind {
        ExprKind::Aggregate { orbit, .. } => orbit.retain(|&l| l != 3),
        ExprKind::Call { args, .. } => args.iter_mut().for_each(drop_in_expr),
        ExprKind::Binary(_, a, b) => {
            drop_in_expr(a);
            drop_in_expr(b);
        }
        ExprKind::Unary(_, a) => drop_in_expr(a),
        ExprKind::If(c, a, b) => {
            drop_in_expr(c);
            drop_in_expr(a);
            drop_in_expr(b);
        }
        ExprKind::Block(stmts, r) => {
            stmts.iter_mut().for_each(drop_in_stmt);
            drop_in_expr(r);
        }
        ExprKind::Real(_)
        | ExprKind::Int(_)
        | ExprKind::Bool(_)
        | ExprKind::Name(_)
        | ExprKind::Read { .. } => {}
    }
}
