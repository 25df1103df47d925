"""The `wolfcal` command line: parse arguments, call one pipeline, print. No logic lives here."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from pathlib import Path

import typer

import wolfcal.opencv_quiet  # noqa: F401  (OpenCV's own log lines off, set before OpenCV loads)
from wolfcal import __version__
from wolfcal.blas_threads import one_blas_thread
from wolfcal.config import default_robot
from wolfcal.errors import DeployRefused, WolfcalError
from wolfcal.fit.systems import selectable_systems, system_presets  # the registry: plain data
from wolfcal.robot.presets import DEFAULT_PRESET

one_blas_thread()  # the command line process: see wolfcal.blas_threads

app = typer.Typer(
    help="Kinematic calibration of humanoid robots: camera intrinsics, pose capture, fitting, evaluation.\n\n"
    "Exit codes: 0 done, 1 refused to deploy, 2 bad usage or input, 3 servo bus failed, 4 camera failed, "
    "130 interrupted.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts are plain: units like "[m]" must not be read as rich markup
)


def show_version(value: bool) -> None:
    if value:
        typer.echo(f"wolfcal {__version__}")
        raise typer.Exit()


@app.callback()
def main_options(
    version: bool = typer.Option(
        False, "--version", callback=show_version, is_eager=True, help="Print wolfcal's version and exit."
    ),
) -> None:
    """Options before the command: --version."""


def friendly_errors(command: Callable) -> Callable:
    """Turn WolfcalError into a one-line message on stderr and its exit code (`wolfcal.errors`: 2 bad input, 1 a
    refusal to deploy); Ctrl-C into exit 130, SIGTERM / SIGHUP during a capture into 143 / 129 (128 + the signal
    number)."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except WolfcalError as exc:
            label = "not deployed" if isinstance(exc, DeployRefused) else "error"
            typer.secho(f"{label}: {exc}", fg=typer.colors.RED, err=True)
            raise typer.Exit(exc.exit_code) from None
        except KeyboardInterrupt as exc:
            signum = getattr(exc, "signum", None)  # wolfcal.capture.signals.Stopped
            typer.secho(str(exc) if signum else "interrupted", err=True)
            raise typer.Exit(128 + signum if signum else 130) from None

    return wrapper


ROBOT_HELP = "Robot config (robot.yaml or its folder); default: configs/wolfgang here, else the packaged Wolfgang."
FORCE_HELP = "Replace outputs that exist (never an input)."


def robot_option() -> Path | None:
    return typer.Option(None, "--robot", help=ROBOT_HELP, show_default=False)


def force_option() -> bool:
    return typer.Option(False, "--force", help=FORCE_HELP)


CURRENT_HELP = (
    "The robot's present calibration: a bitbots_extrinsic_calibration YAML, a hardware interface file "
    "with joint_offset values, or a folder of files wolfcal deployed before. Repeatable."
)


def current_option() -> list[Path]:
    return typer.Option([], "--current", help=CURRENT_HELP)


@app.command()
@friendly_errors
def intrinsics(
    inputs: list[str] = typer.Argument(None, help="Image files, globs, folders or video files."),
    board: str = typer.Option(..., "--board", help="Inner corners COLSxROWS (OpenCV sample: 9x6)."),
    square: float = typer.Option(..., "--square", help="Square edge [m]."),
    out: Path = typer.Option(..., "--out", help="camera_info YAML to write."),
    model: str = typer.Option("plumb_bob", "--model", help="plumb_bob | rational_polynomial | equidistant."),
    charuco: str | None = typer.Option(None, "--charuco", help="ChArUco marker dictionary, e.g. 5X5_100."),
    marker: float | None = typer.Option(None, "--marker", help="ChArUco marker edge [m] (0.75 square)."),
    legacy: bool = typer.Option(False, "--legacy", help="ChArUco layout of OpenCV < 4.6 (older printouts)."),
    camera: str | None = typer.Option(None, "--camera", help="Live camera: index (0) or device path."),
    report: Path | None = typer.Option(None, "--report", help="Report folder (default: OUT_report)."),
    save_frames: Path | None = typer.Option(None, "--save-frames", help="Save views kept from video/camera."),
    min_views: int = typer.Option(10, "--min-views", help="Fewest views to calibrate from."),
    detector: str = typer.Option("classic", "--detector", help="Checkerboard detector: classic | sb."),
    no_reject: bool = typer.Option(False, "--no-reject", help="Keep outlier views."),
    workers: int = typer.Option(2, "--workers", help="Detection threads."),
    name: str = typer.Option("camera", "--name", help="camera_name in the YAML."),
    force: bool = force_option(),
) -> None:
    """Calibrate camera intrinsics from checkerboard or ChArUco views -> camera_info YAML and a report."""
    from wolfcal.intrinsics.pipeline import IntrinsicsOptions, run_intrinsics
    from wolfcal.vision.board import make_board

    options = IntrinsicsOptions(
        model=model, method=detector, min_views=min_views, reject_outliers=not no_reject, workers=workers,
        camera_name=name, report=report, save_frames=save_frames, live_view=True, force=force,
    )  # fmt: skip
    target = make_board(board, square, charuco, marker, legacy)
    run_intrinsics(inputs or [], target, out, options, camera, say=typer.echo)


@app.command()
@friendly_errors
def capture(
    robot: Path | None = robot_option(),
    port: str | None = typer.Option(
        None,
        "--port",
        help="Servo bus device (default: the config's servos.port); for several buses (servos.ports) "
        "DEVICE=PATH,... for each, as `wolfcal emulate` prints.",
    ),
    camera: str | None = typer.Option(
        None,
        "--camera",
        help="Head camera: V4L index or /dev/video path, video file, "
        "image folder, or 'sim' (renders the robot served by `wolfcal emulate`).",
    ),
    external: list[str] = typer.Option(
        [],
        "--external",
        help="External camera NAME=SOURCE (NAME from the config's "
        "external_cameras, SOURCE as for --camera), e.g. tripod=/dev/video2. "
        "Repeatable; beside or instead of --camera.",
    ),
    poses: Path | None = typer.Option(
        None,
        "--poses",
        help="Scripted mode: poses YAML (torque on); a bare name "
        "not found here is taken from the robot config's folder (poses.yaml).",
    ),
    manual: bool = typer.Option(False, "--manual", help="Manual mode: torque off, you pose the robot."),
    samples: int | None = typer.Option(None, "--samples", help="Stop after N samples (--standing: N stances)."),
    out: Path = typer.Option(..., "--out", help="Capture file to write (.mcap)."),
    limp: str | None = typer.Option(
        None,
        "--limp",
        help="Manual mode: groups (head, legs, arms, all) or "
        "joints to switch torque off (default: head,legs; with --floor: head).",
    ),
    yes: bool = typer.Option(False, "--yes", help="Switch torque off (manual mode) or on (--standing) without asking."),
    exit_torque: str = typer.Option("restore", "--exit-torque", help="Torque at the end: restore | on | off."),
    velocity: float | None = typer.Option(None, "--velocity", help="Scripted mode: move speed (rad/s)."),
    binning: int | None = typer.Option(
        None, "--binning", help="Sensor binning of every camera's images (sim default: 4 head, 2 external)."
    ),
    intrinsics: Path | None = typer.Option(
        None,
        "--intrinsics",
        help="Head camera's camera_info YAML (default: the config's; external cameras use their config 'intrinsics').",
    ),
    settle: float = typer.Option(0.3, "--settle", help="Seconds every joint must be still (within a tick)."),
    min_sharpness: float = typer.Option(100.0, "--min-sharpness", help="Minimum variance of the Laplacian."),
    floor: bool = typer.Option(
        False,
        "--floor",
        help="Floor samples: the robot stands (legs held at the config's "
        "floor.standing, torque on) and the head looks at the floor tags, aimed through a "
        "pan/tilt grid, or turned by hand with --manual.",
    ),
    check: bool = typer.Option(
        False,
        "--check",
        help="With --floor: the held-out floor capture that checks a fit "
        "(`evaluate --capture`): the legs go through floor.check_stances, stances the fit's "
        "capture did not use, one head view each. Take it three times, the floor tags "
        "moved between.",
    ),
    standing: bool = typer.Option(
        False,
        "--standing",
        help="Standing samples for the IMU's mount: the legs (torque on) go through the config's "
        "standing stances (imu.stances, or stances made from the floor stance that turn and tilt the torso), "
        "each held still; joint states and the IMU (imu.bus) are recorded. No camera.",
    ),
    field: bool = typer.Option(
        False,
        "--field",
        help="Field views: the robot stands at the config's field.robot_at (legs held at floor.standing, torque on) "
        "and the head sweeps the field.sweep pan/tilt grid over the field's lines, or is turned by hand with --manual.",
    ),
    force: bool = force_option(),
) -> None:
    """Capture still poses (joint angles + an image and camera info per camera) into an MCAP file, or standing
    samples (joint states and the IMU) with --standing."""
    from wolfcal.capture.gating import GateSettings
    from wolfcal.capture.pipeline import CaptureOptions, run_capture

    options = CaptureOptions(
        robot=default_robot(robot),
        out=out,
        camera=camera,
        port=port,
        poses=poses,
        manual=manual,
        samples=samples,
        limp=limp,
        yes=yes,
        exit_torque=exit_torque,
        binning=binning,
        intrinsics=intrinsics,
        velocity=velocity,
        gates=GateSettings(settle_s=settle, min_sharpness=min_sharpness),
        external=external,
        force=force,
        floor=floor,
        floor_check=check,
        standing=standing,
        field_views=field,
    )
    ask = (lambda question: typer.confirm(question, default=False)) if sys.stdin.isatty() else None
    run_capture(options, ask=ask)


@app.command()
@friendly_errors
def venue(
    robot: Path | None = robot_option(),
    port: str | None = typer.Option(None, "--port", help="Servo bus device (default: the config's servos.port)."),
    camera: str = typer.Option(
        ...,
        "--camera",
        help="Head camera: V4L index or /dev/video path, video file, image "
        "folder, or 'sim' (renders the robot served by `wolfcal emulate`).",
    ),
    out: Path | None = typer.Option(
        None, "--out", help="Session folder to create: captures, fit, report, deploy files."
    ),
    resume: Path | None = typer.Option(None, "--resume", help="Continue the interrupted session in this folder."),
    current: Path | None = typer.Option(
        None, "--current", help="The robot's present calibration (the team's deploy files); recorded in the report."
    ),
    yes: bool = typer.Option(
        False, "--yes", help="Switch torque on (and go on to each place the robot must stand) without asking."
    ),
    velocity: float | None = typer.Option(None, "--velocity", help="Safe speed of every move [rad/s] (default 1.5)."),
    acceleration: float | None = typer.Option(
        None, "--acceleration", help="Safe acceleration of every move [rad/s^2] (default 6)."
    ),
    feet_poses: int | None = typer.Option(
        None, "--feet-poses", help="Planned feet views, planned once per robot config (default 8)."
    ),
    binning: int | None = typer.Option(None, "--binning", help="Sensor binning of the images (sim default: 4)."),
    intrinsics: Path | None = typer.Option(
        None, "--intrinsics", help="Head camera's camera_info YAML (default: the config's)."
    ),
    exit_torque: str = typer.Option("restore", "--exit-torque", help="Torque at the end: restore | on | off."),
    field: bool = typer.Option(
        False,
        "--field",
        help="Field views instead of floor views: the robot stands at the config's field.robot_at and the head "
        "sweeps field.sweep; the fit takes the feet views and the field's lines together. With field.check_at, "
        "then held-out field views there: their measured ground error is the verdict's.",
    ),
) -> None:
    """Recalibrate the head camera in one session: planned feet views, floor or field views, fit, check, deploy
    files."""
    from wolfcal.venue.options import VenueOptions
    from wolfcal.venue.session import run_venue

    folder = out if resume is None else resume
    if folder is None or (out is not None and resume is not None):
        raise WolfcalError("give exactly one of --out DIR (a new session) or --resume DIR (continue one)")
    options = VenueOptions(
        robot=default_robot(robot),
        out=folder,
        camera=camera,
        port=port,
        current=current,
        yes=yes,
        resume=resume is not None,
        binning=binning,
        intrinsics=intrinsics,
        exit_torque=exit_torque,
        field_views=field,
    )
    options.velocity = options.velocity if velocity is None else velocity
    options.acceleration = options.acceleration if acceleration is None else acceleration
    options.feet_poses = options.feet_poses if feet_poses is None else feet_poses
    ask = (lambda question: typer.confirm(question, default=False)) if sys.stdin.isatty() else None
    figures = run_venue(options, say=lambda line: typer.echo(line, err=True), ask=ask)
    if not figures["deploy"]["written"]:
        raise DeployRefused(figures["deploy"]["reason"])


@app.command()
@friendly_errors
def fit(
    captures: list[Path] = typer.Argument(
        ...,
        help="Capture files (.mcap) to fit on; with --system mocap, ROS 2 "
        "recordings of the joint states (and Markers, unless --mocap is given).",
    ),
    robot: Path | None = robot_option(),
    free: str = typer.Option(
        DEFAULT_PRESET,
        "--free",
        help="Free parameters: camera | head_camera | leg, and the "
        f"measurement systems' presets ({' | '.join(system_presets())}), several joined by "
        "commas (leg,imu).",
    ),
    side: str = typer.Option("both", "--side", help="Leg preset: right | left | both."),
    fix_tags: bool = typer.Option(False, "--fix-tags", help="Hold the tag mounts at their configured poses."),
    intrinsics: Path | None = typer.Option(
        None, "--intrinsics", help="camera_info YAML overriding the capture's (head camera only)."
    ),
    out: Path = typer.Option(..., "--out", help="Output folder for result.yaml and calibrated.urdf."),
    system: str | None = typer.Option(
        None,
        "--system",
        help="Measurement systems to use: "
        f"{' | '.join(selectable_systems())} (default: every system the captures "
        "contain).",
    ),
    mocap: list[Path] = typer.Option(
        [],
        "--mocap",
        help="Motion-capture file (.c3d, Motive or Vicon .csv) of the "
        "session of each capture, in the same order. Repeatable.",
    ),
    mocap_offset: list[float] = typer.Option(
        [],
        "--mocap-offset",
        help="Clock offset of each --mocap file [s]: t_recording = t_file + offset (default: estimated).",
    ),
    mocap_moving: bool = typer.Option(
        False,
        "--mocap-moving",
        help="The robot's base moved between samples: one base pose in the motion-capture frame per sample.",
    ),
    external_moving: bool = typer.Option(
        False,
        "--external-moving",
        help="External camera moved between samples: one pose per sample instead of one per capture file.",
    ),
    no_cache: bool = typer.Option(False, "--no-cache", help="Detect tags again; neither read nor write the cache."),
    current: list[Path] = current_option(),
    force: bool = force_option(),
) -> None:
    """Estimate the chosen free parameters from one or more captures."""
    from wolfcal.fit.pipeline import FitOptions, run_fit
    from wolfcal.vision.cache import cache_enabled

    options = FitOptions(
        free=free,
        side=side,
        fix_tags=fix_tags,
        system=system,
        external_moving=external_moving,
        mocap_moving=mocap_moving,
    )
    with cache_enabled(not no_cache):
        run_fit(
            captures,
            default_robot(robot),
            out,
            options,
            intrinsics,
            say=typer.echo,
            force=force,
            mocap=mocap,
            mocap_offsets=mocap_offset,
            current=current,
        )


@app.command()
@friendly_errors
def evaluate(
    fit_dir: Path = typer.Argument(..., help="Folder written by `wolfcal fit` (holds result.yaml)."),
    capture: list[Path] = typer.Option(
        [],
        "--capture",
        help="Held-out capture (.mcap), not used by the fit. "
        "Repeatable. Without it: k-fold cross-validation over the fit's samples.",
    ),
    out: Path = typer.Option(..., "--out", help="Report folder: report.html, report.md, metrics.json, deploy files."),
    folds: int = typer.Option(5, "--folds", help="Folds of the cross-validation (without --capture)."),
    deploy_worse: bool = typer.Option(
        False, "--deploy-worse", help="Write the deploy files even when the verdict refuses them."
    ),
    force: bool = force_option(),
    no_cache: bool = typer.Option(False, "--no-cache", help="Detect tags again; neither read nor write the cache."),
    ground_limit: float | None = typer.Option(
        None,
        "--ground-limit-cm",
        help="Largest measured ground error that "
        "may be deployed [cm] (default: the robot config's "
        "floor.ground_check.limit, 5 cm).",
    ),
    mount_limit: float = typer.Option(
        2.0,
        "--mount-limit-deg",
        help="Warn when the camera correction turns the "
        "camera by more than this [deg] and no floor samples measure the ground "
        "error.",
    ),
    current: list[Path] = typer.Option(
        [],
        "--current",
        help="The robot's present calibration, the 'before' model "
        "(default: the one the fit started from). " + CURRENT_HELP.split(": ", 1)[1],
    ),
) -> None:
    """Held-out error before/after in pixels, millimetres and metres on the field; report and files to deploy."""
    import math

    from wolfcal.evaluate.pipeline import run_evaluate
    from wolfcal.vision.cache import cache_enabled

    if (ground_limit is not None and ground_limit <= 0) or mount_limit <= 0:
        raise WolfcalError("--ground-limit-cm and --mount-limit-deg must be positive")
    with cache_enabled(not no_cache):
        metrics = run_evaluate(
            fit_dir,
            capture,
            out,
            deploy_worse,
            folds,
            say=typer.echo,
            force=force,
            ground_limit_m=None if ground_limit is None else ground_limit / 100.0,
            mount_limit_rad=math.radians(mount_limit),
            current=current,
        )
    if not metrics["deploy"]["written"]:
        raise DeployRefused("the verdict above withholds the deploy files; --deploy-worse writes them anyway")


@app.command()
@friendly_errors
def compare(
    fit_dirs: list[Path] = typer.Argument(..., help="Folders written by `wolfcal fit` (each holds result.yaml)."),
    capture: list[Path] = typer.Option(
        [],
        "--capture",
        help="Held-out capture (.mcap) of the head camera, an "
        "external camera or motion capture, used by none of the fits. Repeatable.",
    ),
    out: Path = typer.Option(..., "--out", help="Report folder: report.html, report.md, metrics.json, figures/."),
    force: bool = force_option(),
    no_cache: bool = typer.Option(False, "--no-cache", help="Detect tags again; neither read nor write the cache."),
) -> None:
    """Calibrations side by side on held-out captures of every measurement system; says which to deploy."""
    from wolfcal.evaluate.compare import run_compare
    from wolfcal.vision.cache import cache_enabled

    with cache_enabled(not no_cache):
        run_compare(fit_dirs, capture, out, say=typer.echo, force=force)


@app.command()
@friendly_errors
def demo(
    out: Path = typer.Option(
        Path("demo-output"), "--out", help="Folder for the simulated captures, the fits and the reports."
    ),
    force: bool = force_option(),
) -> None:
    """The venue workflow on simulated demo captures (feet + floor -> fit -> evaluate with the measured ground
    error), then a camera fit refused on a robot whose legs are off. Runs from any folder."""
    from wolfcal.demo import run_demo

    run_demo(out, say=typer.echo, force=force)


@app.command()
@friendly_errors
def simulate(
    out: Path = typer.Option(..., "--out", help="Capture file to write (.mcap); truth goes beside it."),
    robot: Path | None = robot_option(),
    samples: int = typer.Option(24, "--samples", help="Number of still poses."),
    seed: int = typer.Option(0, "--seed", help="Random seed (same seed, same capture)."),
    offsets: str = typer.Option("none", "--offsets", help="Joints with true encoder offsets: none|head|legs|all."),
    binning: int | None = typer.Option(
        None,
        "--binning",
        help="Sensor binning of every camera's images (default, as capture's sim camera: 4 head, 2 external).",
    ),
    noise: float = typer.Option(2.0, "--noise", help="Image noise standard deviation [gray levels]."),
    outliers: float = typer.Option(0.0, "--outliers", help="Share of outlier samples (motion blur, stale joints)."),
    intrinsics: Path | None = typer.Option(
        None, "--intrinsics", help="Head camera's camera_info YAML (default: the config's)."
    ),
    truth: Path | None = typer.Option(None, "--truth", help="Reuse the truth of an earlier simulation (.truth.yaml)."),
    system: str = typer.Option(
        "head",
        "--system",
        help="Cameras: head | external (a tripod camera of the config) "
        "| all (both in every sample) | mocap (motion capture: FILE.mcap with joint states "
        "and Markers, and FILE.c3d) | imu (a standing recording: joint states and "
        "sensor_msgs/msg/Imu, stances that turn and tilt the torso).",
    ),
    external: str | None = typer.Option(
        None, "--external", help="Which external camera of the config (default: the first)."
    ),
    placement: str | None = typer.Option(
        None,
        "--placement",
        help="External camera pose x,y,z,roll,pitch,yaw "
        "(m, rad; body frame x forward, y left, z up) in base_link; default random "
        "1-2 m in front, looking at the robot.",
    ),
    poses: Path | None = typer.Option(
        None,
        "--poses",
        help="Poses file (e.g. from `wolfcal plan`; a bare name "
        "not found here is taken from the robot config's folder): simulate these "
        "poses instead of --samples random ones.",
    ),
    floor: bool = typer.Option(
        False,
        "--floor",
        help="Floor samples: the robot stands and turns its head to see the "
        "config's floor tags lying 0.5-5 m away (true places in FILE.truth.yaml).",
    ),
    check: bool = typer.Option(
        False,
        "--check",
        help="With --floor: the held-out floor capture that checks a fit, "
        "its samples spread over floor.check_stances (stances the fit's capture did not use); with --system field: "
        "the held-out field views, the robot placed at field.check_at.",
    ),
    force: bool = force_option(),
) -> None:
    """Write a simulated capture with known ground truth (FILE.mcap, FILE.truth.yaml, FILE.truth.urdf)."""
    from wolfcal.camera.camera_info import load_camera_info
    from wolfcal.sim.simulate import SimOptions, simulate_capture

    options = SimOptions(
        samples=samples,
        seed=seed,
        binning=binning,
        noise_sigma=noise,
        outlier_fraction=outliers,
        offsets=offsets,
        truth_file=truth,
        system=system,
        external=external,
        placement=placement,
        poses=poses,
        floor=floor,
        floor_check=check,
    )
    camera = load_camera_info(intrinsics) if intrinsics else None
    simulate_capture(default_robot(robot), out, options, camera, say=typer.echo, force=force)


@app.command()
@friendly_errors
def plan(
    out: Path = typer.Option(..., "--out", help="Poses file to write (the format `capture --poses` reads)."),
    robot: Path | None = robot_option(),
    free: str = typer.Option(DEFAULT_PRESET, "--free", help="Free parameters: camera | head_camera | leg."),
    side: str = typer.Option("both", "--side", help="Leg preset: right | left | both."),
    system: str = typer.Option(
        "head",
        "--system",
        help="Measurement system: head | external | mocap (the "
        "config's markers) | floor (head pan/tilt while standing, the config's floor tags).",
    ),
    poses: int = typer.Option(12, "--poses", help="Number of poses to plan."),
    candidates: int = typer.Option(2000, "--candidates", help="Random valid candidate poses to choose from."),
    criterion: str | None = typer.Option(
        None,
        "--criterion",
        help="I (average variance of the delivered poses: "
        "camera or soles) | D (determinant) | A (trace) | E (worst direction); "
        "default: I for head_camera from the head camera and for leg from an external camera, else D.",
    ),
    velocity: float = typer.Option(0.5, "--velocity", help="Capture move speed [rad/s] (for the order and time)."),
    margin: float = typer.Option(0.1, "--margin", help="Kept from each joint limit [rad]."),
    seed: int = typer.Option(0, "--seed", help="Random seed of the candidates."),
    external: str | None = typer.Option(None, "--external", help="External camera of the config (default: first)."),
    placement: str | None = typer.Option(
        None,
        "--placement",
        help="External camera pose x,y,z,roll,pitch,yaw "
        "(m, rad, as for simulate); default 1.5 m in front, looking at the robot.",
    ),
    force: bool = force_option(),
) -> None:
    """Plan the few calibration poses that tell the most: a poses file and the predicted uncertainty."""
    from wolfcal.plan.pipeline import PlanOptions, run_plan

    options = PlanOptions(free=free, side=side, system=system, poses=poses, candidates=candidates,
                          criterion=criterion, velocity=velocity, margin=margin, seed=seed,
                          external=external, placement=placement)  # fmt: skip
    run_plan(default_robot(robot), out, options, say=typer.echo, force=force)


@app.command()
@friendly_errors
def emulate(
    robot: Path | None = robot_option(),
    truth: Path | None = typer.Option(None, "--truth", help="True corrections YAML (e.g. FILE.truth.yaml)."),
    fault: list[str] = typer.Option(
        [],
        "--fault",
        help="KIND:ID, optionally =VALUE and @SECONDS after start, "
        "KIND: no-answer, crc, hw-error, missing, model, late, stale. Repeatable.",
    ),
    operator: Path | None = typer.Option(
        None, "--operator", help="Poses YAML an emulated operator moves the limp joints through (manual capture)."
    ),
    hold: float = typer.Option(2.0, "--hold", help="Seconds the emulated operator holds each pose."),
) -> None:
    """Emulate the robot's Dynamixel bus (Protocol 2.0) on a pseudo-terminal; prints its path first."""
    from wolfcal.capture.emulate import emulate as run

    run(default_robot(robot), truth, fault, operator, hold, say=lambda text: typer.echo(text, nl=True))


@app.command()
@friendly_errors
def recover(
    file: Path = typer.Argument(..., help="Capture that did not finish, e.g. x.mcap.partial."),  # noqa: B008
    out: Path | None = typer.Option(  # noqa: B008
        None, "--out", help="Where to write the rescued capture (default: FILE.recovered.mcap)."
    ),
    force: bool = force_option(),
) -> None:
    """Rescue every complete sample of a capture whose recording stopped before it finished."""
    from wolfcal.io.recover import recover_capture, recovered_path, rescued_text

    target = out or recovered_path(file)
    count = recover_capture(file, target, force)
    typer.echo(f"rescued {rescued_text(target, count)} from {file} into {target}")


@app.command("board")
@friendly_errors
def board_command(
    board: str = typer.Option(..., "--board", help="Inner corners COLSxROWS (a 9x6 board has 10x7 squares)."),
    square: float = typer.Option(..., "--square", help="Square edge [m]."),
    out: Path = typer.Option(..., "--out", help="Output file; OUT.pdf and OUT.png are written."),
    charuco: str | None = typer.Option(None, "--charuco", help="ChArUco marker dictionary, e.g. 5X5_100."),
    marker: float | None = typer.Option(None, "--marker", help="ChArUco marker edge [m] (0.75 square)."),
    legacy: bool = typer.Option(False, "--legacy", help="ChArUco layout of OpenCV < 4.6."),
    paper: str = typer.Option("a4", "--paper", help="a4 | a3 | letter | fit."),
    dpi: float = typer.Option(300, "--dpi", help="PNG resolution."),
    force: bool = force_option(),
) -> None:
    """Write a printable checkerboard or ChArUco board: PDF and PNG at exact size, with a scale line."""
    from wolfcal.vision.board import make_board
    from wolfcal.vision.printing import board_sheet, write_sheet

    paths = write_sheet(board_sheet(make_board(board, square, charuco, marker, legacy), paper), out, dpi, force)
    typer.echo(f"wrote {' and '.join(map(str, paths))}: print at 100 % and check the scale line")


@app.command()
@friendly_errors
def tags(
    ids: str | None = typer.Option(
        None, "--ids", help="Tag ids, e.g. 42-44,50 (default: the robot config's tags and floor tags)."
    ),
    size: float | None = typer.Option(
        None, "--size", help="Edge of the black square [m] (default: each tag's in the robot config)."
    ),
    out: Path = typer.Option(..., "--out", help="Output file; OUT.pdf and OUT.png are written."),
    family: str | None = typer.Option(
        None, "--family", help="AprilTag family: 16h5 | 25h9 | 36h10 | 36h11 (default: the robot config's, else 36h11)."
    ),
    robot: Path | None = robot_option(),
    paper: str | None = typer.Option(
        None,
        "--paper",
        help="a4 | a3 | letter | fit (one page of the tags' size); "
        "default: a4, or the first of a3, fit that holds the tags.",
    ),
    dpi: float = typer.Option(300, "--dpi", help="PNG resolution."),
    force: bool = force_option(),
) -> None:
    """Write sheets of AprilTags with their ids (a PDF page and a PNG per sheet at exact size, with a scale line);
    as many pages of --paper as the tags need."""
    from wolfcal.vision.printing import write_sheet
    from wolfcal.vision.robot_tags import robot_tag_sheets

    paths = write_sheet(robot_tag_sheets(default_robot(robot), ids, size, family, paper), out, dpi, force)
    typer.echo(f"wrote {' and '.join(map(str, paths))}: print at 100 % and check the scale line")


@app.command()
@friendly_errors
def markers(
    file: Path = typer.Argument(..., help="Motion-capture file: .c3d, or a Motive or Vicon Nexus .csv export."),
    json_out: Path | None = typer.Option(None, "--json", help="Also write the summary as JSON to this file."),
    robot: Path | None = typer.Option(None, "--robot", help="Robot config: which of its markers the file has."),
    force: bool = force_option(),
) -> None:
    """What a motion-capture file holds: format, rate, frames, and per marker its label, visible frames and mean
    position [m]; with --robot, the configured markers found and missing and the extra labels."""
    from wolfcal.mocap_report import run_markers

    for line in run_markers(file, json_out, robot, force):
        typer.echo(line)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
