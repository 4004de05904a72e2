"""Reference-code runs for validation cases: stored under reference_runs/<case>/<code>/<variant>/ with
provenance.json, rerun live with `mpmdem validate --live`, regenerated with `make reference`
(`validation.suite.regenerate`, which runs the cases' reference scenes).

A case that compares with reference codes defines
    REFERENCE_CODES = ("liggghts", "yade")
    def reference_scenes(case_dir) -> dict[str, Scene]      # variant name -> scene
"""
from __future__ import annotations

import json
from pathlib import Path

from coupler.errors import BackendUnavailable, UnsupportedFeature
from coupler.results import Result
from coupler.scene import Scene

ROOT = Path(__file__).resolve().parent.parent
REFERENCE_DIR = ROOT / "reference_runs"

RAW_OUTPUTS = ("atoms.dump", "pairs.dump", "bodies.dump", "bodies_yade.csv", "contacts_yade.csv",  # parsed, not stored
               "kratos_states.csv", "kratos_forces.csv", "kratos_particles.csv", "kratos_series.csv",
               "kratos_energy.csv")


def stored_dir(case: str, code: str, variant: str) -> Path:
    return REFERENCE_DIR / case / code / variant


def run_reference(code: str, scene: Scene, out: Path) -> Result:
    from coupler.run import run_scene
    res = run_scene(scene, out, backend=code, progress=False)
    for f in RAW_OUTPUTS:
        (out / f).unlink(missing_ok=True)
    return res


def compress_tables(out: Path) -> None:
    import gzip
    for name in ("bodies", "contacts", "energy", "mpm_bodies"):
        p = out / f"{name}.csv"
        if not p.exists():          # mpm_bodies: MPM runs only
            continue
        with open(p, "rb") as src, open(out / f"{name}.csv.gz", "wb") as raw, \
                gzip.GzipFile(fileobj=raw, mode="wb", compresslevel=9, mtime=0) as dst:
            dst.write(src.read())
        p.unlink()


def inexpressible(code: str, scene: Scene) -> str | None:
    """Why `code` cannot run `scene` (the adapter's UnsupportedFeature message), or None."""
    if code == "liggghts":
        from adapters.liggghts.writer import check_supported
    elif code == "kratos":
        from adapters.kratos.params import check_supported
    else:
        from adapters.yade.params import check_supported
    try:
        check_supported(scene)
    except UnsupportedFeature as e:
        return str(e)
    return None


def get_reference(ctx, code: str, variant: str, scene: Scene | None) -> tuple[Result | None, str]:
    if ctx.live:
        try:
            return run_reference(code, scene, ctx.out_dir / f"{code}_{variant}"), ""
        except (BackendUnavailable, UnsupportedFeature) as e:
            return None, f"live run impossible: {e}"
    d = stored_dir(ctx.name, code, variant)
    if not (d / "summary.json").exists():
        return None, f"no stored run in {d.relative_to(REFERENCE_DIR.parent)} (run `make reference`)"
    prov = json.loads((d / "provenance.json").read_text())
    if scene is not None and prov.get("scene_hash") != scene.text_hash:
        return None, (f"stored run in {d.relative_to(REFERENCE_DIR.parent)} was made for another version of the "
                      f"scene (hash mismatch): run `make reference`")
    return Result.read(d), ""

