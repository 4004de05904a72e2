"""Issue 17, "bad input, systematically": a property-based test (hypothesis, derandomized) that mutates valid scenes
of every kind (DEM spheres / clusters / meshes / rolling laws / gravity schedule, explicit and implicit MPM, coupled)
and checks that every mutation either leaves a valid scene or ends in exactly one SceneError line naming the field,
never another exception (a traceback); plus a handful through the real CLI (exit 2, one stderr line, no run).

Mutations: wrong types, missing keys, negative / zero / huge values, NaN and infinity, empty lists, unknown keys,
unknown materials / laws / names, bodies outside [domain], a mesh file that does not exist or cannot be read.
A mutation that cannot be valid (NaN, infinity, a wrong type, an unknown key or name, a body outside the domain, a
bad mesh file) must raise; the others (a deleted key, zero, a negative number, an empty list) may load.
"""
from __future__ import annotations

import copy
import math
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from coupler.errors import SceneError
from coupler.scene import parse_scene
from tests.conftest import CASES, ROOT, edit, scene_toml

# valid scene files of every kind (each parses in a few ms)
FILES = {
    "dem_pair": "dem_hertz_impact/pair.toml",
    "dem_clusters": "dem_block_drop/block.toml",
    "dem_rolling": "dem_rolling/rolling.toml",
    "dem_mesh": "xval_impacts/mesh.toml",
    "dem_tilt": "dem_block_tip/tilt.toml",
    "mpm_explicit": "mpm_elastic_bar/scene.toml",
    "mpm_implicit": "mpm_bui_implicit/scene.toml",
    "coupled": "coupled_resting_load/scene.toml",
    "coupled_free": "coupled_free_collision/scene.toml",
}

# a DEM scene with a [domain], a lattice, a packing and a mesh wall read from a file (no validation case has these)
STL = """solid floor
facet normal 0 1 0
outer loop
vertex -0.02 0 -0.02
vertex 0.02 0 0.02
vertex 0.02 0 -0.02
endloop
endfacet
facet normal 0 1 0
outer loop
vertex -0.02 0 -0.02
vertex -0.02 0 0.02
vertex 0.02 0 0.02
endloop
endfacet
endsolid floor
"""
DOMAIN_SCENE = scene_toml("""[domain]
min = [-0.05, -0.01, -0.05]
max = [0.05, 0.1, 0.05]
[dem]
[[dem.spheres]]
name = "a"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.0026, 0.0]
velocity = [0.0, -1.0, 0.0]
[[dem.lattices]]
name = "grid"
material = "aluminium"
radius = 1e-3
origin = [-0.01, 0.02, -0.01]
counts = [2, 2, 2]
spacing = 3e-3
[[dem.packings]]
name = "pack"
material = "aluminium"
radius = 1e-3
box_min = [0.0, 0.04, 0.0]
box_max = [0.01, 0.05, 0.01]
count = 5
[[dem.meshes]]
name = "floor"
material = "aluminium"
file = "floor.stl"
""")


def _raw_scenes(tmp: Path) -> dict[str, tuple[dict, Path]]:
    out = {k: (tomllib.loads(Path(CASES, f).read_text()), Path(CASES, f).parent) for k, f in FILES.items()}
    (tmp / "floor.stl").write_text(STL)
    out["dem_domain_meshfile"] = (tomllib.loads(DOMAIN_SCENE), tmp)
    return out


TMP = Path(os.environ.get("PYTEST_TMP_BAD_INPUT", "/tmp")) / f"mpmdem_bad_input_{os.getpid()}"
TMP.mkdir(parents=True, exist_ok=True)
SCENES = _raw_scenes(TMP)


def _sites(node, path=()):
    """Every value of a raw scene with its path (keys and list indices), depth first."""
    yield path, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _sites(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _sites(v, path + (i,))


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _parent(raw, path):
    node = raw
    for k in path[:-1]:
        node = node[k]
    return node


def _mutations(path, value) -> list[tuple[str, object, bool]]:
    """(kind, new value or DELETE, must_fail) for one site."""
    key = next((k for k in reversed(path) if isinstance(k, str)), "")
    out: list[tuple[str, object, bool]] = []
    if path:
        out.append(("delete", DELETE, False))
    if _is_num(value):
        out += [("nan", math.nan, True), ("inf", math.inf, True), ("-inf", -math.inf, True),
                ("zero", 0, False), ("negative", -abs(value) - 1.0, False), ("huge", 1e300, False),
                ("wrong type", "not a number", True), ("fraction", 2.5, False)]
    elif isinstance(value, bool):
        out += [("wrong type", "yes", True), ("wrong type", 1, True)]
    elif isinstance(value, str):
        out += [("wrong type", [1, 2], True), ("empty string", "", False)]
        if key not in ("name",):          # a name may be any string; everything else names something
            out.append(("unknown name", "unobtainium_xyz", True))
    elif isinstance(value, list):
        out += [("empty list", [], False), ("wrong type", "text", True), ("wrong type", 3.5, True),
                ("short list", value[:1], False)]
    elif isinstance(value, dict):
        if path:
            out.append(("wrong type", 7.0, True))
        out.append(("unknown key", ADD_KEY, True))
    return out


DELETE = object()
ADD_KEY = object()


def _apply(raw, path, new):
    raw = copy.deepcopy(raw)
    if new is ADD_KEY:
        node = raw
        for k in path:
            node = node[k]
        node["bogus_key"] = 1.0
        return raw
    parent = _parent(raw, path)
    if new is DELETE:
        del parent[path[-1]]
    else:
        parent[path[-1]] = new
    return raw


def _label(path) -> str:
    s = ""
    for k in path:
        s += f"[{k}]" if isinstance(k, int) else (f".{k}" if s else str(k))
    return s


def check_one(scene: str, path, kind: str, new, must_fail: bool) -> None:
    raw0, base = SCENES[scene]
    raw = _apply(raw0, path, new)
    where = f"{scene}: {kind} at {_label(path) or '<root>'}"
    try:
        parse_scene(raw, default_name="mutated", base_dir=base)
    except SceneError as e:
        msg = f"error: {e}"
        assert "\n" not in msg, f"{where}: the error is not one line: {msg!r}"
        assert e.path, f"{where}: the error names no field: {msg!r}"
        keys = [k for k in path if isinstance(k, str)]
        if kind == "outside the domain":      # names the body and the bounds (coupler/dem/scene.py check_in_domain)
            keys = ["domain"]
        if must_fail and keys and kind != "unknown key":
            # the field named is the mutated one or one of its tables (a cross-field check may name the table)
            assert any(k in msg for k in keys), f"{where}: the error does not name the field: {msg!r}"
        if kind == "unknown key":
            assert "bogus_key" in msg, f"{where}: the unknown key is not named: {msg!r}"
        return
    except Exception as e:  # the hole this test is for: a traceback instead of a one-line error
        raise AssertionError(f"{where}: {type(e).__name__} instead of a SceneError: {e}") from e
    assert not must_fail, f"{where}: the scene loaded (a run would start)"


def test_every_single_mutation_of_every_site():
    """Exhaustive: each mutation kind at each site of each scene (about 4,500 loads, a few seconds). Every hole is
    listed, not only the first."""
    holes = []
    for scene, (raw, _) in SCENES.items():
        for path, value in _sites(raw):
            for kind, new, must_fail in _mutations(path, value):
                try:
                    check_one(scene, path, kind, new, must_fail)
                except AssertionError as e:
                    holes.append(str(e).splitlines()[0])
    assert not holes, f"{len(holes)} mutations not refused with a one-line SceneError:\n" + "\n".join(holes)


@settings(max_examples=300, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.data())
def test_chains_of_mutations_are_a_one_line_scene_error_or_a_valid_scene(data):
    """hypothesis: one to four mutations applied in turn to one scene (each at a site of the already mutated
    scene); the result loads or is one SceneError line naming a field, never another exception."""
    scene = data.draw(st.sampled_from(sorted(SCENES)), label="scene")
    raw, base = SCENES[scene]
    done = []
    for _ in range(data.draw(st.integers(1, 4), label="mutations")):
        path, value = data.draw(st.sampled_from(list(_sites(raw))))
        kind, new, _ = data.draw(st.sampled_from(_mutations(path, value)))
        raw = _apply(raw, path, new)
        done.append(f"{kind} at {_label(path) or '<root>'}")
    try:
        parse_scene(raw, default_name="mutated", base_dir=base)
    except SceneError as e:
        assert "\n" not in str(e) and e.path, f"{scene}: {done}: {e!r}"
    except Exception as e:
        raise AssertionError(f"{scene}: {done}: {type(e).__name__} instead of a SceneError: {e}") from e


# -- targeted cases the random walk may not reach: the domain, the mesh file, unknown laws ---------------------------
@pytest.mark.parametrize("path,new", [
    (("dem", "spheres", 0, "position"), [1.0, 0.0026, 0.0]),               # a sphere outside [domain]
    (("dem", "lattices", 0, "origin"), [-0.01, 0.02, 0.06]),               # a lattice leaving it in z
    (("dem", "packings", 0, "box_max"), [0.01, 0.5, 0.01]),                # a packing box beyond it
    (("domain", "max"), [0.05, 0.001, 0.05]),                              # the domain shrunk under the bodies
])
def test_bodies_outside_the_domain(path, new):
    check_one("dem_domain_meshfile", path, "outside the domain", new, True)


@pytest.mark.parametrize("content", [None, "", "this is not a mesh\n", b"\x00\xff\x10binary garbage", "dir"])
def test_mesh_file_missing_or_unreadable(content, tmp_path):
    raw = copy.deepcopy(SCENES["dem_domain_meshfile"][0])
    p = tmp_path / "floor.stl"
    if content == "dir":
        p.mkdir()
    elif isinstance(content, bytes):
        p.write_bytes(content)
    elif content is not None:
        p.write_text(content)
    with pytest.raises(SceneError) as e:
        parse_scene(raw, base_dir=tmp_path)
    assert e.value.path == "dem.meshes[0].file" and "\n" not in str(e.value), str(e.value)


@pytest.mark.parametrize("scene,path,new", [
    ("dem_pair", ("contacts", 0, "damping"), "viscous"),
    ("dem_rolling", ("contacts", 0, "rolling", "model"), "sticky"),
    ("dem_pair", ("contacts", 0, "normal"), "hooke"),                      # hooke without its stiffness
    ("mpm_implicit", ("mpm", "bodies", 0, "constitutive", "model"), "cam_clay"),
    ("mpm_explicit", ("mpm", "shape_function"), "cubic"),
    ("coupled", ("coupling", "mapper"), "rbf"),
    ("coupled", ("coupling", "material"), "unobtainium"),
    ("coupled", ("coupling", "body"), "rock"),
])
def test_unknown_laws_and_names(scene, path, new):
    check_one(scene, path, "unknown law", new, True)


# -- the real command line: exit 2, one stderr line naming the field, no run ------------------------------------------
BASE = Path(CASES, "dem_hertz_impact", "pair.toml").read_text()
MPM = Path(CASES, "mpm_elastic_bar", "scene.toml").read_text()
COUPLED = Path(CASES, "coupled_resting_load", "scene.toml").read_text()


@pytest.mark.parametrize("text,field", [
    (edit(BASE, "young = 70e9", "young = nan"), "materials.aluminium.young"),
    (edit(BASE, 'material = "aluminium"', 'material = "unobtainium"'), "dem.spheres[0].material"),
    (edit(MPM, "cell_size = 0.01", 'cell_size = "fine"'), "mpm.grid.cell_size"),
    (edit(MPM, "particles_per_cell = 2", "particles_per_cell = -inf"), "mpm.bodies[0].particles_per_cell"),
    (DOMAIN_SCENE.replace('file = "floor.stl"', 'file = "no_such_mesh.stl"'), "dem.meshes[0].file"),
    (edit(DOMAIN_SCENE, "position = [0.0, 0.0026, 0.0]", "position = [0.0, 0.0026, 0.07]"), "domain"),
    (edit(COUPLED, "thickness = 0.04", "thicknes = 0.04"), "coupling.thicknes"),
], ids=["nan", "unknown-material", "wrong-type", "-inf-integer", "no-mesh-file", "outside-domain", "unknown-key"])
def test_cli_bad_scene_exit_2_one_line(text, field, tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text(text)
    (tmp_path / "floor.stl").write_text(STL)
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(scene), "--out", str(out), "--quiet"],
                       capture_output=True, text=True, cwd=ROOT, timeout=300,
                       env=dict(os.environ, PYTHONPATH=ROOT))
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2, (p.returncode, p.stderr[-2000:])
    assert len(lines) == 1 and lines[0].startswith(f"error: {field}"), p.stderr
    assert not out.exists(), "a run started (its output folder was made)"
