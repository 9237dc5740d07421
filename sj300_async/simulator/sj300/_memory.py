"""A drive's parameter memory: RAM that the line writes, EEPROM that survives a power cycle.

Command 07 (and 01 for F001) writes RAM; 0A copies RAM to EEPROM; a power
cycle reloads RAM from EEPROM, so what was not stored is lost. 08 writes
both. An EEPROM write takes a while (``write_s``): until it has finished,
command 09 says storing is not allowed. A 0A during a write restarts it.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping

from ._parameters_table import value_error

__all__ = ["ParameterMemory"]


class _Layered(Mapping[str, int]):
    """*own* over *base*, read-only: a memory as a drive shows it."""

    __slots__ = ("_base", "_own")

    def __init__(self, own: dict[str, int], base: Mapping[str, int]) -> None:
        self._own = own
        self._base = base

    def __getitem__(self, code: str) -> int:
        value = self._own.get(code)
        return self._base[code] if value is None else value

    def __iter__(self) -> Iterator[str]:
        yield from self._base
        yield from (code for code in self._own if code not in self._base)

    def __len__(self) -> int:
        return len(self._base) + sum(1 for code in self._own if code not in self._base)

    def __contains__(self, code: object) -> bool:
        return code in self._own or code in self._base


class ParameterMemory:
    """RAM and EEPROM of one drive, raw values keyed by upper-case code.

    Both hold only what differs from *base*, a table shared by every drive
    made alike and never changed: 200-odd values a drive, twice, were 13 KiB
    per drive, the plant benchmark's simulators' largest share (issue 44).
    """

    __slots__ = ("_base", "_busy_until", "_eeprom", "_ram", "version", "write_s")

    def __init__(
        self, base: Mapping[str, int], own: Mapping[str, int] | None = None, *, write_s: float
    ) -> None:
        #: How long an EEPROM write takes.
        self.write_s = write_s
        self._base = base
        self._eeprom = dict(own or {})
        self._ram = dict(own or {})
        self._busy_until = -math.inf
        #: Moves on every change of RAM, so a reader may cache what it derives from it.
        self.version = 0

    @property
    def ram(self) -> Mapping[str, int]:
        """What command 06 reads, read-only."""
        return _Layered(self._ram, self._base)

    @property
    def eeprom(self) -> Mapping[str, int]:
        """What a power cycle restores, read-only."""
        return _Layered(self._eeprom, self._base)

    def __getitem__(self, code: str) -> int:
        value = self._ram.get(code)
        return self._base[code] if value is None else value

    def __contains__(self, code: object) -> bool:
        return code in self._ram or code in self._base

    def refusal(self, code: str, raw: int) -> str | None:
        """Why the drive refuses writing *raw* to *code*, or None if it accepts."""
        if code not in self:
            return "unknown parameter"
        return value_error(code, raw, self.ram)

    def write(self, code: str, raw: int, *, store: bool = False) -> None:
        """Write RAM (and EEPROM with *store*); the caller has checked :meth:`refusal`."""
        self.version += 1
        memories = (self._ram, self._eeprom) if store else (self._ram,)
        for memory in memories:
            memory[code] = raw
            if code == "A004":
                # A lower maximum frequency pulls the setpoint down with it.
                memory["F001"] = min(_Layered(memory, self._base)["F001"], raw * 10)

    def store(self, now: float) -> None:
        """Command 0A: copy RAM to EEPROM; the write takes ``write_s`` from *now*."""
        self._eeprom = dict(self._ram)
        self._busy_until = now + self.write_s

    def can_store(self, now: float) -> bool:
        """Command 09: True unless an EEPROM write is still in progress at *now*."""
        return now >= self._busy_until

    def initialize(self, table: Mapping[str, int]) -> None:
        """Command 08: load *table* into RAM and EEPROM."""
        self.version += 1
        self._base = dict(table)  # its own now: the shared base is never changed
        self._ram = {}
        self._eeprom = {}

    def power_cycle(self) -> None:
        """RAM forgets everything not stored; an unfinished EEPROM write is over."""
        self.version += 1
        self._ram = dict(self._eeprom)
        self._busy_until = -math.inf
