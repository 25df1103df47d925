"""Checks on an MCAP file before reading it (present, an MCAP file at all, finished: has its footer), the ROS 2
decoder of a channel (`channel_decoder`), and reading only the first bytes of large messages (`iter_message_heads`)."""

from __future__ import annotations

import heapq
import io
import struct
from collections.abc import Callable, Container, Iterator
from pathlib import Path
from typing import IO, NamedTuple

from mcap.exceptions import McapError
from mcap.reader import McapReader
from mcap.records import Channel, ChunkIndex, Message, Schema
from mcap_ros2.decoder import DecoderFactory

from wolfcal.errors import WolfcalError

MAGIC = b"\x89MCAP0\r\n"


def partial_path(path: Path) -> Path:
    """The temporary name a capture is written under until it is closed."""
    return path.with_name(path.name + ".partial")


def recover_hint(path: Path) -> str:
    """What to tell a user holding a torn or damaged file."""
    return f"run `wolfcal recover {path}` to rescue the samples in it"


def check_mcap(path: Path) -> None:
    """WolfcalError naming `path` when it is missing, a folder or not an MCAP file."""
    if path.is_dir():
        inside = sorted(p.name for p in path.glob("*.mcap"))
        hint = f"give the .mcap file(s) in it, e.g. {path / inside[0]}" if inside else "it holds no .mcap file"
        raise WolfcalError(f"{path}: is a folder, not a capture file; {hint}")
    if not path.is_file():
        partial = partial_path(path)
        if partial.is_file():
            raise WolfcalError(
                f"{path}: capture file not found, but {partial} exists: that recording did not finish; "
                f"{recover_hint(partial)}"
            )
        raise WolfcalError(f"{path}: capture file not found; check the path")
    with path.open("rb") as handle:
        start = handle.read(len(MAGIC))
    if start != MAGIC:
        raise WolfcalError(
            f"{path}: not an MCAP file (it does not start with the MCAP magic bytes); give a capture file "
            "written by `wolfcal capture` or a ROS 2 recording in MCAP format (`ros2 bag record -s mcap`)"
        )


def is_finished(path: Path) -> bool:
    """Whether the file ends with the closing MCAP magic, i.e. its writer finished it."""
    size = path.stat().st_size
    if size < 2 * len(MAGIC):
        return False
    with path.open("rb") as handle:
        handle.seek(size - len(MAGIC))
        return handle.read(len(MAGIC)) == MAGIC


def torn_error(path: Path) -> WolfcalError:
    """The error for a file without its closing footer."""
    return WolfcalError(
        f"{path}: was not closed properly (the recording stopped before it finished); {recover_hint(path)}"
    )


def message_count(reader: McapReader, topics: list[str]) -> int:
    """Messages on `topics` according to the file's statistics (0 when it has none)."""
    summary = reader.get_summary()
    if summary is None or summary.statistics is None:
        return 0
    counts = summary.statistics.channel_message_counts
    return sum(counts.get(c.id, 0) for c in summary.channels.values() if c.topic in topics)


def channel_decoder(path: Path, decoders: dict[int, Callable], channel: Channel, schema: Schema | None) -> Callable:
    """The ROS 2 decoder of the channel's messages, made once per channel (kept in `decoders`, channel id ->
    decoder); a WolfcalError naming the file and topic when there is none (not a ROS 2 CDR recording)."""
    if channel.id not in decoders:
        decoder = DecoderFactory().decoder_for(channel.message_encoding, schema)
        if decoder is None:
            raise WolfcalError(f"{path}: topic {channel.topic}: no decoder for its {channel.message_encoding} messages "
                               "(wolfcal reads ROS 2 CDR recordings)")  # fmt: skip
        decoders[channel.id] = decoder
    return decoders[channel.id]


class Head(NamedTuple):
    """A message of `iter_message_heads`: its data may be only the first bytes (`complete` False)."""

    schema: Schema | None
    channel: Channel
    message: Message
    complete: bool
    offset: int | None = None  # where the message's data begin in the file [bytes] (None: read by mcap's reader)


def iter_message_heads(
    reader: McapReader,
    handle: IO[bytes],
    topics: list[str],
    heads: Container[str],
    head_bytes: int,
    enough: Callable[[Schema | None, bytes], bool],
    starting_at: int | None = None,
    ending_at: int | None = None,
) -> Iterator[Head]:
    """`reader.iter_messages(topics, starting_at=, ending_at=)` (log times [ns], both inclusive): the same messages in
    the same order (log time, then place in the file), but of a message on one of the `heads` topics in an
    uncompressed chunk only the first `head_bytes` of its data are read when `enough(schema, those bytes)` says so
    (e.g. an image whose header is all a reader needs): its other bytes are skipped, not read from the file, and
    `Head.offset` says where they are. Files without a chunk index or with compressed chunks are read whole
    (`iter_messages`). `handle`: the file `reader` reads."""
    summary = reader.get_summary()
    wanted = {c.id for c in summary.channels.values() if c.topic in topics} if summary else set()
    low = -1 if starting_at is None else starting_at
    high = 1 << 64 if ending_at is None else ending_at
    chunks = [c for c in summary.chunk_indexes if wanted & c.message_index_offsets.keys()
              and c.message_start_time <= high and c.message_end_time >= low] if summary else []  # fmt: skip
    if summary is None or not chunks or any(c.compression for c in chunks):
        for schema, channel, message in reader.iter_messages(topics=topics, starting_at=starting_at,
                                                             ending_at=ending_at):  # fmt: skip
            yield Head(schema, channel, message, True)
        return
    # the order of `iter_messages`: by log time, then chunk offset, then place in the chunk; a chunk is read when
    # its first log time comes up
    queue: list[tuple[int, int, int, Head | ChunkIndex]] = [(c.message_start_time, c.chunk_start_offset, -1, c)
                                                            for c in chunks]  # fmt: skip
    heapq.heapify(queue)
    while queue:
        _, _, _, item = heapq.heappop(queue)
        if isinstance(item, Head):
            yield item
            continue
        for index, head in _chunk_heads(handle, item, summary, wanted, heads, head_bytes, enough, (low, high)):
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
    times: tuple[int, int],
) -> Iterator[tuple[int, Head]]:
    """(index of the record in the chunk, message) of the wanted messages of one uncompressed chunk with log times in
    `times` (first, last) [ns], read record by record (see `iter_message_heads`)."""
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
            if channel_id in wanted and times[0] <= log_time <= times[1]:
                channel = summary.channels[channel_id]
                schema = summary.schemas.get(channel.schema_id)
                offset = handle.tell()
                data = _exactly(handle, min(size, head_bytes) if channel.topic in heads else size)
                complete = len(data) == size
                if not complete and not enough(schema, data):
                    data += _exactly(handle, size - len(data))
                    complete = True
                fields = {"channel_id": channel_id, "sequence": sequence, "log_time": log_time}
                message = Message(**fields, publish_time=publish_time, data=data)
                yield index, Head(schema, channel, message, complete, offset)
        handle.seek(position)
        index += 1


def _exactly(handle: IO[bytes], count: int) -> bytes:
    """`count` bytes from `handle`; McapError when the file ends first."""
    data = handle.read(count)
    if len(data) != count:
        raise McapError(f"a chunk record ends {count - len(data)} byte(s) early")
    return data
