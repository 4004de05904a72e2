"""Boundary-particle transfer near sliver nodes (mpm.boundary_sliver_fraction, kernels._sliver_weight, issue 15):
a support node holding less than the fraction of a full node's mass (rho h^2) takes a share of the point load
scaled by its mass, so its acceleration stays bounded (also on a support holding only slivers: part of the load is
then not applied, counted); the velocity read uses the same weights (the power of the
load is what the grid receives); the load is kept exactly when a node of the largest weight holding mass is at least
the sliver mass full; bad values name the field."""
from __future__ import annotations

import numpy as np
import pytest

from coupler.errors import SceneError
from coupler.mpm import kernels as K
from coupler.mpm import shapes
from coupler.mpm.solver import MPMSolver
from tests.mpm.test_mpm_contract import SCENE

RHO, H = 1000.0, 0.05


def _make(frac, shape="bspline2"):
    txt = SCENE.format(g=0.0, shape=shape, transfer="usl",
                       extra="" if frac is None else f"boundary_sliver_fraction = {frac}")
    # the top edge 0.2 cells above a node row: the node row above holds 1.6 % of a full node's mass
    from coupler.scene import loads_scene
    return loads_scene(txt.replace("max = [0.6, 0.5]", "max = [0.6, 0.51]"))


def _spread(sol, p, f):
    S, P, B, Gr = sol.state()
    K.sort_strips(S, P, Gr, True)
    K.scatter(S, P, Gr)
    f0 = sol.G[:, :, 3:5].copy()
    sol.fb[:] = 0.0
    sol.fb[p] = f
    K.spread_loads(S, B, Gr, 1e-4)
    return sol.G[:, :, 3:5] - f0


def _top_particle(sol):
    top = np.flatnonzero(np.isclose(sol.xb[:, 1], 0.51))
    return int(top[len(top) // 2])


@pytest.mark.parametrize("frac", [0.05, 0.2])
def test_sliver_nodes_take_a_mass_scaled_share(frac):
    sol = MPMSolver(_make(frac))
    p = _top_particle(sol)
    f = np.array([0.3, -2.0])
    df = _spread(sol, p, f)
    assert np.allclose(df.sum((0, 1)), f, rtol=0, atol=1e-14)            # the load is kept exactly
    # expected weights: N_i min(1, m_i / mc), renormalised over the support nodes holding mass
    mc = frac * RHO * H * H
    xi = (sol.xb[p] - sol.org) / sol.h + K.PAD
    hi = (K.PAD + sol.nx, K.PAD + sol.ny)
    exp = np.zeros_like(df)
    (i0,), (wx,), _ = shapes.evaluate(shapes.BSPLINE2, np.array([xi[0]]), 0.25, K.PAD, hi[0])
    (j0,), (wy,), _ = shapes.evaluate(shapes.BSPLINE2, np.array([xi[1]]), 0.25, K.PAD, hi[1])
    for a in range(3):
        for b in range(3):
            m = sol.G[i0 + a, j0 + b, 0]
            exp[i0 + a, j0 + b] = 0.0 if m <= 1e-300 else wx[a] * wy[b] * min(1.0, m / mc)
    exp = exp / exp[:, :, 0].sum() * f
    assert np.allclose(df, exp, rtol=1e-12, atol=1e-15)
    m = sol.G[:, :, 0]
    sliver = (m > 0) & (m < 0.05 * RHO * H * H) & (np.abs(df).sum(2) > 0)
    assert sliver.any()                                                  # the node row above the top edge
    acc = np.abs(df[sliver]).max(1) / m[sliver]
    assert acc.max() <= np.abs(f).max() / mc * (1 + 1e-12)               # bounded by |f| / mc
    # without the option the same node is pushed many times harder (the fling of issue 15)
    sol0 = MPMSolver(_make(None))
    df0 = _spread(sol0, p, f)
    acc0 = np.abs(df0[sliver]).max(1) / m[sliver]
    assert acc0.max() > 2.0 * acc.max()


@pytest.mark.parametrize("frac", [0.0, 0.2])
def test_velocity_read_is_the_transpose_of_the_spread(frac):
    sol = MPMSolver(_make(frac))
    p = _top_particle(sol)
    f = np.array([0.7, -1.3])
    df = _spread(sol, p, f)
    rng = np.random.default_rng(3)
    sol.V[:, :, 2:4] = rng.normal(size=sol.V[:, :, 2:4].shape)
    S, P, B, Gr = sol.state()
    K.move_boundary(S, B, Gr, 0.0)
    assert float(f @ sol.vb[p]) == pytest.approx(float((df * sol.V[:, :, 2:4]).sum()), rel=1e-12)


def test_zero_fraction_is_the_plain_shape_weights():
    a, b = MPMSolver(_make(None)), MPMSolver(_make(0.0))
    assert (a.b_mc == 0).all() and (b.b_mc == 0).all()
    assert MPMSolver(_make(0.2)).b_mc == pytest.approx(np.full(len(a.xb), 0.2 * RHO * H * H))


def test_bad_fraction_names_the_field():
    for v in (-0.1, 0.6):
        with pytest.raises(SceneError) as e:
            _make(v)
        assert e.value.path == "mpm.boundary_sliver_fraction"
    from coupler.scene import loads_scene
    txt = SCENE.format(g=0.0, shape="bspline2", transfer="usl", extra="boundary_sliver_fraction = 0.1")
    with pytest.raises(SceneError) as e:
        loads_scene(txt.replace("boundary_particles = true", "boundary_particles = false"))
    assert e.value.path == "mpm.boundary_sliver_fraction"


def test_support_of_slivers_keeps_the_bounds():
    """Issue 15 divergence: a boundary particle 1 - 2 cells off the body, whose support reaches only the fringe of
    the points' supports (every node holding mass a sliver). Renormalising its shares over their sum gave its load
    to those slivers whole (node acceleration ~ f / (tot mc), the particle's effective mass ~ tot mc), so the DEM
    contact on it was an explicit spring on a tiny mass. Now the node acceleration is <= |f| / mc, the effective
    mass 1 / sum N_i^2 / m_i >= mc, the load's part not applied is counted as dropped, and the velocity read is
    the transpose of the spread."""
    frac = 0.2
    sol = MPMSolver(_make(frac))
    mc = frac * RHO * H * H
    p = _top_particle(sol)
    S, P, B, Gr = sol.state()
    K.sort_strips(S, P, Gr, True)
    K.scatter(S, P, Gr)
    m = sol.G[:, :, 0]
    top = max(j for j in range(m.shape[1]) if m[:, j].max() > 0)    # the top node row holding mass (slivers)
    assert 0 < m[:, top].max() < 0.1 * mc
    ytop = (top - K.PAD) * sol.h + sol.org[1]
    sol.xb[p, 1] = ytop + 1.4 * sol.h          # its support: the row `top` at the fringe, the rows above empty
    f = np.array([0.3, -2.0])
    sol.drop[:] = 0.0
    df = _spread(sol, p, f)
    moved = np.abs(df).sum(2) > 0
    assert moved.any() and (m[moved] < mc).all()                       # only slivers in its support
    acc = np.abs(df[moved]).max(1) / m[moved]
    assert acc.max() <= np.abs(f).max() / mc * (1 + 1e-12)               # bounded by |f| / mc
    N = df[moved][:, 1] / f[1]
    assert 1.0 / (N ** 2 / m[moved]).sum() >= mc * (1 - 1e-12)          # effective mass >= mc
    kept = N.sum()
    assert 0.0 < kept < 1.0
    assert np.allclose(df.sum((0, 1)), kept * f, rtol=1e-12, atol=0)
    mag = float(np.hypot(*f))
    assert sol.drop[0] == 1 and sol.drop[1] == pytest.approx((1 - kept) * mag * 1e-4, rel=1e-12)
    assert sol.drop[2] == pytest.approx(mag * 1e-4, rel=1e-12)
    rng = np.random.default_rng(5)
    sol.V[:, :, 2:4] = rng.normal(size=sol.V[:, :, 2:4].shape)
    S, P, B, Gr = sol.state()
    K.move_boundary(S, B, Gr, 0.0)
    assert float(f @ sol.vb[p]) == pytest.approx(float((df * sol.V[:, :, 2:4]).sum()), rel=1e-12)
