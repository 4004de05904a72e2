"""Mesh walls: triangles (3D) or segments (2D) with movable nodes; sphere-mesh contacts and node forces.

Contact detection per sphere: the closest point of every candidate face, classified as face interior, edge or
vertex. Resolution (the double hierarchy of Santasusana et al. 2016, Powder Technol. 300): a face contact
dominates the edges and vertices of that face, an edge contact the vertices of that edge, and one edge or vertex
reached from several faces counts once. A sphere crossing a shared edge of a flat mesh therefore always feels one
contact, with the same normal, and its tangential history is carried between features by matching contact normals
(up to 4 contact slots per sphere and mesh). The wall velocity at the contact point is the barycentric interpolation
of the node velocities, and each contact force is returned to the nodes with the same barycentric weights, so the
node forces sum to the contact forces (to round-off).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from coupler.dem.contact import NLAW_HM, contact_force, law_extra
from coupler.dem.state import clone, flavours

KSLOT = 4
NFEAT = 64                # touching features per sphere and mesh examined per step (more: counted in drops)
# slot row: n(3), xi(3), elastic energy, last force(3), active flag, rolling torque on the sphere(3)
SLOT = 14


@dataclass
class Mesh:
    name: str
    mat: int
    x: np.ndarray            # (nv, 3) node positions
    v: np.ndarray            # (nv, 3) node velocities
    faces: np.ndarray        # (nf, 3) triangles or (nf, 2) segments
    face_edges: np.ndarray   # (nf, 3) edge ids of a triangle (segments: unused)
    node_force: np.ndarray   # (nv, 3) force exerted by the spheres on the nodes (last step)
    slots: np.ndarray        # (n_spheres, KSLOT, SLOT)


def build_mesh(name: str, mat: int, vertices: np.ndarray, faces: np.ndarray, velocity: np.ndarray,
               n_spheres: int) -> Mesh:
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if faces.shape[1] == 3:
        edges: dict[tuple[int, int], int] = {}
        fe = np.zeros((len(faces), 3), np.int64)
        for f, tri in enumerate(faces):
            for k in range(3):
                a, b = sorted((int(tri[k]), int(tri[(k + 1) % 3])))
                fe[f, k] = edges.setdefault((a, b), len(edges))
    else:
        fe = np.zeros((len(faces), 3), np.int64)
    nv = len(vertices)
    # + 0.0: a -0.0 coordinate read as +0.0 (a static mesh's nodes are never drifted by x += 0 dt, which did that)
    return Mesh(name, mat, np.array(vertices, float) + 0.0, np.tile(np.asarray(velocity, float), (nv, 1)), faces, fe,
                np.zeros((nv, 3)), np.zeros((n_spheres, KSLOT, SLOT)))


@njit(cache=True, inline="always")
def closest_triangle(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """Closest point of triangle abc to p (Ericson 2005, 5.1.5), on scalars (no array per call: the mesh pass
    examines every candidate face every step). Returns (q0, q1, q2, feature, local id, bary weights): feature 0
    face, 1 edge (local id 0: ab, 1: bc, 2: ca), 2 vertex (local id 0: a, 1: b, 2: c). Dot products summed
    x + y + z, as numpy's 3-vector dot (the same bits as the array version this replaced)."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    ap0, ap1, ap2 = p0 - a0, p1 - a1, p2 - a2
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    if d1 <= 0.0 and d2 <= 0.0:
        return a0, a1, a2, 2, 0, 1.0, 0.0, 0.0
    bp0, bp1, bp2 = p0 - b0, p1 - b1, p2 - b2
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    if d3 >= 0.0 and d4 <= d3:
        return b0, b1, b2, 2, 1, 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a0 + v * ab0, a1 + v * ab1, a2 + v * ab2, 1, 0, 1.0 - v, v, 0.0
    cp0, cp1, cp2 = p0 - c0, p1 - c1, p2 - c2
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    if d6 >= 0.0 and d5 <= d6:
        return c0, c1, c2, 2, 2, 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a0 + w * ac0, a1 + w * ac1, a2 + w * ac2, 1, 2, 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b0 + w * (c0 - b0), b1 + w * (c1 - b1), b2 + w * (c2 - b2), 1, 1, 0.0, 1.0 - w, w
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return (a0 + ab0 * v + ac0 * w, a1 + ab1 * v + ac1 * w, a2 + ab2 * v + ac2 * w, 0, 0, 1.0 - v - w, v, w)


@njit(cache=True, inline="always")
def closest_segment(p0, p1, p2, a0, a1, a2, b0, b1, b2):
    """Closest point of segment ab to p, on scalars, as closest_triangle: (q0, q1, q2, feature, local id, bary)."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    t = ((p0 - a0) * ab0 + (p1 - a1) * ab1 + (p2 - a2) * ab2) / (ab0 * ab0 + ab1 * ab1 + ab2 * ab2)
    if t <= 0.0:
        return a0, a1, a2, 2, 0, 1.0, 0.0, 0.0
    if t >= 1.0:
        return b0, b1, b2, 2, 1, 0.0, 1.0, 0.0
    return a0 + t * ab0, a1 + t * ab1, a2 + t * ab2, 0, 0, 1.0 - t, t, 0.0


@njit(cache=True)
def face_distances(p, v):
    """Distance of point p[k] from face v[k] (v: (n, 2, 3) segments or (n, 3, 3) triangles) by the closest points the
    mesh pass uses (coupler/dem/scene.py checks the overlaps at t = 0 with it)."""
    d = np.empty(p.shape[0])
    for k in range(p.shape[0]):
        if v.shape[1] == 3:
            q0, q1, q2, _, _, _, _, _ = closest_triangle(p[k, 0], p[k, 1], p[k, 2], v[k, 0, 0], v[k, 0, 1], v[k, 0, 2],
                                                         v[k, 1, 0], v[k, 1, 1], v[k, 1, 2], v[k, 2, 0], v[k, 2, 1],
                                                         v[k, 2, 2])
        else:
            q0, q1, q2, _, _, _, _, _ = closest_segment(p[k, 0], p[k, 1], p[k, 2], v[k, 0, 0], v[k, 0, 1], v[k, 0, 2],
                                                        v[k, 1, 0], v[k, 1, 1], v[k, 1, 2])
        d[k] = math.sqrt((p[k, 0] - q0) ** 2 + (p[k, 1] - q1) ** 2 + (p[k, 2] - q2) ** 2)
    return d


@njit(cache=True)
def _closest_triangle(p, a, b, c):
    """closest_triangle on 3-vectors (tests): (point array, feature, local id, bary weights)."""
    q0, q1, q2, ft, loc, w0, w1, w2 = closest_triangle(p[0], p[1], p[2], a[0], a[1], a[2], b[0], b[1], b[2],
                                                       c[0], c[1], c[2])
    return np.array([q0, q1, q2]), ft, loc, w0, w1, w2


@njit(cache=True)
def _sphere_contacts(lo, hi, x, v, w, r, mdamp, mat, mesh_mat, mx, mv, faces, face_edges, cand_off, cand, slots, table,
                     dt, f, t, diss, track, ncon, rec, recf, drops):
    """Contacts of spheres lo..hi-1 with one mesh: features, hierarchy, history slots, the force law, the sphere's
    force, torque and dissipation. Each applied contact is recorded (face, barycentric weights, force on the sphere,
    fn, ft, overlap) in the row cand_off[i] + j of rec / recf (the j-th of sphere i: at most one per candidate face),
    their count in ncon[i]; drops[0], drops[1] count what this chunk could not handle (mesh_forces)."""
    nv_face = faces.shape[1]
    nmax = NFEAT
    feat_type = np.empty(nmax, np.int64)
    feat_key = np.empty(nmax, np.int64)
    face_of = np.empty(nmax, np.int64)
    pts = np.empty((nmax, 3))
    bary = np.empty((nmax, 3))
    keep = np.empty(nmax, np.bool_)
    used = np.empty(KSLOT, np.bool_)
    for i in range(lo, hi):
        ncon[i] = 0
        c0, c1 = cand_off[i], cand_off[i + 1]
        if c1 == c0:
            continue
        p0, p1, p2 = x[i, 0], x[i, 1], x[i, 2]
        m = 0
        for s in range(c0, c1):
            fc = cand[s]
            na, nb = faces[fc, 0], faces[fc, 1]
            if nv_face == 3:
                nc = faces[fc, 2]
                q0, q1, q2, ft_, loc, b0, b1, b2 = closest_triangle(
                    p0, p1, p2, mx[na, 0], mx[na, 1], mx[na, 2], mx[nb, 0], mx[nb, 1], mx[nb, 2],
                    mx[nc, 0], mx[nc, 1], mx[nc, 2])
            else:
                q0, q1, q2, ft_, loc, b0, b1, b2 = closest_segment(
                    p0, p1, p2, mx[na, 0], mx[na, 1], mx[na, 2], mx[nb, 0], mx[nb, 1], mx[nb, 2])
            dx, dy, dz = p0 - q0, p1 - q1, p2 - q2
            if dx * dx + dy * dy + dz * dz >= r[i] * r[i]:
                continue
            if m >= nmax:
                drops[0] += 1
                continue
            feat_type[m] = ft_
            if ft_ == 0:
                feat_key[m] = fc
            elif ft_ == 1:
                feat_key[m] = face_edges[fc, loc]
            else:
                feat_key[m] = faces[fc, loc]
            face_of[m] = fc
            pts[m, 0], pts[m, 1], pts[m, 2] = q0, q1, q2
            bary[m, 0], bary[m, 1], bary[m, 2] = b0, b1, b2
            keep[m] = True
            m += 1
        # hierarchy: faces dominate their edges and vertices, edges their vertices; one feature counts once
        for a in range(m):
            if feat_type[a] == 0:
                continue
            for b in range(m):
                if b == a or not keep[b]:
                    continue
                if feat_type[b] < feat_type[a] and _shares(faces, face_edges, face_of[b], feat_type[b], feat_key[b],
                                                           feat_type[a], feat_key[a]):
                    keep[a] = False
                    break
                if feat_type[b] == feat_type[a] and feat_key[b] == feat_key[a] and b < a:
                    keep[a] = False
                    break
        # slots: match by normal, carry history
        used[:] = False
        napp = 0
        for a in range(m):
            if not keep[a]:
                continue
            dx, dy, dz = p0 - pts[a, 0], p1 - pts[a, 1], p2 - pts[a, 2]
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            nx, ny, nz = -dx / dist, -dy / dist, -dz / dist      # sphere -> wall
            best, bdot = -1, 0.95
            for k in range(KSLOT):
                if slots[i, k, 10] != 0.0 and not used[k]:
                    dd = slots[i, k, 0] * nx + slots[i, k, 1] * ny + slots[i, k, 2] * nz
                    if dd > bdot:
                        best, bdot = k, dd
            if best < 0:
                for k in range(KSLOT):
                    if slots[i, k, 10] == 0.0 and not used[k]:
                        best = k
                        for c in range(SLOT):
                            slots[i, k, c] = 0.0
                        break
            if best < 0:
                drops[1] += 1
                continue
            used[best] = True
            delta = r[i] - dist
            arm = r[i] - 0.5 * delta
            wvx, wvy, wvz = 0.0, 0.0, 0.0
            for c in range(nv_face):
                node = faces[face_of[a], c]
                wvx += bary[a, c] * mv[node, 0]
                wvy += bary[a, c] * mv[node, 1]
                wvz += bary[a, c] * mv[node, 2]
            vx = v[i, 0] + (w[i, 1] * nz - w[i, 2] * ny) * arm - wvx
            vy = v[i, 1] + (w[i, 2] * nx - w[i, 0] * nz) * arm - wvy
            vz = v[i, 2] + (w[i, 0] * ny - w[i, 1] * nx) * arm - wvz
            mi, mj = mat[i], mesh_mat
            normal, kn, ktr, roll, mur, kroll = law_extra(table, mi, mj, table.shape[2] == NLAW_HM)
            gx, gy, gz, fn, ftm, eel, x0, x1, x2, tmx, tmy, tmz, m0, m1, m2 = contact_force(
                delta, nx, ny, nz, vx, vy, vz, w[i, 0], w[i, 1], w[i, 2], r[i], mdamp[i], table[mi, mj, 0],
                table[mi, mj, 1], table[mi, mj, 2], table[mi, mj, 3], table[mi, mj, 4], normal, kn, ktr, roll, mur,
                kroll, dt, slots[i, best, 3], slots[i, best, 4], slots[i, best, 5], slots[i, best, 11], slots[i, best, 12],
                slots[i, best, 13])
            work = 0.5 * ((slots[i, best, 7] + gx) * vx + (slots[i, best, 8] + gy) * vy
                          + (slots[i, best, 9] + gz) * vz) * dt
            if roll != 0.0:               # rolling torque (mesh nodes carry no torque: the wall does not spin)
                work += 0.5 * ((slots[i, best, 11] + tmx) * w[i, 0] + (slots[i, best, 12] + tmy) * w[i, 1]
                               + (slots[i, best, 13] + tmz) * w[i, 2]) * dt
                slots[i, best, 11], slots[i, best, 12], slots[i, best, 13] = m0, m1, m2
                t[i, 0] += tmx
                t[i, 1] += tmy
                t[i, 2] += tmz
            if track:
                diss[i] += -work - (eel - slots[i, best, 6])
            slots[i, best, 0], slots[i, best, 1], slots[i, best, 2] = nx, ny, nz
            slots[i, best, 3], slots[i, best, 4], slots[i, best, 5] = x0, x1, x2
            slots[i, best, 6] = eel
            slots[i, best, 7], slots[i, best, 8], slots[i, best, 9] = gx, gy, gz
            f[i, 0] += gx
            f[i, 1] += gy
            f[i, 2] += gz
            t[i, 0] += arm * (ny * gz - nz * gy)
            t[i, 1] += arm * (nz * gx - nx * gz)
            t[i, 2] += arm * (nx * gy - ny * gx)
            row = c0 + napp               # this sphere's j-th applied contact: a row of its candidate range
            recf[row] = face_of[a]
            rec[row, 0], rec[row, 1], rec[row, 2] = bary[a, 0], bary[a, 1], bary[a, 2]
            rec[row, 3], rec[row, 4], rec[row, 5] = gx, gy, gz
            rec[row, 6], rec[row, 7], rec[row, 8] = fn, ftm, delta
            napp += 1
        ncon[i] = napp
        for k in range(KSLOT):            # contacts that ended release their stored energy account
            if slots[i, k, 10] != 0.0 and not used[k]:
                if track:
                    diss[i] += slots[i, k, 6]
                    if slots[i, k, 11] != 0.0 or slots[i, k, 12] != 0.0 or slots[i, k, 13] != 0.0:
                        diss[i] -= 0.5 * (slots[i, k, 11] * w[i, 0] + slots[i, k, 12] * w[i, 1]
                                          + slots[i, k, 13] * w[i, 2]) * dt
                for c in range(SLOT):
                    slots[i, k, c] = 0.0
            elif used[k]:
                slots[i, k, 10] = 1.0


MCHUNKS = 32              # chunks of the parallel contact pass (each allocates its feature buffers once)
QCHUNKS = 32              # chunks of the parallel candidate search


@njit(cache=True)
def equal_work_bounds(cum, nch):
    """nch + 1 sphere indices splitting spheres 0..n-1 into nch runs of about equal work, cum (n + 1) being the
    work's running sum (a plain function: an allocation inside a parallel one is one more parallel region)."""
    n = cum.shape[0] - 1
    nch = min(nch, n)
    bounds = np.empty(nch + 1, np.int64)
    for c in range(nch):
        bounds[c] = np.searchsorted(cum[:n], (cum[n] * c) // nch)
    bounds[nch] = n
    return bounds


@njit(cache=True)
def _chunks(cand_off):
    """Chunk bounds of about equal candidate counts (MCHUNKS chunks) and per-chunk drop counters."""
    bounds = equal_work_bounds(cand_off, MCHUNKS)
    return bounds, np.zeros((bounds.shape[0] - 1, 2), np.int64)


def mesh_forces(x, v, w, r, mdamp, mat, mesh_mat, mx, mv, faces, face_edges, cand_off, cand, slots, table, dt,
                f, t, nodes, diss, track, out, drops, ncon, rec, recf):
    """Add sphere-mesh contact forces to f, t; node forces to nodes = (node_force, touched, ntouched, mark); out
    rows per active contact: sphere, fx, fy, fz, fn, ft, overlap (first `nout` rows valid; returned). The contacts
    are computed in parallel over chunks of spheres (each sphere's force, torque, slots written by one thread),
    then the node forces and rows are summed in sphere order in one serial pass, so the result is the same bits for
    any thread count (the chunks only decide which thread computes a sphere). Only the nodes of the last pass
    (touched[:ntouched[0]]) are non-zero: they are zeroed, and this pass lists its own, so the cost follows the
    contacts, not the mesh size. Nothing is dropped silently: drops counts (cumulative, per sphere and call) [0]
    touching features beyond the per-sphere buffer of NFEAT, [1] kept contacts beyond the KSLOT history slots (their
    force is not applied), [2] contact rows beyond `out`.
    ncon, rec, recf: the per-sphere contact records (_sphere_contacts)."""
    node_force, touched, ntouched, mark = nodes
    nv_face = faces.shape[1]
    for s in range(ntouched[0]):
        node = touched[s]
        node_force[node, 0] = 0.0
        node_force[node, 1] = 0.0
        node_force[node, 2] = 0.0
        mark[node] = False
    ntouched[0] = 0
    n = x.shape[0]
    # chunks of consecutive spheres holding about equal numbers of candidate faces (the spheres near a wall can
    # be one end of the numbering: equal sphere counts left one thread with most of the work)
    bounds, cdrops = _chunks(cand_off)
    nch = bounds.shape[0] - 1
    for c in prange(nch):
        _sphere_contacts(bounds[c], bounds[c + 1], x, v, w, r, mdamp, mat, mesh_mat, mx, mv, faces, face_edges,
                         cand_off, cand, slots, table, dt, f, t, diss, track, ncon, rec, recf, cdrops[c])
    for c in range(nch):
        drops[0] += cdrops[c, 0]
        drops[1] += cdrops[c, 1]
    nout = 0
    for i in range(n):                     # node forces and contact rows in sphere order: a fixed sum order
        c0 = cand_off[i]
        for s in range(c0, c0 + ncon[i]):
            fc = recf[s]
            gx, gy, gz = rec[s, 3], rec[s, 4], rec[s, 5]
            for c in range(nv_face):
                node = faces[fc, c]
                if not mark[node]:
                    mark[node] = True
                    touched[ntouched[0]] = node
                    ntouched[0] += 1
                node_force[node, 0] -= rec[s, c] * gx
                node_force[node, 1] -= rec[s, c] * gy
                node_force[node, 2] -= rec[s, c] * gz
            if nout < out.shape[0]:
                out[nout, 0] = i
                out[nout, 1], out[nout, 2], out[nout, 3] = gx, gy, gz
                out[nout, 4], out[nout, 5], out[nout, 6] = rec[s, 6], rec[s, 7], rec[s, 8]
                nout += 1
            else:
                drops[2] += 1
    return nout


@njit(cache=True)
def _shares(faces, face_edges, face_b, type_b, key_b, type_a, key_a):
    """Does feature b (a face or an edge) contain the lower-dimensional feature a (an edge or a vertex)?"""
    if type_b == 0:
        if type_a == 1:
            for k in range(3):
                if face_edges[face_b, k] == key_a:
                    return True
            return False
        for k in range(faces.shape[1]):
            if faces[face_b, k] == key_a:
                return True
        return False
    # b is an edge of face_b: find its two vertices
    for k in range(3):
        if face_edges[face_b, k] == key_b:
            return faces[face_b, k] == key_a or faces[face_b, (k + 1) % 3] == key_a
    return False


def candidates_reference(x: np.ndarray, r: np.ndarray, mesh: Mesh, skin: float) -> tuple[np.ndarray, np.ndarray]:
    """Plain O(N faces) statement of the candidate rule (tests compare `candidates` against it): the faces within
    r + skin of the sphere centre (nearer than that at a build, no face can touch the sphere before the next one:
    spheres and nodes together move less than skin / 2 in between), ascending ids."""
    off = np.zeros(len(x) + 1, np.int64)
    lists = []
    for i in range(len(x)):
        reach = r[i] + skin
        sel = [fc for fc in range(len(mesh.faces))
               if face_distance_sq(x[i, 0], x[i, 1], x[i, 2], mesh.x, mesh.faces, fc) < reach * reach]
        lists.append(np.array(sel, np.int64))
        off[i + 1] = off[i] + len(sel)
    return off, (np.concatenate(lists).astype(np.int64) if lists else np.zeros(0, np.int64))


def candidates(x: np.ndarray, r: np.ndarray, mesh: Mesh, skin: float) -> tuple[np.ndarray, np.ndarray]:
    """Faces within r + skin of the sphere centre (CSR by sphere, ascending face ids)."""
    return candidates_binned(x, r, mesh.x, mesh.faces, skin)


@njit(cache=True)
def candidates_binned(x, r, mx, faces, skin):
    """Compiled candidate search: the face boxes, grown by max(r) + skin, are binned on a uniform grid; a sphere
    tests the faces of the one cell holding its centre against its own reach r + skin, box first, then distance
    (the rule of candidates_reference, faces in ascending order). Cost O(N + faces x cells per face)."""
    return query_faces_ser(x, r, skin, bin_faces(mx, faces, max_reach(r, skin), x.shape[0]), mx, faces)


@njit(cache=True)
def max_reach(r, skin):
    reach = skin
    for i in range(r.shape[0]):
        reach = max(reach, r[i] + skin)
    return reach


@njit(cache=True)
def bin_faces(mx, faces, reach, n):
    """The face boxes (lo, hi) and their grid (origin glo, extent ghi, 1/h, cells nc, CSR cstart / items: ascending
    face ids per cell) for n spheres of reach <= `reach`. It depends on the nodes, not on the spheres' positions, so
    a static mesh keeps it between neighbour builds (solver._mesh_candidates)."""
    nf = faces.shape[0]
    kv = faces.shape[1]
    lo = np.empty((nf, 3))
    hi = np.empty((nf, 3))
    for fc in range(nf):
        for c in range(3):
            a = mx[faces[fc, 0], c]
            b = a
            for k in range(1, kv):
                u = mx[faces[fc, k], c]
                a = min(a, u)
                b = max(b, u)
            lo[fc, c] = a
            hi[fc, c] = b
    glo = np.zeros(3)
    ghi = np.zeros(3)
    nc = np.ones(3, np.int64)
    if n == 0 or nf == 0:
        return lo, hi, glo, ghi, 1.0, nc, np.zeros(2, np.int64), np.zeros(0, np.int64)
    for c in range(3):
        glo[c] = lo[:, c].min() - reach
        ghi[c] = hi[:, c].max() + reach
    size = 0.0
    for fc in range(nf):
        e = 0.0
        for c in range(3):
            e = max(e, hi[fc, c] - lo[fc, c])
        size += e
    h = max(size / nf, 2.0 * reach)
    while True:
        for c in range(3):
            nc[c] = max(1, int(math.ceil((ghi[c] - glo[c]) / h)))
        if nc[0] * nc[1] * nc[2] <= 4 * (n + nf) + 64:
            break
        h *= 1.5
    inv_h = 1.0 / h
    ncell = nc[0] * nc[1] * nc[2]
    cstart = np.zeros(ncell + 1, np.int64)
    lo_c = np.empty((nf, 3), np.int64)
    hi_c = np.empty((nf, 3), np.int64)
    for fc in range(nf):
        for c in range(3):
            lo_c[fc, c] = min(max(int((lo[fc, c] - reach - glo[c]) * inv_h), 0), nc[c] - 1)
            hi_c[fc, c] = min(max(int((hi[fc, c] + reach - glo[c]) * inv_h), 0), nc[c] - 1)
        for a in range(lo_c[fc, 0], hi_c[fc, 0] + 1):
            for b in range(lo_c[fc, 1], hi_c[fc, 1] + 1):
                for e in range(lo_c[fc, 2], hi_c[fc, 2] + 1):
                    cstart[(a * nc[1] + b) * nc[2] + e + 1] += 1
    for k in range(ncell):
        cstart[k + 1] += cstart[k]
    fill = cstart[:-1].copy()
    items = np.empty(cstart[ncell], np.int64)
    for fc in range(nf):                      # ascending face ids inside every cell
        for a in range(lo_c[fc, 0], hi_c[fc, 0] + 1):
            for b in range(lo_c[fc, 1], hi_c[fc, 1] + 1):
                for e in range(lo_c[fc, 2], hi_c[fc, 2] + 1):
                    cell = (a * nc[1] + b) * nc[2] + e
                    items[fill[cell]] = fc
                    fill[cell] += 1
    return lo, hi, glo, ghi, inv_h, nc, cstart, items


@njit(cache=True, inline="always")
def face_distance_sq(p0, p1, p2, mx, faces, fc):
    """Squared distance from a point to face fc (its closest point: the contact pass's own computation)."""
    na, nb = faces[fc, 0], faces[fc, 1]
    if faces.shape[1] == 3:
        nc = faces[fc, 2]
        q0, q1, q2, _, _, _, _, _ = closest_triangle(p0, p1, p2, mx[na, 0], mx[na, 1], mx[na, 2], mx[nb, 0], mx[nb, 1],
                                                     mx[nb, 2], mx[nc, 0], mx[nc, 1], mx[nc, 2])
    else:
        q0, q1, q2, _, _, _, _, _ = closest_segment(p0, p1, p2, mx[na, 0], mx[na, 1], mx[na, 2], mx[nb, 0], mx[nb, 1],
                                                    mx[nb, 2])
    return (p0 - q0) ** 2 + (p1 - q1) ** 2 + (p2 - q2) ** 2


@njit(cache=True)
def _sphere_cells(x, r, bins):
    """Per sphere: the grid cell holding its centre (-1: outside the grid), and chunk bounds (QCHUNKS + 1 sphere
    indices) of about equal numbers of faces to test (the faces binned in those cells)."""
    lo, hi, glo, ghi, inv_h, nc, cstart, items = bins
    n = x.shape[0]
    cell_of = np.full(n, -1, np.int64)
    work = np.zeros(n + 1, np.int64)
    for i in range(n):
        inside = True
        cell = 0
        for c in range(3):
            if not (x[i, c] >= glo[c] and x[i, c] <= ghi[c]):
                inside = False
                break
            cell = cell * nc[c] + min(int((x[i, c] - glo[c]) * inv_h), nc[c] - 1)
        work[i + 1] = work[i]
        if inside:
            cell_of[i] = cell
            work[i + 1] += cstart[cell + 1] - cstart[cell]
    return cell_of, equal_work_bounds(work, QCHUNKS)


def query_faces(x, r, skin, bins, mx, faces):
    """Candidate faces per sphere (CSR off, cand; ascending face ids): the faces binned in the cell of its centre
    whose bounding box grown by r + skin holds the centre (the cheap test) and whose distance to it is below
    r + skin (mx, faces: the nodes and faces the bins were built from). Parallel over chunks of spheres, each
    sphere writing its own rows, so the lists are the same for any thread count."""
    lo, hi, glo, ghi, inv_h, nc, cstart, items = bins
    n = x.shape[0]
    off = np.zeros(n + 1, np.int64)
    if n == 0 or lo.shape[0] == 0:
        return off, np.zeros(0, np.int64)
    cell_of, bounds = _sphere_cells(x, r, bins)
    nch = bounds.shape[0] - 1
    cand = np.empty(0, np.int64)
    for sweep in range(2):                    # count, then fill
        if sweep == 1:
            for i in range(n):
                off[i + 1] += off[i]
            cand = np.empty(off[n], np.int64)
        for ch in prange(nch):
            for i in range(bounds[ch], bounds[ch + 1]):
                cell = cell_of[i]
                if cell < 0:
                    continue
                rr = r[i] + skin
                k = 0
                for s in range(cstart[cell], cstart[cell + 1]):
                    fc = items[s]
                    ok = True
                    for c in range(3):
                        if not (x[i, c] >= lo[fc, c] - rr and x[i, c] <= hi[fc, c] + rr):
                            ok = False
                            break
                    if ok and face_distance_sq(x[i, 0], x[i, 1], x[i, 2], mx, faces, fc) < rr * rr:
                        if sweep == 1:
                            cand[off[i] + k] = fc
                        k += 1
                if sweep == 0:
                    off[i + 1] = k
    return off, cand


@njit(cache=True)
def mesh_motion(M):
    """M.moving[k]: does mesh k move during the coming steps (a node velocity not zero, or a node away from its
    position at the last neighbour build, as after a jump by set_mesh_nodes)? A static mesh skips the per-node
    loops of a step: its nodes would drift by exactly 0, and its force power is exactly 0."""
    for k in range(M.mat.shape[0]):
        n0, n1 = M.noff[k], M.noff[k + 1]
        v, x, xr = M.v[n0:n1].ravel(), M.x[n0:n1].ravel(), M.x_ref[n0:n1].ravel()
        moving = 0
        for a in range(v.shape[0]):               # no early exit: the loop vectorises (~35 us per 50k nodes)
            moving |= (v[a] != 0.0) | (x[a] != xr[a])
        M.moving[k] = moving != 0


def mesh_pass(S, M, P, step):
    """Contacts of the spheres with every mesh wall (after the gather, meshes in scene order). With step = True
    also the bookkeeping of a time step: node force sum for the time average (M.node_acc, over the touched nodes:
    the others add exactly 0) and the work of the spheres on the moving nodes, 1/2 (F_old + F_new) . v_node dt
    (M.work; a static mesh does none)."""
    dt = P.dt
    for k in range(M.mat.shape[0]):
        n0, n1 = M.noff[k], M.noff[k + 1]
        f0, f1 = M.foff[k], M.foff[k + 1]
        mv = M.v[n0:n1]
        node_force = M.node_force[n0:n1]
        touched = M.touched[n0:n1]
        moving = step and M.moving[k]
        p_old = 0.0
        if moving:
            for a in range(n1 - n0):
                p_old += node_force[a, 0] * mv[a, 0] + node_force[a, 1] * mv[a, 1] + node_force[a, 2] * mv[a, 2]
        M.nout[k] = mesh_forces(S.x, S.v, S.w, S.r, S.mdamp, S.mat, M.mat[k], M.x[n0:n1], mv, M.faces[f0:f1],
                                M.face_edges[f0:f1], M.cand_off[k], M.cand[M.cbase[k]:M.cbase[k + 1]], M.slots[k],
                                P.table, dt, S.f, S.t, (node_force, touched, M.ntouched[k:k + 1], M.mark[n0:n1]),
                                P.diss, P.track, M.out[k], M.drops[k], M.ncon[k], M.rec[M.cbase[k]:M.cbase[k + 1]],
                                M.recf[M.cbase[k]:M.cbase[k + 1]])
        if step:
            for s in range(M.ntouched[k]):
                a = touched[s]
                for c in range(3):
                    M.node_acc[n0 + a, c] += node_force[a, c]
        if moving:
            p_new = 0.0
            for a in range(n1 - n0):
                p_new += node_force[a, 0] * mv[a, 0] + node_force[a, 1] * mv[a, 1] + node_force[a, 2] * mv[a, 2]
            M.work[k] += 0.5 * (p_old + p_new) * dt


# written once, compiled twice (state.flavours): the contact pass serial / parallel over chunks of spheres
mesh_forces_ser, mesh_forces_par = flavours(mesh_forces)
query_faces_ser, query_faces_par = flavours(query_faces)
mesh_pass_ser = njit(cache=True)(clone(mesh_pass, "mesh_pass_ser", {"mesh_forces": mesh_forces_ser}))
mesh_pass_par = njit(cache=True)(clone(mesh_pass, "mesh_pass_par", {"mesh_forces": mesh_forces_par}))
