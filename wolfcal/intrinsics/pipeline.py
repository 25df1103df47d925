"""`wolfcal intrinsics`: inputs -> detections -> calibration -> camera_info YAML and report folder."""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wolfcal.atomic import output_set
from wolfcal.camera.camera_info import save_camera_info
from wolfcal.errors import WolfcalError
from wolfcal.intrinsics.calibrate import DISTORTION_NAMES, Calibration, calibrate_views
from wolfcal.intrinsics.coverage import PARAM_NAMES, Coverage, ViewSelector, empty_regions, view_params
from wolfcal.intrinsics.detect import METHODS, Detection, Failure, detect_many, probe_board_size
from wolfcal.intrinsics.refine_choice import choose_window
from wolfcal.intrinsics.report import REPORT_FILES, write_detections, write_report
from wolfcal.intrinsics.sources import Inputs, camera_source, expand_inputs, image_jobs, read_image, stream_frames
from wolfcal.outputs import check_output_folder, check_outputs
from wolfcal.vision.board import Board


@dataclass(frozen=True)
class IntrinsicsOptions:
    """Everything but the inputs, the board and the output file."""

    model: str = "plumb_bob"
    method: str = "classic"  # checkerboard detector: classic | sb
    min_views: int = 10
    reject_outliers: bool = True
    workers: int = 2
    camera_name: str = "camera"
    report: Path | None = None  # default: <out stem>_report beside the output
    save_frames: Path | None = None  # folder for frames kept from videos / the live camera
    live_view: bool = False  # show the coverage bars in the terminal while collecting from streams
    force: bool = False  # replace outputs of an earlier run


def _wrong_board_hint(failures: list[Failure], board: Board) -> str:
    """A hint when failed images hold a checkerboard of another size than --board (most common of three)."""
    if board.is_charuco:
        return ""
    sizes: Counter[tuple[int, int]] = Counter()
    where: dict[tuple[int, int], str] = {}
    for failure in failures[:3]:
        try:
            size = probe_board_size(read_image(Path(failure.name)))
        except OSError:
            continue
        if size:  # in the orientation the user wrote --board in
            key = (max(size), min(size)) if board.cols >= board.rows else (min(size), max(size))
            sizes[key] += 1
            where.setdefault(key, failure.name)
    if not sizes:
        return ""
    (cols, rows), _ = sizes.most_common(1)[0]
    if (cols, rows) == (board.cols, board.rows):
        return ""
    return f" (found a {cols}x{rows} checkerboard in {where[cols, rows]}: is --board {cols}x{rows} right?)"


def _check_sizes(views: list[Detection]) -> None:
    sizes = Counter(v.image_size for v in views)
    if len(sizes) > 1:
        common = sizes.most_common(1)[0][0]
        odd = next(v for v in views if v.image_size != common)
        raise WolfcalError(
            f"{odd.name}: image size {odd.image_size[0]}x{odd.image_size[1]} differs from the "
            f"{common[0]}x{common[1]} of most views; calibrate one camera resolution at a time"
        )


def coverage_warnings(calibration: Calibration, board: Board) -> list[str]:
    """Image regions without corners, and pose coverage below ROS camera_calibration's targets."""
    cam = calibration.camera
    warnings = []
    empty = empty_regions(calibration.views, (cam.width, cam.height))
    if empty:
        warnings.append(
            f"no corners in the {', '.join(empty)} of the image: distortion there is extrapolated; "
            "add views with the board there"
        )
    coverage = Coverage([view_params(v, board) for v in calibration.views])
    short = [f"{name} {100 * value:.0f} %" for name, value in zip(PARAM_NAMES, coverage.progress(), strict=True)
             if value < 1.0]  # fmt: skip
    if short:  # one warning, with what to do
        warnings.append(f"the views cover less than ROS camera_calibration asks ({', '.join(short)}): "
                        + "; ".join(coverage.hints()))  # fmt: skip
    return warnings


def run_intrinsics(
    inputs: list[str],
    board: Board,
    out: Path,
    options: IntrinsicsOptions,
    camera: str | None = None,
    say: Callable[[str], None] = print,
) -> Calibration:
    """Detect, calibrate, write `out` (camera_info YAML) and the report folder; return the calibration."""
    found, report = _check_request(inputs, out, options, camera)
    failures = list(found.missing)
    for failure in failures:
        say(f"{failure.name}: {failure.reason}")
    views: list[Detection] = []

    def note(result: Detection | Failure) -> None:
        if isinstance(result, Failure):
            failures.append(result)
            say(f"{result.name}: {result.reason}")

    if found.images:
        say(f"detecting the {board.describe()} in {len(found.images)} images on {options.workers} threads")
        results = detect_many(image_jobs(found.images), board, options.method, options.workers, note)
        views += [r for r in results if isinstance(r, Detection)]
        say(f"board found in {len(views)} of {len(found.images)} images")
    streams = [(str(p), p.name) for p in found.videos] + ([(camera_source(camera), None)] if camera else [])
    if streams:
        views = _views_from_streams(streams, views, board, options, say)
    if not views:
        raise WolfcalError(
            f"the {board.describe()} was not found in any view{_wrong_board_hint(failures, board)}; "
            "check --board (inner corners, COLSxROWS) and --charuco, and that the whole board is in view "
            "(each view's reason is above)"
        )
    _check_sizes(views)
    detected = list(views)
    choice = None
    if len(views) >= options.min_views:
        views, choice = choose_window(views, board, options.model)
        if choice:
            say(choice.describe())
    calibration = calibrate_views(views, board, options.model, options.min_views, options.reject_outliers)
    calibration.camera = dataclasses.replace(calibration.camera, name=options.camera_name)
    warnings = coverage_warnings(calibration, board)
    with output_set():  # the camera_info and its report together, or neither: a failed run leaves nothing
        save_camera_info(calibration.camera, out)
        write_detections(report, detected, failures)
        write_report(report, calibration, failures, warnings,
                     options.method + (f"; {choice.describe()}" if choice else ""))  # fmt: skip
    _say_result(calibration, failures, warnings, say)
    say(f"wrote {out} and the report {report}/summary.md")
    return calibration


def _check_request(inputs: list[str], out: Path, options: IntrinsicsOptions, camera: str | None) -> tuple[Inputs, Path]:
    """The options checked and the inputs found, and the outputs checked before any work; the report folder."""
    if options.method not in METHODS:
        raise WolfcalError(f"unknown --detector {options.method!r}; use one of {', '.join(METHODS)}")
    if options.model not in DISTORTION_NAMES:
        raise WolfcalError(f"unknown --model {options.model!r}; use one of {', '.join(DISTORTION_NAMES)}")
    if not inputs and camera is None:
        raise WolfcalError("give images, folders or videos to calibrate from, or --camera for the live camera")
    found = expand_inputs(inputs)
    report = options.report or out.with_name(f"{out.stem}_report")
    check_outputs([out], options.force, found.images + found.videos)
    check_output_folder(report, REPORT_FILES, options.force, found.images + found.videos, "--report")
    if options.save_frames is not None:
        check_output_folder(options.save_frames, [], options.force, option="--save-frames")
        if not options.force and options.save_frames.is_dir() and any(options.save_frames.glob("view_*.png")):
            raise WolfcalError(
                f"--save-frames {options.save_frames}: holds frames of an earlier run (view_*.png); pass --force "
                "to replace them, or choose another folder"
            )
    return found, report


def _views_from_streams(
    streams: Sequence[tuple[str | int, str | None]],
    views: list[Detection],
    board: Board,
    options: IntrinsicsOptions,
    say: Callable[[str], None],
) -> list[Detection]:
    """Still, distinct views from videos or the live camera added to `views` until the coverage is complete."""
    from wolfcal.intrinsics.live import LiveView, collect_views  # rich's live display: only for streams

    selector = ViewSelector(board, Coverage([view_params(v, board) for v in views]), list(views))
    for source, name in streams:
        say(f"collecting still, distinct views from {name or f'camera {source}'} (Ctrl-C stops)")
        frames = stream_frames(source, name)
        try:
            if options.live_view:
                with LiveView(options.min_views) as view:
                    collect_views(frames, selector, options.min_views, options.method, options.save_frames, view)
            else:
                collect_views(frames, selector, options.min_views, options.method, options.save_frames)
        except KeyboardInterrupt:
            say("stopped; calibrating with the views kept so far")
        if selector.coverage.complete(options.min_views):
            break
    return selector.kept


def _say_result(calibration: Calibration, failures: list[Failure], warnings: list[str], say) -> None:
    cam = calibration.camera
    say(
        f"calibrated {cam.width}x{cam.height} {cam.distortion_model} from {len(calibration.views)} views, "
        f"{calibration.n_points} corners ({len(failures)} views failed)"
    )
    for view, rms in calibration.rejected:
        say(f"rejected outlier view {view.name}: RMS {rms:.3f} px")
    say(
        f"reprojection RMS per point {calibration.rms_per_point:.3f} px (OpenCV's convention; per axis "
        f"{calibration.rms_per_axis:.3f} px)"
    )
    values = np.concatenate([[cam.fx, cam.fy, cam.cx, cam.cy], cam.D])
    for (name, std), value in zip(calibration.std.items(), values, strict=True):
        unit = " px" if name in ("fx", "fy", "cx", "cy") else ""
        say(f"  {name:>3} = {value:.6g} +- {std:.2g}{unit} (1-sigma)")
    for warning in warnings:
        say(f"warning: {warning}")
