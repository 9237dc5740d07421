"""The typed Drive API: one method per thing a user does with a drive.

:class:`Drive` talks to one node; :class:`Broadcast` to every drive at once
(only the commands the protocol lets you broadcast, and no reply comes back).
Both share the write commands through :class:`_Commands`, so a command is
defined once.
"""

from __future__ import annotations

from collections.abc import Coroutine
from typing import TYPE_CHECKING, Any

from ..bus import TransactionStats
from ..wire import Direction, LocalProtocolError
from . import _requests as rq
from ._constants import BROADCAST
from ._parameters import parameter_info
from ._payloads import (
    InverterStatus,
    MonitorData,
    TripHistory,
    _decode_monitor,
    _decode_status,
    _decode_trip_history,
    decode_can_store,
    decode_parameter_value,
)
from ._requests import Request
from ._terminals import InputTerminal

if TYPE_CHECKING:
    from ..bus import Channel

__all__ = ["Broadcast", "Drive"]


class _Commands:
    """The commands a single drive and a broadcast have in common (all may be broadcast)."""

    _node: int

    async def _execute(self, request: Request, *, urgent: bool = False) -> None:
        raise NotImplementedError

    async def run_forward(self) -> None:
        """Command 00: run forward (the drive needs A002 = 03).

        Raises:
            NakError: e.g. code 13 when the run command source is not serial.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        await self._execute(rq.run(self._node, Direction.FORWARD))

    async def run_reverse(self) -> None:
        """Command 00: run reverse. Raises as :meth:`run_forward`."""
        await self._execute(rq.run(self._node, Direction.REVERSE))

    async def stop(self) -> None:
        """Command 00: stop. Jumps the queue: it goes out before every waiting poll.

        Raises as :meth:`run_forward`.
        """
        await self._execute(rq.run(self._node, Direction.STOP), urgent=True)

    async def set_frequency(self, hz: float) -> None:
        """Command 01: set the output frequency in Hz (0.01 Hz steps; the drive needs A001 = 03).

        Raises:
            LocalProtocolError: not a number in range or finer than 0.01 Hz (nothing sent).
            NakError: e.g. 16 above the drive's maximum frequency, 13 when not serial.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        await self._execute(rq.set_frequency(self._node, hz))

    async def set_terminals(self, terminals: InputTerminal | int) -> None:
        """Command 02: set the intelligent input terminals; bits not given are cleared.

        Raises:
            LocalProtocolError: an unassigned bit (nothing sent).
            NakError: the drive refused the request.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        await self._execute(rq.set_terminals(self._node, terminals))

    async def write_parameter(self, code: str, value: float) -> None:
        """Command 07: write an engineering value, scaled by the parameter catalogue.

        Raises:
            LocalProtocolError: bad code, value out of range or too fine (nothing sent).
            NakError: 16 when the drive does not know the code or refuses the value.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        await self._execute(rq.write_parameter(self._node, code, value))

    async def write_parameter_raw(self, code: str, raw: int) -> None:
        """Command 07: write an unscaled integer 0..99999999. Raises as :meth:`write_parameter`."""
        await self._execute(rq.write_parameter_raw(self._node, code, raw))

    async def initialize(self) -> None:
        """Command 08: restore factory settings per B084 (mode) and B085 (country).

        Raises as :meth:`run_forward`.
        """
        await self._execute(rq.initialize(self._node))

    async def store(self) -> None:
        """Command 0A: store the settings to EEPROM. Raises as :meth:`run_forward`."""
        await self._execute(rq.store(self._node))


class Drive(_Commands):
    """One drive on a bus. Get it from :meth:`Bus.drive`.

    Attributes:
        node: the drive's address (1..32).
        stats: counters of this drive's transactions.
        wait_time_s: the drive's C078 wait time; the response time-out grows by it.
        timeout_s: a fixed response time-out for this drive (None: computed).
    """

    def __init__(self, channel: Channel[Request], node: int, *, wait_time_s: float = 0.0) -> None:
        if isinstance(node, bool) or not isinstance(node, int) or not 1 <= node <= 32:
            raise LocalProtocolError(f"node must be 1..32, got {node!r}")
        self._channel = channel
        self._node = node
        # The two reads a poll repeats, built once: no builder call per poll.
        self._status_request = rq.read_status(node)
        self._monitor_request = rq.read_monitor(node)
        self.stats = TransactionStats()
        self.wait_time_s = wait_time_s
        self.timeout_s: float | None = None

    @property
    def node(self) -> int:
        """The drive's node address."""
        return self._node

    def __repr__(self) -> str:
        return f"<Drive {self._node:02d} on {self._channel.description}>"

    async def _execute(self, request: Request, *, urgent: bool = False) -> None:
        await self._data(request, urgent=urgent)

    def _data(self, request: Request, *, urgent: bool = False) -> Coroutine[Any, Any, bytes]:
        # Not a coroutine itself: the caller awaits the arbiter's, one frame less on
        # every resume of a transaction (see Channel.transact).
        return self._channel.transact(
            request, self.stats, wait_s=self.wait_time_s, timeout_s=self.timeout_s, urgent=urgent
        )

    async def read_status(self) -> InverterStatus:
        """Command 04: status A/B/C.

        Raises:
            NakError: the drive refused the request.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
        """
        # The reply parser has checked every character: decode without checking again.
        return _decode_status(await self._data(self._status_request))

    async def read_monitor(self) -> MonitorData:
        """Command 03: the monitor block. Raises as :meth:`read_status`."""
        return _decode_monitor(await self._data(self._monitor_request))

    async def read_trip_history(self) -> TripHistory:
        """Command 05: trip count and the six latest trips. Raises as :meth:`read_status`."""
        return _decode_trip_history(await self._data(rq.read_trip_history(self._node)))

    async def read_parameter_raw(self, code: str) -> int:
        """Command 06: a parameter's unscaled integer value.

        Raises:
            LocalProtocolError: *code* is not a parameter code (nothing sent).
            NakError: 16 when the drive does not know the code.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
        """
        return decode_parameter_value(await self._data(rq.read_parameter(self._node, code)))

    async def read_parameter(self, code: str) -> float:
        """Command 06: a parameter's engineering value (scaled by the catalogue).

        Raises as :meth:`read_parameter_raw`.
        """
        return parameter_info(code).from_raw(await self.read_parameter_raw(code))

    async def can_store(self) -> bool:
        """Command 09: may settings be stored to EEPROM now? Raises as :meth:`read_status`."""
        return decode_can_store(await self._data(rq.can_store(self._node)))

    async def recalculate_constants(self) -> None:
        """Command 0B: recalculate the motor constants. Raises as :meth:`run_forward`."""
        await self._execute(rq.recalculate(self._node))


class Broadcast(_Commands):
    """Every drive on the bus at once (node FF). Nothing answers; the bus waits for them.

    Only the commands the protocol allows to broadcast are offered.
    """

    def __init__(self, channel: Channel[Request]) -> None:
        self._channel = channel
        self._node = BROADCAST
        self.stats = TransactionStats()

    def __repr__(self) -> str:
        return f"<Broadcast on {self._channel.description}>"

    async def _execute(self, request: Request, *, urgent: bool = False) -> None:
        await self._channel.send(request, self.stats, urgent=urgent)
