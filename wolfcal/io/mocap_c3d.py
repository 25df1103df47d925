"""C3D files read with ezc3d (the C++ reader of the pyomeca lab, wheels for every common platform).

ezc3d reads Intel and DEC (VAX) processor formats, integer and float storage, parameters defined twice, analog
headers that disagree with ANALOG:USED and frame counts past 16 bits (POINT:FRAMES or TRIAL:ACTUAL_END_FIELD); it
sets a point whose residual is negative (invalid) to NaN. It refuses SGI/MIPS files (big-endian), so those are first
copied to a temporary file in Intel byte order (`mips_to_intel`: every 16-bit word and 32-bit float of the header,
the parameter records and the data swapped; the processor byte set to Intel) and read from there.

On top of ezc3d: labels are POINT:LABELS, then LABELS2, LABELS3, ... (255 per parameter), cut to POINT:USED; a point
past the labels is named `point <n>` (its 1-based column). POINT:UNITS is one unit for every point or one per point,
NUL or space padded ('mm\\0\\0'). A file without points says what it holds instead (analog channels, force plates,
rotations).
"""

from __future__ import annotations

import os
import struct
import tempfile
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.io.mocap_trajectories import MarkerTrajectories, NoMarkers, times_from_frames, unit_scale

PROCESSORS = {84: "Intel", 85: "DEC", 86: "SGI/MIPS"}


def import_ezc3d(what: str) -> ModuleType:
    """The ezc3d module; a WolfcalError saying how to install it where PyPI has no wheel (ARM Linux)."""
    try:
        import ezc3d
    except ImportError:
        raise WolfcalError(
            f"{what} needs ezc3d, which PyPI has no wheel of for this computer: 'conda install -c "
            "conda-forge ezc3d', or 'pip install ezc3d' with cmake and swig installed; or use a CSV "
            "export"
        ) from None
    return ezc3d


def read_c3d(path: Path) -> MarkerTrajectories:
    """Every point of a C3D file in metres, NaN where invalid; times since the first frame."""
    ezc3d = import_ezc3d(f"{path}: reading a C3D file")

    data = path.read_bytes()
    kind, announced = check_layout(data)
    if kind == "SGI/MIPS":
        handle_fd, scratch = tempfile.mkstemp(suffix=".c3d")
        try:
            with os.fdopen(handle_fd, "wb") as out:
                out.write(mips_to_intel(data))
            c = ezc3d.c3d(scratch)
        finally:
            os.unlink(scratch)
    else:
        c = ezc3d.c3d(str(path))
    params = c["parameters"]
    point = params["POINT"]
    points = c["data"]["points"]  # (4, K, F): x, y, z, 1
    if points.shape[1] == 0:
        raise NoMarkers(
            f"{path}: no marker trajectories in this C3D file (POINT:USED 0); it holds "
            f"{_contents(params)}; export the markers' trajectories (the POINT group) to use it"
        )
    k = points.shape[1]
    notes = (
        [
            f"the data section holds {points.shape[2]} of the {announced} frames POINT:FRAMES announces: the file "
            "may be cut off"
        ]
        if points.shape[2] < announced
        else []
    )
    labels = [str(s).strip() for name in _label_parameters(point) for s in point[name]["value"]][:k]
    labels += [f"point {i + 1}" for i in range(len(labels), k)]
    scale = _point_scales(path, point, k)
    rate = float(_first(point, "RATE", 0.0)) or float(c["header"]["points"]["frame_rate"])
    if not rate > 0:
        raise WolfcalError(f"{path}: POINT:RATE and the header give no frame rate; the file cannot be timed")
    xyz = np.transpose(points[:3], (2, 1, 0)) * scale[None, :, None]
    storage = "float" if float(_first(point, "SCALE", -1.0)) < 0 else "integer"
    units = [str(u).replace("\0", "").strip() for u in point["UNITS"]["value"]]
    return MarkerTrajectories(path, times_from_frames(np.arange(xyz.shape[0], dtype=float), rate), labels, xyz,
                              file_clock=True, format=f"C3D ({kind}, {storage})", rate_hz=rate,
                              unit=units[0] if len(set(units)) == 1 else ",".join(units), notes=notes)  # fmt: skip


def _first(group: dict, name: str, default: float) -> float:
    value = group.get(name, {}).get("value", [])
    return float(value[0]) if len(value) else default


def _label_parameters(point: dict) -> list[str]:
    """LABELS, LABELS2, LABELS3, ... as far as they go without a gap."""
    names, n = [], 1
    while (name := "LABELS" if n == 1 else f"LABELS{n}") in point:
        names.append(name)
        n += 1
    return names


def _point_scales(path: Path, point: dict, k: int) -> np.ndarray:
    """(K,) metres per file unit: one POINT:UNITS entry for all points, or one per point."""
    units = [str(u) for u in point.get("UNITS", {}).get("value", [])]
    named = [u for u in units if u.replace("\0", "").strip()]
    if not named:
        return np.full(k, unit_scale(path, "", "POINT:UNITS"))
    if len({u.replace("\0", "").strip() for u in named}) == 1:
        return np.full(k, unit_scale(path, named[0], "POINT:UNITS"))
    if len(units) < k:
        raise WolfcalError(
            f"{path}: POINT:UNITS gives {len(units)} different units for {k} points; it must give "
            "one unit, or one per point"
        )
    return np.array([unit_scale(path, u, f"POINT:UNITS[{i + 1}]") for i, u in enumerate(units[:k])])


def _contents(params: dict) -> str:
    """What a C3D file without points holds, in words."""
    parts = []
    analog = int(_first(params.get("ANALOG", {}), "USED", 0))
    if analog:
        parts.append(f"{analog} analog channel(s) at {_first(params['ANALOG'], 'RATE', 0):g} Hz (analog only)")
    plates = int(_first(params.get("FORCE_PLATFORM", {}), "USED", 0))
    if plates:
        parts.append(f"{plates} force plate(s)")
    rotations = int(_first(params.get("ROTATION", {}), "USED", 0))
    if rotations:
        parts.append(f"{rotations} rotation(s) (rotations only: segment poses of a markerless system)")
    return ", ".join(parts) or "nothing else either"


def check_layout(data: bytes) -> tuple[str, int]:
    """The processor format ('Intel', 'DEC', 'SGI/MIPS') of a C3D file's bytes and the frame count POINT:FRAMES
    announces (0 when absent or full: 65535 and more are counted elsewhere; the header's count is wrong in some
    real files); ValueError when the header or the parameter records do not fit in the file
    (ezc3d loops forever on some truncated files: checked first)."""
    if len(data) < 512:
        raise ValueError(f"{len(data)} bytes, shorter than a C3D header (512 bytes)")
    if data[1] != 0x50:
        raise ValueError("the header's key byte is not 0x50 (80): not a C3D file")
    section = (max(data[0], 1) - 1) * 512
    if section + 4 > len(data):
        raise ValueError(f"the parameter section (block {data[0]}) lies past the end of the file")
    kind = PROCESSORS.get(data[section + 3])
    if kind is None:
        raise ValueError(f"unknown processor type {data[section + 3]} (84 Intel, 85 DEC, 86 SGI/MIPS)")
    big = kind == "SGI/MIPS"
    groups, frames = {}, 0
    for at, group, name_len in parameter_records(data, section, big_endian=big):
        name = data[at - name_len : at].decode("latin-1").upper()
        if group < 0:
            groups[-group] = name
        elif groups.get(group) == "POINT" and name == "FRAMES" and data[at + 2] == 2 and data[at + 3] == 0:
            frames = struct.unpack(">H" if big else "<H", data[at + 4 : at + 6])[0]
    return kind, frames if frames < 65535 else 0


def parameter_records(data: bytes, section: int, big_endian: bool) -> Iterator[tuple[int, int, int]]:
    """(offset word position, group id, name length) of each group and parameter record, in file order; ValueError
    when a record runs past the end of the file or the chain does not end."""
    pos = section + 4
    end = section + max(data[section + 2], 1) * 512
    if end > len(data):
        raise ValueError(f"the parameter section ({data[section + 2]} blocks) runs past the end of the file")
    for _ in range(100_000):
        if pos + 2 > len(data):
            raise ValueError(f"the parameter section is cut off at byte {pos} (the file has {len(data)})")
        name_len, group = struct.unpack("bb", data[pos : pos + 2])
        name_len = abs(name_len)
        if name_len == 0:
            return
        at = pos + 2 + name_len
        if at + 4 > len(data):
            raise ValueError(f"the parameter section is cut off at byte {at} (the file has {len(data)})")
        yield at, group, name_len
        offset = struct.unpack(">h" if big_endian else "<h", data[at : at + 2])[0]
        if offset <= 0 or at + offset >= end:
            return
        pos = at + offset
    raise ValueError("the parameter records do not end")


def mips_to_intel(data: bytes) -> bytes:
    """An SGI/MIPS (big-endian) C3D file's bytes in Intel (little-endian) order, processor byte 84."""
    out = bytearray(data)

    def swap(start: int, size: int, count: int) -> None:
        end = min(start + size * count, len(out) - (len(out) - start) % size)
        if end > start:
            out[start:end] = np.frombuffer(bytes(out[start:end]), dtype=f">u{size}").astype(f"<u{size}").tobytes()

    is_float = struct.unpack(">f", data[12:16])[0] < 0  # header words 7-8: the point scale, < 0 for float data
    swap(2, 2, 5)  # words 2-6: points, analog samples per frame, first and last frame, gap
    swap(12, 4, 1)  # scale
    swap(16, 2, 2)  # data start block, analog samples per point frame
    swap(20, 4, 1)  # frame rate
    swap(294, 2, 5)  # words 148-152: label and event keys, event count
    swap(304, 4, 18)  # words 153-188: event times
    section = (data[0] - 1) * 512
    out[section + 3] = 84
    for at, group, _ in parameter_records(data, section, big_endian=True):
        swap(at, 2, 1)
        if group > 0:  # a parameter: type, dimensions, values
            size, ndims = struct.unpack("b", data[at + 2 : at + 3])[0], data[at + 3]
            count = int(np.prod(list(data[at + 4 : at + 4 + ndims]))) if ndims else 1
            if abs(size) in (2, 4):
                swap(at + 4 + ndims, abs(size), count)
    start = (struct.unpack(">H", data[16:18])[0] - 1) * 512
    swap(start, 4 if is_float else 2, (len(data) - start) // (4 if is_float else 2))
    return bytes(out)
