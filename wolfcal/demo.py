"""`wolfcal demo`: the venue workflow on simulated captures, then the refusal that protects it; runs from any folder.

0. The demo captures are simulated first, with fixed seeds, into OUT/captures (`wolfcal simulate`, the commands are
   printed), for the packaged Wolfgang robot: the same captures on every machine, and none shipped in the package.
   The head camera is off by a hand-tuning error of about 6 degrees (legs calibrated) in 1, the leg encoders by
   0.025 rad rms in 2; the `*.truth.yaml` beside each capture holds the truth the evaluation compares with.
1. At a venue: fit the camera pose on the feet capture `demo.mcap` together with the floor capture
   `floor_demo.mcap`, then evaluate it on the held-out feet and floor captures (`demo_heldout.mcap`,
   `floor_demo_heldout.mcap`): before/after in pixels and on the field, the ground error measured on the held-out
   floor views beside the simulator's truth, and the files to deploy.
2. A robot whose legs are off (`legs_demo.mcap`): a camera-only fit cannot undo the leg offsets; its evaluation
   (cross-validation) refuses the files to deploy and says that the legs need calibration.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

from wolfcal.config import packaged_robot
from wolfcal.evaluate.deploy import DEPLOY_FILES
from wolfcal.evaluate.pipeline import REPORT_FILES, run_evaluate
from wolfcal.fit.pipeline import FIT_OUTPUTS, FitOptions, run_fit
from wolfcal.io.truth import truth_paths
from wolfcal.outputs import check_output_folder, check_outputs
from wolfcal.sim.simulate import SimOptions, simulate_capture

# The demo captures: file name -> `wolfcal simulate` options. The held-out and floor captures reuse the truth of
# demo.mcap (the same robot); floor views are noise-free, as the check at a venue averages many more of them.
SIMULATIONS: dict[str, dict] = {
    "demo.mcap": {"samples": 24, "seed": 7, "binning": 4, "outliers": 0.08},
    "demo_heldout.mcap": {"samples": 12, "seed": 8, "binning": 4, "truth": "demo.truth.yaml"},
    "floor_demo.mcap": {"floor": True, "samples": 8, "seed": 36, "binning": 4, "noise": 0, "truth": "demo.truth.yaml"},
    "floor_demo_heldout.mcap": {"floor": True, "samples": 16, "seed": 30, "binning": 4, "noise": 0,
                                "truth": "demo.truth.yaml"},
    "legs_demo.mcap": {"offsets": "legs", "samples": 12, "seed": 21, "binning": 4, "noise": 0},
}  # fmt: skip
# option of `wolfcal simulate` -> field of SimOptions
_FIELDS = {"samples": "samples", "seed": "seed", "binning": "binning", "outliers": "outlier_fraction",
           "noise": "noise_sigma", "floor": "floor", "offsets": "offsets", "truth": "truth_file"}  # fmt: skip


def simulate_command(name: str, folder: Path) -> tuple[str, SimOptions]:
    """The `wolfcal simulate` command line of the demo capture `name` written into `folder`, and its options."""
    spec = SIMULATIONS[name]
    values = {key: folder / value if key == "truth" else value for key, value in spec.items()}
    words = [f"--{key}" if value is True else f"--{key} {value}" for key, value in values.items()]
    options = SimOptions(**{_FIELDS[key]: value for key, value in values.items()})
    return f"wolfcal simulate {' '.join(words)} --out {folder / name}", options


def run_demo(out: Path, say: Callable[[str], None] = print, force: bool = False) -> dict[str, dict]:
    """Simulate the demo captures into out/captures, then run both parts; outputs go to `out` (an earlier run's are
    only replaced with `force`; all are checked before any work, and a run that fails removes the `out` it made).
    Returns the metrics of each evaluation: {'venue': ..., 'legs': ...}."""
    out = Path(out)
    robot = packaged_robot() / "robot.yaml"
    captures = out / "captures"
    check_outputs([p for name in SIMULATIONS for p in (captures / name, *truth_paths(captures / name))], force)
    for part in ("fit", "legs_fit"):
        check_output_folder(out / part, FIT_OUTPUTS, force)
    for part in ("report", "legs_report"):
        check_output_folder(out / part, REPORT_FILES + DEPLOY_FILES, force)
    made = not out.exists()
    try:
        _simulate(robot, captures, say, force)
        return _run_parts(robot, captures, out, say, force)
    except BaseException:
        if made:
            shutil.rmtree(out, ignore_errors=True)
        raise


def _simulate(robot: Path, captures: Path, say: Callable[[str], None], force: bool) -> None:
    say(f"==== 0. The demo captures, simulated with fixed seeds for the Wolfgang robot ({robot.parent})")
    for name in SIMULATIONS:
        command, options = simulate_command(name, captures)
        say(f"== {command}")
        simulate_capture(robot, captures / name, options, say=lambda _: None, force=force)


def _run_parts(robot: Path, captures: Path, out: Path, say: Callable[[str], None], force: bool) -> dict[str, dict]:
    say("\n==== 1. At a venue: feet and floor samples -> fit -> evaluate with the ground error measured on the floor")
    fit_dir, report_dir = out / "fit", out / "report"
    fitted = [captures / "demo.mcap", captures / "floor_demo.mcap"]
    heldout = [captures / "demo_heldout.mcap", captures / "floor_demo_heldout.mcap"]
    say(f"== wolfcal fit {' '.join(map(str, fitted))} --free camera --out {fit_dir}")
    run_fit(fitted, robot, fit_dir, FitOptions(free="camera"), say=say, force=force)
    say(f"\n== wolfcal evaluate {fit_dir} {' '.join(f'--capture {p}' for p in heldout)} --out {report_dir}")
    venue = run_evaluate(fit_dir, heldout, report_dir, say=say, force=force)
    say("\n==== 2. A robot whose legs are off: a camera fit must not be deployed")
    fit_dir, report_dir = out / "legs_fit", out / "legs_report"
    say(f"== wolfcal fit {captures / 'legs_demo.mcap'} --free camera --out {fit_dir}")
    run_fit([captures / "legs_demo.mcap"], robot, fit_dir, FitOptions(free="camera"), say=say, force=force)
    say(f"\n== wolfcal evaluate {fit_dir} --out {report_dir}   (no held-out capture: cross-validation)")
    legs = run_evaluate(fit_dir, [], report_dir, say=say, force=force)
    return {"venue": venue, "legs": legs}
