"""The measured ground error of held-out floor views (no truth used) against the simulator's true ground error."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.evaluate.floor_ground import floor_views, measured_ground_errors, real_floor
from wolfcal.evaluate.ground import ground_errors
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import load_robot
from wolfcal.sim.floor import simulate_floor
from wolfcal.sim.simulate import offset_joints
from wolfcal.sim.truth import TruthSpec, random_truth
from wolfcal.vision.corner_bias import inset_moves

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"


@pytest.mark.parametrize("seed", [0, 3])
def test_measured_ground_error_agrees_with_the_true_one(seed):
    robot = load_robot(WOLFGANG)
    camera = load_camera_info(robot.config.head_camera().intrinsics)
    rng = np.random.default_rng(seed)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, "all")), rng)
    floor = simulate_floor(robot, camera, truth, 30, rng, distance=(0.5, 5.0))
    distances = (2.0, 4.5)  # at 1 m seed 0 measures 6.0 cm against a true 7.6 cm (21 %)
    measured = measured_ground_errors(robot, floor.obs, {"before": Corrections()}, distances)
    true = ground_errors(robot, camera, truth, {"before": Corrections()}, distances)
    for row, mine in zip(true, measured["models"]["before"]["rows"]):
        t, m = row["models"]["before"]["error_m"], mine["error_m"]
        assert abs(m - t) < max(0.2 * t, 0.01), (row["distance_m"], t, m)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_small_ground_error_is_measured_within_its_uncertainty(seed):
    """A model near the truth (one ankle off by 1 deg: ~10 cm at 4.5 m) and corners biased inward by a known
    inset, corrected with the fit's inset: the measurement lies within 2 of its 1-sigmas of the truth, and that
    1-sigma is small enough that neither 0 nor twice the true error would pass."""
    robot = load_robot(WOLFGANG)
    camera = load_camera_info(robot.config.head_camera().intrinsics)
    rng = np.random.default_rng(seed)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, "all")), rng)
    model = Corrections({**truth.offsets, "LAnkleRoll": truth.offsets.get("LAnkleRoll", 0.0) + np.deg2rad(1.0)},
                        truth.frames, truth.tags)  # fmt: skip
    floor = simulate_floor(robot, camera, truth, 30, rng, distance=(0.5, 5.0))
    inset = 0.3  # [px] at REFERENCE_EDGE_PX, as the fit would find it
    obs = floor.obs
    ring_of = np.lexsort((obs.corner_index, obs.tag_ids, obs.sample_index))
    ring = obs.uv[ring_of].reshape(-1, 4, 2)  # every simulated view has its 4 corners
    biased = obs.uv.copy()
    biased[ring_of] = (ring + inset * inset_moves(ring)).reshape(-1, 2)
    measured = measured_ground_errors(robot, dataclasses.replace(obs, uv=biased), {"after": model}, (4.5,),
                                      corner_inset=(inset, 0.02))["models"]["after"]["rows"][0]  # fmt: skip
    true = ground_errors(robot, camera, truth, {"after": model}, (4.5,))[0]["models"]["after"]["error_m"]
    assert 0.04 < true < 0.3
    assert abs(measured["error_m"] - true) < 2 * measured["std_m"], (true, measured)
    assert measured["std_m"] < 0.4 * true, (true, measured)


def test_the_readings_rounding_is_fitted_and_the_standing_legs_part_kept_in_the_sigma():
    """The exact model (true ground error 0 at unrounded readings) on views whose readings are rounded to ticks: the
    corner residual comes down to the corner noise (0.15 px), not the head readings' rounding (~0.6 px at this
    camera's 1336 px focal length), and the standing legs' rounding, one tick shared by every sample, stays in the
    1 sigma, which covers the measured error."""
    robot = load_robot(WOLFGANG)
    camera = load_camera_info(robot.config.head_camera().intrinsics)
    rng = np.random.default_rng(1)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, "all")), rng)
    floor = simulate_floor(robot, camera, truth, 30, rng, distance=(0.5, 5.0), noise_px=0.15)
    assert real_floor(robot, floor.obs, truth)["scale_px"] < 0.25
    row = measured_ground_errors(robot, floor.obs, {"exact": truth}, (4.5,))["models"]["exact"]["rows"][0]
    assert row["rounding_std_m"] > 0.005, row
    assert row["error_m"] < 2 * row["std_m"], row


def _near_truth(robot, seed):
    """(camera, truth, a model one ankle off by 1 deg from the truth: ~10 cm at 4.5 m) of a simulated robot."""
    camera = load_camera_info(robot.config.head_camera().intrinsics)
    rng = np.random.default_rng(seed)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, "all")), rng)
    model = Corrections({**truth.offsets, "LAnkleRoll": truth.offsets.get("LAnkleRoll", 0.0) + np.deg2rad(1.0)},
                        truth.frames, truth.tags)  # fmt: skip
    return camera, truth, model, rng


def _joined(a, b):
    """The observations of two captures as one (b's samples after a's)."""
    return dataclasses.replace(
        a, q_measured=np.concatenate([a.q_measured, b.q_measured]), stamps_ns=np.concatenate([a.stamps_ns,
        b.stamps_ns]), sources=[*a.sources, *b.sources], sample_index=np.concatenate([a.sample_index,
        b.sample_index + a.n_samples]), tag_ids=np.concatenate([a.tag_ids, b.tag_ids]),
        corner_index=np.concatenate([a.corner_index, b.corner_index]), uv=np.concatenate([a.uv, b.uv]))  # fmt: skip


@pytest.mark.slow
def test_tags_moved_between_two_check_captures_lie_in_one_place_per_capture_file():
    """Two held-out captures with the tags laid out anew (a user moving them): each tag gets a place per capture
    file, and the measurement agrees with the truth; the capture's size counts both layouts."""
    robot = load_robot(WOLFGANG)
    camera, truth, model, rng = _near_truth(robot, 4)
    first = simulate_floor(robot, camera, truth, 12, rng, distance=(0.5, 5.0), source="check_a.mcap").obs
    second = simulate_floor(robot, camera, truth, 12, rng, distance=(0.5, 5.0), source="check_b.mcap").obs
    both = _joined(first, second)
    placements = floor_views(robot, both, model).placements
    assert len(np.unique(placements)) == len(np.unique(first.tag_ids)) + len(np.unique(second.tag_ids))
    measured = measured_ground_errors(robot, both, {"after": model}, (4.5,))
    assert measured["capture"] == {"samples": 24, "stances": 1, "layouts": 2}
    assert measured["check"] == {"samples": 48, "stances": 16, "layouts": 3}  # Wolfgang's 16 floor.check_stances
    row = measured["models"]["after"]["rows"][0]
    true = ground_errors(robot, camera, truth, {"after": model}, (4.5,))[0]["models"]["after"]["error_m"]
    assert abs(row["error_m"] - true) < max(2 * row["std_m"], 0.2 * true), (true, row)


@pytest.mark.slow
def test_a_view_far_off_is_left_out_as_the_fit_leaves_it_out():
    """One view's corners moved 3 px (a corner caught on something else): it is left out, and the floor comes out
    as without that view."""
    robot = load_robot(WOLFGANG)
    camera, truth, model, rng = _near_truth(robot, 5)
    obs = simulate_floor(robot, camera, truth, 20, rng, distance=(0.5, 5.0)).obs
    view = (obs.sample_index == 3) & (obs.tag_ids == obs.tag_ids[obs.sample_index == 3][0])
    off = dataclasses.replace(obs, uv=obs.uv + np.where(view[:, None], [3.0, -2.0], 0.0))
    without = dataclasses.replace(obs, sample_index=obs.sample_index[~view], tag_ids=obs.tag_ids[~view],
                                  corner_index=obs.corner_index[~view], uv=obs.uv[~view])  # fmt: skip
    floor, clean = real_floor(robot, off, model), real_floor(robot, without, model)
    assert floor["outlier_views"] == 1 and clean["outlier_views"] == 0
    assert floor["views"] == clean["views"]
    assert np.allclose(floor["unknowns"], clean["unknowns"], atol=1e-6), (floor["unknowns"], clean["unknowns"])


@pytest.mark.slow
def test_corners_slid_along_an_edge_are_left_out(monkeypatch):
    """One corner in each of every fifth view slid 1.2 px along its edge (the detector on a small, strongly
    foreshortened far tag; too little for the view rule, `outliers.FIT_VIEW_PX`): those corners are left out, and
    the floor comes out as on the clean corners; kept in, they move it far more."""
    robot = load_robot(WOLFGANG)
    camera, truth, model, rng = _near_truth(robot, 6)
    obs = simulate_floor(robot, camera, truth, 20, rng, distance=(0.5, 5.0), noise_px=0.1).obs
    order = np.lexsort((obs.corner_index, obs.tag_ids, obs.sample_index))
    ring = obs.uv[order].reshape(-1, 4, 2)
    slid = ring.copy()
    edge = ring[::5, 1] - ring[::5, 0]
    slid[::5, 0] += 1.2 * edge / np.linalg.norm(edge, axis=1, keepdims=True)
    uv = obs.uv.copy()
    uv[order] = slid.reshape(-1, 2)
    off = dataclasses.replace(obs, uv=uv)
    clean, floor = real_floor(robot, obs, model), real_floor(robot, off, model)
    assert floor["outlier_corners"] >= len(edge) and floor["outlier_views"] == 0, floor
    monkeypatch.setattr("wolfcal.evaluate.floor_ground.CORNER_ROUNDS", 0)
    kept = real_floor(robot, off, model)
    lever = np.array([4.5, 4.5, 1.0])  # [m/rad, m/rad, m/m]: what the plane's tilt and height move at 4.5 m
    change, kept_change = (np.linalg.norm(lever * (f["unknowns"][:3] - clean["unknowns"][:3])) for f in (floor, kept))
    assert change < 0.3 * kept_change, (change, kept_change)


def test_a_solve_without_some_views_holds_the_unknowns_no_kept_corner_depends_on():
    """Leaving one sample's views out (a jackknife replicate) leaves its head readings' errors with only their prior,
    which the Huber loss takes in too: nothing curbed their steps (a reading error reached 4e9 in one replicate and
    least_squares' SVD failed). They keep their start, and the plane comes out as from any other start of them."""
    from wolfcal.evaluate.floor_ground import _FloorFit

    robot = load_robot(WOLFGANG)
    camera, truth, model, rng = _near_truth(robot, 7)
    obs = simulate_floor(robot, camera, truth, 12, rng, distance=(0.5, 5.0), noise_px=0.1).obs
    views = floor_views(robot, obs, model)
    fit = _FloorFit(robot, views, camera, (0.0, 0.05))
    x = fit.solve(fit.start(), np.ones(len(views.tags), dtype=bool))
    keep = views.samples != views.samples[0]
    orphan = ~fit.sparsity(keep)[: fit.n_pixels(keep)].any(axis=0)
    assert orphan[fit.first_reading :].any()
    far = x.copy()
    far[orphan] = 1e3 * robot.config.priors.encoder_noise  # far up the Huber loss's linear arm
    held, reference = fit.solve(far, keep, 0.1), fit.solve(x, keep, 0.1)
    assert np.array_equal(held[orphan], far[orphan])
    assert np.allclose(held[:7], reference[:7], rtol=0, atol=1e-9), (held[:7], reference[:7])
