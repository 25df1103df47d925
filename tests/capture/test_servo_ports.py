"""Servos on several buses (`servos.ports`): two Protocol 2.0 emulators on two ptys, each holding part of the
Wolfgang's servos, read and moved through the real dynamixel-sdk as one robot, and a scripted capture over both."""

from __future__ import annotations

import io
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from rich.console import Console

from wolfcal.capture.options import CaptureOptions
from wolfcal.capture.pipeline import run_capture
from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.hardware import protocol as P
from wolfcal.hardware.bus import BusError, rad_to_ticks
from wolfcal.hardware.buses import ServoBuses
from wolfcal.hardware.emulator import EmulatorProcess, Fault, parse_fault, read_true_angles, spec_from_config
from wolfcal.io.reader import read_capture
from wolfcal.robot.corrections import Corrections

ROBOT = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"
TRUTH = Corrections(offsets={"HeadTilt": 0.0123, "RKnee": -0.0311, "LElbow": 0.02})
LEGS = ["RHipYaw", "LHipYaw", "RHipRoll", "LHipRoll", "RHipPitch", "LHipPitch", "RKnee", "LKnee", "RAnklePitch",
        "LAnklePitch", "RAnkleRoll", "LAnkleRoll"]  # fmt: skip
WAIT_S = 30.0  # generous: tests must pass on a busy machine


def emulators(config, faults=()):
    """Two emulators: the legs on one bus, head and arms on the other (true offsets TRUTH)."""
    spec = spec_from_config(config, TRUTH, faults=faults)
    legs = {sid for joint, sid in config.servos.ids.items() if joint in LEGS}
    return (EmulatorProcess(replace(spec, servos={s: v for s, v in spec.servos.items() if s in legs})),
            EmulatorProcess(replace(spec, servos={s: v for s, v in spec.servos.items() if s not in legs})))  # fmt: skip


def two_bus_config(folder: Path, legs_port: str, rest_port: str) -> Path:
    """The Wolfgang's robot.yaml with `servos.ports` instead of `servos.port`, written to folder/robot.yaml."""
    data = yaml.safe_load((ROBOT / "robot.yaml").read_text())
    for key, parent in (("urdf", data), ("intrinsics", data["camera"])):
        parent[key] = str(ROBOT / parent[key])
    data.pop("external_cameras")
    ids = data["servos"].pop("ids")
    data["servos"].pop("port")
    data["servos"]["ports"] = {legs_port: [ids[j] for j in LEGS], rest_port: [i for j, i in ids.items()
                                                                              if j not in LEGS]}  # fmt: skip
    data["servos"]["ids"] = ids
    (folder / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return folder / "robot.yaml"


def test_two_buses_read_and_move_as_one_robot(tmp_path):
    config = load_robot_config(ROBOT)
    legs_emulator, rest_emulator = emulators(config)
    with legs_emulator as legs, rest_emulator as rest:
        servos = load_robot_config(two_bus_config(tmp_path, legs.port, rest.port)).servos
        assert servos.buses[legs.port] == tuple(config.servos.ids[j] for j in LEGS)
        with ServoBuses(servos) as bus:
            assert bus.joints == list(config.servos.ids) and bus.port_names == [legs.port, rest.port]
            assert bus.ping_all() == config.servos.models
            state = bus.read_state()
            true = {**read_true_angles(legs.port)[0], **read_true_angles(rest.port)[0]}
            for k, joint in enumerate(bus.joints):
                expected = round((true[joint] - TRUTH.offsets.get(joint, 0.0)) / (2 * math.pi / 4096)) + 2048
                assert state.ticks[k] == expected, joint
            goal = {"HeadTilt": -0.6, "RKnee": -0.9, "LElbow": 0.4}  # joints on both buses
            bus.set_profile_velocity(goal, 4.0)
            bus.set_torque(goal, True)
            assert all(bus.torque_enabled()[j] for j in goal)
            bus.set_goal_positions(goal)
            deadline = time.monotonic() + WAIT_S
            while time.monotonic() < deadline:  # each read waits on the emulators' answers
                state = bus.read_state()
                if all(state.ticks[bus.joints.index(j)] == rad_to_ticks(v) for j, v in goal.items()):
                    break
            else:
                raise AssertionError("the goals were not reached")
            assert read_true_angles(legs.port)[0]["RKnee"] == pytest.approx(-0.9 - 0.0311, abs=1e-3)
            bus.set_torque(goal, False)


def test_a_silent_servo_is_named_with_its_bus(tmp_path):
    config = load_robot_config(ROBOT)
    legs_emulator, rest_emulator = emulators(config, faults=[Fault("missing", config.servos.ids["LKnee"])])
    with legs_emulator as legs, rest_emulator as rest:
        servos = load_robot_config(two_bus_config(tmp_path, legs.port, rest.port)).servos
        with (
            ServoBuses(servos) as bus,
            pytest.raises(BusError, match=rf"(?s){legs.port}: 1 servo problem.*LKnee \(id 14\)"),
        ):
            bus.ping_all()
        with pytest.raises(WolfcalError, match="'servos.ports'"):
            ServoBuses(servos, port="/dev/ttyUSB9")


@pytest.mark.parametrize("ports, words", [
    ({"/dev/a": [1, 2]}, "leaves servo id(s)"),
    ({"/dev/a": list(range(1, 21)), "/dev/b": [3]}, "listed twice"),
    ({"/dev/a": [*range(1, 21), 99]}, "[99] not in 'ids'"),
    ({"/dev/a": []}, "non-empty list"),
])  # fmt: skip
def test_bad_ports_are_named(tmp_path, ports, words):
    data = yaml.safe_load((ROBOT / "robot.yaml").read_text())
    data["urdf"] = str(ROBOT / data["urdf"])
    data["camera"].pop("intrinsics")
    data.pop("external_cameras")
    data["servos"].pop("port")
    data["servos"]["ports"] = ports
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(WolfcalError, match="'servos'") as info:
        load_robot_config(tmp_path / "robot.yaml")
    assert words in str(info.value)


@pytest.mark.slow
def test_scripted_capture_over_two_buses(tmp_path):
    config = load_robot_config(ROBOT)
    poses = tmp_path / "poses.yaml"
    poses.write_text(yaml.safe_dump({"velocity": 4.0, "poses": [
        {"name": "a", "joints": {"HeadPan": 0.1, "HeadTilt": -1.2, "RKnee": -0.8, "LKnee": 0.8}},
        {"name": "b", "joints": {"HeadPan": -0.2, "HeadTilt": -1.0, "RHipPitch": -0.3, "LAnklePitch": -0.2}},
    ]}))  # fmt: skip
    legs_emulator, rest_emulator = emulators(config)
    with legs_emulator as legs, rest_emulator as rest:
        robot_yaml = two_bus_config(tmp_path, legs.port, rest.port)
        out = tmp_path / "two.mcap"
        options = CaptureOptions(robot=robot_yaml, out=out, camera="sim", poses=poses)
        summary = run_capture(options, Console(file=io.StringIO(), force_terminal=False))
    assert summary.samples == 2
    capture = read_capture(out, load_robot_config(robot_yaml))
    for sample, pose in zip(capture.samples, ({"RKnee": -0.8, "LKnee": 0.8}, {"RHipPitch": -0.3}), strict=True):
        readings = dict(zip(sample.joint_names, sample.positions, strict=True))
        for joint, value in pose.items():
            assert readings[joint] == pytest.approx(value, abs=2 * math.pi / 4096), joint
        assert np.isfinite(list(readings.values())).all() and len(readings) == len(config.servos.ids)


def test_a_stale_reply_is_not_taken_for_the_answer():
    """On a busy host the reply to a request the master gave up on can arrive just before the reply to the next
    one, and the SDK takes any status packet of the right id: servo 1's 1-byte reply to a torque read must not
    stand for its 8 bytes of position and velocity in the next sync read."""
    config = load_robot_config(ROBOT)
    with EmulatorProcess(spec_from_config(config, TRUTH)) as emu, ServoBuses(config.servos, emu.port) as buses:
        bus = buses.buses[0]
        first = bus.read_state()
        emu.inject(Fault("stale", 1, 1))  # its next reply held back
        assert bus.port is not None
        _, result, _ = bus.ph.read1ByteTxRx(bus.port, 1, P.TORQUE_ENABLE[0])  # the reply is held back: no answer
        assert result != 0
        assert np.array_equal(bus.read_state().ticks, first.ticks)
    assert parse_fault("stale:13") == Fault("stale", 13, 1, 0.0)  # `wolfcal emulate --fault stale:13`
