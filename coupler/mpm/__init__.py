"""Native explicit 2D MPM (issue #6): shapes, materials, kernels, scene, solver, bench.

Threading layer: numba's TBB layer (picked by default when libtbb is installed, as on this machine with the
Debian TBB 2021.8) leaks on every parallel launch, so a run of 10^4 steps (several launches each) slows down
step after step (numba/numba#10225; measured here: launch cost grows by ~25 us per 1,000 launches). The MPM
therefore asks for OpenMP (then workqueue) unless the user chose a layer with NUMBA_THREADING_LAYER or a
parallel function already ran in this process (the layer is fixed at the first launch).
"""
import os as _os

import numba as _numba
from numba.np.ufunc import parallel as _parallel

if not _os.environ.get("NUMBA_THREADING_LAYER") and not _parallel._is_initialized:
    _numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
