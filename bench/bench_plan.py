"""Planned against random poses: accuracy of the fit and the std it reports, and the time planning takes.

Scenarios (Wolfgang, 2048x1536 head camera / 1280x720 tripod webcam at the expected placement): `leg` (--free leg
--side both, head camera, 0.025 rad rms offsets on head and legs), `head_camera` (head camera, offsets on the head),
`external` (--free leg, tripod camera, offsets on the legs). Per seed: a random truth; 12 planned poses (2000
candidates, D-optimal) against 30 and 12 random valid candidates. Observations are tag corners projected at the true
kinematics with 0.15 px Gaussian noise and quantised encoder readings (no rendering; `wolfcal simulate --poses`
renders a plan, see tests/test_plan.py), fitted by `fit_observations`. Reported: true error (sole position
max over 500 random leg poses, or camera position and rotation max over the head range), median over the seeds;
the worst reported std among the parameters some pose can observe (12 planned vs 12 random), also without the tags'
mounts (what a calibration delivers; the criterion marginalises the mounts), and that again with the directions no
pose informs known exactly (`separated_std` on the fit's own Jacobian at its solution: there the truth's camera
rotation turns the unseparable HeadTilt ~ camera.rx group so that it lends its prior to camera.ry and camera.rz,
alike for every pose set); for the leg scenarios also the sole
error with the offsets no pose separates (the ankle rolls, held at their prior) at their truth; planning time.
`--timing`: CPU and wall time of planning 20 of 2000 candidates per system and criterion, with the load average.
Run: python bench/bench_plan.py [--seeds 5] [--scenarios leg head_camera external] [--timing]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from wolfcal.evaluate.accuracy import camera_pose_errors, link_position_errors  # noqa: E402
from wolfcal.fit.pipeline import FitOptions, fit_observations  # noqa: E402
from wolfcal.plan.candidates import plan_camera  # noqa: E402
from wolfcal.plan.information import fit_separated_std  # noqa: E402
from wolfcal.plan.pipeline import PlanOptions, make_plan  # noqa: E402
from wolfcal.robot.corrections import Corrections  # noqa: E402
from wolfcal.robot.robot import load_robot  # noqa: E402
from wolfcal.sim.external_poses import external_tag_poses  # noqa: E402
from wolfcal.sim.observations import observations_from_poses  # noqa: E402
from wolfcal.sim.simulate import offset_joints  # noqa: E402
from wolfcal.sim.truth import TruthSpec, random_truth  # noqa: E402

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
SCENARIOS = {"leg": ("head", "leg", "all"), "head_camera": ("head", "head_camera", "head"),
             "external": ("external", "leg", "legs")}  # fmt: skip
NOISE_PX = 0.15


def observe(robot, plan, truth: Corrections, idx: np.ndarray, camera, rng):
    """Observations of candidates idx at the true kinematics (readings = the commanded targets)."""
    q_true = plan.candidates.q[idx] + truth.offset_vector(robot.joint_names)
    frames = Corrections(frames=truth.frames, tags=truth.tags)
    if camera.external:
        T = external_tag_poses(robot, camera.T_base_camera, q_true, frames, robot.config.tag_ids)
    else:
        T = robot.camera_and_tag_poses(q_true, robot.config.tag_ids, frames)[1]
    return observations_from_poses(robot, camera.model, truth, q_true, T, plan.candidates.visible[idx], NOISE_PX,
                                   rng, camera.name)  # fmt: skip


def run(name: str, seed: int) -> dict:
    system, free, offsets = SCENARIOS[name]
    robot = load_robot(CONFIG)
    rng = np.random.default_rng(100 + seed)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, offsets)), rng)
    start, cpu = time.perf_counter(), time.process_time()
    plan = make_plan(robot, PlanOptions(free=free, system=system, poses=12, seed=seed), say=lambda _m: None)
    planning, planning_cpu = time.perf_counter() - start, time.process_time() - cpu
    camera = plan_camera(robot, system)
    chosen = np.flatnonzero((plan.candidates.q[:, None, :] == plan.q[None]).all(axis=2).any(axis=1))
    others = rng.permutation(np.setdiff1d(np.arange(len(plan.candidates.q)), chosen))
    out = {"planning_s": planning, "planning_cpu_s": planning_cpu}
    for label, idx in (("planned12", chosen), ("random30", others[:30]), ("random12", others[:12])):
        obs = observe(robot, plan, truth, idx, camera, rng)
        fit = fit_observations(robot, obs, FitOptions(free=free, system=system))
        rot = observable = 0.0
        if free == "leg":
            err = sole_error(robot, fit.corrections, truth, seed)
            observable = sole_error(robot, prior_held_at_truth(fit, plan, truth), truth, seed)
        else:
            rot_errors, pos_errors = camera_pose_errors(robot, fit.corrections, truth)
            err, rot = pos_errors.max(), rot_errors.max()
        names = fit.params.names[: len(fit.chain)]
        keep = [i for i, n in enumerate(names) if plan.observable[plan.params.names.index(n)]]
        units = np.array([p.unit for p in fit.params.parameters])[keep]
        std = fit.solution.std[keep]
        delivered = np.array([fit.params.parameters[i].kind != "tag" for i in keep])  # not the tags' mounts
        worst = [std[(units == u) & delivered].max(initial=0.0) for u in ("m", "rad")]
        separated = fit_separated_std(fit)[keep]
        worst_separated = [separated[(units == u) & delivered].max(initial=0.0) for u in ("m", "rad")]
        out[label] = (err, std[units == "m"].max(), std[units == "rad"].max(), rot, observable, *worst,
                      *worst_separated)
    return out


def sole_error(robot, estimate: Corrections, truth: Corrections, seed: int) -> float:
    """Largest sole position error [m] over 500 random leg poses, both soles."""
    return max(link_position_errors(robot, s, estimate, truth, 500, np.random.default_rng(seed)).max()
               for s in ("r_sole", "l_sole"))  # fmt: skip


def prior_held_at_truth(fit, plan, truth: Corrections) -> Corrections:
    """The fit's estimate with the joint offsets that no pose separates (an ankle roll against its foot tag's mount:
    the plan's groups that keep their prior) at their true values. Such a group is an exact equivalence of the tag's
    motion, so the data leave the estimate anywhere along it and the fit holds it at the prior; the sole hangs on
    the ankle, not on the mount, so its error from the group is the ankle roll's prior error whatever the poses.
    What remains is the sole error the poses decide."""
    values = fit.solution.values[: len(fit.chain)].copy()
    truth_values = fit.chain.values_from(truth)
    for i, p in enumerate(fit.chain.parameters):
        k = plan.params.names.index(p.name)
        if p.kind == "offset" and not plan.observable[k] and plan.at_prior[k]:
            values[i] = truth_values[i]
    return fit.chain.corrections(values)


def timing() -> None:
    """Planning 20 of 2000: candidates and the whole plan, CPU and wall seconds."""
    robot = load_robot(CONFIG)
    for system, criterion in (("head", "D"), ("head", "E"), ("external", "D")):
        marks: list[float] = []

        def mark(message: str, marks: list[float] = marks) -> None:
            if message.startswith("choosing"):
                marks.append(time.process_time())

        start, cpu = time.perf_counter(), time.process_time()
        make_plan(robot, PlanOptions(free="leg", system=system, poses=20, criterion=criterion), say=mark)
        total, wall = time.process_time() - cpu, time.perf_counter() - start
        print(f"{system:9s} {criterion}: 20 of 2000 in {total:.1f} s CPU (candidates {marks[0] - cpu:.1f} s), "
              f"{wall:.1f} s wall; load average {os.getloadavg()[0]:.1f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--scenarios", nargs="*", default=list(SCENARIOS))
    parser.add_argument("--timing", action="store_true", help="time planning 20 of 2000 instead")
    args = parser.parse_args()
    if args.timing:
        timing()
        return
    for name in args.scenarios:
        runs = []
        for seed in range(args.seeds):
            r = run(name, seed)
            runs.append(r)
            print(f"  {name} seed {seed}: true error planned12 {r['planned12'][0] * 1000:.2f} mm, random30 "
                  f"{r['random30'][0] * 1000:.2f} mm, random12 {r['random12'][0] * 1000:.2f} mm; worst std planned12 "
                  f"{r['planned12'][1] * 1000:.3f} mm {np.rad2deg(r['planned12'][2]):.3f} deg, random12 "
                  f"{r['random12'][1] * 1000:.3f} mm {np.rad2deg(r['random12'][2]):.3f} deg; sole error with the "
                  f"prior-held offsets at truth {r['planned12'][4] * 1000:.2f} / {r['random30'][4] * 1000:.2f} / "
                  f"{r['random12'][4] * 1000:.2f} mm", flush=True)
        med = {k: np.median([r[k] for r in runs], axis=0) for k in ("planned12", "random30", "random12")}
        if name == "head_camera":
            mdeg = {k: np.rad2deg(v[3]) * 1000 for k, v in med.items()}
            print(f"{name:12s} camera rotation error (median of {args.seeds} seeds): 12 planned "
                  f"{mdeg['planned12']:.1f} mdeg, 30 random {mdeg['random30']:.1f} mdeg, 12 random "
                  f"{mdeg['random12']:.1f} mdeg", flush=True)  # fmt: skip
        if name != "head_camera":
            obs = {k: v[4] * 1000 for k, v in med.items()}
            print(f"{name:12s} sole error with the prior-held ankle rolls at their truth "
                  f"(median of {args.seeds} seeds): "
                  f"12 planned {obs['planned12']:.2f} mm, 30 random {obs['random30']:.2f} mm, 12 random "
                  f"{obs['random12']:.2f} mm", flush=True)  # fmt: skip
        ratio_m = np.median([r["random12"][1] / r["planned12"][1] for r in runs])
        ratio_rad = np.median([r["random12"][2] / r["planned12"][2] for r in runs])
        gain = [np.median([r["random12"][k] / r["planned12"][k] for r in runs if r["planned12"][k] > 0] or [np.nan])
                for k in (5, 6)]  # fmt: skip
        shown = ["none" if np.isnan(g) else f"{g:.1f}x" for g in gain]  # external leg: offsets only (rad)
        print(f"{name:12s} worst reported std among the observable offsets and camera mount (no tag mounts), "
              f"random12/planned12: {shown[0]} (m), {shown[1]} (rad)", flush=True)
        gain = [np.median([r["random12"][k] / r["planned12"][k] for r in runs if r["planned12"][k] > 0] or [np.nan])
                for k in (7, 8)]  # fmt: skip
        shown = ["none" if np.isnan(g) else f"{g:.1f}x" for g in gain]
        print(f"{name:12s} the same with the unseparable directions known (what the poses decide), "
              f"random12/planned12: {shown[0]} (m), {shown[1]} (rad)", flush=True)
        print(f"{name:12s} true error (median of {args.seeds} seeds): 12 planned {med['planned12'][0] * 1000:.2f} mm, "
              f"30 random {med['random30'][0] * 1000:.2f} mm, 12 random {med['random12'][0] * 1000:.2f} mm; "
              f"worst reported std random12/planned12: {ratio_m:.1f}x (m), {ratio_rad:.1f}x (rad); "
              f"planning {np.median([r['planning_s'] for r in runs]):.1f} s wall, "
              f"{np.median([r['planning_cpu_s'] for r in runs]):.1f} s CPU (12 of 2000; load average "
              f"{os.getloadavg()[0]:.1f})", flush=True)


if __name__ == "__main__":
    main()
