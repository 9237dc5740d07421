"""The drive methods and the writable parameter variables: judged, handed to the gateway.

Every write that arrives over OPC UA goes through the gateway's
controller like every other door's: grants, the control lease, the
value's validation, the read-back, the audit log. Before that, this
module refuses, with a status code of its own and an audit line, what
the gateway need not see, in this order:

- more than :data:`~._security.MAX_OPERATIONS` writes in one request
  (``BadTooManyOperations``: counted, not audited one by one);
- an anonymous session (``BadUserAccessDenied``) or a channel that does
  not encrypt (``BadSecurityModeInsufficient``): writes need a named user
  over SignAndEncrypt;
- arguments of the wrong number (``BadArgumentsMissing``,
  ``BadTooManyArguments``) or type (``BadTypeMismatch``), a direction
  other than ``forward`` or ``reverse`` (``BadInvalidArgument``), a
  parameter's value that is NaN, infinite or out of its range
  (``BadOutOfRange``; a set frequency's value is the gateway's to judge),
  an array where one value is expected (``BadTypeMismatch``), a value
  written with a status code other than Good (``BadWriteNotSupported``),
  nothing of it sent.

A run, a frequency or a parameter for a drive the poller holds offline is
the gateway's to refuse (``no_answer``, so ``BadNoCommunication``):
nothing is sent; a stop is always tried.

The gateway's own refusals map through
:data:`~._quality.REFUSAL_STATUS`. The lease: ``TakeControl()`` takes or
renews it for the session's user (``opcua:NAME``) and answers how long it
lasts; with ``lease_scope = "connection"`` it lapses the moment the
session closes.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from typing import Any, Final

from asyncua import ua

from ...wire import Direction
from .. import (
    DIRECTION_WORDS,
    GatewayDrive,
    GatewayView,
    Heartbeat,
    ParameterValue,
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

#: A run's directions, in the gateway's words (a stop is a call of its own).
_DIRECTIONS: Final = {DIRECTION_WORDS[d]: d for d in (Direction.FORWARD, Direction.REVERSE)}
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
        if variant.VariantType != expected or variant.is_array or isinstance(variant.Value, list):
            raise _Refused(
                ua.StatusCodes.BadTypeMismatch,
                Refusal.MALFORMED,
                f"expected {expected.name}, got {variant.VariantType.name}",
            )
        values.append(variant.Value)
    return values


def _number(variant: ua.Variant) -> float:
    """A written number (any numeric type; NaN and infinities are the gateway's to refuse).

    Raises:
        _Refused: not a number (BadTypeMismatch).
    """
    if (
        variant.VariantType not in _NUMBERS
        or variant.is_array
        or isinstance(variant.Value, bool | list)
    ):
        raise _Refused(
            ua.StatusCodes.BadTypeMismatch,
            Refusal.MALFORMED,
            f"expected a number, got {variant.VariantType.name}",
        )
    return float(variant.Value)


Build = Callable[[list[object]], WriteRequest]


class Calls:
    """The methods' and the writable variables' handlers of one server."""

    def __init__(self, gateway: GatewayView) -> None:
        self.gateway = gateway
        #: Calls and writes by their status code's name (``Good``, ``BadLocked``...).
        self.results: Counter[str] = Counter()

    def count(self, status: int) -> None:
        """Count an answer given without a drive to audit it against (an unknown node)."""
        self.results[_status_name(status)] += 1

    @staticmethod
    def _writer() -> Caller:
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

    async def _handle(
        self, drive: GatewayDrive, what: str, shown: object, build: Callable[[], WriteRequest]
    ) -> int:
        """Judge the caller, then the request *build* makes, then hand it to the gateway.

        The caller first: an anonymous client learns nothing of what it sent. One
        request carries at most MAX_OPERATIONS writes; the rest are answered
        BadTooManyOperations, counted and not audited one by one (a flood would
        otherwise write the audit log full). A failure of our own is audited too.
        """
        caller = current_caller()
        if caller is not None and not caller.operation():
            self.count(ua.StatusCodes.BadTooManyOperations)
            _log.debug("opcua %s to %s %s refused: too many in one request", what, *drive.key)
            return int(ua.StatusCodes.BadTooManyOperations)
        try:
            writer = self._writer()
            request = build()
        except _Refused as refused:
            return self._refuse(drive, what, shown, refused)
        except Exception:  # a bug of ours: audited, answered, logged with its traceback
            _log.exception("opcua %s to %s %s failed", what, *drive.key)
            failed = _Refused(ua.StatusCodes.BadInternalError, Refusal.MALFORMED, "internal error")
            return self._refuse(drive, what, shown, failed)
        principal = writer.principal
        result = await self.gateway.write(
            principal.client, drive, request, connection=principal.connection
        )
        status = refusal_status(result.refusal)
        self.results[_status_name(status)] += 1
        return status

    def _refuse(self, drive: GatewayDrive, what: str, value: object, refused: _Refused) -> int:
        """Audit and count a refusal made here; its status code."""
        caller = current_caller()
        client = caller.principal.client if caller is not None else "opcua:anonymous"
        shown = None if value is None else excerpt(repr(value))
        self.gateway.refused(client, drive, f"opcua {what}", shown, refused.result)
        _log.debug("opcua %s to %s %s refused: %s", what, *drive.key, refused.result)
        self.results[_status_name(refused.status)] += 1
        return refused.status

    async def _call(
        self,
        drive: GatewayDrive,
        what: str,
        args: tuple[Any, ...],
        types: tuple[ua.VariantType, ...],
        build: Build,
    ) -> int:
        shown = [arg.Value if isinstance(arg, ua.Variant) else arg for arg in args] or None
        return await self._handle(drive, what, shown, lambda: build(_arguments(args, types)))

    # -- the methods ----------------------------------------------------------------

    async def take_control(self, drive: GatewayDrive, args: tuple[Any, ...]) -> Any:
        status = await self._call(drive, "TakeControl", args, (), lambda _: Heartbeat())
        if status != GOOD:
            return ua.StatusCode(status)
        return [ua.Variant(float(drive.lease.duration_s), ua.VariantType.Double)]

    async def run(self, drive: GatewayDrive, args: tuple[Any, ...]) -> Any:
        string = (ua.VariantType.String,)
        return ua.StatusCode(await self._call(drive, "Run", args, string, _run))

    async def stop(self, drive: GatewayDrive, args: tuple[Any, ...]) -> Any:
        stop = RunCommand(Direction.STOP)
        return ua.StatusCode(await self._call(drive, "Stop", args, (), lambda _: stop))

    async def set_frequency(self, drive: GatewayDrive, args: tuple[Any, ...]) -> Any:
        double = (ua.VariantType.Double,)
        return ua.StatusCode(await self._call(drive, "SetFrequency", args, double, _frequency))

    # -- the variables ----------------------------------------------------------------

    def not_writable(self, drive: GatewayDrive, name: str) -> int:
        """A write to one of *drive*'s read-only variables: refused and audited."""
        refused = _Refused(
            ua.StatusCodes.BadNotWritable,
            Refusal.NOT_ALLOWED,
            f"{name} is read-only here (granted parameters are the writable ones)",
        )
        return self._refuse(drive, name, None, refused)

    async def write_parameter(self, drive: GatewayDrive, code: str, value: ua.DataValue) -> int:
        """A client's write of parameter *code*'s variable: the status code of the outcome."""

        def build() -> WriteRequest:
            # A value its writer flags as not Good is not sent to a drive (Part 4,
            # 5.10.4: BadWriteNotSupported). A written timestamp is ignored: clients
            # send their own clock (asyncua's write_value does), and the variable's
            # timestamp is the read-back's.
            status = value.StatusCode
            if status is not None and not status.is_good():
                raise _Refused(
                    ua.StatusCodes.BadWriteNotSupported,
                    Refusal.MALFORMED,
                    "a value written with a status code other than Good is not sent",
                )
            variant = value.Value if value.Value is not None else ua.Variant(None)
            # In its unit: the range and the setting increment are the gateway's to judge
            # (after the grants, before the drive's state), as from every door (issue 42).
            return ParameterValue(code, _number(variant), repr(variant.Value))

        shown = value.Value.Value if value.Value is not None else None
        return await self._handle(drive, code, shown, build)


def _run(values: list[object]) -> WriteRequest:
    text = str(values[0]).strip().lower()
    direction = _DIRECTIONS.get(text)
    if direction is None:
        raise _Refused(
            ua.StatusCodes.BadInvalidArgument,
            Refusal.MALFORMED,
            f"expected forward or reverse, got {excerpt(str(values[0]))!r}",
        )
    return RunCommand(direction)


def _frequency(values: list[object]) -> WriteRequest:
    # NaN, infinities, the range and the 0.01 Hz step are the gateway's to judge (after
    # the grants, before the lease), as from every door (issue 42): BadOutOfRange.
    return SetFrequency(float(values[0]))  # type: ignore[arg-type]
