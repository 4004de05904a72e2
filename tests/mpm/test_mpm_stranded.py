"""A boundary particle whose support holds no grid mass stops moving (issue #17: never silent): counted per step and
reported in summary.json (kernels.move_boundary, MPMSolver.stranded_boundary_particles)."""
from __future__ import annotations

from coupler.mpm.solver import MPMSolver, run_mpm
from tests.mpm.test_mpm_contract import make


def test_stranded_boundary_particle_counted_and_reported(tmp_path):
    sol = MPMSolver(make())
    sol.xb[0] = [0.9, 0.9]            # far from the body: its support holds no grid mass
    sol.xb[1] = [0.95, 0.9]
    x0 = sol.xb[:2].copy()
    sol.advance(3)
    st = sol.stranded_boundary_particles()
    assert st == {"particle_steps": 6, "max_at_once": 2, "boundary_particles": len(sol.xb)}
    assert (sol.xb[:2] == x0).all() and (sol.vb[:2] == 0.0).all()
    res = run_mpm(make(), tmp_path)
    s = res.summary["mpm_stranded_boundary_particles"]
    assert s["particle_steps"] == 0 and s["boundary_particles"] == len(sol.xb)


def test_stranded_boundary_particle_counted_by_the_implicit_scheme():
    """The implicit scheme counts them as the explicit one (implicit/kernels.move_boundary): B.drop[4], [5]."""
    from coupler.mpm.implicit.solver import ImplicitMPMSolver
    sol = ImplicitMPMSolver(make(extra='scheme = "implicit"'))
    sol.xb[0] = [0.9, 0.9]
    sol.xb[1] = [0.95, 0.9]
    x0 = sol.xb[:2].copy()
    sol.advance(3)
    st = sol.stranded_boundary_particles()
    assert st == {"particle_steps": 6, "max_at_once": 2, "boundary_particles": len(sol.xb)}
    assert (sol.xb[:2] == x0).all() and (sol.vb[:2] == 0.0).all()
