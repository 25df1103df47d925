"""k-fold cross-validation over a fit's own samples, for when no held-out capture is given.

Sample i goes to fold i mod k (captures are in pose order, so every fold spans the whole pose set). Each fold's
model is fitted with the fit's options on the other folds and made the model it would deploy
(`undetermined.held_model` on the present calibration); each sample is then judged by the model that did not see it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.evaluate.undetermined import held_model
from wolfcal.fit.pipeline import FitOptions, fit_observations
from wolfcal.fit.result import parameter_results
from wolfcal.io.current import CurrentCalibration
from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot


def fold_assignment(n_samples: int, folds: int) -> np.ndarray:
    """(S,) fold index of each sample: i mod k."""
    return np.arange(n_samples) % folds


def cross_validate(
    robot: Robot,
    obs: Observations,
    options: FitOptions,
    folds: int,
    say: Callable[[str], None],
    present: CurrentCalibration | None = None,
) -> tuple[np.ndarray, list[Corrections]]:
    """Fold of each sample and each fold's model to deploy (fitted without that fold's samples; totals on
    `present`, parameters the fold's data cannot determine held at their present values)."""
    if folds < 2:
        raise WolfcalError(f"--folds {folds}: cross-validation needs at least 2 folds")
    if obs.n_samples < 2 * folds:
        folds = max(2, obs.n_samples // 2)
    if obs.n_samples < 4:
        raise WolfcalError(
            f"only {obs.n_samples} sample(s) with tags: too few to cross-validate; give a held-out capture "
            "with --capture"
        )
    fold_of = fold_assignment(obs.n_samples, folds)
    models = []
    for k in range(folds):
        train = np.flatnonzero(fold_of != k)
        say(f"fold {k + 1}/{folds}: fitting on {len(train)} sample(s), holding out {int(np.sum(fold_of == k))}")
        fit = fit_observations(robot, obs.subset(train), options)
        rows = parameter_results(fit)
        models.append(held_model(rows, fit.solution.uncertainty.covariance, present or CurrentCalibration(),
                                 robot)[0])  # fmt: skip
    return fold_of, models
