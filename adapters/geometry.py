"""Wall geometry shared by the adapters: scene mesh walls as triangles (a 2D segment mesh becomes a strip of
triangles along z), a plane as one triangle covering a box (for codes whose flat walls cannot move or tilt),
ASCII STL output, and sphere-to-triangle distances for reading wall contacts back."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def mesh_triangles(vertices: np.ndarray, faces: np.ndarray, half_depth: float) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, triangles) of a scene mesh. Triangles are returned as they are. Segments (2D scenes, all z = 0)
    become strips z in [-half_depth, half_depth], two triangles each: a sphere centred in the plane z = 0 then
    meets the strip's face where it met the segment and the strip's z-edges where it met a segment end."""
    vertices = np.asarray(vertices, float)
    faces = np.asarray(faces, np.int64)
    if faces.shape[1] == 3:
        return vertices.copy(), faces.copy()
    nv = len(vertices)
    dz = np.array([0.0, 0.0, half_depth])
    v = np.vstack([vertices - dz, vertices + dz])            # k: lower copy, nv + k: upper copy
    a, b = faces[:, 0], faces[:, 1]
    tri = np.concatenate([np.column_stack([a, b, nv + b]), np.column_stack([a, nv + b, nv + a])])
    return v, tri


def plane_triangle(point: np.ndarray, normal: np.ndarray, lo: np.ndarray, hi: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """One triangle of the plane (point, normal) that contains the plane's whole section of the box [lo, hi]
    (vertices (3, 3), triangles [[0, 1, 2]]): the right triangle with legs twice the sides of the rectangle in which
    the box projects onto the plane. One triangle has no inner edge a contact could cross. Raises ValueError when
    the plane misses the box."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    corners = np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]
                        for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    s = (corners - point) @ n
    if s.min() > 0.0 or s.max() < 0.0:
        raise ValueError("the plane does not cut the box")
    e1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    u, w = (corners - point) @ e1, (corners - point) @ e2
    u0, w0 = u.min(), w.min()
    du, dw = 2.0 * (u.max() - u0), 2.0 * (w.max() - w0)
    tri = np.array([point + u0 * e1 + w0 * e2, point + (u0 + du) * e1 + w0 * e2, point + u0 * e1 + (w0 + dw) * e2])
    if np.cross(tri[1] - tri[0], tri[2] - tri[0]) @ n < 0.0:
        tri = tri[[0, 2, 1]]
    return tri, np.array([[0, 1, 2]], np.int64)


def write_stl(path: Path, vertices: np.ndarray, triangles: np.ndarray, name: str = "wall") -> None:
    """ASCII STL, full double precision; facet normals from the vertex order."""
    lines = [f"solid {name}"]
    for t in triangles:
        a, b, c = vertices[t]
        nrm = np.cross(b - a, c - a)
        nrm = nrm / np.linalg.norm(nrm)
        lines.append(f"  facet normal {nrm[0]:.17g} {nrm[1]:.17g} {nrm[2]:.17g}")
        lines.append("    outer loop")
        for p in (a, b, c):
            lines.append(f"      vertex {p[0]:.17g} {p[1]:.17g} {p[2]:.17g}")
        lines.append("    endloop")
        lines.append("  endfacet")
    lines.append(f"endsolid {name}")
    Path(path).write_text("\n".join(lines) + "\n")


def closest_points(p: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point p[i] (n, 3), the closest point on the triangles tri (m, 3, 3) and its distance
    (Ericson 2005, 5.1.5, vectorised). Returns (points (n, 3), distances (n,))."""
    p = np.asarray(p, float)[:, None, :]                     # (n, 1, 3)
    a, b, c = tri[None, :, 0], tri[None, :, 1], tri[None, :, 2]
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c
    dot = lambda u, v: np.einsum("...k,...k->...", u, v)    # noqa: E731
    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = 1.0 / (va + vb + vc)
        q = a + ab * (vb * denom)[..., None] + ac * (vc * denom)[..., None]          # face interior
        cases = [
            (d1 <= 0) & (d2 <= 0), a,
            (d3 >= 0) & (d4 <= d3), b,
            (vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * (d1 / (d1 - d3))[..., None],
            (d6 >= 0) & (d5 <= d6), c,
            (vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * (d2 / (d2 - d6))[..., None],
            (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0),
            b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[..., None],
        ]
    done = np.zeros(q.shape[:2], bool)
    for k in range(0, len(cases), 2):                        # the first region that applies wins (Ericson order)
        sel = cases[k] & ~done
        q = np.where(sel[..., None], np.broadcast_to(cases[k + 1], q.shape), q)
        done |= sel
    dist = np.linalg.norm(p - q, axis=2)                     # (n, m)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(best))
    return q[rows, best], dist[rows, best]
