"""The mapper interface (see coupler/coupling/mappers/__init__.py for the conventions)."""
from __future__ import annotations

import numpy as np

from coupler.coupling.exchange import map_forces, map_kinematics


class Mapper:
    name = "base"

    def __init__(self, origin: np.ndarray, chains: list, dest: np.ndarray):
        self.origin = np.asarray(origin, float)
        self.dest = np.asarray(dest, float)
        self.cols, self.w = self.build(self.origin, chains, self.dest)   # (nn, 2) columns and weights
        self._c = np.concatenate([self.cols[:, 0], self.cols[:, 1]])      # fixed order: deterministic sums
        self._w = np.concatenate([self.w[:, 0], self.w[:, 1]])
        # wall node k = interface point k (the default wall with nearest or linear): both maps are the identity;
        # skip the gathers and the bincount (the same values: 1 * u + 0 * u = u, up to the sign of a zero)
        n = len(self.origin)
        self.identity = bool(len(self.dest) == n and np.array_equal(self.cols[:, 0], np.arange(n))
                             and np.all(self.w[:, 0] == 1.0) and np.all(self.w[:, 1] == 0.0))

    @staticmethod
    def build(origin, chains, dest):  # pragma: no cover - abstract
        raise NotImplementedError

    def kinematics(self, u: np.ndarray) -> np.ndarray:
        """(n_mpm, k) -> (n_wall, k)."""
        u = np.asarray(u, float)
        out = np.empty((len(self.dest),) + u.shape[1:])
        map_kinematics(u.reshape(len(u), -1), self.cols, self.w, self.identity, out.reshape(len(out), -1))
        return out

    def forces(self, f: np.ndarray) -> np.ndarray:
        """(n_wall, k) -> (n_mpm, k), the transpose of `kinematics` (same order of summation every call)."""
        f = np.asarray(f, float)
        out = np.empty((len(self.origin),) + f.shape[1:])
        map_forces(f.reshape(len(f), -1), self._c, self._w, self.identity, 1.0, out.reshape(len(out), -1))
        return out

    def matrix(self) -> np.ndarray:
        M = np.zeros((len(self.dest), len(self.origin)))
        np.add.at(M, (np.arange(len(self.dest)), self.cols[:, 0]), self.w[:, 0])
        np.add.at(M, (np.arange(len(self.dest)), self.cols[:, 1]), self.w[:, 1])
        return M
