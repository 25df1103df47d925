"""Faults the emulator can inject, their `--fault` syntax and what each does to a servo.

`no-answer` (the servo falls silent), `crc` (its replies are corrupted), `hw-error` (hardware error status bits:
alert bit in every reply, torque off until REBOOT), `missing` (the id is not on the bus), `model` (it reports
another model number), `late` (its next VALUE replies, default 3, come after the master has given up waiting, as
on a busy host: they are dropped), `stale` (its next VALUE replies, default 1, come so late that they arrive just
before its reply to the next instruction, as the answer to a request the master gave up on can on a busy host).
Each may start some seconds after the emulator.
"""

from __future__ import annotations

from dataclasses import dataclass

from wolfcal.errors import WolfcalError
from wolfcal.hardware import protocol as P
from wolfcal.hardware.emulator.servo import EmulatedServo

FAULT_KINDS = ("no-answer", "crc", "hw-error", "missing", "model", "late", "stale")
OVERLOAD = 32  # hw-error default: the overload bit of Hardware Error Status
LATE_REPLIES = 3  # late default: replies that come too late


@dataclass(frozen=True)
class Fault:
    kind: str
    servo_id: int
    value: int = 0  # hw-error: status bits (default overload, 32); model: the model number reported
    after_s: float = 0.0  # seconds after the emulator starts


def parse_fault(text: str) -> Fault:
    """`KIND:ID[=VALUE][@SECONDS]`, e.g. `no-answer:13@5`, `hw-error:20=32`, `model:7=1020`, `missing:4`."""
    try:
        kind, rest = text.split(":", 1)
        rest, _, after = rest.partition("@")
        sid, _, value = rest.partition("=")
        fault = Fault(
            kind,
            int(sid),
            int(value) if value else {"hw-error": OVERLOAD, "late": LATE_REPLIES, "stale": 1}.get(kind, 0),
            float(after) if after else 0.0,
        )
    except ValueError:
        raise WolfcalError(
            f"--fault {text!r}: expected KIND:ID[=VALUE][@SECONDS] with KIND one of {', '.join(FAULT_KINDS)}"
        ) from None
    if fault.kind not in FAULT_KINDS:
        raise WolfcalError(f"--fault {text!r}: unknown kind {kind!r}; use one of {', '.join(FAULT_KINDS)}")
    if fault.kind == "model" and not fault.value:
        raise WolfcalError(f"--fault {text!r}: give the model number to report, e.g. model:{sid}=1020")
    return fault


def inject(servos: dict[int, EmulatedServo], fault: Fault) -> None:
    """Make the fault's servo (if on the bus) misbehave from now on."""
    servo = servos.get(fault.servo_id)
    if servo is None:
        return
    if fault.kind == "no-answer":
        servo.silent = True
    elif fault.kind == "crc":
        servo.corrupt = True
    elif fault.kind == "missing":
        servo.missing = True
    elif fault.kind == "model":
        servo.write(P.MODEL_NUMBER, fault.value)
    elif fault.kind == "late":
        servo.late_replies = fault.value
    elif fault.kind == "stale":
        servo.stale_replies = fault.value
    elif fault.kind == "hw-error":
        servo.write(P.HARDWARE_ERROR_STATUS, fault.value)
        servo.write(P.TORQUE_ENABLE, 0)


class FaultSchedule:
    """Faults waiting for their start time [s after `start`, monotonic clock]."""

    def __init__(self, faults: list[Fault], start: float):
        self.pending = sorted(faults, key=lambda f: f.after_s)
        self.start = start

    def due(self, now: float) -> list[Fault]:
        """The faults whose start time has come by `now`, removed from the schedule."""
        due = []
        while self.pending and self.pending[0].after_s <= now - self.start:
            due.append(self.pending.pop(0))
        return due
