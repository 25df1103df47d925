"""The IMU as a device on the Dynamixel bus: the robot config's `imu.bus` section and its register layout.

Some robots put their IMU on the servo bus as a Protocol 2.0 device with a control table of its own (ROBOTIS OP3:
the OpenCR board, id 200; the Bit-Bots' IMU board, id 241). Config:

    imu:
      bus:
        id: 200                     # the device's id on the bus
        port: /dev/ttyUSB0          # optional: the servo bus it is on (a device of `servos.ports`; default the
                                    #   only bus, or the first of `servos.ports`)
        model: 29696                # optional: the model number it answers a ping with (checked when given)
        accel: {address: 38, type: int16, scale: 0.000598550}   # three registers x, y, z from `address`
        gyro: {address: 32, type: int16, scale: 0.001064225}

Registers: three consecutive values (x, y, z) of `type` (int16, int32: signed little-endian integers; float32:
IEEE little-endian), each `size` bytes, from `address`. Value in SI units (accelerometer [m/s^2], gyro [rad/s]) =
raw * scale; `scale` is one number or three (per axis: a negative one turns the board's axis into the IMU frame's,
as the OP3's driver negates x and y). The values are in the IMU frame (`imu.frame`).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError

TYPES = {"int16": ("<h", 2), "int32": ("<i", 4), "float32": ("<f", 4)}  # register type -> (struct format, bytes)
MAX_ADDRESS = 0xFFFF  # Protocol 2.0 addresses are 16 bits
MAX_ID = 252  # 253-255 are reserved (254 broadcast)


@dataclass(frozen=True)
class Registers:
    """Three consecutive registers (x, y, z) of one sensor."""

    key: str  # config key, for messages: 'imu.bus.accel' | 'imu.bus.gyro'
    address: int
    type: str  # int16 | int32 | float32
    scale: tuple[float, float, float]  # SI units per raw unit, per axis

    @property
    def size(self) -> int:
        """Bytes of one register."""
        return TYPES[self.type][1]

    @property
    def end(self) -> int:
        """The address after the z register."""
        return self.address + 3 * self.size

    def decode(self, data: bytes, start: int) -> np.ndarray:
        """(3,) SI values of these registers in `data`, a block read from address `start`."""
        offset = self.address - start
        raw = struct.unpack(f"<3{TYPES[self.type][0][1]}", data[offset : offset + 3 * self.size])
        return np.array(raw, dtype=float) * np.array(self.scale)

    def encode(self, values: np.ndarray) -> bytes:
        """The register bytes of (3,) SI values (integers rounded and held within their range)."""
        raw = np.asarray(values, dtype=float) / np.array(self.scale)
        if self.type == "float32":
            return struct.pack("<3f", *raw)
        bound = 2 ** (8 * self.size - 1)
        clipped = np.clip(np.round(raw), -bound, bound - 1).astype(int)
        return struct.pack(f"<3{TYPES[self.type][0][1]}", *clipped)


@dataclass(frozen=True)
class ImuBusConfig:
    """The robot config's `imu.bus` section (module docstring)."""

    id: int
    accel: Registers  # [m/s^2]
    gyro: Registers  # [rad/s]
    port: str | None = None  # the servo bus device it is on; None: the only (or first) bus
    model: int | None = None  # model number it must answer a ping with; None: not checked

    @property
    def span(self) -> tuple[int, int]:
        """(first address, length) of one read that takes both sensors."""
        start = min(self.accel.address, self.gyro.address)
        return start, max(self.accel.end, self.gyro.end) - start


def _integer(path: Path, key: str, value: object, low: int, high: int) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise WolfcalError(f"{path}: '{key}' must be an integer from {low} to {high}, found {value!r}")
    return value


def _registers(path: Path, key: str, data: object) -> Registers:
    if not isinstance(data, dict) or set(data) != {"address", "type", "scale"}:
        raise WolfcalError(
            f"{path}: '{key}' must be a mapping {{address, type, scale}} (e.g. {{address: 38, type: int16, "
            f"scale: 0.000598550}}: three registers x, y, z; SI value = raw * scale)"
        )
    if data["type"] not in TYPES:
        raise WolfcalError(f"{path}: '{key}.type' must be one of {', '.join(TYPES)}, found {data['type']!r}")
    scale = data["scale"]
    scales = scale if isinstance(scale, list) else [scale]
    if len(scales) not in (1, 3) or not all(
        isinstance(s, (int, float)) and not isinstance(s, bool) and s != 0 and np.isfinite(s) for s in scales
    ):
        raise WolfcalError(f"{path}: '{key}.scale' must be one non-zero number or three (x, y, z), found {scale!r}")
    address = _integer(path, f"{key}.address", data["address"], 0, MAX_ADDRESS)
    x, y, z = (float(s) for s in scales * (3 // len(scales)))
    registers = Registers(key, address, data["type"], (x, y, z))
    if registers.end - 1 > MAX_ADDRESS:
        raise WolfcalError(f"{path}: '{key}' runs past the last address {MAX_ADDRESS} of the control table")
    return registers


def parse_imu_bus(path: Path, data: object) -> ImuBusConfig:
    """The `imu.bus` section of the robot config at `path`; a WolfcalError naming the key otherwise."""
    known = {"id", "port", "model", "accel", "gyro"}
    if not isinstance(data, dict) or not {"id", "accel", "gyro"} <= set(data) or set(data) - known:
        raise WolfcalError(
            f"{path}: 'imu.bus' must be a mapping {{id, accel, gyro}} with optional port and model (keys found: "
            f"{', '.join(sorted(data)) if isinstance(data, dict) else type(data).__name__})"
        )
    port = data.get("port")
    if port is not None and (not isinstance(port, str) or not port):
        raise WolfcalError(f"{path}: 'imu.bus.port' must name a servo bus device, e.g. /dev/ttyUSB0")
    accel = _registers(path, "imu.bus.accel", data["accel"])
    gyro = _registers(path, "imu.bus.gyro", data["gyro"])
    if accel.address < gyro.end and gyro.address < accel.end:
        raise WolfcalError(
            f"{path}: 'imu.bus.accel' (addresses {accel.address}-{accel.end - 1}) and 'imu.bus.gyro' "
            f"({gyro.address}-{gyro.end - 1}) overlap; give each sensor its own registers"
        )
    model = data.get("model")
    return ImuBusConfig(
        id=_integer(path, "imu.bus.id", data["id"], 0, MAX_ID),
        accel=accel,
        gyro=gyro,
        port=port,
        model=None if model is None else _integer(path, "imu.bus.model", model, 0, 0xFFFF),
    )
