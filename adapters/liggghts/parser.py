"""Read LIGGGHTS dumps back into the result tables (coupler/results.py)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from adapters.geometry import closest_points
from adapters.liggghts.writer import walls
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
    specs = facts.get("walls") or walls(scene)[0]
    body_frames, energy_rows, contact_frames = [], [], []
    for step, a in atoms:
        t = step * dt
        if a.size == 0:                            # no free spheres (clusters only)
            continue
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
        # wall contacts: per-wall force on each sphere (store_force), overlap from the wall position at t
        for k, wl in enumerate(specs):
            f = a[:, 10 + 3 * k:13 + 3 * k]
            hit = np.abs(f).sum(1) > 0
            if not hit.any():
                continue
            if wl["kind"] == "mesh":                   # one row per sphere and mesh: the sum of its contacts
                q, dist = closest_points(x[hit], wl["vertices"][wl["triangles"]] + wl["velocity"] * t)
                nrm = (x[hit] - q) / dist[:, None]
                ov = r[idx[hit]] - dist
            else:
                dist = (x[hit] - (wl["point"] + wl["velocity"] * t)) @ wl["normal"]
                nrm = np.broadcast_to(wl["normal"], (int(hit.sum()), 3))
                ov = r[idx[hit]] - dist
            keep = ov > 0
            fs, nrm, ov = f[hit][keep], nrm[keep], ov[keep]
            if len(fs):
                fn = np.einsum("ij,ij->i", fs, nrm)    # the wall pushes along its normal
                ft = np.linalg.norm(fs - fn[:, None] * nrm, axis=1)
                contact_frames.append(pd.DataFrame({"t": t, "i": names[idx[hit][keep]], "j": f"wall:{wl['name']}",
                                                    "fx": fs[:, 0], "fy": fs[:, 1], "fz": fs[:, 2], "fn": fn,
                                                    "ft": ft, "overlap": ov}))
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
    if dem.clusters:
        cluster_frames, cluster_energy = parse_multisphere(scene, out, dt)
        body_frames = _merge_by_time(body_frames, cluster_frames)
        energy_rows = _add_energy(energy_rows, cluster_energy)
    bodies = pd.concat(body_frames, ignore_index=True)[BODY_COLUMNS] if body_frames else pd.DataFrame(columns=BODY_COLUMNS)
    if any(wl["kind"] == "plane_mesh" for wl in specs):
        check_cover(scene, bodies, facts.get("cover") or walls(scene)[1])
    contacts = (pd.concat(contact_frames, ignore_index=True).sort_values(["t", "i"], kind="stable")[CONTACT_COLUMNS]
                .reset_index(drop=True) if contact_frames else pd.DataFrame(columns=CONTACT_COLUMNS))
    energy = pd.DataFrame(energy_rows, columns=ENERGY_COLUMNS)
    return bodies, contacts, energy


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of rows of (w, x, y, z) quaternions."""
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.column_stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def parse_multisphere(scene: Scene, out: Path, dt: float) -> tuple[list[pd.DataFrame], dict[float, tuple]]:
    """bodies.dump (compute multisphere: id, xcm, vcm, quat (w,x,y,z), omega, angmom) -> body rows. Bodies are
    matched to the scene clusters by their initial centre of mass; the orientation is reported as the rotation
    since t = 0 applied to the scene orientation (notes P12), the native convention. Kinetic energy from vcm,
    omega and angmom (P16: LIGGGHTS' own multisphere energy is wrong)."""
    dem = scene.dem
    frames = read_dump(out / "bodies.dump")
    if not frames:
        raise RuntimeError(f"LIGGGHTS wrote no multisphere body output ({out / 'bodies.dump'})")
    com0 = np.array([c.position for c in dem.clusters])
    q_scene = np.array([c.orientation for c in dem.clusters])
    mass = {}
    from coupler.dem.clusters import mass_properties
    for c in dem.clusters:
        mass[c.name] = mass_properties(dem.templates[c.template], scene.materials[c.material].density, "").mass
    first = frames[0][1]
    name_of, q0_of = {}, {}
    for row in first:
        k = int(np.argmin(np.linalg.norm(com0 - row[1:4], axis=1)))
        if np.linalg.norm(com0[k] - row[1:4]) > 1e-9:
            raise RuntimeError(f"LIGGGHTS body {int(row[0])} starts at {row[1:4]}, no scene cluster there")
        name_of[int(row[0])] = k
        q0_of[int(row[0])] = row[7:11] / np.linalg.norm(row[7:11])
    if sorted(name_of.values()) != list(range(len(dem.clusters))):
        raise RuntimeError("LIGGGHTS multisphere bodies do not match the scene clusters one to one")
    out_frames, energy = [], {}
    for step, a in frames:
        t = step * dt
        ids = a[:, 0].astype(int)
        k = np.array([name_of[i] for i in ids])
        q = a[:, 7:11] / np.linalg.norm(a[:, 7:11], axis=1)[:, None]
        q0inv = np.array([q0_of[i] * [1.0, -1.0, -1.0, -1.0] for i in ids])
        qr = _qmul(_qmul(q, q0inv), q_scene[k])
        names = [dem.clusters[j].name for j in k]
        out_frames.append(pd.DataFrame({"t": t, "body": names, "x": a[:, 1], "y": a[:, 2], "z": a[:, 3],
                                        "vx": a[:, 4], "vy": a[:, 5], "vz": a[:, 6], "qw": qr[:, 0], "qx": qr[:, 1],
                                        "qy": qr[:, 2], "qz": qr[:, 3], "wx": a[:, 11], "wy": a[:, 12],
                                        "wz": a[:, 13]}).sort_values("body", key=lambda s_: s_.map(
                                            {c.name: j for j, c in enumerate(dem.clusters)})))
        m = np.array([mass[n] for n in names])
        kin = 0.5 * float(np.sum(m * (a[:, 4:7] ** 2).sum(1)) + np.sum((a[:, 11:14] * a[:, 14:17]).sum(1)))
        pot = -float(np.sum(m * (a[:, 1:4] @ scene.gravity)))
        energy[round(t, 12)] = (kin, pot)
    return out_frames, energy


def _merge_by_time(spheres: list[pd.DataFrame], clusters: list[pd.DataFrame]) -> list[pd.DataFrame]:
    """Free-sphere rows then cluster rows at each output time (the native order)."""
    by_t: dict[float, list[pd.DataFrame]] = {}
    for f in spheres + clusters:
        by_t.setdefault(round(float(f["t"].iloc[0]), 12), []).append(f)
    return [pd.concat(by_t[t], ignore_index=True) for t in sorted(by_t)]


def _add_energy(rows: list[tuple], cluster: dict[float, tuple]) -> list[tuple]:
    free = {round(r[0], 12): r for r in rows}
    out = []
    for t in sorted(set(free) | set(cluster)):
        k, p = cluster.get(t, (0.0, 0.0))
        r = free.get(t, (t, 0.0, 0.0, np.nan, np.nan))
        out.append((r[0], r[1] + k, r[2] + p, np.nan, np.nan))
    return out


def check_cover(scene: Scene, bodies: pd.DataFrame, cover: tuple[np.ndarray, np.ndarray]) -> None:
    """A plane written as a mesh polygon (writer.walls) is a plane only inside the covered region: every body must
    have stayed in it, at its bounding radius, for the whole run; else the run is not the scene's."""
    dem = scene.dem
    rb = max([float(dem.radius.max()) if dem.n_spheres else 0.0]
             + [float(np.linalg.norm(dem.templates[c.template].offsets, axis=1).max()
                      + dem.templates[c.template].radii.max()) for c in dem.clusters])
    x = bodies[["x", "y", "z"]].to_numpy(float)
    bad = np.any((x < cover[0] + rb) | (x > cover[1] - rb), axis=1)
    if bad.any():
        row = bodies.iloc[int(np.argmax(bad))]
        raise RuntimeError(f"LIGGGHTS: body {row['body']} reached {x[int(np.argmax(bad))].tolist()} at "
                           f"t = {row['t']:g} s, outside the region [{cover[0].tolist()}, {cover[1].tolist()}] where the planes that "
                           f"move or tilt are written as mesh polygons; the run does not represent the scene")
