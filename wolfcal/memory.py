"""Hand memory the process has freed back to the operating system between the phases of a long job.

glibc's allocator keeps freed heap pages (of every thread's arena) mapped: after reading a long recording or
detecting tags on worker threads, the resident size stays at the phase's peak although the data are gone, and the
next phase's peak lands on top of it. `malloc_trim(0)` returns those pages. How large blocks (image buffers, file
chunks; the solve's arrays) are placed: `buffers_from_heap`, `large_blocks_mapped`; a phase whose transient
blocks would spread the heap that its results live in: `in_own_arena`. Elsewhere (no glibc) this does nothing.
"""

from __future__ import annotations

import contextvars
import ctypes
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import cache
from typing import TypeVar

T = TypeVar("T")


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


M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameter numbers
SOLVE_MMAP_THRESHOLD = 1024 * 1024  # [bytes] blocks from this size up get their own mapping during the solve
MMAP_THRESHOLD_MAX = 32 * 1024 * 1024  # [bytes] the most glibc's own adjustment raises it to (64-bit)
HEAP_TRIM_THRESHOLD = 2 * MMAP_THRESHOLD_MAX  # [bytes] free heap top kept with buffers from the heap (glibc's own pair)
SOLVE_TRIM_THRESHOLD = 32 * 1024 * 1024  # [bytes] free heap top kept (not handed back) during the solve


def buffers_from_heap() -> None:
    """Blocks up to MMAP_THRESHOLD_MAX (image buffers, the file's chunks) come from the heap and are reused there
    once freed, from the first: what glibc's own adjustment reaches only after the first such block is freed, and
    what `large_blocks_mapped` leaves. Until then every large block gets a fresh mapping, zeroed page by page on
    first touch: the first fit in a process (every `wolfcal fit`) read and detected the 24-sample 2048x1536 camera
    capture with 66000-76000 page faults (0.2-0.35 s of system time, about a fifth of its CPU) against 20000-24000
    with the threshold set first, as in any later run. The heap then holds what a phase's peak needed, as it does
    after the adjustment; `release_freed_memory` hands it back between phases."""
    mallopt = _libc("mallopt")
    if mallopt is not None:
        mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_MAX)
        mallopt(M_TRIM_THRESHOLD, HEAP_TRIM_THRESHOLD)


@contextmanager
def large_blocks_mapped() -> Iterator[None]:
    """Inside, blocks from SOLVE_MMAP_THRESHOLD up (numpy arrays of more than 131072 numbers) each get their own
    mapping, handed back when freed. glibc starts at 128 KB but raises the threshold (up to MMAP_THRESHOLD_MAX)
    whenever such a block is freed, after which a long fit's large transient arrays land on the heap, fragment it and
    stay resident: 9 MB of the 6000-frame bench fit's peak (bench_stream, cached detections). Setting the threshold
    stops that adjustment for good, so on leaving it is set to MMAP_THRESHOLD_MAX, where the adjustment would have
    taken it: image buffers of later reading and detection (evaluate after fit in one process) come from the heap
    again instead of being mapped and zeroed afresh each time (reading and detecting 600 frames at 2048x1536 took
    9 s of system time instead of 1 under the low threshold). 1 MB, not glibc's 128 KB: every fresh mapping is
    zeroed page by page on first touch, and the solve's many arrays of 128 KB - 1 MB (Jacobian chunks, noise
    factors) cost page faults: a cached 400-sample leg fit 150000 (0.3 s of system time, of 1.9 s in all) against
    45000; the cached 600 / 6000-frame fits 0.46 / 5.2 s of system time against 0.23 / 4.4 s, their peaks 91 / 133
    MB against 93 / 137 MB. The free top of the heap is kept up to SOLVE_TRIM_THRESHOLD: glibc hands back what
    exceeds its trim threshold (128 KB unless its adjustment raised it before), and the solve's next arrays fault
    the same pages in again: a cached 1000-sample leg fit made 245000 page faults (0.6 s of system time) instead of
    36000 (0.2 s), peak 125 -> 128 MB (the cached 6000-frame fit's 143 -> 149 MB, below its detection's). On
    leaving, the trim threshold is set to twice MMAP_THRESHOLD_MAX, where glibc's own adjustment puts it
    (`buffers_from_heap`). Elsewhere (no glibc) this does nothing."""
    mallopt = _libc("mallopt")
    if mallopt is not None:
        mallopt(M_MMAP_THRESHOLD, SOLVE_MMAP_THRESHOLD)
        mallopt(M_TRIM_THRESHOLD, SOLVE_TRIM_THRESHOLD)
    try:
        yield
    finally:
        buffers_from_heap()


TRIM_BLOCK = 256 * 1024  # [bytes] a block freed to make glibc trim a thread's heap (>= its 64 KB consolidation size)


def release_thread_heap() -> None:
    """Hand back the free top of the calling thread's own heap (its glibc arena; on the main thread: the main heap's).

    glibc trims a thread's heap when a block of 64 KB or more is freed in it while its free top exceeds
    M_TRIM_THRESHOLD, which `buffers_from_heap` sets to 64 MB (image buffers are reused, not faulted in again), and
    `release_freed_memory` (malloc_trim) did not hand back what the detection threads' heaps kept after detection:
    a 600-frame fit at 2048x1536 held 91-100 MB before its solve, 77 MB with each detection thread calling this at
    the end (`wolfcal.vision.batch`), and the 6000-frame fit's solve, whose peak is that memory plus its own, peaked
    lower by as much. So a block is allocated and freed here with the threshold at 0, then the threshold is set back
    as `buffers_from_heap` sets it."""
    mallopt, malloc, free = _libc("mallopt"), _libc("malloc"), _libc("free")
    if mallopt is None or malloc is None or free is None:
        return
    malloc.restype, free.argtypes = ctypes.c_void_p, [ctypes.c_void_p]
    mallopt(M_TRIM_THRESHOLD, 0)
    try:
        free(malloc(TRIM_BLOCK))
    finally:
        mallopt(M_TRIM_THRESHOLD, HEAP_TRIM_THRESHOLD)


def in_own_arena(work: Callable[[], T]) -> T:
    """`work()` run on a thread of its own (the caller waits): its result, or its exception raised here.

    glibc gives each thread a heap of its own (an arena), so the blocks `work` allocates and frees come from that
    heap, not from the caller's. For reading a long file: its message buffers (an image each, 0.6 MB at 2048x1536)
    freed between the small blocks that live on (the pairing's state of each frame, kept to the end of the pass)
    left the main heap spread over 24-26 MB with a few live blocks every 0.8 MB (reading 6000 frames; 9 MB for 600);
    the results built after it (each sample's arrays) took the gaps, and the detection's image buffers that followed
    reused those gaps page by page: the main heap's resident size reached its span, 29-34 MB, against 16-19 MB after
    600 frames. Read on its own thread, the main heap after 6000 frames spans 7 MB and detection's streaming leaves
    it at 18 MB, as after 600; the reading thread's heap is free when it ends, and the next threads (detection's)
    take it up. The thread is a daemon: an interrupted caller does not wait for it at exit."""
    outcome: list = []
    context = contextvars.copy_context()  # the caller's settings (e.g. `--no-cache`) hold on the thread too

    def run() -> None:
        try:
            outcome.append((True, context.run(work)))
        except BaseException as exc:  # noqa: BLE001  (handed to the caller as it is)
            outcome.append((False, exc))

    thread = threading.Thread(target=run, name="wolfcal-own-arena", daemon=True)
    thread.start()
    thread.join()
    ok, value = outcome[0]
    if not ok:
        raise value
    return value
