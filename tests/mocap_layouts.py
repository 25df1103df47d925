"""CSV text in the exact layouts OptiTrack Motive and Vicon Nexus write, for tests (independent of wolfcal's readers).

Layouts as seen in real exports (../shared/realdata/mocap and public repositories):
- Motive 1.21 (hmv-s16 sample take): line 1 'Format Version,1.21,Take Name,...,Export Frame Rate,120.000000,...,
  Length Units,Meters,Coordinate Space,Global', a blank line, then the Type, Name and ID rows and the kind row with
  their first two cells EMPTY, then 'Frame,Time,X,Y,Z,...'. Rigid Body columns: Rotation X Y Z W, Position X Y Z,
  Error Per Marker (axis cell empty); Rigid Body Marker columns: Position X Y Z and Marker Quality; markers of an
  asset are named 'Rigid Body 1:Marker1', unlabelled ones 'Unlabeled:108'.
- Motive 1.23 (Motive 3, optitrack-motive-file-converter's test export): the rows carry their name in the SECOND
  cell (',Type,...', ',Name,...', ',ID,...'), the kind row ',,Position,...', then 'Frame,Time (Seconds),X,Y,Z';
  times rounded to 1 ms ('0.003000' for frame 1 at 360 Hz); unlabelled markers 'Unlabeled 1036'; blank cells
  where a marker was not seen; Length Units 'Millimeters'.
- Motive 1.24: as 1.23, with a TimeCode column after the time (',Type,,Marker,...',
  'Frame,Time (Seconds),TimeCode,X,Y,Z'), e.g. Length Units 'Centimeters'.
- Vicon Nexus (pyomeca exports): 'Devices' section (name, rate, channel names, 'Frame,Sub Frame,...', units 'V'),
  a blank line, then 'Trajectories', the rate, 'Subject:Marker' above each X column (Y and Z cells empty),
  'Frame,Sub Frame,X,Y,Z,...', the units line 'mm' under every axis, one line per frame (frames from 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class MotiveColumns:
    """One asset's block of columns: `kinds` and `axes` per column, `values` (F, columns) in the file's unit."""

    type: str  # 'Marker' | 'Rigid Body' | 'Rigid Body Marker'
    name: str
    id: str
    kinds: list[str]
    axes: list[str]
    values: np.ndarray


def marker(name: str, xyz: np.ndarray, type_: str = "Marker", id_: str = "1") -> MotiveColumns:
    return MotiveColumns(type_, name, id_, ["Position"] * 3, ["X", "Y", "Z"], xyz)


def rigid_body(name: str, quat: np.ndarray, xyz: np.ndarray, error: np.ndarray) -> MotiveColumns:
    return MotiveColumns("Rigid Body", name, "CF5107FCB3ED11E565670A50E6808782",
                         ["Rotation"] * 4 + ["Position"] * 3 + ["Error Per Marker"], ["X", "Y", "Z", "W", "X", "Y",
                                                                                      "Z", ""],
                         np.column_stack([quat, xyz, error]))  # fmt: skip


def rigid_body_marker(name: str, xyz: np.ndarray, quality: np.ndarray) -> MotiveColumns:
    return MotiveColumns(
        "Rigid Body Marker",
        name,
        "CF5107FCB3ED11E565670A50E6808782",
        ["Position"] * 3 + ["Marker Quality"],
        ["X", "Y", "Z", ""],
        np.column_stack([xyz, quality]),
    )


def _cell(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.6f}"


def motive_csv(version: str, rate: float, unit: str, blocks: list[MotiveColumns], first_frame: int = 0) -> str:
    """The whole export as text, in the layout of `version` ('1.21', '1.23' or '1.24')."""
    frames = len(blocks[0].values)
    timecode = version == "1.24"
    meta = ["Format Version", version, "Take Name", "take", "Capture Frame Rate", f"{rate:.6f}", "Export Frame Rate",
            f"{rate:.6f}", "Capture Start Time", "2023-11-28 10.27.58.765 AM", "Total Frames in Take", str(frames),
            "Total Exported Frames", str(frames), "Rotation Type", "Quaternion", "Length Units", unit,
            "Coordinate Space", "Global"]  # fmt: skip
    lead = (lambda name: ["", ""]) if version == "1.21" else (lambda name: ["", name] + ([""] if timecode else []))
    pad = [""] if timecode else []
    rows = [meta, []]
    for row_name, get in (("Type", lambda b: b.type), ("Name", lambda b: b.name), ("ID", lambda b: f'"{b.id}"')):
        rows.append(lead(row_name) + [get(b) for b in blocks for _ in b.axes])
    rows.append(["", ""] + pad + [k for b in blocks for k in b.kinds])
    rows.append(["Frame", "Time" if version == "1.21" else "Time (Seconds)"] + (["TimeCode"] if timecode else [])
                + [a for b in blocks for a in b.axes])  # fmt: skip
    values = np.column_stack([b.values for b in blocks])
    for i in range(frames):
        frame = first_frame + i
        t = frame / rate if version == "1.21" else round(frame / rate, 3)  # Motive 3 rounds the time to 1 ms
        code = [f"15:26:46:{frame % 120:02d}.02"] if timecode else []
        rows.append([str(frame), f"{t:.6f}", *code, *map(_cell, values[i])])
    return "\n".join(",".join(r) for r in rows) + "\n"


def vicon_csv(rate: float, labels: list[str], xyz_mm: np.ndarray, devices: np.ndarray | None = None) -> str:
    """A Nexus export: a Devices section (`devices` (F * 10, C) volts at 10 x rate) when given, then Trajectories
    of `labels` with positions (F, K, 3) [mm], NaN as blank cells."""
    rows: list[list[str]] = []
    if devices is not None:
        channels = devices.shape[1]
        rows += [
            ["Devices"],
            [f"{rate * 10:g}"],
            ["", "", "Imported Analog EMG - Voltage"] + [""] * (channels - 1),
            ["Frame", "Sub Frame"] + [str(c + 1) for c in range(channels)],
            ["", ""] + ["V"] * channels,
        ]
        for i, sample in enumerate(devices):
            rows.append([str(i // 10 + 1), str(i % 10), *[f"{v:g}" for v in sample]])
        rows.append([])
    rows += [
        ["Trajectories"],
        [f"{rate:g}"],
        ["", ""] + [c for name in labels for c in (name, "", "")],
        ["Frame", "Sub Frame"] + ["X", "Y", "Z"] * len(labels),
        ["", ""] + ["mm"] * (3 * len(labels)),
    ]
    for i, frame in enumerate(xyz_mm):
        rows.append([str(i + 1), "0", *[("" if not np.isfinite(v) else f"{v:g}") for v in frame.ravel()]])
    return "\n".join(",".join(r) for r in rows) + "\n"
