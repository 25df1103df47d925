"""What candidate poses would tell the fit: its own blocks, noise model and priors at simulated observations.

The tag corners of each candidate are projected through the camera model at the nominal kinematics (`wolfcal.sim`,
no image, no noise) and handed to the fit's `CameraBlock` and `Problem`, whitened with the configured pixel noise
(priors.pixel_noise) and encoder quantisation (priors.encoder_noise), in the fit's prior-normalised unknowns z
(prior: unit variance). Per candidate k, `factors` gives G_k (r, P): its whitened Jacobian rows, so the information
of a pose set S is I + sum_k G_k^T G_k. For the selection each candidate is its own noise group (a detection error
that repeats across poses, e.g. an external camera's view of the torso tag, is counted only by `predicted`, which
is the fit's full noise model on a chosen set).

What no pose can separate: the directions of z in which the mean information per candidate pose is below NULL_INFO
(the prior's is 1: a hundred such poses would add a tenth of it), e.g. an ankle roll offset against its foot tag's
mount, or the HeadTilt offset against the camera's frame correction (exactly equivalent motions). Parameters with more
than UNSEPARABLE_SHARE of their prior variance in those directions keep their prior whatever the poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.fit.camera_block import CameraBlock
from wolfcal.fit.problem import Problem
from wolfcal.fit.uncertainty import Uncertainty, uncertainty
from wolfcal.observations import Observations
from wolfcal.plan.candidates import PlanCamera
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet, build_parameter_set
from wolfcal.robot.robot import Robot
from wolfcal.sim.external_poses import external_tag_poses
from wolfcal.sim.observations import observations_from_poses

NULL_INFO = 1e-3  # mean information per pose [z units, prior = 1] below which a direction counts as unobservable
UNSEPARABLE_SHARE = 1e-3  # a parameter is unseparable when this share of its prior variance lies in null directions


class _IndependentCameraBlock(CameraBlock):
    """A camera block whose samples share no detection error (each candidate pose its own noise group)."""

    def shared_labels(self) -> np.ndarray:
        return np.full(self.n_units, -1)


@dataclass
class PlanModel:
    """The fit a plan is made for: robot, camera, preset and the tags used."""

    robot: Robot
    camera: PlanCamera
    preset: str
    side: str
    tag_ids: list[int]

    def chain(self) -> ParameterSet:
        return build_parameter_set(self.robot, self.preset, {self.camera.name: self.tag_ids}, self.side)

    def observations(self, q: np.ndarray, visible: np.ndarray) -> Observations:
        """Noise-free corners of the visible tags (visible: (N, T) over config.tag_ids) at readings q (N, J)."""
        robot, nominal = self.robot, Corrections()
        if self.camera.external:
            T_camera_tag = external_tag_poses(robot, self.camera.pose(), q, nominal, robot.config.tag_ids)
        else:
            T_camera_tag = robot.camera_and_tag_poses(q, robot.config.tag_ids)[1]
        return observations_from_poses(robot, self.camera.model, nominal, q, T_camera_tag, visible, 0.0,
                                       np.random.default_rng(0), self.camera.name)  # fmt: skip

    def problem(self, q: np.ndarray, visible: np.ndarray, independent: bool = False) -> Problem:
        """The fit's problem on simulated observations of poses q (N, J)."""
        obs = self.observations(q, visible)
        kind = _IndependentCameraBlock if independent else CameraBlock
        tags = sorted({int(t) for t in obs.tag_ids})
        if self.camera.external:
            block = kind(self.robot, obs, tags, True, np.zeros(obs.n_samples, int), [self.camera.name])
        else:
            block = kind(self.robot, obs, tags)
        priors = self.robot.config.priors
        return Problem(self.chain(), [block], [priors.pixel_noise], priors.encoder_noise)


def factors(problem: Problem) -> np.ndarray:
    """(N, r, P) whitened Jacobian rows of each sample in z units (zero rows pad samples with fewer tags)."""
    J = np.asarray(problem.data_jacobian(np.zeros(len(problem.params)), robust=False))
    block = problem.blocks[0]
    sample_of_row = np.repeat(block.sample_of_unit, block.dim)
    order = np.argsort(sample_of_row, kind="stable")
    counts = np.bincount(sample_of_row, minlength=len(block.q_measured))
    slot = np.arange(len(order)) - np.repeat(np.cumsum(counts) - counts, counts)
    G = np.zeros((len(counts), int(counts.max()), J.shape[1]))
    G[sample_of_row[order], slot] = J[order]
    return G


def predicted(problem: Problem) -> Uncertainty:
    """The uncertainty the fit would report on this problem's poses at the configured noise (fit.uncertainty)."""
    return uncertainty(problem.data_jacobian(np.zeros(len(problem.params)), robust=False), problem.params.prior_sigmas)


@dataclass
class Separability:
    null: np.ndarray  # (P, m) orthonormal directions of z no candidate informs
    unseparable: np.ndarray  # (P,) bool: parameter keeps (much of) its prior whatever the poses
    basis: np.ndarray  # (c, k) orthonormal basis of the chain unknowns the poses can inform

    def groups(self, names: list[str]) -> list[list[str]]:
        """The parameters that no pose separates, in groups that move together (linked through the projector onto
        the null directions), each group strongest first."""
        P = self.null @ self.null.T
        idx = np.flatnonzero(self.unseparable)
        linked = np.abs(P[np.ix_(idx, idx)]) > UNSEPARABLE_SHARE
        groups: list[list[str]] = []
        seen: set[int] = set()
        for a in range(len(idx)):
            if a in seen:
                continue
            members, stack = [], [a]
            while stack:
                b = stack.pop()
                if b not in seen:
                    seen.add(b)
                    members.append(b)
                    stack += list(np.flatnonzero(linked[b]))
            members.sort(key=lambda m: -P[idx[m], idx[m]])
            groups.append([names[idx[m]] for m in members])
        return groups


def separability(G: np.ndarray, n_chain: int) -> Separability:
    """Null directions of the candidates' mean information (G: (N, r, P)) and the observable chain basis."""
    info = np.einsum("nri,nrj->ij", G, G) / len(G)
    lam, V = np.linalg.eigh(info)
    null = V[:, lam < NULL_INFO]
    unseparable = np.sum(null**2, axis=1) > UNSEPARABLE_SHARE
    U, s, _ = np.linalg.svd(null[:n_chain], full_matrices=True)
    rank = int(np.sum(s > 0.5))  # chain directions that are (mostly) null
    return Separability(null, unseparable, U[:, rank:])


def check_observable(params: ParameterSet, G: np.ndarray, sep: Separability, n_candidates: int) -> None:
    """A clear error when a free parameter gets no information from any candidate pose."""
    column_info = np.einsum("nri,nri->i", G, G)
    blind = [params.names[i] for i in np.flatnonzero(column_info <= 1e-12 * max(column_info.max(), 1e-300))]
    if blind:
        raise WolfcalError(
            f"no reachable pose can observe {', '.join(blind)}: none of the {n_candidates} candidate poses shows a "
            "tag whose image moves when these change (a joint that no used tag depends on, or a tag never in "
            "view); free fewer parameters (--free, --side) or add a tag behind that joint"
        )
