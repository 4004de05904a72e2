import os
import shutil

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def require_binary(name: str) -> None:
    """Skip with the reason when a reference code is missing; in CI (CI set) a missing code is a failure."""
    if shutil.which(name) is None:
        if os.environ.get("CI"):
            pytest.fail(f"{name} is not installed, but CI must run the live adapter tests (.ci/run installs it)")
        pytest.skip(f"{name} not installed (apt-get install -y {name}); live comparison skipped")


@pytest.fixture
def scene_text():
    """A small valid DEM scene; tests edit it to make it invalid."""
    return BASE_SCENE


BASE_SCENE = """
name = "t"
dimension = 3
gravity = [0.0, -9.81, 0.0]
[time]
t_end = 1e-5
dt = 1e-8
output_interval = 1e-6
[materials.aluminium]
density = 2700.0
young = 70e9
poisson = 0.33
[[contacts]]
materials = ["aluminium", "aluminium"]
restitution = 0.8
friction = 0.3
[dem]
[[dem.spheres]]
name = "a"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.0026, 0.0]
velocity = [0.0, -1.0, 0.0]
[[dem.planes]]
name = "floor"
material = "aluminium"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
"""
