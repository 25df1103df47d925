"""`wolfcal venue`: the head camera's recalibration as one session, phase by phase.

Phases: `feet` (the planned feet views, the robot on its stand), then, when the robot config has floor tags,
`floor` (the floor views of `capture --floor`, the robot standing on the floor among the tags) and `check` (the
held-out floor views of `capture --floor --check`); with `--field`, instead of the floor phases, `field` (the field
views of `capture --field`, the robot standing on the field at `field.robot_at`) and, when the config gives
`field.check_at`, `field_check` (the held-out field views of `capture --field --check`, the robot moved there).
Every pose is checked against the URDF limits and the collision model before the bus opens and from where the
robot stands (`capture.poses`, `capture.floor`); nothing else is sent. The session says up front what the robot
must be doing and asks before torque is switched on, and each time the robot must stand somewhere else (on the
floor, on the field, at the field's check place); `--yes` answers them all. Robot time counts from torque on to
the last sample, without the time spent waiting for the operator. Ctrl-C, SIGTERM, a bus or camera failure: every
sample taken so far is kept, the torque is left as chosen, and `--resume DIR` continues where the session stopped.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wolfcal.atomic import write_text_atomic
from wolfcal.capture.cameras import CaptureCamera, close_sources, open_sources, plan_cameras
from wolfcal.capture.exit_torque import leave_torque
from wolfcal.capture.field import field_script, one_sided_note
from wolfcal.capture.floor import check_views, floor_joints, floor_script, without_collisions
from wolfcal.capture.options import CaptureOptions
from wolfcal.capture.poses import PoseScript, check_collisions
from wolfcal.capture.signals import interruption, signals_held, stop_on_signals
from wolfcal.errors import WolfcalError
from wolfcal.hardware.bus import BusError
from wolfcal.hardware.buses import ServoBuses
from wolfcal.io.writer import CaptureWriter
from wolfcal.plan.order import capture_order
from wolfcal.robot.floor import standing_pose
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.venue.check import check_session
from wolfcal.venue.motion import PoseDriver, Taken
from wolfcal.venue.options import VenueOptions, check_options
from wolfcal.venue.plans import feet_plan
from wolfcal.venue.report import report_lines, truth_errors
from wolfcal.venue.state import SessionState, load_session, new_session, next_part, parts, robot_digest

Ask = Callable[[str], bool]
LABELS = {"feet": "feet view", "floor": "floor view", "check": "held-out floor view", "field": "field view",
          "field_check": "held-out field view"}  # fmt: skip
FIELD_PHASES = ("field", "field_check")  # the head camera sees the field's lines, not tags


@dataclass
class Phase:
    name: str
    script: PoseScript
    robot_must: str  # what the robot must be doing, in words
    stand: str = ""  # where the robot must stand for it (standing phases), in words


def _phases(robot: Robot, options: VenueOptions, start: dict[str, float], say: Callable[[str], None],
            plan_note: str, feet: PoseScript) -> list[Phase]:  # fmt: skip
    """The session's phases, their poses checked against collisions from `start` (joint -> rad)."""
    note = check_collisions(robot, feet, plan_note, start)
    if note:
        say(f"note: {note}")
    phases = [Phase("feet", feet, "hangs on its stand, legs free to move (torque on: the legs and the head move)")]
    if options.field_views:
        return [*phases, *field_phases(robot, options, start, say)]
    floor = robot.config.floor
    if floor is None or not floor.tags:
        say(f"note: {robot.config.path} lists no floor tags ('floor.tags'): no floor views, so the ground error is "
            "not measured; the check is the cross-validation over the feet views alone")  # fmt: skip
        return phases
    stand = "on the floor among the floor tags (0.5-5 m in front of it)"
    at = standing_pose(robot)
    for name, check in (("floor", False), ("check", True)):
        script, note = without_collisions(robot, floor_script(robot, options.velocity, check), start)
        script = check_views(robot, script) if check else script
        if note:
            say(f"note: {note}")
        script, at = shortest_order(robot, script, at, start)
        phases.append(Phase(name, script, f"stands {stand}, legs held by torque", stand))
    return phases


def field_phases(robot: Robot, options: VenueOptions, start: dict[str, float],
                 say: Callable[[str], None]) -> list[Phase]:  # fmt: skip
    """The field views (`capture.field`), those the robot cannot take without touching itself left out, in the
    order of the shortest moves from the standing pose; then, when the config gives `field.check_at`, the held-out
    field views: the same sweep with the robot moved there (without it, a note that the ground error from field
    views is not measured)."""
    if robot.config.floor is not None and robot.config.floor.tags:
        say("note: --field: field views instead of the floor views (the floor tags are not looked at)")
    script, note = without_collisions(robot, field_script(robot, options.velocity), start, "--field")
    for line in (note, one_sided_note(robot, script)):
        if line:
            say(f"note: {line}")
    fitted, at = shortest_order(robot, script, standing_pose(robot), start)
    config = robot.config.field_config()
    phases = [Phase("field", fitted, *_standing_at("robot_at", config.robot_at))]
    if config.check_at is None:
        say(f"note: {robot.config.path} gives no 'field.check_at': no held-out field views, so the ground error "
            "from field views is not measured")  # fmt: skip
        return phases
    held_out, _ = shortest_order(robot, script, at, start)
    return [*phases, Phase("field_check", held_out, *_standing_at("check_at", config.check_at))]


def _standing_at(key: str, place: tuple[float, float, float]) -> tuple[str, str]:
    """(what the robot must be doing, where it stands) for field views at `field.<key>` = `place` [m, m, rad]."""
    x, y, yaw = place
    stand = (f"on the field at field.{key} (x {x:+.2f} m, y {y:+.2f} m, facing {np.rad2deg(yaw):+.0f} deg from "
             "the direction of the opponent goal)")  # fmt: skip
    return f"stands {stand}, legs held by torque", stand


def shortest_order(robot: Robot, script: PoseScript, q_from: np.ndarray, start: dict[str, float]
                   ) -> tuple[PoseScript, np.ndarray]:  # fmt: skip
    """The script's poses in the order of the shortest moves from readings `q_from` (J,) [rad] (`plan.order`:
    nearest neighbour, then 2-opt), joints no pose names at `start`; and the readings of its last pose."""
    q = script.readings(robot.joint_names, start)
    order, _ = capture_order(q, q_from, script.velocity)
    return PoseScript([script.poses[k] for k in order], script.velocity), q[order[-1]]


def _confirm(question: str, options: VenueOptions, ask: Ask | None, say: Callable[[str], None]) -> None:
    """Go on only when the operator says so (or --yes); WolfcalError otherwise."""
    if options.yes:
        say(f"{question} yes (--yes)")
        return
    if ask is None:
        raise WolfcalError(f"{question} pass --yes to confirm without a terminal")
    if not ask(question):
        raise WolfcalError("not confirmed: nothing was moved after this point; --resume continues the session")


def _open_bus(robot: Robot, options: VenueOptions) -> ServoBuses:
    """The servo buses (`servos.port` or `servos.ports`, or --port), with every servo answering; a port where
    nothing answers is named as such."""
    servos = robot.config.servos
    if servos is None:
        raise WolfcalError(f"{robot.config.path}: no 'servos' section (port, ids): the session needs the servo bus")
    bus = ServoBuses(servos, options.port).open()
    try:
        try:
            bus.torque_enabled()
        except BusError as exc:
            raise BusError(f"{bus.port_name}: no servo answers on this port ({exc}); check that the robot is "
                           f"powered, that --port names its servo bus (the config says {servos.port}) and the baud "
                           f"rate ({servos.baudrate})") from None  # fmt: skip
        bus.ping_all()
        bus.check_hardware()
    except BaseException:
        bus.close()
        raise
    return bus


def run_venue(options: VenueOptions, say: Callable[[str], None] = print, ask: Ask | None = None) -> dict:
    """The whole session; returns the figures written to DIR/metrics.json. Errors are WolfcalError subclasses."""
    wall_start = time.monotonic()
    check_options(options)
    robot = load_robot(options.robot)
    capture_like = CaptureOptions(robot=options.robot, out=options.out / "x.mcap", camera=options.camera,
                                  binning=options.binning, intrinsics=options.intrinsics)  # fmt: skip
    cameras = plan_cameras(capture_like, robot)
    if options.field_views:
        field_script(robot, options.velocity)  # a config without a field or a sweep outside the limits: refused now
    feet = feet_plan(robot, options.feet_poses, options.velocity, say)
    digest = robot_digest(robot.config.path, robot.config.urdf)
    if options.resume:
        state, notes = load_session(options.out, digest)
        if state.plan_key != feet.key:
            raise WolfcalError(
                f"--resume {options.out}: the session was started with other feet views (another "
                "--velocity or --feet-poses, or another wolfcal); resume it with the same options"
            )
        for line in notes:
            say(line)
        if options.field_views != state.field:
            started = "without" if options.field_views else "with"
            raise WolfcalError(f"--resume {options.out}: the session was started {started} --field; resume it with "
                               "the same options")  # fmt: skip
    else:
        state = SessionState(str(robot.config.path), digest, feet.key, field=options.field_views)
        new_session(options.out, state)
    state.runs += 1
    feet_script = PoseScript(feet.script.poses, options.velocity)
    with stop_on_signals():
        bus = _open_bus(robot, options)
        try:
            _drive_session(robot, options, bus, cameras, state, feet_script, feet.source, say, ask)
        finally:
            bus.close()
    try:
        figures = check_session(
            robot,
            parts(options.out, "feet"),
            parts(options.out, "floor"),
            parts(options.out, "check"),
            parts(options.out, "field"),
            parts(options.out, "field_check"),
            options.out,
            options.current,
            say,
        )
    except WolfcalError as exc:
        raise type(exc)(
            f"{exc}\nthe samples are kept in {options.out}; `wolfcal venue --resume {options.out}` "
            "fits and checks them again"
        ) from None
    figures.update({"robot": str(robot.config.path), "plan": feet.source, "robot_time_s": state.robot_time_s,
                    "wall_time_s": time.monotonic() - wall_start, "runs": state.runs,
                    "samples": {p: len(state.done[p]) for p in state.done}})  # fmt: skip
    figures["truth"] = truth_errors(robot, options, figures)
    lines = report_lines(figures)
    write_text_atomic(options.out / "metrics.json", json.dumps(figures, indent=2, default=str) + "\n")
    write_text_atomic(options.out / "report.md", "\n".join(lines) + "\n")
    for line in lines:
        say(line)
    return figures


def _drive_session(robot: Robot, options: VenueOptions, bus: ServoBuses, cameras: dict[str, CaptureCamera],
                   state: SessionState, feet: PoseScript, plan_source: str, say: Callable[[str], None],
                   ask: Ask | None) -> None:  # fmt: skip
    """Every phase's poses not yet taken, the torque left as chosen on every way out."""
    start = dict(zip(bus.joints, (float(v) for v in bus.read_state().positions)))
    phases = _phases(robot, options, start, say, plan_source, feet)
    todo = [(p, [pose for pose in p.script.poses if pose.name not in state.done[p.name]]) for p in phases]
    todo = [(p, poses) for p, poses in todo if poses]
    if not todo:
        say("every pose of the session was taken already: fitting and checking")
        return
    touched = list(dict.fromkeys(j for p in phases for j in p.script.joints))
    say(f"wolfcal venue: recalibrating the head camera of {robot.config.name} (plan: {plan_source})")
    for k, (phase, poses) in enumerate(todo, start=1):
        say(f"  {k}. {len(poses)} {LABELS[phase.name]}s: the robot {phase.robot_must}")
    initial = bus.torque_enabled()
    _confirm(f"Switch torque on for {len(touched)} joints and start moving?", options, ask, say)
    failure: BaseException | None = None
    writer: CaptureWriter | None = None
    try:
        floor_families = {t.family for t in robot.config.floor.tags} if robot.config.floor is not None else set()
        families = sorted({t.family for t in robot.config.tags} | floor_families)
        driver = PoseDriver(bus, {}, _tag_ids(robot), families, options.gates, options.velocity,
                            options.acceleration, say)  # fmt: skip
        since = time.monotonic()
        goals = driver.torque_on(touched)
        stands: str | None = None  # where the robot was last asked to stand
        for phase, poses in todo:
            if phase.stand and phase.stand != stands:  # the legs stand first, then the robot is put down there
                if stands is None:
                    legs = floor_joints(robot)[0]
                    driver.move_only(goals, {j: q for j, q in poses[0].joints.items() if j in legs})
                stands = phase.stand
                state.robot_time_s += time.monotonic() - since
                state.save(options.out)
                _confirm(f"Stand the robot {phase.stand}; its legs hold the standing pose. Go on?", options, ask,
                         say)  # fmt: skip
                since = time.monotonic()
            if phase.name in FIELD_PHASES or not driver.cameras:  # the simulated camera shows the field or the robot
                close_sources(cameras)
                open_sources(cameras, robot, bus.port_names, field=phase.name in FIELD_PHASES,
                             check=phase.name == "field_check")  # fmt: skip
                driver.cameras = {n: c.source for n, c in cameras.items() if c.source is not None}
            driver.field = phase.name in FIELD_PHASES
            streams = {name: (c.model, (c.binning, c.binning)) for name, c in cameras.items()}
            writer = CaptureWriter(next_part(options.out, phase.name), robot.config, streams)
            driver.writer = writer
            driver.tag_ids = _tag_ids(robot, floor=phase.name != "feet")

            def taken(outcome: Taken, name: str = phase.name, label: str = LABELS[phase.name]) -> None:
                nonlocal since
                now = time.monotonic()
                state.robot_time_s += now - since
                since = now
                if outcome.reason is None:
                    state.done[name].append(outcome.name)
                state.save(options.out)  # before it is said: a sample reported is a sample kept
                if outcome.reason is None:
                    seen = f", tags {', '.join(map(str, outcome.tags))}" if outcome.tags else ""
                    say(f"  sample: {label} {outcome.name}{seen}")
                else:
                    say(f"  {label} {outcome.name} not taken: {outcome.reason}")

            driver.drive(goals, poses, LABELS[phase.name], taken, check_first=phase.name == "feet"
                         and not state.done["feet"])  # fmt: skip
            writer.close()
            writer = None
    except BaseException as exc:  # noqa: BLE001 - the torque first, then it surfaces
        failure = exc
    with signals_held() as noted:  # nothing cuts restoring the torque short
        try:
            if writer is not None:
                writer.close()
            close_sources(cameras)
        finally:
            bus.recover_port()
            failed = leave_torque(bus, initial, touched, options.exit_torque)
            state.save(options.out)
    failure = failure or interruption(noted)
    _say_end(state, options, failure, failed, say)


def _tag_ids(robot: Robot, floor: bool = True) -> set[int]:
    """The tags the head camera looks for in a phase: the robot's own, and (`floor`) the floor tags."""
    floor_ids = set(robot.config.floor.tag_ids) if floor and robot.config.floor is not None else set()
    return {t.id for t in robot.config.tags} | floor_ids


def _say_end(state: SessionState, options: VenueOptions, failure: BaseException | None, failed: list[str],
             say: Callable[[str], None]) -> None:  # fmt: skip
    """How the session's driving ended; raises its failure with what was kept and how to go on."""
    kept = sum(len(v) for v in state.done.values())
    torque = (f"; torque could not be left as chosen (--exit-torque {options.exit_torque}) on {', '.join(failed)}: "
              "check these joints before touching the robot") if failed else ""  # fmt: skip
    if failure is None and not failed:
        say(f"all poses taken: {kept} samples in {options.out}, {state.robot_time_s:.1f} s of robot time")
        return
    resume = f"{kept} sample(s) kept in {options.out}; continue with `wolfcal venue --resume {options.out}`{torque}"
    if isinstance(failure, WolfcalError):
        raise type(failure)(f"{failure}\n{resume}") from None
    say(f"session stopped: {resume}")
    if failure is not None:
        raise failure
    raise BusError(f"{options.out}: the bus failed at the end{torque}")
