"""The PUBACK watch: a QoS 1 publish (or a SUBSCRIBE) unanswered for ``keepalive_s`` ends the link.

A broker may answer every PINGREQ and never acknowledge a publish: the
connection looks alive, the publisher would wait for ever, and the will
never speaks. So the client's keepalive tick (every ``keepalive_s / 2``)
asks :class:`PubackWatch` about the oldest QoS 1 publish in flight, and
ends the connection once it has waited ``keepalive_s``: within 1.5
``keepalive_s`` of its writing, like a missing PINGRESP.

Decisions:

- No clock read per message (the publishing path is the client's hot
  one): a publish's wait counts from its batch's last write (one clock
  read per batch) or from the first tick that saw it the oldest, whichever
  came first. The wait said is never more than the truth; one written
  while its batch still waited for in-flight slots is found up to half a
  keepalive later.
- The in-flight map keeps insertion order, so its first id is the oldest
  publish unacknowledged. Ids are reused, so the watch knows a publish by
  its id *and* its batch: the same pair names another publish only after
  the 65,534 other ids went round within one batch.
- While the reader is behind, the broker's answers wait behind the
  messages it has not taken (reading is paused): nothing is judged before
  reading goes on (:meth:`PubackWatch.hold`), as the PINGRESP is not.
- **A SUBSCRIBE or UNSUBSCRIBE is judged the same way**, by a second
  watch over the client's :class:`Request` objects: a broker that never
  sends the SUBACK otherwise hung a session's set-up for ever (it
  subscribes before it starts reading or publishing, so nothing else
  noticed). A request is its own "batch", written when it is sent (one
  clock read per request: they are few); :func:`unanswered` says which.

Sans-IO: the caller gives the time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Final, Generic, Protocol, TypeVar

from ._types import SubscribeUnacknowledged

__all__ = ["PubackWatch", "Request", "Written", "unanswered"]

#: How much of a request's topic filters an error shows.
_EXCERPT: Final = 80
#: The packet that answers each request.
_ANSWERS: Final = {"SUBSCRIBE": "SUBACK", "UNSUBSCRIBE": "UNSUBACK"}

F = TypeVar("F")


class Written(Protocol):
    """A batch of publishes: when its last message was written (inf: not yet)."""

    written: float


class PubackWatch:
    """The oldest QoS 1 publish in flight, judged at each tick (module docstring)."""

    __slots__ = ("_judged_from", "_oldest", "keepalive_s")

    def __init__(self, keepalive_s: float) -> None:
        self.keepalive_s = keepalive_s
        #: The oldest publish as the last tick saw it: its id, batch, and wait's start.
        self._oldest: tuple[int, Written, float] | None = None
        self._judged_from = -math.inf

    def hold(self, now: float) -> None:
        """The broker's answers are held back until *now* (reading paused): judge from here."""
        self._oldest, self._judged_from = None, now

    def overdue(self, now: float, inflight: Mapping[int, Written]) -> tuple[int, float] | None:
        """(packet id, seconds waited) of the oldest publish past ``keepalive_s``, else None."""
        if not inflight:
            self._oldest = None
            return None
        packet_id = next(iter(inflight))
        batch = inflight[packet_id]
        oldest = self._oldest
        if oldest is None or oldest[0] != packet_id or oldest[1] is not batch:
            since = max(min(now, batch.written), self._judged_from)
            oldest = self._oldest = (packet_id, batch, since)
        waited = now - oldest[2]
        return (packet_id, waited) if waited >= self.keepalive_s else None


class Request(Generic[F]):
    """A SUBSCRIBE or UNSUBSCRIBE waiting for its answer: *future* gets it (the client's)."""

    __slots__ = ("filters", "future", "packet", "written")

    def __init__(self, future: F, written: float, packet: str, filters: str) -> None:
        self.future = future
        #: Loop time it was written.
        self.written = written
        #: ``"SUBSCRIBE"`` or ``"UNSUBSCRIBE"``.
        self.packet = packet
        #: Its topic filters, comma-separated (for the error).
        self.filters = filters


def unanswered(
    packet_id: int, waited: float, requests: Mapping[int, Request[F]], *, keepalive_s: float,
    client: str,
) -> SubscribeUnacknowledged:  # fmt: skip
    """The error that ends a connection whose request *packet_id* waited *waited* s."""
    request = requests[packet_id]
    filters = request.filters
    if len(filters) > _EXCERPT:
        filters = filters[: _EXCERPT - 1] + "…"
    return SubscribeUnacknowledged(
        f"no {_ANSWERS.get(request.packet, 'answer')} for {waited:.1f} s (keepalive_s "
        f"{keepalive_s:g}): {request.packet} packet {packet_id} ({filters}) of client {client}, "
        f"the oldest of {len(requests)} waiting"
    )
