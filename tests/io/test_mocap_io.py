"""Motion-capture sources written by independent writers: C3D by ezc3d, Markers recordings by mcap_ros2 with the
message definition text written here; stillness, clock offset, bad input. Then the whole path on `wolfcal simulate
--system mocap` (slow). The file layouts of each system: test_mocap_formats.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from mocap_recordings import RATE, T0, session, write_c3d, write_markers_recording
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.io.mocap_clock import estimate_offset
from wolfcal.io.mocap_files import read_mocap_file
from wolfcal.io.mocap_load import load_marker_observations
from wolfcal.io.mocap_samples import read_recording

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"


def test_c3d_written_by_ezc3d_reads_in_metres_with_invalid_points_missing(tmp_path):
    t, _, p = session()
    p_mm = p * 1000.0
    p_mm[5, 1] = np.nan
    write_c3d(tmp_path / "a.c3d", ["r_foot_fl", "torso_ul", "wand"], p_mm)
    traj = read_mocap_file(tmp_path / "a.c3d")
    assert traj.labels == ["r_foot_fl", "torso_ul", "wand"] and traj.file_clock
    assert np.allclose(traj.times_ns[:3], [0, 10_000_000, 20_000_000])
    assert np.isnan(traj.xyz[5, 1]).all() and np.allclose(traj.xyz[6], p[6], atol=1e-6)


def test_c3d_without_units_is_refused(tmp_path):
    t, _, p = session()
    write_c3d(tmp_path / "a.c3d", ["a", "b", "c"], p * 1000, units="")
    with pytest.raises(WolfcalError, match="POINT:UNITS gives no length unit"):
        read_mocap_file(tmp_path / "a.c3d")


def test_markers_recording_by_name_or_index_and_clock_offset_of_a_c3d(tmp_path):
    config = load_robot_config(WOLFGANG)
    t, q, p = session(n_poses=8)
    labels = ["r_foot_fl", "torso_ul", "unlabelled_3"]
    write_markers_recording(tmp_path / "r.mcap", t, {"RKnee": q}, labels, p)
    states, traj = read_recording(tmp_path / "r.mcap", config, with_markers=True)
    assert traj.labels == labels and np.allclose(traj.xyz[10], p[10]) and not traj.file_clock
    write_markers_recording(tmp_path / "i.mcap", t, {"RKnee": q}, labels, p, by_index=True)
    assert read_recording(tmp_path / "i.mcap", config, with_markers=True)[1].labels == ["0", "1", "2"]
    # a C3D that starts 0.537 s into the recording
    first = 54
    write_c3d(tmp_path / "s.c3d", labels, p[first:] * 1000.0)
    offset = estimate_offset(read_mocap_file(tmp_path / "s.c3d"), [0, 1], states)
    assert offset == pytest.approx(T0 / 1e9 + t[first], abs=0.005)


def test_still_samples_one_per_hold_and_bad_input(tmp_path):
    config = load_robot_config(WOLFGANG)
    t, q, p = session(n_poses=5)
    names = list(config.markers.names)
    labels = ["r_foot_fl", "torso_ul", "ghost"]
    write_markers_recording(tmp_path / "r.mcap", t, {j: q for j in ("RKnee", "LKnee")}, labels, p)
    obs = load_marker_observations(config, ["RKnee", "LKnee"], [tmp_path / "r.mcap"], [])
    assert obs.n_samples == 5 and obs.marker_names == ["r_foot_fl", "torso_ul"] and obs.unknown_names == ["ghost"]
    held = np.array(
        [np.median(p[int((2.5 * k + 1.1) * RATE) : int((2.5 * k + 2.4) * RATE)], axis=0) for k in range(5)]
    )  # per hold: the median of its frames (0.3 mm noise -> ~0.03 mm)
    assert np.allclose(obs.xyz.reshape(5, 2, 3), held[:, :2], atol=0.0001)
    assert np.allclose(obs.q_measured[:, 0], q[(np.arange(5) * 2.5 * RATE + 200).astype(int)])
    write_c3d(tmp_path / "x.c3d", ["a", "b", "c"], p * 1000.0)
    with pytest.raises(WolfcalError, match="none of the robot config's marker names"):
        load_marker_observations(config, ["RKnee"], [tmp_path / "r.mcap"], [tmp_path / "x.c3d"])
    write_markers_recording(tmp_path / "j.mcap", t, {"RKnee": np.zeros_like(q)}, labels, None)
    write_c3d(tmp_path / "y.c3d", labels, p * 1000.0)
    with pytest.raises(WolfcalError, match="cannot find the clock offset"):
        load_marker_observations(config, ["RKnee"], [tmp_path / "j.mcap"], [tmp_path / "y.c3d"])
    assert names  # the config is untouched


@pytest.mark.slow
def test_simulated_session_through_the_cli_recording_and_c3d(tmp_path):
    """Wolfgang, 25 still poses, 0.025 rad rms leg offsets, 0.3 mm noise, 3 % occluded, 1 % reflections, mounts off
    by 1 mm: both the Markers recording and the C3D file (clock offset estimated) give offsets within 3.5 std and
    flag every reflection; the C3D offset within 5 ms."""
    runner = CliRunner()
    out = tmp_path / "s.mcap"
    result = runner.invoke(app, ["simulate", "--robot", str(WOLFGANG), "--system", "mocap", "--offsets", "legs",
                                 "--samples", "25", "--seed", "3", "--out", str(out)])  # fmt: skip
    assert result.exit_code == 0, result.output
    truth = yaml.safe_load((tmp_path / "s.truth.yaml").read_text())
    for name, extra in (("rec", []), ("c3d", ["--mocap", str(tmp_path / "s.c3d")])):
        result = runner.invoke(app, ["fit", str(out), "--robot", str(WOLFGANG), "--system", "mocap", "--free", "leg",
                                     "--out", str(tmp_path / name), *extra])  # fmt: skip
        assert result.exit_code == 0, result.output
        data = yaml.safe_load((tmp_path / name / "result.yaml").read_text())
        for p in data["parameters"]:
            if p["name"].endswith(".offset"):
                error = p["value"] - truth["truth"]["offsets"].get(p["name"][: -len(".offset")], 0.0)
                assert abs(error) < 3.5 * p["std"], (name, p["name"], error, p["std"])
        left_out = {(e["sample"], e["marker"]) for e in data["blocks"][0]["left_out_markers"]}
        assert {(r["pose"], r["marker"]) for r in truth["reflections"]} <= left_out
        if name == "c3d":
            assert data["mocap_clock_offset_s"]["s.c3d"] == pytest.approx(truth["c3d_clock_offset_s"], abs=0.005)
