"""`wolfcal plan`: poses inside the limits and free of collisions (checked independently), selection against brute
force, planned beats random, and bad input."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from wolfcal.capture.poses import joint_limits, load_poses
from wolfcal.cli import app
from wolfcal.errors import WolfcalError
from wolfcal.plan.pipeline import PlanOptions, make_plan, poses_text
from wolfcal.plan.select import criterion_value, information, select, values_after_adding
from wolfcal.robot.robot import load_robot

WOLFGANG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"


def _config_copy(tmp_path: Path, edit) -> Path:
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = str(WOLFGANG / "wolfgang.urdf")
    data["camera"]["intrinsics"] = str(WOLFGANG / "basler_acA2040.yaml")
    data["external_cameras"][0]["intrinsics"] = str(WOLFGANG / "tripod_webcam.yaml")
    edit(data)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _capsule_points(robot, q: np.ndarray) -> dict[str, tuple[np.ndarray, float]]:
    """Independent of wolfcal.robot.collision: points every 2 mm along each link's capsules (link origin to each
    child joint's origin, which is the child link's origin for revolute joints), with the link's radius."""
    radii = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())["collision_radii"]
    children = {link: [j.child for j in robot.model.joints.values() if j.parent == link] for link in radii}
    links = sorted(set(radii) | {c for cs in children.values() for c in cs})
    poses = robot.model.link_poses(q[None], links)
    out = {}
    for link, radius in radii.items():
        a = poses[link][0, :3, 3]
        ends = [poses[c][0, :3, 3] for c in children[link]] or [a]
        pts = [a + np.linspace(0, 1, max(2, int(np.linalg.norm(b - a) / 0.002)))[:, None] * (b - a) for b in ends]
        out[link] = (np.concatenate(pts), radius)
    return out


def _rigid_root(robot, link: str) -> str:
    while link in robot.model.joint_to_child and robot.model.joint_to_child[link].type == "fixed":
        link = robot.model.joint_to_child[link].parent
    return link


def _min_gaps(robot, q: np.ndarray) -> dict[tuple[str, str], float]:
    """Surface gap [m] of every pair of capsule links on different, non-adjacent rigid bodies (brute force)."""
    caps = _capsule_points(robot, q)
    adjacent = {(_rigid_root(robot, j.parent), _rigid_root(robot, j.child)) for j in robot.model.joints.values()}
    gaps = {}
    names = sorted(caps)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            ra, rb = _rigid_root(robot, a), _rigid_root(robot, b)
            if ra == rb or (ra, rb) in adjacent or (rb, ra) in adjacent:
                continue
            d = np.linalg.norm(caps[a][0][:, None] - caps[b][0][None], axis=2).min()
            gaps[(a, b)] = d - caps[a][1] - caps[b][1]
    return gaps


@pytest.fixture(scope="module")
def small_plan(robot):
    options = PlanOptions(free="leg", side="both", system="head", poses=5, candidates=120, seed=3)
    return options, make_plan(robot, options, say=lambda _m: None)


def test_written_poses_are_inside_the_limits_and_collision_free(robot, small_plan, tmp_path):
    options, plan = small_plan
    path = tmp_path / "plan.yaml"
    path.write_text(poses_text(robot, plan, options))
    script = load_poses(path, joint_limits(robot, robot.config.servos.ids))  # refuses targets outside the limits
    assert len(script.poses) == 5
    assert all(list(p.joints) == plan.joints for p in script.poses), "every joint the plan moves is named"
    assert not {"RElbow", "LShoulderPitch"} & set(plan.joints), "the arms are left alone"
    rest_gaps = _min_gaps(robot, np.zeros(len(robot.joint_names)))
    for pose in script.poses:
        q = np.array([pose.joints.get(j, 0.0) for j in robot.joint_names])  # arms at the rest pose (0)
        gaps = _min_gaps(robot, q)
        # pairs that already touch in the rest pose are allowed to (as in the planner); every other pair is apart
        bad = {k: v for k, v in gaps.items() if v < 0 and rest_gaps[k] >= 0.005}
        assert not bad, f"{pose.name}: bodies overlap {bad}"


def test_planned_poses_beat_random_ones(small_plan):
    _, plan = small_plan
    for unit in ("m", "rad"):
        assert plan.worst_std(plan.planned, unit) < plan.worst_std(plan.random, unit)
    assert plan.condition[0] < plan.condition[1]
    named = {name for group in plan.groups for name in group}
    assert {"RAnkleRoll.offset", "LAnkleRoll.offset", "HeadTilt.offset"} <= named, plan.groups


def test_rank_updates_match_direct_criteria_and_exchange_improves_greedy():
    rng = np.random.default_rng(0)
    G = rng.normal(size=(40, 3, 6)) * rng.uniform(0.1, 3, size=(1, 1, 6))
    basis = np.linalg.qr(rng.normal(size=(4, 3)))[0]  # 4 chain unknowns, one direction left out
    M = information(G, [1, 5])
    for criterion in ("D", "A", "E"):
        fast = values_after_adding(M, G, basis, criterion)
        direct = [criterion_value(M + G[k].T @ G[k], basis, criterion) for k in range(len(G))]
        np.testing.assert_allclose(fast, direct, rtol=1e-8, atol=1e-10)
        chosen, value = select(G, 4, basis, criterion)
        assert len(set(chosen)) == 4
        # no single exchange improves the result (a local optimum of the exchange)
        for i in range(4):
            for k in set(range(len(G))) - set(chosen):
                other = chosen[:i] + [k] + chosen[i + 1 :]
                assert criterion_value(information(G, other), basis, criterion) >= value - 1e-9


def test_robot_without_collision_geometry_is_refused(tmp_path):
    path = _config_copy(tmp_path, lambda d: d.pop("collision_radii"))
    result = CliRunner().invoke(app, ["plan", "--robot", str(path), "--out", str(tmp_path / "p.yaml")])
    assert result.exit_code != 0
    assert "collision_radii" in result.output and "Traceback" not in result.output


def test_tag_never_in_view_is_refused(tmp_path):
    def hide_left_tag(data):  # a 'left' tag on the torso's back: the head camera never sees it
        data["tags"][1].update(link="torso", side="left", xyz=[-0.07, 0.0, 0.12], rpy=[1.5708, 0, -1.5708])
    robot = load_robot(_config_copy(tmp_path, hide_left_tag))
    with pytest.raises(WolfcalError, match="tag 44 .* in view in none"):
        make_plan(robot, PlanOptions(free="leg", side="both", poses=3, candidates=50), say=lambda _m: None)


def test_external_camera_facing_away_finds_no_candidate(robot):
    options = PlanOptions(free="leg", system="external", poses=3, candidates=50, placement="-1.5,0,0,0,0,3.1416")
    with pytest.raises(WolfcalError, match="none of .* random poses within the joint limits shows"):
        make_plan(robot, options, say=lambda _m: None)


def test_capture_refuses_a_script_whose_legs_cross(robot, tmp_path):
    from wolfcal.capture.poses import check_collisions

    path = tmp_path / "poses.yaml"
    path.write_text("poses:\n- {name: apart, joints: {RHipRoll: -0.3, LHipRoll: 0.3}}\n"
                    "- {name: crossed, joints: {RHipRoll: 0.6, LHipRoll: -0.6}}\n")
    script = load_poses(path, joint_limits(robot, robot.config.servos.ids))
    crossed = np.array([{"RHipRoll": 0.6, "LHipRoll": -0.6}.get(j, 0.0) for j in robot.joint_names])
    assert min(_min_gaps(robot, crossed).values()) < 0, "the independent check sees the legs overlap"
    with pytest.raises(WolfcalError, match="crossed: .* would touch"):
        check_collisions(robot, script, path, start={})
    first = load_poses(path, joint_limits(robot, robot.config.servos.ids)).poses[:1]
    assert check_collisions(robot, type(script)(first, script.velocity), path, start={}) is None


def test_simulate_renders_a_capture_at_the_planned_poses(robot, small_plan, tmp_path):
    from wolfcal.encoders import RAD_PER_TICK
    from wolfcal.io.reader import read_capture
    from wolfcal.sim.simulate import SimOptions, simulate_capture

    options, plan = small_plan
    path = tmp_path / "plan.yaml"
    path.write_text(poses_text(robot, plan, options))
    out = tmp_path / "sim.mcap"
    simulate_capture(WOLFGANG, out, SimOptions(poses=path, binning=8, offsets="legs"), say=lambda _m: None)
    samples = read_capture(out, robot.config).samples
    assert len(samples) == len(plan.q)
    for sample, q in zip(samples, plan.q):
        reading = sample.joint_positions(robot.joint_names)  # the readings are the commanded targets, to the tick
        np.testing.assert_allclose(reading, q, atol=RAD_PER_TICK)
