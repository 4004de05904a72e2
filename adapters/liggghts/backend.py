"""`mpmdem run --backend liggghts`: write inputs, run LIGGGHTS (1 core), parse the dumps."""
from __future__ import annotations

import shutil
from pathlib import Path

from adapters.common import (check_reached_end, find_binary, package_version, parsing, run_logged, timeout_for,
                             write_provenance)
from adapters.liggghts.parser import parse
from adapters.liggghts.writer import check_supported, write_inputs
from coupler.errors import ReferenceCodeError
from coupler.results import Result
from coupler.scene import Scene


def loop_time(log: Path) -> float:
    """The 'Loop time of T on 1 procs' line of the LIGGGHTS log (the time stepping only)."""
    times = [float(line.split()[3]) for line in log.read_text().splitlines() if line.startswith("Loop time of")]
    return max(times) if times else float("nan")          # the main run (multisphere scenes insert in a 1-step run)


def run(scene: Scene, out_dir: Path, *, progress: bool = False, timeout_s: float | None = None) -> Result:
    """The backend entry (coupler/run.py BACKENDS). progress: not used (LIGGGHTS writes its own log)."""
    check_supported(scene)
    exe = find_binary("liggghts")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for f in ("atoms.dump", "pairs.dump", "bodies.dump"):      # dumps are appended to: never mix two runs
        (out / f).unlink(missing_ok=True)
    facts = write_inputs(scene, out)
    cmd = [exe, "-in", "in.liggghts", "-log", "log.liggghts", "-echo", "none"]
    if shutil.which("stdbuf"):                 # line-buffered: an MPI_Abort otherwise swallows the error message
        cmd = ["stdbuf", "-oL", "-eL"] + cmd
    log = out / "stdout.liggghts"
    wall = run_logged(cmd, out, log.name, timeout_for("liggghts", timeout_s), code="LIGGGHTS")
    screen = log.read_text(errors="replace")
    if "Not all nodes of fix mesh inside simulation box" in screen:      # fix_mesh.cpp deletes such elements
        raise ReferenceCodeError("LIGGGHTS", "deleted mesh elements outside the simulation box", log)
    with parsing("LIGGGHTS", log, out):
        bodies, contacts, energy = parse(scene, out, facts)
        loop = loop_time(out / "log.liggghts")
    check_reached_end("LIGGGHTS", log, list(bodies["t"]) + list(energy["t"]), scene)
    version = package_version("liggghts")
    write_provenance(out, "LIGGGHTS", version, cmd, scene.text_hash, script="in.liggghts", wall_time_s=wall)
    summary = {"scene": scene.name, "backend": "liggghts", "code_version": version, "wall_time_s": wall,
               "loop_time_s": loop,
               "steps": facts["steps"], "dt": facts["dt"], "particles": scene.dem.n_spheres + sum(len(scene.dem.templates[c.template].radii)
                                                                            for c in scene.dem.clusters),
               "energy_note": "elastic and dissipated are not output by LIGGGHTS (NaN); kinetic/potential from dumps",
               "orientation_note": "LIGGGHTS does not integrate sphere orientation: qw..qz of free spheres are NaN; "
                                   "clusters: rotation since t = 0 applied to the scene orientation (P12)"}
    return Result(bodies=bodies, contacts=contacts, energy=energy, summary=summary)
