"""`mpmdem run --backend kratos`: write the Kratos input, run it in a python3 subprocess (1 thread, timeout, log
kept in log.kratos), parse. Kratos comes from PyPI (`pip install .[kratos]`, version in params.KRATOS_VERSION)."""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import sys
from pathlib import Path

from adapters.common import check_reached_end, parsing, run_logged, timeout_for, write_provenance
from adapters.kratos.params import KRATOS_VERSION, check_supported, coupled_step
from adapters.kratos.writer import PROBLEM, write_inputs
from coupler.errors import BackendUnavailable, ReferenceCodeError
from coupler.results import Result
from coupler.scene import Scene

PACKAGES = ("KratosMultiphysics", "KratosDEMApplication", "KratosMPMApplication", "KratosLinearSolversApplication")
PYTHON_VAR = "MPMDEM_KRATOS_PYTHON"     # the Python that runs run_kratos.py (default: this one, sys.executable)
RAW = ("kratos_states.csv", "kratos_forces.csv", "kratos_particles.csv", "kratos_series.csv", "kratos_energy.csv",
       "kratos_interface.csv")


def kratos_version() -> str:
    """The installed KratosMultiphysics version (BackendUnavailable when it is not importable)."""
    if importlib.util.find_spec("KratosMultiphysics") is None:
        raise BackendUnavailable("Kratos is not installed (pip install '.[kratos]': KratosMultiphysics, "
                                 f"KratosDEMApplication, KratosMPMApplication ... =={KRATOS_VERSION})")
    from importlib.metadata import PackageNotFoundError, version
    try:
        return "KratosMultiphysics " + version("KratosMultiphysics")
    except PackageNotFoundError:
        return "KratosMultiphysics unknown"


def kratos_python() -> str:
    """The interpreter of the Kratos subprocess: $MPMDEM_KRATOS_PYTHON (a Python with Kratos installed elsewhere,
    or a fake in the adapter tests), else sys.executable."""
    return os.environ.get(PYTHON_VAR) or sys.executable


def _run_kratos(out: Path, timeout_s: float | None, steps: int) -> tuple[list[str], float, dict]:
    """Run run_kratos.py in out (log.kratos); its timing record, checked against the steps asked for."""
    cmd = [kratos_python(), "run_kratos.py"]
    log = out / "log.kratos"
    wall = run_logged(cmd, out, log.name, timeout_for("kratos", timeout_s), code="Kratos")
    with parsing("Kratos", log, out):
        timing = json.loads((out / "timing_kratos.json").read_text())
        made = int(timing["steps"])
        float(timing["loop_time_s"])
    if made != steps:
        raise ReferenceCodeError("Kratos", f"made {made} steps, {steps} were asked", log)
    return cmd, wall, timing


def available() -> tuple[bool, str]:
    try:
        kratos_version()
    except BackendUnavailable as e:
        return False, str(e)
    return True, ""


def run(scene: Scene, out_dir: Path, *, progress: bool = False, timeout_s: float | None = None,
        initial_velocity: tuple[str, str] | None = None, snapshot_every: int | None = None,
        stress_free_start: bool = False, coupling_dt: float | None = None, friction: str | None = None) -> Result:
    """The backend entry (coupler/run.py BACKENDS). progress: not used (Kratos writes its own log).
    initial_velocity: MPM material-point velocity field (vx, vy) as expressions of x, y (writer.write_inputs),
    for cases whose initial state is not a uniform body velocity (the elastic bar); snapshot_every: MPM particle
    snapshot every that many output times, bodies and energy at every one (default: the scene's
    output.particles_interval); friction: the substitute for a friction wall (params.FRICTION_SUBSTITUTES; refused
    without)."""
    check_supported(scene, stress_free_start, friction)
    # a coupled scene's step, refused before Kratos is looked for
    dt = coupled_step(scene, coupling_dt) if scene.coupling is not None else None
    version = kratos_version()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for f in RAW:
        (out / f).unlink(missing_ok=True)
    if scene.coupling is not None:
        return _run_coupled(scene, out, version, dt, timeout_s)
    if snapshot_every is None:
        snapshot_every = scene.output.snapshot_stride(scene.time.output_interval)
    facts = write_inputs(scene, out, initial_velocity, snapshot_every, stress_free_start, friction)
    cmd, wall, timing = _run_kratos(out, timeout_s, facts["steps"])
    for d in out.glob(f"{PROBLEM}_*"):                   # Kratos' own GiD post files and graphs: not used
        if d.is_dir() and d.name.endswith(("_Post_Files", "_Graphs", "_MPI_results", "_Results_and_Data")):
            shutil.rmtree(d)
    (out / f"{PROBLEM}.post.lst").unlink(missing_ok=True)
    summary = {"scene": scene.name, "backend": "kratos", "code_version": version, "wall_time_s": wall,
               "loop_time_s": timing["loop_time_s"], "steps": facts["steps"], "dt": facts["dt"]}
    if facts["kind"] == "dem":
        from adapters.kratos.parser import check_damping, parse_dem
        with parsing("Kratos", out / "log.kratos", out):
            gam = check_damping(out)
            bodies, contacts, energy, extra = parse_dem(scene, out, facts)
        check_reached_end("Kratos", out / "log.kratos", list(bodies["t"]) + list(energy["t"]), scene)
        summary.update(particles=scene.dem.n_spheres, kratos_damping_gamma=gam,
                       kratos_restitution={f"{p['a']}-{p['b']}": p["restitution_kratos"] for p in facts["pairs"]},
                       integration="Symplectic_Euler", **extra,
                       energy_note="elastic and dissipated not read back from Kratos (NaN); kinetic/potential "
                                   "from the states",
                       orientation_note="Kratos sphere orientation is not read back: qw..qz are NaN")
        particles = []
    else:
        from adapters.kratos.parser import parse_mpm
        with parsing("Kratos", out / "log.kratos", out):
            mpm_bodies, contacts, energy, particles, extra = parse_mpm(scene, out, facts)
        summary.update(extra)
    write_provenance(out, "Kratos Multiphysics", version, cmd, scene.text_hash,
                     **({"kratos_damping_gamma": summary["kratos_damping_gamma"]} if facts["kind"] == "dem" else {}))
    if facts["kind"] == "dem":
        return Result(bodies=bodies, contacts=contacts, energy=energy, summary=summary, particles=particles)
    return Result(contacts=contacts, energy=energy, summary=summary, particles=particles, mpm_bodies=mpm_bodies)


def _run_coupled(scene: Scene, out: Path, version: str, dt: float, timeout_s: float | None) -> Result:
    """Coupled scene through CoSimulationApplication (adapters/kratos/cosim.py): write, run, parse."""
    from adapters.kratos.cosim import write_coupled
    from adapters.kratos.parser import parse_coupled
    facts = write_coupled(scene, out, dt)
    cmd, wall, timing = _run_kratos(out, timeout_s, facts["steps"])
    for d in out.iterdir():                                # Kratos' own post files and graphs: not used
        if d.is_dir() and d.name.endswith(("_Post_Files", "_Graphs", "_MPI_results", "_Results_and_Data")):
            shutil.rmtree(d)
        elif d.name.endswith(".post.lst"):
            d.unlink()
    with parsing("Kratos", out / "log.kratos", out):
        bodies, mpm_bodies, energy, particles, iface, extra = parse_coupled(scene, out, facts)
    summary = {"scene": scene.name, "backend": "kratos", "code_version": version, "wall_time_s": wall,
               "loop_time_s": timing["loop_time_s"], "steps": facts["steps"], "dt": dt,
               "kratos_restitution": {f"{p['a']}-{p['b']}": p["restitution_kratos"] for p in facts["pairs"]},
               **extra}
    write_provenance(out, "Kratos Multiphysics", version, cmd, scene.text_hash)
    return Result(bodies=bodies, energy=energy, summary=summary, particles=particles, mpm_bodies=mpm_bodies,
                  interface=iface)
