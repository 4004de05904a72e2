"""The flow-against-blocks case (issue 15): both scene files model the same column mass per unit depth and the same
blocks; the per-block loads take the sign of each contact row (force on i) and its class (flow, floor, block), so
the momentum balance of a block closes on a synthetic history; stored reference members keep the block rows only."""
import importlib
import json
import math

import numpy as np
import pandas as pd
import pytest

from coupler.results import BODY_COLUMNS, CONTACT_COLUMNS, Result
from coupler.scene import load_scene
from validation.framework import CASES_DIR
from validation.metrics import scene_mpm_body_extent

CASE = importlib.import_module("validation.cases.coupled_flow_blocks.case")
DIR = CASES_DIR / "coupled_flow_blocks"


def test_both_scenes_have_the_same_column_mass_per_depth_and_blocks():
    cp, dm = load_scene(DIR / "coupled.toml"), load_scene(DIR / "dem_only.toml")
    th = cp.coupling.thickness
    body = cp.mpm.bodies[0]
    rho = cp.materials[body.material].density
    (x0, y0), (x1, y1) = scene_mpm_body_extent(cp)
    mpm_mass = rho * (x1 - x0) * (y1 - y0)                          # kg per metre of depth
    grains = sum(dm.materials[m].density * 4 / 3 * math.pi * r ** 3 for m, r in zip(dm.dem.material, dm.dem.radius))
    assert grains / th == pytest.approx(mpm_mass, rel=1e-5)
    assert len(dm.dem.radius) == 505
    for name in CASE.BLOCKS:
        assert CASE._mass(cp, name) / th == pytest.approx(2700 * 0.02 * 0.02, rel=1e-5)   # solid aluminium block
        ca, cb = [next(c for c in s.dem.clusters if c.name == name) for s in (cp, dm)]
        assert np.array_equal(ca.position, cb.position) and ca.template == cb.template
    assert cp.coupling.edges == [1, 2]                     # the right and top sides of the rectangle


def _synthetic(M, T=0.1, n=41):
    t = np.linspace(0.0, T, n)
    g = 9.81
    ax = (2.0 - 0.5) / M
    bodies, contacts = [], []
    for k, name in enumerate(CASE.BLOCKS):
        moving = name == "block1"
        for tt in t:
            bodies.append({"t": tt, "body": name, "x": 0.1 + (0.5 * ax * tt ** 2 if moving else 0.0),
                           "y": 0.01 + 0.02 * k, "z": 0.0, "vx": ax * tt if moving else 0.0, "vy": 0.0, "vz": 0.0,
                           "qw": 1.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "wx": 0.0, "wy": 0.0, "wz": 0.0})
    for tt in t:
        # a column sphere as i: the force on the sphere is -2 N, so +2 N on block1
        contacts.append({"t": tt, "i": "col3s:7", "j": "block1", "fx": -2.0, "fy": 0.0, "fz": 0.0, "fn": 2.0,
                         "ft": 0.0, "overlap": 1e-5})
        contacts.append({"t": tt, "i": "block1", "j": "wall:floor", "fx": -0.5, "fy": M * g, "fz": 0.0,
                         "fn": M * g, "ft": 0.5, "overlap": 1e-5})
    return Result(bodies=pd.DataFrame(bodies)[BODY_COLUMNS], contacts=pd.DataFrame(contacts)[CONTACT_COLUMNS])


def test_block_loads_signs_classes_and_momentum_balance():
    scene = load_scene(DIR / "dem_only.toml")
    M = CASE._mass(scene, "block1")
    rows, hist = CASE.block_metrics(_synthetic(M), scene, np.array([0.0, -9.81, 0.0]))
    r = rows["block1"]
    assert r["impulse_x"] == pytest.approx(0.2) and r["imp_floor_x"] == pytest.approx(-0.05)
    assert r["imp_block_x"] == 0.0 and r["dp_x"] == pytest.approx(0.15)
    assert r["balance"] < 1e-12
    assert r["peak_fx_raw"] == 2.0 and r["t_impact"] == 0.0
    assert r["dx"] == pytest.approx(0.5 * 1.5 / M * 0.01)
    F = hist["block1"][4]
    assert np.allclose(F[:, 0], [2.0, 0.0]) and np.allclose(F[:, 1, 0], -0.5) and np.allclose(F[:, 2], 0.0)
    # a block-block row counts on both blocks with opposite signs
    res = _synthetic(M)
    extra = pd.DataFrame([{"t": 0.0, "i": "block1", "j": "block2", "fx": 0.0, "fy": -1.0, "fz": 0.0, "fn": 1.0,
                           "ft": 0.0, "overlap": 1e-6}])
    res.contacts = pd.concat([res.contacts, extra], ignore_index=True)
    loads = CASE.block_loads(res, np.linspace(0.0, 0.1, 41))
    assert loads["block1"][0, 2, 1] == -1.0 and loads["block2"][0, 2, 1] == 1.0


def test_trim_reference_keeps_block_rows_only(tmp_path):
    res = _synthetic(0.005)
    grain = pd.DataFrame([{c: 0.0 for c in BODY_COLUMNS} | {"body": "col0l:1"}])
    pd.concat([res.bodies, grain]).to_csv(tmp_path / "bodies.csv", index=False)
    c = pd.concat([res.contacts, pd.DataFrame([{"t": 0.0, "i": "col0l:1", "j": "col0l:2", "fx": 1.0, "fy": 0.0,
                                                 "fz": 0.0, "fn": 1.0, "ft": 0.0, "overlap": 1e-6}])])
    c.to_csv(tmp_path / "contacts.csv", index=False)
    (tmp_path / "provenance.json").write_text(json.dumps({"code": "YADE"}))
    CASE.trim_reference(tmp_path)
    b = pd.read_csv(tmp_path / "bodies.csv")
    cc = pd.read_csv(tmp_path / "contacts.csv")
    assert set(b["body"]) == set(CASE.BLOCKS) and len(cc) == len(res.contacts)
    assert "stored_tables" in json.loads((tmp_path / "provenance.json").read_text())


def test_a_member_whose_packing_cannot_be_placed_is_counted_not_dropped_silently():
    """--full's N_MEMBERS_FULL seeds: seed 22 cannot place its packing; with a list it is reported there and left
    out, without one the SceneError is raised (members beyond it still built)."""
    from coupler.errors import SceneError
    unplaced = []
    got = CASE.members(DIR, 24, contacts=False, unplaced=unplaced)
    assert [m for m, _ in unplaced] == ["m22"] and "could place only" in unplaced[0][1]
    assert len(got) == 23 and "m23" in got and "m22" not in got
    with pytest.raises(SceneError, match="dem.packings"):
        CASE.members(DIR, 24, contacts=False)
