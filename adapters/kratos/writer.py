"""Write the Kratos input of a scene into the run folder: .mdpa files, ProjectParameters*.json, Materials*.json and
the python script (run_kratos.py) that runs the analysis stage and records the states the parser reads.
The parameter map is adapters/kratos/params.py."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from adapters.kratos.params import (GRID_ELEMENT, MPM_ELEMENT, check_supported, kratos_restitution, mpm_law,
                                    wall_base, wall_material, wall_young,
                                    native_beta, tangential_penalty, convergence_criterion)
from coupler.dem.timestep import chosen_dt
from coupler.scene import Scene

PROBLEM = "mpmdem"


def _v(x) -> str:
    return f"{float(x):.17g}"


# ------------------------------------------------------------------------------------------------------------ DEM
def plane_quad(p, rmax: float, pos: np.ndarray, vel: np.ndarray, t_end: float) -> tuple[np.ndarray, float]:
    """Corners of a square in the plane, centred on the projection of the spheres' centroid, half-size covering
    every sphere's reach (initial spread + max speed * t_end + wall travel + 4 R_max). Returns (4x3, half size)."""
    n = np.asarray(p.normal, float)
    a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    c = pos.mean(0) if len(pos) else np.asarray(p.point, float)
    c = c - ((c - p.point) @ n) * n
    spread = float(np.max(np.linalg.norm(pos - c, axis=1))) if len(pos) else 0.0
    vmax = float(np.max(np.linalg.norm(vel, axis=1))) if len(vel) else 0.0
    half = spread + (vmax + float(np.linalg.norm(p.velocity))) * t_end * 2.0 + 4.0 * rmax
    corners = np.array([c - half * a - half * b, c + half * a - half * b, c + half * a + half * b,
                        c - half * a + half * b])
    if np.cross(corners[1] - corners[0], corners[2] - corners[0]) @ n < 0:
        corners = corners[::-1].copy()
    return corners, half


def dem_materials(scene: Scene) -> tuple[dict, list]:
    """Kratos materials json and the (law name, e', beta, mu) per contact pair."""
    dem = scene.dem
    used = sorted(set(dem.material))
    wall_used = sorted({wall_material(w) for w in list(dem.planes) + list(dem.meshes)})   # "<mat>__wall" / "__rigidwall"
    mats, ids = [], {}
    for name in used:
        m = scene.materials[name]
        ids[name] = len(mats) + 1
        mats.append({"material_name": name, "material_id": ids[name],
                     "Variables": {"PARTICLE_DENSITY": m.density, "YOUNG_MODULUS": m.young,
                                   "POISSON_RATIO": m.poisson}})
    for kname in wall_used:
        m = scene.materials[wall_base(kname)]
        ids[kname] = len(mats) + 1
        mats.append({"material_name": kname, "material_id": ids[kname],
                     "Variables": {"YOUNG_MODULUS": wall_young(scene, kname), "POISSON_RATIO": m.poisson,
                                   "COMPUTE_WEAR": False}})
    rel, pairs = [], []
    from coupler.materials import pair_key

    def add(a, ka, b, kb):
        law = scene.contacts[pair_key(a, b)]
        e = kratos_restitution(law)
        rel.append({"material_names_list": [ka, kb], "material_ids_list": [ids[ka], ids[kb]],
                    "Variables": {"COEFFICIENT_OF_RESTITUTION": e, "STATIC_FRICTION": law.friction,
                                  "DYNAMIC_FRICTION": law.friction, "FRICTION_DECAY": 500.0,
                                  "ROLLING_FRICTION": 0.0, "ROLLING_FRICTION_WITH_WALLS": 0.0,
                                  "DEM_DISCONTINUUM_CONSTITUTIVE_LAW_NAME": "DEM_D_Hertz_viscous_Coulomb"}})
        pairs.append({"a": ka, "b": kb, "ids": [ids[ka], ids[kb]], "restitution_kratos": e,
                      "beta_native": native_beta(law), "friction": law.friction})

    for i, a in enumerate(used):
        for b in used[i:]:
            if pair_key(a, b) in scene.contacts:
                add(a, a, b, b)
        for kw in wall_used:
            if pair_key(a, wall_base(kw)) in scene.contacts:
                add(a, a, wall_base(kw), kw)
    table = [[f"SpheresPart.mat_{n}", n] for n in used] + [[f"RigidFacePart.wall_{k}", wall_material(w)]
                                                           for k, w in enumerate(list(dem.planes) + list(dem.meshes))]
    return {"materials": mats, "material_relations": rel, "material_assignation_table": table}, pairs


def _spheres_mdpa(scene: Scene) -> str:
    dem = scene.dem
    s = ["Begin ModelPartData", "End ModelPartData", "", "Begin Properties 0", "End Properties", "", "Begin Nodes"]
    for k, x in enumerate(dem.position):
        s.append(f"  {k + 1} {_v(x[0])} {_v(x[1])} {_v(x[2])}")
    s += ["End Nodes", "", "Begin Elements SphericParticle3D"]
    s += [f"  {k + 1} 0 {k + 1}" for k in range(dem.n_spheres)]
    s += ["End Elements", "", "Begin NodalData RADIUS"]
    s += [f"  {k + 1} 0 {_v(r)}" for k, r in enumerate(dem.radius)]
    s += ["End NodalData", ""]
    for name in sorted(set(dem.material)):
        idx = [k + 1 for k, m in enumerate(dem.material) if m == name]
        s += [f"Begin SubModelPart mat_{name}", "  Begin SubModelPartNodes"] + [f"    {i}" for i in idx]
        s += ["  End SubModelPartNodes", "  Begin SubModelPartElements"] + [f"    {i}" for i in idx]
        s += ["  End SubModelPartElements", "End SubModelPart", ""]
    return "\n".join(s) + "\n"


def _walls_mdpa(scene: Scene, t_end: float) -> tuple[str, list]:
    dem = scene.dem
    rmax = float(dem.radius.max()) if dem.n_spheres else 0.0
    nodes, conds, subs, cover = [], [], [], []
    nid = dem.n_spheres
    cid = 0
    walls = list(dem.planes) + list(dem.meshes)
    for k, w in enumerate(walls):
        if hasattr(w, "normal"):
            corners, half = plane_quad(w, rmax, dem.position, dem.velocity, t_end)
            ids = list(range(nid + 1, nid + 5))
            nodes += list(zip(ids, corners))
            nid += 4
            cid += 1
            elems = [("RigidFace3D4N", cid, ids)]
            cover.append({"wall": w.name, "centre": corners.mean(0).tolist(), "half": half,
                          "normal": np.asarray(w.normal, float).tolist()})
        else:
            if w.faces.shape[1] != 3:
                from coupler.errors import UnsupportedFeature
                raise UnsupportedFeature("kratos", f"dem.meshes[{k}]", "2D segment meshes are not written "
                                                                       "(give triangles)")
            ids = list(range(nid + 1, nid + 1 + len(w.vertices)))
            nodes += list(zip(ids, w.vertices))
            nid += len(w.vertices)
            elems = []
            for f in w.faces:
                cid += 1
                elems.append(("RigidFace3D3N", cid, [ids[i] for i in f]))
        conds.append(elems)
        subs.append((k, w, ids, [e[1] for e in elems]))
    s = ["Begin ModelPartData", "End ModelPartData", "", "Begin Properties 0", "End Properties", "", "Begin Nodes"]
    s += [f"  {i} {_v(x[0])} {_v(x[1])} {_v(x[2])}" for i, x in nodes]
    s += ["End Nodes", ""]
    for elems in conds:
        by_kind: dict[str, list] = {}
        for kind, c, ids in elems:
            by_kind.setdefault(kind, []).append(f"  {c} 0 {' '.join(map(str, ids))}")
        for kind, rows in by_kind.items():
            s += [f"Begin Conditions {kind}"] + rows + ["End Conditions", ""]
    for k, w, ids, cs in subs:
        v = np.asarray(w.velocity, float)
        moving = bool(np.any(v != 0.0))
        s += [f"Begin SubModelPart wall_{k} // {w.name}", "  Begin SubModelPartData",
              f"    LINEAR_VELOCITY [3] ({_v(v[0])}, {_v(v[1])}, {_v(v[2])})", "    VELOCITY_PERIOD 0.0",
              "    ANGULAR_VELOCITY [3] (0.0, 0.0, 0.0)", "    ROTATION_CENTER [3] (0.0, 0.0, 0.0)",
              "    ANGULAR_VELOCITY_PERIOD 0.0", "    VELOCITY_START_TIME 0.0", "    VELOCITY_STOP_TIME 1e30",
              "    ANGULAR_VELOCITY_START_TIME 0.0", "    ANGULAR_VELOCITY_STOP_TIME 1e30",
              "    FIXED_MESH_OPTION 0", f"    RIGID_BODY_MOTION {1 if moving else 0}", "    FREE_BODY_MOTION 0",
              "    IS_GHOST 0", f"    IDENTIFIER wall_{k}", "    TOP 0", "    BOTTOM 0", "    FORCE_INTEGRATION_GROUP 0",
              "  End SubModelPartData", "  Begin SubModelPartNodes"] + [f"    {i}" for i in ids]
        s += ["  End SubModelPartNodes", "  Begin SubModelPartConditions"] + [f"    {c}" for c in cs]
        s += ["  End SubModelPartConditions", "End SubModelPart", ""]
    return "\n".join(s) + "\n", cover


EMPTY_MDPA = "Begin ModelPartData\nEnd ModelPartData\n\nBegin Properties 0\nEnd Properties\n\nBegin Nodes\nEnd Nodes\n"


def write_dem(scene: Scene, out: Path) -> dict:
    dem = scene.dem
    dt = chosen_dt(scene)
    steps = int(round(scene.time.t_end / dt))
    every = max(1, int(round(scene.time.output_interval / dt)))
    g = np.asarray(scene.gravity, float)
    materials, pairs = dem_materials(scene)
    (out / "MaterialsDEM.json").write_text(json.dumps(materials, indent=2) + "\n")
    (out / f"{PROBLEM}DEM.mdpa").write_text(_spheres_mdpa(scene))
    walls_text, cover = _walls_mdpa(scene, scene.time.t_end)
    (out / f"{PROBLEM}DEM_FEM_boundary.mdpa").write_text(walls_text)
    (out / f"{PROBLEM}DEM_Clusters.mdpa").write_text(EMPTY_MDPA)
    (out / f"{PROBLEM}DEM_Inlet.mdpa").write_text(EMPTY_MDPA)
    big = 1e3 * (1.0 + float(np.max(np.abs(dem.position))) if dem.n_spheres else 1.0)
    params = {
        "Dimension": 3, "PeriodicDomainOption": False, "BoundingBoxOption": False,
        "AutomaticBoundingBoxOption": False, "BoundingBoxEnlargementFactor": 1.0,
        "BoundingBoxMaxX": big, "BoundingBoxMaxY": big, "BoundingBoxMaxZ": big,
        "BoundingBoxMinX": -big, "BoundingBoxMinY": -big, "BoundingBoxMinZ": -big,
        "dem_inlet_option": False, "GravityX": g[0], "GravityY": g[1], "GravityZ": g[2],
        "RotationOption": True, "CleanIndentationsOption": False,
        "solver_settings": {"RemoveBallsInitiallyTouchingWalls": False, "strategy": "sphere_strategy",
                            "material_import_settings": {"materials_filename": "MaterialsDEM.json"}},
        "VirtualMassCoefficient": 1.0, "RollingFrictionOption": False, "GlobalDamping": 0.0,
        "ContactMeshOption": False, "OutputFileType": "Ascii", "Multifile": "single_file",
        "ElementType": "SphericPartDEMElement3D", "TranslationalIntegrationScheme": "Symplectic_Euler",
        "RotationalIntegrationScheme": "Direct_Integration", "MaxTimeStep": dt,
        "FinalTime": steps * dt * (1.0 + 1e-9), "NeighbourSearchFrequency": 1,
        "GraphExportFreq": 1e30, "VelTrapGraphExportFreq": 1e30, "OutputTimeStep": 1e30,
        "PostDisplacement": False, "PostRadius": False, "PostVelocity": False, "PostAngularVelocity": False,
        "PostElasticForces": False, "PostContactForces": False, "PostRigidElementForces": False,
        "PostStressStrainOption": False, "PostTangentialElasticForces": False, "PostTotalForces": False,
        "PostPressure": False, "PostShearStress": False, "PostNonDimensionalVolumeWear": False,
        "PostParticleMoment": False, "PostEulerAngles": False, "PostRollingResistanceMoment": False,
        "problem_name": PROBLEM,
    }
    (out / "ProjectParametersDEM.json").write_text(json.dumps(params, indent=2) + "\n")
    facts = {"kind": "dem", "dt": dt, "steps": steps, "every": every, "planar": scene.dimension == 2,
             "velocity": dem.velocity.tolist(), "angular_velocity": dem.angular_velocity.tolist(),
             "pairs": pairs, "cover": cover}
    (out / "kratos_input.json").write_text(json.dumps(facts, indent=2) + "\n")
    (out / "run_kratos.py").write_text(DEM_SCRIPT)
    return facts


DEM_SCRIPT = r'''# written by mpmdem (adapters/kratos/writer.py); parameter map: adapters/kratos/params.py
import csv, json, time
import KratosMultiphysics as KM
import KratosMultiphysics.DEMApplication as DEM
from KratosMultiphysics.DEMApplication.DEM_analysis_stage import DEMAnalysisStage

F = json.load(open("kratos_input.json"))
DT, STEPS, EVERY = F["dt"], F["steps"], F["every"]


class Stage(DEMAnalysisStage):
    def Initialize(self):
        super().Initialize()
        nodes = sorted(self.spheres_model_part.Nodes, key=lambda n: n.Id)
        for n in nodes:
            v, w = F["velocity"][n.Id - 1], F["angular_velocity"][n.Id - 1]
            n.SetSolutionStepValue(KM.VELOCITY, KM.Array3(v))
            n.SetSolutionStepValue(KM.ANGULAR_VELOCITY, KM.Array3(w))
            if F["planar"]:                          # spheres in the x-y plane (params.py: not Kratos' 2D cylinders)
                n.SetSolutionStepValue(KM.VELOCITY_Z, 0.0)
                n.Fix(KM.VELOCITY_Z)
                n.SetSolutionStepValue(KM.ANGULAR_VELOCITY_X, 0.0)
                n.Fix(KM.ANGULAR_VELOCITY_X)
                n.SetSolutionStepValue(KM.ANGULAR_VELOCITY_Y, 0.0)
                n.Fix(KM.ANGULAR_VELOCITY_Y)
        self.nodes = nodes
        gam = []
        for p in F["pairs"]:                         # the damping Kratos derived from the restitution we passed
            props = self.spheres_model_part.GetProperties(p["ids"][0])
            sub = props.GetSubProperties(p["ids"][1])
            gam.append({"a": p["a"], "b": p["b"], "gamma": sub[DEM.DAMPING_GAMMA], "beta_native": p["beta_native"],
                        "static_friction": sub[DEM.STATIC_FRICTION]})
        json.dump(gam, open("kratos_gamma.json", "w"), indent=1)
        self.step_count = 0
        self.st = open("kratos_states.csv", "w", newline="")
        self.fc = open("kratos_forces.csv", "w", newline="")
        self.sw, self.fw = csv.writer(self.st), csv.writer(self.fc)
        self.sw.writerow(["step", "id", "x", "y", "z", "vx", "vy", "vz", "wx", "wy", "wz"])
        self.fw.writerow(["step", "id", "fx", "fy", "fz"])
        self.record_state(0)
        self.t_loop = time.perf_counter()

    def record_state(self, step):
        for n in self.nodes:
            v = n.GetSolutionStepValue(KM.VELOCITY)
            w = n.GetSolutionStepValue(KM.ANGULAR_VELOCITY)
            self.sw.writerow([step, n.Id, repr(n.X), repr(n.Y), repr(n.Z), repr(v[0]), repr(v[1]), repr(v[2]),
                              repr(w[0]), repr(w[1]), repr(w[2])])

    def KeepAdvancingSolutionLoop(self):
        return self.step_count < STEPS

    def OutputSolutionStep(self):
        # Symplectic Euler: the contact forces of this step were computed at the positions of the previous step
        self.step_count += 1
        k = self.step_count
        if (k - 1) % EVERY == 0:
            for n in self.nodes:
                f = n.GetSolutionStepValue(DEM.CONTACT_FORCES)
                if f[0] != 0.0 or f[1] != 0.0 or f[2] != 0.0:
                    self.fw.writerow([k - 1, n.Id, repr(f[0]), repr(f[1]), repr(f[2])])
        if k % EVERY == 0 or k == STEPS:
            self.record_state(k)

    def Finalize(self):
        loop = time.perf_counter() - self.t_loop
        self.st.close()
        self.fc.close()
        json.dump({"loop_time_s": loop, "steps": self.step_count,
                   "time": self.spheres_model_part.ProcessInfo[KM.TIME]}, open("timing_kratos.json", "w"))
        super().Finalize()


if __name__ == "__main__":
    KM.Logger.GetDefaultOutput().SetSeverity(KM.Logger.Severity.WARNING)
    with open("ProjectParametersDEM.json") as fh:
        params = KM.Parameters(fh.read())
    Stage(KM.Model(), params).Run()
'''


def write_inputs(scene: Scene, out: Path, initial_velocity: tuple[str, str] | None = None,
                 snapshot_every: int = 1, stress_free_start: bool = False, friction: str | None = None) -> dict:
    """initial_velocity (MPM only): expressions of x, y (math functions allowed) for the material points' initial
    (vx, vy), replacing the bodies' uniform velocity (the elastic bar's first-mode field). snapshot_every (MPM only):
    a material-point snapshot every that many output times (body rows and energy at every output time).
    friction (MPM only): the substitute for a friction wall, params.FRICTION_SUBSTITUTES (refused without)."""
    check_supported(scene, stress_free_start, friction)
    if scene.dem is not None and scene.mpm is None:
        return write_dem(scene, out)
    if scene.mpm is not None and scene.dem is None:
        facts = write_mpm(scene, out, initial_velocity, snapshot_every, friction)
        if any(b.k0 is not None for b in scene.mpm.bodies):
            facts["initial_stress_note"] = ("scene geostatic initial stress not expressible in Kratos (params.py): "
                                            "the Kratos run starts stress-free, gravity from t = 0")
            (out / "kratos_input.json").write_text(json.dumps(facts, indent=2) + "\n")
        return facts
    raise AssertionError("check_supported lets only DEM-only or MPM-only scenes through")


# ------------------------------------------------------------------------------------------------------------ MPM
def mpm_dt(scene: Scene) -> float:
    """The native MPM step (coupler/mpm/solver.py): time.dt, else cfl h / max(P-wave speed + initial speed)."""
    if scene.time.dt is not None:
        return scene.time.dt
    ms = scene.mpm
    cmax = 0.0
    for b in ms.bodies:
        mat = scene.materials[b.material]
        K = mat.young / (3 * (1 - 2 * mat.poisson))
        cmax = max(cmax, math.sqrt((K + 4 * mat.shear_modulus / 3) / mat.density) + float(np.hypot(*b.velocity)))
    return ms.cfl * ms.cell_size / cmax


def _quad_mesh(lo, hi, h, node0: int, elem0: int, tol: float = 1e-9):
    nx, ny = int(round((hi[0] - lo[0]) / h)), int(round((hi[1] - lo[1]) / h))
    xs, ys = lo[0] + h * np.arange(nx + 1), lo[1] + h * np.arange(ny + 1)
    nodes = {}
    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            nodes[node0 + j * (nx + 1) + i + 1] = (x, y)
    elems = []
    for j in range(ny):
        for i in range(nx):
            a = node0 + j * (nx + 1) + i + 1
            elems.append((elem0 + len(elems) + 1, [a, a + 1, a + nx + 2, a + nx + 1]))
    return nodes, elems


def _mdpa(nodes: dict, elems: list, kind: str, subparts: dict[str, tuple[list, list]],
          conditions: dict[str, list] | None = None) -> str:
    """conditions: sub-model-part name -> [(id, [node ids])] LineCondition2D2N (the slip/friction sides)."""
    conditions = conditions or {}
    s = ["Begin ModelPartData", "End ModelPartData", "", "Begin Properties 0", "End Properties", "", "Begin Nodes"]
    s += [f"  {i} {_v(x)} {_v(y)} 0.0" for i, (x, y) in nodes.items()]
    s += ["End Nodes", "", f"Begin Elements {kind}"]
    s += [f"  {e} 0 {' '.join(map(str, c))}" for e, c in elems]
    s += ["End Elements", ""]
    for name, conds in conditions.items():
        s += ["Begin Conditions LineCondition2D2N"] + [f"  {c} 0 {a} {b}" for c, (a, b) in conds]
        s += ["End Conditions", ""]
    for name, (ns, es) in subparts.items():
        s += [f"Begin SubModelPart {name}", "  Begin SubModelPartNodes"] + [f"    {i}" for i in ns]
        s += ["  End SubModelPartNodes", "  Begin SubModelPartElements"] + [f"    {e}" for e in es]
        s += ["  End SubModelPartElements"]
        if name in conditions:
            s += ["  Begin SubModelPartConditions"] + [f"    {c}" for c, _ in conditions[name]]
            s += ["  End SubModelPartConditions"]
        s += ["End SubModelPart", ""]
    return "\n".join(s) + "\n"


def write_mpm(scene: Scene, out: Path, initial_velocity: tuple[str, str] | None = None,
              snapshot_every: int = 1, friction: str | None = None) -> dict:
    ms = scene.mpm
    h = ms.cell_size
    dt = mpm_dt(scene)
    steps = int(math.ceil(scene.time.t_end / dt - 1e-9))
    dt = scene.time.t_end / steps
    every = max(1, int(round(scene.time.output_interval / dt)))
    lo, hi = np.asarray(ms.origin, float), np.asarray(ms.origin, float) + np.asarray(ms.size, float)
    gnodes, gelems = _quad_mesh(lo, hi, h, 0, 0)
    tol = 1e-9 * h
    sides = {"left": lambda x, y: abs(x - lo[0]) < tol, "right": lambda x, y: abs(x - hi[0]) < tol,
             "bottom": lambda x, y: abs(y - lo[1]) < tol, "top": lambda x, y: abs(y - hi[1]) < tol}
    normal_comp = {"left": 0, "right": 0, "bottom": 1, "top": 1}
    grid_sub = {"Parts_grid": (list(gnodes), [e for e, _ in gelems])}
    constraints, others, conds = [], [], {}
    # counter-clockwise walk along each side (outward normal of Kratos' line normal), then flip_normal as in
    # Kratos' own friction test (params.py: friction walls)
    walk = {"bottom": (0, +1), "right": (1, +1), "top": (0, -1), "left": (1, -1)}
    cid = 0
    kinds = {side: ("fixed" if bc.kind == "friction" and friction == "fixed" else bc.kind)
             for side, bc in ms.boundary.items()}      # params.py: friction walls and their substitutes
    for side, bc in ms.boundary.items():
        if kinds[side] == "open":
            continue
        ids = [i for i, (x, y) in gnodes.items() if sides[side](x, y)]
        if kinds[side] == "friction":
            axis, sign = walk[side]
            ids = sorted(ids, key=lambda i: sign * gnodes[i][axis])
            # a corner shared with a fixed or slip side is not a slip node: Kratos rotates a SLIP node's dofs to
            # (normal, tangent) (MPMBoundaryRotationUtility), so the other side's fixed global component would
            # constrain the rotated normal slot and leave the wall-normal motion free (measured: the two points of
            # the corner cell crossed the wall and were lost). The corner node takes both normals fixed instead
            # (params.py: friction walls)
            corner = [i for i in (ids[0], ids[-1]) if any(
                sides[o](*gnodes[i]) for o in ms.boundary if o != side and kinds[o] in ("fixed", "slip"))]
            for i in (ids[0], ids[-1]):
                if any(sides[o](*gnodes[i]) for o in ms.boundary if o != side and kinds[o] == "friction"):
                    from coupler.errors import UnsupportedFeature
                    raise UnsupportedFeature("kratos", f"mpm.boundary.{side}.kind", "two friction sides meeting at "
                                             "a corner are not written (Kratos rotates each slip node to one normal)")
            ids = [i for i in ids if i not in corner]
            if corner:
                grid_sub[f"Corner_{side}"] = (corner, [])
                fix = [k == normal_comp[side] for k in range(3)]
                constraints.append({"python_module": "assign_vector_variable_process",
                                    "kratos_module": "KratosMultiphysics",
                                    "Parameters": {"model_part_name": f"Background_Grid.Corner_{side}",
                                                   "variable_name": "DISPLACEMENT", "constrained": fix,
                                                   "value": [0.0 if f else None for f in fix],
                                                   "interval": [0.0, "End"]}})
            name = f"Slip_{side}"
            grid_sub[name] = (ids, [])
            conds[name] = []
            for a, b in zip(ids[:-1], ids[1:]):
                cid += 1
                conds[name].append((cid, (a, b)))
            others.append({"python_module": "apply_mpm_slip_boundary_process",
                           "kratos_module": "KratosMultiphysics.MPMApplication",
                           "process_name": "ApplyMPMSlipBoundaryProcess",
                           "Parameters": {"model_part_name": f"Background_Grid.{name}",
                                          "friction_coefficient": bc.friction,
                                          "tangential_penalty_coefficient": tangential_penalty(scene, bc.friction,
                                                                                               steps),
                                          "option": "flip_normal"}})
            continue
        grid_sub[f"BC_{side}"] = (ids, [])
        fixed = [True, True, True] if kinds[side] == "fixed" else [k == normal_comp[side] for k in range(3)]
        constraints.append({"python_module": "assign_vector_variable_process", "kratos_module": "KratosMultiphysics",
                            "Parameters": {"model_part_name": f"Background_Grid.BC_{side}",
                                           "variable_name": "DISPLACEMENT", "constrained": fixed,
                                           "value": [0.0 if f else None for f in fixed], "interval": [0.0, "End"]}})
    (out / f"{PROBLEM}_Grid.mdpa").write_text(_mdpa(gnodes, gelems, GRID_ELEMENT, grid_sub, conds))
    bnodes, belems, bsub, props = {}, [], {}, []
    n0 = max(gnodes) + 1000
    for k, b in enumerate(ms.bodies):
        blo, bhi = b.polygon.min(0), b.polygon.max(0)
        nodes, elems = _quad_mesh(blo, bhi, h, n0 + len(bnodes), len(belems) + 100000)
        bnodes.update(nodes)
        belems += elems
        bsub[f"Parts_body_{k}"] = (list(nodes), [e for e, _ in elems])
        mat = scene.materials[b.material]
        m = b.model
        var = {"MATERIAL_POINTS_PER_ELEMENT": b.particles_per_cell ** 2, "DENSITY": mat.density,
               "YOUNG_MODULUS": mat.young, "POISSON_RATIO": mat.poisson, "THICKNESS": 1.0}
        if m.model == "mohr_coulomb":
            var.update({"INTERNAL_FRICTION_ANGLE": math.radians(m.friction_angle), "COHESION": m.cohesion,
                        "INTERNAL_DILATANCY_ANGLE": math.radians(m.dilatancy)})
        props.append({"model_part_name": f"Initial_MPM_Material.Parts_body_{k}", "properties_id": k + 1,
                      "Material": {"constitutive_law": {"name": mpm_law(m.model)}, "Variables": var,
                                   "Tables": None}})
    (out / f"{PROBLEM}_Body.mdpa").write_text(_mdpa(bnodes, belems, MPM_ELEMENT, bsub))
    (out / "ParticleMaterials.json").write_text(json.dumps({"properties": props}, indent=2) + "\n")
    g = np.asarray(scene.gravity, float)
    gmod = float(np.linalg.norm(g[:2]))
    gravity = [{"python_module": "assign_gravity_to_material_point_process",
                "kratos_module": "KratosMultiphysics.MPMApplication",
                "process_name": "AssignGravityToMaterialPointProcess",
                "Parameters": {"model_part_name": "MPM_Material", "variable_name": "MP_VOLUME_ACCELERATION",
                               "modulus": gmod, "direction": (list(g[:2] / gmod) if gmod > 0 else [0.0, -1.0]) + [0.0]}}]
    params = {
        "problem_data": {"problem_name": PROBLEM, "parallel_type": "OpenMP", "echo_level": 0, "start_time": 0.0,
                         "end_time": steps * dt * (1 + 1e-12)},
        "solver_settings": {
            "solver_type": "Dynamic", "model_part_name": "MPM_Material", "domain_size": 2, "echo_level": 0,
            "analysis_type": "non_linear", "time_integration_method": "implicit", "scheme_type": "newmark",
            "model_import_settings": {"input_type": "mdpa", "input_filename": f"{PROBLEM}_Body"},
            "material_import_settings": {"materials_filename": "ParticleMaterials.json"},
            "time_stepping": {"time_step": dt}, "convergence_criterion": convergence_criterion(scene, friction),
            "displacement_relative_tolerance": 1e-4, "displacement_absolute_tolerance": 1e-9,
            "residual_relative_tolerance": 1e-4, "residual_absolute_tolerance": 1e-9, "max_iteration": 20,
            "problem_domain_sub_model_part_list": list(bsub) + ["Parts_grid"],
            "processes_sub_model_part_list": [n for n in grid_sub if n != "Parts_grid"],
            "grid_model_import_settings": {"input_type": "mdpa", "input_filename": f"{PROBLEM}_Grid"},
            "pressure_dofs": False,
            "linear_solver_settings": {"solver_type": "LinearSolversApplication.sparse_lu"},
            **({"auxiliary_variables_list": ["NORMAL", "IS_STRUCTURE"]} if conds else {})},
        "processes": {"constraints_process_list": constraints, "loads_process_list": [],
                      "list_other_processes": others, "gravity": gravity if gmod > 0 else []},
        "output_processes": {}}
    (out / "ProjectParameters.json").write_text(json.dumps(params, indent=2) + "\n")
    vel = {f"Parts_body_{k}": [float(b.velocity[0]), float(b.velocity[1])] for k, b in enumerate(ms.bodies)}
    facts = {"kind": "mpm", "dt": dt, "steps": steps, "every": every, "snapshot_every": int(snapshot_every), "bodies": [b.name for b in ms.bodies],
             "body_velocity": vel, "initial_velocity": list(initial_velocity) if initial_velocity else None,
             "shape_note": (f"scene shape_function {ms.shape!r}; Kratos {MPM_ELEMENT} uses bilinear grid shape "
                            f"functions" if ms.shape != "linear" else "linear (bilinear quadrilaterals) as asked"),
             "transfer_note": f"scene transfer {ms.transfer!r} not used: Kratos implicit Newmark (beta 0.25)"}
    fr = [side for side, bc in ms.boundary.items() if bc.kind == "friction"]
    if fr:
        facts["friction_note"] = (
            f"friction wall(s) {', '.join(fr)} written " + (
                "NO-SLIP (fixed): Kratos 10.4.4's Coulomb wall caps the friction at mu x the normal force summed over "
                "the Newton iterations of a step and its stick penalty creeps every step (adapters/kratos/params.py)"
                if friction == "fixed" else
                "as Kratos' ApplyMPMSlipBoundaryProcess (its friction cap is mu x the normal force summed over the "
                "Newton iterations of a step: adapters/kratos/params.py)"))
    (out / "kratos_input.json").write_text(json.dumps(facts, indent=2) + "\n")
    (out / "run_kratos.py").write_text(MPM_SCRIPT)
    return facts


MPM_SCRIPT = r"""# written by mpmdem (adapters/kratos/writer.py); parameter map: adapters/kratos/params.py
import csv, json, math, time
import KratosMultiphysics as KM
import KratosMultiphysics.MPMApplication as MPM
from KratosMultiphysics.MPMApplication.mpm_analysis import MpmAnalysis

F = json.load(open("kratos_input.json"))
DT, STEPS, EVERY = F["dt"], F["steps"], F["every"]
FIELDS = ["step", "id", "body", "x", "y", "vx", "vy", "sxx", "syy", "sxy", "szz", "mass", "volume", "ux", "uy"]


class Stage(MpmAnalysis):
    def Initialize(self):
        super().Initialize()
        self.mp = self.model.GetModelPart("MPM_Material")
        self.pi = self.mp.ProcessInfo
        self.body_of = {}
        for k, name in enumerate(F["bodies"]):
            sub = self.mp.GetSubModelPart(f"Parts_body_{k}") if self.mp.HasSubModelPart(f"Parts_body_{k}") else None
            for e in (sub.Elements if sub is not None else []):
                self.body_of[e.Id] = k
        expr = F["initial_velocity"]
        for e in self.mp.Elements:
            x = e.CalculateOnIntegrationPoints(MPM.MP_COORD, self.pi)[0]
            if expr:
                env = {"x": x[0], "y": x[1], **{k: getattr(math, k) for k in dir(math) if not k.startswith("_")}}
                v = [eval(expr[0], env), eval(expr[1], env), 0.0]
            else:
                v = F["body_velocity"][f"Parts_body_{self.body_of.get(e.Id, 0)}"] + [0.0]
            e.SetValuesOnIntegrationPoints(MPM.MP_VELOCITY, [KM.Array3(v)], self.pi)
        self.x0 = {e.Id: e.CalculateOnIntegrationPoints(MPM.MP_COORD, self.pi)[0] for e in self.mp.Elements}
        self.fp = open("kratos_particles.csv", "w", newline="")
        self.pw = csv.writer(self.fp)
        self.pw.writerow(FIELDS)
        self.fe = open("kratos_energy.csv", "w", newline="")
        self.ew = csv.writer(self.fe)
        self.ew.writerow(["step", "potential", "kinetic", "strain", "total"])
        self.fs = open("kratos_series.csv", "w", newline="")
        self.sw = csv.writer(self.fs)
        self.sw.writerow(["step", "body", "mass", "x", "y", "vx", "vy"])
        self.mass = {e.Id: e.CalculateOnIntegrationPoints(MPM.MP_MASS, self.pi)[0] for e in self.mp.Elements}
        self.n_out = 0
        self.step_count = 0
        self.newton = []
        self.record(0)
        self.t_loop = time.perf_counter()

    def record(self, step):
        acc = {}
        for e in self.mp.Elements:
            m = self.mass[e.Id]
            x = e.CalculateOnIntegrationPoints(MPM.MP_COORD, self.pi)[0]
            v = e.CalculateOnIntegrationPoints(MPM.MP_VELOCITY, self.pi)[0]
            a = acc.setdefault(self.body_of.get(e.Id, 0), [0.0] * 5)
            a[0] += m; a[1] += m * x[0]; a[2] += m * x[1]; a[3] += m * v[0]; a[4] += m * v[1]
        for b, a in sorted(acc.items()):
            self.sw.writerow([step, b, repr(a[0]), repr(a[1] / a[0]), repr(a[2] / a[0]), repr(a[3] / a[0]),
                              repr(a[4] / a[0])])
        p, k, se, tot = MPM.EnergyCalculationUtility.CalculateAllEnergies(self.mp)
        self.ew.writerow([step, repr(p), repr(k), repr(se), repr(tot)])
        self.n_out += 1
        if (self.n_out - 1) % F["snapshot_every"] == 0 or step == STEPS:
            self.snapshot(step)

    def snapshot(self, step):
        for e in self.mp.Elements:
            g = lambda var: e.CalculateOnIntegrationPoints(var, self.pi)[0]
            x, v, s = g(MPM.MP_COORD), g(MPM.MP_VELOCITY), g(MPM.MP_CAUCHY_STRESS_VECTOR)
            x0 = self.x0[e.Id]
            szz = s[3] if len(s) > 3 else float("nan")
            sxy = s[2] if len(s) == 3 else (s[3] if len(s) == 4 else s[3])
            self.pw.writerow([step, e.Id, self.body_of.get(e.Id, 0), repr(x[0]), repr(x[1]), repr(v[0]), repr(v[1]),
                              repr(s[0]), repr(s[1]), repr(sxy), repr(szz), repr(self.mass[e.Id]),
                              repr(g(MPM.MP_VOLUME)), repr(x[0] - x0[0]), repr(x[1] - x0[1])])

    def KeepAdvancingSolutionLoop(self):
        return self.step_count < STEPS

    def OutputSolutionStep(self):
        self.step_count += 1
        self.newton.append(self.pi[KM.NL_ITERATION_NUMBER])
        if self.step_count % EVERY == 0 or self.step_count == STEPS:
            self.record(self.step_count)
            print(f"mpmdem step {self.step_count}/{STEPS} t={self.pi[KM.TIME]:.5g} "
                  f"{time.perf_counter() - self.t_loop:.1f} s", flush=True)

    def Finalize(self):
        loop = time.perf_counter() - self.t_loop
        self.fp.close()
        self.fe.close()
        self.fs.close()
        json.dump({"loop_time_s": loop, "steps": self.step_count, "time": self.mp.ProcessInfo[KM.TIME],
                   "n_points": self.mp.NumberOfElements(), "newton_iterations_total": int(sum(self.newton)),
                   "newton_iterations_max": int(max(self.newton, default=0)),
                   "newton_iterations_mean": sum(self.newton) / max(1, len(self.newton))},
                  open("timing_kratos.json", "w"))
        super().Finalize()


if __name__ == "__main__":
    KM.Logger.GetDefaultOutput().SetSeverity(KM.Logger.Severity.WARNING)
    with open("ProjectParameters.json") as fh:
        params = KM.Parameters(fh.read())
    Stage(KM.Model(), params).Run()
"""


