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
