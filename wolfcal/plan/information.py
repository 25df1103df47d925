"""What candidate poses would tell the fit: its own blocks, noise model and priors at simulated observations.

The tag corners of each candidate are projected through the camera model at the nominal kinematics
(`wolfcal.projection`, no image, no noise) and handed to the fit's `CameraBlock` and `Problem`, whitened with the
configured pixel noise (priors.pixel_noise) and encoder quantisation (priors.encoder_noise), in the fit's
prior-normalised unknowns z (prior: unit variance). The information of a pose set S is I + M_rep(n) + sum_k G_k^T G_k,
as the fit's noise model makes it:
- G_k (`factors`, r x P): the whitened rows of candidate k that change with the pose (each candidate pose its own
  noise group: the encoder error of one still pose);
- M_rep(n) (`repeated_information`): the views that are the same in every pose, an external camera's view of the tags
  fixed to the base (e.g. the torso tag). Their detection error repeats pose to pose (`CameraBlock.shared_labels`),
  so n such views tell n / (sigma^2 + n tau^2) times what one tells, never more than 1 / tau^2: counted once, for the
  n poses of the plan, through the fit's own grouped whitening.

What no pose can improve: the directions of z in which the mean information per candidate pose is below NULL_INFO
(the prior's is 1: a hundred such poses would add a tenth of it), e.g. an ankle roll offset against its foot tag's
mount, or the HeadTilt offset against the camera's frame correction (exactly equivalent motions). Even with those
directions known exactly, they keep the covariance F = N (N^T (I + M_rep) N)^-1 N^T (N: the null directions): their
prior, or what the repeated view tells (the torso tag's mount along the camera's line of sight). Parameters whose
floor variance F_ii exceeds UNSEPARABLE_SHARE of their prior's keep it whatever the poses and are not counted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.external_view import external_tag_poses
from wolfcal.fit.blocks import Block
from wolfcal.fit.camera_block import CameraBlock
from wolfcal.fit.problem import Problem
from wolfcal.fit.solved import Fit
from wolfcal.fit.uncertainty import Uncertainty, uncertainty
from wolfcal.observations import Observations
from wolfcal.plan.candidates import PlanCamera
from wolfcal.projection import observations_from_poses
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet, build_parameter_set
from wolfcal.robot.robot import Robot

NULL_INFO = 1e-3  # mean information per pose [z units, prior = 1] below which a direction counts as unobservable
UNSEPARABLE_SHARE = 1e-3  # a parameter is unseparable when this share of its prior variance lies in null directions


class _IndependentCameraBlock(CameraBlock):
    """A camera block whose samples share no detection error (each candidate pose its own noise group)."""

    def shared_labels(self) -> np.ndarray:
        return np.full(self.n_units, -1)


class PlanModelLike(Protocol):
    """The fit a plan is made for, one per measurement system (camera: `PlanModel`; `plan.mocap`, `plan.floor`)."""

    def problem(self, q: np.ndarray, visible: np.ndarray, independent: bool = False) -> Problem:
        """The fit's problem on poses q (N, J) with what each shows (N, ...); `independent`: every pose its own noise
        group and no view repeated (the candidates' block, whose repeated views `repeated_information` counts)."""
        ...

    def repeated_information(self, problem: Problem, q: np.ndarray, visible: np.ndarray, n: int) -> np.ndarray:
        """(P, P) [z units] what every plan of n poses gets whatever the poses (over the candidates' unknowns)."""
        ...


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

    def repeated_information(self, problem: Problem, q: np.ndarray, visible: np.ndarray, n: int) -> np.ndarray:
        """(P, P) information of the views repeated in n poses (module function `repeated_information`)."""
        return repeated_information(self, problem, q, visible, n)

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
        return plan_problem(self.chain(), [block], [priors.pixel_noise], priors.encoder_noise)


def plan_problem(chain: ParameterSet, blocks: Sequence[Block], sigmas: list[float], sigma_q: float) -> Problem:
    """The fit's problem over blocks of noise-free simulated observations, whitened at the noise levels `sigmas`
    (one per block, `fit.pipeline.block_sigmas`: the configured pixel noise) and joint reading noise sigma_q [rad].
    The fit raises a block's starting level to the spread of its residuals under the nominal model; here that spread
    is only the encoder quantisation of the simulated readings (0.7-0.9 px for the head camera), already counted by
    sigma_q, so the levels are set back to those assumed."""
    problem = Problem(chain, blocks, sigmas, sigma_q)
    for state, sigma in zip(problem.states, sigmas):
        state.set_sigma(sigma)
    return problem


def camera_block(problem: Problem) -> CameraBlock:
    """The plan problem's one block (`PlanModel.problem`)."""
    block = problem.blocks[0]
    if not isinstance(block, CameraBlock):
        raise TypeError(f"a plan problem holds one camera block, not {type(block).__name__}")
    return block


def repeated_units(problem: Problem) -> np.ndarray:
    """(U,) bool: units of the (independent) candidate block whose detection error the fit shares between poses (a
    label of `CameraBlock.shared_labels` that spans samples): their view is the same in every pose."""
    block = problem.blocks[0]
    if not isinstance(block, CameraBlock):
        return np.zeros(block.n_units, dtype=bool)  # motion capture, floor: no view repeats (`repeated_information`)
    labels, samples = CameraBlock.shared_labels(block), block.sample_of_unit
    lowest = np.full(labels.max() + 1, samples.max())
    highest = np.zeros(labels.max() + 1, dtype=samples.dtype)
    np.minimum.at(lowest, labels, samples)
    np.maximum.at(highest, labels, samples)
    return (highest > lowest)[labels]


def factors(problem: Problem) -> np.ndarray:
    """(N, r, P) whitened Jacobian rows that change with the pose, per sample, in z units (zero rows at the end pad
    samples with fewer tags; the rows of `repeated_units` are left out: `repeated_information` counts them)."""
    J = np.asarray(problem.data_jacobian(np.zeros(len(problem.params)), robust=False))
    block = problem.blocks[0]
    keep = np.repeat(~repeated_units(problem), block.dim)  # each unit is its own noise group here
    J, sample_of_row = J[keep], np.repeat(block.sample_of_unit, block.dim)[keep]
    order = np.argsort(sample_of_row, kind="stable")
    counts = np.bincount(sample_of_row, minlength=len(block.q_measured))
    slot = np.arange(len(order)) - np.repeat(np.cumsum(counts) - counts, counts)
    G = np.zeros((len(counts), int(counts.max()), J.shape[1]))
    G[sample_of_row[order], slot] = J[order]
    return G


def repeated_information(model: PlanModel, problem: Problem, q: np.ndarray, visible: np.ndarray, n: int) -> np.ndarray:
    """(P, P) information [z units] of the views repeated in n poses (see the module docstring), by the fit's own
    noise model on n of the candidates q (N, J) showing only those tags; zero when no view repeats."""
    repeated = repeated_units(problem)
    P = len(problem.params)
    if not repeated.any():
        return np.zeros((P, P))
    block = camera_block(problem)
    tags = np.unique(np.asarray(block.tag_ids)[block.tag_col[repeated]])
    shown = visible[:n] & np.isin(model.robot.config.tag_ids, tags)
    shared = model.problem(q[:n], shown)
    if shared.params.names != problem.params.names:
        raise RuntimeError("the repeated views' problem has other unknowns than the candidates'")
    J = np.asarray(shared.data_jacobian(np.zeros(P), robust=False))
    return J.T @ J


def predicted(problem: Problem) -> Uncertainty:
    """The uncertainty the fit would report on this problem's poses at the configured noise (fit.uncertainty)."""
    return uncertainty(problem.data_jacobian(np.zeros(len(problem.params)), robust=False), problem.params.prior_sigmas)


def separated_std(information: np.ndarray, prior_sigmas: np.ndarray, n_samples: int) -> np.ndarray:
    """(P,) std [SI] of each unknown with the directions that no pose informs known exactly: the fit's covariance
    conditioned on the directions of z whose information per sample (J^T J (P, P) of the whitened data Jacobian, z
    units) is below NULL_INFO. What the poses decide: at the fit's solution an unseparable group (HeadTilt.offset
    against the camera's rotation about the tilt axis) is turned by the camera's rotation correction and lends its
    prior to the camera's other rotations (`fit.uncertainty` reports that share too), whatever the poses."""
    _, B = _split_directions(information, n_samples)
    cov_z = B @ np.linalg.solve(B.T @ (information + np.eye(len(information))) @ B, B.T)
    return np.sqrt(np.clip(np.diag(cov_z), 0.0, None)) * prior_sigmas


def _split_directions(information: np.ndarray, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal directions of z (P, m) whose information per sample (of J^T J (P, P)) is below NULL_INFO, and the
    others (P, P-m)."""
    lam, V = np.linalg.eigh(information / max(n_samples, 1))
    return V[:, lam < NULL_INFO], V[:, lam >= NULL_INFO]


def _fit_information(fit: Fit) -> tuple[np.ndarray, int]:
    """A fit's information J^T J at its solution (`Problem.information`: z units, what the std it reports comes
    from) and its sample count."""
    problem = fit.problem
    z = (fit.solution.values - problem.params.references) / problem.params.prior_sigmas
    return problem.information(z)[0], sum(len(b.q_measured) for b in fit.blocks)


def fit_separated_std(fit: Fit) -> np.ndarray:
    """(P,) a fit's std [SI] with the directions no pose informs known exactly (`separated_std`), from the same
    information at its solution as the std it reports."""
    information, n_samples = _fit_information(fit)
    return separated_std(information, fit.problem.params.prior_sigmas, n_samples)


def fit_null_directions(fit: Fit) -> np.ndarray:
    """(P, m) the directions of a fit's prior-normalised unknowns z that its data do not inform (information per
    sample below NULL_INFO at its solution: those `fit_separated_std` takes as known), orthonormal."""
    information, n_samples = _fit_information(fit)
    return _split_directions(information, n_samples)[0]


@dataclass
class Separability:
    floor: np.ndarray  # (P, P) covariance [z units] left with every informed direction known exactly
    prior_floor: np.ndarray  # (P,) its diagonal without the repeated views (the prior's share in null directions)
    unseparable: np.ndarray  # (P,) bool: parameter keeps (much of) its prior or repeated-view floor whatever the poses
    basis: np.ndarray  # (c, k) orthonormal basis of the chain unknowns the poses can inform

    def groups(self, names: list[str]) -> list[list[str]]:
        """The parameters that no pose separates, in groups that move together (linked through the floor
        covariance), each group strongest first."""
        F = self.floor
        idx = np.flatnonzero(self.unseparable)
        linked = np.abs(F[np.ix_(idx, idx)]) > UNSEPARABLE_SHARE
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
            members.sort(key=lambda m: -F[idx[m], idx[m]])
            groups.append([names[idx[m]] for m in members])
        return groups

    def at_prior(self, i: int) -> bool:
        """Parameter i keeps (nearly) what the prior leaves in the null directions: the repeated views do not
        inform it either."""
        return bool(self.floor[i, i] > 0.9 * self.prior_floor[i])


def separability(
    G: np.ndarray, n_chain: int, M_repeated: np.ndarray | None = None, interest: np.ndarray | None = None
) -> Separability:
    """Null directions of the candidates' mean information (G: (N, r, P)), the floor covariance they leave (with
    the repeated views' information M_repeated (P, P), see the module docstring) and the basis of the observable
    directions among the chain unknowns of `interest` ((n_chain,) bool, default all: `criterion_interest`)."""
    P = G.shape[2]
    M_repeated = np.zeros((P, P)) if M_repeated is None else M_repeated
    info = np.einsum("nri,nrj->ij", G, G) / len(G)
    lam, V = np.linalg.eigh(info)
    null = V[:, lam < NULL_INFO]
    floor = null @ np.linalg.solve(null.T @ (np.eye(P) + M_repeated) @ null, null.T) if null.size else np.zeros((P, P))
    unseparable = np.diag(floor) > UNSEPARABLE_SHARE
    interest = np.ones(n_chain, dtype=bool) if interest is None else interest
    idx = np.flatnonzero(interest)
    mu, U = np.linalg.eigh(floor[np.ix_(idx, idx)])
    keep = mu <= 0.25  # directions that keep less than a quarter of their prior variance
    basis = np.zeros((n_chain, int(keep.sum())))
    basis[idx] = U[:, keep]
    return Separability(floor, np.sum(null**2, axis=1), unseparable, basis)


def criterion_interest(params: ParameterSet, n_chain: int) -> np.ndarray:
    """(n_chain,) bool: the chain unknowns a plan's criterion looks at, all but the tags' mounts. A tag's mount is
    needed by the fit but is not what a calibration delivers (joint offsets, the camera's mount); the criterion
    marginalises it (Ds-optimality) rather than spending poses on it."""
    return np.array([p.kind != "tag" for p in params.parameters[:n_chain]], dtype=bool)


def check_observable(params: ParameterSet, G: np.ndarray, M_repeated: np.ndarray, n_candidates: int) -> None:
    """A clear error when a free parameter gets no information from any candidate pose (nor the repeated views)."""
    column_info = np.einsum("nri,nri->i", G, G) + np.diag(M_repeated)
    blind = [params.names[i] for i in np.flatnonzero(column_info <= 1e-12 * max(column_info.max(), 1e-300))]
    if blind:
        raise WolfcalError(
            f"no reachable pose can observe {', '.join(blind)}: none of the {n_candidates} candidate poses shows a "
            "tag whose image moves when these change (a joint that no used tag depends on, or a tag never in "
            "view); free fewer parameters (--free, --side) or add a tag behind that joint"
        )
