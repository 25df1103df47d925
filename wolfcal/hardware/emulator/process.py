"""The emulator in a process of its own (the SDK busy-waits holding the GIL, so the two cannot share one)."""

from __future__ import annotations

import multiprocessing
from multiprocessing.connection import Connection

from wolfcal.errors import WolfcalError
from wolfcal.hardware.emulator.faults import Fault
from wolfcal.hardware.emulator.serve import serve
from wolfcal.hardware.emulator.spec import EmulatorSpec

START_TIMEOUT_S = 30.0


def port_option(ports: dict[str | None, str]) -> str:
    """`--port` of `wolfcal capture` for emulated buses: the pty of one bus, or DEVICE=PTY,... for several."""
    if list(ports) == [None]:
        return ports[None]
    return ",".join(f"{device}={path}" for device, path in ports.items())


def _child(spec: EmulatorSpec, conn: Connection) -> None:
    try:
        serve(spec, conn.send, conn)
    except KeyboardInterrupt:
        pass


class EmulatorProcess:
    """The emulator in its own process: `with EmulatorProcess(spec) as emu: ... emu.port ...`; `ports`: the pty of
    each bus by config device (`servos.ports`; {None: port} for one bus), `port` the first."""

    def __init__(self, spec: EmulatorSpec):
        self.port = ""
        self.ports: dict[str | None, str] = {}
        ctx = multiprocessing.get_context("spawn")
        self.conn, child_conn = ctx.Pipe()
        self.process = ctx.Process(target=_child, args=(spec, child_conn), daemon=True)
        self.process.start()
        child_conn.close()
        if not self.conn.poll(START_TIMEOUT_S):
            self.stop()
            raise WolfcalError(f"the bus emulator did not start within {START_TIMEOUT_S:.0f} s")
        self.ports = self.conn.recv()
        self.port = next(iter(self.ports.values()))

    @property
    def port_option(self) -> str:
        """What `wolfcal capture --port` takes for these buses: the pty, or DEVICE=PTY,... for several."""
        return port_option(self.ports)

    def inject(self, fault: Fault) -> None:
        """Inject a fault now; returns once the emulator has (every reply after this shows the fault)."""
        self.conn.send(fault)
        if not self.conn.poll(START_TIMEOUT_S) or self.conn.recv() != "injected":
            raise WolfcalError(f"the bus emulator did not confirm fault {fault} within {START_TIMEOUT_S:.0f} s")

    def stop(self) -> None:
        """Ask the emulator to stop; terminate it if it has not within 5 s."""
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
