"""Signals during a capture. SIGTERM and SIGHUP (`timeout`, `kill`, a closed ssh session) stop a capture the
way Ctrl-C does, so the file is finished and the torque left as --exit-torque says; while the torque is being
restored, SIGINT, SIGTERM and SIGHUP are only noted, so a second Ctrl-C cannot cut the restoring short.

Python delivers signals to the main thread only; in other threads (tests) these helpers change nothing.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class Stopped(KeyboardInterrupt):
    """The process was asked to stop by a signal; the CLI exits with 128 + the signal number."""

    def __init__(self, signum: int) -> None:
        self.signum = int(signum)
        super().__init__(f"stopped by {signal.Signals(signum).name}")


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """Inside the block, SIGTERM and SIGHUP raise `Stopped` (as Ctrl-C raises KeyboardInterrupt)."""
    if not _main_thread():
        yield
        return

    def stop(signum: int, frame) -> None:
        raise Stopped(signum)

    previous = {signum: signal.signal(signum, stop) for signum in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


@contextmanager
def signals_held() -> Iterator[list[int]]:
    """Inside the block, SIGINT, SIGTERM and SIGHUP are noted in the yielded list instead of acted on."""
    noted: list[int] = []
    if not _main_thread():
        yield noted
        return
    previous = {
        signum: signal.signal(signum, lambda s, frame: noted.append(s)) for signum in (signal.SIGINT, *STOP_SIGNALS)
    }
    try:
        yield noted
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def interruption(signums: list[int]) -> KeyboardInterrupt | None:
    """The exception for the first of the noted signals (KeyboardInterrupt for SIGINT), or None."""
    if not signums:
        return None
    return KeyboardInterrupt() if signums[0] == signal.SIGINT else Stopped(signums[0])
