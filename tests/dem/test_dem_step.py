"""The one compiled step: serial and parallel flavours, the fused loop and the step-by-step loop give bitwise the
same result, also with mesh walls (moving) and planes in the loop."""
import numba
import numpy as np

from coupler.dem import solver as sv
from coupler.scene import loads_scene
from tests.conftest import ALUMINIUM, scene_toml

SCENE = scene_toml("""[dem]
[[dem.lattices]]
name = "lat"
material = "al"
radius = 1e-3
origin = [-4e-3, 1.05e-3, -4e-3]
counts = [5, 3, 5]
velocity = [0.0, -0.5, 0.0]
[[dem.planes]]
name = "wall"
material = "al"
point = [-5.1e-3, 0.0, 0.0]
normal = [1.0, 0.0, 0.0]
velocity = [0.5, 0.0, 0.0]
[[dem.meshes]]
name = "floor"
material = "al"
velocity = [0.2, 0.3, 0.0]
vertices = [[-0.01, 0.0, -0.01], [0.01, 0.0, -0.01], [0.01, 0.0, 0.01], [-0.01, 0.0, 0.01], [0.0, 0.0, 0.0]]
triangles = [[0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]]
""", name="step", t_end="1e-3", dt="2e-7", output_interval="1e-4",
                   materials={"al": ALUMINIUM}, output={"energy": "true"})


def test_flavours_and_step_by_step_are_bitwise_equal(monkeypatch):
    monkeypatch.setattr(sv, "PARALLEL_MIN_SPHERES", 1)
    out = []
    for threads, one_by_one in ((1, False), (2, False), (1, True)):
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        s = sv.DEMSolver(loads_scene(SCENE))
        (s._advance_general if one_by_one else s.advance)(1500)
        out.append((s.s.x.copy(), s.s.v.copy(), s.s.w.copy(), s.mesh_node_forces("floor", average=False),
                    s.mesh_work("floor"), s.work_input(), s.energies()))
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert s.mesh_work("floor") < 0.0 and s.c.rebuilds >= 2      # the moving mesh hit spheres, lists rebuilt
    assert s._wall_work[0] > 0.0                                  # and so did the moving plane
    for other in out[1:]:
        for a, b in zip(out[0], other):
            assert np.array_equal(np.asarray(a), np.asarray(b))
