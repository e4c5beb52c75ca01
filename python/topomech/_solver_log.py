"""The per-step reports of the linear and nonlinear solves of a run (``solver.csv`` and the
``solver`` entry of ``summary.json``; see :func:`topomech.run.run_scene`).

After every ``static`` or ``implicit_euler`` step, :meth:`SolverLog.after_step` keeps the
step's :meth:`Simulation.solver_report`; :meth:`SolverLog.write` writes them as
``solver.csv``, one row a step; :meth:`SolverLog.summary` sums them up. A step whose solve did
not reach its tolerance (an implicit Euler step whose conjugate gradients stopped at
``max_iterations``) is counted and raises one :class:`SolverWarning` at the end of the run
(the command line prints it as a note).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from topomech.simulation import Simulation

#: The columns of ``solver.csv``, in order.
COLUMNS = (
    "step",
    "time",
    "integrator",
    "linear_solver",
    "preconditioner",
    "iterations",
    "linear_iterations",
    "residual",
    "relative_residual",
    "tolerance",
    "converged",
    "load_steps",
    "jacobian",
)


class SolverWarning(UserWarning):
    """A solve that did not reach its tolerance (the run went on with what it found); the
    command line prints it as a note."""


class SolverLog:
    """The solver reports of a run's steps (empty for the explicit integrators)."""

    def __init__(self) -> None:
        self.rows: list[dict[str, Any]] = []

    def after_step(self, sim: Simulation, *, failed: bool = False) -> None:
        """Keeps the report of the step just taken, or (``failed``) of the step that failed
        (the simulation's state is the one before it); nothing for the explicit
        integrators."""
        r = sim.solver_report()
        if r is None:
            return
        self.rows.append(
            {
                "failed": failed,
                "step": sim.steps + 1 if failed else sim.steps,
                "time": sim.time,
                "integrator": r["integrator"],
                "linear_solver": r.get("linear_solver", "cg"),
                "preconditioner": r.get("preconditioner", "none"),
                "iterations": r["iterations"],
                "linear_iterations": r.get("linear_iterations", r["iterations"]),
                "residual": r["residual"],
                "relative_residual": r["relative_residual"],
                "tolerance": r["tolerance"],
                "converged": bool(r["converged"]),
                "load_steps": r["load_steps"],
                "jacobian": r.get("jacobian", "rules"),
            }
        )

    def write(self, path: Path) -> bool:
        """Writes ``solver.csv`` (False, nothing written, when no step solved anything).
        Raises :class:`OSError` when it cannot be written."""
        if not self.rows:
            return False
        with path.open("w", newline="", encoding="utf-8") as f:
            w = csv.DictWriter(f, fieldnames=COLUMNS)
            w.writeheader()
            for row in self.rows:
                w.writerow({k: _cell(row[k]) for k in COLUMNS})
        return True

    def not_converged(self) -> list[int]:
        """The steps whose solve did not reach its tolerance."""
        return [r["step"] for r in self.rows if not r["converged"]]

    def summary(self, last: dict[str, Any] | None) -> dict[str, Any] | None:
        """The ``solver`` entry of ``summary.json``: the last step's report ``last`` (None for
        the explicit integrators) with the run's totals: ``steps_solved``,
        ``steps_not_converged``, ``total_iterations``, ``total_linear_iterations``,
        ``mean_linear_iterations`` (per step) and ``max_relative_residual``."""
        if last is None:
            return None
        out = dict(last)
        rows = self.rows
        linear = sum(int(r["linear_iterations"]) for r in rows)
        finite = [r["relative_residual"] for r in rows if math.isfinite(r["relative_residual"])]
        out.update(
            steps_solved=len(rows),
            steps_not_converged=len(self.not_converged()),
            total_iterations=sum(int(r["iterations"]) for r in rows),
            total_linear_iterations=linear,
            mean_linear_iterations=linear / len(rows) if rows else 0.0,
            max_relative_residual=max(finite) if finite else None,
        )
        return out

    def warning(self) -> str | None:
        """The message of the run's :class:`SolverWarning`, or None when every solve
        converged."""
        taken = [r for r in self.rows if not r["converged"] and not r["failed"]]
        if not taken:
            return None  # a failed step is the run's error, not a warning
        worst = max(taken, key=lambda r: r["relative_residual"])
        bad = [r["step"] for r in taken]
        first = ", ".join(str(s) for s in bad[:5]) + (", ..." if len(bad) > 5 else "")
        used = worst["linear_solver"]
        others = " or ".join(f'"{x}"' for x in ("pcg", "direct") if x != used)
        return (
            f"the linear solve ({used}) did not reach its tolerance in {len(bad)} of "
            f"{len(self.rows)} steps (steps {first}; worst relative residual "
            f"{worst['relative_residual']:.3e} against {worst['tolerance']:g} at step "
            f"{worst['step']}, after {worst['linear_iterations']} iterations); those steps "
            f"used the approximate solution found: raise integrator.max_iterations, use "
            f"linear_solver = {others}, or a smaller dt (per-step figures: solver.csv)"
        )


def _cell(v: Any) -> Any:
    if isinstance(v, bool):
        return int(v)
    if isinstance(v, float):
        return repr(v)
    return v
