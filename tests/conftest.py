"""Shared test setup."""

import os

# Before numpy loads: see calib_core/__init__.py (single-threaded BLAS).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
