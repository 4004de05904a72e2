"""Write reports/index.html, reports/summary.json and reports/suite.json from a suite result.

The page, top to bottom:
  1. the verdict and a pass/fail matrix of every case against every backend (first screen), each failing cell
     with its reason in one line;
  2. the run: date, machine (host, CPU, cores, OS), Python and library versions, git revision, and the version of
     every reference code (stored runs' provenance.json, installed packages);
  3. one speed-against-error chart of every metric row that records a wall time and a reference;
  4. one section per case: its metric table next to its plots, a failing row's reason in one line.

suite.json keeps everything the page is made from (no live objects), so `render(out_dir)` rebuilds index.html
without rerunning the cases.
"""
from __future__ import annotations

import html
import importlib.metadata
import json
import math
import os
import platform
import shutil
import subprocess
from datetime import datetime, timezone
from pathlib import Path

from coupler import __version__
from validation.references import REFERENCE_DIR, ROOT
from validation.suite import SuiteResult, suite_record

ROW_KEYS = ["case", "backend", "metric", "value", "reference", "tolerance", "passed", "wall_time_s"]
BACKEND_ORDER = ["native", "liggghts", "yade", "kratos"]
LIBRARIES = ["numpy", "scipy", "numba", "pandas", "matplotlib", "meshio", "dask", "distributed"]
REFERENCE_PACKAGES = {"LIGGGHTS": ("dpkg", "liggghts"), "YADE": ("dpkg", "yade"),
                      "Kratos": ("python", "KratosMultiphysics")}


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, bool):
        return "pass" if v else "FAIL"
    if isinstance(v, float):
        return f"{v:.6g}"
    return html.escape(str(v))


def _f(v) -> float:
    return math.nan if v is None else float(v)


def why(row: dict) -> str:
    """One line saying why a metric row failed."""
    v, r, tol, kind = _f(row["value"]), _f(row["reference"]), _f(row["tolerance"]), row.get("kind", "rel")
    note = (row.get("note") or "").strip().splitlines()
    first = note[0] if note else ""
    if kind == "missing" or not math.isfinite(v):
        return first or "no value (comparison could not be made)"
    if kind == "rel":
        s = f"off by {abs(v - r) / abs(r):.3g} relative (tolerance {tol:g})" if r else f"{v:.4g} vs reference 0"
    elif kind == "abs":
        s = f"off by {abs(v - r):.3g} (tolerance {tol:g})"
    else:
        s = f"{v:.4g} above the limit {tol:g}"
    return s + (f"; {first}" if first and len(first) < 120 else "")


# -- the run's provenance -------------------------------------------------------------------------------------------
def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _git_revision() -> str:
    try:
        rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                             text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        branch = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--abbrev-ref", "HEAD"], capture_output=True,
                                text=True, timeout=10).stdout.strip()
        return f"{rev or 'unknown'}{' (uncommitted changes)' if dirty else ''}{f' on {branch}' if branch else ''}"
    except (OSError, subprocess.SubprocessError):
        return "unknown (not a git checkout)"


def reference_code(code: str) -> str:
    """The REFERENCE_PACKAGES key a stored run's provenance `code` belongs to ("Kratos Multiphysics" -> "Kratos",
    "YADE 2023.02a (DEM partition ...) + native MPM" -> "YADE"; also the run folder names provenance() falls back
    on, "kratos", "yade_partition"), so its versions and the installed package share one row; a code that matches
    no key keeps its own name."""
    c = code.lower()
    for key in REFERENCE_PACKAGES:
        k = key.lower()
        if c == k or c.startswith((k + " ", k + "_")):
            return key
    return code


def _installed(kind: str, name: str) -> str:
    if kind == "python":
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            return ""
    if shutil.which("dpkg-query") is None:
        return ""
    try:
        p = subprocess.run(["dpkg-query", "-W", "-f=${Version}", name], capture_output=True, text=True, timeout=10)
        return p.stdout.strip() if p.returncode == 0 else ""
    except (OSError, subprocess.SubprocessError):
        return ""


def provenance(cases: list[str] | None = None) -> dict:
    """Machine, versions and git revision of this run, and the reference codes (stored runs + installed)."""
    libs = {}
    for n in LIBRARIES:
        try:
            libs[n] = importlib.metadata.version(n)
        except importlib.metadata.PackageNotFoundError:
            libs[n] = "not installed"
    stored: dict[str, set] = {}
    if REFERENCE_DIR.exists():
        for p in sorted(REFERENCE_DIR.glob("*/*/*/provenance.json")):
            if cases is not None and p.parts[-4] not in cases:
                continue
            try:
                d = json.loads(p.read_text())
            except (OSError, ValueError):
                continue
            stored.setdefault(reference_code(d.get("code", p.parts[-3])), set()).add(d.get("version", "unknown"))
    refs = {}
    for code, (kind, pkg) in REFERENCE_PACKAGES.items():
        refs[code] = {"stored_runs": sorted(stored.pop(code, set())), "installed": _installed(kind, pkg)}
    for code, vs in stored.items():
        refs[code] = {"stored_runs": sorted(vs), "installed": ""}
    return {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "host": platform.node(),
            "cpu": _cpu_model(), "cores": os.cpu_count(), "os": platform.platform(),
            "python": platform.python_version(), "mpmdem": __version__, "libraries": libs, "git": _git_revision(),
            "reference_codes": refs}


# -- the record the page is made from ------------------------------------------------------------------------------
def write_report(res: SuiteResult | dict, out_dir: Path) -> Path:
    """summary.json, suite.json and index.html of a suite result (or of a record from run_suite_dask)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rec = dict(res) if isinstance(res, dict) else suite_record(res, out_dir)
    rec["provenance"] = provenance([c["name"] for c in rec["cases"]])
    rows = [{k: r[k] for k in ROW_KEYS} | {"kind": r["kind"], "note": r["note"]} for c in rec["cases"]
            for r in c["rows"]]
    (out_dir / "summary.json").write_text(json.dumps(rows, indent=1) + "\n")
    (out_dir / "suite.json").write_text(json.dumps(rec, indent=1) + "\n")
    return render(out_dir, rec)


# -- the page ------------------------------------------------------------------------------------------------------
# Case groups shown as their own section (after the other cases) in the matrix and in the case sections: prefix
# of the case folder name, heading, one line saying what the group is.
GROUPS = (("hard_", "Hard cases (stability)",
           "Where DEM, MPM and coupled codes break (issue #17): extreme speeds, stiffness and mass contrasts, long "
           "runs, step ratios; each case with its result and wall time."),)


def grouped(cases: list[dict]) -> list[tuple[tuple[str, str] | None, list[dict]]]:
    """The cases in report order: the ungrouped ones first (heading None), then each GROUPS section."""
    out = [(None, [c for c in cases if not any(c["name"].startswith(g[0]) for g in GROUPS)])]
    for prefix, head, text in GROUPS:
        sel = [c for c in cases if c["name"].startswith(prefix)]
        if sel:
            out.append(((head, text), sel))
    return out


def _case_passed(c: dict) -> bool:
    return not c["error"] and bool(c["rows"]) and all(r["passed"] for r in c["rows"])


def speed_error_chart(rec: dict, out_dir: Path) -> Path | None:
    """Wall time against relative error |value - reference| / |reference| of every row that records both."""
    pts = []
    for c in rec["cases"]:
        for r in c["rows"]:
            v, ref, w = _f(r["value"]), _f(r["reference"]), _f(r["wall_time_s"])
            if r.get("kind") in ("rel", "abs") and all(map(math.isfinite, (v, ref, w))) and ref != 0.0 and w > 0:
                pts.append((c["name"], r["backend"], w, max(abs(v - ref) / abs(ref), 1e-16), bool(r["passed"])))
    if not pts:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cases = sorted({p[0] for p in pts})
    markers = "osD^v<>phX*"
    cmap = plt.get_cmap("tab10")
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for k, case in enumerate(cases):
        for ok in (True, False):
            sel = [p for p in pts if p[0] == case and p[4] == ok]
            if sel:
                ax.scatter([p[2] for p in sel], [p[3] for p in sel], marker=markers[k % len(markers)],
                           s=36, facecolors=cmap(k % 10) if ok else "none", edgecolors=cmap(k % 10),
                           linewidths=1.4, label=case if ok or not any(p[4] for p in pts if p[0] == case) else None)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time of the run behind the metric [s]")
    ax.set_ylabel("|value − reference| / |reference|")
    ax.set_title("Speed against error, every metric with a wall time (hollow = failed)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best", ncol=2)
    p = out_dir / "speed_error.png"
    fig.savefig(p, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return p


CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:1.2em 2em;color:#222}
h1{font-size:22px;margin:.2em 0} h2{font-size:17px;margin:1.4em 0 .4em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;margin:.4em 0} td,th{border:1px solid #ccc;padding:2px 7px;font-size:13px}
th{background:#f3f3f3;text-align:left} .pass{background:#e3f4e3} .fail{background:#f9dada} .none{color:#999}
.verdict{font-size:18px;padding:.3em .6em;display:inline-block;border-radius:4px}
.why{font-size:12px;color:#8a1c1c} .note{color:#555;font-size:12px} .small{font-size:12px;color:#444}
.case{display:flex;flex-wrap:wrap;gap:1.2em;align-items:flex-start} .case>div{flex:1 1 560px;min-width:0}
.case img{max-width:100%;border:1px solid #ddd} pre.note{white-space:pre-wrap;margin:.2em 0}
.cols{display:flex;flex-wrap:wrap;gap:2em;align-items:flex-start}
"""


def _matrix(rec: dict) -> list[str]:
    backends = sorted({r["backend"] for c in rec["cases"] for r in c["rows"]},
                      key=lambda b: (BACKEND_ORDER.index(b) if b in BACKEND_ORDER else 99, b))
    out = ["<table><tr><th>case</th>" + "".join(f"<th>{html.escape(b)}</th>" for b in backends) +
           "<th>why it fails (first failing metric)</th><th>time [s]</th></tr>"]
    for group, cases in grouped(rec["cases"]):
        if group is not None:       # a section row: the group's heading and how many of its cases pass
            out.append(f"<tr><th colspan='{len(backends) + 3}'><a href='#{html.escape(group[0].split()[0].lower())}'>"
                       f"{html.escape(group[0])}</a>: {sum(map(_case_passed, cases))} of {len(cases)} pass, "
                       f"{sum(c['wall_time_s'] for c in cases):.0f} s</th></tr>")
        for c in cases:
            ok = _case_passed(c)
            cells = []
            for b in backends:
                rs = [r for r in c["rows"] if r["backend"] == b]
                if not rs:
                    cells.append("<td class='none'>–</td>")
                    continue
                nf = sum(not r["passed"] for r in rs)
                cls, txt = ("pass", f"✓ {len(rs)}") if nf == 0 else ("fail", f"✗ {nf} of {len(rs)}")
                cells.append(f"<td class='{cls}'>{txt}</td>")
            bad = [r for r in c["rows"] if not r["passed"]]
            reason = ""
            if c["error"]:
                reason = "case crashed: " + c["error"].splitlines()[0][:160]
            elif bad:
                r = bad[0]
                reason = f"{r['backend']} · {r['metric']}: {why(r)}" + (f" (+{len(bad) - 1} more)" if len(bad) > 1 else "")
            elif not c["rows"]:
                reason = "no metrics recorded"
            out.append(f"<tr><td class='{'pass' if ok else 'fail'}'><a href='#{html.escape(c['name'])}'>"
                       f"{html.escape(c['name'])}</a></td>" + "".join(cells) +
                       f"<td class='why'>{html.escape(reason)}</td><td>{c['wall_time_s']:.1f}</td></tr>")
    out.append("</table>")
    return out


def _provenance_html(p: dict, rec: dict) -> list[str]:
    refs = "".join(
        f"<tr><td>{html.escape(code)}</td><td>{html.escape(', '.join(d['stored_runs']) or '–')}</td>"
        f"<td>{html.escape(d['installed'] or 'not installed')}</td></tr>" for code, d in p["reference_codes"].items())
    libs = ", ".join(f"{k} {v}" for k, v in p["libraries"].items())
    mode = (f"{'full' if rec['full'] else 'default'} studies; reference codes "
            f"{'rerun live' if rec['live'] else 'from the stored runs in reference_runs/'}")
    return ["<div class='cols'><table>",
            f"<tr><th>git revision</th><td>{html.escape(p['git'])}</td></tr>",
            f"<tr><th>date (UTC)</th><td>{html.escape(p['date'])}</td></tr>",
            f"<tr><th>machine</th><td>{html.escape(p['host'])}: {html.escape(p['cpu'])}, {p['cores']} cores, "
            f"{html.escape(p['os'])}</td></tr>",
            f"<tr><th>software</th><td>mpmdem {html.escape(p['mpmdem'])}, Python {html.escape(p['python'])}; "
            f"{html.escape(libs)}</td></tr>",
            f"<tr><th>mode</th><td>{html.escape(mode)}</td></tr></table>",
            "<table><tr><th>reference code</th><th>version of the stored runs used</th><th>installed here</th></tr>"
            + refs + "</table></div>"]


def render(out_dir: Path, rec: dict | None = None) -> Path:
    """index.html from suite.json (or the given record)."""
    out_dir = Path(out_dir)
    if rec is None:
        rec = json.loads((out_dir / "suite.json").read_text())
    p = rec["provenance"]
    n_pass = sum(_case_passed(c) for c in rec["cases"])
    n = len(rec["cases"])
    allok = n_pass == n
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>mpmdem validation</title>",
             f"<style>{CSS}</style></head><body>",
             f"<h1>mpmdem {html.escape(p['mpmdem'])} validation report</h1>",
             f"<p><span class='verdict {'pass' if allok else 'fail'}'><b>{n_pass} of {n} cases pass</b></span> "
             f"<span class='small'>&nbsp;git {html.escape(p['git'])} · {html.escape(p['date'])} · "
             f"{html.escape(p['host'])} ({p['cores']} cores)</span></p>"]
    parts += _matrix(rec)
    parts.append("<p class='small'>Cell: metrics compared for that backend (✓ all pass, ✗ failed of total). "
                 "rel = |value−reference|/|reference| ≤ tol; abs = |value−reference| ≤ tol; max = value ≤ tol; "
                 "missing = comparison could not be made (a failure).</p>")
    if rec["skipped"]:
        parts.append("<p class='small'>Not run in this mode: " + ", ".join(
            f"{html.escape(a)} ({html.escape(b)})" for a, b in rec["skipped"]) + "</p>")
    parts.append("<h2>Run</h2>")
    parts += _provenance_html(p, rec)
    chart = speed_error_chart(rec, out_dir)
    if chart is not None:
        parts.append("<h2>Speed against error</h2><p class='small'>Every metric row that records the wall time of "
                     "the run behind it and a nonzero reference, all cases and backends.</p>"
                     f"<img src='{html.escape(chart.name)}' alt='speed against error' style='max-width:760px'>")
    for group, cases in grouped(rec["cases"]):
        if group is not None:
            parts.append(f"<h1 id='{html.escape(group[0].split()[0].lower())}'>{html.escape(group[0])}</h1>"
                         f"<p class='small'>{html.escape(group[1])}</p>")
        parts += [part for c in cases for part in _case_section(c)]
    parts.append("</body></html>")
    index = out_dir / "index.html"
    index.write_text("\n".join(parts))
    return index


def _case_section(c: dict) -> list[str]:
    """One case: heading with verdict and wall time, metric table, notes, docstring, plots."""
    parts = []
    ok = _case_passed(c)
    parts.append(f"<h2 id='{html.escape(c['name'])}'>{html.escape(c['name'])}: {html.escape(c['title'])} "
                 f"<span class='verdict {'pass' if ok else 'fail'}' style='font-size:13px'>"
                 f"{'pass' if ok else 'FAIL'}</span> <span class='small'>{c['wall_time_s']:.1f} s</span></h2>")
    if c["error"]:
        parts.append(f"<p class='fail'>Case crashed: {html.escape(c['error'])} "
                     f"(traceback: <a href='cases/{html.escape(c['name'])}/error.txt'>error.txt</a>)</p>")
    parts.append("<div class='case'><div>")
    parts.append("<table><tr>" + "".join(f"<th>{k}</th>" for k in
                                         ["backend", "metric", "value", "reference", "tol", "kind", "",
                                          "wall [s]"]) + "</tr>")
    for r in c["rows"]:
        cls = "pass" if r["passed"] else "fail"
        parts.append(f"<tr class='{cls}'>" + "".join(
            f"<td>{_fmt(v)}</td>" for v in (r["backend"], r["metric"], _f(r["value"]), _f(r["reference"]),
                                            _f(r["tolerance"]), r["kind"], r["passed"], _f(r["wall_time_s"])))
            + "</tr>")
        if not r["passed"]:
            parts.append(f"<tr class='fail'><td></td><td colspan='7' class='why'>why: "
                         f"{html.escape(why(r))}</td></tr>")
        elif r.get("note"):
            parts.append(f"<tr><td></td><td colspan='7' class='note'>{html.escape(r['note'])}</td></tr>")
    parts.append("</table>")
    for note in c["notes"]:
        parts.append(f"<p class='note'>{html.escape(note)}</p>")
    if c["doc"]:
        parts.append(f"<details><summary class='small'>about this case</summary>"
                     f"<pre class='note'>{html.escape(c['doc'])}</pre></details>")
    parts.append("</div><div>")
    for rel in c["plots"]:
        parts.append(f"<p><img src='{html.escape(rel)}' alt='{html.escape(Path(rel).name)}'></p>")
    parts.append("</div></div>")
    return parts
