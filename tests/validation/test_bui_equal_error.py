"""The equal-error rows of mpm_bui_implicit (case.reference_rows) on synthetic surfaces with a known error: the
reference's own error from the differences of successive halvings, the trust test it gates, and the implicit /
explicit wall-time ratio at equal error (log-log interpolation between the explicit runs bracketing it)."""
import importlib
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from validation.cases.mpm_bui_implicit import reference as REF
from validation.framework import CASES_DIR, CaseContext

CASE = importlib.import_module("validation.cases.mpm_bui_implicit.case")
X = np.linspace(0.0, 0.5, 201)
HS = (0.01, 0.005, 0.0025, 0.00125, 0.000625)      # explicit 10 / 5 mm runs, stored 2.5 / 1.25 mm, the reference
WALL = {0.01: 0.5, 0.005: 3.0}                      # the explicit runs' wall times [s]


def surfaces(q, amp=0.004):
    """Surfaces s_k = s_inf + amp q^k / (1 - q) phi at HS[k]: one error shape, successive differences amp q^k phi."""
    phi = np.sin(2 * math.pi * X / 0.5)
    return {h: (X, 0.1 - 0.2 * X + amp * q ** k / (1 - q) * phi) for k, h in enumerate(HS)}


def rows_of(tmp_path, surf_all, implicit_err, prefix=""):
    """reference_rows with the explicit 10 / 5 mm runs, the stored 2.5 / 1.25 mm runs (written to a store), the
    0.625 mm reference and one implicit run (2.0 s) of error implicit_err against it."""
    store = write_store(tmp_path / "store", surf_all, (0.0025, 0.00125, 0.000625))
    surf = {h: surf_all[h] for h in WALL}
    ref = REF.candidate("mc", None, coarse=surf, store=store)
    assert ref.h == 0.000625 and ref.levels == HS
    curves = {"explicit": [(WALL[h], 0.0, h, 0.5, REF.rms_against(*surf[h], ref.x, ref.s)) for h in WALL],
              "implicit": [(2.0, 0.0, 0.01, 5.0, implicit_err)]}
    ctx = CaseContext("mpm_bui_implicit", CASES_DIR / "mpm_bui_implicit", tmp_path)
    fig, ax = plt.subplots()
    CASE.reference_rows(ctx, ref, [ref], curves, ax, prefix)
    plt.close(fig)
    return {r.metric: r for r in ctx.rows}


def write_store(store, surf_all, hs):
    """The surfaces at cell sizes hs written as stored runs (reference.path's csv format) into store."""
    store.mkdir(parents=True, exist_ok=True)
    for h in hs:
        REF.path(h, store).write_text("x_m,surface_m\n" + "".join(f"{a:.15f},{b:.15f}\n" for a, b in zip(*surf_all[h])))
    return store


def explicit_errors(surf_all):
    xr, sr = surf_all[0.000625]
    return {h: REF.rms_against(*surf_all[h], xr, sr) for h in WALL}


def test_first_order_surfaces_give_the_tail_bound_and_the_interpolated_ratio(tmp_path):
    s = surfaces(0.5)
    e = explicit_errors(s)
    e_imp = math.sqrt(e[0.01] * e[0.005])   # between the explicit errors: explicit time sqrt(0.5 * 3.0) s
    rows = rows_of(tmp_path, s, e_imp, "t: ")
    own = rows["t: reference: its estimated own surface error / smallest error it ranks [-]"]
    # the differences halve (r = 1/2): the own error is the last difference, |s(1.25) - s(0.625)|, and exactly the
    # reference's true error |s(0.625) - s_inf| (one shape)
    d_last = REF.rms_against(*s[0.00125], *s[0.000625])
    assert "largest ratio r = 0.500" in own.note
    assert abs(own.value - d_last / min(e[0.005], e_imp)) < 1e-6 and own.passed
    goal = rows["t: implicit within 2x explicit at equal error (vs converged reference) [-]"]
    assert abs(goal.value - 2.0 / math.sqrt(1.5)) < 1e-6 and goal.passed
    assert rows["t: reference: explicit error against it decreases with h [-]"].passed


def test_slow_decay_leaves_the_goal_undetermined(tmp_path):
    """Differences that shrink by 0.9 per halving: the reference's own error, 9 x the last difference, is not below
    half the errors it ranks, so the goal row fails as undetermined (NaN) whatever the ratio."""
    s = surfaces(0.9)
    e = explicit_errors(s)
    rows = rows_of(tmp_path, s, math.sqrt(e[0.01] * e[0.005]))
    own = rows["reference: its estimated own surface error / smallest error it ranks [-]"]
    assert "largest ratio r = 0.900" in own.note and not own.passed
    goal = rows["implicit within 2x explicit at equal error (vs converged reference) [-]"]
    assert not goal.passed and math.isnan(goal.value) and "not determined" in goal.note


def test_the_reference_is_the_sequence_with_the_smallest_own_error(tmp_path, monkeypatch):
    """reference.best_candidate: of two stored sequences of a variant (the scene's cfl with the case's 10 / 5 mm runs
    as its coarse levels, and a refined cfl with every level stored) the reference is the finest run of the one whose
    differences of successive halvings give the smaller own-error bound: here the refined one (differences shrinking
    by 1/2 against 0.9), though its finest run is coarser (1.25 mm against 0.625 mm)."""
    monkeypatch.setattr(REF, "STORE", tmp_path)
    monkeypatch.setattr(REF, "STORED", {("mc", None): (0.0025, 0.00125, 0.000625),
                                        ("mc", 0.125): (0.00125, 0.0025, 0.005, 0.01)})
    slow, fast = surfaces(0.9), surfaces(0.5)
    write_store(REF.store_of("mc"), slow, (0.0025, 0.00125, 0.000625))
    write_store(REF.store_of("mc", 0.125), fast, (0.01, 0.005, 0.0025, 0.00125))
    best, cands = REF.best_candidate("mc", {h: slow[h] for h in WALL})
    assert [c.cfl for c in cands] == [None, 0.125]
    assert abs(cands[0].r - 0.9) < 1e-9 and abs(cands[1].r - 0.5) < 1e-9
    assert best is cands[1] and best.h == 0.00125 and best.levels == HS[:4]
    assert abs(best.own - best.diffs[-1]) < 1e-12            # r = 1/2: the bound is the last difference
    assert best.store == tmp_path / "cfl0.125" and "cfl 0.125" in best.label
    # without the refined sequence: the scene's one, with the case's runs as its coarse levels
    monkeypatch.setattr(REF, "STORED", {("mc", None): (0.0025, 0.00125, 0.000625)})
    best, cands = REF.best_candidate("mc", {h: slow[h] for h in WALL})
    assert len(cands) == 1 and best.cfl is None and best.h == 0.000625 and best.levels == HS
