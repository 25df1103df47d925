"""Field captures -> line points: each capture file is one placement of the robot on the field.

Each sample's head image (colour: the turf is told from the lines by its green) is searched for line points
(`wolfcal.field.detect`) no wider than a line would appear under the nominal model at the configured place
(`field.robot_at`); at most `MAX_POINTS_PER_VIEW` points of a view are kept, spread over it. Then the robot's place
is searched around the configured one (`wolfcal.field.place`): the fit starts there, with the camera at the
search's pitch.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.field.detect import detect_line_points
from wolfcal.field.ground import camera_on_field, expected_line_width
from wolfcal.field.model import field_lines, mirrored_pose
from wolfcal.field.observations import FieldObservations, spread
from wolfcal.field.place import DistanceMap, PlaceSearch, far_from_configured, place_offset, search_place
from wolfcal.io.reader import read_capture
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor
from wolfcal.robot.robot import Robot
from wolfcal.vision.observe import detect_observations

TAG_PROBE_SAMPLES = 3  # head images of a capture searched for tags to tell a tag capture from a field capture
MIN_POINTS = 200  # fewer line points in a placement's views cannot place the robot and turn the camera
MIRROR_SCORE_RATIO = 0.5  # lines fitting the robot turned round this much better name the field's symmetry


def field_captures(robot: Robot, captures: list[Path], system: str | None) -> list[Path]:
    """The captures a fit reads as field views: with `--system field` all of them; with every system (`--system
    all` or none) and a `field:` in the robot config, those whose first TAG_PROBE_SAMPLES head images show no tag
    of the config (tag captures, floor captures and field captures may then be fitted together)."""
    if system == "field":
        return list(captures)
    if system not in (None, "all") or robot.config.playing_field is None:
        return []
    return [path for path in captures if not _shows_tags(robot, path)]


def _shows_tags(robot: Robot, path: Path) -> bool:
    """Whether the head images of the capture's first samples show a tag of the robot config (a capture without
    head images is no field capture)."""
    samples = read_capture(path, robot.config).samples_of(HEAD_CAMERA)[:TAG_PROBE_SAMPLES]
    if not samples:
        return True
    try:
        observations, _ = detect_observations(samples, robot, workers=1, cameras=[HEAD_CAMERA])
    except WolfcalError:  # no configured tag in any of them
        return False
    return bool(observations)


def field_observations(robot: Robot, captures: list[Path], say: Callable[[str], None],
                       check: bool = False) -> FieldObservations:  # fmt: skip
    """Line points of every field capture (module docstring); WolfcalError naming the file when a capture holds no
    colour head images or too few line points. `check`: held-out views, taken at `field.check_at` (when set)."""
    config = robot.config.field_config("a field capture needs the field's dimensions and where the robot stands")
    lines = field_lines(config.dimensions)
    distance_map = DistanceMap(lines)
    key = "check_at" if check and config.check_at is not None else "robot_at"
    configured = np.asarray(getattr(config, key), float)
    q_all: list[np.ndarray] = []
    uv_all: list[np.ndarray] = []
    sample_of: list[np.ndarray] = []
    starts: list[np.ndarray] = []
    pitches: list[float] = []
    stamps: list[int] = []
    sources: list[str] = []
    placement: list[int] = []
    camera: CameraModel | None = None
    for k, path in enumerate(captures):
        samples = read_capture(path, robot.config).samples_of(HEAD_CAMERA)
        if not samples:
            raise WolfcalError(f"{path}: no head-camera images; a field capture holds the head camera's views")
        q = np.stack([s.joint_positions(robot.joint_names) for s in samples])
        T_floor_camera = camera_in_floor(robot, q, Corrections())[0]
        first, views = len(stamps), []
        for i, sample in enumerate(samples):
            image, camera = sample.images[HEAD_CAMERA].decode(), sample.images[HEAD_CAMERA].camera
            if image.ndim != 3:
                raise WolfcalError(f"{path}: the head image at t={sample.stamp_ns} ns is grey; field lines are told "
                                   "from the turf by colour: capture field views in colour (bgr8)")  # fmt: skip
            widths = expected_line_width(camera, camera_on_field(T_floor_camera[i], configured),
                                         config.dimensions.line_width)  # fmt: skip
            found = detect_line_points(image, widths).uv
            found = found[spread(found)]
            uv_all.append(found)
            sample_of.append(np.full(len(found), first + i))
            views.append(found)
        points = np.vstack(views)
        say(f"{path}: {len(points)} line points in {len(samples)} views")
        if len(points) < MIN_POINTS:
            raise WolfcalError(f"{path}: only {len(points)} field-line points in {len(samples)} views (at least "
                               f"{MIN_POINTS} needed): aim the head at the field's lines, not at the sky or beyond "
                               "the border")  # fmt: skip
        assert camera is not None
        view_of_point = np.concatenate([np.full(len(v), i) for i, v in enumerate(views)])
        search = search_place(distance_map, robot, q, view_of_point, points, camera, configured)
        turned = search_place(distance_map, robot, q, view_of_point, points, camera,
                              configured + np.array([0.0, 0.0, np.pi]))  # fmt: skip
        _check_half(path, search, turned, configured, f"field.{key}")
        _say_place(path, search, configured, f"field.{key}", say)
        q_all.append(q)
        stamps += [s.stamp_ns for s in samples]
        sources += [str(path)] * len(samples)
        placement += [k] * len(samples)
        starts.append(search.pose)
        pitches.append(search.pitch)
    assert camera is not None
    return FieldObservations(list(robot.joint_names), np.vstack(q_all), np.asarray(stamps, np.int64), sources,
                             np.asarray(placement), np.asarray(starts), camera, np.concatenate(sample_of),
                             np.vstack(uv_all), np.tile(configured, (len(starts), 1)), np.asarray(pitches))  # fmt: skip


def _check_half(path: Path, search: PlaceSearch, turned: PlaceSearch, configured: np.ndarray, key: str) -> None:
    """WolfcalError when the lines fit the robot turned round at its configured place clearly better than as
    configured: through the field's point symmetry that is the robot standing on the other half, facing as
    configured (or turned round on this half); the views alone cannot tell which. `key`: the config key of the
    configured place."""
    if turned.score_m < MIRROR_SCORE_RATIO * search.score_m:
        other = mirrored_pose(*turned.pose)
        raise WolfcalError(
            f"{path}: the lines fit the robot on the other half of the field (x {other[0]:+.2f} m, y {other[1]:+.2f}"
            f" m, yaw {np.rad2deg(other[2]):+.0f} deg) or turned round where {key} puts it (yaw "
            f"{np.rad2deg(turned.pose[2]):+.0f} deg) - the field's point symmetry makes the two look alike - far "
            f"better than at {key} ({configured[0]:+.2f}, {configured[1]:+.2f}, "
            f"{np.rad2deg(configured[2]):+.0f} deg; mean distance from the lines {turned.score_m:.3f} m against "
            f"{search.score_m:.3f} m): set {key} to where the robot stood, on the half it stood on"
        )


def _say_place(path: Path, search: PlaceSearch, configured: np.ndarray, key: str, say: Callable[[str], None]) -> None:
    """The place and camera pitch found, the field's symmetry, and a warning when the place is far from the
    configured one (the config's `key`)."""
    found = search.pose
    mirror = np.round(mirrored_pose(*found), 2)
    say(f"{path}: the robot stands at x {found[0]:+.2f} m, y {found[1]:+.2f} m, yaw {np.rad2deg(found[2]):+.1f} deg "
        f"({key}: {configured[0]:+.2f}, {configured[1]:+.2f}, {np.rad2deg(configured[2]):+.1f} deg), the camera "
        f"pitched about {np.rad2deg(search.pitch):+.0f} deg from the nominal model; the field's point symmetry fits "
        f"the same views at ({mirror[0]:+.2f}, {mirror[1]:+.2f}): the half that {key} names is assumed")  # fmt: skip
    off = place_offset(found, configured)
    if far_from_configured(off):
        say(
            f"warning: {path}: the lines fit best {off[0]:.2f} m and {np.rad2deg(off[1]):.0f} deg from "
            f"{key}; check where the robot stood and correct {key}"
        )
