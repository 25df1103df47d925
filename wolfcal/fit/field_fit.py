"""The field system's fit builder (`wolfcal.fit.systems`): field captures -> the field block to join a fit."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from wolfcal.field.model import field_lines
from wolfcal.field.place import pitched
from wolfcal.fit.blocks import Block
from wolfcal.fit.field_block import FieldBlock
from wolfcal.fit.jackknife import JACKKNIFE_GROUPS
from wolfcal.fit.options import FitOptions
from wolfcal.robot.robot import Robot


def field_blocks(robot: Robot, captures: list[Path], options: FitOptions,
                 say: Callable[[str], None] | None) -> tuple[list[Block], list[Path]]:  # fmt: skip
    """The fit builder of the field system (`wolfcal.fit.systems`): the field captures (`field_captures`: with
    `--system field` every capture, with every system those that show no tag). Its block is solved once on its own,
    weighted and started at the camera pitch the place search found (`wolfcal.field.place`; the median over the
    placements), then weighted again and started at that solution (`FieldBlock.reweighted`): each solve starts
    where its points are weighted, near where they lie. The fit then joins the block to the other blocks, and
    checks the reported std against a jackknife over groups of the field views (`wolfcal.fit.jackknife`)."""
    from wolfcal.field.observe import field_captures, field_observations
    from wolfcal.fit.pipeline import fit_observations

    chosen = field_captures(robot, list(captures), options.system)
    if not chosen:
        return [], []
    tell = say or (lambda _: None)
    obs = field_observations(robot, chosen, tell)
    searched = None if obs.pitches is None else pitched(robot, float(np.median(obs.pitches)))
    block = FieldBlock(robot, obs, field_lines(robot.config.field_config().dimensions), weighted_at=searched,
                       shared_lines=False)  # fmt: skip
    first = fit_observations(robot, {}, replace(options, system="field"), own_blocks=[block])
    tell("weighting the line points at the first solution ...")
    return [block.reweighted(first.chain, first.solution.values, JACKKNIFE_GROUPS)], chosen
