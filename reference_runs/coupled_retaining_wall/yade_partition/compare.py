"""Side by side: coupled retaining wall with the native DEM partition and with the YADE partition (same scene,
same native MPM)."""
import json, sys
import numpy as np, pandas as pd
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
D = {"native": sys.argv[1], "yade": sys.argv[2]}
out = sys.argv[3]
B = {k: pd.read_csv(f"{d}/bodies.csv") for k, d in D.items()}
I = {k: pd.read_csv(f"{d}/interface.csv") for k, d in D.items()}
S = {k: json.load(open(f"{d}/summary.json")) for k, d in D.items()}
def rot_deg(b):
    return np.degrees(2 * np.arctan2(b["qz"], b["qw"]))
rows = []
fig, ax = plt.subplots(1, 3, figsize=(17, 4.5))
names = sorted(B["native"]["body"].unique())
for name in names:
    r = {"block": name}
    for k in D:
        b = B[k][B[k]["body"] == name]
        r[f"dx_{k}_mm"] = 1e3 * (b["x"].iloc[-1] - b["x"].iloc[0])
        r[f"dy_{k}_mm"] = 1e3 * (b["y"].iloc[-1] - b["y"].iloc[0])
        r[f"rot_{k}_deg"] = float(rot_deg(b).iloc[-1])
        ls = "-" if k == "native" else "--"
        ax[0].plot(b["t"], 1e3 * (b["x"] - b["x"].iloc[0]), ls, label=f"{name} {k}")
        ax[1].plot(b["t"], rot_deg(b), ls)
    rows.append(r)
T = pd.DataFrame(rows)
for k in D:
    it = I[k]
    ax[2].plot(it["t"], it["fx_mpm"], "-" if k == "native" else "--", label=f"fx on MPM {k}")
    ax[2].plot(it["t"], it["fy_mpm"], "-" if k == "native" else "--", label=f"fy on MPM {k}")
ax[0].set_xlabel("t [s]"); ax[0].set_ylabel("x - x0 [mm]"); ax[0].legend(fontsize=6, ncol=2)
ax[1].set_xlabel("t [s]"); ax[1].set_ylabel("rotation about z [deg]")
ax[2].set_xlabel("t [s]"); ax[2].set_ylabel("interface force received by the MPM x thickness [N]"); ax[2].legend(fontsize=7)
fig.suptitle("coupled retaining wall: native DEM partition (solid) vs YADE partition (dashed), same native MPM")
fig.tight_layout(); fig.savefig(f"{out}/native_vs_yade_partition.png", dpi=110)
pd.set_option("display.width", 200)
print(T.round(3).to_string(index=False))
for k in D:
    it = I[k]
    for lo, hi in ((0.05, 0.1), (0.1, 0.2), (0.2, 0.3), (0.3, 0.4)):
        m = (it["t"] > lo) & (it["t"] <= hi)
        print(f"{k:7s} interface force on MPM mean over ({lo}, {hi}] s: fx {it.loc[m, 'fx_mpm'].mean():.4f} N fy {it.loc[m, 'fy_mpm'].mean():.4f} N")
    print(k, "wall", round(S[k]["wall_time_s"], 1), "s; cost per step us", {a: round(v) for a, v in S[k]["coupling"]["cost_per_step_us"].items()})
    if "yade_cost_per_step_us" in S[k]["coupling"]:
        print("   ", {a: round(v) for a, v in S[k]["coupling"]["yade_cost_per_step_us"].items()}, "p4", S[k]["coupling"]["yade_p4_dropped_contact_steps"])
T.to_csv(f"{out}/native_vs_yade_partition.csv", index=False)
