"""Scripted capture: torque on, the robot driven through a poses file at a limited profile velocity; at each pose,
once every joint has arrived, a sample is tried for until one is taken or the pose times out (then skipped)."""

from __future__ import annotations

import time

from wolfcal.capture.poses import PoseScript
from wolfcal.capture.session import POLL_S, CaptureSession
from wolfcal.hardware.bus import rad_to_ticks

ARRIVAL_TICKS = 8  # a joint within this many ticks of its goal has arrived (servos under load stop short)
ARRIVAL_MARGIN_S = 3.0  # time allowed for a move beyond distance / velocity


def run_scripted(session: CaptureSession, script: PoseScript) -> None:
    """Drive the script's joints through its poses, sampling at each; skipped poses go to the summary."""
    bus, status = session.bus, session.status
    index = {j: k for k, j in enumerate(bus.joints)}
    velocity = session.options.velocity or script.velocity
    goals = torque_on(session, script.joints, velocity)
    for number, pose in enumerate(script.poses, start=1):
        if session.done():
            return
        status.pose = f"{pose.name}, pose {number}/{len(script.poses)} of the plan"
        goals.update(pose.joints)
        bus.set_goal_positions(goals)
        reason = wait_arrival(session, goals, index, velocity)
        if reason is None:
            reason = sample_until(session, time.monotonic() + session.options.pose_timeout_s)
        if reason is not None:
            session.summary.skipped.append(f"{pose.name}: {reason}")
            session.view.event(f"pose {pose.name} skipped: {reason}")
        status.waiting = ""


def torque_on(session: CaptureSession, joints: list[str], velocity: float) -> dict[str, float]:
    """Torque on for `joints`, each holding where it stands (no jump to a stale goal), later moves at `velocity`
    [rad/s]; returns the goals [rad] by joint."""
    state = session.read()
    index = {j: k for k, j in enumerate(session.bus.joints)}
    goals = {j: float(state.positions[index[j]]) for j in joints}
    session.bus.set_goal_positions(goals)
    session.bus.set_profile_velocity(joints, velocity)
    session.bus.set_torque(joints, True)
    return goals


def sample_until(session: CaptureSession, deadline: float) -> str | None:
    """Try for a sample until one is taken (None) or the deadline (`time.monotonic()` [s]) passes (the last
    reason)."""
    while True:
        reason = session.try_sample()
        if reason is None or time.monotonic() > deadline:
            return reason
        session.status.waiting = reason
        session.view.refresh()
        time.sleep(POLL_S)
        session.read()


def wait_arrival(
    session: CaptureSession, goals: dict[str, float], index: dict[str, int], velocity: float
) -> str | None:
    """Wait until every joint is within ARRIVAL_TICKS of its goal [rad] (None), or why it did not arrive in time;
    `index` maps joints to bus order, `velocity` [rad/s] sets the time allowed."""
    goal_ticks = {j: int(rad_to_ticks(q)) for j, q in goals.items()}
    state = session.read()
    distance = max(abs(state.positions[index[j]] - q) for j, q in goals.items())
    deadline = time.monotonic() + distance / velocity + ARRIVAL_MARGIN_S
    while True:
        off = {j: abs(int(state.ticks[index[j]]) - t) for j, t in goal_ticks.items()}
        worst = max(off, key=lambda j: off[j])
        if off[worst] <= ARRIVAL_TICKS:  # then the stillness gate waits for it to settle
            return None
        if time.monotonic() > deadline:
            return f"did not arrive: {worst} is {off[worst]} ticks from its goal"
        session.status.waiting = f"moving ({worst} {off[worst]} ticks to go)"
        session.status.still = "no"
        session.view.refresh()
        time.sleep(POLL_S)
        state = session.read()
