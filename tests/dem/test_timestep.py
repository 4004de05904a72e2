"""Issue 17, hard cases: the automatic DEM step comes from the stiffest contact the scene can have (a wall stiffer
than the spheres, two materials), and a forced step that would tunnel is refused naming time.dt."""
import math

import pytest

from coupler.dem.timestep import hertz_contact_time, impact_speed, stable_dt
from coupler.errors import SceneError
from coupler.scene import loads_scene
from tests.conftest import scene_toml

R = 2.5e-3
SOFT = {"density": 1100.0, "young": 1e7, "poisson": 0.45}
STEEL = {"density": 7850.0, "young": 210e9, "poisson": 0.3}


def _scene(wall_material: str, dt=None, speed: float = 1.0) -> str:
    body = f"""[dem]
[[dem.spheres]]
name = "ball"
material = "rubber"
radius = {R!r}
position = [0.0, {2 * R!r}, 0.0]
velocity = [0.0, {-speed!r}, 0.0]

[[dem.meshes]]
name = "plate"
material = "{wall_material}"
vertices = [[-0.01, 0.0, -0.01], [0.01, 0.0, -0.01], [0.01, 0.0, 0.01], [-0.01, 0.0, 0.01]]
triangles = [[0, 2, 1], [0, 3, 2]]
"""
    return scene_toml(body, gravity="[0.0, 0.0, 0.0]", dt=dt, t_end="1e-3", output_interval="1e-4",
                      materials={"rubber": SOFT, "steel": STEEL},
                      contacts=[("rubber", "rubber", "0.5", "0.5"), ("rubber", "steel", "0.5", "0.5")])


def test_a_wall_stiffer_than_the_spheres_sets_the_step():
    """A rubber sphere on a steel wall: E* = E_r/(1 - nu_r^2) nearly, R* = R, m* = m, 0.87 x the rubber-rubber
    contact time (before: the sphere pair alone was considered, 15 % above the stable step)."""
    scene = loads_scene(_scene("steel"))
    dt, why = stable_dt(scene)
    assert "wall plate (steel)" in why
    estar = 1.0 / ((1 - SOFT["poisson"] ** 2) / SOFT["young"] + (1 - STEEL["poisson"] ** 2) / STEEL["young"])
    m = SOFT["density"] * 4.0 / 3.0 * math.pi * R ** 3
    assert dt == pytest.approx(hertz_contact_time(estar, R, m, impact_speed(scene)) / 10.0, rel=1e-12)
    pair = loads_scene(_scene("rubber"))
    assert dt < 0.9 * stable_dt(pair)[0]


def test_a_forced_step_that_would_tunnel_is_refused():
    """A soft sphere at 50 m/s: its stable limit (Hertz time / 10) allows a step in which it moves more than half its
    radius, i.e. across a zero-thickness wall within a few steps (accepted before); now refused naming time.dt."""
    v = 50.0
    ok = 0.5 * R / (2 * v)              # half the radius per step at the impact speed 2 |v0|
    assert stable_dt(loads_scene(_scene("rubber", speed=v)))[0] > 1.1 * ok
    with pytest.raises(SceneError, match=r"^time.dt: .*tunnels through a thin wall"):
        loads_scene(_scene("rubber", dt=repr(1.01 * ok), speed=v))
    assert loads_scene(_scene("rubber", dt=repr(0.99 * ok), speed=v)).time.dt == 0.99 * ok

