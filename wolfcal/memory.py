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
