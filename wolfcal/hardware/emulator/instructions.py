"""Answers of the emulated servos to Protocol 2.0 instruction packets: PING, READ, WRITE, REBOOT, SYNC READ,
SYNC WRITE; any other instruction gets an instruction error. A servo that a fault keeps off the bus neither
answers nor acts; a `crc` fault corrupts its replies."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

from wolfcal.hardware import protocol as P
from wolfcal.hardware.emulator.servo import FIRMWARE


class Device(Protocol):
    """What the answers need of a device on the bus (an `EmulatedServo`, the `EmulatedImu`)."""

    sid: int
    table: bytearray
    corrupt: bool
    late_replies: int
    stale_replies: int
    held: bytes

    @property
    def answers(self) -> bool: ...

    def read(self, item: tuple[int, int], signed: bool = False) -> int: ...

    def write(self, item: tuple[int, int], value: int) -> None: ...

    def error_byte(self) -> int: ...


def answer(servos: Mapping[int, Device], packet: P.Packet) -> bytes:
    """The reply bytes (possibly none) to one instruction packet with a good CRC."""
    inst, params = packet.instruction, packet.params
    if inst == P.SYNC_READ and packet.servo_id == P.BROADCAST_ID and len(params) >= 4:
        addr, length = _address_and_length(params)
        return b"".join(_read(servos[sid], addr, length) for sid in params[4:] if sid in servos)
    if inst == P.SYNC_WRITE and packet.servo_id == P.BROADCAST_ID and len(params) >= 4:
        addr, length = _address_and_length(params)
        for k in range(4, len(params) - length, length + 1):
            servo = servos.get(params[k])
            if servo is not None and servo.answers:
                _write(servo, addr, params[k + 1 : k + 1 + length])
        return b""
    servo = servos.get(packet.servo_id)
    if servo is None:
        return b""
    if inst == P.PING:
        return _status(servo, 0, servo.read(P.MODEL_NUMBER).to_bytes(2, "little") + bytes([FIRMWARE]))
    if inst == P.READ and len(params) == 4:
        return _read(servo, *_address_and_length(params))
    if inst == P.WRITE and len(params) >= 3:
        if not servo.answers:
            return b""
        error = _write(servo, int.from_bytes(params[0:2], "little"), params[2:])
        return _status(servo, error)
    if inst == P.REBOOT:
        if not servo.answers:
            return b""
        reply = _status(servo, 0)
        servo.write(P.HARDWARE_ERROR_STATUS, 0)
        servo.write(P.TORQUE_ENABLE, 0)
        return reply
    return _status(servo, P.ERR_INSTRUCTION)


def _address_and_length(params: bytes) -> tuple[int, int]:
    """(start address, data length) from the first four parameters of READ and SYNC READ/WRITE."""
    return int.from_bytes(params[0:2], "little"), int.from_bytes(params[2:4], "little")


def _status(servo: Device, error: int, params: bytes = b"") -> bytes:
    if not servo.answers:
        return b""
    if servo.late_replies:  # this reply would come after the master gave up waiting
        servo.late_replies -= 1
        return b""
    packet = bytearray(P.build_status(servo.sid, error | servo.error_byte(), params))
    if servo.corrupt:
        packet[-1] ^= 0x5A
    if servo.stale_replies:  # this reply comes so late that it arrives before the next one
        servo.stale_replies -= 1
        servo.held += bytes(packet)
        return b""
    held, servo.held = servo.held, b""
    return held + bytes(packet)


def _read(servo: Device, addr: int, length: int) -> bytes:
    if addr + length > len(servo.table):
        return _status(servo, P.ERR_ACCESS)
    return _status(servo, 0, bytes(servo.table[addr : addr + length]))


def _write(servo: Device, addr: int, data: bytes) -> int:
    """Write `data` into the control table at `addr`; the status error number (0: done)."""
    if addr + len(data) > len(servo.table):
        return P.ERR_ACCESS
    if addr == P.TORQUE_ENABLE[0] and data[:1] == b"\x01" and servo.read(P.HARDWARE_ERROR_STATUS):
        return P.ERR_RESULT_FAIL  # a servo in hardware error refuses torque until rebooted
    servo.table[addr : addr + len(data)] = data
    return 0
