"""Velocity Verlet for free spheres (LIGGGHTS `nve/sphere`): half kick, drift, forces, half kick.

Rotation: omega is kicked like v with I = 2/5 m R^2 (isotropic, so no gyroscopic term); the orientation is
advanced by the exact rotation exp(1/2 omega dt) applied on the left of q (world-frame angular velocity).
2D scenes (planar = True) keep z, vz, wx, wy at zero: the constraint of LIGGGHTS fflag/tflag, YADE blockedDOFs.
Cluster members (body >= 0) are skipped here; coupler/dem/clusters.py integrates their bodies.
"""
from __future__ import annotations

import math

from numba import njit, prange

from coupler.dem.state import flavours
from coupler.loops import items


@njit(cache=True, inline="always")
def rotate_quaternion(q, i, wx, wy, wz, dt):
    """q[i] <- exp(1/2 w dt) (x) q[i], normalised; q = (w, x, y, z)."""
    wn = math.sqrt(wx * wx + wy * wy + wz * wz)
    if wn == 0.0:
        return
    half = 0.5 * wn * dt
    s = math.sin(half) / wn
    a0 = math.cos(half)
    a1 = wx * s
    a2 = wy * s
    a3 = wz * s
    q0, q1, q2, q3 = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
    r0 = a0 * q0 - a1 * q1 - a2 * q2 - a3 * q3
    r1 = a0 * q1 + a1 * q0 + a2 * q3 - a3 * q2
    r2 = a0 * q2 - a1 * q3 + a2 * q0 + a3 * q1
    r3 = a0 * q3 + a1 * q2 - a2 * q1 + a3 * q0
    nr = 1.0 / math.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    q[i, 0] = r0 * nr
    q[i, 1] = r1 * nr
    q[i, 2] = r2 * nr
    q[i, 3] = r3 * nr


@njit(cache=True)
def _kick(lo, hi, v, w, f, t, mass, r, body, dt, planar):
    h = 0.5 * dt
    for i in items(lo, hi):
        if body[i] < 0:
            im = 1.0 / mass[i]
            ii = 1.0 / (0.4 * mass[i] * r[i] * r[i])
            v[i, 0] += h * f[i, 0] * im
            v[i, 1] += h * f[i, 1] * im
            v[i, 2] += h * f[i, 2] * im
            w[i, 0] += h * t[i, 0] * ii
            w[i, 1] += h * t[i, 1] * ii
            w[i, 2] += h * t[i, 2] * ii
            if planar:
                v[i, 2] = 0.0
                w[i, 0] = 0.0
                w[i, 1] = 0.0


@njit(cache=True)
def _drift(lo, hi, x, v, w, q, body, dt):
    for i in items(lo, hi):
        if body[i] < 0:
            x[i, 0] += dt * v[i, 0]
            x[i, 1] += dt * v[i, 1]
            x[i, 2] += dt * v[i, 2]
            rotate_quaternion(q, i, w[i, 0], w[i, 1], w[i, 2], dt)


CHUNK = 256


@njit(cache=True, inline="always")
def after_forces(lo, hi, x, v, w, q, f, t, mass, r, body, dt, planar, mode, x_ref):
    """What velocity Verlet does to free spheres lo..hi-1 once their forces are known. mode bit 1: the second half
    kick of this step; bit 2: the first half (kick, drift) of the next step. Between two steps the passes are fused
    (per sphere the same operations in the same order as separate passes, so bitwise the same result). Returns the
    largest squared displacement since the last neighbour build of a free sphere that drifted (0 otherwise)."""
    if mode & 1:
        _kick(lo, hi, v, w, f, t, mass, r, body, dt, planar)
    m = 0.0
    if mode & 2:
        _kick(lo, hi, v, w, f, t, mass, r, body, dt, planar)
        _drift(lo, hi, x, v, w, q, body, dt)
        for i in items(lo, hi):
            if body[i] < 0:
                d = (x[i, 0] - x_ref[i, 0]) ** 2 + (x[i, 1] - x_ref[i, 1]) ** 2 + (x[i, 2] - x_ref[i, 2]) ** 2
                if d > m:
                    m = d
    return m


def kick_pass(S, C, P, mode):
    """after_forces over all spheres as one parallel pass (used when mesh forces come between the gather and the
    kick). Returns the largest squared displacement of a free sphere since the last build."""
    x, v, w, q, f, t, r, mass, mdamp, mat, body = S
    x_ref, dt, planar, dmax = C.x_ref, P.dt, P.planar, P.dmax
    n = x.shape[0]
    nch = (n + CHUNK - 1) // CHUNK
    for c in prange(nch):
        dmax[c] = after_forces(c * CHUNK, min(n, (c + 1) * CHUNK), x, v, w, q, f, t, mass, r, body, dt, planar,
                               mode, x_ref)
    m = 0.0
    for c in range(nch):
        if dmax[c] > m:
            m = dmax[c]
    return m


kick_pass_ser, kick_pass_par = flavours(kick_pass)
