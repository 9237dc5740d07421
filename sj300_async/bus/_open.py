"""``open_bus``: a URL in, a connected bus out, everything closed on the way out.

The protocol-neutral form: the bus speaks the dialect the URL's (or the
caller's) protocol names in the registry, with the URL's protocol options
applied. :func:`sj300_async.open_bus` is the same function with overloads
that give type checkers each built-in protocol's drive class.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from dataclasses import replace
from os import PathLike
from typing import Any, Final

from ..transports import LineFaults, loopback_connector
from ..transports._replay import replay_connector
from ..wire import LineSettings, LocalProtocolError
from ..wire._line import INSTANT_LINE
from ._bus import Bus
from ._capture import CaptureFile, open_capture
from ._dialect import Dialect, SimulatorFactory
from ._line_connector import line_connector
from ._link import Connector, ReconnectPolicy
from ._registry import DEFAULT_PROTOCOL, get_dialect, load_object
from ._replay_open import open_replay
from ._timing import BusTiming
from ._trace import TraceHook
from ._url import BusAddress, parse_bus_url, parse_flag

__all__ = ["make_dialect", "open_bus"]

#: A TCP bridge adds network latency on top of the line's wire time.
_TCP_MARGIN_S: Final = 0.1


def make_dialect(address: BusAddress, protocol: str | None = None) -> Dialect[Any, Any]:
    """The dialect for a parsed URL and an explicit *protocol* (which must agree with the URL's).

    Raises:
        LocalProtocolError: an unknown protocol, the two differ, or a bad protocol option.
    """
    if protocol is not None:
        get_dialect(protocol)
        if address.protocol is not None and protocol != address.protocol:
            raise LocalProtocolError(
                f"protocol={protocol!r} but the URL says protocol={address.protocol}"
            )
    name = protocol or address.protocol or DEFAULT_PROTOCOL
    return get_dialect(name).configure(address.protocol_options)


def _sim_connector(
    address: BusAddress,
    line: LineSettings,
    dialect: Dialect[Any, Any],
    faults: tuple[LineFaults | None, LineFaults | None] | None,
    sim: Any,
) -> tuple[Connector, Any]:
    from ..simulator import LinePacing, PacedLine, PlausibleLine, SimulatorEndpoint

    options = address.sim_options
    wait_ms: int | None = None
    if "wait_ms" in options:
        try:
            wait_ms = int(options["wait_ms"])
        except ValueError:
            raise LocalProtocolError(
                f"wait_ms must be an integer, got {options['wait_ms']!r}"
            ) from None
    if sim is None:
        factory: SimulatorFactory = load_object(dialect.simulator)
        sim = factory(
            dialect,
            address.nodes,
            factory_defaults=parse_flag("factory_defaults", options.get("factory_defaults", "0")),
            wait_ms=wait_ms,
        )
    elif getattr(sim, "protocol", None) != dialect.name:
        raise LocalProtocolError(f"simulator {sim!r} does not speak {dialect.name}")
    elif wait_ms is not None:
        for drive in sim.drives.values():
            drive.set_wait_ms(wait_ms)
    # pace=1: every character takes its wire time. Unpaced on a line with a
    # speed: the drives answer at once but no reply arrives sooner than the
    # request and a short reply could cross that line (PlausibleLine), or the
    # host's plausibility floor would refuse every answer. Instant line: at once.
    pacing = LinePacing(line.baudrate, line.bytesize, line.parity, line.stopbits)
    paced = parse_flag("pace", options.get("pace", "0"))

    def wire() -> PacedLine | None:  # one per connection: a line is booked per endpoint
        if paced:
            return PacedLine(pacing)
        return PlausibleLine(pacing) if pacing.baudrate else None

    to_peer, to_host = faults or (None, None)
    served = sim
    connector = loopback_connector(
        lambda send: SimulatorEndpoint(served, send=send, line=wire()),
        to_peer=to_peer,
        to_host=to_host,
    )
    return connector, sim


def open_bus(
    url: str,
    *,
    protocol: str | None = None,
    timeout: float | None = None,
    deadline: float | None = None,
    retries: int = 2,
    strip_echo: bool | None = None,
    read_only: bool = False,
    line: LineSettings | None = None,
    timing: BusTiming | None = None,
    trace: TraceHook | None = None,
    reconnect: ReconnectPolicy | None = None,
    faults: tuple[LineFaults | None, LineFaults | None] | None = None,
    simulator: Any = None,
    dialect: Dialect[Any, Any] | None = None,
    capture: str | PathLike[str] | CaptureFile | None = None,
) -> AbstractAsyncContextManager[Bus[Any, Any]]:
    """Open a bus, connect, and close everything on exit (also on error and cancellation).

    Args:
        url: ``tcp://host:port``, ``rfc2217://host:port?baudrate=9600``,
            ``serial:///dev/ttyUSB0?baudrate=19200&parity=E``, a bare device
            path, or ``sim://?nodes=1-8`` (see :mod:`._url`).
        protocol: a registered protocol's name (``"sj300"``, the default, or
            ``"fr700"``); the URL's ``protocol=`` may say it instead (the two
            must agree).
        timeout: a fixed response time-out in seconds for every attempt of
            every request (default: computed from the line settings, the
            drive's wait time and a margin). A call makes up to ``retries + 1``
            attempts, with a drain after each failed one.
        deadline: the longest a call may take in seconds, all its attempts
            together: no attempt starts after it (``BusTiming.call_deadline_s``;
            default none).
        retries: attempts after the first, for time-outs and transmission errors.
        strip_echo: the RS-485 adapter's local echo: None to detect and strip it
            (the default, ``echo=auto``), True when the line echoes (``echo=1``:
            a missing echo is counted), False to never look (``echo=0``);
            default: the URL's ``echo``, else auto (see :mod:`._protocol`).
        read_only: refuse every command that changes a drive.
        line: line settings (default: the URL's, else 19200 8N1; instant for sim://).
        timing: the full timing policy (``timeout`` overrides its fixed time-out).
        trace: a hook that sees every frame.
        reconnect: when to reconnect a dropped link.
        faults: (to-drive, to-host) line faults, for sim:// only (tests and soaks).
        simulator: for sim://, serve this simulated bus instead of a new one (its
            nodes replace the URL's).
        dialect: the protocol fully configured (e.g. ``Fr700Dialect(send_ack=True)``),
            instead of the one *protocol* and the URL's options make.
        capture: write every frame that crosses the line to this pcapng file
            (a path: created, and closed with the bus), or into this open
            :class:`~._capture.CaptureFile` as one more line (left open).

    Raises:
        LocalProtocolError: a bad URL or setting (nothing is opened).
        TransportError: the first connection failed.
    """
    return _open_bus(
        url,
        protocol=protocol,
        timeout=timeout,
        deadline=deadline,
        retries=retries,
        strip_echo=strip_echo,
        read_only=read_only,
        line=line,
        timing=timing,
        trace=trace,
        reconnect=reconnect,
        faults=faults,
        simulator=simulator,
        dialect=dialect,
        capture=capture,
    )


@asynccontextmanager
async def _open_bus(
    url: str,
    *,
    protocol: str | None,
    timeout: float | None,  # noqa: ASYNC109 - the response time-out, not a deadline
    deadline: float | None,
    retries: int,
    strip_echo: bool | None,
    read_only: bool,
    line: LineSettings | None,
    timing: BusTiming | None,
    trace: TraceHook | None,
    reconnect: ReconnectPolicy | None,
    faults: tuple[LineFaults | None, LineFaults | None] | None,
    simulator: Any,
    dialect: Dialect[Any, Any] | None,
    capture: str | PathLike[str] | CaptureFile | None,
) -> AsyncIterator[Bus[Any, Any]]:
    address = parse_bus_url(url, protocol=protocol)
    replay = None
    if address.scheme == "replay":  # the capture names the protocol and the line
        replay = open_replay(address, protocol)
        protocol = replay.protocol
        address = replace(address, line=address.line or replay.line)
    made = make_dialect(address, protocol)
    if dialect is None:
        dialect = made
    elif dialect.name != made.name:
        raise LocalProtocolError(f"dialect {dialect.name} but the protocol is {made.name}")
    if line is None:
        line = address.line or (INSTANT_LINE if address.scheme == "sim" else LineSettings())
    if timing is None:
        # A replay answers as the captured line did: time it as a bridge (the
        # margin most captures need; --timeout says otherwise).
        bridged = address.scheme in ("tcp", "rfc2217", "replay")
        timing = BusTiming(margin_s=_TCP_MARGIN_S) if bridged else BusTiming()
    if timeout is not None:
        timing = replace(timing, fixed_timeout_s=timeout)
    if deadline is not None:
        timing = replace(timing, call_deadline_s=deadline)
    if (faults is not None or simulator is not None) and address.scheme != "sim":
        raise LocalProtocolError("faults= and simulator= are for sim:// buses only")
    connector: Connector
    if replay is not None:
        connector = replay_connector(replay.script)
    elif address.scheme == "sim":
        connector, simulator = _sim_connector(address, line, dialect, faults, simulator)
    else:
        connector = line_connector(address, line)
    capture_file = open_capture(capture)
    line_capture = None
    if capture_file is not None:
        line_capture = capture_file.line(dialect, address.description, line)
    bus: Bus[Any, Any] = Bus(
        connector,
        description=address.description,
        line=line,
        timing=timing,
        dialect=dialect,
        retries=retries,
        strip_echo=address.echo if strip_echo is None else strip_echo,
        read_only=read_only,
        trace=trace,
        reconnect=reconnect,
        capture=line_capture,
    )
    bus.simulator = simulator
    try:
        await bus.start()
        yield bus
    finally:
        await bus.aclose()
        if capture_file is not None and capture_file is not capture:
            capture_file.close()
