"""The markings of a RoboCup soccer field as geometry in the field frame.

Field frame: origin at the centre mark, x toward the opponent goal, y to the left seen along x, z up [m]. The
markings are white stripes of `line_width` centred on the geometric lines this module returns: straight segments
(touch lines, goal lines, halfway line, goal and penalty area lines, the arms of the penalty and centre marks) and
the centre circle. A field is point-symmetric about its centre: a robot pose (x, y, yaw) and its mirror
(-x, -y, yaw + pi) see the same lines, which only a prior on the robot's place tells apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from wolfcal.errors import WolfcalError


@dataclass(frozen=True)
class FieldDimensions:
    """Sizes of a field's markings [m], named as in the RoboCup Humanoid League rules."""

    length: float  # between the goal lines
    width: float  # between the touch lines
    line_width: float
    center_circle_diameter: float
    penalty_mark_distance: float  # from the goal line to the penalty mark's centre
    penalty_mark_size: float  # length of each arm of the cross
    goal_area_length: float  # along x, from the goal line
    goal_area_width: float  # along y
    penalty_area_length: float
    penalty_area_width: float


# RoboCup Humanoid League fields (rules of 2021 onwards; the figures the league's own simulator uses).
KIDSIZE = FieldDimensions(9.0, 6.0, 0.05, 1.5, 1.5, 0.1, 1.0, 3.0, 2.0, 5.0)
ADULTSIZE = FieldDimensions(14.0, 9.0, 0.05, 3.0, 2.1, 0.1, 1.0, 4.0, 3.0, 6.0)


def field_dimensions(values: dict, where: str) -> FieldDimensions:
    """Dimensions from a config mapping (every key of FieldDimensions, in metres), checked for a field that can
    exist; `where` names the file and key in errors."""
    names = [f.name for f in fields(FieldDimensions)]
    unknown = sorted(set(values) - set(names))
    missing = [name for name in names if name not in values]
    if unknown or missing:
        raise WolfcalError(
            f"{where}: "
            + (f"unknown key(s) {', '.join(unknown)}; " if unknown else "")
            + (f"missing key(s) {', '.join(missing)}; " if missing else "")
            + f"give all of {', '.join(names)} [m] (KidSize: length 9.0, width 6.0; AdultSize: 14.0, 9.0)"
        )
    try:
        dims = FieldDimensions(**{name: float(values[name]) for name in names})
    except (TypeError, ValueError) as error:
        raise WolfcalError(f"{where}: every dimension must be a number of metres ({error})") from error
    check_dimensions(dims, where)
    return dims


def check_dimensions(dims: FieldDimensions, where: str) -> None:
    """Refuse a field whose markings cannot be laid out: sizes that are not positive, areas that do not nest
    inside the field, a centre circle wider than the field, a penalty mark outside its half."""
    problems = [f"{f.name} is {getattr(dims, f.name)}" for f in fields(dims) if not getattr(dims, f.name) > 0]
    rules = [
        (dims.line_width < 0.3, "line_width must be under 0.3 m (RoboCup: 0.05)"),
        (dims.width < dims.length, "width must be less than length (x runs between the goals)"),
        (dims.goal_area_width < dims.penalty_area_width, "the goal area must be narrower than the penalty area"),
        (dims.goal_area_length < dims.penalty_area_length, "the goal area must be shorter than the penalty area"),
        (dims.penalty_area_width < dims.width, "the penalty area must be narrower than the field"),
        (dims.penalty_area_length < dims.length / 2, "the penalty area must end before the halfway line"),
        (dims.center_circle_diameter < dims.width, "the centre circle must fit between the touch lines"),
        (
            dims.center_circle_diameter / 2 < dims.length / 2 - dims.penalty_area_length,
            "the centre circle must not reach the penalty areas",
        ),
        (dims.penalty_mark_distance < dims.length / 2, "the penalty mark must lie in its half"),
    ]
    if not problems:
        problems = [text for ok, text in rules if not ok]
    if problems:
        raise WolfcalError(f"{where}: impossible field dimensions: {'; '.join(problems)}")


@dataclass(frozen=True)
class FieldLines:
    """The geometric centre lines of the markings, field frame [m]."""

    segments: np.ndarray  # (S, 2, 2) start and end point of each straight line
    circle_radius: float  # the centre circle, centred on the origin
    line_width: float


def field_lines(dims: FieldDimensions) -> FieldLines:
    """Every marking of a field with these dimensions."""
    hx, hy = dims.length / 2, dims.width / 2
    segments = [
        ((-hx, -hy), (hx, -hy)),
        ((-hx, hy), (hx, hy)),  # touch lines
        ((-hx, -hy), (-hx, hy)),
        ((hx, -hy), (hx, hy)),  # goal lines
        ((0.0, -hy), (0.0, hy)),  # halfway line
    ]
    for side in (-1.0, 1.0):
        goal_x = side * hx
        for length, width in (
            (dims.goal_area_length, dims.goal_area_width),
            (dims.penalty_area_length, dims.penalty_area_width),
        ):
            inner_x = goal_x - side * length
            segments += [
                ((goal_x, -width / 2), (inner_x, -width / 2)),
                ((goal_x, width / 2), (inner_x, width / 2)),
                ((inner_x, -width / 2), (inner_x, width / 2)),
            ]
        mark_x = goal_x - side * dims.penalty_mark_distance
        arm = dims.penalty_mark_size / 2
        segments += [((mark_x - arm, 0.0), (mark_x + arm, 0.0)), ((mark_x, -arm), (mark_x, arm))]
    arm = dims.penalty_mark_size / 2
    segments.append(((-arm, 0.0), (arm, 0.0)))  # the centre mark's arm across the halfway line
    return FieldLines(np.asarray(segments, float), dims.center_circle_diameter / 2, dims.line_width)


def distance_to_lines(lines: FieldLines, points: np.ndarray) -> np.ndarray:
    """Distance [m] of field points (N, 2) to the nearest geometric line (segment or the centre circle)."""
    p = np.asarray(points, float).reshape(-1, 2)
    best = np.abs(np.hypot(p[:, 0], p[:, 1]) - lines.circle_radius)
    for start, end in lines.segments:
        half = (end - start) / 2
        half_length = float(np.hypot(*half))
        direction = half / half_length
        rel_x, rel_y = p[:, 0] - (start[0] + half[0]), p[:, 1] - (start[1] + half[1])
        along = np.abs(rel_x * direction[0] + rel_y * direction[1]) - half_length
        across = rel_y * direction[0] - rel_x * direction[1]
        np.minimum(best, np.hypot(np.maximum(along, 0.0), across), out=best)
    return best


def nearest_line(lines: FieldLines, points: np.ndarray) -> np.ndarray:
    """(N,) index of the nearest line of each field point (N, 2): a segment's row in `lines.segments`, or
    `len(lines.segments)` for the centre circle."""
    p = np.asarray(points, float).reshape(-1, 2)
    a, b = lines.segments[:, 0], lines.segments[:, 1]
    ab = b - a
    t = np.clip(np.einsum("nsk,sk->ns", p[:, None, :] - a[None], ab) / np.einsum("sk,sk->s", ab, ab), 0.0, 1.0)
    distances = np.linalg.norm(p[:, None, :] - (a[None] + t[..., None] * ab[None]), axis=-1)
    circle = np.abs(np.linalg.norm(p, axis=1) - lines.circle_radius)
    return np.where(circle < distances.min(axis=1), len(ab), distances.argmin(axis=1))


def nearest_line_normal(lines: FieldLines, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For field points (N, 2): the signed offset [m] from the nearest line (`nearest_line`), that line's unit normal
    (N, 2) and its index (N,), as `line_offset_normal` gives them."""
    index = nearest_line(lines, points)
    offset, normal = line_offset_normal(lines, points, index)
    return offset, normal, index


def line_offset_normal(lines: FieldLines, points: np.ndarray, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For field points (N, 2) and a line of each (N,: a row of `lines.segments`, or `len(lines.segments)` for the
    centre circle): the signed offset [m] from that line and its unit normal (N, 2), so that
    offset = normal . (point - a point of the line): a straight line's fixed normal (its direction turned left),
    the circle's outward radial. The offset is smooth across the line (a residual without a kink at zero); beyond a
    segment's end it is the offset from the segment's extension."""
    p = np.asarray(points, float).reshape(-1, 2)
    a, ab = lines.segments[:, 0], lines.segments[:, 1] - lines.segments[:, 0]
    use_circle = index == len(ab)
    segment = np.where(use_circle, 0, index)
    normal = _segment_normals(ab)[segment]
    offset = np.einsum("nk,nk->n", normal, p - a[segment])
    radius = np.linalg.norm(p, axis=1)
    radial = p / np.maximum(radius, 1e-12)[:, None]
    normal = np.where(use_circle[:, None], radial, normal)
    return np.where(use_circle, radius - lines.circle_radius, offset), normal


def _segment_normals(ab: np.ndarray) -> np.ndarray:
    """Unit normals (S, 2) of segments with directions ab (S, 2)."""
    n = np.column_stack([-ab[:, 1], ab[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def mirrored_pose(x: float, y: float, yaw: float) -> tuple[float, float, float]:
    """The pose that sees the same markings through the field's point symmetry."""
    return -x, -y, math.remainder(yaw + math.pi, 2 * math.pi)
