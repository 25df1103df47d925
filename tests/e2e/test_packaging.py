"""A plain (non-editable) install carries the default robot and its poses: every command, the demo included,
works from any folder."""

from __future__ import annotations

import filecmp
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from wolfcal import __version__

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_a_plain_install_runs_from_any_folder_with_the_packaged_robot_its_poses_and_the_demo(tmp_path):
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target",
         str(target), str(ROOT)],
        check=True, capture_output=True, timeout=600,
    )  # fmt: skip
    packaged = target / "wolfcal" / "data" / "robots" / "wolfgang"
    names = sorted(p.name for p in (ROOT / "configs" / "wolfgang").iterdir())
    assert sorted(p.name for p in packaged.iterdir()) == names
    assert filecmp.cmpfiles(ROOT / "configs" / "wolfgang", packaged, names, shallow=False)[0] == names
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {**os.environ, "PYTHONPATH": str(target)}

    def wolfcal(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "wolfcal.cli", *args], cwd=work, env=env, capture_output=True,
                              text=True, timeout=600)  # fmt: skip

    where = subprocess.run([sys.executable, "-c", "import wolfcal; print(wolfcal.__file__)"], cwd=work, env=env,
                           capture_output=True, text=True, check=True)  # fmt: skip
    assert where.stdout.startswith(str(target))
    version = wolfcal("--version")
    assert version.returncode == 0 and version.stdout == f"wolfcal {__version__}\n", version.stdout
    simulated = wolfcal("simulate", "--out", "sim.mcap", "--poses", "poses.yaml")  # the packaged robot's poses
    assert simulated.returncode == 0, simulated.stderr
    assert yaml.safe_load((work / "sim.truth.yaml").read_text())["samples"] == len(
        yaml.safe_load((packaged / "poses.yaml").read_text())["poses"]
    )
    fitted = wolfcal("fit", "sim.mcap", "--out", "fit")
    assert fitted.returncode == 0, fitted.stderr
    assert (work / "fit" / "calibrated.urdf").is_file()
    assert str(packaged) in (work / "fit" / "result.yaml").read_text()
    demo = wolfcal("demo", "--out", "demo")  # its captures are simulated: none shipped, none looked for
    assert demo.returncode == 0, demo.stdout + demo.stderr
    assert (work / "demo" / "report" / "calibrated.urdf").is_file()
    assert not (target / "captures").exists() and not list(target.rglob("*.mcap"))
