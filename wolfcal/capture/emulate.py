"""`wolfcal emulate`: serve a robot's buses on ptys until Ctrl-C (or SIGTERM); prints what to give --port first.

Every bus of the config (`servos.ports`, or `servos.port`) gets a pty; with `imu.bus`, the IMU answers on its bus
(`wolfcal.hardware.emulator.imu`), mounted as the truth file says (the IMU joint's frame correction and
`imu_bias_m_s2`, as `wolfcal simulate --system imu` writes them) with the simulator's accelerometer and gyro noise.
"""

from __future__ import annotations

import signal
from collections.abc import Callable
from pathlib import Path

from wolfcal.capture.poses import joint_limits, load_poses
from wolfcal.errors import WolfcalError
from wolfcal.hardware.emulator.faults import parse_fault
from wolfcal.hardware.emulator.imu import ImuSpec
from wolfcal.hardware.emulator.process import port_option
from wolfcal.hardware.emulator.serve import serve
from wolfcal.hardware.emulator.spec import load_truth, spec_from_config
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.imu_mount import IMU_KEY, imu_joint
from wolfcal.robot.robot import Robot, load_robot


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
        imu=emulated_imu(robot, corrections, truth),
    )

    def ready(ports: dict[str | None, str]) -> None:
        say(port_option(ports))
        imu = f" and the IMU (id {spec.imu.layout.id})" if spec.imu is not None else ""
        where = ", ".join(f"{device} on {path}" if device else path for device, path in ports.items())
        say(f"emulating {len(spec.servos)} servos{imu} of {robot.config.path}: {where} (Ctrl-C to stop)")

    def stop(signum: int, frame) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)  # clean up the published state on `kill` as on Ctrl-C
    try:
        serve(spec, ready)
    except KeyboardInterrupt:
        say("emulator stopped")


def emulated_imu(robot: Robot, truth: Corrections | None, truth_path: Path | None, seed: int = 0) -> ImuSpec | None:
    """The IMU on the bus when the config has `imu.bus`: its true mount from `truth` (the IMU joint's frame
    correction), its bias from the truth file's `imu_bias_m_s2` (0 without), the simulator's noise."""
    from wolfcal.sim.imu import ImuSimOptions, load_corrections_bias

    section = robot.config.sections.get(IMU_KEY)
    if section is None or section.bus is None:
        return None
    imu_joint(robot)  # a clear error for an IMU frame the URDF lacks
    robot.config.floor_config("the emulated IMU measures gravity along the floor's normal: it needs 'floor.soles'")
    bias = load_corrections_bias(truth_path) if truth_path is not None else [0.0, 0.0, 0.0]
    noise = ImuSimOptions()
    return ImuSpec(str(robot.config.path), section.bus, truth or Corrections(), (bias[0], bias[1], bias[2]),
                   noise.accel_noise, noise.gyro_noise, seed=seed)  # fmt: skip
