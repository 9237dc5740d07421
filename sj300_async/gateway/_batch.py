"""The northbounds' snapshots, handed over together: each northbound takes a batch in turn.

A gateway of 64 lines makes 2,048 snapshots a second. Handed to every
northbound as each is made, the northbounds' code and tables take turns in
the processor's caches with the polls' and with each other's; done
northbound by northbound over the snapshots of 50 ms, the same work costs
markedly less (the figures are in the CHANGELOG). So the gateway gathers
them here and delivers them every :data:`PUBLISH_EVERY_S`, each northbound
its whole batch before the next.

Decisions:

- **50 ms more delay at most, never a reordering.** Each northbound sees
  every snapshot, in the order they were made; the poll interval is a
  second. A write's read-back or a new trip history is not gathered: the
  gateway flushes it at once, after what was gathered before it (someone
  is waiting for it). Commands, leases and stops do not go through here,
  nor do reads (a Modbus or OPC UA read takes the drive's latest snapshot
  itself): it carries only what the northbounds publish.
- **A long batch is delivered in pieces** of :data:`CHUNK` snapshots, each in
  a loop callback of its own, so the loop serves the lines between them (a
  reply waits behind a piece: line time). A plant of 2,048 drives makes
  about 100 snapshots in 50 ms, so its batches go whole, about 8 ms of the
  northbounds' work each; a piece bounds what a burst (many lines back at
  once) can hold the loop. Pieces of 64, which split the plant's batches,
  gave back much of the gain (see CHANGELOG).
- **:meth:`SnapshotBatch.flush` delivers what is gathered at once** (the
  gateway stopping: the northbounds get every snapshot made before they
  close).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Final, Generic, TypeVar

__all__ = ["CHUNK", "PUBLISH_EVERY_S", "SnapshotBatch"]

#: What is gathered: the gateway's are drives as served (:class:`~._served.ServedDrive`).
T = TypeVar("T")

#: Seconds snapshots are gathered before the northbounds take them.
PUBLISH_EVERY_S: Final = 0.05
#: Snapshots delivered in one loop callback at most.
CHUNK: Final = 256


class SnapshotBatch(Generic[T]):
    """Snapshots gathered, then passed to *deliver* in order (see the module docstring)."""

    def __init__(
        self,
        deliver: Callable[[list[T]], None],
        *,
        every_s: float = PUBLISH_EVERY_S,
        chunk: int = CHUNK,
    ) -> None:
        self._deliver = deliver
        self._every_s = every_s
        self._chunk = chunk
        self._pending: list[T] = []
        #: The timer or the callback that delivers next (None: nothing pending).
        self._next: asyncio.Handle | None = None

    def __len__(self) -> int:
        return len(self._pending)

    def add(self, snapshot: T) -> None:
        """Gather *snapshot*; it is delivered within :data:`PUBLISH_EVERY_S`."""
        self._pending.append(snapshot)
        if self._next is None:
            self._next = asyncio.get_running_loop().call_later(self._every_s, self._drain)

    def _drain(self) -> None:
        """Deliver the next piece; the rest (and what came meanwhile) in the next callback."""
        pending = self._pending
        piece = pending[: self._chunk]
        del pending[: self._chunk]
        self._next = asyncio.get_running_loop().call_soon(self._drain) if pending else None
        self._deliver(piece)

    def flush(self) -> None:
        """Deliver everything gathered now, and cancel the delivery that was due."""
        if self._next is not None:
            self._next.cancel()
            self._next = None
        pending, self._pending = self._pending, []
        if pending:
            self._deliver(pending)
