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
        self._c = np.concatenate([self.cols[:, 0], self.cols[:, 1]])      # fixed order: deterministic sums
        self._w = np.concatenate([self.w[:, 0], self.w[:, 1]])

    @staticmethod
    def build(origin, chains, dest):  # pragma: no cover - abstract
        raise NotImplementedError

    def kinematics(self, u: np.ndarray) -> np.ndarray:
        """(n_mpm, k) -> (n_wall, k)."""
        u = np.asarray(u, float)
        return self.w[:, 0:1] * u[self.cols[:, 0]] + self.w[:, 1:2] * u[self.cols[:, 1]]

    def forces(self, f: np.ndarray) -> np.ndarray:
        """(n_wall, k) -> (n_mpm, k), the transpose of `kinematics` (same order of summation every call)."""
        f = np.asarray(f, float)
        n = len(self.origin)
        return np.column_stack([np.bincount(self._c, weights=self._w * np.concatenate([f[:, k], f[:, k]]),
                                            minlength=n) for k in range(f.shape[1])])

    def matrix(self) -> np.ndarray:
        M = np.zeros((len(self.dest), len(self.origin)))
        np.add.at(M, (np.arange(len(self.dest)), self.cols[:, 0]), self.w[:, 0])
        np.add.at(M, (np.arange(len(self.dest)), self.cols[:, 1]), self.w[:, 1])
        return M


def _registry() -> dict:
    from coupler.coupling.mappers.linear import LinearMapper
    from coupler.coupling.mappers.nearest import NearestMapper
    return {"nearest": NearestMapper,
            "linear": LinearMapper}


MAPPERS = ("nearest", "linear")


def make_mapper(name: str, origin, chains, dest) -> Mapper:
    return _registry()[name](origin, chains, dest)
