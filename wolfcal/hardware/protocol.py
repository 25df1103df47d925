"""Dynamixel Protocol 2.0: packet building and parsing, CRC-16, byte stuffing, control-table addresses.

Instruction: `FF FF FD 00 | ID | LEN_L LEN_H | INST | params | CRC_L CRC_H`; LEN counts INST + params + CRC.
Status: the same with INST = 0x55 followed by an error byte. Used by the bus emulator (the real bus goes
through `dynamixel_sdk`, which has its own implementation) and by tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE

PING, READ, WRITE, REBOOT, STATUS, SYNC_READ, SYNC_WRITE = 0x01, 0x02, 0x03, 0x08, 0x55, 0x82, 0x83

# Status error byte: bit 7 alert (hardware error), low bits an error number (those the emulator sends).
ERR_ALERT = 0x80
ERR_RESULT_FAIL, ERR_INSTRUCTION, ERR_ACCESS = 1, 2, 7

# Control table (X series and MX with 2.0 firmware): (address, size in bytes)
MODEL_NUMBER = (0, 2)
FIRMWARE_VERSION = (6, 1)
ID = (7, 1)
TORQUE_ENABLE = (64, 1)
HARDWARE_ERROR_STATUS = (70, 1)
PROFILE_ACCELERATION = (108, 4)
PROFILE_VELOCITY = (112, 4)
GOAL_POSITION = (116, 4)
MOVING = (122, 1)
PRESENT_VELOCITY = (128, 4)
PRESENT_POSITION = (132, 4)
CONTROL_TABLE_SIZE = 147

# Hardware error status bits
HW_ERROR_BITS = {
    0: "input voltage",
    2: "overheating",
    3: "motor encoder",
    4: "electrical shock",
    5: "overload",
}

CENTRE_TICK = 2048
RPM_PER_UNIT = 0.229  # present/profile velocity unit
RAD_S_PER_UNIT = RPM_PER_UNIT * 2.0 * math.pi / 60.0  # velocity unit [rad/s]
REV_PER_MIN2_PER_UNIT = 214.577  # profile acceleration unit (velocity-based profile)
RAD_S2_PER_UNIT = REV_PER_MIN2_PER_UNIT * 2.0 * math.pi / 3600.0  # acceleration unit [rad/s^2]

_CRC_TABLE: list[int] = []
for _i in range(256):
    _c = _i << 8
    for _ in range(8):
        _c = ((_c << 1) ^ 0x8005) if _c & 0x8000 else (_c << 1)
    _CRC_TABLE.append(_c & 0xFFFF)


def crc16(data: bytes) -> int:
    """CRC-16 of Protocol 2.0: polynomial 0x8005, initial value 0, no reflection, no final xor."""
    crc = 0
    for byte in data:
        crc = ((crc << 8) ^ _CRC_TABLE[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes, length_bytes: bytes = b"\x00\x00") -> bytes:
    """Insert an extra 0xFD after every `FF FF FD` in INST..params (the two length bytes precede the body)."""
    out = bytearray()
    prev = bytearray(length_bytes[-2:])
    for byte in body:
        out.append(byte)
        if byte == 0xFD and prev[-2:] == b"\xff\xff":
            out.append(0xFD)
        prev = prev[-1:] + bytes([byte])
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Remove the 0xFD that stuffing added after each `FF FF FD`."""
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if body[i] == 0xFD and i + 1 < len(body) and body[i + 1] == 0xFD and out[-3:-1] == b"\xff\xff":
            i += 1
        i += 1
    return bytes(out)


def build_packet(servo_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete packet (header, stuffing, CRC) for one instruction or status (status: params start with ERR)."""
    raw = bytes([instruction]) + bytes(params)
    raw_len = len(raw) + 2
    body = stuff(raw, raw_len.to_bytes(2, "little"))
    length = len(body) + 2
    packet = HEADER + bytes([servo_id]) + length.to_bytes(2, "little") + body
    return packet + crc16(packet).to_bytes(2, "little")


def build_status(servo_id: int, error: int, params: bytes = b"") -> bytes:
    """A status packet: INST 0x55, the error byte, then the parameters."""
    return build_packet(servo_id, STATUS, bytes([error]) + bytes(params))


@dataclass(frozen=True)
class Packet:
    servo_id: int
    instruction: int
    params: bytes  # unstuffed; for a status packet params[0] is the error byte
    crc_ok: bool = True


class PacketParser:
    """Incremental parser of a byte stream into packets; skips garbage before a header."""

    def __init__(self) -> None:
        self.buffer = bytearray()

    def feed(self, data: bytes) -> list[Packet]:
        self.buffer.extend(data)
        packets: list[Packet] = []
        while True:
            start = self.buffer.find(HEADER[:3])
            if start < 0:
                del self.buffer[: max(0, len(self.buffer) - 2)]
                return packets
            del self.buffer[:start]
            if len(self.buffer) < 7:
                return packets
            if self.buffer[3] != 0x00:  # FF FF FD FD: stuffed bytes, not a header
                del self.buffer[:1]
                continue
            length = int.from_bytes(self.buffer[5:7], "little")
            total = 7 + length
            if length < 3:
                del self.buffer[:1]
                continue
            if len(self.buffer) < total:
                return packets
            packet = bytes(self.buffer[:total])
            del self.buffer[:total]
            crc_ok = crc16(packet[:-2]) == int.from_bytes(packet[-2:], "little")
            body = unstuff(packet[7:-2])
            packets.append(Packet(packet[4], body[0], body[1:], crc_ok))
