"""The motion-capture fit on a Motive CSV 1.23 export of a simulated session reaches the accuracy of the fit on the
C3D of the same session. The CSV is written by the independent Motive layout writer (mocap_layouts.py) from the
marker frames ezc3d reads out of the session's C3D, with the markers labelled 'wolfgang:<name>' as Motive names an
asset's markers: the robot config's short names must find them."""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
import yaml
from mocap_layouts import marker, motive_csv
from typer.testing import CliRunner

from wolfcal.cli import app

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"


def c3d_to_motive(c3d_path: Path, csv_path: Path, asset: str) -> None:
    """The C3D's frames as a Motive 1.23 export in millimetres, invalid points as blank cells."""
    c = ezc3d.c3d(str(c3d_path))
    labels = list(c["parameters"]["POINT"]["LABELS"]["value"])
    rate = float(c["parameters"]["POINT"]["RATE"]["value"][0])
    assert c["parameters"]["POINT"]["UNITS"]["value"][0].strip() == "mm"
    points = np.transpose(c["data"]["points"][:3], (2, 1, 0))  # (F, K, 3) [mm], NaN where invalid
    blocks = [marker(f"{asset}:{label}", points[:, k]) for k, label in enumerate(labels)]
    csv_path.write_text(motive_csv("1.23", rate, "Millimeters", blocks))


@pytest.mark.slow
def test_motive_csv_export_fits_as_well_as_the_c3d(tmp_path):
    runner = CliRunner()
    out = tmp_path / "s.mcap"
    result = runner.invoke(app, ["simulate", "--robot", str(WOLFGANG), "--system", "mocap", "--offsets", "legs",
                                 "--samples", "25", "--seed", "5", "--out", str(out)])  # fmt: skip
    assert result.exit_code == 0, result.output
    truth = yaml.safe_load((tmp_path / "s.truth.yaml").read_text())["truth"]["offsets"]
    c3d_to_motive(tmp_path / "s.c3d", tmp_path / "s.csv", "wolfgang")
    fits = {}
    for name in ("c3d", "csv"):
        args = ["fit", str(out), "--robot", str(WOLFGANG), "--system", "mocap", "--free", "leg"]
        result = runner.invoke(app, [*args, "--mocap", str(tmp_path / f"s.{name}"), "--out", str(tmp_path / name)])
        assert result.exit_code == 0, result.output
        data = yaml.safe_load((tmp_path / name / "result.yaml").read_text())
        fits[name] = {p["name"]: (p["value"], p["std"]) for p in data["parameters"] if p["name"].endswith(".offset")}
        assert data["mocap_clock_offset_s"][f"s.{name}"] == pytest.approx(
            yaml.safe_load((tmp_path / "s.truth.yaml").read_text())["c3d_clock_offset_s"], abs=0.005
        )
    assert fits["csv"].keys() == fits["c3d"].keys() and len(fits["csv"]) >= 10
    for param, (value, std) in fits["csv"].items():
        error = value - truth.get(param[: -len(".offset")], 0.0)
        assert abs(error) < 3.5 * std, (param, error, std)
        c3d_value, c3d_std = fits["c3d"][param]
        assert std == pytest.approx(c3d_std, rel=0.02), param
        assert abs(value - c3d_value) < 0.05 * std, (param, value, c3d_value, std)  # the same data to 1e-6 mm
    rms = {n: float(np.sqrt(np.mean([(v - truth.get(p[:-7], 0.0)) ** 2 for p, (v, _) in f.items()])))
           for n, f in fits.items()}  # fmt: skip
    assert rms["csv"] == pytest.approx(rms["c3d"], rel=0.02, abs=1e-5), rms
