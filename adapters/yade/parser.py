"""Read the CSV files the YADE script wrote into the result tables."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from coupler.results import BODY_COLUMNS, CONTACT_COLUMNS, ENERGY_COLUMNS
from coupler.scene import Scene


def parse(scene: Scene, out: Path) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    dem = scene.dem
    names = np.array(dem.names, dtype=object)
    b = pd.read_csv(out / "bodies_yade.csv", dtype={"id": str})
    ids = b.pop("id")
    b.insert(1, "body", [n[2:] if n.startswith("c:") else names[int(n)] for n in ids])
    # quaternion relative to the initial orientation (P12): spheres start at identity in YADE, so ori is it
    bodies = b[BODY_COLUMNS]
    c = pd.read_csv(out / "contacts_yade.csv", dtype={"i": str, "j": str})

    def body_name(n):
        return n if n.startswith("wall:") else (n[2:] if n.startswith("c:") else names[int(n)])

    if len(c):
        c["i"] = [body_name(n) for n in c["i"]]
        c["j"] = [body_name(n) for n in c["j"]]
    contacts = c[CONTACT_COLUMNS]
    r = dem.radius
    mass = np.array([scene.materials[m].density for m in dem.material]) * 4.0 / 3.0 * math.pi * r ** 3
    index = {n: k for k, n in enumerate(dem.names)}
    from coupler.dem.clusters import mass_properties
    cl = {c.name: mass_properties(dem.templates[c.template], scene.materials[c.material].density, "")
          for c in dem.clusters}
    rows = []
    for t, g in b.groupby("t", sort=True):
        gs = g[g["body"].isin(index)]
        idx = [index[n] for n in gs["body"]]
        m, I = mass[idx], 0.4 * mass[idx] * r[idx] ** 2
        v = gs[["vx", "vy", "vz"]].to_numpy()
        w = gs[["wx", "wy", "wz"]].to_numpy()
        x = gs[["x", "y", "z"]].to_numpy()
        kin = 0.5 * float(np.sum(m * (v ** 2).sum(1)) + np.sum(I * (w ** 2).sum(1)))
        pot = -float(np.sum(m * (x @ scene.gravity)))
        for row in g[g["body"].isin(cl)].itertuples(index=False):      # clusters: M, I about the COM (template
            mp = cl[row.body]                                          # frame) turned by the reported orientation
            R = _rotation(row.qw, row.qx, row.qy, row.qz)
            vv = np.array([row.vx, row.vy, row.vz])
            ww = np.array([row.wx, row.wy, row.wz])
            kin += 0.5 * mp.mass * float(vv @ vv) + 0.5 * float(ww @ (R @ mp.inertia @ R.T) @ ww)
            pot -= mp.mass * float(np.array([row.x, row.y, row.z]) @ scene.gravity)
        rows.append((t, kin, pot, np.nan, np.nan))
    return bodies, contacts, pd.DataFrame(rows, columns=ENERGY_COLUMNS)


def _rotation(w: float, x: float, y: float, z: float) -> np.ndarray:
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
