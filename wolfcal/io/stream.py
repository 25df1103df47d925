"""Encoded images read back from MCAP files by location, as a stream.

The reader keeps only where each used image lies (`ImageLocation`), not its bytes; `stream_images` reads them
back when they are needed (detection, a figure) with mcap's reader: passes over the part of the file they
span, each image's bytes handed on and then dropped, so a long recording's images never sit in memory
together."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from itertools import groupby, islice
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import McapReader, make_reader

from wolfcal.errors import WolfcalError
from wolfcal.io.cdr import image_of


@dataclass(frozen=True, slots=True)
class ImageLocation:
    """Where an image message lies in an MCAP file."""

    path: Path
    topic: str
    log_time: int  # [ns] the message's log time (what the file's index is ordered by)
    stamp_ns: int  # [ns] its header stamp (tells apart messages of one topic with one log time)


WINDOW = 256  # images looked up per pass over the part of the file they span


def stream_images(locations: Iterable[ImageLocation]) -> Iterator[bytes]:
    """The encoded bytes of the image at each location, in the order given.

    Consecutive locations in one file are read in passes of `McapReader.iter_messages` over the time span of
    up to `WINDOW` of them, in the file's order (a pass holds the chunks it is reading and the images waiting
    for their turn, not the recording); an image that comes before its turn waits in memory until then (none
    waits when the order given is the file's, e.g. samples in stamp order). WolfcalError naming the file when
    an image is not found (the file changed since it was read)."""
    for path, run in groupby(locations, key=lambda location: location.path):
        yield from _stream_file(path, run)


def _stream_file(path: Path, wanted: Iterable[ImageLocation]) -> Iterator[bytes]:
    decoders: dict[int, Callable] = {}  # channel id -> its decoder
    run = iter(wanted)
    try:
        with path.open("rb") as handle:
            reader = make_reader(handle)
            while window := list(islice(run, WINDOW)):
                yield from _stream_window(path, reader, decoders, window)
    except (OSError, McapError) as exc:
        raise WolfcalError(f"{path}: cannot read its images again ({exc}); was the file moved or changed?") from None


def _stream_window(
    path: Path,
    reader: McapReader,
    decoders: dict[int, Callable],
    wanted: list[ImageLocation],
) -> Iterator[bytes]:
    """The images at `wanted` (one file), in that order, from one pass of mcap's reader over the time span
    they cover."""
    keys = [(w.topic, w.log_time, w.stamp_ns) for w in wanted]
    remaining: dict[tuple[str, int, int], int] = {}
    for key in keys:
        remaining[key] = remaining.get(key, 0) + 1
    times = {(topic, log_time) for topic, log_time, _ in keys}
    waiting: dict[tuple[str, int, int], bytes] = {}
    turn = 0
    topics = sorted({topic for topic, _, _ in keys})
    first, last = min(log_time for _, log_time, _ in keys), max(log_time for _, log_time, _ in keys)
    for schema, channel, message in reader.iter_messages(topics=topics, starting_at=first, ending_at=last):
        if (channel.topic, message.log_time) not in times:
            continue
        stamp, image = image_of(path, decoders, schema, channel, message)
        key = (channel.topic, message.log_time, stamp)
        if not remaining.get(key) or key in waiting:
            continue
        waiting[key] = bytes(image)  # the image alone, not the message around it
        while turn < len(keys) and keys[turn] in waiting:
            data = waiting[keys[turn]]
            remaining[keys[turn]] -= 1
            if not remaining[keys[turn]]:
                del waiting[keys[turn]]
            turn += 1
            yield data
    if turn < len(keys):
        topic, _, stamp = keys[turn]
        raise WolfcalError(
            f"{path}: the image on {topic} with stamp {stamp} ns is no longer in the file; was the file changed "
            "while wolfcal read it? Run again"
        )
