"""Prescribed cluster motion (`[[dem.clusters]] motion`) in LIGGGHTS (multisphere flags) and YADE (clump
blockedDOFs) against the native solver on the same scene file: a held block that a ball hits and that stays put,
and a block driven at a velocity and spin, released at `until` and falling freely."""
import numpy as np
import pytest

from coupler.run import run_scene
from coupler.scene import loads_scene
from tests.conftest import ALUMINIUM, require_binary, scene_toml

BLOCK = """[dem]
cluster_damping_mass = "body"
[dem.templates.b]
grid = { nx = 6, ny = 5, radius = 2.5e-3, spacing = 5e-3 }
[[dem.clusters]]
name = "block"
template = "b"
material = "aluminium"
position = [0.0, 0.1, 0.0]
MOTION
"""

HELD = scene_toml(BLOCK.replace("MOTION", 'motion = { kind = "fixed" }') + """[[dem.spheres]]
name = "ball"
material = "ball"
radius = 2.5e-3
position = [-2.5e-3, 0.115001, 0.0]
velocity = [0.0, -1.0, 0.0]
""", name="held", dimension=2, t_end="4e-5", dt="1e-8", output_interval="2e-6", output={"contacts": False},
                  materials={"aluminium": ALUMINIUM, "ball": ALUMINIUM},      # YADE: one damping mass per pair (P5)
                  contacts=[("aluminium", "aluminium", "0.8", "0.3"), ("aluminium", "ball", "0.8", "0.3"),
                            ("ball", "ball", "0.8", "0.3")])

G, DT, T_RELEASE = 9.81, 1e-5, 0.02
SOFT = {"soft": {"density": "2700.0", "young": "1e8", "poisson": "0.3"}}     # a stable step of 1e-5 s
DRIVEN = scene_toml(BLOCK.replace('"aluminium"', '"soft"').replace("MOTION", 'motion = { kind = "velocity", velocity = [0.2, 0.1, 0.0], '
                                            f'angular_velocity = [0.0, 0.0, 3.0], until = {T_RELEASE} }}'),
                    name="driven", dimension=2, t_end="0.05", dt=f"{DT}", output_interval="1e-3",
                    materials=SOFT, output={"contacts": False})


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_held_block_stays_while_a_ball_bounces_off_it(code, tmp_path):
    require_binary(code)
    scene = loads_scene(HELD, name="held")
    nat = run_scene(scene, tmp_path / "native", progress=False)
    ref = run_scene(scene, tmp_path / code, backend=code, progress=False)
    for res in (nat, ref):
        b = res.body("block")
        assert np.abs(b[["x", "y"]].to_numpy() - [0.0, 0.1]).max() < 1e-14           # held still
        assert np.abs(b[["vx", "vy", "wz"]].to_numpy()).max() < 1e-14
        assert np.abs(2.0 * np.arctan2(b["qz"], b["qw"])).max() < 1e-14
    vn, vr = nat.body("ball")["vy"].iloc[-1], ref.body("ball")["vy"].iloc[-1]
    assert vn > 0.5                                                                    # it bounced off the block
    assert vr == pytest.approx(vn, rel=1e-6 if code == "liggghts" else 1e-4)


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_driven_block_released_then_falls(code, tmp_path):
    """Driven with v = (0.2, 0.1) m/s, w = 3 rad/s until 0.02 s, then free flight under gravity. LIGGGHTS: as native
    to round-off. YADE: its leapfrog velocity is a half step behind (writer.py), so after the release its centroid
    trails by g dt (t - t_release) / 2 in y (1.5e-6 m at 0.05 s); x and the rotation to round-off."""
    require_binary(code)
    scene = loads_scene(DRIVEN, name="driven")
    nat = run_scene(scene, tmp_path / "native", progress=False).body("block")
    ref = run_scene(scene, tmp_path / code, backend=code, progress=False).body("block")
    assert len(ref) == len(nat)
    t = nat["t"].to_numpy()
    after = np.maximum(t - T_RELEASE, 0.0)
    x_exact = 0.2 * t
    y_exact = 0.1 + 0.1 * t - 0.5 * G * after ** 2
    assert np.abs(nat["x"].to_numpy() - x_exact).max() < 1e-12
    assert np.abs(nat["y"].to_numpy() - y_exact).max() < 1e-12           # velocity Verlet: exact for constant g
    ang = lambda b: 2.0 * np.arctan2(b["qz"].to_numpy(), b["qw"].to_numpy())     # noqa: E731
    assert np.abs(np.unwrap(ang(nat)) - 3.0 * t).max() < 1e-9                   # torque-free: the spin stays
    dy = ref["y"].to_numpy() - nat["y"].to_numpy()
    if code == "liggghts":
        assert np.abs(dy).max() < 1e-12
    else:
        assert np.abs(dy + 0.5 * G * DT * after).max() < 1e-9
    assert np.abs(ref["x"].to_numpy() - nat["x"].to_numpy()).max() < 1e-12
    assert np.abs(np.unwrap(ang(ref)) - np.unwrap(ang(nat))).max() < 1e-9
