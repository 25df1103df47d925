"""Measurement blocks: what one measurement system predicts for the current parameters, and how that changes.

A block owns its measured numbers (units of `dim` numbers: a tag corner's two pixels, a marker's three
coordinates), their noise groups (units that share the error of one still pose's joint readings), its outlier
unit (a view: one tag in one image, one marker in one sample) and its own unknowns (`nuisance`, e.g. an external
camera's pose per placement). The problem and the solver know blocks only through this interface.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from wolfcal.encoders import RAD_PER_TICK
from wolfcal.graph import connected_components
from wolfcal.observations import Observations
from wolfcal.outliers import OutlierRule
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet

if TYPE_CHECKING:
    from wolfcal.config import PriorConfig


class TagViewBlock(Protocol):
    """A block whose units are tag corners seen by one camera (camera, floor and sole-closure blocks)."""

    obs: Observations
    camera_name: str
    tag_ids: list[int]

    @property
    def unit_rule(self) -> OutlierRule | None: ...  # single units left out one by one (`Block.unit_rule`)


@dataclass
class Linearization:
    """A block's residuals and first derivatives at one parameter vector."""

    residual: np.ndarray  # (U, dim) predicted minus measured [unit]
    jac_chain: np.ndarray  # (U, dim, Pc) d(residual)/d(chain parameter values) [unit / SI]
    jac_local: np.ndarray | None  # (U, dim, L) d(residual)/d(the block's own unknowns of each unit) [unit / SI]
    local_cols: np.ndarray | None  # (U, L) column in the block's nuisance set of each jac_local entry
    joint_sensitivity: np.ndarray  # (U, dim, J) d(residual)/d(joint readings) [unit / rad]


@dataclass
class BlockResult:
    """What one measurement block says about the fit, in its own unit."""

    name: str
    system: str
    unit: str  # the block's unit ('px', 'm', ...)
    sigma: float  # noise per measured number of the final noise model [unit]
    rms_before: float  # inlier units, per axis, nominal model [unit]
    rms_after: float
    max_after: float  # largest inlier unit distance [unit]
    n_units: int  # inlier units (corners, markers)
    sample_rms_before: np.ndarray  # (S_block,) per-axis RMS per sample [unit]
    sample_rms_after: np.ndarray
    outlier_views: list[tuple[int, int]]  # (sample, tag or marker id) of each view left out
    outlier_samples: np.ndarray  # (S_block,) bool: every view of the sample was left out
    class_sigma: np.ndarray  # (C,) noise per measured number of each noise class (`Block.noise_classes`) [unit]


@dataclass
class FittedBlock:
    """What a solved fit knows of one block, for its part of result.yaml (`Block.report`)."""

    result: BlockResult  # the solver's figures of the block
    excluded_units: np.ndarray  # (U,) bool: single units left out by the block's unit rule (`Block.unit_rule`)
    local_values: np.ndarray  # (L,) the block's own unknowns at the solution [SI]
    residual: np.ndarray  # (U, dim) predicted minus measured at the solution [unit]
    chain: ParameterSet  # the fit's robot-model parameters
    chain_values: np.ndarray  # (Pc,) their values at the solution [SI]


class Block:
    """Base of the measurement blocks; subclasses set the fields and implement `linearize`.

    A block describes itself to the solver and the result writer, which know no block by name: its unit and what one
    unit is called, the bounds and starting value of its estimated noise level, its part of result.yaml (`report`)
    and the lines the console summary shows of that part (`summary_lines`)."""

    name: str  # e.g. 'head camera', 'external camera tripod'
    system: str  # the registry's system name (`wolfcal.fit.systems`): 'head' | 'external' | 'floor' | ...
    unit: str  # of the measured numbers: 'px' | 'm' | 'rad'
    unit_name: str = "unit"  # what one unit is, in messages: 'corner', 'marker', ...
    dim: int  # measured numbers per unit
    noise_min: float  # lower bound of the estimated noise level per measured number [unit]
    noise_max: float  # upper bound [unit]
    noise_start: float  # the noise level the fit starts from before estimating it [unit]
    outlier_rule: OutlierRule  # which views are left out (`wolfcal.outliers`; floor in the block's unit)
    # which single units of the views kept are left out (None: none; `OutlierRule.limit` of the robust scale of the
    # units' conditional residuals, `solver.flag_units`)
    unit_rule: OutlierRule | None = None
    nuisance: ParameterSet  # the block's own unknowns
    sample_of_unit: np.ndarray  # (U,) sample index of each unit
    view_of_unit: np.ndarray  # (U,) outlier unit (view) of each unit
    view_labels: list[tuple[int, int]]  # (sample, tag or marker id) of each view
    q_measured: np.ndarray  # (S, J) joint readings of the block's samples [rad]
    # the robot model a solve with this block starts from (`Problem.start`; e.g. where the block alone was solved):
    # None: the fit's references (the nominal model, or the present calibration)
    chain_start: Corrections | None = None

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

    def unit_frames(self) -> np.ndarray | None:
        """(U,) frames averaged into each unit (a still span's mean, `wolfcal.spans`): its own noise is the block's
        level / sqrt(frames), a detection error that repeats at one pose is not averaged. None (default): each unit is
        one measurement."""
        return None

    def unit_scatter(self) -> np.ndarray | None:
        """(U, dim) sum of squared deviations of the frames averaged into each unit about their mean [unit^2]
        (frames - 1 degrees of freedom per number): the noise level is estimated from it too. None with
        `unit_frames` None."""
        return None

    def noise_classes(self) -> np.ndarray:
        """(U,) noise class of each unit: units of one class share a noise level, estimated apart from the other
        classes' (e.g. one per motion-capture marker). Default: one class, the block's level."""
        return np.zeros(self.n_units, dtype=int)

    def linearize(self, chain_values: np.ndarray, local_values: np.ndarray, chain: ParameterSet) -> Linearization:
        raise NotImplementedError

    def start_noise(self, priors: PriorConfig) -> float:
        """The noise level per measured number [unit] the fit and pose planning start from (the robot config's
        priors may set it, e.g. the pixel noise). Default: `noise_start`."""
        return self.noise_start

    def report(self, fitted: FittedBlock) -> dict:
        """The block's entry in result.yaml's `blocks`. Every entry holds `name`, `system`, `unit` (of its figures),
        `n_samples`, `n_outlier_samples`, `n_outlier_views`, `n_units_used` and `samples` (one dict per sample),
        and the figures its `summary_lines` read. Default: the common keys and the RMS before/after."""
        b = fitted.result
        return {
            "name": b.name, "system": b.system, "unit": b.unit,
            "rms_meaning": f"per-axis RMS of the residuals in {b.unit}, inlier units",
            f"rms_before_{b.unit}": round(b.rms_before, 6), f"rms_after_{b.unit}": round(b.rms_after, 6),
            f"max_after_{b.unit}": round(b.max_after, 6), f"noise_sigma_{b.unit}": round(b.sigma, 6),
            "n_samples": len(self.q_measured), "n_outlier_samples": int(np.sum(b.outlier_samples)),
            "n_outlier_views": len(b.outlier_views), "n_units_used": b.n_units,
            "samples": [{"index": i, f"rms_before_{b.unit}": round(float(b.sample_rms_before[i]), 6),
                         f"rms_after_{b.unit}": round(float(b.sample_rms_after[i]), 6),
                         "outlier": bool(b.outlier_samples[i])} for i in range(len(self.q_measured))],
        }  # fmt: skip

    @staticmethod
    def summary_lines(entry: dict) -> list[str]:
        """The console's lines of a block's result.yaml entry (`report`), also of a file read back: samples, left
        out, units used, RMS before -> after (lengths in mm)."""
        u = entry["unit"]
        what, used = ("reprojection", "corners") if u == "px" else ("residual", "residuals")
        scale, shown = (1000.0, "mm") if u == "m" else (1.0, u)
        samples = f"{entry['n_samples']} samples"
        if "n_frames" in entry:  # still spans of a recording (`wolfcal.spans`)
            samples = f"{entry['n_samples']} still spans of {entry['n_frames']} frames"
        return [
            f"{entry['name']}: {samples} ({entry['n_outlier_samples']} left out as outliers, "
            f"{entry['n_outlier_views']} outlier view(s) in all"
            + (f", {entry['n_outlier_corners']} single corner(s) far off" if entry.get("n_outlier_corners") else "")
            + (
                f", {entry['n_frame_views_left_out']} single frame's tag view(s) far from their span left out"
                if entry.get("n_frame_views_left_out")
                else ""
            )
            + f"), {used} used: {entry['n_units_used']}",
            f"  {what} RMS (per axis, inliers): {entry[f'rms_before_{u}'] * scale:.3f} {shown} before -> "
            f"{entry[f'rms_after_{u}'] * scale:.3f} {shown} after (max {entry[f'max_after_{u}'] * scale:.3f} {shown})",
        ]


def held_joint_groups(q_measured: np.ndarray, sample_of_unit: np.ndarray) -> np.ndarray:
    """(U, J) reading groups (`Block.joint_reading_groups`) of samples in which joints held still: per joint, the
    units whose sample read the same encoder tick share that reading's error (the standing legs of floor samples,
    which keep one pose while the head looks around)."""
    ticks = np.round(q_measured / RAD_PER_TICK).astype(np.int64)[sample_of_unit]
    return ticks - ticks.min(axis=0, initial=0)  # labels only: equal tick, equal label (non-negative, not 0..G-1)
