"""Measurement blocks: what one measurement system predicts for the current parameters, and how that changes.

A block owns its measured numbers (units of `dim` numbers: a tag corner's two pixels, a marker's three
coordinates), their noise groups (units that share the error of one still pose's joint readings), its outlier
unit (a view: one tag in one image, one marker in one sample) and its own unknowns (`nuisance`, e.g. an external
camera's pose per placement). The problem and the solver know blocks only through this interface.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from wolfcal.encoders import RAD_PER_TICK
from wolfcal.graph import connected_components
from wolfcal.observations import Observations
from wolfcal.outliers import OutlierRule
from wolfcal.robot.parameters import ParameterSet


class TagViewBlock(Protocol):
    """A block whose units are tag corners seen by one camera (camera, floor and sole-closure blocks)."""

    obs: Observations
    camera_name: str
    tag_ids: list[int]


@dataclass
class Linearization:
    """A block's residuals and first derivatives at one parameter vector."""

    residual: np.ndarray  # (U, dim) predicted minus measured [unit]
    jac_chain: np.ndarray  # (U, dim, Pc) d(residual)/d(chain parameter values) [unit / SI]
    jac_local: np.ndarray | None  # (U, dim, L) d(residual)/d(the block's own unknowns of each unit) [unit / SI]
    local_cols: np.ndarray | None  # (U, L) column in the block's nuisance set of each jac_local entry
    joint_sensitivity: np.ndarray  # (U, dim, J) d(residual)/d(joint readings) [unit / rad]


class Block:
    """Base of the measurement blocks; subclasses set the fields and implement `linearize`."""

    name: str  # e.g. 'head camera', 'external camera tripod'
    system: str  # 'head' | 'external' | ...
    unit: str  # 'px' | 'm'
    dim: int  # measured numbers per unit
    outlier_rule: OutlierRule  # which views are left out (`wolfcal.outliers`; floor in the block's unit)
    # which single units of the views kept are left out (None: none; `OutlierRule.limit` of the robust scale of the
    # units' conditional residuals, `solver.flag_units`)
    unit_rule: OutlierRule | None = None
    nuisance: ParameterSet  # the block's own unknowns
    sample_of_unit: np.ndarray  # (U,) sample index of each unit
    view_of_unit: np.ndarray  # (U,) outlier unit (view) of each unit
    view_labels: list[tuple[int, int]]  # (sample, tag or marker id) of each view
    q_measured: np.ndarray  # (S, J) joint readings of the block's samples [rad]

    @property
    def n_units(self) -> int:
        return len(self.sample_of_unit)

    @property
    def n_views(self) -> int:
        return len(self.view_labels)

    def noise_groups(self) -> np.ndarray:
        """(U,) group of each unit: the units of one still pose share its joint readings' error. A still pose is the
        samples with identical readings, joined with the next sample when no reading differs by more than one
        encoder tick (a recording's frames of one pose, while an encoder flickers between two ticks)."""
        ticks = np.round(self.q_measured / RAD_PER_TICK).astype(np.int64)
        _, same = np.unique(ticks, axis=0, return_inverse=True)
        same = same.ravel()
        n, S = int(same.max()) + 1 if len(same) else 0, len(ticks)
        near = np.flatnonzero(np.all(np.abs(np.diff(ticks, axis=0)) <= 1, axis=1))
        edges = np.concatenate([[same, n + np.arange(S)], [n + near, n + near + 1]], axis=1)
        group_of_sample = connected_components(n + S, edges[0], edges[1])[n:]
        return group_of_sample[self.sample_of_unit]

    def joint_reading_groups(self) -> np.ndarray:
        """(U, J) group of each unit's reading of each joint: units with the same group of joint j share that
        reading's error. Default: the still pose (`noise_groups`) for every joint (a read-only view of one column:
        (U,) numbers held, not U * J)."""
        groups = self.noise_groups()
        return np.broadcast_to(groups[:, None], (len(groups), self.q_measured.shape[1]))

    def shared_labels(self) -> np.ndarray:
        """(U,) label of a detection error each unit shares with others (-1: none). Default: none."""
        return np.full(self.n_units, -1)

    def noise_classes(self) -> np.ndarray:
        """(U,) noise class of each unit: units of one class share a noise level, estimated apart from the other
        classes' (e.g. one per motion-capture marker). Default: one class, the block's level."""
        return np.zeros(self.n_units, dtype=int)

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        raise NotImplementedError


def held_joint_groups(q_measured: np.ndarray, sample_of_unit: np.ndarray) -> np.ndarray:
    """(U, J) reading groups (`Block.joint_reading_groups`) of samples in which joints held still: per joint, the
    units whose sample read the same encoder tick share that reading's error (the standing legs of floor samples,
    which keep one pose while the head looks around)."""
    ticks = np.round(q_measured / RAD_PER_TICK).astype(np.int64)[sample_of_unit]
    return ticks - ticks.min(axis=0, initial=0)  # labels only: equal tick, equal label (non-negative, not 0..G-1)
