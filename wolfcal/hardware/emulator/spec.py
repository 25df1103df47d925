"""What the emulator emulates: servos with their true offsets, faults, the operator's poses; from a robot config
and a truth file."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.hardware.emulator.emulated_operator import OPERATOR_SPEED
from wolfcal.hardware.emulator.faults import Fault
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


def spec_from_config(
    config: RobotConfig,
    truth: Corrections | None = None,
    faults: Iterable[Fault] = (),
    operator_poses: Iterable[dict[str, float]] = (),
    hold_s: float = 2.0,
    truth_path: str | None = None,
    operator_speed: float = OPERATOR_SPEED,
) -> EmulatorSpec:
    """The emulated bus of a robot config; true offsets [rad] from `truth`; operator poses: joint -> rad."""
    if config.servos is None:
        raise WolfcalError(f"{config.path}: no 'servos' section: the emulator needs the servo ids")
    offsets = truth.offsets if truth is not None else {}
    servos = {
        sid: ServoSpec(joint, config.servos.models.get(joint, DEFAULT_MODEL), float(offsets.get(joint, 0.0)))
        for joint, sid in config.servos.ids.items()
    }
    return EmulatorSpec(servos, list(faults), [dict(p) for p in operator_poses], hold_s, operator_speed, truth_path)


def load_truth(path: Path) -> Corrections:
    """True corrections from a YAML file: a simulator's truth file (key 'truth') or a plain corrections file."""
    try:
        data = yaml.safe_load(path.read_text()) if path.is_file() else None
    except yaml.YAMLError:
        data = None
    return load_corrections(path, key="truth" if isinstance(data, dict) and "truth" in data else None)
