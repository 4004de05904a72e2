"""Issue 17 item 7: `mpmdem bench` reports a genuinely missing reference code as unavailable with the reason, but a
crash of a sub-bench (or a broken import inside this project) fails loudly: recorded with its error and a non-zero
exit, never `available: false`."""
import pytest

from coupler import bench
from coupler.errors import BackendUnavailable


def test_missing_reference_code_is_unavailable_with_reason():
    def fn():
        raise BackendUnavailable("'yade' is not installed (Debian: apt-get install -y yade)")
    failures = []
    r = bench._optional("YADE", fn, failures)
    assert r == {"available": False, "reason": "YADE not available: 'yade' is not installed (Debian: apt-get install -y yade)"}
    assert failures == []


def test_absent_third_party_package_is_unavailable():
    def fn():
        import kratos_package_that_is_not_installed  # noqa: F401
    failures = []
    r = bench._optional("Kratos", fn, failures)
    assert r["available"] is False and "kratos_package_that_is_not_installed" in r["reason"]
    assert failures == []


@pytest.mark.parametrize("exc", [ZeroDivisionError("boom"), ImportError("cannot import name 'x' from 'coupler.mpm'"),
                                 ModuleNotFoundError("No module named 'coupler.mpm.nothere'", name="coupler.mpm.nothere")])
def test_crash_or_broken_import_fails_loudly(exc):
    def fn():
        raise exc
    failures = []
    r = bench._optional("MPM bench", fn, failures)
    assert r.get("available") is not False
    assert r["failed"] is True and type(exc).__name__ in r["error"]
    assert failures == ["MPM bench"]


def test_cli_bench_exits_nonzero_on_a_failed_sub_bench(monkeypatch, tmp_path, capsys):
    from coupler.cli import main
    monkeypatch.setattr(bench, "run_bench", lambda out, quick=False: {
        "dem_lattice_20k": {}, "mpm_collapse": {"failed": True, "error": "ZeroDivisionError: boom"},
        "failures": ["MPM bench"]})
    monkeypatch.setattr(bench, "print_bench", lambda res: None)
    assert main(["bench", "--out", str(tmp_path)]) == 1
    assert "MPM bench" in capsys.readouterr().err


def test_absent_section_module_is_not_available_but_a_broken_one_raises(tmp_path, monkeypatch):
    """`[mpm]` in a version without the MPM package: the one-line 'not available'; an ImportError inside the
    package (a broken import) propagates with its own message."""
    from coupler import scene as sc
    from coupler.errors import SceneError
    from tests.conftest import BASE_SCENE
    (tmp_path / "brokenpkg").mkdir()
    (tmp_path / "brokenpkg" / "__init__.py").write_text("")
    (tmp_path / "brokenpkg" / "scene.py").write_text("from coupler.mpm import name_that_does_not_exist\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    text = BASE_SCENE + "[extra]\n"
    monkeypatch.setitem(sc.SECTIONS, "extra", sc.Section("absentpkg_xyz.scene", "parse", "T", missing="absent here"))
    with pytest.raises(SceneError, match="extra: absent here"):
        sc.loads_scene(text)
    monkeypatch.setitem(sc.SECTIONS, "extra", sc.Section("brokenpkg.scene", "parse", "T", missing="absent here"))
    with pytest.raises(ImportError, match="name_that_does_not_exist"):
        sc.loads_scene(text)


def test_implicit_rows_against_stored_kratos(capsys):
    """Issue 18: the implicit MPM rows of `mpmdem bench` and their ratio to the stored Kratos run at the same h."""
    imp = {"case": "mpm_bui_implicit h=10mm", "points": 800, "steps": 40, "dt": 2.4e-3, "wall_s": 2.0,
           "cpu_s": 1.9, "mp_steps_per_s": 16000.0, "mp_steps_per_cpu_s": 16842.1, "newton_iterations_mean": 4.0,
           "newton_iterations_max": 9, "step_cuts": 0, "line_search_halvings": 0,
           "split_s": {"assembly": 1.0, "solve": 0.5, "update": 0.5}, "per_iteration": {"factor_ms": 5.0}}
    res = {"machine": {}, "dem_lattice_20k": {}, "mpm_implicit": {"h10mm": imp},
           "mpm_bui_native_vs_kratos": {"kratos": {"h10mm": {"mp_steps_per_s": 1600.0, "wall_time_s": 2290.0,
                                                             "newton_iterations_mean": 6.0, "source": "stored",
                                                             "surface_rms_m": 0.018},
                                                   "h20mm": {"available": False, "reason": "not stored"}}, "native": {}}}
    bench.implicit_vs_kratos(res)
    r = res["mpm_implicit"]["vs_kratos_h10mm"]
    assert r["ratio_mp_steps_per_s"] == 10.0 and r["goal_met"] is False
    assert r["implicit_wall_s_per_simulated_s_estimate"] == 2.0 / (40 * 2.4e-3)
    assert "vs_kratos_h20mm" not in res["mpm_implicit"]
    # the LU bound: 800 points / (4 iterations x 5 ms) = 40,000 MP-steps/s = 25x Kratos; at Kratos' 6: 16.7x
    lb = r["lu_bound"]
    assert lb["own_iterations"]["max_mp_steps_per_s"] == pytest.approx(40000.0)
    assert lb["own_iterations"]["max_ratio"] == pytest.approx(25.0)
    assert lb["kratos_iterations"]["max_ratio"] == pytest.approx(800 / (6 * 5e-3) / 1600.0)
    bench.print_bench(res)
    out = capsys.readouterr().out
    assert "16,000 MP-steps/s" in out and "10.0x Kratos' MP-steps/s" in out and "NOT met" in out
    assert "allows at most 25.0x at 4.00 iterations per step, 16.7x at Kratos' 6.00" in out


def test_implicit_ratio_prefers_the_live_kratos_window(capsys):
    """Issue 18: with a live Kratos run of this bench (kratos_short), the implicit ratio is taken against it, and the
    stored whole run is listed beside; the LU bound uses the live run's iterations."""
    imp = {"case": "mpm_bui_implicit h=5mm", "points": 3200, "steps": 40, "dt": 1.2e-3, "wall_s": 1.6,
           "cpu_s": 1.6, "mp_steps_per_s": 80000.0, "mp_steps_per_cpu_s": 80000.0, "newton_iterations_mean": 5.0,
           "newton_iterations_max": 8, "step_cuts": 0, "line_search_halvings": 0,
           "split_s": {"assembly": 0.5, "solve": 0.9, "update": 0.1}, "per_iteration": {"factor_ms": 3.2}}
    res = {"machine": {}, "dem_lattice_20k": {}, "mpm_implicit": {"h5mm": imp},
           "mpm_bui_native_vs_kratos": {
               "kratos": {"h5mm": {"mp_steps_per_s": 24000.0, "wall_time_s": 1087.0, "newton_iterations_mean": 2.4,
                                   "source": "stored run of 2026-12-02", "surface_rms_m": 0.01}},
               "kratos_short": {"h5mm": {"mp_steps_per_s": 32000.0, "window_s": 0.05, "wall_s_per_simulated_s": 800.0,
                                         "newton_iterations_mean": 2.0, "source": "this bench run"}},
               "native": {}}}
    bench.implicit_vs_kratos(res)
    r = res["mpm_implicit"]["vs_kratos_h5mm"]
    assert r["ratio_mp_steps_per_s"] == pytest.approx(2.5) and r["kratos_source"] == "this bench run, first 0.05 s"
    assert r["kratos_wall_s_per_simulated_s"] == 800.0
    assert r["stored_whole_run"]["ratio_mp_steps_per_s"] == pytest.approx(80000.0 / 24000.0)
    assert r["lu_bound"]["kratos_iterations"]["newton_iterations_mean"] == 2.0
    bench.print_bench(res)
    out = capsys.readouterr().out
    assert "2.5x Kratos' MP-steps/s (this bench run, first 0.05 s" in out
    assert "against the stored whole run (stored run of 2026-12-02, whole 1 s run): 3.3x" in out


def test_implicit_same_work_ratio_against_the_kratos_window(capsys):
    """Issue 18's same-work ratio: the native run on Kratos' discretization over Kratos' live window
    (kratos_short.<h>.native_same_discretization) over Kratos' MP-steps/s in that window, with both iteration
    counts; printed under the bench scene's ratio."""
    imp = {"case": "mpm_bui_implicit h=5mm", "points": 3200, "steps": 40, "dt": 1.2e-3, "wall_s": 1.6,
           "cpu_s": 1.6, "mp_steps_per_s": 80000.0, "mp_steps_per_cpu_s": 80000.0, "newton_iterations_mean": 5.0,
           "newton_iterations_max": 8, "step_cuts": 0, "line_search_halvings": 0,
           "split_s": {"assembly": 0.5, "solve": 0.9, "update": 0.1}, "per_iteration": {"factor_ms": 3.2}}
    same = {**imp, "case": "mpm_bui_implicit h=5mm, dt 0.000121 s, direct, Kratos' discretization",
            "mp_steps_per_s": 640000.0, "newton_iterations_mean": 1.9, "per_iteration": {"factor_ms": 1.1}}
    res = {"machine": {}, "dem_lattice_20k": {}, "mpm_implicit": {"h5mm": imp},
           "mpm_bui_native_vs_kratos": {
               "kratos": {},
               "kratos_short": {"h5mm": {"mp_steps_per_s": 32000.0, "window_s": 0.05, "wall_s_per_simulated_s": 800.0,
                                         "newton_iterations_mean": 2.0, "source": "this bench run", "steps": 413,
                                         "native_same_discretization": same,
                                         "native_same_discretization_modified_newton": {
                                             **same, "case": same["case"] + ", modified Newton (reuse_ratio 0.1)",
                                             "mp_steps_per_s": 800000.0, "newton_iterations_mean": 3.2}}},
               "native": {}}}
    bench.implicit_vs_kratos(res)
    sd = res["mpm_implicit"]["vs_kratos_same_discretization_h5mm"]
    assert sd["ratio_mp_steps_per_s"] == pytest.approx(20.0) and sd["goal_met"] is True
    assert sd["native_newton_iterations_mean"] == 1.9 and sd["kratos_newton_iterations_mean"] == 2.0
    assert sd["modified_newton"]["ratio_mp_steps_per_s"] == pytest.approx(25.0)   # beside, not the goal's row
    assert res["mpm_implicit"]["vs_kratos_h5mm"]["goal_met"] is False     # the bench scene's ratio: 2.5x
    bench.print_bench(res)
    out = capsys.readouterr().out
    assert ("Kratos' 413 steps over its first 0.05 s): 640,000 vs 32,000 MP-steps/s, Newton 1.90 vs 2.00 per step: "
            "20.0x (goal >= 20x: met)") in out
    assert ("modified Newton on the same work (modified Newton (reuse_ratio 0.1); not the goal's Newton-Raphson): "
            "800,000 MP-steps/s, 3.20 iterations per step: 25.0x") in out
