"""``sj300 monitor --url mqtt://HOST:PORT[/prefix]``: every drive of every gateway on a broker.

The fleet view opens no bus: it subscribes to what the gateways' MQTT
bridges publish (the contract is :mod:`sj300_async.gateway._mqtt_topics`),
``<prefix>/+/availability`` and ``<prefix>/+/+/+/state``, and shows the
latest state of each (gateway, line, node). Read-only: it never publishes
(no will, no command topic; a clean session, so it leaves nothing behind on
the broker either).

The URL: ``mqtt://[USER[:PASSWORD]@]HOST[:PORT][/PREFIX]``, ``mqtts://`` for
TLS (the system's certificate authorities). Ports default to 1883 and 8883;
the prefix to ``sj300``, and it may have several levels
(``mqtt://broker/plant/north``). Each level follows the contract's naming
rule (no wildcard, no empty level); a bad URL is exit 2. ``--timeout``
bounds the connection and the subscription (default 10 s); the options
that describe a bus (``--nodes``, ``--protocol``, ``--trace``, the line
settings) are refused, since the gateways own the buses; ``--interval`` and
``--retries`` are the bus monitor's and do nothing here.

Output, as the bus monitor's:

- a terminal: a live table, one row per drive sorted by gateway, line and
  node: gateway, line, node, online, output frequency, current, voltage,
  direction, state (a tripped drive names its trip) and the age of its
  data. The caption says how the broker connection is doing;
- ``--json``: one object per state message received, flushed: the
  message's fields (:class:`~sj300_async.gateway._mqtt_topics.StateMessage`)
  plus ``age_s``, the wall-clock seconds since the gateway polled the drive
  (negative when the two clocks disagree: not hidden), and
  ``gateway_online`` (False once the gateway's last will said offline);
- anything else: one plain line per state message.

``--count N`` ends it after N state messages (the retained ones the broker
hands over on subscribing count: ``--count`` with the number of drives
shows each once); ``--duration`` after so many seconds; SIGTERM with 0,
Ctrl-C with 130, as the bus monitor.

Decisions:

- Staleness: a gateway whose availability is ``offline`` (its last will:
  it died or lost the broker) shows its drives as ``offline (stale)``: its
  retained states describe a past that nobody is refreshing. The
  availability is subscribed before the states, so that the broker hands
  over the retained availability first and no row shows a dead gateway's
  drive online, even for a moment.
- The topic is authoritative: a state whose payload names another
  (gateway, line, node) than its topic is malformed (a misrouted or
  hand-made message), as is one whose shown fields have the wrong type
  (``StateMessage.from_json`` checks only the gateway and the node: a text
  where a number belongs would otherwise break the table), a gateway or
  line that breaks the contract's naming rule, or text that is not
  printable (an escape sequence would reach the terminal as it is).
- Malformed messages (a payload that is no state, an availability that is
  neither ``online`` nor ``offline``, a topic the contract does not name)
  are skipped, counted and logged at DEBUG with their payload. The count
  shows in the live table's caption, and when any was skipped a summary
  line ends the run on stderr (``sj300 monitor: note: 2 malformed messages
  skipped (first: TOPIC: REASON)``): stdout stays the states alone, and
  nobody needs ``-v`` to learn that something on the broker is wrong.
- An empty payload clears a retained message (``mosquitto_pub -r -n``):
  it removes the drive (or forgets the gateway's availability) rather than
  counting as malformed.
- Broker unreachable at the start: one line, exit 1, as an unreachable
  bus. Lost later: reconnect with a growing back-off (0.5 s, doubling, at
  most 10 s: a viewer wants to see the fleet back soon, and one client
  retrying every 10 s costs a broker nothing); the table's caption says so,
  and without the table a note on stderr does. After a reconnect the broker
  hands over the retained states again (``--json`` prints them again).
- aiomqtt (the ``gateway`` extra) is imported only when a broker is asked
  for: the bus monitor does not need it, and without it the fleet view is
  one line naming ``pip install 'sj300-async[gateway]'``, exit 2.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import math
import ssl
import sys
import time
import urllib.parse
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

from ..gateway._mqtt_topics import (
    AVAILABLE,
    DEFAULT_PREFIX,
    UNAVAILABLE,
    StateMessage,
    parse_state_topic,
    valid_name,
)
from ..sj300._codes import StatusA, StatusB, StatusC
from ..sj300._payloads import InverterStatus
from ._errors import FAILURE, USAGE, CliError
from ._output import drive_state, is_terminal, jsonable, print_json
from ._tripinfo import sj300_trip

if TYPE_CHECKING:
    import aiomqtt

__all__ = ["Fleet", "FleetUrl", "is_fleet_url", "parse_fleet_url", "watch_fleet"]

_log = logging.getLogger("sj300_async.cli.fleet")

#: URL schemes of a broker (the fleet view) rather than a bus.
SCHEMES: Final = {"mqtt": 1883, "mqtts": 8883}
#: The reconnection back-off (seconds): the first wait, doubled at each failure up to the ceiling.
BACKOFF_FIRST_S: Final = 0.5
BACKOFF_MAX_S: Final = 10.0
#: The broker connection's keep-alive: a silently dropped link is noticed within 1.5x this.
KEEPALIVE_S: Final = 10
#: How long connecting and subscribing may take without ``--timeout``.
DEFAULT_TIMEOUT_S: Final = 10.0
#: How much of a malformed payload the DEBUG log shows.
_LOGGED_PAYLOAD: Final = 2048
#: The options of a bus, refused with a broker URL (the attribute, the option).
_BUS_OPTIONS: Final = (
    ("nodes", "--nodes"),
    ("protocol", "--protocol"),
    ("trace", "--trace"),
    ("baud", "--baud"),
    ("parity", "--parity"),
    ("bytesize", "--bytesize"),
    ("stopbits", "--stopbits"),
)


def is_fleet_url(url: str) -> bool:
    """True when *url* names a broker (``mqtt://``, ``mqtts://``), not a bus."""
    scheme, sep, _ = url.partition("://")
    return bool(sep) and scheme.lower() in SCHEMES


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
        CliError: not such a URL (exit 2).
    """
    parts = urllib.parse.urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme not in SCHEMES:
        raise CliError(f"not a broker URL: {url!r} (mqtt://HOST:PORT[/prefix], mqtts://...)")
    try:
        port = parts.port or SCHEMES[scheme]
    except ValueError as exc:  # a port that is no number or out of range
        raise CliError(f"bad broker URL {url!r}: {exc}") from None
    if not parts.hostname:
        raise CliError(f"bad broker URL {url!r}: no host (mqtt://HOST:PORT[/prefix])")
    if parts.query or parts.fragment:
        raise CliError(f"bad broker URL {url!r}: it takes no ?query or #fragment")
    prefix = parts.path.strip("/") or DEFAULT_PREFIX
    if not all(valid_name(level) for level in prefix.split("/")):
        raise CliError(
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
    """The first malformed message: where it came, and why it was refused."""

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
            return self._state(key, topic, payload)
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

    def _availability_of(self, topic: str) -> str | None:
        head = self.url.prefix.split("/")
        parts = topic.split("/")
        if len(parts) != len(head) + 2 or parts[: len(head)] != head:
            return None
        gateway, last = parts[len(head) :]
        return gateway if last == "availability" else None

    def _malformed(self, topic: str, payload: bytes, reason: str) -> None:
        self.malformed += 1
        if self.first_malformed is None:  # shown on stderr: no control character gets there
            self.first_malformed = Malformed(_escaped(topic), _escaped(" ".join(reason.split())))
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


def _escaped(text: str) -> str:
    """*text* with each unprintable character written as Python escapes it (``\\x1b``)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _check_shown_fields(message: StateMessage) -> None:
    """Refuse a state whose fields the view shows have the wrong type, or unprintable text.

    Text goes to a terminal as it is (the plain lines): an escape sequence in
    a payload must not reach it.

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
    for name in ("direction", "trip", "protocol"):
        value = getattr(message, name)
        if value is not None and not (isinstance(value, str) and value.isprintable()):
            raise ValueError(f"{name} is not printable text")
    if message.status is not None and not isinstance(message.status, dict):
        raise ValueError("status is not an object")


# --- how it is shown -------------------------------------------------------------------------


def age_s(message: StateMessage, now: float | None = None) -> float:
    """Wall-clock seconds since the gateway polled the drive."""
    return (time.time() if now is None else now) - message.time


def format_age(seconds: float) -> str:
    """``0.4 s``, ``12 s``, ``3 min``, ``2 h``, ``4 d`` (a clock ahead of ours: 0)."""
    seconds = max(seconds, 0.0)
    if seconds < 10:
        return f"{seconds:.1f} s"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.0f} h"
    return f"{seconds / 86400:.0f} d"


def state_text(message: StateMessage) -> str:
    """The drive's state in words, as the bus monitor says it; a trip named."""
    state = _status_words(message)
    if message.tripped or state == "tripped":
        return f"tripped {_trip_words(message)}".rstrip()
    return state


def _status_words(message: StateMessage) -> str:
    status = message.status
    if status is not None:
        with contextlib.suppress(KeyError, TypeError, ValueError):  # names from newer firmware
            if "bits" in status:  # FR-700
                from ..fr700._codes import Fr700StatusBits
                from ..fr700._payloads import Fr700Status

                return drive_state(Fr700Status(Fr700StatusBits(int(status["bits"]))))
            return drive_state(
                InverterStatus(StatusA[status["a"]], StatusB[status["b"]], StatusC[status["c"]])
            )
    if message.running is None:
        return "-"
    if not message.running:
        return "stopped"
    return "running reverse" if message.direction == "reverse" else "running"


def _trip_words(message: StateMessage) -> str:
    """``E07 over-voltage`` (SJ300), ``fault H10`` (FR-700), or the code as it came."""
    code = message.trip
    if code is None:
        return ""
    if message.protocol == "sj300" and code[:1] == "E" and code[1:].isdigit():
        return str(sj300_trip(int(code[1:])))
    if message.protocol == "fr700":
        return f"fault {code}"
    return code


def _number(value: float | None, digits: int) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def cells(message: StateMessage, *, gateway_online: bool, now: float) -> dict[str, str]:
    """Every cell of *message*'s row as text."""
    link = "online" if message.online else "offline"
    if not gateway_online:  # its gateway is gone: nobody refreshes this state
        link = "offline (stale)"
    return {
        "gateway": message.gateway,
        "line": message.line,
        "node": f"{message.node:02d}",
        "link": link,
        "link_short": "stale" if not gateway_online else link,
        "out_hz": _number(message.output_frequency_hz, 2),
        "amps": _number(message.output_current_a, 1),
        "volts": _number(message.output_voltage_v, 1),
        "direction": message.direction or "-",
        "state": state_text(message),
        "age": format_age(age_s(message, now)),
    }


@dataclass(frozen=True, slots=True)
class _Column:
    header: str
    key: str
    justify: str = "left"
    #: Takes the room the others leave, cut with … when short (never a number).
    flexible: bool = False
    min_width: int = 0


_GATEWAY = _Column("gateway", "gateway", flexible=True, min_width=4)
_LINE = _Column("line", "line", flexible=True, min_width=4)
_NODE = _Column("node", "node", "right")
_AGE = _Column("age", "age", "right")
#: The layouts, richest first: the first that fits the terminal is used (else the last).
_LAYOUTS: Final = (
    (
        _GATEWAY,
        _LINE,
        _NODE,
        _Column("online", "link"),
        _Column("out Hz", "out_hz", "right"),
        _Column("current A", "amps", "right"),
        _Column("voltage V", "volts", "right"),
        _Column("direction", "direction"),
        _Column("state", "state", flexible=True, min_width=12),
        _AGE,
    ),
    # Compact (80 columns): no direction (a running FR-700's state says reverse), short
    # headers, "stale" for "offline (stale)".
    (
        _GATEWAY,
        _LINE,
        _NODE,
        _Column("online", "link_short"),
        _Column("Hz", "out_hz", "right"),
        _Column("A", "amps", "right"),
        _Column("V", "volts", "right"),
        _Column("state", "state", flexible=True, min_width=7),
        _AGE,
    ),
)


def _layout(width: int, rows: list[dict[str, str]]) -> tuple[tuple[_Column, ...], dict[str, int]]:
    """The first layout that fits *width* columns, and each of its columns' width.

    A fixed column is as wide as its widest cell or header (numbers are never
    cut); the flexible ones share the rest, each at least its ``min_width``.
    """
    from rich.cells import cell_len

    def natural(column: _Column) -> int:
        return max([cell_len(column.header), *(cell_len(row[column.key]) for row in rows)])

    for columns in _LAYOUTS:
        # Per column: one space of padding each side and a divider; the edges: 1 more.
        left = width - (3 * len(columns) + 1)
        fixed = {c.key: natural(c) for c in columns if not c.flexible}
        flexible = [c for c in columns if c.flexible]
        left -= sum(fixed.values())
        if left >= sum(c.min_width for c in flexible):
            break
    widths = dict(fixed)
    for i, column in enumerate(flexible):
        later = sum(c.min_width for c in flexible[i + 1 :])
        widths[column.key] = max(1, min(natural(column), left - later))
        left -= widths[column.key]
    return columns, widths


def fleet_table(fleet: Fleet, width: int = 160, now: float | None = None) -> Any:
    """The rich table of every drive for *width* columns (Any: rich is imported when used)."""
    from rich import box
    from rich.table import Table
    from rich.text import Text

    now = time.time() if now is None else now
    drives = fleet.drives
    rows = [cells(m, gateway_online=fleet.gateway_online(m.gateway), now=now) for m in drives]
    columns, widths = _layout(width, rows)
    table = Table(
        title=f"sj300 monitor — fleet on {fleet.url.broker} ({fleet.url.prefix}/…)",
        caption=_caption(fleet),
        box=box.SIMPLE_HEAD,
    )
    for column in columns:
        table.add_column(
            column.header,
            justify="right" if column.justify == "right" else "left",
            no_wrap=True,
            min_width=widths[column.key],
            max_width=widths[column.key],
            overflow="ellipsis",
        )
    for message, row in zip(drives, rows, strict=True):
        # A dead gateway's drives, or all of them while the broker is away: old news.
        fresh = fleet.gateway_online(message.gateway) and fleet.link_problem is None
        styled: dict[str, Any] = {
            key: Text(text, style="" if fresh else "dim") for key, text in row.items()
        }
        link_style = "green" if row["link"] == "online" else "bold red"
        styled["link"] = Text(row["link"], style=link_style)
        styled["link_short"] = Text(row["link_short"], style=link_style)
        styled["state"] = Text(row["state"], style=_state_style(message, row["state"]))
        table.add_row(*(styled[column.key] for column in columns))
    return table


def _caption(fleet: Fleet) -> Any:
    from rich.text import Text

    drives = fleet.drives
    gateways = {m.gateway for m in drives}
    offline = sum(1 for g in gateways if not fleet.gateway_online(g))
    caption = Text()
    if drives:
        caption.append(f"{len(drives)} drive{'s' if len(drives) != 1 else ''} on ")
        caption.append(f"{len(gateways)} gateway{'s' if len(gateways) != 1 else ''}")
        if offline:
            caption.append(f" ({offline} offline)", style="bold red")
    else:
        caption.append(f"no state yet on {fleet.url.state_filter}")
    if fleet.link_problem is not None:
        caption.append(f" · {fleet.link_problem}", style="bold red")
    if fleet.malformed:
        caption.append(f" · {fleet.malformed} malformed skipped", style="yellow")
    caption.append(" · Ctrl-C to stop")
    return caption


def _state_style(message: StateMessage, text: str) -> str:
    if text.startswith("tripped"):
        return "bold red"
    return "green" if message.running else ""


def plain_line(fleet: Fleet, message: StateMessage, now: float | None = None) -> str:
    """One line for a log: time, gateway/line/node, online, values with units, state, age."""
    now = time.time() if now is None else now
    c = cells(message, gateway_online=fleet.gateway_online(message.gateway), now=now)
    clock = time.strftime("%H:%M:%S", time.localtime(now)) + f".{int(now % 1 * 1000):03d}"
    return (
        f"{clock} {c['gateway']}/{c['line']}/{c['node']} {c['link']:<7}"
        f" out {c['out_hz']:>6} Hz  {c['amps']:>6} A  {c['volts']:>6} V"
        f"  {c['direction']:<7} {c['state']}  age {c['age']}"
    )


def state_json(
    message: StateMessage, now: float | None = None, *, gateway_online: bool = True
) -> dict[str, Any]:
    """The ``--json`` object: the message's fields plus ``age_s`` and ``gateway_online``.

    ``gateway_online`` is False once the gateway's availability says
    ``offline`` (its last will: it died or lost the broker): the message's
    own ``online`` is then the last word of a gateway that is gone.
    """
    body: dict[str, Any] = jsonable(message)
    body["age_s"] = round(age_s(message, now), 3)
    body["gateway_online"] = gateway_online
    return body


# --- the subscription ------------------------------------------------------------------------


def _import_aiomqtt() -> Any:
    """aiomqtt, or exit 2 naming the extra that brings it."""
    try:
        import aiomqtt
    except ImportError as exc:
        raise CliError(
            f"the fleet view needs the gateway extra ({exc.name or 'aiomqtt'} is missing): "
            "pip install 'sj300-async[gateway]'",
            status=USAGE,
        ) from None
    return aiomqtt


def _refuse_bus_options(args: argparse.Namespace) -> None:
    """A bus option with a broker URL: exit 2 rather than ignore it."""
    for attr, option in _BUS_OPTIONS:
        if getattr(args, attr, None) not in (None, False):
            raise CliError(
                f"{option} does not apply to a broker URL: the gateways own the buses "
                "(the fleet view shows every drive they publish)"
            )


def backoff(attempt: int) -> float:
    """The delay before reconnection *attempt* (0, 1, ...): 0.5 s doubling, at most 10 s."""
    return min(BACKOFF_FIRST_S * 2.0 ** min(attempt, 16), BACKOFF_MAX_S)


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
        CliError: the broker cannot be reached or refuses the subscription
            at the start (exit 1), or aiomqtt is missing (exit 2).
    """
    mqtt = _import_aiomqtt()
    url = fleet.url
    attempt = 0
    connected_once = False

    def link(problem: str | None) -> None:
        fleet.link_problem = problem
        if on_link is not None:
            on_link(problem)

    while True:
        subscribed = False
        client: aiomqtt.Client = mqtt.Client(
            url.host,
            url.port,
            username=url.username,
            password=url.password,
            tls_context=ssl.create_default_context() if url.tls else None,
            timeout=timeout_s,
            keepalive=KEEPALIVE_S,
        )
        try:
            async with client:
                # Availability first: the broker hands over retained messages in the order of
                # the filters, so a dead gateway's drives never show online, even briefly.
                granted = await client.subscribe(
                    [(url.availability_filter, 1), (url.state_filter, 1)]
                )
                _check_granted(url, granted)
                connected_once = subscribed = True
                attempt = 0
                link(None)
                async for message in client.messages:
                    payload = message.payload  # bytes from paho; typed wider by aiomqtt
                    data = b"" if payload is None else payload
                    if not isinstance(data, bytes | bytearray):
                        data = str(data).encode()
                    state = fleet.receive(message.topic.value, bytes(data))
                    if state is not None and not on_state(state):
                        return
        except mqtt.MqttError as exc:
            reason = " ".join(str(exc).split()) or type(exc).__name__
            if not connected_once:
                raise CliError(
                    f"cannot connect to {url.broker}: {reason}", status=FAILURE
                ) from None
            delay = backoff(attempt)
            attempt += 1
            what = "connection to {} lost" if subscribed else "cannot reconnect to {}"
            link(f"{what.format(url.broker)} ({reason}): next attempt in {delay:g} s")
            _log.info("%s: %s; next attempt in %g s", what.format(url.broker), reason, delay)
            await asyncio.sleep(delay)
            fleet.link_problem = f"reconnecting to {url.broker} (attempt {attempt})"


def _check_granted(url: FleetUrl, granted: Any) -> None:
    """A subscription the broker refused (an ACL): exit 1, naming the filter.

    Raises:
        CliError: a refusal (the SUBACK's reason code 0x80 or above).
    """
    filters = (url.availability_filter, url.state_filter)
    for topic_filter, code in zip(filters, granted, strict=False):
        failed = code.is_failure if hasattr(code, "is_failure") else int(code) >= 0x80
        if failed:
            raise CliError(
                f"{url.broker} refused the subscription to {topic_filter}: {code}", status=FAILURE
            )


# --- the command -----------------------------------------------------------------------------


async def watch_fleet(args: argparse.Namespace, url_text: str) -> None:
    """``sj300 monitor`` on a broker: until ``--count`` states, ``--duration`` or a signal.

    Raises:
        CliError: a bad URL or a bus option (exit 2), aiomqtt missing (exit 2),
            the broker unreachable at the start (exit 1).
    """
    url = parse_fleet_url(url_text)
    _refuse_bus_options(args)
    _import_aiomqtt()  # before anything is shown
    fleet = Fleet(url)
    live = is_terminal() and not args.json
    count: int | None = args.count
    received = 0
    connected_before = False

    def on_state(message: StateMessage) -> bool:
        nonlocal received
        received += 1
        if args.json:
            print_json(state_json(message, gateway_online=fleet.gateway_online(message.gateway)))
        elif not live:
            print(plain_line(fleet, message), flush=True)
        return count is None or received < count

    with contextlib.ExitStack() as stack:

        def on_link(problem: str | None) -> None:
            nonlocal connected_before
            if problem is None and not connected_before:
                connected_before = True
                if live:  # only now: a broker that cannot be reached is one line, no table
                    stack.enter_context(_live(fleet))
            elif live:
                return  # the table's caption says it
            elif problem is None:
                _note(f"reconnected to {url.broker}")
            else:
                _note(problem)

        timeout_s = args.timeout or DEFAULT_TIMEOUT_S
        try:
            with contextlib.suppress(TimeoutError):  # --duration is up
                async with asyncio.timeout(args.duration):
                    await follow(fleet, on_state, timeout_s=timeout_s, on_link=on_link)
        finally:
            stack.close()  # the table's last frame, then the summary under it
            summary = fleet.summary()
            if summary is not None:
                _note(summary)


def _note(text: str) -> None:
    print(f"sj300 monitor: note: {text}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def _live(fleet: Fleet) -> Iterator[None]:
    from rich.console import Console
    from rich.live import Live

    console = Console()
    with Live(
        get_renderable=lambda: fleet_table(fleet, console.width),
        console=console,
        refresh_per_second=4,
    ):
        yield
