"""`wolfcal plan` on robot descriptions as they are published: collision geometry from collision_radii, URDF
primitives or meshes, meshes that are not shipped, many boxes per link, and configs without the tags a plan needs."""

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.plan.candidates import CLEARANCE_M
from wolfcal.plan.pipeline import PlanOptions, make_plan
from wolfcal.robot.collision_sources import collision_model
from wolfcal.robot.robot import load_robot

ROOT = Path(__file__).resolve().parents[2]
WOLFGANG = ROOT / "configs" / "wolfgang"
BOXED = ROOT / "tests" / "data" / "boxed_biped" / "robot.urdf"
# beside the clone (CI), or beside the folder of worktrees
REALDATA = next((p for p in (ROOT / ".." / "shared" / "realdata", ROOT.parents[1] / "shared" / "realdata")
                 if p.is_dir()), None)  # fmt: skip
# OP3's links as capsules between joint origins (rough outer sizes of its parts [m]); its URDF's collision meshes
# are not shipped
OP3_RADII = {"body_link": 0.06, "head_tilt_link": 0.04, "r_hip_roll_link": 0.025, "l_hip_roll_link": 0.025,
             "r_hip_pitch_link": 0.025, "l_hip_pitch_link": 0.025, "r_knee_link": 0.025, "l_knee_link": 0.025,
             "r_ank_pitch_link": 0.022, "l_ank_pitch_link": 0.022, "r_ank_roll_link": 0.022,
             "l_ank_roll_link": 0.022}  # fmt: skip


def _wolfgang_copy(tmp_path: Path, edit) -> Path:
    """The repository's Wolfgang config in tmp_path (files copied), edited by `edit(data)`."""
    for f in WOLFGANG.iterdir():
        shutil.copy(f, tmp_path / f.name)
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    edit(data)
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    return tmp_path / "robot.yaml"


def _boxed(tmp_path: Path) -> Path:
    """The Wolfgang config on the boxed test robot (137 <collision>: boxes, three meshes not shipped)."""
    shutil.copy(BOXED, tmp_path / "boxed.urdf")
    return _wolfgang_copy(tmp_path, lambda d: (d.update(urdf="boxed.urdf"), d.pop("collision_radii")))


def _realdata_robot(tmp_path: Path, name: str, edit=None) -> Path:
    if REALDATA is None or not (REALDATA / "robots" / name / "robot.yaml").is_file():
        pytest.skip(f"shared/realdata/robots/{name} not here")
    folder = tmp_path / name
    shutil.copytree(REALDATA / "robots" / name, folder)
    if edit is not None:
        data = yaml.safe_load((folder / "robot.yaml").read_text())
        edit(data)
        (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    return folder / "robot.yaml"


def _check_plan(path: Path, poses: int = 12) -> None:
    """A --free leg plan: poses inside the joint limits, free of collision under the robot's model."""
    robot = load_robot(path)
    plan = make_plan(robot, PlanOptions(free="leg", poses=poses, candidates=300), say=lambda _m: None)
    assert len(plan.q) == poses
    model = collision_model(robot)
    assert np.all(model.clearance(plan.q) >= CLEARANCE_M - 1e-12)
    for j in plan.joints:
        joint, k = robot.model.joints[j], robot.joint_names.index(j)
        assert np.all((plan.q[:, k] >= joint.lower) & (plan.q[:, k] <= joint.upper)), j


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["wolfgang", "boxed", "op3", "unitree_h1", "published/wolfgang", "published/nao",
                                   "published/unitree_g1"])  # fmt: skip
def test_plan_leg_on_each_robot_gives_collision_free_poses(tmp_path, robot):
    if robot.startswith("published/"):  # the published descriptions among the test data, when there
        path = ROOT / "tests" / "data" / "robots" / robot.split("/")[1] / "robot.yaml"
        if not path.is_file():
            pytest.skip(f"{path} not here")
    elif robot == "wolfgang":
        path = WOLFGANG / "robot.yaml"
    elif robot == "boxed":
        path = _boxed(tmp_path)
    elif robot == "op3":  # the URDF as published, the collision from the config
        path = _realdata_robot(tmp_path, "op3", lambda d: d.update(collision_radii=OP3_RADII))
    else:
        path = _realdata_robot(tmp_path, robot)
    _check_plan(path)


def test_boxes_overlapping_at_two_axis_joints_leave_poses_free(tmp_path):
    """Onshape-style boxes (servo cases and horns overlapping across the hip's and ankle's two-axis joints):
    those pairs are not checked, the legs against each other are, and the straight rest pose is free."""
    robot = load_robot(_boxed(tmp_path))
    model = collision_model(robot)
    checked = {model.link_pair(k) for k in range(len(model.pairs))}
    for side in "rl":
        assert (f"{side}_hip_1", f"{side}_upper_leg") not in checked  # hip roll and pitch axes meet
        assert (f"{side}_foot", f"{side}_lower_leg") not in checked  # ankle pitch and roll axes meet
        assert (f"{side}_hip_2", f"{side}_lower_leg") in checked  # hip pitch and knee: parallel, a thigh apart
    assert ("l_lower_leg", "r_lower_leg") in checked and ("l_foot", "r_foot") in checked
    rest = np.zeros(len(robot.joint_names))
    assert model.clearance(rest[None])[0] >= CLEARANCE_M
    crossed = np.array([{"RHipRoll": 0.6, "LHipRoll": -0.6}.get(j, 0.0) for j in robot.joint_names])
    assert model.clearance(crossed[None])[0] < 0


def test_missing_collision_meshes_are_skipped_and_named(tmp_path):
    model = collision_model(load_robot(_boxed(tmp_path)))
    assert len(model.warnings) == 1
    for mesh in ("torso_bumper.stl", "r_foot_cover.stl", "l_foot_cover.stl"):
        assert f"package://boxed_biped_description/meshes/{mesh}" in model.warnings[0]
    assert {"torso", "r_foot", "l_foot"} <= {c.link for c in model.capsules}  # their boxes are kept
    assert "left without collision geometry" not in model.warnings[0]


@pytest.mark.slow
def test_missing_collision_meshes_are_skipped_with_one_warning(tmp_path):
    out = tmp_path / "p.yaml"
    args = ["plan", "--free", "leg", "--robot", str(_boxed(tmp_path)), "--poses", "4", "--candidates", "20"]
    result = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.output.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1, result.output
    for mesh in ("torso_bumper.stl", "r_foot_cover.stl", "l_foot_cover.stl"):
        assert mesh in warnings[0]
    assert out.is_file()


def test_published_op3_without_meshes_or_radii_is_a_clear_error(tmp_path):
    path = _realdata_robot(tmp_path, "op3")
    result = CliRunner().invoke(app, ["plan", "--free", "leg", "--robot", str(path), "--out", str(tmp_path / "p.yaml")])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "body.stl" in result.output and "collision_radii" in result.output
    assert "left without collision geometry (never checked): body_link" in result.output


def test_collision_radii_win_over_urdf_collision(tmp_path):
    path = _wolfgang_copy(tmp_path, lambda d: d.update(urdf=str(BOXED)))
    model = collision_model(load_robot(path))
    assert "collision_radii" in model.source and not model.warnings
    assert {c.link for c in model.capsules} == set(yaml.safe_load(path.read_text())["collision_radii"])


def test_urdf_capsule_primitive(tmp_path):
    text = (WOLFGANG / "wolfgang.urdf").read_text().replace(
        '<link name="torso"/>', '<link name="torso"><collision><origin xyz="0 0 0.1" rpy="0 0 0"/><geometry>'
        '<capsule radius="0.04" length="0.12"/></geometry></collision></link>')  # fmt: skip
    (tmp_path / "robot.urdf").write_text(text)
    path = _wolfgang_copy(tmp_path, lambda d: (d.update(urdf="robot.urdf"), d.pop("collision_radii")))
    (capsule,) = collision_model(load_robot(path)).capsules
    np.testing.assert_allclose(sorted([capsule.a_link[2], capsule.b_link[2]]), [0.04, 0.16])
    assert capsule.radius == 0.04


def test_model_rejecting_every_pose_names_the_pair(tmp_path):
    """Hips that turn 0.2 rad at most, a rest pose with the legs spread (outside those limits) and feet as capsules
    of 0.26 m: apart at rest, overlapping in every pose within the limits (feet at most 0.50 m apart). The refusal
    names the pair and the fixes."""
    import re

    text = (WOLFGANG / "wolfgang.urdf").read_text()
    for joint in ("RHipYaw", "LHipYaw", "RHipRoll", "LHipRoll", "RHipPitch", "LHipPitch"):
        start = text.index(f'<joint name="{joint}"')
        end = text.index("</joint>", start)
        text = text[:start] + re.sub(r'lower="[^"]*" upper="[^"]*"', 'lower="-0.2" upper="0.2"',
                                     text[start:end]) + text[end:]  # fmt: skip
    (tmp_path / "narrow.urdf").write_text(text)
    path = _wolfgang_copy(tmp_path, lambda d: d.update(urdf="narrow.urdf", rest_pose={"RHipRoll": -1.5,
                          "LHipRoll": 1.5}, collision_radii={"r_foot": 0.26, "l_foot": 0.26}))  # fmt: skip
    model = collision_model(load_robot(path))
    assert len(model.group_bodies) == 1 and model.clearance(np.zeros((1, len(model.robot.joint_names))))[0] < 0
    out = tmp_path / "p.yaml"
    args = ["plan", "--free", "leg", "--robot", str(path), "--poses", "4", "--candidates", "20"]
    result = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 2 and "Traceback" not in result.output and not out.exists()
    assert "puts l_foot and r_foot closer than 5 mm in 100% of the poses" in result.output, result.output
    assert "collision_radii" in result.output and "collision_ignore: [[l_foot, r_foot]]" in result.output
    # the fix it names: that pair never checked, and the plan finds its poses
    data = yaml.safe_load(path.read_text())
    data["collision_ignore"] = [["l_foot", "r_foot"]]
    path.write_text(yaml.safe_dump(data))
    assert len(collision_model(load_robot(path)).pairs) == 0


def test_collision_ignore_names_links_of_the_urdf(tmp_path):
    path = _wolfgang_copy(tmp_path, lambda d: d.update(collision_ignore=[["r_foot", "no_such_link"]]))
    result = CliRunner().invoke(app, ["plan", "--free", "leg", "--robot", str(path), "--out", str(tmp_path / "p.yaml")])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "'collision_ignore' names no_such_link" in result.output


@pytest.mark.parametrize("system", ["head", "external"])
def test_config_without_torso_tag_plans_or_says_why(tmp_path, system):
    path = _wolfgang_copy(tmp_path, lambda d: d.update(tags=[t for t in d["tags"] if t["id"] != 42]))
    out = tmp_path / "p.yaml"
    result = CliRunner().invoke(app, ["plan", "--free", "leg", "--robot", str(path), "--system", system, "--poses", "4",
                                      "--candidates", "20", "--out", str(out)])  # fmt: skip
    assert "Traceback" not in result.output
    if system == "head":  # the foot tags are all a head-camera leg plan needs
        assert result.exit_code == 0 and out.is_file(), result.output
    else:
        assert result.exit_code == 2 and "torso tag" in result.output and not out.exists()


def test_config_without_leg_tags_is_a_clear_error(tmp_path):
    def no_sides(data):
        for tag in data["tags"]:
            tag.pop("side", None)

    path = _wolfgang_copy(tmp_path, no_sides)
    result = CliRunner().invoke(app, ["plan", "--free", "leg", "--robot", str(path), "--out", str(tmp_path / "p.yaml")])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "'side: right' or 'side: left'" in result.output


def test_segment_distance_to_a_point_and_line_of_sight_match_brute_force():
    """A capsule that is a sphere (segment of length 0) on either side; sight lines tested body by body equal the
    test of every capsule."""
    from wolfcal.robot.collision import segment_distance

    rng = np.random.default_rng(0)
    p0, p1, q = rng.normal(size=(3, 500, 3))
    s = np.linspace(0.0, 1.0, 10001)[:, None, None]
    brute = np.linalg.norm(p0 + s * (p1 - p0) - q, axis=2).min(axis=0)
    np.testing.assert_allclose(segment_distance(p0, p1, q, q), brute, atol=1e-6)
    np.testing.assert_allclose(segment_distance(q, q, p0, p1), brute, atol=1e-6)
    robot = load_robot(WOLFGANG)
    model = collision_model(robot)
    q = rng.uniform(-1, 1, size=(200, len(robot.joint_names)))
    origin, points = rng.normal(size=(200, 3)) * 0.4, rng.normal(size=(200, 8, 3)) * 0.4
    skip = np.full((8, 2), -1)
    skip[:4, 0] = model.body[0]
    a, b = model.segments(q)
    d = segment_distance(origin[:, None, None], points[:, :, None], a[:, None], b[:, None])
    skipped = np.any(model.body[None, :, None] == skip[:, None, :], axis=2)
    every = np.any((d < model.radius) & ~skipped[None], axis=2)
    assert every.any() and (~every).any()
    np.testing.assert_array_equal(model.blocked(q, origin, points, skip), every)
