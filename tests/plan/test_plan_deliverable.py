"""`wolfcal plan --criterion I`: the criterion is the average predicted variance of what the calibration delivers,
computed independently here from the fit's covariance on the chosen poses and central differences of the FK."""

import numpy as np
import pytest

from wolfcal.geometry import log_so3
from wolfcal.plan.deliverable import (
    POSITION_TOLERANCE,
    ROTATION_TOLERANCE,
    delivered_frames,
    evaluation_configurations,
)
from wolfcal.plan.information import PlanModel, predicted
from wolfcal.plan.pipeline import PlanOptions, make_plan, used_tags
from wolfcal.robot.parameters import ParameterSet


def _numeric_delivered_jacobian(robot, chain: ParameterSet, preset: str, h: float = 1e-6) -> np.ndarray:
    """(m, c) central differences of the delivered frames' base-frame poses: spatial rotation vector [rad] and
    position [m], scaled by the tolerances, 6 rows per configuration and frame (frames in `delivered_frames` order)."""
    q = evaluation_configurations(robot, preset)
    frames, base = delivered_frames(robot, preset), robot.config.base_link
    columns = []
    for i in range(len(chain)):
        poses = []
        for sign in (1.0, -1.0):
            values = chain.references.copy()
            values[i] += sign * h
            poses.append(robot.model.link_poses(q, frames, chain.corrections(values), base=base))
        col = []
        for frame in frames:
            T_plus, T_minus = poses[0][frame], poses[1][frame]
            w = log_so3(T_plus[:, :3, :3] @ np.swapaxes(T_minus[:, :3, :3], 1, 2)) / (2 * h)
            v = (T_plus[:, :3, 3] - T_minus[:, :3, 3]) / (2 * h)
            col.append(np.concatenate([w / ROTATION_TOLERANCE, v / POSITION_TOLERANCE], axis=1))
        columns.append(np.stack(col, axis=0).reshape(-1))
    return np.stack(columns, axis=1)


@pytest.mark.parametrize("free,system", [("head_camera", "head"), ("leg", "external")])
def test_criterion_is_the_average_delivered_variance_of_the_fits_covariance(robot, free, system):
    options = PlanOptions(free=free, system=system, poses=6, candidates=80, seed=4, criterion="I")
    plan = make_plan(robot, options, say=lambda _m: None)
    from wolfcal.plan.candidates import plan_camera

    camera = plan_camera(robot, system)
    chosen = np.array([np.flatnonzero((plan.candidates.q == q).all(axis=1))[0] for q in plan.q])
    visible = plan.candidates.visible[chosen]
    tags = [t for t in used_tags(robot, options, camera.external)
            if plan.candidates.visible[:, robot.config.tag_ids.index(t)].any()]  # fmt: skip
    problem = PlanModel(robot, camera, free, "both", tags).problem(plan.q, visible)  # the fit's, full noise model
    assert problem.params.names == plan.params.names
    c = problem.n_chain
    covariance = predicted(problem).covariance[:c, :c]  # [SI], nuisance unknowns marginalised
    chain = ParameterSet(problem.params.parameters[:c])
    D = _numeric_delivered_jacobian(robot, chain, free)
    moved = np.abs(D).reshape(-1, 6, c).max(axis=(1, 2)) > 0  # (frames * configurations) a free parameter moves
    D = D.reshape(-1, 6, c)[moved].reshape(-1, c)
    direct = np.trace(D @ covariance @ D.T) / len(D)
    assert plan.criterion_value == pytest.approx(direct, rel=1e-4)
    assert plan.delivered is not None
    (rot_planned, pos_planned), (rot_random, pos_random) = plan.delivered
    assert (rot_planned / ROTATION_TOLERANCE) ** 2 + (pos_planned / POSITION_TOLERANCE) ** 2 == pytest.approx(
        6 * direct, rel=1e-4
    )  # each the rms length of a 3-vector: together the 6 rows' variances, 6 x the mean
    assert rot_planned < rot_random and pos_planned < pos_random
