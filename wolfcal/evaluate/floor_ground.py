"""The measured ground error: held-out views of the floor tags, without truth.

Each view (one floor tag in one sample) gives the rays through its four corner pixels, in the model's floor frame
(`robot.floor.camera_in_floor`, at the sample's joint readings). The real floor is the model's floor tilted and lifted:
T_model_real = Trans(0, 0, dz) @ Rx(rx) @ Ry(ry) about the model floor's origin (midway between the soles). The
three plane unknowns and each tag's place (x, y, yaw) are fitted by least squares so that the rays meet the real
floor (at the tag's thickness) in the tag's printed corners: a model whose floor is tilted against the camera
stretches far tags and bends their rows, which the printed size and the views from several head angles reveal.
The ground error at distance D (1, 2, 4.5, 9 m) is then the ground error of `evaluate.ground` against that real
floor: the ball at D on the real floor, the ray from the standing camera (head aimed at it) through it, met with
the model's floor; the worst of the bearings -30, 0, +30 deg [m], with its 1-sigma uncertainty from the plane
unknowns' covariance (residual scatter). Distances beyond the views' are extrapolated by the plane (said in the
report). A turn or shift of the floor within its plane is not seen (the tags' places are unknown), nor errors that
change with the head angle (the plane is one for all samples). Each joint reading between the soles and the camera
is rounded to an encoder tick: that rounding is an unknown too (prior `priors.encoder_noise`), one per joint and
tick, so views of samples that read a joint at the same tick share it (the standing legs while the head looks
around: their rounding moves the floor as the plane does, no view in that stance tells them apart, so it stays in
the 1 sigma as its own part; held-out samples in several stances, none of the fit's, average it:
`floor.check_stances`). A tag lies in one place per capture file (a check taken three times with the tags moved
between: each place has its own corner bias, which the tag jackknife sees). Views far off (`outliers.FIT_VIEW_PX`)
are left out, and so are single corners far off (`outliers.FLOOR_CORNER_PX`: on a small, strongly foreshortened far
tag the detector's corner slides along an edge by pixels while the view's other corners fit)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from functools import partial

import numpy as np
from scipy.optimize import least_squares

from wolfcal.camera.model import CameraModel
from wolfcal.evaluate.ground import BEARINGS_RAD, DISTANCES_M
from wolfcal.fit.blocks import held_joint_groups
from wolfcal.fit.problem import MAD_TO_SIGMA
from wolfcal.geometry import exp_so3, invert_transform, tag_corners
from wolfcal.observations import Observations
from wolfcal.outliers import FIT_VIEW_PX, FLOOR_CORNER_PX
from wolfcal.projection import BEHIND_CAMERA_PX
from wolfcal.robot.aim import aim_head, ball_position
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor, check_size
from wolfcal.robot.robot import Robot
from wolfcal.vision.corner_bias import apparent_edges, inset_moves, small_view_weight

# corners far off are left out, then the rest solved again, at most this many times (`outliers.FLOOR_CORNER_PX`)
CORNER_ROUNDS = 4
MIN_VIEWS = 6  # fewer floor-tag views than this measure no ground error
# the sample jackknife leaves out one group of samples at a time, at most this many groups (one solve each): the
# grouped jackknife's variance is as honest as delete-one's, for a solve per group rather than per sample
JACKKNIFE_GROUPS = 12
# The corner inset differs from tag to tag (the bits next to the border; 0-0.35 px at 30-50 px apparent edge in
# rendered views): the fit's mean inset is taken as a prior of this relative 1-sigma, at least MIN_INSET_STD_PX
INSET_SPREAD = 0.5
MIN_INSET_STD_PX = 0.05


@dataclass
class FloorViews:
    """Held-out views (one floor tag in one sample, all 4 corners) under one model."""

    tags: np.ndarray  # (V,) tag ids
    placements: np.ndarray  # (V,) int: where the tag lay (one place per tag and capture file: tags moved between)
    samples: np.ndarray  # (V,) sample index
    T_floor_camera: np.ndarray  # (V, 4, 4) the model's camera in the model's floor, at the sample's readings
    uv: np.ndarray  # (V, 4, 2) detected corners [px]
    inward: np.ndarray  # (V, 4, 2) `corner_bias.inset_moves` [px/px]
    weight: np.ndarray  # (V,) `corner_bias.small_view_weight`
    twists: np.ndarray  # (V, K, 6) the camera's motion per radian of each chain joint's reading (v, w), camera frame
    readings: np.ndarray  # (V, K) int: which reading error (`_reading_errors`) each chain joint of the view has
    counted: np.ndarray  # (V, 4) bool: the corners the fit counts (not left out as far off, FLOOR_CORNER_PX)


def floor_views(robot: Robot, obs: Observations, model: Corrections) -> FloorViews:
    """The views with all 4 corners; a tag lies in one place per capture file (`obs.sources`)."""
    order = np.lexsort((obs.corner_index, obs.tag_ids, obs.sample_index))
    s, t, uv = obs.sample_index[order], obs.tag_ids[order], obs.uv[order]
    key = s.astype(np.int64) * 1_000_000 + t
    _, start, count = np.unique(key, return_index=True, return_counts=True)
    start = start[count == 4]
    ring = uv[start[:, None] + np.arange(4)]
    T_floor_camera, _ = camera_in_floor(robot, obs.q_measured, model)
    inward = inset_moves(ring)
    twists, readings = _reading_errors(robot, obs.q_measured, model, s[start])
    _, source = np.unique(np.asarray(obs.sources, dtype=object).astype(str), return_inverse=True)
    _, placements = np.unique(np.stack([source.ravel()[s[start]], t[start]], axis=1), axis=0, return_inverse=True)
    return FloorViews(t[start], placements.ravel(), s[start], T_floor_camera[s[start]], ring, inward,
                      small_view_weight(apparent_edges(ring)), twists, readings,
                      np.ones((len(start), 4), dtype=bool))  # fmt: skip


def _reading_errors(robot: Robot, q: np.ndarray, model: Corrections, sample_of_view: np.ndarray,
                    step: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Each view's camera motion per radian of the readings of the joints between the soles and the camera
    (V, K, 6) [m/rad, rad/rad], camera frame, and which reading error each has (V, K) int: the views of samples that
    read a joint at the same encoder tick share that reading's rounding (`fit.blocks.held_joint_groups`: the
    standing legs while the head looks around), numbered 0..G-1 over all joints."""
    columns = [robot.model.column(j) for j in robot.camera_and_leg_joints()]
    T_floor_camera, _ = camera_in_floor(robot, q, model)
    twists = np.zeros((len(q), len(columns), 6))
    for k, column in enumerate(columns):
        plus, minus = q.copy(), q.copy()
        plus[:, column] += step
        minus[:, column] -= step
        dT = (camera_in_floor(robot, plus, model)[0] - camera_in_floor(robot, minus, model)[0]) / (2 * step)
        body = np.swapaxes(T_floor_camera[:, :3, :3], 1, 2) @ dT[:, :3, :]  # R^T dR | R^T dt
        twists[:, k, :3] = body[:, :, 3]
        twists[:, k, 3:] = np.stack([body[:, 2, 1], body[:, 0, 2], body[:, 1, 0]], axis=1)
    groups = held_joint_groups(q, sample_of_view)[:, columns]  # (V, K) labels per joint
    _, readings = np.unique(np.stack([np.broadcast_to(np.arange(len(columns)), groups.shape), groups], axis=-1)
                            .reshape(-1, 2), axis=0, return_inverse=True)  # fmt: skip
    return twists[sample_of_view], readings.reshape(groups.shape)


def _plane(values: np.ndarray) -> np.ndarray:
    """T_model_real (4, 4) of plane unknowns (rx, ry, dz) [rad, m]."""
    T = np.eye(4)
    T[:3, :3] = exp_so3(np.array([values[0], values[1], 0.0]))
    T[2, 3] = values[2]
    return T


def _real_camera(unknowns: np.ndarray, T_floor_camera: np.ndarray) -> np.ndarray:
    """T_real_camera (..., 4, 4): the model's camera turned by the camera rotation unknowns[3:6], in the real floor
    (plane unknowns[:3])."""
    C = np.eye(4)
    C[:3, :3] = exp_so3(unknowns[3:6])
    return invert_transform(_plane(unknowns[:3])) @ T_floor_camera @ C


def _meet(T_real_model: np.ndarray, origins: np.ndarray, rays: np.ndarray, height: np.ndarray) -> np.ndarray:
    """(..., 2) where rays (..., 3) from origins (..., 3), model floor frame, meet the real floor's plane z = height
    (...,), in real floor coordinates [m]; NaN above the horizon."""
    o = origins @ T_real_model[:3, :3].T + T_real_model[:3, 3]
    r = rays @ T_real_model[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (height - o[..., 2]) / r[..., 2]
    s = np.where(s > 0, s, np.nan)
    return o[..., :2] + s[..., None] * r[..., :2]


class _FloorFit:
    """The least-squares fit of the plane, the camera turn, the tags' places and the joint readings' rounding to the
    views' corner pixels. Unknowns: plane (3), turn (3), inset (1), places (3 per tag place), then the readings' errors
    (`FloorViews.readings`, each with a prior of the config's `priors.encoder_noise`) [rad, m, px]."""

    def __init__(self, robot: Robot, views: FloorViews, camera: CameraModel, inset: tuple[float, float]) -> None:
        self.views, self.camera, self.inset = views, camera, inset
        self.scale = 1.0  # [px] of the corner residuals: the priors' residuals count in it
        self.encoder_noise = robot.config.priors.encoder_noise
        floor = robot.config.floor_config()
        self.placements, first, self.tag_of_view = np.unique(views.placements, return_index=True,
                                                             return_inverse=True)  # fmt: skip
        self.ids = views.tags[first]  # (T,) the tag id of each place
        self.tag_of_view = self.tag_of_view.ravel()
        self.printed = np.stack([tag_corners(floor.tag(int(i)).size) for i in self.ids])  # (T, 4, 3)
        self.printed[..., 2] = np.array([floor.tag(int(i)).thickness for i in self.ids])[:, None]
        self.n_readings = int(views.readings.max()) + 1 if views.readings.size else 0

    @property
    def first_reading(self) -> int:
        """Index of the first reading error in the unknowns."""
        return 7 + 3 * len(self.ids)

    def start(self) -> np.ndarray:
        """Zero plane, turn and reading errors; tag places under the model's floor: centre and yaw of each tag's
        first view."""
        v = self.views
        rays = np.einsum("vij,vcj->vci", v.T_floor_camera[:, :3, :3], self.camera.unproject(v.uv))
        height = self.printed[self.tag_of_view, :, 2]
        seen = _meet(np.eye(4), np.repeat(v.T_floor_camera[:, None, :3, 3], 4, axis=1), rays, height)
        places = np.zeros((len(self.ids), 3))
        for k in range(len(self.ids)):
            first = seen[self.tag_of_view == k][0]
            edge = first[1] - first[0]
            places[k] = [*first.mean(axis=0), np.arctan2(edge[1], edge[0])]
        return np.concatenate([np.zeros(6), [self.inset[0]], np.nan_to_num(places).ravel(), np.zeros(self.n_readings)])

    def residuals(self, x: np.ndarray, keep: np.ndarray) -> np.ndarray:
        """Weighted residuals [px] of the counted corners (`FloorViews.counted`) of the views `keep` (V,) bool,
        then the priors' (inset, readings)."""
        v = self.views
        off = self.offsets(x, keep) * v.weight[keep, None, None]
        prior = self.scale * np.append((x[6] - self.inset[0]) / self.inset[1],
                                       x[self.first_reading:] / self.encoder_noise)  # fmt: skip
        return np.append(off[v.counted[keep]].ravel(), prior)

    def n_pixels(self, keep: np.ndarray) -> int:
        """How many corner residuals `residuals(x, keep)` has before the priors'."""
        return 2 * int(self.views.counted[keep].sum())

    def offsets(self, x: np.ndarray, keep: np.ndarray) -> np.ndarray:
        """(V_keep, 4, 2) where the unknowns x put the corners of the views `keep` less where they were seen [px]
        (BEHIND_CAMERA_PX for a corner behind the camera)."""
        v = self.views
        place = x[7 : self.first_reading].reshape(-1, 3)[self.tag_of_view[keep]]
        c, s = np.cos(place[:, 2:3]), np.sin(place[:, 2:3])
        p = self.printed[self.tag_of_view[keep]]
        p_real = np.stack([place[:, :1] + c * p[..., 0] - s * p[..., 1], place[:, 1:2] + s * p[..., 0] + c * p[..., 1],
                           p[..., 2]], axis=-1)  # fmt: skip
        errors = x[self.first_reading :]
        moved = np.einsum("vkd,vk->vd", v.twists[keep], errors[v.readings[keep]])  # (V, 6) camera frame
        T_camera_moved = np.tile(np.eye(4), (len(moved), 1, 1))
        T_camera_moved[:, :3, :3], T_camera_moved[:, :3, 3] = exp_so3(moved[:, 3:]), moved[:, :3]
        T_camera_real = invert_transform(_real_camera(x, v.T_floor_camera[keep] @ T_camera_moved))
        p_camera = np.einsum("vij,vcj->vci", T_camera_real[:, :3, :3], p_real) + T_camera_real[:, None, :3, 3]
        return np.nan_to_num(self.camera.project(p_camera) + x[6] * v.inward[keep] - v.uv[keep], nan=BEHIND_CAMERA_PX)

    def carried(self, other: _FloorFit, x: np.ndarray) -> np.ndarray:
        """Unknowns for this fit (on a subset of `other`'s views) from `other`'s unknowns x: plane, turn, inset, the
        places this fit has and the readings' errors."""
        out = self.start()
        out[:7] = x[:7]
        index = np.searchsorted(other.placements, self.placements)
        out[7 : self.first_reading] = x[7 : other.first_reading].reshape(-1, 3)[index].ravel()
        out[self.first_reading :] = x[other.first_reading : other.first_reading + self.n_readings]
        return out

    def robust(self, x: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, float]:
        """The unknowns solved robustly from x, at the scale of the counted residuals (dof-corrected median), twice,
        and that scale [px]."""
        n_pixels = self.n_pixels(keep)
        for _ in range(2):
            scale = MAD_TO_SIGMA * float(np.median(np.abs(self.residuals(x, keep)[:n_pixels])))
            scale *= float(np.sqrt(n_pixels / max(n_pixels - len(x), 1)))
            x = self.solve(x, keep, scale)
        return x, scale

    def solve(self, x0: np.ndarray, keep: np.ndarray, scale: float | None = None) -> np.ndarray:
        """The unknowns fitted to the views `keep`; with a residual `scale` [px] robustly (Huber at 2 scale). Unknowns
        no kept corner depends on (a left-out tag's place, a reading seen only in left-out views) keep their x0:
        with only a prior, which the Huber loss takes in too, nothing curbs their steps (a reading error reached
        4e9 in a jackknife solve, and least_squares' SVD failed)."""
        if scale is not None:
            self.scale = scale
        loss = {} if scale is None else {"loss": "huber", "f_scale": 2.0 * scale}
        pattern = self.sparsity(keep)
        free = pattern[: self.n_pixels(keep)].any(axis=0)
        columns = _column_groups(pattern[:, free])

        def residuals(x_free: np.ndarray) -> np.ndarray:
            x = x0.copy()
            x[free] = x_free
            return self.residuals(x, keep)

        x = x0.copy()
        x[free] = least_squares(residuals, x0[free], lambda u: _grouped_jacobian(residuals, u, columns),
                                x_scale="jac", **loss).x  # fmt: skip
        return x

    def sparsity(self, keep: np.ndarray) -> np.ndarray:
        """(R, N) bool: which unknowns each residual of `residuals(x, keep)` depends on: a view's 8 on the plane,
        turn and inset, its tag's place and its readings' errors; each prior on its own unknown."""
        v, n = self.views, self.first_reading + self.n_readings
        view_columns = np.concatenate([np.arange(7)[None].repeat(keep.sum(), 0),
                                       7 + 3 * self.tag_of_view[keep, None] + np.arange(3),
                                       self.first_reading + v.readings[keep]], axis=1)  # fmt: skip
        by_view = np.zeros((len(view_columns), n), dtype=bool)
        by_view[np.arange(len(view_columns))[:, None], view_columns] = True
        priors = np.zeros((1 + self.n_readings, n), dtype=bool)
        priors[np.arange(1 + self.n_readings), np.r_[6, np.arange(self.first_reading, n)]] = True
        by_corner = np.repeat(by_view, 4, axis=0)[v.counted[keep].ravel()]
        return np.concatenate([np.repeat(by_corner, 2, axis=0), priors])


def real_floor(robot: Robot, obs: Observations, model: Corrections, corner_inset: tuple[float, float] = (0.0, 0.0),
               camera: CameraModel | None = None) -> dict | None:  # fmt: skip
    """The plane, camera-turn and inset unknowns (7,) [rad, rad, m, rad, rad, rad, px] with their spread: the formal
    covariance (7, 7) with the shared readings' rounding taken as known, the part that rounding adds (7, 7), the
    jackknife replicates deleting one group of samples (at most JACKKNIFE_GROUPS groups) and one tag (n, 7; None
    with fewer than 3 samples or tags); the
    views' count (less `outlier_views`: off by far more than the others, `outliers.FIT_VIEW_PX`), the corners left
    out in them (`outlier_corners`, `outliers.FLOOR_CORNER_PX`, up to CORNER_ROUNDS times), the residual scale
    and the corners' rms [px] and the fitted inset [px]. None with fewer than MIN_VIEWS views of tags
    seen twice. `corner_inset`: the fit's `floor.corner_inset` and its 1-sigma [px]."""
    views = _measurable(floor_views(robot, obs, model))
    if views is None:
        return None
    inset = (corner_inset[0], max(corner_inset[1], INSET_SPREAD * abs(corner_inset[0]), MIN_INSET_STD_PX))
    fit = _FloorFit(robot, views, camera or obs.camera, inset)
    every = np.ones(len(views.tags), dtype=bool)
    fit.scale = robot.config.priors.pixel_noise
    x, scale = fit.robust(fit.solve(fit.start(), every), every)
    # views far off (a corner caught on something else) left out as the fit leaves them out; the rest solved again
    off = fit.offsets(x, every) * views.weight[:, None, None]
    outliers = FIT_VIEW_PX.flags(np.sqrt(np.mean(off.reshape(-1, 8) ** 2, axis=1)))
    if outliers.any():
        views = _measurable(_subset(views, ~outliers))
        if views is None:
            return None
        first, fit = fit, _FloorFit(robot, views, camera or obs.camera, inset)
        every = np.ones(len(views.tags), dtype=bool)
        x, scale = fit.robust(fit.carried(first, x), every)
    # corners far off (on small, strongly foreshortened far tags the detector's corner slides along an edge by 1-5
    # px, on about one corner in ten; each pulls the plane its way, so the figure read high by up to 1.7 cm at
    # 4.5 m): left out, the rest solved again, until none is left
    left_out = 0
    for _ in range(CORNER_ROUNDS):
        bad = views.counted & (np.linalg.norm(fit.offsets(x, every), axis=2) > FLOOR_CORNER_PX.limit(np.array(scale)))
        if not bad.any():
            break
        views.counted[bad] = False
        left_out += int(bad.sum())
        x, scale = fit.robust(x, every)
    n_pixels = fit.n_pixels(every)
    r = fit.residuals(x, every)[:n_pixels]
    J = _jacobian(lambda u: fit.residuals(u, every), x)
    noise = max(float(r @ r) / max(n_pixels - len(x), 1), scale**2)  # [px^2] of the corners (the priors: scale^2)
    information = J[:n_pixels].T @ J[:n_pixels] / noise + J[n_pixels:].T @ J[n_pixels:] / scale**2
    covariance = np.linalg.pinv(information)
    shared = np.flatnonzero(_shared_readings(views, fit.n_readings))
    kept = np.setdiff1d(np.arange(len(x)), fit.first_reading + shared)
    held = np.linalg.pinv(information[np.ix_(kept, kept)])[:7, :7]  # as if the shared readings' rounding were known
    samples, tags = np.unique(views.samples), np.unique(views.tags)
    # delete-a-group: the samples dealt into at most JACKKNIFE_GROUPS groups in turn (each group spans the stances)
    group = np.searchsorted(samples, views.samples) % min(len(samples), JACKKNIFE_GROUPS)
    by_sample = (np.stack([fit.solve(x, group != g, scale)[:7] for g in np.unique(group)]) if len(samples) > 2
                 else None)  # fmt: skip
    by_tag = np.stack([fit.solve(x, views.tags != t, scale)[:7] for t in tags]) if len(tags) > 2 else None
    return {"unknowns": x[:7], "covariance": held, "rounding_covariance": covariance[:7, :7] - held,
            "jackknife_samples": by_sample, "jackknife_tags": by_tag, "views": len(views.tags),
            "outlier_views": int(outliers.sum()), "outlier_corners": left_out, "scale_px": scale,
            "noise_px": float(np.sqrt(noise)),
            "inset_px": float(x[6])}  # fmt: skip


def _shared_readings(views: FloorViews, n: int) -> np.ndarray:
    """(n,) bool: which of the n reading errors (`_FloorFit.n_readings`) views of more than one sample share (a
    joint held still)."""
    first, last = np.full(n, np.iinfo(np.int64).max), np.full(n, -1)
    samples = np.broadcast_to(views.samples[:, None], views.readings.shape)
    np.minimum.at(first, views.readings.ravel(), samples.ravel())
    np.maximum.at(last, views.readings.ravel(), samples.ravel())
    return last > first


def _seen_twice(placements: np.ndarray) -> np.ndarray:
    """(V,) bool: the views of tag places seen in at least two views (a place is unknown: one view is no data)."""
    ids, inverse, counts = np.unique(placements, return_inverse=True, return_counts=True)
    return (counts >= 2)[inverse.ravel()]


def _measurable(views: FloorViews) -> FloorViews | None:
    """The views of tag places seen at least twice (`_seen_twice`); None when fewer than MIN_VIEWS are left."""
    views = _subset(views, _seen_twice(views.placements))
    return views if len(views.tags) >= MIN_VIEWS else None


def _subset(views: FloorViews, keep: np.ndarray) -> FloorViews:
    return FloorViews(*(getattr(views, f.name)[keep] for f in fields(FloorViews)))


def _column_groups(pattern: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Columns of a (R, N) bool sparsity pattern in groups that share no row (greedy), so one residual evaluation
    differences a whole group; per group its columns and the pattern's rows of them (R, len(group)) bool."""
    groups: list[list[int]] = []
    used: list[np.ndarray] = []
    for j in range(pattern.shape[1]):
        for group, rows in zip(groups, used):
            if not np.any(rows & pattern[:, j]):
                group.append(j)
                rows |= pattern[:, j]
                break
        else:
            groups.append([j])
            used.append(pattern[:, j].copy())
    return [(np.array(g), pattern[:, g]) for g in groups]


def _grouped_jacobian(f: Callable[..., np.ndarray], x: np.ndarray, groups: list[tuple[np.ndarray, np.ndarray]],
                      *args: object) -> np.ndarray:  # fmt: skip
    """Forward-difference Jacobian (R, N) of f(x, *args) with the columns of each group (`_column_groups`) stepped
    at once: step sqrt(eps) relative, at least sqrt(eps)."""
    f0 = f(x, *args)
    J = np.zeros((len(f0), len(x)))
    for columns, rows in groups:
        step = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x[columns]))
        moved = x.copy()
        moved[columns] += step
        step = moved[columns] - x[columns]  # the step as represented
        change = f(moved, *args) - f0
        J[:, columns] = np.where(rows, change[:, None], 0.0) / step
    return J


def _jacobian(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, step: float = 1e-7) -> np.ndarray:
    """Central-difference Jacobian of f at x."""
    columns = []
    for i in range(len(x)):
        dx = np.zeros_like(x)
        dx[i] = step * max(1.0, abs(x[i]))
        columns.append((f(x + dx) - f(x - dx)) / (2 * dx[i]))
    return np.stack(columns, axis=1)


def _aimed(robot: Robot, model: Corrections, distance: float, bearing: float) -> tuple[np.ndarray, np.ndarray]:
    """The model's T_floor_camera and T_floor_base (1, 4, 4) with the head aimed at the ball."""
    q = aim_head(robot, model, ball_position(robot, model, distance, bearing))
    return camera_in_floor(robot, q[None], model)


def _landing_offset(aimed: tuple[np.ndarray, np.ndarray], distance: float, bearing: float,
                    unknowns: np.ndarray) -> np.ndarray:  # fmt: skip
    """(2,) where the model (camera aimed: `_aimed`) puts a ball `distance` m away at `bearing` less where it lies
    on the real floor (real floor and camera: `unknowns`) [m]; NaN above the model's horizon."""
    T_model_real = _plane(unknowns[:3])
    T_floor_camera, T_floor_base = aimed
    below = (invert_transform(T_model_real) @ T_floor_base[0, :, 3])[:2]  # point below base, real floor coordinates
    ball = np.array([*(below + distance * np.array([np.cos(bearing), np.sin(bearing)])), 0.0, 1.0])
    ray_camera = (invert_transform(_real_camera(unknowns, T_floor_camera[0])) @ ball)[:3]
    landed = _meet(np.eye(4), T_floor_camera[0, :3, 3], T_floor_camera[0, :3, :3] @ ray_camera, np.array(0.0))
    return landed - ball[:2]


def measured_ground_errors(
    robot: Robot,
    obs: Observations,
    models: dict[str, Corrections],
    distances: tuple[float, ...] = DISTANCES_M,
    corner_inset: tuple[float, float] = (0.0, 0.0),
) -> dict | None:
    """Per model: per distance the measured ground error [m] (worst bearing; None: the ball lies above the model's
    horizon) and its 1-sigma [m] (`_spread`, with its parts); the views' count, the corners left out as far off
    (`real_floor`'s `outlier_corners`), the capture's size (`capture_size`) and the check's size on this robot
    (`robot.floor.check_size`). None when the floor views cannot measure it (fewer than MIN_VIEWS views of tags seen
    twice). `corner_inset`: the fit's `floor.corner_inset` and
    its 1-sigma [px] (result.yaml; (0, 0) without one: then the inset's prior is MIN_INSET_STD_PX wide)."""
    out: dict = {"models": {}}
    for name, model in models.items():
        floor = real_floor(robot, obs, model, corner_inset)
        if floor is None:
            return None
        rows = []
        for distance in distances:
            offsets = [partial(_landing_offset, _aimed(robot, model, distance, b), distance, b) for b in BEARINGS_RAD]
            errors = [float(np.linalg.norm(f(floor["unknowns"]))) for f in offsets]
            if not np.all(np.isfinite(errors)):  # the ball lies above the model's horizon
                rows.append({"distance_m": distance, "error_m": None, "std_m": None})
                continue
            worst = int(np.argmax(errors))
            rows.append({"distance_m": distance, "error_m": errors[worst], **_spread(offsets[worst], floor)})
        out["models"][name] = {"rows": rows, "unknowns": [float(v) for v in floor["unknowns"]]}
        out["views"], out["outlier_corners"] = floor["views"], floor["outlier_corners"]
    out["capture"] = capture_size(robot, obs)
    out["check"] = check_size(robot)
    return out


def capture_size(robot: Robot, obs: Observations) -> dict[str, int]:
    """What averages the held-out floor capture's errors: its samples with floor-tag views, the stances they stand
    in (distinct readings of the joints between the base and the soles: each rounds the standing legs anew) and
    the tag layouts (capture files: the tags may lie elsewhere in each, and each place has its own corner bias)."""
    seen = np.unique(obs.sample_index)
    legs = np.array([robot.model.column(j) for j in robot.actuated_joints_to(list(robot.config.floor_config().soles))])
    return {
        "samples": len(seen),
        "stances": len(np.unique(obs.q_measured[np.ix_(seen, legs)], axis=0)),
        "layouts": len({obs.sources[i] for i in seen}),
    }


def _spread(offset: Callable[[np.ndarray], np.ndarray], floor: dict) -> dict:
    """1-sigma [m] of a ground error: sqrt of the trace of its offset's (2,) covariance, so that it bounds how far
    the error's length can be off even when the offset is near zero. Covariance: the larger of the formal one
    (residual scale, at least the config's `priors.pixel_noise`) and the sample-group jackknife's (errors shared
    within a sample: joint readings), plus the delete-one-tag jackknife's (errors shared by a tag's views: its
    corner bias); each part's sqrt-trace alongside [m]."""
    x = floor["unknowns"]
    G = _jacobian(offset, x, 1e-6)
    formal = G @ floor["covariance"] @ G.T
    by_sample, by_tag = (_jackknife_covariance(offset, floor[k]) for k in ("jackknife_samples", "jackknife_tags"))
    rounding = G @ floor["rounding_covariance"] @ G.T
    total = (formal if np.trace(formal) > np.trace(by_sample) else by_sample) + by_tag + rounding
    parts = {
        "std_m": total,
        "formal_std_m": formal,
        "sample_std_m": by_sample,
        "tag_std_m": by_tag,
        "rounding_std_m": rounding,
    }
    return {k: float(np.sqrt(np.trace(c))) for k, c in parts.items()}


def _jackknife_covariance(offset: Callable[[np.ndarray], np.ndarray], replicates: np.ndarray | None) -> np.ndarray:
    """(2, 2) jackknife covariance [m^2] of a landing offset over `replicates` (n, 7) of the unknowns, each with one
    unit left out (a group of samples or a tag; zero without replicates; inf when a replicate puts the ball above
    the horizon)."""
    if replicates is None:
        return np.zeros((2, 2))
    values = np.array([offset(u) for u in replicates])
    if not np.all(np.isfinite(values)):
        return np.full((2, 2), np.inf)
    d = values - values.mean(axis=0)
    return (len(values) - 1) / len(values) * d.T @ d
