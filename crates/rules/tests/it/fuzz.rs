//! The parser and checker never panic, whatever the input: random bytes, random token soups
//! and mutations of the shipped rule files (bounded by proptest's case count, so this runs in
//! `make test` in a few seconds). Random shipped rules applied at random hooks keep the map
//! valid.

use proptest::prelude::*;
use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_gmap::Dart;
use topomech_rules::{library, load_sources, Params};

const TOKENS: &[&str] = &[
    "dimension",
    "2",
    "3",
    "embedding",
    "rule",
    "left",
    "right",
    "compute",
    "where",
    "hook",
    "let",
    "if",
    "else",
    "{",
    "}",
    "(",
    ")",
    "<",
    ">",
    ",",
    ":",
    ";",
    "=",
    "-",
    "+",
    "*",
    "/",
    "!",
    ".",
    "_",
    "a",
    "b",
    "n0",
    "position",
    "f64",
    "vec3",
    "on",
    "sum",
    "mean",
    "count",
    "0",
    "1",
    "2",
    "1.5",
    "true",
    "&&",
    "==",
    "norm",
    "dot",
    "policy",
    "derived",
    "\n",
    " ",
];

fn mutate(src: &str, edits: &[(prop::sample::Index, u8, u8)]) -> String {
    let mut b: Vec<u8> = src.bytes().collect();
    for (i, kind, x) in edits {
        if b.is_empty() {
            break;
        }
        let k = i.index(b.len());
        match kind % 3 {
            0 => b[k] = b"{}()<>,:;=-_.0123abn #\n"[*x as usize % 23],
            1 => {
                b.remove(k);
            }
            _ => b.insert(k, b"{}()<>,:;=-_.0123abn #\n"[*x as usize % 23]),
        }
    }
    String::from_utf8_lossy(&b).into_owned()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn random_text_never_panics(s in ".{0,200}") {
        let _ = load_sources(&[("f.tmr".into(), s)]);
    }

    #[test]
    fn token_soup_never_panics(toks in prop::collection::vec(prop::sample::select(TOKENS), 0..80)) {
        let _ = load_sources(&[("f.tmr".into(), toks.join(" "))]);
    }

    #[test]
    fn mutated_library_never_panics(dim in 2usize..4, edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), any::<u8>()), 1..6)) {
        let (name, src) = library(dim).unwrap();
        let src = mutate(&src, &edits);
        if let Ok((rules, _)) = load_sources(&[(name, src)]) {
            // whatever still checks must also apply without breaking a map
            let mesh = if dim == 2 { grid([2, 2], [1.0, 1.0], GridElement::Mixed) } else { cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Tetra) };
            // each rule on the mesh as built: applied one after the other, the library's
            // refinements (split, triangulate, subdivide everywhere) multiply the map and a
            // case took over a second in debug builds; sequences of rules on changed maps are
            // `random_rules_at_random_hooks_keep_the_map_valid`'s
            let (g0, _) = build(&mesh, &BuildOptions::default()).unwrap();
            for r in rules.rules().iter().map(|r| r.name.clone()).collect::<Vec<_>>() {
                let mut g = g0.clone();
                let _ = rules.apply_everywhere(&mut g, &r, &Params::new());
                prop_assert!(g.is_valid(), "rule {} broke the map", r);
            }
        }
    }

    #[test]
    fn random_rules_at_random_hooks_keep_the_map_valid(
        three in any::<bool>(),
        steps in prop::collection::vec((any::<prop::sample::Index>(), any::<prop::sample::Index>(), any::<prop::sample::Index>()), 1..12),
    ) {
        let dim = if three { 3 } else { 2 };
        let (rules, _) = load_sources(&[library(dim).unwrap()]).unwrap();
        let mesh = if three { cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Mixed) } else { grid([2, 2], [1.0, 1.0], GridElement::Mixed) };
        let (mut g, _) = build(&mesh, &BuildOptions::default()).unwrap();
        let names: Vec<String> = rules.rules().iter().map(|r| r.name.clone()).collect();
        for (r, a, b) in steps {
            let name = &names[r.index(names.len())];
            let darts: Vec<Dart> = g.darts().collect();
            if darts.is_empty() {
                break;
            }
            let hooks = rules.rule(name).unwrap().hooks.len();
            let at: Vec<Dart> = [a, b][..hooks.min(2)].iter().map(|i| darts[i.index(darts.len())]).collect();
            let before = g.cell_counts();
            let res = rules.apply_at(&mut g, name, &at, &Params::new());
            let v = g.validate();
            prop_assert!(v.is_empty(), "{} at {:?}: {:?}", name, at, v);
            if res.is_err() {
                prop_assert_eq!(g.cell_counts(), before, "a refused application changed the map");
            }
        }
    }
}
