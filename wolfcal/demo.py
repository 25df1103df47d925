"""`wolfcal demo`: the venue workflow on the shipped demo data, then the refusal that protects it.

1. At a venue: fit the camera pose on the feet capture `captures/demo.mcap` together with the floor capture
   `captures/floor_demo.mcap`, then evaluate it on the held-out feet and floor captures (`demo_heldout.mcap`,
   `floor_demo_heldout.mcap`): before/after in pixels and on the field, the ground error measured on the held-out
   floor views beside the simulator's truth, and the files to deploy.
2. A robot whose legs are off (`captures/legs_demo.mcap`): a camera-only fit cannot undo the leg offsets; its
   evaluation (cross-validation) refuses the files to deploy and says that the legs need calibration.

The demo captures are simulated (`wolfcal simulate`, commands in README.md): the Wolfgang robot's head camera is off by
a hand-tuning error of about 6 degrees (legs calibrated) in 1, leg encoder offsets of 0.025 rad rms in 2; the
`*.truth.yaml` beside each capture holds the truth the evaluation compares with.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from wolfcal.errors import WolfcalError
from wolfcal.evaluate.pipeline import run_evaluate
from wolfcal.fit.pipeline import FitOptions, run_fit

DEMO_CAPTURE = Path("captures/demo.mcap")
DEMO_HELDOUT = Path("captures/demo_heldout.mcap")
FLOOR_CAPTURE = Path("captures/floor_demo.mcap")
FLOOR_HELDOUT = Path("captures/floor_demo_heldout.mcap")
LEGS_CAPTURE = Path("captures/legs_demo.mcap")
DEMO_ROBOT = Path("configs/wolfgang/robot.yaml")


def run_demo(root: Path, out: Path, say: Callable[[str], None] = print, force: bool = False) -> dict[str, dict]:
    """Run both parts on the demo data found under `root`; outputs go to `out` (an earlier run's only replaced with
    `force`). Returns the metrics of each evaluation: {'venue': ..., 'legs': ...}."""
    inputs = [DEMO_CAPTURE, FLOOR_CAPTURE, DEMO_HELDOUT, FLOOR_HELDOUT, LEGS_CAPTURE, DEMO_ROBOT]
    missing = [str(root / p) for p in inputs if not (root / p).exists()]
    if missing:
        raise WolfcalError(
            f"demo data not found: {', '.join(missing)}; run `wolfcal demo` from the wolfcal repository root "
            "(where captures/ and configs/ are) or pass --root PATH"
        )
    robot = root / DEMO_ROBOT
    say("==== 1. At a venue: feet and floor samples -> fit -> evaluate with the ground error measured on the floor")
    fit_dir, report_dir = out / "fit", out / "report"
    captures, heldout = [root / DEMO_CAPTURE, root / FLOOR_CAPTURE], [root / DEMO_HELDOUT, root / FLOOR_HELDOUT]
    say(f"== wolfcal fit {' '.join(map(str, captures))} --free camera --out {fit_dir}")
    run_fit(captures, robot, fit_dir, FitOptions(free="camera"), say=say, force=force)
    say(f"\n== wolfcal evaluate {fit_dir} {' '.join(f'--capture {p}' for p in heldout)} --out {report_dir}")
    venue = run_evaluate(fit_dir, heldout, report_dir, say=say, force=force)
    say("\n==== 2. A robot whose legs are off: a camera fit must not be deployed")
    fit_dir, report_dir = out / "legs_fit", out / "legs_report"
    say(f"== wolfcal fit {root / LEGS_CAPTURE} --free camera --out {fit_dir}")
    run_fit([root / LEGS_CAPTURE], robot, fit_dir, FitOptions(free="camera"), say=say, force=force)
    say(f"\n== wolfcal evaluate {fit_dir} --out {report_dir}   (no held-out capture: cross-validation)")
    legs = run_evaluate(fit_dir, [], report_dir, say=say, force=force)
    return {"venue": venue, "legs": legs}
