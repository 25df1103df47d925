"""Read capture files and plain ROS 2 recordings (MCAP) into `Capture`s of still samples.

Cameras: the head camera ('head', topics `camera.topic` / `camera.info_topic`) and the config's external cameras
(`image_topic` / `info_topic`); a file may hold any of them (at least one), see `capture_topics`. A capture file
(written by `CaptureWriter`) holds one JointState per sample, with the stamp of the sample's images: every image is
used. Any other file is read as a recording: each camera's images are paired with the joint states around them and
kept only when the robot was still, and kept frames of different cameras within 0.02 s of each other form one sample
(see `wolfcal.io.recording`); each kept image names its still span (`SampleImage.span`: the camera's frames of one
still pose, `still_spans`), which a fit averages into one sample. Intrinsics per camera: see `intrinsics_choice`
(`--intrinsics` applies to the head camera only). One pass: frames are paired with the joint states as they are read
(`wolfcal.io.pairing`: a window of a few seconds of joint states; a file whose stamps are further out of order is
read again and paired on the whole log) and kept from stamps and image headers; a kept image holds only its location
in the file (`wolfcal.io.stream`), its bytes are read back when they are detected or drawn. Memory does not grow
with the images or the joint states. The images' checks are remembered beside the detection cache (`_Checks`,
`wolfcal.io.filememo`): a second read of an unchanged file takes them from there and reads only the first bytes of
each png image message (`iter_message_heads`), so a fit from cached detections reads no image.

Unusable data (`wolfcal.io.validate`, `wolfcal.camera.validate`): every CameraInfo and intrinsics file is validated
(errors name file, topic and field); joint states with NaN or infinite positions are left out with a note naming
file, topic, joint and count (an error when more than 20 % of them are); damaged images of any camera are left out
with a note naming camera, index and time (an error when more than 20 % of a camera's images are).
"""

from __future__ import annotations

import time
from array import array
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import IO, NamedTuple

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader

from wolfcal.camera.model import CameraModel
from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.io.capture_topics import check_topics
from wolfcal.io.cdr import camera_info_key, compressed_image, image_of, joint_state
from wolfcal.io.filememo import caching, identity_and_memo, read_memo, write_memo
from wolfcal.io.images import PNG_HEAD, image_damage, image_kind, image_size
from wolfcal.io.intrinsics_choice import InfoModel, IntrinsicsChooser, camera_info_model
from wolfcal.io.mcapfile import channel_decoder, check_mcap, is_finished, message_count, recover_hint, torn_error
from wolfcal.io.message_heads import iter_message_heads
from wolfcal.io.msgdefs import CONFIG_ATTACHMENT, URDF_ATTACHMENT, header_stamp_ns
from wolfcal.io.pairing import DISORDER_NS, Disorder, FramePairer, Pairing
from wolfcal.io.recording import SAMPLE_TOLERANCE_NS, Paired, group_by_stamp, still_spans
from wolfcal.io.samples import HEAD_CAMERA, Capture, Sample, SampleImage
from wolfcal.io.stream import ImageLocation
from wolfcal.io.validate import drop_damaged_images, finite_joint_note


def read_captures(
    paths: Iterable[str | Path], robot_config: RobotConfig, intrinsics: CameraModel | None = None
) -> list[Capture]:
    """`read_capture` of each file, in order."""
    return [read_capture(p, robot_config, intrinsics) for p in paths]


ProgressCallback = Callable[[int, int], None]  # (messages read, messages in the file)


def read_capture(
    path: str | Path,
    robot_config: RobotConfig,
    intrinsics: CameraModel | None = None,
    progress: ProgressCallback | None = None,
) -> Capture:
    """Read one capture file or ROS 2 recording; WolfcalError naming the file when it gives no samples.

    `intrinsics` (`--intrinsics`) replaces the head camera's; external cameras use their own CameraInfo or config.
    `progress(messages read, messages in the file)` is called now and then while reading.
    """
    path = Path(path)
    check_mcap(path)
    if not is_finished(path):
        raise torn_error(path)
    try:
        with path.open("rb") as handle:
            return _read(path, handle, robot_config, intrinsics, progress)
    except McapError as exc:
        raise WolfcalError(f"{path}: damaged MCAP file ({exc}); {recover_hint(path)}") from None


def require_cameras(captures: Iterable[Capture], cameras: Iterable[str], config: RobotConfig) -> None:
    """WolfcalError naming file and topic when a capture holds no image of one of `cameras` (e.g. the cameras a
    fit was asked to use). A camera the config does not name is refused first, with the config's message."""
    cameras = list(cameras)
    topics = {name: config.camera_topics(name)[0] for name in cameras}
    for capture in captures:
        for name in cameras:
            if not capture.samples_of(name):
                held = ", ".join(f"'{c}' ({config.camera_topics(c)[0]})" for c in capture.cameras) or "none"
                raise WolfcalError(
                    f"{capture.path}: no images of camera '{name}' (topic {topics[name]}); the file holds images of "
                    f"{held}. Give a capture of that camera, or choose the cameras the capture holds"
                )


class _Header(NamedTuple):
    """What the reader keeps of an image message."""

    stamp: int  # header stamp [ns]
    kind: str | None  # 'png' | 'jpeg' | None (anything else)
    size: tuple[int, int] | None  # (width, height) from the encoded header
    damage: str | None  # why the bytes are damaged, None when whole
    log_time: int  # [ns]


@dataclass(slots=True)
class _Frame:
    camera: str
    stamp: int
    image: SampleImage  # its location in the file, no bytes
    paired: Paired
    damage: str | None


@dataclass
class _PassOne:
    """What one pass over the file gives: the frames paired, each camera's image stamps (sorted) and CameraInfo."""

    pairing: Pairing
    stamps: dict[str, np.ndarray]  # camera -> (N,) int64 header stamps of all its images [ns], sorted
    infos: dict[str, list[tuple[int, InfoModel | None]]]
    checks: _Checks  # the damage found (or taken from the file's memo)


# The reader's memo of a file's image checks (`wolfcal.io.filememo`, kind 'images'); bump when `image_damage` or the
# messages it is applied to change
CHECKS_VERSION = 1
_CheckKey = tuple[str, int, int, int]  # (topic, log time [ns], header stamp [ns], index among the image messages read)


@dataclass
class _Checks:
    """`image_damage` of each image message of a file: the damaged ones by key, and how many messages were checked."""

    damaged: dict[_CheckKey, str]
    images: int = 0

    @classmethod
    def remembered(cls, path: Path) -> _Checks | None:
        """The checks remembered of this file as it is now (`read_memo`), None when there are none to trust."""
        memo = read_memo(path, "images")
        if memo is None or memo.get("version") != CHECKS_VERSION:
            return None
        try:
            damaged = {(str(t), int(lt), int(st), int(n)): str(why) for t, lt, st, n, why in memo["damaged"]}
            return cls(damaged, int(memo["images"]))
        except (KeyError, TypeError, ValueError):  # foreign
            return None

    def remember(self, path: Path, identity: list[int], taken_ns: int) -> None:
        """Write these checks as the file's memo (the file had `identity` when they began, at `taken_ns`)."""
        damaged = [[*key, why] for key, why in self.damaged.items()]
        write_memo(path, "images", identity, taken_ns, {"version": CHECKS_VERSION, "images": self.images,
                                                       "damaged": damaged})  # fmt: skip


def _pass_one(
    path: Path,
    reader,
    config: RobotConfig,
    cameras: list[str],
    info_cameras: set[str],
    progress: ProgressCallback | None,
    disorder_ns: int | None,
    *,
    handle: IO[bytes],
    known: _Checks | None = None,
) -> _PassOne:
    """Joint states and image headers paired as they are read (`FramePairer`), per-camera CameraInfo models.

    `known`: the file's image checks from its memo; then `image_damage` is not applied again: the memo holds its
    outcome for this very content (the file is unchanged since, `read_memo`), so the images left out and the notes
    naming them are the same. Otherwise every png and jpeg image is checked (its checksums: the one cost of this
    pass that grows with the images' bytes)."""
    image_topics = {config.camera_topics(n)[0]: n for n in cameras}
    info_topics = {config.camera_topics(n)[1]: n for n in info_cameras}
    pairer = FramePairer(disorder_ns)
    stamps: dict[str, array] = {n: array("q") for n in cameras}
    infos: dict[str, list[tuple[int, InfoModel | None]]] = {n: [] for n in cameras}
    models: dict[tuple, InfoModel | None] = {}  # CameraInfo models by their content
    by_bytes: dict[tuple[str, bytes], InfoModel | None] = {}  # the same by topic and message bytes but the stamp
    sizes: dict[tuple[int, int] | None, tuple[int, int] | None] = {None: None}  # one tuple per image size
    checks = _Checks({})
    topics = [config.joint_states_topic, *image_topics, *info_topics]
    total = message_count(reader, topics)
    decoders: dict[int, Callable] = {}
    names_seen: dict[bytes, list[str]] = {}  # a JointState's name list by its bytes (`joint_state`)
    # with the checks remembered, of a png only its header is read from the file (`_png_head`)
    messages = iter_message_heads(reader, handle, topics, image_topics if known else (), _HEAD_BYTES, _png_head)
    for count, (schema, channel, message, complete) in enumerate(messages):
        if progress is not None and count % 200 == 0:
            progress(count, total)
        if channel.topic in image_topics:
            image = image_of(path, decoders, schema, channel, message, complete)
            stamp = image[0]
            name = image_topics[channel.topic]
            # the checksums (known None) read the image where it lies, without a copy; kind and size come from a
            # png's first bytes, a jpeg's from anywhere in its header segments
            kind = image_kind(image[1])
            size = image_size(image[1][:PNG_HEAD] if kind == "png" else image[1])
            size = sizes.setdefault(size, size)
            damage = None
            if kind:
                check_key = (channel.topic, message.log_time, stamp, checks.images)
                damage = known.damaged.get(check_key) if known is not None else image_damage(image[1])
                if damage:
                    checks.damaged[check_key] = damage
            checks.images += 1
            header = _Header(stamp, kind, size, damage, message.log_time)
            stamps[name].append(stamp)
            pairer.add_frame(name, stamp, header, pair=header.kind is not None and header.size is not None)
            continue
        if channel.topic == config.joint_states_topic:
            joints = joint_state(message.data, schema, message.log_time, names_seen)
            if joints is None:  # not as `joint_state` reads it: the general decoder
                decoded = channel_decoder(path, decoders, channel, schema)(message.data)
                joints = (header_stamp_ns(decoded.header, message.log_time), decoded.name, decoded.position,
                          decoded.velocity)  # fmt: skip
            pairer.add_joints(*joints)
        else:
            info = _camera_info(path, decoders, schema, channel, message, models, by_bytes)
            infos[info_topics[channel.topic]].append(info)
    pairing = pairer.finish()
    if progress is not None:
        progress(total, total)
    return _PassOne(pairing, {n: np.sort(np.frombuffer(a, np.int64)) for n, a in stamps.items()}, infos, checks)


def _camera_info(
    path: Path,
    decoders: dict[int, Callable],
    schema,
    channel,
    message,
    models: dict[tuple, InfoModel | None],
    by_bytes: dict[tuple[str, bytes], InfoModel | None],
) -> tuple[int, InfoModel | None]:
    """(header stamp [ns], model) of a CameraInfo message; one model per distinct CameraInfo (`models`), and messages
    of the same bytes but their stamp decoded once (`camera_info_key`, `by_bytes`)."""
    known = camera_info_key(message.data, schema, message.log_time)
    if known is not None and (channel.topic, known[1]) in by_bytes:
        return known[0], by_bytes[channel.topic, known[1]]
    decoded = channel_decoder(path, decoders, channel, schema)(message.data)
    key = (channel.topic, decoded.width, decoded.height, decoded.distortion_model, tuple(decoded.k), tuple(decoded.d),
           decoded.binning_x, decoded.binning_y)  # fmt: skip
    if key not in models:
        models[key] = camera_info_model(path, channel.topic, decoded)
    if known is not None:
        by_bytes[channel.topic, known[1]] = models[key]
    return header_stamp_ns(decoded.header, message.log_time), models[key]


_HEAD_BYTES = 4096  # of an image message, read first: the CDR header, format and a png's header


def _png_head(schema, head: bytes) -> bool:
    """Whether the first bytes of an image message hold all the reader needs when the image checks are remembered:
    its stamp and a png's kind and size (else the whole message is read)."""
    image = compressed_image(head, schema, 0, complete=False)
    return image is not None and image_kind(bytes(image[1][:PNG_HEAD])) == "png"


def _read(
    path: Path,
    handle: IO[bytes],
    config: RobotConfig,
    intrinsics: CameraModel | None,
    progress: ProgressCallback | None,
) -> Capture:
    """Read an open file: pair and select frames per camera, leave out damaged images, group the frames into
    samples."""
    reader = make_reader(handle)  # messages decoded by `channel_decoder` or from their layout (`wolfcal.io.cdr`)
    found = check_topics(path, reader, config)
    info_cameras = {n for n in found.with_info if not (n == HEAD_CAMERA and intrinsics is not None)}
    identity, _ = identity_and_memo(path, "images")
    taken_ns = time.time_ns()
    known = _Checks.remembered(path) if caching() else None
    for checks in (known, None) if known is not None else (None,):
        one_pass = partial(_pass_one, path, reader, config, found.cameras, info_cameras, progress, handle=handle,
                           known=checks)  # fmt: skip
        try:
            read = one_pass(DISORDER_NS)
        except Disorder:  # stamps further out of order than the window allows: pair on the whole log
            read = one_pass(None)
        if checks is None or read.checks.images == checks.images:
            break
        known = None  # the memo counted other images: not the file it was taken of; checked again
    if known is None and caching():
        read.checks.remember(path, identity, taken_ns)
    pairing = read.pairing
    attachments = {a.name: a.data.decode("utf-8", errors="replace") for a in reader.iter_attachments()}
    skipped = finite_joint_note(path, config.joint_states_topic, pairing.messages, pairing.bad_messages,
                                pairing.bad_joints)  # fmt: skip
    del reader  # its index of the file's chunks
    frames: list[_Frame] = []
    for name in found.cameras:
        frames += _keep_frames(path, config, name, read, intrinsics, skipped)
    pairing.frames.clear()  # the pass's state of every frame: the samples are built in the room it leaves
    if not frames:
        counts = ", ".join(f"{len(read.stamps[n])} image(s) of '{n}' on {config.camera_topics(n)[0]}"
                           for n in found.cameras)  # fmt: skip
        why = f"; e.g. {skipped[0]}" if skipped else ""
        raise WolfcalError(
            f"{path}: no usable samples ({counts}, {pairing.messages} joint state(s) on "
            f"{config.joint_states_topic}{why}); record the robot holding still poses with the camera running"
        )
    frames = _drop_damaged(path, read.stamps, frames, skipped)
    samples = _group(path, pairing.names, frames, 0 if pairing.exact else SAMPLE_TOLERANCE_NS)
    return Capture(
        path=path,
        samples=samples,
        urdf_text=attachments.get(URDF_ATTACHMENT),
        robot_config_text=attachments.get(CONFIG_ATTACHMENT),
        skipped=skipped,
        cameras=[n for n in found.cameras if any(f.camera == n for f in frames)],
    )


def _keep_frames(
    path: Path,
    config: RobotConfig,
    name: str,
    read: _PassOne,
    intrinsics: CameraModel | None,
    skipped: list[str],
) -> list[_Frame]:
    """The still (or, in a capture file, stamped) frames of one camera; reasons for the others go to `skipped`.
    Frames stamped like a joint state that was left out (non-finite) are left out: `skipped` says so already."""
    chooser = IntrinsicsChooser(path, config, name, intrinsics)
    topic = config.camera_topics(name)[0]
    source = f"{path}: {topic}"  # one string for all the camera's images
    infos = read.infos[name]
    info_stamps = np.asarray([s for s, _ in infos], dtype=np.int64)
    mine = sorted((f for f in read.pairing.frames if f.camera == name), key=lambda f: f.stamp)
    start = int(read.stamps[name][0]) if len(read.stamps[name]) else 0
    kept: dict[int, _Frame] = {}
    readings: list[np.ndarray | None] = []  # per image in stamp order: its readings when kept (`still_spans`)
    for frame in mine:
        header: _Header = frame.item  # type: ignore[assignment]
        stamp, kind, size, damage, log_time = header
        where = f"'{name}' image {(stamp - start) / 1e9:.3f} s after its first (stamp {stamp} ns)"
        if kind is None or size is None:
            skipped.append(f"{where}: not a png or jpeg image")
            readings.append(None)
            continue
        paired = frame.result
        if frame.bad_stamp or not isinstance(paired, Paired):
            if not frame.bad_stamp:
                skipped.append(f"{where}: {paired}")
            readings.append(None)
            continue
        if stamp in kept:
            skipped.append(f"{where}: a second image with the same stamp")
            continue
        readings.append(paired.positions)
        info = infos[int(np.argmin(np.abs(info_stamps - stamp)))][1] if len(infos) else None
        location = ImageLocation(path, topic, log_time, stamp)
        image = SampleImage(b"", kind, chooser.for_image(size, info), source, stamp, location)
        kept[stamp] = _Frame(name, stamp, image, paired, damage)
    if not read.pairing.exact:  # a recording: its frames' still spans (a capture file's samples stand alone)
        spans = iter(span for span in still_spans(readings) if span >= 0)
        for kept_frame in kept.values():
            kept_frame.image.span = next(spans)
    return list(kept.values())


def _drop_damaged(
    path: Path,
    stamps: dict[str, np.ndarray],
    frames: list[_Frame],
    skipped: list[str],
) -> list[_Frame]:
    """The frames whose image is whole; the others are named (camera, index, time) in `skipped` (`stamps`: each
    camera's image stamps, sorted)."""
    whole: set[tuple[str, int]] = set()
    for name, sorted_stamps in stamps.items():
        damage = {f.stamp: f.damage for f in frames if f.camera == name}
        kept, notes = drop_damaged_images(path, name, damage, sorted_stamps.tolist())
        skipped += notes
        whole |= {(name, stamp) for stamp in kept}
    return [f for f in frames if (f.camera, f.stamp) in whole]


def _group(path: Path, names: list[str], frames: list[_Frame], tolerance_ns: int) -> list[Sample]:
    """Samples of frames grouped by stamp; a sample's stamp and joint readings are those of its first frame.
    The samples share one list of joint names and one source string (thousands of samples in a long recording)."""
    groups = group_by_stamp([f.stamp for f in frames], [f.camera for f in frames], tolerance_ns)
    names, source = list(names), str(path)
    readings = [frames[group[0]].paired for group in groups]
    # one block of readings, a row per sample: the pairing's small per-frame arrays (spread over the heap between
    # the file's message buffers, where they would keep its pages resident) are freed with the pairing
    positions = np.array([r.positions for r in readings], dtype=float).reshape(len(readings), len(names))
    velocities = np.array([r.velocities if r.velocities is not None else np.full(len(names), np.nan)
                           for r in readings], dtype=float).reshape(len(readings), len(names))  # fmt: skip
    samples = []
    for k, group in enumerate(groups):
        first = frames[group[0]]
        samples.append(
            Sample(
                stamp_ns=first.stamp,
                joint_names=names,
                positions=positions[k],
                images={frames[i].camera: frames[i].image for i in group},
                velocities=None if readings[k].velocities is None else velocities[k],
                source=source,
            )
        )
    return samples
