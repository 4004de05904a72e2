"""`mpmdem` command line: run a scene, validate, bench, regenerate reference runs."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from coupler.errors import BackendUnavailable, ReferenceCodeError, SceneError, SimulationError
from coupler.run import BACKENDS

ROOT = Path(__file__).resolve().parent.parent


def _run(args) -> int:
    from coupler.checkpoint import Restart
    from coupler.run import run_scene
    from coupler.scene import load_scene
    scene = load_scene(args.scene)
    if args.threads is not None:
        set_threads(args.threads, args.backend)
    out = Path(args.out) if args.out else Path("out") / f"{scene.name}_{args.backend}"
    try:
        res = run_scene(scene, out, backend=args.backend, progress=not args.quiet,
                        restart=Restart(every=args.checkpoint_every, resume=args.resume), keep_tables=False)
    except SimulationError as e:
        if _stopped_run(out):          # a streamed run (coupler/results.py ResultStream) kept its tables
            e.args = (f"{e}; the tables up to the last output time are in {out}",)
        raise
    s = res.summary
    print(f"{scene.name} [{args.backend}]: {s['steps']} steps, dt {s['dt']:.3g} s, {s['particles']} particles, "
          f"{s['wall_time_s']:.2f} s wall -> {out}")
    sys.stdout.flush()
    for line in drop_warnings(s):
        print(f"warning: {line}", file=sys.stderr)
    return 0


def drop_warnings(summary: dict) -> list[str]:
    """One line per kind of thing a run had to drop and counted in summary.json (before the thirty-sixth session
    the counts were there only): mesh contacts beyond the feature buffer or the history slots (their force not
    applied) and contact rows beyond the output buffer; MPM point loads dropped on an empty support; boundary
    particles stranded without grid mass."""
    lines = []
    for mesh, d in (summary.get("mesh_contacts_dropped") or {}).items():
        if mesh == "total" or not isinstance(d, dict):
            continue
        forces = d.get("features_beyond_buffer", 0) + d.get("contacts_beyond_slots", 0)
        if forces:
            lines.append(f"mesh {mesh!r}: {forces} sphere-mesh contacts dropped, their force not applied "
                         f"({d.get('features_beyond_buffer', 0)} beyond the feature buffer, "
                         f"{d.get('contacts_beyond_slots', 0)} beyond the history slots; summary.json "
                         "mesh_contacts_dropped)")
        if d.get("rows_beyond_buffer", 0):
            lines.append(f"mesh {mesh!r}: {d['rows_beyond_buffer']} contact rows left out of contacts.csv "
                         "(output buffer; the forces were applied)")
    mpm = [(summary, "mpm_dropped_point_loads", "mpm_stranded_boundary_particles"),
           (summary.get("coupling") or {}, "mpm_dropped_loads", "mpm_stranded_boundary_particles")]
    for where, dropped, stranded in mpm:
        d = where.get(dropped) or {}
        if d.get("count", 0):
            lines.append(f"{d['count']} MPM point loads dropped on supports without grid mass (impulse "
                         f"{d.get('impulse_dropped', 0.0):.3g} of {d.get('impulse_applied', 0.0):.3g} applied; "
                         f"summary.json {dropped})")
        st = where.get(stranded) or {}
        if st.get("particle_steps", 0):
            lines.append(f"MPM boundary particles stranded without grid mass: {st['particle_steps']} particle-steps, "
                         f"at most {st.get('max_at_once', 0)} at once (summary.json {stranded})")
    return lines


def set_threads(n: int, backend: str) -> None:
    """`mpmdem run --threads N`: the native solvers' thread count (numba; results are the same bits for any count).
    SceneError (exit 2) outside 1 .. NUMBA_NUM_THREADS (the most numba was started with: the machine's cores unless
    the environment sets it) or with a reference backend (their adapters run the codes on one core,
    OMP_NUM_THREADS = 1, so that their timings compare)."""
    import numba
    most = numba.config.NUMBA_NUM_THREADS
    if backend != "native":
        raise SceneError("--threads", f"sets the native solvers' threads; --backend {backend} runs on one core")
    if not 1 <= n <= most:
        raise SceneError("--threads", f"must be between 1 and {most} (NUMBA_NUM_THREADS), got {n}")
    numba.set_num_threads(n)


def _stopped_run(out: Path) -> bool:
    try:
        return json.loads((out / "summary.json").read_text()).get("status") == "stopped"
    except (OSError, ValueError):
        return False


def _validate(args) -> int:
    from validation import golden
    from validation.report import write_report
    from validation.suite import run_suite
    out = Path(args.out)
    regress = getattr(args, "regress", False)
    update = getattr(args, "update_golden", False)
    only = args.cases or (list(golden.QUICK_CASES) if (regress or update) and not args.cases_dir else None)
    cases_dir = Path(args.cases_dir) if args.cases_dir else None
    if args.workers is not None and args.scheduler:
        raise SceneError("--workers", "give either --workers N or --scheduler ADDRESS, not both")
    if args.workers is not None and args.workers < 1:
        raise SceneError("--workers", f"must be >= 1, got {args.workers}")
    if args.workers or args.scheduler:           # each case a dask task (same code path per case as serial)
        from validation.suite import run_suite_dask
        rec = run_suite_dask(out, full=args.full, live=args.live, only=only, workers=args.workers,
                             scheduler=args.scheduler, cases_dir=cases_dir)
    else:
        from validation.suite import suite_record
        rec = suite_record(run_suite(out, full=args.full, live=args.live, only=only, cases_dir=cases_dir), out)
    index = write_report(rec, out)
    rows = golden.rows_from_dicts(r for c in rec["cases"] for r in c["rows"])
    n_pass = sum(not c["error"] and bool(c["rows"]) and all(r["passed"] for r in c["rows"]) for c in rec["cases"])
    print(f"report: {index}  ({n_pass} of {len(rec['cases'])} cases pass)")
    gpath = Path(args.golden)
    if update:
        golden.update(golden.metric_values(rows), gpath)
        print(f"golden: rewrote {len(rec['cases'])} case(s) in {gpath}; say why in the commit that changes it")
        return 0
    if regress:
        ok, table = golden.check(rows, gpath)
        print(table)
        return 0 if ok else 5         # the regression verdict, not the validation verdict (known failures stay)
    return 0 if n_pass == len(rec["cases"]) else 1


def _vtk(args) -> int:
    from coupler.results import Result
    from coupler.scene import load_scene
    from coupler.vtk import write_vtk
    written = write_vtk(Result.read(args.run_dir), args.run_dir, load_scene(args.scene))
    print(f"vtk: {', '.join(sorted(written)) or 'nothing to write'} -> {Path(args.run_dir) / 'vtk'}")
    return 0


def _report(args) -> int:
    from validation.report import render
    print(f"report: {render(Path(args.dir))}")
    return 0


def _regress(args) -> int:
    args.regress, args.update_golden, args.full = True, False, False
    return _validate(args)


def _sweep(args) -> int:
    from coupler.sweep import METRICS, parse_vary, sweep
    if args.workers is not None and args.scheduler:
        raise SceneError("--workers", "give either --workers N or --scheduler ADDRESS, not both")
    df = sweep(args.scene, [parse_vary(v) for v in args.vary], args.out, seeds=args.seeds, backend=args.backend,
               metrics=tuple(args.metric or ("energy_final", "max_fn")), workers=args.workers,
               scheduler=args.scheduler, progress=not args.quiet)
    n_fail = int((df["status"] != "done").sum())
    print(f"sweep: {len(df)} runs ({n_fail} failed) -> {Path(args.out) / 'sweep.csv'}")
    return 0 if n_fail == 0 else 3


def _bench(args) -> int:
    from coupler.bench import print_bench, run_bench
    res = run_bench(Path(args.out), quick=args.quick)
    print_bench(res)
    if res.get("failures"):            # a crashed sub-bench fails the bench (a missing reference code does not)
        print(f"bench failed: {', '.join(res['failures'])} (errors in bench.json)", file=sys.stderr)
        return 1
    return 0


def _reference(args) -> int:
    from validation.suite import regenerate
    regenerate(args.cases or None, args.codes.split(",") if args.codes else None,
               args.variants.split(",") if args.variants else None)
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="mpmdem", description="Partitioned MPM-DEM coupler and its validation harness")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run one scene file")
    r.add_argument("scene")
    r.add_argument("--backend", default="native", choices=list(BACKENDS))
    r.add_argument("--out", default=None, help="output folder (default out/<scene>_<backend>)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--threads", type=int, default=None, metavar="N",
                   help="native backend: threads of the solvers (default: NUMBA_NUM_THREADS, all cores; the same "
                        "results for any N)")
    r.add_argument("--checkpoint-every", type=int, default=0, metavar="N",
                   help="native backend: write <out>/checkpoint.pkl every N output times (0: none)")
    r.add_argument("--resume", action="store_true",
                   help="native backend: continue from <out>/checkpoint.pkl (the same scene and code)")
    r.set_defaults(fn=_run)
    v = sub.add_parser("validate", help="run the validation cases and write the report")
    v.add_argument("--full", action="store_true", help="also run the long studies (finest resolutions)")
    v.add_argument("--live", action="store_true", help="rerun LIGGGHTS/YADE instead of using stored reference runs")
    v.add_argument("--out", default=str(ROOT / "reports"))
    v.add_argument("--regress", action="store_true",
                   help="compare every metric with validation/golden.json (default cases: the quick CI subset); "
                        "exit 5 with a table of what moved")
    v.add_argument("--update-golden", action="store_true",
                   help="rewrite validation/golden.json for the cases run (default: the quick CI subset)")
    v.add_argument("cases", nargs="*", help="only these cases (folder names under validation/cases)")
    v.set_defaults(fn=_validate)
    g = sub.add_parser("regress", help="CI regression: run the quick case subset, compare with validation/golden.json")
    g.add_argument("--live", action="store_true", help="rerun LIGGGHTS/YADE instead of using stored reference runs")
    g.add_argument("--out", default="/tmp/mpmdem-regress")
    g.add_argument("cases", nargs="*", help="only these cases (default: validation.golden.QUICK_CASES)")
    g.set_defaults(fn=_regress)
    k = sub.add_parser("vtk", help="write the ParaView series of an existing run folder (any backend, stored runs)")
    k.add_argument("scene", help="the scene file the run was made from (radius, materials, walls)")
    k.add_argument("run_dir", help="folder with bodies.csv / contacts.csv (.gz) / summary.json")
    k.set_defaults(fn=_vtk)
    rp = sub.add_parser("report", help="rebuild index.html of a validate output folder from its suite.json")
    rp.add_argument("dir", nargs="?", default=str(ROOT / "reports"))
    rp.set_defaults(fn=_report)
    for q in (v, g):
        q.add_argument("--workers", type=int, default=None, help="run the cases on a dask LocalCluster of N processes")
        q.add_argument("--scheduler", default=None, help="run the cases on the dask cluster at this address")
        q.add_argument("--golden", default=str(ROOT / "validation" / "golden.json"), help="golden metrics file")
        q.add_argument("--cases-dir", default=None, help="folder of case folders (default validation/cases)")
    w = sub.add_parser("sweep", help="run the product of scene variants (and seeds) through dask, one table")
    w.add_argument("scene")
    w.add_argument("--vary", action="append", default=[], metavar="FIELD=V1,V2,...",
                   help='dotted scene path and TOML values, e.g. "contacts[0].restitution=0.5,0.8" (repeatable)')
    w.add_argument("--seeds", type=int, default=None, help="ensemble: seed = scene seed + 0..N-1 for every variant")
    w.add_argument("--backend", default="native", choices=list(BACKENDS))
    w.add_argument("--metric", action="append", default=None,
                   help="metric columns (repeatable): energy_final, max_fn, n_contacts_final, bodies_final "
                        "(default energy_final, max_fn)")
    w.add_argument("--workers", type=int, default=None, help="a dask LocalCluster of N worker processes")
    w.add_argument("--scheduler", default=None, help="address of an existing dask scheduler (shared file system)")
    w.add_argument("--out", required=True, help="sweep folder: runs/<id>/ and sweep.csv (resumable)")
    w.add_argument("--quiet", action="store_true")
    w.set_defaults(fn=_sweep)
    b = sub.add_parser("bench", help="throughput benchmarks against the reference codes")
    b.add_argument("--quick", action="store_true", help="fewer steps, no YADE / cluster / MPM runs")
    b.add_argument("--out", default=str(ROOT / "reports"))
    b.set_defaults(fn=_bench)
    f = sub.add_parser("reference", help="regenerate reference_runs/ by running LIGGGHTS and YADE (and the "
                                          "cases' stored fine native runs, code 'native')")
    f.add_argument("--codes", default=None, help="comma-separated subset of the reference codes, e.g. yade "
                                                  "(native: the cases' own fine runs)")
    f.add_argument("--variants", default=None, help="comma-separated subset of the case's variants (ensemble "
                                                    "members), e.g. m01,m02; the others stay as stored")
    f.add_argument("cases", nargs="*")
    f.set_defaults(fn=_reference)
    args = p.parse_args(argv)
    try:
        return args.fn(args)
    except SceneError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except SimulationError as e:
        print(f"simulation failed: {e}", file=sys.stderr)
        return 3
    except BackendUnavailable as e:
        print(f"backend unavailable: {e}", file=sys.stderr)
        return 4
    except ReferenceCodeError as e:    # crashed, timed out or wrote unparsable output: code, what, log path
        print(f"error: {e}", file=sys.stderr)
        return 6


if __name__ == "__main__":
    sys.exit(main())
