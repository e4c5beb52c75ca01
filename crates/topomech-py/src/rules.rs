//! `topomech._core.RuleSet`: rule files loaded and checked, applied to maps.
//!
//! Loading refuses a file with `RuleError` carrying every diagnostic; applying refuses with
//! `ApplyError` (the engine's [`topomech_rules::ApplyError`]) and leaves the map unchanged.
//! Arguments are checked here first, like everywhere else at the boundary: a hook dart is a
//! live dart of the map (`IndexError`, never wrapped), and a parameter value is converted to
//! the type its rule declares (`TypeError` for a value of the wrong kind, `ValueError` for a
//! wrong shape or a non-finite number). A missing or unknown parameter is the rule's business:
//! `ApplyError`.

use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use numpy::{PyArrayDescrMethods, PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyInt, PyList, PyMapping, PyTuple};
use topomech_gmap::{Dart, GMap};
use topomech_physics::{common_rules, prelude_rules};
use topomech_rules::check::{Rule, LOAD_FOR_A_DIMENSION};
use topomech_rules::model::Model;
use topomech_rules::{
    library, load_files, load_files_for, load_sources, load_sources_for,
    ApplyError as KernelApplyError, ApplyReport, Diagnostic, Params, RuleSet, Ty, Val,
};

use crate::convert::{dart_arg, shape_str, type_name};
use crate::errors::{exclusive, guard, not_found, type_error, value_error, Error, Result};
use crate::gmap::PyGMap;

/// Rules loaded from rule files (`.tmr`) and checked: every rule accepted keeps any map of
/// its dimension valid. Load with `RuleSet.load`, `RuleSet.from_source` or `RuleSet.library`.
#[pyclass(name = "RuleSet", module = "topomech._core", frozen)]
pub(crate) struct PyRuleSet {
    inner: RuleSet,
    /// The checker's warnings, one `FILE:LINE:COL: warning[CONDITION]: message` line each.
    warnings: Vec<String>,
}

/// How often an application polls Python's signal handlers (taking the GIL for that).
const SIGNAL_POLL: Duration = Duration::from_millis(10);

/// The interrupt check of a long application: at most once per [`SIGNAL_POLL`], runs
/// Python's signal handlers (`Python::check_signals`, with the GIL); when one raises
/// (`KeyboardInterrupt` for Ctrl-C) keeps the exception in `raised` and asks the engine to
/// stop.
fn signal_raised(last: &Cell<Instant>, raised: &Mutex<Option<PyErr>>) -> bool {
    if last.get().elapsed() < SIGNAL_POLL {
        return false;
    }
    last.set(Instant::now());
    #[allow(clippy::redundant_closure_for_method_calls)] // the method is not general enough
    let checked = Python::attach(|py| py.check_signals());
    match checked {
        Ok(()) => false,
        Err(e) => {
            *raised
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(e);
            true
        }
    }
}

/// The rule set, or `RuleError` with every diagnostic.
fn loaded(
    r: std::result::Result<(RuleSet, Vec<Diagnostic>), Vec<Diagnostic>>,
) -> Result<PyRuleSet> {
    match r {
        Ok((inner, diags)) => Ok(PyRuleSet {
            inner,
            warnings: diags.iter().map(ToString::to_string).collect(),
        }),
        Err(mut diags) => {
            // the checker's advice for files that serve both dimensions, in Python's terms
            for d in &mut diags {
                if let Some(head) = d.message.strip_suffix(LOAD_FOR_A_DIMENSION) {
                    d.message =
                        format!("{head}pass dimension=2 (surfaces) or dimension=3 (volumes)");
                }
            }
            Err(Error::Rules(diags))
        }
    }
}

/// `sources` after the shipped prelude and the common rules of the dimension the first of them
/// declares (unchanged when none declares 2 or 3, or when one of them is that common file
/// already).
fn with_common_rules(sources: Vec<(String, String)>, dim: Option<usize>) -> Vec<(String, String)> {
    let dim = dim.or_else(|| {
        sources.iter().find_map(|(_, text)| {
            topomech_rules::parser::parse(text)
                .ok()
                .and_then(|f| f.dimension)
                .and_then(|(n, _)| usize::try_from(n).ok())
        })
    });
    let Some((name, text)) = dim.and_then(common_rules) else {
        return sources;
    };
    if sources.iter().any(|(n, _)| *n == name) {
        return sources;
    }
    let mut out = Vec::new();
    let (pname, ptext) = prelude_rules();
    if !sources.iter().any(|(n, _)| *n == pname) {
        out.push((pname, ptext.to_string()));
    }
    out.push((name, text.to_string()));
    out.extend(sources);
    out
}

/// A `dimension` argument: None, 2 or 3.
fn rule_dimension(dimension: Option<i64>) -> Result<Option<usize>> {
    match dimension {
        None => Ok(None),
        Some(d @ (2 | 3)) => Ok(usize::try_from(d).ok()),
        Some(d) => Err(value_error(format!("dimension must be 2 or 3, got {d}"))),
    }
}

/// A parameter's value for Python: a float, an int, a bool or a list of floats.
fn val_object<'py>(py: Python<'py>, v: &Val) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Val::F(x) => x.into_pyobject(py)?.into_any(),
        Val::I(x) => x.into_pyobject(py)?.into_any(),
        Val::B(x) => x.into_pyobject(py)?.to_owned().into_any(),
        Val::V2(x) => PyList::new(py, x)?.into_any(),
        Val::V3(x) => PyList::new(py, x)?.into_any(),
        Val::M(m) => PyList::new(py, &m.data)?.into_any(),
    })
}

/// One model declaration as `RuleSet.models` gives it.
fn model_dict<'py>(py: Python<'py>, m: &Model) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", &m.name)?;
    d.set_item("file", &m.file)?;
    d.set_item("line", m.pos.line)?;
    d.set_item("col", m.pos.col)?;
    let params = PyList::empty(py);
    for p in &m.params {
        let default = match &p.default {
            Some(v) => val_object(py, v)?,
            None => py.None().into_bound(py),
        };
        params.append(PyTuple::new(
            py,
            [
                p.name.clone().into_pyobject(py)?.into_any(),
                p.ty.to_string().into_pyobject(py)?.into_any(),
                default,
            ],
        )?)?;
    }
    d.set_item("params", params)?;
    d.set_item("dimensions", m.dimensions.clone())?;
    d.set_item("needs", m.needs.clone())?;
    d.set_item("forces", m.forces.clone())?;
    d.set_item("jvp_outputs", m.jvp_outputs.clone())?;
    d.set_item("has_jvp", !m.jvp.is_empty())?;
    d.set_item("per_element", m.per_element)?;
    Ok(d)
}

/// The `topomech._core.GMap` behind `obj`: the object itself, or its `core` attribute (the
/// `topomech.GMap` wrapper).
pub(crate) fn gmap_core<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyGMap>> {
    match obj.cast::<PyGMap>() {
        Ok(g) => Ok(g.clone()),
        Err(_) => obj
            .getattr("core")
            .ok()
            .and_then(|c| c.cast_into::<PyGMap>().ok())
            .ok_or_else(|| {
                PyErr::from(type_error(format!(
                    "gmap must be a topomech.GMap or a topomech._core.GMap, got {}",
                    type_name(obj)
                )))
            }),
    }
}

/// The map behind `obj` (see [`gmap_core`]), borrowed for writing.
fn gmap_arg<'py>(obj: &Bound<'py, PyAny>) -> PyResult<PyRefMut<'py, PyGMap>> {
    exclusive(&gmap_core(obj)?)
}

/// The hook darts: one int, or a sequence of ints (one per hook), each a live dart of `g`.
fn hooks_arg(g: &GMap, at: &Bound<'_, PyAny>) -> Result<Vec<Dart>> {
    if at.is_instance_of::<PyInt>() || at.extract::<i64>().is_ok() {
        // one dart: a Python or numpy integer
        return Ok(vec![dart_arg(g, at)?]);
    }
    if !(at.is_instance_of::<PyList>() || at.is_instance_of::<PyTuple>())
        && at.cast::<PyUntypedArray>().is_err()
    {
        return Err(type_error(format!(
            "at must be a dart or a list of darts (one per hook), got {}",
            type_name(at)
        )));
    }
    at.try_iter()?
        .map(|d| dart_arg(g, &d?))
        .collect::<Result<Vec<Dart>>>()
}

/// `name: type, ...` of a rule's parameters, for messages.
fn signature(rule: &Rule) -> String {
    if rule.params.is_empty() {
        return "it takes no parameters".to_string();
    }
    let ps: Vec<String> = rule
        .params
        .iter()
        .map(|(p, ty)| format!("{p}: {ty}"))
        .collect();
    format!("it takes {}", ps.join(", "))
}

/// The parameters of `rule` from a mapping `{name: value}`, each converted to its declared
/// type. Missing parameters are left for the engine to name.
fn params_arg(rule: &Rule, params: Option<&Bound<'_, PyAny>>) -> Result<Params> {
    let mut out = Params::new();
    let Some(obj) = params else {
        return Ok(out);
    };
    let map = obj.cast::<PyMapping>().map_err(|_| {
        type_error(format!(
            "params must be a dict of parameter values by name, got {}",
            type_name(obj)
        ))
    })?;
    for item in map.items()?.iter() {
        let (k, v): (Bound<'_, PyAny>, Bound<'_, PyAny>) = item.extract()?;
        let name: String = k.extract().map_err(|_| {
            type_error(format!(
                "parameter names must be str, got {}",
                type_name(&k)
            ))
        })?;
        let Some((_, ty)) = rule.params.iter().find(|(p, _)| *p == name) else {
            return Err(Error::Apply(KernelApplyError::Param {
                rule: rule.name.clone(),
                message: format!("unknown parameter '{name}' ({})", signature(rule)),
            }));
        };
        let what = format!("parameter '{name}' of rule '{}' is {ty}", rule.name);
        let val = value_arg(&v, *ty, &what)?;
        out.insert(name, val);
    }
    Ok(out)
}

/// A real number: an int or a float (Python's or numpy's), not a bool.
fn real_scalar(obj: &Bound<'_, PyAny>) -> Option<f64> {
    if obj.extract::<bool>().is_ok() {
        return None;
    }
    obj.extract::<f64>().ok()
}

/// A value of type `ty`; `what` starts the messages ("parameter 'f' of rule 'r' is f64").
fn value_arg(obj: &Bound<'_, PyAny>, ty: Ty, what: &str) -> Result<Val> {
    let val =
        match ty {
            Ty::Bool => Val::B(obj.extract::<bool>().map_err(|_| {
                type_error(format!("{what}: expected a bool, got {}", type_name(obj)))
            })?),
            Ty::I64 => {
                if obj.extract::<bool>().is_ok() {
                    return Err(type_error(format!("{what}: expected an int, got bool")));
                }
                match obj.extract::<i64>() {
                    Ok(i) => Val::I(i),
                    Err(_) if obj.is_instance_of::<PyInt>() => {
                        return Err(value_error(format!(
                            "{what}: {obj} does not fit in 64 bits"
                        )))
                    }
                    Err(_) => {
                        return Err(type_error(format!(
                            "{what}: expected an int, got {}",
                            type_name(obj)
                        )))
                    }
                }
            }
            Ty::F64 => Val::F(real_scalar(obj).ok_or_else(|| {
                type_error(format!("{what}: expected a number, got {}", type_name(obj)))
            })?),
            Ty::Vec2 | Ty::Vec3 | Ty::Mat(..) => {
                let (shape, data) = real_array(obj, what)?;
                let expected = match ty {
                    Ty::Vec2 => vec![2],
                    Ty::Vec3 => vec![3],
                    Ty::Mat(r, c) => vec![usize::from(r), usize::from(c)],
                    _ => unreachable!("scalar types are handled above"),
                };
                if shape != expected {
                    let want = match ty {
                        Ty::Mat(r, c) => format!("a {r}x{c} matrix (shape ({r}, {c}))"),
                        _ => format!("{} numbers", expected[0]),
                    };
                    return Err(value_error(format!(
                        "{what}: expected {want}, got shape {}",
                        shape_str(&shape)
                    )));
                }
                Val::from_reals(ty, &data)
            }
        };
    let mut reals = Vec::new();
    val.to_reals(&mut reals);
    if reals.iter().any(|x| !x.is_finite()) {
        return Err(value_error(format!(
            "{what}: got a value that is not finite"
        )));
    }
    Ok(val)
}

/// The shape and row-major entries of a vector or matrix: a numpy array of ints or floats,
/// or a list or tuple of numbers, or of rows of numbers.
fn real_array(obj: &Bound<'_, PyAny>, what: &str) -> Result<(Vec<usize>, Vec<f64>)> {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        let dtype = a.dtype();
        if !matches!(dtype.kind(), b'i' | b'u' | b'f') {
            return Err(type_error(format!(
                "{what}: expected an array of numbers, got a {dtype} array"
            )));
        }
        let f = obj.call_method1("astype", ("float64",))?;
        let f = f.extract::<PyReadonlyArrayDyn<'_, f64>>()?;
        return Ok((a.shape().to_vec(), f.as_array().iter().copied().collect()));
    }
    if !(obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>()) {
        return Err(type_error(format!(
            "{what}: expected a list of numbers or a numpy array, got {}",
            type_name(obj)
        )));
    }
    let items: Vec<Bound<'_, PyAny>> = obj.try_iter()?.collect::<PyResult<_>>()?;
    let scalars: Vec<Option<f64>> = items.iter().map(real_scalar).collect();
    if scalars.iter().any(Option::is_some) {
        // a vector: every item a number
        if let Some(k) = scalars.iter().position(Option::is_none) {
            return Err(type_error(format!(
                "{what}: expected numbers, found {} at index {k}",
                type_name(&items[k])
            )));
        }
        let x: Vec<f64> = scalars.into_iter().flatten().collect();
        return Ok((vec![x.len()], x));
    }
    let mut data = Vec::new();
    let mut cols: Option<usize> = None;
    for (k, it) in items.iter().enumerate() {
        let is_row = it.is_instance_of::<PyList>()
            || it.is_instance_of::<PyTuple>()
            || it.cast::<PyUntypedArray>().is_ok();
        if !is_row {
            return Err(type_error(format!(
                "{what}: expected numbers or rows of numbers, found {} at index {k}",
                type_name(it)
            )));
        }
        let (s, d) = real_array(it, what)?;
        if s.len() != 1 {
            return Err(value_error(format!(
                "{what}: expected a vector or a matrix, got more than 2 dimensions"
            )));
        }
        if cols.is_some_and(|c| c != s[0]) {
            return Err(value_error(format!(
                "{what}: its rows have different lengths"
            )));
        }
        cols = Some(s[0]);
        data.extend(d);
    }
    Ok((vec![items.len(), cols.unwrap_or(0)], data))
}

/// `{"matches", "created", "deleted"}` of an application.
fn report_dict<'py>(py: Python<'py>, r: &ApplyReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("matches", r.matches)?;
    d.set_item("created", r.created)?;
    d.set_item("deleted", r.deleted)?;
    Ok(d)
}

#[pymethods]
impl PyRuleSet {
    /// Reads and checks rule files together (they share their dimension and embeddings), for
    /// `dimension` (2 or 3; needed when every file serves both, `dimension 2 3` or no
    /// dimension line; by default the dimension the files say). Raises `FileNotFoundError`
    /// naming the first file that does not exist, else `RuleError` listing every error, an
    /// unreadable file included (and one that is not a regular file: a directory, or a device
    /// or FIFO such as `/dev/zero`, refused before anything is read).
    #[staticmethod]
    #[pyo3(signature = (paths, dimension=None))]
    fn load(py: Python<'_>, paths: Vec<PathBuf>, dimension: Option<i64>) -> PyResult<PyRuleSet> {
        if paths.is_empty() {
            return Err(value_error("load needs at least one rule file").into());
        }
        let dim = rule_dimension(dimension)?;
        if let Some(p) = paths
            .iter()
            .find(|p| std::fs::metadata(p).is_err_and(|e| e.kind() == std::io::ErrorKind::NotFound))
        {
            return Err(not_found(p).into());
        }
        py.detach(move || {
            guard(|| {
                let refs: Vec<&Path> = paths.iter().map(PathBuf::as_path).collect();
                loaded(match dim {
                    Some(d) => load_files_for(d, &refs),
                    None => load_files(&refs),
                })
            })
        })
    }

    /// Checks the text of one rule file; `name` is the file name diagnostics show; for
    /// `dimension` as `from_sources`.
    #[staticmethod]
    #[pyo3(signature = (text, name = "<string>", dimension=None))]
    fn from_source(
        py: Python<'_>,
        text: String,
        name: &str,
        dimension: Option<i64>,
    ) -> PyResult<PyRuleSet> {
        let dim = rule_dimension(dimension)?;
        let sources = [(name.to_string(), text)];
        py.detach(move || {
            guard(|| {
                loaded(match dim {
                    Some(d) => load_sources_for(d, &sources),
                    None => load_sources(&sources),
                })
            })
        })
    }

    /// Checks the texts of several rule files together: `[(name, text), ...]`, for
    /// `dimension` (2 or 3; needed when every file serves both, `dimension 2 3` or no
    /// dimension line; by default the dimension the files say).
    #[staticmethod]
    #[pyo3(signature = (sources, dimension=None))]
    fn from_sources(
        py: Python<'_>,
        sources: Vec<(String, String)>,
        dimension: Option<i64>,
    ) -> PyResult<PyRuleSet> {
        if sources.is_empty() {
            return Err(value_error("from_sources needs at least one (name, text) pair").into());
        }
        let dim = rule_dimension(dimension)?;
        py.detach(move || {
            guard(|| {
                loaded(match dim {
                    Some(d) => load_sources_for(d, &sources),
                    None => load_sources(&sources),
                })
            })
        })
    }

    /// The dimensions a rule file's `dimension` line names (`[2, 3]` for `dimension 2 3`),
    /// empty when it has none (the file then serves both) or does not parse.
    #[staticmethod]
    fn file_dimensions(text: &str) -> Vec<u64> {
        topomech_rules::parser::parse(text)
            .map(|f| f.dimensions.iter().map(|(n, _)| *n).collect())
            .unwrap_or_default()
    }

    /// Checks the texts of model files (`[(name, text), ...]`) as a simulation loads them:
    /// after the shipped common rules of their dimension (the embeddings every simulation
    /// has: `position`, `rest`, `velocity`, `force`, `mass`, `dx`, `dv`, `df`, the
    /// material, ...), so a model file declares only `dimension` and its own embeddings. The
    /// dimension is the first one a file declares; without one (or with one other than 2 or
    /// 3) the files are checked alone and the checker says why. Raises `RuleError` listing
    /// every error at its `FILE:LINE:COL`.
    #[staticmethod]
    #[pyo3(signature = (sources, dimension=None))]
    fn from_model_sources(
        py: Python<'_>,
        sources: Vec<(String, String)>,
        dimension: Option<i64>,
    ) -> PyResult<PyRuleSet> {
        if sources.is_empty() {
            return Err(
                value_error("from_model_sources needs at least one (name, text) pair").into(),
            );
        }
        let dim = rule_dimension(dimension)?;
        py.detach(move || {
            guard(|| {
                let sources = with_common_rules(sources, dim);
                loaded(match dim {
                    Some(d) => load_sources_for(d, &sources),
                    None => load_sources(&sources),
                })
            })
        })
    }

    /// The modeling rules shipped with topomech for `dimension` 2 or 3: split an edge,
    /// triangulate a face, quad subdivision, unsew and sew along the last link, remove a
    /// detached face (2D) or volume (3D). `rule_names` lists them.
    #[staticmethod]
    fn library(py: Python<'_>, dimension: i64) -> PyResult<PyRuleSet> {
        let source = usize::try_from(dimension)
            .ok()
            .and_then(library)
            .ok_or_else(|| {
                PyErr::from(value_error(format!(
                    "there is no rule library for dimension {dimension}: use 2 or 3"
                )))
            })?;
        py.detach(move || guard(|| loaded(load_sources(&[source]))))
    }

    /// The dimension of the maps the rules apply to (2 or 3).
    #[getter]
    fn dimension(&self) -> usize {
        self.inner.dimension()
    }

    /// The checker's warnings, one `FILE:LINE:COL: warning[CONDITION]: message` line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// The rules' names, in file order.
    fn rule_names(&self) -> Vec<String> {
        self.inner.rules().iter().map(|r| r.name.clone()).collect()
    }

    /// The model declarations of the files, in file order: dicts `{"name", "file", "line",
    /// "col", "params": [(name, type, default or None), ...], "dimensions": [int],
    /// "needs": str or None, "forces": [str], "jvp_outputs": [str], "has_jvp": bool,
    /// "per_element": bool}`; a default is a float (`f64`) or a list of 3 floats (`vec3`).
    fn models<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .models()
            .iter()
            .map(|m| model_dict(py, m))
            .collect()
    }

    /// `{"name", "file", "params": [[name, type], ...], "hooks": int, "changes_topology"}`;
    /// `hooks` is the number of darts `apply(..., at=...)` needs.
    fn rule_info<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyDict>> {
        let r = guard(|| Ok(self.inner.rule(name)?))?;
        let d = PyDict::new(py);
        d.set_item("name", &r.name)?;
        d.set_item("file", &r.file)?;
        let params: Vec<(String, String)> = r
            .params
            .iter()
            .map(|(p, ty)| (p.clone(), ty.name()))
            .collect();
        let params = PyList::new(
            py,
            params
                .into_iter()
                .map(|(p, ty)| PyList::new(py, [p, ty]))
                .collect::<PyResult<Vec<_>>>()?,
        )?;
        d.set_item("params", params)?;
        d.set_item("hooks", r.hooks.len())?;
        d.set_item("changes_topology", r.changes_topology)?;
        Ok(d)
    }

    /// Applies rule `name` to `gmap` (changed in place): at every match when `at` is None,
    /// else once with its hooks at the darts `at` (one per hook). `params` maps each
    /// parameter to a value: a number, a bool, a list or array of 2 or 3 numbers, or a 2-D
    /// list or array for a matrix. Returns `{"matches", "created", "deleted"}` (darts).
    /// Raises `ApplyError` (the map unchanged) when the rule does not apply. Ctrl-C
    /// (SIGINT) during an application at every match raises `KeyboardInterrupt` within
    /// milliseconds (the signal is polled every 10 ms), the map valid and without any of the
    /// rule's changes.
    #[pyo3(signature = (gmap, name, at = None, params = None))]
    fn apply<'py>(
        &self,
        py: Python<'py>,
        gmap: &Bound<'py, PyAny>,
        name: &str,
        at: Option<&Bound<'py, PyAny>>,
        params: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mut g = gmap_arg(gmap)?;
        let rules = &self.inner;
        let report = g.mutate(py, |map| {
            let params = params_arg(rules.rule(name)?, params)?;
            let hooks = at.map(|at| hooks_arg(map, at)).transpose()?;
            let raised: Mutex<Option<PyErr>> = Mutex::new(None);
            let r = py.detach(|| match hooks {
                None => {
                    let last = Cell::new(Instant::now());
                    let interrupt = || signal_raised(&last, &raised);
                    rules.apply_everywhere_interruptible(map, name, &params, &interrupt)
                }
                Some(h) => rules.apply_at(map, name, &h, &params),
            });
            let raised = raised
                .into_inner()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            match (r, raised) {
                // the engine stopped because a signal handler raised (KeyboardInterrupt)
                (Err(KernelApplyError::Interrupted { .. }), Some(e)) => Err(Error::Py(e)),
                (r, _) => r.map_err(Error::from),
            }
        })?;
        report_dict(py, &report)
    }

    /// The number of matches `apply(gmap, name, params=params)` would apply. The map may get
    /// the rules' embeddings it lacks (zero everywhere), as `apply` would add them.
    #[pyo3(signature = (gmap, name, params = None))]
    fn count_matches<'py>(
        &self,
        py: Python<'py>,
        gmap: &Bound<'py, PyAny>,
        name: &str,
        params: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<usize> {
        let mut g = gmap_arg(gmap)?;
        let rules = &self.inner;
        g.mutate(py, |map| {
            let params = params_arg(rules.rule(name)?, params)?;
            py.detach(|| rules.count_matches(map, name, &params))
                .map_err(Error::from)
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "<topomech._core.RuleSet dimension={} rules=[{}]>",
            self.inner.dimension(),
            self.rule_names().join(", ")
        )
    }
}

/// Checks a predicate on the rest position `x`, `y`, `z` exactly as a simulation builds a
/// fixed vertex's rule around it ([`topomech_physics::check_predicate`]): one expression of
/// the rule language, of type bool. Raises `RuleError` with the diagnostics, `label` as their
/// file and the line and column in `text`.
#[pyfunction]
#[pyo3(signature = (text, label = "predicate"))]
pub(crate) fn check_predicate(text: &str, label: &str) -> PyResult<()> {
    guard(|| topomech_physics::check_predicate(label, text).map_err(Error::Rules))
}

/// Why a blade whose segment `start` (2 points) moves to the segment `end` sweeps nothing,
/// or `None` ([`topomech_physics::sweep_problem`]: it does not move, or its four points lie
/// on one line), for a scene to name its key; both segments of two distinct finite points.
#[pyfunction]
pub(crate) fn blade_sweep_problem(
    start: [[f64; 3]; 2],
    end: [[f64; 3]; 2],
) -> PyResult<Option<String>> {
    guard(|| Ok(topomech_physics::sweep_problem(&start, &end)))
}

/// The answer of [`topomech_physics::eval_predicate`] and `eval_expression` as the bindings'
/// error: the checker's diagnostics as `RuleError`, a point where the evaluation failed as
/// `ValueError` naming the point.
fn points_error(e: topomech_physics::PointsError, points: &[[f64; 3]]) -> Error {
    match e {
        topomech_physics::PointsError::Refused(d) => Error::Rules(d),
        topomech_physics::PointsError::At(k, why) => {
            let p = points.get(k).copied().unwrap_or([f64::NAN; 3]);
            value_error(format!(
                "cannot be evaluated at ({}, {}, {}) (row {k} of the points): {why}",
                p[0], p[1], p[2]
            ))
        }
    }
}

/// `eval` (a kernel function of the label, the text and the points) over `points` (float64
/// `(N, 3)`), its values as a numpy array `(N,)`, its refusals as [`points_error`] says.
fn at_points<'py, T: numpy::Element>(
    py: Python<'py>,
    text: &str,
    points: &Bound<'py, PyAny>,
    label: &str,
    eval: impl Fn(&str, &str, &[[f64; 3]]) -> std::result::Result<Vec<T>, topomech_physics::PointsError>
        + Send
        + Sync,
) -> PyResult<Bound<'py, numpy::PyArray1<T>>> {
    let pts = guard(|| crate::convert::points_arg(points))?;
    let values = guard(|| {
        py.detach(|| eval(label, text, &pts))
            .map_err(|e| points_error(e, &pts))
    })?;
    Ok(numpy::IntoPyArray::into_pyarray(values, py))
}

/// Evaluates a predicate on `x`, `y`, `z` at each row of `points` (float64 `(N, 3)`) with the
/// kernel's own parser, checker and evaluator, as a scene's `where` is evaluated
/// ([`topomech_physics::eval_predicate`]); returns a bool array `(N,)`. Raises `RuleError`
/// with the diagnostics (`label` as their file) for a refused text, `ValueError` naming the
/// first point where it cannot be evaluated, `TypeError`/`ValueError` for bad points.
#[pyfunction]
#[pyo3(signature = (text, points, label = "predicate"))]
pub(crate) fn eval_predicate<'py>(
    py: Python<'py>,
    text: &str,
    points: &Bound<'py, PyAny>,
    label: &str,
) -> PyResult<Bound<'py, numpy::PyArray1<bool>>> {
    at_points(py, text, points, label, topomech_physics::eval_predicate)
}

/// Evaluates a number-valued expression of the rule language on `x`, `y`, `z` at each row of
/// `points` with the kernel ([`topomech_physics::eval_expression`]: `f64`, or `i64`
/// converted; no quotient of two integers); returns a float64 array `(N,)`. Raises as
/// [`eval_predicate`].
#[pyfunction]
#[pyo3(signature = (text, points, label = "expression"))]
pub(crate) fn eval_expression<'py>(
    py: Python<'py>,
    text: &str,
    points: &Bound<'py, PyAny>,
    label: &str,
) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
    at_points(py, text, points, label, topomech_physics::eval_expression)
}
