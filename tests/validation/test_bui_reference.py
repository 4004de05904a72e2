"""The converged numerical reference of the Bui collapse surface (validation/cases/mpm_bui_implicit/reference.py,
stored in reference_runs/mpm_bui_implicit and, the mu(I) variant, its mu_i folder): provenance of the stored files
and their final points, the estimates of the reference's own error, and (in CI or with MPMDEM_REFERENCE_CHECK=1;
~25 s of CPU) that the stored 2.5 mm surface (to its 1e-9 m print) and points (bitwise) are reproduced by the
command in its header."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from validation.cases.mpm_bui_implicit import reference as REF


SEQUENCES = sorted(REF.STORED, key=lambda k: (k[0], -1.0 if k[1] is None else k[1]))   # (variant, cfl)


def stored(variant="mc", cfl=None):
    return REF.stored_in(REF.store_of(variant, cfl))


def test_sequences_are_the_stored_ones():
    assert REF.sequences("mc") == [None, 0.125] and REF.sequences("mu_i") == [None]
    assert REF.stored_hs("mu_i", 0.125) == ()
    assert REF.store_of("mc", 0.125) == REF.STORE / "cfl0.125" and REF.store_of("mu_i") == REF.STORE / "mu_i"


@pytest.mark.parametrize("variant, cfl", SEQUENCES)
def test_every_stored_run_is_a_listed_one(variant, cfl):
    """The runs in a sequence's store are those reference.STORED lists (the ones `mpmdem reference` regenerates),
    and every one is there."""
    assert tuple(stored(variant, cfl)) == REF.stored_hs(variant, cfl)


@pytest.mark.parametrize("variant, cfl", SEQUENCES)
def test_stored_references_carry_their_provenance(variant, cfl):
    store = REF.store_of(variant, cfl)
    hs = stored(variant, cfl)
    assert hs, f"no stored reference in {store}"
    for h in hs:
        head = [ln for ln in REF.path(h, store).read_text().splitlines() if ln.startswith("#")]
        text = "\n".join(head)
        opt = ("" if variant == "mc" else f" --variant {variant}") + ("" if cfl is None else f" --cfl {cfl:g}")
        assert f"python -m validation.cases.mpm_bui_implicit.reference {h:g}{opt}\n" in text + "\n"
        assert "commit " in text and "points" in text
        if cfl is not None:
            assert f", cfl {cfl:g}," in text
        x, s = REF.load(h, store)
        # bins of width h from the wall to the grid end, the deposit at rest against the wall below the 0.1 m column
        assert np.allclose(np.diff(x), h) and abs(x[0] - 0.5 * h) < 1e-12
        assert 0.05 < s[0] <= 0.1 + h and s[-1] == 0.0


@pytest.mark.parametrize("variant, cfl", SEQUENCES)
def test_stored_reference_points_give_the_stored_surface(variant, cfl):
    """The final points stored with each reference (explicit_h<h>mm_points.npz, for surface_study.py) are those of
    its surface: the case's surface definition applied to them reproduces the csv to its 1e-9 m print."""
    from types import SimpleNamespace
    store = REF.store_of(variant, cfl)
    hs = [h for h in stored(variant, cfl) if REF.points_path(h, store).exists()]
    assert hs, "no stored reference points"
    for h in hs:
        x, y, vol = REF.load_points(h, store)
        assert len(x) == len(y) == len(vol) and f"{len(x)} points" in REF.path(h, store).read_text()
        scene = SimpleNamespace(mpm=SimpleNamespace(cell_size=h, size=(0.8, 0.12),
                                                    bodies=[SimpleNamespace(particles_per_cell=2)]))
        xc, top = REF.surface_of(pd.DataFrame({"x": x, "y": y}), scene)
        xs, s = REF.load(h, store)
        assert np.allclose(xc, xs, rtol=0, atol=1e-6) and np.abs(top - s).max() <= 1e-9


def test_richardson_own_error_recovers_a_synthetic_power_law():
    """reference.own_error: errors e(h) = C (h^p - h0^p) of two runs against a reference at h0 give back p and
    the reference's own error C h0^p (the case's row 'reference: its estimated own surface error ...')."""
    h0, C = 0.00125, 0.7
    for p in (0.6, 1.0, 1.7):
        e = {h: C * (h ** p - h0 ** p) for h in (0.005, 0.0025)}
        pp, own = REF.own_error(0.005, 0.0025, h0, e[0.005], e[0.0025])
        assert abs(pp - p) < 1e-9 and abs(own - C * h0 ** p) < 1e-9 * C * h0 ** p
    # a ratio no order in (0.05, 5) gives: NaN, not a number that looks like an estimate
    assert all(np.isnan(REF.own_error(0.005, 0.0025, h0, 1.0, 2.0)))


def test_tail_bound_own_error_of_a_geometric_sequence():
    """reference.own_error_tail: differences d_k = D q^k of successive halvings (one error shape, order log2(1/q))
    give r = q and the reference's own error d_last q / (1 - q), the sum of the differences still to come: the
    same as Richardson (own_error) on the errors against the reference when the error keeps one shape."""
    D, h0 = 3.0, 0.000625
    for q in (0.3, 0.5, 0.71):
        d = [D * q ** k for k in range(4)]
        r, own = REF.own_error_tail(d)
        assert abs(r - q) < 1e-12 and abs(own - d[-1] * q / (1 - q)) < 1e-12
        # the same sequence as errors of the runs h0 * 2^k against the reference at h0: e(h) = C (h^p - h0^p)
        p = -np.log2(q)
        e = {h0 * 2 ** k: sum(d[len(d) - k:]) for k in (1, 2)}
        pr, own_r = REF.own_error(h0 * 4, h0 * 2, h0, e[h0 * 4], e[h0 * 2])
        assert abs(pr - p) < 1e-6 and abs(own_r - own) < 1e-6 * own
    # the slowest observed decay sets the bound; no decay, or one difference: no estimate
    assert abs(REF.own_error_tail([1.0, 0.4, 0.3])[0] - 0.75) < 1e-15
    assert all(np.isnan(REF.own_error_tail([1.0, 1.2])))
    assert all(np.isnan(REF.own_error_tail([1.0])))


@pytest.mark.slow
@pytest.mark.skipif(not (os.environ.get("MPMDEM_REFERENCE_CHECK") or os.environ.get("CI")),
                    reason="reruns the 2.5 mm explicit reference (~25 s on one idle core, minutes loaded): set "
                           "MPMDEM_REFERENCE_CHECK=1 (CI runs it)")
@pytest.mark.parametrize("variant, cfl, h", [("mc", None, 0.0025), ("mu_i", None, 0.0025), ("mc", 0.125, 0.005)])
def test_stored_reference_is_reproduced_by_its_command(tmp_path, variant, cfl, h):
    """The 2.5 mm run of each sequence at the scene's cfl, the 5 mm one of the time-refined one (~5 s)."""
    store = REF.store_of(variant, cfl)
    subprocess.run([sys.executable, "-m", "validation.cases.mpm_bui_implicit.reference", f"{h:g}", "--variant",
                    variant, "--out", str(tmp_path)] + ([] if cfl is None else ["--cfl", f"{cfl:g}"]),
                   check=True, cwd=REF.ROOT)
    x0, s0 = REF.load(h, store)
    x1, s1 = REF.load(h, tmp_path)
    assert np.array_equal(x0, x1)
    assert np.abs(s1 - s0).max() <= 1e-9
    if REF.points_path(h, store).exists():       # the stored final points: bitwise
        for a, b in zip(REF.load_points(h, store), REF.load_points(h, tmp_path)):
            assert np.array_equal(a, b)


def test_reference_command_regenerates_the_stored_runs(monkeypatch):
    """`mpmdem reference mpm_bui_implicit` reruns the stored fine explicit runs of every sequence (as the code
    "native", so that `--codes yade` leaves them alone) into their stores; reference.write replaced here by a
    recorder (the real runs: hours on one core)."""
    from validation import suite
    calls = []
    monkeypatch.setattr(REF, "write", lambda h, store=REF.STORE, threads=1, variant="mc", cfl=None:
                        calls.append((h, variant, cfl, store)) or REF.path(h, store))
    suite.regenerate(["mpm_bui_implicit"], ["yade"])
    assert calls == []
    once = [(h, v, c, REF.store_of(v, c)) for v, c in REF.STORED for h in REF.stored_hs(v, c)]
    assert len(once) == 13 and {c for _, _, c, _ in once} == {None, 0.125}
    suite.regenerate(["mpm_bui_implicit"], None)
    assert calls == once
    suite.regenerate(["mpm_bui_implicit"], ["native"])
    assert calls == once * 2


def test_area_and_base_layer_see_points_packed_denser_than_their_volumes():
    """surface_study.area_and_volume / base_layer_density (and their report lines): a deposit of points on a regular
    lattice (spacing h / 2, each carrying (h / 2)^2) encloses its volume (area under the case's surface = sum V to the
    half-point lift) and sits at 1 point volume per unit area in the base layer; the bottom 5 mm squeezed to 80 % of
    their height and the rest moved down by the 1 mm freed, volumes kept: the base layer y < 2.5 mm holds the points
    of the first 3.125 mm, 1 / 0.8, and the area falls short by the squeeze, 1 mm x 0.5 m."""
    from validation.cases.mpm_bui_implicit import surface_study as SS
    h, H = 0.000625, 0.05
    s = 0.5 * h
    X, Y = np.meshgrid(np.arange(0.5 * s, 0.5, s), np.arange(0.5 * s, H, s), indexing="ij")
    x, y = X.ravel(), Y.ravel()
    v = np.full(x.size, s * s)
    (a, vol), = SS.area_and_volume({h: (x, y, v)}).values()
    assert abs(a / vol - 1.0) < 0.01
    assert np.allclose(SS.base_layer_density({h: (x, y, v)})[h], (1.0, 1.0), rtol=5e-4, atol=0)
    assert SS.base_layer_line({h: (x, y, v)}).endswith("0.625 mm 1.000 / 1.000")
    y2 = np.where(y < 0.005, 0.8 * y, y - 0.001)
    assert np.allclose(SS.base_layer_density({h: (x, y2, v)})[h], (1.25, 1.25), rtol=5e-4, atol=0)
    assert SS.base_layer_line({h: (x, y2, v)}).endswith("0.625 mm 1.250 / 1.250")
    (a2, _), = SS.area_and_volume({h: (x, y2, v)}).values()
    assert abs((a - a2) - 0.001 * 0.5) < 0.02 * 0.001 * 0.5
    assert SS.base_layer_density({0.01: (x, y, v)})[0.01] is None
    assert SS.base_layer_line({0.01: (x, y, v)}).endswith("10 mm -")
    assert "0.625 mm " in SS.area_line({h: (x, y, v)})
    # folding: the lattice itself is one-to-one with both J 1; squeezed with the volumes kept, the positions' J is
    # 0.8 in the layer where F's (the volumes') says 1, and nothing is inverted
    n, nt, frac, jp, jf = SS.folding({h: (x, y, v)}, {h: (x, y)})[h]
    assert n == 0 and nt > 0 and frac == 0.0 and abs(jp - 1.0) < 1e-9 and abs(jf - 1.0) < 1e-9
    n, _, frac, jp, jf = SS.folding({h: (x, y2, v)}, {h: (x, y)})[h]
    assert n == 0 and frac == 0.0 and abs(jp - 0.8) < 1e-9 and abs(jf - 1.0) < 1e-9
    assert SS.folding_line({h: (x, y2, v)}, {h: (x, y)}).endswith(f"0.625 mm 0 of {nt} / 0.0%, J 0.800 against 1.000")
    assert SS.folding_line({h: (x, y2, v)}, {}).endswith("no run with seeded centres")
    # a run whose triangles all sit above the layer (centroids y > 2.5 mm): counted, with no layer figures
    up = {h: (x, y + 0.003, v)}
    assert SS.folding_line(up, {h: (x, y)}).endswith(f"0.625 mm 0 of {nt} / no triangle in the layer")


def test_failure_zone_finds_a_known_line_and_width():
    """surface_study.failure_zone on a made-up motion: the seeds right of the line x0 = 0.1 + 0.5 (0.05 - y0) move
    right by a displacement rising linearly from 0 at the line to 20 mm, 8 mm further: |u| passes 1 mm at 0.4 mm
    and 10 mm at 4 mm past the line, so the width is 3.6 mm (to the 0.3125 mm seed spacing) and the line is where
    it was put."""
    from validation.cases.mpm_bui_implicit import surface_study as SS
    h = 0.000625
    s = 0.5 * h
    X, Y = np.meshgrid(np.arange(0.5 * s, 0.2, s), np.arange(0.5 * s, 0.1, s), indexing="ij")
    x0, y0 = X.ravel(), Y.ravel()
    line = 0.1 + 0.5 * (0.05 - y0)
    u = np.clip((x0 - line) / 0.008, 0.0, 1.0) * 0.02
    (rows,) = SS.failure_zone({h: (x0 + u, y0, None)}, {h: (x0, y0)}).values()
    for yv, (xl, w) in zip(SS.ZONE_Y0, rows):
        ys = y0[np.argmin(np.abs(y0 - yv))]
        assert abs(xl - (0.1 + 0.5 * (0.05 - ys) + 0.0004)) <= s
        assert abs(w - 0.0036) <= s
    assert SS.failure_zone_line({h: (x0, y0, None)}, {}).endswith("no run with seeded centres")
    assert "0.625 mm x0 " in SS.failure_zone_line({h: (x0 + u, y0, None)}, {h: (x0, y0)})
