//! Rule files that serve 2-maps and 3-maps (`dimension 2 3`, or no dimension line): loaded
//! for a 2-map, label 3 is dropped (alpha3 is free there), so the 3D stretch springs read as
//! exactly the 2D ones; what cannot be read on a 2-map is refused where it is written.

use topomech_rules::check::Rule;
use topomech_rules::check::LOAD_FOR_A_DIMENSION;
use topomech_rules::{load_files, load_files_for, load_sources, load_sources_for, RuleSet};

const PRELUDE: &str = include_str!("../../../physics/models/prelude.tmr");
const COMMON2D: &str = include_str!("../../../physics/models/common2d.tmr");
const COMMON3D: &str = include_str!("../../../physics/models/common3d.tmr");
/// The 2D stretch file as shipped before the two files were merged (a fixture).
const STRETCH2D: &str = include_str!("stretch2d_before_merge.tmr");
/// The shipped stretch file, for both dimensions; read as a 3D file when its dimension line
/// says 3 alone.
const STRETCH: &str = include_str!("../../../physics/models/stretch.tmr");

fn stretch3d() -> String {
    STRETCH.replace("dimension 2 3", "dimension 3")
}

fn srcs(common: &str, model: &str) -> Vec<(String, String)> {
    vec![
        ("prelude.tmr".to_string(), PRELUDE.to_string()),
        ("common.tmr".to_string(), common.to_string()),
        ("stretch.tmr".to_string(), model.to_string()),
    ]
}

/// The rules without their source positions (columns move when `<2,3>` is written for `<2>`).
fn unplaced(r: &RuleSet) -> Vec<Rule> {
    r.rules()
        .iter()
        .cloned()
        .map(|mut rule| {
            for n in &mut rule.nodes {
                n.pos = topomech_rules::ast::Pos::default();
            }
            rule
        })
        .collect()
}

/// The shipped stretch file (one for both dimensions) loaded for a 2-map checks to the same
/// embeddings and rules (labels, programs, guards) as the 2D file shipped before the merge:
/// the two files differ only by label 3, which a 2-map drops. Loaded for a 3-map it is the
/// same file read as `dimension 3`.
#[test]
fn the_stretch_file_read_on_a_2_map_is_the_2d_file() {
    let both = STRETCH.to_string();
    let stretch3d = stretch3d();
    assert_ne!(both, stretch3d);
    let (as2, _) = load_sources_for(2, &srcs(COMMON2D, &both)).unwrap();
    let (want2, _) = load_sources(&srcs(COMMON2D, STRETCH2D)).unwrap();
    assert_eq!(as2.dimension(), 2);
    assert_eq!(as2.embeddings(), want2.embeddings());
    assert_eq!(unplaced(&as2), unplaced(&want2));
    // and for a 3-map it is the 3D file
    let (as3, _) = load_sources_for(3, &srcs(COMMON3D, &both)).unwrap();
    let (want3, _) = load_sources(&srcs(COMMON3D, &stretch3d)).unwrap();
    assert_eq!(as3.embeddings(), want3.embeddings());
    assert_eq!(unplaced(&as3), unplaced(&want3));
    // its models serve both dimensions
    let m = as2.model("stretch_elementary").unwrap();
    assert_eq!(m.dimensions, vec![2, 3]);
}

const V: &str = "embedding w : f64 on <1,2,3>\n";

#[test]
fn label_3_reads_as_free_on_a_2_map() {
    let src = format!(
        "dimension 2 3\n{V}rule r {{\n  left {{ a : <1,2,3> hook  a -0- b  b : <1,2,3> }}\n  compute {{ a.w = sum<1,2,3>(b.w) }}\n}}\nrule s {{\n  left {{ a : <1,2> hook  a -3- a }}\n  compute {{ }}\n}}\n"
    );
    let (r, _) = load_sources_for(2, &[("x.tmr".into(), src.clone())]).unwrap();
    assert_eq!(r.embeddings()[0].orbit.to_string(), "<1,2>");
    let rule = r.rule("r").unwrap();
    assert_eq!(rule.arity, 2);
    assert_eq!(rule.hook_orbit, vec![1, 2]);
    // the loop -3- (free darts at 3) always holds on a 2-map: dropped
    assert!(r.rule("s").unwrap().left_arcs.is_empty());
    let (r3, _) = load_sources_for(3, &[("x.tmr".into(), src)]).unwrap();
    assert_eq!(r3.rule("r").unwrap().arity, 3);
    assert_eq!(r3.rule("s").unwrap().left_arcs.len(), 1);
    assert_eq!(r3.embeddings()[0].orbit.to_string(), "<1,2,3>");
}

#[test]
fn what_a_2_map_cannot_read_is_refused_where_it_is() {
    // an arc -3- between two nodes can never match on a 2-map
    let src = "dimension 2 3\nrule cut {\n  left { a : <0,1> hook  b : <0,1>  a -3- b }\n  right { a : <0,1>  b : <0,1> }\n}\n";
    let d = load_sources_for(2, &[("c.tmr".into(), src.into())]).unwrap_err();
    assert_eq!(d[0].condition, "dimension");
    assert_eq!((d[0].pos.line, d[0].pos.col), (3, 37));
    assert!(d[0].message.contains("arc a -3- b"), "{}", d[0]);
    assert!(
        d[0].message.contains("can never hold on a 2-map"),
        "{}",
        d[0]
    );
    assert!(load_sources_for(3, &[("c.tmr".into(), src.into())]).is_ok());
    // a label 3 relabelled from another label
    let src = "dimension 2 3\nrule r {\n  left { a : <1,2> hook }\n  right { a : <1,3> }\n}\n";
    let d = load_sources_for(2, &[("r.tmr".into(), src.into())]).unwrap_err();
    assert_eq!(d[0].condition, "dimension");
    assert_eq!(d[0].pos.line, 4);
    assert!(
        d[0].message
            .contains("has label 3 where the hook has another label"),
        "{}",
        d[0]
    );
}

#[test]
fn a_file_serves_only_its_dimensions() {
    // `dimension 3` alone still refuses a 2-map, naming the file's line
    let d = load_sources_for(2, &srcs(COMMON3D, &stretch3d())).unwrap_err();
    assert!(d.iter().all(|x| x.condition == "dimension"));
    assert!(
        d[0].message.contains("serves dimension 3, not dimension 2"),
        "{}",
        d[0]
    );
    let lines: Vec<(&str, u32)> = d.iter().map(|x| (x.file.as_str(), x.pos.line)).collect();
    assert_eq!(lines, vec![("common.tmr", 4), ("stretch.tmr", 7)]);
    // a file without a dimension line serves both when loaded for one
    let bare = format!("{V}rule r {{ left {{ a : <1,2,3> hook }} compute {{ a.w = 1.0 }} }}\n");
    for dim in [2, 3] {
        let (r, _) = load_sources_for(dim, &[("b.tmr".into(), bare.clone())]).unwrap();
        assert_eq!(r.dimension(), dim);
    }
    // without a dimension to load for, a set that fixes none is refused clearly ...
    let both = format!("dimension 2 3\n{bare}");
    // (its message says what the file says and what to do, naming no API function)
    let d = load_sources(&[("b.tmr".into(), both.clone())]).unwrap_err();
    assert_eq!(d[0].condition, "dimension");
    assert_eq!(
        d[0].message,
        format!(
            "the file says 'dimension 2 3', so it serves 2-maps and 3-maps, and nothing fixes \
             the dimension: {LOAD_FOR_A_DIMENSION}"
        )
    );
    let d = load_sources(&[
        ("b.tmr".into(), bare.clone()),
        ("c.tmr".into(), both.clone()),
    ])
    .unwrap_err();
    assert_eq!(d.len(), 2);
    assert_eq!(
        d[0].message,
        format!(
            "the file has no 'dimension' line, so it serves 2-maps and 3-maps, and no other \
             file fixes the dimension: {LOAD_FOR_A_DIMENSION}"
        )
    );
    assert!(
        d.iter().all(|x| !x.message.contains("load_sources")),
        "{d:?}"
    );
    // files on disk are loaded for a dimension the same way
    let dir = std::env::temp_dir().join(format!("topomech-both-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("both.tmr");
    std::fs::write(&path, &both).unwrap();
    assert!(load_files(&[path.as_path()]).is_err());
    for dim in [2, 3] {
        let (r, _) = load_files_for(dim, &[path.as_path()]).unwrap();
        assert_eq!(r.dimension(), dim);
    }
    let missing = dir.join("missing.tmr");
    let d = load_files_for(2, &[missing.as_path()]).unwrap_err();
    assert_eq!(d[0].condition, "file");
    std::fs::remove_dir_all(&dir).unwrap();
    // ... and one file of a single dimension fixes it for the others
    let (r, _) = load_sources(&[
        ("a.tmr".into(), "dimension 2\n".into()),
        ("b.tmr".into(), both),
    ])
    .unwrap();
    assert_eq!(r.dimension(), 2);
    assert_eq!(r.embeddings()[0].orbit.to_string(), "<1,2>");
    // a dimension twice on the line is a syntax error
    let d = load_sources(&[("d.tmr".into(), "dimension 2 2\n".into())]).unwrap_err();
    assert_eq!(d[0].condition, "syntax");
    assert!(
        d[0].message.contains("dimension 2 is written twice"),
        "{}",
        d[0]
    );
}
