"""Planned against random poses: accuracy of the fit and the std it reports, and the time planning takes.

Scenarios (Wolfgang, 2048x1536 head camera / 1280x720 tripod webcam at the expected placement): `leg` (--free leg
--side both, head camera, 0.025 rad rms offsets on head and legs), `head_camera` (head camera, offsets on the head),
`external` (--free leg, tripod camera, offsets on the legs), `mocap` (--free leg, motion capture, offsets on the
legs: every marker at its true place, mounts off by 1 mm per axis, 0.3 mm noise, 3 % occluded, 1 % reflections,
the robot anywhere in the motion-capture frame), `floor` (--free head_camera, head camera views of the floor tags
while the robot stands, offsets on the head; the tags laid within 5 cm and 0.3 rad of the layout the plan prints).
Per seed: a random truth; 12 planned poses (2000 candidates, `--criterion`, default the plan's) against 30 and 12
random valid candidates. Observations are tag corners projected at the true kinematics with 0.15 px Gaussian
noise (marker positions for `mocap`) and quantised encoder readings (no rendering; `wolfcal simulate --poses`
renders a plan, see tests/plan/test_plan.py), fitted by `fit_observations`.
Reported, median over the seeds:
- true error: sole position max over 500 random leg poses (leg presets), or camera position and rotation max over
  the head range; raw, and with the estimate's error along the directions its data do not inform removed
  (`without_unseparable`: an ankle roll against its foot tag's or markers' mounts, HeadTilt against the camera
  mount, HeadPan against the floor tags' places: they keep their prior whatever the poses, and the issue does not
  count them), with the paired difference planned12 - random30 per seed (median, 90 % bootstrap interval, wins);
- the worst reported std among the observable parameters other than the tags' mounts (what a calibration
  delivers; the criterion marginalises the mounts), 12 random / 12 planned, as reported and with the directions no
  pose informs known exactly (`fit_separated_std` on the fit's own Jacobian at its solution: there the truth's
  camera rotation turns the unseparable HeadTilt ~ camera.rx group so that it lends its prior to camera.ry and
  camera.rz, alike for every pose set); the count of such directions per fit (the same for every pose set);
- planning time.
`--timing`: CPU and wall time of planning 20 of 2000 candidates per system and criterion, with the load average.
Run: python bench/bench_plan.py [--seeds 5] [--scenarios leg head_camera external mocap floor] [--criterion D|I]
     [--timing]
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from wolfcal.encoders import encoder_readings
from wolfcal.evaluate.accuracy import camera_pose_errors, link_position_errors
from wolfcal.external_view import external_tag_poses
from wolfcal.fit.pipeline import FitOptions, fit_observations
from wolfcal.geometry import invert_transform, tag_corners, transform_from_xyz_rpy
from wolfcal.markers import MarkerObservations
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.plan.candidates import plan_camera
from wolfcal.plan.floor import expected_places
from wolfcal.plan.information import fit_null_directions, fit_separated_std
from wolfcal.plan.pipeline import PlanOptions, make_plan
from wolfcal.projection import (
    observations_from_poses,
    tag_corner_pixels,
)
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor, floor_tag_poses
from wolfcal.robot.robot import load_robot
from wolfcal.sim.mocap_scene import MocapNoise, measure, true_marker_positions
from wolfcal.sim.simulate import offset_joints
from wolfcal.sim.truth import TruthSpec, random_truth

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
SCENARIOS = {"leg": ("head", "leg", "all"), "head_camera": ("head", "head_camera", "head"),
             "external": ("external", "leg", "legs"), "mocap": ("mocap", "leg", "legs"),
             "floor": ("floor", "head_camera", "head")}  # fmt: skip
NOISE_PX = 0.15
PLACE_JITTER_M, PLACE_YAW_RAD = 0.05, 0.3  # floor tags laid near the plan's layout: uniform +- per axis, yaw
SETS = ("planned12", "random30", "random12")
# per pose set: (true error raw, true error with the unseparable part removed [m, or rad for the camera rotation])
# and the worst std [m, rad] among the observable chain parameters other than the tags' mounts, raw and separated
METRICS = ("error", "error_observable", "rotation", "rotation_observable", "std_m", "std_rad", "separated_m",
           "separated_rad", "null")  # fmt: skip


def observe(robot, plan, system: str, truth: Corrections, idx: np.ndarray, camera, rng):
    """(camera observations, marker observations) of candidates idx at the true kinematics (readings = the
    commanded targets, true angles = readings + true offsets)."""
    q_true = plan.candidates.q[idx] + truth.offset_vector(robot.joint_names)
    frames = Corrections(frames=truth.frames, tags=truth.tags)
    if system == "mocap":
        return {}, observe_markers(robot, truth, q_true, rng)
    if system == "floor":
        return {HEAD_CAMERA: observe_floor(robot, plan, truth, q_true, plan.candidates.visible[idx], camera, rng)}, None
    if camera.external:
        T = external_tag_poses(robot, camera.T_base_camera, q_true, frames, robot.config.tag_ids)
    else:
        T = robot.camera_and_tag_poses(q_true, robot.config.tag_ids, frames)[1]
    obs = observations_from_poses(robot, camera.model, truth, q_true, T, plan.candidates.visible[idx], NOISE_PX,
                                  rng, camera.name)  # fmt: skip
    return {camera.name: obs}, None


def readings(robot, truth: Corrections, q_true: np.ndarray) -> np.ndarray:
    """The quantised encoder readings [rad] of true angles q_true (N, J)."""
    return encoder_readings(q_true, truth.offset_vector(robot.joint_names))


def observe_markers(robot, truth: Corrections, q_true: np.ndarray, rng) -> MarkerObservations:
    """Every configured marker at the true kinematics, mounts off by MocapNoise.mount_sigma per axis, the robot
    somewhere in the motion-capture frame; measured with the simulator's noise, occlusions and reflections."""
    noise = MocapNoise()
    markers = robot.config.marker_config()
    mounts = rng.normal(0.0, noise.mount_sigma, (len(markers.entries), 3))
    T_mocap_base = transform_from_xyz_rpy(rng.uniform(-1, 1, 3) + [0, 0, 0.8],
                                          [*rng.normal(0, 0.05, 2), rng.uniform(-np.pi, np.pi)])  # fmt: skip
    p, _ = measure(true_marker_positions(robot, q_true, truth, mounts, T_mocap_base), noise, rng)
    s, k = np.nonzero(np.all(np.isfinite(p), axis=2))
    return MarkerObservations(
        joint_names=list(robot.joint_names), q_measured=readings(robot, truth, q_true),
        stamps_ns=np.arange(len(q_true), dtype=np.int64) * 10**9, sources=["bench"] * len(q_true),
        marker_names=list(markers.names), sample_index=s, marker_index=k, xyz=p[s, k],
    )  # fmt: skip


def observe_floor(robot, plan, truth: Corrections, q_true: np.ndarray, visible: np.ndarray, camera, rng):
    """Head-camera corners of the floor tags the plan expects in view (visible (N, T) over floor.tag_ids; a tag
    seen once left out, as the fit refuses it), each laid near the plan's layout, on the floor of the true soles."""
    floor = robot.config.floor_config()
    places = {t: p + rng.uniform([-PLACE_JITTER_M, -PLACE_JITTER_M, -PLACE_YAW_RAD],
                                 [PLACE_JITTER_M, PLACE_JITTER_M, PLACE_YAW_RAD])
              for t, p in expected_places(robot).items()}  # fmt: skip
    frames = Corrections(frames=truth.frames, tags=truth.tags)
    T_floor_camera, _ = camera_in_floor(robot, q_true, frames)
    T_floor_tag = floor_tag_poses(robot, places)
    visible = visible & (visible.sum(axis=0) >= 2)
    s, t = np.nonzero(visible)
    ids = np.array(floor.tag_ids)[t]
    T_camera_tag = invert_transform(T_floor_camera[s]) @ np.stack([T_floor_tag[i] for i in ids])
    corners = np.stack([tag_corners(floor.tag(i).size) for i in ids])
    uv = tag_corner_pixels(camera.model, T_camera_tag, corners) + rng.normal(0.0, NOISE_PX, (len(s), 4, 2))
    return Observations(
        joint_names=list(robot.joint_names), q_measured=readings(robot, truth, q_true),
        stamps_ns=np.arange(len(q_true), dtype=np.int64), sources=["bench"] * len(q_true), camera=camera.model,
        sample_index=np.repeat(s, 4), tag_ids=np.repeat(ids, 4), corner_index=np.tile(np.arange(4), len(s)),
        uv=uv.reshape(-1, 2),
    )  # fmt: skip


def run(name: str, seed: int, criterion: str | None = None) -> dict:
    system, free, offsets = SCENARIOS[name]
    robot = load_robot(CONFIG)
    rng = np.random.default_rng(100 + seed)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, offsets)), rng)
    start, cpu = time.perf_counter(), time.process_time()
    options = PlanOptions(free=free, system=system, poses=12, seed=seed, criterion=criterion)
    plan = make_plan(robot, options, say=lambda _m: None)
    planning, planning_cpu = time.perf_counter() - start, time.process_time() - cpu
    camera = plan_camera(robot, "head" if system in ("mocap", "floor") else system)
    chosen = np.flatnonzero((plan.candidates.q[:, None, :] == plan.q[None]).all(axis=2).any(axis=1))
    others = rng.permutation(np.setdiff1d(np.arange(len(plan.candidates.q)), chosen))
    out = {"planning_s": planning, "planning_cpu_s": planning_cpu}
    for label, idx in zip(SETS, (chosen, others[:30], others[:12])):
        observations, markers = observe(robot, plan, system, truth, idx, camera, rng)
        fit_system = None if system == "floor" else system
        fit = fit_observations(robot, observations, FitOptions(free=free, system=fit_system), markers=markers)
        observable = without_unseparable(fit, truth)
        rot = rot_observable = 0.0
        if free == "leg":
            err, err_observable = sole_error(robot, fit.corrections, truth, seed), sole_error(robot, observable, truth,
                                                                                             seed)  # fmt: skip
        else:
            rot_errors, pos_errors = camera_pose_errors(robot, fit.corrections, truth)
            err, rot = pos_errors.max(), rot_errors.max()
            rot_errors, pos_errors = camera_pose_errors(robot, observable, truth)
            err_observable, rot_observable = pos_errors.max(), rot_errors.max()
        names = fit.params.names[: len(fit.chain)]
        keep = [i for i, n in enumerate(names) if plan.observable[plan.params.names.index(n)]]
        units = np.array([p.unit for p in fit.params.parameters])[keep]
        delivered = np.array([fit.params.parameters[i].kind != "tag" for i in keep])  # not the tags' mounts
        std, separated = fit.solution.std[keep], fit_separated_std(fit)[keep]
        worst = [x[(units == u) & delivered].max(initial=0.0) for x in (std, separated) for u in ("m", "rad")]
        out[label] = dict(zip(METRICS, (err, err_observable, rot, rot_observable, *worst,
                                        fit_null_directions(fit).shape[1])))  # fmt: skip
    return out


def sole_error(robot, estimate: Corrections, truth: Corrections, seed: int) -> float:
    """Largest sole position error [m] over 500 random leg poses, both soles."""
    return max(link_position_errors(robot, s, estimate, truth, 500, np.random.default_rng(seed)).max()
               for s in ("r_sole", "l_sole"))  # fmt: skip


def without_unseparable(fit, truth: Corrections) -> Corrections:
    """The fit's estimate with its error along the directions its data do not inform removed: moved along them
    (`fit_null_directions`, the same directions `fit_separated_std` takes as known) to the chain values nearest
    the truth in prior-normalised units. Such a direction is an exact equivalence of everything measured (an ankle
    roll against its foot tag's or markers' mounts, HeadTilt against the camera mount, HeadPan against the floor
    tags' places), so the estimate stays at the prior along it whatever the poses; what remains is the error the
    poses decide. The chain's tags' mounts count; the blocks' own unknowns (marker mounts, floor tag places, an
    external camera's pose) have no truth here and are left as fitted."""
    chain = fit.chain
    c, sigma = len(chain), chain.prior_sigmas
    N = fit_null_directions(fit)[:c]  # (c, m) z units
    values = fit.solution.values[:c]
    alpha = np.linalg.lstsq(N, (chain.values_from(truth) - values) / sigma, rcond=1e-9)[0]
    return chain.corrections(values + sigma * (N @ alpha))


def paired(runs: list[dict], metric: str, scale: float) -> str:
    """Paired differences planned12 - random30 of a metric over the seeds: median, 90 % bootstrap interval of the
    median (2000 resamples of the seeds) and how many seeds the planned poses win."""
    d = np.array([r["planned12"][metric] - r["random30"][metric] for r in runs]) * scale
    boot = np.median(np.random.default_rng(0).choice(d, size=(2000, len(d))), axis=1)
    lo, hi = np.percentile(boot, [5, 95])
    return (
        f"median {np.median(d):+.3f} (90 % interval {lo:+.3f} .. {hi:+.3f}), planned better in {(d < 0).sum()} "
        f"of {len(d)}"
    )


def plan(seeds: int, say, scenarios: tuple[str, ...] | None = None) -> dict:
    """Per scenario: each seed's figures (`run`: per pose set the true errors [m, rad], the worst reported and
    separated stds, the null directions; planning wall and CPU time [s]), and the medians over the seeds per pose set
    (METRICS), the paired difference planned12 - random30 of the true error [m], and the median planning time."""
    out = {}
    for name in scenarios or tuple(SCENARIOS):
        runs = [run(name, seed) for seed in range(seeds)]
        for seed, r in enumerate(runs):
            say(f"plan {name} seed {seed}: error planned12 {r['planned12']['error'] * 1000:.2f} mm, random30 "
                f"{r['random30']['error'] * 1000:.2f} mm")  # fmt: skip
        out[name] = {
            "runs": runs,
            "median": {k: {m: float(np.median([r[k][m] for r in runs])) for m in METRICS} for k in SETS},
            "paired_planned12_minus_random30_mm": paired(runs, "error", 1000.0),
            "planning_s": float(np.median([r["planning_s"] for r in runs])),
            "planning_cpu_s": float(np.median([r["planning_cpu_s"] for r in runs])),
        }
    return {"seeds": seeds, "scenarios": out}
