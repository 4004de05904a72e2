"""Implicit MPM (issue 18): Newmark-beta + Newton-Raphson on the background grid (solver.py), numba assembly
(kernels.py). Selected per scene with `[mpm] scheme = "implicit"`."""
