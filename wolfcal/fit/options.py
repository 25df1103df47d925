"""The settings of one fit (`wolfcal fit` options and the rules it applies), saved in result.yaml so that
cross-validation folds and the evaluation fit exactly as the fit did."""

from __future__ import annotations

from dataclasses import dataclass

from wolfcal.errors import WolfcalError
from wolfcal.outliers import FIT_VIEW_PX, OutlierRule
from wolfcal.robot.parameters import check_preset

SYSTEMS = ("head", "external", "mocap", "all")
# Floor of a pixel block's estimated noise [px]: the detector's systematic error. Its corner errors of 0.02-0.05 px
# repeat across poses for each tag corner (they do not average out), and tag mounts absorb part of them, so the
# residuals alone would understate it (measured: docs/accuracy.md, tests/test_other_robot.py).
NOISE_FLOOR_PX = 0.05


@dataclass(frozen=True)
class FitOptions:
    free: str = "camera"
    side: str = "both"
    fix_tags: bool = False
    huber_k: float = 3.0  # robust threshold [standard deviations of the noise model]
    system: str | None = None  # 'head' | 'external' | 'mocap' | 'all'; None: every system the captures contain
    external_moving: bool = False  # one external-camera pose per sample instead of one per capture file
    mocap_moving: bool = False  # one base pose in the motion-capture frame per sample instead of one per source
    outlier: OutlierRule = FIT_VIEW_PX  # which tag views are left out (`wolfcal.outliers`; floor in px)
    noise_floor_px: float = NOISE_FLOOR_PX  # lower bound of a camera block's estimated noise [px per axis]

    def __post_init__(self) -> None:
        check_preset(self.free, self.side)  # before any file is read
        if self.system is not None and self.system not in SYSTEMS:
            raise WolfcalError(f"--system {self.system!r} must be one of {', '.join(SYSTEMS)}")
