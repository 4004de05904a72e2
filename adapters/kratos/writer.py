"""Write the Kratos input of a scene into the run folder: .mdpa files, ProjectParameters*.json, Materials*.json and
the python script (run_kratos.py) that runs the analysis stage and records the states the parser reads.
The parameter map is adapters/kratos/params.py."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from adapters.kratos.params import (GRID_ELEMENT, MPM_ELEMENT, check_supported, kratos_restitution, mpm_law,
                                    native_beta)
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
    wall_used = sorted({w.material for w in list(dem.planes) + list(dem.meshes)})
    mats, ids = [], {}
    for name in used:
        m = scene.materials[name]
        ids[name] = len(mats) + 1
        mats.append({"material_name": name, "material_id": ids[name],
                     "Variables": {"PARTICLE_DENSITY": m.density, "YOUNG_MODULUS": m.young,
                                   "POISSON_RATIO": m.poisson}})
    for name in wall_used:
        m = scene.materials[name]
        ids[name + "__wall"] = len(mats) + 1
        mats.append({"material_name": name + "__wall", "material_id": ids[name + "__wall"],
                     "Variables": {"YOUNG_MODULUS": m.young, "POISSON_RATIO": m.poisson, "COMPUTE_WEAR": False}})
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
        for w in wall_used:
            if pair_key(a, w) in scene.contacts:
                add(a, a, w, w + "__wall")
    table = [[f"SpheresPart.mat_{n}", n] for n in used] + [[f"RigidFacePart.wall_{k}", f"{w.material}__wall"]
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
        self.st = open("states_kratos.csv", "w", newline="")
        self.fc = open("forces_kratos.csv", "w", newline="")
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


def write_inputs(scene: Scene, out: Path) -> dict:
    check_supported(scene)
    if scene.dem is not None and scene.mpm is None:
        return write_dem(scene, out)
    if scene.mpm is not None and scene.dem is None:
        from adapters.kratos.mpm_writer import write_mpm
        return write_mpm(scene, out)
    raise AssertionError("check_supported lets only DEM-only or MPM-only scenes through")
