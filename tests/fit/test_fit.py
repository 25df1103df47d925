"""The estimator against simulated truth (corners projected at the true kinematics, no images: fast)."""

from pathlib import Path

import numpy as np
import pytest

from wolfcal.errors import WolfcalError
from wolfcal.evaluate.accuracy import camera_pose_errors, link_position_errors
from wolfcal.fit.pipeline import FitOptions, fit_observations
from wolfcal.fit.result import explain
from wolfcal.sim.scenario import synthetic_scenario

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"


def z_scores(fit, truth):
    return (fit.solution.values - fit.params.values_from(truth)) / fit.solution.std


def test_camera_preset_recovers_camera_pose_over_whole_head_range(robot, camera):
    scenario = synthetic_scenario(robot, camera, n=24, seed=11)
    fit = fit_observations(robot, scenario.obs, FitOptions(free="camera"))
    rot, trans = camera_pose_errors(robot, fit.corrections, scenario.truth)
    assert np.rad2deg(rot.max()) < 0.05
    assert trans.max() < 0.002
    assert np.all(np.abs(z_scores(fit, scenario.truth)) < 3.0)
    # Before the fit the camera was off by the simulated hand-tuning error (~0.065 rad tilt).
    assert fit.solution.blocks[0].rms_before > 20 * fit.solution.blocks[0].rms_after


def test_leg_preset_puts_soles_within_3mm(robot, camera):
    scenario = synthetic_scenario(robot, camera, n=24, seed=12, offsets="all")
    fit = fit_observations(robot, scenario.obs, FitOptions(free="leg", side="both"))
    rng = np.random.default_rng(0)
    for sole in ("r_sole", "l_sole"):
        errors = link_position_errors(robot, sole, fit.corrections, scenario.truth, 300, rng)
        assert errors.max() < 0.003, sole
    assert np.all(np.abs(z_scores(fit, scenario.truth)) < 3.0)
    # Exactly confounded pairs are reported in words, not silently fitted.
    sentences = explain(fit.params, fit.solution)
    together = [s for s in sentences if "move together" in s]
    assert any("HeadTilt.offset" in s and "camera.rx" in s for s in together)
    assert any("RAnkleRoll.offset" in s for s in sentences)


def test_outlier_samples_are_flagged_and_do_not_drag_the_camera(robot, camera):
    scenario = synthetic_scenario(robot, camera, n=30, seed=13, outlier_fraction=0.1)
    fit = fit_observations(robot, scenario.obs, FitOptions(free="camera"))
    np.testing.assert_array_equal(fit.solution.blocks[0].outlier_samples, scenario.outliers)
    rot, _ = camera_pose_errors(robot, fit.corrections, scenario.truth)
    assert np.rad2deg(rot.max()) < 0.1


def test_one_side_leg_fit_uses_that_side_only(robot, camera):
    scenario = synthetic_scenario(robot, camera, n=20, seed=14, offsets="all")
    fit = fit_observations(robot, scenario.obs, FitOptions(free="leg", side="right"))
    assert fit.tag_ids == [43]
    assert "RKnee.offset" in fit.params.names and "LKnee.offset" not in fit.params.names


def test_too_few_samples_is_a_clear_error(robot, camera):
    scenario = synthetic_scenario(robot, camera, n=4, seed=15)
    with pytest.raises(WolfcalError, match="too few samples"):
        fit_observations(robot, scenario.obs, FitOptions(free="leg"))


def test_a_misdetected_tag_is_left_out_but_not_its_sample(robot, camera):
    scenario = synthetic_scenario(robot, camera, n=24, seed=16)
    obs = scenario.obs
    two_tags = [s for s in range(obs.n_samples) if len(obs.tags_in_sample(s)) == 2]
    s = two_tags[0]
    bad = (obs.sample_index == s) & (obs.tag_ids == 44)
    obs.uv[bad] += [4.0, -3.0]  # e.g. the other foot's tag covers this tag's corners
    fit = fit_observations(robot, obs, FitOptions(free="camera"))
    assert fit.solution.blocks[0].outlier_views == [(s, 44)]
    assert not fit.solution.blocks[0].outlier_samples[s]
    rot, _ = camera_pose_errors(robot, fit.corrections, scenario.truth)
    assert np.rad2deg(rot.max()) < 0.05


def test_tags_by_sample_lists_each_samples_tags_as_tags_in_sample_does(robot, camera):
    obs = synthetic_scenario(robot, camera, n=12, seed=16).obs
    one_tag = obs.subset(np.arange(obs.n_samples), tag_ids=[44])  # samples that saw only tag 43 keep no view
    for o in (obs, one_tag):
        assert o.tags_by_sample() == [o.tags_in_sample(s) for s in range(o.n_samples)]
    assert [] in one_tag.tags_by_sample() and [43, 44] in obs.tags_by_sample()


def test_the_outlier_rule_and_noise_floor_are_the_fits_settings(robot, camera):
    """FitOptions' outlier rule and noise floor decide the fit: a floor above the misdetection keeps the view, a
    noise floor above the real noise holds the estimated noise there."""
    from wolfcal.outliers import OutlierRule

    scenario = synthetic_scenario(robot, camera, n=24, seed=16)
    obs = scenario.obs
    s = [s for s in range(obs.n_samples) if len(obs.tags_in_sample(s)) == 2][0]
    obs.uv[(obs.sample_index == s) & (obs.tag_ids == 44)] += [4.0, -3.0]
    fit = fit_observations(robot, obs, FitOptions(free="camera", outlier=OutlierRule(factor=4.0, floor=50.0)))
    assert fit.solution.blocks[0].outlier_views == []
    fit = fit_observations(robot, obs, FitOptions(free="camera", noise_floor_px=3.0))
    assert fit.solution.blocks[0].sigma >= 3.0
    assert fit.solution.blocks[0].outlier_views == [(s, 44)]
