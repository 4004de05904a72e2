"""Disconnected (zero-stress) state below the packing density (Dunatunga & Kamrin 2015;
coupler/mpm/constitutive/disconnected.py), issue #17 "fixed base".

The failure it removes, reduced to one point: a lone cohesionless point dilated to J = det F = 5 or 20 (as the front
points of the Bui collapse on a no-slip base at h = 1.25 mm) resting on a fixed base, quadratic B-spline, APIC, the
scene's cfl 0.5 of the packed material's wave speed c. Its density is rho_0 / J with the packed moduli, so its wave
speed is sqrt(J) c and the explicit step is unstable for it: its stress oscillates, the cohesionless apex cuts the
tension half, and the point dilates further (faster the larger J: the Bui point reached J = 7e30). With
`disconnected = true` it carries no stress while J > 1 and only settles."""
from __future__ import annotations

import numpy as np
import pytest

from coupler.errors import SceneError
from coupler.mpm.solver import MPMSolver, run_mpm
from coupler.scene import loads_scene
from tests.conftest import scene_toml

BARS = {"density": "2650.0", "young": "0.84e6", "poisson": "0.3"}   # the Bui 2008 aluminium bars

H = 0.00125


def _scene(extra: str = "", t_end: float = 0.2, scheme: str = "", model: str = "mohr_coulomb",
           cohesion: float = 0.0) -> str:
    return scene_toml(f"""[mpm]
shape_function = "bspline2"
transfer = "apic"
cfl = 0.5
{scheme}
[mpm.grid]
origin = [0.0, 0.0]
size = [{16 * H}, {8 * H}]
cell_size = {H}
[mpm.boundary]
bottom = {{ kind = "fixed" }}
top = {{ kind = "open" }}
[[mpm.bodies]]
name = "p"
material = "bars"
rectangle = {{ min = [{8 * H}, 0.0], max = [{8.5 * H}, {0.5 * H}] }}
particles_per_cell = 2
constitutive = {{ model = "{model}", friction_angle = 19.8, cohesion = {cohesion}, dilatancy = 0.0 {extra} }}
""", name="lone_point", dimension=2, t_end=t_end, dt=None, output_interval=t_end / 4, materials={"bars": BARS},
                      contacts=None)


def _lone(J0: float, on: bool) -> MPMSolver:
    """The one-point scene with the point dilated to J0 (F_xx = J0), stress-free."""
    sol = MPMSolver(loads_scene(_scene(", disconnected = true" if on else "")))
    assert len(sol.m) == 1
    sol.F[:, 0] *= J0
    sol.vol[:] = sol.vol0 * J0
    return sol


def _history(sol, t_end=0.2, every=0.005):
    J, s = [], []
    for t in np.arange(every, t_end + 1e-12, every):
        sol.advance_to(t)
        J.append(sol.vol[0] / sol.vol0[0])
        s.append(np.abs(sol.s[0]).max())
    return np.array(J), np.array(s)


@pytest.mark.parametrize("J0", [5.0, 20.0])
def test_dilated_lone_point_does_not_pump_itself_up(J0):
    """With the option: no stress while J > 1, J does not grow (it settles towards the held base node, so J falls);
    without it (the mechanism, measured): the stress comes and goes and J grows."""
    J, s = _history(_lone(J0, True))
    assert np.all(s == 0.0)
    assert np.all(np.diff(J) <= 0.0) and J[-1] < J0
    J_off, s_off = _history(_lone(J0, False))
    assert s_off.max() > 0.0 and np.any(s_off == 0.0)      # stressed, then cut at the apex, repeatedly
    assert J_off[-1] > J0 * 1.02                            # 5 -> 5.14, 20 -> 24.3 in 0.2 s at cfl 0.5


def test_recompacted_point_is_stressed_again():
    """A point slightly below its packing density (J = 1.02) settles stress-free until J <= 1, then carries its
    weight (the usual Mohr-Coulomb update from zero stress) and comes to rest."""
    sol = _lone(1.02, True)
    J, s = _history(sol, 0.2)
    k = int(np.argmax(s > 0.0))
    assert s[0] == 0.0 and s[-1] > 0.0
    assert np.all(J[:k] > 1.0) and abs(J[k] - 1.0) < 1e-5     # stress-free down to J = 1, then stressed again
    assert abs(J[-1] - 1.0) < 1e-4 and abs(sol.v[0, 1]) < 1e-4   # at rest at its packing density, carrying
    assert sol.s[0, 1] < 0.0                                       # its weight


def test_undilated_point_is_unchanged_by_the_option():
    """J = 1 at rest: the option never acts (the same numbers bit for bit)."""
    a, b = _lone(1.0, True), _lone(1.0, False)
    for sol in (a, b):
        sol.advance_to(0.05)
    assert np.array_equal(a.s, b.s) and np.array_equal(a.x, b.x) and np.array_equal(a.F, b.F)


def test_summary_counts_the_disconnected_points():
    res = run_mpm(loads_scene(_scene(", disconnected = true", t_end=0.02)), None)
    d = res.summary["mpm_disconnected_points"]
    assert d["at_end"] == 0 and d["max_at_output"] == 0      # a packed point at rest is never disconnected
    sol = _lone(5.0, True)
    from coupler.mpm.constitutive.disconnected import count
    sol.advance_to(0.01)
    assert int(count(sol.prm, sol.mid, sol.s, sol.vol, sol.vol0).sum()) == 1


@pytest.mark.parametrize("kw,msg", [
    (dict(cohesion=100.0), "cohesionless"),
    (dict(model="elastic"), "cohesionless"),
    (dict(scheme='scheme = "implicit"'), "explicit scheme only"),
])
def test_bad_use_is_one_line_naming_the_field(kw, msg):
    with pytest.raises(SceneError) as e:
        loads_scene(_scene(", disconnected = true", **kw))
    assert "disconnected" in str(e.value) and msg in str(e.value)
