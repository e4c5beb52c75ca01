//! Models from rule files: the shipped models read from their declarations, and a model the
//! user writes in a file of their own (per-vertex anchor springs `f = -k (x - x_rest)`),
//! run with each integrator and checked against the analytic static displacement `m g / k`.

// Numeric reference code: index loops mirror the math; the expected table is a literal.
#![allow(clippy::needless_range_loop, clippy::type_complexity)]

use crate::common;

use std::collections::HashMap;
use std::path::PathBuf;

use common::model;
use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions, Mesh};
use topomech_physics::{shipped_models, Config, Integrator, PhysicsError, Simulation};
use topomech_rules::Val;

/// The anchor-spring model as a user writes it, for a map of dimension `dim`: it declares
/// only its own embeddings and uses the shipped ones (`position`, `rest`, `dx`).
fn anchor_file(dim: usize) -> String {
    let v = if dim == 3 { "<1,2,3>" } else { "<1,2>" };
    format!(
        "dimension {dim}
embedding k_anchor  : f64  on {v}
embedding f_anchor  : vec3 on {v}
embedding df_anchor : vec3 on {v}

rule anchor_init(k: f64) {{
  left {{ v : {v} hook }}
  compute {{ v.k_anchor = k }}
}}
rule anchor_force {{
  left {{ v : {v} hook }}
  compute {{ v.f_anchor = -v.k_anchor * (v.position - v.rest) }}
}}
rule anchor_jvp {{
  left {{ v : {v} hook }}
  compute {{ v.df_anchor = -v.k_anchor * v.dx }}
}}

model anchor(k: f64 = 10.0) {{
  init   anchor_init(k)
  step   anchor_force
  forces f_anchor
  jvp    anchor_jvp -> df_anchor
  needs  \"vertices\"
}}
"
    )
}

/// A fresh folder under the system's temporary folder (not in the package).
fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("topomech-model-files-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes `text` to `name` in a temporary folder and reads it back as `(file name, text)`.
fn written(tag: &str, name: &str, text: &str) -> (String, String) {
    let path = temp_dir(tag).join(name);
    std::fs::write(&path, text).unwrap();
    let back = std::fs::read_to_string(&path).unwrap();
    (path.display().to_string(), back)
}

fn anchor_sim(
    mesh: &Mesh,
    dim: usize,
    k: f64,
    integrator: Integrator,
) -> Result<Simulation, PhysicsError> {
    let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("anchor", &[("k", k)])],
        model_files: vec![written(
            &format!("anchor{dim}"),
            "anchor.tmr",
            &anchor_file(dim),
        )],
        density: 2.0,
        damping: 20.0,
        integrator,
        dt: if integrator == Integrator::Static {
            1.0
        } else {
            1e-3
        },
        ..Config::default()
    };
    Simulation::new(g, cfg)
}

/// Each free vertex of an anchored mesh settles at `u = m g / k` (its own spring balances
/// its weight; the vertices are independent): exact for the static solve (the problem is
/// linear, one Newton step) and reached by the damped explicit integrators (the error decays
/// like exp(-c t / 2) with damping c = 20 1/s; 6 s of simulated time leave ~1e-26), checked
/// to 1e-10 relative to |m g / k|.
#[test]
fn anchor_springs_settle_at_m_g_over_k() {
    let tri = grid([3, 2], [1.5, 1.0], GridElement::Triangle);
    let tet = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let k = 50.0;
    for (mesh, dim) in [(&tri, 2), (&tet, 3)] {
        for integrator in [
            Integrator::Static,
            Integrator::ImplicitEuler,
            Integrator::SymplecticEuler,
            Integrator::ExplicitEuler,
        ] {
            let mut s = anchor_sim(mesh, dim, k, integrator).unwrap();
            let steps = if integrator == Integrator::Static {
                1
            } else {
                6000
            };
            for _ in 0..steps {
                s.step().unwrap();
            }
            let g = s.config().gravity;
            let m = s.vertex_scalar_sum("mass").unwrap();
            let x = s.vertex_vec3("position").unwrap();
            let rest = s.vertex_vec3("rest").unwrap();
            assert!(m.len() > 4);
            for v in 0..m.len() {
                assert!(m[v] > 0.0);
                for a in 0..3 {
                    let want = m[v] * g[a] / k;
                    let got = x[v][a] - rest[v][a];
                    let scale = m[v] * common::norm(g) / k;
                    assert!(
                        (got - want).abs() <= 1e-10 * scale.max(f64::MIN_POSITIVE),
                        "{dim}D {integrator:?} vertex {v} axis {a}: {got} vs m g / k = {want}"
                    );
                }
            }
        }
    }
}

/// A user's model without Jacobian rules runs with the explicit integrators; implicit and
/// static runs are refused naming it. Unknown parameters are refused naming the model's.
#[test]
fn a_users_model_is_refused_where_it_cannot_run() {
    let tri = grid([2, 2], [1.0, 1.0], GridElement::Triangle);
    let no_jvp = anchor_file(2)
        .replace("  jvp    anchor_jvp -> df_anchor\n", "")
        .replace("model anchor", "model anchor_explicit");
    for (integrator, ok) in [
        (Integrator::SymplecticEuler, true),
        (Integrator::Static, false),
        (Integrator::ImplicitEuler, false),
    ] {
        let (g, _) = build(&tri, &BuildOptions::default()).unwrap();
        let cfg = Config {
            models: vec![model("anchor_explicit", &[])],
            model_files: vec![written("nojvp", "anchor.tmr", &no_jvp)],
            integrator,
            ..Config::default()
        };
        match Simulation::new(g, cfg) {
            Ok(_) => assert!(ok, "{integrator:?} accepted"),
            Err(e) => {
                assert!(!ok, "{integrator:?}: {e}");
                assert!(
                    e.to_string()
                        .contains("model 'anchor_explicit' has no Jacobian rules"),
                    "{e}"
                );
            }
        }
    }
    let (g, _) = build(&tri, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("anchor", &[("stiffness", 1.0)])],
        model_files: vec![written("param", "anchor.tmr", &anchor_file(2))],
        ..Config::default()
    };
    let e = Simulation::new(g, cfg).unwrap_err().to_string();
    assert!(
        e.contains("model 'anchor' has no parameter 'stiffness' (it has: k)"),
        "{e}"
    );
}

/// `per_element` counts the elements the init rules on elements match (one per element),
/// not the matches of every init rule: before, a model whose element rule matched only
/// tetrahedra passed on a mesh of hexahedra because its vertex rule's matches were added
/// (45 vertices against 16 elements: every element without force), and a model with vertex
/// rules only passed or failed by how many vertices the mesh had.
#[test]
fn per_element_counts_the_elements_its_init_rules_match() {
    let file = |inits: &str| {
        format!(
            "dimension 3
embedding k_el : f64  on <0,1,2>
embedding k_v  : f64  on <1,2,3>
embedding f_el : vec3 on <1,2>

rule el_init(k: f64) {{
  left {{ e : <0,1,2> hook }}
  where count<0,1,2>(e) == 24
  compute {{ e.k_el = k }}
}}
rule v_init(k: f64) {{
  left {{ v : <1,2,3> hook }}
  compute {{ v.k_v = k }}
}}
rule left_half(k: f64) {{
  left {{ n0 : <> hook }}
  where x(mean<0,1,2>(n0.rest)) < 0.5
  compute {{ n0.k_el = k }}
}}
rule el_force {{
  left {{ c : <1,2> hook }}
  compute {{ c.f_el = -c.k_el * (c.position - c.rest) }}
}}
model tets(k: f64 = 10.0) {{
  init   {inits}
  step   el_force
  forces f_el
  needs  \"tetrahedra\"
  per_element
}}
"
        )
    };
    let sim = |element: BoxElement, inits: &str| {
        let (g, _) = build(
            &cuboid([4, 2, 2], [1.0, 0.5, 0.5], element),
            &BuildOptions::default(),
        )
        .unwrap();
        let cfg = Config {
            models: vec![model("tets", &[])],
            model_files: vec![written("per_element", "tets.tmr", &file(inits))],
            ..Config::default()
        };
        Simulation::new(g, cfg)
    };
    // tetrahedra: every element handled
    sim(BoxElement::Tetra, "el_init(k), v_init(k)").unwrap();
    // hexahedra: the element rule matches none of the 16; the vertex rule's 45 matches
    // handle no element
    let e = sim(BoxElement::Hexa, "el_init(k), v_init(k)")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("model 'tets' handles 0 elements of 16: it needs tetrahedra"),
        "{e}"
    );
    // a dart rule without a one-dart guard: 24 matches a tetrahedron, on the left half of
    // the box only; the matches (24 x 48) outnumber the 96 elements, the elements handled
    // (48) do not
    let e = sim(BoxElement::Tetra, "left_half(k)")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("model 'tets' handles 48 elements of 96: it needs tetrahedra"),
        "{e}"
    );
    // no init rule on elements at all
    let e = sim(BoxElement::Tetra, "v_init(k)").unwrap_err().to_string();
    assert!(
        e.contains("model 'tets' is declared per_element")
            && e.contains("none of its init rules (v_init) is on elements"),
        "{e}"
    );
}

/// A mistake in the user's model file is reported at its file, line and column.
#[test]
fn a_bad_model_file_is_reported_where_it_is_wrong() {
    let tri = grid([2, 2], [1.0, 1.0], GridElement::Triangle);
    let bad = anchor_file(2).replace("init   anchor_init(k)", "init   anchor_init(k, k)");
    let (file, text) = written("bad", "anchor.tmr", &bad);
    let line = text
        .lines()
        .position(|l| l.contains("anchor_init(k, k)"))
        .unwrap()
        + 1;
    let (g, _) = build(&tri, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("anchor", &[])],
        model_files: vec![(file.clone(), text)],
        ..Config::default()
    };
    let Err(PhysicsError::Rules(d)) = Simulation::new(g, cfg) else {
        panic!("accepted, or not a rules error");
    };
    let e = d
        .iter()
        .find(|d| d.condition == "arity")
        .unwrap_or_else(|| panic!("{d:?}"));
    assert_eq!(e.file, file);
    assert_eq!(e.pos.line as usize, line);
    assert_eq!(e.pos.col, 10);
    assert!(
        e.message.contains("rule 'anchor_init' takes 1 argument(s)"),
        "{e}"
    );
}

/// The shipped models, read from their files' declarations, are the ones the Rust table
/// listed before the declarations: names, dimensions, parameters with defaults, needs.
#[test]
fn shipped_models_are_read_from_the_declarations() {
    let springs = |k: f64| vec![("stiffness", k), ("damping", 0.0)];
    let want: Vec<(&str, Vec<usize>, Vec<(&str, f64)>, &str, bool)> = vec![
        (
            "stretch_elementary",
            vec![2, 3],
            springs(1000.0),
            "edges",
            true,
        ),
        (
            "stretch_cumulated",
            vec![2, 3],
            springs(1000.0),
            "edges",
            true,
        ),
        (
            "shear_isotropic",
            vec![2, 3],
            springs(1000.0),
            "quadrilateral faces",
            true,
        ),
        (
            "shear_anisotropic",
            vec![2, 3],
            springs(1000.0),
            "faces",
            true,
        ),
        ("shear_volumic", vec![3], springs(1000.0), "hexahedra", true),
        (
            "bending_linear",
            vec![2],
            springs(100.0),
            "edges continuing each other across faces",
            true,
        ),
        (
            "bending_angular",
            vec![2],
            springs(1.0),
            "interior edges between two triangles or quads",
            false,
        ),
        ("linear_fem", vec![3], vec![], "tetrahedra", true),
        (
            "corotational",
            vec![3],
            vec![],
            "tetrahedra or hexahedra",
            true,
        ),
        ("mass_tensor", vec![3], vec![], "tetrahedra", true),
        (
            "corotational",
            vec![2],
            vec![("thickness", 1.0)],
            "triangles",
            true,
        ),
    ];
    let got = shipped_models();
    for (name, dims, params, needs, jvp) in &want {
        let m = got
            .iter()
            .find(|m| m.name == *name && m.dimensions == *dims)
            .unwrap_or_else(|| panic!("{name} {dims:?} not in {got:?}"));
        let p: HashMap<&str, Option<Val>> = m
            .params
            .iter()
            .map(|p| (p.name.as_str(), p.default.clone()))
            .collect();
        let w: HashMap<&str, Option<Val>> =
            params.iter().map(|(k, v)| (*k, Some(Val::F(*v)))).collect();
        assert_eq!(p, w, "{name}");
        assert_eq!(m.needs.as_deref(), Some(*needs), "{name}");
        assert_eq!(m.has_jvp, *jvp, "{name}");
    }
    assert!(got.len() >= want.len());
}

/// A user's model with a `vec3` parameter, set from the configuration: anchor springs that
/// pull each vertex toward `rest + offset`, `f = -k (x - rest - offset)`. Without gravity
/// the static solve (linear: one Newton step) puts every free vertex exactly at
/// `rest + offset` (to 1e-12 relative to |offset|: one linear solve per vertex, rounding
/// only); with the default offset it stays at rest. A parameter of the wrong type, or a
/// non-finite one, is refused naming the model and the parameter.
#[test]
fn a_vec3_model_parameter_is_set_from_the_configuration() {
    let text = "dimension 2 3
embedding k_off  : f64  on <1,2,3>
embedding u_off  : vec3 on <1,2,3>
embedding f_off  : vec3 on <1,2,3>
embedding df_off : vec3 on <1,2,3>

rule off_init(k: f64, offset: vec3) {
  left { v : <1,2,3> hook }
  compute { v.k_off = k   v.u_off = offset }
}
rule off_force {
  left { v : <1,2,3> hook }
  compute { v.f_off = -v.k_off * (v.position - v.rest - v.u_off) }
}
rule off_jvp {
  left { v : <1,2,3> hook }
  compute { v.df_off = -v.k_off * v.dx }
}

model anchor_offset(k: f64 = 10.0, offset: vec3 = vec3(0, 0, 0)) {
  init   off_init(k, offset)
  step   off_force
  forces f_off
  jvp    off_jvp -> df_off
}
";
    let file = written("vec3param", "offset.tmr", text);
    let tet = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let tri = grid([2, 2], [1.0, 1.0], GridElement::Triangle);
    let run = |mesh: &Mesh, params: HashMap<String, Val>| {
        let (g, _) = build(mesh, &BuildOptions::default()).unwrap();
        let cfg = Config {
            models: vec![topomech_physics::ModelSpec {
                kind: "anchor_offset".into(),
                params,
            }],
            model_files: vec![file.clone()],
            gravity: [0.0; 3],
            integrator: Integrator::Static,
            dt: 1.0,
            ..Config::default()
        };
        let mut s = Simulation::new(g, cfg)?;
        s.step()?;
        Ok::<_, PhysicsError>(s)
    };
    let offset = [0.25, -0.5, 0.125];
    for mesh in [&tet, &tri] {
        for (given, want) in [(Some(offset), offset), (None, [0.0; 3])] {
            let mut params: HashMap<String, Val> = [("k".to_string(), Val::F(40.0))].into();
            if let Some(o) = given {
                params.insert("offset".into(), Val::V3(o));
            }
            let s = run(mesh, params).unwrap();
            let x = s.vertex_vec3("position").unwrap();
            let rest = s.vertex_vec3("rest").unwrap();
            for v in 0..x.len() {
                for a in 0..3 {
                    let got = x[v][a] - rest[v][a];
                    assert!(
                        (got - want[a]).abs() <= 1e-12 * common::norm(offset),
                        "vertex {v} axis {a}: moved {got}, the offset is {}",
                        want[a]
                    );
                }
            }
        }
    }
    for (value, says) in [
        (Val::F(1.0), "parameter 'offset' is a vec3, got a f64"),
        (
            Val::V3([0.0, f64::NAN, 0.0]),
            "parameter 'offset' must be finite",
        ),
    ] {
        let err = run(&tet, [("offset".to_string(), value)].into())
            .err()
            .unwrap();
        let msg = err.to_string();
        assert!(msg.contains("anchor_offset") && msg.contains(says), "{msg}");
    }
    let err = run(&tet, [("k".to_string(), Val::V3([1.0; 3]))].into())
        .err()
        .unwrap();
    assert!(
        err.to_string()
            .contains("parameter 'k' is a f64, got a vec3"),
        "{err}"
    );
}

/// A model listed twice would have its force summed twice with the last parameters for both
/// (its rules and embeddings exist once per map): refused, naming it and both places.
#[test]
fn a_model_listed_twice_is_refused() {
    let tri = grid([2, 2], [1.0, 1.0], GridElement::Triangle);
    let (g, _) = build(&tri, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![
            model("stretch_elementary", &[("stiffness", 100.0)]),
            model("stretch_cumulated", &[]),
            model("stretch_elementary", &[("stiffness", 300.0)]),
        ],
        ..Config::default()
    };
    let err = Simulation::new(g, cfg).err().unwrap().to_string();
    assert!(
        err.contains("model 'stretch_elementary' is listed twice (models 0 and 2)"),
        "{err}"
    );
}

/// A step rule with a guard writes its force only where the guard holds, and the set of
/// vertices changes from step to step: every force column must then be reset before the
/// step rules run (a vertex whose guard stopped holding must not keep last step's force).
/// `Simulation::forces` skips that reset only where no step rule has a guard and nothing
/// changed since its last run; this test fails if the skip ignores the guard. The model
/// pushes up (+y, against gravity; 1 N) every vertex that sank more than 1 mm below its rest
/// position; gravity and the push make vertices sink and rise across that line. After each
/// step, `forces()` is recomputed and each vertex's `f_push` must be exactly the push or
/// exactly zero, as the guard on its current position says.
#[test]
// exact comparisons: the rule writes `up` itself, the reset writes zeros
#[allow(clippy::float_cmp)]
fn a_guarded_step_rule_leaves_no_stale_force() {
    let file = "dimension 3
embedding f_push : vec3 on <1,2,3>
rule push(up: vec3) {
  left { v : <1,2,3> hook }
  where dot(v.position - v.rest, up) < -0.001
  compute { v.f_push = up }
}
rule push_init {
  left { v : <1,2,3> hook }
  compute { v.f_push = 0.0 * v.position }
}
model push(up: vec3 = vec3(0.0, 1.0, 0.0)) {
  init   push_init
  step   push(up)
  forces f_push
}
";
    let mesh = cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("push", &[])],
        model_files: vec![written("push", "push.tmr", file)],
        // vertex weights of about 0.3 N against the 1 N push: vertices rise back
        density: 0.3,
        integrator: Integrator::SymplecticEuler,
        dt: 1e-3,
        ..Config::default()
    };
    let mut s = Simulation::new(g, cfg).unwrap();
    let (mut pushed, mut released) = (0, 0);
    let mut was: Vec<bool> = Vec::new();
    for _ in 0..400 {
        s.step().unwrap();
        s.forces().unwrap();
        let x = s.vertex_vec3("position").unwrap();
        let rest = s.vertex_vec3("rest").unwrap();
        let f = s.vertex_vec3("f_push").unwrap();
        let now: Vec<bool> = (0..x.len())
            .map(|v| x[v][1] - rest[v][1] < -0.001)
            .collect();
        for v in 0..x.len() {
            let want = if now[v] { [0.0, 1.0, 0.0] } else { [0.0; 3] };
            assert_eq!(
                f[v], want,
                "vertex {v}: f_push {:?}, guard {}",
                f[v], now[v]
            );
            if let Some(&before) = was.get(v) {
                pushed += usize::from(now[v] && !before);
                released += usize::from(!now[v] && before);
            }
        }
        was = now;
    }
    // the guard changed both ways during the run, so the check above saw both transitions
    assert!(
        pushed > 0 && released > 0,
        "pushed {pushed}, released {released}"
    );
}

/// A user's model file with a syntax error: the simulation says where (`file:line:col`), not
/// that the model it would have declared is unknown.
#[test]
fn a_model_file_that_does_not_parse_is_reported_where() {
    let file = "dimension 3\nmodel broken(up: vec3 = [0.0, 1.0, 0.0]) {\n  forces f_x\n}\n";
    let mesh = cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let (path, text) = written("broken", "broken.tmr", file);
    let cfg = Config {
        models: vec![model("broken", &[])],
        model_files: vec![(path.clone(), text)],
        ..Config::default()
    };
    let e = Simulation::new(g, cfg).expect_err("refused").to_string();
    assert!(e.contains(&format!("{path}:2:")), "{e}");
    assert!(e.contains("syntax") && !e.contains("unknown model"), "{e}");
}

/// Two models whose rules write one force embedding and that both list it: their rules
/// write one value (the last one's), which the accumulation would sum once per model (QA:
/// an "up" and a "down" force of 1 N gave -2 N). Refused when the simulation is built,
/// naming both models and the embedding.
#[test]
fn two_models_listing_one_force_are_refused() {
    let file = "dimension 3
embedding qa_dummy : f64 on <1,2,3>
embedding fe : vec3 on <1,2,3>
rule qa_noop { left { v : <1,2,3> hook } compute { v.qa_dummy = 0.0 } }
rule fr(a: f64) { left { v : <1,2,3> hook } compute { v.fe = vec3(0.0, a, 0.0) } }
model up(a: f64 = 1.0) { init qa_noop step fr(a) forces fe }
model down(a: f64 = -1.0) { init qa_noop step fr(a) forces fe }
";
    let mesh = cuboid([1, 1, 1], [1.0, 1.0, 1.0], BoxElement::Tetra);
    let (g, _) = build(&mesh, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("up", &[]), model("down", &[])],
        model_files: vec![written("updown", "updown.tmr", file)],
        ..Config::default()
    };
    let e = Simulation::new(g, cfg).unwrap_err().to_string();
    assert!(
        e.contains("models 'up' (model[0]) and 'down' (model[1]) both list the embedding 'fe'"),
        "{e}"
    );
}

/// A model's init rule that fails at set-up (here a non-finite value, `k / x` at the
/// vertices on x = 0) is reported with the model, the rule, its file and the element it
/// failed in (by its rest centroid), not with a dart number alone (a QA report).
#[test]
fn a_failing_init_rule_names_its_model_file_and_element() {
    let tri = grid([2, 2], [1.0, 1.0], GridElement::Triangle);
    let text = anchor_file(2).replace("v.k_anchor = k }", "v.k_anchor = k / x(v.rest) }");
    let (file, body) = written("initfail", "anchor.tmr", &text);
    let (g, _) = build(&tri, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![model("anchor", &[("k", 1.0)])],
        model_files: vec![(file.clone(), body)],
        ..Config::default()
    };
    let e = Simulation::new(g, cfg).unwrap_err().to_string();
    assert!(
        e.contains(&format!(
            "model 'anchor': its init rule 'anchor_init' (in {file}) failed at the element whose rest centroid is ("
        )),
        "{e}"
    );
    assert!(e.contains("non-finite value inf to 'k_anchor'"), "{e}");
    // the centroid named is that of a triangle touching x = 0 (its x below 1/2)
    let x: f64 = e
        .split("rest centroid is (")
        .nth(1)
        .and_then(|r| r.split(',').next())
        .and_then(|x| x.trim().parse().ok())
        .unwrap();
    assert!(x > 0.0 && x < 0.5, "{e}");
}

/// Two models whose init rules write one embedding to other values are refused: the
/// embedding holds the last value written, which both models' step rules read (QA: the
/// elementary springs at 1000 N/m with the cumulated ones at 10 N/m both ran at 10, and in
/// the other order both at 1000). With the same parameters the values are the same, and the
/// pair runs; so do two models that compute the same data by different rules (the
/// rest-shape inverse `hyper_dm_inv` of both hyperelastic models).
#[test]
fn models_setting_one_embedding_differently_are_refused() {
    let tri = grid([2, 2], [1.0, 1.0], GridElement::Triangle);
    let run = |k_elementary: f64, k_cumulated: f64| {
        let (g, _) = build(&tri, &BuildOptions::default()).unwrap();
        let cfg = Config {
            models: vec![
                model("stretch_elementary", &[("stiffness", k_elementary)]),
                model("stretch_cumulated", &[("stiffness", k_cumulated)]),
            ],
            ..Config::default()
        };
        Simulation::new(g, cfg)
    };
    let e = run(1000.0, 10.0).unwrap_err().to_string();
    assert!(
        e.contains("models 'stretch_elementary' (model[0]) and 'stretch_cumulated' (model[1]) both set 'spring_k' in their init rules, to other values"),
        "{e}"
    );
    run(1000.0, 1000.0).unwrap();
    // a value of zero written is a value too (the elementary springs' default damping 0,
    // the cumulated ones' 0.1)
    let (g, _) = build(&tri, &BuildOptions::default()).unwrap();
    let cfg = Config {
        models: vec![
            model("stretch_elementary", &[]),
            model("stretch_cumulated", &[("damping", 0.1)]),
        ],
        ..Config::default()
    };
    let e = Simulation::new(g, cfg).unwrap_err().to_string();
    assert!(e.contains("both set 'spring_c'"), "{e}");
    let (g, _) = build(
        &cuboid([2, 1, 1], [1.0, 0.5, 0.5], BoxElement::Tetra),
        &BuildOptions::default(),
    )
    .unwrap();
    let cfg = Config {
        models: vec![model("neohookean", &[]), model("stvk", &[])],
        ..Config::default()
    };
    Simulation::new(g, cfg).unwrap();
}
