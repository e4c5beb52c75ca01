//! The shipped prelude (`prelude.tmr`, `dimension 2 3`) and the per-dimension common files
//! after it check to the same embeddings and rules as the common file of each dimension did
//! before the prelude was split out (kept as fixtures): the split moves text, it changes no
//! datum, orbit, policy or program. Bit-identical simulations follow from this; the other
//! tests of this crate and the pytest suite check them unchanged.

use topomech_rules::check::Rule;
use topomech_rules::{load_sources, load_sources_for, RuleSet};

const PRELUDE: &str = include_str!("../../models/prelude.tmr");
const COMMON2D: &str = include_str!("../../models/common2d.tmr");
const COMMON3D: &str = include_str!("../../models/common3d.tmr");
const BEFORE2D: &str = include_str!("fixtures/common2d_before_prelude.tmr");
const BEFORE3D: &str = include_str!("fixtures/common3d_before_prelude.tmr");

/// The rules by name, without their file names and source positions (the text moved).
fn unplaced(r: &RuleSet) -> Vec<Rule> {
    let mut rules: Vec<Rule> = r
        .rules()
        .iter()
        .cloned()
        .map(|mut rule| {
            rule.file = String::new();
            for n in &mut rule.nodes {
                n.pos = topomech_rules::ast::Pos::default();
            }
            rule
        })
        .collect();
    rules.sort_by(|a, b| a.name.cmp(&b.name));
    rules
}

#[test]
fn prelude_and_common_file_are_the_common_file_as_before() {
    for (dim, common, before) in [(2, COMMON2D, BEFORE2D), (3, COMMON3D, BEFORE3D)] {
        let (now, _) = load_sources_for(
            dim,
            &[
                ("prelude.tmr".to_string(), PRELUDE.to_string()),
                (format!("common{dim}d.tmr"), common.to_string()),
            ],
        )
        .unwrap_or_else(|d| panic!("{dim}D: {d:?}"));
        let (was, _) = load_sources(&[(format!("common{dim}d.tmr"), before.to_string())])
            .unwrap_or_else(|d| panic!("{dim}D before: {d:?}"));
        assert_eq!(now.dimension(), dim);
        // same embeddings in the same order (storage is declared in this order)
        assert_eq!(now.embeddings(), was.embeddings(), "{dim}D embeddings");
        let (n, w) = (unplaced(&now), unplaced(&was));
        assert_eq!(n.len(), w.len(), "{dim}D rule count");
        assert_eq!(n, w, "{dim}D rules");
    }
}

#[test]
fn the_common_files_keep_only_what_differs() {
    // what both dimensions share is declared once, in the prelude
    for name in [
        "position", "rest", "velocity", "force", "fixed", "f_ext", "dx", "dv", "df",
    ] {
        let decl = format!("embedding {name} ");
        assert!(PRELUDE.contains(&decl), "prelude declares {name}");
        assert!(!COMMON2D.contains(&decl), "common2d.tmr redeclares {name}");
        assert!(!COMMON3D.contains(&decl), "common3d.tmr redeclares {name}");
    }
    for rule in ["init_rest", "symplectic_euler", "explicit_euler"] {
        let decl = format!("rule {rule}");
        assert!(PRELUDE.contains(&decl), "prelude has {rule}");
        assert!(!COMMON2D.contains(&decl) && !COMMON3D.contains(&decl));
    }
    // a common file alone no longer loads: it needs the prelude's `rest`
    let err = load_sources(&[("common2d.tmr".to_string(), COMMON2D.to_string())]).unwrap_err();
    assert!(err.iter().any(|d| d.message.contains("rest")), "{err:?}");
}

/// The shipped files before the shear, glue and topology files were merged across
/// dimensions (fixtures: `fixtures/before_merge/`).
mod before_merge {
    pub const SHEAR2D: &str = include_str!("fixtures/before_merge/shear2d.tmr");
    pub const SHEAR3D: &str = include_str!("fixtures/before_merge/shear3d.tmr");
    pub const GLUE2D: &str = include_str!("fixtures/before_merge/glue2d.tmr");
    pub const GLUE3D: &str = include_str!("fixtures/before_merge/glue3d.tmr");
    pub const TOPOLOGY2D: &str = include_str!("fixtures/before_merge/topology2d.tmr");
    pub const TOPOLOGY3D: &str = include_str!("fixtures/before_merge/topology3d.tmr");
}

const SHEAR: &str = include_str!("../../models/shear.tmr");
const SHEAR_VOLUMIC: &str = include_str!("../../models/shear3d.tmr");
const GLUE: &str = include_str!("../../models/glue.tmr");
const TOPOLOGY: &str = include_str!("../../models/topology.tmr");
const TOPOLOGY2D: &str = include_str!("../../models/topology2d.tmr");
const TOPOLOGY3D: &str = include_str!("../../models/topology3d.tmr");

/// Rule files: `(name, text)`.
type Files<'a> = Vec<(&'a str, &'a str)>;

/// The files loaded for `dim` after the prelude and the common file of that dimension.
fn load_with_common(dim: usize, files: &[(&str, &str)]) -> RuleSet {
    let common = if dim == 2 { COMMON2D } else { COMMON3D };
    let mut srcs = vec![
        ("prelude.tmr".to_string(), PRELUDE.to_string()),
        (format!("common{dim}d.tmr"), common.to_string()),
    ];
    srcs.extend(
        files
            .iter()
            .map(|(n, t)| ((*n).to_string(), (*t).to_string())),
    );
    load_sources_for(dim, &srcs)
        .unwrap_or_else(|d| {
            panic!(
                "{dim}D {files:?}: {d:?}",
                files = files.iter().map(|f| f.0).collect::<Vec<_>>()
            )
        })
        .0
}

/// The embeddings by name (the merged files declare them in another order; storage order
/// changes no value).
fn embeddings_by_name(r: &RuleSet) -> Vec<topomech_rules::check::EmbDecl> {
    let mut e = r.embeddings().to_vec();
    e.sort_by(|a, b| a.name.cmp(&b.name));
    e
}

/// A rule's checked form as text, with each embedding index (`emb: 3`, `emb: Some(3)`,
/// `guard_reads: [3, 4]`) replaced by the embedding's name: the merged files declare the
/// same embeddings in another order, which renumbers them and changes nothing else.
fn by_name(r: &RuleSet, rule: &Rule) -> String {
    let names: Vec<&str> = r.embeddings().iter().map(|e| e.name.as_str()).collect();
    let text = format!("{rule:?}");
    let mut out = String::new();
    let mut rest = text.as_str();
    loop {
        let emb = rest.find("emb: ");
        let reads = rest.find("guard_reads: [");
        let (at, skip) = match (emb, reads) {
            (Some(e), Some(g)) if g < e => (g, "guard_reads: [".len()),
            (Some(e), _) => (e, "emb: ".len()),
            (None, Some(g)) => (g, "guard_reads: [".len()),
            (None, None) => break,
        };
        out.push_str(&rest[..at + skip]);
        rest = &rest[at + skip..];
        let list = skip > "emb: ".len();
        if rest.starts_with("Some(") {
            out.push_str("Some(");
            rest = &rest[5..];
        }
        loop {
            let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
            if digits == 0 {
                break;
            }
            let k: usize = rest[..digits].parse().expect("an index");
            out.push_str(names[k]);
            rest = &rest[digits..];
            if list && rest.starts_with(", ") {
                out.push_str(", ");
                rest = &rest[2..];
            } else {
                break;
            }
        }
    }
    out.push_str(rest);
    out
}

/// The models without their files, positions and dimension lists.
fn models_unplaced(r: &RuleSet) -> Vec<topomech_rules::model::Model> {
    let mut m: Vec<_> = r
        .models()
        .iter()
        .cloned()
        .map(|mut m| {
            m.file = String::new();
            m.pos = topomech_rules::ast::Pos::default();
            m.dimensions.clear();
            m
        })
        .collect();
    m.sort_by(|a, b| a.name.cmp(&b.name));
    m
}

/// The shear springs, the ground rule and the fracture strains are written once for both
/// dimensions (`shear.tmr`, `glue.tmr`, `topology.tmr`, all `dimension 2 3`; the 3D-only
/// volumic shear stays in `shear3d.tmr`, the cuts that unsew alpha2 or alpha3 in
/// `topology{2,3}d.tmr`). Loaded for each dimension they check to exactly the embeddings,
/// rules (labels, programs, guards) and model declarations of the per-dimension files they
/// replace: the merge moves text and drops label 3 on 2-maps, and changes no datum, orbit,
/// policy or program, so every simulation is unchanged (the other tests check them too) —
/// except the fracture strain, moved on purpose from the half-edge to the edge (applied to
/// the old files before comparing).
#[test]
fn the_merged_files_are_the_per_dimension_files_as_before() {
    use before_merge as b;
    let cases: [(usize, Files, Files); 2] = [
        (
            2,
            vec![
                ("shear.tmr", SHEAR),
                ("glue.tmr", GLUE),
                ("topology.tmr", TOPOLOGY),
                ("topology2d.tmr", TOPOLOGY2D),
            ],
            vec![
                ("shear2d.tmr", b::SHEAR2D),
                ("glue2d.tmr", b::GLUE2D),
                ("topology2d.tmr", b::TOPOLOGY2D),
            ],
        ),
        (
            3,
            vec![
                ("shear.tmr", SHEAR),
                ("shear3d.tmr", SHEAR_VOLUMIC),
                ("glue.tmr", GLUE),
                ("topology.tmr", TOPOLOGY),
                ("topology3d.tmr", TOPOLOGY3D),
            ],
            vec![
                ("shear3d.tmr", b::SHEAR3D),
                ("glue3d.tmr", b::GLUE3D),
                ("topology3d.tmr", b::TOPOLOGY3D),
            ],
        ),
    ];
    for (dim, now, was) in cases {
        // one change on purpose since the per-dimension files: the fracture strain lives on
        // the edge and is computed per edge-end (it was per half-edge); the old files with
        // that change applied are what the merged files must equal
        let edge = if dim == 3 {
            ("<0,2,3>", "<2,3>")
        } else {
            ("<0,2>", "<2>")
        };
        // and a second (2026-12-03): the plane cut compares the two distances' signs instead
        // of testing their product, which underflows to 0 for tiny distances
        let vol = if dim == 3 { "<0,1,2>" } else { "<0,1>" };
        let product_guard = format!(
            "  where (dot(mean{vol}(a.position), normal) - offset) * (dot(mean{vol}(b.position), normal) - offset) < 0.0"
        );
        // and a third (2026-12-03): a centroid within 1e-12 of the other's distance from the
        // plane is on it, as for a blade (rounding put centroids on the plane on either side)
        let signs_guard = format!(
            "  where {{\n    let da = dot(mean{vol}(a.position), normal) - offset\n    let db = dot(mean{vol}(b.position), normal) - offset\n    let opposite = (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0)\n    let near = min(abs(da), abs(db))\n    let far = max(abs(da), abs(db))\n    opposite && near > 1e-12 * far\n  }}"
        );
        // and a fifth (2026-12-05): the ground's test below the plane moved from the guard,
        // which read the positions every step writes (so the rule was planned again every
        // step), into the body
        let ground_was = "  where !v.fixed && dot(v.position - p, n) < 0.0\n  compute {\n    v.position = v.position - dot(v.position - p, n) * n\n    v.velocity = v.velocity - min(dot(v.velocity, n), 0.0) * n\n  }";
        let ground_now = "  where !v.fixed\n  compute {\n    let d = dot(v.position - p, n)\n    v.position = if d < 0.0 { v.position - d * n } else { v.position }\n    v.velocity = if d < 0.0 { v.velocity - min(dot(v.velocity, n), 0.0) * n } else { v.velocity }\n  }";
        let was: Vec<(&str, String)> = was
            .iter()
            .map(|(n, t)| {
                let t = t
                    .replace(ground_was, ground_now)
                    .replace(&product_guard, &signs_guard)
                    .replace(
                        "embedding spring_strain : f64 on <0>",
                        &format!("embedding spring_strain : f64 on {}", edge.0),
                    )
                    .replace(
                        "rule spring_strains {\n  left { a : <> hook   b : <>   a -0- b }",
                        &format!(
                            "rule spring_strains {{\n  left {{ a : {0} hook   b : {0}   a -0- b }}",
                            edge.1
                        ),
                    )
                    // and a fourth (2026-12-05): the strain multiplies by the inverse rest
                    // length of the edge, computed once by an init rule, instead of dividing
                    // by the rest positions' distance each time
                    .replace(
                        "a.spring_strain = norm(b.position - a.position) / norm(b.rest - a.rest) - 1.0",
                        "a.spring_strain = norm(b.position - a.position) * a.spring_inv_l0 - 1.0",
                    )
                    .replace(
                        "rule spring_strains {",
                        &format!(
                            "embedding spring_inv_l0 : f64 on {0}\n\nrule spring_strains_init {{\n  left {{ a : {1} hook   b : {1}   a -0- b }}\n  compute {{ a.spring_inv_l0 = 1.0 / norm(b.rest - a.rest) }}\n}}\n\nrule spring_strains {{",
                            edge.0, edge.1
                        ),
                    );
                (*n, t)
            })
            .collect();
        let was: Files = was.iter().map(|(n, t)| (*n, t.as_str())).collect();
        let (now, was) = (load_with_common(dim, &now), load_with_common(dim, &was));
        assert_eq!(now.dimension(), dim);
        assert_eq!(
            embeddings_by_name(&now),
            embeddings_by_name(&was),
            "{dim}D embeddings"
        );
        // rules added since the merge are not in the old files: the blade's cut, and the
        // explicit integrators joined with the ground (2026-12-05; `loads.rs` checks them
        // against the two rules in turn, bit for bit)
        let added = [
            "cut_swept",
            "symplectic_euler_ground",
            "explicit_euler_ground",
        ];
        let (mut n, w) = (unplaced(&now), unplaced(&was));
        n.retain(|r| !added.contains(&r.name.as_str()));
        assert_eq!(
            n.iter().map(|r| &r.name).collect::<Vec<_>>(),
            w.iter().map(|r| &r.name).collect::<Vec<_>>(),
            "{dim}D rule names"
        );
        for (a, b) in n.iter().zip(&w) {
            assert_eq!(by_name(&now, a), by_name(&was, b), "{dim}D rule {}", a.name);
        }
        assert_eq!(
            models_unplaced(&now),
            models_unplaced(&was),
            "{dim}D models"
        );
    }
    // the shared shear models say they serve both dimensions; the volumic one 3D alone
    let r3 = load_with_common(3, &[("shear.tmr", SHEAR), ("shear3d.tmr", SHEAR_VOLUMIC)]);
    for (name, dims) in [
        ("shear_isotropic", vec![2, 3]),
        ("shear_anisotropic", vec![2, 3]),
        ("shear_volumic", vec![3]),
    ] {
        assert_eq!(r3.model(name).expect(name).dimensions, dims, "{name}");
    }
    // one text for both: no per-dimension copy of what is shared is shipped any more
    for (file, text) in [
        ("shear3d.tmr", SHEAR_VOLUMIC),
        ("topology2d.tmr", TOPOLOGY2D),
        ("topology3d.tmr", TOPOLOGY3D),
    ] {
        assert!(
            !text.contains("rule shear_isotropic") && !text.contains("rule spring_strains"),
            "{file}"
        );
    }
}
