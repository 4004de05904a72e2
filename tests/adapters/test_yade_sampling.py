"""Issue 17 items 6 and 7 (YADE): the tables are sampled at the same instant as the other backends (positions,
velocities and contact rows of x(t), not YADE's leapfrog v(t - dt/2) and the forces of the previous step), which the
provenance states; the energy table includes the clusters. Live runs, skipped with the reason without YADE."""
import json

import numpy as np
import pytest

from coupler.run import run_scene
from coupler.scene import loads_scene
from tests.conftest import ALUMINIUM, require_binary, scene_toml
from tests.dem.test_rigid_wall import rigid_scene

FALL = scene_toml("""[dem]
[[dem.spheres]]
name = "ball"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.1, 0.0]
angular_velocity = [0.0, 0.0, 3.0]
""", t_end="1e-3", dt="1e-6", output_interval="1e-4", contacts=None)


def test_free_fall_velocity_is_sampled_at_t(tmp_path):
    require_binary("yade")
    res = run_scene(loads_scene(FALL), tmp_path, backend="yade", progress=False)
    b = res.body("ball")
    assert np.allclose(b["vy"], -9.81 * b["t"], rtol=1e-9, atol=1e-12)     # not -g (t - dt/2)
    assert np.allclose(b["y"], 0.1 - 0.5 * 9.81 * b["t"] ** 2, rtol=0, atol=1e-12)
    prov = json.loads((tmp_path / "provenance.json").read_text())
    assert "v(t)" in prov["sampling"] and "contact rows of x(t)" in prov["sampling"]


def test_contact_rows_are_not_one_step_late(tmp_path):
    """An elastic impact on a rigid plane with a coarse step (dt = 2e-8 s, 1/850 of the contact): a one-step lag
    would differ from the native force history by ~dF/dt dt = 2.4e-3 of the peak."""
    require_binary("yade")
    scene = loads_scene(rigid_scene("plane", dt="2e-8").replace("output_interval = 1e-8", "output_interval = 2e-8"))
    nat = run_scene(scene, tmp_path / "native", progress=False).contacts
    ref = run_scene(scene, tmp_path / "yade", backend="yade", progress=False).contacts
    m = nat[["t", "fn"]].merge(ref[["t", "fn"]], on="t", how="outer", suffixes=("_n", "_y")).fillna(0.0)
    peak = nat["fn"].max()
    assert (m["fn_n"] - m["fn_y"]).abs().max() < 2e-4 * peak


CLUSTER = scene_toml("""[dem]
[dem.templates.pair]
spheres = [[0.0, 0.0, 0.0, 1e-3], [2e-3, 0.0, 0.0, 1e-3]]
[[dem.clusters]]
name = "dumbbell"
template = "pair"
material = "aluminium"
position = [0.0, 0.1, 0.0]
velocity = [0.2, 0.0, 0.0]
angular_velocity = [0.0, 0.0, 40.0]
""", t_end="1e-3", dt="5e-7", output_interval="1e-4", contacts=None)


def test_energy_table_includes_clusters(tmp_path):
    require_binary("yade")
    scene = loads_scene(CLUSTER)
    nat = run_scene(scene, tmp_path / "native", progress=False).energy
    ref = run_scene(scene, tmp_path / "yade", backend="yade", progress=False).energy
    assert ref["kinetic"].iloc[0] > 0.0
    assert np.allclose(ref["kinetic"], nat["kinetic"], rtol=1e-9)
    assert np.allclose(ref["potential"], nat["potential"], rtol=1e-9, atol=1e-15)
