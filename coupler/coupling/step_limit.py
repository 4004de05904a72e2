"""Stable coupling step of an explicit MPM partition against the DEM contact on the interface wall (issue 17).

The interface wall follows the MPM boundary nodes, updated once per coupling step, and the DEM contact force on it
goes back to those nodes as a point load held over the next MPM step: for the nodes the contact is an explicit
spring. Rule: the DEM's own (coupler/dem/timestep.py), a step <= the Hertz contact time / 10, taken for every sphere
kind against the interface material at the DEM's impact speed, with the mass of an MPM surface node in place of the
sphere's: m = rho h^2 / 2 per unit depth x thickness (a node of a full cell row at the body's surface, 2 x 2 points
per cell or more), where the sphere's own mass sets the DEM step.

Measured on hard_coupled (a steel block, E 1e10 Pa, on an MPM body with E 1e6 Pa): staggered runs are stable up to a
coupling step of 2 DEM steps and chatter at 4; this rule gives 0.94 DEM step. The MPM's CFL step alone was 24 DEM
steps. In the validated coupled scenes the rule is 1.0 to 8 times their CFL step, so it does not bind there.

The implicit MPM takes the contact load into its Newton solve with the nodal mass and stiffness of the body, and
runs stably well past this limit (coupled_implicit_resting_load: 8 x): the rule applies to the explicit scheme.
"""
from __future__ import annotations

import math

from coupler.dem.contact import effective_young
from coupler.dem.timestep import hertz_contact_time, impact_speed, sphere_catalogue


def interface_step_limit(scene) -> tuple[float, str]:
    """(largest coupling step, what sets it) for an explicit MPM partition (module docstring)."""
    cs = scene.coupling
    body = next(b for b in scene.mpm.bodies if b.name == cs.body)
    h = scene.mpm.cell_size
    m_node = 0.5 * scene.materials[body.material].density * h * h * cs.thickness
    wall = scene.materials[cs.material]
    v = impact_speed(scene)
    best = (math.inf, "")
    for r, mname in sorted(set(sphere_catalogue(scene))):
        t = hertz_contact_time(effective_young(scene.materials[mname], wall), r, m_node, v) / 10.0
        if t < best[0]:
            best = (t, f"Hertz contact time / 10 of a sphere R={r:g} m ({mname}) on the interface ({cs.material}) "
                       f"at {v:.3g} m/s with the mass of an MPM surface node ({m_node:.3g} kg)")
    return best
