"""The speed and memory parts: a camera fit's first and cached runs against the detection floor, and the peak
memory of fits and of their evaluations on long recordings. Each runs on every tree given (this checkout, and an
older one to compare with), alternating which runs first (`common.alternating`).
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from common import CONFIG, DATA, ROOT, alternating, config_of, run_child, summary
from recording import recording

CHILD = str(Path(__file__).resolve().parent / "child.py")
CLI = ["-c", "from wolfcal.cli import app; app()"]
FIT_SAMPLES = 24  # the camera capture: 24 samples at 2048x1536


def camera_capture() -> Path:
    """The 24-sample 2048x1536 camera capture (simulated once, seed 1, no encoder offsets)."""
    from wolfcal.sim.simulate import SimOptions, simulate_capture

    path = DATA / f"camera_{FIT_SAMPLES}.mcap"
    if not path.exists():
        DATA.mkdir(parents=True, exist_ok=True)
        options = SimOptions(samples=FIT_SAMPLES, seed=1, offsets="none", binning=1)
        simulate_capture(CONFIG, path, options, say=lambda _: None)
    return path


def _warm(path: Path) -> None:
    """Read the file once: every run finds it in the page cache, whichever comes first."""
    with path.open("rb") as handle:
        while handle.read(1 << 24):
            pass


def fit_speed(trees: dict[str, Path], rounds: int, say) -> dict:
    """Per tree: the first run (empty cache) and the cached run of `run_fit --free camera` in one process
    (after a warm-up fit), the cached run as a whole `wolfcal fit` process, and the floor (reading, decoding
    and OpenCV's bare detector on all cores, no wolfcal code) right before each tree's runs; ratios first run
    / floor per round, their median."""
    capture = camera_capture()
    _warm(capture)
    runs: dict[str, dict[str, list[float]]] = {label: {} for label in trees}
    with tempfile.TemporaryDirectory() as scratch:
        for k, label, tree in alternating(trees, rounds):
            cache = Path(scratch) / f"{label}_{k}"
            floor = run_child(tree, [CHILD, "floor", str(capture)]).result or {}
            fit = run_child(tree, [CHILD, "fit", str(capture), str(config_of(tree)), str(cache)]).result or {}
            process = run_child(
                tree,
                [
                    *CLI,
                    "fit",
                    str(capture),
                    "--robot",
                    str(config_of(tree)),
                    "--free",
                    "camera",
                    "--out",
                    str(Path(scratch) / "out"),
                    "--force",
                ],
                env={"WOLFCAL_CACHE_DIR": str(cache)},
            )
            figures = {
                **floor,
                **fit,
                "cached_process_wall": process.wall,
                "cached_process_cpu": process.cpu,
                "cached_process_peak_mb": process.peak_mb,
                "first_over_floor_wall": fit["first_wall"] / floor["floor_wall"],
                "first_over_floor_cpu": fit["first_cpu"] / floor["floor_cpu"],
            }
            for key, value in figures.items():
                runs[label].setdefault(key, []).append(value)
            say(
                f"fit {label} round {k + 1}: first {fit['first_wall']:.2f} s ({figures['first_over_floor_wall']:.2f}x "
                f"the floor {floor['floor_wall']:.2f} s), cached {fit['cached_wall']:.3f} s, cached process "
                f"{process.wall:.2f} s"
            )
    return {
        "samples": FIT_SAMPLES,
        "size": [2048, 1536],
        "rounds": rounds,
        "trees": {label: {key: summary(values) for key, values in figures.items()} for label, figures in runs.items()},
    }


def stream_memory(trees: dict[str, Path], frames: list[int], binning: int, rounds: int, say) -> dict:
    """Per tree and recording length: peak RSS [MB], wall and CPU [s] of a whole `wolfcal fit --free camera
    --no-cache` process on a plain recording (`recording.recording`), and the samples it used."""

    def fit(tree: Path, path: Path, out: Path) -> list[str]:
        return ["fit", str(path), "--robot", str(config_of(tree)), "--free", "camera", "--out", str(out), "--no-cache"]

    def used(run, _out: Path) -> str:
        return next((line.strip() for line in run.output.splitlines() if line.startswith("head camera:")), "")

    return _recording_runs(trees, frames, binning, rounds, "stream", fit, used, say)


def evaluate_memory(trees: dict[str, Path], frames: list[int], binning: int, rounds: int, say) -> dict:
    """Per tree and recording length: peak RSS [MB], wall and CPU [s] of a whole `wolfcal evaluate --no-cache`
    process (cross-validation over the fit's samples) on a fit of a plain recording (`wolfcal fit --free camera`
    by this checkout, made once, not measured), and the samples it judged."""
    fits: dict[Path, Path] = {}

    def evaluate(_tree: Path, path: Path, out: Path) -> list[str]:
        if path not in fits:
            fits[path] = out.parent / f"fit_{path.stem}"
            run_child(ROOT, [*CLI, "fit", str(path), "--robot", str(CONFIG), "--free", "camera", "--out",
                             str(fits[path])])  # fmt: skip
        return ["evaluate", str(fits[path]), "--out", str(out), "--no-cache", "--deploy-worse"]

    def judged(_run, out: Path) -> str:
        metrics = json.loads((out / "metrics.json").read_text())
        spans = f" (still spans of {metrics['n_frames']} frames)" if "n_frames" in metrics else ""
        return f"{metrics['n_samples']} samples{spans}, {metrics['folds']} folds"

    return _recording_runs(trees, frames, binning, rounds, "evaluate", evaluate, judged, say)


def _recording_runs(trees, frames, binning, rounds, name, argv, line, say) -> dict:
    """Per tree and recording length: the figures of a whole `wolfcal` process, `argv(tree, recording, out folder)` its
    arguments, `line(run, out folder)` what it says it used."""
    paths = {n: recording(DATA, n, binning) for n in frames}
    out: dict[str, dict] = {label: {} for label in trees}
    with tempfile.TemporaryDirectory() as scratch:
        for k, label, tree in alternating(trees, rounds):
            for n, path in paths.items():
                arguments = argv(tree, path, Path(scratch) / "out")
                _warm(path)
                run = run_child(tree, [*CLI, *arguments, "--force"])
                used = line(run, Path(scratch) / "out")
                entry = out[label].setdefault(str(n), {"peak_mb": [], "wall": [], "cpu": [], "line": used})
                entry["peak_mb"].append(run.peak_mb)
                entry["wall"].append(run.wall)
                entry["cpu"].append(run.cpu)
                say(f"{name} {label} round {k + 1}: {n} frames, peak {run.peak_mb:.0f} MB, {run.wall:.1f} s; {used}")
    for figures in out.values():
        for entry in figures.values():
            for key in ("peak_mb", "wall", "cpu"):
                entry[key] = summary(entry[key])
        peaks = [entry["peak_mb"]["median"] for entry in figures.values()]
        figures["largest_over_smallest"] = max(peaks) / min(peaks)
    size = [2048 // binning, 1536 // binning]
    return {
        "frames": frames,
        "size": size,
        "rounds": rounds,
        "file_mb": {str(n): p.stat().st_size / 1e6 for n, p in paths.items()},
        "trees": out,
    }


def targets(results: dict) -> list[dict]:
    """The targets' figures, per tree: the cached camera fit's wall (target under 0.5 s; in a process that has
    run a fit, and as a whole process) and CPU time, the first run over the floor (target within 1.5x; medians
    of the rounds' ratios of wall and of CPU times), the peaks of the 6000- and 600-frame fits (target under
    300 MB and within 20 % of each other)."""
    rows = []
    fit, stream = results.get("fit"), results.get("stream")
    for label in (fit or stream or {}).get("trees", {}):
        row: dict = {"tree": label}
        if fit:
            figures = fit["trees"][label]
            row["cached_process_wall"] = figures["cached_process_wall"]["median"]
            row["cached_in_process_wall"] = figures["cached_wall"]["median"]
            row["cached_in_process_cpu"] = figures["cached_cpu"]["median"]
            row["first_over_floor_wall"] = figures["first_over_floor_wall"]["median"]
            row["first_over_floor_cpu"] = figures["first_over_floor_cpu"]["median"]
        if stream and "600" in stream["trees"][label] and "6000" in stream["trees"][label]:
            figures = stream["trees"][label]
            row["peak_6000_mb"] = figures["6000"]["peak_mb"]["median"]
            row["peak_600_mb"] = figures["600"]["peak_mb"]["median"]
            row["peak_ratio"] = row["peak_6000_mb"] / row["peak_600_mb"]
        rows.append(row)
    return rows
