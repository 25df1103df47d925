"""The emulated operator of manual capture: moves the limp joints through a list of poses, holding each."""

from __future__ import annotations

from wolfcal.hardware import protocol as P
from wolfcal.hardware.emulator.servo import EmulatedServo

OPERATOR_SPEED = 1.5  # rad/s of the emulated operator moving limp joints


class EmulatedOperator:
    """Poses are joint -> reading [rad]; the operator brings each limp joint to reading + true offset, waits until
    every one has arrived, holds the pose `hold_s` seconds, then goes on to the next (cycling)."""

    def __init__(self, poses: list[dict[str, float]], hold_s: float, start: float):
        self.poses, self.hold_s = poses, hold_s
        self.index = 0
        self.since = start  # when the current pose was reached (or last found not reached)

    def targets(self, servos: dict[int, EmulatedServo], now: float) -> dict[int, float]:
        """True angles [rad] per servo id the operator is moving the limp joints to."""
        if not self.poses:
            return {}
        pose = self.poses[self.index % len(self.poses)]
        limp = [s for s in servos.values() if s.read(P.TORQUE_ENABLE) == 0]
        targets = {s.sid: pose[s.spec.joint] + s.spec.offset for s in limp if s.spec.joint in pose}
        arrived = all(abs(servos[sid].angle - a) < 1e-9 for sid, a in targets.items())
        if not arrived:
            self.since = now
        elif now - self.since >= self.hold_s:
            self.index += 1
            self.since = now
        return targets
