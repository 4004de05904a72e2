"""Read what run_kratos.py recorded back into the result tables (coupler/results.py)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from adapters.geometry import closest_points
from coupler.results import BODY_COLUMNS, CONTACT_COLUMNS, ENERGY_COLUMNS, MPM_BODY_COLUMNS
from coupler.scene import Scene

GAMMA_RTOL = 1e-9


def check_damping(out: Path) -> list[dict]:
    """The DAMPING_GAMMA Kratos derived for every contact pair must be the native beta (params.py)."""
    gam = json.loads((out / "kratos_gamma.json").read_text())
    for g in gam:
        if abs(g["gamma"] - g["beta_native"]) > GAMMA_RTOL * max(1e-300, abs(g["beta_native"])) + 1e-15:
            raise RuntimeError(f"Kratos damping for {g['a']}-{g['b']}: DAMPING_GAMMA {g['gamma']!r} != native beta "
                               f"{g['beta_native']!r} (parameter map adapters/kratos/params.py)")
    return gam


def _walls(scene: Scene):
    dem = scene.dem
    out = []
    for p in dem.planes:
        out.append(("plane", p.name, np.asarray(p.point, float), np.asarray(p.normal, float),
                    np.asarray(p.velocity, float)))
    for m in dem.meshes:
        out.append(("mesh", m.name, np.asarray(m.vertices, float)[np.asarray(m.faces)], None,
                    np.asarray(m.velocity, float)))
    return out


def check_cover(scene: Scene, bodies: pd.DataFrame, cover: list[dict]) -> None:
    """A plane is written as one finite quadrilateral: every sphere must have stayed over it (params.py)."""
    r = float(scene.dem.radius.max()) if scene.dem.n_spheres else 0.0
    x = bodies[["x", "y", "z"]].to_numpy(float)
    for c in cover:
        n = np.asarray(c["normal"])
        d = x - np.asarray(c["centre"])
        inplane = d - (d @ n)[:, None] * n
        far = np.max(np.abs(inplane), axis=1) > c["half"] - r
        if far.any():
            k = int(np.argmax(far))
            raise RuntimeError(f"Kratos: body {bodies['body'].iloc[k]} left the quadrilateral that represents plane "
                               f"{c['wall']} (half size {c['half']:g} m) at t = {bodies['t'].iloc[k]:g} s")


def parse_dem(scene: Scene, out: Path, facts: dict) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, dict]:
    dem = scene.dem
    dt = facts["dt"]
    names = np.array(dem.names, dtype=object)
    r = dem.radius
    mass = np.array([scene.materials[m].density for m in dem.material]) * 4.0 / 3.0 * math.pi * r ** 3
    inertia = 0.4 * mass * r ** 2
    st = pd.read_csv(out / "kratos_states.csv")
    st["t"] = st["step"] * dt
    st["body"] = names[st["id"].to_numpy() - 1]
    for q, v in (("qw", np.nan), ("qx", np.nan), ("qy", np.nan), ("qz", np.nan)):
        st[q] = v                              # Kratos spheres: orientation not read back
    bodies = st[BODY_COLUMNS].reset_index(drop=True)
    if facts.get("cover"):
        check_cover(scene, bodies, facts["cover"])
    rows = []
    for step, g in st.groupby("step", sort=True):
        idx = g["id"].to_numpy() - 1
        v, w, x = g[["vx", "vy", "vz"]].to_numpy(), g[["wx", "wy", "wz"]].to_numpy(), g[["x", "y", "z"]].to_numpy()
        kin = 0.5 * float(np.sum(mass[idx] * (v ** 2).sum(1)) + np.sum(inertia[idx] * (w ** 2).sum(1)))
        pot = -float(np.sum(mass[idx] * (x @ scene.gravity)))
        rows.append((step * dt, kin, pot, np.nan, np.nan))
    energy = pd.DataFrame(rows, columns=ENERGY_COLUMNS)
    contacts, not_split = _contacts(scene, out, st, dt)
    return bodies, contacts, energy, {"contacts_not_split": not_split}


def _contacts(scene: Scene, out: Path, st: pd.DataFrame, dt: float) -> tuple[pd.DataFrame, int]:
    """One row per sphere whose CONTACT_FORCES comes from exactly one geometric contact (params.py)."""
    dem = scene.dem
    names = np.array(dem.names, dtype=object)
    r = dem.radius
    fr = pd.read_csv(out / "kratos_forces.csv")
    walls = _walls(scene)
    pos = {s: g.sort_values("id")[["x", "y", "z"]].to_numpy() for s, g in st.groupby("step")}
    frames, not_split = [], 0
    for step, g in fr.groupby("step", sort=True):
        if step not in pos:
            continue
        t = step * dt
        x = pos[step]
        forces = {int(i) - 1: f for i, f in zip(g["id"], g[["fx", "fy", "fz"]].to_numpy())}
        touch: dict[int, list] = {i: [] for i in forces}
        for i in forces:
            for kind, name, geo, nrm, vel in walls:
                if kind == "plane":
                    d = float((x[i] - (geo + vel * t)) @ nrm)
                    if d < r[i]:
                        touch[i].append((f"wall:{name}", nrm, r[i] - d))
                else:
                    q, dist = closest_points(x[i:i + 1], geo + vel * t)
                    k = int(np.argmin(dist))
                    if dist[k] < r[i]:
                        touch[i].append((f"wall:{name}", (x[i] - q[0, k] if q.ndim == 3 else x[i] - q[0]) / dist[k],
                                         r[i] - dist[k]))
            d = np.linalg.norm(x - x[i], axis=1)
            for j in np.nonzero((d < r + r[i]) & (np.arange(len(x)) != i))[0]:
                touch[i].append((int(j), (x[i] - x[j]) / d[j], r[i] + r[j] - d[j]))
        done = set()
        rows = []
        for i, f in forces.items():
            if len(touch[i]) != 1:
                not_split += 1
                continue
            j, n, ov = touch[i][0]
            if isinstance(j, int):
                a, b = min(i, j), max(i, j)
                if (a, b) in done:
                    continue
                done.add((a, b))
                if i != a:                              # the row is written for the lower index: force on a
                    f, n = -f, -n
                i, j = a, names[b]
            fn = float(f @ n)
            ft = float(np.linalg.norm(f - fn * n))
            rows.append((t, names[i], j, f[0], f[1], f[2], fn, ft, ov))
        if rows:
            frames.append(pd.DataFrame(rows, columns=CONTACT_COLUMNS))
    contacts = (pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=CONTACT_COLUMNS))
    return contacts[CONTACT_COLUMNS], not_split


PARTICLE_COLUMNS = ["t", "id", "body", "x", "y", "vx", "vy", "sxx", "syy", "sxy", "szz", "eps_p", "mass", "volume",
                    "ux", "uy"]


def mpm_body_table(rows: pd.DataFrame) -> pd.DataFrame:
    """The MPM body table (coupler/results.py MPM_BODY_COLUMNS) from Kratos' per-step body series: time, body,
    mass-weighted centre and velocity; the columns the series does not record are NaN."""
    out = rows.reindex(columns=MPM_BODY_COLUMNS)
    return out.astype({c: float for c in MPM_BODY_COLUMNS if c not in ("body",)})


def parse_mpm(scene: Scene, out: Path, facts: dict):
    """Material-point snapshots (the native particles_frame columns; eps_p is not read back: NaN; every
    snapshot_every output times), one MPM body row (mpm_bodies) per body and output time (mass-weighted centre and velocity, as
    native), energies from Kratos'
    EnergyCalculationUtility (potential, kinetic, strain)."""
    dt = facts["dt"]
    names = facts["bodies"]
    p = pd.read_csv(out / "kratos_particles.csv")
    p["t"] = p["step"] * dt
    p["eps_p"] = np.nan
    p["body"] = [names[int(b)] for b in p["body"]]
    particles = [(step * dt, g.sort_values("id")[PARTICLE_COLUMNS].reset_index(drop=True))
                 for step, g in p.groupby("step", sort=True)]
    s = pd.read_csv(out / "kratos_series.csv")
    bodies = mpm_body_table(pd.DataFrame({"t": s["step"] * dt, "body": [names[int(b)] for b in s["body"]],
                                          "x": s["x"], "y": s["y"], "vx": s["vx"], "vy": s["vy"]}))
    e = pd.read_csv(out / "kratos_energy.csv")
    energy = pd.DataFrame({"t": e["step"] * dt, "kinetic": e["kinetic"], "potential": e["potential"],
                           "elastic": e["strain"], "dissipated": np.nan})[ENERGY_COLUMNS]
    timing = json.loads((out / "timing_kratos.json").read_text())
    extra = {"particles": int(timing["n_points"]), "shape_note": facts["shape_note"],
             **{k: timing[k] for k in ("newton_iterations_total", "newton_iterations_max", "newton_iterations_mean")
                if k in timing},
             **({"initial_stress_note": facts["initial_stress_note"]} if "initial_stress_note" in facts else {}),
             **({"friction_note": facts["friction_note"]} if "friction_note" in facts else {}),
             "transfer_note": facts["transfer_note"], "time_integration": "implicit Newmark (beta 0.25, gamma 0.5)",
             "energy_note": "Kratos EnergyCalculationUtility: kinetic, potential, strain (elastic); dissipated NaN"}
    return bodies, pd.DataFrame(columns=CONTACT_COLUMNS), energy, particles, extra


def parse_coupled(scene: Scene, out: Path, facts: dict):
    """Coupled CoSimulation run (cosim.py): bodies (the DEM discs: 2D, per unit depth in Kratos; positions z = 0,
    orientation NaN), mpm_bodies and particle snapshots of the MPM body, interface (the total force on the DEM
    RigidFacePart nodes and the total CONTACT_FORCE the MPM coupling nodes received, per unit depth in Kratos; both
    multiplied by the scene thickness so that they compare with the native interface.csv, which is in N for one
    DEM layer; work columns NaN), energy NaN (not read back)."""
    from coupler.results import INTERFACE_COLUMNS
    dt = facts["dt"]
    th = facts["thickness_native"]
    names = np.array(facts["spheres"], dtype=object)
    st = pd.read_csv(out / "kratos_states.csv")
    b = pd.DataFrame({"t": st["step"] * dt, "body": names[st["id"].to_numpy() - 1], "x": st["x"], "y": st["y"],
                      "z": 0.0, "vx": st["vx"], "vy": st["vy"], "vz": 0.0, "qw": np.nan, "qx": np.nan,
                      "qy": np.nan, "qz": np.nan, "wx": 0.0, "wy": 0.0, "wz": st["wz"]})[BODY_COLUMNS]
    p = pd.read_csv(out / "kratos_particles.csv")
    body = facts["bodies"][0]
    particles, rows = [], []
    for step, g in p.groupby("step", sort=True):
        g = g.sort_values("id")
        t = step * dt
        df = pd.DataFrame({"t": t, "id": g["id"].to_numpy(), "body": body, "x": g["x"], "y": g["y"], "vx": g["vx"],
                           "vy": g["vy"], "sxx": g["sxx"], "syy": g["syy"], "sxy": g["sxy"], "szz": np.nan,
                           "eps_p": np.nan, "mass": g["mass"], "volume": g["volume"], "ux": g["ux"],
                           "uy": g["uy"]})[PARTICLE_COLUMNS].reset_index(drop=True)
        particles.append((t, df))
        m = df["mass"].to_numpy()
        M = m.sum()
        rows.append({"t": t, "body": body, "mass": M, "x": float((m * df["x"]).sum() / M),
                     "y": float((m * df["y"]).sum() / M), "vx": float((m * df["vx"]).sum() / M),
                     "vy": float((m * df["vy"]).sum() / M),
                     "kinetic": 0.5 * float(np.sum(m * (df["vx"] ** 2 + df["vy"] ** 2))),
                     "ux": float((m * df["ux"]).sum() / M), "uy": float((m * df["uy"]).sum() / M),
                     "ux_max": float(df["ux"].max()), "uy_min": float(df["uy"].min()),
                     "xmin": float(df["x"].min()), "xmax": float(df["x"].max()), "ymin": float(df["y"].min()),
                     "ymax": float(df["y"].max()), "eps_p_max": np.nan, "n_points": len(df)})
    mb = pd.DataFrame(rows).reindex(columns=MPM_BODY_COLUMNS)
    f = pd.read_csv(out / "kratos_interface.csv")
    iface = pd.DataFrame({"t": f["step"] * dt, "fx_dem": f["fx_dem"] * th, "fy_dem": f["fy_dem"] * th,
                          "fx_mpm": f["fx_mpm"] * th, "fy_mpm": f["fy_mpm"] * th, "work_dem": np.nan,
                          "work_mpm": np.nan})[INTERFACE_COLUMNS]
    energy = pd.DataFrame({"t": sorted(set(b["t"])), "kinetic": np.nan, "potential": np.nan, "elastic": np.nan,
                           "dissipated": np.nan})[ENERGY_COLUMNS]
    timing = json.loads((out / "timing_kratos.json").read_text())
    extra = {"particles": int(timing["n_points"]), "time_integration": "implicit Newmark (MPM), Symplectic Euler "
             "(DEM), CoSimulation gauss_seidel_weak, DEM first", "dem_2d": "CylinderParticle2D (per unit depth)",
             "interface_note": "interface forces x scene thickness (Kratos 2D is per unit depth); work NaN",
             "energy_note": "not read back (NaN)"}
    return b, mb, energy, particles, iface, extra
