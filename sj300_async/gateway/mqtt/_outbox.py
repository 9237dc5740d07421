"""The bridge's outbox: what waits to be published, and how it is sent.

Three kinds wait:

- **the latest per topic** (states, availability, a discovery config made
  again): a newer message replaces an older one unsent (counted per drive
  for states);
- **error replies and events**, in order and never replaced, at most
  :data:`MAX_ERRORS` (the oldest is dropped, counted);
- **the discovery configs of an announcement** (every config, at each
  connection and at each Home Assistant birth), made as they are sent, a
  chunk at a time, after what else waits. Made all at once they were a dict
  and a payload per config, 46 configs a drive: at 2,048 drives some 140 MB
  at every (re)connection, of which the process kept most as its resident
  size (issue 44). Each is made from the configuration and the drive's
  maximum as they are when its chunk is made, so a config made again since
  (its drive's maximum changed) is never followed by an older one.
"""

from __future__ import annotations

import asyncio
import collections
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import islice
from typing import Final

from ..mqttlink.client import Client, MqttError
from ._stats import BridgeStats

__all__ = ["MAX_ERRORS", "MAX_IN_FLIGHT", "Key", "Out", "Outbox"]

_log = logging.getLogger("sj300_async.gateway.mqtt")

#: Error replies waiting to be sent, at most (the oldest is dropped, counted).
MAX_ERRORS: Final = 100
#: Publishes in flight at once: a batch is sent in chunks of this many, each
#: acknowledged before the next goes.
MAX_IN_FLIGHT: Final = 256

Key = tuple[str, int]


@dataclass(frozen=True, slots=True)
class Out:
    """One message to publish."""

    topic: str
    payload: bytes
    retain: bool
    #: The drive of a state message (counted per drive), else None.
    drive: Key | None = None


class Outbox:
    """What waits to be published (see the module docstring)."""

    def __init__(self, stats: BridgeStats) -> None:
        self.stats = stats
        #: The latest per topic.
        self.pending: dict[str, Out] = {}
        #: Error replies and events, in order (each is an answer: never coalesced).
        self.errors: collections.deque[Out] = collections.deque()
        #: The announcement's discovery configs not made yet (None: none under way).
        self.announcing: Iterator[Out] | None = None

    def __len__(self) -> int:
        """Messages made and waiting (an announcement's configs not made yet aside)."""
        return len(self.pending) + len(self.errors)

    @property
    def waiting(self) -> bool:
        """Anything waits, an announcement under way included."""
        return bool(self.pending or self.errors or self.announcing is not None)

    def put(self, out: Out) -> None:
        """*out*, replacing a message of its topic not sent yet."""
        old = self.pending.pop(out.topic, None)
        if old is not None and old is not out and old.drive is not None:
            self.stats.replaced[old.drive] += 1
            _log.debug("%s: replaced by a newer state before it was sent", out.topic)
        self.pending[out.topic] = out

    def put_error(self, out: Out) -> None:
        """An error reply or an event (see the module docstring)."""
        if len(self.errors) >= MAX_ERRORS:
            dropped = self.errors.popleft()
            self.stats.errors_dropped += 1
            _log.debug("error reply on %s dropped: %d waiting", dropped.topic, MAX_ERRORS)
        self.errors.append(out)

    def announce(self, configs: Iterator[Out]) -> None:
        """Send *configs* (made as they are sent), in place of an announcement under way."""
        self.announcing = configs

    def _next_batch(self) -> list[Out]:
        batch = list(self.pending.values())
        self.pending.clear()
        batch += self.errors
        self.errors.clear()
        if self.announcing is not None and len(batch) < MAX_IN_FLIGHT:
            more = list(islice(self.announcing, MAX_IN_FLIGHT - len(batch)))
            if len(more) < MAX_IN_FLIGHT - len(batch):
                self.announcing = None  # all made
            batch += more
        return batch

    async def send(self, client: Client, qos: int) -> None:
        """Publish everything waiting; raise the connection's error after counting what
        it cost."""
        while self.waiting:
            batch = self._next_batch()
            for start in range(0, len(batch), MAX_IN_FLIGHT):
                chunk = batch[start : start + MAX_IN_FLIGHT]
                try:
                    await client.publish_many(
                        [(out.topic, out.payload, out.retain) for out in chunk], qos=qos
                    )
                except (asyncio.CancelledError, MqttError) as exc:
                    # Stopped or lost mid-batch: this chunk's fate is unknown (it may
                    # have reached the broker), the rest was never sent. Counted as
                    # lost, since none is confirmed; never silently. (An announcement's
                    # configs not made yet are made again at the next connection.)
                    self.stats.lost += len(batch) - start
                    _log.debug("MQTT: %d messages unconfirmed: %s", len(batch) - start,
                               exc or type(exc).__name__)  # fmt: skip
                    raise
                self.stats.published += len(chunk)
                states = self.stats.states
                for out in chunk:
                    if out.drive is not None:
                        states[out.drive] += 1

    def abandon(self) -> int:
        """Forget what waits (the bridge stops): the messages made and not sent."""
        count = len(self)
        self.pending.clear()
        self.errors.clear()
        self.announcing = None
        return count
