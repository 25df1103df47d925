"""What a `wolfcal venue` session is asked to do: the command's options, checked before anything opens."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from wolfcal.capture.gating import GateSettings
from wolfcal.capture.options import EXIT_TORQUE
from wolfcal.errors import WolfcalError

# Moves of a session: the speed and acceleration every servo's profile is limited to. A robot on its stand or
# standing still moves its legs and head at this pace without swinging; lower them for a frail robot.
SAFE_VELOCITY = 1.5  # [rad/s]
SAFE_ACCELERATION = 6.0  # [rad/s^2]
FEET_POSES = 8  # planned feet views: the fewest that pin the camera and the tag mounts (`wolfcal plan` table)


@dataclass
class VenueOptions:
    robot: Path
    out: Path  # the session folder (new, or with `resume` the interrupted session's)
    camera: str  # head camera source, as `wolfcal capture --camera`
    port: str | None = None
    current: Path | None = None  # the robot's present calibration (recorded; the deploy files are on the URDF)
    yes: bool = False  # switch torque on and go through the phases without asking
    resume: bool = False
    velocity: float = SAFE_VELOCITY
    acceleration: float = SAFE_ACCELERATION
    feet_poses: int = FEET_POSES
    binning: int | None = None  # default as `wolfcal capture`: 4 for the sim camera, else 1
    intrinsics: Path | None = None
    exit_torque: str = "restore"
    field_views: bool = False  # field views (the robot standing at field.robot_at) instead of floor views
    gates: GateSettings = field(default_factory=GateSettings)


def check_options(options: VenueOptions) -> None:
    """Refuse out-of-range options and a --current file that is missing (WolfcalError)."""
    if not 0 < options.velocity <= 6:
        raise WolfcalError(f"--velocity {options.velocity}: give a speed in rad/s in (0, 6]")
    if not 0 < options.acceleration <= 50:
        raise WolfcalError(f"--acceleration {options.acceleration}: give an acceleration in rad/s^2 in (0, 50]")
    if options.feet_poses < 4:
        raise WolfcalError(f"--feet-poses {options.feet_poses}: the camera needs at least 4 feet views")
    if options.exit_torque not in EXIT_TORQUE:
        raise WolfcalError(f"--exit-torque {options.exit_torque!r}: use one of {', '.join(EXIT_TORQUE)}")
    if options.current is not None and not options.current.is_file():
        raise WolfcalError(f"--current {options.current}: file not found; give the robot's present calibration")
