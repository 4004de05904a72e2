"""`mpmdem run --backend yade`: write the script, run `yade -n -x -j1` (one at a time), parse."""
from __future__ import annotations

import json
from pathlib import Path

from adapters.common import (check_reached_end, exclusive, find_binary, package_version, parsing, run_logged,
                             timeout_for, write_provenance)
from adapters.yade.params import check_supported
from adapters.yade.parser import parse
from adapters.yade.writer import write_inputs
from coupler.results import Result
from coupler.scene import Scene


SAMPLING = ("after the contact forces of x(t), before NewtonIntegrator: positions x(t), contact rows of x(t), "
            "velocities v(t) = YADE's leapfrog v(t - dt/2) + a(t) dt/2 (gyroscopic term of clump spin left out), "
            "as the native velocity Verlet; the leapfrog starts from v(-dt/2) = v(0) - a(0) dt/2 so that the trajectory "
            "is the native one (adapters/yade/writer.py start, record)")


def run(scene: Scene, out_dir: Path, *, progress: bool = False, timeout_s: float | None = None) -> Result:
    """The backend entry (coupler/run.py BACKENDS). progress: not used (YADE writes its own log)."""
    check_supported(scene)
    exe = find_binary("yade")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    facts = write_inputs(scene, out)
    cmd = [exe, "-n", "-x", "-j1", "run_yade.py"]
    log = out / "log.yade"
    with exclusive("yade"):                       # YADE opens fixed local ports even with -n
        wall = run_logged(cmd, out, log.name, timeout_for("yade", timeout_s), code="YADE")
    with parsing("YADE", log, out):
        bodies, contacts, energy = parse(scene, out)
        timing = json.loads((out / "timing_yade.json").read_text())
        loop = float(timing["loop_time_s"])
    check_reached_end("YADE", log, list(bodies["t"]) + list(energy["t"]), scene)
    version = package_version("yade")
    write_provenance(out, "YADE", version, cmd, scene.text_hash, betan=facts["beta_pairs"], sampling=SAMPLING,
                     script="run_yade.py", wall_time_s=wall)
    summary = {"scene": scene.name, "backend": "yade", "code_version": version, "wall_time_s": wall,
               "loop_time_s": loop,
               "steps": facts["steps"], "dt": facts["dt"], "particles": scene.dem.n_spheres + sum(len(scene.dem.templates[c.template].radii) for c in scene.dem.clusters),
               "betan": facts["beta_pairs"],
               "p4_dropped_contact_steps": timing.get("p4_dropped_contact_steps", 0),
               "energy_note": "elastic and dissipated not recorded from YADE (NaN); kinetic/potential from states "
                              "(spheres and clumps)",
               "sampling": SAMPLING}
    return Result(bodies=bodies, contacts=contacts, energy=energy, summary=summary)
