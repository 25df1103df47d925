"""Manual capture: torque off on the chosen joints (after confirmation), the operator poses the robot by hand; a
sample is taken whenever a joint has moved `moved_rad` since the last sample and the robot is still again with a
tag in view, or when the operator presses Enter."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

import numpy as np

from wolfcal.capture.session import POLL_S, CaptureSession
from wolfcal.encoders import RAD_PER_TICK
from wolfcal.errors import WolfcalError
from wolfcal.robot.robot import Robot


def joint_groups(robot: Robot) -> dict[str, list[str]]:
    """Groups of the servo joints: head (base -> camera), legs (base -> foot tags), arms (the rest), all."""
    if robot.config.servos is None:
        raise WolfcalError(f"{robot.config.path}: no 'servos' section: manual capture reads the joints over the bus")
    servo_joints = list(robot.config.servos.ids)
    head = [j for j in robot.camera_and_leg_joints(sides=()) if j in servo_joints]
    legs = [j for j in robot.camera_and_leg_joints() if j in servo_joints and j not in head]
    arms = [j for j in servo_joints if j not in head and j not in legs]
    return {"head": head, "legs": legs, "arms": arms, "all": servo_joints}


def parse_limp(text: str, robot: Robot) -> list[str]:
    """The joints named by --limp (groups or joint names, comma-separated), each once, in order."""
    groups = joint_groups(robot)
    joints: list[str] = []
    for item in (t.strip() for t in text.split(",") if t.strip()):
        names = groups.get(item, [item] if item in groups["all"] else None)
        if names is None:
            raise WolfcalError(
                f"--limp {text!r}: {item!r} is neither a group ({', '.join(groups)}) nor a servo joint of "
                f"{robot.config.path}"
            )
        joints += [n for n in names if n not in joints]
    if not joints:
        raise WolfcalError("--limp names no joint; give e.g. head,legs")
    return joints


def confirm_limp(joints: list[str], yes: bool, ask: Callable[[str], bool] | None, legs_hold: bool = False) -> None:
    """Refuse (WolfcalError) to switch torque off on `joints` unless `yes` or the operator confirms through `ask`;
    `legs_hold`: the legs keep their torque (a floor capture), so the robot does not fall."""
    if yes:
        return
    warning = ("The legs stay on, holding the standing pose." if legs_hold
               else "A standing robot will fall: hold it, hang it up or sit it down.")  # fmt: skip
    question = f"Torque goes OFF on {len(joints)} joint(s): {', '.join(joints)}. {warning} Continue?"
    if ask is None or not ask(question):
        raise WolfcalError(
            "manual capture needs torque off on "
            + ", ".join(joints)
            + (
                "; not confirmed"
                if ask is not None
                else "; no terminal to ask on: pass --yes"
                + ("" if legs_hold else " once the robot is supported (hanging or sitting)")
            )
        )


class EnterKey:
    """Sets `pressed` when the operator presses Enter (only when stdin is a terminal)."""

    def __init__(self) -> None:
        self.pressed = threading.Event()
        if sys.stdin is not None and sys.stdin.isatty():
            threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        for _ in sys.stdin:
            self.pressed.set()


def run_manual(session: CaptureSession, limp: list[str], until: int | None = None) -> None:
    """Switch torque off on `limp` and take samples as the operator poses the robot, until enough are taken (or
    the file holds `until` samples)."""
    session.bus.set_torque(limp, False)
    status = session.status
    enter = EnterKey()
    reference = session.read().ticks  # readings at the last sample
    moved = False
    threshold = session.gates.moved_rad / RAD_PER_TICK  # [ticks]
    while not session.done() and (until is None or session.summary.samples < until):
        state = session.read()
        moved = moved or bool(np.max(np.abs(state.ticks - reference)) >= threshold)
        forced = enter.pressed.is_set()
        if moved or forced:
            reason = session.try_sample()
            if reason is None:
                moved = False
                enter.pressed.clear()
                reference = session.window.readings[-1][1]
            status.waiting = reason or ""
        else:
            status.still = "yes" if session.window.why_not_still(time.monotonic()) is None else "no"
            status.waiting = "pose the robot (a sample is taken when it is still), or press Enter"
        session.view.refresh()
        time.sleep(POLL_S)
