"""The model to deploy: what the data determine, and nothing the priors alone chose.

A deployed parameter (an encoder offset or a frame correction) with less than DATA_SHARE_LIMIT of its information
from the data (e.g. the HeadTilt offset in a leg fit, which trades against the camera's pitch) is not deployed at
its fitted value. It is held at its present value (the robot's calibration today, 0 without `--current`), and every
other parameter moves to its best value given that: the conditional mean of the fit's Gaussian posterior,
x_R + C_RU C_UU^-1 (x_U_held - x_U) (the least-squares solution with those parameters fixed, to first order). The
parameters it trades against thus carry what it did, and the model the data determine stays.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wolfcal.fit.result import DATA_SHARE_LIMIT, FitResult, ParameterResult
from wolfcal.io.current import CurrentCalibration
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import COMPONENTS, Parameter, ParameterSet
from wolfcal.robot.robot import Robot

MOVED_NOTE = {"rad": (np.rad2deg(1.0), "deg", 0.01), "m": (1000.0, "mm", 0.01)}  # unit -> (scale, shown, least)


def _chain_parameter(p: ParameterResult, model_joint: Callable[[str], str]) -> Parameter | None:
    """The chain parameter a result row stands for (None: a measurement block's own unknown); `model_joint` maps
    the URDF joint a row names to the robot model's joint it corrects."""
    head, _, component = p.name.rpartition(".")
    if component == "offset" and p.urdf_joint:
        return Parameter(p.name, "offset", p.urdf_joint, 0, p.unit, p.prior_sigma)
    if component in COMPONENTS and p.urdf_joint:
        return Parameter(p.name, "frame", model_joint(p.urdf_joint), COMPONENTS.index(component), p.unit,
                         p.prior_sigma)  # fmt: skip
    if component in COMPONENTS and head.startswith("tag") and head[3:].isdigit():
        return Parameter(p.name, "tag", head[3:], COMPONENTS.index(component), p.unit, p.prior_sigma)
    return None


def deployable_model(result: FitResult, present: CurrentCalibration, robot: Robot) -> tuple[Corrections, list[str]]:
    """The model to deploy (totals: `present` with the fitted parameters replaced) and a sentence per parameter
    held at its present value. A fit without a covariance deploys its values as they are."""
    return held_model(result.parameters, np.asarray(result.covariance.get("matrix") or [], dtype=float), present,
                      robot)  # fmt: skip


def model_joint_of(robot: Robot) -> Callable[[str], str]:
    """URDF joint -> the model joint whose frame correction is written to it: the camera's (`Robot.camera_joint`,
    a joint the robot adds below a body-axes camera link) where it is written to that URDF joint, else itself."""
    camera = robot.camera_joint if robot.config.camera is not None else None
    written_to = robot.model.urdf_joint_of(camera) if camera is not None else None
    return lambda urdf_joint: camera if camera is not None and urdf_joint == written_to else urdf_joint


def held_model(
    rows: list[ParameterResult], covariance: np.ndarray, present: CurrentCalibration, robot: Robot
) -> tuple[Corrections, list[str]]:
    """`deployable_model` of a fit's parameter rows (`fit.result.parameter_results`) and their covariance (P, P)
    [SI units of the parameters]."""
    joint = model_joint_of(robot)
    chain = [(i, c) for i, c in ((i, _chain_parameter(p, joint)) for i, p in enumerate(rows)) if c is not None]
    values = np.array([p.value for p in rows], dtype=float)
    params = ParameterSet([c for _, c in chain])
    index = [i for i, _ in chain]
    held = [i for i, c in chain if c.kind in ("offset", "frame") and rows[i].data_share < DATA_SHARE_LIMIT]
    if not held or covariance.shape != (len(rows), len(rows)):
        return present.corrections.overridden_by(params.corrections(values[index])), []
    present_values = dict(zip(params.names, params.values_from(present.corrections)))
    target = np.array([present_values[rows[i].name] for i in held])
    C = covariance
    shift = C[:, held] @ np.linalg.lstsq(C[np.ix_(held, held)], target - values[held], rcond=None)[0]
    new = values + shift
    new[held] = target
    notes = [_note(rows, i, new[i], values - new, held, index) for i in held]
    return present.corrections.overridden_by(params.corrections(new[index])), notes


def _note(rows: list[ParameterResult], i: int, value: float, change: np.ndarray, held: list[int],
          index: list[int]) -> str:  # fmt: skip
    """What was done with undetermined parameter i, and which deployed parameters carry its share."""
    p = rows[i]
    scale, shown, _ = MOVED_NOTE.get(p.unit, (1.0, p.unit, 0.0))
    moved = [f"{rows[k].name} {-change[k] * MOVED_NOTE[rows[k].unit][0]:+.3f} {MOVED_NOTE[rows[k].unit][1]}"
             for k in index if k not in held and rows[k].unit in MOVED_NOTE
             and abs(change[k]) * MOVED_NOTE[rows[k].unit][0] >= MOVED_NOTE[rows[k].unit][2]]  # fmt: skip
    carried = (f"; the parameters it trades against carry its share: {', '.join(moved)} (change from their fitted "
               "values)") if moved else ""  # fmt: skip
    return (
        f"{p.name}: only {p.data_share:.0%} of its information comes from the data (fitted {p.display}), so it "
        f"is deployed at its present value {value * scale:+.3f} {shown}, not at the fitted one{carried}."
    )
