"""The `wolfcal` process as the entry point starts it (a fresh interpreter importing the CLI): numpy's BLAS on one
thread unless the user set it (wolfcal.blas_threads: threads on tall thin products only contend), and the fit path
loading neither OpenCV nor scipy until a fit needs them (scipy.sparse only for a sparse Jacobian: its array-API
layer loads numpy.f2py and numpy.testing)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from wolfcal.blas_threads import BLAS_VARIABLES

PROBE = """
import wolfcal.cli
from threadpoolctl import threadpool_info
print(min(p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"))
"""


def _probe(**extra: str) -> int:
    """The fewest threads of a BLAS library loaded in a fresh process that imported the CLI."""
    env = {k: v for k, v in os.environ.items() if k not in BLAS_VARIABLES} | extra
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True).stdout
    return int(out)


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="BLAS runs on one thread on one core anyway")
def test_cli_process_has_one_blas_thread():
    assert _probe() == 1


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="BLAS runs on one thread on one core anyway")
def test_cli_keeps_a_users_blas_setting():
    assert _probe(OPENBLAS_NUM_THREADS="2") == 2


def test_fit_path_loads_neither_opencv_nor_scipy():
    probe = "import sys, wolfcal.cli, wolfcal.fit.pipeline, wolfcal.fit.result; print(sorted(sys.modules))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    loaded = {name.strip("'") for name in out.strip("[]\n").split(", ")}
    assert "wolfcal.fit.pipeline" in loaded and "numpy" in loaded  # the probe sees the modules
    assert "cv2" not in loaded
    assert not {m for m in loaded if m.split(".")[0] == "scipy"} and "numpy.f2py" not in loaded
    assert "wolfcal.io.mocap_load" not in loaded and "mcap.writer" not in loaded
