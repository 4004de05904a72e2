"""Solver state handed to the compiled kernels: a few named tuples of arrays, so that a kernel signature reads like
its physics (`gather_pass(S, W, C, P, mode)`) instead of forty positional arrays.

  S  Spheres    per-sphere state (free spheres first, then cluster members)
  W  Planes     plane walls (and their reference positions at the last neighbour build)
  C  Lists      neighbour lists and per-contact state (rebuilt in Python at a rebuild)
  B  Bodies     rigid clusters (zero rows when the scene has none) and their prescribed motion
  M  Meshes     all mesh walls concatenated (per-mesh offsets), candidates, contact slots, node forces; per mesh
                whether its nodes move (set at the start of each compiled call) and the nodes its contacts touched
                in the last force pass (so a static mesh costs per contact, not per node, in a step); the
                contact records of the last pass (per sphere: count; per candidate row: face, weights, force)
  P  Params     time step, gravity, contact-law table, energy tracking and the rebuild threshold

Kernels unpack the fields they use into local names before their loops (numba passes tuples by value; the arrays
inside are shared with the Python side, so a kernel writes the solver's arrays in place).

`flavours(fn)` compiles one written-once kernel twice, serial and parallel (prange is range in the serial flavour),
as two functions with their own names, so numba's on-disk cache keeps them apart.
"""
from __future__ import annotations

import types
from collections import namedtuple

from numba import njit

Spheres = namedtuple("Spheres", "x v w q f t r mass mdamp mat body")
Planes = namedtuple("Planes", "point normal vel mat point_ref moving")
Lists = namedtuple("Lists", "offsets pi pj jstart jlist pstate pout woff wid wstate wout x_ref")
Bodies = namedtuple("Bodies", "c q v L w mass Ip F T member owner offset qtmp wtmp motion vp wp work")
Meshes = namedtuple("Meshes", "x v x_ref faces face_edges noff foff mat cand_off cand cbase slots node_force "
                              "node_acc out nout work drops moving touched ntouched mark ncon rec recf")
Params = namedtuple("Params", "dt planar gravity table track diss half_skin_sq dmax wall_work")

FREE, FIXED, VELOCITY = 0, 1, 2          # body motion kinds (Bodies.motion)
MOTION_KINDS = {"free": FREE, "fixed": FIXED, "velocity": VELOCITY}


def clone(fn, name: str, overrides: dict | None = None):
    """A copy of the Python function `fn` under a new name, its globals optionally overridden (the copy of the
    globals is taken now: call at the end of the defining module)."""
    g = fn.__globals__ if not overrides else {**fn.__globals__, **overrides}
    new = types.FunctionType(fn.__code__, g, name, fn.__defaults__, fn.__closure__)
    new.__qualname__ = name
    new.__doc__ = fn.__doc__
    new.__module__ = fn.__module__
    return new


def flavours(fn, name: str | None = None):
    """(serial, parallel) compiled flavours of a kernel written once with prange."""
    base = name or fn.__name__
    return (njit(cache=True)(clone(fn, base + "_ser")),
            njit(cache=True, parallel=True)(clone(fn, base + "_par")))
