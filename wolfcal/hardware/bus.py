"""The Dynamixel servo bus through `dynamixel_sdk` (Protocol 2.0), in joint terms.

Joint angle [rad] = (present position - 2048) * 2 pi / 4096: the robot's joint convention; the sign of a joint
comes from its URDF axis only, so none is applied here. Every failure raises `BusError` naming the port, the
joint and id and what to check.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from operator import itemgetter
from typing import TypeVar

import dynamixel_sdk as sdk
import numpy as np
import serial

from wolfcal.config import ServoConfig
from wolfcal.encoders import RAD_PER_TICK
from wolfcal.errors import WolfcalError
from wolfcal.hardware import protocol as P

# A transaction that got no (or a corrupted) answer is tried again after a pause that doubles each time, until
# the time budget is spent: a busy host (or emulator) may answer late, a silent servo must still be named soon.
RETRY_BUDGET_S = 1.0  # longest a transaction may take, all attempts included
FIRST_PAUSE_S = 0.005  # pause before the second attempt; doubled before each further one ...
MAX_PAUSE_S = 0.2  # ... up to this
READ_BLOCK_S = 0.002  # longest a serial read blocks before the SDK checks its packet timeout again


class BusError(WolfcalError):
    """The servo bus failed (no answer, corrupted replies, hardware error)."""

    exit_code = 3


def ticks_to_rad(ticks: np.ndarray) -> np.ndarray:
    """Joint angle(s) [rad] of present position(s) [ticks]."""
    return (np.asarray(ticks) - P.CENTRE_TICK) * RAD_PER_TICK


def rad_to_ticks(rad: np.ndarray | float) -> np.ndarray | int:
    """Position(s) [ticks] of joint angle(s) [rad], rounded to the nearest tick."""
    return np.round(np.asarray(rad) / RAD_PER_TICK).astype(int) + P.CENTRE_TICK


def _signed32(value: int) -> int:
    return value - (1 << 32) if value & 0x80000000 else value


Outcome = TypeVar("Outcome")


@dataclass(frozen=True)
class Tried:
    """How a transaction was tried: attempts made, seconds spent, the longest pause between two attempts."""

    attempts: int
    seconds: float
    longest_pause_s: float

    def __str__(self) -> str:
        pauses = (
            f", pausing {FIRST_PAUSE_S * 1000:.0f}-{self.longest_pause_s * 1000:.0f} ms between them"
            if self.attempts > 1
            else ""
        )
        return f"{self.attempts} attempt(s) in {self.seconds:.2f} s{pauses}"


def with_retries(
    transaction: Callable[[], Outcome], comm_result: Callable[[Outcome], int], budget_s: float | None = None
) -> tuple[Outcome, Tried]:
    """The outcome of the first attempt of an SDK transaction that communicated, else of the last one the time
    budget allowed (pauses doubling from FIRST_PAUSE_S to MAX_PAUSE_S), and how it was tried; `comm_result`
    picks the communication result (`sdk.COMM_*`) out of an outcome."""
    budget = RETRY_BUDGET_S if budget_s is None else budget_s
    start = time.monotonic()
    pause, longest, attempts = FIRST_PAUSE_S, 0.0, 0
    while True:
        outcome = transaction()
        attempts += 1
        if comm_result(outcome) == sdk.COMM_SUCCESS or time.monotonic() - start + pause > budget:
            break
        time.sleep(pause)  # a back-off between attempts, not a wait for an event
        longest, pause = pause, min(2 * pause, MAX_PAUSE_S)
    return outcome, Tried(attempts, time.monotonic() - start, longest)


@dataclass
class JointState:
    """One sync read: `ticks` and `velocity_units` raw, per joint in `DynamixelBus.joints` order."""

    ticks: np.ndarray  # (J,) int present positions
    velocity_units: np.ndarray  # (J,) int present velocities (0.229 rpm)

    @property
    def positions(self) -> np.ndarray:
        """(J,) joint angles [rad]."""
        return ticks_to_rad(self.ticks)

    @property
    def velocities(self) -> np.ndarray:
        """(J,) joint velocities [rad/s]."""
        return self.velocity_units * P.RAD_S_PER_UNIT


def hardware_error_text(bits: int) -> str:
    """The names of the Hardware Error Status bits set in `bits`."""
    names = [name for bit, name in P.HW_ERROR_BITS.items() if bits & (1 << bit)]
    return ", ".join(names) or f"bits {bits:#04x}"


class DynamixelBus:
    """The servos of a robot config on one port. Use as a context manager; `joints` fixes the array order."""

    def __init__(self, servos: ServoConfig, port: str | None = None, baudrate: int | None = None):
        self.servos = servos
        self.port_name = port or servos.port
        self.baudrate = baudrate or servos.baudrate
        self.joints = list(servos.ids)
        self.ids = [servos.ids[j] for j in self.joints]
        self.port: sdk.PortHandler | None = None
        self.ph = sdk.PacketHandler(2.0)

    # --- connection -----------------------------------------------------------------------------------------
    def open(self) -> DynamixelBus:
        port = sdk.PortHandler(self.port_name)
        try:
            opened = port.openPort()
        except (serial.SerialException, OSError) as exc:
            raise BusError(
                f"{self.port_name}: cannot open the servo bus ({exc}); check the cable, the --port name and "
                "that you may use the device (group 'dialout')"
            ) from None
        if not opened or not port.setBaudRate(self.baudrate):
            raise BusError(
                f"{self.port_name}: cannot set {self.baudrate} baud; use 57600, 115200, 1000000, "
                "2000000, 3000000 or 4000000"
            )
        # The SDK opens the port with timeout=0 and busy-waits for replies, burning a core that the host (or
        # the emulator) needs; a short blocking timeout lets reads sleep in select() instead.
        port.ser.timeout = READ_BLOCK_S
        self.port = port
        self._state_reader = sdk.GroupSyncRead(port, self.ph, P.PRESENT_VELOCITY[0], 8)
        self._error_reader = sdk.GroupSyncRead(port, self.ph, P.HARDWARE_ERROR_STATUS[0], 1)
        for sid in self.ids:
            self._state_reader.addParam(sid)
            self._error_reader.addParam(sid)
        return self

    def close(self) -> None:
        if self.port is not None:
            self.port.closePort()
            self.port = None

    def recover_port(self) -> None:
        """Make the port usable after an interrupted transaction (Ctrl-C leaves the SDK's busy flag set)."""
        if self.port is not None:
            self.port.is_using = False

    def __enter__(self) -> DynamixelBus:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def _name(self, sid: int) -> str:
        joint = self.joints[self.ids.index(sid)] if sid in self.ids else "?"
        return f"{joint} (id {sid})"

    def comm_text(self, result: int, tried: Tried | None = None) -> str:
        """The SDK's words for a communication result, with 'timeout' and how it was tried."""
        text = self.ph.getTxRxResult(result).replace("[TxRxResult] ", "")
        kind = "timeout: no answer in time" if result == sdk.COMM_RX_TIMEOUT else "no valid answer"
        return f"{text} ({kind}; {tried})" if tried is not None else text

    # --- checks ---------------------------------------------------------------------------------------------
    def ping_all(self) -> dict[str, int]:
        """Ping every configured servo; one BusError lists every missing id and unexpected model number."""
        problems, models = [], {}
        for joint, sid in zip(self.joints, self.ids, strict=True):
            (model, result, _), tried = with_retries(partial(self.ph.ping, self.port, sid), itemgetter(1))
            if result != sdk.COMM_SUCCESS:
                problems.append(f"{joint} (id {sid}): no answer ({self.comm_text(result, tried)})")
                continue
            models[joint] = model
            expected = self.servos.models.get(joint)
            if expected is not None and model != expected:
                problems.append(f"{joint} (id {sid}): model number {model}, expected {expected}")
        if problems:
            raise BusError(
                f"{self.port_name}: {len(problems)} servo problem(s):\n  "
                + "\n  ".join(problems)
                + "\ncheck power, cables and ids (Dynamixel Wizard), or fix 'servos' in the robot config"
            )
        return models

    def hardware_errors(self) -> dict[str, int]:
        """Non-zero Hardware Error Status per joint (polled: sync read replies drop the alert bit)."""
        self._sync_read(self._error_reader, "hardware error status")
        errors = {}
        for joint, sid in zip(self.joints, self.ids, strict=True):
            bits = self._error_reader.getData(sid, P.HARDWARE_ERROR_STATUS[0], 1)
            if bits:
                errors[joint] = bits
        return errors

    def check_hardware(self) -> None:
        """Raise BusError when any servo reports a hardware error."""
        errors = self.hardware_errors()
        if errors:
            listed = "; ".join(f"{j} (id {self.servos.ids[j]}): {hardware_error_text(b)}" for j, b in errors.items())
            raise BusError(
                f"{self.port_name}: hardware error: {listed}; the servo switched its torque off: remove the "
                "cause (load, temperature, supply voltage), then reboot the servo or power-cycle the robot"
            )

    # --- reading --------------------------------------------------------------------------------------------
    def _sync_read(self, group: sdk.GroupSyncRead, what: str) -> None:
        failed_at: Counter[int] = Counter()  # per servo, the attempts that failed at it

        def attempt() -> int:
            result = group.txRxPacket()
            # the SDK takes any status packet of the right id: on a busy host the late reply to an earlier request
            # (of another length) can stand for this one's; such a read failed, and the stale bytes are dropped
            short = next((sid for sid in self.ids if len(group.data_dict.get(sid) or []) < group.data_length), None)
            if result == sdk.COMM_SUCCESS and short is not None and self.port is not None:
                self.port.clearPort()
                result = sdk.COMM_RX_CORRUPT
            # the SDK stops at the first servo that failed; its data is left empty
            culprit = next((sid for sid in self.ids if not group.data_dict.get(sid)), None)
            culprit = short if culprit is None else culprit
            if result != sdk.COMM_SUCCESS and culprit is not None:
                failed_at[culprit] += 1
            return result

        result, tried = with_retries(attempt, lambda result: result)
        if result == sdk.COMM_SUCCESS:
            return
        # the servo most attempts failed at: on a busy host one attempt can fail earlier, at a servo whose answer
        # was merely slow, while the silent servo fails every other attempt
        who = self._name(failed_at.most_common(1)[0][0]) if failed_at else "a servo"
        raise BusError(
            f"{self.port_name}: sync read of {what} failed at {who}: {self.comm_text(result, tried)}; "
            "check that servo's cable and power"
        )

    def read_state(self) -> JointState:
        """Present position and velocity of every joint in one sync read."""
        self._sync_read(self._state_reader, "present position/velocity")
        get = self._state_reader.getData
        ticks = np.array([_signed32(get(s, P.PRESENT_POSITION[0], 4)) for s in self.ids])
        vel = np.array([_signed32(get(s, P.PRESENT_VELOCITY[0], 4)) for s in self.ids])
        return JointState(ticks, vel)

    # --- writing --------------------------------------------------------------------------------------------
    def _write(self, joint: str, item: tuple[int, int], value: int) -> None:
        sid = self.servos.ids[joint]
        addr, size = item
        write = {1: self.ph.write1ByteTxRx, 2: self.ph.write2ByteTxRx, 4: self.ph.write4ByteTxRx}[size]
        unsigned = value & ((1 << (8 * size)) - 1)
        (result, error), tried = with_retries(partial(write, self.port, sid, addr, unsigned), itemgetter(0))
        if result != sdk.COMM_SUCCESS:
            raise BusError(
                f"{self.port_name}: writing address {addr} of {self._name(sid)} failed: "
                f"{self.comm_text(result, tried)}; check that servo's cable and power"
            )
        if error & 0x7F:
            raise BusError(
                f"{self.port_name}: {self._name(sid)} refused writing address {addr}: "
                f"{self.ph.getRxPacketError(error & 0x7F)}"
                + ("; it reports a hardware error: reboot it" if error & P.ERR_ALERT else "")
            )

    def set_torque(self, joints: Iterable[str], on: bool) -> None:
        """Torque on or off, joint by joint, each acknowledged."""
        for joint in joints:
            self._write(joint, P.TORQUE_ENABLE, int(on))

    def torque_enabled(self) -> dict[str, bool]:
        """Torque Enable of every joint, read servo by servo."""
        result = {}
        for joint, sid in zip(self.joints, self.ids, strict=True):
            read = partial(self.ph.read1ByteTxRx, self.port, sid, P.TORQUE_ENABLE[0])
            (value, comm, _), tried = with_retries(read, itemgetter(1))
            if comm != sdk.COMM_SUCCESS:
                raise BusError(
                    f"{self.port_name}: reading the torque state of {self._name(sid)} failed: "
                    f"{self.comm_text(comm, tried)}"
                )
            result[joint] = bool(value)
        return result

    def set_profile_velocity(self, joints: Iterable[str], rad_s: float) -> None:
        """Limit the speed of position moves to `rad_s` (at least one unit of 0.229 rpm)."""
        units = max(1, int(round(rad_s / P.RAD_S_PER_UNIT)))
        for joint in joints:
            self._write(joint, P.PROFILE_VELOCITY, units)

    def set_profile_acceleration(self, joints: Iterable[str], rad_s2: float) -> None:
        """Limit the acceleration of position moves to `rad_s2` (at least one unit of 214.577 rev/min^2); the
        servo speeds up and slows down along a trapezoid of the profile velocity and this acceleration."""
        units = max(1, int(round(rad_s2 / P.RAD_S2_PER_UNIT)))
        for joint in joints:
            self._write(joint, P.PROFILE_ACCELERATION, units)

    def set_goal_positions(self, goals: dict[str, float]) -> None:
        """Goal positions [rad] in one sync write (no reply: read back to confirm arrival)."""
        group = sdk.GroupSyncWrite(self.port, self.ph, P.GOAL_POSITION[0], 4)
        for joint, rad in goals.items():
            tick = int(rad_to_ticks(rad))
            group.addParam(self.servos.ids[joint], list((tick & 0xFFFFFFFF).to_bytes(4, "little")))
        result = group.txPacket()
        if result != sdk.COMM_SUCCESS:
            raise BusError(f"{self.port_name}: sending goal positions failed: {self.comm_text(result)}")

    def reboot(self, joint: str) -> None:
        """Reboot a servo: clears its hardware error; its torque comes back off."""
        sid = self.servos.ids[joint]
        (result, _), tried = with_retries(partial(self.ph.reboot, self.port, sid), itemgetter(0))
        if result != sdk.COMM_SUCCESS:
            raise BusError(f"{self.port_name}: rebooting {self._name(sid)} failed: {self.comm_text(result, tried)}")
