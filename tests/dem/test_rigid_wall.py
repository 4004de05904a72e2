"""Issue 17 item 2: `rigid = true` on a plane or mesh wall gives E* from the sphere alone (Chung & Ooi's rigid
plane, 1/E* = (1 - nu^2)/E); checked against the analytic elastic Hertz impact on a rigid plane (Johnson 1985):
    delta_max = (15 m v^2 / (16 E* sqrt(R)))^(2/5),  F_max = 4/3 E* sqrt(R) delta_max^(3/2),
    t_c = 2.94304 delta_max / v  (the exact Hertz contact-time constant, 2.87 (m^2/(R E*^2 v))^(1/5) rounded)."""
import math

import pytest

from coupler.errors import SceneError
from coupler.run import run_scene
from coupler.scene import loads_scene
from tests.conftest import edit, scene_toml

R, V, RHO, E, NU = 2.5e-3, 1.0, 2700.0, 70e9, 0.33
GAP = 1e-5


def rigid_scene(kind: str = "plane", rigid: bool = True, dt: str = "2e-9", wall_young: str = "70e9") -> str:
    wall = {"plane": """[[dem.planes]]
name = "floor"
material = "wall"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
""", "mesh": """[[dem.meshes]]
name = "floor"
material = "wall"
vertices = [[-0.01, 0.0, -0.01], [0.01, 0.0, -0.01], [0.01, 0.0, 0.01], [-0.01, 0.0, 0.01]]
triangles = [[0, 2, 1], [0, 3, 2]]
"""}[kind]
    if rigid:
        wall += "rigid = true\n"
    body = f"""[dem]
[[dem.spheres]]
name = "ball"
material = "al"
radius = {R!r}
position = [0.0021, {R + GAP!r}, 0.0013]
velocity = [0.0, {-V!r}, 0.0]
""" + wall
    return scene_toml(body, name="rigid_" + kind, gravity="[0.0, 0.0, 0.0]", t_end="3.2e-5", dt=dt,
                      output_interval="1e-8", output={"bodies": True, "contacts": True, "energy": False},
                      materials={"al": {"density": repr(RHO), "young": repr(E), "poisson": repr(NU)},
                                 "wall": {"density": "7800.0", "young": wall_young, "poisson": "0.3"}},
                      contacts=[("al", "wall", "1.0", "0.0")])


def hertz_rigid(estar: float) -> tuple[float, float]:
    m = RHO * 4.0 / 3.0 * math.pi * R ** 3
    d = (15.0 * m * V * V / (16.0 * estar * math.sqrt(R))) ** 0.4
    return 4.0 / 3.0 * estar * math.sqrt(R) * d ** 1.5, 2.94304 * d / V


def impact(res) -> tuple[float, float]:
    c = res.contacts
    c = c[c["fn"] > 0.0]
    return float(c["fn"].max()), len(c) * 1e-8


def check_against_rigid_hertz(res, rel_f=2e-3, rel_t=2e-3):
    f_ref, t_ref = hertz_rigid(E / (1.0 - NU ** 2))
    f, t = impact(res)
    assert f == pytest.approx(f_ref, rel=rel_f), (f, f_ref)
    assert t == pytest.approx(t_ref, rel=rel_t, abs=1.5e-8), (t, t_ref)


@pytest.mark.parametrize("kind", ["plane", "mesh"])
def test_rigid_wall_matches_analytic_hertz(kind, tmp_path):
    check_against_rigid_hertz(run_scene(loads_scene(rigid_scene(kind)), tmp_path, progress=False))


def test_elastic_wall_of_the_sphere_material_is_softer(tmp_path):
    """Without rigid, a wall of the sphere's own material halves E*: the peak force drops by 1 - 2^(-2/5) = 24 %."""
    res = run_scene(loads_scene(rigid_scene("plane", rigid=False, wall_young="70e9")), tmp_path, progress=False)
    f, _ = impact(res)
    estar = 1.0 / ((1 - NU ** 2) / E + (1 - 0.3 ** 2) / 70e9)
    assert f == pytest.approx(hertz_rigid(estar)[0], rel=2e-3)
    assert f < 0.8 * hertz_rigid(E / (1 - NU ** 2))[0]


def test_rigid_wall_ignores_the_wall_modulus_and_limits_the_time_step():
    a = loads_scene(edit(rigid_scene("plane", wall_young="1e3", dt=None), "output_interval = 1e-8", "output_interval = 1e-6"))
    b = loads_scene(edit(rigid_scene("plane", wall_young="1e12", dt=None), "output_interval = 1e-8", "output_interval = 1e-6"))
    from coupler.dem.timestep import stable_dt
    assert stable_dt(a) == stable_dt(b) and "rigid wall" in stable_dt(a)[1]
    from coupler.dem.solver import DEMSolver
    sa, sb = DEMSolver(a), DEMSolver(b)
    k = int(sa.planes.mat[0])                             # the rigid copy of the wall material the plane uses
    assert sa.materials[k].name == "wall" and math.isinf(sa.materials[k].young)
    assert (sa.table[0, k] == sb.table[0, k]).all()
    assert sa.table[0, k, 0] == pytest.approx(E / (1 - NU ** 2), rel=1e-15)


def test_rigid_must_be_a_boolean():
    with pytest.raises(SceneError, match=r"dem.planes\[0\].rigid"):
        loads_scene(rigid_scene("plane", rigid=False).replace('normal = [0.0, 1.0, 0.0]\n',
                                                              'normal = [0.0, 1.0, 0.0]\nrigid = "yes"\n'))
