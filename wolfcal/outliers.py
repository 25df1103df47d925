"""The one outlier rule of wolfcal: a unit (a view, a sample, an edge point) is left out when it is far worse than
the typical one AND off by more than a floor.

    outlier = (spread > factor * median(spread over all units)) & (size > floor)

`spread` is how badly the unit fits relative to what is expected (the fit: its residuals whitened by the noise model;
elsewhere the plain RMS), `size` how far off it is in the measured unit (pixels, metres). The factor says "far worse
than the others"; the floor keeps a good data set (every unit near the noise) from losing its best-but-one units, since
a median of tiny numbers times a factor is still tiny. The parameter sets below are the only places the numbers live;
where they differ, the reason is given beside them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class OutlierRule:
    factor: float  # a unit is an outlier above this multiple of the median unit's spread ...
    floor: float  # ... and only when also off by more than this [the unit's measure, e.g. px]

    def flags(self, spread: np.ndarray, size: np.ndarray | None = None) -> np.ndarray:
        """(N,) bool outliers among units with `spread` (N,) and `size` (N,) (default: size = spread); NaN units
        (nothing measured) are never outliers and do not count in the median."""
        spread = np.asarray(spread, dtype=float)
        size = spread if size is None else np.asarray(size, dtype=float)
        finite = np.isfinite(spread)
        if not finite.any():
            return np.zeros(spread.shape, dtype=bool)
        limit = self.factor * float(np.median(spread[finite]))
        with np.errstate(invalid="ignore"):
            return finite & (spread > limit) & (size > self.floor)

    def limit(self, median_spread: np.ndarray) -> np.ndarray:
        """Where spread = size (a plain distance), the largest a unit may be and not be an outlier:
        max(floor, factor * median), per group of units given each group's median spread (any shape)."""
        return np.maximum(self.floor, self.factor * median_spread)


# The fit's tag views (one tag in one image): spread = whitened RMS under the view's own noise covariance (the
# noise model knows the joint-reading error each view carries), size = per-axis RMS [px].
FIT_VIEW_PX = OutlierRule(factor=4.0, floor=0.5)

# A frame's view of a tag within a still span of a recording, before the span's frames are averaged
# (`wolfcal.spans`): spread = size = per-axis RMS distance of its corners from the span's per-corner median [px]. As
# the fit's views: a misdetected frame is off by pixels, the detector's frame-to-frame noise by a tenth of one.
SPAN_FRAME_PX = OutlierRule(factor=4.0, floor=0.5)

# Floor-tag corners, one corner of a view (the views kept by the view rule): limit (`OutlierRule.limit`) at this
# factor times the robust residual scale (per axis) of the corners counted, size = the corner's distance from where
# the fitted floor puts it, the view's joint-reading errors taken into account [px]. Per corner, not per view: on a
# small, strongly foreshortened far tag one corner slides along an edge by 1-5 px while the view's other three fit.
# Used by the measured ground error (`evaluate.floor_ground`: raw pixels, the readings' errors fitted as unknowns)
# and by the fit's floor block (`Block.unit_rule`, `fit.solver.flag_units`: the block's residual, distances from
# the edges' lines, less the view's share of the readings' errors under the noise model).
FLOOR_CORNER_PX = OutlierRule(factor=4.0, floor=0.3)

# Motion-capture markers, one marker in one sample: spread = whitened RMS, size = per-axis RMS [m]. Tighter factor:
# a reflection 2 mm away is 4-7 noise sigmas at 0.3 mm marker noise and must still be caught; the floor (1 mm) is
# about three times the raw per-axis noise.
MOCAP_MARKER_M = OutlierRule(factor=3.0, floor=0.001)

# The closure of the standing soles (both on one plane), per floor sample [m]: a sample is left out only when the
# soles disagree by more than 5 mm beyond the others (a foot not flat on the floor).
SOLE_CLOSURE_M = OutlierRule(factor=4.0, floor=0.005)

# Held-out evaluation, per sample: held-out data have no noise model (nothing is fitted on them), so spread = size =
# the plain per-axis RMS [px] of the sample under the better model. That RMS still carries the joint-reading error
# the fit's noise model whitens away (larger on far tags), so the floor is twice the fit's. The unit is the sample,
# not the view: a stale joint reading or a blurred image spoils every tag of the sample.
HELD_OUT_SAMPLE_PX = OutlierRule(factor=4.0, floor=1.0)

# Sub-pixel points of one tag edge near a corner (`vision.edges`), per point: spread = size = its distance [px]
# from the first fit of the edge, the median taken over the edge's points. A crisp edge's points lie a few
# hundredths of a pixel off, so the floor keeps them all; dirt, glare or a wrong crossing lie further off.
EDGE_POINT_PX = OutlierRule(factor=4.0, floor=0.3)

# Intrinsics, per board view: spread = size = the per-POINT RMS [px] (sqrt(mean(du^2 + dv^2)), OpenCV's convention,
# not per axis) of the view after OpenCV's calibration, applied to the worst view only and repeated after each
# recalibration (so no view is judged under another outlier's pull; at most a third of the views are dropped).
# Board corners carry no joint-reading error, so a good view's RMS is lower than a tag view's and so is the floor.
INTRINSICS_VIEW_PX = OutlierRule(factor=3.0, floor=0.25)
