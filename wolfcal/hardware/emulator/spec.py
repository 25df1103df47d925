"""What the emulator emulates: servos with their true offsets on one bus or several (`servos.ports`), faults, the
operator's poses, and the IMU on the bus when the config has `imu.bus`; from a robot config and a truth file."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.hardware.emulator.emulated_operator import OPERATOR_SPEED
from wolfcal.hardware.emulator.faults import Fault
from wolfcal.hardware.emulator.imu import ImuSpec
from wolfcal.hardware.emulator.servo import DEFAULT_MODEL, ServoSpec
from wolfcal.robot.corrections import Corrections, load_corrections


@dataclass
class EmulatorSpec:
    servos: dict[int, ServoSpec]
    faults: list[Fault] = field(default_factory=list)
    operator_poses: list[dict[str, float]] = field(default_factory=list)  # joint -> rad (readings), manual mode
    operator_hold_s: float = 2.0
    operator_speed: float = OPERATOR_SPEED  # rad/s
    truth_path: str | None = None  # truth YAML the simulated camera renders with
    ports: dict[str, tuple[int, ...]] = field(default_factory=dict)  # bus device -> ids on it; {}: one bus
    imu: ImuSpec | None = None  # the IMU on the bus (`imu.bus`), None: none
    imu_port: str | None = None  # the device of `ports` the IMU is on (None: the first bus)

    def buses(self) -> dict[str | None, dict[int, ServoSpec]]:
        """The servos of each bus: by config device (`ports`), or {None: all} for one bus."""
        if not self.ports:
            return {None: dict(self.servos)}
        return {
            device: {sid: self.servos[sid] for sid in ids if sid in self.servos} for device, ids in self.ports.items()
        }


def spec_from_config(
    config: RobotConfig,
    truth: Corrections | None = None,
    faults: Iterable[Fault] = (),
    operator_poses: Iterable[dict[str, float]] = (),
    hold_s: float = 2.0,
    truth_path: str | None = None,
    operator_speed: float = OPERATOR_SPEED,
    imu: ImuSpec | None = None,
) -> EmulatorSpec:
    """The emulated buses of a robot config (`servos.ports`, else one); true offsets [rad] from `truth`; operator
    poses: joint -> rad; `imu`: the IMU on the bus (on `imu.bus.port`, default the first bus)."""
    if config.servos is None:
        raise WolfcalError(f"{config.path}: no 'servos' section: the emulator needs the servo ids")
    offsets = truth.offsets if truth is not None else {}
    servos = {
        sid: ServoSpec(joint, config.servos.models.get(joint, DEFAULT_MODEL), float(offsets.get(joint, 0.0)))
        for joint, sid in config.servos.ids.items()
    }
    ports = dict(config.servos.ports)
    imu_port = imu.layout.port if imu is not None and ports else None
    if imu_port is not None and imu_port not in ports:
        raise WolfcalError(
            f"{config.path}: 'imu.bus.port' {imu_port} is not a bus of 'servos.ports' ({', '.join(ports)}); name the "
            "servo bus the IMU is on"
        )
    return EmulatorSpec(servos, list(faults), [dict(p) for p in operator_poses], hold_s, operator_speed, truth_path,
                        ports, imu, imu_port)  # fmt: skip


def load_truth(path: Path) -> Corrections:
    """True corrections from a YAML file: a simulator's truth file (key 'truth') or a plain corrections file."""
    try:
        data = yaml.safe_load(path.read_text()) if path.is_file() else None
    except yaml.YAMLError:
        data = None
    return load_corrections(path, key="truth" if isinstance(data, dict) and "truth" in data else None)
