"""Block flat drop (issue #4): the 6 x 5 block lands flat (6 bottom spheres at once), vy0 = -0.2 m/s, e = 0.8,
no gravity during the short impact. Rebound ratio = vy after / |vy before| for both damping-mass conventions.
Expected from the clamped Hertz ODE of coupler/dem/contact.py: each of the 6 contacts carries M/6 while its
dashpot uses m_d (the body mass M for "body", LIGGGHTS; the member mass m_s for "sphere", YADE), i.e. an
effective damping ratio beta sqrt(6 m_d / M). Reference values in shared/notes (LIGGGHTS 0.611, YADE 0.907) use
the LIGGGHTS beta; here beta is the default "restitution" map. Member mass, member count and the number of bottom
members (contacts) are read from the scene's cluster template."""
from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from coupler.dem.contact import damping_ratio, restitution_clamped
from coupler.scene import load_scene
from validation.metrics import restitution_wall, scene_cluster, sphere_mass

TITLE = "Rigid cluster: flat drop rebound, body vs sphere damping mass"
FULL_ONLY = False


def evaluate(ctx):
    fig, ax = plt.subplots(figsize=(7, 4))
    for conv in ("body", "sphere"):
        scene = load_scene(ctx.case_dir / "block.toml", overrides={"dem.cluster_damping_mass": conv},
                           name=f"block_drop_{conv}")
        res = ctx.run(scene, tag=conv)
        b = res.body("block")
        ratio = restitution_wall(b)
        _, tpl, mat = scene_cluster(scene, "block")
        law = scene.contact_law(mat.name, scene.dem.planes[0].material)
        assert (tpl.radii == tpl.radii[0]).all(), "equal members"
        m_s = sphere_mass(mat.density, float(tpl.radii[0]))
        M = len(tpl.radii) * m_s
        n_bottom = int(np.isclose(tpl.offsets[:, 1], tpl.offsets[:, 1].min()).sum())   # members landing together
        m_d = M if conv == "body" else m_s
        beta = damping_ratio(law) * math.sqrt(n_bottom * m_d / M)
        ctx.check_rel(f"rebound ratio, cluster_damping_mass='{conv}'", ratio, restitution_clamped(beta), 0.01,
                      wall_time_s=ctx.wall_times[conv], note=f"effective beta {beta:.5f}")
        ax.plot(b["t"] * 1e3, b["vy"], label=f"{conv}: rebound {ratio:.4f}")
    ax.set(xlabel="t [ms]", ylabel="vy [m/s]")
    ax.legend()
    ctx.save_plot(fig)
