"""How the allocator is set for large blocks (wolfcal.memory), observed in fresh processes by their page faults."""

from __future__ import annotations

import json
import platform
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="sets glibc's allocator")

# 4 rounds of 20 image-sized buffers (3 MB, 2048x1536 gray) alive together, written, then freed: the minor page
# faults of each round
ROUNDS = """
import json, resource, sys
import numpy as np
from wolfcal.memory import buffers_from_heap
if sys.argv[1] == "heap":
    buffers_from_heap()
faults = []
for _ in range(4):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    blocks = [np.empty(3 << 20, np.uint8) for _ in range(20)]
    for block in blocks:
        block.fill(1)
    del blocks
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
print(json.dumps(faults))
"""


def faults_per_round(mode: str) -> list[int]:
    run = subprocess.run([sys.executable, "-c", ROUNDS, mode], capture_output=True, text=True, check=True)
    return json.loads(run.stdout)


def test_freed_image_buffers_are_reused_from_the_first_round():
    """With `buffers_from_heap` the second round of buffers reuses the first's pages (60 MB: 15000 pages would be
    faulted in afresh); glibc's default maps each buffer of the first rounds on its own and hands it back when freed,
    so the second round faults every page again."""
    pages = (20 * (3 << 20)) // 4096
    heap, default = faults_per_round("heap"), faults_per_round("default")
    assert heap[0] > pages * 0.9 and default[0] > pages * 0.9  # the first round touches every page either way
    assert heap[1] < pages * 0.1 and max(heap[2:]) < pages * 0.1
    assert default[1] > pages * 0.9


def test_a_released_thread_heap_still_reuses_freed_buffers():
    """`release_thread_heap` sets the trim threshold back as `buffers_from_heap` leaves it: rounds of image buffers
    after it reuse most of the freed pages as before. Each release hands back the heap's free top beyond its live
    blocks, which the next round faults in again: 768 or 1536 of the 15360 pages here, by where the interpreter's own
    blocks lie (it depends on the folder the process starts in); without the reuse every page would be."""
    release = "from wolfcal.memory import release_thread_heap; release_thread_heap()\n    "
    script = ROUNDS.replace("faults.append(", release + "faults.append(")
    run = subprocess.run([sys.executable, "-c", script, "heap"], capture_output=True, text=True, check=True)
    faults, pages = json.loads(run.stdout), (20 * (3 << 20)) // 4096
    assert faults[0] > pages * 0.9 and max(faults[1:]) < pages * 0.2, faults


def test_each_detection_thread_releases_its_heap_once(monkeypatch):
    """At the end of detection every worker thread hands back its own heap's free top (`release_thread_heap`), one
    call on each: a thread that took two calls would leave another's heap as it was."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from wolfcal.vision import batch

    called: list[int] = []
    monkeypatch.setattr(batch, "release_thread_heap", lambda: called.append(threading.get_ident()))
    with ThreadPoolExecutor(3) as pool:
        batch._release_worker_heaps(pool, 3)
    assert len(called) == 3 and len(set(called)) == 3 and threading.get_ident() not in called


def test_work_in_its_own_arena_runs_on_a_thread_with_the_callers_settings():
    """`in_own_arena` returns the work's result or raises its exception, runs it on another thread, and the
    caller's context variables (`--no-cache`) hold there."""
    import threading

    from wolfcal.io.filememo import cache_enabled, caching
    from wolfcal.memory import in_own_arena

    with cache_enabled(False):
        thread, cached = in_own_arena(lambda: (threading.get_ident(), caching()))
    assert thread != threading.get_ident() and cached is False

    def fails() -> None:
        raise ValueError("from the thread")

    with pytest.raises(ValueError, match="from the thread"):
        in_own_arena(fails)
