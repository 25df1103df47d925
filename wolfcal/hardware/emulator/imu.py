"""The emulated IMU: a Protocol 2.0 device on the bus with the robot config's register layout (`imu.bus`).

It answers PING with its model number and READ from its control table; before each READ its registers take what
an IMU mounted as the truth says would measure now: specific force = g * (the floor's normal in the IMU frame,
from the true joint angles of every emulated bus and the true geometry, `wolfcal.robot.imu_mount.true_gravity`)
+ a constant bias + white noise per read [m/s^2]; rate of turn = the turn of the IMU frame since the previous read
over its duration + white noise [rad/s]. The torso's linear acceleration is left out (a robot moving between
stances is not still anyway). Other instructions get an instruction error.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wolfcal.geometry import log_so3
from wolfcal.hardware.emulator.table import ControlTable
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.imu_bus import ImuBusConfig
from wolfcal.robot.robot import Robot

GRAVITY = 9.80665  # [m/s^2]
TABLE_SIZE = 128  # bytes of the emulated device's control table (more when the layout reaches further)


@dataclass
class ImuSpec:
    """What the emulated IMU is: its layout on the bus, the robot it sits in, its true mount and errors."""

    robot_path: str  # robot config (URDF, `imu.frame`, `floor.soles`)
    layout: ImuBusConfig
    truth: Corrections = field(default_factory=Corrections)  # true geometry: the IMU joint's frame correction
    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # accelerometer's constant bias, IMU frame [m/s^2]
    accel_noise: float = 0.03  # per axis and read [m/s^2]
    gyro_noise: float = 0.003  # per axis and read [rad/s]
    model: int = 0  # model number answered to PING (the layout's, when it gives one)
    seed: int = 0


class EmulatedImu(ControlTable):
    """The device of an `ImuSpec`; `true_angles()` gives every joint's true angle [rad] (all buses)."""

    def __init__(self, spec: ImuSpec, true_angles: Callable[[], dict[str, float]]):
        self.spec, self.sid, self.true_angles = spec, spec.layout.id, true_angles
        start, length = spec.layout.span
        super().__init__(max(TABLE_SIZE, start + length))
        self.table[0:2] = (spec.layout.model if spec.layout.model is not None else spec.model).to_bytes(2, "little")
        self.silent = self.corrupt = self.missing = False  # the attributes the instruction answers look at
        self.late_replies = self.stale_replies = 0
        self.held = b""
        self.rng = np.random.default_rng(spec.seed)
        self._robot: Robot | None = None  # loaded on first use, in the emulator's own process
        self._last: tuple[float, np.ndarray] | None = None  # (time [s], R_floor_imu) of the previous read

    @property
    def answers(self) -> bool:
        return not (self.silent or self.missing)

    def error_byte(self) -> int:
        return 0

    def refresh(self, now: float) -> None:
        """Set the registers to what the IMU measures at `now` (monotonic clock [s])."""
        from wolfcal.robot.imu_mount import true_gravity
        from wolfcal.robot.robot import load_robot

        if self._robot is None:
            self._robot = load_robot(self.spec.robot_path)
        robot = self._robot
        angles = self.true_angles()
        q = np.array([[angles.get(name, 0.0) for name in robot.joint_names]])
        normal, R = true_gravity(robot, self.spec.truth, q)
        accel = GRAVITY * normal[0] + np.array(self.spec.bias) + self.rng.normal(0.0, self.spec.accel_noise, 3)
        turn = np.zeros(3)
        if self._last is not None and now > self._last[0]:
            turn = log_so3(self._last[1].T @ R[0]) / (now - self._last[0])  # in the IMU frame
        self._last = (now, R[0])
        gyro = turn + self.rng.normal(0.0, self.spec.gyro_noise, 3)
        for registers, values in ((self.spec.layout.accel, accel), (self.spec.layout.gyro, gyro)):
            self.table[registers.address : registers.end] = registers.encode(values)
