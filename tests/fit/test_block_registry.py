"""The registry of measurement systems: every registered part exists, the camera blocks pass the shared derivative
check, and a new system joins the fit, the result file and the console summary through the registry alone.

The new system here is a toy: a protractor that reads one joint's true angle [rad] in each sample. Its block, its
fit builder and its --free preset live in this file; the only thing it changes is the registry's list (patched).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.fit import systems
from wolfcal.fit.blocks import Block, Linearization
from wolfcal.fit.camera_block import CameraBlock, placements
from wolfcal.fit.derivative_check import assert_block_derivatives
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import fit_observations
from wolfcal.fit.result import fit_result, summary_lines
from wolfcal.outliers import OutlierRule
from wolfcal.robot.parameters import ParameterSet, build_parameter_set, offset_parameter
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.sim.scenario import synthetic_external_scenario, synthetic_scenario

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"
JOINT = "RKnee"
TRUE_OFFSET = 0.021  # [rad]
NOISE = 0.002  # the protractor's reading noise [rad]


class ProtractorBlock(Block):
    """One joint's true angle read by a protractor in each sample: residual (q_measured + offset) - angle [rad]."""

    name, system, unit, unit_name, dim = "protractor", "protractor", "rad", "reading", 1
    outlier_rule = OutlierRule(5.0, 0.01)
    noise_min, noise_max, noise_start = 1e-4, 0.5, 0.01

    def __init__(self, robot: Robot, q_measured: np.ndarray, angle: np.ndarray) -> None:
        self.robot, self.q_measured, self.angle = robot, q_measured, angle
        self.column = robot.model.column(JOINT)
        self.sample_of_unit = self.view_of_unit = np.arange(len(angle))
        self.view_labels = [(int(s), 0) for s in range(len(angle))]
        self.nuisance = ParameterSet([])

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        offset = chain.corrections(chain_values).offsets.get(JOINT, 0.0)
        jac_chain = np.zeros((self.n_units, 1, len(chain)))
        for i, p in enumerate(chain.parameters):
            jac_chain[:, 0, i] = float(p.kind == "offset" and p.target == JOINT)
        sensitivity = np.zeros((self.n_units, 1, self.q_measured.shape[1]))
        sensitivity[:, 0, self.column] = 1.0
        residual = (self.q_measured[:, self.column] + offset - self.angle)[:, None]
        return Linearization(residual, jac_chain, None, None, sensitivity)

    @staticmethod
    def summary_lines(entry: dict) -> list[str]:
        return [f"protractor: {entry['n_samples']} readings, RMS {np.rad2deg(entry['rms_after_rad']):.3f} deg after"]


def protractor_parameters(robot: Robot) -> list:
    return [offset_parameter(JOINT, robot.config.priors.offset)]


def protractor_blocks(robot, captures, options, say):
    """The toy's fit builder: readings drawn here instead of read from files (it uses no capture)."""
    rng = np.random.default_rng(3)
    q = rng.uniform(-0.5, 0.5, (40, len(robot.joint_names)))
    angle = q[:, robot.model.column(JOINT)] + TRUE_OFFSET + rng.normal(0.0, NOISE, 40)
    return [ProtractorBlock(robot, q, angle)], []


TOY = systems.System(
    "protractor",
    f"{__name__}:ProtractorBlock",
    reader=None,
    simulator=None,
    planner=None,
    fit_blocks=f"{__name__}:protractor_blocks",
    presets=(("protractor", f"{__name__}:protractor_parameters"),),
)


@pytest.fixture
def toy_registered(monkeypatch):
    monkeypatch.setattr(systems, "SYSTEMS", (*systems.SYSTEMS, TOY))


@pytest.mark.parametrize("entry", systems.SYSTEMS, ids=lambda s: s.name)
def test_every_registered_part_can_be_loaded(entry):
    for part in ("block", "reader", "simulator", "planner", "fit_blocks", "config", "evaluator"):
        if getattr(entry, part) is not None:
            assert callable(entry.load(part)), f"{entry.name}: {part}"
    for _, where in entry.presets:
        assert callable(systems.load_attribute(where, "preset"))


def test_the_command_lists_come_from_the_registry():
    assert systems.selectable_systems()[:3] == ("head", "external", "mocap")
    assert "floor" not in systems.selectable_systems()
    assert "floor" in systems.planned_systems()
    with pytest.raises(WolfcalError, match="--system 'laser' must be one of head, external, mocap"):
        FitOptions(system="laser")


def test_head_and_external_camera_blocks_pass_the_derivative_check():
    robot = load_robot(WOLFGANG)
    camera = CameraModel(1024, 768, np.array([[700.0, 0, 511.5], [0, 700.0, 383.5], [0, 0, 1]]), np.zeros(5))
    head = synthetic_scenario(robot, camera, n=3, seed=2, offsets="legs")
    block = CameraBlock(robot, head.obs, head.obs.observed_tag_ids)
    chain = build_parameter_set(robot, "leg", {"head": block.tag_ids})
    values = np.random.default_rng(1).normal(0.0, 0.01, len(chain))
    assert_block_derivatives(block, chain, values, rtol=1e-4)
    external = synthetic_external_scenario(robot, camera, n=3, seed=2)
    placement, names = placements(external.obs, False)
    block = CameraBlock(robot, external.obs, external.obs.observed_tag_ids, True, placement, names)
    chain = build_parameter_set(robot, "leg", {"tripod": block.tag_ids})
    values = np.random.default_rng(1).normal(0.0, 0.01, len(chain))
    assert_block_derivatives(block, chain, values, block.nuisance.references + 0.01, rtol=1e-4)


def test_a_wrong_derivative_is_caught():
    robot = load_robot(WOLFGANG)
    block = protractor_blocks(robot, [], None, None)[0][0]
    chain = ParameterSet(protractor_parameters(robot))
    assert_block_derivatives(block, chain, np.array([0.01]))

    class Wrong(ProtractorBlock):
        def linearize(self, chain_values, local_values, chain):
            lin = super().linearize(chain_values, local_values, chain)
            lin.jac_chain *= 2.0
            return lin

    wrong = Wrong(robot, block.q_measured, block.angle)
    with pytest.raises(AssertionError, match="protractor chain"):
        assert_block_derivatives(wrong, chain, np.array([0.01]))


def test_a_toy_system_joins_the_fit_result_and_summary_through_the_registry_alone(toy_registered):
    robot = load_robot(WOLFGANG)
    options = FitOptions(free="protractor", system="protractor")
    blocks, _ = protractor_blocks(robot, [], options, None)
    fit = fit_observations(robot, {}, options, own_blocks=blocks)
    assert fit.chain.names == [f"{JOINT}.offset"]
    value, std = fit.solution.values[0], fit.solution.std[0]
    assert abs(value - TRUE_OFFSET) < 3 * std and std < 0.001, (value, std)
    assert fit.solution.blocks[0].sigma == pytest.approx(NOISE, rel=0.3)  # estimated within the block's bounds
    result = fit_result(fit, options, [], None, [])
    entry = result.blocks[0]
    assert entry["system"] == "protractor" and entry["n_samples"] == 40 and entry["unit"] == "rad"
    assert any(line.startswith("protractor: 40 readings, RMS") for line in summary_lines(result))
