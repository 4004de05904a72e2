"""kratos_bench.whole_collapse (issue 18's whole-collapse comparison): its plumbing with a stand-in for the Kratos run
(Kratos' own run is minutes; the live comparison is `python3 -m validation.cases.mpm_bui_collapse.kratos_bench
whole`). The native side is a real run of the implicit case scene (h = 20 mm, about a second)."""
import math

import pytest

import adapters.kratos.backend as KB_backend
from validation.cases.mpm_bui_collapse import kratos_bench as KB


def test_whole_collapse_ratio_and_native_metrics(monkeypatch):
    seen = []

    def fake_kratos(h, sc):
        seen.append((h, sc.mpm.cell_size, sc.name))
        return {"source": "stand-in", "cell_size": h, "wall_time_s": 30.0, "surface_rms_m": 0.01, "points_lost": 0}

    monkeypatch.setattr(KB_backend, "available", lambda: (True, ""))
    monkeypatch.setattr(KB, "_live_kratos", fake_kratos)
    monkeypatch.setattr(KB, "WHOLE_CFL", {0.02: 5.0})
    out = KB.whole_collapse((0.02,))
    assert seen == [(0.02, 0.02, "mpm_bui_collapse")]    # Kratos' scene (kratos_runs) at the same h
    row = out["h20mm"]
    n = row["native"]
    assert n["cfl"] == 5.0 and n["threads"] == 1 and n["steps"] > 0 and n["points_lost"] == 0
    assert math.isclose(row["ratio_wall"], 30.0 / n["wall_time_s"])
    assert 0.0 < n["surface_rms_m"] < 0.02 and abs(n["volume_change"]) < 0.05
    assert n["newton_iterations_mean"] >= 1.0


def test_whole_collapse_without_kratos(monkeypatch):
    monkeypatch.setattr(KB_backend, "available", lambda: (False, "Kratos not installed"))
    assert KB.whole_collapse((0.01,)) == {"available": False, "reason": "Kratos not installed"}


def test_whole_collapse_refuses_a_cell_size_without_a_step():
    with pytest.raises(ValueError, match=r"sizes: cell sizes 7 mm have no step in WHOLE_CFL \(allowed: 10, 5 mm\)"):
        KB.whole_collapse((0.007,))
