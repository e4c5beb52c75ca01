//! Building a simulation: the rules of its models and the glue of a step (accumulation,
//! fixed and prescribed vertices, material regions, ground), and the set-up they run.

use std::fmt::Write as _;

use topomech_gmap::{Dart, GMap, OrbitType, Value};
use topomech_rules::{load_sources_for, Params, Val};

use crate::*;

/// The accumulation rules for the given force and Jacobian-vector-product embeddings, and one
/// rule per fixed predicate.
pub(crate) fn generated_rules(dim: usize, forces: &[&str], jvp: &[&str], cfg: &Config) -> String {
    let fixed = &cfg.fixed;
    let v = if dim == 3 { "<1,2,3>" } else { "<1,2>" };
    let mut s = format!("dimension {dim}\n");
    for (rule, target, parts) in [
        ("accumulate", "force", forces),
        ("accumulate_jvp", "df", jvp),
    ] {
        let _ = write!(
            s,
            "\nrule {rule} {{\n  left {{ v : {v} hook }}\n  compute {{ v.{target} = vec3(0, 0, 0)"
        );
        for f in parts {
            let _ = write!(s, " + sum{v}(v.{f})");
        }
        if rule == "accumulate" {
            // the external loads: constant, so nothing in the Jacobian
            s.push_str(" + v.f_ext");
        }
        s.push_str(" }\n}\n");
    }
    for (k, p) in fixed.iter().enumerate() {
        let _ = write!(
            s,
            "\nrule fix_{k} {{\n  left {{ v : {v} hook }}\n  where {{ let x = x(v.rest)  let y = y(v.rest)  let z = z(v.rest)  {p} }}\n  compute {{ v.fixed = true }}\n}}\n"
        );
    }
    for (k, (p, _)) in cfg.prescribed.iter().enumerate() {
        let _ = write!(
            s,
            "\nrule prescribe_{k}(d: vec3) {{\n  left {{ v : {v} hook }}\n  where {{ let x = x(v.rest)  let y = y(v.rest)  let z = z(v.rest)  {p} }}\n  compute {{ v.fixed = true  v.position = v.rest + d }}\n}}\n"
        );
    }
    let (side, arc, centre) = if dim == 3 {
        ("<0,1>", 3, "mean<0,1>")
    } else {
        ("<0>", 2, "mean<0>")
    };
    for (k, e) in cfg.events.iter().enumerate() {
        if let Cut::Where(p) = &e.cut {
            let _ = write!(
                s,
                "\nrule cut_where_{k} {{\n  left  {{ a : {side} hook   b : {side}   a -{arc}- b }}\n  right {{ a : {side}        b : {side} }}\n  where {{ let c = {centre}(a.position)  let x = x(c)  let y = y(c)  let z = z(c)  {p} }}\n}}\n"
            );
        }
    }
    let e = if dim == 3 { "<0,1,2>" } else { "<0,1>" };
    for (k, r) in cfg.regions.iter().enumerate() {
        let mut body = String::new();
        for (name, val) in [
            ("density", r.density),
            ("young", r.young),
            ("poisson", r.poisson),
        ] {
            if let Some(x) = val {
                let _ = write!(body, " e.{name} = {x:?}");
            }
        }
        let _ = write!(
            s,
            "\nrule region_{k} {{\n  left {{ e : {e} hook }}\n  where {{ let c = mean{e}(e.rest)  let x = x(c)  let y = y(c)  let z = z(c)  {} }}\n  compute {{{body} }}\n}}\n",
            r.predicate
        );
    }
    // the ground plane through p with unit normal n: a free vertex below it is projected onto
    // it and loses its velocity into it (the tangential velocity is kept)
    let _ = write!(
        s,
        "\nrule ground(p: vec3, n: vec3) {{\n  left {{ v : {v} hook }}\n  where !v.fixed && dot(v.position - p, n) < 0.0\n  compute {{\n    v.position = v.position - dot(v.position - p, n) * n\n    v.velocity = v.velocity - min(dot(v.velocity, n), 0.0) * n\n  }}\n}}\n"
    );
    s
}

impl Simulation {
    /// Builds a simulation on `g` (it must have a `position` embedding): loads the rules of
    /// the models, computes rest state, masses and model parameters.
    pub fn new(mut g: GMap, cfg: Config) -> Result<Self, PhysicsError> {
        let dim = g.dimension();
        if !(cfg.dt > 0.0 && cfg.dt.is_finite()) {
            return Err(PhysicsError::Config(format!(
                "dt must be positive, got {}",
                cfg.dt
            )));
        }
        if !(cfg.density > 0.0 && cfg.density.is_finite()) {
            return Err(PhysicsError::Config(format!(
                "density must be positive, got {}",
                cfg.density
            )));
        }
        if cfg.models.is_empty() {
            return Err(PhysicsError::Model("no model given".into()));
        }
        let mut sources = vec![
            (
                format!("common{dim}d.tmr"),
                model_source("common", dim).expect("shipped").to_string(),
            ),
            (
                format!("topology{dim}d.tmr"),
                model_source("topology", dim).expect("shipped").to_string(),
            ),
        ];
        if let Some(f) = cfg.fracture {
            if !(f.threshold.is_finite()) {
                return Err(PhysicsError::Config(format!(
                    "fracture threshold must be finite, got {}",
                    f.threshold
                )));
            }
            if f.criterion == Criterion::Stress {
                if dim != 3 {
                    return Err(PhysicsError::Config("the stress criterion of fracture needs tetrahedra (3D); surfaces tear by strain".into()));
                }
                sources.push((
                    "fem3d.tmr".into(),
                    model_source("fem", 3).expect("shipped").to_string(),
                ));
            }
        }
        for e in &cfg.events {
            if !(e.time >= 0.0 && e.time.is_finite()) {
                return Err(PhysicsError::Config(format!(
                    "event time must be a finite time >= 0, got {}",
                    e.time
                )));
            }
        }
        for (name, text) in model_files(&cfg, dim)? {
            if !sources.iter().any(|s| s.0 == name) {
                sources.push((name, text));
            }
        }
        // the forces the glue sums, from the declarations as written (they are checked with
        // everything else below)
        let outputs: Vec<(Vec<String>, Vec<String>)> = cfg
            .models
            .iter()
            .map(|m| declared_outputs(&sources, &m.kind))
            .collect();
        let forces: Vec<&str> = outputs
            .iter()
            .flat_map(|o| o.0.iter().map(String::as_str))
            .collect();
        let jvp: Vec<&str> = outputs
            .iter()
            .flat_map(|o| o.1.iter().map(String::as_str))
            .collect();
        sources.push((
            "scene-generated.tmr".into(),
            generated_rules(dim, &forces, &jvp, &cfg),
        ));
        let (rules, _warnings) = load_sources_for(dim, &sources).map_err(|diags| {
            // a refused predicate is the scene's fault: say so
            let error =
                |d: &topomech_rules::Diagnostic| d.severity == topomech_rules::Severity::Error;
            if diags
                .iter()
                .any(|d| d.file == "scene-generated.tmr" && error(d))
                && !diags
                    .iter()
                    .any(|d| d.file != "scene-generated.tmr" && error(d))
            {
                let msgs: Vec<String> = diags
                    .iter()
                    .filter(|d| d.severity == topomech_rules::Severity::Error)
                    .map(|d| d.message.clone())
                    .collect();
                PhysicsError::Config(format!(
                    "bad fixed-vertex predicate in {:?}: {}",
                    cfg.fixed,
                    msgs.join("; ")
                ))
            } else {
                PhysicsError::Rules(diags)
            }
        })?;
        let mut defs = Vec::new();
        for m in &cfg.models {
            let decl = rules.model(&m.kind).ok_or_else(|| {
                PhysicsError::Model(format!("model '{}' is not declared in its file", m.kind))
            })?;
            if !decl.dimensions.contains(&dim) {
                return Err(PhysicsError::Model(format!(
                    "model '{}' needs a mesh of dimension {:?}, this one has dimension {dim}",
                    m.kind, decl.dimensions
                )));
            }
            defs.push(RunModel::bind(decl, &m.params)?);
        }
        if matches!(
            cfg.integrator,
            Integrator::ImplicitEuler | Integrator::Static
        ) {
            if let Some(def) = defs.iter().find(|d| d.jvp.is_empty()) {
                return Err(PhysicsError::Model(format!(
                    "model '{}' has no Jacobian rules yet: use explicit_euler or symplectic_euler with it",
                    def.name
                )));
            }
        }
        if let Some(ground) = &cfg.ground {
            ground.plane(cfg.gravity)?;
        }
        if g.embedding_id("position").is_none() {
            return Err(PhysicsError::Config(
                "the map has no 'position' embedding".into(),
            ));
        }
        // the data the simulation itself reads; each rule adds what it uses when it first runs
        rules.prepare_named(
            &mut g,
            &[
                "position", "rest", "velocity", "force", "fixed", "mass", "dx", "dv", "df",
                "vertex0", "face0", "f_ext",
            ],
        )?;
        mark_vertex0(&mut g)?;
        let none = Params::new();
        rules.apply_everywhere(&mut g, "init_rest", &none)?;
        let material: Params = [
            ("density".to_string(), Val::F(cfg.density)),
            ("young".to_string(), Val::F(cfg.young)),
            ("poisson".to_string(), Val::F(cfg.poisson)),
        ]
        .into();
        rules.apply_everywhere(&mut g, "set_material", &material)?;
        for k in 0..cfg.regions.len() {
            let rep = rules.apply_everywhere(&mut g, &format!("region_{k}"), &none)?;
            if rep.matches == 0 {
                return Err(PhysicsError::Config(format!(
                    "material region '{}' contains no element",
                    cfg.regions[k].predicate
                )));
            }
        }
        let (he, elem) = if dim == 3 {
            ("half_edge_volume", "element_volume")
        } else {
            ("half_edge_area", "element_area")
        };
        rules.apply_everywhere(&mut g, he, &none)?;
        rules.apply_everywhere(&mut g, elem, &none)?;
        rules.apply_everywhere(&mut g, "lump_mass", &none)?;
        for k in 0..cfg.fixed.len() {
            let rep = rules.apply_everywhere(&mut g, &format!("fix_{k}"), &none)?;
            if rep.matches == 0 {
                return Err(PhysicsError::Config(format!(
                    "fix predicate '{}' selects no vertex",
                    cfg.fixed[k]
                )));
            }
        }
        for (k, (p, d)) in cfg.prescribed.iter().enumerate() {
            let params: Params = [("d".to_string(), Val::V3(*d))].into();
            let rep = rules.apply_everywhere(&mut g, &format!("prescribe_{k}"), &params)?;
            if rep.matches == 0 {
                return Err(PhysicsError::Config(format!(
                    "prescribed-displacement predicate '{p}' selects no vertex"
                )));
            }
        }
        let elements = g.count_orbits(if dim == 3 {
            OrbitType::volume()
        } else {
            OrbitType::face(2)
        });
        for def in &defs {
            let mut matched = 0;
            for (init, p) in &def.init {
                matched += rules.apply_everywhere(&mut g, init, p)?.matches;
            }
            if matched == 0 {
                return Err(PhysicsError::Model(format!(
                    "model '{}' matches nothing on this mesh: it needs {}",
                    def.name, def.needs
                )));
            }
            if def.per_element && matched < elements {
                return Err(PhysicsError::Model(format!(
                    "model '{}' handles {} elements of {elements}: it needs {}, and the others would get no force",
                    def.name, matched, def.needs
                )));
            }
        }
        // the derived data of what the models stored (cumulated springs, tensors) exists from
        // the start, so that it is kept up to date through topology changes
        let embs = rules.embeddings();
        let derived: Vec<&str> = embs
            .iter()
            .filter(|e| {
                e.derived
                    .is_some_and(|(_, src)| g.embedding_id(&embs[src].name).is_some())
            })
            .map(|e| e.name.as_str())
            .collect();
        rules.prepare_named(&mut g, &derived)?;
        rules.clear_plans();
        g.refresh_derived();
        let step_params: Params = [
            ("dt".to_string(), Val::F(cfg.dt)),
            ("gravity".to_string(), Val::V3(cfg.gravity)),
            ("damping".to_string(), Val::F(cfg.damping)),
        ]
        .into();
        let rows = Rows::init(&mut g)?;
        let vertex_darts_version = g.version();
        let size = {
            let pos = g
                .require("rest")
                .map_err(|e| PhysicsError::Config(e.to_string()))?;
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for d in g.darts() {
                let p = g.real(pos, d);
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
            norm3([hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]]).max(f64::MIN_POSITIVE)
        };
        let cfg_events = cfg.events.len();
        let mut sim = Simulation {
            g,
            rules,
            cfg,
            defs,
            step_params,
            time: 0.0,
            steps: 0,
            rows,
            vertex_darts_version,
            size,
            events_done: vec![false; cfg_events],
            changes: Vec::new(),
            saved: [Vec::new(), Vec::new()],
            report: None,
            static_base: Vec::new(),
        };
        // a welded row is one particle: held when any of its orbits is
        if !sim.rows.welded.is_empty() {
            let fixed = sim.row_any("fixed")?;
            sim.set_vertex_bool("fixed", &fixed)?;
        }
        // every free vertex needs a mass
        let masses = sim.vertex_scalar_sum("mass")?;
        let fixed = sim.vertex_bool("fixed")?;
        if let Some(v) = (0..masses.len()).find(|&v| {
            !fixed[v] && masses[v].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        }) {
            return Err(PhysicsError::Config(format!(
                "vertex {v} has mass {} and is not fixed",
                masses[v]
            )));
        }
        Ok(sim)
    }
}

/// Marks one dart per element (volume in 3D, face in 2D) as `vertex0`: the element's smallest
/// dart; and, where a model declares `face0`, one dart per face `<0,1>` of an element. Rules
/// number an element's or a face's vertices from them.
fn mark_vertex0(g: &mut GMap) -> Result<(), PhysicsError> {
    let elem = if g.dimension() == 3 {
        OrbitType::volume()
    } else {
        OrbitType::face(2)
    };
    mark_one_per_orbit(g, "vertex0", elem)?;
    if g.embedding_id("face0").is_some() {
        mark_one_per_orbit(g, "face0", OrbitType::parse("<0,1>").expect("static"))?;
    }
    Ok(())
}

/// Sets the bool embedding `name` (on `<>`) true on the smallest dart of each orbit `o`,
/// false elsewhere.
fn mark_one_per_orbit(g: &mut GMap, name: &str, o: OrbitType) -> Result<(), PhysicsError> {
    let err = |e: topomech_gmap::EmbeddingError| PhysicsError::Config(e.to_string());
    let id = g.require(name).map_err(err)?;
    let all: Vec<Dart> = g.darts().collect();
    for d in all {
        g.set_value(id, d, &Value::Bool(false)).map_err(err)?;
    }
    for d in g.orbit_representatives(o) {
        g.set_value(id, d, &Value::Bool(true)).map_err(err)?;
    }
    Ok(())
}
