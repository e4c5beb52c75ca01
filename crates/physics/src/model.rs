//! The models topomech ships: each a rule file and the rules a step applies from it.

use crate::PhysicsError;

/// A physical model: its rule file and rules.
#[derive(Clone, Copy, Debug)]
pub struct ModelDef {
    /// The scene's name for it.
    pub kind: &'static str,
    /// Dimensions it exists in.
    pub dims: &'static [usize],
    /// Base name of its rule file in `models/` (`{file}{dim}d.tmr`).
    pub file: &'static str,
    /// Init rules, applied once, in order; a rule's parameters come from the model's
    /// parameters of the same name.
    pub init: &'static [&'static str],
    /// Interaction rules, applied every step, in order.
    pub rules: &'static [&'static str],
    /// The force embeddings the accumulation sums.
    pub forces: &'static [&'static str],
    /// Rules computing the Jacobian-vector product `df = (df/dx) dx + (df/dv) dv`.
    pub jvp_rules: &'static [&'static str],
    /// The embeddings they write, summed per vertex into `df`.
    pub jvp_forces: &'static [&'static str],
    /// Parameters with their defaults.
    pub params: &'static [(&'static str, f64)],
    /// What the model needs of the mesh, said when it matches nothing.
    pub needs: &'static str,
    /// Whether every element must be matched by one of the init rules (the element models:
    /// an element they cannot handle would silently get no force).
    pub per_element: bool,
}

/// Every model topomech ships.
pub const MODELS: &[ModelDef] = &[
    ModelDef {
        kind: "stretch_elementary",
        dims: &[2, 3],
        file: "stretch",
        init: &["stretch_init"],
        rules: &["stretch_elementary"],
        forces: &["f_stretch"],
        jvp_rules: &["stretch_elementary_jvp"],
        jvp_forces: &["df_stretch"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "edges",
        per_element: false,
    },
    ModelDef {
        kind: "stretch_cumulated",
        dims: &[2, 3],
        file: "stretch",
        init: &["stretch_init"],
        rules: &["stretch_cumulated"],
        forces: &["f_stretch_cum"],
        jvp_rules: &["stretch_cumulated_jvp"],
        jvp_forces: &["df_stretch_cum"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "edges",
        per_element: false,
    },
    ModelDef {
        kind: "shear_isotropic",
        dims: &[2, 3],
        file: "shear",
        init: &["shear_isotropic_init"],
        rules: &["shear_isotropic"],
        forces: &["f_shear_iso"],
        jvp_rules: &["shear_isotropic_jvp"],
        jvp_forces: &["df_shear_iso"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "quadrilateral faces",
        per_element: false,
    },
    ModelDef {
        kind: "shear_anisotropic",
        dims: &[2, 3],
        file: "shear",
        init: &["shear_anisotropic_init"],
        rules: &["shear_anisotropic"],
        forces: &["f_shear_aniso"],
        jvp_rules: &["shear_anisotropic_jvp"],
        jvp_forces: &["df_shear_aniso"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "faces",
        per_element: false,
    },
    ModelDef {
        kind: "shear_volumic",
        dims: &[3],
        file: "shear",
        init: &["shear_volumic_init"],
        rules: &["shear_volumic"],
        forces: &["f_shear_vol"],
        jvp_rules: &["shear_volumic_jvp"],
        jvp_forces: &["df_shear_vol"],
        params: &[("stiffness", 1000.0), ("damping", 0.0)],
        needs: "hexahedra",
        per_element: false,
    },
    ModelDef {
        kind: "bending_linear",
        dims: &[2],
        file: "bending",
        init: &["bending_linear_init"],
        rules: &["bending_linear"],
        forces: &["f_bend_lin_a", "f_bend_lin_e"],
        jvp_rules: &["bending_linear_jvp"],
        jvp_forces: &["df_bend_lin_a", "df_bend_lin_e"],
        params: &[("stiffness", 100.0), ("damping", 0.0)],
        needs: "edges continuing each other across faces",
        per_element: false,
    },
    ModelDef {
        kind: "bending_angular",
        dims: &[2],
        file: "bending",
        init: &["bending_angular_init", "face_rest_centroids"],
        rules: &["face_centroids", "bending_angular"],
        forces: &["f_bend", "f_bend_wing"],
        jvp_rules: &[],
        jvp_forces: &[],
        params: &[("stiffness", 1.0), ("damping", 0.0)],
        needs: "interior edges between two triangles or quads",
        per_element: false,
    },
    ModelDef {
        kind: "linear_fem",
        dims: &[3],
        file: "fem",
        init: &["fem_init"],
        rules: &["linear_fem"],
        forces: &["f_linear"],
        jvp_rules: &["linear_fem_jvp"],
        jvp_forces: &["df_linear"],
        params: &[],
        needs: "tetrahedra",
        per_element: true,
    },
    ModelDef {
        kind: "corotational",
        dims: &[3],
        file: "fem",
        init: &["fem_init", "corotational_hex_init"],
        rules: &["corotational", "corotational_hex"],
        forces: &["f_corot", "f_corot_hex"],
        jvp_rules: &["corotational_jvp", "corotational_hex_jvp"],
        jvp_forces: &["df_corot", "df_corot_hex"],
        params: &[],
        needs: "tetrahedra or hexahedra",
        per_element: true,
    },
    ModelDef {
        kind: "corotational",
        dims: &[2],
        file: "fem",
        init: &["corotational_tri_init"],
        rules: &["corotational_tri"],
        forces: &["f_corot_tri"],
        jvp_rules: &["corotational_tri_jvp"],
        jvp_forces: &["df_corot_tri"],
        params: &[("thickness", 1.0)],
        needs: "triangles",
        per_element: true,
    },
    ModelDef {
        kind: "mass_tensor",
        dims: &[3],
        file: "fem",
        init: &["mass_tensor_init"],
        rules: &["mass_tensor_edges", "mass_tensor_vertices"],
        forces: &["f_tensor"],
        jvp_rules: &["mass_tensor_edges_jvp", "mass_tensor_vertices_jvp"],
        jvp_forces: &["df_tensor"],
        params: &[],
        needs: "tetrahedra",
        per_element: true,
    },
    ModelDef {
        kind: "neohookean",
        dims: &[3],
        file: "hyperelastic",
        init: &["neohookean_init"],
        rules: &["neohookean"],
        forces: &["f_neohookean"],
        jvp_rules: &["neohookean_jvp"],
        jvp_forces: &["df_neohookean"],
        params: &[],
        needs: "tetrahedra",
        per_element: true,
    },
    ModelDef {
        kind: "stvk",
        dims: &[3],
        file: "hyperelastic",
        init: &["stvk_init"],
        rules: &["stvk"],
        forces: &["f_stvk"],
        jvp_rules: &["stvk_jvp"],
        jvp_forces: &["df_stvk"],
        params: &[],
        needs: "tetrahedra",
        per_element: true,
    },
];

pub(crate) fn model_source(file: &str, dim: usize) -> Option<&'static str> {
    Some(match (file, dim) {
        ("common", 2) => include_str!("../models/common2d.tmr"),
        ("common", 3) => include_str!("../models/common3d.tmr"),
        ("stretch", 2) => include_str!("../models/stretch2d.tmr"),
        ("stretch", 3) => include_str!("../models/stretch3d.tmr"),
        ("fem", 3) => include_str!("../models/fem3d.tmr"),
        ("shear", 2) => include_str!("../models/shear2d.tmr"),
        ("shear", 3) => include_str!("../models/shear3d.tmr"),
        ("bending", 2) => include_str!("../models/bending2d.tmr"),
        ("fem", 2) => include_str!("../models/fem2d.tmr"),
        ("topology", 2) => include_str!("../models/topology2d.tmr"),
        ("topology", 3) => include_str!("../models/topology3d.tmr"),
        ("hyperelastic", 3) => include_str!("../models/hyperelastic3d.tmr"),
        _ => return None,
    })
}

pub(crate) fn find_model(kind: &str, dim: usize) -> Result<ModelDef, PhysicsError> {
    if let Some(def) = MODELS
        .iter()
        .find(|m| m.kind == kind && m.dims.contains(&dim))
    {
        return Ok(*def);
    }
    let Some(def) = MODELS.iter().find(|m| m.kind == kind) else {
        let mut known: Vec<&str> = MODELS.iter().map(|m| m.kind).collect();
        known.dedup();
        return Err(PhysicsError::Model(format!(
            "unknown model '{kind}' (known: {})",
            known.join(", ")
        )));
    };
    if !def.dims.contains(&dim) {
        return Err(PhysicsError::Model(format!(
            "model '{kind}' needs a mesh of dimension {:?}, this one has dimension {dim}",
            def.dims
        )));
    }
    Ok(*def)
}
