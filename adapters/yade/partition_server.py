"""YADE side of the YADE DEM partition (adapters/yade/partition.py starts it once per coupled run):

    yade -n -x -j1 partition_server.py          (cwd: the partition's run folder, with partition_yade.json, p4.py)

Plain Python run inside YADE 2023.02a (its own interpreter and numpy); it imports nothing from the project but p4.py,
copied next to it. The scene is built from partition_yade.json with the YADE backend's parameter map
(adapters/yade/params.py, applied on the coupler side): FrictMat, Hertz-Mindlin with betan = betas per material pair,
hertzian=True walls and facets (R* = R), clumps for clusters (planar: z translation and X, Y rotations blocked,
the inertia given in global components; see the clump block below), Wall
bodies for axis-aligned planes, one facet per mesh triangle.

The coupling interface is a chain of 2D segments through the MPM wall nodes: each segment is a strip of two
kinematic facets spanning the thickness (z in [-thickness/2, thickness/2]). At every STEP the facets are moved to
the node positions sent by the coupler (vertices reset, pos at the incentre as Ig2_Facet_Sphere_ScGeom requires) and
given the rigid velocity that reproduces the linear node velocity field's normal component along the segment
(translation + spin about z); NewtonIntegrator moves them during the step and the contacts see that velocity.
After the InteractionLoop of every iteration a hook resolves the facet contacts of each sphere and mesh with the
native hierarchy (P4, p4.py: dominated contacts' force and torque are taken back from the sphere) and distributes
every interface contact force to the two nodes of its segment with the barycentric weights of the contact point,
as the native solver does. The node forces are summed over the iterations of a STEP: YADE's leapfrog delivers the
impulse sum_k F_k dt over those iterations, so the returned mean (sum / n) times the duration is exactly the
impulse the spheres received from the wall.

Exchange: binary messages over two pipes inherited from the coupler (fds in MPMDEM_FD_IN / MPMDEM_FD_OUT):
    header  struct "<4sIQQ": magic b"MDYP", command / status, json length, array bytes
    body    json (utf-8), then float64 arrays back to back (their names and shapes are in the json "arrays" list)
Commands: 1 STEP (n steps, motion events, node x, v), 2 STATE (energies, momentum), 3 TABLE (body table),
4 CONTACTS (contact rows), 9 QUIT. Status 0 ok, 1 error (json "error": traceback). On EOF the script exits.
"""
import json
import math
import os
import struct
import sys
import time
import traceback

import numpy as np

sys.path.insert(0, os.getcwd())
from p4 import feature, feature_key, resolve      # noqa: E402  (copied next to this script)

MAGIC = b"MDYP"
HEADER = struct.Struct("<4sIQQ")
FD_IN = int(os.environ["MPMDEM_FD_IN"])
FD_OUT = int(os.environ["MPMDEM_FD_OUT"])
P = json.load(open("partition_yade.json"))


def read_exact(n):
    chunks, got = [], 0
    while got < n:
        b = os.read(FD_IN, min(n - got, 1 << 20))
        if not b:
            raise EOFError
        chunks.append(b)
        got += len(b)
    return b"".join(chunks)


def receive():
    magic, cmd, nj, na = HEADER.unpack(read_exact(HEADER.size))
    if magic != MAGIC:
        raise RuntimeError("bad message magic %r" % (magic,))
    meta = json.loads(read_exact(nj).decode()) if nj else {}
    raw = read_exact(na) if na else b""
    arrays, off = {}, 0
    for name, shape in meta.get("arrays", []):
        n = int(np.prod(shape)) * 8
        arrays[name] = np.frombuffer(raw[off:off + n], dtype="<f8").reshape(shape)
        off += n
    return cmd, meta, arrays


def send(status, meta, arrays=()):
    meta = dict(meta)
    meta["arrays"] = [[name, list(np.shape(a))] for name, a in arrays]
    j = json.dumps(meta).encode()
    data = b"".join(np.ascontiguousarray(a, dtype="<f8").tobytes() for _, a in arrays)
    msg = HEADER.pack(MAGIC, status, len(j), len(data)) + j + data
    view = memoryview(msg)
    while view:
        k = os.write(FD_OUT, view)
        view = view[k:]


# -- the scene ----------------------------------------------------------------------------------------------------
mats = {}
for name, m in P["materials"].items():
    mats[name] = O.materials.append(FrictMat(young=m["young"], poisson=m["poisson"], density=m["density"],
                                             frictionAngle=math.atan(P["friction"]), label=name))
names = {}                                  # body id (free sphere, clump, member) -> scene body name
sphere_ids = []
for k in range(len(P["radius"])):
    b = utils.sphere(P["position"][k], P["radius"][k], material=mats[P["material"][k]])
    b.state.vel = Vector3(*P["velocity"][k])
    b.state.angVel = Vector3(*P["angvel"][k])
    if P["planar"]:
        b.state.blockedDOFs = "zXY"
    i = O.bodies.append(b)
    sphere_ids.append(i)
    names[i] = P["names"][k]
# Planar clumps: z translation AND the out-of-plane rotations X, Y blocked, as the native 2D DEM (one rotation, about
# z). With rotations free (translations-only blocking, P6) a loaded sliding clump is unstable about x: the floor
# contacts' normal forces act through the sphere centres, which shift sideways under a tilt while the blocked z
# translation keeps the centroid, and a Coulomb-sliding contact has no restoring shear stiffness; round-off of the
# interface facets seeded it (stored h = 10 mm run of coupled_retaining_wall: qx of block1 1e-7 at 0.21 s, 1e-4 at
# 0.33 s, block lying on its side, centroid y 12.5 -> 2.5 mm, at 0.56 s). With a rotation blocked NewtonIntegrator
# takes the spherical rotation, angular acceleration M / state.inertia per GLOBAL component (P6: the principal values
# are in the clump's local order there), so state.inertia is set to the diagonal of the global inertia tensor
# R diag(I) R^T; for a planar clump z is a principal axis, so M_z / I_zz is exact.
PLANAR = bool(P["planar"])
FREE_DOFS = "zXY" if PLANAR else ""         # clumps
clumps = []                                 # (clump id, name, ori at t = 0, scene orientation)
clump_of = {}
I_ZZ = {}                                   # planar clump id -> I_zz [kg m^2] (global)


def global_inertia_diagonal(st):
    """Diagonal of R diag(I) R^T (R: the clump's principal frame st.ori)."""
    out = [0.0, 0.0, 0.0]
    for k in range(3):
        e = [0.0, 0.0, 0.0]
        e[k] = 1.0
        a = st.ori.conjugate() * Vector3(*e)          # global axis k in the principal frame
        out[k] = sum(st.inertia[j] * a[j] ** 2 for j in range(3))
    return out


for c in P["clusters"]:
    members = [utils.sphere(m[:3], m[3], material=mats[c["material"]]) for m in c["members"]]
    cid, mids = O.bodies.appendClumped(members)
    st = O.bodies[cid].state
    st.vel = Vector3(*c["velocity"])
    st.angVel = Vector3(*c["angvel"])
    if PLANAR:
        if any(abs(m[2] - st.pos[2]) > 1e-12 * m[3] for m in c["members"]):
            raise RuntimeError("cluster %s: planar clump members must share the clump's z (z a principal axis)"
                               % c["name"])
        st.inertia = Vector3(*global_inertia_diagonal(st))     # spherical rotation path: global components
        I_ZZ[cid] = st.inertia[2]
        st.angVel = Vector3(0.0, 0.0, st.angVel[2])
        st.angMom = Vector3(0.0, 0.0, I_ZZ[cid] * st.angVel[2])
    else:
        wl = st.ori.conjugate() * st.angVel       # angMom from the spin (the clump's principal frame, P12)
        st.angMom = st.ori * Vector3(wl[0] * st.inertia[0], wl[1] * st.inertia[1], wl[2] * st.inertia[2])
    st.blockedDOFs = FREE_DOFS
    names[cid] = c["name"]
    for m in mids:
        names[m] = c["name"]
    clump_of[c["name"]] = cid
    clumps.append((cid, c["name"], Quaternion(st.ori), Quaternion(*c["orientation"])))
walls = {}                                  # wall / facet body id -> wall name
for w in P["walls"]:
    b = utils.wall(w["pos"], w["axis"], material=mats[w["material"]])
    b.state.vel = Vector3(*w["vel"])
    walls[O.bodies.append(b)] = w["name"]
facet_of = {}                               # facet id -> (mesh index, face index, interface segment or -1)
for k, m in enumerate(P["meshes"]):
    V = m["vertices"]
    for f, tri in enumerate(m["triangles"]):
        b = utils.facet([V[i] for i in tri], material=mats[m["material"]], fixed=True)
        b.state.vel = Vector3(*m["vel"])
        fid = O.bodies.append(b)
        facet_of[fid] = (k, f, m["segment_of"][f] if m["interface"] else -1)
        walls[fid] = m["name"]
IFACE = next(k for k, m in enumerate(P["meshes"]) if m["interface"])
iface = P["meshes"][IFACE]
NN = iface["n_nodes"]
SEG = iface["segments"]                     # (a, b) node pairs
HD = iface["half_depth"]
seg_facets = [[] for _ in SEG]              # segment -> [(facet id, triangle)]
for fid, (k, f, s) in facet_of.items():
    if k == IFACE:
        seg_facets[s].append((fid, iface["triangles"][f]))
beta = MatchMaker(matches=[(mats[a], mats[b], v) for a, b, v in P["beta_pairs"]])
roll = P.get("rolling")
ip2 = (Ip2_FrictMat_FrictMat_MindlinPhys(betan=beta, betas=beta) if roll is None else
       Ip2_FrictMat_FrictMat_MindlinPhys(betan=beta, betas=beta, krot=roll["krot"], ktwist=0.0, eta=roll["eta"]))
law = (Law2_ScGeom_MindlinPhys_Mindlin(calcEnergy=True) if roll is None else
       Law2_ScGeom_MindlinPhys_Mindlin(calcEnergy=True, includeMoment=True))
coll = InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb(), Bo1_Facet_Aabb()], verletDist=P["skin"])
O.engines = [
    ForceResetter(),
    coll,
    InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom(hertzian=True),
                     Ig2_Facet_Sphere_ScGeom(hertzian=True)], [ip2], [law]),
    PyRunner(iterPeriod=1, command="after_forces()"),
    NewtonIntegrator(damping=0.0, gravity=Vector3(*P["gravity"])),
]
O.dt = P["dt"]

# -- interface kinematics -----------------------------------------------------------------------------------------
node_x = [[0.0, 0.0] for _ in range(NN)]    # node positions and velocities at the start of the current STEP
node_v = [[0.0, 0.0] for _ in range(NN)]
t_set = [0.0]                               # time of the last node update


SEG_A = np.array([ab[0] for ab in SEG], int)
SEG_B = np.array([ab[1] for ab in SEG], int)
F_IDS = [fid for lst in seg_facets for fid, _ in lst]
F_SEG = np.array([k for k, lst in enumerate(seg_facets) for _ in lst], int)
F_TRI = np.array([tri for lst in seg_facets for _, tri in lst], int)          # into the 2 nn strip vertices
F_BODIES = [O.bodies[fid] for fid in F_IDS]


def move_interface(x, v):
    """Facets of every segment to the node positions x (nn, 2), vectorised; rigid velocity of the segment from
    v (nn, 2): translation with the mean node velocity + spin about z = (v_b - v_a) . n / L (the normal velocity
    along the segment is then the linear interpolation of the node velocities)."""
    X3 = np.zeros((2 * NN, 3))
    X3[:NN, :2] = x
    X3[NN:, :2] = x
    X3[:NN, 2] = -HD
    X3[NN:, 2] = HD
    V = X3[F_TRI]                                            # (nf, 3, 3)
    la = np.linalg.norm(V[:, 1] - V[:, 2], axis=1)
    lb = np.linalg.norm(V[:, 2] - V[:, 0], axis=1)
    lc = np.linalg.norm(V[:, 0] - V[:, 1], axis=1)
    c = (V[:, 0] * la[:, None] + V[:, 1] * lb[:, None] + V[:, 2] * lc[:, None]) / (la + lb + lc)[:, None]
    loc = V - c[:, None, :]                                  # vertices relative to the incentre
    t = x[SEG_B] - x[SEG_A]
    L = np.hypot(t[:, 0], t[:, 1])
    n = np.column_stack([-t[:, 1], t[:, 0]]) / L[:, None]
    m = 0.5 * (x[SEG_A] + x[SEG_B])
    vm = 0.5 * (v[SEG_A] + v[SEG_B])
    om = np.einsum("ij,ij->i", v[SEG_B] - v[SEG_A], n) / L
    fs = F_SEG
    vel = np.zeros((len(fs), 3))
    vel[:, 0] = vm[fs, 0] - om[fs] * (c[:, 1] - m[fs, 1])
    vel[:, 1] = vm[fs, 1] + om[fs] * (c[:, 0] - m[fs, 0])
    cl, locl, vell, oml = c.tolist(), loc.tolist(), vel.tolist(), om[fs].tolist()
    q = Quaternion(1.0, 0.0, 0.0, 0.0)
    for i, b in enumerate(F_BODIES):
        st = b.state
        st.pos = Vector3(*cl[i])
        st.ori = q
        b.shape.vertices = [Vector3(*w) for w in locl[i]]
        st.vel = Vector3(*vell[i])
        st.angVel = Vector3(0.0, 0.0, oml[i])
    for i in range(NN):
        node_x[i][0], node_x[i][1] = float(x[i, 0]), float(x[i, 1])
        node_v[i][0], node_v[i][1] = float(v[i, 0]), float(v[i, 1])
    t_set[0] = O.time
    coll.doSort = True                      # the facets were moved outside NewtonIntegrator: rebuild the bounds


# -- per-iteration hook: P4 resolution + node forces --------------------------------------------------------------
acc = [0.0] * (2 * NN)                      # sum over the iterations of this STEP of the node forces
last = [0.0] * (2 * NN)                     # node forces of the last iteration
dropped = set()
count = {"p4_dropped_contact_steps": 0, "p4_steps": 0, "iterations": 0, "hook_s": 0.0, "hook_cpu_s": 0.0}


def after_forces():
    tic = time.perf_counter()
    cic = time.process_time()
    other = {}                                  # (sphere, mesh) -> facet contacts, meshes other than the interface
    mine = {}                                   # sphere -> interface contacts [(segment, I)]
    for I in O.interactions:
        if not I.isReal:
            continue
        info = facet_of.get(I.id1)
        if info is not None:
            fid, sid = I.id1, I.id2
        else:
            info = facet_of.get(I.id2)
            if info is None:
                continue
            fid, sid = I.id2, I.id1
        if info[2] >= 0:
            lst = mine.get(sid)
            if lst is None:
                mine[sid] = [(info[2], I)]
            else:
                lst.append((info[2], I))
        else:
            other.setdefault((sid, info[0]), []).append((info[1], fid, I))
    dropped.clear()
    for j in range(2 * NN):
        last[j] = 0.0
    dtt = O.time - t_set[0]
    for (sid, k), lst in other.items():        # other meshes: the 3D hierarchy of p4.py, as writer.py
        if len(lst) < 2:
            continue
        lst.sort(key=lambda e: e[0])
        p = O.bodies[sid].state.pos
        feats = []
        for f, fid, I in lst:
            st, sh = O.bodies[fid].state, O.bodies[fid].shape
            a, b, c = [st.pos + st.ori * w for w in sh.vertices]
            tri = P["meshes"][k]["triangles"][f]
            typ, loc = feature(p, a, b, c)
            feats.append((typ, feature_key(f, tri, typ, loc), tri))
        for (f, fid, I), kp in zip(lst, resolve(feats)):
            if not kp:
                take_back(sid, I)
    for sid, lst in mine.items():               # the interface: the native 2D hierarchy (segment face / node)
        px = py = 0.0
        if len(lst) > 1:
            p = O.bodies[sid].state.pos
            px, py = p[0], p[1]
            faces, nodes = {}, {}
            for e, (s, I) in enumerate(lst):
                ia, ib = SEG[s]
                ax = node_x[ia][0] + node_v[ia][0] * dtt
                ay = node_x[ia][1] + node_v[ia][1] * dtt
                tx = node_x[ib][0] + node_v[ib][0] * dtt - ax
                ty = node_x[ib][1] + node_v[ib][1] * dtt - ay
                w = ((px - ax) * tx + (py - ay) * ty) / (tx * tx + ty * ty)
                d = I.geom.penetrationDepth
                if 0.0 < w < 1.0:
                    best = faces.get(s)           # the two triangles of one strip: one face contact
                    if best is None or d > best[0]:
                        faces[s] = (d, e)
                else:
                    node = ia if w <= 0.0 else ib
                    best = nodes.get(node)        # one node reached from two segments counts once
                    if best is None or d > best[0]:
                        nodes[node] = (d, e)
            keep = set(e for _, e in faces.values())
            covered = set()
            for s in faces:
                covered.update(SEG[s])
            keep.update(e for node, (_, e) in nodes.items() if node not in covered)   # a face dominates its nodes
            kept = []
            for e, item in enumerate(lst):
                if e in keep:
                    kept.append(item)
                else:
                    take_back(sid, item[1])
            lst = kept
        for s, I in lst:
            fs = I.phys.normalForce + I.phys.shearForce   # on id2 (P13)
            if sid == I.id1:
                fs = -fs                                  # now: on the sphere
            ia, ib = SEG[s]
            ax = node_x[ia][0] + node_v[ia][0] * dtt
            ay = node_x[ia][1] + node_v[ia][1] * dtt
            tx = node_x[ib][0] + node_v[ib][0] * dtt - ax
            ty = node_x[ib][1] + node_v[ib][1] * dtt - ay
            cp = I.geom.contactPoint
            w = ((cp[0] - ax) * tx + (cp[1] - ay) * ty) / (tx * tx + ty * ty)
            w = 0.0 if w < 0.0 else (1.0 if w > 1.0 else w)
            fx, fy = -fs[0], -fs[1]                       # on the wall
            last[2 * ia] += (1.0 - w) * fx
            last[2 * ia + 1] += (1.0 - w) * fy
            last[2 * ib] += w * fx
            last[2 * ib + 1] += w * fy
    if dropped:
        count["p4_steps"] += 1
    for j in range(2 * NN):
        acc[j] += last[j]
    count["iterations"] += 1
    count["hook_s"] += time.perf_counter() - tic
    count["hook_cpu_s"] += time.process_time() - cic


def take_back(sid, I):
    """P4: the force and torque of a dominated facet contact are taken back from the sphere."""
    fs = I.phys.normalForce + I.phys.shearForce           # on id2 (P13)
    if sid == I.id1:
        fs = -fs
    O.forces.addF(sid, -fs)
    O.forces.addT(sid, -(I.geom.contactPoint - O.bodies[sid].state.pos).cross(fs))
    dropped.add((I.id1, I.id2))
    count["p4_dropped_contact_steps"] += 1


# -- prescribed motion (the coupler decides when; this applies) ---------------------------------------------------
def set_motion(name, kind, vel, spin):
    b = O.bodies[clump_of[name]]
    st = b.state
    if kind == "free":
        st.blockedDOFs = FREE_DOFS
        return
    st.blockedDOFs = "xyzXYZ"
    st.vel = Vector3(*vel)
    st.angVel = Vector3(*spin)
    if PLANAR:
        st.angMom = Vector3(0.0, 0.0, I_ZZ[b.id] * st.angVel[2])
        return
    wl = st.ori.conjugate() * st.angVel
    st.angMom = st.ori * Vector3(wl[0] * st.inertia[0], wl[1] * st.inertia[1], wl[2] * st.inertia[2])


# -- observables --------------------------------------------------------------------------------------------------
def bodies_rows():
    rows = []
    for i in sphere_ids:
        s = O.bodies[i].state
        q = s.ori
        rows.append([s.pos[0], s.pos[1], s.pos[2], s.vel[0], s.vel[1], s.vel[2], q[3], q[0], q[1], q[2],
                     s.angVel[0], s.angVel[1], s.angVel[2]])
    for cid, name, q0, qs in clumps:
        s = O.bodies[cid].state
        q = s.ori * q0.conjugate() * qs           # rotation since t = 0 (P12) applied to the scene orientation
        rows.append([s.pos[0], s.pos[1], s.pos[2], s.vel[0], s.vel[1], s.vel[2], q[3], q[0], q[1], q[2],
                     s.angVel[0], s.angVel[1], s.angVel[2]])
    return np.array(rows, float).reshape(-1, 13)


def state_vector():
    g = Vector3(*P["gravity"])
    kin = pot = 0.0
    p = Vector3(0, 0, 0)
    for i in sphere_ids:
        s = O.bodies[i].state
        I = 0.4 * s.mass * O.bodies[i].shape.radius ** 2
        kin += 0.5 * s.mass * s.vel.squaredNorm() + 0.5 * I * s.angVel.squaredNorm()
        pot -= s.mass * s.pos.dot(g)
        p += s.mass * s.vel
    for cid, _, _, _ in clumps:
        s = O.bodies[cid].state
        if PLANAR:                                # rotation about z only; s.inertia holds the global diagonal
            rot = 0.5 * I_ZZ[cid] * s.angVel[2] ** 2
        else:
            wl = s.ori.conjugate() * s.angVel
            rot = 0.5 * sum(s.inertia[k] * wl[k] ** 2 for k in range(3))
        kin += 0.5 * s.mass * s.vel.squaredNorm() + rot
        pot -= s.mass * s.pos.dot(g)
        p += s.mass * s.vel
    el = 0.0
    for I in O.interactions:
        if not I.isReal or (I.id1, I.id2) in dropped:
            continue
        ph = I.phys
        el += 0.4 * ph.kno * max(I.geom.penetrationDepth, 0.0) ** 2.5          # Hertz: 2/5 kno delta^5/2
        if ph.ks > 0:
            el += 0.5 * ph.shearForce.squaredNorm() / ph.ks
    diss = law.normDampDissip + law.shearDampDissip + law.frictionDissipation
    return np.array([kin, pot, el, diss, p[0], p[1], p[2]])


def contact_rows():
    ii, jj, data = [], [], []
    for I in O.interactions:
        if not I.isReal or I.geom.penetrationDepth <= 0 or (I.id1, I.id2) in dropped:
            continue
        f2 = I.phys.normalForce + I.phys.shearForce          # acts on id2 (P13)
        a, b = I.id1, I.id2
        if a in walls or (b not in walls and b < a):          # the sphere (lowest id) as i
            a, b, f = b, a, f2
        else:
            f = -f2
        ii.append(names[a])
        jj.append(("wall:" + walls[b]) if b in walls else names[b])
        data.append([f[0], f[1], f[2], I.phys.normalForce.norm(), I.phys.shearForce.norm(),
                     I.geom.penetrationDepth])
    return ii, jj, np.array(data, float).reshape(-1, 6)


def check_health():
    lo, hi = P["domain"]
    for i in sphere_ids + [c[0] for c in clumps]:
        s = O.bodies[i].state
        for name, vec in (("position", s.pos), ("velocity", s.vel), ("angular velocity", s.angVel)):
            if not all(math.isfinite(vec[k]) for k in range(3)):
                return "body %s: %s is not finite" % (names[i], name)
        if any(s.pos[k] < lo[k] or s.pos[k] > hi[k] for k in range(3)):
            return "body %s: position %s left the domain [%s, %s]" % (names[i], list(s.pos), lo, hi)
    return None


# -- the loop -----------------------------------------------------------------------------------------------------
totals = {"run_s": 0.0, "run_cpu_s": 0.0, "move_s": 0.0, "move_cpu_s": 0.0, "steps": 0, "step_cpu_s": 0.0}


def do_step(meta, arrays):
    tic = time.perf_counter()
    cic = time.process_time()
    move_interface(arrays["x"], arrays["v"])
    totals["move_s"] += time.perf_counter() - tic
    totals["move_cpu_s"] += time.process_time() - cic
    n = int(meta["n"])
    for j in range(2 * NN):
        acc[j] = 0.0
    done = 0
    events = sorted(meta.get("events", []), key=lambda e: e[0])
    tic = time.perf_counter()
    cic = time.process_time()
    for k, name, kind, vel, spin in events + [[n, None, None, None, None]]:
        for _ in range(int(k - done)):          # O.step() runs in this thread; O.run(n, True) hands over to
            O.step()                             # the simulation thread and polls: ~50 ms per call here
        done = max(done, k)
        if name is not None:
            set_motion(name, kind, vel, spin)
    totals["run_s"] += time.perf_counter() - tic
    totals["run_cpu_s"] += time.process_time() - cic
    totals["steps"] += n
    bad = check_health()
    avg = np.array(acc).reshape(NN, 2) / max(n, 1)
    out = {"iter": O.iter, "steps": totals["steps"], "health": bad, **count, **totals}
    return out, [("avg", avg), ("last", np.array(last).reshape(NN, 2))]


masses = [O.bodies[i].state.mass for i in sphere_ids] + [O.bodies[c[0]].state.mass for c in clumps]
import yade.config                         # noqa: E402
send(0, {"hello": "yade partition", "version": str(getattr(yade.config, "version", "?")),
         "n_spheres": len([b for b in O.bodies if isinstance(b.shape, Sphere)]), "masses": masses,
         "facets": len(facet_of)})
while True:
    c0 = time.process_time()                    # a blocked read costs no CPU time
    try:
        cmd, meta, arrays = receive()
    except EOFError:
        break
    try:
        if cmd == 1:
            out, arr = do_step(meta, arrays)
            send(0, out, arr)
            totals["step_cpu_s"] += time.process_time() - c0     # all of it: receive, move, run, send
        elif cmd == 2:
            send(0, {}, [("state", state_vector())])
        elif cmd == 3:
            send(0, {}, [("bodies", bodies_rows())])
        elif cmd == 4:
            ii, jj, data = contact_rows()
            send(0, {"i": ii, "j": jj}, [("data", data)])
        elif cmd == 9:
            send(0, {"bye": True, **count, **totals})
            break
        else:
            send(1, {"error": "unknown command %d" % cmd})
    except Exception:
        send(1, {"error": traceback.format_exc()})
sys.stdout.flush()
