"""`wolfcal markers` on real exports made by others (../shared/realdata/mocap, see its README for sources and
licences) against a plain csv + numpy reader written here from each file's layout. Skipped when the folder is absent.

What they taught:
- hmv-s16_sample_optitrack_take.csv (Motive 1.21): the header rows carry no names (their first two cells are empty);
  a rigid body's rotation, position and error columns and its model markers ('Rigid Body Marker', with a Marker
  Quality column) come before the measured markers; unlabelled markers are 'Unlabeled:108'; three marker columns
  are blank in every frame.
- optitrack-converter_test_markers_enabled.csv (Motive 3, format 1.23): the rows are named in the second cell
  (',Type', ',Name', ',ID'); 'Time (Seconds)' is rounded to 1 ms (frame 1 at 360 Hz: 0.003000), so times come
  from frame / Export Frame Rate; millimetres; 'Unlabeled 1036'.
- pyomeca_markers.csv (Vicon Nexus Trajectories): 'Subject:Marker' labels ('boite:gauche_ext', 'Daphnee:ASISr'),
  exactly as the C3D of the same trial names them; units line 'mm'; blank cells for gaps.
- pyomeca_analogs.csv (Vicon Nexus Devices only): EMG at 2000 Hz and no markers: refused saying so.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from wolfcal.cli import app

REALDATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata" / "mocap"
pytestmark = pytest.mark.skipif(not REALDATA.is_dir(), reason="../shared/realdata is not beside the repository")


def rows(name: str) -> list[list[str]]:
    with (REALDATA / name).open(newline="") as handle:
        return list(csv.reader(handle))


def cells_to_array(lines: list[list[str]], columns: list[int]) -> np.ndarray:
    return np.array([[float(r[c]) if c < len(r) and r[c] != "" else np.nan for c in columns] for r in lines])


def motive_by_layout(name: str) -> dict:
    """Line 1: key, value pairs; line 2 blank; lines 3-5 Type, Name, ID; line 6 kinds; line 7 axes; then data."""
    lines = rows(name)
    meta = dict(zip(lines[0][::2], lines[0][1::2]))
    types, names, kinds, axes = lines[2], lines[3], lines[5], lines[6]
    x_columns = [c for c in range(len(axes)) if types[c] == "Marker" and kinds[c] == "Position" and axes[c] == "X"]
    data = lines[7:]
    scale = {"Meters": 1.0, "Millimeters": 0.001}[meta["Length Units"]]
    xyz = cells_to_array(data, [c + i for c in x_columns for i in range(3)]).reshape(len(data), -1, 3) * scale
    return {"rate": float(meta["Export Frame Rate"]), "labels": [names[c] for c in x_columns], "xyz": xyz}


def nexus_by_layout(name: str) -> dict:
    """Line 1 'Trajectories'; line 2 the rate; line 3 names above X; line 4 axes; line 5 units (mm); then data."""
    lines = rows(name)
    names = lines[2]
    x_columns = [c for c in range(2, len(names)) if names[c]]
    assert {lines[4][c] for c in x_columns} == {"mm"}
    data = [r for r in lines[5:] if r and r[0]]
    xyz = cells_to_array(data, [c + i for c in x_columns for i in range(3)]).reshape(len(data), -1, 3) / 1000.0
    return {"rate": float(lines[1][0]), "labels": [names[c] for c in x_columns], "xyz": xyz}


def markers_json(tmp_path: Path, name: str) -> dict:
    out = tmp_path / f"{name}.json"
    result = CliRunner().invoke(app, ["markers", str(REALDATA / name), "--json", str(out)])
    assert result.exit_code == 0, result.output
    return json.loads(out.read_text())


@pytest.mark.parametrize(("name", "reader", "fmt", "unit"), [
    ("hmv-s16_sample_optitrack_take.csv", motive_by_layout, "Motive CSV 1.21", "Meters"),
    ("optitrack-converter_test_markers_enabled.csv", motive_by_layout, "Motive CSV 1.23", "Millimeters"),
    ("pyomeca_markers.csv", nexus_by_layout, "Vicon Nexus CSV", "mm"),
])  # fmt: skip
def test_markers_summary_agrees_with_a_reader_written_from_the_layout(tmp_path, name, reader, fmt, unit):
    truth = reader(name)
    data = markers_json(tmp_path, name)
    assert list(data) == ["format", "rate_hz", "frames", "unit_in_file", "markers"]
    assert (data["format"], data["rate_hz"], data["frames"], data["unit_in_file"]) == (
        fmt,
        truth["rate"],
        len(truth["xyz"]),
        unit,
    )
    assert [m["label"] for m in data["markers"]] == truth["labels"]
    seen = np.all(np.isfinite(truth["xyz"]), axis=2)
    for k, m in enumerate(data["markers"]):
        assert list(m) == ["label", "visible_frames", "mean_m"]
        assert m["visible_frames"] == int(seen[:, k].sum()), m["label"]
        if m["visible_frames"]:
            assert np.allclose(m["mean_m"], truth["xyz"][seen[:, k], k].mean(axis=0), atol=1e-6, rtol=0), m["label"]
        else:
            assert m["mean_m"] is None


def test_real_files_hold_what_their_layouts_say(tmp_path):
    """Figures read off the files themselves, so a reader that drifts with them still fails."""
    take = markers_json(tmp_path, "hmv-s16_sample_optitrack_take.csv")
    assert take["frames"] == 250 and take["rate_hz"] == 120.0
    assert [m["label"] for m in take["markers"]][:4] == ["Unlabeled:108", "Unlabeled:110", "Unlabeled:111",
                                                         "Rigid Body 1:Marker1"]  # fmt: skip
    assert sum(m["visible_frames"] == 0 for m in take["markers"]) == 3
    motive3 = markers_json(tmp_path, "optitrack-converter_test_markers_enabled.csv")
    assert (motive3["frames"], motive3["rate_hz"], len(motive3["markers"])) == (1353, 360.0, 18)
    nexus = markers_json(tmp_path, "pyomeca_markers.csv")
    labels = [m["label"] for m in nexus["markers"]]
    assert labels[0] == "boite:gauche_ext" and "Daphnee:ASISr" in labels and nexus["frames"] == 580


def test_devices_only_export_is_refused_naming_what_it_holds(tmp_path):
    result = CliRunner().invoke(app, ["markers", str(REALDATA / "pyomeca_analogs.csv"), "--json",
                                      str(tmp_path / "x.json")])  # fmt: skip
    assert result.exit_code == 2 and not (tmp_path / "x.json").exists()
    assert (
        "pyomeca_analogs.csv: Vicon Nexus CSV without a Trajectories section; it holds Devices (38 channels at "
        "2000 Hz) (analog only)" in result.output
    )


def test_robot_config_short_names_on_a_nexus_export(tmp_path):
    """A config naming 'gauche_ext' (short) and 'Daphnee:ASISr' (full) finds both in the Nexus labels."""
    import yaml

    config = {"name": "box", "urdf": str(Path(__file__).resolve().parents[2] / "tests" / "data" / "strider" /
                                          "strider.urdf"),
              "base_link": "pelvis", "joint_states_topic": "/joint_states",
              "markers": {"list": [{"name": "gauche_ext", "link": "pelvis", "xyz": [0, 0, 0]},
                                   {"name": "Daphnee:ASISr", "link": "pelvis", "xyz": [0, 0, 0]},
                                   {"name": "nowhere", "link": "pelvis", "xyz": [0, 0, 0]}]}}  # fmt: skip
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(config))
    result = CliRunner().invoke(app, ["markers", str(REALDATA / "pyomeca_markers.csv"), "--robot",
                                      str(tmp_path / "robot.yaml")])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "2 of 3 configured markers found" in result.output
    assert "found:   gauche_ext (as boite:gauche_ext), Daphnee:ASISr" in result.output
    assert "missing: nowhere" in result.output
