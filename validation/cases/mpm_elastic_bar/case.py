"""1D vibrating elastic bar (fixed-free), first mode: v(x, 0) = v0 sin(pi x / 2L), analytic period 4 L / c.
Period from the zero crossings of the mean velocity over 10 periods (linear interpolation; L, E, rho from the
scene); energy (kinetic + elastic) drift = max |E(t) - E(0)| / E(0) over 10 periods. Transfer APIC (scene), also MUSL; uGIMP, CFL 0.1 (at CFL 0.4 the energy drift is 1.4-1.7 %, measured).
Kratos MPM column (adapters/kratos, params.py): the same scene in Kratos 10.4.4 implicit Newmark, bilinear quads
(MPMUpdatedLagrangian2D4N, 2x2 points per cell), LinearElasticIsotropicPlaneStrain2DLaw, dt = 1e-4 s (the implicit
scheme is not CFL-bound; dt/T = 1/200), the first-mode velocity given to its material points; stored in
reference_runs/mpm_elastic_bar/kratos/bar (store_kratos_reference), rerun with --live. Same metrics and tolerances."""
from __future__ import annotations

import math
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.mpm.solver import MPMSolver
from coupler.scene import load_scene
from validation.analytic import bar_period
from validation.metrics import period_from_zero_crossings, scene_mpm_body_extent

TITLE = "MPM vibrating elastic bar: period and energy over 10 periods"
FULL_ONLY = False
V0 = 0.1


def bar_length(scene) -> float:
    """Length L of the bar (its body's x extent in the scene; fixed end at the lower x)."""
    lo, hi = scene_mpm_body_extent(scene)
    return float(hi[0] - lo[0])


def simulate(scene):
    sol = MPMSolver(scene)
    L = bar_length(scene)
    sol.v[:, 0] = V0 * np.sin(np.pi * sol.x[:, 0] / (2 * L))
    n = int(math.ceil(scene.time.t_end / sol.dt))
    t, vm, en = [0.0], [float(np.mean(sol.v[:, 0] * sol.m) / np.mean(sol.m))], []
    e = sol.energies()
    en.append(e["kinetic"] + e["elastic"])
    t0 = time.perf_counter()
    for _ in range(n):
        sol.step()
        t.append(sol.t)
        vm.append(float(np.sum(sol.v[:, 0] * sol.m) / np.sum(sol.m)))
        e = sol.energies()
        en.append(e["kinetic"] + e["elastic"])
    return np.array(t), np.array(vm), np.array(en), time.perf_counter() - t0


def evaluate(ctx):
    base = ctx.scene("scene.toml")
    mat = base.materials["bar"]
    T_ref = bar_period(bar_length(base), mat.young, mat.density)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for transfer in ("apic", "musl"):
        scene = load_scene(base.source, overrides={"mpm.transfer": transfer})
        t, v, en, wall = simulate(scene)
        ctx.wall_times[transfer] = wall
        T, nz = period_from_zero_crossings(t, v)
        ctx.check_rel(f"{transfer}: period [s]", T, T_ref, 0.01, wall_time_s=wall, note=f"{nz} zero crossings")
        drift = float(np.max(np.abs(en - en[0])) / en[0])
        ctx.check_max(f"{transfer}: energy drift over 10 periods [-]", drift, 0.01, wall_time_s=wall)
        a1.plot(t / T_ref, v, label=transfer)
        a2.plot(t / T_ref, en / en[0], label=transfer)
    kr = kratos_reference(ctx, base)
    if kr is not None:
        b = kr.mpm_body("bar")
        t, v = b["t"].to_numpy(), b["vx"].to_numpy()
        en = (kr.energy["kinetic"] + kr.energy["elastic"]).to_numpy()
        wall = float(kr.summary["wall_time_s"])
        T, nz = period_from_zero_crossings(t, v)
        ctx.check_rel("kratos: period [s]", T, T_ref, 0.01, backend="kratos", wall_time_s=wall,
                      note=f"{nz} zero crossings; implicit Newmark dt {kr.summary['dt']:g} s, bilinear quads")
        ctx.check_max("kratos: energy drift over 10 periods [-]", float(np.max(np.abs(en - en[0])) / en[0]), 0.01,
                      backend="kratos", wall_time_s=wall)
        a1.plot(t / T_ref, v, "--", label="kratos")
        a2.plot(t / T_ref, en / en[0], "--", label="kratos")
    a1.set_xlabel("t / T"); a1.set_ylabel("mean velocity [m/s]"); a1.legend()
    a2.set_xlabel("t / T"); a2.set_ylabel("E / E0"); a2.legend()
    fig.tight_layout()
    ctx.save_plot(fig)


KRATOS_DT = 1e-4


def kratos_velocity(scene) -> tuple[str, str]:
    """The first-mode initial velocity as Kratos function strings (x, y), L read from the scene."""
    return (f"{V0!r}*sin(pi*x/(2*{bar_length(scene)!r}))", "0.0")


def kratos_scene(base):
    return load_scene(base.source, overrides={"time.dt": KRATOS_DT})


def kratos_reference(ctx, base):
    """The Kratos run: live with --live (Kratos installed), else the stored one (scene hash checked)."""
    from validation.references import get_reference
    scene = kratos_scene(base)
    if ctx.live:
        from adapters.kratos.backend import run
        from coupler.errors import BackendUnavailable
        try:
            res = run(scene, ctx.out_dir / "kratos_bar", initial_velocity=kratos_velocity(scene), snapshot_every=50)
        except BackendUnavailable as e:
            ctx.fail("kratos: period [s]", f"live run impossible: {e}", backend="kratos")
            return None
        res.summary.setdefault("scene_hash", scene.text_hash)
        res.write(ctx.out_dir / "kratos_bar")
        return res
    res, why = get_reference(ctx, "kratos", "bar", scene)
    if res is None:
        ctx.fail("kratos: period [s]", why, backend="kratos")
    return res


def store_kratos_reference(case_dir=None):
    """Run the Kratos bar and store it in reference_runs/mpm_elastic_bar/kratos/bar (about 2 min here)."""
    import shutil
    from pathlib import Path
    from adapters.kratos.backend import run
    from validation.references import RAW_OUTPUTS, compress_tables, stored_dir
    case_dir = Path(case_dir or Path(__file__).parent)
    scene = kratos_scene(load_scene(case_dir / "scene.toml"))
    out = stored_dir("mpm_elastic_bar", "kratos", "bar")
    if out.exists():
        shutil.rmtree(out)
    res = run(scene, out, initial_velocity=kratos_velocity(scene), snapshot_every=50)
    res.summary.setdefault("scene_hash", scene.text_hash)
    res.write(out)
    for f in RAW_OUTPUTS:
        (out / f).unlink(missing_ok=True)
    compress_tables(out)
    return res
