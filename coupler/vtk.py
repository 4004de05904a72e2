"""ParaView (VTK) output built from the result tables, the same for every backend.

`[output] vtk = true` makes `Result.write(out_dir, scene)` call `write_vtk`, which writes `out_dir/vtk/`:

    spheres.pvd          + spheres_<n>.vtu          DEM spheres (free spheres of the bodies table)
    clusters.pvd         + clusters_<n>.vtu         rigid-cluster body frames (one point per body)
    cluster_spheres.pvd  + cluster_spheres_<n>.vtu  the member spheres of the clusters, placed by the body frame
    walls.pvd            + walls_<n>.vtu            plane walls (one quad each) and mesh walls (their faces)
    mpm_points.pvd       + mpm_points_<n>.vtu       MPM material points (every numeric column of the snapshot)
    interface.pvd        + interface_<n>.vtu        coupled runs: the MPM interface points at every output time
                                                    (interface_series.csv), lines along the outline chains
    interface_wall.pvd   + interface_wall_<n>.vtu   coupled runs: the DEM interface wall nodes and segments with
                                                    the node forces (interface_wall.csv)
    legend.json          material / body / wall ids used in the integer arrays, and what each file holds

Every series is a ParaView collection (.pvd) whose `timestep` is the simulation time of the table rows; each
.vtu is written with meshio ("vertex" cells for points, "quad"/"triangle"/"line" for walls).

Where the data comes from. Everything that changes in time comes from the result tables (coupler/results.py),
which every backend (native, LIGGGHTS, YADE, Kratos) fills from its own output, so a run of any backend opens
the same way in ParaView. What does not change in time and the tables do not carry is taken from the scene the
run was made from (all backends run the same Scene): sphere radius and material (scene.dem.radius/material,
per body name), cluster templates (member offsets and radii), plane point/normal/velocity and mesh vertices /
faces / velocity. Wall position at time t is the scene's initial geometry translated by velocity * t, which is
what every backend does for a prescribed wall; a coupled run whose mesh nodes follow the MPM writes the node
positions in interface.csv, drawn as the interface series.

Wall forces: the contacts table gives per-contact forces on the sphere (fx, fy, fz); the force ON a wall is
minus their sum over the contacts with j = "wall:<name>" at that output time, written as cell data
`force` (uniform over the wall's cells, wall_id names the wall in legend.json). Per-node mesh forces are not
in the contract tables (no contact point is recorded), so they are written only when a table carries them
(interface.csv columns fx/fy[/fz] for coupled runs).
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pandas as pd

# Result (coupler/results.py) and Scene (coupler/scene.py) are only annotated here, not imported: results.py
# imports this module, and the import graph (tests/test_architecture.py) counts TYPE_CHECKING imports too.
__all__ = ["write_vtk", "read_pvd", "quat_to_matrix", "SERIES"]

SERIES = ("spheres", "clusters", "cluster_spheres", "walls", "mpm_points", "interface", "interface_wall")


# ----------------------------------------------------------------------------------------------------------------
def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of unit quaternions (n, 4) given as (w, x, y, z)."""
    q = np.asarray(q, float).reshape(-1, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], 1)


def _write_pvd(path: Path, entries: list[tuple[float, str]]) -> None:
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "  <Collection>"]
    for t, name in entries:
        lines.append(f'    <DataSet timestep="{t:.17g}" group="" part="0" file={quoteattr(name)}/>')
    lines += ["  </Collection>", "</VTKFile>", ""]
    path.write_text("\n".join(lines))


def read_pvd(path: str | Path) -> list[tuple[float, Path]]:
    """(time, .vtu path) of each data set of a .pvd collection, in file order."""
    import xml.etree.ElementTree as ET
    path = Path(path)
    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), path.parent / d.get("file")) for d in root.iter("DataSet")]


def _points3(df: pd.DataFrame, cols=("x", "y", "z")) -> np.ndarray:
    out = np.zeros((len(df), 3))
    for k, c in enumerate(cols):
        if c in df:
            out[:, k] = df[c].to_numpy(float)
    return out


def _vec3(df: pd.DataFrame, cols) -> np.ndarray:
    return _points3(df, cols)


class _Series:
    """One time series: collects (t, mesh) pairs and writes the .vtu files and the .pvd collection."""

    def __init__(self, out: Path, name: str):
        self.out, self.name, self.entries = out, name, []

    def add(self, t: float, points, cells, point_data=None, cell_data=None) -> None:
        import meshio
        n = len(self.entries)
        fname = f"{self.name}_{n}.vtu"
        mesh = meshio.Mesh(np.asarray(points, float).reshape(-1, 3), cells,
                           point_data={k: np.ascontiguousarray(v) for k, v in (point_data or {}).items()},
                           cell_data={k: [np.ascontiguousarray(a) for a in v] for k, v in (cell_data or {}).items()})
        meshio.write(self.out / fname, mesh, binary=True)
        self.entries.append((float(t), fname))

    def finish(self) -> Path | None:
        if not self.entries:
            return None
        p = self.out / f"{self.name}.pvd"
        _write_pvd(p, self.entries)
        return p


def _vertex_cells(n: int):
    return [("vertex", np.arange(n, dtype=np.int64).reshape(-1, 1))]


def _times(df: pd.DataFrame) -> list[float]:
    return sorted(df["t"].unique()) if len(df) else []


# ----------------------------------------------------------------------------------------------------------------
def write_vtk(result: "Result", out_dir: str | Path, scene: "Scene") -> dict[str, Path]:
    """Write the VTK series of a run (see the module docstring); returns {series name: .pvd path}."""
    out = Path(out_dir) / "vtk"
    out.mkdir(parents=True, exist_ok=True)
    for old in list(out.glob("*.vtu")) + list(out.glob("*.pvd")):   # a rerun into the same folder starts clean
        old.unlink()
    materials = sorted(scene.materials)
    mat_id = {m: k for k, m in enumerate(materials)}
    legend: dict = {"materials": materials, "series": {}}
    written: dict[str, Path] = {}
    dem = scene.dem
    bodies = result.bodies
    body_names = list(pd.unique(bodies["body"].astype(str))) if len(bodies) else []
    legend["bodies"] = body_names
    body_id = {b: k for k, b in enumerate(body_names)}

    if dem is not None and len(bodies):
        sphere_index = {n: k for k, n in enumerate(dem.names)}
        clusters = {c.name: c for c in dem.clusters}
        sph = bodies[bodies["body"].astype(str).isin(sphere_index.keys())]
        clu = bodies[bodies["body"].astype(str).isin(clusters.keys())]
        s_sph, s_clu, s_mem = _Series(out, "spheres"), _Series(out, "clusters"), _Series(out, "cluster_spheres")
        for t, g in sph.groupby("t", sort=True):
            names = g["body"].astype(str).to_numpy()
            idx = np.array([sphere_index[n] for n in names], dtype=np.int64)
            s_sph.add(t, _points3(g), _vertex_cells(len(g)), point_data={
                "radius": dem.radius[idx].astype(float),
                "velocity": _vec3(g, ("vx", "vy", "vz")),
                "angular_velocity": _vec3(g, ("wx", "wy", "wz")),
                "orientation": g[["qw", "qx", "qy", "qz"]].to_numpy(float),
                "body_id": np.array([body_id[n] for n in names], dtype=np.int64),
                "material_id": np.array([mat_id[dem.material[i]] for i in idx], dtype=np.int64)})
        for t, g in clu.groupby("t", sort=True):
            names = g["body"].astype(str).to_numpy()
            q = g[["qw", "qx", "qy", "qz"]].to_numpy(float)
            R = quat_to_matrix(q)
            c = _points3(g)
            s_clu.add(t, c, _vertex_cells(len(g)), point_data={
                "velocity": _vec3(g, ("vx", "vy", "vz")),
                "angular_velocity": _vec3(g, ("wx", "wy", "wz")),
                "orientation": q,
                # the body frame axes (columns of R) as three vectors, for ParaView glyphs
                "axis_x": R[:, :, 0].copy(), "axis_y": R[:, :, 1].copy(), "axis_z": R[:, :, 2].copy(),
                "body_id": np.array([body_id[n] for n in names], dtype=np.int64),
                "material_id": np.array([mat_id[clusters[n].material] for n in names], dtype=np.int64)})
            pts, rad, bid, mid, vel = [], [], [], [], []
            v = _vec3(g, ("vx", "vy", "vz"))
            w = _vec3(g, ("wx", "wy", "wz"))
            for k, n in enumerate(names):
                tpl = dem.templates[clusters[n].template]
                arm = tpl.offsets @ R[k].T
                pts.append(c[k] + arm)
                rad.append(tpl.radii)
                vel.append(v[k] + np.cross(w[k], arm))
                bid.append(np.full(len(tpl.radii), body_id[n], dtype=np.int64))
                mid.append(np.full(len(tpl.radii), mat_id[clusters[n].material], dtype=np.int64))
            s_mem.add(t, np.vstack(pts), _vertex_cells(sum(len(r) for r in rad)), point_data={
                "radius": np.concatenate(rad).astype(float), "velocity": np.vstack(vel),
                "body_id": np.concatenate(bid), "material_id": np.concatenate(mid)})
        for s, what in ((s_sph, "DEM spheres: radius, velocity, angular_velocity, orientation, body_id, material_id"),
                        (s_clu, "cluster body frames: centre of mass, axis_x/y/z, velocity, angular_velocity"),
                        (s_mem, "cluster member spheres placed by the body frame: radius, velocity, body_id")):
            p = s.finish()
            if p is not None:
                written[s.name] = p
                legend["series"][s.name] = what

    if dem is not None and (dem.planes or dem.meshes):
        p = _write_walls(result, scene, out, mat_id, legend)
        if p is not None:
            written["walls"] = p

    if result.particles:
        s = _Series(out, "mpm_points")
        mpm_bodies = sorted({str(b) for _, df in result.particles if "body" in df for b in df["body"].unique()})
        legend["mpm_bodies"] = mpm_bodies
        for n, (t, df) in enumerate(result.particles):
            tt = float(df["t"].iloc[0]) if "t" in df and len(df) else float(t)
            pd_ = _numeric_columns(df, skip=("t", "x", "y", "z"))
            if {"sxx", "syy", "sxy"} <= set(df.columns):      # the stress tensor for ParaView (Voigt-6 order)
                z = np.zeros(len(df))
                pd_["stress"] = np.column_stack([df["sxx"], df["syy"], df["szz"] if "szz" in df else z,
                                                 df["sxy"], z, z]).astype(float)
            if {"ux", "uy"} <= set(df.columns):
                pd_["displacement"] = _vec3(df, ("ux", "uy", "uz"))
            if {"vx", "vy"} <= set(df.columns):
                pd_["velocity"] = _vec3(df, ("vx", "vy", "vz"))
            if "body" in df:
                pd_["body_id"] = df["body"].astype(str).map({b: k for k, b in enumerate(mpm_bodies)}).to_numpy(np.int64)
            s.add(tt, _points3(df), _vertex_cells(len(df)), point_data=pd_)
        p = s.finish()
        if p is not None:
            written["mpm_points"] = p
            legend["series"]["mpm_points"] = ("MPM material points: every numeric column of particles_<n>.csv, "
                                              "plus stress (xx,yy,zz,xy,yz,xz), displacement, velocity, body_id")

    iface = _interface_table(result, Path(out_dir))
    if iface is not None and len(iface):
        p = _write_interface(out, "interface", iface, result)
        if p is not None:
            written["interface"] = p
            legend["series"]["interface"] = (
                "coupled MPM-DEM interface, MPM side: the interface points at every output time "
                "(interface_series.csv; older runs: interface_points.csv, the end state) as points and, along "
                "each outline chain, lines; force = the point load [N per unit depth], displacement, velocity "
                "and every numeric column; total_<column>: the interface totals (interface.csv) at that time")
    wall_table = Path(out_dir) / "interface_wall.csv"
    if wall_table.exists():
        wt = pd.read_csv(wall_table)
        if len(wt):
            p = _write_interface(out, "interface_wall", wt, result)
            if p is not None:
                written["interface_wall"] = p
                legend["series"]["interface_wall"] = (
                    "coupled MPM-DEM interface, DEM side: the interface wall nodes (interface_wall.csv) at every "
                    "output time, lines = the wall segments; force = the time-averaged force of the spheres on "
                    "the node over the last coupling step [N], velocity = the node velocity of that step")

    (out / "legend.json").write_text(json.dumps(legend, indent=1) + "\n")
    return written


def _numeric_columns(df: pd.DataFrame, skip=()) -> dict[str, np.ndarray]:
    out = {}
    for c in df.columns:
        if c in skip:
            continue
        col = df[c]
        if pd.api.types.is_bool_dtype(col) or pd.api.types.is_numeric_dtype(col):
            out[str(c)] = col.to_numpy(float if not pd.api.types.is_integer_dtype(col) else np.int64)
    return out


def _write_interface(out: Path, name: str, table: pd.DataFrame, result: "Result") -> Path | None:
    """One interface series: per time, the rows as points ("vertex" cells) and, when the table carries `chain`
    (and `closed`), "line" cells joining consecutive rows of a chain (closing the closed ones)."""
    s = _Series(out, name)
    for t, g in table.groupby("t", sort=True):
        pd_ = _numeric_columns(g, skip=("t", "x", "y", "z"))
        if {"fx", "fy"} <= set(g.columns):
            pd_["force"] = _vec3(g, ("fx", "fy", "fz"))
        if {"ux", "uy"} <= set(g.columns):
            pd_["displacement"] = _vec3(g, ("ux", "uy", "uz"))
        if {"vx", "vy"} <= set(g.columns):
            pd_["velocity"] = _vec3(g, ("vx", "vy", "vz"))
        for c, v in _interface_totals(result, t).items():     # the totals on every point (meshio's .vtu
            pd_[f"total_{c}"] = np.full(len(g), v)             # writer keeps no field data)
        cells = _vertex_cells(len(g))
        if "chain" in g:
            ch = g["chain"].to_numpy()
            closed = g["closed"].to_numpy() if "closed" in g else np.zeros(len(g))
            segs = [[k, k + 1] for k in range(len(g) - 1) if ch[k] == ch[k + 1]]
            for c in np.unique(ch):
                rows = np.flatnonzero(ch == c)
                if len(rows) > 2 and closed[rows[0]]:
                    segs.append([int(rows[-1]), int(rows[0])])
            if segs:
                # cell data must cover every block; the point data carries the fields, so no cell data here
                cells = cells + [("line", np.array(segs, dtype=np.int64))]
        s.add(t, _points3(g), cells, point_data=pd_)
    return s.finish()


def _interface_table(result: "Result", out: Path) -> pd.DataFrame | None:
    """Spatial interface rows with t, x, y[, z]: `result.interface` or out/interface.csv when they carry points,
    else the coupler's out/interface_series.csv (every output time), else out/interface_points.csv (x0, y0, ux,
    uy, fx, fy at the end of the run, placed at x0 + ux, y0 + uy and the last output time)."""
    for df in (getattr(result, "interface", None),
               pd.read_csv(out / "interface.csv") if (out / "interface.csv").exists() else None,
               pd.read_csv(out / "interface_series.csv") if (out / "interface_series.csv").exists() else None):
        if isinstance(df, pd.DataFrame) and {"t", "x", "y"} <= set(df.columns):
            return df
    p = out / "interface_points.csv"
    if p.exists():
        df = pd.read_csv(p)
        if {"x0", "y0"} <= set(df.columns):
            df = df.copy()
            df["x"] = df["x0"] + (df["ux"] if "ux" in df else 0.0)
            df["y"] = df["y0"] + (df["uy"] if "uy" in df else 0.0)
            if "t" not in df:
                times = _output_times(result, None)
                df["t"] = times[-1] if times else 0.0
            return df
    return None


def _interface_totals(result: "Result", t: float) -> dict:
    """The interface time series (interface.csv: t, fx_dem, ...) at the row nearest t."""
    df = getattr(result, "interface", None)
    if not isinstance(df, pd.DataFrame) or "t" not in df or not len(df) or {"x", "y"} <= set(df.columns):
        return {}
    k = int(np.argmin(np.abs(df["t"].to_numpy(float) - t)))
    return {str(c): float(df[c].iloc[k]) for c in df.columns if c != "t" and pd.api.types.is_numeric_dtype(df[c])}


def _output_times(result: "Result", scene: "Scene") -> list[float]:
    for df in (result.bodies, result.energy):
        if len(df):
            return _times(df)
    if result.particles:
        return [float(t) for t, _ in result.particles]
    return [0.0]


def _plane_quad(point, normal, half: float) -> np.ndarray:
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    p = np.asarray(point, float)
    return np.array([p - half * u - half * v, p + half * u - half * v, p + half * u + half * v,
                     p - half * u + half * v])


def _scene_extent(result: "Result", scene: "Scene") -> float:
    """Half size of the quads drawn for the (infinite) plane walls: the domain, else the spread of the bodies."""
    if scene.domain is not None:
        lo, hi = scene.domain
        return 0.5 * float(np.max(hi - lo))
    dem = scene.dem
    pts = [dem.position] if len(dem.position) else []
    if len(result.bodies):
        pts.append(_points3(result.bodies))
    if not pts:
        return 1.0
    P = np.vstack(pts)
    span = float(np.max(P.max(0) - P.min(0))) if len(P) > 1 else 0.0
    rmax = float(dem.radius.max()) if len(dem.radius) else 0.0
    return max(span, 10.0 * rmax, 1e-3)


def _near_time(times: np.ndarray, t: float) -> float:
    """The time of `times` (sorted) within the tables' 10 significant digits of the output time t (1e-9 relative),
    else t: tables read back from CSV (a reference code's, interface_wall.csv, a resumed run's contacts) and rows
    that keep every digit (coupler/checkpoint.py) name the same output time."""
    t = float(t)
    if len(times):
        k = int(np.argmin(np.abs(times - t)))
        if abs(times[k] - t) <= 1e-9 * max(1.0, abs(t)):
            return float(times[k])
    return t


def _write_walls(result: "Result", scene: "Scene", out: Path, mat_id: dict, legend: dict) -> Path | None:
    dem = scene.dem
    contacts = result.contacts
    wall_rows = contacts[contacts["j"].astype(str).str.startswith("wall:")] if len(contacts) else contacts
    walls = [("plane", w) for w in dem.planes] + [("mesh", m) for m in dem.meshes]
    legend["walls"] = [w.name for _, w in walls]
    half = _scene_extent(result, scene)
    s = _Series(out, "walls")
    node_pos = {}                   # (mesh name, t) -> (nn, 2) node positions of the coupled interface wall
    cp = getattr(scene, "coupling", None)
    if cp is not None and (out.parent / "interface_wall.csv").exists():
        wt = pd.read_csv(out.parent / "interface_wall.csv")
        for t, g in wt.groupby("t", sort=True):
            node_pos[(cp.wall_name, float(t))] = g[["x", "y"]].to_numpy(float)
    forces_by_t = {}
    if len(wall_rows):
        g = wall_rows.groupby(["t", wall_rows["j"].astype(str)])[["fx", "fy", "fz"]].sum()
        for (t, j), row in g.iterrows():
            forces_by_t[(float(t), j[5:])] = -row.to_numpy(float)      # force ON the wall
    f_times = np.unique([tt for tt, _ in forces_by_t])
    n_times = np.unique([tt for _, tt in node_pos])
    for t in _output_times(result, scene):
        pts, cells, force, wid, mid = [], [], [], [], []
        off = 0
        tf, tn = _near_time(f_times, t), _near_time(n_times, t)
        for k, (kind, w) in enumerate(walls):
            f = forces_by_t.get((tf, w.name), np.zeros(3))
            if kind == "plane":
                P = _plane_quad(w.point + w.velocity * t, w.normal, half)
                if scene.dimension == 2:      # a 2D wall is a line in the x-y plane
                    n = w.normal / np.linalg.norm(w.normal)
                    tdir = np.array([-n[1], n[0], 0.0])
                    p = w.point + w.velocity * t
                    P = np.array([p - half * tdir, p + half * tdir])
                    cells.append(("line", np.array([[off, off + 1]], dtype=np.int64)))
                else:
                    cells.append(("quad", np.array([[off, off + 1, off + 2, off + 3]], dtype=np.int64)))
                nc = 1
            else:
                P = np.asarray(w.vertices, float) + w.velocity * t
                moved = node_pos.get((w.name, tn))
                if moved is not None and moved.shape[0] == P.shape[0]:   # coupled interface wall: the nodes
                    P = P.copy()                                         # where they are at that time
                    P[:, :2] = moved
                ctype = "triangle" if w.faces.shape[1] == 3 else "line"
                cells.append((ctype, np.asarray(w.faces, dtype=np.int64) + off))
                nc = len(w.faces)
            pts.append(P)
            off += len(P)
            force.append(np.tile(f, (nc, 1)))
            wid.append(np.full(nc, k, dtype=np.int64))
            mid.append(np.full(nc, mat_id[w.material], dtype=np.int64))
        # meshio keeps one cell block per entry of `cells`: cell data is one array per block
        s.add(t, np.vstack(pts), cells, cell_data={"force": force, "wall_id": wid, "material_id": mid})
    p = s.finish()
    if p is not None:
        legend["series"]["walls"] = ("plane walls (quads of half size %.6g m; lines in 2D) and mesh walls at "
                                     "initial geometry + velocity * t; cell data force = minus the sum of the "
                                     "contact forces on the spheres touching that wall at that time" % half)
    return p
