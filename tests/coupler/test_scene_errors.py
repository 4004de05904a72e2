"""Bad scenes raise one SceneError naming the field path and the allowed range."""
import re

import pytest

from coupler.errors import SceneError
from coupler.scene import loads_scene
from tests.conftest import BASE_SCENE


def bad(text_from, text_to, count=1):
    assert text_from in BASE_SCENE
    return BASE_SCENE.replace(text_from, text_to, count)


CASES = [
    (bad("young = 70e9", "young = -7e10"), "materials.aluminium.young", "must be > 0, got -7e+10"),
    (bad("density = 2700.0", "density = 0.0"), "materials.aluminium.density", "> 0"),
    (bad("poisson = 0.33", "poisson = 0.5"), "materials.aluminium.poisson", "in (-1, 0.5)"),
    (bad("poisson = 0.33", "poisson = -1.0"), "materials.aluminium.poisson", "in (-1, 0.5)"),
    (bad("restitution = 0.8", "restitution = 0.0"), "contacts[0].restitution", "in (0, 1]"),
    (bad("restitution = 0.8", "restitution = 1.2"), "contacts[0].restitution", "in (0, 1]"),
    (bad("friction = 0.3", "friction = -0.1"), "contacts[0].friction", ">= 0"),
    (bad("radius = 2.5e-3", "radius = -1e-3"), "dem.spheres[0].radius", "> 0"),
    (bad("radius = 2.5e-3", "radius = 0"), "dem.spheres[0].radius", "> 0"),
    (bad("dt = 1e-8", "dt = 1e-4"), "time.dt", "stable limit"),
    (bad("t_end = 1e-5", "t_end = -1.0"), "time.t_end", "> 0"),
    (bad("position = [0.0, 0.0026, 0.0]", "position = [0.0, 0.0020, 0.0]"), "dem.max_initial_overlap",
     "overlaps wall 'floor'"),
    (bad("[dem]", "[dem]\nmax_initial_overlap = 0.9"), "dem.max_initial_overlap", "in [0, 0.5]"),
    (bad("[time]", "gravity_schedule = [[0.0, 0.0, -1.0, 0.0], [0.1, 0.0, -2.0, 0.0]]\n[time]"), "gravity_schedule",
     "either gravity or gravity_schedule"),
    (bad("gravity = [0.0, -9.81, 0.0]", "gravity_schedule = [[0.1, 0.0, -1.0, 0.0], [0.1, 0.0, -2.0, 0.0]]"),
     "gravity_schedule", "strictly increasing"),
    (bad("gravity = [0.0, -9.81, 0.0]", "gravity_schedule = [[0.0, 0.0, -1.0], [0.1, 0.0, -2.0]]"),
     "gravity_schedule", "[t, gx, gy, gz] rows"),
    (bad("friction = 0.3", "friction = 0.3\nfricton = 0.2"), "contacts[0].fricton", "unknown key"),
    (bad('material = "aluminium"\nradius', 'material = "steel"\nradius'), "dem.spheres[0].material",
     "unknown material 'steel'"),
    (bad("dimension = 3", "dimension = 4"), "dimension", "must be 2 or 3"),
    (bad("normal = [0.0, 1.0, 0.0]", "normal = [0.0, 0.0, 0.0]"), "dem.planes[0].normal", "non-zero"),
    (bad("[[contacts]]\nmaterials = [\"aluminium\", \"aluminium\"]\nrestitution = 0.8\nfriction = 0.3\n", ""),
     "contacts", "no contact law"),
    (bad("friction = 0.3", 'friction = 0.3\ndamping = "lammps"'), "contacts[0].damping", "must be one of"),
    (bad("output_interval = 1e-6", "output_interval = 1.0"), "time.output_interval", "<= time.t_end"),
    (bad("velocity = [0.0, -1.0, 0.0]", "velocity = [0.0, -1.0]"), "dem.spheres[0].velocity", "list of 3 numbers"),
    (bad("young = 70e9", 'young = "hard"'), "materials.aluminium.young", "must be a number"),
]


@pytest.mark.parametrize("text,path,msg", CASES, ids=[c[1] + ":" + c[2][:20] for c in CASES])
def test_bad_scene_names_field_and_range(text, path, msg):
    with pytest.raises(SceneError) as ei:
        loads_scene(text)
    assert ei.value.path == path
    assert msg in str(ei.value), str(ei.value)
    assert str(ei.value).startswith(path + ":")


def test_2d_scene_rejects_out_of_plane_values():
    text = bad("dimension = 3", "dimension = 2")
    text = text.replace("velocity = [0.0, -1.0, 0.0]", "velocity = [0.0, -1.0, 0.5]")
    with pytest.raises(SceneError, match=re.escape("dem.spheres[0].velocity[2]: must be 0 in a 2D scene")):
        loads_scene(text)


def test_overlapping_spheres_rejected():
    text = BASE_SCENE + """
[[dem.spheres]]
name = "b"
material = "aluminium"
radius = 2.5e-3
position = [0.004, 0.0026, 0.0]
"""
    with pytest.raises(SceneError, match="spheres 'a' and 'b' overlap by 0.4 of the radius"):
        loads_scene(text)


def test_packing_that_cannot_fit_is_an_error():
    text = BASE_SCENE + """
[[dem.packings]]
material = "aluminium"
radius = 2.5e-3
box_min = [0.1, 0.1, 0.1]
box_max = [0.11, 0.11, 0.11]
count = 500
"""
    with pytest.raises(SceneError, match=r"dem.packings\[0\].count: could place only"):
        loads_scene(text)


def test_valid_scene_loads_and_defaults_are_explicit():
    s = loads_scene(BASE_SCENE)
    law = s.contact_law("aluminium", "aluminium")
    assert law.damping == "restitution" and law.tangential == "history"
    assert s.dem.n_spheres == 1 and s.dem.planes[0].name == "floor"


def test_cli_reports_bad_scene_without_traceback(tmp_path, capsys):
    from coupler.cli import main
    p = tmp_path / "bad.toml"
    p.write_text(bad("young = 70e9", "young = -7e10"))
    assert main(["run", str(p), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "materials.aluminium.young: must be > 0, got -7e+10" in err
    assert "Traceback" not in err


def test_kratos_backend_missing_is_clear(tmp_path, capsys, monkeypatch):
    """Without Kratos installed, --backend kratos is one clear line (exit 4) naming what to install."""
    import importlib.util
    from coupler.cli import main
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a, **k: None if name == "KratosMultiphysics" else real(name, *a, **k))
    p = tmp_path / "s.toml"
    p.write_text(BASE_SCENE)
    assert main(["run", str(p), "--backend", "kratos", "--out", str(tmp_path / "o")]) == 4
    err = capsys.readouterr().err
    assert "Kratos is not installed" in err and "Traceback" not in err
