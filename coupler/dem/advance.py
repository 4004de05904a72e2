"""The DEM time step, written once: velocity Verlet (LIGGGHTS `nve/sphere` + `multisphere`), run for many steps
inside compiled code (no Python per step).

One step n -> n+1:
  first half    free spheres: v += F/m dt/2, x += v dt (and q);  bodies: the same on (v, L), c, q; members placed;
                plane walls and mesh nodes drift with their velocities
  rebuild test  the largest sphere displacement plus the largest wall/node displacement (normal component for a
                plane) since the last neighbour build > skin/2: return to Python, which rebuilds and resumes the
                step where it stopped (`resume`)
  forces        pairs (parallel pass 1), gather + plane contacts (parallel pass 2), mesh walls (contacts
                parallel over spheres, node forces summed in sphere order)
  second half   free spheres and bodies: v += F/m dt/2 (prescribed bodies keep their motion)

Between two steps of one call the second half kick of step n and the first half of step n+1 run in the same pass
as the gather (or, with mesh walls, in one kick pass after the mesh forces): two parallel regions per step instead
of four, each sphere seeing the same operations in the same order (bitwise the result of separate passes).

Flavours: the step is compiled twice from this one definition, with the serial or the parallel kernels bound to
the names `pair_forces`, `gather_pass`, `kick_pass`, `mesh_pass` (state.clone): `run_steps_ser`, `run_steps_par`. One
compiled function choosing between both flavours at run time ran several times slower, and numba's cache cannot
tell apart closures made by a factory; two named copies of one code object are cached apart. Scenes without
clusters or meshes pass zero-row arrays, and the loops over them cost nothing.
"""
from __future__ import annotations

import math

from numba import njit

from coupler.dem import clusters as cl
from coupler.dem import forces as fk
from coupler.dem import integrator as it
from coupler.dem import meshes as msh
from coupler.dem.state import clone

# generic names bound per flavour (the serial ones here, so that the module itself stays importable)
pair_forces = fk.pair_forces_ser
gather_pass = fk.gather_pass_ser
kick_pass = it.kick_pass_ser
mesh_pass = msh.mesh_pass_ser


@njit(cache=True)
def first_half_rest(S, W, C, B, M, P, d2):
    """The first half of a step after the free spheres (bodies, walls) and the rebuild test; d2 is the largest
    squared free-sphere displacement since the last build. Returns True when the neighbour lists must be rebuilt
    before the forces of this step."""
    dt = P.dt
    if B.c.shape[0] > 0:
        cl.body_kick(B, dt, P.planar)
        cl.body_drift(B, dt)
        cl.place_members(B.c, B.q, B.v, B.w, B.member, B.owner, B.offset, S.x, S.v, S.w)
        d2 = max(d2, cl.member_disp_sq(B.member, S.x, C.x_ref))
    wall = 0.0
    point, vel, normal, ref = W.point, W.vel, W.normal, W.point_ref
    for p in range(point.shape[0]):
        for c in range(3):
            point[p, c] += vel[p, c] * dt
        dn = abs((point[p, 0] - ref[p, 0]) * normal[p, 0] + (point[p, 1] - ref[p, 1]) * normal[p, 1]
                 + (point[p, 2] - ref[p, 2]) * normal[p, 2])
        wall = max(wall, dn)
    mx, mv, mref = M.x, M.v, M.x_ref
    for m in range(M.mat.shape[0]):
        if not M.moving[m]:           # static mesh: x += 0 dt and |x - x_ref| = 0 (msh.mesh_motion)
            continue
        for k in range(M.noff[m], M.noff[m + 1]):
            for c in range(3):
                mx[k, c] += mv[k, c] * dt
            d = (mx[k, 0] - mref[k, 0]) ** 2 + (mx[k, 1] - mref[k, 1]) ** 2 + (mx[k, 2] - mref[k, 2]) ** 2
            wall = max(wall, math.sqrt(d))
    disp = math.sqrt(d2) + wall
    return disp * disp > P.half_skin_sq


@njit(cache=True)
def forces_only(S, W, C, B, M, P):
    """Forces of the current state (start of a run): serial kernels, no kicks, no step bookkeeping."""
    fk.pair_forces_ser(S, C, P)
    fk.gather_pass_ser(S, W, C, P, 0)
    msh.mesh_pass_ser(S, M, P, False)
    if B.c.shape[0] > 0:
        cl.reduce_to_bodies(B.c, B.mass, P.gravity, B.member, B.owner, S.x, S.f, S.t, B.F, B.T)


def run_steps(nsteps, resume, S, W, C, B, M, P):
    """Advance up to nsteps velocity-Verlet steps. resume = True: the first half of the first step was done by the
    call that stopped for a rebuild. Returns (steps completed, 1 if the last step stopped after its first half for a
    neighbour-list rebuild, else 0)."""
    dt = P.dt
    has_mesh = M.mat.shape[0] > 0
    has_body = B.c.shape[0] > 0
    if nsteps == 0:
        return 0, 0
    msh.mesh_motion(M)
    if not resume:
        d2 = kick_pass(S, C, P, 2)
        if first_half_rest(S, W, C, B, M, P, d2):
            return 0, 1
    for s in range(nsteps):
        last = s == nsteps - 1
        mode = 1 if last else 3
        pair_forces(S, C, P)
        p_old = fk.plane_power(W, C) if W.moving else 0.0
        if has_mesh:
            gather_pass(S, W, C, P, 0)
            mesh_pass(S, M, P, True)
            d2 = kick_pass(S, C, P, mode)
        else:
            d2 = gather_pass(S, W, C, P, mode)
        if W.moving:
            P.wall_work[0] += 0.5 * (p_old + fk.plane_power(W, C)) * dt
        if has_body:
            cl.reduce_to_bodies(B.c, B.mass, P.gravity, B.member, B.owner, S.x, S.f, S.t, B.F, B.T)
            cl.body_kick(B, dt, P.planar)
            cl.body_spin(B)
            cl.place_members(B.c, B.q, B.v, B.w, B.member, B.owner, B.offset, S.x, S.v, S.w)
        if last:
            break
        if first_half_rest(S, W, C, B, M, P, d2):
            return s + 1, 1
    return nsteps, 0


run_steps_ser = njit(cache=True)(clone(run_steps, "run_steps_ser"))
run_steps_par = njit(cache=True)(clone(run_steps, "run_steps_par", {
    "pair_forces": fk.pair_forces_par, "gather_pass": fk.gather_pass_par, "kick_pass": it.kick_pass_par,
    "mesh_pass": msh.mesh_pass_par}))
RUN_STEPS = {False: run_steps_ser, True: run_steps_par}
