"""Partitioned MPM-DEM coupling (Singer et al. 2022/2023; Kratos CoSimulationApplication `gauss_seidel_weak`).

Layers (lower never imports higher):
  scene.py        the `[coupling]` table -> CouplingScene (+ the interface mesh wall injected into the DEM scene)
  interface.py    MPM boundary particles of the interface outline, the DEM wall polyline through them
  mappers/        one module per mapper (nearest, linear), registry in mappers/__init__.py
  partitions.py   DEMPartition / MPMPartition: the only place that knows the native solvers
  step_limit.py   the stable coupling step of an explicit MPM against the DEM contact on the interface wall
  schemes/        one module per coupling scheme (gauss_seidel_weak), registry in schemes/__init__.py
  solver.py       run_coupled(scene, out_dir, progress) -> Result (+ interface.csv)
"""
