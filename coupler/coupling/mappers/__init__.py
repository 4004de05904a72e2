"""Interface mappers: one module each, one registry line each.

A mapper is built from the MPM interface points (origin, outline order, with their chains) and the DEM wall nodes
(destination) and is a matrix M (n_wall x n_mpm), rows summing to 1:
  kinematics(u_mpm) = M u_mpm        consistent (direct) map of displacements / velocities to the wall nodes
  forces(f_wall)    = M^T f_wall     conservative map (transpose) of the wall node forces to the MPM points
Transposition keeps the resultant exactly (rows sum to 1) and the moment whenever M reproduces the node positions
(x_wall = M x_mpm, i.e. the wall nodes lie on the interface), and the virtual work f_wall . (M u) = (M^T f_wall) . u.
This is the Kratos CoSimulation convention (consistent kinematics, conservative forces).
"""
from __future__ import annotations

import numpy as np


class Mapper:
    name = "base"

    def __init__(self, origin: np.ndarray, chains: list, dest: np.ndarray):
        self.origin = np.asarray(origin, float)
        self.dest = np.asarray(dest, float)
        self.cols, self.w = self.build(self.origin, chains, self.dest)   # (nn, 2) columns and weights
        from scipy.sparse import csr_matrix
        nn, nb = len(self.dest), len(self.origin)
        rows = np.repeat(np.arange(nn), 2)
        self._M = csr_matrix((self.w.ravel(), (rows, self.cols.ravel())), shape=(nn, nb))   # duplicates summed
        self._MT = self._M.T.tocsr()

    @staticmethod
    def build(origin, chains, dest):  # pragma: no cover - abstract
        raise NotImplementedError

    def kinematics(self, u: np.ndarray) -> np.ndarray:
        """(n_mpm, k) -> (n_wall, k)."""
        return self._M @ np.asarray(u, float)

    def forces(self, f: np.ndarray) -> np.ndarray:
        """(n_wall, k) -> (n_mpm, k), the transpose of `kinematics` (same order of summation every call)."""
        return self._MT @ np.asarray(f, float)

    def matrix(self) -> np.ndarray:
        return self._M.toarray()


def _registry() -> dict:
    from coupler.coupling.mappers.linear import LinearMapper
    from coupler.coupling.mappers.nearest import NearestMapper
    return {"nearest": NearestMapper,
            "linear": LinearMapper}


MAPPERS = ("nearest", "linear")


def make_mapper(name: str, origin, chains, dest) -> Mapper:
    return _registry()[name](origin, chains, dest)
