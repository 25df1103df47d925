"""The IMU as a Protocol 2.0 device on a servo bus (`imu.bus`, `wolfcal.robot.imu_bus`), read through
`dynamixel_sdk`: one READ of the registers of both sensors per reading.

Readings are in the IMU frame: specific force [m/s^2] and rate of turn [rad/s]. Every failure raises `BusError`
naming the device (id, port) and the config key to check.
"""

from __future__ import annotations

from functools import partial
from operator import itemgetter

import dynamixel_sdk as sdk
import numpy as np

from wolfcal.hardware import protocol as P
from wolfcal.hardware.bus import BusError, DynamixelBus, with_retries
from wolfcal.io.imu import G_UNITS_RANGE, GRAVITY_RANGE_M_S2
from wolfcal.robot.imu_bus import ImuBusConfig

ERR_DATA_RANGE, ERR_DATA_LENGTH = 4, 5  # status error numbers of a read outside the device's control table
UNITS_READINGS = 5  # readings whose median |a| decides the accelerometer's units


class BusImu:
    """The IMU on `bus` (opened), laid out as `config` says."""

    def __init__(self, bus: DynamixelBus, config: ImuBusConfig):
        self.bus, self.config = bus, config
        self.name = f"the IMU (id {config.id}) on {bus.port_name}"

    def check(self) -> None:
        """Ping it (model number checked when the config gives one) and read it a few times: BusError when it does
        not answer, refuses the registers, or its accelerometer does not read gravity in m/s^2 (robot standing or
        lying still)."""
        (model, result, _), tried = with_retries(
            partial(self.bus.ph.ping, self.bus.port, self.config.id), itemgetter(1)
        )
        if result != sdk.COMM_SUCCESS:
            raise BusError(
                f"{self.name}: no answer ({self.bus.comm_text(result, tried)}); check 'imu.bus.id' and "
                "'imu.bus.port' in the robot config, the IMU's power and cable"
            )
        if self.config.model is not None and model != self.config.model:
            raise BusError(
                f"{self.name}: model number {model}, but 'imu.bus.model' says {self.config.model}: another device "
                "answers at this id; fix 'imu.bus.id' (or 'imu.bus.model')"
            )
        size = float(np.median([np.linalg.norm(self.read()[0]) for _ in range(UNITS_READINGS)]))
        accel = self.config.accel
        if G_UNITS_RANGE[0] <= size <= G_UNITS_RANGE[1]:
            raise BusError(
                f"{self.name}: the accelerometer reads |a| = {size:.3f}: that is in g, not m/s^2; multiply "
                f"'imu.bus.accel.scale' by 9.80665 (now {_scale_text(accel.scale)})"
            )
        if not GRAVITY_RANGE_M_S2[0] <= size <= GRAVITY_RANGE_M_S2[1]:
            raise BusError(
                f"{self.name}: the accelerometer reads |a| = {size:.3g} m/s^2, not gravity (9.81 m/s^2) while the "
                f"robot stands still; check 'imu.bus.accel' (address {accel.address}, type {accel.type}, scale "
                f"{_scale_text(accel.scale)}) against the device's control table"
            )

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """(specific force (3,) [m/s^2], rate of turn (3,) [rad/s]) in the IMU frame."""
        start, length = self.config.span
        read = partial(self.bus.ph.readTxRx, self.bus.port, self.config.id, start, length)
        (data, result, error), tried = with_retries(read, itemgetter(1))
        if result != sdk.COMM_SUCCESS:
            raise BusError(
                f"{self.name}: reading addresses {start}-{start + length - 1} failed: "
                f"{self.bus.comm_text(result, tried)}; check the IMU's cable and power"
            )
        if error & 0x7F in (P.ERR_ACCESS, ERR_DATA_RANGE, ERR_DATA_LENGTH):
            raise BusError(
                f"{self.name} refuses reading addresses {start}-{start + length - 1} "
                f"({self.bus.ph.getRxPacketError(error & 0x7F)}): 'imu.bus.accel' / 'imu.bus.gyro' do not fit its "
                "control table; check their address and type against the device's documentation"
            )
        if error & 0x7F or len(data) != length:
            raise BusError(f"{self.name}: reading its registers failed ({self.bus.ph.getRxPacketError(error)})")
        raw = bytes(data)
        return self.config.accel.decode(raw, start), self.config.gyro.decode(raw, start)


def _scale_text(scale: tuple[float, float, float]) -> str:
    return f"{scale[0]:.6g}" if len(set(scale)) == 1 else "[" + ", ".join(f"{s:.6g}" for s in scale) + "]"
