"""Checks on an MCAP file before reading it (present, an MCAP file at all, finished: has its footer), and the ROS 2
decoder of a channel (`channel_decoder`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from mcap.reader import McapReader
from mcap.records import Channel, Schema
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
