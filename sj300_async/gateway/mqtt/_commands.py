"""MQTT commands: ``…/<line>/<node>/set/<what>`` payloads -> the gateway's neutral writes.

Sans-IO. ``<what>`` is ``lease`` (any payload: take or renew the control
lease), ``command`` (``run_forward``, ``run_reverse``, ``stop``),
``frequency_hz`` (a number) or a parameter code (``A004``, ``Pr.7``: a
number in the parameter's unit, which must be exact at its setting
increment: a number finer than that is refused, not rounded). What cannot
be read is refused here with a neutral :class:`~sj300_async.gateway.Refusal`;
the rest goes to the gateway, which judges it like any other write.
:func:`error_text` words a refusal for the error topic.

A payload is untrusted: one longer than :data:`MAX_PAYLOAD_BYTES` is
refused unread (:func:`oversized`), and a refusal quotes what it got as a
short escaped excerpt (:func:`~sj300_async.gateway.excerpt`), never whole.
"""

from __future__ import annotations

from typing import Final

from ...profiles import Profile
from ...wire import Direction
from .. import (
    Heartbeat,
    ParameterValue,
    Refusal,
    RunCommand,
    SetFrequency,
    WriteRequest,
    WriteResult,
    excerpt,
)

__all__ = [
    "COMMAND_DIRECTIONS",
    "MAX_PAYLOAD_BYTES",
    "error_text",
    "oversized",
    "parse_command",
]

#: The longest command payload read (the longest real one is a number or
#: ``run_forward``): a longer one is refused unread, ``malformed``.
MAX_PAYLOAD_BYTES: Final = 4096

#: The payloads of ``…/set/command``.
COMMAND_DIRECTIONS: Final = {
    "stop": Direction.STOP,
    "run_forward": Direction.FORWARD,
    "run_reverse": Direction.REVERSE,
}


def _number(text: str) -> float | None:
    """A number (NaN and infinities too: the gateway refuses them as invalid values), else
    None."""
    try:
        return float(text)
    except ValueError:
        return None


def oversized(length: int) -> WriteResult | None:
    """The refusal of a payload of *length* bytes too long to read, None for one that is not."""
    if length <= MAX_PAYLOAD_BYTES:
        return None
    return WriteResult(
        Refusal.MALFORMED,
        f"a command is at most {MAX_PAYLOAD_BYTES} bytes, got {length}: not read",
    )


def _quoted(text: str) -> str:
    return f"'{excerpt(text)}'"


def parse_command(profile: Profile, what: str, payload: bytes) -> WriteRequest | WriteResult:
    """The write a command asks for, or why it cannot be one (nothing judged yet)."""
    too_long = oversized(len(payload))
    if too_long is not None:
        return too_long
    if what == "lease":
        return Heartbeat()  # any payload
    try:
        text = payload.decode("utf-8").strip()
    except UnicodeDecodeError:
        return WriteResult(Refusal.MALFORMED, "the payload is not UTF-8 text")
    if what == "command":
        direction = COMMAND_DIRECTIONS.get(text)
        if direction is None:
            return WriteResult(
                Refusal.MALFORMED, f"expected run_forward, run_reverse or stop, got {_quoted(text)}"
            )
        return RunCommand(direction)
    if what == "frequency_hz":
        hz = _number(text)
        if hz is None:
            return WriteResult(Refusal.MALFORMED, f"expected a number of Hz, got {_quoted(text)}")
        # The gateway judges it (a number, within the drive's range, on the 0.01 Hz
        # step), after the grants and before the lease, as from any door (issue 42).
        return SetFrequency(hz)
    code = profile.parameters.code(what)
    if code is None:
        return WriteResult(
            Refusal.UNKNOWN_TARGET,
            f"no such command or parameter {_quoted(what)} "
            "(use lease, command, frequency_hz or a parameter code)",
        )
    value = _number(text)
    if value is None:
        return WriteResult(
            Refusal.MALFORMED, f"expected a number in {code}'s unit, got {_quoted(text)}"
        )
    return ParameterValue(code, value, text)  # the gateway judges it, as from every door


#: What a client on MQTT can do about a refusal, where the neutral sentence does not say.
_HINTS: Final = {Refusal.NO_LEASE: "publish to …/set/lease"}


def error_text(result: WriteResult) -> str:
    """``no_lease: take the control lease first (publish to …/set/lease)``."""
    text = str(result)
    hint = None if result.refusal is None else _HINTS.get(result.refusal)
    return f"{text} ({hint})" if hint else text
