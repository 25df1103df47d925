"""Progress of long steps (reading recordings, detecting tags) as a `(done, total)` callback that prints a line
at most every few seconds: how far, how fast, and about how long is left. Short steps print nothing."""

from __future__ import annotations

import time
from collections.abc import Callable

INTERVAL_S = 2.0  # seconds between two progress lines


def _duration(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


class Progress:
    """Call with (done, total) as work proceeds; says e.g. "detecting tags: 120/480 samples, 35.2 samples/s,
    about 10 s left". `clock` [s] is injectable for tests."""

    def __init__(
        self,
        say: Callable[[str], None],
        what: str,
        unit: str,
        interval_s: float = INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.say, self.what, self.unit, self.interval_s, self.clock = say, what, unit, interval_s, clock
        self.start = clock()
        self.last_said: float | None = None

    def __call__(self, done: int, total: int) -> None:
        now = self.clock()
        elapsed = now - self.start
        finished = total > 0 and done >= total
        if finished:
            if self.last_said is not None:  # close a report that was started; short steps stay silent
                rate = f", {done / elapsed:.1f} {self.unit}/s" if elapsed > 0 else ""
                self.say(f"{self.what}: {done}/{total} {self.unit} in {_duration(elapsed)}{rate}")
                self.last_said = None
            return
        since = now - (self.last_said if self.last_said is not None else self.start)
        if since < self.interval_s or done <= 0:
            return
        self.last_said = now
        per_s = done / elapsed
        left = f", about {_duration((total - done) / per_s)} left" if total > done else ""
        of = f"/{total}" if total > 0 else ""
        self.say(f"{self.what}: {done}{of} {self.unit}, {per_s:.1f} {self.unit}/s{left}")
