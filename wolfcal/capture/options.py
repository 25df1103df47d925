"""What a `wolfcal capture` run is asked to do: the command's options, checked before anything opens."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from wolfcal.capture.gating import GateSettings
from wolfcal.errors import WolfcalError
from wolfcal.outputs import check_outputs

EXIT_TORQUE = ("restore", "on", "off")


@dataclass
class CaptureOptions:
    robot: Path
    out: Path
    camera: str
    port: str | None = None
    poses: Path | None = None
    manual: bool = False
    samples: int | None = None
    limp: str = "head,legs"  # manual mode: joints or groups (head, legs, arms, all) to switch torque off
    yes: bool = False  # manual mode: switch torque off without asking
    exit_torque: str = "restore"  # restore (as found) | on (hold the last pose) | off
    binning: int | None = None  # default 4 for the sim camera (fast rendering), else 1
    intrinsics: Path | None = None
    velocity: float | None = None  # overrides the poses file [rad/s]
    pose_timeout_s: float = 5.0  # scripted: give up a pose that gives no sample within this time after arrival
    image_format: str = "png"
    gates: GateSettings = field(default_factory=GateSettings)
    force: bool = False  # replace an existing capture file at --out


def check_options(options: CaptureOptions) -> None:
    """Refuse contradictory or out-of-range options and an output file that exists (WolfcalError)."""
    if options.manual == (options.poses is not None):
        raise WolfcalError("give exactly one of --poses POSES.yaml (scripted) or --manual")
    if options.out.suffix != ".mcap":
        raise WolfcalError(f"{options.out}: the capture file name must end in .mcap")
    inputs = [p for p in (options.poses, options.intrinsics) if p is not None]
    check_outputs([options.out], options.force, inputs)
    if options.samples is not None and options.samples < 1:
        raise WolfcalError("--samples must be at least 1")
    if options.exit_torque not in EXIT_TORQUE:
        raise WolfcalError(f"--exit-torque {options.exit_torque!r}: use one of {', '.join(EXIT_TORQUE)}")
