"""The servos of a robot config on all their buses (`servos.ports`, e.g. the Wolfgang's four), in joint terms.

`ServoBuses` offers what `DynamixelBus` offers for one port, over one `DynamixelBus` per device: `joints` fixes the
array order (the config's `servos.ids` order, whatever bus a joint is on); reads are one sync read per bus, taken one
after the other; writes go to the bus of each joint. A failure raises the `BusError` of the bus it happened on, which
names that device. `port` (the command line's --port) replaces the config's device: one path for a robot on one bus,
or DEVICE=PATH,... naming each device of `servos.ports` (e.g. the ptys `wolfcal emulate` serves them on).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from typing import TypeVar

import numpy as np

from wolfcal.config import ServoConfig
from wolfcal.errors import WolfcalError
from wolfcal.hardware.bus import BusError, DynamixelBus, JointState

Result = TypeVar("Result")

HARDWARE_POLL_S = 1.0  # `read_state_polled` checks the servos' hardware error status at most this often [s]


class ServoBuses:
    """Every configured servo, on one or more ports. Use as a context manager."""

    def __init__(self, servos: ServoConfig, port: str | None = None, baudrate: int | None = None):
        buses = servos.buses
        paths = port_paths(port, list(buses))
        joint_of = {sid: joint for joint, sid in servos.ids.items()}
        self.servos = servos
        self.joints = list(servos.ids)
        self.buses: list[DynamixelBus] = []
        self.bus_of: dict[str, DynamixelBus] = {}
        for device, ids in buses.items():
            joints = [joint_of[sid] for sid in ids]
            config = replace(servos, port=device, ids={j: servos.ids[j] for j in joints}, ports={},
                             models={j: m for j, m in servos.models.items() if j in joints})  # fmt: skip
            bus = DynamixelBus(config, paths.get(device, device), baudrate)
            self.buses.append(bus)
            self.bus_of.update({joint: bus for joint in joints})
        self.last_hardware_check = -math.inf  # monotonic time of the last `check_hardware` in `read_state_polled`
        self.port_names = [bus.port_name for bus in self.buses]
        self.port_name = ", ".join(self.port_names)

    def bus_on(self, device: str | None) -> DynamixelBus:
        """The bus of a config device (`servos.port` or one of `servos.ports`); None: the first bus."""
        for bus in self.buses:
            if device is None or bus.servos.port == device:
                return bus
        raise WolfcalError(f"{device}: not a servo bus of the robot config ({', '.join(self.servos.buses)})")

    # --- connection -----------------------------------------------------------------------------------------
    def open(self) -> ServoBuses:
        """Open every bus; when one cannot be opened, those already open are closed again."""
        try:
            for bus in self.buses:
                bus.open()
        except BaseException:
            self.close()
            raise
        return self

    def close(self) -> None:
        for bus in self.buses:
            bus.close()

    def recover_port(self) -> None:
        for bus in self.buses:
            bus.recover_port()

    def __enter__(self) -> ServoBuses:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def _grouped(self, joints: Iterable[str]) -> dict[DynamixelBus, list[str]]:
        groups: dict[DynamixelBus, list[str]] = {}
        for joint in joints:
            groups.setdefault(self.bus_of[joint], []).append(joint)
        return groups

    def _merged(self, per_bus: Callable[[DynamixelBus], dict[str, Result]]) -> dict[str, Result]:
        merged: dict[str, Result] = {}
        for bus in self.buses:
            merged.update(per_bus(bus))
        return merged

    # --- checks ---------------------------------------------------------------------------------------------
    def ping_all(self) -> dict[str, int]:
        """Ping every servo on every bus; one BusError with the problems of all buses."""
        models, problems = {}, []
        for bus in self.buses:
            try:
                models.update(bus.ping_all())
            except BusError as exc:
                problems.append(str(exc))
        if problems:
            raise BusError("\n".join(problems))
        return models

    def hardware_errors(self) -> dict[str, int]:
        return self._merged(DynamixelBus.hardware_errors)

    def check_hardware(self) -> None:
        for bus in self.buses:
            bus.check_hardware()

    # --- reading and writing ----------------------------------------------------------------------------------
    def read_state(self) -> JointState:
        """Present position and velocity of every joint: one sync read per bus, in `joints` order."""
        ticks: dict[str, int] = {}
        velocity: dict[str, int] = {}
        for bus in self.buses:
            state = bus.read_state()
            ticks.update(zip(bus.joints, state.ticks))
            velocity.update(zip(bus.joints, state.velocity_units))
        return JointState(np.array([ticks[j] for j in self.joints]), np.array([velocity[j] for j in self.joints]))

    def read_state_polled(self) -> JointState:
        """`read_state`, checking the hardware error status first when it was last checked over HARDWARE_POLL_S
        ago (a servo in overload or overheating raises its `BusError` then): for loops that read the bus without
        pause while the robot moves or holds."""
        now = time.monotonic()
        if now - self.last_hardware_check > HARDWARE_POLL_S:
            self.check_hardware()
            self.last_hardware_check = now
        return self.read_state()

    def set_torque(self, joints: Iterable[str], on: bool) -> None:
        for bus, group in self._grouped(joints).items():
            bus.set_torque(group, on)

    def torque_enabled(self) -> dict[str, bool]:
        return self._merged(DynamixelBus.torque_enabled)

    def set_profile_velocity(self, joints: Iterable[str], rad_s: float) -> None:
        for bus, group in self._grouped(joints).items():
            bus.set_profile_velocity(group, rad_s)

    def set_profile_acceleration(self, joints: Iterable[str], rad_s2: float) -> None:
        for bus, group in self._grouped(joints).items():
            bus.set_profile_acceleration(group, rad_s2)

    def set_goal_positions(self, goals: dict[str, float]) -> None:
        """Goal positions [rad]: one sync write per bus."""
        for bus, group in self._grouped(goals).items():
            bus.set_goal_positions({joint: goals[joint] for joint in group})

    def reboot(self, joint: str) -> None:
        self.bus_of[joint].reboot(joint)


def port_paths(port: str | None, devices: list[str]) -> dict[str, str]:
    """Config device -> path to open, from --port: {} without it; one path for a robot on one bus; DEVICE=PATH,...
    naming every device for several (WolfcalError otherwise)."""
    if port is None:
        return {}
    if "=" not in port:
        if len(devices) > 1:
            raise WolfcalError(
                f"--port {port}: the robot config lists {len(devices)} servo buses under 'servos.ports' "
                f"({', '.join(devices)}); give DEVICE=PATH for each, comma-separated, or drop --port"
            )
        return {devices[0]: port}
    paths = dict(item.strip().partition("=")[::2] for item in port.split(",") if item.strip())
    unknown, missing = sorted(set(paths) - set(devices)), [d for d in devices if d not in paths]
    if unknown or missing or not all(paths.values()):
        raise WolfcalError(
            f"--port {port}: give DEVICE=PATH for each servo bus of the robot config ({', '.join(devices)})"
            + (f"; {', '.join(unknown)} is not one" if unknown else "")
            + (f"; {', '.join(missing)} is missing" if missing else "")
        )
    return paths
