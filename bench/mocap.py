"""The `mocap` part: motion-capture accuracy over seeds, on data wolfcal did not generate
(tests/mocap_session.py: the strider robot and its Vicon-style marker layout, yourdfpy kinematics,
Markers by mcap_ros2, C3D by ezc3d).

Per seed: 25 still poses, 0.025 rad rms leg offsets, 0.3 mm marker noise, 3 % occluded, 1 % reflections 2-20 mm,
mounts off 1 mm; `wolfcal fit --system mocap --free leg` on the Markers recording and on the joint states + C3D
(clock offset estimated), and on the Markers recording with the config's marker places set to the true ones
("known mounts": the mounts' 1 mm prior then centres on the truth). Reported per run:
  sole mm / deg    largest sole error over the 25 poses and both soles: position [mm] and rotation [deg] of the
                   model's T_pelvis_sole (readings + fitted offsets) against the true one
  roll deg         largest |fitted - true| ankle-roll offset [deg]
  mount deg        what the true mount errors of the foot markers predict for it: the rotation about the ankle-roll
                   axis that fits them best, sum((a x r_k) . m_k) / sum(|a x r_k|^2) (r_k: marker in the foot frame,
                   m_k: its true mount error, a: the roll axis), the larger of the two feet [deg]
  max |z|          largest |estimate - truth| / reported std over the leg offsets and the marker mounts
  flagged          reflections flagged / reflections, and other markers left out
  clock ms         |estimated - true| C3D clock offset [ms]
Per source and figure the mean and max over the seeds; `pairs`: (fitted - true roll, mount rotation) [rad].
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from mocap_session import STRIDER, Session, known_mounts_config, mount_rotation, sole_errors, write_session  # noqa: E402

from wolfcal.cli import app  # noqa: E402


def judge(session: Session, fit_dir: Path, known: bool) -> dict:
    """The figures of the module docstring for one fit folder (`known`: fitted with the true marker places)."""
    data = yaml.safe_load((fit_dir / "result.yaml").read_text())
    fitted, z = {}, []
    for p in data["parameters"]:
        name, kind = p["name"].rsplit(".", 1) if p["name"].endswith(".offset") else (p["name"], "")
        if kind == "offset":
            fitted[name] = p["value"]
            z.append((p["value"] - session.offsets[name]) / p["std"])
        elif p["name"].startswith("marker."):
            _, marker, axis = p["name"].split(".")
            true = 0.0 if known else session.mounts[marker]["xyz".index(axis)]
            z.append((p["value"] - true) / p["std"])
    mm, deg = sole_errors(session, fitted)
    block = data["blocks"][0]
    left_out = {(e["sample"], e["marker"]) for e in block["left_out_markers"]}
    roll = {side: fitted[f"{side}_ankle_roll"] - session.offsets[f"{side}_ankle_roll"] for side in "lr"}
    predicted = {side: mount_rotation(session, side) for side in "lr"}
    clock = list(block["mocap_clock_offset_s"].values())
    return {"sole_mm": mm, "sole_deg": deg, "roll_deg": float(np.rad2deg(max(map(abs, roll.values())))),
            "mount_deg": float(np.rad2deg(max(map(abs, predicted.values())))),
            "pairs": [(roll[side], predicted[side]) for side in "lr"], "max_z": float(np.max(np.abs(z))),
            "flagged": len(session.reflections & left_out), "reflections": len(session.reflections),
            "other": len(left_out - session.reflections),
            "clock_ms": abs(clock[0] - session.c3d_offset_s) * 1000 if clock else None}  # fmt: skip


def run(seed: int, folder: Path) -> dict[str, dict]:
    session = write_session(folder, seed)
    fit = ["--system", "mocap", "--free", "leg"]
    config = str(STRIDER / "robot.yaml")
    runs = {
        "markers": [str(folder / "markers.mcap"), "--robot", config],
        "c3d": [str(folder / "joints.mcap"), "--mocap", str(folder / "markers.c3d"), "--robot", config],
        "known": [str(folder / "markers.mcap"), "--robot", str(known_mounts_config(session, folder))],
    }
    out = {}
    for name, args in runs.items():
        result = CliRunner().invoke(app, ["fit", *args, *fit, "--out", str(folder / name)])
        if result.exit_code != 0:
            raise SystemExit(f"seed {seed} {name}: {result.output}")
        out[name] = judge(session, folder / name, known=name == "known")
    return out


def mocap(seeds: int, say) -> dict:
    """Per seed and source (markers, c3d, known), the figures of the module docstring; per source the mean and max
    of each over the seeds, and how the ankle-roll error follows the mounts' rotation (correlation, RMS [deg])."""
    rows = []
    for seed in range(seeds):
        with tempfile.TemporaryDirectory() as tmp:
            for name, r in run(seed, Path(tmp)).items():
                rows.append(r | {"source": name, "seed": seed})
                say(f"mocap seed {seed} {name}: sole {r['sole_mm']:.3f} mm, max |z| {r['max_z']:.2f}")
    summary: dict[str, dict] = {}
    for source in ("markers", "c3d", "known"):
        mine = [r for r in rows if r["source"] == source]
        figures = {}
        for key in ("sole_mm", "sole_deg", "roll_deg", "max_z"):
            v = np.array([r[key] for r in mine])
            figures[key] = {"mean": float(v.mean()), "max": float(v.max())}
        pairs = np.rad2deg([pair for r in mine for pair in r["pairs"]])
        figures["roll_vs_mount_correlation"] = float(np.corrcoef(pairs.T)[0, 1]) if len(pairs) > 1 else None
        figures["roll_vs_mount_rms_deg"] = float(np.sqrt(np.mean(np.diff(pairs) ** 2)))
        summary[source] = figures
    for r in rows:
        r["pairs"] = np.asarray(r["pairs"]).tolist()
    return {"seeds": seeds, "rows": rows, "summary": summary}
