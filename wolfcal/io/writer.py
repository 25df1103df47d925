"""Write capture files: one still sample = JointState + CompressedImage + CameraInfo with one header stamp.

The file is an MCAP file with ROS 2 messages (CDR, `ros2msg` schemas, profile `ros2`), so `ros2 bag` and
Foxglove open it. Durability: every sample is its own chunk, written, flushed and fsynced into
`<path>.partial` before `add_sample` returns; `close()` writes the summary (indexes, Statistics) and renames
the file to `<path>`. A process killed mid-capture leaves `<path>.partial`, from which `wolfcal recover`
rescues every sample that was added.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

import numpy as np
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_ros2._dynamic import serialize_dynamic

from wolfcal.atomic import replace_file
from wolfcal.camera.model import CameraModel
from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.io.images import encode_image
from wolfcal.io.mcapfile import partial_path
from wolfcal.io.msgdefs import CAMERA_INFO, COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS, stamp_dict

URDF_ATTACHMENT = "robot.urdf"
CONFIG_ATTACHMENT = "robot.yaml"
LIBRARY = "wolfcal"
# Chunks close only when a sample is complete (flush), never inside one: a torn file holds whole samples.
_NEVER = 2**62


def camera_info_message(camera: CameraModel, binning: tuple[int, int], stamp_ns: int, frame_id: str) -> dict:
    """sensor_msgs/CameraInfo of a full-resolution camera with images binned by `binning` (ROS convention)."""
    P = np.zeros((3, 4))
    P[:, :3] = camera.K
    return {
        "header": {"stamp": stamp_dict(stamp_ns), "frame_id": frame_id},
        "height": int(camera.height),
        "width": int(camera.width),
        "distortion_model": camera.distortion_model,
        "d": [float(v) for v in camera.D],
        "k": [float(v) for v in camera.K.ravel()],
        "r": [float(v) for v in np.eye(3).ravel()],
        "p": [float(v) for v in P.ravel()],
        "binning_x": int(binning[0]),
        "binning_y": int(binning[1]),
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


class CaptureWriter:
    """Context manager writing one capture file; see the module docstring for the guarantees.

    `camera` is the full-resolution model; images given to `add_sample` must have the binned size
    (camera.width // binning[0], camera.height // binning[1]).
    """

    def __init__(
        self,
        path: str | Path,
        robot_config: RobotConfig,
        camera: CameraModel,
        binning: tuple[int, int] = (1, 1),
        image_format: str = "png",
    ) -> None:
        self.path = Path(path)
        self.partial = partial_path(self.path)
        if image_format not in ("png", "jpeg"):
            raise WolfcalError(f"{self.path}: unknown image format {image_format!r}; use 'png' or 'jpeg'")
        if len(binning) != 2 or any(int(b) != b or b < 1 for b in binning):
            raise WolfcalError(f"{self.path}: binning must be two positive integers, found {binning!r}")
        if self.partial.exists():
            raise WolfcalError(
                f"{self.partial} exists: an earlier capture did not finish; rescue its samples with "
                f"`wolfcal recover {self.partial}` or delete it, then capture again"
            )
        self.config = robot_config
        self.camera = camera
        self.binning = (int(binning[0]), int(binning[1]))
        self.image_size = (camera.width // self.binning[0], camera.height // self.binning[1])
        self.image_format = image_format
        self.count = 0
        self._closed = False
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.partial, "xb")  # closed in close()
        try:
            self._mcap, self._channels, self._encoders = self._start(robot_config)
        except BaseException:  # e.g. an unreadable URDF: leave no .partial that blocks the next capture
            self._file.close()
            self.partial.unlink()
            raise

    def _start(self, config: RobotConfig) -> tuple[McapWriter, dict[str, int], dict[str, Callable]]:
        """Header, schemas, channels and attachments; durable on return."""
        mcap = McapWriter(self._file, chunk_size=_NEVER, compression=CompressionType.NONE)
        mcap.start(profile="ros2", library=LIBRARY)
        channels, encoders = {}, {}
        for topic, datatype in (
            (config.joint_states_topic, JOINT_STATE),
            (config.camera.topic, COMPRESSED_IMAGE),
            (config.camera.info_topic, CAMERA_INFO),
        ):
            schema_id = mcap.register_schema(datatype, "ros2msg", MSGDEFS[datatype].encode())
            channels[datatype] = mcap.register_channel(topic, "cdr", schema_id)
            encoders[datatype] = serialize_dynamic(datatype, MSGDEFS[datatype])[datatype]
        now = time.time_ns()
        for name, media_type, source in (
            (URDF_ATTACHMENT, "application/xml", config.urdf),
            (CONFIG_ATTACHMENT, "application/yaml", config.path),
        ):
            mcap.add_attachment(now, now, name, media_type, Path(source).read_bytes())
        mcap.flush()
        os.fsync(self._file.fileno())
        return mcap, channels, encoders

    def add_sample(
        self,
        stamp_ns: int,
        joint_names: list[str],
        positions: np.ndarray,
        velocities: np.ndarray | None,
        image: np.ndarray,
    ) -> None:
        """Append one still sample (positions [rad], velocities [rad/s] or None); durable on return."""
        if self._closed:
            raise WolfcalError(f"{self.path}: the capture is closed; open a new CaptureWriter")
        positions = np.asarray(positions, dtype=float).ravel()
        velocities = None if velocities is None else np.asarray(velocities, dtype=float).ravel()
        if len(positions) != len(joint_names) or (
            velocities is not None and len(velocities) != len(joint_names)
        ):
            raise WolfcalError(f"{self.path}: {len(joint_names)} joint names but positions/velocities differ")
        height, width = image.shape[:2]
        if (width, height) != self.image_size:
            raise WolfcalError(
                f"{self.path}: image of {width}x{height} px, but camera "
                f"{self.camera.width}x{self.camera.height} with binning {self.binning[0]}x{self.binning[1]} "
                f"gives {self.image_size[0]}x{self.image_size[1]}"
            )
        data, image_format = encode_image(image, self.image_format)
        header = {"stamp": stamp_dict(stamp_ns), "frame_id": self.config.camera.frame}
        messages = (
            (
                JOINT_STATE,
                {
                    "header": {"stamp": header["stamp"], "frame_id": ""},
                    "name": list(joint_names),
                    "position": positions.tolist(),
                    "velocity": [] if velocities is None else velocities.tolist(),
                    "effort": [],
                },
            ),
            (COMPRESSED_IMAGE, {"header": header, "format": image_format, "data": data}),
            (CAMERA_INFO, camera_info_message(self.camera, self.binning, stamp_ns, self.config.camera.frame)),
        )
        for datatype, message in messages:
            self._mcap.add_message(
                self._channels[datatype],
                log_time=int(stamp_ns),
                data=self._encoders[datatype](message),
                publish_time=int(stamp_ns),
                sequence=self.count,
            )
        self._sync()
        self.count += 1

    def close(self) -> Path | None:
        """Finish the file and rename it to `path`; returns `path`, or None if no sample was added."""
        if self._closed:
            return self.path if self.count else None
        self._closed = True
        self._mcap.finish()
        self._file.flush()
        os.fsync(self._file.fileno())
        self._file.close()
        if not self.count:  # an empty capture must not replace an earlier one
            self.partial.unlink()
            return None
        replace_file(self.partial, self.path)  # inside an output set: when the whole set is written
        return self.path

    def _sync(self) -> None:
        self._mcap.flush()
        os.fsync(self._file.fileno())

    def __enter__(self) -> CaptureWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

