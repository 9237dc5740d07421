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
from typing import Any, Final, TypedDict

from typing_extensions import Unpack

from ..transports import LineFaults, replay_connector
from ..wire import INSTANT_LINE, LineSettings, LocalProtocolError
from ._bus import Bus, ConnectMode
from ._capture import CaptureFile, open_capture
from ._dialect import Dialect
from ._line_connector import line_connector
from ._link import Connector, ReconnectPolicy
from ._registry import DEFAULT_PROTOCOL, get_dialect, scheme_connector
from ._replay_open import open_replay
from ._timing import BusTiming
from ._trace import TraceHook
from ._url import BusAddress, parse_bus_url

__all__ = ["BusOptions", "make_dialect", "open_bus"]

#: Attempts after the first when ``retries=`` is not given.
_DEFAULT_RETRIES: Final = 2


class BusOptions(TypedDict, total=False):
    """The keyword arguments of :func:`open_bus` after ``protocol``; every one may be left out.

    :func:`open_bus`'s docstring documents each, with its default. The
    overloads of :func:`sj300_async.open_bus` take them as ``**options`` too
    (``Unpack[BusOptions]``), so they are written once for every signature.
    """

    timeout: float | None
    deadline: float | None
    retries: int
    strip_echo: bool | None
    read_only: bool
    line: LineSettings | None
    timing: BusTiming | None
    trace: TraceHook | None
    reconnect: ReconnectPolicy | None
    faults: tuple[LineFaults | None, LineFaults | None] | None
    simulator: Any
    dialect: Dialect[Any, Any] | None
    capture: str | PathLike[str] | CaptureFile | None
    connect: ConnectMode


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


def _dialect_of(
    address: BusAddress, protocol: str | None, given: Dialect[Any, Any] | None
) -> Dialect[Any, Any]:
    """*given* (``dialect=``) if it speaks the bus's protocol, else the one the URL makes."""
    made = make_dialect(address, protocol)
    if given is None:
        return made
    if given.name != made.name:
        raise LocalProtocolError(f"dialect {given.name} but the protocol is {made.name}")
    return given


def _timing_of(address: BusAddress, options: BusOptions) -> BusTiming:
    """``timing=`` (or the scheme's default) with ``timeout=`` and ``deadline=`` applied."""
    timing = options.get("timing")
    if timing is None:
        # A replay answers as the captured line did: time it as a bridge (the
        # margin most captures need; --timeout says otherwise).
        bridged = address.scheme in ("tcp", "rfc2217", "replay")
        timing = BusTiming(margin_s=_TCP_MARGIN_S) if bridged else BusTiming()
    timeout = options.get("timeout")
    if timeout is not None:
        timing = replace(timing, fixed_timeout_s=timeout)
    deadline = options.get("deadline")
    if deadline is not None:
        timing = replace(timing, call_deadline_s=deadline)
    return timing


def open_bus(
    url: str, *, protocol: str | None = None, **options: Unpack[BusOptions]
) -> AbstractAsyncContextManager[Bus[Any, Any]]:
    """Open a bus, connect, and close everything on exit (also on error and cancellation).

    Args:
        url: ``tcp://host:port``, ``rfc2217://host:port?baudrate=9600``,
            ``serial:///dev/ttyUSB0?baudrate=19200&parity=E``, a bare device
            path, or ``sim://?nodes=1-8`` (see :mod:`._url`).
        protocol: a registered protocol's name (``"sj300"``, the default, or
            ``"fr700"``); the URL's ``protocol=`` may say it instead (the two
            must agree). :func:`sj300_async.open_bus`, whose types follow this
            argument, refuses a URL (or a ``replay://`` capture) that names
            another protocol than it: pass that one.

    Keyword Args:
        timeout: a fixed response time-out in seconds for every attempt of
            every request (default: computed from the line settings, the
            drive's wait time and a margin). A call makes up to ``retries + 1``
            attempts, with a drain after each failed one.
        deadline: the longest a call may take in seconds, all its attempts
            together: no attempt starts after it (``BusTiming.call_deadline_s``;
            default none).
        retries: attempts after the first, for time-outs and transmission errors
            (default 2).
        strip_echo: the RS-485 adapter's local echo: None to detect and strip it
            (the default, ``echo=auto``), True when the line echoes (``echo=1``:
            a missing echo is counted), False to never look (``echo=0``);
            default: the URL's ``echo``, else auto (see :mod:`._protocol`).
        read_only: refuse every command that changes a drive (default False).
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
        connect: ``"now"`` (the default): the first connection must succeed,
            or ``open_bus`` raises. ``"background"``: a line that is down at
            start (connection refused, timed out, host unreachable or unknown,
            a serial device that is not there) is opened anyway, down, and
            reconnected by the ``reconnect`` policy exactly as a link lost
            later (requests fail at once with :class:`TransportError` until
            then; ``bus.connected`` and ``bus.link.last_error`` say so). A bad
            URL or setting, and a port that refuses the line settings, still
            raise (see :meth:`Bus.start`).

    Raises:
        LocalProtocolError: a bad URL or setting (nothing is opened).
        TransportError: the first connection failed (``connect="now"``), or
            the serial port refused the line settings.
        TypeError: a keyword argument that is none of these (at once).
    """
    unknown = options.keys() - BusOptions.__optional_keys__
    if unknown:
        names = ", ".join(sorted(unknown))
        raise TypeError(f"open_bus() got unexpected keyword argument(s) {names}")
    return _open_bus(url, protocol, options)


@asynccontextmanager
async def _open_bus(
    url: str, protocol: str | None, options: BusOptions
) -> AsyncIterator[Bus[Any, Any]]:
    address = parse_bus_url(url, protocol=protocol)
    replay = None
    if address.scheme == "replay":  # the capture names the protocol and the line
        replay = open_replay(address, protocol)
        protocol = replay.protocol
        address = replace(address, line=address.line or replay.line)
    dialect = _dialect_of(address, protocol, options.get("dialect"))
    line = options.get("line")
    if line is None:
        line = address.line or (INSTANT_LINE if address.scheme == "sim" else LineSettings())
    timing = _timing_of(address, options)
    faults, simulator = options.get("faults"), options.get("simulator")
    opener = None if replay is not None else scheme_connector(address.scheme)
    if (faults is not None or simulator is not None) and opener is None:
        raise LocalProtocolError("faults= and simulator= are for sim:// buses only")
    connector: Connector
    if replay is not None:
        connector = replay_connector(replay.script)
    elif opener is not None:  # sim://: found by its scheme in the registry
        opened = opener(address, line=line, dialect=dialect, faults=faults, simulator=simulator)
        connector, simulator = opened.connector, opened.simulator
    else:
        connector = line_connector(address, line)
    capture = options.get("capture")
    capture_file = open_capture(capture)
    line_capture = None
    if capture_file is not None:
        line_capture = capture_file.line(dialect, address.description, line)
    strip_echo = options.get("strip_echo")
    bus: Bus[Any, Any] = Bus(
        connector,
        description=address.description,
        line=line,
        timing=timing,
        dialect=dialect,
        retries=options.get("retries", _DEFAULT_RETRIES),
        strip_echo=address.echo if strip_echo is None else strip_echo,
        read_only=options.get("read_only", False),
        trace=options.get("trace"),
        reconnect=options.get("reconnect"),
        capture=line_capture,
    )
    bus.simulator = simulator
    try:
        await bus.start(connect=options.get("connect", "now"))
        yield bus
    finally:
        await bus.aclose()
        if capture_file is not None and capture_file is not capture:
            capture_file.close()
