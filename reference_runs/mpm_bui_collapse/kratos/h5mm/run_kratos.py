# written by mpmdem (adapters/kratos/writer.py); parameter map: adapters/kratos/params.py
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
