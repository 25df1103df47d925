"""Floor samples in a few stances (`floor.stances`): read and checked against the standing rule, simulated spread
over the stances, captured in each, and modelled with one shared reading error per joint and stance."""

from __future__ import annotations

import io
from dataclasses import replace

import numpy as np
import pytest
import yaml
from conftest import OTHER_CAMERA, WOLFGANG, joined, wolfgang_with_other_tags
from rich.console import Console
from typer.testing import CliRunner

from wolfcal.capture.floor import CHECK_VIEWS_PER_STANCE, check_views, floor_script
from wolfcal.capture.pipeline import CaptureOptions, run_capture
from wolfcal.capture.poses import PoseScript
from wolfcal.cli import app
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.ground import ground_errors
from wolfcal.fit.floor_block import FloorBlock, SoleClosure
from wolfcal.fit.pipeline import FitOptions, fit_observations, load_samples
from wolfcal.robot.aim import AIM_BEARINGS_DEG, AIM_DISTANCES_M
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import moved_stance, stance_poses
from wolfcal.robot.robot import load_robot
from wolfcal.robot.stances import off_plane, sole_gaps
from wolfcal.sim.floor import simulate_floor
from wolfcal.sim.scenario import synthetic_scenario

# knees bent deeper, hips and ankles solved (nominal model) so that each sole keeps the standing orientation
DEEP = [{"RKnee": -0.6, "RHipPitch": -0.1694, "RAnklePitch": 0.1688, "LKnee": 0.6, "LHipPitch": 0.1695,
         "LAnklePitch": -0.1687},
        {"RKnee": -0.9, "RHipPitch": -0.3194, "RAnklePitch": 0.3188, "LKnee": 0.9, "LHipPitch": 0.3196,
         "LAnklePitch": -0.3186}]  # fmt: skip
# the torso 3 cm sideways or turned 0.15 rad, 1 cm lower, each sole kept where it stands (nominal model; stances a
# floor capture spreads its samples over): every leg joint, roll and yaw too, reads another tick than in the standing
# pose
LEAN = yaml.safe_load((WOLFGANG / "floor_stances.yaml").read_text())
STANDING = {"RKnee": -0.2618, "LKnee": 0.2618}


def write_config(folder, stances) -> object:
    data = wolfgang_with_other_tags()
    data["floor"]["tags"] = [{"id": 60 + k, "size": s} for k, s in enumerate([0.12, 0.14, 0.16, 0.18, 0.2, 0.15])]
    if stances is not None:
        data["floor"]["stances"] = stances
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    return folder / "robot.yaml"


@pytest.mark.slow
def test_stances_that_move_every_leg_joint_average_the_standing_readings_rounding(tmp_path):
    """Floor samples all standing share one rounded reading of each leg joint, which the leg fit takes in as an
    offset; spread over stances in which every joint (roll and yaw too) reads another tick, the roundings average.
    Truth: the simulator's offsets; 20 floor samples and 24 feet samples (synthetic corners), 4 seeds."""
    errors = {}
    for name, stances in (("standing", None), ("lean", [STANDING, *LEAN])):
        (tmp_path / name).mkdir()
        robot = load_robot(write_config(tmp_path / name, stances))
        _, gap, bad = off_plane(
            sole_gaps(np.stack(list(robot.model.link_poses(stance_poses(robot), ["l_sole", "r_sole"]).values())))
        )
        assert not bad.any() and gap.max() < 1e-3  # the nominal soles stay on one plane in every stance
        errors[name] = []
        for seed in range(4):
            feet = synthetic_scenario(robot, OTHER_CAMERA, 24, seed, offsets="all")
            floor = simulate_floor(robot, OTHER_CAMERA, feet.truth, 20, np.random.default_rng(seed + 100))
            fit = fit_observations(robot, {"head": joined(feet.obs, floor.obs)}, FitOptions(free="leg", side="both"))
            row = ground_errors(robot, OTHER_CAMERA, feet.truth, {"m": fit.corrections}, (4.5,))[0]
            errors[name].append(row["models"]["m"]["error_m"])
    standing, lean = np.array(errors["standing"]), np.array(errors["lean"])
    assert lean.max() < 0.025 and lean.mean() < 0.7 * standing.mean(), (standing, lean)


def test_stances_are_read_in_order_and_default_to_standing(tmp_path):
    robot = load_robot(write_config(tmp_path, [{"RKnee": -0.2618, "LKnee": 0.2618}, *DEEP]))
    q = stance_poses(robot)
    assert q.shape == (3, len(robot.joint_names))
    assert q[1, robot.model.column("RHipPitch")] == -0.1694 and q[2, robot.model.column("LKnee")] == 0.9
    assert q[0, robot.model.column("RHipPitch")] == 0.0  # joints not named: 0
    _, gap, bad = off_plane(sole_gaps(np.stack(list(robot.model.link_poses(q, ["l_sole", "r_sole"]).values()))))
    assert not bad.any() and gap.max() < 1e-3  # the deep stances keep the nominal soles on one plane
    (tmp_path / "one").mkdir()
    robot = load_robot(write_config(tmp_path / "one", None))
    assert stance_poses(robot).shape[0] == 1
    assert stance_poses(robot)[0, robot.model.column("RKnee")] == robot.config.floor.standing["RKnee"]


@pytest.mark.parametrize(
    "stances, words",
    [
        ([DEEP[0], {"RKnee": -0.6}], "'floor.stances[1]' is not a standing pose: the soles l_sole and r_sole are"),
        ([{"RKnee": -0.6, "LKnee": 0.6, "RAnkleRoll": 0.3}], "'floor.stances[0]' is not a standing pose"),
        ([{"NoJoint": 0.1}], "'floor.stances[0]' names joint(s) NoJoint"),
        ([{"RKnee": "deep"}], "'stances[0].RKnee' must be a number [rad]"),
        ({"RKnee": 0.1}, "'stances' must be a list of standing poses"),
    ],
)
def test_a_bad_stance_is_named(tmp_path, stances, words):
    path = write_config(tmp_path, stances)
    with pytest.raises(WolfcalError, match="robot.yaml") as info:
        load_robot(path)
    assert words in str(info.value)
    result = CliRunner().invoke(app, ["simulate", "--floor", "--robot", str(path), "--out", str(tmp_path / "x.mcap")])
    assert result.exit_code != 0 and words in " ".join(result.output.split()) and "Traceback" not in result.output


def test_simulated_floor_samples_spread_over_the_stances_and_share_a_reading_per_stance(tmp_path):
    robot = load_robot(write_config(tmp_path, [{"RKnee": -0.2618, "LKnee": 0.2618}, *DEEP]))
    truth = Corrections(offsets={"RKnee": 0.02, "LHipPitch": -0.015, "HeadPan": 0.01})
    scene = simulate_floor(robot, OTHER_CAMERA, truth, 20, np.random.default_rng(3))
    knee = robot.model.column("RKnee")
    assert sorted(np.unique(scene.q_true[:, knee], return_counts=True)[1]) == [6, 7, 7]  # 20 spread evenly
    assert set(scene.q_true[:, knee]) == {-0.2618, -0.6, -0.9}  # the true angles of each stance
    np.testing.assert_allclose(scene.obs.q_measured[:, knee], scene.q_true[:, knee] - 0.02, atol=1e-3)
    for block in (FloorBlock(robot, scene.obs), SoleClosure(robot, scene.obs)):
        groups = block.joint_reading_groups()  # (units, joints): one reading error per joint and stance
        units_stance = {k: np.unique(scene.q_true[block.sample_of_unit, knee] == v)
                        for k, v in enumerate((-0.2618, -0.6, -0.9))}  # fmt: skip
        assert all(len(u) for u in units_stance.values())
        for j in ("RKnee", "LHipPitch", "RAnklePitch"):
            assert len(np.unique(groups[:, robot.model.column(j)])) == 3, j
        assert len(np.unique(groups[:, robot.model.column("RHipRoll")])) == 1  # the same reading in every stance


def test_scripted_floor_capture_goes_through_the_stances(tmp_path):
    stances = [{"RKnee": -0.2618, "LKnee": 0.2618}, *DEEP]
    robot = load_robot(write_config(tmp_path, stances))
    poses = floor_script(robot, 0.5).poses
    grid = len(AIM_DISTANCES_M) * len(AIM_BEARINGS_DEG)
    assert len(poses) == 3 * grid
    for k, stance in enumerate(stances):
        for pose in poses[k * grid : (k + 1) * grid]:  # each stance in turn, legs at its readings
            assert pose.name.startswith(f"stance {k}, floor ")
            assert all(pose.joints[j] == v for j, v in stance.items()) and pose.joints["RHipRoll"] == 0.0


def test_manual_floor_capture_in_several_stances_needs_a_sample_count(tmp_path):
    path = write_config(tmp_path, [{"RKnee": -0.2618, "LKnee": 0.2618}, *DEEP])
    options = CaptureOptions(robot=path, out=tmp_path / "x.mcap", port="/dev/null", camera="sim", floor=True,
                             manual=True)  # fmt: skip
    with pytest.raises(WolfcalError, match=r"'floor.stances' lists 3 stances; .* give --samples"):
        run_capture(options, Console(file=io.StringIO()))
    assert not list(tmp_path.glob("x.mcap*"))


def test_a_moved_torso_gives_the_stances_solved_before():
    """`moved_stance` from the torso-sideways stance back to the middle and then sideways the other way, or turned,
    gives floor_stances.yaml's stances (solved separately before, to 0.1 mrad), soles kept on one plane."""
    robot = load_robot(WOLFGANG)
    centre = moved_stance(robot, LEAN[0], (0.0, -0.03, 0.0, 0.0))
    for shift, expected in (((0.0, 0.03, 0.0, 0.0), LEAN[0]), ((0.0, -0.03, 0.0, 0.0), LEAN[1]),
                            ((0.0, 0.0, 0.0, 0.15), LEAN[2])):  # fmt: skip
        moved = moved_stance(robot, centre, shift)
        assert max(abs(moved.get(j, 0.0) - v) for j, v in expected.items()) <= 2e-4, (shift, moved)
    with pytest.raises(WolfcalError, match="from where they stand: take a smaller move"):
        moved_stance(robot, centre, (0.0, 0.0, -0.3, 0.0))  # 30 cm lower: beyond the legs' reach


def test_check_stances_are_read_checked_and_none_of_the_fits(tmp_path):
    """Wolfgang's `floor.check_stances` are standing poses none of which is a fit stance, every leg joint reading
    other ticks in most of them; a bad one is named."""
    floor = load_robot(WOLFGANG).config.floor_config()
    assert len(floor.check_stances) == 16 and floor.capture_stances(check=True) == floor.check_stances
    assert floor.capture_stances() == (floor.standing,)
    fit = [floor.standing, *LEAN]
    assert not any(c == f for c in floor.check_stances for f in fit)
    robot = load_robot(WOLFGANG)
    ticks = np.round(stance_poses(robot, check=True) / (2 * np.pi / 4096))
    legs = [robot.model.column(j) for j in robot.actuated_joints_to(list(floor.soles))]
    assert all(len(np.unique(ticks[:, c])) >= 14 for c in legs)
    data = wolfgang_with_other_tags()
    data["floor"]["check_stances"] = [floor.check_stances[0], {"RKnee": -0.6}]
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(WolfcalError, match=r"'floor.check_stances\[1\]' is not a standing pose"):
        load_robot(tmp_path / "robot.yaml")


def test_the_check_capture_goes_through_the_check_stances(tmp_path):
    """`capture --floor --check`: one head view per check stance, the grid's points in turn; `simulate --floor
    --check`: the samples spread over the check stances."""
    robot = load_robot(WOLFGANG)
    stances = robot.config.floor_config().check_stances
    script = floor_script(robot, 0.5, check=True)
    grid = len(AIM_DISTANCES_M) * len(AIM_BEARINGS_DEG)
    assert len(script.poses) == len(stances) * grid
    poses = check_views(robot, script).poses
    assert len(poses) == len(stances) * CHECK_VIEWS_PER_STANCE
    for k, stance in enumerate(stances):
        pose = poses[k * CHECK_VIEWS_PER_STANCE]
        assert pose.name.startswith(f"stance {k}, floor ")
        assert all(pose.joints[j] == v for j, v in stance.items())
    assert len({p.name.split(", ", 1)[1] for p in poses}) == grid  # the whole grid over the stances
    fewer = PoseScript([p for p in script.poses if "-30 deg" not in p.name], 0.5)  # as if left out for collisions
    assert len(check_views(robot, fewer).poses) == len(stances) * CHECK_VIEWS_PER_STANCE
    # the stances are told by the legs' targets, not by the poses' names
    renamed = PoseScript([replace(p, name=f"view {k}") for k, p in enumerate(script.poses)], 0.5)
    assert check_views(robot, renamed).poses == [replace(p, name=f"view {script.poses.index(p)}") for p in poses]
    out = tmp_path / "check.mcap"
    result = CliRunner().invoke(app, ["simulate", "--floor", "--check", "--samples", "16", "--binning", "4",
                                      "--out", str(out)])  # fmt: skip
    assert result.exit_code == 0, result.output
    samples, _ = load_samples(robot, [out], None)
    knees = sorted(dict(zip(s.joint_names, s.positions))["LKnee"] for s in samples)  # no offsets: the readings
    np.testing.assert_allclose(knees, sorted(s["LKnee"] for s in stances), atol=1e-3)  # one sample per stance
    refused = CliRunner().invoke(app, ["simulate", "--check", "--out", str(tmp_path / "x.mcap")])
    assert refused.exit_code != 0 and "--check is the held-out floor capture: give it with --floor" in refused.output
    data = wolfgang_with_other_tags()
    del data["floor"]["check_stances"]
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    refused = CliRunner().invoke(app, ["simulate", "--floor", "--check", "--robot", str(tmp_path / "robot.yaml"),
                                       "--out", str(tmp_path / "y.mcap")])  # fmt: skip
    text = " ".join(refused.output.split())
    assert refused.exit_code != 0 and "'floor.check_stances', which the config does not give" in text, text
    assert "Traceback" not in refused.output and not (tmp_path / "y.mcap").exists()
