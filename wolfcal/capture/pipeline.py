"""`wolfcal capture`: still poses of the robot -> samples (joint angles, an image and camera info per camera) in an
MCAP file.

Checks everything it can before anything moves, opens the bus, the cameras (`cameras`) and the writer, runs the
scripted mode (`scripted`), the manual one (`manual`), a floor capture (`floor`) or a field capture
(`field`; both either way, with standing legs) in a live view, then leaves the torque as --exit-torque says
(`exit_torque`). A standing capture (joint states and the IMU, no camera) is `standing`'s. The file is written
through `CaptureWriter` (each sample durable on return); Ctrl-C, a bus or camera failure finish the file with every
sample taken so far before the error is reported.
"""

from __future__ import annotations

from collections.abc import Callable

from rich.console import Console

from wolfcal.capture.cameras import CaptureCamera, close_sources, open_sources, plan_cameras
from wolfcal.capture.exit_torque import leave_torque, say_end
from wolfcal.capture.field import field_place, field_script, field_standing, one_sided_note
from wolfcal.capture.floor import (
    check_floor_limp,
    check_views,
    floor_joints,
    floor_script,
    stance_name,
    stance_targets,
    stand,
    without_collisions,
)
from wolfcal.capture.manual import confirm_limp, parse_limp, run_manual
from wolfcal.capture.options import CaptureOptions, check_options
from wolfcal.capture.poses import DEFAULT_VELOCITY, PoseScript, check_collisions, joint_limits, load_poses
from wolfcal.capture.scripted import run_scripted
from wolfcal.capture.session import CaptureSession, CaptureSummary
from wolfcal.capture.signals import interruption, signals_held, stop_on_signals
from wolfcal.capture.standing import run_standing
from wolfcal.capture.view import Coverage, LiveView, Status
from wolfcal.errors import WolfcalError
from wolfcal.hardware.bus import BusError
from wolfcal.hardware.buses import ServoBuses
from wolfcal.hardware.camera import CameraError
from wolfcal.io.writer import CaptureWriter
from wolfcal.robot.robot import Robot, load_robot

__all__ = ["CaptureOptions", "CaptureSummary", "run_capture"]


def run_capture(
    options: CaptureOptions, console: Console | None = None, ask: Callable[[str], bool] | None = None
) -> CaptureSummary:
    """Run a capture; the summary says how many samples the file holds. Errors are WolfcalError subclasses."""
    console = console or Console(stderr=True)
    if options.standing:
        return run_standing(options, console, ask)
    check_options(options)
    robot = load_robot(options.robot)
    if robot.config.servos is None:
        raise WolfcalError(f"{robot.config.path}: no 'servos' section (port, ids): capture needs the servo bus")
    limits = joint_limits(robot, robot.config.servos.ids)
    script, limp, stances = _plan(options, robot, limits)  # refused before anything moves
    cameras = plan_cameras(options, robot)
    touched = script.joints if script else [*(stances[0] if stances else {}), *limp]
    mode = ("floor " if options.floor else "field " if options.field_views else "") + (
        "scripted" if script else "manual"
    )
    status = Status(mode, options.samples or (len(script.poses) if script else None))
    coverage = Coverage({j: limits[j] for j in touched})
    with stop_on_signals(), ServoBuses(robot.config.servos, options.port) as bus:
        bus.ping_all()
        bus.check_hardware()
        if script:  # before anything moves: where the robot stands decides the joints no pose names
            script = _checked_script(options, robot, script, bus, status, console)
        initial = bus.torque_enabled()
        if limp and any(initial[j] for j in limp):
            confirm_limp(
                [j for j in limp if initial[j]], options.yes, ask, legs_hold=options.floor or options.field_views
            )
        writer = _open_outputs(options, robot, cameras, bus.port_names)
        view = LiveView(status, coverage, console)
        sources = {name: c.source for name, c in cameras.items() if c.source is not None}  # all opened above
        session = CaptureSession(robot, bus, sources, writer, options, view, coverage, status)
        failure: BaseException | None = None
        try:
            with view:
                if script:
                    run_scripted(session, script)
                elif stances:
                    _manual_stances(session, robot, stances, limp, options, view)
                else:
                    run_manual(session, limp)
        except (BusError, CameraError, KeyboardInterrupt) as exc:  # KeyboardInterrupt: also SIGTERM, SIGHUP
            failure = exc
        except Exception as exc:  # a bug: leave the torque as chosen first, then let it surface
            failure = exc
        with signals_held() as noted:  # nothing cuts restoring the torque short
            try:
                session.summary.path = writer.close()
                close_sources(cameras)
            finally:
                bus.recover_port()
                failed = leave_torque(bus, initial, touched, options.exit_torque)
        failure = failure or interruption(noted)
    say_end(session.summary, failure, failed, options.exit_torque, bus.port_name, console)
    return session.summary


def _checked_script(
    options: CaptureOptions, robot: Robot, script: PoseScript, bus: ServoBuses, status: Status, console: Console
) -> PoseScript:
    """The script checked against collisions from where the robot stands now, before anything moves.

    Floor views the robot cannot take are left out (with a note); a colliding pose of a poses file is refused.
    """
    start = dict(zip(bus.joints, (float(v) for v in bus.read_state().positions)))
    if options.field_views:
        script, note = without_collisions(robot, script, start, "--field")
        note = "\nnote: ".join(n for n in (note, one_sided_note(robot, script)) if n) or None
        status.target = options.samples or len(script.poses)
    elif options.floor:
        script, note = without_collisions(robot, script, start)
        script = check_views(robot, script) if options.floor_check else script
        status.target = options.samples or len(script.poses)
    else:
        note = check_collisions(robot, script, options.poses or "", start)
    if note:
        console.print(f"note: {note}")
    return script


def _open_outputs(
    options: CaptureOptions, robot: Robot, cameras: dict[str, CaptureCamera], ports: list[str]
) -> CaptureWriter:
    """Open the cameras and the crash-safe capture file; the cameras are closed again if the file cannot be opened."""
    open_sources(cameras, robot, ports, field=options.field_views, check=options.floor_check)
    try:
        streams = {name: (c.model, (c.binning, c.binning)) for name, c in cameras.items()}
        return CaptureWriter(options.out, robot.config, streams, options.image_format)
    except WolfcalError:
        close_sources(cameras)
        raise


def _manual_stances(session: CaptureSession, robot: Robot, stances: list[dict[str, float]], limp: list[str],
                    options: CaptureOptions, view: LiveView) -> None:  # fmt: skip
    """Manual floor capture: the legs moved to each stance in turn (torque on), the operator turning the head
    until the stance's share of --samples is taken."""
    shares = [round((k + 1) * (options.samples or 0) / len(stances)) for k in range(len(stances))]
    for k, targets in enumerate(stances):
        stand(session, targets, options.velocity or DEFAULT_VELOCITY)
        if len(stances) > 1:
            view.event(f"stance {k + 1} of {len(stances)} ({stance_name(robot, k, options.floor_check)}): the legs "
                       "hold it; turn the head to show the floor tags")  # fmt: skip
        run_manual(session, limp, until=shares[k] if len(stances) > 1 else None)


def _plan(
    options: CaptureOptions, robot: Robot, limits: dict[str, tuple[float, float]]
) -> tuple[PoseScript | None, list[str], list[dict[str, float]]]:
    """(poses to drive through, joints to switch off for the operator, the stances' readings [rad] the legs hold
    in turn while the operator turns the head (manual floor capture)), each checked before anything moves."""
    script = load_poses(options.poses, limits) if options.poses else None
    standing = options.floor or options.field_views
    limp = parse_limp(options.limp or ("head" if standing else "head,legs"), robot) if options.manual else []
    stances: list[dict[str, float]] = []
    if standing and options.manual:
        check_floor_limp(robot, limp, "--field" if options.field_views else "--floor")
        legs = floor_joints(robot)[0]
        targets = [field_standing(robot)] if options.field_views else stance_targets(robot, options.floor_check)
        stances = [{j: q for j, q in t.items() if j in legs} for t in targets]
        if len(stances) > 1 and options.samples is None:
            key = "floor.check_stances" if options.floor_check else "floor.stances"
            raise WolfcalError(f"{robot.config.path}: '{key}' lists {len(stances)} stances; a manual floor "
                               "capture takes an equal share of --samples in each: give --samples")  # fmt: skip
    elif options.floor:
        script = floor_script(robot, options.velocity or DEFAULT_VELOCITY, options.floor_check)
    elif options.field_views:
        script = field_script(robot, options.velocity or DEFAULT_VELOCITY)
    if options.field_views:
        field_place(robot, options.floor_check)  # refused before anything moves when --check has no place
    return script, limp, stances
