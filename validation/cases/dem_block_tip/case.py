"""Block tip (issue #4): standing 5 x 6 block (exact mass and inertia, I_zz about the COM) on a 35 deg incline
(tilted gravity), mu = 0.9. Reference: rigid rotation about the contact point of the downhill bottom sphere
(pivot at the sphere's lowest point), I_p theta'' = torque of gravity about the pivot, integrated with scipy
(not linearised). Compared during the tip at t = 0.05, 0.10, 0.12 s within 2 %; the first ~20 ms are dominated by
the contact settling (compliance, the rigid pivot has none) and are shown, not scored."""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from scipy.integrate import solve_ivp

TITLE = "Rigid cluster: block tipping on an incline vs rigid pivot"
FULL_ONLY = False
TIMES = (0.05, 0.10, 0.12)


def pivot_solution(scene, t_eval):
    g = scene.gravity[:2]
    r = 2.5e-3
    mat = scene.materials["aluminium"]
    m = mat.density * 4 / 3 * math.pi * r ** 3
    xs, ys = np.meshgrid(np.arange(5) * 5e-3, np.arange(6) * 5e-3, indexing="ij")
    xs, ys = xs.ravel() - 10e-3, ys.ravel() - 12.5e-3
    M = 30 * m
    Izz = float(np.sum(0.4 * m * r * r + m * (xs ** 2 + ys ** 2)))
    r0 = np.array([-10e-3, 12.5e-3 + r])           # COM relative to the pivot (bottom of the downhill sphere)
    Ip = Izz + M * (r0 @ r0)

    def rhs(_t, y):
        th, om = y                                  # rotation about z (negative = downhill)
        c, s = math.cos(th), math.sin(th)
        rr = np.array([c * r0[0] - s * r0[1], s * r0[0] + c * r0[1]])
        tau = rr[0] * M * g[1] - rr[1] * M * g[0]
        return [om, tau / Ip]

    sol = solve_ivp(rhs, (0, t_eval[-1]), [0.0, 0.0], t_eval=t_eval, rtol=1e-10, atol=1e-13)
    return np.degrees(-sol.y[0])


def evaluate(ctx):
    scene = ctx.scene("block.toml")
    res = ctx.run(scene)
    wall = ctx.wall_times[f"{scene.name}_native"]
    b = res.body("block")
    t = b["t"].to_numpy()
    angle = np.degrees(-2.0 * np.arctan2(b["qz"].to_numpy(), b["qw"].to_numpy()))
    ref = pivot_solution(scene, t)
    for ts in TIMES:
        k = int(np.argmin(abs(t - ts)))
        ctx.check_rel(f"tip angle at t = {ts:g} s [deg]", float(angle[k]), float(ref[k]), 0.02, wall_time_s=wall,
                      note="the compliant contacts settle and start the tip earlier than the rigid pivot (a time "
                           "shift of a few ms in an exponential instability); LIGGGHTS shows the same lead (notes)")
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(t, angle, label="native (exact inertia)")
    ax.plot(t, ref, "k:", label="rigid pivot")
    ax.set(xlabel="t [s]", ylabel="rotation [deg]")
    ax.legend()
    ctx.save_plot(fig)
