"""YADE as the DEM partition of a coupled run (`[coupling] dem_partition = "yade"`; the native MPM stays the MPM side).

YadeDEMPartition implements the DEM partition contract (COORD.md, coupler/coupling/partitions.py DEMPartition):
    constructor (scene, wall_name, dt, motions); time, dt, advance_to(t), set_interface(x, v), interface_forces(),
    interface_work(), energies(), momentum(), body_mass(name), total_mass(), body_names(), body_table(),
    contact_rows(), n_spheres(), info(), close()

YADE runs in its own process, started once (`yade -n -x -j1 partition_server.py` in a run folder of its own, with
the scene as partition_yade.json and the P4 helpers p4.py copied next to it; log.yade there). Each coupling step
set_interface stores the wall node positions and velocities and advance_to sends them with the number of DEM steps
(and any motion switch of a held / driven cluster) in one binary message over a pipe; YADE moves the interface
facets, runs its steps and answers with the per-node forces (time-averaged over the steps) and those of the last
step. Body table, contacts and energies are asked for only when the coupler records them. The parameter map is
the YADE backend's (adapters/yade/params.py: beta_pairs, yade_contact, yade_rolling; pitfall numbers refer to
shared/notes/dem_codes.md), the scene-to-YADE conventions (clumps, walls, facets, P4 resolution) those of
adapters/yade/writer.py; the YADE-side script documents the interface facets (partition_server.py).

Definitions that differ from the native partition (stated, not hidden):
  * time average: YADE integrates with leapfrog (forces at x_k, velocities at half steps). The impulse it
    delivers to the spheres over the n iterations of an advance is dt sum_k F_k (k = first .. last iteration of
    the advance); interface_forces() is that impulse / duration (native velocity Verlet: the trapezoid, with the
    forces at both ends of the advance counting half). Both are "impulse delivered / duration" of their integrator,
    so the momentum handed to the MPM equals the momentum the spheres lose, exactly, in both. momentum() and the
    body table use YADE's state.vel (the half-step velocity).
  * interface work: sum over advances of F_avg . v_node x duration (the rectangle of the same impulse) plus
    F_last . (jump of the nodes) at set_interface, as the native mesh_work.
  * facet kinematics: a segment is moved rigidly during a coupling step (translation + spin about z fitted to the
    node velocities: the normal velocity along the segment is exact, the stretch rate of the segment is not
    applied to the tangential contact velocity); at the next step the vertices are reset to the node positions.
  * energies: kinetic / potential from the states (half-step velocities); elastic = sum over the contacts that
    act (not the dominated ones) of 2/5 kno d^5/2 + |F_s|^2 / 2 k_s; dissipated = NaN: YADE's own counters
    (Law2_ScGeom_MindlinPhys_Mindlin calcEnergy: normal + shear damping + friction) also integrate the facet
    contacts that the P4 resolution takes back, whose forces never act (measured: 0.428 J against the native
    0.106 J in coupled_free_collision, while the same counters agree with the kinetic energy lost to 1.7 % on a
    single facet); the counters are given in info() as yade_law_dissipation_incl_dominated.
Not expressible (UnsupportedFeature, field named): a time-dependent gravity, non-"exact" cluster mass properties,
planes not normal to x, y or z, prescribed cluster spin, 3D scenes; and everything params.py refuses.
"""
from __future__ import annotations

import json
import math
import os
import select
import shutil
import struct
import subprocess
import tempfile
import time
import weakref
from pathlib import Path

import numpy as np

from adapters.common import find_binary, package_version
from adapters.geometry import mesh_triangles
from adapters.yade.params import beta_pairs, yade_contact, yade_rolling
from coupler.errors import SceneError, SimulationError, UnsupportedFeature

HERE = Path(__file__).resolve().parent
SERVER = HERE / "partition_server.py"
MAGIC = b"MDYP"
HEADER = struct.Struct("<4sIQQ")
CMD_STEP, CMD_STATE, CMD_TABLE, CMD_CONTACTS, CMD_QUIT = 1, 2, 3, 4, 9
STARTUP_TIMEOUT_S = float(os.environ.get("MPMDEM_YADE_STARTUP_TIMEOUT", "900"))   # YADE starts in 5-20 s here
REPLY_TIMEOUT_S = float(os.environ.get("MPMDEM_YADE_TIMEOUT", "600"))             # one coupling step / request


class YadePartitionError(SimulationError):
    """The YADE process crashed, hung past the timeout, or answered garbage (the message names its log)."""


def check_partition_supported(scene) -> None:
    """What the YADE partition cannot express, refused with the field named (the rest: params.py)."""
    dem = scene.dem
    if scene.dimension != 2:
        raise UnsupportedFeature("yade partition", "dimension", "coupled scenes are 2D")
    if scene.gravity_schedule is not None:
        raise UnsupportedFeature("yade partition", "gravity_schedule", "a time-dependent gravity is not written")
    for k, c in enumerate(dem.clusters):
        t = dem.templates[c.template]
        if t.mass_properties != "exact":
            raise UnsupportedFeature("yade partition", f"dem.templates.{c.template}.mass_properties",
                                     "YADE clumps compute their own mass properties from the members ('exact' only)")
        if c.motion is not None and np.any(np.asarray(c.motion.angular_velocity) != 0.0):
            raise UnsupportedFeature("yade partition", f"dem.clusters[{k}].motion.angular_velocity",
                                     "a prescribed spin of a clump is not written (translation only)")
    for k, p in enumerate(dem.planes):
        if np.count_nonzero(p.normal) != 1:
            raise UnsupportedFeature("yade partition", f"dem.planes[{k}].normal",
                                     "only planes normal to x, y or z map to YADE Wall bodies")
    beta_pairs(scene)
    yade_rolling(scene)
    yade_contact(scene)


def _quat_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def partition_inputs(scene, wall_name: str, dt: float, thickness: float) -> dict:
    """The scene as the YADE-side script reads it (partition_yade.json)."""
    dem = scene.dem
    pairs = beta_pairs(scene)                                    # P1 + P5, one value per material pair
    roll = yade_rolling(scene)
    r_max = max([float(dem.radius.max()) if dem.n_spheres else 0.0]
                + [float(dem.templates[c.template].radii.max()) for c in dem.clusters])
    walls = [{"name": p.name, "axis": int(np.nonzero(p.normal)[0][0]), "pos": p.point.tolist(),
              "material": p.material, "vel": p.velocity.tolist()} for p in dem.planes]
    meshes = []
    for m in dem.meshes:
        if m.name == wall_name:
            faces = np.asarray(m.faces, np.int64)
            if faces.shape[1] != 2:
                raise UnsupportedFeature("yade partition", "coupling", "the interface must be 2D segments")
            hd = 0.5 * thickness                                 # the strip spans the thickness
            v, tri = mesh_triangles(m.vertices, faces, hd)       # per segment k: triangles k and ns + k
            ns = len(faces)
            meshes.append({"name": m.name, "material": m.material, "vertices": v.tolist(), "triangles": tri.tolist(),
                           "vel": [0.0, 0.0, 0.0], "interface": True, "n_nodes": int(len(m.vertices)),
                           "segments": faces.tolist(), "half_depth": hd,
                           "segment_of": list(range(ns)) + list(range(ns))})
        else:
            v, tri = mesh_triangles(m.vertices, m.faces, 20.0 * r_max)
            meshes.append({"name": m.name, "material": m.material, "vertices": v.tolist(), "triangles": tri.tolist(),
                           "vel": m.velocity.tolist(), "interface": False})
    if not any(m["interface"] for m in meshes):
        raise SceneError("coupling", f"no DEM mesh named {wall_name!r} (the interface wall)")
    from coupler.dem.scene import smallest_radius
    skin = dem.skin if dem.skin is not None else 0.3 * smallest_radius(dem)
    clusters, pts = [], [dem.position] if dem.n_spheres else []
    for c in dem.clusters:
        t = dem.templates[c.template]
        mat = scene.materials[c.material]
        ms = mat.density * 4.0 / 3.0 * math.pi * t.radii ** 3
        com = (ms[:, None] * t.offsets).sum(0) / ms.sum()
        world = c.position + (t.offsets - com) @ _quat_matrix(c.orientation).T
        pts.append(world)
        clusters.append({"name": c.name, "material": c.material, "velocity": c.velocity.tolist(),
                         "angvel": c.angular_velocity.tolist(), "orientation": c.orientation.tolist(),
                         "members": [list(x) + [float(r)] for x, r in zip(world.tolist(), t.radii)]})
    if scene.domain is not None:
        lo, hi = (np.asarray(a, float) for a in scene.domain)
    else:                                                        # as DEMSolver._domain
        allx = np.concatenate(pts)
        lo, hi = allx.min(axis=0), allx.max(axis=0)
        size = max(float((hi - lo).max()), 1.0)
        lo, hi = lo - 10.0 * size, hi + 10.0 * size
    P = {"materials": {m.name: {"young": m.young, "poisson": m.poisson, "density": m.density}
                       for m in scene.materials.values()},
         "friction": yade_contact(scene), "beta_pairs": [[a, b, v] for (a, b), v in pairs.items()],
         "radius": dem.radius.tolist(), "position": dem.position.tolist(), "velocity": dem.velocity.tolist(),
         "angvel": dem.angular_velocity.tolist(), "material": list(dem.material), "names": list(dem.names),
         "planar": True, "walls": walls, "gravity": scene.gravity.tolist(), "dt": float(dt), "skin": float(skin),
         "clusters": clusters, "meshes": meshes, "domain": [lo.tolist(), hi.tolist()]}
    if roll is not None:
        P["rolling"] = roll
    return P


def _shutdown(proc, fds) -> None:
    """Finalizer: never leave a YADE process behind (the partition's own child, by its handle)."""
    for fd in fds:
        try:
            os.close(fd)
        except OSError:
            pass
    if proc.poll() is None:
        try:
            proc.wait(timeout=60)                 # EOF on its pipe ends the script (slow to exit when loaded)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


class YadeDEMPartition:
    @classmethod
    def checkpoint_refusal(cls) -> str:
        """Run checkpoints (coupler/checkpoint.py) cannot hold this partition: its state is in YADE's process."""
        return ("a coupled run with dem_partition = 'yade' has no checkpoints (its DEM state lives in YADE's "
                "process); use the native partition")

    def __init__(self, scene, wall_name: str, dt: float, motions=()):
        check_partition_supported(scene)
        from coupler.dem.timestep import stable_dt
        limit, reason = stable_dt(scene)
        if not (math.isfinite(dt) and dt > 0.0) or dt > limit:
            raise SceneError("coupling.dem_substeps", f"DEM step {dt:.4g} s: must be <= {limit:.4g} s (stable limit: "
                                                      f"{reason}); raise dem_substeps")
        exe = find_binary("yade")                                # BackendUnavailable when missing
        self.scene, self.wall_name = scene, wall_name
        self._dt = float(dt)
        self.dt_limit, self.dt_reason = limit, reason
        thickness = scene.coupling.thickness if scene.coupling is not None else 2.0 * float(scene.dem.radius.max())
        P = partition_inputs(scene, wall_name, self._dt, thickness)
        self.nn = next(m["n_nodes"] for m in P["meshes"] if m["interface"])
        base = os.environ.get("MPMDEM_YADE_PARTITION_DIR")
        if base:
            Path(base).mkdir(parents=True, exist_ok=True)
        self.workdir = Path(tempfile.mkdtemp(prefix="mpmdem-yade-partition-", dir=base))
        (self.workdir / "partition_yade.json").write_text(json.dumps(P))
        shutil.copy(SERVER, self.workdir / "partition_server.py")
        shutil.copy(HERE / "p4.py", self.workdir / "p4.py")
        self.log = self.workdir / "log.yade"
        # cluster motions: the scene's own ([[dem.clusters]] motion, ends at `until` inside a step as the native
        # solver) and the coupling schedule (phases switch at the start of a coupling step, as DEMPartition)
        self._names = list(scene.dem.names) + [c.name for c in scene.dem.clusters]
        self._until: dict[str, float] = {}
        self._pending_events: list = []
        for c in scene.dem.clusters:
            if c.motion is not None:
                self._pending_events.append([0, c.name, c.motion.kind, np.asarray(c.motion.velocity, float).tolist(),
                                             [0.0, 0.0, 0.0]])
                self._until[c.name] = float(c.motion.until)
        self.motions = list(motions)
        self._phase = {m.body: None for m in self.motions}
        # pipes: coupler -> YADE (r_in), YADE -> coupler (w_out)
        r_in, w_in = os.pipe()
        r_out, w_out = os.pipe()
        env = dict(os.environ, OMP_NUM_THREADS="1", MPMDEM_FD_IN=str(r_in), MPMDEM_FD_OUT=str(w_out))
        self.cmd = [exe, "-n", "-x", "-j1", "partition_server.py"]
        t0 = time.perf_counter()
        with open(self.log, "w") as fh:
            self.proc = subprocess.Popen(self.cmd, cwd=self.workdir, stdout=fh, stderr=subprocess.STDOUT,
                                         stdin=subprocess.DEVNULL, pass_fds=(r_in, w_out), env=env)
        os.close(r_in)
        os.close(w_out)
        self._w, self._r = w_in, r_out
        self._finalizer = weakref.finalize(self, _shutdown, self.proc, (w_in, r_out))
        self.closed = False
        self._nstep = 0
        self._x = self._v = None             # nodes as last set (their drift is x + v (t - t_set))
        self._t_set = 0.0
        self._F_avg = np.zeros((self.nn, 2))
        self._F_last = np.zeros((self.nn, 2))
        self._work = 0.0
        self._state_cache: tuple[int, np.ndarray] | None = None
        self._last_reply: dict = {}
        self.cost = {"startup_s": 0.0, "exchange_s": 0.0, "coupler_cpu_s": 0.0, "steps": 0}
        hello, _ = self._receive(STARTUP_TIMEOUT_S, "start-up")
        self.cost["startup_s"] = time.perf_counter() - t0
        if hello.get("hello") != "yade partition":
            self._fail("start-up", f"unexpected first message {hello!r}")
        self.yade_version = package_version("yade")
        self._masses = list(hello["masses"])
        self._n_spheres = int(hello["n_spheres"])
        self._n_facets = int(hello["facets"])

    # -- messages -------------------------------------------------------------------------------------------------
    def _fail(self, what: str, why: str):
        tail = ""
        try:
            tail = "\n".join(self.log.read_text(errors="replace").splitlines()[-12:])
        except OSError:
            pass
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.closed = True
        self._finalizer()                       # close the pipes; the run folder and its log are kept
        raise YadePartitionError(self._nstep, self.time, "<yade partition>", what,
                                 f"{why} (YADE log: {self.log})" + (f"\n{tail}" if tail else ""))

    def _send(self, cmd: int, meta: dict, arrays=()) -> None:
        meta = dict(meta)
        meta["arrays"] = [[name, list(np.shape(a))] for name, a in arrays]
        j = json.dumps(meta).encode()
        data = b"".join(np.ascontiguousarray(a, dtype="<f8").tobytes() for _, a in arrays)
        msg = memoryview(HEADER.pack(MAGIC, cmd, len(j), len(data)) + j + data)
        try:
            while msg:
                msg = msg[os.write(self._w, msg):]
        except (BrokenPipeError, OSError) as e:
            rc = self.proc.poll()
            self._fail("exchange", f"cannot send to YADE ({e}); YADE exit code {rc}")

    def _read(self, n: int, deadline: float, what: str, timeout: float) -> bytes:
        chunks, got = [], 0
        while got < n:
            left = deadline - time.perf_counter()
            if left <= 0:
                self._fail(what, f"no answer from YADE within {timeout:g} s (hung?)")
            ready, _, _ = select.select([self._r], [], [], min(left, 5.0))
            if not ready:
                if self.proc.poll() is not None:
                    self._fail(what, f"YADE exited with code {self.proc.returncode}")
                continue
            b = os.read(self._r, min(n - got, 1 << 20))
            if not b:
                self.proc.wait()
                self._fail(what, f"YADE closed the pipe (exit code {self.proc.returncode})")
            chunks.append(b)
            got += len(b)
        return b"".join(chunks)

    def _receive(self, timeout: float, what: str) -> tuple[dict, dict]:
        deadline = time.perf_counter() + timeout
        head = self._read(HEADER.size, deadline, what, timeout)
        magic, status, nj, na = HEADER.unpack(head)
        if magic != MAGIC or nj > 1 << 28 or na > 1 << 34:
            self._fail(what, f"garbage from YADE (header {head!r})")
        try:
            meta = json.loads(self._read(nj, deadline, what, timeout).decode()) if nj else {}
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            self._fail(what, f"garbage from YADE (json: {e})")
        raw = self._read(na, deadline, what, timeout) if na else b""
        if status != 0:
            self._fail(what, "the YADE script failed:\n" + str(meta.get("error", meta)))
        arrays, off = {}, 0
        for name, shape in meta.get("arrays", []):
            k = int(np.prod(shape)) * 8
            if off + k > len(raw):
                self._fail(what, f"garbage from YADE (array {name} {shape} beyond the {len(raw)} bytes sent)")
            arrays[name] = np.frombuffer(raw[off:off + k], dtype="<f8").reshape(shape).copy()
            off += k
        if off != len(raw):
            self._fail(what, f"garbage from YADE ({len(raw) - off} bytes left over)")
        return meta, arrays

    def _request(self, cmd: int, what: str, meta=None, arrays=()) -> tuple[dict, dict]:
        if self.closed:
            raise RuntimeError("YadeDEMPartition is closed")
        self._send(cmd, meta or {}, arrays)
        return self._receive(REPLY_TIMEOUT_S, what)

    # -- contract ---------------------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return self._nstep * self._dt

    @property
    def dt(self) -> float:
        return self._dt

    def set_interface(self, x: np.ndarray, v: np.ndarray) -> None:
        """Wall node positions now and their velocities over the coupling step, (nn, 2); sent with advance_to.
        The work of the last step's node forces over the jump of the nodes (x minus their drifted positions) is
        added to interface_work, as the native mesh_work."""
        x = np.array(x, float)
        v = np.array(v, float)
        if x.shape != (self.nn, 2) or v.shape != (self.nn, 2):
            raise ValueError(f"set_interface: x and v must have shape ({self.nn}, 2), got {x.shape}, {v.shape}")
        if not (np.isfinite(x).all() and np.isfinite(v).all()):
            raise ValueError("set_interface: x and v must be finite")
        if self._x is not None:
            drifted = self._x + self._v * (self.time - self._t_set)
            self._work += float(np.sum(self._F_last * (x - drifted)))
        self._x, self._v, self._t_set = x, v, self.time

    def interface_state(self) -> tuple[np.ndarray, np.ndarray]:
        """Wall node positions now (drifted linearly with the step's velocities since set_interface, as the
        facets YADE moves) and the node velocities of the current coupling step, (nn, 2) each; output only."""
        if self._x is None:
            z = np.zeros((self.nn, 2))
            return z, z.copy()
        return self._x + self._v * (self.time - self._t_set), self._v.copy()

    def advance_to(self, t: float) -> None:
        """Steps of dt to t (SimulationError "solver time mismatch" otherwise, as the native solver)."""
        k = (float(t) - self.time) / self._dt
        n = round(k)
        if n < 0 or abs(k - n) > 1e-9 * max(1.0, abs(k)):
            raise SimulationError(self._nstep, self.time, "<all>", "solver time mismatch",
                                  f"advance_to({t!r}) from t = {self.time!r} is {k:.12g} steps of dt = {self._dt!r}, "
                                  "not a whole number (set_time_step to a divisor of the coupling step)")
        if self._x is None:
            raise RuntimeError("set_interface before advance_to (the wall nodes)")
        events = self._events(int(n))
        t0, c0 = time.perf_counter(), time.thread_time()     # this thread only (not the MPM workers)
        meta, arr = self._request(CMD_STEP, "coupling step", {"n": int(n), "events": events},
                                  [("x", self._x), ("v", self._v)])
        rt = time.perf_counter() - t0
        self.cost["coupler_cpu_s"] += time.thread_time() - c0
        last = self._last_reply
        d_run = meta["run_s"] - last.get("run_s", 0.0)
        d_move = meta["move_s"] - last.get("move_s", 0.0)
        self.cost["exchange_s"] += rt - d_run - d_move
        self.cost["steps"] += 1
        self._last_reply = meta
        avg, lastf = arr.get("avg"), arr.get("last")
        if avg is None or lastf is None or avg.shape != (self.nn, 2) or lastf.shape != (self.nn, 2):
            self._fail("coupling step", "garbage from YADE (node force arrays missing or of the wrong shape)")
        if not (np.isfinite(avg).all() and np.isfinite(lastf).all()):
            self._fail("coupling step", "YADE returned non-finite interface forces")
        if int(meta["steps"]) != self._nstep + int(n):
            self._fail("coupling step", f"YADE is at step {meta['steps']}, expected {self._nstep + int(n)}")
        self._nstep += int(n)
        self._F_avg, self._F_last = avg, lastf
        self._work += float(np.sum(avg * self._v)) * n * self._dt
        self._state_cache = None
        if meta.get("health"):
            raise SimulationError(self._nstep, self.time, meta["health"].split(":")[0].replace("body ", ""),
                                  "state", f"{meta['health']} (YADE partition; log {self.log})")

    def _events(self, n: int) -> list:
        """Motion switches inside the next n steps: [step index, cluster, kind, velocity, spin]."""
        ev, self._pending_events = self._pending_events, []
        t, eps = self.time, 1e-9 * self._dt
        for body in self._phase:                                 # coupling schedule (DEMPartition._apply_motions)
            now = next((m for m in self.motions if m.body == body and m.start - eps <= t < m.until - eps), None)
            if now is not self._phase[body]:
                if now is None:
                    ev.append([0, body, "free", [0.0] * 3, [0.0] * 3])
                else:
                    ev.append([0, body, now.kind, np.asarray(now.velocity, float).tolist() if now.kind == "velocity"
                               else [0.0] * 3, [0.0] * 3])
                self._until.pop(body, None)
                self._phase[body] = now
        for body, until in list(self._until.items()):            # the scene's own motion ends at `until`
            if not math.isfinite(until) or until <= t:
                continue
            k = max(1, int(math.ceil((until - t) / self._dt - 1e-9)))
            if k <= n:
                ev.append([k, body, "free", [0.0] * 3, [0.0] * 3])
                del self._until[body]
        return ev

    def interface_forces(self) -> np.ndarray:
        """Time-averaged force BY the spheres ON the wall nodes over the last advance_to, (nn, 2) [N]."""
        return self._F_avg.copy()

    def interface_work(self) -> float:
        """Cumulative work done by the spheres on the moving wall nodes [J] (node drift and node jumps)."""
        return self._work

    def _state(self) -> np.ndarray:
        if self._state_cache is None or self._state_cache[0] != self._nstep:
            _, arr = self._request(CMD_STATE, "state")
            self._state_cache = (self._nstep, arr["state"])
        return self._state_cache[1]

    def energies(self) -> tuple[float, float, float, float]:
        """(kinetic, potential, elastic, dissipated = NaN) [J] (definitions and why: module docstring)."""
        k, p, e, d = (float(v) for v in self._state()[:4])
        self._law_dissipation = d
        return k, p, e, float("nan")

    def momentum(self) -> np.ndarray:
        return self._state()[4:7].copy()

    def body_mass(self, name: str) -> float:
        return float(self._masses[self._names.index(name)])

    def total_mass(self) -> float:
        return float(sum(self._masses))

    def body_names(self) -> list[str]:
        return list(self._names)

    def body_table(self) -> np.ndarray:
        _, arr = self._request(CMD_TABLE, "body table")
        return arr["bodies"]

    def contact_rows(self):
        meta, arr = self._request(CMD_CONTACTS, "contacts")
        return list(meta["i"]), list(meta["j"]), arr["data"]

    def n_spheres(self) -> int:
        return self._n_spheres

    def info(self) -> dict:
        c = self.cost
        n = max(1, c["steps"])
        last = self._last_reply
        y = {k: float(last.get(k, 0.0)) for k in ("run_s", "run_cpu_s", "hook_s", "hook_cpu_s", "move_s",
                                                   "move_cpu_s", "step_cpu_s")}
        # YADE's CPU for a step outside O.run and the facet move: receive + unpack + pack + send
        y_io_cpu = max(0.0, y["step_cpu_s"] - y["run_cpu_s"] - y["move_cpu_s"])
        per = {"exchange_wall": c["exchange_s"], "exchange_cpu": c["coupler_cpu_s"] + y_io_cpu,
               "exchange_cpu_coupler": c["coupler_cpu_s"], "exchange_cpu_yade": y_io_cpu,
               "yade_run_wall": y["run_s"], "yade_run_cpu": y["run_cpu_s"], "yade_hook_wall": y["hook_s"],
               "yade_hook_cpu": y["hook_cpu_s"], "yade_move_facets_wall": y["move_s"],
               "yade_move_facets_cpu": y["move_cpu_s"]}
        return {"dem_partition": "yade", "dem_code_version": self.yade_version, "dem_dt": self._dt,
                "dem_dt_limit": self.dt_limit, "dem_dt_limit_reason": self.dt_reason, "dem_steps": self._nstep,
                "yade_log": str(self.log), "yade_facets": self._n_facets,
                "yade_law_dissipation_incl_dominated": getattr(self, "_law_dissipation", float("nan")),
                "dem_dissipated_note": ("NaN: YADE's Law2 energy counters include the P4-dominated facet contacts "
                                        "(adapters/yade/partition.py)"),
                "yade_p4_dropped_contact_steps": int(last.get("p4_dropped_contact_steps", 0)),
                "yade_startup_s": c["startup_s"], "yade_coupling_steps": c["steps"],
                "yade_cost_s": per, "yade_cost_per_step_us": {k: 1e6 * v / n for k, v in per.items()},
                "yade_cost_note": ("per coupling step; exchange_wall = round trip minus YADE's O.run and facet "
                                   "move (wall clock: includes waiting for the CPU on a loaded machine); "
                                   "exchange_cpu = CPU time of packing, sending, receiving, unpacking on both "
                                   "sides; yade_run = O.run of the DEM steps, including yade_hook (the "
                                   "per-iteration P4 resolution + node force distribution in Python); "
                                   "yade_move_facets = moving the interface facets to the nodes")}

    def close(self) -> None:
        """Ends the YADE process (QUIT, then EOF) and removes its run folder (kept when it failed)."""
        if getattr(self, "closed", True):
            return
        try:
            meta, _ = self._request(CMD_QUIT, "quit")
            self._last_reply = {**self._last_reply, **meta}          # final cost totals
        finally:
            self.closed = True
            self._finalizer()
        if self.proc.returncode == 0 and not os.environ.get("MPMDEM_KEEP_YADE_PARTITION"):
            shutil.rmtree(self.workdir, ignore_errors=True)
