"""Time split of the implicit MPM per Newton iteration (issue 18 asks for assembly / solve / update): from a
solver's .stats and the wall time of the block they cover.

  assembly: numba residual (+ tangent) evaluations, incl. their numpy inertia / friction terms (evaluate);
  solve:    Newton matrix into LAPACK band storage (kernels.to_band) + banded LU (gbtrf), `factor`, and the
            back-substitution (gbtrs); SuperLU / gmres for the other linear solvers;
  update:   P2G, dof numbering, stencil groups and constraints at the start of a step, G2P / commit at its end;
  python:   the rest of the wall time (Newton / line-search / active-set logic in solver.py).
Used by bench.bench_implicit (`python -m coupler.mpm.implicit.bench [h]`)."""
from __future__ import annotations

TIMERS = ("assembly_s", "solve_s", "factor_s", "update_s")


def reset(stats: dict) -> None:
    """Zero the timers, counters and the Newton-iteration list of ImplicitMPMSolver.stats (start of a block)."""
    for k in TIMERS:
        stats[k] = 0.0
    stats["newton_iterations"].clear()
    for k in stats["assemblies"]:
        stats["assemblies"][k] = 0


def split(stats: dict, wall: float) -> dict:
    """ms per Newton iteration: total, assembly, solve (of it factor), update, python (= wall - the timed parts)."""
    n = max(1, int(sum(stats["newton_iterations"])))
    ms = 1e3 / n
    a, s, f, u = (stats[k] for k in TIMERS)
    return {"newton_iterations": n, "total_ms": wall * ms, "assembly_ms": a * ms, "solve_ms": s * ms,
            "factor_ms": f * ms, "update_ms": u * ms, "python_ms": (wall - a - s - u) * ms,
            "assemblies_per_iteration": {k: v / n for k, v in stats["assemblies"].items()}}

