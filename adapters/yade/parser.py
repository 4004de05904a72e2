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
    rows = []
    for t, g in b.groupby("t", sort=True):
        g = g[g["body"].isin(index)]             # cluster kinetic energy is not reconstructed here
        idx = [index[n] for n in g["body"]]
        m, I = mass[idx], 0.4 * mass[idx] * r[idx] ** 2
        v = g[["vx", "vy", "vz"]].to_numpy()
        w = g[["wx", "wy", "wz"]].to_numpy()
        x = g[["x", "y", "z"]].to_numpy()
        rows.append((t, 0.5 * float(np.sum(m * (v ** 2).sum(1)) + np.sum(I * (w ** 2).sum(1))),
                     -float(np.sum(m * (x @ scene.gravity))), np.nan, np.nan))
    return bodies, contacts, pd.DataFrame(rows, columns=ENERGY_COLUMNS)
