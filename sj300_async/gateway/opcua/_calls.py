"""The drive methods and the writable parameter variables: judged, handed to the gateway.

Every write that arrives over OPC UA goes through the gateway's
controller like every other door's: grants, the control lease, the
value's validation, the read-back, the audit log. Before that, this
module refuses, with a status code of its own and an audit line, what
the gateway need not see:

- an anonymous session (``BadUserAccessDenied``) or a channel that does
  not encrypt (``BadSecurityModeInsufficient``): writes need a named user
  over SignAndEncrypt;
- arguments of the wrong number (``BadArgumentsMissing``,
  ``BadTooManyArguments``) or type (``BadTypeMismatch``), a direction
  other than ``forward`` or ``reverse`` (``BadInvalidArgument``), a
  number that is NaN, infinite or out of range (``BadOutOfRange``),
  nothing of it sent;
- a run, a frequency or a parameter for a drive the poller holds offline
  (``BadNoCommunication``): nothing is sent. A stop is always tried.

The gateway's own refusals map through
:data:`~._quality.REFUSAL_STATUS`. The lease: ``TakeControl()`` takes or
renews it for the session's user (``opcua:NAME``) and answers how long it
lasts; with ``lease_scope = "connection"`` it lapses the moment the
session closes.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from typing import Any, Final

from asyncua import ua

from ...wire import Direction, LocalProtocolError
from .. import (
    GatewayDrive,
    GatewayView,
    Heartbeat,
    ParameterWrite,
    Refusal,
    RunCommand,
    SetFrequency,
    WriteRequest,
    WriteResult,
    excerpt,
)
from ._quality import GOOD, refusal_status
from ._security import Caller, current_caller

__all__ = ["Calls"]

_log = logging.getLogger("sj300_async.gateway.opcua")

_DIRECTIONS: Final = {"forward": Direction.FORWARD, "reverse": Direction.REVERSE}
_NUMBERS: Final = frozenset(
    {
        ua.VariantType.Double, ua.VariantType.Float,
        ua.VariantType.SByte, ua.VariantType.Byte, ua.VariantType.Int16, ua.VariantType.UInt16,
        ua.VariantType.Int32, ua.VariantType.UInt32, ua.VariantType.Int64, ua.VariantType.UInt64,
    }
)  # fmt: skip


class _Refused(Exception):
    """Refused here, before the gateway: the status code and the audit's words."""

    def __init__(self, status: int, refusal: Refusal, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.result = WriteResult(refusal, detail)


def _status_name(status: int) -> str:
    return str(ua.StatusCode(status).name)


def _arguments(args: tuple[Any, ...], types: tuple[ua.VariantType, ...]) -> list[object]:
    """The values of a call's arguments, checked against the method's argument types."""
    if len(args) < len(types):
        raise _Refused(ua.StatusCodes.BadArgumentsMissing, Refusal.MALFORMED, "missing arguments")
    if len(args) > len(types):
        raise _Refused(ua.StatusCodes.BadTooManyArguments, Refusal.MALFORMED, "too many arguments")
    values = []
    for arg, expected in zip(args, types, strict=True):
        variant = arg if isinstance(arg, ua.Variant) else ua.Variant(arg)
        if variant.VariantType != expected:
            raise _Refused(
                ua.StatusCodes.BadTypeMismatch,
                Refusal.MALFORMED,
                f"expected {expected.name}, got {variant.VariantType.name}",
            )
        values.append(variant.Value)
    return values


def number(variant: ua.Variant) -> float:
    """A written number (any numeric type), finite.

    Raises:
        _Refused: not a number (BadTypeMismatch), NaN or infinite (BadOutOfRange).
    """
    if variant.VariantType not in _NUMBERS or isinstance(variant.Value, bool | list):
        raise _Refused(
            ua.StatusCodes.BadTypeMismatch,
            Refusal.MALFORMED,
            f"expected a number, got {variant.VariantType.name}",
        )
    value = float(variant.Value)
    if not math.isfinite(value):
        raise _Refused(ua.StatusCodes.BadOutOfRange, Refusal.INVALID_VALUE, f"{value} is no value")
    return value


def _moves(request: WriteRequest) -> bool:
    """A request that changes what the drive does (a stop and a lease do not)."""
    if isinstance(request, RunCommand):
        return request.direction != Direction.STOP
    return not isinstance(request, Heartbeat)


class Calls:
    """The methods' and the writable variables' handlers of one server."""

    def __init__(self, gateway: GatewayView) -> None:
        self.gateway = gateway
        #: Calls and writes by their status code's name (``Good``, ``BadLocked``...).
        self.results: Counter[str] = Counter()

    @staticmethod
    def _caller() -> Caller:
        """The caller, who may write (else refused: anonymous, or not encrypted)."""
        caller = current_caller()
        if caller is None or caller.principal.anonymous:
            raise _Refused(
                ua.StatusCodes.BadUserAccessDenied,
                Refusal.NOT_ALLOWED,
                "anonymous sessions only read: log in as a user of [[opcua.users]]",
            )
        if not caller.encrypted:
            raise _Refused(
                ua.StatusCodes.BadSecurityModeInsufficient,
                Refusal.NOT_ALLOWED,
                "writes need a Basic256Sha256 SignAndEncrypt channel",
            )
        return caller

    async def _judge(
        self, drive: GatewayDrive, what: str, value: object, request: WriteRequest
    ) -> int:
        """Refuse here or hand *request* to the gateway; the status code of the outcome."""
        try:
            caller = self._caller()
            if _moves(request) and not drive.snapshot.online:
                raise _Refused(
                    ua.StatusCodes.BadNoCommunication,
                    Refusal.NO_ANSWER,
                    "the drive is offline: nothing was sent",
                )
        except _Refused as refused:
            return self._refuse(drive, what, value, refused)
        result = await self.gateway.write(
            caller.principal.client, drive, request, connection=caller.principal.connection
        )
        status = refusal_status(result.refusal)
        self.results[_status_name(status)] += 1
        return status

    async def _checked(
        self,
        drive: GatewayDrive,
        what: str,
        args: tuple[Any, ...],
        types: tuple[ua.VariantType, ...],
    ) -> list[object] | int:
        """The arguments' values, or the status code of their refusal (audited)."""
        try:
            return _arguments(args, types)
        except _Refused as refused:
            return self._refuse(drive, what, args, refused)

    def _refuse(self, drive: GatewayDrive, what: str, value: object, refused: _Refused) -> int:
        """Audit and count a refusal made here; its status code."""
        caller = current_caller()
        client = caller.principal.client if caller is not None else "opcua:anonymous"
        shown = None if value is None else excerpt(repr(value))
        self.gateway.refused(client, drive, f"opcua {what}", shown, refused.result)
        _log.debug("opcua %s to %s %s refused: %s", what, *drive.key, refused.result)
        self.results[_status_name(refused.status)] += 1
        return refused.status

    # -- the methods ----------------------------------------------------------------

    async def take_control(self, drive: GatewayDrive, args: tuple[Any, ...]) -> Any:
        checked = await self._checked(drive, "TakeControl", args, ())
        if isinstance(checked, int):
            return ua.StatusCode(checked)
        status = await self._judge(drive, "TakeControl", None, Heartbeat())
        if status != GOOD:
            return ua.StatusCode(status)
        return [ua.Variant(float(drive.lease.duration_s), ua.VariantType.Double)]

    async def run(self, drive: GatewayDrive, args: tuple[Any, ...]) -> Any:
        checked = await self._checked(drive, "Run", args, (ua.VariantType.String,))
        if isinstance(checked, int):
            return ua.StatusCode(checked)
        text = str(checked[0]).strip().lower()
        direction = _DIRECTIONS.get(text)
        if direction is None:
            refused = _Refused(
                ua.StatusCodes.BadInvalidArgument,
                Refusal.MALFORMED,
                f"expected forward or reverse, got {excerpt(str(checked[0]))!r}",
            )
            return ua.StatusCode(self._refuse(drive, "Run", checked[0], refused))
        return ua.StatusCode(await self._judge(drive, "Run", text, RunCommand(direction)))

    async def stop(self, drive: GatewayDrive, args: tuple[Any, ...]) -> Any:
        checked = await self._checked(drive, "Stop", args, ())
        if isinstance(checked, int):
            return ua.StatusCode(checked)
        return ua.StatusCode(await self._judge(drive, "Stop", None, RunCommand(Direction.STOP)))

    async def set_frequency(self, drive: GatewayDrive, args: tuple[Any, ...]) -> Any:
        checked = await self._checked(drive, "SetFrequency", args, (ua.VariantType.Double,))
        if isinstance(checked, int):
            return ua.StatusCode(checked)
        hz = float(checked[0])  # type: ignore[arg-type]
        if not math.isfinite(hz):
            refused = _Refused(
                ua.StatusCodes.BadOutOfRange, Refusal.INVALID_VALUE, f"{hz} Hz is no frequency"
            )
            return ua.StatusCode(self._refuse(drive, "SetFrequency", hz, refused))
        # The set frequency's step, every protocol (the MQTT command's rule).
        if abs(hz) <= 1e6 and abs(round(hz * 100) - hz * 100) > 1e-6:
            refused = _Refused(
                ua.StatusCodes.BadOutOfRange,
                Refusal.INVALID_VALUE,
                f"{hz} Hz is finer than 0.01 Hz",
            )
            return ua.StatusCode(self._refuse(drive, "SetFrequency", hz, refused))
        return ua.StatusCode(await self._judge(drive, "SetFrequency", hz, SetFrequency(hz)))

    # -- the variables ----------------------------------------------------------------

    def count(self, status: int) -> None:
        """Count a refusal made without a drive to audit it against (an unknown node)."""
        self.results[_status_name(status)] += 1

    def not_writable(self, drive: GatewayDrive, name: str) -> int:
        """A write to one of *drive*'s read-only variables: refused and audited."""
        refused = _Refused(
            ua.StatusCodes.BadNotWritable,
            Refusal.NOT_ALLOWED,
            f"{name} is read-only here (granted parameters are the writable ones)",
        )
        return self._refuse(drive, name, None, refused)

    async def write_parameter(self, drive: GatewayDrive, code: str, variant: ua.Variant) -> int:
        """A client's write of parameter *code*'s variable: the status code of the outcome."""
        try:
            value = number(variant)
            try:
                raw = drive.profile.parameters.spec(code).to_raw(value)
            except LocalProtocolError as exc:
                raise _Refused(
                    ua.StatusCodes.BadOutOfRange, Refusal.INVALID_VALUE, str(exc)
                ) from None
        except _Refused as refused:
            return self._refuse(drive, code, variant.Value, refused)
        return await self._judge(drive, code, value, ParameterWrite(code, int(raw)))
