"""A number in a parameter's unit, as a client sent it -> the drive's raw value, or a refusal.

Sans-IO. The doors that take a parameter as a number in its unit (the MQTT
JSON topics, a Sparkplug DCMD) read it here, so the same number gets the
same verdict whichever of them it came through. A number is never rounded
to what the drive can hold: outside the parameter's range, or finer than
its setting increment, it is refused (``invalid_value``). Modbus writes the
raw integer itself and has nothing to round.
"""

from __future__ import annotations

from ..profiles import Profile, raw_value
from ._audit import excerpt
from ._writes import ParameterWrite, Refusal, WriteResult

__all__ = ["parameter_request"]


def parameter_request(
    profile: Profile, code: str, value: float, text: str
) -> ParameterWrite | WriteResult:
    """Parameter *code* (normalised) set to *value* in its unit (*text* as sent).

    Refused when outside the parameter's range or finer than its setting
    increment: a number is never rounded to what the drive can hold.
    """
    spec = profile.parameters.spec(code)
    try:
        raw = raw_value(spec, value)
    except (OverflowError, ValueError):
        unit = f" {spec.unit}" if spec.unit else ""
        return WriteResult(
            Refusal.INVALID_VALUE,
            f"{excerpt(text)} is outside {code}'s range, {spec.minimum:g}..{spec.maximum:g}{unit}",
        )
    # raw_value rounds what its step cannot hold (Modbus cannot send it anyway);
    # a number in its unit can be finer, and is refused rather than rounded.
    if abs(spec.from_raw(raw) - value) > 1e-9 * max(1.0, abs(value)):
        return WriteResult(
            Refusal.INVALID_VALUE, f"{excerpt(text)} is finer than {code}'s setting increment"
        )
    return ParameterWrite(code, raw)
