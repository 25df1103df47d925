"""The serving loop: the emulated bus on a new pseudo-terminal, stepped every STEP_S and on every byte received."""

from __future__ import annotations

import os
import pty
import select
import time
import tty
from collections.abc import Callable
from multiprocessing.connection import Connection

from wolfcal.hardware.emulator.bus import EmulatedBus
from wolfcal.hardware.emulator.spec import EmulatorSpec
from wolfcal.hardware.emulator.true_state import TrueStatePublisher

STEP_S = 0.002  # longest wait for bus bytes or a control message between two steps


def serve(spec: EmulatorSpec, on_ready: Callable[[str], None], control: Connection | None = None) -> None:
    """Serve the bus on a new pty until the control connection closes or says 'stop' (or KeyboardInterrupt).

    `on_ready(port)` gets the slave path. Control messages: `Fault` objects (injected now, then confirmed with
    an 'injected' reply, so that the sender can wait for it instead of sleeping), 'stop'.
    """
    master, slave = pty.openpty()
    tty.setraw(slave)
    port = os.ttyname(slave)
    bus = EmulatedBus(spec)
    publisher = TrueStatePublisher(port, list(bus.true_angles()), spec.truth_path)
    publisher.publish(bus.true_angles())
    on_ready(port)
    watched = [master] + ([control] if control is not None else [])
    try:
        while True:
            ready, _, _ = select.select(watched, [], [], STEP_S)
            bus.step(time.monotonic())
            if master in ready:
                reply = bus.handle(os.read(master, 4096))
                if reply:
                    os.write(master, reply)
            if control is not None and control in ready:
                try:
                    message = control.recv()
                except EOFError:
                    break
                if message == "stop":
                    break
                bus.inject(message)
                control.send("injected")
            publisher.publish(bus.true_angles())
    finally:
        publisher.close()
        os.close(master)
        os.close(slave)
