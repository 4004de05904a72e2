"""Force kernels: pass 1 computes every sphere-sphere pair (parallel over pairs), pass 2 gathers per sphere
(parallel over spheres), adds sphere-plane contacts and gravity, and (same chunk, no extra parallel region) kicks
and drifts the free spheres of that chunk. No two threads write one location and the
sum order is fixed, so results are identical for any thread count.

Per-contact state row (carried over neighbour-list rebuilds): [xi_x, xi_y, xi_z, elastic_energy, fx, fy, fz,
mx, my, mz (rolling torque on i)].
Per-contact output row: [fx, fy, fz (force on i), cx, cy, cz (= n x F), fn, ft, overlap, dissipated this step,
mx, my, mz (rolling torque on i, on j the opposite)]. With the compact Hertz-Mindlin law table (no sub-model
columns, coupler/dem/contact/law.py) the rows are the first 7 / 10 columns (widths()).
Energy bookkeeping (energy.csv): per step and contact, dissipated += -W - dE_el with the contact work
W = 1/2 (F_old + F_new) . v_rel dt (trapezoid with half-step velocities, consistent with velocity Verlet), plus
1/2 (M_old + M_new) . (w_i - w_j) dt for a rolling torque.

Each kernel body loops over a range [lo, hi) so that array arguments are passed once per chunk, not per item.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from coupler.dem.contact import NLAW_HM, contact_force, law_extra
from coupler.dem.integrator import after_forces
from coupler.dem.state import flavours
from coupler.loops import items, unsigned

NSTATE = 10                 # with sub-model columns in the law table (rolling state); Hertz-Mindlin only: 7
NOUT = 13                   # idem (rolling torque); Hertz-Mindlin only: 10
NSTATE_HM = 7
NOUT_HM = 10


def widths(table) -> tuple[int, int]:
    """Per-contact (state, output) row widths for a law table (the compact Hertz-Mindlin table: no rolling)."""
    return (NSTATE_HM, NOUT_HM) if table.shape[2] == NLAW_HM else (NSTATE, NOUT)
CHUNK = 256


@njit(cache=True, inline="always")
def _store(state, out, k, fx, fy, fz, fn, ft, eel, x0, x1, x2, vx, vy, vz, nx, ny, nz, delta, dt):
    work = 0.5 * ((state[k, 4] + fx) * vx + (state[k, 5] + fy) * vy + (state[k, 6] + fz) * vz) * dt
    out[k, 9] = -work - (eel - state[k, 3])
    state[k, 0] = x0
    state[k, 1] = x1
    state[k, 2] = x2
    state[k, 3] = eel
    state[k, 4] = fx
    state[k, 5] = fy
    state[k, 6] = fz
    out[k, 0] = fx
    out[k, 1] = fy
    out[k, 2] = fz
    out[k, 3] = ny * fz - nz * fy
    out[k, 4] = nz * fx - nx * fz
    out[k, 5] = nx * fy - ny * fx
    out[k, 6] = fn
    out[k, 7] = ft
    out[k, 8] = delta


@njit(cache=True, inline="always")
def _open(state, out, k, vx, vy, vz, dt):
    """Contact not touching: close the energy account of a contact that just opened, reset its state."""
    diss = 0.0
    if state[k, 3] != 0.0 or state[k, 4] != 0.0 or state[k, 5] != 0.0 or state[k, 6] != 0.0:
        diss = -0.5 * (state[k, 4] * vx + state[k, 5] * vy + state[k, 6] * vz) * dt + state[k, 3]
    for c in range(state.shape[1]):
        state[k, c] = 0.0
    for c in range(out.shape[1]):
        out[k, c] = 0.0
    out[k, 9] = diss


@njit(cache=True, inline="always")
def _store_roll(state, out, k, mx, my, mz, wx, wy, wz, dt):
    """Rolling torque of an active contact (after _store, only when its law has rolling resistance): the work
    1/2 (M_old + M) . w_rel dt enters the dissipation; its stored energy is in the elastic energy of _store."""
    out[k, 9] -= 0.5 * ((state[k, 7] + mx) * wx + (state[k, 8] + my) * wy + (state[k, 9] + mz) * wz) * dt
    state[k, 7] = mx
    state[k, 8] = my
    state[k, 9] = mz
    out[k, 10] = mx
    out[k, 11] = my
    out[k, 12] = mz


@njit(cache=True, inline="always")
def _open_roll(state, k, wx, wy, wz, dt):
    """Half-step work of the rolling torque of a contact that just opened (0 without rolling); call before _open."""
    if state.shape[1] <= 7:
        return 0.0
    return -0.5 * (state[k, 7] * wx + state[k, 8] * wy + state[k, 9] * wz) * dt


@njit(cache=True)
def _pairs(lo, hi, x, v, w, r, mdamp, mat, pi, pj, pstate, table, dt, pout):
    # two compiled copies of one loop: with the compact Hertz-Mindlin table the sub-model ids are constants and
    # their branches fold away (same arithmetic, so the same bits)
    if table.shape[2] == NLAW_HM:
        _pairs_loop(lo, hi, x, v, w, r, mdamp, mat, pi, pj, pstate, table, dt, pout, True)
    else:
        _pairs_loop(lo, hi, x, v, w, r, mdamp, mat, pi, pj, pstate, table, dt, pout, False)


@njit(cache=True, inline="always")
def _pairs_loop(lo, hi, x, v, w, r, mdamp, mat, pi, pj, pstate, table, dt, pout, hm):
    for k in items(lo, hi):
        i = unsigned(pi[k])
        j = unsigned(pj[k])
        dx = x[j, 0] - x[i, 0]
        dy = x[j, 1] - x[i, 1]
        dz = x[j, 2] - x[i, 2]
        d2 = dx * dx + dy * dy + dz * dz
        rs = r[i] + r[j]
        if d2 >= rs * rs and pstate[k, 3] == 0.0 and pstate[k, 4] == 0.0:
            for c in range(pout.shape[1]):
                pout[k, c] = 0.0
            continue
        dist = math.sqrt(d2)
        nx, ny, nz = dx / dist, dy / dist, dz / dist
        delta = rs - dist
        # lever arms to the contact point, a = R - delta/2 (LIGGGHTS `cri`, YADE ScGeom contact point)
        ai = r[i] - 0.5 * delta
        aj = r[j] - 0.5 * delta
        # contact-point velocity of i relative to j: v_i + w_i x (a_i n) - v_j - w_j x (-a_j n)
        vx = v[i, 0] - v[j, 0] + (w[i, 1] * nz - w[i, 2] * ny) * ai + (w[j, 1] * nz - w[j, 2] * ny) * aj
        vy = v[i, 1] - v[j, 1] + (w[i, 2] * nx - w[i, 0] * nz) * ai + (w[j, 2] * nx - w[j, 0] * nz) * aj
        vz = v[i, 2] - v[j, 2] + (w[i, 0] * ny - w[i, 1] * nx) * ai + (w[j, 0] * ny - w[j, 1] * nx) * aj
        wx = w[i, 0] - w[j, 0]
        wy = w[i, 1] - w[j, 1]
        wz = w[i, 2] - w[j, 2]
        if d2 >= rs * rs:
            droll = _open_roll(pstate, k, wx, wy, wz, dt)
            _open(pstate, pout, k, vx, vy, vz, dt)
            if droll != 0.0:
                pout[k, 9] += droll
            continue
        mi = mat[i]
        mj = mat[j]
        normal, kn, ktr, roll, mur, kroll = law_extra(table, mi, mj, hm)
        r0, r1, r2 = (pstate[k, 7], pstate[k, 8], pstate[k, 9]) if roll != 0.0 else (0.0, 0.0, 0.0)
        fx, fy, fz, fn, ft, eel, x0, x1, x2, mx, my, mz, m0, m1, m2 = contact_force(
            delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, r[i] * r[j] / rs, mdamp[i] * mdamp[j] / (mdamp[i] + mdamp[j]),
            table[mi, mj, 0], table[mi, mj, 1], table[mi, mj, 2], table[mi, mj, 3], table[mi, mj, 4],
            normal, kn, ktr, roll, mur, kroll, dt, pstate[k, 0], pstate[k, 1], pstate[k, 2], r0, r1, r2)
        _store(pstate, pout, k, fx, fy, fz, fn, ft, eel, x0, x1, x2, vx, vy, vz, nx, ny, nz, delta, dt)
        if roll != 0.0:
            _store_roll(pstate, pout, k, m0, m1, m2, wx, wy, wz, dt)


def pair_forces(S, C, P):
    """Pass 1: every sphere-sphere pair of the neighbour list (parallel over chunks of pairs)."""
    x, v, w, r, mdamp, mat = S.x, S.v, S.w, S.r, S.mdamp, S.mat
    pi, pj, pstate, pout = C.pi, C.pj, C.pstate, C.pout
    table, dt = P.table, P.dt
    n = pi.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        _pairs(c * CHUNK, min(n, (c + 1) * CHUNK), x, v, w, r, mdamp, mat, pi, pj, pstate, table, dt, pout)


@njit(cache=True)
def _gather(lo, hi, x, v, w, r, mass, mdamp, mat, body, gravity, offsets, jstart, jlist, pout,
            woff, wid, wstate, wout, wpoint, wnormal, wvel, wmat, table, dt, f, t, diss, track):
    """f, t := gravity + sum of pair forces/torques + plane contacts, for spheres lo..hi-1 (two compiled copies
    as _pairs)."""
    if table.shape[2] == NLAW_HM:
        _gather_loop(lo, hi, x, v, w, r, mass, mdamp, mat, body, gravity, offsets, jstart, jlist, pout,
                     woff, wid, wstate, wout, wpoint, wnormal, wvel, wmat, table, dt, f, t, diss, track, True)
    else:
        _gather_loop(lo, hi, x, v, w, r, mass, mdamp, mat, body, gravity, offsets, jstart, jlist, pout,
                     woff, wid, wstate, wout, wpoint, wnormal, wvel, wmat, table, dt, f, t, diss, track, False)


@njit(cache=True, inline="always")
def _gather_loop(lo, hi, x, v, w, r, mass, mdamp, mat, body, gravity, offsets, jstart, jlist, pout,
                 woff, wid, wstate, wout, wpoint, wnormal, wvel, wmat, table, dt, f, t, diss, track, hm):
    for i in items(lo, hi):
        nxt = i + unsigned(1)
        if body[i] < 0:
            fx = mass[i] * gravity[0]
            fy = mass[i] * gravity[1]
            fz = mass[i] * gravity[2]
        else:
            fx = 0.0                  # cluster members: gravity acts on the body
            fy = 0.0
            fz = 0.0
        tx = 0.0
        ty = 0.0
        tz = 0.0
        dd = 0.0
        ri = r[i]
        for k in items(offsets[i], offsets[nxt]):
            arm = ri - 0.5 * pout[k, 8]               # torque arm R - delta/2 (0 when not touching: c = 0)
            fx += pout[k, 0]
            fy += pout[k, 1]
            fz += pout[k, 2]
            tx += arm * pout[k, 3]
            ty += arm * pout[k, 4]
            tz += arm * pout[k, 5]
            if not hm and (pout[k, 10] != 0.0 or pout[k, 11] != 0.0 or pout[k, 12] != 0.0):   # rolling, on i
                tx += pout[k, 10]
                ty += pout[k, 11]
                tz += pout[k, 12]
            dd += pout[k, 9]
        for s in items(jstart[i], jstart[nxt]):
            k = unsigned(jlist[s])
            arm = ri - 0.5 * pout[k, 8]
            fx -= pout[k, 0]
            fy -= pout[k, 1]
            fz -= pout[k, 2]
            tx += arm * pout[k, 3]
            ty += arm * pout[k, 4]
            tz += arm * pout[k, 5]
            if not hm and (pout[k, 10] != 0.0 or pout[k, 11] != 0.0 or pout[k, 12] != 0.0):   # rolling, on j
                tx -= pout[k, 10]
                ty -= pout[k, 11]
                tz -= pout[k, 12]
        for s in items(woff[i], woff[nxt]):
            p = unsigned(wid[s])
            nwx, nwy, nwz = wnormal[p, 0], wnormal[p, 1], wnormal[p, 2]
            gap = ((x[i, 0] - wpoint[p, 0]) * nwx + (x[i, 1] - wpoint[p, 1]) * nwy
                   + (x[i, 2] - wpoint[p, 2]) * nwz)
            delta = ri - gap
            arm = ri - 0.5 * delta                            # LIGGGHTS wall `cr`
            nx, ny, nz = -nwx, -nwy, -nwz                     # from the sphere to the wall
            vx = v[i, 0] + (w[i, 1] * nz - w[i, 2] * ny) * arm - wvel[p, 0]
            vy = v[i, 1] + (w[i, 2] * nx - w[i, 0] * nz) * arm - wvel[p, 1]
            vz = v[i, 2] + (w[i, 0] * ny - w[i, 1] * nx) * arm - wvel[p, 2]
            if delta <= 0.0:
                droll = _open_roll(wstate, s, w[i, 0], w[i, 1], w[i, 2], dt)
                _open(wstate, wout, s, vx, vy, vz, dt)
                if droll != 0.0:
                    wout[s, 9] += droll
            else:
                mi = mat[i]
                mj = wmat[p]
                normal, kn, ktr, roll, mur, kroll = law_extra(table, mi, mj, hm)
                r0, r1, r2 = (wstate[s, 7], wstate[s, 8], wstate[s, 9]) if roll != 0.0 else (0.0, 0.0, 0.0)
                gx, gy, gz, fn, ft, eel, x0, x1, x2, mx, my, mz, m0, m1, m2 = contact_force(
                    delta, nx, ny, nz, vx, vy, vz, w[i, 0], w[i, 1], w[i, 2], ri, mdamp[i], table[mi, mj, 0],
                    table[mi, mj, 1], table[mi, mj, 2], table[mi, mj, 3], table[mi, mj, 4], normal, kn, ktr, roll,
                    mur, kroll, dt, wstate[s, 0], wstate[s, 1], wstate[s, 2], r0, r1, r2)
                _store(wstate, wout, s, gx, gy, gz, fn, ft, eel, x0, x1, x2, vx, vy, vz, nx, ny, nz, delta, dt)
                fx += gx
                fy += gy
                fz += gz
                tx += arm * wout[s, 3]
                ty += arm * wout[s, 4]
                tz += arm * wout[s, 5]
                if roll != 0.0:
                    _store_roll(wstate, wout, s, m0, m1, m2, w[i, 0], w[i, 1], w[i, 2], dt)
                    tx += mx
                    ty += my
                    tz += mz
            dd += wout[s, 9]
        f[i, 0] = fx
        f[i, 1] = fy
        f[i, 2] = fz
        t[i, 0] = tx
        t[i, 1] = ty
        t[i, 2] = tz
        if track:
            diss[i] += dd


def gather_pass(S, W, C, P, mode):
    """Pass 2 (parallel over chunks of spheres): f, t := gravity + pairs + plane contacts, then in the same chunk
    the kicks of `mode` (integrator.after_forces: 1 = second half kick, 2 = first half of the next step, 3 = both;
    0 = forces only). Returns the largest squared displacement of a free sphere since the last neighbour build."""
    x, v, w, q, f, t, r, mass, mdamp, mat, body = S
    offsets, jstart, jlist, pout, woff, wid, wstate, wout, x_ref = (C.offsets, C.jstart, C.jlist, C.pout, C.woff,
                                                                    C.wid, C.wstate, C.wout, C.x_ref)
    wpoint, wnormal, wvel, wmat = W.point, W.normal, W.vel, W.mat
    gravity, table, dt, diss, track, planar, dmax = P.gravity, P.table, P.dt, P.diss, P.track, P.planar, P.dmax
    n = x.shape[0]
    nch = (n + CHUNK - 1) // CHUNK
    for c in prange(nch):
        lo = c * CHUNK
        hi = min(n, (c + 1) * CHUNK)
        _gather(lo, hi, x, v, w, r, mass, mdamp, mat, body, gravity, offsets, jstart, jlist, pout,
                woff, wid, wstate, wout, wpoint, wnormal, wvel, wmat, table, dt, f, t, diss, track)
        dmax[c] = after_forces(lo, hi, x, v, w, q, f, t, mass, r, body, dt, planar, mode, x_ref)
    m = 0.0
    for c in range(nch):
        if dmax[c] > m:
            m = dmax[c]
    return m


@njit(cache=True)
def plane_power(W, C):
    """Sum over plane contacts of (last force on the sphere) . (plane velocity) [W]: the power the moving planes
    put into the spheres (per-contact last forces, so it is carried over neighbour rebuilds)."""
    wid, wstate, vel = C.wid, C.wstate, W.vel
    pw = 0.0
    for s in range(wid.shape[0]):
        p = wid[s]
        pw += wstate[s, 4] * vel[p, 0] + wstate[s, 5] * vel[p, 1] + wstate[s, 6] * vel[p, 2]
    return pw


@njit(cache=True)
def plane_candidates(x, r, wpoint, wnormal, skin, woff_out):
    """Planes within r + skin of each sphere, in sphere order (CSR offsets written to woff_out)."""
    n = x.shape[0]
    nw = wpoint.shape[0]
    cnt = 0
    for i in range(n):
        for p in range(nw):
            gap = ((x[i, 0] - wpoint[p, 0]) * wnormal[p, 0] + (x[i, 1] - wpoint[p, 1]) * wnormal[p, 1]
                   + (x[i, 2] - wpoint[p, 2]) * wnormal[p, 2])
            if gap < r[i] + skin:
                cnt += 1
    wid = np.empty(cnt, np.int32)
    cnt = 0
    woff_out[0] = 0
    for i in range(n):
        for p in range(nw):
            gap = ((x[i, 0] - wpoint[p, 0]) * wnormal[p, 0] + (x[i, 1] - wpoint[p, 1]) * wnormal[p, 1]
                   + (x[i, 2] - wpoint[p, 2]) * wnormal[p, 2])
            if gap < r[i] + skin:
                wid[cnt] = p
                cnt += 1
        woff_out[i + 1] = cnt
    return wid


@njit(cache=True)
def carry_wall_state(n, old_off, old_wid, new_off, new_wid, old_state, new_state):
    for i in range(n):
        for k in range(new_off[i], new_off[i + 1]):
            found = -1
            for s in range(old_off[i], old_off[i + 1]):
                if old_wid[s] == new_wid[k]:
                    found = s
                    break
            for c in range(new_state.shape[1]):
                new_state[k, c] = old_state[found, c] if found >= 0 else 0.0


pair_forces_ser, pair_forces_par = flavours(pair_forces)
gather_pass_ser, gather_pass_par = flavours(gather_pass)
