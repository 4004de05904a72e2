"""Linear interpolation along the interface polyline: a wall node is projected on the closest segment between two
consecutive MPM interface points of a chain (closed chains include the closing segment) and takes
(1 - s) u_i + s u_{i+1}; forces go back by the transpose. Affine fields (rigid motions) along the polyline are
reproduced exactly for nodes on it; beyond a chain end the node takes the end point (s clamped)."""
from __future__ import annotations

import numpy as np

from coupler.coupling.mappers.base import Mapper


class LinearMapper(Mapper):
    name = "linear"

    @staticmethod
    def build(origin, chains, dest):
        segs = []
        for a, b, closed in chains:
            segs += [(i, i + 1) for i in range(a, b - 1)]
            if closed and b - a > 2:
                segs.append((b - 1, a))
            if b - a == 1:
                segs.append((a, a))
        S = np.array(segs, np.int64)
        p0, p1 = origin[S[:, 0]], origin[S[:, 1]]
        d = p1 - p0
        dd = np.einsum("ij,ij->i", d, d)
        cols = np.zeros((len(dest), 2), np.int64)
        w = np.zeros((len(dest), 2))
        for k, x in enumerate(dest):
            with np.errstate(invalid="ignore", divide="ignore"):
                s = np.where(dd > 0, np.einsum("ij,ij->i", x - p0, d) / dd, 0.0)
            s = np.clip(s, 0.0, 1.0)
            q = p0 + s[:, None] * d
            j = int(np.argmin(np.einsum("ij,ij->i", x - q, x - q)))
            cols[k] = S[j]
            w[k] = (1.0 - s[j], s[j])
        return cols, w
