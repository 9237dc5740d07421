"""Codes as a person reads them: ``CONSTANT_SPEED`` -> ``constant speed``."""

from __future__ import annotations

import enum
from typing import Final

__all__ = ["frame_text", "words"]

_CONTROL: Final = {
    0x02: "<STX>",
    0x03: "<ETX>",
    0x05: "<ENQ>",
    0x06: "<ACK>",
    0x0A: "<LF>",
    0x0D: "<CR>",
    0x15: "<NAK>",
}


def frame_text(data: bytes) -> str:
    """*data* as text: printable ASCII as is, control bytes by name, the rest as ``.``."""
    return "".join(_CONTROL.get(b, chr(b) if 0x20 <= b < 0x7F else ".") for b in data)


def words(member: enum.Enum) -> str:
    """An enum member in words: ``CONSTANT_SPEED`` -> ``constant speed``.

    A bit field lists its set members' names: ``OVER_VOLTAGE|THERMAL``, ``-`` for none.
    """
    if isinstance(member, enum.Flag):
        names = [m.name for m in type(member) if m.name and m in member]
        return "|".join(names) if names else "-"
    return (member.name or str(member.value)).lower().replace("_", " ")
