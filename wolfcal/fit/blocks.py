"""Measurement blocks: what one measurement system predicts for the current parameters, and how that changes.

A block owns its measured numbers (units of `dim` numbers: a tag corner's two pixels, a marker's three
coordinates), their noise groups (units that share the error of one still pose's joint readings), its outlier
unit (a view: one tag in one image, one marker in one sample) and its own unknowns (`nuisance`, e.g. an external
camera's pose per placement). The problem and the solver know blocks only through this interface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.robot.parameters import ParameterSet

OUTLIER_FACTOR = 4.0  # a view is an outlier when its whitened RMS exceeds this many times the median view's


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
    outlier_floor: float  # a view is left out only if also off by more than this [unit]
    outlier_factor: float = OUTLIER_FACTOR  # ... and its whitened RMS exceeds this many times the median view's
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
        """(U,) group of each unit: units of samples with identical joint readings share their error."""
        _, group_of_sample = np.unique(self.q_measured, axis=0, return_inverse=True)
        return group_of_sample.ravel()[self.sample_of_unit]

    def shared_labels(self) -> np.ndarray:
        """(U,) label of a detection error each unit shares with others (-1: none). Default: none."""
        return np.full(self.n_units, -1)

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        raise NotImplementedError
