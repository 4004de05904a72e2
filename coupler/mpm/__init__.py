"""Native explicit 2D MPM (issue #6): shapes, materials, kernels, scene, solver, bench.

Threading layer: OpenMP (coupler/__init__.py chooses it for every solver; numba's TBB layer leaks on every
parallel launch).
"""
