"""The `[dem]` part of a scene: spheres, generated packings, rigid clusters, plane and mesh walls.

    [dem]
    skin = 2.5e-4                 # neighbour-list skin [m]; default 0.3 x smallest radius
    max_initial_overlap = 0.01    # largest sphere-sphere / sphere-wall overlap at t = 0, fraction of the radius
    cluster_damping_mass = "body" # effective mass in cluster contact damping: "body" (LIGGGHTS) or "sphere" (YADE)

    [[dem.spheres]]   name, material, radius, position, velocity, angular_velocity
    [[dem.lattices]]  name, material, radius, origin, counts = [nx, ny, nz], spacing, velocity
    [[dem.packings]]  name, material, radius | radius_range, box_min, box_max, count, seed, velocity,
                      random_speed (adds |v| = random_speed in seeded random directions)
    [[dem.planes]]    name, material, point, normal, velocity, rigid
    [[dem.meshes]]    name, material, vertices + triangles (3D) | segments (2D) | file, velocity, rigid
                      rigid = false (default): the wall is elastic with its material's E, nu
                      (1/E* = (1-nu_s^2)/E_s + (1-nu_w^2)/E_w); rigid = true: E* = E_s/(1-nu_s^2), G* from the
                      sphere alone (Chung & Ooi's rigid plane); the wall material still names the contact law
    [dem.templates.<name>]  spheres = [[x, y, z, r], ...] | grid = {nx, ny, nz, radius, spacing};
                            mass_properties = "exact" | "voxel" | "given" (+ mass, center, inertia)
    [[dem.clusters]]  name, template, material, position (centre of mass), orientation (qw,qx,qy,qz) | angle_z,
                      velocity, angular_velocity,
                      motion = {kind = "fixed" | "velocity" | "free", velocity, angular_velocity, until}
                      (prescribed motion, see BodyMotion)
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from coupler.errors import SceneError
from coupler.fields import _MISSING, Table, check_number
from coupler.materials import pair_key, rayleigh_time
from coupler.dem.packing import random_packing
from coupler.scene import Scene, check_material


@dataclass
class PlaneWall:
    name: str
    material: str
    point: np.ndarray
    normal: np.ndarray            # unit, pointing into the region where spheres live
    velocity: np.ndarray          # constant translation velocity [m/s]
    rigid: bool = False           # E* from the sphere alone (1/E* = (1 - nu_s^2)/E_s): a rigid plane


@dataclass
class MeshWall:
    name: str
    material: str
    vertices: np.ndarray          # (nv, 3)
    faces: np.ndarray             # (nf, 3) triangles, or (nf, 2) segments in 2D
    velocity: np.ndarray          # constant translation velocity [m/s] (the coupler moves nodes per step instead)
    source: str = ""              # file name, when read from a file
    rigid: bool = False           # E* from the sphere alone, as a rigid plane (the material gives nu, friction law)


@dataclass
class ClusterTemplate:
    name: str
    offsets: np.ndarray           # (k, 3) member centres relative to the centre of mass, in the template frame
    radii: np.ndarray             # (k,)
    mass_properties: str          # exact | voxel | given
    given_mass: float | None = None
    given_center: np.ndarray | None = None
    given_inertia: np.ndarray | None = None   # (3, 3) about the centre of mass
    voxel_resolution: int = 60


@dataclass
class Cluster:
    name: str
    template: str
    material: str
    position: np.ndarray          # centre of mass
    orientation: np.ndarray       # quaternion (w, x, y, z) of the template frame
    velocity: np.ndarray
    angular_velocity: np.ndarray
    motion: "BodyMotion | None" = None


@dataclass
class BodyMotion:
    """Prescribed motion of a cluster ([[dem.clusters]] motion = {kind, velocity, angular_velocity, until}):
    "fixed" holds it still, "velocity" moves it with the given velocity and spin (as LIGGGHTS fix move, YADE
    blockedDOFs + velocity), both until the time `until` (default: the whole run), after which it moves freely."""
    kind: str                      # "fixed" | "velocity"
    velocity: np.ndarray
    angular_velocity: np.ndarray
    until: float = math.inf


def _parse_motion(ct: Table, dim: int) -> "BodyMotion | None":
    if not ct.has("motion"):
        return None
    mt = ct.table("motion")
    kind = mt.string("kind", choices=("free", "fixed", "velocity"))
    if kind == "fixed":
        for key in ("velocity", "angular_velocity"):
            if mt.has(key):
                raise SceneError(mt.sub(key), 'not allowed with kind = "fixed" (the body is held still)')
        v = np.zeros(3)
        w = np.zeros(3)
    else:
        v = _vec(mt, "velocity", [0.0, 0.0, 0.0], dim)
        w = _spin(mt, dim)
    until = mt.number("until", None, ge=0.0)
    mt.done()
    if kind == "free":
        return None
    return BodyMotion(kind, v, w, math.inf if until is None else until)


@dataclass
class DEMScene:
    # free spheres (each is one body), flat arrays
    names: list[str]
    material: list[str]
    radius: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    planes: list[PlaneWall] = field(default_factory=list)
    meshes: list[MeshWall] = field(default_factory=list)
    templates: dict[str, ClusterTemplate] = field(default_factory=dict)
    clusters: list[Cluster] = field(default_factory=list)
    skin: float | None = None
    max_initial_overlap: float = 0.01
    cluster_damping_mass: str = "body"
    groups: dict[str, slice] = field(default_factory=dict)   # generated groups -> sphere index range

    @property
    def n_spheres(self) -> int:
        return len(self.radius)

    def materials_used(self) -> set[str]:
        used = set(self.material) | {w.material for w in self.planes} | {m.material for m in self.meshes}
        return used | {c.material for c in self.clusters}


INTERFACE_SOURCE = "coupling interface"    # MeshWall.source of the wall coupler/coupling/scene.py adds

# Largest radius, spacing and |coordinate| of DEM geometry [m]: beyond it the r^3 masses and squared distances of
# the load-time checks (time step, initial overlaps) overflow to a traceback (found by the property-based test).
MAX_LENGTH = 1e6


def _length(t: Table, key: str, default=_MISSING) -> float:
    """A length field (radius, spacing): > 0 and <= MAX_LENGTH."""
    v = t.number(key, default, gt=0.0)
    if v > MAX_LENGTH:
        raise SceneError(t.sub(key), f"must be <= {MAX_LENGTH:g} m (the largest DEM length), got {v:g}")
    return v


def _vec(t: Table, key: str, default, dim: int, point: bool = False) -> np.ndarray:
    """A 3-vector field; default None means required. point: a position, each |coordinate| <= MAX_LENGTH."""
    v = t.vector(key, 3, _MISSING if default is None else default)
    if point:
        _check_point(t.sub(key), v)
    if dim == 2 and v[2] != 0.0:
        raise SceneError(f"{t.sub(key)}[2]", f"must be 0 in a 2D scene (x-y plane), got {v[2]:g}")
    return v


def _spin(t: Table, dim: int) -> np.ndarray:
    w = t.vector("angular_velocity", 3, [0.0, 0.0, 0.0])
    if dim == 2 and (w[0] != 0.0 or w[1] != 0.0):
        raise SceneError(t.sub("angular_velocity"), "only the z component may be non-zero in a 2D scene")
    return w


def parse_dem(t: Table, scene: Scene, base_dir: Path) -> DEMScene:
    dim = scene.dimension
    names: list[str] = []
    mats: list[str] = []
    radius: list[np.ndarray] = []
    pos: list[np.ndarray] = []
    vel: list[np.ndarray] = []
    spin: list[np.ndarray] = []
    groups: dict[str, slice] = {}
    taken: set[str] = set()               # names, for the duplicate test (a list search made it O(N^2))

    def add(group: str, mat: str, r: np.ndarray, x: np.ndarray, v: np.ndarray, w: np.ndarray, single: bool):
        n0 = len(names)
        n = len(r)
        if group in groups or (single and group in taken):
            raise SceneError(group, "duplicate body or group name")
        new = [group] if single else [f"{group}:{k}" for k in range(n)]
        names.extend(new)
        taken.update(new)
        mats.extend([mat] * n)
        radius.append(r)
        pos.append(x)
        vel.append(np.broadcast_to(v, (n, 3)).copy())
        spin.append(np.broadcast_to(w, (n, 3)).copy())
        if not single:
            groups[group] = slice(n0, n0 + n)

    for k, st in enumerate(t.tables("spheres")):
        name = st.string("name", f"sphere{k}")
        mat = check_material(scene, st.sub("material"), st.raw_value("material")).name
        r = _length(st, "radius")
        x = _vec(st, "position", None, dim, point=True)
        add(name, mat, np.array([r]), x[None, :], _vec(st, "velocity", [0.0, 0.0, 0.0], dim), _spin(st, dim), True)
        st.done()

    for k, lt in enumerate(t.tables("lattices")):
        name = lt.string("name", f"lattice{k}")
        mat = check_material(scene, lt.sub("material"), lt.raw_value("material")).name
        r = _length(lt, "radius")
        origin = _vec(lt, "origin", None, dim, point=True)
        counts = lt.raw_value("counts")
        if (not isinstance(counts, list) or len(counts) != 3
                or not all(isinstance(c, int) and not isinstance(c, bool) and c >= 1 for c in counts)):
            raise SceneError(lt.sub("counts"), f"must be three integers >= 1 [nx, ny, nz], got {counts!r}")
        if dim == 2 and counts[2] != 1:
            raise SceneError(f"{lt.sub('counts')}[2]", f"must be 1 in a 2D scene, got {counts[2]}")
        spacing = _length(lt, "spacing", 2.0 * r)
        ii, jj, kk = np.meshgrid(np.arange(counts[0]), np.arange(counts[1]), np.arange(counts[2]), indexing="ij")
        x = origin + spacing * np.stack([ii.ravel(), jj.ravel(), kk.ravel()], axis=1).astype(float)
        add(name, mat, np.full(len(x), r), x, _vec(lt, "velocity", [0.0, 0.0, 0.0], dim),
            np.zeros(3), False)
        lt.done()

    for k, pt in enumerate(t.tables("packings")):
        name = pt.string("name", f"packing{k}")
        mat = check_material(scene, pt.sub("material"), pt.raw_value("material")).name
        if pt.has("radius") == pt.has("radius_range"):
            raise SceneError(pt.sub("radius"), "give exactly one of radius or radius_range = [r_min, r_max]")
        if pt.has("radius"):
            rmin = rmax = _length(pt, "radius")
        else:
            rr = pt.vector("radius_range", 2, positive=True)
            rmin, rmax = float(rr[0]), float(rr[1])
            _check_point(pt.sub("radius_range"), rr)
            if rmax < rmin:
                raise SceneError(pt.sub("radius_range[1]"), f"must be >= radius_range[0] ({rmin:g}), got {rmax:g}")
        lo = _vec(pt, "box_min", None, dim, point=True)
        hi = _vec(pt, "box_max", None, dim, point=True)
        count = pt.integer("count", ge=1)
        seed = pt.integer("seed", scene.seed, ge=0)
        r, x = random_packing(pt.sub("count"), lo, hi, count, rmin, rmax, seed, dim)
        v0 = _vec(pt, "velocity", [0.0, 0.0, 0.0], dim) + _random_velocities(
            pt.number("random_speed", 0.0, ge=0.0), count, seed, dim)
        add(name, mat, r, x, v0, np.zeros(3), False)
        pt.done()

    planes = []
    for k, wt in enumerate(t.tables("planes")):
        name = wt.string("name", f"plane{k}")
        mat = check_material(scene, wt.sub("material"), wt.raw_value("material")).name
        point = _vec(wt, "point", [0.0, 0.0, 0.0], dim, point=True)
        normal = wt.vector("normal", 3)
        nrm = np.linalg.norm(normal)
        if nrm == 0.0:
            raise SceneError(wt.sub("normal"), "must be a non-zero vector")
        if dim == 2 and normal[2] != 0.0:
            raise SceneError(f"{wt.sub('normal')}[2]", f"must be 0 in a 2D scene, got {normal[2]:g}")
        planes.append(PlaneWall(name, mat, point, normal / nrm, _vec(wt, "velocity", [0.0, 0.0, 0.0], dim),
                                wt.boolean("rigid", False)))
        wt.done()

    meshes = []
    for k, mt in enumerate(t.tables("meshes")):
        meshes.append(_parse_mesh(mt, k, scene, base_dir))

    templates = {}
    for tname, tt in t.named_tables("templates").items():
        templates[tname] = _parse_template(tt, tname, dim)

    clusters = []
    for k, ct in enumerate(t.tables("clusters")):
        name = ct.string("name", f"cluster{k}")
        tname = ct.string("template")
        if tname not in templates:
            raise SceneError(ct.sub("template"), f"unknown template {tname!r} (defined: {', '.join(sorted(templates)) or 'none'})")
        mat = check_material(scene, ct.sub("material"), ct.raw_value("material")).name
        position = _vec(ct, "position", None, dim, point=True)
        if ct.has("orientation") and ct.has("angle_z"):
            raise SceneError(ct.sub("orientation"), "give orientation or angle_z, not both")
        if ct.has("orientation"):
            q = ct.vector("orientation", 4)
            nq = np.linalg.norm(q)
            if not abs(nq - 1.0) < 1e-6:
                raise SceneError(ct.sub("orientation"), f"must be a unit quaternion (w, x, y, z); |q| = {nq:g}")
            q = q / nq
            if dim == 2 and (abs(q[1]) > 1e-12 or abs(q[2]) > 1e-12):
                raise SceneError(ct.sub("orientation"), "must be a rotation about z in a 2D scene (qx = qy = 0)")
        else:
            a = ct.number("angle_z", 0.0)
            q = np.array([math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)])
        clusters.append(Cluster(name, tname, mat, position, q, _vec(ct, "velocity", [0.0, 0.0, 0.0], dim),
                                _spin(ct, dim), _parse_motion(ct, dim)))
        ct.done()

    dem = DEMScene(
        names=names, material=mats,
        radius=np.concatenate(radius) if radius else np.zeros(0),
        position=np.concatenate(pos) if pos else np.zeros((0, 3)),
        velocity=np.concatenate(vel) if vel else np.zeros((0, 3)),
        angular_velocity=np.concatenate(spin) if spin else np.zeros((0, 3)),
        planes=planes, meshes=meshes, templates=templates, clusters=clusters, groups=groups,
        skin=t.number("skin", None, gt=0.0),
        max_initial_overlap=t.number("max_initial_overlap", 0.01, ge=0.0, le=0.5),
        cluster_damping_mass=t.string("cluster_damping_mass", "body", choices=("body", "sphere")),
    )
    t.done()
    all_names = names + [c.name for c in clusters]
    wall_names = [w.name for w in planes] + [m.name for m in meshes]
    for kind, names_ in (("body", all_names), ("wall", wall_names)):
        twice = [nm for nm, k in Counter(names_).items() if k > 1]      # the first in scene order
        if twice:
            raise SceneError(f"dem ({twice[0]})", f"duplicate {kind} name")
    if dem.n_spheres == 0 and not clusters:
        raise SceneError("dem", "declares no spheres or clusters")
    return dem


def _random_velocities(speed: float, count: int, seed: int, dim: int) -> np.ndarray:
    """Velocities of magnitude `speed` in uniformly random directions (seeded; in-plane for 2D)."""
    rng = np.random.default_rng(seed + 1)
    d = rng.normal(size=(count, 3))
    if dim == 2:
        d[:, 2] = 0.0
    return speed * d / np.linalg.norm(d, axis=1)[:, None]


def _parse_mesh(mt: Table, k: int, scene: Scene, base_dir: Path) -> MeshWall:
    dim = scene.dimension
    name = mt.string("name", f"mesh{k}")
    mat = check_material(scene, mt.sub("material"), mt.raw_value("material")).name
    velocity = _vec(mt, "velocity", [0.0, 0.0, 0.0], dim)
    rigid = mt.boolean("rigid", False)
    source = ""
    if mt.has("file"):
        if mt.has("vertices"):
            raise SceneError(mt.sub("file"), "give either file or vertices, not both")
        fname = mt.string("file")
        source = fname
        p = (base_dir / fname)
        try:
            import warnings
            import meshio
            with warnings.catch_warnings(), np.errstate(all="ignore"):   # meshio's ASCII-STL probe overflows a
                warnings.simplefilter("ignore")                          # uint32 and warns on stderr: not ours
                m = meshio.read(p)
        except Exception as e:  # meshio raises many types
            raise SceneError(mt.sub("file"), f"cannot read mesh file {str(p)!r}: {e}") from None
        verts = np.asarray(m.points, dtype=float)
        if verts.ndim != 2 or len(verts) == 0 or verts.shape[1] not in (2, 3):     # e.g. an empty file
            raise SceneError(mt.sub("file"), f"mesh file {str(p)!r} holds no points (read as shape {verts.shape})")
        if not np.isfinite(verts).all() or np.abs(verts).max() > MAX_LENGTH:
            raise SceneError(mt.sub("file"), f"mesh file {str(p)!r}: vertex coordinates must be finite and within "
                                             f"[-{MAX_LENGTH:g}, {MAX_LENGTH:g}] m")
        if verts.shape[1] == 2:
            verts = np.hstack([verts, np.zeros((len(verts), 1))])
        kind = "line" if dim == 2 else "triangle"
        cells = [c.data for c in m.cells if c.type == kind]
        if not cells:
            raise SceneError(mt.sub("file"), f"mesh file {fname!r} has no {kind} cells")
        faces = np.concatenate(cells).astype(np.int64)
    else:
        raw_verts = mt.raw_value("vertices")
        if not isinstance(raw_verts, list) or not raw_verts:
            raise SceneError(mt.sub("vertices"), f"must be a non-empty list of [x, y, z] points, got {raw_verts!r}")
        verts = np.array([check_vector_3(f"{mt.sub('vertices')}[{i}]", v) for i, v in
                          enumerate(raw_verts)], dtype=float).reshape(-1, 3)
        key = "segments" if dim == 2 else "triangles"
        other = "triangles" if dim == 2 else "segments"
        if mt.has(other):
            raise SceneError(mt.sub(other), f"use {key} in a {dim}D scene")
        raw_faces = mt.raw_value(key)
        nv = 2 if dim == 2 else 3
        if not isinstance(raw_faces, list) or not raw_faces:
            raise SceneError(mt.sub(key), f"must be a non-empty list of {nv}-vertex index lists")
        for i, f in enumerate(raw_faces):
            if (not isinstance(f, list) or len(f) != nv
                    or not all(isinstance(a, int) and not isinstance(a, bool) for a in f)):
                raise SceneError(f"{mt.sub(key)}[{i}]", f"must be a list of {nv} vertex indices, got {f!r}")
        faces = np.array(raw_faces, dtype=np.int64)
    mt.done()
    if len(faces) == 0:
        raise SceneError(mt.sub("file" if source else "vertices"), "mesh has no faces")
    if faces.min() < 0 or faces.max() >= len(verts):
        bad = int(np.argmax((faces < 0).any(axis=1) | (faces >= len(verts)).any(axis=1)))
        raise SceneError(mt.sub(f"faces[{bad}]"), f"vertex index out of range [0, {len(verts) - 1}]")
    if dim == 2 and np.any(verts[:, 2] != 0.0):
        raise SceneError(mt.sub("vertices"), "z must be 0 in a 2D scene")
    # degenerate faces
    if faces.shape[1] == 3:
        a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
        area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        scale = np.maximum(np.linalg.norm(b - a, axis=1), np.linalg.norm(c - a, axis=1)) ** 2
        bad = np.nonzero(area2 <= 1e-12 * np.maximum(scale, 1e-300))[0]
        if len(bad):
            raise SceneError(f"{mt.path} triangle {int(bad[0])}", "degenerate triangle (zero area)")
    else:
        length = np.linalg.norm(verts[faces[:, 1]] - verts[faces[:, 0]], axis=1)
        bad = np.nonzero(length <= 0.0)[0]
        if len(bad):
            raise SceneError(f"{mt.path} segment {int(bad[0])}", "degenerate segment (zero length)")
    return MeshWall(name, mat, verts, faces, velocity, source, rigid)


def check_vector_3(path: str, v) -> list[float]:
    if not isinstance(v, list) or len(v) not in (2, 3):
        raise SceneError(path, f"must be a list of 3 numbers, got {v!r}")
    vals = [check_number(f"{path}[{i}]", x, ge=-MAX_LENGTH, le=MAX_LENGTH) for i, x in enumerate(v)]
    return vals + [0.0] * (3 - len(vals))


def _check_point(path: str, v: np.ndarray) -> None:
    for i, x in enumerate(v):
        check_number(f"{path}[{i}]", float(x), ge=-MAX_LENGTH, le=MAX_LENGTH)


def _parse_template(tt: Table, name: str, dim: int) -> ClusterTemplate:
    if tt.has("spheres") == tt.has("grid"):
        raise SceneError(tt.sub("spheres"), "give exactly one of spheres = [[x, y, z, r], ...] or grid = {...}")
    if tt.has("spheres"):
        raw = tt.raw_value("spheres")
        if not isinstance(raw, list) or not raw:
            raise SceneError(tt.sub("spheres"), "must be a non-empty list of [x, y, z, r] (a template needs >= 1 sphere)")
        rows = []
        for i, s in enumerate(raw):
            p = f"{tt.sub('spheres')}[{i}]"
            if not isinstance(s, list) or len(s) != 4:
                raise SceneError(p, f"must be [x, y, z, r], got {s!r}")
            rows.append([check_number(f"{p}[{j}]", s[j], ge=-MAX_LENGTH, le=MAX_LENGTH) for j in range(3)]
                        + [check_number(f"{p}[3]", s[3], gt=0.0, le=MAX_LENGTH)])
        arr = np.array(rows)
        offsets, radii = arr[:, :3], arr[:, 3]
    else:
        g = tt.table("grid")
        nx, ny, nz = g.integer("nx", ge=1), g.integer("ny", ge=1), g.integer("nz", 1, ge=1)
        r = _length(g, "radius")
        sp = _length(g, "spacing", 2.0 * r)
        g.done()
        ii, jj, kk = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
        offsets = sp * np.stack([ii.ravel(), jj.ravel(), kk.ravel()], axis=1).astype(float)
        radii = np.full(len(offsets), r)
    if dim == 2 and np.any(offsets[:, 2] != offsets[0, 2]):
        raise SceneError(tt.sub("spheres"), "all member spheres must share one z in a 2D scene")
    mp = tt.string("mass_properties", "exact", choices=("exact", "voxel", "given"))
    given_mass = given_center = given_inertia = None
    if mp == "given":
        given_mass = tt.number("mass", gt=0.0)
        given_center = tt.vector("center", 3)
        inn = tt.vector("inertia", 6)  # Ixx, Iyy, Izz, Ixy, Ixz, Iyz
        given_inertia = np.array([[inn[0], inn[3], inn[4]], [inn[3], inn[1], inn[5]], [inn[4], inn[5], inn[2]]])
        ev = np.linalg.eigvalsh(given_inertia)
        if ev.min() <= 0:
            raise SceneError(tt.sub("inertia"), "must be positive definite")
    vox = tt.integer("voxel_resolution", 60, ge=8, le=1000)
    tt.done()
    return ClusterTemplate(name, offsets, radii, mp, given_mass, given_center, given_inertia, vox)


def finish_dem(scene: Scene) -> None:
    """Cross-field checks: a contact law for every material pair that can touch (touching_pairs), every body inside
    [domain], initial overlaps, time step (and output_interval >= dt)."""
    dem: DEMScene = scene.dem
    for a, b in sorted(touching_pairs(scene)):
        if pair_key(a, b) not in scene.contacts:
            raise SceneError("contacts", f"no contact law for materials ({a!r}, {b!r}); add [[contacts]] "
                                         f"materials = [{a!r}, {b!r}]")
    check_in_domain(scene)
    check_initial_overlap(scene)
    from coupler.dem.timestep import check_time_step
    check_time_step(scene)


def touching_pairs(scene: Scene) -> set[tuple[str, str]]:
    """The material pairs (pair_key) that can touch, the only ones that need a [[contacts]] law: two different
    bodies (free spheres, clusters; the members of one cluster never touch each other), or a body and a wall (plane,
    mesh, the coupling interface wall). Two walls never touch; a material of a single body never meets itself."""
    dem: DEMScene = scene.dem
    count: dict[str, int] = {}
    for m in list(dem.material) + [c.material for c in dem.clusters]:
        count[m] = count.get(m, 0) + 1
    walls = {w.material for w in dem.planes} | {m.material for m in dem.meshes}
    coupling = getattr(scene, "coupling", None)
    if coupling is not None and getattr(coupling, "material", None):
        walls.add(coupling.material)
    bodies = sorted(count)
    pairs = set()
    for i, a in enumerate(bodies):
        if count[a] > 1:
            pairs.add(pair_key(a, a))
        for b in bodies[i + 1:]:
            pairs.add(pair_key(a, b))
        for w in walls:
            pairs.add(pair_key(a, w))
    return pairs


def _cluster_members(dem: DEMScene, c: Cluster) -> np.ndarray:
    """World positions of a cluster's member centres at t = 0 (centre of mass from the member volumes, or the
    given centre), for the t = 0 domain check."""
    t = dem.templates[c.template]
    if t.mass_properties == "given" and t.given_center is not None:
        com = t.given_center
    else:
        vol = t.radii ** 3
        com = (vol[:, None] * t.offsets).sum(0) / vol.sum()
    w, x, y, z = c.orientation
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return c.position + (t.offsets - com) @ R.T


def check_in_domain(scene: Scene) -> None:
    """Every sphere centre (free spheres, cluster centres of mass and members) inside [domain] at t = 0 (the run's
    leave-the-domain check would otherwise stop it at step 0)."""
    if scene.domain is None:
        return
    dem: DEMScene = scene.dem
    lo, hi = scene.domain
    items = [(nm, x[None, :]) for nm, x in zip(dem.names, dem.position)]
    items += [(c.name, np.vstack([c.position[None, :], _cluster_members(dem, c)])) for c in dem.clusters]
    for nm, xs in items:
        out = ((xs < lo) | (xs > hi)).any(axis=1)
        if out.any():
            x = xs[int(np.argmax(out))]
            raise SceneError("domain", f"body {nm!r} at {[float(v) for v in x]} is outside the domain "
                                       f"[{[float(v) for v in lo]}, {[float(v) for v in hi]}] at t = 0 "
                                       "(domain.min / domain.max must contain every body)")


def initial_spheres(dem: DEMScene) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Every sphere at t = 0, free spheres then cluster members: centres (n, 3), radii (n,), owner (n,: one index per
    free sphere or cluster; the members of one cluster share it) and the owners' names."""
    xs, rs, owner = [dem.position.reshape(-1, 3)], [dem.radius], [np.arange(dem.n_spheres)]
    names = list(dem.names)
    for c in dem.clusters:
        t = dem.templates[c.template]
        xs.append(_cluster_members(dem, c))
        rs.append(t.radii)
        owner.append(np.full(len(t.radii), len(names)))
        names.append(c.name)
    return np.vstack(xs), np.concatenate(rs), np.concatenate(owner), names


def mesh_overlaps(mesh: MeshWall, x: np.ndarray, r: np.ndarray, tree: cKDTree) -> tuple[np.ndarray, np.ndarray]:
    """(sphere index, overlap / radius) of the spheres within a radius of a face of the mesh (candidates from each
    face's bounding sphere; distances by the mesh pass's closest points, meshes.face_distances)."""
    v = mesh.vertices[mesh.faces]                           # (nf, 2 or 3, 3)
    centre = v.mean(axis=1)
    reach = np.linalg.norm(v - centre[:, None, :], axis=2).max(axis=1) + r.max()
    hits = tree.query_ball_point(centre, reach)
    face = np.repeat(np.arange(len(v)), [len(h) for h in hits])
    if len(face) == 0:
        return np.zeros(0, int), np.zeros(0)
    sph = np.concatenate([np.asarray(h, int) for h in hits])
    from coupler.dem.meshes import face_distances          # the contact detection's own closest points
    d = face_distances(np.ascontiguousarray(x[sph], dtype=float), np.ascontiguousarray(v[face], dtype=float))
    return sph, (r[sph] - d) / r[sph]


def owner_label(dem: DEMScene, owner: np.ndarray, names: list[str], k: int) -> str:
    """'sphere <name>' or 'cluster <name>' for sphere k of initial_spheres."""
    o = int(owner[k])
    return f"sphere {names[o]!r}" if o < dem.n_spheres else f"cluster {names[o]!r}"


def check_initial_overlap(scene: Scene) -> None:
    """No sphere (free, or a member of a cluster) overlaps another body or a wall (plane, mesh) by more than
    dem.max_initial_overlap of its radius at t = 0: such an overlap starts the run with the elastic energy of a deep
    contact and flings the bodies apart. Members of one cluster may overlap. The coupling interface wall is checked
    by coupler/coupling/scene.py, against the MPM body's outline."""
    dem: DEMScene = scene.dem
    x, r, owner, names = initial_spheres(dem)
    if len(r) == 0:
        return
    tol = dem.max_initial_overlap

    def who(k: int) -> str:
        return owner_label(dem, owner, names, k)

    tree = cKDTree(x)
    pairs = tree.query_pairs(2.0 * r.max(), output_type="ndarray")
    pairs = pairs[owner[pairs[:, 0]] != owner[pairs[:, 1]]] if len(pairs) else pairs
    if len(pairs):
        d = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
        ov = (r[pairs[:, 0]] + r[pairs[:, 1]] - d) / np.minimum(r[pairs[:, 0]], r[pairs[:, 1]])
        k = int(np.argmax(ov))
        if ov[k] > tol:
            i, j = pairs[k]
            pair = (f"spheres {names[owner[i]]!r} and {names[owner[j]]!r}"
                    if max(owner[i], owner[j]) < dem.n_spheres else f"{who(i)} and {who(j)}")
            raise SceneError("dem.max_initial_overlap",
                             f"{pair} overlap by {ov[k]:.3g} of the radius at t = 0; allowed range [0, {tol:g}]")
    for w in dem.planes:
        ov = (r - (x - w.point) @ w.normal) / r
        k = int(np.argmax(ov))
        if ov[k] > tol:
            raise SceneError("dem.max_initial_overlap",
                             f"{who(k)} overlaps wall {w.name!r} by {ov[k]:.3g} of the radius at "
                             f"t = 0; allowed range [0, {tol:g}]")
    for m in dem.meshes:
        if m.source != INTERFACE_SOURCE:
            refuse_mesh_overlap(dem, m, (x, r, owner, names), tree, f"wall {m.name!r}")


def refuse_mesh_overlap(dem: DEMScene, mesh: MeshWall, spheres: tuple, tree: cKDTree, what: str) -> None:
    """SceneError when a sphere of spheres = initial_spheres(dem) overlaps `mesh` by more than
    dem.max_initial_overlap of its radius; `what` names the wall in the message."""
    x, r, owner, names = spheres
    sph, ov = mesh_overlaps(mesh, x, r, tree)
    tol = dem.max_initial_overlap
    if len(ov) and ov.max() > tol:
        k = int(np.argmax(ov))
        raise SceneError("dem.max_initial_overlap",
                         f"{owner_label(dem, owner, names, int(sph[k]))} overlaps {what} by {ov[k]:.3g} of the "
                         f"radius at t = 0; allowed range [0, {tol:g}]")


def smallest_radius(dem: DEMScene) -> float:
    rs = [dem.radius.min()] if dem.n_spheres else []
    rs += [dem.templates[c.template].radii.min() for c in dem.clusters]
    return float(min(rs))


__all__ = ["DEMScene", "PlaneWall", "MeshWall", "BodyMotion", "ClusterTemplate", "Cluster", "parse_dem", "finish_dem",
           "rayleigh_time", "smallest_radius"]
