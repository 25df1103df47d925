"""The accuracy parts, on this checkout only: corner accuracy of the tag detector on rendered views, `wolfcal
intrinsics` against a plain OpenCV calibration, and fits of simulated captures over seeds against the
truth."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from common import CONFIG, median

FAMILY, TAG_SIZE = "tag36h11", 0.08  # [m]


def _camera(binning: int):
    """The bench's 2048x1536 camera with strong barrel distortion, binned by `binning`."""
    from wolfcal.camera.model import CameraModel

    full = CameraModel(
        2048,
        1536,
        np.array([[1336.2, 0, 1015.8], [0, 1334.4, 727.0], [0, 0, 1]]),
        np.array([-0.28595, 0.081479, -0.000093, -0.00032, 0.0]),
    )
    return full if binning == 1 else full.scaled(1 / binning, 1 / binning, 2048 // binning, 1536 // binning)


def _random_view(camera, rng: np.random.Generator, width: float) -> np.ndarray:
    """T_camera_tag: a tag at 0.3-1.2 m facing the camera, tilted up to 50 deg, wholly inside the image."""
    from wolfcal.geometry import exp_so3, make_transform, tag_corners, transform_points

    while True:
        ray = camera.unproject(rng.uniform([0, 0], [camera.width - 1, camera.height - 1]))
        ray /= np.linalg.norm(ray)
        z = -ray
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z]) @ exp_so3(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))
        axis = rng.normal(size=2)
        R = R @ exp_so3(np.array([*axis / np.linalg.norm(axis), 0.0]) * np.deg2rad(rng.uniform(0, 50)))
        T = make_transform(R, ray * rng.uniform(0.3, 1.2) / ray[2])
        if camera.in_image(camera.project(transform_points(T, tag_corners(width))), margin=2).all():
            return T


def detection(views: int, say) -> dict:
    """Corner error |detected - projected truth| [px, per corner] of `detect_tags` (each refinement) on
    `views` rendered views per camera (noise sigma 2 gray levels, 4x4 supersampling): median, 95th percentile,
    max, share of tags found."""
    from wolfcal.geometry import tag_corners, transform_points
    from wolfcal.vision.render import PlanarTarget, render_targets
    from wolfcal.vision.tags import detect_tags, tag_texture, tag_texture_width

    out = {}
    for binning in (1, 4):
        camera, rng = _camera(binning), np.random.default_rng(11)
        rendered = []
        for _ in range(views):
            tag_id = int(rng.integers(0, 30))
            texture = tag_texture(FAMILY, tag_id)
            width = tag_texture_width(FAMILY, TAG_SIZE, texture)
            T = _random_view(camera, rng, width)
            image = render_targets(camera, [PlanarTarget(T, texture, width, width)], noise_sigma=2.0, rng=rng)
            rendered.append((tag_id, image, camera.project(transform_points(T, tag_corners(TAG_SIZE)))))
        for refine in ("edges", "subpix"):
            errors, found = [], 0
            for tag_id, image, truth in rendered:
                detected = detect_tags(image, FAMILY, refine=refine)
                if tag_id in detected:
                    found += 1
                    errors.append(np.linalg.norm(detected[tag_id] - truth, axis=1))
            e = np.concatenate(errors) if errors else np.array([np.nan])
            key = f"{camera.width}x{camera.height} {refine}"
            out[key] = {
                "median_px": float(np.median(e)),
                "p95_px": float(np.percentile(e, 95)),
                "max_px": float(e.max()),
                "found": found / views,
                "views": views,
            }
            say(f"detection {key}: median {out[key]['median_px']:.3f} px, p95 {out[key]['p95_px']:.3f} px")
    return out


def intrinsics(seeds: int, say) -> dict:
    """Per seed, 16 rendered checkerboard views at 640x480 (blur 1.5 px, noise 2 gray levels): `wolfcal
    intrinsics`' calibration (`calibrate_views`) and the plain OpenCV recipe (findChessboardCorners,
    cornerSubPix with an 11x11 window, calibrateCamera): focal error [%], principal point error [px], seconds;
    for wolfcal also how often the reported 1-sigma covers the true error of fx, fy, cx, cy."""
    import cv2

    from wolfcal.intrinsics.calibrate import calibrate_views
    from wolfcal.intrinsics.detect import Detection, detect_board
    from wolfcal.intrinsics.synthetic import example_camera, random_board_poses, render_view
    from wolfcal.vision.board import Board

    board = Board(9, 6, 0.025)
    obj = np.zeros((board.cols * board.rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0 : board.cols, 0 : board.rows].T.reshape(-1, 2) * board.square
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    rows: dict[str, dict[str, list[float]]] = {"wolfcal": {}, "opencv": {}}
    z: list[float] = []
    for seed in range(100, 100 + seeds):
        camera = example_camera(640, 480)
        poses = random_board_poses(camera, board, 16, np.random.default_rng(seed))
        images = [
            render_view(camera, board, T, np.random.default_rng([seed, i]), 2.0, 1.5) for i, T in enumerate(poses)
        ]
        start = time.perf_counter()
        found = [detect_board(image, board, f"view {i}") for i, image in enumerate(images)]
        result = calibrate_views([d for d in found if isinstance(d, Detection)], board, min_views=10)
        ours = (
            result.camera.fx,
            result.camera.fy,
            result.camera.cx,
            result.camera.cy,
            time.perf_counter() - start,
        )
        z += [abs(getattr(result.camera, k) - getattr(camera, k)) / result.std[k] for k in ("fx", "fy", "cx", "cy")]
        start = time.perf_counter()
        points = []
        for image in images:
            ok, corners = cv2.findChessboardCorners(image, (board.cols, board.rows), None)
            if ok:
                points.append(cv2.cornerSubPix(image, corners, (11, 11), (-1, -1), criteria))
        _, K, _, _, _ = cv2.calibrateCamera([obj] * len(points), points, (640, 480), None, None)
        theirs = (K[0, 0], K[1, 1], K[0, 2], K[1, 2], time.perf_counter() - start)
        for name, (fx, fy, cx, cy, seconds) in (("wolfcal", ours), ("opencv", theirs)):
            figures = rows[name]
            focal = 100 * max(abs(fx / camera.fx - 1), abs(fy / camera.fy - 1))
            figures.setdefault("focal_error_pct", []).append(focal)
            figures.setdefault("principal_error_px", []).append(max(abs(cx - camera.cx), abs(cy - camera.cy)))
            figures.setdefault("seconds", []).append(seconds)
    out: dict = {
        name: {key: {"median": median(v), "max": max(v)} for key, v in figures.items()}
        for name, figures in rows.items()
    }
    out["wolfcal"]["within_1_sigma"] = float(np.mean(np.array(z) < 1))
    out["wolfcal"]["within_2_sigma"] = float(np.mean(np.array(z) < 2))
    out["seeds"] = seeds
    say(
        f"intrinsics: focal error wolfcal {out['wolfcal']['focal_error_pct']['max']:.3f} %, opencv "
        f"{out['opencv']['focal_error_pct']['max']:.3f} % (worst of {seeds} seeds)"
    )
    return out


SCENARIOS = ("camera", "leg", "outliers")


def seeds(count: int, binning: int, say) -> dict:
    """Simulate -> detect -> fit -> compare with the truth, per scenario and seed (24 samples each): `camera`
    (--free camera), `leg` (0.025 rad rms offsets on every joint, --free leg --side both), `outliers` (10 % of
    the samples blurred or with stale joint readings, --free camera). Camera pose error over the head's range
    [deg, mm], the largest |estimate - truth| / reported std, held-out sole error for `leg` [mm]."""
    from wolfcal.evaluate.accuracy import camera_pose_errors, link_position_errors
    from wolfcal.fit.pipeline import FitOptions, fit_observations, load_samples
    from wolfcal.io.truth import truth_paths
    from wolfcal.observations import HEAD_CAMERA
    from wolfcal.robot.corrections import load_corrections
    from wolfcal.robot.robot import load_robot
    from wolfcal.sim.simulate import SimOptions, simulate_capture
    from wolfcal.vision.observe import detect_observations

    settings = {
        "camera": ({"offsets": "none"}, FitOptions(free="camera")),
        "leg": ({"offsets": "all"}, FitOptions(free="leg", side="both")),
        "outliers": ({"offsets": "none", "outlier_fraction": 0.1}, FitOptions(free="camera")),
    }
    robot = load_robot(CONFIG)
    out: dict = {"binning": binning, "seeds": count, "scenarios": {}}
    with tempfile.TemporaryDirectory() as scratch:
        for name in SCENARIOS:
            sim, options = settings[name]
            runs = []
            for seed in range(count):
                capture = Path(scratch) / f"{name}_{seed}.mcap"
                simulate_capture(
                    CONFIG,
                    capture,
                    SimOptions(samples=24, seed=seed, binning=binning, **sim),
                    say=lambda _: None,
                )
                truth = load_corrections(truth_paths(capture)[0], key="truth")
                samples, _ = load_samples(robot, [capture], None)
                fit = fit_observations(robot, detect_observations(samples, robot)[0][HEAD_CAMERA], options)
                z = np.abs(fit.solution.values - fit.params.values_from(truth)) / fit.solution.std
                rotation, translation = camera_pose_errors(robot, fit.corrections, truth)
                run = {
                    "camera_deg": float(np.rad2deg(rotation.max())),
                    "camera_mm": float(translation.max() * 1e3),
                    "max_z": float(z.max()),
                    "rms_after_px": float(fit.solution.blocks[0].rms_after),
                }
                if name == "leg":
                    rng = np.random.default_rng(seed)
                    run["sole_mm"] = float(
                        1e3
                        * max(
                            link_position_errors(robot, s, fit.corrections, truth, 500, rng).max()
                            for s in ("r_sole", "l_sole")
                        )
                    )
                runs.append(run)
                say(f"seeds {name} {seed}: " + ", ".join(f"{k} {v:.3g}" for k, v in run.items()))
            out["scenarios"][name] = {
                key: {"median": median([r[key] for r in runs]), "max": max(r[key] for r in runs)} for key in runs[0]
            }
    return out
