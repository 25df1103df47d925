"""Standing poses: the rule that both soles lie on one plane, and the config's stances checked against it.

A pose is standing when, under the nominal model, the soles (config `floor.soles`) are at most MAX_SOLE_TILT_RAD
and MAX_SOLE_GAP_M from one plane (the uncalibrated model's soles disagree by a few degrees and a centimetre: that
is data for the fit, not bad input). The floor samples hold one of the config's stances (`floor.stances`, default
`floor.standing`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.robot.kinematics import KinematicModel

SOLE_LEVER_M = 0.1  # a tilt between the soles counts as the displacement it makes at this distance [m]
MAX_SOLE_TILT_RAD = float(np.deg2rad(10.0))  # standing soles further from one plane under the nominal model are
MAX_SOLE_GAP_M = 0.03  # not a standing pose (bad input)
STANDING_RULE = "at most 10 deg and 3 cm from one plane under the nominal model"


def sole_gaps(sole_poses: np.ndarray) -> np.ndarray:
    """(S, 4) how far two sole poses (2, S, 4, 4), in any one frame, are from one plane: heights of the second
    sole's origin above the first's plane and of the first above the second's [m], and the tilt between their z
    axes (x, y in the first sole's frame) times SOLE_LEVER_M [m]."""
    a, b = sole_poses[0], sole_poses[1]
    h_ab = np.einsum("si,si->s", a[:, :3, 2], b[:, :3, 3] - a[:, :3, 3])
    h_ba = np.einsum("si,si->s", b[:, :3, 2], a[:, :3, 3] - b[:, :3, 3])
    z_b_in_a = np.einsum("sji,sj->si", a[:, :3, :3], b[:, :3, 2])
    return np.stack([h_ab, h_ba, SOLE_LEVER_M * z_b_in_a[:, 0], SOLE_LEVER_M * z_b_in_a[:, 1]], axis=1)


def off_plane(gaps: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tilt [rad], gap [m], not standing) per row of `sole_gaps` (S, 4), each (S,)."""
    tilt = np.arcsin(np.clip(np.linalg.norm(gaps[:, 2:], axis=1) / SOLE_LEVER_M, 0.0, 1.0))
    gap = np.abs(gaps[:, :2]).max(axis=1)
    return tilt, gap, (tilt > MAX_SOLE_TILT_RAD) | (gap > MAX_SOLE_GAP_M)


def stance_readings(stances: Sequence[Mapping[str, float]], model: KinematicModel) -> np.ndarray:
    """(K, J) encoder readings [rad] of stances given as joint -> rad maps (`floor.standing`, `floor.stances`), in
    the model's joint columns, other joints 0."""
    q = np.zeros((len(stances), len(model.actuated_joint_names)))
    for i, stance in enumerate(stances):
        for joint, value in stance.items():
            q[i, model.column(joint)] = value
    return q


def check_stances(config: RobotConfig, model: KinematicModel) -> None:
    """Every stance of `floor:` (`floor.standing`, `floor.stances`, `floor.check_stances`) must be standing under
    the nominal model (two soles or more: the first two are compared); a WolfcalError naming the stance
    otherwise."""
    floor = config.floor
    if floor is None or len(floor.soles) < 2:
        return
    named = floor.named_stances()
    q = stance_readings([stance for _, stance in named], model)
    poses = model.link_poses(q, floor.soles[:2], base=config.base_link)
    tilt, gap, bad = off_plane(sole_gaps(np.stack([poses[s] for s in floor.soles[:2]])))
    if bad.any():
        i = int(np.argmax(bad))
        raise WolfcalError(
            f"{config.path}: '{named[i][0]}' is not a standing pose: the soles {floor.soles[0]} and "
            f"{floor.soles[1]} are {np.rad2deg(tilt[i]):.1f} deg and {gap[i] * 100:.1f} cm from one plane under the "
            f"nominal model ({STANDING_RULE}); give readings [rad] that put both soles flat on the floor"
        )
