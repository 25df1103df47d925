"""The torque a capture leaves on the joints it touched (--exit-torque): as found, on (holding where each joint
stands) or off; best effort, so that a failing bus still gets every joint it can."""

from __future__ import annotations

from wolfcal.hardware.bus import BusError
from wolfcal.hardware.buses import ServoBuses


def leave_torque(bus: ServoBuses, initial: dict[str, bool], touched: list[str], mode: str) -> list[str]:
    """Set the torque of the touched joints as `mode` (restore | on | off) says; returns the joints that failed."""
    wanted = {j: (initial[j] if mode == "restore" else mode == "on") for j in touched}
    turn_on = [j for j, on in wanted.items() if on]
    failed = []
    if turn_on:
        try:  # hold where it stands: no jump to an old goal
            state = bus.read_state()
            bus.set_goal_positions({j: float(state.positions[bus.joints.index(j)]) for j in turn_on})
        except BusError:
            failed = list(turn_on)
    for joint in touched:
        if joint in failed:
            continue
        try:
            bus.set_torque([joint], wanted[joint])
        except BusError:
            failed.append(joint)
    return failed
