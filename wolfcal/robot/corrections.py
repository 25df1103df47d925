"""Corrections to the nominal kinematic model: the values a calibration estimates and a simulator takes as truth.

- encoder offsets: q_model = q_measured + offset [rad], per actuated joint;
- frame corrections of joints: origin_new = origin @ Delta, Delta = Trans(x, y, z) @ Exp(rx, ry, rz) in the child frame;
- tag mount corrections: T_link_tag_new = T_link_tag @ Delta (same form).
Vectors are (x, y, z, rx, ry, rz) in metres and radians. YAML form: {offsets: {joint: rad}, frames: {joint: [6]},
tags: {id: [6]}}.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.yamlfile import read_yaml


@dataclass
class Corrections:
    offsets: dict[str, float] = field(default_factory=dict)
    frames: dict[str, np.ndarray] = field(default_factory=dict)
    tags: dict[int, np.ndarray] = field(default_factory=dict)

    def offset_vector(self, joint_names: list[str]) -> np.ndarray:
        """(J,) offsets [rad] in the order of `joint_names` (0 for joints without one)."""
        return np.array([self.offsets.get(n, 0.0) for n in joint_names], dtype=float)

    def plus(self, other: Corrections) -> Corrections:
        """Offsets and correction vectors added (exact when one side is empty; first order otherwise)."""
        offsets = dict(self.offsets)
        for joint, offset in other.offsets.items():
            offsets[joint] = offsets.get(joint, 0.0) + offset
        frames = {k: np.asarray(v, float).copy() for k, v in self.frames.items()}
        for joint, vec in other.frames.items():
            frames[joint] = frames.get(joint, np.zeros(6)) + vec
        tags = {k: np.asarray(v, float).copy() for k, v in self.tags.items()}
        for tag_id, vec in other.tags.items():
            tags[tag_id] = tags.get(tag_id, np.zeros(6)) + vec
        return Corrections(offsets, frames, tags)

    def overridden_by(self, other: Corrections) -> Corrections:
        """These corrections with every offset, frame and tag mount that `other` holds replaced by its value (e.g.
        the robot's present calibration with the fitted parameters' new totals)."""
        frames = {k: np.asarray(v, float).copy() for k, v in {**self.frames, **other.frames}.items()}
        tags = {k: np.asarray(v, float).copy() for k, v in {**self.tags, **other.tags}.items()}
        return Corrections({**self.offsets, **other.offsets}, frames, tags)

    def to_dict(self) -> dict:
        return {
            "offsets": {k: float(v) for k, v in self.offsets.items()},
            "frames": {k: [float(x) for x in v] for k, v in self.frames.items()},
            "tags": {int(k): [float(x) for x in v] for k, v in self.tags.items()},
        }

    @classmethod
    def from_dict(cls, data: dict, source: str = "corrections") -> Corrections:
        if not isinstance(data, dict):
            raise WolfcalError(f"{source}: expected a mapping with offsets, frames and tags")
        unknown = set(data) - {"offsets", "frames", "tags"}
        if unknown:
            raise WolfcalError(f"{source}: unknown key(s) {', '.join(sorted(map(str, unknown)))}")

        def vec6(where: str, value) -> np.ndarray:
            arr = np.asarray(value, dtype=float)
            if arr.shape != (6,) or not np.all(np.isfinite(arr)):
                raise WolfcalError(f"{source}: '{where}' must be 6 numbers (x y z rx ry rz), found {value!r}")
            return arr

        return cls(
            offsets={str(k): float(v) for k, v in (data.get("offsets") or {}).items()},
            frames={str(k): vec6(f"frames.{k}", v) for k, v in (data.get("frames") or {}).items()},
            tags={int(k): vec6(f"tags.{k}", v) for k, v in (data.get("tags") or {}).items()},
        )


def load_corrections(path: str | Path, key: str | None = None) -> Corrections:
    """Read corrections from a YAML file (optionally from one key of it, e.g. 'truth' of a simulator's file)."""
    path = Path(path)
    data = read_yaml(path, "corrections file")
    if key is not None:
        if not isinstance(data, dict) or key not in data:
            raise WolfcalError(f"{path}: missing key '{key}'")
        data = data[key]
    return Corrections.from_dict(data, str(path))
