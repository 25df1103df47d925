"""Rescue the readable part of an MCAP file whose writer died before finishing it (no summary, no footer).

The file is scanned from the start without seeking, record by record, until the first record that cannot
be read (the chunk being written when the process died). Every record before it (schemas, channels,
messages, attachments, metadata) is copied unchanged into a new, finished file. `CaptureWriter` closes one
chunk per sample, so a torn capture loses at most the sample that was being added.
"""

from __future__ import annotations

from pathlib import Path
from typing import IO

from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory

from wolfcal.atomic import atomic_output
from wolfcal.errors import WolfcalError
from wolfcal.io.mcapfile import check_mcap
from wolfcal.io.msgdefs import COMPRESSED_IMAGE, IMU, JOINT_STATE, LIBRARY, header_stamp_ns
from wolfcal.outputs import check_outputs


def recovered_path(path: Path) -> Path:
    """Default output of `wolfcal recover`: capture.mcap(.partial) -> capture.recovered.mcap."""
    name = path.name.removesuffix(".partial").removesuffix(".mcap")
    return path.with_name(name + ".recovered.mcap")


def recover_capture(src: str | Path, dst: str | Path, force: bool = False) -> int:
    """Copy every readable record of `src` into a finished MCAP file `dst` (never `src` itself; an existing
    `dst` only with `force`).

    Returns the number of complete samples rescued: images with a joint state of the same stamp.
    """
    src, dst = Path(src), Path(dst)
    check_mcap(src)
    if dst.resolve() == src.resolve():
        raise WolfcalError(f"{src}: recovery never overwrites the torn file; give another --out FILE")
    check_outputs([dst], force, [src])
    with atomic_output(dst) as out, src.open("rb") as handle:
        count = _copy_records(handle, out)
    return count


def _copy_records(handle: IO[bytes], out: IO[bytes]) -> int:
    """Stream the readable records of `handle` into a new MCAP on `out`; returns the complete samples."""
    writer = McapWriter(out)
    writer.start(profile="ros2", library=LIBRARY)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    schema_ids: dict[int, int] = {}  # id in src -> id in dst
    channel_ids: dict[int, int] = {}
    decoders = DecoderFactory()
    stamps: dict[str, set[int]] = {JOINT_STATE: set(), COMPRESSED_IMAGE: set()}
    records = StreamReader(handle, validate_crcs=True).records
    while True:
        try:
            record = next(records)
        except StopIteration:
            break
        except Exception:  # the first unreadable record ends the readable part, whatever the error
            break
        if isinstance(record, Schema):
            schemas[record.id] = record
            schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
        elif isinstance(record, Channel):
            channels[record.id] = record
            channel_ids[record.id] = writer.register_channel(
                record.topic, record.message_encoding, schema_ids.get(record.schema_id, 0), record.metadata
            )
        elif isinstance(record, Message) and record.channel_id in channels:
            writer.add_message(
                channel_ids[record.channel_id],
                record.log_time,
                record.data,
                record.publish_time,
                record.sequence,
            )
            channel = channels[record.channel_id]
            schema = schemas.get(channel.schema_id)
            if schema is not None and schema.name in stamps:
                decode = decoders.decoder_for(channel.message_encoding, schema)
                if decode is not None:
                    stamps[schema.name].add(header_stamp_ns(decode(record.data).header, record.log_time))
        elif isinstance(record, Attachment):
            writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type, record.data)
        elif isinstance(record, Metadata):
            writer.add_metadata(record.name, record.metadata)
    writer.finish()
    return len(stamps[JOINT_STATE] & stamps[COMPRESSED_IMAGE])


def rescued_text(path: Path, samples: int) -> str:
    """What a rescued capture holds, for the console: its samples (an image with a joint state of the same stamp),
    or, for a capture without images (a standing one), its joint states and IMU messages."""
    if samples:
        return f"{samples} sample(s)"
    with path.open("rb") as handle:
        summary = make_reader(handle).get_summary()
    counts = {IMU: 0, JOINT_STATE: 0}
    if summary is not None and summary.statistics is not None:
        for channel_id, count in summary.statistics.channel_message_counts.items():
            channel = summary.channels[channel_id]
            name = summary.schemas[channel.schema_id].name if channel.schema_id in summary.schemas else ""
            if name in counts:
                counts[name] += count
    if counts[IMU]:
        return f"{counts[JOINT_STATE]} joint state(s) and {counts[IMU]} IMU message(s)"
    return "0 samples"
