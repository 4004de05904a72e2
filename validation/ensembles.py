"""Ensembles instead of single runs (issue 15): a chaotic run (a wall collapse grain by grain) is compared between
codes by the statistics of N runs of the same scene, so that a comparison fails for a real difference and not by
the chance of one trajectory.

Members. `seeds_or_perturbations(scene_text, n, kind)` returns n scene texts, member 0 the scene as written:
  kind = "seed": every `seed = <int>` of the scene (the top-level seed and the seeds of `[[dem.packings]]`,
         `[[mpm.*]]` or any other table) is replaced by seed + SEED_STRIDE * m in member m: new random packings of the
         same geometry and counts, i.e. the scatter of a repeated experiment with a freshly poured backfill;
  kind = "dt":   `[time] dt` becomes dt * (1 - rel * m) in member m (downwards, so no member exceeds the stable
         step): one initial state, perturbed only through the round-off and the step size, i.e. the chaos of the
         integration alone.
The texts are edited line by line (comments, order and every other value kept byte for byte), so the scene hash of
each member is reproducible.

Comparison. `compare_ensembles(a, b, columns, z_max=2.0)`: a and b hold one row per run (e.g. columns
x_final_block1, rot_final_block1, ...). Per column, with NaN rows dropped:
  mean_a, mean_b            sample means
  std_a, std_b              sample standard deviations (ddof = 1; NaN for fewer than 2 runs: unknown spread)
  n_a, n_b                  numbers of runs
  diff   = mean_a - mean_b
  pooled = sqrt(std_a^2 / n_a + std_b^2 / n_b)      the standard error of the difference of the means (Welch)
  z      = |diff| / pooled                           (inf if pooled = 0 and diff != 0; 0 if both are 0)
  passed = z <= z_max
For independent runs with equal expectations z is approximately |N(0, 1)| distributed for large n (Student-t with
the Welch degrees of freedom for small n), so z_max = 2 fails a correct comparison by chance in about 5 % of the
columns at large n (more at n = 8: t with ~14 dof, P(|t| > 2) = 6.5 %). A pass says the ensembles cannot be told apart
at this n, not that they are equal: the resolution of the test is ~ z_max * pooled, which each row reports.
With 2 runs a side's std rests on one degree of freedom and can be far too small by chance (two members that
happen to agree), which inflates z: give each side enough runs (coupled_flow_blocks runs 8 per code for this
reason; its two-member default failed rot_max_block1 with z = 4.83, 0.80 with all 8).
"""
from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd

SEED_STRIDE = 1000          # member m adds m * SEED_STRIDE to every seed of the scene

_TABLE = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_.\-\" ]+?)\s*\]\]?\s*(#.*)?$")
_SEED = re.compile(r"^(\s*seed\s*=\s*)(\d+)(\s*(#.*)?)$")
_DT = re.compile(r"^(\s*dt\s*=\s*)([-+0-9.eE_]+)(\s*(#.*)?)$")


def seeds_or_perturbations(scene_text: str, n: int, kind: str = "seed", rel: float = 1e-3) -> list[str]:
    """n scene texts (member 0 = scene_text unchanged). kind "seed": every `seed = k` becomes k + SEED_STRIDE * m;
    kind "dt": `[time] dt` becomes dt * (1 - rel * m). ValueError when the scene has nothing to vary (no seed line /
    no [time] dt), when n < 1, or when a dt would not stay positive."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if kind not in ("seed", "dt"):
        raise ValueError(f'kind must be "seed" or "dt", got {kind!r}')
    lines = scene_text.splitlines(keepends=True)
    table = ""
    targets = []                                    # (line index, match) of the values to vary
    for k, line in enumerate(lines):
        body = line.rstrip("\r\n")
        mt = _TABLE.match(body)
        if mt and not body.lstrip().startswith(("seed", "dt")):
            table = mt.group(1).strip()
            continue
        if kind == "seed":
            m = _SEED.match(body)
            if m:
                targets.append((k, m))
        elif table == "time":
            m = _DT.match(body)
            if m:
                targets.append((k, m))
    if not targets:
        raise ValueError("the scene has no `seed = <int>` line to vary" if kind == "seed" else
                         "the scene has no [time] dt to perturb (give dt explicitly)")
    if kind == "dt" and not (0.0 < rel * (n - 1) < 1.0 or n == 1):
        raise ValueError(f"rel * (n - 1) must lie in (0, 1) so every dt stays positive, got {rel * (n - 1):g}")
    out = []
    for member in range(n):
        if member == 0:
            out.append(scene_text)
            continue
        new = list(lines)
        for k, m in targets:
            end = lines[k][len(lines[k].rstrip("\r\n")):]
            if kind == "seed":
                value = str(int(m.group(2)) + SEED_STRIDE * member)
            else:
                value = repr(float(m.group(2)) * (1.0 - rel * member))
            new[k] = m.group(1) + value + m.group(3) + end
        out.append("".join(new))
    return out


def compare_ensembles(a: pd.DataFrame, b: pd.DataFrame, columns, *, z_max: float = 2.0) -> list[dict]:
    """Per column: mean_a, mean_b, std_a, std_b (ddof 1), n_a, n_b, diff = mean_a - mean_b, pooled = sqrt(std_a^2/n_a
    + std_b^2/n_b), z = |diff| / pooled, passed = z <= z_max (module docstring). Rows with NaN in a column are left
    out of that column (n counts the runs used); a side with fewer than 2 runs has no spread estimate: std, pooled
    and z are NaN and the column does not pass."""
    if not (z_max > 0.0):
        raise ValueError(f"z_max must be > 0, got {z_max}")
    rows = []
    for col in columns:
        xa = a[col].to_numpy(float)
        xb = b[col].to_numpy(float)
        xa, xb = xa[np.isfinite(xa)], xb[np.isfinite(xb)]
        na, nb = len(xa), len(xb)
        ma = float(xa.mean()) if na else math.nan
        mb = float(xb.mean()) if nb else math.nan
        sa = float(xa.std(ddof=1)) if na > 1 else math.nan
        sb = float(xb.std(ddof=1)) if nb > 1 else math.nan
        diff = ma - mb
        pooled = math.sqrt(sa * sa / na + sb * sb / nb) if na > 1 and nb > 1 else math.nan
        if not (na > 1 and nb > 1):
            z = math.nan
        elif pooled > 0.0:
            z = abs(diff) / pooled
        else:
            z = 0.0 if diff == 0.0 else math.inf
        rows.append({"column": col, "mean_a": ma, "mean_b": mb, "std_a": sa, "std_b": sb, "n_a": na, "n_b": nb,
                     "diff": diff, "pooled": pooled, "z": z, "passed": bool(z <= z_max)})
    return rows
