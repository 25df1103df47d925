"""The motion-capture must-show over seeds, on data wolfcal did not generate (tests/mocap_session.py: the strider
robot and its Vicon-style marker layout, yourdfpy kinematics, Markers by mcap_ros2, C3D by ezc3d).

Per seed: 25 still poses, 0.025 rad rms leg offsets, 0.3 mm marker noise, 3 % occluded, 1 % reflections 2-20 mm,
mounts off 1 mm; `wolfcal fit --system mocap --free leg` on the Markers recording and on the joint states + C3D
(clock offset estimated). Reported per run:
  sole mm / deg    largest sole error over the 25 poses and both soles: position [mm] and rotation [deg] of the
                   model's T_pelvis_sole (readings + fitted offsets) against the true one
  roll deg         largest |fitted - true| ankle-roll offset [deg]
  max |z|          largest |estimate - truth| / reported std over the leg offsets and the marker mounts
  flagged          reflections flagged / reflections, and other markers left out
  clock ms         |estimated - true| C3D clock offset [ms]
Run: python bench/bench_mocap_other_robot.py [--seeds 5]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from mocap_session import STRIDER, Session, write_session  # noqa: E402

from wolfcal.cli import app  # noqa: E402


def sole_errors(session: Session, fitted: dict[str, float]) -> tuple[float, float]:
    """Largest sole position [mm] and rotation [deg] error over the still poses and both soles."""
    true, model = session.sole_poses(None), session.sole_poses(fitted)
    mm, deg = 0.0, 0.0
    for sole in true:
        E = np.linalg.inv(true[sole]) @ model[sole]
        mm = max(mm, float(np.max(np.linalg.norm(E[:, :3, 3], axis=1))) * 1000)
        cos = np.clip((np.trace(E[:, :3, :3], axis1=1, axis2=2) - 1) / 2, -1, 1)
        deg = max(deg, float(np.rad2deg(np.max(np.arccos(cos)))))
    return mm, deg


def judge(session: Session, fit_dir: Path) -> dict:
    """The figures of the module docstring for one fit folder."""
    data = yaml.safe_load((fit_dir / "result.yaml").read_text())
    fitted, z = {}, []
    for p in data["parameters"]:
        name, kind = p["name"].rsplit(".", 1) if p["name"].endswith(".offset") else (p["name"], "")
        if kind == "offset":
            fitted[name] = p["value"]
            z.append((p["value"] - session.offsets[name]) / p["std"])
        elif p["name"].startswith("marker."):
            _, marker, axis = p["name"].split(".")
            z.append((p["value"] - session.mounts[marker]["xyz".index(axis)]) / p["std"])
    mm, deg = sole_errors(session, fitted)
    block = data["blocks"][0]
    left_out = {(e["sample"], e["marker"]) for e in block["left_out_markers"]}
    roll = max(abs(fitted[j] - session.offsets[j]) for j in ("l_ankle_roll", "r_ankle_roll"))
    clock = list(block["mocap_clock_offset_s"].values())
    return {"sole_mm": mm, "sole_deg": deg, "roll_deg": float(np.rad2deg(roll)), "max_z": float(np.max(np.abs(z))),
            "flagged": len(session.reflections & left_out), "reflections": len(session.reflections),
            "other": len(left_out - session.reflections),
            "clock_ms": abs(clock[0] - session.c3d_offset_s) * 1000 if clock else None}  # fmt: skip


def run(seed: int, folder: Path) -> dict[str, dict]:
    session = write_session(folder, seed)
    robot = ["--robot", str(STRIDER / "robot.yaml"), "--system", "mocap", "--free", "leg"]
    runs = {"markers": [str(folder / "markers.mcap")],
            "c3d": [str(folder / "joints.mcap"), "--mocap", str(folder / "markers.c3d")]}
    out = {}
    for name, args in runs.items():
        result = CliRunner().invoke(app, ["fit", *args, *robot, "--out", str(folder / name)])
        if result.exit_code != 0:
            raise SystemExit(f"seed {seed} {name}: {result.output}")
        out[name] = judge(session, folder / name)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    rows = []
    print(f"{'seed':>4} {'source':>7} {'sole mm':>8} {'sole deg':>8} {'roll deg':>8} {'max |z|':>7} {'flagged':>8} "
          f"{'other':>5} {'clock ms':>8}")
    for seed in range(args.seeds):
        with tempfile.TemporaryDirectory() as tmp:
            for name, r in run(seed, Path(tmp)).items():
                rows.append(r)
                clock = "-" if r["clock_ms"] is None else f"{r['clock_ms']:.2f}"
                print(f"{seed:>4} {name:>7} {r['sole_mm']:8.3f} {r['sole_deg']:8.3f} {r['roll_deg']:8.3f} "
                      f"{r['max_z']:7.2f} {r['flagged']:>4}/{r['reflections']:<3} {r['other']:>5} {clock:>8}",
                      flush=True)
    for key in ("sole_mm", "sole_deg", "roll_deg", "max_z"):
        v = np.array([r[key] for r in rows])
        print(f"{key}: mean {v.mean():.3f}, max {v.max():.3f}")


if __name__ == "__main__":
    main()
