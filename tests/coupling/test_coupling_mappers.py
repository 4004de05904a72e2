"""Mappers: forces keep resultant and moment to round-off (transpose of a position-reproducing map), a rigid
motion of the interface maps exactly, and virtual work is the same on both sides."""
import numpy as np
import pytest

from coupler.coupling.interface import _resample
from coupler.coupling.mappers import make_mapper


def polyline():
    # an L-shaped open interface (two edges) with boundary-particle-like spacing
    a = np.column_stack([np.zeros(8), 0.2 - (np.arange(8) + 0.5) * 0.025])
    b = np.column_stack([(np.arange(16) + 0.5) * 0.025, np.zeros(16)])
    return np.vstack([a, b]), [(0, 24, False)]


def cross(x, f):
    return x[:, 0] * f[:, 1] - x[:, 1] * f[:, 0]


@pytest.mark.parametrize("name, wall", [("nearest", "same"), ("linear", "same"), ("linear", "coarse"),
                                        ("linear", "fine")])
def test_resultant_moment_rigid_motion(name, wall):
    pts, chains = polyline()
    dest = pts.copy() if wall == "same" else _resample(pts, False, 0.07 if wall == "coarse" else 0.009)
    m = make_mapper(name, pts, chains, dest)
    rng = np.random.default_rng(3)
    f = rng.normal(size=(len(dest), 2))
    g = m.forces(f)
    scale = np.abs(f).sum()
    assert np.allclose(g.sum(0), f.sum(0), rtol=0, atol=1e-14 * scale)
    assert abs(cross(pts, g).sum() - cross(dest, f).sum()) <= 1e-14 * scale
    # rigid motion: rotation by 0.3 rad about (0.1, 0.05) plus a translation
    th, c, tr = 0.3, np.array([0.1, 0.05]), np.array([0.01, -0.02])
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    u = (pts - c) @ R.T + c + tr - pts
    u_ref = (dest - c) @ R.T + c + tr - dest
    assert np.allclose(m.kinematics(u), u_ref, rtol=0, atol=1e-15)
    # virtual work (consistency of the pair)
    assert abs(np.sum(f * m.kinematics(u)) - np.sum(g * u)) <= 1e-14 * scale
    assert np.allclose(m.matrix().sum(1), 1.0)


def test_nearest_on_a_different_wall_keeps_the_resultant_only():
    pts, chains = polyline()
    dest = _resample(pts, False, 0.07)
    m = make_mapper("nearest", pts, chains, dest)
    f = np.ones((len(dest), 2))
    assert np.allclose(m.forces(f).sum(0), f.sum(0))


def test_closed_chain_linear_wraps():
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    pts = np.column_stack([np.cos(t), np.sin(t)])
    dest = _resample(pts, True, 0.05)
    m = make_mapper("linear", pts, [(0, 40, True)], dest)
    f = np.random.default_rng(1).normal(size=(len(dest), 2))
    g = m.forces(f)
    assert np.allclose(g.sum(0), f.sum(0), atol=1e-13)
    assert abs(cross(pts, g).sum() - cross(dest, f).sum()) < 1e-13
    assert np.allclose(m.kinematics(pts + 0.1), dest + 0.1, atol=1e-15)
