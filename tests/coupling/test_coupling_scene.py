"""[coupling] scene errors: one SceneError naming the field for each bad input."""
from pathlib import Path

import numpy as np
import pytest

from coupler.errors import SceneError
from coupler.scene import loads_scene

ROOT = Path(__file__).resolve().parents[2]
BASE = (ROOT / "validation/cases/coupled_free_collision/scene.toml").read_text()


def scene(replace=(), append=""):
    text = BASE
    for a, b in replace:
        assert a in text, a
        text = text.replace(a, b)
    return loads_scene(text + append, name="t")


def test_base_scene_builds_the_interface_wall():
    sc = scene()
    cs = sc.coupling
    mesh = [m for m in sc.dem.meshes if m.name == "interface"][0]
    assert len(cs.geometry.index) == len(mesh.vertices) == 96      # 32 + 16 + 32 + 16 points (spacing h/2), closed
    assert len(mesh.faces) == len(mesh.vertices)                   # closed loop
    assert mesh.material == "block_wall"


@pytest.mark.parametrize("replace, path", [
    (('mapper = "nearest"', 'mapper = "cubic"'), "coupling.mapper"),
    (("thickness = 0.1", "thickness = 0.0"), "coupling.thickness"),
    (("thickness = 0.1", "thickness = -1.0"), "coupling.thickness"),
    (('body = "block"\nmaterial', 'body = "sand"\nmaterial'), "coupling.body"),
    (("boundary_particles = true", "boundary_particles = false"), "mpm.boundary_particles"),
    (("dem_substeps = 1", "dem_substeps = 0"), "coupling.dem_substeps"),
    (("dem_substeps = 1", 'dem_substeps = "many"'), "coupling.dem_substeps"),
    (('material = "block_wall"\nmapper', 'material = "rubber"\nmapper'), "coupling.material"),
    (('mapper = "nearest"', 'mapper = "nearest"\nscheme = "jacobi"'), "coupling.scheme"),
    (('mapper = "nearest"', 'mapper = "nearest"\npredictor = "quadratic"'), "coupling.predictor"),
    (('mapper = "nearest"', 'mapper = "nearest"\nsides = []'), "coupling.sides"),
    (('mapper = "nearest"', 'mapper = "nearest"\nsides = ["front"]'), "coupling.sides[0]"),
    (('mapper = "nearest"', 'mapper = "nearest"\nsegments = [4]'), "coupling.segments[0]"),
    (('mapper = "nearest"', 'mapper = "nearest"\nsegments = []'), "coupling.segments"),
    (('mapper = "nearest"', 'mapper = "nearest"\ncolour = 1'), "coupling.colour"),
    (("output_interval = 0.003", "output_interval = 0.003\ndt = 1e-5"), "time.dt"),
])
def test_bad_coupling_field(replace, path):
    with pytest.raises(SceneError) as e:
        scene([replace])
    assert e.value.path == path, str(e.value)
    assert "\n" not in str(e.value)


def test_no_interface_particles_message():
    with pytest.raises(SceneError, match="selects no interface particles"):
        scene([('mapper = "nearest"', 'mapper = "nearest"\nsides = []')])


def test_sides_on_a_polygon_body_is_refused():
    with pytest.raises(SceneError) as e:
        scene([('rectangle = { min = [0.0, 0.0], max = [0.4, 0.2] }',
                'polygon = [[0.0, 0.0], [0.4, 0.0], [0.2, 0.2]]'),
               ('mapper = "nearest"', 'mapper = "nearest"\nsides = ["top"]')])
    assert e.value.path == "coupling.sides"


def test_reserved_wall_name_and_missing_contact_law():
    extra = '\n[[dem.meshes]]\nname = "interface"\nmaterial = "ball"\nvertices = [[1.0, 1.0, 0.0], [1.0, 2.0, 0.0]]\nsegments = [[0, 1]]\n'
    text = BASE.replace("[mpm]\n", extra + "\n[mpm]\n", 1)
    with pytest.raises(SceneError) as e:
        loads_scene(text, name="t")
    assert e.value.path == "dem.meshes"
    with pytest.raises(SceneError) as e:
        scene([('materials = ["ball", "block_wall"]\nrestitution = 0.8\nfriction = 0.3',
                'materials = ["ball", "block"]\nrestitution = 0.8\nfriction = 0.3')])
    assert e.value.path == "contacts"


def test_sides_select_the_outline_edges_in_order():
    sc = scene([('mapper = "nearest"', 'mapper = "nearest"\nsides = ["left", "bottom"]')])
    g = sc.coupling.geometry
    # left (edge 3, top to bottom) then bottom (edge 0, left to right): one open chain through the corner
    assert len(g.chains) == 1 and not g.chains[0][2]
    assert np.all(np.diff(g.points[:16, 1]) < 0) and np.all(g.points[:16, 0] == 0.0)
    assert np.all(np.diff(g.points[16:, 0]) > 0) and np.all(g.points[16:, 1] == 0.0)
    assert len(g.wall_segments) == len(g.points) - 1


def test_motion_errors():
    base = BASE.replace('[[dem.spheres]]\nname = "ball"', '[dem.templates.one]\nspheres = [[0.0, 0.0, 0.0, 0.05]]\n'
                        '[[dem.clusters]]\nname = "ball"\ntemplate = "one"\nmaterial = "ball"\n'
                        'position = [-0.055, 0.1, 0.0]\n[[dem.spheres]]\nname = "ball2"')
    base = base.replace('position = [-0.055, 0.1, 0.0]\nvelocity', 'position = [-0.3, 0.1, 0.0]\nvelocity')
    ok = base + '\n[[coupling.motion]]\nbody = "ball"\nkind = "fixed"\nuntil = 0.1\n'
    assert loads_scene(ok, name="t").coupling.motions[0].until == 0.1
    with pytest.raises(SceneError) as e:
        loads_scene(base + '\n[[coupling.motion]]\nbody = "nope"\nkind = "fixed"\n', name="t")
    assert e.value.path == "coupling.motion[0].body"
    with pytest.raises(SceneError) as e:
        loads_scene(ok + '\n[[coupling.motion]]\nbody = "ball"\nkind = "velocity"\nvelocity = [1.0, 0.0, 0.0]\n'
                         'start = 0.05\n', name="t")
    assert e.value.path == "coupling.motion[1].start"
    both = ok.replace('position = [-0.055, 0.1, 0.0]\n', 'position = [-0.055, 0.1, 0.0]\nmotion = { kind = "fixed" }\n', 1)
    assert both != ok
    with pytest.raises(SceneError) as e:
        loads_scene(both, name="t")
    assert e.value.path == "coupling.motion[0].body"


def test_coupling_step_bound_is_the_explicit_cfl_limit_only():
    """coupling.dt (= the MPM step) must stay within the explicit MPM's CFL limit h / c; the implicit Newmark step
    has no such bound (it was held to 10 h / c, named as the CFL limit, before the thirty-fifth session)."""
    from coupler.coupling.partitions import MPMPartition
    path = ROOT / "validation/cases/coupled_implicit_resting_load/scene.toml"
    sc = load_scene_path(path, {"mpm.scheme": "explicit", "mpm.implicit": None})
    limit = MPMPartition(sc, None).sol.dt / sc.mpm.cfl                    # h / c
    assert MPMPartition(sc, 0.99 * limit).sol.dt == 0.99 * limit
    with pytest.raises(SceneError) as e:
        MPMPartition(sc, 1.01 * limit)
    assert e.value.path == "coupling.dt" and "CFL limit" in str(e.value)
    imp = load_scene_path(path, {})
    assert MPMPartition(imp, 13.0 * limit).sol.dt == 13.0 * limit        # refused before (10 h / c)


def load_scene_path(path, overrides):
    """The scene file with overrides; a None value deletes the table or key."""
    import tomllib
    from coupler.scene import parse_scene
    raw = tomllib.loads(path.read_text())
    for key, value in overrides.items():
        *head, last = key.split(".")
        node = raw
        for k in head:
            node = node[k]
        if value is None:
            node.pop(last, None)
        else:
            node[last] = value
    return parse_scene(raw, base_dir=path.parent)
