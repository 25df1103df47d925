"""`wolfcal compare`: several calibrations side by side on held-out captures of every measurement system (the 2019
study's table, figures 6.2-6.6), and which one to deploy.

Rows: "before" (the input URDF, no corrections) and each calibration (a `wolfcal fit` folder). Columns: what the
held-out captures can measure, each with the existing evaluation code of its system:
- head camera: per-sample reprojection RMS per axis [px] and the study's tag-grid distance per tag view [mm]
  (`metrics.model_errors`, on every link tag seen, floor tags apart); samples no model explains are left out for all;
- external camera: the tag-grid distance of each foot tag relative to the torso tag [mm]
  (`external.foot_tag_grid_mm`);
- motion capture: distance between measured and predicted marker [mm] after the base pose in the motion-capture frame
  and the marker mounts (prior 1 mm) are re-estimated with the chain held at the judged model (`MocapBlock`);
  markers left out as outliers under any model are left out for all.
- ground error at 4.5 m [cm] from floor samples: not measured yet (its place: GROUND COLUMN in `run_compare`).
Each cell: mean and standard deviation over the held-out samples (views, markers) in the column's unit.
Deploy: among the calibrations that make no column worse than "before" (mean above before's by more than
`WORSE_TOLERANCE`), the one with the lowest mean ratio to "before" over all columns.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader

import wolfcal
from wolfcal.atomic import output_set, write_bytes_atomic, write_text_atomic
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.external import foot_tag_grid_mm
from wolfcal.evaluate.figures import AFTER, BEFORE, histograms_png
from wolfcal.evaluate.metrics import measure_tag_views, model_errors, outlier_samples
from wolfcal.evaluate.pipeline import load_fit, refuse_fitted_captures
from wolfcal.evaluate.report import render_html, render_markdown
from wolfcal.fit.mocap_block import MOCAP_NOISE_START_M, MocapBlock
from wolfcal.fit.pipeline import load_captures, samples_of, split_floor
from wolfcal.fit.problem import Problem
from wolfcal.fit.solver import solve
from wolfcal.io.mcapfile import check_mcap
from wolfcal.io.mocap_load import load_marker_observations
from wolfcal.io.samples import Capture
from wolfcal.observations import HEAD_CAMERA
from wolfcal.outputs import check_output_folder
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot
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


@dataclass
class Column:
    key: str
    title: str
    unit: str
    system: str  # head | external | mocap: the measurement system it is measured with
    values: dict[str, np.ndarray] = field(default_factory=dict)  # row label -> held-out values [unit]


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
                                        result.corrections))  # fmt: skip
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


def _head_columns(robot: Robot, models: dict[str, Corrections], loaded: list[Capture], say: Callable) -> list[Column]:
    """Head camera: per-sample RMS [px] and per-view tag grid [mm] of every model on the link tags seen."""
    samples, _ = samples_of(loaded, robot)
    observations, _ = detect_observations(samples, robot, cameras=[HEAD_CAMERA])
    links_only, _ = split_floor(robot, observations)
    if HEAD_CAMERA not in links_only:
        return []
    obs = links_only[HEAD_CAMERA]
    say(f"head camera: {obs.n_samples} held-out sample(s), tags {', '.join(map(str, obs.observed_tag_ids))}")
    views = measure_tag_views(robot, obs)
    errors = {label: model_errors(robot, obs, views, model) for label, model in models.items()}
    before = errors[BEFORE_LABEL]
    best = min(errors.values(), key=lambda e: float(np.nanmedian(e.sample_rms)))
    keep = ~outlier_samples(before, best)
    px = Column("head_px", "head camera reprojection RMS per axis, per sample", "px", "head")
    mm = Column("head_tag_grid_mm", "head camera tag-grid distance (2019 study), per tag view", "mm", "head")
    for label, e in errors.items():
        px.values[label] = e.sample_rms[keep]
        grid = e.view_grid[keep[views.sample] & np.isfinite(e.view_grid)]
        mm.values[label] = grid * 1000.0
    return [px, mm]


def _external_columns(
    robot: Robot, models: dict[str, Corrections], loaded: list[Capture], say: Callable
) -> list[Column]:
    """Each external camera: foot tag relative to torso tag, tag-grid distance [mm] per view."""
    names = [c.name for c in robot.config.external_cameras]
    if not any(n in c.cameras for c in loaded for n in names):
        return []
    samples, _ = samples_of(loaded, robot, cameras=())
    observations, _ = detect_observations(samples, robot, cameras=names)
    columns = []
    for name, obs in observations.items():
        column = Column(f"external_{name}_mm", f"external camera {name}: foot tag relative to torso tag, tag grid",
                        "mm", "external")  # fmt: skip
        for label, model in models.items():
            column.values[label] = np.array(foot_tag_grid_mm(robot, obs, model))
        if len(column.values[BEFORE_LABEL]):
            say(f"external camera {name}: {len(column.values[BEFORE_LABEL])} foot-tag view(s)")
            columns.append(column)
    return columns


def _mocap_column(robot: Robot, models: dict[str, Corrections], captures: list[Path], say: Callable) -> list[Column]:
    """Motion capture: marker distance [mm] after re-estimating base pose and mounts with the chain held."""
    if not captures:
        return []
    markers = load_marker_observations(robot.config, robot.joint_names, captures, [])
    say(f"motion capture: {markers.n_samples} held-out still sample(s), {len(markers.xyz)} marker positions")
    distances, left_out = {}, set()
    for label, model in models.items():
        block = MocapBlock(robot, markers, fixed=model)
        problem = Problem(ParameterSet([]), [block], [MOCAP_NOISE_START_M], robot.config.priors.encoder_noise)
        solution = solve(problem)
        residual = block.linearize(np.zeros(0), solution.values, ParameterSet([])).residual  # (M, 3) [m]
        distances[label] = np.linalg.norm(residual, axis=1) * 1000.0
        left_out |= set(solution.blocks[0].outlier_views)
    keep = np.array([view not in left_out for view in block.view_labels], dtype=bool)
    column = Column("mocap_mm", "motion capture: measured to predicted marker distance", "mm", "mocap")
    column.values = {label: d[keep] for label, d in distances.items()}
    return [column]


def _cell(values: np.ndarray) -> dict:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if not v.size:
        return {"mean": None, "std": None, "n": 0}
    return {"mean": round(float(v.mean()), 4), "std": round(float(v.std()), 4), "n": int(v.size)}


def decide(columns: list[Column], calibrations: list[Calibration]) -> dict:
    """Which calibration to deploy (see the module docstring) and why; per calibration its mean ratio to before and
    the columns it makes worse."""
    verdicts: dict[str, dict[str, Any]] = {}
    ratio_of: dict[str, float] = {}
    for c in calibrations:
        worse, ratios = [], []
        for col in columns:
            before, mine = _cell(col.values[BEFORE_LABEL])["mean"], _cell(col.values[c.label])["mean"]
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
        return {"deploy": None, "calibrations": verdicts,
                "message": "deploy none of them: each makes a column worse than the input URDF or improves none"}
    best = min(eligible, key=lambda label: ratio_of[label])
    ratio = ratio_of[best]
    message = (f"deploy {best}: it makes no column worse than the input URDF and has the lowest mean error relative "
               f"to it over the {len(columns)} column(s) ({ratio:.2f} of before's on average)")
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
            row.append("n/a" if cell["mean"] is None else f"{cell['mean']:.2f} ± {cell['std']:.2f} (n={cell['n']})")
    marked = [i for i, row in enumerate(rows) if row[0] == metrics["decision"]["deploy"]]
    blocks = [("h1", f"wolfcal comparison {metrics['robot_name']}"),
              ("p", f"held-out captures: {', '.join(metrics['captures'])}"),
              ("table", (headers, rows, marked)),
              ("banner", (metrics["decision"]["deploy"] is not None, metrics["decision"]["message"])),
              ("h2", "What the columns mean"), ("pre", metrics["meaning"])]  # fmt: skip
    if metrics["not_measured"]:
        blocks.append(("p", "Not measured: " + "; ".join(metrics["not_measured"])))
    blocks.append(("h2", "Distributions"))
    blocks += [("figure", (f"{col.key}.png", f"{col.title} [{col.unit}], every calibration")) for col in columns]
    return blocks


def run_compare(
    fit_dirs: list[Path], captures: list[Path], out_dir: Path, say: Callable[[str], None] = print,
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
    marker_topic = robot.config.markers.topic if robot.config.markers else None
    image_topics = {robot.config.camera_topics(n)[0] for n in robot.config.camera_names}
    topics = {Path(c): _topics(Path(c)) for c in captures}
    mocap_captures = [c for c, t in topics.items() if marker_topic in t]
    camera_captures = [c for c, t in topics.items() if t & image_topics]
    unusable = [str(c) for c, t in topics.items() if not (t & image_topics) and marker_topic not in t]
    if unusable:
        raise WolfcalError(f"{', '.join(unusable)}: neither camera images ({', '.join(sorted(image_topics))}) nor "
                           f"markers ({marker_topic or 'no markers: in the robot config'}); give held-out captures "
                           "of the head camera, an external camera or motion capture")  # fmt: skip
    models = {BEFORE_LABEL: Corrections(), **{c.label: c.corrections for c in calibrations}}
    loaded = load_captures(robot, camera_captures, None, say) if camera_captures else []
    # One builder per measurement system. GROUND COLUMN: the measured ground error at 4.5 m [cm] from floor samples
    # goes here (a Column with unit "cm", system "head") once `wolfcal evaluate` measures it; then drop it from
    # metrics["not_measured"].
    columns = [*_head_columns(robot, models, [c for c in loaded if HEAD_CAMERA in c.cameras], say),
               *_external_columns(robot, models, loaded, say),
               *_mocap_column(robot, models, mocap_captures, say)]  # fmt: skip
    if not columns:
        raise WolfcalError(f"{', '.join(map(str, captures))}: no view of a configured tag or marker that the "
                           "calibrations can be measured on; check the captures and the robot config's tags/markers")
    decision = decide(columns, calibrations)
    metrics: dict[str, Any] = {
        "wolfcal_version": wolfcal.__version__,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "robot": str(robot.config.path), "robot_name": robot.config.name,
        "captures": [str(Path(c).resolve()) for c in captures],
        "meaning": __doc__.split("\n\n", 1)[1].strip(),
        "calibrations": [{"label": c.label, "fit_dir": c.fit_dir, "system": c.system, "preset": c.preset}
                         for c in calibrations],
        "columns": [{"key": col.key, "title": col.title, "unit": col.unit, "system": col.system} for col in columns],
        "table": {label: {col.key: _cell(col.values[label]) for col in columns} for label in models},
        "not_measured": ["ground error at 4.5 m [cm] (not yet measured by wolfcal compare)"],
        "decision": decision,
    }  # fmt: skip
    colours = {BEFORE_LABEL: BEFORE} | {c.label: PALETTE[i % len(PALETTE)] for i, c in enumerate(calibrations)}
    pngs = {f"{col.key}.png": histograms_png([(label, v, colours[label]) for label, v in col.values.items()],
                                             f"{col.title} [{col.unit}]", col.title) for col in columns}  # fmt: skip
    blocks = _blocks(metrics, columns, calibrations)
    with output_set():
        for name, data in pngs.items():
            write_bytes_atomic(out_dir / "figures" / name, data)
        write_text_atomic(out_dir / "report.html", render_html(blocks, pngs, f"wolfcal comparison {robot.config.name}"))
        write_text_atomic(out_dir / "report.md", render_markdown(blocks, "figures"))
        write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    for label in models:
        say(f"{label}: " + "; ".join(f"{col.key} {metrics['table'][label][col.key]['mean']} ± "
                                     f"{metrics['table'][label][col.key]['std']} {col.unit}" for col in columns))
    say(decision["message"])
    say(f"report: {out_dir / 'report.html'}")
    return metrics
