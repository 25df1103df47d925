"""A Dynamixel Protocol 2.0 servo bus on a pseudo-terminal, for dry runs and tests without a robot.

Each servo has a control table (see `protocol`), moves its true angle towards the goal at the profile velocity
while its torque is on, and reports what a real servo with a miscalibrated encoder would: `present position =
round((true angle - true offset) / (2 pi / 4096)) + 2048` ticks. With torque off an emulated operator
(optional) moves the limp joints through a list of poses, holding each for a while: manual capture.

The SDK busy-waits holding the GIL, so the emulator runs in its own process (`EmulatorProcess`, or the
`wolfcal emulate` command). The true joint angles are published in a small memory-mapped file beside the pty
name (`state_paths`) for the simulated camera, which renders the robot as it really is. Faults (`Fault`):
`no-answer` (a servo falls silent), `crc` (its replies are corrupted), `hw-error` (hardware error status bits:
alert bit in every reply, torque off until REBOOT), `missing` (the id is not on the bus), `model` (it reports
another model number). Each may start some seconds after the emulator.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import pty
import select
import signal
import tempfile
import time
import tty
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.hardware import protocol as P

RAD_PER_TICK = 2.0 * math.pi / P.TICKS_PER_TURN
RAD_S_PER_UNIT = P.RPM_PER_UNIT * 2.0 * math.pi / 60.0
MAX_SPEED = 5.0  # rad/s when the profile velocity is 0 (unlimited)
OPERATOR_SPEED = 1.5  # rad/s of the emulated operator moving limp joints
FAULT_KINDS = ("no-answer", "crc", "hw-error", "missing", "model")


@dataclass(frozen=True)
class Fault:
    kind: str
    servo_id: int
    value: int = 0  # hw-error: status bits (default overload, 32); model: the model number reported
    after_s: float = 0.0  # seconds after the emulator starts


def parse_fault(text: str) -> Fault:
    """`KIND:ID[=VALUE][@SECONDS]`, e.g. `no-answer:13@5`, `hw-error:20=32`, `model:7=1020`, `missing:4`."""
    try:
        kind, rest = text.split(":", 1)
        rest, _, after = rest.partition("@")
        sid, _, value = rest.partition("=")
        fault = Fault(
            kind,
            int(sid),
            int(value) if value else (32 if kind == "hw-error" else 0),
            float(after) if after else 0.0,
        )
    except ValueError:
        raise WolfcalError(
            f"--fault {text!r}: expected KIND:ID[=VALUE][@SECONDS] with KIND one of {', '.join(FAULT_KINDS)}"
        ) from None
    if fault.kind not in FAULT_KINDS:
        raise WolfcalError(f"--fault {text!r}: unknown kind {kind!r}; use one of {', '.join(FAULT_KINDS)}")
    if fault.kind == "model" and not fault.value:
        raise WolfcalError(f"--fault {text!r}: give the model number to report, e.g. model:{sid}=1020")
    return fault


@dataclass
class ServoSpec:
    joint: str
    model: int
    offset: float = 0.0  # true encoder offset: true angle = reading + offset [rad]
    angle: float = 0.0  # initial true angle [rad]


@dataclass
class EmulatorSpec:
    servos: dict[int, ServoSpec]
    faults: list[Fault] = field(default_factory=list)
    operator_poses: list[dict[str, float]] = field(
        default_factory=list
    )  # joint -> rad (readings), for manual mode
    operator_hold_s: float = 2.0
    operator_speed: float = OPERATOR_SPEED  # rad/s
    truth_path: str | None = None  # truth YAML the simulated camera renders with


def spec_from_config(
    config,
    truth=None,
    faults=(),
    operator_poses=(),
    hold_s: float = 2.0,
    truth_path: str | None = None,
    operator_speed: float = OPERATOR_SPEED,
) -> EmulatorSpec:
    """The emulated bus of a robot config (`RobotConfig`); true offsets from `truth` (`Corrections`)."""
    if config.servos is None:
        raise WolfcalError(f"{config.path}: no 'servos' section: the emulator needs the servo ids")
    offsets = truth.offsets if truth is not None else {}
    servos = {
        sid: ServoSpec(joint, config.servos.models.get(joint, 311), float(offsets.get(joint, 0.0)))
        for joint, sid in config.servos.ids.items()
    }
    return EmulatorSpec(
        servos, list(faults), [dict(p) for p in operator_poses], hold_s, operator_speed, truth_path
    )


def state_paths(port: str) -> tuple[Path, Path]:
    """(angles file, info JSON) where the emulator serving `port` publishes its true joint angles."""
    name = os.path.realpath(port).strip("/").replace("/", "-")
    folder = Path(tempfile.gettempdir()) / "wolfcal-emulator"
    return folder / f"{name}.bin", folder / f"{name}.json"


class _Servo:
    def __init__(self, sid: int, spec: ServoSpec):
        self.sid, self.spec = sid, spec
        self.table = bytearray(P.CONTROL_TABLE_SIZE)
        self.angle = spec.angle
        self.speed = 0.0
        self.silent = self.corrupt = self.missing = False
        self.write(P.MODEL_NUMBER, spec.model)
        self.write(P.FIRMWARE_VERSION, 46)
        self.write(P.ID, sid)
        self.write(P.GOAL_POSITION, self.reading())
        self.update_present()

    def read(self, item: tuple[int, int], signed: bool = False) -> int:
        addr, size = item
        return int.from_bytes(self.table[addr : addr + size], "little", signed=signed)

    def write(self, item: tuple[int, int], value: int) -> None:
        addr, size = item
        self.table[addr : addr + size] = int(value).to_bytes(size, "little", signed=value < 0)

    def reading(self) -> int:
        return int(round((self.angle - self.spec.offset) / RAD_PER_TICK)) + P.CENTRE_TICK

    def update_present(self) -> None:
        self.write(P.PRESENT_POSITION, self.reading())
        self.write(P.PRESENT_VELOCITY, int(round(self.speed / RAD_S_PER_UNIT)))

    def step(self, dt: float, operator_target: float | None, operator_speed: float) -> None:
        torque = self.read(P.TORQUE_ENABLE) == 1
        if torque:
            target = (
                self.read(P.GOAL_POSITION, signed=True) - P.CENTRE_TICK
            ) * RAD_PER_TICK + self.spec.offset
            profile = self.read(P.PROFILE_VELOCITY)
            vmax = profile * RAD_S_PER_UNIT if profile else MAX_SPEED
        elif operator_target is not None:
            target, vmax = operator_target, operator_speed
        else:
            target, vmax = self.angle, 0.0
        delta = target - self.angle
        move = math.copysign(min(abs(delta), vmax * dt), delta)
        self.angle += move
        self.speed = move / dt if dt > 0 and abs(delta) > 1e-12 else 0.0
        self.write(P.MOVING, int(abs(target - self.angle) > 1e-12))
        self.update_present()

    def error_byte(self) -> int:
        return P.ERR_ALERT if self.read(P.HARDWARE_ERROR_STATUS) else 0


class Emulator:
    """The bus state machine: feed it bytes from the master side of the pty, get reply bytes back."""

    def __init__(self, spec: EmulatorSpec):
        self.spec = spec
        self.servos = {sid: _Servo(sid, s) for sid, s in spec.servos.items()}
        self.parser = P.PacketParser()
        self.pending = sorted(spec.faults, key=lambda f: f.after_s)
        self.start = self.last = time.monotonic()
        self.operator_index = 0
        self.operator_since = self.start
        self.apply_faults(self.start)

    def apply_faults(self, now: float) -> None:
        while self.pending and self.pending[0].after_s <= now - self.start:
            self.inject(self.pending.pop(0))

    def inject(self, fault: Fault) -> None:
        servo = self.servos.get(fault.servo_id)
        if servo is None:
            return
        if fault.kind == "no-answer":
            servo.silent = True
        elif fault.kind == "crc":
            servo.corrupt = True
        elif fault.kind == "missing":
            servo.missing = True
        elif fault.kind == "model":
            servo.write(P.MODEL_NUMBER, fault.value)
        elif fault.kind == "hw-error":
            servo.write(P.HARDWARE_ERROR_STATUS, fault.value)
            servo.write(P.TORQUE_ENABLE, 0)

    def operator_targets(self, now: float) -> dict[int, float]:
        """True angles the emulated operator is moving the limp joints to (pose readings + true offsets)."""
        poses = self.spec.operator_poses
        if not poses:
            return {}
        limp = [s for s in self.servos.values() if s.read(P.TORQUE_ENABLE) == 0]
        pose = poses[self.operator_index % len(poses)]
        targets = {s.sid: pose[s.spec.joint] + s.spec.offset for s in limp if s.spec.joint in pose}
        arrived = all(abs(self.servos[sid].angle - a) < 1e-9 for sid, a in targets.items())
        if not arrived:
            self.operator_since = now
        elif now - self.operator_since >= self.spec.operator_hold_s:
            self.operator_index += 1
            self.operator_since = now
        return targets

    def step(self, now: float) -> None:
        self.apply_faults(now)
        dt, self.last = now - self.last, now
        targets = self.operator_targets(now)
        for servo in self.servos.values():
            servo.step(dt, targets.get(servo.sid), self.spec.operator_speed)

    def true_angles(self) -> dict[str, float]:
        return {s.spec.joint: s.angle for s in self.servos.values()}

    def handle(self, data: bytes) -> bytes:
        out = bytearray()
        for packet in self.parser.feed(data):
            if packet.crc_ok:
                out += self.answer(packet)
        return bytes(out)

    def _status(self, servo: _Servo, error: int, params: bytes = b"") -> bytes:
        if servo.silent or servo.missing:
            return b""
        packet = bytearray(P.build_status(servo.sid, error | servo.error_byte(), params))
        if servo.corrupt:
            packet[-1] ^= 0x5A
        return bytes(packet)

    def answer(self, packet: P.Packet) -> bytes:
        inst, params = packet.instruction, packet.params
        if inst == P.SYNC_READ and packet.servo_id == P.BROADCAST_ID and len(params) >= 4:
            addr, length = int.from_bytes(params[0:2], "little"), int.from_bytes(params[2:4], "little")
            out = b""
            for sid in params[4:]:
                if sid in self.servos:
                    out += self._read(self.servos[sid], addr, length)
            return out
        if inst == P.SYNC_WRITE and packet.servo_id == P.BROADCAST_ID and len(params) >= 4:
            addr, length = int.from_bytes(params[0:2], "little"), int.from_bytes(params[2:4], "little")
            for k in range(4, len(params) - length, length + 1):
                servo = self.servos.get(params[k])
                if servo is not None and not servo.missing and not servo.silent:
                    self._write(servo, addr, params[k + 1 : k + 1 + length])
            return b""
        servo = self.servos.get(packet.servo_id)
        if servo is None:
            return b""
        if inst == P.PING:
            return self._status(servo, 0, servo.read(P.MODEL_NUMBER).to_bytes(2, "little") + bytes([46]))
        if inst == P.READ and len(params) == 4:
            return self._read(
                servo, int.from_bytes(params[0:2], "little"), int.from_bytes(params[2:4], "little")
            )
        if inst == P.WRITE and len(params) >= 3:
            if servo.silent or servo.missing:
                return b""
            error = self._write(servo, int.from_bytes(params[0:2], "little"), params[2:])
            return self._status(servo, error)
        if inst == P.REBOOT:
            if servo.silent or servo.missing:
                return b""
            reply = self._status(servo, 0)
            servo.write(P.HARDWARE_ERROR_STATUS, 0)
            servo.write(P.TORQUE_ENABLE, 0)
            return reply
        return self._status(servo, P.ERR_INSTRUCTION)

    def _read(self, servo: _Servo, addr: int, length: int) -> bytes:
        if addr + length > P.CONTROL_TABLE_SIZE:
            return self._status(servo, P.ERR_ACCESS)
        return self._status(servo, 0, bytes(servo.table[addr : addr + length]))

    def _write(self, servo: _Servo, addr: int, data: bytes) -> int:
        if addr + len(data) > P.CONTROL_TABLE_SIZE:
            return P.ERR_ACCESS
        if addr == P.TORQUE_ENABLE[0] and data[:1] == b"\x01" and servo.read(P.HARDWARE_ERROR_STATUS):
            return P.ERR_RESULT_FAIL  # a servo in hardware error refuses torque until rebooted
        servo.table[addr : addr + len(data)] = data
        return 0


class _StatePublisher:
    """Writes the true joint angles to a memory-mapped file (seqlock: slot 0 counts writes, odd while writing)."""

    def __init__(self, port: str, emulator: Emulator, truth_path: str | None):
        self.bin_path, self.json_path = state_paths(port)
        self.bin_path.parent.mkdir(parents=True, exist_ok=True)
        self.joints = [s.spec.joint for s in emulator.servos.values()]
        self.json_path.write_text(
            json.dumps({"joints": self.joints, "truth": truth_path, "pid": os.getpid()})
        )
        self.array = np.lib.format.open_memmap(
            self.bin_path, mode="w+", dtype=np.float64, shape=(len(self.joints) + 1,)
        )

    def publish(self, angles: dict[str, float]) -> None:
        self.array[0] += 1
        self.array[1:] = [angles[j] for j in self.joints]
        self.array[0] += 1

    def close(self) -> None:
        for path in (self.bin_path, self.json_path):
            path.unlink(missing_ok=True)


def read_true_angles(port: str) -> tuple[dict[str, float], str | None]:
    """The true joint angles [rad] and truth YAML path published by the emulator serving `port`."""
    bin_path, json_path = state_paths(port)
    if not json_path.is_file():
        raise WolfcalError(
            f"{port}: no `wolfcal emulate` serves this port (no {json_path}); the 'sim' camera needs the emulator"
        )
    info = json.loads(json_path.read_text())
    try:
        os.kill(info["pid"], 0)
    except ProcessLookupError:
        raise WolfcalError(f"{port}: the emulator that served this port (pid {info['pid']}) has ended") from None
    array = np.load(bin_path, mmap_mode="r")
    for _ in range(100):
        seq = array[0]
        values = np.array(array[1:])
        if seq % 2 == 0 and array[0] == seq:
            break
        time.sleep(0.0005)
    return dict(zip(info["joints"], values.tolist(), strict=True)), info["truth"]


def load_truth(path: Path):
    """True corrections from a YAML file: a simulator's truth file (key 'truth') or a plain corrections file."""
    import yaml

    from wolfcal.robot.corrections import load_corrections

    try:
        data = yaml.safe_load(path.read_text()) if path.is_file() else None
    except yaml.YAMLError:
        data = None
    return load_corrections(path, key="truth" if isinstance(data, dict) and "truth" in data else None)


def serve(spec: EmulatorSpec, on_ready, control: Connection | None = None) -> None:
    """Serve the bus on a new pty until the control connection closes or says 'stop' (or KeyboardInterrupt).

    `on_ready(port)` gets the slave path. Control messages: `Fault` objects (injected now), 'stop'.
    """
    master, slave = pty.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    emulator = Emulator(spec)
    publisher = _StatePublisher(port, emulator, spec.truth_path)
    publisher.publish(emulator.true_angles())
    on_ready(port)
    watched = [master] + ([control] if control is not None else [])
    try:
        while True:
            ready, _, _ = select.select(watched, [], [], 0.002)
            now = time.monotonic()
            emulator.step(now)
            if master in ready:
                reply = emulator.handle(os.read(master, 4096))
                if reply:
                    os.write(master, reply)
            if control is not None and control in ready:
                try:
                    message = control.recv()
                except EOFError:
                    break
                if message == "stop":
                    break
                emulator.inject(message)
            publisher.publish(emulator.true_angles())
    finally:
        publisher.close()
        os.close(master)
        os.close(slave)


def _child(spec: EmulatorSpec, conn: Connection) -> None:
    try:
        serve(spec, conn.send, conn)
    except KeyboardInterrupt:
        pass


class EmulatorProcess:
    """The emulator in its own process: `with EmulatorProcess(spec) as emu: ... emu.port ...`."""

    def __init__(self, spec: EmulatorSpec):
        self.spec = spec
        self.port = ""
        ctx = multiprocessing.get_context("spawn")
        self.conn, child_conn = ctx.Pipe()
        self.process = ctx.Process(target=_child, args=(spec, child_conn), daemon=True)
        self.process.start()
        child_conn.close()
        if not self.conn.poll(30):
            self.stop()
            raise WolfcalError("the bus emulator did not start within 30 s")
        self.port = self.conn.recv()

    def inject(self, fault: Fault) -> None:
        """Inject a fault now."""
        self.conn.send(fault)

    def stop(self) -> None:
        if self.process.is_alive():
            try:
                self.conn.send("stop")
            except OSError:
                pass
            self.process.join(5)
            if self.process.is_alive():
                self.process.terminate()
                self.process.join(5)
        self.conn.close()

    def __enter__(self) -> EmulatorProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def emulate(
    robot_path: Path, truth: Path | None, faults: list[str], operator: Path | None, hold_s: float, say=print
) -> None:
    """`wolfcal emulate`: serve the robot's bus on a pty until Ctrl-C; prints the port to give --port."""
    from wolfcal.capture.poses import load_poses
    from wolfcal.robot.robot import load_robot

    robot = load_robot(robot_path)
    corrections = load_truth(truth) if truth is not None else None
    poses = []
    if operator is not None:
        limits = {j: (robot.model.joints[j].lower, robot.model.joints[j].upper) for j in robot.joint_names}
        poses = [p.joints for p in load_poses(operator, limits).poses]
    spec = spec_from_config(
        robot.config,
        corrections,
        [parse_fault(f) for f in faults],
        poses,
        hold_s,
        str(truth.resolve()) if truth is not None else None,
    )

    def ready(port: str) -> None:
        say(port)
        say(f"emulating {len(spec.servos)} servos of {robot.config.path} on {port} (Ctrl-C to stop)")

    def stop(signum: int, frame) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)  # clean up the published state on `kill` as on Ctrl-C
    try:
        serve(spec, ready)
    except KeyboardInterrupt:
        say("emulator stopped")
