"""Write a LIGGGHTS input script and data file for a DEM scene: spheres, axis-aligned plane walls and rigid clusters
(`fix multisphere`, one template per cluster template and material with the exact native mass and inertia, P7).

Prescribed cluster motion (`[[dem.clusters]] motion`, adapters/common.prescribed_motions): a held or driven body
gets a template of its own with `fflag off off off tflag off off off` (fix_multisphere.cpp: the force / torque
half kicks are skipped, so the body keeps the insertion velocity and angular momentum while its members still
touch, as the native body_kick), inserted with the prescribed velocity and spin. The release at `until` is
`run N` + `fix_modify ms fflag .. tflag ..` (the free flags of the scene) + `run` for the rest; fix_modify sets
the flags of every body, so all prescribed bodies of a scene must be released at one step (else
UnsupportedFeature). LIGGGHTS keeps the angular momentum of a flag-off body, the native solver its angular
velocity: a spin is accepted only about a principal axis (always so in 2D), where the two are the same motion."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from adapters.liggghts.params import (check_restitution_range, liggghts_model, liggghts_restitution, real_material,
                                      rolling_coefficient, type_names, type_young, wall_type)
from coupler.dem.timestep import chosen_dt
from adapters.common import prescribed_motions
from coupler.errors import UnsupportedFeature
from coupler.materials import pair_key
from coupler.scene import Scene

AXES = "xyz"


def check_supported(scene: Scene) -> None:
    dem = scene.dem
    if dem is None or scene.mpm is not None:
        raise UnsupportedFeature("liggghts", "mpm", "LIGGGHTS runs DEM-only scenes")
    if scene.gravity_schedule is not None:
        raise UnsupportedFeature("liggghts", "gravity_schedule", "a time-dependent gravity is not written in this adapter")
    _motions(scene)
    liggghts_model(scene)                       # one model for all pairs; Hooke / constant k_r not expressible
    check_restitution_range(scene)              # 0.05 < coefficientRestitution <= 1
    if dem.clusters:
        if dem.cluster_damping_mass == "sphere":
            raise UnsupportedFeature("liggghts", "dem.cluster_damping_mass",
                                     "LIGGGHTS multisphere damps with the body mass only (notes P5)")
        if scene.output.contacts:
            raise UnsupportedFeature("liggghts", "output.contacts",
                                     "contact rows of multisphere members are not mapped to the contact table")


def _motions(scene: Scene) -> tuple[dict, int | None]:
    """Prescribed motions by cluster name, and the one step after which they end (None: held to the end)."""
    dt = chosen_dt(scene)
    rows = prescribed_motions("liggghts", scene, dt, int(round(scene.time.t_end / dt)))
    releases = {r.release_step for r in rows}
    if len(releases) > 1:
        raise UnsupportedFeature("liggghts", f"dem.clusters[{rows[0].index}].motion.until",
                                 "LIGGGHTS releases multisphere bodies all at once (fix_modify ms fflag/tflag): give "
                                 "every prescribed cluster the same `until`")
    if rows:
        from coupler.dem.clusters import mass_properties
        for r in rows:
            c = scene.dem.clusters[r.index]
            w = r.angular_velocity
            if np.any(w != 0.0):
                t = scene.dem.templates[c.template]
                I = mass_properties(t, scene.materials[c.material].density, "").inertia
                R = _quat_matrix(c.orientation)
                L = R @ I @ R.T @ w
                if np.linalg.norm(np.cross(L, w)) > 1e-9 * np.linalg.norm(L) * np.linalg.norm(w):
                    raise UnsupportedFeature("liggghts", f"dem.clusters[{r.index}].motion.angular_velocity",
                                             "a prescribed spin must be about a principal axis of the body "
                                             "(LIGGGHTS holds its angular momentum, not its angular velocity)")
    return {r.name: r for r in rows}, (rows[0].release_step if rows else None)


def _quat_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def primitive(p) -> bool:
    """A plane LIGGGHTS can take as a primitive wall: normal along x, y or z and at rest (primitive walls take a
    constant position only). Other planes are written as a mesh polygon covering the domain (walls())."""
    return np.count_nonzero(p.normal) == 1 and not np.any(p.velocity != 0.0)


def box(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """The region the walls must cover (and the data-file box): every body and wall position at t = 0 (mesh nodes
    also at t_end), padded by max(2 bounding radii, 20 sphere radii, a tenth of the extent); 2D: 5 bounding radii
    in z."""
    dem = scene.dem
    pts = [dem.position] + [c.position[None, :] for c in dem.clusters]
    r = max([float(dem.radius.max()) if dem.n_spheres else 0.0]
            + [float(np.linalg.norm(dem.templates[c.template].offsets, axis=1).max()
                     + dem.templates[c.template].radii.max()) for c in dem.clusters])
    for m in dem.meshes:
        pts += [m.vertices, m.vertices + m.velocity * scene.time.t_end]
    allp = np.concatenate(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    for p in dem.planes:
        if primitive(p):
            a = int(np.nonzero(p.normal)[0][0])
            lo[a] = min(lo[a], p.point[a])
            hi[a] = max(hi[a], p.point[a])
    rs = max([float(dem.radius.max()) if dem.n_spheres else 0.0]
             + [float(dem.templates[c.template].radii.max()) for c in dem.clusters])
    pad = np.full(3, max(2.0 * r, 20.0 * rs, 0.1 * float((hi - lo).max())))   # `boundary m m m` grows it
    if scene.dimension == 2:
        pad[2] = 5.0 * r            # a thin slab: LIGGGHTS bins the whole box (a cube here made 79 % neighbour time)
    return lo - pad, hi + pad


def walls(scene: Scene, out: Path | None = None) -> tuple[list[dict], np.ndarray, np.ndarray]:
    """Wall specs in dump-column order, the covered region (box()) and the simulation box. Primitive planes ->
    `wall/gran primitive`; other planes -> one triangle containing the plane's section of the covered region grown
    by |v| t_end, as a mesh moved by `fix move/mesh linear` (exact while every body stays in the covered region:
    the parser checks); mesh walls -> STL (2D segments: strips along z, adapters/geometry.py). The simulation box
    holds every mesh node for the whole run (LIGGGHTS deletes mesh elements outside it, fix_mesh.cpp)."""
    from adapters.geometry import mesh_triangles, plane_triangle, write_stl
    dem = scene.dem
    T = scene.time.t_end
    lo, hi = box(scene)
    specs = []
    for k, p in enumerate(dem.planes):
        if primitive(p):
            specs.append({"name": p.name, "kind": "primitive", "fix": f"w{k}", "material": wall_type(p),
                          "axis": int(np.nonzero(p.normal)[0][0]), "point": p.point, "normal": p.normal,
                          "velocity": p.velocity})
            continue
        grow = float(np.linalg.norm(p.velocity)) * T
        try:
            v, tri = plane_triangle(p.point, p.normal, lo - grow, hi + grow)
        except ValueError:
            raise UnsupportedFeature("liggghts", f"dem.planes[{k}]", f"the plane lies outside the region of the bodies "
                                     f"[{lo.tolist()}, {hi.tolist()}]; a moving or tilted plane is written as a mesh "
                                     f"triangle, which LIGGGHTS needs inside its simulation box") from None
        specs.append({"name": p.name, "kind": "plane_mesh", "fix": f"w{k}", "mesh_fix": f"mp{k}",
                      "stl": f"plane{k}.stl", "material": wall_type(p), "point": p.point, "normal": p.normal,
                      "velocity": p.velocity, "vertices": v, "triangles": tri})
    for k, m in enumerate(dem.meshes):
        v, tri = mesh_triangles(m.vertices, m.faces, 0.25 * float((hi - lo)[2]))
        specs.append({"name": m.name, "kind": "mesh", "fix": f"wm{k}", "mesh_fix": f"m{k}", "stl": f"mesh{k}.stl",
                      "material": wall_type(m), "velocity": m.velocity, "vertices": v, "triangles": tri})
    if out is not None:
        for w in specs:
            if w["kind"] != "primitive":
                write_stl(out / w["stl"], w["vertices"], w["triangles"], w["name"])
    slo, shi = lo.copy(), hi.copy()
    for w in specs:
        if w["kind"] != "primitive":
            for x in (w["vertices"], w["vertices"] + w["velocity"] * T):
                slo, shi = np.minimum(slo, x.min(axis=0)), np.maximum(shi, x.max(axis=0))
    margin = 0.01 * float((shi - slo).max()) if (slo < lo).any() or (shi > hi).any() else 0.0
    return specs, (lo, hi), (slo - margin, shi + margin)


def write_inputs(scene: Scene, out: Path) -> dict:
    """Write in.liggghts + data.spheres into out; return run facts (dt, steps, output stride, type map).
    The box shrink-wraps the spheres (`boundary m m m`); data-file bounds only seed it."""
    check_supported(scene)
    dem = scene.dem
    mats = type_names(scene)              # materials, then one type per rigid wall material (params.py)
    tid = {m: k + 1 for k, m in enumerate(mats)}
    dt = chosen_dt(scene)
    steps = int(round(scene.time.t_end / dt))
    every = max(1, int(round(scene.time.output_interval / dt)))
    specs, cover, (lo, hi) = walls(scene, out)
    n = dem.n_spheres
    rho = np.array([scene.materials[m].density for m in dem.material])
    lines = ["LIGGGHTS data file written by mpmdem", "", f"{n} atoms", f"{len(mats)} atom types", ""]
    for a in range(3):
        lines.append(f"{lo[a]:.12g} {hi[a]:.12g} {AXES[a]}lo {AXES[a]}hi")
    if n:
        lines += ["", "Atoms", ""]
        for i in range(n):
            x = dem.position[i]
            lines.append(f"{i + 1} {tid[dem.material[i]]} {2 * dem.radius[i]:.15g} {rho[i]:.15g} "
                         f"{x[0]:.15g} {x[1]:.15g} {x[2]:.15g}")
        lines += ["", "Velocities", ""]
        for i in range(n):
            v, w = dem.velocity[i], dem.angular_velocity[i]
            lines.append(f"{i + 1} {v[0]:.15g} {v[1]:.15g} {v[2]:.15g} {w[0]:.15g} {w[1]:.15g} {w[2]:.15g}")
    (out / "data.spheres").write_text("\n".join(lines) + "\n")

    def matrix(fn):
        vals = []
        for a in mats:
            for b in mats:
                key = pair_key(real_material(a), real_material(b))
                vals.append(f"{fn(scene.contacts[key]):.15g}" if key in scene.contacts else "0.5")
        return " ".join(vals)

    from coupler.dem.scene import smallest_radius
    skin = dem.skin if dem.skin is not None else 0.3 * smallest_radius(dem)      # the native default
    g = scene.gravity
    gn = float(np.linalg.norm(g))
    model = liggghts_model(scene)
    s = [
        "# written by mpmdem (adapters/liggghts); parameter map: adapters/liggghts/params.py",
        "units si", "atom_style granular", "atom_modify map array", "boundary m m m", "newton off",
        "communicate single vel yes", "hard_particles yes",                             # P14
        "read_data data.spheres",
        f"group free id <= {n}",                       # spheres of the data file; cluster members come later
        f"neighbor {skin:.10g} bin", "neigh_modify delay 0",
        "fix m1 all property/global youngsModulus peratomtype " + " ".join(f"{type_young(scene, m):.15g}" for m in mats),
        "fix m2 all property/global poissonsRatio peratomtype " + " ".join(f"{scene.materials[real_material(m)].poisson:.15g}"
                                                                           for m in mats),
        f"fix m3 all property/global coefficientRestitution peratomtypepair {len(mats)} {matrix(liggghts_restitution)}",
        f"fix m4 all property/global coefficientFriction peratomtypepair {len(mats)} {matrix(lambda l: l.friction)}",
        f"pair_style gran {model} limitForce on",                                      # P2
        "pair_coeff * *",
        f"timestep {dt:.15g}",
    ]
    if "rolling_friction" in model:
        s.insert(s.index("pair_coeff * *") - 1, f"fix m5 all property/global coefficientRollingFriction "
                                                 f"peratomtypepair {len(mats)} {matrix(rolling_coefficient)}")
    if gn > 0:
        s.append(f"fix grav all gravity {gn:.15g} vector {g[0] / gn:.15g} {g[1] / gn:.15g} {g[2] / gn:.15g}")
    wall_cols = []
    for w in specs:
        if w["kind"] == "primitive":
            a = w["axis"]
            s.append(f"fix {w['fix']} all wall/gran {model} primitive type {tid[w['material']]} "
                     f"{AXES[a]}plane {w['point'][a]:.15g} store_force yes limitForce on")
        else:
            s.append(f"fix {w['mesh_fix']} all mesh/surface file {w['stl']} type {tid[w['material']]}")
            v = w["velocity"]
            if np.any(v != 0.0):
                s.append(f"fix mv_{w['mesh_fix']} all move/mesh mesh {w['mesh_fix']} linear "
                         f"{v[0]:.17g} {v[1]:.17g} {v[2]:.17g}")
            s.append(f"fix {w['fix']} all wall/gran {model} mesh n_meshes 1 meshes "
                     f"{w['mesh_fix']} store_force yes limitForce on")                          # P2, P3
        wall_cols += [f"f_force_{w['fix']}[1]", f"f_force_{w['fix']}[2]", f"f_force_{w['fix']}[3]"]
    if n:
        s.append("fix integr free nve/sphere")
        if scene.dimension == 2:
            s.append("fix planar free planeforce 0 0 1")
    if dem.clusters:
        s += _multisphere(scene, out, tid, dt)
    cols = ["id", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz"] + wall_cols
    s.append(f"dump da free custom {every} atoms.dump {' '.join(cols)}")
    s.append("dump_modify da sort id format \"%d" + " %.15g" * (len(cols) - 1) + "\"")
    if scene.output.contacts and n > 1:
        s.append("compute pc all pair/gran/local id force delta")
        s.append(f"dump dc all local {every} pairs.dump c_pc[1] c_pc[2] c_pc[3] c_pc[4] c_pc[5] c_pc[6] c_pc[7]")
        s.append("dump_modify dc format \"%.0f %.0f %.0f %.15g %.15g %.15g %.15g\"")
    if dem.clusters:
        props = ["id_multisphere", "xcm", "vcm", "quat", "omega", "angmom"]
        cref = []
        for p_ in props:
            s.append(f"compute b_{p_} all multisphere property {p_}")
            cref += [f"c_b_{p_}"] if p_ == "id_multisphere" else [f"c_b_{p_}[{k + 1}]" for k in range(4 if p_ == "quat" else 3)]
        s.append(f"dump db all local {every} bodies.dump {' '.join(cref)}")
        s.append("dump_modify db format \"%.0f" + " %.17g" * (len(cref) - 1) + "\"")
    s.append("thermo 100000")
    s.append("thermo_modify lost error")                 # a sphere may never disappear silently
    release = _motions(scene)[1] if dem.clusters else None
    if release is not None:                               # prescribed motions end after step `release`
        free = "fflag on on off tflag off off on" if scene.dimension == 2 else "fflag on on on tflag on on on"
        s += [f"run {release}", f"fix_modify ms {free}", f"run {steps - release}"]
    else:
        s.append(f"run {steps}")
    if steps % every:                                     # the final state, like the native output
        s.append("undump da")
        s.append(f"dump df free custom 1 atoms.dump {' '.join(cols)}")     # free spheres, as `da`
        s.append("dump_modify df sort id append yes format \"%d" + " %.15g" * (len(cols) - 1) + "\"")
        if dem.clusters:
            s.append("undump db")
            s.append(f"dump dbf all local 1 bodies.dump {' '.join(cref)}")
            s.append("dump_modify dbf append yes format \"%.0f" + " %.17g" * (len(cref) - 1) + "\"")
        s.append("run 0")
    (out / "in.liggghts").write_text("\n".join(s) + "\n")
    return {"dt": dt, "steps": steps, "every": every, "types": tid, "walls": specs, "cover": cover}


def prime_seed(k: int) -> int:
    """The k-th prime above 15485863: LIGGGHTS random seeds must be primes > 10000 (random.cpp)."""
    n, found = 15485862, -1
    while found < k:
        n += 1
        if n % 2 and all(n % d for d in range(3, int(n ** 0.5) + 1, 2)):
            found += 1
    return n


INSERT_DT = 1e-15      # the insertion step (multisphere bodies appear in the step after `fix insert/pack`)
REGION_HALF = 1e-15    # half-size of the box in which each body's centre of mass is inserted [m]


def _multisphere(scene: Scene, out: Path, tid: dict, dt: float) -> list[str]:
    """Templates, one insertion per cluster (exact position, orientation, velocity), the multisphere integrator.

    Each body is inserted by `fix insert/pack` into a box of +-1e-15 m around its centre of mass with
    `orientation constant` (LIGGGHTS places member j at x + R(q) (d_j), d_j the template offset from the COM:
    particleToInsert_multisphere.cpp), during one step of 1e-15 s; then the insert fixes are removed, the step
    counter reset and the real time step set. Mass and inertia are the native exact values (P7), the template
    spheres are given relative to the exact COM (with `mass` + `use_density` LIGGGHTS does no Monte Carlo COM)."""
    from coupler.dem.clusters import mass_properties
    dem = scene.dem
    planar = scene.dimension == 2
    motions = _motions(scene)[0]
    keys: dict[tuple[str, str, bool], int] = {}
    lines = []
    for c in dem.clusters:
        key = (c.template, c.material, c.name in motions)
        if key in keys:
            continue
        keys[key] = len(keys) + 1
        k = keys[key]
        t = dem.templates[c.template]
        rho = scene.materials[c.material].density
        mp = mass_properties(t, rho, f"dem.templates.{c.template}")
        d = t.offsets - mp.center
        (out / f"template{k}.txt").write_text("\n".join(f"{a:.17g} {b:.17g} {e:.17g} {r:.17g}"
                                                     for (a, b, e), r in zip(d, t.radii)) + "\n")
        I = mp.inertia
        flags = " fflag on on off tflag off off on" if planar else ""
        if key[2]:                                  # prescribed: no force / torque kicks until the release
            flags = " fflag off off off tflag off off off"
        lines.append(f"fix pts{k} all particletemplate/multisphere {prime_seed(3 * k)} atom_type {tid[c.material]} "
                     f"density constant {rho:.17g} nspheres {len(t.radii)} ntry 1000000 spheres file template{k}.txt scale 1.0 "
                     f"type {k} mass {mp.mass:.17g} inertia_tensor {I[0, 0]:.17g} {I[0, 1]:.17g} {I[0, 2]:.17g} "
                     f"{I[1, 1]:.17g} {I[1, 2]:.17g} {I[2, 2]:.17g} use_density{flags}")
        lines.append(f"fix pdd{k} all particledistribution/discrete {prime_seed(3 * k + 1)} 1 pts{k} 1.0")
    lines.append("fix ms all multisphere")
    for b, c in enumerate(dem.clusters):
        k = keys[(c.template, c.material, c.name in motions)]
        x, v, w, q = c.position, c.velocity, c.angular_velocity, c.orientation
        if c.name in motions:
            v, w = motions[c.name].velocity, motions[c.name].angular_velocity
        box_ = " ".join(f"{x[a] - REGION_HALF:.17g} {x[a] + REGION_HALF:.17g}" for a in range(3))
        lines.append(f"region rb{b} block {box_} units box volume_limit 1e-60")
        lines.append(f"fix ins{b} all insert/pack seed {prime_seed(3 * len(keys) + 3 + b)} distributiontemplate pdd{k} "
                     f"vel constant {v[0]:.17g} {v[1]:.17g} {v[2]:.17g} "
                     f"omega constant {w[0]:.17g} {w[1]:.17g} {w[2]:.17g} "
                     f"orientation constant {q[0]:.17g} {q[1]:.17g} {q[2]:.17g} {q[3]:.17g} "
                     f"insert_every once overlapcheck no all_in no particles_in_region 1 region rb{b} ntry_mc 1000")
    lines.append(f"timestep {INSERT_DT:g}")
    lines.append("run 1")
    lines += [f"unfix ins{b}" for b in range(len(dem.clusters))]
    lines.append("reset_timestep 0")
    lines.append(f"timestep {dt:.15g}")
    return lines
