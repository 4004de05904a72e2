"""Scene features an adapter does not write are refused with the field named, never run differently."""
from pathlib import Path

import pytest

from coupler.errors import UnsupportedFeature
from coupler.scene import load_scene

SLIDE = Path(__file__).resolve().parents[2] / "validation" / "cases" / "dem_block_slide" / "block.toml"


def _checker(code):
    if code == "liggghts":
        from adapters.liggghts.writer import check_supported
    else:
        from adapters.yade.params import check_supported
    return check_supported


@pytest.mark.parametrize("code", ["liggghts", "yade"])
def test_prescribed_cluster_motion_is_written(code):
    """Held / driven clusters are written (tests/adapters/test_prescribed_motion_live.py runs them); an `until`
    shorter than one step is refused with the field named."""
    check = _checker(code)
    check(load_scene(SLIDE, overrides={"dem.clusters[0].motion": {"kind": "fixed"}}))
    check(load_scene(SLIDE, overrides={"dem.clusters[0].motion": {"kind": "velocity", "velocity": [0.1, 0.0, 0.0],
                                                                  "angular_velocity": [0.0, 0.0, 2.0],
                                                                  "until": 0.05}}))
    with pytest.raises(UnsupportedFeature, match=r"dem\.clusters\[0\]\.motion\.until"):
        check(load_scene(SLIDE, overrides={"dem.clusters[0].motion": {"kind": "fixed", "until": 1e-7}}))




def test_kratos_coupled_step_is_given_and_one_dem_step():
    """Kratos CoSimulation runs its MPM and DEM at one step (one DEM step per coupling step): without coupling.dt
    the adapter stopped on a TypeError (a traceback), and a scene whose DEM takes several steps per coupling step
    ran with one. Both are refused before Kratos is looked for."""
    from adapters.kratos.backend import run
    from coupler.errors import SceneError
    cant = Path(__file__).resolve().parents[2] / "validation" / "cases" / "coupled_kratos_cantilever" / "scene.toml"
    sc = load_scene(cant)
    from adapters.kratos.params import coupled_step
    assert coupled_step(sc, None) == 2e-4 and coupled_step(sc, 2e-3) == 2e-3     # the case's steps: one DEM step
    with pytest.raises(SceneError) as e:
        run(load_scene(cant, overrides={"coupling.dt": None}), Path("/nonexistent"))
    assert e.value.path == "coupling.dt" and "must be given for the Kratos backend" in str(e.value)
    with pytest.raises(UnsupportedFeature) as e:
        run(load_scene(cant, overrides={"coupling.dem_substeps": 4}), Path("/nonexistent"))
    assert e.value.path == "coupling.dem_substeps" and "takes 4" in str(e.value)
    from coupler.dem.timestep import chosen_dt
    with pytest.raises(UnsupportedFeature, match="takes 2 "):                    # auto: 2 x the DEM's own step
        coupled_step(sc, 1.999 * chosen_dt(sc))


def test_particles_interval_is_mpm_only_and_reaches_kratos(monkeypatch):
    """output.particles_interval thins the MPM snapshots: a DEM-only scene is refused (it was parsed and ignored),
    and the Kratos MPM backend takes its stride from it when the caller gives none (it wrote every output time)."""
    from coupler.errors import SceneError
    from coupler.scene import loads_scene
    from tests.conftest import BASE_SCENE
    with pytest.raises(SceneError) as e:
        loads_scene(BASE_SCENE + "[output]\nparticles_interval = 2e-6\n")
    assert e.value.path == "output.particles_interval"
    import adapters.kratos.backend as kb
    ok, why = kb.available()
    if not ok:
        pytest.skip(why)
    seen = []

    class Stop(Exception):
        pass

    def capture(scene, out, initial_velocity, snapshot_every, *a):
        seen.append(snapshot_every)
        raise Stop

    monkeypatch.setattr(kb, "write_inputs", capture)
    elastic_bar = Path(__file__).resolve().parents[2] / "validation" / "cases" / "mpm_elastic_bar" / "scene.toml"
    sc = load_scene(elastic_bar)
    text = elastic_bar.read_text() + f"\n[output]\nparticles_interval = {4 * sc.time.output_interval!r}\n"
    for scene, want in ((sc, 1), (loads_scene(text), 4)):
        with pytest.raises(Stop):
            kb.run(scene, Path("/tmp/unused_kratos_out"))
        assert seen[-1] == want
    with pytest.raises(Stop):
        kb.run(sc, Path("/tmp/unused_kratos_out"), snapshot_every=7)
    assert seen[-1] == 7
