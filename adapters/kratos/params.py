"""Parameter map native scene -> Kratos Multiphysics 10.4.4 (DEMApplication, MPMApplication). One place.

DEM (DEMApplication, `DEM_D_Hertz_viscous_Coulomb`, read from its sources: DEM_D_Hertz_viscous_Coulomb_CL.cpp and
sphere_strategy.py GammaForHertzThornton):

| native definition (coupler/dem/contact.py)            | Kratos DEM 10.4.4                                            |
|-------------------------------------------------------|--------------------------------------------------------------|
| E*, G* = 1/((2-nu1)/G1 + (2-nu2)/G2), R*, m*          | identical formulas (InitializeContact)                       |
| S_n = 2 E* sqrt(R* d), S_t = 8 G* sqrt(R* d)          | mKn = 2 E* sqrt(R* d), mKt = 4 G* mKn / E* (= S_t)           |
| F_n = max(0, 4/3 E* sqrt(R*) d^1.5 + gamma_n v_n)     | same, with the same F_n >= 0 clamp (normal dashpot trimmed)  |
| gamma = 2 beta sqrt(S m*), normal and tangential      | c = 2 DAMPING_GAMMA sqrt(m* mK), normal and tangential       |
| beta from restitution per damping mode                | DAMPING_GAMMA = Thornton et al. (2013) fit of the            |
|                                                       | COEFFICIENT_OF_RESTITUTION e' (sphere_strategy.py; e' > 0.999 |
|                                                       | -> 0): we pass the e' whose Kratos gamma equals the native    |
|                                                       | beta (kratos_restitution): "yade" -> e' = e (same fit),       |
|                                                       | "restitution" -> e' = inverse fit of beta_restitution(e)      |
|                                                       | (0.8 -> 0.800066), "liggghts" -> inverse fit of beta_liggghts.  |
|                                                       | The run script reads DAMPING_GAMMA back from every contact    |
|                                                       | sub-property and the parser refuses a run where it is not the |
|                                                       | native beta to 1e-9 (summary: kratos_damping_gamma)            |
| wall: R* = R, m* = m, wall E and nu from its material | rigid faces (RigidFace3D4N / 3D3N) carry their own            |
|                                                       | YOUNG_MODULUS and POISSON_RATIO: the wall's scene material is |
|                                                       | written as a separate Kratos material "<name>__wall" with the  |
|                                                       | same E, nu (R* = R - 0, m* = m in InitializeContactWithFEM)    |
| rigid wall (E*, G* from the sphere alone)             | "<name>__rigidwall" with YOUNG_MODULUS 1e12 x the largest     |
|                                                       | modulus, same nu and law (E* relative error < 2e-12)          |
| friction mu per material pair                         | STATIC_FRICTION = DYNAMIC_FRICTION = mu (FRICTION_DECAY moot) |
| tangential spring: total (secant), Coulomb cap on the | Kratos: incremental (tangent) spring, scaled by               |
| elastic part, no dashpot while sliding                | sqrt(d/d_prev) while unloading, Coulomb cap on elastic +      |
|                                                       | damping (elastic kept, dashpot trimmed first). NOT mappable:  |
|                                                       | differs in partial slip only (like YADE, notes P8); gross      |
|                                                       | sliding is the same law. Native "incremental" (YADE's law)     |
|                                                       | has no unloading scaling: also an approximation here           |
| native time integration                               | Kratos "Symplectic_Euler" (its default; its Velocity_Verlet   |
|                                                       | selects another, iterative strategy). Forces of a step are    |
|                                                       | those at its start positions (the parser labels them with that |
|                                                       | time). Measured: head-on force curves equal native to 2e-10    |
| planes (infinite)                                     | one RigidFace3D4N quadrilateral (no inner edge) covering the   |
|                                                       | region the spheres can reach (initial bounding box grown by    |
|                                                       | max speed * t_end + 4 R_max); the parser checks no sphere left |
|                                                       | it (else the run is refused)                                    |
| mesh walls (triangles)                                | RigidFace3D3N per triangle; edge/vertex handling is Kratos' own |
| moving walls (constant velocity)                      | RIGID_BODY_MOTION with LINEAR_VELOCITY of the wall sub-part     |
| planar (2D) scenes: spheres moving in the x-y plane   | 3D spheres with VELOCITY_Z, ANGULAR_VELOCITY_X/Y fixed to 0.    |
|                                                       | Kratos' own 2D DEM (CylinderParticle, per unit depth mass and   |
|                                                       | the 2D Hertz law) is a different body and law: not used         |
| energies                                              | kinetic, potential from the states; elastic and dissipated     |
|                                                       | not read back (NaN)                                             |
| contacts                                              | CONTACT_FORCES is the sum per sphere: one row for a sphere    |
|                                                       | touching exactly one body (geometric overlap); spheres with    |
|                                                       | more contacts are counted (summary: contacts_not_split)        |
Not expressible here (UnsupportedFeature): clusters (Kratos clusters take their mass properties from a
cluster file, not written here); a time-dependent gravity; tangential = "no_history".

MPM (MPMApplication, read from its tests and python_scripts):

| native                                  | Kratos MPM 10.4.4                                                  |
|-----------------------------------------|--------------------------------------------------------------------|
| background grid cell_size h             | structured Element2D4N quadrilateral grid of the same h           |
| shape_function linear / gimp / bspline2 | MPMUpdatedLagrangian2D4N: bilinear shape functions on the grid;    |
|                                         | gimp and bspline2 are not available for this element: the run is  |
|                                         | made with linear shapes and the summary says so (shape_note)       |
| particles_per_cell n per direction      | MATERIAL_POINTS_PER_ELEMENT = n^2 of Kratos' generator: its points |
|                                         | sit at the quadrilateral's Gauss points, not at the native cell    |
|                                         | sub-centres (n = 2 used and checked; others accepted, not tried)   |
| elastic                                 | LinearElasticIsotropicPlaneStrain2DLaw (small strain, updated      |
|                                         | Lagrangian)                                                        |
| mohr_coulomb (phi, c, psi)              | HenckyMCPlasticPlaneStrain2DLaw (finite strain, Mohr-Coulomb with  |
|                                         | friction/cohesion/dilatancy): same parameters; mu(I) rate:         |
|                                         | UnsupportedFeature                                                 |
| drucker_prager                          | UnsupportedFeature (not mapped here)                               |
| explicit USL/MUSL/APIC                  | Kratos implicit Newmark (its default "Newmark" scheme,             |
|                                         | displacement-based, Newton-Raphson): the transfer scheme of the    |
|                                         | scene is not used (transfer_note); dt = scene time.dt or the      |
|                                         | native CFL step, at least that                                     |
| boundary fixed / slip / open            | DISPLACEMENT fixed on the grid nodes of the side (both / normal   |
|                                         | component) / nothing                                               |
| boundary friction (Coulomb, mu)         | NOT expressible (UnsupportedFeature) unless the caller names the  |
|                                         | substitute (friction=..., see "Friction walls" below): "fixed"    |
|                                         | writes the side no-slip and says so (friction_note); "kratos_slip" |
|                                         | (diagnostics) writes ApplyMPMSlipBoundaryProcess on the side's    |
|                                         | LineCondition2D2N (option flip_normal as Kratos' friction test;   |
|                                         | without it the cap is 0), corner nodes shared with a fixed / slip |
|                                         | side fixed instead of slip nodes, stick penalty tangential_penalty |
|                                         | (native: exact grid-velocity Coulomb projection, no spring)       |
| gravity                                 | VOLUME_ACCELERATION on the material points                         |
| initial velocity (uniform per body)     | MP_VELOCITY of the body's material points                          |
| geostatic initial stress (k0)           | NOT expressible: HenckyMCPlasticPlaneStrain2DLaw (and the linear   |
|                                         | law) compute the stress from their own elastic strain, which       |
|                                         | starts at zero; a stress written onto a material point            |
|                                         | (MP_CAUCHY_STRESS_VECTOR) is overwritten at the first solve.       |
|                                         | Refused (UnsupportedFeature) unless the caller asks for            |
|                                         | stress_free_start=True: then the body starts stress-free with      |
|                                         | gravity from t = 0 and the summary says so (initial_stress_note).  |
|                                         | The Bui case does that and reports it: the column starts at rest, |
|                                         | unconfined, and builds its gravity stress in the first steps      |
|                                         | (the native starts at sigma_xx = K0 sigma_yy, K0 = 1 - sin phi)    |
| Newton iterations                       | ProcessInfo NL_ITERATION_NUMBER after every step (summary)        |
| Newton criterion                        | residual_criterion rtol 1e-4; displacement_criterion (rtol 1e-4)  |
|                                         | with a "kratos_slip" wall (convergence_criterion(); measured)     |
The native scene that solves what a Kratos MPM run solves (linear shapes, the friction substitute, the stress-free
start, Kratos' dt, FLIP; seeding and law stay different): native_same_discretization() (bench and
mpm_bui_implicit, issue 18).

Coupled MPM-DEM (CoSimulationApplication 10.4.4, adapters/kratos/cosim.py; set-up after Kratos' tests/mpm_dem):

| native                                   | Kratos                                                            |
|------------------------------------------|-------------------------------------------------------------------|
| [coupling] scheme gauss_seidel_weak      | coupled_solvers.gauss_seidel_weak, sequence dem -> mpm            |
| interface = boundary particles of the    | MPMGridPointLoadCondition2D1N on separate grid nodes along the    |
| top side, spacing h / ppc, nearest mapper | top side at spacing h / ppc (ends included), turned into material |
|                                          | point conditions (apply_mpm_coupling_interface_neumann_condition_ |
|                                          | process, 1 per condition); wrapper mpm_neumann_wrapper            |
| DEM interface wall (segments, moved with | RigidFacePart of RigidEdge2D2N segments through the same points,  |
| the MPM interface velocity)              | moved by MoveDemMesh with the mapped DISPLACEMENT / VELOCITY      |
| forces: time-averaged wall node forces,  | CONTACT_FORCES of the RigidFacePart nodes -> CONTACT_FORCE of the |
| transpose of the kinematic map, / thick- | MPM coupling nodes (kratos_mapping nearest_neighbor, use_transpose)|
| ness                                     | per unit depth (Kratos 2D), no thickness                          |
| DEM sphere R in one layer of thickness t | CylinderParticle2D disc R (mass rho pi R^2 per unit depth): equal |
|                                          | mass per depth when t = 4R/3 (the cantilever scene uses that)     |
| 3D Hertz F = 4/3 E* sqrt(R) d^1.5 (/ t)   | DEM_D_Hertz_viscous_Coulomb2D: LINEAR k_n = pi/4 E* per unit depth |
|                                          | (k_t from nu), same restitution passed: NOT the same law          |
| coupling step = MPM step (explicit CFL)  | coupling_dt argument (the case: 2e-3 s, Kratos' test), implicit    |
|                                          | Newmark MPM, Symplectic Euler DEM with the same step               |
| interface.csv (N for one layer)          | sums of the two force fields x scene thickness; work columns NaN  |
Refused for coupled scenes: clusters, planes, meshes, another mapper or scheme, more than one MPM body, a side
other than the top of a rectangle, friction grid walls.
"""
from __future__ import annotations

import numpy as np


from coupler.dem.contact import beta_liggghts, beta_restitution, beta_yade
from coupler.errors import UnsupportedFeature
from coupler.materials import ContactLaw
from coupler.scene import Scene

CODE = "kratos"
KRATOS_VERSION = "10.4.4"
E_MAX = 0.999                  # sphere_strategy.py GammaForHertzThornton: e > 0.999 -> gamma = 0
E_MIN = 0.001                  # and e < 0.001 is raised to 0.001


def kratos_gamma(e: float) -> float:
    """DAMPING_GAMMA Kratos computes from COEFFICIENT_OF_RESTITUTION e for a Hertz law (Thornton et al. 2013 fit,
    with Kratos' cut-offs). The fit is the one YADE's en= uses: beta_yade."""
    if e > E_MAX:
        return 0.0
    return beta_yade(max(e, E_MIN))


def restitution_for_gamma(beta: float) -> float:
    """The COEFFICIENT_OF_RESTITUTION whose Kratos DAMPING_GAMMA is beta (bisection; kratos_gamma decreases in e)."""
    if beta <= 0.0:
        return 1.0
    lo, hi = E_MIN, E_MAX
    if not (kratos_gamma(hi) <= beta <= kratos_gamma(lo)):
        raise UnsupportedFeature(CODE, "contacts.restitution",
                                 f"damping ratio {beta:g} is outside what Kratos' restitution fit can express "
                                 f"([{kratos_gamma(hi):g}, {kratos_gamma(lo):g}])")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if kratos_gamma(mid) > beta:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-15:
            break
    return 0.5 * (lo + hi)


def native_beta(law: ContactLaw) -> float:
    if law.damping == "restitution":
        return beta_restitution(law.restitution)
    if law.damping == "liggghts":
        return beta_liggghts(law.restitution)
    if law.damping == "yade":
        return beta_yade(law.restitution)
    raise ValueError(law.damping)


def kratos_restitution(law: ContactLaw) -> float:
    """The COEFFICIENT_OF_RESTITUTION to give Kratos so that its DAMPING_GAMMA equals the native beta."""
    if law.damping == "yade" and law.restitution <= E_MAX:
        return law.restitution
    return restitution_for_gamma(native_beta(law))


# rigid walls (`rigid = true`): the wall material "<material>__rigidwall" with YOUNG_MODULUS = RIGID_FACTOR x the
# largest modulus; Kratos' DEM-FEM Hertz E* = E_s E_w / (E_w (1 - nu_s^2) + E_s (1 - nu_w^2)) then differs from
# E_s / (1 - nu_s^2) by < 2e-12 relative (same contact-law relation as the material's elastic wall)
RIGID_FACTOR = 1e12


def wall_material(w) -> str:
    """The Kratos material name of a plane or mesh wall (one per wall material and rigidity)."""
    return w.material + ("__rigidwall" if getattr(w, "rigid", False) else "__wall")


def wall_base(kname: str) -> str:
    """The scene material of a Kratos wall material name."""
    return kname.rsplit("__", 1)[0]


def wall_young(scene: Scene, kname: str) -> float:
    """YOUNG_MODULUS of a Kratos wall material: the material's, or RIGID_FACTOR x the largest one when rigid."""
    if kname.endswith("__rigidwall"):
        return RIGID_FACTOR * max(m.young for m in scene.materials.values())
    return scene.materials[wall_base(kname)].young


def check_dem(scene: Scene) -> None:
    dem = scene.dem
    if dem.clusters:
        raise UnsupportedFeature(CODE, "dem.clusters", "Kratos clusters take their mass properties from a cluster "
                                                       "file; not written by this adapter")
    if scene.gravity_schedule is not None:
        raise UnsupportedFeature(CODE, "gravity_schedule", "a time-dependent gravity is not written in this adapter")
    for key, law in scene.contacts.items():
        if law.tangential == "no_history":
            raise UnsupportedFeature(CODE, f"contacts[{key[0]}, {key[1]}].tangential",
                                     "Kratos' Hertz law always keeps the tangential spring")
        kratos_restitution(law)
    for k, p in enumerate(dem.planes):
        if abs(float(p.normal @ p.normal) - 1.0) > 1e-9:
            raise UnsupportedFeature(CODE, f"dem.planes[{k}].normal", "must be a unit vector")


# ------------------------------------------------------------------------------------------------------------ MPM
MPM_LAWS = {"elastic": "LinearElasticIsotropicPlaneStrain2DLaw", "mohr_coulomb": "HenckyMCPlasticPlaneStrain2DLaw"}
MPM_ELEMENT = "MPMUpdatedLagrangian2D4N"
GRID_ELEMENT = "Element2D4N"


# Friction walls. Kratos 10.4.4's Coulomb wall (ApplyMPMSlipBoundaryProcess + MPMBoundaryRotationUtility, read from
# its sources and measured here) cannot express the native Coulomb friction:
#  1. its friction cap is mu x STICK_FORCE_X of the previous step, and STICK_FORCE_X accumulates the normal residual
#     of EVERY assembly of that step (ApplySlipCondition: STICK_FORCE[0] -= rLocalVector[j]; cleared once per step in
#     MPMResidualBasedBossakScheme::Predict), so the cap is mu x (number of Newton iterations) x N. Measured: an
#     elastic block (E 1e7) on a mu = 0.36 base under gravity tilted 30 deg (rigid answer: slides 36.9 mm in 0.2 s)
#     moves 1.0 mm; the base nodes' summed STICK_FORCE_X is 1,350 N/m against the block's normal weight 90 N/m, at
#     15 Newton iterations per step. Kratos' own friction_conforming test converges in one iteration per step (a
#     linear point-loaded block), where the cap is right. Without option flip_normal the cap is 0 (frictionless:
#     98.1 mm, the slip answer).
#  2. the stick state is a tangential penalty on each step's displacement increment (the grid is reset every step),
#     so a stuck node creeps F_t / k_t EVERY step: measured 0.339 mm in 200 steps at 10 deg (stick expected), as
#     200 F_t / k_t predicts; on the Bui column with the former penalty 0.1 E/h this crept the base row 4.6 cm.
# So a friction wall is refused unless the caller names the substitute (friction=...):
#  "fixed"        - the side is written no-slip (Kratos' own Bui example, granular_flow_2D, fixes its base), and the
#                   summary says so (friction_note). With 1. the Kratos friction wall sticks anyway: Bui h = 20 mm,
#                   RMS 11.67 mm (slip process, penalty 500 E/h) vs 11.78 mm (fixed), but 496 of 2,066 steps at
#                   the Newton maximum (8.1 iterations per step) vs none (2.8);
#  "kratos_slip"  - Kratos' slip process as it is (diagnostics), with a stick penalty sized so that the creep of 2.
#                   over the whole run stays below CREEP_MAX (tangential_penalty).
FRICTION_SUBSTITUTES = ("fixed", "kratos_slip")
CREEP_MAX = 1e-4              # [m] bound on the summed per-step stick creep of a "kratos_slip" wall over the run


def tangential_penalty(scene: Scene, mu: float, steps: int) -> float:
    """TANGENTIAL_PENALTY_COEFFICIENT [N/m^3, per unit wall area; Kratos multiplies by the nodal area] of a
    "kratos_slip" wall: steps x tau_max / CREEP_MAX with tau_max = mu rho g H of the heaviest body column (each step
    a stuck node creeps tau h / (k h); summed over the run <= CREEP_MAX). Bui h = 20 mm: 460 E/h."""
    g = float(np.linalg.norm(np.asarray(scene.gravity, float)[:2]))
    tau = max(mu * scene.materials[b.material].density * g * float(np.ptp(b.polygon[:, 1]))
              for b in scene.mpm.bodies)
    return steps * tau / CREEP_MAX


def convergence_criterion(scene: Scene, friction: str | None = None) -> str:
    """Kratos MPM Newton criterion: residual_criterion (Kratos' default in its MPM tests and its Bui example), but
    displacement_criterion with Kratos' friction wall (friction = "kratos_slip"): measured on the Bui column
    (h = 10 mm) with the residual criterion the Newton never met rtol 1e-4 once the base friction acts."""
    return ("displacement_criterion" if friction == "kratos_slip"
            and any(bc.kind == "friction" for bc in scene.mpm.boundary.values()) else "residual_criterion")


def check_mpm(scene: Scene, stress_free_start: bool = False, friction: str | None = None) -> None:
    mpm = scene.mpm
    if friction is not None and friction not in FRICTION_SUBSTITUTES:
        raise ValueError(f"friction: one of {FRICTION_SUBSTITUTES} or None, got {friction!r}")
    for side, bc in mpm.boundary.items():
        if bc.kind == "friction" and friction is None:
            raise UnsupportedFeature(CODE, f"mpm.boundary.{side}.kind",
                                     "Kratos 10.4.4's Coulomb wall caps the friction at mu x the normal force summed "
                                     "over the Newton iterations of the step, and its stick penalty creeps every "
                                     "step (params.py); friction='fixed' writes the side no-slip and says so")
    if scene.gravity_schedule is not None:
        raise UnsupportedFeature(CODE, "gravity_schedule", "a time-dependent gravity is not written in this adapter")
    if mpm.damping != 0.0:
        raise UnsupportedFeature(CODE, "mpm.damping", "the local non-viscous damping of the native MPM has no "
                                                      "Kratos MPM counterpart")
    if mpm.boundary_particles:
        raise UnsupportedFeature(CODE, "mpm.boundary_particles", "point-load boundary particles (coupling) are not "
                                                                 "written by this adapter")
    for k, b in enumerate(mpm.bodies):
        m = b.model
        if m.model not in MPM_LAWS:
            raise UnsupportedFeature(CODE, f"mpm.bodies[{k}].constitutive.model",
                                     f"only {', '.join(MPM_LAWS)} are mapped (to {', '.join(MPM_LAWS.values())})")
        if m.rate is not None:
            raise UnsupportedFeature(CODE, f"mpm.bodies[{k}].constitutive.rate", "mu(I) friction has no Kratos law")
        if b.k0 is not None and not stress_free_start:
            raise UnsupportedFeature(CODE, f"mpm.bodies[{k}].initial_stress",
                                     "Kratos' MPM laws compute the stress from their own elastic strain (it starts at "
                                     "zero): a geostatic initial stress cannot be prescribed (params.py); "
                                     "stress_free_start=True runs it stress-free and says so")
        if not 1 <= b.particles_per_cell <= 5:
            raise UnsupportedFeature(CODE, f"mpm.bodies[{k}].particles_per_cell", "Kratos' material point "
                                                                                   "generator takes 1..5 per direction")
        if not _is_rectangle(b.polygon):
            raise UnsupportedFeature(CODE, f"mpm.bodies[{k}].polygon", "only axis-aligned rectangles are meshed by "
                                                                       "this adapter")


def native_same_discretization(scene: Scene, dt: float, stress_free_start: bool = False,
                               friction: str | None = None) -> dict:
    """Scene overrides under which the NATIVE MPM solves what the Kratos run of `scene` (run with these options)
    solves, for same-work comparisons (issue 18): the shapes Kratos uses (bilinear: "linear"), the friction
    substitute on friction sides ("fixed" -> a no-slip side), a stress-free start when the run asks for one,
    Kratos' time step dt (its run summary) and a FLIP update of the point velocities (Kratos' Newmark updates a
    point's own velocity with the interpolated nodal accelerations; the native implicit solver: transfer "musl").
    What stays different, by construction: the seeding (Kratos' Gauss points vs the native cell sub-centres) and
    the law (Kratos' finite-strain Hencky Mohr-Coulomb)."""
    if friction not in (None, "fixed"):
        raise ValueError(f"friction: only the 'fixed' substitute has a native equivalent, got {friction!r}")
    ov: dict = {"mpm.shape_function": "linear", "mpm.transfer": "musl", "time.dt": float(dt)}
    for side, bc in scene.mpm.boundary.items():
        if bc.kind == "friction" and friction == "fixed":
            ov[f"mpm.boundary.{side}"] = {"kind": "fixed"}
    if stress_free_start:
        for k, b in enumerate(scene.mpm.bodies):
            if b.k0 is not None:
                ov[f"mpm.bodies[{k}].initial_stress"] = {"kind": "none"}
    return ov


def _is_rectangle(p) -> bool:
    """An axis-aligned rectangle given by its four corners."""
    xs, ys = sorted(set(round(float(v), 12) for v in p[:, 0])), sorted(set(round(float(v), 12) for v in p[:, 1]))
    return p.shape[0] == 4 and len(xs) == 2 and len(ys) == 2


def mpm_law(model: str) -> str:
    return MPM_LAWS[model]


def check_supported(scene: Scene, stress_free_start: bool = False, friction: str | None = None) -> None:
    """UnsupportedFeature naming the first scene feature Kratos (this adapter) cannot express."""
    if scene.coupling is not None:
        check_coupled(scene)
        return
    if scene.dem is not None:
        check_dem(scene)
    if scene.mpm is not None:
        check_mpm(scene, stress_free_start, friction)


def coupled_step(scene: Scene, dt: float | None) -> float:
    """The coupling step of a Kratos CoSimulation run (dt: the caller's, else the scene's coupling.dt). Kratos runs
    its MPM and its DEM at this one step (the DEM's MaxTimeStep, one DEM step per coupling step: gauss_seidel_weak
    has no sub-cycling), so the step must be given and the scene's DEM sub-steps must come to 1."""
    from coupler.dem.timestep import chosen_dt, dem_substeps
    from coupler.errors import SceneError
    dt = dt if dt is not None else scene.coupling.dt
    if dt is None:
        raise SceneError("coupling.dt", "must be given for the Kratos backend: Kratos runs its MPM and DEM at this "
                                        "one step (the native default, the MPM's CFL step, is not carried over)")
    n = dem_substeps(scene, dt)         # what the native coupler would take
    if n != 1:
        raise UnsupportedFeature(CODE, "coupling.dem_substeps",
                                 f"Kratos CoSimulation runs one DEM step per coupling step; this scene takes {n} "
                                 f"(coupling step {dt:g} s, DEM step {chosen_dt(scene):.3g} s)")
    return dt


# Why the coupled retaining wall (six rigid blocks of glued spheres) cannot be a Kratos CoSimulation run (read from
# the installed Kratos 10.4.4 wheels): the Kratos MPM-DEM coupling is 2D - the DEM partition of Kratos' mpm_dem
# set-up is CylinderParticle2D discs against RigidEdge2D2N interface segments (cosim.py) - and Kratos DEM registers
# rigid clusters only as 3D bodies: the element names in libKratosDEMCore.so are Cluster3D and SingleSphereCluster3D
# (no 2D cluster), built from a cluster file of 3D sphere positions with a 3D inertia tensor
# (DEMApplication/cluster_file_reader.py ReadClusterFile, sphere_strategy.py SetClusterInformationInProperties;
# mesh_creator_cluster.py writes "Begin Elements Cluster3D"). A 2D block of discs has no Kratos element.
KRATOS_NO_2D_CLUSTERS = ("Kratos DEM 10.4.4 has rigid clusters only as 3D bodies (Cluster3D / SingleSphereCluster3D "
                         "from a cluster file), while its MPM-DEM CoSimulation is 2D (CylinderParticle2D discs, "
                         "RigidEdge2D2N walls): no 2D cluster element exists to couple (adapters/kratos/params.py)")


def check_coupled(scene: Scene) -> None:
    c = scene.coupling
    if scene.dimension != 2:
        raise UnsupportedFeature(CODE, "dimension", "coupled Kratos runs are written for 2D scenes only")
    if c.scheme != "gauss_seidel_weak":
        raise UnsupportedFeature(CODE, "coupling.scheme", "only gauss_seidel_weak is written")
    if c.mapper != "nearest":
        raise UnsupportedFeature(CODE, "coupling.mapper", "only nearest (Kratos nearest_neighbor) is written")
    d = scene.dem
    if d.clusters:
        raise UnsupportedFeature(CODE, "dem.clusters", KRATOS_NO_2D_CLUSTERS)
    if d.planes:
        raise UnsupportedFeature(CODE, "dem.planes", "coupled Kratos runs are written with the interface wall as the "
                                                     "only DEM wall (no planes)")
    if any(m.name != c.wall_name for m in d.meshes):
        raise UnsupportedFeature(CODE, "dem.meshes", "coupled Kratos runs are written with the interface wall as the "
                                                     "only DEM wall (no meshes)")
    if len(scene.mpm.bodies) != 1:
        raise UnsupportedFeature(CODE, "mpm.bodies", "one coupled MPM body only")
    b = scene.mpm.bodies[0]
    if not _is_rectangle(b.polygon) or list(c.edges) != [2]:
        raise UnsupportedFeature(CODE, "coupling.sides", "only the top side of a rectangular body is written")
    if b.model.model != "elastic" and b.model.model != "mohr_coulomb":
        raise UnsupportedFeature(CODE, "mpm.bodies[0].constitutive.model", "elastic or mohr_coulomb only")
    for key, law in scene.contacts.items():
        if law.tangential == "no_history":
            raise UnsupportedFeature(CODE, f"contacts[{key[0]}, {key[1]}].tangential",
                                     "Kratos' Hertz law always keeps the tangential spring")
        kratos_restitution(law)
    for side, bc in scene.mpm.boundary.items():
        if bc.kind == "friction":
            raise UnsupportedFeature(CODE, f"mpm.boundary.{side}.kind", "friction walls are not written for "
                                                                         "coupled runs")


# Kratos' 2D DEM law, for a native run of the same physics (coupled_kratos_cantilever): DEM_D_Hertz_viscous_Coulomb2D
# (DEM_D_Hertz_viscous_Coulomb_2D_CL.cpp, InitializeContactWithFEM) is a LINEAR spring per unit depth,
# mKn = 0.7854 E* (KRATOS_M_PI_4), mKt = 4 G* mKn / E*, with the Hertz law's dashpots c = 2 gamma sqrt(m* mK) and
# gamma = DAMPING_GAMMA of the COEFFICIENT_OF_RESTITUTION we pass (kratos_restitution: the native Hertz beta).
KRATOS_PI_4 = 0.7854


def native_equivalent_of_2d_law(law: ContactLaw, sphere, wall, thickness: float) -> dict:
    """`[[contacts]]` fields of a native Hooke law that does on one DEM layer of `thickness` what Kratos' 2D disc-wall
    law does per unit depth: stiffness t * 0.7854 E*, tangential_ratio 4 G*/E*, and the restitution whose clamped
    linear impact has Kratos' damping ratio (damping = "restitution" inverts the clamped impact: beta = gamma to the
    bisection tolerance). A layer of mass t m' then moves as Kratos' disc of mass m' per depth: k/m and c/m agree."""
    from coupler.dem.contact import effective_shear, effective_young, restitution_clamped
    e_star, g_star = effective_young(sphere, wall), effective_shear(sphere, wall)
    gamma = native_beta(law)
    return {"normal": {"model": "hooke", "stiffness": thickness * KRATOS_PI_4 * e_star,
                       "tangential_ratio": 4.0 * g_star / e_star},
            "restitution": restitution_clamped(gamma, "hooke"), "damping": "restitution"}
