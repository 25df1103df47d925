"""Motion-capture files in the layouts real systems write, by independent writers: Motive CSV 1.21 / 1.23 / 1.24
and Vicon Nexus CSV as text (mocap_layouts.py), C3D by ezc3d and byte by byte (c3d_layout.py) for what ezc3d cannot
write (DEC and SGI processor formats, NUL-padded units, duplicated parameters, frame counts past 16 bits). Labels
as the file writes them, short names from the robot config, and no traceback from any file."""

from __future__ import annotations

import json
from pathlib import Path

import ezc3d
import numpy as np
import pytest
from c3d_layout import C3DLayout, Parameter
from mocap_layouts import marker, motive_csv, rigid_body, rigid_body_marker, vicon_csv
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.errors import WolfcalError
from wolfcal.io.mocap_files import read_mocap_file
from wolfcal.io.mocap_labels import match_names
from wolfcal.io.mocap_trajectories import NoMarkers

RNG = np.random.default_rng(7)


def track(frames: int, scale: float = 1.0) -> np.ndarray:
    """(F, 3) positions rounded to 1e-6 of the unit, as Motive prints them."""
    return np.round(RNG.uniform(-2, 2, (frames, 3)) * scale, 6)


def test_motive_1_21_unnamed_header_rows_rigid_body_and_unlabeled_columns(tmp_path):
    """The 1.21 layout of the hmv-s16 take: header rows with empty first cells, a rigid body (rotation, position,
    error) and its model markers before the measured markers; only the measured 'Marker' columns are read."""
    f = 30
    measured = {"Rigid Body 1:Marker1": track(f), "Unlabeled:108": track(f)}
    measured["Unlabeled:108"][4:7] = np.nan  # blank cells: not seen
    blocks = [
        rigid_body("Rigid Body 1", track(f + 0)[:, [0, 1, 2, 0]], track(f), np.full(f, 0.0001)),
        rigid_body_marker("Rigid Body 1_1", track(f), np.ones(f)),
    ] + [marker(n, v) for n, v in measured.items()]
    (tmp_path / "take.csv").write_text(motive_csv("1.21", 120.0, "Meters", blocks, first_frame=0))
    traj = read_mocap_file(tmp_path / "take.csv")
    assert traj.labels == ["Rigid Body 1:Marker1", "Unlabeled:108"] and traj.format == "Motive CSV 1.21"
    assert traj.rate_hz == 120.0 and traj.unit == "Meters"
    assert np.allclose(traj.xyz[:, 0], measured["Rigid Body 1:Marker1"], atol=1e-12)
    assert np.isnan(traj.xyz[4:7, 1]).all() and np.isfinite(traj.xyz[7, 1]).all()
    assert traj.times_ns[1] == 8_333_333 and traj.times_ns[-1] == round(29 / 120 * 1e9)


@pytest.mark.parametrize(("version", "unit", "scale"), [("1.23", "Millimeters", 0.001), ("1.24", "Centimeters", 0.01)])
def test_motive_3_layouts_named_rows_rounded_times_and_prefixed_labels(tmp_path, version, unit, scale):
    """Motive 3 writes ',Type', ',Name', ',ID' (1.24: and a TimeCode column) and rounds the time column to 1 ms:
    times come from frame / Export Frame Rate (frame 7 at 360 Hz: 19.444 ms, the column says 19 ms). Markers of
    different assets with one short name stay apart (the reader once cut 'Box:' and 'Left:' and merged them)."""
    f = 40
    names = ["Box:Marker1", "Left:Marker1", "Right:Marker1", "Unlabeled 1036"]
    values = {n: track(f, 1000.0) for n in names}
    values["Left:Marker1"][10, :] = np.nan
    blocks = [marker(n, v) for n, v in values.items()]
    (tmp_path / "m.csv").write_text(motive_csv(version, 360.0, unit, blocks, first_frame=78593))
    traj = read_mocap_file(tmp_path / "m.csv")
    assert traj.labels == names and traj.format == f"Motive CSV {version}" and traj.unit == unit
    assert traj.times_ns[7] == round(7 / 360 * 1e9) == 19_444_444
    for k, n in enumerate(names):
        assert np.allclose(traj.xyz[:, k], values[n] * scale, atol=1e-12, equal_nan=True), n
    match = match_names("m.csv", ["Box:Marker1", "Unlabeled 1036"], traj.labels)
    assert match.columns == [0, 3] and match.extra == ["Left:Marker1", "Right:Marker1"]
    with pytest.raises(
        WolfcalError,
        match=r"'Marker1' matches 3 labels \('Box:Marker1', 'Left:Marker1', "
        r"'Right:Marker1'\); name it in full",
    ):
        match_names("m.csv", ["Marker1"], traj.labels)


def test_short_names_match_an_unambiguous_prefixed_label():
    labels = ["robot:r_foot_fl", "robot:torso_ul", "wand:tip", "torso_ul_spare"]
    match = match_names("f", ["r_foot_fl", "torso_ul", "robot:torso_ul_x"], labels)
    assert match.found == ["r_foot_fl", "torso_ul"] and match.columns == [0, 1]
    assert match.missing == ["robot:torso_ul_x"] and match.extra == ["wand:tip", "torso_ul_spare"]
    exact = match_names("f", ["tip"], ["tip", "wand:tip"])  # the label equal to the name wins
    assert exact.columns == [0]


def test_vicon_nexus_devices_then_trajectories_with_subject_prefixes(tmp_path):
    """pyomeca's exports: the C3D and the CSV of one trial both label 'boite:gauche_ext'; a Devices section before
    the Trajectories is skipped; a Devices-only export says it holds analog channels only."""
    f = 25
    xyz = np.round(RNG.uniform(-900, 900, (f, 2, 3)), 3)
    xyz[3, 1] = np.nan
    labels = ["boite:gauche_ext", "Daphnee:ASISr"]
    (tmp_path / "v.csv").write_text(vicon_csv(100.0, labels, xyz, devices=RNG.normal(0, 0.01, (f * 10, 3))))
    traj = read_mocap_file(tmp_path / "v.csv")
    assert traj.labels == labels and traj.format == "Vicon Nexus CSV" and traj.unit == "mm"
    assert np.allclose(traj.xyz, xyz / 1000.0, atol=1e-12, equal_nan=True)
    assert traj.times_ns[-1] == 240_000_000
    text = vicon_csv(100.0, labels, xyz, devices=RNG.normal(0, 0.01, (f * 10, 3)))
    (tmp_path / "d.csv").write_text(text[: text.index("Trajectories")])
    with pytest.raises(
        NoMarkers,
        match=r"d.csv: Vicon Nexus CSV without a Trajectories section; it holds Devices "
        r"\(3 channels at 1000 Hz\) \(analog only\)",
    ):
        read_mocap_file(tmp_path / "d.csv")


def points(frames: int, k: int) -> np.ndarray:
    p = np.round(RNG.uniform(-1500, 1500, (frames, k, 3)), 1)
    p[2, 1] = np.nan  # one invalid point
    return p


@pytest.mark.parametrize("processor", ["intel", "dec", "sgi"])
@pytest.mark.parametrize("float_data", [True, False])
def test_c3d_processor_formats_and_storage(tmp_path, processor, float_data):
    """Intel, DEC (VAX floats) and SGI/MIPS (big-endian) files, float or integer (scale 0.1 mm) points, written
    byte by byte: positions to the storage's precision, invalid points (residual < 0) NaN. Checked by hand on the
    c3d.org sample01 trial in its six variants (Eb015pi/pr/si/sr/vi/vr.c3d, not shipped here): the same 26 labels
    (of 48 in POINT:LABELS, POINT:USED 26), the same invalid points and positions within 1e-7 m across them."""
    p = points(20, 3)
    layout = C3DLayout(p, rate=250.0, labels=["LASI", "RASI", "LPSI"], processor=processor, float_data=float_data)
    (tmp_path / "a.c3d").write_bytes(layout.to_bytes())
    traj = read_mocap_file(tmp_path / "a.c3d")
    kind = {"intel": "Intel", "dec": "DEC", "sgi": "SGI/MIPS"}[processor]
    assert traj.format == f"C3D ({kind}, {'float' if float_data else 'integer'})" and traj.rate_hz == 250.0
    assert traj.labels == ["LASI", "RASI", "LPSI"]
    tolerance = 2e-7 if float_data else 1e-9  # float32 of 1500 mm: 1e-4 mm; integers: exact multiples of 0.1 mm
    assert np.allclose(traj.xyz, p / 1000.0, atol=tolerance, equal_nan=True)
    assert np.isnan(traj.xyz[2, 1]).all() and traj.times_ns[1] == 4_000_000


def test_c3d_odd_parameters_real_writers_use(tmp_path):
    """Each a file a real system wrote and the former reader refused or crashed on: units 'mm\\0\\0' (Motion
    Analysis), one unit per point (Optotrak), a parameter defined twice in a group (Nexus 1.4 Plug-in Gait), 5
    labels for 3 points (labels past POINT:USED), an analog header count that disagrees with ANALOG:USED
    (MotionMonitor), no POINT:LABELS at all."""
    p = points(10, 3)
    labels = ["a", "b", "c"]
    cases = {
        "nul_units": C3DLayout(p, labels=labels, units="mm\0\0"),
        "per_point": C3DLayout(p, labels=labels, units=["mm", "mm", "mm"]),
        "twice": C3DLayout(p, labels=labels, extra=[Parameter("SUBJECTS", "NAMES", ["s"]),
                                                    Parameter("SUBJECTS", "NAMES", ["s"])]),
        "past_used": C3DLayout(p, labels=labels + ["d", "e"]),
        "analog_header": C3DLayout(p, labels=labels, analog=RNG.normal(size=(20, 2)), analog_per_frame=2,
                                   header_analog=6),
    }  # fmt: skip
    for name, layout in cases.items():
        (tmp_path / f"{name}.c3d").write_bytes(layout.to_bytes())
        traj = read_mocap_file(tmp_path / f"{name}.c3d")
        assert traj.labels == labels, name
        assert np.allclose(traj.xyz, p / 1000.0, atol=2e-7, equal_nan=True), name
    (tmp_path / "unnamed.c3d").write_bytes(C3DLayout(p, skip={"POINT:LABELS"}).to_bytes())
    assert read_mocap_file(tmp_path / "unnamed.c3d").labels == ["point 1", "point 2", "point 3"]
    (tmp_path / "m.c3d").write_bytes(C3DLayout(p, labels=labels, units=["mm", "m", "mm"]).to_bytes())
    mixed = read_mocap_file(tmp_path / "m.c3d")
    assert np.allclose(mixed.xyz[:, 1], p[:, 1], atol=1e-4, equal_nan=True)  # metres as written


@pytest.mark.parametrize("frames", [65535, 70000])
def test_c3d_frame_counts_past_16_bits(tmp_path, frames):
    """65535 frames (POINT:FRAMES as the unsigned word 0xFFFF) were read as none by the former reader; 70000
    frames: the header's 16-bit counter says 65535, TRIAL:ACTUAL_END_FIELD the rest."""
    p = np.round(RNG.uniform(-1000, 1000, (frames, 1, 3)), 1)
    (tmp_path / "long.c3d").write_bytes(C3DLayout(p, labels=["m"]).to_bytes())
    traj = read_mocap_file(tmp_path / "long.c3d")
    assert traj.xyz.shape == (frames, 1, 3) and np.allclose(traj.xyz[-1, 0], p[-1, 0] / 1000.0, atol=2e-7)


def test_c3d_labels2_written_by_ezc3d_and_units_from_the_file(tmp_path):
    """300 points: ezc3d writes labels 256-300 in POINT:LABELS2."""
    labels = [f"m{i}" for i in range(300)]
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = labels
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    pts = np.ones((4, 300, 3))
    pts[:3] = RNG.uniform(-1, 1, (3, 300, 3))
    c["data"]["points"] = pts
    c.write(str(tmp_path / "many.c3d"))
    traj = read_mocap_file(tmp_path / "many.c3d")
    assert traj.labels == labels and traj.unit == "m"
    assert np.allclose(traj.xyz[1, 299], pts[:3, 299, 1], atol=1e-6)


def test_c3d_without_markers_says_what_it_holds(tmp_path):
    """A force-plate file (the former reader blamed its POINT:UNITS) and a markerless system's rotations."""
    analog = C3DLayout(np.zeros((10, 0, 3)), labels=[], analog=RNG.normal(size=(100, 4)), analog_per_frame=10,
                       extra=[Parameter("FORCE_PLATFORM", "USED", 1)])  # fmt: skip
    (tmp_path / "plates.c3d").write_bytes(analog.to_bytes())
    with pytest.raises(
        NoMarkers,
        match=r"plates.c3d: no marker trajectories in this C3D file \(POINT:USED 0\); "
        r"it holds 4 analog channel\(s\) at 1000 Hz \(analog only\), 1 force plate",
    ):
        read_mocap_file(tmp_path / "plates.c3d")


def garbage_files(tmp_path):
    """Files a user may pass by mistake or that broke on the way: (name, bytes)."""
    good = C3DLayout(points(10, 2), labels=["a", "b"]).to_bytes()
    motive = motive_csv("1.23", 100.0, "Millimeters", [marker("a", track(5))])
    yield "empty.c3d", b""
    yield "text.c3d", b"Format Version,1.23\n"
    yield "truncated.c3d", good[:700]
    yield "params_cut.c3d", good[:512] + bytes(300)
    yield "random.c3d", bytes([2, 0x50]) + RNG.integers(0, 256, 3000, dtype=np.uint8).tobytes()
    yield "binary.csv", bytes(range(256)) * 4
    yield "empty.csv", b""
    yield "no_units.csv", motive.replace("Millimeters", "").encode()
    yield "bad_number.csv", motive.replace("\n3,", "\nthree,").encode()
    yield "cut_header.csv", "\n".join(motive.splitlines()[:4]).encode()
    yield "nexus_cut.csv", b"Trajectories\n100\n"
    yield "wide.csv", motive.replace(",X,Y,Z", ",X,Q,Z").encode()


def test_no_traceback_from_any_file(tmp_path):
    """Damaged or wrong files: `wolfcal markers` exits 2 with one line naming the file, never a traceback."""
    runner = CliRunner()
    for name, data in garbage_files(tmp_path):
        (tmp_path / name).write_bytes(data)
        result = runner.invoke(app, ["markers", str(tmp_path / name)])
        assert result.exit_code == 2, (name, result.output, result.exception)
        assert f"{name}:" in result.output and "Traceback" not in result.output, (name, result.output)


def test_markers_command_json_schema_and_robot_comparison(tmp_path):
    """`wolfcal markers FILE --json OUT --robot R` on a Motive 1.23 export of Wolfgang markers under an asset prefix:
    the JSON holds exactly the documented keys, markers in file order, positions in metres; the report lists the
    configured markers found (by their short names), the missing ones and the extra labels."""
    f = 12
    foot = track(f, 1000.0)
    foot[:5] = np.nan
    blocks = [marker("wolfgang:r_foot_fl", foot), marker("Unlabeled 1036", track(f, 1000.0)),
              marker("wolfgang:torso_ul", track(f, 1000.0))]  # fmt: skip
    (tmp_path / "take.csv").write_text(motive_csv("1.23", 240.0, "Millimeters", blocks))
    runner = CliRunner()
    wolfgang = str(Path(__file__).resolve().parents[2] / "configs" / "wolfgang")
    result = runner.invoke(app, ["markers", str(tmp_path / "take.csv"), "--json", str(tmp_path / "m.json"),
                                 "--robot", wolfgang])  # fmt: skip
    assert result.exit_code == 0, result.output
    data = json.loads((tmp_path / "m.json").read_text())
    assert data == {"format": "Motive CSV 1.23", "rate_hz": 240.0, "frames": f, "unit_in_file": "Millimeters",
                    "markers": [{"label": b.name, "visible_frames": int(np.isfinite(b.values[:, 0]).sum()),
                                 "mean_m": pytest.approx(np.nanmean(b.values, axis=0) / 1000.0, abs=1e-12)}
                                for b in blocks]}  # fmt: skip
    assert "2 of 14 configured markers found" in result.output
    assert "found:   r_foot_fl (as wolfgang:r_foot_fl), torso_ul (as wolfgang:torso_ul)" in result.output
    assert (
        "missing: r_foot_fr, " in result.output
        and "extra labels (not in the config, ignored by a fit): Unlabeled 1036" in result.output
    )
    # an existing JSON is replaced only with --force, the input never; an ambiguous short name is an error
    again = ["markers", str(tmp_path / "take.csv"), "--json", str(tmp_path / "m.json")]
    result = runner.invoke(app, again)
    assert result.exit_code == 2 and "m.json exists; pass --force to replace it" in result.output
    assert runner.invoke(app, [*again, "--force"]).exit_code == 0
    result = runner.invoke(
        app, ["markers", str(tmp_path / "take.csv"), "--json", str(tmp_path / "take.csv"), "--force"]
    )
    assert result.exit_code == 2 and "is an input of the command" in result.output
    blocks.append(marker("spare:torso_ul", track(f, 1000.0)))
    (tmp_path / "two.csv").write_text(motive_csv("1.23", 240.0, "Millimeters", blocks))
    result = runner.invoke(app, ["markers", str(tmp_path / "two.csv"), "--robot", wolfgang])
    assert result.exit_code == 2
    assert "'torso_ul' matches 2 labels ('wolfgang:torso_ul', 'spare:torso_ul')" in result.output


def test_a_c3d_cut_in_its_data_is_read_with_a_note(tmp_path):
    data = C3DLayout(points(40, 2), labels=["a", "b"]).to_bytes()
    (tmp_path / "cut.c3d").write_bytes(data[: len(data) - 10 * 2 * 16 - 5])  # 10.3 frames short
    result = CliRunner().invoke(app, ["markers", str(tmp_path / "cut.c3d")])
    assert result.exit_code == 0, result.output
    assert "29 frames at 100 Hz" in result.output
    assert "note: the data section holds 29 of the 40 frames POINT:FRAMES announces" in result.output


def test_motive_export_of_rigid_bodies_only_says_so(tmp_path):
    """Motive exports the rigid bodies alone when markers are unticked in the export dialog: no measured marker."""
    f = 5
    blocks = [rigid_body("Rigid Body 1", track(f + 0)[:, [0, 1, 2, 0]], track(f), np.full(f, 0.0001)),
              rigid_body_marker("Rigid Body 1_1", track(f), np.ones(f))]  # fmt: skip
    (tmp_path / "rb.csv").write_text(motive_csv("1.21", 120.0, "Meters", blocks))
    result = CliRunner().invoke(app, ["markers", str(tmp_path / "rb.csv")])
    assert result.exit_code == 2
    assert (
        "rb.csv: Motive CSV 1.21: no Marker position columns; it holds Rigid Body, Rigid Body Marker only; "
        "export the markers" in result.output
    )


def test_motive_export_in_the_windows_code_page(tmp_path):
    """A take and asset named with an accent, as Motive on a Windows computer in Western Europe writes them
    (Windows-1252, not UTF-8): the labels keep the accent."""
    text = motive_csv("1.23", 100.0, "Millimeters", [marker("Séance:torso_ul", track(4, 1000.0))])
    (tmp_path / "cp.csv").write_bytes(text.replace("take", "Séance 1").encode("cp1252"))
    assert read_mocap_file(tmp_path / "cp.csv").labels == ["Séance:torso_ul"]
