"""C3D files written byte by byte in the layout of the C3D specification (c3d.org, "The C3D File Format User Guide"),
for the variants ezc3d cannot write: DEC (VAX) and SGI/MIPS processor formats, NUL-padded units, a parameter defined
twice in a group, frame counts past 16 bits, and any parameter set a test needs.

Layout: a 512-byte header block (word 1: parameter block and key 0x50; words 2-6: points, analog samples per frame,
first and last frame (16 bits), interpolation gap; words 7-8: scale (< 0: float data); word 9: data start block;
word 10: analog samples per point frame; words 11-12: frame rate), the parameter section (4 bytes: -, 0x50, blocks,
processor 84 Intel | 85 DEC | 86 SGI/MIPS; then group and parameter records), then per frame each point's x, y, z and
residual word (camera mask << 8 | residual; negative: invalid), then the analog samples. Intel: little-endian IEEE
floats; DEC: little-endian integers, VAX F floats (IEEE value times 4, 16-bit halves swapped); SGI: big-endian.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

PROCESSOR = {"intel": 84, "dec": 85, "sgi": 86}


@dataclass
class Parameter:
    group: str
    name: str
    value: object  # str | list[str] (characters), int | list[int] (int16), float | list[float] (float32)
    kind: str = ""  # "char" | "int" | "byte" | "float": from the value when empty


@dataclass
class C3DLayout:
    """One file: points (F, K, 3) in the file's unit, NaN = invalid; the parameters written in the given order
    (POINT and ANALOG basics are added unless given)."""

    points: np.ndarray
    rate: float = 100.0
    labels: list[str] = field(default_factory=list)
    units: str | list[str] = "mm"
    processor: str = "intel"
    float_data: bool = True
    scale: float = 0.1  # integer data: file value = int16(round(x / scale))
    analog: np.ndarray | None = None  # (F * per_frame, C) samples
    analog_per_frame: int = 0
    header_analog: int | None = None  # word 3 as written (default: channels * per_frame)
    header_last_frame: int | None = None  # word 5 as written (default: min(frames, 65535))
    frames_parameter: int | None = None  # POINT:FRAMES word (default: frames up to 65535, else 65535 and
    # TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD as two 16-bit words each, low word first, as Vicon writes them)
    extra: list[Parameter] = field(default_factory=list)
    skip: set[str] = field(default_factory=set)  # "GROUP:NAME" of default parameters to leave out

    def to_bytes(self) -> bytes:
        f, k = self.points.shape[:2]
        params = self._parameters(f, k)
        param_bytes = self._param_section(params)
        n_param_blocks = (len(param_bytes) + 511) // 512
        data_start = 2 + n_param_blocks
        header = self._header(f, k, data_start)
        body = self._data(f, k)
        param_block = param_bytes.ljust(n_param_blocks * 512, b"\0")
        return header + param_block + body

    # --- numbers in the processor's format ---
    def _i16(self, v: int) -> bytes:
        """A 16-bit word: -32768..32767 signed, 32768..65535 as the unsigned word (as writers store counts)."""
        v = int(v)
        return struct.pack(">H" if self.processor == "sgi" else "<H", v & 0xFFFF)

    def _u16(self, v: int) -> bytes:
        return struct.pack(">H" if self.processor == "sgi" else "<H", int(v))

    def _f32(self, values) -> bytes:
        a = np.asarray(values, dtype=np.float64).ravel()
        if self.processor == "sgi":
            return a.astype(">f4").tobytes()
        if self.processor == "intel":
            return a.astype("<f4").tobytes()
        raw = (a * 4.0).astype("<f4").tobytes()  # VAX F: value * 4 in IEEE, then the 16-bit halves swapped
        words = np.frombuffer(raw, dtype="<u2").reshape(-1, 2)[:, ::-1]
        return words.astype("<u2").tobytes()

    def _header(self, f: int, k: int, data_start: int) -> bytes:
        channels = 0 if self.analog is None else self.analog.shape[1]
        analog_words = channels * self.analog_per_frame if self.header_analog is None else self.header_analog
        last = min(f, 65535) if self.header_last_frame is None else self.header_last_frame
        scale = -abs(self.scale) if self.float_data else abs(self.scale)
        head = bytes([2, 0x50]) + self._u16(k) + self._u16(analog_words) + self._u16(1) + self._u16(last)
        head += self._u16(10) + self._f32([scale]) + self._u16(data_start) + self._u16(self.analog_per_frame)
        head += self._f32([self.rate])
        return head.ljust(512, b"\0")

    def _parameters(self, f: int, k: int) -> list[Parameter]:
        channels = 0 if self.analog is None else self.analog.shape[1]
        frames = self.frames_parameter if self.frames_parameter is not None else min(f, 65535)
        trial = (
            [
                Parameter("TRIAL", "ACTUAL_START_FIELD", [1, 0]),
                Parameter("TRIAL", "ACTUAL_END_FIELD", [f & 0xFFFF, f >> 16]),
            ]
            if f > 65535
            else []
        )
        defaults = [
            Parameter("POINT", "USED", k),
            Parameter("POINT", "FRAMES", frames, "int"),
            Parameter("POINT", "SCALE", -abs(self.scale) if self.float_data else abs(self.scale)),
            Parameter("POINT", "RATE", self.rate),
            Parameter("POINT", "DATA_START", 0),
            Parameter("POINT", "LABELS", self.labels),
            Parameter("POINT", "UNITS", self.units),
            Parameter("ANALOG", "USED", channels),
            Parameter("ANALOG", "RATE", self.rate * self.analog_per_frame),
            Parameter("ANALOG", "GEN_SCALE", 1.0),
            Parameter("ANALOG", "SCALE", [1.0] * channels),
            Parameter("ANALOG", "OFFSET", [0] * channels),
            Parameter("ANALOG", "LABELS", [f"CH{i + 1}" for i in range(channels)]),
            Parameter("ANALOG", "UNITS", ["V"] * channels),
            *trial,
        ]
        given = {(p.group, p.name) for p in self.extra}
        out = [p for p in defaults if f"{p.group}:{p.name}" not in self.skip and (p.group, p.name) not in given]
        return out + self.extra

    def _param_section(self, params: list[Parameter]) -> bytes:
        groups = list(dict.fromkeys(p.group for p in params))
        records = []
        for gid, group in enumerate(groups, start=1):
            records.append(self._record(-gid, group, b"\0"))  # group: description length 0
            for p in params:
                if p.group == group:
                    records.append(self._record(gid, p.name, self._param_body(p)))
        out = b""
        for i, (head, name, rest) in enumerate(records):
            offset = 0 if i == len(records) - 1 else 2 + len(rest)
            out += head + name + self._i16(offset) + rest
        n_blocks = (4 + len(out) + 511) // 512
        return bytes([1, 0x50, n_blocks, PROCESSOR[self.processor]]) + out

    @staticmethod
    def _record(gid: int, name: str, rest: bytes) -> tuple[bytes, bytes, bytes]:
        return struct.pack("<bb", len(name), gid), name.encode(), rest

    def _param_body(self, p: Parameter) -> bytes:
        kind = p.kind or ("char" if isinstance(p.value, str) or (isinstance(p.value, list) and p.value
                                                                 and isinstance(p.value[0], str))
                          else "float" if isinstance(p.value, float) or (isinstance(p.value, list) and p.value
                                                                        and isinstance(p.value[0], float))
                          else "int")  # fmt: skip
        if kind == "char":
            if isinstance(p.value, str):
                data, dims = p.value.encode("latin-1"), [len(p.value)]
            else:
                width = max([len(s) for s in p.value] + [1])
                data = b"".join(s.encode("latin-1").ljust(width) for s in p.value)
                dims = [width, len(p.value)]
            body = struct.pack("<bB", -1, len(dims)) + bytes(dims) + data
        else:
            values = p.value if isinstance(p.value, list) else [p.value]
            dims = [] if not isinstance(p.value, list) else [len(values)]
            if kind == "float":
                data, size = self._f32(values), 4
            elif kind == "byte":
                data, size = bytes(int(v) & 0xFF for v in values), 1
            else:
                data, size = b"".join(self._i16(v) for v in values), 2
            body = struct.pack("<bB", size, len(dims)) + bytes(dims) + data
        return body + b"\0"  # description length 0

    def _data(self, f: int, k: int) -> bytes:
        pts = np.zeros((f, k, 4))
        valid = np.all(np.isfinite(self.points), axis=2)
        pts[:, :, :3] = np.where(valid[..., None], self.points, 0.0)
        if self.float_data:
            pts[:, :, 3] = np.where(valid, 0.5, -1.0)  # residual in the file's unit; -1: invalid
        else:
            pts[:, :, :3] = np.round(pts[:, :, :3] / self.scale)
            pts[:, :, 3] = np.where(valid, 2, -1)  # residual word: mask 0, residual 2 (x scale)
        per_frame = self.analog_per_frame
        analog = None if self.analog is None else self.analog.reshape(f, per_frame * self.analog.shape[1])
        frames = []
        for i in range(f):
            row = self._f32(pts[i]) if self.float_data else b"".join(self._i16(v) for v in pts[i].ravel())
            if analog is not None:
                row += self._f32(analog[i]) if self.float_data else b"".join(self._i16(v) for v in analog[i])
            frames.append(row)
        return b"".join(frames)
