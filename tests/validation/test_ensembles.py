"""validation/ensembles.py: member scenes (seed / dt) and the ensemble comparison (difference of means against the
standard error of the difference)."""
import math
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import ROOT
from validation.ensembles import SEED_STRIDE, compare_ensembles, seeds_or_perturbations

WALL = (Path(ROOT) / "validation" / "cases" / "xval_retaining_wall" / "wall.toml").read_text()


def _seeds(doc):
    out = [doc.get("seed")]
    out += [p.get("seed") for p in doc.get("dem", {}).get("packings", [])]
    return out


def test_seed_members_move_every_seed_and_nothing_else():
    texts = seeds_or_perturbations(WALL, 4, kind="seed")
    assert texts[0] == WALL
    base = tomllib.loads(WALL)
    for m, text in enumerate(texts):
        doc = tomllib.loads(text)
        assert _seeds(doc) == [s + SEED_STRIDE * m for s in _seeds(base)]
        for key in ("time", "materials", "contacts"):
            assert doc[key] == base[key]
        assert doc["dem"]["clusters"] == base["dem"]["clusters"]
        lines_a, lines_b = WALL.splitlines(), text.splitlines()
        assert len(lines_a) == len(lines_b)
        assert all(a == b for a, b in zip(lines_a, lines_b) if not a.lstrip().startswith("seed"))
    assert len(set(texts)) == 4


def test_dt_members_perturb_time_dt_only():
    texts = seeds_or_perturbations(WALL, 3, kind="dt", rel=1e-3)
    assert texts[0] == WALL
    for m, text in enumerate(texts):
        doc = tomllib.loads(text)
        assert doc["time"]["dt"] == pytest.approx(5e-6 * (1 - 1e-3 * m), rel=1e-15)
        assert _seeds(doc) == _seeds(tomllib.loads(WALL))


def test_nothing_to_vary_is_an_error():
    with pytest.raises(ValueError, match="seed"):
        seeds_or_perturbations('name = "x"\n[time]\nt_end = 1.0\n', 2, kind="seed")
    with pytest.raises(ValueError, match="dt"):
        seeds_or_perturbations('seed = 1\n[time]\nt_end = 1.0\n[mpm]\ndt = 1e-3\n', 2, kind="dt")  # not [time]
    with pytest.raises(ValueError, match="kind"):
        seeds_or_perturbations(WALL, 2, kind="mass")


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 10**6), n=st.integers(1, 12), comment=st.booleans())
def test_seed_members_parse_and_differ(seed, n, comment):
    text = f'name = "x"\nseed = {seed}{"  # top" if comment else ""}\n[time]\nt_end = 1.0\n'
    texts = seeds_or_perturbations(text, n, kind="seed")
    assert [tomllib.loads(t)["seed"] for t in texts] == [seed + SEED_STRIDE * m for m in range(n)]


def _frame(values, col="x"):
    return pd.DataFrame({col: values})


def test_compare_definitions_by_hand():
    a, b = [1.0, 2.0, 3.0, 4.0], [2.0, 4.0, 6.0]
    (r,) = compare_ensembles(_frame(a), _frame(b), ["x"], z_max=2.0)
    sa, sb = np.std(a, ddof=1), np.std(b, ddof=1)
    pooled = math.sqrt(sa ** 2 / 4 + sb ** 2 / 3)
    assert r["mean_a"] == 2.5 and r["mean_b"] == 4.0 and r["n_a"] == 4 and r["n_b"] == 3
    assert r["std_a"] == pytest.approx(sa) and r["std_b"] == pytest.approx(sb)
    assert r["diff"] == -1.5 and r["pooled"] == pytest.approx(pooled)
    assert r["z"] == pytest.approx(1.5 / pooled) and r["passed"] == (1.5 / pooled <= 2.0)


def test_compare_edge_cases():
    (r,) = compare_ensembles(_frame([1.0, 1.0]), _frame([1.0, 1.0]), ["x"])
    assert r["z"] == 0.0 and r["passed"]
    (r,) = compare_ensembles(_frame([1.0, 1.0]), _frame([1.0]), ["x"])      # one run: no spread known
    assert math.isnan(r["std_b"]) and math.isnan(r["z"]) and not r["passed"]
    (r,) = compare_ensembles(_frame([1.0, 1.0]), _frame([2.0, 2.0]), ["x"])
    assert r["z"] == math.inf and not r["passed"]
    (r,) = compare_ensembles(_frame([1.0, np.nan, 3.0]), _frame([np.nan]), ["x"])
    assert r["n_a"] == 2 and r["n_b"] == 0 and math.isnan(r["z"]) and not r["passed"]
    with pytest.raises(ValueError):
        compare_ensembles(_frame([1.0]), _frame([1.0]), ["x"], z_max=0.0)


@settings(max_examples=60, deadline=None)
@given(a=st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=10),
       b=st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=10),
       shift=st.floats(-1e3, 1e3), scale=st.floats(1e-3, 1e3))
def test_z_is_symmetric_and_invariant_under_affine_maps(a, b, shift, scale):
    (r,) = compare_ensembles(_frame(a), _frame(b), ["x"])
    (s,) = compare_ensembles(_frame(b), _frame(a), ["x"])
    assert s["diff"] == pytest.approx(-r["diff"], abs=1e-9) and s["z"] == pytest.approx(r["z"], rel=1e-9, abs=1e-9)
    if r["pooled"] > 1e-6 * max(map(abs, a + b + [1.0])):          # away from the degenerate (constant) case
        (t,) = compare_ensembles(_frame([shift + scale * v for v in a]), _frame([shift + scale * v for v in b]), ["x"])
        assert t["z"] == pytest.approx(r["z"], rel=1e-6, abs=1e-9)


def test_same_distribution_passes_at_the_expected_rate():
    """Two ensembles of N = 8 from one distribution: z <= 2 in about 93.5 % of the comparisons (Welch t, ~14 dof);
    a shift of 3 standard errors fails most of them. Seeded, so the counts are fixed."""
    rng = np.random.default_rng(1)
    same = [compare_ensembles(_frame(rng.normal(0, 1, 8)), _frame(rng.normal(0, 1, 8)), ["x"])[0]["passed"]
            for _ in range(2000)]
    assert 0.91 < np.mean(same) < 0.96
    shifted = [compare_ensembles(_frame(rng.normal(0, 1, 8)), _frame(rng.normal(1.5, 1, 8)), ["x"])[0]["passed"]
               for _ in range(2000)]
    assert np.mean(shifted) < 0.4


def test_retaining_wall_run_metrics_on_a_synthetic_history():
    """The per-run row of xval_retaining_wall: final x / rotation per block and the failure-mode quantities measured
    from the release on."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "xrw", Path(ROOT) / "validation" / "cases" / "xval_retaining_wall" / "case.py")
    case = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(case)
    t = np.linspace(0.0, 1.0, 101)
    after = np.maximum(t - 0.25, 0.0)
    hist = {}
    for k, name in enumerate(case.BLOCKS):
        x = 0.2 - 0.012 * k + (0.02 + 0.01 * k) * after          # every block moves out, the upper ones faster
        y = 0.0125 + 0.025 * k + 0.0 * t
        rot = 3.0 * k * after
        hist[name] = (t, x, y, rot)
    row = case.run_metrics(hist, 0.25)
    assert row["x_final_block1"] == pytest.approx(0.2 + 0.02 * 0.75)
    assert row["rot_final_block6"] == pytest.approx(15.0 * 0.75)
    assert row["bottom_slide"] == pytest.approx(0.015) and row["bottom_rot_max"] == 0.0
    assert row["bottom_lift_max"] == 0.0 and row["top_dx"] == pytest.approx(0.07 * 0.75)
    assert row["wall_dx"] == pytest.approx(0.045 * 0.75)
    d0 = math.hypot(0.012, 0.025)                                 # adjacent centroids at the release
    assert row["separation_max"] == pytest.approx(math.hypot(-0.012 + 0.01 * 0.75, 0.025) - d0)
