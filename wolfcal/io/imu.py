"""Standing samples from ROS 2 recordings (and capture files) of joint states and sensor_msgs/msg/Imu.

One sample per still period: a run of IMU messages in which the robot held still, found from the data, never
assumed. An IMU message is still when, over +-STILL_WINDOW_S around it, no axis of the accelerometer scatters by more
than ACCEL_SCATTER_M_S2 (std) and the gyro's rate stays below GYRO_STILL_RAD_S (when the IMU reports one:
angular_velocity_covariance[0] = -1 marks it absent), and no joint reading changes by more than one encoder tick in
the window. A still period is a run of still messages at least MIN_STILL_S
long after EDGE_S is trimmed from both ends, in which every joint stayed within one encoder tick. Its sample: the
mean specific force in the IMU frame [m/s^2] (`linear_acceleration`, which ROS gives in m/s^2), the per-joint median
reading [rad], the accelerometer's scatter and the number of messages. `orientation` (the IMU's own filter) is not
used: it carries the filter's bias and is often marked absent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from wolfcal.errors import WolfcalError
from wolfcal.io.mcapfile import check_mcap, is_finished, recover_hint, torn_error
from wolfcal.io.msgdefs import IMU, header_stamp_ns
from wolfcal.io.recording import ENCODER_TICK, JointStates

STILL_WINDOW_S = 0.25  # half-width of the stillness window [s]
ACCEL_SCATTER_M_S2 = 0.15  # largest per-axis std of the accelerometer in a still window [m/s^2]
GYRO_STILL_RAD_S = 0.05  # largest rate of turn in a still window [rad/s] (about 3 deg/s)
MIN_STILL_S = 1.0  # shortest still period that makes a sample, after trimming [s]
EDGE_S = 0.2  # trimmed from both ends of a still period [s]
GRAVITY_RANGE_M_S2 = (7.0, 12.5)  # the median |specific force| of a standing robot must lie here [m/s^2]
G_UNITS_RANGE = (0.5, 2.0)  # ... and lies here when the driver gives it in g


@dataclass
class StandingSamples:
    """Still periods of a standing robot: what the accelerometer measured and the joints read."""

    joint_names: list[str]
    q_measured: np.ndarray  # (S, J) per-joint median reading of each still period [rad]
    accel: np.ndarray  # (S, 3) mean specific force in the IMU frame [m/s^2]
    scatter: np.ndarray  # (S,) largest per-axis std of the accelerometer in the period [m/s^2]
    n_messages: np.ndarray  # (S,) IMU messages averaged
    stamps_ns: np.ndarray  # (S,) middle of the period [ns]
    sources: list[str]  # (S,) file of each period
    notes: list[str] = field(default_factory=list)  # periods left out and why

    @property
    def n_samples(self) -> int:
        return len(self.q_measured)

    def subset(self, keep: np.ndarray) -> StandingSamples:
        """The samples where `keep` (S,) bool or indices."""
        idx = np.arange(self.n_samples)[keep]
        return StandingSamples(self.joint_names, self.q_measured[idx], self.accel[idx], self.scatter[idx],
                               self.n_messages[idx], self.stamps_ns[idx], [self.sources[i] for i in idx],
                               list(self.notes))  # fmt: skip

    @staticmethod
    def joined(parts: list[StandingSamples]) -> StandingSamples:
        first = parts[0]
        return StandingSamples(first.joint_names, np.concatenate([p.q_measured for p in parts]),
                               np.concatenate([p.accel for p in parts]), np.concatenate([p.scatter for p in parts]),
                               np.concatenate([p.n_messages for p in parts]),
                               np.concatenate([p.stamps_ns for p in parts]), [s for p in parts for s in p.sources],
                               [n for p in parts for n in p.notes])  # fmt: skip


@dataclass
class ImuStream:
    """The IMU messages of one recording, in time order."""

    times_ns: np.ndarray  # (N,)
    accel: np.ndarray  # (N, 3) [m/s^2]
    gyro: np.ndarray | None  # (N, 3) [rad/s], None when the IMU reports none


def topics_of(path: Path) -> dict[str, str]:
    """Topic -> schema name of the channels of an MCAP file (from its summary; empty when it has none); a
    WolfcalError for a file that is not one or was not closed properly."""
    check_mcap(path)
    if not is_finished(path):
        raise torn_error(path)
    try:
        with path.open("rb") as handle:
            summary = make_reader(handle).get_summary()
    except Exception as exc:  # the mcap library raises many types for damaged files
        raise WolfcalError(f"{path}: damaged MCAP file ({type(exc).__name__}: {exc}); {recover_hint(path)}") from None
    if summary is None:
        return {}
    return {c.topic: summary.schemas[c.schema_id].name if c.schema_id in summary.schemas else ""
            for c in summary.channels.values()}  # fmt: skip


def read_imu_recording(path: Path, joint_states_topic: str, imu_topic: str) -> tuple[JointStates, ImuStream]:
    """The joint states and IMU messages of a recording; WolfcalErrors name the file and topic."""
    found = topics_of(path)
    if imu_topic not in found:
        raise WolfcalError(
            f"{path}: no {IMU} messages on {imu_topic} (robot config 'imu.topic'); topics in the "
            f"file: {', '.join(sorted(found)) or 'none'}"
        )
    if found[imu_topic] != IMU:
        raise WolfcalError(f"{path}: {imu_topic} carries {found[imu_topic]}, not {IMU} (robot config 'imu.topic')")
    joints, times, accel, gyro, has_gyro = [], [], [], [], True
    try:
        with path.open("rb") as handle:
            reader = make_reader(handle, decoder_factories=[DecoderFactory()])
            for _, channel, message, msg in reader.iter_decoded_messages(topics=[joint_states_topic, imu_topic]):
                stamp = header_stamp_ns(msg.header, message.log_time)
                if channel.topic == joint_states_topic:
                    joints.append((stamp, list(msg.name), list(msg.position), list(msg.velocity)))
                    continue
                a, w = msg.linear_acceleration, msg.angular_velocity
                times.append(stamp)
                accel.append((a.x, a.y, a.z))
                gyro.append((w.x, w.y, w.z))
                has_gyro &= float(msg.angular_velocity_covariance[0]) != -1.0
    except WolfcalError:
        raise
    except Exception as exc:  # the mcap libraries raise many types for damaged files
        raise WolfcalError(f"{path}: cannot read the recording ({type(exc).__name__}: {exc})") from None
    if not times:
        raise WolfcalError(f"{path}: no {IMU} messages on {imu_topic} (robot config 'imu.topic')")
    if not joints:
        raise WolfcalError(f"{path}: no joint states on {joint_states_topic} (robot config 'joint_states_topic')")
    order = np.argsort(np.array(times), kind="stable")
    stream = ImuStream(np.array(times, dtype=np.int64)[order], np.array(accel, dtype=float)[order],
                       np.array(gyro, dtype=float)[order] if has_gyro else None)  # fmt: skip
    _check_units(path, imu_topic, stream.accel)
    return JointStates.from_messages(joints), stream


def _check_units(path: Path, topic: str, accel: np.ndarray) -> None:
    """A WolfcalError when the accelerometer's magnitude is not that of gravity in m/s^2."""
    finite = accel[np.all(np.isfinite(accel), axis=1)]
    if not len(finite):
        raise WolfcalError(f"{path}: {topic}: every linear_acceleration is NaN or infinite")
    size = float(np.median(np.linalg.norm(finite, axis=1)))
    if G_UNITS_RANGE[0] <= size <= G_UNITS_RANGE[1]:
        raise WolfcalError(
            f"{path}: {topic}: the accelerometer reads |a| = {size:.3f} (median): that is in g, but "
            f"{IMU} gives linear_acceleration in m/s^2; have the IMU driver publish m/s^2 "
            "(multiply by 9.80665)"
        )
    if not GRAVITY_RANGE_M_S2[0] <= size <= GRAVITY_RANGE_M_S2[1]:
        raise WolfcalError(
            f"{path}: {topic}: the accelerometer reads |a| = {size:.3f} m/s^2 (median), not gravity "
            f"(9.81 m/s^2) while the robot stands; check the IMU driver's units and the topic"
        )


def still_messages(stream: ImuStream, states: JointStates | None = None) -> np.ndarray:
    """(N,) bool: the stillness test of the module docstring for each IMU message; with `states`, also no joint
    reading changing by more than one encoder tick within the window (a stance change the IMU barely feels)."""
    t, n = stream.times_ns, len(stream.times_ns)
    half = STILL_WINDOW_S * 1e9
    lo = np.searchsorted(t, t - half, side="left")
    hi = np.searchsorted(t, t + half, side="right")
    csum = np.concatenate([np.zeros((1, 3)), np.cumsum(stream.accel, axis=0)])
    csum2 = np.concatenate([np.zeros((1, 3)), np.cumsum(stream.accel**2, axis=0)])
    count = (hi - lo)[:, None]
    mean = (csum[hi] - csum[lo]) / count
    std = np.sqrt(np.maximum((csum2[hi] - csum2[lo]) / count - mean**2, 0.0))
    full = (t[hi - 1] - t[lo]) >= 1.5 * half  # windows cut by the start or end of the data are not judged
    still = full & np.all(std <= ACCEL_SCATTER_M_S2, axis=1) & np.all(np.isfinite(stream.accel), axis=1)
    if stream.gyro is not None:
        rate = np.linalg.norm(stream.gyro, axis=1)
        fast = np.concatenate([[0], np.cumsum(rate > GYRO_STILL_RAD_S)])
        still &= (fast[hi] - fast[lo]) == 0
    if states is not None:
        moved = np.sort(
            np.concatenate(
                [np.zeros(0, dtype=np.int64)]
                + [s.times[1:][np.abs(np.diff(s.positions)) > ENCODER_TICK + 1e-9] for s in states.series.values()]
            )
        )
        still &= np.searchsorted(moved, t + half, side="right") == np.searchsorted(moved, t - half, side="left")
    return still if n else np.zeros(0, dtype=bool)


def standing_samples(path: Path, states: JointStates, stream: ImuStream, joint_names: list[str]) -> StandingSamples:
    """One sample per still period of `stream` in which the joints held still too (module docstring)."""
    missing = [j for j in joint_names if j not in states.series]
    if missing:
        raise WolfcalError(f"{path}: the joint states lack {', '.join(missing[:5])}; record every joint")
    still, t = still_messages(stream, states), stream.times_ns
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    rows: list[tuple[np.ndarray, np.ndarray, float, int, int]] = []
    notes: list[str] = []
    for a, b in zip(edges[::2], edges[1::2]):
        t0, t1 = t[a] + EDGE_S * 1e9, t[b - 1] - EDGE_S * 1e9
        if t1 - t0 < MIN_STILL_S * 1e9:
            continue
        first, end = int(np.searchsorted(t, t0)), int(np.searchsorted(t, t1, side="right"))
        q = states.held_readings(int(t0), int(t1), joint_names)
        if q is None:
            notes.append(
                f"{path.name}: the IMU was still {(t1 - t0) / 1e9:.1f} s from {t0 / 1e9:.2f} s but a joint "
                "moved; left out"
            )
            continue
        window = stream.accel[first:end]
        rows.append((q, window.mean(axis=0), float(window.std(axis=0).max()), end - first, int((t0 + t1) // 2)))
    if not rows:
        raise WolfcalError(
            f"{path}: the robot never stood still: no period of at least {MIN_STILL_S + 2 * EDGE_S:.1f} "
            f"s in which the IMU (accelerometer scatter <= {ACCEL_SCATTER_M_S2} m/s^2, gyro <= "
            f"{GYRO_STILL_RAD_S} rad/s) and every joint held still; hold each stance about 3 s"
        )
    return StandingSamples(
        joint_names=list(joint_names), q_measured=np.array([r[0] for r in rows]),
        accel=np.array([r[1] for r in rows]), scatter=np.array([r[2] for r in rows]),
        n_messages=np.array([r[3] for r in rows]), stamps_ns=np.array([r[4] for r in rows], dtype=np.int64),
        sources=[str(path)] * len(rows), notes=notes,
    )  # fmt: skip


def read_standing(paths: list[Path], joint_states_topic: str, imu_topic: str,
                  joint_names: list[str]) -> StandingSamples:  # fmt: skip
    """The still periods of every recording, in order."""
    parts = []
    for path in paths:
        states, stream = read_imu_recording(Path(path), joint_states_topic, imu_topic)
        parts.append(standing_samples(Path(path), states, stream, joint_names))
    return StandingSamples.joined(parts)
