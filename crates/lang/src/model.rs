//! Model declarations: a physical model as its rule file says it is run.
//!
//! ```text
//! model anchor(k: f64 = 10.0) {
//!   init   anchor_init(k)               # rules applied once, everywhere, in this order
//!   step   anchor_force                 # rules applied every step, everywhere, in this order
//!   forces f_anchor                     # force embeddings summed into each vertex's `force`
//!   jvp    anchor_jvp(k) -> df_anchor   # optional: Jacobian-vector product rules, outputs
//!   needs  "vertices"                   # optional: said when the model matches nothing
//!   per_element                         # optional: every element matched by an init rule
//!                                       # on elements (hook <0,1,2>, <0,1> in 2D, or <>)
//! }
//! ```
//!
//! A parameter is `name: f64` or `name: vec3`, with a default (`= 1.5`, `= vec3(0, 0, -1)`)
//! or without one (then it is required). A rule call's arguments are model parameters,
//! numbers or `vec3(x, y, z)` literals, one per parameter of the rule, in the rule's order;
//! a rule without parameters is called by its bare name.
//!
//! The checker refuses, with the usual conditions:
//! - `name`: a model declared twice (across the files loaded together), a parameter twice,
//!   a call to an unknown rule, an argument naming no parameter of the model, a force or jvp
//!   output that is not a declared embedding;
//! - `arity`: a call with a number of arguments other than the rule's parameters; a `jvp`
//!   whose outputs are not as many as the forces (output k is the derivative of force k);
//! - `type`: a parameter type other than `f64`/`vec3`, a default or argument of the wrong
//!   type, a force or jvp output that is not a `vec3` embedding on a sub-orbit of the vertex
//!   orbit (labels within {1, 2, 3});
//! - `syntax`: a model without `init`, `step` or `forces`;
//! - `model-rule`: a call to a rule that changes the topology or writes an embedding of the
//!   simulation's own ([`SIMULATION_STATE`]), such an embedding listed as a force or jvp
//!   output;
//! - a force or jvp output listed twice (`name`);
//! - `unused-parameter`: a required parameter no rule call passes on (a warning for one
//!   with a default).

use std::collections::HashMap;

/// The embeddings a simulation owns (declared by its prelude or by the import): the state it
/// integrates, the loads and supports it sets, the rest shape, the sum of the models' forces,
/// the vectors of its linear solves, and the mesh's numbering (`particle`, `point_id`,
/// `cell_id`: the user's rows and input points and cells, which every output is written in)
/// with the element markers it sets up (`vertex0`, `face0`), and the material and masses its
/// common rules set from the configuration (`density`, `young`, `poisson`, `corner_mass`,
/// which the vertex `mass` sums). A model's rules must not write them (a model that wrote
/// `fixed` or `position` would undo the supports, one that wrote `force` would be summed
/// over, one that wrote `point_id` would renumber the output, one that wrote `corner_mass`
/// in a step made the total mass -192 and ran on: QA), and a model cannot list them as
/// forces or jvp outputs (`model-rule`).
pub const SIMULATION_STATE: &[&str] = &[
    "position",
    "rest",
    "velocity",
    "force",
    "fixed",
    "f_ext",
    "dx",
    "dv",
    "df",
    "particle",
    "point_id",
    "cell_id",
    "vertex0",
    "face0",
    "density",
    "young",
    "poisson",
    "corner_mass",
];

use crate::ast::{self, ModelArgKind, Pos};
use crate::check::{Diagnostic, EmbDecl, Rule, Severity};
use crate::value::{Ty, Val};

/// A checked argument of a rule call.
#[derive(Clone, Debug, PartialEq)]
pub enum Arg {
    /// The model parameter of this name.
    Param(String),
    /// A constant.
    Const(Val),
}

/// A checked rule call: the rule and one argument per rule parameter, in its order.
#[derive(Clone, Debug, PartialEq)]
pub struct Call {
    /// The rule.
    pub rule: String,
    /// `(rule parameter name, argument)`, in the rule's parameter order.
    pub args: Vec<(String, Arg)>,
}

/// A checked model parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelParam {
    /// Its name.
    pub name: String,
    /// Its type (`F64` or `Vec3`).
    pub ty: Ty,
    /// Its default; `None` when it is required.
    pub default: Option<Val>,
}

/// A checked model declaration.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// Its name.
    pub name: String,
    /// Its parameters, in declaration order.
    pub params: Vec<ModelParam>,
    /// Rules applied once at set-up, everywhere, in order.
    pub init: Vec<Call>,
    /// Rules applied every step, everywhere, in order.
    pub step: Vec<Call>,
    /// Force embeddings (vec3 on sub-orbits of the vertex) summed into `force`.
    pub forces: Vec<String>,
    /// Rules computing the Jacobian-vector product `(df/dx) dx + (df/dv) dv` (empty: the
    /// model has none, and runs with explicit integrators only).
    pub jvp: Vec<Call>,
    /// The embeddings the jvp rules write, summed into `df`.
    pub jvp_outputs: Vec<String>,
    /// What the model needs of the mesh (said when it matches nothing).
    pub needs: Option<String>,
    /// Whether every element must be matched by one of the init rules.
    pub per_element: bool,
    /// The dimensions of maps it runs on.
    pub dimensions: Vec<usize>,
    /// The file that declares it.
    pub file: String,
    /// Where it is declared.
    pub pos: Pos,
}

impl Model {
    /// The model's parameter values: the defaults, overridden by `given`. Errors name the
    /// model and the parameter: an unknown parameter (listing the model's), a required one
    /// missing, a value of the wrong type.
    pub fn values(&self, given: &HashMap<String, Val>) -> Result<HashMap<String, Val>, String> {
        let mut out = HashMap::new();
        for (k, v) in given {
            let Some(p) = self.params.iter().find(|p| &p.name == k) else {
                let known: Vec<&str> = self.params.iter().map(|p| p.name.as_str()).collect();
                return Err(format!(
                    "model '{}' has no parameter '{k}' (it has: {})",
                    self.name,
                    if known.is_empty() {
                        "none".to_string()
                    } else {
                        known.join(", ")
                    }
                ));
            };
            if v.ty() != p.ty {
                return Err(format!(
                    "model '{}': parameter '{k}' is a {}, got a {}",
                    self.name,
                    p.ty,
                    v.ty()
                ));
            }
            out.insert(k.clone(), v.clone());
        }
        for p in &self.params {
            if out.contains_key(&p.name) {
                continue;
            }
            match &p.default {
                Some(d) => {
                    out.insert(p.name.clone(), d.clone());
                }
                None => {
                    return Err(format!(
                        "model '{}': parameter '{}' is required (it has no default)",
                        self.name, p.name
                    ))
                }
            }
        }
        Ok(out)
    }
}

impl Call {
    /// The rule's parameters for this call, given the model's parameter values (from
    /// [`Model::values`], which has every parameter).
    pub fn params(&self, values: &HashMap<String, Val>) -> HashMap<String, Val> {
        self.args
            .iter()
            .map(|(name, a)| {
                let v = match a {
                    Arg::Const(v) => v.clone(),
                    Arg::Param(p) => values.get(p).cloned().unwrap_or(Val::F(0.0)),
                };
                (name.clone(), v)
            })
            .collect()
    }
}

/// The names of the embeddings `rule`'s program writes, in program order.
pub fn written_by<'a>(rule: &'a Rule, embs: &'a [EmbDecl]) -> impl Iterator<Item = &'a str> {
    rule.program.iter().filter_map(move |st| match st {
        crate::check::TStmt::Write { emb, .. } => embs.get(*emb).map(|e| e.name.as_str()),
        crate::check::TStmt::Let(..) => None,
    })
}

fn error(out: &mut Vec<Diagnostic>, file: &str, pos: Pos, condition: &'static str, m: String) {
    out.push(Diagnostic {
        file: file.to_string(),
        pos,
        severity: Severity::Error,
        condition,
        message: m,
    });
}

fn constant(a: &ast::ModelArg) -> Option<Val> {
    match &a.kind {
        ModelArgKind::Number(x) => Some(Val::F(*x)),
        ModelArgKind::Vec3(v) => Some(Val::V3(*v)),
        ModelArgKind::Param(_) => None,
    }
}

/// Checks the model declarations of `files` (parsed, with their names) against the checked
/// rules and embeddings; `dims[k]` are the dimensions file `k` serves. Diagnostics go to `out`.
pub(crate) fn check_models(
    files: &[(String, ast::File)],
    dims: &[Vec<usize>],
    embs: &[EmbDecl],
    rules: &[Rule],
    out: &mut Vec<Diagnostic>,
) -> Vec<Model> {
    let mut models: Vec<Model> = Vec::new();
    let mut seen: HashMap<String, (String, Pos)> = HashMap::new();
    // every rule written, checked or refused: a call to one the checker refused is not a
    // call to an undefined rule
    let written: Vec<&str> = files
        .iter()
        .flat_map(|(_, f)| f.rules.iter().map(|r| r.name.as_str()))
        .collect();
    for ((file, f), fdims) in files.iter().zip(dims) {
        for m in &f.models {
            let mn = m.name.as_str();
            if let Some((other, p)) = seen.get(mn) {
                error(
                    out,
                    file,
                    m.pos,
                    "name",
                    format!(
                        "model '{mn}' is already declared at {other}:{}:{}",
                        p.line, p.col
                    ),
                );
                continue;
            }
            seen.insert(m.name.clone(), (file.clone(), m.pos));
            // a rule of this file refused for a name another file defines (reported where
            // it is): the model's call of that name means this file's rule, not the other
            // one, so nothing more is said of the model (its checks would be of the wrong
            // rule)
            let shadowed = m.init.iter().chain(&m.step).chain(&m.jvp).any(|c| {
                f.rules.iter().any(|r| r.name == c.rule)
                    && rules.iter().any(|r| r.name == c.rule && &r.file != file)
            });
            if shadowed {
                continue;
            }
            if let Some(c) = check_model(file, m, fdims, embs, (rules, &written), out) {
                models.push(c);
            }
        }
    }
    models
}

/// Whether `rule` runs on the elements of a map of dimension `dim`, one match per element
/// as `per_element` counts them: its hook is on the element's orbit (`<0,1,2>` in 3D,
/// `<0,1>` in 2D; the labels as a set, `<2,0,1>` is `<0,1,2>`) or on a dart (`<>`: the
/// shipped rules take one dart per element, `where n0.vertex0`).
pub fn hook_on_elements(rule: &Rule, dim: usize) -> bool {
    let mut h = rule.hook_orbit.clone();
    h.sort_unstable();
    h.is_empty() || h.iter().copied().eq(0..dim as u8)
}

#[allow(clippy::too_many_lines)]
fn check_model(
    file: &str,
    m: &ast::ModelDecl,
    dims: &[usize],
    embs: &[EmbDecl],
    (rules, written): (&[Rule], &[&str]),
    out: &mut Vec<Diagnostic>,
) -> Option<Model> {
    let before = out.len();
    let mn = m.name.as_str();
    let mut params: Vec<ModelParam> = Vec::new();
    // parameters refused for their type: still known to the model, so that an argument
    // naming one is not reported a second time as naming no parameter
    let mut refused: Vec<&str> = Vec::new();
    for p in &m.params {
        if params.iter().any(|q| q.name == p.name) {
            error(
                out,
                file,
                p.pos,
                "name",
                format!("model '{mn}': parameter '{}' is declared twice", p.name),
            );
            continue;
        }
        let ty = match p.ty.as_str() {
            "f64" => Ty::F64,
            "vec3" => Ty::Vec3,
            other => {
                error(
                    out,
                    file,
                    p.pos,
                    "type",
                    format!(
                        "model '{mn}': parameter '{}' has type '{other}'; a model parameter is f64 or vec3",
                        p.name
                    ),
                );
                refused.push(p.name.as_str());
                continue;
            }
        };
        let default = match &p.default {
            None => None,
            Some(d) => match constant(d) {
                Some(v) if v.ty() == ty && !finite(&v) => {
                    error(
                        out,
                        file,
                        d.pos,
                        "type",
                        format!(
                            "model '{mn}': the default of parameter '{}' is not finite",
                            p.name
                        ),
                    );
                    None
                }
                Some(v) if v.ty() == ty => Some(v),
                Some(v) => {
                    error(
                        out,
                        file,
                        d.pos,
                        "type",
                        format!(
                            "model '{mn}': the default of parameter '{}' is a {}, the parameter a {ty}",
                            p.name,
                            v.ty()
                        ),
                    );
                    None
                }
                None => {
                    error(
                        out,
                        file,
                        d.pos,
                        "type",
                        format!(
                            "model '{mn}': the default of parameter '{}' must be a number or vec3(x, y, z)",
                            p.name
                        ),
                    );
                    None
                }
            },
        };
        params.push(ModelParam {
            name: p.name.clone(),
            ty,
            default,
        });
    }
    for (what, empty) in [
        ("init", m.init.is_empty()),
        ("step", m.step.is_empty()),
        ("forces", m.forces.is_empty()),
    ] {
        if empty {
            error(
                out,
                file,
                m.pos,
                "syntax",
                format!("model '{mn}' has no '{what}' line"),
            );
        }
    }
    let calls = |list: &[ast::RuleCall], what: &str, out: &mut Vec<Diagnostic>| {
        let mut v = Vec::new();
        for c in list {
            let Some(rule) = rules.iter().find(|r| r.name == c.rule) else {
                let why = if written.contains(&c.rule.as_str()) {
                    "which the checker refused (its errors are reported at the rule)"
                } else {
                    "which is not defined"
                };
                error(
                    out,
                    file,
                    c.pos,
                    "name",
                    format!("model '{mn}': {what} calls rule '{}', {why}", c.rule),
                );
                continue;
            };
            // what the rule would change that a model must not (see SIMULATION_STATE)
            let state = written_by(rule, embs).find(|n| SIMULATION_STATE.contains(n));
            let forbidden = if rule.changes_topology {
                Some("changes the topology (it has a right graph): a model's rules compute embeddings only; cuts, fracture and tearing are the simulation's events".to_string())
            } else {
                state.map(|name| format!(
                    "writes '{name}', the simulation's own (its state, loads, solver vectors, numbering and material: {}): a model computes its own embeddings, its forces summed into 'force' by the simulation",
                    SIMULATION_STATE.join(", ")
                ))
            };
            if let Some(why) = forbidden {
                error(
                    out,
                    file,
                    c.pos,
                    "model-rule",
                    format!("model '{mn}': {what} calls rule '{}', which {why}", c.rule),
                );
                continue;
            }
            if c.args.len() != rule.params.len() {
                let want: Vec<String> = rule
                    .params
                    .iter()
                    .map(|(n, t)| format!("{n}: {t}"))
                    .collect();
                error(
                    out,
                    file,
                    c.pos,
                    "arity",
                    format!(
                        "model '{mn}': rule '{}' takes {} argument(s) ({}), the call gives {}",
                        c.rule,
                        rule.params.len(),
                        if want.is_empty() {
                            "none".into()
                        } else {
                            want.join(", ")
                        },
                        c.args.len()
                    ),
                );
                continue;
            }
            let mut args = Vec::new();
            for (a, (pn, pt)) in c.args.iter().zip(&rule.params) {
                let (arg, ty) = if let ModelArgKind::Param(name) = &a.kind {
                    let Some(p) = params.iter().find(|p| &p.name == name) else {
                        if refused.contains(&name.as_str()) {
                            // its type is the error, reported at the parameter
                            continue;
                        }
                        let known: Vec<&str> = params.iter().map(|p| p.name.as_str()).collect();
                        error(
                                out,
                                file,
                                a.pos,
                                "name",
                                format!(
                                    "model '{mn}': argument '{name}' of rule '{}' names no parameter of the model (it has: {})",
                                    c.rule,
                                    if known.is_empty() { "none".into() } else { known.join(", ") }
                                ),
                            );
                        continue;
                    };
                    (Arg::Param(name.clone()), p.ty)
                } else {
                    let v = constant(a).expect("a constant");
                    let t = v.ty();
                    (Arg::Const(v), t)
                };
                if ty != *pt {
                    error(
                        out,
                        file,
                        a.pos,
                        "type",
                        format!(
                            "model '{mn}': parameter '{pn}' of rule '{}' is a {pt}, the argument a {ty}",
                            c.rule
                        ),
                    );
                    continue;
                }
                args.push((pn.clone(), arg));
            }
            v.push(Call {
                rule: c.rule.clone(),
                args,
            });
        }
        v
    };
    let init = calls(&m.init, "init", out);
    let step = calls(&m.step, "step", out);
    let jvp = calls(&m.jvp, "jvp", out);
    // per_element: some init rule must be on elements, a hook on the element's orbit
    // (<0,1,2> in 3D, <0,1> in 2D) or on a dart (<>, one dart per element by a guard, as the
    // shipped rules take it): a simulation counts those rules' matches against its elements
    if let Some(pos) = m.per_element {
        let known: Vec<&Rule> = m
            .init
            .iter()
            .filter_map(|c| rules.iter().find(|r| r.name == c.rule))
            .collect();
        // every dimension the model runs in needs one (a file of `dimension 2 3`)
        let missing = dims
            .iter()
            .find(|&&d| !known.iter().any(|r| hook_on_elements(r, d)));
        if let (true, Some(&d)) = (known.len() == m.init.len(), missing) {
            let in_dim = if dims.len() > 1 {
                format!(" in {d}D")
            } else {
                String::new()
            };
            error(
                out,
                file,
                pos,
                "model-rule",
                format!(
                    "model '{mn}' is declared per_element (every element handled by an init rule), but none of its init rules ({}) is on elements{in_dim}: a rule whose hook is an element ('e : <0,1,2> hook', '<0,1>' in 2D) or one dart of each element ('n0 : <> hook' with 'where n0.vertex0'); drop per_element, or add such a rule",
                    known.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join(", ")
                ),
            );
        }
    }
    // a parameter no rule call passes on changes nothing: required, it would make every
    // user give a value that does nothing (an error); with a default, a likely slip (a
    // warning). The material's `young` and `poisson` are not parameters of models.
    for p in &m.params {
        let used = m.init.iter().chain(&m.step).chain(&m.jvp).any(|c| {
            c.args
                .iter()
                .any(|a| matches!(&a.kind, ModelArgKind::Param(n) if *n == p.name))
        });
        if used {
            continue;
        }
        let (severity, what) = if p.default.is_none() {
            (
                Severity::Error,
                "is required but no rule call of the model passes it on: a value given for it would change nothing (pass it to a rule of init, step or jvp, or remove it)",
            )
        } else {
            (
                Severity::Warning,
                "is passed to no rule call of the model: a value given for it changes nothing",
            )
        };
        out.push(Diagnostic {
            file: file.to_string(),
            pos: p.pos,
            severity,
            condition: "unused-parameter",
            message: format!("model '{mn}': parameter '{}' {what}", p.name),
        });
    }
    let vector_embeddings = |list: &[(String, Pos)], what: &str, out: &mut Vec<Diagnostic>| {
        for (k, (name, pos)) in list.iter().enumerate() {
            if list[..k].iter().any(|(n, _)| n == name) {
                error(
                    out,
                    file,
                    *pos,
                    "name",
                    format!(
                        "model '{mn}': {what} '{name}' is listed twice: it would be summed twice"
                    ),
                );
                continue;
            }
            if SIMULATION_STATE.contains(&name.as_str()) {
                error(
                    out,
                    file,
                    *pos,
                    "model-rule",
                    format!(
                        "model '{mn}': {what} '{name}' is the simulation's own (its state, loads, solver vectors, numbering and material: {}): a model lists embeddings its rules write",
                        SIMULATION_STATE.join(", ")
                    ),
                );
                continue;
            }
            let Some(e) = embs.iter().find(|e| &e.name == name) else {
                error(
                    out,
                    file,
                    *pos,
                    "name",
                    format!("model '{mn}': {what} '{name}' is not a declared embedding"),
                );
                continue;
            };
            let on_vertex = e.orbit.dims().all(|i| (1..=3).contains(&i));
            if e.ty != Ty::Vec3 || !on_vertex {
                error(
                    out,
                    file,
                    *pos,
                    "type",
                    format!(
                        "model '{mn}': {what} '{name}' is a {} on {}; it must be a vec3 on a sub-orbit of the vertex (labels within {{1, 2, 3}})",
                        e.ty, e.orbit
                    ),
                );
            }
        }
    };
    vector_embeddings(&m.forces, "force", out);
    vector_embeddings(&m.jvp_outputs, "jvp output", out);
    // each force is written by an init or step rule, each jvp output by a jvp rule: a name that no
    // rule of its list writes would be summed as whatever the map holds (zero, or a state
    // such as `position`)
    let writes = |calls: &[ast::RuleCall], name: &str| {
        calls.iter().any(|c| {
            rules
                .iter()
                .find(|r| r.name == c.rule)
                .is_some_and(|r| written_by(r, embs).any(|n| n == name))
        })
    };
    // (a constant force may be written once, by an init rule)
    let init_and_step: Vec<ast::RuleCall> = m.init.iter().chain(&m.step).cloned().collect();
    for (list, calls, what, rules_of) in [
        (&m.forces, &init_and_step, "force", "init or step"),
        (&m.jvp_outputs, &m.jvp, "jvp output", "jvp"),
    ] {
        if calls
            .iter()
            .any(|c| !rules.iter().any(|r| r.name == c.rule))
        {
            continue; // an undefined rule is reported above
        }
        for (name, pos) in list {
            if embs.iter().any(|e| &e.name == name) && !writes(calls, name) {
                error(
                    out,
                    file,
                    *pos,
                    "name",
                    format!(
                        "model '{mn}': {what} '{name}' is written by none of its {rules_of} rules ({})",
                        {
                            // each rule once (a rule may be both an init and a step rule)
                            let mut names: Vec<&str> = Vec::new();
                            for c in calls {
                                if !names.contains(&c.rule.as_str()) {
                                    names.push(&c.rule);
                                }
                            }
                            names.join(", ")
                        }
                    ),
                );
            }
        }
    }
    if !m.jvp.is_empty() && m.jvp_outputs.len() != m.forces.len() {
        error(
            out,
            file,
            m.jvp_outputs.first().map_or(m.pos, |o| o.1),
            "arity",
            format!(
                "model '{mn}' has {} force(s) and {} jvp output(s): jvp output k is the derivative of force k",
                m.forces.len(),
                m.jvp_outputs.len()
            ),
        );
    }
    // an error drops the model; a warning (an unused parameter with a default) does not
    if out[before..].iter().any(|d| d.severity == Severity::Error) {
        return None;
    }
    Some(Model {
        name: m.name.clone(),
        params,
        init,
        step,
        forces: m.forces.iter().map(|f| f.0.clone()).collect(),
        jvp,
        jvp_outputs: m.jvp_outputs.iter().map(|f| f.0.clone()).collect(),
        needs: m.needs.as_ref().map(|n| n.0.clone()),
        per_element: m.per_element.is_some(),
        dimensions: dims.to_vec(),
        file: file.to_string(),
        pos: m.pos,
    })
}

/// Whether every entry of a parameter value is finite.
fn finite(v: &Val) -> bool {
    match v {
        Val::F(x) => x.is_finite(),
        Val::V3(x) => x.iter().all(|c| c.is_finite()),
        _ => true,
    }
}
