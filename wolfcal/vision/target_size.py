"""The one rule on the size of a printed target: a tag edge, a board square or a ChArUco marker, in metres.

A printed calibration target is a sheet or a plate, so its tag or square edges lie between a few millimetres and
MAX_PRINTED_EDGE_M. A value above that is almost always millimetres typed where metres are asked for (`--size 80`
for an 80 mm tag): it is refused with the value it probably meant, before any work (a sheet of 80 m tags would
need terabytes of pixels).
"""

from __future__ import annotations

import math

from wolfcal.errors import WolfcalError

MAX_PRINTED_EDGE_M = 0.5  # largest tag or square edge a printed target has [m]


def check_printed_edge(value: float, where: str) -> float:
    """`value` [m] if it is a positive finite length of at most MAX_PRINTED_EDGE_M; else WolfcalError naming
    `where` (an option such as '--size', or a config file and key) and, above the limit, the value in metres."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise WolfcalError(f"{where} {value!r}: must be a positive length in metres")
    if value > MAX_PRINTED_EDGE_M:
        raise WolfcalError(
            f"{where} {value:g}: {value:g} m is larger than a printed target can be "
            f"(at most {MAX_PRINTED_EDGE_M:g} m); did you mean millimetres? The unit is metres: "
            f"{value / 1000:g} for {value:g} mm"
        )
    return float(value)
