"""The emulated bus over time: its servos, the emulated operator and scheduled faults, and the IMU when it is on
this bus; instruction bytes in, reply bytes out."""

from __future__ import annotations

import time

from wolfcal.hardware import protocol as P
from wolfcal.hardware.emulator.emulated_operator import EmulatedOperator
from wolfcal.hardware.emulator.faults import Fault, FaultSchedule, inject
from wolfcal.hardware.emulator.imu import EmulatedImu
from wolfcal.hardware.emulator.instructions import Device, answer
from wolfcal.hardware.emulator.servo import EmulatedServo
from wolfcal.hardware.emulator.spec import EmulatorSpec


class EmulatedBus:
    """Feed it the bytes from the master side of the pty, get the reply bytes; `step` advances its servos to now
    (monotonic clock [s]). `imu`: the emulated IMU when it is on this bus (its registers refreshed before each read
    addressed to it)."""

    def __init__(self, spec: EmulatorSpec, imu: EmulatedImu | None = None):
        self.spec, self.imu = spec, imu
        self.servos = {sid: EmulatedServo(sid, s) for sid, s in spec.servos.items()}
        self.parser = P.PacketParser()
        self.last = time.monotonic()
        self.faults = FaultSchedule(spec.faults, self.last)
        self.operator = EmulatedOperator(spec.operator_poses, spec.operator_hold_s, self.last)
        self._start_due_faults(self.last)

    def inject(self, fault: Fault) -> None:
        """Inject a fault now."""
        inject(self.servos, fault)

    def step(self, now: float) -> None:
        """Start the faults due by `now`, then move every servo from the last step to `now`."""
        self._start_due_faults(now)
        dt, self.last = now - self.last, now
        targets = self.operator.targets(self.servos, now)
        for servo in self.servos.values():
            servo.step(dt, targets.get(servo.sid), self.spec.operator_speed)

    def _start_due_faults(self, now: float) -> None:
        for fault in self.faults.due(now):
            self.inject(fault)

    def true_angles(self) -> dict[str, float]:
        """True angle [rad] per joint."""
        return {s.spec.joint: s.angle for s in self.servos.values()}

    def handle(self, data: bytes) -> bytes:
        """The replies to the complete instruction packets received so far (a corrupted one gets none)."""
        out = bytearray()
        devices: dict[int, Device] = {**self.servos}
        if self.imu is not None:
            devices[self.imu.sid] = self.imu
        for packet in self.parser.feed(data):
            if not packet.crc_ok:
                continue
            if self.imu is not None and packet.servo_id == self.imu.sid and packet.instruction == P.READ:
                self.imu.refresh(time.monotonic())
            out += answer(devices, packet)
        return bytes(out)
