"""``sj300 monitor --url mqtt://HOST:PORT[/prefix]``: every drive of every gateway on a broker.

The fleet view opens no bus: it follows what the gateways' MQTT bridges
publish through the library's fleet subscriber
(:class:`sj300_async.gateway.mqtt.Fleet` and
:func:`~sj300_async.gateway.mqtt.follow`: the URL, the read-only
subscription, reconnection and the checks on every message are there) and
shows the latest state of each (gateway, line, node). This module only
renders it. ``--timeout`` bounds the connection and the subscription,
its retained states included (default 10 s); the options that describe a
bus (``--nodes``, ``--protocol``, ``--trace``, the line settings) are
refused, since the gateways own the buses; ``--interval`` and
``--retries`` are the bus monitor's and do nothing here.

Output, as the bus monitor's:

- a terminal: a live table, one row per drive sorted by gateway, line and
  node: gateway, line, node, online, output frequency, current, voltage,
  direction, state (a tripped drive names its trip) and the age of its
  data. The caption says how the broker connection is doing, and how many
  malformed messages were skipped. The columns keep their width over a
  run, as the bus monitor's (a name column is as wide as its longest name);
- ``--json``: one object per state message received, flushed: the record
  the bus monitor prints too (:class:`~._record.DriveRecord`, :func:`record`),
  ``time`` the gateway's poll (Unix seconds), ``gateway_online`` False once
  the gateway's last will said offline, ``error`` and ``latency_s`` null;
- anything else: one plain line per state message, its columns at fixed
  places.

``--count N`` ends it after N cycles, as on a bus: a cycle is one state of
every drive, the first the retained states the broker hands over on
subscribing (``--count 1``: every drive once), each later one a new state
of every drive whose gateway and the drive itself are online
(:attr:`~sj300_async.gateway.mqtt.Fleet.cycles`). MQTT marks no end to the
retained states: the first cycle ends when a drive sends again (a
gateway's next poll), or ``--timeout`` seconds after the last state when
none comes (a broker whose gateways are all gone); a fleet with no drive
left to wait for then ends the view. ``--duration`` ends it after so many
seconds; SIGTERM with 0, Ctrl-C with 130, as the bus monitor.

Decisions:

- The state in words and the trip's meaning are the gateway's
  (``state``, ``trip_meaning``: its drive profile worked them out); a
  message from a gateway that sends neither is shown from its ``running``,
  ``tripped`` and ``direction`` alone, never by decoding a protocol's
  status codes here.
- A drive of a gateway whose availability is ``offline`` shows as
  ``offline (stale)``.
- When any message was skipped as malformed, a summary line ends the run
  on stderr (``sj300 monitor: note: 2 malformed messages skipped (first:
  TOPIC: REASON)``): stdout stays the states alone, and nobody needs ``-v``
  to learn that something on the broker is wrong.
- Broker unreachable at the start: one line, exit 1, as an unreachable
  bus; lost later: the caption says so, and without the table a note on
  stderr does. The view needs no extra: the MQTT client is the gateway's
  own, on the standard library.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
import time
from collections.abc import Iterator
from typing import Any, Final

from ..gateway.mqtt import (
    BrokerUnreachable,
    Fleet,
    StateMessage,
    SubscriptionRefused,
    follow,
    parse_fleet_url,
)
from ._errors import FAILURE, CliError
from ._fit import STATE_WIDTH, FitColumn, clip, fit
from ._output import Justify, is_terminal, print_json
from ._record import DriveRecord

__all__ = ["fleet_table", "plain_line", "record", "state_text", "watch_fleet"]

#: How long connecting and subscribing may take without ``--timeout``.
DEFAULT_TIMEOUT_S: Final = 10.0
#: How wide a plain line's gateway/line/node is (a longer one pushes the rest).
_DRIVE_WIDTH: Final = 24
#: How wide the age is: ``0.4 s`` .. ``119 min``.
_AGE_WIDTH: Final = len("119 min")
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
    """The gateway's words; from an older gateway, what running and direction tell."""
    if message.state is not None:
        return message.state
    if message.running is None:
        return "-"
    if not message.running:
        return "stopped"
    return "running reverse" if message.direction == "reverse" else "running"


def _trip_words(message: StateMessage) -> str:
    """``E07 over-voltage``; ``fault H9A`` when the profile knows no meaning; an older
    gateway's (no ``state``: it sends no meaning either) the code alone."""
    code = message.trip
    if code is None:
        return ""
    if message.trip_meaning:
        return f"{code} {message.trip_meaning}"
    return code if message.state is None else f"fault {code}"


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


def _Column(
    header: str,
    key: str,
    justify: Justify = "left",
    *,
    flexible: bool = False,
    min_width: int = 0,
    width: int = 0,
) -> FitColumn:
    """A fleet column: left-aligned unless told otherwise (text, mostly)."""
    return FitColumn(header, key, justify, flexible=flexible, min_width=min_width, width=width)


_GATEWAY = _Column("gateway", "gateway", flexible=True, min_width=4)
_LINE = _Column("line", "line", flexible=True, min_width=4)
_NODE = _Column("node", "node", "right")
_AGE = _Column("age", "age", "right", width=_AGE_WIDTH)
#: The layouts, richest first: the first that fits the terminal is used (else the last).
#: Numbers: a frequency up to 400.00 Hz, a current or a voltage up to 999.9 A or V.
_LAYOUTS: Final = (
    (
        _GATEWAY,
        _LINE,
        _NODE,
        _Column("online", "link", width=len("offline (stale)")),
        _Column("out Hz", "out_hz", "right", width=6),
        _Column("current A", "amps", "right"),
        _Column("voltage V", "volts", "right"),
        _Column("direction", "direction"),
        _Column("state", "state", flexible=True, min_width=12, width=STATE_WIDTH),
        _AGE,
    ),
    # Compact (80 columns): no direction (a running FR-700's state says reverse), short
    # headers, "stale" for "offline (stale)".
    (
        _GATEWAY,
        _LINE,
        _NODE,
        _Column("online", "link_short", width=len("offline")),
        _Column("Hz", "out_hz", "right", width=6),
        _Column("A", "amps", "right", width=5),
        _Column("V", "volts", "right", width=5),
        _Column("state", "state", flexible=True, min_width=7, width=STATE_WIDTH),
        _AGE,
    ),
)


def fleet_table(fleet: Fleet, width: int = 160, now: float | None = None) -> Any:
    """The rich table of every drive for *width* columns (Any: rich is imported when used)."""
    from rich import box
    from rich.table import Table
    from rich.text import Text

    now = time.time() if now is None else now
    drives = fleet.drives
    rows = [cells(m, gateway_online=fleet.gateway_online(m.gateway), now=now) for m in drives]
    columns, widths = fit(_LAYOUTS, width, rows)
    table = Table(
        title=f"sj300 monitor — fleet on {fleet.url.broker} ({fleet.url.prefix}/…)",
        caption=_caption(fleet),
        box=box.SIMPLE_HEAD,
    )
    for column in columns:
        table.add_column(
            column.header,
            justify=column.justify,
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
    drive = f"{c['gateway']}/{c['line']}/{c['node']}"
    return (
        f"{clock} {drive:<{_DRIVE_WIDTH}} {c['link']:<15}"
        f" out {c['out_hz']:>6} Hz  {c['amps']:>6} A  {c['volts']:>6} V"
        f"  {c['direction']:<7} {clip(c['state'], STATE_WIDTH):<{STATE_WIDTH}}"
        f"  age {c['age']:>{_AGE_WIDTH}}"
    )


def record(message: StateMessage, *, gateway_online: bool = True) -> DriveRecord:
    """The ``--json`` record of *message* (:mod:`._record`: the bus monitor's shape).

    ``gateway_online`` is False once the gateway's availability says
    ``offline`` (its last will: it died or lost the broker): the message's
    own ``online`` is then the last word of a gateway that is gone.
    """
    return DriveRecord(
        time=message.time,
        gateway=message.gateway,
        line=message.line,
        node=message.node,
        protocol=message.protocol,
        online=message.online,
        state=message.state,
        running=message.running,
        tripped=message.tripped,
        trip=message.trip,
        trip_meaning=message.trip_meaning,
        direction=message.direction,
        output_frequency_hz=message.output_frequency_hz,
        set_frequency_hz=message.set_frequency_hz,
        output_current_a=message.output_current_a,
        output_voltage_v=message.output_voltage_v,
        output_torque_percent=message.output_torque_percent,
        power_kw=message.power_kw,
        status=message.status,
        parameters=message.parameters,
        gateway_online=gateway_online,
        lapse_pending=message.lapse_pending,
    )


# --- the subscription ------------------------------------------------------------------------


def _refuse_bus_options(args: argparse.Namespace) -> None:
    """A bus option with a broker URL: exit 2 rather than ignore it."""
    for attr, option in _BUS_OPTIONS:
        if getattr(args, attr, None) not in (None, False):
            raise CliError(
                f"{option} does not apply to a broker URL: the gateways own the buses "
                "(the fleet view shows every drive they publish)"
            )


# --- the command -----------------------------------------------------------------------------


async def watch_fleet(args: argparse.Namespace, url_text: str) -> None:
    """``sj300 monitor`` on a broker: until ``--count`` cycles, ``--duration`` or a signal.

    Raises:
        CliError: a bad URL or a bus option (exit 2), the broker unreachable at
            the start (exit 1).
    """
    url = parse_fleet_url(url_text)
    _refuse_bus_options(args)
    fleet = Fleet(url)
    live = is_terminal() and not args.json
    count: int | None = args.count
    timeout_s = args.timeout or DEFAULT_TIMEOUT_S
    loop = asyncio.get_running_loop()
    heard = loop.time()  # the latest state or link event
    connected_before = False
    quiet: asyncio.Task[None] | None = None

    def done() -> bool:
        return count is not None and fleet.cycles >= count

    def on_state(message: StateMessage) -> bool:
        nonlocal heard
        heard = loop.time()
        if count is not None and fleet.cycle > count:
            return False  # the first state of the cycle after the last: not shown
        if args.json:
            gateway_online = fleet.gateway_online(message.gateway)
            print_json(record(message, gateway_online=gateway_online).as_json())
        elif not live:
            print(plain_line(fleet, message), flush=True)
        return not done()

    async def end_cycles_when_quiet(deadline: asyncio.Timeout) -> None:
        """What --timeout without a state ends: the first cycle, when no drive sends
        again; a later one's wait for drives gone offline or whose gateway died
        (their gateway's last will came, and no state will)."""
        nonlocal heard
        while True:
            wait = heard + timeout_s - loop.time()
            if wait > 0:
                await asyncio.sleep(wait)
                continue
            fleet.end_first_cycle()
            fleet.recheck()
            heard = loop.time()  # nothing came: looked at again after as long
            # Done, or nothing is left to wait for; --duration may be up at this very moment.
            ended = count is not None and (done() or not fleet.waiting())
            if ended and not deadline.expired():
                deadline.reschedule(loop.time())  # ends the view, as --duration does

    with contextlib.ExitStack() as stack:
        deadline = asyncio.timeout(args.duration)

        def on_link(problem: str | None) -> None:
            nonlocal connected_before, heard, quiet
            heard = loop.time()
            if problem is None and not connected_before:
                connected_before = True
                quiet = loop.create_task(end_cycles_when_quiet(deadline))
                if live:  # only now: a broker that cannot be reached is one line, no table
                    stack.enter_context(_live(fleet))
            elif live:
                return  # the table's caption says it
            elif problem is None:
                _note(f"reconnected to {url.broker}")
            else:
                _note(problem)

        try:
            with contextlib.suppress(TimeoutError):  # --duration is up, or the view is done
                async with deadline:
                    await follow(fleet, on_state, timeout_s=timeout_s, on_link=on_link)
        except BrokerUnreachable as exc:
            raise CliError(f"cannot connect to {url.broker}: {exc}", status=FAILURE) from None
        except SubscriptionRefused as exc:
            raise CliError(str(exc), status=FAILURE) from None
        finally:
            if quiet is not None:
                quiet.cancel()
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
