"""Implicit MPM solver (issue 18): Newmark-beta on the background grid, Newton-Raphson with the consistent tangent
of each constitutive law, sparse direct (banded LU of the row-equilibrated matrix, built in numba, for a
half-bandwidth <= 200 dofs: band_lu.py while threshold pivoting (tau 0.1) swaps no row, twisted when the band is at
least 4 half-bandwidths long (the two ends eliminated at once, one per thread, the same bits on one), LAPACK gbtrf
otherwise; scipy spsolve / SuperLU beyond) or iterative (gmres + ILU) solve, backtracking line search, step cutting. `[mpm] scheme =
"implicit"`, options `[mpm.implicit]` (coupler/mpm/scene.py).

ImplicitMPMSolver keeps MPMSolver's contract (advance, advance_to, step, set_point_loads, interface_state,
dropped_loads, energies, particles_frame, body_rows) and its particles, shape functions, boundary particles and
outputs: it is a subclass that replaces the step only (MPMSolver(scene) returns one when scheme = "implicit", so
the coupler's MPMPartition wraps either).

One step of dt (kernels.py for the kinematics):
  P2G at x^n: grid mass m_i, velocity v_i^n = p_i / m_i (APIC: affine momentum), acceleration a_i^n (mass-weighted
  point accelerations), external force (gravity, point fext, boundary-particle point loads: kernels.spread_loads
  with its dropped-load accounting).
  Unknown: nodal displacement increment u; Newmark: a^{n+1} = (u - dt v^n) / (beta dt^2) - (1 / (2 beta) - 1) a^n,
  v^{n+1} = v^n + dt ((1 - gamma) a^n + gamma a^{n+1}).
  Residual R(u) = m a^{n+1}(u) + f_int(u) - f_ext; tangent m / (beta dt^2) + d f_int / du (assembled in numba into
  a CSR pattern fixed for the step; only at the points a Newton step starts from: trial, line-search and
  active-set re-evaluations compute the residual alone). Converged when ||R|| (free dofs) <= max(rtol ||R_0||, atol) and the active
  sets below did not change; predictor a^{n+1} = a^n. Line search: the Newton step is halved (up to 4 times)
  while it does not reduce ||R||.
  Walls (the same kinds as the explicit solver): fixed = both components held (u = 0, v^n = a^n = 0 there); slip =
  unilateral normal constraint: held while the wall pushes, released when it would pull, held again when the node
  moves into the wall; friction = slip + Coulomb: the tangential dof sticks (held) while |R_t| <= mu N (N the
  normal wall force of the node) and slides with the friction force mu N against the stick force otherwise (back
  to stick when its velocity reverses); open = free.
  Active-set decisions use the step's residual tolerance as force tolerance (a wall force within it neither
  releases nor slides) and a penetration tolerance of 1e-9 h. The sets may change in the first AS_ITER Newton
  iterations; when they return to their state of two changes before (a stick <-> slip cycle of a node whose
  velocity reverses within the step) they freeze at once, the cycling dofs sliding. Once frozen, a stuck friction
  dof beyond mu N is still released and a released normal inside the wall still held again (only these changes:
  it terminates), so no converged step keeps a friction force above the Coulomb limit (before: up to 1.8 / 8.9
  mu N at h = 10 mm, cfl 5 / 10). What the frozen sets leave is counted per accepted step (summary frozen_*: a held
  normal the wall pulls, a sliding dof whose end velocity turned against its friction force; a released normal
  inside the wall is held again even then, so frozen_penetrates stays 0: before, the Bui cfl 20 run ended steps
  with a released base node 1.07 mm (0.11 h) inside the base).
  Modified Newton (reuse_ratio > 0): the LU factor is kept while an iteration reduces ||R|| at least by reuse_ratio,
  within a step and into the next one when the dof numbering (the active nodes), dt and the held set are unchanged
  (the step then starts without a tangent; stats kept_factor_steps); a cut step drops it.
  A step whose Newton iteration does not converge in max_iter iterations (or produces a non-finite stress) is
  restored and done as two steps of dt / 2, at most max_cuts times; then SimulationError (step, iterations,
  residual). So is a converged step that would change some point's volume by more than MAX_VOLUME_RATIO
  (det(I + grad u) outside [1/2, 2]; stats distortion_cuts, summary step_volume_ratio_min / max of the accepted
  steps): at too large a step a point of a one-point-thick sheet on the base can be crushed or inverted (Bui,
  h = 10 mm, cfl 20: det(I + grad u) down to -0.24; one such point's stress went from -42 Pa to -1.4 MPa) and
  then leave through the base or, its elastic energy released, be thrown out of the top (before: 1 or 2 of 8
  ensemble members stopped so; the accepted steps of the Bui runs stay within 0.90 .. 1.14).
  After convergence: points move by sum N u_i, velocity FLIP (usl / musl) or APIC (apic), stress and eps_p of the
  converged state, F and volume updated; boundary particles move with the renormalised grid
  displacement, and their velocity (the one the coupler gives the DEM wall for the next step) is that
  displacement / dt (interface_velocity = "step_mean", default) or the Newmark end-of-step velocity ("newmark").
  Why the step mean: with gamma > 1/2 the Newmark end-of-step velocity of the loaded surface carries an
  alternating (period 2 dt) part that the weak coupling feeds back through the DEM contact; in
  coupled_implicit_resting_load (dt = 37 DEM steps, gamma = 0.7) it grows into a two-step limit cycle of the
  interface load (8 <-> 633 N/m around the 320.5 N/m weight). With the step mean the load is steady (max - min
  < 0.01 N/m over the last 0.1 s).
Statistics: .stats (Newton iterations per step, cuts, time in assembly / solve (of it factor: band + LU) / update,
assemble calls with tangent / residual only / internal force reused); per Newton iteration: profile.py.
"""
from __future__ import annotations

import math
import time

import numba
import numpy as np
from scipy.linalg.lapack import dgbtrf, dgbtrs
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from coupler.errors import SimulationError
from coupler.mpm import kernels as K
from coupler.mpm.implicit import band_lu as BL
from coupler.mpm.implicit import kernels as IK
from coupler.mpm.shapes import WIDTH
from coupler.mpm.solver import MPMSolver


BANDED_MAX = 200  # direct solver: LAPACK banded LU up to this half-bandwidth (dofs), SuperLU (spsolve) beyond
TWISTED = True    # band_lu's twisted factorization when the band is long enough (False: one-sided, for A/B runs)
AS_ITER = 6      # Newton iterations in which the wall active sets may change
MAX_VOLUME_RATIO = 2.0   # a converged step that changes a point's volume by more than this factor (det(I + grad u)
                         # outside [1 / 2, 2]) is cut: an inverted or crushed point, not a solution (docstring)


class _NoConvergence(Exception):
    def __init__(self, iters, res, tol, why, quantity="Newton iteration"):
        self.iters, self.res, self.tol, self.why, self.quantity = iters, res, tol, why, quantity


class ImplicitMPMSolver(MPMSolver):
    def __init__(self, scene):
        super().__init__(scene)
        o = self.ms.implicit
        self.opts = o
        self.W = WIDTH[self.kind]
        n = len(self.m)
        self.acc = np.zeros((n, 2))
        self.A = np.zeros(self.G.shape[:2] + (2,))
        if scene.time.dt is None:
            cmax = self.ms.cfl * self.h / self.dt       # the explicit solver's P-wave speed (+ initial speed)
            self.dt = o.cfl * self.h / cmax
        self.s_new = np.zeros((n, 4))
        self.dep_new = np.zeros(n)
        self.L_new = np.zeros((n, 4))
        self.stats = {"steps": 0, "newton_iterations": [], "cuts": 0, "line_search_halvings": 0,
                      "assembly_s": 0.0, "solve_s": 0.0, "update_s": 0.0, "residual_ratios": [],
                      "reused_factor_iterations": 0, "kept_factor_steps": 0, "cut_log": [], "factor_s": 0.0,
                      "lu_swap_found": 0, "lu_lapack": 0,
                      "active_set_cycles": 0, "distortion_cuts": 0, "volume_ratio_range": (math.inf, -math.inf),
                      "frozen_set_dofs": {"wall_pulls": 0, "penetrates": 0, "slip_reversed": 0,
                                          "stuck_beyond_mu_n": 0},
                      "assemblies": {"tangent": 0, "tangent_at_trial": 0, "residual": 0, "fint_reused": 0}}
        self.record_ratios = False
        self._kept = None    # modified Newton (reuse_ratio > 0): the last step's LU factor, kept for the next step
        self._lu_skip, self._lu_backoff = 0, 1    # banded LU: factorizations left for gbtrf, the next such count
        self._pattern = None     # (node_dof, act, rowptr, cols, slot, diag, bw, code, nin, mu, band) of the last
                                 # active set (band: the banded solve's arrays or None)

    # ---- stepping -------------------------------------------------------------------------------------------
    def advance(self, nsteps: int, dt: float | None = None, profile: bool = False) -> None:
        dt = self.dt if dt is None else float(dt)
        for _ in range(int(nsteps)):
            self._step(dt, 0)
            self.nstep += 1
            self.t += dt

    # checkpoints (MPMSolver.save_checkpoint / load_checkpoint, and run checkpoints): the solver pickled whole.
    # Modified Newton (reuse_ratio > 0) is refused: the factor it keeps across steps can be a SuperLU object, which
    # pickle cannot hold.
    def fingerprint(self) -> str:
        """MPMSolver.fingerprint and the implicit options (Newmark, Newton, solver: a run with others is another)."""
        import hashlib
        return hashlib.sha256((super().fingerprint() + repr(self.opts)).encode()).hexdigest()

    def checkpoint_refusal(self) -> str | None:
        """Why this solver cannot be checkpointed (None: it can); also for run checkpoints (coupler/checkpoint.py,
        whose pickle cannot hold the direct solver's SuperLU factor either)."""
        if self.opts.reuse_ratio > 0.0:
            return ("checkpoints of the implicit MPM: not with modified Newton (mpm.implicit.reuse_ratio = "
                    f"{self.opts.reuse_ratio:g}: its kept LU factor is not saved); use reuse_ratio = 0")
        return None

    # What a cut step undoes. _try writes the point and boundary-particle state (x, v, C, F, s, eps_p, vol, acc, xb,
    # vb) only after its Newton loop converged (kernels.commit, move_boundary; the trial state lives in s_new, dep_new,
    # L_new), and _NoConvergence is raised only before that; the one thing written earlier is the dropped-load
    # record of spread_loads. (Saving all of the state took ~10-20 us a step, ~2 % of a step at h = 10 mm.)
    def _save(self):
        return self.drop.copy()

    def _restore(self, saved):
        self.drop[...] = saved

    def _step(self, dt, depth, t_in=0.0):
        """One step of dt (t_in: its start within the step of advance, for the messages: a cut step's halves)."""
        saved = self._save()
        try:
            self._try(dt)
            return
        except _NoConvergence as e:
            self._restore(saved)     # (_try dropped the kept factor before its Newton loop)
            if depth >= self.opts.max_cuts:
                raise SimulationError(self.nstep, self.t + t_in, ",".join(self.body_names), e.quantity,
                                      f"{e.why}: {e.iters} iterations, residual {e.res:.4g} N/m (tolerance "
                                      f"{e.tol:.3g}) after cutting the step {depth} times to dt = {dt:.4g} s "
                                      f"(mpm.implicit.max_iter = {self.opts.max_iter}, max_cuts = "
                                      f"{self.opts.max_cuts})") from None
            self.stats["cuts"] += 1
            if len(self.stats["cut_log"]) < 1000:
                self.stats["cut_log"].append({"step": self.nstep, "t": self.t + t_in, "dt": dt, "why": e.why,
                                              "iterations": e.iters, "residual_over_tol": e.res / e.tol
                                              if e.tol > 0 else float("nan"), **getattr(e, "diag", {})})
            self._step(0.5 * dt, depth + 1, t_in)
            self._step(0.5 * dt, depth + 1, t_in + 0.5 * dt)

    def _constraints(self, act_nodes, NY):
        """Per dof: code (0 free, 1 fixed, 2 wall normal, 3 friction tangential), inward normal sign, friction."""
        ndof = 2 * len(act_nodes)
        code = np.zeros(ndof, np.int64)
        nin = np.zeros(ndof)
        mu = np.zeros(ndof)
        i, j = act_nodes // NY, act_nodes % NY
        P = K.PAD
        sides = ((i <= P, 0, 1.0), (i >= P + self.nx, 0, -1.0), (j <= P, 1, 1.0), (j >= P + self.ny, 1, -1.0))

        def put(dofs, c, sign=0.0, m=0.0):
            cur = code[dofs]
            take = (cur == 0) | (cur > c)
            code[dofs[take]] = c
            if sign:
                nin[dofs[take]] = sign
            mu[dofs[take]] = m

        for side, (on, d, sign) in enumerate(sides):
            kind = int(self.bc[side])
            if kind == 3 or not on.any():
                continue
            nodes = np.flatnonzero(on)
            if kind == 0:
                put(2 * nodes, 1)
                put(2 * nodes + 1, 1)
            else:
                put(2 * nodes + d, 2, sign)
                if kind == 2:
                    put(2 * nodes + (1 - d), 3, 0.0, float(self.mu[side]))
        return code, nin, mu

    def _try(self, dt):
        o = self.opts
        beta, gamma = o.beta, o.gamma
        b = self.box
        p = K.check_inside(self.x, b[0], b[1], b[2], b[3])
        if p >= 0:
            self._raise(K.STATUS_POINT_OUT, p)
        nb = len(self.xb)
        if nb:
            p = K.check_inside(self.xb, b[0], b[1], b[2], b[3])
            if p >= 0:
                self._raise(K.STATUS_BOUNDARY_OUT, p)
        ta = time.perf_counter()
        S, P, B, Gr = self.state()
        W = self.W
        IK.p2g(S, P, self.acc, W, self.G, self.A)
        frac, first = (K.spread_loads(S, B, Gr, dt) if nb else (0.0, -1))
        NX, NY = self.G.shape[0], self.G.shape[1]
        # the dof numbering, sparsity pattern, band width and wall constraints follow from the active node set
        # alone: kept while it is unchanged (most steps: a node gains or loses mass only when a point crosses a cell)
        act = IK.active_nodes(self.G)
        pat = self._pattern
        if pat is None or not np.array_equal(pat[1], act):
            node_dof, rowptr, cols, slot, diag = IK.number_dofs(NX, NY, act, W)
            bw = IK.half_bandwidth(rowptr, cols)
            # banded direct solve: column j of A in row j of abT (IK.to_band), compact for band_lu (A[i, j] at
            # abT[j, bw + i - j]), or band_lu's two twisted halves (top, bottom) when the band is long enough (m > 0:
            # the first separator dof); the row scales; LAPACK's fallback gets gbtrf's layout, abG[0], when first
            # needed
            nd = 2 * len(act)
            m_tw = BL.twisted_split(nd, bw) if TWISTED else 0
            band = (((BL.twisted_bands(nd, bw, m_tw) if m_tw else BL.band(nd, bw, bw)), np.ones(nd), [None], m_tw)
                    if o.linear_solver == "direct" and bw <= BANDED_MAX else None)
            pat = self._pattern = (node_dof, act, rowptr, cols, slot, diag, bw, *self._constraints(act, NY), band)
        node_dof, act, rowptr, cols, slot, diag, bw, code, nin, mu, band = pat
        serial = numba.get_num_threads() == 1     # assemble's one-pass form (the same bits)
        grp = IK.groups(S, P, NY, serial)     # points by support stencil (fixed within the step), assembly work arrays
        pat_k = IK.Pattern(node_dof, slot, rowptr, act)
        trial = IK.Trial(self.s_new, self.dep_new, self.L_new)
        ndof = 2 * len(act)
        mass, vn0, an0, fext = IK.grid_fields(self.G, self.A, act)
        nrm_dofs, fr_dofs = code == 2, code == 3      # unilateral wall normals, Coulomb friction dofs
        has_nrm, has_fr = bool(nrm_dofs.any()), bool(fr_dofs.any())
        no_dofs = np.zeros(len(code), np.bool_)      # (read only)
        fsign = np.zeros(ndof)                # friction direction of sliding dofs
        held, vn, an, u = IK.predictor(code, vn0, an0, dt, 0.5 * dt * dt)    # held: the active constraints
        c_m = 1.0 / (beta * dt * dt)
        k_a = 0.5 / beta - 1.0
        nnz = rowptr[-1]
        banded = band is not None
        if banded:
            abT, rscale, abG, m_tw = band
        madd = mass * c_m
        data = np.zeros(nnz)
        R = np.zeros(ndof)
        fint = np.zeros(ndof)     # internal force of the last evaluated u
        last_u = np.full(ndof, np.nan)     # that u (its trial state is in s_new, dep_new, L_new)
        bad = np.zeros(1, np.int64)
        self.stats["update_s"] += time.perf_counter() - ta

        def evaluate(uu, want_K, same_u=False):
            """R(uu) (and with want_K the tangent into data). same_u: uu is the point of the last evaluation and
            only vn, an (a wall release or a slip) changed: the internal force fint (and the trial state) are
            those of the last evaluation, only the inertia and friction terms are recomputed."""
            t0 = time.perf_counter()
            if not same_u:
                # the tangent at the point of the last evaluation (a Newton step from an accepted trial point) from its
                # stored trial state: no second stress update / force scatter (fint is that point's already)
                mode = (IK.TANGENT if want_K and IK.same(uu, last_u) else IK.BOTH if want_K else IK.RESIDUAL)
                if want_K:
                    data[:] = 0.0
                if mode != IK.TANGENT:
                    fint[:] = 0.0
                    last_u[:] = uu
                IK.assemble(S, P, W, pat_k, grp, uu, dt, mode, data, fint, trial, bad, serial)
            self.stats["assemblies"]["fint_reused" if same_u else "tangent_at_trial" if mode == IK.TANGENT
                                     else "tangent" if want_K else "residual"] += 1
            IK.inertia_residual(uu, vn, an, mass, fext, fint, c_m, dt, k_a, R)
            self.stats["assembly_s"] += time.perf_counter() - t0
            if bad[0] >= 0:
                raise _NoConvergence(it, float("nan"), 0.0, f"non-finite stress at material point {bad[0]}")
            # friction of sliding dofs (normal force from the reaction of the node's normal dof)
            if has_fr:
                IK.friction_residual(R, fr_dofs, held, nin, mu, fsign)
            return R.copy()

        def free_norm(r):
            return IK.free_norm(r, held)

        def normal_tests(uu, r):
            """Unilateral wall normals: (held ones the wall pulls, released ones moved into the wall, has any of each)."""
            if not has_nrm:
                return no_dofs, no_dofs, False, False
            return IK.normal_tests(nrm_dofs, held, r, uu, nin, tol_f[0], -1e-9 * self.h)

        def friction_tests(uu, r):
            """Coulomb dofs: (stuck ones beyond mu N, N the reaction of the node's held normal; sliding ones whose
            end velocity turned against their friction force, has any of each)."""
            if not has_fr:
                return no_dofs, no_dofs, False, False
            return IK.friction_tests(fr_dofs, held, code, r, uu, vn, an, nin, mu, fsign, c_m, dt, k_a, gamma, tol_f[0])

        def update_active(uu, r):
            """Update the wall active sets; returns (changed, moved): moved = some dof of uu was set to 0 (the
            internal force and tangent then change; otherwise only the inertia and friction terms of R do)."""
            changed = moved = False
            # after AS_ITER iterations, or once the sets returned to those of two changes before (a stick <-> slip
            # cycle), only a stuck friction dof beyond mu N may still be released and a released normal that moved
            # into the wall still be held again (monotone: it terminates, every converged stuck dof keeps
            # |R_t| <= mu N and no converged released node is inside a wall)
            late = it >= AS_ITER or frozen[0]
            # normals: release where the wall pulls, hold again where the node moved into the wall
            rel, back, any_rel, any_back = normal_tests(uu, r)
            if late:
                rel, any_rel = no_dofs, False
            if any_rel or any_back:
                changed = True
                moved = any_back
                held[rel] = False
                held[back] = True
                uu[back] = 0.0
                vn[back] = 0.0
                an[back] = 0.0
                vn[rel], an[rel] = vn0[rel], an0[rel]
            slip, stick, any_slip, any_stick = friction_tests(uu, r)
            if late:
                stick, any_stick = no_dofs, False
            if any_slip or any_stick:
                changed = True
                moved = moved or any_stick
                held[slip] = False
                fsign[slip] = np.sign(r[slip])
                vn[slip], an[slip] = vn0[slip], an0[slip]
                held[stick] = True
                uu[stick] = 0.0
                vn[stick] = 0.0
                an[stick] = 0.0
            if changed and not late:
                if len(as_hist) >= 2 and np.array_equal(held, as_hist[-2]):
                    frozen[0] = True          # a cycle: the dofs it just stuck slide instead
                    held[stick] = False           # (the dofs just stuck: before, not after the test)
                    fsign[stick] = np.sign(r[stick])
                    vn[stick], an[stick] = vn0[stick], an0[stick]
                    self.stats["active_set_cycles"] += 1
                as_hist.append(held.copy())
            return changed, moved

        def factor(r):
            """LU factor of the tangent in data (+ mass term, sliding-friction rows, held rows = identity)."""
            # sliding friction dofs: R_t - mu N s with N = R_n . n_in of the node's held normal dof, so row t of the
            # tangent gets - mu s n_in (row n) (the two dof rows of a node share their CSR columns); without this
            # term Newton converged linearly (ratio ~0.2-0.5 per iteration) whenever the base slid
            slide_n, slide_c = IK.slide_rows(fr_dofs, held, r, nin, mu, fsign)
            if banded:     # LAPACK banded LU (gbtrf): the grid numbering keeps the band narrow
                # rows equilibrated by powers of two (exact): partial pivoting by relative size (Bui, row swaps per
                # LU: h = 10 mm 29 instead of 438 of 528 rows, h = 5 mm 44 instead of 1,199 of 1,848), less fill;
                # the solution equals the unscaled one up to the pivot order (round-off).
                # band_lu first: threshold partial pivoting (BL.PIVOT_THRESHOLD) as long as it swaps no row (the
                # mass-dominated matrix has not needed one on the Bui scenes since tau = 0.1; stats lu_swap_found
                # when it does); then LAPACK's gbtrf on the matrix built again, and for the next 1, 2, 4, .. 64
                # factorizations while they keep needing a swap (no failed attempt each time; stats lu_lapack)
                if self._lu_skip > 0:
                    self._lu_skip -= 1
                else:
                    if m_tw:    # both ends of the band at once, one per thread (band_lu: the twisted factorization)
                        k = IK.to_band_factor_twisted(data, rowptr, cols, diag, madd, held, slide_n, slide_c, bw,
                                                      abT[0], abT[1], m_tw, rscale, BL.PIVOT_THRESHOLD)
                    else:
                        IK.to_band(data, rowptr, cols, diag, madd, held, slide_n, slide_c, bw, abT, bw, rscale, True)
                        k = BL.factor(abT, ndof, bw, bw, bw, BL.PIVOT_THRESHOLD)
                    if k == -1:
                        self._lu_backoff = 1
                        return abT, None, rscale
                    if k <= -2:
                        raise _NoConvergence(it, res, tol, f"singular tangent (zero pivot at dof {-2 - k})")
                    self.stats["lu_swap_found"] += 1
                    self._lu_skip = self._lu_backoff
                    self._lu_backoff = min(2 * self._lu_backoff, 64)
                if abG[0] is None:
                    abG[0] = np.empty((ndof + 1, 3 * bw + 1))
                IK.to_band(data, rowptr, cols, diag, madd, held, slide_n, slide_c, bw, abG[0], 2 * bw, rscale, True)
                self.stats["lu_lapack"] += 1
                lu, piv, info = dgbtrf(abG[0][:ndof].T, bw, bw, overwrite_ab=True)
                if info != 0:
                    raise _NoConvergence(it, res, tol, f"singular tangent (LAPACK gbtrf info {info})")
                return lu, piv, rscale
            data[diag] += madd
            for t in np.flatnonzero(slide_n >= 0):
                n = slide_n[t]
                data[rowptr[t]:rowptr[t + 1]] -= slide_c[t] * data[rowptr[n]:rowptr[n + 1]]
            hmask = held[np.repeat(np.arange(ndof), np.diff(rowptr))]     # per CSR entry: its row is held
            data[hmask] = 0.0
            data[diag[held]] = 1.0
            A = sp.csr_matrix((data, cols, rowptr), shape=(ndof, ndof))
            if o.linear_solver == "direct":
                try:
                    return spla.splu(A.tocsc())
                except RuntimeError as e:
                    raise _NoConvergence(it, res, tol, f"singular tangent ({e})") from None
            return A

        def fac_solve(f, rhs):
            if banded:      # the rhs scaled as the rows
                if f[1] is None:
                    if m_tw:
                        return BL.solve_twisted(f[0][0], f[0][1], ndof, m_tw, bw, bw, f[2] * rhs)
                    return BL.solve(f[0], ndof, bw, bw, bw, f[2] * rhs)
                du, info = dgbtrs(f[0], bw, bw, f[2] * rhs, f[1])
                return du
            if o.linear_solver == "direct":
                return f.solve(rhs)
            try:
                pre = spla.spilu(f.tocsc(), drop_tol=1e-5, fill_factor=20).solve
            except RuntimeError:      # an exactly singular incomplete factor: Jacobi instead
                dg = f.diagonal()
                pre = (lambda z, dg=np.where(dg != 0.0, dg, 1.0): z / dg)
            du, info = spla.gmres(f, rhs, M=spla.LinearOperator(f.shape, pre), rtol=1e-10, atol=0.0,
                                  restart=100, maxiter=50)
            if info != 0:
                raise _NoConvergence(it, res, tol, f"gmres did not converge (info {info})")
            return du

        # modified Newton across steps (reuse_ratio > 0): the last step's factor serves this step while the dof
        # numbering (the active nodes), dt and the held set are the same, and its last iteration met reuse_ratio
        kept = self._kept
        if not (o.reuse_ratio > 0.0 and kept is not None and kept["dt"] == dt and np.array_equal(kept["act"], act)):
            kept = None
        self._kept = None
        it = 0
        frozen = [False]     # the active sets cycled (update_active)
        as_hist = [held.copy()]     # held at the start and after each change of the active sets
        tol_f = [o.atol]     # force tolerance of the active-set decisions: the residual tolerance of the step
        # the tangent is assembled only where a Newton step is taken from (have_K: data holds the tangent of u):
        # trial points, line-search points and re-evaluations after an active-set change get the residual alone
        # (numba assemble with want_K = False, ~1/8 of the cost), so the converged point of a step never builds one
        have_K = kept is None     # with a kept factor the tangent is assembled only if it is not reused
        r = evaluate(u, have_K)
        tol_f[0] = max(o.rtol * free_norm(r), o.atol)
        changed, moved = update_active(u, r)
        if changed:     # u unmoved: the tangent in data is still that of u, the residual alone is re-evaluated
            r = evaluate(u, False, same_u=not moved)
            have_K = have_K and not moved
        res = free_norm(r)
        ref = res
        tol = max(o.rtol * ref, o.atol)
        hist = [res]
        fac = None          # the LU factor in use (banded: (lu, ipiv or None = band_lu's, rscale); direct: SuperLU;
                            # iterative: None)
        fac_held = None     # the held set it was built with (a change of the active sets forces a new one)
        last_ratio = 1.0    # residual ratio of the last iteration (modified Newton: reuse while <= reuse_ratio)
        if kept is not None:
            fac, fac_held, last_ratio = kept["fac"], kept["held"], kept["ratio"]
        n_changed = 0      # iterations whose end changed the wall active sets (diagnostics of a cut step)
        flips = []         # points whose plastic state (eps_p increment > 0) changed, per accepted iterate
        pl_prev = self.dep_new > 0.0
        try:
            while True:
                if res <= tol and not changed:
                    break
                if it >= o.max_iter:
                    raise _NoConvergence(it, res, tol, "Newton did not converge")
                it += 1
                reuse = (fac is not None and last_ratio <= o.reuse_ratio and np.array_equal(held, fac_held))
                t0 = time.perf_counter()
                if not reuse:
                    if not have_K:
                        r = evaluate(u, True)   # the same residual (assemble computes R alike in both modes) + tangent
                        t0 = time.perf_counter()
                    fac = factor(r)
                    fac_held = held.copy()
                    self.stats["factor_s"] += time.perf_counter() - t0
                rhs = -r
                rhs[held] = 0.0
                du = fac_solve(fac, rhs)
                self.stats["solve_s"] += time.perf_counter() - t0
                if reuse:
                    self.stats["reused_factor_iterations"] += 1
                    if it == 1 and kept is not None:
                        self.stats["kept_factor_steps"] += 1     # started on the last step's factor
                if not IK.all_finite(du):
                    raise _NoConvergence(it, res, tol, "singular tangent")
                alpha = 1.0
                r_new = evaluate(u + du, False)
                res_new = free_norm(r_new)
                if o.line_search:
                    halv = 0
                    while res_new > res and halv < 4:
                        alpha *= 0.5
                        halv += 1
                        r_new = evaluate(u + alpha * du, False)
                        res_new = free_norm(r_new)
                    if halv:
                        self.stats["line_search_halvings"] += halv
                u = u + alpha * du
                r = r_new
                have_K = False
                flips.append(IK.plastic_flips(self.dep_new, pl_prev))
                changed, moved = update_active(u, r)
                if changed:
                    n_changed += 1
                    r = evaluate(u, False, same_u=not moved)
                res_prev, res = res, free_norm(r)
                last_ratio = 1.0 if changed else res / res_prev
                hist.append(res)
        except _NoConvergence as e:    # what the failed step did: residual history, active-set changes, plastic points
            e.diag = {"hist": [float(x) for x in hist], "active_set_changes": n_changed, "plastic_flips": flips,
                      "plastic_points": int(np.count_nonzero(self.dep_new > 0.0))}
            raise
        if self.record_ratios:
            self.stats["residual_ratios"].append(hist)
        t0 = time.perf_counter()
        if not np.isfinite(res):
            raise _NoConvergence(it, res, tol, "non-finite residual")
        jlo, plo, jhi, phi = IK.volume_ratio_range(self.L_new)
        if jlo < 1.0 / MAX_VOLUME_RATIO or jhi > MAX_VOLUME_RATIO:
            p, j = (plo, jlo) if jlo < 1.0 / MAX_VOLUME_RATIO else (phi, jhi)
            self.stats["distortion_cuts"] += 1
            raise _NoConvergence(it, res, tol, f"excessive distortion: material point {int(self.pid[p])} would change "
                                 f"its volume by the factor det(I + grad u) = {j:.4g} in the step (allowed "
                                 f"[{1.0 / MAX_VOLUME_RATIO:g}, {MAX_VOLUME_RATIO:g}])", "point volume change")
        self.stats["volume_ratio_range"] = (min(self.stats["volume_ratio_range"][0], jlo),
                                            max(self.stats["volume_ratio_range"][1], jhi))
        # what the frozen active sets left, per accepted step (summary frozen_*): a held wall normal the wall pulls,
        # a released one inside the wall, a sliding dof whose end velocity turned against its friction force, and
        # a stuck friction dof beyond mu N (the second and the last none by construction: update_active holds the
        # one again and releases the other)
        fz = self.stats["frozen_set_dofs"]
        for k, mask in zip(("wall_pulls", "penetrates", "stuck_beyond_mu_n", "slip_reversed"),
                           normal_tests(u, r)[:2] + friction_tests(u, r)[:2]):
            fz[k] += int(np.count_nonzero(mask))
        a1, v1 = IK.newmark_end(u, vn, an, held, c_m, dt, k_a, gamma)
        U, V0, V1, A1 = IK.dof_grids(NX, NY, act, u, vn, v1, a1)
        out = IK.commit(S, P, W, node_dof, U, V0, V1, A1, self.s_new, self.dep_new, self.L_new, self.mode != 2,
                        self.acc)
        if nb:      # boundary particles: velocity = the step's mean (u / dt) or the Newmark end-of-step one
            IK.move_boundary(S, B, self.G, W, U, U / dt if self.opts.interface_velocity == "step_mean" else V1)
        self.stats["update_s"] += time.perf_counter() - t0
        self.stats["newton_iterations"].append(it)
        self.stats["steps"] += 1
        if o.reuse_ratio > 0.0 and fac is not None and o.linear_solver == "direct":
            self._kept = {"dt": dt, "act": act, "fac": fac, "held": fac_held, "ratio": last_ratio}
        if out >= 0:
            self._raise(K.STATUS_POINT_MOVED_OUT, out)
        if nb:
            p = K.check_inside(self.xb, b[0], b[1], b[2], b[3])
            if p >= 0:
                self._raise(K.STATUS_BOUNDARY_MOVED_OUT, p)
        if frac > self.max_dropped_load_fraction:
            self._raise(K.STATUS_DROPPED, first)

    # ---- diagnostics ----------------------------------------------------------------------------------------
    def scheme_summary(self) -> dict:
        its = self.stats["newton_iterations"]
        return {"mpm_scheme": "implicit", "newmark": {"beta": self.opts.beta, "gamma": self.opts.gamma},
                "newton_iterations_mean": float(np.mean(its)) if its else 0.0,
                "newton_iterations_max": int(max(its)) if its else 0, "step_cuts": self.stats["cuts"],
                "step_cuts_distortion": self.stats["distortion_cuts"],
                "step_volume_ratio_min": self.stats["volume_ratio_range"][0],
                "step_volume_ratio_max": self.stats["volume_ratio_range"][1],
                "line_search_halvings": self.stats["line_search_halvings"],
                "active_set_cycles": self.stats["active_set_cycles"],
                **{f"frozen_{k}": v for k, v in self.stats["frozen_set_dofs"].items()},
                "time_assembly_s": self.stats["assembly_s"], "time_solve_s": self.stats["solve_s"],
                "time_update_s": self.stats["update_s"], "linear_solver": self.opts.linear_solver,
                "interface_velocity": self.opts.interface_velocity}
