"""`wolfcal emulate`: serve a robot's bus on a pty until Ctrl-C (or SIGTERM); prints the port to give --port."""

from __future__ import annotations

import signal
from collections.abc import Callable
from pathlib import Path

from wolfcal.capture.poses import joint_limits, load_poses
from wolfcal.errors import WolfcalError
from wolfcal.hardware.emulator.faults import parse_fault
from wolfcal.hardware.emulator.serve import serve
from wolfcal.hardware.emulator.spec import load_truth, spec_from_config
from wolfcal.robot.robot import load_robot


def emulate(
    robot_path: Path,
    truth: Path | None,
    faults: list[str],
    operator: Path | None,
    hold_s: float,
    say: Callable[[str], None] = print,
) -> None:
    """Emulate the bus of the robot config at `robot_path`: true offsets from `truth`, `--fault` texts, the
    operator's poses file (manual capture), each held `hold_s` seconds."""
    robot = load_robot(robot_path)
    corrections = load_truth(truth) if truth is not None else None
    poses = []
    if operator is not None:
        poses = [p.joints for p in load_poses(operator, joint_limits(robot, robot.joint_names)).poses]
    parsed = [parse_fault(f) for f in faults]
    ids = robot.config.servos.ids if robot.config.servos is not None else {}
    unknown = [text for text, fault in zip(faults, parsed) if fault.servo_id not in ids.values()]
    if unknown:
        listed = ", ".join(f"{joint} {sid}" for joint, sid in sorted(ids.items(), key=lambda item: item[1]))
        raise WolfcalError(
            f"--fault {', '.join(unknown)}: no servo with this id in {robot.config.path} (ids: {listed or 'none'}); "
            "give the id of a configured servo"
        )
    spec = spec_from_config(
        robot.config,
        corrections,
        parsed,
        poses,
        hold_s,
        str(truth.resolve()) if truth is not None else None,
    )

    def ready(port: str) -> None:
        say(port)
        say(f"emulating {len(spec.servos)} servos of {robot.config.path} on {port} (Ctrl-C to stop)")

    def stop(signum: int, frame) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)  # clean up the published state on `kill` as on Ctrl-C
    try:
        serve(spec, ready)
    except KeyboardInterrupt:
        say("emulator stopped")
