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
    store = tmp_path / "store"
    store.mkdir(exist_ok=True)
    for h in (0.0025, 0.00125):
        REF.path(h, store).write_text("x_m,surface_m\n" + "".join(f"{a:.15f},{b:.15f}\n" for a, b in zip(*surf_all[h])))
    xr, sr = surf_all[0.000625]
    surf = {h: surf_all[h] for h in WALL}
    curves = {"explicit": [(WALL[h], 0.0, h, 0.5, REF.rms_against(*surf[h], xr, sr)) for h in WALL],
              "implicit": [(2.0, 0.0, 0.01, 5.0, implicit_err)]}
    ctx = CaseContext("mpm_bui_implicit", CASES_DIR / "mpm_bui_implicit", tmp_path)
    fig, ax = plt.subplots()
    CASE.reference_rows(ctx, 0.000625, xr, sr, curves, ax, surf, store, prefix)
    plt.close(fig)
    return {r.metric: r for r in ctx.rows}


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
