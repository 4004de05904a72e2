"""Scene: everything a run needs, loaded from one TOML file and validated.

A scene declares only the physics it uses: a `[dem]` table builds the DEM, an `[mpm]` table the MPM, a
`[coupling]` table the coupler. Every error names the field path and the allowed range.

Layout of a scene file (all SI units; 2D = x-y plane, gravity along -y)::

    name = "sphere_wall"          # optional, defaults to the file stem
    dimension = 3                 # 2 (plane strain / planar motion) or 3
    gravity = [0.0, -9.81, 0.0]
    seed = 1

    [time]
    t_end = 1e-4
    dt = 1e-8                     # optional: computed from the stable limit when absent
    output_interval = 1e-7

    [materials.aluminium]
    density = 2700.0
    young = 70e9
    poisson = 0.33

    [[contacts]]                  # one per material pair that can touch
    materials = ["aluminium", "aluminium"]
    restitution = 0.8
    friction = 0.3

    [dem]
    [[dem.spheres]] / [[dem.lattices]] / [[dem.packings]] / [[dem.planes]]

Materials and contact laws are parsed in `coupler/materials.py`; the physics tables in the module that SECTIONS
(below) names for each: `[dem]` in `coupler/dem/scene.py`, `[mpm]` in `coupler/mpm/scene.py`, `[coupling]` in
`coupler/coupling/scene.py`. This module never imports them (they import it): a new section is one SECTIONS row.
"""
from __future__ import annotations

import hashlib
import importlib
import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from coupler.errors import SceneError
from coupler.fields import Table
# Material, ContactLaw, pair_key, rayleigh_time are defined in coupler/materials.py; importing them from here
# (tests, older code) keeps working.
from coupler.materials import ContactLaw, Material, pair_key, parse_contacts, parse_materials, rayleigh_time

__all__ = ["TimeSpec", "OutputSpec", "Scene", "Section", "SECTIONS", "section_types", "load_scene", "loads_scene",
           "parse_scene", "check_material", "output_stride", "Material", "ContactLaw", "pair_key", "rayleigh_time"]


@dataclass(frozen=True)
class Section:
    """One physics table of a scene and the module that parses it (loaded by name when the table is present).

    `<module>.<parse>(table, scene, base_dir)` returns the section object, an instance of `<module>.<type_name>`,
    stored as `Scene.<table name>`; after all tables are read `<module>.<finish>(scene)` (optional) runs the
    cross-section checks. `missing` is the SceneError message when this version has no such module.
    """
    module: str
    parse: str
    type_name: str
    finish: str | None = None
    missing: str = ""


# The ONE table of scene sections, in parse order (coupling last: it refers to the DEM and MPM sections).
SECTIONS: dict[str, Section] = {
    "dem": Section("coupler.dem.scene", "parse_dem", "DEMScene", finish="finish_dem"),
    "mpm": Section("coupler.mpm.scene", "parse_mpm", "MPMScene",
                   missing="the native MPM is not available in this version (issue #6)"),
    "coupling": Section("coupler.coupling.scene", "parse_coupling", "CouplingScene",
                        missing="MPM-DEM coupling is not available in this version"),
}


def _section_module(name: str):
    """The module parsing section `name`, or None when this version does not have it."""
    sec = SECTIONS[name]
    try:
        return importlib.import_module(sec.module)
    except ModuleNotFoundError as e:
        if not (sec.module + ".").startswith(f"{e.name}."):   # the module exists, one of ITS imports is missing
            raise
        return None


def section_types() -> dict[str, type]:
    """The section classes named in the `Scene.dem/mpm/coupling` annotations, for the sections this version has;
    `typing.get_type_hints(Scene, localns=section_types())` resolves the annotations."""
    out = {}
    for name, sec in SECTIONS.items():
        mod = _section_module(name)
        if mod is not None:
            out[sec.type_name] = getattr(mod, sec.type_name)
    return out


@dataclass(frozen=True)
class TimeSpec:
    t_end: float
    dt: float | None
    output_interval: float
    dt_safety: float = 0.4


@dataclass(frozen=True)
class OutputSpec:
    bodies: bool = True
    contacts: bool = True
    energy: bool = True
    vtk: bool = False          # ParaView series under <out>/vtk/ (coupler/vtk.py), from the result tables
    # MPM snapshots (particles_<n>.csv) every `particles_interval` seconds, a multiple of time.output_interval
    # (default: at every output time); the first and the last output time always have one
    particles_interval: float | None = None

    def snapshot_stride(self, output_interval: float) -> int:
        """Output times per MPM snapshot: particles_interval / output_interval (1 without it)."""
        return 1 if self.particles_interval is None else int(round(self.particles_interval / output_interval))

    def snapshot_at(self, n: int, output_interval: float, last: bool = False) -> bool:
        """Whether output time n (0 = the first) takes an MPM snapshot: every particles_interval and the last."""
        return last or n % self.snapshot_stride(output_interval) == 0


@dataclass
class Scene:
    name: str
    dimension: int
    gravity: np.ndarray
    seed: int
    time: TimeSpec
    materials: dict[str, Material]
    contacts: dict[tuple[str, str], ContactLaw]
    output: OutputSpec = field(default_factory=OutputSpec)
    domain: tuple[np.ndarray, np.ndarray] | None = None
    # The physics sections, typed with the classes SECTIONS names (coupler.dem.scene.DEMScene, ...). The section
    # modules import this one, so the names are resolved through the registry, not imported: section_types().
    dem: DEMScene | None = None
    mpm: MPMScene | None = None
    coupling: CouplingScene | None = None
    source: Path | None = None
    # optional piecewise-linear gravity: rows (t, gx, gy, gz), constant before the first and after the last row;
    # `gravity` is then the final value. A slowly tilted incline ("tilting table") is written this way.
    gravity_schedule: np.ndarray | None = None

    def gravity_at(self, t: float) -> np.ndarray:
        """Gravity vector at time t [m/s^2]."""
        if self.gravity_schedule is None:
            return self.gravity
        s = self.gravity_schedule
        return np.array([np.interp(t, s[:, 0], s[:, k]) for k in (1, 2, 3)])

    @property
    def gravity_max(self) -> float:
        """Largest gravity magnitude over the run (time-step and energy scales)."""
        if self.gravity_schedule is None:
            return float(np.linalg.norm(self.gravity))
        return float(np.linalg.norm(self.gravity_schedule[:, 1:], axis=1).max())
    text_hash: str = ""

    def contact_law(self, a: str, b: str) -> ContactLaw:
        return self.contacts[pair_key(a, b)]


def load_scene(path: str | Path, overrides: dict[str, Any] | None = None, name: str | None = None) -> Scene:
    """Read and validate a scene file. Raises SceneError (never a bare traceback) for bad input.

    overrides: variants of one scene file, as dotted paths, e.g. {"contacts[0].restitution": 0.5,
    "dem.spheres[0].velocity": [0, -2, 0]}; they are part of the scene hash.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise SceneError(str(path), f"cannot read scene file: {e.strerror}") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(str(path), f"not valid TOML: {e}") from None
    for key, value in (overrides or {}).items():
        _set_path(raw, key, value)
    if name is not None:
        raw["name"] = name
    scene = parse_scene(raw, default_name=path.stem, base_dir=path.parent)
    scene.source = path
    extra = json.dumps(overrides or {}, sort_keys=True, default=str) + (name or "")
    scene.text_hash = hashlib.sha256((text + extra).encode()).hexdigest() if overrides or name else \
        hashlib.sha256(text.encode()).hexdigest()
    return scene


def _set_path(raw: dict, dotted: str, value: Any) -> None:
    """Set raw["a"]["b"][2]["c"] from "a.b[2].c" (override of a scene variant)."""
    parts: list[str | int] = []
    for piece in dotted.split("."):
        while "[" in piece:
            head, rest = piece.split("[", 1)
            if head:
                parts.append(head)
            idx, piece = rest.split("]", 1)
            parts.append(int(idx))
        if piece:
            parts.append(piece)
    node: Any = raw
    for k in parts[:-1]:
        try:
            node = node[k]
        except (KeyError, IndexError, TypeError):
            raise SceneError(dotted, "override path does not exist in the scene file") from None
    node[parts[-1]] = value


def loads_scene(text: str, name: str = "scene", base_dir: Path | None = None) -> Scene:
    """Parse a scene from TOML text (tests, generated variants)."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError("<scene>", f"not valid TOML: {e}") from None
    scene = parse_scene(raw, default_name=name, base_dir=base_dir or Path.cwd())
    scene.text_hash = hashlib.sha256(text.encode()).hexdigest()
    return scene


def _gravity_schedule(t: Table, dim: int) -> np.ndarray | None:
    """gravity_schedule = [[t0, gx, gy, gz], [t1, ...], ...] with t0 >= 0 and strictly increasing times."""
    raw = t.raw_value("gravity_schedule", None)
    if raw is None:
        return None
    try:
        arr = np.array(raw, dtype=float)
    except (TypeError, ValueError):
        raise SceneError("gravity_schedule", "must be a list of [t, gx, gy, gz] rows of numbers") from None
    if arr.ndim != 2 or arr.shape[1] != 4 or len(arr) < 2:
        raise SceneError("gravity_schedule", f"must be at least two [t, gx, gy, gz] rows, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise SceneError("gravity_schedule", "must be finite numbers")
    if arr[0, 0] < 0.0 or np.any(np.diff(arr[:, 0]) <= 0.0):
        raise SceneError("gravity_schedule", "times (first column) must be >= 0 and strictly increasing")
    if dim == 2 and np.any(arr[:, 3] != 0.0):
        raise SceneError("gravity_schedule", "gz (fourth column) must be 0 in a 2D scene (x-y plane)")
    return arr


def parse_scene(raw: dict, default_name: str = "scene", base_dir: Path | None = None) -> Scene:
    t = Table(raw, "")
    name = t.string("name", default_name)
    dim = t.integer("dimension", 3)
    if dim not in (2, 3):
        raise SceneError("dimension", f"must be 2 or 3, got {dim}")
    gravity = t.vector("gravity", 3, [0.0, -9.81, 0.0])
    if dim == 2 and gravity[2] != 0.0:
        raise SceneError("gravity[2]", f"must be 0 in a 2D scene (x-y plane), got {gravity[2]:g}")
    schedule = _gravity_schedule(t, dim)
    if schedule is not None:
        if t.has("gravity"):
            raise SceneError("gravity_schedule", "give either gravity or gravity_schedule, not both")
        gravity = schedule[-1, 1:].copy()
    seed = t.integer("seed", 0, ge=0)

    tt = t.table("time")
    time = TimeSpec(
        t_end=tt.number("t_end", gt=0.0),
        dt=tt.number("dt", None, gt=0.0),
        output_interval=tt.number("output_interval", gt=0.0),
        dt_safety=tt.number("dt_safety", 0.4, gt=0.0, le=1.0),
    )
    tt.done()
    if time.output_interval > time.t_end:
        raise SceneError("time.output_interval", f"must be <= time.t_end ({time.t_end:g}), got {time.output_interval:g}")

    materials = parse_materials(t)
    contacts = parse_contacts(t, materials)

    ot = t.table("output", {})
    output = OutputSpec(bodies=ot.boolean("bodies", True), contacts=ot.boolean("contacts", True),
                        energy=ot.boolean("energy", True), vtk=ot.boolean("vtk", False),
                        particles_interval=ot.number("particles_interval", None, gt=0.0))
    ot.done()
    if output.particles_interval is not None:
        oi, pi = time.output_interval, output.particles_interval
        r = pi / oi
        if r < 1.0 - 1e-9 or abs(r - round(r)) > 1e-6 * r:
            raise SceneError("output.particles_interval", f"must be a multiple of time.output_interval ({oi:g} s), "
                                                          f"got {pi:g}")

    domain = None
    if t.has("domain"):
        dt_ = t.table("domain")
        lo, hi = dt_.vector("min", 3), dt_.vector("max", 3)
        dt_.done()
        for k in range(dim):
            if not hi[k] > lo[k]:
                raise SceneError(f"domain.max[{k}]", f"must be > domain.min[{k}] ({lo[k]:g}), got {hi[k]:g}")
        domain = (lo, hi)

    scene = Scene(name=name, dimension=dim, gravity=gravity, gravity_schedule=schedule, seed=seed, time=time, materials=materials,
                  contacts=contacts, output=output, domain=domain)

    base = base_dir or Path.cwd()
    for key, sec in SECTIONS.items():
        if t.has(key):
            mod = _section_module(key)
            if mod is None:
                raise SceneError(key, sec.missing or f"the [{key}] section is not available in this version")
            setattr(scene, key, getattr(mod, sec.parse)(t.table(key), scene, base))
    t.done()
    if scene.dem is None and scene.mpm is None:
        raise SceneError("<scene>", "declares no physics: add a [dem] and/or an [mpm] table")
    if output.particles_interval is not None and scene.mpm is None:
        raise SceneError("output.particles_interval", "sets the MPM snapshots; a scene without [mpm] has none")
    if scene.domain is not None and scene.dem is None:
        raise SceneError("domain", "bounds the DEM bodies (their leave-the-domain check); a scene without [dem] is "
                                   "bounded by mpm.grid")

    for key, sec in SECTIONS.items():
        if sec.finish and getattr(scene, key) is not None:
            getattr(_section_module(key), sec.finish)(scene)
    return scene


def output_stride(scene: Scene, dt: float, what: str = "the time step") -> int:
    """Steps between two output times: round(output_interval / dt). An output_interval shorter than the step
    cannot be met (it used to be raised to dt silently): a SceneError naming both."""
    oi = scene.time.output_interval
    if oi < dt * (1.0 - 1e-9):
        raise SceneError("time.output_interval", f"must be >= {what} dt = {dt:.6g} s (one output per step at most), "
                                                 f"got {oi:g}")
    return max(1, int(round(oi / dt)))


def check_material(scene: Scene, path: str, name: Any) -> Material:
    if not isinstance(name, str) or name not in scene.materials:
        raise SceneError(path, f"unknown material {name!r} (defined: {', '.join(sorted(scene.materials)) or 'none'})")
    return scene.materials[name]

