"""The torque a capture leaves on the joints it touched (--exit-torque): as found, on (holding where each joint
stands) or off; best effort, so that a failing bus still gets every joint it can. And how a capture ends: what its
file holds, how the torque was left, its failure raised after that is said."""

from __future__ import annotations

from rich.console import Console

from wolfcal.capture.session import CaptureSummary
from wolfcal.errors import WolfcalError
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


def say_end(
    summary: CaptureSummary,
    failure: BaseException | None,
    failed: list[str],
    exit_torque: str,
    port: str,
    console: Console,
    what: str = "sample(s)",
) -> None:
    """What the file holds and how the torque was left; raises the capture's failure (with that said) if any."""
    saved = f"{summary.samples} {what} saved in {summary.path}" if summary.path else f"no {what[:-3]} taken, no file"
    if failed:
        saved += (
            f"\ntorque could not be left as chosen (--exit-torque {exit_torque}) on {', '.join(failed)}: "
            "check these joints before touching the robot"
        )
        failure = failure if isinstance(failure, WolfcalError) else BusError(f"{port}: bus failure at exit")
    if isinstance(failure, WolfcalError):
        raise type(failure)(f"{failure}\n{saved}") from None
    console.print(saved)
    if failure is not None:  # Ctrl-C, SIGTERM, SIGHUP, or an unexpected error (its traceback is wanted)
        raise failure
