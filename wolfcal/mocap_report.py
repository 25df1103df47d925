"""`wolfcal markers`: what a motion-capture file holds, checked before a fit.

The summary of a file (also its JSON form, `--json`): `{"format": str, "rate_hz": float, "frames": int,
"unit_in_file": str, "markers": [{"label": str, "visible_frames": int, "mean_m": [x, y, z]}, ...]}` with the
markers in the file's column order, labels as the file writes them, `visible_frames` the frames in which all three
coordinates were measured, and `mean_m` the mean position over those frames in the file's frame [m] (null for a
marker never measured). With a robot config: which configured markers the file has (and under which label), which
it lacks, and which labels no configured marker matches (`mocap_labels` rules).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from wolfcal.atomic import write_text_atomic
from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.io.mocap_files import read_mocap_file
from wolfcal.io.mocap_labels import match_names
from wolfcal.io.mocap_trajectories import MarkerTrajectories, NoMarkers
from wolfcal.outputs import check_outputs


def summary(traj: MarkerTrajectories) -> dict:
    """The JSON summary of the module docstring."""
    seen = np.all(np.isfinite(traj.xyz), axis=2)  # (F, K)
    markers = []
    for k, label in enumerate(traj.labels):
        n = int(seen[:, k].sum())
        mean = traj.xyz[seen[:, k], k].mean(axis=0) if n else None
        markers.append({"label": label, "visible_frames": n,
                        "mean_m": None if mean is None else [float(v) for v in mean]})  # fmt: skip
    return {"format": traj.format, "rate_hz": float(traj.rate_hz), "frames": int(len(traj.times_ns)),
            "unit_in_file": traj.unit, "markers": markers}  # fmt: skip


def report_lines(path: Path, data: dict, robot: Path | None) -> list[str]:
    """The lines a person reads: the file, then one line per marker, then the robot config's comparison."""
    frames, rate = data["frames"], data["rate_hz"]
    lines = [
        f"{path}: {data['format']}, {frames} frames at {rate:g} Hz ({frames / rate:.2f} s), lengths in "
        f"{data['unit_in_file']!r} (shown in m)",
        f"{len(data['markers'])} marker(s), in file order:",
    ]
    width = max(len(m["label"]) for m in data["markers"])
    for m in data["markers"]:
        where = "never measured" if m["mean_m"] is None else "mean " + " ".join(f"{v:+.4f}" for v in m["mean_m"])
        share = 100.0 * m["visible_frames"] / frames
        lines.append(f"  {m['label']:<{width}}  seen in {m['visible_frames']:>6} frames ({share:5.1f} %)  {where}")
    if robot is not None:
        config = load_robot_config(robot)
        names = config.marker_config("'wolfcal markers --robot' compares the file with them").names
        labels = [m["label"] for m in data["markers"]]
        match = match_names(path, names, labels)
        found = [n if labels[c] == n else f"{n} (as {labels[c]})" for n, c in zip(match.found, match.columns)]
        lines.append(f"robot config {config.path}: {len(match.found)} of {len(names)} configured markers found")
        lines.append(f"  found:   {', '.join(found) or 'none'}")
        lines.append(f"  missing: {', '.join(match.missing) or 'none'}")
        lines.append(f"  extra labels (not in the config, ignored by a fit): {', '.join(match.extra) or 'none'}")
    return lines


def run_markers(path: Path, json_out: Path | None, robot: Path | None, force: bool = False) -> list[str]:
    """Read `path`, write the JSON summary to `json_out` (when given; an existing one only with `force`, never the
    input), return the report's lines. A file without usable markers is a WolfcalError naming it and what it
    holds."""
    path = Path(path)
    if json_out is not None:
        check_outputs([json_out], force=force, inputs=[path], option="--json")
    traj = read_mocap_file(path)
    data = summary(traj)
    if not any(m["visible_frames"] for m in data["markers"]):
        raise NoMarkers(
            f"{path}: {len(data['markers'])} marker column(s) ({', '.join(traj.labels[:5])}), but no "
            "marker is measured in any frame"
        )
    lines = report_lines(path, data, robot) + [f"note: {note}" for note in traj.notes]
    if json_out is not None:
        try:
            write_text_atomic(json_out, json.dumps(data, indent=1) + "\n")
        except OSError as exc:
            raise WolfcalError(f"--json {json_out}: cannot write ({exc})") from None
        lines.append(f"wrote {json_out}")
    return lines
