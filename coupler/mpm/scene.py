"""Parse the `[mpm]` table of a scene (errors name the field path and the allowed range).

Schema (SI units, 2D plane strain in x-y, `dimension = 2`):

    [mpm]
    shape_function = "bspline2"      # linear | gimp | bspline2 (coupler/mpm/shapes.py)
    transfer = "musl"                # usl | musl | apic (coupler/mpm/kernels.py)
    cfl = 0.5                        # dt = cfl h / (P-wave speed + initial speed) unless time.dt is given; (0, 1]
                                     # (the explicit scheme's step; scheme = "implicit" takes [mpm.implicit] cfl
                                     # and does not use this one)
    damping = 0.0                    # local non-viscous damping of the grid forces (Cundall 1987); [0, 1)
    boundary_particles = false       # outline points that carry point loads (coupling interface)
    scheme = "explicit"              # explicit | implicit (Newmark-beta + Newton-Raphson, coupler/mpm/implicit/)
    [mpm.implicit]                   beta = 0.25 (0, 0.5], gamma = 0.5 [0.5, 1], rtol = 1e-4 (> 0), atol = 1e-9 (> 0,
                                     N per unit depth), max_iter = 25 (>= 1), max_cuts = 4 (>= 0, halvings of a step
                                     that does not converge), line_search = true, linear_solver = "direct" |
                                     "iterative" (scipy spsolve | gmres + ILU), cfl = 5.0 (> 0: dt = cfl h / c
                                     unless time.dt is given; no stability limit, an accuracy choice),
                                     interface_velocity = "step_mean" | "newmark" (the boundary-particle velocity
                                     the coupler gives the DEM wall: displacement of the step / dt, or the Newmark
                                     end-of-step velocity, which with gamma > 0.5 drives a two-step oscillation
                                     of the weak coupling: coupled_implicit_resting_load), reuse_ratio = 0.0
                                     [0, 1) (modified Newton: the LU factor of the tangent is kept while each
                                     iteration reduces the residual at least by this factor, into the next step
                                     too while the active nodes, dt and the held wall dofs are unchanged; 0 = full
                                     Newton, a new tangent every iteration)
    boundary_sliver_fraction = 0.0  # [0, 0.5]: a support node of a boundary particle holding less than this fraction
                                     # of a full node's mass (rho h^2) takes a share of its load and velocity scaled
                                     # by its mass (coupler/mpm/kernels.py _sliver_weight; 0 = plain shape weights)
    max_dropped_load_fraction = 0.01 # [0, 1]: the run stops (SimulationError) when in one step more than this
                                     # fraction of the total point load |f| falls on boundary particles whose
                                     # support holds no grid mass (such loads are dropped; counted in summary.json)
    [mpm.grid]                       origin = [x, y], size = [Lx, Ly] (> 0), cell_size (> 0, divides size)
    [mpm.boundary]                   left/right/bottom/top = { kind = "fixed" | "slip" | "friction" | "open",
                                     friction = mu (>= 0, only with kind = "friction") }; default slip
    [[mpm.bodies]]
    name, material                   # material: a [materials.<name>] table (density, young, poisson)
    rectangle = { min = [..], max = [..] }  or  polygon = [[x, y], ...] (>= 3 vertices), inside the grid
    particles_per_cell = 2           # per direction, >= 1
    velocity = [vx, vy]              # initial, uniform
    constitutive = { model = "elastic" | "mohr_coulomb" | "drucker_prager", friction_angle [deg, 0..90),
                     cohesion [Pa, >= 0], dilatancy [deg, <= friction_angle],
                     rate = { delta_mu (> 0), i0 (> 0), grain_diameter [m, > 0], grain_density [kg/m3, > 0] } }
                                     # rate: optional mu(I) friction, mohr_coulomb only (coupler/mpm/materials.py)
                     disconnected = false }   # true: zero stress below the packing density (Dunatunga & Kamrin
                                     # 2015; coupler/mpm/constitutive/disconnected.py): mohr_coulomb /
                                     # drucker_prager with cohesion = 0, explicit scheme
    initial_stress = { kind = "none" | "geostatic", k0 = ..., surface = y_s }   # see _initial_stress
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from coupler.errors import SceneError
from coupler.fields import Table
from coupler.mpm.constitutive import LAWS as MODELS, ModelParams, RateParams
from coupler.mpm.shapes import REGISTRY as SHAPES

SIDES = ("left", "right", "bottom", "top")
BC_KINDS = ("fixed", "slip", "friction", "open")
TRANSFERS = ("usl", "musl", "apic")
# default mpm.boundary_sliver_fraction (kernels._sliver_weight)
SLIVER_FRACTION = 0.0


@dataclass(frozen=True)
class BoundarySide:
    kind: str = "slip"
    friction: float = 0.0


@dataclass(frozen=True)
class MPMBody:
    name: str
    material: str
    polygon: np.ndarray          # (k, 2) outline, counter-clockwise or not
    particles_per_cell: int      # per direction
    model: ModelParams
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    k0: float | None = None          # geostatic initial stress: sigma_xx = sigma_zz = k0 sigma_yy (None: stress-free)
    surface: float | None = None     # free-surface height of the geostatic state (default: top of the body)


@dataclass(frozen=True)
class ImplicitOptions:
    """`[mpm.implicit]` (coupler/mpm/implicit/solver.py)."""
    beta: float = 0.25
    gamma: float = 0.5
    rtol: float = 1e-4
    atol: float = 1e-9
    max_iter: int = 25
    max_cuts: int = 4
    line_search: bool = True
    linear_solver: str = "direct"
    cfl: float = 5.0
    interface_velocity: str = "step_mean"
    reuse_ratio: float = 0.0


SCHEMES = ("explicit", "implicit")
LINEAR_SOLVERS = ("direct", "iterative")
INTERFACE_VELOCITIES = ("step_mean", "newmark")


def _implicit_options(t: Table) -> ImplicitOptions:
    it = t.table("implicit", {})
    d = ImplicitOptions()
    o = ImplicitOptions(beta=it.number("beta", d.beta, gt=0.0, le=0.5),
                        gamma=it.number("gamma", d.gamma, ge=0.5, le=1.0),
                        rtol=it.number("rtol", d.rtol, gt=0.0), atol=it.number("atol", d.atol, gt=0.0),
                        max_iter=it.integer("max_iter", d.max_iter), max_cuts=it.integer("max_cuts", d.max_cuts),
                        line_search=it.boolean("line_search", d.line_search),
                        linear_solver=it.string("linear_solver", d.linear_solver, choices=LINEAR_SOLVERS),
                        cfl=it.number("cfl", d.cfl, gt=0.0),
                        interface_velocity=it.string("interface_velocity", d.interface_velocity,
                                                     choices=INTERFACE_VELOCITIES),
                        reuse_ratio=it.number("reuse_ratio", d.reuse_ratio, ge=0.0, lt=1.0))
    if o.max_iter < 1:
        raise SceneError(it.sub("max_iter"), f"must be >= 1, got {o.max_iter}")
    if o.max_cuts < 0:
        raise SceneError(it.sub("max_cuts"), f"must be >= 0, got {o.max_cuts}")
    it.done()
    return o


@dataclass(frozen=True)
class MPMScene:
    origin: np.ndarray
    size: np.ndarray
    cell_size: float
    boundary: dict
    bodies: list
    shape: str = "bspline2"
    transfer: str = "musl"
    cfl: float = 0.5
    boundary_particles: bool = False
    damping: float = 0.0
    max_dropped_load_fraction: float = 0.01
    scheme: str = "explicit"
    implicit: ImplicitOptions = field(default_factory=ImplicitOptions)
    boundary_sliver_fraction: float = SLIVER_FRACTION


def _initial_stress(bt: Table, model: str, nu: float, phi_deg: float, poly: np.ndarray):
    """`initial_stress = { kind = "geostatic", k0 = ..., surface = ... }` or kind "none" (default).
    Geostatic: sigma_yy = rho g_y (surface - y) (compression negative, g_y < 0), sigma_xx = sigma_zz = k0 sigma_yy,
    the state of a body at rest under gravity between lateral supports (a column before its gate is removed).
    Default k0: Jaky's 1 - sin(phi) for a plastic law, nu / (1 - nu) (oedometric) for the elastic law."""
    it = bt.table("initial_stress", {"kind": "none"})
    kind = it.string("kind", "none", choices=("none", "geostatic"))
    if kind == "none":
        it.done()
        return None, None
    k0_default = nu / (1.0 - nu) if model == "elastic" else 1.0 - math.sin(math.radians(phi_deg))
    k0 = it.number("k0", k0_default, gt=0.0)
    surf = it.number("surface", float(poly[:, 1].max()))
    if surf < float(poly[:, 1].max()) - 1e-12:
        raise SceneError(it.sub("surface"), f"must be >= the top of the body ({poly[:, 1].max():g}), got {surf:g}")
    it.done()
    return k0, surf


def inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Even-odd ray test, vectorised over points."""
    x, y = pts[:, 0], pts[:, 1]
    inside = np.zeros(len(pts), bool)
    k = len(poly)
    for a in range(k):
        (x1, y1), (x2, y2) = poly[a], poly[(a + 1) % k]
        cross = (y1 > y) != (y2 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        inside ^= cross & (x < xc)
    return inside


def seed_points(poly: np.ndarray, origin: np.ndarray, h: float, ppc: int) -> tuple[np.ndarray, float]:
    """A body's material points: the centres of the ppc x ppc sub-cells of the grid (spacing d = h / ppc) that lie
    inside its outline, in row order; (points (n, 2), d)."""
    d = h / ppc
    lo, hi = poly.min(0), poly.max(0)
    i0 = np.floor((lo - origin) / d + 1e-9).astype(int)
    i1 = np.ceil((hi - origin) / d - 1e-9).astype(int)
    gx = origin[0] + (np.arange(i0[0], i1[0]) + 0.5) * d
    gy = origin[1] + (np.arange(i0[1], i1[1]) + 0.5) * d
    P = np.array(np.meshgrid(gx, gy, indexing="xy")).reshape(2, -1).T
    return P[inside(poly, P)], d


def parse_mpm(t: Table, scene, base_dir: Path) -> MPMScene:
    if scene.dimension != 2:
        raise SceneError("dimension", "the MPM is 2D plane strain: set dimension = 2")
    g = t.table("grid")
    origin = g.vector("origin", 2)
    size = g.vector("size", 2, positive=True)
    h = g.number("cell_size", gt=0.0)
    g.done()
    for k in range(2):
        n = size[k] / h
        if abs(n - round(n)) > 1e-9 * max(1.0, n) or round(n) < 1:
            raise SceneError(f"mpm.grid.cell_size", f"must divide grid.size[{k}] = {size[k]:g} into whole cells, "
                             f"got {h:g} ({n:.6g} cells)")
    bt = t.table("boundary", {})
    boundary = {}
    for side in SIDES:
        st = bt.table(side, {"kind": "slip"})
        kind = st.string("kind", "slip", choices=BC_KINDS)
        mu = st.number("friction", 0.0, ge=0.0)
        if kind != "friction" and mu != 0.0:
            raise SceneError(st.sub("friction"), f"only used with kind = 'friction' (got kind {kind!r})")
        st.done()
        boundary[side] = BoundarySide(kind, mu)
    bt.done()
    shape = t.string("shape_function", "bspline2", choices=SHAPES)
    transfer = t.string("transfer", "musl", choices=TRANSFERS)
    cfl = t.number("cfl", 0.5, gt=0.0, le=1.0)
    bparts = t.boolean("boundary_particles", False)
    damping = t.number("damping", 0.0, ge=0.0, lt=1.0)
    max_drop = t.number("max_dropped_load_fraction", 0.01, ge=0.0, le=1.0)
    if t.has("boundary_sliver_fraction") and not bparts:
        raise SceneError(t.sub("boundary_sliver_fraction"), "only used with mpm.boundary_particles = true")
    sliver = t.number("boundary_sliver_fraction", SLIVER_FRACTION, ge=0.0, le=0.5)
    scheme = t.string("scheme", "explicit", choices=SCHEMES)
    if scheme != "implicit" and t.has("implicit"):
        raise SceneError(t.sub("implicit"), f"only used with mpm.scheme = 'implicit' (got {scheme!r})")
    imp = _implicit_options(t) if scheme == "implicit" else ImplicitOptions()
    if scheme == "implicit" and damping > 0.0:
        raise SceneError(t.sub("damping"), "the local (Cundall) damping is explicit-only; with scheme = 'implicit' "
                                           "use [mpm.implicit] gamma > 0.5 (Newmark numerical dissipation), got "
                                           f"{damping:g}")
    bodies = []
    lo, hi = origin, origin + size
    for bt_ in t.tables("bodies"):
        name = bt_.string("name", f"mpm{len(bodies)}")
        mname = bt_.string("material")
        if mname not in scene.materials:
            raise SceneError(bt_.sub("material"), f"unknown material {mname!r} "
                             f"(defined: {', '.join(sorted(scene.materials)) or 'none'})")
        mat = scene.materials[mname]
        ppc = bt_.integer("particles_per_cell", 2)
        if ppc < 1:
            raise SceneError(bt_.sub("particles_per_cell"), f"must be >= 1 (points per cell per direction), got {ppc}")
        if bt_.has("rectangle"):
            r = bt_.table("rectangle")
            a, b = r.vector("min", 2), r.vector("max", 2)
            r.done()
            if not (b[0] > a[0] and b[1] > a[1]):
                raise SceneError(bt_.sub("rectangle.max"), "must be > rectangle.min in both directions")
            poly = np.array([[a[0], a[1]], [b[0], a[1]], [b[0], b[1]], [a[0], b[1]]])
            key = "rectangle"
        elif bt_.has("polygon"):
            raw = bt_.raw_value("polygon")
            if not isinstance(raw, list) or len(raw) < 3:
                raise SceneError(bt_.sub("polygon"), "must be a list of >= 3 [x, y] vertices")
            from coupler.fields import check_vector
            poly = np.array([check_vector(f"{bt_.sub('polygon')}[{i}]", v, 2) for i, v in enumerate(raw)])
            key = "polygon"
        else:
            raise SceneError(bt_.sub("rectangle"), "a body needs a rectangle or a polygon")
        if np.any(poly < lo - 1e-12) or np.any(poly > hi + 1e-12):
            raise SceneError(bt_.sub(key), f"body lies outside the grid [{lo[0]:g}, {hi[0]:g}] x [{lo[1]:g}, {hi[1]:g}]")
        # bodies may touch, not overlap: two point sets in one region would double its mass
        pts, _ = seed_points(poly, origin, h, ppc)
        for other in bodies:
            n_in = int(inside(other.polygon, pts).sum())
            if n_in:
                raise SceneError(bt_.sub(key), f"overlaps body {other.name!r}: {n_in} of its {len(pts)} material "
                                               "points lie inside it (bodies may touch, not overlap)")
        ct = bt_.table("constitutive", {})
        model = ct.string("model", "elastic", choices=MODELS)
        phi = ct.number("friction_angle", 0.0, ge=0.0, lt=90.0)
        c = ct.number("cohesion", 0.0, ge=0.0)
        psi = ct.number("dilatancy", 0.0, ge=0.0, lt=90.0)
        if model != "elastic" and phi == 0.0 and c == 0.0:
            raise SceneError(ct.sub("cohesion"), "a plastic model needs friction_angle > 0 or cohesion > 0")
        if psi > phi:
            raise SceneError(ct.sub("dilatancy"), f"must be <= friction_angle ({phi:g}), got {psi:g}")
        rate = None
        if ct.has("rate"):
            if model != "mohr_coulomb":
                raise SceneError(ct.sub("rate"), f"the mu(I) friction is implemented for mohr_coulomb only, "
                                                 f"got model = {model!r}")
            rt = ct.table("rate")
            rate = RateParams(rt.number("delta_mu", gt=0.0), rt.number("i0", gt=0.0),
                              rt.number("grain_diameter", gt=0.0), rt.number("grain_density", gt=0.0))
            rt.done()
        disc = ct.boolean("disconnected", False)
        if disc and (model not in ("mohr_coulomb", "drucker_prager") or c != 0.0):
            raise SceneError(ct.sub("disconnected"), f"only for a cohesionless granular law (mohr_coulomb or "
                                                     f"drucker_prager with cohesion = 0), got model = {model!r}, "
                                                     f"cohesion = {c:g}")
        if disc and scheme != "explicit":
            raise SceneError(ct.sub("disconnected"), f"implemented in the explicit scheme only, got mpm.scheme = "
                                                     f"{scheme!r}")
        ct.done()
        vel = bt_.vector("velocity", 2, [0.0, 0.0])
        k0, surf = _initial_stress(bt_, model, mat.poisson, phi, poly)
        bt_.done()
        bodies.append(MPMBody(name, mname, poly, ppc,
                              ModelParams(model, mat.young, mat.poisson, phi, c, psi, rate, disc), vel, k0, surf))
    if not bodies:
        raise SceneError(t.sub("bodies"), "an [mpm] table needs at least one [[mpm.bodies]]")
    t.done()
    return MPMScene(origin, size, h, boundary, bodies, shape, transfer, cfl, bparts, damping, max_drop, scheme, imp,
                    boundary_sliver_fraction=sliver)
