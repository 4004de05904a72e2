"""Write reports/index.html and reports/summary.json from a suite result."""
from __future__ import annotations

import html
import json
import math
import os
import platform
from datetime import datetime, timezone
from pathlib import Path

from coupler import __version__
from validation.suite import SuiteResult

ROW_KEYS = ["case", "backend", "metric", "value", "reference", "tolerance", "passed", "wall_time_s"]


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, bool):
        return "pass" if v else "FAIL"
    if isinstance(v, float):
        return f"{v:.6g}"
    return html.escape(str(v))


def write_report(res: SuiteResult, out_dir: Path) -> Path:
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for r in res.rows:
        d = r.as_dict()
        rows.append({k: d[k] for k in ROW_KEYS} | {"kind": d["kind"], "note": d["note"]})
    (out_dir / "summary.json").write_text(json.dumps(rows, indent=1) + "\n")

    n_pass = sum(c.passed for c in res.cases)
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>mpmdem validation</title><style>",
        "body{font-family:sans-serif;margin:2em;max-width:1200px} table{border-collapse:collapse;margin:1em 0}",
        "td,th{border:1px solid #ccc;padding:3px 8px;font-size:13px} .pass{background:#e6f6e6}",
        ".fail{background:#fbe3e3} img{max-width:900px;border:1px solid #ddd} .note{color:#555;font-size:12px}",
        "</style></head><body>",
        f"<h1>mpmdem {__version__} validation report</h1>",
        f"<p>{datetime.now(timezone.utc).isoformat(timespec='seconds')} on {html.escape(platform.node())} "
        f"({os.cpu_count()} cores, Python {platform.python_version()}). "
        f"Mode: {'full' if res.full else 'default'} studies, reference codes "
        f"{'rerun live' if res.live else 'from stored reference_runs/'}.</p>",
        f"<p><b>{n_pass} of {len(res.cases)} cases pass.</b> Tolerance kinds: rel = |value−reference|/|reference| ≤ tol; "
        "abs = |value−reference| ≤ tol; max = value ≤ tol; missing = comparison could not be made (a failure).</p>",
    ]
    if res.skipped:
        parts.append("<p>Not run in this mode: " + ", ".join(f"{html.escape(n)} ({html.escape(w)})"
                                                            for n, w in res.skipped) + "</p>")
    parts.append("<h2>Summary</h2><table><tr><th>case</th><th>title</th><th>metrics</th><th>failed</th>"
                 "<th>wall time [s]</th><th>status</th></tr>")
    for c in res.cases:
        nf = sum(not r.passed for r in c.ctx.rows)
        cls = "pass" if c.passed else "fail"
        parts.append(f"<tr class='{cls}'><td><a href='#{c.info.name}'>{c.info.name}</a></td>"
                     f"<td>{html.escape(c.info.title)}</td><td>{len(c.ctx.rows)}</td><td>{nf}</td>"
                     f"<td>{c.wall_time_s:.1f}</td><td>{'pass' if c.passed else 'FAIL'}</td></tr>")
    parts.append("</table>")
    for c in res.cases:
        parts.append(f"<h2 id='{c.info.name}'>{c.info.name}: {html.escape(c.info.title)}</h2>")
        doc = (c.info.module.__doc__ or "").strip()
        if doc:
            parts.append(f"<pre class='note'>{html.escape(doc)}</pre>")
        if c.error:
            parts.append(f"<p class='fail'>Case crashed: {html.escape(c.error)}</p>")
        parts.append("<table><tr>" + "".join(f"<th>{k}</th>" for k in
                                             ["backend", "metric", "value", "reference", "tolerance", "kind",
                                              "passed", "wall_time_s", "note"]) + "</tr>")
        for r in c.ctx.rows:
            cls = "pass" if r.passed else "fail"
            parts.append(f"<tr class='{cls}'>" + "".join(
                f"<td>{_fmt(v)}</td>" for v in (r.backend, r.metric, r.value, r.reference, r.tolerance, r.kind,
                                                r.passed, r.wall_time_s)) + f"<td class='note'>{html.escape(r.note)}</td></tr>")
        parts.append("</table>")
        for n in c.ctx.notes:
            parts.append(f"<p class='note'>{html.escape(n)}</p>")
        for p in c.ctx.plots:
            rel = os.path.relpath(p, out_dir)
            parts.append(f"<p><img src='{html.escape(rel)}' alt='{html.escape(p.name)}'></p>")
    parts.append("</body></html>")
    index = out_dir / "index.html"
    index.write_text("\n".join(parts))
    return index
