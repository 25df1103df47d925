"""One BLAS thread for the command line process; `wolfcal.cli` imports this module before anything imports numpy.

The fit's matrices are tall and thin (thousands of rows, tens of columns): BLAS threads only contend, and with another
busy process on a 2-core machine a multi-threaded product became 20x slower (measured: J^T J of a (4000, 38) Jacobian,
0.3 ms with one thread, 3-12 ms with two). Parallel work (tag detection) uses processes. A user's own setting is kept.
OpenBLAS reads the variable once, when numpy loads it: set after that, it has no effect (`tests/e2e/test_cli_process.py`).
"""

from __future__ import annotations

import os

for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")
