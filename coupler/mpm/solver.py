"""Explicit MPM solver: MPMSolver(scene), run_mpm(scene, out_dir) -> Result.

Stepping (all in compiled code, coupler/mpm/kernels.py: one step definition, n steps per call):
  .advance(n)            n steps of .dt
  .advance_to(t)         k = ceil((t - .t) / .dt - 1e-9) equal steps of (t - .t) / k <= .dt, then .t = t exactly
  .step()                one step of .dt (= advance(1))
Coupling interface (contract in /work/COORD.md):
  .set_point_loads(f)    (nb, 2) N per unit depth on the boundary particles, held until changed (alias
                         apply_point_loads)
  .interface_state()     boundary particles in outline order: x, displacement, velocity, area, body, wall,
                         segment (edge index of the body's outline), index; outline = {body: indices}
                         (boundary_particle_state stays, the same dict)
  .dropped_loads()       point loads (or parts) with no node holding real mass within reach (dropped): count,
                         impulse_dropped, impulse_applied, max_fraction; a step whose dropped fraction of the total
                         |f| exceeds scene mpm.max_dropped_load_fraction (default 0.01) stops the run with a
                         SimulationError; parts moved from a support of slivers to the nearest full nodes: rerouted_
                         count, impulse_rerouted
  .stranded_boundary_particles()  boundary particles with no grid mass within reach (they stop): counted
  .energies(), .particles_frame(), .body_rows() (rows of the MPM body table, results.MPM_BODY_COLUMNS)

Particle snapshot columns: position, velocity, stress (tension positive), eps_p = accumulated equivalent
(deviatoric) plastic strain (definition in materials.py), mass, current volume, displacement from the start.
Boundary particles (scene mpm.boundary_particles): points on each body's outline, spacing = point spacing, each with
its tributary length; they carry point loads (apply_point_loads), move with the grid velocity like material points
(kernels.advect_boundary; the ones created on a wall stay on it) and are checked inside the grid like them."""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from coupler.checkpoint import Checkpoints, Restart, read_pickle, write_pickle
from coupler.errors import SimulationError
from coupler.scene import output_stride
from coupler.mpm import kernels as K
from coupler.mpm.scene import seed_points
from coupler.mpm.shapes import GIMP, REGISTRY as SHAPES, check_shape
from coupler.results import BODY_COLUMNS, ENERGY_COLUMNS, MPM_BODY_COLUMNS, Result, ResultStream, StreamedResult

REORDER_EVERY = 100   # steps between two re-orderings of the point arrays into strip order (MPMSolver._reorder)

_BC = {"fixed": 0, "slip": 1, "friction": 2, "open": 3}
_MODE = {"usl": 0, "musl": 1, "apic": 2}
PARTICLE_COLUMNS = ["t", "id", "body", "x", "y", "vx", "vy", "sxx", "syy", "sxy", "szz", "eps_p", "mass", "volume",
                    "ux", "uy"]


# time integration schemes (scene mpm.scheme): module:class, resolved with importlib (not an import edge)
SCHEMES = {"explicit": "coupler.mpm.solver:MPMSolver",
           "implicit": "coupler.mpm.implicit.solver:ImplicitMPMSolver"}


class MPMSolver:
    def __new__(cls, scene=None, *args, **kwargs):
        """MPMSolver(scene) builds the solver of the scene's scheme (SCHEMES), so every caller wraps either."""
        scheme = getattr(getattr(scene, "mpm", None), "scheme", "explicit")
        if cls is MPMSolver and scheme != "explicit":
            import importlib
            mod, _, name = SCHEMES[scheme].partition(":")
            cls = getattr(importlib.import_module(mod), name)
        return super().__new__(cls)

    def __init__(self, scene):
        self.scene = scene
        ms = scene.mpm
        self.ms = ms
        self.h = float(ms.cell_size)
        self.org = np.asarray(ms.origin, float)
        self.nx, self.ny = (int(round(s / self.h)) for s in ms.size)
        self.kind = check_shape(SHAPES[ms.shape])
        self.mode = _MODE[ms.transfer]
        self.g = np.asarray(scene.gravity[:2], float)
        xs, ms_, vols, vel, lps, mids, bid = [], [], [], [], [], [], []
        prms = []
        self.body_names = []
        bx, bA, bbody, bseg = [], [], [], []
        for b_i, body in enumerate(ms.bodies):
            rho = scene.materials[body.material].density
            n = body.particles_per_cell
            P, d = seed_points(body.polygon, self.org, self.h, n)
            xs.append(P)
            vols.append(np.full(len(P), d * d))
            ms_.append(np.full(len(P), rho * d * d))
            vel.append(np.tile(body.velocity, (len(P), 1)))
            lps.append(np.full(len(P), 0.5 / n))
            mids.append(np.full(len(P), b_i))
            bid.append(np.full(len(P), b_i))
            prms.append(body.model.pack())
            self.body_names.append(body.name)
            if ms.boundary_particles:  # outline points, spacing d, each with the tributary length (x unit depth)
                poly = body.polygon
                for a in range(len(poly)):
                    p0, p1 = poly[a], poly[(a + 1) % len(poly)]
                    L = float(np.hypot(*(p1 - p0)))
                    k = max(1, int(round(L / d)))
                    t = (np.arange(k) + 0.5) / k
                    bx.append(p0 + t[:, None] * (p1 - p0))
                    bA.append(np.full(k, L / k))
                    bbody.append(np.full(k, b_i))
                    bseg.append(np.full(k, a))
        self.x = np.ascontiguousarray(np.vstack(xs))
        self.x0 = self.x.copy()
        self.v = np.ascontiguousarray(np.vstack(vel))
        self.m = np.concatenate(ms_)
        self.vol0 = np.concatenate(vols)
        self.vol = self.vol0.copy()
        self.lp = np.concatenate(lps) if self.kind == GIMP else np.full(len(self.m), 0.25)
        self.mid = np.concatenate(mids).astype(np.int64)
        self.bid = np.concatenate(bid).astype(np.int64)
        self.pid = np.arange(len(self.bid), dtype=np.int64)   # point id (creation order); _reorder permutes rows
        self.prm = np.ascontiguousarray(np.vstack(prms))
        n = len(self.m)
        self.C = np.zeros((n, 2, 2))
        self.F = np.tile(np.array([1.0, 0.0, 0.0, 1.0]), (n, 1))
        self.s = np.zeros((n, 4))
        for b_i, body in enumerate(ms.bodies):
            if body.k0 is not None:   # geostatic state (scene.py _initial_stress)
                sel = self.bid == b_i
                syy = scene.materials[body.material].density * self.g[1] * (body.surface - self.x[sel, 1])
                self.s[sel] = np.column_stack([body.k0 * syy, syy, np.zeros_like(syy), body.k0 * syy])
        self.eps_p = np.zeros(n)
        self.fext = np.zeros((n, 2))
        if bx:
            self.xb = np.ascontiguousarray(np.vstack(bx))
            self.b_area = np.concatenate(bA)
            self.b_body = np.concatenate(bbody).astype(np.int64)
            self.b_segment = np.concatenate(bseg).astype(np.int64)
        else:
            self.xb, self.b_area, self.b_body = np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int64)
            self.b_segment = np.zeros(0, np.int64)
        # points on a side that is not open are attached to that wall (kernels.advect_boundary); their normal
        # coordinate is set to the wall's exactly (the outline vertices may differ from it by round-off)
        self.b_wall = np.full(len(self.xb), -1, np.int64)
        lo_hi = (self.org[0], self.org[0] + ms.size[0], self.org[1], self.org[1] + ms.size[1])
        for side, name in enumerate(("left", "right", "bottom", "top")):
            if ms.boundary[name].kind == "open":
                continue
            d = side // 2
            on = np.abs(self.xb[:, d] - lo_hi[side]) <= 1e-12 * max(1.0, abs(lo_hi[side]), float(ms.size[d]))
            self.xb[on, d] = lo_hi[side]
            self.b_wall[on & (self.b_wall < 0)] = side
        self.xb0 = self.xb.copy()
        # sliver mass of each boundary particle's support nodes (kernels._sliver_weight): the fraction
        # mpm.boundary_sliver_fraction of a full node's mass rho h^2 (per unit depth; sum_p N_i m_p inside a body)
        rho_b = np.array([scene.materials[b.material].density for b in ms.bodies])
        self.b_mc = float(ms.boundary_sliver_fraction) * rho_b[self.b_body] * self.h ** 2 if len(self.xb) \
            else np.zeros(0)
        self.vb = np.zeros_like(self.xb)
        self.fb = np.zeros_like(self.xb)
        NX, NY = self.nx + 1 + 2 * K.PAD, self.ny + 1 + 2 * K.PAD
        self.G = np.zeros((NX, NY, 5))      # m, p_x, p_y, f_x, f_y per node
        self.V = np.zeros((NX, NY, 4))      # v0_x, v0_y, v1_x, v1_y per node
        self.strip_start = np.zeros(K.n_strips(NX) + 1, np.int64)
        self.strip_order = np.zeros(n, np.int64)
        self._scratch = np.zeros(n, np.int64)
        self._chunk_cost = K.new_cost(n)    # cycles per gather chunk: splits the gather between the threads
        self._strip_cost = K.new_strip_cost(NX)   # cycles per P2G strip / grid-update column block: split those
        # box of the "left the grid" check. uGIMP: a point is a domain of half-width lp; with the wall BCs on the
        # wall and ghost nodes its centre can still be drawn up to lp beyond a wall (it feels the first interior
        # node until its domain has left the box, Bardenhagen & Kober 2004), so the box is widened by lp there.
        # Linear and bspline2 (boundary-modified) points cannot cross a wall whose nodes do not move into it.
        tol = float(self.lp.max()) * self.h if self.kind == GIMP and len(self.lp) else 0.0
        self.box_tol = tol
        self.box = np.array([self.org[0] - tol, self.org[1] - tol, self.org[0] + ms.size[0] + tol,
                             self.org[1] + ms.size[1] + tol])
        self.bc = np.array([_BC[ms.boundary[s].kind] for s in ("left", "right", "bottom", "top")], np.int64)
        self.mu = np.array([ms.boundary[s].friction for s in ("left", "right", "bottom", "top")])
        # time step: CFL on the P-wave speed (+ initial speed), factor ms.cfl (default 0.5), unless time.dt given
        cmax = 0.0
        for body in ms.bodies:
            mat = scene.materials[body.material]
            Kb = mat.young / (3 * (1 - 2 * mat.poisson))
            Gb = mat.shear_modulus
            cmax = max(cmax, math.sqrt((Kb + 4 * Gb / 3) / mat.density) + float(np.hypot(*body.velocity)))
        self.dt = scene.time.dt if scene.time.dt is not None else ms.cfl * self.h / cmax
        self.t = 0.0
        self.nstep = 0
        self.max_dropped_load_fraction = float(ms.max_dropped_load_fraction)
        # kernels.Boundary.drop: dropped loads (count, impulse dropped, impulse applied, max fraction), stranded
        # boundary particles (particle-steps, most in one step), rerouted loads (count, impulse rerouted)
        self.drop = np.zeros(8)
        self.timer = np.zeros(len(K.PHASES), np.int64)   # cycles per phase (advance(..., profile=True))

    # ---- coupling interface -------------------------------------------------------------------------------
    def set_point_loads(self, forces: np.ndarray) -> None:
        """Forces (nb, 2) [N per unit depth] on the boundary particles (interface_state order), held until
        changed."""
        f = np.asarray(forces, float)
        if f.shape != self.fb.shape:
            raise ValueError(f"point loads must have shape {self.fb.shape} (boundary particles x 2), got {f.shape}")
        if not np.all(np.isfinite(f)):
            raise ValueError("point loads must be finite")
        self.fb[:] = f

    apply_point_loads = set_point_loads

    def interface_state(self) -> dict:
        """Boundary particles, in outline order per body (the order they were created in: body by body, each
        body's outline edges in order, points along an edge from its first vertex): x, displacement (from the
        start), velocity (of the last step), area (tributary length x unit depth), body (index into
        body_names), wall (side it is attached to, -1 none), segment (edge index in that body's outline),
        index (0..nb-1), outline = {body name: indices in outline order}, t."""
        return {"x": self.xb.copy(), "displacement": self.xb - self.xb0, "velocity": self.vb.copy(),
                "area": self.b_area.copy(), "body": self.b_body.copy(), "wall": self.b_wall.copy(),
                "segment": self.b_segment.copy(), "index": np.arange(len(self.xb)),
                "outline": {name: np.flatnonzero(self.b_body == b) for b, name in enumerate(self.body_names)},
                "t": self.t}

    boundary_particle_state = interface_state

    def dropped_loads(self) -> dict:
        """Point-load applications a boundary particle's support could not carry whole (kernels.spread_loads):
        count, impulse_dropped = sum |f| dt of the parts dropped (no node holding real mass within reach of the
        support) [N s per unit depth], impulse_applied = sum |f| dt of all, max_fraction = largest dropped fraction of
        a step's total |f|, limit = mpm.max_dropped_load_fraction; rerouted_count, impulse_rerouted = the same for the
        parts a support of slivers (or of no mass) could not carry that went to the nearest full nodes (force kept,
        kernels._transfer)."""
        d = self.drop
        return {"count": int(d[0]), "impulse_dropped": float(d[1]), "impulse_applied": float(d[2]),
                "max_fraction": float(d[3]), "limit": self.max_dropped_load_fraction,
                "rerouted_count": int(d[6]), "impulse_rerouted": float(d[7])}

    def stranded_boundary_particles(self) -> dict:
        """Boundary particles no node of whose support or reroute window (kernels._reroute_window) held grid mass in a
        step (kernels.move_boundary): they do not move that step (v = 0), so the outline no longer follows the body
        there. particle_steps = sum over steps of their number, max_at_once = most in one step, of
        boundary_particles. Counted and reported, not an error: a loaded one has its load dropped, which spread_loads
        counts and limits (mpm.max_dropped_load_fraction)."""
        d = self.drop
        return {"particle_steps": int(d[4]), "max_at_once": int(d[5]), "boundary_particles": int(len(self.xb))}

    # ---- stepping -----------------------------------------------------------------------------------------
    def state(self):
        """The solver state as the kernels' named tuples (Setup, Points, Boundary, Grid); the arrays are the
        solver's own (a kernel writes into them)."""
        S = K.Setup(self.kind, self.mode, float(self.org[0]), float(self.org[1]), self.h, self.nx, self.ny,
                    float(self.g[0]), float(self.g[1]), float(self.ms.damping), self.box, self.bc, self.mu, self.prm,
                    self.max_dropped_load_fraction)
        P = K.Points(self.x, self.v, self.C, self.F, self.m, self.vol, self.vol0, self.s, self.eps_p, self.lp,
                     self.mid, self.fext)
        B = K.Boundary(self.xb, self.vb, self.fb, self.b_wall, self.drop, self.b_mc)
        Gr = K.Grid(self.G, self.V, self.strip_start, self.strip_order, self._scratch, self._chunk_cost,
                    self._strip_cost)
        return S, P, B, Gr

    def advance(self, nsteps: int, dt: float | None = None, profile: bool = False) -> None:
        """nsteps steps of dt (default self.dt) in one compiled loop (kernels.advance). profile: add the cycles
        of each phase to self.timer (kernels.PHASES)."""
        dt = self.dt if dt is None else float(dt)
        S, P, B, Gr = self.state()
        left = int(nsteps)
        while left > 0:
            k = min(left, REORDER_EVERY - self.nstep % REORDER_EVERY)
            done, t, code, idx = K.advance(S, P, B, Gr, dt, k, self.t, bool(profile), self.timer)
            self.nstep += int(done)
            self.t = t
            if code != K.STATUS_OK:
                self._raise(code, int(idx))
            left -= k
            if self.nstep % REORDER_EVERY == 0:
                self._reorder()

    def _reorder(self) -> None:
        """Store the points in the strip order of the last step's sort (kernels.sort_strips), in place: each thread's
        share of the P2G strips and of the gather is then one contiguous block of memory (2 threads: 15 % more
        MP-steps/s on the 12,800-point bench, 2026-12-02). Done at fixed step numbers (every REORDER_EVERY steps
        of the run), so the bits of a run do not depend on how it is cut into advance() calls or on the thread
        count; the order of the sums in P2G follows the stored order. Rows keep their point id in self.pid (the
        tables are written in id order)."""
        o = self.strip_order
        if np.array_equal(o, np.arange(len(o))):
            return
        o = o.copy()
        for a in (self.x, self.x0, self.v, self.C, self.F, self.m, self.vol, self.vol0, self.s, self.eps_p, self.lp,
                  self.mid, self.fext, self.bid, self.pid):
            a[:] = a[o]

    def step(self) -> None:
        """One explicit step of self.dt (kernels.step)."""
        self.advance(1)

    def advance_to(self, t: float) -> int:
        """Advance to time t in k = ceil((t - now)/dt - 1e-9) equal steps of (t - now)/k <= dt; the clock is
        then t exactly. Returns k. t earlier than now (beyond round-off) is an error."""
        span = float(t) - self.t
        if span < -1e-12 * max(1.0, abs(t)):
            raise ValueError(f"advance_to({t!r}): the MPM is already at t = {self.t!r}")
        if span <= 0.0:
            return 0
        k = max(1, int(math.ceil(span / self.dt - 1e-9)))
        self.advance(k, dt=span / k)
        self.t = float(t)
        return k

    def _raise(self, code: int, p: int):
        """SimulationError for a kernels.advance status (step and time are those of the failing step)."""
        if code == K.STATUS_POINT_OUT or code == K.STATUS_POINT_MOVED_OUT:
            self._raise_outside("material point", p, self.x, self.body_names[self.bid[p]], int(self.pid[p]))
        if code == K.STATUS_BOUNDARY_OUT or code == K.STATUS_BOUNDARY_MOVED_OUT:
            self._raise_outside("boundary particle", p, self.xb, self.body_names[self.b_body[p]])
        if code == K.STATUS_STRESS:
            raise SimulationError(self.nstep, self.t, self.body_names[self.bid[p]], "stress",
                                  f"non-finite stress at material point {int(self.pid[p])}")
        if code == K.STATUS_DROPPED:
            d = self.dropped_loads()
            raise SimulationError(self.nstep, self.t, self.body_names[self.b_body[p]], "point load",
                                  f"{100 * d['max_fraction']:.3g} % of the point load of this step fell on boundary "
                                  f"particles with no node holding real mass in or within {K.REACH} rings of their support (first: boundary particle {p} at "
                                  f"({self.xb[p, 0]:.6g}, {self.xb[p, 1]:.6g})); allowed: mpm.max_dropped_load_"
                                  f"fraction = {self.max_dropped_load_fraction:g}; dropped so far: {d['count']}")
        raise ValueError(f"unknown shape function id {p} (coupler/mpm/shapes.py)")

    def _raise_outside(self, what, p, x, body, name=None):
        """p: row of x; name: the id the message gives (material points: self.pid[p]; default p)."""
        o, hi = self.box[:2] + self.box_tol, self.box[2:] - self.box_tol
        q = "position" if not np.all(np.isfinite(x[p])) else "position (left the grid)"
        extra = f" by more than the GIMP half-width lp = {self.box_tol:.3g} m" if self.box_tol > 0 else ""
        raise SimulationError(self.nstep, self.t, body, q,
                              f"{what} {p if name is None else name} at ({x[p, 0]:.6g}, {x[p, 1]:.6g}) is outside the grid "
                              f"[{o[0]:g}, {hi[0]:g}] x [{o[1]:g}, {hi[1]:g}]{extra}")

    # ---- checkpoint / restart ------------------------------------------------------------------------
    # the solver is pickled whole (coupler/checkpoint.py write_pickle); the fingerprint of what the scene sets tells
    # a checkpoint of another scene from one of this scene before any of its state is loaded.
    def checkpoint_refusal(self) -> str | None:
        """Why this solver cannot be checkpointed (None: it can; the implicit solver's modified Newton cannot)."""
        return None

    def fingerprint(self) -> str:
        """sha256 of what the scene alone sets (in point-id order, so any row order gives the same): the seeded
        points (x0, mass, volume, body), boundary particles, material parameters, grid and dt."""
        import hashlib
        o = np.argsort(self.pid)
        hsh = hashlib.sha256()
        for a in (self.x0[o], self.m[o], self.vol0[o], self.bid[o], self.xb0, self.b_area, self.prm,
                  np.array([self.h, *self.org, self.nx, self.ny, self.dt], float)):
            hsh.update(np.ascontiguousarray(a).tobytes())
        return hsh.hexdigest()

    def save_checkpoint(self, path, meta: dict | None = None) -> Path:
        """Write the solver, pickled whole (coupler/checkpoint.write_pickle: the format of the run checkpoints, written
        through a temporary file renamed over the last), with its fingerprint and `meta` (JSON-able: the caller's
        provenance). load_checkpoint then continues bitwise as if the run had not stopped. NotImplementedError
        when checkpoint_refusal() says it cannot be saved."""
        why = self.checkpoint_refusal()
        if why:
            raise NotImplementedError(why)
        return write_pickle(path, {"fingerprint": self.fingerprint(), "class": type(self).__name__,
                                   "meta": dict(meta or {})}, self)

    def load_checkpoint(self, path, check=None) -> dict:
        """Restore the state written by save_checkpoint into this solver, built from the same scene (ValueError naming
        the checkpoint when its class or fingerprint differs: another scheme, points, grid, materials or dt);
        returns its meta. check(meta): the caller's own test of the meta (e.g. the commit), run before the
        pickled solver is read."""
        def same(header):
            if header["class"] != type(self).__name__ or header["fingerprint"] != self.fingerprint():
                raise ValueError(f"checkpoint {path}: written for another scene (points, grid, materials, dt or "
                                 "scheme differ)")
            if check is not None:
                check(header["meta"])

        header, sol = read_pickle(path, same)
        self.__dict__.update(vars(sol))
        return header["meta"]

    # ---- diagnostics --------------------------------------------------------------------------------------
    def energies(self) -> dict:
        ke = 0.5 * float(np.sum(self.m * np.sum(self.v ** 2, 1)))
        pe = -float(np.sum(self.m * (self.x @ self.g)))
        el = 0.0
        for b, body in enumerate(self.ms.bodies):
            mat = self.scene.materials[body.material]
            E, nu = mat.young, mat.poisson
            sel = self.mid == b
            sx, sy, sxy, sz = self.s[sel].T
            # complementary energy density of the elastic part, 1/(2E)[s:s - nu((tr s)^2 - s:s) ... ] plane strain 3D
            w = ((sx * sx + sy * sy + sz * sz) - 2 * nu * (sx * sy + sy * sz + sx * sz)
                 + 2 * (1 + nu) * sxy * sxy) / (2 * E)
            el += float(np.sum(w * self.vol[sel]))
        return {"kinetic": ke, "potential": pe, "elastic": el}

    def particles_frame(self) -> pd.DataFrame:
        """The material-point table, one row per point in id order (the solver may store them in another order)."""
        n = len(self.m)
        o = np.argsort(self.pid)
        x, v, s, x0 = self.x[o], self.v[o], self.s[o], self.x0[o]
        return pd.DataFrame({"t": np.full(n, self.t), "id": self.pid[o],
                             "body": [self.body_names[b] for b in self.bid[o]] if len(self.body_names) > 1
                             else np.full(n, self.body_names[0], dtype=object),
                             "x": x[:, 0], "y": x[:, 1], "vx": v[:, 0], "vy": v[:, 1],
                             "sxx": s[:, 0], "syy": s[:, 1], "sxy": s[:, 2], "szz": s[:, 3],
                             "eps_p": self.eps_p[o], "mass": self.m[o], "volume": self.vol[o],
                             "ux": x[:, 0] - x0[:, 0], "uy": x[:, 1] - x0[:, 1]})

    def body_rows(self) -> list[dict]:
        """Rows of the MPM body table (results.MPM_BODY_COLUMNS, documented in coupler/results.py)."""
        rows = []
        for b, name in enumerate(self.body_names):
            sel = self.bid == b
            mb = self.m[sel]
            M = mb.sum()
            x, v = self.x[sel], self.v[sel]
            u = x - self.x0[sel]
            c = (mb[:, None] * x).sum(0) / M
            w = (mb[:, None] * v).sum(0) / M
            um = (mb[:, None] * u).sum(0) / M
            rows.append({"t": self.t, "body": name, "mass": M, "x": c[0], "y": c[1], "vx": w[0], "vy": w[1],
                         "kinetic": 0.5 * float(np.sum(mb * np.sum(v ** 2, 1))), "ux": um[0], "uy": um[1],
                         "ux_max": float(u[:, 0].max()), "uy_min": float(u[:, 1].min()),
                         "xmin": float(x[:, 0].min()), "xmax": float(x[:, 0].max()), "ymin": float(x[:, 1].min()),
                         "ymax": float(x[:, 1].max()), "eps_p_max": float(self.eps_p[sel].max()),
                         "n_points": int(sel.sum())})
        return rows


def run_mpm(scene, out_dir, progress: bool = False, restart: Restart | None = None,
            keep_tables: bool = True) -> Result:
    """keep_tables = False (with out_dir): the snapshots are not held in memory; the returned StreamedResult reads
    them back from out_dir when used (coupler/results.py)."""
    t0 = time.perf_counter()
    ck = Checkpoints(restart, out_dir, scene)          # restart files (coupler/checkpoint.py)
    saved = ck.resumed()
    if saved is None:
        sol = MPMSolver(scene)
        bodies, energy, snaps, k = [], [], [], 0
        disc = {"at_end": 0, "max_at_output": 0, "points_ever_at_output": np.zeros(len(sol.m), bool)}
    else:
        sol, bodies, energy, snaps, disc, k = (saved[n] for n in ("sol", "bodies", "energy", "snaps", "disc", "k"))
    ck.check(sol)
    keep = keep_tables or out_dir is None
    T = scene.time.t_end
    nsteps = int(math.ceil(T / sol.dt - 1e-9))
    every = output_stride(scene, sol.dt, "the MPM time step")     # SceneError if output_interval < dt
    stream = None if out_dir is None else ResultStream(out_dir, ["bodies", "contacts", "mpm_bodies", "energy", "particles"],
                                                       {"scene": scene.name, "backend": "native", "dt": sol.dt,
                                                        "particles": int(len(sol.m))},
                                                       resume=None if saved is None else (sol.t, len(snaps)))

    from coupler.mpm.constitutive.disconnected import count as count_disconnected

    def record(last: bool = False):
        d = count_disconnected(sol.prm, sol.mid, sol.s, sol.vol, sol.vol0)    # sampled at the output times
        disc["at_end"] = int(d.sum())
        disc["max_at_output"] = max(disc["max_at_output"], disc["at_end"])
        disc["points_ever_at_output"][sol.pid[d]] = True       # by point id (the solver reorders its rows)
        rows = sol.body_rows()
        bodies.extend(rows)
        e = sol.energies()
        energy.append({"t": sol.t, **e, "dissipated": float("nan")})
        snap = scene.output.snapshot_at(len(energy) - 1, scene.time.output_interval, last)
        frame = sol.particles_frame() if snap else None
        if snap:
            snaps.append((sol.t, frame if keep else None))
        if stream is not None:
            stream.append(sol.t, {"mpm_bodies": [[r[c] for c in MPM_BODY_COLUMNS] for r in rows],
                                  "energy": [[energy[-1][c] for c in ENERGY_COLUMNS]] if scene.output.energy else []},
                          frame)
        ck.output_done(sol.t, k, lambda: {"sol": sol, "bodies": bodies, "energy": energy,
                                          "snaps": ck.frames_out(snaps), "disc": disc, "k": k}, last)

    from tqdm import tqdm             # progress bar as the DEM's (stderr, after 3 s, off with progress=False)
    try:
        if saved is None:
            record()
        bar = tqdm(total=nsteps, initial=k, disable=not progress, delay=3.0, unit="step", mininterval=1.0,
                   leave=False, desc="mpm")
        chunk = max(100, nsteps // 200)   # the bar moves between outputs too (chunks of steps: the same results)
        while k < nsteps:                 # compiled loop between outputs: every `every` steps and the last
            n = min(every - k % every, nsteps - k, chunk)
            sol.advance(n)
            k += n
            if k % every == 0 or k == nsteps:
                record(last=k == nsteps)
            bar.update(n)
    except SimulationError as err:        # the tables up to the last output time stay on disk (ResultStream)
        if stream is not None:
            stream.stopped(err)
        raise
    bar.close()
    wall = time.perf_counter() - t0
    mpm_bodies = pd.DataFrame(bodies, columns=MPM_BODY_COLUMNS)
    energy = pd.DataFrame(energy if scene.output.energy else [], columns=ENERGY_COLUMNS)
    if keep:
        res = Result(mpm_bodies=mpm_bodies, energy=energy,
                     particles=ck.frames_in(snaps) if saved is not None else snaps)
    else:
        res = StreamedResult(out_dir, {}, energy, mpm_bodies)
    res.summary.update({"scene": scene.name, "backend": "native", "wall_time_s": wall, "steps": nsteps,
                        "dt": sol.dt, "particles": int(len(sol.m)), "mpm_cells": [sol.nx, sol.ny],
                        "mpm_shape_function": sol.ms.shape, "mpm_transfer": sol.ms.transfer,
                        "mpm_dropped_point_loads": sol.dropped_loads(),
                        "mpm_stranded_boundary_particles": sol.stranded_boundary_particles(),
                        "mpm_disconnected_points": {
                            "at_end": disc["at_end"], "max_at_output": disc["max_at_output"],
                            "points_ever_at_output": int(disc["points_ever_at_output"].sum()),
                            "note": "cohesionless points at zero stress below the packing density (constitutive "
                                    "option disconnected, Dunatunga & Kamrin 2015), counted at the output times"},
                        "dissipated_energy": "not tracked (NaN in energy.csv); plastic work is not integrated",
                        **ck.summary()})
    if hasattr(sol, "scheme_summary"):
        res.summary.update(sol.scheme_summary())
    if stream is not None:
        stream.finish(res)
        res.write(out_dir)
    return res
