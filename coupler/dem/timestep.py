"""Stable DEM time step.

Limit (stated, checked at scene load):  dt_max = min(0.5 t_R, t_H / 10)
  t_R = pi R sqrt(rho/G) / (0.1631 nu + 0.8766)         Rayleigh time of the smallest sphere (Li et al. 2005)
  t_H = 2.87 (m*^2 / (R* E*^2 v))^(1/5)                  Hertz contact time (Johnson 1985) at the largest
                                                          expected impact speed v = max(2 |v0|_max, sqrt(2 |g| H), 0.1)
with H the height of the sphere cloud above its lowest point plus its extent. Contacts considered: every sphere
kind with itself (R* = R/2, m* = m/2), every pair of sphere materials at their smallest radii (a stiff and a soft
material in one scene: steel on rubber), and every sphere material against every wall material at its smallest
radius (R* = R, m* = m; E* of the pair, or E/(1-nu^2) for a rigid wall): a wall stiffer than the spheres is a
shorter contact than two spheres. The default step is
`time.dt_safety` (0.4) x dt_max. A forced `time.dt` is refused when it exceeds dt_max, and first when a sphere at
the impact speed v would move more than half the smallest radius in one step (tunnelling: a zero-thickness mesh wall
crossed by the sphere centre within a step pushes it out on the far side). Sub-models with their own stiffness add limits (coupler/dem/contact/law.py
time_limits: Hooke contact time / 10, constant rolling-spring period / 10).
"""
from __future__ import annotations

import math

import numpy as np

from coupler.errors import SceneError
from coupler.materials import rayleigh_time
from coupler.scene import Scene


def hertz_contact_time(estar: float, rstar: float, mstar: float, v: float) -> float:
    return 2.87 * (mstar * mstar / (rstar * estar * estar * v)) ** 0.2


def sphere_catalogue(scene: Scene):
    """(radius, material) of every sphere kind in the scene, with its body mass for the impact estimate."""
    dem = scene.dem
    out = []
    for r, m in zip(dem.radius, dem.material):
        out.append((float(r), m))
    for c in dem.clusters:
        t = dem.templates[c.template]
        for r in t.radii:
            out.append((float(r), c.material))
    return out


def stable_dt(scene: Scene) -> tuple[float, str]:
    """Largest stable step and a one-line explanation of what limits it."""
    from coupler.dem.contact import effective_young
    dem = scene.dem
    cat = sorted(set(sphere_catalogue(scene)))
    v_ref = impact_speed(scene)
    best = (math.inf, "")
    for r, mname in cat:
        mat = scene.materials[mname]
        tr = 0.5 * rayleigh_time(mat, r)
        if tr < best[0]:
            best = (tr, f"0.5 x Rayleigh time of a sphere R={r:g} m ({mname})")
        m = mat.density * 4.0 / 3.0 * math.pi * r ** 3
        # sphere-sphere of the same kind (R* = R/2, m* = m/2) is the shortest contact
        estar = effective_young(mat, mat)
        th = hertz_contact_time(estar, 0.5 * r, 0.5 * m, v_ref) / 10.0
        if th < best[0]:
            best = (th, f"Hertz contact time / 10 at impact speed {v_ref:.3g} m/s, R={r:g} m ({mname})")
    # the shortest contact between two materials, or a material and a wall, is at the smallest radius of each
    rmin: dict[str, float] = {}
    for r, mname in cat:
        rmin[mname] = min(r, rmin.get(mname, math.inf))

    def mass(mname: str) -> float:
        return scene.materials[mname].density * 4.0 / 3.0 * math.pi * rmin[mname] ** 3
    names = sorted(rmin)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            ma, mb, ra, rb = mass(a), mass(b), rmin[a], rmin[b]
            estar = effective_young(scene.materials[a], scene.materials[b])
            th = hertz_contact_time(estar, ra * rb / (ra + rb), ma * mb / (ma + mb), v_ref) / 10.0
            if th < best[0]:
                best = (th, f"Hertz contact time / 10 at impact speed {v_ref:.3g} m/s, {a} R={ra:g} m on {b} "
                            f"R={rb:g} m")
    for w in list(dem.planes) + list(dem.meshes):
        wmat = scene.materials[w.material]
        for a in names:
            mat = scene.materials[a]
            estar = mat.young / (1.0 - mat.poisson ** 2) if w.rigid else effective_young(mat, wmat)
            th = hertz_contact_time(estar, rmin[a], mass(a), v_ref) / 10.0
            if th < best[0]:
                kind = "a rigid wall" if w.rigid else f"wall {w.name} ({w.material})"
                best = (th, f"Hertz contact time / 10 against {kind} at impact speed {v_ref:.3g} m/s, "
                            f"R={rmin[a]:g} m ({a})")
    from coupler.dem.contact.law import time_limits          # Hooke normal, constant rolling stiffness
    for lim in time_limits(scene, cat):
        if lim[0] < best[0]:
            best = lim
    return best


def impact_speed(scene: Scene) -> float:
    """The largest expected impact speed of the stable-step estimate (module docstring)."""
    dem = scene.dem
    cat = sphere_catalogue(scene)
    pts = [dem.position] if dem.n_spheres else []
    pts += [c.position[None, :] for c in dem.clusters]
    height = float(np.ptp(np.concatenate(pts), axis=0).max()) + 2.0 * max(r for r, _ in cat)
    vmax = max([float(np.linalg.norm(dem.velocity, axis=1).max()) if dem.n_spheres else 0.0]
               + [float(np.linalg.norm(c.velocity)) for c in dem.clusters])
    return max(2.0 * vmax, math.sqrt(2.0 * scene.gravity_max * height), 0.1)


def tunnelling_dt(scene: Scene) -> tuple[float, str]:
    """Largest step at which a sphere at the impact speed moves at most half the smallest radius per step."""
    v = impact_speed(scene)
    r = min(r for r, _ in sphere_catalogue(scene))
    return 0.5 * r / v, f"a sphere at the impact speed {v:.3g} m/s may move at most half the smallest radius " \
                        f"({0.5 * r:g} m) per step, or it tunnels through a thin wall"


def check_time_step(scene: Scene) -> None:
    dt_max, why = stable_dt(scene)
    if scene.time.dt is not None:
        dt_tun, why_tun = tunnelling_dt(scene)
        if scene.time.dt > dt_tun:
            raise SceneError("time.dt", f"must be <= {min(dt_tun, dt_max):.4g} s ({why_tun}; stable limit "
                                        f"{dt_max:.4g} s), got {scene.time.dt:g}")
    if scene.time.dt is not None and scene.time.dt > dt_max:
        raise SceneError("time.dt", f"must be <= {dt_max:.4g} s (stable limit: {why}), got {scene.time.dt:g}")
    if getattr(scene, "coupling", None) is None:     # a coupled run checks it against the coupling step
        from coupler.scene import output_stride
        output_stride(scene, chosen_dt(scene), "the time step")


def chosen_dt(scene: Scene) -> float:
    if scene.time.dt is not None:
        return scene.time.dt
    return scene.time.dt_safety * stable_dt(scene)[0]


def dem_substeps(scene: Scene, dt: float) -> int:
    """DEM steps per coupling step dt (the coupler's, and what the Kratos adapter compares with its one):
    coupling.dem_substeps, or for "auto" ceil(dt / chosen_dt)."""
    sub = scene.coupling.dem_substeps
    return max(1, int(math.ceil(dt / chosen_dt(scene) - 1e-9))) if sub is None else sub
