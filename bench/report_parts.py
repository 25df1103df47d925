"""The docs' sections of the harness's longer parts (`bench/report.py` calls these): solve time, the servo bus and
the venue's robot time for docs/performance.md; std coverage on recordings, the floor check, planned poses, every
system on one session, motion capture and the field lines for docs/accuracy.md. A part missing from the results
leaves its section out."""

from __future__ import annotations


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head), *("| " + " | ".join(r) + " |" for r in rows), ""]


def _when(part: dict) -> str:
    return f"taken {part['taken']}, load average {part['load_average']:.1f} at the end, {part['seconds']:.0f} s"


def performance_parts(results: dict) -> list[str]:
    lines: list[str] = []
    if "solve" in results:
        s = results["solve"]
        rows = [[r["system"], str(r["samples"]), str(r["corners"]), str(r["unknowns"]), f"{r['wall']:.3f} s",
                 f"{r['cpu']:.3f} s", str(r["linearisations"])] for r in s["rows"]]  # fmt: skip
        lines += [
            "## Solve time",
            "",
            "The fit's solve alone (no reading, no detection: corners projected at a simulated truth), --free leg, "
            f"BLAS on one thread as in the `wolfcal` command; median of 3. {_when(s)}.",
            "",
            *_table(["system", "samples", "corners", "unknowns", "wall", "CPU", "linearisations"], rows),
        ]
    if "bus" in results or "capture" in results:
        lines += ["## Servo bus and capture", ""]
        if "bus" in results:
            b = results["bus"]
            lines += [
                f"Sync reads (position + velocity) of {b['servos']} servos through dynamixel-sdk against the bus "
                f"emulator on a pseudo-terminal, {b['reads']} reads: {b['rate_hz']:.0f} reads/s, per read median "
                f"{b['median_ms']:.2f} ms, 99th percentile {b['p99_ms']:.2f} ms. A real bus at 1 Mbaud is bound by "
                f"its USB latency timer (set it to 1 ms). {_when(b)}.",
                "",
            ]
        if "capture" in results:
            c = results["capture"]
            lines += [
                f"A scripted capture of the robot's poses against the emulator and the simulated camera: "
                f"{c['samples']} samples in {c['wall']:.1f} s (moves at {c['velocity_rad_s']} rad/s, stillness "
                f"window {c['settle_s']} s); from the robot at rest to the sample on disk: median "
                f"{c['rest_to_sample_median_s']:.2f} s, max {c['rest_to_sample_max_s']:.2f} s. {_when(c)}.",
                "",
            ]
    if "venue" in results:
        v = results["venue"]
        after = v["after"]
        rows = [[name, f"{seconds:.1f} s"] for name, seconds in v["before"].items()]
        lines += [
            "## Robot time at a venue",
            "",
            "The head camera's recalibration against the bus emulator (its default motion model) and the simulated "
            "camera: the single-command recipe (each capture at its default speed; a capture's robot time is its "
            f"wall time) against one `wolfcal venue` session (from torque on to the last sample). {_when(v)}.",
            "",
            *_table(["single commands: capture", "robot time"], rows),
            f"Single commands: {v['before_total_s']:.1f} s of robot time in all. `wolfcal venue`: "
            f"{after['robot_time_s']:.1f} s of robot time ({after['wall_time_s']:.1f} s wall, fit and check "
            f"included), the camera within {after['camera_rotation_deg']:.4f} deg and "
            f"{after['camera_translation_mm']:.3f} mm of the truth.",
            "",
        ]
    return lines


def accuracy_parts(results: dict) -> list[str]:
    lines: list[str] = []
    if "recordings" in results:
        r = results["recordings"]
        rows = [[free, f"{f['max_z']:.2f}", f"{f['median_z']:.2f}", f"{f['chi2_per_p']:.2f}",
                 f"{f['beyond_3']} of {f['numbers']}"] for free, f in r["summary"].items()]  # fmt: skip
        lines += [
            "## Reported std on continuous recordings",
            "",
            f"{r['seeds']} seed(s) of a simulated plain ROS 2 recording (14 still poses of 2.5 s, images at 10 Hz, "
            f"binned {r['binning']}x): read, paired, detected, averaged per still span, fitted. z = (estimate - truth) "
            f"/ reported std over the free parameters; chi2/P about 1 when the covariance is right. {_when(r)}.",
            "",
            *_table(["--free", "max abs z", "median abs z", "chi2 / P", "beyond 3 std"], rows),
        ]
    if "floor" in results:
        f = results["floor"]
        rows = [[name, f"{s['true_before_m'] * 100:.1f} cm", f"{s['true_after_m'] * 100:.2f} cm",
                 f"{s['sole_max_m'] * 1000:.2f} mm", f"{s['agrees']} of {s['measured']}", str(s["refused"])]
                for name, s in f["summary"].items()]  # fmt: skip
        lines += [
            "## Floor check on rendered views",
            "",
            f"{f['seeds']} seed(s) per scenario: feet + floor captures rendered at 1280x960, 0.025 rad rms encoder "
            "offsets (`leg`) or legs calibrated and the camera ~4 deg off (`camera`). Medians over the seeds of the "
            "true ground error at 4.5 m before and after, and of the soles' worst error over 500 poses; how often "
            f"the ground error measured on a held-out floor capture agrees with the true one. {_when(f)}.",
            "",
            *_table(["scenario", "ground error before", "after", "sole error", "measured agrees", "refused"], rows),
        ]
    if "plan" in results:
        p = results["plan"]
        rows = []
        for name, s in p["scenarios"].items():
            m = s["median"]
            rows.append([name] + [f"{m[k]['error'] * 1000:.2f} mm" for k in ("planned12", "random12", "random30")]
                        + [s["paired_planned12_minus_random30_mm"], f"{s['planning_s']:.1f} s"])  # fmt: skip
        lines += [
            "## Planned against random poses",
            "",
            f"{p['seeds']} seed(s): a random truth, 12 planned poses against 12 and 30 random ones, corners projected "
            "with 0.15 px noise. True error (sole position over random leg poses, or camera position over the "
            f"head's range), median over the seeds; paired difference planned 12 - random 30 [mm]. {_when(p)}.",
            "",
            *_table(["scenario", "12 planned", "12 random", "30 random", "planned - random 30", "planning"], rows),
        ]
    if "compare" in results:
        c = results["compare"]
        head = [f"{col['title']} [{col['unit']}]" for col in c["columns"]]
        rows = [[label] + [f"{by[col['key']]['mean']:.3f}" if col["key"] in by else "n/a" for col in c["columns"]]
                for label, by in c["ratio_to_before"].items()]  # fmt: skip
        lines += [
            "## Every measurement system on one session",
            "",
            f"`wolfcal compare` on {c['seeds']} simulated session(s) with a head camera, an external camera and "
            "motion capture, each fitted and checked on held-out captures. Error after over error before per "
            f"column, mean over the sessions (below 1: better). {_when(c)}.",
            "",
            *_table(["calibration", *head], rows),
        ]
    if "mocap" in results:
        m = results["mocap"]
        rows = [[source, f"{s['sole_mm']['max']:.3f} mm", f"{s['sole_deg']['max']:.3f} deg",
                 f"{s['roll_deg']['max']:.3f} deg", f"{s['max_z']['max']:.2f}"]
                for source, s in m["summary"].items()]  # fmt: skip
        lines += [
            "## Motion capture on another robot's data",
            "",
            f"{m['seeds']} seed(s) of a session written by independent writers (another robot, yourdfpy kinematics, "
            "Markers by mcap_ros2, C3D by ezc3d): 25 still poses, 0.025 rad rms leg offsets, 0.3 mm noise, 3 % "
            "occluded, 1 % reflections; `known`: the config's marker places set to the true ones. Worst over the "
            f"seeds: sole position and rotation error, ankle-roll offset error, largest abs z. {_when(m)}.",
            "",
            *_table(["source", "sole position", "sole rotation", "ankle roll", "max abs z"], rows),
        ]
    return lines + field_parts(results)


FIELD_HEAD = ["seed", "rotation [deg]", "translation [mm]", "ground at 4.5 m [cm]", "place (field) [mm / deg]",
              "max abs z", "field CPU / wall [s] (load)"]  # fmt: skip
CHECK_HEAD = ["seed", "model", "true [cm]", "measured [cm]", "1 sigma (formal, jackknife) [cm]", "off [cm]"]


def field_parts(results: dict) -> list[str]:
    """The field part (the camera from field lines against tags, per seed) and the field_check part (the held-out
    ground error from field views against the true one)."""
    lines: list[str] = []
    if "field" in results:
        f = results["field"]
        rows = [[str(r["seed"]), f"{r['rotation_deg']:.3f} / {r['tags']['rotation_deg']:.3f}",
                 f"{r['translation_mm']:.1f} / {r['tags']['translation_mm']:.1f}",
                 f"{r['ground_cm']:.2f} / {r['tags']['ground_cm']:.2f}", f"{r['place_mm']:.1f} / {r['yaw_deg']:.3f}",
                 f"{r['max_z']:.2f} / {r['tags']['max_z']:.2f}",
                 f"{r['cpu_s']:.1f} / {r['wall_s']:.1f} ({r['load']:.1f})"]
                for r in f["rows"]]  # fmt: skip
        w, t = f["worst"], f["worst_tags"]
        lines += [
            "## Field lines against tags",
            "",
            f"Seeds 0-{f['seeds'] - 1}: a rendered field capture of {f['views']} views (512x384 colour, goals, two "
            "other robots, a ball, shadows, people and walls, uneven light, noise, up to 2 px of motion blur) of a "
            "standing Wolfgang within 0.3 m and 10 deg of `field.robot_at` on a KidSize field, `--system field "
            f"--free camera`; and {f['tag_samples']} feet-tag samples of the same true camera, `--free camera`. "
            "Field / tags: the camera's rotation [deg] and translation [mm] error, the ground error at 4.5 m [cm] "
            "(worst bearing of -30, 0, +30 deg), the largest |estimate - truth| / reported std (camera x, y, z, rx, "
            "ry, rz; with field lines also the robot's x, y, yaw); the robot's place error [mm / deg]; detection + "
            "fit of the field capture in one process, BLAS on one thread as in the `wolfcal` command: CPU / wall "
            f"[s] (load average after it, 2 cores). {_when(f)}.",
            "",
            *_table(FIELD_HEAD, rows),
            f"Worst over the seeds, field lines: rotation {w['rotation_deg']:.3f} deg (target 0.1), place "
            f"{w['place_mm'] / 10:.1f} cm / {w['yaw_deg']:.3f} deg (5 cm / 0.5 deg), ground error at 4.5 m "
            f"{w['ground_cm']:.2f} cm (3 cm), max abs z {w['max_z']:.2f} (3), detection + fit {w['cpu_s']:.1f} s "
            f"CPU, {w['wall_s']:.1f} s wall (10 s); tags: rotation {t['rotation_deg']:.3f} deg, ground error "
            f"{t['ground_cm']:.2f} cm, max abs z {t['max_z']:.2f}.",
            "",
        ]
    if "field_check" in results:
        c = results["field_check"]
        rows = [[str(r["seed"]), r["model"], f"{100 * r['true_m']:.1f}", f"{100 * r['measured_m']:.1f}",
                 f"{100 * r['std_m']:.2f} ({100 * r['formal_m']:.2f}, {100 * r['jackknife_m']:.2f})",
                 f"{100 * abs(r['measured_m'] - r['true_m']):.1f}", f"{100 * (c['agree_m'] + 2 * r['std_m']):.1f}",
                 "yes" if r["agrees"] else "no"] for r in c["rows"]]  # fmt: skip
        refused = "".join(f" Seed {r['seed']}: the fit refused its capture." for r in c["refused"])
        lines += [
            "## Held-out ground error from field views",
            "",
            f"Seeds 0-{c['seeds'] - 1}: {c['views']} rendered field views fitted at `field.robot_at`, {c['views']} "
            "held out with the robot near `field.check_at` (another place, the same true camera). The ground error "
            f"at {c['distance_m']:g} m measured on the held-out views (no truth) against the true one, for the "
            f"fitted camera (after), the nominal one (before, several degrees off) and the fitted one tilted by "
            f"{c['tilt_mrad']:g} mrad (an error near the 5 cm limit); 1 sigma: the larger of the formal and the "
            f"jackknife's (both given) [cm]. {_when(c)}.{refused}",
            "",
            *_table([*CHECK_HEAD, f"{100 * c['agree_m']:g} cm + 2 sigma [cm]", "agrees"], rows),
            f"{c['agree']} of {c['measured']} measurements agree with the true ground error within "
            f"{100 * c['agree_m']:g} cm + 2 sigma.",
            "",
        ]
    return lines
