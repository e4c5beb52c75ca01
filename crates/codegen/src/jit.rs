//! Native code for compiled plans, generated with Cranelift: the first slice of a code
//! generator.
//!
//! `compile` turns a plan's register `Program` into one native function
//! `extern "C" fn(args: *const JitArgs, first: u64, n: u64) -> u32` that evaluates rows
//! `first..first + n` (all in one chunk) and stores each write's values into the plan's output
//! buffer exactly where the engine's evaluator (`Ctx::chunk` in `topomech_engine`'s
//! `compiled.rs`) stores them, in the same
//! layout. Inside a row, registers are SSA values (one `f64` value per float of a register's
//! width): the intermediates stay in machine registers instead of going through scratch.
//!
//! **No host pointer is baked into the code.** Every array the row loop touches (column
//! bases, gather index arrays, CSR offsets and slots, counts, fill values, the output buffer)
//! and every helper function (the `extern "C"` trampoline to the Rust built-ins, `fma` where
//! the host lacks it) comes through the `JitArgs` table passed at run time; the code only
//! adds offsets to what it loads from that table. That is what lets another backend (a GPU
//! one) compile the same form later: the table is the whole interface.
//!
//! **Bit identity.** The code performs the evaluator's IEEE operations in the evaluator's
//! order: sums start as the evaluator's do (`0.0 + p0 + ...` for products, the first value
//! for aggregates and `Iterator::sum`), no multiply-add is fused except where the evaluator
//! itself calls `mul_add` (`cross`, through `diff_of_products`), and the built-ins that are
//! not generated natively (`polar`, transcendental functions, `%`, generic built-ins) are
//! called through the table, running the evaluator's own Rust code. Non-finite results are
//! caught by the plan's existing scan of its output buffer; a helper that refuses its argument
//! makes the function return a nonzero code, which the plan treats as the evaluator's `Err`.
//!
//! An operation not covered here makes `compile` fail: the plan then keeps using the
//! evaluator, which stays the reference and the fallback.
//!
//! **The switch.** A plan built while its rule set's switch is on ([`RuleSet::set_jit`];
//! default: on, unless the environment variable `TOPOMECH_JIT` is `0`, `false`, `off` or `no`)
//! and [`Cranelift`] is its backend ([`RuleSet::set_backend`]; the facade `topomech-rules`
//! installs it) generates its code at its first run, once (a few milliseconds), and runs it
//! per chunk with the evaluator's chunking and rayon parallelism. `compiled_count` counts the
//! programs compiled, and [`RuleSet::plan_native`] tells which plans run native code.
//!
//! **The door.** This module implements the engine's interface
//! ([`topomech_engine::native`]): [`Cranelift`] is a [`NativeBackend`], and what it compiles
//! a [`NativeFn`] called with the engine's [`JitArgs`] table.
//!
//! **Lifetime.** The function pointer points into memory owned by the `JITModule` kept in
//! `Native`; `Native` never hands the pointer out and frees the module's memory only when
//! it is dropped, so no call can outlive the code (the engine holds a plan's code as an
//! `Arc<dyn NativeFn>` for as long as it may call it).
#![allow(unsafe_code)]

use std::sync::atomic::{AtomicU64, Ordering};

use cranelift_codegen::ir::condcodes::{FloatCC, IntCC};
use cranelift_codegen::ir::{
    types, AbiParam, InstBuilder, MemFlagsData, SigRef, StackSlotData, StackSlotKind, UserFuncName,
    Value,
};
use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{default_libcall_names, Linkage, Module};

use std::sync::Arc;

use topomech_engine::compiled::{Cmp, Ew, Fast, Op, Program};
use topomech_engine::native::{ColKind, JitArgs, NativeBackend, NativeFn, OutLayout};
#[cfg(doc)]
use topomech_engine::RuleSet;
use topomech_lang::builtins;
use topomech_lang::value::Ty;

pub use topomech_engine::native::chunked_runs;

/// The Cranelift code generator, as the engine's backend for compiled plans' native code.
#[derive(Clone, Copy, Debug, Default)]
pub struct Cranelift;

impl NativeBackend for Cranelift {
    fn compile(
        &self,
        prog: &Program,
        kinds: &[ColKind],
        n_aggs: usize,
        layout: &OutLayout,
    ) -> Result<Arc<dyn NativeFn>, String> {
        Ok(Arc::new(compile(prog, kinds, n_aggs, layout)?))
    }
}

/// What a helper call site computes (through [`jit_call`], with the evaluator's code).
#[derive(Debug)]
enum Call {
    F1(fn(f64) -> f64),
    F2(fn(f64, f64) -> f64),
    Rem,
    Fast {
        f: Fast,
        wa: usize,
        two: bool,
    },
    Generic {
        name: String,
        args: Vec<(usize, Ty)>,
        ty: Ty,
    },
}

type Func = unsafe extern "C" fn(*const JitArgs, u64, u64) -> u32;

/// A program compiled to native code.
struct Native {
    module: Option<JITModule>,
    func: Func,
    /// Per helper call site, its descriptor (never changed after `compile`: the table holds
    /// their addresses).
    calls: Vec<Call>,
    /// The column kinds the code was generated for.
    kinds: Vec<ColKind>,
}

impl std::fmt::Debug for Native {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Native")
            .field("calls", &self.calls)
            .field("kinds", &self.kinds)
            .finish_non_exhaustive()
    }
}

// SAFETY: after `finalize_definitions` the module is never mutated again; the only use of it
// is calling the finalized function (which has no state of its own: everything it touches
// comes through its arguments) and freeing it on drop, which takes `&mut self`. Sharing the
// function between threads is as sound as sharing a `fn` pointer.
unsafe impl Send for Native {}
// SAFETY: see `Send` above: `&Native` only allows calling the stateless finalized function.
unsafe impl Sync for Native {}

impl Drop for Native {
    fn drop(&mut self) {
        if let Some(m) = self.module.take() {
            // SAFETY: `func` points into this module's memory and is dropped with `self`;
            // no call is in flight (dropping needs `&mut self`, a call holds `&self`).
            unsafe { m.free_memory() };
        }
    }
}

/// Tests: generate code as for a host without FMA and SSE4.1 (helper calls for `fma`, `floor`
/// and `ceil`).
#[cfg(test)]
static PORTABLE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

fn portable() -> bool {
    #[cfg(test)]
    {
        PORTABLE.load(Ordering::Relaxed)
    }
    #[cfg(not(test))]
    {
        false
    }
}

/// Natively compiled programs so far (in this process).
static COMPILED: AtomicU64 = AtomicU64::new(0);

/// The number of programs compiled to native code so far in this process.
pub fn compiled_count() -> u64 {
    COMPILED.load(Ordering::Relaxed)
}

impl NativeFn for Native {
    fn kinds(&self) -> &[ColKind] {
        &self.kinds
    }

    /// The descriptors' addresses: `calls` is never changed after `compile` and lives as
    /// long as `self`.
    fn call_table(&self) -> Vec<*const u8> {
        self.calls
            .iter()
            .map(|c| (&raw const *c).cast::<u8>())
            .collect()
    }

    /// `[jit_call, fma]`.
    fn helper_table(&self) -> Vec<*const u8> {
        vec![jit_call as *const u8, jit_fma as *const u8]
    }

    /// Runs rows `first..first + n`.
    ///
    /// # Safety
    /// The contract of [`NativeFn::call`]: `args` describes arrays for which the code was
    /// generated (the column kinds `self.kinds`, index arrays covering the rows, slots inside
    /// their columns, fills of their registers' widths, an output buffer covering the
    /// rows' chunk, `calls` and `helpers` this function's `call_table` and `helper_table`),
    /// and no other thread writes the same rows' output at the same time.
    unsafe fn call(&self, args: &JitArgs, first: usize, n: usize) -> u32 {
        // SAFETY: the caller's contract above is exactly what the generated code reads and
        // writes (see `compile`: it reads each array at the row's index or at slots read from
        // the index arrays, calls the helpers of `helper_table` with the descriptors of
        // `call_table`, and writes the output at `Plan::out_index` of these rows).
        unsafe { (self.func)(args, first as u64, n as u64) }
    }
}

/// The helper behind every call site the code does not compute natively: evaluates `c` on
/// the floats at `args` into `out`, with the evaluator's own code. Returns 0, or 1 where the
/// evaluator would fail (a built-in refusing its argument), 2 on a panic.
extern "C" fn jit_call(c: *const Call, args: *const f64, out: *mut f64) -> u32 {
    // SAFETY: the generated code passes the descriptor from the table (an address of
    // `Native::call_table`, which the engine must put in `JitArgs::calls`: a live `Call` of
    // the `Native` being run, in its never-changed `calls`) and two stack buffers of the
    // lengths `arg_len` and `out_len` give for this descriptor.
    let c = unsafe { &*c };
    let (na, nw) = (arg_len(c), out_len(c));
    // SAFETY: see above: `args` holds `na` floats, `out` `nw`, and they do not overlap.
    let (x, z) = unsafe {
        (
            std::slice::from_raw_parts(args, na),
            std::slice::from_raw_parts_mut(out, nw),
        )
    };
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| helper(c, x, z)));
    match r {
        Ok(Ok(())) => 0,
        Ok(Err(())) => 1,
        Err(_) => 2,
    }
}

extern "C" fn jit_fma(a: f64, b: f64, c: f64) -> f64 {
    a.mul_add(b, c)
}

fn arg_len(c: &Call) -> usize {
    match c {
        Call::F1(_) => 1,
        Call::F2(_) | Call::Rem => 2,
        Call::Fast { wa, two, .. } => wa * if *two { 2 } else { 1 },
        Call::Generic { args, .. } => args.iter().map(|a| a.0).sum(),
    }
}

fn out_len(c: &Call) -> usize {
    match c {
        Call::F1(_) | Call::F2(_) | Call::Rem => 1,
        Call::Fast { f, wa, .. } => match f {
            Fast::Dot | Fast::Norm | Fast::Norm2 | Fast::Cross2 | Fast::Trace => 1,
            _ => *wa,
        },
        Call::Generic { ty, .. } => ty.width(),
    }
}

fn helper(c: &Call, x: &[f64], z: &mut [f64]) -> Result<(), ()> {
    match c {
        Call::F1(f) => z[0] = f(x[0]),
        Call::F2(f) => z[0] = f(x[0], x[1]),
        Call::Rem => z[0] = Ew::Rem.apply(x[0], x[1]),
        Call::Fast { f, wa, two } => {
            let (a, b) = x.split_at(*wa);
            topomech_engine::compiled::fast(*f, a, two.then_some(b), z)?;
        }
        Call::Generic { name, args, ty } => {
            if topomech_engine::compiled::generic_flat(name, x, z) {
                return Ok(());
            }
            let mut vals = Vec::with_capacity(args.len());
            let mut at = 0;
            for &(w, t) in args {
                let v = &x[at..at + w];
                at += w;
                vals.push(topomech_engine::compiled::register_val(t, v));
            }
            let v = builtins::call(name, &vals).map_err(|_| ())?;
            if v.ty() != *ty {
                return Err(());
            }
            let mut buf = Vec::with_capacity(z.len());
            v.to_reals(&mut buf);
            if buf.len() != z.len() {
                return Err(());
            }
            z.copy_from_slice(&buf);
        }
    }
    Ok(())
}

/// Whether `Iterator::sum` of `f64` starts from `-0.0` (then `sum(p0, ...)` is `p0 + ...`
/// bit for bit) rather than `+0.0`.
fn sum_starts_at_neg_zero() -> bool {
    std::iter::empty::<f64>().sum::<f64>().is_sign_negative()
}

struct Gen<'a, 'b> {
    b: FunctionBuilder<'b>,
    fl: MemFlagsData,
    /// Loaded table bases.
    cols: Vec<Value>,
    gathers: Vec<Value>,
    offs: Vec<Value>,
    slots: Vec<Value>,
    counts: Vec<Value>,
    out: Value,
    calls_tbl: Value,
    helper: Value,
    fma_helper: Value,
    helper_sig: SigRef,
    fma_sig: SigRef,
    has_fma: bool,
    has_sse41: bool,
    neg_zero_sum: bool,
    calls: &'a mut Vec<Call>,
}

impl Gen<'_, '_> {
    fn f(&mut self, x: f64) -> Value {
        self.b.ins().f64const(x)
    }
    fn bool_f(&mut self, c: Value) -> Value {
        let (one, zero) = (self.f(1.0), self.f(0.0));
        self.b.ins().select(c, one, zero)
    }
    /// `Iterator::sum` of `xs` (non-empty).
    fn rust_sum(&mut self, xs: &[Value]) -> Value {
        let mut acc = if self.neg_zero_sum {
            xs[0]
        } else {
            let z = self.f(0.0);
            self.b.ins().fadd(z, xs[0])
        };
        for &x in &xs[1..] {
            acc = self.b.ins().fadd(acc, x);
        }
        acc
    }
    fn fma(&mut self, a: Value, b: Value, c: Value) -> Value {
        if self.has_fma {
            self.b.ins().fma(a, b, c)
        } else {
            let inst = self
                .b
                .ins()
                .call_indirect(self.fma_sig, self.fma_helper, &[a, b, c]);
            self.b.inst_results(inst)[0]
        }
    }
    fn diff_of_products(&mut self, a: Value, b: Value, c: Value, d: Value) -> Value {
        let w = self.b.ins().fmul(c, d);
        let nc = self.b.ins().fneg(c);
        let e = self.fma(nc, d, w);
        let nw = self.b.ins().fneg(w);
        let f = self.fma(a, b, nw);
        self.b.ins().fadd(f, e)
    }
    fn max_abs(&mut self, x: &[Value]) -> Value {
        let mut m = self.f(0.0);
        for &v in x {
            let a = self.b.ins().fabs(v);
            m = self.b.ins().fmax(m, a);
        }
        m
    }
    /// `builtins::norm`: the square root of the sum of squares where that sum lies in
    /// `[NORM_DIRECT_MIN, f64::MAX]`, else (a branch to a block of its own, rarely taken)
    /// [`Gen::norm_scaled`].
    fn norm(&mut self, x: &[Value]) -> Value {
        let sq: Vec<Value> = x.iter().map(|&v| self.b.ins().fmul(v, v)).collect();
        let s = self.rust_sum(&sq);
        let lo = self.f(builtins::NORM_DIRECT_MIN);
        let hi = self.f(f64::MAX);
        // false for NaN: ordered comparisons
        let ge = self.b.ins().fcmp(FloatCC::GreaterThanOrEqual, s, lo);
        let le = self.b.ins().fcmp(FloatCC::LessThanOrEqual, s, hi);
        let direct = self.b.ins().band(ge, le);
        let scaled = self.b.create_block();
        let join = self.b.create_block();
        let r = self.b.append_block_param(join, types::F64);
        let root = self.b.ins().sqrt(s);
        self.b.ins().brif(direct, join, &[root.into()], scaled, &[]);
        self.b.set_cold_block(scaled);
        self.b.switch_to_block(scaled);
        let m = self.norm_scaled(x);
        self.b.ins().jump(join, &[m.into()]);
        self.b.switch_to_block(join);
        r
    }
    /// `builtins::norm_scaled`, branches as selects.
    fn norm_scaled(&mut self, x: &[Value]) -> Value {
        let m = self.max_abs(x);
        let zero = self.f(0.0);
        let inf = self.f(f64::INFINITY);
        let nz = self.b.ins().fcmp(FloatCC::NotEqual, m, zero);
        let fin = self.b.ins().fcmp(FloatCC::LessThan, m, inf);
        let normal = self.b.ins().band(nz, fin);
        let sq: Vec<Value> = x
            .iter()
            .map(|&v| {
                let q = self.b.ins().fdiv(v, m);
                self.b.ins().fmul(q, q)
            })
            .collect();
        let s = self.rust_sum(&sq);
        let r = self.b.ins().sqrt(s);
        let r = self.b.ins().fmul(m, r);
        self.b.ins().select(normal, r, m)
    }
    /// A call through [`jit_call`]; on a nonzero code the function returns it.
    fn call(&mut self, c: Call, args: &[Value]) -> Vec<Value> {
        let (na, nw) = (arg_len(&c), out_len(&c));
        debug_assert_eq!(na, args.len());
        let k = self.calls.len();
        self.calls.push(c);
        let ss = self.b.create_sized_stack_slot(StackSlotData::new(
            StackSlotKind::ExplicitSlot,
            ((na + nw) * 8) as u32,
            3,
        ));
        for (j, &a) in args.iter().enumerate() {
            self.b.ins().stack_store(types::I64, a, ss, (j * 8) as i32);
        }
        let pa = self.b.ins().stack_addr(types::I64, ss, 0);
        let po = self.b.ins().stack_addr(types::I64, ss, (na * 8) as i32);
        let desc = self
            .b
            .ins()
            .load(types::I64, self.fl, self.calls_tbl, (k * 8) as i32);
        let inst = self
            .b
            .ins()
            .call_indirect(self.helper_sig, self.helper, &[desc, pa, po]);
        let code = self.b.inst_results(inst)[0];
        let fail = self.b.create_block();
        let cont = self.b.create_block();
        self.b.ins().brif(code, fail, &[], cont, &[]);
        self.b.switch_to_block(fail);
        self.b.ins().return_(&[code]);
        self.b.switch_to_block(cont);
        (0..nw)
            .map(|j| {
                self.b
                    .ins()
                    .stack_load(types::I64, types::F64, ss, ((na + j) * 8) as i32)
            })
            .collect()
    }
}

/// Compiles `prog` for columns of the kinds `kinds`; `Err` names what is not covered.
#[allow(clippy::too_many_lines)]
fn compile(
    prog: &Program,
    kinds: &[ColKind],
    n_aggs: usize,
    layout: &OutLayout,
) -> Result<Native, String> {
    let mut fb = settings::builder();
    let set = |fb: &mut settings::Builder, k: &str, v: &str| {
        fb.set(k, v).map_err(|e| format!("cranelift flag {k}: {e}"))
    };
    set(&mut fb, "use_colocated_libcalls", "false")?;
    set(&mut fb, "is_pic", "false")?;
    set(&mut fb, "opt_level", "speed")?;
    // frames larger than a page probe the stack inline (a call to a probe function would be
    // a symbol resolved into the code)
    set(&mut fb, "enable_probestack", "true")?;
    set(&mut fb, "probestack_strategy", "inline")?;
    let isa = cranelift_native::builder()
        .map_err(|e| format!("no native target: {e}"))?
        .finish(settings::Flags::new(fb))
        .map_err(|e| format!("cranelift isa: {e}"))?;
    if isa.pointer_type() != types::I64 {
        return Err("a target without 64-bit pointers".into());
    }
    let flag = |name: &str| {
        isa.isa_flags()
            .iter()
            .any(|v| v.name == name && v.as_bool() == Some(true))
    };
    let (has_fma, has_sse41) = (
        flag("has_fma") && !portable(),
        flag("has_sse41") && !portable(),
    );
    let mut module = JITModule::new(JITBuilder::with_isa(isa, default_libcall_names()));
    let mut ctx = module.make_context();
    let ptr = types::I64;
    let mut sig = module.make_signature();
    sig.params.extend([AbiParam::new(ptr); 3]);
    sig.returns.push(AbiParam::new(types::I32));
    let mut hsig = module.make_signature();
    hsig.params.extend([AbiParam::new(ptr); 3]);
    hsig.returns.push(AbiParam::new(types::I32));
    let mut fsig = module.make_signature();
    fsig.params.extend([AbiParam::new(types::F64); 3]);
    fsig.returns.push(AbiParam::new(types::F64));
    let id = module
        .declare_function("plan", Linkage::Local, &sig)
        .map_err(|e| e.to_string())?;
    ctx.func.signature = sig;
    ctx.func.name = UserFuncName::user(0, id.as_u32());
    let tcfg = module.target_config();
    let mut fctx = FunctionBuilderContext::new();
    let mut calls = Vec::new();
    {
        let mut b = FunctionBuilder::new(&mut ctx.func, &mut fctx);
        let helper_sig = b.import_signature(hsig);
        let fma_sig = b.import_signature(fsig);
        let entry = b.create_block();
        b.append_block_params_for_function_params(entry);
        b.switch_to_block(entry);
        let p = b.block_params(entry).to_vec();
        let (args, first, n) = (p[0], p[1], p[2]);
        let fl = MemFlagsData::trusted();
        let field = |b: &mut FunctionBuilder, k: i32| b.ins().load(ptr, fl, args, 8 * k);
        let tbl: Vec<Value> = (0..9).map(|k| field(&mut b, k)).collect();
        let load_all = |b: &mut FunctionBuilder, t: Value, n: usize| -> Vec<Value> {
            (0..n)
                .map(|k| b.ins().load(ptr, fl, t, (8 * k) as i32))
                .collect()
        };
        let n_gathers = prog
            .ops
            .iter()
            .filter_map(|o| match o {
                Op::Gather { idx, .. } => Some(idx + 1),
                _ => None,
            })
            .max()
            .unwrap_or(0);
        let cols = load_all(&mut b, tbl[0], kinds.len());
        let gathers = load_all(&mut b, tbl[1], n_gathers);
        let offs = load_all(&mut b, tbl[2], n_aggs);
        let slots = load_all(&mut b, tbl[3], n_aggs);
        let counts = load_all(&mut b, tbl[4], n_aggs);
        let helpers = tbl[8];
        let helper = b.ins().load(ptr, fl, helpers, 0);
        let fma_helper = b.ins().load(ptr, fl, helpers, 8);
        let mut g = Gen {
            b,
            fl,
            cols,
            gathers,
            offs,
            slots,
            counts,
            out: tbl[6],
            calls_tbl: tbl[7],
            helper,
            fma_helper,
            helper_sig,
            fma_sig,
            has_fma,
            has_sse41,
            neg_zero_sum: sum_starts_at_neg_zero(),
            calls: &mut calls,
        };
        // registers: one SSA value per float; fills are loaded once, before the row loop
        let mut v: Vec<Vec<Value>> = vec![Vec::new(); prog.regs.len()];
        for op in &prog.ops {
            if let Op::Fill { dst, at } = op {
                let fp = g.b.ins().load(ptr, fl, tbl[5], (8 * at) as i32);
                v[*dst] = (0..prog.regs[*dst].width)
                    .map(|j| g.b.ins().load(types::F64, fl, fp, (8 * j) as i32))
                    .collect();
            }
        }
        let row = g.b.declare_var(ptr);
        g.b.def_var(row, first);
        let end = g.b.ins().iadd(first, n);
        let header = g.b.create_block();
        let body = g.b.create_block();
        let done = g.b.create_block();
        g.b.ins().jump(header, &[]);
        g.b.switch_to_block(header);
        let r = g.b.use_var(row);
        let more = g.b.ins().icmp(IntCC::UnsignedLessThan, r, end);
        g.b.ins().brif(more, body, &[], done, &[]);
        g.b.switch_to_block(body);
        let r = g.b.use_var(row);
        let width = |k: usize| prog.regs[k].width;
        for op in &prog.ops {
            let res: Vec<Value> = match op {
                Op::Fill { .. } => continue,
                Op::Gather { dst, col, idx } => {
                    let w = width(*dst);
                    let off = g.b.ins().ishl_imm_u(r, 2);
                    let a = g.b.ins().iadd(g.gathers[*idx], off);
                    let s = g.b.ins().uload32(fl, a, 0);
                    let base = g.cols[*col];
                    match kinds[*col] {
                        ColKind::Real => {
                            let o = g.b.ins().imul_imm_u(s, (w * 8) as i64);
                            let a = g.b.ins().iadd(base, o);
                            (0..w)
                                .map(|j| g.b.ins().load(types::F64, fl, a, (8 * j) as i32))
                                .collect()
                        }
                        ColKind::Bool => {
                            let a = g.b.ins().iadd(base, s);
                            let x = g.b.ins().uload8(types::I32, fl, a, 0);
                            let c = g.b.ins().icmp_imm_u(IntCC::NotEqual, x, 0);
                            vec![g.bool_f(c)]
                        }
                        ColKind::Int => {
                            let o = g.b.ins().ishl_imm_u(s, 3);
                            let a = g.b.ins().iadd(base, o);
                            let x = g.b.ins().load(types::I64, fl, a, 0);
                            vec![g.b.ins().fcvt_from_sint(types::F64, x)]
                        }
                    }
                }
                Op::Agg {
                    dst,
                    col,
                    csr,
                    mean,
                } => {
                    if kinds[*col] != ColKind::Real {
                        return Err("an aggregate of a non-real column".into());
                    }
                    let w = width(*dst);
                    let off = g.b.ins().ishl_imm_u(r, 2);
                    let a = g.b.ins().iadd(g.offs[*csr], off);
                    let lo = g.b.ins().uload32(fl, a, 0);
                    let hi = g.b.ins().uload32(fl, a, 4);
                    let (slots, base) = (g.slots[*csr], g.cols[*col]);
                    let zero = g.f(0.0);
                    let acc: Vec<_> = (0..w)
                        .map(|_| {
                            let x = g.b.declare_var(types::F64);
                            g.b.def_var(x, zero);
                            x
                        })
                        .collect();
                    let j = g.b.declare_var(types::I64);
                    let load_slot = |g: &mut Gen, k: Value| -> Vec<Value> {
                        let o = g.b.ins().ishl_imm_u(k, 2);
                        let a = g.b.ins().iadd(slots, o);
                        let s = g.b.ins().uload32(fl, a, 0);
                        let o = g.b.ins().imul_imm_u(s, (w * 8) as i64);
                        let a = g.b.ins().iadd(base, o);
                        (0..w)
                            .map(|t| g.b.ins().load(types::F64, fl, a, (8 * t) as i32))
                            .collect()
                    };
                    let first_b = g.b.create_block();
                    let head = g.b.create_block();
                    let step = g.b.create_block();
                    let exit = g.b.create_block();
                    let nonempty = g.b.ins().icmp(IntCC::UnsignedLessThan, lo, hi);
                    g.b.ins().brif(nonempty, first_b, &[], exit, &[]);
                    // the first value, then each next one added (the evaluator's order)
                    g.b.switch_to_block(first_b);
                    let x0 = load_slot(&mut g, lo);
                    for (t, &x) in x0.iter().enumerate() {
                        g.b.def_var(acc[t], x);
                    }
                    let lo1 = g.b.ins().iadd_imm_u(lo, 1);
                    g.b.def_var(j, lo1);
                    g.b.ins().jump(head, &[]);
                    g.b.switch_to_block(head);
                    let jv = g.b.use_var(j);
                    let go = g.b.ins().icmp(IntCC::UnsignedLessThan, jv, hi);
                    g.b.ins().brif(go, step, &[], exit, &[]);
                    g.b.switch_to_block(step);
                    let jv = g.b.use_var(j);
                    let xs = load_slot(&mut g, jv);
                    for (t, &x) in xs.iter().enumerate() {
                        let a = g.b.use_var(acc[t]);
                        let s = g.b.ins().fadd(a, x);
                        g.b.def_var(acc[t], s);
                    }
                    let j1 = g.b.ins().iadd_imm_u(jv, 1);
                    g.b.def_var(j, j1);
                    g.b.ins().jump(head, &[]);
                    g.b.switch_to_block(exit);
                    let mut res: Vec<Value> = acc.iter().map(|&x| g.b.use_var(x)).collect();
                    if *mean {
                        let len = g.b.ins().isub(hi, lo);
                        let one = g.b.ins().iconst(types::I64, 1);
                        let len = g.b.ins().umax(len, one);
                        let k = g.b.ins().fcvt_from_uint(types::F64, len);
                        for x in &mut res {
                            *x = g.b.ins().fdiv(*x, k);
                        }
                    }
                    res
                }
                Op::RowData { data, .. } => {
                    let off = g.b.ins().ishl_imm_u(r, 3);
                    let a = g.b.ins().iadd(g.counts[*data], off);
                    vec![g.b.ins().load(types::F64, fl, a, 0)]
                }
                Op::Ew { op, a, b, .. } => {
                    let (x, y) = (v[*a].clone(), v[*b].clone());
                    let mut res = Vec::with_capacity(x.len());
                    for (&x, &y) in x.iter().zip(&y) {
                        res.push(match op {
                            Ew::Add => g.b.ins().fadd(x, y),
                            Ew::Sub => g.b.ins().fsub(x, y),
                            Ew::Mul => g.b.ins().fmul(x, y),
                            Ew::Div => g.b.ins().fdiv(x, y),
                            Ew::Rem => g.call(Call::Rem, &[x, y])[0],
                        });
                    }
                    res
                }
                Op::ScaleL { s, v: x, .. } => {
                    let f = v[*s][0];
                    let x = v[*x].clone();
                    x.iter().map(|&x| g.b.ins().fmul(f, x)).collect()
                }
                Op::DivS { v: x, s, .. } => {
                    let f = v[*s][0];
                    let x = v[*x].clone();
                    x.iter().map(|&x| g.b.ins().fdiv(x, f)).collect()
                }
                Op::MatMul {
                    a, b, r: nr, k, c, ..
                } => {
                    let (x, y) = (v[*a].clone(), v[*b].clone());
                    let mut res = Vec::with_capacity(nr * c);
                    for i in 0..*nr {
                        for j in 0..*c {
                            let mut acc = g.f(0.0);
                            for t in 0..*k {
                                let p = g.b.ins().fmul(x[i * k + t], y[t * c + j]);
                                acc = g.b.ins().fadd(acc, p);
                            }
                            res.push(acc);
                        }
                    }
                    res
                }
                Op::MatMulSparse {
                    a,
                    b,
                    k,
                    c,
                    offs,
                    terms,
                    ..
                } => {
                    let (x, y) = (v[*a].clone(), v[*b].clone());
                    let mut res = Vec::new();
                    for (ri, o) in offs.windows(2).enumerate() {
                        let ts = &terms[o[0] as usize..o[1] as usize];
                        for j in 0..*c {
                            let mut acc = g.f(0.0);
                            for &t in ts {
                                let t = t as usize;
                                let p = g.b.ins().fmul(x[ri * k + t], y[t * c + j]);
                                acc = g.b.ins().fadd(acc, p);
                            }
                            res.push(acc);
                        }
                    }
                    res
                }
                Op::Neg { a, .. } => {
                    let x = v[*a].clone();
                    x.iter().map(|&x| g.b.ins().fneg(x)).collect()
                }
                Op::Not { a, .. } => {
                    let zero = g.f(0.0);
                    let c = g.b.ins().fcmp(FloatCC::Equal, v[*a][0], zero);
                    vec![g.bool_f(c)]
                }
                Op::Cmp { op, a, b, .. } => {
                    let cc = match op {
                        Cmp::Lt => FloatCC::LessThan,
                        Cmp::Le => FloatCC::LessThanOrEqual,
                        Cmp::Gt => FloatCC::GreaterThan,
                        Cmp::Ge => FloatCC::GreaterThanOrEqual,
                    };
                    let c = g.b.ins().fcmp(cc, v[*a][0], v[*b][0]);
                    vec![g.bool_f(c)]
                }
                Op::Eq { ne, a, b, .. } => {
                    let (x, y) = (v[*a].clone(), v[*b].clone());
                    let mut eq = g.b.ins().iconst(types::I8, 1);
                    for (&p, &q) in x.iter().zip(&y) {
                        let e = g.b.ins().fcmp(FloatCC::Equal, p, q);
                        eq = g.b.ins().band(eq, e);
                    }
                    let (t, f) = if *ne { (0.0, 1.0) } else { (1.0, 0.0) };
                    let (t, f) = (g.f(t), g.f(f));
                    vec![g.b.ins().select(eq, t, f)]
                }
                Op::And { a, b, .. } | Op::Or { a, b, .. } => {
                    let zero = g.f(0.0);
                    let x = g.b.ins().fcmp(FloatCC::NotEqual, v[*a][0], zero);
                    let y = g.b.ins().fcmp(FloatCC::NotEqual, v[*b][0], zero);
                    let c = if matches!(op, Op::Or { .. }) {
                        g.b.ins().bor(x, y)
                    } else {
                        g.b.ins().band(x, y)
                    };
                    vec![g.bool_f(c)]
                }
                Op::Select { c, a, b, .. } => {
                    let zero = g.f(0.0);
                    let z = g.b.ins().fcmp(FloatCC::Equal, v[*c][0], zero);
                    let (x, y) = (v[*a].clone(), v[*b].clone());
                    x.iter()
                        .zip(&y)
                        .map(|(&x, &y)| g.b.ins().select(z, y, x))
                        .collect()
                }
                Op::Pick { srcs, map, .. } => map
                    .iter()
                    .map(|&(src, off)| {
                        if src == u16::MAX {
                            g.f(0.0)
                        } else {
                            v[srcs[src as usize]][off as usize]
                        }
                    })
                    .collect(),
                Op::F1 { f, name, a, .. } => {
                    let x = v[*a][0];
                    vec![match *name {
                        "sqrt" => g.b.ins().sqrt(x),
                        "abs" => g.b.ins().fabs(x),
                        "floor" if g.has_sse41 => g.b.ins().floor(x),
                        "ceil" if g.has_sse41 => g.b.ins().ceil(x),
                        "sign" => {
                            let zero = g.f(0.0);
                            let t = g.b.ins().fmul(x, zero);
                            let m1 = g.f(-1.0);
                            let neg = g.b.ins().fcmp(FloatCC::LessThan, x, zero);
                            let s = g.b.ins().select(neg, m1, t);
                            let one = g.f(1.0);
                            let pos = g.b.ins().fcmp(FloatCC::GreaterThan, x, zero);
                            g.b.ins().select(pos, one, s)
                        }
                        _ => g.call(Call::F1(*f), &[x])[0],
                    }]
                }
                Op::F2 { f, a, b, .. } => {
                    let (x, y) = (v[*a][0], v[*b][0]);
                    g.call(Call::F2(*f), &[x, y])
                }
                Op::Fast { f, args, .. } => {
                    let x = v[args[0]].clone();
                    let y = args.get(1).map(|&k| v[k].clone());
                    match (f, &y) {
                        (Fast::Dot, Some(y)) => {
                            let ps: Vec<Value> = x
                                .iter()
                                .zip(y)
                                .map(|(&a, &b)| g.b.ins().fmul(a, b))
                                .collect();
                            vec![g.rust_sum(&ps)]
                        }
                        (Fast::Norm2, _) => {
                            let ps: Vec<Value> = x.iter().map(|&a| g.b.ins().fmul(a, a)).collect();
                            vec![g.rust_sum(&ps)]
                        }
                        (Fast::Cross3, Some(y)) => vec![
                            g.diff_of_products(x[1], y[2], x[2], y[1]),
                            g.diff_of_products(x[2], y[0], x[0], y[2]),
                            g.diff_of_products(x[0], y[1], x[1], y[0]),
                        ],
                        (Fast::Cross2, Some(y)) => {
                            vec![g.diff_of_products(x[0], y[1], x[1], y[0])]
                        }
                        (Fast::Norm, _) => vec![g.norm(&x)],
                        (Fast::Normalize, _) => {
                            let m = g.max_abs(&x);
                            let zero = g.f(0.0);
                            let is0 = g.b.ins().fcmp(FloatCC::Equal, m, zero);
                            let z: Vec<Value> = x.iter().map(|&a| g.b.ins().fdiv(a, m)).collect();
                            let n = g.norm_scaled(&z);
                            z.iter()
                                .map(|&a| {
                                    let q = g.b.ins().fdiv(a, n);
                                    g.b.ins().select(is0, zero, q)
                                })
                                .collect()
                        }
                        (Fast::Trace, _) => {
                            let n = (x.len() as f64).sqrt() as usize;
                            let d: Vec<Value> = (0..n).map(|i| x[i * n + i]).collect();
                            if d.is_empty() {
                                vec![g.f(if g.neg_zero_sum { -0.0 } else { 0.0 })]
                            } else {
                                vec![g.rust_sum(&d)]
                            }
                        }
                        (Fast::Sym, _) => {
                            let n = (x.len() as f64).sqrt() as usize;
                            let h = g.f(0.5);
                            let mut res = Vec::with_capacity(n * n);
                            for i in 0..n {
                                for j in 0..n {
                                    let p = g.b.ins().fmul(h, x[i * n + j]);
                                    let q = g.b.ins().fmul(h, x[j * n + i]);
                                    res.push(g.b.ins().fadd(p, q));
                                }
                            }
                            res
                        }
                        (Fast::Polar2 | Fast::Polar3, None) => {
                            let wa = x.len();
                            g.call(
                                Call::Fast {
                                    f: *f,
                                    wa,
                                    two: false,
                                },
                                &x,
                            )
                        }
                        _ => return Err(format!("{f:?} with these arguments")),
                    }
                }
                Op::Generic { name, args, ty, .. } => {
                    let mut xs = Vec::new();
                    let mut desc = Vec::new();
                    for &(k, t) in args {
                        xs.extend_from_slice(&v[k]);
                        desc.push((v[k].len(), t));
                    }
                    g.call(
                        Call::Generic {
                            name: name.clone(),
                            args: desc,
                            ty: *ty,
                        },
                        &xs,
                    )
                }
            };
            let dst = dst_of(op);
            if res.len() != width(dst) {
                return Err(format!(
                    "{op:?}: {} values for width {}",
                    res.len(),
                    width(dst)
                ));
            }
            v[dst] = res;
        }
        // the outputs, at `Plan::out_index`
        let ch = layout.chunk as i64;
        let i = g.b.ins().band_imm_u(r, ch - 1);
        let base = g.b.ins().isub(r, i);
        let base = g.b.ins().imul_imm_u(base, layout.out_width as i64);
        for (w, (_, _, reg, _)) in prog.writes.iter().enumerate() {
            let wd = width(*reg);
            let o = g.b.ins().imul_imm_u(i, wd as i64);
            let o = g.b.ins().iadd(base, o);
            let o = g.b.ins().iadd_imm_u(o, layout.offsets[w] as i64 * ch);
            let o = g.b.ins().ishl_imm_u(o, 3);
            let a = g.b.ins().iadd(g.out, o);
            for (j, &x) in v[*reg].iter().enumerate() {
                g.b.ins().store(fl, x, a, (8 * j) as i32);
            }
        }
        let r1 = g.b.ins().iadd_imm_u(r, 1);
        g.b.def_var(row, r1);
        g.b.ins().jump(header, &[]);
        g.b.switch_to_block(done);
        let ok = g.b.ins().iconst(types::I32, 0);
        g.b.ins().return_(&[ok]);
        g.b.seal_all_blocks();
        g.b.finalize(tcfg);
    }
    module
        .define_function(id, &mut ctx)
        .map_err(|e| format!("cranelift: {e:?}"))?;
    module.clear_context(&mut ctx);
    module
        .finalize_definitions()
        .map_err(|e| format!("cranelift: {e}"))?;
    let code = module.get_finalized_function(id);
    // SAFETY: `code` is the finalized function `id`, defined above with the signature
    // `(i64, i64, i64) -> i32` in the host's default calling convention, which is that of
    // `extern "C" fn(*const JitArgs, u64, u64) -> u32`; it lives as long as `module`, which
    // `Native` keeps (and frees only on drop).
    let func = unsafe { std::mem::transmute::<*const u8, Func>(code) };
    COMPILED.fetch_add(1, Ordering::Relaxed);
    Ok(Native {
        module: Some(module),
        func,
        calls,
        kinds: kinds.to_vec(),
    })
}

fn dst_of(op: &Op) -> usize {
    match op {
        Op::MatMulSparse { dst, .. }
        | Op::Fill { dst, .. }
        | Op::Gather { dst, .. }
        | Op::Agg { dst, .. }
        | Op::RowData { dst, .. }
        | Op::Ew { dst, .. }
        | Op::ScaleL { dst, .. }
        | Op::DivS { dst, .. }
        | Op::MatMul { dst, .. }
        | Op::Neg { dst, .. }
        | Op::Not { dst, .. }
        | Op::Cmp { dst, .. }
        | Op::Eq { dst, .. }
        | Op::And { dst, .. }
        | Op::Or { dst, .. }
        | Op::Select { dst, .. }
        | Op::Pick { dst, .. }
        | Op::F1 { dst, .. }
        | Op::F2 { dst, .. }
        | Op::Fast { dst, .. }
        | Op::Generic { dst, .. } => *dst,
    }
}

#[cfg(test)]
mod tests {
    use super::{Cranelift, PORTABLE};
    use std::sync::atomic::Ordering;
    use std::sync::Arc;
    use topomech_engine::{Params, RuleSet};
    use topomech_gmap::generators::{grid, GridElement};
    use topomech_gmap::mesh::{build, BuildOptions};
    use topomech_lang::check::check_sources;
    use topomech_lang::Val;

    const SRC: &str = "dimension 2
embedding position : vec3 on <1,2>
embedding out : vec3 on <1,2>

rule r(q: vec3) {
  left { v : <1,2> hook }
  compute {
    let p = v.position + vec3(0.3, -0.7, 0.1)
    v.out = cross(p, q) + vec3(floor(7.0 * x(p)), ceil(-5.0 * y(p)), cross(vec2(x(p), y(p)), vec2(z(q), x(q))))
  }
}
";

    /// The paths a host without FMA or SSE4.1 takes (`fma` through the table's helper,
    /// `floor` and `ceil` through `jit_call`) give the evaluator's bits too.
    #[test]
    fn without_host_fma_and_sse41_the_helpers_give_the_same_bits() {
        PORTABLE.store(true, Ordering::Relaxed);
        let (g0, _) = build(
            &grid([13, 11], [1.0, 0.8], GridElement::Quad),
            &BuildOptions::default(),
        )
        .unwrap();
        let run = |jit: bool| {
            // this crate's own backend (under test: the copy that reads `PORTABLE`)
            let (checked, _) = check_sources(&[("t.tmr".to_string(), SRC.to_string())]);
            let mut rules = RuleSet::new(checked.unwrap());
            rules.set_backend(Some(Arc::new(Cranelift)));
            rules.set_jit(jit);
            let mut g = g0.clone();
            rules.prepare(&mut g).unwrap();
            let p: Params = [("q".to_string(), Val::V3([0.25, -1.5, 2.0]))].into();
            rules.apply_everywhere(&mut g, "r", &p).unwrap();
            let id = g.require("out").unwrap();
            let bits: Vec<u64> = g
                .embedding(id)
                .real_column()
                .unwrap()
                .iter()
                .map(|x| x.to_bits())
                .collect();
            (bits, rules.plan_native())
        };
        let (slow, _) = run(false);
        let (fast, native) = run(true);
        PORTABLE.store(false, Ordering::Relaxed);
        assert_eq!(native, vec![("r".to_string(), true)]);
        assert_eq!(slow, fast);
    }
}
