"""Free-parameter sets: names, units, priors, and the presets `camera`, `head_camera`, `leg`.

A parameter is a deviation from the nominal model (nominal value 0). Names follow DESIGN.md and mean the same
everywhere: `<joint>.offset` (encoder offset, rad), `<camera>.x|y|z|rx|ry|rz` (the head camera's pose correction:
the frame correction of the fixed joint above its optical frame, in that joint's child frame, m / rad; `<camera>` is
the config's `camera.name`, default `camera`; result.yaml says which URDF joint it is written to),
`tag<id>.x|...|rz` (tag mount correction in the tag frame, m / rad).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.presets import PRESETS
from wolfcal.robot.robot import Robot

COMPONENTS = ("x", "y", "z", "rx", "ry", "rz")
SIDES = ("right", "left", "both")


@dataclass(frozen=True)
class Parameter:
    name: str
    # 'offset' | 'frame' | 'tag' (chain parameters) | 'pose' (a measurement block's own unknown) | 'marking' (a
    # field marking's place: held by its prior against the robot's place, left out of the condition number)
    kind: str
    target: str  # joint name, tag id as text, or the block's name for its unknowns (e.g. 'tripod@1')
    component: int  # index in (x, y, z, rx, ry, rz); 0 for offsets
    unit: str  # 'rad' | 'm' | 'px' (a measurement block's image-space unknown)
    prior_sigma: float  # standard deviation of the Gaussian prior around `reference`, in `unit`
    reference: float = 0.0  # prior mean and starting value (0: the nominal model) [unit]

    @property
    def in_chain(self) -> bool:
        """Whether the parameter changes the robot model (rather than a measurement block's own unknowns)."""
        return self.kind in ("offset", "frame", "tag")


class ParameterSet:
    """An ordered list of free parameters; maps value vectors to `Corrections`."""

    def __init__(self, parameters: list[Parameter]):
        self.parameters = parameters
        self.names = [p.name for p in parameters]
        self.prior_sigmas = np.array([p.prior_sigma for p in parameters], dtype=float)
        self.references = np.array([p.reference for p in parameters], dtype=float)

    def __len__(self) -> int:
        return len(self.parameters)

    def __add__(self, other: ParameterSet) -> ParameterSet:
        return ParameterSet(self.parameters + other.parameters)

    def values(self, z: np.ndarray) -> np.ndarray:
        """Parameter values [SI] from prior-normalised unknowns z = (value - reference) / prior_sigma."""
        return self.references + np.asarray(z, dtype=float) * self.prior_sigmas

    def corrections(self, values: np.ndarray) -> Corrections:
        """The corrections these parameter values [SI] stand for."""
        out = Corrections()
        for p, value in zip(self.parameters, np.asarray(values, dtype=float)):
            if not p.in_chain:
                continue
            if p.kind == "offset":
                out.offsets[p.target] = out.offsets.get(p.target, 0.0) + float(value)
            else:
                vec = (out.frames.setdefault(p.target, np.zeros(6)) if p.kind == "frame"
                       else out.tags.setdefault(int(p.target), np.zeros(6)))  # fmt: skip
                vec[p.component] += value
        return out

    def centred_on(self, corrections: Corrections) -> ParameterSet:
        """The same parameters with their references (prior means and starting values) at the values `corrections`
        hold (e.g. the robot's present calibration); parameters it does not hold stay at 0."""
        return ParameterSet([replace(p, reference=float(v)) if p.in_chain else p
                             for p, v in zip(self.parameters, self.values_from(corrections))])  # fmt: skip

    def held(self, corrections: Corrections) -> Corrections:
        """The part of `corrections` these parameters do not free (offsets of other joints, frames of other joints,
        other tags' mounts): what a fit holds fixed under them."""
        offsets = {p.target for p in self.parameters if p.kind == "offset"}
        frames = {p.target for p in self.parameters if p.kind == "frame"}
        tags = {int(p.target) for p in self.parameters if p.kind == "tag"}
        return Corrections({k: v for k, v in corrections.offsets.items() if k not in offsets},
                           {k: v for k, v in corrections.frames.items() if k not in frames},
                           {k: v for k, v in corrections.tags.items() if k not in tags})  # fmt: skip

    def held_by(self, corrections: Corrections) -> np.ndarray:
        """(P,) whether `corrections` holds a value of each chain parameter (its joint's offset, its frame, its tag)."""
        held: dict[str, set] = {"offset": set(corrections.offsets), "frame": set(corrections.frames),
                                "tag": set(corrections.tags)}  # fmt: skip
        return np.array([p.in_chain and (int(p.target) if p.kind == "tag" else p.target) in held[p.kind]
                         for p in self.parameters], bool)  # fmt: skip

    def values_from(self, corrections: Corrections) -> np.ndarray:
        """The parameter values a `Corrections` object holds (e.g. a simulator's truth) [SI]."""
        values = []
        for p in self.parameters:
            if not p.in_chain:
                values.append(p.reference)
            elif p.kind == "offset":
                values.append(corrections.offsets.get(p.target, 0.0))
            else:
                vec = (corrections.frames.get(p.target) if p.kind == "frame"
                       else corrections.tags.get(int(p.target)))  # fmt: skip
                values.append(float(vec[p.component]) if vec is not None else 0.0)
        return np.array(values, dtype=float)


def frame_parameters(prefix: str, kind: str, target: str, sigma_m: float, sigma_rad: float) -> list[Parameter]:
    """The six parameters `prefix`.x|y|z [m] and .rx|ry|rz [rad] of a frame correction of `target`, with prior
    sigmas `sigma_m` [m] and `sigma_rad` [rad]."""
    return [
        Parameter(f"{prefix}.{c}", kind, target, i, "m" if i < 3 else "rad", sigma_m if i < 3 else sigma_rad)
        for i, c in enumerate(COMPONENTS)
    ]


def offset_parameter(joint: str, sigma: float) -> Parameter:
    """The encoder offset [rad] of `joint`, with prior sigma `sigma` [rad]."""
    return Parameter(f"{joint}.offset", "offset", joint, 0, "rad", sigma)


def check_preset(preset: str, side: str) -> None:
    """A clear error for an unknown --free preset or --side."""
    if preset not in PRESETS:
        raise WolfcalError(f"--free {preset!r} is not a preset; use one of {', '.join(PRESETS)}")
    if side not in SIDES:
        raise WolfcalError(f"--side {side!r} must be one of {', '.join(SIDES)}")


def tags_for_preset(robot: Robot, preset: str, observed_tag_ids: list[int], side: str) -> list[int]:
    """The observed tags whose observations the preset uses (the leg preset keeps the chosen side's tags)."""
    if preset != "leg" or side == "both":
        return list(observed_tag_ids)
    return [t for t in observed_tag_ids if robot.config.tag(t).side in (side, None)]


def build_parameter_set(
    robot: Robot,
    preset: str,
    tags_by_camera: dict[str, list[int]],
    side: str = "both",
    fix_tags: bool = False,
    marker_links: tuple[str, ...] = (),
) -> ParameterSet:
    """Free chain parameters of a preset for the tags each camera ('head' or an external camera's name) uses.

    With the head camera: camera = its frame correction + the mounts of the tags used; head_camera = + offsets of
    the joints between base and camera; leg = + offsets of the joints between base and each used tag's link (the
    chain camera -> tag). With an external camera, leg frees the offsets of the joints between the base and the
    links of the tags it sees (the torso-to-foot chains) and those tags' mounts (the torso tag's too). With motion
    capture, leg also frees the offsets of the joints between the base and the links of the markers used
    (`marker_links`); the marker mounts are the motion-capture block's own unknowns.
    """
    check_preset(preset, side)
    priors = robot.config.priors
    params: list[Parameter] = []
    links: list[str] = []
    if "head" in tags_by_camera:
        camera_joint = robot.camera_joint
        params += frame_parameters(robot.config.head_camera().name, "frame", camera_joint,
                                   priors.camera_translation, priors.camera_rotation)  # fmt: skip
        if preset in ("head_camera", "leg"):
            links.append(robot.config.head_camera().frame)
    if preset == "leg":
        links += [robot.config.tag(t).link for tags in tags_by_camera.values() for t in tags] + list(marker_links)
    params += [offset_parameter(joint, priors.offset) for joint in robot.actuated_joints_to(links)]
    if not fix_tags:
        for tag_id in sorted({t for tags in tags_by_camera.values() for t in tags}):
            params += frame_parameters(f"tag{tag_id}", "tag", str(tag_id), priors.tag_translation, priors.tag_rotation)
    return ParameterSet(params)
