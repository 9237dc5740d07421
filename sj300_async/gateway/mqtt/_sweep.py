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
  (``<discovery_prefix>/+/sj300_<id>_<line>_<node>/+/config``);
- a drive no longer configured loses all of those; a drive still
  configured loses only the configs the present configuration does not
  make (a grant taken away: its buttons);
- decommissioning (``keep=None``: ``sj300 gateway --decommission``) clears
  everything, the gateway's own availability and device too.

It runs once at the gateway's start, beside the bridge, on a connection of
its own (``<client id>-sweep``, no will), and waits for the broker's
retained messages with a barrier: a message it publishes to itself after
subscribing arrives after them (one connection, in order). What it cleared
is counted and said in one line. A broker whose ACL refuses the
subscriptions leaves things as they were, said once at WARNING.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import secrets
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Final

from ..mqttlink import new_client
from ..mqttlink.client import Client, Message, MqttError
from ._config import MqttConfig
from ._discovery import node_id
from ._stats import BridgeStats
from ._topics import Topics

__all__ = ["SweepRefused", "Swept", "sweep", "sweep_and_say", "sweep_served"]

_log = logging.getLogger("sj300_async.gateway.mqtt")

#: How long the broker may take to hand over what it retained, per barrier.
BARRIER_TIMEOUT_S: Final = 30.0
#: Filters per SUBSCRIBE (a plant has 2,048 drives).
FILTERS_PER_SUBSCRIBE: Final = 256
#: Retained topics read at most: a broker holding more under one gateway id is not ours.
MAX_TOPICS: Final = 200_000


class SweepRefused(Exception):
    """The broker refused a subscription the sweep needs (an ACL): nothing was cleared."""


@dataclass(frozen=True, slots=True)
class Swept:
    """What a sweep cleared."""

    #: Drives no longer configured whose retained topics were cleared.
    drives: tuple[tuple[str, int], ...]
    #: Retained topics cleared, in all.
    topics: int


class _Collector:
    """The retained messages read until a barrier comes back."""

    def __init__(self, client: Client) -> None:
        self._client = client
        self.retained: set[str] = set()

    async def until_barrier(self, barrier: str) -> None:
        await self._client.publish(barrier, b"", qos=1)
        async with asyncio.timeout(BARRIER_TIMEOUT_S):
            async for message in self._client.messages:
                if message.topic == barrier:
                    return
                self._take(message)

    def _take(self, message: Message) -> None:
        # A live message (the bridge publishing as we read) says nothing of the past;
        # an empty retained one is a cleared topic.
        if message.retain and message.length > 0 and len(self.retained) < MAX_TOPICS:
            self.retained.add(message.topic)


async def sweep(
    config: MqttConfig,
    topics: Topics,
    keep: Mapping[tuple[str, int], Iterable[str]] | None,
    *,
    gateway_configs: Iterable[str] = (),
) -> Swept:
    """Clear what *topics*' gateway left retained that is not in *keep* (module docstring).

    *keep*: every drive configured now and the discovery config topics it has
    now; None: nothing is kept (decommissioning). *gateway_configs*: the
    gateway device's own config topics, cleared only when *keep* is None.

    Raises:
        SweepRefused: a subscription refused.
        MqttError, OSError, TimeoutError: the broker unreachable or too slow.
    """
    kept = {} if keep is None else {drive: set(configs) for drive, configs in keep.items()}
    own = f"{topics.prefix}/{topics.gateway}"
    discovered = f"{config.discovery_prefix}/+/{{}}/+/config"
    async with new_client(config, identifier=f"{config.client_id}-sweep") as client:
        collector = _Collector(client)
        barrier = f"{own}/sweep/{secrets.token_hex(8)}"
        await _subscribe(
            client,
            [
                f"{own}/+/+/state",
                f"{own}/+/+/availability",
                topics.availability,
                discovered.format(node_id("sj300", topics.gateway)),
                barrier,
            ],
        )
        await collector.until_barrier(barrier)
        served = {d for d in map(functools.partial(_drive, own), collector.retained) if d}
        drives = sorted(served | set(kept))
        await _subscribe(client, [discovered.format(_node_id(topics, d)) for d in drives])
        await collector.until_barrier(barrier)
        wanted: set[str] = set()
        if keep is not None:
            wanted |= {topics.availability, *gateway_configs}
        for (line, node), configs in kept.items():
            wanted |= {topics.state(line, node), topics.drive_availability(line, node), *configs}
        clear = sorted(collector.retained - wanted)
        if clear:
            await client.publish_many(((topic, b"", True) for topic in clear), qos=1)
    gone = tuple(d for d in drives if d not in kept)
    return Swept(gone, len(clear))


async def sweep_served(
    config: MqttConfig, topics: Topics, drives: Iterable[tuple[str, int]], made: Iterable[str]
) -> Swept:
    """:func:`sweep` keeping *drives* (served now) and the discovery config topics *made*
    now (each under its drive's node id, or the gateway's own)."""
    by_node: dict[str, list[str]] = {}
    for topic in made:
        by_node.setdefault(topic.split("/")[-3], []).append(topic)
    keep = {drive: by_node.get(_node_id(topics, drive), []) for drive in drives}
    own = by_node.get(node_id("sj300", topics.gateway), [])
    return await sweep(config, topics, keep, gateway_configs=own)


async def sweep_and_say(
    config: MqttConfig,
    topics: Topics,
    drives: Iterable[tuple[str, int]],
    made: Iterable[str],
    stats: BridgeStats,
) -> None:
    """:func:`sweep_served` at the bridge's start: counted in *stats*, said in one line,
    a failure said at WARNING (the next start tries again)."""
    try:
        swept = await sweep_served(config, topics, drives, made)
    except (SweepRefused, MqttError, OSError, TimeoutError) as exc:
        _log.warning("MQTT: could not clear what an earlier configuration left retained: %s",
                     exc or type(exc).__name__)  # fmt: skip
        return
    stats.swept += swept.topics
    if swept.topics:
        gone = ", ".join(f"{line} {node}" for line, node in swept.drives) or "none"
        _log.info("MQTT: cleared %d retained topics an earlier configuration left (drives no "
                  "longer configured: %s)", swept.topics, gone)  # fmt: skip


async def _subscribe(client: Client, filters: list[str]) -> None:
    for start in range(0, len(filters), FILTERS_PER_SUBSCRIBE):
        chunk = filters[start : start + FILTERS_PER_SUBSCRIBE]
        granted = await client.subscribe([(f, 1) for f in chunk], qos=1)
        refused = [f for f, qos in zip(chunk, granted, strict=True) if qos >= 0x80]
        if refused:
            raise SweepRefused(f"the broker refused the subscription to {refused[0]}")


def _drive(own: str, topic: str) -> tuple[str, int] | None:
    """``(line, node)`` of a drive's state or availability topic of this gateway."""
    if not topic.startswith(f"{own}/"):
        return None
    parts = topic.removeprefix(f"{own}/").split("/")
    if len(parts) != 3 or not parts[1].isdigit():
        return None
    return parts[0], int(parts[1])


def _node_id(topics: Topics, drive: tuple[str, int]) -> str:
    return node_id("sj300", topics.gateway, *drive)
