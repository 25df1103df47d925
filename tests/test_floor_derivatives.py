"""The floor block's and the sole closure's analytic derivatives against central differences of their residuals, at
a model with leg, head and camera corrections (the other-tags robot, floor tags 0.12-0.2 m)."""

import numpy as np
import pytest
from conftest import OTHER_CAMERA, robot_with_floor_tags

from wolfcal.fit.floor_block import FloorBlock, SoleClosure
from wolfcal.robot.parameters import build_parameter_set
from wolfcal.sim.floor import simulate_floor
from wolfcal.sim.simulate import offset_joints
from wolfcal.sim.truth import TruthSpec, random_truth

CAMERA = OTHER_CAMERA
STEP = 1e-6


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    robot = robot_with_floor_tags(tmp_path_factory.mktemp("floor"))
    rng = np.random.default_rng(5)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, "all")), rng)
    floor = simulate_floor(robot, CAMERA, truth, 6, rng)
    chain = build_parameter_set(robot, "leg", {"head": [7, 8]}, "both")
    values = rng.normal(0.0, 0.02, len(chain))  # away from zero: offsets, camera frame, tag mounts
    return robot, floor.obs, chain, values


def central(f, x: np.ndarray) -> np.ndarray:
    """(..., N) central differences of f at x (N,)."""
    cols = []
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = STEP
        cols.append((f(x + e) - f(x - e)) / (2 * STEP))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("kind", [FloorBlock, SoleClosure])
def test_analytic_derivatives_match_central_differences(setup, kind):
    robot, obs, chain, values = setup
    block = kind(robot, obs)
    local = block.nuisance.references + 0.01 * np.arange(len(block.nuisance))
    lin = block.linearize(values, local, chain)
    scale = np.abs(lin.jac_chain).max()
    d_chain = central(lambda v: block.linearize(v, local, chain).residual, values)
    assert np.abs(lin.jac_chain - d_chain).max() < 1e-5 * scale
    q0 = block.q_measured.copy()

    def at_q(dq: np.ndarray) -> np.ndarray:
        block.q_measured = q0 + dq
        try:
            return block.linearize(values, local, chain).residual
        finally:
            block.q_measured = q0

    # one common change of all samples' readings, column by column: each unit sees its own sample's change
    d_q = central(lambda dq: at_q(np.broadcast_to(dq, q0.shape)), np.zeros(q0.shape[1]))
    assert np.abs(lin.joint_sensitivity - d_q).max() < 1e-5 * np.abs(lin.joint_sensitivity).max()
    if kind is FloorBlock:
        full = central(lambda x: block.linearize(values, x, chain).residual, local)  # (U, 2, L)
        mine = np.take_along_axis(full, np.broadcast_to(lin.local_cols[:, None, :], lin.jac_local.shape), axis=2)
        assert np.abs(lin.jac_local - mine).max() < 1e-5 * np.abs(lin.jac_local).max()
