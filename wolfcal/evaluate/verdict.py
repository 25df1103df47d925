"""The deploy verdict: whether the files to deploy are written, judged on every metric the evaluation has.

Refused (unless overridden with --deploy-worse) when
- the held-out reprojection error gets worse;
- the model's free parameters cannot explain the held-out data (`structure.unexplained`): with the camera presets
  that is the legs, whose offsets tilt the standing robot in a way no camera correction can undo;
- the measured ground error at the check distance (held-out floor samples, `floor_ground`, or field views,
  `field_ground`) gets worse by more than GROUND_SIGMAS of the two measurements' uncertainty, or reads above the
  limit, or the measurement cannot see an error of the limit's size (GROUND_SIGMAS of its uncertainty reach the
  limit: it could read near 0 for an error at the limit); a measured error below the limit whose uncertainty
  reaches past it is a note that the views cannot confirm the limit. Distance and limit come from the robot
  config's `floor.ground_check` (default 5 cm at 4.5 m, half a KidSize field).
(More than 20 % of the samples left out as outliers is refused earlier, by the one outlier rule: `leftout`.)
Without floor samples the ground error is not measured: the verdict says so, gives the ground error the fit's
covariance predicts, and warns when the camera correction turns the camera by more than a mount moves (2 deg).
The banner says in one sentence what to do.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.config import GroundCheck
from wolfcal.robot.floor import CHECK_LAYOUTS

GROUND_SIGMAS = 2.0  # 'worse' and 'confirmed below the limit' need this many 1-sigmas of the measurement
MOUNT_LIMIT_RAD = float(np.deg2rad(2.0))  # a camera correction beyond this is more than a mount moves [rad]


@dataclass(frozen=True)
class VerdictLimits:
    """The verdict's limits: the largest measured ground error that may be deployed [m] for a ball seen
    `ground_distance_m` [m] away (the robot config's `floor.ground_check`), and the camera turn beyond which a note
    warns [rad]."""

    ground_limit_m: float = GroundCheck().limit
    mount_limit_rad: float = MOUNT_LIMIT_RAD
    ground_distance_m: float = GroundCheck().distance


LEGS_ADVICE = (
    "the legs need calibration: run the leg preset (wolfcal fit FEET.mcap FLOOR.mcap --free leg, with floor "
    "samples if possible) instead of deploying this"
)

HEAD_ADVICE = (
    "the head joints need calibration: refit with their offsets free (wolfcal fit ... --free head_camera), which "
    "explains these residuals"
)
NAMES = {"head_camera": "the head joints (--free head_camera)", "leg": "the legs (--free leg)"}

FLOOR_ADVICE = "capture more floor samples, nearer and farther tags, and fit the legs with them (--free leg)"
# The held-out floor capture that measures the ground error at the check distance to about 1 cm is the check
# (docs/workflows/floor-check.md, "The held-out check"; its size on a robot: `robot.floor.check_size`): the standing
# legs' shared tick rounding averages only over stances (floor_ground's `rounding_std_m`), and a tag's corner bias only
# over the places it lies in (`tag_std_m`)
NO_CHECK_STANCES = (
    "list standing poses none of the fit's in the robot config's floor.check_stances "
    "(`wolfcal.robot.floor.moved_stance` makes them), then take `wolfcal capture --floor --check` "
    f"{CHECK_LAYOUTS} times, the floor tags moved between, and give all {CHECK_LAYOUTS} to "
    "`evaluate --capture`"
)


def check_how(check: dict) -> str:
    """How to take the check of size `check` (`robot.floor.check_size`: samples, stances, layouts)."""
    views = check["samples"] // (check["stances"] * check["layouts"])
    return (
        f"`wolfcal capture --floor --check` {check['layouts']} times (floor.check_stances: {check['stances']} "
        f"stances none of the fit's, {views} head view(s) each), the floor tags moved between, and all "
        f"{check['layouts']} given to `evaluate --capture`"
    )


def more_precise(capture: dict | None, check: dict | None) -> str:
    """What to capture to measure the ground error more precisely: what the held-out floor capture
    (`floor_ground.capture_size`) lacks of the check (`robot.floor.check_size`; None: the config lists no check
    stances)."""
    if check is None:
        return f"to measure it more precisely, {NO_CHECK_STANCES}"
    short = [f"{k} {capture[k]} (the check takes {v})" for k, v in check.items()
             if capture is not None and capture[k] < v]  # fmt: skip
    if not short:
        return f"to measure it more precisely, take more held-out floor samples: {check_how(check)}"
    return f"the held-out floor capture is smaller than the check needs: {', '.join(short)}; take {check_how(check)}"


def deploy_verdict(
    free: str,
    before_px: float | None,
    after_px: float | None,
    structure: dict | None,
    measured_ground: dict | None,
    predicted_ground_m: float | None,
    camera_turn_rad: float,
    limits: VerdictLimits = VerdictLimits(),
    pixels_of: str = "",
) -> dict:
    """metrics.json's 'verdict': deploy (bool), worse (the pixel rule), refusals and notes (sentences), banner.

    before_px, after_px: held-out reprojection RMS [px]; None when the held-out views have no tags (field views:
    the ground error is the verdict's measure);
    structure: `structure.unexplained` of the evaluated views, with 'explained_by' and 'tested'
    (`explaining.explaining_preset`) when unexplained, or None;
    measured_ground: {'before_m', 'after_m', 'after_std_m', optional 'before_std_m'} at limits.ground_distance_m
    from held-out views [m], optional 'capture' (`floor_ground.capture_size` of the held-out floor capture) and
    'check' (the check's size on this robot, `robot.floor.check_size`; None: no check stances), optional 'views'
    (what measured it, default 'the held-out floor views') and 'advice' (how to measure it more precisely, default
    `more_precise`'s), or None;
    predicted_ground_m: 1-sigma ground error at limits.ground_distance_m from the fit's covariance [m], or None;
    camera_turn_rad: rotation angle of the fitted camera frame correction [rad];
    pixels_of: what the pixel figures are of, said after them (e.g. ' (of still-span means: ...)'), or ''.
    """
    refusals: list[tuple[str, str]] = []  # (what to do, why)
    notes: list[str] = []
    worse = bool(after_px is not None and before_px is not None and after_px > before_px)
    advice = _advice(free, structure)
    if structure is not None and structure["unexplained"]:
        refusals.append(_unexplained_refusal(advice, structure))
    if worse:
        refusals.append(
            (
                "keep the input URDF and refit with more varied poses or fewer free parameters",
                (
                    f"The calibration makes held-out error worse: reprojection RMS {after_px:.3f} px calibrated vs "
                    f"{before_px:.3f} px with the input URDF{pixels_of}."
                ),
            )
        )
    if measured_ground is not None:
        _judge_measured_ground(advice, measured_ground, limits, refusals, notes)
    else:
        predicted = "" if predicted_ground_m is None else (
            f"; the fit's uncertainty alone predicts +- {predicted_ground_m * 100:.1f} cm at "
            f"{limits.ground_distance_m:g} m (1 sigma), "
            "which does not include errors its free parameters cannot represent")  # fmt: skip
        notes.append(f"The ground error was not measured (no floor samples held out){predicted}.")
    if camera_turn_rad > limits.mount_limit_rad and measured_ground is None and not refusals:
        notes.append(_mount_note(camera_turn_rad, limits.mount_limit_rad))  # measured or refused: nothing to do
    deploy = not refusals
    if deploy:
        ground = ("" if measured_ground is None else
                  f", measured ground error at {limits.ground_distance_m:g} m "
                  f"{measured_ground['after_m'] * 100:.1f} +- "
                  f"{measured_ground['after_std_m'] * 100:.1f} cm")  # fmt: skip
        pixels = ("" if before_px is None or after_px is None else
                  f": held-out reprojection RMS {before_px:.3f} px -> {after_px:.3f} px{pixels_of}")  # fmt: skip
        banner = f"Deploy the files below{pixels}{ground}" + ("." if not notes else "; read the notes below first.")
    else:
        banner = f"Do not deploy: {refusals[0][0]}."
    return {"deploy": deploy, "worse": worse, "refusals": [why for _, why in refusals], "notes": notes,
            "message": banner, "ground_limit_m": limits.ground_limit_m,
            "ground_distance_m": limits.ground_distance_m, "mount_limit_rad": limits.mount_limit_rad}  # fmt: skip


def _advice(free: str, structure: dict | None) -> str:
    """What to do when the model does not explain the data: the free set that does (`explaining_preset`, tested
    on the data), or, when none does, what else to check."""
    explained_by = (structure or {}).get("explained_by")
    tested = (structure or {}).get("tested") or {}
    if explained_by == "head_camera":
        return HEAD_ADVICE
    if explained_by == "leg":
        return LEGS_ADVICE
    if structure is None or not structure["unexplained"]:  # a ground error that got worse: a camera preset's legs
        return LEGS_ADVICE if free in ("camera", "head_camera") else FLOOR_ADVICE
    none = (
        f"neither {' nor '.join(NAMES[p] for p in tested)} explain these residuals either (fitted on them); "
        if tested
        else ""
    )
    return none + "check the tags' ids, sizes and links, the camera intrinsics, and that the captures are of this robot"


def _unexplained_refusal(what: str, structure: dict) -> tuple[str, str]:
    """(what to do, why) when the free parameters cannot explain the held-out tags (`structure.unexplained`)."""
    tested = structure.get("tested") or {}
    scales = ", ".join(f"--free {p} {'could not be fitted' if v is None else f'{v:.1f}'}" for p, v in tested.items())
    sets = f" Fitted on the same views, the whitened residual scale (1 = explained) is: {scales}." if tested else ""
    return what, (
        f"Held-out tags are off by {structure['view_shift_rms_px']:.2f} px RMS per axis, {structure['scale']:.1f} "
        f"times what detection noise ({structure['corner_noise_px']:.2f} px) and joint quantisation explain: "
        f"{what}.{sets}"
    )


def _judge_measured_ground(
    advice: str, measured_ground: dict, limits: VerdictLimits, refusals: list[tuple[str, str]], notes: list[str]
) -> None:
    """Appends the ground rules' refusal or note: worse by GROUND_SIGMAS, above the limit, unable to see an error of
    the limit's size, or not confirmed below."""
    limit_cm, at = limits.ground_limit_m * 100, f"{limits.ground_distance_m:g} m"
    b, a = measured_ground["before_m"] * 100, measured_ground["after_m"] * 100
    sa, sb = measured_ground["after_std_m"] * 100, measured_ground.get("before_std_m", 0.0) * 100
    views = measured_ground.get("views", "the held-out floor views")
    precise = measured_ground.get("advice") or more_precise(
        measured_ground.get("capture"), measured_ground.get("check")
    )
    if a - b > GROUND_SIGMAS * np.hypot(sa, sb):
        refusals.append((advice, f"The measured ground error at {at} gets worse: {b:.1f} +- {sb:.1f} cm -> "
                                 f"{a:.1f} +- {sa:.1f} cm (1 sigma)."))  # fmt: skip
    elif a > limit_cm:
        unsure = f" The measurement is that uncertain: {precise}." if a - GROUND_SIGMAS * sa <= limit_cm else ""
        refusals.append(
            (
                advice,
                (
                    f"The measured ground error at {at} stays above the limit: {a:.1f} +- {sa:.1f} cm (1 sigma) > "
                    f"{limit_cm:g} cm (floor.ground_check.limit or --ground-limit-cm).{unsure}"
                ),
            )
        )
    elif GROUND_SIGMAS * sa >= limit_cm:
        refusals.append((precise, f"The measured ground error at {at} is {a:.1f} +- {sa:.1f} cm (1 sigma): {views} "
                                  f"cannot see an error below {GROUND_SIGMAS * sa:.1f} cm at {at}, so they cannot "
                                  f"judge the limit ({limit_cm:g} cm); {precise}."))  # fmt: skip
    elif a + GROUND_SIGMAS * sa > limit_cm:
        notes.append(
            f"The measured ground error at {at} is {a:.1f} +- {sa:.1f} cm (1 sigma): {views} "
            f"cannot confirm that it is below the limit ({limit_cm:g} cm); {precise}."
        )


def _mount_note(camera_turn_rad: float, mount_limit_rad: float) -> str:
    """The warning that the camera correction turns the camera by more than a mount moves, with what to do: only
    for a calibration that would be deployed without a measured ground error (a measured one is the check)."""
    return (
        f"The camera correction turns the camera by {np.rad2deg(camera_turn_rad):.1f} deg, more than a camera "
        f"mount moves ({np.rad2deg(mount_limit_rad):g} deg): it may be absorbing joint offsets; check the ground "
        "error with held-out floor samples (`wolfcal capture --floor --check`, then `evaluate --capture`) before "
        "deploying."
    )
