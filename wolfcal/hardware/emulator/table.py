"""The control table of an emulated Protocol 2.0 device: little-endian items (address, size [bytes]) in a byte array."""

from __future__ import annotations


class ControlTable:
    """A device's control table, `size` bytes, all 0 at start; subclasses fill in what the device holds."""

    def __init__(self, size: int):
        self.table = bytearray(size)

    def read(self, item: tuple[int, int], signed: bool = False) -> int:
        """The value of a control-table item (address, size)."""
        addr, size = item
        return int.from_bytes(self.table[addr : addr + size], "little", signed=signed)

    def write(self, item: tuple[int, int], value: int) -> None:
        """Set a control-table item (address, size)."""
        addr, size = item
        self.table[addr : addr + size] = int(value).to_bytes(size, "little", signed=value < 0)
