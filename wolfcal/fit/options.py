"""The settings of one fit (`wolfcal fit` options and the rules it applies), saved in result.yaml so that
cross-validation folds and the evaluation fit exactly as the fit did."""

from __future__ import annotations

from dataclasses import dataclass

from wolfcal.errors import WolfcalError
from wolfcal.fit.systems import selectable_systems, system_presets
from wolfcal.outliers import FIT_VIEW_PX, OutlierRule
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import check_preset
from wolfcal.robot.presets import DEFAULT_PRESET, PRESETS

# Floor of a pixel block's estimated noise [px]: the detector's systematic error. Its corner errors of 0.02-0.05 px
# repeat across poses for each tag corner (they do not average out), and tag mounts absorb part of them, so the
# residuals alone would understate it (measured: docs/accuracy.md, tests/robot/test_other_robot.py).
NOISE_FLOOR_PX = 0.05


@dataclass(frozen=True)
class FitOptions:
    free: str = DEFAULT_PRESET
    side: str = "both"
    fix_tags: bool = False
    huber_k: float = 3.0  # robust threshold [standard deviations of the noise model]
    system: str | None = None  # a registered system (`wolfcal.fit.systems`) or 'all'; None: every one the data hold
    external_moving: bool = False  # one external-camera pose per sample instead of one per capture file
    mocap_moving: bool = False  # one base pose in the motion-capture frame per sample instead of one per source
    outlier: OutlierRule = FIT_VIEW_PX  # which tag views are left out (`wolfcal.outliers`; floor in px)
    noise_floor_px: float = NOISE_FLOOR_PX  # lower bound of a camera block's estimated noise [px per axis]
    # the robot's present calibration (`--current`): the free parameters start from it and their priors centre on
    # it; what it holds beyond them is held fixed. None: the input URDF's nominal model
    current: Corrections | None = None

    def __post_init__(self) -> None:
        # before any file is read: --free names presets joined by commas, at most one of the robot model's
        # (camera | head_camera | leg), any of the measurement systems' (`System.presets`, e.g. imu)
        known = (*PRESETS, *system_presets())
        for preset in self.presets:
            if preset not in known:
                raise WolfcalError(
                    f"--free {preset!r} is not a preset; use one of {', '.join(known)}, or several "
                    "joined by commas (e.g. leg,imu)"
                )
        chain = [p for p in self.presets if p in PRESETS]
        if len(chain) > 1:
            raise WolfcalError(
                f"--free {self.free}: give at most one of {', '.join(PRESETS)} (leg includes the "
                "camera's and head_camera's parameters)"
            )
        check_preset(self.chain_preset or PRESETS[0], self.side)
        if self.system is not None and self.system not in selectable_systems():
            raise WolfcalError(f"--system {self.system!r} must be one of {', '.join(selectable_systems())}")

    @property
    def presets(self) -> tuple[str, ...]:
        """The --free presets, in the order given."""
        return tuple(p.strip() for p in self.free.split(","))

    @property
    def chain_preset(self) -> str | None:
        """The robot model's preset among them (camera | head_camera | leg), None when only measurement systems'
        presets are given (e.g. --free imu)."""
        return next((p for p in self.presets if p in PRESETS), None)
