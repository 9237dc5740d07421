"""What a gateway left retained on the broker and no longer serves: found and cleared.

A drive removed from the configuration kept its retained discovery
configs, its ``online`` availability and its last state on the broker for
ever, so Home Assistant showed it as live (issue 43). :func:`sweep` finds
what this gateway id published before and clears (an empty retained
message) what the present configuration would not publish:

- every retained ``<prefix>/<id>/<line>/<node>/state`` and
  ``…/availability`` tells a drive this gateway served once (the topics'
  levels name the gateway id exactly: another gateway's are never read);
- for each such drive, and each drive configured now, the retained
  discovery configs under its node id
  (``<discovery_prefix>/+/sj300_<id>_<line>_<node>/+/config``) that name
  this gateway's topics (another gateway's node id may be written alike:
  ``gw1_b``'s ``hall`` 1 and ``gw1``'s ``b_hall`` 1);
- a drive no longer configured loses all of those; a drive still
  configured loses only the configs the present configuration does not
  make (a grant taken away: its buttons);
- decommissioning (``keep=None``: ``sj300 gateway --decommission``) clears
  everything, the gateway's own availability and device too.

It runs at the bridge's first connection, on that connection (a broker
that ties client ids to its ACL, as AWS IoT does, needs no second id), and
again at the next one until it ran to its end. It waits for the broker's
retained messages with a barrier: a message it publishes to itself after
subscribing arrives after them (one connection, in order); once done it
unsubscribes, not to get every state the gateway publishes back.
``--decommission`` runs it on a connection of its own. What it cleared
is counted and said in one line. A broker whose ACL refuses the
subscriptions leaves things as they were, said once at WARNING.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import secrets
from collections.abc import Coroutine, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Final

from ..mqttlink import new_client
from ..mqttlink.client import Client, Message, MqttError
from ._config import MqttConfig
from ._discovery import node_id
from ._stats import BridgeStats
from ._topics import Topics, parse_node

__all__ = ["SweepRefused", "Sweeper", "Swept", "keep_of", "sweep", "sweep_and_say"]

_log = logging.getLogger("sj300_async.gateway.mqtt")

#: How long the broker may take to hand over what it retained, per barrier.
BARRIER_TIMEOUT_S: Final = 30.0
#: Filters per SUBSCRIBE (a plant has 2,048 drives).
FILTERS_PER_SUBSCRIBE: Final = 256
#: Retained topics read at most: a broker holding more under one gateway id is not ours.
MAX_TOPICS: Final = 200_000
#: Drives no longer configured whose configs one sweep looks for (the next gets the rest).
MAX_GONE_DRIVES: Final = 4096


class SweepRefused(Exception):
    """The broker refused a subscription the sweep needs (an ACL): nothing was cleared."""


@dataclass(frozen=True, slots=True)
class Swept:
    """What a sweep cleared."""

    #: Drives no longer configured whose retained topics were cleared.
    drives: tuple[tuple[str, int], ...]
    #: Retained topics cleared, in all.
    topics: int


class Sweeper:
    """One sweep on a connection whose reader hands it every message (:meth:`feed`).

    The bridge runs it on its own connection (one connection per gateway: a
    broker that ties client ids to ACLs, as AWS IoT does, needs no second
    id); ``sweep`` runs it on one of its own for ``--decommission``.
    """

    def __init__(self, config: MqttConfig, topics: Topics) -> None:
        self._config, self._topics = config, topics
        self._own = f"{topics.prefix}/{topics.gateway}"
        self._barrier = f"{self._own}/sweep/{secrets.token_hex(8)}"
        #: In every config this gateway publishes (its state or availability topics).
        self._names_us = f'"{self._own}/'.encode()
        self._arrived = asyncio.Event()
        self._subscribed: list[str] = []
        #: The non-empty retained topics read so far.
        self.retained: set[str] = set()
        #: It ran to its end (the bridge's: no sweep at the next connection).
        self.done = False

    def feed(self, message: Message) -> bool:
        """True when *message* is the sweep's (then the reader drops it): on the topics it
        reads, which the bridge never subscribes to otherwise, also once it is done
        (the echo of the gateway's own publishes, until the unsubscription took)."""
        topic = message.topic
        if topic.startswith(f"{self._own}/sweep/"):
            # Only this round's: a barrier goes to every subscriber, who could replay it
            # to end the next round before its retained messages came.
            if topic == self._barrier:
                self._arrived.set()
            return True
        ours = topic.startswith(f"{self._own}/") and topic.endswith(("/state", "/availability"))
        if not ours and not (
            topic.startswith(f"{self._config.discovery_prefix}/") and topic.endswith("/config")
        ):
            return False
        # A live message (the bridge publishing as we read) says nothing of the past; an
        # empty retained one is a cleared topic. A config is ours only when it names our
        # topics: another gateway's node id may be written alike (gw1_b's hall 1 and
        # gw1's b_hall 1 are both sj300_gw1_b_hall_1), and junk under our id names it.
        if (
            message.retain
            and message.length > 0
            and len(self.retained) < MAX_TOPICS
            and (ours or (not message.skipped and self._names_us in message.payload))
        ):
            self.retained.add(topic)
        return True

    async def run(
        self,
        client: Client,
        keep: Mapping[tuple[str, int], Iterable[str]] | None,
        gateway_configs: Iterable[str] = (),
    ) -> Swept:
        """Clear what the gateway left retained that is not in *keep* (:func:`sweep`)."""
        topics, own = self._topics, self._own
        kept = {} if keep is None else {drive: set(configs) for drive, configs in keep.items()}
        discovered = f"{self._config.discovery_prefix}/+/{{}}/+/config"
        try:
            await self._subscribe(
                client,
                [
                    f"{own}/+/+/state",
                    f"{own}/+/+/availability",
                    topics.availability,
                    discovered.format(node_id("sj300", topics.gateway)),
                    self._barrier,
                ],
            )
            await self._until_barrier(client)
            served = {d for d in map(functools.partial(_drive, own), self.retained) if d}
            # Anyone the broker lets publish under this gateway's id could leave retained
            # junk for thousands of drives: their configs are looked for up to a bound.
            drives = sorted(served | set(kept))[: len(kept) + MAX_GONE_DRIVES]
            self._barrier = f"{own}/sweep/{secrets.token_hex(8)}"  # a round's own (feed)
            filters = [discovered.format(_node_id(topics, d)) for d in drives]
            await self._subscribe(client, [*filters, self._barrier])
            await self._until_barrier(client)
            wanted: set[str] = set()
            if keep is not None:
                wanted |= {topics.availability, *gateway_configs}
            for (line, node), configs in kept.items():
                wanted |= {
                    topics.state(line, node),
                    topics.drive_availability(line, node),
                    *configs,
                }
            clear = sorted(self.retained - wanted)
            if clear:
                await client.publish_many(((topic, b"", True) for topic in clear), qos=1)
        finally:
            if self._subscribed:  # not to get every state the gateway publishes back
                with contextlib.suppress(MqttError, OSError):  # the connection's gone: moot
                    await client.unsubscribe(self._subscribed)
        return Swept(tuple(d for d in drives if d not in kept), len(clear))

    async def _subscribe(self, client: Client, filters: list[str]) -> None:
        for start in range(0, len(filters), FILTERS_PER_SUBSCRIBE):
            chunk = filters[start : start + FILTERS_PER_SUBSCRIBE]
            granted = await client.subscribe([(f, 1) for f in chunk], qos=1)
            self._subscribed += chunk
            refused = [f for f, qos in zip(chunk, granted, strict=True) if qos >= 0x80]
            if refused:
                raise SweepRefused(f"the broker refused the subscription to {refused[0]}")

    async def _until_barrier(self, client: Client) -> None:
        """Until everything the broker had retained for the subscriptions so far came."""
        self._arrived.clear()
        await client.publish(self._barrier, b"", qos=1)
        async with asyncio.timeout(BARRIER_TIMEOUT_S):
            await self._arrived.wait()


async def sweep(
    config: MqttConfig,
    topics: Topics,
    keep: Mapping[tuple[str, int], Iterable[str]] | None,
    *,
    gateway_configs: Iterable[str] = (),
) -> Swept:
    """Clear what *topics*' gateway left retained that is not in *keep* (module docstring),
    on a connection of its own.

    *keep*: every drive configured now and the discovery config topics it has
    now; None: nothing is kept (decommissioning). *gateway_configs*: the
    gateway device's own config topics, cleared only when *keep* is None.

    Raises:
        SweepRefused: a subscription refused.
        MqttError, OSError, TimeoutError: the broker unreachable or too slow.
    """
    sweeper = Sweeper(config, topics)
    async with new_client(config, identifier=f"{config.client_id}-sweep") as client:

        async def read() -> None:
            async for message in client.messages:
                sweeper.feed(message)

        reading = asyncio.create_task(read())
        try:
            return await sweeper.run(client, keep, gateway_configs)
        finally:
            reading.cancel()
            await asyncio.gather(reading, return_exceptions=True)


def sweep_and_say(
    config: MqttConfig,
    topics: Topics,
    client: Client,
    made: Iterable[str],
    stats: BridgeStats,
    drives: Iterable[tuple[str, int]],
) -> tuple[Sweeper, Coroutine[Any, Any, None]]:
    """The bridge's sweep at its connection *client*, keeping *drives* and the configs it
    *made*: the sweeper (its reader feeds it) and the sweep to run as a task, counted
    in *stats*, said in one line, a failure said at WARNING (``done`` stays False: the
    next connection tries)."""
    sweeper = Sweeper(config, topics)
    keep, own = keep_of(topics, drives, made)

    async def run() -> None:
        try:
            swept = await sweeper.run(client, keep, own)
        except (SweepRefused, MqttError, OSError, TimeoutError) as exc:
            _log.warning("MQTT: could not clear what an earlier configuration left retained: "
                         "%s", exc or type(exc).__name__)  # fmt: skip
            return
        except Exception:  # a bug: said, not left in a task nobody reads until the loss
            _log.exception("MQTT: the sweep of what an earlier configuration left failed")
            return
        sweeper.done = True
        stats.swept += swept.topics
        if swept.topics:
            gone = ", ".join(f"{line} {node}" for line, node in swept.drives) or "none"
            _log.info("MQTT: cleared %d retained topics an earlier configuration left (drives "
                      "no longer configured: %s)", swept.topics, gone)  # fmt: skip

    return sweeper, run()


def keep_of(
    topics: Topics, drives: Iterable[tuple[str, int]], made: Iterable[str]
) -> tuple[dict[tuple[str, int], list[str]], list[str]]:
    """What to keep: *drives* (served now) each with its discovery config topics among
    *made*, and the gateway device's own configs."""
    by_node: dict[str, list[str]] = {}
    for topic in made:
        by_node.setdefault(topic.split("/")[-3], []).append(topic)
    keep = {drive: by_node.get(_node_id(topics, drive), []) for drive in drives}
    return keep, by_node.get(node_id("sj300", topics.gateway), [])


def _drive(own: str, topic: str) -> tuple[str, int] | None:
    """``(line, node)`` of a drive's state or availability topic of this gateway."""
    if not topic.startswith(f"{own}/"):
        return None
    parts = topic.removeprefix(f"{own}/").split("/")
    node = parse_node(parts[1]) if len(parts) == 3 else None
    return None if node is None else (parts[0], node)


def _node_id(topics: Topics, drive: tuple[str, int]) -> str:
    return node_id("sj300", topics.gateway, *drive)
