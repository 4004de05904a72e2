"""The shared validation metrics (validation/metrics.py) on series with known answers."""
import math

import numpy as np
import pandas as pd
import pytest

from coupler.scene import load_scene
from tests.conftest import CASES
from validation import metrics as M


def test_sphere_mass():
    assert M.sphere_mass(2700.0, 2.5e-3) == pytest.approx(2700.0 * 4.0 / 3.0 * math.pi * 2.5e-3 ** 3, rel=1e-15)
    assert np.allclose(M.sphere_mass(1000.0, np.array([1.0, 2.0])), 4000.0 / 3.0 * math.pi * np.array([1.0, 8.0]))


def test_contact_time_from_gap_interpolates_the_crossings():
    t = np.linspace(0.0, 1.0, 11)
    gap = np.abs(t - 0.5) - 0.23                 # in contact for t in (0.27, 0.73): crossings between samples
    assert M.contact_time_from_gap(t, gap) == pytest.approx(0.46, rel=1e-12)
    assert math.isnan(M.contact_time_from_gap(t, np.ones_like(t)))


def test_contact_time_from_force_counts_samples():
    t = np.arange(10) * 1e-8
    fn = np.array([0, 0, 1, 2, 3, 2, 1, 0, 0, 0], float)
    assert M.contact_time_from_force(t, fn) == pytest.approx(4e-8)
    assert math.isnan(M.contact_time_from_force(t, np.zeros(10)))


def test_restitution_and_rebound_angle():
    b = pd.DataFrame({"vx": [3.0, 2.0], "vy": [-1.0, 0.8]})
    assert M.restitution_wall(b) == pytest.approx(0.8)
    moving = pd.DataFrame({"vx": [0.0, 0.0], "vy": [0.0, 1.8]})       # wall at +1 m/s hits a ball at rest
    assert M.restitution_wall(moving, 1.0) == pytest.approx(0.8)
    a, c = pd.DataFrame({"vy": [0.5, -0.4]}), pd.DataFrame({"vy": [-0.5, 0.4]})
    assert M.restitution_pair(a, c) == pytest.approx(0.8)
    assert M.rebound_angle_deg(b) == pytest.approx(math.degrees(math.atan2(2.0, 0.8)))
    assert M.tangential_impulse(b, 2.0) == pytest.approx(2.0)


def test_trajectory_and_curve_differences():
    a = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    b = a + [[0.0, 0.0], [0.0, 0.3], [0.4, 0.0]]
    assert M.trajectory_error(a, b) == pytest.approx(0.4)
    assert M.trajectory_error(a[:, 0], b[:2, 0]) == 0.0              # common leading samples only
    t = np.array([0.0, 1.0, 2.0])
    assert M.trajectory_error_interp(t, np.array([0.0, 1.0, 2.0]), np.array([0.0, 2.0]), np.array([0.0, 4.0])) == 2.0
    assert M.curve_difference(t, np.array([1.0, 2.0, 3.0]), t[1:], np.array([2.0, 4.0])) == pytest.approx(0.25)


def test_rotation_z_and_period():
    th = np.array([0.0, 0.3, -1.0])
    b = pd.DataFrame({"qw": np.cos(th / 2), "qz": np.sin(th / 2)})
    assert np.allclose(M.rotation_z_deg(b), np.degrees(th))
    t = np.linspace(0.0, 10.0, 10001)
    T, n = M.period_from_zero_crossings(t, np.sin(2 * math.pi * t / 2.5 + 0.1))
    assert T == pytest.approx(2.5, rel=1e-6) and n == 8


def test_surface_profile_takes_the_highest_top_per_bin():
    x = np.array([0.001, 0.004, 0.012, 0.5])                         # the last one beyond the range: last bin
    xc, h = M.surface_profile(x, np.array([1.0, 2.0, 3.0, 4.0]), 0.01, 3)
    assert np.allclose(xc, [0.005, 0.015, 0.025]) and list(h) == [2.0, 3.0, 4.0]
    assert M.rms([3.0, -4.0]) == pytest.approx(math.sqrt(12.5))


def test_scene_readers():
    sc = load_scene(f"{CASES}/dem_hertz_impact/pair.toml")
    a = M.scene_sphere_props(sc, "a")
    assert a["radius"] == 2.5e-3 and a["mass"] == M.sphere_mass(2700.0, 2.5e-3) and a["velocity"][1] == 0.5
    with pytest.raises(KeyError, match="no sphere named 'c'"):
        M.scene_sphere(sc, "c")
    lo, hi = M.scene_mpm_body_extent(load_scene(f"{CASES}/mpm_elastic_bar/scene.toml"))
    assert list(lo) == [0.0, 0.0] and list(hi) == [0.25, 0.04]
    exp = M.read_data("bui2008_final_surface.csv")
    assert exp.shape[1] == 2 and exp[0, 0] == 0.0 and exp[0, 1] == 0.1


def test_lattice_triangles_see_affine_motion_and_a_fold():
    """validation.metrics.lattice_triangles: an affine motion x = A X + b of a seeded lattice gives every triangle the
    area ratio det A; two points that pass through each other (the motion folded) turn triangles inside out; points
    off the lattice are an error."""
    from validation.metrics import lattice_triangles
    s = 0.5e-3
    X, Y = np.meshgrid((np.arange(6) + 0.5) * s, (np.arange(4) + 0.5) * s, indexing="ij")
    x0, y0 = X.ravel(), Y.ravel()
    A = np.array([[1.3, 0.4], [-0.2, 0.9]])
    x, y = A[0, 0] * x0 + A[0, 1] * y0 + 0.1, A[1, 0] * x0 + A[1, 1] * y0 - 0.02
    ratio, cx, cy, tri = lattice_triangles(x0, y0, x, y, s)
    assert len(ratio) == 2 * 5 * 3 and tri.shape == (30, 3)
    assert np.allclose(ratio, np.linalg.det(A), rtol=1e-9, atol=0)
    assert np.allclose(cx, x[tri].mean(axis=1)) and np.allclose(cy, y[tri].mean(axis=1))
    # a point of the second row moved below the first row (through its neighbours): its triangles invert
    k = int(np.flatnonzero((np.abs(x0 - 2.5 * s) < 1e-12) & (np.abs(y0 - 1.5 * s) < 1e-12))[0])
    y2 = y0.copy()
    y2[k] = -0.5 * s
    ratio2, *_ = lattice_triangles(x0, y0, x0, y2, s)
    assert (ratio2 < 0).sum() > 0 and (ratio2 > 0).sum() > 0 and np.all(ratio2[ratio2 > 0] > 0)
    # an interior point moved: the signed areas still add up to the area inside the lattice's boundary points
    assert np.isclose(ratio2.sum(), 2 * 5 * 3, rtol=1e-12, atol=0)
    with pytest.raises(ValueError, match="spacing"):
        lattice_triangles(x0 + 0.1 * s, y0, x, y, s)
