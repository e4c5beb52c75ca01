//! Models: the `model` declarations of rule files (shipped in `models/`, or the user's own
//! files given in [`Config::model_files`]), and what a simulation runs of them.
//!
//! A model is found by name: first in the user's files, then in the shipped files of the
//! map's dimension. Its file is loaded with the shipped prelude (`prelude.tmr`, both
//! dimensions) and the common rules of that dimension (the embeddings every simulation has: `position`, `rest`, `velocity`, `force`, `mass`, `dx`,
//! `dv`, `df`, the material, ...), so a user's file declares only its own embeddings. The
//! declaration's `init` calls run once at set-up, its `step` calls every step, its `forces`
//! are summed into `force`, its `jvp` calls and outputs make the Jacobian-vector product.

use std::collections::HashMap;
use std::sync::OnceLock;

use topomech_rules::model::{Model, ModelParam};
use topomech_rules::{load_sources_for, Params, Val};

use crate::{Config, PhysicsError};

/// The shipped model files: `(file name, dimensions, text)`, in the order models are listed.
/// A file serving both dimensions (`dimension 2 3`) is one entry.
const SHIPPED: &[(&str, &[usize], &str)] = &[
    (
        "stretch.tmr",
        &[2, 3],
        include_str!("../models/stretch.tmr"),
    ),
    ("shear.tmr", &[2, 3], include_str!("../models/shear.tmr")),
    ("shear3d.tmr", &[3], include_str!("../models/shear3d.tmr")),
    (
        "bending2d.tmr",
        &[2],
        include_str!("../models/bending2d.tmr"),
    ),
    ("fem3d.tmr", &[3], include_str!("../models/fem3d.tmr")),
    ("fem2d.tmr", &[2], include_str!("../models/fem2d.tmr")),
    (
        "hyperelastic3d.tmr",
        &[3],
        include_str!("../models/hyperelastic3d.tmr"),
    ),
];

/// A shipped rule file that is not a model file (or is loaded for more than its models), for
/// dimension `dim`; `("topology", 0)` is the topology file both dimensions share.
pub(crate) fn model_source(file: &str, dim: usize) -> Option<&'static str> {
    Some(match (file, dim) {
        ("topology", 0) => include_str!("../models/topology.tmr"),
        ("prelude", 2 | 3) => include_str!("../models/prelude.tmr"),
        ("common", 2) => include_str!("../models/common2d.tmr"),
        ("common", 3) => include_str!("../models/common3d.tmr"),
        ("topology", 2) => include_str!("../models/topology2d.tmr"),
        ("topology", 3) => include_str!("../models/topology3d.tmr"),
        ("fem", 3) => include_str!("../models/fem3d.tmr"),
        _ => return None,
    })
}

/// The model names each shipped file declares (parsed once).
fn shipped_names() -> &'static [Vec<String>] {
    static NAMES: OnceLock<Vec<Vec<String>>> = OnceLock::new();
    NAMES.get_or_init(|| {
        SHIPPED
            .iter()
            .map(|(_, _, text)| declared_names(text))
            .collect()
    })
}

/// The names of the models a rule text declares (none when it does not parse: the loader
/// reports why).
fn declared_names(text: &str) -> Vec<String> {
    topomech_rules::parser::parse(text)
        .map(|f| f.models.into_iter().map(|m| m.name).collect())
        .unwrap_or_default()
}

/// A model topomech ships, as its declaration says.
#[derive(Clone, Debug, PartialEq)]
pub struct ShippedModel {
    /// Its name (a scene's `kind`).
    pub name: String,
    /// The dimensions of maps it runs on.
    pub dimensions: Vec<usize>,
    /// Its parameters, with their types and defaults.
    pub params: Vec<ModelParam>,
    /// What it needs of the mesh.
    pub needs: Option<String>,
    /// Whether it has Jacobian rules (implicit Euler and static runs need them).
    pub has_jvp: bool,
    /// Whether it is declared `per_element` (a continuous model: its elements take the
    /// material's `young` and `poisson`).
    pub per_element: bool,
}

/// Every model topomech ships, read from the declarations of its rule files. One name may
/// appear twice when its declarations differ between dimensions (the 2D co-rotational
/// triangle has a `thickness`, the 3D elements have none); declarations that agree are one
/// entry with both dimensions.
///
/// # Panics
/// Never on the shipped files (a test loads each of them); a shipped file that failed to
/// check would be left out.
pub fn shipped_models() -> Vec<ShippedModel> {
    static ALL: OnceLock<Vec<ShippedModel>> = OnceLock::new();
    ALL.get_or_init(|| {
        let mut out: Vec<ShippedModel> = Vec::new();
        for (file, dims, text) in SHIPPED {
            for dim in *dims {
                let common = model_source("common", *dim).expect("shipped");
                let prelude = model_source("prelude", *dim).expect("shipped");
                let Ok((rules, _)) = load_sources_for(
                    *dim,
                    &[
                        ("prelude.tmr".to_string(), prelude.to_string()),
                        (format!("common{dim}d.tmr"), common.to_string()),
                        ((*file).to_string(), (*text).to_string()),
                    ],
                ) else {
                    continue;
                };
                for m in rules.models() {
                    let needs = m.needs.clone();
                    if let Some(e) = out
                        .iter_mut()
                        .find(|e| e.name == m.name && e.params == m.params && e.needs == needs)
                    {
                        if !e.dimensions.contains(dim) {
                            e.dimensions.push(*dim);
                            e.dimensions.sort_unstable();
                        }
                        continue;
                    }
                    out.push(ShippedModel {
                        name: m.name.clone(),
                        dimensions: m.dimensions.clone(),
                        params: m.params.clone(),
                        needs,
                        has_jvp: !m.jvp.is_empty(),
                        per_element: m.per_element,
                    });
                }
            }
        }
        out
    })
    .clone()
}

/// Why a model's parameters cannot hold the material's `key` (`young`, `poisson` or
/// `density`), and where it is set instead: on the simulation (Python's keyword, Rust's
/// [`Config`] field, per region too); in a scene `[material]`, or for `young` and
/// `poisson` the `[[model]]` table of a continuous model (the scene moves them to its
/// material). A model that is not continuous (not `per_element`: springs, bending) reads
/// neither `young` nor `poisson`: the message says so rather than where to put them.
fn material_key_in_model(m: &Model, key: &str, has: &str) -> String {
    let name = &m.name;
    if key != "density" && !m.per_element {
        return format!(
            "model '{name}' has no parameter '{key}' (it has: {has}): '{key}' is the material's, read by the continuous models (declared per_element: corotational, linear_fem, ...) only; this model does not use it (its stiffness is among its own parameters)"
        );
    }
    let scene = if key == "density" {
        format!("[material] {key} = ...")
    } else {
        format!("[material] {key} = ..., or {key} = ... in the model's [[model]] table, which sets the material's")
    };
    format!(
        "model '{name}' has no parameter '{key}' (it has: {has}): '{key}' is the material's, one for every model that uses it, so it is set on the simulation, not in a model's parameters (Python: Simulation(..., {key}=...), or regions=[{{\"where\": ..., \"{key}\": ...}}] for some elements; Rust: Config::{key}; a scene: {scene})"
    )
}

/// A model as a simulation runs it: its rule calls with their parameters bound.
#[derive(Clone, Debug)]
pub(crate) struct RunModel {
    /// Its name.
    pub name: String,
    /// Init rules and their parameters, in order.
    pub init: Vec<(String, Params)>,
    /// Step rules and their parameters, in order.
    pub step: Vec<(String, Params)>,
    /// Jacobian-vector product rules and their parameters, in order.
    pub jvp: Vec<(String, Params)>,
    /// What it needs of the mesh.
    pub needs: String,
    /// Whether every element must be matched by an init rule.
    pub per_element: bool,
}

impl RunModel {
    /// Binds a checked declaration to the scene's parameter values (`given`, over the
    /// declaration's defaults).
    pub(crate) fn bind(m: &Model, given: &HashMap<String, Val>) -> Result<Self, PhysicsError> {
        // in name order, so that the parameter named is the same from run to run
        let mut names: Vec<&String> = given.keys().collect();
        names.sort();
        for k in names {
            if !m.params.iter().any(|p| &p.name == k) {
                let known: Vec<&str> = m.params.iter().map(|p| p.name.as_str()).collect();
                if ["young", "poisson", "density"].contains(&k.as_str()) {
                    let has = if known.is_empty() {
                        "none".to_string()
                    } else {
                        known.join(", ")
                    };
                    return Err(PhysicsError::Config(material_key_in_model(m, k, &has)));
                }
                return Err(PhysicsError::Config(format!(
                    "model '{}' has no parameter '{k}' (it has: {})",
                    m.name,
                    if known.is_empty() {
                        "none; it uses the material's young and poisson".into()
                    } else {
                        known.join(", ")
                    }
                )));
            }
        }
        for (k, v) in given {
            let bad = match v {
                Val::F(x) if !x.is_finite() => Some(format!("{x}")),
                Val::V3(x) if !x.iter().all(|c| c.is_finite()) => {
                    Some(format!("[{}, {}, {}]", x[0], x[1], x[2]))
                }
                _ => None,
            };
            if let Some(bad) = bad {
                return Err(PhysicsError::Config(format!(
                    "model '{}': parameter '{k}' must be finite, got {bad}",
                    m.name
                )));
            }
        }
        let values = m.values(given).map_err(PhysicsError::Config)?;
        let bind = |calls: &[topomech_rules::model::Call]| -> Vec<(String, Params)> {
            calls
                .iter()
                .map(|c| (c.rule.clone(), c.params(&values)))
                .collect()
        };
        Ok(RunModel {
            name: m.name.clone(),
            init: bind(&m.init),
            step: bind(&m.step),
            jvp: bind(&m.jvp),
            needs: m
                .needs
                .clone()
                .unwrap_or_else(|| "what its init rules match".into()),
            per_element: m.per_element,
        })
    }
}

/// The rule files the models of `cfg` need on a map of dimension `dim`, in the order they
/// are loaded after the common files: the shipped file declaring each shipped model (once),
/// then the user's files. Errors: a model no file declares (listing the known ones), or one
/// declared only for other dimensions.
pub(crate) fn model_files(cfg: &Config, dim: usize) -> Result<Vec<(String, String)>, PhysicsError> {
    let user: Vec<Vec<String>> = cfg
        .model_files
        .iter()
        .map(|(_, text)| declared_names(text))
        .collect();
    let names = shipped_names();
    let mut out: Vec<(String, String)> = Vec::new();
    for spec in &cfg.models {
        let kind = spec.kind.as_str();
        if user.iter().any(|n| n.iter().any(|x| x == kind)) {
            continue;
        }
        let found = SHIPPED
            .iter()
            .zip(names)
            .find(|((_, d, _), n)| d.contains(&dim) && n.iter().any(|x| x == kind));
        if let Some(((file, _, text), _)) = found {
            if !out.iter().any(|s| s.0 == *file) {
                out.push(((*file).to_string(), (*text).to_string()));
            }
            continue;
        }
        let mut dims: Vec<usize> = SHIPPED
            .iter()
            .zip(names)
            .filter(|(_, n)| n.iter().any(|x| x == kind))
            .flat_map(|((_, d, _), _)| d.iter().copied())
            .collect();
        dims.sort_unstable();
        dims.dedup();
        if dims.is_empty() {
            // a user's file that does not parse declares nothing: its error, not "unknown"
            for (file, text) in &cfg.model_files {
                if let Err(e) = topomech_rules::parser::parse(text) {
                    return Err(PhysicsError::Model(format!(
                        "{file}:{}:{}: error[syntax]: {} (model '{kind}' is declared in no file that parses)",
                        e.pos.line, e.pos.col, e.message
                    )));
                }
            }
            let mut known: Vec<&str> = Vec::new();
            for n in names.iter().chain(&user).flatten() {
                if !known.contains(&n.as_str()) {
                    known.push(n);
                }
            }
            return Err(PhysicsError::Model(format!(
                "unknown model '{kind}' (known: {})",
                known.join(", ")
            )));
        }
        return Err(PhysicsError::Model(format!(
            "model '{kind}' needs a mesh of dimension {}, this one has dimension {dim}",
            dims_text(&dims)
        )));
    }
    out.extend(cfg.model_files.iter().cloned());
    Ok(out)
}

/// The forces and jvp outputs of model `kind` as declared (unchecked) in `sources`; empty when
/// no source declares it (the checker then says why).
pub(crate) fn declared_outputs(
    sources: &[(String, String)],
    kind: &str,
) -> (Vec<String>, Vec<String>) {
    for (_, text) in sources {
        if let Ok(f) = topomech_rules::parser::parse(text) {
            if let Some(m) = f.models.into_iter().find(|m| m.name == kind) {
                return (
                    m.forces.into_iter().map(|x| x.0).collect(),
                    m.jvp_outputs.into_iter().map(|x| x.0).collect(),
                );
            }
        }
    }
    (Vec::new(), Vec::new())
}

/// Dimensions as a message says them: `3`, `2 or 3`.
pub(crate) fn dims_text(dims: &[usize]) -> String {
    dims.iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(" or ")
}
