//! Jacobian-vector products, implicit Euler and the static solve (Newton with a line search
//! and load stepping, conjugate gradients).

use topomech_rules::{ApplyError, Params};

use crate::*;

/// What the solve of the last static or implicit Euler step did
/// ([`Simulation::solver_report`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SolverReport {
    /// `static` or `implicit_euler`.
    pub integrator: &'static str,
    /// Newton iterations over every load step (static), or conjugate-gradient iterations
    /// of the linearized solve (implicit Euler).
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
    /// Whether `relative_residual <= tolerance`, or (static) within [`STALL_TOLERANCE`] where
    /// rounding in the forces stops Newton from decreasing the residual further.
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
}

/// The relative residual a static solve must reach.
pub const STATIC_TOLERANCE: f64 = 1e-10;
/// The relative residual the linear solve of an implicit Euler step must reach.
pub const IMPLICIT_TOLERANCE: f64 = 1e-8;
/// The relative residual at which a static solve whose Newton step no longer decreases the
/// residual (rounding in the forces) counts as converged.
pub const STALL_TOLERANCE: f64 = 1e-8;
/// The rounding level of the forces, in ulps of the size of their terms, at which a static
/// solve whose Newton step no longer decreases the residual counts as converged.
const ROUNDING_ULPS: f64 = 1e3;
/// The smallest load increment automatic load stepping tries, as a fraction of the load.
pub const MIN_LOAD_INCREMENT: f64 = 1.0 / 1024.0;
/// Newton iterations allowed for one load increment.
const NEWTON_ITERATIONS: usize = 30;
/// Halvings of a Newton step the line search tries before giving up on the increment.
const LINE_SEARCH_HALVINGS: usize = 10;

/// The outcome of Newton iterations for one load increment.
pub(crate) struct NewtonOutcome {
    converged: bool,
    iterations: usize,
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

impl Simulation {
    /// `(df/dx) dx + (df/dv) dv` for vertex vectors in row order (a welded row's result is the
    /// sum over its orbits).
    pub fn jvp(&mut self, dx: &[[f64; 3]], dv: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, PhysicsError> {
        self.set_vertex_vec3("dx", dx)?;
        self.set_vertex_vec3("dv", dv)?;
        let none = Params::new();
        for def in &self.defs {
            for (r, p) in &def.jvp {
                self.rules.apply_everywhere(&mut self.g, r, p)?;
            }
        }
        self.rules
            .apply_everywhere(&mut self.g, "accumulate_jvp", &none)?;
        self.vertex_vec3_sum("df")
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

    pub(crate) fn implicit_euler(&mut self) -> Result<(), PhysicsError> {
        let h = self.cfg.dt;
        let c = self.cfg.damping;
        let (f, m, fixed) = self.total_force()?;
        let v = self.vertex_vec3("velocity")?;
        let zero = vec![[0.0; 3]; v.len()];
        let kv = self.jvp(&v, &zero)?;
        let mut rhs: Vec<[f64; 3]> = f
            .iter()
            .zip(&kv)
            .map(|(f, k)| std::array::from_fn(|a| h * (f[a] + h * k[a])))
            .collect();
        project(&mut rhs, &fixed);
        // A z = (1 + h c) M z - h^2 (df/dx) z - h (df/dv) z
        let solve = self.cg(&rhs, &fixed, |sim, z| {
            let dx: Vec<[f64; 3]> = z.iter().map(|z| z.map(|x| h * h * x)).collect();
            let dv: Vec<[f64; 3]> = z.iter().map(|z| z.map(|x| h * x)).collect();
            let df = sim.jvp(&dx, &dv)?;
            Ok(z.iter()
                .zip(&df)
                .zip(&m)
                .map(|((z, d), m)| std::array::from_fn(|a| (1.0 + h * c) * m * z[a] - d[a]))
                .collect())
        })?;
        let converged = solve.relative <= IMPLICIT_TOLERANCE;
        self.record(SolverReport {
            integrator: "implicit_euler",
            iterations: solve.iterations,
            residual: solve.residual,
            relative_residual: solve.relative,
            tolerance: IMPLICIT_TOLERANCE,
            converged,
            load_steps: 0,
            load_fraction: 1.0,
            worst_relative_residual: 0.0,
            load_stepped_steps: 0,
        });
        if !converged {
            return Err(PhysicsError::Diverged {
                step: self.steps + 1,
                vertex: 0,
                why: format!(
                    "the linear solve of the implicit Euler step did not converge: relative residual {:.3e} above the tolerance {IMPLICIT_TOLERANCE:e} after {} conjugate-gradient iterations; try a smaller dt or a finer mesh (the solve is global: the vertex named is the first)",
                    solve.relative, solve.iterations
                ),
            });
        }
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

    /// Newton iterations on f(x) + `f_ext` + m g = 0 with conjugate gradients on -df/dx and a
    /// backtracking line search on the residual norm; the velocity is set to zero. Converged
    /// when the residual on the free vertices is at most [`STATIC_TOLERANCE`] of the load
    /// (gravity and external loads, or the first residual when prescribed displacements drive
    /// it). When the whole load does not converge in 30 iterations, the load (gravity,
    /// `f_ext` and prescribed displacements) is applied in increments from the last converged
    /// fraction, halving the increment on failure down to [`MIN_LOAD_INCREMENT`].
    /// [`Simulation::solver_report`] then says what happened.
    /// Errors: [`PhysicsError::Diverged`] (the positions before the solve restored) when no
    /// increment converges, with the relative residual, the tolerance and what to try; a
    /// rule's failure other than a non-finite value.
    pub fn solve_static(&mut self) -> Result<(), PhysicsError> {
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
        if !scale.is_finite() {
            return Err(PhysicsError::Diverged {
                step: self.steps + 1,
                vertex: 0,
                why: format!(
                    "the static solve's load overflows: its size is {scale:e} (gravity times mass plus the external loads), beyond what f64 arithmetic can balance; scale the problem (units) or the load down"
                ),
            });
        }
        let tol = STATIC_TOLERANCE * scale;
        // the rounding level of the forces: the stiffness applied to the positions is the
        // size of the forces' terms (at unit strain), each computed to a few ulps
        let zero = vec![[0.0; 3]; n];
        let mut kx = self.jvp(&x0, &zero)?;
        project(&mut kx, &fixed);
        let rounding = ROUNDING_ULPS * f64::EPSILON * norm(&kx);
        let stall = (STALL_TOLERANCE * scale).max(rounding);
        let mut iterations = 0;
        let mut load_steps = 0;
        let (mut s, mut ds) = (0.0f64, 1.0f64);
        let mut good = start;
        // the closest the whole load came to balance (the first attempt is the whole load)
        let (mut best, mut worst) = (f64::INFINITY, 0);
        loop {
            let t = (s + ds).min(1.0);
            let trial = at(t, &good);
            self.set_vertex_vec3("position", &trial)?;
            let out = self.newton(&fixed, &r0, t, (tol, stall))?;
            iterations += out.iterations;
            if t >= 1.0 && out.residual < best {
                best = out.residual;
                worst = out.worst;
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
                ds *= 0.5;
                if ds < MIN_LOAD_INCREMENT {
                    self.set_vertex_vec3("position", &x0)?;
                    let rel = best / scale;
                    self.record(SolverReport {
                        integrator: "static",
                        iterations,
                        residual: best,
                        relative_residual: rel,
                        tolerance: STATIC_TOLERANCE,
                        converged: false,
                        load_steps,
                        load_fraction: s,
                        worst_relative_residual: 0.0,
                        load_stepped_steps: 0,
                    });
                    return Err(PhysicsError::Diverged {
                        step: self.steps + 1,
                        vertex: worst,
                        why: format!(
                            "the static solve did not converge: relative residual {rel:.3e} above the tolerance {STATIC_TOLERANCE:e} after {iterations} Newton iterations with a line search and load stepping down to increments of 1/{} of the load ({:.1}% of the load reached); try a smaller load, a finer mesh, or the integrator implicit_euler to find a dynamic path; the largest residual force is",
                            (1.0 / MIN_LOAD_INCREMENT).round(),
                            100.0 * s
                        ),
                    });
                }
            }
        }
        let res = norm(&self.static_residual(&fixed, None, 1.0)?);
        self.set_vertex_vec3("position", &good)?;
        self.static_base = good;
        self.record(SolverReport {
            integrator: "static",
            iterations,
            residual: res,
            relative_residual: res / scale,
            tolerance: STATIC_TOLERANCE,
            converged: true,
            load_steps,
            load_fraction: 1.0,
            worst_relative_residual: 0.0,
            load_stepped_steps: 0,
        });
        Ok(())
    }

    /// Keeps `r` as the last step's report, with the run's worst relative residual and count
    /// of load-stepped steps carried over from the previous one.
    pub(crate) fn record(&mut self, mut r: SolverReport) {
        let (worst, stepped) = self.report.as_ref().map_or((0.0, 0), |p| {
            (p.worst_relative_residual, p.load_stepped_steps)
        });
        r.worst_relative_residual = worst.max(r.relative_residual);
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
                    residual: f64::INFINITY,
                    worst: 0,
                });
            }
        };
        let mut res = norm(&r);
        let zero = vec![[0.0; 3]; r.len()];
        let mut iterations = 0;
        let done = |converged, iterations, res: f64, r: &[[f64; 3]]| NewtonOutcome {
            converged,
            iterations,
            residual: if res.is_finite() { res } else { f64::INFINITY },
            worst: worst_of(r),
        };
        while iterations < NEWTON_ITERATIONS {
            if res <= tol {
                return Ok(done(true, iterations, res, &r));
            }
            if !res.is_finite() {
                break;
            }
            iterations += 1;
            let du = match self.cg(&r, fixed, |sim, z| {
                Ok(sim.jvp(z, &zero)?.iter().map(|d| d.map(|x| -x)).collect())
            }) {
                Ok(c) => c.x,
                Err(e) => {
                    attempt(e)?;
                    return Ok(done(false, iterations, res, &r));
                }
            };
            let x = self.vertex_vec3("position")?;
            let mut alpha = 1.0;
            let mut accepted = None;
            for _ in 0..=LINE_SEARCH_HALVINGS {
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
                    }
                    Err(e) => attempt(e)?,
                }
                alpha *= 0.5;
            }
            let Some((rt, nt)) = accepted else {
                self.set_vertex_vec3("position", &x)?;
                // the residual may stall at the rounding level of the forces just above the
                // tolerance (small loads on stiff models): close enough when within
                // STALL_TOLERANCE
                return Ok(done(res <= stall, iterations, res, &r));
            };
            r = rt;
            res = nt;
        }
        Ok(done(res <= tol, iterations, res, &r))
    }

    /// Conjugate gradients on `apply`, with fixed vertices' components held at zero; relative
    /// residual 1e-12, at most 10 n iterations; returns the solution, the iterations and the
    /// relative residual reached.
    pub(crate) fn cg(
        &mut self,
        b: &[[f64; 3]],
        fixed: &[bool],
        mut apply: impl FnMut(&mut Self, &[[f64; 3]]) -> Result<Vec<[f64; 3]>, PhysicsError>,
    ) -> Result<CgOutcome, PhysicsError> {
        let n = b.len();
        let dot = |a: &[[f64; 3]], b: &[[f64; 3]]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| x[0] * y[0] + x[1] * y[1] + x[2] * y[2])
                .sum::<f64>()
        };
        let mut x = vec![[0.0; 3]; n];
        let mut r = b.to_vec();
        let mut p = r.clone();
        let mut rr = dot(&r, &r);
        let rr0 = rr;
        let tol = 1e-24 * rr;
        let mut iterations = 0;
        for _ in 0..(10 * 3 * n).max(50) {
            if rr <= tol || rr == 0.0 {
                break;
            }
            iterations += 1;
            let mut ap = apply(self, &p)?;
            project(&mut ap, fixed);
            let pap = dot(&p, &ap);
            if pap <= 0.0 || !pap.is_finite() {
                return Err(PhysicsError::Diverged {
                    step: self.steps + 1,
                    vertex: 0,
                    why: format!("the linear system is not positive definite (p^T A p = {pap:e})"),
                });
            }
            let alpha = rr / pap;
            for i in 0..n {
                for a in 0..3 {
                    x[i][a] += alpha * p[i][a];
                    r[i][a] -= alpha * ap[i][a];
                }
            }
            let rr_new = dot(&r, &r);
            let beta = rr_new / rr;
            rr = rr_new;
            for i in 0..n {
                for a in 0..3 {
                    p[i][a] = r[i][a] + beta * p[i][a];
                }
            }
        }
        Ok(CgOutcome {
            x,
            iterations,
            relative: if rr0 > 0.0 { (rr / rr0).sqrt() } else { 0.0 },
            residual: rr.sqrt(),
        })
    }
}

/// Per vertex: total force, mass, fixed.
pub(crate) type VertexForces = (Vec<[f64; 3]>, Vec<f64>, Vec<bool>);
