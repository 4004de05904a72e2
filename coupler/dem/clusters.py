"""Rigid clusters of glued spheres (LIGGGHTS `multisphere`, YADE clumps).

Mass properties (template frame):
  * exact  : non-overlapping members, M = sum m_i, I = sum [2/5 m_i r_i^2 1 + m_i (|d|^2 1 - d d^T)]
  * voxel  : union of (possibly overlapping) members on a regular grid of `voxel_resolution` cells along the
             longest side; the stated error is the change against half that resolution
  * given  : mass, centre and inertia tensor from the scene
Bodies are integrated in their principal frame: world angular momentum L is kicked with the torque (half steps,
like velocity Verlet), the orientation is advanced by exp(1/2 w dt) with w = R I^-1 R^T L evaluated at the
mid-step orientation (implicit-midpoint rotation; Omelyan 1998 style), which keeps L exact for zero torque and the
energy error bounded. Planar scenes keep vz = Lx = Ly = 0: rotation about z with the world I_zz about the COM
(not the blockedDOFs pitfall of notes P6).
Member spheres follow the body: x = c + R d, v = v_c + w x (x - c), w_member = w.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from coupler.dem.integrator import rotate_quaternion
from coupler.dem.state import FREE
from coupler.errors import SceneError

if TYPE_CHECKING:        # a type only: the kernel cache is not keyed on the scene modules (coupler.kernel_sources)
    from coupler.dem.scene import ClusterTemplate


@dataclass
class MassProperties:
    mass: float
    center: np.ndarray        # COM in the template frame
    inertia: np.ndarray       # (3, 3) about the COM, template frame
    error: float = 0.0        # relative error estimate (voxel)

    def principal(self) -> tuple[np.ndarray, np.ndarray]:
        """Principal moments and the rotation R0 (columns = principal axes in the template frame, det +1)."""
        ev, vecs = np.linalg.eigh(self.inertia)
        if np.linalg.det(vecs) < 0:
            vecs[:, 0] *= -1.0
        return ev, vecs


def mass_properties(t: ClusterTemplate, density: float, path: str) -> MassProperties:
    d, r = t.offsets, t.radii
    if t.mass_properties == "given":
        return MassProperties(t.given_mass, np.asarray(t.given_center, float), np.asarray(t.given_inertia, float))
    if t.mass_properties == "exact":
        if len(r) > 1:
            from scipy.spatial.distance import pdist
            gap = pdist(d) - (r[:, None] + r[None, :])[np.triu_indices(len(r), 1)]
            if gap.min() < -1e-12 * r.max():
                raise SceneError(f"{path}.mass_properties", "members overlap: 'exact' is for non-overlapping spheres; "
                                                            "use 'voxel' or 'given'")
        m = density * 4.0 / 3.0 * math.pi * r ** 3
        M = float(m.sum())
        c = (m[:, None] * d).sum(0) / M
        rel = d - c
        inertia = np.zeros((3, 3))
        for mi, ri, x in zip(m, r, rel):
            inertia += 0.4 * mi * ri * ri * np.eye(3) + mi * (x @ x * np.eye(3) - np.outer(x, x))
        return MassProperties(M, c, inertia)
    full = _voxel(d, r, density, t.voxel_resolution)
    half = _voxel(d, r, density, max(4, t.voxel_resolution // 2))
    err = abs(full.mass - half.mass) / full.mass
    full.error = max(err, float(np.abs(full.inertia - half.inertia).max() / np.abs(full.inertia).max()))
    return full


def _voxel(d, r, density, n) -> MassProperties:
    lo, hi = (d - r[:, None]).min(0), (d + r[:, None]).max(0)
    h = float((hi - lo).max()) / n
    axes = [lo[k] + h * (np.arange(max(1, int(math.ceil((hi[k] - lo[k]) / h)))) + 0.5) for k in range(3)]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    inside = np.zeros(len(g), bool)
    for x, ri in zip(d, r):
        inside |= ((g - x) ** 2).sum(1) <= ri * ri
    p = g[inside]
    dm = density * h ** 3
    M = dm * len(p)
    c = p.mean(0)
    q = p - c
    inertia = dm * ((q * q).sum() * np.eye(3) - q.T @ q) + dm * h * h / 6.0 * np.eye(3) * len(p)
    return MassProperties(M, c, inertia)


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


# -- kernels ---------------------------------------------------------------------------------------------------

@njit(cache=True, inline="always")
def _rot(q, b, vx, vy, vz):
    """R(q[b]) v."""
    w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    return ((1 - 2 * (y * y + z * z)) * vx + 2 * (x * y - w * z) * vy + 2 * (x * z + w * y) * vz,
            2 * (x * y + w * z) * vx + (1 - 2 * (x * x + z * z)) * vy + 2 * (y * z - w * x) * vz,
            2 * (x * z - w * y) * vx + 2 * (y * z + w * x) * vy + (1 - 2 * (x * x + y * y)) * vz)


@njit(cache=True, inline="always")
def _rot_t(q, b, vx, vy, vz):
    """R(q[b])^T v."""
    w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    return ((1 - 2 * (y * y + z * z)) * vx + 2 * (x * y + w * z) * vy + 2 * (x * z - w * y) * vz,
            2 * (x * y - w * z) * vx + (1 - 2 * (x * x + z * z)) * vy + 2 * (y * z + w * x) * vz,
            2 * (x * z + w * y) * vx + 2 * (y * z - w * x) * vy + (1 - 2 * (x * x + y * y)) * vz)


@njit(cache=True)
def omega_from_L(q, L, Ip, w):
    """w = R I^-1 R^T L for every body."""
    for b in range(q.shape[0]):
        a0, a1, a2 = _rot_t(q, b, L[b, 0], L[b, 1], L[b, 2])
        w[b, 0], w[b, 1], w[b, 2] = _rot(q, b, a0 / Ip[b, 0], a1 / Ip[b, 1], a2 / Ip[b, 2])


@njit(cache=True)
def body_kick(B, dt, planar):
    """Half kick of every body: v += F/M dt/2, L += T dt/2. A body with prescribed motion (fixed / velocity, as
    LIGGGHTS fix move or YADE blockedDOFs) keeps v = vp and the angular momentum of w = wp at its orientation; the
    work the prescription does on it, -(F.vp + T.wp) dt/2 per half kick (trapezoid over the step), goes to B.work."""
    v, L, F, T, mass, q, Ip, motion, vp, wp = B.v, B.L, B.F, B.T, B.mass, B.q, B.Ip, B.motion, B.vp, B.wp
    h = 0.5 * dt
    for b in range(v.shape[0]):
        if motion[b] != FREE:
            B.work[b] -= h * (F[b, 0] * vp[b, 0] + F[b, 1] * vp[b, 1] + F[b, 2] * vp[b, 2]
                              + T[b, 0] * wp[b, 0] + T[b, 1] * wp[b, 1] + T[b, 2] * wp[b, 2])
            a0, a1, a2 = _rot_t(q, b, wp[b, 0], wp[b, 1], wp[b, 2])
            L[b, 0], L[b, 1], L[b, 2] = _rot(q, b, a0 * Ip[b, 0], a1 * Ip[b, 1], a2 * Ip[b, 2])
            for k in range(3):
                v[b, k] = vp[b, k]
        else:
            for k in range(3):
                v[b, k] += h * F[b, k] / mass[b]
                L[b, k] += h * T[b, k]
        if planar:
            v[b, 2] = 0.0
            L[b, 0] = 0.0
            L[b, 1] = 0.0


@njit(cache=True)
def body_spin(B):
    """w from L for every body (prescribed bodies: w = wp exactly)."""
    omega_from_L(B.q, B.L, B.Ip, B.w)
    for b in range(B.w.shape[0]):
        if B.motion[b] != FREE:
            for k in range(3):
                B.w[b, k] = B.wp[b, k]


@njit(cache=True)
def body_drift(B, dt):
    """c += dt v; q advanced with w at the mid-step orientation (two fixed-point passes); prescribed bodies turn
    with w = wp."""
    c, q, v, L, Ip, w, qtmp, wtmp = B.c, B.q, B.v, B.L, B.Ip, B.w, B.qtmp, B.wtmp
    for b in range(c.shape[0]):
        for k in range(3):
            c[b, k] += dt * v[b, k]
    omega_from_L(q, L, Ip, w)
    for _ in range(2):
        for b in range(q.shape[0]):
            for k in range(4):
                qtmp[b, k] = q[b, k]
            rotate_quaternion(qtmp, b, w[b, 0], w[b, 1], w[b, 2], 0.5 * dt)
        omega_from_L(qtmp, L, Ip, wtmp)
        for b in range(q.shape[0]):
            for k in range(3):
                w[b, k] = wtmp[b, k]
    for b in range(q.shape[0]):
        if B.motion[b] != FREE:
            for k in range(3):
                w[b, k] = B.wp[b, k]
        rotate_quaternion(q, b, w[b, 0], w[b, 1], w[b, 2], dt)


@njit(cache=True)
def member_disp_sq(member, x, x_ref):
    """Largest squared displacement of a cluster member since the last neighbour build."""
    m = 0.0
    for k in range(member.shape[0]):
        i = member[k]
        d = (x[i, 0] - x_ref[i, 0]) ** 2 + (x[i, 1] - x_ref[i, 1]) ** 2 + (x[i, 2] - x_ref[i, 2]) ** 2
        if d > m:
            m = d
    return m


@njit(cache=True)
def place_members(c, q, v, w, member, owner, offset, x, vs, ws):
    """Members follow their bodies: x = c + R d, v = v_c + w x (x - c), w_member = w."""
    for k in range(member.shape[0]):
        i = member[k]
        b = owner[k]
        rx, ry, rz = _rot(q, b, offset[k, 0], offset[k, 1], offset[k, 2])
        x[i, 0] = c[b, 0] + rx
        x[i, 1] = c[b, 1] + ry
        x[i, 2] = c[b, 2] + rz
        vs[i, 0] = v[b, 0] + w[b, 1] * rz - w[b, 2] * ry
        vs[i, 1] = v[b, 1] + w[b, 2] * rx - w[b, 0] * rz
        vs[i, 2] = v[b, 2] + w[b, 0] * ry - w[b, 1] * rx
        ws[i, 0] = w[b, 0]
        ws[i, 1] = w[b, 1]
        ws[i, 2] = w[b, 2]


@njit(cache=True)
def reduce_to_bodies(c, mass, gravity, member, owner, x, f, t, F, T):
    """F = M g + sum f_i, T = sum (x_i - c) x f_i + t_i, members in a fixed order (deterministic)."""
    for b in range(c.shape[0]):
        for k in range(3):
            F[b, k] = mass[b] * gravity[k]
            T[b, k] = 0.0
    for k in range(member.shape[0]):
        i = member[k]
        b = owner[k]
        rx, ry, rz = x[i, 0] - c[b, 0], x[i, 1] - c[b, 1], x[i, 2] - c[b, 2]
        F[b, 0] += f[i, 0]
        F[b, 1] += f[i, 1]
        F[b, 2] += f[i, 2]
        T[b, 0] += ry * f[i, 2] - rz * f[i, 1] + t[i, 0]
        T[b, 1] += rz * f[i, 0] - rx * f[i, 2] + t[i, 1]
        T[b, 2] += rx * f[i, 1] - ry * f[i, 0] + t[i, 2]


@dataclass
class Bodies:
    """Rigid-body state (struct of arrays) and the member map."""
    names: list[str]
    c: np.ndarray          # COM
    q: np.ndarray          # orientation of the principal frame (w, x, y, z)
    q_ref: np.ndarray      # principal frame in the template frame: reported q = q (x) q_ref^-1
    v: np.ndarray
    L: np.ndarray          # world angular momentum
    w: np.ndarray
    mass: np.ndarray
    Ip: np.ndarray         # principal moments
    F: np.ndarray
    T: np.ndarray
    member: np.ndarray     # sphere index of each member
    owner: np.ndarray      # body index of each member
    offset: np.ndarray     # member centre in the principal frame
    mass_error: np.ndarray

    def kinetic(self) -> float:
        return 0.5 * float(np.sum(self.mass * (self.v ** 2).sum(1)) + np.sum((self.w * self.L).sum(1)))

    def reported_q(self) -> np.ndarray:
        out = np.empty_like(self.q)
        for b in range(len(self.q)):
            r = self.q_ref[b] * np.array([1.0, -1.0, -1.0, -1.0])
            out[b] = quat_mul(self.q[b], r)
        return out
