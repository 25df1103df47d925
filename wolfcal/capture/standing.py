"""`wolfcal capture --standing`: standing samples for the IMU's mount. The robot stands on a flat floor; its legs
(torque on, after confirmation) go through the config's standing stances (`imu.stances`, else stances from the floor
stance that turn the torso by up to 0.3 rad and tilt it by up to 0.15 rad with both soles where they stand:
`wolfcal.sim.imu.imu_stances`, as `wolfcal simulate --system imu`), holding each until the joints and the IMU
(`imu.bus`, read over the servo bus) have been still for HOLD_S, by the same test the reader applies
(`wolfcal.io.imu.still_messages`); a stance that does not get there within STANCE_TIMEOUT_S after arriving is
skipped with the reason.

Recorded throughout, moves included, at up to RATE_HZ: a JointState per bus reading and an Imu per IMU reading, each
stamped when read (`wolfcal.io.standing_writer`): a recording the IMU reader takes like `ros2 bag record`.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from rich.console import Console

from wolfcal.capture.exit_torque import leave_torque, say_end
from wolfcal.capture.manual import joint_groups
from wolfcal.capture.options import CaptureOptions, check_options
from wolfcal.capture.poses import DEFAULT_VELOCITY, joint_limits
from wolfcal.capture.scripted import ARRIVAL_MARGIN_S
from wolfcal.capture.session import CaptureSummary
from wolfcal.capture.signals import interruption, signals_held, stop_on_signals
from wolfcal.capture.standing_recorder import StandingRecorder
from wolfcal.capture.view import Coverage, LiveView, Status
from wolfcal.errors import WolfcalError
from wolfcal.hardware.bus import BusError
from wolfcal.hardware.buses import ServoBuses
from wolfcal.hardware.imu_device import BusImu
from wolfcal.io.imu import EDGE_S, MIN_STILL_S
from wolfcal.io.standing_writer import StandingWriter
from wolfcal.robot.imu_mount import imu_config
from wolfcal.robot.robot import Robot, load_robot

HOLD_S = MIN_STILL_S + 2 * EDGE_S + 0.4  # still time held in each stance [s] (the reader keeps MIN_STILL_S of it)
STANCE_TIMEOUT_S = 15.0  # a stance not held still this long after arriving is skipped [s]
RATE_HZ = 100.0  # readings per second at most


def standing_stances(robot: Robot) -> list[tuple[str, dict[str, float]]]:
    """(name, readings [rad] of the leg servos) per stance (module docstring), every one within the URDF limits
    (WolfcalError naming the stance otherwise): checked before anything moves."""
    from wolfcal.sim.imu import imu_stances

    config = imu_config(robot, "capture --standing needs the IMU's frame, topic and place on the bus")
    q = imu_stances(robot)
    legs = joint_groups(robot)["legs"]
    key = "imu.stances" if config.stances else "the stances made from the floor stance (`floor.stances`)"
    stances = []
    for k, row in enumerate(q):
        targets = {j: float(row[robot.model.column(j)]) for j in legs}
        outside = [f"{j} = {v:.4f} rad (limits [{lo:.4f}, {hi:.4f}])" for j, v in targets.items()
                   for lo, hi in [joint_limits(robot, [j])[j]] if not lo <= v <= hi]  # fmt: skip
        if outside:
            raise WolfcalError(f"{robot.config.path}: stance {k} of {key} puts joints outside their URDF limits: "
                               + "; ".join(outside) + "; nothing was moved")  # fmt: skip
        stances.append((f"imu.stances[{k}]" if config.stances else f"stance {k}", targets))
    return stances


def confirm_standing(legs: list[str], count: int, yes: bool, ask: Callable[[str], bool] | None) -> None:
    """Refuse (WolfcalError) to switch the legs' torque on and move them unless `yes` or the operator confirms."""
    if yes:
        return
    question = (f"Torque goes ON on {len(legs)} leg joint(s) and the legs move through {count} stances that turn "
                "and tilt the torso. Stand the robot on a flat floor, soles flat, and be ready to catch it. "
                "Continue?")  # fmt: skip
    if ask is None or not ask(question):
        raise WolfcalError("--standing moves the standing robot's legs with torque on; "
                           + ("not confirmed" if ask is not None else "no terminal to ask on: pass --yes"))  # fmt: skip


def run_standing(options: CaptureOptions, console: Console, ask: Callable[[str], bool] | None) -> CaptureSummary:
    """Run a standing capture; the summary counts the stances held. Errors are WolfcalError subclasses."""
    check_options(options)
    robot = load_robot(options.robot)
    servos = robot.config.servos
    if servos is None:
        raise WolfcalError(f"{robot.config.path}: no 'servos' section (port, ids): capture needs the servo bus")
    layout = imu_config(robot, "capture --standing records the IMU").bus
    if layout is None:
        raise WolfcalError(f"{robot.config.path}: no 'imu.bus': capture --standing reads the IMU over the servo bus; "
                           "give its id and register layout, or record joint states and the IMU with "
                           "`ros2 bag record` (docs: IMU workflow)")  # fmt: skip
    if layout.port is not None and layout.port not in servos.buses:
        raise WolfcalError(f"{robot.config.path}: 'imu.bus.port' {layout.port} is not a servo bus of the config "
                           f"({', '.join(servos.buses)})")  # fmt: skip
    stances = standing_stances(robot)[: options.samples]
    legs = list(stances[0][1])
    status = Status("standing", len(stances))
    coverage = Coverage(joint_limits(robot, legs))
    summary = CaptureSummary(None, 0)
    with stop_on_signals(), ServoBuses(servos, options.port) as bus:
        bus.ping_all()
        bus.check_hardware()
        imu = BusImu(bus.bus_on(layout.port), layout)
        imu.check()
        initial = bus.torque_enabled()
        confirm_standing(legs, len(stances), options.yes, ask)
        writer = StandingWriter(options.out, robot.config, imu_config(robot).topic, imu_config(robot).frame)
        recorder = StandingRecorder(bus, imu, writer, RATE_HZ)
        failure: BaseException | None = None
        try:
            with LiveView(status, coverage, console) as view:
                velocity = options.velocity or DEFAULT_VELOCITY
                _torque_on(recorder, legs, velocity)
                for k, (name, targets) in enumerate(stances):
                    status.pose = f"{name}, {k + 1}/{len(stances)}"
                    reason = _hold(recorder, targets, velocity, status, view)
                    writer.flush()
                    if reason is None:
                        summary.samples += 1
                        status.taken = summary.samples
                        coverage.add(bus.joints, recorder.last_positions)
                        view.event(f"stance {k + 1}/{len(stances)} ({name}): held still {HOLD_S:.1f} s")
                    else:
                        summary.skipped.append(f"{name}: {reason}")
                        view.event(f"stance {k + 1}/{len(stances)} ({name}) skipped: {reason}")
        except (BusError, KeyboardInterrupt) as exc:  # KeyboardInterrupt: also SIGTERM, SIGHUP
            failure = exc
        except Exception as exc:  # a bug: leave the torque as chosen first, then let it surface
            failure = exc
        with signals_held() as noted:  # nothing cuts restoring the torque short
            try:
                summary.path = writer.close()
            finally:
                bus.recover_port()
                failed = leave_torque(bus, initial, legs, options.exit_torque)
        failure = failure or interruption(noted)
    say_end(summary, failure, failed, options.exit_torque, bus.port_name, console, "held stance(s)")
    return summary


def _torque_on(recorder: StandingRecorder, legs: list[str], velocity: float) -> None:
    """Torque on for the legs, each holding where it stands (no jump to a stale goal); moves at `velocity` [rad/s]."""
    bus = recorder.bus
    positions = recorder.record()
    bus.set_goal_positions({j: float(positions[bus.joints.index(j)]) for j in legs})
    bus.set_profile_velocity(legs, velocity)
    bus.set_torque(legs, True)


def _hold(recorder: StandingRecorder, targets: dict[str, float], velocity: float, status: Status,
          view: LiveView) -> str | None:  # fmt: skip
    """Move the legs to `targets` [rad] and record until the robot has held still HOLD_S (None), or why not."""
    bus = recorder.bus
    start = recorder.record()
    distance = max(abs(float(start[bus.joints.index(j)]) - q) for j, q in targets.items())
    bus.set_goal_positions(targets)
    recorder.begin_stance()
    deadline = time.monotonic() + distance / velocity + ARRIVAL_MARGIN_S + STANCE_TIMEOUT_S
    while True:
        recorder.record()
        held = recorder.still_for()
        if held >= HOLD_S:
            return None
        if time.monotonic() > deadline:
            return f"not still for {HOLD_S:.1f} s within {STANCE_TIMEOUT_S:.0f} s ({recorder.why_not_still()})"
        status.still = f"{held:.1f} s" if held else "no"
        status.waiting = "holding still" if held else "moving or settling"
        view.refresh()
