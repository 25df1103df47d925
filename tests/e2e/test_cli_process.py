"""The `wolfcal` process as the entry point starts it (a fresh interpreter importing the CLI): numpy's BLAS on one
thread (wolfcal.blas_threads: threads on tall thin products only contend on a busy machine, measured 20x slower; the
variable must be set before numpy loads OpenBLAS), and the fit path loading neither OpenCV nor scipy until a fit
needs them (scipy.sparse only for a sparse Jacobian: its array-API layer loads numpy.f2py and numpy.testing)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

PROBE = """
import os, sys
import wolfcal.cli
import numpy as np
J = np.random.default_rng(0).normal(size=(4000, 38))
for _ in range(3):
    J.T @ J  # OpenBLAS starts its worker threads at load time; a product makes sure they would be running
threads = len(os.listdir("/proc/self/task"))
print(threads, os.environ["OPENBLAS_NUM_THREADS"])
"""

BLAS_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _probe(**extra: str) -> tuple[int, str]:
    env = {k: v for k, v in os.environ.items() if k not in BLAS_VARIABLES} | extra
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True).stdout
    threads, setting = out.split()
    return int(threads), setting


@pytest.mark.skipif(not os.path.isdir("/proc/self/task") or (os.cpu_count() or 1) < 2,
                    reason="counts threads in Linux's /proc; OpenBLAS starts no threads on one core")  # fmt: skip
def test_cli_process_has_one_blas_thread():
    threads, setting = _probe()
    assert setting == "1"
    assert threads == 1  # the interpreter's own thread only: no OpenBLAS workers


def test_cli_keeps_a_users_blas_setting():
    assert _probe(OPENBLAS_NUM_THREADS="2")[1] == "2"


def test_fit_path_loads_neither_opencv_nor_scipy():
    probe = "import sys, wolfcal.cli, wolfcal.fit.pipeline, wolfcal.fit.result; print(sorted(sys.modules))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    loaded = {name.strip("'") for name in out.strip("[]\n").split(", ")}
    assert "wolfcal.fit.pipeline" in loaded and "numpy" in loaded  # the probe sees the modules
    assert "cv2" not in loaded
    assert not {m for m in loaded if m.split(".")[0] == "scipy"} and "numpy.f2py" not in loaded
    assert "wolfcal.io.mocap_load" not in loaded and "mcap.writer" not in loaded
