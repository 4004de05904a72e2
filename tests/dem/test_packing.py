"""`[[dem.packings]]` (coupler/dem/packing.py): the cell-grid RSA places exactly the spheres of the plain definition
(each candidate of the seeded stream accepted when no placed sphere is closer than the sum of the radii), and large
scenes load in linear time."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from coupler.dem.packing import BATCH, random_packing
from coupler.errors import SceneError
from coupler.scene import loads_scene
from tests.conftest import scene_toml


def plain_rsa(lo, hi, count, rmin, rmax, seed, dim):
    """The definition, O(N^2): the same generator stream, every placed sphere tested."""
    rng = np.random.default_rng(seed)
    r = np.sort(rng.uniform(rmin, rmax, count) if rmax > rmin else np.full(count, rmin))[::-1]
    a, b = np.array(lo, float) + rmax, np.array(hi, float) - rmax
    if dim == 2:
        a[2] = b[2] = lo[2]
    if np.any(b[:dim] < a[:dim]):
        return "the box is smaller than one sphere"
    x, n, tries = np.zeros((count, 3)), 0, 0
    while n < count and tries < 200 * count + 10000:
        cand = rng.uniform(a, b, (BATCH, 3))
        if dim == 2:
            cand[:, 2] = lo[2]
        tries += BATCH
        for c in cand:
            if n < count and np.all(np.linalg.norm(x[:n] - c, axis=1) >= r[n] + r[:n]):
                x[n] = c
                n += 1
    return (r, x) if n == count else n


@settings(max_examples=40, deadline=None)
@given(dim=st.sampled_from([2, 3]), seed=st.integers(0, 10_000), size=st.floats(0.03, 0.12),
       rmin=st.floats(2e-3, 8e-3), spread=st.sampled_from([1.0, 1.3, 3.0]), fill=st.floats(0.05, 0.6))
def test_grid_packing_is_the_plain_definition(dim, seed, size, rmin, spread, fill):
    rmax = rmin * spread
    lo = np.array([0.1, -0.2, 0.0])
    hi = lo + np.array([size, 0.8 * size, 0.0 if dim == 2 else 1.1 * size])
    area = np.prod((hi - lo)[:dim])
    count = min(300, max(1, int(fill * area / (np.pi * rmax ** 2 if dim == 2 else 4 / 3 * np.pi * rmax ** 3))))
    want = plain_rsa(lo, hi, count, rmin, rmax, seed, dim)
    if isinstance(want, str):
        with pytest.raises(SceneError, match=want):
            random_packing("p", lo, hi, count, rmin, rmax, seed, dim)
        return
    if isinstance(want, int):                 # the box is too full for this stream: both refuse
        with pytest.raises(SceneError, match=f"could place only {want} of {count}"):
            random_packing("p", lo, hi, count, rmin, rmax, seed, dim)
        return
    r, x = random_packing("p", lo, hi, count, rmin, rmax, seed, dim)
    assert np.array_equal(r, want[0]) and np.array_equal(x, want[1])
    assert np.all(x[:, :dim] - r[:, None] >= lo[:dim] - 1e-15) and np.all(x[:, :dim] + r[:, None] <= hi[:dim] + 1e-15)


def test_fifty_thousand_spheres_load():
    """A 50,000-sphere packing (it took 22 s to load before the thirty-sixth session: 4.3 s the KD-tree rebuilt per
    batch, 17 s a quadratic duplicate-name check; the speed is measured in the session log, not asserted here)."""
    glass = {"density": 2500.0, "young": 1e8, "poisson": 0.25}
    text = scene_toml("""[dem]
[[dem.packings]]
name = "beads"
material = "glass"
radius_range = [1.5e-3, 2e-3]
box_min = [0.0, 0.0, 0.0]
box_max = [0.2, 0.2, 0.2]
count = 50000
""", materials={"glass": glass}, dt=None, t_end="1e-4", output_interval="1e-4")
    s = loads_scene(text)
    d = s.dem
    assert d.n_spheres == 50_000 and len(set(d.names)) == 50_000 and d.names[7] == "beads:7"
    from scipy.spatial import cKDTree
    pairs = cKDTree(d.position).query_pairs(2 * d.radius.max(), output_type="ndarray")
    gap = np.linalg.norm(d.position[pairs[:, 0]] - d.position[pairs[:, 1]], axis=1) - d.radius[pairs].sum(1)
    assert gap.min() >= 0.0


def test_duplicate_names_are_refused():
    base = scene_toml("[dem]\n", materials={"m": {"density": 2500.0, "young": 1e8, "poisson": 0.25}})
    sph = '[[dem.spheres]]\nname = "%s"\nmaterial = "m"\nradius = 1e-3\nposition = [%g, 0.0, 0.0]\n'
    text = base + sph % ("a", 0.0) + sph % ("b", 0.01) + sph % ("b", 0.02) + sph % ("a", 0.03)
    with pytest.raises(SceneError, match=r"b: duplicate body or group name"):
        loads_scene(text)
    wall = '[[dem.planes]]\nname = "w"\nmaterial = "m"\npoint = [0.0, %g, 0.0]\nnormal = [0.0, 1.0, 0.0]\n'
    pack = ('[[dem.packings]]\nname = "p"\nmaterial = "m"\nradius = 1e-3\nbox_min = [0.0, 0.0, 0.0]\n'
            'box_max = [0.02, 0.02, 0.02]\ncount = 5\n')
    with pytest.raises(SceneError, match=r"p:3\)?: duplicate body"):   # a packing member's name
        loads_scene(base + pack + sph % ("p:3", 0.05))
    with pytest.raises(SceneError, match=r"dem \(w\): duplicate wall name"):
        loads_scene(base + sph % ("a", 0.0) + wall % -0.01 + wall % -0.02)
