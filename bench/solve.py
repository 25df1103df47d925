"""The `solve` and `stability` parts.

`solve`: the solve's wall and CPU time (median of 3; reading and tag detection excluded: observations are projected
without images) and the number of linearisations, the leg preset (both sides) with the head camera on synthetic
samples and with an external camera on 30 and 120. BLAS runs on one thread, as in the `wolfcal` command.

`stability`: per case, the largest |change| of a chain parameter in its reported standard deviations (and the largest
relative change of a std) when the samples come in another order (2 orders, corner rows shuffled too), when 1e-7 px
is added to every corner (1e-10 m to every marker; 2 draws), when BLAS runs another kernel
(OPENBLAS_CORETYPE=Sandybridge: other summation orders; a subprocess), and when the solver's rounds stop elsewhere
(ROUND_STD_TOL 0.03 and ROUND_COST_TOL 1e-4, or 0.3 and 1e-2); with the solve's CPU time and linearisations. Cases:
the shipped demo captures (`wolfcal demo`'s two fits, the external camera demo), synthetic corners (head camera
25/100/400 samples with outliers, external camera 30/120), a motion-capture session (tests/mocap_session.py) and the
harness's 24-sample camera capture when present."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.fit import solver
from wolfcal.fit.pipeline import FitOptions, fit_observations, load_samples
from wolfcal.robot.robot import load_robot
from wolfcal.sim.observations import reordered
from wolfcal.sim.scenario import synthetic_external_scenario, synthetic_scenario
from wolfcal.vision.observe import detect_observations

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "wolfgang"
BENCH_DATA = Path(tempfile.gettempdir()) / "wolfcal_bench"
TRIPOD = CameraModel(1920, 1080, np.array([[1400.0, 0, 959.5], [0, 1400.0, 539.5], [0, 0, 1]]), np.zeros(5))


def timed(robot, obs, options: FitOptions) -> tuple[float, float, object]:
    wall, cpu, fit = [], [], None
    for _ in range(3):
        w, c = time.perf_counter(), time.process_time()
        fit = fit_observations(robot, obs, options)
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
    return float(np.median(wall)), float(np.median(cpu)), fit


def speed(sizes: tuple[int, ...], say) -> dict:
    """The solve's wall and CPU time [s] (median of 3) and linearisations: the head camera's leg preset on `sizes`
    synthetic samples, an external camera on 30 and 120 (and 120 with a pose per sample)."""
    robot = load_robot(CONFIG)
    camera = load_camera_info(CONFIG / "basler_acA2040.yaml")
    rows = []
    external = [("external camera", 30, False), ("external camera", 120, False), ("external camera", 120, True)]
    cases = [("head camera", n, False) for n in sizes] + external
    for system, n, moving in cases:
        if system == "head camera":
            scenario = synthetic_scenario(robot, camera, n=n, seed=n, offsets="all")
            options = FitOptions(free="leg", side="both")
        else:
            scenario = synthetic_external_scenario(robot, TRIPOD, n=n, seed=n)
            options = FitOptions(free="leg", external_moving=moving)
        wall, cpu, fit = timed(robot, scenario.obs, options)
        rows.append({"system": system + (" (moving)" if moving else ""), "samples": n, "corners": len(scenario.obs.uv),
                     "unknowns": len(fit.params), "wall": wall, "cpu": cpu,
                     "linearisations": fit.solution.evaluations})  # fmt: skip
        say(f"solve {rows[-1]['system']}, {n} samples: {wall:.3f} s wall, {cpu:.3f} s CPU")
    return {"preset": "leg", "rows": rows}


Case = Callable[[], tuple]  # -> (robot, observations by camera, markers or None, options)


def from_captures(config: Path, captures: list[Path], **options) -> Case:
    def load() -> tuple:
        robot = load_robot(config)
        samples, _ = load_samples(robot, captures, None, cameras=())
        return robot, detect_observations(samples, robot)[0], None, FitOptions(**options)

    return load


def synthetic(n: int, noise_px: float, outliers: float | None) -> Case:
    def load() -> tuple:
        robot = load_robot(CONFIG)
        if outliers is None:
            obs = synthetic_external_scenario(robot, TRIPOD, n=n, seed=n, noise_px=noise_px).obs
            return robot, {obs.camera_name: obs}, None, FitOptions(free="leg")
        camera = load_camera_info(CONFIG / "basler_acA2040.yaml")
        obs = synthetic_scenario(robot, camera, n=n, seed=n, offsets="all", noise_px=noise_px,
                                 outlier_fraction=outliers).obs  # fmt: skip
        return robot, {obs.camera_name: obs}, None, FitOptions(free="leg", side="both")

    return load


def mocap_session() -> tuple:
    sys.path.insert(0, str(ROOT / "tests"))
    from mocap_session import STRIDER, write_session

    from wolfcal.io.mocap_load import load_marker_observations

    robot = load_robot(STRIDER)
    with tempfile.TemporaryDirectory() as folder:
        write_session(Path(folder), 0)
        markers = load_marker_observations(robot.config, robot.joint_names, [Path(folder) / "markers.mcap"], [])
    return robot, {}, markers, FitOptions(free="leg", system="mocap")


def cases() -> dict[str, Case]:
    out: dict[str, Case] = {
        "demo venue": from_captures(CONFIG, [ROOT / "captures/demo.mcap", ROOT / "captures/floor_demo.mcap"],
                                    free="camera"),
        "demo legs": from_captures(CONFIG, [ROOT / "captures/legs_demo.mcap"], free="camera"),
        "external demo": from_captures(CONFIG, [ROOT / "captures/external_demo.mcap"], free="leg"),
        "synthetic 25": synthetic(25, 0.3, 0.1), "synthetic 100": synthetic(100, 0.15, 0.1),
        "synthetic 400": synthetic(400, 0.15, 0.05), "external 30": synthetic(30, 0.15, None),
        "external 120": synthetic(120, 0.4, None), "mocap": mocap_session,
    }  # fmt: skip
    if (BENCH_DATA / "camera_24.mcap").is_file():  # the harness's camera capture (bench/run.py --parts fit)
        out["bench 24"] = from_captures(CONFIG, [BENCH_DATA / "camera_24.mcap"], free="camera")
    return out


def permuted(observations: dict, markers, seed: int) -> tuple[dict, object]:
    """The same data with the samples in another order (and the corner rows shuffled)."""
    out = {name: reordered(obs, seed) for name, obs in observations.items()}
    if markers is not None:
        markers = markers.subset(np.random.default_rng(seed).permutation(markers.n_samples))
    return out, markers


def jittered(observations: dict, markers, seed: int) -> tuple[dict, object]:
    """The same data with 1e-7 px on every corner, 1e-10 m on every marker."""
    out = {k: replace(o, uv=o.uv + 1e-7 * np.random.default_rng(seed).standard_normal(o.uv.shape))
           for k, o in observations.items()}  # fmt: skip
    if markers is not None:
        markers = replace(
            markers, xyz=markers.xyz + 1e-10 * np.random.default_rng(seed).standard_normal(markers.xyz.shape)
        )
    return out, markers


def chain_fit(robot, observations, markers, options) -> dict:
    start = time.process_time()
    fit = fit_observations(robot, observations, options, markers=markers)
    cpu = time.process_time() - start
    n = len(fit.chain)
    return {"values": fit.solution.values[:n].tolist(), "std": fit.solution.std[:n].tolist(),
            "evaluations": fit.solution.evaluations, "cpu": cpu}  # fmt: skip


def change(a: dict, b: dict) -> tuple[float, float]:
    std = np.array(a["std"])
    moved = np.abs(np.array(a["values"]) - np.array(b["values"])) / std
    return float(np.max(moved)), float(np.max(np.abs(np.array(b["std"]) / std - 1.0)))


def with_rounds(std_tol: float, cost_tol: float, fit: Callable[[], dict]) -> dict:
    saved = solver.ROUND_STD_TOL, solver.ROUND_COST_TOL
    solver.ROUND_STD_TOL, solver.ROUND_COST_TOL = std_tol, cost_tol
    try:
        return fit()
    finally:
        solver.ROUND_STD_TOL, solver.ROUND_COST_TOL = saved


def stability(names: list[str], say) -> dict:
    """Per case (all by default): unknowns, linearisations, CPU [s], and per change that should not matter the
    largest |change| of a chain parameter in its reported stds and the largest relative change of a std."""
    known = cases()
    out = {}
    for name in names or list(known):
        robot, observations, markers, options = known[name]()
        base = chain_fit(robot, observations, markers, options)
        others: dict[str, list[dict]] = {
            "order": [chain_fit(robot, *permuted(observations, markers, s), options) for s in (1, 3)],
            "1e-7 px": [chain_fit(robot, *jittered(observations, markers, s), options) for s in (1, 2)],
            "rounds": [with_rounds(t, c, lambda: chain_fit(robot, observations, markers, options))  # noqa: B023
                       for t, c in ((0.03, 1e-4), (0.3, 1e-2))],
        }  # fmt: skip
        with tempfile.TemporaryDirectory() as folder:  # the same data, fitted in a process with another BLAS kernel
            data = Path(folder) / "case.pickle"
            data.write_bytes(pickle.dumps((robot.config.path, observations, markers, options)))
            env = {**os.environ, "OPENBLAS_CORETYPE": "Sandybridge"}
            dumped = subprocess.run([sys.executable, __file__, "--dump", str(data)], env=env, capture_output=True,
                                    text=True, check=True).stdout  # fmt: skip
        others["BLAS kernel"] = [json.loads(dumped.splitlines()[-1])]
        changes = {}
        for label, fits in others.items():
            moved, std = np.max([change(base, f) for f in fits], axis=0)
            changes[label] = {"moved_std": float(moved), "std_change": float(std)}
        out[name] = {"unknowns": len(base["values"]), "linearisations": base["evaluations"], "cpu": base["cpu"],
                     "changes": changes}  # fmt: skip
        say(f"stability {name}: largest change {max(c['moved_std'] for c in changes.values()):.1e} std")
    return out


if __name__ == "__main__":  # `stability`'s fit in a process with another BLAS kernel: a pickled case -> JSON
    config, observations, markers, options = pickle.loads(Path(sys.argv[2]).read_bytes())
    print(json.dumps(chain_fit(load_robot(config), observations, markers, options)))
