"""What the bench parts share: paths, running a snippet in a child process on a given source tree, statistics.

A "tree" is a folder holding the `wolfcal` package (this checkout, or an older one to compare with): the child
runs with it first on PYTHONPATH, so the same measurement runs on either. Peak memory is the child's own
(`os.wait4`), wall time the parent's clock around the child, CPU time the child's user + system time.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "wolfgang"


def config_of(tree: Path) -> Path:
    """The Wolfgang config of a checkout (an older tree reads its own: newer configs have keys it does not know)."""
    return tree / "configs" / "wolfgang"


DATA = Path(tempfile.gettempdir()) / "wolfcal_bench"  # generated inputs, kept between runs


@dataclass
class ChildRun:
    """One child process: what it printed last as JSON (or None), its wall [s], CPU [s] and peak RSS [MB]."""

    result: dict | None
    wall: float
    cpu: float
    peak_mb: float
    output: str


SPAWNER = r"""
import json, os, subprocess, sys, time
for line in sys.stdin:
    job = json.loads(line)
    start = time.perf_counter()
    child = subprocess.Popen(job["argv"], env=job["env"], cwd=job["cwd"], stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    output = child.stdout.read()
    child.stdout.close()
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    print(json.dumps({"output": output, "code": child.returncode, "wall": time.perf_counter() - start,
                      "cpu": usage.ru_utime + usage.ru_stime, "peak_kb": usage.ru_maxrss}), flush=True)
"""
_spawner: subprocess.Popen | None = None


def start_spawner() -> None:
    """Start the small process that starts every measured child. Linux counts the memory of the process a
    child was forked from into the child's peak (ru_maxrss keeps its high-water mark across exec), so children
    are started from this process, small because it is started before the harness loads anything large."""
    global _spawner
    if _spawner is None:
        _spawner = subprocess.Popen(
            [sys.executable, "-c", SPAWNER], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )


def run_child(tree: Path, argv: list[str], env: dict[str, str] | None = None) -> ChildRun:
    """Run `python argv...` with `tree` first on PYTHONPATH, from the spawner (`start_spawner`); SystemExit
    with its output when it fails."""
    start_spawner()
    assert _spawner is not None and _spawner.stdin is not None and _spawner.stdout is not None
    environment = {**os.environ, **(env or {}), "PYTHONPATH": str(tree)}
    job = {"argv": [sys.executable, *argv], "env": environment, "cwd": tempfile.gettempdir()}
    _spawner.stdin.write(json.dumps(job) + "\n")
    _spawner.stdin.flush()
    done = json.loads(_spawner.stdout.readline())
    output = done["output"]
    if done["code"]:
        raise SystemExit(f"child failed ({' '.join(argv[:3])} ...):\n{output[-3000:]}")
    last = next((line for line in reversed(output.splitlines()) if line.startswith("{")), None)
    return ChildRun(json.loads(last) if last else None, done["wall"], done["cpu"], done["peak_kb"] / 1024, output)


def median(values: list[float]) -> float:
    return float(statistics.median(values))


def summary(values: list[float]) -> dict:
    """Median, min and max of a list of figures, and the figures."""
    return {"median": median(values), "min": min(values), "max": max(values), "runs": values}


def alternating(trees: dict[str, Path], rounds: int) -> list[tuple[int, str, Path]]:
    """(round, label, tree) in an order that alternates which tree runs first, so a drift of the machine's
    speed between minutes falls on both alike."""
    labels = list(trees)
    order = []
    for k in range(rounds):
        for label in labels if k % 2 == 0 else labels[::-1]:
            order.append((k, label, trees[label]))
    return order
