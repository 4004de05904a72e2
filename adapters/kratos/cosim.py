"""Coupled MPM-DEM scenes through Kratos CoSimulationApplication (gauss_seidel_weak, DEM first), written after the
set-up of Kratos' own tests/mpm_dem case (read, not copied): MPM = MPMApplication implicit Newmark with a Neumann
coupling interface (MPMGridPointLoadCondition2D1N point conditions on the interface, turned into material point
conditions by apply_mpm_coupling_interface_neumann_condition_process; solver wrapper mpm_neumann_wrapper), DEM =
DEMApplication in 2D (CylinderParticle2D discs, DEM_D_Hertz_viscous_Coulomb2D, the interface as RigidEdge2D2N
segments of the RigidFacePart, moved by the mapped MPM displacement; solver wrapper dem_wrapper), data transfer
kratos_mapping nearest_neighbor, the DEM contact force mapped with use_transpose.

What is mapped and how (params.py, "coupled" section): only the Kratos regression layout is written: one
rectangular MPM body coupled on its top side, DEM spheres only (no planes, meshes or clusters), mapper nearest,
scheme gauss_seidel_weak. Anything else: UnsupportedFeature naming the field."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from adapters.kratos.params import check_coupled, kratos_restitution, native_beta
from adapters.kratos.writer import _mdpa, _quad_mesh, _v
from coupler.materials import pair_key
from coupler.scene import Scene

CODE = "kratos"


def write_coupled(scene: Scene, out: Path, dt: float) -> dict:
    """All Kratos files of a coupled run into out; dt: the coupling (= MPM = DEM) step."""
    from adapters.kratos.params import mpm_law
    check_coupled(scene)
    ms, c, d = scene.mpm, scene.coupling, scene.dem
    steps = int(round(scene.time.t_end / dt))
    every = max(1, int(round(scene.time.output_interval / dt)))
    h = ms.cell_size
    lo, hi = np.asarray(ms.origin, float), np.asarray(ms.origin, float) + np.asarray(ms.size, float)
    b = ms.bodies[0]
    blo, bhi = b.polygon.min(0), b.polygon.max(0)
    # ---- MPM grid + body
    gnodes, gelems = _quad_mesh(lo, hi, h, 0, 0)
    tol = 1e-9 * h
    sides = {"left": lambda x, y: abs(x - lo[0]) < tol, "right": lambda x, y: abs(x - hi[0]) < tol,
             "bottom": lambda x, y: abs(y - lo[1]) < tol, "top": lambda x, y: abs(y - hi[1]) < tol}
    normal_comp = {"left": 0, "right": 0, "bottom": 1, "top": 1}
    sub = {"Parts_grid": (list(gnodes), [e for e, _ in gelems])}
    constraints = []
    for side, bc in ms.boundary.items():
        if bc.kind == "open":
            continue
        ids = [i for i, (x, y) in gnodes.items() if sides[side](x, y)]
        sub[f"BC_{side}"] = (ids, [])
        fixed = [True, True, True] if bc.kind == "fixed" else [k == normal_comp[side] for k in range(3)]
        constraints.append({"python_module": "assign_vector_variable_process", "kratos_module": "KratosMultiphysics",
                            "Parameters": {"model_part_name": f"Background_Grid.BC_{side}",
                                           "variable_name": "DISPLACEMENT", "constrained": fixed,
                                           "value": [0.0 if f else None for f in fixed], "interval": [0.0, "End"]}})
    # interface: point conditions on separate nodes along the top side, at the native boundary-particle spacing
    # (h / ppc), ends included
    n_if = int(round((bhi[0] - blo[0]) / (h / b.particles_per_cell))) + 1
    xs = np.linspace(blo[0], bhi[0], n_if)
    n0 = max(gnodes) + 1
    if_nodes = {n0 + k: (float(x), float(bhi[1])) for k, x in enumerate(xs)}
    gnodes_all = dict(gnodes)
    gnodes_all.update(if_nodes)
    sub["INTERFACE_top"] = (list(if_nodes), [])
    grid = _mdpa(gnodes_all, gelems, "Element2D4N", sub)
    pc = ["Begin Conditions MPMGridPointLoadCondition2D1N"] + [f"  {k + 1} 0 {i}" for k, i in enumerate(if_nodes)]
    pc += ["End Conditions", ""]
    grid = grid.replace("Begin SubModelPart Parts_grid", "\n".join(pc) + "\nBegin SubModelPart Parts_grid", 1)
    grid = grid.replace("Begin SubModelPart INTERFACE_top\n  Begin SubModelPartNodes",
                        "Begin SubModelPart INTERFACE_top\n  Begin SubModelPartNodes", 1)
    cond_block = "  Begin SubModelPartConditions\n" + "\n".join(f"    {k + 1}" for k in range(n_if)) + \
                 "\n  End SubModelPartConditions\n"
    head, tail = grid.split("Begin SubModelPart INTERFACE_top", 1)
    tail = tail.replace("  End SubModelPartElements\n", "  End SubModelPartElements\n" + cond_block, 1)
    (out / "beam_Grid.mdpa").write_text(head + "Begin SubModelPart INTERFACE_top" + tail)
    bnodes, belems = _quad_mesh(blo, bhi, h, max(gnodes_all) + 1000, 100000)
    (out / "beam_Body.mdpa").write_text(_mdpa(bnodes, belems, "MPMUpdatedLagrangian2D4N",
                                              {"Parts_body_0": (list(bnodes), [e for e, _ in belems])}))
    mat = scene.materials[b.material]
    var = {"MATERIAL_POINTS_PER_ELEMENT": b.particles_per_cell ** 2, "DENSITY": mat.density,
           "YOUNG_MODULUS": mat.young, "POISSON_RATIO": mat.poisson, "THICKNESS": 1.0}
    if b.model.model == "mohr_coulomb":
        var.update({"INTERNAL_FRICTION_ANGLE": math.radians(b.model.friction_angle), "COHESION": b.model.cohesion,
                    "INTERNAL_DILATANCY_ANGLE": math.radians(b.model.dilatancy)})
    (out / "ParticleMaterials.json").write_text(json.dumps({"properties": [
        {"model_part_name": "Initial_MPM_Material.Parts_body_0", "properties_id": 1,
         "Material": {"constitutive_law": {"name": mpm_law(b.model.model)}, "Variables": var, "Tables": None}}]},
        indent=2) + "\n")
    g = np.asarray(scene.gravity, float)
    gmod = float(np.linalg.norm(g[:2]))
    mpm_params = {
        "problem_data": {"problem_name": "beam", "parallel_type": "OpenMP", "echo_level": 0, "start_time": 0.0,
                         "end_time": steps * dt * (1 + 1e-12)},
        "solver_settings": {
            "solver_type": "Dynamic", "model_part_name": "MPM_Material", "domain_size": 2, "echo_level": 0,
            "analysis_type": "non_linear", "time_integration_method": "implicit", "scheme_type": "newmark",
            "model_import_settings": {"input_type": "mdpa", "input_filename": "beam_Body"},
            "material_import_settings": {"materials_filename": "ParticleMaterials.json"},
            "time_stepping": {"time_step": dt}, "convergence_criterion": "residual_criterion",
            "displacement_relative_tolerance": 1e-4, "displacement_absolute_tolerance": 1e-9,
            "residual_relative_tolerance": 1e-4, "residual_absolute_tolerance": 1e-9, "max_iteration": 20,
            "grid_model_import_settings": {"input_type": "mdpa", "input_filename": "beam_Grid"},
            "pressure_dofs": False,
            "linear_solver_settings": {"solver_type": "LinearSolversApplication.sparse_lu"},
            "auxiliary_variables_list": ["NORMAL", "IS_STRUCTURE"]},
        "processes": {
            "constraints_process_list": constraints,
            "loads_process_list": [{"python_module": "apply_mpm_coupling_interface_neumann_condition_process",
                                    "kratos_module": "KratosMultiphysics.MPMApplication",
                                    "Parameters": {"model_part_name": "Background_Grid.INTERFACE_top",
                                                   "material_points_per_condition": 1}}],
            "list_other_processes": [],
            "gravity": [{"python_module": "assign_gravity_to_material_point_process",
                         "kratos_module": "KratosMultiphysics.MPMApplication",
                         "process_name": "AssignGravityToMaterialPointProcess",
                         "Parameters": {"model_part_name": "MPM_Material",
                                        "modulus": gmod,
                                        "direction": list(g[:2] / gmod) + [0.0]}}] if gmod > 0 else []},
        "output_processes": {}}
    (out / "ProjectParametersMPM.json").write_text(json.dumps(mpm_params, indent=2) + "\n")
    # ---- DEM (2D discs, CylinderParticle2D) + the interface edges
    wall_mat = c.material
    used = sorted(set(d.material))
    mats, ids = [], {}
    for name in used:
        m = scene.materials[name]
        ids[name] = len(mats) + 1
        mats.append({"material_name": name, "material_id": ids[name],
                     "Variables": {"PARTICLE_DENSITY": m.density, "YOUNG_MODULUS": m.young,
                                   "POISSON_RATIO": m.poisson, "PARTICLE_MATERIAL": ids[name]}})
    wm = scene.materials[wall_mat]
    ids["wall"] = len(mats) + 1
    mats.append({"material_name": "wall", "material_id": ids["wall"],
                 "Variables": {"YOUNG_MODULUS": wm.young, "POISSON_RATIO": wm.poisson, "COMPUTE_WEAR": False}})
    rel, pairs = [], []
    for i, a in enumerate(used):
        for bb in used[i:] + ["wall"]:
            key = pair_key(a, wall_mat if bb == "wall" else bb)
            if key not in scene.contacts:
                continue
            law = scene.contacts[key]
            e = kratos_restitution(law)
            rel.append({"material_names_list": [a, bb], "material_ids_list": [ids[a], ids[bb]],
                        "Variables": {"COEFFICIENT_OF_RESTITUTION": e, "STATIC_FRICTION": law.friction,
                                      "DYNAMIC_FRICTION": law.friction, "FRICTION_DECAY": 500.0,
                                      "ROLLING_FRICTION": 0.0, "ROLLING_FRICTION_WITH_WALLS": 0.0,
                                      "DEM_DISCONTINUUM_CONSTITUTIVE_LAW_NAME": "DEM_D_Hertz_viscous_Coulomb2D"}})
            pairs.append({"a": a, "b": bb, "restitution_kratos": e, "beta_native": native_beta(law),
                          "friction": law.friction})
    (out / "MaterialsDEM.json").write_text(json.dumps({
        "materials": mats, "material_relations": rel,
        "material_assignation_table": [[f"SpheresPart.mat_{n}", n] for n in used] + [["RigidFacePart", "wall"]]},
        indent=2) + "\n")
    s = ["Begin ModelPartData", "End ModelPartData", "", "Begin Properties 0", "End Properties", "", "Begin Nodes"]
    s += [f"  {k + 1} {_v(x[0])} {_v(x[1])} 0.0" for k, x in enumerate(d.position)]
    s += ["End Nodes", "", "Begin Elements CylinderParticle2D"] + [f"  {k + 1} 0 {k + 1}" for k in range(d.n_spheres)]
    s += ["End Elements", "", "Begin NodalData RADIUS"] + [f"  {k + 1} 0 {_v(r)}" for k, r in enumerate(d.radius)]
    s += ["End NodalData", ""]
    for name in used:
        idx = [k + 1 for k, m in enumerate(d.material) if m == name]
        s += [f"Begin SubModelPart mat_{name}", "  Begin SubModelPartNodes"] + [f"    {i}" for i in idx]
        s += ["  End SubModelPartNodes", "  Begin SubModelPartElements"] + [f"    {i}" for i in idx]
        s += ["  End SubModelPartElements", "End SubModelPart", ""]
    (out / "discDEM.mdpa").write_text("\n".join(s) + "\n")
    w0 = d.n_spheres + 1
    wn = [(w0 + k, x) for k, x in enumerate(xs)]
    s = ["Begin ModelPartData", "End ModelPartData", "", "Begin Properties 0", "End Properties", "", "Begin Nodes"]
    s += [f"  {i} {_v(x)} {_v(bhi[1])} 0.0" for i, x in wn]
    s += ["End Nodes", "", "Begin Conditions RigidEdge2D2N"]
    s += [f"  {k + 1} 0 {wn[k + 1][0]} {wn[k][0]}" for k in range(len(wn) - 1)]   # walked -x: normal up (outward)
    s += ["End Conditions", "", "Begin SubModelPart interface", "  Begin SubModelPartData",
          "    RIGID_BODY_MOTION 0", "    FIXED_MESH_OPTION 0", "    FREE_BODY_MOTION 0", "    IS_GHOST 0",
          "    IDENTIFIER interface", "    TOP 0", "    BOTTOM 0", "    FORCE_INTEGRATION_GROUP 0",
          "  End SubModelPartData", "  Begin SubModelPartNodes"] + [f"    {i}" for i, _ in wn]
    s += ["  End SubModelPartNodes", "  Begin SubModelPartConditions"] + [f"    {k + 1}" for k in range(len(wn) - 1)]
    s += ["  End SubModelPartConditions", "End SubModelPart", ""]
    (out / "discDEM_FEM_boundary.mdpa").write_text("\n".join(s) + "\n")
    empty = "Begin ModelPartData\nEnd ModelPartData\n\nBegin Properties 0\nEnd Properties\n\nBegin Nodes\nEnd Nodes\n"
    (out / "discDEM_Clusters.mdpa").write_text(empty)
    (out / "discDEM_Inlet.mdpa").write_text(empty)
    big = 1e3
    dem_params = {
        "Dimension": 2, "PeriodicDomainOption": False, "BoundingBoxOption": False,
        "AutomaticBoundingBoxOption": False, "BoundingBoxEnlargementFactor": 1.0,
        "BoundingBoxMaxX": big, "BoundingBoxMaxY": big, "BoundingBoxMaxZ": big,
        "BoundingBoxMinX": -big, "BoundingBoxMinY": -big, "BoundingBoxMinZ": -big,
        "dem_inlet_option": False, "GravityX": g[0], "GravityY": g[1], "GravityZ": 0.0,
        "RotationOption": True, "CleanIndentationsOption": False,
        "solver_settings": {"RemoveBallsInitiallyTouchingWalls": False, "strategy": "sphere_strategy",
                            "material_import_settings": {"materials_filename": "MaterialsDEM.json"}},
        "VirtualMassCoefficient": 1.0, "RollingFrictionOption": False, "GlobalDamping": 0.0,
        "ContactMeshOption": False, "OutputFileType": "Ascii", "Multifile": "single_file",
        "ElementType": "CylinderPartDEMElement2D", "TranslationalIntegrationScheme": "Symplectic_Euler",
        "RotationalIntegrationScheme": "Direct_Integration", "MaxTimeStep": dt,
        "FinalTime": steps * dt * (1.0 + 1e-9), "NeighbourSearchFrequency": 1,
        "GraphExportFreq": 1e30, "VelTrapGraphExportFreq": 1e30, "OutputTimeStep": 1e30,
        "PostDisplacement": False, "PostRadius": False, "PostVelocity": False, "PostAngularVelocity": False,
        "PostElasticForces": False, "PostContactForces": False, "PostRigidElementForces": False,
        "PostStressStrainOption": False, "PostTangentialElasticForces": False, "PostTotalForces": False,
        "PostPressure": False, "PostShearStress": False, "PostNonDimensionalVolumeWear": False,
        "PostParticleMoment": False, "PostEulerAngles": False, "PostRollingResistanceMoment": False,
        "problem_name": "disc"}
    (out / "ProjectParametersDEM.json").write_text(json.dumps(dem_params, indent=2) + "\n")
    cosim = {
        "problem_data": {"start_time": 0.0, "end_time": steps * dt * (1 + 1e-9), "echo_level": 0,
                         "print_colors": False, "parallel_type": "OpenMP"},
        "solver_settings": {
            "type": "coupled_solvers.gauss_seidel_weak", "echo_level": 0,
            "data_transfer_operators": {"nearest": {"type": "kratos_mapping",
                                                    "mapper_settings": {"mapper_type": "nearest_neighbor"}}},
            "coupling_operations": {},
            "coupling_sequence": [
                {"name": "dem", "input_data_list": [], "output_data_list": []},
                {"name": "mpm",
                 "input_data_list": [{"data": "load", "from_solver": "dem", "from_solver_data": "contact_force",
                                      "data_transfer_operator": "nearest",
                                      "data_transfer_operator_options": ["use_transpose"]}],
                 "output_data_list": [{"data": "disp", "to_solver": "dem", "to_solver_data": "disp",
                                       "data_transfer_operator": "nearest"},
                                      {"data": "velocity", "to_solver": "dem", "to_solver_data": "velocity",
                                       "data_transfer_operator": "nearest"}]}],
            "solvers": {
                "dem": {"type": "solver_wrappers.kratos.dem_wrapper",
                        "solver_wrapper_settings": {"input_file": "ProjectParametersDEM",
                                                    "move_mesh_model_part": ["RigidFacePart"]},
                        "data": {"disp": {"model_part_name": "RigidFacePart", "variable_name": "DISPLACEMENT",
                                          "dimension": 2},
                                 "contact_force": {"model_part_name": "RigidFacePart",
                                                   "variable_name": "CONTACT_FORCES", "dimension": 2},
                                 "velocity": {"model_part_name": "RigidFacePart", "variable_name": "VELOCITY",
                                              "dimension": 2}}},
                "mpm": {"type": "solver_wrappers.kratos.mpm_neumann_wrapper",
                        "solver_wrapper_settings": {"input_file": "ProjectParametersMPM",
                                                    "interface_model_part_name": "MPM_Material.INTERFACE_top"},
                        "data": {"disp": {"model_part_name": "MPM_Coupling_Neumann_Interface",
                                          "variable_name": "DISPLACEMENT", "dimension": 2},
                                 "load": {"model_part_name": "MPM_Coupling_Neumann_Interface",
                                          "variable_name": "CONTACT_FORCE", "dimension": 2},
                                 "velocity": {"model_part_name": "MPM_Coupling_Neumann_Interface",
                                              "variable_name": "VELOCITY", "dimension": 2}}}}}}
    (out / "ProjectParametersCoSim.json").write_text(json.dumps(cosim, indent=2) + "\n")
    facts = {"kind": "coupled", "dt": dt, "steps": steps, "every": every, "bodies": [b.name],
             "spheres": list(d.names), "velocity": d.velocity.tolist(), "angular_velocity": d.angular_velocity.tolist(),
             "pairs": pairs, "n_interface": n_if, "thickness_native": c.thickness,
             "body_velocity": {"Parts_body_0": [float(b.velocity[0]), float(b.velocity[1])]}}
    (out / "kratos_input.json").write_text(json.dumps(facts, indent=2) + "\n")
    (out / "run_kratos.py").write_text(COSIM_SCRIPT)
    return facts


COSIM_SCRIPT = r'''# written by mpmdem (adapters/kratos/cosim.py); parameter map: adapters/kratos/params.py
import csv, json, time
import KratosMultiphysics as KM
import KratosMultiphysics.MPMApplication as MPM
import KratosMultiphysics.DEMApplication as DEM
from KratosMultiphysics.CoSimulationApplication.co_simulation_analysis import CoSimulationAnalysis

F = json.load(open("kratos_input.json"))
DT, STEPS, EVERY = F["dt"], F["steps"], F["every"]


class Analysis(CoSimulationAnalysis):
    def Initialize(self):
        super().Initialize()
        w = self._GetSolver().solver_wrappers
        self.dem_model, self.mpm_model = w["dem"].model, w["mpm"].model
        self.sp = self.dem_model.GetModelPart("SpheresPart")
        for n in self.sp.Nodes:
            n.SetSolutionStepValue(KM.VELOCITY, KM.Array3(F["velocity"][n.Id - 1]))
            n.SetSolutionStepValue(KM.ANGULAR_VELOCITY, KM.Array3(F["angular_velocity"][n.Id - 1]))
        self.mp = self.mpm_model.GetModelPart("MPM_Material")
        self.pi = self.mp.ProcessInfo
        for e in self.mp.Elements:
            e.SetValuesOnIntegrationPoints(MPM.MP_VELOCITY, [KM.Array3(F["body_velocity"]["Parts_body_0"] + [0.0])],
                                           self.pi)
        self.x0 = {e.Id: e.CalculateOnIntegrationPoints(MPM.MP_COORD, self.pi)[0] for e in self.mp.Elements}
        self.mass = {e.Id: e.CalculateOnIntegrationPoints(MPM.MP_MASS, self.pi)[0] for e in self.mp.Elements}
        self.files = {k: open(f"kratos_{k}.csv", "w", newline="") for k in ("states", "particles", "interface")}
        self.w = {k: csv.writer(f) for k, f in self.files.items()}
        self.w["states"].writerow(["step", "id", "x", "y", "vx", "vy", "wz", "mass"])
        self.w["particles"].writerow(["step", "id", "x", "y", "vx", "vy", "sxx", "syy", "sxy", "mass", "volume",
                                      "ux", "uy"])
        self.w["interface"].writerow(["step", "fx_dem", "fy_dem", "fx_mpm", "fy_mpm"])
        self.k = 0
        self.record()
        self.t0 = time.perf_counter()

    def record(self):
        k = self.k
        for n in self.sp.Nodes:
            v, om = n.GetSolutionStepValue(KM.VELOCITY), n.GetSolutionStepValue(KM.ANGULAR_VELOCITY)
            self.w["states"].writerow([k, n.Id, repr(n.X), repr(n.Y), repr(v[0]), repr(v[1]), repr(om[2]),
                                       repr(n.GetSolutionStepValue(KM.NODAL_MASS))])
        if k % EVERY == 0 or k == STEPS:
            for e in self.mp.Elements:
                g = lambda var: e.CalculateOnIntegrationPoints(var, self.pi)[0]
                x, v, s = g(MPM.MP_COORD), g(MPM.MP_VELOCITY), g(MPM.MP_CAUCHY_STRESS_VECTOR)
                x0 = self.x0[e.Id]
                self.w["particles"].writerow([k, e.Id, repr(x[0]), repr(x[1]), repr(v[0]), repr(v[1]), repr(s[0]),
                                              repr(s[1]), repr(s[2]), repr(self.mass[e.Id]), repr(g(MPM.MP_VOLUME)),
                                              repr(x[0] - x0[0]), repr(x[1] - x0[1])])
        rf = self.dem_model.GetModelPart("RigidFacePart")
        fd = [0.0, 0.0]
        for n in rf.Nodes:
            f = n.GetSolutionStepValue(DEM.CONTACT_FORCES)
            fd[0] += f[0]; fd[1] += f[1]
        ci = self.mpm_model.GetModelPart("MPM_Coupling_Neumann_Interface")
        fm = [0.0, 0.0]
        for n in ci.Nodes:
            f = n.GetSolutionStepValue(KM.CONTACT_FORCE)
            fm[0] += f[0]; fm[1] += f[1]
        self.w["interface"].writerow([k, repr(fd[0]), repr(fd[1]), repr(fm[0]), repr(fm[1])])

    def KeepAdvancingSolutionLoop(self):
        return self.k < STEPS

    def OutputSolutionStep(self):
        super().OutputSolutionStep()
        self.k += 1
        self.record()

    def Finalize(self):
        loop = time.perf_counter() - self.t0
        for f in self.files.values():
            f.close()
        json.dump({"loop_time_s": loop, "steps": self.k, "n_points": self.mp.NumberOfElements()},
                  open("timing_kratos.json", "w"))
        super().Finalize()


if __name__ == "__main__":
    KM.Logger.GetDefaultOutput().SetSeverity(KM.Logger.Severity.WARNING)
    with open("ProjectParametersCoSim.json") as fh:
        params = KM.Parameters(fh.read())
    Analysis(params).Run()
'''
