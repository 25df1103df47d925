"""The fit result: `result.yaml` (every number with its meaning) and the words that say what to trust."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import yaml

import wolfcal
from wolfcal.atomic import write_text_atomic
from wolfcal.errors import WolfcalError
from wolfcal.fit.solver import Solution
from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet
from wolfcal.yamlfile import read_yaml

CONDITION_LIMIT = 100.0
DATA_SHARE_LIMIT = 0.5


def correlated_groups(names: list[str], pairs: list[tuple[str, str, float]]) -> list[list[str]]:
    """Connected groups of parameters linked by strongly correlated pairs, in parameter order."""
    group = {n: {n} for n in names}
    for a, b, _ in pairs:
        if group[a] is not group[b]:
            merged = group[a] | group[b]
            for n in merged:
                group[n] = merged
    seen, out = set(), []
    for n in names:
        if len(group[n]) > 1 and n not in seen:
            seen |= group[n]
            out.append([m for m in names if m in group[n]])
    return out


def explain(params: ParameterSet, solution: Solution) -> list[str]:
    """Plain sentences on what the data cannot tell apart and which values rest on the priors."""
    lines = []
    pairs = solution.correlated_pairs(params.names)
    for members in correlated_groups(params.names, pairs):
        strongest = max(abs(c) for a, b, c in pairs if a in members)
        lines.append(
            f"{', '.join(members)} move together in these poses (|correlation| up to {strongest:.2f}): the data "
            "cannot tell them apart, so how the correction splits between them comes from the priors; the model "
            "they give together is still determined. Add poses that move them differently, or fix some of them."
        )
    for name, share in zip(params.names, solution.data_share):
        if share < DATA_SHARE_LIMIT:
            lines.append(
                f"{name}: only {share:.0%} of its information comes from the data; its value stays near the nominal "
                "model (prior)."
            )
    if solution.condition_number > CONDITION_LIMIT:
        lines.append(
            f"condition number {solution.condition_number:.3g} of the column-scaled Jacobian is above "
            f"{CONDITION_LIMIT:.0f}: some parameter combinations are weakly or not at all observable in these poses."
        )
    return lines


def _display(value: float, unit: str) -> str:
    return f"{np.rad2deg(value):+.3f} deg" if unit == "rad" else f"{value * 1000:+.2f} mm"


def result_dict(
    *,
    robot_path: Path,
    urdf_path: Path,
    captures: list[Path],
    intrinsics: Path | None,
    preset: str,
    side: str,
    fix_tags: bool,
    tag_ids: list[int],
    params: ParameterSet,
    solution: Solution,
    obs: Observations,
    corrections: Corrections,
    huber_k: float,
    warnings: list[str],
) -> dict:
    samples = []
    for i in range(obs.n_samples):
        samples.append(
            {
                "index": i,
                "source": Path(obs.sources[i]).name,
                "stamp_ns": int(obs.stamps_ns[i]),
                "tags": obs.tags_in_sample(i),
                "rms_before_px": round(float(solution.sample_rms_before[i]), 4),
                "rms_after_px": round(float(solution.sample_rms_after[i]), 4),
                "outlier": bool(solution.outlier_samples[i]),
                "outlier_tags": sorted(t for s, t in solution.outlier_views if s == i),
            }
        )
    return {
        "wolfcal_version": wolfcal.__version__,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "robot": str(robot_path.resolve()),
        "urdf": str(urdf_path.resolve()),
        "captures": [str(Path(c).resolve()) for c in captures],
        "intrinsics": str(intrinsics.resolve()) if intrinsics else None,
        "free": preset,
        "side": side,
        "fix_tags": fix_tags,
        "tags_used": tag_ids,
        "rms_meaning": "per-axis RMS of corner residuals in pixels (sqrt(mean(du^2 + dv^2) / 2)), inlier samples",
        "rms_before_px": round(solution.rms_before_px, 4),
        "rms_after_px": round(solution.rms_after_px, 4),
        "max_after_px": round(solution.max_after_px, 4),
        "noise_model": {
            "corner_sigma_px": round(solution.sigma_px, 4),
            "joint_sigma_rad": float(f"{solution.sigma_q:.4g}"),
            "meaning": "per-sample residual covariance sigma_px^2 I + sigma_q^2 A A^T, A = d(pixels)/d(joint readings)",
        },
        "robust_loss": {"kind": "huber", "threshold_sigma": huber_k},
        "n_samples": obs.n_samples,
        "n_outlier_samples": int(solution.outlier_samples.sum()),
        "n_outlier_tag_views": len(solution.outlier_views),
        "n_corners_used": solution.n_corners,
        "converged": bool(solution.converged),
        "condition_number": float(solution.condition_number) if np.isfinite(solution.condition_number) else None,
        "parameters": [
            {
                "name": p.name,
                "value": float(v),
                "std": float(s),
                "unit": p.unit,
                "prior_sigma": p.prior_sigma,
                "data_share": round(float(share), 4),
                "display": f"{_display(v, p.unit)} +- {_display(s, p.unit)[1:]}",
            }
            for p, v, s, share in zip(params.parameters, solution.values, solution.std, solution.data_share)
        ],
        "correlated_pairs": [
            {"a": a, "b": b, "correlation": round(c, 4)} for a, b, c in solution.correlated_pairs(params.names)
        ],
        "covariance": {"names": params.names, "matrix": np.round(solution.covariance, 15).tolist()},
        "explanations": explain(params, solution),
        "warnings": warnings,
        "samples": samples,
        "corrections": corrections.to_dict(),
    }


def plain(value):
    """Numpy scalars and arrays inside nested dicts/lists -> plain Python values (for YAML and JSON)."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


def write_result(path: Path, data: dict) -> None:
    write_text_atomic(path, yaml.safe_dump(plain(data), sort_keys=False, width=120))


def load_result(path: str | Path) -> dict:
    """Read a `result.yaml` (or the folder that holds one)."""
    path = Path(path)
    if path.is_dir():
        path = path / "result.yaml"
    data = read_yaml(path, "fit result", "run `wolfcal fit ... --out DIR` first")
    for key in ("robot", "captures", "free", "parameters", "corrections"):
        if not isinstance(data, dict) or key not in data:
            raise WolfcalError(f"{path}: missing key '{key}'; is this a wolfcal fit result?")
    return data


def summary_lines(data: dict) -> list[str]:
    """A short human summary of a result dict."""
    lines = [
        f"samples: {data['n_samples']} ({data['n_outlier_samples']} left out as outliers, "
        f"{data['n_outlier_tag_views']} outlier tag view(s) in all), corners used: {data['n_corners_used']}",
        f"reprojection RMS (per axis, inliers): {data['rms_before_px']:.3f} px before -> "
        f"{data['rms_after_px']:.3f} px after (max {data['max_after_px']:.2f} px)",
        f"condition number (column-scaled Jacobian): {data['condition_number'] or float('inf'):.1f}",
        "parameters (value +- std, share of information from data):",
    ]
    width = max(len(p["name"]) for p in data["parameters"])
    for p in data["parameters"]:
        lines.append(f"  {p['name']:<{width}}  {p['display']:>28}  data {p['data_share']:.0%}")
    return lines
