"""results.frame_csv, the fast CSV writer of the result tables: the same characters as pandas'
to_csv(index=False, float_format=...) on random frames (floats with -0, infinities, subnormals and huge values,
integers, names; NaN, booleans and strings the csv module quotes go to pandas itself), with and without the header,
for the two float formats the tables use; and on a real MPM snapshot."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st

from coupler.results import frame_csv

FLOATS = st.one_of(st.floats(allow_nan=False, width=64), st.sampled_from([0.0, -0.0, 5e-324, -1e308, 1e16, 0.1]))
NAMES = st.text(alphabet="abcAB_0 ,\"-", min_size=0, max_size=4)


@st.composite
def frames(draw):
    n = draw(st.integers(0, 6))
    cols = {}
    for k in range(draw(st.integers(1, 5))):
        kind = draw(st.sampled_from(["f", "f", "i", "s", "nan", "b", "f32"]))
        if kind == "f":
            cols[f"c{k}"] = np.array(draw(st.lists(FLOATS, min_size=n, max_size=n)), float)
        elif kind == "f32":
            cols[f"c{k}"] = np.array(draw(st.lists(st.floats(-1e6, 1e6, width=32), min_size=n, max_size=n)),
                                     np.float32)
        elif kind == "nan":
            cols[f"c{k}"] = np.array(draw(st.lists(st.sampled_from([1.5, math.nan]), min_size=n, max_size=n)))
        elif kind == "i":
            cols[f"c{k}"] = np.array(draw(st.lists(st.integers(-2 ** 62, 2 ** 62), min_size=n, max_size=n)),
                                     np.int64)
        elif kind == "b":
            cols[f"c{k}"] = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)), bool)
        else:
            cols[f"c{k}"] = np.array(draw(st.lists(NAMES, min_size=n, max_size=n)), dtype=object)
    return pd.DataFrame(cols)


@settings(max_examples=400, deadline=None)
@given(frames(), st.sampled_from(["%.10g", "%.12g"]), st.booleans())
def test_same_characters_as_pandas(df, fmt, header):
    assert frame_csv(df, fmt, header) == df.to_csv(index=False, float_format=fmt, header=header)


def test_a_snapshot_takes_the_fast_path_and_matches(monkeypatch):
    """A material-point snapshot (float, integer and body-name columns) is written without pandas, the same."""
    n = 1000
    rng = np.random.default_rng(3)
    df = pd.DataFrame({"t": np.full(n, 0.05), "id": np.arange(n), "body": np.full(n, "soil", dtype=object),
                       **{c: rng.normal(size=n) * 10.0 ** rng.integers(-12, 6, n) for c in ("x", "y", "sxx", "ux")}})
    want = df.to_csv(index=False, float_format="%.10g")
    monkeypatch.setattr(pd.DataFrame, "to_csv", lambda *a, **k: pytest.fail("fell back to pandas"))
    assert frame_csv(df, "%.10g") == want


def test_chunked_rows_and_the_file_writer(tmp_path, monkeypatch):
    """More rows than one chunk (CSV_CHUNK_ROWS set small): the same characters, and write_csv's file the same bytes
    as pandas' to_csv to a path."""
    import coupler.results as R
    monkeypatch.setattr(R, "CSV_CHUNK_ROWS", 7)
    rng = np.random.default_rng(5)
    n = 52
    df = pd.DataFrame({"t": np.full(n, 0.1), "id": np.arange(n), "body": np.full(n, "b1", dtype=object),
                       "x": rng.normal(size=n)})
    assert frame_csv(df, "%.10g") == df.to_csv(index=False, float_format="%.10g")
    R.write_csv(tmp_path / "a.csv", df, "%.10g")
    df.to_csv(tmp_path / "b.csv", index=False, float_format="%.10g")
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    df.loc[3, "x"] = np.nan                      # the pandas path of write_csv
    R.write_csv(tmp_path / "c.csv", df, "%.10g")
    df.to_csv(tmp_path / "d.csv", index=False, float_format="%.10g")
    assert (tmp_path / "c.csv").read_bytes() == (tmp_path / "d.csv").read_bytes()
