"""The floor block's and the sole closure's analytic derivatives against central differences of their residuals, at
a model with leg, head and camera corrections (the other-tags robot, floor tags 0.12-0.2 m)."""

import numpy as np
import pytest
from conftest import OTHER_CAMERA, robot_with_floor_tags

from wolfcal.fit.derivative_check import assert_block_derivatives
from wolfcal.fit.floor_block import FloorBlock, SoleClosure
from wolfcal.robot.parameters import build_parameter_set
from wolfcal.sim.floor import simulate_floor
from wolfcal.sim.simulate import offset_joints
from wolfcal.sim.truth import TruthSpec, random_truth

CAMERA = OTHER_CAMERA


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    robot = robot_with_floor_tags(tmp_path_factory.mktemp("floor"))
    rng = np.random.default_rng(5)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, "all")), rng)
    floor = simulate_floor(robot, CAMERA, truth, 6, rng)
    chain = build_parameter_set(robot, "leg", {"head": [7, 8]}, "both")
    values = rng.normal(0.0, 0.02, len(chain))  # away from zero: offsets, camera frame, tag mounts
    return robot, floor.obs, chain, values


@pytest.mark.parametrize("kind", [FloorBlock, SoleClosure])
def test_analytic_derivatives_match_central_differences(setup, kind):
    robot, obs, chain, values = setup
    block = kind(robot, obs)
    local = block.nuisance.references + 0.01 * np.arange(len(block.nuisance))
    assert_block_derivatives(block, chain, values, local)
