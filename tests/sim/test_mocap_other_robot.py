"""The motion-capture must-show on data wolfcal did not generate (tests/mocap_session.py: the strider robot and its
Vicon-style marker layout, yourdfpy kinematics, Markers in metres by mcap_ros2, C3D in mm by ezc3d): 25 still poses,
0.025 rad rms leg offsets, 0.3 mm noise, 3 % occluded, 1 % reflections 2-20 mm away, mounts off 1 mm."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from mocap_session import STRIDER, known_mounts_config, mount_rotation, sole_errors, write_session
from typer.testing import CliRunner

from wolfcal.cli import app

FIT = ["--system", "mocap", "--free", "leg"]


def fit(args: list[str], out) -> dict:
    result = CliRunner().invoke(app, ["fit", *args, *FIT, "--out", str(out)])
    assert result.exit_code == 0, result.output
    return yaml.safe_load((out / "result.yaml").read_text())


def offsets(data: dict) -> dict[str, float]:
    return {p["name"][: -len(".offset")]: p["value"] for p in data["parameters"] if p["name"].endswith(".offset")}


@pytest.mark.slow
def test_leg_fit_of_another_robot_from_markers_and_from_c3d(tmp_path):
    """Over 6 seeds (the bench harness's `mocap` part) the soles are within 0.78 mm; their orientation within
    0.18-0.74 deg, not 0.3: the ankle roll is each foot's last joint, so its offset error is a fixed rotation of the
    foot that a rotation of the foot markers' mounts undoes in every pose; only the mounts' 1 mm prior decides it,
    and the error is the rotation the true mount errors make about the roll axis (0.07 deg rms apart). With the true
    marker places in the config the soles are within 0.22 deg. This seed: 0.44 deg, 0.16 deg with known mounts."""
    session = write_session(tmp_path, seed=1)
    config = ["--robot", str(STRIDER / "robot.yaml")]
    runs = {"markers": fit([str(tmp_path / "markers.mcap"), *config], tmp_path / "fit_markers"),
            "c3d": fit([str(tmp_path / "joints.mcap"), "--mocap", str(tmp_path / "markers.c3d"), *config],
                       tmp_path / "fit_c3d")}  # fmt: skip
    for name, data in runs.items():
        mm, deg = sole_errors(session, offsets(data))
        assert mm < 1.0 and deg < 0.6, (name, mm, deg)
        for p in data["parameters"]:  # the leg offsets and the marker mounts
            if p["name"].endswith(".offset"):
                true = session.offsets[p["name"][: -len(".offset")]]
            else:
                _, marker, axis = p["name"].split(".") if p["name"].startswith("marker.") else (None, None, None)
                if marker is None:
                    continue
                true = session.mounts[marker]["xyz".index(axis)]
            assert abs(p["value"] - true) < 3 * p["std"], (name, p["name"], p["value"], true, p["std"])
        for side in "lr":  # the ankle-roll error is the mounts' rotation about its axis
            error = offsets(data)[f"{side}_ankle_roll"] - session.offsets[f"{side}_ankle_roll"]
            assert error == pytest.approx(mount_rotation(session, side), abs=np.deg2rad(0.1)), (name, side)
        left_out = {(e["sample"], e["marker"]) for e in data["blocks"][0]["left_out_markers"]}
        assert session.reflections <= left_out and len(left_out - session.reflections) <= 1, name
    clock = runs["c3d"]["blocks"][0]["mocap_clock_offset_s"]["markers.c3d"]
    assert clock == pytest.approx(session.c3d_offset_s, abs=0.005)
    known = fit([str(tmp_path / "markers.mcap"), "--robot", str(known_mounts_config(session, tmp_path))],
                tmp_path / "fit_known")  # fmt: skip
    mm, deg = sole_errors(session, offsets(known))
    assert mm < 1.0 and deg < 0.3
