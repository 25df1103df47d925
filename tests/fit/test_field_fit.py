"""The field system: the head camera's mount and the robot's place on the field from the white lines alone, against
simulated truth; the block's derivatives; the field config; bad field captures."""

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.field.model import KIDSIZE, field_lines
from wolfcal.field.place import DistanceMap, far_places, search_place
from wolfcal.fit.derivative_check import assert_block_derivatives
from wolfcal.fit.field_block import FieldBlock
from wolfcal.fit.jackknife import JACKKNIFE_GROUPS
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import fit_observations
from wolfcal.geometry import exp_so3, log_so3
from wolfcal.io.writer import CaptureWriter
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import build_parameter_set
from wolfcal.robot.robot import load_robot
from wolfcal.sim.field import synthetic_field
from wolfcal.sim.truth import TruthSpec, random_truth

ROOT = Path(__file__).resolve().parents[2]
WOLFGANG = ROOT / "configs" / "wolfgang"
CAMERA = load_camera_info(WOLFGANG / "basler_acA2040.yaml").binned(4)
DIMENSIONS = {name: getattr(KIDSIZE, name) for name in KIDSIZE.__dataclass_fields__}


def field_robot(folder: Path, **field) -> Path:
    """The Wolfgang config with a KidSize field (or `field` given), written to folder/robot.yaml."""
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = str(WOLFGANG / data["urdf"])
    data["camera"]["intrinsics"] = str(WOLFGANG / data["camera"]["intrinsics"])
    data.pop("external_cameras", None)
    data["field"] = field or {"dimensions": DIMENSIONS, "robot_at": {"x": -3.0, "y": 0.0, "yaw": 0.0}}
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    return folder / "robot.yaml"


def test_the_block_derivatives_match_central_differences(tmp_path):
    robot = load_robot(field_robot(tmp_path))
    rng = np.random.default_rng(1)
    truth = random_truth(robot, TruthSpec(), rng)
    pose = np.array([-3.1, 0.15, 0.05])
    obs = synthetic_field(robot, CAMERA, truth, pose, np.array([-3.0, 0.0, 0.0]), KIDSIZE, 3, rng)
    block = FieldBlock(robot, obs, field_lines(KIDSIZE))
    places = rng.normal(0.0, 0.005, len(block.nuisance) - 3)  # the markings' places off their nominal ones [m]
    for preset in ("camera", "leg"):  # the camera's mount; the head and camera chain with the standing legs
        chain = build_parameter_set(robot, preset, {"head": []})
        values = np.array([truth.frames[robot.camera_joint][i] if p.kind == "frame" else 0.0
                           for i, p in zip([p.component for p in chain.parameters], chain.parameters)])  # fmt: skip
        assert_block_derivatives(block, chain, values, np.concatenate([pose, places]), rtol=1e-4)


def test_a_fitted_place_far_from_the_configured_one_is_said(tmp_path):
    """A robot placed up to 0.3 m and 10 deg off is normal; a fitted place 1.7 m and 34 deg off is named, with the
    config's place, in the block's notes and summary."""
    robot = load_robot(field_robot(tmp_path))
    rng = np.random.default_rng(2)
    obs = synthetic_field(robot, CAMERA, Corrections(), np.array([-3.0, 0.0, 0.0]), np.array([-3.0, 0.0, 0.0]),
                          KIDSIZE, 2, rng)  # fmt: skip
    obs = replace(obs, configured=np.array([[-3.0, 0.0, 0.0]]))
    assert far_places(obs, ["field_pose"], np.array([[-2.8, 0.2, 0.17]])) == []
    notes = far_places(obs, ["field_pose"], np.array([[-1.4, 0.7, 0.6]]))
    assert len(notes) == 1 and notes[0].startswith("field_pose lies 1.75 m and 34 deg from where the config places")
    entry = {"name": "field", "unit": "px", "n_samples": 2, "n_outlier_samples": 0, "n_outlier_views": 0,
             "n_units_used": 10, "rms_before_px": 1.0, "rms_after_px": 0.2, "max_after_px": 0.5,
             "notes": notes}  # fmt: skip
    assert FieldBlock.summary_lines(entry)[-1] == f"  warning: {notes[0]}"
    assert far_places(replace(obs, configured=None), ["field_pose"], np.array([[-1.4, 0.7, 0.6]])) == []


@pytest.mark.parametrize("seed, tilt", [(0, TruthSpec.camera_tilt), (3, TruthSpec.camera_tilt), (2, -0.15)])
def test_the_camera_and_the_place_come_out_of_line_points(tmp_path, seed, tilt):
    """Exact line points with 0.3 px noise, 12 views from a robot up to 0.3 m and 10 deg from where it was meant to
    stand, the camera several degrees off (seed 2: pitched 12.8 deg down, which the solve weighted at the first
    solution, restarted at the nominal camera, fitted 21 deg off): rotation within 0.1 deg (of the points on lines,
    the block uses a few dozen per view), place within 5 cm and 0.5 deg, every estimate within 3 reported std."""
    robot = load_robot(field_robot(tmp_path))
    rng = np.random.default_rng(seed)
    truth = random_truth(robot, TruthSpec(camera_tilt=tilt), rng)
    pose = np.array([-3.0, 0.0, 0.0]) + rng.uniform([-0.3, -0.3, -0.17], [0.3, 0.3, 0.17])
    obs = synthetic_field(robot, CAMERA, truth, pose, np.array([-3.0, 0.0, 0.0]), KIDSIZE, 12, rng)
    options = FitOptions(free="camera", system="field")
    block = FieldBlock(robot, obs, field_lines(KIDSIZE))
    first = fit_observations(robot, {}, options, own_blocks=[block])
    fit = fit_observations(robot, {}, options, own_blocks=[block.reweighted(first.chain, first.solution.values)])
    estimate = dict(zip(fit.params.names, fit.solution.values))
    std = dict(zip(fit.params.names, fit.solution.std))
    true_camera = truth.frames[robot.camera_joint]
    rotation = np.array([estimate[f"camera.{c}"] for c in ("rx", "ry", "rz")])
    assert np.rad2deg(np.linalg.norm(log_so3(exp_so3(rotation).T @ exp_so3(true_camera[3:])))) < 0.1
    assert np.hypot(estimate["field_pose.x"] - pose[0], estimate["field_pose.y"] - pose[1]) < 0.05
    assert abs(np.rad2deg(estimate["field_pose.yaw"] - pose[2])) < 0.5
    truths = dict(zip([f"camera.{c}" for c in ("x", "y", "z", "rx", "ry", "rz")], true_camera))
    truths.update({"field_pose.x": pose[0], "field_pose.y": pose[1], "field_pose.yaw": pose[2]})
    z = {name: (estimate[name] - value) / std[name] for name, value in truths.items()}
    assert max(abs(v) for v in z.values()) < 3.0, z


@pytest.mark.parametrize("prior_deg, found_deg", [(None, -16.0), (4.0, -12.0)])
def test_the_place_search_finds_a_camera_pitched_far_down(tmp_path, prior_deg, found_deg):
    """A camera pitched 16 deg down (the simulated tilt and 3 std of its spread beyond it): with the config's
    camera rotation prior (5.7 deg) the pitches tried reach it, and the search finds it within 1 deg and the robot's
    place within 0.1 m. With a prior of 4 deg they reach 12 deg: the search takes the pitch nearest the truth, not
    one that lifts the far points above the horizon and scores the near ones alone (it took +8 deg, 0.4 m off)."""
    path = field_robot(tmp_path)
    if prior_deg is not None:
        data = yaml.safe_load(path.read_text())
        data["priors"] = {"camera_rotation": float(np.deg2rad(prior_deg))}
        path.write_text(yaml.safe_dump(data))
    robot = load_robot(path)
    rng = np.random.default_rng(1)
    truth = random_truth(robot, TruthSpec(camera_tilt=-0.24), rng)
    assert np.rad2deg(truth.frames[robot.camera_joint][3]) == pytest.approx(-16.0, abs=0.1)
    pose = np.array([-3.0, 0.0, 0.0]) + rng.uniform([-0.3, -0.3, -0.17], [0.3, 0.3, 0.17])
    obs = synthetic_field(robot, CAMERA, truth, pose, np.array([-3.0, 0.0, 0.0]), KIDSIZE, 12, rng)
    found = search_place(DistanceMap(field_lines(KIDSIZE)), robot, obs.q_measured, obs.sample_index, obs.uv,
                         obs.camera, np.array([-3.0, 0.0, 0.0]))  # fmt: skip
    assert np.rad2deg(found.pitch) == pytest.approx(found_deg, abs=1.0)
    if prior_deg is None:
        assert np.hypot(*(found.pose[:2] - pose[:2])) < 0.1


def shifted_views(tmp_path):
    """The robot, its truth, its place and line points of 12 synthetic views (0.1 px noise), each view shifted as a
    whole by 1 px rms (seed 2)."""
    robot = load_robot(field_robot(tmp_path))
    rng = np.random.default_rng(2)
    truth = random_truth(robot, TruthSpec(), rng)
    pose = np.array([-3.0, 0.0, 0.0]) + rng.uniform([-0.3, -0.3, -0.17], [0.3, 0.3, 0.17])
    obs = synthetic_field(robot, CAMERA, truth, pose, np.array([-3.0, 0.0, 0.0]), KIDSIZE, 12, rng, 0.1)
    obs = replace(obs, uv=obs.uv + rng.normal(0.0, 1.0, (obs.n_samples, 2))[obs.sample_index])
    return robot, truth, pose, obs


def test_the_solve_weighted_at_a_solution_ends_where_it_ends_from_any_start(tmp_path):
    """The views of the jackknife test below, solved weighted at the first solution: started there and started at
    the nominal camera (its place still at the first solution's) it ends at the same point, each point held on the
    line nearest it at the first solution. Re-associated at every linearisation, the two ended 2.7 mm apart in the
    robot's y (0.6 std): a point that changes its line moves the cost by a step, on which a solve may stop."""
    robot, truth, pose, obs = shifted_views(tmp_path)
    options = FitOptions(free="camera", system="field")
    first = fit_observations(robot, {}, options, own_blocks=[FieldBlock(robot, obs, field_lines(KIDSIZE))])
    solutions = []
    for start in ("first solution", "nominal camera"):
        block = FieldBlock(robot, obs, field_lines(KIDSIZE)).reweighted(first.chain, first.solution.values)
        if start == "nominal camera":
            block.chain_start = None
        fit = fit_observations(robot, {}, options, own_blocks=[block])
        solutions.append(fit.solution.values[: len(fit.chain) + 3])
    assert np.abs(solutions[0] - solutions[1]).max() < 1e-4, solutions


def test_an_error_the_noise_model_does_not_name_is_held_by_the_jackknife(tmp_path):
    """Line points of 12 views, each view shifted as a whole by 1 px rms (an error no part of the noise model
    names): the formal std leaves an estimate beyond 3.5 std of the truth; the reported one, the larger of the
    formal and the grouped jackknife's over the views, holds every estimate within 3 std, and the covariance is
    scaled with it (the correlations stay the formal ones)."""
    robot, truth, pose, obs = shifted_views(tmp_path)
    options = FitOptions(free="camera", system="field")
    block = FieldBlock(robot, obs, field_lines(KIDSIZE))
    first = fit_observations(robot, {}, options, own_blocks=[block])
    checked = block.reweighted(first.chain, first.solution.values, JACKKNIFE_GROUPS)
    fit = fit_observations(robot, {}, options, own_blocks=[checked])
    names = [*fit.chain.names, "field_pose.x", "field_pose.y", "field_pose.yaw"]
    at = [fit.params.names.index(name) for name in names]
    error = fit.solution.values[at] - np.concatenate([truth.frames[robot.camera_joint], pose])
    reported = fit.solution.uncertainty.std[at]
    ratio = np.array([checked.jackknife_ratio[name] for name in names])
    formal = reported / np.maximum(ratio, 1.0)
    assert np.abs(error / formal).max() > 3.5 and np.abs(error / reported).max() < 3.0, (error / formal, ratio)
    u = fit.solution.uncertainty
    assert np.allclose(u.covariance, u.correlation * np.outer(u.std, u.std))


def test_the_field_config_is_read_and_checked(tmp_path):
    config = load_robot_config(field_robot(tmp_path))
    assert config.field_config().dimensions == KIDSIZE and config.field_config().robot_at == (-3.0, 0.0, 0.0)
    bad = field_robot(tmp_path, dimensions={**DIMENSIONS, "penalty_area_width": 7.0},
                      robot_at={"x": -3.0, "y": 0.0, "yaw": 0.0})  # fmt: skip
    with pytest.raises(WolfcalError, match="'field.dimensions'.*penalty area must be narrower than the field"):
        load_robot_config(bad)
    with pytest.raises(WolfcalError, match="field.robot_at.*missing key"):
        load_robot_config(field_robot(tmp_path, dimensions=DIMENSIONS, robot_at={"x": 1.0}))


def write_capture(path: Path, robot_path: Path, image: np.ndarray, n: int = 3) -> None:
    """A capture of n standing samples, each with this head image (binned 4x)."""
    robot = load_robot(robot_path)
    full = load_camera_info(WOLFGANG / "basler_acA2040.yaml")
    q = np.zeros(len(robot.joint_names))
    with CaptureWriter(path, robot.config, {"head": (full, (4, 4))}) as writer:
        for i in range(n):
            writer.add_sample(10**18 + i * 10**9, robot.joint_names, q, None, {"head": image})


def fit_command(capture: Path, robot: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "wolfcal.cli", "fit", str(capture), "--robot", str(robot),
                           "--system", "field", "--free", "camera", "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)  # fmt: skip


def test_views_without_lines_and_grey_views_are_refused(tmp_path):
    robot = field_robot(tmp_path)
    sky = np.zeros((384, 512, 3), np.uint8)
    sky[:] = (230, 200, 160)  # a view of the hall's ceiling: no turf, no lines
    write_capture(tmp_path / "sky.mcap", robot, sky)
    result = fit_command(tmp_path / "sky.mcap", robot, tmp_path / "fit")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "sky.mcap: only 0 field-line points in 3 views" in result.stderr + result.stdout
    write_capture(tmp_path / "grey.mcap", robot, np.full((384, 512), 90, np.uint8))
    result = fit_command(tmp_path / "grey.mcap", robot, tmp_path / "fit")
    assert result.returncode == 2 and "is grey; field lines are told from the turf by colour" in result.stderr
    assert not (tmp_path / "fit").exists()


@pytest.mark.slow
def test_a_rendered_field_capture_calibrates_the_camera(tmp_path):
    """`simulate --system field` then `fit --system field`: rendered 512x384 colour views with clutter."""
    robot = field_robot(tmp_path)
    capture = tmp_path / "field.mcap"
    subprocess.run([sys.executable, "-m", "wolfcal.cli", "simulate", "--robot", str(robot), "--system", "field",
                    "--samples", "10", "--binning", "4", "--seed", "5", "--out", str(capture)],
                   cwd=ROOT, check=True, capture_output=True, timeout=600)  # fmt: skip
    result = fit_command(capture, robot, tmp_path / "fit")
    assert result.returncode == 0, result.stderr
    truth = yaml.safe_load((tmp_path / "field.truth.yaml").read_text())
    params = {p["name"]: p for p in yaml.safe_load((tmp_path / "fit" / "result.yaml").read_text())["parameters"]}
    true_camera = np.array(truth["truth"]["frames"][load_robot(robot).camera_joint])
    rotation = np.array([params[f"camera.{c}"]["value"] for c in ("rx", "ry", "rz")])
    assert np.rad2deg(np.linalg.norm(log_so3(exp_so3(rotation).T @ exp_so3(true_camera[3:])))) < 0.1
    pose = truth["field_pose"]
    assert np.hypot(params["field_pose.x"]["value"] - pose["x"], params["field_pose.y"]["value"] - pose["y"]) < 0.05


def test_stray_points_are_left_out_without_their_views(tmp_path):
    """Every twelfth point 60 px off (a white robot part beside a line) in every fourth view: the fit leaves out
    most of those points one by one (not those that landed near another line) and keeps every view."""
    robot = load_robot(field_robot(tmp_path))
    rng = np.random.default_rng(2)
    truth = random_truth(robot, TruthSpec(), rng)
    pose = np.array([-3.1, 0.1, 0.05])
    obs = synthetic_field(robot, CAMERA, truth, pose, np.array([-3.0, 0.0, 0.0]), KIDSIZE, 12, rng)
    stray = np.concatenate([np.flatnonzero(obs.sample_index == s)[::12] for s in range(0, 12, 4)])
    obs.uv[stray] += [0.0, 60.0]
    options = FitOptions(free="camera", system="field")
    block = FieldBlock(robot, obs, field_lines(KIDSIZE))
    first = fit_observations(robot, {}, options, own_blocks=[block])
    fit = fit_observations(robot, {}, options, own_blocks=[block.reweighted(first.chain, first.solution.values)])
    state = fit.problem.states[0]
    assert not state.excluded.any()
    used = state.block.obs.uv
    left_out = {tuple(p) for p in used[state.excluded_units]}
    z = (fit.solution.values - fit.params.references) / fit.params.prior_sigmas
    residual = fit.problem.raw_residuals(z)[0][:, 0]
    on_a_line = {tuple(p) for p in used[np.abs(residual) < 5.0]}
    kept_strays = {tuple(p) for p in obs.uv[stray] if (used == p).all(axis=1).any()}
    far = kept_strays - on_a_line
    assert len(far) >= 2 and len(far & left_out) >= len(far) / 2


def simulate(robot: Path, out: Path, *extra: str) -> None:
    subprocess.run([sys.executable, "-m", "wolfcal.cli", "simulate", "--robot", str(robot), "--binning", "4",
                    "--out", str(out), *extra], cwd=ROOT, check=True, capture_output=True, timeout=600)  # fmt: skip


def test_a_robot_on_the_other_half_names_the_field_symmetry(tmp_path):
    """The robot stood at (+3, 0) facing +x while field.robot_at says (-3, 0): its views are those of the configured
    place turned round. The fit refuses, naming the other half and the symmetry, rather than fitting the mirror."""
    (tmp_path / "real").mkdir()
    real = field_robot(tmp_path / "real", dimensions=DIMENSIONS, robot_at={"x": 3.0, "y": 0.0, "yaw": 0.0})
    simulate(real, tmp_path / "field.mcap", "--system", "field", "--samples", "6", "--seed", "4")
    result = fit_command(tmp_path / "field.mcap", field_robot(tmp_path), tmp_path / "fit")
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    assert "the lines fit the robot on the other half of the field (x +3" in result.stderr
    assert "point symmetry" in result.stderr and not (tmp_path / "fit").exists()


@pytest.mark.slow
def test_field_and_tag_captures_in_one_fit(tmp_path):
    """`fit feet.mcap field.mcap --free camera`: the feet tags and the field lines (same true camera) in one fit;
    both blocks contribute and the camera and the robot's place land on the truth."""
    robot = field_robot(tmp_path)
    simulate(robot, tmp_path / "feet.mcap", "--system", "head", "--samples", "10", "--seed", "7")
    simulate(robot, tmp_path / "field.mcap", "--system", "field", "--samples", "10", "--seed", "7",
             "--truth", str(tmp_path / "feet.truth.yaml"))  # fmt: skip
    result = subprocess.run([sys.executable, "-m", "wolfcal.cli", "fit", str(tmp_path / "feet.mcap"),
                             str(tmp_path / "field.mcap"), "--robot", str(robot), "--free", "camera", "--out",
                             str(tmp_path / "fit")], cwd=ROOT, capture_output=True, text=True, timeout=600)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "\nhead camera: " in result.stdout and "\nfield: 10 samples" in result.stdout
    fitted = yaml.safe_load((tmp_path / "fit" / "result.yaml").read_text())
    assert {b["name"] for b in fitted["blocks"]} == {"head camera", "field"}
    params = {p["name"]: p for p in fitted["parameters"]}
    true_camera = np.array(yaml.safe_load((tmp_path / "feet.truth.yaml").read_text())["truth"]["frames"][
        load_robot(robot).camera_joint])  # fmt: skip
    rotation = np.array([params[f"camera.{c}"]["value"] for c in ("rx", "ry", "rz")])
    assert np.rad2deg(np.linalg.norm(log_so3(exp_so3(rotation).T @ exp_so3(true_camera[3:])))) < 0.1
    pose = yaml.safe_load((tmp_path / "field.truth.yaml").read_text())["field_pose"]
    assert np.hypot(params["field_pose.x"]["value"] - pose["x"], params["field_pose.y"]["value"] - pose["y"]) < 0.05
