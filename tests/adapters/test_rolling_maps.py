"""Rolling-resistance and sub-model maps to LIGGGHTS and YADE (adapters/*/params.py; no binary needed)."""
import json

import pytest

from adapters.liggghts.params import liggghts_model
from adapters.liggghts.writer import write_inputs as write_liggghts
from adapters.yade.params import WALL_RSTAR_OVER_RMEAN, yade_rolling
from adapters.yade.writer import write_inputs as write_yade
from coupler.errors import UnsupportedFeature
from coupler.scene import loads_scene
from tests.conftest import BASE_SCENE

CDT = 'rolling = { model = "cdt", coefficient = 0.1 }'
EPSD2 = 'rolling = { model = "epsd2", coefficient = 0.1 }'
EPSD2_K = 'rolling = { model = "epsd2", coefficient = 0.1, stiffness = 1e-4 }'


def scene(line="", extra=""):
    return loads_scene(BASE_SCENE.replace("friction = 0.3", f"friction = 0.3\n{line}") + extra)


SECOND_SPHERE = """[[dem.spheres]]
name = "b"
material = "aluminium"
radius = 2.5e-3
position = [0.01, 0.0026, 0.0]
"""


def test_liggghts_no_rolling_writes_the_unchanged_model():
    assert liggghts_model(scene()) == "model hertz tangential history"


def test_liggghts_no_history():
    assert liggghts_model(scene('tangential = "no_history"')) == "model hertz tangential no_history"


@pytest.mark.parametrize("line, word", [(CDT, "cdt"), (EPSD2, "epsd2")])
def test_liggghts_rolling_in_pair_style_and_walls(tmp_path, line, word):
    write_liggghts(scene(line), tmp_path)
    s = (tmp_path / "in.liggghts").read_text()
    assert f"pair_style gran model hertz tangential history rolling_friction {word} limitForce on" in s
    assert f"wall/gran model hertz tangential history rolling_friction {word} primitive type 1 yplane 0" in s
    assert "fix m5 all property/global coefficientRollingFriction peratomtypepair 1 0.1\n" in s
    assert s.index("coefficientRollingFriction") < s.index("run ")


def test_liggghts_without_rolling_has_no_rolling_property(tmp_path):
    write_liggghts(scene(), tmp_path)
    assert "rolling" not in (tmp_path / "in.liggghts").read_text().lower()


@pytest.mark.parametrize("line, field", [
    (EPSD2_K, "contacts[0].rolling.stiffness"),
    ('normal = { model = "hooke", stiffness = 1e5 }', "contacts[0].normal"),
])
def test_liggghts_inexpressible(line, field):
    with pytest.raises(UnsupportedFeature) as e:
        liggghts_model(scene(line))
    assert e.value.path == field and "liggghts" in str(e.value)


def test_liggghts_one_model_for_all_pairs():
    text = BASE_SCENE.replace("[dem]", """[materials.steel]
density = 7800.0
young = 200e9
poisson = 0.3
[[contacts]]
materials = ["aluminium", "steel"]
restitution = 0.8
friction = 0.3
rolling = { model = "cdt", coefficient = 0.1 }
[dem]""")
    with pytest.raises(UnsupportedFeature, match="one contact model for all type pairs"):
        liggghts_model(loads_scene(text))


def test_yade_no_rolling_is_none_and_script_unchanged(tmp_path):
    assert yade_rolling(scene()) is None
    write_yade(scene(), tmp_path)
    s = (tmp_path / "run_yade.py").read_text()
    assert "[Ip2_FrictMat_FrictMat_MindlinPhys(betan=beta, betas=beta)]" in s
    assert "[Law2_ScGeom_MindlinPhys_Mindlin()]" in s


def test_yade_epsd2_constant_stiffness_maps_to_krot_and_eta(tmp_path):
    r = yade_rolling(scene(EPSD2_K))
    assert r["krot"] == 1e-4
    # maxBendPl = eta Rmean = mu_r R*: for a hertzian wall refR1 = 1e8 R, R*/Rmean = 2e8/(1e8+1)^2
    R = 2.5e-3
    rstar, rmean = 1e8 * R * R / (1e8 * R + R), (1e8 * R + R) / 2
    assert r["eta"] * rmean == pytest.approx(0.1 * rstar, rel=1e-14)
    assert WALL_RSTAR_OVER_RMEAN == pytest.approx(rstar / rmean, rel=1e-14)
    write_yade(scene(EPSD2_K), tmp_path)
    s = (tmp_path / "run_yade.py").read_text()
    assert "Law2_ScGeom_MindlinPhys_Mindlin(includeMoment=True)" in s
    assert 'krot=P["rolling"]["krot"], ktwist=0.0, eta=P["rolling"]["eta"]' in s
    assert json.loads((tmp_path / "scene_yade.json").read_text())["rolling"]["eta"] == r["eta"]


def test_yade_sphere_pairs_of_one_radius_use_half():
    text = BASE_SCENE.replace("friction = 0.3", "friction = 0.3\n" + EPSD2_K)
    text = text[:text.index("[[dem.planes]]")] + SECOND_SPHERE
    assert yade_rolling(loads_scene(text))["eta"] == pytest.approx(0.05, rel=1e-15)


@pytest.mark.parametrize("line, extra, field, words", [
    (CDT, "", "contacts[0].rolling", "constant-directional-torque"),
    (EPSD2, "", "contacts[0].rolling.stiffness", "krot is a constant"),
    (EPSD2_K, SECOND_SPHERE, "contacts.rolling", "sphere-wall and sphere-sphere"),
    ('tangential = "no_history"', "", "contacts[0].tangential", "no_history"),
    ('normal = { model = "hooke", stiffness = 1e5 }', "", "contacts[0].normal", "hooke"),
])
def test_yade_inexpressible(line, extra, field, words):
    with pytest.raises(UnsupportedFeature) as e:
        yade_rolling(scene(line, extra))
    assert e.value.path == field and words in str(e.value) and "yade" in str(e.value)
