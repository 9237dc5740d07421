"""The Bus: one line, its link, its arbiter, and the drives on it; and ``open_bus``.

A bus speaks one protocol, its dialect: SJ300 (the default) or the
Mitsubishi FR-700 computer link (``open_bus(url, protocol="fr700")`` or
``?protocol=fr700``). :meth:`Bus.drive` hands out the protocol's drive
class: :class:`~sj300_async.Drive` (nodes 1..32) or
:class:`~sj300_async.fr700.Fr700Drive` (stations 0..31). For type
checkers the bus is generic in that class: ``open_bus(url)`` and
``open_bus(url, protocol="sj300")`` give a ``Bus[Drive]`` (plain ``Bus``),
``open_bus(url, protocol="fr700")`` a ``Bus[Fr700Drive]``. A URL that names
the protocol only in its query is typed by the ``protocol`` argument, so
code that wants FR-700 types passes it (the two must agree).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import TYPE_CHECKING, Any, Final, Generic, Literal, Protocol, overload

from typing_extensions import TypeVar

from ._arbiter import Arbiter
from ._commands import Command
from ._dialect import SJ300_DIALECT, Dialect, LineRequest
from ._drive import Broadcast, Drive
from ._errors import BusClosedError, LocalProtocolError, ReadOnlyError
from ._line import INSTANT_LINE, LineSettings
from ._link import Connector, Link, ReconnectPolicy
from ._protocol import LineProtocol
from ._stats import BusStats, TransactionStats
from ._timing import BusTiming
from ._trace import TraceHook
from ._url import BusAddress, ProtocolName, parse_bus_url, parse_flag
from .fr700 import Fr700Dialect, Fr700Drive
from .transports import LineFaults, loopback_connector, serial_connector, tcp_connector

if TYPE_CHECKING:
    from .simulator import SimulatedBus
    from .simulator.fr700 import Fr700SimulatedBus


class BusDrive(Protocol):
    """What every protocol's drive class offers the bus."""

    #: The drive's own wait before replying, in seconds.
    wait_time_s: float

    @property
    def node(self) -> int:
        """The drive's address on the line."""


#: The drive class a bus hands out (for type checkers; SJ300's by default).
DriveT = TypeVar("DriveT", bound=BusDrive, default=Drive)

__all__ = ["MUTATING_COMMANDS", "Bus", "make_dialect", "open_bus"]

_log = logging.getLogger("sj300_async.bus")

#: Commands that change a drive; a read-only bus refuses them.
MUTATING_COMMANDS: Final = frozenset(
    {
        Command.RUN,
        Command.SET_FREQUENCY,
        Command.SET_TERMINALS,
        Command.WRITE_PARAMETER,
        Command.INITIALIZE,
        Command.STORE,
        Command.RECALCULATE,
    }
)

#: A TCP bridge adds network latency on top of the line's wire time.
_TCP_MARGIN_S: Final = 0.1


#: Each protocol's drive class.
_DRIVE_CLASSES: Final[dict[str, Callable[[Any, int], Any]]] = {
    "sj300": Drive,
    "fr700": Fr700Drive,
}


class Bus(Generic[DriveT]):
    """One RS-485 line and the drives on it. Open it with :func:`open_bus`.

    Attributes:
        stats: counters of the whole bus.
        line: the line settings used for wire-time arithmetic.
        timing: the timing policy.
        retries: attempts after the first for transmission errors and time-outs.
        read_only: refuse every command that changes a drive.
    """

    def __init__(
        self,
        connector: Connector,
        *,
        description: str,
        line: LineSettings,
        timing: BusTiming,
        retries: int = 2,
        strip_echo: bool = False,
        read_only: bool = False,
        trace: TraceHook | None = None,
        reconnect: ReconnectPolicy | None = None,
        dialect: Dialect = SJ300_DIALECT,
    ) -> None:
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise LocalProtocolError(f"retries must be an int >= 0, got {retries!r}")
        self.description = description
        self.stats = BusStats()
        self.line = line
        self.timing = timing
        self.retries = retries
        self.read_only = read_only
        self._trace = trace
        self._strip_echo = strip_echo
        #: The protocol spoken on this bus.
        self.dialect = dialect
        self._parser = dialect.new_parser()
        self.link = Link(
            connector, self._make_protocol, self.stats, description=description, policy=reconnect
        )
        self._arbiter = Arbiter(self.link, line, timing, self.stats, dialect)
        try:
            self._drive_class = _DRIVE_CLASSES[dialect.name]
        except KeyError:
            raise LocalProtocolError(f"no drive class for protocol {dialect.name!r}") from None
        self._drives: dict[int, DriveT] = {}
        self._broadcast = Broadcast(self)
        self._closed = False
        #: The in-memory simulator behind a sim:// bus (None otherwise): tests use its
        #: fault hooks, demos trip its drives.
        self.simulator: SimulatedBus | Fr700SimulatedBus | None = None
        self._supervisor: asyncio.Task[None] | None = None

    def _make_protocol(self) -> LineProtocol:
        # A new connection starts with a clean parser: bytes of the old one are gone.
        self._parser.reset()
        return LineProtocol(
            self._parser,
            self._arbiter,
            self.stats,
            strip_echo=self._strip_echo,
            trace=self._trace,
            trace_bytes=self.dialect.trace_bytes,
        )

    @property
    def trace(self) -> TraceHook | None:
        """The hook that sees every frame; set it to None to stop tracing."""
        return self._trace

    @trace.setter
    def trace(self, hook: TraceHook | None) -> None:
        self._trace = hook
        protocol = self.link.protocol
        if protocol is not None:
            protocol.trace = hook

    @property
    def connected(self) -> bool:
        """True while the link is up."""
        return self.link.connected

    @property
    def closed(self) -> bool:
        """True once the bus is closed."""
        return self._closed

    def drive(self, node: int, *, wait_time_s: float | None = None) -> DriveT:
        """Return the drive at *node* (the same object each time).

        An SJ300 bus gives a :class:`Drive` (nodes 1..32), an FR-700 bus an
        :class:`~sj300_async.fr700.Fr700Drive` (stations 0..31).

        Args:
            wait_time_s: the drive's own wait before replying in seconds, if
                known (SJ300: C078; FR-700: Pr.123 when requests carry no
                waiting-time field).

        Raises:
            LocalProtocolError: *node* is out of the protocol's range.
        """
        # Validate before the cache: True == 1 and 1.0 == 1 would find drive 1.
        if isinstance(node, bool) or not isinstance(node, int):
            raise LocalProtocolError(
                f"node must be an int (1..32; FR-700 stations 0..31), got {node!r}"
            )
        drive = self._drives.get(node)
        if drive is None:
            drive = self._drive_class(self, node)
            self._drives[node] = drive
        if wait_time_s is not None:
            if not 0 <= wait_time_s <= 1.0:
                raise LocalProtocolError(f"a drive's wait time is 0..1 s, got {wait_time_s!r}")
            drive.wait_time_s = wait_time_s
        return drive

    @property
    def drives(self) -> dict[int, DriveT]:
        """The drives handed out so far, by node."""
        return dict(self._drives)

    @property
    def broadcast(self) -> Broadcast:
        """Commands to every drive at once (no reply).

        Raises:
            LocalProtocolError: the bus's protocol has no broadcast (FR-700).
        """
        if self.dialect.name != "sj300":
            raise LocalProtocolError(f"the {self.dialect.name} protocol has no broadcast")
        return self._broadcast

    async def _execute(
        self,
        request: LineRequest,
        stats: TransactionStats,
        *,
        wait_s: float = 0.0,
        timeout_s: float | None = None,
        urgent: bool = False,
        mutating: bool | None = None,
    ) -> Any:
        """Run a request of this bus's dialect (the Drive classes call this).

        Args:
            mutating: does the request change a drive? (None: decide from the
                SJ300 command table.)
        """
        if self._closed:
            raise BusClosedError(f"bus {self.description} is closed")
        if mutating is None:
            mutating = getattr(request, "command", None) in MUTATING_COMMANDS
        if self.read_only and mutating:
            raise ReadOnlyError(f"bus {self.description} is read-only: {request.label} refused")
        return await self._arbiter.transact(
            request, stats, wait_s=wait_s, timeout_s=timeout_s, retries=self.retries, urgent=urgent
        )

    async def start(self) -> None:
        """Connect, and keep the link up from now on (``open_bus`` calls this).

        The reconnect supervisor is a plain task owned by the bus, not an anyio
        task group held across ``open_bus``'s yield: a task group would wrap
        the caller's own exceptions (a NakError raised in the body) in an
        ExceptionGroup.

        Raises:
            TransportError: the first connection failed.
        """
        await self.link.connect()
        self._supervisor = asyncio.create_task(
            self.link.supervise(), name=f"sj300 link {self.description}"
        )

    def close(self) -> None:
        """Close the bus: the link closes, waiting requests fail. Idempotent."""
        self._closed = True
        self.link.close()
        if self._supervisor is not None:
            self._supervisor.cancel()

    async def aclose(self) -> None:
        """Close the bus and wait until its background task has ended. Idempotent."""
        self.close()
        supervisor, self._supervisor = self._supervisor, None
        if supervisor is not None:
            # wait() neither raises the supervisor's CancelledError nor hides ours.
            await asyncio.wait([supervisor])
            if not supervisor.cancelled() and supervisor.exception() is not None:
                _log.error("link supervisor failed", exc_info=supervisor.exception())

    async def __aenter__(self) -> Bus[DriveT]:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.aclose()


_TERMINATORS: Final = {"none": "", "": "", "cr": "\r", "crlf": "\r\n"}


def make_dialect(address: BusAddress, protocol: ProtocolName | None = None) -> Dialect:
    """The dialect for a parsed URL and an explicit *protocol* (which must agree with the URL's).

    Raises:
        LocalProtocolError: the two protocols differ, or a bad FR-700 option.
    """
    if protocol is not None and protocol not in _DRIVE_CLASSES:
        raise LocalProtocolError(f"unknown protocol {protocol!r} (use sj300 or fr700)")
    if protocol is not None and address.protocol is not None and protocol != address.protocol:
        raise LocalProtocolError(
            f"protocol={protocol!r} but the URL says protocol={address.protocol}"
        )
    if (protocol or address.protocol) != "fr700":
        return SJ300_DIALECT
    options = address.protocol_options
    terminator = options.get("terminator", "cr").lower()
    if terminator not in _TERMINATORS:
        raise LocalProtocolError(f"terminator must be none, cr or crlf, got {terminator!r}")
    return Fr700Dialect(
        wait_field=parse_flag("wait_field", options.get("wait_field", "1")),
        terminator=_TERMINATORS[terminator],
        send_ack=parse_flag("ack", options.get("ack", "0")),
    )


def _sim_connector(
    address: BusAddress,
    line: LineSettings,
    dialect: Dialect,
    faults: tuple[LineFaults | None, LineFaults | None] | None,
    sim: SimulatedBus | Fr700SimulatedBus | None,
) -> tuple[Connector, SimulatedBus | Fr700SimulatedBus]:
    from .simulator import LinePacing, SimulatedBus, SimulatorEndpoint
    from .simulator.fr700 import Fr700SimulatedBus

    options = address.sim_options
    factory_defaults = parse_flag("factory_defaults", options.get("factory_defaults", "0"))
    if sim is None:
        if isinstance(dialect, Fr700Dialect):
            sim = Fr700SimulatedBus(
                address.nodes,
                wait_field=dialect.options.wait_field,
                terminator=dialect.options.terminator,
                factory_defaults=factory_defaults,
            )
        else:
            sim = SimulatedBus(nodes=address.nodes, factory_defaults=factory_defaults)
    if isinstance(sim, Fr700SimulatedBus) != isinstance(dialect, Fr700Dialect):
        raise LocalProtocolError(f"simulator {sim!r} does not speak {dialect.name}")
    if "wait_ms" in options:
        try:
            wait_ms = int(options["wait_ms"])
        except ValueError:
            raise LocalProtocolError(
                f"wait_ms must be an integer, got {options['wait_ms']!r}"
            ) from None
        for drive in sim.drives.values():
            drive.set_wait_ms(wait_ms)
    pacing = None
    if parse_flag("pace", options.get("pace", "0")):
        pacing = LinePacing(line.baudrate, line.bytesize, line.parity, line.stopbits)
    to_peer, to_host = faults or (None, None)
    served = sim
    connector = loopback_connector(
        lambda send: SimulatorEndpoint(served, send=send, pacing=pacing),
        to_peer=to_peer,
        to_host=to_host,
    )
    return connector, sim


@overload
def open_bus(
    url: str,
    *,
    protocol: Literal["fr700"],
    timeout: float | None = None,
    retries: int = 2,
    strip_echo: bool | None = None,
    read_only: bool = False,
    line: LineSettings | None = None,
    timing: BusTiming | None = None,
    trace: TraceHook | None = None,
    reconnect: ReconnectPolicy | None = None,
    faults: tuple[LineFaults | None, LineFaults | None] | None = None,
    simulator: SimulatedBus | Fr700SimulatedBus | None = None,
    dialect: Dialect | None = None,
) -> AbstractAsyncContextManager[Bus[Fr700Drive]]: ...


@overload
def open_bus(
    url: str,
    *,
    protocol: Literal["sj300"] | None = None,
    timeout: float | None = None,
    retries: int = 2,
    strip_echo: bool | None = None,
    read_only: bool = False,
    line: LineSettings | None = None,
    timing: BusTiming | None = None,
    trace: TraceHook | None = None,
    reconnect: ReconnectPolicy | None = None,
    faults: tuple[LineFaults | None, LineFaults | None] | None = None,
    simulator: SimulatedBus | Fr700SimulatedBus | None = None,
    dialect: Dialect | None = None,
) -> AbstractAsyncContextManager[Bus]: ...


def open_bus(
    url: str,
    *,
    protocol: ProtocolName | None = None,
    timeout: float | None = None,
    retries: int = 2,
    strip_echo: bool | None = None,
    read_only: bool = False,
    line: LineSettings | None = None,
    timing: BusTiming | None = None,
    trace: TraceHook | None = None,
    reconnect: ReconnectPolicy | None = None,
    faults: tuple[LineFaults | None, LineFaults | None] | None = None,
    simulator: SimulatedBus | Fr700SimulatedBus | None = None,
    dialect: Dialect | None = None,
) -> AbstractAsyncContextManager[Bus[Any]]:
    """Open a bus, connect, and close everything on exit (also on error and cancellation).

    Args:
        url: ``tcp://host:port``, ``serial:///dev/ttyUSB0?baudrate=19200&parity=E``,
            a bare device path, or ``sim://?nodes=1-8`` (see :mod:`sj300_async._url`).
        protocol: ``"sj300"`` (default) or ``"fr700"``; the URL's ``protocol=``
            may say it instead (the two must agree).
        timeout: a fixed response time-out in seconds for every request
            (default: computed from the line settings, the drive's wait time
            and a margin).
        retries: attempts after the first, for time-outs and transmission errors.
        strip_echo: remove the RS-485 adapter's local echo (default: the URL's ``echo``).
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

    Raises:
        LocalProtocolError: a bad URL or setting (nothing is opened).
        TransportError: the first connection failed.
    """
    return _open_bus(
        url,
        protocol=protocol,
        timeout=timeout,
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
    )


@asynccontextmanager
async def _open_bus(
    url: str,
    *,
    protocol: ProtocolName | None,
    timeout: float | None,  # noqa: ASYNC109 - the response time-out, not a deadline
    retries: int,
    strip_echo: bool | None,
    read_only: bool,
    line: LineSettings | None,
    timing: BusTiming | None,
    trace: TraceHook | None,
    reconnect: ReconnectPolicy | None,
    faults: tuple[LineFaults | None, LineFaults | None] | None,
    simulator: SimulatedBus | Fr700SimulatedBus | None,
    dialect: Dialect | None,
) -> AsyncIterator[Bus[Any]]:
    address = parse_bus_url(url, protocol=protocol)
    made = make_dialect(address, protocol)
    if dialect is None:
        dialect = made
    elif dialect.name != made.name:
        raise LocalProtocolError(f"dialect {dialect.name} but the protocol is {made.name}")
    if line is None:
        line = address.line or (INSTANT_LINE if address.scheme == "sim" else LineSettings())
    if timing is None:
        timing = BusTiming(margin_s=_TCP_MARGIN_S) if address.scheme == "tcp" else BusTiming()
    if timeout is not None:
        timing = BusTiming(
            margin_s=timing.margin_s,
            fixed_timeout_s=timeout,
            guard_chars=timing.guard_chars,
            broadcast_processing_s=timing.broadcast_processing_s,
            drain_max_s=timing.drain_max_s,
        )
    if (faults is not None or simulator is not None) and address.scheme != "sim":
        raise LocalProtocolError("faults= and simulator= are for sim:// buses only")
    connector: Connector
    if address.scheme == "tcp":
        connector = tcp_connector(address.host, address.port)
    elif address.scheme == "serial":
        if line.baudrate == 0:
            raise LocalProtocolError(f"a serial line needs a baud rate: {url!r}")
        connector = serial_connector(address.device, line)
    else:
        connector, simulator = _sim_connector(address, line, dialect, faults, simulator)
    bus: Bus[Any] = Bus(
        connector,
        description=address.description,
        line=line,
        timing=timing,
        retries=retries,
        strip_echo=bool(address.echo) if strip_echo is None else strip_echo,
        read_only=read_only,
        trace=trace,
        reconnect=reconnect,
        dialect=dialect,
    )
    bus.simulator = simulator
    try:
        await bus.start()
        yield bus
    finally:
        await bus.aclose()
