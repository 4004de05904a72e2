"""Metrics shared by the validation cases, each defined once, and the readers of the inputs they need.

A case computes its numbers with these functions; the analytic inputs (radii, densities, moduli, speeds, friction,
restitution, geometry) come from the case's scene file (``scene_*`` readers below, on the loaded ``Scene``) or from
the data files in ``validation/data`` (``read_data``), not typed again in ``case.py``. The analytic solutions
themselves are in ``validation/analytic.py``.

Conventions: ``b`` is one body's table (``Result.body(name)``: columns t, x, y, z, vx, vy, vz, wx, wy, wz, qw, qx,
qy, qz); "first" and "last" are the first and last output rows of the run; results are plain floats.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

DATA_DIR = Path(__file__).resolve().parent / "data"


# -- inputs: scene and data files ---------------------------------------------------------------------------------
def sphere_mass(density, radius):
    """Mass of a solid sphere, rho 4/3 pi R^3 [kg] (numbers or arrays; evaluated left to right in this order)."""
    return density * 4 / 3 * math.pi * radius ** 3


def scene_sphere(scene, name: str) -> int:
    """Index of the named free sphere in ``scene.dem`` (KeyError naming the sphere if absent)."""
    try:
        return scene.dem.names.index(name)
    except ValueError:
        raise KeyError(f"{scene.name}: no sphere named {name!r} (spheres: {', '.join(scene.dem.names)})") from None


def scene_sphere_props(scene, name: str) -> dict:
    """The named sphere's radius [m], material (``Material``), mass [kg] (``sphere_mass``), initial velocity (3,)."""
    i = scene_sphere(scene, name)
    mat = scene.materials[scene.dem.material[i]]
    radius = float(scene.dem.radius[i])
    return {"radius": radius, "material": mat, "mass": sphere_mass(mat.density, radius),
            "velocity": np.asarray(scene.dem.velocity[i], dtype=float)}


def scene_cluster(scene, name: str):
    """(cluster, template, material) of the named rigid cluster in ``scene.dem``."""
    for c in scene.dem.clusters:
        if c.name == name:
            return c, scene.dem.templates[c.template], scene.materials[c.material]
    raise KeyError(f"{scene.name}: no cluster named {name!r}")


def scene_wall_velocity(scene) -> np.ndarray:
    """Translation velocity of the scene's first wall (planes first, then meshes); zero if it has none."""
    dem = scene.dem
    walls = list(dem.planes) + list(dem.meshes)
    return walls[0].velocity if walls else np.zeros(3)


def scene_mpm_body_extent(scene, k: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(lower corner, upper corner) [m] of the bounding box of the k-th MPM body's initial outline."""
    poly = np.asarray(scene.mpm.bodies[k].polygon, dtype=float)
    return poly.min(axis=0), poly.max(axis=0)


def read_data(name: str) -> np.ndarray:
    """A CSV of ``validation/data``: '#' lines are comments, the first other line is the header; rows as floats."""
    rows = [l for l in (DATA_DIR / name).read_text().splitlines() if l and not l.startswith("#")]
    return np.array([[float(v) for v in r.split(",")] for r in rows[1:]])


# -- single contacts ----------------------------------------------------------------------------------------------
def peak_force(fn) -> float:
    """Largest normal force [N] over the samples (of a contact table's fn column or a force series)."""
    return float(np.max(fn))


def max_overlap(overlap) -> float:
    """Largest overlap [m] over the samples of a contact table's overlap column."""
    return float(np.max(overlap))


def contact_force_series(res, body: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, F_n, |F_t|) of the contacts of ``body`` (as the contact table's i), summed over its contacts per sample."""
    c = res.contacts[res.contacts["i"] == body].groupby("t")[["fn", "ft"]].sum()
    return c.index.to_numpy(), c["fn"].to_numpy(), c["ft"].to_numpy()


def contact_time_from_gap(t, gap) -> float:
    """Contact duration [s] from a gap series (surface distance, < 0 in contact): time between the first and the last
    zero crossing, each linearly interpolated between the two samples around it. NaN if the gap never closes.
    For comparison with the analytic Hertz time: resolves the duration below the output interval."""
    inside = np.nonzero(gap < 0)[0]
    if len(inside) == 0:
        return float("nan")
    i0, i1 = inside[0], inside[-1]
    t_in = t[i0 - 1] + (t[i0] - t[i0 - 1]) * gap[i0 - 1] / (gap[i0 - 1] - gap[i0])
    t_out = t[i1] + (t[i1 + 1] - t[i1]) * gap[i1] / (gap[i1] - gap[i1 + 1])
    return t_out - t_in


def contact_time_from_force(t, fn) -> float:
    """Contact duration [s] from a force series: first to last sample with F_n > 0 (+- one sample; a definition every
    code's output allows, for code-to-code comparison on the same samples, notes P15). NaN if no force."""
    on = t[fn > 0]
    return float(on[-1] - on[0]) if len(on) else float("nan")


def wall_gap(b, radius: float) -> np.ndarray:
    """Gap [m] of a sphere above the floor plane y = 0: y - R per sample."""
    return b["y"].to_numpy() - radius


def pair_gap(a, b, radius_a: float, radius_b: float) -> np.ndarray:
    """Gap [m] between two spheres moving in the x-y plane: centre distance - (R_a + R_b) per sample."""
    return np.hypot(b["x"] - a["x"], b["y"] - a["y"]).to_numpy() - (radius_a + radius_b)


def restitution_wall(b, wall_vy: float = 0.0) -> float:
    """Normal restitution against a wall of normal +y moving at wall_vy, in the wall frame:
    (vy_last - v_w) / (v_w - vy_first). For a resting wall this is the rebound ratio vy_last / -vy_first (also the
    rebound ratio of a cluster's centre of mass dropped flat)."""
    return float((b["vy"].iloc[-1] - wall_vy) / (wall_vy - b["vy"].iloc[0]))


def restitution_pair(a, b) -> float:
    """Normal restitution of a head-on pair along y (a below b): (vy_b - vy_a)_last / (vy_a - vy_b)_first."""
    return float((b["vy"].iloc[-1] - a["vy"].iloc[-1]) / (a["vy"].iloc[0] - b["vy"].iloc[0]))


def tangential_impulse(b, mass: float) -> float:
    """Tangential (x) impulse the wall gives a sphere [N s]: m (vx_first - vx_last)."""
    return mass * (b["vx"].iloc[0] - b["vx"].iloc[-1])


def rebound_angle_deg(b, wall_velocity=(0.0, 0.0)) -> float:
    """Rebound angle [deg] atan2(vx, vy) of the last velocity in the frame of a wall moving at wall_velocity (x, y)."""
    return math.degrees(math.atan2(b["vx"].iloc[-1] - wall_velocity[0], b["vy"].iloc[-1] - wall_velocity[1]))


# -- energies -----------------------------------------------------------------------------------------------------
def total_energy(e, dissipated: bool = True) -> np.ndarray:
    """Energy account per sample of an energy table: kinetic + potential + elastic (+ dissipated, the accumulated
    contact work, if ``dissipated``); conserved by an exact integrator (e = 1, mu = 0: without D as well)."""
    total = e["kinetic"] + e["potential"] + e["elastic"]
    return (total + e["dissipated"] if dissipated else total).to_numpy()


# -- trajectories -------------------------------------------------------------------------------------------------
def rotation_z_deg(b) -> np.ndarray:
    """Rotation about z [deg] of a body from its orientation quaternion: 2 atan2(qz, qw) (positive counter-clockwise)."""
    return np.degrees(2.0 * np.arctan2(b["qz"].to_numpy(), b["qw"].to_numpy()))


def trajectory_error(a, b) -> float:
    """Largest distance between two trajectories sampled at the same times: max_k |a_k - b_k| (Euclidean over the
    columns for (n, d) arrays, absolute for 1-D series). Arrays of different lengths are compared over the common
    leading samples."""
    a, b = np.asarray(a), np.asarray(b)
    n = min(len(a), len(b))
    d = a[:n] - b[:n]
    return float((np.linalg.norm(d, axis=1) if d.ndim == 2 else np.abs(d)).max())


def trajectory_error_interp(t_a, a, t_b, b) -> float:
    """Largest |a(t) - b(t)| at the samples t_a of a, b linearly interpolated to them (series on different times)."""
    return float(np.abs(a - np.interp(t_a, t_b, b)).max())


def curve_difference(t1, f1, t2, f2) -> float:
    """max |f1 - f2| over the samples common to both series (times matched to 1e-12 s) / max |f2|; NaN if none."""
    common, i1, i2 = np.intersect1d(np.round(t1, 12), np.round(t2, 12), return_indices=True)
    if len(common) == 0:
        return float("nan")
    return float(np.max(np.abs(f1[i1] - f2[i2])) / np.max(np.abs(f2)))


def period_from_zero_crossings(t, v) -> tuple[float, int]:
    """Period of an oscillating signal from its sign changes: the crossing times are linearly interpolated between the
    two samples around each; period = 2 (last - first crossing) / (number of crossings - 1). Returns (period, number
    of crossings)."""
    s = np.sign(v)
    idx = np.nonzero(s[:-1] * s[1:] < 0)[0]
    tz = t[idx] - v[idx] * (t[idx + 1] - t[idx]) / (v[idx + 1] - v[idx])
    return 2 * (tz[-1] - tz[0]) / (len(tz) - 1), len(tz)


def value_at(t, y, ts: float) -> float:
    """y at the output sample nearest to time ts (no interpolation)."""
    return float(y[int(np.argmin(abs(t - ts)))])


# -- free surfaces and deposits -----------------------------------------------------------------------------------
def surface_profile(x, top, width: float, nbins: int) -> tuple[np.ndarray, np.ndarray]:
    """Free-surface profile of a deposit: per x-bin [k width, (k+1) width), k = 0 .. nbins-1, the highest ``top``
    (e.g. a grain's or point's top) of the bodies whose x falls in it; x outside [0, nbins width) goes to the end
    bins; an empty bin is 0. Returns (bin centres (k + 1/2) width, heights)."""
    h = np.zeros(nbins)
    k = np.clip((x / width).astype(int), 0, nbins - 1)
    np.maximum.at(h, k, top)
    return (np.arange(nbins) + 0.5) * width, h


def lattice_triangles(x0, y0, x, y, spacing: float):
    """Do the points still sample the deformation? Points seeded on a lattice of `spacing` (initial centres x0, y0
    at (i + 1/2, j + 1/2) spacing), now at (x, y): each lattice square of four points gives two triangles
    (lower-left, lower-right, upper-right; lower-left, upper-right, upper-left). Returns (area ratio now / seeded of
    each triangle, its current centroid x, y, and its vertices (n, 3) as row indices). A motion that is affine at
    the point spacing gives every triangle the ratio J = det F of its points; a negative ratio is a triangle turned
    inside out: its points passed through each other, or (gradually, through zero area) the motion bent the
    material between them at a scale below the spacing. Raises ValueError if a point is not on the lattice."""
    x0, y0, x, y = (np.asarray(a, float) for a in (x0, y0, x, y))
    i = np.rint(x0 / spacing - 0.5).astype(np.int64)
    j = np.rint(y0 / spacing - 0.5).astype(np.int64)
    off = max(np.abs(x0 - (i + 0.5) * spacing).max(), np.abs(y0 - (j + 0.5) * spacing).max())
    if off > 1e-6 * spacing:
        raise ValueError(f"spacing: the initial centres are not on a lattice of {spacing:g} m (off by {off:.3g} m)")
    i -= i.min()
    j -= j.min()
    idx = -np.ones((i.max() + 1, j.max() + 1), np.int64)
    idx[i, j] = np.arange(len(x))
    a, b, c, d = (idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel())
    ok = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
    tri = np.concatenate([np.stack([a, b, d], 1)[ok], np.stack([a, d, c], 1)[ok]])
    p, q, r = tri[:, 0], tri[:, 1], tri[:, 2]
    area = 0.5 * ((x[q] - x[p]) * (y[r] - y[p]) - (x[r] - x[p]) * (y[q] - y[p]))
    return (area / (0.5 * spacing * spacing), (x[p] + x[q] + x[r]) / 3.0, (y[p] + y[q] + y[r]) / 3.0, tri)


def rms(d) -> float:
    """Root mean square of a difference series, sqrt(mean(d^2))."""
    return float(np.sqrt(np.mean(np.asarray(d) ** 2)))


def self_weight_error(scene, df, material: str = "soil") -> tuple[np.ndarray, np.ndarray, float]:
    """(y0, sigma_yy error / (rho g H), H) of the material points `df` of a column on a base at the lowest point of
    the first MPM body: against sigma_yy(y0) = -rho g (H - y0) in the reference coordinate y0 = y - uy."""
    from validation.analytic import geostatic_stress
    mat = scene.materials[material]
    g = -float(scene.gravity[1])
    lo, hi = scene_mpm_body_extent(scene)
    H = float(hi[1] - lo[1])
    y0 = (df["y"] - df["uy"]).to_numpy() - float(lo[1])
    err = (df["syy"].to_numpy() - geostatic_stress(mat.density, g, H, y0)) / (mat.density * g * H)
    return y0 + float(lo[1]), err, H
