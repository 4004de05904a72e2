"""The coupling interface: MPM boundary particles of the chosen outline edges and the DEM wall polyline.

MPM side: the boundary particles MPMSolver places on each body outline (coupler/mpm/solver.py: for every edge of
length L, k = max(1, round(L / d)) points at the midpoints of k equal pieces, d = cell_size / particles_per_cell),
in outline order, body after body. `outline_points` reproduces that rule so that the scene can be checked (and
the DEM wall built) before any solver exists; the coupled run checks it against the solver's own points.

DEM side: a 2D mesh wall of segments through the interface points in outline order. The selected edges form
chains (runs of consecutive edges); consecutive points of a chain are joined, and a chain that is the whole
outline is closed. With `wall_spacing` the wall nodes are instead placed along each chain polyline at that
spacing (a coarser or finer wall; its kinematics then need the linear mapper).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class InterfaceGeometry:
    body: str
    index: np.ndarray          # (ni,) indices of the interface points in the MPM boundary-particle arrays
    points: np.ndarray         # (ni, 2) their initial positions, outline order
    chains: list               # list of (start, stop, closed) slices into `points` (outline order)
    wall_nodes: np.ndarray     # (nn, 2) DEM wall node positions
    wall_segments: np.ndarray  # (ns, 2) node index pairs
    wall_chains: list          # list of (start, stop, closed) slices into wall_nodes


def outline_points(mpm_scene, body_index: int) -> list[np.ndarray]:
    """Initial boundary-particle positions of one body, one array per outline edge (MPMSolver's rule)."""
    body = mpm_scene.bodies[body_index]
    d = mpm_scene.cell_size / body.particles_per_cell
    poly = body.polygon
    out = []
    for a in range(len(poly)):
        p0, p1 = poly[a], poly[(a + 1) % len(poly)]
        L = float(np.hypot(*(p1 - p0)))
        k = max(1, int(round(L / d)))
        t = (np.arange(k) + 0.5) / k
        out.append(p0 + t[:, None] * (p1 - p0))
    return out


def edge_chains(edges: list[int], n_edges: int) -> list[tuple[list[int], bool]]:
    """Split a sorted set of outline edges into runs of consecutive edges (cyclically); (edges, closed)."""
    es = sorted(set(edges))
    if len(es) == n_edges:
        return [(es, True)]
    sel = set(es)
    starts = [e for e in es if (e - 1) % n_edges not in sel]
    chains = []
    for s in starts:
        run = [s]
        while (run[-1] + 1) % n_edges in sel:
            run.append((run[-1] + 1) % n_edges)
        chains.append((run, False))
    return chains


def _resample(poly: np.ndarray, closed: bool, spacing: float) -> np.ndarray:
    """Nodes along a polyline at (about) `spacing`, ends kept (closed: evenly around the loop)."""
    pts = np.vstack([poly, poly[:1]]) if closed else poly
    seg = np.hypot(*np.diff(pts, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(1, int(round(s[-1] / spacing)))
    ss = np.linspace(0.0, s[-1], n + 1)
    if closed:
        ss = ss[:-1]
    return np.column_stack([np.interp(ss, s, pts[:, 0]), np.interp(ss, s, pts[:, 1])])


def build_interface(mpm_scene, body_index: int, edges: list[int], wall_spacing: float | None) -> InterfaceGeometry:
    per_body = [outline_points(mpm_scene, b) for b in range(len(mpm_scene.bodies))]
    base = sum(sum(len(e) for e in pb) for pb in per_body[:body_index])
    edge_pts = per_body[body_index]
    edge_off = np.concatenate([[0], np.cumsum([len(e) for e in edge_pts])])
    idx, chains, pts = [], [], []
    for run, closed in edge_chains(edges, len(edge_pts)):
        start = len(idx)
        for e in run:
            idx.extend(range(base + edge_off[e], base + edge_off[e + 1]))
            pts.append(edge_pts[e])
        chains.append((start, len(idx), closed))
    points = np.vstack(pts)
    nodes, segs, wchains = [], [], []
    n0 = 0
    for a, b, closed in chains:
        p = points[a:b] if wall_spacing is None else _resample(points[a:b], closed, wall_spacing)
        nodes.append(p)
        k = len(p)
        s = [[n0 + i, n0 + i + 1] for i in range(k - 1)]
        if closed and k > 2:
            s.append([n0 + k - 1, n0])
        segs.extend(s)
        wchains.append((n0, n0 + k, closed))
        n0 += k
    return InterfaceGeometry(mpm_scene.bodies[body_index].name, np.array(idx, np.int64), points, chains,
                             np.vstack(nodes), np.array(segs, np.int64).reshape(-1, 2), wchains)
