"""Tangential sub-models (coupler/dem/contact/tangential.py): the incremental (YADE Mindlin) spring against the total
(LIGGGHTS) one, analytically and against YADE's stored oblique impacts (shared/notes/dem_codes.md P8)."""
import math
from pathlib import Path

import numpy as np
import pytest

from adapters.liggghts.params import liggghts_model
from adapters.yade.params import check_supported as yade_supported
from coupler.dem.contact.tangential import tangential_force
from coupler.errors import UnsupportedFeature
from coupler.results import Result
from coupler.run import run_scene
from coupler.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]
WALL = ROOT / "validation" / "cases" / "xval_impacts" / "wall.toml"
HISTORY, INCREMENTAL = 1.0, 2.0


def oblique(vt, tangential, extra=None):
    return load_scene(WALL, name=f"oblique_{vt:g}_{tangential}",
                      overrides={"dem.spheres[0].velocity": [vt, -1.0, 0.0], "contacts[0].tangential": tangential,
                                 **(extra or {})})


def step(model, st, x, v=(0.0, 0.0, 0.0), fn=1e9, mu=0.3, dt=1e-6):
    """One call of the tangential law on the plane with normal y (no dashpot: beta = 0)."""
    return tangential_force(model, st, 0.0, 1.0, fn, mu, 0.0, 1.0, 0.0, v[0], v[1], v[2], dt, *x)


def test_stiffness_change_without_motion_moves_only_the_total_spring():
    """The defining difference (P8): a tangential displacement u, then the stiffness doubles (the overlap grows)
    with no tangential motion. Total spring: F = -S_t u follows the new stiffness (-2 k u); incremental: dF = -S_t
    v_t dt = 0, the force stays -k u. Both reach -k u after the first (loading) step."""
    k, u, dt = 1e6, 1e-6, 1e-6
    for model in (HISTORY, INCREMENTAL):
        r = step(model, k, (0.0, 0.0, 0.0), v=(u / dt, 0.0, 0.0), dt=dt)
        assert r[0] == pytest.approx(-k * u, rel=1e-14)
        r2 = step(model, 2 * k, r[4:7], dt=dt)
        assert r2[0] == pytest.approx((-2 * k * u) if model == HISTORY else (-k * u), rel=1e-14)
    # with a constant stiffness the two are the same law; the state differs only in what it stores (u vs F)
    rh = step(HISTORY, k, (0.0, 0.0, 0.0), v=(0.3, 0.0, 0.2), dt=dt)
    ri = step(INCREMENTAL, k, (0.0, 0.0, 0.0), v=(0.3, 0.0, 0.2), dt=dt)
    assert np.allclose(rh[:4], ri[:4], rtol=1e-14) and np.allclose(np.array(rh[4:7]) * -k, ri[4:7], rtol=1e-14)


def test_incremental_sliding_is_on_the_coulomb_cone_without_dashpot():
    k, mu, fn = 1e6, 0.3, 2.0
    ft = tangential_force(INCREMENTAL, k, 0.1, 1.0, fn, mu, 0.0, 1.0, 0.0, 5.0, 0.0, -5.0, 1e-3, 0.0, 0.0, 0.0)
    assert math.hypot(ft[0], ft[2]) == pytest.approx(mu * fn, rel=1e-14)      # capped, no dashpot added
    assert ft[0] < 0 and ft[2] > 0 and ft[3] == pytest.approx(0.5 * (mu * fn) ** 2 / k, rel=1e-14)
    assert ft[4:7] == ft[0:3]                                                   # the state is the capped force
    # the old force is kept on the new tangent plane: a normal turned by 90 degrees about z drops its x part
    r = tangential_force(INCREMENTAL, k, 0.0, 1.0, fn, mu, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1e-3, -0.4, 0.0, 0.1)
    assert r[0:3] == (0.0, 0.0, 0.1)


def test_constant_stiffness_makes_the_two_springs_one_law(tmp_path):
    """Hooke normal (constant S_t = k_t): an oblique impact in partial slip gives the same trajectory with either
    spring (to round-off)."""
    hooke = {"contacts[0].normal": {"model": "hooke", "stiffness": 2e6}}
    out = {}
    for tang in ("history", "incremental"):
        res = run_scene(oblique(0.5, tang, hooke), tmp_path / tang, progress=False)
        out[tang] = res.body("ball")[["vx", "vy", "wz"]].to_numpy()
    assert np.abs(out["history"] - out["incremental"]).max() <= 1e-9 * np.abs(out["history"]).max()


@pytest.mark.parametrize("vt", [0.5, 1.0])
def test_incremental_spring_reproduces_yade_in_partial_slip(vt, tmp_path):
    """YADE's stored oblique impacts (xval_impacts, partial slip): exit spin and peak |F_t| of the native
    incremental law within 0.2 % / 0.1 % of YADE's; the total spring misses YADE's spin by 1.2 % (v_t/v_n = 1) to
    10 % (0.5): the whole LIGGGHTS-YADE difference in partial slip is the spring formulation (P8)."""
    yade = Result.read(ROOT / "reference_runs" / "xval_impacts" / "yade" / f"oblique_{vt:g}")
    wz_y = float(yade.body("ball")["wz"].iloc[-1])
    ft_y = float(yade.contacts.groupby("t")["ft"].sum().max())
    got = {}
    for tang in ("history", "incremental"):
        res = run_scene(oblique(vt, tang), tmp_path / tang, progress=False)
        got[tang] = (float(res.body("ball")["wz"].iloc[-1]), float(res.contacts.groupby("t")["ft"].sum().max()))
    wz_i, ft_i = got["incremental"]
    assert wz_i == pytest.approx(wz_y, rel=2e-3) and ft_i == pytest.approx(ft_y, rel=1e-3)
    assert abs(got["history"][0] / wz_y - 1.0) > 0.01


def test_reference_codes_map_or_refuse_the_incremental_spring():
    sc = oblique(0.5, "incremental")
    yade_supported(sc)                                  # Mindlin is this law
    with pytest.raises(UnsupportedFeature, match=r"contacts\[0\]\.tangential"):
        liggghts_model(sc)                              # LIGGGHTS 3.8 has the total spring only
    assert liggghts_model(oblique(0.5, "history")).startswith("model hertz tangential history")
