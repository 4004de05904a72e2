"""ParaView output (coupler/vtk.py): every written file is read back with meshio and its fields and times checked."""
from __future__ import annotations

import json

import meshio
import numpy as np
import pandas as pd
import pytest

from coupler.results import Result
from coupler.run import run_scene
from coupler.scene import loads_scene
from tests.conftest import ALUMINIUM, scene_toml
from coupler.vtk import quat_to_matrix, read_pvd

DEM = scene_toml("""[dem]
[[dem.spheres]]
name = "a"
material = "al"
radius = 2.5e-3
position = [0.0, 0.002505, 0.0]
velocity = [0.1, -1.0, 0.0]
angular_velocity = [0.0, 0.0, 3.0]
[[dem.spheres]]
name = "b"
material = "steel"
radius = 1.5e-3
position = [0.02, 0.01, 0.0]
[[dem.planes]]
name = "floor"
material = "steel"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
[[dem.meshes]]
name = "ramp"
material = "al"
velocity = [0.0, 0.0, 0.5]
vertices = [[0.05, 0.0, -0.01], [0.07, 0.0, -0.01], [0.07, 0.0, 0.01], [0.05, 0.0, 0.01]]
triangles = [[0, 1, 2], [0, 2, 3]]
[dem.templates.t]
spheres = [[0.0, 0.0, 0.0, 2e-3], [5e-3, 0.0, 0.0, 1.5e-3]]
[[dem.clusters]]
name = "c"
template = "t"
material = "al"
position = [-0.03, 0.02, 0.0]
angular_velocity = [0.0, 0.0, 20.0]
""", name="vtk_dem", t_end="4e-5", dt="1e-7", output_interval="1e-5",
                 materials={"al": ALUMINIUM, "steel": {"density": "7800.0", "young": "200e9", "poisson": "0.3"}},
                 contacts=[("al", "al", "0.8", "0.3"), ("al", "steel", "0.8", "0.3"), ("steel", "steel", "0.8", "0.3")],
                 output={"vtk": "true"})


def _series(path):
    entries = read_pvd(path)
    assert entries, path
    return [(t, meshio.read(p)) for t, p in entries]


@pytest.fixture(scope="module")
def dem_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("vtk_dem")
    scene = loads_scene(DEM)
    res = run_scene(scene, out, progress=False)
    return scene, res, out


def test_dem_series_fields_and_times(dem_run):
    scene, res, out = dem_run
    times = sorted(res.bodies["t"].unique())
    legend = json.loads((out / "vtk" / "legend.json").read_text())
    assert set(legend["series"]) == {"spheres", "clusters", "cluster_spheres", "walls"}

    sph = _series(out / "vtk" / "spheres.pvd")
    assert [t for t, _ in sph] == pytest.approx(times, rel=0, abs=0)
    for t, m in sph:
        rows = res.bodies[(res.bodies["t"] == t) & res.bodies["body"].isin(["a", "b"])]
        assert len(m.points) == 2
        np.testing.assert_array_equal(m.points, rows[["x", "y", "z"]].to_numpy())
        np.testing.assert_array_equal(m.point_data["velocity"], rows[["vx", "vy", "vz"]].to_numpy())
        np.testing.assert_array_equal(m.point_data["angular_velocity"], rows[["wx", "wy", "wz"]].to_numpy())
        np.testing.assert_array_equal(m.point_data["radius"], [2.5e-3, 1.5e-3])
        mats = [legend["materials"][k] for k in m.point_data["material_id"]]
        assert mats == ["al", "steel"]
        assert [legend["bodies"][k] for k in m.point_data["body_id"]] == ["a", "b"]

    clu = _series(out / "vtk" / "clusters.pvd")
    mem = _series(out / "vtk" / "cluster_spheres.pvd")
    assert [t for t, _ in clu] == [t for t, _ in mem] == times
    tpl = scene.dem.templates["t"]
    for (t, m), (_, mm) in zip(clu, mem):
        row = res.body("c")
        row = row[row["t"] == t].iloc[0]
        np.testing.assert_array_equal(m.points[0], row[["x", "y", "z"]].to_numpy(float))
        R = quat_to_matrix(row[["qw", "qx", "qy", "qz"]].to_numpy(float))[0]
        np.testing.assert_allclose(m.point_data["axis_x"][0], R[:, 0])
        np.testing.assert_allclose(mm.points, row[["x", "y", "z"]].to_numpy(float) + tpl.offsets @ R.T, atol=1e-15)
        np.testing.assert_array_equal(mm.point_data["radius"], tpl.radii)
    # at t = 0 the members sit where the scene put them: the body frame of the table is the template frame
    t0 = mem[0][1]
    np.testing.assert_allclose(t0.points, scene.dem.clusters[0].position + tpl.offsets, atol=1e-12)


def test_wall_series_geometry_and_forces(dem_run):
    scene, res, out = dem_run
    walls = _series(out / "vtk" / "walls.pvd")
    times = sorted(res.bodies["t"].unique())
    assert [t for t, _ in walls] == times
    mesh0 = scene.dem.meshes[0]
    touched = False
    for t, m in walls:
        blocks = {c.type: c.data for c in m.cells}
        assert set(blocks) == {"quad", "triangle"}
        tri = blocks["triangle"]
        np.testing.assert_allclose(m.points[tri.min():tri.max() + 1], mesh0.vertices + mesh0.velocity * t, atol=1e-15)
        quad_force = m.cell_data["force"][0][0]
        rows = res.contacts[(res.contacts["t"] == t) & (res.contacts["j"] == "wall:floor")]
        np.testing.assert_allclose(quad_force, -rows[["fx", "fy", "fz"]].sum().to_numpy(float), rtol=1e-12, atol=0)
        touched |= len(rows) > 0
        assert list(m.cell_data["wall_id"][1]) == [1, 1]
    assert touched, "the test scene should have sphere a pressing on the floor at some output time"


def test_table_only_backend_and_interface(tmp_path):
    """A backend's parsed tables (no solver) give the same files; MPM points and interface rows are written too."""
    scene = loads_scene(DEM)
    t = [0.0, 1e-3]
    bodies = pd.DataFrame([{"t": ti, "body": "a", "x": 0.0, "y": 0.01 - ti, "z": 0.0, "vx": 0.0, "vy": -1.0,
                            "vz": 0.0, "qw": 1.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "wx": 0.0, "wy": 0.0, "wz": 0.0}
                           for ti in t])
    parts = [(ti, pd.DataFrame({"t": [ti] * 3, "id": [0, 1, 2], "body": ["bar"] * 3, "x": [0.0, 1.0, 2.0],
                                "y": [0.0, 0.0, ti], "vx": [0.0] * 3, "vy": [1.0] * 3, "sxx": [1.0, 2.0, 3.0],
                                "syy": [4.0] * 3, "sxy": [0.5] * 3, "szz": [0.1] * 3, "eps_p": [0.0, 0.1, 0.2],
                                "ux": [0.0] * 3, "uy": [ti] * 3})) for ti in t]
    iface = pd.DataFrame({"t": [0.0, 0.0, 1e-3, 1e-3], "x": [0.0, 1.0, 0.0, 1.0], "y": [0.0] * 4,
                          "fx": [1.0, 2.0, 3.0, 4.0], "fy": [0.0] * 4, "body": ["bar"] * 4})
    res = Result(bodies=bodies, particles=parts,
                 summary={"scene": "x", "backend": "liggghts", "code_version": "x", "wall_time_s": 0.0, "steps": 1,
                          "dt": 1.0, "particles": 1})
    out = tmp_path / "run"
    out.mkdir()
    iface.to_csv(out / "interface.csv", index=False)
    res.write(out, scene)
    sph = _series(out / "vtk" / "spheres.pvd")
    assert [ti for ti, _ in sph] == t
    assert sph[1][1].points[0, 1] == pytest.approx(0.01 - 1e-3)
    mp = _series(out / "vtk" / "mpm_points.pvd")
    assert [ti for ti, _ in mp] == t
    m = mp[1][1]
    np.testing.assert_array_equal(m.point_data["eps_p"], [0.0, 0.1, 0.2])
    np.testing.assert_array_equal(m.point_data["stress"][:, 0], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(m.point_data["stress"][:, 3], [0.5] * 3)
    np.testing.assert_array_equal(m.point_data["displacement"][:, 1], [1e-3] * 3)
    it = _series(out / "vtk" / "interface.pvd")
    assert [ti for ti, _ in it] == t
    np.testing.assert_array_equal(it[1][1].point_data["force"][:, 0], [3.0, 4.0])
    assert not (out / "vtk" / "clusters.pvd").exists()          # no cluster rows in these tables: no file


def test_vtk_off_by_default(tmp_path):
    scene = loads_scene(DEM.replace("vtk = true", "vtk = false"))
    assert scene.output.vtk is False
    Result(summary={}).write(tmp_path, scene)
    assert not (tmp_path / "vtk").exists()


def test_stored_liggghts_run_through_the_cli(tmp_path):
    """A reference backend's parsed tables (a stored LIGGGHTS run) open the same way: `mpmdem vtk SCENE RUN_DIR`."""
    import shutil

    from coupler.cli import ROOT, main
    run = tmp_path / "lig"
    shutil.copytree(ROOT / "reference_runs" / "xval_impacts" / "liggghts" / "mesh", run)
    assert main(["vtk", str(ROOT / "validation" / "cases" / "xval_impacts" / "mesh.toml"), str(run)]) == 0
    res = Result.read(run)
    sph = read_pvd(run / "vtk" / "spheres.pvd")
    assert [t for t, _ in sph] == sorted(res.bodies["t"].unique())
    t, p = sph[len(sph) // 2]
    m = meshio.read(p)
    row = res.bodies[res.bodies["t"] == t]
    np.testing.assert_array_equal(m.points, row[["x", "y", "z"]].to_numpy(float))
    walls = read_pvd(run / "vtk" / "walls.pvd")
    assert len(walls) == len(sph)
    hit = set(res.contacts.loc[res.contacts["j"] == "wall:floor", "t"])
    assert hit
    for t, p in [w for w in walls if w[0] in hit][::5]:     # the ball pushes the mesh floor down on impact
        f = meshio.read(p).cell_data["force"][0][0]
        rows = res.contacts[(res.contacts["t"] == t) & (res.contacts["j"] == "wall:floor")]
        np.testing.assert_allclose(f, -rows[["fx", "fy", "fz"]].sum().to_numpy(float), rtol=1e-12)
        assert f[1] < 0.0


def test_coupled_interface_points_and_totals(tmp_path):
    """The coupler's interface_points.csv (end state) and interface.csv totals (Result.interface) are written."""
    scene = loads_scene(DEM)
    res = Result(summary={}, particles=[(0.0, pd.DataFrame({"t": [0.0], "x": [0.0], "y": [0.0]})),
                                        (2e-3, pd.DataFrame({"t": [2e-3], "x": [0.0], "y": [0.0]}))])
    res.interface = pd.DataFrame({"t": [1e-3, 2e-3], "fx_dem": [1.0, 2.0], "fy_dem": [3.0, 4.0],
                                  "fx_mpm": [1.0, 2.0], "fy_mpm": [3.0, 4.0], "work_dem": [0.0, 0.1],
                                  "work_mpm": [0.0, 0.1]})
    out = tmp_path / "run"
    out.mkdir()
    pd.DataFrame({"x0": [0.0, 1.0], "y0": [0.5, 0.5], "ux": [0.1, 0.2], "uy": [0.0, -0.1], "fx": [5.0, 6.0],
                  "fy": [7.0, 8.0]}).to_csv(out / "interface_points.csv", index=False)
    res.write(out, scene)
    it = _series(out / "vtk" / "interface.pvd")
    assert [t for t, _ in it] == [2e-3]
    m = it[0][1]
    np.testing.assert_allclose(m.points[:, :2], [[0.1, 0.5], [1.2, 0.4]])
    np.testing.assert_array_equal(m.point_data["force"][:, :2], [[5.0, 7.0], [6.0, 8.0]])
    np.testing.assert_array_equal(m.point_data["total_fy_dem"], [4.0, 4.0])
