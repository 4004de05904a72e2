# written by mpmdem (adapters/kratos/writer.py); parameter map: adapters/kratos/params.py
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
