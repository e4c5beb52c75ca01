//! The co-rotational rule file as a user would copy it into a file of their own: every rule
//! and embedding of the model renamed. Shared by `tests/compiled.rs` and the engine bench.
#![allow(dead_code, missing_docs)]

use topomech_rules::check::check_sources;
use topomech_rules::RuleSet;

/// The shipped prelude (both dimensions).
pub const PRELUDE: &str = include_str!("../../../models/prelude.tmr");
/// The shipped 3D common rules.
pub const COMMON3D: &str = include_str!("../../../models/common3d.tmr");
/// The shipped 3D FEM rules.
pub const FEM3D: &str = include_str!("../../../models/fem3d.tmr");

/// `fem3d.tmr` renamed: the rule `corotational` is `my_warped_tets`, its force `my_force`, its
/// stiffness `my_stiffness`, its shape matrix `my_shape`, its rest vector `my_rest_vector`, its
/// initialisation `my_init`.
pub fn renamed_fem3d() -> String {
    FEM3D
        .replace("corotational", "my_warped_tets")
        .replace("f_corot", "my_force")
        .replace("k_elem", "my_stiffness")
        .replace("dm_inv", "my_shape")
        .replace("x_rest", "my_rest_vector")
        .replace("fem_init", "my_init")
}

/// The rule set of the shipped prelude, the 3D common rules and the FEM rules `text`, read as
/// file `file`.
pub fn load_with_common3d(text: &str, file: &str) -> RuleSet {
    let (checked, diags) = check_sources(&[
        ("prelude.tmr".to_string(), PRELUDE.to_string()),
        ("common3d.tmr".to_string(), COMMON3D.to_string()),
        (file.to_string(), text.to_string()),
    ]);
    RuleSet::new(checked.unwrap_or_else(|| panic!("{file} checks: {diags:?}")))
}
