"""`wolfcal plan`: candidates -> expected information -> chosen poses -> capture order -> poses file + table.

The poses file is the one `wolfcal capture --poses` and `wolfcal simulate --poses` read (`wolfcal.capture.poses`):
every pose names every joint the plan moves; the others stay where they stand (planned and checked at the
rest pose; `capture --poses` checks again where they really stand). The table compares the
standard deviations the fit would report (configured pixel and encoder noise) for the planned poses and for as many
random candidate poses.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wolfcal.atomic import write_text_atomic
from wolfcal.errors import WolfcalError
from wolfcal.fit.systems import planned_systems
from wolfcal.fit.uncertainty import Uncertainty, uncertainty
from wolfcal.outputs import check_outputs
from wolfcal.plan.candidates import Candidates, draw_candidates, plan_camera
from wolfcal.plan.deliverable import deliverable_basis, delivered_std
from wolfcal.plan.floor import FloorPlanModel, draw_floor_candidates, expected_places, places_text
from wolfcal.plan.information import (
    PlanModel,
    PlanModelLike,
    check_observable,
    criterion_interest,
    factors,
    predicted,
    separability,
)
from wolfcal.plan.mocap import MocapPlanModel, draw_mocap_candidates, used_markers
from wolfcal.plan.order import capture_order
from wolfcal.plan.select import check_criterion, cover_twice, criterion_value, information, select
from wolfcal.robot.collision import CollisionModel
from wolfcal.robot.collision_sources import collision_model, rest_configuration
from wolfcal.robot.parameters import ParameterSet, check_preset, tags_for_preset
from wolfcal.robot.presets import DEFAULT_PRESET
from wolfcal.robot.robot import Robot, load_robot

# --criterion when none is given, per (system, preset): the one that planned the more accurate calibration in
# the bench harness's `plan` part; D for the others
DEFAULT_CRITERION = {("head", "head_camera"): "I", ("external", "leg"): "I"}


@dataclass(frozen=True)
class PlanOptions:
    free: str = DEFAULT_PRESET
    side: str = "both"
    system: str = "head"
    poses: int = 12
    candidates: int = 2000
    criterion: str | None = None  # D | A | E | I; None: DEFAULT_CRITERION of the system and preset
    velocity: float = 0.5  # profile velocity of the capture [rad/s]
    margin: float = 0.1  # kept from each URDF joint limit [rad]
    seed: int = 0
    external: str | None = None  # which external camera (default: the config's first)
    placement: str | None = None  # its expected pose 'x,y,z,roll,pitch,yaw' (default: the simulator's middle)

    def __post_init__(self) -> None:
        check_preset(self.free, self.side)
        criterion = DEFAULT_CRITERION.get((self.system, self.free), "D") if self.criterion is None else self.criterion
        object.__setattr__(self, "criterion", check_criterion(criterion))
        if self.system not in planned_systems():
            raise WolfcalError(f"--system {self.system!r}: plan supports {', '.join(planned_systems())}")
        if self.poses < 1 or self.candidates < self.poses:
            raise WolfcalError("--poses must be at least 1 and --candidates at least --poses")
        if not 0 < self.velocity <= 6:
            raise WolfcalError(f"--velocity {self.velocity}: give a speed in rad/s in (0, 6]")


@dataclass
class Plan:
    q: np.ndarray  # (n, J) planned joint readings in capture order [rad]
    joints: list[str]  # joints written per pose: those the plan moves
    move_time_s: float  # moves from the rest pose through every pose at the velocity [s]
    params: ParameterSet  # every unknown (chain first)
    n_chain: int
    planned: Uncertainty
    random: Uncertainty
    observable: np.ndarray  # (P,) bool: parameters some pose can inform
    groups: list[list[str]]  # parameters no pose separates, in groups
    at_prior: np.ndarray  # (P,) bool: unseparable and keeping its prior (else bounded by a repeated view)
    candidates: Candidates
    condition: tuple[float, float]  # planned, random: over the observable parameters
    planned_names: list[str] = field(default_factory=list)  # the unknowns of `planned` (chain first, as params)
    notes: list[str] = field(default_factory=list)  # what the plan assumes (e.g. where the floor tags lie)
    criterion_value: float = 0.0  # of the planned poses (`plan.select`; I: mean scaled variance of the delivered)
    # planned, random: rms predicted std of the delivered rotation [rad] and position [m] (`plan.deliverable`)
    delivered: tuple[tuple[float, float], tuple[float, float]] | None = None

    def worst_std(self, which: Uncertainty, unit: str) -> float:
        """Largest std among the observable chain parameters of a unit ('m' | 'rad') [unit]."""
        units = np.array([p.unit for p in self.params.parameters[: self.n_chain]])
        keep = self.observable[: self.n_chain] & (units == unit)
        return float(which.std[: self.n_chain][keep].max()) if keep.any() else 0.0


def used_tags(robot: Robot, options: PlanOptions, external: bool) -> list[int]:
    """The tags the fit would use for this preset and camera (all the preset's, plus the base-fixed ones for an
    external camera)."""
    tags = tags_for_preset(robot, options.free, robot.config.tag_ids, options.side)
    if options.free == "leg" and not external:
        tags = [t for t in tags if robot.config.tag(t).side is not None]
    if external:
        tags = sorted(set(tags) | {t for t in robot.config.tag_ids if robot.off_the_legs(robot.config.tag(t).link)})
    if not tags:
        raise WolfcalError(f"{robot.config.path}: --free leg --system {options.system} needs tags on the feet marked "
                           "'side: right' or 'side: left' under 'tags:' (none of "
                           f"{', '.join(map(str, robot.config.tag_ids))} has one)")  # fmt: skip
    return tags


def seen_tags(robot: Robot, options: PlanOptions, tags: list[int], candidates: Candidates, say) -> list[int]:
    """The used tags some candidate shows; a leg-preset tag that none shows is an error, others a note."""
    seen = [t for t in tags if candidates.visible[:, robot.config.tag_ids.index(t)].any()]
    for t in sorted(set(tags) - set(seen)):
        tag = robot.config.tag(t)
        message = (f"tag {t} (on {tag.link}) is in view in none of the {len(candidates.q)} candidate poses, so the "
                   f"--system {options.system} camera cannot observe the joints behind it")  # fmt: skip
        if options.free == "leg" and tag.side is not None:
            raise WolfcalError(f"{message}; choose another --side or --system, or move the tag")
        say(f"note: {message}; it is left out")
    return seen


def system_candidates(robot: Robot, options: PlanOptions, collisions: CollisionModel, rng: np.random.Generator,
                      say: Callable[[str], None]) -> tuple[PlanModelLike, Candidates, list[str]]:  # fmt: skip
    """The fit a plan is made for, its candidate poses and what the plan assumes, per measurement system."""
    for warning in collisions.warnings:
        say(f"warning: {warning}")
    for note in collisions.notes:
        say(f"note: {note}")
    say(f"drawing {options.candidates} candidate poses (collisions: capsules from {collisions.source}) ...")
    notes: list[str] = []
    model: PlanModelLike
    if options.system == "mocap":
        markers = used_markers(robot, options.free, options.side)
        candidates = draw_mocap_candidates(robot, markers, options.candidates, rng, collisions, options.margin)
        model = MocapPlanModel(robot, options.free, options.side, markers)
        notes.append(f"every one of the {len(markers)} markers counts as measured in every pose (cameras all around)")
    elif options.system == "floor":
        camera = plan_camera(robot, "head")
        places = expected_places(robot)
        candidates = draw_floor_candidates(robot, camera, places, options.candidates, rng, collisions, options.margin)
        model = FloorPlanModel(robot, camera, options.free, options.side, places)
        notes.append(f"floor tags lying face up (yaw 0, floor frame: x ahead) at: {places_text(places)}")
    else:
        camera = plan_camera(robot, options.system, options.external, options.placement)
        tags = used_tags(robot, options, camera.external)
        candidates = draw_candidates(robot, camera, tags, options.candidates, rng, collisions, options.margin)
        model = PlanModel(robot, camera, options.free, options.side, seen_tags(robot, options, tags, candidates, say))
    say(f"{len(candidates.q)} candidates from {candidates.drawn} random poses; left out: "
        + ", ".join(f"{k} {v}" for k, v in candidates.rejected.items()))  # fmt: skip
    return model, candidates, notes


def make_plan(robot: Robot, options: PlanOptions, say: Callable[[str], None] = print) -> Plan:
    """Candidates, selection and order (no file written)."""
    rng = np.random.default_rng(options.seed)
    collisions = collision_model(robot)
    model, candidates, notes = system_candidates(robot, options, collisions, rng, say)
    problem = model.problem(candidates.q, candidates.visible, independent=True)
    G = factors(problem)
    M_repeated = model.repeated_information(problem, candidates.q, candidates.visible, options.poses)
    sep = separability(G, problem.n_chain, M_repeated, criterion_interest(problem.params, problem.n_chain))
    check_observable(problem.params, G, M_repeated, len(G))
    chain = ParameterSet(problem.params.parameters[: problem.n_chain])
    criterion = check_criterion(str(options.criterion))  # set in __post_init__
    basis = deliverable_basis(robot, chain, options.free) if criterion == "I" else sep.basis
    say(f"choosing {options.poses} poses ({criterion}-optimal) ...")
    chosen, value = select(G, options.poses, basis, criterion, M_repeated)
    if options.system == "floor":  # the fit refuses a floor tag seen once
        labels = [f"floor tag {t}" for t in robot.config.floor_config().tag_ids]
        chosen = cover_twice(G, chosen, candidates.visible, labels, basis, criterion, M_repeated)
        value = criterion_value(information(G, chosen, M_repeated), basis, criterion)
    order, move_time = capture_order(candidates.q[chosen], rest_configuration(robot), options.velocity)
    chosen = np.array(chosen)[order]
    others = rng.choice(np.setdiff1d(np.arange(len(G)), chosen), size=min(options.poses, len(G) - len(chosen)),
                        replace=False) if len(G) > len(chosen) else chosen  # fmt: skip
    planned_problem = model.problem(candidates.q[chosen], candidates.visible[chosen])
    random_problem = model.problem(candidates.q[others], candidates.visible[others])
    observable = ~sep.unseparable
    planned, random = predicted(planned_problem), predicted(random_problem)
    return Plan(
        q=candidates.q[chosen], joints=candidates.joints,
        move_time_s=move_time, params=problem.params, n_chain=problem.n_chain,
        planned=planned, random=random, observable=observable,
        groups=sep.groups(problem.params.names), candidates=candidates,
        at_prior=np.array([sep.at_prior(i) for i in range(len(problem.params))], dtype=bool),
        condition=(_condition(planned_problem, problem.params.names, observable),
                   _condition(random_problem, problem.params.names, observable)),
        planned_names=planned_problem.params.names, notes=notes, criterion_value=value,
        delivered=_delivered(robot, chain, options.free, planned, random),
    )  # fmt: skip


def _delivered(robot: Robot, chain: ParameterSet, preset: str, planned: Uncertainty, random: Uncertainty):
    """(planned, random) rms predicted std of the delivered rotation [rad] and position [m]; None when the free
    parameters move nothing the preset delivers (e.g. `camera` with an external camera: only the tags' mounts)."""
    c = len(chain)
    try:
        return tuple(delivered_std(robot, chain, preset, u.covariance[:c, :c]) for u in (planned, random))
    except WolfcalError:
        return None


def _condition(problem, names: list[str], observable: np.ndarray) -> float:
    """Condition number of the column-scaled Jacobian over the observable parameters (the others at their prior;
    observable (P,) over `names`, which hold the problem's: a pose set may show fewer floor tags than the
    candidates)."""
    keep = np.array([observable[names.index(n)] for n in problem.params.names], dtype=bool)
    J = np.asarray(problem.data_jacobian(np.zeros(len(problem.params)), robust=False))
    return uncertainty(J[:, keep], problem.params.prior_sigmas[keep]).condition_number


def poses_text(robot: Robot, plan: Plan, options: PlanOptions) -> str:
    """The poses file (`wolfcal capture --poses` format) of a plan."""
    columns = [robot.model.column(j) for j in plan.joints]
    lines = [
        f"# Planned by `wolfcal plan --free {options.free} --side {options.side} --system {options.system} "
        f"--criterion {options.criterion}` for {robot.config.name}: {len(plan.q)} poses chosen from "
        f"{len(plan.candidates.q)} candidates,",
        f"# ordered for short moves (about {plan.move_time_s:.0f} s of moves at {options.velocity:.2g} rad/s). "
        "Joint readings [rad]; every joint the plan moves is named.",
        *[f"# Assumed: {note}." for note in plan.notes],
        f"velocity: {options.velocity}",
        "poses:",
    ]
    for i, q in enumerate(plan.q):
        joints = ", ".join(f"{j}: {q[c]:.5f}" for j, c in zip(plan.joints, columns))
        lines += [f"- name: plan{i + 1:02d}", f"  joints: {{{joints}}}"]
    return "\n".join(lines) + "\n"


def table_lines(plan: Plan) -> list[str]:
    """The printed comparison: per free parameter, predicted std for the planned and as many random poses."""
    n = len(plan.q)
    lines = [f"predicted standard deviation (configured noise) for {n} planned and {n} random candidate poses:",
             f"  {'parameter':44s} {'prior':>9s} {'planned':>9s} {'random':>9s}"]  # fmt: skip
    for i, p in enumerate(plan.params.parameters[: plan.n_chain]):
        scale, unit = (1000.0, "mm") if p.unit == "m" else (np.rad2deg(1.0), "deg")
        note = (
            ""
            if plan.observable[i]
            else (
                "  (no pose separates it: keeps its prior)"
                if plan.at_prior[i]
                else "  (no pose improves it: the view repeated in every pose bounds it)"
            )
        )
        lines.append(f"  {p.name:44s} {p.prior_sigma * scale:7.3f}{unit:>2s} {plan.planned.std[i] * scale:7.3f}"
                     f"{unit:>2s} {plan.random.std[i] * scale:7.3f}{unit:>2s}{note}")  # fmt: skip
    lines += [f"  assumed: {note}" for note in plan.notes]
    for unit, scale, shown in (("m", 1000.0, "mm"), ("rad", np.rad2deg(1.0), "deg")):
        planned, random = plan.worst_std(plan.planned, unit) * scale, plan.worst_std(plan.random, unit) * scale
        lines.append(f"  worst std of the observable parameters in {shown}: planned {planned:.3f}, random {random:.3f}")
    if plan.delivered is not None:
        (rot_p, pos_p), (rot_r, pos_r) = plan.delivered
        lines.append("  predicted rms error of the delivered pose (head camera or soles in the base frame over the "
                     "evaluation configurations of `--criterion I`, with what no pose separates at its prior): "
                     f"planned {np.rad2deg(rot_p):.4f} deg {pos_p * 1000:.3f} mm, random {np.rad2deg(rot_r):.4f} deg "
                     f"{pos_r * 1000:.3f} mm")  # fmt: skip
    lines.append(
        "  condition number (column-scaled Jacobian, observable parameters): "
        f"planned {plan.condition[0]:.3g}, random {plan.condition[1]:.3g}"
    )
    names = plan.params.names
    for group in plan.groups:
        if all(plan.at_prior[names.index(g)] for g in group):
            lines.append(f"  no pose separates {' ~ '.join(group)} (equivalent motions; they keep their prior)")
        else:
            lines.append(
                f"  no pose improves {' ~ '.join(group)} (bounded by their prior and the view repeated in "
                "every pose, whose detection error repeats too)"
            )
    observable_names = [nm for nm, ok in zip(names, plan.observable) if ok]
    chain_names = set(names[: plan.n_chain])
    for a, b, r in plan.planned.correlated_pairs(plan.planned_names):
        if a in observable_names and b in observable_names and chain_names & {a, b}:
            lines.append(f"  correlated in the plan: {a} ~ {b} ({r:+.2f})")
    return lines


def run_plan(robot_path: Path, out: Path, options: PlanOptions, say: Callable[[str], None] = print,
             force: bool = False) -> Plan:  # fmt: skip
    """The whole `wolfcal plan` job: writes the poses file `out` and prints the table."""
    robot = load_robot(robot_path)
    check_outputs([out], force, [robot.config.path, robot.config.urdf])
    plan = make_plan(robot, options, say)
    write_text_atomic(out, poses_text(robot, plan, options))
    for line in table_lines(plan):
        say(line)
    say(f"wrote {out}: {len(plan.q)} poses, about {plan.move_time_s:.0f} s of moves at {options.velocity} rad/s")
    return plan
