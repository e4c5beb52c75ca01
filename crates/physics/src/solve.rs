//! Jacobian-vector products, implicit Euler and the static solve (Newton with a line search
//! and load stepping, conjugate gradients).

use topomech_rules::{ApplyError, Params};

use crate::*;

/// The ratio of an element's size (the largest distance between two of its vertices) to its
/// size at rest at or below which a static solve's balanced state is refused as degenerate:
/// the element shrunk to a point (see [`Simulation::solve_static`]).
pub const DEGENERATE_SIZE: f64 = 1e-3;

/// A static balance refused ([`Simulation::solve_static`]): the vertex to name and why.
struct Degenerate {
    row: usize,
    why: String,
}

/// The signed volume of 3D element `el` at positions `p` (rows; positive at rest).
fn signed(el: &Element, p: &[[f64; 3]]) -> f64 {
    topomech_gmap::mesh::signed_volume(el.kind, &el.rows, p)
}

/// What the solve of the last static or implicit Euler step did
/// ([`Simulation::solver_report`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SolverReport {
    /// `static` or `implicit_euler`.
    pub integrator: &'static str,
    /// Newton iterations over every load step (static), or conjugate-gradient iterations
    /// of the linearized solve (implicit Euler; 0 with the direct solver).
    pub iterations: usize,
    /// The norm of the residual force on the free vertices (static: of the whole load), or of
    /// the linear system's residual (implicit Euler).
    pub residual: f64,
    /// `residual` divided by the load (static: gravity plus external loads, or the first
    /// residual when prescribed displacements drive the solve), or by the norm of the linear
    /// system's right-hand side (implicit Euler).
    pub relative_residual: f64,
    /// The relative residual the solve must reach.
    pub tolerance: f64,
    /// Whether `relative_residual <= tolerance`, or (static) within [`STALL_TOLERANCE`] or
    /// the forces' rounding level where rounding in the forces stops Newton from decreasing
    /// the residual further (then `relative_residual` may be far above `tolerance`: near 1
    /// for a load below that level; see [`Simulation::solve_static`]). An
    /// implicit Euler step whose iterative solve reached `max_iterations` first is still
    /// taken, with the solution found, and says false here.
    pub converged: bool,
    /// The load increments the static solve took (1: the whole load at once; more when
    /// automatic load stepping was needed; 0 for implicit Euler).
    pub load_steps: usize,
    /// The fraction of the load at which the static solve last converged (1 when it
    /// converged).
    pub load_fraction: f64,
    /// The largest relative residual of every static or implicit Euler step so far (the
    /// failed one included).
    pub worst_relative_residual: f64,
    /// How many static steps so far needed more than one load increment.
    pub load_stepped_steps: usize,
    /// How many static or implicit Euler steps so far did not reach their tolerance (an
    /// implicit Euler step taken with the approximate solution of a linear solve stopped at
    /// `max_iterations`, or a static step that failed).
    pub not_converged_steps: usize,
    /// The linear solver used: `cg`, `pcg` or `direct` (what [`LinearSolver::Auto`] chose;
    /// with `Auto`, a Newton iteration whose direct solve finds the stiffness singular is
    /// solved by `pcg` instead, its iterations counted in `linear_iterations`).
    pub linear_solver: &'static str,
    /// The preconditioner of `pcg`: `jacobi` or `block_jacobi`; `none` for `cg` and `direct`.
    pub preconditioner: &'static str,
    /// The iterations of the iterative linear solver over the whole step (every Newton
    /// iteration of a static solve); 0 for `direct`.
    pub linear_iterations: usize,
    /// Where the Jacobian-vector products of the solve came from: `rules` (the models'
    /// `jvp` rules) or `finite_differences` (central differences of the forces: a static
    /// solve that the rules' products could not bring to balance is taken again with them,
    /// see [`Simulation::solve_static`]).
    pub jacobian: &'static str,
}

/// The smallest [`Config::tolerance`] accepted: a relative residual below it is within
/// rounding of f64 arithmetic (a few ulps times the matrix's condition), so whether a solve
/// reached it says nothing.
pub const MIN_TOLERANCE: f64 = 1e-14;

/// The relative residual a static solve must reach (the default of [`Config::tolerance`]).
pub const STATIC_TOLERANCE: f64 = 1e-10;
/// The relative residual the linear solve of an implicit Euler step must reach (the default
/// of [`Config::tolerance`]).
pub const IMPLICIT_TOLERANCE: f64 = 1e-6;
/// The relative residual of the iterative linear solve of each Newton iteration of a static
/// solve.
pub const NEWTON_LINEAR_TOLERANCE: f64 = 1e-12;
/// The most free degrees of freedom (3 per free vertex) for which [`LinearSolver::Auto`]
/// solves a static step with [`LinearSolver::Direct`] (above: [`LinearSolver::Pcg`]).
/// Measured on co-rotational cantilevers under gravity to 1e-8 (`make bench`, one thread):
/// direct 0.2 s against block-Jacobi PCG 1.0 s at 1,500 tetrahedra, 4 s against 24 s at
/// 12,000, 89 s at 10^5 (57k free degrees of freedom; PCG, whose iterations grow with the
/// mesh, is slower still there). The limit bounds the factor's memory: its fill grows faster
/// than the degrees of freedom in 3D (the process held 4 GB at 57k with a minimum degree
/// ordering; nested dissection, now used, fills less).
pub const AUTO_DIRECT_MAX_DOFS: usize = 100_000;
/// Implicit Euler steps between two rebuilds of its preconditioner (see
/// [`Simulation::solver_report`] and the rules in `implicit_euler`'s docs).
pub const PRECOND_REFRESH_STEPS: u64 = 50;
/// The relative residual at which a static solve whose Newton step no longer decreases the
/// residual (rounding in the forces) counts as converged.
pub const STALL_TOLERANCE: f64 = 1e-8;
/// The rounding level of the forces, in ulps of the size of their terms, at which a static
/// solve whose Newton step no longer decreases the residual counts as converged.
const ROUNDING_ULPS: f64 = 1e3;
/// The smallest load increment automatic load stepping tries, as a fraction of the load.
pub const MIN_LOAD_INCREMENT: f64 = 1.0 / 1024.0;

/// The step of [`Simulation::jvp_finite_differences`] relative to the object's size: about
/// the cube root of the machine epsilon, where the truncation of central differences
/// (O(h^2)) meets the rounding of the forces (O(eps / h)).
const FD_STEP: f64 = 6e-6;

/// How far the models' `jvp` rules may differ from finite differences of the forces
/// (relative) before a static solve whose Newton iterations failed on the rules goes on with
/// finite differences (see [`Simulation::solve_static`]): far above the differences' own
/// error (about 1e-8), far below the warped stiffness's omission at large rotations.
const JACOBIAN_MISMATCH: f64 = 1e-4;
/// Newton iterations allowed for one load increment.
const NEWTON_ITERATIONS: usize = 30;
/// With the direct solver, a static Newton iteration reuses the last factorization (a chord
/// step) when the step before cut the residual to at most this fraction of what it was.
pub const CHORD_RATIO: f64 = 0.8;
/// Halvings of a Newton step the line search tries before giving up on the increment.
const LINE_SEARCH_HALVINGS: usize = 10;

/// The outcome of Newton iterations for one load increment.
pub(crate) struct NewtonOutcome {
    converged: bool,
    iterations: usize,
    linear_iterations: usize,
    /// Why a linear solve failed (indefinite stiffness, singular matrix), if one did.
    why: Option<String>,
    /// The final residual norm and its largest vertex.
    residual: f64,
    worst: usize,
}

/// The conjugate-gradient solution, its iterations and its relative residual.
pub(crate) struct CgOutcome {
    x: Vec<[f64; 3]>,
    iterations: usize,
    relative: f64,
    residual: f64,
}

/// Which system a linear solve is of (for its messages).
#[derive(Clone, Copy)]
pub(crate) enum System {
    /// The stiffness of a static Newton iteration.
    Stiffness,
    /// The same, solved by conjugate gradients after the direct solver found it singular
    /// (`linear_solver = "auto"`): the direct solver is not suggested again.
    StiffnessAfterDirect,
    /// The implicit Euler matrix.
    Implicit,
}

impl System {
    fn what(self) -> &'static str {
        match self {
            System::Stiffness | System::StiffnessAfterDirect => "the stiffness matrix -df/dx",
            System::Implicit => "the implicit Euler matrix (1 + h c) M - h df/dv - h^2 df/dx",
        }
    }

    /// What to try after the direct solver failed (it was the one tried: it is not
    /// suggested again).
    fn direct_hint(self) -> &'static str {
        match self {
            System::Stiffness | System::StiffnessAfterDirect => "the stiffness is singular at this state: buckling, or a model with no stiffness in some direction (springs without shear springs, a free vertex or a rigid-body motion no fixed vertex holds); load stepping is automatic, so try more fixed vertices, a smaller load, a stiffer shear model, or the integrator implicit_euler",
            System::Implicit => "the stiffness is indefinite at this state (buckling, inverted elements) beyond what the mass holds at this time step; try a smaller dt or a stiffer shear model",
        }
    }

    fn hint(self) -> &'static str {
        match self {
            // the direct solver was tried first, and found the stiffness singular
            System::StiffnessAfterDirect => "the direct solver found the stiffness singular at this state and conjugate gradients found it not positive definite: buckling, or a model with no stiffness in some direction (springs without shear springs, a free vertex or a rigid-body motion no fixed vertex holds); load stepping is automatic, so try more fixed vertices, a smaller load, a stiffer shear model, or the integrator implicit_euler",
            System::Stiffness => "the stiffness is not positive definite at this state: buckling, or a model with no stiffness in some direction (springs without shear springs, a free vertex or a rigid-body motion no fixed vertex holds); load stepping is automatic, so try more fixed vertices, a smaller load, a stiffer shear model, the linear solver direct (its LDL^T factorization handles an indefinite but nonsingular stiffness), or the integrator implicit_euler",
            System::Implicit => "the stiffness is indefinite at this state (buckling, inverted elements) beyond what the mass holds at this time step; try a smaller dt, a stiffer shear model, or the linear solver direct (its LDL^T factorization handles an indefinite but nonsingular matrix)",
        }
    }
}

impl Simulation {
    /// `(df/dx) dx + (df/dv) dv` for vertex vectors in row order (a welded row's result is the
    /// sum over its orbits).
    pub fn jvp(&mut self, dx: &[[f64; 3]], dv: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, PhysicsError> {
        if self.fd_jacobian {
            return self.jvp_finite_differences(dx, dv);
        }
        self.set_vertex_vec3("dx", dx)?;
        self.set_vertex_vec3("dv", dv)?;
        let none = Params::new();
        // scratch values, rewritten at every product (see `Simulation::forces`)
        for def in &self.defs {
            for (r, p) in &def.jvp {
                self.rules.apply_everywhere_eager(&mut self.g, r, p)?;
            }
        }
        self.rules
            .apply_everywhere_eager(&mut self.g, "accumulate_jvp", &none)?;
        self.vertex_vec3_sum("df")
    }

    /// [`Simulation::jvp`] by central differences of the models' forces:
    /// `(f(x + h dx, v + h dv) - f(x - h dx, v - h dv)) / 2h`, two force evaluations, with
    /// `h = FD_STEP * size / max(|dx|, |dv|)` (`size` the rest bounding box's diagonal; the
    /// step near the cube root of the machine epsilon balances the O(h^2) truncation against
    /// the rounding of the forces over 2h). Positions and velocities are restored after.
    /// Exact for forces linear in the positions up to rounding; for the others the
    /// derivative every force rule implies, whatever its `jvp` rules approximate (the
    /// co-rotational tetrahedra's omit dR/dx).
    pub fn jvp_finite_differences(
        &mut self,
        dx: &[[f64; 3]],
        dv: &[[f64; 3]],
    ) -> Result<Vec<[f64; 3]>, PhysicsError> {
        let x = self.vertex_vec3("position")?;
        let v = self.vertex_vec3("velocity")?;
        let big = dx
            .iter()
            .chain(dv)
            .flatten()
            .fold(0.0f64, |m, a| m.max(a.abs()));
        if big == 0.0 {
            return Ok(vec![[0.0; 3]; x.len()]);
        }
        let h = FD_STEP * self.size / big;
        let mut at = |sign: f64| -> Result<Vec<[f64; 3]>, PhysicsError> {
            let shift = |base: &[[f64; 3]], d: &[[f64; 3]]| -> Vec<[f64; 3]> {
                base.iter()
                    .zip(d)
                    .map(|(b, d)| std::array::from_fn(|a| b[a] + sign * h * d[a]))
                    .collect()
            };
            self.set_vertex_vec3("position", &shift(&x, dx))?;
            self.set_vertex_vec3("velocity", &shift(&v, dv))?;
            self.forces()?;
            self.vertex_vec3_sum("force")
        };
        let plus = at(1.0);
        let minus = plus.and_then(|p| at(-1.0).map(|m| (p, m)));
        self.set_vertex_vec3("position", &x)?;
        self.set_vertex_vec3("velocity", &v)?;
        let (plus, minus) = minus?;
        Ok(plus
            .iter()
            .zip(&minus)
            .map(|(p, m)| std::array::from_fn(|a| (p[a] - m[a]) / (2.0 * h)))
            .collect())
    }

    /// Whether the models' `jvp` rules differ from finite differences of their forces
    /// ([`Simulation::jvp_finite_differences`]) at the current state by more than
    /// [`JACOBIAN_MISMATCH`] relative, along one fixed direction on the free vertices (a
    /// smooth function of the row, nonzero in every component). Exact rules agree to about
    /// 1e-8 (the differences' truncation and rounding); the co-rotational tetrahedra's warped
    /// stiffness, bent and rotated, differs by 1e-3 and more. False where either product
    /// fails (a non-finite value): nothing to conclude.
    fn jacobian_rules_approximate(&mut self, fixed: &[bool]) -> bool {
        let n = fixed.len();
        let dx: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let t = i as f64;
                if fixed[i] {
                    [0.0; 3]
                } else {
                    [
                        (0.7 * t).sin() + 1.5,
                        (1.3 * t).cos() - 1.5,
                        (2.1 * t).sin() + 1.5,
                    ]
                }
            })
            .collect();
        let zero = vec![[0.0; 3]; n];
        let (Ok(rules), Ok(fd)) = (
            self.jvp(&dx, &zero),
            self.jvp_finite_differences(&dx, &zero),
        ) else {
            return false;
        };
        let (mut diff, mut size) = (0.0, 0.0);
        for ((a, b), held) in rules.iter().zip(&fd).zip(fixed) {
            if !held {
                for k in 0..3 {
                    diff += (a[k] - b[k]) * (a[k] - b[k]);
                    size += b[k] * b[k];
                }
            }
        }
        diff.sqrt() > JACOBIAN_MISMATCH * size.sqrt()
    }

    /// The total force on each vertex: the models' forces, gravity and viscous damping.
    pub(crate) fn total_force(&mut self) -> Result<VertexForces, PhysicsError> {
        self.forces()?;
        let f = self.vertex_vec3_sum("force")?;
        let m = self.vertex_scalar_sum("mass")?;
        let v = self.vertex_vec3("velocity")?;
        let fixed = self.vertex_bool("fixed")?;
        let g = self.cfg.gravity;
        let c = self.cfg.damping;
        let total = f
            .iter()
            .zip(&m)
            .zip(&v)
            .map(|((f, m), v)| {
                [
                    f[0] + m * (g[0] - c * v[0]),
                    f[1] + m * (g[1] - c * v[1]),
                    f[2] + m * (g[2] - c * v[2]),
                ]
            })
            .collect();
        Ok((total, m, fixed))
    }

    /// The linear solver and preconditioner a solve uses: [`Config::linear_solver`], `Auto`
    /// resolved ([`LinearSolver`]'s docs) for a static solve or not with `free_dofs`.
    pub(crate) fn linear_choice(&self, is_static: bool, free_dofs: usize) -> LinearSolver {
        match self.cfg.linear_solver {
            LinearSolver::Auto if is_static && free_dofs <= AUTO_DIRECT_MAX_DOFS => {
                LinearSolver::Direct
            }
            LinearSolver::Auto => LinearSolver::Pcg,
            s => s,
        }
    }

    /// The report's names of a linear solver choice.
    fn solver_names(&self, s: LinearSolver) -> (&'static str, &'static str) {
        match s {
            LinearSolver::Pcg => ("pcg", self.cfg.preconditioner.name()),
            LinearSolver::Direct => ("direct", "none"),
            LinearSolver::Cg | LinearSolver::Auto => ("cg", "none"),
        }
    }

    /// The most iterations of one iterative linear solve: [`Config::max_iterations`], or 10
    /// times the degrees of freedom (at least 50).
    fn max_linear_iterations(&self, rows: usize) -> usize {
        self.cfg.max_iterations.unwrap_or((10 * 3 * rows).max(50))
    }

    /// The implicit Euler preconditioner, kept across steps: it is rebuilt (3 products of the
    /// rules per color of a distance-1 coloring of the coupling graph) when the topology,
    /// the fixed vertices or the kind changed, every [`PRECOND_REFRESH_STEPS`] steps, and
    /// when the last solve took markedly more iterations (more than 1.5 times plus 3) than
    /// the first solve with it. A lagged preconditioner is the exact block diagonal of an
    /// earlier state's matrix, still symmetric positive definite, so conjugate gradients
    /// converge to the same solution, only in more iterations when the state has moved far.
    fn implicit_precond(
        &mut self,
        kind: Preconditioner,
        h: f64,
        c: f64,
        m: &[f64],
        fixed: &[bool],
        last_iterations: Option<usize>,
    ) -> Result<linear::Precond, PhysicsError> {
        self.sync_rows()?;
        let identity = self.g.identity();
        let steps = self.steps;
        let keep = self.solver.precond.as_ref().is_some_and(|p| {
            p.kind == kind
                && p.identity == identity
                && p.fixed == fixed
                && steps - p.built < PRECOND_REFRESH_STEPS
                && match (p.base_iterations, last_iterations) {
                    (Some(b), Some(l)) => l as f64 <= 1.5 * b as f64 + 3.0,
                    _ => true,
                }
        });
        if !keep {
            let d = self.diagonal_blocks(h * h, h)?;
            let a: Vec<[[f64; 3]; 3]> = d
                .iter()
                .zip(m)
                .map(|(d, m)| {
                    std::array::from_fn(|x| {
                        std::array::from_fn(|y| {
                            let shift = if x == y { (1.0 + h * c) * m } else { 0.0 };
                            shift - d[x][y]
                        })
                    })
                })
                .collect();
            self.solver.precond = Some(linear::LaggedPrecond {
                kind,
                identity,
                fixed: fixed.to_vec(),
                built: steps,
                base_iterations: None,
                p: linear::Precond::build(kind, &a, fixed),
            });
        }
        Ok(self.solver.precond.as_ref().expect("set above").p.clone())
    }

    /// One implicit Euler step (Baraff & Witkin 1998, linearized once):
    /// `A dv = h (f + h (df/dx) v)` with `A = (1 + h c) M - h df/dv - h^2 df/dx` (`c` the
    /// viscous damping), then `v += dv`, `x += h v`. The linear solve is
    /// [`Config::linear_solver`] (`Auto`: block-Jacobi preconditioned conjugate gradients,
    /// warm-started from the last step's `dv`, the preconditioner kept across steps as
    /// [`Simulation::implicit_precond`] says) to [`Config::tolerance`] (default
    /// [`IMPLICIT_TOLERANCE`]). An iterative solve that reaches [`Config::max_iterations`]
    /// first still takes the step with the solution it found; the report says
    /// `converged: false`. Errors: [`PhysicsError::Diverged`] (no vertex: the solve is global)
    /// when the matrix is not positive definite for conjugate gradients, or singular for
    /// the direct solver; (naming the vertex of the largest right-hand side) when the solve
    /// has no finite residual or solution (a norm that overflows f64); a rule's failure.
    pub(crate) fn implicit_euler(&mut self) -> Result<(), PhysicsError> {
        let h = self.cfg.dt;
        let c = self.cfg.damping;
        let (f, m, fixed) = self.total_force()?;
        let v = self.vertex_vec3("velocity")?;
        let n = v.len();
        let zero = vec![[0.0; 3]; n];
        let kv = self.jvp(&v, &zero)?;
        let mut rhs: Vec<[f64; 3]> = f
            .iter()
            .zip(&kv)
            .map(|(f, k)| std::array::from_fn(|a| h * (f[a] + h * k[a])))
            .collect();
        project(&mut rhs, &fixed);
        let tol = self.cfg.tolerance.unwrap_or(IMPLICIT_TOLERANCE);
        let free = 3 * fixed.iter().filter(|f| !**f).count();
        let choice = self.linear_choice(false, free);
        // A z = (1 + h c) M z - h^2 (df/dx) z - h (df/dv) z
        let apply = |sim: &mut Self, z: &[[f64; 3]]| -> Result<Vec<[f64; 3]>, PhysicsError> {
            let dx: Vec<[f64; 3]> = z.iter().map(|z| z.map(|x| h * h * x)).collect();
            let dv: Vec<[f64; 3]> = z.iter().map(|z| z.map(|x| h * x)).collect();
            let df = sim.jvp(&dx, &dv)?;
            Ok(z.iter()
                .zip(&df)
                .zip(&m)
                .map(|((z, d), m)| std::array::from_fn(|a| (1.0 + h * c) * m * z[a] - d[a]))
                .collect())
        };
        let solve = if choice == LinearSolver::Direct {
            let blocks = self.assemble_blocks(h * h, h)?;
            let (x, _) = self.direct_solve(
                &blocks,
                Some((&m, 1.0 + h * c)),
                &rhs,
                &fixed,
                (System::Implicit.what(), System::Implicit.direct_hint()),
            )?;
            let mut ax = apply(self, &x)?;
            project(&mut ax, &fixed);
            let res: Vec<[f64; 3]> = ax
                .iter()
                .zip(&rhs)
                .map(|(a, b)| std::array::from_fn(|k| b[k] - a[k]))
                .collect();
            let residual = rows_norm(&res);
            let bn = rows_norm(&rhs);
            CgOutcome {
                x,
                iterations: 0,
                relative: if bn > 0.0 { residual / bn } else { 0.0 },
                residual,
            }
        } else {
            let precond = if choice == LinearSolver::Pcg {
                let last = self
                    .report
                    .as_ref()
                    .filter(|r| r.integrator == "implicit_euler")
                    .map(|r| r.linear_iterations);
                Some(self.implicit_precond(self.cfg.preconditioner, h, c, &m, &fixed, last)?)
            } else {
                None
            };
            let x0 = (self.solver.last_dv.len() == n).then(|| {
                let mut x0 = self.solver.last_dv.clone();
                project(&mut x0, &fixed);
                x0
            });
            let max_it = self.max_linear_iterations(n);
            let out = self.cg(
                &rhs,
                &fixed,
                x0.as_deref(),
                precond.as_ref(),
                (tol, max_it),
                System::Implicit,
                apply,
            )?;
            if let Some(p) = self.solver.precond.as_mut() {
                p.base_iterations.get_or_insert(out.iterations);
            }
            out
        };
        // a norm that overflows (a load or a velocity whose square is beyond f64) leaves the
        // solve without a finite residual: no step is taken with it
        if !solve.relative.is_finite() || solve.x.iter().flatten().any(|x| !x.is_finite()) {
            let vertex = (0..rhs.len()).max_by(|&a, &b| norm3(rhs[a]).total_cmp(&norm3(rhs[b])));
            return Err(PhysicsError::diverged(
                self.steps + 1,
                vertex,
                format!(
                    "the implicit step's linear solve has no finite result (relative residual {:e}): the forces or velocities are beyond what f64 arithmetic can solve for (the largest at this vertex); scale the problem (units) or the load down, or take a smaller dt",
                    solve.relative
                ),
            ));
        }
        let converged = solve.relative <= tol;
        let (linear_solver, preconditioner) = self.solver_names(choice);
        self.record(SolverReport {
            integrator: "implicit_euler",
            iterations: solve.iterations,
            residual: solve.residual,
            relative_residual: solve.relative,
            tolerance: tol,
            converged,
            load_steps: 0,
            load_fraction: 1.0,
            worst_relative_residual: 0.0,
            load_stepped_steps: 0,
            not_converged_steps: 0,
            linear_solver,
            preconditioner,
            linear_iterations: solve.iterations,
            jacobian: "rules",
        });
        self.solver.last_dv.clone_from(&solve.x);
        let dvel = solve.x;
        let x = self.vertex_vec3("position")?;
        let newv: Vec<[f64; 3]> = v
            .iter()
            .zip(&dvel)
            .map(|(v, d)| std::array::from_fn(|a| v[a] + d[a]))
            .collect();
        let newx: Vec<[f64; 3]> = x
            .iter()
            .zip(&newv)
            .map(|(x, v)| std::array::from_fn(|a| x[a] + h * v[a]))
            .collect();
        self.set_vertex_vec3("velocity", &newv)?;
        self.set_vertex_vec3("position", &newx)?;
        self.contact()
    }

    /// Newton iterations on f(x) + `f_ext` + m g = 0, each solving `K du = R` (`K = -df/dx`)
    /// with [`Config::linear_solver`] (`Auto`: the direct solver up to
    /// [`AUTO_DIRECT_MAX_DOFS`] free degrees of freedom: the stiffness assembled from the
    /// rules and factored, the symbolic factorization kept between iterations; else
    /// block-Jacobi preconditioned conjugate gradients to [`NEWTON_LINEAR_TOLERANCE`]), and a
    /// backtracking line search on the residual norm (with the direct solver, the last
    /// factorization is reused, as chord steps, while each step cuts the residual to
    /// at most [`CHORD_RATIO`] of what it was: an assembly costs 3 products of the rules per color of a distance-2
    /// coloring, a reused factorization one triangular solve); the velocity is set to zero. Converged
    /// when the residual on the free vertices is at most [`Config::tolerance`] (default
    /// [`STATIC_TOLERANCE`]) of the load
    /// (gravity and external loads, or the first residual when prescribed displacements drive
    /// it). When the whole load does not converge in 30 iterations, the load (gravity,
    /// `f_ext` and prescribed displacements) is applied in increments from the last converged
    /// fraction, halving the increment on failure down to [`MIN_LOAD_INCREMENT`]. Newton
    /// on the rules' products that fails the first time compares them with central
    /// differences of the forces (two force evaluations a product); where they differ by
    /// more than [`JACOBIAN_MISMATCH`] (the co-rotational tetrahedra's warped stiffness omits
    /// dR/dx, and Newton on it stalls at large rotations), the solve goes on with the
    /// differences from that increment. When the rules' products reach no balance down to
    /// the smallest increment, the whole solve is taken again from the start with the
    /// differences.
    /// [`Simulation::solver_report`] then says what happened (`jacobian`).
    /// Errors: [`PhysicsError::Diverged`] (the positions before the solve restored) when no
    /// increment converges, or when the balanced state is degenerate: an element shrunk to a
    /// point (its size at most [`DEGENERATE_SIZE`] of its rest size: F = 0, a stationary
    /// point of the hyperelastic energies), or (3D) elements inverted at the balance of a
    /// start that had inverted elements (a mirrored start's fold or mirror image), with the relative residual, the
    /// tolerance and what to try; a rule's failure other than a non-finite value.
    pub fn solve_static(&mut self) -> Result<(), PhysicsError> {
        let result = self.solve_static_with_fallback();
        self.fd_jacobian = false;
        result.map_err(|e| self.with_input_point(e))
    }

    /// [`Simulation::solve_static`]: load-stepped Newton on the models' `jvp` rules, and,
    /// where that does not reach balance, the same again from the start with
    /// finite-difference products ([`Simulation::jvp_finite_differences`], set through
    /// `fd_jacobian`, which the caller resets).
    fn solve_static_with_fallback(&mut self) -> Result<(), PhysicsError> {
        self.capped_solve = None;
        let n = self.rows.darts.len();
        self.set_vertex_vec3("velocity", &vec![[0.0; 3]; n])?;
        let x0 = self.vertex_vec3("position")?;
        let fixed = self.vertex_bool("fixed")?;
        let load: f64 = {
            let m = self.vertex_scalar_sum("mass")?;
            let external: f64 = self.vertex_vec3_sum("f_ext")?.into_iter().map(norm3).sum();
            m.iter().sum::<f64>() * norm3(self.cfg.gravity) + external
        };
        // the positions of the fixed vertices ramp from where the last solve held them (the
        // rest positions before the first) to where they are now
        let base = if self.static_base.len() == n {
            self.static_base.clone()
        } else {
            self.vertex_vec3("rest")?
        };
        let at = |t: f64, free: &[[f64; 3]]| -> Vec<[f64; 3]> {
            free.iter()
                .zip(&x0)
                .zip(&base)
                .zip(&fixed)
                .map(|(((x, target), b), &held)| {
                    if held {
                        std::array::from_fn(|a| b[a] + t * (target[a] - b[a]))
                    } else {
                        *x
                    }
                })
                .collect()
        };
        // the residual of the start (fixed vertices at their base): the part of the load the
        // current state does not balance yet. At fraction t the residual solved for is
        // R(x) - (1 - t) R0, which is R(x) at t = 1 (from rest: the load scaled by t).
        let start = at(0.0, &x0);
        self.set_vertex_vec3("position", &start)?;
        let r0 = self.static_residual(&fixed, None, 1.0)?;
        self.set_vertex_vec3("position", &x0)?;
        let first = self.static_residual(&fixed, None, 1.0)?;
        let norm = rows_norm;
        let scale = load.max(norm(&first)).max(norm(&r0)).max(f64::MIN_POSITIVE);
        let tolerance = self.cfg.tolerance.unwrap_or(STATIC_TOLERANCE);
        let tol = tolerance * scale;
        let free = 3 * fixed.iter().filter(|f| !**f).count();
        let choice = self.linear_choice(true, free);
        let (linear_solver, preconditioner) = self.solver_names(choice);
        // the report of this solve: (iterations, load steps, linear iterations) as counted
        let report = |residual: f64,
                      converged: bool,
                      load_fraction: f64,
                      n: (usize, usize, usize),
                      fd: bool| {
            SolverReport {
                integrator: "static",
                iterations: n.0,
                residual,
                relative_residual: residual / scale,
                tolerance,
                converged,
                load_steps: n.1,
                load_fraction,
                worst_relative_residual: 0.0,
                load_stepped_steps: 0,
                not_converged_steps: 0,
                linear_solver,
                preconditioner,
                linear_iterations: n.2,
                jacobian: if fd { "finite_differences" } else { "rules" },
            }
        };
        if !scale.is_finite() {
            // the report says so too (a step that raised describes that step)
            let mut failed = report(f64::INFINITY, false, 0.0, (0, 0, 0), false);
            failed.relative_residual = f64::INFINITY;
            self.record(failed);
            return Err(PhysicsError::diverged(
                self.steps + 1,
                None,
                format!(
                    "the static solve's load overflows: its size is {scale:e} (gravity times mass plus the external loads), beyond what f64 arithmetic can balance; scale the problem (units) or the load down"
                ),
            ));
        }
        let mut linear_iterations = 0;
        let mut why: Option<String> = None;
        // the rounding level of the forces: the stiffness applied to the positions is the
        // size of the forces' terms (at unit strain), each computed to a few ulps
        let zero = vec![[0.0; 3]; n];
        let mut kx = self.jvp(&x0, &zero)?;
        project(&mut kx, &fixed);
        // The rules compute forces from the coordinates themselves, which round at their own
        // size: a body far from the origin (site coordinates, a part of a large assembly)
        // rounds its forces as many times more as its coordinates are larger than its own
        // extent, which `K x0` does not see (the stiffness annihilates a translation). QA: a
        // 10 cm beam moved 100 m away stalled at a relative residual of 1e-4 and was refused.
        let rounding = ROUNDING_ULPS * f64::EPSILON * norm(&kx) * offset_ratio(&x0);
        let stall = (STALL_TOLERANCE.max(tolerance) * scale).max(rounding);
        let mut iterations = 0;
        let mut load_steps = 0;
        let (mut s, mut ds) = (0.0f64, 1.0f64);
        let mut good = start.clone();
        // the closest the whole load came to balance (the first attempt is the whole load)
        let (mut best, mut worst) = (f64::INFINITY, 0);
        // the vertex of the largest residual force of the last attempt with a finite one
        // (named where no attempt at the whole load had one)
        let mut last_worst: Option<usize> = None;
        // whether the rules' products were compared with finite differences yet
        let mut probed = false;
        // A body held nowhere can move rigidly: its stiffness is singular, and a load it
        // does not balance by itself has no static equilibrium; no Jacobian helps there.
        let held = fixed.iter().any(|f| *f);
        loop {
            let t = (s + ds).min(1.0);
            let trial = at(t, &good);
            self.set_vertex_vec3("position", &trial)?;
            let out = self.newton(&fixed, &r0, t, (tol, stall), choice)?;
            iterations += out.iterations;
            linear_iterations += out.linear_iterations;
            if out.why.is_some() {
                why.clone_from(&out.why);
            }
            if t >= 1.0 && out.residual < best {
                best = out.residual;
                worst = out.worst;
            }
            if out.residual.is_finite() {
                last_worst = Some(out.worst);
            }
            if out.converged {
                load_steps += 1;
                s = t;
                good = self.vertex_vec3("position")?;
                if s >= 1.0 {
                    break;
                }
                ds = (2.0 * ds).min(1.0 - s);
            } else {
                // The first failure on the rules' products: where they differ from the
                // forces' derivative here (an approximate tangent), go on with finite
                // differences from this increment, instead of halving it on the rules.
                if !self.fd_jacobian && !probed && held {
                    probed = true;
                    if self.jacobian_rules_approximate(&fixed) {
                        self.fd_jacobian = true;
                        continue;
                    }
                }
                ds *= 0.5;
                if ds < MIN_LOAD_INCREMENT && !self.fd_jacobian && held {
                    // The models' Jacobian rules may approximate the derivative of their
                    // forces (the co-rotational tetrahedra's omit dR/dx): Newton on them
                    // converges linearly at best, and not at all at large rotations. Start
                    // again with the derivative of the forces themselves.
                    self.fd_jacobian = true;
                    (s, ds) = (0.0, 1.0);
                    good.clone_from(&start);
                    (best, worst) = (f64::INFINITY, 0);
                    continue;
                }
                if ds < MIN_LOAD_INCREMENT {
                    self.set_vertex_vec3("position", &x0)?;
                    let rel = best / scale;
                    self.record(report(
                        best,
                        false,
                        s,
                        (iterations, load_steps, linear_iterations),
                        self.fd_jacobian,
                    ));
                    if !held {
                        return Err(PhysicsError::diverged(
                            self.steps + 1,
                            None,
                            format!(
                                "the static solve did not converge: relative residual {rel:.3e} above the tolerance {tolerance:e} ({:.1}% of the load reached), and no vertex is held (fixed or prescribed): the body can move rigidly, so its stiffness is singular (a load it does not balance by itself has no static equilibrium at all, and a balanced one leaves the rigid motion undetermined); hold some vertices, or use the integrator implicit_euler for its motion",
                                100.0 * s
                            ),
                        ));
                    }
                    // what to try: first the parts of the body whose held vertices leave
                    // them a rigid motion (that explains a linear solve's failure too: a
                    // singular matrix), then the last failed linear solve's advice,
                    // otherwise the general advice (a static solve has no ground:
                    // `Simulation::new` refuses one)
                    let worst = if best.is_finite() {
                        worst
                    } else {
                        last_worst.unwrap_or(worst)
                    };
                    let support = self.support_problem(&start, &fixed, &r0);
                    let (cause, vertex, named) = match (&why, support) {
                        (_, Some(p)) if p.loose.is_empty() => {
                            let each = first_of(p.hinges.iter().map(|&(row, held, joint)| {
                                format!(
                                    "the one at vertex row {row}{}, joined {} (at vertex row {joint}{})",
                                    self.input_point_note(row),
                                    match held {
                                        Held::Line => "to the rest at pinched vertices on one line",
                                        _ => "to the rest at one pinched vertex only",
                                    },
                                    self.input_point_note(joint)
                                )
                            }));
                            let k = p.hinges.len();
                            (
                                format!(
                                    "; {k} piece(s) of the body touch the rest only at pinched vertices (points where elements meet without sharing a {}, kept as one particle), held nowhere else, and the load turns them about those points: a hinge, so the stiffness is singular there: {each}; hold vertices of each piece, join the pieces through shared {}s in the mesh (or import it with the pinched option set to split, to see the pieces apart), or use the integrator implicit_euler for their motion",
                                    if self.g.dimension() == 3 { "face" } else { "edge" },
                                    if self.g.dimension() == 3 { "face" } else { "edge" },
                                ),
                                p.hinges[0].0,
                                if k == 1 { "it is the one" } else { "the first is the one" },
                            )
                        }
                        (_, Some(p)) => {
                            let (what, named, at) = match (p.parts, &p.loose[..]) {
                                (1, [(_, held)]) => (format!(
                                    "; the held vertices (fixed or prescribed) all lie {}, so the body can still rotate rigidly about it: its stiffness is singular there, and a load with a moment about it has no nearby balance; hold vertices that are not all on one line (three, not in a row, at least), or use the integrator implicit_euler for its motion",
                                    held.where_()
                                ), "the largest residual force is", worst),
                                (n, loose) => {
                                    let each = first_of(loose.iter().map(|&(row, held)| {
                                        format!(
                                            "the one at vertex row {row}{}, held {}",
                                            self.input_point_note(row),
                                            held.where_()
                                        )
                                    }));
                                    let k = loose.len();
                                    (format!(
                                        "; the body is {n} parts (elements connected to each other), and {k} of them can still move rigidly, their stiffness singular (held nowhere, or on vertices that all lie at one point or on one line that the load turns them about): {each}; hold vertices of each that are not all on one line (three, not in a row, at least), or use the integrator implicit_euler for their motion",
                                    ), if k == 1 { "it is the one" } else { "the first is the one" }, loose[0].0)
                                }
                            };
                            (what, at, named)
                        }
                        (Some(w), None) => (
                            format!("; the last linear solve that failed: {w}"),
                            worst,
                            "the largest residual force is",
                        ),
                        (None, None) => (
                            match self.capped_solve.take() {
                                Some(w) => format!("; {w}"),
                                None => "; try a smaller load, a finer mesh, or the integrator implicit_euler to find a dynamic path".to_string(),
                            },
                            worst,
                            "the largest residual force is",
                        ),
                    };
                    return Err(PhysicsError::diverged(
                        self.steps + 1,
                        Some(vertex),
                        format!(
                            "the static solve did not converge: relative residual {rel:.3e} above the tolerance {tolerance:e} after {iterations} Newton iterations with a line search and load stepping down to increments of 1/{} of the load, on the models' Jacobian rules and then on finite differences of their forces ({:.1}% of the load reached){cause}; {named}",
                            (1.0 / MIN_LOAD_INCREMENT).round(),
                            100.0 * s
                        ),
                    ));
                }
            }
        }
        let res = norm(&self.static_residual(&fixed, None, 1.0)?);
        self.set_vertex_vec3("position", &good)?;
        if let Some(d) = self.degenerate_balance(&base, &start, &good)? {
            // a stationary point of the energy, not an equilibrium a body can hold
            self.set_vertex_vec3("position", &x0)?;
            self.record(report(
                res,
                false,
                s,
                (iterations, load_steps, linear_iterations),
                self.fd_jacobian,
            ));
            return Err(PhysicsError::diverged(self.steps + 1, Some(d.row), d.why));
        }
        self.static_base = good;
        self.record(report(
            res,
            true,
            1.0,
            (iterations, load_steps, linear_iterations),
            self.fd_jacobian,
        ));
        Ok(())
    }

    /// Why the balance a static solve reached at `positions` (rows) from `start` is refused,
    /// if it is; `None` when it stands. Two cases, elements as [`Simulation::elements`]
    /// gives them (oriented positive at rest):
    /// - an element shrunk to a point: its size (the largest distance between two of its
    ///   vertices) at most [`DEGENERATE_SIZE`] of its rest size. F = 0 balances the forces of
    ///   the hyperelastic models, a stationary point of their energy.
    /// - (3D, a model other than linear FEM) elements inverted at the balance when the start
    ///   (`start`: the held vertices where `base`, the last state a solve held or the rest
    ///   shape, had them) inverted elements that `base` had not: from a mirrored start,
    ///   Newton balances the forces on stationary points that are no minimum (a Neo-Hookean
    ///   body folded onto a line, half its elements inverted; St. Venant-Kirchhoff's mirror
    ///   image, of zero energy). Elements inverted at the balance of a start that inverted
    ///   none are kept (a load can invert elements), and so is every balance of linear FEM,
    ///   whose answer does not depend on the start.
    fn degenerate_balance(
        &self,
        base: &[[f64; 3]],
        start: &[[f64; 3]],
        positions: &[[f64; 3]],
    ) -> Result<Option<Degenerate>, PhysicsError> {
        let rest = self.rest_points()?;
        let size = |rows: &[usize], p: &[[f64; 3]]| {
            let mut m = 0.0_f64;
            for (a, &i) in rows.iter().enumerate() {
                for &j in &rows[a + 1..] {
                    m = m.max(norm3(std::array::from_fn(|k| p[i][k] - p[j][k])));
                }
            }
            m
        };
        let elements = self.elements()?;
        for (k, el) in elements.iter().enumerate() {
            let (s0, s) = (size(&el.rows, &rest), size(&el.rows, positions));
            // (an element of size zero at rest: a degenerate mesh, refused at set-up)
            if s0 > 0.0 && s <= DEGENERATE_SIZE * s0 {
                let inverted_start = self.g.dimension() == 3
                    && elements
                        .iter()
                        .any(|el| signed(el, start) < 0.0 && signed(el, base) >= 0.0);
                let cause = if inverted_start {
                    "a start with inverted elements (mirrored positions) leads there; start from positions where every element keeps its rest orientation (the rest positions, or the last state a solve held)"
                } else {
                    "Newton went there from this start instead of to an equilibrium (a start far from one, compressed or stretched a lot, can); start nearer (the rest positions, or the last state a solve held), or apply the load in smaller steps"
                };
                return Ok(Some(Degenerate {
                    row: el.rows[0],
                    why: format!(
                        "the static solve reached a balance of the forces where element {k} (in the order of Simulation::elements) has shrunk to {:.3e} of its rest size (the largest distance between two of its vertices; at most {DEGENERATE_SIZE:e} is refused): an element collapsed to a point (deformation gradient F = 0) is a stationary point of the energy, not a state the body can hold; {cause}. The element has its first vertex",
                        s / s0
                    ),
                }));
            }
        }
        // linear FEM's balance does not depend on the start (its stiffness is constant): an
        // inverted element in it is the answer of its equations
        let linear = self.cfg.models.iter().all(|m| m.kind == "linear_fem");
        if self.g.dimension() != 3 || linear {
            return Ok(None);
        }
        // inverted at the start but not in the last state a solve held (the rest shape before
        // the first): what the caller's positions inverted (a mirror), not the load
        let before = elements
            .iter()
            .filter(|el| signed(el, start) < 0.0 && signed(el, base) >= 0.0)
            .count();
        let after = elements
            .iter()
            .filter(|el| signed(el, positions) < 0.0)
            .count();
        if before == 0 || after == 0 {
            return Ok(None);
        }
        let (k, el) = elements
            .iter()
            .enumerate()
            .find(|(_, el)| signed(el, positions) < 0.0)
            .expect("counted");
        Ok(Some(Degenerate {
            row: el.rows[0],
            why: format!(
                "the static solve reached a balance of the forces with {after} of {} elements inverted (the first: element {k} in the order of Simulation::elements), from a start where {before} elements were inverted that the last state a solve held (the rest shape before the first) had not: from such a start (a mirror) Newton finds stationary points of the energy that are not a state the body holds (folded, or the model's mirror image); start from positions where every element keeps the orientation it had (the rest positions, or the last state a solve held). The element has its first vertex",
                elements.len()
            ),
        }))
    }

    /// Keeps `r` as the last step's report, with the run's worst relative residual and count
    /// of load-stepped steps carried over from the previous one.
    pub(crate) fn record(&mut self, mut r: SolverReport) {
        let (worst, stepped, unmet) = self.report.as_ref().map_or((0.0, 0, 0), |p| {
            (
                p.worst_relative_residual,
                p.load_stepped_steps,
                p.not_converged_steps,
            )
        });
        r.worst_relative_residual = worst.max(r.relative_residual);
        r.not_converged_steps = unmet + usize::from(!r.converged);
        r.load_stepped_steps =
            stepped + usize::from(r.integrator == "static" && (r.load_steps > 1 || !r.converged));
        self.report = Some(r);
    }

    /// What the solve of the last static or implicit Euler step did (None before the first
    /// such step, and for the other integrators).
    pub fn solver_report(&self) -> Option<&SolverReport> {
        self.report.as_ref()
    }

    /// The static residual at the current positions, fixed vertices' components zero:
    /// R(x) - (1 - t) R0 (R0 given), or R(x).
    pub(crate) fn static_residual(
        &mut self,
        fixed: &[bool],
        r0: Option<&[[f64; 3]]>,
        t: f64,
    ) -> Result<Vec<[f64; 3]>, PhysicsError> {
        let (mut r, _, _) = self.total_force()?;
        if let Some(r0) = r0 {
            for (r, r0) in r.iter_mut().zip(r0) {
                for a in 0..3 {
                    r[a] -= (1.0 - t) * r0[a];
                }
            }
        }
        project(&mut r, fixed);
        Ok(r)
    }

    /// Newton iterations with a backtracking line search on the residual norm for the load
    /// fraction `t`, from the current positions. A non-finite force, an indefinite stiffness
    /// or a line search that finds no decrease ends them unconverged (positions left as
    /// they are: the caller restores them).
    pub(crate) fn newton(
        &mut self,
        fixed: &[bool],
        r0: &[[f64; 3]],
        t: f64,
        (tol, stall): (f64, f64),
        choice: LinearSolver,
    ) -> Result<NewtonOutcome, PhysicsError> {
        let norm = rows_norm;
        let worst_of = |r: &[[f64; 3]]| {
            r.iter()
                .map(|x| norm3(*x))
                .enumerate()
                .fold(
                    (0, -1.0),
                    |acc, (i, v)| if v > acc.1 { (i, v) } else { acc },
                )
                .0
        };
        let attempt = |e: PhysicsError| match e {
            PhysicsError::Apply(ApplyError::NonFinite { .. }) | PhysicsError::Diverged { .. } => {
                Ok(())
            }
            e => Err(e),
        };
        let mut r = match self.static_residual(fixed, Some(r0), t) {
            Ok(r) => r,
            Err(e) => {
                attempt(e)?;
                return Ok(NewtonOutcome {
                    converged: false,
                    iterations: 0,
                    linear_iterations: 0,
                    why: None,
                    residual: f64::INFINITY,
                    worst: 0,
                });
            }
        };
        let mut res = norm(&r);
        let mut iterations = 0;
        let mut linear_iterations = 0;
        // chord steps: with the direct solver, the last factorization is reused while each
        // step cuts the residual to CHORD_RATIO of what it was or less (an assembly costs 3 products of the rules per
        // color of a distance-2 coloring, a reused factorization one triangular solve); a
        // step whose line search fails on a reused factorization is retried with a fresh one
        let mut lagged = false;
        let cap = if choice == LinearSolver::Direct {
            2 * NEWTON_ITERATIONS
        } else {
            NEWTON_ITERATIONS
        };
        let done =
            |converged, iterations, linear_iterations, res: f64, r: &[[f64; 3]]| NewtonOutcome {
                converged,
                iterations,
                linear_iterations,
                why: None,
                residual: if res.is_finite() { res } else { f64::INFINITY },
                worst: worst_of(r),
            };
        while iterations < cap {
            if res <= tol {
                return Ok(done(true, iterations, linear_iterations, res, &r));
            }
            if !res.is_finite() {
                break;
            }
            iterations += 1;
            let (du, reused) = match self.newton_direction(&r, fixed, choice, lagged) {
                Ok((du, its, reused)) => {
                    linear_iterations += its;
                    (du, reused)
                }
                Err(e) => {
                    let why = match &e {
                        PhysicsError::Diverged { why, .. } => Some(why.clone()),
                        _ => None,
                    };
                    attempt(e)?;
                    let mut out = done(false, iterations, linear_iterations, res, &r);
                    out.why = why;
                    return Ok(out);
                }
            };
            let x = self.vertex_vec3("position")?;
            let mut alpha = 1.0;
            let mut accepted = None;
            // the full step's residual, its norm and its positions, where finite
            let mut full: Option<FullStep> = None;
            for halvings in 0..=LINE_SEARCH_HALVINGS {
                let trial: Vec<[f64; 3]> = x
                    .iter()
                    .zip(&du)
                    .map(|(x, d)| std::array::from_fn(|a| x[a] + alpha * d[a]))
                    .collect();
                self.set_vertex_vec3("position", &trial)?;
                match self.static_residual(fixed, Some(r0), t) {
                    Ok(rt) => {
                        let nt = norm(&rt);
                        // sufficient decrease (Armijo on the residual norm)
                        if nt.is_finite() && nt <= (1.0 - 1e-4 * alpha) * res {
                            accepted = Some((rt, nt));
                            break;
                        }
                        if halvings == 0 && nt.is_finite() {
                            full = Some((rt, nt, trial));
                        }
                    }
                    Err(e) => attempt(e)?,
                }
                alpha *= 0.5;
            }
            let Some((rt, nt)) = accepted else {
                self.set_vertex_vec3("position", &x)?;
                if reused {
                    lagged = false;
                    continue;
                }
                // the residual may stall at the rounding level of the forces just above the
                // tolerance (small loads on stiff models): close enough when within
                // STALL_TOLERANCE, or the rounding level. Where the full Newton step's residual
                // is at that level too, the step is taken: its residual cannot show it is
                // better, but it comes from the linear solve, which is (a linear model's
                // displacement, exactly). QA: a load on a stiff beam below the forces'
                // rounding level was "balanced" at the rest positions, 0 displacement. Only a
                // step far below the object's size is taken: a load at the rounding level
                // moves the body by about that much over its stiffness, while a step along a
                // mechanism (a body held at one point, free to turn) may be anything.
                let small = du.iter().all(|d| norm3(*d) <= 1e-6 * self.size);
                if res <= stall && small {
                    if let Some((rt, nt, trial)) = full.filter(|f| f.1 <= stall) {
                        self.set_vertex_vec3("position", &trial)?;
                        return Ok(done(true, iterations, linear_iterations, nt, &rt));
                    }
                }
                return Ok(done(res <= stall, iterations, linear_iterations, res, &r));
            };
            lagged = nt <= CHORD_RATIO * res;
            r = rt;
            res = nt;
        }
        Ok(done(res <= tol, iterations, linear_iterations, res, &r))
    }

    /// Preconditioned conjugate gradients on `apply` (symmetric positive definite on the
    /// free components), fixed vertices' components held at zero, from `x0` (zero when
    /// None), with the preconditioner `precond` (none when None), until the residual is at
    /// most `tol` times `|b|` or after `max_iterations`; returns the solution, the
    /// iterations and the relative residual reached (the caller compares it with `tol`).
    /// Errors: [`PhysicsError::Diverged`] without a vertex (the solve is global) when
    /// `p^T A p` is not positive or not finite, saying what to try for `system`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn cg(
        &mut self,
        b: &[[f64; 3]],
        fixed: &[bool],
        x0: Option<&[[f64; 3]]>,
        precond: Option<&linear::Precond>,
        (tol, max_iterations): (f64, usize),
        system: System,
        mut apply: impl FnMut(&mut Self, &[[f64; 3]]) -> Result<Vec<[f64; 3]>, PhysicsError>,
    ) -> Result<CgOutcome, PhysicsError> {
        let n = b.len();
        let dot = |a: &[[f64; 3]], b: &[[f64; 3]]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| x[0] * y[0] + x[1] * y[1] + x[2] * y[2])
                .sum::<f64>()
        };
        let bb = dot(b, b);
        if bb == 0.0 {
            return Ok(CgOutcome {
                x: vec![[0.0; 3]; n],
                iterations: 0,
                relative: 0.0,
                residual: 0.0,
            });
        }
        let (mut x, mut r) = match x0 {
            Some(x0) if x0.iter().flatten().any(|v| *v != 0.0) => {
                let mut ax = apply(self, x0)?;
                project(&mut ax, fixed);
                let r: Vec<[f64; 3]> = b
                    .iter()
                    .zip(&ax)
                    .map(|(b, a)| std::array::from_fn(|k| b[k] - a[k]))
                    .collect();
                // a guess worse than none is dropped
                if dot(&r, &r) < bb {
                    (x0.to_vec(), r)
                } else {
                    (vec![[0.0; 3]; n], b.to_vec())
                }
            }
            _ => (vec![[0.0; 3]; n], b.to_vec()),
        };
        let precondition = |r: &[[f64; 3]]| match precond {
            Some(p) => {
                let mut z = p.apply(r);
                project(&mut z, fixed);
                z
            }
            None => r.to_vec(),
        };
        let mut z = precondition(&r);
        let mut p = z.clone();
        let mut rz = dot(&r, &z);
        let mut rr = dot(&r, &r);
        let target = tol * tol * bb;
        let mut iterations = 0;
        while rr > target && iterations < max_iterations {
            iterations += 1;
            let mut ap = apply(self, &p)?;
            project(&mut ap, fixed);
            let pap = dot(&p, &ap);
            if pap <= 0.0 || !pap.is_finite() || rz <= 0.0 || rz.is_nan() {
                return Err(PhysicsError::diverged(
                    self.steps + 1,
                    None,
                    format!(
                        "{} is not positive definite for conjugate gradients (p^T A p = {pap:.3e} at iteration {iterations}): {}",
                        system.what(),
                        system.hint()
                    ),
                ));
            }
            let alpha = rz / pap;
            for i in 0..n {
                for a in 0..3 {
                    x[i][a] += alpha * p[i][a];
                    r[i][a] -= alpha * ap[i][a];
                }
            }
            z = precondition(&r);
            let rz_new = dot(&r, &z);
            rr = dot(&r, &r);
            let beta = rz_new / rz;
            rz = rz_new;
            for i in 0..n {
                for a in 0..3 {
                    p[i][a] = z[i][a] + beta * p[i][a];
                }
            }
        }
        Ok(CgOutcome {
            x,
            iterations,
            relative: (rr / bb).sqrt(),
            residual: rr.sqrt(),
        })
    }

    /// The Newton direction `du` with `K du = r` (`K = -df/dx` on the free components) by
    /// the static solve's linear solver, the iterations it took, and whether it came from
    /// the last factorization (`lagged`: asked for and available, direct solver only).
    fn newton_direction(
        &mut self,
        r: &[[f64; 3]],
        fixed: &[bool],
        choice: LinearSolver,
        lagged: bool,
    ) -> Result<(Vec<[f64; 3]>, usize, bool), PhysicsError> {
        // (set again below where this direction's solve stops at max_iterations)
        self.capped_solve = None;
        let n = r.len();
        let zero = vec![[0.0; 3]; n];
        let apply = |sim: &mut Self, z: &[[f64; 3]]| -> Result<Vec<[f64; 3]>, PhysicsError> {
            Ok(sim.jvp(z, &zero)?.iter().map(|d| d.map(|x| -x)).collect())
        };
        let mut choice = choice;
        let mut system = System::Stiffness;
        if choice == LinearSolver::Direct && lagged {
            if let Some(x) = self.direct_resolve(r, fixed) {
                return Ok((x, 0, true));
            }
        }
        if choice == LinearSolver::Direct {
            let blocks = self.assemble_blocks(1.0, 0.0)?;
            match self.direct_solve(
                &blocks,
                None,
                r,
                fixed,
                (System::Stiffness.what(), System::Stiffness.direct_hint()),
            ) {
                Ok((x, _)) => return Ok((x, 0, false)),
                // auto: a singular stiffness (a mechanism the load does not excite) may
                // still have a solution conjugate gradients find in its range
                Err(PhysicsError::Diverged { .. })
                    if self.cfg.linear_solver == LinearSolver::Auto =>
                {
                    choice = LinearSolver::Pcg;
                    system = System::StiffnessAfterDirect;
                }
                Err(e) => return Err(e),
            }
        }
        let precond = if choice == LinearSolver::Pcg {
            let d = self.diagonal_blocks(1.0, 0.0)?;
            let k: Vec<[[f64; 3]; 3]> = d.iter().map(|b| b.map(|row| row.map(|v| -v))).collect();
            Some(linear::Precond::build(self.cfg.preconditioner, &k, fixed))
        } else {
            None
        };
        let max_it = self.max_linear_iterations(n);
        let out = self.cg(
            r,
            fixed,
            None,
            precond.as_ref(),
            (NEWTON_LINEAR_TOLERANCE, max_it),
            system,
            apply,
        )?;
        if out.iterations >= max_it && out.relative > NEWTON_LINEAR_TOLERANCE {
            // the direction is the approximate one found: said if the solve then fails
            self.capped_solve = Some(format!(
                "a Newton step's linear solve stopped at max_iterations ({max_it}) with relative residual {:.3e}, above its tolerance {NEWTON_LINEAR_TOLERANCE:e}: raise integrator.max_iterations, or use the direct solver",
                out.relative
            ));
        }
        Ok((out.x, out.iterations, false))
    }
}

/// Per vertex: total force, mass, fixed.
pub(crate) type VertexForces = (Vec<[f64; 3]>, Vec<f64>, Vec<bool>);

/// How the held vertices of a part of a body leave it a rigid motion (see
/// [`Simulation::support_problem`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Held {
    /// None is held: it can move rigidly.
    Nowhere,
    /// All lie at one point: it can rotate about it.
    Point,
    /// All lie on one line: it can rotate about it.
    Line,
}

impl Held {
    /// Where the held vertices lie, for a message.
    fn where_(self) -> &'static str {
        match self {
            Held::Nowhere => "nowhere",
            Held::Point => "at one point",
            Held::Line => "on one line",
        }
    }
}

/// The parts of a body whose held vertices leave them a rigid motion.
struct Support {
    /// The number of parts of the body.
    parts: usize,
    /// Each such part's smallest vertex row and how its held vertices lie: those held
    /// nowhere first, then at one point, then on one line, each by row.
    loose: Vec<(usize, Held)>,
    /// Pieces of parts that are held as a whole, joined to the rest of their part only at
    /// pinched vertices (rows of several vertex orbits kept as one particle) that all lie
    /// at one point or on one line, with nothing of their own holding them off it, and
    /// whose load turns them about it: (the piece's smallest row, how, the row of a
    /// pinched vertex it hangs on), by row.
    hinges: Vec<(usize, Held, usize)>,
}

/// A relative size of a moment, against the load's forces times the body's size, below
/// which the load leaves a rotation about a support unexcited (rounding of sums of a few
/// thousand products is far below it; a load with a real moment far above).
const MOMENT_TOLERANCE: f64 = 1e-9;

impl Simulation {
    /// The parts of the body ([`Simulation::parts`]: its connected components, joined
    /// through welded rows; each named by its smallest row) whose held vertices (`fixed`, at positions `x`, by row)
    /// leave them a rigid motion: none held (its stiffness is singular, whatever the
    /// load), or all at one point or on one line ([`held_on_a_line`]) with a load (`load`,
    /// by row: the residual of the start) that has a moment about that point, or about
    /// that line's axis; `None` when there is none: every part is held on a plane at
    /// least, or its load does not turn it (a sheet in a plane held along a line of it
    /// under loads in that plane). Which one stops the solve the residual cannot tell (a
    /// part held on a line may swing to a balance, another not), so all are given.
    fn support_problem(
        &mut self,
        x: &[[f64; 3]],
        fixed: &[bool],
        load: &[[f64; 3]],
    ) -> Option<Support> {
        let (part, _) = self.parts();
        // each part's smallest row (parts are numbered in row order, so a part is new at its
        // smallest row), its held positions and its free rows
        let mut parts: Vec<(usize, Vec<[f64; 3]>, Vec<usize>)> = Vec::new();
        for (r, &p) in part.iter().enumerate().take(x.len()) {
            if p == parts.len() {
                parts.push((r, Vec::new(), Vec::new()));
            }
            if fixed[r] {
                parts[p].1.push(x[r]);
            } else {
                parts[p].2.push(r);
            }
        }
        let size = body_size(x);
        let count = parts.len();
        // how each part is held, where that leaves it a rigid motion its load excites
        let problem = |(row, held, free): &(usize, Vec<[f64; 3]>, Vec<usize>)| {
            if held.is_empty() {
                return Some((*row, Held::Nowhere));
            }
            let (how, axis) = held_on_a_line(held, size)?;
            // the load's moment about the first held vertex (along the line's axis)
            let p0 = held[0];
            let (mut m, mut total) = ([0.0; 3], 0.0);
            for &r in free {
                let arm: [f64; 3] = std::array::from_fn(|a| x[r][a] - p0[a]);
                let f = load[r];
                m[0] += arm[1] * f[2] - arm[2] * f[1];
                m[1] += arm[2] * f[0] - arm[0] * f[2];
                m[2] += arm[0] * f[1] - arm[1] * f[0];
                total += norm3(f);
            }
            let turning = match axis {
                Some(u) => (m[0] * u[0] + m[1] * u[1] + m[2] * u[2]).abs(),
                None => norm3(m),
            };
            (turning > MOMENT_TOLERANCE * total * size).then_some((*row, how))
        };
        let mut loose: Vec<(usize, Held)> = parts.iter().filter_map(problem).collect();
        loose.sort_by_key(|&(row, held)| (held as u8, row));
        let hinges = self.hinges(x, fixed, &part, &loose, &problem);
        (!loose.is_empty() || !hinges.is_empty()).then_some(Support {
            parts: count,
            loose,
            hinges,
        })
    }

    /// The pieces of the body's parts (the map's connected components: the elements
    /// joined through faces in 3D, edges in 2D) that hang on the rest of their part at
    /// pinched vertices only (see [`Support::hinges`]), for parts not in `loose`: each
    /// piece's held positions are its own held rows' and those of the pinched rows joining
    /// it to another piece, taken as held (where the other piece is held), and `problem`
    /// says whether they leave it a rotation its load excites.
    #[allow(clippy::type_complexity)]
    fn hinges(
        &self,
        x: &[[f64; 3]],
        fixed: &[bool],
        part: &[usize],
        loose: &[(usize, Held)],
        problem: &dyn Fn(&(usize, Vec<[f64; 3]>, Vec<usize>)) -> Option<(usize, Held)>,
    ) -> Vec<(usize, Held, usize)> {
        if self.rows.welded.is_empty() {
            return Vec::new();
        }
        let mut comps = crate::integrate::Components::new(&self.g);
        let mut piece = |d: topomech_gmap::Dart| comps.of(&self.g, d);
        let n = x.len().min(self.rows.darts.len());
        let mut of_row: Vec<usize> = (0..n).map(|r| piece(self.rows.darts[r])).collect();
        // the pinched rows joining two pieces or more: (row, its pieces)
        let mut joints: Vec<(usize, Vec<usize>)> = Vec::new();
        for (row, darts) in &self.rows.welded {
            let mut ps: Vec<usize> = darts.iter().map(|&d| piece(d)).collect();
            ps.sort_unstable();
            ps.dedup();
            if *row < n && ps.len() > 1 {
                of_row[*row] = usize::MAX;
                joints.push((*row, ps));
            }
        }
        let pieces = comps.count();
        // per piece: (smallest row, held positions, free rows), and a joint it hangs on
        let mut each: Vec<(usize, Vec<[f64; 3]>, Vec<usize>)> =
            vec![(usize::MAX, Vec::new(), Vec::new()); pieces];
        let mut joint_of: Vec<Option<usize>> = vec![None; pieces];
        let mut part_of: Vec<usize> = vec![usize::MAX; pieces];
        for (r, &p) in of_row.iter().enumerate() {
            if p == usize::MAX {
                continue;
            }
            let e = &mut each[p];
            e.0 = e.0.min(r);
            part_of[p] = part[r];
            if fixed[r] {
                e.1.push(x[r]);
            } else {
                e.2.push(r);
            }
        }
        for (row, ps) in &joints {
            for &p in ps {
                each[p].1.push(x[*row]);
                joint_of[p].get_or_insert(*row);
                if part_of[p] == usize::MAX {
                    part_of[p] = part[*row];
                }
            }
        }
        let loose_parts: Vec<usize> = loose.iter().map(|&(row, _)| part[row]).collect();
        let mut out: Vec<(usize, Held, usize)> = (0..pieces)
            .filter_map(|p| {
                let joint = joint_of[p]?;
                // a piece of pinched vertices alone has no element of its own to turn
                if loose_parts.contains(&part_of[p]) || each[p].0 == usize::MAX {
                    return None;
                }
                let (row, how) = problem(&each[p])?;
                (how != Held::Nowhere).then_some((row, how, joint))
            })
            .collect();
        out.sort_by_key(|&(row, held, _)| (held as u8, row));
        out
    }

    /// " (input point P)" for vertex row `row`, where the map has input points; else "".
    fn input_point_note(&self, row: usize) -> String {
        self.input_point(row)
            .map_or(String::new(), |q| format!(" (input point {q})"))
    }

    /// The input point of vertex row `row` (its `point_id`), where the map has one.
    pub(crate) fn input_point(&self, row: usize) -> Option<i64> {
        let id = self.g.embedding_id("point_id")?;
        let d = *self.rows.darts.get(row)?;
        match self.g.value(id, d) {
            Ok(topomech_gmap::Value::Int(p)) if p >= 0 => Some(p),
            _ => None,
        }
    }
}

/// The first four of `items` joined by "; ", then "; and N more" for the others.
fn first_of(items: impl ExactSizeIterator<Item = String>) -> String {
    let n = items.len();
    let mut out: Vec<String> = items.take(4).collect();
    if n > 4 {
        out.push(format!("and {} more", n - 4));
    }
    out.join("; ")
}

/// The diagonal of the bounding box of `x`.
fn body_size(x: &[[f64; 3]]) -> f64 {
    let (lo, hi) = x.iter().fold(
        ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]),
        |(lo, hi), p| {
            (
                std::array::from_fn(|a| lo[a].min(p[a])),
                std::array::from_fn(|a| hi[a].max(p[a])),
            )
        },
    );
    norm3(std::array::from_fn(|a| hi[a] - lo[a]))
}

/// Where the held positions `held` all lie when they leave rigid rotations free:
/// [`Held::Point`] (all within 1e-9 of `size`, the body's, of the first), or [`Held::Line`]
/// with its unit direction (the largest distance of any from the line through the first and
/// the farthest from it within 1e-9 of `size`); `None` when they span a plane, or none is
/// given. A body held so can turn about that point or line: its stiffness matrix is
/// singular there.
fn held_on_a_line(held: &[[f64; 3]], size: f64) -> Option<(Held, Option<[f64; 3]>)> {
    let first = *held.first()?;
    if !(size.is_finite() && size > 0.0) {
        return None;
    }
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let eps = 1e-9 * size;
    // the held vertex farthest from the first, then the farthest from the line through both
    let far = held
        .iter()
        .copied()
        .max_by(|a, b| norm3(sub(*a, first)).total_cmp(&norm3(sub(*b, first))))?;
    let axis = sub(far, first);
    let length = norm3(axis);
    if length <= eps {
        return Some((Held::Point, None));
    }
    let u = axis.map(|c| c / length);
    let off_line = held.iter().map(|p| {
        let d = sub(*p, first);
        let along = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
        norm3([
            d[0] - along * u[0],
            d[1] - along * u[1],
            d[2] - along * u[2],
        ])
    });
    (off_line.fold(0.0, f64::max) <= eps).then_some((Held::Line, Some(u)))
}

/// A Newton step's trial at the full step: its residual, the residual's norm, the positions.
type FullStep = (Vec<[f64; 3]>, f64, Vec<[f64; 3]>);

/// How many times the coordinates of `x` are larger than the body's own extent: the largest
/// coordinate magnitude over the largest distance from the mean position, at least 1 (see
/// the rounding level of [`Simulation::solve_static`]).
fn offset_ratio(x: &[[f64; 3]]) -> f64 {
    if x.is_empty() {
        return 1.0;
    }
    #[allow(clippy::cast_precision_loss)]
    let n = x.len() as f64;
    let mean: [f64; 3] = std::array::from_fn(|k| x.iter().map(|p| p[k] / n).sum());
    let (mut abs, mut own) = (0.0_f64, 0.0_f64);
    for p in x {
        for k in 0..3 {
            abs = abs.max(p[k].abs());
            own = own.max((p[k] - mean[k]).abs());
        }
    }
    let ratio = abs / own;
    if ratio.is_finite() {
        ratio.max(1.0)
    } else {
        1.0
    }
}
