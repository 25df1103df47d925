"""Protocol 2.0 packets, the bus emulator and `DynamixelBus` through the real dynamixel-sdk on a pty."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import numpy as np
import pytest

from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.hardware import protocol as P
from wolfcal.hardware.bus import BusError, DynamixelBus, JointState, rad_to_ticks, ticks_to_rad
from wolfcal.hardware.emulator import (
    EmulatorProcess,
    Fault,
    parse_fault,
    read_true_angles,
    spec_from_config,
)
from wolfcal.robot.corrections import Corrections

ROBOT = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"
WAIT_S = 30.0  # generous: tests must pass on a busy machine


def read_until(bus: DynamixelBus, condition) -> JointState:
    """Read the bus until `condition(state)` holds (each read is itself a wait on the emulator's answer)."""
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        state = bus.read_state()
        if condition(state):
            return state
    raise AssertionError(f"condition not met within {WAIT_S:.0f} s")


@pytest.fixture(scope="module")
def config():
    return load_robot_config(ROBOT)


# --- packets ------------------------------------------------------------------------------------------------
def test_crc_matches_the_reference_vectors():
    assert P.build_packet(1, P.PING)[-2:] == bytes([0x19, 0x4E])
    assert P.build_status(1, 0, bytes([0x06, 0x04, 0x26]))[-2:] == bytes([0x65, 0x5D])
    read = P.build_packet(1, P.READ, (132).to_bytes(2, "little") + (4).to_bytes(2, "little"))
    assert read[-2:] == bytes([0x1D, 0x15])


def test_byte_stuffing_round_trips_through_the_parser():
    params = bytes([0x74, 0x00, 0xFF, 0xFF, 0xFD, 0x01])
    packet = P.build_packet(7, P.WRITE, params)
    assert b"\xff\xff\xfd\xfd" in packet  # stuffed
    parsed = P.PacketParser().feed(b"\x00\x13" + packet + packet[:4])  # garbage before, a torn packet after
    assert parsed == [P.Packet(7, P.WRITE, params, True)]
    broken = bytearray(packet)
    broken[-1] ^= 1
    assert not P.PacketParser().feed(bytes(broken))[0].crc_ok


def test_ticks_and_radians():
    assert ticks_to_rad(2048) == 0.0
    assert ticks_to_rad(3072) == pytest.approx(math.pi / 2)
    assert ticks_to_rad(1024) == pytest.approx(-math.pi / 2)
    ticks = np.arange(0, 4096, 7)
    assert np.array_equal(rad_to_ticks(ticks_to_rad(ticks)), ticks)


def test_fault_syntax():
    assert parse_fault("no-answer:13@2.5") == Fault("no-answer", 13, 0, 2.5)
    assert parse_fault("hw-error:20") == Fault("hw-error", 20, 32, 0.0)
    assert parse_fault("model:7=1020") == Fault("model", 7, 1020, 0.0)
    assert parse_fault("late:13") == Fault("late", 13, 3, 0.0)
    for bad in ("smoke:3", "crc", "crc:x", "model:7"):
        with pytest.raises(WolfcalError):
            parse_fault(bad)


# --- the bus through the real SDK against the emulator ------------------------------------------------------
TRUTH = Corrections(offsets={"HeadTilt": 0.0123, "RKnee": -0.0311, "LAnklePitch": 0.02})


@pytest.fixture(scope="module")
def emulator(config):
    with EmulatorProcess(spec_from_config(config, TRUTH)) as emu:
        yield emu


def test_ping_and_read_report_true_angle_minus_offset(config, emulator):
    with DynamixelBus(config.servos, emulator.port) as bus:
        models = bus.ping_all()
        assert models == config.servos.models
        state = bus.read_state()
        true, _ = read_true_angles(emulator.port)
        for k, joint in enumerate(bus.joints):
            expected = round((true[joint] - TRUTH.offsets.get(joint, 0.0)) / (2 * math.pi / 4096)) + 2048
            assert state.ticks[k] == expected, joint
        assert state.ticks[bus.joints.index("RKnee")] == 2048 + round(0.0311 / (2 * math.pi / 4096))


def test_scripted_move_at_profile_velocity_arrives_exactly(config, emulator):
    with DynamixelBus(config.servos, emulator.port) as bus:
        joints = ["HeadTilt", "LKnee"]
        bus.set_profile_velocity(joints, 2.0)
        bus.set_torque(joints, True)
        assert bus.torque_enabled()["HeadTilt"]
        goal = {"HeadTilt": -0.8, "LKnee": 0.5}
        bus.set_goal_positions(goal)
        k = bus.joints.index("HeadTilt")
        moving = read_until(bus, lambda state: state.velocity_units[k] != 0)
        assert moving.velocities[k] == pytest.approx(-2.0, abs=0.03)  # signed, two's complement decoded
        state = read_until(bus, lambda state: not np.any(state.velocity_units))
        for joint, rad in goal.items():
            assert state.ticks[bus.joints.index(joint)] == rad_to_ticks(rad)
        true, _ = read_true_angles(emulator.port)
        assert true["HeadTilt"] == pytest.approx(ticks_to_rad(rad_to_ticks(-0.8)) + 0.0123, abs=1e-9)
        bus.set_torque(joints, False)


def test_many_sync_reads_in_a_row_all_answer(config, emulator):
    """The rate is the bench harness's `bus` part; here: no read is lost or mixed up with another's reply."""
    with DynamixelBus(config.servos, emulator.port) as bus:
        states = [bus.read_state() for _ in range(200)]
    assert all(np.array_equal(s.ticks, states[0].ticks) for s in states)


def test_missing_ids_and_wrong_models_are_listed_in_one_message(config):
    faults = [Fault("missing", 4), Fault("missing", 13), Fault("model", 20, 1020)]
    with (
        EmulatorProcess(spec_from_config(config, faults=faults)) as emu,
        DynamixelBus(config.servos, emu.port) as bus,
    ):
        with pytest.raises(BusError) as info:
            bus.ping_all()
    message = str(info.value)
    assert emu.port in message and "3 servo problem(s)" in message
    assert "LShoulderRoll (id 4): no answer" in message and "RKnee (id 13): no answer" in message
    assert "HeadTilt (id 20): model number 1020, expected 311" in message


@pytest.mark.parametrize(
    "fault, expected",
    [
        (Fault("no-answer", 13), r"failed at RKnee \(id 13\): There is no status packet"),
        # a corrupted answer; on a busy machine the last attempt may time out before it arrives
        (Fault("crc", 9), r"failed at RHipRoll \(id 9\): (Incorrect status packet|There is no status packet)"),
    ],
)
def test_communication_faults_name_the_servo(config, fault, expected):
    with EmulatorProcess(spec_from_config(config)) as emu, DynamixelBus(config.servos, emu.port) as bus:
        bus.read_state()
        emu.inject(fault)  # returns once the emulator has the fault
        with pytest.raises(BusError, match=expected) as info:
            bus.read_state()
    assert re.search(r"\d+ attempt\(s\) in \d+\.\d+ s, pausing 5-\d+ ms between them", str(info.value))
    if fault.kind == "no-answer":
        assert "timeout: no answer in time" in str(info.value)


def test_hardware_error_is_polled_and_cleared_by_reboot(config):
    with EmulatorProcess(spec_from_config(config)) as emu, DynamixelBus(config.servos, emu.port) as bus:
        bus.set_torque(["HeadPan"], True)
        emu.inject(Fault("hw-error", 19, 32 | 4))
        bus.read_state()  # sync read drops the alert bit: polling is what finds it
        assert bus.hardware_errors() == {"HeadPan": 36}
        with pytest.raises(BusError, match=r"HeadPan \(id 19\): overheating, overload"):
            bus.check_hardware()
        with pytest.raises(BusError, match="refused"):
            bus.set_torque(["HeadPan"], True)
        bus.reboot("HeadPan")  # acknowledged: done when it returns
        assert bus.hardware_errors() == {}
        assert not bus.torque_enabled()["HeadPan"]


def test_a_late_answer_is_waited_for_within_the_time_budget(config):
    """A servo that answers late (busy host or emulator) is retried with pauses, not reported dead at once."""
    with EmulatorProcess(spec_from_config(config)) as emu, DynamixelBus(config.servos, emu.port) as bus:
        before = bus.read_state()
        emu.inject(Fault("late", 13, 4))  # its next 4 replies come after the SDK stopped waiting
        assert np.array_equal(bus.read_state().ticks, before.ticks)
        emu.inject(Fault("late", 13, 10_000))  # too late for too long: a timeout error that says what was tried
        with pytest.raises(BusError, match=r"RKnee \(id 13\): .*timeout: no answer in time; \d+ attempt"):
            bus.read_state()


def test_opening_a_missing_port_names_it(config):
    with pytest.raises(BusError, match="/dev/ttyNOPE0: cannot open the servo bus"):
        DynamixelBus(config.servos, "/dev/ttyNOPE0").open()
