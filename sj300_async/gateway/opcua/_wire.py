"""A DataValue in OPC UA binary, faster than asyncua's generic encoder; the same bytes.

asyncua encodes a DataValue the way it encodes any structure: field by
field, each through a looked-up function, the encoding mask by testing
each optional field by name. Every value a subscription publishes goes
through it, once per monitored item: at plant scale, 2,048 a second. The
gateway's values have one of a few shapes (a scalar number or boolean, a
status, two timestamps), which one ``struct`` call packs.

Decisions:

- **The same bytes, or asyncua's.** A shape this module does not know
  (a string, an array, picoseconds, a value the struct refuses) is left to
  asyncua's own encoder: :func:`datavalue_binary` returns None and the
  caller falls back. ``tests/opcua/test_opcua_wire.py`` compares the two
  byte for byte over every variant type the gateway serves.
- **Timestamps** go through asyncua's own conversion
  (``datetime_to_win_epoch``: its clamping at 1601 and 9999 included).
- Sans-IO: nothing here runs a server.
"""

from __future__ import annotations

import struct
from typing import Any, Final

from asyncua import ua

__all__ = ["datavalue_binary"]

# A scalar variant's struct format, by variant type (OPC UA Part 6, 5.2.2).
_SCALARS: Final = {
    ua.VariantType.Boolean: "?",
    ua.VariantType.SByte: "b",
    ua.VariantType.Byte: "B",
    ua.VariantType.Int16: "h",
    ua.VariantType.UInt16: "H",
    ua.VariantType.Int32: "i",
    ua.VariantType.UInt32: "I",
    ua.VariantType.Int64: "q",
    ua.VariantType.UInt64: "Q",
    ua.VariantType.Float: "f",
    ua.VariantType.Double: "d",
}
# Every field present but the picoseconds: the encoding mask (Part 6, 5.2.2.17), the
# variant's type byte and value, the status code, the source and server timestamps.
_FULL: Final = 0x0F
_PACKERS: Final = {vtype: struct.Struct(f"<BB{fmt}Iqq").pack for vtype, fmt in _SCALARS.items()}
# A Null variant (a Bad status's: Part 4, 7.7.1) is its type byte alone.
_NULL: Final = struct.Struct("<BBIqq").pack
_ticks = ua.datetime_to_win_epoch


def datavalue_binary(value: Any) -> bytes | None:
    """*value* (a DataValue) in OPC UA binary, or None for a shape left to asyncua."""
    variant = value.Value
    status = value.StatusCode
    source = value.SourceTimestamp
    server = value.ServerTimestamp
    if (
        status is None
        or source is None
        or server is None
        or value.SourcePicoseconds is not None
        or value.ServerPicoseconds is not None
    ):
        return None
    try:
        if variant is None:  # a DataValue makes a Null variant of None: not the gateway's
            return None
        if variant.VariantType == ua.VariantType.Null and variant.Value is None:
            return _NULL(_FULL, 0, status.value, _ticks(source), _ticks(server))
        pack = _PACKERS.get(variant.VariantType)
        if pack is None or variant.is_array or variant.Dimensions is not None:
            return None
        scalar = variant.Value
        if type(scalar) in (list, tuple):
            return None
        return pack(
            _FULL,
            variant.VariantType.value,
            scalar,
            status.value,
            _ticks(source),
            _ticks(server),
        )
    except (struct.error, TypeError, OverflowError):
        return None  # asyncua's encoder says what is wrong with it
