"""`wolfcal demo`: the main job on the shipped demo data: fit the camera pose on `captures/demo.mcap`, then
evaluate it on the held-out `captures/demo_heldout.mcap`; the evaluation prints the before/after table.

The demo captures are simulated (`wolfcal simulate`): the Wolfgang robot's head camera is off by a hand-tuning
error of about 6 degrees; `demo.truth.yaml` beside each capture holds the truth the evaluation compares with.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from wolfcal.errors import WolfcalError
from wolfcal.evaluate.pipeline import run_evaluate
from wolfcal.fit.pipeline import FitOptions, run_fit

DEMO_CAPTURE = Path("captures/demo.mcap")
DEMO_HELDOUT = Path("captures/demo_heldout.mcap")
DEMO_ROBOT = Path("configs/wolfgang/robot.yaml")


def run_demo(root: Path, out: Path, say: Callable[[str], None] = print, force: bool = False) -> dict:
    """Fit and evaluate the demo capture found under `root`; outputs go to `out` (an earlier run's only replaced
    with `force`). Returns the metrics."""
    capture, heldout, robot = root / DEMO_CAPTURE, root / DEMO_HELDOUT, root / DEMO_ROBOT
    missing = [str(p) for p in (capture, heldout, robot) if not p.exists()]
    if missing:
        raise WolfcalError(
            f"demo data not found: {', '.join(missing)}; run `wolfcal demo` from the wolfcal repository root "
            "(where captures/ and configs/ are) or pass --root PATH"
        )
    fit_dir, report_dir = out / "fit", out / "report"
    say(f"== wolfcal fit {capture} --free camera --out {fit_dir}")
    run_fit([capture], robot, fit_dir, FitOptions(free="camera"), say=say, force=force)
    say(f"\n== wolfcal evaluate {fit_dir} --capture {heldout} --out {report_dir}")
    return run_evaluate(fit_dir, [heldout], report_dir, say=say, force=force)
