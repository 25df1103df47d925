"""What a `wolfcal capture` run is asked to do: the command's options, checked before anything opens."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from wolfcal.capture.gating import GateSettings
from wolfcal.capture.poses import find_poses
from wolfcal.errors import WolfcalError
from wolfcal.outputs import check_outputs

EXIT_TORQUE = ("restore", "on", "off")


@dataclass
class CaptureOptions:
    robot: Path
    out: Path
    camera: str | None = None  # head camera source (--camera); None: external cameras only
    port: str | None = None
    poses: Path | None = None
    manual: bool = False
    samples: int | None = None
    limp: str | None = None  # manual mode: joints or groups (head, legs, arms, all) to switch torque off
    #   (None: head,legs; with `floor`: head)
    yes: bool = False  # manual mode: switch torque off without asking
    exit_torque: str = "restore"  # restore (as found) | on (hold the last pose) | off
    binning: int | None = None  # default: a sim camera's (`sim.scene.sim_binning`), else 1
    intrinsics: Path | None = None
    velocity: float | None = None  # overrides the poses file [rad/s]
    pose_timeout_s: float = 5.0  # scripted: give up a pose that gives no sample within this time after arrival
    image_format: str = "png"
    gates: GateSettings = field(default_factory=GateSettings)
    external: list[str] = field(default_factory=list)  # --external NAME=SOURCE, one per external camera
    force: bool = False  # replace an existing capture file at --out
    floor: bool = False  # floor samples: legs standing, the head looks at the floor tags (`wolfcal.capture.floor`)
    # --check: the held-out capture that checks a fit: floor views in `floor.check_stances`, or field views with the
    # robot at `field.check_at`
    floor_check: bool = False
    standing: bool = False  # standing samples: joint states and the IMU in stances (`wolfcal.capture.standing`)
    field_views: bool = False  # --field: standing at field.robot_at, the head sweeps the field (`capture.field`)

    def __post_init__(self) -> None:
        if self.poses is not None:
            self.poses = find_poses(self.poses, self.robot)  # a bare name: the robot's own (`poses.yaml`)


def parse_external(text: str) -> tuple[str, str]:
    """(camera name, source) of an `--external NAME=SOURCE` value."""
    name, _, source = text.partition("=")
    if not name.strip() or not source.strip():
        raise WolfcalError(
            f"--external {text!r}: give NAME=SOURCE, e.g. tripod=/dev/video2 (NAME as under 'external_cameras:' "
            "in the robot config; SOURCE a device index or path, video file, image folder or 'sim')"
        )
    return name.strip(), source.strip()


def check_options(options: CaptureOptions) -> None:
    """Refuse contradictory or out-of-range options and an output file that exists (WolfcalError)."""
    if options.standing:
        given = [name for name, on in (("--floor", options.floor), ("--manual", options.manual),
                 ("--poses", options.poses is not None), ("--camera", options.camera is not None),
                 ("--external", bool(options.external)), ("--check", options.floor_check),
                 ("--field", options.field_views)) if on]  # fmt: skip
        if given:
            raise WolfcalError(f"--standing records joint states and the IMU in the config's standing stances, no "
                               f"camera: drop {', '.join(given)}")  # fmt: skip
    elif options.field_views:
        if options.floor:
            raise WolfcalError("give one of --field (views of the field's lines) and --floor (views of floor tags)")
        if options.poses is not None:
            raise WolfcalError("--field moves the head through its own sweep (field.sweep in the robot config): drop "
                               "--poses (or give --manual to turn the head by hand)")  # fmt: skip
        if options.camera is None or options.external:
            raise WolfcalError("--field records the head camera's views of the field: give --camera SOURCE and no "
                               "--external")  # fmt: skip
    elif options.floor:
        if options.poses is not None:
            raise WolfcalError("--floor moves the head through its own grid of floor views: drop --poses (or give "
                               "--manual to turn the head by hand)")  # fmt: skip
        if options.camera is None:
            raise WolfcalError("--floor records the head camera's views of the floor tags: give --camera SOURCE")
    elif options.floor_check:
        raise WolfcalError("--check is a held-out capture that checks a fit: give it with --floor or --field")
    elif options.manual == (options.poses is not None):
        raise WolfcalError(
            "give exactly one of --poses POSES.yaml (scripted), --manual, --floor, --field or --standing"
        )
    if options.camera is None and not options.external and not options.standing:
        raise WolfcalError("give at least one camera: --camera SOURCE (head camera) and/or --external NAME=SOURCE")
    names = [parse_external(text)[0] for text in options.external]
    if len(set(names)) != len(names):
        raise WolfcalError(f"--external names a camera twice ({', '.join(names)}); give each camera once")
    if options.out.suffix != ".mcap":
        raise WolfcalError(f"{options.out}: the capture file name must end in .mcap")
    inputs = [p for p in (options.poses, options.intrinsics) if p is not None]
    check_outputs([options.out], options.force, inputs)
    if options.samples is not None and options.samples < 1:
        raise WolfcalError("--samples must be at least 1")
    if options.exit_torque not in EXIT_TORQUE:
        raise WolfcalError(f"--exit-torque {options.exit_torque!r}: use one of {', '.join(EXIT_TORQUE)}")
