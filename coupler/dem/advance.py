"""Fused time loop: runs many velocity-Verlet steps inside compiled code (no Python per step).

Stops early, after the drift of a step, when a sphere has moved more than skin/2 since the last neighbour-list
build; the caller then rebuilds and finishes that step (forces, second kick) in Python.
"""
from __future__ import annotations

from numba import njit

from coupler.dem import clusters as cl
from coupler.dem import forces as fk
from coupler.dem import integrator as it


@njit(cache=True)
def _max_disp_sq(x, x_ref):
    m = 0.0
    for i in range(x.shape[0]):
        d = (x[i, 0] - x_ref[i, 0]) ** 2 + (x[i, 1] - x_ref[i, 1]) ** 2 + (x[i, 2] - x_ref[i, 2]) ** 2
        if d > m:
            m = d
    return m


# Two explicit copies (serial / parallel kernels): one compiled function calling both flavours ran several
# times slower, and numba's cache cannot tell apart closures made by a factory.
@njit(cache=True)
def advance_ser(nsteps, x, v, w, q, f, t, r, mass, mdamp, mat, body, gravity, planar, dt,
                pi, pj, offsets, jstart, jlist, pstate, pout, woff, wid, wstate, wout,
                wpoint, wnormal, wvel, wmat, table, diss, track, x_ref, half_skin_sq, wall_speed, t_since_ref):
    """Advance up to nsteps with the ser kernels. Returns (steps completed, 1 if the last step stopped
    after its drift for a neighbour-list rebuild)."""
    for s in range(nsteps):
        it.kick_drift_ser(x, v, w, q, f, t, mass, r, body, dt, planar)
        for p in range(wpoint.shape[0]):
            for c in range(3):
                wpoint[p, c] += wvel[p, c] * dt
        t_since_ref += dt
        disp = _max_disp_sq(x, x_ref) ** 0.5 + wall_speed * t_since_ref
        if disp * disp > half_skin_sq:
            return s, 1
        fk.pair_forces_ser(x, v, w, r, mdamp, mat, pi, pj, pstate, table, dt, pout)
        fk.gather_ser(x, v, w, r, mass, mdamp, mat, body, gravity, offsets, jstart, jlist, pout,
                       woff, wid, wstate, wout, wpoint, wnormal, wvel, wmat, table, dt, f, t, diss, track)
        it.kick_ser(v, w, f, t, mass, r, body, dt, planar)
    return nsteps, 0


@njit(cache=True)
def advance_par(nsteps, x, v, w, q, f, t, r, mass, mdamp, mat, body, gravity, planar, dt,
                pi, pj, offsets, jstart, jlist, pstate, pout, woff, wid, wstate, wout,
                wpoint, wnormal, wvel, wmat, table, diss, track, x_ref, half_skin_sq, wall_speed, t_since_ref):
    """Advance up to nsteps with the par kernels. Returns (steps completed, 1 if the last step stopped
    after its drift for a neighbour-list rebuild)."""
    for s in range(nsteps):
        it.kick_drift_par(x, v, w, q, f, t, mass, r, body, dt, planar)
        for p in range(wpoint.shape[0]):
            for c in range(3):
                wpoint[p, c] += wvel[p, c] * dt
        t_since_ref += dt
        disp = _max_disp_sq(x, x_ref) ** 0.5 + wall_speed * t_since_ref
        if disp * disp > half_skin_sq:
            return s, 1
        fk.pair_forces_par(x, v, w, r, mdamp, mat, pi, pj, pstate, table, dt, pout)
        fk.gather_par(x, v, w, r, mass, mdamp, mat, body, gravity, offsets, jstart, jlist, pout,
                       woff, wid, wstate, wout, wpoint, wnormal, wvel, wmat, table, dt, f, t, diss, track)
        it.kick_par(v, w, f, t, mass, r, body, dt, planar)
    return nsteps, 0


@njit(cache=True)
def advance_clusters_ser(nsteps, x, v, w, q, f, t, r, mass, mdamp, mat, body, gravity, planar, dt,
                        pi, pj, offsets, jstart, jlist, pstate, pout, woff, wid, wstate, wout,
                        wpoint, wnormal, wvel, wmat, table, diss, track, x_ref, half_skin_sq, wall_speed, t_since_ref,
                        bc, bq, bv, bL, bw, bmass, bIp, bF, bT, member, owner, boffset, qtmp, wtmp):
    """advance_ser with rigid clusters: the bodies get the same half kick / drift / half kick as the free spheres
    (clusters.py), their members are placed after each drift and their forces reduced to the bodies."""
    for s in range(nsteps):
        it.kick_drift_ser(x, v, w, q, f, t, mass, r, body, dt, planar)
        cl.body_kick(bv, bL, bF, bT, bmass, dt, planar)
        cl.body_drift(bc, bq, bv, bL, bIp, bw, dt, qtmp, wtmp)
        cl.place_members(bc, bq, bv, bw, member, owner, boffset, x, v, w)
        for p in range(wpoint.shape[0]):
            for c in range(3):
                wpoint[p, c] += wvel[p, c] * dt
        t_since_ref += dt
        disp = _max_disp_sq(x, x_ref) ** 0.5 + wall_speed * t_since_ref
        if disp * disp > half_skin_sq:
            return s, 1
        fk.pair_forces_ser(x, v, w, r, mdamp, mat, pi, pj, pstate, table, dt, pout)
        fk.gather_ser(x, v, w, r, mass, mdamp, mat, body, gravity, offsets, jstart, jlist, pout,
                       woff, wid, wstate, wout, wpoint, wnormal, wvel, wmat, table, dt, f, t, diss, track)
        cl.reduce_to_bodies(bc, bmass, gravity, member, owner, x, f, t, bF, bT)
        cl.body_kick(bv, bL, bF, bT, bmass, dt, planar)
        cl.omega_from_L(bq, bL, bIp, bw)
        cl.place_members(bc, bq, bv, bw, member, owner, boffset, x, v, w)
        it.kick_ser(v, w, f, t, mass, r, body, dt, planar)
    return nsteps, 0


@njit(cache=True)
def advance_clusters_par(nsteps, x, v, w, q, f, t, r, mass, mdamp, mat, body, gravity, planar, dt,
                        pi, pj, offsets, jstart, jlist, pstate, pout, woff, wid, wstate, wout,
                        wpoint, wnormal, wvel, wmat, table, diss, track, x_ref, half_skin_sq, wall_speed, t_since_ref,
                        bc, bq, bv, bL, bw, bmass, bIp, bF, bT, member, owner, boffset, qtmp, wtmp):
    """advance_par with rigid clusters: the bodies get the same half kick / drift / half kick as the free spheres
    (clusters.py), their members are placed after each drift and their forces reduced to the bodies."""
    for s in range(nsteps):
        it.kick_drift_par(x, v, w, q, f, t, mass, r, body, dt, planar)
        cl.body_kick(bv, bL, bF, bT, bmass, dt, planar)
        cl.body_drift(bc, bq, bv, bL, bIp, bw, dt, qtmp, wtmp)
        cl.place_members(bc, bq, bv, bw, member, owner, boffset, x, v, w)
        for p in range(wpoint.shape[0]):
            for c in range(3):
                wpoint[p, c] += wvel[p, c] * dt
        t_since_ref += dt
        disp = _max_disp_sq(x, x_ref) ** 0.5 + wall_speed * t_since_ref
        if disp * disp > half_skin_sq:
            return s, 1
        fk.pair_forces_par(x, v, w, r, mdamp, mat, pi, pj, pstate, table, dt, pout)
        fk.gather_par(x, v, w, r, mass, mdamp, mat, body, gravity, offsets, jstart, jlist, pout,
                       woff, wid, wstate, wout, wpoint, wnormal, wvel, wmat, table, dt, f, t, diss, track)
        cl.reduce_to_bodies(bc, bmass, gravity, member, owner, x, f, t, bF, bT)
        cl.body_kick(bv, bL, bF, bT, bmass, dt, planar)
        cl.omega_from_L(bq, bL, bIp, bw)
        cl.place_members(bc, bq, bv, bw, member, owner, boffset, x, v, w)
        it.kick_par(v, w, f, t, mass, r, body, dt, planar)
    return nsteps, 0
