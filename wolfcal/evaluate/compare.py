"""`wolfcal compare`: several calibrations side by side on held-out captures of every measurement system (the 2019
study's table, figures 6.2-6.6), and which one to deploy.

Rows: "before" (the input URDF, no corrections) and each calibration (a `wolfcal fit` folder). Columns: what the
held-out captures can measure, each with the existing evaluation code of its system:
- head camera: per-sample reprojection RMS per axis [px] and the study's tag-grid distance per tag view [mm]
  (`metrics.model_errors`, on every link tag seen, floor tags apart); samples no model explains are left out for all;
- external camera: the tag-grid distance of each foot tag relative to the torso tag [mm]
  (`external.foot_tag_grid_mm`);
- motion capture: distance between measured and predicted marker [mm], markers on moving links (the torso markers
  fix the frame): every row with the NOMINAL marker mounts of the robot config (no row gets mounts fitted, so none
  is flattered), the base pose in the motion-capture frame per capture by a rigid registration of the torso markers
  (per marker its median over the capture), which no leg model changes; a marker in a sample that is off by more
  than 3 times the median distance and 1 mm under any model (a reflection) is left out for all rows;
- ground error at the robot config's `floor.ground_check.distance` (default 4.5 m) [cm], from the head camera's
  held-out views of the floor tags (`floor_ground`: the real floor fitted to the views under each model, the error
  of a ball seen that far away at the worst of three bearings);
  one number per row with its 1-sigma, not a distribution.
Each cell: mean and standard deviation over the held-out samples (views, markers) in the column's unit (ground:
the error and its 1-sigma).
Deploy: among the calibrations that make no column worse than "before" (mean above before's by more than
`WORSE_TOLERANCE`), the one with the lowest mean ratio to "before" over all columns.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader

from wolfcal.atomic import output_set, write_bytes_atomic, write_text_atomic
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.external import foot_tag_grid_mm
from wolfcal.evaluate.figures import AFTER, BEFORE, histograms_png
from wolfcal.evaluate.floor_ground import measured_ground_errors
from wolfcal.evaluate.ground_figures import ground_check
from wolfcal.evaluate.metrics import measure_tag_views, model_errors, outlier_samples
from wolfcal.evaluate.pipeline import load_fit, refuse_fitted_captures
from wolfcal.evaluate.provenance import provenance
from wolfcal.evaluate.report import render_html, render_markdown
from wolfcal.fit.mocap_block import MocapBlock
from wolfcal.fit.pipeline import load_captures, samples_of, split_floor
from wolfcal.io.mcapfile import check_mcap
from wolfcal.io.mocap_load import load_marker_observations
from wolfcal.io.samples import Capture
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.outliers import MOCAP_MARKER_M
from wolfcal.outputs import check_output_folder
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot
from wolfcal.spans import sample_count, still_span_observations
from wolfcal.vision.corner_bias import CORNER_INSET
from wolfcal.vision.observe import detect_observations

COMPARE_FILES = ("report.html", "report.md", "metrics.json")
WORSE_TOLERANCE = 0.01  # a column's mean more than 1 % above before's counts as worse
BEFORE_LABEL = "before (input URDF)"
PALETTE = [AFTER, (40, 170, 40), (30, 160, 230), (160, 60, 160), (120, 120, 40), (90, 90, 90)]  # BGR


@dataclass
class Calibration:
    label: str  # the fit folder's name
    fit_dir: str
    system: str  # the measurement systems the fit used (its blocks)
    preset: str  # --free (and --side)
    corrections: Corrections
    corner_inset: tuple[float, float] | None = None  # the fit's floor.corner_inset and 1-sigma [px], if it had one
    external_moving: bool = False  # the fit took one external-camera pose per sample (--external-moving)


@dataclass
class Column:
    key: str
    title: str
    unit: str
    system: str  # head | external | mocap: the measurement system it is measured with
    values: dict[str, np.ndarray] = field(default_factory=dict)  # row label -> held-out values [unit]
    sigma: dict[str, float] | None = None  # one value per row with its 1-sigma [unit] (ground), not a distribution


def _calibrations(fit_dirs: list[Path]) -> tuple[Robot, list[Calibration], list[list[str]]]:
    """The robot shared by the fits, each fit as a Calibration, and the captures each was fitted on."""
    if not fit_dirs:
        raise WolfcalError("give at least one fit folder (the --out folder of `wolfcal fit`)")
    robot: Robot | None = None
    calibrations, used = [], []
    for fit_dir in fit_dirs:
        if Path(fit_dir).is_dir() and not (Path(fit_dir) / "result.yaml").is_file():
            raise WolfcalError(f"{fit_dir}: no result.yaml; give the --out folder of a `wolfcal fit` run")
        result, fit_robot = load_fit(Path(fit_dir))
        if robot is not None and fit_robot.config.name != robot.config.name:
            raise WolfcalError(f"{fit_dir}: a fit of robot '{fit_robot.config.name}', the others are of "
                               f"'{robot.config.name}'; compare calibrations of one robot")  # fmt: skip
        robot = robot or fit_robot
        preset = result.free + ("" if result.side == "both" else f" ({result.side})")
        system = ", ".join(result.systems_used) or result.system
        calibrations.append(Calibration(Path(fit_dir).name, str(Path(fit_dir).resolve()), system, preset,
                                        result.corrections, result.estimate(CORNER_INSET),
                                        result.external_moving))  # fmt: skip
        used.append(result.captures)
    assert robot is not None  # fit_dirs is not empty
    labels = [c.label for c in calibrations]
    for c in calibrations:
        if labels.count(c.label) > 1:
            c.label = str(Path(c.fit_dir).parent.name + "/" + c.label)
    return robot, calibrations, used


def _topics(path: Path) -> set[str]:
    """Topics with messages in an MCAP file."""
    check_mcap(path)
    try:
        with path.open("rb") as handle:
            summary = make_reader(handle).get_summary()
    except Exception as exc:  # the mcap library raises many types for damaged files
        raise WolfcalError(f"{path}: cannot read the MCAP file ({type(exc).__name__}: {exc})") from None
    if summary is None:
        raise WolfcalError(f"{path}: the MCAP file has no summary; run `wolfcal recover` on it")
    counts = summary.statistics.channel_message_counts if summary.statistics else {}
    return {c.topic for c in summary.channels.values() if counts.get(c.id, 1)}


def _head_columns(
    robot: Robot,
    models: dict[str, Corrections],
    loaded: list[Capture],
    say: Callable,
    corner_inset: tuple[float, float],
) -> list[Column]:
    """Head camera: per-sample RMS [px] and per-view tag grid [mm] of every model on the link tags seen (a
    recording's samples: its still spans, as the fit takes them)."""
    samples, _ = samples_of(loaded, robot)
    observations, _ = detect_observations(samples, robot, cameras=[HEAD_CAMERA])
    links_only, floor = split_floor(robot, still_span_observations(robot.config, observations))
    ground = _ground_column(robot, models, floor, say, corner_inset)
    if HEAD_CAMERA not in links_only:
        return ground
    obs = links_only[HEAD_CAMERA]
    say(f"head camera: {sample_count(obs)} held out, tags {', '.join(map(str, obs.observed_tag_ids))}")
    views = measure_tag_views(robot, obs)
    errors = {label: model_errors(robot, obs, views, model) for label, model in models.items()}
    before = errors[BEFORE_LABEL]
    best = min(errors.values(), key=lambda e: float(np.nanmedian(e.sample_rms)))
    keep = ~outlier_samples(before, best)
    of = _span_means(obs)
    px = Column("head_px", f"head camera reprojection RMS per axis, per sample{of}", "px", "head")
    mm = Column("head_tag_grid_mm", f"head camera tag-grid distance (2019 study), per tag view{of}", "mm", "head")
    for label, e in errors.items():
        px.values[label] = e.sample_rms[keep]
        grid = e.view_grid[keep[views.sample] & np.isfinite(e.view_grid)]
        mm.values[label] = grid * 1000.0
    return [px, mm, *ground]


def _ground_column(robot: Robot, models: dict[str, Corrections], floor: Observations | None,
                   say: Callable, corner_inset: tuple[float, float]) -> list[Column]:  # fmt: skip
    """The measured ground error at the robot config's `floor.ground_check.distance` [cm] of every model, from
    held-out floor views (none without them or when too few views measure it); a ball above a model's horizon is an
    infinite error. corner_inset: the detector's inward corner bias on small floor tags [px] and its 1-sigma, from a
    fit."""
    if floor is None:
        return []
    distance = ground_check(robot).distance
    measured = measured_ground_errors(robot, floor, models, (distance,), corner_inset)
    if measured is None:
        say(f"floor: {floor.n_samples} sample(s) with floor tags, too few views to measure the ground error")
        return []
    say(f"floor: {measured['views']} held-out floor-tag view(s)")
    values, sigma = {}, {}
    for label, rows in measured["models"].items():
        error, std = rows["rows"][0]["error_m"], rows["rows"][0]["std_m"]
        values[label] = np.array([np.inf if error is None else error * 100.0])
        sigma[label] = np.nan if std is None else std * 100.0
    return [Column("ground_cm", f"ground error at {distance:g} m, measured on floor tags", "cm", "head",
                   values, sigma)]  # fmt: skip


def _external_columns(
    robot: Robot, models: dict[str, Corrections], loaded: list[Capture], say: Callable, moving: bool
) -> list[Column]:
    """Each external camera: foot tag relative to torso tag, tag-grid distance [mm] per view (a recording's: per
    still span, unless the camera moved between samples, `moving`)."""
    names = [c.name for c in robot.config.external_cameras]
    if not any(n in c.cameras for c in loaded for n in names):
        return []
    samples, _ = samples_of(loaded, robot, cameras=())
    observations, _ = detect_observations(samples, robot, cameras=names)
    columns = []
    for name, obs in still_span_observations(robot.config, observations, moving).items():
        of = _span_means(obs)
        column = Column(f"external_{name}_mm", f"external camera {name}: foot tag relative to torso tag, tag grid"
                        f"{of}", "mm", "external")  # fmt: skip
        for label, model in models.items():
            column.values[label] = np.array(foot_tag_grid_mm(robot, obs, model))
        if len(column.values[BEFORE_LABEL]):
            say(f"external camera {name}: {len(column.values[BEFORE_LABEL])} foot-tag view(s)")
            columns.append(column)
    return columns


def _mocap_column(robot: Robot, models: dict[str, Corrections], captures: list[Path], say: Callable) -> list[Column]:
    """Motion capture: distance [mm] of the markers on moving links, nominal mounts, base pose from the torso
    markers (module docstring)."""
    if not captures:
        return []
    markers = load_marker_observations(robot.config, robot.joint_names, captures, [])
    say(f"motion capture: {markers.n_samples} held-out still sample(s), {len(markers.xyz)} marker positions")
    distances, left_out = {}, np.zeros(len(markers.xyz), dtype=bool)
    moving = np.array([not robot.fixed_to_base(robot.config.marker_config().marker(n).link)
                       for n in markers.marker_names], dtype=bool)[markers.marker_index]  # fmt: skip
    for label, model in models.items():
        block = MocapBlock(robot, markers, fixed=model)  # its nuisance references: Kabsch poses, mounts 0
        residual = block.linearize(np.zeros(0), block.nuisance.references, ParameterSet([])).residual  # (M, 3) [m]
        distances[label] = np.linalg.norm(residual, axis=1) * 1000.0
        d = distances[label][moving]
        left_out[moving] |= MOCAP_MARKER_M.flags(d, d / 1000.0 / np.sqrt(3.0))  # size: per-axis RMS [m]
    keep = moving & ~left_out
    column = Column("mocap_mm", "motion capture: measured to predicted marker distance, markers on moving links",
                    "mm", "mocap")  # fmt: skip
    column.values = {label: d[keep] for label, d in distances.items()}
    return [column]


def _cell(column: Column, label: str) -> dict:
    """Mean, standard deviation and count of a column's values of one row (a single value: its 1-sigma)."""
    v = np.asarray(column.values[label], dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return {"mean": None, "std": None, "n": 0}
    std = float(v.std()) if column.sigma is None else column.sigma[label]
    return {"mean": round(float(v.mean()), 4), "std": None if not np.isfinite(std) else round(std, 4),
            "n": int(v.size)}  # fmt: skip


def decide(columns: list[Column], calibrations: list[Calibration]) -> dict:
    """Which calibration to deploy (see the module docstring) and why; per calibration its mean ratio to before and
    the columns it makes worse."""
    verdicts: dict[str, dict[str, Any]] = {}
    ratio_of: dict[str, float] = {}
    for c in calibrations:
        worse, ratios = [], []
        for col in columns:
            before, mine = _cell(col, BEFORE_LABEL)["mean"], _cell(col, c.label)["mean"]
            if before is None or mine is None or before <= 0:
                continue
            ratios.append(mine / before)
            if mine > before * (1 + WORSE_TOLERANCE):
                worse.append(f"{col.title}: {mine:.2f} {col.unit} against {before:.2f} {col.unit} before")
        if ratios:
            ratio_of[c.label] = round(float(np.mean(ratios)), 4)
        verdicts[c.label] = {"mean_ratio_to_before": ratio_of.get(c.label), "worse_columns": worse}
    eligible = [label for label, ratio in ratio_of.items() if not verdicts[label]["worse_columns"] and ratio < 1.0]
    if not eligible:
        return {
            "deploy": None,
            "calibrations": verdicts,
            "message": "deploy none of them: each makes a column worse than the input URDF or improves none",
        }
    best = min(eligible, key=lambda label: ratio_of[label])
    ratio = ratio_of[best]
    message = (
        f"deploy {best}: it makes no column worse than the input URDF and has the lowest mean error relative "
        f"to it over the {len(columns)} column(s) ({ratio:.2f} of before's on average)"
    )
    rejected = [f"{label} is worse than before on {'; '.join(v['worse_columns'])}" for label, v in verdicts.items()
                if v["worse_columns"]]  # fmt: skip
    if rejected:
        message += "; not deployable: " + "; ".join(rejected)
    return {"deploy": best, "calibrations": verdicts, "message": message}


def _blocks(metrics: dict, columns: list[Column], calibrations: list[Calibration]) -> list:
    """Report blocks (`report.render_*`): the table, the decision, one histogram per column."""
    headers = ["calibration", "system", "preset"] + [f"{col.title} [{col.unit}] mean ± std" for col in columns]
    rows = [[BEFORE_LABEL, "-", "-"]] + [[c.label, c.system, c.preset] for c in calibrations]
    for row in rows:
        for col in columns:
            cell = metrics["table"][row[0]][col.key]
            std = "?" if cell["std"] is None else f"{cell['std']:.2f}"
            n = "" if col.sigma is not None else f" (n={cell['n']})"
            row.append("n/a" if cell["mean"] is None else f"{cell['mean']:.2f} ± {std}{n}")
    marked = [i for i, row in enumerate(rows) if row[0] == metrics["decision"]["deploy"]]
    blocks = [("h1", f"wolfcal comparison {metrics['robot_name']}"),
              ("p", f"held-out captures: {', '.join(metrics['captures'])}"),
              ("table", (headers, rows, marked)),
              ("banner", (metrics["decision"]["deploy"] is not None, metrics["decision"]["message"])),
              ("h2", "What the columns mean"), ("pre", metrics["meaning"])]  # fmt: skip
    if metrics["not_measured"]:
        blocks.append(("p", "Not measured: " + "; ".join(metrics["not_measured"])))
    blocks.append(("h2", "Distributions"))
    blocks += [("figure", (f"{col.key}.png", f"{col.title} [{col.unit}], every calibration")) for col in columns
               if col.sigma is None]  # fmt: skip
    return blocks


def _split_by_system(robot: Robot, captures: list[Path]) -> tuple[list[Path], list[Path]]:
    """(camera captures, motion-capture captures) by the topics each capture holds; a capture with neither the
    configured camera images nor the marker topic is refused."""
    marker_topic = robot.config.markers.topic if robot.config.markers else None
    image_topics = {robot.config.camera_topics(n)[0] for n in robot.config.camera_names}
    topics = {Path(c): _topics(Path(c)) for c in captures}
    unusable = [str(c) for c, t in topics.items() if not (t & image_topics) and marker_topic not in t]
    if unusable:
        raise WolfcalError(f"{', '.join(unusable)}: neither camera images ({', '.join(sorted(image_topics))}) nor "
                           f"markers ({marker_topic or 'no markers: in the robot config'}); give held-out captures "
                           "of the head camera, an external camera or motion capture")  # fmt: skip
    return ([c for c, t in topics.items() if t & image_topics], [c for c, t in topics.items() if marker_topic in t])


def _write_report(out_dir: Path, metrics: dict, columns: list[Column], calibrations: list[Calibration]) -> None:
    """report.html, report.md, metrics.json and one histogram per sample column, written as one set."""
    colours = {BEFORE_LABEL: BEFORE} | {c.label: PALETTE[i % len(PALETTE)] for i, c in enumerate(calibrations)}
    pngs = {f"{col.key}.png": histograms_png([(label, v, colours[label]) for label, v in col.values.items()],
                                             f"{col.title} [{col.unit}]", col.title) for col in columns
            if col.sigma is None}  # fmt: skip
    blocks = _blocks(metrics, columns, calibrations)
    title = f"wolfcal comparison {metrics['robot_name']}"
    with output_set():
        for name, data in pngs.items():
            write_bytes_atomic(out_dir / "figures" / name, data)
        write_text_atomic(out_dir / "report.html", render_html(blocks, pngs, title))
        write_text_atomic(out_dir / "report.md", render_markdown(blocks, "figures"))
        write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2, allow_nan=False) + "\n")


def run_compare(
    fit_dirs: list[Path],
    captures: list[Path],
    out_dir: Path,
    say: Callable[[str], None] = print,
    force: bool = False,
) -> dict:
    """The whole `wolfcal compare` job; returns the metrics written to out_dir/metrics.json. Outputs are checked
    before the work and written as one set."""
    out_dir = Path(out_dir)
    robot, calibrations, used = _calibrations([Path(f) for f in fit_dirs])
    if not captures:
        raise WolfcalError("give held-out captures with --capture (captures none of the fits used)")
    for fitted_on in used:
        refuse_fitted_captures(captures, fitted_on)
    inputs = [*captures, robot.config.path, robot.config.urdf]
    check_output_folder(out_dir, COMPARE_FILES, force, inputs)
    camera_captures, mocap_captures = _split_by_system(robot, captures)
    models = {BEFORE_LABEL: Corrections(), **{c.label: c.corrections for c in calibrations}}
    loaded = load_captures(robot, camera_captures, None, say) if camera_captures else []
    # One builder per measurement system (the head camera's includes the ground error when floor views exist).
    # The corner inset is the detector's, the same for every model: taken from the first fit that measured it.
    inset = next((c.corner_inset for c in calibrations if c.corner_inset is not None), (0.0, 0.0))
    columns = [*_head_columns(robot, models, [c for c in loaded if HEAD_CAMERA in c.cameras], say, inset),
               *_external_columns(robot, models, loaded, say, any(c.external_moving for c in calibrations)),
               *_mocap_column(robot, models, mocap_captures, say)]  # fmt: skip
    if not columns:
        raise WolfcalError(
            f"{', '.join(map(str, captures))}: no view of a configured tag or marker that the "
            "calibrations can be measured on; check the captures and the robot config's tags/markers"
        )
    decision = decide(columns, calibrations)
    metrics: dict[str, Any] = {
        **provenance(robot),
        "captures": [str(Path(c).resolve()) for c in captures],
        "meaning": __doc__.split("\n\n", 1)[1].strip(),
        "calibrations": [{"label": c.label, "fit_dir": c.fit_dir, "system": c.system, "preset": c.preset}
                         for c in calibrations],
        "columns": [{"key": col.key, "title": col.title, "unit": col.unit, "system": col.system} for col in columns],
        "table": {label: {col.key: _cell(col, label) for col in columns} for label in models},
        "not_measured": [] if any(col.key == "ground_cm" for col in columns) else [
            f"ground error at {ground_check(robot).distance:g} m [cm] (needs held-out head-camera views of the floor "
            "tags)"],
        "decision": decision,
    }  # fmt: skip
    _write_report(out_dir, metrics, columns, calibrations)
    for label in models:
        say(
            f"{label}: "
            + "; ".join(
                f"{col.key} {metrics['table'][label][col.key]['mean']} ± "
                f"{metrics['table'][label][col.key]['std']} {col.unit}"
                for col in columns
            )
        )
    say(decision["message"])
    say(f"report: {out_dir / 'report.html'}")
    return metrics


def _span_means(obs: Observations) -> str:
    """' (still-span means)' for a column of observations summarised by still span, '' otherwise."""
    return "" if obs.span_frames is None else " (still-span means)"
