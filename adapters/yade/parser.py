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
    b = pd.read_csv(out / "bodies_yade.csv")
    b.insert(1, "body", names[b.pop("id").to_numpy()])
    # quaternion relative to the initial orientation (P12): spheres start at identity in YADE, so ori is it
    bodies = b[BODY_COLUMNS]
    c = pd.read_csv(out / "contacts_yade.csv", dtype={"j": str})
    if len(c):
        c["i"] = names[c["i"].to_numpy()]
        isw = c["j"].str.startswith("wall:")
        c.loc[~isw, "j"] = names[c.loc[~isw, "j"].astype(int).to_numpy()]
    contacts = c[CONTACT_COLUMNS]
    r = dem.radius
    mass = np.array([scene.materials[m].density for m in dem.material]) * 4.0 / 3.0 * math.pi * r ** 3
    index = {n: k for k, n in enumerate(dem.names)}
    rows = []
    for t, g in b.groupby("t", sort=True):
        idx = [index[n] for n in g["body"]]
        m, I = mass[idx], 0.4 * mass[idx] * r[idx] ** 2
        v = g[["vx", "vy", "vz"]].to_numpy()
        w = g[["wx", "wy", "wz"]].to_numpy()
        x = g[["x", "y", "z"]].to_numpy()
        rows.append((t, 0.5 * float(np.sum(m * (v ** 2).sum(1)) + np.sum(I * (w ** 2).sum(1))),
                     -float(np.sum(m * (x @ scene.gravity))), np.nan, np.nan))
    return bodies, contacts, pd.DataFrame(rows, columns=ENERGY_COLUMNS)
