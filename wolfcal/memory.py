"""Hand memory the process has freed back to the operating system between the phases of a long job.

glibc's allocator keeps freed heap pages (of every thread's arena) mapped: after reading a long recording or
detecting tags on worker threads, the resident size stays at the phase's peak although the data are gone, and the
next phase's peak lands on top of it. `malloc_trim(0)` returns those pages. Elsewhere (no glibc) this does nothing.
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache


@cache
def _libc(name: str):
    """The C library's function `name` (the library the interpreter runs on), or None where it has none."""
    try:
        return getattr(ctypes.CDLL(None), name, None)
    except OSError:
        return None


def release_freed_memory() -> None:
    """Return the freed heap pages to the operating system (glibc), so the next phase starts from the live data."""
    trim = _libc("malloc_trim")
    if trim is not None:
        trim(0)


M_MMAP_THRESHOLD = -3  # glibc's mallopt parameter number
MMAP_THRESHOLD = 128 * 1024  # [bytes] glibc's initial value
MMAP_THRESHOLD_MAX = 32 * 1024 * 1024  # [bytes] the most glibc's own adjustment raises it to (64-bit)


@contextmanager
def large_blocks_mapped() -> Iterator[None]:
    """Inside, blocks from MMAP_THRESHOLD up (numpy arrays of more than 16384 numbers) each get their own mapping,
    handed back when freed. glibc starts there but raises the threshold (up to MMAP_THRESHOLD_MAX) whenever such a
    block is freed, after which a long fit's large transient arrays land on the heap, fragment it and stay resident:
    9 MB of the 6000-frame bench fit's peak (bench_stream, cached detections). Setting the threshold stops that
    adjustment for good, so on leaving it is set to MMAP_THRESHOLD_MAX, where the adjustment would have taken it:
    image buffers of later reading and detection (evaluate after fit in one process) come from the heap again
    instead of being mapped and zeroed afresh each time (reading and detecting 600 frames at 2048x1536 took 9 s of
    system time instead of 1 under the low threshold). Elsewhere (no glibc) this does nothing."""
    mallopt = _libc("mallopt")
    if mallopt is not None:
        mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)
    try:
        yield
    finally:
        if mallopt is not None:
            mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_MAX)
