"""A solved fit: what `wolfcal fit` hands to the result writer, the evaluation and pose planning."""

from __future__ import annotations

from dataclasses import dataclass, field

from wolfcal.fit.blocks import Block
from wolfcal.fit.problem import Problem
from wolfcal.fit.solver import Solution
from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot


@dataclass
class Fit:
    """A solved fit: the measurement blocks and their observations, the unknowns and the solution."""

    robot: Robot
    observations: dict[str, Observations]  # per camera, only the tags used
    blocks: list[Block]  # the measurement blocks (camera, floor, sole closure, motion capture)
    chain: ParameterSet  # the robot-model parameters (the first len(chain) unknowns)
    problem: Problem
    solution: Solution
    held: Corrections = field(default_factory=Corrections)  # corrections held fixed under the free ones (--current)

    @property
    def params(self) -> ParameterSet:
        """Every unknown: the chain parameters, then each block's own (e.g. external camera poses)."""
        return self.problem.params

    @property
    def tag_ids(self) -> list[int]:
        """The ids of the tags on links that the fit's blocks observe (floor tags not included)."""
        return sorted({t for b in self.blocks if b.system != "floor" for t in getattr(b, "tag_ids", ())})

    @property
    def corrections(self) -> Corrections:
        """The fitted model's corrections (offsets [rad], frame and tag-mount vectors [m, rad]): the free
        parameters' values (totals, not changes) with what the fit held fixed."""
        return self.chain.corrections(self.solution.values[: len(self.chain)]).plus(self.held)
