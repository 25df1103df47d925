"""One BLAS thread for the command line process (`one_blas_thread`, which `wolfcal.cli` calls when it loads).

The fit's matrices are tall and thin (thousands of rows, tens of columns): BLAS threads gain nothing on them
and only contend with each other and with other busy processes. Parallel work (tag detection) runs on threads
of its own. A user's own setting (any of BLAS_VARIABLES in the environment) is kept. threadpoolctl limits the
BLAS libraries loaded when it is called: numpy's, which this module loads first.
"""

from __future__ import annotations

import os

BLAS_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread() -> None:
    """Limit numpy's BLAS to one thread, unless the user set one of BLAS_VARIABLES."""
    if any(variable in os.environ for variable in BLAS_VARIABLES):
        return
    import numpy  # noqa: F401  (its BLAS loaded, so that the limit reaches it)
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")
