"""Whether a model explains what the camera saw: residuals measured against the noise they should have.

A tag's four corners share every model error that moves the whole tag (a joint offset, a camera turn), but not
their detection noise. So the scatter of the corners about their tag's mean residual measures the corner noise
(at least `priors.pixel_noise`), independent of any model error; the joint readings' quantisation adds a known,
pose-dependent shift (sigma_q^2 A A^T, A = d(pixels)/d(readings), the fit's noise model). Residuals whitened with
that noise model have unit RMS when the model explains the data (outlier samples are left out first); an RMS far
above 1 means a structured
error the model's free parameters could not absorb (a camera fitted on a robot whose legs are off).

On a recording's still-span means (`wolfcal.spans`) the corner noise so measured is the means' own; its floor
`priors.pixel_noise` is also the fit's floor for the detection error that repeats at one pose, which a span's mean
keeps whole, so averaging frames does not make the test easier.
"""

from __future__ import annotations

import numpy as np

from wolfcal.fit.camera_block import CameraBlock
from wolfcal.fit.noise import GroupedWhitening, SharedErrors, row_groups
from wolfcal.observations import Observations, rms_by
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot

SCALE_LIMIT = 2.0  # whitened residual scale above which the model does not explain the data
SHIFT_FLOOR_PX = 1.0  # ... and only when the tags are also off by more than this, RMS per axis [px]


def unexplained(
    robot: Robot, obs: Observations, model: Corrections, residuals: np.ndarray, inlier_samples: np.ndarray
) -> dict:
    """Residuals (M, 2) [px] of the inlier samples against the noise model at `model`: corner noise [px], RMS of
    each tag view's mean residual [px], whitened RMS (1: explained) and whether it is unexplained."""
    block = CameraBlock(robot, obs, obs.observed_tag_ids, fixed=model)
    lin = block.linearize(np.zeros(0), np.zeros(0), ParameterSet([]))
    keep = inlier_samples[obs.sample_index] & np.all(np.isfinite(residuals), axis=1)
    view, n_views = block.view_of_unit, block.n_views
    count = np.bincount(view[keep], minlength=n_views).astype(float)
    mean = np.stack([np.bincount(view[keep], residuals[keep, k], n_views) for k in range(2)], axis=1)
    mean = mean / np.maximum(count, 1)[:, None]
    deviation = (residuals - mean[view])[keep]
    dof = 2 * int(np.sum(np.maximum(count - 1, 0)))
    corner = float(np.sqrt(np.sum(deviation**2) / dof)) if dof else 0.0
    sigma = max(corner, robot.config.priors.pixel_noise)
    groups = block.noise_groups()
    shared = SharedErrors(
        A=lin.joint_sensitivity.reshape(-1, lin.joint_sensitivity.shape[-1]),
        sigma_q=robot.config.priors.encoder_noise,
        reading=np.repeat(groups, 2),
        label=np.full(2 * block.n_units, -1),
        axis=np.tile(np.arange(2), block.n_units),
    )
    whitening = GroupedWhitening(row_groups(groups, 2, keep), shared)
    norms = whitening.group_norms(np.nan_to_num(residuals).ravel(), sigma)  # squared Mahalanobis norm per group
    scale = float(np.sqrt(np.sum(norms) / len(whitening.rows))) if len(whitening.rows) else 0.0
    used = count > 0
    shift = float(np.sqrt(np.mean(rms_by(np.arange(n_views), mean, n_views)[used] ** 2))) if used.any() else 0.0
    return {
        "corner_noise_px": sigma,
        "view_shift_rms_px": shift,
        "scale": scale,
        "unexplained": bool(scale > SCALE_LIMIT and shift > SHIFT_FLOOR_PX),
        "meaning": "residuals whitened with the noise they should have (corner noise from the scatter of each "
        "tag's corners about their mean, at least priors.pixel_noise, plus the joint readings' quantisation): "
        f"RMS 1 = explained; above {SCALE_LIMIT:g} with tags off by more than {SHIFT_FLOOR_PX:g} px "
        "(RMS per axis of each tag view's mean residual) = an error the free parameters cannot absorb",
    }
