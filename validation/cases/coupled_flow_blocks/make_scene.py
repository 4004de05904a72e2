"""Writes coupled.toml and dem_only.toml (run once from this folder; the scene files are what the case reads).
Issue 15, "Flow impacting stacked blocks": a granular column of width L0 and height H0 against a back wall at
x = 0, released at t = 0 on a flat bed, collapses onto a stack of three blocks (rigid DEM clusters of 4 x 4 spheres,
R = 2.5 mm, 2 x 2 cm) standing on the bed at x = X_BLOCKS.

coupled.toml: the column is an MPM body (plane-strain Mohr-Coulomb, the Bui 2008 aluminium-bar parameters of
mpm_bui_collapse: rho 2650, E 0.84 MPa, nu 0.3, phi 19.8 deg, c = 0, psi = 0; geostatic initial stress); the
interface is its right and top sides: the right face becomes the flow front and the run-out surface, the top side
the upper slope; the bottom side stays on the bed (MPM friction boundary) and the left one on the back wall.
dem_only.toml: the same geometry with the column as spheres: ten horizontal 1 cm strips, alternately R = 1.4 and
1.0 mm (bidisperse, so the packing does not crystallise), each a seeded random packing (RSA, area fraction ~0.42,
a loose column released at t = 0, as xval_column), of the same mass per unit depth as the MPM column over the
coupling thickness (2R_block = 5 mm): grain density = 2650 L0 H0 THICKNESS / (sphere volume), so that the column /
block mass ratio is the same in both models.
Blocks: density such that a cluster (16 spheres) over THICKNESS has the mass per unit depth of a solid aluminium
block, 2700 x 0.02 x 0.02 = 1.08 kg/m (README, Units). Contacts: e = 0.5, mu = 0.4 for every pair (YADE takes one
friction); DEM grains, blocks and walls E = 100 MPa (soft grains, as xval_retaining_wall); the block contact with
the MPM column has the column's stiffness (README: c dt / m_node < 2 on the MPM boundary nodes)."""
import math

L0, H0 = 0.05, 0.10              # column width and height [m]
X_BLOCKS = 0.10                  # block centres x [m] (front face of the stack 4 cm from the column toe)
RB, NBX, NBY = 2.5e-3, 4, 4      # block spheres: radius, columns, rows (touching, 5 mm spacing)
BW, BH = 2 * RB * NBX, 2 * RB * NBY
THICKNESS = 2 * RB
RHO_AL, RHO_COL = 2700.0, 2650.0
V_BLOCK = NBX * NBY * 4.0 / 3.0 * math.pi * RB ** 3
RHO_BLOCK = RHO_AL * BW * BH * THICKNESS / V_BLOCK
STRIPS, GAP = 10, 1e-4
GRAINS = (("large", 1.4e-3, 34), ("small", 1.0e-3, 67))       # per strip: name, radius, count
V_GRAINS = sum(STRIPS // 2 * n * 4.0 / 3.0 * math.pi * r ** 3 for _, r, n in GRAINS)
RHO_GRAIN = RHO_COL * L0 * H0 * THICKNESS / V_GRAINS
T_END, OUT = 0.5, 2.5e-3
OUT_COUPLED = 5e-4               # the coupled impact is a sharp transient: sampled every 2.5 ms, the bottom block's
                                 # momentum balance misses by 21 % to t = 0.125 s (0.15 % at 0.5 ms, 0.7 % at 0.25 ms)
SLIVER = 0.1                     # mpm.boundary_sliver_fraction (coupler/mpm/kernels.py _sliver_weight): without it
                                 # the run stops at t = 0.2406 s (the top block kicked to ~5.7 m/s by the interface
                                 # wall, the boundary point that took the reaction flung off the grid)
SNAP = 0.01                      # coupled: MPM snapshot interval (at every 0.5 ms output: ~317 MB per run)
DT_DEM = 6.5e-6                  # DEM-only step: 0.38 x the stable limit (native default 0.4 x: 6.9e-6 s)
CELL, PPC = 0.005, 3             # MPM grid; 3 points per cell direction (2 flings the flow-front boundary point off
                                 # the grid at the first impact, t ~ 0.1 s: the sliver-mass node, coupler/mpm/kernels.py)
SEED = 11


def common(name: str, dem_materials: list[str], extra_materials: str, damping: str) -> list[str]:
    out = [f'name = "{name}"\ndimension = 2\ngravity = [0.0, -9.81, 0.0]\nseed = {SEED}\n\n'
           f"[time]\nt_end = {T_END:g}\n" + (f"dt = {DT_DEM:g}\n" if name.endswith("dem_only") else "")
           + f"output_interval = {OUT if name.endswith('dem_only') else OUT_COUPLED:g}\n"]
    out.append(f"[materials.block]\ndensity = {RHO_BLOCK:.3f}\nyoung = 1e8\npoisson = 0.3\n")
    out.append(extra_materials)
    mats = ["block"] + dem_materials
    for i, a in enumerate(mats):
        for b in mats[i:]:
            out.append(f'[[contacts]]\nmaterials = ["{a}", "{b}"]\nrestitution = 0.5\nfriction = 0.4\n')
    offs = ", ".join(f"[{i * 2 * RB:.4e}, {j * 2 * RB:.4e}, 0.0, {RB:.1e}]" for i in range(NBX) for j in range(NBY))
    out.append(f'[dem]\ncluster_damping_mass = "{damping}"\n\n[dem.templates.block]\nspheres = [{offs}]\n')
    for k in range(3):
        out.append(f'[[dem.clusters]]\nname = "block{k + 1}"\ntemplate = "block"\nmaterial = "block"\n'
                   f"position = [{X_BLOCKS:.4f}, {BH / 2 + BH * k:.4f}, 0.0]\n")
    out.append('[[dem.planes]]\nname = "floor"\nmaterial = "floor"\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 1.0, 0.0]\n')
    return out


def coupled() -> str:
    mats = (f"[materials.floor]\ndensity = 2700.0\nyoung = 1e8\npoisson = 0.3\n\n"
            f"[materials.column_wall]        # DEM material standing for the MPM column in the block contact\n"
            f"density = {RHO_COL:g}\nyoung = 0.84e6\npoisson = 0.3\n\n"
            f"[materials.aluminium_bars]\ndensity = {RHO_COL:g}\nyoung = 0.84e6\npoisson = 0.3\n")
    out = [f"# Coupled flow impacting stacked blocks (issue 15), generated by make_scene.py (its docstring says every "
           f"parameter and why).\n"]
    out += common("coupled_flow_blocks", ["floor", "column_wall"], mats, "body")
    out.append(f"[output]\nparticles_interval = {SNAP:g}   # MPM snapshots (the tables: every {OUT_COUPLED:g} s)\n")
    out.append(f"""[mpm]
shape_function = "bspline2"
transfer = "apic"
cfl = 0.5
boundary_particles = true
boundary_sliver_fraction = {SLIVER:g}   # support nodes < this fraction of full mass: mass-weighted share (issue 15)

[mpm.grid]
origin = [0.0, 0.0]
size = [0.3, 0.15]
cell_size = {CELL:g}

[mpm.boundary]
left = {{ kind = "slip" }}
right = {{ kind = "slip" }}
bottom = {{ kind = "friction", friction = 0.4 }}
top = {{ kind = "open" }}

[[mpm.bodies]]
name = "column"
material = "aluminium_bars"
rectangle = {{ min = [0.0, 0.0], max = [{L0:g}, {H0:g}] }}
particles_per_cell = {PPC}
constitutive = {{ model = "mohr_coulomb", friction_angle = 19.8, cohesion = 0.0, dilatancy = 0.0 }}
initial_stress = {{ kind = "geostatic" }}

[coupling]
body = "column"
sides = ["right", "top"]
material = "column_wall"
mapper = "nearest"
dem_substeps = "auto"
thickness = {THICKNESS:g}
""")
    return "\n".join(out)


def dem_only() -> str:
    mats = "".join(f"[materials.{m}]\ndensity = {d:.3f}\nyoung = 1e8\npoisson = 0.3\n\n"
                   for m, d in (("grain_large", RHO_GRAIN), ("grain_small", RHO_GRAIN), ("floor", 2700.0)))
    out = ["# DEM-only flow impacting stacked blocks (issue 15), generated by make_scene.py (its docstring says every "
           "parameter and why).\n"]
    out += common("flow_blocks_dem_only", ["grain_large", "grain_small", "floor"], mats, "body")
    h = H0 / STRIPS
    for k in range(STRIPS):
        size, r, n = GRAINS[k % 2]
        out.append(f'[[dem.packings]]\nname = "col{k}{size[0]}"\nmaterial = "grain_{size}"\nradius = {r:.1e}\n'
                   f"box_min = [{GAP:.4f}, {k * h + GAP:.4f}, 0.0]\nbox_max = [{L0 - GAP:.4f}, {(k + 1) * h:.4f}, 0.0]\n"
                   f"count = {n}\nseed = {k + 1}\n")
    out.append('[[dem.planes]]\nname = "back"\nmaterial = "floor"\npoint = [0.0, 0.0, 0.0]\nnormal = [1.0, 0.0, 0.0]\n')
    return "\n".join(out)


def main() -> None:
    open("coupled.toml", "w").write(coupled())
    open("dem_only.toml", "w").write(dem_only())


if __name__ == "__main__":
    main()
