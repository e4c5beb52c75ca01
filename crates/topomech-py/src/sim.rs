//! `topomech._core.Simulation`: a physical simulation on a copy of a map, stepped from Python.
//!
//! The configuration arrives as a dict (or keyword arguments) mirroring
//! [`topomech_physics::Config`]; each key is checked here, by name, before the kernel sees it:
//! an unknown key or a value of the wrong kind is a `TypeError`, a value of the right kind
//! but out of range (a non-finite number, a vector of the wrong length, an unknown
//! integrator) a `ValueError`. What only the kernel can judge (an unknown model, a predicate
//! that selects nothing, a model that matches nothing on the mesh) is a `SimulationError`, and
//! a diverging step a `DivergenceError` naming the step and the vertex.
//!
//! Per-vertex arrays are in row order: row k is the particle numbered k by the map's
//! `particle` embedding (the input point order for a map built from a mesh; the vertex orbit
//! order, as `GMap.vertex_labels` numbers it, for a map without one). A row may be made of
//! several vertex orbits (a pinched input vertex kept as one particle): they share positions
//! and velocities, and masses and forces are summed over them. Topology changes append rows.

use std::collections::HashMap;

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList, PyString, PyTuple};
use topomech_gmap::{EmbeddingType, OrbitType, Value};
use topomech_physics::{
    is_additive, shipped_models, Blade, Config, Criterion, Csr, Cut, Fracture, Ground, Integrator,
    LinearSolver, MaterialRegion, ModelSpec, Preconditioner, Simulation, TimedEvent,
    TopologyChange,
};
use topomech_rules::Val;

use crate::convert::{array_arg, rows3_arg, rows_to_array, shape_str, type_name};
use crate::errors::{
    exclusive, guard, shared, type_error, value_error, Error, InternalError, Result,
};
use crate::gmap::{
    embedding_key, embedding_specs, orbit_values_arg, orbit_values_to_py, read_orbit_values,
    OrbitValuesPy, PyGMap,
};

/// The keys of a configuration, in the order of [`Config`]'s fields.
const CONFIG_KEYS: &[&str] = &[
    "models",
    "model_files",
    "density",
    "young",
    "poisson",
    "damping",
    "gravity",
    "fixed",
    "prescribed",
    "regions",
    "ground",
    "events",
    "fracture",
    "integrator",
    "dt",
    "linear_solver",
    "preconditioner",
    "tolerance",
    "max_iterations",
];

/// The linear solvers' names, as [`LinearSolver::parse`] reads them.
const LINEAR_SOLVERS: &[&str] = &["auto", "cg", "pcg", "direct"];

/// The preconditioners' names, as [`Preconditioner::parse`] reads them.
const PRECONDITIONERS: &[&str] = &["jacobi", "block_jacobi"];

/// An int >= 1 (not a bool): a `TypeError` for another type, a `ValueError` below 1.
fn count_arg(obj: &Bound<'_, PyAny>, what: &str) -> Result<usize> {
    if obj.is_instance_of::<PyBool>() || !obj.is_instance_of::<pyo3::types::PyInt>() {
        return Err(type_error(format!(
            "{what} must be an int, got {}",
            type_name(obj)
        )));
    }
    match obj.extract::<i64>() {
        Ok(v) if v >= 1 => Ok(usize::try_from(v).unwrap_or(usize::MAX)),
        Ok(v) => Err(value_error(format!("{what} must be at least 1, got {v}"))),
        Err(_) => Err(value_error(format!("{what} is out of range: {obj}"))),
    }
}

/// A kernel CSR matrix as numpy arrays `(indptr, indices, data, n)`.
#[allow(clippy::type_complexity)]
fn csr_to_py(
    py: Python<'_>,
    m: Csr,
) -> (
    Bound<'_, PyArray1<i64>>,
    Bound<'_, PyArray1<i64>>,
    Bound<'_, PyArray1<f64>>,
    usize,
) {
    let to_i64 = |v: Vec<usize>| v.into_iter().map(|x| x as i64).collect::<Vec<i64>>();
    (
        to_i64(m.indptr).into_pyarray(py),
        to_i64(m.indices).into_pyarray(py),
        m.data.into_pyarray(py),
        m.n,
    )
}

/// The fracture criteria, as `fracture`'s `criterion` names them.
const CRITERIA: &[&str] = &["stress", "strain"];

fn criterion_arg(name: &str, what: &str) -> Result<Criterion> {
    match name {
        "stress" => Ok(Criterion::Stress),
        "strain" => Ok(Criterion::Strain),
        _ => Err(value_error(format!(
            "{what}: unknown criterion '{name}' (expected one of {})",
            CRITERIA.join(", ")
        ))),
    }
}

/// The integrators' names, as [`Integrator::parse`] reads them.
const INTEGRATORS: &[&str] = &[
    "explicit_euler",
    "symplectic_euler",
    "implicit_euler",
    "static",
];

fn integrator_name(i: Integrator) -> &'static str {
    match i {
        Integrator::ExplicitEuler => "explicit_euler",
        Integrator::SymplecticEuler => "symplectic_euler",
        Integrator::ImplicitEuler => "implicit_euler",
        Integrator::Static => "static",
    }
}

/// A finite real: a Python int or float (or a numpy scalar), not a bool, nor a complex (a
/// numpy complex is a Python complex, whose conversion to float would drop its imaginary part
/// with only a warning: QA).
fn real_arg(obj: &Bound<'_, PyAny>, what: &str) -> Result<f64> {
    if obj.is_instance_of::<PyBool>()
        || obj.is_instance_of::<PyString>()
        || obj.is_instance_of::<pyo3::types::PyComplex>()
    {
        return Err(type_error(format!(
            "{what} must be a number, got {}",
            type_name(obj)
        )));
    }
    let x: f64 = obj.extract().map_err(|_| {
        // an int too large for a float is a number all the same: say so
        if obj.is_instance_of::<pyo3::types::PyInt>() {
            value_error(format!(
                "{what} is too large for a float (beyond about 1.8e308)"
            ))
        } else {
            type_error(format!("{what} must be a number, got {}", type_name(obj)))
        }
    })?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(value_error(format!("{what} must be finite, got {x}")))
    }
}

// A setting's value out of its range is a `ValueError`, like a non-finite one (`real_arg`):
// the same kind of bad value gives the same kind of exception.

/// `x` (a finite number) when it is > 0.
fn positive(x: f64, what: &str) -> Result<f64> {
    if x > 0.0 {
        Ok(x)
    } else {
        Err(value_error(format!("{what} must be positive, got {x}")))
    }
}

/// `x` (a finite number) when it is >= 0.
fn non_negative(x: f64, what: &str) -> Result<f64> {
    if x >= 0.0 {
        Ok(x)
    } else {
        Err(value_error(format!("{what} must be >= 0, got {x}")))
    }
}

/// `x` (a finite number) when it is a Poisson ratio, in (-1, 0.5).
fn poisson_ratio(x: f64, what: &str) -> Result<f64> {
    if -1.0 < x && x < 0.5 {
        Ok(x)
    } else {
        Err(value_error(format!("{what} must be in (-1, 0.5), got {x}")))
    }
}

/// A str.
fn str_arg(obj: &Bound<'_, PyAny>, what: &str) -> Result<String> {
    obj.cast::<PyString>()
        .map(ToString::to_string)
        .map_err(|_| type_error(format!("{what} must be a str, got {}", type_name(obj))))
}

/// The items of a list or tuple.
fn list_arg<'py>(obj: &Bound<'py, PyAny>, what: &str) -> Result<Vec<Bound<'py, PyAny>>> {
    if let Ok(l) = obj.cast::<PyList>() {
        return Ok(l.iter().collect());
    }
    if let Ok(t) = obj.cast::<PyTuple>() {
        return Ok(t.iter().collect());
    }
    Err(type_error(format!(
        "{what} must be a list, got {}",
        type_name(obj)
    )))
}

/// Three finite reals (a list, a tuple or a numpy array).
fn vec3_arg(obj: &Bound<'_, PyAny>, what: &str) -> Result<[f64; 3]> {
    if obj.is_instance_of::<PyString>() {
        return Err(type_error(format!(
            "{what} must be 3 numbers, got {}",
            type_name(obj)
        )));
    }
    let items: Vec<Bound<'_, PyAny>> = obj
        .try_iter()
        .map_err(|_| type_error(format!("{what} must be 3 numbers, got {}", type_name(obj))))?
        .collect::<PyResult<_>>()?;
    if items.len() != 3 {
        return Err(value_error(format!(
            "{what} must be 3 numbers, got {}",
            items.len()
        )));
    }
    let mut out = [0.0; 3];
    for (k, x) in items.iter().enumerate() {
        out[k] = real_arg(x, &format!("{what}[{k}]"))?;
    }
    Ok(out)
}

/// The entries of a dict with str keys.
fn dict_items<'py>(
    obj: &Bound<'py, PyAny>,
    what: &str,
) -> Result<Vec<(String, Bound<'py, PyAny>)>> {
    let d = obj
        .cast::<PyDict>()
        .map_err(|_| type_error(format!("{what} must be a dict, got {}", type_name(obj))))?;
    d.iter()
        .map(|(k, v)| {
            let k: String = k.extract().map_err(|_| {
                type_error(format!(
                    "{what} has a key that is not a str: {}",
                    type_name(&k)
                ))
            })?;
            Ok((k, v))
        })
        .collect()
}

/// A model: its kind alone (`"corotational"`), or a dict `{"kind": ..., param: value, ...}`
/// where a value is a real (an `f64` parameter) or 3 reals (a `vec3` one; the declaration's
/// type is checked when the simulation is built).
fn model_arg(obj: &Bound<'_, PyAny>, k: usize) -> Result<ModelSpec> {
    let what = format!("models[{k}]");
    if obj.is_instance_of::<PyString>() {
        return Ok(ModelSpec {
            kind: str_arg(obj, &what)?,
            params: HashMap::new(),
        });
    }
    if !obj.is_instance_of::<PyDict>() {
        return Err(type_error(format!(
            "{what} must be a model kind (str) or a dict with 'kind' and parameters, got {}",
            type_name(obj)
        )));
    }
    let mut kind = None;
    let mut params = HashMap::new();
    for (key, v) in dict_items(obj, &what)? {
        if key == "kind" {
            kind = Some(str_arg(&v, &format!("{what}['kind']"))?);
        } else if key == "file" {
            return Err(type_error(format!(
                "{what}['file']: a model from a rule file is given as topomech.Model.load(path) (optionally .with_params(...)), not as a dict"
            )));
        } else {
            let at = format!("{what}['{key}']");
            if v.is_instance_of::<PyDict>() {
                return Err(type_error(format!(
                    "{at}: a model parameter is a real or 3 reals, got dict; parameters go in the model's dict itself ({{\"kind\": ..., \"stiffness\": 1e3}}), not under a key of their own"
                )));
            }
            let x = if v.is_instance_of::<PyString>() || v.is_instance_of::<PyBool>() {
                Val::F(real_arg(&v, &at)?)
            } else if v.try_iter().is_ok() {
                Val::V3(vec3_arg(&v, &at)?)
            } else {
                Val::F(real_arg(&v, &at)?)
            };
            params.insert(key, x);
        }
    }
    let kind = kind.ok_or_else(|| value_error(format!("{what} has no 'kind'")))?;
    Ok(ModelSpec { kind, params })
}

/// A prescribed displacement: `(predicate, [dx, dy, dz])` or `{"where": ..., "displacement": ...}`.
fn prescribed_arg(obj: &Bound<'_, PyAny>, k: usize) -> Result<(String, [f64; 3])> {
    let what = format!("prescribed[{k}]");
    if obj.is_instance_of::<PyDict>() {
        let mut pred = None;
        let mut disp = None;
        for (key, v) in dict_items(obj, &what)? {
            match key.as_str() {
                "where" => pred = Some(str_arg(&v, &format!("{what}['where']"))?),
                "displacement" => disp = Some(vec3_arg(&v, &format!("{what}['displacement']"))?),
                _ => {
                    return Err(type_error(format!(
                        "{what} has an unknown key '{key}' (known: where, displacement)"
                    )))
                }
            }
        }
        return match (pred, disp) {
            (Some(p), Some(d)) => Ok((p, d)),
            _ => Err(value_error(format!(
                "{what} needs both 'where' and 'displacement'"
            ))),
        };
    }
    let items = list_arg(obj, &what).map_err(|_| {
        type_error(format!(
            "{what} must be (predicate, [dx, dy, dz]) or a dict with 'where' and 'displacement', got {}",
            type_name(obj)
        ))
    })?;
    if items.len() != 2 {
        return Err(value_error(format!(
            "{what} must be (predicate, [dx, dy, dz]), got {} items",
            items.len()
        )));
    }
    Ok((
        str_arg(&items[0], &format!("{what}[0]"))?,
        vec3_arg(&items[1], &format!("{what}[1]"))?,
    ))
}

/// A material region: `{"where": ..., "density": ..., "young": ..., "poisson": ...}`.
fn region_arg(obj: &Bound<'_, PyAny>, k: usize) -> Result<MaterialRegion> {
    let what = format!("regions[{k}]");
    let mut r = MaterialRegion::default();
    let mut pred = None;
    for (key, v) in dict_items(obj, &what)? {
        let w = format!("{what}['{key}']");
        match key.as_str() {
            "where" => pred = Some(str_arg(&v, &w)?),
            "density" => r.density = Some(positive(real_arg(&v, &w)?, &w)?),
            "young" => r.young = Some(positive(real_arg(&v, &w)?, &w)?),
            "poisson" => r.poisson = Some(poisson_ratio(real_arg(&v, &w)?, &w)?),
            _ => {
                return Err(type_error(format!(
                    "{what} has an unknown key '{key}' (known: where, density, young, poisson)"
                )))
            }
        }
    }
    r.predicate = pred.ok_or_else(|| value_error(format!("{what} has no 'where'")))?;
    Ok(r)
}

/// A cut plane: `{"normal": [nx, ny, nz], "offset": o}` (a non-zero normal).
fn plane_arg(obj: &Bound<'_, PyAny>, what: &str) -> Result<Cut> {
    let mut normal = None;
    let mut offset = None;
    for (key, v) in dict_items(obj, what)? {
        let w = format!("{what}['{key}']");
        match key.as_str() {
            "normal" => normal = Some(vec3_arg(&v, &w)?),
            "offset" => offset = Some(real_arg(&v, &w)?),
            _ => {
                return Err(type_error(format!(
                    "{what} has an unknown key '{key}' (known: normal, offset)"
                )))
            }
        }
    }
    let (Some(normal), Some(offset)) = (normal, offset) else {
        return Err(value_error(format!(
            "{what} needs both 'normal' and 'offset'"
        )));
    };
    plane_cut(normal, offset, what)
}

/// The plane `normal . x = offset`, refusing a zero normal.
fn plane_cut(normal: [f64; 3], offset: f64, what: &str) -> Result<Cut> {
    if normal.iter().all(|x| *x == 0.0) {
        return Err(value_error(format!("{what}: the normal must not be zero")));
    }
    Ok(Cut::Plane { normal, offset })
}

/// A timed event: `{"time": t, "kind": "cut", "plane": {"normal": [..], "offset": o}}` or
/// `{"time": t, "kind": "cut", "where": predicate}`.
fn event_arg(obj: &Bound<'_, PyAny>, k: usize) -> Result<TimedEvent> {
    let what = format!("events[{k}]");
    // the kind first: a misspelled kind is said as such, not as the keys of another kind
    if let Ok(d) = obj.cast::<PyDict>() {
        if let Some(kind) = d.get_item("kind")? {
            let kind = str_arg(&kind, &format!("{what}['kind']"))?;
            if kind != "cut" {
                return Err(value_error(format!(
                    "{what}['kind']: unknown event kind '{kind}' (expected 'cut' or 'blade')"
                )));
            }
        }
    }
    let mut time = None;
    let mut kind = None;
    let mut plane = None;
    let mut pred = None;
    for (key, v) in dict_items(obj, &what)? {
        let w = format!("{what}['{key}']");
        match key.as_str() {
            "time" => time = Some(real_arg(&v, &w)?),
            "kind" => kind = Some(str_arg(&v, &w)?),
            "plane" => plane = Some(plane_arg(&v, &w)?),
            "where" => pred = Some(str_arg(&v, &w)?),
            _ => {
                return Err(type_error(format!(
                    "{what} has an unknown key '{key}' (known: time, kind, plane, where)"
                )))
            }
        }
    }
    let time = time.ok_or_else(|| value_error(format!("{what} has no 'time'")))?;
    if time < 0.0 {
        return Err(value_error(format!(
            "{what}['time'] must be >= 0, got {time}"
        )));
    }
    match kind.as_deref() {
        Some("cut") => {}
        Some(other) => {
            return Err(value_error(format!(
                "{what}['kind']: unknown event kind '{other}' (expected 'cut' or 'blade')"
            )))
        }
        None => {
            return Err(value_error(format!(
                "{what} has no 'kind' (expected 'cut' or 'blade')"
            )))
        }
    }
    let cut = match (plane, pred) {
        (Some(p), None) => p,
        (None, Some(p)) => Cut::Where(p),
        (Some(_), Some(_)) => {
            return Err(value_error(format!(
                "{what} has both 'plane' and 'where': give one"
            )))
        }
        (None, None) => {
            return Err(value_error(format!(
                "{what} has no geometry: give 'plane' ({{\"normal\": [..], \"offset\": ..}}) or 'where' (a predicate)"
            )))
        }
    };
    Ok(TimedEvent { time, cut })
}

/// Whether an `events` entry is a dict whose `kind` is `"blade"`.
fn is_blade(obj: &Bound<'_, PyAny>) -> bool {
    obj.cast::<PyDict>().is_ok_and(|d| {
        d.get_item("kind")
            .ok()
            .flatten()
            .is_some_and(|k| k.extract::<String>().is_ok_and(|k| k == "blade"))
    })
}

/// Two points, a blade's segment: `[[x, y, z], [x, y, z]]`.
fn segment_arg(obj: &Bound<'_, PyAny>, what: &str) -> Result<[[f64; 3]; 2]> {
    let bad = || {
        type_error(format!(
            "{what} must be 2 points [[x, y, z], [x, y, z]], got {}",
            type_name(obj)
        ))
    };
    if obj.is_instance_of::<PyString>() {
        return Err(bad());
    }
    let items: Vec<Bound<'_, PyAny>> = obj
        .try_iter()
        .map_err(|_| bad())?
        .collect::<PyResult<_>>()?;
    if items.len() != 2 {
        return Err(value_error(format!(
            "{what} must be 2 points [[x, y, z], [x, y, z]], got {} items",
            items.len()
        )));
    }
    Ok([
        vec3_arg(&items[0], &format!("{what}[0]"))?,
        vec3_arg(&items[1], &format!("{what}[1]"))?,
    ])
}

/// A blade: `{"kind": "blade", "start": t0, "end": t1, "from": [[..], [..]], "to": [[..], [..]]}`.
fn blade_arg(obj: &Bound<'_, PyAny>, k: usize) -> Result<Blade> {
    let what = format!("events[{k}]");
    let (mut start, mut end, mut from, mut to) = (None, None, None, None);
    for (key, v) in dict_items(obj, &what)? {
        let w = format!("{what}['{key}']");
        match key.as_str() {
            "kind" => {}
            "start" => start = Some(real_arg(&v, &w)?),
            "end" => end = Some(real_arg(&v, &w)?),
            "from" => from = Some(segment_arg(&v, &w)?),
            "to" => to = Some(segment_arg(&v, &w)?),
            _ => {
                return Err(type_error(format!(
                "{what} (a blade) has an unknown key '{key}' (known: kind, start, end, from, to)"
            )))
            }
        }
    }
    let missing = |key: &str| value_error(format!("{what} (a blade) has no '{key}'"));
    let blade = Blade {
        start: start.ok_or_else(|| missing("start"))?,
        end: end.ok_or_else(|| missing("end"))?,
        from: from.ok_or_else(|| missing("from"))?,
        to: to.ok_or_else(|| missing("to"))?,
    };
    if let Some(why) = blade.problem() {
        return Err(value_error(format!("{what} (a blade): {why}")));
    }
    Ok(blade)
}

/// Fracture settings: `{"criterion": "stress" | "strain", "threshold": x}`.
fn fracture_arg(obj: &Bound<'_, PyAny>) -> Result<Fracture> {
    let what = "fracture";
    let mut criterion = None;
    let mut threshold = None;
    for (key, v) in dict_items(obj, what)? {
        let w = format!("{what}['{key}']");
        match key.as_str() {
            "criterion" => criterion = Some(criterion_arg(&str_arg(&v, &w)?, &w)?),
            "threshold" => threshold = Some(real_arg(&v, &w)?),
            _ => {
                return Err(type_error(format!(
                    "{what} has an unknown key '{key}' (known: criterion, threshold)"
                )))
            }
        }
    }
    let (Some(criterion), Some(threshold)) = (criterion, threshold) else {
        return Err(value_error(format!(
            "{what} needs both 'criterion' and 'threshold'"
        )));
    };
    Ok(Fracture {
        criterion,
        threshold,
    })
}

/// A topology change as a dict `{"step", "time", "kind", "unsewn"}`.
fn change_dict<'py>(py: Python<'py>, c: &TopologyChange) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("step", c.step)?;
    d.set_item("time", c.time)?;
    d.set_item("kind", c.kind)?;
    d.set_item("unsewn", c.unsewn)?;
    Ok(d)
}

/// `ground`: None, a height along the up direction (a number), or `{"point": [x, y, z],
/// "normal": [nx, ny, nz]}` (`normal` optional: the opposite of gravity).
fn ground_arg(v: &Bound<'_, PyAny>) -> Result<Option<Ground>> {
    if v.is_none() {
        return Ok(None);
    }
    if !v.is_instance_of::<PyDict>() {
        return Ok(Some(Ground::Height(real_arg(v, "ground")?)));
    }
    let mut point = None;
    let mut normal = None;
    for (key, x) in dict_items(v, "ground")? {
        match key.as_str() {
            "point" => point = Some(vec3_arg(&x, "ground.point")?),
            "normal" => {
                normal = if x.is_none() {
                    None
                } else {
                    Some(vec3_arg(&x, "ground.normal")?)
                }
            }
            other => {
                return Err(type_error(format!(
                    "ground.{other}: unknown key (known: point, normal)"
                )))
            }
        }
    }
    let point = point.ok_or_else(|| {
        value_error("ground.point: missing (a point [x, y, z] of the ground plane)".to_string())
    })?;
    Ok(Some(Ground::Plane { point, normal }))
}

/// A user's model file: `(file name, text)`, the name shown in diagnostics.
fn model_file_arg(obj: &Bound<'_, PyAny>, i: usize) -> Result<(String, String)> {
    let what = format!("model_files[{i}]");
    let items = list_arg(obj, &what)
        .ok()
        .filter(|t| t.len() == 2)
        .ok_or_else(|| {
            type_error(format!(
                "{what} must be a (file name, text) pair of str, got {}",
                type_name(obj)
            ))
        })?;
    Ok((
        str_arg(&items[0], &format!("{what}[0]"))?,
        str_arg(&items[1], &format!("{what}[1]"))?,
    ))
}

/// The value of the string `obj` named in `names`, parsed by `parse`; `TypeError` for a
/// non-string, `ValueError` naming the key `what` and the allowed names otherwise.
fn choice_arg<T>(
    obj: &Bound<'_, PyAny>,
    what: &str,
    parse: impl Fn(&str) -> Option<T>,
    names: &[&str],
) -> Result<T> {
    let name = str_arg(obj, what)?;
    parse(&name).ok_or_else(|| {
        value_error(format!(
            "unknown {what} '{name}': expected one of {}",
            names.join(", ")
        ))
    })
}

/// A [`Config`] from `{key: value}` entries (unset keys keep [`Config::default`]).
fn config_arg(entries: &[(String, Bound<'_, PyAny>)]) -> Result<Config> {
    let mut cfg = Config::default();
    for (key, v) in entries {
        let k = key.as_str();
        // a key given None keeps its default (as `ground=None`, `fracture=None` always did)
        if v.is_none() && CONFIG_KEYS.contains(&k) {
            continue;
        }
        match k {
            "models" => {
                cfg.models = list_arg(v, k)?
                    .iter()
                    .enumerate()
                    .map(|(i, m)| model_arg(m, i))
                    .collect::<Result<_>>()?;
            }
            "model_files" => {
                cfg.model_files = list_arg(v, k)?
                    .iter()
                    .enumerate()
                    .map(|(i, f)| model_file_arg(f, i))
                    .collect::<Result<_>>()?;
            }
            "density" => cfg.density = positive(real_arg(v, k)?, k)?,
            "young" => cfg.young = positive(real_arg(v, k)?, k)?,
            "poisson" => cfg.poisson = poisson_ratio(real_arg(v, k)?, k)?,
            "damping" => cfg.damping = non_negative(real_arg(v, k)?, k)?,
            "dt" => cfg.dt = positive(real_arg(v, k)?, k)?,
            "gravity" => cfg.gravity = vec3_arg(v, k)?,
            "ground" => cfg.ground = ground_arg(v)?,
            "fixed" => {
                cfg.fixed = if v.is_instance_of::<PyString>() {
                    vec![str_arg(v, k)?]
                } else {
                    list_arg(v, k)?
                        .iter()
                        .enumerate()
                        .map(|(i, p)| str_arg(p, &format!("fixed[{i}]")))
                        .collect::<Result<_>>()?
                };
            }
            "prescribed" => {
                cfg.prescribed = list_arg(v, k)?
                    .iter()
                    .enumerate()
                    .map(|(i, p)| prescribed_arg(p, i))
                    .collect::<Result<_>>()?;
            }
            "regions" => {
                cfg.regions = list_arg(v, k)?
                    .iter()
                    .enumerate()
                    .map(|(i, r)| region_arg(r, i))
                    .collect::<Result<_>>()?;
            }
            "events" => {
                for (i, e) in list_arg(v, k)?.iter().enumerate() {
                    if is_blade(e) {
                        cfg.blades.push(blade_arg(e, i)?);
                    } else {
                        cfg.events.push(event_arg(e, i)?);
                    }
                }
            }
            "fracture" => {
                cfg.fracture = if v.is_none() {
                    None
                } else {
                    Some(fracture_arg(v)?)
                };
            }
            "integrator" => cfg.integrator = choice_arg(v, k, Integrator::parse, INTEGRATORS)?,
            "linear_solver" => {
                cfg.linear_solver = choice_arg(v, k, LinearSolver::parse, LINEAR_SOLVERS)?;
            }
            "preconditioner" => {
                cfg.preconditioner = choice_arg(v, k, Preconditioner::parse, PRECONDITIONERS)?;
            }
            "tolerance" => {
                let t = real_arg(v, k)?;
                if !(t > 0.0 && t < 1.0) {
                    return Err(value_error(format!(
                        "tolerance must be a relative residual in (0, 1), got {t}"
                    )));
                }
                cfg.tolerance = Some(t);
            }
            "max_iterations" => cfg.max_iterations = Some(count_arg(v, k)?),
            _ => {
                return Err(type_error(format!(
                    "unknown configuration key '{k}' (known: {})",
                    CONFIG_KEYS.join(", ")
                )))
            }
        }
    }
    Ok(cfg)
}

/// The map behind `obj` (see [`crate::rules::gmap_core`]), copied.
fn gmap_copy_arg(obj: &Bound<'_, PyAny>) -> PyResult<topomech_gmap::GMap> {
    let core = crate::rules::gmap_core(obj)?;
    let g = shared(&core)?;
    Ok(g.map()?.clone())
}

/// A physical simulation of a map: the models of the configuration, summed, stepped by its
/// integrator. The simulation owns a copy of the map; read it back with `gmap()`.
///
/// `config` (or keyword arguments, not both for one key): `models` (a list of kinds or of
/// dicts `{"kind": ..., param: value}`), `density`, `young`, `poisson`, `damping`, `dt`
/// (numbers), `gravity` (3 numbers), `fixed` (predicates on the rest position `x`, `y`, `z`),
/// `prescribed` (`(predicate, [dx, dy, dz])` pairs), `regions` (dicts with `where` and any of
/// `density`, `young`, `poisson`), `ground` (None, a height along the opposite of gravity, or
/// `{"point": [x, y, z], "normal": [nx, ny, nz]}`, the normal defaulting to the opposite of
/// gravity), `integrator`
/// (`explicit_euler`, `symplectic_euler`, `implicit_euler` or `static`), `events` (timed
/// topology changes: dicts `{"time": t, "kind": "cut", "plane": {"normal": [..], "offset":
/// o}}` or `{"time": t, "kind": "cut", "where": predicate on the centroid of the shared face
/// or edge}`), `fracture` (`{"criterion": "stress" | "strain", "threshold": x}`, or None).
///
/// Raises `TypeError` for a value of the wrong type or an unknown key, `ValueError` for a
/// value that is not finite or out of its range (`dt`, `density`, `young` > 0, `poisson` in
/// (-1, 0.5), `damping` >= 0; NaN, an infinity and a negative `dt` alike) and
/// `SimulationError` for a configuration the kernel refuses.
#[pyclass(name = "Simulation", module = "topomech._core")]
pub(crate) struct PySimulation {
    inner: Simulation,
    /// Set when a panic interrupted a step: the state is then unknown, and every later call
    /// refuses with `InternalError`.
    poisoned: bool,
}

impl PySimulation {
    fn sim(&self) -> PyResult<&Simulation> {
        if self.poisoned {
            Err(InternalError::new_err(
                "this simulation was left in an unknown state by an earlier internal error and cannot be used",
            ))
        } else {
            Ok(&self.inner)
        }
    }

    /// Runs `f` on the simulation without the GIL; a panic poisons the simulation.
    fn run<T: Send>(
        &mut self,
        py: Python<'_>,
        f: impl FnOnce(&mut Simulation) -> Result<T> + Send,
    ) -> PyResult<T> {
        self.sim()?;
        let inner = &mut self.inner;
        let r = py.detach(|| guard(|| f(inner)));
        if r.as_ref()
            .is_err_and(|e| e.is_instance_of::<InternalError>(py))
        {
            self.poisoned = true;
        }
        r
    }

    /// Reads the simulation through `f`, a panic becoming `InternalError`.
    fn read<T>(&self, f: impl FnOnce(&Simulation) -> Result<T>) -> PyResult<T> {
        let sim = self.sim()?;
        guard(|| f(sim))
    }

    /// Sets a vec3 vertex embedding from a float64 `(V, 3)` array of finite values.
    fn set_vec3(
        &mut self,
        py: Python<'_>,
        name: &'static str,
        what: &str,
        values: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let n = self.sim()?.n_vertices();
        let rows = guard(|| {
            let rows = rows3_arg(values, what, "V")?;
            if rows.len() != n {
                return Err(value_error(format!(
                    "{what} must have shape (V, 3) = ({n}, 3), got ({}, 3)",
                    rows.len()
                )));
            }
            if let Some(k) = rows.iter().position(|r| r.iter().any(|x| !x.is_finite())) {
                return Err(value_error(format!(
                    "{what} must be finite: row {k} is {:?}",
                    rows[k]
                )));
            }
            Ok(rows)
        })?;
        self.run(py, |sim| {
            if name == "velocity" {
                // a held vertex keeps zero velocity
                Ok(sim.set_velocities(&rows)?)
            } else {
                Ok(sim.set_vertex_vec3(name, &rows)?)
            }
        })
    }
}

#[pymethods]
impl PySimulation {
    #[new]
    #[pyo3(signature = (gmap, config = None, **kwargs))]
    fn new(
        py: Python<'_>,
        gmap: &Bound<'_, PyAny>,
        config: Option<&Bound<'_, PyAny>>,
        kwargs: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let g = gmap_copy_arg(gmap)?;
        let cfg = guard(|| {
            let mut entries = match config {
                None => Vec::new(),
                Some(c) if c.is_none() => Vec::new(),
                Some(c) => dict_items(c, "config")?,
            };
            if let Some(kw) = kwargs {
                for (k, v) in dict_items(kw.as_any(), "keyword arguments")? {
                    if entries.iter().any(|(e, _)| *e == k) {
                        return Err(type_error(format!(
                            "'{k}' is given both in config and as a keyword argument"
                        )));
                    }
                    entries.push((k, v));
                }
            }
            config_arg(&entries)
        })?;
        let inner = py.detach(move || guard(|| Ok(Simulation::new(g, cfg)?)))?;
        Ok(PySimulation {
            inner,
            poisoned: false,
        })
    }

    /// Sets the external loads `f_ext` from a float64 `(V, 3)` array of finite values (N, in
    /// vertex order): constant forces added to the models' forces every step and balanced by
    /// the static solve.
    fn set_external_forces(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        forces: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        let n = this.sim()?.vertex_darts().len();
        let rows = guard(|| {
            let rows = rows3_arg(forces, "forces", "V")?;
            if rows.len() != n {
                return Err(value_error(format!(
                    "forces must have shape (V, 3) = ({n}, 3), got ({}, 3)",
                    rows.len()
                )));
            }
            if let Some(k) = rows.iter().position(|r| r.iter().any(|x| !x.is_finite())) {
                return Err(value_error(format!(
                    "forces must be finite: row {k} is {:?}",
                    rows[k]
                )));
            }
            Ok(rows)
        })?;
        this.run(py, |sim| Ok(sim.set_external_forces(&rows)?))
    }

    /// The external loads `f_ext` `(V, 3)` (N).
    fn external_forces<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let this = shared(slf)?;
        let rows = this.read(|s| Ok(s.external_forces()?))?;
        guard(|| rows_to_array(py, &rows))
    }

    /// Runs `n` time steps. On divergence raises `DivergenceError` (with `step`, `vertex` and
    /// `why`); the state is then the one before the failed step. Ctrl-C stops between steps.
    #[pyo3(signature = (n = 1))]
    fn step(slf: &Bound<'_, Self>, py: Python<'_>, n: i64) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        let n = u64::try_from(n)
            .map_err(|_| PyErr::from(value_error(format!("n must be >= 0, got {n}"))))?;
        for _ in 0..n {
            this.run(py, |sim| Ok(sim.step()?))?;
            py.check_signals()?;
        }
        Ok(())
    }

    /// Cuts now along the plane `normal . x = offset`: every face (3D) or edge (2D) between
    /// two elements whose centroids lie on opposite sides is unsewn, and the vertices on it
    /// split (a centroid whose distance is within 1e-12 of the other's is on the plane).
    /// Returns how many faces or edges were unsewn (0 when the plane misses the object:
    /// nothing changes then) and the rows appended, int64 (k,) (existing rows keep their
    /// meaning).
    fn cut<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
        normal: &Bound<'_, PyAny>,
        offset: &Bound<'_, PyAny>,
    ) -> PyResult<(usize, Bound<'py, PyArray1<i64>>)> {
        let mut this = exclusive(slf)?;
        let cut = guard(|| {
            let normal = vec3_arg(normal, "normal")?;
            let offset = real_arg(offset, "offset")?;
            plane_cut(normal, offset, "normal")
        })?;
        let r = this.run(py, move |sim| Ok(sim.cut(&cut)?))?;
        Ok((r.unsewn, rows_i64(&r.added_rows).into_pyarray(py)))
    }

    /// Cuts now along the quad swept by a blade moving from the segment `start` to the
    /// segment `end` (each 2 points, `[[x, y, z], [x, y, z]]`): unsews every face (3D) or edge
    /// (2D) between two elements whose centroids the quad separates. Returns how many and
    /// the rows appended for the vertices that split, int64 (k,). Raises `ValueError` for
    /// points that are not 2 finite 3-vectors.
    fn cut_swept<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
        start: &Bound<'_, PyAny>,
        end: &Bound<'_, PyAny>,
    ) -> PyResult<(usize, Bound<'py, PyArray1<i64>>)> {
        let mut this = exclusive(slf)?;
        let (from, to) = guard(|| Ok((segment_arg(start, "start")?, segment_arg(end, "end")?)))?;
        let r = this.run(py, move |sim| Ok(sim.cut_swept(from, to)?))?;
        Ok((r.unsewn, rows_i64(&r.added_rows).into_pyarray(py)))
    }

    /// Builds now what cuts search the faces (3D) or edges (2D) with: the compiled guards of
    /// the plane cut and the blade, which cuts then only run and patch. Cuts give the same
    /// results either way, bit for bit.
    fn prepare_cuts(slf: &Bound<'_, Self>, py: Python<'_>) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        this.run(py, move |sim| Ok(sim.prepare_cuts()?))
    }

    /// Opens now every face (3D) or edge (2D) where the criterion exceeds the threshold:
    /// `stress` (the mean largest principal stress of the two tetrahedra, Pa; 3D, with the
    /// FEM rules: a stress `fracture` or an FEM model) or `strain` (spring strain
    /// l / l0 - 1). Returns how many faces or edges were opened and the rows appended, int64
    /// (k,).
    fn fracture<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
        criterion: &Bound<'_, PyAny>,
        threshold: &Bound<'_, PyAny>,
    ) -> PyResult<(usize, Bound<'py, PyArray1<i64>>)> {
        let mut this = exclusive(slf)?;
        let f = guard(|| {
            let criterion = criterion_arg(&str_arg(criterion, "criterion")?, "criterion")?;
            let threshold = real_arg(threshold, "threshold")?;
            Ok(Fracture {
                criterion,
                threshold,
            })
        })?;
        let r = this.run(py, move |sim| Ok(sim.fracture(f)?))?;
        Ok((r.unsewn, rows_i64(&r.added_rows).into_pyarray(py)))
    }

    /// What the solve of the last static or implicit Euler step did, as a dict:
    /// `integrator`, `iterations` (Newton iterations over every load increment, or
    /// conjugate-gradient iterations), `residual`, `relative_residual` (to the load),
    /// `tolerance`, `converged`, `load_steps` (the load increments taken), `load_fraction`
    /// (reached), `worst_relative_residual` (over every step so far), `not_converged_steps`
    /// (steps so far that did not reach their tolerance) and `load_stepped_steps`
    /// (steps that needed more than one increment), `linear_solver` (`cg`, `pcg` or `direct`:
    /// what `auto` chose), `preconditioner` (`jacobi`, `block_jacobi`, or `none` for `cg` and
    /// `direct`), `linear_iterations` (iterations of the iterative linear solver over the
    /// step, 0 for `direct`) and `jacobian` (`rules`, or `finite_differences` for a static
    /// solve that the models' `jvp` rules did not bring to balance and that was taken again
    /// on central differences of the forces); None before the first such step and for the explicit
    /// integrators. After a failed step it describes the failure.
    fn solver_report<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(r) = shared(slf)?.read(|s| Ok(s.solver_report().cloned()))? else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("integrator", r.integrator)?;
        d.set_item("iterations", r.iterations)?;
        d.set_item("residual", r.residual)?;
        d.set_item("relative_residual", r.relative_residual)?;
        d.set_item("tolerance", r.tolerance)?;
        d.set_item("converged", r.converged)?;
        d.set_item("load_steps", r.load_steps)?;
        d.set_item("load_fraction", r.load_fraction)?;
        d.set_item("worst_relative_residual", r.worst_relative_residual)?;
        d.set_item("load_stepped_steps", r.load_stepped_steps)?;
        d.set_item("not_converged_steps", r.not_converged_steps)?;
        d.set_item("linear_solver", r.linear_solver)?;
        d.set_item("preconditioner", r.preconditioner)?;
        d.set_item("linear_iterations", r.linear_iterations)?;
        d.set_item("jacobian", r.jacobian)?;
        Ok(Some(d))
    }

    /// The stiffness matrix K = -df/dx at the current positions and velocities, assembled
    /// from the models' Jacobian-vector product rules (compressed probing, Curtis, Powell &
    /// Reid 1974): `(indptr, indices, data, n)` of a CSR matrix, `n = 3 V`, degree of freedom
    /// `3 i + a` being component `a` of row (vertex) `i`, fixed vertices included (no
    /// boundary condition applied), column indices sorted per row; int64, int64, float64
    /// arrays, N/m. Symmetric for the shipped models. Raises `SimulationError` when the
    /// models' rules cannot be assembled by probing (a jvp rule reaching vertices its
    /// matches do not name), or a rule fails.
    #[allow(clippy::type_complexity)]
    fn stiffness_matrix<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<f64>>,
        usize,
    )> {
        let mut this = exclusive(slf)?;
        let m = this.run(py, |sim| Ok(sim.stiffness_matrix()?))?;
        Ok(csr_to_py(py, m))
    }

    /// The lumped mass matrix: `(indptr, indices, data, n)` of a diagonal CSR matrix as
    /// `stiffness_matrix` gives (same order), each vertex's mass (kg) on its 3 degrees of
    /// freedom.
    #[allow(clippy::type_complexity)]
    fn mass_matrix<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<(
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, PyArray1<f64>>,
        usize,
    )> {
        let mut this = exclusive(slf)?;
        let m = this.run(py, |sim| Ok(sim.mass_matrix()?))?;
        Ok(csr_to_py(py, m))
    }

    /// The topology changes so far, in order: dicts `{"step": after which step, "time",
    /// "kind": "cut" | "fracture", "unsewn": faces (3D) or edges (2D) unsewn}`.
    fn topology_changes<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let this = shared(slf)?;
        let changes = this.read(|s| Ok(s.topology_changes().to_vec()))?;
        changes.iter().map(|c| change_dict(py, c)).collect()
    }

    /// Current positions, float64 (V, 3).
    fn positions<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let this = shared(slf)?;
        let rows = this.read(|s| Ok(s.vertex_vec3("position")?))?;
        guard(|| rows_to_array(py, &rows))
    }

    /// Current velocities, float64 (V, 3).
    fn velocities<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let this = shared(slf)?;
        let rows = this.read(|s| Ok(s.vertex_vec3("velocity")?))?;
        guard(|| rows_to_array(py, &rows))
    }

    /// Rest positions (the positions when the simulation was built), float64 (V, 3).
    fn rest_positions<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let this = shared(slf)?;
        let rows = this.read(|s| Ok(s.vertex_vec3("rest")?))?;
        guard(|| rows_to_array(py, &rows))
    }

    /// The models' forces on each vertex at the current state (without gravity and viscous
    /// damping), float64 (V, 3), summed over a row's orbits. Computes them now.
    fn forces<'py>(slf: &Bound<'_, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let mut this = exclusive(slf)?;
        let rows = this.run(py, |s| {
            s.forces()?;
            Ok(s.vertex_vec3_sum("force")?)
        })?;
        guard(|| rows_to_array(py, &rows))
    }

    /// Lumped vertex masses, float64 (V,), summed over a row's orbits.
    fn masses<'py>(slf: &Bound<'_, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let this = shared(slf)?;
        Ok(this
            .read(|s| Ok(s.vertex_scalar_sum("mass")?))?
            .into_pyarray(py))
    }

    /// The input point index of each row, int64 (V,) (-1 for none).
    fn point_ids<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray1<i64>>> {
        let this = shared(slf)?;
        Ok(this.read(|s| Ok(s.point_ids()?))?.into_pyarray(py))
    }

    /// Every element (volume in 3D, face in 2D), in the order of its smallest dart: the
    /// `cell_id`s, int64 (E,) (-1 when unknown), and each element's vertex rows, int64 arrays.
    #[allow(clippy::type_complexity)]
    fn elements<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyArray1<i64>>, Vec<Bound<'py, PyArray1<i64>>>)> {
        let this = shared(slf)?;
        let elements = this.read(|s| Ok(s.elements()?))?;
        let ids: Vec<i64> = elements.iter().map(|e| e.cell_id).collect();
        let rows = elements
            .iter()
            .map(|e| rows_i64(&e.rows).into_pyarray(py))
            .collect();
        Ok((ids.into_pyarray(py), rows))
    }

    /// Holds the rows where `mask` (bool (V,)) is true, frees the others.
    fn set_fixed(slf: &Bound<'_, Self>, py: Python<'_>, mask: &Bound<'_, PyAny>) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        let n = this.sim()?.n_vertices();
        let mask = guard(|| {
            let a = array_arg::<bool>(mask, "mask", "bool")?;
            if a.shape() != [n] {
                return Err(value_error(format!(
                    "mask must have shape (V,) = ({n},), got {}",
                    shape_str(a.shape())
                )));
            }
            Ok(a.as_array().iter().copied().collect::<Vec<bool>>())
        })?;
        this.run(py, move |sim| Ok(sim.set_fixed(&mask)?))
    }

    /// Writes a vertex embedding from one value per row: float64 (V,) for `f64`, float64
    /// (V, 3) for `vec3`, bool (V,) for `bool` (every orbit of a row gets its row's value; a
    /// force, `f_*`, goes to the row's first orbit alone: it is the row's total). For a
    /// writable vertex embedding (held by the map, or declared by the rules) the values are
    /// checked against its type here: booleans for a number embedding, or numbers for a bool
    /// one, are a `TypeError` naming the embedding's type; a wrong shape a `ValueError` naming
    /// the shape that type takes, `(V, 3)` or `(V,)`. The other cases (unknown, derived or
    /// non-vertex embeddings, other types) are the kernel's `SimulationError`.
    fn set_vertex_field(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        name: &str,
        values: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        use numpy::{PyArrayDescrMethods as _, PyUntypedArray};

        let mut this = exclusive(slf)?;
        let sim = this.sim()?;
        let n = sim.n_vertices();
        // the type of `name` when the kernel would write it: a stored, not derived vertex
        // embedding of type f64, vec3 or bool, or one the rules declare so (added on writing)
        let vertex = OrbitType::vertex(sim.gmap().dimension());
        let ty = match sim.gmap().embedding_id(name) {
            Some(id) => {
                let e = sim.gmap().embedding(id);
                (e.orbit() == vertex && e.derived().is_none()).then(|| e.ty())
            }
            None => sim
                .rules()
                .embeddings()
                .iter()
                .find(|e| e.name == name && e.orbit == vertex && e.derived.is_none())
                .and_then(|e| match e.ty {
                    topomech_rules::Ty::F64 => Some(EmbeddingType::F64),
                    topomech_rules::Ty::Vec3 => Some(EmbeddingType::Vec3),
                    topomech_rules::Ty::Bool => Some(EmbeddingType::Bool),
                    _ => None,
                }),
        }
        .filter(|t| {
            matches!(
                t,
                EmbeddingType::F64 | EmbeddingType::Vec3 | EmbeddingType::Bool
            )
        });
        let values = guard(|| {
            let Some(ty) = ty else {
                // the kernel refuses the name whatever the values: the generic conversion
                let shape_err = |shape: &[usize]| {
                    value_error(format!(
                        "values for '{name}' must have shape (V,) or (V, 3) with V = {n}, got {}",
                        shape_str(shape)
                    ))
                };
                if let Ok(a) = array_arg::<bool>(values, "values", "bool") {
                    if a.shape() != [n] {
                        return Err(shape_err(a.shape()));
                    }
                    return Ok(bool_values(&a));
                }
                let a = array_arg::<f64>(values, "values", "float64 or bool")?;
                return match a.shape() {
                    [m] if *m == n => Ok(real_values(&a, false)),
                    [m, 3] if *m == n => Ok(real_values(&a, true)),
                    s => Err(shape_err(s)),
                };
            };
            // what the type takes: "a vec3", the shape as written and with V's value
            let (article, wanted, form) = match ty {
                EmbeddingType::Vec3 => ("a", vec![n, 3], "(V, 3)"),
                EmbeddingType::F64 => ("an", vec![n], "(V,)"),
                _ => ("a", vec![n], "(V,)"),
            };
            let wanted_str = shape_str(&wanted);
            let kind = values
                .cast::<PyUntypedArray>()
                .ok()
                .map(|a| a.dtype().kind());
            let is_bool = ty == EmbeddingType::Bool;
            if is_bool && matches!(kind, Some(b'i' | b'u' | b'f')) {
                return Err(type_error(format!(
                    "'{name}' is a bool embedding: numbers given (it takes booleans of shape \
                     (V,) = {wanted_str})"
                )));
            }
            if !is_bool && kind == Some(b'b') {
                return Err(type_error(format!(
                    "'{name}' is {article} {ty} embedding: booleans given (it takes numbers of \
                     shape {form} = {wanted_str})"
                )));
            }
            let shape_err = |shape: &[usize]| {
                value_error(format!(
                    "values for '{name}' ({article} {ty} embedding) must have shape {form} = \
                     {wanted_str}, got {}",
                    shape_str(shape)
                ))
            };
            if is_bool {
                let a = array_arg::<bool>(values, "values", "bool")?;
                if a.shape() != wanted.as_slice() {
                    return Err(shape_err(a.shape()));
                }
                return Ok(bool_values(&a));
            }
            let a = array_arg::<f64>(values, "values", "float64")?;
            if a.shape() != wanted.as_slice() {
                return Err(shape_err(a.shape()));
            }
            Ok(real_values(&a, ty == EmbeddingType::Vec3))
        })?;
        this.run(py, move |sim| Ok(sim.set_vertex_field(name, &values)?))
    }

    /// Whether each vertex is fixed (held in place or at a prescribed displacement), bool (V,).
    fn fixed<'py>(slf: &Bound<'_, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let this = shared(slf)?;
        Ok(this.read(|s| Ok(s.vertex_bool("fixed")?))?.into_pyarray(py))
    }

    /// Sets the positions, float64 (V, 3) of finite values (fixed vertices included: they stay
    /// where they are put).
    fn set_positions(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        positions: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        this.set_vec3(py, "position", "positions", positions)
    }

    /// Sets the velocities, float64 (V, 3) of finite values.
    fn set_velocities(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        velocities: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        this.set_vec3(py, "velocity", "velocities", velocities)
    }

    /// Sum of the vertex masses.
    fn total_mass(slf: &Bound<'_, Self>) -> PyResult<f64> {
        let this = shared(slf)?;
        this.read(|s| Ok(s.total_mass()?))
    }

    /// Kinetic energy, sum of m |v|^2 / 2.
    fn kinetic_energy(slf: &Bound<'_, Self>) -> PyResult<f64> {
        let this = shared(slf)?;
        this.read(|s| Ok(s.kinetic_energy()?))
    }

    /// Linear momentum, sum of m v, float64 (3,).
    fn momentum<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let this = shared(slf)?;
        Ok(this.read(|s| Ok(s.momentum()?))?.to_vec().into_pyarray(py))
    }

    /// The values of a vertex embedding, one row per vertex: shape (V,) for `f64` (float64),
    /// `i64` (int64) and `bool`; (V, 2) and (V, 3) for `vec2` and `vec3`; (V, R, C) for a
    /// matrix. An embedding on another orbit raises `EmbeddingError`. For a row of several
    /// orbits, masses and forces (`mass`, `force`, `df`, `f_*`, `df_*`) are summed over them;
    /// other values are the first orbit's.
    fn embedding<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
        name: &str,
    ) -> PyResult<Bound<'py, PyAny>> {
        enum Column {
            Real(Vec<usize>, Vec<f64>),
            Int(Vec<i64>),
            Bool(Vec<bool>),
        }
        let this = shared(slf)?;
        let col = this.read(|s| {
            let g = s.gmap();
            let id = g.require(name)?;
            let e = g.embedding(id);
            let vertex = OrbitType::vertex(g.dimension());
            if e.orbit() != vertex {
                return Err(Error::EmbeddingInput(format!(
                    "embedding '{name}' is on the orbit {}, not on the vertex orbit {vertex}: \
                     only vertex embeddings can be read per vertex (read the map with gmap())",
                    e.orbit()
                )));
            }
            let darts = s.vertex_darts();
            let n = darts.len();
            let ty = e.ty();
            Ok(match ty {
                EmbeddingType::I64 => Column::Int(
                    darts
                        .iter()
                        .map(|&d| match g.value(id, d)? {
                            Value::Int(x) => Ok(x),
                            v => Err(Error::EmbeddingInput(format!("'{name}': {v:?}"))),
                        })
                        .collect::<Result<_>>()?,
                ),
                EmbeddingType::Bool => Column::Bool(
                    darts
                        .iter()
                        .map(|&d| match g.value(id, d)? {
                            Value::Bool(x) => Ok(x),
                            v => Err(Error::EmbeddingInput(format!("'{name}': {v:?}"))),
                        })
                        .collect::<Result<_>>()?,
                ),
                _ => {
                    let shape = match ty {
                        EmbeddingType::F64 => vec![n],
                        EmbeddingType::Vec2 => vec![n, 2],
                        EmbeddingType::Vec3 => vec![n, 3],
                        EmbeddingType::Mat { rows, cols } => {
                            vec![n, usize::from(rows), usize::from(cols)]
                        }
                        EmbeddingType::I64 | EmbeddingType::Bool => unreachable!("matched above"),
                    };
                    let mut flat = Vec::with_capacity(n * ty.width());
                    for &d in &darts {
                        match g.value(id, d)? {
                            Value::Real(x) => flat.extend_from_slice(&x),
                            v => return Err(Error::EmbeddingInput(format!("'{name}': {v:?}"))),
                        }
                    }
                    // additive quantities (masses, forces) of a welded row: the sum over its
                    // orbits; the others are shared by them
                    if is_additive(name) {
                        let w = ty.width();
                        for (row, orbits) in s.welded_rows() {
                            let out = &mut flat[row * w..(row + 1) * w];
                            out.fill(0.0);
                            for &d in orbits {
                                for (o, x) in out.iter_mut().zip(g.real(id, d)) {
                                    *o += x;
                                }
                            }
                        }
                    }
                    Column::Real(shape, flat)
                }
            })
        })?;
        Ok(match col {
            Column::Int(v) => v.into_pyarray(py).into_any(),
            Column::Bool(v) => v.into_pyarray(py).into_any(),
            Column::Real(shape, flat) => {
                let a = guard(|| {
                    ArrayD::from_shape_vec(IxDyn(&shape), flat)
                        .map_err(|e| value_error(format!("cannot shape '{name}': {e}")))
                })?;
                let arr: Bound<'py, PyArrayDyn<f64>> = a.into_pyarray(py);
                arr.into_any()
            }
        })
    }

    /// The embedding `name` of the simulated map, one row per orbit: the tuple `(values,
    /// darts, orbit)` of `GMap.embedding` (rows by the smallest dart of each orbit, not the
    /// per-vertex row order of `embedding`). Reads any orbit type: a corner force `<1,2>`, a
    /// per-element matrix `<0,1,2>`. Raises `KeyError` for an unknown name, listing the map's
    /// embeddings.
    fn orbit_embedding<'py>(
        slf: &Bound<'_, Self>,
        py: Python<'py>,
        name: &str,
    ) -> PyResult<OrbitValuesPy<'py>> {
        let this = shared(slf)?;
        let g = this.sim()?.gmap();
        let id = embedding_key(g, name)?;
        let v = this.read(|s| {
            let g = s.gmap();
            if g.is_stale(id) {
                // derived values are a cache: recompute them on a copy, the simulation is
                // only read
                let mut copy = g.clone();
                copy.refresh_derived();
                read_orbit_values(&copy, id)
            } else {
                read_orbit_values(g, id)
            }
        })?;
        orbit_values_to_py(py, name, v)
    }

    /// Writes every value of the stored embedding `name` of the simulated map, in the layout
    /// of `orbit_embedding(name)` (as `GMap.set_embedding`), then recomputes the derived
    /// embeddings; the next step starts from the values written. Nothing is written when it
    /// raises: `KeyError`, `TypeError`, `ValueError` and `EmbeddingError` as
    /// `GMap.set_embedding`; `ValueError` also when the orbits of one particle (a pinched
    /// vertex kept as one row) would get different values of a shared vertex quantity
    /// (`position`, `velocity`, ...; masses and forces are per orbit and may differ);
    /// `SimulationError` for the embeddings that number rows and elements (`particle`,
    /// `point_id`, `cell_id`, `vertex0`, `face0`).
    fn set_orbit_embedding(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        name: &str,
        values: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let mut this = exclusive(slf)?;
        let vals = {
            let s = this.sim()?;
            let g = s.gmap();
            let id = embedding_key(g, name)?;
            guard(|| {
                let (vals, reps) = orbit_values_arg(g, id, values)?;
                // a value no material has: a ValueError, as for a NaN (the simulation's
                // own check, for Rust callers, gives a SimulationError)
                if let crate::gmap::Gathered::Real(v) = &vals {
                    if let Some(why) = topomech_physics::material_value_problem(name, v) {
                        return Err(value_error(why));
                    }
                }
                let e = g.embedding(id);
                if e.orbit() == OrbitType::vertex(g.dimension()) && !is_additive(name) {
                    check_welded(s, name, e.ty().width(), &vals, &reps)?;
                }
                Ok(vals)
            })?
        };
        this.run(py, move |sim| {
            Ok(sim.set_orbit_values(name, vals.as_column())?)
        })
    }

    /// Every embedding of the simulated map, in declaration order: `(name, type, orbit,
    /// derived)` tuples, as `GMap.embeddings`.
    fn embeddings(slf: &Bound<'_, Self>) -> PyResult<Vec<(String, String, String, bool)>> {
        let this = shared(slf)?;
        Ok(embedding_specs(this.sim()?.gmap()))
    }

    /// A copy of the simulated map, with every embedding (positions as they are now).
    fn gmap(slf: &Bound<'_, Self>) -> PyResult<PyGMap> {
        let this = shared(slf)?;
        Ok(PyGMap::new(this.read(|s| Ok(s.gmap().clone()))?))
    }

    /// Simulated time.
    #[getter]
    fn time(slf: &Bound<'_, Self>) -> PyResult<f64> {
        let this = shared(slf)?;
        Ok(this.sim()?.time())
    }

    /// Steps done.
    #[getter]
    fn steps(slf: &Bound<'_, Self>) -> PyResult<u64> {
        let this = shared(slf)?;
        Ok(this.sim()?.steps())
    }

    /// The number of vertices (V, the rows of the per-vertex arrays: particles).
    #[getter]
    fn n_vertices(slf: &Bound<'_, Self>) -> PyResult<usize> {
        let this = shared(slf)?;
        Ok(this.sim()?.n_vertices())
    }

    /// The dimension of the map: 2 (surface) or 3 (volume).
    #[getter]
    fn dimension(slf: &Bound<'_, Self>) -> PyResult<usize> {
        let this = shared(slf)?;
        Ok(this.sim()?.gmap().dimension())
    }

    /// The time step.
    #[getter]
    fn dt(slf: &Bound<'_, Self>) -> PyResult<f64> {
        let this = shared(slf)?;
        Ok(this.sim()?.config().dt)
    }

    /// The map's topology version: it changes when a topology change (a cut, a fracture)
    /// relinks darts, and with it the vertices and cells.
    #[getter]
    fn topology_version(slf: &Bound<'_, Self>) -> PyResult<u64> {
        let this = shared(slf)?;
        Ok(this.sim()?.gmap().version())
    }

    /// The integrator's name.
    #[getter]
    fn integrator(slf: &Bound<'_, Self>) -> PyResult<&'static str> {
        let this = shared(slf)?;
        Ok(integrator_name(this.sim()?.config().integrator))
    }

    fn __repr__(slf: &Bound<'_, Self>) -> String {
        let Ok(this) = slf.try_borrow() else {
            return "<topomech._core.Simulation (busy: in use by another thread)>".to_string();
        };
        if this.poisoned {
            return "<topomech._core.Simulation (unusable after an internal error)>".to_string();
        }
        format!(
            "<topomech._core.Simulation dimension={} vertices={} steps={} time={}>",
            this.inner.gmap().dimension(),
            this.inner.n_vertices(),
            this.inner.steps(),
            this.inner.time()
        )
    }
}

/// Refuses values of a shared vertex quantity that differ between the orbits of one welded row
/// (`vals` one value of `w` scalars per vertex orbit, orbits by smallest dart `reps`).
fn check_welded(
    s: &Simulation,
    name: &str,
    w: usize,
    vals: &crate::gmap::Gathered,
    reps: &[topomech_gmap::Dart],
) -> Result<()> {
    for (row, orbits) in s.welded_rows() {
        let ks: Vec<usize> = orbits
            .iter()
            .filter_map(|d| reps.binary_search(d).ok())
            .collect();
        let Some((&k0, rest)) = ks.split_first() else {
            continue;
        };
        for &k in rest {
            if !vals.rows_equal(w, k0, k) {
                return Err(value_error(format!(
                    "values for '{name}': rows {k0} and {k} (the orbits of darts {} and {}) are one particle (vertex row {row}, a pinched vertex kept as one) and must have the same value",
                    reps[k0].0, reps[k].0
                )));
            }
        }
    }
    Ok(())
}

/// Rows as int64.
fn rows_i64(rows: &[usize]) -> Vec<i64> {
    rows.iter()
        .map(|&r| i64::try_from(r).unwrap_or(i64::MAX))
        .collect()
}

/// The models topomech ships: `[{"kind", "dims", "params": {name: default}, "param_types":
/// {name: "f64" | "vec3"}, "needs", "has_jvp", "per_element"}]` (`per_element`: a continuous
/// model, taking the material's young and poisson); a default is a float, a list of 3
/// floats, or None for a required parameter.
#[pyfunction]
pub(crate) fn models(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    shipped_models()
        .iter()
        .map(|m| {
            let d = PyDict::new(py);
            d.set_item("kind", &m.name)?;
            d.set_item("dims", m.dimensions.clone())?;
            let p = PyDict::new(py);
            let types = PyDict::new(py);
            for q in &m.params {
                match &q.default {
                    Some(Val::F(v)) => p.set_item(&q.name, *v)?,
                    Some(Val::V3(v)) => p.set_item(&q.name, v.to_vec())?,
                    _ => p.set_item(&q.name, py.None())?,
                }
                types.set_item(&q.name, q.ty.to_string())?;
            }
            d.set_item("params", p)?;
            d.set_item("param_types", types)?;
            d.set_item("needs", m.needs.as_deref().unwrap_or(""))?;
            d.set_item("has_jvp", m.has_jvp)?;
            d.set_item("per_element", m.per_element)?;
            Ok(d)
        })
        .collect()
}

/// One `Value::Bool` per entry of `a` (a `(V,)` mask): the rows of `set_vertex_field`.
fn bool_values(a: &numpy::PyReadonlyArrayDyn<'_, bool>) -> Vec<Value> {
    a.as_array().iter().map(|&b| Value::Bool(b)).collect()
}

/// One `Value::Real` per row of `a`: a vec3 per row of a `(V, 3)` array (`vec3`), else a
/// scalar per entry of a `(V,)` one: the rows of `set_vertex_field`.
fn real_values(a: &numpy::PyReadonlyArrayDyn<'_, f64>, vec3: bool) -> Vec<Value> {
    if vec3 {
        a.as_array()
            .rows()
            .into_iter()
            .map(|r| Value::Real(r.to_vec()))
            .collect()
    } else {
        a.as_array().iter().map(|&x| Value::Real(vec![x])).collect()
    }
}
