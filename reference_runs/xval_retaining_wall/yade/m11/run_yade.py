
# written by mpmdem (adapters/yade); parameter map: adapters/yade/params.py
import json, math
from yade import utils
P = json.load(open("scene_yade.json"))
mats = {}
for name, m in P["materials"].items():
    mats[name] = O.materials.append(FrictMat(young=m["young"], poisson=m["poisson"], density=m["density"],
                                             frictionAngle=math.atan(P["friction"]), label=name))
ids = []
for k in range(len(P["radius"])):
    b = utils.sphere(P["position"][k], P["radius"][k], material=mats[P["material"][k]])
    b.state.vel = Vector3(*P["velocity"][k])
    b.state.angVel = Vector3(*P["angvel"][k])
    if P["planar"]:
        b.state.blockedDOFs = "zXY"
    ids.append(O.bodies.append(b))
owner = {}
clumps = []
for c in P["clusters"]:
    members = [utils.sphere(m[:3], m[3], material=mats[c["material"]]) for m in c["members"]]
    cid, mids = O.bodies.appendClumped(members)
    st = O.bodies[cid].state
    st.vel = Vector3(*c["velocity"])
    st.angVel = Vector3(*c["angvel"])
    # clumps are aspherical: NewtonIntegrator integrates angMom (global frame) and derives angVel from it, so the
    # initial spin must be given as L = R diag(I) R^T w (R: the clump's principal frame, P12)
    wl = st.ori.conjugate() * st.angVel
    st.angMom = st.ori * Vector3(wl[0] * st.inertia[0], wl[1] * st.inertia[1], wl[2] * st.inertia[2])
    if P["planar"]:
        st.blockedDOFs = "z"                 # translations only (notes P6)
    if c["motion"] is not None:              # prescribed: no accelerations, moved with vel / angVel (module doc)
        st.blockedDOFs = "xyzXYZ"
        st.vel = Vector3(*c["motion"]["velocity"])
        st.angVel = Vector3(*c["motion"]["angvel"])
    for m in mids:
        owner[m] = c["name"]
    clumps.append((cid, c["name"], Quaternion(st.ori), Quaternion(*c["orientation"])))
walls = {}                              # wall or facet body id -> wall name
for w in P["walls"]:
    b = utils.wall(w["pos"], w["axis"], material=mats[w["material"]])
    b.state.vel = Vector3(*w["vel"])    # non-dynamic: NewtonIntegrator moves it with this velocity
    walls[O.bodies.append(b)] = w["name"]
facet_of = {}                           # facet body id -> (mesh index, face index)
for k, m in enumerate(P["meshes"]):
    V = m["vertices"]
    for f, tri in enumerate(m["triangles"]):
        b = utils.facet([V[i] for i in tri], material=mats[m["material"]], fixed=True)
        b.state.vel = Vector3(*m["vel"])
        fid = O.bodies.append(b)
        facet_of[fid] = (k, f)
        walls[fid] = m["name"]
# one damping ratio per material pair (adapters/yade/params.py beta_pairs, notes P5)
beta = MatchMaker(matches=[(mats[a], mats[b], v) for a, b, v in P["beta_pairs"]])
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb(), Bo1_Facet_Aabb()], verletDist=P["skin"]),
    InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom(hertzian=True),
                     Ig2_Facet_Sphere_ScGeom(hertzian=True)],                                   # R* = R (P3)
                    [Ip2_FrictMat_FrictMat_MindlinPhys(betan=beta, betas=beta)],
                    [Law2_ScGeom_MindlinPhys_Mindlin()]),
] + ([PyRunner(iterPeriod=1, command="p4()")] if facet_of else []) + [
    # sampled after the contact forces of x(t) and before NewtonIntegrator: positions x(t), contact rows of x(t),
    # velocities v(t) = v(t - dt/2) + a(t) dt/2 (aligned with the native velocity Verlet, see record())
    PyRunner(iterPeriod=1, command="maybe_record()", initRun=True),
    NewtonIntegrator(damping=0.0, gravity=Vector3(*P["gravity"])),
]

# P4 (adapters/yade/p4.py, copied below): the facet contacts of one sphere with one mesh are resolved as the native
# hierarchy after the InteractionLoop; the force and torque of every dominated contact are taken back from the
# sphere before NewtonIntegrator. `dropped` lists them for the contact table.
dropped = set()
p4_count = [0, 0]                       # dominated contact-steps, steps with one

def feature(p, a, b, c):
    """Region of the closest point of triangle abc to p (Ericson 2005, 5.1.5, as coupler/dem/meshes.py):
    (0, 0) face, (1, k) edge k (0: ab, 1: bc, 2: ca), (2, k) vertex k (0: a, 1: b, 2: c)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab.dot(ap), ac.dot(ap)
    if d1 <= 0 and d2 <= 0:
        return 2, 0
    bp = p - b
    d3, d4 = ab.dot(bp), ac.dot(bp)
    if d3 >= 0 and d4 <= d3:
        return 2, 1
    if d1 * d4 - d3 * d2 <= 0 and d1 >= 0 and d3 <= 0:
        return 1, 0
    cp = p - c
    d5, d6 = ab.dot(cp), ac.dot(cp)
    if d6 >= 0 and d5 <= d6:
        return 2, 2
    if d5 * d2 - d1 * d6 <= 0 and d2 >= 0 and d6 <= 0:
        return 1, 2
    if d3 * d6 - d5 * d4 <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0:
        return 1, 1
    return 0, 0


def feature_key(face, tri, typ, loc):
    """Mesh-global key of a feature: the face index, the sorted vertex pair of an edge, or the vertex index."""
    if typ == 0:
        return face
    if typ == 1:
        return tuple(sorted((tri[loc], tri[(loc + 1) % 3])))
    return tri[loc]


def contains(tri_b, typ_b, key_b, typ_a, key_a):
    """Does feature b (a face with vertices tri_b, or an edge of it) contain the lower feature a?"""
    if typ_b == 0:
        return set(key_a) <= set(tri_b) if typ_a == 1 else key_a in tri_b
    return key_a in key_b


def resolve(feats):
    """feats: [(type, key, face vertices)] of one sphere's contacts with one mesh, in face order.
    Returns keep flags (the native hierarchy; False = dominated, its force must not act)."""
    keep = [True] * len(feats)
    for ia, (ta, ka, _) in enumerate(feats):
        if ta == 0:
            continue
        for ib, (tb, kb, trib) in enumerate(feats):
            if ib == ia or not keep[ib]:
                continue
            if (tb < ta and contains(trib, tb, kb, ta, ka)) or (tb == ta and kb == ka and ib < ia):
                keep[ia] = False
                break
    return keep


def p4():
    per = {}
    for I in O.interactions:
        if not I.isReal:
            continue
        if I.id1 in facet_of:
            fid, sid = I.id1, I.id2
        elif I.id2 in facet_of:
            fid, sid = I.id2, I.id1
        else:
            continue
        k, f = facet_of[fid]
        per.setdefault((sid, k), []).append((f, fid, I))
    dropped.clear()
    for (sid, k), lst in per.items():
        if len(lst) < 2:
            continue
        lst.sort(key=lambda e: e[0])                       # face order, as the native candidate list
        p = O.bodies[sid].state.pos
        feats = []
        for f, fid, I in lst:
            st, sh = O.bodies[fid].state, O.bodies[fid].shape
            a, b, c = [st.pos + st.ori * v for v in sh.vertices]
            tri = P["meshes"][k]["triangles"][f]
            typ, loc = feature(p, a, b, c)
            feats.append((typ, feature_key(f, tri, typ, loc), tri))
        keep = resolve(feats)
        for (f, fid, I), kp in zip(lst, keep):
            if kp:
                continue
            fs = I.phys.normalForce + I.phys.shearForce       # on id2 (P13)
            if sid == I.id1:
                fs = -fs
            O.forces.addF(sid, -fs)
            O.forces.addT(sid, -(I.geom.contactPoint - p).cross(fs))
            dropped.add((I.id1, I.id2))
            p4_count[0] += 1
    if dropped:
        p4_count[1] += 1


O.dt = P["dt"]
bf = open("bodies_yade.csv", "w")
cf = open("contacts_yade.csv", "w")
bf.write("t,id,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz\n")
cf.write("t,i,j,fx,fy,fz,fn,ft,overlap\n")

GRAV = Vector3(*P["gravity"])


def maybe_record():
    if O.iter == 0:
        start()
    if O.iter % P["every"] == 0 or O.iter == P["steps"]:
        record()


def _accel(cid):
    """Force and torque on a clump from this step's member forces (NewtonIntegrator sums them the same way)."""
    s = O.bodies[cid].state
    f, tq = Vector3(O.forces.f(cid)), Vector3(O.forces.t(cid))
    for mid in O.bodies[cid].shape.members.keys():
        fm = O.forces.f(mid)
        f += fm
        tq += O.forces.t(mid) + (O.bodies[mid].state.pos - s.pos).cross(fm)
    return f, tq


def _inv_clump(s):
    def inv(tq):
        l = s.ori.conjugate() * tq
        return s.ori * Vector3(l[0] / s.inertia[0], l[1] / s.inertia[1], l[2] / s.inertia[2])
    return inv


def start():
    """YADE's leapfrog takes state.vel as v(-dt/2): start it from v(0) - a(0) dt/2 (a(0) from the forces of x(0)),
    so that x(dt) = x(0) + v(0) dt + a(0) dt^2/2 as the native velocity Verlet (and record() gives back v(0))."""
    for k in ids:
        b = O.bodies[k]
        v, w = _half(b, b.state, -O.forces.f(k), -O.forces.t(k), lambda tq, s=b.state: tq / s.inertia[0], -1.0)
        b.state.vel, b.state.angVel = v, w
    for cid, name, q0, qs in clumps:
        b = O.bodies[cid]
        f, tq = _accel(cid)
        v, w = _half(b, b.state, -f, -tq, _inv_clump(b.state), -1.0)
        b.state.vel, b.state.angVel = v, w
        wl = b.state.ori.conjugate() * w       # aspherical: NewtonIntegrator integrates angMom (see above)
        b.state.angMom = b.state.ori * Vector3(wl[0] * b.state.inertia[0], wl[1] * b.state.inertia[1],
                                               wl[2] * b.state.inertia[2])


def _half(b, s, f, tq, inv_inertia, gsign=1.0):
    """v(t), w(t) from YADE's leapfrog v(t - dt/2), w(t - dt/2) and this step's force and torque (half a step of
    a = f/m + g, w' = I^-1 tq; gyroscopic term of aspherical clumps left out), blocked DOFs untouched."""
    if not b.dynamic:                  # a prescribed (non-dynamic) body keeps its velocity
        return Vector3(s.vel), Vector3(s.angVel)
    h = 0.5 * O.dt
    a = f / s.mass + gsign * GRAV
    dw = inv_inertia(tq)
    v, w = Vector3(s.vel), Vector3(s.angVel)
    for c in range(3):
        if "xyz"[c] not in s.blockedDOFs:
            v[c] += a[c] * h
        if "XYZ"[c] not in s.blockedDOFs:
            w[c] += dw[c] * h
    return v, w


def record():
    t = O.iter * O.dt
    for k in ids:
        s = O.bodies[k].state
        q = s.ori
        v, w = _half(O.bodies[k], s, O.forces.f(k), O.forces.t(k), lambda tq: tq / s.inertia[0])
        bf.write("%.17g,%d,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n" % (
            t, k, s.pos[0], s.pos[1], s.pos[2], v[0], v[1], v[2], q[3], q[0], q[1], q[2], w[0], w[1], w[2]))
    for cid, name, q0, qs in clumps:
        s = O.bodies[cid].state
        q = s.ori * q0.conjugate() * qs     # rotation since t = 0 (P12) applied to the scene orientation
        f, tq = _accel(cid)
        v, w = _half(O.bodies[cid], s, f, tq, _inv_clump(s))
        bf.write("%.17g,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n" % (
            t, "c:" + name, s.pos[0], s.pos[1], s.pos[2], v[0], v[1], v[2], q[3], q[0], q[1], q[2], w[0], w[1], w[2]))
    if not P["contacts"]:
        return
    for I in O.interactions:
        if not I.isReal or I.geom.penetrationDepth <= 0 or (I.id1, I.id2) in dropped:
            continue
        f2 = I.phys.normalForce + I.phys.shearForce          # acts on id2 (notes P13)
        a, b = I.id1, I.id2
        if a in walls or (b not in walls and b < a):          # report the sphere (lowest id) as i
            a, b, f = b, a, f2
        else:
            f = -f2
        jname = ("wall:" + walls[b]) if b in walls else ("c:" + owner[b] if b in owner else str(b))
        if a in owner:
            a = "c:" + owner[a]
        cf.write("%.17g,%s,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n" % (
            t, a, jname, f[0], f[1], f[2], I.phys.normalForce.norm(), I.phys.shearForce.norm(),
            I.geom.penetrationDepth))

def release(cid):
    """The end of a prescribed motion: free DOFs again and the angular momentum of the current spin."""
    st = O.bodies[cid].state
    st.blockedDOFs = "z" if P["planar"] else ""
    wl = st.ori.conjugate() * st.angVel
    st.angMom = st.ori * Vector3(wl[0] * st.inertia[0], wl[1] * st.inertia[1], wl[2] * st.inertia[2])


import time
_t0 = time.perf_counter()
for step, cids in sorted((int(s), [clumps[k][0] for k in ks]) for s, ks in P["releases"].items()):
    O.run(step - O.iter, True)
    for cid in cids:
        release(cid)
O.run(P["steps"] + 1 - O.iter, True)   # the last iteration only records the final state (like the native output)
json.dump({"loop_time_s": time.perf_counter() - _t0, "p4_dropped_contact_steps": p4_count[0],
           "p4_steps": p4_count[1]}, open("timing_yade.json", "w"))
bf.close()
cf.close()
