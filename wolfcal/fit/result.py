"""The fit result: `FitResult`, the one definition of `result.yaml` (written and read here only; every number with its
meaning), and the words that say what to trust."""

from __future__ import annotations

from dataclasses import MISSING, asdict, dataclass, field, fields
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np

import wolfcal
from wolfcal.atomic import atomic_output
from wolfcal.errors import WolfcalError
from wolfcal.fit.blocks import FittedBlock
from wolfcal.fit.options import NOISE_FLOOR_PX, FitOptions
from wolfcal.fit.solver import Solution
from wolfcal.fit.systems import block_class
from wolfcal.geometry import matrix_to_rpy, transform_from_twist_params
from wolfcal.io.current import CurrentCalibration
from wolfcal.outliers import FIT_VIEW_PX, OutlierRule
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet
from wolfcal.yamlfile import dump_yaml_pieces, read_yaml

if TYPE_CHECKING:
    from wolfcal.fit.solved import Fit

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
    """Plain sentences on what the data cannot tell apart and which values rest on the priors, each saying what to
    do, each said once. Only the robot model's parameters are named: a measurement's own unknowns (floor tag
    places, a camera's placement) that the data cannot separate leave the model as determined, and ask for nothing.
    """
    lines = []
    u = solution.uncertainty
    in_chain = {p.name for p in params.parameters if p.in_chain}
    pairs = u.correlated_pairs(params.names)
    for members in correlated_groups(params.names, pairs):
        if not in_chain & set(members):
            continue
        strongest = max(abs(c) for a, b, c in pairs if a in members)
        lines.append(
            f"{', '.join(members)} move together in these poses (|correlation| up to {strongest:.2f}): the data "
            "cannot tell them apart, so how the correction splits between them comes from the priors; the model "
            "they give together is still determined. Add poses that move them differently, or fix some of them."
        )
    for name, share in zip(params.names, u.data_share):
        if share < DATA_SHARE_LIMIT and name in in_chain:
            lines.append(
                f"{name}: only {share:.0%} of its information comes from the data; its value stays near its prior "
                "(the nominal model, or the present calibration given with --current), and the evaluation deploys it "
                "at its present value."
            )
    if u.condition_number > CONDITION_LIMIT and not lines:
        lines.append(
            f"condition number {u.condition_number:.3g} of the column-scaled Jacobian is above "
            f"{CONDITION_LIMIT:.0f}: some parameter combinations are weakly observable in these poses; add poses "
            "that move the free joints more, or free fewer parameters."
        )
    return lines


def _display(value: float, unit: str) -> str:
    """A parameter value [SI, or px] as a user reads it: degrees, millimetres or pixels."""
    if unit == "rad":
        return f"{np.rad2deg(value):+.3f} deg"
    if unit == "m":
        return f"{value * 1000:+.2f} mm"
    return f"{value:+.3f} {unit}"


def _measured_by(fit: Fit) -> list[list[str]]:
    """Per parameter, the measurement systems whose data inform it (non-zero Jacobian column)."""
    z = np.zeros(len(fit.params))
    out: list[list[str]] = [[] for _ in fit.params.parameters]
    start = len(fit.chain)
    for state, lin in zip(fit.problem.states, fit.problem.evaluate(z)):
        chain = np.abs(lin.jac_chain).reshape(-1, len(fit.chain)).max(axis=0) if len(fit.chain) else np.zeros(0)
        for column in np.flatnonzero(chain > 0):
            out[int(column)].append(state.block.name)
        for i in range(len(state.block.nuisance)):
            out[start + i].append(state.block.name)
        start += len(state.block.nuisance)
    return out


def _block_dict(fit: Fit, k: int) -> dict:
    """The result of one measurement block (`Block.report`: residuals, noise, outliers, per-sample errors)."""
    state, params = fit.problem.states[k], fit.problem.params
    residual = fit.problem.raw_residuals((fit.solution.values - params.references) / params.prior_sigmas)[k]
    local = fit.solution.values[state.start : state.start + len(state.block.nuisance)]
    chain_values = fit.solution.values[: len(fit.chain)]
    return state.block.report(
        FittedBlock(fit.solution.blocks[k], state.excluded_units, local, residual, fit.chain, chain_values)
    )


def external_camera_poses(fit: Fit) -> dict:
    """T_base_camera of every external camera placement, as xyz [m] and rpy [rad] with the 4x4 matrix."""
    out = {}
    for block in fit.blocks:
        for name in dict.fromkeys(p.target for p in block.nuisance.parameters if p.kind == "pose"):
            idx = [i for i, p in enumerate(fit.params.parameters) if p.kind == "pose" and p.target == name]
            T = transform_from_twist_params(fit.solution.values[idx])
            out[name] = {
                "camera": getattr(block, "camera_name", block.name),
                "xyz": [float(v) for v in T[:3, 3]],
                "rpy": [float(v) for v in matrix_to_rpy(T[:3, :3])],
                "T_base_camera": np.round(T, 12).tolist(),
            }
    return out


RESULT_VERSION = 1  # of result.yaml's layout; 0: files written before the key existed (read with the defaults)


@dataclass
class ParameterResult:
    """One estimated unknown as result.yaml lists it."""

    name: str  # e.g. camera.rx, HeadTilt.offset, tag43.x, tripod.z
    value: float  # [unit]
    std: float  # 1-sigma [unit]
    unit: str  # 'rad' | 'm'
    prior_sigma: float  # [unit]
    data_share: float  # share of its information from the data rather than the prior, 0..1
    measured_by: list[str]  # names of the blocks whose data inform it
    urdf_joint: str | None = None  # the URDF joint an offset or frame parameter is written to (None: not one)
    display: str = ""  # value +- std in deg or mm, for people


@dataclass
class FitResult:
    """Everything result.yaml holds, in its order: the one place that defines the file (`to_dict` / `from_dict`
    map fields to keys one to one; a field that is None and marked OPTIONAL is left out). To add a key: add a
    field with a default (files written before it read with that default) and fill it in `fit_result`."""

    wolfcal_version: str
    created: str  # ISO 8601, UTC
    robot: str  # absolute path of the robot config
    urdf: str  # absolute path of its URDF
    captures: list[str]  # absolute paths
    intrinsics: str | None
    free: str  # --free preset
    side: str
    fix_tags: bool
    system: str  # 'head' | 'external' | 'all'
    external_moving: bool
    systems_used: list[str]  # block names
    tags_used: list[int]
    noise_model: dict  # {joint_sigma_rad, per_block_sigma, meaning}
    robust_loss: dict  # {kind: huber, threshold_sigma}
    n_samples: int
    n_outlier_samples: int
    n_outlier_tag_views: int
    n_corners_used: int  # corners the fit counts (views kept, less the single corners left out)
    converged: bool
    condition_number: float | None  # of the column-scaled Jacobian; None: infinite
    parameters: list[ParameterResult]
    correlated_pairs: list[dict]  # {a, b, correlation}
    covariance: dict  # {names, matrix} [SI units of the parameters]
    explanations: list[str]
    warnings: list[str]
    blocks: list[dict]  # per measurement block, see `_block_dict`
    external_cameras: dict  # placement -> {camera, xyz, rpy, T_base_camera}
    samples: list[dict]  # the head camera's per-sample rows (else the first block's)
    corrections: Corrections
    version: int = RESULT_VERSION
    # the head camera's figures at the top level (absent without a head camera); see blocks for their meaning
    rms_meaning: str | None = None
    rms_before_px: float | None = None
    rms_after_px: float | None = None
    max_after_px: float | None = None
    outlier_rule: dict = field(default_factory=lambda: {"factor": FIT_VIEW_PX.factor, "floor_px": FIT_VIEW_PX.floor})
    noise_floor_px: float = NOISE_FLOOR_PX
    mocap_moving: bool = False  # one base pose in the motion-capture frame per sample
    # motion-capture file -> clock offset [s]: t_recording = t_file + offset, t_file = seconds since the file's
    # first frame (absent without motion-capture files)
    mocap_clock_offset_s: dict[str, float] | None = None
    # single corners of views kept left out as far off (blocks with a corner rule, the floor's; 0 in older files)
    n_outlier_corners: int = 0
    # the robot's present calibration the fit started from (`--current`; `io.current.CurrentCalibration.to_dict`:
    # sources, corrections, imu_offsets); absent: the input URDF's nominal model. `corrections` are totals.
    current: dict | None = None

    HEAD_FIGURES: ClassVar[tuple[str, ...]] = ("rms_meaning", "rms_before_px", "rms_after_px", "max_after_px")
    OPTIONAL: ClassVar[tuple[str, ...]] = (*HEAD_FIGURES, "mocap_clock_offset_s", "current")
    KEY_ORDER: ClassVar[tuple[str, ...]] = (  # result.yaml's key order (fields not listed follow in field order)
        "version",
        "wolfcal_version",
        "created",
        "robot",
        "urdf",
        "captures",
        "intrinsics",
        "free",
        "side",
        "fix_tags",
        "system",
        "external_moving",
        "systems_used",
        "tags_used",
        "rms_meaning",
        "rms_before_px",
        "rms_after_px",
        "max_after_px",
        "noise_model",
        "robust_loss",
        "outlier_rule",
        "noise_floor_px",
        "n_samples",
        "n_outlier_samples",
        "n_outlier_tag_views",
        "n_outlier_corners",
    )

    @property
    def options(self) -> FitOptions:
        """The settings the fit ran with, to fit again exactly the same way (cross-validation folds)."""
        return FitOptions(
            free=self.free, side=self.side, fix_tags=self.fix_tags, huber_k=float(self.robust_loss["threshold_sigma"]),
            system=self.system, external_moving=self.external_moving, mocap_moving=self.mocap_moving,
            outlier=OutlierRule(float(self.outlier_rule["factor"]), float(self.outlier_rule["floor_px"])),
            noise_floor_px=self.noise_floor_px,
            current=None if self.current is None else self.current_calibration.corrections,
        )  # fmt: skip

    @property
    def current_calibration(self) -> CurrentCalibration:
        """The present calibration the fit started from (empty: the input URDF's nominal model)."""
        return CurrentCalibration() if self.current is None else CurrentCalibration.from_dict(self.current, "result")

    def estimate(self, name: str) -> tuple[float, float] | None:
        """A fitted parameter's value and 1-sigma in its own unit (None: not among the fit's parameters)."""
        found = [(p.value, p.std) for p in self.parameters if p.name == name]
        return found[0] if found else None

    def to_dict(self) -> dict:
        """Plain data for YAML, keys in `KEY_ORDER`."""
        names = [f.name for f in fields(self)]
        order = [n for n in self.KEY_ORDER if n in names] + [n for n in names if n not in self.KEY_ORDER]
        out = {}
        for name in order:
            value = getattr(self, name)
            if value is None and name in self.OPTIONAL:
                continue
            if name == "parameters":
                value = [{k: v for k, v in asdict(p).items() if v is not None} for p in value]
            elif name == "corrections":
                value = value.to_dict()
            out[name] = value
        return plain(out)

    @classmethod
    def from_dict(cls, data: dict, path: Path) -> FitResult:
        """The result of a result.yaml's data; a clear error for a file that is not one."""
        known = {f.name: f for f in fields(cls)}
        required = [n for n, f in known.items() if f.default is MISSING and f.default_factory is MISSING]
        missing = [n for n in required if n not in data]
        if missing:
            raise WolfcalError(
                f"{path}: missing key(s) {', '.join(missing)}; is this a wolfcal fit result? (run `wolfcal fit` again "
                "to write a complete one)"
            )
        values = {k: v for k, v in data.items() if k in known}
        values.setdefault("version", 0)
        try:
            values["parameters"] = [ParameterResult(**p) for p in data["parameters"]]
        except TypeError as exc:
            raise WolfcalError(f"{path}: 'parameters' entries do not match a wolfcal fit result ({exc})") from None
        values["corrections"] = Corrections.from_dict(data["corrections"], f"{path}: corrections")
        return cls(**values)


def parameter_results(fit: Fit) -> list[ParameterResult]:
    """result.yaml's row of every unknown of a solved fit: value, std, data share, what measured it."""
    u, params = fit.solution.uncertainty, fit.params
    return [
        ParameterResult(
            name=p.name, value=float(v), std=float(s), unit=p.unit, prior_sigma=p.prior_sigma,
            data_share=round(float(share), 4), measured_by=by,
            urdf_joint=fit.robot.model.urdf_joint_of(p.target) if p.kind in ("offset", "frame") else None,
            display=f"{_display(v, p.unit)} +- {_display(s, p.unit)[1:]}",
        )
        for p, v, s, share, by in zip(params.parameters, fit.solution.values, u.std, u.data_share, _measured_by(fit))
    ]  # fmt: skip


def _noise_model(fit: Fit, blocks: list[dict]) -> dict:
    return {
        "joint_sigma_rad": float(f"{fit.solution.sigma_q:.4g}"),
        "per_block_sigma": {b["name"]: b[f"noise_sigma_{b['unit']}"] for b in blocks},
        "meaning": "per still pose and block: residual covariance sigma^2 I + sigma_q^2 A A^T, A = d(residuals)"
        "/d(joint readings); sigma per measured number (pixel axis or metre axis)",
    }


def fit_result(
    fit: Fit,
    options: FitOptions,
    captures: list[Path],
    intrinsics: Path | None,
    warnings: list[str],
    current: CurrentCalibration | None = None,
) -> FitResult:
    """The result of a fit, with the settings it ran with and the present calibration it started from."""
    config, solution, params = fit.robot.config, fit.solution, fit.params
    u = solution.uncertainty
    blocks = [_block_dict(fit, k) for k in range(len(fit.blocks))]
    head = next((b for b in blocks if b["system"] == "head"), None)
    head_figures = {k: head[k] for k in FitResult.HEAD_FIGURES} if head else {}
    return FitResult(
        wolfcal_version=wolfcal.__version__,
        created=datetime.now(timezone.utc).isoformat(timespec="seconds"),
        robot=str(config.path.resolve()),
        urdf=str(config.urdf.resolve()),
        captures=[str(Path(c).resolve()) for c in captures],
        intrinsics=str(intrinsics.resolve()) if intrinsics else None,
        free=options.free, side=options.side, fix_tags=options.fix_tags, system=options.system or "all",
        external_moving=options.external_moving,
        systems_used=[b["name"] for b in blocks],
        tags_used=fit.tag_ids,
        **head_figures,
        noise_model=_noise_model(fit, blocks),
        robust_loss={"kind": "huber", "threshold_sigma": options.huber_k},
        outlier_rule={"factor": options.outlier.factor, "floor_px": options.outlier.floor},
        noise_floor_px=options.noise_floor_px,
        n_samples=sum(b["n_samples"] for b in blocks),
        n_outlier_samples=sum(b["n_outlier_samples"] for b in blocks),
        n_outlier_tag_views=sum(b["n_outlier_views"] for b in blocks),
        n_outlier_corners=sum(b.get("n_outlier_corners", 0) for b in blocks),
        n_corners_used=sum(b["n_units_used"] for b in blocks),
        converged=bool(solution.converged),
        condition_number=float(u.condition_number) if np.isfinite(u.condition_number) else None,
        parameters=parameter_results(fit),
        correlated_pairs=[{"a": a, "b": b, "correlation": round(c, 4)} for a, b, c in u.correlated_pairs(params.names)],
        covariance={"names": params.names, "matrix": np.round(u.covariance, 15).tolist()},
        explanations=explain(params, solution),
        warnings=warnings,
        blocks=blocks,
        external_cameras=external_camera_poses(fit),
        samples=head["samples"] if head is not None else blocks[0]["samples"],
        corrections=fit.corrections,
        mocap_moving=options.mocap_moving,
        mocap_clock_offset_s=next((b["mocap_clock_offset_s"] for b in blocks if b["system"] == "mocap"), None),
        current=None if current is None else current.to_dict(),
    )  # fmt: skip


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


def write_result(path: Path, result: FitResult) -> None:
    """Write result.yaml atomically, in pieces (`dump_yaml_pieces`: a long recording's per-sample rows are never
    one node tree in memory)."""
    with atomic_output(path) as handle:
        for piece in dump_yaml_pieces(result.to_dict(), sort_keys=False, width=120):
            handle.write(piece.encode("utf-8"))


def load_result(path: str | Path) -> FitResult:
    """Read a `result.yaml` (or the folder that holds one)."""
    path = Path(path)
    if path.is_dir():
        path = path / "result.yaml"
    data = read_yaml(path, "fit result", "run `wolfcal fit ... --out DIR` first")
    if not isinstance(data, dict):
        raise WolfcalError(f"{path}: not a mapping; is this a wolfcal fit result?")
    return FitResult.from_dict(data, path)


def summary_lines(result: FitResult) -> list[str]:
    """A short human summary of a fit result."""
    lines = []
    for b in result.blocks:
        lines += block_class(b["system"]).summary_lines(b)  # each block's own lines (`Block.summary_lines`)
    lines += [
        f"condition number (column-scaled Jacobian): {result.condition_number or float('inf'):.3g}",
        "parameters (value +- std, share of information from data):",
    ]
    hidden = {name for b in result.blocks for name in b.get("marking_places_m", ())}  # named in their block's lines
    shown = [p for p in result.parameters if p.name not in hidden]
    width = max(len(p.name) for p in shown)
    for p in shown:
        lines.append(f"  {p.name:<{width}}  {p.display:>28}  data {p.data_share:.0%}")
    return lines
