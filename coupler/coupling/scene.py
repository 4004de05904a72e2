"""The `[coupling]` table of a scene (MPM-DEM coupling; the scene needs both [dem] and [mpm], dimension = 2).

    [coupling]
    body = "soil"                 # the [[mpm.bodies]] name whose outline is the interface
    sides = ["top"]               # rectangle bodies: any of bottom, right, top, left; or
    segments = [2, 3]             # outline edge indices (edge i joins polygon vertices i and i + 1);
                                  # neither: the whole outline (closed)
    material = "soil_wall"        # DEM material standing for the MPM soil in the wall contact (the interface
                                  # wall carries its stiffness); needs [[contacts]] with the DEM materials
    scheme = "gauss_seidel_weak"  # schemes/ registry
    mapper = "nearest"            # nearest | linear (mappers/ registry)
    predictor = "constant"        # wall velocity within a coupling step: "constant" (default: the MPM interface
                                  # velocity of the step start) | "linear" (extrapolated to the step end,
                                  # 2 v_n - v_(n-1): removes the first-order wall-lag energy error on the DEM
                                  # side; explicit extrapolation, unstable at large coupling steps)
    dt = 1e-4                     # optional coupling step = MPM step [s] (> 0; explicit MPM: <= the CFL limit
                                  # cell_size / P-wave speed); default the MPM's own step (mpm.cfl), or for
                                  # the explicit MPM the interface contact's stable step if that is smaller
                                  # (coupling/step_limit.py; summary: coupling_dt_limited_by)
    dem_substeps = 10             # DEM steps per coupling step (integer >= 1) or "auto" (default):
                                  # ceil(coupling step / DEM default step), the DEM step is dt / dem_substeps
    thickness = 0.1               # out-of-plane depth [m] one DEM layer represents (> 0): forces into the MPM
                                  # are divided by it (N per unit depth), a DEM body of mass M stands for
                                  # M / thickness kg per metre of depth
    dem_partition = "native"      # the DEM side: "native" (default) or "yade" (YADE in its own process,
                                  # adapters/yade/partition.py); partitions.py DEM_PARTITIONS
    wall_spacing = 0.05           # optional: DEM wall nodes at this spacing along the interface instead of at
                                  # the boundary particles (needs mapper = "linear" for exact rigid motions)
    [[coupling.motion]]           # motion SCHEDULE of a DEM cluster (several phases, e.g. held, then pushed);
    body = "wall", kind = "fixed" | "velocity", velocity = [vx, vy, 0], start = t0 (default 0),
    until = t1 (default: end); several entries per body with disjoint [start, until); outside them: free.
    Each phase is set through DEMSolver.set_body_motion at the coupling step it starts in (start / until must be
    multiples of the coupling step). A single phase from t = 0 belongs in [[dem.clusters]] motion = {kind,
    velocity, angular_velocity, until} (the DEM solver's own prescription); the solver's motion has one phase
    and then frees the body, so a fixed-then-moved wall needs this schedule. A cluster takes one or the other.

The MPM needs `mpm.boundary_particles = true` (the interface points) and `time.dt` must be absent (the two steps
are set here). The interface wall is added to the DEM scene as mesh `interface` (a scene may not use that name).
A DEM sphere may not start overlapping the selected outline by more than `dem.max_initial_overlap` of its radius
(start_overlap; the wall's own cut of the outline's corners is reported in summary.json).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from coupler.coupling.interface import InterfaceGeometry, build_interface
from coupler.coupling.mappers import MAPPERS
from coupler.coupling.partitions import DEM_PARTITIONS
from coupler.coupling.schemes import PREDICTORS, SCHEMES
from coupler.errors import SceneError
from coupler.fields import Table
from coupler.scene import check_material

RECT_SIDES = ("bottom", "right", "top", "left")     # MPM rectangle outline edge order (coupler/mpm/scene.py)
WALL_NAME = "interface"
MOTION_KINDS = ("fixed", "velocity")


@dataclass(frozen=True)
class Motion:
    body: str
    kind: str
    velocity: np.ndarray
    start: float
    until: float


@dataclass
class CouplingScene:
    body: str
    body_index: int
    edges: list
    material: str
    scheme: str
    mapper: str
    dt: float | None
    dem_substeps: int | None        # None: automatic
    thickness: float
    wall_spacing: float | None
    geometry: InterfaceGeometry
    wall_name: str = WALL_NAME
    motions: list = field(default_factory=list)
    dem_partition: str = "native"
    predictor: str = "constant"
    start_overlap: dict = field(default_factory=dict)   # the DEM spheres' t = 0 overlap with the interface wall


def parse_coupling(t: Table, scene, base_dir: Path) -> CouplingScene:
    if scene.dem is None or scene.mpm is None:
        raise SceneError("coupling", "a [coupling] table needs both a [dem] and an [mpm] table")
    ms = scene.mpm
    names = [b.name for b in ms.bodies]
    body = t.string("body")
    if body not in names:
        raise SceneError(t.sub("body"), f"unknown MPM body {body!r} (defined in [mpm]: {', '.join(names)})")
    bi = names.index(body)
    if not ms.boundary_particles:
        raise SceneError("mpm.boundary_particles", "must be true in a coupled scene (the interface points)")
    if scene.time.dt is not None:
        raise SceneError("time.dt", "not used in a coupled scene: the coupling step is coupling.dt (default: the "
                                    "MPM CFL step) and the DEM step coupling.dt / coupling.dem_substeps")
    poly = ms.bodies[bi].polygon
    n_edges = len(poly)
    if t.has("sides") and t.has("segments"):
        raise SceneError(t.sub("sides"), "give sides or segments, not both")
    if t.has("sides"):
        sides = t.raw_value("sides")
        is_rect = n_edges == 4 and np.allclose(poly, [[poly[0, 0], poly[0, 1]], [poly[2, 0], poly[0, 1]],
                                                      [poly[2, 0], poly[2, 1]], [poly[0, 0], poly[2, 1]]])
        if not is_rect:
            raise SceneError(t.sub("sides"), f"names sides of a rectangle body; body {body!r} is a polygon: "
                                             f"use segments = [edge indices 0..{n_edges - 1}]")
        if not isinstance(sides, list) or not sides:
            raise SceneError(t.sub("sides"), f"selects no interface particles: give a non-empty list of "
                                             f"{', '.join(RECT_SIDES)}")
        edges = []
        for k, s in enumerate(sides):
            if s not in RECT_SIDES:
                raise SceneError(f"{t.sub('sides')}[{k}]", f"must be one of {', '.join(RECT_SIDES)}; got {s!r}")
            edges.append(RECT_SIDES.index(s))
    elif t.has("segments"):
        segs = t.raw_value("segments")
        if not isinstance(segs, list) or not segs:
            raise SceneError(t.sub("segments"), f"selects no interface particles: give a non-empty list of "
                                                f"edge indices 0..{n_edges - 1}")
        edges = []
        for k, s in enumerate(segs):
            if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s < n_edges:
                raise SceneError(f"{t.sub('segments')}[{k}]", f"must be an edge index in [0, {n_edges - 1}]; "
                                                              f"got {s!r}")
            edges.append(s)
    else:
        edges = list(range(n_edges))
    if len(set(edges)) != len(edges):
        raise SceneError(t.sub("sides" if t.has("sides") else "segments"), "names an edge twice")
    mat = check_material(scene, t.sub("material"), t.raw_value("material")).name
    scheme = t.string("scheme", "gauss_seidel_weak", choices=SCHEMES)
    mapper = t.string("mapper", "nearest", choices=MAPPERS)
    predictor = t.string("predictor", "constant", choices=PREDICTORS)
    dt = t.number("dt", None, gt=0.0)
    raw_sub = t.raw_value("dem_substeps", "auto")
    if raw_sub == "auto":
        sub = None
    elif isinstance(raw_sub, bool) or not isinstance(raw_sub, int) or raw_sub < 1:
        raise SceneError(t.sub("dem_substeps"), f"must be an integer >= 1 or \"auto\"; got {raw_sub!r}")
    else:
        sub = int(raw_sub)
    thickness = t.number("thickness", gt=0.0)
    spacing = t.number("wall_spacing", None, gt=0.0)
    dem_partition = t.string("dem_partition", "native", choices=DEM_PARTITIONS)
    motions = []
    cluster_names = [c.name for c in scene.dem.clusters]
    for mt in t.tables("motion"):
        b = mt.string("body")
        if b not in cluster_names:
            raise SceneError(mt.sub("body"), f"unknown DEM cluster {b!r} (clusters: {', '.join(cluster_names) or 'none'})")
        if next(c for c in scene.dem.clusters if c.name == b).motion is not None:
            raise SceneError(mt.sub("body"), f"cluster {b!r} already has [[dem.clusters]] motion; give its motion "
                                             f"in one place")
        kind = mt.string("kind", choices=MOTION_KINDS)
        vel = mt.vector("velocity", 3, [0.0, 0.0, 0.0])
        if kind == "fixed" and np.any(vel != 0.0):
            raise SceneError(mt.sub("velocity"), "only with kind = 'velocity'")
        if vel[2] != 0.0:
            raise SceneError(f"{mt.sub('velocity')}[2]", "must be 0 in a 2D scene")
        start = mt.number("start", 0.0, ge=0.0)
        until = mt.number("until", None, gt=start)
        until = math.inf if until is None else until
        mt.done()
        for m in motions:
            if m.body == b and start < m.until and m.start < until:
                raise SceneError(mt.sub("start"), f"overlaps another motion of cluster {b!r} "
                                                  f"[{m.start:g}, {m.until:g})")
        motions.append(Motion(b, kind, vel, start, until))
    t.done()

    geo = build_interface(ms, bi, edges, spacing)
    if len(geo.index) == 0:
        raise SceneError(t.sub("body"), "no interface particles on the selected outline")
    for a, b, _ in geo.wall_chains:
        if b - a < 2:
            raise SceneError(t.sub("sides" if t.has("sides") else "segments"),
                             "an interface chain holds a single boundary particle: the DEM wall needs >= 2 points "
                             "(refine mpm.grid.cell_size or particles_per_cell, or select more edges)")
    from coupler.dem.scene import INTERFACE_SOURCE, MeshWall
    walls = [w.name for w in scene.dem.planes] + [m.name for m in scene.dem.meshes]
    if WALL_NAME in walls:
        raise SceneError("dem.meshes", f"the name {WALL_NAME!r} is reserved for the coupling interface wall")
    verts = np.column_stack([geo.wall_nodes, np.zeros(len(geo.wall_nodes))])
    wall = MeshWall(WALL_NAME, mat, verts, geo.wall_segments, np.zeros(3), INTERFACE_SOURCE)
    start = start_overlap(scene, body, poly, edges, wall)
    scene.dem.meshes.append(wall)
    return CouplingScene(body, bi, sorted(edges), mat, scheme, mapper, dt, sub, thickness, spacing, geo,
                         WALL_NAME, motions, dem_partition=dem_partition, predictor=predictor, start_overlap=start)


def start_overlap(scene, body: str, poly: np.ndarray, edges: list, wall) -> dict:
    """The t = 0 overlap of the DEM spheres with the interface. A sphere centre inside the MPM body, or more than
    dem.max_initial_overlap of a radius across its selected outline edges (the geometry the scene gives), is a
    SceneError, as for any DEM wall. Against the DEM wall itself, the chain through the boundary particles, which
    cuts the outline's corners (a block resting in a corner of the outline overlaps the chord): reported, not
    refused (summary.json coupling.interface_start_overlap)."""
    from scipy.spatial import cKDTree

    from coupler.dem.scene import MeshWall, initial_spheres, mesh_overlaps, owner_label, refuse_mesh_overlap
    dem = scene.dem
    x, r, owner, names = initial_spheres(dem)
    if len(r) == 0:
        return {"largest_fraction_of_radius": 0.0, "spheres_over_tolerance": 0}
    from coupler.mpm.scene import inside
    buried = np.flatnonzero(inside(poly, x[:, :2]))
    if len(buried):
        k = int(buried[0])
        raise SceneError("dem.max_initial_overlap",
                         f"{owner_label(dem, owner, names, k)} starts inside MPM body {body!r} (the coupled soil; "
                         f"{len(buried)} sphere centre(s) inside its outline at t = 0)")
    tree = cKDTree(x)
    tol = dem.max_initial_overlap
    n = len(poly)
    outline = MeshWall("outline", wall.material, np.column_stack([poly, np.zeros(n)]),
                       np.array([[e, (e + 1) % n] for e in edges]), np.zeros(3))
    refuse_mesh_overlap(dem, outline, (x, r, owner, names), tree,
                        f"the coupling interface (the outline of MPM body {body!r})")
    sph, ov = mesh_overlaps(wall, x, r, tree)
    over = np.unique(sph[ov > tol]) if len(ov) else np.zeros(0)
    return {"largest_fraction_of_radius": float(max(0.0, ov.max())) if len(ov) else 0.0,
            "spheres_over_tolerance": int(len(over))}
