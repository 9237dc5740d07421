"""A parameter's value as a client sent it -> the drive's raw value, or a refusal.

Sans-IO; the controller's (:mod:`._control`), for every door: a number in
the parameter's unit (:class:`~._writes.ParameterValue`) is never rounded
to what the drive can hold: outside the parameter's range, finer than its
setting increment, or no number at all, it is refused (``invalid_value``).
A raw integer (:class:`~._writes.ParameterWrite`, Modbus's and the HTTP
API's ``raw``) is refused outside the range.
"""

from __future__ import annotations

import math

from ..profiles import Profile
from ..wire import LocalProtocolError
from ._audit import excerpt
from ._writes import ParameterWrite, Refusal, WriteResult

__all__ = ["parameter_request", "raw_refusal"]


def parameter_request(
    profile: Profile, code: str, value: float, text: str = ""
) -> ParameterWrite | WriteResult:
    """Parameter *code* (normalised) set to *value* in its unit (*text* as sent).

    Refused (``invalid_value``, the catalogue's sentence) when not a finite number,
    outside the parameter's range (a special setting such as FR-700's 9999 is
    within it), or finer than its setting increment: never rounded.
    """
    spec = profile.parameters.spec(code)
    if not math.isfinite(value):
        shown = excerpt(text) if text else f"{value:g}"
        return WriteResult(Refusal.INVALID_VALUE, f"{shown} is no value of {code}")
    try:
        raw = int(spec.to_raw(value))
    except (LocalProtocolError, OverflowError, ValueError) as exc:
        return WriteResult(Refusal.INVALID_VALUE, str(exc))
    return ParameterWrite(code, raw)


def raw_refusal(profile: Profile, request: ParameterWrite) -> WriteResult | None:
    """*request*'s integer refused when the value it stands for is one the catalogue would
    not send (outside the range and no special setting), else None."""
    spec = profile.parameters.spec(request.code)
    try:
        spec.to_raw(spec.from_raw(request.raw))
    except (LocalProtocolError, OverflowError, ValueError) as exc:
        return WriteResult(Refusal.INVALID_VALUE, f"raw {request.raw}: {exc}")
    return None
