"""Write a standing capture: continuous streams of sensor_msgs/msg/JointState (`joint_states_topic`) and
sensor_msgs/msg/Imu (`imu.topic`), each message with its own stamp, the layout of a plain ROS 2 recording
(`ros2 bag record /joint_states /imu/data`) that `wolfcal.io.imu` reads: still periods are found in the data.

Imu messages: `linear_acceleration` [m/s^2] and `angular_velocity` [rad/s] in the IMU frame (header.frame_id =
`imu.frame`); no orientation (orientation_covariance[0] = -1, REP 145); covariances unknown (zeros).

Durability as `CaptureWriter`: messages go into `<path>.partial`; `flush()` (after each stance) closes the chunk,
flushes and fsyncs, so a killed capture keeps every flushed message (`wolfcal recover` copies them into a finished
file); `close()` writes the summary and renames the
file to `<path>` (a file without any message is removed instead).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from wolfcal.atomic import make_folder
from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.io.mcapfile import partial_path
from wolfcal.io.msgdefs import IMU, JOINT_STATE, stamp_dict
from wolfcal.io.writer import finish_file, start_file

NO_ORIENTATION = [-1.0] + [0.0] * 8  # orientation_covariance of an IMU that gives no orientation (REP 145)


class StandingWriter:
    """One standing capture file (module docstring); `imu_topic`, `imu_frame` from the config's `imu:`."""

    def __init__(self, path: Path, config: RobotConfig, imu_topic: str, imu_frame: str):
        self.path, self.partial = Path(path), partial_path(Path(path))
        if self.partial.exists():
            raise WolfcalError(f"{self.partial} exists: an earlier capture did not finish; rescue what it holds with "
                               f"`wolfcal recover {self.partial}` or delete it, then capture again")  # fmt: skip
        self.joint_topic, self.imu_topic, self.imu_frame = config.joint_states_topic, imu_topic, imu_frame
        self.count = 0
        self._closed = False
        make_folder(self.path.parent)
        self._file = open(self.partial, "xb")  # closed in close()
        try:
            topics = [(self.joint_topic, JOINT_STATE), (imu_topic, IMU)]
            self._mcap, self._channels, self._encoders = start_file(self._file, config, topics, {})
        except BaseException:
            self._file.close()
            self.partial.unlink()
            raise

    def joint_state(self, stamp_ns: int, names: list[str], positions: np.ndarray, velocities: np.ndarray) -> None:
        """One JointState: positions [rad], velocities [rad/s]."""
        message = {"header": {"stamp": stamp_dict(stamp_ns), "frame_id": ""}, "name": list(names),
                   "position": [float(v) for v in positions], "velocity": [float(v) for v in velocities],
                   "effort": []}  # fmt: skip
        self._add(self.joint_topic, JOINT_STATE, stamp_ns, message)

    def imu(self, stamp_ns: int, accel: np.ndarray, gyro: np.ndarray) -> None:
        """One Imu: specific force [m/s^2] and rate of turn [rad/s] in the IMU frame."""
        message = {
            "header": {"stamp": stamp_dict(stamp_ns), "frame_id": self.imu_frame},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}, "orientation_covariance": NO_ORIENTATION,
            "angular_velocity": dict(zip("xyz", (float(v) for v in gyro))), "angular_velocity_covariance": [0.0] * 9,
            "linear_acceleration": dict(zip("xyz", (float(v) for v in accel))),
            "linear_acceleration_covariance": [0.0] * 9,
        }  # fmt: skip
        self._add(self.imu_topic, IMU, stamp_ns, message)

    def _add(self, topic: str, datatype: str, stamp_ns: int, message: dict) -> None:
        if self._closed:
            raise WolfcalError(f"{self.path}: the capture is closed")
        data = self._encoders[datatype](message)
        self._mcap.add_message(self._channels[topic], log_time=int(stamp_ns), data=data,
                               publish_time=int(stamp_ns), sequence=self.count)  # fmt: skip
        self.count += 1

    def flush(self) -> None:
        """Make every message so far durable."""
        self._mcap.flush()
        os.fsync(self._file.fileno())

    def close(self) -> Path | None:
        """Finish the file and rename it to `path`; returns `path`, or None if nothing was written."""
        if self._closed:
            return self.path if self.count else None
        self._closed = True
        return finish_file(self._mcap, self._file, self.partial, self.path, bool(self.count))
