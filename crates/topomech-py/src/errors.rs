//! The one place where Rust errors become Python exceptions.
//!
//! ```text
//! Exception
//! └── TopomechError              everything the kernel refuses
//!     ├── MeshError              a mesh that cannot become a G-map (mesh::MeshError)
//!     ├── MeshReadError          a mesh file that cannot be read (raised by topomech.io)
//!     ├── TopologyError          links, sews, orbits, invalid maps
//!     ├── EmbeddingError         embeddings
//!     ├── FileFormatError        the .tmg format (io::FormatError)
//!     ├── RuleError              a rule file refused by the checker (its diagnostics)
//!     ├── ApplyError             a rule that does not apply (topomech_rules::ApplyError)
//!     ├── SimulationError        a simulation that cannot be built or stepped (PhysicsError)
//!     │   └── DivergenceError    a step that produced non-finite values (step, vertex, why)
//!     ├── SceneError             a scene file that is refused (raised by topomech.scene)
//!     ├── BusyError              a map or simulation in use by another thread
//!     └── InternalError          a bug: a Rust panic, caught before it reaches Python
//! ```
//!
//! Arguments checked at the boundary raise Python's own classes: `ValueError` for shapes and
//! values, `TypeError` for types, `IndexError` for dart and dimension indices. A file that
//! does not exist raises `FileNotFoundError` naming it ([`not_found`]), as `open` does: the
//! classes above are for files that exist and are refused.
//!
//! Every exported function runs its body through [`guard`], so a Rust panic never unwinds into
//! Python: it becomes an `InternalError` carrying the panic's message and location.
//!
//! Methods borrow their object through [`shared`] and [`exclusive`], never through `&self`:
//! an object that another thread is using (a step or a rule running without the GIL) then
//! raises `BusyError` naming it, not `PyO3`'s `RuntimeError: Already mutably borrowed`.

use std::any::Any;
use std::cell::RefCell;
use std::fmt::Display;
use std::panic::{self, AssertUnwindSafe};
use std::path::Path;
use std::sync::Once;

use pyo3::exceptions::{PyException, PyFileNotFoundError, PyIndexError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::pyclass::boolean_struct::False;
use pyo3::PyClass;
use topomech_gmap::io::FormatError;
use topomech_gmap::mesh::MeshError as KernelMeshError;
use topomech_gmap::{
    EmbeddingError as KernelEmbeddingError, GMapError, LinkError, OrbitTypeError, SewError,
};
use topomech_physics::PhysicsError;
use topomech_rules::{ApplyError as KernelApplyError, Diagnostic, Severity};

pyo3::create_exception!(
    topomech._core,
    TopomechError,
    PyException,
    "Base class of every error raised by topomech."
);
pyo3::create_exception!(
    topomech._core,
    MeshError,
    TopomechError,
    "A mesh that cannot become a G-map; the message names the cells or points. `option` is\n\
     the `(name, value)` of the build option that would accept the mesh, or `None`."
);
pyo3::create_exception!(
    topomech._core,
    MeshReadError,
    TopomechError,
    "A mesh file that cannot be read: unreadable, or not a mesh (a missing file raises\n\
     FileNotFoundError)."
);
pyo3::create_exception!(
    topomech._core,
    TopologyError,
    TopomechError,
    "A refused operation on darts, links or orbits, or a map that breaks an invariant."
);
pyo3::create_exception!(
    topomech._core,
    EmbeddingError,
    TopomechError,
    "A refused operation on an embedding (unknown name, wrong type, stale derived value)."
);
pyo3::create_exception!(
    topomech._core,
    FileFormatError,
    TopomechError,
    "A .tmg file that cannot be written or read back."
);
pyo3::create_exception!(
    topomech._core,
    RuleError,
    TopomechError,
    "A rule file refused by the checker. The message has one line per error,\n\
     `FILE:LINE:COL: error[CONDITION]: message`; `diagnostics` holds those lines as a list\n\
     and `warnings` the warnings' lines."
);
pyo3::create_exception!(
    topomech._core,
    ApplyError,
    TopomechError,
    "A rule that does not apply: unknown rule, no match at the given darts (the message says\n\
     which arc, orbit or dart failed), wrong hooks or parameters, a map that does not fit the\n\
     rules, or a failed evaluation. The map is unchanged."
);
pyo3::create_exception!(
    topomech._core,
    SimulationError,
    TopomechError,
    "A simulation that cannot be built (unknown model, a model or predicate that matches\n\
     nothing, a bad setting) or a step that fails."
);
pyo3::create_exception!(
    topomech._core,
    DivergenceError,
    SimulationError,
    "A step that produced a non-finite position or velocity, or a linear system that is not\n\
     positive definite. The simulation keeps the state before the step; `step` is the step\n\
     that failed (1-based), `vertex` the vertex (its row in the per-vertex arrays) and `why` what happened."
);
pyo3::create_exception!(
    topomech._core,
    SceneError,
    TopomechError,
    "A scene file that is refused: bad TOML, an unknown or mistyped key (the message names its\n\
     path, e.g. `integrator.dtt: unknown key`), a missing mesh, or a simulation that cannot be\n\
     built from it."
);
pyo3::create_exception!(
    topomech._core,
    BusyError,
    TopomechError,
    "A map or simulation used while another thread is using it (a call on it that runs\n\
     without the GIL, such as `Simulation.step` or `RuleSet.apply`, has not returned). The\n\
     object is unchanged by the refused call; wait for the other call, or give each thread\n\
     its own object."
);
pyo3::create_exception!(
    topomech._core,
    InternalError,
    TopomechError,
    "A bug in topomech (a Rust panic, caught at the boundary). Please report it."
);

/// Registers the exception classes in the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("TopomechError", py.get_type::<TopomechError>())?;
    let mesh_error = py.get_type::<MeshError>();
    // the default for a MeshError raised without one (e.g. by topomech.io)
    mesh_error.setattr("option", py.None())?;
    m.add("MeshError", mesh_error)?;
    m.add("MeshReadError", py.get_type::<MeshReadError>())?;
    m.add("TopologyError", py.get_type::<TopologyError>())?;
    m.add("EmbeddingError", py.get_type::<EmbeddingError>())?;
    m.add("FileFormatError", py.get_type::<FileFormatError>())?;
    m.add("RuleError", py.get_type::<RuleError>())?;
    m.add("ApplyError", py.get_type::<ApplyError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    m.add("DivergenceError", py.get_type::<DivergenceError>())?;
    m.add("SceneError", py.get_type::<SceneError>())?;
    m.add("BusyError", py.get_type::<BusyError>())?;
    m.add("InternalError", py.get_type::<InternalError>())?;
    install_panic_hook();
    Ok(())
}

/// Any error a binding can meet; `?` converts the kernel's errors into it, and `PyO3` turns it
/// into the right Python exception.
#[derive(Debug)]
pub(crate) enum Error {
    /// A mesh refused by the kernel.
    Mesh(KernelMeshError),
    /// A mesh refused at the boundary (a check the kernel cannot make, e.g. a negative index).
    MeshInput(String),
    /// Links, sews, map construction, orbit types, invalid maps.
    Topology(String),
    /// Embeddings.
    Embedding(KernelEmbeddingError),
    /// An embedding problem found by the bindings.
    EmbeddingInput(String),
    /// The `.tmg` format.
    Format(FormatError),
    /// Rule files refused by the checker: every diagnostic, errors and warnings.
    Rules(Vec<Diagnostic>),
    /// A rule that does not apply.
    Apply(KernelApplyError),
    /// A simulation that cannot be built or stepped.
    Physics(PhysicsError),
    /// An error that is already a Python exception (argument checks).
    Py(PyErr),
}

impl From<KernelMeshError> for Error {
    fn from(e: KernelMeshError) -> Self {
        Error::Mesh(e)
    }
}

impl From<LinkError> for Error {
    fn from(e: LinkError) -> Self {
        Error::Topology(e.to_string())
    }
}

impl From<SewError> for Error {
    fn from(e: SewError) -> Self {
        Error::Topology(e.to_string())
    }
}

impl From<GMapError> for Error {
    fn from(e: GMapError) -> Self {
        Error::Topology(e.to_string())
    }
}

impl From<OrbitTypeError> for Error {
    fn from(e: OrbitTypeError) -> Self {
        Error::Topology(e.to_string())
    }
}

impl From<KernelEmbeddingError> for Error {
    fn from(e: KernelEmbeddingError) -> Self {
        Error::Embedding(e)
    }
}

impl From<FormatError> for Error {
    fn from(e: FormatError) -> Self {
        Error::Format(e)
    }
}

impl From<KernelApplyError> for Error {
    fn from(e: KernelApplyError) -> Self {
        Error::Apply(e)
    }
}

impl From<PhysicsError> for Error {
    fn from(e: PhysicsError) -> Self {
        Error::Physics(e)
    }
}

impl From<PyErr> for Error {
    fn from(e: PyErr) -> Self {
        Error::Py(e)
    }
}

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        match e {
            Error::Mesh(e) => mesh_error(e.to_string(), e.option()),
            Error::MeshInput(msg) => mesh_error(msg, None),
            Error::Topology(msg) => TopologyError::new_err(msg),
            Error::Embedding(e) => EmbeddingError::new_err(e.to_string()),
            Error::EmbeddingInput(msg) => EmbeddingError::new_err(msg),
            Error::Format(FormatError::Io { path, source })
                if source.kind() == std::io::ErrorKind::NotFound =>
            {
                not_found_err(&path)
            }
            Error::Format(e) => FileFormatError::new_err(e.to_string()),
            Error::Rules(diags) => rule_error(&diags),
            Error::Apply(e) => ApplyError::new_err(e.to_string()),
            Error::Physics(e) => physics_error(&e),
            Error::Py(e) => e,
        }
    }
}

/// The diagnostics of `severity`, one `FILE:LINE:COL: severity[CONDITION]: message` each.
fn diagnostic_lines(diags: &[Diagnostic], severity: Severity) -> Vec<String> {
    diags
        .iter()
        .filter(|d| d.severity == severity)
        .map(ToString::to_string)
        .collect()
}

/// A `RuleError` whose message is the error lines, with `diagnostics` (the error lines) and
/// `warnings` (the warning lines) as attributes.
fn rule_error(diags: &[Diagnostic]) -> PyErr {
    let errors = diagnostic_lines(diags, Severity::Error);
    let warnings = diagnostic_lines(diags, Severity::Warning);
    let err = RuleError::new_err(errors.join("\n"));
    Python::attach(|py| {
        let value = err.value(py);
        match value
            .setattr("diagnostics", errors)
            .and_then(|()| value.setattr("warnings", warnings))
        {
            Ok(()) => err,
            Err(e) => e,
        }
    })
}

/// A `MeshError` with `option`: the `(name, value)` of the build option that would accept
/// the mesh (e.g. `("pinched", "split")`), or `None`. The message names no option; the
/// Python layer appends it in the user's syntax.
fn mesh_error(msg: String, option: Option<(&'static str, &'static str)>) -> PyErr {
    let err = MeshError::new_err(msg);
    Python::attach(|py| match err.value(py).setattr("option", option) {
        Ok(()) => err,
        Err(e) => e,
    })
}

/// A `DivergenceError` with `step`, `vertex` (None for a failure of a global linear solve),
/// `point` (that row's input point, None where unknown) and `why` for a divergence, else a
/// `SimulationError` with the kernel's message.
fn physics_error(e: &PhysicsError) -> PyErr {
    let PhysicsError::Diverged {
        step,
        vertex,
        point,
        why,
    } = e
    else {
        return SimulationError::new_err(e.to_string());
    };
    let err = DivergenceError::new_err(e.to_string());
    Python::attach(|py| {
        let value = err.value(py);
        match value
            .setattr("step", *step)
            .and_then(|()| value.setattr("vertex", *vertex))
            .and_then(|()| value.setattr("point", *point))
            .and_then(|()| value.setattr("why", why.as_str()))
        {
            Ok(()) => err,
            Err(e) => e,
        }
    })
}

/// `errno.ENOENT`: the same number on every platform Python runs on.
const ENOENT: i32 = 2;

/// The `FileNotFoundError` of a missing `path`, as `open` raises it: `errno` `ENOENT`,
/// `filename` the path, and the message `[Errno 2] No such file or directory: 'PATH'`.
fn not_found_err(path: &str) -> PyErr {
    PyFileNotFoundError::new_err((ENOENT, "No such file or directory", path.to_string()))
}

/// A `FileNotFoundError` naming `path` (a file to read that does not exist).
pub(crate) fn not_found(path: &Path) -> Error {
    Error::Py(not_found_err(&path.display().to_string()))
}

/// A `ValueError` (bad shape or value of an argument).
pub(crate) fn value_error(msg: impl Display) -> Error {
    Error::Py(PyValueError::new_err(msg.to_string()))
}

/// A `TypeError` (an argument of the wrong type).
pub(crate) fn type_error(msg: impl Display) -> Error {
    Error::Py(PyTypeError::new_err(msg.to_string()))
}

/// An `IndexError` (a dart or dimension out of range).
pub(crate) fn index_error(msg: impl Display) -> Error {
    Error::Py(PyIndexError::new_err(msg.to_string()))
}

/// The `BusyError` of a `what` (e.g. "Simulation") that another thread is using.
fn busy_error(what: &str, writing: bool) -> PyErr {
    BusyError::new_err(format!(
        "this {what} is busy: another thread is {} it (a call on it has not returned yet); \
         wait for that call to finish, or give each thread its own {what}",
        if writing { "changing" } else { "using" }
    ))
}

/// The Python object's name, for messages.
fn class_name<T: PyClass>(slf: &Bound<'_, T>) -> String {
    slf.as_any()
        .get_type()
        .name()
        .map_or_else(|_| "object".to_string(), |n| n.to_string())
}

/// `slf` borrowed for reading, or `BusyError` when another thread is changing it.
pub(crate) fn shared<'py, T: PyClass>(slf: &Bound<'py, T>) -> PyResult<PyRef<'py, T>> {
    slf.try_borrow()
        .map_err(|_| busy_error(&class_name(slf), true))
}

/// `slf` borrowed for writing, or `BusyError` when another thread is using it.
pub(crate) fn exclusive<'py, T: PyClass<Frozen = False>>(
    slf: &Bound<'py, T>,
) -> PyResult<PyRefMut<'py, T>> {
    slf.try_borrow_mut().map_err(|_| {
        // a failed shared borrow means a writer holds it; otherwise readers do
        let writing = slf.try_borrow().is_err();
        busy_error(&class_name(slf), writing)
    })
}

/// The result type of the bindings' internals.
pub(crate) type Result<T, E = Error> = std::result::Result<T, E>;

/// Runs `f`, turning a panic into `InternalError` and an [`Error`] into its Python exception.
///
/// Every exported function goes through here: a Rust panic must never unwind into Python.
pub(crate) fn guard<T>(f: impl FnOnce() -> Result<T>) -> PyResult<T> {
    match panic::catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r.map_err(PyErr::from),
        Err(payload) => Err(InternalError::new_err(panic_report(payload.as_ref()))),
    }
}

thread_local! {
    /// Where the last panic on this thread happened, recorded by the hook for [`guard`].
    static LAST_PANIC_LOCATION: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Replaces the default panic hook (which prints to stderr) by one that records the location
/// for the `InternalError` message; with `TOPOMECH_BACKTRACE=1` the default hook runs too.
/// The hook belongs to this extension's copy of the Rust runtime only.
fn install_panic_hook() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let default_hook = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            let location = info.location().map(ToString::to_string);
            LAST_PANIC_LOCATION.with(|l| *l.borrow_mut() = location);
            if std::env::var_os("TOPOMECH_BACKTRACE").is_some_and(|v| v != "0") {
                default_hook(info);
            }
        }));
    });
}

/// The message of an `InternalError`: the panic's payload and where it happened.
fn panic_report(payload: &(dyn Any + Send)) -> String {
    let msg = if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic payload".to_string()
    };
    let at = LAST_PANIC_LOCATION
        .with(|l| l.borrow_mut().take())
        .map(|loc| format!(" at {loc}"))
        .unwrap_or_default();
    format!("internal error in topomech (Rust panic{at}): {msg}; please report this bug")
}
