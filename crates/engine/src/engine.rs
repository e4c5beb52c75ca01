//! Matching and application of checked rules on a G-map.
//!
//! A match of a rule at hook darts: the hook's orbit is walked breadth-first, each dart a
//! *row*; every node of the left graph gets one dart per row, reached from the hook through
//! explicit arcs, and must show the node's orbit type (relabelled) and arcs on those darts.
//! Application evaluates every expression on the map as it was before the rule (values
//! are read before any write), then rewrites the topology in one batch
//! ([`GMap::rewire`]), then writes the values; the embeddings of the map the rule does not
//! write on an orbit made only of new darts get a value by their policy (`fill_new_orbits`).
//! Global application finds every match first, then applies them all. The matches of a rule
//! that changes the topology never overlap (the whole footprint of a match is marked); those
//! of a computation rule may share darts, since a force pattern reads its neighbours (the
//! paper's angular springs match two whole faces per edge), but no match is applied twice: a
//! match found again from another hook dart — the same footprint — is skipped. Two matches
//! writing different values to one orbit are refused.

use std::collections::HashMap;
use std::fmt;
use std::sync::Arc;

use topomech_gmap::{
    ColumnRef, Dart, EmbeddingId, EmbeddingType, GMap, Marks, OrbitType, Policy, RewireError, Value,
};

use crate::ast::AggKind;
use crate::builtins;
use crate::check::{Checked, EmbDecl, Rule, Source, TExpr, TStmt};
use crate::native::NativeBackend;
use crate::value::{binop, unop, BinOp, Ty, UnOp, Val};

/// Why a rule did not apply.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ApplyError {
    /// No rule of that name.
    #[error("no rule named '{0}'")]
    UnknownRule(String),
    /// The rule does not match at the given hook(s).
    #[error("rule '{rule}' does not match at {at}: {reason}")]
    NoMatch {
        /// The rule.
        rule: String,
        /// The hook darts.
        at: String,
        /// Which arc, orbit or dart failed.
        reason: String,
    },
    /// Wrong number of hook darts, or a dart that does not exist.
    #[error("rule '{rule}': {message}")]
    Hooks {
        /// The rule.
        rule: String,
        /// What is wrong.
        message: String,
    },
    /// The map does not fit the rule file (dimension, embedding declarations).
    #[error("{0}")]
    Map(String),
    /// A missing, unknown or mistyped parameter.
    #[error("rule '{rule}': {message}")]
    Param {
        /// The rule.
        rule: String,
        /// What is wrong.
        message: String,
    },
    /// A numerical error while evaluating an expression.
    #[error("rule '{rule}' at dart {dart}: {message}")]
    Eval {
        /// The rule.
        rule: String,
        /// The row's dart of the hook.
        dart: Dart,
        /// What failed.
        message: String,
    },
    /// Two writes of different values to one orbit.
    #[error("rule '{rule}': embedding-write-conflict: '{embedding}' gets two different values on the orbit of dart {dart}")]
    WriteConflict {
        /// The rule.
        rule: String,
        /// The embedding.
        embedding: String,
        /// A dart of the orbit.
        dart: Dart,
    },
    /// A write of a non-finite value (NaN or an infinity) to an embedding: the application
    /// writes nothing (every value is checked before the first write).
    #[error("rule '{rule}' writes a non-finite value {value} to '{embedding}' at dart {dart}; nothing was written")]
    NonFinite {
        /// The rule.
        rule: String,
        /// The embedding.
        embedding: String,
        /// The dart of the orbit written (the hook's dart for a node the rule creates).
        dart: Dart,
        /// The value, as the language prints it.
        value: String,
    },
    /// The caller's interrupt check ([`RuleSet::apply_everywhere_interruptible`]) asked to
    /// stop. The application stops only where the map is valid: while matches are found or
    /// values evaluated, before any change to the topology or the values (embeddings the rules
    /// declare may have been added to the map, zero everywhere, as `prepare` adds them).
    #[error("rule '{rule}': interrupted while {stage} ({found} match(es) found so far); {applied} match(es) applied, the map is valid")]
    Interrupted {
        /// The rule.
        rule: String,
        /// What it was doing: `finding matches`, `evaluating`, `planning the new topology`,
        /// `checking the values written` or `running its compiled plan`.
        stage: &'static str,
        /// Matches found before the interruption.
        found: usize,
        /// Matches applied: always 0, since an application writes all its matches in one
        /// batch after every value is evaluated.
        applied: usize,
    },
    /// A topology-changing rule would create orbits made only of new darts where an
    /// embedding of the map gets no value: the rule does not write it there and its policy
    /// gives none (`error`, or no old orbit to take it from; README, "Embeddings the rule's
    /// file does not declare"). Nothing was changed.
    #[error("rule '{rule}' creates {orbit} orbits made only of new darts (e.g. at dart {dart}), where embedding '{embedding}' ({ty} on {orbit}, policy {policy}) has no value: {reason}; declare it in the rule's file and write it, or give it policy sum")]
    NoValue {
        /// The rule.
        rule: String,
        /// The embedding of the map.
        embedding: String,
        /// Its value type.
        ty: EmbeddingType,
        /// Its orbit type.
        orbit: OrbitType,
        /// Its policy: `copy`, `mean`, `sum` or `error`.
        policy: &'static str,
        /// A new dart of such an orbit.
        dart: Dart,
        /// Why the policy gives no value.
        reason: String,
    },
    /// The rewrite was refused by the kernel (should not happen for checked rules; reported,
    /// never a panic).
    #[error("rule '{rule}': {source}")]
    Rewire {
        /// The rule.
        rule: String,
        /// The kernel's reason.
        source: RewireError,
    },
}

/// A match: rows of the hook orbit and one dart per row for each left node.
#[derive(Clone, Debug)]
pub struct Match {
    /// Number of rows.
    pub rows: usize,
    /// `next[r * arity + t]`: the row reached from row `r` through orbit position `t`.
    pub next: Vec<u32>,
    /// For each node, its darts by row (empty for created nodes).
    pub darts: NodeDarts,
}

impl Match {
    fn all_darts(&self) -> impl Iterator<Item = Dart> + '_ {
        self.darts.iter().flatten().copied()
    }
}

/// The placeholder of a dart not yet known, in [`NodeDarts`] (no map has `u32::MAX` darts:
/// a dart's index fits a `u32` below the map's capacity).
const NO_DART: Dart = Dart(u32::MAX);

/// The darts of a match's nodes by row, in one array, node after node: node `k`'s darts are
/// `darts[k]` (`rows` of them), or none for a node the rule creates. One allocation per match
/// instead of one per node: a set-up rule is matched at every dart of the map, 2.4 million
/// times at 10^5 tetrahedra, and the allocations were a third of its matching.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeDarts {
    rows: usize,
    /// Node-major; a node without darts holds `NO_DART` in every row.
    flat: Vec<Dart>,
}

impl NodeDarts {
    /// `nodes` nodes of `rows` rows (at least 1), none known yet.
    fn new(nodes: usize, rows: usize) -> Self {
        debug_assert!(rows > 0);
        NodeDarts {
            rows,
            flat: vec![NO_DART; nodes * rows],
        }
    }

    /// The number of nodes.
    pub fn len(&self) -> usize {
        self.flat.len() / self.rows
    }

    /// Whether there are no nodes.
    pub fn is_empty(&self) -> bool {
        self.flat.is_empty()
    }

    /// Node `k`'s darts by row, `None` past the last node.
    pub fn get(&self, k: usize) -> Option<&[Dart]> {
        (k < self.len()).then(|| &self[k])
    }

    /// Each node's darts by row, in node order (empty for created nodes).
    pub fn iter(&self) -> impl Iterator<Item = &[Dart]> + '_ {
        (0..self.len()).map(move |k| &self[k])
    }

    /// Whether node `k`'s darts are known.
    fn is_set(&self, k: usize) -> bool {
        self.flat[k * self.rows] != NO_DART
    }

    /// Node `k`'s rows, to fill (`NO_DART` where unknown).
    fn col_mut(&mut self, k: usize) -> &mut [Dart] {
        &mut self.flat[k * self.rows..(k + 1) * self.rows]
    }

    /// Node `q`'s darts: node `p`'s, each mapped by `f`.
    fn fill_from(&mut self, p: usize, q: usize, f: impl Fn(Dart) -> Dart) {
        let n = self.rows;
        for r in 0..n {
            self.flat[q * n + r] = f(self.flat[p * n + r]);
        }
    }

    /// One vector per node (empty for created nodes).
    pub fn to_vecs(&self) -> Vec<Vec<Dart>> {
        self.iter().map(<[Dart]>::to_vec).collect()
    }

    /// The heap bytes held.
    fn heap_bytes(&self) -> usize {
        self.flat.capacity() * std::mem::size_of::<Dart>()
    }
}

impl std::ops::Index<usize> for NodeDarts {
    type Output = [Dart];

    fn index(&self, k: usize) -> &[Dart] {
        let col = &self.flat[k * self.rows..(k + 1) * self.rows];
        if col[0] == NO_DART {
            &[]
        } else {
            col
        }
    }
}

/// Rule parameters by name.
pub type Params = HashMap<String, Val>;

/// What an application did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ApplyReport {
    /// Matches applied.
    pub matches: usize,
    /// Darts created.
    pub created: usize,
    /// Darts deleted.
    pub deleted: usize,
    /// Expression evaluations for writes: one per distinct value written per match, not
    /// one per dart.
    pub evaluations: usize,
}

/// How much work (darts tried, rows evaluated) passes between two calls of an interrupt
/// check: a few microseconds of matching, so a check that answers at once stops an
/// application within milliseconds.
pub const INTERRUPT_EVERY: usize = 1024;

/// The caller's interrupt check, called once per [`INTERRUPT_EVERY`] units of work.
struct Poll<'a> {
    check: &'a dyn Fn() -> bool,
    work: usize,
}

impl<'a> Poll<'a> {
    fn new(check: &'a dyn Fn() -> bool) -> Self {
        Poll { check, work: 0 }
    }

    /// Counts `n` units of work; true when the check was due and asks to stop.
    fn tick(&mut self, n: usize) -> bool {
        self.work += n;
        if self.work < INTERRUPT_EVERY {
            return false;
        }
        self.work = 0;
        (self.check)()
    }
}

fn never() -> bool {
    false
}

/// Rows of the orbit of `d` with the given labels, breadth-first; `next` as in [`Match`].
fn rows_of(g: &GMap, d: Dart, labels: &[u8]) -> (Vec<Dart>, Vec<u32>) {
    let k = labels.len();
    // sized as the last orbit walked on this thread (a search walks orbits of one type in
    // turn): no regrowth, and a large one goes to the table at once
    let hint = LAST_ROWS.with(std::cell::Cell::get).max(1);
    let mut darts = Vec::with_capacity(hint);
    darts.push(d);
    let mut next = Vec::with_capacity(hint * k);
    let mut r = 0;
    if hint > 32 {
        let out = ROW_OF.with(|t| rows_of_large(g, labels, darts, next, r, &mut t.borrow_mut()));
        LAST_ROWS.with(|c| c.set(out.0.len()));
        return out;
    }
    // small orbits (the usual case) are searched linearly
    while r < darts.len() {
        if darts.len() > 32 {
            let out =
                ROW_OF.with(|t| rows_of_large(g, labels, darts, next, r, &mut t.borrow_mut()));
            LAST_ROWS.with(|c| c.set(out.0.len()));
            return out;
        }
        let x = darts[r];
        for &l in labels {
            let y = g.alpha(l as usize, x);
            let s = if let Some(i) = darts.iter().position(|&z| z == y) {
                i as u32
            } else {
                darts.push(y);
                (darts.len() - 1) as u32
            };
            next.push(s);
        }
        r += 1;
    }
    debug_assert_eq!(next.len(), darts.len() * k);
    LAST_ROWS.with(|c| c.set(darts.len()));
    (darts, next)
}

thread_local! {
    /// The number of rows of the last orbit [`rows_of`] walked on this thread.
    static LAST_ROWS: std::cell::Cell<usize> = const { std::cell::Cell::new(8) };
    /// Per dart, its row plus one in the orbit [`rows_of`] is walking (0: not in it): a
    /// table the size of the map, per thread, reset after each walk (for the darts it set).
    static ROW_OF: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// [`rows_of`] for an orbit of more than 32 darts, from row `r` on: rows looked up in the
/// dense table `row_of` instead of by a linear search (a vertex of a tetrahedral mesh has
/// about a hundred darts).
fn rows_of_large(
    g: &GMap,
    labels: &[u8],
    mut darts: Vec<Dart>,
    mut next: Vec<u32>,
    mut r: usize,
    row_of: &mut Vec<u32>,
) -> (Vec<Dart>, Vec<u32>) {
    if row_of.len() < g.capacity() {
        row_of.resize(g.capacity(), 0);
    }
    // a large orbit: a vertex of a tetrahedral mesh has a few hundred darts (the caller
    // reserved as many as the last orbit had)
    if darts.capacity() < 64 {
        darts.reserve(256);
        next.reserve(256 * labels.len());
    }
    for (i, z) in darts.iter().enumerate() {
        row_of[z.index()] = i as u32 + 1;
    }
    while r < darts.len() {
        let x = darts[r];
        for &l in labels {
            let y = g.alpha(l as usize, x);
            let e = &mut row_of[y.index()];
            if *e == 0 {
                darts.push(y);
                *e = darts.len() as u32;
            }
            next.push(*e - 1);
        }
        r += 1;
    }
    for z in &darts {
        row_of[z.index()] = 0;
    }
    debug_assert_eq!(next.len(), darts.len() * labels.len());
    (darts, next)
}

/// Tries to match `rule` with its hooks at `hooks` (one dart per hook, in order); the error
/// says why it does not match.
pub fn match_at(g: &GMap, rule: &Rule, hooks: &[Dart]) -> Result<Match, String> {
    match_explained(g, rule, hooks, true)
}

/// [`match_at`] where only whether it matches matters: a failure is not described (the
/// searches try many darts that do not match, and the message would cost more than the try).
fn try_match(g: &GMap, rule: &Rule, hooks: &[Dart]) -> Option<Match> {
    match_explained(g, rule, hooks, false).ok()
}

/// [`match_at`], the error message written only when `explain`.
fn match_explained(g: &GMap, rule: &Rule, hooks: &[Dart], explain: bool) -> Result<Match, String> {
    // the reason, when asked for
    macro_rules! why {
        ($($t:tt)*) => {
            if explain { format!($($t)*) } else { String::new() }
        };
    }
    let arity = rule.arity;
    // a hook on the empty orbit (a rule on darts, as the set-up's half-edge volumes: 2.4
    // million tries at 10^5 tets) has one row, its dart: no walk, nothing allocated
    let (first, next) = if rule.hook_orbit.is_empty() {
        (Vec::new(), Vec::new())
    } else {
        rows_of(g, hooks[0], &rule.hook_orbit)
    };
    let rows = first.len().max(1);
    let mut darts = NodeDarts::new(rule.nodes.len(), rows);
    for (j, &h) in rule.hooks.iter().enumerate() {
        let col = darts.col_mut(h);
        if j == 0 {
            // the other hooks' walks read `next` only
            if first.is_empty() {
                col[0] = hooks[0];
            } else {
                col.copy_from_slice(&first);
            }
            continue;
        }
        // the other hooks' orbits, walked in parallel with the first (`NO_DART`: not
        // reached yet)
        let shape = || {
            why!(
                "hook '{}': its orbit differs in shape from hook '{}'",
                rule.nodes[h].name,
                rule.nodes[rule.hooks[0]].name
            )
        };
        col[0] = hooks[j];
        for r in 0..rows {
            let x = col[r];
            if x == NO_DART {
                return Err(shape());
            }
            for (t, &l) in rule.hook_orbit.iter().enumerate() {
                let y = g.alpha(l as usize, x);
                let s = next[r * arity + t] as usize;
                if col[s] == NO_DART {
                    col[s] = y;
                } else if col[s] != y {
                    return Err(shape());
                }
            }
        }
        // a smaller orbit (a boundary edge's one dart where the first hook's edge has two)
        // fills the rows consistently but repeats a dart
        let mut seen = col.to_vec();
        seen.sort_unstable();
        if seen.windows(2).any(|w| w[0] == w[1]) {
            return Err(shape());
        }
    }
    drop(first);
    // other left nodes, through the left arcs
    loop {
        let mut progress = false;
        let mut missing = false;
        for &(a, i, b) in &rule.left_arcs {
            for (p, q) in [(a, b), (b, a)] {
                if darts.is_set(p) && !darts.is_set(q) {
                    darts.fill_from(p, q, |x| g.alpha(i as usize, x));
                    progress = true;
                }
            }
            missing |= !darts.is_set(a) || !darts.is_set(b);
        }
        if !progress || !missing {
            break;
        }
    }
    for (k, nd) in rule.nodes.iter().enumerate() {
        if nd.left.is_some() && !darts.is_set(k) {
            return Err(why!("node '{}' is not reached from a hook", nd.name));
        }
    }
    // arcs and loops
    for &(a, i, b) in &rule.left_arcs {
        for (r, &x) in darts[a].iter().enumerate() {
            let y = g.alpha(i as usize, x);
            if a != b && y == x {
                return Err(why!(
                    "arc {} -{i}- {}: dart {x} is {i}-free",
                    rule.nodes[a].name,
                    rule.nodes[b].name
                ));
            }
            if y != darts[b][r] {
                let what = if a == b {
                    why!(
                        "loop {} -{i}- {}: dart {x} is not {i}-free (alpha{i}({x}) = {y})",
                        rule.nodes[a].name,
                        rule.nodes[a].name
                    )
                } else {
                    why!(
                        "arc {} -{i}- {}: alpha{i}({x}) = {y}, expected {}",
                        rule.nodes[a].name,
                        rule.nodes[b].name,
                        darts[b][r]
                    )
                };
                return Err(what);
            }
        }
    }
    // orbit types (a hook's holds by construction: its rows were walked, or checked above,
    // through its own labels, which are the hook orbit's)
    for (k, nd) in rule.nodes.iter().enumerate() {
        let Some(labels) = &nd.left else { continue };
        if rule.hooks.contains(&k) {
            debug_assert!(labels
                .iter()
                .map(|l| l.expect("a hook's labels"))
                .eq(rule.hook_orbit.iter().copied()));
            continue;
        }
        for (t, l) in labels.iter().enumerate() {
            let Some(i) = l else { continue };
            for r in 0..rows {
                let x = darts[k][r];
                let want = darts[k][next[r * arity + t] as usize];
                let y = g.alpha(*i as usize, x);
                if y != want {
                    return Err(why!("node '{}': orbit label {i} at position {t}: alpha{i}({x}) = {y}, but the orbit needs {want}", nd.name));
                }
            }
        }
    }
    // kept nodes gaining an explicit arc need free darts
    for (k, nd) in rule.nodes.iter().enumerate() {
        if !nd.is_kept() {
            continue;
        }
        for i in 0..=g.dimension() {
            if nd.left_src[i] == Source::None && nd.right_src[i] != Source::None {
                if let Some(&x) = darts[k].iter().find(|&&x| !g.is_free(i, x)) {
                    return Err(why!(
                        "node '{}' gains label {i} but dart {x} is already {i}-linked to {}",
                        nd.name,
                        g.alpha(i, x)
                    ));
                }
            }
        }
    }
    // no dart twice (pairwise for a small footprint, else sorted: the map may be huge)
    let total: usize = darts.iter().map(<[Dart]>::len).sum();
    if total <= 16 {
        let flat = || {
            darts
                .iter()
                .enumerate()
                .flat_map(|(k, col)| col.iter().map(move |&x| (x, k)))
        };
        for (i, (x, k)) in flat().enumerate() {
            if let Some((_, k2)) = flat().skip(i + 1).find(|(y, _)| *y == x) {
                return Err(why!("dart {x} would be matched twice (node '{}'): the pattern folds onto itself here", rule.nodes[k.max(k2)].name));
            }
        }
        return Ok(Match { rows, next, darts });
    }
    // marks find whether a dart repeats (the usual answer: none); the sort below says which
    let repeats = topomech_gmap::marks::with_marks(g.capacity(), |m| {
        darts.iter().flatten().any(|&x| !m.mark(x))
    });
    if !repeats {
        return Ok(Match { rows, next, darts });
    }
    let mut all: Vec<(Dart, usize)> = darts
        .iter()
        .enumerate()
        .flat_map(|(k, col)| col.iter().map(move |&x| (x, k)))
        .collect();
    all.sort_unstable();
    if let Some(w) = all.windows(2).find(|w| w[0].0 == w[1].0) {
        let (x, k) = (w[0].0, w[0].1.max(w[1].1));
        return Err(why!(
            "dart {x} would be matched twice (node '{}'): the pattern folds onto itself here",
            rule.nodes[k].name
        ));
    }
    Ok(Match { rows, next, darts })
}

/// A rule file loaded and checked, ready to apply on maps of its dimension.
///
/// It keeps, per computation rule, the matches its last global application found (a *plan*):
/// a cache derived from the map, keyed by the topology version and by the write counts of the
/// embeddings the rule's guard reads, so it is rebuilt exactly when what it was computed from
/// changed, and never a second source of truth. After a topology change a plan is patched
/// instead where that gives what a rebuild gives (see `RuleSet::patch_plan`): the matches
/// around the changed darts dropped and found again, the others kept.
#[derive(Debug)]
pub struct RuleSet {
    checked: Checked,
    plans: std::sync::Mutex<HashMap<usize, Plan>>,
    /// Matches found for a plan, kept for the other rules of the same pattern until the
    /// topology changes or [`RuleSet::clear_shared_matches`] (see [`pattern_key`]).
    shared: std::sync::Mutex<SharedMatches>,
    compile: bool,
    /// Whether compiled plans run native code (see [`crate::native`]).
    jit: bool,
    /// The code generator of the native code (see [`crate::native`]): none, and compiled
    /// plans run the evaluator.
    backend: Option<Arc<dyn NativeBackend>>,
    /// Plans patched after a topology change instead of rebuilt (see
    /// [`RuleSet::plan_patches`]).
    patches: std::sync::atomic::AtomicUsize,
    /// Those of `patches` made in place ([`RuleSet::plan_patches_in_place`]).
    in_place_patches: std::sync::atomic::AtomicUsize,
    /// Plans of computation rules built from a search ([`RuleSet::plans_built`]).
    builds: std::sync::atomic::AtomicUsize,
    /// Matches of patched plans rebuilt without a search ([`RuleSet::matches_rebuilt`]).
    rebuilt: std::sync::atomic::AtomicUsize,
    /// Runs of a compiled plan that failed and were applied by the interpreter instead (see
    /// [`RuleSet::plan_fallbacks`]).
    fallbacks: std::sync::atomic::AtomicUsize,
    /// The compiled guards of rules that change the topology, by rule index (see
    /// [`RuleSet::guarded_matches`]).
    guard_plans: std::sync::Mutex<HashMap<usize, GuardPlan>>,
    /// Applications whose matches a compiled guard gave, and guard plans patched (see
    /// [`RuleSet::compiled_guard_runs`]).
    guard_runs: std::sync::atomic::AtomicUsize,
    guard_patches: std::sync::atomic::AtomicUsize,
    /// Applications whose compiled guard ran over the hook orbits near a region only (see
    /// [`RuleSet::apply_everywhere_within`]).
    culled_runs: std::sync::atomic::AtomicUsize,
    /// The last [`GMap::changes_since`] the plans' patches asked for, with the map state it
    /// answered for (see [`RuleSet::changes_since`]): the plans of one step patched after a
    /// topology change all ask for the same one.
    changes: std::sync::Mutex<Option<ChangesMemo>>,
}

/// The guard of a rule that changes the topology, compiled over every hook orbit where the
/// rule's left graph matches (see [`RuleSet::guarded_matches`]).
#[derive(Debug)]
struct GuardPlan {
    /// The map's identity and topology version when it was built or patched.
    identity: (u64, u64),
    /// The map's embeddings the guard reads (by the rule's `guard_reads`), then.
    reads: Vec<EmbeddingId>,
    plan: crate::compiled::Plan,
    /// The matches by number (row `k` of the plan is match `k`'s row 0).
    index: Index,
    /// Per match, the smallest dart of its hook orbit: where [`find_all`] finds it.
    first: Vec<u32>,
    /// The rows by where they read a `vec3` embedding, for runs near a region (built when
    /// the guard is prepared for them or at the first such run, see
    /// [`GuardPlan::candidates`]).
    cull: Option<Cull>,
}

/// A box in the space of a `vec3` embedding's values (positions, say), for
/// [`RuleSet::apply_everywhere_within`]: `lo` and `hi` are its opposite corners (each
/// coordinate of `lo` at most that of `hi`), in the embedding's units.
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    /// The `vec3` embedding.
    pub embedding: String,
    /// The corner of the smallest coordinates.
    pub lo: [f64; 3],
    /// The corner of the largest coordinates.
    pub hi: [f64; 3],
}

/// A guard plan's rows by the values they read of one `vec3` embedding (see
/// [`GuardPlan::candidates`]).
#[derive(Debug)]
struct Cull {
    /// The embedding.
    emb: EmbeddingId,
    /// The plan's rows indexed (those built, then those patches appended).
    rows: usize,
    /// The embedding's values when the rows were indexed, 3 per slot; a slot created later
    /// joins with its value when the rows are next looked up.
    values: Vec<f64>,
    /// Per coordinate, a bound on the distance, at the values of `values`, between a row's
    /// first slot's value and any other value the row reads of the embedding (for a row
    /// appended later: its distance when it joined, plus twice how far the values had moved
    /// from `values` then).
    extent: [f64; 3],
    /// The rows indexed first, by first slot: those of slot `s` are
    /// `by_slot[start[s]..start[s + 1]]`.
    start: Vec<u32>,
    by_slot: Vec<u32>,
    /// The rows appended since, with their first slots: (slot, row).
    tail: Vec<(u32, u32)>,
    /// Rows that read no value of the embedding.
    always: Vec<u32>,
    /// Rows indexed before whose slots a patch read again in place: placed again, as rows
    /// appended since are, at the next lookup (their entries under their old first slots
    /// stay, giving them twice at most: the lookup's answer is deduplicated).
    moved: Vec<u32>,
}

/// The matches of the patterns planned on one map state, by [`pattern_key`].
#[derive(Debug, Default)]
struct SharedMatches {
    identity: (u64, u64),
    by_pattern: HashMap<String, Arc<Vec<Match>>>,
}

/// What a computation rule's matches depend on, as a key: its left graph (each node's orbit
/// type, the arcs, the hooks, the hook orbit). Two rules with the same key have the same
/// matches on a map (the names of their nodes, their embeddings and their programs do not
/// matter), so the second one planned reuses the first one's (an init rule and the step rule
/// of one model, the spring strains and the cumulated springs). `None` for a rule whose
/// matches depend on more: a guard (it filters them), or a topology change.
fn pattern_key(rule: &Rule) -> Option<String> {
    if rule.guard.is_some() || rule.changes_topology {
        return None;
    }
    Some(left_graph_key(rule))
}

/// The left graph of `rule` as a key (see [`pattern_key`]), whatever its guard.
fn left_graph_key(rule: &Rule) -> String {
    let nodes: Vec<_> = rule.nodes.iter().map(|n| (&n.left, n.left_src)).collect();
    format!(
        "{nodes:?}|{:?}|{:?}|{:?}|{}",
        rule.left_arcs, rule.hooks, rule.hook_orbit, rule.arity
    )
}

/// The key of the matches of a computation rule with a guard: its left graph, its guard,
/// the embeddings it reads (by id) and what it depends on ([`guard_state`]: their write
/// counts, the values of the parameters it reads), so that rules with the same left graph
/// and the same guard (a model's init, step and Jacobian rules over its elements,
/// `where n0.vertex0 && ...`)
/// share their matches while nothing the guard reads changes: [`find_all`] depends on the
/// rule through nothing else (the leading conjuncts and the row-invariance it tests come
/// from the guard and the embeddings' orbits). `None` for a rule that changes the topology
/// or has no guard.
fn guarded_key(g: &GMap, b: &Bound) -> Option<String> {
    let rule = b.rule;
    let guard = rule.guard.as_ref().filter(|_| !rule.changes_topology)?;
    let ids: Vec<u32> = rule.guard_reads.iter().map(|&e| b.ids[e].0).collect();
    Some(format!(
        "{}|where {guard:?}|reads {ids:?}|state {:?}",
        left_graph_key(rule),
        guard_state(g, b),
    ))
}

/// What the guard of `b`'s rule depends on in the map and the parameters: the write counts
/// of the embeddings it reads, then the bits of the parameters it reads
/// ([`guard_param_bits`]). A plan and shared guarded matches stay valid while it is the same.
fn guard_state(g: &GMap, b: &Bound) -> Vec<u64> {
    let mut state: Vec<u64> = b
        .rule
        .guard_reads
        .iter()
        .map(|&e| g.embedding(b.ids[e]).writes())
        .collect();
    guard_param_bits(b, &mut state);
    state
}

/// Appends to `out` the bits of the values of the parameters `b`'s guard reads, in the order
/// of the rule's parameters (nothing for a rule without a guard, or whose guard reads none).
fn guard_param_bits(b: &Bound, out: &mut Vec<u64>) {
    let Some(guard) = &b.rule.guard else {
        return;
    };
    let mut ks = Vec::new();
    crate::check::visit(guard, &mut |e| {
        if let TExpr::Param(k) = e {
            ks.push(*k);
        }
    });
    ks.sort_unstable();
    ks.dedup();
    for k in ks {
        match &b.params[k] {
            Val::F(x) => out.push(x.to_bits()),
            Val::I(i) => out.push(*i as u64),
            Val::B(x) => out.push(u64::from(*x)),
            Val::V2(v) => out.extend(v.iter().map(|x| x.to_bits())),
            Val::V3(v) => out.extend(v.iter().map(|x| x.to_bits())),
            Val::M(m) => out.extend(m.data.iter().map(|x| x.to_bits())),
        }
    }
}

/// Whether the left graph of `rule` is one node and no arc: a match's footprint is then its
/// hook orbit.
fn one_node(rule: &Rule) -> bool {
    rule.nodes.len() == 1 && rule.left_arcs.is_empty()
}

/// Whether the matches of `rule` (a computation rule with a guard) are those of its left
/// graph without the guard that pass the guard, evaluated at each match's row 0, in the same
/// order and from the same hook darts, so that they may be taken from the shared matches of
/// that left graph ([`RuleSet::matches_of`]). True when the left graph is one node, its
/// hook, and the guard is row-invariant ([`row_invariant`]):
/// - the footprint of a match is then its hook orbit, so two hook orbits never give one
///   footprint, and [`find_all`]'s de-duplication never compares matches of two orbits;
/// - without the guard, [`find_all`] takes the first dart of each hook orbit (in dart
///   order) that matches, and marks the orbit; with it, that same dart gives the same match,
///   whose guard has one value on every row: where it holds, the match is kept, and where it
///   fails the orbit is marked (a leading conjunct failing on the hook dart alone fails at
///   every dart of the orbit, which then gives nothing either way).
///
/// Integrators (`where !v.fixed`) and the predicates that hold or load vertices and select
/// material regions are of this kind: they reuse the vertex or element matches of the rules
/// planned before them instead of walking every dart of the map again.
fn guard_filters_shared(rule: &Rule, embs: &[EmbDecl]) -> bool {
    !rule.changes_topology
        && one_node(rule)
        && rule.hooks.len() == 1
        && rule
            .guard
            .as_ref()
            .is_some_and(|e| row_invariant(e, &left_labels(rule), embs))
}

impl Clone for RuleSet {
    fn clone(&self) -> Self {
        let mut r = RuleSet::new(self.checked.clone());
        r.compile = self.compile;
        r.jit = self.jit;
        r.backend.clone_from(&self.backend);
        r
    }
}

/// A [`GMap::changes_since`] answer and the map state it was given for: (identity and
/// topology version, change record, version asked for).
#[derive(Debug)]
struct ChangesMemo {
    key: ((u64, u64), (u64, u64), u64),
    changes: Arc<(Vec<Dart>, Vec<Dart>)>,
}

/// The plan of a computation rule, and what it was computed from.
#[derive(Debug)]
struct Plan {
    /// The map's identity and topology version ([`GMap::identity`]).
    identity: (u64, u64),
    /// Write counts of the embeddings the guard reads.
    reads: Vec<u64>,
    kind: PlanKind,
    /// What patching the plan after a topology change needs (see [`RuleSet::patch_plan`]);
    /// `None` for a plan that is rebuilt instead.
    index: Option<Index>,
}

/// The matches of a plan by number, for patching it: match `k` is the `k`-th match the plan
/// was built with or appended (compiled plans number their rows' matches the same way).
#[derive(Debug)]
struct Index {
    /// The rule's embeddings on the map when the plan was built.
    ids: Vec<EmbeddingId>,
    /// Per match: whether it is still in the plan.
    alive: Vec<bool>,
    /// Matches still in the plan.
    live: usize,
    /// Per match, its hook orbit's darts: `hook_darts[hook_start[k]..hook_start[k + 1]]`.
    hook_start: Vec<u32>,
    hook_darts: Vec<u32>,
    /// Per dart, the match whose hook orbit held it when that match was added (`u32::MAX`
    /// for none). Hook orbits of the live matches are disjoint (as in [`find_all`], where a
    /// match's hook darts are marked used), so an entry naming a live match is right; one
    /// naming a dropped match is stale.
    of_hook: Vec<u32>,
}

impl Index {
    fn new(ids: Vec<EmbeddingId>, capacity: usize) -> Index {
        Index {
            ids,
            alive: Vec::new(),
            live: 0,
            hook_start: vec![0],
            hook_darts: Vec::new(),
            of_hook: vec![u32::MAX; capacity],
        }
    }

    /// Adds `m` (hooked at node `hook`) and returns its number.
    fn push(&mut self, m: &Match, hook: usize) -> u32 {
        let k = self.alive.len() as u32;
        self.alive.push(true);
        self.live += 1;
        for &d in &m.darts[hook] {
            self.hook_darts.push(d.0);
            self.of_hook[d.index()] = k;
        }
        self.hook_start.push(self.hook_darts.len() as u32);
        k
    }

    /// The live match whose hook orbit holds `d`, if any.
    fn live_at(&self, d: Dart) -> Option<u32> {
        let k = *self.of_hook.get(d.index())?;
        (k != u32::MAX && self.alive[k as usize]).then_some(k)
    }
}

/// Per left node of `rule` (single hook), the labels of the arcs through which
/// [`match_at`] reaches its darts from the hook's, in order (the hook: none); `None` for a
/// node it does not reach. The same fixed-point loop as [`match_at`]'s, so node `n`'s dart at
/// row `r` is `alpha_{l_k}(... alpha_{l_1}(hook dart at row r))`.
fn node_paths(rule: &Rule) -> Vec<Option<Vec<u8>>> {
    let mut path: Vec<Option<Vec<u8>>> = vec![None; rule.nodes.len()];
    path[rule.hooks[0]] = Some(Vec::new());
    loop {
        let mut progress = false;
        let mut missing = false;
        for &(a, i, b) in &rule.left_arcs {
            for (p, q) in [(a, b), (b, a)] {
                if path[p].is_some() && path[q].is_none() {
                    let mut v = path[p].clone().expect("checked");
                    v.push(i);
                    path[q] = Some(v);
                    progress = true;
                }
            }
            missing |= path[a].is_none() || path[b].is_none();
        }
        if !progress || !missing {
            break;
        }
    }
    path
}

#[derive(Debug)]
enum PlanKind {
    /// Compiled to flat index arrays and a program (see [`crate::compiled`]).
    Compiled(Box<crate::compiled::Plan>),
    /// Left to the interpreter: the matches (shared with the rules of the same pattern).
    Matches(Arc<Vec<Match>>),
}

struct Bound<'a> {
    rule: &'a Rule,
    embs: &'a [EmbDecl],
    ids: Vec<EmbeddingId>,
    params: Vec<Val>,
}

impl RuleSet {
    /// Wraps checked rules.
    pub fn new(checked: Checked) -> Self {
        RuleSet {
            checked,
            plans: std::sync::Mutex::new(HashMap::new()),
            shared: std::sync::Mutex::new(SharedMatches::default()),
            compile: true,
            jit: crate::native::enabled_by_env(),
            backend: crate::native::default_backend(),
            patches: std::sync::atomic::AtomicUsize::new(0),
            in_place_patches: std::sync::atomic::AtomicUsize::new(0),
            builds: std::sync::atomic::AtomicUsize::new(0),
            rebuilt: std::sync::atomic::AtomicUsize::new(0),
            fallbacks: std::sync::atomic::AtomicUsize::new(0),
            guard_plans: std::sync::Mutex::new(HashMap::new()),
            guard_runs: std::sync::atomic::AtomicUsize::new(0),
            guard_patches: std::sync::atomic::AtomicUsize::new(0),
            culled_runs: std::sync::atomic::AtomicUsize::new(0),
            changes: std::sync::Mutex::new(None),
        }
    }

    /// [`GMap::changes_since`]`(version)`, shared by the plans that ask for it at one state
    /// of the map: the answer is kept with the map's identity and topology version and the
    /// state of its change record ([`GMap::change_record`]), which together fix it (every
    /// change the record answers from adds an entry or moves the version), and given again
    /// while they are the same.
    fn changes_since(&self, g: &GMap, version: u64) -> Option<Arc<(Vec<Dart>, Vec<Dart>)>> {
        let key = (g.identity(), g.change_record()?, version);
        let mut memo = self
            .changes
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(m) = memo.as_ref().filter(|m| m.key == key) {
            return Some(Arc::clone(&m.changes));
        }
        let changes = Arc::new(g.changes_since(version)?);
        *memo = Some(ChangesMemo {
            key,
            changes: Arc::clone(&changes),
        });
        Some(changes)
    }

    /// The dimension of the rules.
    pub fn dimension(&self) -> usize {
        self.checked.dim
    }

    /// The rules.
    pub fn rules(&self) -> &[Rule] {
        &self.checked.rules
    }

    /// The checked model declarations (see [`crate::model`]).
    pub fn models(&self) -> &[crate::model::Model] {
        &self.checked.models
    }

    /// The model declared as `name`, if any.
    pub fn model(&self, name: &str) -> Option<&crate::model::Model> {
        self.checked.models.iter().find(|m| m.name == name)
    }

    /// The declared embeddings.
    pub fn embeddings(&self) -> &[EmbDecl] {
        &self.checked.embeddings
    }

    /// The rule named `name`.
    pub fn rule(&self, name: &str) -> Result<&Rule, ApplyError> {
        self.checked
            .rules
            .iter()
            .find(|r| r.name == name)
            .ok_or_else(|| ApplyError::UnknownRule(name.to_string()))
    }

    /// Checks that `g` fits the rules: same dimension, and every declared embedding present
    /// with the same type and orbit (an absent one is added, zero everywhere; a derived one is
    /// added and computed). Refreshes stale derived embeddings.
    pub fn prepare(&self, g: &mut GMap) -> Result<Vec<EmbeddingId>, ApplyError> {
        self.prepare_some(g, |_, _| true)
    }

    /// [`RuleSet::prepare`] for the embeddings named in `names` only (and the sources of the
    /// derived ones among them); the others keep their state.
    pub fn prepare_named(&self, g: &mut GMap, names: &[&str]) -> Result<(), ApplyError> {
        self.prepare_some(g, |_, e| names.contains(&e.name.as_str()))
            .map(|_| ())
    }

    /// Prepares the embeddings `want` selects, and the sources of the derived ones; the ids
    /// of the others are theirs in `g` if they exist, else [`EmbeddingId`]`(u32::MAX)`, never
    /// dereferenced by a caller that only uses what it asked for.
    fn prepare_some(
        &self,
        g: &mut GMap,
        want: impl Fn(usize, &EmbDecl) -> bool,
    ) -> Result<Vec<EmbeddingId>, ApplyError> {
        let embs = &self.checked.embeddings;
        let mut needed: Vec<bool> = embs.iter().enumerate().map(|(k, e)| want(k, e)).collect();
        // the sources of derived embeddings, transitively (declared before their users)
        for k in (0..embs.len()).rev() {
            if needed[k] {
                if let Some((_, src)) = embs[k].derived {
                    needed[src] = true;
                }
            }
        }
        if g.dimension() != self.checked.dim {
            return Err(ApplyError::Map(format!(
                "the rules are for dimension {}, the map has dimension {}",
                self.checked.dim,
                g.dimension()
            )));
        }
        let mut ids = Vec::new();
        for (k, e) in self.checked.embeddings.iter().enumerate() {
            if !needed[k] {
                ids.push(g.embedding_id(&e.name).unwrap_or(EmbeddingId(u32::MAX)));
                continue;
            }
            let ty = emb_type(e.ty);
            let id = if let Some(id) = g.embedding_id(&e.name) {
                let have = g.embedding(id);
                if have.ty() != ty || have.orbit() != e.orbit {
                    return Err(ApplyError::Map(format!(
                        "embedding '{}' is {} on {} in the map but {} on {} in the rules",
                        e.name,
                        have.ty(),
                        have.orbit(),
                        ty,
                        e.orbit
                    )));
                }
                id
            } else if let Some((agg, src)) = e.derived {
                let src = &self.checked.embeddings[src].name;
                g.add_derived(&e.name, src, e.orbit, agg)
                    .map_err(|x| ApplyError::Map(x.to_string()))?
            } else {
                g.add_embedding(&e.name, ty, e.orbit, e.policy)
                    .map_err(|x| ApplyError::Map(x.to_string()))?
            };
            ids.push(id);
        }
        g.refresh_derived();
        Ok(ids)
    }

    fn bind<'a>(
        &'a self,
        g: &mut GMap,
        name: &str,
        params: &Params,
    ) -> Result<Bound<'a>, ApplyError> {
        self.bind_for(g, name, params, false)
    }

    /// Binds rule `name`: its parameters, and the embeddings it uses (`guard_only`: those its
    /// guard reads, enough to find its matches). A model's file may declare data for elements
    /// the mesh does not have: a rule without matches adds nothing to the map.
    fn bind_for<'a>(
        &'a self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        guard_only: bool,
    ) -> Result<Bound<'a>, ApplyError> {
        let rule = self.rule(name)?;
        let used = if guard_only {
            let mut v = rule.guard_reads.clone();
            v.sort_unstable();
            v
        } else {
            rule_embeddings(rule)
        };
        let ids = self.prepare_some(g, |k, _| used.binary_search(&k).is_ok())?;
        let mut vals = Vec::new();
        for (p, ty) in &rule.params {
            let v = params.get(p).ok_or_else(|| ApplyError::Param {
                rule: name.into(),
                message: format!("missing parameter '{p}' ({ty})"),
            })?;
            let v = match (v, ty) {
                (Val::I(i), Ty::F64) => Val::F(*i as f64),
                (v, t) if v.ty() == *t => v.clone(),
                (v, t) => {
                    return Err(ApplyError::Param {
                        rule: name.into(),
                        message: format!("parameter '{p}' is {t}, got a {}", v.ty()),
                    })
                }
            };
            vals.push(v);
        }
        for k in params.keys() {
            if !rule.params.iter().any(|(p, _)| p == k) {
                return Err(ApplyError::Param {
                    rule: name.into(),
                    message: format!("unknown parameter '{k}'"),
                });
            }
        }
        Ok(Bound {
            rule,
            embs: &self.checked.embeddings,
            ids,
            params: vals,
        })
    }

    /// Applies rule `name` once, with its hooks at `hooks`.
    pub fn apply_at(
        &self,
        g: &mut GMap,
        name: &str,
        hooks: &[Dart],
        params: &Params,
    ) -> Result<ApplyReport, ApplyError> {
        let b = self.bind(g, name, params)?;
        let rule = b.rule;
        if hooks.len() != rule.hooks.len() {
            return Err(ApplyError::Hooks {
                rule: name.into(),
                message: format!(
                    "it has {} hook(s), {} dart(s) given",
                    rule.hooks.len(),
                    hooks.len()
                ),
            });
        }
        for &h in hooks {
            if !g.is_alive(h) {
                return Err(ApplyError::Hooks {
                    rule: name.into(),
                    message: format!("dart {h} does not exist"),
                });
            }
        }
        let at = hooks
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", ");
        let m = match_at(g, rule, hooks).map_err(|reason| ApplyError::NoMatch {
            rule: name.into(),
            at: at.clone(),
            reason,
        })?;
        if let Some(guard) = &rule.guard {
            let mut ev = Eval::new(g, &b, &m);
            let ok = ev
                .eval(guard, 0)
                .map_err(|e| eval_err(name, hooks[0], &e))?;
            if ok != Val::B(true) {
                return Err(ApplyError::NoMatch {
                    rule: name.into(),
                    at,
                    reason: "the 'where' guard is false".into(),
                });
            }
        }
        apply_matches(g, &b, &[m], &mut Poll::new(&never))
    }

    /// Every non-overlapping match of rule `name` (single-hook rules), in dart order, whose
    /// guard holds.
    pub fn find_matches(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
    ) -> Result<Vec<Match>, ApplyError> {
        let b = self.bind(g, name, params)?;
        find_all(g, &b, &mut Poll::new(&never))
    }

    /// Applies rule `name` at every match at once (see the module docs).
    pub fn apply_everywhere(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
    ) -> Result<ApplyReport, ApplyError> {
        self.apply_everywhere_interruptible(g, name, params, &never)
    }

    /// [`RuleSet::apply_everywhere`] for a rule that changes the topology and whose guard the
    /// caller knows to be false wherever the box bounding the values the guard reads of the
    /// `vec3` embedding `region.embedding` (in one hook orbit's row) misses the box
    /// `region.lo..=region.hi`: the same matches, found by evaluating the compiled guard only
    /// at the hook orbits that may meet the box (see [`Region`]), so that its cost grows
    /// with them, not with the map. Where the guard is not compiled, or does not read that
    /// embedding, every hook orbit is tried, as by [`RuleSet::apply_everywhere`].
    ///
    /// # Errors
    /// Those of [`RuleSet::apply_everywhere`]; an embedding `region` names that the map
    /// lacks or that is not `vec3`; corners that are not finite, or a `lo` above `hi`.
    pub fn apply_everywhere_within(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        region: &Region,
    ) -> Result<ApplyReport, ApplyError> {
        vec3_embedding(g, name, &region.embedding)?;
        let corners = region.lo.iter().chain(&region.hi);
        if !corners.clone().all(|v| v.is_finite()) || (0..3).any(|k| region.lo[k] > region.hi[k]) {
            return Err(ApplyError::Map(format!(
                "rule '{name}': the region's corners must be finite with lo <= hi in each coordinate, got lo {:?} and hi {:?}",
                region.lo, region.hi
            )));
        }
        self.apply_with(g, name, params, &never, Some(region))
    }

    /// [`RuleSet::apply_everywhere`], calling `interrupt` once per [`INTERRUPT_EVERY`] darts
    /// tried or rows evaluated (and before a compiled plan runs): when it returns true the
    /// application stops with [`ApplyError::Interrupted`] before changing the topology or
    /// any value, so the map stays valid. A caller that answers Ctrl-C polls its signal
    /// flag there.
    pub fn apply_everywhere_interruptible(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        interrupt: &dyn Fn() -> bool,
    ) -> Result<ApplyReport, ApplyError> {
        self.apply_with(g, name, params, interrupt, None)
    }

    /// [`RuleSet::apply_everywhere`] for a computation rule whose values are to be tested
    /// before any is written: `check(embedding, values)` is called with the values of each
    /// embedding the rule writes (`width` floats per orbit, for a part of the orbits at a
    /// time; every value written is in one call, and all are finite), and the rule writes
    /// them only when every call returns true. A caller that would otherwise save what the
    /// rule overwrites, to restore it when the result is refused, needs no copy.
    ///
    /// `Some(report)`: applied, every value passed. `None`: nothing written, because a call
    /// returned false, or because the values could not be tested before being written (a
    /// rule that changes the topology, one without a compiled plan, plans switched off, or a
    /// plan run that failed, whose error [`RuleSet::apply_everywhere`] would report): the
    /// caller applies the rule another way.
    ///
    /// # Errors
    /// Those of [`RuleSet::apply_everywhere`] raised before anything is written (binding,
    /// matching); the map is then unchanged.
    pub fn apply_everywhere_checked(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        check: &(dyn Fn(EmbeddingId, &[f64]) -> bool + Sync),
    ) -> Result<Option<ApplyReport>, ApplyError> {
        self.apply_inner(
            g,
            name,
            params,
            &never,
            None,
            Some(check),
            true,
            false,
            None,
        )
    }

    /// [`RuleSet::apply_everywhere`] for a rule applied once (a simulation's set-up: rest
    /// shape, material, masses, a model's init rules): the same matches and values, but a
    /// computation rule's plan is dropped after it ran instead of being kept for the next
    /// application, and builds no index of the darts its rows read (the index serves only
    /// to patch a kept plan after a topology change). At 10^5 tetrahedra the indexes of the
    /// set-up's rules cost about a tenth of it.
    ///
    /// # Errors
    /// Those of [`RuleSet::apply_everywhere`].
    pub fn apply_once(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
    ) -> Result<ApplyReport, ApplyError> {
        self.apply_once_inner(g, name, params, None)
    }

    /// [`RuleSet::apply_once`], with a hook dart of each match of the computation rule
    /// (one of the darts of its hook node), where the application found its matches (it
    /// does at its first run: `None` otherwise, say for a rule applied before without being
    /// dropped). What a simulation tells the elements a model's init rules handled by.
    ///
    /// # Errors
    /// Those of [`RuleSet::apply_everywhere`].
    pub fn apply_once_hooks(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
    ) -> Result<(ApplyReport, Option<Vec<Dart>>), ApplyError> {
        let mut hooks = None;
        let report = self.apply_once_inner(g, name, params, Some(&mut hooks))?;
        Ok((report, hooks))
    }

    /// [`RuleSet::apply_once`], with the hooks of [`RuleSet::apply_once_hooks`] where
    /// `hooks` asks for them.
    fn apply_once_inner(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        hooks: Option<&mut Option<Vec<Dart>>>,
    ) -> Result<ApplyReport, ApplyError> {
        let out = self
            .apply_inner(g, name, params, &never, None, None, false, false, hooks)
            .map(Option::unwrap_or_default);
        // the plan just built (or an earlier one of this rule): dropped
        if let Some(index) = self.checked.rules.iter().position(|r| r.name == name) {
            self.plans
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .remove(&index);
        }
        out
    }

    fn apply_with(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        interrupt: &dyn Fn() -> bool,
        region: Option<&Region>,
    ) -> Result<ApplyReport, ApplyError> {
        self.apply_inner(g, name, params, interrupt, region, None, true, false, None)
            .map(Option::unwrap_or_default)
    }

    /// [`RuleSet::apply_everywhere`] for a computation rule whose written values are
    /// scratch, rewritten before they are read again (a simulation's forces, at every
    /// step): its compiled plan writes the values of each part of its rows (a chunk) as
    /// soon as they are evaluated, while they are in cache, instead of evaluating every row
    /// before writing any. The same values are written. What differs is a failure: the
    /// values of the chunks evaluated before it may have been written (the embeddings the
    /// rule reads are unchanged, and the map stays valid); the error is the one
    /// [`RuleSet::apply_everywhere`] reports. A rule that reads an embedding it writes, one
    /// that changes the topology or one without a compiled plan is applied as by
    /// [`RuleSet::apply_everywhere`].
    ///
    /// # Errors
    /// Those of [`RuleSet::apply_everywhere`].
    pub fn apply_everywhere_eager(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
    ) -> Result<ApplyReport, ApplyError> {
        self.apply_inner(g, name, params, &never, None, None, true, true, None)
            .map(Option::unwrap_or_default)
    }

    /// The application of [`RuleSet::apply_with`], with the `check` of
    /// [`RuleSet::apply_everywhere_checked`] (`None` only with a check); `keep`: a
    /// computation rule's plan is built with its index by dart, to be patched after a
    /// topology change (not for [`RuleSet::apply_once`], which drops it once it ran);
    /// `eager`: the writes of [`RuleSet::apply_everywhere_eager`]; `hooks`: where to put a
    /// hook dart of each match of a computation rule, when its matches are found (a plan
    /// built now; see [`RuleSet::apply_once_hooks`]).
    #[allow(clippy::too_many_arguments)]
    fn apply_inner(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        interrupt: &dyn Fn() -> bool,
        region: Option<&Region>,
        check: Option<&crate::compiled::ValueCheck<'_>>,
        keep: bool,
        eager: bool,
        mut hooks: Option<&mut Option<Vec<Dart>>>,
    ) -> Result<Option<ApplyReport>, ApplyError> {
        let poll = &mut Poll::new(interrupt);
        let b = self.bind_for(g, name, params, true)?;
        if b.rule.changes_topology && check.is_some() {
            // its values cannot be tested before it changes the map
            return Ok(None);
        }
        if b.rule.changes_topology {
            let ms = match self.guarded_matches(g, &b, poll, region)? {
                Some(ms) => ms,
                None => find_all(g, &b, poll)?,
            };
            if ms.is_empty() {
                return Ok(Some(ApplyReport::default()));
            }
            let b = self.bind(g, name, params)?;
            return apply_matches(g, &b, &ms, poll).map(Some);
        }
        // a computation rule: reuse its plan while the topology and the guard's inputs stay
        let index = self
            .checked
            .rules
            .iter()
            .position(|r| std::ptr::eq(r, b.rule))
            .expect("bound rule is ours");
        // with the values of the parameters the guard reads: the matches it accepts, so the
        // plan, depend on them (a rule applied again with another threshold)
        let reads = guard_state(g, &b);
        let mut plans = self
            .plans
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let fresh = plans
            .get(&index)
            .is_some_and(|p| p.identity == g.identity() && p.reads == reads);
        let patched = if fresh {
            None
        } else {
            plans
                .remove(&index)
                .and_then(|old| self.patch_plan(g, name, params, old, &reads))
        };
        if let Some(p) = patched {
            self.patches
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            plans.insert(index, p);
        } else if !fresh {
            self.builds
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let matches = self.matches_of(g, &b, poll)?;
            if let Some(h) = hooks.as_mut() {
                let hook = b.rule.hooks[0];
                **h = Some(
                    matches
                        .iter()
                        .filter_map(|m| m.darts.get(hook).and_then(|d| d.first().copied()))
                        .collect(),
                );
            }
            let index_of =
                if keep && patchable(b.rule, b.embs) && (self.compile || matches.is_empty()) {
                    // a plan without matches keeps the guard's embeddings only: a rule without
                    // matches adds nothing to the map (see `bind_for`)
                    let ids = if matches.is_empty() {
                        b.ids.clone()
                    } else {
                        self.bind(g, name, params)?.ids
                    };
                    let mut ix = Index::new(ids, g.capacity());
                    for m in matches.iter() {
                        ix.push(m, b.rule.hooks[0]);
                    }
                    Some(ix)
                } else {
                    None
                };
            let kind = if matches.is_empty() {
                PlanKind::Matches(matches)
            } else {
                let b = self.bind(g, name, params)?;
                match crate::compiled::compile(b.rule, b.embs) {
                    Ok(prog) if self.compile => {
                        PlanKind::Compiled(Box::new(crate::compiled::Plan::build(
                            prog,
                            b.rule,
                            g,
                            &b.ids,
                            &matches,
                            self.native(),
                        )))
                    }
                    _ => PlanKind::Matches(matches),
                }
            };
            // an interpreter plan with matches is rebuilt, not patched
            let index_of =
                index_of.filter(|_| !matches!(&kind, PlanKind::Matches(ms) if !ms.is_empty()));
            g.track_changes();
            plans.insert(
                index,
                Plan {
                    identity: g.identity(),
                    reads,
                    kind,
                    index: index_of,
                },
            );
        }
        let plan = plans.get_mut(&index).expect("inserted above");
        if matches!(&plan.kind, PlanKind::Matches(ms) if ms.is_empty()) {
            return Ok(Some(ApplyReport::default()));
        }
        let b = self.bind(g, name, params)?;
        match &mut plan.kind {
            PlanKind::Compiled(p) => {
                if (poll.check)() {
                    return Err(ApplyError::Interrupted {
                        rule: name.into(),
                        stage: "running its compiled plan",
                        found: p.matches(),
                        applied: 0,
                    });
                }
                if p.run(g, &b.ids, &b.params, check, eager).is_ok() {
                    return Ok(Some(ApplyReport {
                        matches: p.matches(),
                        evaluations: p.evaluations(),
                        ..ApplyReport::default()
                    }));
                }
                if check.is_some() {
                    // nothing written: the caller applies it another way
                    return Ok(None);
                }
                // the interpreter reports what failed, with the dart (or applies the rule
                // where a failure was in a branch the interpreter does not take)
                self.fallbacks
                    .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let ms = find_all(g, &b, poll)?;
                apply_matches(g, &b, &ms, poll).map(Some)
            }
            PlanKind::Matches(_) if check.is_some() => Ok(None),
            PlanKind::Matches(ms) => apply_matches(g, &b, ms, poll).map(Some),
        }
    }

    /// Patches the plan `old` of rule `name` for the map's new topology instead of
    /// rebuilding it; `None` when it cannot (then the caller rebuilds it).
    ///
    /// Why the patched plan is the one a rebuild gives (up to the order of its rows and the
    /// choice of each match's hook dart, which [`find_all`] makes by dart order): let `C` be
    /// the darts changed since the plan was built ([`GMap::changed_since`]: links, slots,
    /// created, removed) and `C*` the darts of `C` together with, for every orbit type the
    /// program aggregates over, the orbits (on the new map) of the live darts of `C`.
    /// - [`match_at`] reads only the links of the darts of the match it returns (its
    ///   footprint), and a compiled row reads only the slots of those darts and, through its
    ///   aggregates, the darts and slots of their orbits of the aggregated types. An orbit
    ///   (on the new map) that holds no dart of `C` is the same orbit, with the same slots, on
    ///   the old map: it is closed under the old links. So a match whose footprint misses
    ///   `C*` is found again, the same, from the same hook dart, and its rows are unchanged:
    ///   it is kept. Every other match is dropped.
    /// - A match of the new map whose footprint misses `C*` was a match of the old map with
    ///   the same footprint, which is kept: nothing to add. One whose footprint holds a dart
    ///   `y` of `C*`, as node `n`'s dart of some row, is found from the hook dart of that row,
    ///   which walking node `n`'s arc path ([`node_paths`]) back from `y` reaches. So every
    ///   dart of `C*`, walked back along every node's path, gives the candidate hooks; those
    ///   whose match holds a dart of `C*` are added, once per footprint.
    /// - The matches to drop are found the same way: walking back from a dart of `C*` along
    ///   node `n`'s path on the new map reaches the hook orbit of an old match holding it at
    ///   node `n`, or else a dart of `C` nearer the hook on that path, from which walking
    ///   back reaches it (every link before the first changed dart of the path is unchanged).
    /// - Without a guard, let `R` be the relinked darts of `C` ([`GMap::changes_since`]:
    ///   links changed, created, removed). A dropped match whose footprint misses `R` is the
    ///   match found again from its old hook dart, with the same darts ([`match_at`] reads
    ///   only its footprint's links): [`rebuild_unlinked`] rebuilds it without a search, and
    ///   the plan gives it new rows (its slots may have changed). A match of the new map
    ///   whose footprint misses `R` was one of the old map (the same links), so it is kept
    ///   or rebuilt; the others hold a dart `y` of `R` and are found from the hook darts
    ///   walked back from `y`, as above, with `R` in place of `C*`. (A guard may read values
    ///   that changed: a rebuilt match would need it again, so there every dart of `C*` is
    ///   walked back from.)
    ///
    /// Only rules without a guard (a guard may read what changed) and with one hook are
    /// patched, compiled plans or plans without matches, on the map (same identity) and
    /// embeddings they were built for, when the change record covers their version.
    fn patch_plan(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        old: Plan,
        reads: &[u64],
    ) -> Option<Plan> {
        let (id, version) = g.identity();
        if old.identity.0 != id || old.reads != reads {
            return None;
        }
        let Plan { kind, index, .. } = old;
        let mut ix = index?;
        // a plan without matches binds what its guard reads only (it must not create the
        // rule's other embeddings); if it gains matches it is rebuilt, below
        let empty = !matches!(kind, PlanKind::Compiled(_));
        let b = self.bind_for(g, name, params, empty).ok()?;
        let rule = b.rule;
        if !patchable(rule, b.embs)
            || (!empty
                && rule_embeddings(rule)
                    .iter()
                    .any(|&k| ix.ids.get(k) != b.ids.get(k)))
        {
            return None;
        }
        // without a guard, a dropped match whose footprint kept its links is rebuilt from its
        // hook dart, and the search looks only around the relinked darts (see below)
        let changes = self.changes_since(g, old.identity.1)?;
        let changed = &changes.0;
        let relinked = rule.guard.is_none().then(|| marks_of(g, &changes.1));
        let compiled = match kind {
            PlanKind::Compiled(p) => Some(p),
            PlanKind::Matches(ms) if ms.is_empty() && self.compile => None,
            PlanKind::Matches(_) => return None,
        };
        let aggs = match &compiled {
            Some(p) => p.agg_orbits(),
            None => crate::compiled::compile(rule, b.embs).ok()?.agg_orbits(),
        };
        // C* is C expanded along each chain of orbit types in turn
        let mut chains: Vec<Vec<OrbitType>> = aggs.into_iter().map(|o| vec![o]).collect();
        // a guard's too: it is evaluated now, so the values it reads must be unchanged, not
        // only their slots (see `expr_orbits`)
        if let Some(guard) = &rule.guard {
            expr_orbits(guard, b.embs, &mut chains);
        }
        let (star, candidates, dropped) =
            drop_changed(g, rule, &mut ix, changed, &chains, relinked.as_ref())?;
        let kept = ix.live;
        let hook = rule.hooks[0];
        // the dropped matches whose footprint kept its links, rebuilt (new numbers, new rows)
        let mut all: Vec<Match> = match &relinked {
            Some(r) => rebuild_unlinked(g, rule, &ix, &dropped, r)?,
            None => Vec::new(),
        };
        self.rebuilt
            .fetch_add(all.len(), std::sync::atomic::Ordering::Relaxed);
        let mut numbers: Vec<u32> = all.iter().map(|m| ix.push(m, hook)).collect();
        // new matches, from the candidate hooks not in a kept or rebuilt match's hook orbit
        // (where the left graph has one node, a footprint is one hook orbit: no two are the
        // same)
        let single = rule.nodes.iter().filter(|n| n.left.is_some()).count() == 1;
        let mut prints: std::collections::HashSet<Vec<u32>, FastHash> =
            std::collections::HashSet::default();
        let new = rematch(
            g,
            rule,
            &ix,
            relinked.as_ref().unwrap_or(&star),
            candidates,
            &rule.hook_images,
            |m| match &rule.guard {
                None => Some(true),
                // an error is left to a rebuild, which reports it
                Some(guard) => match Eval::new(g, &b, m).eval(guard, 0) {
                    Ok(Val::B(true)) => Some(true),
                    Ok(_) => Some(false),
                    Err(_) => None,
                },
            },
            |m| {
                if single {
                    return true;
                }
                let mut key: Vec<u32> = m.all_darts().map(|x| x.0).collect();
                key.sort_unstable();
                prints.insert(key)
            },
        )?;
        numbers.extend(new.iter().map(|m| ix.push(m, hook)));
        all.extend(new);
        let kind = match compiled {
            Some(p) => {
                let alive = &ix.alive;
                let (p, in_place) = p.patch(
                    rule,
                    g,
                    &b.ids,
                    &|k| alive[k as usize],
                    &dropped,
                    kept,
                    &all,
                    &numbers,
                );
                if in_place {
                    self.in_place_patches
                        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                PlanKind::Compiled(Box::new(p))
            }
            None if all.is_empty() => PlanKind::Matches(Arc::new(Vec::new())),
            // a plan without matches gains some: rebuilt (binding, and so creating, the
            // rule's embeddings)
            None => return None,
        };
        Some(Plan {
            identity: (id, version),
            reads: reads.to_vec(),
            kind,
            index: Some(ix),
        })
    }

    /// The matches [`find_all`] gives for `b`'s rule, a rule that changes the topology and
    /// has a guard, found through the guard compiled over every hook orbit (kept between
    /// applications and patched after topology changes as computation plans are, see
    /// [`RuleSet::patch_plan`]); `None` when that does not apply (compiled plans switched
    /// off, a guard the plan machinery does not cover or that is not [`row_invariant`], an
    /// evaluation the plan refuses), and the caller runs [`find_all`], which decides.
    ///
    /// Why the same matches: [`find_all`] tries the darts in increasing order. At a dart not
    /// in a kept footprint nor in a hook orbit that failed, it matches the left graph (the
    /// same footprint from every dart of the hook orbit, with the rows in another order),
    /// skips the match if its footprint meets a kept one, and else evaluates the guard at
    /// row 0, which gives one value on every row ([`row_invariant`]), so one for the whole
    /// hook orbit. So it keeps, in increasing order of their smallest darts, the hook orbits
    /// whose match passes the guard and misses the footprints kept before, each matched from
    /// its smallest dart. The plan has one row per hook orbit where the left graph matches
    /// (row 0 of its match): it gives the orbits that pass, and the loop below keeps them in
    /// that order, matched from the same darts.
    fn guarded_matches(
        &self,
        g: &mut GMap,
        b: &Bound,
        poll: &mut Poll,
        region: Option<&Region>,
    ) -> Result<Option<Vec<Match>>, ApplyError> {
        let rule = b.rule;
        let Some(index) = self.guard_plan_index(b) else {
            return Ok(None);
        };
        let mut plans = self
            .guard_plans
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let Some(mut gp) = self.guard_plan(g, b, plans.remove(&index), poll)? else {
            return Ok(None);
        };
        if (poll.check)() {
            // the plan stays (it is the map's), for the next application
            plans.insert(index, gp);
            return Err(ApplyError::Interrupted {
                rule: rule.name.clone(),
                stage: "running its compiled guard",
                found: 0,
                applied: 0,
            });
        }
        let culled = region.and_then(|r| {
            let id = g.embedding_id(&r.embedding)?;
            let rows = gp.candidates(g, &b.ids, id, r)?;
            gp.plan.guard_rows(g, &b.ids, &rows)
        });
        let run = match culled {
            Some(mut sub) => {
                self.culled_runs
                    .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                sub.run_guard(g, &b.ids, &b.params)
            }
            None => gp.plan.run_guard(g, &b.ids, &b.params),
        };
        let Ok(pass) = run else {
            plans.insert(index, gp);
            return Ok(None);
        };
        // the rows of dropped matches stay in a patched plan (see `patch_guard_plan`)
        let mut first: Vec<u32> = pass
            .iter()
            .filter(|&&k| gp.index.alive[k as usize])
            .map(|&k| gp.first[k as usize])
            .collect();
        first.sort_unstable();
        let mut used = Marks::with_capacity(g.capacity());
        let mut out = Vec::new();
        for d in first {
            let Some(m) = try_match(g, rule, &[Dart(d)]) else {
                // (a hook orbit matched from one of its darts matches from all)
                plans.insert(index, gp);
                return Ok(None);
            };
            if m.all_darts().any(|x| used.is_marked(x)) {
                continue;
            }
            for x in m.all_darts() {
                used.mark(x);
            }
            out.push(m);
        }
        plans.insert(index, gp);
        self.guard_runs
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Ok(Some(out))
    }

    /// The index of `b`'s rule when its matches can be found through a compiled guard (see
    /// [`RuleSet::guarded_matches`]): compiled plans on, a rule that changes the topology,
    /// with one hook and a [`row_invariant`] guard.
    fn guard_plan_index(&self, b: &Bound) -> Option<usize> {
        let rule = b.rule;
        let guard = rule.guard.as_ref()?;
        if !self.compile
            || !rule.changes_topology
            || rule.hooks.len() != 1
            || !row_invariant(guard, &left_labels(rule), b.embs)
        {
            return None;
        }
        self.checked
            .rules
            .iter()
            .position(|r| std::ptr::eq(r, rule))
    }

    /// The guard plan of `b`'s rule for the map as it is: `old` when it is current, `old`
    /// patched, or a new one; `None` when the guard does not compile.
    fn guard_plan(
        &self,
        g: &mut GMap,
        b: &Bound,
        old: Option<GuardPlan>,
        poll: &mut Poll,
    ) -> Result<Option<GuardPlan>, ApplyError> {
        let reads: Vec<EmbeddingId> = b.rule.guard_reads.iter().map(|&k| b.ids[k]).collect();
        let gp = match old {
            Some(gp) if gp.identity == g.identity() && gp.reads == reads => Some(gp),
            Some(gp) if gp.reads == reads => {
                let p = self
                    .changes_since(g, gp.identity.1)
                    .and_then(|changes| patch_guard_plan(g, b, gp, &changes));
                if p.is_some() {
                    self.guard_patches
                        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                p
            }
            _ => None,
        };
        match gp {
            Some(gp) => Ok(Some(gp)),
            None => build_guard_plan(g, b, reads, self.native(), poll),
        }
    }

    /// Builds now the compiled guard of `name`, a rule that changes the topology, for the
    /// map as it is (see [`RuleSet::guarded_matches`]): its first application then only
    /// patches and runs it, instead of building it. A simulation does this when it is set
    /// up for the cuts its configuration declares. `params` are any values of the rule's
    /// parameters (the plan does not depend on them). Returns whether the guard compiled
    /// (when not, applications find their matches through the interpreter, as before).
    ///
    /// # Errors
    /// An unknown rule or parameter, a map the rules do not fit ([`ApplyError`]).
    pub fn prepare_guard(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
    ) -> Result<bool, ApplyError> {
        self.prepare_guard_with(g, name, params, None)
    }

    /// [`RuleSet::prepare_guard`] for applications through
    /// [`RuleSet::apply_everywhere_within`] with regions of the `vec3` embedding
    /// `embedding`: the guard's rows indexed by where they read it too, so that the first
    /// such application only looks them up.
    ///
    /// # Errors
    /// Those of [`RuleSet::prepare_guard`]; an `embedding` the map lacks or that is not
    /// `vec3`.
    pub fn prepare_guard_within(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        embedding: &str,
    ) -> Result<bool, ApplyError> {
        let id = vec3_embedding(g, name, embedding)?;
        self.prepare_guard_with(g, name, params, Some(id))
    }

    fn prepare_guard_with(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        within: Option<EmbeddingId>,
    ) -> Result<bool, ApplyError> {
        let b = self.bind_for(g, name, params, true)?;
        let Some(index) = self.guard_plan_index(&b) else {
            return Ok(false);
        };
        let mut plans = self
            .guard_plans
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let old = plans.remove(&index);
        match self.guard_plan(g, &b, old, &mut Poll::new(&never))? {
            Some(mut gp) => {
                // the native code too, so that the first application only runs it
                gp.plan.compile_now(g, &b.ids);
                if let Some(id) = within {
                    let cols = gp.plan.cols_reading(&b.ids, id);
                    if let Some(x) = g.embedding(id).real_column().filter(|_| !cols.is_empty()) {
                        gp.cull = gp.index_rows(&cols, id, x);
                    }
                }
                plans.insert(index, gp);
                Ok(true)
            }
            None => Ok(false),
        }
    }

    /// How many applications of rules that change the topology found their matches through
    /// a compiled guard (see [`RuleSet::guarded_matches`]), and how many times such a guard's
    /// plan was patched after a topology change instead of rebuilt, since this rule set was
    /// made.
    pub fn compiled_guard_runs(&self) -> (usize, usize) {
        (
            self.guard_runs.load(std::sync::atomic::Ordering::Relaxed),
            self.guard_patches
                .load(std::sync::atomic::Ordering::Relaxed),
        )
    }

    /// How many applications of [`RuleSet::apply_everywhere_within`] ran their compiled
    /// guard over the hook orbits near the region only, since this rule set was made.
    pub fn culled_guard_runs(&self) -> usize {
        self.culled_runs.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// How many runs of a compiled plan (native code or the plan evaluator) failed (a value
    /// not finite, a built-in refusing its argument, two writes of one orbit that differ) and
    /// were left to the interpreter, which reports the error or applies the rule, since this
    /// rule set was made.
    pub fn plan_fallbacks(&self) -> usize {
        self.fallbacks.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// How many plans of computation rules were built from a search of their matches (the
    /// first application on a map, and again where a plan cannot be kept or patched: what
    /// its guard reads was written, a parameter it reads changed, the map changed beyond a
    /// patch), since this rule set was made.
    pub fn plans_built(&self) -> usize {
        self.builds.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// How many times a plan was patched after a topology change instead of rebuilt (see
    /// [`RuleSet::patch_plan`]), since this rule set was made.
    pub fn plan_patches(&self) -> usize {
        self.patches.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// How many of [`RuleSet::plan_patches`] left the kept rows in place (a plan without
    /// duplicate writes: the dropped matches' rows stay, dead, until a patch
    /// compacts the plan; see "Topology changes during a run" in the README).
    pub fn plan_patches_in_place(&self) -> usize {
        self.in_place_patches
            .load(std::sync::atomic::Ordering::Relaxed)
    }

    /// How many matches [`RuleSet::plan_patches`] rebuilt from their hook dart without a
    /// search (a match dropped because slots it reads changed, its footprint's links not),
    /// since this rule set was made.
    pub fn matches_rebuilt(&self) -> usize {
        self.rebuilt.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Drops every plan (they are rebuilt when needed): after rules that run once. The
    /// matches shared by rules of one pattern stay (until the topology changes or
    /// [`RuleSet::clear_shared_matches`]), so the rules run next reuse those of the rules
    /// run before (a simulation's step rules those of its init rules).
    pub fn clear_plans(&self) {
        self.plans
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clear();
    }

    /// Drops the matches kept for rules of the same pattern (they are found again when a
    /// plan needs them): a caller that has planned what it will run (a simulation, after a
    /// step) frees them, since compiled plans no longer need them.
    pub fn clear_shared_matches(&self) {
        let mut shared = self
            .shared
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if !shared.by_pattern.is_empty() {
            shared.by_pattern.clear();
        }
    }

    /// How many patterns have matches kept for sharing now (see [`RuleSet::clear_shared_matches`]).
    pub fn shared_patterns(&self) -> usize {
        self.shared
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .by_pattern
            .len()
    }

    /// The matches of a computation rule on `g`: those of an earlier rule of the same
    /// pattern on the same map state when there are some, else found now (and kept for the
    /// next rule of that pattern).
    fn matches_of(
        &self,
        g: &GMap,
        b: &Bound,
        poll: &mut Poll,
    ) -> Result<Arc<Vec<Match>>, ApplyError> {
        if let Some(guard) = b
            .rule
            .guard
            .as_ref()
            .filter(|_| guard_filters_shared(b.rule, b.embs))
        {
            let all = self.shared_of(g, b, left_graph_key(b.rule), poll, true)?;
            // as `find_all` decides: a match one of whose leading conjuncts reading the hook
            // alone is false is skipped, whatever the others give (an error among them is
            // not reported); else the guard is evaluated whole
            let hook = b.rule.hooks[0];
            let conjuncts = hook_prefix(guard, hook);
            let mut kept = Vec::new();
            for m in all.iter() {
                if poll.tick(1) {
                    return Err(ApplyError::Interrupted {
                        rule: b.rule.name.clone(),
                        stage: "finding matches",
                        found: kept.len(),
                        applied: 0,
                    });
                }
                let mut ev = Eval::new(g, b, m);
                if conjuncts
                    .iter()
                    .any(|e| matches!(ev.eval(e, 0), Ok(Val::B(false))))
                {
                    continue;
                }
                if ev
                    .eval(guard, 0)
                    .map_err(|e| eval_err(&b.rule.name, m.darts[hook][0], &e))?
                    == Val::B(true)
                {
                    kept.push(m.clone());
                }
            }
            return Ok(Arc::new(kept));
        }
        let Some(key) = pattern_key(b.rule).or_else(|| guarded_key(g, b)) else {
            return Ok(Arc::new(find_all(g, b, poll)?));
        };
        self.shared_of(g, b, key, poll, false)
    }

    /// The matches of the left graph `key` on `g`, shared or found now (and kept); without
    /// the guard of `b.rule` when `unguarded`.
    fn shared_of(
        &self,
        g: &GMap,
        b: &Bound,
        key: String,
        poll: &mut Poll,
        unguarded: bool,
    ) -> Result<Arc<Vec<Match>>, ApplyError> {
        {
            let mut shared = self
                .shared
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            if shared.identity != g.identity() {
                shared.by_pattern.clear();
                shared.identity = g.identity();
            }
            if let Some(ms) = shared.by_pattern.get(&key) {
                return Ok(Arc::clone(ms));
            }
        }
        let ms = Arc::new(if unguarded {
            let rule = Rule {
                guard: None,
                ..b.rule.clone()
            };
            find_all(
                g,
                &Bound {
                    rule: &rule,
                    embs: b.embs,
                    ids: b.ids.clone(),
                    params: b.params.clone(),
                },
                poll,
            )?
        } else {
            find_all(g, b, poll)?
        });
        let mut shared = self
            .shared
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if shared.identity == g.identity() {
            shared.by_pattern.insert(key, Arc::clone(&ms));
        }
        Ok(ms)
    }

    /// Whether computation rules run through compiled plans (see [`RuleSet::set_compiled`]).
    pub fn compiled(&self) -> bool {
        self.compile
    }

    /// Whether computation rules, and the guards of rules that change the topology, run
    /// through compiled plans (the default) or through the interpreter only (for comparisons
    /// and tests: both give the same results).
    pub fn set_compiled(&mut self, on: bool) {
        self.compile = on;
        self.plans
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clear();
        self.guard_plans
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clear();
    }

    /// Whether compiled plans run native code generated by the rule set's backend (see
    /// [`crate::native`]; the facade `topomech-rules` installs Cranelift's)
    /// instead of the plan evaluator: the same results bit for bit, the evaluator staying
    /// the fallback for what the code generator does not cover. The default is on, unless
    /// the environment variable `TOPOMECH_JIT` is `0`, `false`, `off` or `no` (read once per process); this
    /// overrides it for this rule set (for comparisons and tests). Plans are rebuilt.
    pub fn set_jit(&mut self, on: bool) {
        self.jit = on;
        self.plans
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clear();
    }

    /// Whether compiled plans run native code (see [`RuleSet::set_jit`]).
    pub fn jit(&self) -> bool {
        self.jit
    }

    /// Hands the rule set the code generator its compiled plans' native code comes from
    /// (see [`crate::native`]), or none: then compiled plans run the evaluator whatever the
    /// switch ([`RuleSet::set_jit`]) says. [`RuleSet::new`] starts with the process-wide
    /// default ([`crate::native::set_default_backend`]). Plans are rebuilt.
    pub fn set_backend(&mut self, backend: Option<Arc<dyn NativeBackend>>) {
        self.backend = backend;
        self.plans
            .get_mut()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clear();
    }

    /// Whether the rule set has a code generator for native code (see
    /// [`RuleSet::set_backend`]).
    pub fn has_backend(&self) -> bool {
        self.backend.is_some()
    }

    /// The backend plans built now compile their native code with: the rule set's, when
    /// its switch is on.
    fn native(&self) -> Option<Arc<dyn NativeBackend>> {
        self.backend.clone().filter(|_| self.jit)
    }

    /// Which computation rules run native code: `(rule, native)` for every rule whose
    /// compiled plan exists now and has run at least once (the code is generated at a plan's
    /// first run); `false` where the plan's program uses what the code generator does not
    /// cover, or the switch is off.
    pub fn plan_native(&self) -> Vec<(String, bool)> {
        let plans = self
            .plans
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let mut out: Vec<(String, bool)> = plans
            .iter()
            .filter_map(|(k, p)| match &p.kind {
                PlanKind::Compiled(c) => Some((self.checked.rules[*k].name.clone(), c.is_native())),
                PlanKind::Matches(_) => None,
            })
            .collect();
        out.sort();
        out
    }

    /// Which computation rules run compiled: `(rule, compiled)` for every rule whose plan
    /// exists now and has matches (a plan is built by the rule's first global application).
    pub fn plan_kinds(&self) -> Vec<(String, bool)> {
        let plans = self
            .plans
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let mut out: Vec<(String, bool)> = plans
            .iter()
            .filter(|(_, p)| !matches!(&p.kind, PlanKind::Matches(ms) if ms.is_empty()))
            .map(|(k, p)| {
                (
                    self.checked.rules[*k].name.clone(),
                    matches!(p.kind, PlanKind::Compiled(_)),
                )
            })
            .collect();
        out.sort();
        out
    }

    /// Bytes held by the plans (index arrays, output buffers, cached matches).
    pub fn plan_bytes(&self) -> usize {
        let plans = self
            .plans
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        plans
            .values()
            .map(|p| match &p.kind {
                PlanKind::Compiled(c) => c.memory_bytes(),
                PlanKind::Matches(ms) => ms
                    .iter()
                    .map(|m| {
                        std::mem::size_of::<Match>() + m.next.capacity() * 4 + m.darts.heap_bytes()
                    })
                    .sum(),
            })
            .sum()
    }

    /// For every match of rule `name` that [`RuleSet::apply_everywhere`] applies (a guard's
    /// false matches left out), the darts its program and guard can reach: every dart of its
    /// left nodes, and every dart of each orbit the rule reads or writes through a node (an
    /// embedding's orbit, an aggregate's orbit), except the orbits whose labels all belong
    /// to `within`: those stay inside the `within` orbit of the node's dart, which the
    /// caller resolves itself (a Jacobian's coupling graph passes the vertex orbit, so that
    /// only orbits that leave a vertex are walked). Darts may repeat within a footprint.
    /// What a simulation builds the vertex coupling graph of its Jacobian-vector product
    /// rules from.
    pub fn match_footprints(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
        within: OrbitType,
    ) -> Result<Vec<Vec<Dart>>, ApplyError> {
        fn walk(e: &TExpr, embs: &[EmbDecl], out: &mut Vec<(usize, OrbitType)>) {
            match e {
                TExpr::Const(_) | TExpr::Param(_) | TExpr::Local(_) => {}
                TExpr::Read { node, emb } => out.push((*node, embs[*emb].orbit)),
                TExpr::Agg { orbit, node, .. } => out.push((*node, *orbit)),
                TExpr::Bin(_, a, c) => {
                    walk(a, embs, out);
                    walk(c, embs, out);
                }
                TExpr::Un(_, a) | TExpr::ToReal(a) => walk(a, embs, out),
                TExpr::Call(_, args) => args.iter().for_each(|a| walk(a, embs, out)),
                TExpr::If(c, a, d) => {
                    walk(c, embs, out);
                    walk(a, embs, out);
                    walk(d, embs, out);
                }
                TExpr::Block(lets, r) => {
                    for (_, v) in lets {
                        walk(v, embs, out);
                    }
                    walk(r, embs, out);
                }
            }
        }
        let b = self.bind(g, name, params)?;
        let ms = find_all(g, &b, &mut Poll::new(&never))?;
        let mut reach: Vec<(usize, OrbitType)> = Vec::new();
        for st in &b.rule.program {
            match st {
                TStmt::Let(_, v) => walk(v, b.embs, &mut reach),
                TStmt::Write {
                    node, emb, value, ..
                } => {
                    reach.push((*node, b.embs[*emb].orbit));
                    walk(value, b.embs, &mut reach);
                }
            }
        }
        if let Some(guard) = &b.rule.guard {
            walk(guard, b.embs, &mut reach);
        }
        reach.retain(|(_, o)| !o.is_subset_of(within));
        reach.sort_unstable_by_key(|(n, o)| (*n, o.mask()));
        reach.dedup();
        Ok(ms
            .iter()
            .map(|m| {
                let mut out: Vec<Dart> = m.all_darts().collect();
                for &(node, o) in &reach {
                    if let Some(ds) = m.darts.get(node) {
                        for &d in ds {
                            out.extend(g.orbit(d, o));
                        }
                    }
                }
                out
            })
            .collect())
    }

    /// The number of matches [`RuleSet::apply_everywhere`] would apply.
    pub fn count_matches(
        &self,
        g: &mut GMap,
        name: &str,
        params: &Params,
    ) -> Result<usize, ApplyError> {
        Ok(self.find_matches(g, name, params)?.len())
    }
}

/// Whether every orbit of type `o` that meets a match's footprint lies in it: every node of
/// the left graph has an orbit type without `_` whose labels include `o`'s. Then node `n`'s
/// darts, closed under its labels (the orbit-type check of [`match_at`]: position `t` of
/// row `r` leads to another row of the node), hold the whole `o`-orbit of each one.
fn orbit_in_footprint(rule: &Rule, o: OrbitType) -> bool {
    rule.nodes
        .iter()
        .filter_map(|n| n.left.as_ref())
        .all(|labels| {
            labels.iter().all(Option::is_some) && o.dims().all(|i| labels.contains(&Some(i as u8)))
        })
}

/// The patching of a plan's matches after a topology change (see [`RuleSet::patch_plan`]):
/// `C*`, the darts of `changed` with, for each chain of orbit types in `chains`, the orbits
/// along it of the live darts of `changed` (none for a chain of one orbit type that
/// [`orbit_in_footprint`]: those orbits add no match to drop); every match of `ix` holding a dart of `C*` is
/// dropped. Returns the marks of `C*`, the candidate hook darts of the new matches (walked
/// back from every dart of `C*`, or, with `relinked`, from its marked darts only: see
/// [`rebuild_unlinked`]) and the matches dropped; `None` when the index has seen too much
/// churn (a rebuild compacts it).
fn drop_changed(
    g: &GMap,
    rule: &Rule,
    ix: &mut Index,
    changed: &[Dart],
    chains: &[Vec<OrbitType>],
    relinked: Option<&Marks>,
) -> Option<(Marks, Vec<Dart>, Vec<u32>)> {
    let cap = g.capacity();
    if ix.of_hook.len() < cap {
        ix.of_hook.resize(cap, u32::MAX);
    }
    // C*: the changed darts and their aggregated orbits
    let mut star = Marks::with_capacity(cap);
    let mut cstar: Vec<Dart> = Vec::with_capacity(changed.len());
    for &d in changed {
        if star.mark(d) {
            cstar.push(d);
        }
    }
    for chain in chains {
        if let [o] = chain[..] {
            if orbit_in_footprint(rule, o) {
                // every orbit of type `o` meeting a footprint lies in it: a footprint meets
                // the orbit of a changed dart only where it holds that dart, so C is enough
                continue;
            }
        }
        let mut from: Vec<Dart> = changed.iter().copied().filter(|&d| g.is_alive(d)).collect();
        for &o in chain {
            let mut seen = Marks::with_capacity(cap);
            let mut next = Vec::new();
            for &d in &from {
                if !seen.is_marked(d) {
                    g.visit_orbit(d, o, &mut seen, |x| next.push(x));
                }
            }
            from = next;
        }
        for x in from {
            if star.mark(x) {
                cstar.push(x);
            }
        }
    }
    let paths: Vec<Vec<u8>> = node_paths(rule).into_iter().flatten().collect();
    let back = |y: Dart, path: &[u8]| {
        path.iter()
            .rev()
            .fold(y, |x, &l| g.alpha(usize::from(l), x))
    };
    // drop the matches holding a dart of C*
    let mut candidates: Vec<Dart> = Vec::new();
    let mut dropped: Vec<u32> = Vec::new();
    for &y in &cstar {
        for p in &paths {
            let h = back(y, p);
            if let Some(k) = ix.live_at(h) {
                ix.alive[k as usize] = false;
                ix.live -= 1;
                dropped.push(k);
            }
            if g.is_alive(h) && relinked.is_none_or(|r| r.is_marked(y)) {
                candidates.push(h);
            }
        }
    }
    // too much churn: a rebuild compacts
    if ix.hook_darts.len() > 2 * cap.max(1024) {
        return None;
    }
    Some((star, candidates, dropped))
}

/// Node `n`'s dart at row 0 of the match whose hook orbit is `hd` (its darts in row order),
/// per node (`Dart(u32::MAX)` for a node not in the left graph), when no dart of its
/// footprint is in `relinked`: no dart of its hook orbit, nor of any node's arc path from
/// any row's hook dart (the walks [`rebuild_unlinked`] makes). Then it is the match
/// [`rebuild_unlinked`] would rebuild, with the same darts (`paths`: [`node_paths`]).
fn unlinked_row0(
    g: &GMap,
    rule: &Rule,
    paths: &[Option<Vec<u8>>],
    hd: &[u32],
    relinked: &Marks,
) -> Option<Vec<Dart>> {
    if hd.iter().any(|&d| relinked.is_marked(Dart(d))) {
        return None;
    }
    let mut out = vec![Dart(u32::MAX); rule.nodes.len()];
    for (r, &h) in hd.iter().enumerate() {
        for (n, nd) in rule.nodes.iter().enumerate() {
            if nd.left.is_none() {
                continue;
            }
            let mut x = Dart(h);
            for &l in paths[n].as_ref()? {
                x = g.alpha(usize::from(l), x);
                if relinked.is_marked(x) {
                    return None;
                }
            }
            if r == 0 {
                out[n] = x;
            }
        }
    }
    Some(out)
}

/// The matches among `dropped` (matches of `ix`, dropped by [`drop_changed`]) whose
/// footprint holds no dart of `relinked` (the darts whose links changed, or that were
/// created or removed, since `ix` was current), rebuilt from their hook darts without a
/// search: each is the match [`match_at`] gives on the map now from the same hook dart, the
/// same darts in the same rows. `None` where a match cannot be rebuilt so (a node no arc
/// path reaches; the caller rebuilds the plan).
///
/// Why: [`match_at`] reads only the links of the darts of the match it returns. Walking the
/// hook orbit from the match's first hook dart ([`rows_of`]) and each node's arc path
/// ([`node_paths`]) from the hook darts reads the links of footprint darts only, so as long
/// as every dart reached is not relinked it reaches the old footprint's darts, in the old
/// order, and they are not relinked either: the old match, whose every check (links,
/// freeness) reads links that did not change. The first relinked dart such a walk reaches
/// is one of the old footprint's (every link read before it is unchanged): that match is
/// left out, as it should (its footprint changed; [`rematch`] finds what is there now).
fn rebuild_unlinked(
    g: &GMap,
    rule: &Rule,
    ix: &Index,
    dropped: &[u32],
    relinked: &Marks,
) -> Option<Vec<Match>> {
    let hook = rule.hooks[0];
    let paths = node_paths(rule);
    let mut out = Vec::new();
    'matches: for &k in dropped {
        let hd = &ix.hook_darts
            [ix.hook_start[k as usize] as usize..ix.hook_start[k as usize + 1] as usize];
        if hd.iter().any(|&d| relinked.is_marked(Dart(d))) {
            continue;
        }
        let (first, next) = rows_of(g, Dart(hd[0]), &rule.hook_orbit);
        if first.len() != hd.len() || first.iter().zip(hd).any(|(a, &b)| a.0 != b) {
            // (not reached: the walk reads unchanged links only, see above)
            return None;
        }
        let mut darts = NodeDarts::new(rule.nodes.len(), first.len());
        for (n, nd) in rule.nodes.iter().enumerate() {
            if nd.left.is_none() {
                continue;
            }
            let p = paths[n].as_ref()?;
            let col = darts.col_mut(n);
            for (r, &h) in first.iter().enumerate() {
                let mut x = h;
                for &l in p {
                    x = g.alpha(usize::from(l), x);
                    if relinked.is_marked(x) {
                        continue 'matches;
                    }
                }
                col[r] = x;
            }
        }
        debug_assert!(darts[hook] == first[..]);
        out.push(Match {
            rows: first.len(),
            next,
            darts,
        });
    }
    Some(out)
}

/// `darts` marked, in marks the size of `g`.
fn marks_of(g: &GMap, darts: &[Dart]) -> Marks {
    let mut m = Marks::with_capacity(g.capacity());
    for &d in darts {
        m.mark(d);
    }
    m
}

/// The `vec3` embedding named `embedding` of `g`, for a region of rule `name`'s guard.
fn vec3_embedding(g: &GMap, name: &str, embedding: &str) -> Result<EmbeddingId, ApplyError> {
    g.embedding_id(embedding)
        .filter(|&id| g.embedding(id).ty() == EmbeddingType::Vec3)
        .ok_or_else(|| {
            ApplyError::Map(format!(
                "rule '{name}': the region's embedding {embedding:?} is not a vec3 embedding of the map"
            ))
        })
}

impl GuardPlan {
    /// The rows whose match may pass a guard that is false wherever the box bounding the
    /// values the row reads of embedding `emb` misses `region` (the caller's knowledge, see
    /// [`RuleSet::apply_everywhere_within`]), in increasing order; `None` where this plan
    /// cannot tell (the guard reads no value of `emb`, or `emb` is not a real column).
    ///
    /// Why no row that may pass is left out (coordinate by coordinate): let `x` be the
    /// values now and `X` those when the rows were indexed ([`Cull`]), `d` the largest change
    /// `|x_s - X_s|` of the coordinate over the slots then, and `E` the largest distance then
    /// between that coordinate of a row's first slot's value and of another value it read. A
    /// row indexed then reads the same slots now (a patch keeps a row's slots, drops the row,
    /// or reads them again in place and lists the row in [`Cull::moved`], placed again below
    /// as an appended row), so every value it reads is within `E + 2d` of its first slot's
    /// value now. If the box of those values meets the region at a point `q`, each
    /// coordinate of `q` lies between two of them, so the first slot's value is within
    /// `E + 2d` of `q`: inside the region grown by `E + 2d`. The rows whose first slot's
    /// value is there are taken (the growth has a margin for rounding), and so are the rows
    /// appended or moved since the index was built (by their slots now) and those reading no
    /// value of `emb`.
    fn candidates(
        &mut self,
        g: &GMap,
        ids: &[EmbeddingId],
        emb: EmbeddingId,
        region: &Region,
    ) -> Option<Vec<u32>> {
        let cols = self.plan.cols_reading(ids, emb);
        if cols.is_empty() {
            return None;
        }
        let x = g.embedding(emb).real_column()?;
        if x.len() % 3 != 0 {
            return None;
        }
        let rows = self.plan.rows();
        let stale = self.cull.as_ref().is_none_or(|c| {
            c.emb != emb || c.tail.len() * 4 > rows.max(1024) || c.values.len() > x.len()
        });
        if stale {
            self.cull = Some(self.index_rows(&cols, emb, x)?);
        }
        let mut c = self.cull.take()?;
        // the slots created since: their values now join the snapshot
        let old = c.values.len();
        c.values.extend_from_slice(&x[old..]);
        // per coordinate, the largest change of a value since it joined the snapshot, and
        // whether every value is finite (in one pass: a value that is not finite gives
        // every row, and the guard decides)
        let (mut moved, mut finite) = ([0.0_f64; 3], true);
        for (a, b) in c.values.chunks_exact(3).zip(x.chunks_exact(3)) {
            for k in 0..3 {
                finite &= b[k].is_finite();
                moved[k] = moved[k].max((a[k] - b[k]).abs());
            }
        }
        if !finite {
            // the snapshot holds finite values only (a slot joins with a finite value)
            c.values.truncate(old);
            self.cull = Some(c);
            return None;
        }
        let spans = c.extent.iter().fold(0.0_f64, |m, &e| m.max(e));
        if moved.iter().any(|&m| m > spans.max(f64::MIN_POSITIVE)) {
            // the values moved more than a row spans: index again, so that the grown region
            // stays about the size of the region
            self.cull = Some(self.index_rows(&cols, emb, x)?);
            return self.candidates(g, ids, emb, region);
        }
        // the rows appended since: their first slots, and their extents now, grown by what
        // the values moved since they joined the snapshot (see above)
        let mut buf = Vec::new();
        let sources = self.plan.slot_sources(&cols);
        let moved_rows = std::mem::take(&mut c.moved);
        for r in moved_rows
            .into_iter()
            .map(|r| r as usize)
            .chain(c.rows..rows)
        {
            buf.clear();
            self.plan.row_slots_from(&sources, r, |s| buf.push(s));
            if buf.is_empty() {
                c.always.push(r as u32);
                continue;
            }
            if buf.iter().any(|&s| 3 * s as usize + 3 > x.len()) {
                return None;
            }
            let (s0, ext) = row_anchor(&buf, x);
            for k in 0..3 {
                c.extent[k] = c.extent[k].max(ext[k] + 2.0 * moved[k]);
            }
            c.tail.push((s0, r as u32));
        }
        c.rows = rows;
        let grow: [f64; 3] = std::array::from_fn(|k| c.extent[k] + 2.0 * moved[k]);
        let scale = region
            .lo
            .iter()
            .chain(&region.hi)
            .chain(&grow)
            .fold(0.0_f64, |m, v| m.max(v.abs()));
        let lo: [f64; 3] = std::array::from_fn(|k| region.lo[k] - grow[k] - 1e-9 * (1.0 + scale));
        let hi: [f64; 3] = std::array::from_fn(|k| region.hi[k] + grow[k] + 1e-9 * (1.0 + scale));
        let inside = |s: u32| {
            let p = &x[3 * s as usize..3 * s as usize + 3];
            (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k])
        };
        let mut out: Vec<u32> = c.always.clone();
        for s in 0..c.start.len() - 1 {
            if inside(s as u32) {
                out.extend_from_slice(&c.by_slot[c.start[s] as usize..c.start[s + 1] as usize]);
            }
        }
        out.extend(c.tail.iter().filter(|t| inside(t.0)).map(|t| t.1));
        out.sort_unstable();
        out.dedup();
        // of those, the rows whose own box (of the values they read now) meets the region
        // grown by the rounding margin: the caller's promise makes the guard false at the
        // others. The growth above, by the largest extent of any row around its first slot,
        // finds twice a row's size around a thin region such as a blade's quad (the plane
        // of the blade, one step of its sweep): the box halves the rows the guard runs on
        let margin = 1e-9 * (1.0 + scale);
        out.retain(|&r| {
            let (mut blo, mut bhi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            let (mut read, mut outside) = (false, false);
            self.plan.row_slots_from(&sources, r as usize, |s| {
                let Some(p) = x.get(3 * s as usize..3 * s as usize + 3) else {
                    outside = true;
                    return;
                };
                read = true;
                for k in 0..3 {
                    blo[k] = blo[k].min(p[k]);
                    bhi[k] = bhi[k].max(p[k]);
                }
            });
            // a row reading no value of the region's embedding, or a slot past its values:
            // the guard decides
            !read
                || outside
                || (0..3)
                    .all(|k| blo[k] <= region.hi[k] + margin && bhi[k] >= region.lo[k] - margin)
        });
        self.cull = Some(c);
        Some(out)
    }

    /// The rows of the plan by the first slot each reads of embedding `emb` (program
    /// columns `cols`), with `x` the embedding's values now (see [`GuardPlan::candidates`]).
    fn index_rows(&self, cols: &[usize], emb: EmbeddingId, x: &[f64]) -> Option<Cull> {
        if x.len() % 3 != 0 || x.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let slots = x.len() / 3;
        let rows = self.plan.rows();
        let mut first = vec![u32::MAX; rows];
        let mut extent = [0.0_f64; 3];
        let mut always = Vec::new();
        let mut buf = Vec::new();
        let sources = self.plan.slot_sources(cols);
        for (r, f) in first.iter_mut().enumerate() {
            buf.clear();
            self.plan.row_slots_from(&sources, r, |s| buf.push(s));
            if buf.is_empty() {
                always.push(r as u32);
                continue;
            }
            if buf.iter().any(|&s| s as usize >= slots) {
                return None;
            }
            let (s0, ext) = row_anchor(&buf, x);
            for k in 0..3 {
                extent[k] = extent[k].max(ext[k]);
            }
            *f = s0;
        }
        if extent.iter().any(|e| !e.is_finite()) {
            return None;
        }
        // rows by first slot (a counting sort)
        let mut start = vec![0u32; slots + 1];
        for &f in &first {
            if f != u32::MAX {
                start[f as usize + 1] += 1;
            }
        }
        for s in 0..slots {
            start[s + 1] += start[s];
        }
        let mut at = start.clone();
        let mut by_slot = vec![0u32; start[slots] as usize];
        for (r, &f) in first.iter().enumerate() {
            if f != u32::MAX {
                by_slot[at[f as usize] as usize] = r as u32;
                at[f as usize] += 1;
            }
        }
        Some(Cull {
            emb,
            rows,
            values: x.to_vec(),
            extent,
            start,
            by_slot,
            tail: Vec::new(),
            always,
            moved: Vec::new(),
        })
    }
}

/// The guard plan of `b`'s rule (see [`RuleSet::guarded_matches`]): one row per hook orbit
/// where the left graph matches, found from its smallest dart; `None` when the guard does
/// not compile. Starts the map's change record, for the patches.
fn build_guard_plan(
    g: &mut GMap,
    b: &Bound,
    reads: Vec<EmbeddingId>,
    backend: Option<Arc<dyn NativeBackend>>,
    poll: &mut Poll,
) -> Result<Option<GuardPlan>, ApplyError> {
    let rule = b.rule;
    let Ok(prog) = crate::compiled::compile_guard(rule, b.embs) else {
        return Ok(None);
    };
    let hook = rule.hooks[0];
    let mut builder = crate::compiled::Plan::builder(prog, rule, g, &b.ids);
    let mut index = Index::new(b.ids.clone(), g.capacity());
    let mut first = Vec::new();
    let mut seen = Marks::with_capacity(g.capacity());
    // the matches are held a batch at a time
    let mut batch = Vec::with_capacity(GUARD_BATCH);
    for d in g.darts() {
        if poll.tick(1) {
            return Err(ApplyError::Interrupted {
                rule: rule.name.clone(),
                stage: "compiling its guard",
                found: 0,
                applied: 0,
            });
        }
        if seen.is_marked(d) {
            continue;
        }
        let Some(m) = try_match(g, rule, &[d]) else {
            continue;
        };
        for &x in &m.darts[hook] {
            seen.mark(x);
        }
        index.push(&m, hook);
        first.push(d.0);
        batch.push(m);
        if batch.len() == GUARD_BATCH {
            builder.add(rule, g, &b.ids, &batch);
            batch.clear();
        }
    }
    builder.add(rule, g, &b.ids, &batch);
    let mut plan = builder.finish(g, &b.ids, backend);
    // the patches after cuts append rows: room for an eighth more, so that the first ones
    // do not copy every array (about 15 bytes more per face side)
    plan.reserve_rows(plan.rows() / 8);
    g.track_changes();
    Ok(Some(GuardPlan {
        identity: g.identity(),
        reads,
        plan,
        index,
        first,
        cull: None,
    }))
}

/// Matches held at once while a guard plan is built.
const GUARD_BATCH: usize = 4096;

/// `gp` patched for the map's new topology, as [`RuleSet::patch_plan`] patches a compiled
/// plan (the same proof, with one row per hook orbit instead of one per footprint, and no
/// guard evaluated: the plan evaluates it when it runs, so dropped rows whose footprint kept
/// its links are rebuilt as without a guard: in place, the same match reading its slots
/// again, where its slot lists keep their lengths); `None` when it cannot be (another
/// map, a change record that does not cover its version, too much churn).
fn patch_guard_plan(
    g: &GMap,
    b: &Bound,
    gp: GuardPlan,
    changes: &(Vec<Dart>, Vec<Dart>),
) -> Option<GuardPlan> {
    if gp.identity.0 != g.identity().0 {
        return None;
    }
    let (changed, relinked) = changes;
    let relinked = marks_of(g, relinked);
    let rule = b.rule;
    let GuardPlan {
        mut plan,
        mut index,
        mut first,
        reads,
        cull,
        ..
    } = gp;
    let chains: Vec<Vec<OrbitType>> = plan.agg_orbits().into_iter().map(|o| vec![o]).collect();
    let (_, candidates, dropped) =
        drop_changed(g, rule, &mut index, changed, &chains, Some(&relinked))?;
    let hook = rule.hooks[0];
    // the dropped rows whose footprint kept its links are the same matches (see
    // `rebuild_unlinked`): their rows read their slots again in place, under their own
    // numbers (a vertex split re-slots the faces around it: a plane cut's next cut rebuilt
    // some 20,000 rows); the rows the cull index must place again
    let paths = node_paths(rule);
    let mut in_place: Vec<u32> = Vec::new();
    let mut dropped_still: Vec<u32> = Vec::with_capacity(dropped.len());
    let mut rows: Vec<(usize, Vec<Dart>)> = Vec::new();
    for &k in &dropped {
        let hd = &index.hook_darts
            [index.hook_start[k as usize] as usize..index.hook_start[k as usize + 1] as usize];
        match unlinked_row0(g, rule, &paths, hd, &relinked) {
            Some(darts) => rows.push((k as usize, darts)),
            None => dropped_still.push(k),
        }
    }
    for ((k, _), done) in rows.iter().zip(plan.reslot_guard_rows(g, &b.ids, &rows)) {
        if done {
            index.alive[*k] = true;
            index.live += 1;
            in_place.push(*k as u32);
        } else {
            dropped_still.push(*k as u32);
        }
    }
    let dropped = dropped_still;
    let mut cull = cull;
    if let Some(c) = &mut cull {
        c.moved.extend_from_slice(&in_place);
    }
    // the others rebuilt, then one row per new hook orbit: no guard evaluated (the plan
    // does), no footprint merged
    let mut new = rebuild_unlinked(g, rule, &index, &dropped, &relinked)?;
    let mut push = |m: &Match, index: &mut Index| {
        first.push(m.darts[hook].iter().map(|d| d.0).min().expect("a row"));
        index.push(m, hook)
    };
    let mut numbers: Vec<u32> = new.iter().map(|m| push(m, &mut index)).collect();
    let found = rematch(
        g,
        rule,
        &index,
        &relinked,
        candidates,
        &[],
        |_| Some(true),
        |_| true,
    )?;
    numbers.extend(found.iter().map(|m| push(m, &mut index)));
    new.extend(found);
    // rows stay numbered by match (row k is match k's row 0): the dropped matches' rows
    // stay in the plan, their values ignored (`RuleSet::guarded_matches` keeps the live
    // matches only), and the new ones are appended; a rebuild compacts (`drop_changed`)
    plan.append_guard_rows(rule, g, &b.ids, &new, &numbers)?;
    Some(GuardPlan {
        identity: g.identity(),
        reads,
        plan,
        index,
        first,
        // its rows keep their slots (the patch's proof); the appended ones are candidates
        cull,
    })
}

/// The new matches of a patch (see [`RuleSet::patch_plan`]): from each candidate hook dart
/// not tried yet, not in the hook orbit of a match found here or of a live match of `ix`,
/// the match there when it holds a dart of `C*` (`star`; else it is a kept match's) and
/// `pass` accepts it (`None`: give up, the plan is rebuilt); its hook orbit is then taken,
/// and the match kept when `fresh` says it is not one found already. `mirrors`: nodes whose
/// darts in an accepted match are taken too, for a `fresh` refusing a footprint found before
/// ([`Rule::hook_images`]: a match from them has the same footprint); empty where every
/// hook orbit is wanted.
#[allow(clippy::too_many_arguments)]
fn rematch(
    g: &GMap,
    rule: &Rule,
    ix: &Index,
    star: &Marks,
    candidates: Vec<Dart>,
    mirrors: &[usize],
    mut pass: impl FnMut(&Match) -> Option<bool>,
    mut fresh: impl FnMut(&Match) -> bool,
) -> Option<Vec<Match>> {
    let cap = g.capacity();
    let hook = rule.hooks[0];
    let mut used = Marks::with_capacity(cap);
    // a candidate tried once gives the same answer again (its match, the guard at it)
    let mut tried = Marks::with_capacity(cap);
    let mut new = Vec::new();
    for h in candidates {
        if !tried.mark(h) || used.is_marked(h) || ix.live_at(h).is_some() {
            continue;
        }
        let Some(m) = try_match(g, rule, &[h]) else {
            // no dart of the hook orbit matches (see `find_all`): tried once for all of them
            // (a face side opened by a cut, now free, was tried from each of its darts)
            for x in rows_of(g, h, &rule.hook_orbit).0 {
                tried.mark(x);
            }
            continue;
        };
        if !m.all_darts().any(|x| star.is_marked(x)) {
            continue; // a kept match's footprint (or one its guard rejects still)
        }
        if !pass(&m)? {
            continue;
        }
        for &x in &m.darts[hook] {
            used.mark(x);
        }
        // the hook orbits of the same footprint's other matches: `fresh` would refuse them
        for &n in mirrors {
            for &x in &m.darts[n] {
                used.mark(x);
            }
        }
        if fresh(&m) {
            new.push(m);
        }
    }
    Some(new)
}

/// Whether plans of `rule` may be patched after a topology change (see
/// [`RuleSet::patch_plan`]): a computation rule with one hook, and either no guard or one
/// whose value does not depend on which dart of the hook orbit is row 0 (a hook orbit of one
/// dart, or a guard [`row_invariant`] over the rows): then, as in [`find_all`], a footprint
/// is planned exactly when some dart's match with that footprint passes the guard.
fn patchable(rule: &Rule, embs: &[EmbDecl]) -> bool {
    !rule.changes_topology
        && rule.hooks.len() == 1
        && rule.guard.as_ref().is_none_or(|e| {
            rule.hook_orbit.is_empty() || row_invariant(e, &left_labels(rule), embs)
        })
}

/// Adds to `out` the chains of orbit types through which `e` reads the map from a node's
/// dart `x`: a read of embedding `e` depends on the darts of the `e`-orbit of `x` (its slot
/// and value), an aggregate over orbit `o` of embedding `k` on the `o`-orbit of `x` and on
/// the `k`-orbits of its darts. A dart `x` lies in such an orbit holding a dart `c` exactly
/// when `x` is in the orbit of `c` along the chain walked back (orbits are symmetric): the
/// `o`-orbit of `c` for `[o]`; the `o`-orbits of the `k`-orbit of `c` for `[k, o]`.
fn expr_orbits(e: &TExpr, embs: &[EmbDecl], out: &mut Vec<Vec<OrbitType>>) {
    let mut add = |c: Vec<OrbitType>| {
        if !out.contains(&c) {
            out.push(c);
        }
    };
    match e {
        TExpr::Const(_) | TExpr::Param(_) | TExpr::Local(_) => {}
        TExpr::Read { emb, .. } => add(vec![embs[*emb].orbit]),
        TExpr::Agg { orbit, emb, .. } => {
            add(vec![*orbit]);
            if let Some(k) = emb {
                add(vec![embs[*k].orbit, *orbit]);
            }
        }
        TExpr::Bin(_, a, c) => {
            expr_orbits(a, embs, out);
            expr_orbits(c, embs, out);
        }
        TExpr::Un(_, a) | TExpr::ToReal(a) => expr_orbits(a, embs, out),
        TExpr::Call(_, args) => args.iter().for_each(|a| expr_orbits(a, embs, out)),
        TExpr::If(c, a, d) => {
            expr_orbits(c, embs, out);
            expr_orbits(a, embs, out);
            expr_orbits(d, embs, out);
        }
        TExpr::Block(lets, r) => {
            for (_, v) in lets {
                expr_orbits(v, embs, out);
            }
            expr_orbits(r, embs, out);
        }
    }
}

fn rule_embeddings(rule: &Rule) -> Vec<usize> {
    let mut ids = Vec::new();
    for s in &rule.program {
        match s {
            TStmt::Let(_, e) => ids.extend(crate::check::reads_of(e)),
            TStmt::Write { emb, value, .. } => {
                ids.push(*emb);
                ids.extend(crate::check::reads_of(value));
            }
        }
    }
    if let Some(gd) = &rule.guard {
        ids.extend(crate::check::reads_of(gd));
    }
    ids.sort_unstable();
    ids.dedup();
    ids
}

fn emb_type(t: Ty) -> EmbeddingType {
    match t {
        Ty::F64 => EmbeddingType::F64,
        Ty::I64 => EmbeddingType::I64,
        Ty::Bool => EmbeddingType::Bool,
        Ty::Vec2 => EmbeddingType::Vec2,
        Ty::Vec3 => EmbeddingType::Vec3,
        Ty::Mat(r, c) => EmbeddingType::Mat { rows: r, cols: c },
    }
}

fn eval_err(rule: &str, dart: Dart, e: &crate::value::EvalError) -> ApplyError {
    ApplyError::Eval {
        rule: rule.into(),
        dart,
        message: e.0.clone(),
    }
}

fn find_all(g: &GMap, b: &Bound, poll: &mut Poll) -> Result<Vec<Match>, ApplyError> {
    let rule = b.rule;
    if rule.hooks.len() != 1 {
        return Err(ApplyError::Hooks {
            rule: rule.name.clone(),
            message: format!(
                "it has {} hooks: apply it at explicit darts, one per hook",
                rule.hooks.len()
            ),
        });
    }
    // A rule that changes the topology: matches never overlap (the whole footprint is
    // marked). A computation rule: matches may share darts (a force pattern reads its
    // neighbours, as the paper's angular springs do), but each match is applied once — the
    // darts of its hook are marked, and a match found again from another hook (the same
    // footprint) is skipped.
    let overlap = !rule.changes_topology;
    let one_node = one_node(rule);
    // Leading conjuncts of the guard that read the hook dart only are tried first, on the hook
    // dart alone (row 0 of a match is its hook dart): most darts fail them, and need no match.
    let hook = rule.hooks[0];
    // The prefix conjuncts that test a boolean embedding of the hook (`n0.vertex0`,
    // `!v.fixed`): read from their column for each dart instead of through the interpreter
    // (a dart fails the prefix when one conjunct is false, in any order: an error is left to
    // the full evaluation, and a flag's read has none).
    let mut flags: Vec<(EmbeddingId, bool)> = Vec::new();
    let mut prefix = rule
        .guard
        .as_ref()
        .map_or_else(Vec::new, |e| hook_prefix(e, hook));
    prefix.retain(|e| match flag_conjunct(g, b, e, hook) {
        Some(f) => {
            flags.push(f);
            false
        }
        None => true,
    });
    // A guard reading every node through embeddings on orbits that contain the node's orbit
    // has one value on every row of a match: a dart of the hook orbit that fails it, fails it
    // for all, so the hook orbit is tried once (a plane cut's guard, which walks both
    // volumes, runs once per side of a face instead of once per dart).
    let invariant = rule
        .guard
        .as_ref()
        .is_some_and(|e| row_invariant(e, &left_labels(rule), b.embs));
    // the hook darts whose orbit failed an invariant guard (a rule that changes the topology
    // keeps them apart from the footprints: another match may still hold them)
    let mut failed = Marks::with_capacity(if overlap { 0 } else { g.capacity() });
    let mut probe = Match {
        rows: 1,
        next: vec![0; rule.arity],
        darts: NodeDarts::new(rule.nodes.len(), 1),
    };
    let mut used = Marks::with_capacity(g.capacity());
    // footprints kept (sorted, flat), listed by their smallest dart: a footprint found again
    // has the same smallest dart, so only that list is compared
    let mut head: Vec<u32> = if overlap {
        vec![u32::MAX; g.capacity()]
    } else {
        Vec::new()
    };
    let mut chain: Vec<u32> = Vec::new();
    let mut prints: Vec<u32> = Vec::new();
    let mut starts: Vec<usize> = vec![0];
    let mut key: Vec<u32> = Vec::new();
    let mut out = Vec::new();
    for d in g.darts() {
        if poll.tick(1) {
            return Err(ApplyError::Interrupted {
                rule: rule.name.clone(),
                stage: "finding matches",
                found: out.len(),
                applied: 0,
            });
        }
        if used.is_marked(d) || (!overlap && failed.is_marked(d)) {
            continue;
        }
        // flags first (`n0.vertex0`, `!v.fixed`): read from their column, no evaluation
        if flags
            .iter()
            .any(|&(id, want)| flag_at(g, id, d) != Some(want))
        {
            continue;
        }
        if !prefix.is_empty() {
            probe.darts.col_mut(hook)[0] = d;
            let mut ev = Eval::new(g, b, &probe);
            // an error is left to the full evaluation below, which reports it in order
            if prefix
                .iter()
                .any(|e| matches!(ev.eval(e, 0), Ok(Val::B(false))))
            {
                continue;
            }
        }
        let Some(m) = try_match(g, rule, &[d]) else {
            // With one hook, whether the left graph matches does not depend on which dart of
            // the hook orbit is the hook: from each, the hook orbit is the same set of darts
            // (its rows in another order), every node reached through the arcs is too, and
            // every test (free darts, links between rows, orbit labels, darts matched twice)
            // is over all rows. So the orbit's other darts fail too: skipped (a rule that
            // changes the topology keeps them apart from the footprints, as for a guard).
            let skip = if overlap { &mut used } else { &mut failed };
            for x in rows_of(g, d, &rule.hook_orbit).0 {
                skip.mark(x);
            }
            continue;
        };
        if !overlap && m.all_darts().any(|x| used.is_marked(x)) {
            continue;
        }
        if let Some(guard) = &rule.guard {
            let mut ev = Eval::new(g, b, &m);
            let ok = ev.eval(guard, 0).map_err(|e| eval_err(&rule.name, d, &e))?;
            if ok != Val::B(true) {
                if invariant {
                    // the other darts of the hook orbit give this footprint and this guard
                    let marks = if overlap { &mut used } else { &mut failed };
                    for &x in &m.darts[hook] {
                        marks.mark(x);
                    }
                }
                continue;
            }
        }
        if overlap && one_node {
            // the footprint is the hook orbit, marked as a whole below for every match kept:
            // no later dart can give it again, so there is nothing to compare
            for &x in &m.darts[hook] {
                used.mark(x);
            }
        } else if overlap {
            key.clear();
            key.extend(m.all_darts().map(|x| x.0));
            key.sort_unstable();
            let min = key[0] as usize;
            let mut k = head[min];
            let mut dup = false;
            while k != u32::MAX {
                let k_ = k as usize;
                if prints[starts[k_]..starts[k_ + 1]] == key[..] {
                    dup = true;
                    break;
                }
                k = chain[k_];
            }
            if dup {
                // every dart of its hook orbit gives this footprint again (the hook orbit is
                // the same set of darts from each, and so is every node reached from it):
                // tried once, not once per dart (a spring's second end, or a pattern's
                // mirror image, was matched again from each of its ~10 darts)
                for &x in &m.darts[hook] {
                    used.mark(x);
                }
                continue;
            }
            chain.push(head[min]);
            head[min] = (starts.len() - 1) as u32;
            prints.extend_from_slice(&key);
            starts.push(prints.len());
            for &x in &m.darts[rule.hooks[0]] {
                used.mark(x);
            }
            // The darts of a node the automorphisms of the left graph move the hook to
            // (`Rule::hook_images`) are a hook orbit whose every dart gives this footprint
            // again (the match composed with the automorphism): its tries would end as
            // duplicates, or fail the guard, so they are skipped (a spring's other end, a
            // half-edge's partner: half the tries of a symmetric pattern).
            for &n in &rule.hook_images {
                if n != hook {
                    for &x in &m.darts[n] {
                        used.mark(x);
                    }
                }
            }
        } else {
            for x in m.all_darts() {
                used.mark(x);
            }
        }
        out.push(m);
    }
    Ok(out)
}

/// `Some((id, want))` when `e` is `n.flag` (`want` true) or `!n.flag` (false) for the hook
/// node `n` and a boolean, non-derived embedding `flag` of the map: a test [`flag_at`] makes
/// from the column, as the interpreter would read it.
fn flag_conjunct(g: &GMap, b: &Bound, e: &TExpr, hook: usize) -> Option<(EmbeddingId, bool)> {
    let (read, want) = match e {
        TExpr::Un(UnOp::Not, a) => (&**a, false),
        e => (e, true),
    };
    let TExpr::Read { node, emb } = read else {
        return None;
    };
    let id = *b.ids.get(*emb)?;
    let e = g.embedding(id);
    (*node == hook && e.derived().is_none() && matches!(e.column(), ColumnRef::Bool(_)))
        .then_some((id, want))
}

/// The value of the boolean embedding `id` at the live dart `d` (`None` for another column).
fn flag_at(g: &GMap, id: EmbeddingId, d: Dart) -> Option<bool> {
    let e = g.embedding(id);
    match e.column() {
        ColumnRef::Bool(v) => v.get(e.slot(d)).copied(),
        _ => None,
    }
}

/// The slot a row of a guard plan is indexed by (see [`GuardPlan::candidates`]): of the
/// slots `buf` the row reads (points `x[3 s..3 s + 3]`, every slot inside `x`), the one
/// nearest to their mean, and per coordinate the largest distance from it to the others.
/// A central point keeps the extent every row's box is grown by small: the first slot read
/// could be a far corner (an aggregate's slots come in increasing order, so a volume's
/// centroid may list its apex first), and a larger extent sends more rows to the guard.
fn row_anchor(buf: &[u32], x: &[f64]) -> (u32, [f64; 3]) {
    let point = |s: u32| &x[3 * s as usize..3 * s as usize + 3];
    let mut mean = [0.0_f64; 3];
    for &s in buf {
        for (m, v) in mean.iter_mut().zip(point(s)) {
            *m += v / buf.len() as f64;
        }
    }
    let d2 = |s: u32| (0..3).map(|k| (point(s)[k] - mean[k]).powi(2)).sum::<f64>();
    let s0 = buf
        .iter()
        .copied()
        .min_by(|&a, &b| d2(a).total_cmp(&d2(b)))
        .expect("a slot");
    let mut ext = [0.0_f64; 3];
    for &s in buf {
        for ((e, v), v0) in ext.iter_mut().zip(point(s)).zip(point(s0)) {
            *e = e.max((v - v0).abs());
        }
    }
    (s0, ext)
}

/// The leading conjuncts of the guard `e` that read the hook node `hook` only, up to the
/// first that reads more: what [`find_all`] tries on the hook dart alone.
fn hook_prefix(e: &TExpr, hook: usize) -> Vec<&TExpr> {
    let mut prefix = Vec::new();
    leading_conjuncts(e, &mut prefix);
    if let Some(k) = prefix.iter().position(|e| !reads_only(e, hook)) {
        prefix.truncate(k);
    }
    prefix
}

/// The operands of the leading `&&` chain of `e`, in evaluation order.
fn leading_conjuncts<'a>(e: &'a TExpr, out: &mut Vec<&'a TExpr>) {
    if let TExpr::Bin(BinOp::And, a, b) = e {
        leading_conjuncts(a, out);
        leading_conjuncts(b, out);
    } else {
        out.push(e);
    }
}

/// Whether `e` has one value on every row of a match: it reads each node `n` only through
/// embeddings (or aggregates) whose orbit contains every label of `n`'s orbit type in the left
/// graph (`labels[n]`; `None` for a node whose labels are not all known, which nothing may
/// read). The darts of node `n` over the rows of a match are one orbit of its orbit type, so
/// such a read gives the same value from each of them; constants, parameters and the locals
/// of the guard's own blocks (checked where they are bound) do too.
///
/// This is what lets a guard that fails at one hook dart fail for the whole hook orbit: the
/// match found from another dart of the hook orbit is the same footprint with its rows in
/// another order, and the guard is evaluated at its row 0.
fn row_invariant(e: &TExpr, labels: &[Option<Vec<u8>>], embs: &[EmbDecl]) -> bool {
    let covers = |node: usize, o: OrbitType| {
        labels
            .get(node)
            .and_then(Option::as_ref)
            .is_some_and(|ls| ls.iter().all(|&l| o.contains(usize::from(l))))
    };
    let rec = |x: &TExpr| row_invariant(x, labels, embs);
    match e {
        TExpr::Const(_) | TExpr::Param(_) | TExpr::Local(_) => true,
        TExpr::Read { node, emb } => covers(*node, embs[*emb].orbit),
        TExpr::Agg { node, orbit, .. } => covers(*node, *orbit),
        TExpr::Bin(_, a, c) => rec(a) && rec(c),
        TExpr::Un(_, a) | TExpr::ToReal(a) => rec(a),
        TExpr::Call(_, args) => args.iter().all(rec),
        TExpr::If(c, a, d) => rec(c) && rec(a) && rec(d),
        TExpr::Block(lets, res) => lets.iter().all(|(_, x)| rec(x)) && rec(res),
    }
}

/// The labels of each node's orbit type in the left graph of `rule` (`None` for a node the
/// rule creates, or one with a position that is not a label).
fn left_labels(rule: &Rule) -> Vec<Option<Vec<u8>>> {
    rule.nodes
        .iter()
        .map(|n| {
            n.left
                .as_ref()
                .and_then(|ls| ls.iter().copied().collect::<Option<Vec<u8>>>())
        })
        .collect()
}

/// Whether `e` reads the map only through node `hook` (and no local variable).
fn reads_only(e: &TExpr, hook: usize) -> bool {
    match e {
        TExpr::Const(_) | TExpr::Param(_) => true,
        TExpr::Local(_) | TExpr::Block(..) => false,
        TExpr::Read { node, .. } | TExpr::Agg { node, .. } => *node == hook,
        TExpr::Bin(_, a, b) => reads_only(a, hook) && reads_only(b, hook),
        TExpr::Un(_, a) | TExpr::ToReal(a) => reads_only(a, hook),
        TExpr::Call(_, args) => args.iter().all(|a| reads_only(a, hook)),
        TExpr::If(c, a, b) => reads_only(c, hook) && reads_only(a, hook) && reads_only(b, hook),
    }
}

/// A fast hasher for footprints (sorted dart lists): multiply-rotate over the words, as in
/// rustc's `FxHash`. Not resistant to adversarial keys, which dart numbers are not.
#[derive(Clone, Copy, Default)]
struct FastHash;

impl std::hash::BuildHasher for FastHash {
    type Hasher = FastHasher;
    fn build_hasher(&self) -> FastHasher {
        FastHasher(0)
    }
}

struct FastHasher(u64);

impl std::hash::Hasher for FastHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            self.write_u64(u64::from_le_bytes(c.try_into().expect("8 bytes")));
        }
        for &b in chunks.remainder() {
            self.write_u64(u64::from(b));
        }
    }
    fn write_u32(&mut self, x: u32) {
        self.write_u64(u64::from(x));
    }
    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// One evaluated write: the node, the embedding, and per row the value (by row class).
struct Pending {
    node: usize,
    emb: usize,
    /// For each row, its value.
    values: Vec<Val>,
}

fn apply_matches(
    g: &mut GMap,
    b: &Bound,
    ms: &[Match],
    poll: &mut Poll,
) -> Result<ApplyReport, ApplyError> {
    let rule = b.rule;
    // 1. evaluate every write on the map as it is
    let mut evaluations = 0;
    let mut pending: Vec<Vec<Pending>> = Vec::with_capacity(ms.len());
    for m in ms {
        // nothing is changed before every value is evaluated: a stop here leaves the map as is
        if poll.tick(m.rows) {
            return Err(ApplyError::Interrupted {
                rule: rule.name.clone(),
                stage: "evaluating",
                found: ms.len(),
                applied: 0,
            });
        }
        let mut ev = Eval::new(g, b, m);
        let mut ps = Vec::new();
        for s in &rule.program {
            let TStmt::Write {
                node,
                emb,
                value,
                uniform,
            } = s
            else {
                continue;
            };
            let classes = row_classes(m, rule.arity, uniform);
            let mut by_class: HashMap<u32, Val> = HashMap::new();
            let mut values = Vec::with_capacity(m.rows);
            for (r, &cls) in classes.iter().enumerate() {
                let v = if let Some(v) = by_class.get(&cls) {
                    v.clone()
                } else {
                    evaluations += 1;
                    let v = ev
                        .run_to(value, s, r)
                        .map_err(|e| eval_err(&rule.name, m.darts[rule.hooks[0]][r], &e))?;
                    if !finite(&v) {
                        let dart = m
                            .darts
                            .get(*node)
                            .and_then(|d| d.get(r))
                            .copied()
                            .unwrap_or(m.darts[rule.hooks[0]][r]);
                        return Err(ApplyError::NonFinite {
                            rule: rule.name.clone(),
                            embedding: b.embs[*emb].name.clone(),
                            dart,
                            value: describe_non_finite(&v),
                        });
                    }
                    by_class.insert(cls, v.clone());
                    v
                };
                values.push(v);
            }
            ps.push(Pending {
                node: *node,
                emb: *emb,
                values,
            });
        }
        pending.push(ps);
    }
    // 2. the new topology, planned but not applied yet
    let mut report = ApplyReport {
        matches: ms.len(),
        evaluations,
        ..ApplyReport::default()
    };
    let mut node_darts: Vec<Vec<Vec<Dart>>> = Vec::with_capacity(ms.len());
    let mut changes = Vec::new();
    let mut fresh = Vec::new();
    let mut remove = Vec::new();
    let interrupted = |stage| ApplyError::Interrupted {
        rule: rule.name.clone(),
        stage,
        found: ms.len(),
        applied: 0,
    };
    if rule.changes_topology {
        for m in ms {
            // the darts created so far are free (every alpha a fixed point): removing them
            // leaves the map as it was
            if poll.tick(m.rows) {
                undo_fresh(g, &fresh);
                return Err(interrupted("planning the new topology"));
            }
            let mut nd_darts = m.darts.to_vecs();
            for (k, nd) in rule.nodes.iter().enumerate() {
                if nd.left.is_none() {
                    let first = g.add_darts(m.rows);
                    nd_darts[k] = (0..m.rows as u32).map(|r| Dart(first.0 + r)).collect();
                    fresh.extend(nd_darts[k].iter().copied());
                    report.created += m.rows;
                }
            }
            for (k, nd) in rule.nodes.iter().enumerate() {
                if nd.right.is_none() {
                    for &x in &nd_darts[k] {
                        for i in 0..=g.dimension() {
                            changes.push((i, x, x));
                        }
                        remove.push(x);
                    }
                    report.deleted += m.rows;
                    continue;
                }
                for i in 0..=g.dimension() {
                    let kept_mentioned = nd.is_kept() && nd.left_src[i] != Source::None;
                    for r in 0..m.rows {
                        let x = nd_darts[k][r];
                        let y = match nd.right_src[i] {
                            Source::Orbit(t) => nd_darts[k][m.next[r * rule.arity + t] as usize],
                            Source::Arc(o) => nd_darts[o][r],
                            Source::Loop => x,
                            Source::None if kept_mentioned => x,
                            Source::None => continue,
                        };
                        changes.push((i, x, y));
                    }
                }
            }
            node_darts.push(nd_darts);
        }
    } else {
        node_darts = ms.iter().map(|m| m.darts.to_vecs()).collect();
    }
    // 3. one value per orbit of the result: checked on the planned topology, before any change
    // (needed only to place values written or filled in: a cut that only unsews has none)
    let needs_overlay = rule.changes_topology
        && (!fresh.is_empty() || pending.iter().flatten().any(|p| !p.values.is_empty()));
    let mut overlay: HashMap<(usize, Dart), Dart> =
        HashMap::with_capacity(if needs_overlay { changes.len() } else { 0 });
    for chunk in changes.chunks(INTERRUPT_EVERY).filter(|_| needs_overlay) {
        if poll.tick(chunk.len()) {
            undo_fresh(g, &fresh);
            return Err(interrupted("planning the new topology"));
        }
        overlay.extend(chunk.iter().map(|&(i, a, b)| ((i, a), b)));
    }
    let mut groups: HashMap<usize, HashMap<Dart, u32>> = HashMap::new();
    let mut written: HashMap<(usize, u32), (Val, Dart)> = HashMap::new();
    let mut conflict = None;
    'outer: for (ps, nd_darts) in pending.iter().zip(&node_darts) {
        if poll.tick(ps.iter().map(|p| p.values.len()).sum()) {
            undo_fresh(g, &fresh);
            return Err(interrupted("checking the values written"));
        }
        for p in ps {
            let orbit = b.embs[p.emb].orbit;
            let group = groups.entry(p.emb).or_default();
            for (r, v) in p.values.iter().enumerate() {
                let x = nd_darts[p.node][r];
                let id = if rule.changes_topology {
                    orbit_id(g, &overlay, group, x, orbit)
                } else {
                    g.embedding(b.ids[p.emb]).slot(x) as u32
                };
                match written.get(&(p.emb, id)) {
                    Some((w, _)) if same_value(w, v) => {}
                    Some(_) => {
                        conflict = Some(ApplyError::WriteConflict {
                            rule: rule.name.clone(),
                            embedding: b.embs[p.emb].name.clone(),
                            dart: x,
                        });
                        break 'outer;
                    }
                    None => {
                        written.insert((p.emb, id), (v.clone(), x));
                    }
                }
            }
        }
    }
    if let Some(c) = conflict {
        undo_fresh(g, &fresh);
        return Err(c);
    }
    // 4. a value for every embedding of the map on the orbits made only of new darts that
    // the rule does not write, planned before any change (a refusal changes nothing)
    let filled = if rule.changes_topology && !fresh.is_empty() {
        let mut origin: HashMap<Dart, Dart> = HashMap::with_capacity(fresh.len());
        for (m, nd_darts) in ms.iter().zip(&node_darts) {
            let hook = &m.darts[rule.hooks[0]];
            for (k, nd) in rule.nodes.iter().enumerate() {
                if nd.left.is_none() {
                    for (r, &x) in nd_darts[k].iter().enumerate() {
                        origin.insert(x, hook[r]);
                    }
                }
            }
        }
        let mut written_darts: HashMap<EmbeddingId, std::collections::HashSet<Dart>> =
            HashMap::new();
        for ((emb, _), (_, x)) in &written {
            written_darts.entry(b.ids[*emb]).or_default().insert(*x);
        }
        match fill_new_orbits(g, &rule.name, &overlay, &fresh, &origin, &written_darts) {
            Ok(f) => f,
            Err(e) => {
                undo_fresh(g, &fresh);
                return Err(e);
            }
        }
    } else {
        Vec::new()
    };
    // 5. rewrite the topology, then write
    if rule.changes_topology && !ms.is_empty() {
        if let Err(source) = g.rewire_interruptible(&changes, &fresh, &remove, poll.check) {
            undo_fresh(g, &fresh);
            if source == RewireError::Interrupted {
                return Err(interrupted("rewriting the topology"));
            }
            return Err(ApplyError::Rewire {
                rule: rule.name.clone(),
                source,
            });
        }
    }
    for (id, d, v) in filled {
        g.set_value(id, d, &v)
            .map_err(|e| ApplyError::Map(e.to_string()))?;
    }
    let written: HashMap<(usize, usize), Val> = written
        .into_iter()
        .map(|((emb, _), (v, x))| ((emb, g.embedding(b.ids[emb]).slot(x)), v))
        .collect();
    let mut by_emb: HashMap<usize, Vec<(usize, Val)>> = HashMap::new();
    for ((emb, slot), v) in written {
        by_emb.entry(emb).or_default().push((slot, v));
    }
    for (emb, writes) in by_emb {
        let id = b.ids[emb];
        let mut buf = Vec::new();
        for (slot, v) in writes {
            let value = match v {
                Val::I(i) => Value::Int(i),
                Val::B(x) => Value::Bool(x),
                other => {
                    buf.clear();
                    other.to_reals(&mut buf);
                    Value::Real(buf.clone())
                }
            };
            g.set_slot_value(id, slot, &value)
                .map_err(|e| ApplyError::Map(e.to_string()))?;
        }
    }
    Ok(report)
}

/// The values of the embeddings of the map on the orbits made only of new darts that the rule
/// does not write: Jerboa's condition that every embedding of the modeler gets a value on every
/// orbit of the result (Belhaouari et al., "Jerboa: a graph transformation library for
/// topology-based geometric modeling", ICGT 2014, section 4), checked when the rule is applied
/// since the map may carry embeddings the rule's file does not declare.
///
/// Every new dart is a copy of the hook's dart of its row (a created node has one dart per row
/// of the hook orbit): its *origin*. For each non-derived embedding, an orbit of the planned
/// result (`overlay` over `g`) made only of `fresh` darts, none of which the rule writes, gets
/// its value from the old orbits of its darts' origins, by the embedding's policy:
/// - `copy`: the value of the first origin (the origin of the orbit's first new dart in
///   creation order), as a merge under `copy` keeps the first value;
/// - `mean`: the mean of the distinct origin orbits' values (integers: floored; booleans: any);
/// - `sum`: zero, its neutral value, so every total over the map is kept (the origins keep
///   their values);
/// - `error`: refused (the new orbit would split its origin).
///
/// Orbits that hold an old dart are left to [`GMap::rewire`] (merged or split by the policy);
/// derived embeddings are recomputed when read; the vertex numbering `particle`/`point_id`
/// (i64 on the vertex orbit) is numbered by [`GMap::rewire`]. Returns `(embedding, new dart,
/// value)` to write after the rewrite, or [`ApplyError::NoValue`].
fn fill_new_orbits(
    g: &GMap,
    rule: &str,
    overlay: &HashMap<(usize, Dart), Dart>,
    fresh: &[Dart],
    origin: &HashMap<Dart, Dart>,
    written: &HashMap<EmbeddingId, std::collections::HashSet<Dart>>,
) -> Result<Vec<(EmbeddingId, Dart, Value)>, ApplyError> {
    let is_fresh: std::collections::HashSet<Dart> = fresh.iter().copied().collect();
    // the orbits made only of new darts, once per orbit type
    let mut partitions: HashMap<OrbitType, Vec<Vec<Dart>>> = HashMap::new();
    let mut out = Vec::new();
    let vertex = OrbitType::vertex(g.dimension());
    for (k, e) in g.embeddings().iter().enumerate() {
        let id = EmbeddingId(k as u32);
        if e.derived().is_some() {
            continue;
        }
        if e.orbit() == vertex
            && e.ty() == EmbeddingType::I64
            && (e.name() == "particle" || e.name() == "point_id")
        {
            continue;
        }
        let o = e.orbit();
        let orbits = partitions
            .entry(o)
            .or_insert_with(|| new_only_orbits(g, overlay, fresh, &is_fresh, o));
        let w = written.get(&id);
        for orbit in orbits.iter() {
            if let Some(w) = w {
                if orbit.iter().any(|d| w.contains(d)) {
                    continue;
                }
            }
            let first = orbit[0];
            let refuse = |reason: String| ApplyError::NoValue {
                rule: rule.to_string(),
                embedding: e.name().to_string(),
                ty: e.ty(),
                orbit: o,
                policy: e.policy().name(),
                dart: first,
                reason,
            };
            // distinct old orbits of the origins, in the order of the new darts
            let mut slots: Vec<usize> = Vec::new();
            let mut values: Vec<Value> = Vec::new();
            for d in orbit {
                if let Some(&src) = origin.get(d) {
                    let s = e.slot(src);
                    if !slots.contains(&s) {
                        slots.push(s);
                        values.push(
                            g.value(id, src)
                                .map_err(|x| ApplyError::Map(x.to_string()))?,
                        );
                    }
                }
            }
            let v = match e.policy() {
                Policy::Sum => zero_of(e.ty()),
                Policy::Error => {
                    return Err(refuse(
                        "policy error refuses to split an orbit into new ones".to_string(),
                    ))
                }
                _ if values.is_empty() => {
                    return Err(refuse(
                        "its darts copy no old dart, and the policy has no neutral value"
                            .to_string(),
                    ))
                }
                Policy::Copy => values[0].clone(),
                Policy::Mean => mean_of(&values),
            };
            out.push((id, first, v));
        }
    }
    Ok(out)
}

/// The orbits of type `o` in the planned result that are made only of `fresh` darts, each
/// listed from its first new dart in creation order.
fn new_only_orbits(
    g: &GMap,
    overlay: &HashMap<(usize, Dart), Dart>,
    fresh: &[Dart],
    is_fresh: &std::collections::HashSet<Dart>,
    o: OrbitType,
) -> Vec<Vec<Dart>> {
    let mut seen: std::collections::HashSet<Dart> = std::collections::HashSet::new();
    let mut out = Vec::new();
    for &d in fresh {
        if !seen.insert(d) {
            continue;
        }
        let mut darts = vec![d];
        let mut only_new = true;
        let mut at = 0;
        while at < darts.len() {
            let y = darts[at];
            at += 1;
            for i in o.dims() {
                if i > g.dimension() {
                    continue;
                }
                let z = overlay
                    .get(&(i, y))
                    .copied()
                    .unwrap_or_else(|| g.alpha(i, y));
                if seen.insert(z) {
                    only_new &= is_fresh.contains(&z);
                    darts.push(z);
                }
            }
        }
        if only_new {
            out.push(darts);
        }
    }
    out
}

/// The zero of a type (the neutral value of `sum`).
fn zero_of(t: EmbeddingType) -> Value {
    match t {
        EmbeddingType::I64 => Value::Int(0),
        EmbeddingType::Bool => Value::Bool(false),
        other => Value::Real(vec![0.0; other.width()]),
    }
}

/// The mean of values of one type: reals component-wise, integers floored, booleans any.
fn mean_of(values: &[Value]) -> Value {
    let n = values.len();
    match &values[0] {
        Value::Int(_) => {
            let s: i128 = values
                .iter()
                .map(|v| {
                    if let Value::Int(i) = v {
                        i128::from(*i)
                    } else {
                        0
                    }
                })
                .sum();
            Value::Int(s.div_euclid(n as i128) as i64)
        }
        Value::Bool(_) => Value::Bool(values.iter().any(|v| matches!(v, Value::Bool(true)))),
        Value::Real(first) => {
            let mut acc = vec![0.0; first.len()];
            for v in values {
                if let Value::Real(x) = v {
                    for (a, y) in acc.iter_mut().zip(x) {
                        *a += y;
                    }
                }
            }
            for a in &mut acc {
                *a /= n as f64;
            }
            Value::Real(acc)
        }
    }
}

/// Removes the darts an application created before it stopped (free darts, linked to
/// nothing yet).
fn undo_fresh(g: &mut GMap, fresh: &[Dart]) {
    for &d in fresh {
        let _ = g.remove_dart(d);
    }
}

/// Whether every real of a value is finite (integers and booleans always are).
fn finite(v: &Val) -> bool {
    match v {
        Val::F(x) => x.is_finite(),
        Val::I(_) | Val::B(_) => true,
        Val::V2(a) => a.iter().all(|x| x.is_finite()),
        Val::V3(a) => a.iter().all(|x| x.is_finite()),
        Val::M(m) => m.data.iter().all(|x| x.is_finite()),
    }
}

/// A real for a message: as Rust prints it, except a finite value of magnitude at least 1e16
/// or below 1e-5 (not zero), which is written with an exponent (`-1.25e300`, not
/// its 301 digits).
fn short_real(x: f64) -> String {
    if x.is_finite() && x != 0.0 && !(1e-5..1e16).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        x.to_string()
    }
}

/// A non-finite value for a message: a scalar or vector in full, a matrix by its type and its
/// first non-finite entry.
fn describe_non_finite(v: &Val) -> String {
    let list = |a: &[f64]| {
        a.iter()
            .map(|&x| short_real(x))
            .collect::<Vec<_>>()
            .join(", ")
    };
    match v {
        Val::F(x) => short_real(*x),
        Val::V2(a) => format!("({})", list(a)),
        Val::V3(a) => format!("({})", list(a)),
        Val::M(m) => {
            let k = m.data.iter().position(|x| !x.is_finite()).unwrap_or(0);
            format!(
                "(a {} with entry ({}, {}) = {})",
                v.ty(),
                k / m.cols.max(1),
                k % m.cols.max(1),
                short_real(m.data.get(k).copied().unwrap_or(f64::NAN))
            )
        }
        Val::I(i) => i.to_string(),
        Val::B(b) => b.to_string(),
    }
}

/// Bitwise equality of values: a NaN written twice is the same value, and 0.0 and -0.0 are not.
fn same_value(a: &Val, b: &Val) -> bool {
    if let (Val::I(p), Val::I(q)) = (a, b) {
        return p == q;
    }
    let (mut x, mut y) = (Vec::new(), Vec::new());
    a.to_reals(&mut x);
    b.to_reals(&mut y);
    a.ty() == b.ty()
        && x.len() == y.len()
        && x.iter().zip(&y).all(|(p, q)| p.to_bits() == q.to_bits())
}

/// A number naming the orbit `o` of `x` in the map as it will be after `overlay` is applied
/// (the same number for every dart of one orbit); `ids` caches what was walked.
fn orbit_id(
    g: &GMap,
    overlay: &HashMap<(usize, Dart), Dart>,
    ids: &mut HashMap<Dart, u32>,
    x: Dart,
    o: OrbitType,
) -> u32 {
    if let Some(&id) = ids.get(&x) {
        return id;
    }
    let id = x.0;
    ids.insert(x, id);
    let mut stack = vec![x];
    while let Some(y) = stack.pop() {
        for i in o.dims() {
            if i > g.dimension() {
                continue;
            }
            let z = overlay
                .get(&(i, y))
                .copied()
                .unwrap_or_else(|| g.alpha(i, y));
            if let std::collections::hash_map::Entry::Vacant(e) = ids.entry(z) {
                e.insert(id);
                stack.push(z);
            }
        }
    }
    id
}

/// Partition of the rows: rows joined through the orbit positions `uniform` share a class.
fn row_classes(m: &Match, arity: usize, uniform: &[usize]) -> Vec<u32> {
    let mut cls = vec![u32::MAX; m.rows];
    let mut n = 0;
    for r0 in 0..m.rows {
        if cls[r0] != u32::MAX {
            continue;
        }
        cls[r0] = n;
        let mut stack = vec![r0];
        while let Some(r) = stack.pop() {
            for &t in uniform {
                let s = m.next[r * arity + t] as usize;
                if cls[s] == u32::MAX {
                    cls[s] = n;
                    stack.push(s);
                }
            }
        }
        n += 1;
    }
    cls
}

/// Evaluates expressions of one match on the map before the rule.
struct Eval<'a> {
    g: &'a GMap,
    b: &'a Bound<'a>,
    m: &'a Match,
    locals: Vec<Option<Val>>,
    /// For each local of the compute block, the row its value was computed for.
    let_row: Vec<Option<usize>>,
}

impl<'a> Eval<'a> {
    fn new(g: &'a GMap, b: &'a Bound<'a>, m: &'a Match) -> Self {
        Eval {
            g,
            b,
            m,
            // grown when a `let` is first set: a guard tried at every dart of a map
            // (`where n0.vertex0`) allocates nothing
            locals: Vec::new(),
            let_row: Vec::new(),
        }
    }

    /// Sets local `k` to `v` (computed at row `r`, when from the compute block).
    fn set_local(&mut self, k: usize, v: Val, r: Option<usize>) {
        if self.locals.len() <= k {
            let n = self.b.rule.n_locals.max(k + 1);
            self.locals.resize(n, None);
            self.let_row.resize(n, None);
        }
        self.locals[k] = Some(v);
        if r.is_some() {
            self.let_row[k] = r;
        }
    }

    /// Evaluates the `let`s before statement `stop`, then `value`, at row `r`.
    fn run_to(
        &mut self,
        value: &TExpr,
        stop: &TStmt,
        r: usize,
    ) -> Result<Val, crate::value::EvalError> {
        for s in &self.b.rule.program {
            if std::ptr::eq(s, stop) {
                break;
            }
            if let TStmt::Let(k, e) = s {
                // a `let` of the compute block is evaluated once per row of a match
                if self.let_row.get(*k).copied().flatten() != Some(r) {
                    let v = self.eval(e, r)?;
                    self.set_local(*k, v, Some(r));
                }
            }
        }
        self.eval(value, r)
    }

    fn read(&self, emb: usize, d: Dart) -> Val {
        let id = self.b.ids[emb];
        let ty = self.b.embs[emb].ty;
        match self.g.value(id, d) {
            Ok(Value::Real(x)) => Val::from_reals(ty, &x),
            Ok(Value::Int(i)) => Val::I(i),
            Ok(Value::Bool(x)) => Val::B(x),
            Err(_) => Val::zero(ty),
        }
    }

    fn eval(&mut self, e: &TExpr, r: usize) -> Result<Val, crate::value::EvalError> {
        Ok(match e {
            TExpr::Const(v) => v.clone(),
            TExpr::Param(k) => self.b.params[*k].clone(),
            TExpr::Local(k) => {
                self.locals.get(*k).cloned().flatten().ok_or_else(|| {
                    crate::value::EvalError("variable used before it is set".into())
                })?
            }
            TExpr::Read { node, emb } => self.read(*emb, self.m.darts[*node][r]),
            TExpr::Agg {
                kind,
                orbit,
                node,
                emb,
                ty,
            } => self.aggregate(*kind, *orbit, self.m.darts[*node][r], *emb, *ty)?,
            TExpr::Bin(op, a, bb) => {
                if matches!(op, BinOp::And | BinOp::Or) {
                    let x = self.eval(a, r)?;
                    if (x == Val::B(false) && *op == BinOp::And)
                        || (x == Val::B(true) && *op == BinOp::Or)
                    {
                        return Ok(x);
                    }
                    return self.eval(bb, r);
                }
                let x = self.eval(a, r)?;
                let y = self.eval(bb, r)?;
                binop(*op, &x, &y)?
            }
            TExpr::Un(op, a) => {
                let x = self.eval(a, r)?;
                unop(*op, &x)?
            }
            TExpr::Call(name, args) => {
                let mut vs = Vec::with_capacity(args.len());
                for a in args {
                    vs.push(self.eval(a, r)?);
                }
                builtins::call(name, &vs)?
            }
            TExpr::If(c, a, bb) => {
                if self.eval(c, r)? == Val::B(true) {
                    self.eval(a, r)?
                } else {
                    self.eval(bb, r)?
                }
            }
            TExpr::Block(lets, res) => {
                for (k, v) in lets {
                    let x = self.eval(v, r)?;
                    self.set_local(*k, x, None);
                }
                self.eval(res, r)?
            }
            TExpr::ToReal(a) => match self.eval(a, r)? {
                Val::I(i) => Val::F(i as f64),
                v => v,
            },
        })
    }

    fn aggregate(
        &self,
        kind: AggKind,
        orbit: OrbitType,
        d: Dart,
        emb: Option<usize>,
        ty: Ty,
    ) -> Result<Val, crate::value::EvalError> {
        let darts = self.g.orbit(d, orbit);
        let Some(emb) = emb else {
            return Ok(Val::I(darts.len() as i64));
        };
        let e = self.g.embedding(self.b.ids[emb]);
        // the orbit's distinct slots in increasing order: the sum is a function of the orbit,
        // the same bits from each of its darts (compiled plans sum in this order too)
        let mut slots: Vec<(usize, Dart)> = darts.into_iter().map(|x| (e.slot(x), x)).collect();
        slots.sort_unstable_by_key(|&(s, _)| s);
        slots.dedup_by_key(|&mut (s, _)| s);
        let reps: Vec<Dart> = slots.into_iter().map(|(_, x)| x).collect();
        if kind == AggKind::Count {
            return Ok(Val::I(reps.len() as i64));
        }
        let mut acc: Option<Val> = None;
        for &x in &reps {
            let v = self.read(emb, x);
            acc = Some(match acc {
                None => v,
                Some(a) => binop(BinOp::Add, &a, &v)?,
            });
        }
        let total = acc.unwrap_or_else(|| Val::zero(ty));
        Ok(match kind {
            AggKind::Mean => {
                let total = match total {
                    Val::I(i) => Val::F(i as f64),
                    v => v,
                };
                binop(BinOp::Div, &total, &Val::F(reps.len().max(1) as f64))?
            }
            _ => total,
        })
    }
}

impl fmt::Display for Match {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "match of {} rows", self.rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A non-finite value's description stays short: huge and tiny finite entries get an
    /// exponent, ordinary ones print as before, and the non-finite one is named.
    #[test]
    fn a_non_finite_value_is_described_briefly() {
        let d = describe_non_finite(&Val::V3([-1.25e300, f64::NEG_INFINITY, 0.0]));
        assert_eq!(d, "(-1.25e300, -inf, 0)");
        assert_eq!(describe_non_finite(&Val::V2([1.5, f64::NAN])), "(1.5, NaN)");
        assert_eq!(describe_non_finite(&Val::F(f64::INFINITY)), "inf");
        assert_eq!(short_real(2.5e-7), "2.5e-7");
        assert_eq!(short_real(-12345.5), "-12345.5");
    }

    /// The guards the fast search relies on are proven invariant over the rows of a match,
    /// and those whose value may differ between rows are not: a plane cut (reads both
    /// volumes through `<0,1,2>` aggregates of `<0,1>` nodes) and a fracture criterion on the
    /// face (`mean<0,1>` of a `<0>` embedding) are; a read of a dart embedding (`<>`) from a
    /// face node, or of a face node's half-edge value without aggregation, is not.
    #[test]
    fn guards_proven_invariant_over_the_rows_of_a_match() {
        let text = "dimension 3
embedding position : vec3 on <1,2,3>
embedding tag      : bool on <>
embedding strain   : f64 on <0>
rule cut(normal: vec3) {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where dot(mean<0,1,2>(a.position), normal) * dot(mean<0,1,2>(b.position), normal) < 0.0
}
rule fracture {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where { let s = mean<0,1>(a.strain); s > 0.5 }
}
rule by_tag {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where b.tag
}
rule by_half_edge {
  left  { a : <0,1> hook   b : <0,1>   a -3- b }
  right { a : <0,1>        b : <0,1> }
  where a.strain > 0.5
}
";
        let (checked, _) = crate::check::check_sources(&[("t.tmr".to_string(), text.to_string())]);
        let rules = RuleSet::new(checked.unwrap());
        for (name, want) in [
            ("cut", true),
            ("fracture", true),
            ("by_tag", false),
            ("by_half_edge", false),
        ] {
            let r = rules.rule(name).unwrap();
            let guard = r.guard.as_ref().unwrap();
            assert_eq!(
                row_invariant(guard, &left_labels(r), rules.embeddings()),
                want,
                "{name}"
            );
        }
    }
}
