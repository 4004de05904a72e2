# written by mpmdem (adapters/kratos/cosim.py); parameter map: adapters/kratos/params.py
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
