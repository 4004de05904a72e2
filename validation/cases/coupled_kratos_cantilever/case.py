"""Kratos CoSimulation regression case (issue 16): an elastic MPM cantilever hit by a DEM disc, one scene file run
natively and through Kratos (CoSimulationApplication gauss_seidel_weak, DEM first; adapters/kratos/cosim.py).

Compared like with like: Kratos at the native coupling step 2e-4 s against the native coupler with Kratos' own
models (stored Kratos runs of kratos_run.py, --live reruns them):
  * disc trajectory: vertical displacement y(t_end) - y0 and vertical velocity at t_end (10 %);
  * the vertical impulse the disc gave the beam by t_end, integral of fy_dem dt (10 %; Kratos' per-depth force
    times the scene thickness);
  * beam: the free end's vertical displacement at t_end (mean uy of the points with initial x >= 1.9 m) and the
    largest downward displacement of any point over the run (10 %).
What is compared, and why (measured 2026-12-02, first with the scene as written, where all five rows differed by
20-60 %):
  - native_kratos_law: the same scene with Kratos' 2D law mapped onto the native DEM
    (adapters/kratos/params.native_equivalent_of_2d_law: Hooke k = t 0.7854 E*, k_t = 4 G*/E* k, the same damping
    ratio) and the implicit MPM partition (Newmark, as Kratos), coupling step 2e-4 s; against Kratos at 2e-4 s.
    The 10 % rows are these. What still differs by construction: the 2D disc (I = m R^2 / 2) against a sphere
    (2/5 m R^2), Kratos' incremental tangential spring, Symplectic Euler DEM at the coupling step against native
    velocity Verlet sub-steps, grid point-load conditions against boundary particles.
  - the scene as written (native 3D Hertz / thickness, explicit MPM): the effect of the contact law, in the notes.
  - Kratos' own test step 2e-3 s: Kratos is not converged in time there. Its interface force is non-zero in only 5
    of 25 coupling steps (peak 1.5e5 N): the DEM wall jumps with the MPM interface, and the contact stiffness
    against one interface node's mass (k / m_node ~ 8e4 1/s^2 at h = 0.1 m: omega dt ~ 0.6) is barely resolved.
    The native coupler at 2e-3 s is within 1.3 % of its own 2e-4 s run, because the implicit partition hands the
    wall the step-mean interface velocity (coupler/mpm/implicit/solver.py); with the Newmark end-of-step velocity
    instead it gives dy -4.59 cm, tip -6.19 cm and 4 zero-force steps (measured 2026-12-02). Both codes at 2e-3 s
    are in the notes and the plot, not pass/fail rows. At 2e-4 s Kratos' force still drops to zero in 10 of the
    first 61 coupling steps (native: 1; both take one DEM step per coupling step there), which averages out in the
    impulse.
The 10 % is a statement of what "the same physics" means across these models, not an accuracy bound."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

TITLE = "Coupled cantilever hit by a DEM disc: native vs Kratos CoSimulation (issue 16)"
FULL_ONLY = False
RTOL = 0.10
TIP_X0 = 1.9                  # free-end points: initial x >= this [m]


def disc(res, name="disc"):
    b = res.body(name)
    return b["t"].to_numpy(), b["y"].to_numpy(), b["vy"].to_numpy()


def tip_series(res, x0_min=TIP_X0):
    rows = []
    for t, df in res.particles:
        x0 = df["x"] - df["ux"]
        sel = x0 >= x0_min - 1e-9
        rows.append((t, float(df.loc[sel, "uy"].mean()), float(df["uy"].min())))
    return np.array(rows)


def impulse(res):
    f = res.interface
    t = f["t"].to_numpy()
    fy = f["fy_dem"].to_numpy()
    dt = np.diff(np.concatenate([[0.0], t]))
    return float(np.sum(fy * dt)), t, fy


def kratos_law_scene(ctx, sc, dt: float):
    """The scene with Kratos' 2D disc-wall law on the coupling material's contacts and the implicit MPM partition at
    coupling step dt (adapters/kratos/params.py says how the law maps)."""
    import tomllib
    from adapters.kratos.params import native_equivalent_of_2d_law
    from coupler.scene import load_scene
    path = ctx.case_dir / "scene.toml"
    raw = tomllib.loads(path.read_text())
    wall = sc.coupling.material
    over: dict = {"mpm.scheme": "implicit", "coupling.dt": dt}
    for i, ct in enumerate(raw["contacts"]):
        a, b = ct["materials"]
        if (a == wall) != (b == wall):
            law = sc.contacts[tuple(sorted((a, b)))]
            other = sc.materials[b if a == wall else a]
            for k, v in native_equivalent_of_2d_law(law, other, sc.materials[wall], sc.coupling.thickness).items():
                over[f"contacts[{i}].{k}"] = float(v) if isinstance(v, float) else v
    return load_scene(path, overrides=over, name=f"{sc.name}_kratos_law_{dt:g}")


def summary(res):
    """disc dy, disc vy at t_end, vertical impulse, beam tip uy at t_end, largest downward uy."""
    _, y, vy = disc(res)
    tip = tip_series(res)
    return {"dy": y[-1] - y[0], "vy": vy[-1], "impulse": impulse(res)[0], "tip": tip[-1, 1], "min_uy": tip[:, 2].min()}


ROWS = (("dy", "disc vertical displacement at t_end [m]"), ("vy", "disc vertical velocity at t_end [m/s]"),
        ("impulse", "vertical impulse disc -> beam by t_end [N s]"), ("tip", "beam free-end displacement at t_end [m]"),
        ("min_uy", "beam largest downward displacement over the run [m]"))


def evaluate(ctx):
    from validation.cases.coupled_kratos_cantilever import kratos_run as KR
    sc = ctx.scene("scene.toml")
    runs = {"native (scene: 3D Hertz, explicit, 2e-4 s)": ctx.run(sc, tag="native")}
    kr = {}                       # coupling step -> (Kratos result, its wall time)
    for variant, dt in KR.VARIANTS.items():      # one native run with Kratos' law per stored Kratos step
        tag = f"dt{dt:g}"
        runs[f"native, Kratos law, implicit, {dt:g} s"] = ctx.run(kratos_law_scene(ctx, sc, dt), tag=f"native_{tag}")
        if ctx.live:
            res, prov = KR.run_kratos(sc, ctx.out_dir / f"kratos_{tag}", dt), {"date": "this run (live)"}
        else:
            res, why, prov = KR.stored(sc, variant)
            if res is None:
                ctx.fail(f"kratos {variant}", why, backend="kratos")
                continue
        kr[dt] = (res, float(prov.get("wall_time_s", res.summary.get("wall_time_s", float("nan")))))
        runs[f"Kratos, {dt:g} s ({res.summary.get('steps')} steps)"] = res
    vals = {name: summary(r) for name, r in runs.items()}
    if KR.NATIVE_DT in kr:
        res, wk = kr[KR.NATIVE_DT]
        nat = vals[f"native, Kratos law, implicit, {KR.NATIVE_DT:g} s"]
        kv = summary(res)
        for key, label in ROWS:
            ctx.check_rel(f"{label} (Kratos vs native, same law and step 2e-4 s)", kv[key], nat[key], RTOL,
                          backend="kratos", wall_time_s=wk, note=f"native {nat[key]:.5g}, Kratos {kv[key]:.5g}")
    for name, v in vals.items():
        ctx.notes.append(f"{name}: disc dy {v['dy'] * 100:.2f} cm, vy {v['vy']:.4f} m/s, impulse {v['impulse']:.1f} "
                         f"N s, beam tip {v['tip'] * 100:.2f} cm, largest downward {v['min_uy'] * 100:.2f} cm")
    ctx.notes.append("native wall times: " + ", ".join(f"{k} {w:.1f} s" for k, w in ctx.wall_times.items()) +
                     "; Kratos (stored, loaded machine: upper bounds): " +
                     ", ".join(f"{k:g} s: {w:.0f} s" for k, (_, w) in kr.items()))
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for name, r in runs.items():
        style = "o--" if name.startswith("Kratos") else "-"
        t, y, _ = disc(r)
        ax[0].plot(t, y - y[0], style, ms=3, label=name)
        _, ti, fy = impulse(r)
        ax[1].plot(ti, fy, style, ms=3, label=name)
        s = tip_series(r)
        ax[2].plot(s[:, 0], s[:, 1], style, ms=3, label=name)
    ax[0].set_xlabel("t [s]"); ax[0].set_ylabel("disc y - y0 [m]"); ax[0].legend(fontsize=6)
    ax[1].set_xlabel("t [s]"); ax[1].set_ylabel("fy on the interface wall [N] (one layer)")
    ax[2].set_xlabel("t [s]"); ax[2].set_ylabel("beam free-end uy [m]")
    fig.tight_layout()
    ctx.save_plot(fig)
