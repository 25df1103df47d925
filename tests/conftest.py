"""Shared fixtures: the default Wolfgang robot and its head camera (2048x1536, strong barrel distortion)."""

import os
import signal
import subprocess
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the CLI: BLAS threads spinning on busy cores cost 50x

import numpy as np
import pytest
import yaml

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.field.model import KIDSIZE
from wolfcal.observations import Observations
from wolfcal.robot.robot import Robot, load_robot

WOLFGANG = Path(__file__).resolve().parents[1] / "configs" / "wolfgang"


@pytest.fixture(scope="session", autouse=True)
def detection_cache_dir(tmp_path_factory):
    """Tests never read or write the user's detection cache: one temporary cache folder for the session."""
    folder = tmp_path_factory.mktemp("detection-cache")
    previous = os.environ.get("WOLFCAL_CACHE_DIR")
    os.environ["WOLFCAL_CACHE_DIR"] = str(folder)
    yield folder
    if previous is None:
        os.environ.pop("WOLFCAL_CACHE_DIR", None)
    else:
        os.environ["WOLFCAL_CACHE_DIR"] = previous


def wolfgang_with_other_tags() -> dict:
    """Wolfgang's robot.yaml (absolute paths, no external cameras) with other tag ids and sizes: feet 7 and 8 of
    0.1 m, torso 3 of 0.12 m: a config the shipped data were not made for."""
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = str((WOLFGANG / data["urdf"]).resolve())
    data["camera"]["intrinsics"] = str((WOLFGANG / data["camera"]["intrinsics"]).resolve())
    data.pop("external_cameras", None)
    new_ids = {43: 7, 44: 8, 42: 3}
    for tag in data["tags"]:
        tag["size"] = 0.12 if tag["id"] == 42 else 0.1
        tag["id"] = new_ids[tag["id"]]
    return data


# A camera the shipped data do not use: 1280x960 with k1 = -0.12 (the floor tests' and the bench harness's floor part)
OTHER_CAMERA = CameraModel(1280, 960, np.array([[1000.0, 0, 645.0], [0, 1002.0, 478.0], [0, 0, 1]]),
                           np.array([-0.12, 0.08, 0.0005, -0.0003, 0.0]))  # fmt: skip


def robot_with_floor_tags(folder: Path) -> Robot:
    """`wolfgang_with_other_tags` with floor tags 60-65 of 0.12-0.2 m, written to folder/robot.yaml and loaded."""
    data = wolfgang_with_other_tags()
    data["floor"]["tags"] = [{"id": 60 + k, "size": s} for k, s in enumerate([0.12, 0.14, 0.16, 0.18, 0.2, 0.15])]
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    return load_robot(folder / "robot.yaml")


@pytest.fixture(scope="session")
def robot():
    return load_robot(WOLFGANG)


@pytest.fixture(scope="session")
def camera():
    """2048x1536, plumb_bob with k1 = -0.286 (the Wolfgang's Basler camera)."""
    return load_camera_info(WOLFGANG / "basler_acA2040.yaml")


def default_sigint() -> None:
    """Popen `preexec_fn`: the child takes Ctrl-C as from a terminal even when the tests run where SIGINT is ignored
    (a background job inherits SIG_IGN, and Python keeps it ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def wolfgang_on_a_field(folder: Path, **field) -> Path:
    """Wolfgang's robot.yaml (absolute paths, no external cameras) with a KidSize field and the robot placed at
    (-3, 0, 0) (or the `field` section given), written to folder/robot.yaml."""
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = str((WOLFGANG / data["urdf"]).resolve())
    data["camera"]["intrinsics"] = str((WOLFGANG / data["camera"]["intrinsics"]).resolve())
    data.pop("external_cameras", None)
    dimensions = {name: getattr(KIDSIZE, name) for name in KIDSIZE.__dataclass_fields__}
    data["field"] = field or {"dimensions": dimensions, "robot_at": {"x": -3.0, "y": 0.0, "yaw": 0.0}}
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    return folder / "robot.yaml"


def stop_after_sample(
    command: list[str], cwd: Path, signum: int, sample: int = 2, wait_s: float = 60.0
) -> tuple[int, str]:
    """Run a `wolfcal capture` command, send it `signum` once it has printed 'sample N' (that sample is on disk:
    an event, no sleeping), and return its exit code and everything it wrote to stderr."""
    process = subprocess.Popen(
        command, cwd=cwd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, preexec_fn=default_sigint
    )
    try:
        for line in process.stderr:
            if line.startswith(f"sample {sample}"):
                break
        process.send_signal(signum)
        stderr = process.stderr.read()  # until the process has closed it
        process.wait(wait_s)
    finally:
        if process.poll() is None:
            process.kill()
    return process.returncode, stderr


def joined(a: Observations, b: Observations) -> Observations:
    """Feet samples then floor samples, as one head-camera capture."""
    return Observations(
        a.joint_names, np.concatenate([a.q_measured, b.q_measured]), np.concatenate([a.stamps_ns, b.stamps_ns]),
        a.sources + b.sources, a.camera, np.concatenate([a.sample_index, b.sample_index + a.n_samples]),
        np.concatenate([a.tag_ids, b.tag_ids]), np.concatenate([a.corner_index, b.corner_index]),
        np.concatenate([a.uv, b.uv]),
    )  # fmt: skip
