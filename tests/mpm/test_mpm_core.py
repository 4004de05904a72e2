"""MPM unit tests (issue #6): shape functions, return mapping, transfers, patch test, boundary particles,
scene errors, determinism."""
from __future__ import annotations

import math

import numpy as np
import pytest

from coupler.errors import SceneError, SimulationError
from coupler.mpm import kernels as K
from coupler.mpm import shapes
from coupler.mpm.materials import (ModelParams, RateParams, dp_plane_strain_match, mc_return_principal,
                                   update_stress)
from coupler.mpm.solver import MPMSolver
from coupler.scene import loads_scene
from tests.conftest import ROOT, on_1_and_2_threads, scene_toml

BASE = scene_toml("""[mpm]
shape_function = "{shape}"
transfer = "{transfer}"
boundary_particles = {bp}
damping = {damp}
[mpm.grid]
origin = [0.0, 0.0]
size = [{sx}, {sy}]
cell_size = {h}
[mpm.boundary]
left = {{ kind = "slip" }}
right = {{ kind = "slip" }}
bottom = {bottom}
top = {{ kind = "open" }}
[[mpm.bodies]]
name = "b"
material = "m"
rectangle = {{ min = [{x0}, {y0}], max = [{x1}, {y1}] }}
particles_per_cell = {ppc}
constitutive = {{ model = "{model}", friction_angle = {phi}, cohesion = {c} }}
{body_extra}
""", dimension=2, gravity="[0.0, {g}, 0.0]", t_end="{t_end}", dt=None, output_interval="{t_end}",
                  materials={"m": {"density": "1000.0", "young": "1.0e6", "poisson": "0.3"}}, contacts=None)


_DEFAULTS = dict(g=-9.81, t_end=0.01, shape="bspline2", transfer="musl", bp="false", sx=1.0, sy=1.0, h=0.1,
                 x0=0.2, y0=0.0, x1=0.6, y1=0.4, ppc=2, model="elastic", phi=0.0, c=0.0, damp=0.0,
                 bottom='{ kind = "fixed" }', body_extra="")


def make(**kw):
    return loads_scene(BASE.format(**{**_DEFAULTS, **kw}))


@pytest.mark.parametrize("kind", [0, 1, 2])
def test_shape_partition_of_unity_and_gradient(kind):
    xi = np.linspace(2.0, 8.0, 301)       # walls at 2 and 8 (bspline2 boundary-modified within half a cell)
    i0, w, dw = shapes.evaluate(kind, xi, 0.25, 2.0, 8.0)
    assert np.allclose(w.sum(1), 1.0, atol=1e-13)
    assert np.allclose(dw.sum(1), 0.0, atol=1e-13)
    # linear reproduction: sum N_i x_i = x, and its derivative sum dN_i x_i = 1
    assert np.allclose((w * (i0[:, None] + np.arange(3))).sum(1), xi, atol=1e-12)
    assert np.allclose((dw * (i0[:, None] + np.arange(3))).sum(1), 1.0, atol=1e-12)
    assert np.all(w >= -1e-15)
    # continuity of each node's weight and derivative along x (C0 / C1 except linear and GIMP kinks)
    xf = np.linspace(2.0, 8.0, 60001)
    i0, w, dw = shapes.evaluate(kind, xf, 0.25, 2.0, 8.0)
    W = np.zeros((len(xf), 12))
    D = np.zeros((len(xf), 12))
    for a in range(3):
        W[np.arange(len(xf)), i0 + a] += w[:, a]
        D[np.arange(len(xf)), i0 + a] += dw[:, a]
    assert np.abs(np.diff(W, axis=0)).max() < 1e-3
    if kind == 2:
        assert np.abs(np.diff(D, axis=0)).max() < 1e-3


def test_bspline_boundary_modified_at_walls():
    """bspline2 on the wall: the wall node alone (Kronecker), no weight on the ghost node outside; in the half
    cell next to the wall linear in the distance; interior unchanged."""
    i0, w, dw = shapes.evaluate(2, np.array([2.0, 2.2, 8.0, 7.9, 3.0]), 0.25, 2.0, 8.0)
    assert np.array_equal(w[0], [0.0, 1.0, 0.0]) and i0[0] == 1
    assert np.allclose(w[1], [0.0, 0.8, 0.2]) and np.allclose(dw[1], [0.0, -1.0, 1.0])
    assert np.array_equal(w[2], [0.0, 1.0, 0.0]) and i0[2] == 7
    assert np.allclose(w[3], [0.1, 0.9, 0.0])
    assert np.allclose(w[4], [0.125, 0.75, 0.125])


PRM = dict(K=1.0e6 / (3 * 0.4), G=1.0e6 / 2.6)


def _mc_f(p, phi, c):
    return (p[0] - p[2]) + (p[0] + p[2]) * math.sin(phi) - 2 * c * math.cos(phi)


@pytest.mark.parametrize("trial,mode", [((-1000.0, -5000.0, -9000.0), 1), ((-1000.0, -1500.0, -9000.0), 3),
                                        ((-1000.0, -8500.0, -9000.0), 2), ((2000.0, 1500.0, 1000.0), 4)])
def test_mc_return_on_surface_and_modes(trial, mode):
    phi, psi, c = math.radians(30), math.radians(10), 100.0
    out = np.zeros(5)
    mc_return_principal(np.array(trial), PRM["K"], PRM["G"], phi, c, psi, out)
    assert int(out[4]) == mode
    s = out[:3]
    assert s[0] >= s[1] - 1e-9 and s[1] >= s[2] - 1e-9
    assert abs(_mc_f(s, phi, c)) < 1e-8 * 1e4
    if mode == 2:  # right edge: sigma_1 plane with sigma_2 too
        assert abs((s[0] - s[1]) + (s[0] + s[1]) * math.sin(phi) - 2 * c * math.cos(phi)) < 1e-4
    if mode == 3:
        assert abs((s[1] - s[2]) + (s[1] + s[2]) * math.sin(phi) - 2 * c * math.cos(phi)) < 1e-4
    if mode == 4:
        assert np.allclose(s, c / math.tan(phi))


@pytest.mark.parametrize("psi_deg", [0.0, 10.0, 30.0])
def test_mc_flow_direction_follows_dilatancy(psi_deg):
    """Main-plane return: plastic strain increment = C^-1 (sigma_tr - sigma); its volumetric / deviatoric ratio
    equals that of the flow vector N = (1 + sin psi, 0, -1 + sin psi)."""
    phi, psi = math.radians(30), math.radians(psi_deg)
    Kb, G = PRM["K"], PRM["G"]
    tr = np.array([-1000.0, -5000.0, -9000.0])
    out = np.zeros(5)
    mc_return_principal(tr, Kb, G, phi, 0.0, psi, out)
    assert int(out[4]) == 1
    ds = tr - out[:3]
    lam = Kb - 2 * G / 3
    D = np.full((3, 3), lam) + 2 * G * np.eye(3)
    dep = np.linalg.solve(D, ds)
    N = np.array([1 + math.sin(psi), 0.0, -1 + math.sin(psi)])
    assert np.allclose(dep / out[3], N, rtol=1e-9, atol=1e-12)


def test_dp_matches_mc_in_plane_strain():
    """Plane-strain match (de Souza Neto et al. 2008, eq. 8.94): on the DP cone, at the state where the associated
    plastic flow has no out-of-plane component (s_zz = -2 eta sqrt(J2) / 3), the in-plane Mohr circle touches the
    MC envelope: radius = -centre sin(phi) + c cos(phi)."""
    from scipy.optimize import brentq
    phi, c = math.radians(25.0), 50.0
    eta, xi = dp_plane_strain_match(phi, c)
    for cen in (-1e3, -1e4):
        def state(r):
            # s_zz from the zero-out-of-plane-flow condition, solved by fixed point (converges: |d/d.| < 1)
            szz = cen
            for _ in range(200):
                p = (2 * cen + szz) / 3
                s = np.array([cen + r - p, cen - r - p, szz - p])
                j2 = 0.5 * (s @ s)
                szz = p - 2 * eta * math.sqrt(j2) / 3
            p = (2 * cen + szz) / 3
            s = np.array([cen + r - p, cen - r - p, szz - p])
            return math.sqrt(0.5 * (s @ s)) + eta * p - xi * c
        r = brentq(state, 1e-9, -cen * 2 + 10 * c)
        assert r == pytest.approx(-cen * math.sin(phi) + c * math.cos(phi), rel=1e-8)
    # and the DP kernel returns a trial state onto the cone: f = 0 afterwards
    prm = ModelParams("drucker_prager", 1e6, 0.3, 25.0, 50.0, 10.0).pack()
    s = np.array([-1000.0, -3000.0, 800.0, -1500.0])
    tmp = np.zeros(8)
    ep = update_stress(prm, s, np.zeros(3), 0.0, 0.0, tmp)
    p = (s[0] + s[1] + s[3]) / 3
    d = np.array([s[0] - p, s[1] - p, s[3] - p])
    f = math.sqrt(0.5 * (d @ d) + s[2] ** 2) + eta * p - xi * 50.0
    assert ep > 0 and abs(f) < 1e-8 * 1e3


@pytest.mark.parametrize("shape", ["linear", "gimp", "bspline2"])
def test_p2g_mass_momentum(shape):
    sol = MPMSolver(make(shape=shape))
    rng = np.random.default_rng(1)
    sol.v[:] = rng.normal(size=sol.v.shape)
    o = sol.org
    K.strip_sort(sol.kind, sol.x, o[0], sol.h, sol.strip_start, sol._scratch, sol.strip_order)
    assert sorted(sol.strip_order) == list(range(len(sol.m)))
    K.p2g(sol.kind, sol.x, sol.v, sol.C, sol.m, sol.vol, sol.s, sol.lp, sol.fext, o[0], o[1], sol.h, sol.nx,
          sol.ny, 0.0, 0.0, False, sol.strip_start, sol.strip_order, sol.G)
    assert sol.G[..., 0].sum() == pytest.approx(sol.m.sum(), rel=1e-14)
    P = (sol.m[:, None] * sol.v).sum(0)
    assert np.allclose(sol.G[..., 1:3].sum((0, 1)), P, rtol=1e-12, atol=1e-12 * np.abs(P).max())
    # G2P of a uniform grid velocity returns it exactly (PIC part); stage 0 with APIC (mode 2), no stress change
    sol.V[..., 0:2] = 0.0
    sol.V[..., 2:4] = np.array([0.3, -0.2])
    x0 = sol.x.copy()
    bad = K.gather(0, sol.kind, sol.x, sol.v, sol.C, sol.F, sol.vol, sol.vol0, sol.s, sol.eps_p, sol.prm, sol.mid,
                   sol.lp, o[0], o[1], sol.h, sol.nx, sol.ny, 1e-3, sol.V, 2, sol.box)
    assert bad == -1
    assert np.allclose(sol.v, [0.3, -0.2], atol=1e-13)
    assert np.allclose(sol.x - x0, [3e-4, -2e-4], atol=1e-15)
    assert np.abs(sol.C).max() < 1e-12 and np.abs(sol.s).max() < 1e-6


def test_patch_uniform_stress_stays_uniform():
    """No gravity, uniform initial stress in a body filling the grid between fixed walls: zero net nodal force
    at interior nodes, so stress and position do not change."""
    sc = make(g=0.0, x0=0.0, y0=0.0, x1=1.0, y1=1.0, shape="gimp")
    sol = MPMSolver(sc)
    sol.bc[:] = 0  # all sides fixed
    sol.s[:] = [-1000.0, -500.0, 0.0, -450.0]
    s0 = sol.s.copy()
    for _ in range(20):
        sol.step()
    assert np.allclose(sol.s, s0, rtol=1e-10, atol=1e-9)
    assert np.abs(sol.v).max() < 1e-12


def test_boundary_particles_prescribed_load():
    """Elastic block on a fixed base, roller walls, uniform pressure q on the top edge through boundary particles.
    With local damping the top settles to the oedometric q H / M."""
    sc = make(g=0.0, bp="true", x0=0.0, x1=0.2, y0=0.0, y1=0.4, sx=0.2, sy=0.6, h=0.05, shape="gimp", t_end=1.0,
              damp=0.3)
    sol = MPMSolver(sc)
    st = sol.boundary_particle_state()
    top = np.isclose(st["x"][:, 1], 0.4)
    q = 1000.0
    f = np.zeros_like(st["x"])
    f[top, 1] = -q * st["area"][top]
    assert f[:, 1].sum() == pytest.approx(-q * 0.2)
    sol.apply_point_loads(f)
    M = 1e6 * 0.7 / (1.3 * 0.4)
    c = math.sqrt(M / 1000.0)
    T = 4 * 0.4 / c
    n = int(round(15 * T / sol.dt))
    for _ in range(n):
        sol.step()
    u = sol.boundary_particle_state()["displacement"][top, 1]
    assert np.abs(sol.v).max() < 0.05 * q * 0.4 / M / T  # at rest
    assert u.mean() == pytest.approx(-q * 0.4 / M, rel=0.02)
    st = sol.boundary_particle_state()
    assert st["velocity"].shape == st["x"].shape
    # points created on the roller walls / fixed base stay attached: normal coordinate exactly the wall's, and
    # (slip) they slide along the wall with the material; the base (fixed) points do not move at all
    w = st["wall"]
    assert set(w[~top]) == {0, 1, 2} and (w[top] == -1).all()
    assert (st["x"][w == 0, 0] == 0.0).all() and (st["x"][w == 1, 0] == 0.2).all()
    assert (st["displacement"][w == 2] == 0.0).all()
    assert st["displacement"][w == 0, 1].min() < -0.5 * q * 0.4 / M


@pytest.mark.parametrize("kw,path", [
    (dict(ppc=0), "mpm.bodies[0].particles_per_cell"),
    (dict(x1=1.2), "mpm.bodies[0].rectangle"),
    (dict(h=0.3), "mpm.grid.cell_size"),
    (dict(model="mohr_coulomb"), "mpm.bodies[0].constitutive.cohesion"),
])
def test_bad_scene_errors(kw, path):
    with pytest.raises(SceneError) as e:
        make(**kw)
    assert e.value.path == path


def test_rate_friction_only_on_mohr_coulomb_and_positive():
    rate = "delta_mu = 0.26, i0 = 0.279, grain_diameter = 1e-3, grain_density = 2650.0"
    with pytest.raises(SceneError) as e:
        loads_scene(BASE.format(**{**_DEFAULTS, "model": "drucker_prager", "phi": 20.0}).replace(
            "cohesion = 0.0 }", f"cohesion = 0.0, rate = {{ {rate} }} }}"))
    assert e.value.path == "mpm.bodies[0].constitutive.rate" and "mohr_coulomb" in str(e.value)
    with pytest.raises(SceneError) as e:
        loads_scene(BASE.format(**{**_DEFAULTS, "model": "mohr_coulomb", "phi": 20.0}).replace(
            "cohesion = 0.0 }", f"cohesion = 0.0, rate = {{ {rate.replace('i0 = 0.279', 'i0 = 0.0')} }} }}"))
    assert e.value.path == "mpm.bodies[0].constitutive.rate.i0"


@pytest.mark.parametrize("gdot", [0.0, 3.0, 30.0, 300.0])
def test_rate_friction_simple_shear(gdot):
    """mu(I) friction (Jop et al. 2006): steady simple shear at rate gdot from sigma_xx = sigma_yy = sigma_zz = -p
    (psi = 0, the mean stress stays p): the shear stress ends on the MC surface of phi(I), tau = p sin phi(I), with
    tan phi(I) = tan phi + delta_mu I / (I0 + I), I = gdot d / sqrt(p / rho_s); gdot = 0 gives tau = 0 (no
    strain, elastic)."""
    phi, dmu, i0, d, rho, p = 19.8, 0.26, 0.279, 1.25e-3, 2650.0, 1000.0
    prm = ModelParams("mohr_coulomb", 0.84e6, 0.3, phi, 0.0, 0.0, RateParams(dmu, i0, d, rho)).pack()
    s = np.array([-p, -p, 0.0, -p])
    dt = 1e-4
    for _ in range(3000):
        update_stress(prm, s, np.array([0.0, 0.0, gdot * dt]), 0.0, 0.0, dt=dt)
    inum = gdot * d / math.sqrt(p / rho)
    mu = math.tan(math.radians(phi)) + dmu * inum / (i0 + inum)
    assert -(s[0] + s[1] + s[3]) / 3 == pytest.approx(p, rel=1e-9)
    assert s[2] == pytest.approx(p * mu / math.sqrt(1 + mu * mu) if gdot > 0 else 0.0, rel=1e-6, abs=1e-9)
    # without the rate table the same shear mobilises tau = p sin(phi) at any rate
    prm0 = ModelParams("mohr_coulomb", 0.84e6, 0.3, phi, 0.0, 0.0).pack()
    s0 = np.array([-p, -p, 0.0, -p])
    for _ in range(3000):
        update_stress(prm0, s0, np.array([0.0, 0.0, max(gdot, 3.0) * dt]), 0.0, 0.0, dt=dt)
    assert s0[2] == pytest.approx(p * math.sin(math.radians(phi)), rel=1e-6)


def test_boundary_particles_move_like_material_points():
    """A free-floating block translating at a uniform velocity: its boundary particles (none on a wall) move by
    exactly dt * v each step (no clipping, renormalised interpolation of a uniform field), like the material."""
    sc = make(g=0.0, bp="true", x0=0.3, x1=0.5, y0=0.3, y1=0.5, h=0.05, t_end=1.0)
    sol = MPMSolver(sc)
    assert (sol.b_wall == -1).all()
    sol.v[:] = [0.2, -0.1]
    xb0 = sol.xb.copy()
    for _ in range(10):
        sol.step()
    st = sol.boundary_particle_state()
    assert np.allclose(st["velocity"], [0.2, -0.1], rtol=0, atol=1e-12)
    assert np.allclose(st["x"] - xb0, np.array([0.2, -0.1]) * 10 * sol.dt, rtol=0, atol=1e-12)
    assert np.allclose(sol.x - sol.x0, np.array([0.2, -0.1]) * 10 * sol.dt, rtol=0, atol=1e-12)


def test_boundary_particle_leaving_grid_raises():
    """Open top: the outline points on the top edge are not attached to anything; moving up they leave the grid
    before any material point does, and the run stops naming the boundary particle (no clipping to the box)."""
    sc = make(g=0.0, bp="true", x0=0.2, x1=0.6, y0=0.6, y1=1.0, t_end=1.0)
    sol = MPMSolver(sc)
    sol.v[:, 1] = 0.5
    with pytest.raises(SimulationError) as e:
        sol.step()
    assert e.value.quantity == "position (left the grid)" and e.value.step == 1
    assert "boundary particle" in str(e.value) and e.value.body == "b"
    assert sol.xb[:, 1].max() > 1.0          # where it really went: not held on the box
    sol = MPMSolver(sc)
    sol.xb[3, 0] = np.nan
    with pytest.raises(SimulationError) as e:
        sol.step()
    assert e.value.quantity == "position" and "boundary particle 3" in str(e.value) and e.value.step == 0


def test_equivalent_plastic_strain_definition():
    """eps_p increment = sqrt(2/3 de:de), de = dev(d eps_p). MC main plane: d eps_p = dgamma N (principal axes);
    psi = 0 gives (2/sqrt 3) dgamma. DP (radial return): de = dgamma s / (2 sqrt J2), so sqrt(2/3 de:de) =
    dgamma / sqrt 3."""
    for psi in (0.0, 10.0):
        prm = ModelParams("mohr_coulomb", 1e6, 0.3, 30.0, 100.0, psi).pack()
        s = np.array([-1000.0, -9000.0, 0.0, -5000.0])       # principal (xx, zz, yy) = (s1, s2, s3)
        out = np.zeros(5)
        Kb, G = prm[1], prm[2]
        mc_return_principal(np.array([-1000.0, -5000.0, -9000.0]), Kb, G, math.radians(30), 100.0,
                            math.radians(psi), out)
        assert int(out[4]) == 1
        sp = math.sin(math.radians(psi))
        N = np.array([1 + sp, 0.0, -1 + sp])
        dev = N - N.mean()
        ref = out[3] * math.sqrt(2 / 3 * dev @ dev)
        ep = update_stress(prm, s, np.zeros(3), 0.0, 0.0)
        assert ep == pytest.approx(ref, rel=1e-10)
        assert np.allclose([s[0], s[3], s[1]], out[:3], rtol=1e-12)
        if psi == 0.0:
            assert ep == pytest.approx(2 / math.sqrt(3) * out[3], rel=1e-10)
    prm = ModelParams("drucker_prager", 1e6, 0.3, 25.0, 50.0, 10.0).pack()
    Kb, G = prm[1], prm[2]
    eta, xi = dp_plane_strain_match(math.radians(25.0), 50.0)
    etab, _ = dp_plane_strain_match(math.radians(10.0), 50.0)
    s = np.array([-1000.0, -3000.0, 800.0, -1500.0])
    p = (s[0] + s[1] + s[3]) / 3
    d = np.array([s[0] - p, s[1] - p, s[3] - p])
    f = math.sqrt(0.5 * (d @ d) + s[2] ** 2) + eta * p - xi * 50.0
    dg = f / (G + Kb * eta * etab)
    ep = update_stress(prm, s, np.zeros(3), 0.0, 0.0)
    assert ep == pytest.approx(dg / math.sqrt(3), rel=1e-10)
    # elastic step: no increment
    prm = ModelParams("mohr_coulomb", 1e6, 0.3, 30.0, 100.0, 0.0).pack()
    assert update_stress(prm, np.array([-1000.0, -1100.0, 0.0, -1050.0]), np.zeros(3), 0.0, 0.25) == 0.25


@pytest.mark.parametrize("transfer", ["usl", "musl", "apic"])
def test_uniform_translation_is_stress_free(transfer):
    """Galilean invariance: a block translating at uniform speed (no gravity, no walls reached) gets no strain.
    For MUSL this needs the remap with the same shape functions as the mass (S at x^n): momentum mapped from the
    moved points but divided by the old nodal mass gives wrong velocities at the body edge."""
    sc = make(g=0.0, x0=0.3, x1=0.5, y0=0.3, y1=0.5, h=0.05, transfer=transfer, shape="gimp")
    sol = MPMSolver(sc)
    sol.v[:] = [3.0, -2.0]
    for _ in range(20):
        sol.step()
    assert np.abs(sol.s).max() < 1e-9 * 1e6
    assert np.allclose(sol.v, [3.0, -2.0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("transfer, calls", [("musl", "steps"), ("apic", "steps"), ("apic", "one"),
                                              ("usl", "one")])
def test_bitwise_identical_for_1_and_2_threads(transfer, calls):
    """Colour-stripped parallel P2G + per-point gathers: the same bits whatever the thread count, one step per call
    and in one compiled loop (kernels.advance)."""
    def run():
        sol = MPMSolver(make(model="mohr_coulomb", phi=20.0, transfer=transfer, h=0.02, bp="true"))
        if calls == "steps":
            for _ in range(150):
                sol.step()
        else:
            sol.advance(150)
        return [sol.x, sol.v, sol.s, sol.F, sol.eps_p, sol.G, sol.V, sol.xb]

    outs = on_1_and_2_threads(run)
    assert len(outs[0][0]) > 3 * K.CHUNK and outs[0][4].max() > 0.0   # several chunks; plastic flow happened
    for a, b in zip(*outs):
        assert np.array_equal(a, b)


def test_stored_order_is_invisible():
    """MPMSolver._reorder stores the points in strip order every REORDER_EVERY steps: the bits of a run do not
    depend on how it is cut into advance() calls, and the point table keeps each point's id and row."""
    import pandas as pd

    from coupler.mpm.solver import REORDER_EVERY
    sc = dict(model="mohr_coulomb", phi=20.0, transfer="apic", h=0.02)
    a, b = MPMSolver(make(**sc)), MPMSolver(make(**sc))
    x0 = a.x.copy()
    n = 2 * REORDER_EVERY + 17
    a.advance(n)
    for k in (REORDER_EVERY - 3, 5, REORDER_EVERY, 15):
        b.advance(k)
    assert b.nstep == n
    assert not np.array_equal(a.pid, np.arange(len(a.pid)))      # the stored order did change
    fa, fb = a.particles_frame(), b.particles_frame()
    pd.testing.assert_frame_equal(fa, fb, check_exact=True)
    assert np.array_equal(fa["id"], np.arange(len(fa)))            # rows in id order
    assert np.array_equal(a.x0[np.argsort(a.pid)], x0)              # each row kept its point's data


def test_point_leaving_grid_raises():
    sc = make(g=0.0, y0=0.6, y1=0.99)
    sol = MPMSolver(sc)
    sol.v[:, 1] = 50.0
    sol.dt = 1e-3
    with pytest.raises(SimulationError) as e:
        for _ in range(100):
            sol.step()
    assert "material point" in str(e.value) and e.value.quantity.startswith("position")


def test_gimp_point_at_a_wall_stays_within_its_half_width():
    """uGIMP: a point whose domain overlaps the base still feels the first interior node, so the Bui collapse
    (h = 5 mm, friction base) draws a centre below the base at t ~ 0.37 s; it stays within lp h of it (the
    leave-the-grid check allows exactly that, and only for GIMP), and a point pushed further still stops the run."""
    from pathlib import Path
    from coupler.scene import load_scene
    bui = Path(ROOT) / "validation" / "cases" / "mpm_bui_collapse" / "scene.toml"
    sol = MPMSolver(load_scene(bui, overrides={"mpm.grid.cell_size": 0.005, "mpm.shape_function": "gimp"}))
    lp = float(sol.lp.max()) * sol.h
    ymin = 0.0
    while sol.t < 0.42:
        sol.step()
        ymin = min(ymin, float(sol.x[:, 1].min()))
    assert sol.box_tol == pytest.approx(lp) and -lp <= ymin < 0.0
    sol.x[0, 1] = -1.01 * lp
    with pytest.raises(SimulationError) as e:
        sol.step()
    assert "GIMP half-width" in str(e.value) and e.value.quantity == "position (left the grid)"
    # the other shapes keep the grid box itself
    assert MPMSolver(make()).box_tol == 0.0


def test_deterministic():
    outs = []
    for _ in range(2):
        sol = MPMSolver(make(model="mohr_coulomb", phi=20.0, transfer="apic"))
        for _ in range(50):
            sol.step()
        outs.append((sol.x.copy(), sol.s.copy()))
    assert np.array_equal(outs[0][0], outs[1][0]) and np.array_equal(outs[0][1], outs[1][1])


def test_nan_raises_with_quantity():
    sol = MPMSolver(make())
    sol.s[3, 0] = np.nan
    with pytest.raises(SimulationError) as e:
        for _ in range(3):
            sol.step()
    assert e.value.quantity in ("stress", "position")


def test_run_scene_outputs(tmp_path):
    from coupler.results import Result
    from coupler.run import run_scene
    sc = make(t_end=0.02)
    res = run_scene(sc, tmp_path, backend="native")
    assert len(res.bodies) == 0                                   # bodies.csv: rigid (DEM) bodies only
    assert list(res.mpm_bodies["body"].unique()) == ["b"] and (tmp_path / "mpm_bodies.csv").exists()
    assert res.energy["dissipated"].isna().all() and len(res.contacts) == 0
    assert (tmp_path / "particles_0.csv").exists()
    assert not list(tmp_path.glob("*.vtu"))        # ParaView files only with [output] vtk = true (vtk/)
    back = Result.read(tmp_path)
    assert len(back.particles) == len(res.particles)


@pytest.mark.parametrize("transfer", ["usl", "musl", "apic"])
@pytest.mark.parametrize("shape", ["linear", "gimp", "bspline2"])
def test_momentum_conserved_without_external_forces(transfer, shape):
    """No gravity, no wall reached: a free elastic block with a random velocity field deforms (internal forces sum
    to zero over the nodes, sum_i grad N_i = 0) and its total linear momentum stays at the initial value to
    round-off through every P2G / grid update / G2P of 30 steps; mass is exactly constant."""
    sol = MPMSolver(make(g=0.0, x0=0.3, x1=0.6, y0=0.3, y1=0.6, h=0.05, transfer=transfer, shape=shape))
    rng = np.random.default_rng(7)
    sol.v[:] = 0.05 * rng.normal(size=sol.v.shape)
    P0 = (sol.m[:, None] * sol.v).sum(0)
    scale = (sol.m[:, None] * np.abs(sol.v)).sum()
    m0 = sol.m.copy()
    for _ in range(30):
        sol.step()
    assert np.abs(sol.s).max() > 1.0                      # the block did deform
    P = (sol.m[:, None] * sol.v).sum(0)
    assert np.abs(P - P0).max() < 1e-13 * scale
    assert np.array_equal(sol.m, m0)


def test_geostatic_initial_stress_is_in_equilibrium():
    """initial_stress = geostatic: sigma_yy = rho g (H - y), sigma_xx = sigma_zz = k0 sigma_yy. An elastic column
    between rollers on a fixed base with k0 = nu / (1 - nu) (the default for the elastic law) is the oedometric
    equilibrium: it stays at rest (velocities stay below 1 % of the free-fall speed over the same time)."""
    geo = dict(transfer="apic", sx=0.4, sy=0.5, h=0.05, x0=0.0, x1=0.4, y1=0.4)
    sc = make(**geo, body_extra='initial_stress = { kind = "geostatic" }')
    body = sc.mpm.bodies[0]
    assert body.k0 == pytest.approx(0.3 / 0.7) and body.surface == 0.4
    sol = MPMSolver(sc)
    y = sol.x[:, 1]
    assert np.allclose(sol.s[:, 1], -1000.0 * 9.81 * (0.4 - y)) and np.allclose(sol.s[:, 0], 0.3 / 0.7 * sol.s[:, 1])
    n = 200
    for _ in range(n):
        sol.step()
    assert np.abs(sol.v).max() < 0.01 * 9.81 * n * sol.dt
    with pytest.raises(SceneError) as e:
        make(**geo, body_extra='initial_stress = { kind = "geostatic", surface = 0.3 }')
    assert e.value.path == "mpm.bodies[0].initial_stress.surface"


@pytest.mark.parametrize("shape", ["gimp", "bspline2"])
def test_block_sliding_on_friction_base(shape):
    """Analytic sliding block: an elastic block launched at v0 along a Coulomb-friction base (mu) decelerates at
    mu g (Bardenhagen et al. 2001 grid contact: tangential nodal velocity reduced by mu |dv_n|) and stops after
    v0^2 / (2 mu g)."""
    mu, v0, g = 0.3, 1.0, 9.81
    sol = MPMSolver(make(g=-g, t_end=1.0, shape=shape, transfer="apic", sy=0.2, h=0.025, x0=0.05, x1=0.25, y1=0.1,
                         bottom=f'{{ kind = "friction", friction = {mu} }}',
                         body_extra=f'initial_stress = {{ kind = "geostatic" }}\nvelocity = [{v0}, 0.0]'))
    xc0 = np.average(sol.x[:, 0], weights=sol.m)
    t_half = 0.5 * v0 / (mu * g)
    while sol.t < t_half:
        sol.step()
    u = np.average(sol.v[:, 0], weights=sol.m)
    assert u == pytest.approx(v0 - mu * g * sol.t, rel=0.02)
    while sol.t < 2.0 * v0 / (mu * g):
        sol.step()
    dist = np.average(sol.x[:, 0], weights=sol.m) - xc0
    assert abs(np.average(sol.v[:, 0], weights=sol.m)) < 0.01 * v0
    assert dist == pytest.approx(v0 ** 2 / (2 * mu * g), rel=0.02)
