"""`mpmdem run` prints one warning line per kind of thing the run dropped (coupler/cli.py drop_warnings); the counts
themselves are in summary.json. Summaries below have the shapes the native runs write."""
import subprocess
import sys
from pathlib import Path

from coupler.cli import drop_warnings

BAR = Path(__file__).resolve().parents[2] / "validation" / "cases" / "mpm_elastic_bar" / "scene.toml"


def test_each_kind_of_drop_is_one_line():
    s = {"mesh_contacts_dropped": {"floor": {"features_beyond_buffer": 0, "contacts_beyond_slots": 11,
                                             "rows_beyond_buffer": 3},
                                   "lid": {"features_beyond_buffer": 0, "contacts_beyond_slots": 0,
                                           "rows_beyond_buffer": 0}, "total": 14},
         "mpm_dropped_point_loads": {"count": 2, "impulse_dropped": 1e-6, "impulse_applied": 3e-3},
         "mpm_stranded_boundary_particles": {"particle_steps": 5, "max_at_once": 1},
         "coupling": {"mpm_dropped_loads": {"count": 0}, "mpm_stranded_boundary_particles": {"particle_steps": 8,
                                                                                             "max_at_once": 2}}}
    lines = drop_warnings(s)
    assert len(lines) == 5, lines
    assert "mesh 'floor': 11 sphere-mesh contacts dropped" in lines[0] and "11 beyond the history slots" in lines[0]
    assert "3 contact rows left out" in lines[1]
    assert lines[2].startswith("2 MPM point loads dropped") and "1e-06 of 0.003" in lines[2]
    assert "5 particle-steps" in lines[3] and "8 particle-steps, at most 2 at once" in lines[4]


def test_a_clean_run_warns_nothing(tmp_path):
    assert drop_warnings({"mesh_contacts_dropped": {"m": {"features_beyond_buffer": 0, "contacts_beyond_slots": 0,
                                                          "rows_beyond_buffer": 0}, "total": 0},
                          "mpm_dropped_point_loads": {"count": 0},
                          "mpm_stranded_boundary_particles": {"particle_steps": 0}}) == []
    scene = tmp_path / "bar.toml"
    scene.write_text(BAR.read_text().replace("t_end = 0.2 ", "t_end = 0.004 ", 1))
    r = subprocess.run([sys.executable, "-m", "coupler.cli", "run", str(scene), "--out", str(tmp_path / "o"),
                        "--quiet"], capture_output=True, text=True)
    assert r.returncode == 0 and "warning" not in r.stderr, r.stderr
