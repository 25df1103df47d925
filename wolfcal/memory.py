"""Hand memory the process has freed back to the operating system between the phases of a long job.

glibc's allocator keeps freed heap pages (of every thread's arena) mapped: after reading a long recording or
detecting tags on worker threads, the resident size stays at the phase's peak although the data are gone, and the
next phase's peak lands on top of it. `malloc_trim(0)` returns those pages. Elsewhere (no glibc) this does nothing.
"""

from __future__ import annotations

import ctypes
from functools import cache


@cache
def _malloc_trim():
    try:
        return getattr(ctypes.CDLL(None), "malloc_trim", None)  # the C library the interpreter runs on
    except OSError:
        return None


def release_freed_memory() -> None:
    """Return the freed heap pages to the operating system (glibc), so the next phase starts from the live data."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


M_MMAP_THRESHOLD = -3  # glibc's mallopt parameter number
MMAP_THRESHOLD = 128 * 1024  # [bytes] glibc's initial value


@cache
def _mallopt():
    try:
        return getattr(ctypes.CDLL(None), "mallopt", None)
    except OSError:
        return None


def keep_large_blocks_mapped() -> None:
    """Blocks from MMAP_THRESHOLD up (numpy arrays of more than 16384 numbers) each get their own mapping, handed
    back when freed. glibc starts there but raises the threshold (up to 32 MB) whenever such a block is freed, after
    which a long fit's large transient arrays land on the heap, fragment it and stay resident: 9 MB of the
    6000-frame bench fit's peak (bench_stream, cached detections). Setting the threshold stops that adjustment.
    For the solve only: image buffers above it are mapped and zeroed afresh each time (reading and detecting 600
    frames at 2048x1536 took 9 s of system time instead of 1). Elsewhere (no glibc) this does nothing."""
    mallopt = _mallopt()
    if mallopt is not None:
        mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)
