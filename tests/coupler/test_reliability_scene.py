"""Issue 17, scene-level reliability: contact laws only for pairs that can touch, output_interval against dt, bodies
outside [domain] at t = 0. Each is a one-line SceneError (exit 2) or a valid scene, never a run that blows up."""
import pytest

from coupler.cli import main
from coupler.errors import SceneError
from coupler.scene import loads_scene
from tests.conftest import ALUMINIUM, BASE_SCENE, FLOOR, SPHERE_A, edit, scene_toml

STEEL = {"density": "7850.0", "young": "210e9", "poisson": "0.3"}
SPHERE_S = SPHERE_A.replace('name = "a"', 'name = "s"').replace('"aluminium"', '"steel"').replace(
    "position = [0.0, 0.0026, 0.0]", "position = [0.01, 0.0026, 0.0]")


def test_lone_sphere_and_wall_wall_need_no_law():
    """One aluminium sphere on a steel floor, one more steel wall: only (aluminium, steel) can touch."""
    floor = FLOOR.replace('"aluminium"', '"steel"')
    side = floor.replace('name = "floor"', 'name = "side"').replace("normal = [0.0, 1.0, 0.0]", "normal = [1.0, 0.0, 0.0]").replace(
        "point = [0.0, 0.0, 0.0]", "point = [-0.01, 0.0, 0.0]")
    text = scene_toml("[dem]\n" + SPHERE_A + floor + side, materials={"aluminium": ALUMINIUM, "steel": STEEL},
                      contacts=[("aluminium", "steel", "0.8", "0.3")])
    scene = loads_scene(text)                       # neither (aluminium, aluminium) nor (steel, steel) is asked
    assert set(scene.contacts) == {("aluminium", "steel")}
    from coupler.dem.solver import DEMSolver
    s = DEMSolver(scene)
    s.advance(15000)                                 # the sphere hits the steel floor with the only law there is
    assert s.s.v[0, 1] > 0.0


@pytest.mark.parametrize("body,missing", [
    # two aluminium spheres can touch each other: (aluminium, aluminium) is needed
    ("[dem]\n" + SPHERE_A + SPHERE_A.replace('name = "a"', 'name = "b"').replace(
        "position = [0.0, 0.0026, 0.0]", "position = [0.01, 0.0026, 0.0]") + FLOOR.replace('"aluminium"', '"steel"'),
     ("aluminium", "aluminium")),
    # a steel sphere and an aluminium sphere: (aluminium, steel) is needed
    ("[dem]\n" + SPHERE_A + SPHERE_S, ("aluminium", "steel")),
    # a sphere on a wall of another material
    ("[dem]\n" + SPHERE_A + FLOOR.replace('"aluminium"', '"steel"'), ("aluminium", "steel")),
])
def test_missing_law_of_a_pair_that_can_touch_is_an_error(body, missing):
    laws = [("steel", "steel", "0.8", "0.3")] if missing == ("aluminium", "aluminium") else \
        [("aluminium", "aluminium", "0.8", "0.3")]
    if missing == ("aluminium", "aluminium"):
        laws.append(("aluminium", "steel", "0.8", "0.3"))
    text = scene_toml(body, materials={"aluminium": ALUMINIUM, "steel": STEEL}, contacts=laws)
    with pytest.raises(SceneError) as ei:
        loads_scene(text)
    assert ei.value.path == "contacts"
    assert f"no contact law for materials ({missing[0]!r}, {missing[1]!r})" in str(ei.value)


def test_two_clusters_of_one_material_need_their_law_but_one_alone_does_not():
    tmpl = """[dem.templates.pair]
spheres = [[0.0, 0.0, 0.0, 1e-3], [2e-3, 0.0, 0.0, 1e-3]]
"""
    c1 = '[[dem.clusters]]\nname = "c1"\ntemplate = "pair"\nmaterial = "aluminium"\nposition = [0.0, 0.01, 0.0]\n'
    c2 = c1.replace('"c1"', '"c2"').replace("[0.0, 0.01, 0.0]", "[0.0, 0.02, 0.0]")
    floor = FLOOR.replace('"aluminium"', '"steel"')
    mats = {"aluminium": ALUMINIUM, "steel": STEEL}
    one = scene_toml("[dem]\n" + tmpl + c1 + floor, materials=mats, contacts=[("aluminium", "steel", "0.8", "0.3")])
    assert set(loads_scene(one).contacts) == {("aluminium", "steel")}
    two = scene_toml("[dem]\n" + tmpl + c1 + c2 + floor, materials=mats,
                     contacts=[("aluminium", "steel", "0.8", "0.3")])
    with pytest.raises(SceneError, match=r"no contact law for materials \('aluminium', 'aluminium'\)"):
        loads_scene(two)


def test_output_interval_below_the_time_step_is_an_error():
    with pytest.raises(SceneError) as ei:
        loads_scene(edit(BASE_SCENE, "output_interval = 1e-6", "output_interval = 5e-9"))   # dt = 1e-8
    assert ei.value.path == "time.output_interval"
    assert "must be >= the time step" in str(ei.value) and "1e-08" in str(ei.value)


def test_output_interval_below_the_automatic_time_step_is_an_error():
    text = edit(edit(BASE_SCENE, "dt = 1e-8\n", ""), "output_interval = 1e-6", "output_interval = 1e-12")
    with pytest.raises(SceneError, match=r"time.output_interval: must be >= the time step"):
        loads_scene(text)


def test_output_interval_below_the_mpm_time_step_is_an_error():
    from tests.mpm.test_mpm_core import _DEFAULTS, BASE
    from coupler.mpm.solver import run_mpm
    scene = loads_scene(edit(BASE.format(**_DEFAULTS), "output_interval = 0.01", "output_interval = 1e-9"))
    with pytest.raises(SceneError, match=r"time.output_interval: must be >= the MPM time step"):
        run_mpm(scene, None, progress=False)


DOMAIN = "[domain]\nmin = [-0.01, -0.01, -0.01]\nmax = [0.01, 0.01, 0.01]\n[dem]"


def test_domain_without_dem_is_an_error():
    """[domain] bounds the DEM bodies; an MPM-only scene parsed it and never used it (before the thirty-fifth
    session)."""
    from tests.mpm.test_mpm_core import _DEFAULTS, BASE
    text = BASE.format(**_DEFAULTS) + "[domain]\nmin = [-1.0, -1.0, -1.0]\nmax = [1.0, 1.0, 1.0]\n"
    with pytest.raises(SceneError) as ei:
        loads_scene(text)
    assert ei.value.path == "domain" and "bounded by mpm.grid" in str(ei.value)


@pytest.mark.parametrize("old,new,body", [
    ("position = [0.0, 0.0026, 0.0]", "position = [0.0, 0.02, 0.0]", "a"),
    ("position = [0.0, 0.0026, 0.0]", "position = [0.0, 0.0026, -0.05]", "a"),
])
def test_body_outside_the_domain_at_t0_is_a_scene_error(old, new, body):
    text = edit(edit(BASE_SCENE, "[dem]", DOMAIN), old, new)
    with pytest.raises(SceneError) as ei:
        loads_scene(text)
    assert ei.value.path == "domain"
    msg = str(ei.value)
    assert f"body {body!r}" in msg and "outside the domain" in msg and "[-0.01, -0.01, -0.01]" in msg, msg


def test_cluster_outside_the_domain_at_t0_is_a_scene_error():
    tmpl = '[dem.templates.pair]\nspheres = [[0.0, 0.0, 0.0, 1e-3], [2e-3, 0.0, 0.0, 1e-3]]\n'
    cl = '[[dem.clusters]]\nname = "blk"\ntemplate = "pair"\nmaterial = "aluminium"\nposition = [0.0095, 0.005, 0.0]\n'
    text = edit(BASE_SCENE, "[dem]", DOMAIN) + tmpl + cl      # the COM is inside, the second member is not
    with pytest.raises(SceneError, match=r"domain: body 'blk' .*outside the domain"):
        loads_scene(text)


def test_body_outside_the_domain_exits_2_and_writes_nothing(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(edit(edit(BASE_SCENE, "[dem]", DOMAIN), "position = [0.0, 0.0026, 0.0]",
                          "position = [0.0, 0.02, 0.0]"))
    out = tmp_path / "out"
    assert main(["run", str(scene), "--out", str(out)]) == 2
    assert not out.exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: domain: body 'a'")
