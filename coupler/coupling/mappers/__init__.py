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

from coupler.coupling.mappers.base import Mapper
from coupler.coupling.mappers.linear import LinearMapper
from coupler.coupling.mappers.nearest import NearestMapper

# the registry: one line per mapper
REGISTRY: dict[str, type[Mapper]] = {
    "nearest": NearestMapper,
    "linear": LinearMapper,
}


MAPPERS = tuple(REGISTRY)


def make_mapper(name: str, origin, chains, dest) -> Mapper:
    return REGISTRY[name](origin, chains, dest)
