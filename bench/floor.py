"""The `floor` part: the venue check on rendered images: feet + floor captures -> fit -> true and measured ground error.

A robot config and camera the shipped demos do not use (Wolfgang's URDF, feet tags 7 and 8 of 0.1 m, torso tag 3,
floor tags 60-65 of 0.12-0.2 m lying 1-4 m away; a 1280x960 camera with k1 = -0.12), simulated with 0.025 rad rms
leg and head encoder offsets and the camera ~4 deg off. Per seed:
  leg     24 feet + 20 floor samples, `--free leg --side both`: true ground error at 4.5 m (worst bearing of -30, 0,
          +30 deg) before and after, the measured one on a held-out floor capture (no truth) with its 1-sigma and
          its parts, whether it agrees with the true one (within 20 % or 1 cm) and its CPU time, the soles' worst
          pose error over 500 calibration-range poses, fit time
  camera  legs calibrated (no offsets), camera ~4 deg off, 24 feet + 20 floor samples, `--free camera`
The held-out floor capture: 16 samples, all standing.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from wolfcal.camera.camera_info import save_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.accuracy import link_pose_errors
from wolfcal.evaluate.floor_ground import measured_ground_errors
from wolfcal.evaluate.ground import ground_errors
from wolfcal.fit.pipeline import FitOptions, fit_observations, load_samples, split_floor
from wolfcal.io.truth import truth_paths
from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.floor import moved_stance
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.sim.simulate import SimOptions, simulate_capture
from wolfcal.vision.corner_bias import CORNER_INSET
from wolfcal.vision.observe import detect_observations

WOLFGANG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"
CAMERA = CameraModel(1280, 960, np.array([[1000.0, 0, 645.0], [0, 1002.0, 478.0], [0, 0, 1]]),
                     np.array([-0.12, 0.08, 0.0005, -0.0003, 0.0]))  # fmt: skip
FLOOR_DISTANCE_M = (1.0, 4.0)
FLOOR_TAG_SIZES_M = (0.12, 0.14, 0.16, 0.18, 0.2, 0.15)
# stances of the floor samples besides `floor.standing` (--stances): the torso moved sideways or turned, soles kept,
# so every leg joint reads another tick (see the file's comment)
STANCES = yaml.safe_load((WOLFGANG / "floor_stances.yaml").read_text())


def held_stances(count: int) -> list[dict[str, float]]:
    """`count` stances for the held-out floor samples, none of the fit's: the recipe of Wolfgang's
    `floor.check_stances` (robot.yaml; its first 16 are these): the torso moved from 1 cm below standing (knees
    bent) by a pseudo-random (numpy default_rng(0)) dx +-2 cm, dy +-3 cm, dz 0-1.5 cm lower, yaw +-0.15 rad
    (`robot.floor.moved_stance`, soles kept)."""
    robot = load_robot(WOLFGANG / "robot.yaml")
    shipped = list(robot.config.floor_config().check_stances)
    if count <= len(shipped):
        return shipped[:count]
    centre = moved_stance(robot, STANCES[0], (0.0, -0.03, 0.0, 0.0))  # STANCES[0] moved back to the middle
    shifts = np.random.default_rng(0).uniform([-0.02, -0.03, -0.015, -0.15], [0.02, 0.03, 0.0, 0.15], (count, 4))
    stances = [moved_stance(robot, centre, shift) for shift in shifts]
    assert stances[: len(shipped)] == shipped, "robot.yaml's floor.check_stances follow this recipe"
    return stances


def write_config(folder: Path, stances: bool = True, n_tags: int = 6, check: int = 0) -> Path:
    """robot.yaml with other tag ids and sizes, the 1280x960 camera, `n_tags` floor tags (60, 61, ... of the sizes
    FLOOR_TAG_SIZES_M in turn), (`stances`) the floor stances `floor.standing` and STANCES and `check`
    `held_stances` as `floor.check_stances`; returns its path."""
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = str((WOLFGANG / data["urdf"]).resolve())
    save_camera_info(CAMERA, folder / "camera.yaml")
    data["camera"]["intrinsics"] = str(folder / "camera.yaml")
    data.pop("external_cameras", None)
    data["floor"].pop("check_stances", None)
    if check:
        data["floor"]["check_stances"] = held_stances(check)
    new_ids = {43: 7, 44: 8, 42: 3}
    for tag in data["tags"]:
        tag["size"] = 0.12 if tag["id"] == 42 else 0.1
        tag["id"] = new_ids[tag["id"]]
    sizes = FLOOR_TAG_SIZES_M
    data["floor"]["tags"] = [{"id": 60 + k, "size": sizes[k % len(sizes)]} for k in range(n_tags)]
    if stances:
        data["floor"]["stances"] = [data["floor"]["standing"], *STANCES]
    path = folder / ("robot.yaml" if stances else "robot_standing.yaml")
    path.write_text(yaml.safe_dump(data))
    return path


def observations(robot: Robot, captures: list[Path]) -> dict[str, Observations]:
    samples, _ = load_samples(robot, captures, None)
    return detect_observations(samples, robot)[0]


@dataclass(frozen=True)
class Held:
    """The held-out floor capture: `samples` in all, spread over `layouts` captures with the tags laid out anew in
    each (a user moving the tags), in the stances (`stances`) or all standing, tags `distance` m away."""

    samples: int = 16
    layouts: int = 1
    stances: int = 1  # 1: all standing; 5: `floor.standing` and STANCES (the fit's); 0: `new_stances`
    new_stances: int = 0  # held-out stances none of the fit's (`held_stances`)
    distance: tuple[float, float] = FLOOR_DISTANCE_M

    def tag(self) -> str:
        """The part of a --keep folder's name these options set."""
        stances = f"_new-stances{self.new_stances}" if self.new_stances else {1: "", 5: "_held-stances"}[self.stances]
        return (
            f"_held{self.samples}x{self.layouts}"
            + stances
            + ("" if self.distance == FLOOR_DISTANCE_M else f"_held{self.distance[0]:g}-{self.distance[1]:g}m")
        )


def simulate(
    config: Path,
    folder: Path,
    seed: int,
    offsets: str,
    n_tags: int = 6,
    n_floor: int = 20,
    held: Held = Held(),
) -> tuple[dict[str, Path], list[Path]]:
    """feet and floor (`n_floor` samples, in the stances) captures of one simulated robot (names -> paths) and the
    held-out floor captures (`held`; `n_tags` floor tags), each made once per folder."""
    paths = {k: folder / f"{k}.mcap" for k in ("feet", "floor")}
    quiet = lambda _m: None  # noqa: E731
    if not paths["feet"].exists():
        simulate_capture(config, paths["feet"], SimOptions(samples=24, seed=seed, offsets=offsets), say=quiet)
    truth = truth_paths(paths["feet"])[0]
    if not paths["floor"].exists():
        simulate_capture(config, paths["floor"], SimOptions(samples=n_floor, seed=seed + 100, floor=True,
                         truth_file=truth, floor_distance=FLOOR_DISTANCE_M), say=quiet)  # fmt: skip
    held_folder = folder / held.tag().lstrip("_")  # the fit's captures shared by every held-out protocol
    held_folder.mkdir(exist_ok=True)
    held_config = write_config(held_folder, bool(held.new_stances) or held.stances == 5, n_tags, held.new_stances)
    sizes = np.diff(np.linspace(0, held.samples, held.layouts + 1).round().astype(int))
    held_paths = [held_folder / f"held_floor{k}.mcap" for k in range(held.layouts)]
    for k, (path, n) in enumerate(zip(held_paths, sizes)):
        if not path.exists():
            simulate_capture(held_config, path, SimOptions(samples=int(n), seed=seed + 200 + 1000 * k, floor=True,
                             floor_check=bool(held.new_stances),
                             truth_file=truth, floor_distance=held.distance), say=quiet)  # fmt: skip
    return paths, held_paths


def run(scenario: str, seed: int, folder: Path, stances: bool, n_tags: int = 6, n_floor: int = 20,
        held: Held = Held()) -> dict:  # fmt: skip
    """The figures of one scenario and seed (ground errors [m], sole errors [m, rad], CPU times [s])."""
    folder.mkdir(parents=True, exist_ok=True)
    config = write_config(folder, stances, n_tags)
    paths, held_paths = simulate(config, folder, seed, "all" if scenario == "leg" else "none", n_tags, n_floor, held)
    robot = load_robot(config)
    truth = load_corrections(truth_paths(paths["feet"])[0], key="truth")
    obs = observations(robot, [paths["feet"], paths["floor"]])
    start = time.process_time()
    fit = fit_observations(robot, obs, FitOptions(free=scenario, side="both"))
    cpu = time.process_time() - start
    rows = ground_errors(robot, CAMERA, truth, {"before": Corrections(), "after": fit.corrections}, (4.5,))[0]
    before, after = (rows["models"][k]["error_m"] for k in ("before", "after"))
    _, held_obs = split_floor(robot, observations(robot, held_paths))
    out: dict = {"scenario": scenario, "seed": seed, "true_before_m": before, "true_after_m": after, "fit_cpu": cpu}
    if held_obs is not None:
        names = fit.params.names
        k = names.index(CORNER_INSET)
        inset = (float(fit.solution.values[k]), float(fit.solution.uncertainty.std[k]))
        start = time.process_time()
        measured = measured_ground_errors(robot, held_obs, {"after": fit.corrections}, (4.5,), inset)
        measure_cpu = time.process_time() - start
        if measured is not None:
            row = measured["models"]["after"]["rows"][0]
            agrees = abs(row["error_m"] - after) <= max(0.2 * after, 0.01)
            out |= {"measured_m": row["error_m"], "measured_std_m": row["std_m"], "agrees": bool(agrees),
                    "z": (row["error_m"] - after) / row["std_m"], "views": measured["views"],
                    "outlier_corners": measured["outlier_corners"], "inset_px": inset[0], "measure_cpu": measure_cpu,
                    **{k: row[k] for k in ("formal_std_m", "sample_std_m", "tag_std_m", "rounding_std_m")}}  # fmt: skip
    rng = np.random.default_rng(seed)
    soles = [link_pose_errors(robot, s, fit.corrections, truth, 500, rng) for s in robot.config.floor_config().soles]
    out["sole_max_m"] = float(max(p.max() for _, p in soles))
    out["sole_max_rad"] = float(max(r.max() for r, _ in soles))
    floor_block = [b for b in fit.solution.blocks if b.name == "floor"]
    if floor_block:
        out["floor_rms_px"] = floor_block[0].rms_after
    return out


def floor(seeds: int, say, scenarios: tuple[str, ...] = ("leg", "camera")) -> dict:
    """Per scenario and seed the figures of `run` (or why wolfcal refused, as a user would read it); per scenario
    the medians over the seeds of the true ground error before and after [m], the soles' worst error [m] and how
    many measured ground errors agree with the true one."""
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        for scenario in scenarios:
            for seed in range(seeds):
                try:
                    rows.append(run(scenario, seed, Path(tmp) / f"{scenario}_{seed}", False))
                except WolfcalError as exc:  # e.g. a floor tag seen in one sample only
                    rows.append({"scenario": scenario, "seed": seed, "refused": str(exc)})
                r = rows[-1]
                told = r.get("refused") or f"ground error {r['true_before_m']:.3f} -> {r['true_after_m']:.4f} m"
                say(f"floor {scenario} seed {seed}: {told}")
    summary = {}
    for scenario in scenarios:
        done = [r for r in rows if r["scenario"] == scenario and "refused" not in r]
        if done:
            summary[scenario] = {
                **{k: float(np.median([r[k] for r in done])) for k in ("true_before_m", "true_after_m", "sole_max_m")},
                "agrees": sum(bool(r.get("agrees")) for r in done),
                "measured": sum("measured_m" in r for r in done),
                "refused": sum(r["scenario"] == scenario and "refused" in r for r in rows),
            }
    return {"seeds": seeds, "rows": rows, "summary": summary}
