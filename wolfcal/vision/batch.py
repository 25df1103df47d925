"""Tag detection in many encoded images on all cores: decode once, detect, refine; bounded memory.

Images go to the workers in tasks of about PIXELS_PER_TASK (one image at 1280x960 and above, six at 512x384:
single large images keep both cores busy to the last image), of at least BATCH images for processes (each task
pickles its images), and at most 2 tasks per worker are under way at once, so memory stays bounded however many
images the input yields (it may be a lazy iterator over a long recording). A worker decodes an image, finds its
tags with OpenCV and keeps a crop around each (`wolfcal.vision.tags.find_tags`); the caller's thread refines the
corners of consecutive images' tags together, up to TAGS_PER_PASS tags and PASS_BYTES of crops a pass (`_refined`:
the refinement's cost is numpy's per call, so large images with one or two tags each are refined many at a time).
Results come back in input order, each what `wolfcal.vision.tags.detect_tags` returns for the decoded image (to
~1e-13 px: refined together, the sums run over padded arrays).

Workers are threads by default: the refinement (`wolfcal.vision.edges`) spends its time in OpenCV and in numpy's
large-array loops, which release the interpreter lock, and threads neither start processes nor pickle images.
`processes=True` is kept for callers whose own Python work would compete for the lock: the pool is started on
first use, kept for the life of the process, and its workers start from a fork server (spawn where there is
none), never by forking a process whose OpenCV threads are running; as with any use of multiprocessing, a script
that uses it must guard its top level with `if __name__ == "__main__":`.
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Callable, Generator, Iterable, Mapping, Sized
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from itertools import chain, islice
from typing import TYPE_CHECKING, Any

import numpy as np

from wolfcal.errors import WolfcalError

if TYPE_CHECKING:
    from wolfcal.vision.tags import PendingTags

Families = Mapping[str, "set[int] | None"]  # tag family -> ids to keep (None: all)
FamilyList = list[tuple[str, "frozenset[int] | None"]]  # the same, as the workers get it
Detections = dict[int, np.ndarray]  # tag id -> (4, 2) corners [px], aruco order, OpenCV pixel centres
BATCH = 4  # images per process task at least (each task pickles its encoded images)
# Pixels per task: one image at 1280x960 and above, six at 512x384 (a task's own cost is small against a small
# image's detection; the refinement takes consecutive tasks' tags together whatever their size)
PIXELS_PER_TASK = 1_200_000
# Bytes of crops waiting for one refinement pass at most (held on top of detection's own buffers): a pass takes
# about nine tags of a 2048x1536 image seen from a typical distance
PASS_BYTES = 4 * 1024 * 1024
IN_PROCESS = 3  # inputs of at most this many images are detected here, without a pool

_pool: ProcessPoolExecutor | None = None
_pool_workers = 0


def cpu_count() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _family_list(families: Families) -> FamilyList:
    return [(family, None if ids is None else frozenset(ids)) for family, ids in families.items()]


def _detect_batch(batch: list[bytes], families: FamilyList, refine: str) -> list[PendingTags | None]:
    """Decode each encoded image (png, jpeg, ...; None if undecodable) and find the tags of every family, their
    corners still to be refined (`_refined`); each image is dropped once its tags' crops are taken."""
    from wolfcal.io.images import decode_gray
    from wolfcal.vision.tags import find_tags

    wanted = {family: None if ids is None else set(ids) for family, ids in families}
    found: list[PendingTags | None] = []
    for data in batch:
        # straight to 8-bit gray: a colour jpeg decodes only its luma, within 1 grey level of decoding the colours
        # and converting them
        image = decode_gray(data)
        found.append(None if image is None else find_tags(image, wanted, refine))
    return found


def _refined(found: Iterable[PendingTags | None]) -> Generator[Detections | None, None, None]:
    """Each image's detections in input order (None for an undecodable image), the corners of consecutive images'
    tags refined together in passes of up to TAGS_PER_PASS tags and PASS_BYTES of crops (`refine_found`: its cost
    is mostly per call, not per tag). At most that many images wait for their pass."""
    from wolfcal.vision.edges import TAGS_PER_PASS
    from wolfcal.vision.tags import refine_found

    def refined(pending: list[PendingTags | None]) -> list[Detections | None]:
        results = iter(refine_found([p for p in pending if p is not None]))
        return [None if p is None else next(results) for p in pending]

    pending: list[PendingTags | None] = []
    count, size = 0, 0  # tags of `pending` to refine, and their crops' bytes
    for item in found:
        more = item.count() if item is not None else 0
        if count and count + more > TAGS_PER_PASS:
            yield from refined(pending)
            pending, count, size = [], 0, 0
        pending.append(item)
        count += more
        size += item.nbytes() if item is not None else 0
        if count == 0 or count >= TAGS_PER_PASS or size >= PASS_BYTES:  # nothing to wait for, or a full pass
            yield from refined(pending)
            pending, count, size = [], 0, 0
    yield from refined(pending)


def task_size(data: bytes, processes: bool) -> int:
    """Images per task: as many as make PIXELS_PER_TASK (by the first image's size; at least BATCH for
    processes, whose tasks pickle their images)."""
    from wolfcal.io.images import image_size

    size = image_size(data)
    by_pixels = max(1, PIXELS_PER_TASK // (size[0] * size[1])) if size else 1
    return max(by_pixels, BATCH if processes else 1)


def _one_opencv_thread() -> int:
    """Run OpenCV's functions on the calling thread alone (the worker threads are one per core already: OpenCV's own
    threads beside them only spin and wait); returns the number of threads to restore."""
    import cv2

    previous = cv2.getNumThreads()
    cv2.setNumThreads(1)
    return previous


def _worker_start() -> None:
    import cv2

    cv2.setNumThreads(1)  # one process per core: OpenCV's own threads would only compete


def _get_pool(workers: int) -> ProcessPoolExecutor:
    global _pool, _pool_workers
    if _pool is None or _pool_workers != workers:
        import multiprocessing  # only when processes are asked for

        if _pool is not None:
            _pool.shutdown(cancel_futures=True)
        method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        context = multiprocessing.get_context(method)
        if method == "forkserver":
            context.set_forkserver_preload(["wolfcal.vision.tags"])  # workers fork with cv2 already imported
        _pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_worker_start)
        _pool_workers = workers
    return _pool


def shutdown_pool() -> None:
    """Stop the worker processes (they are also stopped when the interpreter exits)."""
    global _pool
    if _pool is not None:
        _pool.shutdown()
        _pool = None


def iter_detect_encoded(
    images: Iterable[bytes],
    families: Families,
    refine: str = "edges",
    workers: int | None = None,
    batch: int | None = None,
    processes: bool = False,
    total: int | None = None,
) -> Generator[Detections | None, None, None]:
    """Detections of each encoded image in input order (None for an image that cannot be decoded), found on the
    workers and refined here (`_refined`).

    Tasks of `batch` images (default `task_size`); at most 2 * `workers` tasks are read ahead of the results.
    `workers`: threads, or processes if `processes` (default: one per core); 1 detects in this thread. Inputs of at
    most IN_PROCESS images are detected in this thread: `total`, how many images `images` yields if known, tells it
    at once, and the first task goes to a worker as soon as its images are read (else the first IN_PROCESS + 1
    images are read before any is detected, with the cores idle).
    """
    yield from _refined(_found_on_workers(images, families, refine, workers, batch, processes, total))


def _found_on_workers(
    images: Iterable[bytes],
    families: Families,
    refine: str,
    workers: int | None,
    batch: int | None,
    processes: bool,
    total: int | None,
) -> Generator[PendingTags | None, None, None]:
    """The tags found in each encoded image, in input order, their corners still to be refined (see
    `iter_detect_encoded`)."""
    workers = max(1, workers or cpu_count())
    names = _family_list(families)
    source = iter(images)
    head = list(islice(source, 1 if total is not None else IN_PROCESS + 1))
    if not head:
        return
    batch = batch or task_size(head[0], processes)
    depth = 2 * workers  # tasks under way
    stream = chain(head, source)
    if workers == 1 or (total if total is not None else len(head)) <= IN_PROCESS:
        while chunk := list(islice(stream, batch)):
            yield from _detect_batch(chunk, names, refine)
        return
    pool = _get_pool(workers) if processes else ThreadPoolExecutor(workers, thread_name_prefix="wolfcal-detect")
    pending: deque[Future] = deque()
    opencv_threads = _one_opencv_thread() if not processes else None
    try:
        while chunk := list(islice(stream, batch)):
            pending.append(pool.submit(_detect_batch, chunk, names, refine))
            if len(pending) >= depth:
                yield from pending.popleft().result()
        while pending:
            yield from pending.popleft().result()
    except BrokenProcessPool:
        shutdown_pool()
        raise WolfcalError(
            "a tag detection worker process died (out of memory, or a script that starts wolfcal without an "
            "`if __name__ == '__main__':` guard); close other programs and retry"
        ) from None
    finally:
        for future in pending:
            future.cancel()
        if not processes:
            pool.shutdown()
        if opencv_threads is not None:
            import cv2

            cv2.setNumThreads(opencv_threads)


def detect_encoded(images: Iterable[bytes], families: Families, **options: Any) -> list[Detections]:
    """Detect tags of `families` ({family: ids or None}) in every encoded image, on all cores -> per image
    {tag id: (4, 2) corners [px]}, as `detect_tags` gives them; `options`: those of `iter_detect_checked`."""
    return list(iter_detect_checked(images, families, **options))


def iter_detect_checked(
    images: Iterable[bytes],
    families: Families,
    refine: str = "edges",
    workers: int | None = None,
    progress: Callable[[int, int | None], None] | None = None,
    total: int | None = None,
    labels: Callable[[int], str] | None = None,
    processes: bool = False,
) -> Generator[Detections, None, None]:
    """`detect_encoded` as a stream, for a caller that may stop early (close the generator: the tasks under way
    are cancelled or finished, and no more images are read). `processes`: see the module docstring.

    `progress(done, total)` after each image (`total` as given, default len(images) if it has one); an image that
    cannot be decoded is a WolfcalError that names it by `labels(index)` (default "image <index>").
    """
    if total is None and isinstance(images, Sized):
        total = len(images)
    stream = iter_detect_encoded(images, families, refine, workers, processes=processes, total=total)
    try:
        for index, detections in enumerate(stream):
            if detections is None:
                name = labels(index) if labels else f"image {index}"
                raise WolfcalError(f"{name}: the image cannot be decoded (not a complete png or jpeg)")
            yield detections
            if progress:
                progress(index + 1, total)
    finally:
        stream.close()
