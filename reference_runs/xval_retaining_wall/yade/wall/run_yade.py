
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
    if P["planar"]:
        st.blockedDOFs = "z"                 # translations only (notes P6)
    for m in mids:
        owner[m] = c["name"]
    clumps.append((cid, c["name"], Quaternion(st.ori)))
walls = {}
for w in P["walls"]:
    walls[O.bodies.append(utils.wall(w["pos"], w["axis"], material=mats[w["material"]]))] = w["name"]
# one damping ratio per material pair (adapters/yade/params.py beta_pairs, notes P5)
beta = MatchMaker(matches=[(mats[a], mats[b], v) for a, b, v in P["beta_pairs"]])
O.engines = [
    PyRunner(iterPeriod=P["every"], command="record()", initRun=True),   # state at the start of the iteration
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()], verletDist=P["skin"]),
    InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom(hertzian=True)],
                    [Ip2_FrictMat_FrictMat_MindlinPhys(betan=beta, betas=beta)],
                    [Law2_ScGeom_MindlinPhys_Mindlin()]),
    NewtonIntegrator(damping=0.0, gravity=Vector3(*P["gravity"])),
]
O.dt = P["dt"]
bf = open("bodies_yade.csv", "w")
cf = open("contacts_yade.csv", "w")
bf.write("t,id,x,y,z,vx,vy,vz,qw,qx,qy,qz,wx,wy,wz\n")
cf.write("t,i,j,fx,fy,fz,fn,ft,overlap\n")

def record():
    t = O.iter * O.dt
    for k in ids:
        s = O.bodies[k].state
        q = s.ori
        bf.write("%.17g,%d,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n" % (
            t, k, s.pos[0], s.pos[1], s.pos[2], s.vel[0], s.vel[1], s.vel[2], q[3], q[0], q[1], q[2],
            s.angVel[0], s.angVel[1], s.angVel[2]))
    for cid, name, q0 in clumps:
        s = O.bodies[cid].state
        q = s.ori * q0.conjugate()          # rotation since t = 0 (notes P12)
        bf.write("%.17g,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n" % (
            t, "c:" + name, s.pos[0], s.pos[1], s.pos[2], s.vel[0], s.vel[1], s.vel[2], q[3], q[0], q[1], q[2],
            s.angVel[0], s.angVel[1], s.angVel[2]))
    if not P["contacts"]:
        return
    for I in O.interactions:
        if not I.isReal or I.geom.penetrationDepth <= 0:
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

import time
_t0 = time.perf_counter()
O.run(P["steps"], True)
record()                         # the final state, like the native output
json.dump({"loop_time_s": time.perf_counter() - _t0}, open("timing_yade.json", "w"))
bf.close()
cf.close()
