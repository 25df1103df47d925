"""What every evaluation's metrics.json begins with: which wolfcal wrote it, when (UTC), on which robot config and,
for a judged fit, from which fit folder with which parameters free."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import wolfcal
from wolfcal.robot.robot import Robot


def provenance(robot: Robot, fit_dir: str | Path | None = None, free: str | None = None) -> dict:
    """The head of a metrics mapping: `wolfcal_version`, `created` (ISO 8601, UTC, seconds), `fit_dir` (absolute;
    only when given), `robot` (the config's path), `robot_name`, `free` (only when given)."""
    head: dict = {
        "wolfcal_version": wolfcal.__version__,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    if fit_dir is not None:
        head["fit_dir"] = str(Path(fit_dir).resolve())
    head |= {"robot": str(robot.config.path), "robot_name": robot.config.name}
    if free is not None:
        head["free"] = free
    return head
