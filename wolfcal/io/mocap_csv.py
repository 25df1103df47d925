"""OptiTrack Motive and Vicon Nexus CSV exports -> `MarkerTrajectories`.

Motive (CSV formats 1.21-1.24): line 1 holds key, value pairs ('Format Version', '1.23', ..., 'Export Frame Rate',
'360.000000', ..., 'Length Units', 'Millimeters', ...); a blank line; then the column header rows Type, Name, ID,
(Parent,) the kind row ('Rotation', 'Position', 'Marker Quality', 'Error Per Marker', ...) and the axis row starting
'Frame, Time (Seconds)' (1.21: 'Frame, Time'); then one line per frame. Format 1.21 writes the header rows with
their first two cells empty; 1.22 on write the row's name in the second cell (',Type,...'). Read: the columns of
Type 'Marker' whose kind is 'Position' (X, Y, Z), labelled by their Name as written ('Rigid Body 1:Marker1',
'Unlabeled 1036', 'Unlabeled:108'). Rigid Body, Rigid Body Marker, Bone and Bone Marker columns are the system's
solved asset poses and model marker places, not measurements: not read. Times: (frame - first frame) / Export Frame
Rate (the 'Time' column is rounded to 1 ms by modern Motive). A blank cell: not measured.

Vicon Nexus: sections ('Devices', 'Joints', 'Model Outputs', 'Segments', 'Trajectories'), each a name line, a rate
line, a names line ('Subject:Marker' above each X column), the axis line 'Frame, Sub Frame, X, Y, Z, ...', a units
line (mm) and the data lines, ended by a blank line. Read: the Trajectories section, wherever it is in the file.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.io.mocap_trajectories import MarkerTrajectories, NoMarkers, times_from_frames, unit_scale

MOTIVE_ROWS = ("Type", "Name", "ID", "Parent")  # header rows above the kind row, in Motive's order
VICON_SECTIONS = ("Devices", "Joints", "Model Outputs", "Segments", "Trajectories")


def read_csv_export(path: Path) -> MarkerTrajectories:
    """A Motive or Vicon Nexus CSV export, told apart by its first cell. UTF-8 (with or without a byte-order mark),
    else Windows-1252: Motive and Nexus on Windows write take and subject names in the system's code page."""
    raw = path.read_bytes()
    if b"\0" in raw[:4096]:
        raise WolfcalError(f"{path}: a binary file, not a CSV export; give a Motive or Vicon Nexus CSV export")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("cp1252", errors="replace")
    rows = list(csv.reader(io.StringIO(text, newline="")))
    first = rows[0][0].strip() if rows and rows[0] else ""
    if first == "Format Version":
        return read_motive(path, rows)
    if first in VICON_SECTIONS:
        return read_vicon(path, rows)
    raise WolfcalError(
        f"{path}: neither a Motive CSV export (first cell 'Format Version') nor a Vicon Nexus CSV "
        f"export (first cell 'Trajectories' or 'Devices'); found {first!r}"
    )


def numbers(path: Path, rows: list[list[str]], first_line: int, columns: list[int]) -> np.ndarray:
    """(len(rows), len(columns)) floats of data rows, NaN for blank or missing cells; `first_line` is the 0-based
    line of rows[0] in the file, for messages."""
    out = np.full((len(rows), len(columns)), np.nan)
    for i, row in enumerate(rows):
        for j, c in enumerate(columns):
            if c < len(row) and row[c].strip():
                try:
                    out[i, j] = float(row[c])
                except ValueError:
                    raise WolfcalError(
                        f"{path}: line {first_line + i + 1}, column {c + 1}: {row[c]!r} is not a number"
                    ) from None
    return out


def read_motive(path: Path, rows: list[list[str]]) -> MarkerTrajectories:
    meta = rows[0]
    pairs = {meta[i].strip(): meta[i + 1].strip() for i in range(0, len(meta) - 1, 2)}
    version = pairs.get("Format Version", "?")
    axis_line = next((i for i, r in enumerate(rows[:20]) if r and r[0].strip() == "Frame"), None)
    if axis_line is None or axis_line < 3:
        raise WolfcalError(
            f"{path}: Motive CSV {version}: no column header line starting 'Frame' in the first 20 "
            "lines; export with the header rows on"
        )
    kinds = rows[axis_line - 1]
    first_header = next(i for i in range(1, axis_line) if any(c.strip() for c in rows[i]))
    header = rows[first_header : axis_line - 1]
    named = {r[1].strip(): r for r in header if len(r) > 1 and r[1].strip() in MOTIVE_ROWS}
    if not named:  # format 1.21: the rows carry no names, in Motive's order
        named = dict(zip(MOTIVE_ROWS, header))
    if "Type" not in named or "Name" not in named:
        raise WolfcalError(f"{path}: Motive CSV {version}: no Type and Name rows above line {axis_line}")
    types, names, axes = named["Type"], named["Name"], rows[axis_line]
    cell = lambda row, c: row[c].strip() if c < len(row) else ""  # noqa: E731
    labels, columns, skipped = [], [], set()
    for c in range(2, len(axes) - 2):
        if cell(axes, c) != "X" or cell(kinds, c) != "Position":
            continue
        if cell(types, c) != "Marker":
            skipped.add(cell(types, c) or "untyped")
            continue
        if [cell(axes, c + 1), cell(axes, c + 2)] != ["Y", "Z"] or len({cell(names, c + i) for i in range(3)}) != 1:
            raise WolfcalError(
                f"{path}: Motive CSV {version}: column {c + 1}: marker {cell(names, c)!r} has no "
                "X, Y, Z columns of one name"
            )
        labels.append(cell(names, c))
        columns += [c, c + 1, c + 2]
    if not labels:
        raise NoMarkers(
            f"{path}: Motive CSV {version}: no Marker position columns; it holds "
            f"{', '.join(sorted(skipped)) or 'no position columns'} only; export the markers"
        )
    rate_text = pairs.get("Export Frame Rate") or pairs.get("Capture Frame Rate", "")
    try:
        rate = float(rate_text)
    except ValueError:
        rate = 0.0
    if not rate > 0:
        raise WolfcalError(
            f"{path}: Motive CSV {version}: the first line gives no 'Export Frame Rate' (found {rate_text!r})"
        )
    scale = unit_scale(path, pairs.get("Length Units", ""), f"Motive CSV {version}: the first line's 'Length Units'")
    data_rows = [r for r in rows[axis_line + 1 :] if r and any(c.strip() for c in r)]
    data = numbers(path, data_rows, axis_line + 1, [0] + columns)
    if np.isnan(data[:, 0]).any():
        raise WolfcalError(f"{path}: Motive CSV {version}: a data line without a frame number (column 1)")
    xyz = data[:, 1:].reshape(len(data), -1, 3) * scale
    return MarkerTrajectories(path, times_from_frames(data[:, 0], rate), labels, xyz, file_clock=True,
                              format=f"Motive CSV {version}", rate_hz=rate, unit=pairs["Length Units"])  # fmt: skip


def read_vicon(path: Path, rows: list[list[str]]) -> MarkerTrajectories:
    starts = {r[0].strip(): i for i, r in enumerate(rows) if r and r[0].strip() in VICON_SECTIONS}
    if "Trajectories" not in starts:
        held = ", ".join(f"{name} ({_section_summary(rows, i)})" for name, i in starts.items())
        raise NoMarkers(
            f"{path}: Vicon Nexus CSV without a Trajectories section; it holds {held} "
            "(analog only); export the trajectories"
        )
    start = starts["Trajectories"]
    if start + 5 > len(rows):
        raise WolfcalError(
            f"{path}: Vicon Nexus CSV: the Trajectories section (line {start + 1}) ends before its "
            "rate, names, axis and units lines"
        )
    try:
        rate = float(rows[start + 1][0])
    except (ValueError, IndexError):
        rate = 0.0
    if not rate > 0:
        raise WolfcalError(f"{path}: Vicon Nexus CSV: line {start + 2} gives no frame rate under 'Trajectories'")
    names, axes, units = rows[start + 2], rows[start + 3], rows[start + 4]
    if not axes or axes[0].strip() != "Frame":
        raise WolfcalError(f"{path}: Vicon Nexus CSV: line {start + 4} is not the 'Frame, Sub Frame, X, Y, Z' line")
    labels, columns, scales = [], [], []
    for c in range(2, len(axes) - 2):
        if axes[c].strip() == "X" and c < len(names) and names[c].strip():
            labels.append(names[c].strip())
            columns += [c, c + 1, c + 2]
            unit = units[c] if c < len(units) else ""
            scales.append(
                unit_scale(path, unit, f"Vicon Nexus CSV: the units line (line {start + 5}) under {names[c].strip()!r}")
            )
    if not labels:
        raise NoMarkers(f"{path}: Vicon Nexus CSV: the Trajectories section names no markers")
    end = next((i for i in range(start + 5, len(rows)) if not rows[i] or not rows[i][0].strip()), len(rows))
    data = numbers(path, rows[start + 5 : end], start + 5, [0] + columns)
    if not len(data):
        raise WolfcalError(f"{path}: Vicon Nexus CSV: the Trajectories section holds no frames")
    xyz = data[:, 1:].reshape(len(data), -1, 3) * np.array(scales)[None, :, None]
    unit = units[columns[0]].strip() if columns[0] < len(units) else ""
    return MarkerTrajectories(path, times_from_frames(data[:, 0], rate), labels, xyz, file_clock=True,
                              format="Vicon Nexus CSV", rate_hz=rate, unit=unit)  # fmt: skip


def _section_summary(rows: list[list[str]], start: int) -> str:
    """'N channels at R Hz' of a Vicon section, from its rate and axis lines."""
    rate = rows[start + 1][0].strip() if start + 1 < len(rows) and rows[start + 1] else "?"
    axes = rows[start + 3] if start + 3 < len(rows) else []
    return f"{sum(1 for c in axes[2:] if c.strip())} channels at {rate} Hz"
