"""The serving loop: each emulated bus on a new pseudo-terminal (one per `servos.ports` device, or one), all stepped
every STEP_S and on every byte received, in one process: the IMU's gravity needs the true angles of every bus."""

from __future__ import annotations

import os
import pty
import select
import time
import tty
from collections.abc import Callable
from dataclasses import replace
from multiprocessing.connection import Connection

from wolfcal.hardware.emulator.bus import EmulatedBus
from wolfcal.hardware.emulator.imu import EmulatedImu
from wolfcal.hardware.emulator.spec import EmulatorSpec
from wolfcal.hardware.emulator.true_state import TrueStatePublisher

STEP_S = 0.002  # longest wait for bus bytes or a control message between two steps


def serve(spec: EmulatorSpec, on_ready: Callable[[dict[str | None, str]], None],
          control: Connection | None = None) -> None:  # fmt: skip
    """Serve the buses on new ptys until the control connection closes or says 'stop' (or KeyboardInterrupt).

    `on_ready(ports)` gets the slave path of each bus by config device (`servos.ports`; {None: path} for one
    bus). Control messages: `Fault` objects (injected now, then confirmed with an 'injected' reply, so that the
    sender can wait for it instead of sleeping), 'stop'.
    """
    buses: list[EmulatedBus] = []
    imu = (
        EmulatedImu(spec.imu, lambda: {j: a for bus in buses for j, a in bus.true_angles().items()})
        if spec.imu
        else None
    )
    first = next(iter(spec.buses()))
    ttys: dict[int, tuple[int, EmulatedBus, TrueStatePublisher]] = {}
    ports: dict[str | None, str] = {}
    try:
        for device, servos in spec.buses().items():
            master, slave = pty.openpty()
            tty.setraw(slave)
            ports[device] = os.ttyname(slave)
            on_this = imu is not None and device == (spec.imu_port or first)
            bus = EmulatedBus(replace(spec, servos=servos), imu if on_this else None)
            buses.append(bus)
            publisher = TrueStatePublisher(ports[device], list(bus.true_angles()), spec.truth_path)
            publisher.publish(bus.true_angles())
            ttys[master] = (slave, bus, publisher)
        on_ready(ports)
        _loop(ttys, control)
    finally:
        for master, (slave, _, publisher) in ttys.items():
            publisher.close()
            os.close(master)
            os.close(slave)


def _loop(ttys: dict[int, tuple[int, EmulatedBus, TrueStatePublisher]], control: Connection | None) -> None:
    watched: list = [*ttys] + ([control] if control is not None else [])
    while True:
        ready, _, _ = select.select(watched, [], [], STEP_S)
        now = time.monotonic()
        for _, bus, _ in ttys.values():
            bus.step(now)
        for master, (_, bus, _) in ttys.items():
            if master in ready:
                reply = bus.handle(os.read(master, 4096))
                if reply:
                    os.write(master, reply)
        if control is not None and control in ready:
            try:
                message = control.recv()
            except EOFError:
                return
            if message == "stop":
                return
            for _, bus, _ in ttys.values():
                bus.inject(message)
            control.send("injected")
        for _, bus, publisher in ttys.values():
            publisher.publish(bus.true_angles())
