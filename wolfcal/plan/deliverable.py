"""What a calibration delivers, as a linear function of its free chain parameters: the I-optimal criterion's target.

A calibration is used through the poses it predicts, not through its parameters: for a camera preset (`camera`,
`head_camera`) the head camera's pose in the base frame over the head's range, for `leg` the soles' poses in the
base frame over the legs' range. Each pose error is a rotation (rad, the spatial rotation vector) and a position (m),
scaled by ROTATION_TOLERANCE and POSITION_TOLERANCE so that both count alike. D_z (m, c) stacks the derivatives of
these 6 scaled numbers per evaluation configuration w.r.t. the chain unknowns z (prior-normalised, as the plan
works in), from `robot.derivatives.ChainDerivatives` at the nominal kinematics. The I-criterion is the average
predicted variance trace(D_z C_cc D_z^T) / m (C: the plan's posterior covariance in z, nuisance unknowns
marginalised); `basis` factors D_z^T D_z / m = B B^T, so that it is the A-criterion on B (`plan.select`).
"""

from __future__ import annotations

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.derivatives import ChainDerivatives, cross
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.ranges import range_grid, sampling_bounds
from wolfcal.robot.robot import Robot

ROTATION_TOLERANCE = 1e-3  # [rad] rotation error that counts as much as POSITION_TOLERANCE
POSITION_TOLERANCE = 1e-3  # [m]
CAMERA_GRID = 5  # evaluation configurations per joint between base and camera
LEG_CONFIGURATIONS = 32  # random evaluation configurations for the soles (fixed seed)


def delivered_frames(robot: Robot, preset: str) -> list[str]:
    """The frames whose base-frame pose a preset delivers: the head camera's, or the soles (`floor.soles`, else the
    links of the tags on a leg)."""
    if preset in ("camera", "head_camera"):
        if robot.config.camera is None:
            raise WolfcalError(f"--criterion I with --free {preset}: {robot.config.path} has no head camera, whose "
                               "pose the preset delivers; use --criterion D")  # fmt: skip
        return [robot.config.head_camera().frame]
    if robot.config.floor is not None:
        return list(robot.config.floor.soles)
    return list(dict.fromkeys(t.link for t in robot.config.tags if t.side is not None))


def evaluation_configurations(robot: Robot, preset: str) -> np.ndarray:
    """(E, J) readings [rad] at which the delivered poses count: a grid over the head's range (camera presets) or
    LEG_CONFIGURATIONS draws within the calibration ranges (`sampling_bounds`, system head; seed 0)."""
    if preset in ("camera", "head_camera"):
        return range_grid(robot, delivered_frames(robot, preset)[0], CAMERA_GRID)
    lo, hi = sampling_bounds(robot, "head")
    return np.random.default_rng(0).uniform(lo, hi, size=(LEG_CONFIGURATIONS, len(lo)))


def delivered_jacobian(robot: Robot, chain: ParameterSet, preset: str) -> np.ndarray:
    """(m, c) derivative of the scaled pose errors (rotation / ROTATION_TOLERANCE, position / POSITION_TOLERANCE,
    base frame; 6 rows per evaluation configuration and delivered frame) w.r.t. the chain parameters [SI], at the
    nominal kinematics; frames that no free parameter moves are left out."""
    q = evaluation_configurations(robot, preset)
    frames, base = delivered_frames(robot, preset), robot.config.base_link
    derivatives = ChainDerivatives(robot, q, Corrections(), chain, frames + [base], [])
    R_root_base = derivatives.T_root[base][:, :3, :3]  # (E, 3, 3)
    rows = []
    for frame in frames:
        twist = derivatives.twist_p(frame) - derivatives.twist_p(base)  # (E, c, 6): motion relative to the base
        p_root = derivatives.T_root[frame][:, :3, 3]
        dp = twist[:, :, :3] + cross(twist[:, :, 3:], p_root[:, None, :])  # (E, c, 3) [root frame]
        dp_base = np.einsum("eji,ecj->eic", R_root_base, dp)  # (E, 3, c)
        w_base = np.einsum("eji,ecj->eic", R_root_base, twist[:, :, 3:])
        block = np.concatenate([w_base / ROTATION_TOLERANCE, dp_base / POSITION_TOLERANCE], axis=1)
        if np.any(block != 0.0):
            rows.append(block.reshape(-1, len(chain)))
    if not rows:
        raise WolfcalError(f"--criterion I with --free {preset}: no free parameter moves {', '.join(frames)} (what "
                           "the preset delivers) relative to the base; use --criterion D")  # fmt: skip
    return np.concatenate(rows)


def deliverable_basis(robot: Robot, chain: ParameterSet, preset: str) -> np.ndarray:
    """(c, k) B with B B^T = D_z^T D_z / m (D_z: `delivered_jacobian` in z units), so that trace(B^T C_cc B) is the
    average predicted variance of the scaled delivered pose errors."""
    D_z = delivered_jacobian(robot, chain, preset) * chain.prior_sigmas
    lam, U = np.linalg.eigh(D_z.T @ D_z / len(D_z))
    keep = lam > 1e-12 * lam.max()
    return U[:, keep] * np.sqrt(lam[keep])


def delivered_std(robot: Robot, chain: ParameterSet, preset: str, covariance: np.ndarray) -> tuple[float, float]:
    """Predicted rms length of the delivered rotation error [rad] and position error [m] (root of the mean over
    the evaluation configurations and delivered frames of the trace of their 3x3 covariance), from the chain
    parameters' covariance (c, c) [SI]."""
    J = delivered_jacobian(robot, chain, preset).reshape(-1, 2, 3, len(chain))
    variance = np.einsum("nkic,cd,nkid->k", J, covariance, J) / len(J)
    return (float(np.sqrt(variance[0])) * ROTATION_TOLERANCE, float(np.sqrt(variance[1])) * POSITION_TOLERANCE)
