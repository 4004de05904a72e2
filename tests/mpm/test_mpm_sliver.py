"""Boundary-particle transfer near sliver nodes (mpm.boundary_sliver_fraction, kernels._sliver_weight, issue 15):
a support node holding less than the fraction of a full node's mass (rho h^2) takes a share of the point load
scaled by its mass, so its acceleration stays bounded (also on a support holding only slivers: the part of the load
it cannot carry goes to the nearest full nodes, counted as rerouted; dropped and counted only with none within
reach); the velocity read uses the same weights (the power of the
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


def _off_body_particle(frac, dy=1.4):
    """A boundary particle dy cells above the top node row holding mass (slivers: the fringe of the points'
    supports), so its support holds only slivers (issue 15 divergence), and the grid after P2G."""
    sol = MPMSolver(_make(frac))
    p = _top_particle(sol)
    S, P, B, Gr = sol.state()
    K.sort_strips(S, P, Gr, True)
    K.scatter(S, P, Gr)
    m = sol.G[:, :, 0]
    top = max(j for j in range(m.shape[1]) if m[:, j].max() > 0)    # the top node row holding mass (slivers)
    assert 0 < m[:, top].max() < 0.1 * frac * RHO * H * H
    sol.xb[p, 1] = (top - K.PAD) * sol.h + sol.org[1] + dy * sol.h
    return sol, p


def test_support_of_slivers_reroutes_to_the_nearest_full_nodes():
    """Issue 15: a boundary particle 1 - 2 cells off the body, whose support reaches only the fringe of the points'
    supports (every node holding mass a sliver). Renormalising its shares over their sum gave its load to those
    slivers whole (node acceleration ~ f / (tot mc)); dividing by D bounded it but dropped the part 1 - tot / D. Now
    that part goes to the full nodes (m >= mc) of the nearest window around the support, by their mass: the force
    on the grid is the load (no dropped count, one rerouted), every node's acceleration is <= |f| / mc, and the
    velocity read is the transpose of the spread (it includes those nodes)."""
    frac = 0.2
    mc = frac * RHO * H * H
    sol, p = _off_body_particle(frac)
    m = sol.G[:, :, 0]
    f = np.array([0.3, -2.0])
    sol.drop[:] = 0.0
    df = _spread(sol, p, f)
    assert np.allclose(df.sum((0, 1)), f, rtol=0, atol=1e-15)          # the load is kept (round-off)
    moved = np.abs(df).sum(2) > 0
    sliver = moved & (m < mc)
    full = moved & (m >= mc)
    assert sliver.any() and full.any()                                  # its support's slivers + the full nodes
    acc = np.abs(df[moved]).max(1) / m[moved]
    assert acc.max() <= np.abs(f).max() / mc * (1 + 1e-12)               # bounded by |f| / mc
    # the slivers take s_i / D (as before), the full nodes the rest by their mass: equal acceleration
    kept = df[sliver][:, 1].sum() / f[1]
    assert 0.0 < kept < 1.0
    a_full = df[full] / m[full][:, None]
    assert np.allclose(a_full, a_full[0], rtol=1e-12, atol=0)
    assert np.allclose(a_full[0] * m[full].sum(), (1 - kept) * f, rtol=1e-12, atol=0)
    # the full nodes are the nearest: within one ring of the support, and none of the support's rows
    jf = np.nonzero(full)[1]
    js = np.nonzero(sliver)[1]
    assert jf.max() == js.min() - 1
    mag = float(np.hypot(*f))
    assert sol.drop[0] == 0 and sol.drop[1] == 0.0 and sol.drop[3] == 0.0            # nothing dropped
    assert sol.drop[6] == 1 and sol.drop[7] == pytest.approx((1 - kept) * mag * 1e-4, rel=1e-12)
    assert sol.drop[2] == pytest.approx(mag * 1e-4, rel=1e-12)
    d = sol.dropped_loads()
    assert d["count"] == 0 and d["rerouted_count"] == 1 and d["impulse_rerouted"] == sol.drop[7]
    rng = np.random.default_rng(5)
    sol.V[:, :, 2:4] = rng.normal(size=sol.V[:, :, 2:4].shape)
    S, P, B, Gr = sol.state()
    K.move_boundary(S, B, Gr, 0.0)
    assert float(f @ sol.vb[p]) == pytest.approx(float((df * sol.V[:, :, 2:4]).sum()), rel=1e-12)
    # a uniform grid velocity is read exactly (the weights sum to 1: the particle follows the body)
    sol.V[:, :, 2], sol.V[:, :, 3] = 0.25, -1.5
    K.move_boundary(S, B, Gr, 0.0)
    assert sol.vb[p] == pytest.approx([0.25, -1.5], rel=1e-13)
    assert sol.drop[4] == 0                                              # not stranded


def test_implicit_read_is_the_same_transfer():
    """The implicit scheme's boundary-particle read (implicit/kernels.move_boundary) uses the shared transfer
    (kernels._read): on the all-sliver support its displacement and velocity are the explicit read of U and V1."""
    from coupler.mpm.implicit import kernels as IK
    sol, p = _off_body_particle(0.2)
    S, P, B, Gr = sol.state()
    rng = np.random.default_rng(7)
    U = rng.normal(size=sol.G.shape[:2] + (2,))
    V1 = rng.normal(size=sol.G.shape[:2] + (2,))
    x0 = sol.xb[p].copy()
    sol.V[:, :, 2:4] = V1
    K.move_boundary(S, B, Gr, 0.0)
    v_exp = sol.vb[p].copy()
    sol.xb[p] = x0
    sol.V[:, :, 2:4] = U
    K.move_boundary(S, B, Gr, 0.0)
    u_exp = sol.vb[p].copy()
    sol.xb[p] = x0
    IK.move_boundary(S, B, sol.G, 3, U, V1)
    assert (sol.vb[p] == v_exp).all() and (sol.xb[p] - x0 == pytest.approx(u_exp, rel=1e-12, abs=1e-15))


def test_no_full_node_within_reach_drops_the_part_and_counts_it():
    """A support of slivers with no full node within kernels.REACH rings: the part 1 - tot / D really is dropped
    (counted, and limited by mpm.max_dropped_load_fraction); node accelerations stay <= |f| / mc."""
    frac = 0.2
    mc = frac * RHO * H * H
    sol, p = _off_body_particle(frac)
    S, P, B, Gr = sol.state()
    G = sol.G
    G[:, :, 0] = np.minimum(G[:, :, 0], 0.05 * mc)       # every node a sliver (hand-made grid)
    G[:, :, 3:5] = 0.0
    f = np.array([0.3, -2.0])
    sol.fb[:] = 0.0
    sol.fb[p] = f
    sol.drop[:] = 0.0
    frac_dropped, first = K.spread_loads(S, B, Gr, 1e-4)
    df = G[:, :, 3:5]
    kept = df[:, :, 1].sum() / f[1]
    assert 0.0 < kept < 1.0 and np.allclose(df.sum((0, 1)), kept * f, rtol=1e-12, atol=0)
    moved = np.abs(df).sum(2) > 0
    assert (np.abs(df[moved]).max(1) / G[:, :, 0][moved]).max() <= np.abs(f).max() / mc * (1 + 1e-12)
    assert first == p and frac_dropped == pytest.approx(1 - kept, rel=1e-12)
    assert sol.drop[0] == 1 and sol.drop[6] == 0 and sol.drop[1] == pytest.approx((1 - kept) * np.hypot(*f) * 1e-4)
