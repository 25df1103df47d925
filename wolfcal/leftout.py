"""How much data may be left out before a result stops meaning what it says.

The outlier rule is there for a blurred image or a stale joint reading now and then, not to absorb unusable
data: when more than `MAX_LEFT_OUT` of the samples, tag views or joint readings are left out, `wolfcal fit`
fails, `wolfcal evaluate` refuses, and the readers reject the file, each with what was left out and why.
"""

from __future__ import annotations

from wolfcal.errors import WolfcalError

MAX_LEFT_OUT = 0.2  # largest share of samples / tag views / joint readings that may be left out


def too_many(left_out: int, total: int) -> bool:
    """Whether `left_out` of `total` is more than `MAX_LEFT_OUT`."""
    return total > 0 and left_out > MAX_LEFT_OUT * total


def check_left_out(counts: dict[str, tuple[int, int]], where: str, advice: str) -> None:
    """WolfcalError when any (left out, total) of `counts` (keyed by what is counted, e.g. "samples") is
    more than `MAX_LEFT_OUT`; `where` names the files, `advice` says what to do."""
    over = [f"{n} of {total} {what} ({n / total:.0%})" for what, (n, total) in counts.items() if too_many(n, total)]
    if over:
        raise WolfcalError(
            f"{where}: {' and '.join(over)} left out as outliers, more than the {MAX_LEFT_OUT:.0%} the outlier "
            f"rule may absorb; {advice}"
        )
