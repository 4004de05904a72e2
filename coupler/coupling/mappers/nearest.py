"""Nearest neighbour: each wall node takes the kinematics of the closest MPM interface point (ties: the lower
index), forces go back by the transpose (each node force to its nearest point). Exact when the wall nodes are the
interface points (the default wall); otherwise resultant-conserving but not moment-conserving."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from coupler.coupling.mappers.base import Mapper


class NearestMapper(Mapper):
    name = "nearest"

    @staticmethod
    def build(origin, chains, dest):
        _, j = cKDTree(origin).query(dest, k=1)
        j = np.asarray(j, np.int64)
        return np.column_stack([j, j]), np.column_stack([np.ones(len(j)), np.zeros(len(j))])
