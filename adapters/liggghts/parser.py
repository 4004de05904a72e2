"""Read LIGGGHTS dumps back into the result tables (coupler/results.py)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from coupler.results import BODY_COLUMNS, CONTACT_COLUMNS, ENERGY_COLUMNS
from coupler.scene import Scene


def read_dump(path: Path) -> list[tuple[int, np.ndarray]]:
    """LIGGGHTS text dump (custom or local) -> [(timestep, rows)]."""
    out = []
    if not path.exists():
        return out
    blocks = path.read_text().split("ITEM: TIMESTEP")
    for b in blocks[1:]:
        lines = b.strip().splitlines()
        step = int(lines[0])
        k = next(i for i, l in enumerate(lines) if l.startswith("ITEM: ATOMS") or l.startswith("ITEM: ENTRIES"))
        rows = [list(map(float, l.split())) for l in lines[k + 1:] if l.strip()]
        out.append((step, np.array(rows, dtype=float) if rows else np.zeros((0, 0))))
    return out


def parse(scene: Scene, out: Path, facts: dict) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    dem = scene.dem
    dt = facts["dt"]
    names = np.array(dem.names, dtype=object)
    r = dem.radius
    mass = np.array([scene.materials[m].density for m in dem.material]) * 4.0 / 3.0 * math.pi * r ** 3
    inertia = 0.4 * mass * r ** 2
    atoms = read_dump(out / "atoms.dump")
    body_frames, energy_rows, contact_frames = [], [], []
    for step, a in atoms:
        t = step * dt
        idx = a[:, 0].astype(int) - 1
        x, v, w = a[:, 1:4], a[:, 4:7], a[:, 7:10]
        df = pd.DataFrame({"t": t, "body": names[idx], "x": x[:, 0], "y": x[:, 1], "z": x[:, 2],
                           "vx": v[:, 0], "vy": v[:, 1], "vz": v[:, 2],
                           "qw": np.nan, "qx": np.nan, "qy": np.nan, "qz": np.nan,   # not integrated by LIGGGHTS
                           "wx": w[:, 0], "wy": w[:, 1], "wz": w[:, 2]})
        body_frames.append(df)
        m, I = mass[idx], inertia[idx]
        kin = 0.5 * float(np.sum(m * (v ** 2).sum(1)) + np.sum(I * (w ** 2).sum(1)))
        pot = -float(np.sum(m * (x @ scene.gravity)))
        energy_rows.append((t, kin, pot, np.nan, np.nan))
        # wall contacts: per-wall force on each sphere (store_force), overlap from the plane position
        for k, p in enumerate(dem.planes):
            f = a[:, 10 + 3 * k:13 + 3 * k]
            gap = (x - p.point) @ p.normal
            ov = r[idx] - gap
            sel = (ov > 0) & (np.abs(f).sum(1) > 0)
            if sel.any():
                fn = f[sel] @ p.normal                 # the wall pushes along its normal
                ft = np.linalg.norm(f[sel] - np.outer(f[sel] @ p.normal, p.normal), axis=1)
                contact_frames.append(pd.DataFrame({"t": t, "i": names[idx[sel]], "j": f"wall:{p.name}",
                                                    "fx": f[sel, 0], "fy": f[sel, 1], "fz": f[sel, 2], "fn": fn,
                                                    "ft": ft, "overlap": ov[sel]}))
    pos = {step: a for step, a in atoms}
    for step, c in read_dump(out / "pairs.dump"):
        if len(c) == 0 or step not in pos:
            continue
        a = pos[step]
        order = np.argsort(a[:, 0])
        xs = a[order, 1:4]
        i, j = c[:, 0].astype(int) - 1, c[:, 1].astype(int) - 1
        f = c[:, 3:6].copy()
        delta = c[:, 6]
        d = xs[j] - xs[i]
        nrm = d / np.linalg.norm(d, axis=1)[:, None]
        fn = -(f * nrm).sum(1)                      # force on i: the normal part points from j to i
        clamped = fn <= 0.0                        # P11: the compute keeps a stale tangential force here
        f[clamped] = 0.0
        fn[clamped] = 0.0
        ft = np.linalg.norm(f + fn[:, None] * nrm, axis=1)
        sel = delta > 0
        contact_frames.append(pd.DataFrame({"t": step * dt, "i": names[i[sel]], "j": names[j[sel]],
                                            "fx": f[sel, 0], "fy": f[sel, 1], "fz": f[sel, 2], "fn": fn[sel],
                                            "ft": ft[sel], "overlap": delta[sel]}))
    bodies = pd.concat(body_frames, ignore_index=True)[BODY_COLUMNS] if body_frames else pd.DataFrame(columns=BODY_COLUMNS)
    contacts = (pd.concat(contact_frames, ignore_index=True).sort_values(["t", "i"], kind="stable")[CONTACT_COLUMNS]
                .reset_index(drop=True) if contact_frames else pd.DataFrame(columns=CONTACT_COLUMNS))
    energy = pd.DataFrame(energy_rows, columns=ENERGY_COLUMNS)
    return bodies, contacts, energy
