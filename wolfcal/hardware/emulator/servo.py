"""One emulated servo: its control table and how its true angle [rad] moves.

It reports what a real servo with a miscalibrated encoder would: present position = round((true angle - true
offset) / (2 pi / 4096)) + 2048 ticks. With torque on the true angle moves towards the goal along the velocity-based
profile of the Dynamixel documentation: speed up at the profile acceleration (0: at once), cruise at the profile
velocity (0: MAX_SPEED), slow down at the profile acceleration so as to stop at the goal (a trapezoid, or a
triangle for a short move). With torque off it stays where it is unless the emulated operator moves it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wolfcal.encoders import RAD_PER_TICK
from wolfcal.hardware import protocol as P
from wolfcal.hardware.emulator.table import ControlTable

FIRMWARE = 46  # firmware version reported by every servo
MAX_SPEED = 5.0  # rad/s when the profile velocity is 0 (unlimited)
DEFAULT_MODEL = 311  # model number of a joint the robot config gives none for (MX-64(2.0))


@dataclass
class ServoSpec:
    joint: str
    model: int
    offset: float = 0.0  # true encoder offset: true angle = reading + offset [rad]


class EmulatedServo(ControlTable):
    """Control table, true angle [rad] and speed [rad/s] of one servo; `silent`, `corrupt`, `missing` are faults."""

    def __init__(self, sid: int, spec: ServoSpec):
        self.sid, self.spec = sid, spec
        super().__init__(P.CONTROL_TABLE_SIZE)
        self.angle = 0.0
        self.speed = 0.0
        self.silent = self.corrupt = self.missing = False
        self.late_replies = 0  # fault: replies still to come too late for the master (dropped)
        self.stale_replies = 0  # fault: replies still to be held back until the next reply (sent before it)
        self.held = b""  # replies held back, sent before the next one
        self.write(P.MODEL_NUMBER, spec.model)
        self.write(P.FIRMWARE_VERSION, FIRMWARE)
        self.write(P.ID, sid)
        self.write(P.GOAL_POSITION, self.reading())
        self.update_present()

    @property
    def answers(self) -> bool:
        """False while a fault keeps it off the bus (no reply, no effect of instructions)."""
        return not (self.silent or self.missing)

    @property
    def torque_on(self) -> bool:
        return self.read(P.TORQUE_ENABLE) == 1

    def reading(self) -> int:
        """The present position [ticks] its encoder gives for the true angle."""
        return int(round((self.angle - self.spec.offset) / RAD_PER_TICK)) + P.CENTRE_TICK

    def update_present(self) -> None:
        self.write(P.PRESENT_POSITION, self.reading())
        self.write(P.PRESENT_VELOCITY, int(round(self.speed / P.RAD_S_PER_UNIT)))

    def step(self, dt: float, operator_target: float | None, operator_speed: float) -> None:
        """Move for `dt` seconds: to the goal under torque, else to the operator's target [rad] at `operator_speed`
        [rad/s] when there is one."""
        accel = math.inf
        if self.torque_on:
            target = (self.read(P.GOAL_POSITION, signed=True) - P.CENTRE_TICK) * RAD_PER_TICK + self.spec.offset
            profile = self.read(P.PROFILE_VELOCITY)
            vmax = profile * P.RAD_S_PER_UNIT if profile else MAX_SPEED
            accel = self.read(P.PROFILE_ACCELERATION) * P.RAD_S2_PER_UNIT or math.inf
        elif operator_target is not None:
            target, vmax = operator_target, operator_speed
        else:
            target, vmax = self.angle, 0.0
        delta = target - self.angle
        if math.isinf(accel):
            move = math.copysign(min(abs(delta), vmax * dt), delta)
            speed = move / dt if dt > 0 and abs(delta) > 1e-12 else 0.0
        else:  # speed up towards vmax, or slow down once the distance left is what stopping takes
            toward = self.speed * math.copysign(1.0, delta)  # present speed towards the goal [rad/s]
            if toward > 0 and toward**2 / (2.0 * accel) >= abs(delta):
                toward -= accel * dt
            else:
                toward = min(vmax, toward + accel * dt)
            speed = math.copysign(toward, delta)
            move = 0.5 * (self.speed + speed) * dt
            if move * delta > 0 and abs(move) >= abs(delta) or abs(delta) <= 1e-12:
                move, speed = delta, 0.0  # arrives within this step
        self.angle += move
        self.speed = speed
        self.write(P.MOVING, int(abs(target - self.angle) > 1e-12))
        self.update_present()

    def error_byte(self) -> int:
        """The alert bit every status packet carries while a hardware error is set."""
        return P.ERR_ALERT if self.read(P.HARDWARE_ERROR_STATUS) else 0
