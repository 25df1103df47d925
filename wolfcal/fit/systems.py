"""The registry of measurement systems: each system named once, with where its parts live.

A system is a way of measuring the robot: its block (what it predicts and how that changes, `wolfcal.fit.blocks`),
the reader that turns files into the block's observations, the simulator that writes data with known truth, and
the planner that draws candidate poses for `wolfcal plan`. Parts are named as 'module:attribute' and imported only
when asked for (`System.load`), so this module imports nothing of wolfcal: the robot config, the fit, the simulator
and the planner all read their lists of systems from here without importing each other (the dependency direction
of the house).

To add a system: write its block module (and reader, simulator, optional planner), add one `System` below, and
test its block with `wolfcal.fit.derivative_check.assert_block_derivatives`. A system with `fit_blocks` (and
`presets`) joins `wolfcal fit` through that builder alone: the solver, the result writer and the fit pipeline know
no system by name.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

ALL = "all"  # --system all: every system the data contain


@dataclass(frozen=True)
class System:
    """One measurement system. Parts: 'module:attribute' (None: the system has no such part)."""

    name: str  # as --system and result.yaml's blocks name it
    block: str  # the block class
    reader: str | None  # files -> the block's observations
    simulator: str | None  # simulated data with known truth
    planner: str | None  # candidate poses for `wolfcal plan` (None: not planned)
    selectable: bool = True  # `--system NAME` of fit and simulate picks it (floor: reached through the head camera)
    sampling_ranges: bool = False  # the robot config's `sampling_ranges` may hold its joint ranges
    # a fit builder (robot, captures, options, say) -> (list of blocks, captures it used), for systems that read their
    # own files beside the camera captures; None: the fit pipeline's camera and motion-capture paths build it
    fit_blocks: str | None = None
    # --free presets this system adds, each -> 'module:attribute' of a function (robot) -> list of chain Parameters
    presets: tuple[tuple[str, str], ...] = ()
    # its section of the robot config, under the system's name: 'module:attribute' of a parser (config path, data)
    # -> a typed section (`RobotConfig.section`); None: the system has none (or config.py reads it)
    config: str | None = None
    # judges held-out recordings of its own (fit_dir, result, robot, captures, out_dir, deploy_worse, say, present,
    # limits: the 'before' calibration and the verdict's limits) -> metrics.json's content, or None when the
    # captures are not its own (the camera evaluation judges them)
    evaluator: str | None = None
    description: str = ""

    def load(self, part: str) -> Any:
        """The part ('block', 'reader', 'simulator', 'planner', 'fit_blocks', 'config', 'evaluator') imported;
        LookupError when the system has none."""
        return load_attribute(getattr(self, part), f"{self.name} system's {part}")


def load_attribute(where: str | None, what: str) -> Any:
    """'module:attribute' imported; LookupError naming `what` for None."""
    if where is None:
        raise LookupError(f"the {what} is not registered")
    module, _, attribute = where.partition(":")
    return getattr(importlib.import_module(module), attribute)


SYSTEMS: tuple[System, ...] = (
    System(
        "head",
        "wolfcal.fit.camera_block:CameraBlock",
        "wolfcal.vision.observe:detect_observations",
        "wolfcal.sim.simulate:simulate_cameras",
        "wolfcal.plan.candidates:draw_candidates",
        sampling_ranges=True,
        description="tags on links seen by the head camera [px]",
    ),
    System(
        "external",
        "wolfcal.fit.camera_block:CameraBlock",
        "wolfcal.vision.observe:detect_observations",
        "wolfcal.sim.simulate:simulate_cameras",
        "wolfcal.plan.candidates:draw_candidates",
        sampling_ranges=True,
        description="tags on links seen by a camera on a tripod [px]",
    ),
    System(
        "mocap",
        "wolfcal.fit.mocap_block:MocapBlock",
        "wolfcal.io.mocap_load:load_marker_observations",
        "wolfcal.sim.simulate:simulate_mocap_session",
        "wolfcal.plan.mocap:draw_mocap_candidates",
        sampling_ranges=True,
        description="markers on links measured by motion capture [m]",
    ),
    System(
        "floor",
        "wolfcal.fit.floor_block:FloorBlock",
        "wolfcal.vision.observe:detect_observations",
        "wolfcal.sim.floor:floor_views",
        "wolfcal.plan.floor:draw_floor_candidates",
        selectable=False,
        description="tags lying on the floor seen by the head camera while the robot stands [px]",
    ),
    System(
        "imu",
        "wolfcal.fit.imu_block:ImuBlock",
        "wolfcal.io.imu:read_standing",
        "wolfcal.sim.imu:simulate_imu",
        None,
        fit_blocks="wolfcal.fit.imu_block:imu_fit_blocks",
        presets=(("imu", "wolfcal.robot.imu_mount:imu_parameters"),),
        config="wolfcal.robot.imu_mount:parse_imu_config",
        evaluator="wolfcal.evaluate.imu:evaluate_held_out",
        description="gravity in the IMU frame while the robot stands still, soles flat [rad]",
    ),
    System(
        "field",
        "wolfcal.fit.field_block:FieldBlock",
        "wolfcal.field.observe:field_observations",
        "wolfcal.sim.field:simulate_field_capture",
        None,
        fit_blocks="wolfcal.fit.field_fit:field_blocks",
        evaluator="wolfcal.evaluate.field_check:evaluate_held_out",
        description="the white lines of a RoboCup field seen by the head camera while the robot stands [px]",
    ),
)


def system(name: str) -> System:
    """The registered system of that name; LookupError naming the registered ones."""
    for entry in SYSTEMS:
        if entry.name == name:
            return entry
    raise LookupError(f"no measurement system {name!r}; registered: {', '.join(s.name for s in SYSTEMS)}")


def selectable_systems() -> tuple[str, ...]:
    """Names `--system` of `wolfcal fit` takes (with `all`)."""
    return (*(s.name for s in SYSTEMS if s.selectable), ALL)


def simulated_systems() -> tuple[str, ...]:
    """Names `--system` of `wolfcal simulate` takes (with `all`: every camera in every sample)."""
    return (*(s.name for s in SYSTEMS if s.selectable and s.simulator), ALL)


def planned_systems() -> tuple[str, ...]:
    """Names `--system` of `wolfcal plan` takes."""
    return tuple(s.name for s in SYSTEMS if s.planner)


def sampling_systems() -> tuple[str, ...]:
    """Keys of the robot config's `sampling_ranges`."""
    return tuple(s.name for s in SYSTEMS if s.sampling_ranges)


def evaluating_systems() -> tuple[System, ...]:
    """Systems that judge held-out recordings of their own (`System.evaluator`)."""
    return tuple(s for s in SYSTEMS if s.evaluator)


def own_file_systems() -> tuple[System, ...]:
    """Systems that read their own files beside the camera captures (`System.fit_blocks`)."""
    return tuple(s for s in SYSTEMS if s.fit_blocks)


def system_presets() -> dict[str, str]:
    """--free presets the systems add -> 'module:attribute' of their parameter function."""
    return {name: where for s in SYSTEMS for name, where in s.presets}


def config_sections() -> dict[str, Any]:
    """Robot config keys the systems add -> their parsers (imported)."""
    return {s.name: s.load("config") for s in SYSTEMS if s.config}


def block_class(system_name: str) -> Any:
    """The block class of a system (for `summary_lines` of a result read back); the base `Block` for a name not
    registered (a file written by another version)."""
    try:
        return system(system_name).load("block")
    except LookupError:
        return load_attribute("wolfcal.fit.blocks:Block", "measurement block base")
