//! The README's reference of built-ins lists every built-in function the language has.

#[test]
fn readme_lists_every_builtin() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../README.md")).unwrap();
    for (name, _, _) in topomech_rules::builtins::full_catalogue() {
        assert!(
            readme.contains(&format!("| `{name}` |")),
            "README misses built-in '{name}'"
        );
    }
}
