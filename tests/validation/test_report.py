"""The readable report (validation/report.py): matrix first, reasons in one line, provenance, a browser screenshot."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from validation.report import REFERENCE_PACKAGES, provenance, reference_code, render, why, write_report
from validation.suite import run_suite

CASE_OK = '''
"""A passing fake case with a plot."""
TITLE = "fake pass"
def evaluate(ctx):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ctx.check_rel("period [s]", 1.001, 1.0, 0.01, wall_time_s=2.0)
    ctx.check_rel("period [s]", 1.002, 1.0, 0.01, backend="yade", wall_time_s=20.0)
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot([0, 1], [0, 1])
    ctx.save_plot(fig)
'''
CASE_BAD = '''
"""A failing fake case."""
TITLE = "fake fail"
def evaluate(ctx):
    ctx.check_rel("peak force [N]", 1.2, 1.0, 0.05, wall_time_s=0.5, note="too stiff")
    ctx.check_abs("angle [deg]", 30.0, 33.0, 3.0, wall_time_s=0.5)
    ctx.fail("run-out", "liggghts/run: stored run missing", backend="liggghts")
'''
CASE_CRASH = '''
TITLE = "fake crash"
def evaluate(ctx):
    raise RuntimeError("boom in step 12")
'''


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rep")
    for name, text in (("a_ok", CASE_OK), ("b_bad", CASE_BAD), ("c_crash", CASE_CRASH)):
        (tmp / "cases" / name).mkdir(parents=True)
        (tmp / "cases" / name / "case.py").write_text(text)
    res = run_suite(tmp / "out", cases_dir=tmp / "cases", progress=False)
    return write_report(res, tmp / "out")


def test_first_screen_matrix_reasons_and_provenance(report):
    text = report.read_text()
    head = text[:text.index("<h2>Run</h2>")]                     # everything above the run details
    assert "1 of 3 cases pass" in head
    for s in ("a_ok", "b_bad", "c_crash", "<th>native</th>", "<th>liggghts</th>", "<th>yade</th>",
              "✗ 1 of 2", "✗ 1 of 1", "✓ 1", "case crashed: RuntimeError: boom in step 12",
              "native · peak force [N]: off by 0.2 relative (tolerance 0.05); too stiff (+1 more)"):
        assert s in head, s
    rec = json.loads((report.parent / "suite.json").read_text())
    prov = rec["provenance"]
    assert prov["git"] and prov["cores"] and prov["cpu"] and set(prov["reference_codes"]) >= {"LIGGGHTS", "YADE"}
    assert "git revision" in text and "reference code" in text
    assert (report.parent / "speed_error.png").exists()          # 4 rows with a wall time and a reference
    assert "cases/a_ok/a_ok.png" in text
    assert "why: off by 0 (tolerance 3)" not in text and "why: liggghts/run: stored run missing" in text
    assert render(report.parent).read_text() == text              # rebuilt from suite.json alone: the same page


def test_stored_runs_share_a_row_with_their_installed_code():
    # the stored provenance names ("Kratos Multiphysics", "YADE 2023.02a (DEM partition ...)") join the package rows
    assert reference_code("Kratos Multiphysics") == "Kratos"
    assert reference_code('YADE 2023.02a (DEM partition, coupling.dem_partition = "yade") + native MPM') == "YADE"
    assert reference_code("kratos") == "Kratos" and reference_code("yade_partition") == "YADE"   # folder names
    assert reference_code("LIGGGHTS") == "LIGGGHTS" and reference_code("Other code") == "Other code"
    refs = provenance()["reference_codes"]
    assert set(refs) == set(REFERENCE_PACKAGES), refs                  # every stored run maps to a known code
    assert all(refs[c]["stored_runs"] for c in REFERENCE_PACKAGES)     # each has stored runs in reference_runs/


def test_why_is_one_line():
    assert why({"value": 2.0, "reference": 1.0, "tolerance": 0.5, "kind": "rel", "note": "a\nb"}) == \
        "off by 1 relative (tolerance 0.5); a"
    assert why({"value": 5.0, "reference": None, "tolerance": 1.0, "kind": "max", "note": ""}) == \
        "5 above the limit 1"


def test_screenshot_in_headless_chromium(report):
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is not installed, but CI must render the report (.ci/run installs it)")
        pytest.skip("chromium not installed (apt-get install -y chromium)")
    shot = report.parent / "shot.png"
    with tempfile.TemporaryDirectory() as prof:
        subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                        "--disable-background-networking", "--disable-component-update", "--disable-sync",
                        f"--user-data-dir={prof}", f"--screenshot={shot}", "--window-size=1280,900",
                        report.resolve().as_uri()], capture_output=True, timeout=120)
    assert shot.exists() and shot.stat().st_size > 10_000
    from matplotlib.image import imread
    img = imread(shot)
    assert img.shape[:2] == (900, 1280)
    # the page is not blank: the pass (green) and fail (red) cells of the matrix are on the first screen
    rgb = (img[..., :3] * 255).round() if img.dtype != "uint8" else img[..., :3]
    green = ((abs(rgb[..., 0] - 0xe3) < 3) & (abs(rgb[..., 1] - 0xf4) < 3) & (abs(rgb[..., 2] - 0xe3) < 3)).sum()
    red = ((abs(rgb[..., 0] - 0xf9) < 3) & (abs(rgb[..., 1] - 0xda) < 3) & (abs(rgb[..., 2] - 0xda) < 3)).sum()
    assert green > 500 and red > 500


def test_hard_cases_are_one_section_after_the_others(tmp_path):
    """Cases named hard_* (issue #17) follow the other cases under one heading, in the matrix and in the sections,
    the matrix row saying how many of them pass."""
    for name, text in (("hard_a", CASE_OK), ("b_ok", CASE_OK), ("hard_c", CASE_BAD)):
        (tmp_path / "cases" / name).mkdir(parents=True)
        (tmp_path / "cases" / name / "case.py").write_text(text)
    text = write_report(run_suite(tmp_path / "out", cases_dir=tmp_path / "cases", progress=False),
                        tmp_path / "out").read_text()
    head = text[:text.index("<h2>Run</h2>")]
    assert head.index(">b_ok<") < head.index("Hard cases (stability)</a>: 1 of 2 pass") < head.index(">hard_a<") \
        < head.index(">hard_c<")
    body = text[text.index("<h2>Run</h2>"):]
    assert body.index("<h2 id='b_ok'>") < body.index("<h1 id='hard'>Hard cases (stability)</h1>") \
        < body.index("<h2 id='hard_a'>") < body.index("<h2 id='hard_c'>")
