"""The workbench's event stream: server-sent events, encoded once, coalesced per subject.

Sans-IO but for one :class:`asyncio.Event` per stream. The gateway hands
each new state (a drive's snapshot, a line's counters) to
:meth:`EventHub.publish` as one encoded frame, built once for every open
stream; each :class:`EventStream` keeps the frames its client has not been
sent yet.

Decisions:

- **Latest state wins.** A stream keeps at most one pending frame per
  subject (a drive, a line): a new one replaces the one not yet sent,
  where it stood. A client that reads slowly (a tab in the background, a
  slow link) gets the newest state of everything, never a backlog, and
  the gateway's memory per stream is bounded by the number of subjects.
  Each replaced frame is counted (``sj300_http_events_replaced_total``):
  nothing is dropped silently.
- Publishing never blocks and never awaits: it runs in the gateway's
  batch (the northbound's ``publish``).
- **One write per batch, not per sample.** A drive's frame is put in
  every stream without waking it (``wake=False``); the gateway's batch of
  snapshots ends with the northbound's ``flush``, which wakes each stream
  with frames pending (:meth:`EventHub.flush`), and the stream writes
  them together. Waking every stream's task for every sample cost the
  gateway more than the poll itself (see docs/BENCHMARKS.md, "workbench").
  The gateway's batch did the gathering: a stream has no timer of its own
  (it used to wait 50 ms more, issue 42). A line's frames come from the
  workbench's own tick, all in one step, and wake the streams at once.
- The frames are SSE's (``event: NAME`` and one ``data:`` line of JSON);
  a comment line keeps an idle stream alive through proxies and tells a
  dead client from a quiet gateway (the write fails).
"""

from __future__ import annotations

import asyncio
from typing import Any, Final

from .. import compact_json

__all__ = ["KEEPALIVE", "EventHub", "EventStream", "sse_frame"]

#: What an idle stream is sent every ``keepalive_s`` (an SSE comment).
KEEPALIVE: Final = b": keepalive\n\n"


def sse_frame(event: str, data: Any) -> bytes:
    """One server-sent event: ``event: NAME``, its JSON on one ``data:`` line."""
    return b"event: %s\ndata: %s\n\n" % (event.encode(), compact_json(data))


class EventStream:
    """One client's pending frames, at most one per subject (see the module docstring)."""

    def __init__(self, hub: EventHub) -> None:
        self._hub = hub
        self._pending: dict[str, bytes] = {}
        self._ready = asyncio.Event()
        self.closed = False

    def put(self, subject: str, frame: bytes, *, wake: bool = True) -> None:
        """*frame* of *subject* to send, replacing one not sent yet; *wake*: now (else at
        the next :meth:`wake`)."""
        if subject in self._pending:
            self._hub.replaced += 1
        self._pending[subject] = frame
        if wake:
            self._ready.set()

    def wake(self) -> None:
        """Send what is pending (the batch it belongs to is whole)."""
        if self._pending:
            self._ready.set()

    async def take(self, timeout_s: float) -> bytes | None:
        """The pending frames as one chunk, waiting up to *timeout_s* to be woken for them.

        Returns b"" when none came in time, None once the stream is closed.
        """
        if not self._ready.is_set() and not self.closed:
            try:
                async with asyncio.timeout(timeout_s):
                    await self._ready.wait()
            except TimeoutError:
                return b""
        if self.closed:
            return None
        chunk = b"".join(self._pending.values())
        self._hub.sent += len(self._pending)
        self._pending.clear()
        self._ready.clear()
        return chunk

    def close(self) -> None:
        self.closed = True
        self._ready.set()


class EventHub:
    """Every open stream; :meth:`publish` puts a frame into each."""

    def __init__(self) -> None:
        self._streams: set[EventStream] = set()
        #: Frames handed to clients, and frames replaced by a newer one before being sent.
        self.sent = 0
        self.replaced = 0
        #: Streams opened since the start.
        self.opened = 0

    def __len__(self) -> int:
        return len(self._streams)

    def open(self) -> EventStream:
        stream = EventStream(self)
        self._streams.add(stream)
        self.opened += 1
        return stream

    def discard(self, stream: EventStream) -> None:
        stream.close()
        self._streams.discard(stream)

    def publish(self, subject: str, frame: bytes, *, wake: bool = True) -> None:
        """*frame* of *subject* into every stream; *wake*: sent now, else at :meth:`flush`."""
        for stream in self._streams:
            stream.put(subject, frame, wake=wake)

    def flush(self) -> None:
        """Wake every stream with frames pending: the batch they belong to is whole."""
        for stream in self._streams:
            stream.wake()

    def close(self) -> None:
        """End every stream (the gateway is stopping)."""
        for stream in list(self._streams):
            self.discard(stream)
