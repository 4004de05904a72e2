"""The Bui collapse in Kratos MPM (adapters/kratos, map in params.py): the case's scene at a cell size h, with the
Kratos step KRATOS_DT, stress-free start (the geostatic stress is not expressible in Kratos: params.py) and the rough
base written no-slip (FRICTION; Kratos' Coulomb wall cannot express it: params.py). Stored in
reference_runs/mpm_bui_collapse/kratos/h<h>mm/ with provenance (store(h); `python3 -m
validation.cases.mpm_bui_collapse.kratos_runs 20 10 5` from the repository root), read back by the case (stored()),
rerun with --live."""
from __future__ import annotations

import json
import os
import shutil
import sys
import time
from pathlib import Path

from coupler.scene import Scene, load_scene

CASE_DIR = Path(__file__).resolve().parent
# Kratos step: the native explicit step (CFL 0.5 of the P-wave: 2.4e-4 s at h = 10 mm, 1.2e-4 s at 5 mm), the
# adapter's default. Tried dt = 5e-4 s at h = 10 mm: the Newton did not converge (20 iterations, every step).
SIZES = (0.02, 0.01, 0.005)   # stored Kratos cell sizes [m]
SNAPSHOT_EVERY = 1        # particle snapshot every output time (0.1 s)
FRICTION = "fixed"        # the rough base (Coulomb mu = 0.36) in Kratos: no-slip, as Kratos' own granular_flow_2D
#                           example; Kratos 10.4.4's Coulomb wall caps the friction at mu x the normal force summed
#                           over the Newton iterations and creeps every step (adapters/kratos/params.py, measured)


def variant(h: float, variant_of: str | None = None) -> str:
    return f"h{h * 1000:g}mm" + (f"_{variant_of}" if variant_of else "")


DIAGNOSTIC = {"fixed_base": {"mpm.boundary.bottom": {"kind": "fixed"}}}   # variants that are NOT the case's scene


def kratos_scene(h: float, base: Scene | None = None, t_end: float | None = None, variant_of: str | None = None) -> Scene:
    """The case scene at h for Kratos; variant_of: a DIAGNOSTIC variant (e.g. the no-slip base instead of the
    friction base, to separate Kratos' friction condition from the rest)."""
    base = base or load_scene(CASE_DIR / "scene.toml")
    ov = {"mpm.grid.cell_size": h, **(DIAGNOSTIC[variant_of] if variant_of else {})}
    if t_end is not None:                    # a short run: at most one output interval, so it has a last frame
        ov["time.t_end"] = t_end
        ov["time.output_interval"] = min(base.time.output_interval, t_end)
    return load_scene(base.source, overrides=ov)


def run_kratos(scene: Scene, out: Path, timeout_s: float = 4 * 3600):
    from adapters.kratos.backend import run
    return run(scene, out, stress_free_start=True, friction=FRICTION, snapshot_every=SNAPSHOT_EVERY,
               timeout_s=timeout_s)


def store(h: float, variant_of: str | None = None):
    """Run Kratos at cell size h and store the run with provenance (script, version, scene hash, wall time,
    MP-steps/s, Newton iterations)."""
    from validation.references import RAW_OUTPUTS, compress_tables, stored_dir
    scene = kratos_scene(h, variant_of=variant_of)
    out = stored_dir("mpm_bui_collapse", "kratos", variant(h, variant_of))
    if out.exists():
        shutil.rmtree(out)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    res = run_kratos(scene, out)
    load1 = os.getloadavg()
    wall = time.perf_counter() - t0
    res.summary.setdefault("scene_hash", scene.text_hash)
    res.write(out)
    for f in RAW_OUTPUTS:
        (out / f).unlink(missing_ok=True)
    compress_tables(out)
    prov = json.loads((out / "provenance.json").read_text())
    s = res.summary
    prov.update(script="validation/cases/mpm_bui_collapse/kratos_runs.py store(h) -> adapters/kratos/backend.run "
                       f"(stress_free_start=True, friction={FRICTION!r})", cell_size=h, dt=s["dt"], steps=s["steps"],
                particles=s["particles"], wall_time_s=wall, kratos_loop_time_s=s["loop_time_s"],
                mp_steps_per_s=s["particles"] * s["steps"] / s["loop_time_s"],
                newton_iterations_total=s.get("newton_iterations_total"),
                newton_iterations_mean=s.get("newton_iterations_mean"),
                newton_iterations_max=s.get("newton_iterations_max"),
                newton_steps_not_converged=(out / "log.kratos").read_text(errors="replace").count(
                    "max iterations (20) exceeded"),
                machine=(f"2 cores shared with other jobs; load average (1/5/15 min) {load0[0]:.1f}/{load0[1]:.1f}/"
                         f"{load0[2]:.1f} at the start, {load1[0]:.1f}/{load1[1]:.1f}/{load1[2]:.1f} at the end: "
                         f"wall time an upper bound"),
                initial_stress_note=s.get("initial_stress_note"), friction_note=s.get("friction_note"))
    (out / "provenance.json").write_text(json.dumps(prov, indent=2) + "\n")
    return res


def stored(h: float, scene: Scene, variant_of: str | None = None):
    """The stored Kratos run at h (None, why) when missing or made for another scene text."""
    from coupler.results import Result
    from validation.references import REFERENCE_DIR, stored_dir
    d = stored_dir("mpm_bui_collapse", "kratos", variant(h, variant_of))
    if not (d / "summary.json").exists():
        return None, f"no stored Kratos run in {d.relative_to(REFERENCE_DIR.parent)}", {}
    prov = json.loads((d / "provenance.json").read_text())
    if prov.get("scene_hash") != scene.text_hash:
        return None, f"stored Kratos run in {d.relative_to(REFERENCE_DIR.parent)} is for another scene text", prov
    return Result.read(d), "", prov


if __name__ == "__main__":
    for a in sys.argv[1:]:
        h, _, var = a.partition(":")
        r = store(float(h) / 1000.0, var or None)
        print(a, "mm:", json.dumps({k: r.summary.get(k) for k in ("wall_time_s", "steps", "particles",
                                                                  "newton_iterations_mean")}), flush=True)
