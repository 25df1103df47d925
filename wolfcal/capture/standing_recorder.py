"""The recording of a standing capture: each reading of the servo buses and of the IMU goes into the file, and the
readings since the current stance began are kept to judge its stillness the way the IMU reader will
(`wolfcal.io.imu.still_messages`: the accelerometer's scatter, the gyro, every joint within one encoder tick)."""

from __future__ import annotations

import time

import numpy as np

from wolfcal.hardware.buses import ServoBuses
from wolfcal.hardware.imu_device import BusImu
from wolfcal.io.imu import ACCEL_SCATTER_M_S2, GYRO_STILL_RAD_S, STILL_WINDOW_S, ImuStream, still_messages
from wolfcal.io.recording import ENCODER_TICK, JointStates
from wolfcal.io.standing_writer import StandingWriter

JUDGE_EVERY = 10  # readings between two stillness judgements (each looks at the whole stance so far)


class StandingRecorder:
    """Reads `bus` and `imu` at up to `rate_hz`, writes every reading to `writer`, keeps the current stance's."""

    def __init__(self, bus: ServoBuses, imu: BusImu, writer: StandingWriter, rate_hz: float):
        self.bus, self.imu, self.writer, self.period = bus, imu, writer, 1.0 / rate_hz
        self.last_positions = np.zeros(len(bus.joints))  # (J,) [rad] of the latest reading
        self.next_at = 0.0  # monotonic time of the next reading [s]
        self.begin_stance()

    def begin_stance(self) -> None:
        """Forget the readings kept so far (not those in the file)."""
        self.joints: list[tuple[int, list[str], list[float], list[float]]] = []  # (stamp [ns], names, q, [])
        self.times: list[int] = []  # IMU stamps [ns]
        self.accel: list[np.ndarray] = []  # (3,) [m/s^2]
        self.gyro: list[np.ndarray] = []  # (3,) [rad/s]
        self.held_s = 0.0

    def record(self) -> np.ndarray:
        """One reading of the buses and the IMU, written and kept; returns the joint positions (J,) [rad]."""
        pause = self.next_at - time.monotonic()
        if pause > 0:
            time.sleep(pause)  # pacing the readings, not waiting for an event
        self.next_at = time.monotonic() + self.period
        state = self.bus.read_state_polled()
        stamp = time.time_ns()
        self.writer.joint_state(stamp, self.bus.joints, state.positions, state.velocities)
        accel, gyro = self.imu.read()
        imu_stamp = time.time_ns()
        self.writer.imu(imu_stamp, accel, gyro)
        self.joints.append((stamp, self.bus.joints, state.positions.tolist(), []))
        self.times.append(imu_stamp)
        self.accel.append(accel)
        self.gyro.append(gyro)
        self.last_positions = state.positions
        return state.positions

    def still_for(self) -> float:
        """The longest time [s] the robot has held still in this stance (joints and IMU, the reader's test),
        judged every JUDGE_EVERY readings."""
        if len(self.times) % JUDGE_EVERY == 0:
            still = still_messages(self._stream(), JointStates.from_messages(self.joints))
            edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
            t = np.array(self.times)
            spans = [(t[b - 1] - t[a]) / 1e9 for a, b in zip(edges[::2], edges[1::2])]
            self.held_s = max(spans, default=0.0)
        return self.held_s

    def why_not_still(self) -> str:
        """What moved over the last STILL_WINDOW_S: a joint, the accelerometer's scatter or the gyro."""
        recent = np.array(self.times) >= self.times[-1] - STILL_WINDOW_S * 1e9
        scatter = float(np.array(self.accel)[recent].std(axis=0).max())
        rate = float(np.linalg.norm(np.array(self.gyro)[recent], axis=1).max())
        q = np.array([row[2] for row in self.joints])[recent[: len(self.joints)]]
        moved = float(np.ptp(q, axis=0).max() / ENCODER_TICK) if len(q) else 0.0
        return (f"lately: joints moved up to {moved:.0f} ticks, accelerometer scatter {scatter:.3f} m/s^2 (still: "
                f"<= {ACCEL_SCATTER_M_S2}), gyro {rate:.3f} rad/s (still: <= {GYRO_STILL_RAD_S})")  # fmt: skip

    def _stream(self) -> ImuStream:
        return ImuStream(np.array(self.times, dtype=np.int64), np.array(self.accel), np.array(self.gyro))
