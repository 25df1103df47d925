"""The bench harness: run the measurements, write their figures as JSON (`bench/report.py` makes the docs'
tables).

    python bench/run.py [--parts fit,stream,...] [--out bench/results.json] [--before PATH] [--rounds 3]
                        [--frames 600,6000] [--stream-binning 4] [--seeds 3] ...

Parts (bench/README.md says what each measures): `fit`, `stream` (speed and memory of `wolfcal fit`), `evaluate`
(the same of `wolfcal evaluate`), `detection`, `intrinsics`, `seeds` (accuracy against simulated truth), `solve`
(solve time on synthetic samples), `stability` (how far a fit moves under changes that should not matter),
`recordings` (std coverage on continuous recordings), `floor` (the venue's floor check on rendered views), `plan`
(planned against random poses), `compare` (every measurement system on one session), `mocap` (motion capture on
another robot's data), `field` and `field_check` (the camera from field lines against tags, the held-out ground
error from field views), `bus` and `capture` (the servo bus emulator), `venue` (robot time of a venue session against
single commands), `realfield` (the field-line detector on real robot-camera images, `--field-images`: a clone of
https://github.com/GuiFornes/field_detector). `--before PATH`: a folder holding an older `wolfcal` package; `fit`,
`stream` and `evaluate` then run on both, alternating which goes first. Results of the parts run are merged into the
JSON file (other parts' results are kept). Generated inputs are kept in the temp folder (`common.DATA`). A part
skipped for want of its input (`realfield` without `--field-images`) keeps its earlier figures."""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's wolfcal for generating inputs

from common import ROOT, start_spawner  # noqa: E402
from quality import detection, intrinsics, seeds  # noqa: E402
from targets import evaluate_memory, fit_speed, stream_memory, targets  # noqa: E402

PARTS = ("fit", "stream", "evaluate", "detection", "intrinsics", "seeds", "solve", "stability", "recordings", "floor",
         "plan", "compare", "mocap", "field", "field_check", "bus", "capture", "venue", "realfield")  # fmt: skip
DEFAULT_PARTS = ("fit", "stream", "detection", "intrinsics", "seeds")  # about a minute; the others take longer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--parts", default=",".join(DEFAULT_PARTS), help="comma-separated, of " + ", ".join(PARTS))
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results.json")
    parser.add_argument("--before", type=Path, default=None, help="a folder holding an older wolfcal package")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of the fit part (each tree once a round)")
    parser.add_argument("--stream-rounds", type=int, default=1)
    parser.add_argument("--frames", default="600,6000", help="recording lengths of the stream part")
    parser.add_argument("--stream-binning", type=int, default=4, help="1: 2048x1536 frames; 4: 512x384")
    parser.add_argument("--views", type=int, default=20, help="rendered views per camera of the detection part")
    parser.add_argument("--seeds", type=int, default=3, help="seeds of the intrinsics and seeds parts")
    parser.add_argument("--binning", type=int, default=4, help="image binning of the seeds and recordings parts")
    parser.add_argument("--sizes", default="25,100,400,1000", help="synthetic samples of the solve part")
    parser.add_argument("--reads", type=int, default=2000, help="sync reads of the bus part")
    parser.add_argument(
        "--field-images", type=Path, default=None, help="realfield: a clone of GuiFornes/field_detector"
    )
    parser.add_argument("--field-views", type=int, default=20, help="rendered views per capture of the field part")
    parser.add_argument("--check-views", type=int, default=12, help="views per capture of the field_check part")
    args = parser.parse_args()
    start_spawner()  # before anything large is loaded: see `common.start_spawner`
    parts = [p for p in args.parts.split(",") if p]
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        parser.error(f"unknown part(s) {', '.join(unknown)}; choose from {', '.join(PARTS)}")
    trees = {"after": ROOT}
    if args.before is not None:
        if not (args.before / "wolfcal" / "__init__.py").is_file():
            parser.error(f"--before {args.before}: holds no wolfcal package")
        trees = {"before": args.before.resolve(), "after": ROOT}

    def say(line: str) -> None:
        print(line, flush=True)

    results = json.loads(args.out.read_text()) if args.out.is_file() else {}
    for part in parts:
        start = time.perf_counter()
        if part == "fit":
            results["fit"] = fit_speed(trees, args.rounds, say)
        elif part == "stream":
            frames = [int(n) for n in args.frames.split(",")]
            results["stream"] = stream_memory(trees, frames, args.stream_binning, args.stream_rounds, say)
        elif part == "evaluate":
            frames = [int(n) for n in args.frames.split(",")]
            results["evaluate"] = evaluate_memory(trees, frames, args.stream_binning, args.stream_rounds, say)
        elif part == "detection":
            results["detection"] = detection(args.views, say)
        elif part == "intrinsics":
            results["intrinsics"] = intrinsics(args.seeds, say)
        elif part == "seeds":
            results["seeds"] = seeds(args.seeds, args.binning, say)
        elif part == "realfield":
            from realfield import realfield

            measured = realfield(args.field_images, trees, say)
            if measured is None:
                continue  # the images are absent: an earlier measurement stays
            results[part] = measured
        else:
            results[part] = in_process_part(part, args, say)
        if part in ("fit", "stream"):
            results[part]["code"] = {label: commit_of(path) for label, path in trees.items()}
        results[part]["seconds"] = time.perf_counter() - start
        results[part]["taken"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        results[part]["load_average"] = os.getloadavg()[0]
    results["targets"] = targets(results)
    results["machine"] = {
        "cores": len(os.sched_getaffinity(0)),
        "python": platform.python_version(),
        "processor": platform.processor() or platform.machine(),
    }
    args.out.write_text(json.dumps(results, indent=1, default=_plain) + "\n")
    say(f"wrote {args.out}")


def commit_of(tree: Path) -> str:
    """The commit a checkout holds, as `<short hash> <subject>` (subject cut at 72 characters; ", with changes to
    wolfcal/" when its package differs from the commit); "unknown" outside git."""

    def git(*args: str) -> str:
        run = subprocess.run(["git", "-C", str(tree), *args], capture_output=True, text=True)
        return run.stdout.strip() if run.returncode == 0 else ""

    head = git("log", "-1", "--format=%h %s")
    if not head:
        return "unknown"
    head = head if len(head) <= 80 else head[:77] + "..."
    return head + (", with changes to wolfcal/" if git("status", "--porcelain", "--", "wolfcal") else "")


def in_process_part(part: str, args: argparse.Namespace, say) -> dict:
    """A part measured in this process, BLAS on one thread as in the `wolfcal` command (the modules are imported
    here: their imports are heavy)."""
    from wolfcal.blas_threads import one_blas_thread

    one_blas_thread()
    if part == "solve":
        from solve import speed

        return speed(tuple(int(n) for n in args.sizes.split(",")), say)
    if part == "stability":
        from solve import stability

        return stability([], say)
    if part == "recordings":
        from coverage import recordings

        return recordings(args.seeds, args.binning, say)
    if part == "floor":
        from floor import floor

        return floor(args.seeds, say)
    if part == "plan":
        from plan import plan

        return plan(args.seeds, say)
    if part == "compare":
        from compare import compare_systems

        return compare_systems(args.seeds, say)
    if part == "mocap":
        from mocap import mocap

        return mocap(args.seeds, say)
    if part == "field":
        from field import field

        return field(args.seeds, args.field_views, say)
    if part == "field_check":
        from field_check import field_check

        return field_check(args.seeds, args.check_views, say)
    if part == "venue":
        from venue import venue

        return venue(say)
    from hardware import bus, capture

    return bus(args.reads, say) if part == "bus" else capture(3.0, 0.3, say)


def _plain(value):
    """numpy numbers and arrays as JSON numbers and lists."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"not JSON: {type(value).__name__}")


if __name__ == "__main__":
    main()
