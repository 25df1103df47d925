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

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"


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
    G[::3, 2:] = 0.0  # candidates with fewer rows (padded with zeros at the end, as `factors` packs them)
    G[1::7, 1:] = 0.0
    G[4] = 0.0  # a candidate that tells nothing
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
    path.write_text(
        "poses:\n- {name: apart, joints: {RHipRoll: -0.3, LHipRoll: 0.3}}\n"
        "- {name: crossed, joints: {RHipRoll: 0.6, LHipRoll: -0.6}}\n"
    )
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


def _box_stl(path: Path, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """An ASCII STL of an axis-aligned box (written here, independently of trimesh); returns its 8 corners."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]  # fmt: skip
    lines = ["solid box"]
    for f in faces:
        lines += ["facet normal 0 0 0", "outer loop", *(f"vertex {c[0]} {c[1]} {c[2]}" for c in corners[list(f)]),
                  "endloop", "endfacet"]  # fmt: skip
    path.write_text("\n".join(lines + ["endsolid box"]) + "\n")
    return corners


def test_urdf_collision_meshes_and_primitives_are_bounded_by_capsules(tmp_path):
    from wolfcal.geometry import transform_from_xyz_rpy
    from wolfcal.robot.collision import segment_distance
    from wolfcal.robot.collision_sources import collision_model
    from wolfcal.robot.collision_urdf import BOX_SLACK_M

    robot0 = load_robot(WOLFGANG)
    ankle = {side: robot0.model.joints[f"{side}AnklePitch"].T_parent_origin[:3, 3] for side in "RL"}
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    # each lower leg: a 3 x 3 cm box from the knee to the ankle joint, in the mesh's own frame along x, placed by the
    # <collision> origin (rotated so that x runs along the shin), plus a 1.5 scale on a half-size mesh for the left
    length = float(np.linalg.norm(ankle["R"]))
    corners = _box_stl(meshes / "shin.stl", np.array([0.0, -0.015, -0.015]), np.array([length, 0.015, 0.015]))
    _box_stl(meshes / "shin_half.stl", np.array([0.0, -0.015, -0.015]) / 1.5, np.array([length, 0.015, 0.015]) / 1.5)
    collisions = {}
    for side, mesh, scale in (("R", "shin.stl", "1 1 1"), ("L", "shin_half.stl", "1.5 1.5 1.5")):
        d = ankle[side] / np.linalg.norm(ankle[side])
        yaw, pitch = np.arctan2(d[1], d[0]), -np.arcsin(d[2])
        link = f"{side.lower()}_lower_leg"
        collisions[link] = (f'<collision><origin xyz="0 0 0" rpy="0 {pitch} {yaw}"/><geometry>'
                            f'<mesh filename="package://wolfgang_description/meshes/{mesh}" scale="{scale}"/>'
                            "</geometry></collision>", transform_from_xyz_rpy([0, 0, 0], [0, pitch, yaw]))  # fmt: skip
    collisions["torso"] = ('<collision><origin xyz="0 0 0.05" rpy="0 0 0"/><geometry><box size="0.1 0.16 0.2"/>'
                           "</geometry></collision>", None)  # fmt: skip
    collisions["head"] = ('<collision><geometry><sphere radius="0.05"/></geometry></collision>', None)
    text = (WOLFGANG / "wolfgang.urdf").read_text()
    for link, (xml, _) in collisions.items():
        text = text.replace(f'<link name="{link}"/>', f'<link name="{link}">{xml}</link>')
    package = tmp_path / "wolfgang_description"
    package.mkdir()
    (meshes).rename(package / "meshes")
    (package / "robot.urdf").write_text(text)
    path = _config_copy(tmp_path, lambda d: (d.update(urdf=str(package / "robot.urdf")), d.pop("collision_radii")))
    robot = load_robot(path)
    model = collision_model(robot)
    assert "<collision>" in model.source
    by_link: dict[str, list] = {}
    for c in model.capsules:
        by_link.setdefault(c.link, []).append(c)
    assert set(by_link) == set(collisions)

    def covered(points: np.ndarray, link: str) -> np.ndarray:  # each point inside one of the link's capsules
        return np.any([segment_distance(points, points, c.a_link, c.b_link) <= c.radius + 1e-9
                       for c in by_link[link]], axis=0)  # fmt: skip

    grid = np.stack(np.meshgrid(*[np.linspace(0, 1, 7)] * 3, indexing="ij"), -1).reshape(-1, 3)
    for side in "RL":  # the shin: capsules over its full length, containing the box, at most BOX_SLACK_M thicker
        link = f"{side.lower()}_lower_leg"
        T = collisions[link][1]
        box = (corners.min(0) + grid * (corners.max(0) - corners.min(0))) @ T[:3, :3].T
        assert covered(box, link).all()
        for c in by_link[link]:
            assert np.linalg.norm(c.b_link - c.a_link) == pytest.approx(length, abs=1e-6)
            assert c.radius - 0.015 <= BOX_SLACK_M + 1e-12
    torso_box = np.array([-0.05, -0.08, -0.05]) + grid * np.array([0.1, 0.16, 0.2])  # centred at z = 0.05
    assert covered(torso_box, "torso").all()
    assert all(c.radius - 0.05 <= BOX_SLACK_M + 1e-12 for c in by_link["torso"])  # not one capsule 9.4 cm thick
    beyond = np.array([[0.05 + BOX_SLACK_M + 0.001, 0.0, 0.05]])  # just off the middle of the torso's front face
    assert not covered(beyond, "torso").any()
    head = by_link["head"][0]
    assert head.radius == 0.05 and np.allclose(head.a_link, head.b_link)
    # the shins (5.6 cm apart at rest) cross when the hips roll inwards
    crossed = np.array([{"RHipRoll": 0.45, "LHipRoll": -0.45}.get(j, 0.0) for j in robot.joint_names])
    assert set(model.colliding_pair(crossed) or ()) == {"r_lower_leg", "l_lower_leg"}
    assert model.colliding_pair(np.zeros(len(robot.joint_names))) is None


def test_plan_information_is_the_fits_and_counts_the_repeated_torso_view_once(robot):
    """The selection's information (per-pose rows + the repeated views) equals the fit's own on the chosen poses,
    with the torso tag's repeating detection error: n views of it tell far less than n times one view."""
    from wolfcal.plan.candidates import draw_candidates, plan_camera
    from wolfcal.plan.information import PlanModel, factors, repeated_information
    from wolfcal.plan.pipeline import used_tags
    from wolfcal.robot.collision_sources import collision_model

    options = PlanOptions(free="leg", system="external", poses=6, candidates=30)
    camera = plan_camera(robot, "external")
    tags = used_tags(robot, options, True)
    cands = draw_candidates(robot, camera, tags, 30, np.random.default_rng(2), collision_model(robot))
    model = PlanModel(robot, camera, "leg", "both", tags)
    problem = model.problem(cands.q, cands.visible, independent=True)
    G = factors(problem)
    chosen = [3, 7, 11, 19, 23, 29]
    M_rep = repeated_information(model, problem, cands.q, cands.visible, len(chosen))
    fit = model.problem(cands.q[chosen], cands.visible[chosen])  # the fit's problem, its full noise model
    J = np.asarray(fit.data_jacobian(np.zeros(len(fit.params)), robust=False))
    M_fit = np.eye(len(fit.params)) + J.T @ J
    np.testing.assert_allclose(information(G, chosen, M_rep), M_fit, atol=1e-6 * np.abs(M_fit).max())
    # n views with noise sigma and a repeating error tau (= sigma, priors.pixel_noise) tell n / (sigma^2 + n tau^2):
    # 6 views 6/7 of what one view tells without its repeating error, where 6 independent views would tell 6 times
    one = repeated_information(model, problem, cands.q, cands.visible, 1)
    np.testing.assert_allclose(M_rep, one * 6 / 7, atol=1e-9 * np.abs(one).max())


def test_capsule_distances_are_exact_where_they_matter(robot):
    """The midpoint prefilter of the capsule pairs changes no distance below its limit (brute force on all pairs)."""
    from wolfcal.robot.collision import EXACT_BELOW_M, segment_distance
    from wolfcal.robot.collision_sources import collision_model

    model = collision_model(robot)
    q = np.random.default_rng(1).uniform(-1, 1, size=(2000, len(robot.joint_names)))
    a, b = model.segments(q)
    i, j = model.pairs.T
    exact = segment_distance(a[:, i], b[:, i], a[:, j], b[:, j]) - model.radius[i] - model.radius[j]
    fast = model._pair_clearance(q)
    near = exact < EXACT_BELOW_M
    assert near.any() and (~near).any()
    np.testing.assert_allclose(fast[near], exact[near], atol=1e-12)
    assert np.all(fast[~near] >= EXACT_BELOW_M - 1e-12) and np.all(fast <= exact + 1e-12)


def test_collision_checks_split_by_the_head_joints_are_exact(robot):
    """The candidate draw checks the pairs the head does not move once per leg configuration and the others per
    head configuration: together (and in the early-exit order) they keep exactly the poses with clearance."""
    from wolfcal.plan.candidates import CLEARANCE_M
    from wolfcal.robot.collision_sources import collision_model

    model = collision_model(robot)
    rng = np.random.default_rng(4)
    q = rng.uniform(-1.2, 1.2, size=(3000, len(robot.joint_names)))
    head = ["HeadPan", "HeadTilt"]
    moved = model.pairs_moved_by(head)
    assert moved.any() and (~moved).any()
    full = model.clearance(q) >= CLEARANCE_M
    assert full.any() and (~full).any()
    np.testing.assert_array_equal(model.collision_free(q, CLEARANCE_M), full)
    split = model.collision_free(q, CLEARANCE_M, ~moved) & model.collision_free(q, CLEARANCE_M, moved)
    np.testing.assert_array_equal(split, full)
    # the pairs the head does not move keep their distance whatever the head does; the others do not
    q2 = q.copy()
    q2[:, [robot.joint_names.index(j) for j in head]] = rng.uniform(-1.2, 1.2, size=(len(q), 2))
    d1, d2 = model._pair_clearance(q), model._pair_clearance(q2)
    np.testing.assert_allclose(d1[:, ~moved], d2[:, ~moved], atol=1e-12)
    assert np.all(np.abs(d1[:, moved] - d2[:, moved]).max(axis=0) > 1e-6)


def test_candidates_drawn_by_parts_pass_every_check_and_head_views_match_full_fk(robot):
    """Legs drawn once for many head configurations: every candidate passes the full checks (all capsule pairs,
    tags in view by a full forward-kinematics pass, line of sight), and the head views from the legs' tag poses
    equal those of a full pass."""
    from wolfcal.plan.candidates import (
        CLEARANCE_M,
        base_tag_poses,
        draw_candidates,
        line_of_sight,
        plan_camera,
        pose_ok,
        tag_views,
    )
    from wolfcal.plan.pipeline import used_tags
    from wolfcal.robot.collision_sources import collision_model

    model = collision_model(robot)
    camera = plan_camera(robot, "head")
    tags = used_tags(robot, PlanOptions(), False)
    cands = draw_candidates(robot, camera, tags, 300, np.random.default_rng(5), model)
    assert len(cands.q) == 300
    assert cands.drawn >= sum(cands.rejected.values()) + len(cands.q)  # every configuration drawn is accounted for
    assert np.all(model.clearance(cands.q) >= CLEARANCE_M)
    views = tag_views(robot, camera, cands.q, tags) & line_of_sight(robot, camera, cands.q, model)
    np.testing.assert_array_equal(views, cands.visible)
    assert pose_ok(robot, camera, views).all()
    ids = [t for t in robot.config.tag_ids if t in tags]
    q = np.random.default_rng(6).uniform(-1.5, 1.5, size=(500, len(robot.joint_names)))
    np.testing.assert_array_equal(
        tag_views(robot, camera, q, tags, base_tag_poses(robot, q, ids)), tag_views(robot, camera, q, tags)
    )
    # the head is drawn uniformly: the candidates' head angles spread over the range that shows the feet
    pan = cands.q[:, robot.joint_names.index("HeadPan")]
    assert pan.min() < -0.3 and pan.max() > 0.3


def test_criterion_looks_at_the_parameters_of_interest_and_marginalises_the_others():
    """Ds-optimality: with the tags' mounts left out of the criterion, the basis has no component on them, and the
    criterion is the covariance of the other unknowns with the tags' uncertainty marginalised (not fixed)."""
    from wolfcal.plan.information import separability

    rng = np.random.default_rng(7)
    G = rng.normal(size=(50, 4, 6))
    G[:, :, 5] = G[:, :, 4]  # unknowns 4 and 5 only ever move together: their difference is not observable
    interest = np.array([True, True, False, True, False, False])
    sep = separability(G, 6, None, interest)
    assert sep.basis.shape == (6, 3) and np.allclose(sep.basis[~interest], 0.0)
    M = information(G, [0, 1, 2])
    C = np.linalg.inv(M)
    idx = np.flatnonzero(interest)
    expected = np.linalg.slogdet(C[np.ix_(idx, idx)])[1]  # marginal covariance of the unknowns of interest
    assert np.isclose(criterion_value(M, sep.basis, "D"), expected)


def _fit_information(problem) -> np.ndarray:
    J = np.asarray(problem.data_jacobian(np.zeros(len(problem.params)), robust=False))
    return np.eye(len(problem.params)) + J.T @ J


def test_mocap_plan_information_is_the_fits_and_its_poses_are_valid(robot, tmp_path):
    """--system mocap: the selection's information on chosen poses equals the fit's MocapBlock problem (base pose and
    marker mounts its nuisance); the written poses move the leg joints only, inside the limits, apart; each ankle
    roll is named with its foot markers' mounts (a rotation about the ankle-roll axis moves the foot's markers as
    their mounts can)."""
    from wolfcal.plan.information import factors
    from wolfcal.plan.mocap import MocapPlanModel, draw_mocap_candidates, used_markers
    from wolfcal.robot.collision_sources import collision_model

    markers = used_markers(robot, "leg", "right")
    assert markers and all(robot.config.marker_config().marker(m).side in ("right", None) for m in markers)
    cands = draw_mocap_candidates(robot, markers, 40, np.random.default_rng(1), collision_model(robot))
    model = MocapPlanModel(robot, "leg", "right", markers)
    problem = model.problem(cands.q, cands.visible, independent=True)
    chosen = [2, 5, 11, 17, 23, 31]
    M_rep = model.repeated_information(problem, cands.q, cands.visible, len(chosen))
    M_fit = _fit_information(model.problem(cands.q[chosen], cands.visible[chosen]))
    np.testing.assert_allclose(information(factors(problem), chosen, M_rep), M_fit, atol=1e-6 * np.abs(M_fit).max())
    assert any(n.startswith("marker.") for n in problem.params.names) and "mocap.x" in problem.params.names

    options = PlanOptions(free="leg", side="both", system="mocap", poses=6, candidates=150, seed=2)
    plan = make_plan(robot, options, say=lambda _m: None)
    path = tmp_path / "mocap.yaml"
    path.write_text(poses_text(robot, plan, options))
    script = load_poses(path, joint_limits(robot, robot.config.servos.ids))
    assert len(script.poses) == 6 and not {"HeadPan", "RElbow"} & set(plan.joints)
    rest_gaps = _min_gaps(robot, np.zeros(len(robot.joint_names)))
    for pose in script.poses:
        gaps = _min_gaps(robot, np.array([pose.joints.get(j, 0.0) for j in robot.joint_names]))
        assert not {k: v for k, v in gaps.items() if v < 0 and rest_gaps[k] >= 0.005}, pose.name
    groups = [g for g in plan.groups if "RAnkleRoll.offset" in g]
    assert groups and any(n.startswith("marker.r_foot") for n in groups[0]), plan.groups
    assert plan.worst_std(plan.planned, "rad") <= plan.worst_std(plan.random, "rad")


def test_floor_plan_information_is_the_fits_and_every_planned_tag_is_seen_twice(robot, tmp_path):
    """--system floor: the candidates' floor-block rows plus the sole closure of n samples equal the fit's floor
    blocks (`fit.pipeline.floor_blocks`) on those n poses; the legs stand still at floor.standing in every pose, only
    the head moves, every floor tag in view lies whole in the image, and no tag is seen once (the fit refuses it)."""
    from wolfcal.fit.floor_block import FloorBlock, SoleClosure
    from wolfcal.plan.candidates import plan_camera
    from wolfcal.plan.floor import FloorPlanModel, PosewiseFloorBlock, draw_floor_candidates, expected_places
    from wolfcal.plan.information import factors, plan_problem
    from wolfcal.robot.collision_sources import collision_model

    camera, places = plan_camera(robot, "head"), expected_places(robot)
    cands = draw_floor_candidates(robot, camera, places, 60, np.random.default_rng(4), collision_model(robot))
    standing = {"RKnee": -0.2618, "LKnee": 0.2618}
    legs = [j for j in cands.joints if not j.startswith("Head")]
    for j in legs:
        np.testing.assert_allclose(cands.q[:, robot.model.column(j)], standing.get(j, 0.0))
    assert np.ptp(cands.q[:, robot.model.column("HeadPan")]) > 0.3
    # the corners the plan counts lie inside the image (independently: project and compare with the frame)
    model = FloorPlanModel(robot, camera, "head_camera", "both", places)
    obs = model.observations(cands.q, cands.visible)
    assert np.all((obs.uv > 0) & (obs.uv < [camera.model.width, camera.model.height]))
    chosen = list(range(40))
    assert np.all(cands.visible[chosen].sum(axis=0) >= 2) and cands.visible.any(axis=0).all()
    problem = model.problem(cands.q, cands.visible, independent=True)
    M_rep = model.repeated_information(problem, cands.q[chosen], cands.visible[chosen], len(chosen))
    fit = model.problem(cands.q[chosen], cands.visible[chosen])
    assert [type(b) for b in fit.blocks] == [FloorBlock, SoleClosure] and fit.params.names == problem.params.names
    # the selection adds up the poses: the fit's blocks with each pose's leg readings its own error
    posewise = plan_problem(model.chain(), [PosewiseFloorBlock(robot, fit.blocks[0].obs), fit.blocks[1]],
                            [s.sigma for s in fit.states], robot.config.priors.encoder_noise)  # fmt: skip
    M_fit = _fit_information(posewise)
    np.testing.assert_allclose(information(factors(problem), chosen, M_rep), M_fit, atol=1e-6 * np.abs(M_fit).max())

    options = PlanOptions(free="head_camera", system="floor", poses=5, candidates=200, seed=1)
    plan = make_plan(robot, options, say=lambda _m: None)
    views = plan.candidates.visible[[int(np.flatnonzero((plan.candidates.q == q).all(axis=1))[0]) for q in plan.q]]
    assert not np.any(views.sum(axis=0) == 1), views.sum(axis=0)
    text = poses_text(robot, plan, options)
    assert "floor tags lying face up" in text and "tag 50 at x" in text
    named = {name for group in plan.groups for name in group}
    assert "HeadPan.offset" in named, "the floor tags' unknown places take any yaw of the head"


def test_cover_twice_exchanges_a_pose_so_no_column_is_seen_once():
    from wolfcal.plan.select import cover_twice

    rng = np.random.default_rng(3)
    G = rng.normal(size=(30, 2, 5))
    shows = np.zeros((30, 3), dtype=bool)
    shows[:, 0] = True
    shows[7, 1] = True  # column 1 only in candidates 7 and 19
    shows[19, 1] = True
    shows[[3, 4], 2] = True
    basis = np.eye(5)
    fixed = cover_twice(G, [7, 0, 1, 2], shows, ["a", "b", "c"], basis)
    assert len(set(fixed)) == 4 and not np.any(shows[fixed].sum(axis=0) == 1)
    with pytest.raises(WolfcalError, match="b seen once"):
        cover_twice(G, [7], shows[:, :2], ["a", "b"], basis)  # one pose: column a is seen once whatever it is


@pytest.mark.parametrize(
    "system,edit,message",
    [
        ("mocap", lambda d: d.pop("markers"), "add 'markers:'"),
        ("floor", lambda d: d["floor"].update(tags=[]), "lists no floor tag"),
        ("floor", lambda d: d.pop("floor"), "has no 'floor:'"),
    ],
)
def test_mocap_and_floor_plans_without_markers_or_floor_tags_are_refused(tmp_path, system, edit, message):
    out = tmp_path / "p.yaml"
    path = _config_copy(tmp_path, edit)
    result = CliRunner().invoke(app, ["plan", "--robot", str(path), "--system", system, "--out", str(out)])
    assert result.exit_code != 0 and "Traceback" not in result.output and not out.exists()
    assert message in result.output, result.output


def test_mocap_plan_for_the_head_camera_is_refused(tmp_path):
    result = CliRunner().invoke(
        app,
        [
            "plan",
            "--robot",
            str(WOLFGANG),
            "--system",
            "mocap",
            "--free",
            "head_camera",
            "--out",
            str(tmp_path / "p.yaml"),
        ],
    )
    assert result.exit_code != 0 and "motion capture cannot see" in result.output


def test_plan_predicts_the_std_the_fit_reports_on_what_the_poses_decide(robot):
    """The plan whitens with the configured pixel noise (not the quantisation spread of its noise-free readings), and
    at the fit's noise level it predicts the std the fit reports at a true kinematics, once the unseparable direction
    (HeadTilt.offset ~ the camera's rotation about the tilt axis) is known exactly: at the truth the camera's rotation
    correction turns that direction so that camera.ry and camera.rz share the prior held along it."""
    from wolfcal.evaluate.accuracy import camera_pose_errors
    from wolfcal.fit.pipeline import FitOptions, fit_observations
    from wolfcal.plan.candidates import draw_candidates, plan_camera
    from wolfcal.plan.information import PlanModel, fit_null_directions, fit_separated_std, predicted
    from wolfcal.plan.pipeline import used_tags
    from wolfcal.projection import observations_from_poses
    from wolfcal.robot.collision_sources import collision_model
    from wolfcal.robot.corrections import Corrections

    options = PlanOptions(free="head_camera", system="head")
    camera = plan_camera(robot, "head")
    tags = used_tags(robot, options, False)
    cands = draw_candidates(robot, camera, tags, 40, np.random.default_rng(5), collision_model(robot))
    idx = np.arange(10)
    seen = [t for t in tags if cands.visible[idx, robot.config.tag_ids.index(t)].any()]  # the tags the fit will see
    model = PlanModel(robot, camera, "head_camera", "both", seen)
    plan_problem = model.problem(cands.q[idx], cands.visible[idx])
    assert [s.sigma for s in plan_problem.states] == [robot.config.priors.pixel_noise]

    rng = np.random.default_rng(7)
    head = {"HeadPan": 0.02, "HeadTilt": -0.015}
    truth = Corrections(
        offsets=head,
        frames={robot.camera_joint: np.array([0.002, -0.001, 0.002, -0.06, 0.02, 0.08])},
        tags={t: np.array([0.001, 0.0, -0.001, 0.005, -0.004, 0.006]) for t in seen},
    )
    q_true = cands.q[idx] + truth.offset_vector(robot.joint_names)
    T = robot.camera_and_tag_poses(q_true, robot.config.tag_ids, Corrections(frames=truth.frames, tags=truth.tags))[1]
    obs = observations_from_poses(robot, camera.model, truth, q_true, T, cands.visible[idx], 0.2, rng, camera.name)
    fit = fit_observations(robot, obs, FitOptions(free="head_camera", system="head"))
    assert fit.params.names == plan_problem.params.names
    for state, fitted in zip(plan_problem.states, fit.problem.states):
        state.set_sigma(fitted.sigma)
    expected = predicted(plan_problem).std
    separated, reported = fit_separated_std(fit), fit.solution.std
    for name in ("camera.x", "camera.ry", "camera.rz", "HeadPan.offset"):
        i = fit.params.names.index(name)
        assert separated[i] == pytest.approx(expected[i], rel=0.05), name
    ry = fit.params.names.index("camera.ry")
    assert reported[ry] > 1.5 * separated[ry], "the turned unseparable direction lends camera.ry its prior"

    # the direction it takes as known (`fit_null_directions`): one, HeadTilt.offset against camera.rx, along which
    # the camera's pose in the base frame does not change over the head's range
    null = fit_null_directions(fit)
    assert null.shape == (len(fit.params), 1)
    largest = {fit.params.names[i] for i in np.argsort(-np.abs(null[:, 0]))[:2]}
    assert largest == {"HeadTilt.offset", "camera.rx"}
    c, sigma = len(fit.chain), fit.params.prior_sigmas[: len(fit.chain)]
    values = fit.solution.values[:c]
    moved = fit.chain.corrections(values + 0.1 * sigma * null[:c, 0])
    rotation, position = camera_pose_errors(robot, moved, fit.chain.corrections(values))
    tilt = fit.params.names.index("HeadTilt.offset")
    assert rotation.max() < 0.02 * abs(0.1 * sigma[tilt] * null[tilt, 0])
    assert position.max() < 1e-5
