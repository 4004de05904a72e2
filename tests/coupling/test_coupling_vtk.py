"""The interface VTK series of a coupled run (coupler/vtk.py): one data set per output time for the MPM interface
points (interface_series.csv) and for the DEM interface wall nodes (interface_wall.csv); every written file is read
back and its fields and time values checked against the tables and the run's output times."""
from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pandas as pd

from coupler.results import Result
from coupler.run import run_scene
from coupler.scene import load_scene
from coupler.vtk import read_pvd

CASES = Path(__file__).resolve().parents[2] / "validation" / "cases"


def test_coupled_interface_series_every_output_time(tmp_path):
    text = (CASES / "coupled_free_collision" / "scene.toml").read_text() + "\n[output]\nvtk = true\n"
    src = tmp_path / "collision.toml"
    src.write_text(text)
    sc = load_scene(src, overrides={"time.t_end": 0.009, "time.output_interval": 0.003, "coupling.dem_substeps": 2})
    out = tmp_path / "run"
    res = run_scene(sc, out, progress=False)
    times = sorted(res.energy["t"].to_numpy(float))
    assert len(times) == 4                                     # t = 0 and three output intervals
    pts = pd.read_csv(out / "interface_series.csv")
    wall = pd.read_csv(out / "interface_wall.csv")
    n_pts = len(sc.coupling.geometry.index)
    n_nodes = len(sc.coupling.geometry.wall_nodes)
    assert len(pts) == 4 * n_pts and len(wall) == 4 * n_nodes
    # the last output time is the end state of interface_points.csv
    end = pts[pts.t == pts.t.max()]
    ip = pd.read_csv(out / "interface_points.csv")
    np.testing.assert_allclose(end[["ux", "uy"]].to_numpy(), ip[["ux", "uy"]].to_numpy(), rtol=1e-10, atol=1e-15)

    for name, table, n in (("interface", pts, n_pts), ("interface_wall", wall, n_nodes)):
        series = read_pvd(out / "vtk" / f"{name}.pvd")
        assert len(series) == 4
        np.testing.assert_allclose([t for t, _ in series], times, rtol=1e-10, atol=1e-15)
        for (t, f), (tt, g) in zip(series, table.groupby("t", sort=True)):
            assert f.exists()
            m = meshio.read(f)
            assert abs(t - tt) <= 1e-12
            np.testing.assert_allclose(m.points[:, :2], g[["x", "y"]].to_numpy(), rtol=1e-12)
            np.testing.assert_allclose(m.point_data["force"][:, :2], g[["fx", "fy"]].to_numpy(), rtol=1e-12)
            np.testing.assert_allclose(m.point_data["velocity"][:, :2], g[["vx", "vy"]].to_numpy(), rtol=1e-12)
            cells = {c.type: c.data for c in m.cells}
            assert len(cells["vertex"]) == n
            assert len(cells["line"]) == n            # the whole outline: one closed chain
            # the interface totals of that time are on every point
            it = res.interface
            k = int(np.argmin(np.abs(it.t.to_numpy() - t)))
            np.testing.assert_allclose(m.point_data["total_fx_dem"], it.fx_dem.iloc[k], rtol=1e-12)
        if name == "interface":
            np.testing.assert_allclose(m.point_data["displacement"][:, :2], g[["ux", "uy"]].to_numpy(),
                                       rtol=1e-12)
    # the sphere was hit: the last data set carries a non-zero wall force and a moved interface
    last = meshio.read(read_pvd(out / "vtk" / "interface_wall.pvd")[-1][1])
    assert np.abs(last.point_data["force"]).max() > 0.0 or np.abs(wall.fx).max() > 0.0
    # the walls series draws the coupled interface wall where its nodes are at each time
    ws = read_pvd(out / "vtk" / "walls.pvd")
    assert len(ws) == 4
    m = meshio.read(ws[-1][1])
    g = wall[wall.t == wall.t.max()]
    np.testing.assert_allclose(m.points[:n_nodes, :2], g[["x", "y"]].to_numpy(), rtol=1e-12)
    # the run folder reads back as a Result with the interface table
    assert len(Result.read(out).interface) == res.summary["steps"] + 1
