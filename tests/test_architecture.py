"""The import graph of the project's own packages: no cycles, and lower layers never import higher ones.

Every `import` / `from ... import` statement counts, at module level or inside a function, including those under
`if TYPE_CHECKING:` (the same graph as /work/shared/tools/import_cycles.py). Dynamic loading through the two
registries (`coupler.run.BACKENDS`, `coupler.scene.SECTIONS`, both by module name) is not an import edge; the
registry rows are checked here instead. Layers (design.md):

    errors, fields  <  materials  <  scene  <  section parsers (dem/scene, mpm/scene, coupling/scene) and solvers
    <  coupling  <  run (backend registry), native, results writers, bench, cli  <  validation
    adapters/ sit beside the native solvers: they read scene + results, never coupler.run / bench / validation.
"""
from __future__ import annotations

import ast
import inspect
import typing
from dataclasses import fields
from pathlib import Path

import pytest

from tests.conftest import scene_toml

ROOT = next(d for d in Path(__file__).resolve().parents if (d / "pyproject.toml").exists())
PACKAGES = ("coupler", "adapters", "validation")


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            name = ".".join(f.relative_to(ROOT).with_suffix("").parts)
            if name.endswith(".__init__"):
                name = name[: -len(".__init__")]
            mods[name] = f
    return mods


def import_graph() -> dict[str, set[str]]:
    """module -> project modules it imports (a `from pkg import name` counts pkg.name when that is a module)."""
    mods = _modules()

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, f in mods.items():
        pkg = m if f.name == "__init__.py" else m.rpartition(".")[0]
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = pkg.split(".")
                    base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            else:
                continue
            for t in targets:
                r = resolve(t)
                if r and r != m:
                    graph[m].add(r)
    return graph


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Components with more than one module (iterative Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


GRAPH = import_graph()


def _in(mod: str, prefix: str) -> bool:
    return mod == prefix or mod.startswith(prefix + ".")


def test_cycle_finder_finds_a_cycle():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e"}}
    assert strongly_connected(g) == [["a", "b", "c"]]


def test_no_import_cycles():
    cycles = strongly_connected(GRAPH)
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def _violations(importer: str, forbidden: tuple[str, ...], allowed_importers: tuple[str, ...] = ()) -> list[str]:
    bad = []
    for m, deps in GRAPH.items():
        if not _in(m, importer) or any(_in(m, a) for a in allowed_importers):
            continue
        bad += [f"{m} imports {d}" for d in sorted(deps) if any(_in(d, f) for f in forbidden)]
    return bad


BENCH_DRIVERS = ("coupler.dem.bench_clusters", "coupler.mpm.bench", "coupler.coupling.bench")

LAYER_RULES = [
    # (importer prefix, forbidden import prefixes, importers exempt from the rule)
    # the command line is the shell over everything (`mpmdem validate` runs the validation suite)
    ("coupler", ("validation",), ("coupler.cli",)),
    # the native code reaches the reference codes only through the backend registry (by module name)
    ("coupler", ("adapters",), ()),
    ("adapters", ("coupler.run", "coupler.native", "coupler.bench", "coupler.cli", "coupler.coupling",
                  "validation"), ()),
    # the scene model: physical parameters and scene tables, no solver, no section parser, no backend
    ("coupler.errors", ("coupler", "adapters", "validation"), ()),
    ("coupler.fields", ("coupler.materials", "coupler.scene", "coupler.dem", "coupler.mpm",
                        "coupler.coupling", "coupler.run", "coupler.results"), ()),
    ("coupler.materials", ("coupler.scene", "coupler.dem", "coupler.mpm", "coupler.coupling",
                           "coupler.run", "coupler.results"), ()),
    ("coupler.scene", ("coupler.dem", "coupler.mpm", "coupler.coupling", "coupler.run", "coupler.native",
                       "coupler.results", "coupler.bench"), ()),
    ("coupler.results", ("coupler.dem", "coupler.mpm", "coupler.coupling", "coupler.run", "coupler.native"), ()),
    # the two solvers sit side by side; only the coupling (through its partitions) sees both. The benchmark
    # drivers next to a solver (dem/bench_clusters.py, mpm/bench.py, coupling/bench.py) are bench-layer modules.
    ("coupler.dem", ("coupler.mpm", "coupler.coupling", "coupler.run", "coupler.native", "coupler.cli"),
     BENCH_DRIVERS),
    ("coupler.mpm", ("coupler.dem", "coupler.coupling", "coupler.run", "coupler.native", "coupler.cli"),
     BENCH_DRIVERS),
    ("coupler.coupling", ("coupler.run", "coupler.native", "coupler.bench", "coupler.cli"), BENCH_DRIVERS),
    ("coupler.run", ("coupler.native", "coupler.dem", "coupler.mpm", "coupler.coupling", "coupler.bench"), ()),
]


@pytest.mark.parametrize("importer,forbidden,exempt", LAYER_RULES, ids=[r[0] + "-" + r[1][0] for r in LAYER_RULES])
def test_lower_layers_never_import_higher_ones(importer, forbidden, exempt):
    bad = _violations(importer, forbidden, exempt)
    assert not bad, "layer violations:\n" + "\n".join(bad)


def test_only_the_cli_reaches_validation():
    users = sorted(m for m, deps in GRAPH.items() if _in(m, "coupler") and any(_in(d, "validation") for d in deps))
    assert users in ([], ["coupler.cli"])


# -- the two registries ------------------------------------------------------------------------------------------

def test_backend_registry_rows_resolve():
    import importlib

    from coupler import run
    from coupler.errors import BackendUnavailable
    assert list(run.BACKENDS)[0] == "native"
    for name, b in run.BACKENDS.items():
        if not (ROOT / (b.module.replace(".", "/") + ".py")).exists():
            assert b.missing, f"backend {name!r}: module {b.module} absent and no `missing` message"
            with pytest.raises(BackendUnavailable, match="not written yet"):
                run.backend_module(name)
            continue
        mod = importlib.import_module(b.module)
        params = inspect.signature(mod.run).parameters
        for p in ("progress", "timeout_s"):
            assert p in params and params[p].kind is inspect.Parameter.KEYWORD_ONLY, f"{b.module}.run({p}=...)"


def test_unknown_backend_message_unchanged():
    from coupler.errors import SceneError
    from coupler.run import backend_module
    with pytest.raises(SceneError, match=r"--backend: must be one of native, liggghts, yade, kratos; got 'abaqus'"):
        backend_module("abaqus")


def test_scene_section_registry_rows_resolve():
    import importlib

    from coupler.scene import SECTIONS, Scene, section_types
    names = {f.name for f in fields(Scene)}
    types = section_types()
    for key, sec in SECTIONS.items():
        assert key in names, f"Scene has no field {key!r} for section [{key}]"
        if not (ROOT / (sec.module.replace(".", "/") + ".py")).exists():
            assert sec.missing, f"section [{key}]: module {sec.module} absent and no `missing` message"
            continue
        mod = importlib.import_module(sec.module)
        assert callable(getattr(mod, sec.parse)), f"{sec.module}.{sec.parse}"
        assert len(inspect.signature(getattr(mod, sec.parse)).parameters) == 3, \
            f"{sec.module}.{sec.parse}(table, scene, base_dir)"
        if sec.finish:
            assert callable(getattr(mod, sec.finish)), f"{sec.module}.{sec.finish}"
        assert isinstance(types[sec.type_name], type)
        # the Scene annotation names the registered class
        assert Scene.__annotations__[key] == f"{sec.type_name} | None"
    # with every section class present, the annotations resolve to the real classes
    missing = {sec.type_name: object for sec in SECTIONS.values() if sec.type_name not in types}
    hints = typing.get_type_hints(Scene, localns={**types, **missing})
    assert hints["dem"] == types["DEMScene"] | None


def test_sections_parse_into_their_registered_types():
    from coupler.scene import SECTIONS, loads_scene, section_types
    scene = loads_scene(SPHERE_SCENE)
    assert isinstance(scene.dem, section_types()[SECTIONS["dem"].type_name])
    assert scene.mpm is None and scene.coupling is None


SPHERE_SCENE = scene_toml("""[dem]
[[dem.spheres]]
material = "aluminium"
radius = 1e-3
position = [0.0, 0.0, 0.0]
""", name="arch")


# -- dead code stays out ------------------------------------------------------------------------------------------

def test_output_vtk_is_used():
    """`[output] vtk` is back (issue 19) and used: Result.write hands it to coupler/vtk.py (tests/coupler/test_vtk.py)."""
    from coupler.scene import loads_scene
    assert loads_scene(SPHERE_SCENE.replace("[dem]", "[output]\nvtk = true\n[dem]")).output.vtk is True
    assert "write_vtk" in (ROOT / "coupler" / "results.py").read_text()


def test_removed_names_stay_removed():
    from coupler.dem.solver import DEMSolver
    from coupler.scene import Scene
    assert not hasattr(Scene, "with_time")
    assert not hasattr(DEMSolver, "wall_forces")
    assert "pyvista" not in (ROOT / "pyproject.toml").read_text()


def test_numba_cache_key_covers_every_kernel_and_what_it_imports():
    """The kernel cache folder is keyed on coupler.kernel_sources(): every file that defines numba code and every
    project module it imports (constants baked into machine code), not the orchestration that only calls kernels."""
    import coupler
    root = Path(coupler.__file__).resolve().parent
    keyed = set(coupler.kernel_sources(root))
    marked = {p for p in list((root / "dem").rglob("*.py")) + list((root / "mpm").rglob("*.py"))
              if coupler.KERNEL_MARKS.search(p.read_text())}
    assert marked and marked <= keyed
    assert root / "mpm" / "constitutive" / "__init__.py" in keyed          # N_PRM, read by the kernels
    assert root / "mpm" / "solver.py" not in keyed and root / "mpm" / "implicit" / "solver.py" not in keyed
    # the scene modules are orchestration too: clusters.py names ClusterTemplate under `if TYPE_CHECKING:` only, so
    # editing a scene check keeps the compiled kernels (before the thirty-fifth session it recompiled all of them)
    for p in ("scene.py", "dem/scene.py", "mpm/scene.py", "materials.py", "coupling/scene.py"):
        assert root / p not in keyed, p
