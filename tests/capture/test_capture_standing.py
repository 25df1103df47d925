"""`wolfcal capture --standing` through the real dynamixel-sdk against the Protocol 2.0 emulator on a pty: the IMU
is a device on the servo bus (the Wolfgang's board: float32 registers; the OP3's OpenCR: int16), served with gravity
in the IMU frame from the emulated robot's true angles, true mount and bias; the capture's recording fits back to
that mount. Bad input: no IMU at the configured id, a layout the device's control table does not hold, readings in
g; an interrupted capture keeps its stances and leaves the torque as chosen; several buses on one emulator."""

from __future__ import annotations

import io
import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import WOLFGANG, default_sigint
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rich.console import Console

from wolfcal.capture.emulate import emulated_imu
from wolfcal.capture.options import CaptureOptions
from wolfcal.capture.pipeline import run_capture
from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.fit.imu_block import ImuBlock
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import fit_observations
from wolfcal.hardware.bus import BusError
from wolfcal.hardware.buses import ServoBuses
from wolfcal.hardware.emulator import EmulatorProcess, spec_from_config
from wolfcal.hardware.imu_device import BusImu
from wolfcal.io.imu import read_standing
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.imu_mount import imu_config, imu_joint
from wolfcal.robot.robot import load_robot

DEG = float(np.rad2deg(1.0))
MOUNT = (0.011, -0.017)  # true roll, pitch correction of the IMU's mount [rad]
BIAS = [0.012, -0.009, 0.015]  # true accelerometer bias [m/s^2]
OPENCR = {"id": 200, "model": 29696,  # ROBOTIS OP3's OpenCR (OPEN-CR.device; open_cr_module's scale factors)
          "accel": {"address": 38, "type": "int16", "scale": 2.0 / 32768 * 9.80665},
          "gyro": {"address": 32, "type": "int16", "scale": 2000.0 / 32800 * math.pi / 180}}  # fmt: skip
WAIT_S = 60.0  # generous: tests must pass on a busy machine


def write_config(folder: Path, bus: dict | None = None, ports: dict | None = None) -> Path:
    """The Wolfgang's robot.yaml with absolute paths, `imu.bus` replaced by `bus` when given, `servos.ports` when
    given; written to folder/robot.yaml."""
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = str(WOLFGANG / data["urdf"])
    for camera in [data["camera"], *data.pop("external_cameras")]:
        camera["intrinsics"] = str(WOLFGANG / camera["intrinsics"])
    if bus is not None:
        data["imu"]["bus"] = bus
    if ports is not None:
        data["servos"].pop("port")
        data["servos"]["ports"] = ports
    (folder / "robot.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return folder / "robot.yaml"


def emulator(config_path: Path, truth: Corrections | None = None, bias=(0.0, 0.0, 0.0)) -> EmulatorProcess:
    robot = load_robot(config_path)
    spec = spec_from_config(robot.config, truth, imu=emulated_imu(robot, truth, None))
    assert spec.imu is not None
    spec.imu.bias = tuple(bias)
    return EmulatorProcess(spec)


def quiet() -> Console:
    return Console(file=io.StringIO(), force_terminal=False)


@pytest.mark.slow
def test_standing_capture_fits_back_to_the_emulators_mount(tmp_path):
    robot = load_robot(WOLFGANG)
    joint = imu_joint(robot)
    truth = Corrections(frames={joint: np.array([0.0, 0.0, 0.0, *MOUNT, 0.0])})
    out = tmp_path / "standing.mcap"
    with emulator(WOLFGANG / "robot.yaml", truth, BIAS) as emu:
        options = CaptureOptions(robot=WOLFGANG, out=out, port=emu.port, standing=True, yes=True, velocity=3.0,
                                 samples=7)  # fmt: skip
        summary = run_capture(options, quiet())
        with ServoBuses(robot.config.servos, emu.port) as bus:
            assert not any(bus.torque_enabled().values()), "--exit-torque restore: the legs were off at the start"
    assert summary.samples == 7 and summary.path == out and not summary.skipped
    samples = read_standing([out], robot.config.joint_states_topic, imu_config(robot).topic, robot.joint_names)
    assert samples.n_samples == 7, samples.notes
    fit = fit_observations(robot, {}, FitOptions(free="imu", system="imu"), own_blocks=[ImuBlock(robot, samples)])
    idx = [fit.params.names.index("imu.rx"), fit.params.names.index("imu.ry")]
    error = (fit.solution.values[idx] - np.array(MOUNT)) * DEG
    found, std = np.round(fit.solution.values[idx] * DEG, 3), np.round(fit.solution.std[idx] * DEG, 3)
    print(f"recovered mount {found} deg, true {np.round(np.array(MOUNT) * DEG, 3)} deg, std {std} deg")
    assert np.all(np.abs(error) < 0.15), f"mount error {error} deg"
    assert np.all(np.abs(error) < 3.0 * fit.solution.std[idx] * DEG)
    with out.open("rb") as handle:  # the Imu messages as an independent reader sees them
        messages = [m for _, c, _, m in make_reader(handle, decoder_factories=[DecoderFactory()])
                    .iter_decoded_messages(topics=["/imu/data"])]  # fmt: skip
    assert messages and all(m.header.frame_id == "imu_frame" for m in messages)
    assert all(m.orientation_covariance[0] == -1.0 for m in messages)
    size = np.median([np.linalg.norm([m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z])
                      for m in messages])  # fmt: skip
    assert size == pytest.approx(9.80665, abs=0.05), "linear_acceleration in m/s^2"


def test_bad_imu_devices_are_named(tmp_path):
    """One emulated OpenCR (id 200, int16 registers), read with configs that name another id, a layout its control
    table does not hold, and a scale that leaves out g (the OP3 driver's factor 9.80665); then the right layout, but
    the operator does not confirm the torque."""
    served = write_config(tmp_path, OPENCR)
    cases = [
        ({**OPENCR, "id": 201}, r"IMU \(id 201\).*no answer.*'imu\.bus\.id'"),
        ({**OPENCR, "accel": {**OPENCR["accel"], "address": 300}}, r"IMU \(id 200\).*do not fit its control table"),
        ({**OPENCR, "accel": {**OPENCR["accel"], "scale": 2.0 / 32768}}, r"in g, not m/s\^2.*'imu\.bus\.accel\.scale'"),
    ]
    with emulator(served) as emu:
        with ServoBuses(load_robot_config(served).servos, emu.port) as bus:  # the right layout reads gravity
            accel, gyro = BusImu(bus.buses[0], imu_config(load_robot(served)).bus).read()
            assert np.linalg.norm(accel) == pytest.approx(9.80665, abs=0.15) and np.linalg.norm(gyro) < 0.05
        for k, (layout, words) in enumerate(cases):
            folder = tmp_path / str(k)
            folder.mkdir()
            out = folder / "s.mcap"
            options = CaptureOptions(robot=write_config(folder, layout), out=out, port=emu.port, standing=True,
                                     yes=True)  # fmt: skip
            with pytest.raises(BusError, match=f"(?s){words}"):
                run_capture(options, quiet())
            assert not out.exists() and not list(folder.glob("*.partial")), "nothing moved, nothing written"
        asked: list[str] = []  # the right layout, but the operator says no
        options = CaptureOptions(robot=served, out=tmp_path / "no.mcap", port=emu.port, standing=True)
        with pytest.raises(WolfcalError, match="not confirmed"):
            run_capture(options, quiet(), ask=lambda question: asked.append(question) or False)
        assert "Torque goes ON on 12 leg joint(s)" in asked[0] and not (tmp_path / "no.mcap").exists()
        with ServoBuses(load_robot_config(served).servos, emu.port) as bus:
            assert not any(bus.torque_enabled().values())


@pytest.mark.parametrize("bus, words", [
    ({**OPENCR, "gyro": {**OPENCR["gyro"], "address": 40}}, "overlap"),
    ({**OPENCR, "accel": {**OPENCR["accel"], "type": "int12"}}, "'imu.bus.accel.type'"),
    ({**OPENCR, "accel": {"address": 38, "type": "int16"}}, "'imu.bus.accel'"),
    ({**OPENCR, "id": 254}, "'imu.bus.id'"),
])  # fmt: skip
def test_bad_layouts_are_named_when_the_config_loads(tmp_path, bus, words):
    with pytest.raises(WolfcalError, match="robot.yaml") as info:
        load_robot_config(write_config(tmp_path, bus))
    assert words in str(info.value)


def test_standing_options_are_checked_before_anything_opens(tmp_path):
    with pytest.raises(WolfcalError, match="drop --camera"):
        run_capture(CaptureOptions(robot=WOLFGANG, out=tmp_path / "s.mcap", camera="sim", standing=True), quiet())
    data = yaml.safe_load(write_config(tmp_path).read_text())
    del data["imu"]["bus"]
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(WolfcalError, match="no 'imu.bus'.*ros2 bag record"):
        run_capture(CaptureOptions(robot=tmp_path, out=tmp_path / "s.mcap", standing=True, yes=True), quiet())


@pytest.mark.slow
def test_an_interrupted_standing_capture_keeps_its_stances_and_restores_the_torque(tmp_path):
    robot = load_robot(WOLFGANG)
    out = tmp_path / "cut.mcap"
    with emulator(WOLFGANG / "robot.yaml") as emu:
        command = [sys.executable, "-m", "wolfcal.cli", "capture", "--standing", "--robot", str(WOLFGANG),
                   "--port", emu.port, "--yes", "--velocity", "3", "--out", str(out)]  # fmt: skip
        process = subprocess.Popen(command, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                                   cwd=Path(__file__).resolve().parents[2], preexec_fn=default_sigint)  # fmt: skip
        try:
            assert process.stderr is not None
            for line in process.stderr:  # an event: stance 2 is held and on disk
                if line.startswith("stance 2/"):
                    process.send_signal(signal.SIGINT)
                    break
            stderr = process.stderr.read()
            code = process.wait(WAIT_S)
        finally:
            process.kill()
        assert code != 0 and "held stance(s) saved in" in stderr, stderr
        with ServoBuses(robot.config.servos, emu.port) as bus:
            assert not any(bus.torque_enabled().values()), stderr
    samples = read_standing([out], robot.config.joint_states_topic, "/imu/data", robot.joint_names)
    assert samples.n_samples >= 2


def test_the_emulator_serves_every_bus_and_the_imu_on_its_own(tmp_path):
    """`servos.ports` with two buses: one emulator process, one pty each; the IMU on the second bus
    (`imu.bus.port`), its gravity from the true angles of both."""
    config = load_robot_config(WOLFGANG)
    legs = [config.servos.ids[j] for j in ("RHipPitch", "LHipPitch", "RKnee", "LKnee")]
    ports = {"/dev/ttyUSB0": [i for i in config.servos.ids.values() if i not in legs], "/dev/ttyUSB1": legs}
    path = write_config(tmp_path, {**OPENCR, "port": "/dev/ttyUSB1"}, ports)
    with emulator(path) as emu:
        assert list(emu.ports) == list(ports) and len(set(emu.ports.values())) == 2
        servos = load_robot_config(path).servos
        with ServoBuses(servos, emu.port_option) as bus:
            bus.ping_all()
            assert len(bus.read_state().ticks) == len(config.servos.ids)
            accel, _ = BusImu(bus.bus_on("/dev/ttyUSB1"), imu_config(load_robot(path)).bus).read()
            assert np.linalg.norm(accel) == pytest.approx(9.80665, abs=0.15)
            other = bus.bus_on("/dev/ttyUSB0")
            assert other.ph.ping(other.port, OPENCR["id"])[1] != 0, "the IMU answers on its own bus only"
        with pytest.raises(WolfcalError, match="/dev/ttyUSB1 is missing"):
            ServoBuses(servos, f"/dev/ttyUSB0={emu.ports['/dev/ttyUSB0']}")


def test_command_line_emulate_serves_every_bus_of_the_config(tmp_path):
    config = load_robot_config(WOLFGANG)
    legs = [i for j, i in config.servos.ids.items() if j.startswith(("R", "L")) and "Shoulder" not in j]
    ports = {"/dev/ttyUSB0": [i for i in config.servos.ids.values() if i not in legs], "/dev/ttyUSB1": legs}
    path = write_config(tmp_path, {**OPENCR, "port": "/dev/ttyUSB1"}, ports)
    emulate = subprocess.Popen([sys.executable, "-m", "wolfcal.cli", "emulate", "--robot", str(path)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               cwd=Path(__file__).resolve().parents[2])  # fmt: skip
    try:
        assert emulate.stdout is not None
        port = emulate.stdout.readline().strip()  # the first line: what capture --port takes
        served = dict(item.split("=") for item in port.split(","))
        assert list(served) == list(ports), port
        with ServoBuses(load_robot_config(path).servos, port) as bus:
            assert bus.ping_all() == config.servos.models
        emulate.send_signal(signal.SIGTERM)
        emulate.wait(WAIT_S)
    finally:
        emulate.kill()
    assert emulate.returncode == 0 and "the IMU (id 200)" in emulate.stdout.read()


def test_stances_outside_the_urdf_limits_are_refused_before_anything_opens(tmp_path):
    """`imu.stances` turning both hip yaws by 0.15 rad (a standing stance) where the URDF allows 0.1."""
    urdf = (WOLFGANG / "wolfgang.urdf").read_text()
    head, _, tail = urdf.partition('<joint name="LHipYaw"')
    tail = tail.replace('<limit lower="-1.5708" upper="1.5708"', '<limit lower="-0.1" upper="0.1"', 1)
    (tmp_path / "narrow.urdf").write_text(head + '<joint name="LHipYaw"' + tail)
    data = yaml.safe_load(write_config(tmp_path).read_text())
    data["urdf"] = "narrow.urdf"
    data["imu"]["stances"] = [{"RKnee": -0.5, "LKnee": 0.5}, {"LHipYaw": 0.15, "RHipYaw": 0.15}]
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    options = CaptureOptions(robot=tmp_path, out=tmp_path / "s.mcap", port="/dev/no-such-bus", standing=True, yes=True)
    with pytest.raises(
        WolfcalError, match=r"(?s)stance 1 of imu\.stances .*LHipYaw = .*limits \[-0\.1000, 0\.1000\].*nothing was"
    ):
        run_capture(options, quiet())
