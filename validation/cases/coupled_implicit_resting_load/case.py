"""Coupled resting load with the IMPLICIT MPM as the MPM partition (issue 18): a DEM block resting on an elastic
MPM block, weak Gauss-Seidel coupling, the DEM sub-cycling inside each implicit MPM step. The same checks as
coupled_resting_load (its evaluate() runs on this folder's scene): the load the MPM receives = the block weight per
unit depth (0.1 %), the settlement = that of the same implicit MPM under the same loads applied directly (1 %),
the interface force balance. Notes: Newton iterations of the implicit MPM, DEM sub-steps per MPM step.

Last measured (2026-12-01, loaded machine): load 320.510 vs 320.518 N/m (-0.002 %, pass), force balance 2.7e-16
(pass), settlement 0.2180 vs 0.2109 mm direct (+3.3 %, FAILS the 1 %); with gamma = 0.9 the settlement error grows
to +7.5 % (load still -0.008 %), so it is not a transient left at t_end: the weak coupling at the implicit step
(37 DEM sub-steps per MPM step) leaves a systematic settlement difference that is not understood yet (open)."""
from __future__ import annotations

from validation.cases.coupled_resting_load import case as _resting

TITLE = "Coupled resting load, IMPLICIT MPM partition (Newmark + Newton, DEM sub-cycled per implicit step)"
FULL_ONLY = False


def evaluate(ctx):
    import json
    _resting.evaluate(ctx)
    p = ctx.out_dir / "coupled" / "summary.json"
    if p.exists():
        s = json.loads(p.read_text())
        c = s.get("coupling", {})
        keys = ("mpm_scheme", "coupling_dt", "dem_substeps", "dem_dt", "mpm_steps", "newton_iterations_mean",
                "newton_iterations_max", "step_cuts", "time_assembly_s", "time_solve_s", "time_update_s")
        ctx.notes.append("run summary: " + ", ".join(f"{k} = {c[k]}" for k in keys if k in c))
