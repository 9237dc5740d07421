"""The fleet on a broker: every drive of every gateway, from what their MQTT bridges publish.

:class:`Fleet` is the model (sans-IO): it takes ``<prefix>/+/availability``
and ``<prefix>/+/+/+/state`` messages in (:meth:`Fleet.receive`) and keeps
the latest state of each (gateway, line, node). :func:`follow` is the
subscriber: it keeps a read-only connection (the transport's ``keep_connected``) and feeds
the model. ``sj300 monitor --url mqtt://…`` renders it; anything else may.

The URL: ``mqtt://[USER[:PASSWORD]@]HOST[:PORT][/PREFIX]``, ``mqtts://`` for
TLS (the system's certificate authorities). Ports default to 1883 and 8883;
the prefix to ``sj300``, and it may have several levels
(``mqtt://broker/plant/north``). Each level follows the contract's naming
rule (no wildcard, no empty level).

Decisions:

- Read-only: it never publishes (no will, no command topic; a clean
  session, so it leaves nothing behind on the broker either).
- Staleness: a gateway whose availability is ``offline`` (its last will:
  it died or lost the broker) makes its drives' retained states a past
  nobody is refreshing (:meth:`Fleet.gateway_online`). The availability is
  subscribed before the states, so that the broker hands over the retained
  availability first and no drive of a dead gateway is shown online, even
  for a moment.
- The topic is authoritative: a state whose payload names another
  (gateway, line, node) than its topic is malformed (a misrouted or
  hand-made message), as is one whose shown fields have the wrong type
  (``StateMessage.from_json`` checks only the gateway and the node: a text
  where a number belongs would otherwise break a table), a gateway or line
  that breaks the contract's naming rule, or text that is not printable
  (an escape sequence would reach a terminal as it is).
- Malformed messages (a payload that is no state, an availability that is
  neither ``online`` nor ``offline``, a topic the contract does not name)
  are skipped, counted and logged at DEBUG with a bounded excerpt of their
  payload; the first is kept for a summary (:meth:`Fleet.summary`).
- An empty payload clears a retained message (``mosquitto_pub -r -n``): it
  removes the drive (or forgets the gateway's availability) rather than
  counting as malformed.
- Cycles, as a bus monitor counts them (:attr:`Fleet.cycles`: what ``sj300
  monitor --count`` counts on a bus and a broker alike): a cycle is one
  state of every drive. Which drives there are is learnt from the first:
  the retained states the broker hands over on subscribing, one per drive
  (or, on a broker that holds none, the first states published). MQTT
  marks no end to them, so the first cycle ends when a drive already in it
  sends again (that state is the second cycle's), when the connection is
  lost, or when the consumer says every drive has been heard
  (:meth:`Fleet.end_first_cycle`: the fleet view does after ``--timeout``
  without a state). Each later cycle ends once every drive waited for has
  sent a state since it began; a drive whose state says offline, or whose
  gateway's availability does, is not waited for (as the bus monitor does
  not wait for a node set aside as offline), and a drive first heard of
  during a cycle is in it.
- Unreachable at the start: :class:`~sj300_async.gateway.mqttlink.BrokerUnreachable` (a
  command line fails at once). Lost later: reconnect with a back-off of
  0.5 s doubling to 10 s (a viewer wants to see the fleet back soon); the
  broker then hands over the retained states again.
- The client is the gateway's own (the MQTT transport's,
  :mod:`sj300_async.gateway.mqttlink.client`, standard library only):
  the view needs no extra.
"""

from __future__ import annotations

import asyncio
import logging
import math
import secrets
import ssl
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

from ...wire import LocalProtocolError
from .. import excerpt, valid_name
from ..mqttlink import keep_connected
from ..mqttlink.client import Client, MqttError
from ._topics import AVAILABLE, DEFAULT_PREFIX, UNAVAILABLE, StateMessage, parse_state_topic

__all__ = [
    "FLEET_SCHEMES",
    "Fleet",
    "FleetUrl",
    "Malformed",
    "SubscriptionRefused",
    "follow",
    "is_fleet_url",
    "parse_fleet_url",
]

_log = logging.getLogger("sj300_async.gateway.mqtt.fleet")

#: URL schemes of a broker (the fleet) rather than a bus, with their default ports.
FLEET_SCHEMES: Final = {"mqtt": 1883, "mqtts": 8883}
#: The reconnection back-off's ceiling.
BACKOFF_MAX_S: Final = 10.0
#: The broker connection's keep-alive: a silently dropped link is noticed within 1.5x this.
KEEPALIVE_S: Final = 10
#: How long connecting and subscribing may take, unless the caller says.
DEFAULT_TIMEOUT_S: Final = 10.0
#: How much of a malformed payload the DEBUG log shows.
_LOGGED_PAYLOAD: Final = 2048
#: How much of a malformed message's topic or reason the summary shows.
_SHOWN: Final = 200


class SubscriptionRefused(Exception):
    """The broker refused a subscription (an ACL)."""


def is_fleet_url(url: str) -> bool:
    """True when *url* names a broker (``mqtt://``, ``mqtts://``), not a bus."""
    scheme, sep, _ = url.partition("://")
    return bool(sep) and scheme.lower() in FLEET_SCHEMES


@dataclass(frozen=True, slots=True)
class FleetUrl:
    """A broker URL, taken apart."""

    scheme: str
    host: str
    port: int
    prefix: str = DEFAULT_PREFIX
    username: str | None = None
    password: str | None = None

    @property
    def tls(self) -> bool:
        return self.scheme == "mqtts"

    @property
    def broker(self) -> str:
        """``mqtt://HOST:PORT`` (never the password), for messages."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.scheme}://{host}:{self.port}"

    @property
    def availability_filter(self) -> str:
        return f"{self.prefix}/+/availability"

    @property
    def state_filter(self) -> str:
        return f"{self.prefix}/+/+/+/state"


def parse_fleet_url(url: str) -> FleetUrl:
    """Take ``mqtt[s]://[USER[:PASSWORD]@]HOST[:PORT][/PREFIX]`` apart.

    Raises:
        LocalProtocolError: not such a URL.
    """
    parts = urllib.parse.urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme not in FLEET_SCHEMES:
        raise LocalProtocolError(
            f"not a broker URL: {url!r} (mqtt://HOST:PORT[/prefix], mqtts://...)"
        )
    try:
        port = parts.port or FLEET_SCHEMES[scheme]
    except ValueError as exc:  # a port that is no number or out of range
        raise LocalProtocolError(f"bad broker URL {url!r}: {exc}") from None
    if not parts.hostname:
        raise LocalProtocolError(f"bad broker URL {url!r}: no host (mqtt://HOST:PORT[/prefix])")
    if parts.query or parts.fragment:
        raise LocalProtocolError(f"bad broker URL {url!r}: it takes no ?query or #fragment")
    prefix = parts.path.strip("/") or DEFAULT_PREFIX
    if not all(valid_name(level) for level in prefix.split("/")):
        raise LocalProtocolError(
            f"bad topic prefix {prefix!r}: levels of letters, digits, '_', '.', '-' "
            "separated by '/'"
        )
    unquote = urllib.parse.unquote
    return FleetUrl(
        scheme,
        parts.hostname,
        port,
        prefix,
        None if parts.username is None else unquote(parts.username),
        None if parts.password is None else unquote(parts.password),
    )


# --- what is known of the fleet (no I/O) -----------------------------------------------------


@dataclass(frozen=True, slots=True)
class Malformed:
    """The first malformed message: where it came, and why it was refused (escaped, bounded)."""

    topic: str
    reason: str


class Fleet:
    """The latest state of every drive on the broker, and how the connection is doing."""

    def __init__(self, url: FleetUrl) -> None:
        self.url = url
        self._drives: dict[tuple[str, str, int], StateMessage] = {}
        #: Each gateway's availability (True: online), once heard.
        self.gateways: dict[str, bool] = {}
        self.malformed = 0
        self.first_malformed: Malformed | None = None
        #: None while connected; else what is going on (``connecting``, ``lost ...``).
        self.link_problem: str | None = "connecting"
        #: Cycles complete (see the module docstring).
        self.cycles = 0
        #: The cycle the latest state belongs to (1: the first; 0 before any state).
        self.cycle = 0
        #: The drives heard from in the first cycle.
        self._heard: set[tuple[str, str, int]] = set()
        #: The drives a later cycle still waits for.
        self._pending: set[tuple[str, str, int]] = set()

    @property
    def drives(self) -> list[StateMessage]:
        """Every drive's latest state, sorted by gateway, line and node."""
        return [self._drives[key] for key in sorted(self._drives)]

    def gateway_online(self, gateway: str) -> bool:
        """False only when the gateway said ``offline`` (not yet heard: trusted)."""
        return self.gateways.get(gateway, True)

    def receive(self, topic: str, payload: bytes) -> StateMessage | None:
        """Take one message in; the state it carries, if it is one (else None)."""
        key = parse_state_topic(topic, self.url.prefix)
        if key is not None:
            state = self._state(key, topic, payload)
            if state is not None:
                self._count(key)
            return state
        gateway = self._availability_of(topic)
        if gateway is None:
            self._malformed(topic, payload, "not a state or availability topic")
        elif not payload:  # a retained availability cleared
            self.gateways.pop(gateway, None)
        elif payload in (AVAILABLE.encode(), UNAVAILABLE.encode()):
            self.gateways[gateway] = payload == AVAILABLE.encode()
        else:
            self._malformed(topic, payload, f"availability is {AVAILABLE!r} or {UNAVAILABLE!r}")
        return None

    def _state(self, key: tuple[str, str, int], topic: str, payload: bytes) -> StateMessage | None:
        if not payload:  # a retained state cleared: the drive is gone
            self._drives.pop(key, None)
            return None
        try:
            message = StateMessage.from_json(payload)
            _check_shown_fields(message)
        except ValueError as exc:
            self._malformed(topic, payload, str(exc))
            return None
        named = (message.gateway, message.line, message.node)
        if named != key:
            gateway, line, node = named
            self._malformed(topic, payload, f"the payload is {gateway}/{line}/{node}'s state")
            return None
        self._drives[key] = message
        return message

    def waits_for(self, key: tuple[str, str, int]) -> bool:
        """True when a cycle waits for the drive (gateway, line, node): it and its gateway
        are online."""
        message = self._drives.get(key)
        return message is not None and message.online and self.gateway_online(message.gateway)

    def waiting(self) -> bool:
        """True when a cycle waits for any drive (see :meth:`waits_for`)."""
        return any(self.waits_for(key) for key in self._drives)

    def end_first_cycle(self) -> None:
        """Every drive has been heard: the first cycle ends (if it holds any state)."""
        if self.cycles == 0 and self._heard:
            self._heard = set()
            self._next_cycle()

    def _next_cycle(self) -> None:
        self.cycles += 1
        self._pending = {key for key in self._drives if self.waits_for(key)}

    def _count(self, key: tuple[str, str, int]) -> None:
        """Count a state in its cycle (see the module docstring); O(1) amortized."""
        if self.cycles == 0:
            if key not in self._heard:
                self._heard.add(key)
                self.cycle = 1
                return
            self.end_first_cycle()  # a drive sends again: every drive has been heard
        self.cycle = self.cycles + 1
        self._pending.discard(key)
        self.recheck()

    def recheck(self) -> None:
        """A later cycle drops the drives it no longer waits for (offline, their gateway
        gone) and ends when none is left: after a state, and when a caller finds the
        fleet quiet (a gateway that died sends no state that would do it); O(1) amortized."""
        if self.cycles == 0:
            return
        pending = self._pending
        while pending:
            first = next(iter(pending))
            if self.waits_for(first):
                return
            pending.discard(first)
        self._next_cycle()

    def _availability_of(self, topic: str) -> str | None:
        head = self.url.prefix.split("/")
        parts = topic.split("/")
        if len(parts) != len(head) + 2 or parts[: len(head)] != head:
            return None
        gateway, last = parts[len(head) :]
        return gateway if last == "availability" else None

    def _malformed(self, topic: str, payload: bytes, reason: str) -> None:
        self.malformed += 1
        if self.first_malformed is None:  # shown on a terminal: no control character gets there
            self.first_malformed = Malformed(
                excerpt(topic, _SHOWN), excerpt(" ".join(reason.split()), _SHOWN)
            )
        shown = payload[:_LOGGED_PAYLOAD]
        more = f" (+{len(payload) - len(shown)} bytes)" if len(payload) > len(shown) else ""
        _log.debug("skipped a malformed message on %s: %s: %r%s", topic, reason, shown, more)

    def summary(self) -> str | None:
        """The line that ends a run that skipped malformed messages (None: none skipped)."""
        first = self.first_malformed
        if first is None:
            return None
        plural = "s" if self.malformed != 1 else ""
        return (
            f"{self.malformed} malformed message{plural} skipped "
            f"(first: {first.topic}: {first.reason})"
        )


def _check_shown_fields(message: StateMessage) -> None:
    """Refuse a state whose fields a view shows have the wrong type, or unprintable text.

    Raises:
        ValueError: the first such field.
    """

    def number(value: Any) -> bool:
        return isinstance(value, int | float) and not isinstance(value, bool)

    for name in ("gateway", "line"):
        if not isinstance(getattr(message, name), str) or not valid_name(getattr(message, name)):
            raise ValueError(f"{name} is not a name (letters, digits, '_', '.', '-')")
    if not number(message.time) or not math.isfinite(message.time):
        raise ValueError("time is not a finite number")
    if not isinstance(message.online, bool):
        raise ValueError("online is not true/false")
    for name in ("output_frequency_hz", "output_current_a", "output_voltage_v"):
        value = getattr(message, name)
        if value is not None and not number(value):
            raise ValueError(f"{name} is not a number")
    for name in ("direction", "trip", "protocol", "state", "trip_meaning"):
        value = getattr(message, name)
        if value is not None and not (isinstance(value, str) and value.isprintable()):
            raise ValueError(f"{name} is not printable text")
    if message.status is not None and not isinstance(message.status, dict):
        raise ValueError("status is not an object")


# --- the subscription ------------------------------------------------------------------------


async def follow(
    fleet: Fleet,
    on_state: Callable[[StateMessage], bool],
    *,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    on_link: Callable[[str | None], None] | None = None,
) -> None:
    """Subscribe and feed *fleet* until *on_state* answers False; reconnect when lost.

    *on_state* gets each state received and says whether to go on. *on_link*
    hears when the link is up (None: connected and subscribed) and when it
    is down (what happened, and when the next attempt comes).

    Raises:
        BrokerUnreachable: the broker cannot be reached at the start.
        SubscriptionRefused: the broker refused a subscription.
        Exception: whatever *on_state* or *on_link* raised (it ends the view).
    """
    url = fleet.url
    # A viewer of its own on the broker: two views never take each other's session.
    identifier = f"sj300-fleet-{secrets.token_hex(6)}"

    def connect() -> Client:
        return Client(
            url.host,
            url.port,
            identifier=identifier,
            username=url.username,
            password=url.password,
            tls=ssl.create_default_context() if url.tls else None,
            connect_timeout_s=timeout_s,
            keepalive_s=KEEPALIVE_S,
        )

    def link(problem: str | None) -> None:
        fleet.link_problem = problem
        if problem is not None:
            fleet.end_first_cycle()  # what came before the connection was lost
        if on_link is not None:
            on_link(problem)

    async def subscription(client: Client, connected: Callable[[], None]) -> None:
        # Availability first: the broker hands over retained messages in the order of
        # the filters, so a dead gateway's drives never show online, even briefly.
        filters = [(url.availability_filter, 1), (url.state_filter, 1)]
        try:
            async with asyncio.timeout(timeout_s):
                granted = await client.subscribe(filters)
        except TimeoutError:
            raise MqttError(f"no answer to the subscription within {timeout_s:g} s") from None
        _check_granted(url, granted)
        connected()
        async for message in client.messages:
            if message.skipped:  # past the client's limit: only its head was read
                fleet._malformed(
                    message.topic, message.payload, f"{message.length} bytes: not read"
                )
                continue
            state = fleet.receive(message.topic, message.payload)
            if state is not None and not on_state(state):
                return

    await keep_connected(
        connect,
        subscription,
        url=url.broker,
        log=_log,
        ceiling_s=BACKOFF_MAX_S,
        outage_level=logging.INFO,
        fail_first=True,
        survive_errors=False,  # the consumer's error (a closed pipe) ends the view
        on_link=link,
        on_attempt=lambda n: setattr(
            fleet, "link_problem", f"reconnecting to {url.broker} (attempt {n})"
        ),
    )


def _check_granted(url: FleetUrl, granted: tuple[int, ...]) -> None:
    """A subscription the broker refused (an ACL) fails, naming the filter.

    Raises:
        SubscriptionRefused: a refusal (the SUBACK's reason code 0x80 or above).
    """
    filters = (url.availability_filter, url.state_filter)
    for topic_filter, code in zip(filters, granted, strict=False):
        if code >= 0x80:
            raise SubscriptionRefused(
                f"{url.broker} refused the subscription to {topic_filter} (SUBACK {code:#04x})"
            )
