"""One MQTT connection kept up: connect, run, and after a loss reconnect with a back-off.

The JSON bridge and the fleet subscriber (``gateway.mqtt``) and the
Sparkplug edge node (``gateway.sparkplug``) keep their connection through
:func:`keep_connected`: one reconnect loop, one back-off, one way of
reporting outages.

Decisions:

- The back-off starts at :data:`BACKOFF_FIRST_S` and doubles at each
  failed attempt up to the caller's ceiling (the bridge 30 s: a gateway
  that retries every 30 s costs a broker nothing; a person watching the
  fleet view 10 s, to see the fleet back soon). A connection that came up
  resets it.
- An outage is logged once, at the caller's level, when it starts (``lost
  …; reconnecting`` or ``cannot connect to …; retrying``); the attempts
  after it at DEBUG; the recovery at INFO. The fleet view logs outages at
  INFO (its table's caption shows them: a WARNING would reach the terminal
  under the table).
- A connection ended because a QoS 1 publish waited past ``keepalive_s``
  for its PUBACK (the client's :class:`~.client.PublishUnacknowledged`:
  a broker that answers pings and swallows publishes) is counted in
  ``SessionStats.puback_timeouts``, whether it was up or still setting
  up, and logged as any other end is (the outage's one WARNING carries the
  client's reason: the packet, how long, how many waited). The client
  ended it without DISCONNECT, so the broker publishes the will:
  "offline" is the truth while nothing gets through. A SUBSCRIBE whose
  SUBACK never came (:class:`~.client.SubscribeUnacknowledged`) is the
  same, counted in ``SessionStats.suback_timeouts``: the session
  subscribes while it sets up, so it is usually still setting up (its
  WARNING says "cannot connect ... no SUBACK for ..."; not one of the
  ``losses``, which count connections that were up), and the next attempt
  follows the back-off.
- ``on_link`` hears every change: None when connected, else a sentence
  saying what happened and when the next attempt comes.
- A bug in the session body (any exception but the client's MqttError) is, for a
  service (``survive_errors``: the gateway's bridge), logged with its
  traceback and treated as a lost connection, so it cannot end the
  connection for good; for a viewer it ends the session and is raised (the
  fleet view whose reader went away must stop, not reconnect for ever). A
  caller that must fail at once on an unreachable broker (a command line)
  asks for it with ``fail_first``.
- Cancellation ends the loop at once (whatever it was doing); the body's
  own ``except CancelledError`` runs first, inside the connection (the
  bridge says "offline" there).
- A body reads its messages from the connection's first moment, while it
  sets up (:func:`reader`): the broker's answers the set-up waits for
  (SUBACKs, PUBACKs) come behind the messages it sent before them, and a
  client whose reader is behind stops reading: unread, 1,000 messages of
  a flood under way at a (re)connection hung the set-up for ever.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import ssl
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final

from ._broker import load_client_certificate
from .client import Client, MqttError, PublishUnacknowledged, SubscribeUnacknowledged, Will

if TYPE_CHECKING:
    from ._broker import BrokerConfig

__all__ = [
    "BACKOFF_FIRST_S",
    "BrokerUnreachable",
    "SessionStats",
    "backoff",
    "cancel_and_wait",
    "keep_connected",
    "new_client",
    "reader",
]

BACKOFF_FIRST_S: Final = 0.5
#: How often a task that lost its cancellation is cancelled again (see cancel_and_wait).
CANCEL_AGAIN_S: Final = 0.1

#: The body of a connection: runs with the connected client until the connection
#: fails (raising the client's MqttError) or its work is done (returning); it calls the
#: given function once it is set up (subscribed), which counts as "connected".
Body = Callable[[Client, Callable[[], None]], Awaitable[None]]


class BrokerUnreachable(Exception):
    """The first connection failed and the caller asked to fail at once (``fail_first``)."""


@dataclass
class SessionStats:
    """Connections made and lost."""

    connects: int = 0
    #: Connections lost after they were up (each logged once).
    losses: int = 0
    #: Connections ended because a QoS 1 publish waited past keepalive_s for its
    #: PUBACK (up or still setting up; those up are also in ``losses``).
    puback_timeouts: int = 0
    #: Connections ended because a SUBSCRIBE (or UNSUBSCRIBE) waited past keepalive_s
    #: for its answer (usually while setting up: not in ``losses`` then).
    suback_timeouts: int = 0
    #: SUBACKs that refused a subscription, per topic filter (every filter
    #: subscribed is here, at 0 until refused): see :mod:`._subscriptions`.
    subscriptions_refused: collections.Counter[str] = field(default_factory=collections.Counter)


def new_client(
    config: BrokerConfig,
    *,
    identifier: str,
    will: Will | None = None,
    max_in_flight: int = 256,
    max_payload: int = 1 << 20,
) -> Client:
    """A client for one connection attempt to *config*'s broker (not entered yet).

    Its URL, credentials, TLS (with the client's certificate, when the
    section gives one) and keepalive are the section's; the session is
    clean (nothing the broker kept for us: no stale command). *max_in_flight*
    caps the QoS 1 publishes awaiting their acknowledgement. A broker that
    stops reading makes publishes wait, and its keepalive ends the
    connection (:mod:`.client`). A received payload past *max_payload*
    bytes is skipped unread, and delivered as its first 256 bytes with its
    length.
    """
    tls = None
    if config.tls:
        tls = ssl.create_default_context(
            cafile=None if config.tls_ca is None else str(config.tls_ca)
        )
        if config.tls_cert is not None:
            # Read at each attempt, as the CA is: a renewed certificate needs no restart.
            load_client_certificate(tls, config.tls_cert, config.tls_key)
    return Client(
        config.host,
        config.port,
        identifier=identifier,
        username=config.username,
        password=config.password,
        tls=tls,
        will=will,
        clean_session=True,
        keepalive_s=config.keepalive_s,
        max_in_flight=max_in_flight,
        max_publish_bytes=max_payload,
    )


def backoff(attempt: int, ceiling_s: float) -> float:
    """The delay before reconnection *attempt* (0, 1, ...): 0.5 s doubling, at most *ceiling_s*."""
    return min(BACKOFF_FIRST_S * 2.0 ** min(attempt, 16), ceiling_s)


async def keep_connected(
    connect: Callable[[], Client],
    body: Body,
    *,
    url: str,
    log: logging.Logger,
    ceiling_s: float,
    stats: SessionStats | None = None,
    outage_level: int = logging.WARNING,
    fail_first: bool = False,
    survive_errors: bool = True,
    on_link: Callable[[str | None], None] | None = None,
    on_attempt: Callable[[int], None] | None = None,
    who: str = "",
) -> None:
    """Run *body* on a connection to *url* until it returns (see the module docstring).

    Args:
        connect: makes a new (not yet entered) client for each attempt.
        survive_errors: treat the body's other exceptions as a lost connection
            (logged); False: raise them.
        on_attempt: told each reconnection attempt's number as it starts.
        who: appended to the first "connected" log line (``" as gw1"``).

    Raises:
        BrokerUnreachable: with *fail_first*, the first connection failed.
    """
    stats = SessionStats() if stats is None else stats
    attempt = 0  # failed attempts since the last good connection
    outage = False  # an outage already logged (its next failed attempts are DEBUG)
    ever = False  # connected at least once

    def link(problem: str | None) -> None:
        if on_link is not None:
            on_link(problem)

    while True:
        up = False

        def connected() -> None:
            nonlocal up, ever, attempt, outage
            up = True
            stats.connects += 1
            if outage:
                log.info("MQTT: connected again to %s", url)
            else:
                log.info("MQTT: connected to %s%s", url, who)
            ever, attempt, outage = True, 0, False
            link(None)

        try:
            async with connect() as client:
                await body(client, connected)
            return
        except MqttError as exc:
            reason = " ".join(str(exc).split()) or type(exc).__name__
            if isinstance(exc, PublishUnacknowledged):
                stats.puback_timeouts += 1
            elif isinstance(exc, SubscribeUnacknowledged):
                stats.suback_timeouts += 1
        except Exception as exc:  # a bug of ours must not end a service's connection for good
            if not survive_errors:
                raise
            log.exception("MQTT: unexpected error")
            reason = f"{type(exc).__name__}: {exc}"
        if fail_first and not ever:
            raise BrokerUnreachable(reason)
        delay = backoff(attempt, ceiling_s)
        attempt += 1
        if up:
            stats.losses += 1
            what = f"connection to {url} lost"
            log.log(outage_level, "MQTT: lost %s (%s); reconnecting", url, reason)
        elif not outage:
            what = f"cannot connect to {url}" if not ever else f"cannot reconnect to {url}"
            log.log(outage_level, "MQTT: cannot connect to %s (%s); retrying", url, reason)
        else:
            what = f"cannot reconnect to {url}" if ever else f"cannot connect to {url}"
            log.debug("MQTT: %s still unreachable (%s)", url, reason)
        outage = True
        link(f"{what} ({reason}): next attempt in {delay:g} s")
        await asyncio.sleep(delay)
        if on_attempt is not None:
            on_attempt(attempt)


def reader(receive: Coroutine[Any, Any, None], name: str) -> asyncio.Task[None]:
    """*receive* (a body's reader) as a task started now, to run while the body sets up.

    Its error is marked retrieved: it is the connection's, which the set-up
    meets too when it fails first. The body cancels it when it ends.
    """
    task = asyncio.get_running_loop().create_task(receive, name=name)
    task.add_done_callback(lambda done: None if done.cancelled() else done.exception())
    return task


async def cancel_and_wait(
    tasks: set[asyncio.Task[None]], *, patience_s: float = CANCEL_AGAIN_S
) -> None:
    """Cancel *tasks* and wait until each has ended, cancelling again any still running.

    Once is not always enough on Python 3.11: a task inside ``asyncio.wait_for``
    can lose a cancellation that arrives as the awaited result does
    (gh-86296), and run on (a publisher on aiomqtt, before the client was
    ours, kept a dead Sparkplug session born and deaf that way). A command's
    write still goes through code that uses it. The tasks get *patience_s*
    after the first cancellation (a connection's task says "offline" and
    disconnects as it ends: cancelled again meanwhile, it would say
    nothing), then are cancelled again every :data:`CANCEL_AGAIN_S`.
    """
    pending = {task for task in tasks if not task.done()}
    wait_s = patience_s
    while pending:
        for task in pending:
            task.cancel()
        _, pending = await asyncio.wait(pending, timeout=wait_s)
        wait_s = CANCEL_AGAIN_S
    for task in tasks:
        if not task.cancelled():
            task.exception()  # retrieved: the caller has the task's error already
