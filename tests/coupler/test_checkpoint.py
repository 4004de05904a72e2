"""Run checkpoints (coupler/checkpoint.py, `mpmdem run --checkpoint-every N` / `--resume`): a run resumed from its
last checkpoint writes tables bitwise equal to the run that was not stopped (DEM with clusters, explicit and implicit
MPM, coupled); what a stopped run left after the checkpoint is cut away; a checkpoint of another scene, a missing
one, another backend, a negative interval, modified Newton and a YADE partition are refused with one line naming
the flag; the ParaView files of a resumed run carry the same data to the tables' digits; a run killed mid-way
resumes; and no solver holds two arrays sharing memory (pickle would copy them apart and a resumed run diverge)."""
from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import time
import types
from pathlib import Path

import numpy as np
import pytest

from coupler.checkpoint import FILE, Restart, read_pickle
from coupler.errors import SceneError
from coupler.run import run_scene
from coupler.scene import load_scene

CASES = Path(__file__).resolve().parents[2] / "validation" / "cases"
# (scene file, overrides, checkpoint interval in output times): short versions of the cases' scenes
SCENES = {
    "dem_clusters": (CASES / "dem_wall_stack" / "wall.toml", {"time.t_end": 0.1, "output.contacts": True}, 3),
    "mpm_explicit": (CASES / "mpm_elastic_bar" / "scene.toml", {"time.t_end": 0.02}, 7),
    "mpm_implicit": (CASES / "mpm_bui_implicit" / "scene.toml", {"time.t_end": 0.35}, 2),
    "coupled": (CASES / "coupled_free_collision" / "scene.toml", {}, 5),
}
# scene text added to a kind's file (the free collision has no [output] section: its contact rows are asked here)
EXTRA = {"coupled": "\n[output]\ncontacts = true\n"}


def scene_of(kind: str, tmp_path: Path, **over):
    """The kind's scene with its overrides (and `over`), from a copy carrying EXTRA where the kind has one."""
    path, base, _ = SCENES[kind]
    if kind in EXTRA:
        copy = tmp_path / f"{kind}.toml"
        copy.write_text(path.read_text() + EXTRA[kind])
        path = copy
    return load_scene(path, overrides={**base, **over})


def tables(d: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.glob("*.csv"))}


@pytest.mark.parametrize("kind", list(SCENES))
def test_resumed_run_writes_the_same_tables(kind, tmp_path):
    """Run a: uninterrupted. Run b: the same with checkpoints; then b's folder is left as a run killed after its
    last checkpoint would leave it (a half-written row on every table, a snapshot file past the checkpoint) and
    resumed: every table (bodies, contacts, energy, MPM bodies and snapshots, interface series) bitwise a's."""
    every = SCENES[kind][2]
    scene = scene_of(kind, tmp_path)
    ra = run_scene(scene, tmp_path / "a", progress=False)
    b = tmp_path / "b"
    run_scene(scene, b, progress=False, restart=Restart(every=every))
    ck, _ = read_pickle(b / FILE)
    assert 0 < ck["t"] < scene.time.t_end and ck["step"] > 0
    for p in b.glob("*.csv"):
        with open(p, "a") as f:
            f.write("0.1234,garbage")
    n_snap = len(list(b.glob("particles_*.csv")))
    (b / f"particles_{n_snap}.csv").write_text("x,y\n1,2\n")
    res = run_scene(scene, b, progress=False, restart=Restart(resume=True))
    assert res.summary["checkpoints"]["resumed_from"]["t"] == ck["t"]
    ta, tb = tables(tmp_path / "a"), tables(b)
    assert sorted(ta) == sorted(tb)
    assert [n for n in ta if ta[n] != tb[n]] == []
    assert len(ta) >= 3
    # the returned tables are whole too (the rows of the segment before the checkpoint read back from disk)
    for name in ("bodies", "contacts", "energy", "mpm_bodies"):
        assert len(getattr(res, name)) == len(getattr(ra, name)), name
    assert len(res.particles) == len(ra.particles)
    if kind in ("dem_clusters", "coupled"):
        assert len(ra.contacts) > 0


@pytest.mark.parametrize("kind", ["dem_clusters", "coupled"])
def test_checkpoint_does_not_hold_the_tables(kind, tmp_path):
    """What a checkpoint holds beside the solvers grows by the energy and log rows only (a few hundred bytes per
    output time), not by the body, contact or interface rows, which stay on disk (Checkpoints.earlier): the same
    scene run twice as long gives a checkpoint whose run-loop part grew by less than 400 bytes per extra output
    time, while one output time's body and contact rows take more than that."""
    sizes, per_output = [], 0
    for f in (1, 2):
        scene = scene_of(kind, tmp_path, **{"time.t_end": f * scene_of(kind, tmp_path).time.t_end})
        d = tmp_path / str(f)
        res = run_scene(scene, d, progress=False, restart=Restart(every=1))
        ck, state = read_pickle(d / FILE)
        rest = {k: v for k, v in state.items() if k not in ("solver", "run", "sol")}
        sizes.append((len(pickle.dumps(rest, protocol=5)), ck["n_outputs"]))
        on_disk = sum((d / n).stat().st_size for n in ("bodies.csv", "contacts.csv", "interface.csv",
                                                       "interface_series.csv", "interface_wall.csv")
                      if (d / n).exists())
        per_output = on_disk / res.energy["t"].nunique()
    (s1, n1), (s2, n2) = sizes
    assert n2 > n1 + 2
    growth = (s2 - s1) / (n2 - n1)
    assert growth < 400.0 < per_output, (growth, per_output)


def test_a_killed_run_resumes(tmp_path):
    """`mpmdem run --checkpoint-every 50` on two threads killed (SIGKILL) once a checkpoint exists, then `--resume`
    on one thread: the tables are those of the uninterrupted two-thread run (the MPM's results are the same bits on
    any thread count; if the run ended before the kill, the resume redoes its last segment)."""
    scene = CASES / "mpm_elastic_bar" / "scene.toml"
    cli = [sys.executable, "-m", "coupler.cli", "run", str(scene), "--quiet"]
    two, one = ({**os.environ, "NUMBA_NUM_THREADS": n} for n in ("2", "1"))
    subprocess.run(cli + ["--out", str(tmp_path / "a")], check=True, env=two, capture_output=True)
    b = tmp_path / "b"
    proc = subprocess.Popen(cli + ["--out", str(b), "--checkpoint-every", "50"], env=two,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while not (b / FILE).exists() and proc.poll() is None and time.time() - t0 < 120:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    r = subprocess.run(cli + ["--out", str(b), "--resume"], env=one, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    ta, tb = tables(tmp_path / "a"), tables(b)
    assert sorted(ta) == sorted(tb) and [n for n in ta if ta[n] != tb[n]] == []


def test_refusals(tmp_path):
    """One line naming the flag: no checkpoint, another scene's checkpoint, a reference backend, every < 0."""
    path, over, every = SCENES["mpm_explicit"]
    scene = load_scene(path, overrides=over)
    with pytest.raises(SceneError, match="--resume: no checkpoint"):
        run_scene(scene, tmp_path / "x", progress=False, restart=Restart(resume=True))
    run_scene(scene, tmp_path / "x", progress=False, restart=Restart(every=every))
    other = load_scene(path, overrides={**over, "time.t_end": 0.03})
    with pytest.raises(SceneError, match="--resume: .* another scene file"):
        run_scene(other, tmp_path / "x", progress=False, restart=Restart(resume=True))
    header, _ = read_pickle(tmp_path / "x" / FILE)      # other code: refused by the header, before its classes load
    with open(tmp_path / "x" / FILE, "wb") as f:
        pickle.dump({**header, "key": {**header["key"], "code": "0" * 64}}, f)
        f.write(b"\x80\x05cno_such_module\nSolver\n.")     # a body naming a class this code does not have
    with pytest.raises(SceneError, match="--resume: .* another code"):
        run_scene(scene, tmp_path / "x", progress=False, restart=Restart(resume=True))
    run_scene(scene, tmp_path / "x", progress=False)      # a fresh run in the folder removes the old checkpoint
    assert not (tmp_path / "x" / FILE).exists()
    with pytest.raises(SceneError, match="--checkpoint-every: only the native backend"):
        run_scene(scene, tmp_path / "y", backend="liggghts", progress=False, restart=Restart(every=1))
    with pytest.raises(SceneError, match="--checkpoint-every: must be >= 0"):
        Restart(every=-1)
    ipath, iover, _ = SCENES["mpm_implicit"]        # modified Newton's kept LU factor is not saved
    modified = load_scene(ipath, overrides={**iover, "mpm.implicit.reuse_ratio": 0.1})
    with pytest.raises(SceneError, match="--checkpoint-every: .*not with modified Newton"):
        run_scene(modified, tmp_path / "m", progress=False, restart=Restart(every=1))
    cpath, cover, _ = SCENES["coupled"]             # YADE's state lives in its process
    yade = load_scene(cpath, overrides={**cover, "coupling.dem_partition": "yade"})
    with pytest.raises(SceneError, match="--checkpoint-every: .*dem_partition = 'yade'"):
        run_scene(yade, tmp_path / "c", progress=False, restart=Restart(every=1))
    r = subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(path), "--out", str(tmp_path / "z"),
                        "--resume"], capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "--resume" in r.stderr


def _arrays(o, path: str, seen: set, out: dict) -> None:
    """Every numpy array reachable from o (attributes, dict / list / tuple items), by path; the scene (read only
    during a run) is left out."""
    if id(o) in seen or isinstance(o, (str, bytes, int, float, bool, type(None), type, types.FunctionType)):
        return
    seen.add(id(o))
    if isinstance(o, np.ndarray):
        out[path] = o
    elif isinstance(o, dict):
        for k, v in o.items():
            _arrays(v, f"{path}[{k!r}]", seen, out)
    elif isinstance(o, (list, tuple)):
        for i, v in enumerate(o):
            _arrays(v, f"{path}[{i}]", seen, out)
    elif hasattr(o, "__dict__"):
        for k, v in vars(o).items():
            if k != "scene":
                _arrays(v, f"{path}.{k}", seen, out)


def _shared(o) -> set:
    found: dict[str, np.ndarray] = {}
    _arrays(o, "run", set(), found)
    items = [(k, a) for k, a in found.items() if a.size]
    return {(a, b) for i, (a, x) in enumerate(items) for b, y in items[i + 1:]
            if np.may_share_memory(x, y) and np.shares_memory(x, y)}


@pytest.mark.parametrize("kind", ["dem_clusters", "mpm_implicit", "coupled"])
def test_no_solver_arrays_share_memory(kind):
    """Pickle copies two arrays sharing memory apart (a view and its base become two arrays): a solver holding
    such a pair continues differently after a resume unless its __setstate__ joins them again. The only pairs
    allowed are the DEM meshes' views into the packed mesh arrays, and they share memory again after a pickle
    round trip (DEMSolver.__setstate__); any other pair is a defect."""
    from coupler.coupling.solver import CoupledRun
    from coupler.dem.solver import DEMSolver
    from coupler.mpm.solver import MPMSolver
    path, over, _ = SCENES[kind]
    run = {"dem_clusters": DEMSolver, "mpm_implicit": MPMSolver, "coupled": CoupledRun}[kind](
        load_scene(path, overrides=over))
    before = _shared(run)
    assert all(".meshes[" in a + b and "._M[" in a + b for a, b in before), sorted(before)
    assert _shared(pickle.loads(pickle.dumps(run, protocol=5))) == before
    if kind == "coupled":
        assert before          # the coupled wall is a mesh: its views exist


def test_resumed_paraview_series_match(tmp_path):
    """With `[output] vtk = true` the ParaView files of a resumed run carry the same data as the uninterrupted run's
    to the tables' 10 significant digits (the contacts before the checkpoint are read back from contacts.csv): the
    wall forces, matched to the output times within those digits, are there and not zero."""
    import meshio
    text = (CASES / "dem_wall_stack" / "wall.toml").read_text().replace("[output]\n", "[output]\nvtk = true\n", 1)
    path = tmp_path / "wall_vtk.toml"
    path.write_text(text)
    scene = load_scene(path, overrides={"time.t_end": 0.1, "output.contacts": True})
    a, b = tmp_path / "a", tmp_path / "b"
    run_scene(scene, a, progress=False)
    run_scene(scene, b, progress=False, restart=Restart(every=3))
    run_scene(scene, b, progress=False, restart=Restart(resume=True))
    files = sorted(p.relative_to(a) for p in (a / "vtk").glob("*.vtu"))
    assert files and sorted(p.relative_to(b) for p in (b / "vtk").glob("*.vtu")) == files
    seen_force = False
    for p in files:
        ma, mb = meshio.read(a / p), meshio.read(b / p)
        assert np.allclose(ma.points, mb.points, rtol=1e-9, atol=1e-12)
        for k in ma.cell_data:
            for xa, xb in zip(ma.cell_data[k], mb.cell_data[k]):
                assert np.allclose(xa, xb, rtol=1e-9, atol=0.0), (p, k)
                seen_force |= k == "force" and bool(np.any(np.asarray(xa) != 0.0))
    assert seen_force
