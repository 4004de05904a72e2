"""`mpmdem run --backend liggghts`: write inputs, run LIGGGHTS (1 core), parse the dumps."""
from __future__ import annotations

from pathlib import Path

from adapters.common import find_binary, package_version, run_logged, write_provenance
from adapters.liggghts.parser import parse
from adapters.liggghts.writer import check_supported, write_inputs
from coupler.results import Result
from coupler.scene import Scene


def loop_time(log: Path) -> float:
    """The 'Loop time of T on 1 procs' line of the LIGGGHTS log (the time stepping only)."""
    for line in log.read_text().splitlines():
        if line.startswith("Loop time of"):
            return float(line.split()[3])
    return float("nan")


def run(scene: Scene, out_dir: Path, timeout_s: float | None = None) -> Result:
    check_supported(scene)
    exe = find_binary("liggghts")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for f in ("atoms.dump", "pairs.dump"):
        (out / f).unlink(missing_ok=True)
    facts = write_inputs(scene, out)
    cmd = [exe, "-in", "in.liggghts", "-log", "log.liggghts", "-echo", "none"]
    wall = run_logged(cmd, out, "stdout.liggghts", timeout_s or 3600)
    bodies, contacts, energy = parse(scene, out, facts)
    version = package_version("liggghts")
    write_provenance(out, "LIGGGHTS", version, cmd, scene.text_hash)
    summary = {"scene": scene.name, "backend": "liggghts", "code_version": version, "wall_time_s": wall,
               "loop_time_s": loop_time(out / "log.liggghts"),
               "steps": facts["steps"], "dt": facts["dt"], "particles": scene.dem.n_spheres,
               "energy_note": "elastic and dissipated are not output by LIGGGHTS (NaN); kinetic/potential from dumps",
               "orientation_note": "LIGGGHTS does not integrate sphere orientation: qw..qz are NaN"}
    return Result(bodies=bodies, contacts=contacts, energy=energy, summary=summary)
