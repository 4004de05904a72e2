"""Compiled MPM step (numba), written once: `advance` runs n steps in one compiled loop, `step` is one step, each
phase of it is one function below, and the per-phase profile (`advance(..., prof)`) is timed inside the same loop.

Solver state is bundled in four named tuples (fields documented at each):
  Points    material points    x, v, C (APIC affine matrix B D^-1), F, m, vol, vol0, s, eps_p, lp, mid, fext
  Boundary  boundary particles x, v, f (point loads), wall, drop (dropped-load counters)
  Grid      grid and scratch   G (m, p, f per node), V (v^n, v^{n+1} per node), start / order (P2G strips), scratch,
                               cost (cycles per gather chunk, balances the gather's work groups)
  Setup     constants          shape, transfer mode, grid origin / cell / size, gravity, damping, box, BCs, prm, ...
so that a phase reads like its physics: `scatter(S, P, Gr)`, `grid_solve(S, Gr, dt)`, `g2p(S, P, Gr, dt, 0)`.

One step (`step`):  check positions + strip sort -> P2G (`scatter`) -> point loads (`spread_loads`) -> grid update
+ BCs (`grid_solve`) -> G2P + stress (`g2p`) [MUSL: g2p velocity -> `remap` -> g2p position, stress] ->
boundary particles (`move_boundary`) -> check boundary particles. Every point is checked inside the grid before each
transfer that reads its position (the gather checks the new material-point positions as it writes them).
Failures come back as a status (code, index) that the solver turns into a SimulationError naming step, body, point
and quantity (solver.MPMSolver._raise); the codes are the STATUS_* constants.

Shape functions: the shape id selects one compiled copy of each transfer (`_scatter_<shape>`, `_g2p_<shape>`,
`_remap_<shape>`, the branches of spread_loads / move_boundary), with the support width `shapes.WIDTH[id]` a
compile-time constant, so the node loops have the registered width; an id that is not registered returns
STATUS_SHAPE from `advance` (and the Python entry points raise ValueError, shapes.check_shape).

Determinism: P2G is coloured in x-strips of STRIP = 2 cells, even strips first, then odd ones; two strips of one
colour share no node (a point's support spans at most MAX_WIDTH = 3 nodes), and inside a strip points are taken in
stored order (stable counting sort), so every node sum has one fixed order whatever the thread count. The gathers
are per point. Results are bitwise identical for any number of threads (tests/mpm/test_mpm_core.py).

Threads: every phase but the BCs on the wall nodes and the boundary particles runs in parallel regions (6 per step:
sort count + place, P2G colour 0 + colour 1, grid update, gather; their scratch arrays are allocated in serial
helpers, since an np.zeros / np.full in a parallel function is one more parallel region). numba splits a prange into
equal index ranges, one per thread (the OpenMP layer's static schedule), so the work items are made equal: the sort
takes NGROUP blocks of equal point counts; P2G takes NGROUP groups of strips of about equal measured cost
(colour_groups: each strip's cycles in the last P2G, Grid.scost[0]; point counts before the first measurement; the
strips of colour 0 zero the grid columns they own), the grid update takes NGROUP groups of node-column blocks of
about equal measured cost (block_groups, Grid.scost[1]; only the columns a point reaches: P2G's colour-0 strips
zero V with G), the gathers take
the points in strip order (Gr.order) in chunks of CHUNK points, dealt in NGROUP groups of consecutive chunks of
about equal cost (chunk_groups: each chunk's cycles in the last step's gather; a Mohr-Coulomb point on the
yield surface costs more than an elastic one, and the flowing toe, at the end of the strip order, held 58 % of the
gather's work in the 12,800-point bench, 2026-12-02: one thread waited 28 % of the gather for the other), so each
thread gathers mostly the points it scattered and their data stay in its own core's cache (a gather in index order moved them between the cores every step; with the
grid update's columns dealt round-robin as well, the 12,800-point bench ran 1.1x faster on two threads than on one,
1.3x with both aligned, on the 2-core machine of 2026-12-02). None of this changes the order of any sum (the work groups only say which thread computes a point). The solver
also stores the points in strip order every REORDER_EVERY steps (solver.MPMSolver._reorder), so each thread's share
is one contiguous block of memory (1.4x -> 1.6x on two threads); that sets the order of P2G's sums (the stored
order), at fixed step numbers, so it is the same for any thread count.

`strip_sort`, `p2g`, `gather` (= sort_strips, scatter, g2p with long positional signatures) are kept as thin Python
entry points for the unit tests of single transfers; the solver uses only the tuple form.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from llvmlite import ir
from numba import njit, prange
from numba.core import cgutils, types
from numba.extending import intrinsic

from coupler.loops import items, unsigned
from coupler.mpm.constitutive import stress_update
from coupler.mpm.constitutive.base import N_PRM
from coupler.mpm.constitutive.disconnected import disconnected
from coupler.mpm.shapes import BSPLINE2, GIMP, LINEAR, MAX_WIDTH, WIDTH, check_shape, first_node, weights3

PAD = 2
STRIP = 2      # cells per P2G strip; needs STRIP >= MAX_WIDTH - 1 so that strips s and s + 2 share no node
CHUNK = 64     # points per chunk of the gathers (timed; chunk_groups deals them in NGROUP groups of equal cost)
NGROUP = 8     # work groups of P2G colours / grid node loops; prange splits them into equal ranges per thread,
               # so 1, 2, 4, 8 threads get equal shares (a constant, not numba.get_num_threads(): a function
               # calling that cannot be cached)
assert STRIP >= MAX_WIDTH - 1

Points = namedtuple("Points", ["x", "v", "C", "F", "m", "vol", "vol0", "s", "eps_p", "lp", "mid", "fext"])
Points.__doc__ = """Material points (n each): x, v (n,2); C (n,2,2) APIC affine matrix B D^-1 (Jiang et al. 2015;
_gather_range; USL / MUSL: the velocity gradient, not read); F (n,4) deformation gradient [xx, xy, yx, yy]; m, vol,
vol0 (n,); s (n,4) stress [xx, yy, xy, zz]; eps_p (n,); lp (n,) GIMP half-width [cells]; mid (n,) material row of
Setup.prm; fext (n,2) external force."""
Boundary = namedtuple("Boundary", ["x", "v", "f", "wall", "drop", "mc"])
Boundary.__doc__ = """Boundary particles (nb each): x, v, f (nb,2) point loads [N per unit depth]; wall (nb,) side they
are attached to (-1 none); drop (8,) counters: dropped loads [count, impulse dropped, impulse applied, max fraction]
(spread_loads), stranded particles [particle-steps, most in one step] (move_boundary), rerouted loads [count, impulse
rerouted] (spread_loads); mc (nb,) sliver mass [kg per unit depth]: a support node holding less mass takes a share
scaled by m_i / mc (_sliver_weight; 0 = off)."""
Grid = namedtuple("Grid", ["G", "V", "start", "order", "scratch", "cost", "scost"])
Grid.__doc__ = """G (NX,NY,5) node mass, momentum, force; V (NX,NY,4) node velocity v^n (0:2), v^{n+1} (2:4);
start (nstrips+1,), order (n,) the P2G strips; scratch (n,) int64; cost (2, n_chunks(n)) int64 cycles of each
gather chunk (row 0: full gather, stage 0 / 2; row 1: MUSL velocity, stage 1), smoothed over steps (g2p; zeros
at the start); scost (2, nstrips) int64 cycles of each P2G strip (row 0, colour_groups) and of each grid-update
column block k (row 1, at index 2 k, block_groups), smoothed over steps (zeros at the start). Only the split of the
work between the threads reads cost and scost, never a result."""
Setup = namedtuple("Setup", ["kind", "mode", "org0", "org1", "h", "nx", "ny", "g0", "g1", "damping", "box", "bc",
                             "mu", "prm", "max_drop"])
Setup.__doc__ = """Constants of a run: kind (shape id), mode (0 usl, 1 musl, 2 apic), grid origin org0, org1, cell h,
cells nx, ny, gravity g0, g1, damping (local, Cundall), box (4,) [lo0, lo1, hi0, hi1] of the inside-the-grid check,
bc (4,) / mu (4,) side BC kinds and frictions (apply_bc), prm (nmat, N_PRM) packed material parameters, max_drop
the largest dropped fraction of the point load allowed in a step."""

STATUS_OK, STATUS_POINT_OUT, STATUS_BOUNDARY_OUT, STATUS_STRESS, STATUS_POINT_MOVED_OUT, STATUS_BOUNDARY_MOVED_OUT, \
    STATUS_DROPPED, STATUS_SHAPE = range(8)
# phases timed by advance(..., prof=True): index into the timer array ("check": the boundary particles before the
# step; the material points are checked inside "strip_sort")
PHASES = ("check", "strip_sort", "p2g", "point_loads", "grid_update", "gather(g2p+stress)", "musl_remap",
          "boundary_particles")


@intrinsic
def _cycles(typingctx):
    """CPU cycle counter (llvm.readcyclecounter), for the compiled per-phase timer (0 where not supported)."""
    def codegen(context, builder, signature, args):
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(64), []),
                                            "llvm.readcyclecounter")
        return builder.call(fn, [])
    return types.int64(), codegen


@njit(cache=True)
def cycles_now():
    """The cycle counter read from Python (to convert the phase timer to seconds)."""
    return _cycles()


@njit(cache=True)
def check_inside(x, lo0, lo1, hi0, hi1):
    """Index of the first point outside [lo, hi] or a NaN position, -1 if none."""
    for p in range(x.shape[0]):
        a, b = x[p, 0], x[p, 1]
        if not (a >= lo0 and a <= hi0 and b >= lo1 and b <= hi1):
            return p
    return -1


def n_strips(NX: int) -> int:
    return (NX + STRIP - 1) // STRIP


def n_chunks(n: int) -> int:
    """Chunks of CHUNK points of the gathers (columns of Grid.cost)."""
    return (n + CHUNK - 1) // CHUNK


def new_cost(n: int) -> np.ndarray:
    """Grid.cost of n points: no measurement yet (the first gather splits its chunks evenly)."""
    return np.zeros((2, n_chunks(n)), np.int64)


def new_strip_cost(NX: int) -> np.ndarray:
    """Grid.scost of a grid of NX node columns: no measurement yet (the first P2G and grid update split by points)."""
    return np.zeros((2, n_strips(NX)), np.int64)


# ---- strip sort ---------------------------------------------------------------------------------------------
@njit(cache=True)
def _sort_scratch(nb, ns):
    """sort_strips' histogram (nb, ns) and failure slots (nb,), allocated here, outside the parallel function (an
    np.zeros / np.full there is a parallel region of its own)."""
    return np.zeros((nb, ns), np.int64), np.full(nb, -1, np.int64)


@njit(cache=True, parallel=True)
def sort_strips(S, P, Gr, check):
    """Stable counting sort of the points by the x-strip of their first support node, parallel over NGROUP blocks of
    consecutive points (equal counts, so each thread gets an equal share): a strip histogram per block, one prefix
    sum over (strip, block), then each block places its points (the result does not depend on the blocks). On return the points of strip s are order[start[s]:start[s + 1]], in index order (the same array for
    any thread count). check: each point is first tested inside S.box (a NaN position fails); returns the index of
    the first point outside, or -1 (start / order are valid only then). Without check the positions must be
    inside the grid."""
    # every array written is reached through a local name (see _gather_range)
    start, cursor, order, x = Gr.start, Gr.scratch, Gr.order, P.x
    ns = start.shape[0] - 1
    ih = 1.0 / S.h
    kind, org0 = S.kind, S.org0
    lo0, lo1, hi0, hi1 = S.box[0], S.box[1], S.box[2], S.box[3]
    n = x.shape[0]
    nb = NGROUP
    bs = (n + nb - 1) // nb         # points per block
    hist, bad = _sort_scratch(nb, ns)
    for k in prange(nb):
        for p in range(k * bs, min(n, (k + 1) * bs)):
            a, b = x[p, 0], x[p, 1]
            if check and not (a >= lo0 and a <= hi0 and b >= lo1 and b <= hi1):
                bad[k] = p
                break
            s = first_node(kind, (a - org0) * ih + PAD) // STRIP
            cursor[p] = s           # cursor is (n,) scratch: the strip of point p
            hist[k, s] += 1
    for k in range(nb):
        if bad[k] >= 0:
            return bad[k]
    tot = 0                         # hist[k, s] -> first slot of block k in strip s
    for s in range(ns):
        start[s] = tot
        for k in range(nb):
            c = hist[k, s]
            hist[k, s] = tot
            tot += c
    start[ns] = tot
    for k in prange(nb):
        for p in range(k * bs, min(n, (k + 1) * bs)):
            s = cursor[p]
            order[hist[k, s]] = p
            hist[k, s] += 1
    return -1


@njit(cache=True)
def _bounds(est, ng, out):
    """out[0:ng + 1]: ng groups of consecutive items of about equal total est (int64 > 0); boundary g sits before or
    after the item where the running total crosses g / ng of the total, whichever is nearer."""
    nk = est.shape[0]
    tot = 0
    for k in range(nk):
        tot += est[k]
    out[0] = 0
    g = 1
    acc = 0
    for k in range(nk):
        prev = acc
        acc += est[k]
        while g < ng and acc * ng >= g * tot:      # boundary g: before or after item k, whichever is nearer
            out[g] = k + 1 if acc * ng - g * tot <= g * tot - prev * ng else k
            g += 1
    while g <= ng:
        out[g] = nk
        g += 1


@njit(cache=True)
def _measured(cost, start, c, nk):
    """Estimates of items k < nk (strip / column block 2 k + c) from their measured cycles: each capped at 4x the
    mean over the items whose strip holds points (one item timed across a preemption cannot skew a split; the
    empty ones cost little), at least 1. An empty array when an item has no measurement yet (cost <= 0)."""
    tot, cnt = 0, 0
    for k in range(nk):
        st = 2 * k + c
        if cost[st] <= 0:
            return np.empty(0, np.int64)
        if start[st + 1] > start[st]:
            tot += cost[st]
            cnt += 1
    cap = 4 * tot // cnt if cnt > 0 else 0
    est = np.empty(nk, np.int64)
    for k in range(nk):
        e = cost[2 * k + c]
        est[k] = max(1, min(e, cap) if cap > 0 else e)
    return est


@njit(cache=True)
def colour_groups(start, ng, zero_w, cost):
    """Work items of the two colours of P2G (and of the MUSL remap): strips 2 k + c, k in grp[c, g]:grp[c, g + 1],
    form group g of colour c; ng groups of consecutive strips carrying about equal work. numba splits a prange into
    equal index ranges, one per thread, and the points fill only a part of the strips (a column collapsing in a
    long box), so a prange over the strips themselves leaves one thread with most of the points; over NGROUP groups
    of equal work each thread gets an equal share. The work of a strip is its measured cost (cost[strip]: cycles
    of the strip in the last P2G, smoothed over steps, Grid.scost[0]; capped, _measured): a Mohr-Coulomb toe, a
    dense strip or the zeroing of the colour-0 strips' columns cost what they cost, not what their point count
    says. Without a measurement of every strip of the colour (the first step; cost of size 0: the remap) it is the
    number of points of the strip + zero_w per strip of colour 0 (which also zeroes the grid columns it owns). The
    grouping never changes a result: strips of one colour share no node."""
    ns = start.shape[0] - 1
    grp = np.empty((2, ng + 1), np.int64)
    for c in range(2):
        nk = (ns - c + 1) // 2
        est = _measured(cost, start, c, nk) if cost.shape[0] == ns else np.empty(0, np.int64)
        if est.shape[0] != nk or nk == 0:
            est = np.empty(nk, np.int64)
            extra = zero_w if c == 0 else 0
            for k in range(nk):
                est[k] = start[2 * k + c + 1] - start[2 * k + c] + extra
        _bounds(est, ng, grp[c])
    return grp


@njit(cache=True)
def block_groups(start, ng, cost, grp):
    """Work items of the grid update: column blocks k (node columns 2 STRIP k .. 2 STRIP k + 2 STRIP - 1, those P2G's
    colour-0 strip 2 k owns), blocks gb[g]:gb[g + 1] form group g; ng groups of about equal measured cost (cost[2 k]:
    cycles of block k in the last grid update, smoothed, Grid.scost[1]; capped, _measured), since a block's work is
    its nodes holding mass, not its points. Without a measurement: P2G's colour-0 groups grp[0] (the columns each
    group zeroed). Each node is updated on its own, so no result depends on this."""
    ns = start.shape[0] - 1
    nk = (ns + 1) // 2
    gb = np.empty(ng + 1, np.int64)
    est = _measured(cost, start, 0, nk) if cost.shape[0] == ns else np.empty(0, np.int64)
    if est.shape[0] != nk or nk == 0:
        gb[:] = grp[0]
    else:
        _bounds(est, ng, gb)
    return gb


@njit(cache=True, inline="always")
def zero_work(NY):
    """colour_groups' zero_w: P2G's colour-0 strips zero G and V of the 4 node columns they own (9 values per node),
    about the work of scattering 3 NY / 20 points."""
    return 1 + (3 * NY) // 20


@njit(cache=True, inline="always")
def column_has_points(start, i):
    """Whether node column i is in the support of a point: strip st (first support node in columns 2 st, 2 st + 1,
    support up to 2 st + 3) holds points for a strip st in (i - 2) // 2 .. i // 2 (at most 2 strips)."""
    ns = start.shape[0] - 1
    for st in range(max(0, (i - 2) // 2), min(ns - 1, i // 2) + 1):
        if start[st + 1] > start[st]:
            return True
    return False


@njit(cache=True, inline="always")
def group_columns(grp, g, NX):
    """Node columns [lo, hi) of work group g: those its colour-0 strips own (even strip k: columns 2 STRIP k ..
    2 STRIP k + 2 STRIP - 1, zeroed in P2G); the last group also takes the columns beyond. The grid update and the
    MUSL remap take their nodes by these ranges, so each thread reads the nodes it summed."""
    hi = NX if g == grp.shape[1] - 2 else min(2 * STRIP * grp[0, g + 1], NX)
    return min(2 * STRIP * grp[0, g], NX), hi


# ---- P2G ----------------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _scatter_point(p, kind, W, S, P, G, ih, hx, hy, apic):
    """Mass, momentum (APIC: with the affine part C r) and force (gravity + fext - div stress) of point p onto its
    W x W support nodes. The weights are tensor products (N = wx_a wy_b, dN = (dwx_a wy_b, wx_a dwy_b) / h,
    r = (rx_a, ry_b)), so each node value is two or three products of a factor of node column a (in registers)
    with one of node row b: m N = (m wx_a) wy_b, m N (v + C r) = (m wx_a (v + C_.x rx_a)) wy_b + (m wx_a C_.y)
    (wy_b ry_b), N b - V s dN = (wx_a b - V s_.x dwx_a / h) wy_b - (V s_.y wx_a / h) dwy_b."""
    x, h, org0, org1 = P.x, S.h, S.org0, S.org1
    xp, yp = x[p, 0], x[p, 1]
    i0, wx, dwx = weights3(kind, (xp - org0) * ih + PAD, P.lp[p], PAD, hx)
    j0, wy, dwy = weights3(kind, (yp - org1) * ih + PAD, P.lp[p], PAD, hy)
    mp = P.m[p]
    Vh = P.vol[p] * ih
    sxx, syy, sxy = P.s[p, 0], P.s[p, 1], P.s[p, 2]
    vx, vy = P.v[p, 0], P.v[p, 1]
    bx = mp * S.g0 + P.fext[p, 0]
    by = mp * S.g1 + P.fext[p, 1]
    c00 = c01 = c10 = c11 = 0.0
    if apic:
        C = P.C
        c00, c01, c10, c11 = C[p, 0, 0], C[p, 0, 1], C[p, 1, 0], C[p, 1, 1]
    rx0 = (i0 - PAD) * h + org0 - xp
    ry0 = (j0 - PAD) * h + org1 - yp
    wyr = (wy[0] * ry0, wy[1] * (ry0 + h), wy[2] * (ry0 + 2.0 * h))     # wy_b ry_b
    for a in range(W):
        i = unsigned(i0 + a)              # >= 0: the point is inside the padded grid (loops.py)
        mw = mp * wx[a]
        ux, uy = vx, vy
        if apic:
            rx = rx0 + a * h
            ux += c00 * rx
            uy += c10 * rx
        m1, m2 = mw * ux, mw * uy         # x wy_b
        k1, k2 = mw * c01, mw * c11       # x wy_b ry_b (APIC)
        f3 = wx[a] * bx - Vh * sxx * dwx[a]
        f4 = wx[a] * by - Vh * sxy * dwx[a]     # x wy_b
        e3 = Vh * sxy * wx[a]
        e4 = Vh * syy * wx[a]             # x dwy_b
        for b in range(W):
            j = unsigned(j0 + b)
            w = wy[b]
            G[i, j, 0] += mw * w
            if apic:
                G[i, j, 1] += m1 * w + k1 * wyr[b]
                G[i, j, 2] += m2 * w + k2 * wyr[b]
            else:
                G[i, j, 1] += m1 * w
                G[i, j, 2] += m2 * w
            G[i, j, 3] += f3 * w - e3 * dwy[b]
            G[i, j, 4] += f4 * w - e4 * dwy[b]


@njit(cache=True, inline="always")
def _scatter_strip(st, kind, W, S, P, Gr, ih, hx, hy, apic):
    order, G = Gr.order, Gr.G
    for q in items(Gr.start[st], Gr.start[st + 1]):
        _scatter_point(unsigned(order[q]), kind, W, S, P, G, ih, hx, hy, apic)


@njit(cache=True, inline="always")
def _scatter_all(kind, W, S, P, Gr):
    G, V = Gr.G, Gr.V
    NX = G.shape[0]
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    ih = 1.0 / S.h
    apic = S.mode == 2
    ng = NGROUP
    sc = Gr.scost[0]                # cycles per strip (colour_groups), written by the thread that owns the strip
    grp = colour_groups(Gr.start, ng, zero_work(G.shape[1]), sc)
    for color in range(2):
        for g in prange(ng):
            for k in range(grp[color, g], grp[color, g + 1]):
                st = 2 * k + color
                c0 = _cycles()
                if color == 0:      # even strip k owns node columns 4 k .. 4 k + 3 (its whole support): zero them
                    for i in range(4 * k, min(4 * k + 4, NX)):
                        G[i] = 0.0
                        V[i] = 0.0  # grid_solve writes only the nodes holding mass
                _scatter_strip(st, kind, W, S, P, Gr, ih, hx, hy, apic)
                dc = _cycles() - c0
                sc[st] = dc if sc[st] <= 0 else (sc[st] + dc) // 2     # smoothed over steps


# one compiled copy per registered shape (its id and width constants), picked by _by_shape
@njit(cache=True, parallel=True)
def _scatter_linear(S, P, Gr):
    _scatter_all(S.kind, WIDTH[LINEAR], S, P, Gr)


@njit(cache=True, parallel=True)
def _scatter_gimp(S, P, Gr):
    _scatter_all(S.kind, WIDTH[GIMP], S, P, Gr)


@njit(cache=True, parallel=True)
def _scatter_bspline2(S, P, Gr):
    _scatter_all(S.kind, WIDTH[BSPLINE2], S, P, Gr)


@njit(cache=True)
def scatter(S, P, Gr):
    """P2G of all points (strip-coloured, see module docstring). G is zeroed first."""
    if S.kind == BSPLINE2:
        _scatter_bspline2(S, P, Gr)
    elif S.kind == GIMP:
        _scatter_gimp(S, P, Gr)
    elif S.kind == LINEAR:
        _scatter_linear(S, P, Gr)


# ---- point loads --------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _sliver_weight(w, m, mc):
    """Share of a support node of mass m in a boundary particle's transfer, from its shape weight w: w if m >= mc,
    w m / mc below (0 for a node without mass). Below mc the weights are the mass-weighted ones of immersed-boundary
    spreading (N_i m_i, Peskin 2002 Acta Numerica 11, sec. 6), so a node holding a sliver of mass gets an
    acceleration w f / mc at most (not w f / m -> infinite) and its velocity counts by its momentum; at or above mc
    (a node at least that fraction full) the plain shape weight keeps the load's point of action (issue 15).
    The shares are normalised by _support_norm, not by their sum alone (that would undo the bound); what they
    cannot carry goes to the nearest full nodes (_transfer)."""
    if m <= 1e-300:
        return 0.0
    if m < mc:
        return w * (m / mc)
    return w


# The boundary-particle transfer below takes each particle's scalars (position xp, yp and sliver mass mc), read
# by the loop over the particles: an array of a named tuple (B.mc) read again inside these inlined helpers cost
# numba a reference count on every particle (~60-170 ns each: move_boundary of 536 particles 147 -> ~20 us).
@njit(cache=True, inline="always")
def _support_norm(kind, W, S, G, xp, yp, mc, hx, hy):
    """(i0, j0, wx, wy, tot, D) of the boundary particle at (xp, yp) of sliver mass mc: tot = sum of its support's shares s_i (_sliver_weight),
    D = max(tot, w_max), w_max the largest shape weight of a support node holding mass. The transfer weights are
    N_i = s_i / D (spread and velocity read alike). D = tot (the load kept exactly, the weights renormalised over the
    nodes holding mass) whenever a node of the largest weight holding mass is at least mc full, which is every
    attached particle. D > tot only for a particle whose support holds slivers where its weight is: dividing by tot
    there gave N_i = s_i / tot ~ 1 on a node of mass << mc, so the particle's effective mass 1 / sum N_i^2 / m_i fell
    to ~ tot mc (issue 15: 0.04 mc at h = 2.5 mm, the DEM contact on it an explicit spring on ~1 % of the mass the
    coupling step assumes, diverging in 6 steps). With D: node acceleration N_i f / m_i <= f / mc and effective mass
    >= mc (sum s_i^2 / m_i <= w_max tot / mc); the load's part 1 - tot / D goes to the nearest full nodes (_transfer),
    dropped only when none is within reach (spread_loads counts both)."""
    i0, wx, _ = weights3(kind, (xp - S.org0) / S.h + PAD, 0.25, PAD, hx)
    j0, wy, _ = weights3(kind, (yp - S.org1) / S.h + PAD, 0.25, PAD, hy)
    tot = wmax = 0.0
    for a in range(W):
        i = unsigned(i0 + a)              # >= 0: the particle is inside the padded grid (checked; loops.py)
        for b in range(W):
            w = wx[a] * wy[b]
            m = G[i, unsigned(j0 + b), 0]
            tot += _sliver_weight(w, m, mc)
            if m > 1e-300 and w > wmax:
                wmax = w
    return i0, j0, wx, wy, tot, max(tot, wmax)


REACH = 2   # rings of nodes around a boundary particle's support searched for full nodes (_reroute_window)


@njit(cache=True, inline="always")
def _full(m, mc):
    """Whether a node of mass m holds real mass for a boundary particle of sliver mass mc: m >= mc (any mass if
    mc = 0)."""
    return m > 1e-300 and m >= mc


@njit(cache=True, inline="always")
def _reroute_window(G, i0, j0, W, mc):
    """Where the part of a load its support cannot carry goes (_support_norm: 1 - tot / D): the full nodes (_full)
    of the smallest window of nodes [ia, ib) x [ja, jb) around the W x W support at i0, j0, grown by g = 0 .. REACH
    rings (g = 0: the support itself), that holds one; the part is spread over them by their mass (equal
    acceleration: the nearest patch of the body takes it as a rigid piece; a node's acceleration stays <= f / mc).
    Returns (ia, ib, ja, jb, M), M the mass of those full nodes; M = 0: none within reach (the part is dropped)."""
    NX, NY = G.shape[0], G.shape[1]
    for g in range(REACH + 1):
        ia, ib = max(i0 - g, 0), min(i0 + W + g, NX)
        ja, jb = max(j0 - g, 0), min(j0 + W + g, NY)
        M = 0.0
        for i in items(ia, ib):
            for j in items(ja, jb):
                if _full(G[i, j, 0], mc):
                    M += G[i, j, 0]
        if M > 0.0:
            return ia, ib, ja, jb, M
    return 0, 0, 0, 0, 0.0


@njit(cache=True, inline="always")
def _transfer(kind, W, S, G, xp, yp, mc, hx, hy):
    """The transfer of a boundary particle (at xp, yp, sliver mass mc), shared by the load spread (spread_loads) and the velocity /
    displacement reads (move_boundary here and in implicit/kernels.py), so one is the transpose of the other:
    weights N_i = s_i / D on its support (_support_norm), plus c m_j on the full nodes j of the reroute window
    (_reroute_window) when the support cannot carry the whole load (rem = 1 - tot / D > 0: a support of slivers, or
    of no mass), c = rem / M, so the weights sum to 1 (force and momentum kept). Returns (i0, j0, wx, wy, D, ia,
    ib, ja, jb, c, rem): c = 0 when nothing is rerouted (D = tot: bitwise the transfer without the window), rem > 0
    with c = 0 when no full node is within reach (that part is dropped)."""
    i0, j0, wx, wy, tot, D = _support_norm(kind, W, S, G, xp, yp, mc, hx, hy)
    ia = ib = ja = jb = 0
    c = rem = 0.0
    if not D == tot or tot <= 0.0:
        rem = (D - tot) / D if D > 0.0 else 1.0
        ia, ib, ja, jb, M = _reroute_window(G, i0, j0, W, mc)
        if M > 0.0:
            c = rem / M
    return i0, j0, wx, wy, D, ia, ib, ja, jb, c, rem


@njit(cache=True, inline="always")
def _read(kind, W, S, G, xp, yp, mc, hx, hy, A, k):
    """sum_i N_i A[i, k:k+2] with _transfer's weights (the transpose of the spread). Returns (ux, uy, ok), ok False
    when no node of the support nor of the reroute window holds mass (stranded: 0, 0)."""
    i0, j0, wx, wy, D, ia, ib, ja, jb, c, rem = _transfer(kind, W, S, G, xp, yp, mc, hx, hy)
    ux = uy = 0.0
    for a in range(W):
        i = unsigned(i0 + a)
        for b in range(W):
            j = unsigned(j0 + b)
            N = _sliver_weight(wx[a] * wy[b], G[i, j, 0], mc)   # the spread's weights (transpose)
            if N > 0.0:
                ux += N * A[i, j, k]
                uy += N * A[i, j, k + 1]
    if D > 0.0:
        ux, uy = ux / D, uy / D
    if c > 0.0:
        rx = ry = 0.0
        for i in items(ia, ib):
            for j in items(ja, jb):
                m = G[i, j, 0]
                if _full(m, mc):
                    rx += m * A[i, j, k]
                    ry += m * A[i, j, k + 1]
        ux += c * rx
        uy += c * ry
    return ux, uy, D > 0.0 or c > 0.0


@njit(cache=True, inline="always")
def _spread_one(kind, W, S, G, xp, yp, mc, fx, fy, hx, hy):
    """Load (fx, fy) of the boundary particle at (xp, yp), sliver mass mc, onto its support's nodes holding mass, weights N_i = s_i / D (_support_norm), and
    the part a support of slivers cannot carry onto the full nodes of the reroute window (_transfer). Returns
    (fraction applied, fraction rerouted): (1, 0) when D = tot (renormalised, kept exactly), (1, rem) when rem was
    rerouted, (1 - rem, 0) when no full node is within reach (tot / D on slivers, 0 with no mass: dropped)."""
    i0, j0, wx, wy, D, ia, ib, ja, jb, c, rem = _transfer(kind, W, S, G, xp, yp, mc, hx, hy)
    if D > 0.0:
        for a in range(W):
            i = unsigned(i0 + a)
            for b in range(W):
                j = unsigned(j0 + b)
                w = _sliver_weight(wx[a] * wy[b], G[i, j, 0], mc)
                if w > 0.0:
                    N = w / D
                    G[i, j, 3] += N * fx
                    G[i, j, 4] += N * fy
    if c > 0.0:
        for i in items(ia, ib):
            for j in items(ja, jb):
                m = G[i, j, 0]
                if _full(m, mc):
                    G[i, j, 3] += c * m * fx
                    G[i, j, 4] += c * m * fy
        return 1.0, rem
    return 1.0 - rem, 0.0


@njit(cache=True)
def spread_loads(S, B, Gr, dt):
    """Point loads of the boundary particles onto the grid (boundary particles carry no mass). Only nodes holding
    mass receive force; the weights are renormalised over them so the load is kept exactly. On a support whose nodes
    of the largest weight hold only slivers (_support_norm), or no mass, the part it cannot carry (1 - tot / D) goes
    to the nearest full nodes (_transfer, _reroute_window: force kept); counted as rerouted, B.drop[6] = count,
    B.drop[7] = impulse rerouted |f| rem dt. With no full node within reach that part is dropped; dropped loads and
    parts are counted: B.drop[0:4] = [count, impulse dropped |f| dt, impulse applied |f| dt, largest dropped fraction
    of a step's total |f|]. Returns (dropped fraction of this step, first boundary particle whose load was dropped,
    wholly or in part, or -1)."""
    G = Gr.G
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    fb, xb, mcs = B.f, B.x, B.mc
    tot = dropped = rerouted = 0.0
    first = -1
    for p in range(xb.shape[0]):
        fx, fy = fb[p, 0], fb[p, 1]
        if fx == 0.0 and fy == 0.0:
            continue
        mag = np.sqrt(fx * fx + fy * fy)
        tot += mag
        xp, yp, mc = xb[p, 0], xb[p, 1], mcs[p]
        if S.kind == BSPLINE2:
            kept, moved = _spread_one(BSPLINE2, WIDTH[BSPLINE2], S, G, xp, yp, mc, fx, fy, hx, hy)
        elif S.kind == GIMP:
            kept, moved = _spread_one(GIMP, WIDTH[GIMP], S, G, xp, yp, mc, fx, fy, hx, hy)
        else:
            kept, moved = _spread_one(LINEAR, WIDTH[LINEAR], S, G, xp, yp, mc, fx, fy, hx, hy)
        if moved > 0.0:
            rerouted += moved * mag
            B.drop[6] += 1.0
        if kept < 1.0:
            dropped += (1.0 - kept) * mag
            B.drop[0] += 1.0
            if first < 0:
                first = p
    if tot == 0.0:
        return 0.0, first
    frac = dropped / tot
    B.drop[1] += dropped * dt
    B.drop[2] += tot * dt
    B.drop[7] += rerouted * dt
    if frac > B.drop[3]:
        B.drop[3] = frac
    return frac, first


# ---- grid update and BCs ------------------------------------------------------------------------------------
@njit(cache=True)
def apply_bc(V, off, nx, ny, bc, mu):
    """BCs on the velocity pair V[:, :, off:off+2]. Sides: 0 left, 1 right, 2 bottom, 3 top; bc 0 fixed, 1 slip,
    2 friction, 3 open. Nodes on or beyond a side: the normal velocity into the wall is removed (separation
    allowed); friction reduces the tangential speed by mu |dv_n| (Coulomb, Bardenhagen et al. 2001); fixed sets
    both components to 0."""
    NX, NY = V.shape[0], V.shape[1]
    for side in range(4):
        k = bc[side]
        if k == 3:
            continue
        if side < 2:
            r0, r1 = (0, PAD + 1) if side == 0 else (PAD + nx, NX)
            for i in range(r0, r1):
                for j in range(NY):
                    V[i, j, off], V[i, j, off + 1] = wall_velocity(V[i, j, off], V[i, j, off + 1], 0,
                                                                   1.0 if side == 0 else -1.0, k, mu[side])
        else:
            r0, r1 = (0, PAD + 1) if side == 2 else (PAD + ny, NY)
            for i in range(NX):
                for j in range(r0, r1):
                    V[i, j, off], V[i, j, off + 1] = wall_velocity(V[i, j, off], V[i, j, off + 1], 1,
                                                                   1.0 if side == 2 else -1.0, k, mu[side])


@njit(cache=True, inline="always")
def wall_velocity(ux, uy, d, nrm, k, mu):
    """Velocity (ux, uy) at a wall with inward normal nrm e_d under BC kind k (see apply_bc)."""
    if k == 0:
        return 0.0, 0.0
    if k == 3:
        return ux, uy
    un = (ux if d == 0 else uy) * nrm
    if un >= 0.0:
        return ux, uy
    ut = uy if d == 0 else ux
    if k == 2:
        red = mu * (-un)
        if abs(ut) <= red:
            ut = 0.0
        else:
            ut = ut - red * (1.0 if ut > 0 else -1.0)
    return (0.0, ut) if d == 0 else (ut, 0.0)


@njit(cache=True, parallel=True)
def grid_solve(S, Gr, dt):
    """v^n = p / m, v^{n+1} = (p + f dt) / m, then the BCs on both. Local non-viscous damping (Cundall 1987):
    f <- f - alpha |f| sign(p), alpha = S.damping (0 = none)."""
    G, V, alpha = Gr.G, Gr.V, S.damping
    NX, NY = G.shape[0], G.shape[1]
    ng = NGROUP
    # the node columns in blocks of 2 STRIP (those P2G's colour-0 strip 2 k zeroed), dealt in groups of about equal
    # measured cost (block_groups; before a measurement, the colour-0 groups of P2G). P2G zeroed V, so only the
    # nodes holding mass are written, and columns no point reaches are skipped (most of a long box)
    bc = Gr.scost[1]                # cycles per column block, at index 2 k (written by the block's thread)
    gb = block_groups(Gr.start, ng, bc, colour_groups(Gr.start, ng, zero_work(NY), Gr.scost[0]))
    for g in prange(ng):
        for k in range(gb[g], gb[g + 1]):
            c0 = _cycles()
            for i in range(2 * STRIP * k, min(2 * STRIP * (k + 1), NX)):
                if not column_has_points(Gr.start, i):
                    continue
                for j in range(NY):
                    mm = G[i, j, 0]
                    if mm > 1e-300:
                        for d in range(2):
                            pd = G[i, j, 1 + d]
                            f = G[i, j, 3 + d]
                            if alpha > 0.0 and pd != 0.0:
                                f -= alpha * abs(f) * (1.0 if pd > 0.0 else -1.0)
                            V[i, j, d] = pd / mm
                            V[i, j, 2 + d] = (pd + f * dt) / mm
            dc = _cycles() - c0
            bc[2 * k] = dc if bc[2 * k] <= 0 else (bc[2 * k] + dc) // 2   # smoothed over steps
    apply_bc(V, 0, S.nx, S.ny, S.bc, S.mu)
    apply_bc(V, 2, S.nx, S.ny, S.bc, S.mu)


@njit(cache=True, inline="always")
def apic_d(kind, W, i0, j0, xi, eta, wx, wy):
    """Diagonal of APIC's D = sum_i N_i r_i r_i^T in cell units, r_i = x_i - x_p (Jiang et al. 2015; diagonal with
    linear reproduction and a tensor product): Jiang's constant 1/4 for the quadratic B-spline (it bounds the wall
    half cells' D(x_p); _gather_range), D(x_p) of the weights for linear / uGIMP. Explicit gather and implicit
    commit."""
    if kind == BSPLINE2:
        return 0.25, 0.25
    dxx = dyy = 0.0
    for a in range(W):
        rx = i0 + a - xi
        dxx += wx[a] * rx * rx
        ry = j0 + a - eta
        dyy += wy[a] * ry * ry
    return dxx, dyy


# ---- G2P + stress -------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _gather_range(lo, hi, order, stage, kind, W, S, P, V, dt):
    """Points order[lo:hi], weights at the current x (= x^n). stage 0: USL/APIC full update (velocity, position,
    deformation, stress); 1: MUSL velocity only; 2: MUSL position from v1 + L from the remapped velocity V[.., 0:2]
    + stress. Returns 2 p for the first point with a non-finite stress, 2 p + 1 for one whose new position is
    outside the box S.box = (lo0, lo1, hi0, hi1) or not finite, -1 if none; of several such points, the one with
    the lowest index (every point of the range is updated).
    C: APIC (mode 2) the affine matrix C = B D^-1 of Jiang et al. 2015 (SIGGRAPH, APIC), B = sum_i N_i v_i r_i^T,
    D = sum_i N_i r_i r_i^T, r_i = x_i - x_p (quadratic B-spline: D = h^2/4 I): the weighted least-squares affine
    fit of the node velocities (at a wall, for the spline, the fit regularised by tr(C (h^2/4 I - D) C^T) >= 0),
    so a P2G -> G2P round trip cannot gain kinetic energy and conserves angular momentum (the spline: away from
    the wall half cells); the strain and stress use L = sum_i v_i grad N_i^T. USL / MUSL: C = L (not read by
    their P2G)."""
    # every array written is reached through a local name: numba 0.68 drops an item write through a tuple attribute
    # (P.eps_p[p] += ...) inside a parallel loop
    x, v, C, F, s, vol, vol0, eps_p, lp = P.x, P.v, P.C, P.F, P.s, P.vol, P.vol0, P.eps_p, P.lp
    org0, org1, box, mode = S.org0, S.org1, S.box, S.mode
    ih = 1.0 / S.h
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    lgo = 0 if stage == 2 else 2      # velocity pair used for L
    flip = stage == 1 or (stage == 0 and mode == 0)
    apic = stage == 0 and mode == 2
    first = -1
    for q in items(lo, hi):
        ps = order[q]                     # signed copy for the status codes below
        p = unsigned(ps)
        xp, yp = x[p, 0], x[p, 1]
        xi, eta = (xp - org0) * ih + PAD, (yp - org1) * ih + PAD
        i0, wx, dwx = weights3(kind, xi, lp[p], PAD, hx)
        j0, wy, dwy = weights3(kind, eta, lp[p], PAD, hy)
        px = py = dvx = dvy = 0.0
        l00 = l01 = l10 = l11 = 0.0
        b00 = b01 = b10 = b11 = 0.0
        dxx = dyy = 0.0
        if apic:
            # D in cell units (r / h). Quadratic B-spline: Jiang's constant D = h^2/4 I. It is D(x_p) in the
            # interior and bounds it at a wall (the wall-modified spline is linear in the wall half cell:
            # D = s (1 - s) h^2 <= h^2/4), so the transfer energy 1/2 m (|v|^2 + h^2/4 |C|^2) does not depend on
            # x_p and bounds the P2G grid kinetic energy wherever the point has moved: with D(x_p) there, an affine
            # mode stored at D ~ 0 (a lone point on the wall) came back as kinetic energy when the point moved off
            # the wall (a stress-free point under a layer sliding on the friction base was thrown out of the grid;
            # tests/mpm/test_apic.py). Linear / uGIMP: D(x_p) of the
            # weights (Jiang et al. 2015; exact for affine fields); with linear reproduction (sum_i N_i r_i = 0)
            # and a tensor product D is diagonal.
            dxx, dyy = apic_d(kind, W, i0, j0, xi, eta, wx, wy)
        # node sums factored by node column a (tensor-product weights, N = wx_a wy_b): sums over the rows b with wy_b,
        # wy_b r_y(b) and dwy_b, then combined with wx_a, wx_a r_x(a), dwx_a (fewer products than N_ab per node;
        # the same sums in another order: round-off-level differences, docs/development_log.md thirteenth session)
        wyr = (wy[0] * (j0 - eta), wy[1] * (j0 + 1 - eta), wy[2] * (j0 + 2 - eta))
        for a in range(W):
            i = unsigned(i0 + a)
            ux_ = uy_ = dx_ = dy_ = rx_ = ry_ = gx_ = gy_ = hx_ = hy_ = 0.0
            for b in range(W):
                j = unsigned(j0 + b)
                ux, uy = V[i, j, 2], V[i, j, 3]
                ux_ += wy[b] * ux
                uy_ += wy[b] * uy
                if flip:
                    dx_ += wy[b] * (ux - V[i, j, 0])
                    dy_ += wy[b] * (uy - V[i, j, 1])
                if apic:
                    rx_ += wyr[b] * ux
                    ry_ += wyr[b] * uy
                if stage != 1:
                    gx, gy = V[i, j, lgo], V[i, j, lgo + 1]
                    if lgo != 2:
                        gx_ += wy[b] * gx
                        gy_ += wy[b] * gy
                    hx_ += dwy[b] * gx
                    hy_ += dwy[b] * gy
            px += wx[a] * ux_
            py += wx[a] * uy_
            if flip:
                dvx += wx[a] * dx_
                dvy += wx[a] * dy_
            if apic:
                wr = wx[a] * (i0 + a - xi)
                b00 += wr * ux_
                b01 += wx[a] * rx_
                b10 += wr * uy_
                b11 += wx[a] * ry_
            if stage != 1:
                if lgo == 2:
                    gx_, gy_ = ux_, uy_
                l00 += dwx[a] * gx_
                l01 += wx[a] * hx_
                l10 += dwx[a] * gy_
                l11 += wx[a] * hy_
        if stage == 1:
            v[p, 0] += dvx
            v[p, 1] += dvy
            continue
        l00, l01, l10, l11 = l00 * ih, l01 * ih, l10 * ih, l11 * ih
        if stage == 0:
            if mode == 2:
                v[p, 0], v[p, 1] = px, py
            else:
                v[p, 0] += dvx
                v[p, 1] += dvy
        if apic:
            # C = B D^-1 (Jiang et al. 2015). D_xx = 0 only for linear weights with the point on a node line:
            # there B D^-1 -> dv/dx, the column of L (with weights linear in x, B_.x / D_xx = (v_i+1 - v_i) / h
            # = L_.x wherever D_xx > 0: its limit)
            if dxx > 0.0:
                C[p, 0, 0], C[p, 1, 0] = b00 * ih / dxx, b10 * ih / dxx
            else:
                C[p, 0, 0], C[p, 1, 0] = l00, l10
            if dyy > 0.0:
                C[p, 0, 1], C[p, 1, 1] = b01 * ih / dyy, b11 * ih / dyy
            else:
                C[p, 0, 1], C[p, 1, 1] = l01, l11
        else:
            C[p, 0, 0], C[p, 0, 1], C[p, 1, 0], C[p, 1, 1] = l00, l01, l10, l11
        xn, yn = xp + dt * px, yp + dt * py
        x[p, 0], x[p, 1] = xn, yn
        # deformation gradient, volume, stress (strain increment d = sym(L) dt, spin W_xy dt)
        l00, l01, l10, l11 = l00 * dt, l01 * dt, l10 * dt, l11 * dt
        f00, f01, f10, f11 = F[p, 0], F[p, 1], F[p, 2], F[p, 3]
        F[p, 0] = f00 + l00 * f00 + l01 * f10
        F[p, 1] = f01 + l00 * f01 + l01 * f11
        F[p, 2] = f10 + l10 * f00 + l11 * f10
        F[p, 3] = f11 + l10 * f01 + l11 * f11
        J = F[p, 0] * F[p, 3] - F[p, 1] * F[p, 2]
        vol[p] = vol0[p] * J
        prm = S.prm[P.mid[p]]
        if disconnected(prm, s[p, 0], s[p, 1], s[p, 2], s[p, 3], J):
            # cohesionless point at sigma = 0 below its packing density (J > 1): no contact, no stress, no elastic
            # memory (Dunatunga & Kamrin 2015; constitutive/disconnected.py); counted in summary.json
            r = (0.0, 0.0, 0.0, 0.0, 0.0)
        else:
            r = stress_update(prm, s[p, 0], s[p, 1], s[p, 2], s[p, 3], l00, l11, l01 + l10, 0.5 * (l01 - l10), dt)
        s[p, 0], s[p, 1], s[p, 2], s[p, 3] = r[0], r[1], r[2], r[3]
        eps_p[p] += r[4]
        code = -1
        if not (np.isfinite(r[0]) and np.isfinite(r[1]) and np.isfinite(r[2]) and np.isfinite(r[3])):
            code = 2 * ps
        elif not (xn >= box[0] and xn <= box[2] and yn >= box[1] and yn <= box[3]):
            code = 2 * ps + 1
        if code >= 0 and (first < 0 or code < first):
            first = code
    return first


@njit(cache=True)
def chunk_groups(cost, nc, ng):
    """The gather's work items: chunks bnd[g]:bnd[g + 1] (of CHUNK points in strip order) form group g, ng groups of
    consecutive chunks of about equal estimated cost, so that a prange over the groups (equal index ranges per
    thread) gives the threads equal work. The estimate of a chunk is its cost (cycles, the gather's own timer,
    smoothed over steps), capped at 4x the mean so that one chunk timed across a preemption cannot skew the split;
    without a measurement (the first step, a run resized) all chunks count alike. Also returns the groups' failure
    slots (ng,), allocated here, outside the parallel function. Only which thread gathers a point depends on this:
    the gather is per point, so no result does."""
    tot = 0
    for c in range(nc):
        tot += cost[c]
    cap = 4 * tot // max(nc, 1)
    est = np.ones(nc, np.int64)
    if cap > 0:
        tot = 0
        for c in range(nc):
            est[c] = max(1, min(cost[c], cap))
            tot += est[c]
    else:
        tot = nc
    bnd = np.empty(ng + 1, np.int64)
    bnd[0] = 0
    acc, c = 0, 0
    for g in range(1, ng):          # group g starts at the chunk nearest to the cost quantile g / ng
        target = tot * g / ng
        while c < nc and acc + 0.5 * est[c] < target:
            acc += est[c]
            c += 1
        bnd[g] = c
    bnd[ng] = nc
    return bnd, np.full(ng, -1, np.int64)


@njit(cache=True, inline="always")
def _g2p_all(kind, W, S, P, Gr, dt, stage):
    n = P.x.shape[0]
    nc = (n + CHUNK - 1) // CHUNK
    V, order, cost = Gr.V, Gr.order, Gr.cost
    row = 1 if stage == 1 else 0
    ng = NGROUP
    bnd, bad = chunk_groups(cost[row], nc, ng)
    for g in prange(ng):
        fg = -1
        for c in range(bnd[g], bnd[g + 1]):
            c0 = _cycles()
            r = _gather_range(c * CHUNK, min(n, (c + 1) * CHUNK), order, stage, kind, W, S, P, V, dt)
            dc = _cycles() - c0
            cost[row, c] = dc if cost[row, c] <= 0 else (cost[row, c] + dc) // 2   # smoothed over steps
            if r >= 0 and (fg < 0 or r < fg):
                fg = r
        bad[g] = fg
    first = -1
    for g in range(ng):
        if bad[g] >= 0 and (first < 0 or bad[g] < first):
            first = bad[g]
    return first


@njit(cache=True, parallel=True)
def _g2p_linear(S, P, Gr, dt, stage):
    return _g2p_all(S.kind, WIDTH[LINEAR], S, P, Gr, dt, stage)


@njit(cache=True, parallel=True)
def _g2p_gimp(S, P, Gr, dt, stage):
    return _g2p_all(S.kind, WIDTH[GIMP], S, P, Gr, dt, stage)


@njit(cache=True, parallel=True)
def _g2p_bspline2(S, P, Gr, dt, stage):
    return _g2p_all(S.kind, WIDTH[BSPLINE2], S, P, Gr, dt, stage)


@njit(cache=True)
def g2p(S, P, Gr, dt, stage):
    """G2P + stress per point over chunks in work groups of equal cost (chunk_groups, _gather_range); returns the code of the first bad point
    (2 p: stress not finite, 2 p + 1: new position outside the box) or -1."""
    if S.kind == BSPLINE2:
        return _g2p_bspline2(S, P, Gr, dt, stage)
    if S.kind == GIMP:
        return _g2p_gimp(S, P, Gr, dt, stage)
    return _g2p_linear(S, P, Gr, dt, stage)


# ---- MUSL remap ---------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _remap_strip(st, kind, W, S, P, Gr, ih, hx, hy):
    x, v, m, G = P.x, P.v, P.m, Gr.G
    for q in range(Gr.start[st], Gr.start[st + 1]):
        p = Gr.order[q]
        i0, wx, _ = weights3(kind, (x[p, 0] - S.org0) * ih + PAD, P.lp[p], PAD, hx)
        j0, wy, _ = weights3(kind, (x[p, 1] - S.org1) * ih + PAD, P.lp[p], PAD, hy)
        mvx, mvy = m[p] * v[p, 0], m[p] * v[p, 1]
        for a in range(W):
            for b in range(W):
                N = wx[a] * wy[b]
                G[i0 + a, j0 + b, 1] += N * mvx
                G[i0 + a, j0 + b, 2] += N * mvy


@njit(cache=True, inline="always")
def _remap_all(kind, W, S, P, Gr):
    G, V = Gr.G, Gr.V
    ih = 1.0 / S.h
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    NX, NY = G.shape[0], G.shape[1]
    ng = NGROUP
    grp = colour_groups(Gr.start, ng, 0, np.empty(0, np.int64))     # by point counts
    for g in prange(ng):        # node columns by the colour-0 groups, as in grid_solve
        i_lo, i_hi = group_columns(grp, g, NX)
        for i in range(i_lo, i_hi):
            for j in range(NY):
                G[i, j, 1] = 0.0
                G[i, j, 2] = 0.0
    for color in range(2):
        for g in prange(ng):
            for k in range(grp[color, g], grp[color, g + 1]):
                _remap_strip(2 * k + color, kind, W, S, P, Gr, ih, hx, hy)
    for g in prange(ng):
        i_lo, i_hi = group_columns(grp, g, NX)
        for i in range(i_lo, i_hi):
            for j in range(NY):
                mm = G[i, j, 0]
                if mm > 1e-300:
                    V[i, j, 0] = G[i, j, 1] / mm
                    V[i, j, 1] = G[i, j, 2] / mm
                else:
                    V[i, j, 0] = 0.0
                    V[i, j, 1] = 0.0
    apply_bc(V, 0, S.nx, S.ny, S.bc, S.mu)


@njit(cache=True, parallel=True)
def _remap_linear(S, P, Gr):
    _remap_all(S.kind, WIDTH[LINEAR], S, P, Gr)


@njit(cache=True, parallel=True)
def _remap_gimp(S, P, Gr):
    _remap_all(S.kind, WIDTH[GIMP], S, P, Gr)


@njit(cache=True, parallel=True)
def _remap_bspline2(S, P, Gr):
    _remap_all(S.kind, WIDTH[BSPLINE2], S, P, Gr)


@njit(cache=True)
def remap(S, P, Gr):
    """MUSL: p_i = sum S_ip(x^n) m_p v_p^{n+1} (same strips and order as P2G), V[.., 0:2] = p_i / m_i with the
    mass of this step's P2G, then the BCs."""
    if S.kind == BSPLINE2:
        _remap_bspline2(S, P, Gr)
    elif S.kind == GIMP:
        _remap_gimp(S, P, Gr)
    else:
        _remap_linear(S, P, Gr)


# ---- boundary particles -------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _move_one(kind, W, S, G, V, xp, yp, mc, side, bc, mu, hx, hy):
    """The velocity of the boundary particle at (xp, yp) (sliver mass mc, attached to wall `side` or -1;
    move_boundary): (ux, uy, ok), ok False if no node of its support or reroute window holds mass (stranded: 0)."""
    ux, uy, ok = _read(kind, W, S, G, xp, yp, mc, hx, hy, V, 2)
    if side >= 0:
        d = 0 if side < 2 else 1
        ux, uy = wall_velocity(ux, uy, d, 1.0 if side % 2 == 0 else -1.0, bc[side], mu[side])
        if d == 0:
            ux = 0.0
        else:
            uy = 0.0
    return ux, uy, ok


@njit(cache=True)
def move_boundary(S, B, Gr, dt):
    """Boundary particles move like material points, x += dt v, with v the grid velocity v1 interpolated with
    weights renormalised over the nodes holding mass (empty nodes carry no velocity; a point on the outline has
    part of its support outside the body); the weights are spread_loads' (_read = _transfer: sliver nodes count by
    their momentum; on a support of slivers N_i = s_i / D sum to tot / D < 1 and the rest is the mass-weighted
    velocity of the nearest full nodes, _reroute_window), so the power of a point load is what the grid
    receives. A point created on a side that is not
    open (wall[p] = side, the outline of a body placed against that wall) stays attached to it: its velocity
    follows the side's BC (wall_velocity) with no normal component, so it slides along the wall and its normal
    coordinate stays exactly the wall's. (Linear and boundary-modified B-spline weights give the wall node's velocity on the wall, but GIMP
    mixes in the first interior node there, and the wall node may separate by round-off: either would let the
    point drift to the other side of the wall by round-off.) Positions are never clipped; the step checks every
    point inside the grid before each transfer. A particle no node of whose support or reroute window holds mass is
    stranded: v = 0, it does not move; counted in B.drop[4] (particle-steps) and B.drop[5] (most in one step)."""
    hx, hy = float(PAD + S.nx), float(PAD + S.ny)
    xb, vb, mcs, wall, G, V, bc, mu = B.x, B.v, B.mc, B.wall, Gr.G, Gr.V, S.bc, S.mu
    stranded = 0
    for p in range(xb.shape[0]):
        xp, yp, mc, side = xb[p, 0], xb[p, 1], mcs[p], wall[p]
        if S.kind == BSPLINE2:
            ux, uy, ok = _move_one(BSPLINE2, WIDTH[BSPLINE2], S, G, V, xp, yp, mc, side, bc, mu, hx, hy)
        elif S.kind == GIMP:
            ux, uy, ok = _move_one(GIMP, WIDTH[GIMP], S, G, V, xp, yp, mc, side, bc, mu, hx, hy)
        else:
            ux, uy, ok = _move_one(LINEAR, WIDTH[LINEAR], S, G, V, xp, yp, mc, side, bc, mu, hx, hy)
        vb[p, 0], vb[p, 1] = ux, uy
        xb[p, 0] = xp + dt * ux
        xb[p, 1] = yp + dt * uy
        if not ok:
            stranded += 1
    B.drop[4] += stranded          # stranded boundary particles: particle-steps, most in one step (counted, #17)
    if stranded > B.drop[5]:
        B.drop[5] = stranded


# ---- the step -----------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _tick(prof, T, k, c0):
    """Per-phase timer: adds the cycles since c0 to T[k] and returns the new start (no-op unless prof)."""
    if prof:
        c1 = _cycles()
        T[k] += c1 - c0
        return c1
    return c0


@njit(cache=True)
def step(S, P, B, Gr, dt, prof, T):
    """One explicit step (module docstring). Returns (status, index): STATUS_OK, or the first failure with the
    index of the point it names. Codes STATUS_POINT_OUT / STATUS_BOUNDARY_OUT (before P2G) return before the
    step changes anything; the others are found during or after the step, which has then been completed.
    prof: add the cycles of each phase to T[PHASES index]."""
    b = S.box
    c = _cycles() if prof else 0
    p = sort_strips(S, P, Gr, True)         # checks every point inside the grid first
    if p >= 0:
        return STATUS_POINT_OUT, p
    c = _tick(prof, T, 1, c)
    nb = B.x.shape[0]
    if nb:
        p = check_inside(B.x, b[0], b[1], b[2], b[3])
        if p >= 0:
            return STATUS_BOUNDARY_OUT, p
    c = _tick(prof, T, 0, c)
    scatter(S, P, Gr)
    c = _tick(prof, T, 2, c)
    frac, first = 0.0, -1
    if nb:
        frac, first = spread_loads(S, B, Gr, dt)
    c = _tick(prof, T, 3, c)
    grid_solve(S, Gr, dt)
    c = _tick(prof, T, 4, c)
    if S.mode == 1:   # MUSL: FLIP velocity, remap with S(x^n), then position and stress
        g2p(S, P, Gr, dt, 1)
        c = _tick(prof, T, 5, c)
        remap(S, P, Gr)
        c = _tick(prof, T, 6, c)
        bad = g2p(S, P, Gr, dt, 2)
    else:
        bad = g2p(S, P, Gr, dt, 0)
    c = _tick(prof, T, 5, c)
    if nb:
        move_boundary(S, B, Gr, dt)
    if bad >= 0:
        if bad % 2 == 0:
            return STATUS_STRESS, bad // 2
        return STATUS_POINT_MOVED_OUT, bad // 2
    if nb:
        p = check_inside(B.x, b[0], b[1], b[2], b[3])
        if p >= 0:
            return STATUS_BOUNDARY_MOVED_OUT, p
    c = _tick(prof, T, 7, c)
    if frac > S.max_drop:
        return STATUS_DROPPED, first
    return STATUS_OK, -1


@njit(cache=True)
def advance(S, P, B, Gr, dt, nsteps, t, prof, T):
    """Up to nsteps steps of dt in one compiled loop, t += dt after each completed step. Stops at the first
    failure. Returns (steps completed, t, status, index); a failure found during or after a step (status >
    STATUS_BOUNDARY_OUT) counts that step as completed."""
    if S.kind != LINEAR and S.kind != GIMP and S.kind != BSPLINE2:
        return 0, t, STATUS_SHAPE, S.kind
    for k in range(nsteps):
        code, idx = step(S, P, B, Gr, dt, prof, T)
        if code == STATUS_POINT_OUT or code == STATUS_BOUNDARY_OUT:
            return k, t, code, idx
        t += dt
        if code != STATUS_OK:
            return k + 1, t, code, idx
    return nsteps, t, STATUS_OK, -1


# ---- entry points with the flat signatures (unit tests of single transfers) ---------------------------------
def _setup(kind, mode, org0, org1, h, nx, ny, g0=0.0, g1=0.0, box=None, bc=None, mu=None, prm=None):
    check_shape(kind)
    return Setup(int(kind), int(mode), float(org0), float(org1), float(h), int(nx), int(ny), float(g0), float(g1),
                 0.0, np.zeros(4) if box is None else box, np.zeros(4, np.int64) if bc is None else bc,
                 np.zeros(4) if mu is None else mu, np.zeros((1, N_PRM)) if prm is None else prm, 1.0)


def _points(x, v=None, C=None, F=None, m=None, vol=None, vol0=None, s=None, eps_p=None, lp=None, mid=None,
            fext=None):
    n = x.shape[0]
    z1, z2 = np.zeros(n), np.zeros((n, 2))
    return Points(x, z2 if v is None else v, np.zeros((n, 2, 2)) if C is None else C,
                  np.zeros((n, 4)) if F is None else F, z1 if m is None else m, z1 if vol is None else vol,
                  z1 if vol0 is None else vol0, np.zeros((n, 4)) if s is None else s, z1 if eps_p is None else eps_p,
                  np.full(n, 0.25) if lp is None else lp, np.zeros(n, np.int64) if mid is None else mid,
                  z2 if fext is None else fext)


def strip_sort(kind, x, org0, h, start, cursor, order):
    """sort_strips with flat arguments."""
    S = _setup(kind, 0, org0, 0.0, h, 0, 0)
    sort_strips(S, _points(x), Grid(np.zeros((1, 1, 5)), np.zeros((1, 1, 4)), start, order, cursor,
                                    new_cost(len(order)), new_strip_cost(0)), False)


def p2g(kind, x, v, C, m, vol, s, lp, fext, org0, org1, h, nx, ny, g0, g1, apic, start, order, G):
    """scatter with flat arguments (apic: use C)."""
    S = _setup(kind, 2 if apic else 0, org0, org1, h, nx, ny, g0, g1)
    scatter(S, _points(x, v, C, m=m, vol=vol, s=s, lp=lp, fext=fext),
            Grid(G, np.zeros((G.shape[0], G.shape[1], 4)), start, order, np.zeros(len(order), np.int64),
                 new_cost(len(order)), np.zeros((2, len(start) - 1), np.int64)))


def gather(stage, kind, x, v, C, F, vol, vol0, s, eps_p, prm, mid, lp, org0, org1, h, nx, ny, dt, V, mode,
                  box):
    """g2p with flat arguments; returns its code."""
    S = _setup(kind, mode, org0, org1, h, nx, ny, box=box, prm=prm)
    P = _points(x, v, C, F, vol=vol, vol0=vol0, s=s, eps_p=eps_p, lp=lp, mid=mid)
    n = x.shape[0]
    return g2p(S, P, Grid(np.zeros((1, 1, 5)), V, np.zeros(2, np.int64), np.arange(n, dtype=np.int64),
                          np.zeros(0, np.int64), new_cost(n), new_strip_cost(0)), float(dt), int(stage))
