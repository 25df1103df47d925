"""Planning for motion capture (`--system mocap`): candidate poses and the fit's MocapBlock as their information.

The robot stands on its stand (base still, one base pose in the motion-capture frame for the whole capture) and moves
the joints between the base and the markers' links (the config's `markers:`; with the leg preset and one --side,
the markers of that leg and those on no leg, as the fit takes them: `wolfcal.fit.pipeline.mocap_block`).
Visibility: the DESIGN.md motion-capture model has cameras all around the robot and no rule by which the robot's
pose hides a marker (the simulator drops 3 % of the marker samples at random, whatever the pose, and the fit leaves
a missing marker out): every configured marker counts as measured in every candidate pose. A candidate is a draw of
those joints uniform within their URDF limits shrunk by the margin (the others at the rest pose) that keeps
CLEARANCE_M between the robot's bodies (`wolfcal.plan.candidates`).
Information: noise-free marker positions under the nominal model (base pose: identity) handed to the fit's own
`MocapBlock` (base pose and marker mounts its nuisance unknowns), whitened with the noise the fit starts from.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import block_sigmas, mocap_block
from wolfcal.fit.problem import Problem
from wolfcal.markers import MarkerObservations
from wolfcal.plan.candidates import BATCH, CLEARANCE_M, HINT_POSES, Candidates, draw_until, joint_bounds
from wolfcal.plan.information import plan_problem
from wolfcal.robot.collision import CollisionModel
from wolfcal.robot.parameters import ParameterSet, build_parameter_set
from wolfcal.robot.robot import Robot

SOURCE = "plan"  # one marker source: one base pose for every sample, as on the stand


def used_markers(robot: Robot, preset: str, side: str) -> list[str]:
    """Names of the configured markers the fit would use (see the module docstring); a clear error without any."""
    if robot.config.markers is None or not robot.config.markers.entries:
        raise WolfcalError(f"{robot.config.path}: --system mocap plans where the motion-capture markers are; add "
                           "'markers:' (topic and list of {name, link, xyz}) to the robot config")  # fmt: skip
    if preset in ("camera", "head_camera"):
        raise WolfcalError(f"--free {preset} estimates the head camera, which motion capture cannot see (no marker "
                           "on the camera's optical frame); plan --system mocap with --free leg")  # fmt: skip
    entries = robot.config.markers.entries
    return [m.name for m in entries if preset != "leg" or side == "both" or m.side in (side, None)]


def marker_joints(robot: Robot, names: list[str]) -> list[str]:
    """The joints that move the markers relative to the base, in model order."""
    config = robot.config.marker_config()
    moved = set(robot.actuated_joints_to([config.marker(n).link for n in names]))
    return [j for j in robot.joint_names if j in moved]


def draw_mocap_candidates(robot: Robot, names: list[str], n: int, rng: np.random.Generator,
                          collisions: CollisionModel, margin: float = 0.1) -> Candidates:  # fmt: skip
    """Up to n collision-free poses of the markers' joints (within their limits shrunk by `margin` [rad]); visible
    (N, K): every marker of `names` (see above)."""
    joints = marker_joints(robot, names)
    if not joints:
        raise WolfcalError(f"{robot.config.path}: no movable joint between {robot.config.base_link} and the markers' "
                           "links; motion capture has nothing to observe")  # fmt: skip
    lo, hi = joint_bounds(robot, joints, margin)

    def batch() -> tuple[np.ndarray, np.ndarray, int]:
        q = rng.uniform(lo, hi, size=(BATCH, len(lo)))
        q = q[collisions.collision_free(q, CLEARANCE_M)]
        return q, np.ones((len(q), len(names)), dtype=bool), BATCH

    q, visible, drawn = draw_until(n, batch)
    if not len(q):
        hint = collisions.rejection_hint(rng.uniform(lo, hi, size=(HINT_POSES, len(lo))), CLEARANCE_M)
        raise WolfcalError(f"none of {drawn} random poses of {', '.join(joints)} within the joint limits is free of "
                           f"self-collision: {hint}")  # fmt: skip
    return Candidates(q, visible, joints, drawn, {"self-collision": drawn - len(q)})


@dataclass
class MocapPlanModel:
    """The motion-capture fit a plan is made for (same interface as `wolfcal.plan.information.PlanModel`)."""

    robot: Robot
    preset: str
    side: str
    markers: list[str]

    def observations(self, q: np.ndarray, visible: np.ndarray) -> MarkerObservations:
        """Noise-free positions (base frame = motion-capture frame) of the visible markers (N, K) at readings q."""
        config = self.robot.config.marker_config()
        entries = [config.marker(n) for n in self.markers]
        links = list(dict.fromkeys(m.link for m in entries))
        poses = self.robot.model.link_poses(q, links, base=self.robot.config.base_link)
        xyz = np.stack([poses[m.link][:, :3, :3] @ np.asarray(m.xyz) + poses[m.link][:, :3, 3] for m in entries], 1)
        s, k = np.nonzero(visible)
        return MarkerObservations(
            joint_names=list(self.robot.joint_names), q_measured=q, stamps_ns=np.arange(len(q), dtype=np.int64),
            sources=[SOURCE] * len(q), marker_names=list(self.markers), sample_index=s, marker_index=k,
            xyz=xyz[s, k],
        )  # fmt: skip

    def chain(self, links: tuple[str, ...]) -> ParameterSet:
        return build_parameter_set(self.robot, self.preset, {}, self.side, marker_links=links)

    def problem(self, q: np.ndarray, visible: np.ndarray, independent: bool = False) -> Problem:
        """The fit's problem on simulated marker positions (every sample its own noise group either way)."""
        options = FitOptions(free=self.preset, side=self.side, system="mocap")
        block = mocap_block(self.robot, self.observations(q, visible), options)
        if block is None:
            raise RuntimeError("the fit took no motion-capture block")
        return plan_problem(self.chain(tuple(block.links)), [block], block_sigmas(self.robot, [block]),
                            self.robot.config.priors.encoder_noise)  # fmt: skip

    def repeated_information(self, problem: Problem, q: np.ndarray, visible: np.ndarray, n: int) -> np.ndarray:
        """Motion capture repeats no measurement from pose to pose (the base pose and mounts are unknowns)."""
        P = len(problem.params)
        return np.zeros((P, P))
