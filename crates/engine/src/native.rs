//! The door from the engine to a code generator: what a backend that compiles a plan's
//! register program (`compiled::Program`) to native code implements, and the run-time table
//! the generated code reads.
//!
//! The engine defines this interface and never names a backend: a rule set runs native code
//! only when one is handed to it ([`RuleSet::set_backend`](crate::RuleSet::set_backend), or
//! the process-wide default of [`set_default_backend`]); without one, compiled plans run the
//! evaluator, which stays the reference and the fallback. `topomech-codegen` implements it
//! with Cranelift, and the facade `topomech-rules` installs that backend in the rule sets it
//! builds.
//!
//! **The switch.** A plan built while its rule set's switch is on
//! ([`RuleSet::set_jit`](crate::RuleSet::set_jit); default: on, unless the environment
//! variable `TOPOMECH_JIT` is `0`, `false`, `off` or `no`, see [`enabled_by_env`]) and a
//! backend is installed generates its code at its first run, once, and runs it per chunk
//! with the evaluator's chunking and rayon parallelism.
//! [`RuleSet::plan_native`](crate::RuleSet::plan_native) tells which plans run native code.
//!
//! **No host pointer is baked into the code.** Every array the row loop touches and every
//! helper function comes through the [`JitArgs`] table passed at run time: the table is the
//! whole interface between a plan and its code.
// The interface declares `NativeFn::call`, an `unsafe fn` (the generated code trusts the
// table it is given), and `JitArgs`'s `Sync`, each with its safety contract below.
#![allow(unsafe_code)]

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

use crate::compiled::Program;

/// The run-time table of a native plan function: addresses of arrays of addresses, one entry
/// per column, gather, aggregate, count array, fill, helper call. The generated code reads
/// field `k` at byte offset `8 * k` (64-bit targets only).
#[repr(C)]
#[derive(Debug)]
pub struct JitArgs {
    /// Per program column: the base of its values (`f64`, `bool` or `i64`, see [`ColKind`]).
    pub cols: *const *const u8,
    /// Per gather: its slot per domain row.
    pub gathers: *const *const u32,
    /// Per aggregate: CSR offsets (rows + 1).
    pub offs: *const *const u32,
    /// Per aggregate: CSR slots.
    pub slots: *const *const u32,
    /// Per aggregate: per-row counts.
    pub counts: *const *const f64,
    /// Per fill: its values.
    pub fills: *const *const f64,
    /// The plan's output buffer.
    pub out: *mut f64,
    /// Per helper call site: its descriptor, opaque to the engine
    /// ([`NativeFn::call_table`]).
    pub calls: *const *const u8,
    /// The backend's helper functions ([`NativeFn::helper_table`]).
    pub helpers: *const *const u8,
}

// SAFETY: the table is only read by the generated code, and each call writes only the output
// rows of its own chunk, so several threads may run calls with one table at once (on
// distinct chunks, as `Plan::run` does).
unsafe impl Sync for JitArgs {}

/// The element type of a column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColKind {
    /// `f64` values.
    Real,
    /// `bool` values (one byte each).
    Bool,
    /// `i64` values.
    Int,
}

/// The layout of a plan's output buffer (see `Plan::out_index`): a chunk's block holds
/// `chunk * out_width` floats, each write's rows contiguous from `offsets[write] * chunk`.
#[derive(Debug)]
pub struct OutLayout<'a> {
    /// Rows per chunk (a power of two).
    pub chunk: usize,
    /// Floats per output row.
    pub out_width: usize,
    /// Per write, its offset in an output row.
    pub offsets: &'a [usize],
}

/// A program compiled to native code by a [`NativeBackend`].
pub trait NativeFn: Send + Sync + std::fmt::Debug {
    /// The column kinds the code was generated for.
    fn kinds(&self) -> &[ColKind];

    /// The addresses [`JitArgs::calls`] must list, in order: the descriptors of the code's
    /// helper call sites, valid (and unchanged) as long as `self` lives.
    fn call_table(&self) -> Vec<*const u8>;

    /// The addresses [`JitArgs::helpers`] must list, in order.
    fn helper_table(&self) -> Vec<*const u8>;

    /// Runs rows `first..first + n` (all in one chunk), storing each write's values into
    /// `args.out` where the evaluator stores them; nonzero where the evaluator would fail.
    ///
    /// # Safety
    /// `args` must describe arrays for which the code was generated: the column kinds
    /// [`NativeFn::kinds`], every index array covering rows `first..first + n`, every slot
    /// they hold inside its column, fills of their registers' widths, an output buffer
    /// covering the chunk of these rows, `calls` and `helpers` the tables of
    /// [`NativeFn::call_table`] and [`NativeFn::helper_table`] of `self`; and no other thread
    /// may write the same rows' output at the same time.
    unsafe fn call(&self, args: &JitArgs, first: usize, n: usize) -> u32;
}

/// A code generator for compiled plans (`topomech-codegen` implements it with Cranelift).
pub trait NativeBackend: Send + Sync + std::fmt::Debug {
    /// Compiles `prog` for columns of the kinds `kinds`, with `n_aggs` aggregates and the
    /// output buffer laid out as `layout`; `Err` names what is not covered (the plan then
    /// keeps using the evaluator). The code must give the evaluator's results bit for bit.
    fn compile(
        &self,
        prog: &Program,
        kinds: &[ColKind],
        n_aggs: usize,
        layout: &OutLayout,
    ) -> Result<Arc<dyn NativeFn>, String>;
}

/// The process-wide default backend (see [`set_default_backend`]).
static DEFAULT: OnceLock<Arc<dyn NativeBackend>> = OnceLock::new();

/// Sets the backend [`RuleSet::new`](crate::RuleSet::new) hands every rule set it creates
/// from now on, once per process: `false` (and nothing changes) if one is already set.
///
/// Why a default besides [`RuleSet::set_backend`](crate::RuleSet::set_backend): the engine
/// cannot name its code generator (the door goes the other way), and callers of the facade
/// build rule sets with `RuleSet::new` on checked rules of their own; the facade registers
/// its backend here from each of its entry points that give checked rules or rule sets, so
/// those callers keep native code unchanged.
pub fn set_default_backend(backend: Arc<dyn NativeBackend>) -> bool {
    DEFAULT.set(backend).is_ok()
}

/// The process-wide default backend, if one is set (see [`set_default_backend`]).
pub fn default_backend() -> Option<Arc<dyn NativeBackend>> {
    DEFAULT.get().cloned()
}

/// Runs of native code that checked and scattered their values chunk by chunk (see
/// `Plan::run_chunked` in `compiled.rs`), failed ones included, in this process.
pub(crate) static CHUNKED: AtomicU64 = AtomicU64::new(0);

/// The number of plan runs so far in this process whose native code checked each chunk's
/// values as soon as the chunk was evaluated and then scattered them chunk by chunk (in
/// parallel where the plan runs in parallel), failed ones included: what tests check to
/// know that path ran.
pub fn chunked_runs() -> u64 {
    CHUNKED.load(Ordering::Relaxed)
}

/// Whether compiled plans run native code by default: the environment variable
/// `TOPOMECH_JIT` (`0`, `false`, `off`, `no`, in any case: off; unset or anything else: on),
/// read once per process.
///
/// On by default: on every shipped model and integrator the native code gives the
/// evaluator's bits (tests `physics/tests/jit.rs`, `rules/tests/jit.rs`), compiles in a few
/// milliseconds per plan, and steps faster (see the `engine` bench of `topomech-physics`).
pub fn enabled_by_env() -> bool {
    static ON: OnceLock<bool> = OnceLock::new();
    *ON.get_or_init(|| {
        std::env::var("TOPOMECH_JIT").map_or(true, |v| {
            !matches!(
                v.trim().to_ascii_lowercase().as_str(),
                "0" | "false" | "off" | "no"
            )
        })
    })
}
