"""Bad inputs through the real command line (`python -m wolfcal.cli ...` in a subprocess), one case each: the
inputs made in a temporary folder (a simulated capture and faulty copies of it, broken camera_info files and URDFs,
outputs of earlier runs); per case the exit code, whether a traceback was printed, whether every input file is
unchanged, and the message wolfcal gave (`tests/e2e/test_bad_inputs.py` runs them all).

`python tests/e2e/bad_input_cases.py [--keep]` prints one line per case and exits 1 if any fails."""

from __future__ import annotations

import argparse
import hashlib
import math
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from wolfcal.config import load_robot_config
from wolfcal.hardware.bus import DynamixelBus
from wolfcal.sim.faulty import rewrite_capture, with_camera_info, with_damaged_image, with_joint_values

ROOT = Path(__file__).resolve().parents[2]
ROBOT = ROOT / "configs" / "wolfgang"
TIMEOUT_S = 600


@dataclass
class Case:
    name: str
    args: list[str]
    code: int  # expected exit code
    says: str  # expected in the output
    inputs: list[Path] = field(default_factory=list)  # must be unchanged afterwards
    not_created: list[Path] = field(default_factory=list)  # must not exist afterwards


@dataclass
class Outcome:
    code: int
    output: str
    unchanged: bool
    extra_ok: bool = True


def wolfcal(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "wolfcal.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=TIMEOUT_S)  # fmt: skip


def digests(paths: list[Path]) -> dict[Path, str | None]:
    out: dict[Path, str | None] = {}
    for path in paths:
        files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
        for f in files:
            out[f] = hashlib.sha256(f.read_bytes()).hexdigest() if f.is_file() else None
    return out


def message(output: str) -> str:
    """The line a user reads first: the error, else the first warning, else the last line."""
    lines = [line.strip() for line in output.splitlines() if line.strip()]
    for prefix in ("error:", "warning:"):
        found = [line for line in lines if line.startswith(prefix)]
        if found:
            return found[0]
    return lines[-1] if lines else ""


def camera_yaml(folder: Path, name: str, **change) -> Path:
    data = yaml.safe_load((ROBOT / "basler_acA2040.yaml").read_text())
    data.update(change)
    path = folder / name
    path.write_text(yaml.safe_dump(data))
    return path


def matrix(*values: float) -> dict:
    return {"rows": 3, "cols": 3, "data": list(values)}


def broken_robot(folder: Path, name: str, edit: Callable[[str], str]) -> Path:
    robot = folder / name
    shutil.copytree(ROBOT, robot)
    urdf = robot / "wolfgang.urdf"
    urdf.write_text(edit(urdf.read_text()))
    return robot


def make_cases(w: Path) -> list[Case]:
    """The inputs in folder `w`, and the cases."""
    good = w / "good.mcap"
    assert wolfcal(["simulate", "--robot", ROBOT, "--out", good, "--samples", 16, "--seed", 4, "--binning", 4],
                   w).returncode == 0  # fmt: skip
    held = w / "held_outliers.mcap"
    assert wolfcal(["simulate", "--robot", ROBOT, "--out", held, "--samples", 12, "--seed", 9, "--binning", 4,
                    "--outliers", 0.6, "--truth", w / "good.truth.yaml"], w).returncode == 0  # fmt: skip
    outliers = w / "outliers.mcap"
    assert wolfcal(["simulate", "--robot", ROBOT, "--out", outliers, "--samples", 16, "--seed", 4, "--binning", 4,
                    "--outliers", 0.5], w).returncode == 0  # fmt: skip
    assert wolfcal(["fit", good, "--robot", ROBOT, "--out", w / "fit"], w).returncode == 0
    joints, image, info = "/joint_states", "/camera/image_proc/compressed", "/camera/camera_info"
    faults = {
        "nan_half.mcap": with_joint_values(joints, range(0, 16, 2), "HeadTilt", math.nan),
        "inf_half.mcap": with_joint_values(joints, range(0, 16, 2), "RKnee", math.inf),
        "nan_one.mcap": with_joint_values(joints, [3], "HeadTilt", math.nan),
        "damaged_image.mcap": with_damaged_image(image, 5),
        "info_fx0.mcap": with_camera_info(info, k=[0.0, 0, 1015.8, 0, 1334.4, 727.0, 0, 0, 1]),
    }
    for name, edit in faults.items():
        rewrite_capture(good, w / name, edit)
    cams = {
        "fx0": camera_yaml(w, "fx0.yaml", camera_matrix=matrix(0, 0, 1015.8, 0, 1334.4, 727, 0, 0, 1)),
        "fy<0": camera_yaml(w, "fyneg.yaml", camera_matrix=matrix(1336.2, 0, 1015.8, 0, -1334.4, 727, 0, 0, 1)),
        "fx nan": camera_yaml(w, "fxnan.yaml", camera_matrix=matrix(math.nan, 0, 1015.8, 0, 1334.4, 727, 0, 0, 1)),
        "8 numbers": camera_yaml(w, "k8.yaml", camera_matrix={"rows": 3, "cols": 3, "data": [1336.2, 0, 1015.8, 0,
                                                                                             1334.4, 727, 0, 0]}),
        "rows 2": camera_yaml(w, "rows2.yaml", camera_matrix={"rows": 2, "cols": 3, "data": [1336.2, 0, 1015.8, 0,
                                                                                             1334.4, 727, 0, 0, 1]}),
        "640x480": camera_yaml(w, "vga.yaml", image_width=640, image_height=480,
                               camera_matrix=matrix(500, 0, 320, 0, 500, 240, 0, 0, 1)),
    }  # fmt: skip
    entity = broken_robot(w, "robot_entity", lambda t: t.replace('<link name="base_link"/>',
                                                                 '<link name="base_link"/>&nbsp;', 1))  # fmt: skip
    unclosed = broken_robot(w, "robot_unclosed", lambda t: t.replace("</robot>", ""))
    (w / "a_file").write_text("not a folder")
    existing = w / "existing.mcap"
    shutil.copy(good, existing)
    torn = w / "torn.mcap.partial"
    torn.write_bytes(good.read_bytes()[: good.stat().st_size // 3])
    (w / "camera_out.yaml").write_text("an earlier calibration\n")
    (w / "sheet.pdf").write_text("an earlier sheet\n")
    partial_fit = w / "fit_without_urdf"
    partial_fit.mkdir()
    shutil.copy(w / "fit" / "result.yaml", partial_fit / "result.yaml")
    captures = w / "captures"
    captures.mkdir()
    shutil.copy(good, captures / "game3.mcap")
    every = [good, w / "fit", ROBOT]

    def fit(capture: Path, says: str, code: int = 2, *extra, out: Path | None = None, name: str = "") -> Case:
        new = out is None
        out = out or w / f"fit_{capture.stem}_{len(extra)}"
        name = name or f"fit {capture.name} {' '.join(Path(str(e)).name for e in extra)}".strip()
        return Case(name, ["fit", capture, "--robot", ROBOT, "--out", out, *extra], code, says, [capture, *every],
                    [out / "result.yaml"] if new and code else [])  # fmt: skip

    nan_half = "8 of 16 joint state(s) on /joint_states hold NaN or infinite positions"

    cases = [
        fit(w / "nan_half.mcap", f"{nan_half} (HeadTilt 8x)"),
        fit(w / "inf_half.mcap", f"{nan_half} (RKnee 8x)"),
        fit(w / "nan_one.mcap", "1 of 16 joint state(s) on /joint_states hold NaN", 0),
        fit(outliers, "left out as outliers, more than the 20%"),
        Case(
            "evaluate: held-out capture with 60 % outliers",
            ["evaluate", w / "fit", "--capture", held, "--out", w / "report_outliers"],
            2,
            "evaluation refuses",
            [held, *every],
            [w / "report_outliers"],
        ),
        fit(w / "info_fx0.mcap", "CameraInfo on /camera/camera_info: 'k[0]' (fx) is 0"),
        *[
            fit(good, f"{cams[name]}: {says}", 2, "--intrinsics", cams[name])
            for name, says in (
                ("fx0", "'camera_matrix.data[0]' (fx) is 0"),
                ("fy<0", "'camera_matrix.data[4]' (fy) is -1334.4"),
                ("fx nan", "'camera_matrix.data[0]' is nan"),
                ("8 numbers", "'camera_matrix.data' must have 9 numbers"),
                ("rows 2", "'camera_matrix.rows' is 2"),
            )
        ],
        fit(good, "say 640x480 px, the images are 512x384 px", 2, "--intrinsics", cams["640x480"]),
        Case(
            "recover --out an existing capture",
            ["recover", torn, "--out", existing],
            2,
            "existing.mcap exists; pass --force",
            [torn, existing],
        ),
        Case(
            "recover --out the torn file itself, --force",
            ["recover", torn, "--out", torn, "--force"],
            2,
            "never overwrites the torn file",
            [torn],
        ),
        Case(
            "simulate --out an existing capture",
            ["simulate", "--robot", ROBOT, "--out", existing, "--samples", 2],
            2,
            "exists; pass --force",
            [existing, w / "existing.truth.yaml"],
        ),
        Case(
            "capture --out an existing capture",
            ["capture", "--robot", ROBOT, "--port", "/dev/ttyNOPE", "--camera", "sim", "--manual", "--out", existing],
            2,
            "exists; pass --force",
            [existing],
        ),
        fit(good, "is a file, not a folder", 2, out=w / "a_file", name="fit --out an existing file"),
        fit(good, "is a file, not a folder", 2, out=w / "a_file" / "fit", name="fit --out below a file"),
        fit(good, "pass --force", 2, out=w / "fit", name="fit --out an earlier fit"),
        Case(
            "fit with a URDF with an undefined entity",
            ["fit", good, "--robot", entity, "--out", w / "fit_entity"],
            2,
            "not a well-formed URDF: Entity 'nbsp' not defined",
            [good, entity],
            [w / "fit_entity"],
        ),
        Case(
            "fit with a URDF without </robot>",
            ["fit", good, "--robot", unclosed, "--out", w / "fit_unclosed"],
            2,
            "not a well-formed URDF: Premature end of data",
            [good, unclosed],
            [w / "fit_unclosed"],
        ),
        Case(
            "evaluate --out the fit folder (its input)",
            ["evaluate", w / "fit", "--capture", w / "damaged_image.mcap", "--out", w / "fit"],
            2,
            "input of the command",
            every,
        ),
        Case(
            "intrinsics --out an existing camera_info",
            ["intrinsics", w / "imgs", "--board", "9x6", "--square", "0.025", "--out", w / "camera_out.yaml"],
            2,
            "camera_out.yaml exists; pass --force",
            [w / "camera_out.yaml"],
        ),
        Case(
            "board --out an existing sheet",
            ["board", "--board", "9x6", "--square", "0.02", "--out", w / "sheet"],
            2,
            "sheet.pdf exists; pass --force",
            [w / "sheet.pdf"],
            [w / "sheet.png"],
        ),
        fit(w / "damaged_image.mcap", "image 6 of 16 (10.000 s after the first): png checksum error", 0),
        Case(
            "emulate --fault no-answer:99",
            ["emulate", "--robot", ROBOT, "--fault", "no-answer:99"],
            2,
            "--fault no-answer:99: no servo with this id",
            [ROBOT],
        ),
        Case(
            "tags --ids 5-2",
            ["tags", "--ids", "5-2", "--size", "0.05", "--out", w / "t52"],
            2,
            "the range 5-2 runs backwards; write 2-5",
            [],
            [w / "t52.pdf"],
        ),
        Case(
            "fit a folder given as capture",
            ["fit", captures, "--robot", ROBOT, "--out", w / "fit_folder"],
            2,
            "is a folder, not a capture file; give the .mcap file(s) in it",
            [captures],
            [w / "fit_folder"],
        ),
        Case(
            "evaluate a fit folder without calibrated.urdf",
            ["evaluate", partial_fit, "--out", w / "report_p"],
            2,
            "not a complete fit folder (calibrated.urdf, calibrated_robot.yaml missing)",
            [partial_fit],
            [w / "report_p"],
        ),
        Case("intrinsics --help shows units", ["intrinsics", "--help"], 0, "Square edge [m]."),
        Case(
            "tags --ids 42-44 --size 0.08 on A4 (README)",
            ["tags", "--ids", "42-44", "--size", "0.08", "--out", w / "tags"],
            0,
            "tags-p2.png",
        ),
    ]
    return cases


def run_case(case: Case, w: Path) -> Outcome:
    before = digests(case.inputs)
    result = wolfcal(case.args, w)
    return Outcome(result.returncode, result.stdout + result.stderr, digests(case.inputs) == before,
                   not any(p.exists() for p in case.not_created))  # fmt: skip


def sigterm_capture(w: Path) -> tuple[str, Outcome]:
    """SIGTERM to `wolfcal capture` against `wolfcal emulate`: torque left as found, file finished, exit 143."""
    config = load_robot_config(ROBOT)
    emulator = subprocess.Popen([sys.executable, "-m", "wolfcal.cli", "emulate", "--robot", str(ROBOT)], cwd=w,
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)  # fmt: skip
    out = w / "stopped.mcap"
    try:
        port = emulator.stdout.readline().strip()
        with DynamixelBus(config.servos, port) as bus:
            bus.set_torque(["HeadPan"], True)
            initial = bus.torque_enabled()
        capture = subprocess.Popen([sys.executable, "-m", "wolfcal.cli", "capture", "--robot", str(ROBOT), "--port",
                                    port, "--camera", "sim", "--poses", str(ROBOT / "poses.yaml"), "--velocity", "5",
                                    "--out", str(out)], cwd=w, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                   text=True)  # fmt: skip
        for line in capture.stderr:
            if line.startswith("sample 2"):
                break
        capture.send_signal(signal.SIGTERM)
        output = capture.stderr.read()
        capture.wait(TIMEOUT_S)
        with DynamixelBus(config.servos, port) as bus:
            after = bus.torque_enabled()
    finally:
        emulator.send_signal(signal.SIGTERM)
        emulator.wait(TIMEOUT_S)
    ok = after == initial and out.is_file() and capture.returncode == 143 and "stopped by SIGTERM" in output
    text = output + f"\ntorque as found: {after == initial}"
    return "stopped by SIGTERM", Outcome(capture.returncode, text, True, ok)


def line(name: str, expected: str, outcome: Outcome, code: int) -> tuple[bool, str]:
    traceback = "Traceback" in outcome.output
    ok = outcome.code == code and not traceback and expected in outcome.output and outcome.unchanged
    ok = ok and outcome.extra_ok
    said = message(outcome.output)
    if expected not in said:  # show the line that has what was expected
        said = next((x.strip() for x in outcome.output.splitlines() if expected in x), said)
    unchanged = "unchanged" if outcome.unchanged else "CHANGED"
    return ok, (f"{'PASS' if ok else 'FAIL'}  {name:<46} exit {outcome.code:>3}  "
                f"{'TRACEBACK' if traceback else 'no traceback'}  inputs {unchanged}  | {said[:220]}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--keep", action="store_true", help="keep the temporary folder and print its path")
    args = parser.parse_args()
    w = Path(tempfile.mkdtemp(prefix="wolfcal-bad-inputs-"))
    try:
        cases = make_cases(w)
        results = [line(c.name, c.says, run_case(c, w), c.code) for c in cases]
        name, outcome = sigterm_capture(w)
        results.append(line("capture stopped by SIGTERM (torque as found)", name, outcome, 143))
    finally:
        if args.keep:
            print(f"inputs and outputs kept in {w}")
        else:
            shutil.rmtree(w, ignore_errors=True)
    for _, text in results:
        print(text)
    failed = sum(not ok for ok, _ in results)
    print(f"{len(results) - failed} of {len(results)} cases pass")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
