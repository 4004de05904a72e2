"""The cantilever scene through Kratos CoSimulation (adapters/kratos/cosim.py) at two coupling steps: KRATOS_DT
(2e-3 s, the step of Kratos' own mpm_dem test) and NATIVE_DT (2e-4 s, the native scene's coupling step). Stored in
reference_runs/coupled_kratos_cantilever/kratos/<variant>/ with provenance
(`python3 -m validation.cases.coupled_kratos_cantilever.kratos_run`), read back by the case, rerun with --live."""
from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

from coupler.scene import Scene, load_scene

CASE_DIR = Path(__file__).resolve().parent
KRATOS_DT = 2e-3
NATIVE_DT = 2e-4
VARIANTS = {"cantilever": KRATOS_DT, "cantilever_dt2e-4": NATIVE_DT}     # stored variant -> Kratos coupling step
VARIANT = "cantilever"


def scene() -> Scene:
    return load_scene(CASE_DIR / "scene.toml")


def run_kratos(sc: Scene, out: Path, dt: float = KRATOS_DT):
    from adapters.kratos.backend import run
    return run(sc, out, coupling_dt=dt, timeout_s=3600)


def store(variant: str = VARIANT):
    from validation.references import RAW_OUTPUTS, compress_tables, stored_dir
    sc = scene()
    dt = VARIANTS[variant]
    out = stored_dir("coupled_kratos_cantilever", "kratos", variant)
    if out.exists():
        shutil.rmtree(out)
    machine = (f"{os.cpu_count()} cores, 1-min load average {os.getloadavg()[0]:.1f} at the start (wall time an "
               f"upper bound when loaded)")
    t0 = time.perf_counter()
    res = run_kratos(sc, out, dt)
    wall = time.perf_counter() - t0
    res.summary.setdefault("scene_hash", sc.text_hash)
    res.write(out)
    for f in RAW_OUTPUTS + ("kratos_interface.csv",):
        (out / f).unlink(missing_ok=True)
    for d in out.iterdir():
        if d.is_dir() and d.name.endswith(("_Post_Files", "_Graphs")):
            shutil.rmtree(d)
        elif d.name.endswith(".post.lst"):
            d.unlink()
    compress_tables(out)
    prov = json.loads((out / "provenance.json").read_text())
    prov.update(script="validation/cases/coupled_kratos_cantilever/kratos_run.py store() -> adapters/kratos/backend.run"
                       f" (coupling_dt={dt})", wall_time_s=wall, kratos_loop_time_s=res.summary["loop_time_s"],
                steps=res.summary["steps"], dt=dt, machine=machine)
    (out / "provenance.json").write_text(json.dumps(prov, indent=2) + "\n")
    return res


def stored(sc: Scene, variant: str = VARIANT):
    from coupler.results import Result
    from validation.references import REFERENCE_DIR, stored_dir
    d = stored_dir("coupled_kratos_cantilever", "kratos", variant)
    if not (d / "summary.json").exists():
        return None, f"no stored Kratos run in {d.relative_to(REFERENCE_DIR.parent)}", {}
    prov = json.loads((d / "provenance.json").read_text())
    if prov.get("scene_hash") != sc.text_hash:
        return None, f"stored Kratos run in {d.relative_to(REFERENCE_DIR.parent)} is for another scene text", prov
    return Result.read(d), "", prov


if __name__ == "__main__":
    import sys
    for v in sys.argv[1:] or list(VARIANTS):
        r = store(v)
        print(v, json.dumps({k: r.summary.get(k) for k in ("wall_time_s", "steps", "particles")}))
