"""Which free set explains a residual pattern the fitted model leaves: tested on the data, not guessed.

When the fitted model does not explain the evaluated tag views (`structure.unexplained`), each larger preset is
fitted on those same views and judged by the same test: the head joints (`head_camera`: camera + the offsets of the
joints between base and camera) first, then the legs (`leg`). The first whose model explains the views is the
advice; none: the refusal says that neither does.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.evaluate.metrics import TagViews, model_errors
from wolfcal.evaluate.structure import unexplained
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import fit_observations
from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

LARGER = {"camera": ("head_camera", "leg"), "head_camera": ("leg",), "leg": ()}  # preset -> larger sets, in order


def explaining_preset(
    robot: Robot,
    obs: Observations,
    views: TagViews,
    options: FitOptions,
    present: Corrections,
    inlier_samples: np.ndarray,
) -> dict:
    """{'tested': {preset: whitened residual scale, or None when it could not be fitted}, 'explained_by': the first
    preset of LARGER[options.free] whose fit on `obs` explains them, or None}."""
    tested: dict[str, float | None] = {}
    for preset in LARGER.get(options.free, ()):
        try:
            fit = fit_observations(robot, obs, replace(options, free=preset, current=present))
        except WolfcalError:
            tested[preset] = None  # too few views for its parameters
            continue
        model = fit.corrections
        judged = unexplained(robot, obs, model, model_errors(robot, obs, views, model).residuals, inlier_samples)
        tested[preset] = judged["scale"]
        if not judged["unexplained"]:
            return {"tested": tested, "explained_by": preset}
    return {"tested": tested, "explained_by": None}
