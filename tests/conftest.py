import os
import shutil

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASES = os.path.join(ROOT, "validation", "cases")


def require_binary(name: str) -> None:
    """Skip with the reason when a reference code is missing; in CI (CI set) a missing code is a failure."""
    if shutil.which(name) is None:
        if os.environ.get("CI"):
            pytest.fail(f"{name} is not installed, but CI must run the live adapter tests (.ci/run installs it)")
        pytest.skip(f"{name} not installed (apt-get install -y {name}); live comparison skipped")


# -- scene builder ------------------------------------------------------------------------------------------------
ALUMINIUM = {"density": "2700.0", "young": "70e9", "poisson": "0.33"}


def _toml(v) -> str:
    """A value as TOML: a str is written as given (a TOML literal, or a str.format placeholder), bools lower case,
    numbers by repr, lists element by element."""
    if isinstance(v, str):
        return v
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(v)


def scene_toml(body: str = "", *, name: str = "t", dimension=3, gravity="[0.0, -9.81, 0.0]", t_end="1e-5",
               dt="1e-8", output_interval="1e-6", materials: dict | None = None, contacts="self",
               output: dict | None = None) -> str:
    """The TOML text of a test scene: the common header, then ``body`` (the [dem] / [mpm] sections).

    Header: name, dimension, gravity, [time] (``dt=None`` leaves the time step automatic), [materials.*]
    (default: aluminium, rho 2700, E 70 GPa, nu 0.33), [[contacts]] ("self": the first material with itself,
    e = 0.8, mu = 0.3; a list of (material_a, material_b, restitution, friction); None: no laws), [output].
    Values are TOML literals when given as str (so the defaults read exactly as written, and a test can edit them
    with ``edit``), else formatted from Python values."""
    materials = {"aluminium": ALUMINIUM} if materials is None else materials
    lines = ["", f'name = "{name}"', f"dimension = {_toml(dimension)}", f"gravity = {_toml(gravity)}", "[time]",
             f"t_end = {_toml(t_end)}"]
    if dt is not None:
        lines.append(f"dt = {_toml(dt)}")
    lines.append(f"output_interval = {_toml(output_interval)}")
    for mat, props in materials.items():
        lines.append(f"[materials.{mat}]")
        lines += [f"{k} = {_toml(v)}" for k, v in props.items()]
    if contacts == "self":
        first = next(iter(materials))
        contacts = [(first, first, "0.8", "0.3")]
    for a, b, e, mu in contacts or ():
        lines += ["[[contacts]]", f'materials = ["{a}", "{b}"]', f"restitution = {_toml(e)}", f"friction = {_toml(mu)}"]
    if output:
        lines.append("[output]")
        lines += [f"{k} = {_toml(v)}" for k, v in output.items()]
    return "\n".join(lines) + "\n" + body


def edit(text: str, old: str, new: str, count: int = 1) -> str:
    """text with ``old`` replaced by ``new`` (the first ``count`` times); an error if ``old`` is not in text, so an
    edit that changes nothing cannot pass unnoticed."""
    if old not in text:
        raise AssertionError(f"edit: {old!r} not in the scene text")
    return text.replace(old, new, count)


SPHERE_A = """[[dem.spheres]]
name = "a"
material = "aluminium"
radius = 2.5e-3
position = [0.0, 0.0026, 0.0]
velocity = [0.0, -1.0, 0.0]
"""
FLOOR = """[[dem.planes]]
name = "floor"
material = "aluminium"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
"""
SPHERE_ON_FLOOR = "[dem]\n" + SPHERE_A + FLOOR

# A small valid DEM scene (one aluminium sphere 0.1 mm above a floor at 1 m/s); tests edit it to make it invalid.
BASE_SCENE = scene_toml(SPHERE_ON_FLOOR)


@pytest.fixture
def scene_text():
    """A small valid DEM scene; tests edit it to make it invalid."""
    return BASE_SCENE


def on_1_and_2_threads(run):
    """[run() with 1 numba thread, run() with 2] (the thread count restored after); skips when numba has fewer than
    2 threads (NUMBA_NUM_THREADS). For tests that the bits do not depend on the thread count."""
    import numba
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has fewer than 2 threads (NUMBA_NUM_THREADS)")
    old = numba.get_num_threads()
    try:
        outs = []
        for nt in (1, 2):
            numba.set_num_threads(nt)
            outs.append(run())
        return outs
    finally:
        numba.set_num_threads(old)
