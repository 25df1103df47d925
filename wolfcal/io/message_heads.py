"""Reading only the first bytes of large messages of an MCAP file: the one fast path beside mcap's own reader.

A fit from cached detections needs of each image message only its stamp and, for a png, its size: reading the
images' bytes of a multi-GB recording (as `McapReader.iter_messages` does, chunk by chunk) would make a cached
fit wait for the disk. `iter_message_heads` gives the messages `iter_messages` gives, in its order, but of an
image in an uncompressed chunk reads only its head. It parses the chunk records of the MCAP specification
itself, so it is checked against mcap's reader (`tests/test_message_heads.py`); `WOLFCAL_MESSAGE_HEADS=0` in
the environment (or `ENABLED = False`) turns it off, and then every message is read whole by mcap's reader.
"""

from __future__ import annotations

import heapq
import io
import os
import struct
from collections.abc import Callable, Container, Iterator
from typing import IO, NamedTuple

from mcap.exceptions import McapError
from mcap.reader import McapReader
from mcap.records import Channel, ChunkIndex, Message, Schema

ENABLED = os.environ.get("WOLFCAL_MESSAGE_HEADS", "1") != "0"


class Head(NamedTuple):
    """A message of `iter_message_heads`: its data may be only the first bytes (`complete` False)."""

    schema: Schema | None
    channel: Channel
    message: Message
    complete: bool


def iter_message_heads(
    reader: McapReader,
    handle: IO[bytes],
    topics: list[str],
    heads: Container[str],
    head_bytes: int,
    enough: Callable[[Schema | None, bytes], bool],
) -> Iterator[Head]:
    """`reader.iter_messages(topics)`: the same messages in the same order (log time, then place in the file),
    but of a message on one of the `heads` topics in an uncompressed chunk only the first `head_bytes` of its
    data are read when `enough(schema, those bytes)` says so (e.g. an image whose header is all a reader
    needs): its other bytes are skipped, not read from the file. Files without a chunk index or with
    compressed chunks, and every file while `ENABLED` is False, are read whole (`iter_messages`). `handle`:
    the file `reader` reads."""
    summary = reader.get_summary()
    wanted = {c.id for c in summary.channels.values() if c.topic in topics} if summary else set()
    chunks = [c for c in summary.chunk_indexes if wanted & c.message_index_offsets.keys()] if summary else []
    if not ENABLED or summary is None or not chunks or any(c.compression for c in chunks):
        for schema, channel, message in reader.iter_messages(topics=topics):
            yield Head(schema, channel, message, True)
        return
    # the order of `iter_messages`: by log time, then chunk offset, then place in the chunk; a chunk is read
    # when its first log time comes up
    queue: list[tuple[int, int, int, Head | ChunkIndex]] = [
        (c.message_start_time, c.chunk_start_offset, -1, c) for c in chunks
    ]
    heapq.heapify(queue)
    while queue:
        _, _, _, item = heapq.heappop(queue)
        if isinstance(item, Head):
            yield item
            continue
        for index, head in _chunk_heads(handle, item, summary, wanted, heads, head_bytes, enough):
            heapq.heappush(queue, (head.message.log_time, item.chunk_start_offset, index, head))


_CHUNK_FIXED = struct.Struct("<QQQI")  # message start and end time, uncompressed size, uncompressed crc
_MESSAGE_FIXED = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_OPCODE_MESSAGE = 0x05


def _chunk_heads(
    handle: IO[bytes],
    chunk: ChunkIndex,
    summary,
    wanted: set[int],
    heads: Container[str],
    head_bytes: int,
    enough: Callable[[Schema | None, bytes], bool],
) -> Iterator[tuple[int, Head]]:
    """(index of the record in the chunk, message) of the wanted messages of one uncompressed chunk, read
    record by record (see `iter_message_heads`)."""
    handle.seek(chunk.chunk_start_offset + 1 + 8 + _CHUNK_FIXED.size)
    (length,) = struct.unpack("<I", _exactly(handle, 4))
    handle.seek(length, io.SEEK_CUR)  # the compression's name ('')
    (records,) = struct.unpack("<Q", _exactly(handle, 8))
    position, end = handle.tell(), handle.tell() + records
    index = 0
    while position < end:
        opcode, length = struct.unpack("<BQ", _exactly(handle, 9))
        position += 9 + length
        if opcode == _OPCODE_MESSAGE:
            channel_id, sequence, log_time, publish_time = _MESSAGE_FIXED.unpack(_exactly(handle, _MESSAGE_FIXED.size))
            size = length - _MESSAGE_FIXED.size
            if channel_id in wanted:
                channel = summary.channels[channel_id]
                schema = summary.schemas.get(channel.schema_id)
                data = _exactly(handle, min(size, head_bytes) if channel.topic in heads else size)
                complete = len(data) == size
                if not complete and not enough(schema, data):
                    data += _exactly(handle, size - len(data))
                    complete = True
                fields = {"channel_id": channel_id, "sequence": sequence, "log_time": log_time}
                message = Message(**fields, publish_time=publish_time, data=data)
                yield index, Head(schema, channel, message, complete)
        handle.seek(position)
        index += 1


def _exactly(handle: IO[bytes], count: int) -> bytes:
    """`count` bytes from `handle`; McapError when the file ends first."""
    data = handle.read(count)
    if len(data) != count:
        raise McapError(f"a chunk record ends {count - len(data)} byte(s) early")
    return data
